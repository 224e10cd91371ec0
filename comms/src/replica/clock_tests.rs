//! Shared time between two replicas: the transit a value's age gains, the estimate a
//! teammate's clock gets, and frames with wild stamps and echoes that must not poison it.

use std::time::Duration;

use super::tests::{addr, robot, t};
use super::*;
use crate::wire::{encode_frame, Echo, Frame, FrameClock, Item};

/// Robot 2's clock reads robot 1's plus this.
const B_AHEAD: Duration = Duration::from_secs(5);
/// One-way delay each way.
const DELAY: Duration = Duration::from_millis(12);

/// Robots 1 and 2 exchange every frame for `secs` seconds (a tick every 50 ms, a value
/// written each tick); returns the time on robot 1's clock at the end.
fn exchange(a: &mut Replica, b: &mut Replica, secs: u64) -> Instant {
    let mut now = t(0);
    for tick in 0..secs * 20 {
        now = t(tick * 50);
        a.handle_timeout(now);
        b.handle_timeout(now + B_AHEAD);
        a.set(now, "*.var.x", Value::Int(tick as i64)).unwrap();
        b.set(now + B_AHEAD, "*.var.y", Value::Int(tick as i64))
            .unwrap();
        while let Some(f) = a.poll_transmit() {
            b.handle_datagram(now + DELAY + B_AHEAD, addr(), &f.payload);
        }
        // Robot 2 sends on hearing robot 1 (its latest input): DELAY later on both clocks.
        while let Some(f) = b.poll_transmit() {
            a.handle_datagram(now + DELAY * 2, addr(), &f.payload);
        }
        while a.poll_event().is_some() || b.poll_event().is_some() {}
    }
    now
}

#[test]
fn a_value_s_age_includes_the_transit_once_the_teammate_s_clock_is_known() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    let now = exchange(&mut a, &mut b, 3);
    let peer = b.peers().find(|p| p.robot == 1).expect("robot 1 heard");
    assert!(peer.clock_samples > 10, "{peer:?}");
    let offset = peer.clock_offset_us.expect("an estimate");
    assert!(
        (offset + 5_000_000).abs() < 200,
        "robot 1's clock is 5 s behind robot 2's, estimated {offset} µs"
    );
    assert_eq!(peer.round_trip, Some(DELAY * 2), "no hold in the exchange");
    let e = b.get("1.var.x").unwrap().expect("replicated");
    let age = e.age(now + DELAY + B_AHEAD);
    assert!(
        age.abs_diff(DELAY) < Duration::from_micros(200),
        "a value written as its frame left is {age:?} old on arrival: the {DELAY:?} transit"
    );
    assert_eq!(
        b.stats().clock_echoes_rejected + b.stats().clock_outliers,
        0
    );
}

#[test]
fn without_clock_sync_the_default_transit_is_used() {
    let mut cfg = ReplicaConfig::new(2, 7);
    cfg.clock_sync = false;
    cfg.default_transit = Duration::from_millis(3);
    let (mut a, mut b) = (robot(1, 11), Replica::new(cfg, 22, t(0)).unwrap());
    let now = exchange(&mut a, &mut b, 2);
    let e = b.get("1.var.x").unwrap().expect("replicated");
    assert_eq!(
        e.age(now + DELAY + B_AHEAD),
        Duration::from_millis(3),
        "the configured transit, not the real one"
    );
    assert!(b.stats().transit_defaulted > 0);
}

#[test]
fn wild_stamps_and_forged_echoes_are_counted_and_change_no_estimate() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    let now = exchange(&mut a, &mut b, 3);
    let before = b.peers().find(|p| p.robot == 1).unwrap();
    let arrive = now + DELAY + B_AHEAD + Duration::from_millis(1);
    let forged = |seq: u64, stamp_us: u32, echo: Option<Echo>| {
        encode_frame(
            &Frame {
                team: 7,
                sender: 1,
                incarnation: 11,
                seq,
                clock: FrameClock { stamp_us, echo },
                items: vec![Item::Update {
                    path: format!("z{seq}"),
                    value: Value::Int(seq as i64),
                    version: seq,
                    age_us: 1_000,
                }],
            },
            None,
        )
    };
    let stats = |b: &Replica| {
        let s = b.stats();
        (
            s.clock_echoes_rejected,
            s.clock_outliers,
            s.clock_stamps_implausible,
        )
    };
    let real_stamp = (now.as_micros() + 1_000) as u32;
    // An echo of a frame robot 2 never sent.
    let never_sent = Echo {
        target: 2,
        seq16: 0xbeef,
        hold_10us: 0,
    };
    b.handle_datagram(
        arrive,
        addr(),
        &forged(10_000, real_stamp, Some(never_sent)),
    );
    assert_eq!(stats(&b), (1, 0, 0), "an echo of a stamp never sent");
    // An echo of a real frame held longer than the round trip, and one held 600 ms.
    let last16 = b.seq as u16;
    for hold_10us in [u16::MAX, 60_000] {
        let held = Echo {
            target: 2,
            seq16: last16,
            hold_10us,
        };
        b.handle_datagram(
            arrive,
            addr(),
            &forged(10_001 + u64::from(hold_10us), real_stamp, Some(held)),
        );
    }
    assert_eq!(stats(&b), (3, 0, 0), "negative round trips");
    // A plausible echo in a frame whose stamp is an hour off: an outlier, and its values
    // are stamped with the default transit.
    let fresh = Echo {
        target: 2,
        seq16: last16,
        hold_10us: 100,
    };
    let wild = real_stamp.wrapping_add(3_600_000_000);
    b.handle_datagram(arrive, addr(), &forged(20_000, wild, Some(fresh)));
    assert_eq!(
        stats(&b),
        (3, 1, 1),
        "an outlier sample and an implausible transit"
    );
    let z = b
        .get("1.var.z20000")
        .unwrap()
        .expect("the value itself is kept");
    assert_eq!(
        z.age(arrive),
        Duration::from_millis(1),
        "its age, no transit"
    );
    let after = b.peers().find(|p| p.robot == 1).unwrap();
    assert_eq!(
        (after.clock_offset_us, after.clock_samples),
        (before.clock_offset_us, before.clock_samples),
        "the estimate did not move"
    );
}
