//! The field side on a thread of its own (`--field-loop thread`, and what `auto` picks
//! with Zenoh's lowlatency transport): three daemons change 100 keys 20 times, and a
//! subscriber gets every key's final value and the liveliness token of every robot; then
//! lone changes are put by the field thread itself (the fast path's counter).
//! The lowlatency case runs a router, a subscriber and the bridge all with
//! `transport/unicast/lowlatency` and QoS off, as docs/bridge.md's venue config has it.

#![allow(clippy::disallowed_methods)] // real sockets, real time

mod common;

use std::time::Duration;

use common::{set_round, wait_until, BridgeProcess, Recorder};
use comms::Value;
use huddle_bridge::harness::{client, free_port, router, Daemon, DaemonSpec};
use zenoh::Wait;

const TEAM: u8 = 7;
const KEYS: usize = 100;
const ROUNDS: i64 = 20;
const LOWLATENCY: &[(&str, &str)] = &[
    ("transport/unicast/lowlatency", "true"),
    ("transport/unicast/qos/enabled", "false"),
];

#[test]
fn a_field_thread_mirrors_every_keys_final_value() {
    mirror("thread", &[], &["--field-loop", "thread"]);
}

#[test]
fn on_the_lowlatency_transport_the_field_thread_mirrors_every_keys_final_value() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("lowlatency.json5");
    std::fs::write(
        &file,
        "{ transport: { unicast: { lowlatency: true, qos: { enabled: false } } } }",
    )
    .unwrap();
    mirror(
        "lowlat",
        LOWLATENCY,
        &["--zenoh-config", file.to_str().unwrap()],
    );
}

fn mirror(venue: &str, settings: &[(&str, &str)], flags: &[&str]) {
    let port = free_port().unwrap();
    let _router = router(port, settings).expect("router");
    let session = client(port, settings).expect("subscriber session");
    let recorder = Recorder::new(
        &session,
        &format!("huddle/@v1/{venue}/{TEAM}/**"),
        Some(&format!("huddle/@v1/{venue}/{TEAM}/*/@alive/*")),
    );
    let group = driver::scratch_group().unwrap();
    let daemons: Vec<Daemon> = (1..=3u8)
        .map(|id| Daemon::start(DaemonSpec::new(id, TEAM, group)).unwrap())
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("bridge.log");
    let _bridge = BridgeProcess::start_logged(group, TEAM, venue, port, flags, &log);
    // Up when its token is on the router.
    let up = wait_until(Duration::from_secs(20), || {
        session
            .liveliness()
            .get(format!("huddle/@v1/{venue}/{TEAM}/@bridge/alive"))
            .wait()
            .ok()
            .and_then(|r| r.recv_timeout(Duration::from_secs(2)).ok().flatten())
            .is_some_and(|reply| reply.result().is_ok())
    });
    assert!(
        up,
        "the bridge came up ({})",
        std::fs::read_to_string(&log).unwrap_or_default()
    );
    for round in 1..=ROUNDS {
        set_round(&daemons, KEYS, round);
        std::thread::sleep(Duration::from_millis(20));
    }
    // Lone changes (one key per datagram) go on the fast path: the field thread puts
    // them itself (a 100-key datagram is more than one turn's share and is handed over;
    // a put slowed by the burst sends every put through the publisher for a second).
    std::thread::sleep(Duration::from_millis(1500));
    for i in 1..=5 {
        daemons[0].set("*.var.lone", Value::Int(i));
        std::thread::sleep(Duration::from_millis(20));
    }
    let missing = || {
        let samples = recorder.samples();
        let mut missing = 0;
        for id in 1..=3u8 {
            for k in 0..KEYS {
                let key = format!("huddle/@v1/{venue}/{TEAM}/{id}/var/k{k}");
                let last = samples.iter().rev().find(|s| s.key == key);
                if last.map(|s| s.payload.as_str()) != Some(&ROUNDS.to_string()) {
                    missing += 1;
                }
            }
        }
        let lone = format!("huddle/@v1/{venue}/{TEAM}/1/var/lone");
        if samples
            .iter()
            .rev()
            .find(|s| s.key == lone)
            .map(|s| s.payload.as_str())
            != Some("5")
        {
            missing += 1;
        }
        missing
    };
    let all = wait_until(Duration::from_secs(20), || missing() == 0);
    let log_text = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(
        all,
        "{} of {} keys' final values never arrived; bridge log:\n{log_text}",
        missing(),
        3 * KEYS
    );
    let robots: std::collections::BTreeSet<String> = recorder
        .alive()
        .into_iter()
        .filter(|(kind, _)| *kind == zenoh::sample::SampleKind::Put)
        .map(|(_, key)| key.split('/').nth(4).unwrap_or_default().to_owned())
        .collect();
    assert_eq!(
        robots.len(),
        3,
        "a liveliness token for each of the 3 robots: {robots:?}"
    );
    assert!(
        log_text.contains("field side: Thread"),
        "the field side ran on its own thread; bridge log:\n{log_text}"
    );
    let stats = huddle_bridge::bench::bridge_stats(&session, venue).expect("@bridge/stats");
    let inline = stats["timing_us"]["inline_puts"].as_u64().unwrap_or(0);
    assert!(
        inline > 0,
        "the field thread put samples itself (inline_puts {inline}): {stats}"
    );
}
