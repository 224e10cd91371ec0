//! The analysis front end: Hann-windowed, zero-padded FFT frames and the power at each
//! tone for a set of candidate frequency scales.
//!
//! A sender's clock may be off by a fraction of a percent, which moves the top tone by up
//! to 20 Hz — almost half the tone spacing. Rather than widen every tone's bin (which adds
//! noise), the analysis reads each tone at `f_k · (1 + s)` for a comb of scales `s`
//! spaced so the top tone moves by at most half a (zero-padded) bin between neighbours;
//! the detector then picks the scale per frame.

use std::sync::Arc;

use rustfft::{num_complex::Complex, FftPlanner};

use crate::tones::{tone_frequency_hz, TONE_COUNT};

/// Sizes and frequencies of the analysis, fixed by the sample rate and tone duration.
#[derive(Clone, Debug)]
pub(crate) struct Geometry {
    pub rate_hz: u32,
    /// Samples per analysis window.
    pub window_len: usize,
    /// Samples between window starts (half a window).
    pub hop: usize,
    /// FFT size (twice the window: zero padding halves the scalloping loss).
    pub fft_len: usize,
    /// Windows that fit wholly inside one tone duration (at least 1).
    pub slot_windows: usize,
    /// Tone duration in samples.
    pub slot_samples: f64,
    /// Candidate frequency scales (relative error), symmetric about 0.
    pub scales: Vec<f64>,
    /// `bins[j * 72 + k]`: FFT bin of tone `k` at scale `j`.
    pub bins: Vec<usize>,
    /// `margin_bins[k]`: the bin just below tone `k`'s lowest comb bin; `[72 + k]`: just
    /// above its highest. A peak there lies beyond the tolerated frequency error.
    pub margin_bins: Vec<usize>,
}

/// Smallest `2^a · 3^b ≥ n` (sizes rustfft handles fastest).
fn smooth_size_at_least(n: usize) -> usize {
    let mut best = usize::MAX;
    let mut p3 = 1usize;
    while p3 < 2 * n.max(1) {
        let mut v = p3;
        while v < n {
            v *= 2;
        }
        best = best.min(v);
        p3 *= 3;
    }
    best
}

impl Geometry {
    pub fn new(rate_hz: u32, tone_duration_s: f64, max_frequency_error: f64) -> Geometry {
        let rate = f64::from(rate_hz);
        // Longer windows integrate more coherently (less non-coherent loss) but react
        // later; 1/8 of the tone, kept within 64–128 ms so adjacent tones (49 Hz apart)
        // stay ≥ 3 bins apart.
        let window_s = (tone_duration_s / 8.0).clamp(0.064, 0.128);
        let window_len = smooth_size_at_least((window_s * rate).ceil() as usize);
        let hop = window_len / 2;
        let fft_len = 2 * window_len;
        let slot_samples = tone_duration_s * rate;
        let slot_windows = if slot_samples >= window_len as f64 {
            ((slot_samples - window_len as f64) / hop as f64).floor() as usize + 1
        } else {
            1
        };
        let fine_bin_hz = rate / fft_len as f64;
        let step = fine_bin_hz / (2.0 * crate::tones::HIGHEST_TONE_HZ);
        let half = (max_frequency_error / step).ceil().max(0.0) as usize;
        let scales: Vec<f64> = (0..=2 * half)
            .map(|j| {
                if half == 0 {
                    0.0
                } else {
                    (j as f64 - half as f64) * max_frequency_error / half as f64
                }
            })
            .collect();
        let nyquist_bin = fft_len / 2;
        let mut bins = Vec::with_capacity(scales.len() * TONE_COUNT);
        for s in &scales {
            for k in 0..TONE_COUNT {
                let f = tone_frequency_hz(k) * (1.0 + s);
                let b = (f * fft_len as f64 / rate).round() as usize;
                bins.push(b.min(nyquist_bin));
            }
        }
        let mut margin_bins = vec![0; 2 * TONE_COUNT];
        for k in 0..TONE_COUNT {
            let comb = (0..scales.len()).map(|j| bins[j * TONE_COUNT + k]);
            let low = comb.clone().min().unwrap_or(0);
            let high = comb.max().unwrap_or(0);
            margin_bins[k] = low.saturating_sub(1);
            margin_bins[TONE_COUNT + k] = (high + 1).min(nyquist_bin);
        }
        Geometry {
            rate_hz,
            window_len,
            hop,
            fft_len,
            slot_windows,
            slot_samples,
            scales,
            bins,
            margin_bins,
        }
    }

    pub fn scale_count(&self) -> usize {
        self.scales.len()
    }

    /// Index of the scale 0 (nominal frequencies).
    pub fn nominal_scale(&self) -> usize {
        self.scales.len() / 2
    }
}

/// Cuts the sample stream into windows and measures tone powers.
pub(crate) struct Analyzer {
    geometry: Geometry,
    hann: Vec<f32>,
    fft: Arc<dyn rustfft::Fft<f32>>,
    buffer: Vec<Complex<f32>>,
    scratch: Vec<Complex<f32>>,
    pending: Vec<f32>,
    /// Read position in `pending` of the next window's first sample.
    offset: usize,
    /// Absolute index of `pending[0]`.
    pending_start: u64,
    /// Powers of the last window, `[j * 72 + k]`.
    powers: Vec<f32>,
    /// Powers of the last window at the margin bins (see [`Geometry::margin_bins`]).
    margin_powers: Vec<f32>,
}

impl Analyzer {
    pub fn new(geometry: Geometry) -> Analyzer {
        let l = geometry.window_len;
        let hann = (0..l)
            .map(|n| (0.5 - 0.5 * (2.0 * std::f64::consts::PI * n as f64 / l as f64).cos()) as f32)
            .collect();
        let fft = FftPlanner::<f32>::new().plan_fft_forward(geometry.fft_len);
        let scratch = vec![Complex::new(0.0, 0.0); fft.get_inplace_scratch_len()];
        Analyzer {
            buffer: vec![Complex::new(0.0, 0.0); geometry.fft_len],
            powers: vec![0.0; geometry.scale_count() * TONE_COUNT],
            margin_powers: vec![0.0; 2 * TONE_COUNT],
            geometry,
            hann,
            fft,
            scratch,
            pending: Vec::new(),
            offset: 0,
            pending_start: 0,
        }
    }

    /// Queues samples; non-finite values become 0 so no input can poison the state.
    pub fn push(&mut self, samples: impl Iterator<Item = f32>) {
        if self.offset > 4 * self.geometry.window_len {
            self.pending.drain(..self.offset);
            self.pending_start += self.offset as u64;
            self.offset = 0;
        }
        self.pending.extend(samples.map(|x| {
            if x.is_finite() {
                x.clamp(-1e6, 1e6)
            } else {
                0.0
            }
        }));
    }

    /// Analyses the next complete window, if any: returns its first sample's index; the
    /// tone powers are then in [`Analyzer::powers`].
    pub fn next_window(&mut self) -> Option<u64> {
        let l = self.geometry.window_len;
        if self.pending.len() - self.offset < l {
            return None;
        }
        let start = self.pending_start + self.offset as u64;
        let frame = &self.pending[self.offset..self.offset + l];
        // Removing the window's mean keeps a DC offset out of the low tones' sidelobes.
        let mean = frame.iter().sum::<f32>() / l as f32;
        for (i, (z, (&x, &w))) in self
            .buffer
            .iter_mut()
            .zip(frame.iter().zip(&self.hann))
            .enumerate()
        {
            debug_assert!(i < l);
            *z = Complex::new((x - mean) * w, 0.0);
        }
        for z in &mut self.buffer[l..] {
            *z = Complex::new(0.0, 0.0);
        }
        self.fft
            .process_with_scratch(&mut self.buffer, &mut self.scratch);
        for (p, &b) in self.powers.iter_mut().zip(&self.geometry.bins) {
            *p = self.buffer[b].norm_sqr();
        }
        for (p, &b) in self
            .margin_powers
            .iter_mut()
            .zip(&self.geometry.margin_bins)
        {
            *p = self.buffer[b].norm_sqr();
        }
        self.offset += self.geometry.hop;
        Some(start)
    }

    pub fn powers(&self) -> &[f32] {
        &self.powers
    }

    pub fn margin_powers(&self) -> &[f32] {
        &self.margin_powers
    }

    /// The `len` samples from absolute index `from`, if still held (samples from the next
    /// window's start on are always held; older ones until the next trim).
    pub fn samples(&self, from: u64, len: usize) -> Option<&[f32]> {
        let i = usize::try_from(from.checked_sub(self.pending_start)?).ok()?;
        self.pending.get(i..i.checked_add(len)?)
    }

    /// Samples pushed so far.
    pub fn samples_pushed(&self) -> u64 {
        self.pending_start + self.pending.len() as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometry_at_common_rates() {
        let g = Geometry::new(16_000, 1.0, 0.006);
        assert_eq!((g.window_len, g.hop, g.slot_windows), (2048, 1024, 14));
        assert!(g.scales.first().unwrap() + 0.006 < 1e-12 && g.scales.len() % 2 == 1);
        let g = Geometry::new(44_100, 0.1, 0.006);
        assert!(
            g.window_len >= 2822 && g.window_len <= 3072,
            "{}",
            g.window_len
        );
        assert_eq!(smooth_size_at_least(5513), 5832);
    }

    #[test]
    fn a_tone_is_loudest_in_its_own_bin() {
        let g = Geometry::new(16_000, 1.0, 0.006);
        let nominal = g.nominal_scale();
        let mut a = Analyzer::new(g.clone());
        let f = tone_frequency_hz(40);
        a.push(
            (0..4096).map(|n| (2.0 * std::f64::consts::PI * f * n as f64 / 16_000.0).sin() as f32),
        );
        assert_eq!(a.next_window(), Some(0));
        let p = &a.powers()[nominal * TONE_COUNT..(nominal + 1) * TONE_COUNT];
        let loudest = (0..TONE_COUNT)
            .max_by(|&i, &j| p[i].total_cmp(&p[j]))
            .unwrap();
        assert_eq!(loudest, 40);
        assert!(
            p[41] < p[40] * 1e-3,
            "neighbour leakage {} vs {}",
            p[41],
            p[40]
        );
        assert_eq!(a.next_window(), Some(1024));
    }
}
