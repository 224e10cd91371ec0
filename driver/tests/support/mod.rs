//! What the driver's socket tests share.

use comms::wire::{encode_frame, Frame, Item};
use comms::Value;

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
