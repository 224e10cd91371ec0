//! Five robots on the `competition` WLAN (netsim preset: 20% loss with 100 ms bursts
//! shared by all receivers, 20 ms ± 10 ms; without loss, the power-save variant that
//! holds multicast to the next DTIM beacon),
//! replicating their blackboards through `huddle::harness`. Robot 4 is cut off
//! (`Sim::isolate`) from 1.0 s to 3.0 s while everybody keeps writing, and robot 4 and
//! robot 1 each post a talk message during the cut.
//!
//! **Converged** means: every replica holds exactly the same set of global bindings
//! `n.var.<path>` (every owner n, local keys excluded), with the same value **and** the
//! same version, as every other replica (hence as each owner's own copy). Writes stop at
//! the heal, so the target does not move; the test measures, with 1 ms resolution, the
//! time from the heal to the first instant at which the team has converged.
//!
//! What the network allows. The access point holds multicast to the next beacon (every
//! 102.4 ms from time zero), so arrivals come in lumps: the heal at 3.0 s is 72 ms before
//! a beacon, and convergence times can only be 72, 175, 277, 380, … ms. A refresh crosses
//! from one robot to another in a beacon wait (0–102.4 ms) plus 50 ± 20 ms, and the team
//! needs eight directions to cross (robot 4 → each of four robots, and back). Even with
//! **no loss** this takes up to one refresh period (the phase of the first refresh after
//! the heal) plus the worst crossing: ≈ 312 ms, i.e. the 277 ms beacon. "Within two
//! refresh periods" (200 ms, i.e. the 175 ms beacon) is therefore not guaranteed by the
//! preset even without loss, and with 20% loss it needs all eight directions to succeed
//! at the first attempt (0.8⁸ ≈ 17%), so most seeds miss it.
//!
//! A replica that hears a robot for the first time, again after it departed, or
//! restarted, queues a full refresh at once (an extra copy besides the periodic one), so
//! a lost attempt is repaired by the next without waiting a whole period. The test
//! asserts what the preset allows a correct protocol to guarantee:
//! - without loss, every seed converges within one refresh period plus the worst
//!   crossing (beacon + 50 ms + 3 × 20 ms);
//! - with the preset's loss, the median does too, the 90th percentile converges within
//!   two refresh periods plus the worst crossing (one lost attempt repaired by the next:
//!   the periodic refresh alone would miss this), and every seed within 1 s;
//! - each talk message posted during the cut reaches every other robot exactly once
//!   (never given up), on every seed.
//!
//! Run with `--nocapture` to see the measured distribution.

use std::collections::BTreeMap;
use std::time::Duration;

use comms::{Event, Key, Pattern, ReplicaConfig, Scope, Value};
use huddle::harness::Harness;
use huddle::summary::percentile;
use netsim::{Preset, Sim, Time};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const ROBOTS: usize = 5;
/// Robot 4, by index.
const CUT: usize = 3;
const REFRESH: Duration = Duration::from_millis(100);
const TICK: Duration = Duration::from_millis(40);
const ISOLATE_AT: Duration = Duration::from_secs(1);
const HEAL_AT: Duration = Duration::from_secs(3);
/// How long after the heal the run goes on (and the hard bound on convergence).
const AFTER_HEAL: Duration = Duration::from_secs(1);
const SEEDS: u64 = 100;
/// The slowest a multicast frame crosses the preset: a whole beacon interval, then
/// 50 ms + 3 × 20 ms.
const WORST_CROSSING: Duration = Duration::from_micros(102_400 + 110_000);

fn at(d: Duration) -> Time {
    Time::from_nanos(d.as_nanos() as u64)
}

/// Every global binding a replica holds: (owner, path) → (value, version).
type Snapshot = BTreeMap<(u8, String), (Value, u64)>;

fn snapshot(h: &Harness, i: usize) -> Snapshot {
    let all = Pattern::parse("+.var.#").expect("valid pattern");
    let r = h.replica(i).expect("nobody is switched off");
    r.iter(&all)
        .filter_map(|(key, e)| match key.scope() {
            Scope::Robot(owner) => {
                Some(((owner, key.path().to_owned()), (e.value.clone(), e.version)))
            }
            _ => None,
        })
        .collect()
}

fn converged(h: &Harness) -> bool {
    let first = snapshot(h, 0);
    (1..ROBOTS).all(|i| snapshot(h, i) == first)
}

/// What one seed did.
struct Outcome {
    /// Heal → first converged instant; `None` if not within [`AFTER_HEAL`].
    converged_after: Option<Duration>,
    /// (receiver index, sender id, message) → deliveries of the two partition messages.
    talk: BTreeMap<(usize, u8, String), usize>,
    given_up: usize,
}

fn collect(h: &mut Harness, out: &mut Outcome) {
    for i in 0..ROBOTS {
        for e in h.drain_events(i) {
            match e {
                Event::TalkDelivered { from, value, .. } => {
                    let text = match value {
                        Value::String(s) => s,
                        other => format!("{other:?}"),
                    };
                    *out.talk.entry((i, from, text)).or_default() += 1;
                }
                Event::TalkGivenUp { .. } => out.given_up += 1,
                _ => {}
            }
        }
    }
}

/// Real robots are switched on one by one, so their refresh timers are out of phase:
/// switch every robot off at zero and on again at a seeded instant within the first
/// refresh period (the harness starts every replica at zero, all in phase).
fn power_on_staggered(h: &mut Harness, seed: u64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut on: Vec<(Duration, usize)> = (0..ROBOTS)
        .map(|i| {
            h.kill(i);
            (Duration::from_micros(rng.random_range(0..100_000)), i)
        })
        .collect();
    on.sort();
    for (t, i) in on {
        h.run_until(at(t));
        h.restart(i).expect("a valid replica");
    }
    h.run_until(at(REFRESH));
}

fn run(seed: u64, preset_net: netsim::SimBuilder) -> Outcome {
    let replica = ReplicaConfig::new(1, 7).with_refresh_period(REFRESH);
    let mut h = Harness::new(ROBOTS, preset_net, replica, seed).expect("a valid team");
    power_on_staggered(&mut h, seed);
    let pose = Key::parse("*.var.pose").expect("valid key");
    let role = Key::parse("*.var.role").expect("valid key");
    for i in 0..ROBOTS {
        h.set(i, &role, Value::from("field")).expect("own key");
    }
    let cut = h.node(CUT);
    h.net_mut()
        .at(at(ISOLATE_AT), netsim::Action::Isolate(cut))
        .expect("a future action");
    h.net_mut()
        .at(at(HEAL_AT), netsim::Action::Heal)
        .expect("a future action");
    let mut out = Outcome {
        converged_after: None,
        talk: BTreeMap::new(),
        given_up: 0,
    };
    // Everybody writes its pose at 25 Hz until the heal; robot 4 also changes its role
    // and robots 4 and 1 post a talk message, all while robot 4 is cut off.
    let mut t = Duration::ZERO;
    let mut tick = 0u32;
    while t + TICK < HEAL_AT {
        t += TICK;
        tick += 1;
        h.run_until(at(t));
        for i in 0..ROBOTS {
            let v = Value::Floats(vec![i as f64, tick as f64 * 0.01]);
            h.set(i, &pose, v).expect("own key");
        }
        if t == Duration::from_millis(2000) {
            h.set(CUT, &role, Value::from("lost")).expect("own key");
            let now = h.local_now(CUT);
            h.replica_mut(CUT)
                .expect("alive")
                .post(now, "*.talk.plan", Value::from("from 4 in the dark"))
                .expect("own queue");
            let now = h.local_now(0);
            h.replica_mut(0)
                .expect("alive")
                .post(now, "*.talk.plan", Value::from("from 1 while 4 is away"))
                .expect("own queue");
        }
        collect(&mut h, &mut out);
    }
    h.run_until(at(HEAL_AT));
    collect(&mut h, &mut out);
    let mut ms = 0u64;
    while ms <= AFTER_HEAL.as_millis() as u64 {
        h.run_until(at(HEAL_AT + Duration::from_millis(ms)));
        if out.converged_after.is_none() && converged(&h) {
            out.converged_after = Some(Duration::from_millis(ms));
        }
        ms += 1;
    }
    // Leave time for talk repair (NACK, re-send) to finish before counting.
    h.run_until(at(HEAL_AT + AFTER_HEAL + Duration::from_secs(1)));
    collect(&mut h, &mut out);
    out
}

fn check_talk(seed: u64, out: &Outcome) {
    assert_eq!(out.given_up, 0, "seed {seed}: a talk message was given up");
    for (sender, text) in [(4u8, "from 4 in the dark"), (1u8, "from 1 while 4 is away")] {
        for i in 0..ROBOTS {
            if i + 1 == usize::from(sender) {
                continue;
            }
            let n = out
                .talk
                .get(&(i, sender, text.to_owned()))
                .copied()
                .unwrap_or(0);
            assert_eq!(
                n,
                1,
                "seed {seed}: robot {} received robot {sender}'s partition message {n} times",
                i + 1
            );
        }
    }
    let total: usize = out.talk.values().sum();
    assert_eq!(
        total,
        2 * (ROBOTS - 1),
        "seed {seed}: no other talk: {:?}",
        out.talk
    );
}

#[test]
fn a_team_reconverges_after_robot_4_is_cut_off_for_two_seconds_on_a_competition_wlan() {
    let mut times = Vec::new();
    for seed in 0..SEEDS {
        let out = run(seed, Sim::builder().preset(Preset::Competition));
        check_talk(seed, &out);
        let t = out
            .converged_after
            .unwrap_or_else(|| panic!("seed {seed}: not converged {AFTER_HEAL:?} after the heal"));
        times.push(t);
    }
    times.sort();
    let within_two = times.iter().filter(|&&t| t <= 2 * REFRESH).count();
    let (p50, p90, max) = (
        percentile(&times, 0.5).expect("seeds"),
        percentile(&times, 0.9).expect("seeds"),
        *times.last().expect("seeds"),
    );
    eprintln!(
        "competition, {SEEDS} seeds: converged after the heal in p50 {p50:?}, p90 {p90:?}, \
         max {max:?}; within two refresh periods: {within_two}/{SEEDS}"
    );
    assert!(
        p50 <= REFRESH + WORST_CROSSING,
        "median convergence {p50:?} is slower than a lossless network guarantees ({:?})",
        REFRESH + WORST_CROSSING
    );
    assert!(
        p90 <= 2 * REFRESH + WORST_CROSSING,
        "90th percentile {p90:?}: more than one lost attempt repaired per direction ({:?})",
        2 * REFRESH + WORST_CROSSING
    );
}

#[test]
fn without_loss_the_team_reconverges_within_one_refresh_period_and_one_crossing() {
    // The power-save competition preset's delays (DTIM beacon, 20 ± 10 ms, 6 Mbit/s)
    // without its loss.
    let link = netsim::LinkConfig {
        loss: 0.0,
        ..Preset::CompetitionPs.link()
    };
    let mut times = Vec::new();
    for seed in 0..SEEDS {
        let out = run(seed, Sim::builder().link(link.clone()));
        check_talk(seed, &out);
        let t = out
            .converged_after
            .unwrap_or_else(|| panic!("seed {seed}: not converged {AFTER_HEAL:?} after the heal"));
        assert!(
            t <= REFRESH + WORST_CROSSING,
            "seed {seed}: converged {t:?} after the heal, later than one refresh period \
             plus the worst crossing ({:?})",
            REFRESH + WORST_CROSSING
        );
        times.push(t);
    }
    times.sort();
    let within_two = times.iter().filter(|&&t| t <= 2 * REFRESH).count();
    eprintln!(
        "competition delays without loss, {SEEDS} seeds: converged after the heal in p50 \
         {:?}, max {:?}; within two refresh periods: {within_two}/{SEEDS}",
        percentile(&times, 0.5).expect("seeds"),
        times.last().expect("seeds")
    );
}
