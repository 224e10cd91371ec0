//! The whole team on the simulated field, over a grid of network conditions: loss
//! {0, 10, 30%} × latency {0, 50, 150 ms} (independent loss, 5 ms jitter), 90 s of play
//! each, seed 1. Definitions of "ball visible" and "goer" are in `huddle::sim::metrics`.
//!
//! Claims checked in every cell:
//! - exactly one goer for ≥ 99% of ball-visible time at ≤ 10% loss and ≤ 50 ms, and
//!   ≥ 95% everywhere else (the issue asks it at 30% and 150 ms);
//! - never two goers for longer than latency + two refresh periods.

use std::time::Duration;

use huddle::sim::{NetworkConfig, Report, SimConfig, Simulation};

fn play(loss: f64, latency_ms: u64, seed: u64, duration_s: f64) -> Report {
    let cfg = SimConfig {
        duration_s,
        seed,
        network: NetworkConfig::simple(
            loss,
            Duration::from_millis(latency_ms),
            Duration::from_millis(5),
        ),
        ..SimConfig::default()
    };
    let mut sim = Simulation::new(cfg).expect("a valid configuration");
    sim.run(|_| {});
    sim.report(0.0)
}

#[test]
fn exactly_one_goer_across_the_loss_latency_grid() {
    let mut failures = Vec::new();
    for loss in [0.0, 0.1, 0.3] {
        for latency_ms in [0, 50, 150] {
            let r = play(loss, latency_ms, 1, 90.0);
            let need = if loss <= 0.1 && latency_ms <= 50 {
                99.0
            } else {
                95.0
            };
            eprintln!(
                "loss {:>3.0}% latency {latency_ms:>3} ms: one goer {:.2}% (need {need}), conflict {:.2}%, none {:.2}%, longest conflict {:.0}/{:.0} ms, handovers {:.1}/min, flaps {:.1}/min, ball visible {:.1} s",
                loss * 100.0, r.exactly_one_goer_pct, r.conflict_pct, r.no_goer_pct,
                r.longest_conflict_ms, r.conflict_bound_ms, r.handovers_per_min, r.flaps_per_min, r.ball_visible_s
            );
            assert!(r.ball_visible_s > 45.0, "the ball must be in play: {r:?}");
            if r.exactly_one_goer_pct < need {
                failures.push(format!(
                    "loss {loss}, {latency_ms} ms: exactly one goer {:.2}% < {need}%",
                    r.exactly_one_goer_pct
                ));
            }
            if r.longest_conflict_ms > r.conflict_bound_ms {
                failures.push(format!(
                    "loss {loss}, {latency_ms} ms: two goers for {:.0} ms > bound {:.0} ms (at {:.1} s)",
                    r.longest_conflict_ms, r.conflict_bound_ms, r.longest_conflict_at_s
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn the_same_seed_gives_the_same_report_and_another_seed_another() {
    let a = play(0.2, 50, 5, 20.0);
    let b = play(0.2, 50, 5, 20.0);
    let c = play(0.2, 50, 6, 20.0);
    assert_eq!(a, b, "same seed, same match");
    assert_ne!(a, c, "another seed, another match");
}
