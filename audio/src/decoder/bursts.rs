//! Whether a first frame is one the background assembled: a weak frame in a crowded
//! band. The per-tone checks of `confirm.rs` (both halves, above the neighbourhood,
//! steadiness) judge each vote tone alone; at a typical tone of 5–9 dB per window they
//! have no power left (a steady tone that weak reads below the noise mean one window in
//! ten), and a crowd or two talkers in a hall put tones at that level all over the band.
//! The messages of the babble rows at 0 dB are not that weak, and in white noise, where
//! they are, the band around them is empty.

use super::confirm::{typical_level, vote_basics, HALL_CLEAR_LEVEL};
use super::Decoder;
use crate::significance::hann_share_inside;
use crate::tones::{basic_tones, Frame, TONE_COUNT};

/// Least typical tone level (per-window excess, 10 dB) of a first frame in a crowded
/// band (see [`assembled_by_background`]). The messages of the 0 dB babble rows
/// sit at 11 dB and above (tuning rows 52009 and 52018: 2 of 1,989 first slots at
/// 10.9 dB, none below), the frames a crowd or two talkers assembled in 10 h of
/// backgrounds at 5–9 dB (tuning seeds 14–23: four of the eight false messages).
pub(super) const WEAK_LEVEL: f64 = 10.0;
/// Present tones outside the frame that make the band crowded: under Gaussian noise, 66
/// tones at `P_TONE_CONFIRM` (1e-2) give 8 or more about once in 10⁵ slots, so the dry
/// rows at −13 dB (weak frames in white noise) are not touched.
pub(super) const CROWD: usize = 8;

/// How many tones outside the frame's own six are present: the crowd both checks here
/// ask about.
fn crowd_size(frame: Frame, present: &[bool; TONE_COUNT]) -> usize {
    let own = frame.tones();
    (0..TONE_COUNT)
        .filter(|k| present[*k] && !own.contains(k))
        .count()
}

/// Why a first frame (its `present` tones at per-window excess `level`) is one the
/// background assembled rather than a transmitter's, if it is: it is weak
/// ([`WEAK_LEVEL`]) in a crowded band ([`CROWD`] other tones present), none of its
/// tones at the hall level (`HALL_CLEAR_LEVEL`, 15 dB).
pub(super) fn assembled_by_background(
    frame: Frame,
    present: &[bool; TONE_COUNT],
    level: &[f64; TONE_COUNT],
) -> Option<String> {
    let typical = typical_level(frame, present, level);
    let own = frame.tones();
    let crowd = crowd_size(frame, present);
    // A frame with a tone at the hall level is not one babble assembled (its frames
    // have no tone at 15 dB): in a hall a message's median tone sits under 10 dB now
    // and then, pulled down by tones in the room's notches, while one of its tones
    // rings far above the talkers (tuning row 52024 at 890.59 s: 9.2 dB typical,
    // k68 at 81 per window, refused without this).
    let loudest = own
        .iter()
        .filter(|&&k| present[k])
        .map(|&k| level[k])
        .fold(0.0f64, f64::max);
    if typical < WEAK_LEVEL && crowd >= CROWD && loudest < HALL_CLEAR_LEVEL {
        return Some(format!(
            "weak frame ({:.1} dB) among {crowd} other tones",
            10.0 * typical.max(1e-12).log10()
        ));
    }
    // Two loud tones of something else, each completed to a vote by a tone near the
    // floor: the one frame behind three of the four false messages of round 17's
    // backgrounds (tuning rows 31051 and 37050, Goalkeeper's data 7 from k0 and k10 of a
    // note and its octave in the music, their vote tones k24, k34, k58 at 2–4 per window).
    // A transmitter in a room's notches loses one tone of a basic now and then, and
    // sounds it faint in the other; losing both votes so at once, with their loud tones
    // loud, the tuning rows never did (S = 88, 89: 0 of 26,000 messages at 10 dB; at
    // 20 dB, 3 short messages of 89018).
    // Each vote's loud tone must be loud (the hall level, 15 dB): a weak message in white
    // noise at −13 dB has every tone near the floor, faint votes and all, and is a message.
    let tones: Vec<usize> = own.into_iter().filter(|&k| present[k]).collect();
    let loud_beside_faint = vote_basics(frame).into_iter().all(|basic| {
        basic_tones(basic)
            .iter()
            .filter(|&&k| present[k])
            .any(|&k| level[k] >= HALL_CLEAR_LEVEL)
    });
    if loud_beside_faint && votes_rest_on_faint_tones(&tones, |i| level[tones[i]], FAINT_VOTE_TONE)
    {
        return Some("both votes rest on a faint tone beside a loud one".to_string());
    }
    None
}

/// Per-window excess (10 dB) under which the tone a vote rests on beside a louder one is
/// faint (see [`assembled_by_background`], `Decoder::has_off_grid_tone`).
pub(super) const FAINT_VOTE_TONE: f64 = 10.0;

/// Whether each of the two basics among a frame's present `tones` (per-window excess
/// `excess(i)` of `tones[i]`) rests its vote on a tone under `faint`: its second loudest.
pub(super) fn votes_rest_on_faint_tones(
    tones: &[usize],
    excess: impl Fn(usize) -> f64,
    faint: f64,
) -> bool {
    let mut basics: Vec<usize> = tones
        .iter()
        .map(|&k| k % crate::tones::BASIC_COUNT)
        .collect();
    basics.sort_unstable();
    basics.dedup();
    basics.len() == 2
        && basics.iter().all(|&basic| {
            let mut levels: Vec<f64> = (0..tones.len())
                .filter(|&i| tones[i] % crate::tones::BASIC_COUNT == basic)
                .map(&excess)
                .collect();
            levels.sort_by(|x, y| y.total_cmp(x));
            levels.get(1).is_some_and(|&l| l < faint)
        })
}

/// Least share of a slot's central windows in which every tone a frame's votes rest on
/// sounds (see [`Decoder::votes_sound_apart`]).
pub(super) const TOGETHER_SHARE: f64 = 0.7;
/// Share of its own median window below which a vote tone counts as silent in a window
/// (−7 dB; at least [`SILENT_LEVEL`]).
const SILENT_SHARE: f64 = 0.2;
/// Window reading (noise mean 1) under which a vote tone counts as silent whatever its
/// median: a steady tone of 10 dB per window reads under it about once in a thousand
/// windows.
const SILENT_LEVEL: f32 = 2.0;
/// Share of the slot at each end left out (as for the steadiness test in `confirm.rs`).
const TOGETHER_EDGE: f64 = 0.1;

impl Decoder {
    /// Why a first frame below the hall level in a crowded band is one the background
    /// assembled from bursts, if it is: its vote tones (the two loudest present tones of
    /// each of its two basics) do not sound together. A transmitter sounds all six tones
    /// through the slot, so in nearly every central window each vote tone reads near its
    /// own median; babble, a crowd or music puts each of them there in its own bursts
    /// (a syllable, a note), and in many windows one of the four is silent (under
    /// [`SILENT_SHARE`] of its median, or [`SILENT_LEVEL`]). Refused when fewer than
    /// [`TOGETHER_SHARE`] of the windows hold all four.
    ///
    /// The background's frames that passed every other check in 10 h draws (tuning
    /// seeds 24–27, 21, 23) sat at 10.7–14.1 dB typical with all four together in 20–60%
    /// of the windows; the real first slots of the 0 dB rooms rows (tuning rows 68015,
    /// 68018: 1,982 slots) in 60% or fewer only at 16.4 dB and above (3 slots), and in
    /// 70% or more below it. White noise (the dry rows) has no crowd: weak frames there
    /// are not asked.
    pub(super) fn votes_sound_apart(
        &self,
        frame: Frame,
        present: &[bool; TONE_COUNT],
        level: &[f64; TONE_COUNT],
        scale: usize,
        a: f64,
        b: f64,
    ) -> Option<String> {
        let typical = typical_level(frame, present, level);
        let crowd = crowd_size(frame, present);
        if typical >= HALL_CLEAR_LEVEL || crowd < CROWD {
            return None;
        }
        let votes = vote_tones(frame, present, level);
        let window_len = self.geometry.window_len as f64;
        let (from, to) = (a + TOGETHER_EDGE * (b - a), b - TOGETHER_EDGE * (b - a));
        let windows: Vec<&[f32]> = self
            .history
            .iter()
            .filter(|w| hann_share_inside(w.start as f64, window_len, from, to) >= 0.9)
            .filter_map(|w| w.r.get(scale * TONE_COUNT..(scale + 1) * TONE_COUNT))
            .collect();
        let share = together_share(&windows, &votes)?;
        (share < TOGETHER_SHARE).then(|| {
            format!(
                "vote tones {votes:?} together in {:.0}% of the windows ({:.1} dB, {crowd} other tones)",
                100.0 * share,
                10.0 * typical.max(1e-12).log10()
            )
        })
    }
}

/// The tones a frame's 2-of-3 votes rest on: the two loudest `present` tones of each of
/// its basics (fewer when a basic has fewer present).
pub(super) fn vote_tones(
    frame: Frame,
    present: &[bool; TONE_COUNT],
    level: &[f64; TONE_COUNT],
) -> Vec<usize> {
    let mut votes = Vec::with_capacity(4);
    for b in frame.basics() {
        let mut tones: Vec<usize> = basic_tones(b).into_iter().filter(|&k| present[k]).collect();
        tones.sort_by(|x, y| level[*y].total_cmp(&level[*x]));
        votes.extend(tones.into_iter().take(2));
    }
    votes
}

/// Share of `windows` (each tone's per-window power, noise mean 1) in which every tone of
/// `votes` sounds: at least [`SILENT_SHARE`] of its own median window and at least
/// [`SILENT_LEVEL`]. `None` with fewer than four windows (too few to tell).
pub(super) fn together_share(windows: &[&[f32]], votes: &[usize]) -> Option<f64> {
    if windows.len() < 4 || votes.is_empty() {
        return None;
    }
    let floors: Vec<f32> = votes
        .iter()
        .map(|&k| {
            let mut r: Vec<f32> = windows
                .iter()
                .map(|w| w.get(k).copied().unwrap_or(0.0))
                .collect();
            r.sort_by(f32::total_cmp);
            let median = r[r.len() / 2];
            (SILENT_SHARE as f32 * median).max(SILENT_LEVEL)
        })
        .collect();
    let held = windows
        .iter()
        .filter(|w| {
            votes
                .iter()
                .zip(&floors)
                .all(|(&k, &floor)| w.get(k).copied().unwrap_or(0.0) >= floor)
        })
        .count();
    Some(held as f64 / windows.len() as f64)
}
