//! The fixed tone plan: 72 tones, 24 basics, senders, data values, short and long messages.
//!
//! Everything here is fixed by the protocol so that other implementations interoperate:
//! tone `k` sounds at `500 + k · 3500/71` Hz; basic `b` sounds on tones `b`, `b + 24` and
//! `b + 48`; basics 0–2 name the sender, basics 3–23 carry a data value 0–20.

use std::fmt;

/// Number of tones in the plan.
pub const TONE_COUNT: usize = 72;
/// Number of basics (each sounds on three tones).
pub const BASIC_COUNT: usize = 24;
/// Number of sender basics (0, 1, 2).
pub const SENDER_COUNT: usize = 3;
/// Number of data values carried by one short message (basics 3–23).
pub const DATA_VALUES: u8 = 21;
/// Number of values carried by a long message (`21 · first + second`).
pub const LONG_VALUES: u16 = 441;
/// Lowest tone, Hz.
pub const LOWEST_TONE_HZ: f64 = 500.0;
/// Highest tone, Hz.
pub const HIGHEST_TONE_HZ: f64 = 4000.0;

/// Frequency of tone `k` (0 … 71) in Hz: `500 + k · 3500/71`.
pub fn tone_frequency_hz(k: usize) -> f64 {
    LOWEST_TONE_HZ + k as f64 * (HIGHEST_TONE_HZ - LOWEST_TONE_HZ) / (TONE_COUNT - 1) as f64
}

/// The three tones of basic `b` (0 … 23), lowest first.
pub fn basic_tones(b: usize) -> [usize; 3] {
    [b, b + BASIC_COUNT, b + 2 * BASIC_COUNT]
}

/// Who sends: the three sender basics.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Sender {
    /// Basic 0.
    Goalkeeper,
    /// Basic 1.
    LeftAttacker,
    /// Basic 2.
    RightAttacker,
}

impl Sender {
    /// All senders in basic order.
    pub const ALL: [Sender; 3] = [
        Sender::Goalkeeper,
        Sender::LeftAttacker,
        Sender::RightAttacker,
    ];

    /// The sender's basic (0, 1 or 2), also its number on the command line.
    pub fn index(self) -> u8 {
        match self {
            Sender::Goalkeeper => 0,
            Sender::LeftAttacker => 1,
            Sender::RightAttacker => 2,
        }
    }

    /// The sender with basic `index`, if 0 … 2.
    pub fn from_index(index: u8) -> Option<Sender> {
        Sender::ALL.get(index as usize).copied()
    }
}

impl fmt::Display for Sender {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Sender::Goalkeeper => "goalkeeper",
            Sender::LeftAttacker => "left-attacker",
            Sender::RightAttacker => "right-attacker",
        })
    }
}

/// One tone-duration slot: a sender and a data value 0 … 20, sounding on six tones.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Frame {
    /// Sender basic.
    pub sender: Sender,
    /// Data value 0 … 20 (basic `3 + data`).
    pub data: u8,
}

impl Frame {
    /// The two basics of the frame: `[sender, 3 + data]`.
    pub fn basics(&self) -> [usize; 2] {
        [
            self.sender.index() as usize,
            SENDER_COUNT + self.data as usize,
        ]
    }

    /// The six tones of the frame, lowest first.
    pub fn tones(&self) -> [usize; 6] {
        let [s, d] = self.basics();
        let mut t = [0; 6];
        t[..3].copy_from_slice(&basic_tones(s));
        t[3..].copy_from_slice(&basic_tones(d));
        t.sort_unstable();
        t
    }
}

/// Why a message cannot be built.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MessageError {
    /// A short message's data must be 0 … 20.
    #[error("data value {0} out of range 0..=20")]
    DataOutOfRange(u16),
    /// A long message's value must be 0 … 440.
    #[error("long value {0} out of range 0..=440")]
    LongValueOutOfRange(u16),
}

/// A message: one frame (short) or two frames from the same sender back to back (long).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Message {
    /// One frame: `data` 0 … 20.
    Short {
        /// Who sends.
        sender: Sender,
        /// Data value 0 … 20.
        data: u8,
    },
    /// Two frames: `value = 21 · first + second`, 0 … 440 (a robot's position).
    Long {
        /// Who sends.
        sender: Sender,
        /// Value 0 … 440.
        value: u16,
    },
}

impl Message {
    /// A short message, checked.
    pub fn short(sender: Sender, data: u8) -> Result<Message, MessageError> {
        if data >= DATA_VALUES {
            return Err(MessageError::DataOutOfRange(data.into()));
        }
        Ok(Message::Short { sender, data })
    }

    /// A long message, checked.
    pub fn long(sender: Sender, value: u16) -> Result<Message, MessageError> {
        if value >= LONG_VALUES {
            return Err(MessageError::LongValueOutOfRange(value));
        }
        Ok(Message::Long { sender, value })
    }

    /// The sender.
    pub fn sender(&self) -> Sender {
        match *self {
            Message::Short { sender, .. } | Message::Long { sender, .. } => sender,
        }
    }

    /// The value carried: data for a short, `21 · first + second` for a long.
    pub fn value(&self) -> u16 {
        match *self {
            Message::Short { data, .. } => data.into(),
            Message::Long { value, .. } => value,
        }
    }

    /// `"short"` or `"long"`.
    pub fn kind(&self) -> &'static str {
        match self {
            Message::Short { .. } => "short",
            Message::Long { .. } => "long",
        }
    }

    /// The frames in the order they sound (one or two). Values out of range are
    /// clamped, which only matters for a message built without the checked constructors.
    pub fn frames(&self) -> Vec<Frame> {
        match *self {
            Message::Short { sender, data } => vec![Frame {
                sender,
                data: data.min(DATA_VALUES - 1),
            }],
            Message::Long { sender, value } => {
                let value = value.min(LONG_VALUES - 1);
                let d = u16::from(DATA_VALUES);
                vec![
                    Frame {
                        sender,
                        data: (value / d) as u8,
                    },
                    Frame {
                        sender,
                        data: (value % d) as u8,
                    },
                ]
            }
        }
    }
}

impl fmt::Display for Message {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} sender={} data={}",
            self.kind(),
            self.sender().index(),
            self.value()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tone_plan_spans_the_band_uniformly() {
        assert_eq!(tone_frequency_hz(0), 500.0);
        assert!((tone_frequency_hz(71) - 4000.0).abs() < 1e-9);
        let spacing = tone_frequency_hz(1) - tone_frequency_hz(0);
        assert!((spacing - 3500.0 / 71.0).abs() < 1e-9, "spacing {spacing}");
    }

    #[test]
    fn every_tone_belongs_to_exactly_one_basic() {
        let mut seen = [0; TONE_COUNT];
        for b in 0..BASIC_COUNT {
            for k in basic_tones(b) {
                seen[k] += 1;
            }
        }
        assert!(seen.iter().all(|&n| n == 1), "{seen:?}");
    }

    #[test]
    fn long_value_splits_into_two_frames() {
        let m = Message::long(Sender::RightAttacker, 21 * 7 + 13).unwrap();
        let f = m.frames();
        assert_eq!((f[0].data, f[1].data), (7, 13));
        assert_eq!(
            Message::long(Sender::Goalkeeper, 441),
            Err(MessageError::LongValueOutOfRange(441))
        );
        assert_eq!(
            Message::short(Sender::Goalkeeper, 21),
            Err(MessageError::DataOutOfRange(21))
        );
    }

    #[test]
    fn frame_tones_are_the_two_basics() {
        let f = Frame {
            sender: Sender::LeftAttacker,
            data: 20,
        };
        assert_eq!(f.tones(), [1, 23, 25, 47, 49, 71]);
    }
}
