//! The GameController's loose ends on real sockets: real `huddle daemon` processes on
//! loopback, a scripted GC sending RGme by unicast to the daemon's `--gc-listen` port, an
//! RGrt receiver on the `--gc-status-port`, and (where frames are counted) the daemon's
//! own frames counted on the wire by the test: the daemon runs `--transport unicast` with
//! the test's socket as its one `--peer`.
//!
//! - The status packet's `ballAge` is the team layer's ball age (`age_s` of
//!   `local.var.team.ball` plus the entry's age), −1 before any ball: a ball seen once
//!   ages in the packets as it ages in the layer.
//! - A GC that goes quiet leaves its last figure in force: the daemon, pushed to send, sends
//!   no more than that figure allows, however long the silence.
//! - A relay client's `CLOK` cannot move the game clock the budget paces by while the GC's
//!   figures are in force (`ERR 424`, counted).
//! - A daemon killed mid-game and started again keeps to the GC's figures across both
//!   lives (#34: "a daemon restarted mid-game resumes from the GC's figures").
//! - A whistle the robot program hears (`local.var.robot.whistle`) starts play while the
//!   GC still says Set (GameController3 shows play 15 s late): the layer goes and its
//!   frames resume at the whistle.
//! - Under the SPL budget the same whistle starts the pacing clock while the GC's delayed
//!   Set keeps its clock standing (`TeamLayer::paced_game_remaining`, #34): more frames
//!   than the standing line lets out, none beyond the running line.
//!
//! No wall-clock thresholds: the assertions are on order, on agreement with the daemon's
//! own figures, and on frame counts the GC's figures bound.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use daemon_support::{free_tcp_port, free_udp_port, Client, Daemon};
use gamecontroller::{GameControlData, GcBudget, State, StatusMessage};

/// The status period (`GameControllerConfig::new`: 750 ms): the tolerance of an age
/// compared across a packet and a read of the blackboard.
const STATUS_PERIOD_S: f32 = 0.75;

/// The margin the SPL budget keeps short of the GC's 0 for a team of five (the daemon's
/// default `--team-size`).
fn margin() -> u64 {
    u64::from(GcBudget::spl(5).margin)
}

struct ScriptedGc {
    socket: UdpSocket,
    to: String,
    game: GameControlData,
}

impl ScriptedGc {
    /// Team 12 against 34, sending to the daemon's GC port `port`.
    fn new(port: u16) -> ScriptedGc {
        ScriptedGc {
            socket: UdpSocket::bind("127.0.0.1:0").unwrap(),
            to: format!("127.0.0.1:{port}"),
            game: GameControlData::new([12, 34]),
        }
    }

    /// Sends the game as it stands, numbered one after the last.
    fn send(&mut self) {
        self.game.packet_number = self.game.packet_number.wrapping_add(1);
        self.socket.send_to(&self.game.encode(), &self.to).unwrap();
    }

    fn set_budget(&mut self, left: u16) {
        self.game.team_mut(12).unwrap().message_budget = left;
    }
}

/// The daemon's one unicast peer: every frame it sends arrives here, to be counted.
struct Wire {
    socket: UdpSocket,
    frames: u64,
}

impl Wire {
    /// Bound on 127.0.0.2 (the daemon binds the same port on 127.0.0.1).
    fn new() -> Wire {
        let socket = UdpSocket::bind("127.0.0.2:0").expect("bind 127.0.0.2");
        socket.set_nonblocking(true).unwrap();
        Wire { socket, frames: 0 }
    }

    fn port(&self) -> u16 {
        self.socket.local_addr().unwrap().port()
    }

    /// Counts what arrived since the last call; the total so far.
    fn drain(&mut self) -> u64 {
        let mut buf = [0u8; 2048];
        while let Ok((_, from)) = self.socket.recv_from(&mut buf) {
            // Only the daemon sends to this port; a stray would be a test bug.
            assert_eq!(from.ip().to_string(), "127.0.0.1", "a frame from {from}");
            self.frames += 1;
        }
        self.frames
    }
}

/// Robot 1 of team 12 with the GC listener on `gc_port` (status packets to
/// `status_port` on 127.0.0.1) and `extra` flags, sending by unicast to `wire` only.
fn daemon(
    wire: &Wire,
    gc_port: u16,
    status_port: u16,
    extra: &[&str],
) -> (Daemon, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let port = wire.port().to_string();
    let peer = format!("127.0.0.2:{port}");
    let net = [
        "--transport",
        "unicast",
        "--port",
        &port,
        "--iface",
        "127.0.0.1",
        "--peer",
        &peer,
    ];
    let listen = format!("127.0.0.1:{gc_port}");
    let status = status_port.to_string();
    let mut args = vec![
        "--team",
        "12",
        "--gamecontroller",
        "--gc-listen",
        &listen,
        "--gc-status-port",
        &status,
    ];
    args.extend_from_slice(extra);
    let d = Daemon::start_on(1, &net, free_tcp_port(), &args, dir.path());
    (d, dir)
}

/// [`daemon`] with `extra` flags on a fresh wire and GC port, its status packets to a
/// socket of the test's that nothing reads (kept open, with the config directory, for
/// as long as the test holds them).
fn gc_daemon(extra: &[&str]) -> (Wire, u16, Daemon, UdpSocket, tempfile::TempDir) {
    let wire = Wire::new();
    let status = UdpSocket::bind("127.0.0.1:0").unwrap();
    let gc_port = free_udp_port();
    let (d, dir) = daemon(&wire, gc_port, status.local_addr().unwrap().port(), extra);
    (wire, gc_port, d, status, dir)
}

/// The floats of a `VAL key floats [...]` answer (empty for anything else).
fn floats(answer: &str) -> Vec<f32> {
    let Some(b) = comms::relay::Binding::parse(answer) else {
        return Vec::new();
    };
    b.value
        .trim_matches(['[', ']'])
        .split(',')
        .filter_map(|f| f.trim().parse().ok())
        .collect()
}

/// The team layer's own figure for its ball's age now: `age_s` (the 9th float of
/// `local.var.team.ball`) plus the entry's age; `None` while it has no ball.
fn layer_ball_age(c: &mut Client) -> Option<f32> {
    let answer = c.ask("GETV local.var.team.ball");
    let v = floats(&answer);
    let age_ms = comms::relay::Binding::parse(&answer)?.age_ms;
    (v.len() >= 9).then(|| v[8] + age_ms as f32 / 1000.0)
}

#[test]
fn the_status_packets_ball_age_is_the_team_layers_minus_one_before_any_ball() {
    // Scenario: robot 1 knows its pose; the GC (Playing) is heard twice a second, so the
    // daemon sends its status. Before any ball every packet says −1. Then the program
    // writes ONE sighting, 1.5 m ahead, and nothing more: the packets' ballAge rises from
    // packet to packet, and each agrees with the layer's own age of its ball (read from
    // the blackboard right after the packet came) within one status period.
    let wire = Wire::new();
    let status = UdpSocket::bind("127.0.0.1:0").unwrap();
    status
        .set_read_timeout(Some(Duration::from_millis(50)))
        .unwrap();
    let gc_port = free_udp_port();
    let (d, _dir) = daemon(&wire, gc_port, status.local_addr().unwrap().port(), &[]);
    let mut c = d.client();
    let pose = "SETV local.var.robot.pose [0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.003]";
    assert!(c.ask(pose).starts_with("OK"));
    let mut gc = ScriptedGc::new(gc_port);
    gc.game.state = State::Playing;
    gc.game.secs_remaining = 500;

    // Status packets for a while: (ballAge, the layer's figure just after), in order.
    let listen = |gc: &mut ScriptedGc, c: &mut Client, packets: usize| {
        let mut got = Vec::new();
        let mut next_gc = Instant::now();
        let give_up = Instant::now() + Duration::from_secs(30);
        let mut buf = [0u8; 64];
        while got.len() < packets {
            assert!(
                Instant::now() < give_up,
                "status packets stopped coming: {got:?}"
            );
            if Instant::now() >= next_gc {
                gc.send();
                next_gc += Duration::from_millis(500);
            }
            let Ok((n, _)) = status.recv_from(&mut buf) else {
                continue;
            };
            let msg = StatusMessage::decode(&buf[..n]).expect("a valid RGrt");
            got.push((msg.ball_age, layer_ball_age(c)));
        }
        got
    };

    let before = listen(&mut gc, &mut c, 3);
    for (age, layer) in &before {
        assert_eq!(
            (*age, *layer),
            (-1.0, None),
            "no ball seen yet: ballAge -1 and no team ball ({before:?})"
        );
    }

    assert!(c
        .ask("SETV local.var.robot.ball [1.5, 0.0, 0.01, 0.0, 0.01]")
        .starts_with("OK"));
    // Packets computed before the layer's tick took the sighting may still say -1.
    let mut after = listen(&mut gc, &mut c, 8);
    let first_ball = after
        .iter()
        .position(|(age, _)| *age >= 0.0)
        .expect("a packet with the ball");
    after.drain(..first_ball);
    assert!(
        after.len() >= 5,
        "at least five packets with the ball: {after:?}"
    );
    for (i, (age, layer)) in after.iter().enumerate() {
        let layer = layer.unwrap_or_else(|| panic!("the layer lost its ball: {after:?}"));
        assert!(
            (age - layer).abs() <= STATUS_PERIOD_S,
            "packet {i}: ballAge {age} s, the layer's age of its ball {layer} s: \
             they must agree within a status period ({after:?})"
        );
        if i > 0 {
            assert!(
                *age > after[i - 1].0,
                "packet {i}: the ball seen once ages from packet to packet ({after:?})"
            );
        }
    }
    eprintln!("(ballAge s, the layer's age s) per status packet: {after:?}");
    let (first, last) = (after[0], after[after.len() - 1]);
    let (grew, layer_grew) = (last.0 - first.0, last.1.unwrap() - first.1.unwrap());
    assert!(
        (grew - layer_grew).abs() <= STATUS_PERIOD_S,
        "ballAge grew {grew} s over the packets, the layer's age {layer_grew} s ({after:?})"
    );
}

#[test]
fn a_gc_gone_quiet_leaves_its_last_figure_in_force_on_the_wire() {
    // Scenario: robot 1 under the SPL budget, its program writing a value every 20 ms
    // (and the daemon's heartbeats: it always has something to send). The GC says
    // Playing, 2 s left in the second half (the pacing line is open: it is the figure
    // that binds), and `margin + 3` messages left: the team may send 3 more. It keeps
    // saying so, less what it counted on the wire, for 1.5 s, then goes quiet for longer
    // than the listener's `lost_after` (5 s) and then some. Counted on the wire: from the
    // GC's first packet on, the daemon sends at most the 3, and after its last packet at
    // most what that one allowed. (Before the fix a silent GC's figure was forgotten
    // after 5 s and the daemon paced by its own share again: frames at the GC's 0.)
    let (mut wire, gc_port, d, _status, _dir) = gc_daemon(&["--budget", "spl"]);
    let mut c = d.client();
    let mut gc = ScriptedGc::new(gc_port);
    gc.game.state = State::Playing;
    gc.game.first_half = false;
    gc.game.secs_remaining = 2;
    let start_left = margin() + 3;
    gc.set_budget(start_left as u16);

    let mut k = 0;
    let mut write = |c: &mut Client| {
        let answer = c.ask(&format!("SETV *.var.x {k}"));
        assert!(answer.starts_with("OK"), "{answer:?}");
        k += 1;
        std::thread::sleep(Duration::from_millis(20));
    };

    // Before the GC: whatever the daemon's own pacing sent.
    let before = wire.drain();
    gc.send();
    c.wait_for("local.var.gc.budget", Duration::from_secs(5), |a| {
        a.contains(&format!(" {start_left} "))
    });
    // Heard: its figure every 500 ms, less the frames it counted.
    let heard_until = Instant::now() + Duration::from_millis(1500);
    let mut next_gc = Instant::now() + Duration::from_millis(500);
    let mut last_left = start_left;
    while Instant::now() < heard_until {
        write(&mut c);
        if Instant::now() >= next_gc {
            last_left = start_left.saturating_sub(wire.drain() - before);
            gc.set_budget(last_left as u16);
            gc.send();
            next_gc += Duration::from_millis(500);
        }
    }
    let at_last_packet = wire.drain();
    // Quiet: 5 s until the listener calls the GC lost, 4 s more.
    let quiet_until = Instant::now() + Duration::from_secs(9);
    while Instant::now() < quiet_until {
        write(&mut c);
    }
    std::thread::sleep(Duration::from_millis(300));
    let end = wire.drain();
    let (since_first, in_silence) = (end - before, end - at_last_packet);
    eprintln!(
        "frames on the wire: {before} before the GC, {since_first} since its first packet \
         ({start_left} left), {in_silence} in its silence (last figure {last_left})"
    );
    assert!(
        since_first >= 1,
        "the daemon was pushed and the figure let 3 go: it sent some ({since_first})"
    );
    assert!(
        since_first + margin() <= start_left,
        "the GC said {start_left} left (margin {}): {since_first} frames on the wire since",
        margin()
    );
    assert!(
        in_silence + margin() <= last_left,
        "the GC's last figure was {last_left} (margin {}): {in_silence} frames on the wire \
         in its 9 s of silence",
        margin()
    );
}

#[test]
fn a_clients_clok_is_refused_while_the_gcs_figures_set_the_clock() {
    // Scenario: robot 1 under the SPL budget. Before any GC, `CLOK` sets the game clock
    // (OK). The GC says Playing, 300 s left in the second half, 30 messages left (16 to
    // spend after the margin): the pacing line keeps ~296 for the rest of the half, so
    // nothing ordinary goes. A client then says `CLOK 1` (one second left): that would
    // open the line until the GC's next packet, and the 16 would go at once. It is
    // refused (`ERR 424`), counted, and in the GC's silence that follows (shorter than
    // its `lost_after`) nothing goes on the wire while the program writes.
    let (mut wire, gc_port, d, _status, _dir) =
        gc_daemon(&["--budget", "spl", "--refresh", "50ms"]);
    let mut c = d.client();
    let answer = c.ask("CLOK 1200");
    assert_eq!(answer, "OK", "no GC heard: the client's clock is taken");

    let mut gc = ScriptedGc::new(gc_port);
    gc.game.state = State::Playing;
    gc.game.first_half = false;
    gc.game.secs_remaining = 300;
    gc.set_budget(30);
    gc.send();
    c.wait_for("local.var.gc.budget", Duration::from_secs(5), |a| {
        a.contains(" 30 ")
    });
    let before = wire.drain();
    let answer = c.ask("CLOK 1");
    assert!(
        answer.starts_with("ERR 424 "),
        "the GC's figures set the clock: {answer:?}"
    );
    for k in 0..75 {
        let answer = c.ask(&format!("SETV *.var.x {k}"));
        assert!(answer.starts_with("OK"), "{answer:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(300));
    let sent = wire.drain() - before;
    assert_eq!(
        sent, 0,
        "the GC's clock (300 s left) holds the line: {sent} frames went after the CLOK"
    );
    c.wait_for(
        "local.var.huddle.stats.relay_clock_refused",
        Duration::from_secs(3),
        |a| a.contains(" 1 "),
    );
}

#[test]
fn a_daemon_restarted_mid_game_keeps_to_the_gcs_figures_on_the_wire() {
    // Scenario: robot 1 under the SPL budget, its program writing every 20 ms; the GC says
    // Playing, the last 4 s of the second half running down (the pacing line opens for
    // the last frames in the last 2 s: then the figure binds) and `margin + 3` left, and
    // counts what it sees on the wire. The daemon spends what the
    // figure allows and is killed (SIGKILL, a crash); a fresh daemon of the same robot
    // starts with no memory of it while the GC goes on saying what is left. Counted on
    // the wire over both lives: the team sends the 3, and the new life nothing once it
    // has the GC's figure (before it, only its start frame: a fresh replica's own
    // accounting sends one at once, out of the margin).
    let mut wire = Wire::new();
    let status = UdpSocket::bind("127.0.0.1:0").unwrap();
    let status_port = status.local_addr().unwrap().port();
    let gc_port = free_udp_port();
    let (mut first, dir) = daemon(&wire, gc_port, status_port, &["--budget", "spl"]);
    let mut gc = ScriptedGc::new(gc_port);
    gc.game.state = State::Playing;
    gc.game.first_half = false;
    gc.game.secs_remaining = 4;
    let start_left = margin() + 3;
    gc.set_budget(start_left as u16);

    let before = wire.drain();
    let kick_off = Instant::now();
    gc.send();
    // One life: pushed to send while the GC counts, for `d`.
    let live = |c: &mut Client, gc: &mut ScriptedGc, wire: &mut Wire, d: Duration| {
        let until = Instant::now() + d;
        let mut next_gc = Instant::now() + Duration::from_millis(500);
        let mut k = 0;
        while Instant::now() < until {
            let answer = c.ask(&format!("SETV *.var.x {k}"));
            assert!(answer.starts_with("OK"), "{answer:?}");
            k += 1;
            std::thread::sleep(Duration::from_millis(20));
            if Instant::now() >= next_gc {
                let left = start_left.saturating_sub(wire.drain() - before);
                gc.set_budget(left as u16);
                let played = kick_off.elapsed().as_secs();
                gc.game.secs_remaining = 4i16.saturating_sub(played as i16).max(0);
                gc.send();
                next_gc += Duration::from_millis(500);
            }
        }
    };
    let mut c = first.client();
    c.wait_for("local.var.gc.budget", Duration::from_secs(5), |a| {
        a.contains(&format!(" {start_left} "))
    });
    live(&mut c, &mut gc, &mut wire, Duration::from_millis(4500));
    first.kill();
    let first_life = wire.drain() - before;

    // The same robot again, while the GC keeps sending.
    let (second, _dir2) = {
        let d = dir; // the first life's config dir is dropped with it
        drop(d);
        daemon(&wire, gc_port, status_port, &["--budget", "spl"])
    };
    let mut c = second.client();
    gc.send();
    let left = start_left.saturating_sub(wire.drain() - before);
    c.wait_for("local.var.gc.budget", Duration::from_secs(5), |a| {
        a.contains(&format!(" {left} ")) || a.contains(&format!(" {} ", left.saturating_sub(1)))
    });
    let at_figure = wire.drain();
    live(&mut c, &mut gc, &mut wire, Duration::from_secs(3));
    std::thread::sleep(Duration::from_millis(300));
    let end = wire.drain();
    let (second_before_figure, second_after) = (at_figure - before - first_life, end - at_figure);
    eprintln!(
        "frames on the wire: first life {first_life} (the GC said {start_left} left), second \
         life {second_before_figure} before its first figure and {second_after} after"
    );
    assert!(
        first_life + margin() <= start_left,
        "the first life sent {first_life} with {start_left} left (margin {})",
        margin()
    );
    assert!(
        second_before_figure <= 1,
        "before its first figure the new life sends its start frame at most: \
         {second_before_figure}"
    );
    assert_eq!(
        second_after, 0,
        "the new life has the GC's figure (nothing left after the margin): it sent \
         {second_after} frames"
    );
}

#[test]
fn a_whistle_the_program_hears_starts_play_while_the_gc_still_says_set() {
    // Scenario (#34, eleventh session): GameController3 keeps saying Set for 15 s after
    // the whistle that starts play (`delayAfterPlaying`). Robot 1's program writes its
    // pose every 40 ms and a cost of 2 (not the kick-off taker); the scripted GC says Set
    // throughout, every 500 ms. For 3 s the program hears no whistle: the layer is out of
    // play, in the kick-off hold, and does not go. Then it writes the whistle: the layer
    // is in play at once and, after the hold's 3 s, goes, while the GC still says Set;
    // its frames on the wire resume then, not when the GC says Playing (it never does
    // here).
    let (mut wire, gc_port, d, _status, _dir) = gc_daemon(&["--refresh", "50ms"]);
    let mut c = d.client();
    let mut gc = ScriptedGc::new(gc_port);
    gc.game.state = State::Set;
    gc.send();
    c.wait_for("local.var.gc.state", Duration::from_secs(5), |a| {
        a.contains("set")
    });
    let pose = "[0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.003]";
    let mut next_gc = Instant::now();
    // Feeds the program's pose and cost for `d`, the GC's Set every 500 ms; whether the
    // layer said it goes at any read.
    let mut feed = |c: &mut Client, gc: &mut ScriptedGc, d: Duration| -> bool {
        let until = Instant::now() + d;
        let mut went = false;
        while Instant::now() < until {
            for line in [
                format!("SETV local.var.robot.pose {pose}"),
                "SETV local.var.robot.cost 2.0".to_string(),
            ] {
                assert!(c.ask(&line).starts_with("OK"), "{line}");
            }
            if Instant::now() >= next_gc {
                gc.send();
                next_gc += Duration::from_millis(500);
            }
            went |= c.ask("GETV local.var.team.going").contains(" true ");
            std::thread::sleep(Duration::from_millis(40));
        }
        went
    };
    let before = wire.drain();
    assert!(
        !feed(&mut c, &mut gc, Duration::from_secs(3)),
        "in Set with no whistle the layer does not go"
    );
    let in_set = wire.drain() - before;
    assert!(c.ask("SETV local.var.robot.whistle true").starts_with("OK"));
    // The hold's 3 s and then some: it goes.
    assert!(
        feed(&mut c, &mut gc, Duration::from_secs(6)),
        "after the whistle and the hold the layer goes, the GC still saying Set"
    );
    let state = c.ask("GETV local.var.gc.state");
    assert!(state.contains("set"), "the GC still says Set: {state:?}");
    let at_go = wire.drain();
    feed(&mut c, &mut gc, Duration::from_secs(3));
    let in_play = wire.drain() - at_go;
    eprintln!(
        "frames on the wire: {in_set} in 3 s of Set, {in_play} in 3 s of play after the whistle"
    );
    assert!(
        in_play > in_set,
        "its frames resume at the whistle: {in_play} in play against {in_set} in Set"
    );
    // A malformed whistle is refused like any input.
    assert!(
        c.ask("SETV local.var.robot.whistle 3").starts_with("ERR"),
        "a whistle must be a bool"
    );
}

/// Frames on the wire in `window` of the GC's delayed Set, its clock standing at the
/// first half's start, robot 1 (a team of one: the team's whole line is its own) under
/// `--budget spl` with its program writing its pose,
/// its cost and a shared value every 40 ms; the program hears the whistle at the
/// window's start if `whistle`. The GC counts what it sees on the wire.
fn frames_in_delayed_set(whistle: bool, window: Duration) -> u64 {
    let (mut wire, gc_port, d, _status, _dir) =
        gc_daemon(&["--budget", "spl", "--team-size", "1", "--refresh", "50ms"]);
    let mut c = d.client();
    let mut gc = ScriptedGc::new(gc_port);
    gc.game.state = State::Set;
    gc.game.first_half = true;
    gc.game.secs_remaining = 600;
    let start_left: u16 = 1200;
    gc.set_budget(start_left);
    gc.send();
    c.wait_for("local.var.gc.secs_remaining", Duration::from_secs(5), |a| {
        a.contains(" 600 ")
    });
    let pose = "[0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.003]";
    let before = wire.drain();
    if whistle {
        assert!(c.ask("SETV local.var.robot.whistle true").starts_with("OK"));
    }
    let until = Instant::now() + window;
    let mut next_gc = Instant::now();
    let mut k = 0;
    while Instant::now() < until {
        for line in [
            format!("SETV local.var.robot.pose {pose}"),
            "SETV local.var.robot.cost 2.0".to_string(),
            format!("SETV *.var.x {k}"),
        ] {
            assert!(c.ask(&line).starts_with("OK"), "{line}");
        }
        k += 1;
        if Instant::now() >= next_gc {
            // GameController3's delayed Set: the state and the clock stand.
            let sent = wire.drain() - before;
            gc.set_budget(start_left.saturating_sub(sent as u16));
            gc.send();
            next_gc += Duration::from_millis(500);
        }
        std::thread::sleep(Duration::from_millis(40));
    }
    let state = c.ask("GETV local.var.gc.state");
    assert!(state.contains("set"), "the GC still says Set: {state:?}");
    // The layer tells its GC listener the play whistle it acts on (or none).
    let published = floats(&c.ask("GETV local.var.team.play_whistle"));
    assert_eq!(
        published.len(),
        usize::from(whistle),
        "local.var.team.play_whistle holds the whistle the layer acts on: {published:?}"
    );
    std::thread::sleep(Duration::from_millis(200));
    wire.drain() - before
}

#[test]
fn a_play_whistle_runs_the_pacing_clock_while_the_gcs_delayed_set_stands() {
    // Scenario (#34, twelfth session): GameController3 says Set with its clock standing
    // for 15 s after the whistle that starts play. Without the program's whistle the
    // pacing line stands with the GC's clock and only the priority room's frames go; with
    // it the daemon's clock runs from the whistle (the rule the simulator applies,
    // `TeamLayer::paced_game_remaining`), so its ordinary frames go at the line's rate
    // (1,194 / 1,200 s for a team of one): more than the standing line's, and no more than the
    // running line allows beyond them.
    let window = Duration::from_secs(15);
    let standing = frames_in_delayed_set(false, window);
    let running = frames_in_delayed_set(true, window);
    let spl = GcBudget::spl(1);
    let usable = f64::from(spl.messages_per_game - spl.margin);
    let line = (window.as_secs_f64() + 1.0) * usable / 1200.0;
    eprintln!(
        "frames on the wire in {window:?} of delayed Set: {standing} without the whistle, \
         {running} with it (the running line allows {line:.1} beyond the standing one)"
    );
    assert!(
        running as f64 >= standing as f64 + line / 2.0,
        "the whistle runs the pacing clock: {running} frames with it against {standing} \
         without (the standing line)"
    );
    assert!(
        running as f64 <= standing as f64 + line + 2.0,
        "nothing beyond the running line: {running} frames, {standing} standing + {line:.1}"
    );
}
