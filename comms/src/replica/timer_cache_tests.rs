//! `poll_timeout` keeps its last answer until an input may change it: after any sequence
//! of writes, posts, frames (some lost), timers, silences and game-clock figures, the kept
//! answer is the one worked out from scratch.

use std::time::Duration;

use proptest::prelude::*;

use crate::{BudgetSpec, ExternalCap, Instant, Key, Replica, ReplicaConfig, Value};

#[derive(Debug, Clone)]
enum Op {
    /// Robot `.0` writes key `.1` (priority when `.2`).
    Set(usize, usize, bool),
    /// Robot `.0` posts to its talk queue.
    Post(usize),
    /// Robot `.0` sends what it has; teammate `j` loses the frames where bit `j` of `.1` is set.
    Send(usize, u8),
    /// Time passes by this many ms and every robot's due timers run.
    Wait(u64),
    /// Robot `.0` goes silent this many ms while the others keep talking (departures,
    /// talk give-ups).
    Silence(usize, u64),
    /// The budgeted robot hears a GameController figure.
    GameClock(u64),
}

fn any_op() -> impl Strategy<Value = Op> {
    prop_oneof![
        4 => (0..3usize, 0..3usize, any::<bool>()).prop_map(|(r, k, p)| Op::Set(r, k, p)),
        1 => (0..3usize).prop_map(Op::Post),
        4 => (0..3usize, any::<u8>()).prop_map(|(r, l)| Op::Send(r, l)),
        3 => (0..400u64).prop_map(Op::Wait),
        1 => (0..3usize, 0..1500u64).prop_map(|(r, ms)| Op::Silence(r, ms)),
        1 => (0..200u64).prop_map(Op::GameClock),
    ]
}

struct Team {
    robots: Vec<Replica>,
    now_us: u64,
}

impl Team {
    /// Robot 1 under the SPL budget (its fifth), robots 2 and 3 without.
    fn new() -> Team {
        let budgeted = ReplicaConfig {
            budget: Some(BudgetSpec::SPL.share(5).split()),
            mtu: 128,
            ..ReplicaConfig::new(1, 1)
        };
        let robots = vec![
            Replica::new(budgeted, 11, Instant::ZERO).unwrap(),
            Replica::new(ReplicaConfig::new(2, 1), 12, Instant::ZERO).unwrap(),
            Replica::new(ReplicaConfig::new(3, 1), 13, Instant::ZERO).unwrap(),
        ];
        Team { robots, now_us: 0 }
    }

    fn now(&self) -> Instant {
        Instant::from_micros(self.now_us)
    }

    fn send(&mut self, from: usize, lost: u8) {
        let addr = format!("10.0.0.{}:2000", from + 1).parse().unwrap();
        let now = self.now();
        while let Some(t) = self.robots[from].poll_transmit() {
            for to in (0..3).filter(|&to| to != from && lost & (1 << to) == 0) {
                self.robots[to].handle_datagram(now, addr, &t.payload);
            }
        }
    }

    fn wait(&mut self, ms: u64, silent: Option<usize>) {
        let end = self.now_us + ms * 1000;
        // In 10 ms steps, so that timers fire near their time and everyone's frames go.
        while self.now_us < end {
            self.now_us = (self.now_us + 10_000).min(end);
            let now = self.now();
            for i in (0..3).filter(|&i| Some(i) != silent) {
                if self.robots[i].poll_timeout().is_some_and(|t| t <= now) {
                    self.robots[i].handle_timeout(now);
                }
                self.send(i, 0);
            }
            self.check();
        }
    }

    fn apply(&mut self, op: &Op) {
        let now = self.now();
        match *op {
            Op::Set(r, k, priority) => {
                let key = Key::parse(["*.var.x", "*.var.goer", "local.var.y"][k]).unwrap();
                let value = Value::Int(self.now_us as i64);
                let robot = &mut self.robots[r];
                if priority {
                    robot.set_priority(now, &key, value).unwrap();
                } else {
                    robot.set_key(now, &key, value).unwrap();
                }
            }
            Op::Post(r) => {
                self.robots[r]
                    .post(now, "*.talk.q", Value::Int(self.now_us as i64))
                    .unwrap();
            }
            Op::Send(r, lost) => self.send(r, lost),
            Op::Wait(ms) => self.wait(ms, None),
            Op::Silence(r, ms) => self.wait(ms, Some(r)),
            Op::GameClock(left) => {
                self.robots[0].set_game_clock(now, Duration::from_secs(600));
                self.robots[0].set_external_budget(Some(ExternalCap {
                    counted: true,
                    team_left: left,
                    rate_per_s: 1.0,
                    margin: 0,
                }));
            }
        }
    }

    /// Every robot's answer against one worked out from scratch, asked twice (the second
    /// time from the cache).
    fn check(&self) {
        for r in &self.robots {
            let fresh = Some(r.next_deadline());
            assert_eq!(r.poll_timeout(), fresh, "robot {}", r.robot_id());
            assert_eq!(r.poll_timeout(), fresh, "robot {}, kept", r.robot_id());
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn the_kept_timeout_is_always_the_one_worked_out_afresh(
        ops in proptest::collection::vec(any_op(), 1..40),
    ) {
        let mut team = Team::new();
        team.check();
        for op in &ops {
            team.apply(op);
            team.check();
        }
    }
}
