//! Per-link statistics.

use std::time::Duration;

use crate::link::DropReason;

/// What happened on one one-way link (or, merged, on several).
///
/// Every packet offered to the link is counted in `sent`; each copy either arrives
/// (`delivered`), is dropped (`lost`, by reason), or is still in flight, so
/// `sent + duplicated == delivered + lost_total() + in flight`. For multicast, each
/// receiver's link counts its own copy; a loss on the sender's shared uplink is counted
/// on every receiver's link with an `Uplink*` reason.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LinkStats {
    /// Packets offered to the link.
    pub sent: u64,
    /// Copies that arrived (duplicates included).
    pub delivered: u64,
    /// Extra copies made by duplication.
    pub duplicated: u64,
    /// Arrivals of a packet after a packet sent later on the same link had arrived.
    pub reordered: u64,
    lost: [u64; DropReason::ALL.len()],
    /// One-way delay of each delivered copy, in arrival order, nanoseconds.
    delays_ns: Vec<u64>,
}

impl LinkStats {
    pub(crate) fn record_loss(&mut self, reason: DropReason) {
        self.lost[reason.index()] += 1;
    }

    pub(crate) fn record_delivery(&mut self, delay: Duration) {
        self.delivered += 1;
        self.delays_ns
            .push(u64::try_from(delay.as_nanos()).unwrap_or(u64::MAX));
    }

    /// Copies lost for `reason`.
    pub fn lost(&self, reason: DropReason) -> u64 {
        self.lost[reason.index()]
    }

    /// Copies lost for any reason.
    pub fn lost_total(&self) -> u64 {
        self.lost.iter().sum()
    }

    /// `lost_total / (sent + duplicated)`, or 0 with nothing sent.
    pub fn loss_rate(&self) -> f64 {
        let copies = self.sent + self.duplicated;
        if copies == 0 {
            0.0
        } else {
            self.lost_total() as f64 / copies as f64
        }
    }

    /// The delay of each delivered copy, in arrival order.
    pub fn delays(&self) -> impl ExactSizeIterator<Item = Duration> + '_ {
        self.delays_ns.iter().map(|&ns| Duration::from_nanos(ns))
    }

    /// Delay quantiles (`q` in [0, 1], nearest rank) of delivered copies, in the order
    /// asked; empty if nothing was delivered.
    pub fn delay_percentiles(&self, quantiles: &[f64]) -> Vec<Duration> {
        if self.delays_ns.is_empty() {
            return Vec::new();
        }
        let mut sorted = self.delays_ns.clone();
        sorted.sort_unstable();
        quantiles
            .iter()
            .map(|q| {
                let rank = (q.clamp(0.0, 1.0) * sorted.len() as f64).ceil() as usize;
                Duration::from_nanos(sorted[rank.clamp(1, sorted.len()) - 1])
            })
            .collect()
    }

    /// Adds another link's counts to these.
    pub fn merge(&mut self, other: &LinkStats) {
        self.sent += other.sent;
        self.delivered += other.delivered;
        self.duplicated += other.duplicated;
        self.reordered += other.reordered;
        for (mine, theirs) in self.lost.iter_mut().zip(other.lost) {
            *mine += theirs;
        }
        self.delays_ns.extend_from_slice(&other.delays_ns);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_use_nearest_rank() {
        let mut s = LinkStats::default();
        for ms in [40, 10, 30, 20] {
            s.record_delivery(Duration::from_millis(ms));
        }
        let p = s.delay_percentiles(&[0.0, 0.25, 0.5, 0.51, 1.0]);
        let ms: Vec<u128> = p.iter().map(Duration::as_millis).collect();
        assert_eq!(ms, vec![10, 10, 20, 30, 40]);
        assert!(LinkStats::default().delay_percentiles(&[0.5]).is_empty());
    }
}
