//! Backgrounds that stop and start: a source gated on and off with digital silence
//! between its spells, music-like notes in phrases, and a door that slams now and then.
//! Issue #33: a background with pauses (speech over digital silence) threw the decoder's
//! noise floor off whatever its level, so the false-message runs need backgrounds whose
//! silences are real zeros, not a steady floor.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};

use super::Source;

/// Plays `source` in spells of `on_s` seconds, each at its own level (±`level_db` around
/// the source's own), with digital silence of `off_s` seconds between them. The source
/// is paused while off (it continues where it stopped).
pub struct Gated<S> {
    source: S,
    rng: ChaCha8Rng,
    rate: f64,
    on_s: (f64, f64),
    off_s: (f64, f64),
    level_db: f64,
    /// Samples left in the current spell, and whether it sounds.
    left: usize,
    on: bool,
    gain: f32,
    scratch: Vec<f32>,
}

impl<S: Source> Gated<S> {
    /// Spells of U(`on_s`) seconds of `source`, at a level drawn within ±`level_db` dB,
    /// with U(`off_s`) seconds of zeros between them; it starts silent.
    pub fn new(
        source: S,
        seed: u64,
        sample_rate_hz: u32,
        on_s: (f64, f64),
        off_s: (f64, f64),
        level_db: f64,
    ) -> Self {
        Gated {
            source,
            rng: ChaCha8Rng::seed_from_u64(seed),
            rate: f64::from(sample_rate_hz),
            on_s,
            off_s,
            level_db: level_db.abs(),
            left: 0,
            on: true,
            gain: 1.0,
            scratch: Vec::new(),
        }
    }

    fn next_spell(&mut self) {
        self.on = !self.on;
        let (a, b) = if self.on { self.on_s } else { self.off_s };
        let s = if b > a {
            self.rng.random_range(a..b)
        } else {
            a
        };
        self.left = ((s * self.rate) as usize).max(1);
        if self.on {
            let db = if self.level_db > 0.0 {
                self.rng.random_range(-self.level_db..self.level_db)
            } else {
                0.0
            };
            self.gain = 10f32.powf(db as f32 / 20.0);
        }
    }
}

impl<S: Source> Source for Gated<S> {
    fn add_to(&mut self, out: &mut [f32]) {
        let mut at = 0;
        while at < out.len() {
            if self.left == 0 {
                self.next_spell();
            }
            let n = self.left.min(out.len() - at);
            if self.on {
                self.scratch.clear();
                self.scratch.resize(n, 0.0);
                self.source.add_to(&mut self.scratch);
                for (o, v) in out[at..at + n].iter_mut().zip(&self.scratch) {
                    *o += self.gain * v;
                }
            }
            self.left -= n;
            at += n;
        }
    }
}

/// One sounding note: fundamental, harmonic amplitudes, phases, vibrato.
#[derive(Clone, Debug)]
struct Note {
    f0: f64,
    harmonics: Vec<(f64, f64)>,
    vibrato_hz: f64,
    vibrato_depth: f64,
    vibrato_phase: f64,
}

/// Music-like tones: phrases of 3–16 notes (one to three at once, equal-tempered,
/// fundamentals 130–1050 Hz with 1–8 harmonics falling off by 3–12 dB each, some with
/// vibrato), 0.08–1.2 s a note with a short attack and release, and 0.3–4 s of digital
/// silence between phrases. Held harmonic tones are what the 72-tone plan is made of,
/// so this is the background most like a message that is not one.
#[derive(Clone, Debug)]
pub struct Melody {
    rng: ChaCha8Rng,
    rate: f64,
    amplitude: f32,
    notes: Vec<Note>,
    note_len: usize,
    note_left: usize,
    notes_left_in_phrase: usize,
    rest_left: usize,
}

impl Melody {
    /// Music of RMS amplitude about `rms` while it sounds.
    pub fn new(seed: u64, sample_rate_hz: u32, rms: f64) -> Self {
        Melody {
            rng: ChaCha8Rng::seed_from_u64(seed),
            rate: f64::from(sample_rate_hz),
            amplitude: rms as f32,
            notes: Vec::new(),
            note_len: 1,
            note_left: 0,
            notes_left_in_phrase: 0,
            rest_left: 0,
        }
    }

    fn next_note(&mut self) {
        let chord = self.rng.random_range(1..=3usize);
        let root = self.rng.random_range(-9..28i32); // semitones from A3 (220 Hz)
        let timbre_fall_db = self.rng.random_range(3.0..12.0);
        let harmonics = self.rng.random_range(1..=8usize);
        let vibrato = self.rng.random_bool(0.4);
        self.notes = (0..chord)
            .map(|i| {
                let step = [0, 4, 7, 12][i.min(3)]
                    + if i > 0 {
                        self.rng.random_range(-1..=1)
                    } else {
                        0
                    };
                let f0 = 220.0 * 2f64.powf(f64::from(root + step) / 12.0);
                let amp = |h: usize| 10f64.powf(-timbre_fall_db * h as f64 / 20.0);
                let norm = (0..harmonics).map(|h| amp(h) * amp(h)).sum::<f64>().sqrt();
                Note {
                    f0,
                    harmonics: (0..harmonics)
                        .map(|h| {
                            (
                                amp(h) / norm / (chord as f64).sqrt(),
                                self.rng.random_range(0.0..1.0),
                            )
                        })
                        .collect(),
                    vibrato_hz: self.rng.random_range(4.0..7.0),
                    vibrato_depth: if vibrato {
                        self.rng.random_range(0.002..0.01)
                    } else {
                        0.0
                    },
                    vibrato_phase: 0.0,
                }
            })
            .collect();
        self.note_len = ((self.rng.random_range(0.08..1.2) * self.rate) as usize).max(1);
        self.note_left = self.note_len;
    }
}

impl Source for Melody {
    fn add_to(&mut self, out: &mut [f32]) {
        let tau = 2.0 * std::f64::consts::PI;
        for x in out {
            if self.note_left == 0 {
                if self.rest_left > 0 {
                    self.rest_left -= 1;
                    continue;
                }
                if self.notes_left_in_phrase == 0 {
                    self.notes_left_in_phrase = self.rng.random_range(3..=16);
                }
                self.notes_left_in_phrase -= 1;
                self.next_note();
                if self.notes_left_in_phrase == 0 {
                    self.rest_left = (self.rng.random_range(0.3..4.0) * self.rate) as usize;
                }
            }
            self.note_left -= 1;
            let i = self.note_len - self.note_left;
            // 10 ms attack, 30 ms release: notes, not clicks.
            let edge = ((i as f64 / (0.01 * self.rate))
                .min(self.note_left as f64 / (0.03 * self.rate)))
            .min(1.0);
            let mut s = 0.0;
            for note in &mut self.notes {
                note.vibrato_phase = (note.vibrato_phase + note.vibrato_hz / self.rate).fract();
                let f = note.f0 * (1.0 + note.vibrato_depth * (tau * note.vibrato_phase).sin());
                for (h, (a, phase)) in note.harmonics.iter_mut().enumerate() {
                    let fh = f * (h + 1) as f64;
                    if fh >= 0.45 * self.rate {
                        continue;
                    }
                    *phase = (*phase + fh / self.rate).fract();
                    s += *a * (tau * *phase).sin();
                }
            }
            *x += self.amplitude * (std::f64::consts::SQRT_2 * edge * s) as f32;
        }
    }
}

/// A door (or a ball on a board, a dropped robot): broadband bursts with a sharp attack
/// decaying over 30–300 ms, some with a rattle of a few hundred hertz, 1–20 s apart, digital
/// silence between.
#[derive(Clone, Debug)]
pub struct Door {
    rng: ChaCha8Rng,
    rate: f64,
    amplitude: f32,
    decay: f32,
    envelope: f32,
    rattle_hz: f64,
    phase: f64,
    gap_left: usize,
    burst_left: usize,
}

impl Door {
    /// Slams of peak RMS amplitude about `rms`.
    pub fn new(seed: u64, sample_rate_hz: u32, rms: f64) -> Self {
        Door {
            rng: ChaCha8Rng::seed_from_u64(seed),
            rate: f64::from(sample_rate_hz),
            amplitude: rms as f32,
            decay: 0.0,
            envelope: 0.0,
            rattle_hz: 0.0,
            phase: 0.0,
            gap_left: 0,
            burst_left: 0,
        }
    }
}

impl Source for Door {
    fn add_to(&mut self, out: &mut [f32]) {
        for x in out {
            if self.burst_left == 0 {
                if self.gap_left > 0 {
                    self.gap_left -= 1;
                    continue;
                }
                let tau_s = self.rng.random_range(0.03..0.3);
                self.decay = (-1.0 / (tau_s * self.rate)).exp() as f32;
                self.envelope = 10f32.powf(self.rng.random_range(-10.0f32..0.0) / 20.0);
                self.rattle_hz = if self.rng.random_bool(0.5) {
                    self.rng.random_range(150.0..600.0)
                } else {
                    0.0
                };
                self.burst_left = (6.0 * tau_s * self.rate) as usize;
                self.gap_left = (self.rng.random_range(1.0..20.0) * self.rate) as usize;
            }
            self.burst_left -= 1;
            let n: f32 = StandardNormal.sample(&mut self.rng);
            let rattle = if self.rattle_hz > 0.0 {
                self.phase = (self.phase + self.rattle_hz / self.rate).fract();
                1.0 + 0.8 * (2.0 * std::f64::consts::PI * self.phase).sin() as f32
            } else {
                1.0
            };
            *x += self.amplitude * self.envelope * rattle * n;
            self.envelope *= self.decay;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::{power, Babble};
    use super::*;

    #[test]
    fn gated_sources_fall_to_digital_silence_between_spells() {
        let mut a = vec![0.0f32; 16_000 * 30];
        let mut b = vec![0.0f32; 16_000 * 30];
        let make = || {
            Gated::new(
                Babble::new(5, 16_000, 2, 0.1),
                9,
                16_000,
                (1.0, 3.0),
                (0.5, 2.0),
                6.0,
            )
        };
        make().add_to(&mut a);
        let mut g = make();
        for chunk in b.chunks_mut(777) {
            g.add_to(chunk);
        }
        assert_eq!(a, b, "same seed, same sound, whatever the block size");
        let silent = a
            .chunks(1600)
            .filter(|c| c.iter().all(|&v| v == 0.0))
            .count();
        let loud = a.chunks(1600).filter(|c| power(c) > 1e-4).count();
        assert!(
            silent >= 30 && loud >= 60,
            "{silent} silent and {loud} loud 100 ms blocks of 300"
        );
    }

    #[test]
    fn melody_and_door_have_their_silences_and_their_level() {
        let mut m = vec![0.0f32; 16_000 * 60];
        Melody::new(3, 16_000, 0.1).add_to(&mut m);
        let blocks: Vec<f64> = m.chunks(1600).map(power).collect();
        let silent = blocks.iter().filter(|&&p| p == 0.0).count();
        let sounding: Vec<f64> = blocks.iter().copied().filter(|&p| p > 1e-4).collect();
        assert!(
            silent >= 20,
            "phrases rest in digital silence: {silent} of 600 blocks"
        );
        let rms = (sounding.iter().sum::<f64>() / sounding.len() as f64).sqrt();
        assert!(
            (0.03..0.3).contains(&rms),
            "music at about 0.1 RMS while it sounds: {rms}"
        );
        let mut d = vec![0.0f32; 16_000 * 60];
        Door::new(4, 16_000, 0.1).add_to(&mut d);
        let silent = d
            .chunks(1600)
            .filter(|c| c.iter().all(|&v| v == 0.0))
            .count();
        assert!(
            silent >= 300,
            "a door is mostly silence: {silent} of 600 blocks"
        );
        assert!(d.iter().any(|&v| v.abs() > 0.05), "and it slams");
    }
}
