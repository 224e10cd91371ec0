//! Raw bytes against a real daemon's relay port: every command, every error, a 1 MiB
//! line, and a client that never reads while values change fast. Loopback only.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::time::{Duration, Instant};

use comms::relay::Binding;
use daemon_support::{Client, Daemon};

/// Robot `id` alone on a group of its own, its relay on a free port.
fn daemon(id: u8) -> (Daemon, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group().to_string();
    let relay_port = daemon_support::free_tcp_port();
    (
        Daemon::start(id, &group, relay_port, &["--refresh", "100ms"], dir.path()),
        dir,
    )
}

#[test]
fn every_command_over_tcp() {
    let (d, _dir) = daemon(4);
    let mut c = d.client();
    assert_eq!(c.greeting, "HUDDLE 2 robot 4");
    assert_eq!(c.ask("SETV *.var.pose [1.5, -2, 0.25]"), "OK");
    assert_eq!(c.ask("setv local.var.note \"a \\\"quoted\\\" word\""), "OK");
    let b = Binding::parse(&c.ask("GETV *.var.pose")).unwrap();
    let age = b.age_ms;
    assert_eq!(
        (b.key.as_str(), b.ty.as_str(), b.value.as_str()),
        ("4.var.pose", "floats", "[1.5, -2.0, 0.25]")
    );
    assert!(age < 1000);
    c.send_raw(b"GETV local.var.note\r\n");
    assert!(c
        .line()
        .starts_with("VAL local.var.note string \"a \\\"quoted\\\" word\" "));
    assert_eq!(c.ask("ADDW 4.var.#"), "OK");
    assert_eq!(c.ask("ADDW local.var.note"), "OK");
    c.send_raw(b"LSTW\n");
    assert_eq!(
        [c.line(), c.line(), c.line()],
        ["WATCH 4.var.#", "WATCH local.var.note", "END"]
    );
    assert_eq!(c.ask("DELW local.var.note"), "OK");
    // Periodic pushes: the snapshot at once, then one per period.
    assert_eq!(c.ask("REFR 50"), "OK");
    let started = Instant::now();
    for _ in 0..3 {
        assert!(c
            .line()
            .starts_with("UPD 4.var.pose floats [1.5, -2.0, 0.25] "));
    }
    assert!(
        started.elapsed() >= Duration::from_millis(90),
        "three pushes span two periods"
    );
    // Push on change.
    assert_eq!(c.ask("CLRW"), "OK");
    assert_eq!(c.ask("ADDW +.var.speed"), "OK");
    assert_eq!(c.ask("REFR 0"), "OK");
    let mut other = d.client();
    assert_eq!(other.ask("SETV *.var.speed 3"), "OK");
    assert_eq!(c.line(), "UPD 4.var.speed int 3 0");
    assert_eq!(c.ask("QUIT"), "BYE");
    let (_, closed) = c.drain_to_end(Duration::from_secs(2));
    assert!(closed, "QUIT closes the connection");
}

#[test]
fn every_error_over_tcp_and_the_session_continues() {
    let (d, _dir) = daemon(5);
    let mut c = d.client();
    let too_big = format!("SETV *.var.blob \"{}\"", "x".repeat(2000));
    let cases: Vec<(String, &str)> = vec![
        ("FROB x".into(), "ERR 400 "),
        ("GETV".into(), "ERR 401 "),
        ("GETV local.var.nothing".into(), "ERR 404 "),
        ("DELW 1.var.x".into(), "ERR 404 "),
        ("GETV 300.var.x".into(), "ERR 410 "),
        ("ADDW #.var".into(), "ERR 411 "),
        ("SETV *.var.x maybe".into(), "ERR 412 "),
        ("REFR soon".into(), "ERR 413 "),
        ("SETV 2.var.x 1".into(), "ERR 420 "),
        ("SETV 2.talk.plan 1".into(), "ERR 421 "),
        ("GETV *.talk.plan".into(), "ERR 421 "),
        (too_big, "ERR 422 "),
    ];
    for (line, want) in &cases {
        let got = c.ask(line);
        assert!(
            got.starts_with(want),
            "{line:.40} answered {got:?}, wanted {want}..."
        );
    }
    c.send_raw(b"SETV local.var.s \"\xc3\x28\"\n");
    assert!(c.line().starts_with("ERR 403 "));
    for i in 0..256 {
        assert_eq!(c.ask(&format!("ADDW local.var.w{i}")), "OK");
    }
    assert!(c.ask("ADDW local.var.one-more").starts_with("ERR 429 "));
    assert_eq!(
        c.ask("SETV local.var.after 1"),
        "OK",
        "errors never end the session"
    );
}

#[test]
fn a_one_mebibyte_line_is_refused_once_and_the_session_continues() {
    let (d, _dir) = daemon(6);
    let mut c = d.client();
    let mut huge = b"SETV local.var.x \"".to_vec();
    huge.resize(huge.len() + (1 << 20), b'z');
    huge.extend_from_slice(b"\"\nGETV local.var.x\nSETV local.var.x 7\nGETV local.var.x\n");
    let mut writer = c.writer.try_clone().unwrap();
    let sender = std::thread::spawn(move || {
        use std::io::Write;
        writer.write_all(&huge).unwrap();
    });
    assert!(c.line().starts_with("ERR 402 "));
    assert!(
        c.line().starts_with("ERR 404 "),
        "the huge line was not executed"
    );
    assert_eq!(c.line(), "OK");
    assert!(c.line().starts_with("VAL local.var.x int 7 "));
    sender.join().unwrap();
}

#[test]
fn a_client_that_never_reads_is_cut_off_and_the_others_carry_on() {
    let (d, _dir) = daemon(7);
    // The sluggard watches everything, asks for every change, then never reads.
    let mut sluggard = d.client();
    sluggard.send_raw(b"ADDW #\nREFR 0\n");
    // A well-behaved watcher of one key.
    let mut watcher = d.client();
    assert_eq!(watcher.ask("ADDW local.var.tick"), "OK");
    assert_eq!(watcher.ask("REFR 0"), "OK");
    // A writer changes 3 KB values as fast as the relay takes them.
    let mut writer = d.client();
    let blob = "b".repeat(3000);
    let started = Instant::now();
    let mut cut_off = false;
    let mut round = 0u64;
    while started.elapsed() < Duration::from_secs(20) {
        let mut batch = String::new();
        for i in 0..100 {
            batch += &format!("SETV local.var.blob{} \"{blob}{round}\"\n", i % 10);
        }
        writer.send_raw(batch.as_bytes());
        for _ in 0..100 {
            assert_eq!(writer.line(), "OK");
        }
        round += 1;
        assert_eq!(writer.ask(&format!("SETV local.var.tick {round}")), "OK");
        assert_eq!(
            watcher.line(),
            format!("UPD local.var.tick int {round} 0"),
            "the watcher carries on"
        );
        if round.is_multiple_of(20) {
            // Peek without reading the backlog: has the relay closed the socket?
            let mut probe = [0u8; 1];
            let sock = sluggard.reader.get_ref();
            sock.set_nonblocking(true).unwrap();
            let peeked = sock.peek(&mut probe);
            sock.set_nonblocking(false).unwrap();
            if peeked.is_err()
                && !matches!(
                    peeked.as_ref().map_err(|e| e.kind()),
                    Err(std::io::ErrorKind::WouldBlock)
                )
            {
                cut_off = true;
                break;
            }
            // A closed socket still delivers its buffered bytes first: drain it to know.
            if round.is_multiple_of(200) {
                let (bytes, closed) = sluggard.drain_to_end(Duration::from_secs(2));
                assert!(closed, "after {round} rounds ({bytes} bytes read late) the sluggard is still connected");
                cut_off = true;
                break;
            }
        }
    }
    assert!(cut_off, "the client that never reads was not cut off");
    // The daemon and the others are fine.
    assert_eq!(writer.ask("SETV local.var.tick 0"), "OK");
    assert_eq!(watcher.line(), "UPD local.var.tick int 0 0");
    let mut fresh: Client = d.client();
    assert!(fresh
        .ask("GETV local.var.tick")
        .starts_with("VAL local.var.tick int 0 "));
}

#[test]
fn a_non_ascii_watch_pattern_or_key_is_refused_and_counted() {
    // Robot 5; a client watches `*.var.balé.#` (it would never match: keys are ASCII),
    // then tries keys with non-ASCII letters in SETV, GETV and a talk post.
    let (d, _dir) = daemon(5);
    let mut c = d.client();
    let refused = [
        ("ADDW *.var.bal\u{e9}.#", "ERR 411 "),
        ("DELW +.var.\u{3b2}", "ERR 411 "),
        ("SETV *.var.caf\u{e9} 1", "ERR 410 "),
        ("GETV 2.var.\u{3b2}", "ERR 410 "),
        ("SETV *.talk.pl\u{e4}n 1", "ERR 410 "),
    ];
    for (line, want) in refused {
        let answer = c.ask(line);
        assert!(answer.starts_with(want), "{line:?} answered {answer:?}");
    }
    c.send_raw(b"LSTW\n");
    assert_eq!(c.line(), "END", "the pattern was not added");
    assert_eq!(
        c.ask("SETV local.var.name \"Jos\u{e9}\""),
        "OK",
        "a string value"
    );
    // The counter is mirrored at the daemon's timers.
    let want = refused.len().to_string();
    c.wait_for(
        "local.var.huddle.stats.relay_non_ascii_refused",
        Duration::from_secs(5),
        |a| a.contains(&format!(" int {want} ")),
    );
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_huddle"))
        .args(["stats", "--relay", &d.relay.to_string()])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        stdout.contains(&format!("relay_non_ascii_refused {want}")),
        "huddle stats shows it:\n{stdout}"
    );
}

/// Connects, and returns the client if it was served, or the one line it got before
/// the daemon closed the connection.
fn served_or_refused(d: &Daemon) -> Result<Client, String> {
    let mut c = d.client();
    if !c.greeting.starts_with("ERR ") {
        return Ok(c);
    }
    let mut rest = String::new();
    let n = std::io::BufRead::read_line(&mut c.reader, &mut rest).unwrap_or(0);
    assert_eq!(n, 0, "closed after the one line, not {rest:?}");
    Err(c.greeting)
}

#[test]
fn clients_over_the_cap_get_one_err_503_line_and_the_others_carry_on() {
    // Robot 6 with the default cap of 64 relay clients: one host opens 65. The
    // connection the start-up probe made may still count for a moment, so the 64 are
    // retried until served; from then on every connection over the cap is refused.
    let (d, _dir) = daemon(6);
    let cap = 64;
    let mut refused = 0;
    let mut clients = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(10);
    while clients.len() < cap {
        match served_or_refused(&d) {
            Ok(c) => clients.push(c),
            Err(_) => {
                refused += 1;
                assert!(Instant::now() < deadline, "only {} served", clients.len());
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    }
    let over = served_or_refused(&d).err().expect("the 65th is refused");
    refused += 1;
    assert!(
        over.starts_with("ERR 503 too many relay clients (64 connected, --max-clients)"),
        "{over}"
    );
    // Every client already connected still works.
    for (i, c) in clients.iter_mut().enumerate() {
        assert_eq!(
            c.ask(&format!("SETV local.var.c{i} {i}")),
            "OK",
            "client {i}"
        );
    }
    let b = Binding::parse(&clients[0].ask("GETV local.var.c63")).unwrap();
    assert_eq!(b.value, "63");
    clients[0].wait_for(
        "local.var.huddle.stats.relay_clients_refused",
        Duration::from_secs(5),
        |a| a.contains(&format!(" int {refused} ")),
    );
    // One leaves: a newcomer is served again.
    drop(clients.pop());
    let deadline = Instant::now() + Duration::from_secs(10);
    let newcomer = loop {
        match served_or_refused(&d) {
            Ok(c) => break c,
            Err(_) => {
                assert!(Instant::now() < deadline, "no room after one left");
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    };
    assert_eq!(newcomer.greeting, "HUDDLE 2 robot 6");
}

#[test]
fn max_clients_sets_the_cap() {
    // Robot 7 with --max-clients 2: the third connection is refused and counted.
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group().to_string();
    let port = daemon_support::free_tcp_port();
    let d = Daemon::start(7, &group, port, &["--max-clients", "2"], dir.path());
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut clients = Vec::new();
    while clients.len() < 2 {
        match served_or_refused(&d) {
            Ok(c) => clients.push(c),
            Err(_) => {
                assert!(Instant::now() < deadline, "only {} served", clients.len());
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    }
    let over = served_or_refused(&d).err().expect("the third is refused");
    assert!(
        over.starts_with("ERR 503 too many relay clients (2 connected"),
        "{over}"
    );
    assert_eq!(clients[1].ask("SETV local.var.x 1"), "OK");
    // The command line says why it cannot connect.
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_huddle"))
        .args(["get", "local.var.x", "--relay", &d.relay.to_string()])
        .env_remove("RUST_LOG")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("refused the connection: ERR 503 too many relay clients"),
        "{stderr}"
    );
}
