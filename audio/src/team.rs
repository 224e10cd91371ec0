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
}

/// Values per frame in a [`TeamPlan::Six`] bank.
const BANK_VALUES: u8 = 10;

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
    pub const ALL: [TeamPlan; 2] = [TeamPlan::Three, TeamPlan::Six];

    /// Number of robots.
    pub fn robots(self) -> u8 {
        match self {
            TeamPlan::Three => SENDER_COUNT as u8,
            TeamPlan::Six => 2 * SENDER_COUNT as u8,
        }
    }

    /// Values of a short message (0 … this − 1).
    pub fn short_values(self) -> u16 {
        match self {
            TeamPlan::Three => u16::from(DATA_VALUES),
            TeamPlan::Six => u16::from(BANK_VALUES),
        }
    }

    /// Values of a long message (0 … this − 1).
    pub fn long_values(self) -> u16 {
        self.short_values() * self.short_values()
    }

    /// The name used on the command line and in configuration ("three", "six").
    pub fn name(self) -> &'static str {
        match self {
            TeamPlan::Three => "three",
            TeamPlan::Six => "six",
        }
    }

    /// The frames' data values for robot `robot`'s values (bank offset applied).
    fn data(self, robot: u8, value: u8) -> u8 {
        match self {
            TeamPlan::Three => value,
            TeamPlan::Six => (robot / SENDER_COUNT as u8) * BANK_VALUES + value,
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
        let n = self.short_values();
        let (max, kind) = if m.long {
            (self.long_values(), "long")
        } else {
            (n, "short")
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
            let first = self.data(m.robot, (m.value / n) as u8);
            let second = self.data(m.robot, (m.value % n) as u8);
            Message::long(
                sender,
                u16::from(DATA_VALUES) * u16::from(first) + u16::from(second),
            )?
        } else {
            Message::short(sender, self.data(m.robot, m.value as u8))?
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
            other => Err(format!("unknown team plan {other:?} (three or six)")),
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
}
