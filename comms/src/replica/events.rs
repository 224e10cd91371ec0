//! What a replica hands back to its driver: datagrams to send and events to react to.

use std::net::SocketAddr;

use crate::key::Key;
use crate::stats::DropReason;
use crate::value::Value;

/// Where a [`Transmit`] goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Destination {
    /// The team's multicast group (every frame goes there: repairs help every receiver).
    Group,
}

/// A datagram to send.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Transmit {
    /// Where to.
    pub destination: Destination,
    /// The frame, at most `mtu` bytes.
    pub payload: Vec<u8>,
}

/// Something the application may want to react to.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// A stored value was inserted or changed (read it with [`Replica::get`](super::Replica::get)).
    /// Coalesced per key until drained; a refresh with the same value is no change.
    ValueChanged {
        /// The key as stored: `local.var.x` or `n.var.x`.
        key: Key,
    },
    /// The next message of a teammate's talk queue.
    TalkDelivered {
        /// Queue path (`plan` for `n.talk.plan`).
        queue: String,
        /// The sender.
        from: u8,
        /// Its sequence number (per queue and sender incarnation, from 1).
        seq: u64,
        /// The message.
        value: Value,
    },
    /// Messages `first..=last` of a teammate's queue could not be recovered; or, with
    /// `first == last`, one message arrived whose value has a tag this build does not
    /// know (a newer build's): acknowledged, counted in `Stats::talk_unknown_value`, and
    /// skipped here rather than delivered as something else.
    TalkGivenUp {
        /// Queue path.
        queue: String,
        /// The sender.
        from: u8,
        /// First lost sequence number.
        first: u64,
        /// Last lost sequence number.
        last: u64,
    },
    /// A robot was heard for the first time, or again after departing.
    PeerJoined {
        /// Its id.
        robot: u8,
        /// Its incarnation.
        incarnation: u64,
    },
    /// A robot came back with a new incarnation: its values replace the old ones at once.
    PeerRestarted {
        /// Its id.
        robot: u8,
        /// The incarnation it had.
        old_incarnation: u64,
        /// The one it has now.
        new_incarnation: u64,
    },
    /// Two incarnations of one robot id are sending at once: another robot runs with
    /// this id (or a stray frame carried it). Frames of `other` are dropped while
    /// `current` is heard; if `current` falls silent, `other` takes over again.
    IncarnationConflict {
        /// The robot id.
        robot: u8,
        /// The incarnation whose frames are applied.
        current: u64,
        /// The other live one, whose frames are dropped.
        other: u64,
    },
    /// A robot was silent for longer than `departed_after`. Its values stay readable,
    /// marked departed and ageing, for `release_departed_after`, then they are released;
    /// arbitration should ignore stale values by their stamps.
    PeerDeparted {
        /// Its id.
        robot: u8,
    },
    /// A datagram was dropped (also counted in [`Stats`](crate::Stats)).
    FrameDropped {
        /// Its source address.
        from: SocketAddr,
        /// Why.
        reason: DropReason,
    },
}
