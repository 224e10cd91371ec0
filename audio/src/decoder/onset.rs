//! Where a found frame began: a step change in the per-window energy of its six tones,
//! refined by fitting the Hann-window share of the windows around the step.

use super::windows::WindowRecord;
use super::{median, Decoder};
use crate::significance::hann_share_inside;
use crate::tones::{basic_tones, Frame, SENDER_COUNT};

/// How much later than the six-tone onset a frame's data basic must begin, slots, for
/// the data basic's onset to be taken (see [`Decoder::estimate_onset`]): well beyond
/// the spread of an onset estimated on three tones.
const DATA_LATER_SLOTS: f64 = 0.25;

impl Decoder {
    /// Locates the onset of `frame` at `scale` in the windows since the floor.
    ///
    /// A frame of the sender whose first slot just failed, with its onset inside that
    /// slot, is located on its data basic alone when that begins clearly later. The
    /// sender's tones sounded through the failed slot, so they do not mark where this
    /// frame began: when the failed slot was a long message's first frame (refused for
    /// a tone in a notch of the room, say), the replay after it finds the second frame,
    /// and on six tones its onset lies wherever the shared sender tones and the new data
    /// tones balance, inside the first frame. A slot there reads the second frame's data
    /// with the first frame's sender, and with a talker's harmonic on the data tones it
    /// passed and became a wrong long message (lab T60 2 s, 0 dB, row 959027 at 960.76
    /// s: sender 2 value 264 over 306). Located on its data basic, the frame starts
    /// where the failed slot ends, and the checks for the second half of a long message
    /// (the sender sounding before it) drop it. A message that merely began inside a
    /// slot babble assembled with its sender's basic starts its data tones with its
    /// sender's, so its onset stays.
    pub(super) fn estimate_onset(&self, frame: Frame, scale: usize) -> Option<f64> {
        let onset = self.estimate_onset_of(&frame.tones(), scale)?;
        let inside_failed = matches!(
            self.failed_slot,
            Some((sender, end)) if sender == frame.sender && onset < end
        );
        if !inside_failed {
            return Some(onset);
        }
        let data = basic_tones(SENDER_COUNT + usize::from(frame.data));
        let data_onset = self.estimate_onset_of(&data, scale)?;
        if data_onset > onset + DATA_LATER_SLOTS * self.geometry.slot_samples {
            self.note(onset, || {
                format!(
                    "onset inside a failed slot of the sender: the data basic begins at {:.2} s",
                    data_onset / self.rate()
                )
            });
            return Some(data_onset);
        }
        Some(onset)
    }

    /// Locates the onset of the tones `tones` sounding together at `scale` in the windows
    /// since the floor.
    fn estimate_onset_of(&self, tones: &[usize], scale: usize) -> Option<f64> {
        let window_len = self.geometry.window_len as f64;
        let lookback = 3 * self.geometry.slot_windows + 4;
        // During a replay the search stands at an earlier window: what follows it is not
        // part of the frame's onset.
        let newest = self.replaying.unwrap_or(u64::MAX);
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
