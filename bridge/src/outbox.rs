//! Between the exporter and Zenoh: a queue that hands every version of every key to
//! Zenoh in order, and falls back to the latest value per key when Zenoh falls behind.
//!
//! The field thread pushes the exporter's operations; the publisher thread takes them
//! all at once and hands them to Zenoh with blocking congestion control. Up to
//! [`CAPACITY`] operations wait in order for up to [`MAX_WAIT`], each version of a key in
//! its own place: a scheduling stall of the publisher thread (tens of ms on a loaded
//! machine, longer than a 100 Hz key's period) loses nothing. Only when Zenoh pushes back
//! for real (a slow subscriber, a busy router: the queue full, or its oldest operation
//! waiting longer than that) does the queue fall back to the latest value per key: the
//! waiting values are compacted to each key's newest, and a value pushed for a key
//! already waiting replaces that key's value in its place (both counted as `coalesced`).
//! The queue then grows by at most one operation per key, so it stays bounded and fresh
//! (a slow reader gets each key's newest value, not a backlog), the field thread never
//! waits for Zenoh, and what is dropped is only ever a value that a newer one of the
//! same key superseded. The newest value of each key is
//! always in the queue or already handed over. Talk messages (each one counts) and
//! liveliness changes (their order counts) are never merged.
//!
//! Until the seventh session the queue merged a key's waiting value whenever a newer one
//! came, full or not: on the 2-core test machine the publisher thread's stalls merged
//! 10–15 % of the 100 k updates/s load phase (docs/bridge.md).
//!
//! A value's age was computed when the exporter decided it; the publisher adds the time
//! it waited here ([`Outbox::take`] returns it with each value), so an age is never
//! below the true one however long Zenoh blocked. Sans-IO: times are arguments.

use std::collections::{HashMap, VecDeque};

use std::time::Duration;

use comms::Instant;

use crate::export::{Op, Sample};

/// Operations that wait in order before values start to merge: 0.65 s of the issue's
/// load target (100 k updates/s), a few MB of samples.
pub const CAPACITY: usize = 65_536;

/// How long the oldest operation may wait before the queue falls back to the latest
/// value per key: far above a scheduling stall, short enough that a slow reader does not
/// get a backlog of stale versions.
pub const MAX_WAIT: Duration = Duration::from_millis(500);

/// Counters of the queue.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct OutboxStats {
    /// Values replaced in the queue by a newer value of the same key before Zenoh took
    /// them (the newer one went instead), because Zenoh pushed back (the queue full, or
    /// its oldest operation waiting longer than [`MAX_WAIT`]).
    pub coalesced: u64,
    /// The longest the queue has been (operations waiting).
    pub high_water: u64,
}

#[derive(Debug)]
enum Slot {
    /// A value, with when its age was computed.
    Value(Sample, Instant),
    /// A talk message or a liveliness change, in its place.
    Other(Op, Instant),
}

/// The queue; see the module docs.
#[derive(Debug)]
pub struct Outbox {
    order: VecDeque<Slot>,
    /// The position (in `order`) of each key's newest waiting value.
    newest: HashMap<String, usize>,
    /// When the queue last went from empty to waiting.
    since: Option<Instant>,
    capacity: usize,
    max_wait: Duration,
    /// Zenoh pushed back since the last take: values merge.
    merging: bool,
    stats: OutboxStats,
}

impl Default for Outbox {
    fn default() -> Outbox {
        Outbox::new()
    }
}

impl Outbox {
    /// An empty queue of [`CAPACITY`] and [`MAX_WAIT`].
    pub fn new() -> Outbox {
        Outbox::with_limits(CAPACITY, MAX_WAIT)
    }

    /// An empty queue whose values merge once `capacity` operations wait or the oldest
    /// has waited `max_wait`.
    pub fn with_limits(capacity: usize, max_wait: Duration) -> Outbox {
        Outbox {
            order: VecDeque::new(),
            newest: HashMap::new(),
            since: None,
            capacity,
            max_wait,
            merging: false,
            stats: OutboxStats::default(),
        }
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
            .all(|slot| matches!(slot, Slot::Value(..) | Slot::Other(Op::Talk(_), _)))
    }

    /// Since when the oldest waiting operation has waited.
    pub fn waiting_since(&self) -> Option<Instant> {
        self.since
    }

    /// Queues `op`, decided at `now`. A value goes in its own place until Zenoh pushes
    /// back (see the module docs); then it replaces its key's waiting value.
    pub fn push(&mut self, now: Instant, op: Op) {
        let since = *self.since.get_or_insert(now);
        if !self.merging
            && (self.order.len() >= self.capacity
                || now.saturating_duration_since(since) >= self.max_wait)
        {
            self.merging = true;
            self.compact();
        }
        match op {
            Op::Put(sample) => match self.newest.get(&sample.key) {
                Some(&at) if self.merging => {
                    self.order[at] = Slot::Value(sample, now);
                    self.stats.coalesced += 1;
                }
                _ => {
                    self.newest.insert(sample.key.clone(), self.order.len());
                    self.order.push_back(Slot::Value(sample, now));
                }
            },
            other => self.order.push_back(Slot::Other(other, now)),
        }
        self.stats.high_water = self.stats.high_water.max(self.order.len() as u64);
    }

    /// Keeps of the waiting values only each key's newest, in its place.
    fn compact(&mut self) {
        let before = self.order.len();
        let newest = std::mem::take(&mut self.newest);
        self.order = std::mem::take(&mut self.order)
            .into_iter()
            .enumerate()
            .filter(|(i, slot)| match slot {
                Slot::Value(sample, _) => newest.get(&sample.key) == Some(i),
                Slot::Other(..) => true,
            })
            .map(|(_, slot)| slot)
            .collect();
        self.stats.coalesced += (before - self.order.len()) as u64;
        for (i, slot) in self.order.iter().enumerate() {
            if let Slot::Value(sample, _) = slot {
                self.newest.insert(sample.key.clone(), i);
            }
        }
    }

    /// Takes everything waiting at `now`, oldest first, each value's age advanced by the
    /// time it waited.
    pub fn take(&mut self, now: Instant) -> Vec<Op> {
        self.since = None;
        self.merging = false;
        self.newest.clear();
        self.order
            .drain(..)
            .map(|slot| match slot {
                Slot::Value(sample, at) => Op::Put(sample.aged(now.saturating_duration_since(at))),
                Slot::Other(Op::Talk(sample), at) => {
                    Op::Talk(sample.aged(now.saturating_duration_since(at)))
                }
                Slot::Other(op, _) => op,
            })
            .collect()
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

    /// The load target's traffic (1,000 keys at 100 Hz) while the publisher thread is
    /// descheduled for 50 ms: five versions of every key wait, and every one of them goes
    /// out, in order, none merged. (The queue before the seventh session merged them to
    /// 1,000 values: 80 % of the versions lost to a scheduling stall.)
    #[test]
    fn a_stall_below_capacity_hands_over_every_version_in_order() {
        let mut q = Outbox::new();
        for tick in 1..=5u64 {
            for k in 0..1000 {
                q.push(at(tick * 10), value(&format!("k{k}"), tick, 0));
            }
        }
        assert_eq!(q.stats().coalesced, 0, "nothing merged below the capacity");
        let out = payloads(&q.take(at(50)));
        assert_eq!(out.len(), 5000, "every version of every key");
        let expected: Vec<(String, String)> = (1..=5u64)
            .flat_map(|tick| (0..1000).map(move |k| (format!("k{k}"), tick.to_string())))
            .collect();
        assert_eq!(out, expected, "in the order the versions came");
    }

    /// Zenoh is blocked and the queue fills (capacity 2 here) while a robot changes key
    /// `a` 1,000 times and `b` once: from then on the queue holds one value per key, the
    /// newest of each, in the order the keys first waited.
    #[test]
    fn a_full_queue_merges_to_each_keys_newest_value() {
        let mut q = Outbox::with_limits(2, MAX_WAIT);
        for v in 1..=1000 {
            q.push(at(0), value("a", v, 0));
            if v == 10 {
                q.push(at(0), value("b", 7, 0));
            }
        }
        assert_eq!(q.len(), 2, "one waiting value per key");
        assert_eq!(q.stats().coalesced, 999);
        let out = q.take(at(1));
        assert_eq!(
            payloads(&out),
            vec![("a".into(), "1000".into()), ("b".into(), "7".into())],
            "the newest value of each key, nothing in between"
        );
        assert!(q.is_empty());
        q.push(at(2), value("a", 1001, 0));
        q.push(at(2), value("a", 1002, 0));
        assert_eq!(q.len(), 2, "after a take, versions wait in order again");
    }

    /// A reader so slow that Zenoh blocks the publisher for 0.6 s while 100 keys change
    /// at 100 Hz: below the capacity, but once the oldest value has waited MAX_WAIT
    /// (0.5 s) the queue compacts to each key's newest and merges from then on, so the
    /// reader gets 100 fresh values, not 6,000 stale ones.
    #[test]
    fn zenoh_blocked_past_the_wait_bound_gets_the_latest_values() {
        let mut q = Outbox::new();
        for tick in 0..60u64 {
            for k in 0..100 {
                q.push(at(tick * 10), value(&format!("k{k}"), tick, 0));
            }
        }
        assert_eq!(q.len(), 100, "one value per key once Zenoh pushed back");
        assert_eq!(q.stats().coalesced, 5900);
        let out = payloads(&q.take(at(600)));
        assert!(
            out.iter().all(|(_, v)| v == "59"),
            "every key's newest value: {out:?}"
        );
    }

    /// Talk messages are a queue (each one is delivered), and a restart's withdrawal
    /// comes before its new token: neither is merged or reordered.
    #[test]
    fn talk_and_liveliness_keep_every_item_in_order() {
        // Capacity 1: values merge, talk and liveliness do not.
        let mut q = Outbox::with_limits(1, MAX_WAIT);
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
        let ages: Vec<_> = out
            .iter()
            .map(|op| match op {
                Op::Put(s) => parse_attachment(&s.attachment()),
                other => panic!("a value: {other:?}"),
            })
            .collect();
        assert_eq!(
            ages,
            vec![
                Some((1, 1, Duration::from_millis(5 + 50))),
                Some((1, 2, Duration::from_millis(3 + 40)))
            ],
            "the exporter's age + the time in the queue"
        );
    }

    proptest::proptest! {
        /// Any interleaving of values over a few keys, taken at any points, at any
        /// capacity: every key's last pushed value is the last one taken for it, the queue
        /// never exceeds its capacity by more than the number of keys, and nothing merges
        /// while it is below its capacity (what is taken is then exactly what was pushed).
        #[test]
        fn the_last_value_of_every_key_is_the_last_taken(
            steps in proptest::collection::vec((0u8..5, proptest::bool::ANY), 1..300),
            capacity in 1usize..40,
        ) {
            let mut q = Outbox::with_limits(capacity, Duration::from_secs(3600));
            let mut last_pushed: HashMap<String, String> = HashMap::new();
            let mut last_taken: HashMap<String, String> = HashMap::new();
            let (mut pushed, mut taken) = (0u64, 0u64);
            for (i, (k, take)) in steps.iter().enumerate() {
                let key = format!("k{k}");
                q.push(at(i as u64), value(&key, i as u64, 0));
                pushed += 1;
                last_pushed.insert(key, i.to_string());
                proptest::prop_assert!(q.len() <= capacity + 5);
                if *take {
                    for (key, payload) in payloads(&q.take(at(i as u64))) {
                        taken += 1;
                        last_taken.insert(key, payload);
                    }
                }
            }
            for (key, payload) in payloads(&q.take(at(1000))) {
                taken += 1;
                last_taken.insert(key, payload);
            }
            proptest::prop_assert_eq!(last_taken, last_pushed);
            proptest::prop_assert_eq!(taken + q.stats().coalesced, pushed);
            if steps.len() <= capacity {
                proptest::prop_assert_eq!(q.stats().coalesced, 0);
            }
        }
    }
}
