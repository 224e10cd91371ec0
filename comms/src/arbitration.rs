//! Should-I-go arbitration (ISocRob-2000 §3.2.2, eq. 19): who goes to the ball.
//!
//! Pure logic, no I/O and no clock: every robot posts its cost `h` for going to the ball
//! (with whether it is going now) to `*.var.machine.heuristic`, reads everyone's copies
//! from its blackboard, and decides on its own. The decision is a function of what the
//! robot has heard, so robots that have heard the same agree; the only disagreement left
//! is the network's delay, which the hysteresis margin keeps to the rare real handovers.
//!
//! The seed's heuristic, with units (metres):
//!
//! ```text
//! h = d_ball + k1 · f_other    if the ball is seen (f_ball = 1)
//! h = 1000                     otherwise
//! ```
//!
//! `d_ball` is the robot's distance to the ball in metres, `f_other` is 1 when it is facing
//! the opponent goal, and `k1 < 0` (metres) is how much facing the goal is worth: with
//! `k1 = -0.5`, facing the goal is as good as being half a metre closer.

use std::collections::VecDeque;
use std::time::Duration;

use thiserror::Error;

use crate::{Blackboard, Instant, Key, Pattern, Scope, Value};

/// The blackboard key each robot publishes its cost on (`*` scope: replicated).
pub const HEURISTIC_KEY: &str = "*.var.machine.heuristic";
/// The pattern that matches every robot's copy of [`HEURISTIC_KEY`].
pub const HEURISTIC_PATTERN: &str = "+.var.machine.heuristic";

/// Configuration keys (`local.var.machine.config.*`) and their defaults.
pub mod config_keys {
    /// `k1` of eq. (19), metres, must be negative.
    pub const K1_M: &str = "local.var.machine.config.k1_m";
    /// Cost posted when the ball is not seen (the seed's 1000).
    pub const NO_BALL_COST: &str = "local.var.machine.config.no_ball_cost";
    /// Hysteresis margin, metres.
    pub const HYSTERESIS_M: &str = "local.var.machine.config.hysteresis_m";
    /// Staleness limit, milliseconds.
    pub const STALE_MS: &str = "local.var.machine.config.stale_ms";
    /// Tie band between two claims, metres.
    pub const TIE_M: &str = "local.var.machine.config.tie_m";
    /// Expected one-way latency of the team network, milliseconds.
    pub const LATENCY_MS: &str = "local.var.machine.config.latency_ms";
    /// Listening time after a (re)start, milliseconds.
    pub const LISTEN_MS: &str = "local.var.machine.config.listen_ms";
    /// Role: `"goalkeeper"` never competes; anything else does.
    pub const ROLE: &str = "local.var.machine.config.role";
}

/// The parameters of arbitration.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArbitrationParams {
    /// Reward for facing the opponent goal, metres (k1 < 0).
    pub k1_m: f64,
    /// Cost when the ball is not seen.
    pub no_ball_cost: f64,
    /// A robot already going keeps going unless beaten by more than this, metres.
    pub hysteresis_m: f64,
    /// Two robots that both claim the ball with costs within this band are a tie, won by
    /// the lower id, metres. Why: each robot sees its own cost now and the other's one
    /// latency late; two robots racing to the ball from equal distances each see
    /// themselves ahead, and without the band both would keep going as long as the race
    /// lasts.
    pub tie_m: f64,
    /// Values older than this (receiver-side age) do not count.
    pub stale_after: Duration,
    /// A robot that (re)starts listens this long before it may go.
    pub listen_for: Duration,
    /// The team network's expected one-way latency. A robot hears its teammates' costs
    /// about this late but knows its own at once, so near a handover each robot sees
    /// itself ahead and the old and the new goer disagree for about one latency. With
    /// compensation a robot decides on its **own cost as posted this long ago** (and its
    /// own current claim), the same data its teammates decide on now: both ends of a
    /// handover switch at about the same instant, at the price of reacting one latency
    /// later. Zero: off (the seed's behaviour).
    pub latency_compensation: Duration,
}

impl Default for ArbitrationParams {
    fn default() -> Self {
        Self {
            k1_m: -0.5,
            no_ball_cost: 1000.0,
            // Five standard deviations of the difference of two robots' smoothed distance
            // estimates at 2.5 m (camera: 2 cm + 5% of range, smoothed over ~4 frames),
            // and no single flip of `f_other` (|k1| = 0.5 m) takes the ball by itself.
            hysteresis_m: 0.5,
            // About one latency of two robots approaching at top speed (1.5 m/s · 0.1 s).
            tie_m: 0.15,
            // Three refresh periods of the default 100 ms.
            stale_after: Duration::from_millis(300),
            // One refresh period: by then every teammate has re-sent its cost once.
            listen_for: Duration::from_millis(100),
            latency_compensation: Duration::ZERO,
        }
    }
}

/// What one robot knows of the ball for eq. (19).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallView {
    /// Distance from the robot to the ball, metres.
    pub distance_m: f64,
    /// Whether the robot faces the opponent goal (the seed's `front_found_other_goal()`).
    pub facing_opponent_goal: bool,
}

/// Eq. (19): the cost of going to the ball.
pub fn heuristic(params: &ArbitrationParams, ball: Option<BallView>) -> f64 {
    match ball {
        Some(b) => {
            let f_other = if b.facing_opponent_goal { 1.0 } else { 0.0 };
            b.distance_m + params.k1_m * f_other
        }
        None => params.no_ball_cost,
    }
}

/// The value posted on [`HEURISTIC_KEY`]: `[h, going]` as a float vector, so that a
/// relay client reads it as `floats [h, 0|1]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Posted {
    /// The cost, eq. (19).
    pub h: f64,
    /// Whether this robot is going to the ball now.
    pub going: bool,
}

impl Posted {
    /// As the float vector stored on the blackboard.
    pub fn to_floats(self) -> Vec<f32> {
        vec![self.h as f32, if self.going { 1.0 } else { 0.0 }]
    }

    /// From a float vector; `None` when it is not of this shape (a bad value from a
    /// client must not decide anything).
    pub fn from_floats(v: &[f32]) -> Option<Self> {
        match v {
            [h, going] if h.is_finite() && going.is_finite() => Some(Self {
                h: f64::from(*h),
                going: *going >= 0.5,
            }),
            _ => None,
        }
    }
}

/// One robot's posted cost as this robot sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    /// The robot id (1–254).
    pub robot: u8,
    /// What it posted.
    pub posted: Posted,
    /// Age on this robot's clock (receiver-side timestamp).
    pub age: Duration,
}

/// Who goes to the ball, as decided from one robot's view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// The robot that should go, if any candidate is fresh.
    pub goer: Option<u8>,
    /// Its effective cost (after the hysteresis bonus).
    pub goer_cost: f64,
}

impl Decision {
    /// The seed's `should_I_go()` for robot `me`.
    pub fn should_go(&self, me: u8) -> bool {
        self.goer == Some(me)
    }
}

/// Decide who goes: the fresh, eligible candidate with the lowest effective cost, ties
/// to the lower robot id. A robot that says it is going has its cost lowered by the
/// hysteresis margin, so it keeps going unless beaten by more than the margin. Every
/// robot computes the same function of the same data, so robots that have heard the same
/// values agree.
///
/// Not counted: values older than [`ArbitrationParams::stale_after`] (receiver-side age),
/// non-finite costs, and costs at or above [`ArbitrationParams::no_ball_cost`]. That last
/// rule is huddle's reading of the seed: a robot that does not see the ball has nothing to
/// approach (it searches instead), so when nobody sees the ball nobody goes, rather than
/// the lowest id "going" to a ball it cannot see and then fighting the robot that first
/// spots it.
///
/// `candidates` should include the deciding robot itself (its current `h`, its current
/// `going`, age zero).
pub fn decide(params: &ArbitrationParams, candidates: &[Candidate]) -> Decision {
    let counted = |c: &&Candidate| {
        let h = c.posted.h;
        c.age <= params.stale_after && h.is_finite() && h < params.no_ball_cost
    };
    let cost = |c: &Candidate| {
        if c.posted.going {
            c.posted.h - params.hysteresis_m
        } else {
            c.posted.h
        }
    };
    let mut best: Option<(f64, u8, bool)> = None;
    for c in candidates.iter().filter(counted) {
        let k = cost(c);
        let better = match best {
            None => true,
            Some((bc, br, _)) => k < bc || (k == bc && c.robot < br),
        };
        if better {
            best = Some((k, c.robot, c.posted.going));
        }
    }
    // Two claims within the tie band: the lower id keeps the ball (see `tie_m`).
    if let Some((bc, _, true)) = best {
        for c in candidates.iter().filter(counted) {
            let k = cost(c);
            if c.posted.going
                && k <= bc + params.tie_m
                && best.is_some_and(|(_, br, _)| c.robot < br)
            {
                best = Some((k, c.robot, true));
            }
        }
    }
    Decision {
        goer: best.map(|(_, r, _)| r),
        goer_cost: best.map_or(f64::INFINITY, |(c, _, _)| c),
    }
}

/// One robot's side of the arbitration: the state `decide` needs between ticks (whether
/// this robot is going, how long it has been listening).
///
/// A robot that has just started (or restarted) has an empty blackboard: it would think
/// itself alone and claim the ball while the team's goer is still going. So it listens
/// first: for [`ArbitrationParams::listen_for`] after start it posts its cost but never
/// goes. Everyone else already counts its cost, so if it is the best robot, the current
/// goer yields to it as soon as the listening robot claims.
#[derive(Debug, Clone)]
pub struct Arbiter {
    me: u8,
    goalkeeper: bool,
    params: ArbitrationParams,
    listening_left: Duration,
    going: bool,
    /// Time since start (sum of the `dt`s).
    clock: Duration,
    /// What this robot posted lately, for comparing like with like (see
    /// [`ArbitrationParams::latency_compensation`]).
    history: VecDeque<(Duration, f64)>,
}

impl Arbiter {
    /// A robot `me` that starts now. A goalkeeper never competes.
    pub fn new(me: u8, goalkeeper: bool, params: ArbitrationParams) -> Self {
        Self {
            me,
            goalkeeper,
            params,
            listening_left: params.listen_for,
            going: false,
            clock: Duration::ZERO,
            history: VecDeque::new(),
        }
    }

    /// This robot's id.
    pub fn me(&self) -> u8 {
        self.me
    }

    /// The parameters in force.
    pub fn params(&self) -> &ArbitrationParams {
        &self.params
    }

    /// Replace the parameters (e.g. after the configuration keys changed).
    pub fn set_params(&mut self, params: ArbitrationParams) {
        self.params = params;
    }

    /// Whether this robot decided to go at its last tick.
    pub fn going(&self) -> bool {
        self.going
    }

    /// Whether this robot is still listening after its start.
    pub fn listening(&self) -> bool {
        !self.listening_left.is_zero()
    }

    /// One control tick, `dt` after the previous one: this robot's cost `h` now and the
    /// teammates' copies it has heard (its own copy among them is ignored). Returns the
    /// team decision as seen from here and what to post on [`HEURISTIC_KEY`].
    ///
    /// A goalkeeper posts the no-ball cost so that no teammate counts it; a listening
    /// robot posts its real cost with `going = false`.
    pub fn tick(&mut self, dt: Duration, h: f64, heard: &[Candidate]) -> (Decision, Posted) {
        self.listening_left = self.listening_left.saturating_sub(dt);
        self.clock += dt;
        let own_h = if self.goalkeeper {
            self.params.no_ball_cost
        } else {
            h
        };
        // Own cost as the team sees it now; own claim as it stands (a robot knows what
        // it decided, and a claim that flips back one latency later would make the goer
        // oscillate with a period of about one latency).
        let own = Posted {
            h: self.own_cost_seen(own_h),
            going: self.going,
        };
        let mut all: Vec<Candidate> = heard
            .iter()
            .filter(|c| c.robot != self.me)
            .copied()
            .collect();
        all.push(Candidate {
            robot: self.me,
            posted: own,
            age: Duration::ZERO,
        });
        let decision = decide(&self.params, &all);
        self.going = !self.goalkeeper && !self.listening() && decision.should_go(self.me);
        let posted = Posted {
            h: own_h,
            going: self.going,
        };
        if !self.params.latency_compensation.is_zero() {
            self.history.push_back((self.clock, own_h));
        }
        (decision, posted)
    }

    /// This robot's own cost as its teammates see it now: what it posted one expected
    /// latency ago (the no-ball cost before it had posted that long), or `now` without
    /// compensation.
    fn own_cost_seen(&mut self, now: f64) -> f64 {
        let lag = self.params.latency_compensation;
        if lag.is_zero() {
            self.history.clear();
            return now;
        }
        let Some(cut) = self.clock.checked_sub(lag) else {
            return self.params.no_ball_cost;
        };
        // Keep the newest entry at or before the cut and everything after it.
        while self.history.len() >= 2 && self.history[1].0 <= cut {
            self.history.pop_front();
        }
        match self.history.front() {
            Some(&(t, h)) if t <= cut => h,
            _ => self.params.no_ball_cost,
        }
    }
}

/// Every robot's posted `[h, going]` on `board`, aged at `now` by the blackboard's
/// receiver-side stamps. Values of the wrong shape (a client wrote garbage) are skipped:
/// they must not decide anything.
pub fn heard(board: &Blackboard, now: Instant) -> Vec<Candidate> {
    let pattern = heuristic_pattern();
    board
        .iter(&pattern)
        .filter_map(|(key, entry)| {
            let Scope::Robot(robot) = key.scope() else {
                return None;
            };
            let Value::Floats(v) = &entry.value else {
                return None;
            };
            Some(Candidate {
                robot,
                posted: Posted::from_floats(v)?,
                age: entry.age(now),
            })
        })
        .collect()
}

fn heuristic_pattern() -> Pattern {
    Pattern::parse(HEURISTIC_PATTERN).expect("HEURISTIC_PATTERN is a valid pattern")
}

/// The key to write `[h, going]` to (`*.var.machine.heuristic`).
pub fn heuristic_key() -> Key {
    Key::parse(HEURISTIC_KEY).expect("HEURISTIC_KEY is a valid key")
}

impl From<Posted> for Value {
    fn from(p: Posted) -> Value {
        Value::Floats(p.to_floats())
    }
}

/// Why the configuration keys do not make valid parameters.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ParamsError {
    /// A numeric key holds something that is not an int or a float.
    #[error("{key} must be a number, found {found}")]
    NotANumber {
        /// The configuration key.
        key: &'static str,
        /// The value found, as text.
        found: String,
    },
    /// A key is out of its range (the seed requires k1 < 0; margins and times ≥ 0).
    #[error("{key} = {value} is out of range: {rule}")]
    OutOfRange {
        /// The configuration key.
        key: &'static str,
        /// The value found.
        value: f64,
        /// The rule it breaks.
        rule: &'static str,
    },
    /// The role is not a string.
    #[error("{ROLE_KEY} must be a string such as \"goalkeeper\", found {0}")]
    BadRole(String),
}

const ROLE_KEY: &str = config_keys::ROLE;

fn number(board: &Blackboard, key: &'static str) -> Result<Option<f64>, ParamsError> {
    let k = Key::parse(key).expect("configuration keys are valid");
    match board.get(&k).map(|e| &e.value) {
        None => Ok(None),
        Some(Value::Float(x)) => Ok(Some(*x)),
        Some(Value::Int(i)) => Ok(Some(*i as f64)),
        Some(other) => Err(ParamsError::NotANumber {
            key,
            found: format!("{other:?}"),
        }),
    }
}

fn check(key: &'static str, value: f64, ok: bool, rule: &'static str) -> Result<f64, ParamsError> {
    if ok && value.is_finite() {
        Ok(value)
    } else {
        Err(ParamsError::OutOfRange { key, value, rule })
    }
}

impl ArbitrationParams {
    /// The parameters from `local.var.machine.config.*` on `board` (the seed's
    /// configuration files end up there), each missing key taken from `defaults`.
    pub fn from_blackboard(
        board: &Blackboard,
        defaults: ArbitrationParams,
    ) -> Result<Self, ParamsError> {
        use config_keys::*;
        let mut p = defaults;
        if let Some(v) = number(board, K1_M)? {
            p.k1_m = check(K1_M, v, v < 0.0, "the seed requires k1 < 0")?;
        }
        if let Some(v) = number(board, NO_BALL_COST)? {
            p.no_ball_cost = check(NO_BALL_COST, v, v > 0.0, "must be positive")?;
        }
        if let Some(v) = number(board, HYSTERESIS_M)? {
            p.hysteresis_m = check(HYSTERESIS_M, v, v >= 0.0, "must be >= 0")?;
        }
        if let Some(v) = number(board, TIE_M)? {
            p.tie_m = check(TIE_M, v, v >= 0.0, "must be >= 0")?;
        }
        if let Some(v) = number(board, STALE_MS)? {
            p.stale_after =
                Duration::from_secs_f64(check(STALE_MS, v, v > 0.0, "must be > 0")? / 1000.0);
        }
        if let Some(v) = number(board, LATENCY_MS)? {
            p.latency_compensation =
                Duration::from_secs_f64(check(LATENCY_MS, v, v >= 0.0, "must be >= 0")? / 1000.0);
        }
        if let Some(v) = number(board, LISTEN_MS)? {
            p.listen_for =
                Duration::from_secs_f64(check(LISTEN_MS, v, v >= 0.0, "must be >= 0")? / 1000.0);
        }
        Ok(p)
    }
}

/// Whether `local.var.machine.config.role` names the goalkeeper (who never competes).
pub fn is_goalkeeper(board: &Blackboard) -> Result<bool, ParamsError> {
    let k = Key::parse(ROLE_KEY).expect("configuration keys are valid");
    match board.get(&k).map(|e| &e.value) {
        None => Ok(false),
        Some(Value::String(s)) => Ok(s.eq_ignore_ascii_case("goalkeeper")),
        Some(other) => Err(ParamsError::BadRole(format!("{other:?}"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fresh(robot: u8, h: f64, going: bool) -> Candidate {
        Candidate {
            robot,
            posted: Posted { h, going },
            age: Duration::from_millis(20),
        }
    }

    #[test]
    fn the_seeds_example_the_robot_facing_the_goal_goes() {
        // Robots 1 and 2 are both 2 m from the ball; only robot 2 faces the opponent goal.
        let p = ArbitrationParams::default();
        let h1 = heuristic(
            &p,
            Some(BallView {
                distance_m: 2.0,
                facing_opponent_goal: false,
            }),
        );
        let h2 = heuristic(
            &p,
            Some(BallView {
                distance_m: 2.0,
                facing_opponent_goal: true,
            }),
        );
        let d = decide(&p, &[fresh(1, h1, false), fresh(2, h2, false)]);
        assert!(d.should_go(2), "robot 2 faces the goal and must go: {d:?}");
        assert!(!d.should_go(1), "robot 1 must stand still: {d:?}");
    }

    #[test]
    fn a_robot_that_does_not_see_the_ball_posts_the_seeds_1000() {
        assert_eq!(heuristic(&ArbitrationParams::default(), None), 1000.0);
    }

    #[test]
    fn ties_go_to_the_lower_robot_id_whatever_the_order_heard() {
        let p = ArbitrationParams::default();
        let a = decide(&p, &[fresh(3, 1.0, false), fresh(2, 1.0, false)]);
        let b = decide(&p, &[fresh(2, 1.0, false), fresh(3, 1.0, false)]);
        assert_eq!(a.goer, Some(2));
        assert_eq!(b.goer, Some(2));
    }

    #[test]
    fn stale_values_do_not_count() {
        let p = ArbitrationParams::default();
        let mut dead = fresh(1, 0.1, true);
        dead.age = p.stale_after + Duration::from_millis(1);
        let d = decide(&p, &[dead, fresh(2, 3.0, false)]);
        assert_eq!(d.goer, Some(2), "a silent robot's old cost must not win");
    }

    #[test]
    fn the_current_goer_keeps_going_unless_beaten_by_more_than_the_margin() {
        let p = ArbitrationParams {
            hysteresis_m: 0.3,
            ..Default::default()
        };
        // Robot 2 is going at 2.0 m; robot 1 is 0.2 m closer: not enough to take over.
        let d = decide(&p, &[fresh(1, 1.8, false), fresh(2, 2.0, true)]);
        assert_eq!(d.goer, Some(2), "a 0.2 m edge is inside the 0.3 m margin");
        // 0.4 m closer: robot 1 takes over.
        let d = decide(&p, &[fresh(1, 1.6, false), fresh(2, 2.0, true)]);
        assert_eq!(d.goer, Some(1), "a 0.4 m edge beats the 0.3 m margin");
    }

    #[test]
    fn malformed_posted_values_are_ignored() {
        assert_eq!(Posted::from_floats(&[1.0]), None);
        assert_eq!(Posted::from_floats(&[f32::NAN, 1.0]), None);
        let p = Posted {
            h: 2.5,
            going: true,
        };
        assert_eq!(Posted::from_floats(&p.to_floats()), Some(p));
    }

    #[test]
    fn nobody_goes_when_nobody_sees_the_ball() {
        let p = ArbitrationParams::default();
        let d = decide(&p, &[fresh(1, 1000.0, true), fresh(2, 1000.0, false)]);
        assert_eq!(d.goer, None, "no robot sees the ball: {d:?}");
    }

    #[test]
    fn a_restarted_robot_listens_before_it_claims_the_ball() {
        let p = ArbitrationParams::default();
        let mut a = Arbiter::new(3, false, p);
        // Robot 3 is the best placed, but it has just started and heard nobody yet.
        let (d, posted) = a.tick(Duration::from_millis(40), 0.5, &[]);
        assert!(d.should_go(3), "its view says it is best: {d:?}");
        assert!(
            !posted.going && !a.going(),
            "but it must not go while listening"
        );
        // After the listening time it hears robot 1 going at 2 m and takes over.
        let heard = [fresh(1, 2.0, true)];
        let (_, posted) = a.tick(Duration::from_millis(80), 0.5, &heard);
        assert!(
            posted.going,
            "listening is over and 0.5 m beats 2.0 m - margin"
        );
    }

    #[test]
    fn a_goalkeeper_never_competes() {
        let p = ArbitrationParams::default();
        let mut gk = Arbiter::new(
            1,
            true,
            ArbitrationParams {
                listen_for: Duration::ZERO,
                ..p
            },
        );
        let (d, posted) = gk.tick(Duration::from_millis(40), 0.1, &[fresh(2, 3.0, false)]);
        assert_eq!(d.goer, Some(2), "the field player goes: {d:?}");
        assert!(!posted.going);
        assert_eq!(
            posted.h, p.no_ball_cost,
            "teammates must never count the keeper"
        );
    }

    #[test]
    fn costs_are_read_from_the_blackboard_with_receiver_side_ages() {
        let mut board = Blackboard::new(2);
        let t0 = Instant::from_micros(1_000_000);
        board
            .set(
                t0,
                &heuristic_key(),
                Posted {
                    h: 1.5,
                    going: true,
                }
                .into(),
            )
            .unwrap();
        // A teammate's copy that claims to be a float, not [h, going]: ignored.
        board
            .set(
                t0,
                &Key::parse("*.var.machine.other").unwrap(),
                Value::Float(0.0),
            )
            .unwrap();
        let later = Instant::from_micros(1_250_000);
        let got = heard(&board, later);
        assert_eq!(got.len(), 1, "{got:?}");
        assert_eq!(got[0].robot, 2);
        assert_eq!(
            got[0].posted,
            Posted {
                h: 1.5,
                going: true
            }
        );
        assert_eq!(got[0].age, Duration::from_millis(250));
    }

    #[test]
    fn parameters_come_from_the_configuration_keys_and_bad_ones_are_refused() {
        let mut board = Blackboard::new(1);
        let t = Instant::ZERO;
        let set = |b: &mut Blackboard, k: &str, v: Value| {
            b.set(t, &Key::parse(k).unwrap(), v).unwrap();
        };
        set(&mut board, config_keys::K1_M, Value::Float(-0.8));
        set(&mut board, config_keys::STALE_MS, Value::Int(450));
        set(
            &mut board,
            config_keys::ROLE,
            Value::String("goalkeeper".into()),
        );
        let p = ArbitrationParams::from_blackboard(&board, ArbitrationParams::default()).unwrap();
        assert_eq!(p.k1_m, -0.8);
        assert_eq!(p.stale_after, Duration::from_millis(450));
        assert_eq!(
            p.hysteresis_m,
            ArbitrationParams::default().hysteresis_m,
            "default kept"
        );
        assert!(is_goalkeeper(&board).unwrap());
        set(&mut board, config_keys::K1_M, Value::Float(0.5));
        let err = ArbitrationParams::from_blackboard(&board, ArbitrationParams::default());
        assert!(
            matches!(err, Err(ParamsError::OutOfRange { .. })),
            "k1 >= 0 breaks the seed: {err:?}"
        );
        set(&mut board, config_keys::K1_M, Value::String("far".into()));
        let err = ArbitrationParams::from_blackboard(&board, ArbitrationParams::default());
        assert!(
            matches!(err, Err(ParamsError::NotANumber { .. })),
            "{err:?}"
        );
    }

    #[test]
    fn two_robots_claiming_at_once_from_equal_distances_agree_on_the_lower_id() {
        // Robots 1 and 2 race to the ball from 2 m; each hears the other 50 ms late, so
        // each sees itself 7.5 cm ahead (1.5 m/s · 50 ms).
        let p = ArbitrationParams::default();
        let view_of_1 = decide(&p, &[fresh(1, 1.925, true), fresh(2, 2.0, true)]);
        let view_of_2 = decide(&p, &[fresh(1, 2.0, true), fresh(2, 1.925, true)]);
        assert_eq!(view_of_1.goer, Some(1));
        assert_eq!(
            view_of_2.goer,
            Some(1),
            "robot 2 must yield, or both keep going"
        );
        // Without the tie band both would go.
        let no_band = ArbitrationParams { tie_m: 0.0, ..p };
        assert_eq!(
            decide(&no_band, &[fresh(1, 2.0, true), fresh(2, 1.925, true)]).goer,
            Some(2)
        );
        // A claim better by more than the band still wins.
        let d = decide(&p, &[fresh(1, 2.0, true), fresh(2, 1.7, true)]);
        assert_eq!(d.goer, Some(2));
    }

    #[test]
    fn with_latency_compensation_both_ends_of_a_handover_switch_together() {
        // Robot 1 is going at 2.0 m; robot 2's cost drops to 1.0 m at once (it has just
        // seen the ball close by). Latency 50 ms, ticks of 10 ms.
        let p = ArbitrationParams {
            listen_for: Duration::ZERO,
            latency_compensation: Duration::from_millis(50),
            ..Default::default()
        };
        let tick = Duration::from_millis(10);
        let mut a1 = Arbiter::new(1, false, p);
        let mut a2 = Arbiter::new(2, false, p);
        // Both have been posting for a while: robot 1 going at 2.0, robot 2 at 3.0.
        let mut sent1 = Vec::new();
        let mut sent2 = Vec::new();
        let mut switched = (None, None);
        for k in 0..40usize {
            let h2 = if k < 20 { 3.0 } else { 1.0 };
            // Each hears the other's post from 5 ticks (50 ms) ago.
            let heard = |sent: &Vec<Posted>, robot| -> Vec<Candidate> {
                sent.len()
                    .checked_sub(5)
                    .map(|i| Candidate {
                        robot,
                        posted: sent[i],
                        age: Duration::ZERO,
                    })
                    .into_iter()
                    .collect()
            };
            let h1_heard = heard(&sent2, 2);
            let h2_heard = heard(&sent1, 1);
            let (_, p1) = a1.tick(tick, 2.0, &h1_heard);
            let (_, p2) = a2.tick(tick, h2, &h2_heard);
            sent1.push(p1);
            sent2.push(p2);
            if k >= 20 && !p1.going && switched.0.is_none() {
                switched.0 = Some(k);
            }
            if k >= 20 && p2.going && switched.1.is_none() {
                switched.1 = Some(k);
            }
        }
        let (Some(stop), Some(start)) = switched else {
            panic!("the handover never happened: {switched:?}");
        };
        assert!(
            stop.abs_diff(start) <= 1,
            "robot 1 stopped at tick {stop}, robot 2 started at {start}"
        );
        assert!(
            start >= 24,
            "robot 2 claims one latency after its cost dropped, at {start}"
        );
    }
}
