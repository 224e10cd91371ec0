//! Virtual time: nanoseconds since the start of a simulation (or of a real-socket driver).

use std::fmt;
use std::ops::{Add, AddAssign, Sub};
use std::time::Duration;

/// A point in virtual time: whole nanoseconds since the start of the run.
///
/// It is the simulator's global clock (the "true" time of the network); each node reads its
/// own clock through [`crate::NodeClock`]. A real-socket driver using [`crate::LinkModel`]
/// passes the time elapsed since it started. Arithmetic saturates instead of wrapping: a
/// `u64` of nanoseconds lasts 584 years, so saturation only guards nonsense inputs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Time(u64);

impl Time {
    /// The start of the run.
    pub const ZERO: Time = Time(0);
    /// The latest representable time.
    pub const MAX: Time = Time(u64::MAX);

    /// `ns` nanoseconds after the start.
    pub const fn from_nanos(ns: u64) -> Time {
        Time(ns)
    }

    /// `us` microseconds after the start (saturating).
    pub const fn from_micros(us: u64) -> Time {
        Time(us.saturating_mul(1_000))
    }

    /// `ms` milliseconds after the start (saturating).
    pub const fn from_millis(ms: u64) -> Time {
        Time(ms.saturating_mul(1_000_000))
    }

    /// `s` whole seconds after the start (saturating).
    pub const fn from_secs(s: u64) -> Time {
        Time(s.saturating_mul(1_000_000_000))
    }

    /// `s` seconds after the start, rounded to the nearest nanosecond; negative or NaN
    /// inputs give [`Time::ZERO`], huge ones [`Time::MAX`].
    pub fn from_secs_f64(s: f64) -> Time {
        let ns = (s * 1e9).round();
        if ns.is_nan() || ns <= 0.0 {
            Time::ZERO
        } else if ns >= u64::MAX as f64 {
            Time::MAX
        } else {
            Time(ns as u64)
        }
    }

    /// Nanoseconds since the start.
    pub const fn as_nanos(self) -> u64 {
        self.0
    }

    /// Seconds since the start.
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }

    /// The time since the start as a [`Duration`].
    pub const fn since_start(self) -> Duration {
        Duration::from_nanos(self.0)
    }

    /// `self - earlier`, or zero if `earlier` is later.
    pub const fn saturating_duration_since(self, earlier: Time) -> Duration {
        Duration::from_nanos(self.0.saturating_sub(earlier.0))
    }

    /// `self - earlier`, or `None` if `earlier` is later.
    pub fn checked_duration_since(self, earlier: Time) -> Option<Duration> {
        self.0.checked_sub(earlier.0).map(Duration::from_nanos)
    }
}

/// Nanoseconds in a [`Duration`], saturating at `u64::MAX`.
pub(crate) fn duration_ns(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

impl Add<Duration> for Time {
    type Output = Time;
    fn add(self, rhs: Duration) -> Time {
        Time(self.0.saturating_add(duration_ns(rhs)))
    }
}

impl AddAssign<Duration> for Time {
    fn add_assign(&mut self, rhs: Duration) {
        *self = *self + rhs;
    }
}

impl Sub<Duration> for Time {
    type Output = Time;
    fn sub(self, rhs: Duration) -> Time {
        Time(self.0.saturating_sub(duration_ns(rhs)))
    }
}

impl Sub<Time> for Time {
    type Output = Duration;
    /// Saturating: a later `rhs` gives zero.
    fn sub(self, rhs: Time) -> Duration {
        self.saturating_duration_since(rhs)
    }
}

impl fmt::Display for Time {
    /// Seconds with nine decimals, e.g. `12.050000000s`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}.{:09}s",
            self.0 / 1_000_000_000,
            self.0 % 1_000_000_000
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constructors_agree_and_arithmetic_saturates() {
        assert_eq!(Time::from_millis(1500), Time::from_micros(1_500_000));
        assert_eq!(Time::from_secs_f64(1.5), Time::from_millis(1500));
        assert_eq!(
            Time::from_secs_f64(-3.0),
            Time::ZERO,
            "negative seconds clamp to zero"
        );
        assert_eq!(
            Time::MAX + Duration::from_secs(1),
            Time::MAX,
            "addition saturates"
        );
        assert_eq!(Time::ZERO - Duration::from_secs(1), Time::ZERO);
        assert_eq!(Time::from_millis(5) - Time::from_millis(7), Duration::ZERO);
        assert_eq!(
            Time::from_millis(2) + Duration::from_millis(3),
            Time::from_millis(5)
        );
        assert_eq!(
            Time::from_nanos(12_050_000_000).to_string(),
            "12.050000000s"
        );
    }
}
