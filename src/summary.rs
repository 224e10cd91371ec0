//! Summaries of measured samples.

/// The `p`-quantile (`p` in [0, 1], clamped) of samples sorted in ascending order, `None`
/// if there are none.
///
/// Definition: the sample at 0-based index round(p·(n − 1)), halves rounded up; no
/// interpolation, so the answer is always one of the samples (the one nearest the
/// linear-interpolation position). This is not the nearest-rank definition ⌈p·n⌉ that
/// `netsim::LinkStats::delay_percentiles` uses: on four samples, p = 0.5 gives the third
/// here and the second there.
///
/// Generic over the sample type, so durations need no conversion:
///
/// ```
/// use huddle::summary::percentile;
/// use std::time::Duration;
///
/// let ms = [10, 20, 30, 40].map(Duration::from_millis);
/// assert_eq!(percentile(&ms, 0.5), Some(Duration::from_millis(30)));
/// assert_eq!(percentile(&[1.0, 2.0, 3.0], 0.99), Some(3.0));
/// assert_eq!(percentile::<f64>(&[], 0.5), None);
/// ```
pub fn percentile<T: Copy>(sorted: &[T], p: f64) -> Option<T> {
    let last = sorted.len().checked_sub(1)?;
    let i = (last as f64 * p.clamp(0.0, 1.0)).round() as usize;
    Some(sorted[i])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_index_is_the_rounded_interpolation_position() {
        let v: Vec<f64> = (0..101).map(f64::from).collect();
        assert_eq!(percentile(&v, 0.0), Some(0.0));
        assert_eq!(percentile(&v, 0.5), Some(50.0));
        assert_eq!(percentile(&v, 0.99), Some(99.0));
        assert_eq!(percentile(&v, 1.0), Some(100.0));
        // Five samples: p = 0.99 sits at 3.96, the last sample; p = 0.375 at 1.5 rounds up.
        let five = [1, 2, 3, 4, 5];
        assert_eq!(percentile(&five, 0.99), Some(5));
        assert_eq!(percentile(&five, 0.375), Some(3));
        assert_eq!(percentile(&five, 7.0), Some(5), "p is clamped");
    }
}
