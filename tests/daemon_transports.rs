//! The transports a league allows, on real daemons (`huddle daemon --transport`):
//!
//! - loopback: three daemons broadcast to 127.255.255.255 on a port of the test's own and
//!   replicate values every way, with no drop counted for their own echoes; a listen-only
//!   `huddle record --transport broadcast` hears them, and so does a live `huddle
//!   monitor --transport broadcast`; three daemons with `--transport
//!   unicast` (127.0.0.1, .2, .3, one port, each listing the other two) do the same;
//! - start-up: unicast without `--peer`, `--group` with broadcast, an unusable
//!   `--broadcast` are one clear line each, not a panic;
//! - two network namespaces joined by a veth pair (10.77.0.1 and 10.77.0.2): a value set
//!   on one host appears on the other over broadcast to 10.77.0.255:10007 (team 7's SPL
//!   port, the default) and over unicast. Needs root and `ip`; skipped with the reason
//!   otherwise.
//!
//! Nothing leaves the machine: loopback, or veths that exist only inside the namespaces.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use comms::relay::Binding;
use daemon_support::netns::{NetnsPair, ADDRESSES, BROADCAST};
use daemon_support::{free_tcp_port, free_udp_port, replay_json, Daemon};

fn huddle() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_huddle"));
    c.env("RUST_LOG", "warn");
    c
}

/// Every daemon sets a value of its own; every other reads it fresh, and nothing was
/// dropped as an error (own echoes included).
fn replicate_every_way(daemons: &[(u8, &Daemon)], transport: &str) {
    for &(id, d) in daemons {
        let mut c = d.client();
        assert_eq!(c.ask(&format!("SETV *.var.pos {id}.5")), "OK");
    }
    for &(reader, d) in daemons {
        let mut c = d.client();
        for &(writer, _) in daemons.iter().filter(|(w, _)| *w != reader) {
            let key = format!("{writer}.var.pos");
            let answer = c.wait_for(&key, Duration::from_secs(5), |a| a.starts_with("VAL"));
            let b = Binding::parse(&answer).unwrap();
            assert_eq!(
                (b.ty.as_str(), b.value.as_str()),
                ("float", format!("{writer}.5").as_str()),
                "{transport}: robot {reader} reads robot {writer}'s value"
            );
            assert!(
                b.age_ms < 500,
                "{transport}: robot {reader} sees robot {writer}'s value {} ms old",
                b.age_ms
            );
        }
        // Counters are mirrored at each refresh: wait for one that has seen traffic.
        c.wait_for(
            "local.var.huddle.stats.frames_in",
            Duration::from_secs(3),
            |a| Binding::parse(a).is_some_and(|b| b.value != "0"),
        );
        assert_eq!(
            c.stat("drops.total"),
            0,
            "{transport}: robot {reader} counted a drop (its own echo is none)"
        );
    }
}

#[test]
fn three_broadcast_daemons_on_loopback_replicate_and_a_recorder_hears_them() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_udp_port().to_string();
    let net = [
        "--transport",
        "broadcast",
        "--port",
        &port,
        "--iface",
        "127.0.0.1",
    ];
    let extra = ["--refresh", "50ms", "--team", "7"];
    let daemons: Vec<Daemon> = (1..=3)
        .map(|id| Daemon::start_on(id, &net, free_tcp_port(), &extra, dir.path()))
        .collect();
    let file = dir.path().join("broadcast.pcapng");
    let mut recorder = huddle()
        .args(["record", "--transport", "broadcast", "--port", &port])
        .args(["--iface", "127.0.0.1", "--duration", "20s"])
        .arg(&file)
        .stdout(Stdio::null())
        .spawn()
        .expect("spawn huddle record");
    wait_until_recorded(&file);

    let pairs: Vec<(u8, &Daemon)> = (1..=3).zip(&daemons).collect();
    replicate_every_way(&pairs, "broadcast");
    assert_eq!(daemons[1].client().ask("SETV *.var.last 42"), "OK");
    daemons[0]
        .client()
        .wait_for("2.var.last", Duration::from_secs(5), |a| {
            a.starts_with("VAL 2.var.last int 42 ")
        });
    // The recorder is another process: under load it may write the frame that carries
    // the write a little after daemon 1 took it. Stop it once the file has it (or after
    // 10 s, and the assertion below says what it heard).
    let deadline = Instant::now() + Duration::from_secs(10);
    let heard = |file: &Path| {
        let out = huddle().arg("replay").arg(file).arg("--json").output();
        out.is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains("\"key\":\"2.var.last\""))
    };
    while !heard(&file) && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = recorder.kill();
    let _ = recorder.wait();

    // The recording holds every robot's broadcast, sent to 127.255.255.255:<port>.
    let lines = replay_json(&file);
    for key in ["1.var.pos", "2.var.pos", "3.var.pos", "2.var.last"] {
        assert!(
            lines.contains(&format!("\"key\":\"{key}\"")),
            "the recorder did not hear {key}:\n{lines}"
        );
    }
    let to_broadcast = huddle()
        .arg("replay")
        .arg(&file)
        .args(["--json", "--group", &format!("127.255.255.255:{port}")])
        .output()
        .expect("run huddle replay --group");
    let filtered = String::from_utf8(to_broadcast.stdout).unwrap();
    assert!(
        filtered.contains("\"key\":\"2.var.last\""),
        "the frames were recorded as sent to 127.255.255.255:{port}"
    );
}

/// `GET /state` of a monitor, as JSON (`None` while it is not up).
fn monitor_state(addr: std::net::SocketAddr) -> Option<serde_json::Value> {
    use std::io::{Read, Write};
    let mut s = std::net::TcpStream::connect(addr).ok()?;
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

#[test]
fn a_live_monitor_hears_a_broadcast_team() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_udp_port().to_string();
    let net = [
        "--transport",
        "broadcast",
        "--port",
        &port,
        "--iface",
        "127.0.0.1",
    ];
    let extra = ["--refresh", "50ms", "--team", "7"];
    let d1 = Daemon::start_on(1, &net, free_tcp_port(), &extra, dir.path());
    let _d2 = Daemon::start_on(2, &net, free_tcp_port(), &extra, dir.path());
    let http: std::net::SocketAddr = format!("127.0.0.1:{}", free_tcp_port()).parse().unwrap();
    struct Killed(std::process::Child);
    impl Drop for Killed {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }
    let _monitor = Killed(
        huddle()
            .args([
                "monitor",
                "--transport",
                "broadcast",
                "--port",
                &port,
                "--team",
                "7",
            ])
            .args(["--iface", "127.0.0.1", "--http", &http.to_string()])
            .stdout(Stdio::null())
            .spawn()
            .expect("spawn huddle monitor"),
    );
    assert_eq!(d1.client().ask("SETV *.var.ball.dist 2.25"), "OK");
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut last = None;
    loop {
        if let Some(s) = monitor_state(http) {
            let board = s["board"].as_array().cloned().unwrap_or_default();
            let robots = s["robots"].as_array().cloned().unwrap_or_default();
            let has_robot = |id: u64| robots.iter().any(|r| r["id"] == id);
            if has_robot(1)
                && has_robot(2)
                && board
                    .iter()
                    .any(|b| b["key"] == "1.var.ball.dist" && b["value"] == 2.25)
            {
                break;
            }
            last = Some(s);
        }
        assert!(
            Instant::now() < deadline,
            "the monitor never showed both robots and 1.var.ball.dist: {last:?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Waits until the recorder has written its headers and a frame.
fn wait_until_recorded(file: &Path) {
    let deadline = Instant::now() + Duration::from_secs(20);
    while !(file.exists() && std::fs::metadata(file).unwrap().len() > 100) {
        assert!(
            Instant::now() < deadline,
            "the recorder never wrote a frame"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A datagram from an address that is not a listed peer is refused, and the refusal
/// shows in `huddle stats` (it was counted in the driver only). The check is on the source
/// address, which anyone can forge: it is not authentication (a team key is).
#[test]
fn a_unicast_daemon_refuses_a_stranger_and_says_so_in_huddle_stats() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_udp_port();
    let net = [
        "--transport".to_string(),
        "unicast".into(),
        "--port".into(),
        port.to_string(),
        "--iface".into(),
        "127.0.0.1".into(),
        "--peer".into(),
        format!("127.0.0.2:{port}"),
    ];
    let net: Vec<&str> = net.iter().map(String::as_str).collect();
    let d = Daemon::start_on(1, &net, free_tcp_port(), &["--team", "7"], dir.path());
    let stranger = std::net::UdpSocket::bind("127.0.0.3:0").expect("bind 127.0.0.3");
    stranger
        .send_to(b"not from a peer", format!("127.0.0.1:{port}"))
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let out = huddle()
            .args(["stats", "--json", "--relay", &d.relay.to_string()])
            .output()
            .expect("run huddle stats");
        let stats: serde_json::Value =
            serde_json::from_slice(&out.stdout).unwrap_or(serde_json::Value::Null);
        if stats["unicast_refused"].as_i64().is_some_and(|n| n >= 1) {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "unicast_refused never showed: {}",
            String::from_utf8_lossy(&out.stdout)
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn three_unicast_daemons_on_loopback_replicate_to_their_peers() {
    let dir = tempfile::tempdir().unwrap();
    let port = free_udp_port();
    // Three "hosts" on 127.0.0.1, .2, .3, one port, each listing the other two.
    let addr = |id: u8| format!("127.0.0.{id}");
    let daemons: Vec<Daemon> = (1..=3u8)
        .map(|id| {
            let mut net: Vec<String> = ["--transport", "unicast", "--port", &port.to_string()]
                .map(String::from)
                .into();
            net.extend(["--iface".into(), addr(id)]);
            for other in (1..=3u8).filter(|o| *o != id) {
                net.extend(["--peer".into(), format!("{}:{port}", addr(other))]);
            }
            let net: Vec<&str> = net.iter().map(String::as_str).collect();
            let extra = ["--refresh", "50ms", "--team", "7"];
            Daemon::start_on(id, &net, free_tcp_port(), &extra, dir.path())
        })
        .collect();
    let pairs: Vec<(u8, &Daemon)> = (1..=3).zip(&daemons).collect();
    replicate_every_way(&pairs, "unicast");
}

/// Runs `huddle daemon` with `args` (on loopback) and returns its exit and stderr.
fn daemon_fails(args: &[&str]) -> String {
    let dir = tempfile::tempdir().unwrap();
    let relay = format!("127.0.0.1:{}", free_tcp_port());
    let out = huddle()
        .args([
            "daemon",
            "--id",
            "1",
            "--relay",
            &relay,
            "--iface",
            "127.0.0.1",
        ])
        .arg("--config-dir")
        .arg(dir.path())
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("run huddle daemon");
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{args:?} started: {stderr}");
    assert!(!stderr.contains("panicked"), "{args:?}: {stderr}");
    stderr
}

#[test]
fn transport_mistakes_are_one_clear_line_at_start_up() {
    let port = free_udp_port().to_string();
    let cases: [(&[&str], &str); 4] = [
        (
            &["--transport", "unicast", "--port", &port],
            "--transport unicast sends to each --peer only: give at least one --peer",
        ),
        (
            &["--transport", "broadcast", "--group", "239.1.2.3:4000"],
            "has none: give the port with --port",
        ),
        (
            &[
                "--transport",
                "broadcast",
                "--port",
                &port,
                "--broadcast",
                "255.255.255.255",
            ],
            "255.255.255.255 cannot be the broadcast address",
        ),
        (
            &["--transport", "multicast", "--port", &port],
            "the port is --group's",
        ),
    ];
    for (args, expected) in cases {
        let stderr = daemon_fails(args);
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
}

/// A command inside namespace `i`, retried until it succeeds (a daemon's relay may not be
/// up yet) or `within` has passed.
fn in_ns_until_ok(ns: &NetnsPair, i: usize, args: &[&str], within: Duration) -> Output {
    let deadline = Instant::now() + within;
    loop {
        let out = ns
            .command(i, env!("CARGO_BIN_EXE_huddle"))
            .args(args)
            .env("RUST_LOG", "warn")
            .stdin(Stdio::null())
            .output()
            .expect("run huddle in a namespace");
        if out.status.success() || Instant::now() >= deadline {
            return out;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A daemon inside namespace `i`, killed (before the namespaces go) when dropped.
struct NsDaemon(std::process::Child);

impl Drop for NsDaemon {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn ns_daemon(ns: &NetnsPair, i: usize, net: &[&str], dir: &Path) -> NsDaemon {
    let id = (i + 1).to_string();
    let child = ns
        .command(i, env!("CARGO_BIN_EXE_huddle"))
        .args(["daemon", "--id", &id, "--team", "7", "--refresh", "50ms"])
        .args(["--iface", ADDRESSES[i], "--relay", "127.0.0.1:2001"])
        .arg("--config-dir")
        .arg(dir)
        .args(net)
        .env("RUST_LOG", "warn")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .spawn()
        .expect("spawn huddle daemon in a namespace");
    NsDaemon(child)
}

/// Sets robot 1's value on host 0, reads it on host 1 and back the other way.
fn values_cross_the_veth(ns: &NetnsPair, transport: &str) {
    let relay = ["--relay", "127.0.0.1:2001"];
    let set = |i: usize, key: &str, value: &str| {
        let mut args = vec!["set", key, value];
        args.extend(relay);
        let out = in_ns_until_ok(ns, i, &args, Duration::from_secs(10));
        assert!(
            out.status.success(),
            "{transport}: set on host {i}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    let get = |i: usize, key: &str| -> String {
        let mut args = vec!["get", key, "--wait", "--timeout", "10s"];
        args.extend(relay);
        let out = in_ns_until_ok(ns, i, &args, Duration::from_secs(15));
        assert!(
            out.status.success(),
            "{transport}: {key} never reached host {i}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    set(0, "*.var.ball.dist", "1.25");
    let seen = get(1, "1.var.ball.dist");
    assert!(seen.contains("1.25"), "{transport}: host 1 read {seen:?}");
    set(1, "*.var.role", "\"keeper\"");
    let seen = get(0, "2.var.role");
    assert!(seen.contains("keeper"), "{transport}: host 0 read {seen:?}");
}

#[test]
fn two_hosts_on_a_veth_pair_replicate_over_broadcast_and_over_unicast() {
    let ns = match NetnsPair::create("tr") {
        Ok(ns) => ns,
        Err(reason) => {
            eprintln!("SKIPPED two_hosts_on_a_veth_pair_replicate_over_broadcast_and_over_unicast: {reason}");
            return;
        }
    };
    let dir = tempfile::tempdir().unwrap();

    // Broadcast: no --port, so team 7's SPL port 10007; the broadcast address is the
    // veth's own (10.77.0.255), found from the interface.
    {
        let _daemons: Vec<NsDaemon> = (0..2)
            .map(|i| ns_daemon(&ns, i, &["--transport", "broadcast"], dir.path()))
            .collect();
        values_cross_the_veth(&ns, "broadcast");
        // A listen-only recorder on host 1 hears host 0's broadcasts to 10.77.0.255.
        let file = dir.path().join("veth.pcapng");
        let out = ns
            .command(1, env!("CARGO_BIN_EXE_huddle"))
            .args(["record", "--transport", "broadcast", "--port", "10007"])
            .args(["--iface", ADDRESSES[1], "--duration", "1s"])
            .arg(&file)
            .env("RUST_LOG", "warn")
            .output()
            .expect("huddle record in a namespace");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let replay = huddle()
            .arg("replay")
            .arg(&file)
            .args(["--json", "--group", &format!("{BROADCAST}:10007")])
            .output()
            .expect("huddle replay");
        let lines = String::from_utf8_lossy(&replay.stdout);
        assert!(
            lines.contains("\"key\":\"1.var.ball.dist\""),
            "the recorder on host 1 heard no broadcast of robot 1 to {BROADCAST}:10007:\n{lines}"
        );
    }

    // Unicast: each lists the other; no group, no broadcast.
    {
        let peer = |i: usize| format!("{}:10007", ADDRESSES[i]);
        let (p0, p1) = (peer(1), peer(0));
        let _d0 = ns_daemon(
            &ns,
            0,
            &["--transport", "unicast", "--peer", &p0],
            dir.path(),
        );
        let _d1 = ns_daemon(
            &ns,
            1,
            &["--transport", "unicast", "--peer", &p1],
            dir.path(),
        );
        values_cross_the_veth(&ns, "unicast");
    }
}
