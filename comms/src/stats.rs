//! Counters a replica keeps about its traffic, and what it knows about its peers.

use std::collections::BTreeMap;
use std::fmt;
use std::time::Duration;

use crate::time::Instant;
use crate::wire::DecodeError;

/// Why a received datagram was not applied.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum DropReason {
    /// Shorter than a header (or a tag).
    TooShort,
    /// Longer than the configured MTU.
    Oversized,
    /// Not a huddle frame.
    BadMagic,
    /// A format version this build does not speak.
    UnknownVersion,
    /// Another team's frame.
    OtherTeam,
    /// A team key is configured but the frame has no tag.
    MissingTag,
    /// The frame has a tag but no team key is configured.
    UnexpectedTag,
    /// Wrong tag: another key, or an altered frame.
    BadTag,
    /// Undecodable body, bad sender id or bad path.
    Malformed,
    /// With a team key: a frame seen before, or too old, from the current incarnation.
    Replay,
    /// From an incarnation of a robot that has since restarted.
    RetiredIncarnation,
    /// Carries this robot's id but another incarnation: two robots share an id.
    RobotIdConflict,
}

impl DropReason {
    /// Every reason, in stats order.
    pub const ALL: [DropReason; 12] = [
        DropReason::TooShort,
        DropReason::Oversized,
        DropReason::BadMagic,
        DropReason::UnknownVersion,
        DropReason::OtherTeam,
        DropReason::MissingTag,
        DropReason::UnexpectedTag,
        DropReason::BadTag,
        DropReason::Malformed,
        DropReason::Replay,
        DropReason::RetiredIncarnation,
        DropReason::RobotIdConflict,
    ];

    /// The name used in `local.var.huddle.stats.drops.<name>`.
    pub fn name(self) -> &'static str {
        match self {
            DropReason::TooShort => "too_short",
            DropReason::Oversized => "oversized",
            DropReason::BadMagic => "bad_magic",
            DropReason::UnknownVersion => "unknown_version",
            DropReason::OtherTeam => "other_team",
            DropReason::MissingTag => "missing_tag",
            DropReason::UnexpectedTag => "unexpected_tag",
            DropReason::BadTag => "bad_tag",
            DropReason::Malformed => "malformed",
            DropReason::Replay => "replay",
            DropReason::RetiredIncarnation => "retired_incarnation",
            DropReason::RobotIdConflict => "robot_id_conflict",
        }
    }

    fn index(self) -> usize {
        self as usize
    }
}

impl From<&DecodeError> for DropReason {
    fn from(e: &DecodeError) -> DropReason {
        match e {
            DecodeError::TooShort => DropReason::TooShort,
            DecodeError::Oversized => DropReason::Oversized,
            DecodeError::BadMagic => DropReason::BadMagic,
            DecodeError::UnknownVersion(_) => DropReason::UnknownVersion,
            DecodeError::OtherTeam(_) => DropReason::OtherTeam,
            DecodeError::MissingTag => DropReason::MissingTag,
            DecodeError::UnexpectedTag => DropReason::UnexpectedTag,
            DecodeError::BadTag => DropReason::BadTag,
            DecodeError::Malformed(_) => DropReason::Malformed,
        }
    }
}

impl fmt::Display for DropReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Traffic counters of one replica.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stats {
    /// Datagrams handed to `handle_datagram`, good or bad.
    pub frames_in: u64,
    /// Their bytes.
    pub bytes_in: u64,
    /// Frames produced by `poll_transmit`.
    pub frames_out: u64,
    /// Their bytes.
    pub bytes_out: u64,
    /// This robot's own frames looped back by multicast (ignored, not dropped).
    pub own_frames: u64,
    /// Items of received frames skipped as unknown (a newer build's item type, value type
    /// or known path; see the wire module's "Unknown items"): the rest of the frame was
    /// applied.
    pub items_skipped: u64,
    /// Updates that changed or refreshed a stored value.
    pub updates_applied: u64,
    /// Updates older than the stored version (ignored).
    pub updates_stale: u64,
    /// Updates of new keys refused because the sender (or all teammates together) has
    /// as many bindings as the limits allow.
    pub updates_refused: u64,
    /// Stored versions their owner never re-sent, replaced by the lower versions it
    /// keeps sending (a forged or corrupted version).
    pub updates_unconfirmed_replaced: u64,
    /// Bindings an owner's older incarnation left, removed when its new one published.
    pub bindings_superseded: u64,
    /// Bindings of departed robots released after the grace period.
    pub bindings_released: u64,
    /// Talk messages delivered.
    pub talk_delivered: u64,
    /// Talk messages given up.
    pub talk_given_up: u64,
    /// Talk messages whose value has a tag this build does not know (a newer build's):
    /// acknowledged and handed up as `TalkGivenUp` for that one seq, not delivered.
    pub talk_unknown_value: u64,
    /// Talk messages re-sent on request.
    pub talk_resent: u64,
    /// NACK items sent.
    pub nacks_sent: u64,
    /// NACK items not sent because the bytes heard from their sender did not pay for them
    /// (`talk::AMPLIFICATION`).
    pub nacks_limited: u64,
    /// NACK items dropped while waiting for a frame: replaced by a newer NACK of the same
    /// queue, or beyond `talk::NACKS_WAITING_MAX`.
    pub nacks_superseded: u64,
    /// Talk items ignored because the sender has too many queues.
    pub talk_queue_overflow: u64,
    /// Talk items refused as implausible (a head spanning or jumping too far, a message
    /// beyond the reorder window) or over the reorder buffers' byte bounds.
    pub talk_refused: u64,
    /// Own posts refused because the queue's retention was full of recent messages.
    pub talk_refused_full: u64,
    /// Re-sends not made because the queue's repair allowance was spent.
    pub talk_repair_limited: u64,
    /// Times two live incarnations of one robot id were heard (reported at most once a
    /// second per pair): a second robot runs with a teammate's id.
    pub id_conflicts: u64,
    /// Echoes of this robot's frames used for a teammate's clock estimate.
    pub clock_samples: u64,
    /// Echoes refused: naming a frame not sent recently, or a round trip below zero or
    /// over a second.
    pub clock_echoes_rejected: u64,
    /// Echoes that disagreed with the estimate by more than their round trip allows.
    pub clock_outliers: u64,
    /// Frames whose send stamp gave an impossible transit (far below zero or over a
    /// second): stamped with the default transit instead.
    pub clock_stamps_implausible: u64,
    /// Frames stamped with the default transit because no estimate existed yet (or
    /// `clock_sync` is off).
    pub transit_defaulted: u64,
    /// Last time each robot was heard (on this robot's clock).
    pub last_heard: BTreeMap<u8, Instant>,
    drops: [u64; DropReason::ALL.len()],
}

impl Stats {
    /// Datagrams dropped for `reason`.
    pub fn drops(&self, reason: DropReason) -> u64 {
        self.drops[reason.index()]
    }

    /// Datagrams dropped for any reason.
    pub fn drops_total(&self) -> u64 {
        self.drops.iter().sum()
    }

    pub(crate) fn count_drop(&mut self, reason: DropReason) {
        self.drops[reason.index()] += 1;
    }
}

/// What this robot knows about a teammate.
#[derive(Clone, Debug, PartialEq)]
pub struct PeerInfo {
    /// Its robot id.
    pub robot: u8,
    /// Its current incarnation.
    pub incarnation: u64,
    /// When a valid frame from it last arrived (this robot's clock).
    pub last_heard: Instant,
    /// Heard within the `departed_after` limit.
    pub present: bool,
    /// Valid frames received from it.
    pub frames: u64,
    /// An older incarnation of this id is sending beside the current one (two robots
    /// share the id), as of its last frames.
    pub conflicting: bool,
    /// Its clock minus this robot's now, in microseconds, as estimated from echoes
    /// (modulo 2^32 µs, read as signed: ±35 minutes); `None` before the first echo.
    /// Diagnostics only: values are stamped through it, never compared with it.
    pub clock_offset_us: Option<i64>,
    /// The fitted drift of its clock against this robot's, ppm.
    pub clock_drift_ppm: Option<f64>,
    /// The shortest round trip among the estimate's recent samples.
    pub round_trip: Option<Duration>,
    /// Echo samples that went into the estimate (this life of the peer).
    pub clock_samples: u64,
    /// Its clock minus this robot's from its frames' send stamps alone, µs (modulo 2^32,
    /// read as signed): the median of its last few frames' stamp − reception, early by
    /// a typical transit. Coarser than [`PeerInfo::clock_offset_us`] (milliseconds to
    /// tens of them) but there from its first frame, where echoes are sparse (a
    /// league's budget); not extrapolated, so it stands still while it is not heard.
    pub clock_offset_one_way_us: Option<i64>,
}
