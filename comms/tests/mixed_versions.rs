//! A team mid-upgrade: two robots of this build and one of a newer build that adds an item
//! type this build does not know to every frame and registers one more known path. The
//! team keeps replicating every key both builds know, and no frame is dropped as
//! malformed: the unknown items are skipped and counted. Then a robot of an older build
//! (format 3) joins, and this build answers it in format 3 while it is present.

use std::net::SocketAddr;

use comms::wire::{FrameWriter, ItemRef, KnownPaths, TeamKey, LEGACY_VERSION, TAG_LEN, VERSION};
use comms::{DropReason, Instant, Replica, ReplicaConfig, Value};

const TEAM: u8 = 7;
const KEY: &[u8] = b"team secret";
const TABLE: [&str; 4] = [
    "machine.heuristic",
    "world.local",
    "machine.pass_to",
    "audio.heard",
];

fn config(id: u8, newer: bool) -> ReplicaConfig {
    let mut paths: Vec<&str> = TABLE.to_vec();
    if newer {
        // The newer build's table grew at its end.
        paths.push("ball.seen_by_feet");
    }
    ReplicaConfig::new(id, TEAM)
        .with_team_key(KEY.to_vec())
        .with_known_paths(KnownPaths::new(paths).expect("valid paths"))
}

/// What the newer build puts in its frames: item type 9 with 3 bytes of fields, inserted
/// before the tag (format 4 items run to the end of the body), and the tag made again.
fn add_future_item(frame: &[u8]) -> Vec<u8> {
    assert_eq!(frame[2], VERSION, "a format 4 frame");
    let mut out = frame[..frame.len() - TAG_LEN].to_vec();
    out.extend_from_slice(&[9, 3, 0xf0, 0x0d, 0x01]);
    let tag = TeamKey::new(KEY).tag(&out);
    out.extend_from_slice(&tag);
    out
}

fn at_ms(ms: u64) -> Instant {
    Instant::from_micros(1_000_000 + ms * 1000)
}

#[test]
fn a_newer_builds_unknown_items_are_skipped_and_every_shared_key_replicates() {
    let from = SocketAddr::from(([127, 0, 0, 1], 2000));
    let mut team: Vec<Replica> = (1..=3u8)
        .map(|id| Replica::new(config(id, id == 3), u64::from(id) * 77, at_ms(0)).unwrap())
        .collect();
    let mut last = [0i64; 3];
    for step in 0..200u64 {
        let now = at_ms(step * 10);
        for (i, r) in team.iter_mut().enumerate() {
            let v = (step * 10 + i as u64) as i64;
            r.set(now, "*.var.pose.x", Value::Int(v)).unwrap();
            r.set(now, "*.var.machine.heuristic", Value::Float(v as f64))
                .unwrap();
            last[i] = v;
            if i == 2 {
                r.set(now, "*.var.ball.seen_by_feet", Value::Bool(true))
                    .unwrap();
            }
            r.handle_timeout(now);
        }
        let mut frames = Vec::new();
        for (i, r) in team.iter_mut().enumerate() {
            while let Some(t) = r.poll_transmit() {
                let bytes = if i == 2 {
                    add_future_item(&t.payload)
                } else {
                    t.payload
                };
                frames.push((i, bytes));
            }
        }
        for (sender, bytes) in &frames {
            for (i, r) in team.iter_mut().enumerate() {
                if i != *sender {
                    r.handle_datagram(now, from, bytes);
                }
            }
        }
    }
    for (i, r) in team.iter().enumerate() {
        let s = r.stats();
        assert_eq!(
            s.drops(DropReason::Malformed),
            0,
            "robot {}: no frame dropped as malformed",
            i + 1
        );
        assert_eq!(
            s.drops_total(),
            0,
            "robot {}: no frame dropped at all",
            i + 1
        );
        for (j, &v) in last.iter().enumerate() {
            if i == j {
                continue;
            }
            let owner = j + 1;
            let x = r.get(&format!("{owner}.var.pose.x")).unwrap();
            assert_eq!(
                x.map(|e| &e.value),
                Some(&Value::Int(v)),
                "robot {} holds robot {owner}'s latest pose.x",
                i + 1
            );
            let h = r.get(&format!("{owner}.var.machine.heuristic")).unwrap();
            assert_eq!(
                h.map(|e| &e.value),
                Some(&Value::Float(v as f64)),
                "robot {} holds robot {owner}'s claim (a known path, one byte on the wire)",
                i + 1
            );
        }
    }
    for (i, r) in team.iter().take(2).enumerate() {
        let s = r.stats();
        assert!(
            s.items_skipped >= 2 * 200,
            "robot {}: robot 3's item 9 and its newer known path skipped and counted ({})",
            i + 1,
            s.items_skipped
        );
        assert!(r.get("3.var.ball.seen_by_feet").unwrap().is_none());
    }
    assert_eq!(
        team[2].get("1.var.pose.x").unwrap().map(|e| &e.value),
        Some(&Value::Int(last[0])),
        "the newer build hears this one"
    );
    assert_eq!(
        team[2].stats().items_skipped,
        0,
        "the newer build knows everything"
    );
}

#[test]
fn this_build_speaks_format_3_while_an_older_teammate_is_present() {
    let from = SocketAddr::from(([127, 0, 0, 1], 2000));
    let mut r1 = Replica::new(config(1, false), 11, at_ms(0)).unwrap();
    r1.set(at_ms(0), "*.var.pose.x", Value::Int(1)).unwrap();
    r1.handle_timeout(at_ms(0));
    let first = r1.poll_transmit().expect("a first frame").payload;
    assert_eq!(first[2], VERSION, "alone: format 4");
    // Robot 4 runs an older build: its frames are format 3, its claim by index 0.
    let key = TeamKey::new(KEY);
    let table = KnownPaths::new(TABLE).unwrap();
    let old_frame = |seq: u64| {
        let mut w = FrameWriter::new(TEAM, 4, 44, seq, 1200, Some(&key))
            .with_known_paths(&table)
            .with_version(LEGACY_VERSION);
        assert!(w.push(ItemRef::Update {
            path: "machine.heuristic",
            value: &Value::Float(2.5),
            version: seq,
            age_us: 0,
        }));
        w.finish()
    };
    r1.handle_datagram(at_ms(5), from, &old_frame(1));
    assert_eq!(
        r1.get("4.var.machine.heuristic").unwrap().map(|e| &e.value),
        Some(&Value::Float(2.5)),
        "a format 3 frame is read, its known path by the same table"
    );
    r1.set(at_ms(10), "*.var.pose.x", Value::Int(2)).unwrap();
    let answer = r1.poll_transmit().expect("news goes").payload;
    assert_eq!(answer[2], LEGACY_VERSION, "robot 4 present: format 3");
    // Robot 4 upgrades and leaves the old build behind; once it is silent as a format 3
    // speaker (departed), frames go back to format 4.
    r1.handle_timeout(at_ms(2000));
    r1.set(at_ms(2000), "*.var.pose.x", Value::Int(3)).unwrap();
    let later = r1.poll_transmit().expect("news goes").payload;
    assert!(r1.is_departed(4), "robot 4 silent for 2 s");
    assert_eq!(later[2], VERSION, "no format 3 teammate present: format 4");
}
