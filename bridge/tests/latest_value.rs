//! The latest-value guarantee: a subscriber slower than the team (0.3 ms per sample,
//! while the team changes 600 keys many times a second) still gets every key's final
//! value, because the bridge merges superseded values instead of letting Zenoh drop
//! samples. With puts under Zenoh's drop congestion control (the bridge before its
//! outbox) the router dropped samples for such a subscriber, and since only changes are
//! published a dropped final value never came again.

#![allow(clippy::disallowed_methods)] // real sockets, real time

mod common;

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use common::{set_round, wait_until, BridgeProcess};
use huddle_bridge::harness::{client, free_port, router, Daemon, DaemonSpec};
use zenoh::Wait;

const TEAM: u8 = 7;
const VENUE: &str = "lab";
const KEYS: usize = 200;

/// 18,000 changes in about 0.6 s: run by CI. It passes with drop congestion control too
/// (Zenoh's queues and the loopback TCP buffers hold that much), so it checks the
/// guarantee, not the difference; the outbox's unit tests check the merging.
#[test]
fn a_slow_subscriber_gets_every_keys_final_value() {
    slow_subscriber(30, Duration::from_millis(20), Duration::from_secs(20));
}

/// 60,000 changes in about 1 s: this one lost all 600 final values under drop congestion
/// control and passed with the outbox, but it also failed once in three runs with the
/// outbox on the loaded VM (load average ~20): a Zenoh link that could not be written for
/// 5 s was closed (`wait_before_close`) with final values in it. This subscriber is a
/// plain one: it does not `get` when the bridge's token reappears, so values lost in its
/// own closed link stay lost (the bridge re-puts everything only when *its* link comes
/// back). `tests/recovery.rs` runs the same situation with the documented protocol.
/// Not in CI: `cargo test -p huddle-bridge --test latest_value -- --ignored`.
#[test]
#[ignore = "a plain subscriber (no get on the bridge's token) loses what a closed link held; see tests/recovery.rs"]
fn a_much_slower_subscriber_gets_every_keys_final_value() {
    slow_subscriber(100, Duration::from_millis(10), Duration::from_secs(40));
}

fn slow_subscriber(rounds: i64, spacing: Duration, wait: Duration) {
    let port = free_port().unwrap();
    let _router = router(port, &[]).expect("router");
    let group = driver::scratch_group().unwrap();
    let session = client(port, &[]).unwrap();
    let last: Arc<Mutex<HashMap<String, String>>> = Arc::default();
    let received = Arc::new(Mutex::new(0u64));
    let _sub = {
        let last = last.clone();
        let received = received.clone();
        session
            .declare_subscriber(format!("huddle/@v1/{VENUE}/{TEAM}/**"))
            .callback(move |s| {
                // A consumer slower than the team: 0.3 ms per sample.
                std::thread::sleep(Duration::from_micros(300));
                let payload = s.payload().try_to_string().unwrap_or_default().into_owned();
                last.lock()
                    .unwrap()
                    .insert(s.key_expr().as_str().to_owned(), payload);
                *received.lock().unwrap() += 1;
            })
            .wait()
            .expect("subscribe")
    };
    let daemons: Vec<Daemon> = (1..=3u8)
        .map(|id| Daemon::start(DaemonSpec::new(id, TEAM, group)).unwrap())
        .collect();
    let _bridge = BridgeProcess::start(group, TEAM, VENUE, port, &[]);
    std::thread::sleep(Duration::from_millis(500));
    for round in 1..=rounds {
        set_round(&daemons, KEYS, round);
        std::thread::sleep(spacing);
    }
    let final_value = rounds.to_string();
    let missing = || {
        let last = last.lock().unwrap();
        let mut missing = Vec::new();
        for id in 1..=3u8 {
            for k in 0..KEYS {
                let key = format!("huddle/@v1/{VENUE}/{TEAM}/{id}/var/k{k}");
                if last.get(&key) != Some(&final_value) {
                    missing.push(key);
                }
            }
        }
        missing
    };
    // What Zenoh holds in its queues (some hundred kB) drains at the subscriber's pace;
    // then the merged final values follow. Allow for a loaded machine.
    let all = wait_until(wait, || missing().is_empty());
    let got = *received.lock().unwrap();
    let missing = missing();
    assert!(
        all,
        "{} of {} keys' final values never arrived (samples received: {got}), e.g. {:?}",
        missing.len(),
        3 * KEYS,
        missing.first()
    );
    eprintln!(
        "samples received: {got} for {} changes",
        3 * KEYS as u64 * rounds as u64
    );
}
