//! A warning that is said at most once per period, with a count of what it stands for.

use std::time::Duration;

use comms::Instant;

/// Rate limit for a repeated warning: the first occurrence is reported at once, then at
/// most one report per `period`, each carrying how many occurrences it stands for (the
/// ones kept quiet since the last report, plus this one). A pure function of the times
/// it is given: no clock inside.
///
/// ```
/// use std::time::Duration;
/// use comms::Instant;
/// use driver::RateLimit;
///
/// let mut limit = RateLimit::new(Duration::from_secs(10));
/// let s = |secs: u64| Instant::from_micros(secs * 1_000_000);
/// assert_eq!(limit.record(s(100)), Some(1)); // said at once
/// assert_eq!(limit.record(s(101)), None); // kept quiet...
/// assert_eq!(limit.record(s(105)), None);
/// assert_eq!(limit.record(s(110)), Some(3)); // ...and counted in the next report
/// ```
#[derive(Clone, Debug)]
pub struct RateLimit {
    period: Duration,
    last_report: Option<Instant>,
    quiet: u64,
}

impl RateLimit {
    /// At most one report per `period`.
    pub fn new(period: Duration) -> RateLimit {
        RateLimit {
            period,
            last_report: None,
            quiet: 0,
        }
    }

    /// Records one occurrence at `now`. `Some(n)`: report now, for `n` occurrences since
    /// the previous report (this one included); `None`: stay quiet (it is counted).
    pub fn record(&mut self, now: Instant) -> Option<u64> {
        let due = match self.last_report {
            None => true,
            Some(last) => now.saturating_duration_since(last) >= self.period,
        };
        if !due {
            self.quiet = self.quiet.saturating_add(1);
            return None;
        }
        self.last_report = Some(now);
        let n = self.quiet.saturating_add(1);
        self.quiet = 0;
        Some(n)
    }

    /// Occurrences recorded since the last report and not reported yet.
    pub fn pending(&self) -> u64 {
        self.quiet
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(ms: u64) -> Instant {
        Instant::from_micros(ms * 1000)
    }

    #[test]
    fn the_first_is_said_then_one_report_per_period_with_the_count() {
        let mut limit = RateLimit::new(Duration::from_secs(10));
        assert_eq!(limit.record(ms(5_000)), Some(1));
        for t in [5_000, 5_001, 9_000, 14_999] {
            assert_eq!(limit.record(ms(t)), None, "at {t} ms");
        }
        assert_eq!(limit.pending(), 4);
        // Exactly one period after the last report: due, for the 4 quiet ones and this.
        assert_eq!(limit.record(ms(15_000)), Some(5));
        assert_eq!(limit.pending(), 0);
        assert_eq!(limit.record(ms(24_999)), None);
        // A long silence: the next one is said at once, counting the one kept quiet.
        assert_eq!(limit.record(ms(600_000)), Some(2));
        assert_eq!(limit.record(ms(610_000)), Some(1));
    }

    #[test]
    fn time_going_backwards_keeps_it_quiet_and_never_panics() {
        let mut limit = RateLimit::new(Duration::from_secs(10));
        assert_eq!(limit.record(ms(20_000)), Some(1));
        assert_eq!(limit.record(ms(0)), None);
        assert_eq!(limit.record(ms(30_000)), Some(2));
    }
}
