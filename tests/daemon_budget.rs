//! A league's message budget on a real daemon (`huddle daemon --budget`), over loopback.
//!
//! Scenario: robot 1 runs with `--budget 20/10s --team-size 1` (20 messages per 10 s of
//! game, 2 of them reserved for priority items) and writes a value 200 times as fast as
//! its relay takes them. Its teammate, robot 2 without a budget, counts what arrives.
//! Claims: robot 1 sends at most its share in the first 3 s (the paced allowance, one
//! ahead, plus the reserve), its teammate still gets the latest value, and under an SPL
//! budget a value that cannot fit a 128-byte frame is refused at SETV with the reason.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::time::Duration;

use daemon_support::{free_tcp_port, scratch_group, Daemon};

#[test]
fn a_budgeted_daemon_paces_its_frames_and_its_teammate_still_gets_the_latest_value() {
    let dir = tempfile::tempdir().unwrap();
    let group = scratch_group().to_string();
    let budgeted = Daemon::start(
        1,
        &group,
        free_tcp_port(),
        &["--budget", "20/10s", "--team-size", "1"],
        dir.path(),
    );
    let listener = Daemon::start(2, &group, free_tcp_port(), &[], dir.path());
    let mut c = budgeted.client();
    let started = std::time::Instant::now();
    for k in 0..200 {
        let answer = c.ask(&format!("SETV *.var.x {k}"));
        assert!(answer.starts_with("OK"), "SETV answered {answer:?}");
    }
    let mut l = listener.client();
    l.wait_for("1.var.x", Duration::from_secs(10), |a| a.contains(" 199"));
    let elapsed = started.elapsed().as_secs_f64();
    // Let the counters mirror (they refresh with the refresh period).
    std::thread::sleep(Duration::from_millis(300));
    let frames = c.stat("frames_out");
    // The paced allowance: one at once, then one per remaining game time / messages
    // left (about 0.56 s), plus at most the paced reserve (one ahead).
    let allowed = 1 + (elapsed / 0.5).ceil() as i64 + 2;
    assert!(
        (1..=allowed).contains(&frames),
        "{frames} frames in {elapsed:.2} s under 20 per 10 s (allowed {allowed})"
    );
}

#[test]
fn under_an_spl_budget_a_value_that_cannot_fit_128_bytes_is_refused_at_setv() {
    let dir = tempfile::tempdir().unwrap();
    let d = Daemon::start(
        3,
        &scratch_group().to_string(),
        free_tcp_port(),
        &["--budget", "spl"],
        dir.path(),
    );
    let mut c = d.client();
    let long = "x".repeat(150);
    let answer = c.ask(&format!("SETV *.var.note \"{long}\""));
    assert!(
        answer.starts_with("ERR") && answer.contains("128"),
        "a 150-byte string cannot fit an SPL frame: {answer:?}"
    );
    let fits = c.ask("SETV *.var.note \"short\"");
    assert!(fits.starts_with("OK"), "a short one fits: {fits:?}");
}
