//! Shared time from the traffic itself: a per-peer estimate of the peer's clock against
//! this robot's, from the send stamps and echoes every frame carries, and from it the
//! network transit of each frame.
//!
//! # Why
//!
//! A value's stamp on this robot's clock is *reception − transit − age the sender
//! reported*. The age is measured by the sender, on its clock, up to the frame's send
//! stamp; the transit (time on the air, queues, an access point holding multicast until a
//! beacon) differs frame by frame, so a configured mean cannot stand in for it: the
//! newest of three copies delivered at one beacon travelled less than the mean, a copy
//! held a whole DTIM interval more. What each frame's transit *is* follows from its send
//! stamp once the sender's clock is known in ours: `transit = t_receive − (t_send − θ)`,
//! with θ the sender's clock minus ours.
//!
//! # How θ is estimated (NTP's four timestamps, no extra message)
//!
//! Every frame carries its send stamp and echoes one teammate (see [`crate::wire`]): the
//! low bits of the seq of the frame last heard from it, and how long it was held. When
//! robot A hears B echo A's own frame: t1 = A's send stamp of that frame (A remembers its
//! recent frames, [`SentLog`]), t2 = B's reception (t3 − hold), t3 = B's send stamp, t4 =
//! A's reception now. Round trip δ = (t4 − t1) − (t3 − t2); offset θ = ((t2 − t1) + (t3 −
//! t4)) / 2. The true offset lies within θ ± δ/2, so a sample with a short round trip is a
//! good one (the path's asymmetry is what is left).
//!
//! The estimate ([`ClockEstimate`]) keeps the samples of the last [`WINDOW`], takes the
//! shortest-round-trip sample of each [`BIN`] of it (NTP's clock filter), and fits a line
//! θ(t) = a + b·t through those, each weighted by its round trip, with a weak prior that
//! the drift b is small (clocks drift tens to hundreds of ppm): a weighted least-squares
//! fit with a ridge on b. One sample gives an estimate (b = 0); the drift comes as the
//! window fills.
//!
//! Stamps are u32 microseconds and wrap every 71.6 minutes: every difference between
//! them is taken modulo 2^32 and read as a signed 32-bit number (±35 minutes). θ itself
//! is known modulo 2^32 µs, which is all a transit needs: it is kept relative to the first
//! sample's (the *anchor*), so the fit works on small numbers.
//!
//! # Untrusted input
//!
//! An echo is used only if it names a frame this robot sent recently and gives a round
//! trip in 0..=[`MAX_ROUND_TRIP`]; once an estimate exists, a sample further from it than
//! its own round trip allows (plus [`OUTLIER_MARGIN`]) is refused as an outlier. All
//! three are counted. [`OUTLIERS_TO_RESET`] outliers in a row mean the estimate is the
//! wrong one (the peer's clock really jumped, or the first samples were bad): it starts
//! again from the newest sample; so does the first outlier after a silence longer than
//! [`WINDOW`] (under a league's budget echoes are sparse and games have long silences,
//! and a line extrapolated across one refused the samples after it for minutes). A
//! send stamp alone changes no estimate: a frame whose
//! stamp gives a transit outside −[`IMPLAUSIBLE_MARGIN`]..=[`MAX_TRANSIT`] is stamped with
//! the configured default transit instead, and counted.

use std::collections::VecDeque;
use std::time::Duration;

use crate::time::Instant;

/// The estimate keeps samples this long.
pub(super) const WINDOW: Duration = Duration::from_secs(64);
/// Of each bin of this length, only the shortest-round-trip sample is fitted.
pub(super) const BIN: Duration = Duration::from_secs(1);
/// Most samples kept per peer (bounds memory whatever the traffic).
const MAX_SAMPLES: usize = 512;
/// A longer round trip is not a sample (a stale or forged echo).
pub(super) const MAX_ROUND_TRIP: Duration = Duration::from_secs(1);
/// Largest transit a frame is believed to have had; beyond it (or more than
/// [`IMPLAUSIBLE_MARGIN`] below zero) its stamp is implausible.
pub(super) const MAX_TRANSIT: Duration = Duration::from_secs(1);
/// How far below zero an estimated transit may be before the stamp is implausible (the
/// estimate's own error makes small negative transits normal; they count as zero).
pub(super) const IMPLAUSIBLE_MARGIN: Duration = Duration::from_millis(50);
/// Slack beyond a sample's round-trip bound before it is an outlier.
pub(super) const OUTLIER_MARGIN: Duration = Duration::from_millis(20);
/// Outliers in a row after which the estimate starts over.
pub(super) const OUTLIERS_TO_RESET: u32 = 8;
/// Prior standard deviation of the relative drift (ppm): loose enough for two clocks
/// hundreds of ppm apart, tight enough that a second of samples does not invent a drift.
const DRIFT_PRIOR_PPM: f64 = 500.0;
/// The fitted drift is clamped to this (ppm).
const MAX_DRIFT_PPM: f64 = 2_000.0;
/// A sample's error (µs) when its round trip is the window's shortest: what the path's
/// asymmetry leaves even then. Longer round trips add half their excess.
const SAMPLE_ERROR_FLOOR_US: f64 = 2_000.0;
/// Own frames remembered for matching echoes.
const SENT_LOG_LEN: usize = 128;

/// The low 32 bits of an instant's microseconds: what a frame's stamp carries.
pub(super) fn stamp_of(t: Instant) -> u32 {
    t.as_micros() as u32
}

/// `a − b` of two wrapping u32 stamps, as a signed number of microseconds.
fn wrapping_diff(a: u32, b: u32) -> i64 {
    i64::from(a.wrapping_sub(b) as i32)
}

/// This robot's recent frames: seq and send instant, for matching echoes.
#[derive(Debug)]
pub(super) struct SentLog {
    frames: VecDeque<(u64, Instant)>,
}

impl Default for SentLog {
    /// Its whole length at once (2 KiB): the log never grows, so no frame ever pays for
    /// a reallocation (see [`ClockEstimate::default`]).
    fn default() -> SentLog {
        SentLog {
            frames: VecDeque::with_capacity(SENT_LOG_LEN),
        }
    }
}

impl SentLog {
    pub(super) fn record(&mut self, seq: u64, at: Instant) {
        if self.frames.len() == SENT_LOG_LEN {
            self.frames.pop_front();
        }
        self.frames.push_back((seq, at));
    }

    /// When the frame whose seq has low bits `seq16` left, if it is a recent one.
    pub(super) fn sent_at(&self, seq16: u16) -> Option<Instant> {
        self.frames
            .iter()
            .rev()
            .find(|(seq, _)| *seq as u16 == seq16)
            .map(|&(_, at)| at)
    }
}

/// One offset sample.
#[derive(Clone, Copy, Debug)]
struct Sample {
    /// Local reception time (t4), µs.
    at_us: u64,
    /// θ relative to the anchor, µs.
    theta_us: f64,
    /// Round trip, µs.
    rtt_us: f64,
}

/// The [`BIN`] a sample received at `at_us` falls in.
fn bin_of(at_us: u64) -> u64 {
    at_us / BIN.as_micros() as u64
}

/// The fitted line θ(t) = a + b·(t − t_ref).
#[derive(Clone, Copy, Debug)]
struct Fit {
    t_ref_us: u64,
    a_us: f64,
    b_ppm: f64,
}

impl Fit {
    fn at(&self, t_us: u64) -> f64 {
        let dt_s = (t_us as f64 - self.t_ref_us as f64) / 1e6;
        self.a_us + self.b_ppm * dt_s
    }
}

/// What became of an echo.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum SampleOutcome {
    /// It was added to the estimate.
    Used,
    /// Its round trip was negative or too long.
    Rejected,
    /// It disagreed with the estimate by more than its round trip allows.
    Outlier,
}

/// Most runs of samples in one bin the window can hold: one per [`BIN`] of [`WINDOW`],
/// and the bin the window's oldest edge falls in.
const MAX_RUNS: usize = (WINDOW.as_secs() / BIN.as_secs()) as usize + 1;

/// The estimate of one peer's clock against this robot's.
#[derive(Debug)]
pub(super) struct ClockEstimate {
    anchor: Option<u32>,
    samples: VecDeque<Sample>,
    /// What the fit uses: of each run of consecutive `samples` in one [`BIN`], the
    /// shortest-round-trip sample (the first of equals), oldest first. Kept up to date as
    /// samples come and go rather than rebuilt from all of them at every echo, which at
    /// hundreds of echoes a second per peer (512 samples) was most of a frame's cost.
    best: VecDeque<Sample>,
    fit: Option<Fit>,
    used: u64,
    outliers_in_row: u32,
}

impl Default for ClockEstimate {
    /// An estimate with no sample yet, its buffers at their full size (12 KiB and
    /// 1.5 KiB): a deque that doubles copies its samples into fresh memory inside the
    /// frame whose echo fills it (at the 256th sample: two page faults and a 6 KiB copy
    /// in one round trip, a tenth of `bench comms`'s slowest), so it is sized once,
    /// when the peer appears.
    fn default() -> ClockEstimate {
        ClockEstimate {
            anchor: None,
            samples: VecDeque::with_capacity(MAX_SAMPLES),
            best: VecDeque::with_capacity(MAX_RUNS),
            fit: None,
            used: 0,
            outliers_in_row: 0,
        }
    }
}

impl ClockEstimate {
    /// Forgets every sample (keeping the count of those used, and the buffers).
    fn start_over(&mut self) {
        self.anchor = None;
        self.samples.clear();
        self.best.clear();
        self.fit = None;
        self.outliers_in_row = 0;
    }

    /// Adds the sample from an echo of own frame sent at `t1`, held `hold_us` by the
    /// peer, in a frame stamped `t3` (peer's clock) received at `t4`.
    pub(super) fn add_echo(
        &mut self,
        t1: Instant,
        hold_us: u32,
        t3: u32,
        t4: Instant,
    ) -> SampleOutcome {
        let elapsed_us = t4.as_micros() as i64 - t1.as_micros() as i64;
        let rtt_us = elapsed_us - i64::from(hold_us);
        // The hold is rounded to 10 µs: a few µs below zero is a very short trip.
        if !(-(crate::wire::ECHO_HOLD_UNIT_US as i64)..=MAX_ROUND_TRIP.as_micros() as i64)
            .contains(&rtt_us)
        {
            return SampleOutcome::Rejected;
        }
        let rtt_us = rtt_us.max(0) as f64;
        // θ = (t3 − t4) + δ/2, the first term modulo 2^32 and relative to the anchor.
        let raw = t3.wrapping_sub(stamp_of(t4));
        let anchor = *self.anchor.get_or_insert(raw);
        let theta_us = wrapping_diff(raw, anchor) as f64 + rtt_us / 2.0;
        let t4_us = t4.as_micros();
        if let Some(fit) = self.fit {
            let bound = rtt_us / 2.0 + OUTLIER_MARGIN.as_micros() as f64;
            if (theta_us - fit.at(t4_us)).abs() > bound {
                self.outliers_in_row += 1;
                // A line whose newest sample has left the window is an extrapolation
                // across a silence (Ready, Set and the break under a league's budget,
                // where echoes are sparse): it does not get to refuse the first samples
                // after it, which under a budget could take minutes to outvote it.
                let window_us = WINDOW.as_micros() as u64;
                let stale = self
                    .samples
                    .back()
                    .is_none_or(|s| s.at_us + window_us < t4_us);
                if self.outliers_in_row < OUTLIERS_TO_RESET && !stale {
                    return SampleOutcome::Outlier;
                }
                // Consistently elsewhere: the estimate is what is wrong. Start over.
                self.start_over();
                return self.add_echo(t1, hold_us, t3, t4);
            }
        }
        self.outliers_in_row = 0;
        if self.samples.len() == MAX_SAMPLES {
            self.pop_oldest();
        }
        self.push(Sample {
            at_us: t4_us,
            theta_us,
            rtt_us,
        });
        self.used += 1;
        self.refit(t4_us);
        SampleOutcome::Used
    }

    /// Appends the newest sample (and to `best`: a new run, or the current one's best).
    fn push(&mut self, s: Sample) {
        self.samples.push_back(s);
        match self.best.back_mut() {
            Some(b) if bin_of(b.at_us) == bin_of(s.at_us) => {
                if s.rtt_us < b.rtt_us {
                    *b = s;
                }
            }
            _ => self.best.push_back(s),
        }
    }

    /// Forgets the oldest sample; the oldest run's best goes with its last sample, or is
    /// found again among the run's others if it was this one.
    fn pop_oldest(&mut self) {
        let Some(gone) = self.samples.pop_front() else {
            return;
        };
        let bin = bin_of(gone.at_us);
        let mut run = self
            .samples
            .iter()
            .take_while(|s| bin_of(s.at_us) == bin)
            .peekable();
        if run.peek().is_none() {
            self.best.pop_front();
            return;
        }
        // The run's best is its first sample of the shortest round trip: `gone` (the
        // run's first) was it exactly if its round trip is that shortest one.
        let was_best = self.best.front().is_some_and(|b| b.rtt_us == gone.rtt_us);
        if was_best {
            let mut best = *run.next().expect("peeked");
            for s in run {
                if s.rtt_us < best.rtt_us {
                    best = *s;
                }
            }
            if let Some(b) = self.best.front_mut() {
                *b = best;
            }
        }
    }

    fn refit(&mut self, now_us: u64) {
        let window_us = WINDOW.as_micros() as u64;
        while self
            .samples
            .front()
            .is_some_and(|s| s.at_us + window_us < now_us)
        {
            self.pop_oldest();
        }
        // The shortest round trip of each bin: `best`.
        let best = &self.best;
        // Weighted least squares of θ on t (seconds from now), ridge on the drift. A
        // sample's error is bounded by half its round trip; what is common to every round
        // trip (the path's minimum) is no error, so the weight counts the excess.
        let shortest = best.iter().map(|s| s.rtt_us).fold(f64::INFINITY, f64::min);
        let (mut s0, mut s1, mut s2, mut t0, mut t1) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for s in best {
            let err = (s.rtt_us - shortest) / 2.0 + SAMPLE_ERROR_FLOOR_US;
            let w = 1.0 / (err * err);
            let x = (s.at_us as f64 - now_us as f64) / 1e6;
            s0 += w;
            s1 += w * x;
            s2 += w * x * x;
            t0 += w * s.theta_us;
            t1 += w * x * s.theta_us;
        }
        if s0 <= 0.0 {
            self.fit = None;
            return;
        }
        let ridge = 1.0 / (DRIFT_PRIOR_PPM * DRIFT_PRIOR_PPM);
        let det = s0 * (s2 + ridge) - s1 * s1;
        let mut b = if det > 0.0 {
            (s0 * t1 - s1 * t0) / det
        } else {
            0.0
        };
        b = b.clamp(-MAX_DRIFT_PPM, MAX_DRIFT_PPM);
        let a = (t0 - b * s1) / s0;
        self.fit = Some(Fit {
            t_ref_us: now_us,
            a_us: a,
            b_ppm: b,
        })
        .filter(|f| f.a_us.is_finite() && f.b_ppm.is_finite());
    }

    /// The transit of a frame stamped `t3` (peer's clock) received at `t4`, in µs (may be
    /// negative by the estimate's error), if an estimate exists.
    pub(super) fn transit_us(&self, t3: u32, t4: Instant) -> Option<f64> {
        let fit = self.fit?;
        let anchor = self.anchor?;
        let raw = t3.wrapping_sub(stamp_of(t4));
        // transit = θ − (t3 − t4), both relative to the anchor.
        Some(fit.at(t4.as_micros()) - wrapping_diff(raw, anchor) as f64)
    }

    /// The peer's clock minus this robot's at `now`, µs, modulo 2^32 read as signed.
    pub(super) fn offset_us(&self, now: Instant) -> Option<i64> {
        let fit = self.fit?;
        let anchor = self.anchor?;
        let whole = fit.at(now.as_micros()).round() as i64;
        Some(wrapping_diff(anchor.wrapping_add(whole as u32), 0))
    }

    /// The fitted drift of the peer's clock against this robot's, ppm.
    pub(super) fn drift_ppm(&self) -> Option<f64> {
        self.fit.map(|f| f.b_ppm)
    }

    /// The shortest round trip in the window.
    pub(super) fn min_round_trip(&self) -> Option<Duration> {
        // Each bin's best is the shortest of its samples, so the shortest of the bests is
        // the window's (a walk over about 64 bests, not up to 512 samples).
        self.best
            .iter()
            .map(|s| s.rtt_us)
            .min_by(f64::total_cmp)
            .map(|us| Duration::from_micros(us as u64))
    }

    /// Samples used since the peer's current life began.
    pub(super) fn samples(&self) -> u64 {
        self.used
    }
}

/// Per-peer timing state: what to echo back to it, and the estimate of its clock.
#[derive(Debug, Default)]
pub(super) struct PeerClock {
    /// Seq of the frame last heard from the peer and when (this robot's clock).
    pub(super) heard: Option<(u64, Instant)>,
    /// When an echo to the peer last went out.
    pub(super) echoed_at: Option<Instant>,
    pub(super) estimate: ClockEstimate,
    /// Its last frames' send stamps minus their receptions, µs (newest last, at most
    /// [`ONE_WAY_SAMPLES`]): its clock minus ours, less each frame's transit.
    one_way: VecDeque<i64>,
}

/// One-way samples kept per peer for [`PeerClock::one_way_offset_us`].
const ONE_WAY_SAMPLES: usize = 9;

impl PeerClock {
    /// A frame stamped `stamp_us` on the peer's clock arrived at `now`.
    pub(super) fn note_stamp(&mut self, stamp_us: u32, now: Instant) {
        if self.one_way.len() == ONE_WAY_SAMPLES {
            self.one_way.pop_front();
        }
        self.one_way
            .push_back(wrapping_diff(stamp_us, stamp_of(now)));
    }

    /// The peer's clock minus ours from send stamps alone, µs (modulo 2^32, read as
    /// signed): the median of its last frames' stamp − reception, so early by a typical
    /// transit (milliseconds on a WLAN) and unmoved by one odd stamp. Coarse, but there
    /// from the first frame: under a league's budget echoes need a teammate's frame to
    /// follow one of ours within 655 ms, and an echo estimate may take minutes to come.
    pub(super) fn one_way_offset_us(&self) -> Option<i64> {
        if self.one_way.is_empty() {
            return None;
        }
        // No allocation: `Replica::peers` serves this to the team layer every tick.
        let mut kept = [0i64; ONE_WAY_SAMPLES];
        for (slot, &v) in kept.iter_mut().zip(&self.one_way) {
            *slot = v;
        }
        let v = &mut kept[..self.one_way.len()];
        v.sort_unstable();
        // The samples are relative to one reading of the wrapping clock: a peer whose
        // offset sits at the ±35 min seam could straddle it, which no team does.
        Some(v[v.len() / 2])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two clocks: the peer's reads `offset_us + t·(1 + drift)` when ours reads `t`.
    fn peer_stamp(t_us: u64, offset_us: i64, drift_ppm: f64) -> u32 {
        let local = t_us as f64 * (1.0 + drift_ppm * 1e-6) + offset_us as f64;
        (local.round() as i64) as u32
    }

    /// Feeds symmetric exchanges every 100 ms with `one_way_us` each way; returns the
    /// estimate.
    fn exchange(
        offset_us: i64,
        drift_ppm: f64,
        one_way_us: u64,
        seconds: u64,
    ) -> (ClockEstimate, u64) {
        let mut est = ClockEstimate::default();
        let mut t = 1_000_000u64;
        while t < seconds * 1_000_000 {
            let t1 = Instant::from_micros(t);
            let hold = 30_000u32;
            let t3_local = t + one_way_us + u64::from(hold);
            let t3 = peer_stamp(t3_local, offset_us, drift_ppm);
            let t4 = Instant::from_micros(t3_local + one_way_us);
            assert_eq!(est.add_echo(t1, hold, t3, t4), SampleOutcome::Used);
            t += 100_000;
        }
        (est, t)
    }

    #[test]
    fn send_stamps_alone_give_the_offset_to_a_transit_and_one_odd_stamp_moves_nothing() {
        // The peer's clock is 7.18 s ahead; its frames take 5-30 ms; one stamp is odd (a
        // clock jump, or a forged frame).
        let mut c = PeerClock::default();
        assert_eq!(
            c.one_way_offset_us(),
            None,
            "nothing before the first frame"
        );
        let offset = 7_180_000i64;
        for k in 0..20u64 {
            let sent = 1_000_000 + k * 3_000_000;
            let transit = 5_000 + (k * 7_919) % 25_000;
            let stamp = if k == 17 {
                peer_stamp(sent, offset + 900_000_000, 0.0)
            } else {
                peer_stamp(sent, offset, 0.0)
            };
            c.note_stamp(stamp, Instant::from_micros(sent + transit));
        }
        let got = c.one_way_offset_us().expect("an offset");
        let early = offset - got;
        assert!(
            (5_000..=30_000).contains(&early),
            "stamps give the offset early by a transit: {early} µs"
        );
    }

    #[test]
    fn symmetric_paths_give_the_true_transit_across_the_wrap() {
        // The peer's clock is 4000 s ahead (past the u32 wrap) and 150 ppm fast.
        let (est, t) = exchange(4_000_000_000, 150.0, 20_000, 40);
        let t4 = Instant::from_micros(t + 35_000);
        let t3 = peer_stamp(t, 4_000_000_000, 150.0);
        let transit = est.transit_us(t3, t4).expect("an estimate");
        assert!(
            (transit - 35_000.0).abs() < 100.0,
            "a frame sent 35 ms ago has a transit of 35 ms, not {transit} µs"
        );
        let drift = est.drift_ppm().unwrap();
        assert!((drift - 150.0).abs() < 5.0, "drift {drift} ppm, not 150");
    }

    #[test]
    fn an_echo_with_a_negative_or_huge_round_trip_is_rejected() {
        let mut est = ClockEstimate::default();
        let t1 = Instant::from_micros(10_000_000);
        let t4 = Instant::from_micros(10_050_000);
        assert_eq!(
            est.add_echo(t1, 60_000, 0, t4),
            SampleOutcome::Rejected,
            "held longer than the round trip"
        );
        assert_eq!(
            est.add_echo(t1, 0, 0, t4 + Duration::from_secs(2)),
            SampleOutcome::Rejected,
            "a round trip beyond a second"
        );
        assert_eq!(est.samples(), 0);
        assert!(est.transit_us(0, t4).is_none(), "no estimate from rejects");
    }

    #[test]
    fn a_wild_sample_is_an_outlier_and_a_persistent_shift_resets() {
        let (mut est, t) = exchange(-7_000_000, -80.0, 10_000, 10);
        let good = est.transit_us(
            peer_stamp(t, -7_000_000, -80.0),
            Instant::from_micros(t + 10_000),
        );
        // A forged frame: a stamp 3 s off with a plausible echo.
        let t1 = Instant::from_micros(t);
        let t4 = Instant::from_micros(t + 20_000);
        let wild = peer_stamp(t + 10_000, -7_000_000 + 3_000_000, -80.0);
        assert_eq!(est.add_echo(t1, 0, wild, t4), SampleOutcome::Outlier);
        let after = est.transit_us(
            peer_stamp(t, -7_000_000, -80.0),
            Instant::from_micros(t + 10_000),
        );
        assert_eq!(good, after, "the outlier did not move the estimate");
        // The same shift, again and again: the estimate follows it.
        let mut outcome = SampleOutcome::Outlier;
        for k in 1..OUTLIERS_TO_RESET {
            let t = t + u64::from(k) * 100_000;
            let wild = peer_stamp(t + 10_000, -4_000_000, -80.0);
            outcome = est.add_echo(
                Instant::from_micros(t),
                0,
                wild,
                Instant::from_micros(t + 20_000),
            );
        }
        assert_eq!(outcome, SampleOutcome::Used, "the estimate started over");
    }

    #[test]
    fn after_a_silence_longer_than_the_window_the_first_sample_starts_over() {
        // Ten seconds of echoes, then a silence (a break under the SPL budget) across
        // which the peer's clock was stepped by 300 ms; then one echo.
        let stepped_after = |silence_us: u64| {
            let (mut est, t) = exchange(-7_000_000, -80.0, 10_000, 10);
            let t = t + silence_us;
            let stepped = peer_stamp(t + 10_000, -7_000_000 + 300_000, -80.0);
            let outcome = est.add_echo(
                Instant::from_micros(t),
                0,
                stepped,
                Instant::from_micros(t + 20_000),
            );
            (est, t, outcome)
        };
        let (est, t, outcome) = stepped_after(100_000_000);
        assert_eq!(
            outcome,
            SampleOutcome::Used,
            "after 100 s a stale line does not refuse the first sample"
        );
        let transit = est
            .transit_us(
                peer_stamp(t + 30_000, -7_000_000 + 300_000, -80.0),
                Instant::from_micros(t + 40_000),
            )
            .expect("an estimate");
        assert!(
            (transit - 10_000.0).abs() < 1_000.0,
            "the estimate follows the stepped clock at once: transit {transit} µs, not 10 ms"
        );
        // Within the window the same step is still an outlier (the forged-stamp rule).
        let (_, _, outcome) = stepped_after(30_000_000);
        assert_eq!(
            outcome,
            SampleOutcome::Outlier,
            "30 s after the last sample the line is still trusted"
        );
    }

    /// What the fit used to rebuild at every echo: the shortest round trip of each run
    /// of consecutive samples in one bin, the first of equals.
    fn best_rebuilt(samples: &VecDeque<Sample>) -> Vec<(u64, u64, u64)> {
        let mut best: Vec<Sample> = Vec::new();
        for s in samples {
            match best.last_mut() {
                Some(b) if bin_of(b.at_us) == bin_of(s.at_us) => {
                    if s.rtt_us < b.rtt_us {
                        *b = *s;
                    }
                }
                _ => best.push(*s),
            }
        }
        best.iter().map(key_of).collect()
    }

    fn key_of(s: &Sample) -> (u64, u64, u64) {
        (s.at_us, s.theta_us.to_bits(), s.rtt_us.to_bits())
    }

    /// A busy link (an echo every 700 µs to 2.3 ms, so the 512-sample cap evicts within a
    /// bin, round trips from a few values so ties happen, a stretch with the clock going
    /// back so runs of one bin repeat) and a quiet one (the 64 s window evicts whole
    /// bins): the kept per-bin bests are at every step what rebuilding them from the
    /// samples gives, so the fit is the one it always was.
    #[test]
    fn the_kept_bin_bests_are_what_rebuilding_them_gives() {
        let mut est = ClockEstimate::default();
        let mut state = 2026u64;
        let mut next = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            state >> 33
        };
        let mut t = 1_000_000u64;
        for step in 0..6_000u64 {
            t = if (3_000..3_050).contains(&step) {
                t.saturating_sub(40_000) // the clock handed in goes back
            } else if step >= 5_000 {
                t + 900_000 + next() % 2_000_000 // quiet: whole bins expire
            } else {
                t + 700 + next() % 1_600
            };
            let rtt = 100 + 50 * (next() % 4);
            let t1 = Instant::from_micros(t.saturating_sub(rtt));
            let t4 = Instant::from_micros(t);
            let t3 = stamp_of(t4).wrapping_add(5_000 + (next() % 30) as u32);
            est.add_echo(t1, 0, t3, t4);
            let kept: Vec<_> = est.best.iter().map(key_of).collect();
            assert_eq!(kept, best_rebuilt(&est.samples), "step {step}");
            // The shortest round trip, read off the bests, is the samples' shortest.
            let of_samples = est
                .samples
                .iter()
                .map(|s| s.rtt_us)
                .min_by(f64::total_cmp)
                .map(|us| Duration::from_micros(us as u64));
            assert_eq!(est.min_round_trip(), of_samples, "step {step}");
        }
        assert!(
            est.samples.len() < MAX_SAMPLES,
            "the quiet stretch emptied old bins"
        );
    }

    /// A ping-pong at 20 µs round trips (as `bench comms` runs): 3,000 echoes in one
    /// bin, so the window fills to `MAX_SAMPLES` and every later echo pops one, then
    /// eight outliers in a row make the estimate start over. Its buffers never grow:
    /// no echo pays for a reallocation (and the fresh memory's page faults).
    #[test]
    fn the_estimates_buffers_are_sized_once() {
        let mut est = ClockEstimate::default();
        let (samples_cap, best_cap) = (est.samples.capacity(), est.best.capacity());
        assert!(samples_cap >= MAX_SAMPLES && best_cap >= MAX_RUNS);
        let mut t = 1_000_000u64;
        for i in 0..3_000u64 {
            let rtt = 20 + i % 7;
            let t4 = Instant::from_micros(t);
            let t1 = Instant::from_micros(t - rtt);
            assert_eq!(est.add_echo(t1, 0, stamp_of(t4), t4), SampleOutcome::Used);
            t += 25;
        }
        assert_eq!(est.samples.len(), MAX_SAMPLES, "the window is full");
        for _ in 0..OUTLIERS_TO_RESET {
            // The peer's clock jumped by a minute.
            let t4 = Instant::from_micros(t);
            let t3 = stamp_of(t4).wrapping_add(60_000_000);
            est.add_echo(Instant::from_micros(t - 20), 0, t3, t4);
            t += 25;
        }
        assert_eq!(
            est.samples.len(),
            1,
            "the estimate started over from the newest"
        );
        assert_eq!(est.samples(), 3_001, "the count of samples used goes on");
        assert_eq!(
            (est.samples.capacity(), est.best.capacity()),
            (samples_cap, best_cap),
            "no buffer was reallocated"
        );
        let mut log = SentLog::default();
        let log_cap = log.frames.capacity();
        for seq in 1..=1_000u64 {
            log.record(seq, Instant::from_micros(seq));
        }
        assert_eq!(log.frames.capacity(), log_cap, "the sent log never grows");
    }

    #[test]
    fn the_sent_log_finds_recent_frames_by_their_low_seq_bits() {
        let mut log = SentLog::default();
        for seq in 1..=300u64 {
            log.record(seq, Instant::from_micros(seq * 1000));
        }
        assert_eq!(log.sent_at(300), Some(Instant::from_micros(300_000)));
        assert_eq!(log.sent_at(200), Some(Instant::from_micros(200_000)));
        assert_eq!(log.sent_at(100), None, "too old: forgotten");
        assert_eq!(log.sent_at(4000), None, "never sent");
    }
}
