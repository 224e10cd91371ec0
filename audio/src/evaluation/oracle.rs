//! An oracle-timing reference decoder for the room trials: what a decoder of this format
//! could get if it knew when each message starts, how long it is and its sender's clock
//! error, and had no detection step at all. It is evaluation only (it is told the truth),
//! never part of the product decoder.
//!
//! It reads the same windows the decoder reads (the [`Analyzer`]'s Hann windows of
//! 128 ms, a hop of 64 ms, the tone powers at the comb scale nearest the message's clock
//! error), each tone's power normalised by that tone's median power over the windows
//! within ±10 s (the babble's spectrum, which the messages — a few tones each, a share of
//! the time — do not move). For each slot of the message it takes the windows wholly
//! inside the slot and gives each basic two scores: the sum over its three tones of the
//! **median** window (a tone that sounds through the slot; a talker's harmonic passing
//! through does not move it) and of the **mean** window (every window's energy, the
//! non-coherent sum a matched filter with unknown tone gains would take). The frame it
//! picks under each score is the most likely one: the best of the three sender basics
//! (for a long message over both slots, one sender sends both) and the best of the 21 data
//! basics in each slot. It is told whether the message is short or long; it knows nothing
//! of the team plan.
use crate::analysis::{Analyzer, Geometry};
use crate::tones::{basic_tones, Message, Sender, DATA_VALUES, SENDER_COUNT, TONE_COUNT};

/// Seconds either side of a message over which each tone's noise median is taken.
const NOISE_SPAN_S: f64 = 10.0;

/// What the oracle made of one sent message.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct OracleVerdict {
    /// The message sent.
    pub sent: Message,
    /// Its start as heard, s.
    pub start_s: f64,
    /// The message picked by the median-window score.
    pub median_pick: Message,
    /// The message picked by the mean-window score.
    pub mean_pick: Message,
    /// The median score's margin of the frame's weakest decision, dB: the true basic's
    /// score over the best other basic's (negative when the pick is wrong).
    pub median_margin_db: f64,
}

impl OracleVerdict {
    /// The median score picked the sent message.
    pub fn median_right(&self) -> bool {
        self.median_pick == self.sent
    }

    /// The mean score picked the sent message.
    pub fn mean_right(&self) -> bool {
        self.mean_pick == self.sent
    }
}

struct Scheduled {
    message: Message,
    /// First and one-past-last sample, as heard.
    start: f64,
    end: f64,
    /// Comb scale index nearest the message's clock error.
    scale: usize,
    /// Windows wholly inside the message, at its scale: `(window start, powers)`.
    windows: Vec<(u64, [f32; TONE_COUNT])>,
}

/// The oracle, fed the same mix as the decoder, block by block.
pub(crate) struct Oracle {
    analyzer: Analyzer,
    geometry: Geometry,
    schedule: Vec<Scheduled>,
    /// Messages before this one have ended before the last window.
    first_open: usize,
    /// Every window's tone powers at the nominal scale (for the noise medians).
    nominal: Vec<[f32; TONE_COUNT]>,
}

impl Oracle {
    /// An oracle for messages `(message, start, end, clock error)`, times in samples as
    /// heard (the room's delay included), at `rate_hz` with tones of `tone_duration_s`.
    pub(crate) fn new(
        rate_hz: u32,
        tone_duration_s: f64,
        max_frequency_error: f64,
        messages: &[(Message, f64, f64, f64)],
    ) -> Oracle {
        let geometry = Geometry::new(rate_hz, tone_duration_s, max_frequency_error);
        let mut schedule: Vec<Scheduled> = messages
            .iter()
            .map(|&(message, start, end, error)| {
                let scale = (0..geometry.scale_count())
                    .min_by(|&a, &b| {
                        (geometry.scales[a] - error)
                            .abs()
                            .total_cmp(&(geometry.scales[b] - error).abs())
                    })
                    .unwrap_or(0);
                Scheduled {
                    message,
                    start,
                    end,
                    scale,
                    windows: Vec::new(),
                }
            })
            .collect();
        schedule.sort_by(|a, b| a.start.total_cmp(&b.start));
        Oracle {
            analyzer: Analyzer::new(geometry.clone()),
            geometry,
            schedule,
            first_open: 0,
            nominal: Vec::new(),
        }
    }

    /// Analyses the next samples of the mix.
    pub(crate) fn push(&mut self, samples: &[f32]) {
        self.analyzer.push(samples.iter().copied());
        let len = self.geometry.window_len as f64;
        let nominal = self.geometry.nominal_scale();
        while let Some(start) = self.analyzer.next_window() {
            let powers = self.analyzer.powers();
            let mut row = [0.0f32; TONE_COUNT];
            row.copy_from_slice(&powers[nominal * TONE_COUNT..(nominal + 1) * TONE_COUNT]);
            self.nominal.push(row);
            let s = start as f64;
            while self.first_open < self.schedule.len() && self.schedule[self.first_open].end < s {
                self.first_open += 1;
            }
            for m in self.schedule[self.first_open..].iter_mut() {
                if m.start > s {
                    break;
                }
                if s + len <= m.end {
                    let j = m.scale;
                    let mut row = [0.0f32; TONE_COUNT];
                    row.copy_from_slice(&powers[j * TONE_COUNT..(j + 1) * TONE_COUNT]);
                    m.windows.push((start, row));
                }
            }
        }
    }

    /// Each message's verdict, in the order of their starts.
    pub(crate) fn verdicts(&self) -> Vec<OracleVerdict> {
        let rate = f64::from(self.geometry.rate_hz);
        let hop = self.geometry.hop as f64;
        let span = (NOISE_SPAN_S * rate / hop) as usize;
        let len = self.geometry.window_len as f64;
        self.schedule
            .iter()
            .map(|m| {
                // Each tone's noise: its median window within ±10 s at the nominal scale.
                let centre = (m.start / hop) as usize;
                let lo = centre.saturating_sub(span).min(self.nominal.len());
                let hi = (centre + span).min(self.nominal.len());
                let mut noise = [1e-30f64; TONE_COUNT];
                for (k, n) in noise.iter_mut().enumerate() {
                    let mut v: Vec<f32> = self.nominal[lo..hi].iter().map(|w| w[k]).collect();
                    *n = f64::from(median(&mut v)).max(1e-30);
                }
                let frames = m.message.frames();
                let slot = (m.end - m.start) / frames.len() as f64;
                // Per slot, per basic: (median score, mean score).
                let scores: Vec<[(f64, f64); 24]> = (0..frames.len())
                    .map(|i| {
                        let a = m.start + i as f64 * slot;
                        let b = a + slot;
                        let inside: Vec<&[f32; TONE_COUNT]> = m
                            .windows
                            .iter()
                            .filter(|(s, _)| *s as f64 >= a && *s as f64 + len <= b)
                            .map(|(_, w)| w)
                            .collect();
                        let mut out = [(0.0, 0.0); 24];
                        for (basic, o) in out.iter_mut().enumerate() {
                            for k in basic_tones(basic) {
                                let mut x: Vec<f32> = inside
                                    .iter()
                                    .map(|w| (f64::from(w[k]) / noise[k]) as f32)
                                    .collect();
                                let mean = x.iter().map(|&v| f64::from(v)).sum::<f64>()
                                    / x.len().max(1) as f64;
                                o.0 += f64::from(median(&mut x));
                                o.1 += mean;
                            }
                        }
                        out
                    })
                    .collect();
                let pick = |which: fn(&(f64, f64)) -> f64| -> (Message, f64) {
                    let sender_score =
                        |s: usize| scores.iter().map(|slot| which(&slot[s])).sum::<f64>();
                    let sender = (0..SENDER_COUNT)
                        .max_by(|&a, &b| sender_score(a).total_cmp(&sender_score(b)))
                        .unwrap_or(0);
                    let true_sender = m.message.sender().index() as usize;
                    let best_other = |scores: &dyn Fn(usize) -> f64,
                                      range: std::ops::Range<usize>,
                                      own: usize| {
                        range
                            .filter(|&b| b != own)
                            .map(scores)
                            .fold(1e-30f64, f64::max)
                    };
                    let mut margin = 10.0
                        * (sender_score(true_sender).max(1e-30)
                            / best_other(&sender_score, 0..SENDER_COUNT, true_sender))
                        .log10();
                    let data: Vec<u8> = scores
                        .iter()
                        .zip(&frames)
                        .map(|(slot, frame)| {
                            let d = (0..DATA_VALUES as usize)
                                .max_by(|&a, &b| {
                                    which(&slot[SENDER_COUNT + a])
                                        .total_cmp(&which(&slot[SENDER_COUNT + b]))
                                })
                                .unwrap_or(0);
                            let own = SENDER_COUNT + frame.data as usize;
                            let s = |b: usize| which(&slot[b]);
                            let m_db = 10.0
                                * (s(own).max(1e-30) / best_other(&s, SENDER_COUNT..24, own))
                                    .log10();
                            margin = margin.min(m_db);
                            d as u8
                        })
                        .collect();
                    let sender = Sender::ALL[sender];
                    let message = match m.message {
                        Message::Short { .. } => Message::Short {
                            sender,
                            data: data[0],
                        },
                        Message::Long { .. } => Message::Long {
                            sender,
                            value: u16::from(data[0]) * u16::from(DATA_VALUES)
                                + u16::from(data.get(1).copied().unwrap_or(0)),
                        },
                    };
                    (message, margin)
                };
                let (median_pick, median_margin_db) = pick(|s| s.0);
                let (mean_pick, _) = pick(|s| s.1);
                OracleVerdict {
                    sent: m.message,
                    start_s: m.start / rate,
                    median_pick,
                    mean_pick,
                    median_margin_db,
                }
            })
            .collect()
    }
}

/// Median of `v` (reordered); 0 when empty.
fn median(v: &mut [f32]) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    *m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::encoder::{Encoder, EncoderConfig};

    #[test]
    fn the_oracle_told_the_start_picks_a_short_and_a_long_message_over_noise_and_a_decoy() {
        // A short message at 1 s and a long one at 4 s over white noise (seed 11015), and
        // between them a steady decoy frame of another sender and data at half their
        // amplitude, sounding through the first message: told the starts, lengths and
        // clock errors (0), the oracle picks both messages, each with a clear margin.
        let encoder = Encoder::new(EncoderConfig::default()).unwrap();
        let rate = 16_000usize;
        let short = Message::short(Sender::LeftAttacker, 4).unwrap();
        let long = Message::long(Sender::RightAttacker, 21 * 17 + 3).unwrap();
        let mut x = vec![0.0f32; 8 * rate];
        let place = |x: &mut Vec<f32>, at: usize, m: &Message, gain: f32| {
            for (i, v) in encoder.encode_f32(m).into_iter().enumerate() {
                x[at + i] += gain * v;
            }
        };
        place(&mut x, rate, &short, 1.0);
        place(
            &mut x,
            rate,
            &Message::short(Sender::Goalkeeper, 9).unwrap(),
            0.5,
        );
        place(&mut x, 4 * rate, &long, 1.0);
        let mut noise = crate::channel::WhiteNoise::new(11015, 0.05);
        crate::channel::Source::add_to(&mut noise, &mut x);
        let len = |m: &Message| encoder.message_samples(m) as f64;
        let schedule = [
            (short, rate as f64, rate as f64 + len(&short), 0.0),
            (long, 4.0 * rate as f64, 4.0 * rate as f64 + len(&long), 0.0),
        ];
        let mut oracle = Oracle::new(16_000, 1.0, 0.006, &schedule);
        for chunk in x.chunks(1000) {
            oracle.push(chunk);
        }
        let verdicts = oracle.verdicts();
        assert_eq!(verdicts.len(), 2);
        for v in &verdicts {
            assert!(
                v.median_right() && v.mean_right() && v.median_margin_db > 3.0,
                "sent {} at {:.2} s: median {}, mean {}, margin {:.1} dB",
                v.sent,
                v.start_s,
                v.median_pick,
                v.mean_pick,
                v.median_margin_db
            );
        }
    }
}
