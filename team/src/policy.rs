//! When a robot tells its team what it knows: the sending policy. Under a league's
//! message budget (`comms::Budget`) every message counts; the replica paces and counts
//! frames, the policy decides what is worth one.
//!
//! - [`SendPolicy::Every`]: every control tick (today's behaviour, for leagues with no
//!   budget; under a budget the replica's pacing then decides alone).
//! - [`SendPolicy::Baseline`]: B-Human's hand limiter as its team reports describe it: at
//!   least 1 s between messages, and then only when the robot moved ≥ 300 mm or turned
//!   ≥ 5°, its ball moved ≥ 300 mm (or appeared or vanished), its role (going or not)
//!   changed, or its team ball is stale. Once it decided to send, it sends its newest
//!   state when the budget lets the frame go.
//! - [`SendPolicy::Voi`] (huddle's): value of information. The robot runs, for itself,
//!   the predictor its teammates run: the last ball track anyone told the team (itself or
//!   a teammate) rolled forward by the ball model. It sends when its own ball is off that
//!   prediction by more than [`VOI_SIGMAS`] σ (its own and the told track's) *and* its
//!   message would move teammates' belief by more than they tolerate
//!   ([`VOI_BALL_TOLERANCE_M`], [`VOI_ABUNDANT_BALL_TOLERANCE_M`] with plenty in hand; a Kalman step of their predicted σ against its own, so a
//!   robot far from the ball, seeing it vaguely, stays quiet); when its cost would turn
//!   the team's decision of who goes; while two robots claim the ball (once a second);
//!   once more when it stopped going and no teammate took the ball within
//!   [`VOI_RELEASE_REPEAT_S`];
//!   when it moved more than teammates tolerate; while it sees the ball, before teammates
//!   would drop its claim; and once every [`VOI_HEARTBEAT_S`]. A message the budget
//!   holds back stays, with the newest state, until it goes (taking it back when a
//!   teammate told the team meanwhile cost more than it saved: `huddle sim --budget
//!   spl`, seeds 4–27, blind team-ball RMSE 0.931 m and one goer 97.87% with it, 0.903 m
//!   and 98.31% without). Under a budget running short it keeps
//!   [`VOI_SPARE`] frames in hand (the tolerance grows, pose and heartbeat wait), so a
//!   ball that moves unforeseen goes out at once.
//!   A ball more than [`VOI_URGENT_BALL_M`] off what teammates believe goes with
//!   priority while the team is not beyond its pacing line
//!   ([`VOI_URGENT_BALL_MIN_HEADROOM`]): the rest of the priority room is for claims.
//! - Under both: a kick and a goer change go with priority (the replica may spend its
//!   reserve on them at once), and under a budget a goer's claim goes again before
//!   teammates would drop it (`keepalive_s`). Under VOI with a budget a robot's first
//!   message goes with priority when it claims the ball: teammates hold nothing of it,
//!   so the claim is a goer change for them (before, it waited for the pacing line,
//!   which opens no ordinary frame in a game's first seconds).

use fusion::{BallEstimate, BallModel};
use serde::Serialize;

use crate::geometry::Pose;

/// The VOI policy's threshold, in σ of the robot's own ball estimate.
pub const VOI_SIGMAS: f64 = 3.0;
/// While two robots claim the ball, the VOI policy repeats its claim this often, s.
pub const VOI_CONFLICT_REPEAT_S: f64 = 1.0;
/// A robot that told its team it no longer goes says so again this long after, with
/// priority, if no teammate has been heard taking the ball meanwhile, seconds. Why: a lost
/// "not going" leaves every teammate that missed it deferring to a goer that stopped (the
/// team decides on what it was told), and under a budget the robot's next message may be
/// seconds away. `huddle sim --budget spl`, 600 s, one goer with / without the repeat:
/// seeds 4–27 97.3 / 96.9%, seeds 28–51 97.4 / 96.6%; blind robots' team-ball RMSE 1.29 /
/// 1.31 m and 1.35 / 1.33 m (the baseline: 96.5 and 96.8%).
pub const VOI_RELEASE_REPEAT_S: f64 = 1.0;
/// Frames the VOI policy keeps in hand under a budget: below this headroom it asks only
/// for what cannot wait (a ball further off what teammates believe, a claim about to be
/// dropped). Tuned on seeds 4–27 (SPL, 600 s; blind team-ball RMSE, one goer): 3 1.295 m
/// 89.5%, 4 1.177 m 88.4%, 5 1.124 m 87.9%, 6 1.154 m 86.8%; the one-goer cost of a larger
/// spare was claims of robots at the ball dropped by teammates while the heartbeat
/// waited, so such a claim now goes before it would be dropped whatever the headroom
/// (`PolicyState::voi`): 5 then gives 1.210 m 89.6%, and on seeds 28–51 1.14 m against
/// 1.26 m at 3, one goer unchanged (−0.05 ± 1.2 points).
pub const VOI_SPARE: i64 = 5;
/// Ball error teammates tolerate under the VOI policy, metres: a blind robot walks to a
/// ball it is told about and looks. Tuned on seeds 4–15 (SPL, 600 s, blind team-ball
/// RMSE, baseline 1.764 m): 0.5 m 1.393, 0.8 m 1.326, 1.0 m 1.307, 1.5 m 1.310, 2.0 m
/// 1.244 (within the seeds' noise from 1.0 m on; one goer 86.8–87.9% throughout).
pub const VOI_BALL_TOLERANCE_M: f64 = 1.0;
/// A ball further off what teammates believe than this, metres, is news that cannot wait:
/// the VOI policy sends it with priority (the team's room beyond its pacing line), where
/// a dry budget would otherwise hold it for seconds. Why: a kick whose report turned out
/// wrong (a weak contact, a push after it) or a bounce sends every blind teammate's
/// belief off at metres per second until someone who sees the ball speaks (seed 1: after
/// robot 4's kick report at 44.5 s robot 2's team ball was 2 m off within 0.5 s and 4.5 m
/// off at 46 s, with no spare frame in the team). Tuned on seeds 4–27 (`huddle sim
/// --budget spl`, 600 s; blind team-ball RMSE, one goer): none 1.074 m 98.26%, 1.0 m
/// 0.931 m 97.31%, 1.25 m 0.903 m 98.31%, 1.5 m 0.960 m 98.28%, 2.0 m 1.005 m 98.46%,
/// 2.5 m 1.027 m 97.94%, 3.0 m 1.022 m 97.90% (the baseline: 1.452 m 96.88%). Below
/// 1.25 m the priority frames crowd out claims; above it the tail waits.
pub const VOI_URGENT_BALL_M: f64 = 1.25;
/// Urgent ball news ([`VOI_URGENT_BALL_M`]) goes with priority only while the budget's
/// headroom is at least this (0: the team is not beyond its pacing line); beyond it, it
/// waits for an ordinary frame. The team's priority room (one frame per robot beyond
/// the line, `comms` budget) is then left to claims and kicks. Why: traced on tuning
/// seeds 103–107 (SPL, 300 s), VOI's conflicts were nearly all a goer's claim (its
/// keepalive or its goer change) waiting for a frame while the team stood beyond the
/// room; urgent ball news asked for the room 120–270 times in 300 s (a team's budget
/// is 1 frame/s) and got it in 0.1 s, goer changes waited 0.2–0.9 s, keepalives
/// 0.7–3.7 s. Tuned on seeds 101–110 and 4–19 (`huddle sim --budget spl`, 300 s), one
/// goer VOI − baseline in points, drawn / ideal world (blind robots' team-ball RMSE
/// VOI / baseline, drawn / ideal):
///
/// | minimum headroom | 101–110 | 4–19 | blind, 101–110 | blind, 4–19 |
/// |---|---|---|---|---|
/// | none (−4: the whole room) | +0.28 / −0.80 | −1.68 / +0.90 | 0.69 / 0.61 | 0.68 / 0.59 |
/// | −3 | +0.00 / +2.74 | | 0.69 / 0.66 | |
/// | −2 | +1.52 / +1.76 | | 0.68 / 0.63 | |
/// | −1 | +1.42 / +1.82 | +1.02 / +0.36 | 0.79 / 0.63 | 0.68 / 0.61 |
/// | **0** | +2.42 / +1.36 | +1.40 / +2.18 | 0.70 / 0.65 | 0.67 / 0.64 |
/// | 1 (never beyond the line) | +2.72 / +1.47 | +1.62 / +1.05 | 0.75 / 0.69 | 0.71 / 0.63 |
pub const VOI_URGENT_BALL_MIN_HEADROOM: i64 = 0;
/// … with plenty of budget in hand (a Humanoid budget), metres.
pub const VOI_ABUNDANT_BALL_TOLERANCE_M: f64 = 0.25;
/// Ball news goes out under a budget only once the robot's own track took a sighting at
/// two ticks in a row ([`Now::ball_confirmed`]). Why: a camera's false ball (one frame)
/// lands on a robot's vague track and looks like news metres off what teammates
/// believe, so it went with priority, spent the team's frames and pulled blind teammates
/// to where no ball was. `huddle sim --budget spl`, seeds 4–11 (tuning), 300 s, blind
/// robots' team-ball RMSE and one goer:
///
/// | world | VOI, one frame is news | VOI, two ticks | baseline |
/// |---|---|---|---|
/// | drawn | 1.744 m, 93.72% | 1.382 m, 97.18% | 1.980 m, 94.75% |
/// | ideal | 0.943 m, 95.44% | 0.858 m, 97.09% | |
///
/// (Drawn, with the camera's false balls switched off: 0.972 m, 96.32%.)
pub const VOI_CONFIRM_TICKS: u32 = 2;
/// The VOI policy sends at least this often, seconds.
pub const VOI_HEARTBEAT_S: f64 = 10.0;
/// … with no budget: metres, radians.
pub const VOI_UNBUDGETED_POSE_TOLERANCE: (f64, f64) = (0.5, 0.35);
/// Pose change teammates tolerate under the VOI policy: metres, radians.
pub const VOI_POSE_TOLERANCE: (f64, f64) = (2.0, std::f64::consts::PI);

/// Which sending policy robots use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Default)]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
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

impl SendPolicy {
    /// The policy a robot uses unless told otherwise: [`SendPolicy::Voi`] under a
    /// league's budget (it beats the baseline on blind robots' team ball, see the crate
    /// docs' table), [`SendPolicy::Every`] without one.
    pub fn default_for(budgeted: bool) -> Self {
        if budgeted {
            SendPolicy::Voi
        } else {
            SendPolicy::Every
        }
    }
}

/// What this robot last told its team.
#[derive(Debug, Clone, Copy)]
struct Sent {
    t_s: f64,
    pose: Pose,
    ball: Option<BallEstimate>,
    going: bool,
    cost: f64,
    h: f64,
}

/// What the policy asks of the robot at a tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    /// Nothing to send.
    Quiet,
    /// Write the world model (newest) for the next frame; `priority` for a goer change
    /// or a kick report.
    Send {
        /// Under a budget it may draw on the reserve at once.
        priority: bool,
    },
}

/// A robot's sending state.
#[derive(Debug, Clone, Default)]
pub struct PolicyState {
    /// What teammates were last told (the last world model that went out).
    last: Option<Sent>,
    /// The world model written last, while it waits for a frame.
    pending: Option<Sent>,
    /// A kick whose report has not been sent yet.
    kick_pending: bool,
    /// A claim written between ticks (going, cost as posted, cost as weighed) that has
    /// not gone out yet: what teammates will hold once it has.
    claim_pending: Option<(bool, f64, f64)>,
    /// When its latest "not going" went out, while no teammate has been heard taking
    /// the ball since (VOI under a budget, see [`VOI_RELEASE_REPEAT_S`]).
    released_at: Option<f64>,
    /// What the robot knew at its latest tick.
    latest: Option<Sent>,
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
    /// Its own ball track took a sighting at this tick and the one before (a fresh
    /// track: at two ticks since it started). A false ball is one camera frame; VOI
    /// under a budget tells no ball news on one (see [`VOI_CONFIRM_TICKS`]).
    pub ball_confirmed: bool,
    /// Whether it is going to the ball.
    pub going: bool,
    /// Whether it has no usable team ball.
    pub team_ball_stale: bool,
    /// It kicked at this tick.
    pub kicked: bool,
    /// The ball model teammates predict with.
    pub model: &'a BallModel,
    /// The freshest ball track a teammate has told the team (its last message's).
    pub told: Option<BallEstimate>,
    /// Its cost to go to the ball as the arbitration weighs it (eq. 19, less the
    /// hysteresis margin while it goes).
    pub cost: f64,
    /// Its cost as posted (eq. 19).
    pub h: f64,
    /// Under a budget: teammates drop what this robot said once it is twice this old
    /// (s); a goer's claim goes again before then, under either policy (a goer pinned at
    /// a ball that moves nowhere would otherwise fall silent, be dropped, and go on
    /// unaware beside the next goer).
    pub keepalive_s: Option<f64>,
    /// A teammate also claims to be going, as heard.
    pub rival_going: bool,
    /// The lowest such cost among teammates, as heard (the no-ball cost when no
    /// teammate counts; `None`: not known).
    pub rival_cost: Option<f64>,
    /// The gate teammates' GWMs hold a sighting to (χ², 2 dof): a message further off
    /// what they believe restarts their team ball rather than nudging it.
    pub gate_chi2: f64,
    /// Under a budget: frames its pacing would let go now (`comms::Replica::
    /// budget_headroom`); `None` without one.
    pub headroom: Option<i64>,
    /// A frame goes anyway for another write (the pass receiver changed; a claim change
    /// written between ticks and still waiting counts too, see [`PolicyState::decide`]):
    /// under a budget the world model rides in it, whatever the policy would have asked.
    pub frame_anyway: bool,
}

impl PolicyState {
    /// What to do this tick. `waiting`: the world model written last has not gone out
    /// yet (a budget's pacing holds it).
    /// `claim_waiting`: the claim written with it has not gone out either (a frame
    /// may carry the small claim while the world model still waits for room).
    pub fn decide(
        &mut self,
        policy: SendPolicy,
        now: &Now<'_>,
        waiting: bool,
        claim_waiting: bool,
    ) -> Action {
        self.kick_pending |= now.kicked;
        let told_going_before = self.last.map(|l| l.going);
        if !waiting {
            // It went out since the previous tick: that is what teammates now hold.
            if let Some(sent) = self.pending.take() {
                self.last = Some(sent);
            }
        }
        if !claim_waiting {
            // The claim went (alone, or with the world model): teammates hold its cost
            // and its going. One written between ticks is newer than the tick's.
            if let Some((going, h, cost)) = self.claim_pending.take() {
                self.sent_going(going, h, cost);
            } else if let Some(sent) = self.pending.filter(|_| waiting) {
                self.sent_going(sent.going, sent.h, sent.cost);
            }
        }
        if told_going_before == Some(true) && self.last.is_some_and(|l| !l.going) {
            self.released_at = Some(now.t_s);
        }
        let decision = match policy {
            SendPolicy::Every => Some(self.urgent(now)),
            SendPolicy::Baseline => self.baseline(now),
            SendPolicy::Voi => self.voi(now),
        };
        // Under a budget a frame is the scarce thing, not its bytes: one that goes anyway
        // carries the newest world model.
        let anyway = now.frame_anyway || (claim_waiting && self.claim_pending.is_some());
        let decision = decision.or((anyway && now.headroom.is_some()).then_some(false));
        let state = Sent {
            t_s: now.t_s,
            pose: now.pose,
            ball: now.ball,
            going: now.going,
            cost: now.cost,
            h: now.h,
        };
        self.latest = Some(state);
        match decision {
            Some(priority) => {
                self.pending = Some(state);
                // The claim in this frame is the newest.
                self.claim_pending = None;
                // A kick made at this very tick is in the next LWM: it stays pending.
                self.kick_pending = now.kicked;
                Action::Send { priority }
            }
            // Once it decided to send, the newest state goes when the budget lets it.
            None if waiting => {
                self.pending = Some(state);
                Action::Send { priority: false }
            }
            None => Action::Quiet,
        }
    }

    /// Whatever [`PolicyState::decide`] said at this tick, its newest state goes, with
    /// priority: the robot must tell the team now (the kick-off taker's claim in Set,
    /// see `TeamLayer::set_kick_off_next`). Call it after `decide`.
    pub fn insist(&mut self) -> Action {
        if let Some(latest) = self.latest {
            self.pending = Some(latest);
        }
        self.claim_pending = None;
        Action::Send { priority: true }
    }

    /// The world model of the latest tick rides in a frame that goes anyway (with a claim
    /// written between ticks), unless that tick's already went or waits: teammates hold
    /// it once that frame went. Whether it rides.
    pub fn world_model_rides(&mut self) -> bool {
        let Some(latest) = self.latest else {
            return false;
        };
        let told = |s: Option<Sent>| s.is_some_and(|s| s.t_s >= latest.t_s);
        if told(self.pending) || told(self.last) {
            return false;
        }
        self.pending = Some(latest);
        true
    }

    /// The claim teammates last heard from this robot, cost and going (`None` before its
    /// first message).
    pub fn told(&self) -> Option<comms::arbitration::Posted> {
        self.last.map(|l| comms::arbitration::Posted {
            h: l.h,
            going: l.going,
        })
    }

    /// The robot wrote a claim change between ticks; it counts as told once it went out
    /// (a budget's pacing may hold it).
    pub fn wrote_claim(&mut self, going: bool, h: f64, cost: f64) {
        self.claim_pending = Some((going, h, cost));
    }

    /// A claim went out on its own (its world model still waits, or it was written
    /// between ticks): teammates hold this going and cost.
    pub fn sent_going(&mut self, going: bool, h: f64, cost: f64) {
        if let Some(last) = &mut self.last {
            last.going = going;
            last.h = h;
            last.cost = cost;
        }
    }

    /// VOI with no budget: messages cost bandwidth only, so it tells teammates whenever
    /// its own last ball, rolled forward with the model's growing σ, is more than
    /// [`VOI_SIGMAS`] σ off what it knows or has grown vaguer than it by far, and when it
    /// moved or turned more than half a metre or 20°.
    fn voi_unbudgeted(&self, now: &Now<'_>) -> Option<bool> {
        let Some(last) = self.last else {
            return Some(false);
        };
        if self.urgent(now) {
            return Some(true);
        }
        if now.t_s - last.t_s >= VOI_HEARTBEAT_S {
            return Some(false);
        }
        let (tol_m, tol_rad) = VOI_UNBUDGETED_POSE_TOLERANCE;
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

    /// A goer whose claim is about to be dropped by teammates says it again, with
    /// priority (a robot that does not go loses nothing much when its cost is dropped).
    fn keepalive(&self, now: &Now<'_>) -> Option<bool> {
        (now.going && claim_due(&self.last?, now)).then_some(true)
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
        if let Some(keepalive) = self.keepalive(now) {
            return Some(keepalive);
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

    fn voi(&mut self, now: &Now<'_>) -> Option<bool> {
        if now.headroom.is_none() {
            return self.voi_unbudgeted(now);
        }
        let Some(last) = self.last else {
            // Teammates hold nothing of it: a goer's claim is a goer change for them.
            return Some(now.going);
        };
        if self.urgent(now) {
            return Some(true);
        }
        if let Some(keepalive) = self.keepalive(now) {
            return Some(keepalive);
        }
        // Teammates decide who goes on the cost this robot last told them: news when
        // its cost now would turn that decision (it would beat the best teammate where
        // it did not, or no longer beat it).
        if let Some(rival) = now.rival_cost {
            if (last.cost < rival) != (now.cost < rival) {
                return Some(false);
            }
        }
        // A release teammates may not have heard: none of them took the ball since.
        if let Some(at) = self.released_at {
            if now.going || now.rival_going {
                self.released_at = None;
            } else if now.t_s - at >= VOI_RELEASE_REPEAT_S {
                self.released_at = None;
                return Some(true);
            }
        }
        // Two goers: one of them has not heard the other's latest (a lost frame). Saying
        // it again, at most once a second and with priority (it is a goer's claim),
        // lets both decide on the same numbers.
        if now.going && now.rival_going && now.t_s - last.t_s >= VOI_CONFLICT_REPEAT_S {
            return Some(true);
        }
        // Under a budget running short, only what cannot wait asks for a frame, so a few
        // stay in hand for the moment the ball moves unforeseen.
        // A robot that sees no ball has the least to tell: it waits for twice the spare.
        let needed = if now.ball.is_some() {
            VOI_SPARE
        } else {
            2 * VOI_SPARE
        };
        let spare = now.headroom.is_none_or(|h| h >= needed);
        let tolerance = match now.headroom {
            // Plenty in hand (a Humanoid budget): spend it on smaller errors.
            Some(h) if h >= 4 * VOI_SPARE => VOI_ABUNDANT_BALL_TOLERANCE_M,
            Some(h) if h < 1 => VOI_BALL_TOLERANCE_M * 3.0,
            Some(h) if h < VOI_SPARE => VOI_BALL_TOLERANCE_M * 2.0,
            _ => VOI_BALL_TOLERANCE_M,
        };
        // A robot at the ball keeps its claim alive at teammates (they drop it at twice
        // `keepalive_s`) whatever the headroom: the heartbeat below waits for spare
        // frames, and a dropped claim leaves teammates deciding without its cost.
        if now.ball.is_some() && claim_due(&last, now) {
            return Some(false);
        }
        if spare && now.t_s - last.t_s >= VOI_HEARTBEAT_S {
            return Some(false);
        }
        let (tol_m, tol_rad) = VOI_POSE_TOLERANCE;
        if spare
            && (last.pose.at.distance(now.pose.at) > tol_m
                || fusion::wrap_angle(last.pose.theta_rad - now.pose.theta_rad).abs() > tol_rad)
        {
            return Some(false);
        }
        // What the team was told last about the ball, by this robot or a teammate.
        let told = match (last.ball, now.told) {
            (Some(a), Some(b)) => Some(if a.t_s >= b.t_s { a } else { b }),
            (a, b) => a.or(b),
        };
        match (last.ball, now.ball) {
            (None, None) => None,
            // Teammates believe I see a ball I lost.
            (Some(_), None) => spare.then_some(false),
            // One frame's ball is not news yet: the next frame says whether it was real.
            (_, Some(_)) if !now.ball_confirmed => None,
            (_, Some(mine)) => {
                let Some(told) = told else {
                    return Some(false);
                };
                // Teammates' belief: the last told track rolled forward by the model.
                let predicted = told.predict_to(now.model, now.t_s);
                let e = mine.position() - predicted.position();
                // Along the error: is it real (beyond my σ and the told track's σ when
                // it was told), and how far would my message move teammates' belief (a
                // Kalman step: their predicted σ against mine)? A robot far from the ball,
                // seeing it vaguely, moves a well-told belief little.
                let dir = e / e.norm().max(1e-9);
                let along = |p: fusion::nalgebra::Matrix2<f64>| dir.dot(&(p * dir)).max(0.0);
                let (mine_var, told_var) = (along(mine.position_cov()), along(told.position_cov()));
                let significant = e.norm() > VOI_SIGMAS * (mine_var + told_var).sqrt();
                let theirs = along(predicted.position_cov());
                let total = (theirs + mine_var).max(1e-12);
                // Beyond their gate teammates restart on it: the belief moves all the way.
                let shift = if e.norm_squared() / total > now.gate_chi2 {
                    e.norm()
                } else {
                    e.norm() * theirs / total
                };
                if significant && shift > VOI_URGENT_BALL_M {
                    // With priority only while the team is not beyond its line: the
                    // rest of the room beyond it is for claims and kicks.
                    return Some(
                        now.headroom
                            .is_none_or(|h| h >= VOI_URGENT_BALL_MIN_HEADROOM),
                    );
                }
                (significant && shift > tolerance).then_some(false)
            }
        }
    }
}

/// Under a budget teammates drop what a robot said once it is twice `keepalive_s` old:
/// whether its claim is due to go again.
fn claim_due(last: &Sent, now: &Now<'_>) -> bool {
    now.keepalive_s
        .is_some_and(|keepalive| now.t_s - last.t_s >= keepalive)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A still ball at (x, 0), known to a millimetre, as estimated at `t_s`.
    fn still_ball(t_s: f64, x: f64) -> BallEstimate {
        BallEstimate {
            t_s,
            mean: fusion::nalgebra::Vector4::new(x, 0.0, 0.0, 0.0),
            cov: fusion::nalgebra::Matrix4::identity() * 1e-3,
        }
    }

    fn now(model: &BallModel, t_s: f64, going: bool, h: f64) -> Now<'_> {
        Now {
            t_s,
            pose: Pose::default(),
            ball: None,
            ball_confirmed: true,
            going,
            team_ball_stale: false,
            kicked: false,
            model,
            told: None,
            cost: h,
            h,
            keepalive_s: Some(5.0),
            rival_going: false,
            rival_cost: Some(1.0),
            gate_chi2: 13.82,
            headroom: Some(10),
            frame_anyway: false,
        }
    }

    /// Scenario: a game's first kick-off; robot 3 claims the ball at the whistle and has
    /// never sent a message. Teammates hold nothing of it, so its claim is a goer change
    /// for them and goes with priority; before, a first message always went as an
    /// ordinary frame, which the pacing line does not open in a game's first seconds
    /// (ideal seed 602: the claim waited 5 s and a second robot went). A robot that
    /// does not go has no such news: its first message is ordinary.
    #[test]
    fn a_goer_s_first_message_goes_with_priority() {
        let model = BallModel::default();
        for (going, priority) in [(true, true), (false, false)] {
            let mut p = PolicyState::default();
            let first = Now {
                headroom: Some(-3),
                ..now(&model, 55.0, going, 0.1)
            };
            assert_eq!(
                p.decide(SendPolicy::Voi, &first, false, false),
                Action::Send { priority },
                "going: {going}"
            );
        }
    }

    /// Under a budget a frame may carry the small claim while the world model written
    /// with it waits for room: teammates then hold the new cost, and so must the robot
    /// (it decides on what they hold), or the two sides weigh different numbers.
    #[test]
    fn a_claim_that_went_alone_is_what_teammates_hold() {
        let model = BallModel::default();
        let mut p = PolicyState::default();
        // The first message goes out: teammates hold cost 2.0, not going.
        assert_eq!(
            p.decide(SendPolicy::Voi, &now(&model, 0.0, false, 2.0), false, false),
            Action::Send { priority: false }
        );
        p.decide(
            SendPolicy::Voi,
            &now(&model, 0.04, false, 2.0),
            false,
            false,
        );
        assert_eq!(p.told().map(|t| t.h), Some(2.0));
        // It starts going with cost 0.5: a goer change, with priority.
        assert_eq!(
            p.decide(SendPolicy::Voi, &now(&model, 1.0, true, 0.5), false, false),
            Action::Send { priority: true }
        );
        // Nothing went out yet: teammates still hold 2.0.
        p.decide(SendPolicy::Voi, &now(&model, 1.04, true, 0.5), true, true);
        assert_eq!(p.told().map(|t| t.h), Some(2.0), "nothing went out yet");
        // The claim went in a frame, the world model still waits.
        p.decide(SendPolicy::Voi, &now(&model, 1.08, true, 0.5), true, false);
        assert_eq!(
            p.told().map(|t| t.h),
            Some(0.5),
            "the claim went alone: teammates hold cost 0.5"
        );
    }

    /// A claim change written between ticks waits for a frame like any other: until it
    /// went, teammates hold the claim before it, and so must the robot (its arbiter
    /// decides on what they hold).
    #[test]
    fn a_claim_written_between_ticks_is_told_once_it_went() {
        let model = BallModel::default();
        let mut p = PolicyState::default();
        p.decide(SendPolicy::Voi, &now(&model, 0.0, false, 2.0), false, false);
        p.decide(
            SendPolicy::Voi,
            &now(&model, 0.04, false, 2.0),
            false,
            false,
        );
        let not_going = comms::arbitration::Posted {
            h: 2.0,
            going: false,
        };
        assert_eq!(p.told(), Some(not_going));
        // Between ticks it decides to go, at cost 2.0 (1.5 as weighed with the margin).
        p.wrote_claim(true, 2.0, 1.5);
        // The budget holds the claim: teammates still hold "not going".
        p.decide(SendPolicy::Voi, &now(&model, 0.08, true, 2.0), false, true);
        assert_eq!(p.told(), Some(not_going), "the claim still waits");
        // It went.
        p.decide(SendPolicy::Voi, &now(&model, 0.12, true, 2.0), false, false);
        assert_eq!(
            p.told(),
            Some(comms::arbitration::Posted {
                h: 2.0,
                going: true
            }),
            "the claim went: teammates hold it"
        );
    }

    /// A goer stops and tells its team. If that frame was lost, every teammate that
    /// missed it still defers to it: unless one of them is heard taking the ball within
    /// a second, it says "not going" again, with priority.
    #[test]
    fn a_release_nobody_answers_goes_again() {
        let model = BallModel::default();
        for (taken, expected) in [
            (false, Action::Send { priority: true }),
            (true, Action::Quiet),
        ] {
            let mut p = PolicyState::default();
            p.decide(SendPolicy::Voi, &now(&model, 0.0, true, 0.5), false, false);
            p.decide(SendPolicy::Voi, &now(&model, 0.04, true, 0.5), false, false);
            // It stops: a goer change, with priority; the frame goes.
            assert_eq!(
                p.decide(SendPolicy::Voi, &now(&model, 2.0, false, 0.5), false, false),
                Action::Send { priority: true }
            );
            let later = |t_s: f64| Now {
                rival_going: taken,
                ..now(&model, t_s, false, 0.5)
            };
            assert_eq!(
                p.decide(SendPolicy::Voi, &later(2.04), false, false),
                Action::Quiet,
                "the release went; teammate taking the ball: {taken}"
            );
            assert_eq!(
                p.decide(SendPolicy::Voi, &later(3.04), false, false),
                expected,
                "a second later, teammate taking the ball: {taken}"
            );
        }
    }

    /// A ball far off what teammates believe goes at once, with priority, on a dry
    /// budget; a smaller error waits for spare frames. Once the team is beyond its line
    /// the far ball waits for an ordinary frame: the priority room left is for claims
    /// (seed 105, drawn: a goer's keepalive waited 8 s behind ball news and a second
    /// robot went for 5 s).
    #[test]
    fn a_ball_far_off_what_teammates_believe_goes_with_priority() {
        let model = BallModel::default();
        let far = VOI_URGENT_BALL_M + 0.2;
        for (off_m, headroom, expected) in [
            (1.1, 0, Action::Quiet),
            (far, 0, Action::Send { priority: true }),
            (far, -1, Action::Send { priority: false }),
            (far, -4, Action::Send { priority: false }),
        ] {
            // Told at x = 0 (still); the robot sees it at `off_m`, with `headroom` frames
            // in hand.
            let at = |t_s: f64, x: f64| Now {
                ball: Some(still_ball(t_s, x)),
                told: Some(still_ball(0.0, 0.0)),
                headroom: Some(headroom),
                ..now(&model, t_s, false, 2.0)
            };
            let mut p = PolicyState::default();
            p.decide(SendPolicy::Voi, &at(0.0, 0.0), false, false);
            p.decide(SendPolicy::Voi, &at(0.04, 0.0), false, false);
            assert_eq!(
                p.decide(SendPolicy::Voi, &at(1.0, off_m), false, false),
                expected,
                "the ball {off_m} m off what teammates believe, headroom {headroom}"
            );
        }
    }

    /// A ball seen in one camera frame only (a false ball on a vague track) is not news
    /// yet: it waits for the next frame, and goes with priority once the track took a
    /// sighting at two ticks in a row. #29's drawn world (false balls, 1 frame in 500):
    /// such frames went with priority and pulled blind teammates to where no ball was.
    #[test]
    fn a_one_frame_ball_waits_for_the_next_frame() {
        let model = BallModel::default();
        let far = VOI_URGENT_BALL_M + 1.0;
        let at = |t_s: f64, x: f64, confirmed: bool| Now {
            ball: Some(still_ball(t_s, x)),
            ball_confirmed: confirmed,
            told: Some(still_ball(0.0, 0.0)),
            ..now(&model, t_s, false, 2.0)
        };
        let mut p = PolicyState::default();
        p.decide(SendPolicy::Voi, &at(0.0, 0.0, true), false, false);
        p.decide(SendPolicy::Voi, &at(0.04, 0.0, true), false, false);
        assert_eq!(
            p.decide(SendPolicy::Voi, &at(1.0, far, false), false, false),
            Action::Quiet,
            "one frame's ball {far} m off what teammates believe"
        );
        assert_eq!(
            p.decide(SendPolicy::Voi, &at(1.04, far, true), false, false),
            Action::Send { priority: true },
            "seen again at the next tick"
        );
    }

    /// Under a budget a frame that goes anyway (a claim waiting, a new pass receiver)
    /// carries the newest world model, though nothing in it is news enough to ask for a
    /// frame of its own; without a budget frames are not counted and nothing changes.
    #[test]
    fn a_frame_that_goes_anyway_carries_the_world_model() {
        let model = BallModel::default();
        for (headroom, expected) in [
            (Some(10), Action::Send { priority: false }),
            (None, Action::Quiet),
        ] {
            let at = |t_s: f64, frame_anyway: bool| Now {
                headroom,
                frame_anyway,
                ..now(&model, t_s, false, 2.0)
            };
            let mut p = PolicyState::default();
            p.decide(SendPolicy::Voi, &at(0.0, false), false, false);
            assert_eq!(
                p.decide(SendPolicy::Voi, &at(0.04, false), false, false),
                Action::Quiet,
                "nothing new (headroom {headroom:?})"
            );
            assert_eq!(
                p.decide(SendPolicy::Voi, &at(0.08, true), false, false),
                expected,
                "a frame goes anyway (headroom {headroom:?})"
            );
            // Baseline's limiter too: under a second since its last message.
            let mut p = PolicyState::default();
            p.decide(SendPolicy::Baseline, &at(0.0, false), false, false);
            p.decide(SendPolicy::Baseline, &at(0.04, false), false, false);
            assert_eq!(
                p.decide(SendPolicy::Baseline, &at(0.08, true), false, false),
                expected,
                "baseline: a frame goes anyway (headroom {headroom:?})"
            );
        }
    }

    /// A claim written between ticks takes the latest tick's world model along: once
    /// that frame went, teammates hold that tick's ball, and so does the robot's
    /// predictor of what they believe.
    #[test]
    fn a_world_model_riding_with_a_claim_is_told_once_it_went() {
        let model = BallModel::default();
        let at = |t_s: f64, x: f64| Now {
            ball: Some(still_ball(t_s, x)),
            ..now(&model, t_s, false, 2.0)
        };
        let mut p = PolicyState::default();
        p.decide(SendPolicy::Voi, &at(0.0, 0.0), false, false);
        p.decide(SendPolicy::Voi, &at(0.04, 0.0), false, false);
        // The ball moved 30 cm: not worth a frame of its own (tolerance 1 m).
        assert_eq!(
            p.decide(SendPolicy::Voi, &at(0.08, 0.3), false, false),
            Action::Quiet
        );
        // Between ticks it decides to go: the claim is written, the 0.08 s tick's world
        // model rides along.
        p.wrote_claim(true, 0.5, 0.0);
        assert!(
            p.world_model_rides(),
            "the 0.08 s tick's world model did not go"
        );
        assert!(!p.world_model_rides(), "it rides once");
        assert_eq!(p.told().map(|t| t.h), Some(2.0), "nothing went yet");
        // By the next tick the frame went: teammates hold that ball and the new claim.
        let going = Now {
            going: true,
            h: 0.5,
            cost: 0.0,
            ..at(0.12, 0.3)
        };
        p.decide(SendPolicy::Voi, &going, false, false);
        let told = p.told().expect("told");
        assert_eq!((told.h, told.going), (0.5, true), "the claim went");
        let sent = p.last.and_then(|l| l.ball).expect("a ball was told");
        assert_eq!(sent.mean.x, 0.3, "the latest tick's ball rode along");
    }

    /// A robot at a still ball, with a budget running dry: nothing it knows has changed,
    /// so no ball news, and the heartbeat waits for spare frames. Its claim must still go
    /// before teammates drop it (at twice `keepalive_s`), or they decide without its cost;
    /// a robot that sees no ball loses nothing when its no-ball cost is dropped.
    #[test]
    fn a_robot_at_the_ball_keeps_its_claim_alive_on_a_dry_budget() {
        let model = BallModel::default();
        let ball = BallEstimate {
            t_s: 0.0,
            mean: fusion::nalgebra::Vector4::new(1.0, 2.0, 0.0, 0.0),
            cov: fusion::nalgebra::Matrix4::identity() * 1e-3,
        };
        for (sees, expected) in [
            (true, Action::Send { priority: false }),
            (false, Action::Quiet),
        ] {
            let at = |t_s: f64| Now {
                ball: sees.then_some(BallEstimate { t_s, ..ball }),
                told: sees.then_some(ball),
                headroom: Some(0),
                ..now(&model, t_s, false, 2.0)
            };
            let mut p = PolicyState::default();
            p.decide(SendPolicy::Voi, &at(0.0), false, false);
            p.decide(SendPolicy::Voi, &at(0.04), false, false);
            assert_eq!(
                p.decide(SendPolicy::Voi, &at(4.0), false, false),
                Action::Quiet,
                "sees the ball: {sees}; nothing to tell 4 s on"
            );
            assert_eq!(
                p.decide(SendPolicy::Voi, &at(5.0), false, false),
                expected,
                "sees the ball: {sees}; teammates drop its claim at 10 s"
            );
        }
    }
}
