//! Searches of the GWM's time-ordered queues that start where the answer usually is.

use std::collections::VecDeque;

/// Elements a search walks from one end before it bisects.
const WALK: usize = 8;

/// `q.partition_point(pred)` (`pred` holds for a prefix of `q`: the queues are in time
/// order) when the answer is usually within a few elements of the back: a new
/// observation, a state asked for at a recent time. Walking from the back reads the
/// neighbours of the answer; bisecting a queue of a few hundred ~300-byte elements reads
/// eight or nine elements far apart, each a cache miss, and mispredicts half its
/// branches. The same index either way.
pub(super) fn partition_near_back<T>(q: &VecDeque<T>, pred: impl Fn(&T) -> bool) -> usize {
    let n = q.len();
    for k in (n.saturating_sub(WALK)..n).rev() {
        if pred(&q[k]) {
            return k + 1;
        }
    }
    if n <= WALK {
        0
    } else {
        q.partition_point(pred)
    }
}

/// [`partition_near_back`] for an answer usually near the front: what the commit lag
/// lets go at each message.
pub(super) fn partition_near_front<T>(q: &VecDeque<T>, pred: impl Fn(&T) -> bool) -> usize {
    let n = q.len();
    for (k, e) in q.iter().take(WALK).enumerate() {
        if !pred(e) {
            return k;
        }
    }
    if n <= WALK {
        n
    } else {
        q.partition_point(pred)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// Both walks give bisection's index, wherever the answer lies, also in a queue
        /// that wraps around its buffer.
        #[test]
        fn the_walks_find_what_bisection_finds(
            mut times in proptest::collection::vec(0u32..60, 0..40),
            rotate in 0usize..40,
            at in 0u32..62,
        ) {
            times.sort_unstable();
            let mut q: VecDeque<u32> = VecDeque::with_capacity(times.len().max(1));
            // Fill from the back and pop from the front so that the contents wrap.
            for _ in 0..rotate.min(times.len()) {
                q.push_back(u32::MAX);
                q.pop_front();
            }
            q.extend(times.iter().copied());
            let le = |t: &u32| *t <= at;
            let lt = |t: &u32| *t < at;
            let preds: [&dyn Fn(&u32) -> bool; 2] = [&le, &lt];
            for pred in preds {
                let want = q.partition_point(pred);
                prop_assert_eq!(partition_near_back(&q, pred), want, "from the back in {:?}", q);
                prop_assert_eq!(partition_near_front(&q, pred), want, "from the front in {:?}", q);
            }
        }
    }
}
