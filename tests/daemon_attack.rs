//! An attacker on the team's (unkeyed) LAN against two real daemons, robots 1 and 2:
//! a million spoofed keys, a forged newer incarnation of robot 1, a forged huge version of
//! one of its values, a forged talk head for its queue and a stream of spoofed NACKs. The
//! team must keep working (robot 2 hears robot 1's new values and talk), memory must stay
//! bounded, and robot 1 must not answer the NACKs with more than its own traffic. The
//! figures are printed (`cargo test --test daemon_attack -- --nocapture`). Everything
//! sends on loopback only, on a group and ports of the test's own.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::time::Duration;

use comms::wire::{encode_frame, Frame, Item};
use comms::Value;
use daemon_support::Daemon;
use driver::{open_multicast, SocketConfig};

const TEAM: u8 = 7;

fn start(id: u8, group: SocketAddrV4, dir: &std::path::Path) -> Daemon {
    let relay_port = daemon_support::free_tcp_port();
    Daemon::start(id, &group.to_string(), relay_port, &["--team", "7"], dir)
}

fn rss_kib(d: &Daemon) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{}/status", d.child.id()))
        .expect("the daemon's /proc status");
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .expect("a VmRSS line")
}

struct Attacker {
    socket: UdpSocket,
    group: SocketAddrV4,
    seq: u64,
    bytes: usize,
}

impl Attacker {
    fn send(&mut self, sender: u8, incarnation: u64, items: Vec<Item>) {
        self.seq += 1;
        let frame = Frame {
            team: TEAM,
            sender,
            incarnation,
            seq: self.seq,
            clock: Default::default(),
            items,
        };
        let bytes = encode_frame(&frame, None);
        self.bytes += bytes.len();
        // A full send buffer is the attacker's problem, not the test's.
        let _ = self.socket.send_to(&bytes, self.group);
    }
}

#[test]
fn an_attacker_on_an_unkeyed_lan_cannot_break_the_team_or_its_memory() {
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group();
    let one = start(1, group, dir.path());
    let two = start(2, group, dir.path());
    let (mut c1, mut c2) = (one.client(), two.client());
    assert_eq!(c1.ask("SETV *.var.x 1"), "OK");
    c2.wait_for("1.var.x", Duration::from_secs(3), |a| a.contains(" int 1 "));
    let socket = open_multicast(&SocketConfig {
        group,
        iface: Ipv4Addr::LOCALHOST,
        ..SocketConfig::default()
    })
    .expect("the attacker joins on loopback")
    .socket;
    socket.set_nonblocking(false).unwrap();
    let mut attacker = Attacker {
        socket,
        group,
        seq: 0,
        bytes: 0,
    };
    let rss_before = rss_kib(&two);

    // 1. A million spoofed keys from 200 made-up robots, 40 a frame.
    for frame in 0..25_000u64 {
        let sender = 10 + (frame % 200) as u8;
        let items = (0..40)
            .map(|k| Item::Update {
                path: format!("spoof.{frame}.{k}"),
                value: Value::Int(k),
                version: 1,
                age_us: 0,
            })
            .collect();
        attacker.send(sender, 1, items);
        if frame % 200 == 0 {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    std::thread::sleep(Duration::from_millis(500));
    let rss_after = rss_kib(&two);
    println!(
        "1M spoofed keys: robot 2's memory {} -> {} MiB",
        rss_before / 1024,
        rss_after / 1024
    );
    assert!(
        rss_after < rss_before + 100 * 1024,
        "1M spoofed keys grew robot 2 from {rss_before} to {rss_after} KiB"
    );

    // 2-4. A forged newer incarnation of robot 1, a forged huge version of its value and
    // a forged talk head for its queue.
    attacker.send(1, u64::MAX, vec![]);
    attacker.send(
        1,
        u64::MAX,
        vec![Item::Update {
            path: "x".into(),
            value: Value::Int(666),
            version: u64::MAX,
            age_us: 0,
        }],
    );
    attacker.send(
        1,
        u64::MAX,
        vec![Item::TalkHead {
            queue: "plan".into(),
            first: 1 << 62,
            last: 1 << 62,
        }],
    );
    // The team keeps working: robot 1's next value and its talk reach robot 2.
    let mut listener = two.client();
    assert_eq!(listener.ask("ADDW +.talk.plan"), "OK");
    assert_eq!(c1.ask("SETV *.var.x 2"), "OK");
    c2.wait_for("1.var.x", Duration::from_secs(5), |a| a.contains(" int 2 "));
    for i in 0..3 {
        assert_eq!(c1.ask(&format!("SETV *.talk.plan {i}")), "OK");
    }
    for i in 0..3 {
        let line = listener.line();
        assert!(
            line.starts_with(&format!("UPD 1.talk.plan int {i} ")),
            "message {i}: {line:?}"
        );
    }

    // 5. Spoofed NACKs asking robot 1 to repeat everything it holds.
    for i in 0..50u64 {
        assert_eq!(
            c1.ask(&format!(
                "SETV *.talk.big \"{}\"",
                "z".repeat(900 + i as usize)
            )),
            "OK"
        );
    }
    std::thread::sleep(Duration::from_millis(200));
    let out_before = c1.stat("bytes_out");
    let nack_bytes_before = attacker.bytes;
    for _ in 0..2_000 {
        attacker.send(
            9,
            1,
            vec![Item::Nack {
                target: 1,
                queue: "big".into(),
                first: 1,
                last: 50,
            }],
        );
        std::thread::sleep(Duration::from_micros(500));
    }
    std::thread::sleep(Duration::from_millis(300));
    let nack_bytes = attacker.bytes - nack_bytes_before;
    let drawn = c1.stat("bytes_out") - out_before;
    println!(
        "spoofed NACKs: {nack_bytes} bytes in drew {drawn} bytes out ({:.1}x) in ~1.3 s",
        drawn as f64 / nack_bytes as f64
    );
    let posted: i64 = (0..50).map(|i| 900 + i + 20).sum();
    assert!(
        drawn < 2 * posted + 64 * 1024,
        "robot 1 sent {drawn} bytes for NACKs after posting {posted}"
    );
    assert!(c1.stat("talk_repair_limited") > 0, "the limit was counted");
}
