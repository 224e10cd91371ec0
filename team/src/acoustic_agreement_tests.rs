//! A team of four field players in a perfect room: every claim sounded is heard by every
//! teammate, their clocks agree, the radio fails at once for all. Whatever their costs do
//! after the radio fails, they hold the same claims, so they must name the same goer at
//! every tick: a disagreement here is the fallback's own (two goers, or none), not the
//! room's.

use super::*;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const TICK_S: f64 = 0.01;
/// The decoder reports a claim this long after its tone began (the hall's median, about).
const DECODED_AFTER_S: f64 = 0.45;
const OUTAGE_AT_S: f64 = 10.0;
const END_S: f64 = 30.0;
const FIELD: [u8; 4] = [2, 3, 4, 5];

/// One robot's cost over time: a straight line, kept on the field (0.2–6 m).
#[derive(Clone, Copy)]
struct Path {
    h0: f64,
    slope: f64,
}

impl Path {
    fn h(&self, t: f64) -> f64 {
        (self.h0 + self.slope * t).clamp(0.2, 6.0)
    }
}

/// Plays one scenario; returns the ticks after the fallback took control at which the
/// robots named different goers, with the first such time.
fn play(paths: &[Path; 4], outage_at_s: f64) -> (usize, Option<f64>) {
    let cfg = AcousticConfig::default();
    let plan = SlotPlan::for_team(5, cfg.slot_s());
    let params = ArbitrationParams::default();
    let mut robots: Vec<SoundFallback> = FIELD
        .iter()
        .map(|&me| SoundFallback::new(me, plan, &cfg, 5, params))
        .collect();
    // What each robot last sent by radio (the same for every listener), and when.
    let mut sent: [Option<(Posted, f64)>; 4] = [None; 4];
    let mut going = [false; 4];
    // Messages in the air: (decoded at, listener index, message, start).
    let mut air: Vec<(f64, usize, Message, f64)> = Vec::new();
    let (mut disagreements, mut first) = (0, None);
    let mut k = 0u64;
    loop {
        let t = k as f64 * TICK_S;
        k += 1;
        if t > END_S {
            break;
        }
        for (at, who, message, start) in &air {
            if *at <= t && *at > t - TICK_S {
                robots[*who].hear(FIELD[*who], message, *start);
            }
        }
        air.retain(|m| m.0 > t);
        let mut named = [None; 4];
        let mut all_in_control = true;
        for i in 0..4 {
            let me = FIELD[i];
            let heard: Vec<Candidate> = (0..4)
                .filter(|&j| j != i)
                .filter_map(|j| sent[j].map(|(p, at)| (j, p, at)))
                .map(|(j, posted, at)| Candidate {
                    robot: FIELD[j],
                    posted,
                    age: Duration::from_secs_f64(t - at),
                })
                .collect();
            let h = paths[i].h(t);
            let fb = &mut robots[i];
            let decision = if fb.radio(me, &heard, params.stale_after, &super::tests::lab(), t) {
                let claims = fb.candidates(me, t, &heard);
                fb.decide(&claims)
            } else {
                all_in_control = false;
                let mut all = heard.clone();
                all.push(Candidate {
                    robot: me,
                    posted: Posted { h, going: going[i] },
                    age: Duration::ZERO,
                });
                let d = arbitration::decide(&params, &all);
                fb.posted(
                    t,
                    Posted {
                        h,
                        going: d.should_go(me),
                    },
                );
                d
            };
            going[i] = decision.should_go(me);
            named[i] = decision.goer;
            if fb.starts_in(me, t, TICK_S) {
                let posted = Posted { h, going: going[i] };
                if let Some(message) = fb.claim(me, posted, t) {
                    for j in (0..4).filter(|&j| j != i) {
                        air.push((t + DECODED_AFTER_S, j, message, t));
                    }
                }
            }
        }
        if t < outage_at_s {
            for i in 0..4 {
                sent[i] = Some((
                    Posted {
                        h: paths[i].h(t),
                        going: going[i],
                    },
                    t,
                ));
            }
        }
        if all_in_control && named.iter().any(|n| *n != named[0]) {
            disagreements += 1;
            first.get_or_insert(t);
        }
    }
    (disagreements, first)
}

#[test]
fn robots_that_hear_every_claim_never_disagree_on_the_goer() {
    // Seeded scenarios: each robot's cost runs from 0.3–4 m at up to ±0.3 m/s, and the
    // radio fails anywhere in a cycle.
    let mut rng = ChaCha8Rng::seed_from_u64(33);
    let mut bad = Vec::new();
    for scenario in 0..200 {
        let paths: [Path; 4] = std::array::from_fn(|_| Path {
            h0: rng.random_range(0.3..4.0),
            slope: rng.random_range(-0.3..0.3),
        });
        let outage = OUTAGE_AT_S + rng.random_range(0.0..2.8);
        let (n, first) = play(&paths, outage);
        if n > 0 {
            bad.push((scenario, n, first));
        }
    }
    assert!(
        bad.is_empty(),
        "robots holding the same claims disagreed (scenario, ticks, first at s): {bad:?}"
    );
}
