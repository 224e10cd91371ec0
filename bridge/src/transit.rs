//! Each frame's time on the air, estimated by a bridge that never sends.
//!
//! The robots measure transit from round trips of their own frames (echoes); the bridge
//! sends no frames, so its listening replica would take every frame to have arrived
//! instantly and report ages short by the transit (tens of ms on a loaded WLAN, more
//! with an access point holding multicast). What it hears instead:
//!
//! - **A sender's clock, anchored by its echoes.** The bridge and robot T hear robot S's
//!   frame q at the same moment (one medium: a multicast datagram reaches every listener
//!   together; the delay and the loss are the sender's link's). When T's frame f echoes
//!   q, held `hold` at T, f left at `reception(q) + hold` on the bridge's clock, so
//!   `offset(T) = reception(q) + hold − stamp(f)` maps T's stamps onto the bridge's
//!   clock, and any frame g of T took `reception(g) − stamp(g) − offset(T)`. One echo is
//!   enough: nothing has to converge. The smallest offset in the last [`WINDOW`] is kept
//!   (the bridge reading q late would make the offset larger and the transit shorter; T
//!   reading q late makes it smaller and the transit longer, the safe side).
//! - **The excess over the fastest frame**, a lower bound that needs no echo: for a
//!   sender S, `raw = reception − stamp` is S's clock offset plus the transit; its
//!   minimum over the window is the offset plus the fastest transit, so `raw − min(raw)`
//!   is how much longer this frame took than the fastest one (never more than its
//!   transit).
//! - **Half the fastest round trip** between two robots (from pairs of echoes): the
//!   fastest transit, assuming the two directions alike. It is added to the excess for a
//!   sender not anchored yet.
//!
//! A frame's estimate is the anchored transit (never below the excess) once its sender
//! is anchored; before that, the excess plus the floor, which can be short of the truth:
//! the exporter holds a sender's values until its clock is anchored, at most
//! [`ANCHOR_WAIT`] after the bridge first hears it (`crate::export`). What it cannot
//! see is asymmetry between the path to the bridge and the paths between robots.
//! Sans-IO: times are arguments.

use std::collections::{HashMap, VecDeque};
use std::time::Duration;

use comms::wire::{Frame, FrameClock, FrameRef};
use comms::Instant;

/// How long a minimum holds: long enough to contain a fast frame under bursty delay,
/// short enough that clock drift (50 ppm: 0.5 ms per 10 s) does not matter.
pub const WINDOW: Duration = Duration::from_secs(10);

/// How long the exporter holds a sender's values for its clock to be anchored by an echo
/// (one or two of its frames on a team of two or more; a robot alone has no echo).
pub const ANCHOR_WAIT: Duration = Duration::from_millis(500);

/// Echoes a sender's clock needs before its values go without waiting: each anchor is
/// late by however late the bridge read the echoed frame (scheduling, a busy socket), and
/// the smallest offset of a few is the least late.
pub const ANCHORS_NEEDED: u32 = 3;

/// A round trip or excess beyond this is taken for a glitch (a restart, a stamp wrap).
const MAX_PLAUSIBLE_US: i64 = 1_000_000;

/// Frames remembered per sender for matching echoes.
const RECENT: usize = 128;

/// A windowed minimum in one-second buckets.
#[derive(Debug, Default)]
struct WindowMin {
    buckets: VecDeque<(u64, i64)>,
}

impl WindowMin {
    fn push(&mut self, now: Instant, x: i64) {
        let second = now.as_micros() / 1_000_000;
        match self.buckets.back_mut() {
            Some((s, m)) if *s == second => *m = (*m).min(x),
            _ => self.buckets.push_back((second, x)),
        }
        let keep = WINDOW.as_secs();
        while self.buckets.front().is_some_and(|(s, _)| s + keep < second) {
            self.buckets.pop_front();
        }
    }

    fn min(&self) -> Option<i64> {
        self.buckets.iter().map(|(_, m)| *m).min()
    }
}

#[derive(Debug)]
struct Sender {
    incarnation: u64,
    /// Unwrapped send stamps: the last raw u32 and the number of wraps.
    last_stamp: u32,
    wraps: i64,
    raw_min: WindowMin,
    /// The smallest echo-anchored offset (bridge clock − this sender's stamps), µs.
    off_min: WindowMin,
    /// When the bridge first heard this life.
    first_heard: Instant,
    /// Echoes that anchored this life's clock.
    anchors: u32,
    /// (seq16, unwrapped stamp, reception on the bridge's clock in µs) of recent frames.
    recent: VecDeque<(u16, i64, i64)>,
    /// Per echoed teammate: the last one-way delay plus clock difference, and when.
    one_way: HashMap<u8, (i64, Instant)>,
}

impl Sender {
    fn new(incarnation: u64, stamp: u32, now: Instant) -> Sender {
        Sender {
            incarnation,
            last_stamp: stamp,
            wraps: 0,
            raw_min: WindowMin::default(),
            off_min: WindowMin::default(),
            first_heard: now,
            anchors: 0,
            recent: VecDeque::new(),
            one_way: HashMap::new(),
        }
    }

    fn unwrap(&mut self, stamp: u32) -> i64 {
        // A stamp much smaller than the last one wrapped (every 71.6 minutes); one a
        // little smaller is a reordered frame.
        if stamp < self.last_stamp && self.last_stamp - stamp > u32::MAX / 2 {
            self.wraps += 1;
        }
        self.last_stamp = stamp;
        self.wraps * (1i64 << 32) + i64::from(stamp)
    }
}

/// Counters of the estimator.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TransitStats {
    /// Round trips measured from pairs of echoes.
    pub round_trips: u64,
    /// Implausible excesses ignored (taken as 0).
    pub implausible: u64,
    /// Implausible round trips ignored.
    pub implausible_round_trips: u64,
    /// Echoes that anchored a sender's clock (its offset from the bridge's).
    pub anchors: u64,
    /// Anchors ignored: the echoed frame's hold or the offset out of bounds.
    pub implausible_anchors: u64,
}

/// What a frame needs for its transit: sender, life, seq and clock fields.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Heard {
    /// The sending robot.
    pub sender: u8,
    /// Its incarnation.
    pub incarnation: u64,
    /// Its frame counter.
    pub seq: u64,
    /// Its send stamp and echo.
    pub clock: FrameClock,
}

impl From<&Frame> for Heard {
    fn from(f: &Frame) -> Heard {
        Heard {
            sender: f.sender,
            incarnation: f.incarnation,
            seq: f.seq,
            clock: f.clock,
        }
    }
}

impl From<&FrameRef<'_>> for Heard {
    fn from(f: &FrameRef<'_>) -> Heard {
        Heard {
            sender: f.sender,
            incarnation: f.incarnation,
            seq: f.seq,
            clock: f.clock,
        }
    }
}

/// A frame's timing as heard: enough to estimate its transit later, with what the
/// estimator knows by then (the exporter keeps one per key).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FrameTiming {
    /// The sender.
    pub sender: u8,
    /// Its life.
    pub incarnation: u64,
    /// Reception on the bridge's clock minus the unwrapped send stamp, µs.
    pub raw_us: i64,
}

/// The estimator; see the module docs.
#[derive(Debug, Default)]
pub struct TransitEstimator {
    senders: HashMap<u8, Sender>,
    rtt_min: WindowMin,
    stats: TransitStats,
}

impl TransitEstimator {
    /// A new estimator.
    pub fn new() -> TransitEstimator {
        TransitEstimator::default()
    }

    /// The counters.
    pub fn stats(&self) -> &TransitStats {
        &self.stats
    }

    /// The floor: half the smallest round trip between two robots in the window.
    pub fn floor(&self) -> Duration {
        self.rtt_min
            .min()
            .map_or(Duration::ZERO, |rtt| micros(rtt / 2))
    }

    /// Takes a frame (already decoded and checked) received at `now`; returns its
    /// estimated transit.
    pub fn frame(&mut self, now: Instant, frame: &Frame) -> Duration {
        let timing = self.heard(now, Heard::from(frame));
        self.transit(&timing)
    }

    /// Takes a frame's header received at `now`; returns its timing (see
    /// [`TransitEstimator::transit`]).
    pub fn heard(&mut self, now: Instant, frame: Heard) -> FrameTiming {
        let stamp = frame.clock.stamp_us;
        let sender = self
            .senders
            .entry(frame.sender)
            .or_insert_with(|| Sender::new(frame.incarnation, stamp, now));
        if sender.incarnation != frame.incarnation {
            if frame.incarnation < sender.incarnation {
                // An old life's frame; the replica drops it.
                return FrameTiming {
                    sender: frame.sender,
                    incarnation: frame.incarnation,
                    raw_us: 0,
                };
            }
            *sender = Sender::new(frame.incarnation, stamp, now);
        }
        let s = sender.unwrap(stamp);
        let raw = now.as_micros() as i64 - s;
        sender.raw_min.push(now, raw);
        sender
            .recent
            .push_back(((frame.seq & 0xffff) as u16, s, now.as_micros() as i64));
        if sender.recent.len() > RECENT {
            sender.recent.pop_front();
        }
        let excess = raw - sender.raw_min.min().unwrap_or(raw);
        if let Some(echo) = frame.clock.echo {
            self.echo(now, frame.sender, s, echo);
        }
        // An excess past the bound is counted here (and capped in `transit`): it is
        // mostly the bridge reading its socket late (a backlog under load).
        if excess >= MAX_PLAUSIBLE_US {
            self.stats.implausible += 1;
        }
        FrameTiming {
            sender: frame.sender,
            incarnation: frame.incarnation,
            raw_us: raw,
        }
    }

    /// Whether the clock of `timing`'s sender (in that life) is anchored by
    /// [`ANCHORS_NEEDED`] echoes.
    pub fn anchored(&self, timing: &FrameTiming) -> bool {
        self.senders.get(&timing.sender).is_some_and(|s| {
            s.incarnation == timing.incarnation
                && s.anchors >= ANCHORS_NEEDED
                && s.off_min.min().is_some()
        })
    }

    /// Until when values of `timing`'s sender wait for its clock's anchor: the bridge
    /// first heard that life plus [`ANCHOR_WAIT`] (`None`: a life no longer current).
    pub fn anchor_deadline(&self, timing: &FrameTiming) -> Option<Instant> {
        self.senders
            .get(&timing.sender)
            .filter(|s| s.incarnation == timing.incarnation)
            .map(|s| s.first_heard + ANCHOR_WAIT)
    }

    /// The transit of a frame with `timing`, from what is known now: anchored, or the
    /// excess plus the floor (see the module docs); capped at a second (a backlog: the
    /// bridge read its socket late), never taken for 0, which would make every value of
    /// the backlog look younger than it is.
    pub fn transit(&self, timing: &FrameTiming) -> Duration {
        let Some(s) = self
            .senders
            .get(&timing.sender)
            .filter(|s| s.incarnation == timing.incarnation)
        else {
            return self.floor();
        };
        let excess = timing.raw_us - s.raw_min.min().unwrap_or(timing.raw_us);
        let us = match s.off_min.min() {
            Some(off) => (timing.raw_us - off).max(excess),
            None => excess + self.floor().as_micros() as i64,
        };
        micros(us.min(MAX_PLAUSIBLE_US))
    }

    fn echo(&mut self, now: Instant, from: u8, stamp: i64, echo: comms::wire::Echo) {
        let Some(target) = self.senders.get(&echo.target) else {
            return;
        };
        let Some(&(_, target_stamp, target_heard)) = target
            .recent
            .iter()
            .rev()
            .find(|(q, _, _)| *q == echo.seq16)
        else {
            return;
        };
        let hold = i64::from(echo.hold_us());
        // The anchor: `from` sent this frame `hold` after it heard the echoed one, which
        // the bridge heard at `target_heard` (one medium).
        let offset = target_heard + hold - stamp;
        let raw = now.as_micros() as i64 - stamp;
        if (0..MAX_PLAUSIBLE_US).contains(&(raw - offset)) {
            if let Some(sender) = self.senders.get_mut(&from) {
                sender.off_min.push(now, offset);
                sender.anchors = sender.anchors.saturating_add(1);
                self.stats.anchors += 1;
            }
        } else {
            self.stats.implausible_anchors += 1;
        }
        let mixed = stamp - hold - target_stamp;
        let back = self
            .senders
            .get(&echo.target)
            .and_then(|t| t.one_way.get(&from))
            .filter(|(_, at)| now.saturating_duration_since(*at) < WINDOW)
            .map(|(m, _)| *m);
        if let Some(sender) = self.senders.get_mut(&from) {
            sender.one_way.insert(echo.target, (mixed, now));
        }
        if let Some(back) = back {
            let rtt = mixed + back;
            if (0..MAX_PLAUSIBLE_US).contains(&rtt) {
                self.stats.round_trips += 1;
                self.rtt_min.push(now, rtt);
            } else {
                self.stats.implausible_round_trips += 1;
            }
        }
    }
}

fn micros(us: i64) -> Duration {
    Duration::from_micros(u64::try_from(us).unwrap_or(0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use comms::wire::{Echo, FrameClock};

    fn frame(sender: u8, seq: u64, stamp_us: u32, echo: Option<Echo>) -> Frame {
        Frame {
            team: 7,
            sender,
            incarnation: 1,
            seq,
            clock: FrameClock { stamp_us, echo },
            items: Vec::new(),
        }
    }

    /// Two robots whose clocks are off the bridge's by +5 s and −3 s exchange frames
    /// over a link whose one-way delay is 10 ms + `extra[i]`; the bridge hears every
    /// frame with the same delay as the teammate (one medium).
    #[test]
    fn the_floor_and_the_excess_add_up_to_the_true_transit() {
        let off = [0i64, 5_000_000, -3_000_000]; // robot r's clock = bridge + off[r]
        let base = 10_000i64;
        let extra = [0i64, 7_000, 0, 15_000, 2_000, 0, 9_000, 0];
        let mut est = TransitEstimator::new();
        let mut worst_error = 0i64;
        let mut last_heard: [Option<(u64, i64)>; 3] = [None, None, None];
        for i in 0..200u64 {
            let robot = (i % 2 + 1) as u8;
            let other = (3 - robot) as usize;
            let send = 1_000_000 + i as i64 * 50_000; // bridge clock, µs
            let transit = base + extra[i as usize % extra.len()];
            let stamp = (send + off[robot as usize]) as u32;
            // Echo the other robot's last frame heard, held since its arrival.
            let echo = last_heard[robot as usize].map(|(seq, arrived)| Echo {
                target: other as u8,
                seq16: seq as u16,
                hold_10us: ((send - arrived) / 10) as u16,
            });
            let got = est.frame(
                Instant::from_micros((send + transit) as u64),
                &frame(robot, i / 2 + 1, stamp, echo),
            );
            last_heard[other] = Some((i / 2 + 1, send + transit));
            if i > 20 {
                worst_error = worst_error.max((got.as_micros() as i64 - transit).abs());
            }
        }
        assert!(est.stats().round_trips > 50, "{:?}", est.stats());
        assert_eq!(
            est.floor(),
            Duration::from_millis(10),
            "half the fastest round trip"
        );
        assert!(
            worst_error <= 20,
            "each frame's transit within the hold's 10 µs rounding: off by {worst_error} µs"
        );
    }

    /// The bridge starts hearing two robots (clocks +5 s and −3 s off its own) while the
    /// link is slow: their first frames take 30 ms, and only from the tenth on does one in
    /// two take 10 ms. From each robot's first echo of a frame the bridge heard, every
    /// estimate is at least the true transit (within the hold's 10 µs rounding): an age is
    /// never below the true one. The estimator before the echo anchor took the first
    /// frames to be the fastest (an excess of 0, no round trip yet for a floor) and
    /// reported them up to 30 ms short.
    #[test]
    fn from_the_first_echo_no_transit_is_underestimated() {
        let off = [0i64, 5_000_000, -3_000_000];
        let mut est = TransitEstimator::new();
        let mut last_heard: [Option<(u64, i64)>; 3] = [None, None, None];
        let mut echoed = [false; 3];
        let mut short = Vec::new();
        for i in 0..60u64 {
            let robot = (i % 2 + 1) as u8;
            let other = (3 - robot) as usize;
            let send = 1_000_000 + i as i64 * 50_000;
            let transit = if i >= 10 && i % 4 < 2 { 10_000 } else { 30_000 };
            let stamp = (send + off[robot as usize]) as u32;
            let echo = last_heard[robot as usize].map(|(seq, arrived)| Echo {
                target: other as u8,
                seq16: seq as u16,
                hold_10us: ((send - arrived) / 10) as u16,
            });
            let got = est.frame(
                Instant::from_micros((send + transit) as u64),
                &frame(robot, i / 2 + 1, stamp, echo),
            );
            last_heard[other] = Some((i / 2 + 1, send + transit));
            echoed[robot as usize] |= echo.is_some();
            if echoed[robot as usize] && (got.as_micros() as i64) < transit - 10 {
                short.push((i, transit, got.as_micros()));
            }
        }
        assert!(
            short.is_empty(),
            "(frame, true transit, estimate) below the truth after an echo: {short:?}"
        );
    }

    /// A sender is anchored by its echoes of frames the bridge heard (ANCHORS_NEEDED of
    /// them); before that, the exporter knows to wait (its deadline is the first frame
    /// plus ANCHOR_WAIT).
    #[test]
    fn a_sender_is_anchored_by_its_echoes() {
        let mut est = TransitEstimator::new();
        let t = |ms: u64| Instant::from_micros(ms * 1000);
        let a = est.heard(t(100), Heard::from(&frame(1, 1, 100_000, None)));
        assert!(!est.anchored(&a));
        assert_eq!(est.anchor_deadline(&a), Some(t(100) + ANCHOR_WAIT));
        let echo = Echo {
            target: 1,
            seq16: 1,
            hold_10us: 500,
        };
        // Robot 2 heard robot 1's frame at 100 ms (bridge clock), held it 5 ms, and its
        // frame took 12 ms: 117 ms. Its clock is 98 ms behind the bridge's.
        let b = est.heard(t(117), Heard::from(&frame(2, 1, 7_000, Some(echo))));
        assert!(!est.anchored(&b), "one echo is not enough");
        for (seq, at) in [(2u64, 140u64), (3, 160)] {
            // Sent 12 ms before `at`, holding robot 1's frame since 100 ms.
            let echo = Echo {
                hold_10us: (at as u16 - 112) * 100,
                ..echo
            };
            let stamp = ((at - 110) * 1000) as u32;
            est.heard(t(at), Heard::from(&frame(2, seq, stamp, Some(echo))));
        }
        assert!(est.anchored(&b));
        assert!(!est.anchored(&a), "robot 1 has echoed nobody yet");
        assert_eq!(est.transit(&b), Duration::from_millis(12));
        assert_eq!(est.stats().anchors, 3);
    }

    #[test]
    fn without_echoes_only_the_excess_is_known() {
        let mut est = TransitEstimator::new();
        let t = |ms: u64| Instant::from_micros(ms * 1000);
        assert_eq!(
            est.frame(t(100), &frame(1, 1, 90_000, None)),
            Duration::ZERO
        );
        assert_eq!(
            est.frame(t(230), &frame(1, 2, 200_000, None)),
            Duration::from_millis(20),
            "this frame took 20 ms longer than the fastest"
        );
    }

    #[test]
    fn a_stamp_wrap_is_not_a_huge_transit() {
        let mut est = TransitEstimator::new();
        let t = |us: u64| Instant::from_micros(us);
        est.frame(t(10_000_000), &frame(1, 1, u32::MAX - 1000, None));
        let got = est.frame(t(10_002_000), &frame(1, 2, 1000, None));
        assert!(got < Duration::from_millis(1), "{got:?}");
    }

    /// The bridge reads a frame 3 s after the fastest one's transit (its socket backed
    /// up under load): the excess is counted as implausible and capped at 1 s, never taken
    /// for 0, which made the values it carried 3 s younger than they were.
    #[test]
    fn a_backlog_is_capped_not_forgotten() {
        let mut est = TransitEstimator::new();
        let t = |ms: u64| Instant::from_micros(ms * 1000);
        est.frame(t(100), &frame(1, 1, 90_000, None));
        let got = est.frame(t(3_300), &frame(1, 2, 200_000, None));
        assert_eq!(got, Duration::from_secs(1), "capped at the plausible bound");
        assert_eq!(est.stats().implausible, 1, "and counted");
    }

    proptest::proptest! {
        /// Any sequence of frames (stamps, echoes, senders, lives, arrival times from the
        /// network) gives an estimate below the floor plus a second, without panicking.
        #[test]
        fn arbitrary_frames_never_panic(
            frames in proptest::collection::vec(
                (1u8..5, 0u64..3, 0u64..1000, proptest::num::u32::ANY, proptest::option::of((1u8..5, proptest::num::u16::ANY, proptest::num::u16::ANY)), 0u64..5_000_000),
                1..200,
            )
        ) {
            let mut est = TransitEstimator::new();
            let mut now = 0u64;
            for (sender, inc, seq, stamp, echo, dt) in frames {
                now += dt;
                let mut f = frame(sender, seq, stamp, echo.map(|(target, seq16, hold_10us)| Echo { target, seq16, hold_10us }));
                f.incarnation = inc;
                let got = est.frame(Instant::from_micros(now), &f);
                proptest::prop_assert!(got <= est.floor() + Duration::from_secs(1));
            }
        }
    }
}
