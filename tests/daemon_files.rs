//! `huddle daemon` start-up files (issue #12): it says on stderr what it loaded (never the
//! key), refuses a missing config dir, a config or key that is not a regular file and a
//! key file without end, and warns about team-key mismatches at most once per 10 s.
//! Everything sends on loopback only (a group and port of the test's own).

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::io::{BufRead, BufReader};
use std::net::{Ipv4Addr, SocketAddrV4, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use comms::wire::{encode_frame, Frame, Item, TeamKey};
use comms::Value;
use driver::{open_multicast, SocketConfig};

const KEY: &str = "s3cret-team-key-do-not-print";

fn daemon(id: u8, group: SocketAddrV4, relay_port: u16, dir: &Path, extra: &[&str]) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_huddle"));
    cmd.args(["daemon", "--id", &id.to_string(), "--team", "7"])
        .args(["--group", &group.to_string(), "--iface", "127.0.0.1"])
        .args(["--relay", &format!("127.0.0.1:{relay_port}")])
        .arg("--config-dir")
        .arg(dir)
        .args(extra)
        .env("RUST_LOG", "info")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    cmd
}

/// Waits for a daemon that must exit at start (with a cap: an old daemon hung on a FIFO).
fn exits_at_start(mut child: Child) -> Output {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "the daemon did not exit: {}",
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn refused(dir: &Path, extra: &[&str]) -> String {
    let group = daemon_support::scratch_group();
    let relay = daemon_support::free_tcp_port();
    let child = daemon(1, group, relay, dir, extra).spawn().unwrap();
    let out = exits_at_start(child);
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "started anyway: {stderr}");
    stderr
}

#[test]
fn a_missing_config_dir_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-dir");
    let stderr = refused(&missing, &[]);
    assert!(
        stderr.contains("config dir") && stderr.contains("no-such-dir"),
        "{stderr}"
    );
}

#[test]
fn a_fifo_config_is_refused_instead_of_hanging_the_daemon() {
    let dir = tempfile::tempdir().unwrap();
    daemon_support::mkfifo(&dir.path().join("config.dat"));
    let stderr = refused(dir.path(), &[]);
    assert!(
        stderr.contains("config.dat: not a regular file (it is a FIFO)"),
        "{stderr}"
    );
    let dir = tempfile::tempdir().unwrap();
    daemon_support::mkfifo(&dir.path().join("config-1.dat"));
    let stderr = refused(dir.path(), &[]);
    assert!(
        stderr.contains("config-1.dat: not a regular file"),
        "{stderr}"
    );
}

#[test]
fn a_key_file_must_be_a_small_regular_file() {
    let dir = tempfile::tempdir().unwrap();
    let stderr = refused(dir.path(), &["--key-file", "/dev/zero"]);
    assert!(
        stderr.contains("key file /dev/zero: not a regular file"),
        "{stderr}"
    );
    let fifo = dir.path().join("fifo.key");
    daemon_support::mkfifo(&fifo);
    let stderr = refused(dir.path(), &["--key-file", fifo.to_str().unwrap()]);
    assert!(stderr.contains("it is a FIFO"), "{stderr}");
    let big = dir.path().join("big.key");
    std::fs::write(&big, vec![b'k'; 1 << 20]).unwrap();
    let stderr = refused(dir.path(), &["--key-file", big.to_str().unwrap()]);
    assert!(stderr.contains("larger than 4096 bytes"), "{stderr}");
}

/// The daemon's stderr, line by line, read by a thread.
fn stderr_lines(child: &mut Child) -> (mpsc::Receiver<String>, std::thread::JoinHandle<()>) {
    let stderr = child.stderr.take().unwrap();
    let (tx, rx) = mpsc::channel();
    let reader = std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines() {
            let Ok(line) = line else { return };
            if tx.send(line).is_err() {
                return;
            }
        }
    });
    (rx, reader)
}

/// Lines until one contains `needle` (with a cap); returns them all.
fn until(rx: &mpsc::Receiver<String>, needle: &str) -> Vec<String> {
    let mut seen = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match rx.recv_timeout(left) {
            Ok(line) => {
                let found = line.contains(needle);
                seen.push(line);
                if found {
                    return seen;
                }
            }
            Err(_) => panic!("no stderr line with {needle:?}; got {seen:#?}"),
        }
    }
}

#[test]
fn the_daemon_says_what_it_loaded_and_warns_once_about_key_mismatches() {
    let dir = tempfile::tempdir().unwrap();
    let key = dir.path().join("team.key");
    std::fs::write(&key, format!("{KEY}\n")).unwrap();
    std::fs::write(
        dir.path().join("config.dat"),
        "local.var.a = 1\n*.var.b = \"two\"\n",
    )
    .unwrap();
    std::fs::write(dir.path().join("config-2.dat"), "*.var.c = [1.5]\n").unwrap();
    let group = daemon_support::scratch_group();
    let relay = daemon_support::free_tcp_port();
    let mut child = daemon(
        2,
        group,
        relay,
        dir.path(),
        &["--key-file", key.to_str().unwrap()],
    )
    .spawn()
    .unwrap();
    let (rx, reader) = stderr_lines(&mut child);
    let mut lines = until(&rx, "config: 3 values from config.dat, config-2.dat");
    let key_line = lines
        .iter()
        .find(|l| l.contains("team key: "))
        .unwrap_or_else(|| panic!("no team key line before the config line: {lines:#?}"));
    assert!(key_line.contains(key.to_str().unwrap()), "{key_line}");

    // The relay is up once it accepts.
    let relay_addr = format!("127.0.0.1:{relay}").parse().unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    while TcpStream::connect(relay_addr).is_err() {
        assert!(Instant::now() < deadline, "the relay never came up");
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut c = daemon_support::Client::connect(relay_addr);

    // Three frames under another key and two without a tag, to the group.
    let tx = open_multicast(&SocketConfig {
        group,
        iface: Ipv4Addr::LOCALHOST,
        ..SocketConfig::default()
    })
    .unwrap()
    .socket;
    let forged = |seq| Frame {
        team: 7,
        sender: 9,
        incarnation: 1,
        seq,
        clock: Default::default(),
        items: vec![Item::Update {
            path: "x".into(),
            value: Value::Int(1),
            version: seq,
            age_us: 0,
        }],
    };
    let sending = Instant::now();
    for seq in 1..=3 {
        let bytes = encode_frame(&forged(seq), Some(&TeamKey::new(b"another-key")));
        tx.send_to(&bytes, group).unwrap();
    }
    for seq in 4..=5 {
        tx.send_to(&encode_frame(&forged(seq), None), group)
            .unwrap();
    }
    // Once the daemon has counted all five, it has said all it will say about them.
    let deadline = Instant::now() + Duration::from_secs(20);
    while c.stat("drops.bad_tag") < 3 || c.stat("drops.missing_tag") < 2 {
        assert!(Instant::now() < deadline, "the drops were never counted");
        std::thread::sleep(Duration::from_millis(20));
    }
    let counted_within = sending.elapsed();
    let _ = child.kill();
    let _ = child.wait();
    reader.join().unwrap();
    lines.extend(rx.try_iter());

    let warnings: Vec<&String> = lines
        .iter()
        .filter(|l| l.contains("team-key mismatch"))
        .collect();
    assert!(!warnings.is_empty(), "no warning: {lines:#?}");
    assert!(warnings[0].contains("1 frame(s)"), "{}", warnings[0]);
    // Five drops within one 10 s period make one warning (the other four are counted
    // for the next); only a machine stalled for 10 s could spread them over two.
    if counted_within < Duration::from_secs(10) {
        assert_eq!(warnings.len(), 1, "one warning for five drops: {lines:#?}");
    }
    assert!(
        lines.iter().all(|l| !l.contains(KEY)),
        "the key was printed: {lines:#?}"
    );
}
