//! `huddle monitor` live against two daemons on loopback (a group and port of the test's
//! own), and `huddle replay --monitor` from a simulated match's recording: `GET /state`
//! shows each robot's claim, talk and departure; the monitor never sends a frame.

#![allow(clippy::disallowed_methods)] // real daemons and servers over loopback, real time

mod daemon_support;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use daemon_support::Daemon;

struct Killed(Child);
impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn state(addr: SocketAddr) -> Option<serde_json::Value> {
    let mut s = TcpStream::connect(addr).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(5))).ok()?;
    write!(
        s,
        "GET /state HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .ok()?;
    let mut text = String::new();
    s.read_to_string(&mut text).ok()?;
    serde_json::from_str(text.split_once("\r\n\r\n")?.1).ok()
}

/// Polls `/state` until `ok` holds (or panics after a generous bound).
fn wait_state(
    addr: SocketAddr,
    what: &str,
    ok: impl Fn(&serde_json::Value) -> bool,
) -> serde_json::Value {
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut last = None;
    loop {
        if let Some(s) = state(addr) {
            if ok(&s) {
                return s;
            }
            last = Some(s);
        }
        assert!(
            Instant::now() < deadline,
            "{what}: never; last state {last:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn robot(s: &serde_json::Value, id: u64) -> serde_json::Value {
    s["robots"]
        .as_array()
        .and_then(|r| r.iter().find(|r| r["id"] == id).cloned())
        .unwrap_or_default()
}

#[test]
fn the_live_monitor_shows_claims_talk_and_departures_and_never_sends() {
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group();
    let g = group.to_string();
    let mut d1 = Daemon::start(1, &g, daemon_support::free_tcp_port(), &[], dir.path());
    let d2 = Daemon::start(2, &g, daemon_support::free_tcp_port(), &[], dir.path());
    let http: SocketAddr = format!("127.0.0.1:{}", daemon_support::free_tcp_port())
        .parse()
        .unwrap();
    let _monitor = Killed(
        Command::new(env!("CARGO_BIN_EXE_huddle"))
            .args(["monitor", "--group", &g, "--iface", "127.0.0.1"])
            .args(["--http", &http.to_string(), "--budget", "1200"])
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .spawn()
            .expect("spawn huddle monitor"),
    );
    wait_state(http, "both robots heard", |s| {
        robot(s, 1).is_object() && robot(s, 2).is_object()
    });

    let (mut c1, mut c2) = (d1.client(), d2.client());
    assert_eq!(c2.ask("SETV *.var.machine.heuristic [1.5, 1]"), "OK");
    assert_eq!(c1.ask("SETV *.var.machine.heuristic [3.0, 0]"), "OK");
    assert_eq!(c1.ask(r#"SETV *.talk.plan "pass to 2""#), "OK");
    let s = wait_state(http, "robot 2 goes, talk logged", |s| {
        s["goer"] == 2 && s["talk"].as_array().is_some_and(|t| !t.is_empty())
    });
    assert_eq!(robot(&s, 2)["role"], "active");
    assert_eq!(robot(&s, 2)["h"], 1.5);
    assert!(robot(&s, 2)["budget_used"].as_f64().unwrap() > 0.0);
    assert_eq!(s["talk"][0]["key"], "1.talk.plan");
    assert_eq!(s["talk"][0]["value"], "pass to 2");
    assert!(s["board"]
        .as_array()
        .unwrap()
        .iter()
        .any(|b| b["key"] == "2.var.machine.heuristic" && b["owner"] == 2));
    assert!(s["source"] == "live");

    // The monitor is no member that speaks: the daemons never heard of robot 254.
    let heard = c1.wait_for(
        "local.var.huddle.stats.peer.2.last_heard_us",
        Duration::from_secs(5),
        |a| a.starts_with("VAL"),
    );
    assert!(heard.starts_with("VAL"), "{heard}");
    let monitor = c1.ask("GETV local.var.huddle.stats.peer.254.last_heard_us");
    assert!(
        monitor.starts_with("ERR"),
        "the daemon heard the monitor: {monitor}"
    );

    d1.kill();
    let s = wait_state(http, "robot 1 departed", |s| {
        robot(s, 1)["departed"] == true
    });
    assert_eq!(robot(&s, 2)["departed"], false);

    // A second robot started with id 2: the monitor marks robot 2 as conflicting.
    let _twin = Daemon::start(2, &g, daemon_support::free_tcp_port(), &[], dir.path());
    wait_state(http, "robot 2 conflicting", |s| {
        robot(s, 2)["conflicting"] == true
    });
}

#[test]
fn a_recording_replays_into_the_monitor() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("sim.pcapng");
    let status = Command::new(env!("CARGO_BIN_EXE_huddle"))
        .args([
            "sim",
            "--robots",
            "3",
            "--duration",
            "2s",
            "--preset",
            "lan",
            "--record",
        ])
        .arg(&file)
        .stdout(Stdio::null())
        .status()
        .unwrap();
    assert!(status.success());
    let http: SocketAddr = format!("127.0.0.1:{}", daemon_support::free_tcp_port())
        .parse()
        .unwrap();
    let _replay = Killed(
        Command::new(env!("CARGO_BIN_EXE_huddle"))
            .arg("replay")
            .arg(&file)
            .args(["--speed", "50", "--monitor", &http.to_string()])
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .spawn()
            .unwrap(),
    );
    let s = wait_state(http, "the replay over", |s| s["finished"] == true);
    assert_eq!(s["source"], "replay");
    for id in 1..=3 {
        let r = robot(&s, id);
        assert!(r["pose"]["x"].is_number(), "robot {id} placed: {r}");
    }
    assert!(s["team_ball"]["x"].is_number(), "a team ball: {s}");
}
