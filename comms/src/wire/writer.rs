//! Building frames: item by item within a byte budget, and the exact encoded sizes.

use super::auth::TeamKey;
use super::codec;
use super::{
    Frame, FrameClock, ItemRef, KnownPaths, ECHO_LEN, FLAG_ECHO, FLAG_TAGGED, HEADER_LEN,
    LEGACY_VERSION, MAGIC, TAG_LEN, VERSION,
};
use crate::value::Value;

/// Bytes a varint takes for `v`.
pub fn varint_len(v: u64) -> usize {
    match v {
        0..=250 => 1,
        251..=0xFFFF => 3,
        0x1_0000..=0xFFFF_FFFF => 5,
        _ => 9,
    }
}

/// Builds one frame item by item within a byte budget (the MTU), writing into a buffer
/// the caller hands in and gets back ([`FrameWriter::new_in`], [`FrameWriter::finish`]).
#[derive(Debug)]
pub struct FrameWriter<'k> {
    /// Header, echo, seq and the items so far.
    buf: Vec<u8>,
    /// Where the items start in `buf`.
    items_at: usize,
    /// The frame's seq (its varint ends the header part, after any echo).
    seq: u64,
    count: usize,
    budget: usize,
    key: Option<&'k TeamKey>,
    known: &'k KnownPaths,
    version: u8,
}

impl<'k> FrameWriter<'k> {
    /// A writer for a frame of at most `budget` bytes (tag included), with a send stamp
    /// of 0 and no echo until [`FrameWriter::set_clock`], in a buffer of its own.
    pub fn new(
        team: u8,
        sender: u8,
        incarnation: u64,
        seq: u64,
        budget: usize,
        key: Option<&'k TeamKey>,
    ) -> FrameWriter<'k> {
        let buf = Vec::with_capacity(budget.min(2048));
        FrameWriter::new_in(buf, team, sender, incarnation, seq, budget, key)
    }

    /// [`FrameWriter::new`] writing into `buf` (cleared first; its capacity is reused).
    pub fn new_in(
        mut buf: Vec<u8>,
        team: u8,
        sender: u8,
        incarnation: u64,
        seq: u64,
        budget: usize,
        key: Option<&'k TeamKey>,
    ) -> FrameWriter<'k> {
        buf.clear();
        // A fresh buffer (`Replica::poll_transmit` passes an empty one per frame) would
        // otherwise grow 8 → 16 → … bytes, item by item, reallocating and copying each time.
        if buf.capacity() == 0 {
            buf.reserve(budget.min(2048));
        }
        // The header in one copy (a push per field checked the capacity each time).
        let mut header = [0u8; HEADER_LEN];
        header[..2].copy_from_slice(&MAGIC);
        header[2] = VERSION;
        header[3] = if key.is_some() { FLAG_TAGGED } else { 0 };
        header[4] = team;
        header[5] = sender;
        header[6..14].copy_from_slice(&incarnation.to_le_bytes());
        buf.extend_from_slice(&header);
        codec::put_varint(seq, &mut buf);
        FrameWriter {
            items_at: buf.len(),
            seq,
            buf,
            count: 0,
            budget,
            key,
            known: KnownPaths::none(),
            version: VERSION,
        }
    }

    /// The writer sends the paths of `known` as an index (item 4; see the module docs).
    /// Off (an empty table) by default.
    pub fn with_known_paths(mut self, known: &'k KnownPaths) -> Self {
        self.known = known;
        self
    }

    /// Writes format `version`: [`VERSION`] (the default) or [`LEGACY_VERSION`], for
    /// teammates that read only it; any other is ignored. Call before pushing items.
    pub fn with_version(mut self, version: u8) -> Self {
        if (version == VERSION || version == LEGACY_VERSION) && self.count == 0 {
            self.version = version;
            self.buf[2] = version;
        }
        self
    }

    /// Sets the frame's send stamp and echo (best before pushing items: an echo takes
    /// [`ECHO_LEN`] bytes of the budget, and items already pushed move to make room).
    pub fn set_clock(&mut self, clock: FrameClock) {
        self.buf[14..HEADER_LEN].copy_from_slice(&clock.stamp_us.to_le_bytes());
        let had = self.buf[3] & FLAG_ECHO != 0;
        match clock.echo {
            Some(e) => {
                let mut b = [0u8; ECHO_LEN];
                b[0] = e.target;
                b[1..3].copy_from_slice(&e.seq16.to_le_bytes());
                b[3..5].copy_from_slice(&e.hold_10us.to_le_bytes());
                if had {
                    self.buf[HEADER_LEN..HEADER_LEN + ECHO_LEN].copy_from_slice(&b);
                } else if self.count == 0 {
                    // Only the seq follows the header (the usual case: the clock is set
                    // first): written again after the echo.
                    self.buf.truncate(HEADER_LEN);
                    self.buf.extend_from_slice(&b);
                    codec::put_varint(self.seq, &mut self.buf);
                    self.items_at = self.buf.len();
                    self.buf[3] |= FLAG_ECHO;
                } else {
                    // Room after the header: the few bytes behind it (the seq, any items)
                    // move up in one copy (a `splice` cost more than the rest of this
                    // call, on every frame).
                    let len = self.buf.len();
                    self.buf.resize(len + ECHO_LEN, 0);
                    self.buf.copy_within(HEADER_LEN..len, HEADER_LEN + ECHO_LEN);
                    self.buf[HEADER_LEN..HEADER_LEN + ECHO_LEN].copy_from_slice(&b);
                    self.items_at += ECHO_LEN;
                    self.buf[3] |= FLAG_ECHO;
                }
            }
            None if had => {
                self.buf.drain(HEADER_LEN..HEADER_LEN + ECHO_LEN);
                self.items_at -= ECHO_LEN;
                self.buf[3] &= !FLAG_ECHO;
            }
            None => {}
        }
    }

    fn total_len(&self, count: usize) -> usize {
        let tag = if self.key.is_some() { TAG_LEN } else { 0 };
        // Format 3 puts an item count before the items.
        let count = if self.version == LEGACY_VERSION {
            varint_len(count as u64)
        } else {
            0
        };
        self.buf.len() + count + tag
    }

    /// Frame size so far.
    pub fn len(&self) -> usize {
        self.total_len(self.count)
    }

    /// Whether no item was added.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Appends `item` if the frame stays within budget; returns whether it did.
    pub fn push(&mut self, item: ItemRef<'_>) -> bool {
        let shape = codec::item_type(&item, self.known);
        let fields = fields_len(&item, shape.1.is_some());
        let with_len = self.version != LEGACY_VERSION;
        let item_len = varint_len(shape.0)
            + if with_len {
                varint_len(fields as u64)
            } else {
                0
            }
            + fields;
        if self.total_len(self.count + 1) + item_len > self.budget {
            return false;
        }
        let before = self.buf.len();
        codec::put_item(item, shape, with_len.then_some(fields), &mut self.buf);
        debug_assert_eq!(
            self.buf.len() - before,
            item_len,
            "item sizes are computed exactly"
        );
        self.count += 1;
        true
    }

    /// The finished frame, tagged if a key was given: the buffer handed to
    /// [`FrameWriter::new_in`], to hand back to the next writer.
    pub fn finish(mut self) -> Vec<u8> {
        if self.version == LEGACY_VERSION {
            // Only known now; format 3 is the path of teammates on older builds.
            let mut count = Vec::with_capacity(9);
            codec::put_varint(self.count as u64, &mut count);
            self.buf.splice(self.items_at..self.items_at, count);
        }
        if let Some(key) = self.key {
            let tag = key.tag(&self.buf);
            self.buf.extend_from_slice(&tag);
        }
        self.buf
    }
}

/// Bytes of an item's fields (after its type and length), the path as an index if
/// `indexed`.
fn fields_len(item: &ItemRef<'_>, indexed: bool) -> usize {
    let str_len = |s: &str| varint_len(s.len() as u64) + s.len();
    match *item {
        ItemRef::Update {
            path,
            value,
            version,
            age_us,
        } => {
            // Indices are below 251: one byte.
            let path = if indexed { 1 } else { str_len(path) };
            path + value_len(value) + varint_len(version) + varint_len(age_us)
        }
        ItemRef::Talk { queue, seq, value } => str_len(queue) + varint_len(seq) + value_len(value),
        ItemRef::TalkHead { queue, first, last } => {
            str_len(queue) + varint_len(first) + varint_len(last)
        }
        ItemRef::Nack {
            queue, first, last, ..
        } => 1 + str_len(queue) + varint_len(first) + varint_len(last),
    }
}

/// Encoded size of one item in format 4 (what it adds to a frame's body: type, length and
/// fields), computed without encoding, as a writer without known paths writes it.
pub fn item_len(item: ItemRef<'_>) -> usize {
    item_len_coded(item, KnownPaths::none())
}

/// [`item_len`] for a writer that sends the paths of `known` as an index
/// ([`FrameWriter::with_known_paths`]).
pub fn item_len_coded(item: ItemRef<'_>, known: &KnownPaths) -> usize {
    let (ty, index) = codec::item_type(&item, known);
    let fields = fields_len(&item, index.is_some());
    varint_len(ty) + varint_len(fields as u64) + fields
}

/// Encoded size of a value.
pub fn value_len(value: &Value) -> usize {
    1 + match value {
        // Signed integers are zigzag-encoded before the varint.
        Value::Int(v) => varint_len(((v << 1) ^ (v >> 63)) as u64),
        Value::Float(_) => 8,
        Value::Bool(_) => 1,
        Value::String(s) => varint_len(s.len() as u64) + s.len(),
        Value::Floats(v) => varint_len(v.len() as u64) + 8 * v.len(),
        Value::Bytes(b) => varint_len(b.len() as u64) + b.len(),
    }
}

/// Encodes a whole frame with no size budget (tests, tools, benches).
pub fn encode_frame(frame: &Frame, key: Option<&TeamKey>) -> Vec<u8> {
    let mut w = FrameWriter::new(
        frame.team,
        frame.sender,
        frame.incarnation,
        frame.seq,
        usize::MAX,
        key,
    );
    w.set_clock(frame.clock);
    for item in &frame.items {
        w.push(item.as_ref());
    }
    w.finish()
}
