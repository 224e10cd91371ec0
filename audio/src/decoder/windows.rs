//! The analysed windows: each normalised by the noise floor, kept for look-back, and
//! summed over the last tone duration (the sliding sum the search reads), or over any
//! one slot (the sums a slot is decided on).

use super::Decoder;
use crate::significance::hann_share_inside;
use crate::tones::TONE_COUNT;

/// One analysed window kept for look-back.
#[derive(Clone, Debug)]
pub(super) struct WindowRecord {
    pub(super) index: u64,
    pub(super) start: u64,
    /// Noise level this window was normalised by.
    pub(super) level: f64,
    /// Normalised powers `[j * 72 + k]`.
    pub(super) r: Vec<f32>,
    /// Normalised powers at the margin bins (`[k]` below tone `k`'s comb, `[72 + k]`
    /// above).
    pub(super) margin_r: [f32; 2 * TONE_COUNT],
}

/// Sums of one slot's windows (see [`Decoder::integrate_slot`]).
pub(super) struct SlotSums {
    /// Sum of each tone's normalised power at the slot's scale.
    pub(super) sums: [f64; TONE_COUNT],
    /// Windows summed.
    pub(super) count: usize,
    /// Per-window excess power of each tone.
    pub(super) level: [f64; TONE_COUNT],
    /// Geometric mean of the windows' noise levels.
    pub(super) noise: f64,
}

impl Decoder {
    /// Normalises the window starting at sample `start` (its powers in `scratch_powers`),
    /// keeps it, adds it to the sliding sum and moves the search or the tracking on.
    pub(super) fn on_window(&mut self, start: u64) {
        let scales = self.geometry.scale_count();
        let nominal = self.geometry.nominal_scale();
        let (exclude, frozen) = self.floor_masks();
        let powers = std::mem::take(&mut self.scratch_powers);
        let level = self.noise.update(
            &powers[nominal * TONE_COUNT..(nominal + 1) * TONE_COUNT],
            &exclude,
            &frozen,
        );
        let mut r = if self.history.len() >= self.history_cap {
            let mut old = self.history.pop_front().map(|w| w.r).unwrap_or_default();
            old.resize(scales * TONE_COUNT, 0.0);
            old
        } else {
            vec![0.0; scales * TONE_COUNT]
        };
        for j in 0..scales {
            for k in 0..TONE_COUNT {
                let i = j * TONE_COUNT + k;
                r[i] = (f64::from(powers[i]) / (level * self.noise.shape[k])) as f32;
            }
        }
        self.scratch_powers = powers;
        let mut margin_r = [0.0f32; 2 * TONE_COUNT];
        for (i, (m, &p)) in margin_r
            .iter_mut()
            .zip(self.analyzer.margin_powers())
            .enumerate()
        {
            *m = (f64::from(p) / (level * self.noise.shape[i % TONE_COUNT])) as f32;
        }
        let index = self.windows_seen;
        self.windows_seen += 1;
        self.history.push_back(WindowRecord {
            index,
            start,
            level,
            r,
            margin_r,
        });
        if start >= self.floor {
            self.add_to_sliding(index);
        }
        self.update_blocked();
        if self.tracking.is_some() {
            self.advance_tracking();
        } else {
            self.detect();
        }
        self.run_pending_replays();
    }

    fn position(&self, index: u64) -> Option<usize> {
        let first = self.history.front()?.index;
        let pos = index.checked_sub(first)? as usize;
        (pos < self.history.len()).then_some(pos)
    }

    pub(super) fn record(&self, index: u64) -> Option<&WindowRecord> {
        self.position(index).map(|p| &self.history[p])
    }

    pub(super) fn add_to_sliding(&mut self, index: u64) {
        let Some(pos) = self.position(index) else {
            return;
        };
        // The sums hold consecutive windows, each once: a window already summed is not
        // added again, and one past a gap starts the sums afresh (the oldest window,
        // taken off as the sums slide, must be the one that was added first).
        let next = self.sliding_first + self.sliding_count as u64;
        if self.sliding_count > 0 && index < next {
            return;
        }
        if self.sliding_count > 0 && index > next {
            self.sliding.iter_mut().for_each(|s| *s = 0.0);
            self.sliding_count = 0;
        }
        if self.sliding_count == 0 {
            self.sliding_first = index;
        }
        for (s, &x) in self.sliding.iter_mut().zip(&self.history[pos].r) {
            *s += f64::from(x);
        }
        self.sliding_count += 1;
        if self.sliding_count > self.geometry.slot_windows {
            if let Some(old) = self.position(self.sliding_first) {
                for (s, &x) in self.sliding.iter_mut().zip(&self.history[old].r) {
                    *s -= f64::from(x);
                }
            }
            self.sliding_first += 1;
            self.sliding_count -= 1;
        }
    }

    /// Indices of the windows in the history that start at or after `floor`.
    pub(super) fn indices_from(&self, floor: u64) -> Vec<u64> {
        self.history
            .iter()
            .filter(|w| w.start >= floor)
            .map(|w| w.index)
            .collect()
    }

    /// Restarts integration from the windows starting at or after `floor`.
    pub(super) fn reset_sliding(&mut self, floor: u64) {
        self.floor = floor;
        self.sliding.iter_mut().for_each(|s| *s = 0.0);
        self.sliding_count = 0;
        let indices = self.indices_from(floor);
        let keep = indices.len().saturating_sub(self.geometry.slot_windows);
        for &i in &indices[keep..] {
            self.add_to_sliding(i);
        }
        self.run = None;
    }

    /// Per-window excess of `tones` at `scale` in window `rec`.
    pub(super) fn excess(rec: &WindowRecord, scale: usize, tones: &[usize]) -> f64 {
        tones
            .iter()
            .map(|&k| f64::from(rec.r[scale * TONE_COUNT + k]) - 1.0)
            .sum()
    }

    /// The sample just past the newest window.
    pub(super) fn latest_window_end(&self) -> f64 {
        self.history
            .back()
            .map(|w| (w.start + self.geometry.window_len as u64) as f64)
            .unwrap_or(0.0)
    }

    /// Integrates the windows lying (≥ 90% of their Hann area) inside `[a, b)` at `scale`.
    pub(super) fn integrate_slot(&self, scale: usize, a: f64, b: f64) -> Option<SlotSums> {
        let window_len = self.geometry.window_len as f64;
        let mut sums = [0.0; TONE_COUNT];
        let mut energy_share = 0.0;
        let mut count = 0;
        let mut best_partial: Option<(f64, &WindowRecord)> = None;
        let mut log_level = 0.0;
        for w in &self.history {
            let share = hann_share_inside(w.start as f64, window_len, a, b);
            if share >= 0.9 {
                log_level += w.level.ln();
                for (k, s) in sums.iter_mut().enumerate() {
                    *s += f64::from(w.r[scale * TONE_COUNT + k]);
                }
                energy_share += share * share;
                count += 1;
            } else if share >= 0.5 && best_partial.is_none_or(|(s, _)| share > s) {
                best_partial = Some((share, w));
            }
        }
        if count == 0 {
            // Tones shorter than a window: use the window holding most of the tone.
            let (share, w) = best_partial?;
            for (k, s) in sums.iter_mut().enumerate() {
                *s = f64::from(w.r[scale * TONE_COUNT + k]);
            }
            energy_share = share * share;
            count = 1;
            log_level = w.level.ln();
        }
        let mut level = [0.0; TONE_COUNT];
        for k in 0..TONE_COUNT {
            level[k] = ((sums[k] - count as f64) / energy_share).max(0.0);
        }
        Some(SlotSums {
            sums,
            count,
            level,
            noise: (log_level / count as f64).exp(),
        })
    }
}
