//! Receiving: a datagram is checked (size, own loopback, decoding, peer admission) and
//! its items applied: updates to the blackboard, talk messages and heads to the inboxes,
//! NACKs addressed to this robot to the outboxes.

use std::net::SocketAddr;
use std::time::Duration;

use crate::stats::DropReason;
use crate::talk::{AMPLIFICATION, CREDIT_MAX_BYTES};
use crate::time::Instant;
use crate::wire::{self, FrameClock, ItemView};

use super::clock::{SampleOutcome, IMPLAUSIBLE_MARGIN, MAX_TRANSIT};
use super::talk::TalkItem;
use super::{Event, Replica};

/// Frames the running mean of seen transits spans (see `Replica::transit_seen_us`).
const TRANSIT_SEEN_FRAMES: f64 = 16.0;

impl Replica {
    fn drop_frame(&mut self, from: SocketAddr, reason: DropReason) {
        self.stats.count_drop(reason);
        self.events.push_back(Event::FrameDropped { from, reason });
    }

    /// Feeds one received datagram. Never panics; anything wrong with it is a counted
    /// drop and an [`Event::FrameDropped`], and nothing stored is lost.
    pub fn handle_datagram(&mut self, now: Instant, from: SocketAddr, bytes: &[u8]) {
        if bytes.len() <= self.cfg.mtu && self.is_own_frame(bytes) {
            // Our own frame, looped back by the kernel (every frame we send comes back:
            // half of what a busy replica reads): the plain header names its sender, so
            // it is counted and skipped before the body is decoded or the tag checked,
            // and before anything is set up to apply a frame. A forged copy of our own
            // header is ignored the same way, which is all a checked one would get.
            self.advance(now);
            self.count_frame_in(bytes);
            self.stats.own_frames += 1;
            return;
        }
        self.timers_may_change();
        // The table is shared (a reference count, no copy): the items borrow it (and the
        // datagram) while they are applied to `self`.
        let known = self.cfg.known_paths.clone();
        let mut items = recycle(std::mem::take(&mut self.item_scratch));
        self.receive(now, from, bytes, &known, &mut items);
        self.item_scratch = recycle(items);
    }

    fn count_frame_in(&mut self, bytes: &[u8]) {
        self.stats.frames_in += 1;
        self.stats.bytes_in += bytes.len() as u64;
    }

    fn receive<'a>(
        &mut self,
        now: Instant,
        from: SocketAddr,
        bytes: &'a [u8],
        known: &'a wire::KnownPaths,
        items: &mut Vec<ItemView<'a>>,
    ) {
        self.advance(now);
        self.count_frame_in(bytes);
        if bytes.len() > self.cfg.mtu {
            return self.drop_frame(from, DropReason::Oversized);
        }
        // Our own frames (looped back by the kernel) were skipped in `handle_datagram`
        // before getting here.
        // One pass: the items come out validated (none if the frame is malformed).
        let frame =
            match wire::decode_frame_into(bytes, self.cfg.team_id, self.key.as_ref(), known, items)
            {
                Ok(frame) => frame,
                Err(e) => return self.drop_frame(from, DropReason::from(&e)),
            };
        let sender = frame.sender;
        if sender == self.cfg.robot_id {
            if frame.incarnation == self.incarnation {
                self.stats.own_frames += 1;
                return;
            }
            // Another robot sends with this robot's id: say so, at most once a second.
            if self
                .own_conflict_reported
                .is_none_or(|t| t + Duration::from_secs(1) <= now)
            {
                self.own_conflict_reported = Some(now);
                self.stats.id_conflicts += 1;
                self.events.push_back(Event::IncarnationConflict {
                    robot: sender,
                    current: self.incarnation,
                    other: frame.incarnation,
                });
            }
            return self.drop_frame(from, DropReason::RobotIdConflict);
        }
        if let Err(reason) = self.admit(now, sender, frame.incarnation, frame.seq) {
            return self.drop_frame(from, reason);
        }
        self.stats.items_skipped += frame.skipped() as u64;
        if let Some(peer) = self.peers.get_mut(&sender) {
            peer.legacy_format = frame.version == wire::LEGACY_VERSION;
            // What its frames cost on the air pays for the NACKs and re-sends they cause.
            let earned = AMPLIFICATION * bytes.len() as f64;
            peer.nack_credit = (peer.nack_credit + earned).min(CREDIT_MAX_BYTES);
            peer.repair_credit = (peer.repair_credit + earned).min(CREDIT_MAX_BYTES);
        }
        let transit = self.on_frame_clock(now, sender, frame.seq, &frame.clock);
        for item in items.drain(..) {
            match item {
                ItemView::Update {
                    path,
                    value,
                    version,
                    age_us,
                } => {
                    // Set `age` before the frame left, which was `transit` ago.
                    let stamp = now
                        .saturating_sub(transit)
                        .saturating_sub(Duration::from_micros(age_us));
                    self.apply_update(
                        sender,
                        frame.incarnation,
                        path,
                        value.to_value(),
                        version,
                        stamp,
                    );
                }
                ItemView::Talk { queue, seq, value } => self.on_talk_item(
                    now,
                    sender,
                    queue,
                    TalkItem::Message {
                        seq,
                        value: value.value(),
                    },
                ),
                ItemView::TalkHead { queue, first, last } => {
                    self.on_talk_item(now, sender, queue, TalkItem::Head { first, last })
                }
                ItemView::Nack {
                    target,
                    queue,
                    first,
                    last,
                } if target == self.cfg.robot_id => self.repair(now, sender, queue, first, last),
                ItemView::Nack { .. } => {}
            }
        }
    }
}

/// An empty list of items of another lifetime on the same allocation: the receive path
/// keeps one list across datagrams that each borrow their own bytes. (std collects a
/// `Vec`'s own `IntoIter` in place when the element layout is the same, as here; were it
/// ever not to, this would allocate, nothing worse.)
// `filter` would keep the lifetime: the `filter_map` is what changes it.
#[allow(clippy::unnecessary_filter_map)]
fn recycle<'b>(mut items: Vec<ItemView<'_>>) -> Vec<ItemView<'b>> {
    items.clear();
    items.into_iter().filter_map(|_| None).collect()
}

impl Replica {
    /// The timing part of an admitted frame: remember it for the next echo to `sender`,
    /// feed an echo of our own frame to the estimate of `sender`'s clock, and return the
    /// frame's transit (estimated, or the configured default).
    fn on_frame_clock(
        &mut self,
        now: Instant,
        sender: u8,
        seq: u64,
        clock: &FrameClock,
    ) -> Duration {
        let Some(peer) = self.peers.get_mut(&sender) else {
            return self.cfg.default_transit;
        };
        peer.clock.heard = Some((seq, now));
        peer.clock.note_stamp(clock.stamp_us, now);
        if let Some(echo) = clock.echo.filter(|e| e.target == self.cfg.robot_id) {
            let outcome = match self.sent.sent_at(echo.seq16) {
                Some(t1) => peer
                    .clock
                    .estimate
                    .add_echo(t1, echo.hold_us(), clock.stamp_us, now),
                None => SampleOutcome::Rejected,
            };
            match outcome {
                SampleOutcome::Used => self.stats.clock_samples += 1,
                SampleOutcome::Rejected => self.stats.clock_echoes_rejected += 1,
                SampleOutcome::Outlier => self.stats.clock_outliers += 1,
            }
        }
        let estimated = if self.cfg.clock_sync {
            peer.clock.estimate.transit_us(clock.stamp_us, now)
        } else {
            None
        };
        // Without an estimate for this sender, the transit frames were last seen to take
        // (the same air for every teammate), else the configured default: under a
        // league's budget a sender's echoes are seconds apart and its estimate is mostly
        // absent, and a transit of zero stamped every value one network delay late.
        let fallback = self.transit_seen_us.map_or(self.cfg.default_transit, |us| {
            Duration::from_micros(us.round() as u64)
        });
        let Some(transit_us) = estimated else {
            self.stats.transit_defaulted += 1;
            return fallback;
        };
        let plausible = -(IMPLAUSIBLE_MARGIN.as_micros() as f64)..=MAX_TRANSIT.as_micros() as f64;
        if !plausible.contains(&transit_us) {
            // A stamp that cannot be right (forged, or a broken clock): as documented,
            // the default (`clock_tests`).
            self.stats.clock_stamps_implausible += 1;
            return self.cfg.default_transit;
        }
        let transit_us = transit_us.max(0.0);
        self.transit_seen_us = Some(match self.transit_seen_us {
            Some(mean) => mean + (transit_us - mean) / TRANSIT_SEEN_FRAMES,
            None => transit_us,
        });
        Duration::from_micros(transit_us.round() as u64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The receive path allocates no list per frame: the one it keeps survives the
    /// change of lifetime with its capacity (and its allocation).
    #[test]
    fn the_item_list_keeps_its_allocation_across_frames() {
        let mut items: Vec<ItemView<'static>> = Vec::with_capacity(32);
        let at = items.as_ptr();
        let bytes = String::from("a.b");
        let mut borrowed: Vec<ItemView<'_>> = recycle(std::mem::take(&mut items));
        borrowed.push(ItemView::TalkHead {
            queue: &bytes,
            first: 1,
            last: 0,
        });
        let back: Vec<ItemView<'static>> = recycle(borrowed);
        assert!(back.is_empty(), "no item outlives its frame");
        assert_eq!(back.capacity(), 32, "the capacity is kept");
        assert_eq!(back.as_ptr(), at, "the allocation is the same");
    }
}
