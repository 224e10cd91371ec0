//! Per-node clocks: an offset and a constant drift against the simulator's global time.

use std::time::Duration;

use crate::time::{duration_ns, Time};

/// The largest drift a [`NodeClock`] accepts, in parts per million (10%). Real quartz
/// drifts by tens of ppm; the bound keeps the clock invertible with plenty of room.
pub const MAX_DRIFT_PPM: f64 = 100_000.0;

const PPB_PER_PPM: f64 = 1_000.0;
const NS_PER_S: i128 = 1_000_000_000;

/// Why a [`NodeClock`] could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ClockError {
    /// The drift is NaN or beyond ±[`MAX_DRIFT_PPM`].
    #[error("clock drift {drift_ppm} ppm is not a number within ±{MAX_DRIFT_PPM} ppm")]
    DriftOutOfRange {
        /// The rejected drift.
        drift_ppm: f64,
    },
}

/// A node's own clock: `local = offset + global · (1 + drift)`.
///
/// A robot never sees the global time; it timestamps receptions and sets its timers on
/// this clock. The harness converts with [`NodeClock::to_local`] (a delivery's global time
/// to what the node reads) and [`NodeClock::to_global`] (a node's local deadline to the
/// global time at which the simulator must wake it).
///
/// Drift is stored in whole parts per billion so that the conversion is exact integer
/// arithmetic. `to_local` is monotone; `to_global(l)` is the **earliest** global time at
/// which the clock reads at least `l`, so a timer converted with it never fires early:
/// `to_local(to_global(l)) >= l` always, and `to_global(to_local(g)) == g` whenever the
/// drift is ≥ 0 (with negative drift several nanoseconds of global time can share one
/// local reading, and the earliest is returned).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct NodeClock {
    offset_ns: u64,
    drift_ppb: i64,
}

impl NodeClock {
    /// A perfect clock: local time equals global time.
    pub const IDEAL: NodeClock = NodeClock {
        offset_ns: 0,
        drift_ppb: 0,
    };

    /// A clock that reads `offset` at global time zero and gains `drift_ppm` microseconds
    /// per second (negative: loses).
    pub fn new(offset: Duration, drift_ppm: f64) -> Result<NodeClock, ClockError> {
        if !drift_ppm.is_finite() || drift_ppm.abs() > MAX_DRIFT_PPM {
            return Err(ClockError::DriftOutOfRange { drift_ppm });
        }
        Ok(NodeClock {
            offset_ns: duration_ns(offset),
            drift_ppb: (drift_ppm * PPB_PER_PPM).round() as i64,
        })
    }

    /// The reading at global time zero.
    pub fn offset(&self) -> Duration {
        Duration::from_nanos(self.offset_ns)
    }

    /// The drift in parts per million.
    pub fn drift_ppm(&self) -> f64 {
        self.drift_ppb as f64 / PPB_PER_PPM
    }

    /// What this clock reads at global time `global` (saturating at [`Time::MAX`]).
    pub fn to_local(&self, global: Time) -> Time {
        if self.drift_ppb == 0 {
            // The common case, without 128-bit division.
            return Time::from_nanos(global.as_nanos().saturating_add(self.offset_ns));
        }
        let g = i128::from(global.as_nanos());
        let gained = (g * i128::from(self.drift_ppb)).div_euclid(NS_PER_S);
        let local = i128::from(self.offset_ns) + g + gained;
        Time::from_nanos(u64::try_from(local.max(0)).unwrap_or(u64::MAX))
    }

    /// The earliest global time at which this clock reads at least `local`; a local time
    /// before the clock's reading at global zero gives [`Time::ZERO`].
    pub fn to_global(&self, local: Time) -> Time {
        let l = i128::from(local.as_nanos());
        let since_offset = l - i128::from(self.offset_ns);
        if since_offset <= 0 {
            return Time::ZERO;
        }
        // Invert the linear part, then correct the rounding by stepping at most a few ns.
        let estimate = since_offset * NS_PER_S / (NS_PER_S + i128::from(self.drift_ppb));
        let mut g = u64::try_from(estimate.max(0)).unwrap_or(u64::MAX);
        while self.to_local(Time::from_nanos(g)) < local {
            if g == u64::MAX {
                return Time::MAX;
            }
            g += 1;
        }
        while g > 0 && self.to_local(Time::from_nanos(g - 1)) >= local {
            g -= 1;
        }
        Time::from_nanos(g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn drift_beyond_ten_percent_is_refused() {
        assert!(NodeClock::new(Duration::ZERO, 150_000.0).is_err());
        assert!(NodeClock::new(Duration::ZERO, f64::NAN).is_err());
        assert!(NodeClock::new(Duration::ZERO, -99_999.0).is_ok());
    }

    #[test]
    fn a_fast_clock_reads_offset_plus_scaled_time() {
        // 3 s ahead, 50 ppm fast: after 1000 s of global time it has gained 50 ms.
        let clock = NodeClock::new(Duration::from_secs(3), 50.0).unwrap();
        assert_eq!(
            clock.to_local(Time::from_secs(1000)),
            Time::from_millis(1_003_050)
        );
        assert_eq!(
            clock.to_global(Time::from_millis(1_003_050)),
            Time::from_secs(1000)
        );
        assert_eq!(
            clock.to_global(Time::from_secs(1)),
            Time::ZERO,
            "before offset"
        );
    }
}
