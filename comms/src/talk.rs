//! Talk queues: exactly-once, in-order delivery of each sender's queue to every teammate
//! over a lossy, duplicating, reordering network.
//!
//! The sender numbers its messages per queue (1, 2, ... within one incarnation), keeps
//! the last `retain` of them for repair, and advertises the span it still holds (`TalkHead`
//! with every refresh). A receiver delivers message `next` and whatever follows it from
//! its reorder buffer. A message is *known missing* from the moment a later message or a
//! head shows it exists; from then on it is NACKed (first after `nack_interval`, then at
//! growing intervals up to three times that), and `give_up_after` after it became known
//! missing (or at once, when the sender's head says it was evicted) it is given up and
//! reported. Each missing message gets the full `give_up_after` from its own moment.
//!
//! Where a receiver starts: from the start of a sender incarnation it saw begin (a
//! restart it witnessed, a sender that started about when it did, or a queue that
//! appeared later), every message is delivered. A receiver that meets a sender mid-life
//! (it started or joined the network late, while the sender had been running for several
//! seconds) starts each queue at the first message or head it hears: older messages were
//! for the team as it was then, and are not delivered as if new.
//!
//! Bounds, so that a misconfigured or hostile sender cannot do lasting damage: a head
//! spanning more than [`MAX_HEAD_SPAN`] messages is ignored; a head that would give up
//! more than `window` messages at once is applied only when a second, later head agrees
//! (the real sender repeats its head every refresh; one stray frame does not); a message
//! beyond the reorder window does not open a gap. Memory: `retain` messages per own
//! queue, `window` messages and `window_bytes` bytes buffered per (sender, queue),
//! `max_queues` queues per sender. Repairs cost the sender at most [`REPAIR_SHARE`] times
//! the bytes it posted (a re-send serves every receiver that lost the message) plus
//! [`REPAIR_TRICKLE_BYTES_PER_S`], however many NACKs arrive; and in bytes on the air
//! NACKs about a sender, and re-sends a sender's NACKs cause, cost at most
//! [`AMPLIFICATION`] times the bytes of that sender's frames heard (banked up to
//! [`CREDIT_MAX_BYTES`]). At most [`NACKS_WAITING_MAX`] NACK items wait for a frame.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use crate::time::Instant;
use crate::value::Value;

/// Missing spans one NACK asks for at most.
pub(crate) const NACK_SPANS: usize = 16;

/// A head claiming a span longer than this is not from a real sender.
pub const MAX_HEAD_SPAN: u64 = 1 << 16;

/// Repairs a queue may send, as a share of the bytes it posted: a message lost by any of
/// several receivers is re-sent once for all of them, and at 30% loss with up to ten
/// receivers one message in a few needs a second round.
pub const REPAIR_SHARE: f64 = 2.0;

/// Repair allowance earned with time alone, bytes per second per queue (beyond
/// [`REPAIR_SHARE`] of the bytes posted): enough to answer a newcomer's NACK of a quiet
/// queue.
pub const REPAIR_TRICKLE_BYTES_PER_S: f64 = 2048.0;

/// Bytes of NACKs a robot may send about a sender, and bytes of re-sends a sender's NACKs
/// may cause, per byte of that sender's frames heard: NACKs from gaps and re-sends from
/// NACKs each cost at most twice the bytes that caused them on the air (each NACK item
/// and each re-send is charged as if it went in a frame of its own, header included).
pub const AMPLIFICATION: f64 = 2.0;

/// The most NACK or repair credit one sender's frames can bank, bytes: what a burst
/// after a quiet spell may use.
pub const CREDIT_MAX_BYTES: f64 = 16_384.0;

/// NACK items waiting for a frame, at most (a new NACK of one queue replaces the one
/// waiting; beyond this the oldest waiting are dropped: the inbox asks again on its next
/// timer). With a budget frames are rare, and NACKs must not pile up between them.
pub const NACKS_WAITING_MAX: usize = 256;

/// Limits and timers of the talk queues.
#[derive(Clone, Debug, PartialEq)]
pub struct TalkLimits {
    /// Messages kept per own queue for repair (default 256). A post is refused while all
    /// of them are younger than `give_up_after` (a teammate may still need them): that
    /// caps one queue at `retain / give_up_after` messages a second.
    pub retain: usize,
    /// Out-of-order messages buffered per (sender, queue) (default 256).
    pub window: usize,
    /// Bytes of out-of-order messages buffered per (sender, queue) (default 256 KiB).
    pub window_bytes: usize,
    /// Bytes of out-of-order messages buffered over all senders and queues (default
    /// 16 MiB).
    pub buffered_bytes_total: usize,
    /// Queues tracked per sender, and own queues (default 64).
    pub max_queues: usize,
    /// Delay before the first NACK of a gap, and between the first NACKs (default 20 ms).
    pub nack_interval: Duration,
    /// How long a message may stay known missing before it is given up (default 1 s).
    pub give_up_after: Duration,
}

impl Default for TalkLimits {
    fn default() -> TalkLimits {
        TalkLimits {
            retain: 256,
            window: 256,
            window_bytes: 256 * 1024,
            buffered_bytes_total: 16 << 20,
            max_queues: 64,
            nack_interval: Duration::from_millis(20),
            give_up_after: Duration::from_secs(1),
        }
    }
}

/// Bytes a message takes in memory and, roughly, on the wire.
pub(crate) fn message_bytes(value: &Value) -> usize {
    8 + match value {
        Value::Int(_) | Value::Float(_) => 8,
        Value::Bool(_) => 1,
        Value::String(s) => s.len(),
        Value::Floats(v) => 8 * v.len(),
        Value::Bytes(b) => b.len(),
    }
}

/// The sender's side of one queue.
#[derive(Debug, Default)]
pub(crate) struct Outbox {
    last: u64,
    /// Contiguous, oldest first: (seq, message, when posted, when last put on the wire).
    retained: VecDeque<(u64, Value, Instant, Option<Instant>)>,
    /// Bytes of the retained messages (kept up to date: repairs are capped by it).
    retained_bytes: usize,
    /// Bytes of repairs still allowed, and when that was last brought up to date.
    repair_budget: f64,
    budget_at: Option<Instant>,
}

impl Outbox {
    /// Whether a post at `now` must be refused: every retained message is younger than
    /// `give_up_after`, so evicting the oldest could lose it for a teammate still
    /// repairing it.
    pub(crate) fn full(&self, now: Instant, limits: &TalkLimits) -> bool {
        self.retained.len() >= limits.retain.max(1)
            && self
                .retained
                .front()
                .is_some_and(|m| m.2 + limits.give_up_after > now)
    }

    /// Numbers and keeps a new message; returns its sequence number.
    pub(crate) fn post(&mut self, now: Instant, value: Value, retain: usize) -> u64 {
        self.last += 1;
        let bytes = message_bytes(&value);
        self.repair_budget += REPAIR_SHARE * bytes as f64;
        self.retained_bytes += bytes;
        self.retained.push_back((self.last, value, now, None));
        while self.retained.len() > retain.max(1) {
            if let Some((_, evicted, _, _)) = self.retained.pop_front() {
                self.retained_bytes -= message_bytes(&evicted);
            }
        }
        self.last
    }

    /// Oldest retained sequence number (`last + 1` when nothing is retained).
    pub(crate) fn first(&self) -> u64 {
        self.retained.front().map_or(self.last + 1, |m| m.0)
    }

    /// Newest sequence number posted (0 before the first post).
    pub(crate) fn last(&self) -> u64 {
        self.last
    }

    fn index(&self, seq: u64) -> Option<usize> {
        let first = self.retained.front()?.0;
        let i = usize::try_from(seq.checked_sub(first)?).ok()?;
        (i < self.retained.len()).then_some(i)
    }

    /// A retained message.
    pub(crate) fn get(&self, seq: u64) -> Option<&Value> {
        self.index(seq).map(|i| &self.retained[i].1)
    }

    /// Whether `seq` is retained and has never been on the wire (a post, not a re-send).
    pub(crate) fn unsent(&self, seq: u64) -> bool {
        self.index(seq)
            .is_some_and(|i| self.retained[i].3.is_none())
    }

    /// Records that `seq` went on the wire at `now`.
    pub(crate) fn mark_sent(&mut self, seq: u64, now: Instant) {
        if let Some(i) = self.index(seq) {
            self.retained[i].3 = Some(now);
        }
    }

    /// Takes the bytes of one re-send of `seq` from the repair allowance; `false` (and
    /// nothing taken) when the allowance is spent.
    pub(crate) fn spend_repair(&mut self, now: Instant, seq: u64) -> bool {
        let Some(i) = self.index(seq) else {
            return false;
        };
        let cap = REPAIR_SHARE * self.retained_bytes as f64 + 4.0 * REPAIR_TRICKLE_BYTES_PER_S;
        if let Some(at) = self.budget_at {
            let dt = now.saturating_duration_since(at).as_secs_f64();
            self.repair_budget += dt * REPAIR_TRICKLE_BYTES_PER_S;
        }
        self.repair_budget = self.repair_budget.min(cap);
        self.budget_at = Some(now);
        let cost = message_bytes(&self.retained[i].1) as f64;
        if self.repair_budget < cost {
            return false;
        }
        self.repair_budget -= cost;
        true
    }

    /// Retained messages of `first..=last` not sent within `quiet` before `now`: what to
    /// re-send for a NACK (several receivers NACKing one loss cause one re-send).
    pub(crate) fn to_resend(
        &self,
        first: u64,
        last: u64,
        now: Instant,
        quiet: Duration,
    ) -> Vec<u64> {
        let from = first.max(self.first());
        let to = last.min(self.last);
        if from > to {
            return Vec::new();
        }
        let start = self.index(from).unwrap_or(0);
        self.retained
            .iter()
            .skip(start)
            .take_while(|m| m.0 <= to)
            .filter(|m| m.3.is_none_or(|t| t + quiet <= now))
            .map(|m| m.0)
            .collect()
    }
}

/// What a receiver hands up, in order.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Delivery {
    /// The next message of the queue; `None`: its value has a tag this build does not
    /// know (a newer build's), handed up as skipped.
    Message { seq: u64, value: Option<Value> },
    /// Messages `first..=last` will never arrive.
    GivenUp { first: u64, last: u64 },
}

/// Whether a received talk item was taken into account.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Heard {
    /// Used (or a harmless duplicate).
    Taken,
    /// Not plausible from a real sender, or over a bound: ignored.
    Refused,
}

/// The receiver's side of one (sender incarnation, queue).
#[derive(Debug)]
pub(crate) struct Inbox {
    next: u64,
    buffer: BTreeMap<u64, Option<Value>>,
    buffered_bytes: usize,
    known_last: u64,
    /// From which sequence number on messages became known to exist, and when: increasing
    /// in both; the entry at or below `next` tells when `next` became known missing.
    known_since: VecDeque<(u64, Instant)>,
    /// When to NACK next, and how many NACKs the current gap has had.
    nack_at: Option<Instant>,
    nacks: u32,
    /// A head asked to give up more than a window at once: its `first`, until a later
    /// head agrees.
    unconfirmed_jump: Option<u64>,
}

impl Default for Inbox {
    fn default() -> Inbox {
        Inbox::starting_at(1)
    }
}

impl Inbox {
    /// An inbox whose first message to deliver is `next`.
    pub(crate) fn starting_at(next: u64) -> Inbox {
        let next = next.max(1);
        Inbox {
            next,
            buffer: BTreeMap::new(),
            buffered_bytes: 0,
            known_last: next - 1,
            known_since: VecDeque::new(),
            nack_at: None,
            nacks: 0,
            unconfirmed_jump: None,
        }
    }

    /// Bytes held in the reorder buffer.
    pub(crate) fn buffered_bytes(&self) -> usize {
        self.buffered_bytes
    }

    /// Messages up to `last` are now known to exist (from `now` on, for those new).
    fn learn(&mut self, now: Instant, last: u64) {
        if last > self.known_last {
            self.known_since.push_back((self.known_last + 1, now));
            self.known_last = last;
        }
    }

    /// A message arrived. `room` is how many more bytes the replica lets all reorder
    /// buffers hold.
    pub(crate) fn on_message(
        &mut self,
        now: Instant,
        seq: u64,
        value: Option<Value>,
        limits: &TalkLimits,
        room: usize,
        out: &mut Vec<Delivery>,
    ) -> Heard {
        let window_end = self.next.saturating_add(limits.window as u64);
        if seq >= window_end {
            // Beyond the window: it opens no gap; the sender's head will, if it is real.
            return Heard::Refused;
        }
        let mut heard = Heard::Taken;
        if seq == self.next {
            self.learn(now, seq);
            out.push(Delivery::Message { seq, value });
            self.next += 1;
            self.drain(out);
        } else if seq > self.next {
            self.learn(now, seq);
            if !self.buffer.contains_key(&seq) {
                let bytes = value.as_ref().map_or(0, message_bytes);
                if bytes > room || self.buffered_bytes + bytes > limits.window_bytes {
                    // Over the byte bound: dropped; a NACK brings it back later.
                    heard = Heard::Refused;
                } else {
                    self.buffered_bytes += bytes;
                    self.buffer.insert(seq, value);
                }
            }
        }
        self.update_gap(now, limits);
        heard
    }

    /// The sender says it holds `first..=last`: anything older than `first` is gone.
    pub(crate) fn on_head(
        &mut self,
        now: Instant,
        first: u64,
        last: u64,
        limits: &TalkLimits,
        out: &mut Vec<Delivery>,
    ) -> Heard {
        if first > last.saturating_add(1) || last - first.min(last) >= MAX_HEAD_SPAN {
            return Heard::Refused;
        }
        if first > self.next.saturating_add(limits.window as u64) {
            // It would give up more than a window at once: only if a later head agrees.
            if self.unconfirmed_jump.is_none_or(|j| first < j) {
                self.unconfirmed_jump = Some(first);
                return Heard::Refused;
            }
        }
        self.unconfirmed_jump = None;
        self.learn(now, last);
        if first > self.next {
            self.give_up_until(first, out);
        }
        self.update_gap(now, limits);
        Heard::Taken
    }

    /// Delivers buffered messages below `until` in order, giving up the missing ones,
    /// and moves `next` to at least `until`.
    fn give_up_until(&mut self, until: u64, out: &mut Vec<Delivery>) {
        while self.next < until {
            match self.buffer.pop_first() {
                Some((seq, value)) if seq < until => {
                    self.buffered_bytes -= value.as_ref().map_or(0, message_bytes);
                    if seq > self.next {
                        out.push(Delivery::GivenUp {
                            first: self.next,
                            last: seq - 1,
                        });
                    }
                    out.push(Delivery::Message { seq, value });
                    self.next = seq + 1;
                }
                Some((seq, value)) => {
                    self.buffer.insert(seq, value);
                    out.push(Delivery::GivenUp {
                        first: self.next,
                        last: until - 1,
                    });
                    self.next = until;
                }
                None => {
                    out.push(Delivery::GivenUp {
                        first: self.next,
                        last: until - 1,
                    });
                    self.next = until;
                }
            }
        }
        self.drain(out);
    }

    fn drain(&mut self, out: &mut Vec<Delivery>) {
        while let Some(value) = self.buffer.remove(&self.next) {
            self.buffered_bytes -= value.as_ref().map_or(0, message_bytes);
            out.push(Delivery::Message {
                seq: self.next,
                value,
            });
            self.next += 1;
        }
        // Stale entries cannot exist (only seqs > next are buffered), but keep the
        // invariant cheap to trust.
        while let Some((&s, _)) = self.buffer.first_key_value() {
            if s >= self.next {
                break;
            }
            if let Some((_, v)) = self.buffer.pop_first() {
                self.buffered_bytes -= v.as_ref().map_or(0, message_bytes);
            }
        }
        // Forget when messages before `next` became known.
        while self.known_since.len() >= 2 && self.known_since[1].0 <= self.next {
            self.known_since.pop_front();
        }
    }

    fn has_gap(&self) -> bool {
        self.known_last >= self.next
    }

    /// When message `next` became known missing.
    fn missing_since(&self) -> Option<Instant> {
        if !self.has_gap() {
            return None;
        }
        self.known_since
            .iter()
            .take_while(|(from, _)| *from <= self.next)
            .last()
            .map(|&(_, at)| at)
    }

    fn update_gap(&mut self, now: Instant, limits: &TalkLimits) {
        if !self.has_gap() {
            self.nack_at = None;
            self.nacks = 0;
        } else if self.nack_at.is_none() {
            self.nack_at = Some(now + limits.nack_interval);
        }
    }

    /// When this inbox next needs `on_timeout`.
    pub(crate) fn deadline(&self, limits: &TalkLimits) -> Option<Instant> {
        let give_up = self.missing_since().map(|t| t + limits.give_up_after);
        match (self.nack_at, give_up) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Up to [`NACK_SPANS`] missing spans in the window, for a NACK: enough that every
    /// message known missing is asked for while its give-up time runs.
    pub(crate) fn missing(&self, limits: &TalkLimits) -> Vec<(u64, u64)> {
        let horizon = self
            .known_last
            .min(self.next.saturating_add(limits.window as u64 - 1));
        let mut spans = Vec::new();
        let mut from = self.next;
        for &seq in self.buffer.keys() {
            if spans.len() == NACK_SPANS || from > horizon {
                break;
            }
            if seq > from {
                spans.push((from, (seq - 1).min(horizon)));
            }
            from = seq + 1;
        }
        if spans.len() < NACK_SPANS && from <= horizon {
            spans.push((from, horizon));
        }
        spans
    }

    /// Timers: gives up the messages that have been known missing for `give_up_after`,
    /// and returns the spans to NACK now (if any).
    pub(crate) fn on_timeout(
        &mut self,
        now: Instant,
        limits: &TalkLimits,
        out: &mut Vec<Delivery>,
    ) -> Vec<(u64, u64)> {
        while let Some(since) = self.missing_since() {
            if now < since + limits.give_up_after {
                break;
            }
            // Give up the missing run at `next`, but only as far as its messages have
            // been known missing that long; later ones get their own time.
            let buffered = self.buffer.keys().next().copied();
            let due_until = self
                .known_since
                .iter()
                .find(|(from, at)| *from > self.next && now < *at + limits.give_up_after)
                .map(|&(from, _)| from);
            let until = [buffered, due_until, Some(self.known_last + 1)]
                .into_iter()
                .flatten()
                .min()
                .unwrap_or(self.known_last + 1);
            self.give_up_until(until, out);
            self.nacks = 0;
        }
        self.update_gap(now, limits);
        match self.nack_at {
            Some(at) if now >= at && self.has_gap() => {
                self.nacks = self.nacks.saturating_add(1);
                // 1, 1, 2, 3, 3, ... intervals: quick repair first, then no flood.
                let factor = match self.nacks {
                    0..=2 => 1,
                    3 => 2,
                    _ => 3,
                };
                self.nack_at = Some(now + limits.nack_interval * factor);
                self.missing(limits)
            }
            _ => Vec::new(),
        }
    }

    /// The sender restarted: hand up what is buffered, give up the holes, forget.
    pub(crate) fn flush(&mut self, out: &mut Vec<Delivery>) {
        let until = self.known_last + 1;
        self.give_up_until(until, out);
        *self = Inbox::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(ms: u64) -> Instant {
        Instant::from_micros(ms * 1000)
    }
    const ROOM: usize = usize::MAX / 2;

    fn msg(seq: u64) -> Delivery {
        Delivery::Message {
            seq,
            value: Some(Value::Int(seq as i64)),
        }
    }

    #[test]
    fn reordered_and_duplicated_messages_come_out_once_in_order() {
        let limits = TalkLimits::default();
        let mut inbox = Inbox::default();
        let mut out = Vec::new();
        for seq in [2, 3, 2, 1, 3, 4, 1] {
            inbox.on_message(
                t(0),
                seq,
                Some(Value::Int(seq as i64)),
                &limits,
                ROOM,
                &mut out,
            );
        }
        assert_eq!(out, vec![msg(1), msg(2), msg(3), msg(4)]);
        assert_eq!(inbox.deadline(&limits), None, "no gap left");
    }

    #[test]
    fn a_gap_is_nacked_after_the_interval_and_given_up_after_the_limit() {
        let limits = TalkLimits::default();
        let mut inbox = Inbox::default();
        let mut out = Vec::new();
        inbox.on_message(t(0), 1, Some(Value::Int(1)), &limits, ROOM, &mut out);
        inbox.on_message(t(0), 4, Some(Value::Int(4)), &limits, ROOM, &mut out);
        inbox.on_head(t(0), 1, 6, &limits, &mut out);
        assert_eq!(
            inbox.on_timeout(t(10), &limits, &mut out),
            vec![],
            "too early"
        );
        assert_eq!(
            inbox.on_timeout(t(20), &limits, &mut out),
            vec![(2, 3), (5, 6)]
        );
        assert_eq!(inbox.deadline(&limits), Some(t(40)));
        inbox.on_message(t(30), 3, Some(Value::Int(3)), &limits, ROOM, &mut out);
        inbox.on_timeout(t(1000), &limits, &mut out);
        assert_eq!(
            out,
            vec![
                msg(1),
                Delivery::GivenUp { first: 2, last: 2 },
                msg(3),
                msg(4),
                Delivery::GivenUp { first: 5, last: 6 },
            ],
            "after 1 s message 2 is given up and 3, 4 follow in order; 5 and 6, known \
             missing since the head at 0 ms, are due too"
        );
    }

    #[test]
    fn a_head_past_next_gives_up_evicted_messages_at_once() {
        let limits = TalkLimits::default();
        let mut inbox = Inbox::default();
        let mut out = Vec::new();
        inbox.on_message(t(0), 3, Some(Value::Int(3)), &limits, ROOM, &mut out);
        inbox.on_head(t(0), 5, 6, &limits, &mut out);
        assert_eq!(
            out,
            vec![
                Delivery::GivenUp { first: 1, last: 2 },
                msg(3),
                Delivery::GivenUp { first: 4, last: 4 }
            ]
        );
        assert_eq!(inbox.missing(&limits), vec![(5, 6)]);
    }

    #[test]
    fn the_outbox_keeps_a_bounded_tail_and_suppresses_repeat_resends() {
        let mut outbox = Outbox::default();
        for i in 1..=5 {
            outbox.post(t(0), Value::Int(i), 3);
        }
        assert_eq!((outbox.first(), outbox.last()), (3, 5));
        assert_eq!(outbox.get(2), None);
        assert_eq!(outbox.get(4), Some(&Value::Int(4)));
        outbox.mark_sent(4, t(100));
        let quiet = Duration::from_millis(10);
        assert_eq!(outbox.to_resend(1, 9, t(105), quiet), vec![3, 5]);
        assert_eq!(outbox.to_resend(1, 9, t(110), quiet), vec![3, 4, 5]);
    }
}
