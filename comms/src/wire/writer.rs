//! Building frames: item by item within a byte budget, and the exact encoded sizes.

use super::auth::TeamKey;
use super::codec;
use super::{
    Frame, FrameClock, ItemRef, ECHO_LEN, FLAG_ECHO, FLAG_TAGGED, HEADER_LEN, MAGIC, TAG_LEN,
    VERSION,
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

/// Builds one frame item by item within a byte budget (the MTU).
#[derive(Debug)]
pub struct FrameWriter<'k> {
    header: [u8; HEADER_LEN],
    echo: Option<[u8; ECHO_LEN]>,
    seq: u64,
    items: Vec<u8>,
    count: usize,
    budget: usize,
    key: Option<&'k TeamKey>,
    known_paths: bool,
}

impl<'k> FrameWriter<'k> {
    /// A writer for a frame of at most `budget` bytes (tag included), with a send stamp
    /// of 0 and no echo until [`FrameWriter::set_clock`].
    pub fn new(
        team: u8,
        sender: u8,
        incarnation: u64,
        seq: u64,
        budget: usize,
        key: Option<&'k TeamKey>,
    ) -> FrameWriter<'k> {
        let mut header = [0u8; HEADER_LEN];
        header[..2].copy_from_slice(&MAGIC);
        header[2] = VERSION;
        header[3] = if key.is_some() { FLAG_TAGGED } else { 0 };
        header[4] = team;
        header[5] = sender;
        header[6..14].copy_from_slice(&incarnation.to_le_bytes());
        FrameWriter {
            header,
            echo: None,
            seq,
            items: Vec::with_capacity(budget.min(2048)),
            count: 0,
            budget,
            key,
            known_paths: false,
        }
    }

    /// The writer sends the paths of [`super::KNOWN_PATHS`] as one byte (item 4; see
    /// the module docs). Off by default.
    pub fn with_known_paths(mut self, on: bool) -> Self {
        self.known_paths = on;
        self
    }

    /// Sets the frame's send stamp and echo (call before pushing items: an echo takes
    /// [`ECHO_LEN`] bytes of the budget).
    pub fn set_clock(&mut self, clock: FrameClock) {
        self.header[14..18].copy_from_slice(&clock.stamp_us.to_le_bytes());
        self.echo = clock.echo.map(|e| {
            let mut b = [0u8; ECHO_LEN];
            b[0] = e.target;
            b[1..3].copy_from_slice(&e.seq16.to_le_bytes());
            b[3..5].copy_from_slice(&e.hold_10us.to_le_bytes());
            b
        });
        if self.echo.is_some() {
            self.header[3] |= FLAG_ECHO;
        } else {
            self.header[3] &= !FLAG_ECHO;
        }
    }

    fn total_len(&self, items_len: usize, count: usize) -> usize {
        let tag = if self.key.is_some() { TAG_LEN } else { 0 };
        let echo = if self.echo.is_some() { ECHO_LEN } else { 0 };
        HEADER_LEN + echo + varint_len(self.seq) + varint_len(count as u64) + items_len + tag
    }

    /// Frame size so far.
    pub fn len(&self) -> usize {
        self.total_len(self.items.len(), self.count)
    }

    /// Whether no item was added.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Appends `item` if the frame stays within budget; returns whether it did.
    pub fn push(&mut self, item: ItemRef<'_>) -> bool {
        let before = self.items.len();
        if !codec::encode_item(item, self.known_paths, &mut self.items)
            || self.total_len(self.items.len(), self.count + 1) > self.budget
        {
            self.items.truncate(before);
            return false;
        }
        self.count += 1;
        true
    }

    /// The finished frame, tagged if a key was given.
    pub fn finish(self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.len());
        out.extend_from_slice(&self.header);
        if let Some(echo) = &self.echo {
            out.extend_from_slice(echo);
        }
        codec::encode_varint(self.seq, &mut out);
        codec::encode_varint(self.count as u64, &mut out);
        out.extend_from_slice(&self.items);
        if let Some(key) = self.key {
            let tag = key.tag(&out);
            out.extend_from_slice(&tag);
        }
        out
    }
}

/// Encoded size of one item (what it adds to a frame's body), computed without encoding,
/// as a writer without known paths writes it.
pub fn item_len(item: ItemRef<'_>) -> usize {
    item_len_coded(item, false)
}

/// [`item_len`] for a writer that sends known paths as one byte (`known_paths`, see
/// [`FrameWriter::with_known_paths`]) or not.
pub fn item_len_coded(item: ItemRef<'_>, known_paths: bool) -> usize {
    let str_len = |s: &str| varint_len(s.len() as u64) + s.len();
    let path_len = |s: &str| match super::known_path_index(s).filter(|_| known_paths) {
        Some(i) => varint_len(u64::from(i)),
        None => str_len(s),
    };
    // Every variant index is below 251: one byte.
    1 + match item {
        ItemRef::Update {
            path,
            value,
            version,
            age_us,
        } => path_len(path) + value_len(value) + varint_len(version) + varint_len(age_us),
        ItemRef::Talk { queue, seq, value } => str_len(queue) + varint_len(seq) + value_len(value),
        ItemRef::TalkHead { queue, first, last } => {
            str_len(queue) + varint_len(first) + varint_len(last)
        }
        ItemRef::Nack {
            queue, first, last, ..
        } => 1 + str_len(queue) + varint_len(first) + varint_len(last),
    }
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
