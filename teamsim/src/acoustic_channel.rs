//! The acoustic channel between simulated robots (the simulator's side of the fallback;
//! robots never see it): each robot's loudspeaker and microphone at its true position,
//! delay by distance, 1/r attenuation, a diffuse reverberant field and the crowd's babble,
//! mixed into each listener's own streaming decoder (see [`super::acoustic`]).

use super::acoustic::*;
use audio::channel::{Babble, Source};
use audio::{Decoder, DecoderConfig, Detection, Encoder, EncoderConfig, Message};
use comms::arbitration::Posted;
use serde::Serialize;

/// Schroeder's reverberator: four combs in parallel, two all-passes in series; the comb
/// feedback gives the configured T60; the output is scaled so that its energy per unit
/// input energy is `level²`.
#[derive(Debug, Clone)]
struct Reverb {
    combs: Vec<(Vec<f32>, usize, f32)>,
    allpasses: Vec<(Vec<f32>, usize)>,
    out_gain: f32,
}

impl Reverb {
    fn new(t60_s: f64, level: f64) -> Self {
        let fs = f64::from(SAMPLE_RATE_HZ);
        // Mutually prime lengths (about 30–40 ms) so the echoes do not pile up.
        let comb_len = [487usize, 541, 593, 631];
        let mut energy = 0.0;
        let combs = comb_len
            .iter()
            .map(|&n| {
                let g = 10f64.powf(-3.0 * n as f64 / (t60_s.max(0.05) * fs));
                energy += 1.0 / (1.0 - g * g);
                (vec![0.0f32; n], 0usize, g as f32)
            })
            .collect();
        let allpasses = [173usize, 59]
            .iter()
            .map(|&n| (vec![0.0f32; n], 0usize))
            .collect();
        Self {
            combs,
            allpasses,
            out_gain: (level / energy.sqrt()) as f32,
        }
    }

    fn process(&mut self, x: f32) -> f32 {
        let mut y = 0.0f32;
        for (buf, i, g) in &mut self.combs {
            let out = buf[*i];
            buf[*i] = x + *g * out;
            *i = (*i + 1) % buf.len();
            y += out;
        }
        for (buf, i) in &mut self.allpasses {
            let d = buf[*i];
            let v = y + 0.7 * d;
            buf[*i] = v;
            *i = (*i + 1) % buf.len();
            y = d - 0.7 * v;
        }
        y * self.out_gain
    }
}

/// One message in the air, for the statistics.
#[derive(Debug, Clone, Copy)]
struct Sounded {
    /// Robot index of the sender.
    from: usize,
    /// Per listener: first and one-past-last sample of the direct sound.
    arrival: [(u64, u64); 16],
    value: Message,
}

/// What one listener's decoder produced, with who it is attributed to by the slot plan.
#[derive(Debug, Clone, Copy)]
pub struct Heard {
    /// Listener (robot index).
    pub listener: usize,
    /// The detection, times in seconds of the channel's clock (simulated time).
    pub detection: Detection,
}

/// Counters of the channel.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct AcousticStats {
    /// Messages sounded.
    pub sounded: u64,
    /// Detections that match a message a teammate sounded in the slot they were heard in.
    pub decoded: u64,
    /// Detections that match nothing sounded then (a wrong value, sender or slot).
    pub wrong: u64,
    /// Receptions (message × listener other than its sender) whose direct sound
    /// overlapped another message's at that listener.
    pub collided: u64,
    /// Receptions in all.
    pub receptions: u64,
}

/// The room: every robot's loudspeaker and microphone, and each microphone's decoder.
pub struct AcousticChannel {
    encoder: Encoder,
    room: Room,
    decoders: Vec<Decoder>,
    sounded: Vec<Sounded>,
    /// Decoder's window of start times in which a detection may match a message, samples.
    tolerance: u64,
    /// The figures so far.
    pub stats: AcousticStats,
}

/// The air between the robots, without decoders: what each robot's loudspeaker puts into
/// it (direct sound delayed by distance and attenuated 1/r, and a diffuse reverberant
/// field), and what each microphone picks up, the crowd's babble with it. The in-process
/// channel sounds encoded messages into it; `huddle sim --daemons` streams each daemon's
/// loudspeaker into it and each microphone's signal out to its daemon.
pub struct Room {
    listeners: Vec<RoomListener>,
    /// Samples already played out.
    cursor: u64,
    critical_gain: f32,
}

struct RoomListener {
    /// Direct sound to come, from `cursor` on.
    direct: Vec<f32>,
    /// Input to the reverberator to come, from `cursor` on.
    diffuse: Vec<f32>,
    reverb: Reverb,
    crowd: Babble,
    /// What the microphone picked up in the last [`Room::play`].
    heard: Vec<f32>,
}

impl Room {
    /// A room with `robots` robots (at most 16), its crowd deterministic for `seed`.
    pub fn new(cfg: &AcousticConfig, robots: usize, seed: u64) -> Result<Self, AcousticError> {
        if robots > 16 {
            return Err(AcousticError::Robots(robots));
        }
        let encoder = Encoder::new(EncoderConfig {
            sample_rate_hz: SAMPLE_RATE_HZ,
            tone_duration_s: cfg.tone_s,
            ..EncoderConfig::default()
        })
        .map_err(|e| AcousticError::Codec(e.to_string()))?;
        // The crowd level: one robot's sound at 1 m over the babble is the configured SNR
        // (babble is speech, nearly all of its power inside the 500–4000 Hz band).
        let probe = encoder.encode_f32(&encode_claim(
            Posted {
                h: 1.0,
                going: true,
            },
            1000.0,
        ));
        let signal_power = audio::channel::power(&probe);
        let crowd_rms = (signal_power / 10f64.powf(cfg.crowd_snr_db_at_1m / 10.0)).sqrt();
        let listeners = (0..robots)
            .map(|i| RoomListener {
                direct: Vec::new(),
                diffuse: Vec::new(),
                reverb: Reverb::new(cfg.t60_s, 1.0),
                crowd: Babble::new(
                    seed.wrapping_mul(0x9e37_79b9).wrapping_add(i as u64),
                    SAMPLE_RATE_HZ,
                    6,
                    crowd_rms,
                ),
                heard: Vec::new(),
            })
            .collect();
        Ok(Self {
            listeners,
            cursor: 0,
            critical_gain: (1.0 / cfg.critical_distance_m.max(0.1)) as f32,
        })
    }

    /// Samples played out so far.
    pub fn cursor(&self) -> u64 {
        self.cursor
    }

    /// Robot `from`'s loudspeaker plays `pcm` from now (the cursor) at `positions[from]`
    /// (`positions`: every robot's true position, m). Returns, per listener, the first
    /// and one-past-last sample of its direct sound.
    pub fn sound(
        &mut self,
        from: usize,
        pcm: &[f32],
        positions: &[(f64, f64)],
    ) -> [(u64, u64); 16] {
        let fs = f64::from(SAMPLE_RATE_HZ);
        let mut arrival = [(0u64, 0u64); 16];
        for (j, l) in self.listeners.iter_mut().enumerate() {
            let (dx, dy) = (
                positions[j].0 - positions[from].0,
                positions[j].1 - positions[from].1,
            );
            let r = (dx * dx + dy * dy).sqrt();
            let delay = (r / SPEED_OF_SOUND_MPS * fs).round() as usize;
            let gain = (1.0 / r.max(1.0)) as f32;
            let end = delay + pcm.len();
            if l.direct.len() < end {
                l.direct.resize(end, 0.0);
                l.diffuse.resize(end, 0.0);
            }
            for (k, &s) in pcm.iter().enumerate() {
                l.direct[delay + k] += gain * s;
                l.diffuse[delay + k] += self.critical_gain * s;
            }
            arrival[j] = (self.cursor + delay as u64, self.cursor + end as u64);
        }
        arrival
    }

    /// Plays the next `n` samples: each microphone's signal (direct sound, reverberation,
    /// crowd), then read with [`Room::microphone`].
    pub fn play(&mut self, n: usize) {
        for l in &mut self.listeners {
            l.heard.clear();
            l.heard.resize(n, 0.0);
            l.crowd.add_to(&mut l.heard);
            let take = n.min(l.direct.len());
            for (k, x) in l.heard.iter_mut().enumerate() {
                let (d, w) = if k < take {
                    (l.direct[k], l.diffuse[k])
                } else {
                    (0.0, 0.0)
                };
                *x += d + l.reverb.process(w);
            }
            l.direct.drain(..take);
            l.diffuse.drain(..take);
        }
        self.cursor += n as u64;
    }

    /// What listener `listener`'s microphone picked up in the last [`Room::play`]. Empty
    /// for no such listener.
    pub fn microphone(&self, listener: usize) -> &[f32] {
        self.listeners.get(listener).map_or(&[], |l| &l.heard)
    }

    /// Robots in the room.
    pub fn robots(&self) -> usize {
        self.listeners.len()
    }
}

/// Why the channel could not be set up.
#[derive(Debug, thiserror::Error)]
pub enum AcousticError {
    /// The codec refused the tone duration.
    #[error("acoustic codec: {0}")]
    Codec(String),
    /// Too many robots for the statistics' fixed arrays.
    #[error("the acoustic channel takes at most 16 robots, not {0}")]
    Robots(usize),
}

impl AcousticChannel {
    /// A room with `robots` robots, deterministic for `seed`.
    pub fn new(cfg: &AcousticConfig, robots: usize, seed: u64) -> Result<Self, AcousticError> {
        let room = Room::new(cfg, robots, seed)?;
        let encoder = Encoder::new(EncoderConfig {
            sample_rate_hz: SAMPLE_RATE_HZ,
            tone_duration_s: cfg.tone_s,
            ..EncoderConfig::default()
        })
        .map_err(|e| AcousticError::Codec(e.to_string()))?;
        let dec = DecoderConfig {
            sample_rate_hz: SAMPLE_RATE_HZ,
            tone_duration_s: cfg.tone_s,
            ..DecoderConfig::default()
        };
        let decoders = (0..robots)
            .map(|_| Decoder::new(dec.clone()).map_err(|e| AcousticError::Codec(e.to_string())))
            .collect::<Result<Vec<_>, AcousticError>>()?;
        Ok(Self {
            encoder,
            room,
            decoders,
            sounded: Vec::new(),
            tolerance: (0.5 * cfg.slot_s() * f64::from(SAMPLE_RATE_HZ)) as u64,
            stats: AcousticStats::default(),
        })
    }

    /// Simulated time the decoders have heard up to, s.
    pub fn time_s(&self) -> f64 {
        self.room.cursor() as f64 / f64::from(SAMPLE_RATE_HZ)
    }

    /// The samples listener `listener`'s microphone picked up in the last
    /// [`AcousticChannel::advance_to`] (direct sound, reverberation and crowd): the
    /// channel's received level, which the decoder's tone SNR no longer follows (its noise
    /// floor is held within 13 dB of the band's tone power). Empty for no such listener.
    pub fn microphone(&self, listener: usize) -> &[f32] {
        self.room.microphone(listener)
    }

    /// Robot `from` sounds `message` now (at the channel's cursor) from `positions[from]`;
    /// `positions` are every robot's true positions, m.
    pub fn sound(&mut self, from: usize, message: &Message, positions: &[(f64, f64)]) {
        let pcm = self.encoder.encode_f32(message);
        let arrival = self.room.sound(from, &pcm, positions);
        self.stats.sounded += 1;
        // Collisions: receptions whose direct sounds overlap at a listener.
        let n = self.room.robots();
        for other in &self.sounded {
            for (j, (&(a0, a1), &(b0, b1))) in
                arrival[..n].iter().zip(&other.arrival[..n]).enumerate()
            {
                if a0 < b1 && b0 < a1 {
                    if j != from {
                        self.stats.collided += 1;
                    }
                    if j != other.from {
                        self.stats.collided += 1;
                    }
                }
            }
        }
        self.stats.receptions += n as u64 - 1;
        self.sounded.push(Sounded {
            from,
            arrival,
            value: *message,
        });
    }

    /// Let the room play until `t_s`: every listener's microphone signal (direct sound,
    /// reverberation, crowd) into its decoder. Returns what the decoders produced.
    pub fn advance_to(&mut self, t_s: f64) -> Vec<Heard> {
        let to = (t_s * f64::from(SAMPLE_RATE_HZ)).round() as u64;
        let mut heard = Vec::new();
        if to <= self.room.cursor() {
            return heard;
        }
        self.room.play((to - self.room.cursor()) as usize);
        for (j, decoder) in self.decoders.iter_mut().enumerate() {
            decoder.push_f32(self.room.microphone(j));
            while let Some(d) = decoder.poll_message() {
                heard.push(Heard {
                    listener: j,
                    detection: d,
                });
            }
        }
        for h in &heard {
            let start = (h.detection.start_s * f64::from(SAMPLE_RATE_HZ)) as u64;
            let matched = self.sounded.iter().any(|s| {
                s.from != h.listener
                    && s.value == h.detection.message
                    && s.arrival[h.listener].0.abs_diff(start) <= self.tolerance
            });
            if matched {
                self.stats.decoded += 1;
            } else if !self.sounded.iter().any(|s| {
                s.from == h.listener && s.arrival[h.listener].0.abs_diff(start) <= self.tolerance
            }) {
                self.stats.wrong += 1;
            }
        }
        // Forget messages long past (kept a few seconds for matching late detections).
        let keep_after = to.saturating_sub(u64::from(SAMPLE_RATE_HZ) * 5);
        self.sounded
            .retain(|s| s.arrival.iter().any(|&(_, end)| end >= keep_after));
        heard
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_robot_hears_a_teammate_later_and_softer_by_its_distance() {
        // A quiet room (crowd 200 dB down, little reverberation): robot 1 stands 6.86 m
        // from robot 0, 20 ms of sound away.
        let cfg = AcousticConfig {
            crowd_snr_db_at_1m: 200.0,
            t60_s: 0.05,
            critical_distance_m: 100.0,
            ..AcousticConfig::default()
        };
        let mut room = Room::new(&cfg, 2, 1).expect("a room");
        let at = [(0.0, 0.0), (2.0 * SPEED_OF_SOUND_MPS * 0.01, 0.0)];
        let burst = vec![1.0f32; 80];
        let arrival = room.sound(0, &burst, &at);
        assert_eq!(arrival[1], (320, 400), "20 ms at 16 kHz, then 80 samples");
        room.play(1000);
        let mic = room.microphone(1);
        let loud: Vec<usize> = (0..mic.len()).filter(|&k| mic[k].abs() > 0.1).collect();
        assert_eq!(
            (loud.first(), loud.last()),
            (Some(&320), Some(&399)),
            "the burst arrives 320 samples late"
        );
        let gain = mic[350];
        assert!(
            (gain - 1.0 / 6.86).abs() < 0.01,
            "1/r attenuation: {gain} at 6.86 m"
        );
        assert!(
            room.microphone(0)[..5].iter().all(|x| x.abs() > 0.5),
            "its sender hears it at once, at full level"
        );
    }
}
