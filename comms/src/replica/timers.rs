//! Timers: the periodic refresh and heartbeat (and the extra refresh for a newcomer),
//! departures, talk NACKs and give-ups, and the stats mirror written at each refresh.

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::Arc;

use crate::blackboard::{Blackboard, SlotId};
use crate::key::{KeyRef, Kind, Scope};
use crate::stats::DropReason;
use crate::talk::NACKS_WAITING_MAX;
use crate::time::Instant;
use crate::value::Value;
use crate::wire::{self, ItemRef, HEADER_LEN};

use super::{Event, Replica};

impl Replica {
    /// A robot appeared, came back after departing, or restarted: it may have missed
    /// (or lost) everything we own, so it gets a full refresh and our talk heads now
    /// instead of up to a refresh period later. The periodic schedule is untouched, so
    /// this is an extra copy, which on a lossy network is also an extra chance. At most
    /// one per quarter period: a refresh that recent reaches the newcomer as well when
    /// several robots come back at once (after a team-wide outage).
    pub(super) fn refresh_for_newcomer(&mut self, now: Instant) {
        let quiet = self.cfg.refresh_period / 4;
        if self.last_full_refresh.is_none_or(|t| t + quiet <= now) {
            self.queue_full_refresh(now);
        }
    }

    /// Queues every own global value and every own talk head, and a heartbeat.
    fn queue_full_refresh(&mut self, now: Instant) {
        let own = Scope::Robot(self.cfg.robot_id);
        self.refresh_queue = self
            .board
            .scope_entries(own)
            .map(|(p, _)| p.to_owned())
            .collect();
        self.heads_out.extend(self.outboxes.keys().cloned());
        self.heartbeat_due = true;
        self.last_full_refresh = Some(now);
    }

    /// Runs timers due at `now`: the periodic refresh and heartbeat, departures, NACKs
    /// and talk give-ups. Call it when [`Replica::poll_timeout`] is reached (calling it
    /// earlier is harmless).
    pub fn handle_timeout(&mut self, now: Instant) {
        self.timers_may_change();
        self.advance(now);
        if now >= self.next_refresh {
            self.next_refresh += self.cfg.refresh_period;
            if self.next_refresh <= now {
                self.next_refresh = now + self.cfg.refresh_period;
            }
            self.queue_full_refresh(now);
            self.mirror_stats(now);
        }
        let limits = self.cfg.talk.clone();
        let departed_after = self.cfg.departed_after;
        let mut nacks = Vec::new();
        let mut handed = Vec::new();
        for (&robot, peer) in &mut self.peers {
            if peer.present && peer.last_heard + departed_after <= now {
                peer.present = false;
                self.events.push_back(Event::PeerDeparted { robot });
            }
            for (queue, inbox) in &mut peer.inboxes {
                for (first, last) in inbox.on_timeout(now, &limits, &mut self.deliveries) {
                    nacks.push((robot, queue.clone(), first, last));
                }
                if !self.deliveries.is_empty() {
                    handed.push((robot, queue.clone(), std::mem::take(&mut self.deliveries)));
                }
            }
        }
        // Give-ups emptied reorder buffers: recount (every inbox was visited anyway).
        self.talk_buffered = self
            .peers
            .values()
            .flat_map(|p| p.inboxes.values())
            .map(|i| i.buffered_bytes())
            .sum();
        for (robot, queue, mut d) in handed {
            Self::hand_up_into(&mut self.events, &mut self.stats, &mut d, robot, &queue);
        }
        self.queue_nacks(nacks);
        self.release_departed(now);
    }

    /// NACKs due: each paid from its sender's NACK credit (refused ones counted in
    /// `nacks_limited`: the inbox asks again on its next timer), replacing any still
    /// waiting for the same queue, at most [`NACKS_WAITING_MAX`] waiting.
    fn queue_nacks(&mut self, nacks: Vec<(u8, String, u64, u64)>) {
        let mut paid: Vec<(u8, String, u64, u64)> = Vec::with_capacity(nacks.len());
        for (robot, queue, first, last) in nacks {
            let Some(peer) = self.peers.get_mut(&robot) else {
                continue;
            };
            let cost = (HEADER_LEN
                + wire::item_len(ItemRef::Nack {
                    target: robot,
                    queue: &queue,
                    first,
                    last,
                })) as f64;
            if peer.nack_credit < cost {
                self.stats.nacks_limited += 1;
                continue;
            }
            peer.nack_credit -= cost;
            paid.push((robot, queue, first, last));
        }
        if paid.is_empty() {
            return;
        }
        self.stats.nacks_sent += paid.len() as u64;
        let fresh: BTreeSet<(u8, &str)> =
            paid.iter().map(|(r, q, _, _)| (*r, q.as_str())).collect();
        let before = self.nacks_out.len();
        self.nacks_out
            .retain(|(r, q, _, _)| !fresh.contains(&(*r, q.as_str())));
        let mut dropped = (before - self.nacks_out.len()) as u64;
        self.nacks_out.extend(paid);
        while self.nacks_out.len() > NACKS_WAITING_MAX {
            self.nacks_out.pop_front();
            dropped += 1;
        }
        self.stats.nacks_superseded += dropped;
    }

    /// When robot `robot`'s values are released if it stays departed: its
    /// `release_departed_after` grace period after its departure.
    fn release_at(&self, last_heard: Instant) -> Instant {
        last_heard + self.cfg.departed_after + self.cfg.release_departed_after
    }

    /// Releases the values of robots departed for longer than the grace period.
    fn release_departed(&mut self, now: Instant) {
        let due: Vec<u8> = self
            .peers
            .iter()
            .filter(|(_, p)| !p.present && self.release_at(p.last_heard) <= now)
            .map(|(&robot, _)| robot)
            .filter(|&robot| self.board.owner_len(robot) > 0)
            .collect();
        for robot in due {
            self.board.release_owner(robot);
        }
        self.sync_board_counts();
    }

    /// Mirrors the counters into `local.var.huddle.stats.*`. It runs at every refresh of
    /// every replica (about 50 keys with four teammates), so a key already written is read
    /// back through its cached slot, not by hashing its path, and only a counter whose
    /// stored value differs is written; no path is built once its key exists.
    fn mirror_stats(&mut self, now: Instant) {
        let s = &self.stats;
        let counters = counter_values(s);
        let (board, mirror) = (&mut self.board, &mut self.stats_mirror);
        let (fixed, scratch) = (&mut mirror.fixed, &mut mirror.scratch);
        fixed.resize_with(COUNTERS.len() + DropReason::ALL.len(), || None);
        let (counter_slots, drop_slots) = fixed.split_at_mut(COUNTERS.len());
        for ((name, v), cached) in COUNTERS.iter().zip(counters).zip(counter_slots) {
            mirror_one(board, now, cached, scratch, v as i64, |p| {
                p.push_str(name);
            });
        }
        for (r, cached) in DropReason::ALL.iter().zip(drop_slots) {
            mirror_one(board, now, cached, scratch, s.drops(*r) as i64, |p| {
                p.push_str("drops.");
                p.push_str(r.name());
            });
        }
        // Two robots sending with one id: which ids, as of their last frames.
        // (Not through `peers()`, which works out every peer's clock as well.)
        let live_within = self.cfg.departed_after;
        let per_peer = &mut mirror.peers;
        for (&robot, p) in &self.peers {
            let v = i64::from(p.conflicting(live_within));
            let cached = &mut peer_slots(per_peer, robot)[0];
            mirror_one(board, now, cached, scratch, v, |p| {
                let _ = write!(p, "peer.{robot}.conflicting");
            });
        }
        for (&robot, t) in &s.last_heard {
            let cached = &mut peer_slots(per_peer, robot)[1];
            mirror_one(board, now, cached, scratch, t.as_micros() as i64, |p| {
                let _ = write!(p, "peer.{robot}.last_heard_us");
            });
        }
    }

    /// Something `poll_timeout` reads may change: every `&mut self` entry point that can
    /// touch the refresh time, the peers (presence, talk inboxes), the board's owners,
    /// the budget, the dirty queue or `now` calls this first.
    pub(super) fn timers_may_change(&mut self) {
        *self.timeout_cache.get_mut() = STALE;
    }

    /// When [`Replica::handle_timeout`] should next be called.
    pub fn poll_timeout(&self) -> Option<Instant> {
        let cached = self.timeout_cache.load(Relaxed);
        if cached != STALE {
            // Tests run with debug assertions: an entry point that forgets to clear the
            // cache shows up here as a disagreement, not as a missed timer.
            debug_assert_eq!(
                self.next_deadline().as_micros(),
                cached,
                "poll_timeout's cached answer is stale"
            );
            return Some(Instant::from_micros(cached));
        }
        let next = self.next_deadline();
        // The end of time is the sentinel: it is worked out again (it never occurs).
        self.timeout_cache.store(next.as_micros(), Relaxed);
        Some(next)
    }

    pub(super) fn next_deadline(&self) -> Instant {
        let limits = &self.cfg.talk;
        let mut next = self.next_refresh;
        for (&robot, peer) in &self.peers {
            if peer.present {
                next = next.min(peer.last_heard + self.cfg.departed_after);
            } else if self.board.owner_len(robot) > 0 {
                next = next.min(self.release_at(peer.last_heard));
            }
            for inbox in peer.inboxes.values() {
                if let Some(t) = inbox.deadline(limits) {
                    next = next.min(t);
                }
            }
        }
        // Changed values held back by the budget's pacing go when it opens.
        if let Some(b) = &self.budget {
            if !self.dirty.is_empty() {
                if let Some(t) = b.next_ordinary(self.now) {
                    next = next.min(t.max(self.now));
                }
            }
        }
        next
    }
}

/// `timeout_cache` holds no answer.
pub(super) const STALE: u64 = u64::MAX;

/// The counters mirrored first, in this order, as `huddle.stats.<name>`; then the drops
/// by reason (`drops.<reason>`), then per peer `peer.<id>.conflicting` and
/// `peer.<id>.last_heard_us`. The order is the order of the change events.
/// The values of [`COUNTERS`], in its order (the mirror's and its test's one list).
fn counter_values(s: &crate::stats::Stats) -> [u64; COUNTERS.len()] {
    [
        s.frames_in,
        s.frames_out,
        s.bytes_in,
        s.bytes_out,
        s.updates_applied,
        s.updates_stale,
        s.items_skipped,
        s.updates_refused,
        s.updates_unconfirmed_replaced,
        s.bindings_superseded,
        s.bindings_released,
        s.talk_delivered,
        s.talk_given_up,
        s.talk_unknown_value,
        s.talk_resent,
        s.talk_refused,
        s.talk_refused_full,
        s.talk_repair_limited,
        s.id_conflicts,
        s.nacks_sent,
        s.nacks_limited,
        s.nacks_superseded,
        s.clock_samples,
        s.clock_echoes_rejected,
        s.clock_outliers,
        s.clock_stamps_implausible,
        s.transit_defaulted,
        s.drops_total(),
    ]
}

const COUNTERS: [&str; 28] = [
    "frames_in",
    "frames_out",
    "bytes_in",
    "bytes_out",
    "updates_applied",
    "updates_stale",
    "items_skipped",
    "updates_refused",
    "updates_unconfirmed_replaced",
    "bindings_superseded",
    "bindings_released",
    "talk_delivered",
    "talk_given_up",
    "talk_unknown_value",
    "talk_resent",
    "talk_refused",
    "talk_refused_full",
    "talk_repair_limited",
    "id_conflicts",
    "nacks_sent",
    "nacks_limited",
    "nacks_superseded",
    "clock_samples",
    "clock_echoes_rejected",
    "clock_outliers",
    "clock_stamps_implausible",
    "transit_defaulted",
    "drops.total",
];

impl crate::stats::Stats {
    /// The counter mirrored as `huddle.stats.<name>` (one of the mirror's fixed counters,
    /// `drops.total` or `drops.<reason>`), read from these stats; `None` for a name the
    /// mirror does not write (the per-peer keys included). One list serves the mirror and
    /// every front door that reads a counter by name (the C node's
    /// `huddle_node_stats_counter`).
    pub fn mirrored(&self, name: &str) -> Option<u64> {
        if let Some(reason) = name.strip_prefix("drops.").filter(|&r| r != "total") {
            let reason = DropReason::ALL.into_iter().find(|r| r.name() == reason)?;
            return Some(self.drops(reason));
        }
        let i = COUNTERS.iter().position(|&n| n == name)?;
        Some(counter_values(self)[i])
    }
}

const PREFIX: &str = "huddle.stats.";

/// Where the stats mirror last found each of its keys, so that a refresh reads the
/// stored value through the slot instead of a path lookup (a `BTreeMap` search and a
/// hash of a 30-byte path, about 400 instructions, for each of ~50 keys per refresh).
#[derive(Debug, Default)]
pub(super) struct StatsMirror {
    /// The [`COUNTERS`], then the drops in [`DropReason::ALL`]'s order.
    fixed: Vec<Option<MirrorSlot>>,
    /// Per robot id: `conflicting`, `last_heard_us`.
    peers: Vec<[Option<MirrorSlot>; 2]>,
    /// A path being built (only for a key not yet found).
    scratch: String,
}

/// A mirrored key's slot, and its path as the blackboard stores it: the slot is taken
/// as the key's only while it holds this very path (held here, so the allocation cannot
/// be reused), so a binding removed and its slot reused is never mistaken for it.
#[derive(Debug)]
struct MirrorSlot {
    id: SlotId,
    path: Arc<str>,
}

fn peer_slots(
    per_peer: &mut Vec<[Option<MirrorSlot>; 2]>,
    robot: u8,
) -> &mut [Option<MirrorSlot>; 2] {
    let i = usize::from(robot);
    if per_peer.len() <= i {
        per_peer.resize_with(i + 1, Default::default);
    }
    &mut per_peer[i]
}

/// Writes `v` to `local.var.huddle.stats.<name>` unless that is stored already (the
/// value compared as the blackboard would: `Value::Int(v)`), so a counter that did not
/// change costs no version, stamp or change event; `name` writes the name after the
/// prefix, called only while the key's slot is unknown.
fn mirror_one(
    board: &mut Blackboard,
    now: Instant,
    cached: &mut Option<MirrorSlot>,
    scratch: &mut String,
    v: i64,
    name: impl FnOnce(&mut String),
) {
    let value = Value::Int(v);
    if let Some(c) = cached {
        if let Some(entry) = board.at_slot(c.id, Scope::Local, &c.path) {
            if entry.value != value {
                let key = KeyRef {
                    scope: Scope::Local,
                    kind: Kind::Var,
                    path: &c.path,
                };
                // A local key of valid shape, not subject to the local-key limit:
                // this cannot fail.
                let _ = board.write_unlimited(now, key, value);
            }
            return;
        }
        *cached = None;
    }
    scratch.clear();
    scratch.push_str(PREFIX);
    name(scratch);
    if board
        .get_stored(Scope::Local, scratch)
        .is_some_and(|e| e.value == value)
    {
        return; // found again next time (rare: someone else wrote the same value)
    }
    let key = KeyRef {
        scope: Scope::Local,
        kind: Kind::Var,
        path: scratch,
    };
    if let Ok(id) = board.write_unlimited(now, key, value) {
        *cached = board.shared_path(id).map(|path| MirrorSlot {
            id,
            path: path.clone(),
        });
    }
}

#[cfg(test)]
mod mirror_tests;
