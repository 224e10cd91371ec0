//! Seeded channel models: the noise and interference a robot-soccer hall throws at the
//! codec, for tests and `huddle audio eval`. Every source is deterministic for its seed.
//!
//! All sources *add* into a buffer ([`Source::add_to`]) so they can be mixed. Levels are
//! RMS amplitudes (full scale 1.0).

mod intermittent;
mod room;

pub use intermittent::{Door, Gated, Melody};
pub use room::{band_limit, in_band_power, Convolver, RoomSpec};

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use crate::tones::{HIGHEST_TONE_HZ, LOWEST_TONE_HZ};

/// Something that adds sound into a buffer, sample by sample, continuing where it stopped.
pub trait Source {
    /// Adds the next `out.len()` samples of this source to `out`.
    fn add_to(&mut self, out: &mut [f32]);
}

/// White noise σ (per sample) whose power inside 500–4000 Hz is `signal_power / 10^(snr/10)`:
/// the in-band SNR definition of this crate.
pub fn white_sigma_for_in_band_snr(signal_power: f64, snr_db: f64, sample_rate_hz: u32) -> f64 {
    let in_band_noise = signal_power / 10f64.powf(snr_db / 10.0);
    let band_share = (HIGHEST_TONE_HZ - LOWEST_TONE_HZ) / (f64::from(sample_rate_hz) / 2.0);
    (in_band_noise / band_share).sqrt()
}

/// Mean power of `x`.
pub fn power(x: &[f32]) -> f64 {
    if x.is_empty() {
        return 0.0;
    }
    x.iter().map(|&v| f64::from(v) * f64::from(v)).sum::<f64>() / x.len() as f64
}

/// Gaussian white noise.
#[derive(Clone, Debug)]
pub struct WhiteNoise {
    rng: ChaCha8Rng,
    sigma: f32,
}

impl WhiteNoise {
    /// White noise with standard deviation `sigma`.
    pub fn new(seed: u64, sigma: f64) -> Self {
        WhiteNoise {
            rng: ChaCha8Rng::seed_from_u64(seed),
            sigma: sigma as f32,
        }
    }
}

impl Source for WhiteNoise {
    fn add_to(&mut self, out: &mut [f32]) {
        for x in out {
            let n: f32 = StandardNormal.sample(&mut self.rng);
            *x += self.sigma * n;
        }
    }
}

/// Pink (1/f) noise: white noise through Paul Kellet's refined filter (±0.05 dB over the
/// audio band), scaled to an RMS level.
#[derive(Clone, Debug)]
pub struct PinkNoise {
    white: WhiteNoise,
    b: [f32; 7],
    gain: f32,
}

impl PinkNoise {
    /// Pink noise of RMS amplitude `rms`.
    pub fn new(seed: u64, rms: f64) -> Self {
        PinkNoise {
            white: WhiteNoise::new(seed, 1.0),
            b: [0.0; 7],
            // The filter's output RMS for unit white input is about 3.2 (measured).
            gain: (rms / 3.2) as f32,
        }
    }
}

impl Source for PinkNoise {
    fn add_to(&mut self, out: &mut [f32]) {
        let mut w = vec![0.0f32; out.len()];
        self.white.add_to(&mut w);
        let b = &mut self.b;
        for (x, &white) in out.iter_mut().zip(&w) {
            b[0] = 0.99886 * b[0] + white * 0.0555179;
            b[1] = 0.99332 * b[1] + white * 0.0750759;
            b[2] = 0.96900 * b[2] + white * 0.153852;
            b[3] = 0.86650 * b[3] + white * 0.3104856;
            b[4] = 0.55000 * b[4] + white * 0.5329522;
            b[5] = -0.7616 * b[5] - white * 0.0168980;
            let pink = b[0] + b[1] + b[2] + b[3] + b[4] + b[5] + b[6] + white * 0.5362;
            b[6] = white * 0.115926;
            *x += self.gain * pink;
        }
    }
}

/// A two-pole resonator (formant) with unit gain at its centre.
#[derive(Clone, Debug, Default)]
struct Resonator {
    a1: f32,
    a2: f32,
    gain: f32,
    y1: f32,
    y2: f32,
}

impl Resonator {
    fn tune(&mut self, centre_hz: f64, bandwidth_hz: f64, rate: f64) {
        let r = (-std::f64::consts::PI * bandwidth_hz / rate).exp();
        let theta = 2.0 * std::f64::consts::PI * centre_hz / rate;
        self.a1 = (2.0 * r * theta.cos()) as f32;
        self.a2 = (-r * r) as f32;
        self.gain = ((1.0 - r) * (1.0 + r * r - 2.0 * r * (2.0 * theta).cos()).sqrt()) as f32;
    }

    fn step(&mut self, x: f32) -> f32 {
        let y = self.gain * x + self.a1 * self.y1 + self.a2 * self.y2;
        self.y2 = self.y1;
        self.y1 = y;
        y
    }
}

/// One synthetic talker: a glottal pulse train (harmonics of a drifting pitch, 90–250 Hz)
/// or hiss, through three formants that change every syllable, with a syllabic envelope
/// and pauses.
#[derive(Clone, Debug)]
struct Talker {
    rng: ChaCha8Rng,
    rate: f64,
    pitch_hz: f64,
    phase: f64,
    formants: [Resonator; 3],
    syllable_left: usize,
    syllable_len: usize,
    voiced: bool,
    silent: bool,
}

impl Talker {
    fn new(seed: u64, rate: f64) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let pitch_hz = rng.random_range(90.0..250.0);
        Talker {
            rng,
            rate,
            pitch_hz,
            phase: 0.0,
            formants: Default::default(),
            syllable_left: 0,
            syllable_len: 1,
            voiced: true,
            silent: false,
        }
    }

    fn next_syllable(&mut self) {
        self.syllable_len = (self.rng.random_range(0.12..0.35) * self.rate) as usize;
        self.syllable_left = self.syllable_len;
        self.silent = self.rng.random_bool(0.2);
        self.voiced = self.rng.random_bool(0.8);
        let f = [
            self.rng.random_range(300.0..900.0),
            self.rng.random_range(900.0..2500.0),
            self.rng.random_range(2400.0..3500.0),
        ];
        for (res, f) in self.formants.iter_mut().zip(f) {
            res.tune(f, 80.0 + f * 0.05, self.rate);
        }
        self.pitch_hz = (self.pitch_hz * self.rng.random_range(0.9..1.1)).clamp(90.0, 250.0);
    }

    fn sample(&mut self) -> f32 {
        if self.syllable_left == 0 {
            self.next_syllable();
        }
        self.syllable_left -= 1;
        let u = 1.0 - self.syllable_left as f64 / self.syllable_len as f64;
        let envelope = if self.silent {
            0.0
        } else {
            (std::f64::consts::PI * u).sin() as f32
        };
        let excitation = if self.voiced {
            // Slow pitch glide within the syllable, as in real intonation.
            self.phase += self.pitch_hz * (1.0 + 0.05 * (u - 0.5)) / self.rate;
            if self.phase >= 1.0 {
                self.phase -= 1.0;
                6.0
            } else {
                0.0
            }
        } else {
            let n: f32 = StandardNormal.sample(&mut self.rng);
            0.5 * n
        };
        let y: f32 = self.formants.iter_mut().map(|r| r.step(excitation)).sum();
        envelope * y
    }
}

/// Speech-like babble: several talkers at once (a crowd, a coach, a commentator).
#[derive(Clone, Debug)]
pub struct Babble {
    talkers: Vec<Talker>,
    gain: f32,
}

impl Babble {
    /// `talkers` voices mixed to RMS amplitude about `rms`.
    pub fn new(seed: u64, sample_rate_hz: u32, talkers: usize, rms: f64) -> Self {
        let rate = f64::from(sample_rate_hz);
        let mut b = Babble {
            talkers: (0..talkers.max(1) as u64)
                .map(|i| Talker::new(seed.wrapping_mul(31).wrapping_add(i), rate))
                .collect(),
            gain: 1.0,
        };
        // Calibrate the gain on a throw-away copy so the stream itself is untouched.
        let mut probe = b.clone();
        let mut x = vec![0.0f32; (rate * 4.0) as usize];
        probe.add_to(&mut x);
        b.gain = (rms / power(&x).sqrt().max(1e-12)) as f32;
        b
    }
}

impl Source for Babble {
    fn add_to(&mut self, out: &mut [f32]) {
        for x in out {
            let s: f32 = self.talkers.iter_mut().map(|t| t.sample()).sum();
            *x += self.gain * s;
        }
    }
}

/// A referee's whistle: bursts sweeping between 2 and 4 kHz (up or down, with a warble),
/// 0.2–1.5 s long, 0.3–3 s apart.
#[derive(Clone, Debug)]
pub struct Whistle {
    rng: ChaCha8Rng,
    rate: f64,
    amplitude: f32,
    phase: f64,
    gap_left: usize,
    burst_len: usize,
    burst_left: usize,
    from_hz: f64,
    to_hz: f64,
}

impl Whistle {
    /// Whistle bursts of RMS amplitude `rms` while sounding.
    pub fn new(seed: u64, sample_rate_hz: u32, rms: f64) -> Self {
        Whistle {
            rng: ChaCha8Rng::seed_from_u64(seed),
            rate: f64::from(sample_rate_hz),
            amplitude: (rms * std::f64::consts::SQRT_2) as f32,
            phase: 0.0,
            gap_left: 0,
            burst_len: 1,
            burst_left: 0,
            from_hz: 2000.0,
            to_hz: 4000.0,
        }
    }

    /// Starts one burst now (for placing a whistle over a message).
    pub fn start_burst(&mut self, duration_s: f64, from_hz: f64, to_hz: f64) {
        self.burst_len = ((duration_s * self.rate) as usize).max(1);
        self.burst_left = self.burst_len;
        self.from_hz = from_hz;
        self.to_hz = to_hz;
        self.gap_left = usize::MAX / 2;
    }
}

impl Source for Whistle {
    fn add_to(&mut self, out: &mut [f32]) {
        for x in out {
            if self.burst_left == 0 {
                if self.gap_left > 0 {
                    self.gap_left -= 1;
                    continue;
                }
                let d = self.rng.random_range(0.2..1.5);
                let (a, b) = if self.rng.random_bool(0.5) {
                    (2000.0, 4000.0)
                } else {
                    (4000.0, 2000.0)
                };
                self.start_burst(d, a, b);
                self.gap_left = (self.rng.random_range(0.3..3.0) * self.rate) as usize;
            }
            let u = 1.0 - self.burst_left as f64 / self.burst_len as f64;
            self.burst_left -= 1;
            let warble = 1.0
                + 0.02
                    * (2.0 * std::f64::consts::PI * 25.0 * u * self.burst_len as f64 / self.rate)
                        .sin();
            let f = (self.from_hz + (self.to_hz - self.from_hz) * u) * warble;
            self.phase = (self.phase + f / self.rate).fract();
            let edge = (u.min(1.0 - u) * self.burst_len as f64 / (0.01 * self.rate)).min(1.0);
            *x += self.amplitude
                * edge as f32
                * (2.0 * std::f64::consts::PI * self.phase).sin() as f32;
        }
    }
}

/// Another team's tone codec: bursts of 1–8 equal tones, half the time on a 64-tone grid
/// of its own (600–3800 Hz), otherwise anywhere in 500–4000 Hz; 0.05–2 s long, 0.1–1 s
/// apart.
#[derive(Clone, Debug)]
pub struct ForeignTones {
    rng: ChaCha8Rng,
    rate: f64,
    rms: f64,
    tones: Vec<(f64, f64)>,
    amplitude: f32,
    burst_left: usize,
    burst_len: usize,
    gap_left: usize,
}

impl ForeignTones {
    /// Bursts whose total RMS amplitude is `rms` while sounding.
    pub fn new(seed: u64, sample_rate_hz: u32, rms: f64) -> Self {
        ForeignTones {
            rng: ChaCha8Rng::seed_from_u64(seed),
            rate: f64::from(sample_rate_hz),
            rms,
            tones: Vec::new(),
            amplitude: 0.0,
            burst_left: 0,
            burst_len: 1,
            gap_left: 0,
        }
    }

    fn next_burst(&mut self) {
        let n = self.rng.random_range(1..=8usize);
        let own_grid = self.rng.random_bool(0.5);
        self.tones = (0..n)
            .map(|_| {
                let f = if own_grid {
                    600.0 + 50.0 * f64::from(self.rng.random_range(0..64u32))
                } else {
                    self.rng.random_range(LOWEST_TONE_HZ..HIGHEST_TONE_HZ)
                };
                (f, self.rng.random_range(0.0..1.0))
            })
            .collect();
        self.amplitude = (self.rms * (2.0 / n as f64).sqrt()) as f32;
        self.burst_len = (self.rng.random_range(0.05..2.0) * self.rate) as usize;
        self.burst_left = self.burst_len;
        self.gap_left = (self.rng.random_range(0.1..1.0) * self.rate) as usize;
    }
}

impl Source for ForeignTones {
    fn add_to(&mut self, out: &mut [f32]) {
        for x in out {
            if self.burst_left == 0 {
                if self.gap_left > 0 {
                    self.gap_left -= 1;
                    continue;
                }
                self.next_burst();
            }
            self.burst_left -= 1;
            let mut s = 0.0;
            for (f, phase) in &mut self.tones {
                *phase = (*phase + *f / self.rate).fract();
                s += (2.0 * std::f64::consts::PI * *phase).sin();
            }
            let i = self.burst_len - self.burst_left;
            let edge = ((i.min(self.burst_left) as f64) / (0.005 * self.rate)).min(1.0);
            *x += self.amplitude * (edge * s) as f32;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sources_are_reproducible_and_at_their_level() {
        let mut a = vec![0.0f32; 64_000];
        let mut b = vec![0.0f32; 64_000];
        PinkNoise::new(7, 0.1).add_to(&mut a);
        PinkNoise::new(7, 0.1).add_to(&mut b);
        assert_eq!(a, b, "same seed, same noise");
        let rms = power(&a).sqrt();
        assert!((rms / 0.1 - 1.0).abs() < 0.25, "pink rms {rms}");
        let mut c = vec![0.0f32; 64_000];
        Babble::new(3, 16_000, 5, 0.05).add_to(&mut c);
        let rms = power(&c).sqrt();
        assert!((rms / 0.05 - 1.0).abs() < 0.5, "babble rms {rms}");
    }

    #[test]
    fn in_band_snr_definition() {
        // At 16 kHz the band 500–4000 Hz is 7/16 of 0–8 kHz.
        let s = white_sigma_for_in_band_snr(1.0, 0.0, 16_000);
        assert!((s * s * 3500.0 / 8000.0 - 1.0).abs() < 1e-12);
    }
}
