//! The blackboard's bounds through the replica: forged versions, restarts, key limits.

use super::tests::{addr, robot, t};
use super::*;
use crate::wire::FrameWriter;

fn pump(now: Instant, from: &mut Replica, to: &mut Replica) {
    while let Some(tx) = from.poll_transmit() {
        to.handle_datagram(now, addr(), &tx.payload);
    }
}
/// Frames from `sender` (incarnation `incarnation`, no key) carrying `updates`.
fn forged(sender: u8, incarnation: u64, updates: &[(String, Value, u64)]) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    let mut rest = updates;
    let mut seq = 1000;
    while !rest.is_empty() {
        seq += 1;
        let mut w = FrameWriter::new(7, sender, incarnation, seq, 1200, None);
        while let Some((path, value, version)) = rest.first() {
            let item = ItemRef::Update {
                path,
                value,
                version: *version,
                age_us: 0,
            };
            if !w.push(item) {
                break;
            }
            rest = &rest[1..];
        }
        out.push(w.finish());
    }
    out
}

#[test]
fn a_forged_top_version_does_not_pin_a_value_the_owner_keeps_publishing() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    a.set(t(0), "*.var.x", Value::Int(0)).unwrap();
    pump(t(1), &mut a, &mut b);
    // One stray frame in robot 1's name, version 2^64 - 1.
    for f in forged(1, 11, &[("x".into(), Value::Int(666), u64::MAX)]) {
        b.handle_datagram(t(5), addr(), &f);
    }
    assert_eq!(b.get("1.var.x").unwrap().unwrap().value, Value::Int(666));
    // The real owner keeps publishing (a write every 10 ms, its refresh every 100 ms).
    let mut recovered = None;
    for ms in (10..=1000).step_by(10) {
        a.set(t(ms), "*.var.x", Value::Int(ms as i64)).unwrap();
        a.handle_timeout(t(ms));
        pump(t(ms), &mut a, &mut b);
        if b.get("1.var.x").unwrap().unwrap().value == Value::Int(ms as i64) {
            recovered = Some(ms);
            break;
        }
    }
    let ms = recovered.expect("the real value is readable again within 1 s");
    assert!(ms <= 5 + 300 + 10, "recovered at {ms} ms");
    assert_eq!(b.stats().updates_unconfirmed_replaced, 1);
    // From then on it follows the owner, and an old frame is still stale.
    a.set(t(ms + 10), "*.var.x", Value::Int(-1)).unwrap();
    pump(t(ms + 10), &mut a, &mut b);
    assert_eq!(b.get("1.var.x").unwrap().unwrap().value, Value::Int(-1));
}

#[test]
fn a_restarted_robots_new_life_removes_the_values_its_old_one_left() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    a.set(t(0), "*.var.keep", Value::Int(1)).unwrap();
    a.set(t(0), "*.var.gone", Value::Int(1)).unwrap();
    pump(t(1), &mut a, &mut b);
    let mut a2 = robot(1, 99);
    b.handle_timeout(t(50));
    // The new life has not published yet: the old values are all there is.
    assert!(b.get("1.var.gone").unwrap().is_some());
    a2.set(t(60), "*.var.keep", Value::Int(2)).unwrap();
    pump(t(61), &mut a2, &mut b);
    assert_eq!(b.get("1.var.keep").unwrap().unwrap().value, Value::Int(2));
    assert!(b.get("1.var.gone").unwrap().is_none());
    assert_eq!(b.stats().bindings_superseded, 1);
}

#[test]
fn spoofed_keys_are_bounded_per_robot_and_in_total_and_nothing_stored_is_lost() {
    let mut cfg = ReplicaConfig::new(2, 7);
    cfg.max_bindings_per_owner = 300;
    cfg.max_remote_bindings = 500;
    let mut b = Replica::new(cfg, 22, t(0)).unwrap();
    let mut a = robot(1, 11);
    a.set(t(0), "*.var.pose", Value::Float(1.0)).unwrap();
    pump(t(1), &mut a, &mut b);
    let spoof = |n: usize| -> Vec<(String, Value, u64)> {
        (0..n)
            .map(|i| (format!("spoof.k{i}"), Value::Int(i as i64), 1))
            .collect()
    };
    for f in forged(1, 11, &spoof(1000)) {
        b.handle_datagram(t(2), addr(), &f);
    }
    assert_eq!(b.blackboard().owner_len(1), 300, "per robot");
    for f in forged(9, 99, &spoof(1000)) {
        b.handle_datagram(t(3), addr(), &f);
    }
    assert_eq!(b.blackboard().owner_len(9), 200, "all robots together");
    assert_eq!(b.blackboard().len(), 500);
    assert_eq!(
        b.stats().updates_refused,
        701 + 800,
        "pose was one of the 300"
    );
    // What was stored before still updates.
    a.set(t(4), "*.var.pose", Value::Float(2.0)).unwrap();
    pump(t(5), &mut a, &mut b);
    assert_eq!(
        b.get("1.var.pose").unwrap().unwrap().value,
        Value::Float(2.0)
    );
    b.handle_timeout(t(100));
    let mirrored = b.get("local.var.huddle.stats.updates_refused").unwrap();
    assert_eq!(mirrored.map(|e| e.value.clone()), Some(Value::Int(1501)));
}

#[test]
fn own_and_local_keys_have_limits_but_the_stats_mirror_does_not() {
    let mut cfg = ReplicaConfig::new(2, 7);
    cfg.max_bindings_per_owner = 2;
    cfg.max_local_bindings = 1;
    let mut r = Replica::new(cfg, 22, t(0)).unwrap();
    r.set(t(0), "local.var.a", Value::Int(1)).unwrap();
    assert!(matches!(
        r.set(t(0), "local.var.b", Value::Int(1)),
        Err(SetError::TooManyKeys { .. })
    ));
    r.set(t(0), "*.var.a", Value::Int(1)).unwrap();
    r.set(t(0), "*.var.b", Value::Int(1)).unwrap();
    assert!(r.set(t(0), "*.var.c", Value::Int(1)).is_err());
    r.handle_timeout(t(0));
    assert!(r.get("local.var.huddle.stats.frames_in").unwrap().is_some());
}
