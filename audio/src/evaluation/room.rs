//! Messages played into a reverberant hall ([`RoomSpec`]): each message from a sender
//! whose clock is off by up to ±0.5%, through the room's impulse response and the
//! loudspeaker/microphone band limit, with white noise at the microphone or babble from
//! talkers elsewhere in the same hall (through their own impulse response).
//!
//! In-band SNR here is the sent message's mean power (the impulse response has unit
//! energy, so that is also the received power on average) over the noise power at the
//! microphone inside 500–4000 Hz.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::{
    finish_and_score, random_message, shifted, Sent, SnrOutcome, TrialError, SIGNAL_POWER,
};
use crate::channel::{in_band_power, Babble, Convolver, RoomSpec, Source, WhiteNoise};
use crate::decoder::{Decoder, DecoderConfig};
use crate::encoder::{Encoder, EncoderConfig};
use crate::tones::{HIGHEST_TONE_HZ, LOWEST_TONE_HZ};

/// The background of a room trial.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RoomNoise {
    /// Gaussian white noise at the microphone (not reverberant).
    White,
    /// Six synthetic talkers elsewhere in the hall, reverberant like the message.
    Babble,
}

impl RoomNoise {
    /// Short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            RoomNoise::White => "white",
            RoomNoise::Babble => "babble",
        }
    }
}

/// What to send through a room.
#[derive(Clone, Debug)]
pub struct RoomTrial {
    /// Seed of the room, messages, clocks, gaps and noise.
    pub seed: u64,
    /// Reverberation time of the hall, s.
    pub t60_s: f64,
    /// In-band SNR at the microphone, dB.
    pub snr_db: f64,
    /// The background.
    pub noise: RoomNoise,
    /// Messages to send.
    pub messages: usize,
    /// Share of long messages (0 … 1).
    pub long_share: f64,
    /// Largest sender clock error; each message draws one uniformly in ± this.
    pub max_clock_error: f64,
    /// Decoder configuration (its rate must be the trial's, 16 kHz by default).
    pub decoder: DecoderConfig,
}

impl RoomTrial {
    /// The standard row: short messages, 1 s tones, 16 kHz, clocks off by up to ±0.5%.
    pub fn new(seed: u64, t60_s: f64, snr_db: f64, noise: RoomNoise, messages: usize) -> Self {
        RoomTrial {
            seed,
            t60_s,
            snr_db,
            noise,
            messages,
            long_share: 0.0,
            max_clock_error: 0.005,
            decoder: DecoderConfig::default(),
        }
    }
}

/// A noise source heard through a room (or not), at a gain set for an in-band level.
struct RoomBackground {
    source: Box<dyn Source>,
    room: Option<Convolver>,
    gain: f32,
}

impl RoomBackground {
    fn new(noise: RoomNoise, seed: u64, t60_s: f64, rate: u32, in_band_target: f64) -> Self {
        match noise {
            RoomNoise::White => {
                let sigma = crate::channel::white_sigma_for_in_band_snr(in_band_target, 0.0, rate);
                RoomBackground {
                    source: Box::new(WhiteNoise::new(seed, sigma)),
                    room: None,
                    gain: 1.0,
                }
            }
            RoomNoise::Babble => {
                let babble = Babble::new(seed, rate, 6, 0.1);
                let h = RoomSpec::hall(seed ^ 0xbabb1e, t60_s, rate).impulse_response();
                // Calibrate on a copy: 20 s after the room has filled.
                let mut probe = babble.clone();
                let mut probe_room = Convolver::new(&h);
                let warm = (t60_s * 1.5 * f64::from(rate)) as usize + probe_room.latency();
                let mut x = vec![0.0f32; warm + 20 * rate as usize];
                probe.add_to(&mut x);
                probe_room.process(&mut x);
                let p = in_band_power(&x[warm..], f64::from(rate), LOWEST_TONE_HZ, HIGHEST_TONE_HZ);
                RoomBackground {
                    source: Box::new(babble),
                    room: Some(Convolver::new(&h)),
                    gain: (in_band_target / p.max(1e-30)).sqrt() as f32,
                }
            }
        }
    }

    fn add_to(&mut self, out: &mut [f32]) {
        let mut x = vec![0.0f32; out.len()];
        self.source.add_to(&mut x);
        if let Some(room) = self.room.as_mut() {
            room.process(&mut x);
        }
        for (o, v) in out.iter_mut().zip(&x) {
            *o += self.gain * v;
        }
    }
}

/// Sends `trial.messages` random messages through the room and its noise.
pub fn run_room_trial(trial: &RoomTrial) -> Result<SnrOutcome, TrialError> {
    let mut rng = ChaCha8Rng::seed_from_u64(trial.seed);
    let rate = trial.decoder.sample_rate_hz;
    let tone_s = trial.decoder.tone_duration_s;
    let rate_f = f64::from(rate);
    let encoder = Encoder::new(EncoderConfig {
        sample_rate_hz: rate,
        tone_duration_s: tone_s,
        fade_s: (tone_s / 20.0).min(0.01),
        ..EncoderConfig::default()
    })?;
    let mut decoder = Decoder::new(trial.decoder.clone())?;
    let h = RoomSpec::hall(trial.seed, trial.t60_s, rate).impulse_response();
    let peak = h.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    let arrival = h.iter().position(|v| v.abs() >= 0.3 * peak).unwrap_or(0);
    let mut room = Convolver::new(&h);
    let delay = (room.latency() + arrival) as f64 / rate_f;
    let noise_power = SIGNAL_POWER / 10f64.powf(trial.snr_db / 10.0);
    let mut background = RoomBackground::new(
        trial.noise,
        trial.seed ^ 0x5eed,
        trial.t60_s,
        rate,
        noise_power,
    );
    let mut sent = Vec::with_capacity(trial.messages);
    let mut out = SnrOutcome::default();
    let mut detections = Vec::new();
    let mut t_samples = 0u64;
    // Lead-in: the room and the noise floor settle.
    let mut segments: Vec<(usize, Option<crate::tones::Message>)> = vec![(2 * rate as usize, None)];
    for _ in 0..trial.messages {
        let gap_s = rng.random_range(0.6..1.4) * tone_s.max(0.25);
        segments.push((
            (gap_s * rate_f) as usize,
            Some(random_message(
                &mut rng,
                trial.long_share,
                trial.decoder.team,
            )),
        ));
    }
    segments.push((
        2 * rate as usize + ((2.5 * tone_s + 1.5 * trial.t60_s) * rate_f) as usize,
        None,
    ));
    for (gap, message) in segments {
        let mut block = vec![0.0f32; gap];
        if let Some(m) = message {
            let error = rng.random_range(-1.0..=1.0) * trial.max_clock_error;
            let x = shifted(&encoder, &m, error);
            let gain = (SIGNAL_POWER / crate::channel::power(&x).max(1e-20)).sqrt() as f32;
            let start = t_samples + gap as u64;
            sent.push(Sent {
                message: m,
                start_s: start as f64 / rate_f + delay,
                end_s: (start + x.len() as u64) as f64 / rate_f + delay,
                matched: false,
            });
            out.sent += 1;
            block.extend(x.iter().map(|v| v * gain));
        }
        room.process(&mut block);
        background.add_to(&mut block);
        t_samples += block.len() as u64;
        for chunk in block.chunks(rate as usize) {
            decoder.push_f32(chunk);
            while let Some(d) = decoder.poll_message() {
                detections.push(d);
            }
        }
    }
    finish_and_score(&mut decoder, detections, &mut sent, &mut out);
    out.samples = t_samples;
    Ok(out)
}

/// False messages heard in `hours` of reverberant babble (six talkers through a hall of
/// reverberation time `t60_s`) at 16 kHz with the default decoder.
pub fn run_room_false_alarm_trial(t60_s: f64, hours: f64, seed: u64) -> super::FalseAlarmOutcome {
    let rate = 16_000u32;
    let mut decoder = Decoder::new(DecoderConfig::default()).expect("the default config is valid");
    let mut background = RoomBackground::new(RoomNoise::Babble, seed, t60_s, rate, SIGNAL_POWER);
    let total = (hours * 3600.0 * f64::from(rate)) as u64;
    let mut done = 0u64;
    let mut detections = Vec::new();
    let mut block = vec![0.0f32; rate as usize];
    while done < total {
        let n = (total - done).min(u64::from(rate)) as usize;
        block.truncate(n);
        block.iter_mut().for_each(|x| *x = 0.0);
        background.add_to(&mut block);
        decoder.push_f32(&block);
        detections.extend(std::iter::from_fn(|| decoder.poll_message()));
        done += n as u64;
    }
    decoder.finish();
    detections.extend(std::iter::from_fn(|| decoder.poll_message()));
    super::FalseAlarmOutcome {
        hours,
        false_messages: detections.len(),
        detections,
        samples: done,
    }
}
