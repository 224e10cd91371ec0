//! Named network conditions: `lan`, `wlan`, `competition`, `competition-ps`.
//!
//! Each preset says where its numbers come from. What the access point does (hold
//! group-addressed frames to a DTIM beacon, only while a station sleeps) is kept apart
//! from what the air does (delay, loss, bursts), so the two are not stacked by accident.

use std::fmt;
use std::str::FromStr;
use std::time::Duration;

use crate::impairment::{GilbertElliott, JitterDist, LinkConfig, UplinkConfig};
use crate::spec::SpecError;

/// A named set of network conditions.
///
/// Each preset has two parts: the per-receiver [`LinkConfig`] ([`Preset::link`]) and the
/// sender's shared [`UplinkConfig`] ([`Preset::uplink`]), which the simulator applies
/// once per transmission so that one burst hits every receiver of a multicast packet.
/// [`Preset::standalone`] folds both into one link config, for a single receiver (a
/// real-socket driver, or the spec string `preset=competition`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Preset {
    /// Wired switch: 100 µs ± 20 µs (normal), 100 Mbit/s, no loss.
    Lan,
    /// A quiet WLAN: 2 ms latency with heavy-tailed spikes (Pareto, scale 3 ms), 1% loss
    /// per receiver plus rare 50 ms bursts at the sender (≈ 1.5% in all), 24 Mbit/s.
    Wlan,
    /// A crowded competition WLAN with power save off, as robot teams run it:
    /// - **loss 20% in all**: bursts of 100 ms about every second at the sender, shared by
    ///   every receiver of a frame (10%: interference, a busy channel), plus 11.1%
    ///   independent per receiver. Group-addressed 802.11 frames are neither acknowledged
    ///   nor retried (IEEE 802.11-2020 §10.3.6: "no ACK … in response to group addressed
    ///   frames"), so what the air loses stays lost;
    /// - **20 ms ± 10 ms** (normal) one way: the station→AP leg is unicast, acknowledged and
    ///   retried, and waits for a loaded channel; the AP→group leg goes at once. This is an
    ///   assumption for a loaded cell (tens of robots and spectators' phones), not a
    ///   measurement: `huddle sim --sweep delay` shows how every figure moves with it;
    /// - **6 Mbit/s**: multicast goes at a basic rate (the lowest mandatory OFDM rate);
    /// - no beacon hold: an AP buffers group traffic to the DTIM beacon only while some
    ///   associated station is in power save (IEEE 802.11-2020 §11.2.3.6), and robot
    ///   teams switch power save off. See [`Preset::CompetitionPs`] for when one does not.
    Competition,
    /// [`Preset::Competition`] with a station in power save on the AP: every multicast
    /// frame is held to the next DTIM beacon, every DTIM period × 102.4 ms (hostapd's
    /// defaults: `beacon_int=100` TU of 1024 µs, `dtim_period=2`, so 204.8 ms; the
    /// hold adds 102.4 ms on average). Unicast is not held.
    CompetitionPs,
}

/// The standard 802.11 beacon interval: 100 time units of 1024 µs (hostapd `beacon_int`).
pub const BEACON_INTERVAL: Duration = Duration::from_micros(102_400);

/// hostapd's default DTIM period: group traffic buffered for sleeping stations goes out
/// after every second beacon.
pub const DEFAULT_DTIM_PERIOD: u32 = 2;

impl Preset {
    /// Every preset.
    pub const ALL: [Preset; 4] = [
        Preset::Lan,
        Preset::Wlan,
        Preset::Competition,
        Preset::CompetitionPs,
    ];

    /// The spec-string name.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Lan => "lan",
            Preset::Wlan => "wlan",
            Preset::Competition => "competition",
            Preset::CompetitionPs => "competition-ps",
        }
    }

    /// The per-receiver part.
    pub fn link(self) -> LinkConfig {
        match self {
            Preset::Lan => LinkConfig {
                latency: Duration::from_micros(100),
                jitter: Duration::from_micros(20),
                jitter_dist: JitterDist::Normal,
                rate_bps: Some(100_000_000),
                ..LinkConfig::default()
            },
            Preset::Wlan => LinkConfig {
                latency: Duration::from_millis(2),
                jitter: Duration::from_millis(3),
                jitter_dist: JitterDist::Pareto,
                loss: 0.01,
                rate_bps: Some(24_000_000),
                queue_limit: 128,
                ..LinkConfig::default()
            },
            Preset::Competition => LinkConfig {
                latency: Duration::from_millis(20),
                jitter: Duration::from_millis(10),
                jitter_dist: JitterDist::Normal,
                // With the uplink's 10%: 1 − 0.9 · (1 − 1/9) = 20% in all.
                loss: 1.0 / 9.0,
                rate_bps: Some(6_000_000),
                queue_limit: 64,
                ..LinkConfig::default()
            },
            Preset::CompetitionPs => LinkConfig {
                beacon: Some(dtim_interval(DEFAULT_DTIM_PERIOD)),
                ..Preset::Competition.link()
            },
        }
    }

    /// The sender's shared part.
    pub fn uplink(self) -> UplinkConfig {
        match self {
            Preset::Lan => UplinkConfig::default(),
            Preset::Wlan => UplinkConfig {
                loss: 0.0,
                burst: Some(GilbertElliott {
                    mean_good: Duration::from_secs(5),
                    mean_bad: Duration::from_millis(50),
                    loss_good: 0.0,
                    loss_bad: 0.5,
                }),
            },
            Preset::Competition | Preset::CompetitionPs => UplinkConfig {
                loss: 0.0,
                burst: Some(GilbertElliott::default()),
            },
        }
    }

    /// Link and uplink folded into one config, as one receiver sees them.
    pub fn standalone(self) -> LinkConfig {
        let link = self.link();
        let uplink = self.uplink();
        LinkConfig {
            loss: 1.0 - (1.0 - link.loss) * (1.0 - uplink.loss),
            burst: link.burst.or(uplink.burst),
            ..link
        }
    }
}

/// How long multicast waits at most under a DTIM period of `period` beacons.
pub fn dtim_interval(period: u32) -> Duration {
    BEACON_INTERVAL * period.max(1)
}

impl fmt::Display for Preset {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Preset {
    type Err = SpecError;
    fn from_str(s: &str) -> Result<Preset, SpecError> {
        Preset::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| SpecError::UnknownPreset {
                name: s.to_string(),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn competition_loses_twenty_percent_in_all() {
        let total = 1.0
            - (1.0 - Preset::Competition.uplink().mean_loss())
                * (1.0 - Preset::Competition.link().mean_loss());
        assert!(
            (total - 0.2).abs() < 1e-12,
            "competition total loss {total}"
        );
        assert!((Preset::Competition.standalone().mean_loss() - 0.2).abs() < 1e-12);
        assert_eq!(
            Preset::CompetitionPs.standalone().mean_loss(),
            Preset::Competition.standalone().mean_loss(),
            "power save changes when frames go, not whether"
        );
        for p in Preset::ALL {
            p.link().validate().unwrap();
            p.uplink().validate().unwrap();
            assert_eq!(p.name().parse::<Preset>().unwrap(), p);
        }
    }

    #[test]
    fn only_power_save_holds_multicast_to_the_dtim_beacon() {
        assert_eq!(Preset::Competition.link().beacon, None);
        assert_eq!(
            Preset::CompetitionPs.link().beacon,
            Some(Duration::from_micros(204_800)),
            "hostapd defaults: DTIM period 2 × 102.4 ms"
        );
        assert_eq!(
            LinkConfig {
                beacon: None,
                ..Preset::CompetitionPs.link()
            },
            Preset::Competition.link()
        );
    }
}
