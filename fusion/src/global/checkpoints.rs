//! [`Checkpoints`]: the state of the GWM's team track after each of its pending
//! observations, brought up to date only where and when it is read.
//!
//! A late observation (a teammate's message, a beacon hold) slots in among the pending
//! ones and changes every state after it. A robot's GWM takes up to four teammates' late
//! messages in a tick before it asks for the newest state: carrying every later
//! checkpoint forward at each of them did the same chain four times. Here an insertion
//! only marks the checkpoints after it stale; a read brings the stale ones it needs (the
//! ones up to the time asked for) up to date, each once.
//!
//! **Same states as carrying them forward at once.** A checkpoint is written by exactly
//! the step an eager replay would write it with (`step`: the pending observation
//! applied to the checkpoint before it, or that state itself if it cannot be applied),
//! from the same state, once every state before it is final. An inserted observation's
//! own checkpoint is computed at once from the state the gate saw (as before).
//!
//! **The state at a time** is the checkpoint of the last pending observation at or
//! before it (or the committed ball), predicted to it. The eager window predicted the
//! newest state instead whenever the time was not before it; the two are the same
//! state: checkpoints' times never decrease, and a checkpoint whose time is before its
//! own observation's is a copy of the one before it (an observation that could not be
//! applied: a successful step, an inserted observation and a kick all end at or after
//! their own time). So if the newest state is not after `t`, every observation after
//! `t` failed, and every checkpoint from the last one at or before `t` to the newest is
//! the same bits.

use crate::ball::{BallEstimate, BallModel};
use std::collections::VecDeque;

use super::measured::Measured;

/// The states after each pending observation (see the module docs): `states[k]` belongs
/// to `pending[k]`; `states[..valid]` are up to date, the rest stale.
#[derive(Debug, Clone, Default)]
pub(super) struct Checkpoints {
    states: VecDeque<BallEstimate>,
    valid: usize,
    /// Tests only: carry every change forward at once and read the newest state as the
    /// eager window did, to compare with.
    #[cfg(test)]
    pub(super) eager: bool,
    /// Tests only: checkpoints computed by [`Self::settle`].
    #[cfg(test)]
    pub(super) steps: u64,
}

/// What the checkpoints are computed from: the committed ball under the pending
/// observations, and the model they are applied with.
pub(super) struct Base<'a> {
    pub(super) model: &'a BallModel,
    pub(super) committed: Option<&'a BallEstimate>,
    pub(super) pending: &'a VecDeque<Measured>,
}

impl Checkpoints {
    /// Every checkpoint, stale ones as they are (see [`Self::settled`]).
    pub(super) fn states(&self) -> &VecDeque<BallEstimate> {
        &self.states
    }

    /// Brings `states[..upto]` up to date.
    pub(super) fn settle(&mut self, base: &Base<'_>, upto: usize) {
        #[cfg(test)]
        if self.eager {
            return;
        }
        debug_assert_eq!(self.states.len(), base.pending.len());
        for k in self.valid..upto {
            // Each checkpoint is written in place and read back as the next one's state:
            // no copy of a 168-byte estimate through a local per step.
            let before = match k.checked_sub(1) {
                Some(j) => &self.states[j],
                None => base.committed.expect("a committed ball under pending ones"),
            };
            self.states[k] = match base.pending[k].apply(base.model, before) {
                Some(e) => e,
                None => *before,
            };
            #[cfg(test)]
            {
                self.steps += 1;
            }
        }
        self.valid = self.valid.max(upto);
    }

    /// The state after the first `n` pending observations (the committed ball for none),
    /// brought up to date.
    pub(super) fn after<'a>(&'a mut self, base: &Base<'a>, n: usize) -> Option<&'a BallEstimate> {
        self.settle(base, n);
        match n.checked_sub(1) {
            Some(k) => Some(&self.states[k]),
            None => base.committed,
        }
    }

    /// The state at `t_s` (see the module docs): the one after the pending observations
    /// up to `t_s`, predicted to it.
    pub(super) fn state_at(&mut self, base: &Base<'_>, t_s: f64) -> Option<BallEstimate> {
        #[cfg(test)]
        if self.eager {
            return self.eager_state_at(base, t_s);
        }
        let n = super::partition_near_back(base.pending, |p| p.t_s <= t_s);
        let state = self.after(base, n)?;
        Some(state.predict_to(base.model, t_s))
    }

    /// The eager window's read: the newest state if `t_s` is not before it, else the
    /// checkpoint before `t_s`.
    #[cfg(test)]
    fn eager_state_at(&mut self, base: &Base<'_>, t_s: f64) -> Option<BallEstimate> {
        assert_eq!(
            self.valid,
            self.states.len(),
            "the eager window is up to date"
        );
        let head = self.states.back().or(base.committed)?;
        if t_s >= head.t_s {
            return Some(head.predict_to(base.model, t_s));
        }
        let n = super::partition_near_back(base.pending, |p| p.t_s <= t_s);
        let state = if n == 0 {
            base.committed?
        } else {
            &self.states[n - 1]
        };
        Some(state.predict_to(base.model, t_s))
    }

    /// A pending observation was inserted at `at` (`base` holds it) with checkpoint
    /// `state`, computed from the state before it: settle `at` before the insertion. Every
    /// checkpoint after it goes stale.
    pub(super) fn insert(&mut self, base: &Base<'_>, at: usize, state: BallEstimate) {
        debug_assert!(
            self.valid >= at,
            "the state before an insertion is up to date"
        );
        self.states.insert(at, state);
        self.valid = at + 1;
        self.after_change(base, at + 1);
    }

    /// The state under pending observation `from` changed (the committed ball, for 0):
    /// it and every checkpoint after it go stale.
    pub(super) fn stale_from(&mut self, base: &Base<'_>, from: usize) {
        self.valid = self.valid.min(from);
        self.after_change(base, from);
    }

    /// Tests only, the eager window: every checkpoint from `from` on is carried forward
    /// at once (the eager window's own loop, not [`Self::settle`]'s, to compare with).
    #[cfg(test)]
    fn after_change(&mut self, base: &Base<'_>, from: usize) {
        if !self.eager {
            return;
        }
        for k in from..base.pending.len() {
            let before = match k.checked_sub(1) {
                Some(j) => &self.states[j],
                None => base.committed.expect("a committed ball under pending ones"),
            };
            self.states[k] = match base.pending[k].apply(base.model, before) {
                Some(e) => e,
                None => *before,
            };
            self.steps += 1;
        }
        self.valid = self.states.len();
    }

    #[cfg(not(test))]
    fn after_change(&mut self, _base: &Base<'_>, _from: usize) {}

    /// A pending observation was added at the back with checkpoint `state`: settle every
    /// checkpoint before it first.
    pub(super) fn push_back(&mut self, state: BallEstimate) {
        debug_assert_eq!(
            self.valid,
            self.states.len(),
            "the checkpoints before are up to date"
        );
        self.states.push_back(state);
        self.valid = self.states.len();
    }

    /// The first `n` pending observations were committed (after reading their last
    /// checkpoint through [`Self::after`]).
    pub(super) fn drain_front(&mut self, n: usize) {
        self.states.drain(..n);
        self.valid = self.valid.saturating_sub(n);
    }

    /// Only the first `keep` pending observations stay.
    pub(super) fn truncate(&mut self, keep: usize) {
        self.states.truncate(keep);
        self.valid = self.valid.min(keep);
    }

    /// No pending observations.
    pub(super) fn clear(&mut self) {
        self.states.clear();
        self.valid = 0;
    }

    /// Every checkpoint, up to date (for a track set aside: see `Rewind`).
    pub(super) fn settled(&mut self, base: &Base<'_>) -> &VecDeque<BallEstimate> {
        self.settle(base, self.states.len());
        &self.states
    }

    /// Checkpoints `states`, all up to date (a track set aside, restored).
    pub(super) fn restore(&mut self, states: VecDeque<BallEstimate>) {
        self.valid = states.len();
        self.states = states;
    }
}
