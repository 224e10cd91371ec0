//! The command line as people use it: one duration syntax, `--relay` in every form and
//! `HUDDLE_RELAY`, `echo`, `keys`, `get --json/--wait`, `stats --json`, completions and
//! the man page; output into a closed pipe ends quietly; user errors without backtraces;
//! plain logs off a terminal; `-q`/`-v`. Daemons on loopback only.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::io::{BufRead, BufReader, Read};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use daemon_support::Daemon;

fn huddle(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_huddle"));
    c.args(args)
        .env_remove("HUDDLE_RELAY")
        .env_remove("RUST_LOG");
    c
}

fn run(args: &[&str]) -> Output {
    huddle(args).output().expect("run huddle")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Runs with stdout a pipe whose reading end is closed before anything is written.
fn with_stdout_closed(mut cmd: Command) -> Output {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn huddle");
    drop(child.stdout.take());
    child.wait_with_output().expect("wait for huddle")
}

fn assert_quiet_exit(what: &str, out: &Output) {
    let stderr = text(&out.stderr);
    assert!(
        out.status.success(),
        "{what}: {} with stderr {stderr}",
        out.status
    );
    assert!(!stderr.contains("panicked"), "{what}: {stderr}");
    assert!(!stderr.contains("Broken pipe"), "{what}: {stderr}");
}

fn one_daemon(id: u8) -> (Daemon, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group().to_string();
    let port = daemon_support::free_tcp_port();
    let d = Daemon::start(id, &group, port, &["--refresh", "50ms"], dir.path());
    (d, dir)
}

#[test]
fn output_into_a_closed_pipe_ends_quietly() {
    let out = with_stdout_closed(huddle(&["sim", "--duration", "2s", "--robots", "3"]));
    assert_quiet_exit("sim | head", &out);
    let out = with_stdout_closed(huddle(&[
        "audio",
        "eval",
        "--messages",
        "5",
        "--noise-time",
        "1s",
    ]));
    assert_quiet_exit("audio eval | head", &out);
    let (d, _dir) = one_daemon(5);
    let relay = d.relay.to_string();
    let out = with_stdout_closed(huddle(&["stats", "--relay", &relay]));
    assert_quiet_exit("stats | head", &out);
    let out = with_stdout_closed(huddle(&["keys", "--relay", &relay]));
    assert_quiet_exit("keys | head", &out);
    let out = with_stdout_closed(huddle(&["completions", "bash"]));
    assert_quiet_exit("completions | head", &out);
    // And `sim | head -1` for real: read one line, then stop reading.
    let mut child = huddle(&["sim", "--duration", "2s", "--robots", "3"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    assert!(!first.is_empty());
    let out = child.wait_with_output().unwrap();
    assert_quiet_exit("sim | head -1", &out);
}

#[test]
fn user_errors_are_one_line_without_a_backtrace() {
    let port = daemon_support::free_tcp_port().to_string();
    let out = huddle(&["get", "*.var.x", "--relay", &port])
        .env("RUST_BACKTRACE", "1")
        .output()
        .unwrap();
    let stderr = text(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.starts_with("error: cannot reach a huddle relay at 127.0.0.1:"),
        "{stderr}"
    );
    assert!(!stderr.to_lowercase().contains("backtrace"), "{stderr}");
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
}

#[test]
fn bench_with_zero_rounds_is_a_clear_error() {
    for args in [
        ["bench", "comms", "--rounds", "0"],
        ["bench", "comms", "--updates", "0"],
    ] {
        let out = run(&args);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        assert!(
            stderr.contains("--rounds") || stderr.contains("--updates"),
            "{stderr}"
        );
    }
}

#[test]
fn a_robot_id_out_of_range_names_the_range_the_help_gives() {
    for id in ["0", "255", "300"] {
        let out = run(&["daemon", "--id", id]);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "--id {id}: {stderr}");
        assert!(
            stderr.contains("1..=254"),
            "--id {id} should say 1..=254: {stderr}"
        );
    }
    let help = text(&run(&["daemon", "--help"]).stdout);
    assert!(help.contains("1..=254"), "the help gives the same range");
}

#[test]
fn one_duration_syntax_and_bare_numbers_show_the_fix() {
    for (args, fix) in [
        (vec!["watch", "x.var.y", "--interval", "500"], "500ms"),
        (vec!["daemon", "--id", "1", "--refresh", "100"], "100ms"),
        (vec!["sim", "--duration", "300"], "300s"),
        (vec!["audio", "decode", "x.wav", "--duration", "1"], "1s"),
        (vec!["get", "x", "--wait", "--timeout", "5"], "5s"),
    ] {
        let out = run(&args);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(fix), "{args:?} should show {fix}: {stderr}");
    }
    // And the forms with units are taken everywhere.
    let help = run(&["audio", "decode", "--help"]);
    assert!(text(&help.stdout).contains("[default: 1s]"));
    let help = run(&["daemon", "--help"]);
    assert!(text(&help.stdout).contains("[default: 100ms]"));
}

#[test]
fn the_clients_against_a_daemon() {
    let (d, _dir) = one_daemon(6);
    let port = d.relay.port().to_string();
    let host_port = format!("localhost:{port}");
    // --relay as host:port with a name, as a bare port, and HUDDLE_RELAY.
    let out = run(&["set", "*.var.ball.dist", "1.5", "--relay", &host_port]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = huddle(&["get", "*.var.ball.dist", "--json"])
        .env("HUDDLE_RELAY", &port)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["key"], "6.var.ball.dist");
    assert_eq!(v["owner"], 6, "an integer, as in /state and Python");
    assert_eq!(v["type"], "float");
    assert_eq!(v["value"], 1.5);
    assert!(v["age_ms"].as_u64().unwrap() < 5000);

    // keys
    let out = run(&["keys", "6.var.#", "--relay", &port]);
    assert_eq!(text(&out.stdout), "6.var.ball.dist\n");
    let out = run(&["keys", "--all", "--relay", &port]);
    assert!(text(&out.stdout).contains("local.var.huddle.stats.frames_out\n"));

    // stats --json
    let out = run(&["stats", "--json", "--relay", &port]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["frames_out"].is_i64(), "{v}");
    assert!(v["drops"]["total"].is_i64(), "{v}");

    // echo: the current value, then each change as it happens.
    let mut echo = huddle(&["echo", "+.var.ball.#", "-n", "2", "--relay", &port])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(echo.stdout.take().unwrap()).lines();
    let first = lines.next().unwrap().unwrap();
    let fields: Vec<&str> = first.split('\t').collect();
    assert_eq!(fields[1..4], ["6", "6.var.ball.dist", "1.5"], "{first}");
    assert!(fields[4].ends_with("ms"), "{first}");
    run(&["set", "*.var.ball.dist", "2.5", "--relay", &port]);
    let second = lines.next().unwrap().unwrap();
    assert!(second.contains("\t6.var.ball.dist\t2.5\t"), "{second}");
    assert!(echo.wait().unwrap().success(), "-n 2: exits after two");
    let out = run(&[
        "echo",
        "+.var.ball.#",
        "-n",
        "1",
        "--json",
        "--relay",
        &port,
    ]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["value"], 2.5);
    assert!(v["time"].as_str().unwrap().ends_with('Z'));

    // get --wait waits for a key to appear; without --wait an unknown key fails at once.
    let out = run(&["get", "*.var.late", "--relay", &port]);
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out.stderr).contains("--wait"));
    let waiting = huddle(&[
        "get",
        "*.var.late",
        "--wait",
        "--timeout",
        "10s",
        "--relay",
        &port,
    ])
    .stdout(Stdio::piped())
    .spawn()
    .unwrap();
    std::thread::sleep(Duration::from_millis(300));
    run(&["set", "*.var.late", "\"here\"", "--relay", &port]);
    let out = waiting.wait_with_output().unwrap();
    assert!(out.status.success());
    assert!(text(&out.stdout).starts_with("6.var.late string \"here\""));
    let started = Instant::now();
    let out = run(&[
        "get",
        "*.var.never",
        "--wait",
        "--timeout",
        "300ms",
        "--relay",
        &port,
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(started.elapsed() >= Duration::from_millis(300));
    assert!(
        text(&out.stderr).contains("after 300ms"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn watch_on_a_pipe_survives_a_daemon_restart() {
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group().to_string();
    let port = daemon_support::free_tcp_port();
    let relay = format!("127.0.0.1:{port}");
    let mut d = Daemon::start(7, &group, port, &["--refresh", "50ms"], dir.path());
    run(&["set", "*.var.x", "1", "--relay", &relay]);
    let mut watch = huddle(&["watch", "+.var.x", "--interval", "0s", "--relay", &relay])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(watch.stdout.take().unwrap()).lines();
    assert!(lines
        .next()
        .unwrap()
        .unwrap()
        .starts_with("7.var.x\t7\t1\t"));
    d.kill();
    let d2 = Daemon::start(7, &group, port, &["--refresh", "50ms"], dir.path());
    run(&["set", "*.var.x", "2", "--relay", &relay]);
    let line = lines.next().unwrap().unwrap();
    assert!(
        line.starts_with("7.var.x\t7\t2\t"),
        "after the restart: {line}"
    );
    let _ = watch.kill();
    let mut stderr = String::new();
    watch
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut stderr)
        .unwrap();
    let _ = watch.wait();
    assert!(stderr.contains("reconnecting"), "{stderr}");
    drop(d2);
}

#[test]
fn logs_are_plain_off_a_terminal_and_q_quietens_them() {
    let daemon_log = |extra: &[&str]| {
        let dir = tempfile::tempdir().unwrap();
        let group = daemon_support::scratch_group().to_string();
        let relay = daemon_support::free_tcp_port().to_string();
        let mut args = vec!["daemon", "--id", "9", "--group", &group, "--relay", &relay];
        let dir_arg = dir.path().to_str().unwrap().to_owned();
        args.extend(["--config-dir", &dir_arg]);
        args.extend(extra);
        let mut child = huddle(&args)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Up once the relay greets: the daemon logged that it runs before it serves.
        let addr = format!("127.0.0.1:{relay}").parse().unwrap();
        daemon_support::await_relay(&mut child, addr, 9);
        let _ = child.kill();
        text(&child.wait_with_output().unwrap().stderr)
    };
    let log = daemon_log(&[]);
    assert!(log.contains("huddle daemon running"), "{log}");
    assert!(!log.contains('\x1b'), "no colour codes on a pipe: {log:?}");
    let log = daemon_log(&["-q"]);
    assert!(!log.contains("huddle daemon running"), "-q: {log}");
    let log = daemon_log(&["-v"]);
    assert!(
        log.contains("DEBUG") || log.contains("huddle daemon running"),
        "{log}"
    );
}

#[test]
fn completions_and_the_man_page_come_from_the_same_definitions() {
    for shell in ["bash", "zsh", "fish"] {
        let out = run(&["completions", shell]);
        assert!(out.status.success());
        let script = text(&out.stdout);
        assert!(
            script.contains("huddle") && script.contains("echo") && script.contains("relay"),
            "{shell}"
        );
    }
    let out = run(&["man"]);
    let page = text(&out.stdout);
    assert!(
        page.starts_with(".ie") || page.contains(".TH huddle"),
        "{page}"
    );
    assert!(page.contains("completions") && page.contains("echo"));
}

#[test]
fn get_with_a_maximum_age_refuses_a_stale_value() {
    let (d, _dir) = one_daemon(7);
    let relay = d.relay.to_string();
    let set = run(&["set", "local.var.pose.x", "1.5", "--relay", &relay]);
    assert!(set.status.success(), "set: {}", text(&set.stderr));
    std::thread::sleep(Duration::from_millis(50));
    let fresh_enough = run(&[
        "get",
        "local.var.pose.x",
        "--max-age",
        "1min",
        "--relay",
        &relay,
    ]);
    assert!(
        fresh_enough.status.success() && text(&fresh_enough.stdout).contains("1.5"),
        "{}",
        text(&fresh_enough.stderr)
    );
    let stale = run(&[
        "get",
        "local.var.pose.x",
        "--max-age",
        "10ms",
        "--relay",
        &relay,
    ]);
    assert_eq!(stale.status.code(), Some(1), "a stale value is an error");
    let err = text(&stale.stderr);
    assert!(err.contains("406") && err.contains("ms old"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

/// The golden frame of `comms/tests/talk_unknown_value.rs` (robot 3 of team 7, a newer
/// build): talk queue `plan`, messages 1 (`Int(5)`), 2 (value tag 6, unknown here) and 3
/// (`Int(7)`).
const GOLDEN_FUTURE_TALK: &str = include_str!("../comms/tests/golden/future_talk.hex");

#[test]
fn huddle_stats_shows_a_newer_builds_talk_value_on_its_talk_line() {
    // Robot 1 of team 7 hears robot 3 of a newer build post a value type it does not
    // know: `huddle stats` says so (before, only `--json` and the blackboard did).
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group();
    let d = Daemon::start(
        1,
        &group.to_string(),
        daemon_support::free_tcp_port(),
        &["--team", "7", "--refresh", "50ms"],
        dir.path(),
    );
    let socket = driver::open_multicast(&driver::SocketConfig {
        group,
        iface: std::net::Ipv4Addr::LOCALHOST,
        ..driver::SocketConfig::default()
    })
    .expect("the newer robot joins on loopback")
    .socket;
    let hex = GOLDEN_FUTURE_TALK.trim();
    let frame: Vec<u8> = (0..hex.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).unwrap())
        .collect();
    socket.send_to(&frame, group).expect("send on loopback");
    let mut c = d.client();
    c.wait_for(
        "local.var.huddle.stats.talk_unknown_value",
        Duration::from_secs(5),
        |a| a.contains(" int 1 "),
    );
    let relay = d.relay.to_string();
    let out = run(&["stats", "--relay", &relay]);
    let stdout = text(&out.stdout);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        stdout.contains("talk delivered 2  given up 0  unknown value 1  resent 0"),
        "messages 1 and 3 delivered, 2 counted on the talk line:\n{stdout}"
    );
}
