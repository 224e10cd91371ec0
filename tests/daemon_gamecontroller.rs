//! The league's GameController on a real daemon (`huddle daemon --budget spl`), over
//! loopback: a scripted GC sends RGme packets by unicast to 127.0.0.1 on a port of the
//! test's own and listens for the robot's RGrt status on another.
//!
//! Scenario: robot 1 of team 12 runs under the SPL budget; its program writes a value
//! every 20 ms. The GC says Playing with plenty left: frames go and the game state is on
//! the blackboard. A stale packet (an older packetNumber saying Set) and truncated,
//! oversized, wrong-version and wrong-team packets are counted and change nothing. The GC
//! penalizes the robot: its keys change. A program cannot write the GC's keys or the
//! team layer's outputs (`ERR 423`). Its status packets carry the pose, the team layer's
//! ball relative to the robot and `fallen`. Then the GC says the team's budget is 0: the
//! daemon sends nothing more while the program keeps writing.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use daemon_support::{free_tcp_port, free_udp_port, scratch_group, Client, Daemon};
use gamecontroller::{GameControlData, State, StatusMessage};

struct ScriptedGc {
    socket: UdpSocket,
    to: String,
    game: GameControlData,
}

impl ScriptedGc {
    /// Sends the game as it stands, numbered one after the last.
    fn send(&mut self) {
        self.game.packet_number = self.game.packet_number.wrapping_add(1);
        self.socket.send_to(&self.game.encode(), &self.to).unwrap();
    }

    fn send_raw(&self, bytes: &[u8]) {
        self.socket.send_to(bytes, &self.to).unwrap();
    }
}

/// Writes `*.var.x` every 20 ms for `d`, sending the GC's packet every 100 ms.
fn write_for(c: &mut Client, gc: &mut ScriptedGc, d: Duration) {
    let start = Instant::now();
    let mut k = 0;
    while start.elapsed() < d {
        let answer = c.ask(&format!("SETV *.var.x {k}"));
        assert!(answer.starts_with("OK"), "{answer:?}");
        if k % 5 == 0 {
            gc.send();
        }
        k += 1;
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn a_scripted_gamecontroller_drives_the_keys_the_status_and_the_budget_to_zero() {
    let dir = tempfile::tempdir().unwrap();
    let gc_port = free_udp_port();
    let status = UdpSocket::bind("127.0.0.1:0").unwrap();
    status
        .set_read_timeout(Some(Duration::from_secs(3)))
        .unwrap();
    let status_port = status.local_addr().unwrap().port().to_string();
    let listen = format!("127.0.0.1:{gc_port}");
    let d = Daemon::start(
        1,
        &scratch_group().to_string(),
        free_tcp_port(),
        &[
            "--budget",
            "spl",
            "--team",
            "12",
            "--gc-listen",
            &listen,
            "--gc-status-port",
            &status_port,
        ],
        dir.path(),
    );
    let mut c = d.client();
    let mut gc = ScriptedGc {
        socket: UdpSocket::bind("127.0.0.1:0").unwrap(),
        to: listen.clone(),
        game: GameControlData::new([12, 34]),
    };
    // Playing, first half, 500 s left, 1,150 of the team's messages left: ahead of the
    // GC's line (1,100 for the 1,100 s to go).
    gc.game.state = State::Playing;
    gc.game.secs_remaining = 500;
    gc.game.team_mut(12).unwrap().message_budget = 1150;
    gc.send();
    c.wait_for("local.var.gc.state", Duration::from_secs(5), |a| {
        a.contains("\"playing\"")
    });
    let budget = c.ask("GETV local.var.gc.budget");
    assert!(budget.contains(" 1150 "), "{budget:?}");
    let counted = c.ask("GETV local.var.gc.counted");
    assert!(counted.contains(" true "), "{counted:?}");

    write_for(&mut c, &mut gc, Duration::from_secs(1));
    let frames = c.stat("frames_out");
    assert!(frames > 0, "frames go while the GC's budget has room");

    // A stale packet (the number before the newest) saying Set: ignored.
    let mut stale = gc.game;
    stale.packet_number = gc.game.packet_number.wrapping_sub(1);
    stale.state = State::Set;
    gc.send_raw(&stale.encode());
    // Bad packets: truncated, oversized, another version, another game.
    let good = gc.game.encode();
    gc.send_raw(&good[..60]);
    gc.send_raw(&[&good[..], &[0u8; 4]].concat());
    let mut v17 = good;
    v17[4] = 17;
    gc.send_raw(&v17);
    let mut other = GameControlData::new([5, 6]);
    other.packet_number = gc.game.packet_number.wrapping_add(1);
    other.state = State::Finished;
    gc.send_raw(&other.encode());
    c.wait_for(
        "local.var.huddle.stats.gc.wrong_team",
        Duration::from_secs(5),
        |a| a.contains(" 1 "),
    );
    assert_eq!(c.stat("gc.bad_length"), 2);
    assert_eq!(c.stat("gc.wrong_version"), 1);
    assert_eq!(c.stat("gc.stale"), 1);
    let state = c.ask("GETV local.var.gc.state");
    assert!(
        state.contains("\"playing\""),
        "neither the stale nor the bad packets moved the game: {state:?}"
    );

    // A penalty for robot 1: pushing, 45 s.
    let me = &mut gc.game.team_mut(12).unwrap().players[0];
    me.penalty = 2;
    me.secs_till_unpenalised = 45;
    gc.send();
    c.wait_for("local.var.gc.penalty", Duration::from_secs(5), |a| {
        a.contains(" 2 ")
    });
    let secs = c.ask("GETV local.var.gc.penalty_secs");
    assert!(secs.contains(" 45 "), "{secs:?}");

    // The GC's keys and the team layer's outputs are the daemon's: a program cannot
    // write them (`ERR 423`), so no program makes the others read a false game.
    for line in [
        "SETV local.var.gc.state \"set\"",
        "SETP local.var.gc.penalty 0",
        "SETV local.var.team.ball [2.0, 2.0]",
    ] {
        let answer = c.ask(line);
        assert!(answer.starts_with("ERR 423 "), "{line}: {answer}");
    }
    assert!(
        c.ask("GETV local.var.gc.state").contains("\"playing\""),
        "the GC's word stands"
    );

    // Status: pose (1 m, 2 m, facing +x); the program sees the ball 1 m ahead, so the
    // team layer's ball is at (2 m, 2 m); fallen.
    for _ in 0..10 {
        for line in [
            "SETV local.var.robot.ball [1.0, 0.0, 0.0004, 0.0, 0.0004]",
            "SETV local.var.robot.pose [1.0, 2.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.003]",
        ] {
            assert!(c.ask(line).starts_with("OK"), "{line}");
        }
        std::thread::sleep(Duration::from_millis(40));
    }
    c.wait_for("local.var.team.ball", Duration::from_secs(5), |a| {
        a.contains(" floats [") && !a.contains(" floats []")
    });
    assert!(c.ask("SETV local.var.robot.fallen true").starts_with("OK"));
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut buf = [0u8; 64];
    let msg = loop {
        let (n, _) = status.recv_from(&mut buf).expect("status packets arrive");
        let msg = StatusMessage::decode(&buf[..n]).expect("a valid RGrt");
        if msg.fallen || Instant::now() > deadline {
            break msg;
        }
    };
    assert_eq!((msg.player_num, msg.team_num, msg.fallen), (1, 12, true));
    assert_eq!(msg.pose, [1000.0, 2000.0, 0.0]);
    assert!(
        (msg.ball[0] - 1000.0).abs() < 20.0 && msg.ball[1].abs() < 20.0,
        "the team layer's ball, 1 m ahead (mm, robot frame): {msg:?}"
    );
    assert!((0.0..5.0).contains(&msg.ball_age), "{msg:?}");

    // The GC says the team has nothing left: not one frame more.
    gc.game.team_mut(12).unwrap().message_budget = 0;
    gc.send();
    c.wait_for("local.var.gc.budget", Duration::from_secs(5), |a| {
        a.contains(" 0 ")
    });
    // Counters are mirrored with the refresh period.
    std::thread::sleep(Duration::from_millis(300));
    let at_zero = c.stat("frames_out");
    write_for(&mut c, &mut gc, Duration::from_secs(2));
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(
        c.stat("frames_out"),
        at_zero,
        "a frame sent at the GC's 0 makes the team illegal"
    );
    assert!(c.stat("gc.status_sent") > 0, "status packets still go");
}

/// A daemon of team 12 with the GC listener on `gc_port` (status packets to `status_port`)
/// and its team layer.
fn team_daemon(
    id: u8,
    group: &str,
    gc_port: u16,
    status_port: u16,
    dir: &std::path::Path,
) -> Daemon {
    Daemon::start(
        id,
        group,
        free_tcp_port(),
        &[
            "--team",
            "12",
            "--refresh",
            "50ms",
            "--gamecontroller",
            "--gc-listen",
            &format!("127.0.0.1:{gc_port}"),
            "--gc-status-port",
            &status_port.to_string(),
        ],
        dir,
    )
}

#[test]
fn a_penalised_robot_leaves_the_arbitration_and_its_teammates_drop_its_claim() {
    // Robots 1 and 2 of team 12, each with its program's cost: robot 1 is nearer the ball
    // (0.5 against 1.0) and goes. The GameController penalises robot 1 and robot 2 hears
    // it first: robot 2 goes at once, by the GC's word alone (robot 1 still claims).
    // Then robot 1 hears it too: it stops, and tells the team (its claim turns to the
    // penalised cost). Its penalty over, it is back in the arbitration.
    let dir = tempfile::tempdir().unwrap();
    let group = scratch_group().to_string();
    let status = UdpSocket::bind("127.0.0.1:0").unwrap();
    let status_port = status.local_addr().unwrap().port();
    let (p1, p2) = (free_udp_port(), free_udp_port());
    let d1 = team_daemon(1, &group, p1, status_port, dir.path());
    let d2 = team_daemon(2, &group, p2, status_port, dir.path());
    let (mut c1, mut c2) = (d1.client(), d2.client());
    let pose = "[0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.003]";
    for (c, cost) in [(&mut c1, "0.5"), (&mut c2, "1.0")] {
        for line in [
            format!("SETV local.var.robot.pose {pose}"),
            format!("SETV local.var.robot.cost {cost}"),
        ] {
            assert!(c.ask(&line).starts_with("OK"), "{line}");
        }
    }
    let mut gc = ScriptedGc {
        socket: UdpSocket::bind("127.0.0.1:0").unwrap(),
        to: format!("127.0.0.1:{p2}"),
        game: GameControlData::new([12, 34]),
    };
    gc.game.state = State::Playing;
    gc.send();
    let goer = |a: &str| a.contains(" int 1 ");
    c2.wait_for("local.var.team.goer", Duration::from_secs(5), goer);
    c1.wait_for("local.var.team.goer", Duration::from_secs(5), goer);

    // Robot 1 penalised; only robot 2's listener hears it for now.
    let me = &mut gc.game.team_mut(12).unwrap().players[0];
    me.penalty = 2;
    me.secs_till_unpenalised = 45;
    gc.send();
    c2.wait_for("local.var.gc.penalized", Duration::from_secs(5), |a| {
        a.contains("[1")
    });
    c2.wait_for("local.var.team.goer", Duration::from_secs(3), |a| {
        a.contains(" int 2 ")
    });
    let claim = c2.ask("GETV 1.var.machine.heuristic");
    assert!(
        claim.starts_with("VAL") && !claim.contains("1000000"),
        "robot 1 is unaware and still posts its cost; robot 2 goes anyway: {claim:?}"
    );

    // Now robot 1 hears it: it stops claiming and says so.
    gc.to = format!("127.0.0.1:{p1}");
    gc.send();
    c1.wait_for("local.var.team.going", Duration::from_secs(3), |a| {
        a.contains(" false ")
    });
    c2.wait_for("1.var.machine.heuristic", Duration::from_secs(3), |a| {
        a.contains("[1000000")
    });

    // Unpenalised (both hear it): robot 1 is back in the arbitration with its cost.
    gc.game.team_mut(12).unwrap().players[0] = Default::default();
    for to in [p1, p2] {
        gc.to = format!("127.0.0.1:{to}");
        gc.send();
    }
    c2.wait_for("1.var.machine.heuristic", Duration::from_secs(3), |a| {
        a.contains("[0.5")
    });
}
