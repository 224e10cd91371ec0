//! `huddle sim --daemons` killed in the middle of its match: its daemons stop too. A
//! simulator stopped by Ctrl-C or killed by a CI timeout runs no destructors; its daemons
//! (real `huddle daemon` processes on loopback) used to run on, holding their relay ports
//! and their speakers' FIFOs, until someone found them with `ps`.
//!
//! Scenario: three robots, a 60 s match; once all three daemons are up, SIGKILL the
//! simulator (the worst case: not even a signal handler runs). Every daemon must be gone
//! (or a zombie waiting for its new parent to reap it) within 15 s: each gets SIGTERM from
//! the kernel when the simulator dies (prctl PR_SET_PDEATHSIG) and stops as on a robot.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time
#![cfg(target_os = "linux")]

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The pids whose parent is `parent` and whose command line is a `huddle daemon`.
fn daemons_of(parent: u32) -> Vec<u32> {
    let mut out = Vec::new();
    let Ok(dir) = std::fs::read_dir("/proc") else {
        return out;
    };
    for entry in dir.flatten() {
        let Some(pid) = entry
            .file_name()
            .to_str()
            .and_then(|s| s.parse::<u32>().ok())
        else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
            continue;
        };
        // "pid (comm) state ppid ...": comm may hold spaces, so split after its ')'.
        let Some(rest) = stat.rfind(')').map(|i| &stat[i + 1..]) else {
            continue;
        };
        let ppid = rest.split_whitespace().nth(1).and_then(|s| s.parse().ok());
        let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
        let args: Vec<&[u8]> = cmdline.split(|&b| b == 0).collect();
        if ppid == Some(parent) && args.get(1) == Some(&&b"daemon"[..]) {
            out.push(pid);
        }
    }
    out
}

/// Whether `pid` still runs (gone or a zombie: it does not).
fn running(pid: u32) -> bool {
    let Ok(stat) = std::fs::read_to_string(format!("/proc/{pid}/stat")) else {
        return false;
    };
    let state = stat
        .rfind(')')
        .and_then(|i| stat[i + 1..].split_whitespace().next());
    !matches!(state, Some("Z") | Some("X") | None)
}

#[test]
fn a_killed_simulator_takes_its_daemons_with_it() {
    let mut sim = Command::new(env!("CARGO_BIN_EXE_huddle"))
        .args(["sim", "--daemons", "--robots", "3", "--duration", "60s"])
        .args(["--seed", "5", "--json"])
        .env("RUST_LOG", "warn")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("run huddle sim --daemons");
    let started = Instant::now();
    let daemons = loop {
        let found = daemons_of(sim.id());
        if found.len() == 3 {
            break found;
        }
        if let Ok(Some(status)) = sim.try_wait() {
            panic!("the simulator ended before its three daemons were up: {status}");
        }
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "three daemons never came up (found {found:?})"
        );
        std::thread::sleep(Duration::from_millis(100));
    };
    // Let the match begin, then kill the simulator outright.
    std::thread::sleep(Duration::from_secs(2));
    sim.kill().expect("SIGKILL the simulator");
    sim.wait().expect("reap the simulator");
    let killed = Instant::now();
    let mut left: Vec<u32> = daemons.clone();
    while !left.is_empty() && killed.elapsed() < Duration::from_secs(15) {
        std::thread::sleep(Duration::from_millis(100));
        left.retain(|&pid| running(pid));
    }
    for &pid in &left {
        // Do not leave them behind for the next test either.
        let _ = Command::new("kill").args(["-9", &pid.to_string()]).status();
    }
    assert!(
        left.is_empty(),
        "daemons {left:?} of {daemons:?} still ran 15 s after their simulator was killed"
    );
}

#[test]
fn a_daemon_told_a_parent_that_is_not_its_own_refuses_to_start() {
    // Its real parent is this test; process 1 is not it (that parent has "exited").
    let out = Command::new(env!("CARGO_BIN_EXE_huddle"))
        .args(["daemon", "--id", "2", "--relay", "127.0.0.1:0"])
        .args(["--iface", "127.0.0.1", "--parent-pid", "1"])
        .env("RUST_LOG", "warn")
        .output()
        .expect("run huddle daemon");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "it must not start: {stderr}");
    assert!(
        stderr.contains("--parent-pid 1"),
        "the error names the flag: {stderr}"
    );
}
