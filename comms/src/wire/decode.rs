//! Reading frames: the plain header is checked first, then the body is decoded and every
//! item validated. Safe on untrusted input.

use thiserror::Error;

use super::auth::TeamKey;
use super::codec::{Fault, Reader, ITEM_TALK};
use super::{
    Echo, Frame, FrameClock, ItemView, KnownPaths, ECHO_LEN, FLAG_ECHO, FLAG_TAGGED, HEADER_LEN,
    LEGACY_VERSION, MAGIC, MAX_FRAME_LEN, MAX_TALK_SEQ, TAG_LEN, VERSION,
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
    if header[..2] != MAGIC || !readable(header[2]) || header[4] != team {
        return None;
    }
    let mut incarnation = [0u8; 8];
    incarnation.copy_from_slice(&header[6..14]);
    Some((header[5], u64::from_le_bytes(incarnation)))
}

fn readable(version: u8) -> bool {
    version == VERSION || version == LEGACY_VERSION
}

/// A received frame, checked and validated, borrowing the datagram (see the module docs).
#[derive(Clone, Debug)]
pub struct FrameRef<'a> {
    /// The format version it came in ([`VERSION`] or [`LEGACY_VERSION`]).
    pub version: u8,
    /// Team id.
    pub team: u8,
    /// Sending robot (1..=254).
    pub sender: u8,
    /// Sender's incarnation.
    pub incarnation: u64,
    /// Sender's frame counter.
    pub seq: u64,
    /// The sender's send stamp and echo.
    pub clock: FrameClock,
    items: &'a [u8],
    known: &'a KnownPaths,
    skipped: usize,
}

impl<'a> FrameRef<'a> {
    /// The items this build can read, in frame order (validated already: iterating
    /// cannot fail).
    pub fn items(&self) -> Items<'a> {
        Items {
            r: Reader::new(self.items),
            legacy: self.version == LEGACY_VERSION,
            known: self.known,
        }
    }

    /// Items skipped: of a type, with a value type, or of a known-path index this build
    /// does not know (see "Unknown items" in the module docs).
    pub fn skipped(&self) -> usize {
        self.skipped
    }

    /// An owned copy (unknown items left out).
    pub fn to_frame(&self) -> Frame {
        Frame {
            team: self.team,
            sender: self.sender,
            incarnation: self.incarnation,
            seq: self.seq,
            clock: self.clock,
            // A talk message whose value this build cannot decode is left out too.
            items: self
                .items()
                .filter(|i| !matches!(i, ItemView::Talk { value, .. } if value.value().is_none()))
                .map(|i| i.to_item())
                .collect(),
        }
    }
}

/// The readable items of a [`FrameRef`].
#[derive(Clone, Debug)]
pub struct Items<'a> {
    r: Reader<'a>,
    legacy: bool,
    known: &'a KnownPaths,
}

impl<'a> Items<'a> {
    /// The next item: `Some(Ok(None))` for one skipped, `None` at the end.
    fn next_raw(&mut self) -> Option<Result<Option<ItemView<'a>>, DecodeError>> {
        if self.r.is_empty() {
            return None;
        }
        Some(self.read_one())
    }

    fn read_one(&mut self) -> Result<Option<ItemView<'a>>, DecodeError> {
        let ty = self.r.varint().map_err(fault)?;
        if self.legacy {
            // No length: nothing can be skipped.
            return match self.r.item(ty, self.known) {
                Ok(item) => Ok(Some(item)),
                Err(Fault::Skip) => Ok(None),
                Err(Fault::Unknown) => Err(DecodeError::Malformed(format!(
                    "format 3 item of type {ty}, or a value or known path this build lacks"
                ))),
                Err(e) => Err(fault(e)),
            };
        }
        let len = self.r.varint().map_err(fault)?;
        let len = usize::try_from(len)
            .ok()
            .filter(|&n| n <= self.r.remaining())
            .ok_or_else(|| DecodeError::Malformed(format!("item of {len} bytes past the body")))?;
        let bytes = self.r.take(len).map_err(fault)?;
        let mut fields = Reader::new(bytes);
        match fields.item(ty, self.known) {
            // Bytes after the fields we know: a newer build's added fields.
            Ok(item) => Ok(Some(item)),
            // A talk message with a value tag this build lacks: read as a message it
            // cannot decode (acknowledged, handed up as skipped), not skipped unseen.
            Err(Fault::Unknown) if ty == ITEM_TALK => Reader::new(bytes)
                .talk_of_unknown_value()
                .map(Some)
                .map_err(fault),
            Err(Fault::Unknown | Fault::Skip) => Ok(None),
            Err(e) => Err(fault(e)),
        }
    }
}

impl<'a> Iterator for Items<'a> {
    type Item = ItemView<'a>;

    fn next(&mut self) -> Option<ItemView<'a>> {
        loop {
            match self.next_raw()? {
                Ok(Some(item)) => return Some(item),
                Ok(None) => continue,
                // Validated when the frame was decoded: cannot happen.
                Err(_) => return None,
            }
        }
    }
}

fn fault(f: Fault) -> DecodeError {
    match f {
        Fault::Unknown | Fault::Skip => DecodeError::Malformed("unknown item".into()),
        Fault::Malformed(what) => DecodeError::Malformed(what.into()),
    }
}

/// Decodes and validates a frame addressed to `team` into an owned [`Frame`], with no
/// known paths (updates by index are skipped): for tools and tests. See
/// [`decode_frame_with`].
pub fn decode_frame(bytes: &[u8], team: u8, key: Option<&TeamKey>) -> Result<Frame, DecodeError> {
    decode_frame_with(bytes, team, key, KnownPaths::none()).map(|f| f.to_frame())
}

/// Decodes and validates a frame addressed to `team`; with `key`, it must carry a valid
/// tag, and without one it must carry none; updates by index are read with `known`.
/// Every item is validated before this returns; [`FrameRef::items`] walks them again.
/// Safe on untrusted input; allocates nothing unless the frame is malformed. A receiver
/// that applies every item reads the frame once with [`decode_frame_into`].
pub fn decode_frame_with<'a>(
    bytes: &'a [u8],
    team: u8,
    key: Option<&TeamKey>,
    known: &'a KnownPaths,
) -> Result<FrameRef<'a>, DecodeError> {
    decode(bytes, team, key, known, |_| {})
}

/// [`decode_frame_with`] in one pass: the readable items, validated, are also put in
/// `items` (cleared first, and left empty if the frame is malformed, so a malformed frame
/// hands out nothing), in frame order. A receiver that keeps one `items` allocates nothing
/// per frame, and each item is read once instead of validated and then read again.
pub fn decode_frame_into<'a>(
    bytes: &'a [u8],
    team: u8,
    key: Option<&TeamKey>,
    known: &'a KnownPaths,
    items: &mut Vec<ItemView<'a>>,
) -> Result<FrameRef<'a>, DecodeError> {
    items.clear();
    let frame = decode(bytes, team, key, known, |item| items.push(item));
    if frame.is_err() {
        items.clear();
    }
    frame
}

/// The header, then every item read, validated and handed to `each` in one walk.
fn decode<'a>(
    bytes: &'a [u8],
    team: u8,
    key: Option<&TeamKey>,
    known: &'a KnownPaths,
    mut each: impl FnMut(ItemView<'a>),
) -> Result<FrameRef<'a>, DecodeError> {
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
    let version = bytes[2];
    if !readable(version) {
        return Err(DecodeError::UnknownVersion(version));
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
    let mut r = Reader::new(body);
    let seq = r.varint().map_err(fault)?;
    let legacy = version == LEGACY_VERSION;
    let count = if legacy {
        Some(r.varint().map_err(fault)?)
    } else {
        None
    };
    let items_bytes = body.get(body.len() - r.remaining()..).unwrap_or_default();
    let mut items = Items { r, legacy, known };
    // Every item is checked before the frame is returned: a malformed frame applies
    // nothing (what `each` was given is the caller's to discard).
    let (mut read, mut skipped) = (0u64, 0usize);
    loop {
        if count.is_some_and(|c| read == c) {
            break;
        }
        match items.next_raw() {
            None if count.is_some() => {
                return Err(DecodeError::Malformed(format!(
                    "{read} of {} items",
                    count.unwrap_or_default()
                )))
            }
            None => break,
            Some(Err(e)) => return Err(e),
            Some(Ok(None)) => skipped += 1,
            Some(Ok(Some(item))) => {
                validate_item(&item)?;
                each(item);
            }
        }
        read += 1;
    }
    if legacy && !items.r.is_empty() {
        let rest = items.r.remaining();
        return Err(DecodeError::Malformed(format!(
            "{rest} bytes after the items"
        )));
    }
    Ok(FrameRef {
        version,
        team,
        sender,
        incarnation: u64::from_le_bytes(incarnation),
        seq,
        clock: FrameClock { stamp_us, echo },
        items: items_bytes,
        known,
        skipped,
    })
}

fn validate_item(item: &ItemView<'_>) -> Result<(), DecodeError> {
    let bad_path = |e: crate::KeyError| DecodeError::Malformed(e.to_string());
    match *item {
        ItemView::Update { path, .. } => validate_path(path).map_err(bad_path),
        ItemView::Talk { queue, seq, .. } => {
            validate_path(queue).map_err(bad_path)?;
            if seq == 0 || seq > MAX_TALK_SEQ {
                return Err(DecodeError::Malformed(format!("talk seq {seq}")));
            }
            Ok(())
        }
        ItemView::TalkHead { queue, first, last } => {
            validate_path(queue).map_err(bad_path)?;
            if first == 0 || first > last.saturating_add(1) || last > MAX_TALK_SEQ {
                return Err(DecodeError::Malformed(format!("talk head {first}..{last}")));
            }
            Ok(())
        }
        ItemView::Nack {
            target,
            queue,
            first,
            last,
        } => {
            validate_path(queue).map_err(bad_path)?;
            if !ROBOT_IDS.contains(&target) || first == 0 || first > last || last > MAX_TALK_SEQ {
                return Err(DecodeError::Malformed(format!(
                    "nack {target} {first}..{last}"
                )));
            }
            Ok(())
        }
    }
}
