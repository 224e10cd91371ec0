//! Attacks on a budgeted team's network, against real daemons on loopback (a group and
//! ports of the test's own; nothing leaves the host): forged frame counters that claim
//! the pool is spent, unkeyed talk heads that open gaps in 6,400 queues (NACKs), and
//! heads that make a relay give up messages (`LOST` lines). The team keeps sending within
//! its budget, memory stays bounded, relay clients are not flooded. Figures are printed:
//! `cargo test --test daemon_attack_budget -- --nocapture`.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::time::{Duration, Instant};

use comms::wire::{FrameWriter, ItemRef};
use comms::Value;
use daemon_support::Daemon;
use driver::{open_multicast, SocketConfig};

const TEAM: u8 = 7;

fn start(id: u8, group: SocketAddrV4, dir: &std::path::Path, extra: &[&str]) -> Daemon {
    let mut args = vec!["--team", "7"];
    args.extend_from_slice(extra);
    Daemon::start(
        id,
        &group.to_string(),
        daemon_support::free_tcp_port(),
        &args,
        dir,
    )
}

fn rss_mib(d: &Daemon) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{}/status", d.child.id())).unwrap();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .expect("a VmRSS line")
        / 1024
}

struct Attacker {
    socket: UdpSocket,
    group: SocketAddrV4,
    bytes: usize,
}

impl Attacker {
    fn new(group: SocketAddrV4) -> Attacker {
        let socket = open_multicast(&SocketConfig {
            group,
            iface: Ipv4Addr::LOCALHOST,
            ..SocketConfig::default()
        })
        .expect("the attacker joins on loopback")
        .socket;
        socket.set_nonblocking(false).unwrap();
        Attacker {
            socket,
            group,
            bytes: 0,
        }
    }

    /// One frame from `sender` numbered `seq` with `items` (no key), at most `mtu` bytes:
    /// items that do not fit are left out.
    fn send(&mut self, sender: u8, seq: u64, mtu: usize, items: &[ItemRef<'_>]) {
        let mut w = FrameWriter::new(TEAM, sender, 9, seq, mtu, None);
        for &item in items {
            w.push(item);
        }
        let bytes = w.finish();
        self.bytes += bytes.len();
        let _ = self.socket.send_to(&bytes, self.group);
    }
}

/// 252 forged headers (senders 3-254, counter 10^9) and 160 as an absent robot 5: the
/// pooled robot 1 went silent for the rest of the game. It now keeps its own share.
#[test]
fn forged_frame_counters_do_not_silence_a_pooled_team() {
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group();
    // 600 messages per minute for a team of 5: 2 a second per robot.
    let budget = ["--budget", "600/60s", "--budget-pool", "--team-size", "5"];
    let one = start(1, group, dir.path(), &budget);
    let two = start(2, group, dir.path(), &budget);
    let (mut c1, mut c2) = (one.client(), two.client());
    assert_eq!(c1.ask("SETV *.var.x 0"), "OK");
    c2.wait_for("1.var.x", Duration::from_secs(5), |a| a.contains(" int 0 "));

    let mut attacker = Attacker::new(group);
    let x = Value::Int(1);
    let header = [ItemRef::Update {
        path: "x",
        value: &x,
        version: 1,
        age_us: 0,
    }];
    for sender in 3..=254u8 {
        attacker.send(sender, 1_000_000_000, 128, &header);
    }
    for i in 0..160 {
        attacker.send(5, 1_000_000_000 + i, 128, &header);
    }
    std::thread::sleep(Duration::from_millis(200));
    let before = c1.stat("frames_out");
    let started = Instant::now();
    for i in 1..=100 {
        assert_eq!(c1.ask(&format!("SETV *.var.x {i}")), "OK");
        std::thread::sleep(Duration::from_millis(100));
    }
    let secs = started.elapsed().as_secs_f64();
    let sent = c1.stat("frames_out") - before;
    println!("after the forged counters robot 1 sent {sent} frames in {secs:.1} s (own share 2/s)");
    // Its own equal part of the line: (600 - 20) / 5 per minute, 1.93 a second.
    assert!(
        sent as f64 >= 1.93 * secs * 0.6,
        "robot 1 fell silent: {sent} frames in {secs:.1} s"
    );
    assert!(
        sent as f64 <= 2.0 * secs + 12.0,
        "beyond its share: {sent} frames in {secs:.1} s"
    );
    c2.wait_for("1.var.x", Duration::from_secs(5), |a| {
        a.contains(" int 100 ")
    });
}

/// 100 spoofed senders x 64 queues, a gap in each once a second, at an SPL robot: its
/// memory grew 6.6 -> 275 MB (NACKs piling up between paced frames) and its frames
/// carried NACKs, never its own value. Now memory stays bounded and its value arrives.
#[test]
fn spoofed_gaps_under_a_budget_neither_grow_memory_nor_crowd_out_the_robots_news() {
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group();
    let budget = ["--budget", "spl", "--team-size", "5"];
    let one = start(1, group, dir.path(), &budget);
    let two = start(2, group, dir.path(), &budget);
    let (mut c1, mut c2) = (one.client(), two.client());
    assert_eq!(c1.ask("SETV *.var.x 0"), "OK");
    c2.wait_for("1.var.x", Duration::from_secs(10), |a| {
        a.contains(" int 0 ")
    });
    let rss_before = rss_mib(&one);
    let mut attacker = Attacker::new(group);
    let queues: Vec<String> = (0..64).map(|q| format!("q{q}")).collect();
    let mut seq = 0;
    for s in 0..15u64 {
        for sender in 10..110u8 {
            // 8 heads to a 128-byte frame.
            for chunk in queues.chunks(8) {
                let items: Vec<ItemRef<'_>> = chunk
                    .iter()
                    .map(|q| ItemRef::TalkHead {
                        queue: q,
                        first: 1,
                        last: 10 * (s + 1),
                    })
                    .collect();
                seq += 1;
                attacker.send(sender, seq, 128, &items);
            }
        }
        assert_eq!(c1.ask(&format!("SETV *.var.x {}", s + 1)), "OK");
        std::thread::sleep(Duration::from_secs(1));
    }
    let rss_after = rss_mib(&one);
    println!(
        "15 s of spoofed gaps ({} kB): robot 1's memory {rss_before} -> {rss_after} MiB",
        attacker.bytes / 1000
    );
    assert!(rss_after <= 64, "robot 1 grew to {rss_after} MiB");
    // An SPL share is a frame every 5 s: the latest value is there within two.
    c2.wait_for("1.var.x", Duration::from_secs(12), |a| {
        a.contains(" int 15 ")
    });
}

/// Talk heads that make robot 2 give up messages, 1,000 a second for 3 s: a relay client
/// watching the team's talk got a `LOST` line for each (2.5x the attacker's bytes). Now
/// at most 20 a second, the rest counted.
#[test]
fn lost_lines_for_spoofed_give_ups_are_rate_limited_per_client() {
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group();
    let two = start(2, group, dir.path(), &[]);
    let mut watcher = two.client();
    assert_eq!(watcher.ask("ADDW +.talk.#"), "OK");
    let mut attacker = Attacker::new(group);
    let started = Instant::now();
    for k in 1..=3_000u64 {
        let head = [ItemRef::TalkHead {
            queue: "q",
            first: k + 1,
            last: k + 1,
        }];
        attacker.send(9, k, 1200, &head);
        if k % 100 == 0 {
            std::thread::sleep(Duration::from_millis(100));
        }
    }
    let secs = started.elapsed().as_secs_f64();
    let (bytes, _) = watcher.drain_to_end(Duration::from_secs(2));
    println!(
        "{} bytes of spoofed heads in {secs:.1} s -> {bytes} bytes of LOST lines to a client",
        attacker.bytes
    );
    let most = ((secs + 2.0) * 20.0 + 20.0) * 40.0;
    assert!(
        (bytes as f64) <= most,
        "{bytes} bytes of LOST lines (at most {most})"
    );
    let mut c = two.client();
    let suppressed = c.stat("relay_lost_suppressed");
    assert!(suppressed > 0, "the suppressed lines are counted");
}
