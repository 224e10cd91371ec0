//! The team layer under a robot program's extreme senses: values of the contract's
//! shapes, finite, but absurd (a pose 1e300 m away, a variance of 5e-324 or 1e300, a
//! landmark σ that squares to 0). The independent attack suite (`scripts/attack/`, its
//! `team_inputs` attack) wrote such senses to a daemon and read a NaN team ball, own ball
//! and pose back; the filters then carry the NaN for good. Every write is either refused
//! by the contract or leaves the layer's outputs finite.

use super::{TeamCore, TeamLayerConfig};
use comms::{Instant, Replica, ReplicaConfig, Value};
use std::time::Duration;
use team::contract;

/// xorshift64*: the test's own seeded draws (no clock, no global RNG).
struct Draws(u64);

impl Draws {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }

    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Half the time an extreme, else an ordinary value within ±5.
    fn place(&mut self) -> f64 {
        const EXTREMES: [f64; 14] = [
            0.0, 1e-300, -1e-300, 5e-324, 1e300, -1e300, 1.7e308, -1.7e308, 1e15, -1e15, 1e6, -1e6,
            100.0, -100.0,
        ];
        if self.unit() < 0.5 {
            EXTREMES[self.below(EXTREMES.len())]
        } else {
            self.unit() * 10.0 - 5.0
        }
    }

    fn variance(&mut self) -> f64 {
        const VARIANCES: [f64; 8] = [1e-300, 5e-324, 1e-12, 1e300, 1e-3, 0.01, 1.0, 1e6];
        VARIANCES[self.below(VARIANCES.len())]
    }
}

/// One write of the program's senses: its key and value.
fn sense(d: &mut Draws) -> (&'static str, Value) {
    let f = |v: Vec<f64>| Value::Floats(v);
    match d.below(6) {
        0 => {
            let (a, b, c) = (d.variance(), d.variance(), d.variance());
            let pose = vec![d.place(), d.place(), d.place(), a, 0.0, 0.0, b, 0.0, c];
            (contract::POSE_KEY, f(pose))
        }
        1 => (
            contract::ODOMETRY_KEY,
            f(vec![d.place(), d.place(), d.place()]),
        ),
        2 => {
            let (a, b) = (d.variance(), d.variance());
            (contract::BALL_KEY, f(vec![d.place(), d.place(), a, 0.0, b]))
        }
        3 => {
            let mut all = Vec::new();
            for _ in 0..1 + d.below(3) {
                let sighting = [
                    d.place(),
                    d.place(),
                    d.place().abs(),
                    d.place(),
                    d.variance(),
                    d.variance(),
                ];
                all.extend(sighting);
            }
            (contract::LANDMARKS_KEY, f(all))
        }
        4 => (contract::KICK_KEY, f(vec![d.place(), d.unit() * 20.0])),
        _ => (contract::COST_KEY, Value::Float(d.place())),
    }
}

/// The first non-finite number the layer published, if any.
fn non_finite(replica: &Replica) -> Option<(&'static str, Vec<f64>)> {
    [
        contract::TEAM_BALL_KEY,
        contract::OWN_BALL_KEY,
        contract::POSE_OUT_KEY,
        contract::MATES_KEY,
    ]
    .into_iter()
    .find_map(|key| match replica.get(key).expect("a valid key") {
        Some(e) => match &e.value {
            Value::Floats(v) if v.iter().any(|x| !x.is_finite()) => Some((key, v.clone())),
            _ => None,
        },
        None => None,
    })
}

#[test]
fn extreme_senses_are_refused_or_leave_the_team_layer_finite() {
    for seed in 1..=6u64 {
        let mut d = Draws(seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1);
        let mut now = Instant::from_micros(1_000_000);
        let mut core = TeamCore::new(1, TeamLayerConfig::new(5, None));
        let config = ReplicaConfig::new(1, 0).with_known_paths(team::known_paths());
        let mut replica = Replica::new(config, 7, now).expect("a valid replica");
        let start = Value::Floats(vec![0.5, -1.0, 0.25, 0.01, 0.0, 0.0, 0.01, 0.0, 0.003]);
        core.input(contract::POSE_KEY, &start, now)
            .expect("a valid pose");
        let (mut taken, mut refused) = (0, 0);
        let mut history: Vec<String> = Vec::new();
        for write in 0..4_000 {
            let (key, value) = sense(&mut d);
            let closes = match core.input(key, &value, now) {
                Ok(closes) => {
                    taken += 1;
                    closes
                }
                Err(_) => {
                    refused += 1;
                    false
                }
            };
            history.push(format!("{key} {value:?}"));
            if closes {
                core.tick(&mut replica, now);
                if let Some((key, v)) = non_finite(&replica) {
                    let last = &history[history.len().saturating_sub(8)..];
                    panic!(
                        "seed {seed}, write {write}: {key} = {v:?} after {taken} senses taken \
                         ({refused} refused); the last writes:\n{}",
                        last.join("\n")
                    );
                }
            }
            now += Duration::from_millis(5);
        }
        assert!(
            taken > 500,
            "seed {seed}: only {taken} of 4000 writes were taken"
        );
    }
}
