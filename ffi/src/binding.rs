//! `huddle_binding`: one blackboard binding copied out as text for the caller.

use std::ffi::c_char;
use std::time::Duration;

use comms::{Entry, Key};

use crate::text::write_text;

/// One binding as read by `huddle_node_get` or `huddle_replica_get`.
#[repr(C)]
#[allow(non_camel_case_types)]
pub struct huddle_binding {
    /// The key as stored: `local.var.x` or `n.var.x` (for `*.var.x`, the copy read).
    pub key: [c_char; 256],
    /// The value's type: `int`, `float`, `bool`, `string`, `floats` or `bytes`.
    pub r#type: [c_char; 16],
    /// The value as a literal (`1.5`, `"text"` with escapes, `[1.0, 2.0]`, `0x0a0b`),
    /// the syntax `huddle_node_set` reads: it parses back to the same value. Cut (at a
    /// UTF-8 boundary) when longer than 1023 bytes: see `value_len`.
    pub value: [c_char; 1024],
    /// The robot that wrote it (this robot for `local` keys).
    pub owner: u8,
    /// Time since it was set, on this robot's clock (for a teammate's value: the age
    /// the teammate reported when it arrived, plus the time since).
    pub age_ms: u64,
    /// Length in bytes of the whole literal; more than 1023 means `value` holds only
    /// its beginning.
    pub value_len: usize,
}

/// Fills `out` with `key`'s `entry`, `age` old.
pub(crate) fn fill_binding(out: &mut huddle_binding, key: &Key, entry: &Entry, age: Duration) {
    write_text(&mut out.key, &key.to_string());
    write_text(&mut out.r#type, entry.value.value_type().name());
    let literal = entry.value.to_string();
    write_text(&mut out.value, &literal);
    out.value_len = literal.len();
    out.owner = entry.owner;
    out.age_ms = u64::try_from(age.as_millis()).unwrap_or(u64::MAX);
}
