//! The body's primitives by bincode 2 (`config::standard()`): the one file that uses
//! bincode (see the module docs for why, and how to leave it). The impls are written by
//! hand so the item and value layouts stay as the format table says.
//!
//! Writing appends to the caller's buffer; reading borrows from the datagram (paths and
//! queues are `&str` into it, values stay encoded until asked for): neither allocates.

use bincode::de::{Decode, Decoder};
use bincode::enc::{Encode, Encoder};
use bincode::error::{AllowedEnumVariants, DecodeError as BincodeDecodeError, EncodeError};

use super::{ItemRef, ItemView, KnownPaths, RawValue, MAX_FRAME_LEN};
use crate::value::Value;

fn config() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<MAX_FRAME_LEN>()
}

/// Item types (the varint before each item; see the module docs' table).
pub(super) const ITEM_UPDATE: u64 = 0;
pub(super) const ITEM_TALK: u64 = 1;
pub(super) const ITEM_TALK_HEAD: u64 = 2;
pub(super) const ITEM_NACK: u64 = 3;
pub(super) const ITEM_KNOWN_UPDATE: u64 = 4;

/// bincode's output straight into the frame's buffer: no `std::io::Write` adapter (and
/// its error plumbing) per primitive written, on every item of every frame.
struct VecWriter<'a>(&'a mut Vec<u8>);

impl bincode::enc::write::Writer for VecWriter<'_> {
    #[inline]
    fn write(&mut self, bytes: &[u8]) -> Result<(), EncodeError> {
        self.0.extend_from_slice(bytes);
        Ok(())
    }
}

/// The largest varint bincode writes as its own single byte.
const SINGLE_BYTE_MAX: u64 = 250;
/// The marker bytes of bincode's wider varints.
const U16_BYTE: u8 = 251;
const U32_BYTE: u8 = 252;
const U64_BYTE: u8 = 253;

/// Appends `v` as a varint to `out`.
#[inline]
pub(super) fn put_varint(v: u64, out: &mut Vec<u8>) {
    // bincode's standard varint, written directly (its encoder's limit check and
    // writer cost more than the bytes): one byte up to 250 (inlined: most varints on
    // the wire), else a marker byte and the value in 2, 4 or 8 little-endian bytes.
    if v <= SINGLE_BYTE_MAX {
        out.push(v as u8);
    } else {
        put_wide_varint(v, out);
    }
}

#[inline(never)]
fn put_wide_varint(v: u64, out: &mut Vec<u8>) {
    if let Ok(v) = u16::try_from(v) {
        out.push(U16_BYTE);
        out.extend_from_slice(&v.to_le_bytes());
    } else if let Ok(v) = u32::try_from(v) {
        out.push(U32_BYTE);
        out.extend_from_slice(&v.to_le_bytes());
    } else {
        out.push(U64_BYTE);
        out.extend_from_slice(&v.to_le_bytes());
    }
}

/// bincode's zigzag mapping of a signed integer onto the varint's unsigned one.
#[inline]
fn zigzag(v: i64) -> u64 {
    if v < 0 {
        !(v as u64) * 2 + 1
    } else {
        (v as u64) * 2
    }
}

/// A string or byte string: its length, then its bytes (as bincode writes `&str`).
#[inline]
fn put_bytes(bytes: &[u8], out: &mut Vec<u8>) {
    put_varint(bytes.len() as u64, out);
    out.extend_from_slice(bytes);
}

/// Appends a value: an integer by hand (the common case on the hot path), the others
/// through bincode. The bytes are bincode's either way (`Value`'s `Encode`).
#[inline]
fn put_value(value: &Value, out: &mut Vec<u8>) {
    match value {
        Value::Int(v) => {
            out.push(0);
            put_varint(zigzag(*v), out);
        }
        other => {
            let _ = bincode::encode_into_writer(other, VecWriter(out), config());
        }
    }
}

/// The type an item goes out as, and its known-path index if it is item 4.
pub(super) fn item_type(item: &ItemRef<'_>, known: &KnownPaths) -> (u64, Option<u8>) {
    match item {
        ItemRef::Update { path, .. } => match known.index(path) {
            Some(i) => (ITEM_KNOWN_UPDATE, Some(i)),
            None => (ITEM_UPDATE, None),
        },
        ItemRef::Talk { .. } => (ITEM_TALK, None),
        ItemRef::TalkHead { .. } => (ITEM_TALK_HEAD, None),
        ItemRef::Nack { .. } => (ITEM_NACK, None),
    }
}

/// An item's fields (everything after its type and length), through bincode: what
/// [`put_fields`] writes by hand, kept as its reference in the tests.
#[cfg(test)]
pub(super) struct Fields<'a> {
    pub(super) item: ItemRef<'a>,
    pub(super) index: Option<u8>,
}

#[cfg(test)]
impl Encode for Fields<'_> {
    fn encode<E: Encoder>(&self, e: &mut E) -> Result<(), EncodeError> {
        match self.item {
            ItemRef::Update {
                path,
                value,
                version,
                age_us,
            } => {
                match self.index {
                    Some(i) => u64::from(i).encode(e)?,
                    None => path.encode(e)?,
                }
                value.encode(e)?;
                version.encode(e)?;
                age_us.encode(e)
            }
            ItemRef::Talk { queue, seq, value } => {
                queue.encode(e)?;
                seq.encode(e)?;
                value.encode(e)
            }
            ItemRef::TalkHead { queue, first, last } => {
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
                target.encode(e)?;
                queue.encode(e)?;
                first.encode(e)?;
                last.encode(e)
            }
        }
    }
}

/// Appends an item: its type, its fields' length `fields_len` when `with_len` (format 4;
/// format 3 items carry none), then the fields.
pub(super) fn put_item(
    item: ItemRef<'_>,
    (ty, index): (u64, Option<u8>),
    fields_len: Option<usize>,
    out: &mut Vec<u8>,
) {
    put_varint(ty, out);
    if let Some(len) = fields_len {
        put_varint(len as u64, out);
    }
    put_fields(item, index, out);
}

/// An item's fields, as bincode writes [`Fields`] (a proptest holds them equal): one
/// call per field instead of bincode's encoder around every primitive.
pub(super) fn put_fields(item: ItemRef<'_>, index: Option<u8>, out: &mut Vec<u8>) {
    match item {
        ItemRef::Update {
            path,
            value,
            version,
            age_us,
        } => {
            match index {
                Some(i) => put_varint(u64::from(i), out),
                None => put_bytes(path.as_bytes(), out),
            }
            put_value(value, out);
            put_varint(version, out);
            put_varint(age_us, out);
        }
        ItemRef::Talk { queue, seq, value } => {
            put_bytes(queue.as_bytes(), out);
            put_varint(seq, out);
            put_value(value, out);
        }
        ItemRef::TalkHead { queue, first, last } => {
            put_bytes(queue.as_bytes(), out);
            put_varint(first, out);
            put_varint(last, out);
        }
        ItemRef::Nack {
            target,
            queue,
            first,
            last,
        } => {
            // bincode writes a `u8` as its byte.
            out.push(target);
            put_bytes(queue.as_bytes(), out);
            put_varint(first, out);
            put_varint(last, out);
        }
    }
}

/// Why bytes being read are not what they should be.
#[derive(Debug)]
pub(super) enum Fault {
    /// Something this build does not know, whose end is not known without the item's
    /// length (an item type, a value type): skipped in format 4, malformed in format 3.
    Unknown,
    /// An item read to its end that this build cannot use (a known-path index beyond its
    /// table): skipped.
    Skip,
    /// Truncated or invalid: the frame is malformed.
    Malformed(&'static str),
}

/// A cursor over bytes being decoded.
#[derive(Clone, Debug)]
pub(super) struct Reader<'a> {
    bytes: &'a [u8],
}

impl<'a> Reader<'a> {
    pub(super) fn new(bytes: &'a [u8]) -> Reader<'a> {
        Reader { bytes }
    }

    pub(super) fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    pub(super) fn remaining(&self) -> usize {
        self.bytes.len()
    }

    #[inline]
    pub(super) fn varint(&mut self) -> Result<u64, Fault> {
        // bincode's varint read directly (a proptest holds it to bincode's reading):
        // one byte inline, the wider ones out of line.
        match self.bytes.split_first() {
            Some((&b, rest)) if u64::from(b) <= SINGLE_BYTE_MAX => {
                self.bytes = rest;
                Ok(u64::from(b))
            }
            _ => self.wide_varint(),
        }
    }

    /// A varint of a marker byte and 2, 4 or 8 bytes; anything else (a u128 marker, too
    /// few bytes, nothing) through bincode, which decides what is an error.
    #[inline(never)]
    fn wide_varint(&mut self) -> Result<u64, Fault> {
        if let Some((&b, rest)) = self.bytes.split_first() {
            let wide = |n: usize| rest.get(..n).map(|w| (w, &rest[n..]));
            let read = match b {
                U16_BYTE => wide(2).map(|(w, r)| (u64::from(u16::from_le_bytes([w[0], w[1]])), r)),
                U32_BYTE => wide(4)
                    .map(|(w, r)| (u64::from(u32::from_le_bytes([w[0], w[1], w[2], w[3]])), r)),
                U64_BYTE => wide(8).map(|(w, r)| {
                    let mut b8 = [0u8; 8];
                    b8.copy_from_slice(w);
                    (u64::from_le_bytes(b8), r)
                }),
                _ => None,
            };
            if let Some((v, rest)) = read {
                self.bytes = rest;
                return Ok(v);
            }
        }
        let (v, used): (u64, usize) = bincode::decode_from_slice(self.bytes, config())
            .map_err(|_| Fault::Malformed("bad varint"))?;
        self.bytes = &self.bytes[used..];
        Ok(v)
    }

    pub(super) fn take(&mut self, n: usize) -> Result<&'a [u8], Fault> {
        if n > self.bytes.len() {
            return Err(Fault::Malformed("truncated"));
        }
        let (head, rest) = self.bytes.split_at(n);
        self.bytes = rest;
        Ok(head)
    }

    fn u8(&mut self) -> Result<u8, Fault> {
        Ok(self.take(1)?[0])
    }

    fn len(&mut self) -> Result<usize, Fault> {
        usize::try_from(self.varint()?).map_err(|_| Fault::Malformed("length"))
    }

    pub(super) fn str(&mut self) -> Result<&'a str, Fault> {
        let n = self.len()?;
        std::str::from_utf8(self.take(n)?).map_err(|_| Fault::Malformed("not UTF-8"))
    }

    /// A value, checked (every byte a valid encoding) but left encoded.
    fn value(&mut self) -> Result<RawValue<'a>, Fault> {
        let start = self.bytes;
        // Writers put the tag in one byte; anything else (another tag, a wider varint)
        // is a value type this build does not know.
        match self.u8()? {
            0 => {
                self.varint()?;
            }
            1 => {
                self.take(8)?;
            }
            2 => {
                if self.u8()? > 1 {
                    return Err(Fault::Malformed("bool"));
                }
            }
            3 => {
                self.str()?;
            }
            4 => {
                let n = self.len()?;
                self.take(n.checked_mul(8).ok_or(Fault::Malformed("length"))?)?;
            }
            5 => {
                let n = self.len()?;
                self.take(n)?;
            }
            // A value type of a newer build.
            _ => return Err(Fault::Unknown),
        }
        Ok(RawValue(&start[..start.len() - self.bytes.len()]))
    }

    /// A talk item whose value has a tag this build does not know (format 4 only, where
    /// the item's length bounds it): queue and seq read, the value left as the rest of
    /// the item's bytes ([`RawValue::value`] is `None`). The message is acknowledged
    /// and handed up as skipped, never retried for ever (see the compatibility promise).
    pub(super) fn talk_of_unknown_value(&mut self) -> Result<ItemView<'a>, Fault> {
        let queue = self.str()?;
        let seq = self.varint()?;
        let value = RawValue(self.take(self.remaining())?);
        Ok(ItemView::Talk { queue, seq, value })
    }

    /// The fields of an item of type `ty`. `Fault::Unknown` for a type or a value type
    /// this build does not know, `Fault::Skip` for a known-path index beyond its table.
    pub(super) fn item(&mut self, ty: u64, known: &'a KnownPaths) -> Result<ItemView<'a>, Fault> {
        Ok(match ty {
            ITEM_UPDATE | ITEM_KNOWN_UPDATE => {
                let path = if ty == ITEM_UPDATE {
                    Ok(self.str()?)
                } else {
                    let index = self.varint()?;
                    known.get(index).ok_or(Fault::Skip)
                };
                let value = self.value()?;
                let version = self.varint()?;
                let age_us = self.varint()?;
                // An index beyond our table is known only once the item was read through.
                ItemView::Update {
                    path: path?,
                    value,
                    version,
                    age_us,
                }
            }
            ITEM_TALK => ItemView::Talk {
                queue: self.str()?,
                seq: self.varint()?,
                value: self.value()?,
            },
            ITEM_TALK_HEAD => ItemView::TalkHead {
                queue: self.str()?,
                first: self.varint()?,
                last: self.varint()?,
            },
            ITEM_NACK => ItemView::Nack {
                target: self.u8()?,
                queue: self.str()?,
                first: self.varint()?,
                last: self.varint()?,
            },
            _ => return Err(Fault::Unknown),
        })
    }
}

/// The value a checked [`RawValue`] holds.
pub(super) fn decode_value(raw: &[u8]) -> Option<Value> {
    // An integer (tag 0, a zigzag varint) by hand; the rest by bincode.
    if let Some((0, rest)) = raw.split_first() {
        let mut r = Reader::new(rest);
        if let Ok(z) = r.varint() {
            if r.is_empty() {
                return Some(Value::Int(((z >> 1) as i64) ^ -((z & 1) as i64)));
            }
        }
    }
    bincode::decode_from_slice::<Value, _>(raw, config())
        .ok()
        .map(|(v, _)| v)
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
            4 => Value::Floats(Vec::<f64>::decode(d)?),
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

#[cfg(test)]
mod hand_tests {
    use super::*;
    use crate::wire::tests::any_item;
    use proptest::prelude::*;

    /// Integers around every width bincode's varint switches at, and small ones.
    fn edgy_u64() -> impl Strategy<Value = u64> {
        prop_oneof![
            0..=300u64,
            proptest::sample::select(vec![
                250,
                251,
                252,
                0xFFFF,
                0x1_0000,
                0xFFFF_FFFF,
                0x1_0000_0000,
                u64::MAX
            ]),
            any::<u64>(),
        ]
    }

    fn edgy_i64() -> impl Strategy<Value = i64> {
        prop_oneof![
            -300..=300i64,
            proptest::sample::select(vec![-126, -125, 125, 126, i64::MIN, i64::MAX]),
            any::<i64>(),
        ]
    }

    fn bincode_bytes(item: ItemRef<'_>, index: Option<u8>) -> Vec<u8> {
        let mut out = Vec::new();
        bincode::encode_into_writer(Fields { item, index }, VecWriter(&mut out), config())
            .expect("a Vec takes anything");
        out
    }

    proptest! {
        /// The hand-written writer gives bincode's bytes for every item: the wire
        /// format did not change with it.
        #[test]
        fn fields_by_hand_are_bincodes(item in any_item(), index in proptest::option::of(0..=250u8)) {
            let mut hand = Vec::new();
            put_fields(item.as_ref(), index, &mut hand);
            prop_assert_eq!(hand, bincode_bytes(item.as_ref(), index));
        }

        /// The same for updates of small integers, versions and ages at every varint
        /// width, which the item strategy above rarely draws.
        #[test]
        fn small_integers_by_hand_are_bincodes(v in edgy_i64(), version in edgy_u64(), age_us in edgy_u64()) {
            let value = Value::Int(v);
            let item = ItemRef::Update { path: "a.b", value: &value, version, age_us };
            let mut hand = Vec::new();
            put_fields(item, None, &mut hand);
            prop_assert_eq!(&hand, &bincode_bytes(item, None));
            // And reading them back by hand gives what bincode reads.
            let mut raw = Vec::new();
            put_value(&value, &mut raw);
            prop_assert_eq!(decode_value(&raw), Some(value));
            let via_bincode: Value = bincode::decode_from_slice(&raw, config()).unwrap().0;
            prop_assert_eq!(via_bincode, Value::Int(v));
            let mut varint = Vec::new();
            put_varint(version, &mut varint);
            let mut r = Reader::new(&varint);
            prop_assert_eq!(r.varint().ok(), Some(version));
            prop_assert!(r.is_empty());
        }

        /// Any bytes read as a varint by hand read as bincode reads them (the fast path
        /// takes one byte below 251 only; the rest is bincode's).
        #[test]
        fn varints_read_by_hand_are_bincodes(bytes in marked_bytes()) {
            let by_bincode: Option<(u64, usize)> = bincode::decode_from_slice(&bytes, config()).ok();
            let mut r = Reader::new(&bytes);
            let by_hand = r.varint().ok().map(|v| (v, bytes.len() - r.remaining()));
            prop_assert_eq!(by_hand, by_bincode);
        }

        /// Any bytes read as a value read as bincode reads them.
        #[test]
        fn values_read_by_hand_are_bincodes(tail in marked_bytes(), tag in 0..8u8) {
            let mut bytes = vec![tag];
            bytes.extend(tail);
            let by_bincode: Option<Value> =
                bincode::decode_from_slice(&bytes, config()).ok().map(|(v, _)| v);
            // Debug text: a NaN read both ways is the same NaN.
            prop_assert_eq!(format!("{:?}", decode_value(&bytes)), format!("{by_bincode:?}"));
        }
    }

    /// Bytes that start with each of bincode's varint markers often (and anything).
    fn marked_bytes() -> impl Strategy<Value = Vec<u8>> {
        let first = prop_oneof![
            proptest::sample::select(vec![250u8, 251, 252, 253, 254, 255]),
            any::<u8>()
        ];
        (first, proptest::collection::vec(any::<u8>(), 0..12)).prop_map(|(b, mut rest)| {
            rest.insert(0, b);
            rest
        })
    }
}
