//! The wire format: the only place that knows how frames look on the network, and the
//! only user of bincode (2.0.1, `config::standard()`: little-endian, varint integers,
//! decoding limited to [`MAX_FRAME_LEN`] bytes of claimed allocations).
//!
//! ```text
//! offset  size  field
//! 0       2     magic "HD"
//! 2       1     format version (1)
//! 3       1     flags: bit 0 = an HMAC tag follows the body; other bits must be 0
//! 4       1     team id
//! 5       1     sender robot id (1..=254)
//! 6       8     sender incarnation, u64 little-endian (random per start)
//! 14      ..    body, bincode: seq (varint u64), items (varint count, then each item)
//! end-16  16    tag (only if flag bit 0): HMAC-SHA256 over bytes [0, end-16), truncated
//! ```
//!
//! Items (bincode enum: varint variant index, then the fields in order):
//!
//! | idx | item       | fields                                            |
//! |-----|------------|---------------------------------------------------|
//! | 0   | `Update`   | path (str), value, version (varint), age_us (varint) |
//! | 1   | `Talk`     | queue (str), seq (varint), value                  |
//! | 2   | `TalkHead` | queue (str), first retained seq, last posted seq  |
//! | 3   | `Nack`     | target robot (u8), queue (str), first, last (missing seqs) |
//!
//! Values: varint tag 0..=5 (`Int` zigzag varint, `Float` 8 bytes LE, `Bool` 1 byte,
//! `String` varint length + UTF-8, `Floats` varint count + 4 bytes LE each, `Bytes` varint
//! length + bytes). Strings are validated as UTF-8 and paths as key paths on decode.
//!
//! Decoding happens in two steps, smoltcp-style: the fixed header is checked first (magic,
//! version, team, tag), then the body is decoded into owned values and validated.
//! [`decode_frame`] is safe on any input: it returns a [`DecodeError`], never panics.

use bincode::de::{Decode, Decoder};
use bincode::enc::{Encode, Encoder};
use bincode::error::{AllowedEnumVariants, DecodeError as BincodeDecodeError, EncodeError};
use hmac::{Hmac, KeyInit, Mac};
use sha2::Sha256;
use thiserror::Error;

use crate::key::{validate_path, ROBOT_IDS};
use crate::value::Value;

/// The first two bytes of every frame.
pub const MAGIC: [u8; 2] = *b"HD";
/// The format version this code speaks.
pub const VERSION: u8 = 1;
/// Bytes before the body.
pub const HEADER_LEN: usize = 14;
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

fn config() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<MAX_FRAME_LEN>()
}

/// A decoded frame.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Team id; frames of other teams are dropped.
    pub team: u8,
    /// Sending robot (1..=254).
    pub sender: u8,
    /// Sender's incarnation: random per start, so a restart is recognised at once.
    pub incarnation: u64,
    /// Sender's frame counter within this incarnation (replay protection).
    pub seq: u64,
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

/// Why bytes are not a frame for us. Each variant is a drop reason in the stats.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum DecodeError {
    /// Shorter than the header (or the tag).
    #[error("frame too short")]
    TooShort,
    /// Longer than the limit.
    #[error("frame too long")]
    Oversized,
    /// Not a huddle frame.
    #[error("bad magic")]
    BadMagic,
    /// A format version this code does not speak.
    #[error("unknown format version {0}")]
    UnknownVersion(u8),
    /// Another team's frame.
    #[error("frame of team {0}")]
    OtherTeam(u8),
    /// We hold a team key but the frame carries no tag.
    #[error("frame has no authentication tag")]
    MissingTag,
    /// The frame carries a tag but we hold no team key to check it.
    #[error("frame has a tag but no team key is configured")]
    UnexpectedTag,
    /// The tag does not match: wrong key, or the frame was altered.
    #[error("authentication tag does not match")]
    BadTag,
    /// Header flags, sender id, body encoding or a path is invalid.
    #[error("malformed frame: {0}")]
    Malformed(String),
}

/// A team key, ready to tag and check frames.
#[derive(Clone)]
pub struct TeamKey(Hmac<Sha256>);

impl TeamKey {
    /// Prepares HMAC-SHA256 with `key` (any length; 32 random bytes recommended).
    pub fn new(key: &[u8]) -> TeamKey {
        // HMAC accepts keys of every length (long ones are hashed), so this cannot fail.
        TeamKey(Hmac::<Sha256>::new_from_slice(key).expect("HMAC takes keys of any length"))
    }

    fn tag(&self, data: &[u8]) -> [u8; TAG_LEN] {
        let mut mac = self.0.clone();
        mac.update(data);
        let full = mac.finalize().into_bytes();
        let mut tag = [0u8; TAG_LEN];
        tag.copy_from_slice(&full[..TAG_LEN]);
        tag
    }

    fn verify(&self, data: &[u8], tag: &[u8]) -> bool {
        let mut mac = self.0.clone();
        mac.update(data);
        // Constant-time comparison of the leftmost TAG_LEN bytes.
        mac.verify_truncated_left(tag).is_ok()
    }
}

impl std::fmt::Debug for TeamKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("TeamKey(..)")
    }
}

/// Bytes bincode's varint takes for `v`.
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
    seq: u64,
    items: Vec<u8>,
    count: usize,
    budget: usize,
    key: Option<&'k TeamKey>,
}

impl<'k> FrameWriter<'k> {
    /// A writer for a frame of at most `budget` bytes (tag included).
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
            seq,
            items: Vec::with_capacity(budget.min(2048)),
            count: 0,
            budget,
            key,
        }
    }

    fn total_len(&self, items_len: usize, count: usize) -> usize {
        let tag = if self.key.is_some() { TAG_LEN } else { 0 };
        HEADER_LEN + varint_len(self.seq) + varint_len(count as u64) + items_len + tag
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
        if bincode::encode_into_std_write(item, &mut self.items, config()).is_err()
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
        // Writing varints into a Vec cannot fail.
        let _ = bincode::encode_into_std_write(self.seq, &mut out, config());
        let _ = bincode::encode_into_std_write(self.count as u64, &mut out, config());
        out.extend_from_slice(&self.items);
        if let Some(key) = self.key {
            let tag = key.tag(&out);
            out.extend_from_slice(&tag);
        }
        out
    }
}

/// Encoded size of one item (what it adds to a frame's body), computed without encoding.
pub fn item_len(item: ItemRef<'_>) -> usize {
    let str_len = |s: &str| varint_len(s.len() as u64) + s.len();
    // Every variant index is below 251: one byte.
    1 + match item {
        ItemRef::Update {
            path,
            value,
            version,
            age_us,
        } => str_len(path) + value_len(value) + varint_len(version) + varint_len(age_us),
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
        Value::Floats(v) => varint_len(v.len() as u64) + 4 * v.len(),
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
    for item in &frame.items {
        w.push(item.as_ref());
    }
    w.finish()
}

/// The sender id and incarnation of what looks like a frame of `team`, read from the
/// plain header alone (magic, version and team checked; nothing else, no tag). Only for
/// recognising one's own looped-back frames cheaply: never trust it for anything else.
pub fn peek_origin(bytes: &[u8], team: u8) -> Option<(u8, u64)> {
    let header = bytes.get(..HEADER_LEN)?;
    if header[..2] != MAGIC || header[2] != VERSION || header[4] != team {
        return None;
    }
    let mut incarnation = [0u8; 8];
    incarnation.copy_from_slice(&header[6..14]);
    Some((header[5], u64::from_le_bytes(incarnation)))
}

/// Decodes and validates a frame addressed to `team`; with `key`, it must carry a valid
/// tag, and without one it must carry none. Safe on untrusted input.
pub fn decode_frame(bytes: &[u8], team: u8, key: Option<&TeamKey>) -> Result<Frame, DecodeError> {
    if bytes.len() > MAX_FRAME_LEN {
        return Err(DecodeError::Oversized);
    }
    if bytes.len() < 2 {
        return Err(DecodeError::TooShort);
    }
    if bytes[..2] != MAGIC {
        return Err(DecodeError::BadMagic);
    }
    if bytes.len() < HEADER_LEN {
        return Err(DecodeError::TooShort);
    }
    if bytes[2] != VERSION {
        return Err(DecodeError::UnknownVersion(bytes[2]));
    }
    let flags = bytes[3];
    if flags & !FLAG_TAGGED != 0 {
        return Err(DecodeError::Malformed(format!(
            "unknown flags {flags:#04x}"
        )));
    }
    if bytes[4] != team {
        return Err(DecodeError::OtherTeam(bytes[4]));
    }
    let body = match (flags & FLAG_TAGGED != 0, key) {
        (true, Some(key)) => {
            if bytes.len() < HEADER_LEN + TAG_LEN {
                return Err(DecodeError::TooShort);
            }
            let (signed, tag) = bytes.split_at(bytes.len() - TAG_LEN);
            if !key.verify(signed, tag) {
                return Err(DecodeError::BadTag);
            }
            &signed[HEADER_LEN..]
        }
        (false, Some(_)) => return Err(DecodeError::MissingTag),
        (true, None) => return Err(DecodeError::UnexpectedTag),
        (false, None) => &bytes[HEADER_LEN..],
    };
    let sender = bytes[5];
    if !ROBOT_IDS.contains(&sender) {
        return Err(DecodeError::Malformed(format!("sender id {sender}")));
    }
    let mut incarnation = [0u8; 8];
    incarnation.copy_from_slice(&bytes[6..14]);
    let ((seq, items), used): ((u64, Vec<Item>), usize) =
        bincode::decode_from_slice(body, config())
            .map_err(|e| DecodeError::Malformed(e.to_string()))?;
    if used != body.len() {
        return Err(DecodeError::Malformed(format!(
            "{} bytes after the items",
            body.len() - used
        )));
    }
    for item in &items {
        validate_item(item)?;
    }
    Ok(Frame {
        team,
        sender,
        incarnation: u64::from_le_bytes(incarnation),
        seq,
        items,
    })
}

fn validate_item(item: &Item) -> Result<(), DecodeError> {
    let bad_path = |e: crate::KeyError| DecodeError::Malformed(e.to_string());
    match item {
        Item::Update { path, .. } => validate_path(path).map_err(bad_path),
        Item::Talk { queue, seq, .. } => {
            validate_path(queue).map_err(bad_path)?;
            if *seq == 0 || *seq > MAX_TALK_SEQ {
                return Err(DecodeError::Malformed(format!("talk seq {seq}")));
            }
            Ok(())
        }
        Item::TalkHead { queue, first, last } => {
            validate_path(queue).map_err(bad_path)?;
            if *first == 0 || *first > last.saturating_add(1) || *last > MAX_TALK_SEQ {
                return Err(DecodeError::Malformed(format!("talk head {first}..{last}")));
            }
            Ok(())
        }
        Item::Nack {
            target,
            queue,
            first,
            last,
        } => {
            validate_path(queue).map_err(bad_path)?;
            if !ROBOT_IDS.contains(target) || *first == 0 || first > last || *last > MAX_TALK_SEQ {
                return Err(DecodeError::Malformed(format!(
                    "nack {target} {first}..{last}"
                )));
            }
            Ok(())
        }
    }
}

impl Encode for Value {
    fn encode<E: Encoder>(&self, e: &mut E) -> Result<(), EncodeError> {
        match self {
            Value::Int(v) => {
                0u32.encode(e)?;
                v.encode(e)
            }
            Value::Float(v) => {
                1u32.encode(e)?;
                v.encode(e)
            }
            Value::Bool(v) => {
                2u32.encode(e)?;
                v.encode(e)
            }
            Value::String(v) => {
                3u32.encode(e)?;
                v.encode(e)
            }
            Value::Floats(v) => {
                4u32.encode(e)?;
                v.encode(e)
            }
            Value::Bytes(v) => {
                5u32.encode(e)?;
                v.as_slice().encode(e)
            }
        }
    }
}

impl<Ctx> Decode<Ctx> for Value {
    fn decode<D: Decoder<Context = Ctx>>(d: &mut D) -> Result<Self, BincodeDecodeError> {
        Ok(match u32::decode(d)? {
            0 => Value::Int(i64::decode(d)?),
            1 => Value::Float(f64::decode(d)?),
            2 => Value::Bool(bool::decode(d)?),
            3 => Value::String(String::decode(d)?),
            4 => Value::Floats(Vec::<f32>::decode(d)?),
            5 => Value::Bytes(Vec::<u8>::decode(d)?),
            found => {
                return Err(BincodeDecodeError::UnexpectedVariant {
                    type_name: "Value",
                    allowed: &AllowedEnumVariants::Range { min: 0, max: 5 },
                    found,
                })
            }
        })
    }
}

impl Encode for ItemRef<'_> {
    fn encode<E: Encoder>(&self, e: &mut E) -> Result<(), EncodeError> {
        match *self {
            ItemRef::Update {
                path,
                value,
                version,
                age_us,
            } => {
                0u32.encode(e)?;
                path.encode(e)?;
                value.encode(e)?;
                version.encode(e)?;
                age_us.encode(e)
            }
            ItemRef::Talk { queue, seq, value } => {
                1u32.encode(e)?;
                queue.encode(e)?;
                seq.encode(e)?;
                value.encode(e)
            }
            ItemRef::TalkHead { queue, first, last } => {
                2u32.encode(e)?;
                queue.encode(e)?;
                first.encode(e)?;
                last.encode(e)
            }
            ItemRef::Nack {
                target,
                queue,
                first,
                last,
            } => {
                3u32.encode(e)?;
                target.encode(e)?;
                queue.encode(e)?;
                first.encode(e)?;
                last.encode(e)
            }
        }
    }
}

impl<Ctx> Decode<Ctx> for Item {
    fn decode<D: Decoder<Context = Ctx>>(d: &mut D) -> Result<Self, BincodeDecodeError> {
        Ok(match u32::decode(d)? {
            0 => Item::Update {
                path: String::decode(d)?,
                value: Value::decode(d)?,
                version: u64::decode(d)?,
                age_us: u64::decode(d)?,
            },
            1 => Item::Talk {
                queue: String::decode(d)?,
                seq: u64::decode(d)?,
                value: Value::decode(d)?,
            },
            2 => Item::TalkHead {
                queue: String::decode(d)?,
                first: u64::decode(d)?,
                last: u64::decode(d)?,
            },
            3 => Item::Nack {
                target: u8::decode(d)?,
                queue: String::decode(d)?,
                first: u64::decode(d)?,
                last: u64::decode(d)?,
            },
            found => {
                return Err(BincodeDecodeError::UnexpectedVariant {
                    type_name: "Item",
                    allowed: &AllowedEnumVariants::Range { min: 0, max: 3 },
                    found,
                })
            }
        })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use proptest::prelude::*;

    fn hex(bytes: &[u8]) -> String {
        bytes.iter().map(|b| format!("{b:02x}")).collect()
    }

    fn sample() -> Frame {
        Frame {
            team: 7,
            sender: 3,
            incarnation: 0x0102_0304_0506_0708,
            seq: 300,
            items: vec![
                Item::Update {
                    path: "ball.dist".into(),
                    value: Value::Float(1.5),
                    version: 2,
                    age_us: 1000,
                },
                Item::Update {
                    path: "mode".into(),
                    value: Value::Int(-2),
                    version: 1,
                    age_us: 0,
                },
                Item::Talk {
                    queue: "plan".into(),
                    seq: 1,
                    value: Value::String("go".into()),
                },
                Item::TalkHead {
                    queue: "plan".into(),
                    first: 1,
                    last: 1,
                },
                Item::Nack {
                    target: 5,
                    queue: "q".into(),
                    first: 4,
                    last: 6,
                },
                Item::Update {
                    path: "v".into(),
                    value: Value::Floats(vec![1.0, -2.0]),
                    version: 1,
                    age_us: 0,
                },
                Item::Update {
                    path: "b".into(),
                    value: Value::Bytes(vec![0xab]),
                    version: 1,
                    age_us: 0,
                },
                Item::Update {
                    path: "t".into(),
                    value: Value::Bool(true),
                    version: 1,
                    age_us: 0,
                },
            ],
        }
    }

    // Frozen bytes: if this test fails, the wire format changed. Bump VERSION instead of
    // editing the fixture, or robots running different builds stop understanding each other.
    const GOLDEN: &str = concat!(
        "4844",
        "01",
        "00",
        "07",
        "03",
        "0807060504030201", // header
        "fb2c01",
        "08", // seq 300, 8 items
        "00",
        "09",
        "62616c6c2e64697374",
        "01",
        "000000000000f83f",
        "02",
        "fbe803",
        "00",
        "04",
        "6d6f6465",
        "00",
        "03",
        "01",
        "00",
        "01",
        "04",
        "706c616e",
        "01",
        "03",
        "02",
        "676f",
        "02",
        "04",
        "706c616e",
        "01",
        "01",
        "03",
        "05",
        "0171",
        "04",
        "06",
        "00",
        "0176",
        "04",
        "02",
        "0000803f",
        "000000c0",
        "01",
        "00",
        "00",
        "0162",
        "05",
        "01",
        "ab",
        "01",
        "00",
        "00",
        "0174",
        "02",
        "01",
        "01",
        "00",
    );

    #[test]
    fn golden_bytes_freeze_the_format() {
        let bytes = encode_frame(&sample(), None);
        assert_eq!(hex(&bytes), GOLDEN);
        assert_eq!(decode_frame(&bytes, 7, None), Ok(sample()));
    }

    #[test]
    fn golden_tag_is_truncated_hmac_sha256_over_everything_before_it() {
        let key = TeamKey::new(b"team key");
        let frame = Frame {
            items: vec![],
            ..sample()
        };
        let bytes = encode_frame(&frame, Some(&key));
        assert_eq!(
            hex(&bytes),
            "4844010107030807060504030201fb2c0100dab453d28cb443313096653934e84bdc",
            "header with flag 1, seq, 0 items, 16-byte tag (checked against Python's hmac)"
        );
        assert_eq!(decode_frame(&bytes, 7, Some(&key)), Ok(frame));
    }

    #[test]
    fn bad_frames_are_told_apart() {
        let key = TeamKey::new(b"k");
        let plain = encode_frame(&sample(), None);
        let tagged = encode_frame(&sample(), Some(&key));
        assert_eq!(
            decode_frame(&plain[..1], 7, None),
            Err(DecodeError::TooShort)
        );
        assert_eq!(
            decode_frame(&plain[..10], 7, None),
            Err(DecodeError::TooShort)
        );
        assert_eq!(
            decode_frame(b"XX0123456789abcdef", 7, None),
            Err(DecodeError::BadMagic)
        );
        let mut v2 = plain.clone();
        v2[2] = 2;
        assert_eq!(
            decode_frame(&v2, 7, None),
            Err(DecodeError::UnknownVersion(2))
        );
        assert_eq!(
            decode_frame(&plain, 8, None),
            Err(DecodeError::OtherTeam(7))
        );
        assert_eq!(
            decode_frame(&plain, 7, Some(&key)),
            Err(DecodeError::MissingTag)
        );
        assert_eq!(
            decode_frame(&tagged, 7, None),
            Err(DecodeError::UnexpectedTag)
        );
        assert_eq!(
            decode_frame(&tagged, 7, Some(&TeamKey::new(b"other"))),
            Err(DecodeError::BadTag)
        );
        let mut flipped = tagged.clone();
        flipped[20] ^= 1;
        assert_eq!(
            decode_frame(&flipped, 7, Some(&key)),
            Err(DecodeError::BadTag)
        );
        let truncated = &plain[..plain.len() - 1];
        assert!(matches!(
            decode_frame(truncated, 7, None),
            Err(DecodeError::Malformed(_))
        ));
        let mut trailing = plain.clone();
        trailing.push(0);
        assert!(matches!(
            decode_frame(&trailing, 7, None),
            Err(DecodeError::Malformed(_))
        ));
        let mut sender0 = plain.clone();
        sender0[5] = 0;
        assert!(matches!(
            decode_frame(&sender0, 7, None),
            Err(DecodeError::Malformed(_))
        ));
        let huge = vec![0u8; MAX_FRAME_LEN + 1];
        assert_eq!(decode_frame(&huge, 7, None), Err(DecodeError::Oversized));
    }

    #[test]
    fn a_bad_path_or_a_huge_claimed_length_is_malformed_not_a_panic_or_an_allocation() {
        let mut w = FrameWriter::new(7, 3, 1, 1, 1200, None);
        w.push(ItemRef::Update {
            path: "a..b",
            value: &Value::Int(1),
            version: 1,
            age_us: 0,
        });
        assert!(matches!(
            decode_frame(&w.finish(), 7, None),
            Err(DecodeError::Malformed(_))
        ));
        // seq 1, then a claimed item count of 2^62.
        let mut bytes = encode_frame(
            &Frame {
                items: vec![],
                ..sample()
            },
            None,
        );
        bytes.truncate(HEADER_LEN);
        bytes.extend_from_slice(&[1, 0xfd, 0, 0, 0, 0, 0, 0, 0, 0x40]);
        assert!(matches!(
            decode_frame(&bytes, 7, None),
            Err(DecodeError::Malformed(_))
        ));
    }

    #[test]
    fn a_world_model_update_fits_the_spl_message_limit_with_a_tag() {
        let key = TeamKey::new(&[7u8; 32]);
        let world = Value::Bytes(vec![0x5a; 40]);
        let mut w = FrameWriter::new(7, 3, u64::MAX, 1 << 31, 1200, Some(&key));
        assert!(w.push(ItemRef::Update {
            path: "world.local",
            value: &world,
            version: 60_000,
            age_us: 40_000,
        }));
        let bytes = w.finish();
        assert!(
            bytes.len() <= 128,
            "world model frame is {} bytes",
            bytes.len()
        );
    }

    #[test]
    fn the_writer_never_exceeds_its_budget() {
        let value = Value::Bytes(vec![1; 100]);
        let mut w = FrameWriter::new(7, 3, 1, 1, 400, None);
        let mut pushed = 0;
        while w.push(ItemRef::Update {
            path: "x",
            value: &value,
            version: 1,
            age_us: 1,
        }) {
            pushed += 1;
        }
        let len = w.len();
        let bytes = w.finish();
        assert_eq!(bytes.len(), len, "len() predicts the finished size");
        assert!(
            bytes.len() <= 400 && bytes.len() > 400 - 110,
            "{} bytes",
            bytes.len()
        );
        assert_eq!(pushed, 3);
    }

    fn any_value() -> impl Strategy<Value = Value> {
        prop_oneof![
            any::<i64>().prop_map(Value::Int),
            any::<f64>()
                .prop_filter("NaN is never equal", |x| !x.is_nan())
                .prop_map(Value::Float),
            any::<bool>().prop_map(Value::Bool),
            ".{0,12}".prop_map(Value::String),
            proptest::collection::vec(-1e6f32..1e6, 0..6).prop_map(Value::Floats),
            proptest::collection::vec(any::<u8>(), 0..48).prop_map(Value::Bytes),
        ]
    }

    fn any_path() -> impl Strategy<Value = String> {
        "[a-z0-9_-]{1,8}(\\.[a-z0-9_-]{1,8}){0,2}"
    }

    pub(crate) fn any_item() -> impl Strategy<Value = Item> {
        prop_oneof![
            (any_path(), any_value(), any::<u64>(), any::<u64>()).prop_map(
                |(path, value, version, age_us)| Item::Update {
                    path,
                    value,
                    version,
                    age_us
                }
            ),
            (any_path(), 1..=MAX_TALK_SEQ, any_value())
                .prop_map(|(queue, seq, value)| Item::Talk { queue, seq, value }),
            (any_path(), 1..MAX_TALK_SEQ / 2, 0..1000u64).prop_map(|(queue, first, n)| {
                Item::TalkHead {
                    queue,
                    first,
                    last: first - 1 + n,
                }
            }),
            (1..=254u8, any_path(), 1..MAX_TALK_SEQ / 2, 0..1000u64).prop_map(
                |(target, queue, first, n)| Item::Nack {
                    target,
                    queue,
                    first,
                    last: first + n
                }
            ),
        ]
    }

    pub(crate) fn any_frame() -> impl Strategy<Value = Frame> {
        (
            any::<u8>(),
            1..=254u8,
            any::<u64>(),
            any::<u64>(),
            proptest::collection::vec(any_item(), 0..8),
        )
            .prop_map(|(team, sender, incarnation, seq, items)| Frame {
                team,
                sender,
                incarnation,
                seq,
                items,
            })
    }

    proptest! {
        #[test]
        fn decode_inverts_encode_for_any_frame(frame in any_frame(), keyed in any::<bool>()) {
            let key = TeamKey::new(b"secret");
            let key = keyed.then_some(&key);
            let bytes = encode_frame(&frame, key);
            prop_assert_eq!(decode_frame(&bytes, frame.team, key), Ok(frame));
        }

        #[test]
        fn computed_item_sizes_match_the_encoder(item in any_item()) {
            let mut sink = Vec::new();
            bincode::encode_into_std_write(item.as_ref(), &mut sink, config()).unwrap();
            prop_assert_eq!(item_len(item.as_ref()), sink.len());
        }

        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
            let _ = decode_frame(&bytes, 7, None);
            let _ = decode_frame(&bytes, 7, Some(&TeamKey::new(b"k")));
        }

        #[test]
        fn corrupted_frames_never_panic(frame in any_frame(), at in any::<usize>(), byte in any::<u8>(), cut in any::<usize>()) {
            let mut bytes = encode_frame(&frame, None);
            let i = at % bytes.len();
            bytes[i] = byte;
            bytes.truncate(cut % (bytes.len() + 1));
            let _ = decode_frame(&bytes, frame.team, None);
        }
    }
}
