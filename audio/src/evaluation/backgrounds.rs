//! False messages in backgrounds that stop and start (issue #33): talkers who pause, a
//! crowd that comes and goes, whistles, music-like tones and doors, each falling to
//! digital silence between its spells (no floor is added anywhere), dry or in a hall.
//! Nothing is sent: every report is a false message.

use crate::channel::{Babble, Convolver, Door, Gated, Melody, RoomSpec, Source, Whistle};
use crate::decoder::{Decoder, DecoderConfig, TraceEvent};
use crate::team::TeamPlan;

use super::FalseAlarmOutcome;

/// A background of the false-message run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Background {
    /// Two synthetic talkers, 1–8 s of speech, then 0.5–6 s of digital silence.
    Talkers,
    /// A crowd of eight, 5–60 s at a time, 1–10 s of silence between.
    Crowd,
    /// A referee's whistle bursts (2–4 kHz sweeps) with silence between.
    Whistles,
    /// Music-like tones: phrases of held harmonic notes and chords, rests between.
    Music,
    /// Door slams and knocks, 1–20 s apart.
    Doors,
    /// All of the above at once, each stopping and starting on its own.
    Everything,
}

impl Background {
    /// All backgrounds, in table order.
    pub const ALL: [Background; 6] = [
        Background::Talkers,
        Background::Crowd,
        Background::Whistles,
        Background::Music,
        Background::Doors,
        Background::Everything,
    ];

    /// Short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            Background::Talkers => "talkers",
            Background::Crowd => "crowd",
            Background::Whistles => "whistles",
            Background::Music => "music",
            Background::Doors => "doors",
            Background::Everything => "everything",
        }
    }

    /// The background's sources for `seed` at 16 kHz, each at RMS about 0.1 while it
    /// sounds. (The decoder is level-free, so only the levels *between* sources matter.)
    fn sources(self, seed: u64, rate: u32) -> Vec<Box<dyn Source>> {
        let talkers = |s: u64| -> Box<dyn Source> {
            Box::new(Gated::new(
                Babble::new(s, rate, 2, 0.1),
                s ^ 0x51,
                rate,
                (1.0, 8.0),
                (0.5, 6.0),
                6.0,
            ))
        };
        let crowd = |s: u64| -> Box<dyn Source> {
            Box::new(Gated::new(
                Babble::new(s, rate, 8, 0.1),
                s ^ 0x52,
                rate,
                (5.0, 60.0),
                (1.0, 10.0),
                6.0,
            ))
        };
        let whistles = |s: u64| -> Box<dyn Source> { Box::new(Whistle::new(s, rate, 0.1)) };
        let music = |s: u64| -> Box<dyn Source> { Box::new(Melody::new(s, rate, 0.1)) };
        let doors = |s: u64| -> Box<dyn Source> { Box::new(Door::new(s, rate, 0.1)) };
        match self {
            Background::Talkers => vec![talkers(seed)],
            Background::Crowd => vec![crowd(seed)],
            Background::Whistles => vec![whistles(seed)],
            Background::Music => vec![music(seed)],
            Background::Doors => vec![doors(seed)],
            Background::Everything => vec![
                talkers(seed),
                crowd(seed ^ 1),
                whistles(seed ^ 2),
                music(seed ^ 3),
                doors(seed ^ 4),
            ],
        }
    }
}

/// Streams `seconds` of `kind` (seeded) through a 16 kHz, 1 s tone decoder set to the
/// team plan `team`, dry when `t60_s` is 0, else through a hall of that reverberation
/// time (which fills the silences with the background's own tail). Every report is
/// false.
pub fn run_background_false_alarm_trial(
    kind: Background,
    seconds: f64,
    t60_s: f64,
    seed: u64,
    team: TeamPlan,
) -> FalseAlarmOutcome {
    background_trial(kind, seconds, t60_s, seed, team, false).0
}

/// [`run_background_false_alarm_trial`] with the decoder's trace (see
/// [`Decoder::enable_trace`]), for diagnosing a false message.
pub fn run_background_false_alarm_trial_traced(
    kind: Background,
    seconds: f64,
    t60_s: f64,
    seed: u64,
    team: TeamPlan,
) -> (FalseAlarmOutcome, Vec<TraceEvent>) {
    background_trial(kind, seconds, t60_s, seed, team, true)
}

fn background_trial(
    kind: Background,
    seconds: f64,
    t60_s: f64,
    seed: u64,
    team: TeamPlan,
    trace: bool,
) -> (FalseAlarmOutcome, Vec<TraceEvent>) {
    let rate = 16_000u32;
    let mut decoder = Decoder::new(DecoderConfig {
        team,
        ..DecoderConfig::default()
    })
    .expect("the default config is valid");
    if trace {
        decoder.enable_trace();
    }
    let mut sources = kind.sources(seed, rate);
    let mut hall = (t60_s > 0.0)
        .then(|| Convolver::new(&RoomSpec::hall(seed ^ 0x4a11, t60_s, rate).impulse_response()));
    let total = (seconds.max(0.0) * f64::from(rate)) as u64;
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
        if let Some(h) = hall.as_mut() {
            h.process(&mut block);
        }
        decoder.push_f32(&block);
        detections.extend(std::iter::from_fn(|| decoder.poll_message()));
        done += n as u64;
    }
    decoder.finish();
    detections.extend(std::iter::from_fn(|| decoder.poll_message()));
    let outcome = FalseAlarmOutcome {
        hours: seconds / 3600.0,
        false_messages: detections.len(),
        detections,
        samples: done,
    };
    (outcome, decoder.take_trace())
}
