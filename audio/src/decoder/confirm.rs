//! The decision on one aligned slot: the rules again on exactly its windows, the frame
//! test at a stricter level, and the checks that tell our message from someone else's
//! sound that happens to contain its tones (it must sound through the slot, carry no
//! stray tone as loud as its own, and sit on one frequency scale, see `off_grid`); and
//! the check that a first frame is not the orphaned second half of a long message.

use super::end_test::{
    CONTINUATION_SHARE, LLR_CLIP, MAX_SHARE_BEFORE_END, SPRT_BOUND, SPRT_HORIZON,
};
use super::tracking::Tracking;
use super::windows::SlotSums;
use super::{median, Decoder};
use crate::significance::{gamma_upper_quantile, hann_share_inside, ln_tone_likelihood};
use crate::tones::{basic_tones, Frame, BASIC_COUNT, SENDER_COUNT, TONE_COUNT};

/// Per-tone false-alarm probability of "present" when re-deciding an accepted frame on its
/// aligned slot: a frame is already there, so the threshold trades a missed tone against
/// an extra basic (21 · 3 · p² ≈ 0.6% of frames refused) rather than against noise alone.
pub(super) const P_TONE_CONFIRM: f64 = 1e-2;
/// Per-tone false-alarm probability for a *rival* basic on the aligned slot: a second
/// sender or data basic rejects the frame only when 2 of its 3 tones pass this stricter
/// threshold (22 rival basics · 3p² ≈ 7e-5 of frames refused by noise, instead of 0.6% at
/// [`P_TONE_CONFIRM`]). A real second transmitter sounds all three of its tones at full
/// level, far above either threshold unless it is itself lost in the noise.
pub(super) const P_TONE_RIVAL: f64 = 1e-3;
/// The frame-energy test again on the aligned slot, stricter (union-bounded like
/// [`P_FRAME`](super::search::P_FRAME)): a frame's six tones summed over exactly its slot.
/// Real frames at the lowest operating SNR pass it with room; a noise frame that scraped
/// through the search's coarser gate does not.
pub(super) const P_FRAME_CONFIRM: f64 = 1e-10;

/// Tones of its basic a 2-of-3 vote rests on.
const TWO_OF_THREE: usize = 2;

/// Least share of its even-spread energy each half of a slot must hold (see
/// [`Decoder::sounds_through_slot`]): far below what a real frame's halves hold even at
/// the lowest operating SNR.
const MIN_HALF_SHARE: f64 = 0.3;
/// Per-tone false-alarm probability a tone outside the frame must pass to count as a
/// stray (see [`Decoder::has_stray_tone`]): 66 tones · 1e-6 ≈ 7e-5 of slots refused by
/// noise alone. At the lenient [`P_TONE_CONFIRM`] noise tones would reach the stray share
/// now and then at low SNR (the frame's median level is itself noisy there); a foreign
/// signal loud enough to assemble our frame is far above either threshold.
const P_STRAY: f64 = 1e-6;
/// A present tone outside the frame this many times louder than a tone the frame's
/// 2-of-3 vote rests on (+10 dB) also makes the slot someone else's signal: a foreign
/// burst whose loud tones hit one tone of each of our basics, their second tones being
/// faint near-misses.
const STRAY_OVER_VOTE: f64 = 10.0;
/// A present tone outside the frame at this share of the frame's median tone level
/// makes the slot someone else's signal (see [`Decoder::has_stray_tone`]).
const STRAY_SHARE: f64 = 0.7;

/// Per-tone false-alarm probability of "present" in one half of a slot (see
/// [`Decoder::votes_hold_in_each_half`]): lenient, as the test is there to find a tone
/// that is absent from half of the slot, not to tell a tone from noise.
const P_HALF_TONE: f64 = 0.2;

/// Tones on each side whose slot sums give a tone's local background (see
/// [`Decoder::votes_stand_above_their_neighbours`]): ±150 Hz, about a formant's width.
const NEIGHBOURHOOD: usize = 3;

/// Standard deviations of its noise-only spread a neighbourhood's level must exceed the
/// floor by before it raises a tone's threshold.
const LOCAL_Z: f64 = 2.5;

/// Share of the slot at each end left out of the dropout count (see
/// [`Decoder::votes_sound_steadily`]): the onset is known to some tens of milliseconds, and
/// a window straddling a misplaced edge reads low for that reason alone.
const STEADY_EDGE: f64 = 0.1;
/// Least median window (noise mean 1) of a steady vote tone (see
/// [`Decoder::votes_sound_steadily`]): the median of a dozen noise windows (ln 2 on
/// average) exceeds it about once in twenty slots, that of a tone of excess 1 most of
/// the time, while a tone whose energy came in a few bursts sits at the floor there.
const MEDIAN_PRESENT: f64 = 1.3;
/// Least probability, under a steady tone, of as many dropouts as a vote tone shows.
const P_DROPOUTS: f64 = 1e-3;
/// Share of its median window below which a window of a loud vote tone counts as a
/// dip (−10 dB; see [`Decoder::votes_sound_steadily`]). A steady tone of excess 20 falls
/// that low in a window about once in 10⁵ (below excess 10 the cut is the noise mean); a
/// note with tremolo, or a warbling whistle, does so every other window while its median
/// stays high (everything dry, seed 13050: a false message at 1153.8 s whose data tone
/// read 374, 39, 235, 232, 75, 379, 25, 497, 28 … in successive windows).
const DEEP_SHARE: f64 = 0.1;
/// Least median window (noise mean 1, 13 dB) of a tone one of whose windows may collapse
/// between two that hold (see [`isolated_collapse`]).
const COLLAPSE_LOUD: f64 = 20.0;
/// Least share of the tone's median window every window but a collapse keeps (−5 dB; see
/// [`isolated_collapse`]).
const COLLAPSE_NEIGHBOUR_SHARE: f64 = 0.3;
/// Least mean excess per window (noise mean 1, 6 dB) of a tone whose median window is
/// held to its mean (see [`Decoder::votes_sound_steadily`]): a steady tone of excess 4
/// has a median window of about 4.5, with a spread of about 1 over a dozen windows.
const BURST_MIN: f64 = 4.0;
/// Least share of its mean excess a steady tone's median window keeps (−6 dB): about
/// 3 spreads below the median of a steady tone at [`BURST_MIN`], and more above it.
const BURST_SHARE: f64 = 0.25;

/// Least typical tone level (per-window excess over the noise, 15 dB) of a frame the hall
/// allowances apply to (see [`stands_clear`]). Nearly all the messages they recover in
/// babble halls at 0 dB in-band sit above it (tuning rows, seeds 4–9: 37 recovered at
/// 6 dB, 35 at 15 dB); the frames babble assembles sit near 0 dB, but the few that
/// bring a rival along reach 11 dB now and then: at 6 dB one of 11 dB became a false
/// message in 10 h of dry babble, and one of 8 dB after a failed slot in a T60 2.0 s
/// hall.
pub(super) const HALL_CLEAR_LEVEL: f64 = 31.6;

/// Least typical tone level (10 dB) of a frame whose rivals are judged by the transmitter
/// test because each of its basics has a tone at the hall level (see [`votes_ring_clear`]).
const RINGING_TYPICAL_LEVEL: f64 = 10.0;

/// Least share of the first slot's level the sender's tones keep in the second half of a
/// second slot (−5 dB; see [`Decoder::second_frame_holds_its_level`]).
const SECOND_FRAME_SHARE: f64 = 0.3;
/// Noise allowance of that test, standard deviations of the summed excess.
const SECOND_FRAME_NOISE_Z: f64 = 3.0;

/// Shares of the frame's level a leftover tail before the onset may have (see
/// [`Decoder::sender_sounded_before`]): 0, −20, −15 and −10 dB, all well below the
/// [`CONTINUATION_SHARE`] a first frame that was missed would sound at.
const LEFTOVER_SHARES: [f64; 4] = [0.0, 0.01, 0.03, 0.1];

/// A slot that passed its decision.
pub(super) struct SlotDecision {
    /// The frame it sounds.
    pub(super) frame: Frame,
    /// Tones present in it.
    pub(super) present: [bool; TONE_COUNT],
    /// Per-window excess power of each tone.
    pub(super) level: [f64; TONE_COUNT],
    /// Noise level during the slot.
    pub(super) noise: f64,
}

impl Decoder {
    /// Decides the slot `[a, b)` of the tracked frame `t`: the rules on exactly its windows
    /// must give a frame from `t`'s sender whose six-tone energy passes
    /// [`P_FRAME_CONFIRM`], and the frame must pass the checks against foreign sounds.
    pub(super) fn confirm_slot(&self, t: &Tracking, a: f64, b: f64) -> Option<SlotDecision> {
        let SlotSums {
            sums,
            count,
            level,
            noise,
        } = self.integrate_slot(t.scale, a, b)?;
        let own = Some(t.sender.index() as usize);
        let (frame, present) =
            match Self::apply_rules(&sums, count, P_TONE_CONFIRM, P_TONE_RIVAL, own, |_, _| true) {
                (None, _) => {
                    // A rival basic is a second transmitter only if its tones sound like
                    // one: through both halves of the slot, above their neighbourhood,
                    // steadily. In a babble hall some basic gets two tones from talkers'
                    // harmonics now and then, at the level of a real frame's tone that
                    // sits in a notch of the room, and as a rival it refused the message.
                    // A real second sender sounds its tones through the slot (one that
                    // overlaps only part of it fails the frame's own checks when its data
                    // wins). Only for a frame that stands clear of the floor, like every
                    // message in a hall: babble assembles its frames near 0 dB, and there
                    // a babble rival is what refuses them.
                    let transmitter = |f: Frame, present: &[bool; TONE_COUNT]| {
                        self.sounds_like_tones(f, present, &sums, count, t.scale, a, b)
                    };
                    let (frame, present) = Self::apply_rules(
                        &sums,
                        count,
                        P_TONE_CONFIRM,
                        P_TONE_RIVAL,
                        own,
                        transmitter,
                    );
                    (
                        frame.filter(|&f| {
                            stands_clear(f, &present, &level)
                                || votes_ring_clear(f, &present, &level)
                        }),
                        present,
                    )
                }
                decided => decided,
            };
        // A long message's second slot: its sender is the first slot's (tracking.rs).
        let (frame, present) = match frame {
            None if t.stage == super::tracking::Stage::Slot2 => self
                .second_slot_rules(t, a, b)
                .map_or((None, present), |(f, p)| (Some(f), p)),
            decided => (decided, present),
        };
        // A first frame whose own tones the room spread too far apart (see `own_tones.rs`).
        let (frame, present) =
            match frame {
                None => Self::own_tones_rules(t, &sums, count, P_TONE_CONFIRM, P_TONE_RIVAL)
                    .map_or((None, present), |(f, p)| {
                        self.note(a, || "rules: decided on the frame's own tones".to_string());
                        (Some(f), p)
                    }),
                decided => (decided, present),
            };
        let Some(frame) = frame else {
            self.note(a, || {
                let votes: Vec<usize> = (0..crate::tones::BASIC_COUNT)
                    .map(|b| basic_tones(b).iter().filter(|&&k| present[k]).count())
                    .collect();
                // The tracked frame's tones: per-window excess, and present or not.
                let n = count.max(1) as f64;
                let tracked = Frame {
                    sender: t.sender,
                    data: t.data[if a > t.onset + 0.5 * self.geometry.slot_samples {
                        1
                    } else {
                        0
                    }],
                };
                let tones: Vec<String> = tracked
                    .tones()
                    .iter()
                    .map(|&k| {
                        format!(
                            "{}k{k} {:.1} ({:.1}|{:.1})",
                            if present[k] { "*" } else { "" },
                            (sums[k] - n) / n,
                            if k > 0 { (sums[k - 1] - n) / n } else { 0.0 },
                            if k + 1 < TONE_COUNT { (sums[k + 1] - n) / n } else { 0.0 },
                        )
                    })
                    .collect();
                let crowd = present.iter().filter(|&&p| p).count();
                let (loud_k, loud) = (0..TONE_COUNT)
                    .map(|k| (k, (sums[k] - n) / n))
                    .fold((0, f64::NEG_INFINITY), |m, x| if x.1 > m.1 { x } else { m });
                format!(
                    "slot refused by the rules: votes per basic {votes:?} tones {} present {crowd} loudest k{loud_k} {loud:.1}",
                    tones.join(" ")
                )
            });
            return None;
        };
        if frame.sender != t.sender {
            self.note(a, || {
                format!(
                    "slot refused: sender {:?} not the tracked one",
                    frame.sender
                )
            });
            return None;
        }
        let energy: f64 = frame.tones().iter().map(|&k| sums[k]).sum();
        if energy < self.frame_threshold(count, P_FRAME_CONFIRM) {
            self.note(a, || "slot refused: frame energy".to_string());
            return None;
        }
        let clear = stands_clear(frame, &present, &level);
        let sender_tones = self.sender_vote_tones(t, frame);
        let refused = if !self.sounds_through_slot(frame, &present, t.scale, a, b) {
            Some("does not sound through")
        } else if !self.votes_hold_in_each_half(frame, &present, t.scale, a, b, sender_tones) {
            Some("a vote misses a half")
        } else if !Self::votes_stand_above_their_neighbours(frame, &present, &sums, count) {
            Some("a vote not above its neighbours")
        } else if !self.votes_sound_steadily(
            frame,
            &present,
            &sums,
            count,
            t.scale,
            a,
            b,
            sender_tones,
        ) {
            Some("a vote not steady")
        } else if let Err(why) = self.basics_sound_together(frame, &present, t.scale, a, b) {
            // Its two basics did not begin and end together (see `coherence.rs`).
            self.note(a, || why);
            Some("basics not together")
        } else if let Some(basic) = (t.stage == super::tracking::Stage::Slot1)
            .then(|| self.second_transmitter(frame, &present, &sums, count, t.scale, a, b))
            .flatten()
        {
            // A second slot's sender is the first slot's, its data began with the slot
            // (the quarters above): another robot sounding under it does not make its
            // data ambiguous, save in the rare case that robot began with the slot.
            self.note(a, || {
                format!("basic {basic} sounds like a second transmitter")
            });
            Some("a second transmitter")
        } else if let Some(basic) = (t.stage == super::tracking::Stage::Slot2)
            .then(|| self.sender_began_with_slot(t, frame, &sums, count, a, b))
            .flatten()
        {
            // Another robot began with this second slot: the data may be its first
            // frame's, ours lost in the room's notches (see `coherence.rs`).
            self.note(a, || {
                format!("second slot: sender basic {basic} began with it")
            });
            Some("a second sender")
        } else if let Some(why) = (t.stage == super::tracking::Stage::Slot1)
            .then(|| {
                super::bursts::assembled_by_background(frame, &present, &level)
                    .or_else(|| self.votes_sound_apart(frame, &present, &level, t.scale, a, b))
            })
            .flatten()
        {
            // A weak frame among many tones, or one whose votes sound apart (see
            // `bursts.rs`).
            self.note(a, || why);
            Some("assembled by the background")
        } else if let Some(share) = (t.stage == super::tracking::Stage::Slot2
            && frame.data != t.data[0])
            .then(|| self.second_data_began_before(t, frame.data, &present, a, b))
            .flatten()
        {
            // Another robot's frame that began in the first slot (see `coherence.rs`).
            self.note(a, || {
                format!(
                    "second slot: data {} held {share:.2} of its level before the slot",
                    frame.data
                )
            });
            Some("data began before the slot")
        } else if self.has_stray_tone(
            frame,
            &present,
            &level,
            &sums,
            count,
            t.scale,
            a,
            b,
            clear,
            &self.second_slot_own_tones(t, frame, &present, a, b, &level),
        ) {
            self.note(a, || {
                let own = frame.tones();
                let med = median(
                    own.iter()
                        .filter(|&&k| present[k])
                        .map(|&k| level[k])
                        .collect(),
                );
                let steady = self.steadiness(frame, &sums, count, t.scale, a, b);
                let n = count.max(1) as f64;
                let strays: Vec<String> = (0..TONE_COUNT)
                    .filter(|&k| present[k] && !own.contains(&k) && level[k] >= 0.3 * med)
                    .map(|k| {
                        let around = neighbourhood(&own, k, &sums);
                        let basic: Vec<String> = basic_tones(k % BASIC_COUNT)
                            .iter()
                            .map(|&j| {
                                if present[j] {
                                    format!("{:.1}", level[j])
                                } else {
                                    "-".into()
                                }
                            })
                            .collect();
                        format!(
                            "k{k} {:.2}x med, local {:.1}, steady {:?}, basic [{}]",
                            level[k] / med,
                            median(around) / n,
                            steady.as_ref().map(|s| s(k)),
                            basic.join(" ")
                        )
                    })
                    .collect();
                format!("strays (clear {clear}): {}", strays.join("; "))
            });
            Some("stray tone")
        } else if self.has_off_grid_tone(
            frame,
            &present,
            t.scale,
            a,
            b,
            clear,
            t.stage == super::tracking::Stage::Slot2,
        ) {
            Some("off grid")
        } else {
            None
        };
        if refused == Some("a vote not steady") {
            self.note(a, || {
                let steady = self.steadiness(frame, &sums, count, t.scale, a, b);
                let tones: Vec<String> = frame
                    .tones()
                    .iter()
                    .filter(|&&k| present[k])
                    .map(|&k| format!("k{k} {:?}", steady.as_ref().map(|s| s(k))))
                    .collect();
                format!("steadiness of the frame's tones: {}", tones.join(", "))
            });
        }
        let first = t.stage == super::tracking::Stage::Slot1;
        let refused = match refused {
            Some(why) if first => {
                self.remember_refusal(frame, a, t.onset, t.scale, why);
                Some(why)
            }
            None if first => self
                .recalled_refusal(frame, a, t.onset, t.scale)
                .map(|(why, ago)| {
                    self.note(a, || {
                        format!("the same frame was refused {ago:.2} s away: {why}")
                    });
                    "refused nearby"
                }),
            refused => refused,
        };
        self.note(a, || {
            let typical = typical_level(frame, &present, &level);
            let n = count.max(1) as f64;
            let own = frame.tones();
            let tones: Vec<String> = (0..TONE_COUNT)
                .filter(|&k| present[k] || own.contains(&k))
                .map(|k| {
                    let around = neighbourhood(&own, k, &sums);
                    format!(
                        "{}k{k}{} {:.1}/{:.1}",
                        if own.contains(&k) { "*" } else { "" },
                        if present[k] { "" } else { "(absent)" },
                        level[k],
                        median(around) / n
                    )
                })
                .collect();
            format!(
                "slot {frame:?} level {:.1} dB: {} [{}]",
                10.0 * typical.max(1e-12).log10(),
                refused.unwrap_or("passes"),
                tones.join(" ")
            )
        });
        if refused.is_none() {
            self.note(a, || {
                let rows: Vec<String> = self
                    .history
                    .iter()
                    .filter(|w| (w.start as f64) > a - 0.5 * (b - a))
                    .map(|w| {
                        let v: Vec<String> = frame
                            .tones()
                            .iter()
                            .map(|&k| format!("{:.0}", w.r[t.scale * TONE_COUNT + k]))
                            .collect();
                        format!("{:.2}:{}", w.start as f64 / self.rate(), v.join(","))
                    })
                    .collect();
                format!("timeline {}", rows.join(" "))
            });
        }
        refused.is_none().then_some(SlotDecision {
            frame,
            present,
            level,
            noise,
        })
    }

    /// Whether the votes of `frame` (its tones `present` in the slot `[a, b)` with sums
    /// `sums` over `count` windows at `scale`) are a transmitter's tones rather than
    /// babble's: they hold in each half, stand above their neighbourhood and sound
    /// steadily (the checks a frame's own votes must pass).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn sounds_like_tones(
        &self,
        frame: Frame,
        present: &[bool; TONE_COUNT],
        sums: &[f64; TONE_COUNT],
        count: usize,
        scale: usize,
        a: f64,
        b: f64,
    ) -> bool {
        self.votes_hold_in_each_half(frame, present, scale, a, b, TWO_OF_THREE)
            && Self::votes_stand_above_their_neighbours(frame, present, sums, count)
            && self.votes_sound_steadily(frame, present, sums, count, scale, a, b, TWO_OF_THREE)
    }

    /// How many of its present tones the sender's vote of `frame`, decided on a slot of
    /// `t`, must hold on in each half of the slot and steadily through it (see
    /// [`Decoder::votes_hold_in_each_half`], [`Decoder::votes_sound_steadily`]): one on a
    /// long message's second slot, and on a first slot whose data only a long message of
    /// the team's plan carries (the checked plan's data 10 … 20); two otherwise. The data's
    /// vote always needs two, and the sender's vote still needs two tones present over the
    /// slot (the rules).
    ///
    /// A sender in a room's notch sounds one loud tone and a second 15–25 dB under it, and
    /// that weak tone, a few times the noise per window, misses a half or reads dropouts
    /// among talkers now and then (long lab-1.2 0 dB, tuning rows 82021–87021: 29 of the
    /// 101 lost long messages were refused so, the sender's weak tone failing 19 times
    /// against the data's 4, e.g. LeftAttacker's k49 at 3–12 per window beside k25 at
    /// 200–400 and k1 in a notch). The two checks are there to refuse frames that babble
    /// assembled from passing harmonics. On a second slot the sender is no longer in
    /// question: the first slot decided it, and its tones must keep their first-slot level
    /// through the slot (`second_frame_holds_its_level`). On a first slot of a frame only
    /// a long message has, the frame is reported only if a second slot passes too: frames
    /// of babble would have to do so twice, the sender holding its level through both.
    fn sender_vote_tones(&self, t: &Tracking, frame: Frame) -> usize {
        let second = t.stage == super::tracking::Stage::Slot2;
        let long_only = t.stage == super::tracking::Stage::Slot1
            && self.config.team.frame_is_long_only(frame.data);
        if second || long_only {
            1
        } else {
            TWO_OF_THREE
        }
    }

    /// Whether a second slot `[a, b)` is a second frame rather than the first frame's
    /// reverberant tail: the sender's tones (the same tones, through the same room, so at
    /// the same level as in the first slot) must keep [`SECOND_FRAME_SHARE`] of the first
    /// slot's level through the second half of the slot, within the noise.
    ///
    /// In a hall of T60 2.5 s a tone's tail still holds a fifth of its energy over the
    /// next second, front-loaded, and with the same data it passes for a second frame of
    /// the same data: a short message would become a wrong long one. Half a slot after
    /// the end such a tail has fallen by 10–25 dB; a second frame has not fallen at all.
    pub(super) fn second_frame_holds_its_level(&self, t: &Tracking, a: f64, b: f64) -> bool {
        let window_len = self.geometry.window_len as f64;
        if b - a < 4.0 * window_len {
            // Half a slot of a window or so: too little to tell a tail by, and a window
            // reaching past the slot would read a long message's end as a decay.
            return true;
        }
        self.sender_keeps_level(t, 0.5 * (a + b), b)
    }

    /// Whether the sender's tones of `t` (as present and measured in its last decided
    /// slot) keep [`SECOND_FRAME_SHARE`] of that level, within the noise, over the windows
    /// wholly inside `[from, to)`: true when none are.
    pub(super) fn sender_keeps_level(&self, t: &Tracking, from: f64, to: f64) -> bool {
        self.basic_keeps_level(t, t.sender.index() as usize, from, to)
    }

    /// Whether basic `basic`'s tones of `t` (as present and measured in its last decided
    /// slot) keep [`SECOND_FRAME_SHARE`] of that level, within the noise, over the windows
    /// wholly inside `[from, to)`: true when none are.
    pub(super) fn basic_keeps_level(&self, t: &Tracking, basic: usize, from: f64, to: f64) -> bool {
        let window_len = self.geometry.window_len as f64;
        let tones: Vec<usize> = basic_tones(basic)
            .into_iter()
            .filter(|&k| t.present[k] && t.level[k] > 0.0)
            .collect();
        // On the first slot's noise level: where the background is the tones' own leakage
        // (a clean recording), each frame's data tones set a different per-window level.
        let (mut observed, mut noise, mut windows) = (0.0, 0.0, 0usize);
        for w in &self.history {
            let start = w.start as f64;
            if start < from || start + window_len > to {
                continue;
            }
            let scale = w.level / t.noise;
            observed += Self::excess(w, t.scale, &tones) * scale;
            noise += scale;
            windows += 1;
        }
        let expected: f64 = tones.iter().map(|&k| t.level[k]).sum::<f64>() * windows as f64;
        let spread = (tones.len() as f64 / windows.max(1) as f64).sqrt() * noise;
        windows == 0 || observed >= SECOND_FRAME_SHARE * expected - SECOND_FRAME_NOISE_Z * spread
    }

    /// Whether the first slot `t` (its level and tones measured, starting at `a`) is the
    /// second frame of a long message whose first frame was missed: the same sender's slot
    /// failed its decision just before it, or the sender was already sounding.
    ///
    /// By the protocol a robot leaves more than half a tone of silence between messages,
    /// so the same sender within that of a failed slot is the second frame of that
    /// transmission; the look-back test alone can miss it when the sender's tones before
    /// the onset are weak. Reporting such a frame as a short would be a wrong message;
    /// missing it is the lesser harm.
    pub(super) fn continues_earlier_frame(&self, t: &Tracking, a: f64) -> bool {
        let slot_len = self.geometry.slot_samples;
        // A second frame starts where the first ended; a frame that started well inside
        // the failed slot (found again after it, see `Decoder::decide_slot`) is not one.
        let window_len = self.geometry.window_len as f64;
        let follows_failed = matches!(
            self.failed_slot,
            Some((sender, end)) if sender == t.sender
                && a - end > -window_len
                && a - end < SPRT_HORIZON * slot_len + window_len
        );
        // ... and only if the sender really sounded through that slot: the two frames of
        // a long message sound the same sender tones through the same room, so at the
        // same level. In a babble hall a first slot also fails when talkers assembled a
        // frame with the sender's basic for a moment, or when the sender's next message
        // was found early, its onset on the babble before it: the sender's tones then
        // fill little of the failed slot, and the message after it is a message.
        let clear = stands_clear(
            Frame {
                sender: t.sender,
                data: t.data[0],
            },
            &t.present,
            &t.level,
        );
        let follows_failed = follows_failed
            && !(clear
                && self
                    .failed_slot
                    .is_some_and(|(_, end)| !self.sender_keeps_level(t, end - slot_len, end)));
        follows_failed || self.sender_sounded_before(t)
    }

    /// Whether the sender's tones were sounding just before the onset (the mirror of the
    /// end test): log-likelihood of "sounding at the measured level" against "silent" on
    /// the windows (almost) wholly before the onset, within [`SPRT_HORIZON`] slots.
    fn sender_sounded_before(&self, t: &Tracking) -> bool {
        let window_len = self.geometry.window_len as f64;
        let slot_len = self.geometry.slot_samples;
        let onset = t.onset;
        // "Silent" allows a leftover at a few small shares of the level: in a hall the
        // sender's previous message (at least half a tone earlier, by the protocol) may
        // still be heard as a decaying tail, which is not the sender sounding on.
        let mut llr = [0.0; LEFTOVER_SHARES.len()];
        for w in &self.history {
            let start = w.start as f64;
            if start + window_len < onset - SPRT_HORIZON * slot_len {
                continue;
            }
            let after = hann_share_inside(start, window_len, onset, onset + slot_len);
            if after > MAX_SHARE_BEFORE_END {
                break;
            }
            let before = hann_share_inside(start, window_len, onset - slot_len, onset);
            for k in basic_tones(t.sender.index() as usize) {
                if !t.present[k] || t.level[k] <= 0.0 {
                    continue;
                }
                let r = f64::from(w.r[t.scale * TONE_COUNT + k]) * w.level / t.noise;
                let sounding = t.level[k] * (after * after + CONTINUATION_SHARE * before * before);
                for (acc, share) in llr.iter_mut().zip(LEFTOVER_SHARES) {
                    let silent = t.level[k] * (after * after + share * before * before);
                    *acc += (ln_tone_likelihood(r, sounding) - ln_tone_likelihood(r, silent))
                        .clamp(-LLR_CLIP, LLR_CLIP);
                }
            }
        }
        llr.into_iter().fold(f64::INFINITY, f64::min) > SPRT_BOUND / 3.0
    }

    /// Whether the frame's tones sound through the whole slot: the excess power of its
    /// present tones in each half of the slot must be at least [`MIN_HALF_SHARE`] of what
    /// an even spread would give. A burst of foreign tones shorter than a slot, or a sweep
    /// crossing a tone, piles its energy into part of the slot; a message does not.
    fn sounds_through_slot(
        &self,
        frame: Frame,
        present: &[bool; TONE_COUNT],
        scale: usize,
        a: f64,
        b: f64,
    ) -> bool {
        let window_len = self.geometry.window_len as f64;
        if self.geometry.slot_windows >= 2 && b - a < 2.0 * window_len {
            // A half slot shorter than a window: the windows of the two halves overlap,
            // so the split cannot tell a burst from a tone and only costs real frames.
            // The other rules still apply. With a single whole window per slot (tones
            // under 1.5 windows) the check stays: there it still refuses frames assembled
            // from the edges of two messages.
            return true;
        }
        let mid = 0.5 * (a + b);
        let tones: Vec<usize> = frame.tones().into_iter().filter(|&k| present[k]).collect();
        let mut halves = [(0.0f64, 0usize); 2];
        for w in &self.history {
            let start = w.start as f64;
            if hann_share_inside(start, window_len, a, b) < 0.9 {
                continue;
            }
            let half = usize::from(start + 0.5 * window_len >= mid);
            halves[half].0 += Self::excess(w, scale, &tones);
            halves[half].1 += 1;
        }
        let total: f64 = halves.iter().map(|h| h.0).sum();
        let count: usize = halves.iter().map(|h| h.1).sum();
        if halves.iter().any(|h| h.1 == 0) || total <= 0.0 {
            // Too few windows to split (tones about as short as a window): no verdict.
            return true;
        }
        halves
            .iter()
            .all(|h| h.0 >= MIN_HALF_SHARE * total * h.1 as f64 / count as f64)
    }

    /// Whether each half of the slot `[a, b)` gives the frame's two basics their 2-of-3
    /// votes on its own: two of each basic's tones `present` in the slot are present in
    /// the half too (at the lenient [`P_HALF_TONE`]).
    ///
    /// A message's six tones are steady: each sounds through its whole slot. Babble (dry
    /// or in a hall) assembles a frame from harmonics that each sound for a syllable, a
    /// fraction of a slot: summed over the slot they pass for tones, yet in one half of it
    /// a tone a vote rests on is not there at all. [`Decoder::sounds_through_slot`] looks
    /// at the frame's energy as a whole, which bursts of different tones at different
    /// times satisfy; this looks at each vote. A real frame's tone misses a half only when
    /// noise pulls its half-sum below the Gamma quantile at [`P_HALF_TONE`], and a vote
    /// fails only when two of its three tones do (at the lowest operating SNR about 1e-4
    /// per basic and half).
    fn votes_hold_in_each_half(
        &self,
        frame: Frame,
        present: &[bool; TONE_COUNT],
        scale: usize,
        a: f64,
        b: f64,
        sender_tones: usize,
    ) -> bool {
        let window_len = self.geometry.window_len as f64;
        if b - a < 4.0 * window_len {
            // Halves of a window or two: their windows overlap the other half, and the
            // few windows hold too little evidence for a per-half vote.
            return true;
        }
        let mid = 0.5 * (a + b);
        [(a, mid), (mid, b)].into_iter().all(|(from, to)| {
            let Some(half) = self.integrate_slot(scale, from, to) else {
                return true;
            };
            let own = frame.tones();
            let mut background: Vec<f64> = (0..TONE_COUNT)
                .filter(|k| !own.contains(k))
                .map(|k| half.sums[k])
                .collect();
            background.sort_unstable_by(|x, y| x.total_cmp(y));
            let rank = ((1.0 - P_HALF_TONE) * background.len() as f64) as usize;
            let above_most = background
                .get(rank.min(background.len().saturating_sub(1)))
                .copied()
                .unwrap_or(0.0);
            let threshold = gamma_upper_quantile(half.count as f64, P_HALF_TONE).max(above_most);
            votes_hold_on(frame, present, sender_tones, |k| half.sums[k] >= threshold)
        })
    }

    /// Whether each of the frame's basics has two `present` tones that also stand out of
    /// their own neighbourhood: a tone's slot sum must pass the Gamma quantile at
    /// [`P_TONE_CONFIRM`] scaled by the level of the tones around it (the median slot sum
    /// of the non-frame tones within [`NEIGHBOURHOOD`] tones, over its noise-only
    /// expectation, when above 1).
    ///
    /// The noise floor is one level for the band times a slowly learnt shape. Speech puts
    /// its energy where its formants are, for a syllable at a time, and a hall smears it
    /// over a second: over a slot, whole regions of the band sit several times above the
    /// floor, and any tone there passes the Gamma test. A message's tone stands above its
    /// neighbours, which sound only the background; a region of babble does not. Under
    /// white noise the neighbours read the floor and the test is the Gamma test again.
    fn votes_stand_above_their_neighbours(
        frame: Frame,
        present: &[bool; TONE_COUNT],
        sums: &[f64; TONE_COUNT],
        count: usize,
    ) -> bool {
        let own = frame.tones();
        let n = count.max(1) as f64;
        let threshold = gamma_upper_quantile(n, P_TONE_CONFIRM);
        let stands_out = |k: usize| {
            let around = neighbourhood(&own, k, sums);
            // The median of m Gamma(n) sums over n spreads by about 1.25 / √(m n) under
            // noise alone: only a level beyond that spread is the neighbourhood's own.
            let spread = 1.25 / ((around.len().max(1) as f64) * n).sqrt();
            let local = (median(around) / n - LOCAL_Z * spread).max(1.0);
            sums[k] >= threshold * local
        };
        each_vote_holds(frame, present, stands_out)
    }

    /// Whether each of the frame's basics has two `present` tones that sound steadily
    /// through the slot: a steady tone at level λ (per window, noise mean 1) reads below
    /// the noise mean in a window with probability `p(λ) = P(r < 1)` (the non-central χ²
    /// of [`ln_tone_likelihood`]), small once λ is a few times the noise; more such
    /// dropouts among the slot's central windows than a binomial at `p(λ)` allows at
    /// [`P_DROPOUTS`] mean the tone's energy came in bursts, not from a tone.
    ///
    /// Babble that happens to dwell on a few of our tones (a talker's harmonic held for a
    /// syllable, smeared by a hall) sums over a slot to what looks like a frame of weak
    /// tones, standing above their neighbours; in between its bursts each of them falls
    /// to the floor, which a tone never does. Its level is taken from the median window
    /// (bursts of babble on a real tone do not lift it) and relative to its neighbourhood
    /// (see [`Decoder::votes_stand_above_their_neighbours`]), so a real tone in a loud
    /// region of babble is judged against that region.
    #[allow(clippy::too_many_arguments)]
    fn votes_sound_steadily(
        &self,
        frame: Frame,
        present: &[bool; TONE_COUNT],
        sums: &[f64; TONE_COUNT],
        count: usize,
        scale: usize,
        a: f64,
        b: f64,
        sender_tones: usize,
    ) -> bool {
        let Some(steady) = self.steadiness(frame, sums, count, scale, a, b) else {
            return true;
        };
        votes_hold_on(frame, present, sender_tones, steady)
    }

    /// The test of [`Decoder::votes_sound_steadily`] for one tone `k` of the slot `[a, b)`
    /// (its neighbourhood leaving out `frame`'s tones), or `None` when the slot is too
    /// short to tell.
    fn steadiness<'s>(
        &'s self,
        frame: Frame,
        sums: &'s [f64; TONE_COUNT],
        count: usize,
        scale: usize,
        a: f64,
        b: f64,
    ) -> Option<impl Fn(usize) -> bool + 's> {
        let window_len = self.geometry.window_len as f64;
        if b - a < 4.0 * window_len {
            return None;
        }
        let own = frame.tones();
        let n = count.max(1) as f64;
        let (from, to) = (a + STEADY_EDGE * (b - a), b - STEADY_EDGE * (b - a));
        let windows: Vec<&super::windows::WindowRecord> = self
            .history
            .iter()
            .filter(|w| hann_share_inside(w.start as f64, window_len, from, to) >= 0.9)
            .collect();
        if windows.len() < 4 {
            return None;
        }
        Some(move |k: usize| {
            let around = neighbourhood(&own, k, sums);
            let spread = 1.25 / ((around.len().max(1) as f64) * n).sqrt();
            let raised = median(around.clone()) / n - LOCAL_Z * spread;
            let local = (median(around) / n).max(1.0);
            let mut r: Vec<f64> = windows
                .iter()
                .map(|w| f64::from(w.r[scale * TONE_COUNT + k]) / local)
                .collect();
            let middle = median(r.clone());
            if let Some(i) = isolated_collapse(&r, middle) {
                r.remove(i);
            }
            let lambda = (middle - 1.0).max(0.0);
            let dropouts = r.iter().filter(|&&x| x < 1.0).count();
            let tail = binomial_upper_tail(r.len(), dropouts, probability_below(1.0, lambda));
            // A loud tone must not dip either: a window below DEEP_SHARE of its median,
            // with windows at the median both before and after it, is a dip a steady tone
            // far above the noise does not make, while a warbling or pulsed sound (a note
            // with tremolo, a whistle's chirps) dips by 10–20 dB between its beats
            // without reaching the floor. Only dips inside the tone count: a window past
            // a tone that ends early (an onset found late) falls as far, once.
            let cut = (DEEP_SHARE * middle).max(1.0);
            let dips = (0..r.len())
                .filter(|&i| {
                    r[i] < cut
                        && r[..i].iter().any(|&x| x >= middle)
                        && r[i + 1..].iter().any(|&x| x >= middle)
                })
                .count();
            let dip_tail = binomial_upper_tail(r.len(), dips, probability_below(cut, lambda));
            // Where the neighbourhood stands above the floor (speech around), the median
            // window must also show the tone: a tone made of a few bursts has a median at
            // the floor, and at that level of λ its dropouts are no surprise.
            let median_shows = raised <= 1.0 || middle >= MEDIAN_PRESENT;
            // A tone whose slot level is clear of the noise must show most of that level
            // in its median window too: a steady tone's median window sits at its mean
            // (within a few of its spread), while a "tone" whose level came from two or
            // three bursts (a note of music, a syllable, over a hall) has its mean far
            // above its median. Below BURST_MIN the windows' own spread is too large to
            // tell, and the tests above judge alone.
            let mean = r.iter().sum::<f64>() / r.len() as f64 - 1.0;
            let not_bursts = mean < BURST_MIN || middle - 1.0 >= BURST_SHARE * mean;
            tail >= P_DROPOUTS && dip_tail >= P_DROPOUTS && median_shows && not_bursts
        })
    }

    /// Whether a tone outside the frame sounds about as loud as the frame's own tones
    /// ([`STRAY_SHARE`] of their median excess), or far louder than a tone a 2-of-3 vote
    /// rests on ([`STRAY_OVER_VOTE`]): the mark of someone else's multi-tone signal that
    /// happens to contain our two basics, not of noise (the tone must pass [`P_STRAY`])
    /// nor of leakage (ruled out by the neighbour and dynamic-range tests already). Tones
    /// marked in `own_tail` (the first frame's data dying away in a second slot, see
    /// `Decoder::first_data_tail` in tracking.rs) are the message's own and never strays.
    #[allow(clippy::too_many_arguments)]
    fn has_stray_tone(
        &self,
        frame: Frame,
        present: &[bool; TONE_COUNT],
        level: &[f64; TONE_COUNT],
        sums: &[f64; TONE_COUNT],
        count: usize,
        scale: usize,
        a: f64,
        b: f64,
        clear: bool,
        own_tail: &[bool; TONE_COUNT],
    ) -> bool {
        let own = frame.tones();
        let strict = gamma_upper_quantile(count.max(1) as f64, P_STRAY);
        let median = median(
            own.iter()
                .filter(|&&k| present[k])
                .map(|&k| level[k])
                .collect(),
        );
        // The weakest tone a basic's 2-of-3 vote rests on (the second loudest of each).
        let vote = |b: usize| {
            let mut l = basic_tones(b).map(|k| if present[k] { level[k] } else { 0.0 });
            l.sort_by(|a, b| b.total_cmp(a));
            l[1]
        };
        let [sender, data] = vote_basics(frame);
        let weakest_vote = vote(sender).min(vote(data));
        // A stray is a foreign transmitter's tone only if it sounds like one, steadily
        // through the slot: a foreign signal steady enough to hold our six tones for a
        // slot holds its own too, while in a babble hall a talker's harmonic smeared
        // over the slot reaches the level of a frame tone in a notch now and then.
        // The same holds below the hall level: a stray judged by the test a frame's own
        // votes must pass (a burst of babble is a tone neither for us nor for a rival).
        let _ = clear;
        let steady = self.steadiness(frame, sums, count, scale, a, b);
        (0..TONE_COUNT).any(|k| {
            present[k]
                && !own.contains(&k)
                && !own_tail[k]
                && sums[k] >= strict
                && (level[k] >= STRAY_SHARE * median || level[k] >= STRAY_OVER_VOTE * weakest_vote)
                && steady.as_ref().is_none_or(|steady| steady(k))
        })
    }
}

/// The sums of the tones within [`NEIGHBOURHOOD`] of tone `k`, leaving out `k` and the
/// frame's own tones `own`: the local background a tone is judged against.
pub(super) fn neighbourhood(own: &[usize; 6], k: usize, sums: &[f64]) -> Vec<f64> {
    (k.saturating_sub(NEIGHBOURHOOD)..=k + NEIGHBOURHOOD)
        .filter(|&j| j < TONE_COUNT && j != k && !own.contains(&j))
        .map(|j| sums[j])
        .collect()
}

/// Whether `frame` stands clear of the floor: its typical tone (the median of its
/// `present` tones' per-window excess `level`) at least [`HALL_CLEAR_LEVEL`]. The
/// allowances made for what a hall does to a real frame (a rival or a stray of babble
/// beside it, a failed slot of babble before it, its tones off the search's scale) are
/// made only for such frames.
pub(super) fn stands_clear(
    frame: Frame,
    present: &[bool; TONE_COUNT],
    level: &[f64; TONE_COUNT],
) -> bool {
    typical_level(frame, present, level) >= HALL_CLEAR_LEVEL
}

/// Whether each of the frame's two basics has a `present` tone at [`HALL_CLEAR_LEVEL`]
/// or above, and its typical tone is at least [`RINGING_TYPICAL_LEVEL`]: a frame whose
/// median is pulled under the hall level by tones in the room's notches, but whose votes
/// each rest on a tone far above the talkers. Such a frame's rival basics are judged by
/// the transmitter test as those of a clear frame are (hall T60 1.2 s at 0 dB, tuning
/// row 11018: 23 of 55 short messages lost to a rival of babble, their typical tone at
/// 10–14 dB, their loudest sender and data tones mostly 16–28 dB). Babble assembles its
/// frames near 0 dB, with no tone of either basic at 15 dB.
fn votes_ring_clear(frame: Frame, present: &[bool; TONE_COUNT], level: &[f64; TONE_COUNT]) -> bool {
    let loudest = |b: usize| {
        basic_tones(b)
            .into_iter()
            .filter(|&k| present[k])
            .map(|k| level[k])
            .fold(0.0f64, f64::max)
    };
    typical_level(frame, present, level) >= RINGING_TYPICAL_LEVEL
        && vote_basics(frame)
            .into_iter()
            .all(|b| loudest(b) >= HALL_CLEAR_LEVEL)
}

/// The median level of the frame's own tones that are present.
pub(super) fn typical_level(
    frame: Frame,
    present: &[bool; TONE_COUNT],
    level: &[f64; TONE_COUNT],
) -> f64 {
    median(
        frame
            .tones()
            .into_iter()
            .filter(|&k| present[k])
            .map(|k| level[k])
            .collect(),
    )
}

/// The two basics a frame's 2-of-3 votes are taken on: its sender's and its data's.
pub(super) fn vote_basics(frame: Frame) -> [usize; 2] {
    [
        frame.sender.index() as usize,
        SENDER_COUNT + usize::from(frame.data),
    ]
}

/// Whether both of the frame's votes rest on two `present` tones that pass `holds`.
fn each_vote_holds(
    frame: Frame,
    present: &[bool; TONE_COUNT],
    holds: impl Fn(usize) -> bool,
) -> bool {
    votes_hold_on(frame, present, TWO_OF_THREE, holds)
}

/// Whether the frame's sender vote rests on `sender_tones` `present` tones that pass
/// `holds`, and its data vote on two.
fn votes_hold_on(
    frame: Frame,
    present: &[bool; TONE_COUNT],
    sender_tones: usize,
    holds: impl Fn(usize) -> bool,
) -> bool {
    let [sender, data] = vote_basics(frame);
    let held = |basic: usize| {
        basic_tones(basic)
            .iter()
            .filter(|&&k| present[k] && holds(k))
            .count()
    };
    held(sender) >= sender_tones && held(data) >= TWO_OF_THREE
}

/// The one window of a loud tone (median window `middle` ≥ [`COLLAPSE_LOUD`]) that fell
/// below [`DEEP_SHARE`] of its median (or the noise mean), inside the slot, while every
/// other window kept [`COLLAPSE_NEIGHBOUR_SHARE`] of it: the steadiness tests leave it
/// out.
///
/// In a room with talkers a steady tone reads |tone + babble|² in its bin, and a
/// talker's harmonic gliding through the tone's frequency at about its level cancels it
/// for the window in which their phases oppose. Counted, that one window refused frames
/// whose tones sounded through the rest of the slot: short lab T60 1.2 s 0 dB, tuning
/// draws S = 111–122, 6 of the 11 first slots refused for "a vote not steady" had one
/// vote tone collapse in a single window (113015 at 742.62 s: k28 at 599, 0, 454 per
/// window, its median 390, the noise level within 1 dB). A tremolo or a warbling
/// whistle swings by 5–10 dB from window to window besides its deepest dips, and a tone
/// babble assembled falls to the floor between its bursts: neither has every other
/// window at its level, and nothing of theirs is excused.
fn isolated_collapse(r: &[f64], middle: f64) -> Option<usize> {
    if middle < COLLAPSE_LOUD || r.len() < 3 {
        return None;
    }
    let cut = (DEEP_SHARE * middle).max(1.0);
    let hold = COLLAPSE_NEIGHBOUR_SHARE * middle;
    let mut low = (0..r.len()).filter(|&i| r[i] < hold);
    match (low.next(), low.next()) {
        (Some(i), None) if i > 0 && i + 1 < r.len() && r[i] < cut => Some(i),
        _ => None,
    }
}

/// `P(r < x)` for the normalised power `r` of a steady tone of excess `lambda` in noise of
/// mean 1 (Simpson's rule on the non-central χ² density, 32 intervals).
pub(super) fn probability_below(x: f64, lambda: f64) -> f64 {
    let steps = 32;
    let h = x.max(0.0) / steps as f64;
    let density = |r: f64| ln_tone_likelihood(r, lambda).exp();
    let mut sum = density(0.0) + density(x.max(0.0));
    for i in 1..steps {
        sum += density(i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
    }
    (sum * h / 3.0).clamp(0.0, 1.0)
}

/// `P(X ≥ k)` for `X ~ Binomial(n, p)`.
pub(super) fn binomial_upper_tail(n: usize, k: usize, p: f64) -> f64 {
    let p = p.clamp(0.0, 1.0);
    let mut term = (1.0 - p).powi(n as i32); // P(X = 0)
    let mut below = 0.0;
    for i in 0..k.min(n + 1) {
        below += term;
        // P(X = i + 1) from P(X = i).
        term *= (n - i) as f64 / (i + 1) as f64 * p / (1.0 - p).max(1e-300);
    }
    if k > n {
        return 0.0;
    }
    (1.0 - below).clamp(0.0, 1.0)
}

#[cfg(test)]
mod collapse_tests {
    use super::isolated_collapse;

    /// The windows of 113015's k28 at 742.62 s (per window, noise mean 1): one window in
    /// antiphase with a talker's harmonic, the rest at the tone's level.
    #[test]
    fn one_window_of_a_loud_tone_collapsing_between_two_that_hold_is_excused() {
        let k28 = [
            671.0, 498.0, 375.0, 357.0, 324.0, 336.0, 366.0, 429.0, 599.0, 0.0, 454.0, 381.0,
        ];
        let middle = super::super::median(k28.to_vec());
        assert_eq!(
            isolated_collapse(&k28, middle),
            Some(9),
            "the window at 0 is excused"
        );
    }

    /// What the dip tests are for stays counted: a warbling note's data tone (seed 13050's
    /// false message) dips every other window, a tone at the slot's edge is a misplaced
    /// onset, and a faint tone's dropouts are the noise's.
    #[test]
    fn a_warble_an_edge_and_a_faint_tone_are_not_excused() {
        let warble = [374.0, 39.0, 235.0, 232.0, 75.0, 379.0, 25.0, 497.0, 28.0];
        let middle = super::super::median(warble.to_vec());
        // Its deepest dip (25) lies between two windows at its level, but 39 and 75 swing
        // far below it too.
        assert_eq!(
            isolated_collapse(&warble, middle),
            None,
            "a warble is not excused"
        );
        let edge = [0.0, 300.0, 310.0, 290.0, 305.0, 300.0];
        assert_eq!(
            isolated_collapse(&edge, 300.0),
            None,
            "an edge is not a collapse"
        );
        let faint = [6.0, 0.2, 5.0, 4.0, 7.0, 5.0];
        assert_eq!(
            isolated_collapse(&faint, 5.0),
            None,
            "a faint tone is not loud enough"
        );
    }
}
