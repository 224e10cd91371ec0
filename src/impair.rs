//! netsim's link model on a real daemon's socket: `huddle daemon --impair SPEC`.
//!
//! [`LinkImpairment`] implements `driver::Impairment` with netsim's standalone
//! [`LinkModel`]: the driver hands it every outgoing datagram, it answers when each copy
//! should go on the socket (or that the datagram is lost), and the driver holds the
//! copies with tokio timers. The spec is netsim's (`loss=20%,delay=50ms,jitter=20ms`,
//! `preset=competition`, see `netsim::spec`); the seed makes the model's draws
//! repeatable (the wall-clock instants they are applied at are not). Multicast
//! datagrams go through `transmit_multicast` (held to beacons if the spec has them);
//! each destination address gets its own random stream, derived from the seed and the
//! address, so a `--peer`'s unicast copies fare independently of the group's.

use std::collections::BTreeMap;
use std::net::SocketAddr;

use comms::Instant;
use driver::Impairment;
use netsim::{ConfigError, LinkConfig, LinkModel, Time};

/// netsim's link model, one stream per destination.
#[derive(Debug)]
pub struct LinkImpairment {
    config: LinkConfig,
    seed: u64,
    links: BTreeMap<SocketAddr, LinkModel>,
}

impl LinkImpairment {
    /// A model for `config` (validated here) with draws from `seed`.
    pub fn new(config: LinkConfig, seed: u64) -> Result<LinkImpairment, ConfigError> {
        LinkModel::new(config.clone(), seed)?;
        Ok(LinkImpairment {
            config,
            seed,
            links: BTreeMap::new(),
        })
    }

    /// The configuration in force.
    pub fn config(&self) -> &LinkConfig {
        &self.config
    }

    fn link(&mut self, to: SocketAddr) -> &mut LinkModel {
        let (config, seed) = (&self.config, self.seed);
        self.links.entry(to).or_insert_with(|| {
            let model = LinkModel::new(config.clone(), seed ^ address_hash(to));
            model.expect("validated in new")
        })
    }
}

/// FNV-1a of the address text: a stable, seed-independent stream id per destination.
fn address_hash(to: SocketAddr) -> u64 {
    to.to_string().bytes().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3)
    })
}

impl Impairment for LinkImpairment {
    fn judge(&mut self, now: Instant, to: SocketAddr, len: usize, copies: &mut Vec<Instant>) {
        let at = Time::from_micros(now.as_micros());
        let link = self.link(to);
        let verdict = if to.ip().is_multicast() {
            link.transmit_multicast(at, len)
        } else {
            link.transmit(at, len)
        };
        // Round up to the next microsecond: a copy never leaves before its time.
        copies.extend(
            verdict
                .delivery_times()
                .map(|t| Instant::from_micros(t.as_nanos().div_ceil(1000))),
        );
    }
}

/// A WLAN outage rehearsed on a real daemon (`huddle daemon --outage DURATION@START`):
/// every outgoing datagram is lost from START to START + DURATION after the daemon's
/// start, and the rest go through `inner` (`--impair`) or straight out. With every robot
/// given the same outage, the team's radio is silent both ways, as in `huddle sim
/// --outage`.
#[derive(Debug)]
pub struct Outage {
    inner: Option<LinkImpairment>,
    start: std::time::Duration,
    duration: std::time::Duration,
    /// The daemon's start, on the driver's clock.
    origin: Instant,
}

impl Outage {
    /// An outage of `duration` from `start` after `origin` (the daemon's start on the
    /// driver's clock), around `inner`. Counted from the start, not from the first
    /// datagram: robots started together go silent together, whenever each first sends.
    pub fn new(
        inner: Option<LinkImpairment>,
        duration: std::time::Duration,
        start: std::time::Duration,
        origin: Instant,
    ) -> Outage {
        Outage {
            inner,
            start,
            duration,
            origin,
        }
    }
}

impl Impairment for Outage {
    fn judge(&mut self, now: Instant, to: SocketAddr, len: usize, copies: &mut Vec<Instant>) {
        let since = now.saturating_duration_since(self.origin);
        if since >= self.start && since < self.start + self.duration {
            // Lost: the driver counts it (`io.impair_dropped`).
            return;
        }
        match &mut self.inner {
            Some(model) => model.judge(now, to, len, copies),
            None => copies.push(now),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn group() -> SocketAddr {
        "239.255.1.1:2000".parse().unwrap()
    }

    #[test]
    fn the_spec_decides_loss_and_delay_and_the_seed_replays_it() {
        let config: LinkConfig = "loss=20%,delay=50ms,jitter=20ms".parse().unwrap();
        let run = |seed| {
            let mut m = LinkImpairment::new(config.clone(), seed).unwrap();
            let mut out = Vec::new();
            for k in 0..2000u64 {
                let now = Instant::from_micros(k * 1000);
                let mut copies = Vec::new();
                m.judge(now, group(), 60, &mut copies);
                assert!(copies.len() <= 1, "no duplication in the spec");
                out.push(copies.first().map(|t| t.as_micros() - now.as_micros()));
            }
            out
        };
        let a = run(1);
        assert_eq!(a, run(1), "same seed, same fates");
        assert_ne!(a, run(2), "another seed, other fates");
        let lost = a.iter().filter(|d| d.is_none()).count();
        // 99.9% binomial bound for 2000 draws at 20%: ± 3.29 σ = ± 59.
        assert!((341..=459).contains(&lost), "{lost} of 2000 lost");
        let delays: Vec<u64> = a.iter().flatten().copied().collect();
        let mean_ms = delays.iter().sum::<u64>() as f64 / delays.len() as f64 / 1000.0;
        assert!((mean_ms - 50.0).abs() < 2.0, "mean delay {mean_ms} ms");
    }

    #[test]
    fn an_outage_loses_every_datagram_inside_its_window_and_nothing_outside() {
        let mut m = Outage::new(
            None,
            std::time::Duration::from_secs(2),
            std::time::Duration::from_secs(5),
            Instant::from_micros(100_000_000),
        );
        // The daemon starts at 100 s on its clock; a datagram every 100 ms for 10 s.
        let mut fates = Vec::new();
        for k in 0..100u64 {
            let now = Instant::from_micros(100_000_000 + k * 100_000);
            let mut copies = Vec::new();
            m.judge(now, group(), 60, &mut copies);
            fates.push((k, copies));
        }
        for (k, copies) in &fates {
            let inside = (50..70).contains(k);
            assert_eq!(
                copies.is_empty(),
                inside,
                "datagram {k} ({} s after start): lost only inside 5–7 s",
                *k as f64 / 10.0
            );
            if !inside {
                assert_eq!(copies.len(), 1, "outside, it leaves at once");
            }
        }
        let lost = fates.iter().filter(|(_, c)| c.is_empty()).count();
        assert_eq!(lost, 20, "20 datagrams in the 2 s window");
        // Counted from the daemon's start, not its first datagram: a daemon that first
        // sends 4.9 s after it started still goes silent 5 s after it started.
        let mut late = Outage::new(
            None,
            std::time::Duration::from_secs(2),
            std::time::Duration::from_secs(5),
            Instant::from_micros(100_000_000),
        );
        for (at_us, lost) in [
            (104_900_000, false),
            (105_000_000, true),
            (107_000_000, false),
        ] {
            let mut copies = Vec::new();
            late.judge(Instant::from_micros(at_us), group(), 60, &mut copies);
            assert_eq!(copies.is_empty(), lost, "datagram at {at_us} µs");
        }
    }

    #[test]
    fn each_destination_has_its_own_stream() {
        let config: LinkConfig = "loss=50%".parse().unwrap();
        let mut m = LinkImpairment::new(config, 3).unwrap();
        let peer: SocketAddr = "127.0.0.1:2000".parse().unwrap();
        let (mut g, mut p) = (Vec::new(), Vec::new());
        for k in 0..200 {
            let now = Instant::from_micros(k);
            let (mut cg, mut cp) = (Vec::new(), Vec::new());
            m.judge(now, group(), 60, &mut cg);
            m.judge(now, peer, 60, &mut cp);
            g.push(cg.is_empty());
            p.push(cp.is_empty());
        }
        assert_ne!(g, p, "the group's and the peer's losses are independent");
    }
}
