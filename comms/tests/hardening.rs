//! What a replica does when the team's network carries frames that do not belong: replays
//! of a robot's earlier life, a stray frame with a forged incarnation, a second robot with
//! a teammate's id, spoofed NACKs and talk heads; and whether talk survives steady loss.
//! Each scenario is a story with one assertion per claim; the network is netsim's or a
//! hand-carried list of frames.

use std::net::SocketAddr;
use std::time::Duration;

use comms::wire::{encode_frame, Frame, Item};
use comms::{DropReason, Event, Instant, PostError, Replica, ReplicaConfig, Value};
use comms_netsim::Harness;
use netsim::{LinkConfig, Sim, Time};

const TEAM: u8 = 7;
const KEY: &[u8] = b"robocup team key";

fn t(ms: u64) -> Instant {
    Instant::from_micros(1_000_000 + ms * 1000)
}

fn addr() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 2000))
}

fn robot(id: u8, incarnation: u64, keyed: bool) -> Replica {
    let mut cfg = ReplicaConfig::new(id, TEAM);
    if keyed {
        cfg = cfg.with_team_key(KEY.to_vec());
    }
    Replica::new(cfg, incarnation, t(0)).expect("a valid config")
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

fn value(r: &Replica, key: &str) -> Option<Value> {
    r.get(key).expect("a valid key").map(|e| e.value.clone())
}

/// A robot's life recorded by an attacker, then the robot restarts. Neither a receiver
/// that knows the new life nor one that heard nine lives in between lets the replay
/// change a value, deliver talk, or cut the current life off.
#[test]
fn a_replayed_frame_of_an_earlier_life_changes_nothing_at_a_receiver_that_knows_the_current_one() {
    let mut old = robot(1, 1_000 << 16, true);
    old.set(t(0), "*.var.ball.seen", Value::Bool(true)).unwrap();
    old.post(t(0), "*.talk.plan", Value::from("old plan"))
        .unwrap();
    let recorded = frames(&mut old);

    // Robot 1 restarts (a later start: a larger incarnation); robot 2 started after that.
    let mut new = robot(1, 2_000 << 16, true);
    new.set(t(100), "*.var.ball.seen", Value::Bool(false))
        .unwrap();
    let mut receiver = robot(2, 3_000 << 16, true);
    deliver(t(101), &frames(&mut new), &mut receiver);
    events(&mut receiver);

    deliver(t(200), &recorded, &mut receiver);
    assert_eq!(
        value(&receiver, "1.var.ball.seen"),
        Some(Value::Bool(false)),
        "the replay rolled the value back"
    );
    let after_replay = events(&mut receiver);
    assert!(
        !after_replay
            .iter()
            .any(|e| matches!(e, Event::TalkDelivered { .. } | Event::PeerRestarted { .. })),
        "the replay delivered talk or retired the current life: {after_replay:?}"
    );
    assert!(receiver.stats().drops(DropReason::RetiredIncarnation) >= 1);

    // The current life is still heard.
    new.set(t(300), "*.var.ball.seen", Value::Bool(true))
        .unwrap();
    deliver(t(301), &frames(&mut new), &mut receiver);
    assert_eq!(
        value(&receiver, "1.var.ball.seen"),
        Some(Value::Bool(true)),
        "the current life was cut off by the replay"
    );

    // Ten restarts later, the first life's frames are still refused (they fell out of
    // the remembered lives long ago, and are older than the current one).
    let mut listener = robot(3, 4_000 << 16, true);
    for life in 1..=10u64 {
        let mut r = robot(1, (10_000 + life) << 16, true);
        r.set(t(400 + life), "*.var.life", Value::Int(life as i64))
            .unwrap();
        deliver(t(400 + life), &frames(&mut r), &mut listener);
    }
    deliver(t(500), &recorded, &mut listener);
    assert_eq!(value(&listener, "1.var.life"), Some(Value::Int(10)));
    assert_eq!(
        value(&listener, "1.var.ball.seen"),
        None,
        "a value from the first life appeared after ten restarts"
    );
}

/// Without a key a team trusts its LAN, but one stray frame (here a bare header naming
/// robot 1 with a huge incarnation) must not lock robot 1 out: robot 1 keeps sending in
/// its own life and is heard again within the departure limit and a few frames.
#[test]
fn one_stray_frame_with_a_forged_incarnation_locks_nobody_out() {
    let mut one = robot(1, 10 << 16, false);
    let mut two = robot(2, 20 << 16, false);
    one.set(t(0), "*.var.k", Value::Int(0)).unwrap();
    deliver(t(1), &frames(&mut one), &mut two);

    let stray = Frame {
        team: TEAM,
        sender: 1,
        incarnation: u64::MAX,
        seq: 1,
        clock: Default::default(),
        items: vec![],
    };
    two.handle_datagram(t(5), addr(), &encode_frame(&stray, None));

    // Robot 1 goes on publishing every 100 ms (its refresh) for one second.
    for k in 1..=10u64 {
        let now = t(5 + 100 * k);
        one.set(now, "*.var.k", Value::Int(k as i64)).unwrap();
        one.handle_timeout(now);
        deliver(now, &frames(&mut one), &mut two);
        two.handle_timeout(now);
    }
    assert_eq!(
        value(&two, "1.var.k"),
        Some(Value::Int(10)),
        "robot 1 is still locked out one second after one stray frame"
    );
}

/// A second daemon started with robot 1's id (a later start, so a larger incarnation)
/// talks for 10 s, then leaves. Receivers report the conflict (event, counter, peer
/// flag) while both talk, and hear the real robot 1 again within 1 s of the impostor
/// leaving.
#[test]
fn a_duplicate_id_is_reported_and_the_real_robot_is_heard_again_once_the_impostor_leaves() {
    let mut real = robot(1, 10 << 16, true);
    let mut impostor = robot(1, 50 << 16, true);
    let mut two = robot(2, 20 << 16, true);
    let mut conflicts = 0;
    let step = |now: Instant, r: &mut Replica, two: &mut Replica, k: i64| {
        r.set(now, "*.var.k", Value::Int(k)).unwrap();
        r.handle_timeout(now);
        deliver(now, &frames(r), two);
    };
    for i in 0..100u64 {
        let now = t(100 * i);
        step(now, &mut real, &mut two, i as i64);
        step(now + Duration::from_millis(50), &mut impostor, &mut two, -1);
        two.handle_timeout(now);
        conflicts += events(&mut two)
            .iter()
            .filter(|e| matches!(e, Event::IncarnationConflict { robot: 1, .. }))
            .count();
    }
    assert!(conflicts >= 5, "{conflicts} conflict reports in 10 s");
    assert!(two.stats().id_conflicts >= 5);
    assert!(
        two.peers().any(|p| p.robot == 1 && p.conflicting),
        "robot 1 is not marked conflicting"
    );
    assert_eq!(
        value(&two, "1.var.k"),
        Some(Value::Int(-1)),
        "the newer start wins"
    );

    // The impostor leaves; the real robot goes on.
    for i in 100..110u64 {
        let now = t(100 * i);
        step(now, &mut real, &mut two, i as i64);
        two.handle_timeout(now);
    }
    assert_eq!(
        value(&two, "1.var.k"),
        Some(Value::Int(109)),
        "the real robot 1 is not heard 1 s after the impostor left"
    );
}

/// Spoofed NACKs for a robot holding 256 messages of 1 kB: the repairs it sends stay
/// within twice what it posted (one re-send per message, and a second for some: what real
/// loss needs) plus a small margin, however many NACKs arrive.
#[test]
fn spoofed_nacks_cannot_make_a_robot_send_more_than_twice_what_it_posted() {
    let mut victim = robot(1, 10 << 16, false);
    let mut posted_bytes = 0usize;
    for i in 0..256u64 {
        let now = t(4 * i);
        victim
            .post(now, "*.talk.q", Value::Bytes(vec![0xab; 1000]))
            .unwrap();
        posted_bytes += 1000;
    }
    frames(&mut victim);
    let before = victim.stats().bytes_out;
    let mut nack_bytes = 0usize;
    for i in 0..2_000u64 {
        let now = t(2_000 + i);
        let nack = Frame {
            team: TEAM,
            sender: 9,
            incarnation: 9 << 16,
            seq: i + 1,
            clock: Default::default(),
            items: vec![Item::Nack {
                target: 1,
                queue: "q".into(),
                first: 1,
                last: 256,
            }],
        };
        let bytes = encode_frame(&nack, None);
        nack_bytes += bytes.len();
        victim.handle_datagram(now, addr(), &bytes);
        frames(&mut victim);
    }
    let sent = (victim.stats().bytes_out - before) as usize;
    // Framing (a header per frame of re-sends, ~3%), heartbeats and heads over those 2 s,
    // and the time-earned trickle.
    let margin = posted_bytes / 20 + 16 * 1024;
    assert!(
        sent <= 2 * posted_bytes + margin,
        "{sent} bytes out for {nack_bytes} bytes of NACKs after posting {posted_bytes}"
    );
    println!(
        "{nack_bytes} bytes of spoofed NACKs drew {sent} bytes ({:.1}x)",
        sent as f64 / nack_bytes as f64
    );
    assert!(
        victim.stats().talk_repair_limited > 0,
        "the limit was counted"
    );
}

/// A forged talk head claiming messages up to 2^62, from a teammate's id: nothing is
/// given up in bulk, and the teammate's real messages keep being delivered.
#[test]
fn a_forged_talk_head_neither_silences_a_queue_nor_inflates_the_losses() {
    let mut one = robot(1, 10 << 16, false);
    let mut two = robot(2, 20 << 16, false);
    one.post(t(0), "*.talk.q", Value::Int(1)).unwrap();
    deliver(t(1), &frames(&mut one), &mut two);
    let forged = Frame {
        team: TEAM,
        sender: 1,
        incarnation: 10 << 16,
        seq: 1_000,
        clock: Default::default(),
        items: vec![Item::TalkHead {
            queue: "q".into(),
            first: 1 << 62,
            last: 1 << 62,
        }],
    };
    two.handle_datagram(t(2), addr(), &encode_frame(&forged, None));
    for k in 2..=5 {
        let now = t(100 * k);
        one.post(now, "*.talk.q", Value::Int(k as i64)).unwrap();
        one.handle_timeout(now);
        deliver(now, &frames(&mut one), &mut two);
        two.handle_timeout(now);
    }
    let delivered: Vec<i64> = events(&mut two)
        .into_iter()
        .filter_map(|e| match e {
            Event::TalkDelivered {
                value: Value::Int(v),
                ..
            } => Some(v),
            _ => None,
        })
        .collect();
    assert_eq!(delivered, [1, 2, 3, 4, 5], "the queue went silent");
    assert_eq!(two.stats().talk_given_up, 0);
}

/// A receiver that starts after the sender has been running for 10 s and posted 100
/// messages does not get them as if new; it gets what is posted once it is listening.
#[test]
fn a_late_joiner_starts_at_the_senders_current_position() {
    let mut one = robot(1, 10 << 16, false);
    for i in 1..=100u64 {
        let now = t(100 * i);
        one.post(now, "*.talk.q", Value::Int(i as i64)).unwrap();
        one.handle_timeout(now);
        frames(&mut one);
    }
    let mut late = robot(2, 20 << 16, false);
    for k in 0..5u64 {
        let now = t(10_050 + 100 * k);
        if k >= 2 {
            one.post(now, "*.talk.q", Value::Int(1_000 + k as i64))
                .unwrap();
        }
        one.handle_timeout(now);
        deliver(now, &frames(&mut one), &mut late);
        late.handle_timeout(now);
    }
    let delivered: Vec<i64> = events(&mut late)
        .into_iter()
        .filter_map(|e| match e {
            Event::TalkDelivered {
                value: Value::Int(v),
                ..
            } => Some(v),
            _ => None,
        })
        .collect();
    assert_eq!(delivered, [1_002, 1_003, 1_004]);
    assert_eq!(
        late.stats().talk_given_up,
        0,
        "nothing old reported lost either"
    );
}

/// Posting faster than the retention can hold for the give-up time is refused, not lost.
#[test]
fn a_post_that_would_evict_a_message_still_being_repaired_is_refused() {
    let mut one = robot(1, 10 << 16, false);
    for i in 1..=256 {
        one.post(t(0), "*.talk.q", Value::Int(i)).unwrap();
    }
    assert!(matches!(
        one.post(t(0), "*.talk.q", Value::Int(257)),
        Err(PostError::RetentionFull { .. })
    ));
    assert_eq!(one.stats().talk_refused_full, 1);
    assert_eq!(
        one.post(t(1_000), "*.talk.q", Value::Int(257)),
        Ok(257),
        "once the oldest is older than the give-up time it may go"
    );
}

/// 2,000 messages at 100 a second over a link losing 30% with 50 ms delay reach both
/// teammates exactly once, in order: each missing message gets its full give-up time
/// from when it was known missing, even though some gap is open almost all the time.
#[test]
fn talk_at_100_per_second_with_30_percent_loss_arrives_exactly_once_in_order() {
    for seed in 1..=5 {
        talk_at_100_per_second(seed);
    }
}

fn talk_at_100_per_second(seed: u64) {
    let link = LinkConfig {
        latency: Duration::from_millis(50),
        loss: 0.3,
        ..LinkConfig::default()
    };
    let net = Sim::builder().link(link).record_trace(false);
    let mut team = Harness::new(3, net, ReplicaConfig::new(1, TEAM), seed).expect("a valid team");
    // Robot 1 posts every 10 ms for 20 s; 5 s more for the last repairs.
    for k in 1..=2_000i64 {
        team.run_until(Time::from_millis(10 * (k as u64 - 1)));
        team.post(0, "*.talk.q", Value::Int(k)).unwrap();
    }
    team.run_until(Time::from_secs(25));
    let mut delivered: Vec<Vec<i64>> = vec![Vec::new(); 3];
    let mut given_up = 0u64;
    for (i, got) in delivered.iter_mut().enumerate() {
        for e in team.drain_events(i) {
            match e {
                Event::TalkDelivered {
                    value: Value::Int(v),
                    ..
                } => got.push(v),
                Event::TalkGivenUp { first, last, .. } => given_up += last - first + 1,
                _ => {}
            }
        }
    }
    let expected: Vec<i64> = (1..=2_000).collect();
    assert_eq!(given_up, 0, "seed {seed}: messages given up");
    for (i, got) in delivered.iter().enumerate().skip(1) {
        assert_eq!(
            got.len(),
            2_000,
            "seed {seed}: robot {} got {}",
            i + 1,
            got.len()
        );
        assert!(
            got == &expected,
            "seed {seed}: robot {} out of order",
            i + 1
        );
    }
}

/// With a key, a life this receiver never took as current cannot become current, even
/// while the robot is silent: a recording from another day replayed frame by frame (each
/// "fresh" to this receiver) changes nothing.
#[test]
fn with_a_key_a_replayed_life_never_heard_cannot_take_over_a_silent_robot() {
    let mut old_day = robot(1, 1_000 << 16, true);
    let mut recording = Vec::new();
    for k in 0..20u64 {
        old_day
            .set(t(100 * k), "*.var.role", Value::from("old day"))
            .unwrap();
        old_day.handle_timeout(t(100 * k));
        recording.extend(frames(&mut old_day));
    }
    let mut today = robot(1, 2_000 << 16, true);
    today.set(t(0), "*.var.role", Value::from("today")).unwrap();
    let mut receiver = robot(2, 3_000 << 16, true);
    deliver(t(1), &frames(&mut today), &mut receiver);
    // Robot 1 is switched off; the attacker replays the whole recording over 2 s.
    for (i, f) in recording.iter().enumerate() {
        let now = t(1_000 + 100 * i as u64);
        receiver.handle_datagram(now, addr(), f);
        receiver.handle_timeout(now);
    }
    assert_eq!(
        value(&receiver, "1.var.role"),
        Some(Value::from("today")),
        "a replayed life took over"
    );
}

/// Without a key, a robot whose clock went back at boot (no RTC) starts with a smaller
/// incarnation than its last life; it is heard again once that last life is silent.
#[test]
fn without_a_key_a_robot_rebooted_with_an_earlier_clock_is_heard_again() {
    let mut before = robot(1, 5_000 << 16, false);
    let mut two = robot(2, 20 << 16, false);
    before.set(t(0), "*.var.boot", Value::Int(1)).unwrap();
    deliver(t(1), &frames(&mut before), &mut two);
    let mut after = robot(1, 10 << 16, false);
    for k in 1..=10u64 {
        let now = t(100 * k);
        after.set(now, "*.var.boot", Value::Int(2)).unwrap();
        after.handle_timeout(now);
        deliver(now, &frames(&mut after), &mut two);
        two.handle_timeout(now);
    }
    assert_eq!(value(&two, "1.var.boot"), Some(Value::Int(2)));
}
