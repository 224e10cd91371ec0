//! `huddle monitor --http` against a spoofer and hostile HTTP clients, on loopback (a
//! group and ports of the test's own): a board filled with spoofed keys, 20 event-stream
//! clients and 1,200 silent connections. The monitor must keep answering `GET /state`
//! (the figures are printed: `cargo test --test monitor_attack -- --nocapture`; the test
//! bounds only a generous timeout), close silent connections, stay within 128 MB, and
//! with a team key count only verified frames.

#![allow(clippy::disallowed_methods)] // a real monitor over loopback, real time

mod daemon_support;

use std::io::{Read, Write};
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, TcpStream, UdpSocket};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use comms::wire::{FrameWriter, ItemRef, TeamKey};
use comms::Value;
use driver::{open_multicast, SocketConfig};

const TEAM: u8 = 7;

struct Killed(Child);
impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn monitor(group: SocketAddrV4, http: SocketAddr, extra: &[&str]) -> Killed {
    Killed(
        Command::new(env!("CARGO_BIN_EXE_huddle"))
            .args([
                "monitor",
                "--group",
                &group.to_string(),
                "--iface",
                "127.0.0.1",
            ])
            .args(["--http", &http.to_string(), "--team", "7"])
            .args(extra)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .spawn()
            .expect("spawn huddle monitor"),
    )
}

fn rss_mib(child: &Child) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{}/status", child.id())).unwrap();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .expect("a VmRSS line")
        / 1024
}

/// `GET /state`: the body and how long the answer took.
fn state(addr: SocketAddr) -> Option<(String, Duration)> {
    let started = Instant::now();
    let mut s = TcpStream::connect(addr).ok()?;
    s.set_read_timeout(Some(Duration::from_secs(10))).ok()?;
    write!(
        s,
        "GET /state HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )
    .ok()?;
    let mut text = String::new();
    s.read_to_string(&mut text).ok()?;
    let body = text.split_once("\r\n\r\n")?.1.to_owned();
    Some((body, started.elapsed()))
}

fn wait_state(addr: SocketAddr, what: &str, ok: impl Fn(&serde_json::Value) -> bool) {
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        if let Some((body, _)) = state(addr) {
            if serde_json::from_str(&body).is_ok_and(|s| ok(&s)) {
                return;
            }
        }
        assert!(Instant::now() < deadline, "{what}: never");
        std::thread::sleep(Duration::from_millis(50));
    }
}

fn sender(group: SocketAddrV4) -> UdpSocket {
    let socket = open_multicast(&SocketConfig {
        group,
        iface: Ipv4Addr::LOCALHOST,
        ..SocketConfig::default()
    })
    .expect("the spoofer joins on loopback")
    .socket;
    socket.set_nonblocking(false).unwrap();
    socket
}

fn http_addr() -> SocketAddr {
    format!("127.0.0.1:{}", daemon_support::free_tcp_port())
        .parse()
        .unwrap()
}

#[test]
fn the_monitor_keeps_answering_under_a_full_board_event_streams_and_silent_connections() {
    let group = daemon_support::scratch_group();
    let http = http_addr();
    let m = monitor(group, http, &[]);
    wait_state(http, "the monitor serves", |_| true);

    // A spoofer fills the board: 200 made-up robots, 70k keys.
    let socket = sender(group);
    for frame in 0..1_750u64 {
        let mut w = FrameWriter::new(TEAM, 10 + (frame % 200) as u8, 1, frame + 1, 1400, None);
        for k in 0..40 {
            let path = format!("spoof.{frame}.{k}");
            w.push(ItemRef::Update {
                path: &path,
                value: &Value::Int(k),
                version: 1,
                age_us: 0,
            });
        }
        let _ = socket.send_to(&w.finish(), group);
        if frame % 100 == 0 {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    wait_state(http, "the board filled", |s| {
        s["board_total"].as_u64().is_some_and(|n| n > 10_000)
    });

    // 20 event-stream clients that read everything.
    let mut streams = Vec::new();
    for _ in 0..20 {
        let mut s = TcpStream::connect(http).unwrap();
        write!(s, "GET /events HTTP/1.1\r\nHost: {http}\r\n\r\n").unwrap();
        streams.push(std::thread::spawn(move || {
            let mut buf = [0u8; 65536];
            let mut total = 0usize;
            let until = Instant::now() + Duration::from_secs(4);
            s.set_read_timeout(Some(Duration::from_secs(1))).unwrap();
            while Instant::now() < until {
                match s.read(&mut buf) {
                    Ok(0) | Err(_) => break,
                    Ok(n) => total += n,
                }
            }
            total
        }));
    }
    // 1,200 connections that never send a byte.
    let silent: Vec<TcpStream> = (0..1_200)
        .filter_map(|_| TcpStream::connect(http).ok())
        .collect();
    println!("{} silent connections open", silent.len());

    let mut times = Vec::new();
    let mut largest = 0;
    for _ in 0..20 {
        let (body, took) = state(http).expect("GET /state answered under the attack");
        let parsed: serde_json::Value = serde_json::from_str(&body).expect("JSON");
        assert!(parsed["board"].is_array());
        largest = largest.max(body.len());
        times.push(took);
        std::thread::sleep(Duration::from_millis(100));
    }
    times.sort();
    let rss = rss_mib(&m.0);
    println!(
        "GET /state under attack: median {:?}, worst {:?}, body up to {} kB; monitor RSS {rss} MiB",
        times[times.len() / 2],
        times[times.len() - 1],
        largest / 1000
    );
    assert!(
        largest < 1_000_000,
        "{largest} bytes of /state: the board is shown a page at a time"
    );
    assert!(rss <= 128, "the monitor grew to {rss} MiB");
    let streamed: usize = streams.into_iter().map(|t| t.join().unwrap()).sum();
    println!("20 event streams read {} kB in 4 s", streamed / 1000);

    // The silent connections are closed (evicted at the cap, or at the header timeout).
    let mut last = silent.into_iter().last().expect("a silent connection");
    last.set_read_timeout(Some(Duration::from_secs(20)))
        .unwrap();
    let mut buf = [0u8; 16];
    let closed = match last.read(&mut buf) {
        Ok(0) => true,
        Ok(_) => true, // an error response, then the close
        Err(e) => e.kind() == std::io::ErrorKind::ConnectionReset,
    };
    assert!(closed, "a silent connection stayed open");
}

#[test]
fn a_keyed_monitor_counts_only_verified_frames() {
    let dir = tempfile::tempdir().unwrap();
    let key = b"robocup team key";
    let key_file = dir.path().join("team.key");
    std::fs::write(&key_file, key).unwrap();
    let group = daemon_support::scratch_group();
    let http = http_addr();
    let _m = monitor(group, http, &["--key-file", key_file.to_str().unwrap()]);
    wait_state(http, "the monitor serves", |_| true);
    let tk = TeamKey::new(key);
    let frame = |incarnation: u64, seq: u64, signed: bool| {
        let mut w = FrameWriter::new(TEAM, 2, incarnation, seq, 1400, signed.then_some(&tk));
        w.push(ItemRef::Update {
            path: "x",
            value: &Value::Int(seq as i64),
            version: seq,
            age_us: 0,
        });
        w.finish()
    };
    let socket = sender(group);
    let (old, current) = (1_000u64 << 16, 2_000u64 << 16);
    let recorded = frame(old, 381, true);
    for seq in 1..=20 {
        socket.send_to(&frame(current, seq, true), group).unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    // A replayed frame of robot 2's earlier life, a replayed copy, an unsigned forgery
    // numbered 10^9; then the real robot goes on.
    socket.send_to(&recorded, group).unwrap();
    socket.send_to(&frame(current, 5, true), group).unwrap();
    socket
        .send_to(&frame(current, 1_000_000_000, false), group)
        .unwrap();
    std::thread::sleep(Duration::from_millis(20));
    for seq in 21..=25 {
        socket.send_to(&frame(current, seq, true), group).unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    wait_state(http, "robot 2's frames counted", |s| {
        s["robots"]
            .as_array()
            .and_then(|r| r.iter().find(|r| r["id"] == 2))
            .is_some_and(|r| r["frames_received"] == 25)
    });
    let (body, _) = state(http).unwrap();
    let s: serde_json::Value = serde_json::from_str(&body).unwrap();
    let r = s["robots"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["id"] == 2)
        .unwrap()
        .clone();
    assert_eq!(r["frames_sent"], 25, "{r}");
    assert_eq!(r["loss"], 0.0, "{r}");
}
