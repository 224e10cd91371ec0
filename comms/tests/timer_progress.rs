//! A driver that sleeps until `poll_timeout`, calls `handle_timeout` and drains
//! `poll_transmit` must move on: the next deadline is then after `now`. A deadline that
//! stays due is a driver spinning on one instant (the daemon burning a core, the netsim
//! harness hanging a whole game), as the budget's free-state deadline at the
//! GameController's zero once did.
//!
//! Three robots under random budgets (none, a split or pooled SPL share, the
//! GameController's figure counted or free, down to zero), random writes, priority
//! items, talk posts, losses and silences; after every step each robot is driven as a
//! driver would, and checked.

use std::net::SocketAddr;
use std::time::Duration;

use comms::{BudgetSpec, ExternalCap, Instant, Key, Replica, ReplicaConfig, Value};
use proptest::prelude::*;

#[derive(Debug, Clone)]
enum Step {
    /// Robot `r` writes a value of `len` floats to one of a few keys.
    Set { r: usize, key: u8, len: usize },
    /// Robot `r` writes a priority item.
    Priority { r: usize },
    /// Robot `r` posts to its talk queue.
    Post { r: usize },
    /// The GameController's figure for robot `r` changes (`None`: it goes away).
    Gc { r: usize, cap: Option<(bool, u64)> },
    /// Time passes; frames sent meanwhile are lost when `lose` is set.
    Wait { ms: u64, lose: bool },
}

fn step() -> impl Strategy<Value = Step> {
    prop_oneof![
        4 => (0..3usize, 0..4u8, 1..7usize).prop_map(|(r, key, len)| Step::Set { r, key, len }),
        1 => (0..3usize).prop_map(|r| Step::Priority { r }),
        1 => (0..3usize).prop_map(|r| Step::Post { r }),
        1 => (0..3usize, proptest::option::of((any::<bool>(), prop_oneof![Just(0u64), Just(1), 0..600u64])))
            .prop_map(|(r, cap)| Step::Gc { r, cap }),
        4 => (0..3_000u64, any::<bool>()).prop_map(|(ms, lose)| Step::Wait { ms, lose }),
    ]
}

fn at(ms: u64) -> Instant {
    Instant::from_micros(1_000_000 + ms * 1000)
}

fn team(budget: u8) -> Vec<Replica> {
    (1..=3u8)
        .map(|id| {
            let mut cfg = ReplicaConfig {
                mtu: 128,
                ..ReplicaConfig::new(id, 5)
            };
            cfg = match budget {
                0 => cfg,
                1 => ReplicaConfig {
                    budget: Some(BudgetSpec::SPL.share(3).split()),
                    ..cfg
                },
                _ => cfg.with_budget(&BudgetSpec::SPL, 3),
            };
            let mut r = Replica::new(cfg, u64::from(id), at(0)).expect("a valid config");
            r.set_game_clock(at(0), Duration::from_secs(600));
            r
        })
        .collect()
}

/// Drives every robot as a driver would at `now`: fire due timers, send what is
/// queued (delivered unless `lose`), until nothing is due; then checks that each
/// deadline is after `now`.
fn drive(team: &mut [Replica], now: Instant, lose: bool) -> Result<(), TestCaseError> {
    let from = |id: u8| SocketAddr::from(([127, 0, 0, id], 2000));
    // Delivering can make a teammate due again (a NACK, a newcomer's refresh): a few
    // rounds settle it; a team that never settles is itself the bug.
    for _round in 0..50 {
        let mut frames = Vec::new();
        for r in team.iter_mut() {
            if r.poll_timeout().is_some_and(|t| t <= now) {
                r.handle_timeout(now);
            }
            while let Some(t) = r.poll_transmit() {
                frames.push((r.robot_id(), t.payload));
            }
        }
        if frames.is_empty() {
            break;
        }
        if !lose {
            for (sender, bytes) in &frames {
                for r in team.iter_mut().filter(|r| r.robot_id() != *sender) {
                    r.handle_datagram(now, from(*sender), bytes);
                }
            }
        }
    }
    for r in team.iter_mut() {
        r.handle_timeout(now);
        while r.poll_transmit().is_some() {}
        let next = r.poll_timeout();
        prop_assert!(
            next.is_none_or(|t| t > now),
            "robot {}: deadline {:?} is still due at {:?} after handle_timeout and \
             draining its transmits (budget headroom {:?}, status {:?})",
            r.robot_id(),
            next,
            now,
            r.budget_headroom(),
            r.budget_status()
        );
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    #[test]
    fn a_driver_firing_each_deadline_always_moves_on(
        budget in 0..3u8,
        steps in proptest::collection::vec(step(), 1..60),
    ) {
        let mut team = team(budget);
        let keys: Vec<Key> = (0..4)
            .map(|i| Key::parse(&format!("*.var.k{i}")).unwrap())
            .collect();
        let goer = Key::parse("*.var.goer").unwrap();
        let mut ms = 0;
        for s in steps {
            let now = at(ms);
            let mut lose = false;
            match s {
                Step::Set { r, key, len } => {
                    let v = Value::Floats((0..len).map(|i| (ms + i as u64) as f64).collect());
                    team[r].set_key(now, &keys[usize::from(key)], v).unwrap();
                }
                Step::Priority { r } => {
                    team[r].set_priority(now, &goer, Value::Int(ms as i64)).unwrap();
                }
                Step::Post { r } => {
                    // A full queue is an answer, not a failure of the property.
                    let _ = team[r].post(now, "*.talk.say", Value::Int(ms as i64));
                }
                Step::Gc { r, cap } => {
                    team[r].set_external_budget(cap.map(|(counted, team_left)| ExternalCap {
                        counted,
                        team_left,
                        rate_per_s: 1.0,
                        margin: 0,
                    }));
                }
                Step::Wait { ms: dt, lose: l } => {
                    ms += dt;
                    lose = l;
                }
            }
            drive(&mut team, at(ms), lose)?;
        }
    }
}
