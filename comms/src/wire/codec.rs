//! The body's encoding by bincode 2 (`config::standard()`): the one file that uses
//! bincode (see the module docs for why, and how to leave it). The impls are written by
//! hand so the item and value layouts stay as the format table says.

use bincode::de::{Decode, Decoder};
use bincode::enc::{Encode, Encoder};
use bincode::error::{AllowedEnumVariants, DecodeError as BincodeDecodeError, EncodeError};

use super::{known_path_index, DecodeError, Item, ItemRef, KNOWN_PATHS, MAX_FRAME_LEN};
use crate::value::Value;

fn config() -> impl bincode::config::Config {
    bincode::config::standard().with_limit::<MAX_FRAME_LEN>()
}

/// Appends the encoding of `item` to `out`, an update of a known path as item 4 when
/// `known_paths`; false if it could not be encoded (writing into a `Vec` does not fail).
pub(super) fn encode_item(item: ItemRef<'_>, known_paths: bool, out: &mut Vec<u8>) -> bool {
    if let ItemRef::Update {
        path,
        value,
        version,
        age_us,
    } = item
    {
        if let Some(index) = known_path_index(path).filter(|_| known_paths) {
            let known = KnownUpdate {
                index,
                value,
                version,
                age_us,
            };
            return bincode::encode_into_std_write(known, out, config()).is_ok();
        }
    }
    bincode::encode_into_std_write(item, out, config()).is_ok()
}

/// The indices item 4 may carry.
const KNOWN_PATH_INDICES: AllowedEnumVariants = AllowedEnumVariants::Range {
    min: 0,
    max: KNOWN_PATHS.len() as u32 - 1,
};

/// Item 4: an update whose path is [`KNOWN_PATHS`]`[index]`.
struct KnownUpdate<'a> {
    index: u8,
    value: &'a Value,
    version: u64,
    age_us: u64,
}

impl Encode for KnownUpdate<'_> {
    fn encode<E: Encoder>(&self, e: &mut E) -> Result<(), EncodeError> {
        4u32.encode(e)?;
        u32::from(self.index).encode(e)?;
        self.value.encode(e)?;
        self.version.encode(e)?;
        self.age_us.encode(e)
    }
}

/// Appends `v` as a varint to `out`.
pub(super) fn encode_varint(v: u64, out: &mut Vec<u8>) {
    // Writing a varint into a Vec cannot fail.
    let _ = bincode::encode_into_std_write(v, out, config());
}

/// Decodes a body, `seq` then the items; returns them and the bytes used.
pub(super) fn decode_body(body: &[u8]) -> Result<(u64, Vec<Item>, usize), DecodeError> {
    let ((seq, items), used): ((u64, Vec<Item>), usize) =
        bincode::decode_from_slice(body, config())
            .map_err(|e| DecodeError::Malformed(e.to_string()))?;
    Ok((seq, items, used))
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
            4 => {
                let index = u32::decode(d)?;
                let Some(path) = usize::try_from(index).ok().and_then(|i| KNOWN_PATHS.get(i))
                else {
                    return Err(BincodeDecodeError::UnexpectedVariant {
                        type_name: "known path",
                        allowed: &KNOWN_PATH_INDICES,
                        found: index,
                    });
                };
                Item::Update {
                    path: (*path).to_owned(),
                    value: Value::decode(d)?,
                    version: u64::decode(d)?,
                    age_us: u64::decode(d)?,
                }
            }
            found => {
                return Err(BincodeDecodeError::UnexpectedVariant {
                    type_name: "Item",
                    allowed: &AllowedEnumVariants::Range { min: 0, max: 4 },
                    found,
                })
            }
        })
    }
}
