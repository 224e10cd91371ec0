//! Synthesis by inverse FFT, exact at any sample rate.
//!
//! Every tone `f_k = (35500 + 3500 k)/71` Hz makes a whole number of cycles in
//! `0.142 s`: `f_k · 0.142 = 71 + 7k`. So a period of `P = 0.142 · m` seconds, with `m`
//! the smallest integer making `P · rate` a whole number of samples
//! (`m = 500 / gcd(500, rate)`: 1 at 8/16/48 kHz, 5 at 44.1 kHz), puts every tone
//! *exactly* on an FFT bin of a `P · rate`-point inverse FFT. One IFFT gives one period;
//! tiling it is phase-continuous because every tone has whole cycles per period. There is
//! no frequency error from bin rounding and no overlap-add seam.
//!
//! Each tone's phase is `π k² / 72` (a Schroeder-like comb phase) on absolute time from
//! the message start, so the sender tones run on without a phase jump from the first frame
//! of a long message into the second, and six tones do not pile up into one tall peak.

use std::sync::Arc;

use rustfft::{num_complex::Complex, FftPlanner};

use crate::tones::{tone_frequency_hz, Frame, Message};

/// How to synthesise.
#[derive(Clone, Debug, PartialEq)]
pub struct EncoderConfig {
    /// Output sample rate, Hz (8000 … 192000).
    pub sample_rate_hz: u32,
    /// Duration of one frame (one short message), seconds.
    pub tone_duration_s: f64,
    /// Raised-cosine fade in and out of each frame, seconds.
    pub fade_s: f64,
    /// Peak level of the output, as a fraction of full scale (0 … 1].
    pub peak_level: f32,
}

impl Default for EncoderConfig {
    fn default() -> Self {
        EncoderConfig {
            sample_rate_hz: 16_000,
            tone_duration_s: 1.0,
            fade_s: 0.01,
            peak_level: 0.5,
        }
    }
}

/// Why an encoder configuration is refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EncoderConfigError {
    /// The rate must be 8000 … 192000 Hz: below 8 kHz the top tone (4 kHz) is above Nyquist.
    #[error("sample rate {0} Hz unsupported (8000..=192000)")]
    SampleRate(u32),
    /// The tone duration must be 0.02 … 10 s.
    #[error("tone duration {0} s unsupported (0.02..=10)")]
    ToneDuration(f64),
    /// The fade must be 0 … a quarter of the tone duration.
    #[error("fade {0} s must be between 0 and a quarter of the tone duration")]
    Fade(f64),
    /// The peak level must be in (0, 1].
    #[error("peak level {0} must be in (0, 1]")]
    PeakLevel(f32),
}

/// Turns messages into samples.
pub struct Encoder {
    config: EncoderConfig,
    period_samples: usize,
    /// Cycles of tone `k` per period.
    cycles: [usize; crate::tones::TONE_COUNT],
    ifft: Arc<dyn rustfft::Fft<f32>>,
}

impl std::fmt::Debug for Encoder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Encoder")
            .field("config", &self.config)
            .field("period_samples", &self.period_samples)
            .finish()
    }
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

impl Encoder {
    /// An encoder for `config`.
    pub fn new(config: EncoderConfig) -> Result<Encoder, EncoderConfigError> {
        if !(8_000..=192_000).contains(&config.sample_rate_hz) {
            return Err(EncoderConfigError::SampleRate(config.sample_rate_hz));
        }
        if !(0.02..=10.0).contains(&config.tone_duration_s) {
            return Err(EncoderConfigError::ToneDuration(config.tone_duration_s));
        }
        if !(0.0..=config.tone_duration_s / 4.0).contains(&config.fade_s) {
            return Err(EncoderConfigError::Fade(config.fade_s));
        }
        if !(config.peak_level > 0.0 && config.peak_level <= 1.0) {
            return Err(EncoderConfigError::PeakLevel(config.peak_level));
        }
        let rate = u64::from(config.sample_rate_hz);
        let m = 500 / gcd(500, rate);
        // P = 0.142 m s = 71 m / 500 s; samples = rate · 71 m / 500, whole by choice of m.
        let period_samples = (rate * 71 * m / 500) as usize;
        let mut cycles = [0; crate::tones::TONE_COUNT];
        for (k, c) in cycles.iter_mut().enumerate() {
            *c = (71 + 7 * k) * m as usize;
            debug_assert!(
                ((*c as f64) * rate as f64 / period_samples as f64 - tone_frequency_hz(k)).abs()
                    < 1e-6
            );
        }
        let ifft = FftPlanner::<f32>::new().plan_fft_inverse(period_samples);
        Ok(Encoder {
            config,
            period_samples,
            cycles,
            ifft,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &EncoderConfig {
        &self.config
    }

    /// Samples in one frame (one short message).
    pub fn frame_samples(&self) -> usize {
        (self.config.tone_duration_s * f64::from(self.config.sample_rate_hz)).round() as usize
    }

    /// Samples in `message`.
    pub fn message_samples(&self, message: &Message) -> usize {
        self.frame_samples() * message.frames().len()
    }

    /// One period of the six tones of `frame`, unit amplitude per tone.
    fn period(&self, frame: &Frame) -> Vec<f32> {
        let n = self.period_samples;
        let mut spectrum = vec![Complex::new(0.0f32, 0.0); n];
        for k in frame.tones() {
            let c = self.cycles[k];
            let phase = std::f64::consts::PI * (k * k) as f64 / 72.0;
            if 2 * c == n {
                // The Nyquist bin (4 kHz at 8 kHz) holds a real cosine only.
                spectrum[c] += Complex::new((n as f64 * phase.cos()) as f32, 0.0);
            } else {
                let half = n as f64 / 2.0;
                let z = Complex::new((half * phase.cos()) as f32, (half * phase.sin()) as f32);
                spectrum[c] += z;
                spectrum[n - c] += z.conj();
            }
        }
        self.ifft.process(&mut spectrum);
        // rustfft does not normalise: the inverse of X is n · x.
        spectrum.iter().map(|z| z.re / n as f32).collect()
    }

    /// `message` as f32 samples in [-1, 1].
    pub fn encode_f32(&self, message: &Message) -> Vec<f32> {
        let frame_len = self.frame_samples();
        let fade_len =
            (self.config.fade_s * f64::from(self.config.sample_rate_hz)).round() as usize;
        let mut out = Vec::with_capacity(self.message_samples(message));
        let periods: Vec<Vec<f32>> = message.frames().iter().map(|f| self.period(f)).collect();
        // One gain for the whole message, set by its peakiest frame, so a tone sounding in
        // both frames of a long message keeps its level.
        let peak = periods
            .iter()
            .flatten()
            .fold(0.0f32, |m, x| m.max(x.abs()))
            .max(1e-9);
        let gain = self.config.peak_level / peak;
        for period in &periods {
            for i in 0..frame_len {
                // Absolute sample index keeps every tone's phase continuous across frames.
                let n = out.len();
                let mut x = period[n % self.period_samples] * gain;
                let edge = i.min(frame_len - 1 - i);
                if edge < fade_len {
                    let u = (edge as f32 + 0.5) / fade_len as f32;
                    x *= 0.5 - 0.5 * (std::f32::consts::PI * u).cos();
                }
                out.push(x);
            }
        }
        out
    }

    /// `message` as 16-bit PCM samples.
    pub fn encode_i16(&self, message: &Message) -> Vec<i16> {
        self.encode_f32(message)
            .into_iter()
            .map(crate::pcm::f32_to_i16)
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tones::Sender;

    /// Power of `x` at `freq_hz` by direct correlation, normalised to amplitude².
    fn tone_amplitude(x: &[f32], rate: f64, freq_hz: f64) -> f64 {
        let (mut c, mut s) = (0.0, 0.0);
        for (n, &v) in x.iter().enumerate() {
            let ph = 2.0 * std::f64::consts::PI * freq_hz * n as f64 / rate;
            c += v as f64 * ph.cos();
            s += v as f64 * ph.sin();
        }
        2.0 * (c * c + s * s).sqrt() / x.len() as f64
    }

    #[test]
    fn tones_land_exactly_on_the_plan_at_44_1_khz() {
        // 44.1 kHz is the awkward rate: f_k is not on a bin of any power-of-two FFT.
        let enc = Encoder::new(EncoderConfig {
            sample_rate_hz: 44_100,
            fade_s: 0.0,
            ..EncoderConfig::default()
        })
        .unwrap();
        let frame = Frame {
            sender: Sender::Goalkeeper,
            data: 20,
        };
        let x = enc.encode_f32(&Message::short(frame.sender, frame.data).unwrap());
        let on = tone_amplitude(&x, 44_100.0, tone_frequency_hz(71));
        // 1 Hz off the exact frequency over 1 s, a correlation falls to zero:
        // energy there would mean the tone is not where the plan says.
        let off = tone_amplitude(&x, 44_100.0, tone_frequency_hz(71) + 1.0);
        assert!(on > 0.05, "tone 71 amplitude {on}");
        assert!(
            off < on * 1e-3,
            "tone 71 spread off-frequency: on {on}, 1 Hz off {off}"
        );
        let absent = tone_amplitude(&x, 44_100.0, tone_frequency_hz(30));
        // Only the rectangular-window sidelobes of tones ≥ 296 Hz away remain.
        assert!(
            absent < on * 3e-3,
            "tone 30 should be silent: {absent} vs {on}"
        );
    }

    #[test]
    fn long_message_is_two_frames_and_respects_peak_level() {
        let enc = Encoder::new(EncoderConfig::default()).unwrap();
        let m = Message::long(Sender::LeftAttacker, 300).unwrap();
        let x = enc.encode_f32(&m);
        assert_eq!(x.len(), 32_000);
        let peak = x.iter().fold(0.0f32, |a, v| a.max(v.abs()));
        assert!((peak - 0.5).abs() < 0.01, "peak {peak}");
        assert!(
            x[0].abs() < 0.01,
            "fade-in must start near zero, got {}",
            x[0]
        );
    }

    #[test]
    fn bad_configs_are_refused() {
        let bad = |c: EncoderConfig| Encoder::new(c).is_err();
        assert!(bad(EncoderConfig {
            sample_rate_hz: 4_000,
            ..Default::default()
        }));
        assert!(bad(EncoderConfig {
            tone_duration_s: 0.0,
            ..Default::default()
        }));
        assert!(bad(EncoderConfig {
            fade_s: 0.5,
            ..Default::default()
        }));
        assert!(bad(EncoderConfig {
            peak_level: 1.5,
            ..Default::default()
        }));
    }
}
