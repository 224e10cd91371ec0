//! Named network conditions: `lan`, `wlan`, `competition`.

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
    /// A crowded competition WLAN: 20% loss in all (bursts of 100 ms every ~1 s at the
    /// sender, shared by all receivers: 10%; plus 11.1% independent per receiver),
    /// 50 ms ± 20 ms (normal), 6 Mbit/s (the multicast basic rate), and multicast held by
    /// the access point until the next beacon (every 102.4 ms).
    Competition,
}

/// The standard 802.11 beacon interval: 100 time units of 1024 µs.
pub const BEACON_INTERVAL: Duration = Duration::from_micros(102_400);

impl Preset {
    /// Every preset.
    pub const ALL: [Preset; 3] = [Preset::Lan, Preset::Wlan, Preset::Competition];

    /// The spec-string name.
    pub fn name(self) -> &'static str {
        match self {
            Preset::Lan => "lan",
            Preset::Wlan => "wlan",
            Preset::Competition => "competition",
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
                latency: Duration::from_millis(50),
                jitter: Duration::from_millis(20),
                jitter_dist: JitterDist::Normal,
                // With the uplink's 10%: 1 − 0.9 · (1 − 1/9) = 20% in all.
                loss: 1.0 / 9.0,
                rate_bps: Some(6_000_000),
                queue_limit: 64,
                beacon: Some(BEACON_INTERVAL),
                ..LinkConfig::default()
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
            Preset::Competition => UplinkConfig {
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
        for p in Preset::ALL {
            p.link().validate().unwrap();
            p.uplink().validate().unwrap();
            assert_eq!(p.name().parse::<Preset>().unwrap(), p);
        }
    }
}
