//! A pooled budget (SPL: 1,200 messages per team per 20-minute game) against frames that
//! claim the team has spent it: forged headers without a key, and with a team key
//! replayed frames of a teammate's earlier life or of a teammate absent today. In every
//! case the robot keeps sending within its own share (the pool's floor), and a replayed
//! frame of a life it never took as current counts for nothing.

use std::net::SocketAddr;

use comms::wire::{FrameWriter, ItemRef};
use comms::{BudgetSpec, Instant, Replica, ReplicaConfig, Value};

const TEAM: u8 = 7;
const KEY: &[u8] = b"robocup team key";

fn t(ms: u64) -> Instant {
    Instant::from_micros(1_000_000 + ms * 1000)
}

fn addr() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 2000))
}

fn pooled(id: u8, incarnation: u64, keyed: bool) -> Replica {
    let mut cfg = ReplicaConfig::new(id, TEAM).with_budget(&BudgetSpec::SPL, 5);
    if keyed {
        cfg = cfg.with_team_key(KEY.to_vec());
    }
    Replica::new(cfg, incarnation, t(0)).expect("a valid config")
}

/// A header-only frame (one update) from `sender` numbered `seq`, unkeyed.
fn forged(sender: u8, seq: u64) -> Vec<u8> {
    let mut w = FrameWriter::new(TEAM, sender, 9, seq, 128, None);
    w.push(ItemRef::Update {
        path: "x",
        value: &Value::Int(1),
        version: 1,
        age_us: 0,
    });
    w.finish()
}

/// Runs `r` with news every 100 ms from `from_ms` for `secs`, feeding `attack(ms)` frames
/// to it first each tick; returns the frames it sent.
fn chatty(
    r: &mut Replica,
    from_ms: u64,
    secs: u64,
    mut attack: impl FnMut(u64) -> Vec<Vec<u8>>,
) -> u64 {
    let mut sent = 0;
    for ms in (from_ms..from_ms + secs * 1000).step_by(100) {
        for f in attack(ms) {
            r.handle_datagram(t(ms), addr(), &f);
        }
        r.handle_timeout(t(ms));
        r.set(t(ms), "*.var.ball", Value::Int(ms as i64)).unwrap();
        while r.poll_transmit().is_some() {
            sent += 1;
        }
    }
    sent
}

/// An SPL robot's own equal part of the line over 600 s of a 1,200 s game: (1200 - 20) / 5
/// per game, half of it.
const OWN_HALF_GAME: u64 = 236 / 2;

#[test]
fn forged_headers_from_252_senders_and_one_absent_robot_leave_each_robot_its_own_share() {
    let mut r = pooled(1, 1, false);
    // Senders 3-254 numbered 1e9, then 160 headers as robot 2 (absent today).
    let mut burst: Vec<Vec<u8>> = (3..=254).map(|s| forged(s, 1_000_000_000)).collect();
    burst.extend((0..160).map(|i| forged(2, 1_000_000_000 + i)));
    let sent = chatty(&mut r, 0, 600, |ms| {
        // And again every 10 s: the claims keep coming.
        if ms % 10_000 == 0 {
            burst.clone()
        } else {
            Vec::new()
        }
    });
    assert!(
        sent >= OWN_HALF_GAME * 9 / 10,
        "the robot fell silent: {sent} frames in half a game, its own share is {OWN_HALF_GAME}"
    );
    let (own, _) = r.budget_status().unwrap();
    assert!(
        own <= BudgetSpec::SPL.team_messages / 5,
        "and within its share: {own}"
    );
}

/// A teammate's earlier life, signed with the team key, recorded and replayed once: the
/// receiver knows the current life, so the replay counts for nothing in its pool.
#[test]
fn with_a_key_one_replayed_frame_of_an_earlier_life_costs_the_pool_nothing() {
    // Robot 2's earlier life sent 381 frames; the attacker kept the last.
    let mut old = Replica::new(
        ReplicaConfig::new(2, TEAM).with_team_key(KEY.to_vec()),
        1_000 << 16,
        t(0),
    )
    .unwrap();
    let mut recorded = Vec::new();
    for i in 0..381 {
        old.set(t(i), "*.var.x", Value::Int(i as i64)).unwrap();
        while let Some(f) = old.poll_transmit() {
            recorded = f.payload;
        }
    }
    // Its current life, heard by robot 1 for 30 s (one frame a second).
    let mut mate = Replica::new(
        ReplicaConfig::new(2, TEAM)
            .with_team_key(KEY.to_vec())
            .with_budget(&BudgetSpec::SPL, 5),
        2_000 << 16,
        t(0),
    )
    .unwrap();
    let mut r = pooled(1, 3_000 << 16, true);
    for s in 0..30 {
        let now = t(s * 1000);
        mate.handle_timeout(now);
        mate.set(now, "*.var.x", Value::Int(s as i64)).unwrap();
        while let Some(f) = mate.poll_transmit() {
            r.handle_datagram(now, addr(), &f.payload);
        }
    }
    r.handle_timeout(t(30_000));
    let before = r.budget_status().unwrap().1;
    r.handle_datagram(t(30_001), addr(), &recorded);
    r.set(t(30_002), "*.var.ball", Value::Int(1)).unwrap();
    let _ = r.poll_transmit();
    let after = r.budget_status().unwrap().1;
    assert!(
        before - after <= 1,
        "the replayed frame (counter 381) counted: {before} messages left before, {after} after"
    );
}

/// A teammate absent today, its frames of another day replayed with their signatures: a
/// receiver that never heard it cannot tell them from a live robot, so they count, but
/// the robot keeps its own share.
#[test]
fn with_a_key_a_replayed_absent_teammate_does_not_silence_the_team() {
    let mut absent = Replica::new(
        ReplicaConfig::new(4, TEAM).with_team_key(KEY.to_vec()),
        1_000 << 16,
        t(0),
    )
    .unwrap();
    let mut recorded = Vec::new();
    for i in 0..1_500u64 {
        absent.set(t(i), "*.var.x", Value::Int(i as i64)).unwrap();
        while let Some(f) = absent.poll_transmit() {
            recorded.push(f.payload);
        }
    }
    let mut r = pooled(1, 3_000 << 16, true);
    let mut replay = recorded.chunks(100);
    let sent = chatty(&mut r, 0, 600, |ms| {
        // 100 recorded frames a second for the first 15 s.
        if ms % 1000 == 0 {
            replay.next().map(|c| c.to_vec()).unwrap_or_default()
        } else {
            Vec::new()
        }
    });
    assert!(
        sent >= OWN_HALF_GAME * 9 / 10,
        "the replay silenced the robot: {sent} frames in half a game, own share {OWN_HALF_GAME}"
    );
}
