//! When a robot tells its team what it knows: the sending policy. Under a league's
//! message budget (`comms::Budget`) every message counts; the replica paces and counts
//! frames, the policy decides what is worth one.
//!
//! - [`SendPolicy::Every`]: every control tick (today's behaviour, for leagues with no
//!   budget; under a budget the replica's pacing then decides alone).
//! - [`SendPolicy::Baseline`]: B-Human's hand limiter as its team reports describe it: at
//!   least 1 s between messages, and then only when the robot moved ≥ 300 mm or turned
//!   ≥ 5°, its ball moved ≥ 300 mm (or appeared or vanished), its role (going or not)
//!   changed, or its team ball is stale.
//! - [`SendPolicy::Voi`] (huddle's): value of information. The robot runs, for itself,
//!   the predictor its teammates run on its last message — its last sent ball estimate
//!   rolled forward by the ball model — and sends when what it knows now differs from
//!   that prediction by more than [`VOI_SIGMAS`] σ (of the prediction and its own
//!   estimate together), when the prediction has grown vaguer than what it knows by far
//!   (teammates have lost track of a ball it sees), when it moved or turned more than
//!   teammates can tolerate for formation and passes, and otherwise once every
//!   [`VOI_HEARTBEAT_S`] so teammates know it is alive. A kick and a goer change go with
//!   priority (the replica may spend its reserve on them at once), under both policies.

use fusion::{BallEstimate, BallModel};
use serde::Serialize;

use crate::field::geometry::Pose;

/// The VOI policy's threshold, in σ of the teammates' prediction error.
pub const VOI_SIGMAS: f64 = 3.0;
/// The VOI policy sends at least this often, seconds.
pub const VOI_HEARTBEAT_S: f64 = 10.0;
/// Pose change teammates tolerate under the VOI policy: metres, radians.
pub const VOI_POSE_TOLERANCE: (f64, f64) = (0.5, 0.35);

/// Which sending policy robots use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum SendPolicy {
    /// Every control tick.
    #[default]
    Every,
    /// B-Human-style thresholds.
    Baseline,
    /// Value of information (huddle's).
    Voi,
}

/// What this robot last told its team.
#[derive(Debug, Clone, Copy)]
struct Sent {
    t_s: f64,
    pose: Pose,
    ball: Option<BallEstimate>,
    going: bool,
}

/// A robot's sending state.
#[derive(Debug, Clone, Default)]
pub struct PolicyState {
    last: Option<Sent>,
    /// A kick whose report has not been sent yet.
    kick_pending: bool,
}

/// What the robot knows now, for the decision.
#[derive(Debug, Clone, Copy)]
pub struct Now<'a> {
    /// Its clock, seconds.
    pub t_s: f64,
    /// Its pose estimate.
    pub pose: Pose,
    /// Its own ball estimate, if it has one (seen within its ball memory).
    pub ball: Option<BallEstimate>,
    /// Whether it is going to the ball.
    pub going: bool,
    /// Whether it has no usable team ball.
    pub team_ball_stale: bool,
    /// It kicked at this tick.
    pub kicked: bool,
    /// The ball model teammates predict with.
    pub model: &'a BallModel,
}

impl PolicyState {
    /// Whether to send this tick: `None` no, `Some(priority)` yes.
    pub fn decide(&mut self, policy: SendPolicy, now: &Now<'_>) -> Option<bool> {
        self.kick_pending |= now.kicked;
        let decision = match policy {
            SendPolicy::Every => Some(self.urgent(now)),
            SendPolicy::Baseline => self.baseline(now),
            SendPolicy::Voi => self.voi(now),
        };
        if decision.is_some() {
            self.last = Some(Sent {
                t_s: now.t_s,
                pose: now.pose,
                ball: now.ball,
                going: now.going,
            });
            // A kick made at this very tick is in the next LWM: it stays pending.
            self.kick_pending = now.kicked;
        }
        decision
    }

    /// The robot sent a goer change between ticks (with priority).
    pub fn sent_going(&mut self, going: bool) {
        if let Some(last) = &mut self.last {
            last.going = going;
        }
    }

    /// A goer change or a kick report waiting: priority.
    fn urgent(&self, now: &Now<'_>) -> bool {
        let going_changed = self.last.is_some_and(|l| l.going != now.going);
        going_changed || (self.kick_pending && !now.kicked)
    }

    fn baseline(&self, now: &Now<'_>) -> Option<bool> {
        let Some(last) = self.last else {
            return Some(false);
        };
        if self.urgent(now) {
            return Some(true);
        }
        if now.t_s - last.t_s < 1.0 {
            return None;
        }
        let moved = last.pose.at.distance(now.pose.at) >= 0.3
            || fusion::wrap_angle(last.pose.theta_rad - now.pose.theta_rad).abs()
                >= 5f64.to_radians();
        let ball_moved = match (last.ball, now.ball) {
            (Some(a), Some(b)) => (a.position() - b.position()).norm() >= 0.3,
            (None, None) => false,
            _ => true,
        };
        (moved || ball_moved || now.team_ball_stale).then_some(false)
    }

    fn voi(&self, now: &Now<'_>) -> Option<bool> {
        let Some(last) = self.last else {
            return Some(false);
        };
        if self.urgent(now) {
            return Some(true);
        }
        if now.t_s - last.t_s >= VOI_HEARTBEAT_S {
            return Some(false);
        }
        let (tol_m, tol_rad) = VOI_POSE_TOLERANCE;
        if last.pose.at.distance(now.pose.at) > tol_m
            || fusion::wrap_angle(last.pose.theta_rad - now.pose.theta_rad).abs() > tol_rad
        {
            return Some(false);
        }
        match (last.ball, now.ball) {
            (None, None) => None,
            // Teammates believe I see a ball I lost, or do not know one I see.
            (Some(_), None) | (None, Some(_)) => Some(false),
            (Some(sent), Some(mine)) => {
                let predicted = sent.predict_to(now.model, now.t_s);
                let e = mine.position() - predicted.position();
                let s = predicted.position_cov() + mine.position_cov();
                let d2 = s.cholesky().map_or(f64::INFINITY, |c| e.dot(&c.solve(&e)));
                // Vaguer by far: teammates' σ more than three times mine and over 0.5 m.
                let vague = predicted.position_cov().trace()
                    > (9.0 * mine.position_cov().trace()).max(0.25);
                (d2 > VOI_SIGMAS * VOI_SIGMAS || vague).then_some(false)
            }
        }
    }
}
