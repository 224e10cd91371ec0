//! Team plans: how many robots share the tone plan, and what each can say.
//!
//! The seed's plan ([`TeamPlan::Three`], the default) has three sender basics and 21 data
//! values (basics 3 … 23); a long message carries `21 · first + second` (0 … 440).
//! Teams that field more robots use [`TeamPlan::Six`]: robot `r` (0 … 5) sends on sender
//! basic `r mod 3` and in data *bank* `r div 3`; bank `b` holds the data basics
//! `3 + 10·b … 12 + 10·b`, so each robot says a value 0 … 9 in a short message and
//! `10 · first + second` (0 … 99) in a long one (both frames in its bank). Data basic 23
//! (data 20) is unused.
//!
//! On the air a six-robot message is an ordinary frame of the seed's plan, so the
//! decoder's detection, rules and false-alarm reasoning are untouched and every figure
//! of `huddle audio eval` holds as it is; the plan only maps frames to robots and
//! values, and a decoder set to it drops what the plan cannot have sent (data 20, a long
//! message whose frames lie in different banks). The price is fewer values per robot:
//! 10 instead of 21 per frame.
//!
//! **A frame that says what it is** ([`TeamPlan::Checked`], issue #33). Under the seed's
//! plan every frame of a long message is also a valid short message, so a long message
//! whose second frame is lost (a hall's echo, babble, a second robot sounding over it)
//! comes out as a *wrong* short one, and no end test can rule that out. The checked plan
//! splits the data basics: a short message says 0 … 9 on basics 3 … 12, a long message's
//! two frames each say 0 … 10 on basics 13 … 23 (`11 · first + second`, 0 … 120). A
//! long message cut to either frame, a first frame heard while another robot sounds, and
//! two short messages run together are then messages the plan cannot have sent, and a
//! decoder set to it drops them: lost, never wrong. It costs no airtime and no change on
//! the air (every frame is still one sender and one data basic, so detection and the
//! false-alarm reasoning are untouched); the price is values: 10 instead of 21 for a
//! short message, 121 instead of 441 for a long one (an 11 × 11 grid over the field
//! instead of 21 × 21).

use std::fmt;

use crate::tones::{Message, MessageError, Sender, DATA_VALUES, SENDER_COUNT};

/// Which team plan the senders use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum TeamPlan {
    /// The seed's plan: 3 robots, values 0 … 20 (short) and 0 … 440 (long).
    #[default]
    Three,
    /// Up to 6 robots: values 0 … 9 (short) and 0 … 99 (long).
    Six,
    /// 3 robots whose long frames never read as a short message: values 0 … 9 (short,
    /// data basics 3 … 12) and 0 … 120 (long, both frames on data basics 13 … 23).
    Checked,
}

/// Values per frame in a [`TeamPlan::Six`] bank, and of a [`TeamPlan::Checked`] short.
const BANK_VALUES: u8 = 10;
/// Values per frame of a [`TeamPlan::Checked`] long message (data 10 … 20).
const CHECKED_LONG_VALUES: u8 = DATA_VALUES - BANK_VALUES;

/// Why a team message cannot be sent under a plan.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum TeamError {
    /// The robot number is not in the plan.
    #[error("robot {robot} is not in the {plan} plan (0..={max})")]
    Robot {
        /// The robot asked for.
        robot: u8,
        /// The plan.
        plan: TeamPlan,
        /// Highest robot number of the plan.
        max: u8,
    },
    /// The value does not fit.
    #[error("value {value} out of range 0..={max} for a {kind} message in the {plan} plan")]
    Value {
        /// The value asked for.
        value: u16,
        /// Highest value.
        max: u16,
        /// "short" or "long".
        kind: &'static str,
        /// The plan.
        plan: TeamPlan,
    },
    /// The message could not be built.
    #[error(transparent)]
    Message(#[from] MessageError),
}

/// A message as a team plan reads it: which robot, short or long, and the value.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TeamMessage {
    /// Robot number (0 … robots − 1).
    pub robot: u8,
    /// Two frames (long) or one (short).
    pub long: bool,
    /// The value.
    pub value: u16,
}

impl TeamPlan {
    /// Both plans.
    pub const ALL: [TeamPlan; 3] = [TeamPlan::Three, TeamPlan::Six, TeamPlan::Checked];

    /// Number of robots.
    pub fn robots(self) -> u8 {
        match self {
            TeamPlan::Three | TeamPlan::Checked => SENDER_COUNT as u8,
            TeamPlan::Six => 2 * SENDER_COUNT as u8,
        }
    }

    /// Values of a short message (0 … this − 1).
    pub fn short_values(self) -> u16 {
        match self {
            TeamPlan::Three => u16::from(DATA_VALUES),
            TeamPlan::Six | TeamPlan::Checked => u16::from(BANK_VALUES),
        }
    }

    /// Values per frame of a long message (`long_values` is its square).
    fn long_frame_values(self) -> u16 {
        match self {
            TeamPlan::Checked => u16::from(CHECKED_LONG_VALUES),
            _ => self.short_values(),
        }
    }

    /// Whether a frame carrying `data` can only be a long message's frame under this plan
    /// (the checked plan's data 10 … 20): the decoder then knows, on the first slot, that a
    /// second must follow.
    pub(crate) fn frame_is_long_only(self, data: u8) -> bool {
        self == TeamPlan::Checked && data >= BANK_VALUES
    }

    /// Whether a frame carrying `data` can only be a short message under this plan (the
    /// checked plan's data 0 … 9): no long message begins with it.
    pub(crate) fn frame_is_short_only(self, data: u8) -> bool {
        self == TeamPlan::Checked && data < BANK_VALUES
    }

    /// Values of a long message (0 … this − 1).
    pub fn long_values(self) -> u16 {
        self.long_frame_values() * self.long_frame_values()
    }

    /// The name used on the command line and in configuration ("three", "six").
    pub fn name(self) -> &'static str {
        match self {
            TeamPlan::Three => "three",
            TeamPlan::Six => "six",
            TeamPlan::Checked => "checked",
        }
    }

    /// The frames' data values for robot `robot`'s values (bank offset applied) in a
    /// short (`long` false) or a long message.
    fn data(self, robot: u8, value: u8, long: bool) -> u8 {
        match self {
            TeamPlan::Three => value,
            TeamPlan::Six => (robot / SENDER_COUNT as u8) * BANK_VALUES + value,
            TeamPlan::Checked => {
                if long {
                    BANK_VALUES + value
                } else {
                    value
                }
            }
        }
    }

    /// The message that says `m` under this plan.
    pub fn encode(self, m: TeamMessage) -> Result<Message, TeamError> {
        if m.robot >= self.robots() {
            return Err(TeamError::Robot {
                robot: m.robot,
                plan: self,
                max: self.robots() - 1,
            });
        }
        let sender = Sender::ALL[usize::from(m.robot) % SENDER_COUNT];
        let n = self.long_frame_values();
        let (max, kind) = if m.long {
            (self.long_values(), "long")
        } else {
            (self.short_values(), "short")
        };
        if m.value >= max {
            return Err(TeamError::Value {
                value: m.value,
                max: max - 1,
                kind,
                plan: self,
            });
        }
        Ok(if m.long {
            let first = self.data(m.robot, (m.value / n) as u8, true);
            let second = self.data(m.robot, (m.value % n) as u8, true);
            Message::long(
                sender,
                u16::from(DATA_VALUES) * u16::from(first) + u16::from(second),
            )?
        } else {
            Message::short(sender, self.data(m.robot, m.value as u8, false))?
        })
    }

    /// What `m` says under this plan, or `None` if this plan cannot have sent it.
    pub fn decode(self, m: &Message) -> Option<TeamMessage> {
        let sender = m.sender().index();
        match self {
            TeamPlan::Three => Some(TeamMessage {
                robot: sender,
                long: matches!(m, Message::Long { .. }),
                value: m.value(),
            }),
            TeamPlan::Six => {
                let split = |data: u8| {
                    (data < 2 * BANK_VALUES).then_some((data / BANK_VALUES, data % BANK_VALUES))
                };
                match *m {
                    Message::Short { data, .. } => {
                        let (bank, v) = split(data)?;
                        Some(TeamMessage {
                            robot: sender + SENDER_COUNT as u8 * bank,
                            long: false,
                            value: u16::from(v),
                        })
                    }
                    Message::Long { value, .. } => {
                        let first = (value / u16::from(DATA_VALUES)) as u8;
                        let second = (value % u16::from(DATA_VALUES)) as u8;
                        let (b1, v1) = split(first)?;
                        let (b2, v2) = split(second)?;
                        (b1 == b2).then_some(TeamMessage {
                            robot: sender + SENDER_COUNT as u8 * b1,
                            long: true,
                            value: u16::from(v1) * u16::from(BANK_VALUES) + u16::from(v2),
                        })
                    }
                }
            }
            TeamPlan::Checked => match *m {
                Message::Short { data, .. } => (data < BANK_VALUES).then_some(TeamMessage {
                    robot: sender,
                    long: false,
                    value: u16::from(data),
                }),
                Message::Long { value, .. } => {
                    let first = (value / u16::from(DATA_VALUES)) as u8;
                    let second = (value % u16::from(DATA_VALUES)) as u8;
                    let n = u16::from(CHECKED_LONG_VALUES);
                    // Lazily: the subtraction is only valid once both halves are checked
                    // (a decoded message is untrusted input and must not overflow).
                    (first >= BANK_VALUES && second >= BANK_VALUES).then(|| TeamMessage {
                        robot: sender,
                        long: true,
                        value: u16::from(first - BANK_VALUES) * n + u16::from(second - BANK_VALUES),
                    })
                }
            },
        }
    }
}

impl fmt::Display for TeamPlan {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for TeamPlan {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "three" | "3" => Ok(TeamPlan::Three),
            "six" | "6" => Ok(TeamPlan::Six),
            "checked" => Ok(TeamPlan::Checked),
            other => Err(format!(
                "unknown team plan {other:?} (three, six or checked)"
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_team_message_round_trips_and_nothing_else_decodes() {
        for plan in TeamPlan::ALL {
            let mut seen = std::collections::HashSet::new();
            for robot in 0..plan.robots() {
                for long in [false, true] {
                    let max = if long {
                        plan.long_values()
                    } else {
                        plan.short_values()
                    };
                    for value in 0..max {
                        let m = TeamMessage { robot, long, value };
                        let air = plan.encode(m).expect("in range");
                        assert!(seen.insert(air), "{plan}: {m:?} shares its frames");
                        assert_eq!(plan.decode(&air), Some(m), "{plan}: {m:?} via {air}");
                    }
                    let too_big = TeamMessage {
                        robot,
                        long,
                        value: max,
                    };
                    assert!(plan.encode(too_big).is_err(), "{plan}: {too_big:?}");
                }
            }
            let nobody = TeamMessage {
                robot: plan.robots(),
                long: false,
                value: 0,
            };
            assert!(plan.encode(nobody).is_err());
        }
        // What the six-robot plan cannot have sent: data 20, and frames in two banks.
        let six = TeamPlan::Six;
        assert_eq!(
            six.decode(&Message::short(Sender::Goalkeeper, 20).unwrap()),
            None
        );
        let mixed = Message::long(Sender::Goalkeeper, 21 * 3 + 14).unwrap();
        assert_eq!(
            six.decode(&mixed),
            None,
            "banks 0 and 1 in one long message"
        );
        // Robot 4 is the left attacker's basic in bank 1.
        let m = six
            .encode(TeamMessage {
                robot: 4,
                long: false,
                value: 7,
            })
            .unwrap();
        assert_eq!(m, Message::short(Sender::LeftAttacker, 17).unwrap());
    }

    /// Every way a long message of the checked plan can come out cut, and two shorts run
    /// together, is a message the plan cannot have sent (the wrong messages of #33's
    /// room tests: long (15, 2) heard as short 15, long (10, 8) as short 8, a long
    /// message's first frame read while another robot sounded).
    #[test]
    fn a_checked_long_message_cut_to_one_frame_is_never_a_message() {
        let plan = TeamPlan::Checked;
        for robot in 0..3 {
            for value in 0..plan.long_values() {
                let long = TeamMessage {
                    robot,
                    long: true,
                    value,
                };
                let air = plan.encode(long).unwrap();
                let frames = air.frames();
                for f in frames {
                    let cut = Message::short(f.sender, f.data).unwrap();
                    assert_eq!(plan.decode(&cut), None, "{long:?} cut to {cut}");
                    assert!(
                        plan.frame_is_long_only(f.data) && !plan.frame_is_short_only(f.data),
                        "{long:?}: its frame {f:?} must read as a long message's only"
                    );
                }
            }
            for a in 0..plan.short_values() {
                let short = plan
                    .encode(TeamMessage {
                        robot,
                        long: false,
                        value: a,
                    })
                    .unwrap();
                for f in short.frames() {
                    assert!(
                        plan.frame_is_short_only(f.data) && !plan.frame_is_long_only(f.data),
                        "short {a}: its frame {f:?} must read as a short message's only"
                    );
                }
                for b in 0..plan.short_values() {
                    let sender = Sender::ALL[usize::from(robot)];
                    let together = Message::long(sender, 21 * a + b).unwrap();
                    assert_eq!(
                        plan.decode(&together),
                        None,
                        "shorts {a} and {b} run together"
                    );
                }
            }
        }
        assert_eq!((plan.short_values(), plan.long_values()), (10, 121));
        assert_eq!("checked".parse::<TeamPlan>(), Ok(TeamPlan::Checked));
    }
}
