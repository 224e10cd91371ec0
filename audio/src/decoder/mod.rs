//! The streaming decoder: a sans-IO detector you push samples into and poll messages out of.
//!
//! # Where each idea lives
//!
//! | file            | what it holds                                                       |
//! |-----------------|---------------------------------------------------------------------|
//! | `mod.rs`        | the public API: [`Decoder`], [`DecoderConfig`], [`Detection`]        |
//! | `windows.rs`    | analysed windows: normalised, kept for look-back, integrated         |
//! | `noise_floor.rs`| the noise level and spectral shape powers are divided by             |
//! | `rules.rs`      | the seed's rules (tone present, 2-of-3 vote, one sender, one data)   |
//! | `search.rs`     | finding a frame in the integrated sums while nothing is tracked      |
//! | `onset.rs`      | where a found frame began                                            |
//! | `confirm.rs`    | the decision on one aligned slot, and the checks a message must pass |
//! | `off_grid.rs`   | the check that all six tones share one frequency scale               |
//! | `coherence.rs`  | the check that a frame's two basics begin and end together           |
//! | `bursts.rs`     | the check that a first frame is not one the background assembled   |
//! | `refusals.rs`   | first slots refused for a foreign sound, remembered over their span  |
//! | `tracking.rs`   | following a frame from its first slot to a report                    |
//! | `second_slot_by_sums.rs` | a refused second slot decided by its data's median windows |
//! | `end_test.rs`   | the end test after a slot: short or long message                     |
//!
//! # How it decides
//!
//! 1. **Analysis** (`analysis`): Hann windows of about 1/8 of a tone (64–128 ms), half
//!    overlapping, zero-padded FFT; the power of each of the 72 tones at each candidate
//!    frequency scale.
//! 2. **Noise floor** ([`NoiseFloor`]): per window, the level is the median over the 66
//!    tones outside the candidate frame (the tracked one, else the best sender and data
//!    basic so far), over that order statistic's expectation, divided by the spectral
//!    shape (with the frame's tones in, the median would read high exactly while a
//!    message sounds); the shape (pink noise, a microphone's response) is a slow,
//!    outlier-gated average per tone, frozen on the tones of a message being tracked.
//!    The level never falls below −13 dB of the band's mean tone power held at its peak
//!    and let down 20 dB per three tone durations: a background that stops and starts
//!    (talkers pausing into digital silence) would otherwise swing a steady tone's
//!    normalised power by orders of magnitude from window to window.
//!    Powers are divided by level × shape, so under noise each is ≈ Exp(1). The level is
//!    smoothed lightly, except that one 10 dB or more off is taken at once: a new
//!    background (a sound after digital silence, a tail dying away), not the estimate's
//!    spread; smoothed across such a step, the first windows of a message after silence
//!    read tens of times louder than its last.
//! 3. **Integration**: the normalised powers of the last `n` windows that fit in one tone
//!    duration are summed per tone and scale (the energy detector matched to the tone
//!    length). Under noise each sum is ≈ Gamma(n, 1).
//! 4. **Detection**: for each scale, the best sender basic and the best data basic (sums
//!    of their three tones); the frame hypothesis energy (six tones) must exceed the
//!    Gamma(6n) quantile for a per-window false-alarm probability of
//!    [`P_FRAME`](search::P_FRAME) after a union bound over the 63 hypotheses and all
//!    scales. This is a coarse gate; the rules below carry most of the false-alarm
//!    protection.
//! 5. **The seed's rules**, on the integrated sums at the chosen scale: a tone is present
//!    when its sum exceeds the Gamma(n) quantile at [`P_TONE`](search::P_TONE) and is not
//!    merely leakage from a much louder neighbour; a basic is present when ≥ 2 of its 3
//!    tones are; the frame is valid only with exactly one sender basic and exactly one data
//!    basic. Two consecutive windows must give the same valid frame before it is accepted.
//!    On the aligned slot the frame's six-tone energy must pass the frame test again, at
//!    the stricter [`P_FRAME_CONFIRM`](confirm::P_FRAME_CONFIRM), and a rival basic (a
//!    second sender or data basic) must pass the stricter
//!    [`P_TONE_RIVAL`](confirm::P_TONE_RIVAL) to reject the frame. A stray tone outside
//!    the frame's basics is judged by its own test (step 7). In a hall a real frame's
//!    tones each reach the microphone at their own level (a tone in a notch of the room
//!    sits 10–20 dB below the others), and babble puts two tones of some other basic, or
//!    a single tone, at that level now and then: for a frame that stands clear of the
//!    floor (typical tone ≥ 15 dB per window, as the messages of the 0 dB babble rows
//!    mostly are; babble's frames sit near 0 dB), a rival basic counts only if its votes sound like a
//!    transmitter's (the tone checks of step 7), and a stray only if it sounds steadily.
//! 6. **Timing and re-decision**: once accepted, the onset is located on the per-window
//!    energy of the frame's six tones (a step-change estimate refined by a least-squares
//!    fit of the Hann-window share of the windows around the step), once more when the
//!    whole slot has been heard; the frame is re-decided with the rules on exactly the
//!    windows inside `[onset, onset + T]`.
//! 7. **Short or long**: a sequential probability ratio test on the sender's tones (and
//!    a second frame's data basic, the best of the 21) just after the slot end, with the
//!    tone level measured in the slot: sender stops → a short message; sender continues →
//!    a second slot is decided the same way and the sender must then stop → a long
//!    message. A frame that keeps sounding past two slots is not a message (and is
//!    ignored until it stops), unless, half a slot later, the sender is plainly silent
//!    (the same late test as after an unclear first slot), or the second frame's data
//!    is (the sender's next message may begin there, just over half a tone later): then
//!    what went on was the second frame's own tail in a hall, and the two slots are a
//!    long message. A second slot the checks below refuse, its sender holding its level
//!    through both halves, is decided once more under a plan whose long frames say data
//!    of their own (`second_slot_by_sums.rs`): the data basic whose three tones' median
//!    window stands 4 times clear of every other candidate's.
//!    The test runs on short Hann windows (half an analysis window, 64 ms at 1 s tones)
//!    from the estimated end on, every quarter of their length, at the frame's exact
//!    frequencies, each judged as soon as its samples arrive. Overlapping windows do not
//!    carry independent evidence: the sum is divided by its variance inflation
//!    (1 + 2 Σ (1 − m/n) c_m over the windows' correlations c_m; one window counts fully,
//!    a long run 3/8) before it meets the bounds: "stopped" at 7 nats (a long message
//!    cut to a wrong short about 1 in 1000 at the conservative continuation level),
//!    "continues" at 12 + ln 21 nats (a wrong "continues" loses the message, a late one
//!    costs nothing). Undecided at the horizon, the same test on the analysis windows
//!    gives the lean (a weak lean is a stop). "Stopped" must also beat a second frame
//!    whose data tones sound up to 14 dB below the first frame's (in a hall each tone
//!    has its own level), in the lean and, under any stop hypothesis the sender's own
//!    tones do not bear out, in the short windows too; when the sender plainly went on
//!    but no data basic did at the first frame's level, the verdict is unclear: a long
//!    message is lost rather than cut to a wrong short. An unclear end, and a second
//!    slot that fails after "continues", are looked at once more half a slot later,
//!    when any tail up to T60 2.5 s has fallen 12 dB more while a second frame's sender
//!    still sounds at full level: a sender plainly silent there (its tones alone, at
//!    ±14) makes the first slot a short message (in a hall a short message's own tail,
//!    a tone in a notch of the room reverberating louder than it sounded, passes for a
//!    continuation now and then). A second slot must also keep the sender's level through
//!    its second half (≥ −5 dB of the first slot's, within the noise): a T60 2.5 s tail
//!    of a frame, front-loaded, holds a fifth of its energy over the next second and,
//!    with the same data, passed for a second frame.
//!    The test looks half a slot past the end, so two messages from one robot need more
//!    than half a tone of silence between them (closer frames *are* a long message).
//!    Each slot must also sound through: both of its halves carry a fair share of the
//!    frame's energy (a foreign burst shorter than a slot does not).
//!    And a slot where a tone outside the frame is about as loud as the frame's own is
//!    someone else's multi-tone signal that happens to contain our two basics.
//!    So is a slot whose tones do not share one frequency scale: a sender's clock error
//!    moves all six tones by one factor, while another codec's tones that pass near ours
//!    are each off by their own amount (a present tone must keep most of its best-scale
//!    power at one common scale, within the noise (for a frame clear of the floor, the
//!    slot's own best scale: the one found by the search may sit a bin off in a hall); at
//!    the comb's edge the power must not still be rising outward; tones 20 dB above their
//!    neighbourhood must have interpolated peaks that agree with one scale within a
//!    fraction of a hertz (babble around a tone pulls its peak, and a hall's low tones sit
//!    in the talkers' band), and none may peak on the bin just beyond the comb). One tone
//!    of a frame clear of the floor may miss the common scale, or one loud tone's peak
//!    disagree (or lie beyond the comb) while at least three others agree, when its
//!    basic keeps its 2-of-3 vote on its other two tones: in a babble hall a talker's
//!    harmonic beside a low tone pulls it by hertz, while another codec's tones are each
//!    off by their own amount.
//!    A tone outside the frame much louder than one its 2-of-3 votes rest on is a stray
//!    too.
//!    And each vote must be a tone's, not babble's: the two tones of each basic its vote
//!    rests on must be present in each half of the slot on their own (and above most of
//!    the band's other tones there), stand above their neighbourhood (a formant region of
//!    speech lifts all its tones), and not fall to the floor between bursts more often
//!    than a steady tone at their level would (a held harmonic does).
//!    And the frame's two basics must be one transmitter's (`coherence.rs`): neither fades
//!    from a quarter of the slot the other holds (two robots a fraction of a tone apart
//!    put one's sender and the other's data in a slot found between them); the frame does
//!    not fade from the slot's last quarter unless it sounded just before the onset (a
//!    burst shorter than a tone); and under a first slot no other sender or data basic
//!    with two tones at the rival level sounds like a transmitter's, at any level (two
//!    robots starting together: which data is whose cannot be told).
//!    Symmetrically, a first frame whose sender was already sounding just before it is the
//!    second half of a long message whose first half was missed, and is dropped; so is
//!    one right after a failed slot of the same sender, unless (for a frame clear of the
//!    floor) the sender's tones did not hold their level through that slot: the two
//!    frames of a long message sound the same tones through the same room, while a slot
//!    babble assembled, or the sender's next message found early, holds them only in part.
//! 8. **Once per transmission**: after a decision the integration restarts after the
//!    transmission's end.
//! 9. **Replay**: while a frame is tracked the search is idle. When a first slot fails
//!    (babble assembled a frame for a moment over a hall's tail), the search runs again
//!    over the windows heard since just before that frame's onset, as a second search
//!    running alongside would have, so a message that began meanwhile is found at its
//!    onset rather than half over. Replays run one after another, each starting after the
//!    last one's floor. A first slot failing right after the same sender's decided
//!    transmission is that transmission's tail, not a long message's lost first frame.
//!    A failed second slot is replayed from its start too (a message of another robot may
//!    have begun under it), without tracking its sender's frames that begin inside the
//!    failed transmission (its own second frame, or its tail).
//!
//! # False alarms
//!
//! A false message needs, in two consecutive windows, the six-tone energy above a
//! threshold at 1e-6 per window (union-bounded over hypotheses and scales) *and* ≥ 2 of 3
//! tones of exactly one sender basic and of exactly one data basic at
//! [`P_TONE`](search::P_TONE) per tone. Consecutive windows share 13 of 14 windows'
//! energy, so the second window adds little independence: the search alone lets through
//! about 1e-6 of noise windows, i.e. ≲ 0.6 per 10 hours of Gaussian noise (≈ 560 000
//! windows at 64 ms). The aligned slot then needs its six-tone energy at
//! [`P_FRAME_CONFIRM`](confirm::P_FRAME_CONFIRM) = 1e-10 (union-bounded), the rules again
//! ([`P_TONE_CONFIRM`](confirm::P_TONE_CONFIRM)), and the sender stopping cleanly: well
//! under 1e-3 false messages per 10 hours of Gaussian noise. What is left are structured
//! sounds, which `huddle audio eval` measures. Speech is one, and the rules step assumes
//! what it is not: exponential powers, independent from window to window and tone to
//! tone. Over a slot, speech lifts whole formant regions of the band several times above
//! the floor, and a talker's harmonic held for a syllable (smeared over a second by a
//! hall) puts a burst on one tone; six talkers assemble a frame of weak tones from such
//! bursts now and then (the room rules, which let a rival basic count only within 6 dB
//! and bound crowds of tones to 10 dB, made that easier: 19 false messages in 10 h of
//! reverberant babble and 1 in 10 h of dry babble before the checks below). A message's
//! tones differ in three ways babble cannot easily fake together, each checked on the
//! tones of each basic its vote rests on: they sound in *both halves* of the slot
//! (present in each half at a lenient 0.2 and above 80% of the band's other tones there,
//! a rank test that needs no noise model); they stand above *their neighbourhood* (±3
//! tones; in a formant region the Gamma threshold is scaled by the region's level); and
//! they are *steady* (a tone at level λ reads below the noise mean in a window with
//! probability p(λ), and a vote tone with more such dropouts than a binomial at p(λ)
//! allows at 1e-3 was bursts; where speech lifts the neighbourhood, the median window
//! must show the tone too; and a tone 6 dB or more above the noise over the slot must
//! hold a quarter of that level in its median window: a "tone" of two or three bursts
//! has its mean far above its median). A tone outside the frame counts as a stray (a
//! foreign transmitter's) only if it passes the same steadiness test. Under Gaussian noise these cost little (the neighbourhood
//! and the rank read the floor), so the argument above stands; under babble they are
//! what holds, and that is measured, not derived: `huddle audio eval --noise-time
//! 600min` counts false messages in 10 h of dry and of reverberant babble (the crate's
//! room tests hold 20 min of each at 0, and 10 h of each with `--ignored`).

//! # Report delay
//!
//! A short message is reported once the sender is known to have stopped (otherwise it may
//! be the first half of a long message, and reporting it would be a wrong message). A
//! loud slot decides on the first short window after its end, i.e. about one short window
//! after the end; a quieter one needs a few more windows, a hop apart. Lower still, the
//! evidence is simply not there sooner: each tone is barely above the noise in a window,
//! the sender's three tones give a few tenths of a nat per window towards "stopped", and
//! holding wrong accepts at 1e-3 needs about 7 nats, i.e. more than the half-slot horizon
//! holds: the lean decides there, about half a tone after the end.

mod bursts;
mod coherence;
mod confirm;
mod end_test;
mod noise_floor;
mod off_grid;
mod onset;
mod own_tones;
mod refusals;
mod rules;
mod search;
mod second_slot;
mod second_slot_by_sums;
mod tracking;
mod windows;

#[cfg(test)]
mod bursts_tests;
#[cfg(test)]
mod coherence_tests;
#[cfg(test)]
mod own_tones_tests;
#[cfg(test)]
mod tests;

use std::collections::VecDeque;

use crate::analysis::{Analyzer, Geometry};
use crate::team::{TeamMessage, TeamPlan};
use crate::tones::{Message, Sender, TONE_COUNT};

use end_test::ShortWindow;
use noise_floor::NoiseFloor;
use search::Run;
use tracking::{Stage, Tracking};
use windows::WindowRecord;

/// Shortest tone duration the decoder accepts, s (see [`DecoderConfigError::ToneDuration`]).
pub const MIN_TONE_DURATION_S: f64 = 0.06;

/// Reports the team plan refused that a decoder keeps for [`Decoder::poll_refused`] when
/// nobody polls them (the oldest go first): the decoder's state stays bounded.
const REFUSED_KEPT: usize = 64;

/// How to decode.
#[derive(Clone, Debug, PartialEq)]
pub struct DecoderConfig {
    /// Input sample rate, Hz (8000 … 192000).
    pub sample_rate_hz: u32,
    /// Duration of one frame (short message), seconds, as the senders use it.
    pub tone_duration_s: f64,
    /// Largest relative frequency error tolerated between sender and receiver clocks.
    pub max_frequency_error: f64,
    /// The team plan the senders use: messages it cannot have sent are dropped (see
    /// [`TeamPlan`]; [`Detection::team_message`] reads a detection under it).
    pub team: TeamPlan,
}

impl Default for DecoderConfig {
    fn default() -> Self {
        DecoderConfig {
            sample_rate_hz: 16_000,
            tone_duration_s: 1.0,
            max_frequency_error: 0.006,
            team: TeamPlan::Three,
        }
    }
}

/// Why a decoder configuration is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecoderConfigError {
    /// The rate must be 8000 … 192000 Hz: below 8 kHz the top tone is above Nyquist.
    #[error("sample rate {0} Hz unsupported (8000..=192000)")]
    SampleRate(u32),
    /// The tone duration must be 0.06 … 5 s: the analysis window is at least 64 ms (so
    /// tones 49 Hz apart stay resolved), and tones much shorter than it are decoded
    /// wrongly more often than a wrong message may be.
    #[error("tone duration {0} s unsupported (0.06..=5)")]
    ToneDuration(f64),
    /// The tolerated frequency error must be 0 … 2%.
    #[error("frequency error {0} unsupported (0..=0.02)")]
    FrequencyError(f64),
}

/// A decoded message.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Detection {
    /// What was said.
    pub message: Message,
    /// When it began, seconds from the first sample pushed.
    pub start_s: f64,
    /// When it ended (estimated), seconds from the first sample pushed.
    pub end_s: f64,
    /// How much audio had been pushed when it was decided, seconds: `decided_at_s - end_s`
    /// is the reporting delay.
    pub decided_at_s: f64,
    /// Sender's frequency scale relative to the plan (1.003 = 0.3% sharp).
    pub frequency_scale: f64,
    /// Estimated signal-to-noise ratio per tone in one analysis window, dB.
    pub tone_snr_db: f64,
}

impl Detection {
    /// The message as the team plan `plan` reads it (robot, short or long, value), `None`
    /// if that plan cannot have sent it.
    pub fn team_message(&self, plan: TeamPlan) -> Option<TeamMessage> {
        plan.decode(&self.message)
    }
}

/// The streaming decoder. Push samples in any block size with [`Decoder::push_f32`] or
/// [`Decoder::push_i16`]; after each push, drain [`Decoder::poll_message`] until `None`.
/// At the end of a stream call [`Decoder::finish`] and drain again.
///
/// No input panics it: non-finite samples count as 0, silence is handled, and the
/// state's size is bounded by the configuration.
pub struct Decoder {
    config: DecoderConfig,
    analyzer: Analyzer,
    geometry: Geometry,
    noise: NoiseFloor,
    history: VecDeque<WindowRecord>,
    history_cap: usize,
    windows_seen: u64,
    /// Per-tone sums over the integration windows, `[j * 72 + k]`.
    sliding: Vec<f64>,
    /// Index of the oldest window in `sliding`, and how many are summed.
    sliding_first: u64,
    sliding_count: usize,
    /// Windows starting before this sample belong to a finished transmission.
    floor: u64,
    run: Option<Run>,
    tracking: Option<Tracking>,
    /// A frame that kept sounding too long, or whose transmission was just decided (its
    /// reverberant tail): ignored until it falls quiet.
    blocked: Option<search::Blocked>,
    /// The frame of the last decided transmission, while its tail may still sound.
    recent: Option<search::Recent>,
    /// Sender and end (sample) of the last slot that failed its decision: a frame from
    /// the same sender right after it is the second half of a long message.
    failed_slot: Option<(Sender, f64)>,
    /// Sender and end (sample) of the last transmission whose second slot failed: the
    /// replay after it does not track that sender's frames beginning before that end
    /// (its own second frame, or its tail; see `Decoder::decide_slot`).
    failed_transmission: Option<(Sender, f64)>,
    /// While the search replays windows already heard (see [`Decoder::replay_search`]):
    /// the index of the window it stands at, which it treats as the newest.
    replaying: Option<u64>,
    /// A replay asked for (from this floor) by a decision taken during a search or a
    /// replay; run once that has returned (see [`Decoder::run_pending_replays`]).
    pending_replay: Option<u64>,
    /// First slots lately refused for a foreign sound under them (see `refusals.rs`).
    refusals: std::cell::Cell<refusals::Refusals>,
    output: VecDeque<Detection>,
    /// Reports the team plan cannot have sent, dropped from `output` (the newest
    /// [`REFUSED_KEPT`]; see [`Decoder::poll_refused`]).
    refused: VecDeque<Detection>,
    scratch_powers: Vec<f32>,
    /// The end test's short window.
    short_window: ShortWindow,
    eof: bool,
    /// Diagnosis: what the decoder decided and why, when asked for (see
    /// [`Decoder::enable_trace`]); `None` costs nothing.
    trace: std::cell::RefCell<Option<Vec<TraceEvent>>>,
}

/// One step of the decoder's reasoning, for diagnosis (see [`Decoder::enable_trace`]).
#[derive(Clone, Debug, PartialEq)]
pub struct TraceEvent {
    /// Where in the stream it concerns, s (a frame's onset or a slot's end).
    pub at_s: f64,
    /// What happened.
    pub what: String,
}

impl std::fmt::Debug for Decoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Decoder")
            .field("config", &self.config)
            .field("window_len", &self.geometry.window_len)
            .field("windows_seen", &self.windows_seen)
            .finish()
    }
}

impl Decoder {
    /// A decoder for `config`.
    pub fn new(config: DecoderConfig) -> Result<Decoder, DecoderConfigError> {
        if !(8_000..=192_000).contains(&config.sample_rate_hz) {
            return Err(DecoderConfigError::SampleRate(config.sample_rate_hz));
        }
        if !(MIN_TONE_DURATION_S..=5.0).contains(&config.tone_duration_s) {
            return Err(DecoderConfigError::ToneDuration(config.tone_duration_s));
        }
        if !(0.0..=0.02).contains(&config.max_frequency_error) {
            return Err(DecoderConfigError::FrequencyError(
                config.max_frequency_error,
            ));
        }
        let geometry = Geometry::new(
            config.sample_rate_hz,
            config.tone_duration_s,
            config.max_frequency_error,
        );
        let per_slot = (geometry.slot_samples / geometry.hop as f64).ceil() as usize + 2;
        let history_cap = 3 * geometry.slot_windows + 3 * per_slot + 16;
        Ok(Decoder {
            analyzer: Analyzer::new(geometry.clone()),
            sliding: vec![0.0; geometry.scale_count() * TONE_COUNT],
            scratch_powers: vec![0.0; geometry.scale_count() * TONE_COUNT],
            noise: NoiseFloor::new(
                geometry.window_len,
                geometry.slot_samples / geometry.hop as f64,
            ),
            short_window: ShortWindow::new(geometry.window_len),
            geometry,
            config,
            history: VecDeque::with_capacity(history_cap),
            history_cap,
            windows_seen: 0,
            sliding_first: 0,
            sliding_count: 0,
            floor: 0,
            run: None,
            tracking: None,
            blocked: None,
            recent: None,
            failed_slot: None,
            failed_transmission: None,
            replaying: None,
            pending_replay: None,
            refusals: std::cell::Cell::default(),
            output: VecDeque::new(),
            refused: VecDeque::new(),
            eof: false,
            trace: std::cell::RefCell::new(None),
        })
    }

    /// Starts recording the decoder's decisions (frames found, slots refused and by
    /// which check, end-test verdicts) for diagnosis; drain them with
    /// [`Decoder::take_trace`]. Off by default: it does not change any decision.
    pub fn enable_trace(&mut self) {
        *self.trace.borrow_mut() = Some(Vec::new());
    }

    /// The decisions recorded since the last call (empty when tracing is off).
    pub fn take_trace(&mut self) -> Vec<TraceEvent> {
        self.trace
            .borrow_mut()
            .as_mut()
            .map(std::mem::take)
            .unwrap_or_default()
    }

    /// Records `what` at sample `at` when tracing is on.
    fn note(&self, at: f64, what: impl FnOnce() -> String) {
        if let Some(trace) = self.trace.borrow_mut().as_mut() {
            trace.push(TraceEvent {
                at_s: at / self.rate(),
                what: what(),
            });
        }
    }

    /// The configuration.
    pub fn config(&self) -> &DecoderConfig {
        &self.config
    }

    /// Analysis window length in samples (the time resolution of detection).
    pub fn window_len(&self) -> usize {
        self.geometry.window_len
    }

    /// Samples pushed so far.
    pub fn samples_pushed(&self) -> u64 {
        self.analyzer.samples_pushed()
    }

    /// Pushes f32 samples (full scale ±1; any level works, the detector is relative).
    pub fn push_f32(&mut self, samples: &[f32]) {
        self.analyzer.push(samples.iter().copied());
        self.drain_windows();
        self.quick_look();
    }

    /// Pushes 16-bit samples.
    pub fn push_i16(&mut self, samples: &[i16]) {
        self.analyzer
            .push(samples.iter().map(|&s| crate::pcm::i16_to_f32(s)));
        self.drain_windows();
        self.quick_look();
    }

    /// The end test's short windows need samples, not a whole analysis window: try them
    /// as soon as they arrive rather than at the next window.
    fn quick_look(&mut self) {
        if matches!(
            self.tracking,
            Some(Tracking {
                stage: Stage::EndTest(end),
                ..
            }) if end.short.running()
        ) {
            self.advance_tracking();
            self.run_pending_replays();
        }
    }

    /// The next decoded message, in order of decision.
    pub fn poll_message(&mut self) -> Option<Detection> {
        self.output.pop_front()
    }

    /// The next report the team plan ([`DecoderConfig::team`]) cannot have sent, dropped
    /// from [`Decoder::poll_message`]: someone else's sound, or a long message cut to one
    /// frame under the checked plan. For diagnostics and evaluation; never a message. Only
    /// the newest few are kept when nobody polls.
    pub fn poll_refused(&mut self) -> Option<Detection> {
        self.refused.pop_front()
    }

    /// Ends the stream: a transmission whose slots are complete is decided on the evidence
    /// so far (a stream ending right after a message reports it). Pushing after this
    /// continues the stream.
    pub fn finish(&mut self) {
        self.eof = true;
        self.advance_tracking();
        self.run_pending_replays();
        if self.tracking.is_some() {
            // Slots not complete: not a message.
            self.tracking = None;
        }
        self.eof = false;
    }

    fn rate(&self) -> f64 {
        f64::from(self.geometry.rate_hz)
    }

    fn drain_windows(&mut self) {
        while let Some(start) = self.analyzer.next_window() {
            self.scratch_powers.copy_from_slice(self.analyzer.powers());
            self.on_window(start);
        }
    }
}

/// The median of `values` (the upper one of an even count), 0 when there are none.
fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(|a, b| a.total_cmp(b));
    values.get(values.len() / 2).copied().unwrap_or(0.0)
}
