//! The run loop under a flood of frames (issue #30): after a datagram whose reactions ran
//! the loop reads on at once instead of passing through its wait, and it looks at the
//! shutdown future only on passes that find nothing to read and on every 16th pass. A
//! socket that never runs dry must still let shutdown end the loop. Everything sends on
//! loopback only, to a group and port of the test's own.

#![allow(clippy::disallowed_methods)] // a real driver over loopback, real time

mod support;

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use comms::wire::{encode_frame, Frame, Item};
use comms::{ReplicaConfig, Value};
use driver::{open_multicast, scratch_group, Driver, DriverConfig, Notice, SocketConfig};
use support::run_local;

/// Robot 7's `seq`-th frame: `7.var.x` = `seq`, a new version each time.
fn frame(seq: u64) -> Vec<u8> {
    let frame = Frame {
        team: 0,
        sender: 7,
        incarnation: 1,
        seq,
        clock: Default::default(),
        items: vec![Item::Update {
            path: "x".into(),
            value: Value::Int(seq as i64),
            version: seq,
            age_us: 0,
        }],
    };
    encode_frame(&frame, None)
}

#[test]
fn shutdown_ends_the_run_loop_in_the_middle_of_a_flood_whose_every_frame_wakes_a_watch() {
    let group = scratch_group().unwrap();
    let reactions = Arc::new(AtomicU64::new(0));
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let (ended_tx, ended) = std::sync::mpsc::channel();
    // The member runs on a thread of its own, so that a loop that never yields shows as
    // a timeout here rather than a hung test.
    let member = {
        let reactions = reactions.clone();
        std::thread::spawn(move || {
            run_local(async move {
                let mut cfg = DriverConfig::new(ReplicaConfig::new(1, 0));
                cfg.socket.group = group;
                let member = Driver::bind(cfg).unwrap();
                let _watch = member
                    .handle()
                    .watch("7.var.x", move |_, notice| {
                        if let Notice::Changed { .. } = notice {
                            reactions.fetch_add(1, Ordering::Relaxed);
                            // A slow reaction: the flood outpaces the member, so its
                            // socket never runs dry.
                            let t = std::time::Instant::now();
                            while t.elapsed() < Duration::from_micros(50) {}
                        }
                    })
                    .unwrap();
                let result = member
                    .run(async {
                        let _ = stopped.await;
                    })
                    .await;
                let _ = ended_tx.send(result.is_ok());
            })
        })
    };

    // Robot 7 sends as fast as it can until told to stop.
    let flooding = Arc::new(AtomicBool::new(true));
    let flood = {
        let flooding = flooding.clone();
        std::thread::spawn(move || {
            let cfg = SocketConfig {
                group,
                ..SocketConfig::default()
            };
            let team = open_multicast(&cfg).unwrap().socket;
            let mut seq = 0;
            while flooding.load(Ordering::Relaxed) {
                seq += 1;
                // A full buffer is no failure here: the flood goes on.
                let _ = team.send_to(&frame(seq), group);
            }
            seq
        })
    };

    // Shut down once the watch has reacted to many frames, with the flood still on.
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while reactions.load(Ordering::Relaxed) < 200 && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(1));
    }
    let reacted = reactions.load(Ordering::Relaxed);
    stop.send(()).unwrap();
    let result = ended.recv_timeout(Duration::from_secs(10));
    flooding.store(false, Ordering::Relaxed);
    let sent = flood.join().unwrap();
    assert!(
        reacted >= 200,
        "the watch reacted to {reacted} of {sent} frames in 10 s"
    );
    let ok = result.unwrap_or_else(|_| {
        panic!("the member did not stop within 10 s of shutdown while {sent} frames flooded it")
    });
    assert!(ok, "the member's run failed");
    member.join().unwrap();
}
