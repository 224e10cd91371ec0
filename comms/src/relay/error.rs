//! The relay's `ERR` codes.

use std::fmt;

/// The code in an `ERR code text` line. Codes are stable; the text is for people.
///
/// | code | meaning |
/// |------|---------|
/// | 400 | unknown command word |
/// | 401 | wrong number of arguments |
/// | 402 | line longer than the limit (4 KiB): the whole line is discarded |
/// | 403 | line is not UTF-8 text |
/// | 404 | `GETV`: no value bound to the key; `DELW`: pattern not watched |
/// | 406 | `GETV key max_age_ms`: the value is older than `max_age_ms` |
/// | 410 | malformed key (one that is not ASCII too) |
/// | 411 | malformed watch pattern, or one that is not ASCII (it could never match a key) |
/// | 412 | malformed value literal |
/// | 413 | `REFR` period is not whole milliseconds in 0..=3600000 |
/// | 420 | write refused: the key belongs to another robot |
/// | 421 | write refused: wrong kind of key (a talk queue has no value to get or set; only own queues can be posted to) |
/// | 422 | write refused: the value does not fit in one frame |
/// | 423 | write refused: the key is the daemon's own, read-only to clients (`local.var.team.*` while its team layer runs, `local.var.gc.*` while its GameController listener runs, `local.var.huddle.*`: its counters) |
/// | 424 | `CLOK` refused: the budget's game clock follows the league's referee system (a GameController's figures are in force on this robot: the daemon's listener heard one, and its last figure stays in force through a silence); the clock is its, not a client's |
/// | 429 | limit reached: too many watch patterns, talk queues, or keys (`SETV` of a new `local` key beyond the local-key limit, or of a new own global beyond the per-robot limit) |
/// | 430 | post refused: the talk queue's retention buffer is full of messages teammates may still need; retry later |
/// | 503 | not available here (e.g. posting without a replica) |
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ErrCode {
    /// 400
    UnknownCommand,
    /// 401
    Usage,
    /// 402
    LineTooLong,
    /// 403
    NotText,
    /// 404
    NotFound,
    /// 406
    TooOld,
    /// 410
    BadKey,
    /// 411
    BadPattern,
    /// 412
    BadValue,
    /// 413
    BadPeriod,
    /// 420
    NotOwner,
    /// 421
    WrongKind,
    /// 422
    TooLarge,
    /// 423
    ReadOnly,
    /// 424
    ClockOwned,
    /// 429
    TooMany,
    /// 430
    QueueFull,
    /// 503
    Unavailable,
}

impl ErrCode {
    /// The number sent on the wire.
    pub fn number(self) -> u16 {
        match self {
            ErrCode::UnknownCommand => 400,
            ErrCode::Usage => 401,
            ErrCode::LineTooLong => 402,
            ErrCode::NotText => 403,
            ErrCode::NotFound => 404,
            ErrCode::TooOld => 406,
            ErrCode::BadKey => 410,
            ErrCode::BadPattern => 411,
            ErrCode::BadValue => 412,
            ErrCode::BadPeriod => 413,
            ErrCode::NotOwner => 420,
            ErrCode::WrongKind => 421,
            ErrCode::TooLarge => 422,
            ErrCode::ReadOnly => 423,
            ErrCode::ClockOwned => 424,
            ErrCode::TooMany => 429,
            ErrCode::QueueFull => 430,
            ErrCode::Unavailable => 503,
        }
    }
}

impl fmt::Display for ErrCode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.number())
    }
}
