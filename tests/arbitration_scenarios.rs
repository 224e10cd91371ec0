//! Should-I-go arbitration between robots that talk only through comms replicas over
//! netsim (the `huddle::harness`), with costs given by the scenario instead of a field:
//! the seed's example, a goer that dies, a robot that rejoins, and flapping.
//!
//! Each robot ticks at 25 Hz (ticks spread over the period), reads every
//! `+.var.machine.heuristic` copy from its own blackboard with receiver-side ages,
//! decides with `comms::arbitration::Arbiter`, and posts `[h, going]`. A sample every
//! 10 ms records who is going.

use std::time::Duration;

use comms::arbitration::{self, heuristic, Arbiter, ArbitrationParams, BallView};
use comms::ReplicaConfig;
use huddle::field::camera::standard_normal;
use huddle::harness::Harness;
use huddle::sim::{Metrics, NetworkConfig};
use netsim::{Sim, Time};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

const TICK: Duration = Duration::from_millis(40);
const SAMPLE: Duration = Duration::from_millis(10);
const REFRESH: Duration = Duration::from_millis(100);

/// A team of `n` robots deciding who goes, with costs from `cost(robot index, t_s)`.
struct Team {
    harness: Harness,
    arbiters: Vec<Arbiter>,
    params: ArbitrationParams,
    alive: Vec<bool>,
    next_tick: Vec<Duration>,
    now: Duration,
}

impl Team {
    fn new(n: usize, net: NetworkConfig, params: ArbitrationParams, seed: u64) -> Team {
        let (link, uplink) = net.links();
        let builder = Sim::builder().link(link).uplink(uplink);
        let replica = ReplicaConfig::new(1, 7).with_refresh_period(REFRESH);
        let mut harness = Harness::new(n, builder, replica, seed).expect("a valid team");
        harness.keep_events(false);
        Team {
            harness,
            arbiters: (0..n)
                .map(|i| Arbiter::new(i as u8 + 1, false, params))
                .collect(),
            params,
            alive: vec![true; n],
            next_tick: (0..n).map(|i| TICK * i as u32 / n as u32).collect(),
            now: Duration::ZERO,
        }
    }

    /// Run for `d`, calling `cost` at every tick; returns the goers at every sample.
    fn run(&mut self, d: Duration, mut cost: impl FnMut(usize, f64) -> f64) -> Vec<(f64, Vec<u8>)> {
        let end = self.now + d;
        let mut samples = Vec::new();
        while self.now < end {
            self.now += SAMPLE;
            self.harness
                .run_until(Time::from_nanos(self.now.as_nanos() as u64));
            for i in 0..self.arbiters.len() {
                if !self.alive[i] || self.next_tick[i] > self.now {
                    continue;
                }
                self.next_tick[i] += TICK;
                let local = self.harness.local_now(i);
                let board = self.harness.replica(i).expect("alive").blackboard();
                let heard = arbitration::heard(board, local);
                let (_, posted) =
                    self.arbiters[i].tick(TICK, cost(i, self.now.as_secs_f64()), &heard);
                self.harness
                    .set(i, &arbitration::heuristic_key(), posted.into())
                    .expect("own key");
            }
            self.harness.flush();
            let goers = (0..self.arbiters.len())
                .filter(|&i| self.alive[i] && self.arbiters[i].going())
                .map(|i| i as u8 + 1)
                .collect();
            samples.push((self.now.as_secs_f64(), goers));
        }
        samples
    }

    fn kill(&mut self, i: usize) {
        self.alive[i] = false;
        self.harness.kill(i);
    }

    fn restart(&mut self, i: usize) {
        self.harness.restart(i).expect("restart");
        self.arbiters[i] = Arbiter::new(i as u8 + 1, false, self.params);
        self.alive[i] = true;
        self.next_tick[i] = self.now + SAMPLE;
    }
}

fn net(loss: f64, latency_ms: u64) -> NetworkConfig {
    NetworkConfig::simple(
        loss,
        Duration::from_millis(latency_ms),
        Duration::from_millis(5),
    )
}

fn params_for(net: &NetworkConfig) -> ArbitrationParams {
    ArbitrationParams {
        latency_compensation: net.expected_delay(),
        ..ArbitrationParams::default()
    }
}

/// Longest run of samples matching `pred`, seconds.
fn longest(samples: &[(f64, Vec<u8>)], pred: impl Fn(&[u8]) -> bool) -> f64 {
    let (mut best, mut run) = (0.0f64, 0.0);
    for (_, g) in samples {
        if pred(g) {
            run += SAMPLE.as_secs_f64();
            best = best.max(run);
        } else {
            run = 0.0;
        }
    }
    best
}

#[test]
fn the_seeds_example_two_robots_equally_far_the_one_facing_the_goal_goes() {
    // isocrob-2000 §3.2.2: robots 1 and 2 are both 2 m from the ball; robot 2 faces the
    // opponent goal. Over a competition-grade network (20% loss, 50 ms).
    let net = net(0.2, 50);
    let p = params_for(&net);
    let h1 = heuristic(
        &p,
        Some(BallView {
            distance_m: 2.0,
            facing_opponent_goal: false,
        }),
    );
    let h2 = heuristic(
        &p,
        Some(BallView {
            distance_m: 2.0,
            facing_opponent_goal: true,
        }),
    );
    let mut team = Team::new(2, net, p, 11);
    let samples = team.run(Duration::from_secs(5), |i, _| if i == 0 { h1 } else { h2 });
    let settled: Vec<_> = samples.iter().filter(|(t, _)| *t > 1.0).collect();
    assert!(
        settled.iter().all(|(_, g)| g == &vec![2]),
        "after the first second only robot 2 may go; saw {:?}",
        settled.iter().find(|(_, g)| g != &vec![2])
    );
}

#[test]
fn a_goer_that_dies_is_replaced_within_the_silent_goer_limit() {
    // Three robots at 1.0, 1.5 and 2.0 m; robot 1 goes. At 5 s it dies (its replica
    // stops sending). Its last claim said it was going, and a silent goer is not taken
    // for one that gave up: the claim holds the ball for `silent_goer_after` (a burst
    // must not make two goers), counted from when its teammates received it. So the
    // replacement comes within one latency + that limit + one control tick, and not
    // before the normal staleness limit.
    let net = net(0.1, 50);
    let p = params_for(&net);
    let costs = [1.0, 1.5, 2.0];
    let mut team = Team::new(3, net, p, 12);
    let before = team.run(Duration::from_secs(5), |i, _| costs[i]);
    assert_eq!(
        before.last().map(|s| s.1.clone()),
        Some(vec![1]),
        "robot 1 is the goer"
    );
    team.kill(0);
    let after = team.run(Duration::from_secs(3), |i, _| costs[i]);
    let replaced_at = after
        .iter()
        .find(|(_, g)| g == &vec![2])
        .map(|(t, _)| t - 5.0)
        .expect("robot 2 must take over");
    let limit = (net.latency() + p.silent_goer_after + TICK + SAMPLE).as_secs_f64();
    eprintln!("dead goer replaced after {replaced_at:.3} s (limit {limit:.3} s)");
    assert!(
        replaced_at <= limit,
        "replaced after {replaced_at:.3} s, limit {limit:.3} s"
    );
    assert!(
        replaced_at > p.stale_after.as_secs_f64(),
        "replaced after {replaced_at:.3} s: a silent goer holds the ball past the staleness limit"
    );
    assert!(
        after.iter().all(|(_, g)| !g.contains(&3)),
        "robot 3 (the worst) never goes"
    );
    assert!(
        after
            .iter()
            .filter(|(t, _)| *t > 5.0 + limit)
            .all(|(_, g)| g == &vec![2]),
        "after the replacement robot 2 goes alone"
    );
}

#[test]
fn a_robot_that_rejoins_causes_no_double_go_beyond_one_refresh_period() {
    // Robot 1 (the best placed) dies and comes back with an empty blackboard. Coming
    // back worse placed, it must never claim; coming back best placed, it takes the ball
    // back with at most one refresh period of two goers.
    for (back_cost, story) in [(2.5, "worse placed"), (0.5, "best placed")] {
        let net = net(0.1, 50);
        let p = params_for(&net);
        let mut team = Team::new(3, net, p, 13);
        let costs = [1.0, 1.5, 2.0];
        team.run(Duration::from_secs(3), |i, _| costs[i]);
        team.kill(0);
        let gap = team.run(Duration::from_secs(2), |i, _| costs[i]);
        assert_eq!(
            gap.last().map(|s| s.1.clone()),
            Some(vec![2]),
            "{story}: robot 2 took over"
        );
        team.restart(0);
        let after = team.run(Duration::from_secs(3), |i, _| {
            if i == 0 {
                back_cost
            } else {
                costs[i]
            }
        });
        let double = longest(&after, |g| g.len() >= 2);
        eprintln!("rejoin {story}: longest double-go {double:.3} s");
        assert!(
            double <= REFRESH.as_secs_f64(),
            "{story}: two goers for {double:.3} s after the rejoin (limit one refresh period)"
        );
        let expected = if back_cost < 1.5 { vec![1] } else { vec![2] };
        assert_eq!(
            after.last().map(|s| s.1.clone()),
            Some(expected),
            "{story}: final goer"
        );
    }
}

/// Handovers per minute between two robots at nearly equal, noisy cost.
fn handovers_per_min(hysteresis_m: f64) -> (f64, f64) {
    let net = net(0.1, 50);
    let p = ArbitrationParams {
        hysteresis_m,
        ..params_for(&net)
    };
    let mut team = Team::new(2, net, p, 14);
    // 2.00 m and 2.05 m from the ball, raw camera noise at 2 m (σ = 2 cm + 5% = 12 cm),
    // unsmoothed: the worst case for flapping.
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    let samples = team.run(Duration::from_secs(120), |i, _| {
        2.0 + 0.05 * i as f64 + 0.12 * standard_normal(&mut rng)
    });
    let mut m = Metrics::default();
    for (t, g) in &samples {
        m.sample(*t, SAMPLE.as_secs_f64(), true, g);
    }
    (m.handovers_per_min(), m.exactly_one_pct())
}

#[test]
fn hysteresis_keeps_two_nearly_equal_robots_from_flapping() {
    // Stated bound: fewer than 2 handovers per minute with the default margin; with the
    // margin set to zero the same scenario breaks it (which is why the margin exists).
    const BOUND_PER_MIN: f64 = 2.0;
    let (with_margin, one_pct) = handovers_per_min(ArbitrationParams::default().hysteresis_m);
    assert!(
        with_margin < BOUND_PER_MIN,
        "{with_margin:.2} handovers/min with the default margin (bound {BOUND_PER_MIN})"
    );
    assert!(one_pct > 99.0, "and one goer {one_pct:.2}% of the time");
    let (without, _) = handovers_per_min(0.0);
    eprintln!("handovers/min: {with_margin:.2} with the margin, {without:.2} without");
    assert!(
        without > BOUND_PER_MIN,
        "with margin 0 the bound must fail, got {without:.2} handovers/min"
    );
}
