//! Seeded robustness trials behind `huddle audio eval`: messages through noise at a set
//! in-band SNR, hours of interference with no message, a whistle over messages. Each
//! trial streams its audio through one [`Decoder`] in one-second blocks (memory stays
//! flat for any length) and scores what comes out. No clock is read here: the caller
//! times a trial if it wants a speed.

mod backgrounds;
mod oracle;
mod room;
mod scene;

pub use backgrounds::{
    run_background_false_alarm_trial, run_background_false_alarm_trial_traced, Background,
};
pub use oracle::OracleVerdict;
pub use room::{run_room_false_alarm_trial, run_room_trial, RoomNoise, RoomTrial};
pub use scene::{
    load_room_set, run_scene_false_alarm_trial, run_scene_trial, run_scene_trial_traced,
    run_scene_trial_with_oracle, ExternalRoom, RoomSet, RoomSetError, SceneOutcome, SceneTrial,
    ROOM_SET_RATE_HZ,
};

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::channel::{
    power, white_sigma_for_in_band_snr, Babble, ForeignTones, PinkNoise, Source, Whistle,
    WhiteNoise,
};
use crate::decoder::{Decoder, DecoderConfig, DecoderConfigError, Detection};
use crate::encoder::{Encoder, EncoderConfig, EncoderConfigError};
use crate::team::{TeamMessage, TeamPlan};
use crate::tones::{Message, Sender, DATA_VALUES, LONG_VALUES};

/// Why a trial cannot run.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrialError {
    /// The rate or tone duration is not one the encoder accepts.
    #[error(transparent)]
    Encoder(#[from] EncoderConfigError),
    /// The rate or tone duration is not one the decoder accepts.
    #[error(transparent)]
    Decoder(#[from] DecoderConfigError),
}

/// Mean power every test message is scaled to (RMS 0.1).
const SIGNAL_POWER: f64 = 0.01;

/// What to send through noise.
#[derive(Clone, Debug)]
pub struct SnrTrial {
    /// Seed of messages, gaps and noise.
    pub seed: u64,
    /// In-band SNR, dB (signal power over white-noise power inside 500–4000 Hz).
    pub snr_db: f64,
    /// Messages to send.
    pub messages: usize,
    /// Tone duration, s.
    pub tone_duration_s: f64,
    /// Sample rate, Hz.
    pub sample_rate_hz: u32,
    /// Share of long messages (0 … 1).
    pub long_share: f64,
    /// Frequency error of the sender (e.g. 0.004 = 0.4% sharp).
    pub frequency_error: f64,
}

/// Outcome of an [`SnrTrial`].
#[derive(Clone, Debug, Default)]
pub struct SnrOutcome {
    /// Messages sent.
    pub sent: usize,
    /// Decoded right (the report overlaps the sent message and says the same).
    pub correct: usize,
    /// Reported over a sent message, but a different message.
    pub wrong: usize,
    /// Reported where nothing was sent (or a second report of one message).
    pub spurious: usize,
    /// Delay from each correct message's end to its report, s.
    pub delays_s: Vec<f64>,
    /// |reported start − true start| of each correct message, s.
    pub start_errors_s: Vec<f64>,
    /// Samples decoded.
    pub samples: u64,
    /// Each message not decoded right, with its start and end (s, as heard), for
    /// diagnosis.
    pub missed: Vec<(Message, f64, f64)>,
}

impl SnrOutcome {
    /// Share decoded correctly.
    pub fn correct_share(&self) -> f64 {
        self.correct as f64 / self.sent.max(1) as f64
    }
    /// Share decoded wrongly.
    pub fn wrong_share(&self) -> f64 {
        self.wrong as f64 / self.sent.max(1) as f64
    }
}

/// Es/N0 of one short message (all six tones over one tone duration) for an in-band SNR:
/// `Es = P·T`, `N0 = P_noise,in-band / 3500 Hz`.
pub fn es_n0_db(snr_db: f64, tone_duration_s: f64) -> f64 {
    snr_db + 10.0 * (3500.0 * tone_duration_s).log10()
}

fn random_message(rng: &mut ChaCha8Rng, long_share: f64, team: TeamPlan) -> Message {
    if team != TeamPlan::Three {
        let robot = rng.random_range(0..team.robots());
        let long = rng.random_bool(long_share.clamp(0.0, 1.0));
        let max = if long {
            team.long_values()
        } else {
            team.short_values()
        };
        let value = rng.random_range(0..max);
        return team
            .encode(TeamMessage { robot, long, value })
            .expect("drawn within the plan");
    }
    let sender = Sender::ALL[rng.random_range(0..3usize)];
    if rng.random_bool(long_share.clamp(0.0, 1.0)) {
        Message::Long {
            sender,
            value: rng.random_range(0..LONG_VALUES),
        }
    } else {
        Message::Short {
            sender,
            data: rng.random_range(0..DATA_VALUES),
        }
    }
}

/// A sent message's place in the stream.
#[derive(Clone, Copy, Debug)]
struct Sent {
    message: Message,
    start_s: f64,
    end_s: f64,
    matched: bool,
}

fn score(sent: &mut [Sent], d: &Detection, out: &mut SnrOutcome) {
    // A report belongs to the sent message its span overlaps most.
    let overlap = |s: &Sent| (d.end_s.min(s.end_s) - d.start_s.max(s.start_s)).max(0.0);
    let hit = sent
        .iter_mut()
        .filter(|s| overlap(s) > 0.0)
        .max_by(|a, b| overlap(a).total_cmp(&overlap(b)));
    match hit {
        Some(s) if !s.matched && s.message == d.message => {
            s.matched = true;
            out.correct += 1;
            out.delays_s.push(d.decided_at_s - s.end_s);
            out.start_errors_s.push((d.start_s - s.start_s).abs());
        }
        Some(s) if !s.matched => {
            s.matched = true;
            out.wrong += 1;
        }
        _ => out.spurious += 1,
    }
}

/// Ends the stream, collects what the decoder still holds, then scores every detection
/// against what was sent (scoring after the end, so a late report still counts).
fn finish_and_score(
    decoder: &mut Decoder,
    mut detections: Vec<Detection>,
    sent: &mut [Sent],
    out: &mut SnrOutcome,
) {
    decoder.finish();
    while let Some(d) = decoder.poll_message() {
        detections.push(d);
    }
    for d in &detections {
        score(sent, d, out);
    }
    out.missed = sent
        .iter()
        .filter(|s| !s.matched)
        .map(|s| (s.message, s.start_s, s.end_s))
        .collect();
}

/// Sends `trial.messages` random messages separated by random gaps through white noise.
pub fn run_snr_trial(trial: &SnrTrial) -> Result<SnrOutcome, TrialError> {
    run_snr_trial_team(trial, TeamPlan::Three)
}

/// [`run_snr_trial`] with messages of the team plan `team`, decoded under it.
pub fn run_snr_trial_team(trial: &SnrTrial, team: TeamPlan) -> Result<SnrOutcome, TrialError> {
    let mut rng = ChaCha8Rng::seed_from_u64(trial.seed);
    let rate = trial.sample_rate_hz;
    let encoder = Encoder::new(EncoderConfig {
        sample_rate_hz: rate,
        tone_duration_s: trial.tone_duration_s,
        fade_s: (trial.tone_duration_s / 20.0).min(0.01),
        ..EncoderConfig::default()
    })?;
    let mut decoder = Decoder::new(DecoderConfig {
        sample_rate_hz: rate,
        tone_duration_s: trial.tone_duration_s,
        team,
        ..DecoderConfig::default()
    })?;
    let sigma = white_sigma_for_in_band_snr(SIGNAL_POWER, trial.snr_db, rate);
    let mut noise = WhiteNoise::new(trial.seed ^ 0x5eed, sigma);
    let mut sent = Vec::with_capacity(trial.messages);
    let mut out = SnrOutcome::default();
    let mut t_samples = 0u64;
    let rate_f = f64::from(rate);
    let mut detections = Vec::new();
    // Lead-in noise lets the noise floor settle, as on a robot that listens all the time.
    let mut segments: Vec<(usize, Option<Message>)> = vec![(rate as usize, None)];
    for _ in 0..trial.messages {
        // A robot leaves more than half a tone of silence between its messages: frames
        // closer than that are, by the protocol, one long message (see `decoder`).
        let gap_s = rng.random_range(0.6..1.4) * trial.tone_duration_s.max(0.25);
        segments.push((
            (gap_s * rate_f) as usize,
            Some(random_message(&mut rng, trial.long_share, team)),
        ));
    }
    segments.push((
        2 * rate as usize + (2.5 * trial.tone_duration_s * rate_f) as usize,
        None,
    ));
    for (gap, message) in segments {
        let mut block = vec![0.0f32; gap];
        if let Some(m) = message {
            let x = if trial.frequency_error != 0.0 {
                shifted(&encoder, &m, trial.frequency_error)
            } else {
                encoder.encode_f32(&m)
            };
            let gain = (SIGNAL_POWER / power(&x).max(1e-20)).sqrt() as f32;
            let start = t_samples + gap as u64;
            sent.push(Sent {
                message: m,
                start_s: start as f64 / rate_f,
                end_s: (start + x.len() as u64) as f64 / rate_f,
                matched: false,
            });
            out.sent += 1;
            block.extend(x.iter().map(|v| v * gain));
        }
        noise.add_to(&mut block);
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

/// `message` as a sender whose clock runs `error` fast would play it: resampled by
/// linear interpolation (plenty for a frequency shift test).
fn shifted(encoder: &Encoder, message: &Message, error: f64) -> Vec<f32> {
    let x = encoder.encode_f32(message);
    let n = (x.len() as f64 / (1.0 + error)) as usize;
    (0..n)
        .map(|i| {
            let p = i as f64 * (1.0 + error);
            let i0 = p.floor() as usize;
            let f = (p - i0 as f64) as f32;
            let a = x.get(i0).copied().unwrap_or(0.0);
            let b = x.get(i0 + 1).copied().unwrap_or(0.0);
            a + f * (b - a)
        })
        .collect()
}

/// The kinds of sound with no message in them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interference {
    /// Gaussian white noise.
    White,
    /// Pink (1/f) noise.
    Pink,
    /// Six synthetic talkers.
    Babble,
    /// Referee whistle bursts sweeping 2–4 kHz, over quiet white noise.
    Whistle,
    /// Another team's tones, over quiet white noise.
    ForeignTones,
}

impl Interference {
    /// All kinds, in table order.
    pub const ALL: [Interference; 5] = [
        Interference::White,
        Interference::Pink,
        Interference::Babble,
        Interference::Whistle,
        Interference::ForeignTones,
    ];

    /// Short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            Interference::White => "white noise",
            Interference::Pink => "pink noise",
            Interference::Babble => "speech babble",
            Interference::Whistle => "whistle sweeps",
            Interference::ForeignTones => "foreign tones",
        }
    }
}

/// False messages heard in `hours` of `kind` at 16 kHz with 1 s tones.
#[derive(Clone, Debug)]
pub struct FalseAlarmOutcome {
    /// Audio decoded, hours.
    pub hours: f64,
    /// Messages reported (all false: nothing was sent).
    pub false_messages: usize,
    /// What was reported, in order (each one false).
    pub detections: Vec<Detection>,
    /// Samples decoded.
    pub samples: u64,
}

/// Streams `hours` of `kind` (seeded) through a decoder; every report is false.
pub fn run_false_alarm_trial(kind: Interference, hours: f64, seed: u64) -> FalseAlarmOutcome {
    let rate = 16_000u32;
    let mut decoder = Decoder::new(DecoderConfig::default()).expect("the default config is valid");
    let mut sources: Vec<Box<dyn Source>> = match kind {
        Interference::White => vec![Box::new(WhiteNoise::new(seed, 0.1))],
        Interference::Pink => vec![Box::new(PinkNoise::new(seed, 0.1))],
        Interference::Babble => vec![Box::new(Babble::new(seed, rate, 6, 0.1))],
        Interference::Whistle => vec![
            Box::new(WhiteNoise::new(seed, 0.003)),
            Box::new(Whistle::new(seed ^ 1, rate, 0.1)),
        ],
        Interference::ForeignTones => vec![
            Box::new(WhiteNoise::new(seed, 0.003)),
            Box::new(ForeignTones::new(seed ^ 2, rate, 0.1)),
        ],
    };
    let total = (hours * 3600.0 * f64::from(rate)) as u64;
    let mut done = 0u64;
    let mut detections = Vec::new();
    let mut block = vec![0.0f32; rate as usize];
    while done < total {
        let n = (total - done).min(u64::from(rate)) as usize;
        block.truncate(n);
        block.iter_mut().for_each(|x| *x = 0.0);
        for s in &mut sources {
            s.add_to(&mut block);
        }
        decoder.push_f32(&block);
        detections.extend(std::iter::from_fn(|| decoder.poll_message()));
        done += n as u64;
    }
    decoder.finish();
    detections.extend(std::iter::from_fn(|| decoder.poll_message()));
    FalseAlarmOutcome {
        hours,
        false_messages: detections.len(),
        detections,
        samples: done,
    }
}

/// A whistle over messages: `messages` short messages at 10 dB in-band SNR, each with a
/// whistle sweep (2–4 kHz, random direction, length, timing and level from −10 to +20 dB
/// relative to the message) over it.
pub fn run_whistle_over_messages(messages: usize, seed: u64) -> SnrOutcome {
    let rate = 16_000u32;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let encoder = Encoder::new(EncoderConfig::default()).expect("the default config is valid");
    let mut decoder = Decoder::new(DecoderConfig::default()).expect("the default config is valid");
    let sigma = white_sigma_for_in_band_snr(SIGNAL_POWER, 10.0, rate);
    let mut noise = WhiteNoise::new(seed ^ 3, sigma);
    let mut out = SnrOutcome::default();
    let mut sent = Vec::new();
    let mut detections = Vec::new();
    let mut t = 0u64;
    for i in 0..=messages {
        let gap = rng.random_range(16_000..24_000usize);
        let mut block = vec![0.0f32; gap];
        if i < messages {
            let m = random_message(&mut rng, 0.0, TeamPlan::Three);
            let x = encoder.encode_f32(&m);
            let gain = (SIGNAL_POWER / power(&x)).sqrt() as f32;
            let start = t + gap as u64;
            sent.push(Sent {
                message: m,
                start_s: start as f64 / 16_000.0,
                end_s: (start as f64 + x.len() as f64) / 16_000.0,
                matched: false,
            });
            out.sent += 1;
            block.extend(x.iter().map(|v| v * gain));
            let level_db = rng.random_range(-10.0..20.0);
            let mut whistle = Whistle::new(
                rng.random(),
                rate,
                SIGNAL_POWER.sqrt() * 10f64.powf(level_db / 20.0),
            );
            let (a, b) = if rng.random_bool(0.5) {
                (2000.0, 4000.0)
            } else {
                (4000.0, 2000.0)
            };
            whistle.start_burst(rng.random_range(0.3..1.2), a, b);
            let offset = (gap + rng.random_range(0..12_000usize)).min(block.len());
            whistle.add_to(&mut block[offset..]);
        } else {
            block.extend(vec![0.0f32; 48_000]);
        }
        noise.add_to(&mut block);
        t += block.len() as u64;
        decoder.push_f32(&block);
        while let Some(d) = decoder.poll_message() {
            detections.push(d);
        }
    }
    finish_and_score(&mut decoder, detections, &mut sent, &mut out);
    out.samples = t;
    out
}
