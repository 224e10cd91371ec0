//! The sans-IO link model: `(now, packet size)` in, drop or delivery times out.

use std::collections::VecDeque;
use std::fmt;
use std::time::Duration;

use rand::RngExt;
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

use crate::burst::BurstChain;
use crate::impairment::{ConfigError, JitterDist, LinkConfig, UplinkConfig, PARETO_SHAPE};
use crate::seed::{self, Domain};
use crate::time::{duration_ns, Time};

/// Why a packet was not delivered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum DropReason {
    /// The link's independent loss.
    Loss,
    /// The link's Gilbert–Elliott channel (per receiver).
    Burst,
    /// The sender's uplink: independent loss shared by all receivers.
    UplinkLoss,
    /// The sender's uplink: bursty loss shared by all receivers.
    UplinkBurst,
    /// Tail drop: the link's queue was full.
    QueueFull,
    /// The two nodes were partitioned when it was sent or when it would have arrived.
    Partition,
}

impl DropReason {
    /// Every reason, in a fixed order (the index used by [`crate::LinkStats`]).
    pub const ALL: [DropReason; 6] = [
        DropReason::Loss,
        DropReason::Burst,
        DropReason::UplinkLoss,
        DropReason::UplinkBurst,
        DropReason::QueueFull,
        DropReason::Partition,
    ];

    pub(crate) fn index(self) -> usize {
        self as usize
    }

    /// A short lowercase name, as used in traces.
    pub fn name(self) -> &'static str {
        match self {
            DropReason::Loss => "loss",
            DropReason::Burst => "burst",
            DropReason::UplinkLoss => "uplink-loss",
            DropReason::UplinkBurst => "uplink-burst",
            DropReason::QueueFull => "queue-full",
            DropReason::Partition => "partition",
        }
    }
}

impl fmt::Display for DropReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What the link decided for one packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Lost.
    Drop(DropReason),
    /// Delivered at `at`, and a second copy at `duplicate_at` if duplicated.
    Deliver {
        /// Arrival time of the packet.
        at: Time,
        /// Arrival time of the duplicate, if any (may be before `at`).
        duplicate_at: Option<Time>,
    },
}

impl Verdict {
    /// Every arrival time (zero, one or two of them).
    pub fn delivery_times(&self) -> impl Iterator<Item = Time> {
        let (first, second) = match *self {
            Verdict::Drop(_) => (None, None),
            Verdict::Deliver { at, duplicate_at } => (Some(at), duplicate_at),
        };
        first.into_iter().chain(second)
    }
}

/// One one-way link's impairments with their state: a seeded random stream, the
/// Gilbert–Elliott channel and the bandwidth queue.
///
/// Sans-IO: it never reads a clock, it is told `now`. The simulator owns one per link; a
/// real-socket driver can own one too and hold each datagram until the returned times:
///
/// ```
/// use netsim::{LinkModel, Time, Verdict};
/// let config = "loss=20%,delay=50ms,jitter=20ms".parse().expect("valid spec");
/// let mut link = LinkModel::new(config, 42).expect("valid config");
/// // `now` is the driver's time since it started, as a netsim Time.
/// match link.transmit(Time::from_millis(3), 200) {
///     Verdict::Drop(reason) => println!("dropped: {reason}"),
///     Verdict::Deliver { at, duplicate_at } => {
///         assert!(at >= Time::from_millis(33) && at <= Time::from_millis(73));
///         assert!(duplicate_at.is_none(), "no dup= in the spec");
///     }
/// }
/// ```
#[derive(Debug, Clone)]
pub struct LinkModel {
    config: LinkConfig,
    rng: ChaCha8Rng,
    burst: Option<BurstChain>,
    /// Finish times of packets accepted by the rate limiter and not yet serialised.
    queue: VecDeque<Time>,
}

impl LinkModel {
    /// A link with its own random stream from `seed`.
    pub fn new(config: LinkConfig, seed: u64) -> Result<LinkModel, ConfigError> {
        LinkModel::with_rng(config, seed::stream(seed, Domain::Standalone, 0, 0))
    }

    pub(crate) fn with_rng(config: LinkConfig, rng: ChaCha8Rng) -> Result<LinkModel, ConfigError> {
        config.validate()?;
        Ok(LinkModel {
            burst: config.burst.map(BurstChain::new),
            config,
            rng,
            queue: VecDeque::new(),
        })
    }

    /// The configuration in force.
    pub fn config(&self) -> &LinkConfig {
        &self.config
    }

    /// Retunes the link. Its random stream, queue and (if the burst parameters are
    /// unchanged) burst state carry on.
    pub fn set_config(&mut self, config: LinkConfig) -> Result<(), ConfigError> {
        config.validate()?;
        if self.burst.as_ref().map(|b| *b.params()) != config.burst {
            self.burst = config.burst.map(BurstChain::new);
        }
        self.config = config;
        Ok(())
    }

    /// Packets waiting for (or on) the wire at `now`.
    pub fn queue_len(&self, now: Time) -> usize {
        self.queue.iter().filter(|&&finish| finish > now).count()
    }

    /// Decides the fate of a unicast packet of `size_bytes` sent at `now`.
    /// `now` must not go backwards between calls.
    pub fn transmit(&mut self, now: Time, size_bytes: usize) -> Verdict {
        self.decide(now, size_bytes, false)
    }

    /// As [`LinkModel::transmit`] for a multicast packet: arrivals are also held to the
    /// next beacon, if the link has one.
    pub fn transmit_multicast(&mut self, now: Time, size_bytes: usize) -> Verdict {
        self.decide(now, size_bytes, true)
    }

    fn decide(&mut self, now: Time, size_bytes: usize, multicast: bool) -> Verdict {
        let on_wire_at = match self.serialise(now, size_bytes) {
            Some(finish) => finish,
            None => return Verdict::Drop(DropReason::QueueFull),
        };
        if let Some(burst) = &mut self.burst {
            let p = burst.loss_at(now, &mut self.rng);
            if p > 0.0 && self.rng.random::<f64>() < p {
                return Verdict::Drop(DropReason::Burst);
            }
        }
        if self.config.loss > 0.0 && self.rng.random::<f64>() < self.config.loss {
            return Verdict::Drop(DropReason::Loss);
        }
        let at = self.arrival(on_wire_at, multicast);
        let duplicate_at = (self.config.duplicate > 0.0
            && self.rng.random::<f64>() < self.config.duplicate)
            .then(|| self.arrival(on_wire_at, multicast));
        Verdict::Deliver { at, duplicate_at }
    }

    /// Bandwidth: when the packet has left the wire, or `None` for a tail drop.
    fn serialise(&mut self, now: Time, size_bytes: usize) -> Option<Time> {
        let Some(rate_bps) = self.config.rate_bps else {
            return Some(now);
        };
        while self.queue.front().is_some_and(|&finish| finish <= now) {
            self.queue.pop_front();
        }
        if self.queue.len() >= self.config.queue_limit {
            return None;
        }
        let start = self.queue.back().copied().unwrap_or(now).max(now);
        let bits = u128::try_from(size_bytes)
            .unwrap_or(u128::MAX)
            .saturating_mul(8);
        // Round up: a packet is not on the far side until its last bit is.
        let ns = (bits * 1_000_000_000).div_ceil(u128::from(rate_bps));
        let finish = start + Duration::from_nanos(u64::try_from(ns).unwrap_or(u64::MAX));
        self.queue.push_back(finish);
        Some(finish)
    }

    fn arrival(&mut self, on_wire_at: Time, multicast: bool) -> Time {
        let reordered = self.config.reorder > 0.0 && self.rng.random::<f64>() < self.config.reorder;
        let delay = if reordered {
            Duration::ZERO
        } else {
            self.delay()
        };
        let at = on_wire_at + delay;
        match self.config.beacon {
            Some(beacon) if multicast => hold_to_beacon(at, beacon),
            _ => at,
        }
    }

    fn delay(&mut self) -> Duration {
        let latency_ns = duration_ns(self.config.latency) as f64;
        let jitter_ns = duration_ns(self.config.jitter) as f64;
        if jitter_ns == 0.0 {
            return self.config.latency;
        }
        let ns = match self.config.jitter_dist {
            JitterDist::Uniform => {
                latency_ns - jitter_ns + 2.0 * jitter_ns * self.rng.random::<f64>()
            }
            JitterDist::Normal => {
                let z: f64 = self.rng.sample(StandardNormal);
                latency_ns + jitter_ns * z
            }
            JitterDist::Pareto => {
                let u: f64 = self.rng.random();
                latency_ns + jitter_ns * ((1.0 - u).powf(-1.0 / PARETO_SHAPE) - 1.0)
            }
        };
        // A packet cannot arrive before it was sent: clip at zero, as netem does.
        Duration::from_nanos(if ns > 0.0 { ns.round() as u64 } else { 0 })
    }
}

/// Rounds `at` up to the next multiple of `beacon` since time zero.
fn hold_to_beacon(at: Time, beacon: Duration) -> Time {
    let b = duration_ns(beacon).max(1);
    Time::from_nanos(at.as_nanos().div_ceil(b).saturating_mul(b))
}

/// The sender's shared uplink stage.
#[derive(Debug, Clone)]
pub(crate) struct Uplink {
    config: UplinkConfig,
    rng: ChaCha8Rng,
    burst: Option<BurstChain>,
}

impl Uplink {
    pub(crate) fn new(config: UplinkConfig, rng: ChaCha8Rng) -> Result<Uplink, ConfigError> {
        config.validate()?;
        Ok(Uplink {
            burst: config.burst.map(BurstChain::new),
            config,
            rng,
        })
    }

    pub(crate) fn set_config(&mut self, config: UplinkConfig) -> Result<(), ConfigError> {
        config.validate()?;
        if self.burst.as_ref().map(|b| *b.params()) != config.burst {
            self.burst = config.burst.map(BurstChain::new);
        }
        self.config = config;
        Ok(())
    }

    /// `Err(reason)` if the transmission is lost for every receiver.
    pub(crate) fn transmit(&mut self, now: Time) -> Result<(), DropReason> {
        if let Some(burst) = &mut self.burst {
            let p = burst.loss_at(now, &mut self.rng);
            if p > 0.0 && self.rng.random::<f64>() < p {
                return Err(DropReason::UplinkBurst);
            }
        }
        if self.config.loss > 0.0 && self.rng.random::<f64>() < self.config.loss {
            return Err(DropReason::UplinkLoss);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lossless(latency_ms: u64) -> LinkConfig {
        LinkConfig {
            latency: Duration::from_millis(latency_ms),
            ..LinkConfig::default()
        }
    }

    #[test]
    fn bandwidth_serialises_back_to_back_and_tail_drops_beyond_the_queue() {
        // 1 Mbit/s, 1250-byte packets: 10 ms each on the wire; 5 may wait.
        let config = LinkConfig {
            rate_bps: Some(1_000_000),
            queue_limit: 5,
            ..lossless(2)
        };
        let mut link = LinkModel::new(config, 1).unwrap();
        let verdicts: Vec<Verdict> = (0..8).map(|_| link.transmit(Time::ZERO, 1250)).collect();
        for (i, v) in verdicts.iter().take(5).enumerate() {
            let expected = Time::from_millis(10 * (i as u64 + 1) + 2);
            assert_eq!(
                *v,
                Verdict::Deliver {
                    at: expected,
                    duplicate_at: None
                },
                "packet {i}: serialisation 10 ms each, back to back, plus 2 ms latency"
            );
        }
        for v in &verdicts[5..] {
            assert_eq!(
                *v,
                Verdict::Drop(DropReason::QueueFull),
                "queue of 5 is full"
            );
        }
        // At 25 ms two have left the wire: three wait, so two more fit, after the last.
        assert_eq!(link.queue_len(Time::from_millis(25)), 3);
        for expected_ms in [62, 72] {
            assert_eq!(
                link.transmit(Time::from_millis(25), 1250),
                Verdict::Deliver {
                    at: Time::from_millis(expected_ms),
                    duplicate_at: None
                }
            );
        }
        assert_eq!(
            link.transmit(Time::from_millis(25), 1250),
            Verdict::Drop(DropReason::QueueFull)
        );
        // An idle link starts serialising at once.
        assert_eq!(
            link.transmit(Time::from_secs(1), 125),
            Verdict::Deliver {
                at: Time::from_millis(1003),
                duplicate_at: None
            },
            "125 bytes at 1 Mbit/s take 1 ms"
        );
    }

    #[test]
    fn multicast_waits_for_the_next_beacon_but_unicast_does_not() {
        let config = LinkConfig {
            beacon: Some(Duration::from_micros(102_400)),
            ..lossless(50)
        };
        let mut link = LinkModel::new(config, 1).unwrap();
        assert_eq!(
            link.transmit_multicast(Time::from_millis(10), 100),
            Verdict::Deliver {
                at: Time::from_micros(102_400),
                duplicate_at: None
            }
        );
        assert_eq!(
            link.transmit_multicast(Time::from_millis(60), 100),
            Verdict::Deliver {
                at: Time::from_micros(204_800),
                duplicate_at: None
            },
            "arrives at 110 ms, held to the second beacon"
        );
        assert_eq!(
            link.transmit(Time::from_millis(60), 100),
            Verdict::Deliver {
                at: Time::from_millis(110),
                duplicate_at: None
            }
        );
    }

    #[test]
    fn reordered_packets_skip_the_delay_and_duplicates_get_their_own() {
        let config = LinkConfig {
            reorder: 1.0,
            duplicate: 1.0,
            ..lossless(30)
        };
        let mut link = LinkModel::new(config, 9).unwrap();
        assert_eq!(
            link.transmit(Time::from_millis(5), 10),
            Verdict::Deliver {
                at: Time::from_millis(5),
                duplicate_at: Some(Time::from_millis(5))
            }
        );
    }

    #[test]
    fn retuning_keeps_the_random_stream_going() {
        let spec: LinkConfig = "loss=50%".parse().unwrap();
        let mut a = LinkModel::new(spec.clone(), 3).unwrap();
        let mut b = LinkModel::new(spec.clone(), 3).unwrap();
        for i in 0..10 {
            assert_eq!(
                a.transmit(Time::from_millis(i), 1),
                b.transmit(Time::from_millis(i), 1)
            );
        }
        b.set_config(spec).unwrap();
        for i in 10..50 {
            assert_eq!(
                a.transmit(Time::from_millis(i), 1),
                b.transmit(Time::from_millis(i), 1),
                "setting the same config must not restart the stream"
            );
        }
    }
}
