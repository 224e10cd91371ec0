use std::net::SocketAddr;
use std::time::Duration;

use super::*;
use crate::key::Key;
use crate::stats::DropReason;
use crate::wire::Item;

pub(super) fn t(ms: u64) -> Instant {
    Instant::from_micros(ms * 1000)
}
pub(super) fn addr() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 2000))
}
pub(super) fn robot(id: u8, incarnation: u64) -> Replica {
    Replica::new(ReplicaConfig::new(id, 7), incarnation, t(0)).unwrap()
}
fn frames(r: &mut Replica) -> Vec<Vec<u8>> {
    std::iter::from_fn(|| r.poll_transmit().map(|t| t.payload)).collect()
}
fn deliver(now: Instant, frames: &[Vec<u8>], to: &mut Replica) {
    for f in frames {
        to.handle_datagram(now, addr(), f);
    }
}
fn events(r: &mut Replica) -> Vec<Event> {
    std::iter::from_fn(|| r.poll_event()).collect()
}

#[test]
fn a_global_write_reaches_a_teammate_as_the_writers_copy() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    a.set(t(5), "*.var.ball.dist", Value::Float(1.5)).unwrap();
    a.set(t(5), "local.var.secret", Value::Int(1)).unwrap();
    let out = frames(&mut a);
    assert_eq!(out.len(), 1, "one change, one frame");
    deliver(t(6), &out, &mut b);
    let e = b
        .get("1.var.ball.dist")
        .unwrap()
        .expect("robot 2 holds robot 1's copy");
    assert_eq!((e.owner, e.version, &e.value), (1, 1, &Value::Float(1.5)));
    assert_eq!(e.stamp, t(6), "age 0 at send time: stamped at reception");
    assert_eq!(b.get("*.var.ball.dist").unwrap().map(|e| e.owner), Some(1));
    assert!(
        b.get("1.var.secret").unwrap().is_none(),
        "local values never leave"
    );
    assert_eq!(
        a.get("1.var.ball.dist").unwrap().map(|e| e.owner),
        Some(1),
        "the writer reads its own copy as 1.var.x"
    );
    let evs = events(&mut b);
    assert!(
        evs.contains(&Event::PeerJoined {
            robot: 1,
            incarnation: 11
        }),
        "{evs:?}"
    );
    assert!(evs.contains(&Event::ValueChanged {
        key: Key::parse("1.var.ball.dist").unwrap()
    }));
    assert_eq!(
        a.poll_transmit(),
        None,
        "nothing left to send until the next tick"
    );
}

#[test]
fn a_periodically_resent_old_value_does_not_look_fresh() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    a.set(t(0), "*.var.x", Value::Int(4)).unwrap();
    frames(&mut a); // lost
    a.handle_timeout(t(0));
    frames(&mut a); // lost too
    a.handle_timeout(t(100));
    let refresh = frames(&mut a);
    assert!(!refresh.is_empty(), "the refresh re-sends every global");
    deliver(t(104), &refresh, &mut b);
    let e = b.get("1.var.x").unwrap().unwrap();
    assert_eq!(
        e.stamp,
        t(4),
        "reception 104 ms minus the reported 100 ms age"
    );
    assert!(
        b.get_fresher(t(104), "1.var.x", Duration::from_millis(50))
            .unwrap()
            .is_none(),
        "set 100 ms ago on the sender: not fresh, though just received"
    );
}

#[test]
fn older_updates_never_overwrite_newer_ones_whatever_the_arrival_order() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    a.set(t(0), "*.var.x", Value::Int(1)).unwrap();
    let old = frames(&mut a);
    a.set(t(1), "*.var.x", Value::Int(2)).unwrap();
    let new = frames(&mut a);
    deliver(t(2), &new, &mut b);
    deliver(t(3), &old, &mut b);
    deliver(t(4), &new, &mut b);
    let e = b.get("1.var.x").unwrap().unwrap();
    assert_eq!((e.value.clone(), e.version), (Value::Int(2), 2));
    assert_eq!(b.stats().updates_stale, 1);
}

#[test]
fn a_restarted_robot_is_accepted_at_once_and_its_old_frames_are_dropped() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    for v in 0..3 {
        a.set(t(v), "*.var.x", Value::Int(v as i64)).unwrap();
    }
    let before_restart = frames(&mut a);
    deliver(t(5), &before_restart, &mut b);
    let mut a2 = robot(1, 99);
    a2.set(t(10), "*.var.x", Value::Int(42)).unwrap();
    deliver(t(11), &frames(&mut a2), &mut b);
    let e = b.get("1.var.x").unwrap().unwrap();
    assert_eq!(
        (e.value.clone(), e.version, e.incarnation),
        (Value::Int(42), 1, 99)
    );
    assert!(events(&mut b).contains(&Event::PeerRestarted {
        robot: 1,
        old_incarnation: 11,
        new_incarnation: 99
    }));
    deliver(t(12), &before_restart, &mut b);
    assert_eq!(b.get("1.var.x").unwrap().unwrap().value, Value::Int(42));
    assert_eq!(b.stats().drops(DropReason::RetiredIncarnation), 1);
}

#[test]
fn a_silent_robot_departs_after_three_refresh_periods_and_rejoins() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    a.handle_timeout(t(0));
    deliver(t(10), &frames(&mut a), &mut b);
    events(&mut b);
    assert!(
        b.poll_timeout().unwrap() <= t(310),
        "b must wake for the departure"
    );
    b.handle_timeout(t(309));
    assert!(!events(&mut b).contains(&Event::PeerDeparted { robot: 1 }));
    b.handle_timeout(t(310));
    assert!(events(&mut b).contains(&Event::PeerDeparted { robot: 1 }));
    assert!(!b.peers().next().unwrap().present);
    a.handle_timeout(t(400));
    deliver(t(400), &frames(&mut a), &mut b);
    assert!(events(&mut b).contains(&Event::PeerJoined {
        robot: 1,
        incarnation: 11
    }));
}

#[test]
fn a_robot_that_reappears_gets_a_full_refresh_at_once() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    b.set(t(0), "*.var.y", Value::Int(5)).unwrap();
    b.handle_timeout(t(0));
    frames(&mut b);
    a.handle_timeout(t(0));
    deliver(t(10), &frames(&mut a), &mut b);
    assert!(
        frames(&mut b).is_empty(),
        "b's refresh of 10 ms ago serves a newcomer heard now: no extra copy"
    );
    b.handle_timeout(t(310));
    assert!(events(&mut b).contains(&Event::PeerDeparted { robot: 1 }));
    frames(&mut b); // the periodic refresh at 310 ms, lost while a is away
    a.handle_timeout(t(340));
    deliver(t(350), &frames(&mut a), &mut b);
    let extra = frames(&mut b);
    assert!(
        !extra.is_empty(),
        "a reappears at 350 ms: b re-sends what it owns now, not at 410 ms"
    );
    let mut c = robot(3, 33);
    deliver(t(351), &extra, &mut c);
    assert_eq!(
        c.get("2.var.y").unwrap().map(|e| e.value.clone()),
        Some(Value::Int(5)),
        "the extra copy is a full refresh"
    );
    assert_eq!(
        b.poll_timeout(),
        Some(t(410)),
        "the periodic schedule is unchanged"
    );
}

#[test]
fn a_large_blackboard_spans_several_frames_none_above_the_mtu() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    for i in 0..100 {
        a.set(
            t(0),
            &format!("*.var.item{i}"),
            Value::Bytes(vec![i as u8; 50]),
        )
        .unwrap();
    }
    frames(&mut a);
    a.handle_timeout(t(100));
    let refresh = frames(&mut a);
    assert!(refresh.len() >= 5, "{} frames for ~6 KB", refresh.len());
    assert!(
        refresh.iter().all(|f| f.len() <= 1200),
        "sizes {:?}",
        refresh.iter().map(Vec::len).collect::<Vec<_>>()
    );
    deliver(t(101), &refresh, &mut b);
    assert_eq!(b.iter(&Pattern::parse("1.var.#").unwrap()).count(), 100);
}

#[test]
fn bad_datagrams_are_counted_drops_that_lose_nothing() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    a.set(t(0), "*.var.x", Value::Int(1)).unwrap();
    deliver(t(1), &frames(&mut a), &mut b);
    let mut other_team = Replica::new(ReplicaConfig::new(3, 8), 3, t(0)).unwrap();
    other_team.set(t(0), "*.var.x", Value::Int(9)).unwrap();
    deliver(t(2), &frames(&mut other_team), &mut b);
    b.handle_datagram(t(3), addr(), b"hello");
    b.handle_datagram(t(3), addr(), &[]);
    b.handle_datagram(t(3), addr(), &vec![0x48; 5000]);
    a.set(t(4), "*.var.x", Value::Int(2)).unwrap();
    let good = frames(&mut a).remove(0);
    b.handle_datagram(t(5), addr(), &good[..good.len() - 2]);
    let s = b.stats();
    assert_eq!(
        [
            DropReason::OtherTeam,
            DropReason::BadMagic,
            DropReason::TooShort,
            DropReason::Oversized,
            DropReason::Malformed
        ]
        .map(|r| s.drops(r)),
        [1, 1, 1, 1, 1]
    );
    assert_eq!(
        b.get("1.var.x").unwrap().unwrap().value,
        Value::Int(1),
        "still the last good value"
    );
    assert!(b.get("3.var.x").unwrap().is_none());
    assert!(events(&mut b).iter().any(|e| matches!(
        e,
        Event::FrameDropped {
            reason: DropReason::OtherTeam,
            ..
        }
    )));
    b.handle_timeout(t(100));
    let mirrored = b
        .get("local.var.huddle.stats.drops.other_team")
        .unwrap()
        .unwrap();
    assert_eq!(mirrored.value, Value::Int(1));
    assert_eq!(
        b.get("local.var.huddle.stats.drops.total")
            .unwrap()
            .unwrap()
            .value,
        Value::Int(5)
    );
}

#[test]
fn with_a_team_key_forged_untagged_and_replayed_frames_are_dropped() {
    let keyed = |id, inc, key: &[u8]| {
        Replica::new(ReplicaConfig::new(id, 7).with_team_key(key), inc, t(0)).unwrap()
    };
    let (mut a, mut b) = (keyed(1, 11, b"k1"), keyed(2, 22, b"k1"));
    a.set(t(0), "*.var.x", Value::Int(1)).unwrap();
    let f1 = frames(&mut a);
    deliver(t(1), &f1, &mut b);
    assert_eq!(b.get("1.var.x").unwrap().unwrap().value, Value::Int(1));
    a.set(t(2), "*.var.x", Value::Int(2)).unwrap();
    deliver(t(3), &frames(&mut a), &mut b);
    deliver(t(4), &f1, &mut b);
    assert_eq!(
        b.stats().drops(DropReason::Replay),
        1,
        "same incarnation, old seq"
    );
    let mut plain = robot(3, 33);
    plain.set(t(0), "*.var.x", Value::Int(3)).unwrap();
    deliver(t(5), &frames(&mut plain), &mut b);
    let mut forger = keyed(4, 44, b"guess");
    forger.set(t(0), "*.var.x", Value::Int(4)).unwrap();
    deliver(t(6), &frames(&mut forger), &mut b);
    assert_eq!(b.stats().drops(DropReason::MissingTag), 1);
    assert_eq!(b.stats().drops(DropReason::BadTag), 1);
    assert_eq!(b.get("*.var.x").unwrap().unwrap().value, Value::Int(2));
}

#[test]
fn writes_that_cannot_be_replicated_are_refused() {
    let mut a = robot(1, 11);
    assert!(matches!(
        a.set(t(0), "2.var.x", Value::Int(1)),
        Err(SetError::NotOwner { owner: 2, .. })
    ));
    assert!(matches!(
        a.set(t(0), "*.var.big", Value::Bytes(vec![0; 1200])),
        Err(SetError::TooLarge { .. })
    ));
    assert!(
        a.set(t(0), "local.var.big", Value::Bytes(vec![0; 5000]))
            .is_ok(),
        "local values have no size limit"
    );
    assert!(matches!(
        a.set(t(0), "*.talk.q", Value::Int(1)),
        Err(SetError::TalkKey(_))
    ));
    assert!(matches!(
        a.post(t(0), "*.var.q", Value::Int(1)),
        Err(PostError::NotOwnQueue(_))
    ));
    assert!(matches!(
        a.post(t(0), "2.talk.q", Value::Int(1)),
        Err(PostError::NotOwnQueue(_))
    ));
    assert!(matches!(
        a.post(t(0), "*.talk.q", Value::Bytes(vec![0; 1200])),
        Err(PostError::TooLarge { .. })
    ));
    assert_eq!(a.post(t(0), "1.talk.q", Value::Int(1)), Ok(1));
    assert_eq!(a.post(t(0), "*.talk.q", Value::Int(2)), Ok(2));
    assert!(matches!(
        Replica::new(ReplicaConfig::new(0, 7), 1, t(0)),
        Err(ConfigInvalid::RobotId(0))
    ));
}

#[test]
fn own_looped_back_frames_are_ignored_and_a_twin_id_is_reported() {
    let mut a = robot(1, 11);
    a.set(t(0), "*.var.x", Value::Int(1)).unwrap();
    let own = frames(&mut a);
    deliver(t(1), &own, &mut a);
    assert_eq!((a.stats().own_frames, a.stats().drops_total()), (1, 0));
    let mut twin = robot(1, 12);
    twin.set(t(0), "*.var.x", Value::Int(5)).unwrap();
    deliver(t(1), &frames(&mut twin), &mut a);
    assert_eq!(a.stats().drops(DropReason::RobotIdConflict), 1);
    assert_eq!(a.get("1.var.x").unwrap().unwrap().value, Value::Int(1));
}

#[test]
fn a_lost_talk_message_is_repaired_by_nack_and_delivered_in_order() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    b.handle_timeout(t(0)); // start-up heartbeat, so the next wake-up is a talk timer
    frames(&mut b);
    let mut wire_ab = Vec::new();
    for i in 1..=3 {
        a.post(t(0), "*.talk.plan", Value::Int(i)).unwrap();
        wire_ab.push(frames(&mut a));
    }
    deliver(t(1), &wire_ab[0], &mut b);
    deliver(t(1), &wire_ab[2], &mut b); // message 2 lost
    let got: Vec<i64> = events(&mut b)
        .into_iter()
        .filter_map(|e| match e {
            Event::TalkDelivered {
                value: Value::Int(v),
                ..
            } => Some(v),
            _ => None,
        })
        .collect();
    assert_eq!(got, [1], "3 waits for 2");
    let wake = b.poll_timeout().unwrap();
    assert_eq!(
        wake,
        t(21),
        "first NACK one nack_interval after the gap appeared"
    );
    b.handle_timeout(wake);
    let nack = frames(&mut b);
    deliver(t(22), &nack, &mut a);
    assert_eq!(a.stats().talk_resent, 1);
    deliver(t(23), &frames(&mut a), &mut b);
    let got: Vec<(u64, Value)> = events(&mut b)
        .into_iter()
        .filter_map(|e| match e {
            Event::TalkDelivered {
                seq,
                value,
                from: 1,
                ..
            } => Some((seq, value)),
            _ => None,
        })
        .collect();
    assert_eq!(got, [(2, Value::Int(2)), (3, Value::Int(3))]);
}

#[test]
fn an_unrepairable_talk_gap_is_given_up_with_an_event() {
    let mut cfg = ReplicaConfig::new(1, 7);
    cfg.talk.retain = 2;
    // The sender gives its own receivers 1 ms: posts a millisecond apart may then evict.
    cfg.talk.give_up_after = Duration::from_millis(1);
    let mut a = Replica::new(cfg, 11, t(0)).unwrap();
    let mut b = robot(2, 22);
    for i in 1..=5 {
        a.post(t(i as u64), "*.talk.q", Value::Int(i)).unwrap();
    }
    frames(&mut a); // all lost
    a.handle_timeout(t(100));
    deliver(t(100), &frames(&mut a), &mut b);
    let evs: Vec<Event> = events(&mut b)
        .into_iter()
        .filter(|e| matches!(e, Event::TalkGivenUp { .. } | Event::TalkDelivered { .. }))
        .collect();
    assert_eq!(
        evs,
        [Event::TalkGivenUp {
            queue: "q".into(),
            from: 1,
            first: 1,
            last: 3
        }],
        "only 4 and 5 are still held"
    );
    b.handle_timeout(t(120));
    deliver(t(121), &frames(&mut b), &mut a);
    deliver(t(122), &frames(&mut a), &mut b);
    let seqs: Vec<u64> = events(&mut b)
        .into_iter()
        .filter_map(|e| match e {
            Event::TalkDelivered { seq, .. } => Some(seq),
            _ => None,
        })
        .collect();
    assert_eq!(seqs, [4, 5]);
    assert_eq!(b.stats().talk_given_up, 3);
}

#[test]
fn a_restart_gives_up_the_old_queues_holes_and_starts_the_new_queue_at_one() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    let mut sent = Vec::new();
    for i in 1..=3 {
        a.post(t(0), "*.talk.q", Value::Int(i)).unwrap();
        sent.push(frames(&mut a));
    }
    deliver(t(1), &sent[0], &mut b);
    deliver(t(1), &sent[2], &mut b); // 2 is lost, then robot 1 reboots
    events(&mut b);
    let mut a2 = robot(1, 12);
    a2.post(t(50), "*.talk.q", Value::Int(100)).unwrap();
    deliver(t(51), &frames(&mut a2), &mut b);
    let talk: Vec<Event> = events(&mut b)
        .into_iter()
        .filter(|e| matches!(e, Event::TalkDelivered { .. } | Event::TalkGivenUp { .. }))
        .collect();
    let delivered = |seq, v| Event::TalkDelivered {
        queue: "q".into(),
        from: 1,
        seq,
        value: Value::Int(v),
    };
    assert_eq!(
        talk,
        [
            Event::TalkGivenUp {
                queue: "q".into(),
                from: 1,
                first: 2,
                last: 2
            },
            delivered(3, 3),
            delivered(1, 100),
        ],
        "the old incarnation's gap is reported, its tail delivered, the new queue starts at 1"
    );
}

#[test]
fn configurations_that_cannot_work_are_refused() {
    let with = |f: fn(&mut ReplicaConfig)| {
        let mut cfg = ReplicaConfig::new(1, 7);
        f(&mut cfg);
        Replica::new(cfg, 1, t(0)).err()
    };
    assert_eq!(with(|c| c.mtu = 63), Some(ConfigInvalid::Mtu(63)));
    assert_eq!(with(|c| c.mtu = 70_000), Some(ConfigInvalid::Mtu(70_000)));
    assert_eq!(
        with(|c| c.refresh_period = Duration::ZERO),
        Some(ConfigInvalid::Period)
    );
    assert_eq!(with(|c| c.talk.window = 0), Some(ConfigInvalid::TalkLimits));
    assert_eq!(
        with(|c| c.robot_id = 255),
        Some(ConfigInvalid::RobotId(255))
    );
    assert_eq!(with(|_| {}), None);
    let cfg = ReplicaConfig::new(1, 7).with_refresh_period(Duration::from_millis(50));
    assert_eq!(cfg.departed_after, Duration::from_millis(150));
}

proptest::proptest! {
    #[test]
    fn any_well_formed_frame_from_a_teammate_is_handled_without_panic(
        frames in proptest::collection::vec(crate::wire::tests::any_frame(), 1..6),
        later_ms in 0u64..5_000,
    ) {
        let mut r = robot(9, 99);
        for (i, mut f) in frames.into_iter().enumerate() {
            f.team = 7;
            if i % 2 == 0 {
                // Half of them name this robot in their NACKs.
                for item in &mut f.items {
                    if let Item::Nack { target, .. } = item {
                        *target = 9;
                    }
                }
            }
            r.handle_datagram(t(i as u64), addr(), &wire::encode_frame(&f, None));
        }
        r.post(t(10), "*.talk.q", Value::Int(1)).unwrap();
        for now in [t(20), t(40), t(1_100), t(later_ms + 1_100)] {
            r.handle_timeout(now);
            while r.poll_transmit().is_some() {}
            while r.poll_event().is_some() {}
        }
        let s = r.stats();
        let expected = s.drops(DropReason::RobotIdConflict) + s.drops(DropReason::RetiredIncarnation);
        proptest::prop_assert_eq!(s.drops_total(), expected, "well-formed frames decode");
    }
}

#[test]
fn a_change_polled_with_its_slot_reads_the_binding_the_blackboard_holds() {
    let (mut a, mut b) = (robot(1, 11), robot(2, 22));
    a.set(t(1), "*.var.ball.dist", Value::Float(1.5)).unwrap();
    deliver(t(2), &frames(&mut a), &mut b);
    b.set(t(3), "local.var.mode", Value::Int(2)).unwrap();
    b.set(t(3), "*.var.pose", Value::Int(7)).unwrap();
    let mut changed = Vec::new();
    while let Some((event, at)) = b.poll_event_at() {
        if let Event::ValueChanged { key } = event {
            let at = at.expect("a value change says where its binding is");
            let entry = b.changed_entry(&key, at).cloned();
            assert_eq!(entry.as_ref(), b.blackboard().get(&key), "{key}");
            changed.push((key.to_string(), entry.map(|e| e.value)));
        } else {
            assert!(at.is_none(), "{event:?} is no value change");
        }
    }
    assert_eq!(
        changed,
        [
            ("1.var.ball.dist".to_string(), Some(Value::Float(1.5))),
            ("local.var.mode".to_string(), Some(Value::Int(2))),
            ("2.var.pose".to_string(), Some(Value::Int(7))),
        ]
    );
}
