//! Frames dropped from a full send backlog are shown where operators look: the driver's
//! and the session's `local.var.huddle.stats.send_backlog_drops`, not only `IoStats`.
//!
//! On loopback the kernel never refuses a datagram (the sender's buffer is released as
//! the datagram is handed over), so the tests fill the backlog themselves, as a full
//! send buffer on a congested interface would have: the next frame meets the limit.

use std::net::SocketAddr;
use std::time::Duration;

use comms::{ReplicaConfig, Value};

use super::SEND_BACKLOG_FRAMES;
use crate::run::{Driver, DriverConfig};

fn config(id: u8) -> DriverConfig {
    let mut cfg = DriverConfig::new(ReplicaConfig::new(id, 0));
    cfg.socket.group = crate::scratch_group().expect("a scratch group");
    cfg
}

#[test]
fn a_frame_dropped_from_the_drivers_full_backlog_moves_its_key() {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    tokio::task::LocalSet::new().block_on(&rt, async {
        let cfg = config(1);
        let group = SocketAddr::from(cfg.socket.group);
        let driver = Driver::bind(cfg).expect("robot 1 binds");
        let h = driver.handle();
        // The driver's task is not running: the test has the turns.
        {
            let mut inner = h.inner().borrow_mut();
            for _ in inner.backlog.len()..SEND_BACKLOG_FRAMES {
                inner.backlog.push_back((vec![0u8; 8], group));
            }
        }
        h.set("*.var.x", 1).expect("robot 1 sets its own key");
        let drops = h.stats().io.send_backlog_drops;
        assert!(
            drops >= 1,
            "the frame met a full backlog: {:?}",
            h.stats().io
        );
        // The driver's timer mirrors the counters.
        h.inner().borrow_mut().handle_timeout();
        let key = "local.var.huddle.stats.send_backlog_drops";
        let shown = h.get(key).expect("a valid key").map(|e| e.value);
        assert_eq!(
            shown,
            Some(Value::Int(drops as i64)),
            "{key} shows the drops IoStats counted"
        );
        h.inner().borrow_mut().backlog.clear();
    });
}

#[test]
fn a_frame_dropped_from_the_sessions_full_backlog_moves_its_key() {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    rt.block_on(async {
        let session = crate::Session::open(config(2))
            .await
            .expect("robot 2 opens");
        let drops = session.fill_backlog_and_set_for_test("*.var.x", 1);
        assert!(drops >= 1, "the frame met a full backlog");
        // The receive task sends the backlog (to the test's own group on loopback) and,
        // at the replica's next timer (a refresh period, 100 ms), mirrors the counters.
        let key = "local.var.huddle.stats.send_backlog_drops";
        let mut shown = None;
        for _ in 0..500 {
            shown = session.get(key).expect("a valid key").map(|e| e.value);
            if shown == Some(Value::Int(drops as i64)) {
                break;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        assert_eq!(
            shown,
            Some(Value::Int(drops as i64)),
            "{key} shows the drops the session counted"
        );
        assert_eq!(session.stats().io.send_backlog_drops, drops);
    });
}
