//! Plain references for a team's fusion: the centralized filter, which sees every robot's
//! sightings at once, and the same filter under a network's information pattern. They
//! have none of the GWM's rules (consensus, dissent, per-robot restarts, kick reach), so
//! a GWM can beat them by those rules alone: `huddle sim`'s own references run the
//! [`crate::GlobalModel`] instead (`teamsim::references`); `huddle sim --daemons` keeps
//! [`CentralizedBall`].

use super::{
    BallEstimate, BallFilter, BallFilterConfig, BallSighting, BallUpdate, FieldObservation, Kick,
};
use crate::pose::PoseEstimate;
use std::collections::VecDeque;

/// The reference a team's fusion is measured against: one ball filter, same model, fed every
/// robot's raw sightings (each with that robot's pose estimate) at once, with no network.
/// Feed sightings in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct CentralizedBall {
    pub(super) filter: BallFilter,
}

impl CentralizedBall {
    /// A centralized filter with the given settings.
    pub fn new(config: BallFilterConfig) -> Self {
        CentralizedBall {
            filter: BallFilter::new(config),
        }
    }

    /// Applies a sighting that a robot at `pose` made at `t_s`.
    pub fn sighting(
        &mut self,
        t_s: f64,
        pose: &PoseEstimate,
        sighting: &BallSighting,
    ) -> BallUpdate {
        self.filter.sighting(t_s, pose, sighting)
    }

    /// A robot's kick, at once (it is a control input the team knows, not a sighting).
    pub fn kick(&mut self, kick: &Kick) {
        self.filter.kick(kick);
    }

    /// The estimate predicted to `t_s`.
    pub fn estimate_at(&self, t_s: f64) -> Option<BallEstimate> {
        self.filter.estimate_at(t_s)
    }

    /// Drops the track (the ball was put elsewhere by hand).
    pub fn forget(&mut self) {
        self.filter = BallFilter::new(self.filter.config);
    }
}

/// The centralized filter under a network's information pattern: the same filter as
/// [`CentralizedBall`], fed at one robot with exactly the ball information that has reached
/// that robot so far (its own sightings and kicks at once, each teammate's batches and
/// kick reports when its message arrives, in whatever order they arrive). It is the
/// reference for a fusion over that information: what the centralized filter itself makes
/// of what this network delivered (not a proof of optimality — it is the same gated EKF),
/// so a team ball's RMSE over this one's measures the fusion, and this one's over the
/// centralized filter's measures the network.
///
/// Observations are kept for `window_s` so that a late one slots in at its own time. The
/// filter after each kept event is kept too, so a late event replays only the events
/// after it, and an estimate is the last state predicted (before, every estimate
/// replayed the whole window: a fifth of `huddle sim`'s time). The replay waits until a
/// state is asked for (settling, an estimate): the several events one message brings, and
/// the robot's own sighting that a teammate's earlier one then slots in front of, are
/// replayed once, not once per event. The states are the same operations in the same
/// order either way, so the figures are identical.
#[derive(Debug, Clone, PartialEq)]
pub struct NetworkLimitedBall {
    settled: BallFilter,
    /// Events at or after `settled_until_s`, in time order. (Queues: settling takes
    /// from the front at every tick, and a vector moved the whole window each time.)
    recent: VecDeque<Event>,
    /// `after[k]`: `settled` with `recent[..=k]` applied in order, for the first
    /// `after.len()` events; the rest are still to be replayed (see `catch_up`).
    after: VecDeque<BallFilter>,
    settled_until_s: f64,
    window_s: f64,
    late: u64,
}

/// What the reference replays.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Event {
    Seen(FieldObservation),
    Kicked(Kick),
    Track(crate::TrackGain),
}

impl Event {
    fn t_s(&self) -> f64 {
        match self {
            Event::Seen(o) => o.t_s,
            Event::Kicked(k) => k.t_s,
            Event::Track(g) => g.t_s,
        }
    }

    fn apply(&self, filter: &mut BallFilter) {
        match self {
            Event::Seen(o) => {
                filter.observe(o);
            }
            Event::Kicked(k) => filter.kick(k),
            Event::Track(g) => {
                filter.measure_state(g.t_s, &g.mean, &g.cov);
            }
        }
    }
}

impl NetworkLimitedBall {
    /// A reference with the given filter settings that keeps observations re-orderable for
    /// `window_s` (longer than the network's worst delay plus the repeats' reach).
    pub fn new(config: BallFilterConfig, window_s: f64) -> Self {
        NetworkLimitedBall {
            settled: BallFilter::new(config),
            recent: VecDeque::new(),
            after: VecDeque::new(),
            settled_until_s: f64::NEG_INFINITY,
            window_s,
            late: 0,
        }
    }

    fn insert(&mut self, event: Event) -> bool {
        let t_s = event.t_s();
        if t_s < self.settled_until_s {
            self.late += 1;
            return false;
        }
        let at = self.recent.partition_point(|p| p.t_s() <= t_s);
        self.recent.insert(at, event);
        // The states from the new event on are to be replayed.
        self.after.truncate(at);
        true
    }

    /// The filter before `recent[from]` (`from` ≤ `after.len()`).
    fn before(&self, from: usize) -> BallFilter {
        match from {
            0 => self.settled.clone(),
            _ => self.after[from - 1].clone(),
        }
    }

    /// Replays the events whose states are not kept yet.
    fn catch_up(&mut self) {
        let from = self.after.len();
        if from == self.recent.len() {
            return;
        }
        let mut filter = self.before(from);
        for event in self.recent.range(from..) {
            event.apply(&mut filter);
            self.after.push_back(filter.clone());
        }
    }

    /// One observation, whenever it arrives; `false` (and counted) if it is older than
    /// the settled state and cannot be used.
    pub fn observe(&mut self, obs: &FieldObservation) -> bool {
        self.insert(Event::Seen(*obs))
    }

    /// A kick, whenever its report arrives; `false` (and counted) if too late.
    pub fn kick(&mut self, kick: &Kick) -> bool {
        self.insert(Event::Kicked(*kick))
    }

    /// A teammate's track gain (its compact message), whenever it arrives; `false` (and
    /// counted) if too late.
    pub fn track(&mut self, gain: &crate::TrackGain) -> bool {
        self.insert(Event::Track(*gain))
    }

    /// Settles every event older than `now_s − window_s` into the filter for good (and
    /// replays what came since the last call).
    pub fn settle(&mut self, now_s: f64) {
        self.catch_up();
        let until = now_s - self.window_s;
        if until <= self.settled_until_s {
            return;
        }
        self.settled_until_s = until;
        let n = self.recent.partition_point(|p| p.t_s() < until);
        if n > 0 {
            self.settled = self.after[n - 1].clone();
            self.recent.drain(..n);
            self.after.drain(..n);
        }
    }

    /// The estimate from everything received, predicted to `t_s`.
    pub fn estimate_at(&self, t_s: f64) -> Option<BallEstimate> {
        let from = self.after.len();
        if from == self.recent.len() {
            return self.after.back().unwrap_or(&self.settled).estimate_at(t_s);
        }
        // Events not replayed yet (no settle since they came): replayed here, not kept.
        let mut filter = self.before(from);
        for event in self.recent.range(from..) {
            event.apply(&mut filter);
        }
        filter.estimate_at(t_s)
    }

    /// The filter's settings.
    pub fn config(&self) -> &BallFilterConfig {
        &self.settled.config
    }

    /// Events that arrived after their time had settled.
    pub fn late(&self) -> u64 {
        self.late
    }

    /// Drops the track and ignores information from before `t_s` (the ball was put
    /// elsewhere by hand).
    pub fn forget(&mut self, t_s: f64) {
        self.settled = BallFilter::new(self.settled.config);
        self.recent.clear();
        self.after.clear();
        self.settled_until_s = t_s;
    }
}
