//! Talk queues through the replica: posting to own queues, handing teammates' messages up
//! in order (or as given up), and repairing what a teammate NACKs. The per-queue state
//! machines are [`crate::talk`]'s.

use std::collections::VecDeque;

use thiserror::Error;

use crate::key::{Key, KeyError, Kind, Scope};
use crate::stats::Stats;
use crate::talk::{Delivery, Heard, Inbox};
use crate::time::Instant;
use crate::value::Value;
use crate::wire::{self, ItemRef};

use super::{Event, Replica};

/// Why a talk message was refused.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum PostError {
    /// The key does not parse.
    #[error(transparent)]
    Key(#[from] KeyError),
    /// Only `*.talk.<queue>` (or this robot's own `n.talk.<queue>`) can be posted to.
    #[error("{0} is not a talk queue of this robot (post to *.talk.<queue>)")]
    NotOwnQueue(String),
    /// The message would not fit in one frame.
    #[error("{key}: the message takes {bytes} bytes, more than one frame holds ({mtu} byte MTU)")]
    TooLarge {
        /// The key as given.
        key: String,
        /// Encoded item size.
        bytes: usize,
        /// Configured MTU.
        mtu: usize,
    },
    /// This robot already has `talk.max_queues` queues.
    #[error("too many talk queues (limit {0})")]
    TooManyQueues(usize),
    /// The queue's retention is full of messages a teammate may still be repairing
    /// (all younger than `give_up_after`): posting now would evict one. Post again
    /// later; the queue carries at most `retain / give_up_after` messages a second.
    #[error("{key}: the queue's {retain} retained messages are all younger than {give_up_ms} ms; try again later")]
    RetentionFull {
        /// The key as given.
        key: String,
        /// Messages retained per queue.
        retain: usize,
        /// The give-up time, ms.
        give_up_ms: u64,
    },
}

/// A teammate's talk item, as [`Replica::on_talk_item`] takes it.
pub(super) enum TalkItem {
    /// `value` is `None` for a value tag this build does not know.
    Message {
        seq: u64,
        value: Option<Value>,
    },
    Head {
        first: u64,
        last: u64,
    },
}

impl Replica {
    /// Posts a message to this robot's queue `*.talk.<queue>`; every teammate receives
    /// it once, in order, as [`Event::TalkDelivered`] (this robot does not). Returns its
    /// sequence number.
    pub fn post(&mut self, now: Instant, key: &str, value: Value) -> Result<u64, PostError> {
        self.timers_may_change();
        self.advance(now);
        let key = Key::parse(key)?;
        let own =
            matches!(key.scope(), Scope::Global) || key.scope() == Scope::Robot(self.cfg.robot_id);
        if key.kind() != Kind::Talk || !own {
            return Err(PostError::NotOwnQueue(key.to_string()));
        }
        let bytes = wire::item_len(ItemRef::Talk {
            queue: key.path(),
            seq: u64::MAX,
            value: &value,
        });
        if bytes + self.frame_overhead() > self.cfg.mtu {
            return Err(PostError::TooLarge {
                key: key.to_string(),
                bytes,
                mtu: self.cfg.mtu,
            });
        }
        if !self.outboxes.contains_key(key.path())
            && self.outboxes.len() >= self.cfg.talk.max_queues
        {
            return Err(PostError::TooManyQueues(self.cfg.talk.max_queues));
        }
        let outbox = self.outboxes.entry(key.path().to_owned()).or_default();
        if outbox.full(now, &self.cfg.talk) {
            self.stats.talk_refused_full += 1;
            return Err(PostError::RetentionFull {
                key: key.to_string(),
                retain: self.cfg.talk.retain,
                give_up_ms: self.cfg.talk.give_up_after.as_millis() as u64,
            });
        }
        let seq = outbox.post(now, value, self.cfg.talk.retain);
        self.talk_out.push_back((key.path().to_owned(), seq));
        Ok(seq)
    }

    /// The inbox of `sender`'s `queue`, opened if new: at 1, or, while this robot is
    /// catching up with a sender it met mid-life, at `start` (the first message or head
    /// heard).
    pub(super) fn inbox(
        &mut self,
        now: Instant,
        sender: u8,
        queue: &str,
        start: u64,
    ) -> Option<&mut Inbox> {
        let max = self.cfg.talk.max_queues;
        let peer = self.peers.get_mut(&sender)?;
        if !peer.inboxes.contains_key(queue) {
            if peer.inboxes.len() >= max {
                self.stats.talk_queue_overflow += 1;
                return None;
            }
            let inbox = if peer.catch_up_until.is_some_and(|t| now < t) {
                Inbox::starting_at(start)
            } else {
                Inbox::default()
            };
            peer.inboxes.insert(queue.to_owned(), inbox);
        }
        peer.inboxes.get_mut(queue)
    }

    /// A teammate's talk message or head: into its inbox, whatever is now deliverable
    /// handed up, refusals counted, the reorder buffers' byte total kept.
    pub(super) fn on_talk_item(&mut self, now: Instant, sender: u8, queue: &str, item: TalkItem) {
        let limits = self.cfg.talk.clone();
        let room = limits
            .buffered_bytes_total
            .saturating_sub(self.talk_buffered);
        let start = match item {
            TalkItem::Message { seq, .. } => seq,
            TalkItem::Head { last, .. } => last.saturating_add(1),
        };
        let mut out = std::mem::take(&mut self.deliveries);
        let mut heard = Heard::Taken;
        let mut delta = (0, 0);
        if let Some(inbox) = self.inbox(now, sender, queue, start) {
            let before = inbox.buffered_bytes();
            heard = match item {
                TalkItem::Message { seq, value } => {
                    inbox.on_message(now, seq, value, &limits, room, &mut out)
                }
                TalkItem::Head { first, last } => {
                    inbox.on_head(now, first, last, &limits, &mut out)
                }
            };
            delta = (before, inbox.buffered_bytes());
        }
        self.talk_buffered = self.talk_buffered + delta.1 - delta.0;
        if heard == Heard::Refused {
            self.stats.talk_refused += 1;
        }
        self.hand_up(sender, queue, &mut out);
        self.deliveries = out;
    }

    pub(super) fn hand_up(&mut self, sender: u8, queue: &str, out: &mut Vec<Delivery>) {
        Self::hand_up_into(&mut self.events, &mut self.stats, out, sender, queue);
    }

    pub(super) fn hand_up_into(
        events: &mut VecDeque<Event>,
        stats: &mut Stats,
        deliveries: &mut Vec<Delivery>,
        from: u8,
        queue: &str,
    ) {
        for d in deliveries.drain(..) {
            events.push_back(match d {
                // A newer build's value this build cannot decode: acknowledged (the
                // queue moves on, no NACK), counted and handed up as skipped, never
                // delivered as something else.
                Delivery::Message { seq, value: None } => {
                    stats.talk_unknown_value += 1;
                    Event::TalkGivenUp {
                        queue: queue.to_owned(),
                        from,
                        first: seq,
                        last: seq,
                    }
                }
                Delivery::Message {
                    seq,
                    value: Some(value),
                } => {
                    stats.talk_delivered += 1;
                    Event::TalkDelivered {
                        queue: queue.to_owned(),
                        from,
                        seq,
                        value,
                    }
                }
                Delivery::GivenUp { first, last } => {
                    stats.talk_given_up = stats.talk_given_up.saturating_add(last - first + 1);
                    Event::TalkGivenUp {
                        queue: queue.to_owned(),
                        from,
                        first,
                        last,
                    }
                }
            });
        }
    }

    /// Whether an own post waits for its first frame (news, unlike a re-send).
    pub(super) fn talk_posts_waiting(&self) -> bool {
        self.talk_out
            .iter()
            .any(|(q, seq)| self.outboxes.get(q).is_some_and(|o| o.unsent(*seq)))
    }

    /// Teammate `from` asked for `first..=last` of our queue.
    pub(super) fn repair(&mut self, now: Instant, from: u8, queue: &str, first: u64, last: u64) {
        let Some(outbox) = self.outboxes.get_mut(queue) else {
            return;
        };
        // A resend within half a NACK interval already answers this request.
        let quiet = self.cfg.talk.nack_interval / 2;
        let wanted = outbox.to_resend(first, last, now, quiet);
        let mut credit = self.peers.get(&from).map_or(0.0, |p| p.repair_credit);
        for (i, &seq) in wanted.iter().enumerate() {
            // However many NACKs arrive (spoofed ones too), repairs stay within twice
            // what was posted plus a trickle, and within twice the bytes heard from the
            // robot that asks. Once either allowance is spent the rest of the request is
            // refused at once: a flood of NACKs costs no more work.
            let cost = outbox.get(seq).map_or(0, |value| {
                wire::HEADER_LEN + wire::item_len(ItemRef::Talk { queue, seq, value })
            }) as f64;
            if credit < cost || !outbox.spend_repair(now, seq) {
                self.stats.talk_repair_limited += (wanted.len() - i) as u64;
                break;
            }
            credit -= cost;
            outbox.mark_sent(seq, now);
            self.talk_out.push_back((queue.to_owned(), seq));
            self.stats.talk_resent += 1;
        }
        if let Some(peer) = self.peers.get_mut(&from) {
            peer.repair_credit = credit;
        }
        if first < outbox.first() || last > outbox.last() {
            // Some of it is gone (or never existed): the head tells them to give up.
            self.heads_out.insert(queue.to_owned());
        }
    }
}
