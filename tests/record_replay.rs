//! `huddle record` and `huddle replay`: two daemons on loopback multicast (a group and port
//! of the test's own), a listen-only recorder, and every update found in the replay.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use daemon_support::Daemon;

fn huddle() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_huddle"));
    c.env("RUST_LOG", "warn");
    c
}

/// `huddle replay FILE --json`, parsed.
fn replay_json(file: &std::path::Path) -> Vec<serde_json::Value> {
    daemon_support::replay_json(file)
        .lines()
        .map(|l| serde_json::from_str(l).expect("each line is JSON"))
        .collect()
}

#[test]
fn two_daemons_recorded_and_replayed_every_update_found() {
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group();
    let g = group.to_string();
    let d1 = Daemon::start(1, &g, daemon_support::free_tcp_port(), &[], dir.path());
    let d2 = Daemon::start(2, &g, daemon_support::free_tcp_port(), &[], dir.path());
    // Robot 254 is the id a live monitor takes: a replay picks a free one instead.
    let d254 = Daemon::start(254, &g, daemon_support::free_tcp_port(), &[], dir.path());
    let file = dir.path().join("team.pcapng");
    let mut recorder = huddle()
        .args(["record", "--group", &g, "--iface", "127.0.0.1"])
        .arg(&file)
        .stdout(Stdio::null())
        .spawn()
        .expect("spawn huddle record");
    // The recorder has joined once it has written the file's headers and heard a frame:
    // both daemons send a heartbeat every refresh period.
    let deadline = Instant::now() + Duration::from_secs(20);
    while !(file.exists() && std::fs::metadata(&file).unwrap().len() > 100) {
        assert!(
            Instant::now() < deadline,
            "the recorder never wrote a frame"
        );
        std::thread::sleep(Duration::from_millis(20));
    }

    let (mut c1, mut c2) = (d1.client(), d2.client());
    let expected: Vec<(&str, &str, serde_json::Value)> = vec![
        ("1.var.ball.dist", "float", serde_json::json!(1.5)),
        ("1.var.ball.seen", "bool", serde_json::json!(true)),
        ("1.var.pose", "floats", serde_json::json!([1.0, -2.5, 0.25])),
        ("2.var.name", "string", serde_json::json!("robot \"two\"")),
        ("2.var.count", "int", serde_json::json!(41)),
        ("2.var.count", "int", serde_json::json!(42)),
        ("2.talk.plan", "string", serde_json::json!("pass to 1")),
        ("254.var.x", "int", serde_json::json!(7)),
    ];
    assert_eq!(d254.client().ask("SETV *.var.x 7"), "OK");
    for line in [
        "SETV *.var.ball.dist 1.5",
        "SETV *.var.ball.seen true",
        "SETV *.var.pose [1, -2.5, 0.25]",
    ] {
        assert_eq!(c1.ask(line), "OK", "{line}");
    }
    for line in [
        r#"SETV *.var.name "robot \"two\"""#,
        "SETV *.var.count 41",
        "SETV *.var.count 42",
        r#"SETV *.talk.plan "pass to 1""#,
    ] {
        assert_eq!(c2.ask(line), "OK", "{line}");
    }

    // Every datagram is on disk as it arrives: replay until all are there.
    let deadline = Instant::now() + Duration::from_secs(20);
    let lines = loop {
        let lines = replay_json(&file);
        let found = |(key, ty, value): &(&str, &str, serde_json::Value)| {
            lines
                .iter()
                .any(|l| l["key"] == *key && l["type"] == *ty && l["value"] == *value)
        };
        if expected.iter().all(found) {
            break lines;
        }
        let missing: Vec<_> = expected.iter().filter(|e| !found(e)).collect();
        assert!(
            Instant::now() < deadline,
            "not in the replay: {missing:?}\nreplayed: {lines:#?}"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    let _ = recorder.kill();
    let _ = recorder.wait();

    for l in &lines {
        let owner = l["owner"].as_u64().expect("an owner");
        let key = l["key"].as_str().expect("a key");
        assert!(key.starts_with(&format!("{owner}.")), "{l}");
        assert!(l["t"].as_f64().is_some_and(|t| t >= 0.0), "{l}");
    }
    // In the order they were set, per robot.
    let pos = |key: &str, value: serde_json::Value| {
        lines
            .iter()
            .position(|l| l["key"] == key && l["value"] == value)
            .unwrap()
    };
    assert!(pos("2.var.count", 41.into()) < pos("2.var.count", 42.into()));
    assert!(
        pos("1.var.ball.dist", 1.5.into())
            < pos("1.var.pose", serde_json::json!([1.0, -2.5, 0.25]))
    );
}

#[test]
fn a_recording_with_nothing_heard_is_valid_and_garbage_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group().to_string();
    let file = dir.path().join("empty.pcapng");
    let status = huddle()
        .args([
            "record",
            "--group",
            &group,
            "--iface",
            "127.0.0.1",
            "--duration",
            "100ms",
        ])
        .arg(&file)
        .status()
        .expect("run huddle record");
    assert!(status.success());
    assert!(replay_json(&file).is_empty());

    let junk = dir.path().join("junk.pcapng");
    std::fs::write(&junk, b"this is not a capture at all").unwrap();
    let out = huddle().arg("replay").arg(&junk).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("not a pcapng file"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn a_simulated_match_is_recorded_in_the_same_format_and_replays() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("sim.pcapng");
    let out = huddle()
        .args([
            "sim",
            "--robots",
            "3",
            "--duration",
            "3s",
            "--preset",
            "lan",
        ])
        .args(["--kill", "2@1s", "--json", "--record"])
        .arg(&file)
        .output()
        .expect("run huddle sim");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines = replay_json(&file);
    for robot in 1..=3 {
        for key in ["var.world.local", "var.machine.heuristic"] {
            let key = format!("{robot}.{key}");
            assert!(
                lines.iter().any(|l| l["key"] == key.as_str()),
                "no {key} in the replay"
            );
        }
    }
    // Robot 2 was switched off at 1 s: nothing of it after that, and the replay says it
    // departed.
    assert!(lines
        .iter()
        .filter(|l| l["owner"] == 2)
        .all(|l| l["t"].as_f64().unwrap() < 1.1));
    let text = huddle().arg("replay").arg(&file).output().unwrap();
    let text = String::from_utf8(text.stdout).unwrap();
    assert!(text.contains("robot 2 departed"), "{text}");
}

/// A pcapng file of `packets` (reception time in ns, frame), written as `huddle record`
/// writes one (section and interface headers, one enhanced packet block each).
fn pcapng_of(packets: &[(u64, Vec<u8>)]) -> Vec<u8> {
    let mut b = Vec::new();
    let block = |b: &mut Vec<u8>, kind: u32, body: &[u8]| {
        let len = (12 + body.len()) as u32;
        b.extend_from_slice(&kind.to_le_bytes());
        b.extend_from_slice(&len.to_le_bytes());
        b.extend_from_slice(body);
        b.extend_from_slice(&len.to_le_bytes());
    };
    let mut shb = Vec::new();
    shb.extend_from_slice(&0x1A2B_3C4Du32.to_le_bytes());
    shb.extend_from_slice(&1u16.to_le_bytes());
    shb.extend_from_slice(&0u16.to_le_bytes());
    shb.extend_from_slice(&(-1i64).to_le_bytes());
    block(&mut b, 0x0A0D_0D0A, &shb);
    // IPv4 link, snap length 65535, if_tsresol 9 (nanoseconds).
    let mut idb = Vec::new();
    idb.extend_from_slice(&228u16.to_le_bytes());
    idb.extend_from_slice(&0u16.to_le_bytes());
    idb.extend_from_slice(&65_535u32.to_le_bytes());
    idb.extend_from_slice(&[9, 0, 1, 0, 9, 0, 0, 0, 0, 0, 0, 0]);
    block(&mut b, 1, &idb);
    let from = "127.0.0.1:40000".parse().unwrap();
    let to = "239.255.0.1:2000".parse().unwrap();
    for (t_ns, payload) in packets {
        let mut data = Vec::new();
        netsim::pcap::push_ipv4_udp(&mut data, from, to, 1, 0, payload);
        let mut epb = Vec::new();
        epb.extend_from_slice(&0u32.to_le_bytes());
        epb.extend_from_slice(&((t_ns >> 32) as u32).to_le_bytes());
        epb.extend_from_slice(&(*t_ns as u32).to_le_bytes());
        epb.extend_from_slice(&(data.len() as u32).to_le_bytes());
        epb.extend_from_slice(&(data.len() as u32).to_le_bytes());
        epb.extend_from_slice(&data);
        epb.resize(20 + data.len().div_ceil(4) * 4, 0);
        block(&mut b, 6, &epb);
    }
    b
}

/// A frame of robot `sender` (team 1, no key) numbered `seq`, setting `x`.
fn frame(sender: u8, seq: u64) -> Vec<u8> {
    let mut w = comms::wire::FrameWriter::new(1, sender, 5, seq, 1200, None);
    w.push(comms::wire::ItemRef::Update {
        path: "x",
        value: &comms::Value::Int(seq as i64),
        version: seq,
        age_us: 0,
    });
    w.finish()
}

/// Runs `huddle replay` on `file`, killed after `limit`; returns its output and how long
/// it took.
fn replay_within(file: &std::path::Path, limit: Duration) -> (std::process::Output, Duration) {
    let started = Instant::now();
    let mut child = huddle()
        .arg("replay")
        .arg(file)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run huddle replay");
    while child.try_wait().unwrap().is_none() {
        if started.elapsed() > limit {
            child.kill().unwrap();
            let out = child.wait_with_output().unwrap();
            panic!(
                "replay still running after {limit:?}: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let took = started.elapsed();
    (child.wait_with_output().unwrap(), took)
}

/// Two frames 2^63 ns apart (a 200-byte file) took about a week of CPU: the listener
/// stepped through every 100 ms of the gap. Now any gap costs O(frames). The figure is
/// printed; the test bounds only a generous 20 s (a debug build on a shared machine).
#[test]
fn a_recording_with_a_gap_of_centuries_replays_at_once() {
    let dir = tempfile::tempdir().unwrap();
    for (name, gap_ns) in [
        ("forever.pcapng", 1u64 << 63),
        ("month.pcapng", 30 * 24 * 3600 * 1_000_000_000),
    ] {
        let file = dir.path().join(name);
        std::fs::write(&file, pcapng_of(&[(1, frame(1, 1)), (gap_ns, frame(1, 2))])).unwrap();
        let (out, took) = replay_within(&file, Duration::from_secs(20));
        println!("{name}: replayed in {took:?}");
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains("1.var.x = 2"), "{name}: {text}");
    }
}

/// `/dev/zero` was read into memory until it failed, a FIFO waited forever: both are
/// refused at once with a clear error.
#[test]
fn a_replay_of_a_device_or_a_fifo_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("fifo.pcapng");
    let made = Command::new("mkfifo").arg(&fifo).status();
    let mut inputs = vec![std::path::PathBuf::from("/dev/zero")];
    if made.is_ok_and(|s| s.success()) {
        inputs.push(fifo);
    } else {
        eprintln!("mkfifo not available: the FIFO case is skipped");
    }
    for input in inputs {
        let (out, _) = replay_within(&input, Duration::from_secs(20));
        assert!(!out.status.success(), "{}", input.display());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("not a regular file"),
            "{}: {err}",
            input.display()
        );
        assert!(!err.contains("panicked"), "{err}");
    }
}
