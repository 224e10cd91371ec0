//! Where a found frame began: a step change in the per-window energy of its six tones,
//! refined by fitting the Hann-window share of the windows around the step.

use super::windows::WindowRecord;
use super::{median, Decoder};
use crate::significance::hann_share_inside;
use crate::tones::{basic_tones, Frame, SENDER_COUNT};

/// How much later than a first slot's onset its decided data basic may begin, slots,
/// inside a failed slot of the same sender (see [`Decoder::data_begins_later`]): well
/// beyond the spread of an onset estimated on three tones.
pub(super) const DATA_LATER_SLOTS: f64 = 0.25;

impl Decoder {
    /// Locates the onset of `frame` at `scale` in the windows since the floor.
    pub(super) fn estimate_onset(&self, frame: Frame, scale: usize) -> Option<f64> {
        let newest = self.replaying.unwrap_or(u64::MAX);
        self.estimate_onset_of(&frame.tones(), scale, newest)
    }

    /// Where the data basic of `frame` began, when that is clearly (more than
    /// [`DATA_LATER_SLOTS`]) after `a`, the onset of the slot `[a, b)` it was decided on
    /// as a first slot; `None` when it began about there.
    ///
    /// Only asked of a frame of the sender whose first slot just failed, with its onset
    /// inside that slot (see `Decoder::decide_slot`). The sender's tones sounded through
    /// the failed slot, so a six-tone onset does not mark where this frame began: when
    /// the failed slot was a long message's first frame (refused for a tone in a notch of
    /// the room, say), the replay after it finds the second frame at the balance of the
    /// shared sender tones and the new data tones, inside the first frame, and moves on
    /// a hop at each slot that fails there. With a talker's harmonics on the second
    /// frame's data tones such a slot passed, and the next one too: a wrong long message
    /// (lab T60 2 s, 0 dB, row 959027 at 960.76 s: sender 2 value 264 over 306). The
    /// first frame itself, found a little late by the same replay, decides its own data,
    /// which began with the slot (same row, 28.72 s), and stays a message.
    pub(super) fn data_begins_later(
        &self,
        frame: Frame,
        scale: usize,
        a: f64,
        b: f64,
    ) -> Option<f64> {
        let window_len = self.geometry.window_len as f64;
        // The windows up to the slot's end (during a replay the history holds more).
        let newest = self
            .history
            .iter()
            .filter(|w| w.start as f64 + window_len <= b + 0.25 * window_len)
            .map(|w| w.index)
            .next_back()?;
        let data = basic_tones(SENDER_COUNT + usize::from(frame.data));
        let onset = self.estimate_onset_of(&data, scale, newest)?;
        (onset > a + DATA_LATER_SLOTS * self.geometry.slot_samples).then_some(onset)
    }

    /// Locates the onset of the tones `tones` sounding together at `scale` in the windows
    /// since the floor up to window `newest` (during a replay the search stands at an
    /// earlier window than the newest heard: what follows it is not part of the onset).
    fn estimate_onset_of(&self, tones: &[usize], scale: usize, newest: u64) -> Option<f64> {
        let window_len = self.geometry.window_len as f64;
        let lookback = 3 * self.geometry.slot_windows + 4;
        let recent: Vec<&WindowRecord> = self
            .history
            .iter()
            .rev()
            .filter(|w| w.index <= newest)
            .take(lookback)
            .filter(|w| w.start >= self.floor)
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect();
        if recent.is_empty() {
            return None;
        }
        // Excess powers on one common noise level (the median of the windows'): each
        // window's own level drifts by orders of magnitude where the noise is digital
        // silence (a file that starts with the message), and a step found on such
        // numbers lands windows late.
        let common = median(recent.iter().map(|w| w.level).collect()).max(1e-300);
        let candidates: Vec<(u64, u64, f64)> = recent
            .iter()
            .map(|w| {
                (
                    w.index,
                    w.start,
                    (Self::excess(w, scale, tones) + tones.len() as f64) * w.level / common
                        - tones.len() as f64,
                )
            })
            .collect();
        // Step-change estimate: the start maximising the standardised sum to now.
        let mut best = (f64::NEG_INFINITY, 0usize);
        let mut tail = 0.0;
        for i in (0..candidates.len()).rev() {
            tail += candidates[i].2;
            let score = tail / ((candidates.len() - i) as f64).sqrt();
            if score > best.0 {
                best = (score, i);
            }
        }
        let w0 = best.1;
        let plateau_end = (w0 + self.geometry.slot_windows).min(candidates.len());
        // The edge refinement compares raw (level-scaled) excess powers, so a jump of the
        // per-window noise estimate at the edge does not bias it.
        let plateau = candidates[w0..plateau_end]
            .iter()
            .filter_map(|c| self.record(c.0))
            .map(|w| Self::excess(w, scale, tones) * w.level)
            .sum::<f64>()
            / (plateau_end - w0) as f64;
        let mut onset = candidates[w0].1 as f64;
        if plateau > 0.0 {
            // Refine on the windows around the step: each one's excess is (its Hann area
            // inside the tone)² of the plateau; the onset is the least-squares fit of that
            // model over a 2 ms-step grid. Fitting all of them, rather than taking the one
            // window nearest half the plateau, keeps one plateau window that happens to
            // read low from passing for the edge.
            let first_index = candidates[w0].0;
            let measured: Vec<(f64, f64)> = (first_index.saturating_sub(2)..=first_index + 2)
                .filter_map(|idx| self.record(idx))
                .map(|rec| {
                    (
                        rec.start as f64,
                        Self::excess(rec, scale, tones) * rec.level / plateau,
                    )
                })
                .collect();
            let slot_len = self.geometry.slot_samples;
            let steps = 96;
            let from = onset - window_len;
            let mut best = f64::INFINITY;
            for i in 0..=steps {
                let candidate = from + 1.5 * window_len * i as f64 / steps as f64;
                let misfit: f64 = measured
                    .iter()
                    .map(|&(start, q)| {
                        let share =
                            hann_share_inside(start, window_len, candidate, candidate + slot_len);
                        (q - share * share).powi(2)
                    })
                    .sum();
                if misfit < best {
                    best = misfit;
                    onset = candidate;
                }
            }
        }
        Some(onset.max(self.floor as f64))
    }
}
