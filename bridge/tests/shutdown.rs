//! The latest-value guarantee through the bridge's own shutdown (SIGTERM): what waits
//! in its outbox and in Zenoh's queue is written out before it exits. The bridge ends
//! with a flush barrier (a query that only the router answers, behind its puts) before it
//! closes its session; before the barrier, a router blocked on a slow subscriber let the
//! close's per-batch timeout run out and the final values were lost (4 runs of 6 under
//! load).
//!
//! Nothing here is synchronised by sleeping: the test waits on events (a teammate holding
//! every final value, the bridge's exit, the subscriber's samples), each with a generous
//! timeout, and the subscriber is held behind a gate until the bridge has been told to
//! stop, so that it is behind by construction, however loaded the machine is.

#![allow(clippy::disallowed_methods)] // real sockets, real time

mod common;

use std::collections::HashMap;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use common::{wait_until, BridgeProcess};
use comms::Value;
use huddle_bridge::harness::{client, free_port, router, Daemon, DaemonSpec};
use zenoh::Wait;

const TEAM: u8 = 7;
const VENUE: &str = "lab";
const KEYS: usize = 50;
const ROUNDS: i64 = 40;
/// Zenoh closes a link it could not write to for `wait_before_close` (5 s by default).
/// The gated subscriber stalls the router and, behind it, the bridge's link for as long
/// as the test takes to send the rounds and see them at a teammate: longer than 5 s on
/// a very loaded machine. Lengthened so the stalled subscriber is a slow one, not a dead
/// one (a dead link is `tests/recovery.rs`' case).
const WAIT_BEFORE_CLOSE_US: &str = "60000000";

/// The subscriber's gate: closed until the bridge has been sent SIGTERM.
#[derive(Default)]
struct Gate {
    open: Mutex<bool>,
    cv: Condvar,
}

impl Gate {
    fn wait(&self) {
        let open = self.open.lock().unwrap();
        // Generous: a test that fails must not hang.
        let _ = self
            .cv
            .wait_timeout_while(open, Duration::from_secs(60), |open| !*open)
            .unwrap();
    }

    fn open(&self) {
        *self.open.lock().unwrap() = true;
        self.cv.notify_all();
    }
}

/// A value of about 1 kB that says which round it is: 6,000 of them outgrow the
/// loopback's socket buffers, so the router's queue to the stalled subscriber blocks, and
/// the bridge's queue behind it.
fn padded(round: i64) -> Value {
    Value::from(format!("{round}:{}", "x".repeat(1000)))
}

/// The round of a sample's payload (the relay's literal: `"40:xxx…"`).
fn round_of(payload: &str) -> Option<i64> {
    payload.trim_matches('"').split(':').next()?.parse().ok()
}

fn key(id: u8, k: usize) -> String {
    format!("huddle/@v1/{VENUE}/{TEAM}/{id}/var/k{k}")
}

/// Story: a subscriber that stalls (held behind a gate) and then is slower than the team
/// (0.3 ms per sample) while three robots change 50 keys each 40 times (1 kB values); once a teammate
/// holds every final value (so the frames are in the bridge's socket too: loopback
/// multicast delivers to every member at the send), the bridge gets SIGTERM and the gate
/// opens. The bridge reads what is left in its socket, hands its outbox to Zenoh, waits
/// for the flush barrier and closes: every key's final value arrives.
#[test]
fn a_bridge_that_stops_flushes_every_final_value() {
    let port = free_port().unwrap();
    let slow_close = [(
        "transport/link/tx/queue/congestion_control/block/wait_before_close",
        WAIT_BEFORE_CLOSE_US,
    )];
    let _router = router(port, &slow_close).expect("router");
    let group = driver::scratch_group().unwrap();
    let session = client(port, &slow_close).unwrap();
    let last: Arc<Mutex<HashMap<String, String>>> = Arc::default();
    let gate = Arc::new(Gate::default());
    let _sub = {
        let last = last.clone();
        let gate = gate.clone();
        session
            .declare_subscriber(format!("huddle/@v1/{VENUE}/{TEAM}/**"))
            .callback(move |s| {
                gate.wait();
                // The subscriber's own work: slower than the team.
                std::thread::sleep(Duration::from_micros(300));
                let payload = s.payload().try_to_string().unwrap_or_default().into_owned();
                last.lock()
                    .unwrap()
                    .insert(s.key_expr().as_str().to_owned(), payload);
            })
            .wait()
            .expect("subscribe")
    };
    let daemons: Vec<Daemon> = (1..=3u8)
        .map(|id| Daemon::start(DaemonSpec::new(id, TEAM, group)).unwrap())
        .collect();
    let observer = Daemon::start(DaemonSpec::new(4, TEAM, group)).unwrap();
    let config = tempfile::Builder::new()
        .suffix(".json5")
        .tempfile()
        .unwrap();
    std::fs::write(
        config.path(),
        format!(
            "{{ transport: {{ link: {{ tx: {{ queue: {{ congestion_control: {{ block: \
             {{ wait_before_close: {WAIT_BEFORE_CLOSE_US} }} }} }} }} }} }} }}"
        ),
    )
    .unwrap();
    let config_path = config.path().to_string_lossy().into_owned();
    let mut bridge =
        BridgeProcess::start(group, TEAM, VENUE, port, &["--zenoh-config", &config_path]);
    // The bridge is up when its token is on the router (asked on a session of its own:
    // the gated subscriber's may be held).
    let probe = client(port, &[]).unwrap();
    let up = wait_until(Duration::from_secs(30), || {
        probe
            .liveliness()
            .get(format!("huddle/@v1/{VENUE}/{TEAM}/@bridge/alive"))
            .wait()
            .ok()
            .and_then(|r| r.recv_timeout(Duration::from_secs(2)).ok().flatten())
            .is_some_and(|reply| reply.result().is_ok())
    });
    assert!(up, "the bridge declares its token within 30 s");

    // Each round goes out before the next is set (a teammate holds it): the robots would
    // otherwise merge the rounds into their last one before sending.
    let teammate_holds = |round: i64| {
        let (tx, rx) = std::sync::mpsc::channel();
        observer.run(move |h| {
            let all = (1..=3u8).all(|id| {
                (0..KEYS).all(|k| {
                    h.get(&format!("{id}.var.k{k}"))
                        .ok()
                        .flatten()
                        .is_some_and(|e| e.value == padded(round))
                })
            });
            let _ = tx.send(all);
            None
        });
        rx.recv_timeout(Duration::from_secs(5)).unwrap_or(false)
    };
    for v in 1..=ROUNDS {
        for d in &daemons {
            d.run(move |h| {
                h.batch(|b| {
                    for k in 0..KEYS {
                        let _ = b.set(&format!("*.var.k{k}"), padded(v));
                    }
                });
                None
            });
        }
        // Every value of the round is on the wire, and so in the bridge's socket
        // (loopback multicast delivers to every member at the send), when a teammate
        // holds it.
        assert!(
            wait_until(Duration::from_secs(30), || teammate_holds(v)),
            "a teammate holds round {v} within 30 s"
        );
    }
    let missing = || {
        let last = last.lock().unwrap();
        (1..=3u8)
            .flat_map(|id| (0..KEYS).map(move |k| key(id, k)))
            .filter(|key| last.get(key).and_then(|p| round_of(p)) != Some(ROUNDS))
            .collect::<Vec<_>>()
    };
    let behind = missing().len();
    let status = std::process::Command::new("kill")
        .args(["-TERM", &bridge.0.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
    gate.open();
    let stopping = Instant::now();
    assert!(
        wait_until(Duration::from_secs(60), || !bridge.running()),
        "the bridge exits within 60 s of SIGTERM"
    );
    let exited_after = stopping.elapsed();
    let all = wait_until(Duration::from_secs(60), || missing().is_empty());
    eprintln!(
        "final values not at the subscriber at SIGTERM: {behind} of 150; the bridge exited \
         {:.0} ms after it",
        exited_after.as_secs_f64() * 1e3
    );
    assert_eq!(
        behind, 150,
        "the gated subscriber had no final value when the bridge was stopped"
    );
    let rounds_seen = {
        let last = last.lock().unwrap();
        let mut r: Vec<Option<i64>> = (1..=3u8)
            .flat_map(|id| (0..KEYS).map(move |k| key(id, k)))
            .map(|key| last.get(&key).and_then(|p| round_of(p)))
            .collect();
        r.sort();
        r.dedup();
        r
    };
    assert!(
        all,
        "{} final values lost in the shutdown, e.g. {:?}; rounds the subscriber holds: {rounds_seen:?}",
        missing().len(),
        missing().first()
    );
}
