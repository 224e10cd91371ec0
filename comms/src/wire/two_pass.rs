//! The decoder as it was before it read a frame in one pass (validate every item, then
//! walk the items again to hand them out), kept word for word as the reference the
//! one-pass decoder is checked against (`one_pass_*` proptests in `tests.rs`).

use super::codec::{Fault, Reader, ITEM_TALK};
use super::decode::DecodeError;
use super::{
    Echo, FrameClock, ItemView, KnownPaths, TeamKey, ECHO_LEN, FLAG_ECHO, FLAG_TAGGED, HEADER_LEN,
    LEGACY_VERSION, MAGIC, MAX_FRAME_LEN, MAX_TALK_SEQ, TAG_LEN, VERSION,
};
use crate::key::{validate_path, ROBOT_IDS};

/// What the old decoder gave: the header fields, the items its second walk handed out,
/// and the count of skipped items.
#[derive(Debug, PartialEq)]
pub(crate) struct Decoded<'a> {
    pub version: u8,
    pub sender: u8,
    pub incarnation: u64,
    pub seq: u64,
    pub clock: FrameClock,
    pub items: Vec<ItemView<'a>>,
    pub skipped: usize,
}

fn readable(version: u8) -> bool {
    version == VERSION || version == LEGACY_VERSION
}

#[derive(Clone, Debug)]
struct Items<'a> {
    r: Reader<'a>,
    legacy: bool,
    known: &'a KnownPaths,
}

impl<'a> Items<'a> {
    fn next_raw(&mut self) -> Option<Result<Option<ItemView<'a>>, DecodeError>> {
        if self.r.is_empty() {
            return None;
        }
        Some(self.read_one())
    }

    fn read_one(&mut self) -> Result<Option<ItemView<'a>>, DecodeError> {
        let ty = self.r.varint().map_err(fault)?;
        if self.legacy {
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

/// The old `decode_frame_with`, then its `items()`.
pub(crate) fn decode<'a>(
    bytes: &'a [u8],
    team: u8,
    key: Option<&TeamKey>,
    known: &'a KnownPaths,
) -> Result<Decoded<'a>, DecodeError> {
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
            Some(Ok(Some(item))) => validate_item(&item)?,
        }
        read += 1;
    }
    if legacy && !items.r.is_empty() {
        let rest = items.r.remaining();
        return Err(DecodeError::Malformed(format!(
            "{rest} bytes after the items"
        )));
    }
    let again = Items {
        r: Reader::new(items_bytes),
        legacy,
        known,
    };
    Ok(Decoded {
        version,
        sender,
        incarnation: u64::from_le_bytes(incarnation),
        seq,
        clock: FrameClock { stamp_us, echo },
        items: again.collect(),
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
