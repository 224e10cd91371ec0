//! The stats mirror reads its keys through cached slots; the blackboard must end up as
//! the per-key lookups it replaced left it: the same keys, values, versions and stamps,
//! and the same change events in the same order.

use std::fmt::Write as _;

use super::super::tests::{addr, robot, t};
use super::super::*;
use crate::key::Kind;
use crate::stats::DropReason;

/// The mirror as it was before the slots were cached (a path built and looked up per
/// counter, a key built per write): the reference the new one must match.
fn reference_mirror(r: &Replica, board: &mut Blackboard, now: Instant) {
    let s = &r.stats;
    let mut expected: Vec<(String, i64)> = super::COUNTERS
        .iter()
        .zip(super::counter_values(s))
        .map(|(name, v)| (format!("huddle.stats.{name}"), v as i64))
        .collect();
    for reason in DropReason::ALL {
        let path = format!("huddle.stats.drops.{}", reason.name());
        expected.push((path, s.drops(reason) as i64));
    }
    for (&robot, p) in &r.peers {
        let v = i64::from(p.conflicting(r.cfg.departed_after));
        expected.push((format!("huddle.stats.peer.{robot}.conflicting"), v));
    }
    for (&robot, at) in &s.last_heard {
        let mut path = String::new();
        let _ = write!(path, "huddle.stats.peer.{robot}.last_heard_us");
        expected.push((path, at.as_micros() as i64));
    }
    for (path, v) in expected {
        let unchanged = board
            .get_stored(Scope::Local, &path)
            .is_some_and(|e| e.value == Value::Int(v));
        if !unchanged {
            let key = Key::from_shared(Scope::Local, Kind::Var, path.into());
            board
                .write_unlimited(now, key.as_parts(), Value::Int(v))
                .unwrap();
        }
    }
}

fn mirrored(board: &Blackboard) -> Vec<(String, Entry)> {
    let pattern = Pattern::parse("local.var.huddle.stats.#").unwrap();
    board
        .iter(&pattern)
        .map(|(k, e)| (k.to_string(), e.clone()))
        .collect()
}

fn changes(board: &mut Blackboard) -> Vec<String> {
    std::iter::from_fn(|| board.poll_change().map(|k| k.to_string())).collect()
}

fn pump(now: Instant, from: &mut Replica, to: &mut Replica) {
    while let Some(tx) = from.poll_transmit() {
        to.handle_datagram(now, addr(), &tx.payload);
    }
}

/// Robot 2 hears robot 1 throughout, robot 3 until it departs at 2 s, a second robot 1
/// (an older start still running) from 1.0 to 1.5 s, another team's frames and garbage;
/// its program overwrites mirrored keys three times. At every 10 ms robot 2's mirror is
/// compared with the reference run on a copy of its blackboard.
#[test]
fn the_cached_mirror_leaves_the_blackboard_as_the_per_key_lookups_did() {
    let (mut a, mut b, mut c) = (robot(1, 11), robot(2, 22), robot(3, 33));
    let mut a_old = robot(1, 5);
    let mut other_team = Replica::new(ReplicaConfig::new(4, 8), 44, t(0)).unwrap();
    let (mut writes, mut conflicted, mut restored) = (0, false, 0);
    for ms in (0..=4000).step_by(10) {
        let now = t(ms);
        a.set(now, "*.var.x", Value::Int(ms as i64)).unwrap();
        a.handle_timeout(now);
        pump(now, &mut a, &mut b);
        if ms < 2000 {
            c.set(now, "*.var.y", Value::Int(3)).unwrap();
            c.handle_timeout(now);
            pump(now, &mut c, &mut b);
        }
        if (1000..1500).contains(&ms) {
            a_old.set(now, "*.var.x", Value::Int(-(ms as i64))).unwrap();
            a_old.handle_timeout(now);
            pump(now, &mut a_old, &mut b);
        }
        if ms % 300 == 0 {
            other_team.set(now, "*.var.z", Value::Int(1)).unwrap();
            pump(now, &mut other_team, &mut b);
            b.handle_datagram(now, addr(), b"hi");
        }
        // The program writes the mirror's keys: another value (put back at the next
        // refresh), the value already mirrored (left), and a float.
        let overwrite = match ms {
            1000 => Some(("frames_in", Value::Int(-1))),
            1500 => Some((
                "drops.too_short",
                Value::Int(b.stats.drops(DropReason::TooShort) as i64),
            )),
            2500 => Some(("peer.3.last_heard_us", Value::Float(0.0))),
            _ => None,
        };
        if let Some((name, v)) = overwrite {
            b.set(now, &format!("local.var.huddle.stats.{name}"), v)
                .unwrap();
            restored += 1;
        }
        let mut reference = b.board.clone();
        reference_mirror(&b, &mut reference, now);
        b.mirror_stats(now);
        assert_eq!(mirrored(&b.board), mirrored(&reference), "at {ms} ms");
        let ours = changes(&mut b.board);
        assert_eq!(ours, changes(&mut reference), "change events at {ms} ms");
        writes += ours.len();
        conflicted |= b
            .get("local.var.huddle.stats.peer.1.conflicting")
            .unwrap()
            .is_some_and(|e| e.value == Value::Int(1));
        b.handle_timeout(now);
        pump(now, &mut b, &mut a);
        changes(&mut b.board);
    }
    assert!(
        conflicted,
        "the two starts of robot 1 were seen as a conflict"
    );
    assert_eq!(restored, 3);
    assert!(writes > 400, "{writes} changed stats over 4 s");
    let drops = b
        .get("local.var.huddle.stats.drops.total")
        .unwrap()
        .unwrap();
    assert!(matches!(drops.value, Value::Int(n) if n >= 14), "{drops:?}");
    let never = b
        .get("local.var.huddle.stats.talk_resent")
        .unwrap()
        .unwrap();
    assert_eq!(
        never.version, 1,
        "a counter that never changed is written once"
    );
    let gone = b
        .get("local.var.huddle.stats.peer.3.last_heard_us")
        .unwrap()
        .unwrap();
    let last = b.stats.last_heard[&3].as_micros() as i64;
    assert_eq!(
        gone.value,
        Value::Int(last),
        "put back after the program's float"
    );
}
