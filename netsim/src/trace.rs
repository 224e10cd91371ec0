//! The trace: every event of a run, a stable hash of them, and a text rendering.

use std::fmt;
use std::io::{self, Write};
use std::sync::Arc;

use crate::link::DropReason;
use crate::sim::{Action, Dest, NodeId};
use crate::time::Time;

/// One thing that happened, at global time `at`.
#[derive(Debug, Clone, PartialEq)]
pub struct TraceEvent {
    /// Global time of the event.
    pub at: Time,
    /// What happened.
    pub kind: TraceKind,
}

/// What happened.
#[derive(Debug, Clone, PartialEq)]
pub enum TraceKind {
    /// `from` handed `len` bytes to the network; `tx` numbers transmissions from 0.
    Send {
        /// Transmission number.
        tx: u64,
        /// Sender.
        from: NodeId,
        /// Node or group.
        dest: Dest,
        /// Payload length.
        len: usize,
        /// Stable hash of the payload, so the trace hash covers the contents.
        payload_hash: u64,
    },
    /// The copy of transmission `tx` for `to` was lost.
    Drop {
        /// Transmission number.
        tx: u64,
        /// Sender.
        from: NodeId,
        /// Receiver.
        to: NodeId,
        /// The packet's number on the link `from → to`.
        seq: u64,
        /// Why.
        reason: DropReason,
    },
    /// A copy of transmission `tx` arrived at `to`.
    Deliver {
        /// Transmission number.
        tx: u64,
        /// Sender.
        from: NodeId,
        /// Receiver.
        to: NodeId,
        /// The packet's number on the link `from → to`.
        seq: u64,
        /// Where it was addressed (the receiver or a group).
        dest: Dest,
        /// Global send time.
        sent_at: Time,
        /// Arrival on the receiver's own clock.
        local_at: Time,
        /// Whether this is the extra copy made by duplication.
        duplicate: bool,
        /// The payload (shared, not copied).
        bytes: Arc<[u8]>,
    },
    /// A fault verb was applied.
    Action(Action),
}

/// The events of a run and their running hash.
///
/// The hash folds a fixed little-endian encoding of every event (payloads
/// through their hash at send), so it is the same on every platform and run; it is kept
/// even when recording the events themselves is switched off.
#[derive(Debug, Clone)]
pub struct Trace {
    events: Vec<TraceEvent>,
    recording: bool,
    hash: StableHash,
    count: u64,
}

impl Trace {
    pub(crate) fn new(recording: bool) -> Trace {
        Trace {
            events: Vec::new(),
            recording,
            hash: StableHash::new(),
            count: 0,
        }
    }

    pub(crate) fn set_recording(&mut self, recording: bool) {
        self.recording = recording;
    }

    /// Whether events are being kept (the hash always is).
    pub fn is_recording(&self) -> bool {
        self.recording
    }

    /// The hash of every event so far.
    pub fn hash(&self) -> u64 {
        self.hash.0
    }

    /// How many events happened (recorded or not).
    pub fn event_count(&self) -> u64 {
        self.count
    }

    /// The recorded events.
    pub fn events(&self) -> &[TraceEvent] {
        &self.events
    }

    pub(crate) fn push(&mut self, at: Time, kind: TraceKind) {
        self.count += 1;
        let h = &mut self.hash;
        h.u64(at.as_nanos());
        match &kind {
            TraceKind::Send {
                tx,
                from,
                dest,
                len,
                payload_hash,
            } => {
                h.u8(1)
                    .u64(*tx)
                    .u16(from.0)
                    .dest(*dest)
                    .u64(*len as u64)
                    .u64(*payload_hash);
            }
            TraceKind::Drop {
                tx,
                from,
                to,
                seq,
                reason,
            } => {
                h.u8(2)
                    .u64(*tx)
                    .u16(from.0)
                    .u16(to.0)
                    .u64(*seq)
                    .u8(reason.index() as u8);
            }
            TraceKind::Deliver {
                tx,
                from,
                to,
                seq,
                dest,
                sent_at,
                local_at,
                duplicate,
                ..
            } => {
                h.u8(3).u64(*tx).u16(from.0).u16(to.0).u64(*seq).dest(*dest);
                h.u64(sent_at.as_nanos())
                    .u64(local_at.as_nanos())
                    .u8(u8::from(*duplicate));
            }
            TraceKind::Action(action) => {
                h.u8(4).bytes(action.to_string().as_bytes());
            }
        }
        if self.recording {
            self.events.push(TraceEvent { at, kind });
        }
    }

    /// Writes one text line per recorded event (see [`TraceEvent`]'s `Display`).
    pub fn write_text<W: Write>(&self, mut out: W) -> io::Result<()> {
        for event in &self.events {
            writeln!(out, "{event}")?;
        }
        out.flush()
    }
}

impl fmt::Display for TraceEvent {
    /// One line, e.g. `0.102400000 deliver tx=0 n1->n2 seq=0 via=g1 sent=0.000000000
    /// local=0.102400000 dup=0 len=200`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} ", self.at)?;
        match &self.kind {
            TraceKind::Send {
                tx,
                from,
                dest,
                len,
                payload_hash,
            } => {
                write!(
                    f,
                    "send tx={tx} {from}->{dest} len={len} hash={payload_hash:016x}"
                )
            }
            TraceKind::Drop {
                tx,
                from,
                to,
                seq,
                reason,
            } => {
                write!(f, "drop tx={tx} {from}->{to} seq={seq} reason={reason}")
            }
            TraceKind::Deliver {
                tx,
                from,
                to,
                seq,
                dest,
                sent_at,
                local_at,
                duplicate,
                bytes,
            } => {
                write!(
                    f,
                    "deliver tx={tx} {from}->{to} seq={seq} via={dest} sent={sent_at} \
                     local={local_at} dup={} len={}",
                    u8::from(*duplicate),
                    bytes.len()
                )
            }
            TraceKind::Action(action) => write!(f, "action {action}"),
        }
    }
}

/// A small stable hash over 64-bit little-endian words: each word is folded in with a
/// multiply by the golden-ratio constant and an xor-shift. Same value on every platform
/// and release (a golden test pins it); fast enough to hash every event; not
/// cryptographic, only meant to tell runs apart.
#[derive(Debug, Clone, Copy)]
pub(crate) struct StableHash(u64);

impl StableHash {
    pub(crate) fn new() -> StableHash {
        StableHash(0xcbf2_9ce4_8422_2325)
    }

    fn u64(&mut self, v: u64) -> &mut StableHash {
        let h = (self.0 ^ v).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        self.0 = h ^ (h >> 32);
        self
    }

    pub(crate) fn bytes(&mut self, bytes: &[u8]) -> &mut StableHash {
        let mut words = bytes.chunks_exact(8);
        for w in &mut words {
            self.u64(u64::from_le_bytes(w.try_into().expect("8 bytes")));
        }
        let mut tail = [0u8; 8];
        tail[..words.remainder().len()].copy_from_slice(words.remainder());
        self.u64(u64::from_le_bytes(tail)).u64(bytes.len() as u64)
    }

    fn u8(&mut self, v: u8) -> &mut StableHash {
        self.u64(u64::from(v))
    }

    fn u16(&mut self, v: u16) -> &mut StableHash {
        self.u64(u64::from(v))
    }

    fn dest(&mut self, dest: Dest) -> &mut StableHash {
        match dest {
            Dest::Node(n) => self.u64(u64::from(n.0)),
            Dest::Group(g) => self.u64(1 << 32 | u64::from(g.0)),
        }
    }

    pub(crate) fn finish(&self) -> u64 {
        self.0
    }
}

/// The stable hash of a payload.
pub(crate) fn payload_hash(bytes: &[u8]) -> u64 {
    StableHash::new().bytes(bytes).finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOLDEN_EMPTY: u64 = 0x8603_89c5_7a9c_1205;
    const GOLDEN_TEXT: u64 = 0xdcaa_a8c1_3270_3542;

    #[test]
    fn the_hash_is_pinned_and_sees_every_byte_and_the_length() {
        // Golden values: changing them breaks every stored trace hash.
        assert_eq!(payload_hash(b""), GOLDEN_EMPTY, "{:#x}", payload_hash(b""));
        assert_eq!(
            payload_hash(b"huddle netsim"),
            GOLDEN_TEXT,
            "{:#x}",
            payload_hash(b"huddle netsim")
        );
        assert_ne!(payload_hash(b"a"), payload_hash(b"a\0"), "length is hashed");
        assert_ne!(
            payload_hash(b"huddle netsiM"),
            payload_hash(b"huddle netsim")
        );
    }
}
