//! The end test after a slot: did the sender stop (a short message, or the end of a long
//! one) or does it continue (a long message's second frame)? A sequential
//! log-likelihood-ratio test, run on short windows from the estimated slot end on as
//! soon as their samples arrive, and alongside on the analysis windows, which decide when
//! the short windows cannot.

use super::tracking::Tracking;
use super::{median, Decoder};
use crate::significance::{hann_share_inside, ln_tone_likelihood};
use crate::tones::{basic_tones, tone_frequency_hz, DATA_VALUES, SENDER_COUNT, TONE_COUNT};

/// Bound of the short/long sequential test on the analysis windows (log-likelihood
/// ratio). Half-overlapping windows count their evidence about twice, so this is about
/// ±7 (1 in 1000) in independent evidence.
pub(super) const SPRT_BOUND: f64 = 14.0;
/// How far after a slot's end (in slots) the short/long test looks. A long message's
/// second frame follows with no gap, so its evidence is in the first windows; looking
/// further would mistake the same robot's next message for a continuation.
pub(super) const SPRT_HORIZON: f64 = 0.5;
/// Largest share of a window's Hann area before the slot end for it to count as "after"
/// in the short/long test (a window starting 1/8 window before the end).
pub(super) const MAX_SHARE_BEFORE_END: f64 = 0.02;
/// Power share of the first slot's level assumed for a continuing tone (−2.2 dB).
pub(super) const CONTINUATION_SHARE: f64 = 0.6;
/// Largest evidence one tone in one window adds to the short/long test.
pub(super) const LLR_CLIP: f64 = 8.0;
/// Length of the end test's short windows, as a share of an analysis window (64 ms at
/// 1 s tones: tones 49 Hz apart stay ~3 bins apart).
const END_WINDOW_SHARE: f64 = 0.5;
/// Hop between the end test's short windows, as a share of their length (16 ms at 1 s
/// tones): evidence arrives every hop instead of every analysis window.
const END_HOP_SHARE: f64 = 0.25;
/// "Stopped" bound of the end test in independent evidence (nats): stopping wrongly when
/// the sender continues at the modelled level (a long message reported as a short, a
/// wrong message) has probability about e^−7 ≈ 1e-3 (Wald). The summed evidence of
/// overlapping windows is first divided by its variance inflation (see
/// [`ShortWindow::effective`]).
const END_BOUND_NATS: f64 = 7.0;
/// "Continues" bound of the end test, nats (plus ln 21 for the unknown data basic). Far
/// stricter: continuing wrongly loses the message (and the second slot swallows what
/// follows), while deciding "continues" later costs nothing, as the second slot must be
/// heard anyway.
const END_CONTINUE_NATS: f64 = 12.0;

/// The "stopped" hypotheses, as (reverberation time s, leftover share). A tone that stops
/// in a hall goes on as a reverberant tail whose power decays by 60 dB in T60; over
/// babble, the talkers' harmonics keep putting power on the sender's tones after it
/// stopped, far more than the noise model allows, which a leftover at a share of the
/// tone's level stands for. "Stopped" is the best of these (dry first) against
/// "continues": a tail slower than the slowest still decays by 9 dB within the test's
/// half-slot horizon, and a leftover is 8 dB below the continuation level, while a
/// continuation holds its level.
pub(super) const STOP_HYPOTHESES: [(f64, f64); 7] = [
    (0.0, 0.0),
    (0.4, 0.0),
    (0.8, 0.0),
    (1.5, 0.0),
    (2.5, 0.0),
    (0.0, 0.1),
    (1.5, 0.1),
];
/// Longest tail hypothesis, in tone durations: 60 dB / 9 dB × the half-slot horizon.
const MAX_T60_PER_TONE: f64 = 3.3;
/// Number of "stopped" hypotheses.
const TAILS: usize = STOP_HYPOTHESES.len();
/// Levels of the "continues" hypothesis, as shares of the slot's level: the conservative
/// [`CONTINUATION_SHARE`], and the full level (against which a slow tail is told apart
/// only once it has decayed).
const CONTINUATION_SHARES: [f64; 2] = [CONTINUATION_SHARE, 1.0];
/// Number of continuation levels.
const CONTINUATIONS: usize = CONTINUATION_SHARES.len();
/// Levels of a second frame's data basic, as shares of the first slot's typical tone
/// level (0, −7 and −14 dB). In a hall each tone reaches the microphone at its own level
/// (the room's response at a single frequency varies by ±10 dB and more from tone to
/// tone), so a second frame's data tones may sound far below the first frame's: tested
/// only at the typical level, they read as "not there", and a long message whose sender
/// plainly went on would be cut to a wrong short.
const DATA_LEVELS: [f64; 3] = [1.0, 0.2, 0.04];
/// Least typical tone level (per-window excess over the noise, 6 dB) of a first slot
/// that [`Decoder::sender_stopped_late`] may still make a short message. Every room row
/// `huddle audio eval` runs (down to −6 dB in-band) has its tones 12 dB or more above the
/// noise in a window; the frames babble assembles sit near 0 dB, and in 10 h of
/// reverberant babble one was let through this way.
const LATE_MIN_LEVEL: f64 = 4.0;
/// Number of data levels.
const DATA_LEVEL_COUNT: usize = DATA_LEVELS.len();

/// Expected power share of a stopped tone (its reverberant tail and any leftover) in a
/// window whose centre lies `tau_s` seconds after the end and that holds `after` of the
/// next slot's Hann area, for each of [`STOP_HYPOTHESES`]: the tail power decays as
/// e^(−ln(10⁶) τ / T60) (all of the slot's level taken as reverberant: the worst case).
///
/// A tail that cannot decay by 9 dB within the test's horizon (T60 over
/// [`MAX_T60_PER_TONE`] tone durations) cannot be told from a continuation at all: such
/// a hypothesis falls back to no tail (short tones are decided as in a dry room).
pub(super) fn tail_shares(after: f64, tau_s: f64, tone_s: f64) -> [f64; TAILS] {
    std::array::from_fn(|m| {
        let (t60, leftover) = STOP_HYPOTHESES[m];
        let tail = if t60 <= 0.0 || t60 > MAX_T60_PER_TONE * tone_s {
            0.0
        } else {
            (-(1e6f64).ln() * tau_s.max(0.0) / t60).exp()
        };
        after * after * (tail + leftover)
    })
}

/// Leftover share of each "stopped" hypothesis (for tones that were not sounding).
fn leftover_shares(after: f64) -> [f64; TAILS] {
    std::array::from_fn(|m| after * after * STOP_HYPOTHESES[m].1)
}

/// Evidence, summed over windows, that the tracked frame continues after the slot end,
/// against each "stopped" hypothesis of [`STOP_HYPOTHESES`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Evidence {
    /// From the sender's tones, `[continuation level][stop hypothesis]`.
    llr: [[f64; TAILS]; CONTINUATIONS],
    /// From each data basic's tones (a second frame sounds one, which one unknown, at
    /// one of [`DATA_LEVELS`]), `[continuation level][stop hypothesis][data level][d]`.
    data_llr: [[[[f64; DATA_VALUES as usize]; DATA_LEVEL_COUNT]; TAILS]; CONTINUATIONS],
}

impl Evidence {
    fn new() -> Self {
        Evidence {
            llr: [[0.0; TAILS]; CONTINUATIONS],
            data_llr: [[[[0.0; DATA_VALUES as usize]; DATA_LEVEL_COUNT]; TAILS]; CONTINUATIONS],
        }
    }

    /// The evidence against "stopped": [`Evidence::total`] with the second frame's data
    /// basic at any level of [`DATA_LEVELS`]. "Stopped" must beat a continuation whose
    /// data tones sound far below the first frame's, too: in a hall they may.
    fn against_stop(&self) -> f64 {
        self.total_over(DATA_LEVEL_COUNT)
    }

    /// The sender's evidence plus the best data basic's at the typical level (a
    /// generalised likelihood ratio),
    /// for the continuation level that explains the windows best, against the "stopped"
    /// hypothesis that explains them best: "continues" must beat every stop hypothesis,
    /// "stopped" needs one to beat every continuation level (a slow tail and a
    /// continuation at full level look alike at first; neither decides then).
    fn total(&self) -> f64 {
        self.total_over(1)
    }

    /// Whether one "stopped" hypothesis beats every continuation (`beats` says whether an
    /// evidence sum is far enough below zero): with the second frame's data basic at the
    /// typical level and, where the sender's own tones lean to "continues" under that
    /// hypothesis, at every level of [`DATA_LEVELS`].
    fn stopped(&self, beats: impl Fn(f64) -> bool) -> bool {
        (0..TAILS).any(|m| {
            let best = |levels: usize, with_data: bool| {
                (0..CONTINUATIONS)
                    .map(|c| {
                        let data = self.data_llr[c][m][..levels]
                            .iter()
                            .flatten()
                            .copied()
                            .fold(f64::NEG_INFINITY, f64::max);
                        self.llr[c][m] + if with_data { data } else { 0.0 }
                    })
                    .fold(f64::NEG_INFINITY, f64::max)
            };
            beats(best(1, true)) && (best(1, false) <= 0.0 || beats(best(DATA_LEVEL_COUNT, true)))
        })
    }

    /// [`Evidence::total`] with the second frame's data basic at any of the first
    /// `levels` of [`DATA_LEVELS`].
    fn total_over(&self, levels: usize) -> f64 {
        (0..TAILS)
            .map(|m| {
                (0..CONTINUATIONS)
                    .map(|c| {
                        let best_data = self.data_llr[c][m][..levels]
                            .iter()
                            .flatten()
                            .copied()
                            .fold(f64::NEG_INFINITY, f64::max);
                        self.llr[c][m] + best_data
                    })
                    .fold(f64::NEG_INFINITY, f64::max)
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Adds one window's evidence: the window holds `before` of the ended slot's Hann area
    /// and `after` of the next slot's, `tails` are the stopped tone's shares under each
    /// "stopped" hypothesis ([`tail_shares`]), and `power(k)` is tone `k`'s
    /// normalised power in it.
    fn add_window(
        &mut self,
        c: &Continuation,
        before: f64,
        after: f64,
        tails: &[f64; TAILS],
        power: impl Fn(usize) -> f64,
    ) {
        let t = c.tracking;
        // A tail still within a factor of two of a continuation's level says nothing
        // either way in this window: at high SNR the clipped evidence would otherwise
        // follow whichever model the (imperfectly measured) level happens to sit nearer.
        let alike = |tail: f64, share: f64| tail > 0.5 * share * after * after;
        // Clipped: at high SNR a small level mismatch (fades, a phase step, room echo)
        // must not swamp the evidence of other windows.
        let llr = |r: f64, ended: f64, continued: f64| {
            (ln_tone_likelihood(r, continued) - ln_tone_likelihood(r, ended))
                .clamp(-LLR_CLIP, LLR_CLIP)
        };
        for k in basic_tones(t.sender.index() as usize) {
            if !t.present[k] || t.level[k] <= 0.0 {
                continue;
            }
            // Continuation at [`CONTINUATION_SHARE`] (conservative: an unknown phase at
            // the slot edge, and the second frame up to 2.2 dB quieter, as another
            // encoder may normalise each frame's peak) or at the full level.
            let level = t.level[k] * c.ratio;
            let r = power(k);
            for (ci, share) in CONTINUATION_SHARES.iter().enumerate() {
                let continued = level * (before * before + share * after * after);
                for (acc, tail) in self.llr[ci].iter_mut().zip(tails) {
                    if alike(*tail, *share) {
                        continue;
                    }
                    let ended = level * (before * before + tail);
                    *acc += llr(r, ended, continued);
                }
            }
        }
        // A second frame also sounds one data basic, which one unknown: its evidence
        // enters as the best of the 21, doubling what the sender alone gives.
        let leftovers = leftover_shares(after);
        for d in 0..DATA_VALUES as usize {
            let same = d as u8 == c.current_data;
            for k in basic_tones(SENDER_COUNT + d) {
                let level = if same && t.present[k] {
                    t.level[k]
                } else {
                    c.typical
                } * c.ratio;
                if level <= 0.0 {
                    continue;
                }
                let r = power(k);
                if same {
                    // The same data basic goes on at the level it was measured at, at
                    // every data level alike.
                    for (ci, share) in CONTINUATION_SHARES.iter().enumerate() {
                        for (m, tail) in tails.iter().enumerate() {
                            if alike(*tail, *share) {
                                continue;
                            }
                            let ended = level * (before * before + tail);
                            let continued = level * (before * before + share * after * after);
                            let x = llr(r, ended, continued);
                            for acc in &mut self.data_llr[ci][m] {
                                acc[d] += x;
                            }
                        }
                    }
                    continue;
                }
                // Another data basic: "stopped" leaves at most a leftover (per stop
                // hypothesis), "continues" sounds it at a share and a data level; each
                // likelihood once, then their differences.
                let ended: [f64; TAILS] =
                    std::array::from_fn(|m| ln_tone_likelihood(r, level * leftovers[m]));
                for (ci, share) in CONTINUATION_SHARES.iter().enumerate() {
                    for (li, factor) in DATA_LEVELS.iter().enumerate() {
                        let continued =
                            ln_tone_likelihood(r, factor * share * level * after * after);
                        for (m, e) in ended.iter().enumerate() {
                            self.data_llr[ci][m][li][d] +=
                                (continued - e).clamp(-LLR_CLIP, LLR_CLIP);
                        }
                    }
                }
            }
        }
    }
}

/// The end test's verdict on a slot's end.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum EndVerdict {
    /// The sender stopped: the message ends with this slot.
    Stopped,
    /// The sender goes on: a second frame follows.
    Continues,
    /// Neither can be told with the confidence a report needs: the sender's tones went on
    /// but no data basic did at the level of the first frame, or the evidence leans to
    /// "continues" too weakly. Reporting a short could be a wrong message, so nothing is
    /// reported.
    Unclear,
}

impl EndVerdict {
    /// The verdict of a lean (the horizon reached or the stream ended undecided): "continues"
    /// above `bound`, "stopped" when even the weakest continuation leans no further than
    /// that, else unclear.
    fn lean(evidence: &Evidence, bound: f64, effective: impl Fn(f64) -> f64) -> Self {
        if effective(evidence.total()) > bound {
            EndVerdict::Continues
        } else if effective(evidence.against_stop()) <= bound {
            EndVerdict::Stopped
        } else {
            EndVerdict::Unclear
        }
    }
}

/// What the tracked frame would sound like if it continued: the levels measured in its
/// last slot, in units of a window `ratio` times an analysis window's length.
struct Continuation<'a> {
    tracking: &'a Tracking,
    /// The data value of the slot that just ended.
    current_data: u8,
    /// Typical tone level of the slot, for data tones it did not contain.
    typical: f64,
    ratio: f64,
}

/// State of the end test on short windows (see [`Decoder::short_end_test`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct EndWindows {
    /// Next short window, counted from the first after the end.
    next: u32,
    /// Evidence summed over the windows so far.
    evidence: Evidence,
    /// A window's samples were no longer held: the test on analysis windows decides.
    abandoned: bool,
    /// The windows reached [`SPRT_HORIZON`] undecided: the analysis windows' lean decides.
    out_of_time: bool,
}

impl EndWindows {
    fn new() -> Self {
        EndWindows {
            next: 0,
            evidence: Evidence::new(),
            abandoned: false,
            out_of_time: false,
        }
    }

    /// Whether the short windows may still decide.
    pub(super) fn running(&self) -> bool {
        !self.abandoned && !self.out_of_time
    }
}

/// Where the end test after a slot stands.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct EndTest {
    /// The slot that ended (1 or 2).
    pub(super) slot: u8,
    /// Where it ended, sample.
    pub(super) slot_end: f64,
    /// Evidence of the analysis windows so far.
    windows: Evidence,
    /// Next analysis window to weigh.
    next_index: u64,
    /// The test on short windows.
    pub(super) short: EndWindows,
}

impl EndTest {
    /// The end test after `slot` ending at `slot_end`, weighing analysis windows from
    /// `next_index` on.
    pub(super) fn new(slot: u8, slot_end: f64, next_index: u64) -> Self {
        EndTest {
            slot,
            slot_end,
            windows: Evidence::new(),
            next_index,
            short: EndWindows::new(),
        }
    }
}

/// The end test's short Hann window and how much overlapping ones share.
pub(super) struct ShortWindow {
    hann: Vec<f64>,
    /// Samples between window starts.
    hop: usize,
    /// Amplitude correlation of noise between windows 1, 2, … hops apart.
    overlap: Vec<f64>,
}

impl ShortWindow {
    /// The short window for analysis windows of `window_len` samples.
    pub(super) fn new(window_len: usize) -> Self {
        let len = ((END_WINDOW_SHARE * window_len as f64).round() as usize).max(8);
        let hann: Vec<f64> = (0..len)
            .map(|n| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * n as f64 / len as f64).cos())
            .collect();
        let hop = ((END_HOP_SHARE * len as f64).round() as usize).max(1);
        let energy: f64 = hann.iter().map(|w| w * w).sum();
        let overlap = (1..)
            .map(|m| m * hop)
            .take_while(|&lag| lag < len)
            .map(|lag| {
                hann.iter()
                    .zip(&hann[lag..])
                    .map(|(a, b)| a * b)
                    .sum::<f64>()
                    / energy
            })
            .collect();
        ShortWindow { hann, hop, overlap }
    }

    /// The evidence `sum` of `n` overlapping short windows in independent terms: divided
    /// by the variance inflation of a sum of `n` correlated terms,
    /// 1 + 2 Σ_m (1 − m/n) c_m, with c_m the windows' amplitude correlation m hops apart
    /// (the bound where a steady tone's cross term dominates; the powers of noise alone
    /// correlate only by c_m²). One window counts fully; a long run about 3/8 (hop 1/4).
    fn effective(&self, sum: f64, n: u32) -> f64 {
        let n = f64::from(n.max(1));
        let inflation = 1.0
            + 2.0
                * self
                    .overlap
                    .iter()
                    .enumerate()
                    .map(|(i, c)| (1.0 - (i + 1) as f64 / n).max(0.0) * c)
                    .sum::<f64>();
        sum / inflation
    }
}

/// Powers of the Hann-weighted samples `y` at the angular frequencies (rad/sample) whose
/// `2 cos ω` are `coefs`, in the analysis's units (|Σ y e^{−iωn}|²): Goertzel's recursion,
/// all tones in one pass over the samples (three flops per sample and tone).
pub(super) fn tone_powers(y: &[f64], coefs: &[f64; TONE_COUNT]) -> [f64; TONE_COUNT] {
    let mut s1 = [0.0f64; TONE_COUNT];
    let mut s2 = [0.0f64; TONE_COUNT];
    for &v in y {
        for k in 0..TONE_COUNT {
            let s0 = v + coefs[k] * s1[k] - s2[k];
            s2[k] = s1[k];
            s1[k] = s0;
        }
    }
    std::array::from_fn(|k| (s1[k] * s1[k] + s2[k] * s2[k] - coefs[k] * s1[k] * s2[k]).max(0.0))
}

impl Decoder {
    /// Moves the end test `test` of the tracked frame `t` on with the samples and windows
    /// that arrived: the verdict (continues?) and, when the short windows reached it, the
    /// sample at which they did; `None` until then.
    pub(super) fn decide_end(
        &self,
        t: &Tracking,
        test: &mut EndTest,
    ) -> Option<(EndVerdict, Option<f64>)> {
        let c = Continuation {
            tracking: t,
            current_data: t.data[usize::from(test.slot.clamp(1, 2) - 1)],
            typical: median(
                (0..TONE_COUNT)
                    .filter(|&k| t.present[k] && t.level[k] > 0.0)
                    .map(|k| t.level[k])
                    .collect(),
            ),
            ratio: 1.0,
        };
        if test.short.running() {
            if let Some((continues, at)) = self.short_end_test(&c, test.slot_end, &mut test.short) {
                return Some((continues, Some(at)));
            }
        }
        self.window_end_test(&c, test)
            .map(|verdict| (verdict, None))
    }

    /// The short/long test after a slot's end, on short Hann windows
    /// ([`END_WINDOW_SHARE`] of an analysis window, the first starting at the estimated
    /// end, then every [`END_HOP_SHARE`] of their length) at the
    /// frame's exact frequencies, each judged as soon as its samples arrive. Each window
    /// adds, per tone, the log-likelihood ratio of "continues" (the sender's tones at
    /// [`CONTINUATION_SHARE`] of the level measured in the slot; a second frame's data
    /// basic, the best of the 21, likewise) against "stopped"; the sum, divided by its
    /// variance inflation from the windows' overlap, decides "stopped" at
    /// −[`END_BOUND_NATS`] and "continues" at [`END_CONTINUE_NATS`] + ln 21. A loud slot
    /// decides on its first window; a quieter one after a few more.
    /// Returns the verdict (continues?) and the sample at which it was reached, or `None`
    /// until then; marks the state out of time at [`SPRT_HORIZON`] (the analysis windows'
    /// lean then decides) and abandoned when a window's samples are no longer held. At the
    /// end of the stream, a weak lean is a stop.
    fn short_end_test(
        &self,
        c: &Continuation,
        slot_end: f64,
        st: &mut EndWindows,
    ) -> Option<(EndVerdict, f64)> {
        let t = c.tracking;
        let window_len = self.geometry.window_len as f64;
        let slot_len = self.geometry.slot_samples;
        let slot_start = slot_end - slot_len;
        let len = self.short_window.hann.len();
        let hop = self.short_window.hop as u64;
        // No guard after the end: the Hann taper keeps a late end's tail small (20 ms late,
        // a 64 ms window holds 3% of the tone's power), and a tail only slows "stopped",
        // while a guard would delay every report by its length.
        let first = slot_end.ceil().max(0.0) as u64;
        // Normalised like the analysis: a Hann window of `len` has `len / L` of the noise
        // power of one of length L, and (`len / L`)² of a steady tone's.
        let ratio = len as f64 / window_len;
        let c = Continuation { ratio, ..*c };
        let scale = 1.0 + self.geometry.scales[t.scale];
        let rate = self.rate();
        let coefs: [f64; TONE_COUNT] = std::array::from_fn(|k| {
            2.0 * (2.0 * std::f64::consts::PI * tone_frequency_hz(k) * scale / rate).cos()
        });
        let normaliser = |k: usize| (t.noise * self.noise.shape[k] * ratio).max(1e-300);
        let effective = |st: &EndWindows, x: f64| self.short_window.effective(x, st.next);
        loop {
            let start = first + u64::from(st.next) * hop;
            let end = start + len as u64;
            let Some(x) = self.analyzer.samples(start, len) else {
                if self.analyzer.samples_pushed() >= end {
                    st.abandoned = true;
                    return None;
                }
                if self.eof {
                    let at = self.analyzer.samples_pushed() as f64;
                    let verdict =
                        EndVerdict::lean(&st.evidence, END_BOUND_NATS / 3.0, |x| effective(st, x));
                    return Some((verdict, at));
                }
                return None;
            };
            let mean = x.iter().map(|&v| f64::from(v)).sum::<f64>() / len as f64;
            let y: Vec<f64> = x
                .iter()
                .zip(&self.short_window.hann)
                .map(|(&v, &w)| (f64::from(v) - mean) * w)
                .collect();
            let s = start as f64;
            let before = hann_share_inside(s, len as f64, slot_start, slot_end);
            let after = hann_share_inside(s, len as f64, slot_end, slot_end + slot_len);
            let powers = tone_powers(&y, &coefs);
            let tails = tail_shares(
                after,
                (s + 0.5 * len as f64 - slot_end) / rate,
                self.config.tone_duration_s,
            );
            st.evidence
                .add_window(&c, before, after, &tails, |k| powers[k] / normaliser(k));
            st.next += 1;
            let evidence = effective(st, st.evidence.total());
            let at = end as f64;
            // "Continues" rests on the best of 21 data basics: a union over them costs
            // ln 21 (the stop side needs no such allowance: the true one is among them).
            // Where the sender's own tones lean to "continues", "stopped" must also beat a
            // second frame whose data tones sound far below the first frame's (see
            // `DATA_LEVELS`), as in the lean at the horizon: in a hall a long message's
            // second data basic may reach the microphone 10 dB down while its sender
            // plainly goes on, and tested at the typical level alone the frame was cut to
            // a wrong short within a few windows. Where the sender leans to "stopped" the
            // typical-level test decides within a few windows (the weak data hypotheses,
            // each near neither side, would only slow it).
            if evidence >= END_CONTINUE_NATS + (DATA_VALUES as f64).ln() {
                return Some((EndVerdict::Continues, at));
            }
            if st.evidence.stopped(|x| effective(st, x) <= -END_BOUND_NATS) {
                return Some((EndVerdict::Stopped, at));
            }
            if at >= slot_end + SPRT_HORIZON * slot_len {
                st.out_of_time = true;
                return None;
            }
        }
    }

    /// After a second slot that failed its decision: whether the sender had plainly
    /// stopped at the first slot's end `end`, judged on the analysis windows wholly in the
    /// second half of that second slot (from [`SPRT_HORIZON`] slots after `end` on).
    ///
    /// The end test decides within half a slot, and in a hall a short message's own tail
    /// sometimes passes there for a continuation (a tone in a notch of the room's
    /// response reverberates louder than it sounded, and talkers put power on the data
    /// tones); the second slot then fails, and the message would be lost. Half a slot
    /// later any tail of T60 up to 2.5 s has fallen 12 dB more, while a second frame's
    /// sender sounds through its whole slot: the sender's tones alone, against every
    /// stop hypothesis at each continuation level, must say "stopped" at
    /// [`SPRT_BOUND`]. A long message whose second slot failed keeps its sender sounding
    /// there and is not taken for a short.
    pub(super) fn sender_stopped_late(&self, t: &Tracking, end: f64) -> bool {
        self.basic_stopped_late(t, t.sender.index() as usize, end)
    }

    /// After a second slot that failed its decision, under a plan whose short messages
    /// say data of their own ([`crate::TeamPlan::Checked`]: data 0 … 9): whether the
    /// first frame of `t`, ending at `end`, was a short message that stopped. Its data
    /// can begin no long message, so what the end test took for a continuation was its
    /// tail or the robot's next message; the message ends when the sender fell below the
    /// frame's level over the second quarter of a slot after `end` (the gap a robot
    /// leaves between messages, at least half a tone) and the first frame's data plainly
    /// stopped over the second half ([`Decoder::data_stopped_after_gap`]).
    ///
    /// Why: on the short lab T60 1.2 s 0 dB row, tuning draws S = 111–122, 11 of the 86
    /// lost short messages were lost on a second slot: the end test took the tail (a
    /// tone in a notch ringing on, talkers on the sender's tones) for a second frame, and
    /// the slot then failed; the sender's next message, begun 0.6 s after the end,
    /// sounded in the late test's span (111015 at 1560.70 s). Tones that go straight on
    /// through the gap are a frame that sounded too long, whatever it was, and are never
    /// taken; nor is a frame whose next message says the same data.
    pub(super) fn short_stopped_late(&self, t: &Tracking, end: f64) -> bool {
        if !self.config.team.frame_is_short_only(t.data[0]) {
            return false;
        }
        let data_stopped = self.data_stopped_after_gap(t, t.data[0], end);
        self.note(end, || {
            format!("late short check: data stopped after the gap {data_stopped}")
        });
        data_stopped
    }

    /// Whether the frame of `t` whose data is `data`, ending at `end`, ended its message:
    /// the sender fell below the frame's level over the second quarter of a slot after
    /// `end` (the gap a robot leaves between messages, at least half a tone, so its next
    /// message cannot sound there), and the data plainly stopped over the second half (as
    /// [`Decoder::sender_stopped_late`] judges the sender). Tones that go straight on
    /// through the gap are a frame that sounded too long, whatever its data.
    pub(super) fn data_stopped_after_gap(&self, t: &Tracking, data: u8, end: f64) -> bool {
        let slot_len = self.geometry.slot_samples;
        !self.sender_keeps_level(t, end + 0.25 * slot_len, end + 0.5 * slot_len)
            && self.basic_stopped_late(t, SENDER_COUNT + usize::from(data), end)
    }

    /// [`Decoder::sender_stopped_late`] for any basic's tones of `t` (as present and
    /// measured in its last decided slot).
    pub(super) fn basic_stopped_late(&self, t: &Tracking, basic: usize, end: f64) -> bool {
        let window_len = self.geometry.window_len as f64;
        let slot_len = self.geometry.slot_samples;
        if slot_len < 4.0 * window_len {
            // Half a slot of a window or so: nothing to go by but windows that reach past
            // the second slot, where a long message has ended too.
            return false;
        }
        let typical = median(
            (0..TONE_COUNT)
                .filter(|&k| t.present[k])
                .map(|k| t.level[k])
                .collect(),
        );
        if typical < LATE_MIN_LEVEL {
            // A frame barely above the floor: the end test could not tell because there
            // was little to tell by, and babble assembles such frames now and then.
            return false;
        }
        let (from, to) = (end + SPRT_HORIZON * slot_len, end + slot_len);
        let mut llr = [[0.0f64; TAILS]; CONTINUATIONS];
        let mut windows = 0;
        for w in &self.history {
            let start = w.start as f64;
            if start < from || start + window_len > to {
                continue;
            }
            windows += 1;
            let after = hann_share_inside(start, window_len, end, end + slot_len);
            let tails = tail_shares(
                after,
                (start + 0.5 * window_len - end) / self.rate(),
                self.config.tone_duration_s,
            );
            for k in basic_tones(basic) {
                if !t.present[k] || t.level[k] <= 0.0 {
                    continue;
                }
                let r = f64::from(w.r[t.scale * TONE_COUNT + k]) * w.level / t.noise;
                for (acc, share) in llr.iter_mut().zip(CONTINUATION_SHARES) {
                    let continued = ln_tone_likelihood(r, t.level[k] * share * after * after);
                    for (x, tail) in acc.iter_mut().zip(tails) {
                        *x += (continued - ln_tone_likelihood(r, t.level[k] * tail))
                            .clamp(-LLR_CLIP, LLR_CLIP);
                    }
                }
            }
        }
        windows > 0 && (0..TAILS).any(|m| llr.iter().all(|acc| acc[m] <= -SPRT_BOUND))
    }

    /// The same test on the analysis windows (almost) wholly after the slot end, run
    /// alongside the short windows: it decides at ±[`SPRT_BOUND`] only when the short
    /// windows' samples were no longer held, and by its lean when the short windows ran
    /// out of time undecided (at low SNR the short windows' lean is the noisier one) or
    /// the stream ends. Out of time, a long message continues with no gap, so its
    /// evidence comes early and strong: a weak lean is a stop.
    fn window_end_test(&self, c: &Continuation, test: &mut EndTest) -> Option<EndVerdict> {
        let t = c.tracking;
        let window_len = self.geometry.window_len as f64;
        let slot_len = self.geometry.slot_samples;
        let slot_end = test.slot_end;
        let slot_start = slot_end - slot_len;
        let fallback = test.short.abandoned;
        let lean_here = test.short.abandoned || test.short.out_of_time;
        let mut verdict = None;
        for w in &self.history {
            if w.index < test.next_index {
                continue;
            }
            test.next_index = w.index + 1;
            let start = w.start as f64;
            if start + window_len <= slot_end {
                continue;
            }
            let before = hann_share_inside(start, window_len, slot_start, slot_end);
            // Only windows (almost) wholly after the estimated slot end: the power of a
            // window straddling the end depends on the exact end, known only to some tens
            // of milliseconds, and at high SNR that mismatch alone would decide the test.
            if before > MAX_SHARE_BEFORE_END {
                continue;
            }
            let after = hann_share_inside(start, window_len, slot_end, slot_end + slot_len);
            // Same normalisation as the slot, so levels compare directly even where the
            // per-window noise estimate jumps.
            let tails = tail_shares(
                after,
                (start + 0.5 * window_len - slot_end) / self.rate(),
                self.config.tone_duration_s,
            );
            test.windows.add_window(c, before, after, &tails, |k| {
                f64::from(w.r[t.scale * TONE_COUNT + k]) * w.level / t.noise
            });
            if fallback && test.windows.total() >= SPRT_BOUND {
                verdict = Some(EndVerdict::Continues);
            } else if fallback && test.windows.against_stop() <= -SPRT_BOUND {
                verdict = Some(EndVerdict::Stopped);
            } else if lean_here && start + window_len >= slot_end + SPRT_HORIZON * slot_len {
                verdict = Some(EndVerdict::lean(&test.windows, SPRT_BOUND / 3.0, |x| x));
            }
            if verdict.is_some() {
                break;
            }
        }
        if verdict.is_none() && self.eof && lean_here {
            verdict = Some(EndVerdict::lean(&test.windows, SPRT_BOUND / 3.0, |x| x));
        }
        verdict
    }
}
