//! What the driver's socket tests share.
#![allow(dead_code)] // each test file uses a different part

use std::time::Duration;

use comms::wire::{encode_frame, Frame, Item};
use comms::Value;
use driver::Notice;

/// A frame from `sender` (team 0, no key) setting `sender.var.x`.
pub fn frame_from(sender: u8) -> Vec<u8> {
    let frame = Frame {
        team: 0,
        sender,
        incarnation: 1,
        seq: 1,
        clock: Default::default(),
        items: vec![Item::Update {
            path: "x".into(),
            value: Value::Int(i64::from(sender)),
            version: 1,
            age_us: 0,
        }],
    };
    encode_frame(&frame, None)
}

/// Runs `test` on a current-thread runtime inside a `LocalSet` (the driver's tasks are
/// local).
pub fn run_local(test: impl std::future::Future<Output = ()>) {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    tokio::task::LocalSet::new().block_on(&rt, test);
}

/// Waits (at most 10 s) until `key` appears on the subscription.
pub async fn wait_for(sub: &mut driver::Subscription, key: &str) {
    let wait = tokio::time::timeout(Duration::from_secs(10), async {
        loop {
            match sub.next().await {
                Some(Notice::Changed { key: k, .. }) if k.to_string() == key => return,
                Some(_) => {}
                None => panic!("the driver stopped"),
            }
        }
    });
    wait.await.unwrap_or_else(|_| panic!("{key} never arrived"));
}
