//! The noise floor every tone power is divided by: a per-window level times a slowly
//! learnt per-tone shape, measured on the tones a message is not using.

use super::Decoder;
use crate::tones::{basic_tones, Frame, BASIC_COUNT, SENDER_COUNT, TONE_COUNT};

/// Powers above this multiple of the floor do not update the shape (a signal, not noise).
const SHAPE_GATE: f64 = 4.0;
/// Share of the tones (the quietest) whose mean sets the level (see [`NoiseFloor::update`]).
const KEEP: f64 = 0.85;
/// Slowest shape adaptation rate per window (time constant 256 windows, 16–33 s).
const SHAPE_RATE: f64 = 1.0 / 256.0;
/// A level this many times above or below the smoothed one (10 dB) is taken at once: far
/// beyond the estimate's own spread (about ±17% per window), it is a new background (a
/// sound starting after digital silence, a hall's tail dying away), not noise in the
/// estimate. Smoothing across such a step would normalise the first windows of a message
/// that follows silence by a level orders of magnitude too low, and its first half would
/// look like a burst.
const LEVEL_JUMP: f64 = 10.0;
/// The quietest noise assumed: quantisation noise of a 20-bit recording. Without it a
/// synthetic, noise-free signal would be normalised by FFT round-off, which jumps by
/// orders of magnitude from window to window.
const QUIETEST_NOISE_BITS: i32 = 20;
/// The level is never taken below this share (−13 dB) of the band's mean tone power,
/// held at its peak and let down by [`MIX_FLOOR_FALL_DB`] per [`MIX_FLOOR_FALL_SLOTS`]
/// tone durations. Why: a background that stops and starts (talkers pausing over digital
/// silence, a door, a whistle between silences) swings the measured floor by orders of
/// magnitude from window to window, and a message's tones normalised by it swing with
/// it: a tone steady in the air reads as bursts, its slot's halves disagree, the end
/// test reads a tail as a continuation. Held relative to what the microphone hears, the
/// floor moves slowly however the background comes and goes, and under a steady
/// background louder than this (white at any SNR the decoder works at) it never binds.
/// An outside test found the same: a steady white floor 20 dB under the mix fixed it.
/// −13 dB was chosen on the tuning room sets (seeds 1 and 7 of audio/rooms/make_rooms.py):
/// −20 dB held 92% of short messages at 0 dB babble in a free field, −15 … −10 dB 98–99%;
/// a message's own tones still sit 24 dB and more above it per window.
const MIX_FLOOR: f64 = 0.05;
/// How far the held mix level falls per [`MIX_FLOOR_FALL_SLOTS`], dB.
const MIX_FLOOR_FALL_DB: f64 = 20.0;
/// Tone durations over which the held mix level falls by [`MIX_FLOOR_FALL_DB`].
const MIX_FLOOR_FALL_SLOTS: f64 = 3.0;

/// The noise floor: a per-window level times a slowly learnt per-tone shape.
#[derive(Clone, Debug)]
pub(super) struct NoiseFloor {
    pub(super) shape: [f64; TONE_COUNT],
    level: f64,
    updates: u64,
    /// Lowest level used (see [`QUIETEST_NOISE_BITS`]).
    minimum: f64,
    /// The band's mean tone power, held at its peak and falling slowly (see [`MIX_FLOOR`]).
    held_mix: f64,
    /// Factor the held mix level falls by per window.
    mix_fall: f64,
}

impl NoiseFloor {
    pub(super) fn new(window_len: usize, windows_per_slot: f64) -> Self {
        let step = 2f64.powi(1 - QUIETEST_NOISE_BITS);
        // Quantisation noise variance step²/12 through a Hann window (Σw² = 3L/8).
        let minimum = step * step / 12.0 * 0.375 * window_len as f64;
        NoiseFloor {
            shape: [1.0; TONE_COUNT],
            level: 0.0,
            updates: 0,
            minimum,
            held_mix: 0.0,
            mix_fall: 10f64.powf(
                -MIX_FLOOR_FALL_DB / 10.0 / (MIX_FLOOR_FALL_SLOTS * windows_per_slot.max(1.0)),
            ),
        }
    }

    /// Updates from the nominal-scale powers of one window; returns the level.
    ///
    /// The level is the median of the tones not in `exclude` (the candidate message's
    /// tones), divided by that order statistic's expectation under noise alone. Taking it
    /// over all 72 would read high whenever a message sounds: its six loud tones push
    /// every order statistic up, i.e. the detector would lose sensitivity exactly when it
    /// matters. `frozen` tones keep their learnt shape.
    pub(super) fn update(
        &mut self,
        nominal: &[f32],
        exclude: &[bool; TONE_COUNT],
        frozen: &[bool; TONE_COUNT],
    ) -> f64 {
        let mut ratios = [0.0f64; TONE_COUNT];
        let mut m = 0;
        for k in 0..TONE_COUNT {
            if !exclude[k] {
                ratios[m] = f64::from(nominal[k]) / self.shape[k];
                m += 1;
            }
        }
        let ratios = &mut ratios[..m.max(1)];
        let m = ratios.len();
        // The mean of the lowest KEEP share of the tones, over that statistic's
        // expectation under noise alone (E[X_(i) of m] for Exp(1) = Σ_{j<i} 1/(m − j)).
        // Under Gaussian noise it reads the level like the median does; under babble,
        // whose voiced harmonics make a few tones of each window far louder than the
        // rest, the median sits far below the mean, and every harmonic would pass for a
        // tone; the trimmed mean takes in most of the spread and still drops the peaks.
        let keep = ((KEEP * m as f64).round() as usize).clamp(1, m);
        ratios.sort_unstable_by(|a, b| a.total_cmp(b));
        let sum: f64 = ratios[..keep].iter().sum();
        let mut order = 0.0;
        let mut expected = 0.0;
        for i in 0..keep {
            order += 1.0 / (m - i) as f64;
            expected += order;
        }
        let measured = sum / expected;
        let band = nominal.iter().map(|&p| f64::from(p)).sum::<f64>() / nominal.len() as f64;
        self.held_mix = band.max(self.held_mix * self.mix_fall);
        let mix_floor = MIX_FLOOR * self.held_mix;
        let instant = measured.max(self.minimum).max(mix_floor);
        let jump = (instant / self.level).ln().abs() > LEVEL_JUMP.ln();
        self.level = if self.level <= 0.0 || jump {
            instant
        } else {
            // Light smoothing in the log domain: the median of 72 exponentials is ±17%.
            (0.7 * self.level.ln() + 0.3 * instant.ln()).exp()
        };
        if measured < 2.0 * self.minimum || measured < mix_floor {
            // (Near-)digital silence, or a background under the mix floor, says nothing
            // about the noise's shape (learnt there, the shape would sink towards zero
            // on the quiet tones and blow up their normalised powers).
            return self.level;
        }
        // E[X | X < 4] for X ~ Exp(1): undoes the gate's bias.
        let gate_mean =
            (1.0 - (1.0 + SHAPE_GATE) * (-SHAPE_GATE).exp()) / (1.0 - (-SHAPE_GATE).exp());
        let rate = SHAPE_RATE.max(1.0 / (self.updates as f64 + 8.0));
        for k in 0..TONE_COUNT {
            if frozen[k] {
                continue;
            }
            let x = f64::from(nominal[k]) / (self.level * self.shape[k]);
            if x < SHAPE_GATE {
                self.shape[k] *= 1.0 + rate * (x / gate_mean - 1.0);
                self.shape[k] = self.shape[k].clamp(1e-6, 1e6);
            }
        }
        // Only level × shape is measured, so the shape's overall scale is free; any bias
        // of the gated update against the trimmed-mean level (under babble the gated mean
        // of a heavy-tailed power is not Exp(1)'s) walks it off for good: in an hour of
        // babble it sank ×5 per 1,500 windows onto the clamp, the per-tone shape was lost
        // and the mix floor (in the band's own units) stopped binding: short messages
        // degraded after ~600 s. The level takes the scale; the shape keeps mean log 0.
        let mean_ln = self.shape.iter().map(|s| s.ln()).sum::<f64>() / TONE_COUNT as f64;
        let g = mean_ln.exp();
        self.shape.iter_mut().for_each(|s| *s /= g);
        self.level *= g;
        self.updates += 1;
        self.level
    }
}

impl Decoder {
    /// The tones the floor leaves out of its level (`exclude`) and whose shape it does
    /// not learn (`frozen`): the tracked frame's, both data basics of a long message
    /// included; with nothing tracked, the best sender and data basic of the integrated
    /// sums so far (nominal scale), whose shape is still learnt. Under noise alone these
    /// are six tones picked by a slot-long sum, barely louder than the rest in any one
    /// window.
    pub(super) fn floor_masks(&self) -> ([bool; TONE_COUNT], [bool; TONE_COUNT]) {
        let nominal = self.geometry.nominal_scale();
        let mut frozen = [false; TONE_COUNT];
        if let Some(t) = &self.tracking {
            for k in (Frame {
                sender: t.sender,
                data: t.data[0],
            })
            .tones()
            {
                frozen[k] = true;
            }
            for k in (Frame {
                sender: t.sender,
                data: t.data[1],
            })
            .tones()
            {
                frozen[k] = true;
            }
        }
        let exclude = if self.tracking.is_some() {
            frozen
        } else {
            let s = &self.sliding[nominal * TONE_COUNT..(nominal + 1) * TONE_COUNT];
            let basic = |b: usize| -> f64 { basic_tones(b).iter().map(|&k| s[k]).sum() };
            let best = |r: std::ops::Range<usize>| {
                r.max_by(|&a, &b| basic(a).total_cmp(&basic(b)))
                    .unwrap_or(0)
            };
            let mut exclude = [false; TONE_COUNT];
            for b in [best(0..SENDER_COUNT), best(SENDER_COUNT..BASIC_COUNT)] {
                for k in basic_tones(b) {
                    exclude[k] = true;
                }
            }
            exclude
        };
        (exclude, frozen)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Exp1, StandardNormal};

    /// Geometric mean of the learnt shape.
    fn shape_scale(floor: &NoiseFloor) -> f64 {
        (floor.shape.iter().map(|s| s.ln()).sum::<f64>() / TONE_COUNT as f64).exp()
    }

    /// An hour of talkers who pause (seed 33): spells of speech, whose formants lift some
    /// tones far above others from window to window, then pauses with a quiet room 40 dB
    /// down. The floor must come out of that hour as it went in: the shape's overall
    /// scale where it started, and in the first window of a pause the level still held
    /// by the mix floor (−13 dB of the speech just heard), as in the first minute.
    ///
    /// The old floor let the shape's scale, which nothing measures (only level × shape
    /// is), walk down under babble until it sat on its clamp (after about ten minutes of
    /// audio) and the mix floor, kept in the band's own units, no longer bound: short
    /// messages over babble degraded after about 600 s.
    #[test]
    fn an_hour_of_talkers_with_pauses_leaves_the_floor_as_it_was() {
        let windows_per_slot = 16_000.0 / 1024.0;
        let mut floor = NoiseFloor::new(2048, windows_per_slot);
        let mut rng = ChaCha8Rng::seed_from_u64(33);
        let none = [false; TONE_COUNT];
        let speech = 100.0;
        let quiet = speech * 1e-4;
        let hour = (3600.0 * windows_per_slot) as usize;
        let mut seen = 0usize;
        let mut first_pause_levels = Vec::new();
        while seen < hour {
            let spell = rng.random_range(30..80);
            for _ in 0..spell {
                let powers: Vec<f32> = (0..TONE_COUNT)
                    .map(|_| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        let formant = (1.5 * z).exp();
                        let e: f64 = Exp1.sample(&mut rng);
                        (speech * formant * e) as f32
                    })
                    .collect();
                floor.update(&powers, &none, &none);
            }
            let band = floor.held_mix;
            let pause = rng.random_range(8..50);
            for i in 0..pause {
                let powers: Vec<f32> = (0..TONE_COUNT)
                    .map(|_| {
                        let e: f64 = Exp1.sample(&mut rng);
                        (quiet * e) as f32
                    })
                    .collect();
                let level = floor.update(&powers, &none, &none);
                if i == 0 {
                    // What the tones are divided by, in the band's units.
                    first_pause_levels.push((seen, level * shape_scale(&floor) / band));
                }
            }
            seen += spell + pause;
        }
        let scale = shape_scale(&floor);
        assert!(
            (0.5..2.0).contains(&scale),
            "after an hour of talkers the shape's scale is {scale:.3e} (it started at 1)"
        );
        let late: Vec<f64> = first_pause_levels
            .iter()
            .filter(|&&(at, _)| at > hour / 2)
            .map(|&(_, l)| l)
            .collect();
        let lowest = late.iter().copied().fold(f64::INFINITY, f64::min);
        assert!(
            lowest >= 0.5 * MIX_FLOOR,
            "in the second half hour a pause's first window was divided by {lowest:.2e} of \
             the speech before it; the mix floor holds {MIX_FLOOR}"
        );
    }
}
