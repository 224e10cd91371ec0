//! Honesty: over ≥ 100,000 packets, the link model does what its configuration says.
//!
//! Every tolerance is derived from the sample size at a 99.9% (or stricter) level, so a
//! correct model fails at most once in a thousand seeds, and these seeds are fixed.

use std::time::Duration;

use netsim::{
    Dest, DropReason, GilbertElliott, JitterDist, LinkConfig, LinkModel, Preset, Sim, Time,
    TraceKind, UplinkConfig, Verdict,
};

/// Two-sided 99.9% normal quantile.
const Z_999: f64 = 3.2905;

/// Sends `n` packets `interval` apart; returns each verdict.
fn run_link(config: LinkConfig, seed: u64, n: usize, interval: Duration) -> Vec<Verdict> {
    let mut link = LinkModel::new(config, seed).expect("valid config");
    let mut now = Time::ZERO;
    (0..n)
        .map(|_| {
            now += interval;
            link.transmit(now, 200)
        })
        .collect()
}

#[test]
fn independent_loss_lies_within_the_binomial_bound() {
    for (seed, p) in [(1, 0.01), (2, 0.2), (3, 0.5)] {
        let n = 200_000;
        let config = LinkConfig {
            loss: p,
            ..LinkConfig::default()
        };
        let lost = run_link(config, seed, n, Duration::from_millis(1))
            .iter()
            .filter(|v| matches!(v, Verdict::Drop(DropReason::Loss)))
            .count() as f64;
        let expected = n as f64 * p;
        let bound = Z_999 * (n as f64 * p * (1.0 - p)).sqrt();
        assert!(
            (lost - expected).abs() <= bound,
            "loss={p}, seed {seed}: lost {lost} of {n}, expected {expected} ± {bound:.0}"
        );
    }
}

/// Standard normal CDF via erf (Abramowitz & Stegun 7.1.26, |error| < 1.5e-7).
fn phi(x: f64) -> f64 {
    let z = x / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * z.abs());
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let erf = 1.0 - poly * (-z * z).exp();
    0.5 * (1.0 + if z >= 0.0 { erf } else { -erf })
}

/// A CDF of a delay in milliseconds.
type Cdf = Box<dyn Fn(f64) -> f64>;

/// Kolmogorov–Smirnov distance between samples and a CDF that may have an atom at 0
/// (the clipped normal puts the mass of negative delays there).
fn ks_distance(mut samples_ms: Vec<f64>, cdf: impl Fn(f64) -> f64, atom_at_zero: bool) -> f64 {
    samples_ms.sort_by(f64::total_cmp);
    let n = samples_ms.len() as f64;
    let mut d: f64 = 0.0;
    let mut i = 0;
    while i < samples_ms.len() {
        let v = samples_ms[i];
        let mut j = i;
        while j < samples_ms.len() && samples_ms[j] == v {
            j += 1;
        }
        let below = if atom_at_zero && v == 0.0 {
            0.0
        } else {
            cdf(v)
        };
        d = d
            .max((i as f64 / n - below).abs())
            .max((j as f64 / n - cdf(v)).abs());
        i = j;
    }
    d
}

/// The 99.9% critical value of the one-sample KS statistic, `sqrt(−ln(α/2)/2) / √n`.
fn ks_critical(n: usize) -> f64 {
    (-(0.001f64 / 2.0).ln() / 2.0).sqrt() / (n as f64).sqrt()
}

#[test]
fn delivered_delays_follow_the_configured_distribution_with_loss_and_bursts_on() {
    let latency_ms = 50.0;
    let jitter_ms = 20.0;
    let cases: [(JitterDist, Cdf, bool); 3] = [
        (
            JitterDist::Uniform,
            Box::new(move |x| ((x - (latency_ms - jitter_ms)) / (2.0 * jitter_ms)).clamp(0.0, 1.0)),
            false,
        ),
        (
            JitterDist::Normal,
            Box::new(move |x| phi((x - latency_ms) / jitter_ms)),
            true,
        ),
        (
            JitterDist::Pareto,
            Box::new(move |x| {
                if x < latency_ms {
                    0.0
                } else {
                    1.0 - (1.0 + (x - latency_ms) / jitter_ms).powf(-netsim::PARETO_SHAPE)
                }
            }),
            false,
        ),
    ];
    for (seed, (dist, cdf, atom)) in cases.into_iter().enumerate() {
        let config: LinkConfig = format!(
            "delay=50ms,jitter=20ms,dist={},loss=20%,burst-good=500ms,burst-bad=50ms",
            dist.name()
        )
        .parse()
        .unwrap();
        let verdicts = run_link(config, seed as u64, 150_000, Duration::from_millis(2));
        let delays_ms: Vec<f64> = verdicts
            .iter()
            .enumerate()
            .filter_map(|(i, v)| match v {
                Verdict::Deliver { at, .. } => {
                    let sent = Time::from_millis(2 * (i as u64 + 1));
                    Some((*at - sent).as_secs_f64() * 1e3)
                }
                Verdict::Drop(_) => None,
            })
            .collect();
        let n = delays_ms.len();
        assert!(n > 100_000, "{dist:?}: {n} delivered of 150,000");
        let d = ks_distance(delays_ms, cdf, atom);
        assert!(
            d < ks_critical(n),
            "{dist:?}: KS distance {d:.5} over {n} delivered packets exceeds the 99.9% critical value {:.5}",
            ks_critical(n)
        );
    }
}

/// Mean length (in packets) of runs of `true`, and of runs of `false`.
fn mean_runs(lost: &[bool]) -> (f64, f64, usize) {
    let (mut runs, mut lens) = ([0usize; 2], [0usize; 2]);
    for (i, &l) in lost.iter().enumerate() {
        lens[usize::from(l)] += 1;
        if i == 0 || lost[i - 1] != l {
            runs[usize::from(l)] += 1;
        }
    }
    (
        lens[1] as f64 / runs[1] as f64,
        lens[0] as f64 / runs[0] as f64,
        runs[1].min(runs[0]),
    )
}

#[test]
fn gilbert_elliott_loss_bursts_and_gaps_match_the_continuous_time_chain_at_any_send_rate() {
    // Total loss in 20 ms bursts, 200 ms apart on average.
    let ge = GilbertElliott {
        mean_good: Duration::from_millis(200),
        mean_bad: Duration::from_millis(20),
        loss_good: 0.0,
        loss_bad: 1.0,
    };
    let (mg, mb) = (0.2, 0.02);
    let pi_bad = ge.bad_fraction();
    let rate_sum = 1.0 / mg + 1.0 / mb;
    let mut estimated_mean_bad_s = Vec::new();
    for (seed, interval_ms, n) in [(11, 1u64, 1_000_000usize), (12, 10, 400_000)] {
        let tau = interval_ms as f64 * 1e-3;
        let config = LinkConfig {
            burst: Some(ge),
            ..LinkConfig::default()
        };
        let lost: Vec<bool> = run_link(config, seed, n, Duration::from_millis(interval_ms))
            .iter()
            .map(|v| matches!(v, Verdict::Drop(_)))
            .collect();

        // Mean loss: samples of a stationary two-state chain, correlation ρ = e^{−(λ+μ)τ}.
        let rho = (-rate_sum * tau).exp();
        let measured = lost.iter().filter(|&&l| l).count() as f64 / n as f64;
        let sd = (pi_bad * (1.0 - pi_bad) / n as f64 * (1.0 + rho) / (1.0 - rho)).sqrt();
        assert!(
            (measured - ge.mean_loss()).abs() < 4.5 * sd,
            "every {interval_ms} ms: mean loss {measured:.5}, theory {:.5} ± {:.5}",
            ge.mean_loss(),
            4.5 * sd
        );

        // Runs seen by packets τ apart: P(stay bad) = π_b + π_g·ρ, P(stay good) = π_g + π_b·ρ.
        let (burst, gap, runs) = mean_runs(&lost);
        let burst_theory = 1.0 / (1.0 - (pi_bad + (1.0 - pi_bad) * rho));
        let gap_theory = 1.0 / (1.0 - ((1.0 - pi_bad) + pi_bad * rho));
        let rel_tol = 5.0 / (runs as f64).sqrt();
        assert!(
            (burst / burst_theory - 1.0).abs() < rel_tol,
            "every {interval_ms} ms: mean burst {burst:.3} packets, theory {burst_theory:.3} (±{:.1}%)",
            rel_tol * 100.0
        );
        assert!(
            (gap / gap_theory - 1.0).abs() < rel_tol,
            "every {interval_ms} ms: mean gap {gap:.3} packets, theory {gap_theory:.3} (±{:.1}%)",
            rel_tol * 100.0
        );

        // Invert the runs back to the chain's mean burst duration: it must not depend on τ.
        let stay_bad = 1.0 - 1.0 / burst;
        let rho_hat = (stay_bad - measured) / (1.0 - measured);
        let rate_sum_hat = -rho_hat.ln() / tau;
        estimated_mean_bad_s.push(1.0 / (rate_sum_hat * (1.0 - measured)));
    }
    for (rate, mean_bad_s) in ["1 kHz", "100 Hz"].iter().zip(&estimated_mean_bad_s) {
        assert!(
            (mean_bad_s / mb - 1.0).abs() < 0.1,
            "at {rate} the bursts last {:.2} ms on average, configured 20 ms",
            mean_bad_s * 1e3
        );
    }
}

#[test]
fn multicast_loss_is_shared_by_receivers_of_one_transmission_plus_a_private_part() {
    // Uplink 10% (shared), each link 10% (private): each receiver loses 19%, and all four
    // lose the same transmission with probability 0.1 + 0.9·0.1⁴ (it would be 0.19⁴ ≈
    // 0.0013 if the losses were independent).
    let mut sim = Sim::builder()
        .seed(5)
        .link("loss=10%".parse().unwrap())
        .uplink(UplinkConfig {
            loss: 0.1,
            burst: None,
        })
        .build()
        .unwrap();
    let nodes = sim.add_nodes(5);
    let team = sim.add_group(&nodes).unwrap();
    let n = 100_000u64;
    for i in 0..n {
        sim.send_at(
            Time::from_millis(i),
            nodes[0],
            Dest::Group(team),
            vec![0u8; 10],
        )
        .unwrap();
    }
    sim.run_until(Time::from_secs(n / 1000 + 1));
    let mut lost_per_tx = vec![0u8; n as usize];
    for event in sim.trace().events() {
        if let TraceKind::Drop { tx, .. } = event.kind {
            lost_per_tx[tx as usize] += 1;
        }
    }
    let all_lost = lost_per_tx.iter().filter(|&&k| k == 4).count() as f64;
    let p_all = 0.1 + 0.9 * 0.1f64.powi(4);
    let bound = Z_999 * (n as f64 * p_all * (1.0 - p_all)).sqrt();
    assert!(
        (all_lost - n as f64 * p_all).abs() <= bound,
        "{all_lost} transmissions lost by all four receivers, expected {:.0} ± {bound:.0}",
        n as f64 * p_all
    );
    for &r in &nodes[1..] {
        let s = sim.link_stats(nodes[0], r).unwrap();
        let p = 0.19;
        let bound = Z_999 * (n as f64 * p * (1.0 - p)).sqrt();
        assert!(
            (s.lost_total() as f64 - n as f64 * p).abs() <= bound,
            "receiver {r}: lost {} of {n}, expected {:.0} ± {bound:.0}",
            s.lost_total(),
            n as f64 * p
        );
        assert_eq!(
            s.lost(DropReason::UplinkLoss) + s.lost(DropReason::Loss),
            s.lost_total()
        );
    }
    let own = sim.link_stats(nodes[0], nodes[0]).unwrap();
    assert_eq!(
        (own.sent, own.delivered),
        (n, n),
        "loopback copies are never lost"
    );
}

#[test]
fn the_power_save_competition_preset_loses_a_fifth_of_multicast_and_holds_it_to_dtim_beacons() {
    let mut sim = Sim::builder()
        .seed(8)
        .preset(Preset::CompetitionPs)
        .build()
        .unwrap();
    let nodes = sim.add_nodes(5);
    let team = sim.add_group(&nodes).unwrap();
    // 100,000 transmissions from robot 1 at 100 Hz: 1000 s of play.
    let n = 100_000u64;
    for i in 0..n {
        sim.send_at(
            Time::from_millis(10 * i),
            nodes[0],
            Dest::Group(team),
            vec![1u8; 200],
        )
        .unwrap();
        if i % 1000 == 999 {
            sim.run_until(Time::from_millis(10 * i));
            for &node in &nodes {
                sim.drain(node).for_each(drop);
            }
        }
    }
    sim.run_until(Time::from_secs(1100));
    let mut total = netsim::LinkStats::default();
    for &r in &nodes[1..] {
        total.merge(sim.link_stats(nodes[0], r).unwrap());
    }
    // The shared burst chain (900 ms good / 100 ms bad) dominates the variance: the time
    // average of its state over T seconds has variance 2·π_b·π_g / ((λ+μ)·T).
    let (pi_b, rate_sum, t_s) = (0.1, 1.0 / 0.9 + 1.0 / 0.1, n as f64 / 100.0);
    let sd_shared = (2.0 * pi_b * (1.0 - pi_b) / (rate_sum * t_s)).sqrt();
    let sd_private = (0.2 * 0.8 / (4.0 * n as f64)).sqrt();
    let tol = 4.5 * (sd_shared * sd_shared + sd_private * sd_private).sqrt();
    assert!(
        (total.loss_rate() - 0.2).abs() < tol,
        "competition multicast loss {:.4}, expected 0.2 ± {tol:.4}",
        total.loss_rate()
    );
    let beacon_ns = netsim::dtim_interval(netsim::DEFAULT_DTIM_PERIOD).as_nanos() as u64;
    for event in sim.trace().events() {
        if let TraceKind::Deliver { from, to, .. } = &event.kind {
            if from != to {
                assert_eq!(
                    event.at.as_nanos() % beacon_ns,
                    0,
                    "multicast held to a DTIM beacon"
                );
            }
        }
    }
}
