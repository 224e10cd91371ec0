//! Reading frames: the plain header is checked first, then the body is decoded and every
//! item validated. Safe on untrusted input.

use thiserror::Error;

use super::auth::TeamKey;
use super::codec;
use super::{
    Echo, Frame, FrameClock, Item, ECHO_LEN, FLAG_ECHO, FLAG_TAGGED, HEADER_LEN, MAGIC,
    MAX_FRAME_LEN, MAX_TALK_SEQ, TAG_LEN, VERSION,
};
use crate::key::{validate_path, ROBOT_IDS};

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
    if flags & !(FLAG_TAGGED | FLAG_ECHO) != 0 {
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
    let stamp_us = u32::from_le_bytes([bytes[14], bytes[15], bytes[16], bytes[17]]);
    let (echo, body) = if flags & FLAG_ECHO != 0 {
        let Some((e, rest)) = body.split_first_chunk::<ECHO_LEN>() else {
            return Err(DecodeError::TooShort);
        };
        if !ROBOT_IDS.contains(&e[0]) {
            return Err(DecodeError::Malformed(format!("echo target {}", e[0])));
        }
        let echo = Echo {
            target: e[0],
            seq16: u16::from_le_bytes([e[1], e[2]]),
            hold_10us: u16::from_le_bytes([e[3], e[4]]),
        };
        (Some(echo), rest)
    } else {
        (None, body)
    };
    let (seq, items, used) = codec::decode_body(body)?;
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
        clock: FrameClock { stamp_us, echo },
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
