//! A reverberant hall: a seeded room impulse response (image-source early reflections of a
//! shoebox room plus an exponentially decaying diffuse tail with a given T60) behind a
//! loudspeaker/microphone band limit of about 300–6000 Hz, applied by FFT overlap-add.
//!
//! The direct-to-reverberant ratio follows Sabine's critical distance
//! `r_c = 0.057 · √(V / T60)` for the room's volume and the source–microphone distance,
//! so a long T60 in a hall of a given size means more reverberant energy, as in a real
//! hall. Room size, positions and the tail's fine structure all come from the seed.

use std::sync::Arc;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use rustfft::{num_complex::Complex, Fft, FftPlanner};

const SPEED_OF_SOUND: f64 = 343.0;

/// A seeded room: everything that shapes its impulse response.
#[derive(Clone, Debug, PartialEq)]
pub struct RoomSpec {
    /// Seed of the geometry and the diffuse tail.
    pub seed: u64,
    /// Reverberation time (energy decays by 60 dB), s.
    pub t60_s: f64,
    /// Sample rate, Hz.
    pub sample_rate_hz: u32,
    /// Lower and upper band edge of loudspeaker and microphone, Hz.
    pub band_hz: (f64, f64),
}

impl RoomSpec {
    /// A hall with reverberation time `t60_s`, band-limited to 300–6000 Hz.
    pub fn hall(seed: u64, t60_s: f64, sample_rate_hz: u32) -> Self {
        RoomSpec {
            seed,
            t60_s,
            sample_rate_hz,
            band_hz: (300.0, 6000.0),
        }
    }

    /// The impulse response, normalised to unit energy (so the received power equals the
    /// sent power on average). Its length is 1.2 · T60 (the tail is −72 dB there).
    pub fn impulse_response(&self) -> Vec<f32> {
        let rate = f64::from(self.sample_rate_hz);
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed ^ 0x700d_face);
        // A hall 15–45 m long, 10–30 m wide, 5–12 m high; source and microphone 2–12 m
        // apart, at robot height.
        let dims = [
            rng.random_range(15.0..45.0),
            rng.random_range(10.0..30.0),
            rng.random_range(5.0..12.0),
        ];
        let volume: f64 = dims.iter().product();
        let place = |rng: &mut ChaCha8Rng| {
            [
                rng.random_range(2.0..dims[0] - 2.0),
                rng.random_range(2.0..dims[1] - 2.0),
                rng.random_range(0.2..0.8),
            ]
        };
        let src = place(&mut rng);
        let mut mic = place(&mut rng);
        let distance = |a: [f64; 3], b: [f64; 3]| {
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        };
        let wanted = rng.random_range(2.0..12.0f64);
        // Move the microphone along the line from the source to the wanted distance
        // (clamped into the room).
        let d0 = distance(src, mic).max(0.1);
        for i in 0..3 {
            mic[i] = (src[i] + (mic[i] - src[i]) * wanted / d0).clamp(0.1, dims[i] - 0.1);
        }
        let direct = distance(src, mic).max(0.5);
        let t60 = self.t60_s.max(0.05);
        let len = ((1.2 * t60 + direct / SPEED_OF_SOUND) * rate) as usize + 1;
        let mut h = vec![0.0f64; len];
        // Energy decay: amplitude e^{-6.91 t / T60}.
        let decay = 6.91 / t60;
        // Wall reflection coefficient that gives this T60 by Sabine/Eyring:
        // T60 = 0.161 V / (−S ln(1 − α)).
        let surface = 2.0 * (dims[0] * dims[1] + dims[0] * dims[2] + dims[1] * dims[2]);
        let alpha = 1.0 - (-0.161 * volume / (surface * t60)).exp();
        let beta = (1.0 - alpha).max(0.0).sqrt();
        // Image sources up to order 3 (fractional delays by linear split between taps).
        let add_tap = |h: &mut [f64], delay_s: f64, gain: f64| {
            let p = delay_s * rate;
            let i = p.floor() as usize;
            let f = p - i as f64;
            if i + 1 < h.len() {
                h[i] += gain * (1.0 - f);
                h[i + 1] += gain * f;
            }
        };
        let order = 3i32;
        for nx in -order..=order {
            for ny in -order..=order {
                for nz in -order..=order {
                    let n = nx.abs() + ny.abs() + nz.abs();
                    if n > order {
                        continue;
                    }
                    let image = |n: i32, s: f64, l: f64| {
                        if n % 2 == 0 {
                            f64::from(n) * l + s
                        } else {
                            f64::from(n + 1) * l - s
                        }
                    };
                    let img = [
                        image(nx, src[0], dims[0]),
                        image(ny, src[1], dims[1]),
                        image(nz, src[2], dims[2]),
                    ];
                    let r = distance(img, mic).max(0.5);
                    add_tap(&mut h, r / SPEED_OF_SOUND, beta.powi(n) * direct / r);
                }
            }
        }
        // The diffuse tail, from the mixing time on, with the energy Sabine's critical
        // distance gives relative to the direct sound: E_rev / E_dir = (direct / r_c)².
        let critical = 0.057 * (volume / t60).sqrt();
        let reverberant_energy = (direct / critical).powi(2);
        let t_start = direct / SPEED_OF_SOUND;
        let t_mix = t_start + (0.002 * volume.sqrt()).clamp(0.01, 0.08);
        let mut tail = vec![0.0f64; len];
        let mut tail_energy = 0.0;
        for (i, v) in tail.iter_mut().enumerate() {
            let t = i as f64 / rate;
            if t < t_start {
                continue;
            }
            // Fade in from the direct sound to the mixing time (early reflections thicken).
            let ramp = ((t - t_start) / (t_mix - t_start)).min(1.0);
            let n: f64 = StandardNormal.sample(&mut rng);
            *v = n * ramp * (-decay * (t - t_start)).exp();
            tail_energy += *v * *v;
        }
        let tail_gain = (reverberant_energy / tail_energy.max(1e-30)).sqrt();
        for (a, b) in h.iter_mut().zip(&tail) {
            *a += tail_gain * b;
        }
        let mut h: Vec<f32> = h.into_iter().map(|v| v as f32).collect();
        band_limit(&mut h, rate, self.band_hz);
        let energy: f64 = h.iter().map(|&v| f64::from(v) * f64::from(v)).sum();
        let g = (1.0 / energy.max(1e-30)).sqrt() as f32;
        h.iter_mut().for_each(|v| *v *= g);
        h
    }
}

/// Loudspeaker and microphone: 4th-order Butterworth-like high-pass and low-pass
/// (two cascaded 2nd-order sections each), applied in place.
pub fn band_limit(x: &mut [f32], rate: f64, (low_hz, high_hz): (f64, f64)) {
    for _ in 0..2 {
        Biquad::high_pass(low_hz, rate).run(x);
        Biquad::low_pass(high_hz.min(0.45 * rate), rate).run(x);
    }
}

/// An RBJ biquad.
struct Biquad {
    b: [f64; 3],
    a: [f64; 2],
}

impl Biquad {
    fn design(f0: f64, rate: f64, high: bool) -> Biquad {
        let w = 2.0 * std::f64::consts::PI * f0 / rate;
        let alpha = w.sin() / (2.0 * std::f64::consts::FRAC_1_SQRT_2);
        let c = w.cos();
        let a0 = 1.0 + alpha;
        let (b0, b1) = if high {
            ((1.0 + c) / 2.0, -(1.0 + c))
        } else {
            ((1.0 - c) / 2.0, 1.0 - c)
        };
        Biquad {
            b: [b0 / a0, b1 / a0, b0 / a0],
            a: [-2.0 * c / a0, (1.0 - alpha) / a0],
        }
    }
    fn high_pass(f0: f64, rate: f64) -> Biquad {
        Biquad::design(f0, rate, true)
    }
    fn low_pass(f0: f64, rate: f64) -> Biquad {
        Biquad::design(f0, rate, false)
    }
    fn run(&self, x: &mut [f32]) {
        let (mut x1, mut x2, mut y1, mut y2) = (0.0, 0.0, 0.0, 0.0);
        for v in x {
            let x0 = f64::from(*v);
            let y0 =
                self.b[0] * x0 + self.b[1] * x1 + self.b[2] * x2 - self.a[0] * y1 - self.a[1] * y2;
            x2 = x1;
            x1 = x0;
            y2 = y1;
            y1 = y0;
            *v = y0 as f32;
        }
    }
}

/// Streaming convolution with a fixed impulse response by uniformly partitioned FFT
/// overlap-add: push blocks of any size, get the same number of samples out, the
/// convolution delayed by [`Convolver::latency`].
pub struct Convolver {
    block: usize,
    fft: Arc<dyn Fft<f32>>,
    ifft: Arc<dyn Fft<f32>>,
    /// Spectra of the impulse response's partitions (uniformly partitioned).
    h_parts: Vec<Vec<Complex<f32>>>,
    /// Spectra of the last input blocks, newest first.
    x_parts: std::collections::VecDeque<Vec<Complex<f32>>>,
    /// Input gathered for the current block.
    pending: Vec<f32>,
    /// The overlap (second half) of the last block's output.
    overlap: Vec<f32>,
    /// Output ready to hand out.
    ready: std::collections::VecDeque<f32>,
    /// The accumulator of one block's product of spectra.
    scratch: Vec<Complex<f32>>,
}

impl std::fmt::Debug for Convolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Convolver")
            .field("block", &self.block)
            .field("parts", &self.h_parts.len())
            .finish()
    }
}

impl Convolver {
    /// A convolver for `h` (uniformly partitioned in blocks of 4096 samples).
    pub fn new(h: &[f32]) -> Self {
        let block = 4096usize;
        let mut planner = FftPlanner::new();
        let fft = planner.plan_fft_forward(2 * block);
        let ifft = planner.plan_fft_inverse(2 * block);
        let h_parts: Vec<Vec<Complex<f32>>> = h
            .chunks(block)
            .map(|c| {
                let mut buf = vec![Complex::new(0.0, 0.0); 2 * block];
                for (b, &v) in buf.iter_mut().zip(c) {
                    b.re = v;
                }
                fft.process(&mut buf);
                buf
            })
            .collect();
        Convolver {
            block,
            fft,
            ifft,
            x_parts: std::collections::VecDeque::new(),
            h_parts,
            pending: Vec::with_capacity(block),
            overlap: vec![0.0; block],
            ready: std::collections::VecDeque::new(),
            scratch: vec![Complex::new(0.0, 0.0); 2 * block],
        }
    }

    fn run_block(&mut self) {
        let n = 2 * self.block;
        let mut x = vec![Complex::new(0.0, 0.0); n];
        for (b, &v) in x.iter_mut().zip(&self.pending) {
            b.re = v;
        }
        self.pending.clear();
        self.fft.process(&mut x);
        self.x_parts.push_front(x);
        self.x_parts.truncate(self.h_parts.len());
        let acc = &mut self.scratch;
        acc.iter_mut().for_each(|c| *c = Complex::new(0.0, 0.0));
        for (xp, hp) in self.x_parts.iter().zip(&self.h_parts) {
            for ((a, &xv), &hv) in acc.iter_mut().zip(xp).zip(hp) {
                *a += xv * hv;
            }
        }
        self.ifft.process(acc);
        let scale = 1.0 / n as f32;
        for i in 0..self.block {
            self.ready.push_back(acc[i].re * scale + self.overlap[i]);
            self.overlap[i] = acc[i + self.block].re * scale;
        }
    }

    /// Convolves `x` in place, [`Convolver::latency`] samples late (a block is
    /// transformed once it is full).
    pub fn process(&mut self, x: &mut [f32]) {
        for v in x.iter_mut() {
            self.pending.push(*v);
            if self.pending.len() == self.block {
                self.run_block();
            }
            *v = self.ready.pop_front().unwrap_or(0.0);
        }
    }

    /// The latency of [`Convolver::process`], samples: output sample `i` is the
    /// convolution's sample `i − latency`.
    pub fn latency(&self) -> usize {
        self.block - 1
    }
}

/// Mean power of `x` inside `low_hz … high_hz` (by FFT, with `x` treated as periodic).
pub fn in_band_power(x: &[f32], rate: f64, low_hz: f64, high_hz: f64) -> f64 {
    let n = x.len();
    if n == 0 {
        return 0.0;
    }
    let mut buf: Vec<Complex<f32>> = x.iter().map(|&v| Complex::new(v, 0.0)).collect();
    FftPlanner::new().plan_fft_forward(n).process(&mut buf);
    let mut sum = 0.0f64;
    for (i, c) in buf.iter().enumerate() {
        let f = i.min(n - i) as f64 * rate / n as f64;
        if (low_hz..=high_hz).contains(&f) {
            sum += f64::from(c.norm_sqr());
        }
    }
    sum / (n as f64 * n as f64)
}
