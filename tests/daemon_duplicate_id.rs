//! A second daemon started by mistake with robot 1's id, on loopback beside the real
//! robots 1 and 2: robot 2 reports the conflict in its stats while both send, and hears
//! the real robot 1 again within a second of the impostor leaving. Everything sends on
//! loopback only, on a group and ports of the test's own.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::time::Duration;

use daemon_support::Daemon;

fn start(id: u8, group: &str, dir: &std::path::Path) -> Daemon {
    let relay_port = daemon_support::free_tcp_port();
    Daemon::start(id, group, relay_port, &["--team", "7"], dir)
}

#[test]
fn a_duplicate_id_is_reported_and_the_real_robot_is_heard_again_once_it_leaves() {
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group().to_string();
    let real = start(1, &group, dir.path());
    let two = start(2, &group, dir.path());
    let (mut c1, mut c2) = (real.client(), two.client());
    assert_eq!(c1.ask("SETV *.var.who \"real\""), "OK");
    c2.wait_for("1.var.who", Duration::from_secs(3), |a| {
        a.contains("\"real\"")
    });

    // The impostor starts later, so its incarnation is the newer one.
    let mut impostor = start(1, &group, dir.path());
    let mut ci = impostor.client();
    assert_eq!(ci.ask("SETV *.var.who \"impostor\""), "OK");
    c2.wait_for(
        "local.var.huddle.stats.id_conflicts",
        Duration::from_secs(3),
        |a| a.starts_with("VAL") && !a.contains(" int 0 "),
    );
    c2.wait_for(
        "local.var.huddle.stats.peer.1.conflicting",
        Duration::from_secs(3),
        |a| a.contains(" int 1 "),
    );
    // The real robot sees frames with its own id too, and counts them.
    c1.wait_for(
        "local.var.huddle.stats.id_conflicts",
        Duration::from_secs(3),
        |a| a.starts_with("VAL") && !a.contains(" int 0 "),
    );

    // The impostor leaves; the real robot is heard again (the 1 s bound is checked in
    // virtual time by comms' hardening tests; here only that it happens, on real sockets).
    drop(ci);
    impostor.kill();
    assert_eq!(c1.ask("SETV *.var.who \"real again\""), "OK");
    c2.wait_for("1.var.who", Duration::from_secs(5), |a| {
        a.contains("\"real again\"")
    });
}
