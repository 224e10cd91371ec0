//! Transmit packing: pending NACKs, talk messages, changed values, the refresh and talk
//! heads, in that order, packed into frames of at most `mtu` bytes.

use std::collections::BTreeSet;
use std::sync::Arc;

use crate::blackboard::{Blackboard, Entry};
use crate::key::Scope;
use crate::time::{duration_to_micros, Instant};
use crate::wire::{
    self, varint_len, Echo, FrameClock, FrameWriter, ItemRef, KnownPaths, ECHO_HOLD_UNIT_US,
    ECHO_LEN, HEADER_LEN, LEGACY_VERSION, MAX_ECHO_HOLD_US, TAG_LEN, VERSION,
};

use super::budget::Class;
use super::clock::stamp_of;
use super::dirty::DirtyQueue;
use super::{Destination, Replica, Transmit};

impl Replica {
    /// Bytes a frame spends besides its items, at worst. Under a budget the frame
    /// counter is at most the budget's messages (< 2¹⁶: a 3-byte varint) and a frame holds
    /// fewer than 251 items (a 1-byte count): a league's 128 bytes are not spent on room
    /// for counters that cannot grow that far.
    pub(super) fn frame_overhead(&self) -> usize {
        let tag = if self.key.is_some() { TAG_LEN } else { 0 };
        match &self.budget {
            Some(b) if b.budget.messages < 1 << 16 => HEADER_LEN + ECHO_LEN + 3 + 1 + tag,
            _ => HEADER_LEN + ECHO_LEN + 9 + 3 + tag,
        }
    }

    /// The paths frames send as a one-byte index: the application's table.
    pub(crate) fn known_paths(&self) -> &KnownPaths {
        &self.cfg.known_paths
    }

    /// The format the next frame goes out in: format 3 while a present teammate speaks
    /// only that (see [`crate::ReplicaConfig::legacy_fallback`]), else format 4.
    pub(super) fn write_version(&self) -> u8 {
        let legacy =
            self.cfg.legacy_fallback && self.peers.values().any(|p| p.present && p.legacy_format);
        if legacy {
            LEGACY_VERSION
        } else {
            VERSION
        }
    }

    /// The widest version and age an update item may carry: under a budget, ages are
    /// clamped to 2³² µs (71 minutes: "old") and versions assumed below 2³² (a robot
    /// setting one key at 100 Hz gets there in 16 months), 5-byte varints instead of 9.
    pub(super) fn widest_version_and_age(&self) -> (u64, u64) {
        if self.budget.is_some() {
            (u64::from(u32::MAX), u64::from(u32::MAX))
        } else {
            (u64::MAX, u64::MAX)
        }
    }

    /// Under a budget: whether the changed values waiting fit one frame without an echo
    /// but not with one. The echo then waits for the next frame (it only feeds the clock
    /// estimate, which any later frame can); the values would wait for a frame of their
    /// own, seconds later under a league's budget. Only for frames of changed values
    /// alone (NACKs and talk messages keep the echo).
    fn echo_crowds_out_news(&self, now: Instant, age_cap: u64) -> bool {
        if !(self.nacks_out.is_empty() && self.talk_out.is_empty()) {
            return false;
        }
        let me = Scope::Robot(self.cfg.robot_id);
        let known = self.known_paths();
        let (mut items, mut len) = (0u64, 0usize);
        // Priority items are changed values too: the dirty queue holds them all.
        for path in self.dirty.iter() {
            if let Some(e) = self.board.get_stored(me, path) {
                items += 1;
                len += wire::item_len_coded(update_ref(path, e, now, age_cap), known);
            }
        }
        let tag = if self.key.is_some() { TAG_LEN } else { 0 };
        // Format 3 counts its items; format 4 gives each a length (in `item_len_coded`).
        let count = if self.write_version() == LEGACY_VERSION {
            varint_len(items)
        } else {
            0
        };
        let frame = HEADER_LEN + varint_len(self.seq + 1) + count + len + tag;
        frame <= self.cfg.mtu && frame + ECHO_LEN > self.cfg.mtu
    }

    /// The echo for the next frame: of the present teammates heard recently enough for
    /// the hold to fit, the one whose echo went out longest ago (never first, then the
    /// lowest id). Marks it echoed at `now`.
    fn next_echo(&mut self, now: Instant) -> Option<Echo> {
        let (&robot, peer) = self
            .peers
            .iter_mut()
            .filter(|(_, p)| p.present)
            .filter(|(_, p)| {
                p.clock.heard.is_some_and(|(_, at)| {
                    duration_to_micros(now.saturating_duration_since(at))
                        <= u64::from(MAX_ECHO_HOLD_US)
                })
            })
            .min_by_key(|(_, p)| p.clock.echoed_at)?;
        let (seq, heard_at) = peer.clock.heard?;
        peer.clock.echoed_at = Some(now);
        let hold_us = duration_to_micros(now.saturating_duration_since(heard_at));
        let hold_10us = (hold_us + u64::from(ECHO_HOLD_UNIT_US) / 2) / u64::from(ECHO_HOLD_UNIT_US);
        Some(Echo {
            target: robot,
            seq16: seq as u16,
            hold_10us: u16::try_from(hold_10us).unwrap_or(u16::MAX),
        })
    }

    /// The next frame to send, at most `mtu` bytes: NACKs, talk messages, changed
    /// values, the periodic refresh and talk heads, in that order of priority. Ages in it
    /// are measured to the latest `now` given to any input.
    ///
    /// With a budget, only NACKs, talk messages and changed values start a frame, and only
    /// when the budget allows one (a priority item may draw on the reserve); the refresh
    /// and talk heads ride along in the room left.
    ///
    /// The allocating convenience: one fresh `Vec` per frame. Drivers drain with
    /// [`Replica::poll_transmit_into`] and one kept buffer instead (the daemon, the Rust
    /// `Session`, the C node and the netsim harness do; `comms/tests/alloc_per_frame.rs`
    /// holds that path at 0 allocations per frame).
    pub fn poll_transmit(&mut self) -> Option<Transmit> {
        let mut payload = Vec::new();
        let destination = self.poll_transmit_into(&mut payload)?;
        Some(Transmit {
            destination,
            payload,
        })
    }

    /// [`Replica::poll_transmit`] writing the frame into `buf` (cleared first) and
    /// returning where it goes: a driver that keeps one buffer allocates nothing per
    /// frame (quinn-proto's way).
    pub fn poll_transmit_into(&mut self, buf: &mut Vec<u8>) -> Option<Destination> {
        let pending = !(self.nacks_out.is_empty()
            && self.talk_out.is_empty()
            && self.dirty.is_empty()
            && self.refresh_queue.is_empty()
            && self.heads_out.is_empty());
        if !pending && !self.heartbeat_due {
            // Nothing changed: a driver polls every replica after every input.
            return None;
        }
        self.timers_may_change();
        self.note_team_frames();
        let class = match &self.budget {
            None => None,
            Some(b) => {
                let own_news = !self.dirty.is_empty() || self.talk_posts_waiting();
                let news = own_news || !(self.nacks_out.is_empty() && self.talk_out.is_empty());
                let class = if self.dirty.iter().any(|p| self.urgent.contains(p)) {
                    Class::Priority
                } else {
                    Class::Ordinary
                };
                if !news || !b.allows(self.now, class) {
                    return None;
                }
                // NACKs and re-sends alone start at most half of the frames: the rest
                // are the robot's own news'.
                if !own_news {
                    if self.repair_frames.saturating_mul(2) > b.sent() {
                        return None;
                    }
                    self.repair_frames += 1;
                }
                Some(class)
            }
        };
        let me = Scope::Robot(self.cfg.robot_id);
        let now = self.now;
        let age_cap = self.widest_version_and_age().1;
        let echo = if class.is_some() && self.echo_crowds_out_news(now, age_cap) {
            None
        } else {
            self.next_echo(now)
        };
        let version = self.write_version();
        let mut w = FrameWriter::new_in(
            std::mem::take(buf),
            self.cfg.team_id,
            self.cfg.robot_id,
            self.incarnation,
            self.seq + 1,
            self.cfg.mtu,
            self.key.as_ref(),
        )
        .with_known_paths(&self.cfg.known_paths)
        .with_version(version);
        w.set_clock(FrameClock {
            stamp_us: stamp_of(now),
            echo,
        });
        let mut full = false;
        // Under a budget the robot's own values go first, and NACKs take at most a
        // quarter of the frame: a flood of gaps must not crowd its news out.
        let budgeted = class.is_some();
        let refreshing = !self.refresh_queue.is_empty();
        let mut sent = std::mem::take(&mut self.sent_scratch);
        if budgeted {
            full |= push_values(
                &self.board,
                &mut self.dirty,
                &mut self.urgent,
                me,
                refreshing,
                &mut w,
                &mut sent,
                (now, age_cap),
            );
        }
        let nack_room = if budgeted {
            self.cfg.mtu / 4
        } else {
            usize::MAX
        };
        let nacks_from = w.len();
        while let Some((target, queue, first, last)) = self.nacks_out.front() {
            let item = ItemRef::Nack {
                target: *target,
                queue,
                first: *first,
                last: *last,
            };
            if w.len() > nacks_from && w.len() - nacks_from + wire::item_len(item) > nack_room {
                break;
            }
            if !w.push(item) {
                full = true;
                break;
            }
            self.nacks_out.pop_front();
        }
        while !full {
            let Some((queue, seq)) = self.talk_out.front() else {
                break;
            };
            if let Some(outbox) = self.outboxes.get_mut(queue) {
                if let Some(value) = outbox.get(*seq) {
                    if !w.push(ItemRef::Talk {
                        queue,
                        seq: *seq,
                        value,
                    }) {
                        full = true;
                        break;
                    }
                    outbox.mark_sent(*seq, now);
                }
            }
            self.talk_out.pop_front();
        }
        if !budgeted {
            full |= push_values(
                &self.board,
                &mut self.dirty,
                &mut self.urgent,
                me,
                refreshing,
                &mut w,
                &mut sent,
                (now, age_cap),
            );
        }
        while !full {
            let Some(path) = self.refresh_queue.front() else {
                break;
            };
            if let Some(e) = self.board.get_stored(me, path) {
                let fresh = self.dirty.contains(path) || sent.iter().any(|s| **s == **path);
                if !fresh && !w.push(update_ref(path, e, now, age_cap)) {
                    full = true;
                    break;
                }
            }
            self.refresh_queue.pop_front();
        }
        if !full {
            while let Some(queue) = self.heads_out.first() {
                if let Some(outbox) = self.outboxes.get(queue) {
                    if !w.push(ItemRef::TalkHead {
                        queue,
                        first: outbox.first(),
                        last: outbox.last(),
                    }) {
                        break;
                    }
                }
                self.heads_out.pop_first();
            }
        }
        if w.is_empty() && pending {
            // Cannot happen (set and post refuse items that do not fit an empty frame),
            // but never stall on one: skip the item that did not fit.
            if self.nacks_out.pop_front().is_none()
                && self.talk_out.pop_front().is_none()
                && self.dirty.pop_first().is_none()
                && self.refresh_queue.pop_front().is_none()
            {
                self.heads_out.pop_first();
            }
        }
        self.heartbeat_due = false;
        if let (Some(b), Some(class)) = (&mut self.budget, class) {
            b.spend(now, class);
        }
        self.seq += 1;
        self.sent.record(self.seq, now);
        *buf = w.finish();
        sent.clear();
        self.sent_scratch = sent;
        self.stats.frames_out += 1;
        self.stats.bytes_out += buf.len() as u64;
        Some(Destination::Group)
    }
}

/// Priority items, then changed values, into `w` (see `poll_transmit`); those pushed go
/// into `sent` when a refresh is due. Returns whether one did not fit.
#[allow(clippy::too_many_arguments)]
fn push_values(
    board: &Blackboard,
    dirty: &mut DirtyQueue,
    urgent: &mut BTreeSet<Arc<str>>,
    me: Scope,
    refreshing: bool,
    w: &mut FrameWriter<'_>,
    sent: &mut Vec<Arc<str>>,
    (now, age_cap): (Instant, u64),
) -> bool {
    // Priority items first, then the longest waiting. One that does not fit keeps its
    // place at the head of the line while a few smaller ones behind it may still go.
    // Values in this frame as news: the refresh does not repeat them. Kept only when a
    // refresh is due (no list on the busy path of a frame of news).
    let mut full = false;
    if !urgent.is_empty() {
        let first = std::mem::take(urgent);
        for path in first {
            match board.get_stored(me, &path) {
                Some(e) if !w.push(update_ref(&path, e, now, age_cap)) => {
                    full = true;
                    urgent.insert(path);
                }
                _ => {
                    dirty.remove(&path);
                    if refreshing {
                        sent.push(path);
                    }
                }
            }
        }
    }
    let mut i = 0;
    let mut skipped = 0;
    while skipped < MAX_SKIPPED {
        let Some((path, slot)) = dirty.get(i) else {
            break;
        };
        let pushed = match board.get_at(slot, me, path) {
            Some(e) if !w.push(update_ref(path, e, now, age_cap)) => {
                full = true;
                skipped += 1;
                i += 1;
                continue;
            }
            Some(_) => true,
            None => false,
        };
        let path = dirty.remove_at(i);
        if pushed && refreshing {
            sent.extend(path);
        }
    }
    full
}

/// Changed values that did not fit a frame, after which it is sent as it is.
const MAX_SKIPPED: usize = 4;

fn update_ref<'a>(path: &'a str, e: &'a Entry, now: Instant, age_cap: u64) -> ItemRef<'a> {
    ItemRef::Update {
        path,
        value: &e.value,
        version: e.version,
        age_us: duration_to_micros(e.age(now)).min(age_cap),
    }
}
