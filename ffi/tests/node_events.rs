//! The node's events through the C API on a loopback group of its own: peers joining,
//! restarting and departing as the replica reports them, talk delivered, and another
//! robot sending with this node's id.
#![allow(clippy::disallowed_methods)] // real sockets in real time: a sleep orders two starts

use std::ffi::{c_char, CStr, CString};
use std::time::Duration;

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

/// A node for `robot` on `group`, with a 20 ms refresh (departed after 60 ms).
struct Node(*mut huddle_node);

impl Node {
    fn start(robot: u8, group: std::net::SocketAddrV4) -> Node {
        let ip = CString::new(group.ip().to_string()).unwrap();
        let mut cfg: huddle_node_config = zeroed();
        cfg.robot_id = robot;
        cfg.group_address = ip.as_ptr();
        cfg.group_port = group.port();
        cfg.refresh_ms = 20;
        let mut err: huddle_error = zeroed();
        // SAFETY: a valid config whose strings outlive the call; a writable error.
        let node = unsafe { huddle_node_start(&cfg, &mut err) };
        assert!(!node.is_null(), "start: {}", text(&err.message));
        Node(node)
    }

    /// The first event `want` accepts, skipping others; panics after 5 s without one.
    fn wait_for(&self, what: &str, want: impl Fn(&huddle_event) -> bool) -> huddle_event {
        let mut event: huddle_event = zeroed();
        let mut err: huddle_error = zeroed();
        for _ in 0..50 {
            // SAFETY: a live node, a writable event and error.
            let rc = unsafe { huddle_node_next_event(self.0, 100, &mut event, &mut err) };
            assert!(rc >= 0, "next_event: {}", text(&err.message));
            if rc == 1 && want(&event) {
                return event;
            }
        }
        panic!("no {what} within 5 s");
    }

    fn post(&self, key: &str, literal: &str) {
        let (key, literal) = (CString::new(key).unwrap(), CString::new(literal).unwrap());
        let mut err: huddle_error = zeroed();
        // SAFETY: a live node, NUL-terminated strings, a writable error.
        let rc = unsafe {
            huddle_node_post(
                self.0,
                key.as_ptr(),
                literal.as_ptr(),
                std::ptr::null_mut(),
                &mut err,
            )
        };
        assert_eq!(rc, 0, "post: {}", text(&err.message));
    }
}

impl Drop for Node {
    fn drop(&mut self) {
        huddle_node_stop(self.0);
    }
}

#[test]
fn peers_join_restart_and_depart_and_talk_is_delivered() {
    let group = driver::scratch_group().unwrap();
    let watcher = Node::start(2, group);
    let first = Node::start(1, group);
    let joined = watcher.wait_for("join of robot 1", |e| {
        e.kind == HUDDLE_EVENT_PEER_JOINED && e.robot == 1
    });
    assert_ne!(joined.incarnation, 0);

    first.post("*.talk.plan", "\"go\"");
    let talk = watcher.wait_for("talk from robot 1", |e| {
        e.kind == HUDDLE_EVENT_TALK_DELIVERED && e.robot == 1
    });
    assert_eq!(text(&talk.name), "plan");
    assert_eq!(text(&talk.value), "\"go\"");
    assert_eq!(talk.seq, 1);

    // Robot 1 starts again before it could be thought departed: a restart.
    drop(first);
    std::thread::sleep(Duration::from_millis(2)); // the next incarnation is a later ms
    let second = Node::start(1, group);
    let restarted = watcher.wait_for("restart of robot 1", |e| {
        e.kind == HUDDLE_EVENT_PEER_RESTARTED && e.robot == 1
    });
    assert!(
        restarted.incarnation > joined.incarnation,
        "{:x} after {:x}",
        restarted.incarnation,
        joined.incarnation
    );

    drop(second);
    watcher.wait_for("departure of robot 1", |e| {
        e.kind == HUDDLE_EVENT_PEER_DEPARTED && e.robot == 1
    });
}

#[test]
fn another_robot_with_this_id_is_reported() {
    let group = driver::scratch_group().unwrap();
    let one = Node::start(7, group);
    let _twin = Node::start(7, group);
    let conflict = one.wait_for("an id conflict", |e| e.kind == HUDDLE_EVENT_ID_CONFLICT);
    assert_eq!(conflict.robot, 7);
    assert_ne!(conflict.incarnation, 0, "the twin's incarnation");
}
