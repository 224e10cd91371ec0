//! Should-I-go arbitration (ISocRob-2000 §3.2.2, eq. 19): who goes to the ball.
//!
//! Pure logic, no I/O and no clock: every robot posts its cost `h` for going to the ball
//! (with whether it is going now) to `*.var.machine.heuristic`, reads everyone's copies
//! from its blackboard, and decides on its own. The decision is a function of what the
//! robot has heard, so robots that have heard the same agree; the only disagreement left
//! is the network's delay, which the hysteresis margin keeps to the rare real handovers.
//!
//! Bursty loss (and multicast held to power-save beacons) keeps one robot's claims from the
//! others for hundreds of milliseconds. Two rules keep that from making two goers:
//! - **silence is not giving up**: a claim to be going counts for
//!   [`ArbitrationParams::silent_goer_after`] (1 s), far beyond the normal staleness,
//!   while a goer that gives up says so and frees the ball at once;
//! - **a claim must be acknowledged**: a robot that claims the ball from a goer backs off
//!   if the goer still claims in a post it made after the claim should have reached it
//!   ([`ArbitrationParams::ack_margin`]), and waits for the goer to let go. The incumbent
//!   keeps the ball until it has heard its successor.
//!
//! Ages are receiver-side, so a post is estimated to have been made one transit later
//! than it was; the acknowledgement wait allows for that (two latencies). With ages that
//! include each frame's transit the estimate is exact and the rule only errs on the safe
//! side (it waits up to one latency longer than it must).
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

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use thiserror::Error;

use crate::{Blackboard, Instant, Key, Value};

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
    /// Margin of a new claim's acknowledgement, milliseconds.
    pub const ACK_MARGIN_MS: &str = "local.var.machine.config.ack_margin_ms";
    /// How long a silent goer's claim still holds the ball, milliseconds.
    pub const SILENT_GOER_MS: &str = "local.var.machine.config.silent_goer_ms";
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
    /// Values older than this (receiver-side age) do not count, except a claim to be
    /// going (see [`ArbitrationParams::silent_goer_after`]).
    pub stale_after: Duration,
    /// A claim to be going counts this long (receiver-side age) instead of
    /// `stale_after`. Why: silence is not giving up. A goer that falls silent (its frames
    /// lost in a burst, or held to a beacon) is still driving at the ball; taking the ball
    /// from it after the normal staleness makes two goers for as long as the silence
    /// lasts. A goer that gives up says so (`going = false`, or the no-ball cost), which
    /// frees the ball at once, so only a dead or cut-off goer is waited for this long. It
    /// should cover the longest silence the network is expected to produce (bursts of up
    /// to about a second) and be at least `stale_after`.
    pub silent_goer_after: Duration,
    /// A robot that claims the ball from a goer waits for the goer to let go; if the goer
    /// still claims in a post made more than two `latency_compensation`s plus this margin
    /// after the new claim (time for the claim to reach it and its release to come back),
    /// the goer has not heard the claim (the new claimant's frames are being lost) or
    /// disagrees, and the new claimant backs off until the goer lets go. Why: otherwise
    /// both go for as long as the new claimant's silence lasts. The margin covers the
    /// jitter and the goer's reaction (a control period or two).
    pub ack_margin: Duration,
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
            // The competition network's bursts last 100 ms on average, exponentially
            // distributed: one over 1 s is a 1-in-20,000 event (e^-10).
            silent_goer_after: Duration::from_millis(1000),
            // Two control periods of 40 ms.
            ack_margin: Duration::from_millis(80),
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
    pub fn to_floats(self) -> Vec<f64> {
        vec![self.h, if self.going { 1.0 } else { 0.0 }]
    }

    /// From a float vector; `None` when it is not of this shape (a bad value from a
    /// client must not decide anything).
    pub fn from_floats(v: &[f64]) -> Option<Self> {
        match v {
            [h, going] if h.is_finite() && going.is_finite() => Some(Self {
                h: *h,
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
/// claims to be going older than [`ArbitrationParams::silent_goer_after`], non-finite costs, and costs at or above [`ArbitrationParams::no_ball_cost`]. That last
/// rule is huddle's reading of the seed: a robot that does not see the ball has nothing to
/// approach (it searches instead), so when nobody sees the ball nobody goes, rather than
/// the lowest id "going" to a ball it cannot see and then fighting the robot that first
/// spots it.
///
/// `candidates` should include the deciding robot itself (its current `h`, its current
/// `going`, age zero).
pub fn decide(params: &ArbitrationParams, candidates: &[Candidate]) -> Decision {
    let counted = |c: &&Candidate| params.counts(c);
    let cost = |c: &Candidate| params.effective_cost(&c.posted);
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
    /// When this robot's current claim began (its clock).
    claimed_at: Option<Duration>,
    /// Per teammate whose claim to be going counts: since when it has claimed, as far as
    /// this robot knows (when the claim was first heard, less its age).
    claiming_since: BTreeMap<u8, Duration>,
    /// The goer this robot backed off from: it does not claim while that goer's claim
    /// counts (see [`ArbitrationParams::ack_margin`]).
    deferring_to: Option<u8>,
    /// The cost its teammates last heard from it, when messages are sparse (see
    /// [`Arbiter::set_told_cost`]).
    told: Option<f64>,
    /// … and whether that message said it was going (see [`Arbiter::set_told`]).
    told_going: Option<bool>,
}

impl Arbiter {
    /// Sparse messages (a league's budget): the cost teammates last heard from this
    /// robot. It then decides on that cost, as they do, rather than on its own newer one,
    /// so that every robot weighs the same numbers and they agree on one goer; a sending
    /// policy sends the newer cost when it would turn the decision. `None`: decide on the
    /// own current cost (messages every control period).
    pub fn set_told_cost(&mut self, told: Option<f64>) {
        self.told = told.filter(|h| h.is_finite());
        self.told_going = None;
    }

    /// Sparse messages: the claim teammates last heard from this robot, cost and going.
    /// It then decides entirely on what they hold: its own claim to be going counts (with
    /// the hysteresis margin) only once it went out, as it does for them. Why: a robot
    /// that weighed its own untold claim with the margin while teammates weighed it
    /// without would see itself ahead where they see a teammate, and both would go for
    /// as long as the claim waits for a frame (seconds, under a league's budget).
    pub fn set_told(&mut self, told: Option<Posted>) {
        self.set_told_cost(told.map(|t| t.h));
        self.told_going = told.filter(|t| t.h.is_finite()).map(|t| t.going);
    }

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
            claimed_at: None,
            claiming_since: BTreeMap::new(),
            deferring_to: None,
            told: None,
            told_going: None,
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

    /// The goer this robot has backed off from, if any: its claim to the ball was not
    /// acknowledged (see [`ArbitrationParams::ack_margin`]).
    pub fn deferring_to(&self) -> Option<u8> {
        self.deferring_to
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
        let seen = self.own_cost_seen(own_h);
        let own = Posted {
            h: match self.told {
                Some(told) if !self.goalkeeper => told,
                _ => seen,
            },
            going: match self.told_going {
                Some(going) if !self.goalkeeper => going,
                _ => self.going,
            },
        };
        // Sized once: the filter's size hint would let the vector grow as it fills.
        let mut all: Vec<Candidate> = Vec::with_capacity(heard.len() + 1);
        all.extend(heard.iter().filter(|c| c.robot != self.me).copied());
        all.push(Candidate {
            robot: self.me,
            posted: own,
            age: Duration::ZERO,
        });
        let decision = decide(&self.params, &all);
        self.track_claims(&all);
        let wants = !self.goalkeeper && !self.listening() && decision.should_go(self.me);
        self.going = wants && !self.unacknowledged(&all);
        if !self.going {
            self.claimed_at = None;
        } else if self.claimed_at.is_none() {
            self.claimed_at = Some(self.clock);
        }
        let posted = Posted {
            h: own_h,
            going: self.going,
        };
        if !self.params.latency_compensation.is_zero() {
            self.history.push_back((self.clock, own_h));
        }
        (decision, posted)
    }

    /// Keep `claiming_since` up to date: a teammate's counted claim to be going is known
    /// to have begun at the latest when it was first heard, less its age.
    fn track_claims(&mut self, all: &[Candidate]) {
        let (me, clock, params) = (self.me, self.clock, self.params);
        let going = |c: &Candidate| c.robot != me && c.posted.going && params.counts(c);
        self.claiming_since
            .retain(|r, _| all.iter().any(|c| c.robot == *r && going(c)));
        for c in all.iter().filter(|c| going(c)) {
            self.claiming_since
                .entry(c.robot)
                .or_insert(clock.saturating_sub(c.age));
        }
        if let Some(g) = self.deferring_to {
            if !self.claiming_since.contains_key(&g) {
                // The goer let go (or fell silent beyond the silent-goer limit).
                self.deferring_to = None;
            }
        }
    }

    /// Whether this robot must not go although `decide` says so: it backed off from a
    /// goer that still claims, or its own claim has not been acknowledged by a goer that
    /// claimed before it (that goer still claims in a post made after the claim should
    /// have reached it and its release come back). The incumbent keeps the ball; the new
    /// claimant takes it when the incumbent lets go.
    fn unacknowledged(&mut self, all: &[Candidate]) -> bool {
        if self.deferring_to.is_some() {
            return true;
        }
        let Some(since) = self.claimed_at else {
            return false;
        };
        let wait = self.params.latency_compensation * 2 + self.params.ack_margin;
        let older = all.iter().find(|c| {
            c.robot != self.me
                && c.posted.going
                && c.age <= self.params.stale_after
                && self
                    .claiming_since
                    .get(&c.robot)
                    .is_some_and(|&s| s < since)
                && self.clock.saturating_sub(c.age) >= since + wait
        });
        if let Some(c) = older {
            self.deferring_to = Some(c.robot);
            return true;
        }
        false
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
    // Room for a team of up to 8 at once: collected from the scope walk (no size hint),
    // the vector started at 4 and regrew for a fifth robot, every robot every tick.
    let mut out = Vec::with_capacity(8);
    out.extend(
        board
            .robots_at(HEURISTIC_PATH)
            .filter_map(|(robot, entry)| {
                let Value::Floats(v) = &entry.value else {
                    return None;
                };
                Some(Candidate {
                    robot,
                    posted: Posted::from_floats(v)?,
                    age: entry.age(now),
                })
            }),
    );
    out
}

/// The path of [`HEURISTIC_KEY`] (what [`HEURISTIC_PATTERN`] matches in each robot's
/// scope).
const HEURISTIC_PATH: &str = "machine.heuristic";

/// The key to write `[h, going]` to (`*.var.machine.heuristic`).
pub fn heuristic_key() -> Key {
    // Parsed once: every robot asks for it several times a control tick, and a clone
    // shares the path (a reference count) where a parse allocates it.
    static KEY: std::sync::OnceLock<Key> = std::sync::OnceLock::new();
    KEY.get_or_init(|| Key::parse(HEURISTIC_KEY).expect("HEURISTIC_KEY is a valid key"))
        .clone()
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
    /// Whether `decide` counts this candidate: fresh (a claim to be going for longer), and
    /// with a finite cost below the no-ball cost.
    /// A posted cost as [`decide`] weighs it: lowered by the hysteresis margin while the
    /// robot says it is going.
    pub fn effective_cost(&self, posted: &Posted) -> f64 {
        if posted.going {
            posted.h - self.hysteresis_m
        } else {
            posted.h
        }
    }

    pub fn counts(&self, c: &Candidate) -> bool {
        let limit = if c.posted.going {
            self.stale_after.max(self.silent_goer_after)
        } else {
            self.stale_after
        };
        let h = c.posted.h;
        c.age <= limit && h.is_finite() && h < self.no_ball_cost
    }

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
        if let Some(v) = number(board, ACK_MARGIN_MS)? {
            p.ack_margin = Duration::from_secs_f64(
                check(ACK_MARGIN_MS, v, v >= 0.0, "must be >= 0")? / 1000.0,
            );
        }
        if let Some(v) = number(board, SILENT_GOER_MS)? {
            p.silent_goer_after =
                Duration::from_secs_f64(check(SILENT_GOER_MS, v, v > 0.0, "must be > 0")? / 1000.0);
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
mod tests;
