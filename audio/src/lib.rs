//! audio: the 72-tone acoustic messaging codec robots fall back on when the radio fails.
//!
//! **What it is.** Cerberus's (RoboCup 2001) tone plan built as a real codec: 72 tones
//! uniformly spaced over 500–4000 Hz (`f_k = 500 + k · 3500/71` Hz); 24 *basics*, basic
//! `b` sounding on tones `b`, `b + 24`, `b + 48`; a *short* message is one sender basic
//! (0 goalkeeper, 1 left attacker, 2 right attacker) plus one data basic (3 … 23 → value
//! 0 … 20), six tones for one tone duration (1 s by default); a *long* message is two
//! shorts from the same sender back to back, value `21 · first + second` (0 … 440).
//! The [`Encoder`] synthesises by inverse FFT with every tone exactly on its frequency at
//! any sample rate; the [`Decoder`] is a streaming, sans-IO detector: push samples in any
//! block size, poll [`Detection`]s with their start times. It measures the noise floor,
//! integrates each tone's energy over the tone duration, tolerates a ±0.6% frequency
//! error, applies the seed's rules (2-of-3 vote per basic, more than one sender or data
//! basic → not a message, consecutive windows agree, once per transmission) and tells
//! short from long. See the `decoder` module docs for the detector and its false-alarm
//! reasoning. WAV files ([`read_wav`], [`write_wav_i16`]) and raw s16le PCM
//! ([`S16leDecoder`], [`i16_to_s16le`]) are the I/O; [`channel`] holds the seeded noise and
//! interference models `huddle audio eval` measures against.
//!
//! **What it is not.** Not a general data-over-sound modem (about 6 bits per second at
//! the default tone length, by design), not encrypted or authenticated (anyone can whistle
//! the tones), and it does no audio device I/O: it reads and writes samples, files and
//! pipes (`arecord … | huddle audio listen`). It never reads a clock; time is the sample
//! count.
//!
//! **Teams of up to six.** [`TeamPlan::Six`] maps six robots onto the same frames (sender
//! basic × data bank, 10 values per frame); [`DecoderConfig::team`] selects it (the
//! seed's three-robot plan is the default). See the `team` module.
//!
//! **In-band SNR** (used throughout the docs, tests and `eval`): the signal's mean power
//! over its duration divided by the noise power inside 500–4000 Hz. For white noise of
//! variance σ² at rate `fs` the latter is `σ² · 3500 / (fs / 2)`.
//!
//! ```
//! use audio::{Decoder, DecoderConfig, Encoder, EncoderConfig, Message, Sender};
//!
//! let encoder = Encoder::new(EncoderConfig::default()).unwrap(); // 16 kHz, 1 s tones
//! let message = Message::long(Sender::LeftAttacker, 21 * 5 + 9).unwrap();
//! let mut samples = vec![0.0f32; 8_000]; // half a second of silence first
//! samples.extend(encoder.encode_f32(&message));
//! samples.extend(vec![0.0f32; 8_000]);
//!
//! let mut decoder = Decoder::new(DecoderConfig::default()).unwrap();
//! let mut heard = Vec::new();
//! for block in samples.chunks(512) {
//!     decoder.push_f32(block);
//!     while let Some(d) = decoder.poll_message() {
//!         heard.push(d);
//!     }
//! }
//! assert_eq!(heard.len(), 1);
//! assert_eq!(heard[0].message, message);
//! assert!((heard[0].start_s - 0.5).abs() < 0.05);
//! ```

#![forbid(unsafe_code)]

mod analysis;
pub mod channel;

mod decoder;
mod encoder;
pub mod evaluation;
mod pcm;
mod significance;
mod team;
mod tones;
mod wav;

pub use decoder::{
    Decoder, DecoderConfig, DecoderConfigError, Detection, TraceEvent, MIN_TONE_DURATION_S,
};
pub use encoder::{Encoder, EncoderConfig, EncoderConfigError};
pub use pcm::{f32_to_i16, i16_to_f32, i16_to_s16le, S16leDecoder};
pub use team::{TeamError, TeamMessage, TeamPlan};
pub use tones::{
    basic_tones, tone_frequency_hz, Frame, Message, MessageError, Sender, BASIC_COUNT, DATA_VALUES,
    HIGHEST_TONE_HZ, LONG_VALUES, LOWEST_TONE_HZ, SENDER_COUNT, TONE_COUNT,
};
pub use wav::{
    read_wav, write_wav_f32, write_wav_i16, ReadWavError, Recording, WriteWavError, MAX_RATE_HZ,
    MIN_RATE_HZ,
};
