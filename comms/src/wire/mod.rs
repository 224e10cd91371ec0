//! The wire format: the only place that knows how frames look on the network.
//!
//! ```text
//! offset  size  field
//! 0       2     magic "HD"
//! 2       1     format version (3)
//! 3       1     flags: bit 0 = an HMAC tag follows the body; bit 1 = an echo follows
//!               the header; other bits must be 0
//! 4       1     team id
//! 5       1     sender robot id (1..=254)
//! 6       8     sender incarnation, u64 little-endian (random per start)
//! 14      4     send stamp: the sender's clock when the frame was built, microseconds,
//!               u32 little-endian, wrapping every 2^32 µs (71.6 minutes)
//! 18      5     echo (only if flag bit 1): target robot id (u8), the low 16 bits of the
//!               seq of the target's frame heard last (u16 LE), and how long the sender
//!               held it before this frame, in units of 10 µs (u16 LE, at most 655.35 ms)
//! 18|23   ..    body: seq (varint u64), items (varint count, then each item)
//! end-16  16    tag (only if flag bit 0): HMAC-SHA256 over bytes [0, end-16), truncated
//! ```
//!
//! The stamp and the echo are the four NTP timestamps spread over ordinary traffic (no
//! extra message, no server): robot A's frame leaves at t1 (its stamp), B hears it at t2,
//! B's next frame leaves at t3 (its stamp) echoing A's frame and the hold t3 − t2, and A
//! hears that at t4. A then knows the round trip (t4 − t1) − (t3 − t2) and B's clock
//! offset ((t2 − t1) + (t3 − t4)) / 2 (the replica's `clock` module keeps the estimate).
//! A frame echoes one teammate, the one whose echo is oldest, so the cost is 4 bytes per
//! frame plus 5 when an echo rides along.
//!
//! The body is the frame counter `seq` (varint), then items to the end of the body. Each
//! item is its **type** (varint), the **length** of its fields in bytes (varint), then
//! the fields:
//!
//! | type | item       | fields                                            |
//! |------|------------|---------------------------------------------------|
//! | 0    | `Update`   | path (str), value, version (varint), age_us (varint) |
//! | 1    | `Talk`     | queue (str), seq (varint), value                  |
//! | 2    | `TalkHead` | queue (str), first retained seq, last posted seq  |
//! | 3    | `Nack`     | target robot (u8), queue (str), first, last (missing seqs) |
//! | 4    | `Update` of a known path | index into the [`KnownPaths`] table (varint), value, version (varint), age_us (varint) |
//!
//! Item 4 is item 0 with the path as one byte: a team's busiest keys (huddle's team
//! layer registers its arbitration claim, world model, pass receiver and heard tones)
//! cost 12 to 18 bytes of a frame as text, and a league's 128 bytes hold a claim, a pass
//! receiver and a world model only without them. The table is the application's
//! ([`KnownPaths`], in [`crate::ReplicaConfig::known_paths`]), not the protocol's: comms
//! names no application key.
//!
//! Values: a tag byte 0..=5 (`Int` zigzag varint, `Float` 8 bytes LE, `Bool` 1 byte,
//! `String` varint length + UTF-8, `Floats` varint count + 8 bytes LE each (f64), `Bytes`
//! varint length + bytes). Strings are validated as UTF-8 and paths as key paths on decode.
//! A varint is one byte below 251, else a marker byte (251, 252, 253) and the value as a
//! little-endian u16, u32 or u64.
//!
//! # Unknown items: the one rule
//!
//! A reader **skips an item it cannot read to the end of its length and counts it**
//! ([`FrameRef::skipped`], the replica's `items_skipped`); the rest of the frame is
//! applied. An item it cannot read is one of a type it does not know, one whose value has
//! a tag it does not know, and an item 4 whose index is beyond its table. Bytes after
//! the fields a reader knows, inside an item's length, are ignored. One exception: a
//! `Talk` item (type 1) whose value has a tag the reader does not know is **read, not
//! skipped**: its queue and seq are valid, its value is the rest of the item's bytes and
//! [`RawValue::value`] is `None` (format 4 only; format 3 has no length to bound it).
//! Anything else wrong
//! (a length running past the body, a truncated or invalid field of a known item, a bad
//! path, a talk seq out of range) makes the frame malformed: it is dropped whole and
//! nothing in it applied.
//!
//! # The compatibility promise
//!
//! Within format 4, these changes keep every older build of format 4 reading the frame
//! (minus what it does not know), and need **no new VERSION**:
//! - a new item type (the next free number; never reuse one);
//! - new fields at the end of an existing item's fields;
//! - a new value tag (an older reader skips the updates that carry it; a talk message
//!   that carries it follows the talk rule below);
//! - new entries at the end of the application's [`KnownPaths`] table.
//!
//! The talk rule for a mixed-version team: a talk message whose value an older reader
//! cannot decode is **acknowledged** (its seq counts as received: no NACK, the sender
//! stops re-sending it, and the queue's order moves on to the next message at once),
//! **counted** (`Stats::talk_unknown_value`, mirrored as
//! `huddle.stats.talk_unknown_value`) and **surfaced** to the program in its place in the
//! queue as `Event::TalkGivenUp` with `first == last == seq`: never retried for ever,
//! never delivered as some other value. A newer build that needs the older reader to
//! act on such a message must post it with a value the older build knows. Golden
//! bytes: `comms/tests/golden/future_talk.hex`, read by `wire/tests.rs`, `comms/tests/talk_unknown_value.rs` and the root `tests/cli_habits.rs`.
//! (Builds up to afe99d9 skipped such a message as an unknown item:
//! 18 NACKs, the next message held ~1 s, then `TalkGivenUp`.)
//!
//! These need a **new VERSION** (and the reader of the old one kept, as format 3 is):
//! - anything in the 18-byte header or the echo, or a new flag bit (readers drop frames
//!   with flags they do not know: a flag can change how the whole frame reads);
//! - removing a field, changing its meaning, width or encoding, or reordering fields;
//! - changing how an item's type or length, a varint or a value tag is encoded;
//! - reusing an item type number, a value tag, or a table index for something else.
//!
//! # Format 3, still read
//!
//! Format 3 (the builds up to the change to format 4) has the same header with version
//! byte 3, and a body of `seq` (varint), an item count (varint), then the items as type
//! and fields with no length, so it cannot skip anything: an item, value type or index it
//! does not know makes its frame malformed. Item 4 there indexes the same table; huddle's
//! team layer registers its paths in format 3's fixed order, so format 3 frames from older
//! robots read the same. This build reads both, and writes format 3 on request
//! ([`FrameWriter::with_version`]): a replica does while a teammate still speaks format 3
//! (see `Replica`'s docs), so a team upgrades one robot at a time. Version 2 (no stamp)
//! and version 1 (`Floats` as f32) are dropped ([`DecodeError::UnknownVersion`]).
//!
//! # A frame's size
//!
//! Overhead per frame: the 18-byte header, the 5-byte echo when present, the seq varint
//! (1 to 9 bytes) and, with a team key, the 16-byte tag. Per update item: the type byte,
//! the length varint (1 byte below 251 bytes of fields, else 3), the path (length varint
//! and bytes, or one byte for a known path under item 4), the value (1 tag byte, then
//! its encoding; `Bytes` adds a length varint), and the version and age varints (1 to 9
//! bytes each). So the same payload costs more as a match goes on and its counters grow;
//! [`FrameWriter::len`] and [`item_len`] ([`item_len_coded`] for a writer with known
//! paths) compute it exactly without encoding.
//!
//! # Reading frames
//!
//! Decoding happens in two steps, smoltcp-style: the fixed header is checked first (magic,
//! version, team, tag), then the body is walked once and every item validated, before
//! anything is handed out. [`decode_frame_with`] gives a [`FrameRef`] borrowing the
//! datagram: its items are [`ItemView`]s whose paths are `&str` into the bytes and whose
//! values stay encoded until [`RawValue::to_value`], so the receive path allocates only
//! for the values it stores. [`decode_frame_into`] is the same walk that also hands each
//! validated item out into a list the caller keeps: the replica reads each item once
//! (a `FrameRef`'s [`FrameRef::items`] reads them a second time). [`decode_frame`] gives
//! an owned [`Frame`]. All are safe on any input: a [`DecodeError`], never a panic.
//!
//! # Writing frames
//!
//! [`FrameWriter::new_in`] writes into a buffer the caller hands in and gets back from
//! [`FrameWriter::finish`] (quinn-proto's way): a sender that keeps one buffer allocates
//! nothing per frame.
//!
//! # Why bincode, and the way out
//!
//! The body is bincode 2 with `config::standard()` (little-endian, varint integers),
//! decoding limited to [`MAX_FRAME_LEN`] bytes of claimed allocations, because bincode
//! is what the project asked for. It is pinned (`=2.0.1`), built without its default
//! features (no derive macros, no serde: the encode and decode impls are written by
//! hand) and used in one file of this module, `codec.rs`, and nowhere else in huddle.
//! It encodes and decodes the primitives (varints, strings, values); the framing around
//! them (header, item types and lengths) is this module's.
//!
//! RustSec advisory RUSTSEC-2025-0141 marks bincode unmaintained: its team stopped work
//! on it. It reports no vulnerability, and the format needs no further work from
//! upstream. There is no upgrade to take: 3.0.0 is a tombstone release. The exits are
//! wincode, a bincode-compatible implementation, and postcard, whose LEB128 varints
//! differ from bincode's, so there the integer encoding would be written by hand. The
//! golden-byte tests beside this module freeze the format byte for byte: either swap is
//! a change to `codec.rs` alone, and those tests tell whether it kept the format.

use crate::value::Value;

mod auth;
mod codec;
mod decode;
mod known;
#[cfg(test)]
mod two_pass;
mod writer;

pub use auth::TeamKey;
pub use decode::{
    decode_frame, decode_frame_into, decode_frame_with, peek_origin, DecodeError, FrameRef, Items,
};
pub use known::{KnownPaths, KnownPathsError, MAX_KNOWN_PATHS};
pub use writer::{encode_frame, item_len, item_len_coded, value_len, varint_len, FrameWriter};

/// The first two bytes of every frame.
pub const MAGIC: [u8; 2] = *b"HD";
/// The format version this code writes. Version 4: every item carries its type and length,
/// and a reader skips the ones it does not know. Version 3 ([`LEGACY_VERSION`]) is read,
/// and written on request; version 2 (no stamp) and version 1 (`Floats` as f32) are
/// dropped ([`DecodeError::UnknownVersion`]) rather than misread.
pub const VERSION: u8 = 4;
/// The older format still read (and written to teammates that speak only it): items with
/// no length, after an item count.
pub const LEGACY_VERSION: u8 = 3;
/// Bytes of the fixed header (the echo, when present, follows it).
pub const HEADER_LEN: usize = 18;
/// Bytes of an echo.
pub const ECHO_LEN: usize = 5;
/// Longest hold an echo can carry (u16 in units of 10 µs).
pub const MAX_ECHO_HOLD_US: u32 = u16::MAX as u32 * ECHO_HOLD_UNIT_US;
/// The unit of an echo's hold, in microseconds.
pub const ECHO_HOLD_UNIT_US: u32 = 10;
/// Bytes of the truncated HMAC-SHA256 tag (128 bits).
pub const TAG_LEN: usize = 16;
/// Largest frame ever decoded (the largest UDP payload over IPv4).
pub const MAX_FRAME_LEN: usize = 65_507;
/// Smallest MTU a frame writer accepts: a header, the largest seq and count varints and
/// a tag, with room for small items.
pub const MIN_MTU: usize = 64;

/// Largest talk sequence number accepted (2^62): far beyond any real queue, and it keeps
/// the receivers' `seq + 1` arithmetic free of overflow whatever a frame claims.
pub const MAX_TALK_SEQ: u64 = 1 << 62;

const FLAG_TAGGED: u8 = 1;
const FLAG_ECHO: u8 = 2;

/// The timing part of a frame: the sender's clock at send and, optionally, an echo of
/// one teammate's frame (see the module docs for how a receiver uses them).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameClock {
    /// The sender's clock when the frame was built, in microseconds, wrapping at 2^32.
    pub stamp_us: u32,
    /// An echo of the frame last heard from one teammate.
    pub echo: Option<Echo>,
}

/// An echo: "the last frame I heard from `target` was its frame `seq16`, and I held it
/// `hold` before sending this one".
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Echo {
    /// The teammate whose frame is echoed (1..=254).
    pub target: u8,
    /// The low 16 bits of that frame's seq.
    pub seq16: u16,
    /// Time from its reception to this frame's stamp, in units of
    /// [`ECHO_HOLD_UNIT_US`] (10 µs), on the sender's clock.
    pub hold_10us: u16,
}

impl Echo {
    /// The hold in microseconds.
    pub fn hold_us(&self) -> u32 {
        u32::from(self.hold_10us) * ECHO_HOLD_UNIT_US
    }
}

/// A decoded frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Team id; frames of other teams are dropped.
    pub team: u8,
    /// Sending robot (1..=254).
    pub sender: u8,
    /// Sender's incarnation: ordered by start time ([`crate::ordered_incarnation`]), so a
    /// restart is recognised at once and an older life's frames are dropped.
    pub incarnation: u64,
    /// Sender's frame counter within this incarnation (replay protection).
    pub seq: u64,
    /// The sender's send stamp and echo.
    pub clock: FrameClock,
    /// The payload.
    pub items: Vec<Item>,
}

/// One unit of payload.
#[derive(Clone, Debug, PartialEq)]
pub enum Item {
    /// The sender's own global value `sender.var.path`.
    Update {
        /// Key path (after `n.var.`).
        path: String,
        /// The value.
        value: Value,
        /// The sender's version of this key.
        version: u64,
        /// Microseconds since the sender set it, by the sender's clock.
        age_us: u64,
    },
    /// A message of the sender's talk queue `sender.talk.queue`.
    Talk {
        /// Queue path (after `n.talk.`).
        queue: String,
        /// 1-based sequence number within the queue and the sender's incarnation.
        seq: u64,
        /// The message.
        value: Value,
    },
    /// The span of messages the sender still holds for a queue: lets receivers see a lost
    /// tail (`last`) and give up at once on what was evicted (before `first`).
    TalkHead {
        /// Queue path.
        queue: String,
        /// Oldest retained sequence number (`last + 1` if none is retained).
        first: u64,
        /// Newest posted sequence number (0 if none yet).
        last: u64,
    },
    /// A request to `target` to re-send messages `first..=last` of its queue.
    Nack {
        /// The robot asked to repair.
        target: u8,
        /// Queue path.
        queue: String,
        /// First missing sequence number.
        first: u64,
        /// Last missing sequence number.
        last: u64,
    },
}

/// A borrowed item, for encoding without copying values out of the blackboard.
#[derive(Clone, Copy, Debug)]
pub enum ItemRef<'a> {
    /// See [`Item::Update`].
    Update {
        /// Key path.
        path: &'a str,
        /// The value.
        value: &'a Value,
        /// Version.
        version: u64,
        /// Age in microseconds.
        age_us: u64,
    },
    /// See [`Item::Talk`].
    Talk {
        /// Queue path.
        queue: &'a str,
        /// Sequence number.
        seq: u64,
        /// The message.
        value: &'a Value,
    },
    /// See [`Item::TalkHead`].
    TalkHead {
        /// Queue path.
        queue: &'a str,
        /// Oldest retained.
        first: u64,
        /// Newest posted.
        last: u64,
    },
    /// See [`Item::Nack`].
    Nack {
        /// Robot asked to repair.
        target: u8,
        /// Queue path.
        queue: &'a str,
        /// First missing.
        first: u64,
        /// Last missing.
        last: u64,
    },
}

impl Item {
    /// A borrowed view for encoding.
    pub fn as_ref(&self) -> ItemRef<'_> {
        match self {
            Item::Update {
                path,
                value,
                version,
                age_us,
            } => ItemRef::Update {
                path,
                value,
                version: *version,
                age_us: *age_us,
            },
            Item::Talk { queue, seq, value } => ItemRef::Talk {
                queue,
                seq: *seq,
                value,
            },
            Item::TalkHead { queue, first, last } => ItemRef::TalkHead {
                queue,
                first: *first,
                last: *last,
            },
            Item::Nack {
                target,
                queue,
                first,
                last,
            } => ItemRef::Nack {
                target: *target,
                queue,
                first: *first,
                last: *last,
            },
        }
    }
}

/// A borrowed, validated item of a received frame ([`FrameRef::items`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ItemView<'a> {
    /// See [`Item::Update`].
    Update {
        /// Key path.
        path: &'a str,
        /// The value, still encoded.
        value: RawValue<'a>,
        /// Version.
        version: u64,
        /// Age in microseconds.
        age_us: u64,
    },
    /// See [`Item::Talk`].
    Talk {
        /// Queue path.
        queue: &'a str,
        /// Sequence number.
        seq: u64,
        /// The message, still encoded.
        value: RawValue<'a>,
    },
    /// See [`Item::TalkHead`].
    TalkHead {
        /// Queue path.
        queue: &'a str,
        /// Oldest retained.
        first: u64,
        /// Newest posted.
        last: u64,
    },
    /// See [`Item::Nack`].
    Nack {
        /// Robot asked to repair.
        target: u8,
        /// Queue path.
        queue: &'a str,
        /// First missing.
        first: u64,
        /// Last missing.
        last: u64,
    },
}

impl ItemView<'_> {
    /// An owned copy.
    pub fn to_item(&self) -> Item {
        match *self {
            ItemView::Update {
                path,
                value,
                version,
                age_us,
            } => Item::Update {
                path: path.to_owned(),
                value: value.to_value(),
                version,
                age_us,
            },
            ItemView::Talk { queue, seq, value } => Item::Talk {
                queue: queue.to_owned(),
                seq,
                value: value.to_value(),
            },
            ItemView::TalkHead { queue, first, last } => Item::TalkHead {
                queue: queue.to_owned(),
                first,
                last,
            },
            ItemView::Nack {
                target,
                queue,
                first,
                last,
            } => Item::Nack {
                target,
                queue: queue.to_owned(),
                first,
                last,
            },
        }
    }
}

/// A value as it was received: checked, still encoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RawValue<'a>(&'a [u8]);

impl RawValue<'_> {
    /// The value (allocates only for strings, vectors and bytes).
    pub fn to_value(&self) -> Value {
        // Checked on decode, so this cannot fail; should it, an empty value is stored
        // rather than a panic.
        codec::decode_value(self.0).unwrap_or(Value::Bytes(Vec::new()))
    }

    /// The value, or `None` for a tag this build does not know (only a talk message
    /// carries one: see "The compatibility promise").
    pub fn value(&self) -> Option<Value> {
        match self.0.first() {
            Some(&tag) if tag <= 5 => Some(self.to_value()),
            _ => None,
        }
    }

    /// Its encoded bytes.
    pub fn as_bytes(&self) -> &[u8] {
        self.0
    }
}

#[cfg(test)]
pub(crate) mod tests;
