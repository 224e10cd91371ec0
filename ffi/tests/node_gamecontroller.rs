//! The GameController on an in-process node, over loopback: the daemon's listener logic
//! (`driver::GcListener`) on the node's own thread.
//!
//! Scenario: robot 1 of team 12 runs a node under the SPL budget with the listener on
//! `127.0.0.1` (a scripted GC sends it packets; nothing leaves loopback). The GC's game
//! reaches `local.var.gc.*`, the program's pose goes back in a status packet, and when the
//! GC says the team's budget is 0 not one frame more goes out.
#![allow(clippy::disallowed_methods)] // real sockets in real time: the test waits for packets

use std::ffi::{c_char, CStr, CString};
use std::net::UdpSocket;
use std::time::{Duration, Instant};

use gamecontroller::{GameControlData, State, StatusMessage};
use huddle::*;

fn zeroed<T>() -> T {
    // SAFETY: used for the C structs only, where all-zero is valid (NULL strings).
    unsafe { std::mem::zeroed() }
}

fn text(chars: &[c_char]) -> String {
    // SAFETY: huddle NUL-terminates every string it writes.
    unsafe { CStr::from_ptr(chars.as_ptr()) }
        .to_string_lossy()
        .into_owned()
}

fn c(s: &str) -> CString {
    CString::new(s).unwrap()
}

/// The node's `local.var.gc.*` string or int as text, if there is one.
fn literal(node: *mut huddle_node, key: &str) -> Option<String> {
    let key = c(key);
    let mut buf = [0 as c_char; 64];
    let mut len = 0;
    let mut err: huddle_error = zeroed();
    // SAFETY: a live node, a NUL-terminated key, a buffer of the capacity given.
    let rc = unsafe {
        huddle_node_get_literal(node, key.as_ptr(), buf.as_mut_ptr(), 64, &mut len, &mut err)
    };
    assert!(rc >= 0, "{}", text(&err.message));
    (rc == 1).then(|| text(&buf))
}

fn frames_out(node: *mut huddle_node) -> u64 {
    let mut stats: huddle_stats = zeroed();
    // SAFETY: a live node, a writable record.
    assert_eq!(
        unsafe { huddle_node_stats(node, &mut stats, std::ptr::null_mut()) },
        0
    );
    stats.frames_out
}

/// Polls `f` every 10 ms for up to 5 s.
fn eventually(what: &str, mut f: impl FnMut() -> bool) {
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(5) {
        if f() {
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    panic!("{what}: not within 5 s");
}

#[test]
fn a_scripted_gamecontroller_drives_a_nodes_keys_status_and_budget() {
    let group = driver::scratch_group().unwrap();
    let gc = UdpSocket::bind("127.0.0.1:0").unwrap();
    let status = UdpSocket::bind("127.0.0.1:0").unwrap();
    status
        .set_read_timeout(Some(Duration::from_secs(3)))
        .unwrap();
    let listen = {
        let probe = UdpSocket::bind("127.0.0.1:0").unwrap();
        probe.local_addr().unwrap()
    };
    let (ip, listen_text, spl) = (c(&group.ip().to_string()), c(&listen.to_string()), c("spl"));
    let mut cfg: huddle_node_config = zeroed();
    cfg.robot_id = 1;
    cfg.team_id = 12;
    cfg.group_address = ip.as_ptr();
    cfg.group_port = group.port();
    cfg.budget = spl.as_ptr();
    cfg.gamecontroller = HUDDLE_GC_ON;
    cfg.gc_listen = listen_text.as_ptr();
    cfg.gc_status_port = status.local_addr().unwrap().port();
    let mut err: huddle_error = zeroed();
    // SAFETY: a valid config whose strings outlive the call; a writable error.
    let node = unsafe { huddle_node_start(&cfg, &mut err) };
    assert!(!node.is_null(), "{}", text(&err.message));

    // Playing, 500 s left, 1,150 of the team's messages left.
    let mut game = GameControlData::new([12, 34]);
    game.state = State::Playing;
    game.secs_remaining = 500;
    game.team_mut(12).unwrap().message_budget = 1150;
    let send = |game: &mut GameControlData| {
        game.packet_number = game.packet_number.wrapping_add(1);
        gc.send_to(&game.encode(), listen).unwrap();
    };
    send(&mut game);
    eventually("the GC's state on the node", || {
        literal(node, "local.var.gc.state").as_deref() == Some("\"playing\"")
    });
    assert_eq!(
        literal(node, "local.var.gc.budget").as_deref(),
        Some("1150")
    );
    // The listener's keys are its own: the program's set call is refused (as the
    // daemon's relay answers `ERR 423`) and the GC's word stands.
    let (state, set) = (c("local.var.gc.state"), c("\"set\""));
    // SAFETY: a live node, NUL-terminated strings, a writable error.
    let rc = unsafe { huddle_node_set(node, state.as_ptr(), set.as_ptr(), &mut err) };
    assert_eq!((rc, err.code), (-1, HUDDLE_E_KEY), "{}", text(&err.message));
    assert!(
        text(&err.message).contains("written by the GameController listener"),
        "{}",
        text(&err.message)
    );
    assert_eq!(
        literal(node, "local.var.gc.state").as_deref(),
        Some("\"playing\"")
    );

    // The GC's clock is the budget's: the program's is refused, as the relay's `CLOK`.
    // SAFETY: a live node, a writable error.
    let rc = unsafe { huddle_node_set_game_clock(node, 1000, &mut err) };
    assert_eq!(
        (rc, err.code),
        (-1, HUDDLE_E_CLOCK),
        "{}",
        text(&err.message)
    );

    // The program's pose reaches the GC in a status packet.
    let cov = [0.01, 0.0, 0.0, 0.01, 0.0, 0.001];
    // SAFETY: a live node, 6 readable doubles, a writable error.
    let rc =
        unsafe { huddle_node_set_robot_pose(node, -1.5, 0.5, 0.25, cov.as_ptr(), 0.0, &mut err) };
    assert_eq!(rc, 0, "{}", text(&err.message));
    let mut buf = [0u8; 64];
    let msg = loop {
        let (n, _) = status
            .recv_from(&mut buf)
            .expect("a status packet within 3 s");
        let msg = StatusMessage::decode(&buf[..n]).expect("a status packet");
        if msg.pose[0] != 0.0 {
            break msg;
        }
    };
    assert_eq!((msg.player_num, msg.team_num), (1, 12), "{msg:?}");
    assert!(
        (msg.pose[0] + 1500.0).abs() < 1e-3 && (msg.pose[1] - 500.0).abs() < 1e-3,
        "the pose in mm: {msg:?}"
    );

    // The GC says the team has nothing left: not one frame more.
    game.team_mut(12).unwrap().message_budget = 0;
    send(&mut game);
    eventually("the GC's zero on the node", || {
        literal(node, "local.var.gc.budget").as_deref() == Some("0")
    });
    let at_zero = frames_out(node);
    let key = c("*.var.x");
    for k in 0..50 {
        // SAFETY: a live node, a NUL-terminated key, a writable error.
        let rc = unsafe { huddle_node_set_float(node, key.as_ptr(), f64::from(k), &mut err) };
        assert_eq!(rc, 0, "{}", text(&err.message));
        std::thread::sleep(Duration::from_millis(20));
        if k % 5 == 0 {
            send(&mut game);
        }
    }
    assert_eq!(
        frames_out(node),
        at_zero,
        "a frame sent at the GC's 0 makes the team illegal"
    );
    huddle_node_stop(node);
}
