//! The peer table: every robot heard, its current incarnation and the older ones still
//! remembered, when it was last heard, its talk inboxes, and the replay window that keyed
//! teams check every frame against.
//!
//! # Incarnations are ordered
//!
//! A replica's incarnation is chosen at start so that a later start of the same robot has
//! a larger one (the driver puts the start time in the high bits; see
//! [`Replica::new`](super::Replica::new)). So "newer" is decided without history:
//!
//! - a frame from a **larger** incarnation is a restart: it becomes current at once;
//! - a frame from a **smaller** incarnation never changes a value, delivers talk, or
//!   retires the current incarnation. It is dropped (`retired_incarnation`). If it is
//!   *fresh* (its sequence number is beyond anything heard from that incarnation), two
//!   robots are sending with one id: that is reported ([`Event::IncarnationConflict`],
//!   `id_conflicts`), and once the current incarnation has been silent for
//!   `departed_after` while the older one keeps sending fresh frames, the older one is
//!   current again. A duplicate that leaves, or one stray frame with a forged large
//!   incarnation, therefore costs the real robot at most `departed_after` and a few frames.
//!   Without a key the same holds for a life never heard before (a robot whose clock went
//!   back at boot comes back that way); with a key only a life this receiver once took as
//!   current may be current again, so a replay of a life it never took changes nothing.
//!
//! A receiver that has never heard a robot accepts the first incarnation it hears, even an
//! old one replayed, and only until it hears a larger one. With a team key a replayed frame
//! of an older incarnation can change nothing at a receiver that has heard the current
//! one: its sequence number is not fresh (the receiver tracks the highest heard of each
//! remembered incarnation), and an incarnation it never heard is smaller than the current.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use crate::stats::{DropReason, PeerInfo};
use crate::talk::Inbox;
use crate::time::Instant;

use super::clock::PeerClock;
use super::{Event, Replica};

/// The incarnation of a replica started at `start_ms` (milliseconds on a clock that does
/// not go back between two starts of the robot, e.g. the Unix time) with 16 bits of
/// `random` below, so two starts in one millisecond still differ: a later start has a
/// larger incarnation.
pub fn ordered_incarnation(start_ms: u64, random: u64) -> u64 {
    (start_ms << 16) | (random & 0xffff)
}

/// How many of a peer's older incarnations are remembered (for conflict detection and to
/// know their highest sequence numbers).
const OLDER_INCARNATIONS: usize = 8;

/// Fresh frames an older, still-live incarnation must send in a row before it is current
/// again after the current one fell silent.
const FRESH_FRAMES_TO_RETURN: u32 = 3;

/// A sender whose frame numbers are past this when first heard has been running for a
/// while (it sends at least one frame per refresh period: 64 frames is over 6 s at the
/// default 100 ms): this robot met it mid-life and does not take its talk history as new.
/// A younger sender's queues are delivered from their first message.
const YOUNG_SENDER_FRAMES: u64 = 64;

/// How often one conflict between two live incarnations is reported again.
const CONFLICT_REPORT_EVERY: Duration = Duration::from_secs(1);

/// Replay protection: the highest sequence number seen and a 64-frame window below it.
#[derive(Debug, Default)]
pub(super) struct ReplayWindow {
    highest: u64,
    seen: u64,
}

impl ReplayWindow {
    fn accept(&mut self, seq: u64) -> bool {
        if seq > self.highest {
            let shift = seq - self.highest;
            self.seen = if shift >= 64 { 0 } else { self.seen << shift };
            self.seen |= 1;
            self.highest = seq;
            return true;
        }
        let back = self.highest - seq;
        if back >= 64 || self.seen & (1 << back) != 0 {
            return false;
        }
        self.seen |= 1 << back;
        true
    }
}

/// An incarnation of a peer that is not (or no longer) its current one.
#[derive(Debug, Clone)]
struct OlderLife {
    incarnation: u64,
    /// Highest frame sequence number heard from it.
    highest_seq: u64,
    last_heard: Instant,
    /// Fresh frames heard in a row without a silence of `departed_after`.
    fresh: u32,
    /// When a conflict with the current incarnation was last reported.
    reported: Option<Instant>,
    /// It was this receiver's current life of the peer once (not only heard beside one).
    was_current: bool,
    /// Frames of it a pooled budget counts: what was counted while it was current here
    /// (0 for a life only heard beside the current one: a replay proves nothing).
    counted: u64,
}

#[derive(Debug)]
pub(super) struct Peer {
    incarnation: u64,
    /// Highest frame sequence number heard from the current incarnation.
    highest_seq: u64,
    older: VecDeque<OlderLife>,
    pub(super) last_heard: Instant,
    pub(super) present: bool,
    frames: u64,
    /// Frames admitted from the current life.
    life_frames: u64,
    replay: ReplayWindow,
    pub(super) inboxes: BTreeMap<String, Inbox>,
    /// Until then, queues first heard start at the sender's current position: this robot
    /// met the peer mid-life and the older messages were for the team as it was then.
    pub(super) catch_up_until: Option<Instant>,
    /// The last time an older incarnation was heard live beside the current one.
    conflict_at: Option<Instant>,
    /// Echo bookkeeping and the estimate of its clock (of the current life).
    pub(super) clock: PeerClock,
    /// Bytes of NACKs this robot may still send about its queues, and bytes of re-sends
    /// its NACKs may still cause ([`crate::talk::AMPLIFICATION`] per byte heard from it).
    pub(super) nack_credit: f64,
    pub(super) repair_credit: f64,
    /// Its last frame was in format 3 ([`crate::wire::LEGACY_VERSION`]): an older build
    /// that cannot read format 4, so frames go out in format 3 while it is present.
    pub(super) legacy_format: bool,
}

impl Peer {
    /// An older incarnation was heard live beside the current one within `live_within`
    /// of its last frame: two robots send with one id.
    pub(super) fn conflicting(&self, live_within: Duration) -> bool {
        self.conflict_at
            .is_some_and(|t| self.last_heard.saturating_duration_since(t) < live_within)
    }

    /// Frames this peer has sent as a pooled budget counts them: its current life's
    /// counter, and what was counted of each earlier life while it was current here. A
    /// counter is the sender's word, so it counts for at most twice the frames of that
    /// life actually heard, plus four (losses of up to half a teammate's frames are still
    /// counted in full): a forged frame with a huge counter, or one replayed frame of an
    /// earlier life (never current here: it proves nothing), cannot use up the team's
    /// budget. What a spoofer can still claim (without a key, or by replaying a whole
    /// recorded life) the budget survives by its floor: see [`super::Budget`].
    pub(super) fn frames_sent(&self) -> u64 {
        let older: u64 = self.older.iter().map(|o| o.counted).sum();
        self.current_counted().saturating_add(older)
    }

    fn current_counted(&self) -> u64 {
        self.highest_seq
            .min(self.life_frames.saturating_mul(2).saturating_add(4))
    }

    fn new(now: Instant, incarnation: u64, seq: u64, catch_up_until: Option<Instant>) -> Peer {
        Peer {
            incarnation,
            highest_seq: seq,
            older: VecDeque::new(),
            last_heard: now,
            present: true,
            frames: 0,
            life_frames: 0,
            replay: ReplayWindow::default(),
            inboxes: BTreeMap::new(),
            catch_up_until,
            conflict_at: None,
            clock: PeerClock::default(),
            nack_credit: 0.0,
            repair_credit: 0.0,
            legacy_format: false,
        }
    }

    /// Makes `incarnation` current; the current one joins the older ones.
    fn switch_to(&mut self, now: Instant, incarnation: u64, seq: u64) -> u64 {
        let old = self.incarnation;
        let life = OlderLife {
            incarnation: self.incarnation,
            highest_seq: self.highest_seq,
            last_heard: self.last_heard,
            fresh: 0,
            reported: None,
            was_current: true,
            counted: self.current_counted(),
        };
        // A life coming back keeps what was counted of it.
        let returning = self
            .older
            .iter()
            .find(|l| l.incarnation == incarnation)
            .map_or(0, |l| l.counted);
        self.older.retain(|l| l.incarnation != incarnation);
        self.older.push_front(life);
        self.older.truncate(OLDER_INCARNATIONS);
        self.incarnation = incarnation;
        self.highest_seq = seq;
        self.life_frames = returning;
        self.replay = ReplayWindow::default();
        // A new life restarts its clock's origin (and its frame numbers).
        self.clock = PeerClock::default();
        self.present = true;
        self.last_heard = now;
        old
    }
}

/// What to do with a frame of an incarnation older than the current one.
enum Older {
    /// Drop it; `conflict` names an incarnation heard live beside the current one.
    Drop { conflict: Option<u64> },
    /// The current incarnation fell silent and this live one takes over again.
    Return,
}

impl Replica {
    /// Every robot heard so far.
    pub fn peers(&self) -> impl Iterator<Item = PeerInfo> + '_ {
        let live_within = self.cfg.departed_after;
        self.peers.iter().map(move |(&robot, p)| PeerInfo {
            robot,
            incarnation: p.incarnation,
            last_heard: p.last_heard,
            present: p.present,
            frames: p.frames,
            conflicting: p.conflicting(live_within),
            clock_offset_us: p.clock.estimate.offset_us(self.now),
            clock_drift_ppm: p.clock.estimate.drift_ppm(),
            round_trip: p.clock.estimate.min_round_trip(),
            clock_samples: p.clock.estimate.samples(),
            clock_offset_one_way_us: p.clock.one_way_offset_us(),
        })
    }

    /// Peer bookkeeping for a valid frame: join, restart, older incarnations, replay check.
    pub(super) fn admit(
        &mut self,
        now: Instant,
        sender: u8,
        incarnation: u64,
        seq: u64,
    ) -> Result<(), DropReason> {
        let keyed = self.key.is_some();
        let departed_after = self.cfg.departed_after;
        let mut joined = true;
        let catch_up = Some(now + departed_after);
        let peer = match self.peers.get_mut(&sender) {
            None => {
                let catch_up = catch_up.filter(|_| seq > YOUNG_SENDER_FRAMES);
                self.events.push_back(Event::PeerJoined {
                    robot: sender,
                    incarnation,
                });
                self.peers
                    .entry(sender)
                    .or_insert(Peer::new(now, incarnation, seq, catch_up))
            }
            Some(peer) if incarnation > peer.incarnation => {
                // A restart this robot witnessed: the new life's queues start at 1.
                self.switch_life(now, sender, incarnation, seq, None)
            }
            Some(peer) if incarnation < peer.incarnation => {
                match Self::older_frame(peer, now, departed_after, keyed, incarnation, seq) {
                    Older::Drop { conflict } => {
                        if let Some(live) = conflict {
                            self.stats.id_conflicts += 1;
                            self.events.push_back(Event::IncarnationConflict {
                                robot: sender,
                                current: peer.incarnation,
                                other: live,
                            });
                        }
                        return Err(DropReason::RetiredIncarnation);
                    }
                    // Its queues went on while it was not current here.
                    Older::Return => self.switch_life(now, sender, incarnation, seq, catch_up),
                }
            }
            Some(peer) => {
                joined = !peer.present;
                if joined {
                    peer.present = true;
                    self.events.push_back(Event::PeerJoined {
                        robot: sender,
                        incarnation,
                    });
                }
                peer
            }
        };
        if keyed && !peer.replay.accept(seq) {
            return Err(DropReason::Replay);
        }
        peer.highest_seq = peer.highest_seq.max(seq);
        peer.last_heard = now;
        peer.frames += 1;
        peer.life_frames += 1;
        self.stats.last_heard.insert(sender, now);
        if joined {
            self.refresh_for_newcomer(now);
        }
        Ok(())
    }

    /// Makes `incarnation` the current life of `sender` (a restart, or an older life
    /// back): the old life's queues are flushed, the switch reported.
    fn switch_life(
        &mut self,
        now: Instant,
        sender: u8,
        incarnation: u64,
        seq: u64,
        catch_up_until: Option<Instant>,
    ) -> &mut Peer {
        let peer = self.peers.get_mut(&sender).expect("a known peer");
        let old = peer.switch_to(now, incarnation, seq);
        peer.catch_up_until = catch_up_until;
        self.flush_inboxes_of(sender);
        self.events.push_back(Event::PeerRestarted {
            robot: sender,
            old_incarnation: old,
            new_incarnation: incarnation,
        });
        self.peers.get_mut(&sender).expect("a known peer")
    }

    /// A frame of an incarnation older than `peer`'s current one.
    fn older_frame(
        peer: &mut Peer,
        now: Instant,
        departed_after: Duration,
        keyed: bool,
        incarnation: u64,
        seq: u64,
    ) -> Older {
        let index = match peer.older.iter().position(|l| l.incarnation == incarnation) {
            Some(i) => i,
            None => {
                // Never heard (or forgotten): a replay of an ancient life, or a duplicate
                // that started before the current one. Remember it; it proves nothing yet.
                peer.older.push_back(OlderLife {
                    incarnation,
                    highest_seq: seq,
                    last_heard: now,
                    fresh: 0,
                    reported: None,
                    was_current: false,
                    counted: 0,
                });
                if peer.older.len() > OLDER_INCARNATIONS {
                    peer.older.pop_front();
                }
                return Older::Drop { conflict: None };
            }
        };
        let life = &mut peer.older[index];
        if seq <= life.highest_seq {
            // A late copy or a replay: nothing new.
            return Older::Drop { conflict: None };
        }
        if life.last_heard + departed_after <= now {
            life.fresh = 0;
        }
        life.highest_seq = seq;
        life.last_heard = now;
        life.fresh = life.fresh.saturating_add(1);
        if life.fresh < 2 {
            // One fresh frame may be the last of a life the network held back.
            return Older::Drop { conflict: None };
        }
        // With a key, only a life this receiver once took as current may be again (a
        // duplicate that left, a forged newer incarnation): a life it never took could be
        // a replay from another day.
        let may_return = life.was_current || !keyed;
        if may_return
            && peer.last_heard + departed_after <= now
            && life.fresh >= FRESH_FRAMES_TO_RETURN
        {
            return Older::Return;
        }
        peer.conflict_at = Some(now);
        let report = life
            .reported
            .is_none_or(|t| t + CONFLICT_REPORT_EVERY <= now);
        if report {
            life.reported = Some(now);
        }
        Older::Drop {
            conflict: report.then_some(incarnation),
        }
    }

    /// The sender's old incarnation can no longer repair its queues: hand up what is
    /// buffered and give up the holes.
    fn flush_inboxes_of(&mut self, sender: u8) {
        let Some(peer) = self.peers.get_mut(&sender) else {
            return;
        };
        for (queue, mut inbox) in std::mem::take(&mut peer.inboxes) {
            self.talk_buffered = self.talk_buffered.saturating_sub(inbox.buffered_bytes());
            inbox.flush(&mut self.deliveries);
            Self::hand_up_into(
                &mut self.events,
                &mut self.stats,
                &mut self.deliveries,
                sender,
                &queue,
            );
        }
    }
}
