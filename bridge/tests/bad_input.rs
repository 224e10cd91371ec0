//! Bad input on the Zenoh side: a query carrying bytes that are not UTF-8 (the only
//! inbound path with a payload), a subscriber that goes away, the router that goes away
//! and comes back. Each is counted in `@bridge/stats`; the field side carries on (the
//! replica keeps taking the robots' changes throughout), and the bridge sends nothing on
//! the field.

#![allow(clippy::disallowed_methods)] // real sockets, real time

mod common;

use std::time::Duration;

use common::{wait_until, BridgeProcess, Capture, Recorder};
use comms::Value;
use huddle_bridge::harness::{client, free_port, router, Daemon, DaemonSpec};
use zenoh::Wait;

const TEAM: u8 = 7;
const VENUE: &str = "lab";

fn stats(session: &zenoh::Session) -> Option<serde_json::Value> {
    let reply = session
        .get(format!("huddle/@v1/{VENUE}/{TEAM}/@bridge/stats"))
        .wait()
        .ok()?
        .recv_timeout(Duration::from_secs(2))
        .ok()??;
    let sample = reply.into_result().ok()?;
    serde_json::from_slice(&sample.payload().to_bytes()).ok()
}

/// The value of robot 1's `x` in the bridge's replica, by a `get`.
fn replica_x(session: &zenoh::Session) -> Option<String> {
    let replies = session
        .get(format!("huddle/@v1/{VENUE}/{TEAM}/1/var/x"))
        .wait()
        .ok()?;
    let reply = replies.recv_timeout(Duration::from_secs(2)).ok()??;
    let sample = reply.into_result().ok()?;
    Some(sample.payload().try_to_string().ok()?.into_owned())
}

#[test]
fn bad_input_from_zenoh_is_counted_and_the_field_side_carries_on() {
    let port = free_port().unwrap();
    let first = router(port, &[]).expect("router");
    let group = driver::scratch_group().unwrap();
    let capture = Capture::start(group);
    let d1 = Daemon::start(DaemonSpec::new(1, TEAM, group)).unwrap();
    let _d2 = Daemon::start(DaemonSpec::new(2, TEAM, group)).unwrap();
    let mut bridge = BridgeProcess::start(group, TEAM, VENUE, port, &[]);
    let leaving = client(port, &[]).unwrap();
    let staying = client(port, &[]).unwrap();
    let left = Recorder::new(&leaving, &format!("huddle/@v1/{VENUE}/{TEAM}/**"), None);
    let rec = Recorder::new(&staying, &format!("huddle/@v1/{VENUE}/{TEAM}/**"), None);
    let x = format!("huddle/@v1/{VENUE}/{TEAM}/1/var/x");
    d1.set("*.var.x", Value::Int(1));
    assert!(
        wait_until(Duration::from_secs(5), || !rec.of(&x).is_empty()
            && !left.of(&x).is_empty()),
        "both subscribers hear the team"
    );

    // A query whose payload is not UTF-8: an error reply, counted; nothing else.
    let replies: Vec<_> = staying
        .get(format!("huddle/@v1/{VENUE}/{TEAM}/**"))
        .payload(vec![0xff_u8, 0xfe, 0x00, 0xc3])
        .wait()
        .unwrap()
        .iter()
        .collect();
    assert!(
        !replies.is_empty() && replies.into_iter().all(|r| r.into_result().is_err()),
        "the query with bytes gets an error reply, no values"
    );

    // A subscriber goes away; the other still gets every change.
    leaving.close().wait().unwrap();
    d1.set("*.var.x", Value::Int(2));
    assert!(
        wait_until(Duration::from_secs(5), || rec
            .of(&x)
            .last()
            .is_some_and(|s| s.payload == "2")),
        "a subscriber leaving changes nothing for the others"
    );

    // The router goes away: the robots keep changing x, the replica keeps taking it.
    first.close().wait().unwrap();
    drop(first);
    for v in 3..=5 {
        std::thread::sleep(Duration::from_millis(300));
        d1.set("*.var.x", Value::Int(v));
    }
    std::thread::sleep(Duration::from_millis(700));
    let _second = router(port, &[]).expect("a router on the same port");
    let staying = client(port, &[]).unwrap();
    assert!(
        wait_until(Duration::from_secs(15), || replica_x(&staying).as_deref()
            == Some("5")),
        "the field side carried on while the router was away: the replica has x = 5"
    );
    let stats = (0..50)
        .find_map(|_| {
            let s = stats(&staying).filter(|s| s["zenoh"]["back"].as_u64() >= Some(1));
            if s.is_none() {
                std::thread::sleep(Duration::from_millis(100));
            }
            s
        })
        .expect("@bridge/stats answers once the router is back");
    assert_eq!(
        stats["zenoh"]["queries_refused"], 1,
        "the query with bytes was counted: {stats}"
    );
    assert!(
        stats["zenoh"]["lost"].as_u64() >= Some(1),
        "the lost router was counted: {stats}"
    );
    assert_eq!(stats["field"]["frames_sent"], 0);
    let origins = capture.origins(TEAM);
    assert!(origins.len() > 20, "the capture heard the team");
    assert!(
        origins.iter().all(|(sender, _)| *sender != 254),
        "the bridge (listener id 254) sent nothing on the field"
    );
    assert!(bridge.running(), "the bridge is still up");
}
