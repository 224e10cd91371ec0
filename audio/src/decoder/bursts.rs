//! Whether a first frame's vote tones hold their level in every window of the slot, taken
//! together: a transmitter's tone does, while a frame that babble or music assembled from
//! bursts (a talker's harmonic held for a syllable, a note, smeared by a hall) falls far
//! below its own typical level between the bursts.
//!
//! The per-tone steadiness test (`confirm.rs`, `Decoder::votes_sound_steadily`) judges
//! each vote tone on its own, against the noise mean, at 1e-3: a tone made of bursts
//! whose dips reach a few dB above the floor, or one dip each on three tones, passes it.
//! Here each window of each vote tone is judged against the tone's own typical level
//! (its median window, which bursts on top of a real tone do not lift) in that window's
//! noise (the floor follows a background that stops and starts, so the tone's level is
//! taken in absolute power and its share of each window's noise computed from it), and
//! the dips of the four vote tones are counted together.

use super::confirm::{
    binomial_upper_tail, neighbourhood, probability_below, stands_clear, typical_level,
};
use super::{median, Decoder};
use crate::significance::hann_share_inside;
use crate::tones::{basic_tones, Frame, SENDER_COUNT, TONE_COUNT};

/// A window of a vote tone reading below what a steady tone at the tone's typical level
/// reads with this probability is a dip.
pub(super) const P_DIP: f64 = 0.01;
/// Share of the slot at each end left out (the onset is known to tens of milliseconds).
const EDGE: f64 = 0.1;

/// The dips of a frame's vote tones (see the module's note).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Dips {
    /// Windows (of all vote tones) that read below the steady tone's [`P_DIP`] quantile.
    pub(super) dips: usize,
    /// Windows judged (vote tones × central windows).
    pub(super) cells: usize,
    /// Probability of at least `dips` dips among `cells` under steady tones.
    pub(super) tail: f64,
}

impl Decoder {
    /// The dips of `frame`'s vote tones (for each of its two basics, the two `present`
    /// tones with the highest median window) over the central windows of the slot
    /// `[a, b)` at `scale`; `None` when the slot has too few windows to tell.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn frame_dips(
        &self,
        frame: Frame,
        present: &[bool; TONE_COUNT],
        sums: &[f64; TONE_COUNT],
        count: usize,
        scale: usize,
        a: f64,
        b: f64,
    ) -> Option<Dips> {
        let window_len = self.geometry.window_len as f64;
        if b - a < 4.0 * window_len {
            return None;
        }
        let (from, to) = (a + EDGE * (b - a), b - EDGE * (b - a));
        let windows: Vec<&super::windows::WindowRecord> = self
            .history
            .iter()
            .filter(|w| hann_share_inside(w.start as f64, window_len, from, to) >= 0.9)
            .collect();
        if windows.len() < 4 {
            return None;
        }
        let own = frame.tones();
        let n = count.max(1) as f64;
        // Each tone's windows in units of that window's local noise.
        let normalised = |k: usize| -> Vec<f64> {
            let local = (median(neighbourhood(&own, k, sums)) / n).max(1.0);
            windows
                .iter()
                .map(|w| f64::from(w.r[scale * TONE_COUNT + k]) / local)
                .collect()
        };
        let (mut dips, mut cells) = (0usize, 0usize);
        for basic in [
            frame.sender.index() as usize,
            SENDER_COUNT + usize::from(frame.data),
        ] {
            let mut tones: Vec<(f64, Vec<f64>)> = basic_tones(basic)
                .into_iter()
                .filter(|&k| present[k])
                .map(|k| {
                    let x = normalised(k);
                    (median(x.clone()), x)
                })
                .collect();
            tones.sort_by(|p, q| q.0.total_cmp(&p.0));
            for (_, x) in tones.iter().take(2) {
                // The tone's power in absolute units (noise level × excess), typical of
                // the slot at its median window.
                let power = median(
                    x.iter()
                        .zip(&windows)
                        .map(|(&x, w)| (x - 1.0).max(0.0) * w.level)
                        .collect(),
                );
                for (&x, w) in x.iter().zip(&windows) {
                    let lambda = power / w.level.max(1e-30);
                    cells += 1;
                    if probability_below(x, lambda) < P_DIP {
                        dips += 1;
                    }
                }
            }
        }
        Some(Dips {
            dips,
            cells,
            tail: binomial_upper_tail(cells, dips, P_DIP),
        })
    }
}

/// Least typical tone level (per-window excess, 10 dB) of a first frame in a crowded
/// band (see [`Decoder::assembled_by_background`]). The messages of the 0 dB babble rows
/// sit at 11 dB and above (tuning rows 52009 and 52018: 2 of 1,989 first slots at
/// 10.9 dB, none below), the frames a crowd or two talkers assembled in 10 h of
/// backgrounds at 5–9 dB (tuning seeds 14–23: four of the seven false messages).
pub(super) const WEAK_LEVEL: f64 = 10.0;
/// Present tones outside the frame that make the band crowded: under Gaussian noise, 66
/// tones at `P_TONE_CONFIRM` (1e-2) give 8 or more about once in 10⁵ slots, so the dry
/// rows at −13 dB (weak frames in white noise) are not touched.
pub(super) const CROWD: usize = 8;
/// Least probability of its vote tones' dips (see [`Decoder::frame_dips`]) for a first
/// frame that does not stand clear of the floor: ≥ 6 dips of 48 windows.
pub(super) const P_DIPS: f64 = 1e-4;

impl Decoder {
    /// Why a first frame (its `present` tones at per-window excess `level`, slot sums
    /// `sums` over `count` windows of `[a, b)` at `scale`) is one the background
    /// assembled rather than a transmitter's, if it is:
    /// - it is weak ([`WEAK_LEVEL`]) in a crowded band ([`CROWD`] other tones present):
    ///   a crowd or two talkers put tones at that level all over the band, and at such a
    ///   level the per-tone tests (both halves, neighbours, steadiness) have no power
    ///   left to tell their bursts from tones;
    /// - or it does not stand clear of the floor (`stands_clear`) and its vote tones,
    ///   together, dip below their own typical level in more windows than steady tones
    ///   do at [`P_DIPS`]: a talker's harmonics held for a syllable each.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn assembled_by_background(
        &self,
        frame: Frame,
        present: &[bool; TONE_COUNT],
        level: &[f64; TONE_COUNT],
        sums: &[f64; TONE_COUNT],
        count: usize,
        scale: usize,
        a: f64,
        b: f64,
    ) -> Option<String> {
        let typical = typical_level(frame, present, level);
        let own = frame.tones();
        let crowd = (0..TONE_COUNT)
            .filter(|k| present[*k] && !own.contains(k))
            .count();
        if typical < WEAK_LEVEL && crowd >= CROWD {
            return Some(format!(
                "weak frame ({:.1} dB) among {crowd} other tones",
                10.0 * typical.max(1e-12).log10()
            ));
        }
        if stands_clear(frame, present, level) {
            return None;
        }
        self.frame_dips(frame, present, sums, count, scale, a, b)
            .filter(|d| d.tail < P_DIPS)
            .map(|d| {
                format!(
                    "vote tones dip in {} of {} windows ({:.1} dB)",
                    d.dips,
                    d.cells,
                    10.0 * typical.max(1e-12).log10()
                )
            })
    }
}
