//! One relay command line, parsed (mini-redis style: check the words, then build a typed
//! command; nothing here touches the blackboard).

use crate::key::{Key, KeyError};
use crate::literal::{parse_literal, LiteralError};
use crate::pattern::{Pattern, PatternError};
use crate::value::Value;

use super::error::ErrCode;

/// Longest `REFR` period accepted: one hour.
pub const MAX_REFRESH_MS: u64 = 3_600_000;

/// A parsed command.
#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    /// `GETV key [max_age_ms]`: with a maximum age, an older value is refused
    /// (`ERR 406`).
    Get(Key, Option<u64>),
    /// `SETV key value` (on a `talk` key: post a message).
    Set(Key, Value),
    /// `SETP key value`: a `SETV` of a global value that may draw on a league budget's
    /// reserve for priority items at once (a goer change, a kick report).
    SetPriority(Key, Value),
    /// `CLOK secs`: the game clock (seconds of play left in the game, as the referee's
    /// clock says) that a league budget paces itself over.
    GameClock(f64),
    /// `ADDW pattern`
    AddWatch(Pattern),
    /// `DELW pattern`
    DelWatch(Pattern),
    /// `CLRW`
    ClearWatches,
    /// `LSTW`
    ListWatches,
    /// `REFR ms` (0: push each change as it happens).
    Refresh(u64),
    /// `QUIT`
    Quit,
}

/// Why a line is not a command: the `ERR` code and text to answer with.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Rejected {
    /// The code.
    pub code: ErrCode,
    /// A one-line explanation.
    pub text: String,
}

impl Rejected {
    pub(crate) fn new(code: ErrCode, text: impl Into<String>) -> Rejected {
        Rejected {
            code,
            text: text.into(),
        }
    }
}

impl From<KeyError> for Rejected {
    fn from(e: KeyError) -> Rejected {
        Rejected::new(ErrCode::BadKey, e.to_string())
    }
}

impl From<PatternError> for Rejected {
    fn from(e: PatternError) -> Rejected {
        Rejected::new(ErrCode::BadPattern, e.to_string())
    }
}

impl From<LiteralError> for Rejected {
    fn from(e: LiteralError) -> Rejected {
        Rejected::new(ErrCode::BadValue, e.to_string())
    }
}

/// Splits off the first whitespace-separated word.
fn word(s: &str) -> (&str, &str) {
    let s = s.trim_start();
    match s.find(char::is_whitespace) {
        Some(i) => (&s[..i], &s[i..]),
        None => (s, ""),
    }
}

/// One argument and nothing after it.
fn single<'a>(verb: &str, rest: &'a str, what: &str) -> Result<&'a str, Rejected> {
    let (arg, after) = word(rest);
    if arg.is_empty() {
        return Err(Rejected::new(
            ErrCode::Usage,
            format!("usage: {verb} {what}"),
        ));
    }
    if !after.trim().is_empty() {
        return Err(Rejected::new(
            ErrCode::Usage,
            format!("usage: {verb} {what} (one argument)"),
        ));
    }
    Ok(arg)
}

fn none(verb: &str, rest: &str) -> Result<(), Rejected> {
    if rest.trim().is_empty() {
        Ok(())
    } else {
        Err(Rejected::new(
            ErrCode::Usage,
            format!("usage: {verb} (no arguments)"),
        ))
    }
}

impl Command {
    /// Parses one line (without its line terminator). Command words are
    /// case-insensitive; keys, patterns and values are not.
    pub fn parse(line: &str) -> Result<Command, Rejected> {
        let (verb, rest) = word(line);
        let upper = verb.to_ascii_uppercase();
        match upper.as_str() {
            "GETV" => {
                let usage = || Rejected::new(ErrCode::Usage, "usage: GETV key [max_age_ms]");
                let (key, rest) = word(rest);
                let (max_age, after) = word(rest);
                if key.is_empty() || !after.trim().is_empty() {
                    return Err(usage());
                }
                let digits = max_age.bytes().all(|b| b.is_ascii_digit());
                let max_age = match max_age.parse::<u64>() {
                    _ if max_age.is_empty() => None,
                    Ok(ms) if digits => Some(ms),
                    _ => {
                        return Err(Rejected::new(
                            ErrCode::Usage,
                            format!("bad max_age_ms {max_age:?}: expected whole milliseconds"),
                        ))
                    }
                };
                Ok(Command::Get(Key::parse(key)?, max_age))
            }
            "SETV" | "SETP" => {
                let (key, value) = word(rest);
                if key.is_empty() || value.trim().is_empty() {
                    return Err(Rejected::new(
                        ErrCode::Usage,
                        format!("usage: {verb} key value"),
                    ));
                }
                let (key, value) = (Key::parse(key)?, parse_literal(value)?);
                Ok(if verb == "SETP" {
                    Command::SetPriority(key, value)
                } else {
                    Command::Set(key, value)
                })
            }
            "CLOK" => {
                let secs = single("CLOK", rest, "secs")?;
                match secs.parse::<f64>() {
                    Ok(s) if s.is_finite() && (0.0..=86_400.0).contains(&s) => {
                        Ok(Command::GameClock(s))
                    }
                    _ => Err(Rejected::new(
                        ErrCode::BadValue,
                        format!("bad game clock {secs:?}: expected seconds 0..=86400"),
                    )),
                }
            }
            "ADDW" => Ok(Command::AddWatch(Pattern::parse(single(
                "ADDW", rest, "pattern",
            )?)?)),
            "DELW" => Ok(Command::DelWatch(Pattern::parse(single(
                "DELW", rest, "pattern",
            )?)?)),
            "CLRW" => none("CLRW", rest).map(|()| Command::ClearWatches),
            "LSTW" => none("LSTW", rest).map(|()| Command::ListWatches),
            "REFR" => {
                let ms = single("REFR", rest, "ms")?;
                let digits = ms.bytes().all(|b| b.is_ascii_digit());
                match ms.parse::<u64>() {
                    Ok(n) if digits && n <= MAX_REFRESH_MS => Ok(Command::Refresh(n)),
                    _ => Err(Rejected::new(
                        ErrCode::BadPeriod,
                        format!(
                            "bad period {ms:?}: expected whole milliseconds 0..={MAX_REFRESH_MS}"
                        ),
                    )),
                }
            }
            "QUIT" => none("QUIT", rest).map(|()| Command::Quit),
            _ => Err(Rejected::new(
                ErrCode::UnknownCommand,
                format!(
                    "unknown command {:?} (GETV SETV SETP CLOK ADDW DELW CLRW LSTW REFR QUIT)",
                    verb.chars().take(16).collect::<String>()
                ),
            )),
        }
    }
}
