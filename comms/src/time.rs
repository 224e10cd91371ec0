//! The local monotonic clock, as the caller hands it in.
//!
//! comms never reads a clock: every input carries `now`, so the same code runs under
//! the real driver (which reads `std::time::Instant`) and under virtual time in netsim.

use std::fmt;
use std::ops::{Add, AddAssign};
use std::time::Duration;

/// A point on this robot's monotonic clock, in microseconds since an arbitrary origin
/// chosen by the driver (typically process start). Only differences are meaningful, and
/// only between instants of the same robot.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Instant(u64);

impl Instant {
    /// The clock's origin.
    pub const ZERO: Instant = Instant(0);

    /// An instant `micros` microseconds after the origin.
    pub const fn from_micros(micros: u64) -> Self {
        Instant(micros)
    }

    /// Microseconds since the origin.
    pub const fn as_micros(self) -> u64 {
        self.0
    }

    /// Time elapsed from `earlier` to `self`, or zero if `earlier` is later.
    pub fn saturating_duration_since(self, earlier: Instant) -> Duration {
        Duration::from_micros(self.0.saturating_sub(earlier.0))
    }

    /// `self - d`, clamped at the origin (a sender may report an age longer than our
    /// clock has run).
    pub fn saturating_sub(self, d: Duration) -> Instant {
        Instant(self.0.saturating_sub(duration_to_micros(d)))
    }
}

/// Whole microseconds of `d`, saturating at `u64::MAX`.
pub(crate) fn duration_to_micros(d: Duration) -> u64 {
    u64::try_from(d.as_micros()).unwrap_or(u64::MAX)
}

impl Add<Duration> for Instant {
    type Output = Instant;
    /// Saturates at the end of time instead of overflowing.
    fn add(self, d: Duration) -> Instant {
        Instant(self.0.saturating_add(duration_to_micros(d)))
    }
}

impl AddAssign<Duration> for Instant {
    fn add_assign(&mut self, d: Duration) {
        *self = *self + d;
    }
}

impl fmt::Display for Instant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{:06}s", self.0 / 1_000_000, self.0 % 1_000_000)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arithmetic_saturates_instead_of_wrapping() {
        let t = Instant::from_micros(1_500);
        assert_eq!((t + Duration::from_millis(2)).as_micros(), 3_500);
        assert_eq!(
            t.saturating_duration_since(Instant::from_micros(2_000)),
            Duration::ZERO,
            "an earlier instant minus a later one is zero, not a wrap-around"
        );
        assert_eq!(t.saturating_sub(Duration::from_secs(1)), Instant::ZERO);
        assert_eq!(
            (Instant::from_micros(u64::MAX - 1) + Duration::from_secs(1)).as_micros(),
            u64::MAX
        );
        assert_eq!(Instant::from_micros(2_000_001).to_string(), "2.000001s");
    }
}
