//! Between the exporter and Zenoh: a latest-value queue, so that the last value of every
//! key always goes out, however far Zenoh falls behind.
//!
//! The field thread pushes the exporter's operations; the publisher thread takes them
//! all at once and hands them to Zenoh with blocking congestion control. While Zenoh
//! blocks (a slow subscriber, a busy router), a value pushed for a key already waiting
//! replaces the waiting one in its place: the queue holds at most one value per key, so
//! it is bounded by the number of keys, the field thread never waits for Zenoh, and
//! what is dropped is only ever a value that a newer one of the same key superseded. The
//! newest value of each key is always in the queue or already handed over (a final
//! flush with nothing to flush). Talk messages (each one counts) and liveliness changes
//! (their order counts) are never merged; they keep their place among the values.
//!
//! A value's age was computed when the exporter decided it; the publisher adds the time
//! it waited here ([`Outbox::take`] returns it with each value), so an age is never
//! below the true one however long Zenoh blocked. Sans-IO: times are arguments.

use std::collections::{HashMap, VecDeque};

use comms::Instant;

use crate::export::{Op, Sample};

/// Counters of the queue.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct OutboxStats {
    /// Values replaced in the queue by a newer value of the same key before Zenoh took
    /// them (the newer one went instead).
    pub coalesced: u64,
    /// The longest the queue has been (operations waiting).
    pub high_water: u64,
}

#[derive(Debug)]
enum Slot {
    /// A value: its sample is in `values` under this key.
    Value(String),
    /// A talk message or a liveliness change, in its place.
    Other(Op, Instant),
}

/// The latest-value queue; see the module docs.
#[derive(Debug, Default)]
pub struct Outbox {
    order: VecDeque<Slot>,
    /// The waiting value of each key, with when its age was computed.
    values: HashMap<String, (Sample, Instant)>,
    /// When the queue last went from empty to waiting.
    since: Option<Instant>,
    stats: OutboxStats,
}

impl Outbox {
    /// An empty queue.
    pub fn new() -> Outbox {
        Outbox::default()
    }

    /// The counters.
    pub fn stats(&self) -> &OutboxStats {
        &self.stats
    }

    /// Operations waiting.
    pub fn len(&self) -> usize {
        self.order.len()
    }

    /// Whether nothing waits.
    pub fn is_empty(&self) -> bool {
        self.order.is_empty()
    }

    /// Whether only values and talk messages wait (no liveliness change).
    pub fn only_samples(&self) -> bool {
        self.order
            .iter()
            .all(|slot| matches!(slot, Slot::Value(_) | Slot::Other(Op::Talk(_), _)))
    }

    /// Since when the oldest waiting operation has waited.
    pub fn waiting_since(&self) -> Option<Instant> {
        self.since
    }

    /// Queues `op`, decided at `now`: a value replaces its key's waiting value in place.
    pub fn push(&mut self, now: Instant, op: Op) {
        self.since.get_or_insert(now);
        match op {
            Op::Put(sample) => {
                if let Some(waiting) = self.values.get_mut(&sample.key) {
                    *waiting = (sample, now);
                    self.stats.coalesced += 1;
                } else {
                    self.order.push_back(Slot::Value(sample.key.clone()));
                    self.values.insert(sample.key.clone(), (sample, now));
                }
            }
            other => self.order.push_back(Slot::Other(other, now)),
        }
        self.stats.high_water = self.stats.high_water.max(self.order.len() as u64);
    }

    /// Takes everything waiting at `now`, oldest first, each value's age advanced by the
    /// time it waited.
    pub fn take(&mut self, now: Instant) -> Vec<Op> {
        self.since = None;
        let mut out = Vec::with_capacity(self.order.len());
        for slot in self.order.drain(..) {
            match slot {
                Slot::Value(key) => {
                    if let Some((sample, at)) = self.values.remove(&key) {
                        out.push(Op::Put(sample.aged(now.saturating_duration_since(at))));
                    }
                }
                Slot::Other(Op::Talk(sample), at) => {
                    out.push(Op::Talk(sample.aged(now.saturating_duration_since(at))));
                }
                Slot::Other(op, _) => out.push(op),
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::export::{parse_attachment, Meta};
    use std::time::Duration;

    fn at(ms: u64) -> Instant {
        Instant::from_micros(ms * 1000)
    }

    fn value(key: &str, v: u64, age_ms: u64) -> Op {
        Op::Put(Sample {
            key: key.to_owned(),
            payload: v.to_string(),
            meta: Meta::Value {
                incarnation: 1,
                version: v,
                age: Duration::from_millis(age_ms),
            },
            ros2: None,
        })
    }

    fn payloads(ops: &[Op]) -> Vec<(String, String)> {
        ops.iter()
            .map(|op| match op {
                Op::Put(s) | Op::Talk(s) => (s.key.clone(), s.payload.clone()),
                Op::Alive { key, .. } => (key.clone(), "alive".into()),
                Op::Gone { robot } => (robot.to_string(), "gone".into()),
            })
            .collect()
    }

    /// Zenoh is blocked while a robot changes key `a` 1,000 times and `b` once: the
    /// queue holds two values, the last of each, in the order the keys first waited.
    #[test]
    fn a_blocked_zenoh_gets_each_keys_newest_value_once() {
        let mut q = Outbox::new();
        for v in 1..=1000 {
            q.push(at(v), value("a", v, 0));
            if v == 10 {
                q.push(at(v), value("b", 7, 0));
            }
        }
        assert_eq!(q.len(), 2, "one waiting value per key");
        assert_eq!(q.stats().coalesced, 999);
        let out = q.take(at(1000));
        assert_eq!(
            payloads(&out),
            vec![("a".into(), "1000".into()), ("b".into(), "7".into())],
            "the newest value of each key, nothing in between"
        );
        assert!(q.is_empty());
    }

    /// Talk messages are a queue (each one is delivered), and a restart's withdrawal
    /// comes before its new token: neither is merged or reordered.
    #[test]
    fn talk_and_liveliness_keep_every_item_in_order() {
        let mut q = Outbox::new();
        let talk = |n: u64| {
            Op::Talk(Sample {
                key: "t".into(),
                payload: n.to_string(),
                meta: Meta::Talk {
                    incarnation: 1,
                    seq: n,
                },
                ros2: None,
            })
        };
        q.push(at(0), talk(1));
        q.push(at(0), Op::Gone { robot: 2 });
        q.push(at(0), value("a", 1, 0));
        q.push(
            at(0),
            Op::Alive {
                robot: 2,
                incarnation: 9,
                key: "alive".into(),
            },
        );
        q.push(at(0), talk(2));
        q.push(at(0), value("a", 2, 0));
        let got = payloads(&q.take(at(1)));
        assert_eq!(
            got,
            vec![
                ("t".into(), "1".into()),
                ("2".into(), "gone".into()),
                ("a".into(), "2".into()),
                ("alive".into(), "alive".into()),
                ("t".into(), "2".into()),
            ],
            "talk twice, the withdrawal before the token; the value in its first place"
        );
    }

    /// A value that waited 40 ms for Zenoh goes out 40 ms older than the exporter made it:
    /// the age in its attachment is never below the true one.
    #[test]
    fn the_time_spent_waiting_is_added_to_the_age() {
        let mut q = Outbox::new();
        q.push(at(100), value("a", 1, 5));
        q.push(at(110), value("a", 2, 3));
        let out = q.take(at(150));
        let Op::Put(s) = &out[0] else {
            panic!("a value: {out:?}")
        };
        assert_eq!(
            parse_attachment(&s.attachment()),
            Some((1, 2, Duration::from_millis(3 + 40))),
            "3 ms at the exporter + 40 ms in the queue"
        );
    }

    proptest::proptest! {
        /// Any interleaving of values over a few keys, taken at any points: every key's
        /// last pushed value is the last one taken for it, and the queue never holds two
        /// values of one key.
        #[test]
        fn the_last_value_of_every_key_is_the_last_taken(
            steps in proptest::collection::vec((0u8..5, proptest::bool::ANY), 1..300)
        ) {
            let mut q = Outbox::new();
            let mut last_pushed: HashMap<String, String> = HashMap::new();
            let mut last_taken: HashMap<String, String> = HashMap::new();
            for (i, (k, take)) in steps.iter().enumerate() {
                let key = format!("k{k}");
                q.push(at(i as u64), value(&key, i as u64, 0));
                last_pushed.insert(key, i.to_string());
                proptest::prop_assert!(q.len() <= 5);
                if *take {
                    for (key, payload) in payloads(&q.take(at(i as u64))) {
                        last_taken.insert(key, payload);
                    }
                }
            }
            for (key, payload) in payloads(&q.take(at(1000))) {
                last_taken.insert(key, payload);
            }
            proptest::prop_assert_eq!(last_taken, last_pushed);
        }
    }
}
