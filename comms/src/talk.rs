//! Talk queues: exactly-once, in-order delivery of each sender's queue to every teammate
//! over a lossy, duplicating, reordering network.
//!
//! The sender numbers its messages per queue (1, 2, ... within one incarnation), keeps
//! the last `retain` of them for repair, and advertises the span it still holds (`TalkHead`
//! with every refresh). A receiver delivers message `next` and whatever follows it from
//! its reorder buffer; a gap (a later message, or a head beyond `next`) starts a timer:
//! after `nack_interval` it asks the sender to re-send the missing span (NACK), again
//! every `nack_interval`, and after `give_up_after` (or at once, when the sender's head
//! says the messages were evicted) it gives the span up and reports it. Memory is bounded
//! on both sides: `retain` messages per own queue, `window` buffered messages per
//! (sender, queue), `max_queues` queues per sender.

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use crate::time::Instant;
use crate::value::Value;

/// Limits and timers of the talk queues.
#[derive(Clone, Debug, PartialEq)]
pub struct TalkLimits {
    /// Messages kept per own queue for repair (default 256).
    pub retain: usize,
    /// Out-of-order messages buffered per (sender, queue) (default 256).
    pub window: usize,
    /// Queues tracked per sender, and own queues (default 64).
    pub max_queues: usize,
    /// Delay before the first NACK of a gap, and between NACKs (default 20 ms).
    pub nack_interval: Duration,
    /// How long a gap may stay open before its messages are given up (default 1 s).
    pub give_up_after: Duration,
}

impl Default for TalkLimits {
    fn default() -> TalkLimits {
        TalkLimits {
            retain: 256,
            window: 256,
            max_queues: 64,
            nack_interval: Duration::from_millis(20),
            give_up_after: Duration::from_secs(1),
        }
    }
}

/// The sender's side of one queue.
#[derive(Debug, Default)]
pub(crate) struct Outbox {
    last: u64,
    /// Contiguous, oldest first: (seq, message, when last put on the wire).
    retained: VecDeque<(u64, Value, Option<Instant>)>,
}

impl Outbox {
    /// Numbers and keeps a new message; returns its sequence number.
    pub(crate) fn post(&mut self, value: Value, retain: usize) -> u64 {
        self.last += 1;
        self.retained.push_back((self.last, value, None));
        while self.retained.len() > retain.max(1) {
            self.retained.pop_front();
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

    /// Records that `seq` went on the wire at `now`.
    pub(crate) fn mark_sent(&mut self, seq: u64, now: Instant) {
        if let Some(i) = self.index(seq) {
            self.retained[i].2 = Some(now);
        }
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
            .filter(|m| m.2.is_none_or(|t| t + quiet <= now))
            .map(|m| m.0)
            .collect()
    }
}

/// What a receiver hands up, in order.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Delivery {
    /// The next message of the queue.
    Message { seq: u64, value: Value },
    /// Messages `first..=last` will never arrive.
    GivenUp { first: u64, last: u64 },
}

/// The receiver's side of one (sender incarnation, queue).
#[derive(Debug)]
pub(crate) struct Inbox {
    next: u64,
    buffer: BTreeMap<u64, Value>,
    known_last: u64,
    /// Since when the gap at `next` has been open, and when to NACK next.
    gap: Option<(Instant, Instant)>,
}

impl Default for Inbox {
    fn default() -> Inbox {
        Inbox {
            next: 1,
            buffer: BTreeMap::new(),
            known_last: 0,
            gap: None,
        }
    }
}

impl Inbox {
    /// A message arrived.
    pub(crate) fn on_message(
        &mut self,
        now: Instant,
        seq: u64,
        value: Value,
        limits: &TalkLimits,
        out: &mut Vec<Delivery>,
    ) {
        self.known_last = self.known_last.max(seq);
        if seq == self.next {
            out.push(Delivery::Message { seq, value });
            self.next += 1;
            self.drain(out);
        } else if seq > self.next && seq - self.next < limits.window as u64 {
            // Beyond the window it is dropped; the NACK will bring it back later.
            self.buffer.entry(seq).or_insert(value);
        }
        self.update_gap(now, limits);
    }

    /// The sender says it holds `first..=last`: anything older than `first` is gone.
    pub(crate) fn on_head(
        &mut self,
        now: Instant,
        first: u64,
        last: u64,
        limits: &TalkLimits,
        out: &mut Vec<Delivery>,
    ) {
        self.known_last = self.known_last.max(last);
        if first > self.next {
            self.give_up_until(first, out);
        }
        self.update_gap(now, limits);
    }

    /// Delivers buffered messages below `until` in order, giving up the missing ones,
    /// and moves `next` to at least `until`.
    fn give_up_until(&mut self, until: u64, out: &mut Vec<Delivery>) {
        while self.next < until {
            match self.buffer.pop_first() {
                Some((seq, value)) if seq < until => {
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
            out.push(Delivery::Message {
                seq: self.next,
                value,
            });
            self.next += 1;
        }
        // Stale entries cannot exist (only seqs > next are buffered), but keep the
        // invariant cheap to trust.
        while self
            .buffer
            .first_key_value()
            .is_some_and(|(&s, _)| s < self.next)
        {
            self.buffer.pop_first();
        }
    }

    fn has_gap(&self) -> bool {
        self.known_last >= self.next
    }

    fn update_gap(&mut self, now: Instant, limits: &TalkLimits) {
        match (self.has_gap(), self.gap) {
            (false, _) => self.gap = None,
            (true, None) => self.gap = Some((now, now + limits.nack_interval)),
            (true, Some(_)) => {}
        }
    }

    /// When this inbox next needs `on_timeout`.
    pub(crate) fn deadline(&self, limits: &TalkLimits) -> Option<Instant> {
        self.gap
            .map(|(since, nack_at)| nack_at.min(since + limits.give_up_after))
    }

    /// Up to four missing spans in the window, for a NACK.
    pub(crate) fn missing(&self, limits: &TalkLimits) -> Vec<(u64, u64)> {
        let horizon = self
            .known_last
            .min(self.next.saturating_add(limits.window as u64 - 1));
        let mut spans = Vec::new();
        let mut from = self.next;
        for &seq in self.buffer.keys() {
            if spans.len() == 4 || from > horizon {
                break;
            }
            if seq > from {
                spans.push((from, (seq - 1).min(horizon)));
            }
            from = seq + 1;
        }
        if spans.len() < 4 && from <= horizon {
            spans.push((from, horizon));
        }
        spans
    }

    /// Timers: returns the spans to NACK now (if any) and gives up a gap that stayed
    /// open too long.
    pub(crate) fn on_timeout(
        &mut self,
        now: Instant,
        limits: &TalkLimits,
        out: &mut Vec<Delivery>,
    ) -> Vec<(u64, u64)> {
        let Some((since, nack_at)) = self.gap else {
            return Vec::new();
        };
        if now >= since + limits.give_up_after {
            // Give up the first missing span only; later ones get their own time.
            let until = self
                .buffer
                .keys()
                .next()
                .copied()
                .unwrap_or(self.known_last + 1);
            self.give_up_until(until, out);
            self.gap = None;
            self.update_gap(now, limits);
            return Vec::new();
        }
        if now >= nack_at {
            self.gap = Some((since, now + limits.nack_interval));
            return self.missing(limits);
        }
        Vec::new()
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
    fn msg(seq: u64) -> Delivery {
        Delivery::Message {
            seq,
            value: Value::Int(seq as i64),
        }
    }

    #[test]
    fn reordered_and_duplicated_messages_come_out_once_in_order() {
        let limits = TalkLimits::default();
        let mut inbox = Inbox::default();
        let mut out = Vec::new();
        for seq in [2, 3, 2, 1, 3, 4, 1] {
            inbox.on_message(t(0), seq, Value::Int(seq as i64), &limits, &mut out);
        }
        assert_eq!(out, vec![msg(1), msg(2), msg(3), msg(4)]);
        assert_eq!(inbox.deadline(&limits), None, "no gap left");
    }

    #[test]
    fn a_gap_is_nacked_after_the_interval_and_given_up_after_the_limit() {
        let limits = TalkLimits::default();
        let mut inbox = Inbox::default();
        let mut out = Vec::new();
        inbox.on_message(t(0), 1, Value::Int(1), &limits, &mut out);
        inbox.on_message(t(0), 4, Value::Int(4), &limits, &mut out);
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
        inbox.on_message(t(30), 3, Value::Int(3), &limits, &mut out);
        inbox.on_timeout(t(1000), &limits, &mut out);
        assert_eq!(
            out,
            vec![
                msg(1),
                Delivery::GivenUp { first: 2, last: 2 },
                msg(3),
                msg(4)
            ],
            "after 1 s message 2 is given up and 3, 4 follow in order"
        );
    }

    #[test]
    fn a_head_past_next_gives_up_evicted_messages_at_once() {
        let limits = TalkLimits::default();
        let mut inbox = Inbox::default();
        let mut out = Vec::new();
        inbox.on_message(t(0), 3, Value::Int(3), &limits, &mut out);
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
            outbox.post(Value::Int(i), 3);
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
