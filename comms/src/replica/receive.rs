//! Receiving: a datagram is checked (size, own loopback, decoding, peer admission) and
//! its items applied: updates to the blackboard, talk messages and heads to the inboxes,
//! NACKs addressed to this robot to the outboxes.

use std::net::SocketAddr;
use std::time::Duration;

use crate::stats::DropReason;
use crate::time::Instant;
use crate::wire::{self, Item};

use super::talk::TalkItem;
use super::{Event, Replica};

impl Replica {
    fn drop_frame(&mut self, from: SocketAddr, reason: DropReason) {
        self.stats.count_drop(reason);
        self.events.push_back(Event::FrameDropped { from, reason });
    }

    /// Feeds one received datagram. Never panics; anything wrong with it is a counted
    /// drop and an [`Event::FrameDropped`], and nothing stored is lost.
    pub fn handle_datagram(&mut self, now: Instant, from: SocketAddr, bytes: &[u8]) {
        self.advance(now);
        self.stats.frames_in += 1;
        self.stats.bytes_in += bytes.len() as u64;
        if bytes.len() > self.cfg.mtu {
            return self.drop_frame(from, DropReason::Oversized);
        }
        // Our own frame, looped back by the kernel (every frame we send comes back): the
        // plain header names its sender, so it is skipped before the body is decoded or
        // the tag checked. A forged copy of our own header is ignored the same way, which
        // is all a checked one would get.
        if wire::peek_origin(bytes, self.cfg.team_id) == Some((self.cfg.robot_id, self.incarnation))
        {
            self.stats.own_frames += 1;
            return;
        }
        let frame = match wire::decode_frame(bytes, self.cfg.team_id, self.key.as_ref()) {
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
        for item in frame.items {
            match item {
                Item::Update {
                    path,
                    value,
                    version,
                    age_us,
                } => {
                    let stamp = now.saturating_sub(Duration::from_micros(age_us));
                    self.apply_update(sender, frame.incarnation, &path, value, version, stamp);
                }
                Item::Talk { queue, seq, value } => {
                    self.on_talk_item(now, sender, &queue, TalkItem::Message { seq, value })
                }
                Item::TalkHead { queue, first, last } => {
                    self.on_talk_item(now, sender, &queue, TalkItem::Head { first, last })
                }
                Item::Nack {
                    target,
                    queue,
                    first,
                    last,
                } if target == self.cfg.robot_id => self.repair(now, &queue, first, last),
                Item::Nack { .. } => {}
            }
        }
    }
}
