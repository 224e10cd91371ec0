//! The keys a robot program feeds the team layer through, and the keys it reads back:
//! `docs/team-layer.md` in code. Parsing is strict and total: every malformed input is a
//! [`ContractError`] that says what is wrong (the daemon turns it into the relay's
//! `ERR 412` line), and nothing is half-taken.

use fusion::nalgebra::{Matrix2, Matrix3, Vector2};
use fusion::{BallEstimate, PoseEstimate, RangeBearingSighting};
use thiserror::Error;

use crate::frames;
use crate::geometry::{Pose, Vec2};

/// The robot's own pose estimate (floats, see the contract).
pub const POSE_KEY: &str = "local.var.robot.pose";
/// Odometry since the previous write (floats `[forward, left, turn]`).
pub const ODOMETRY_KEY: &str = "local.var.robot.odometry";
/// Landmark sightings (floats, 6 per sighting).
pub const LANDMARKS_KEY: &str = "local.var.robot.landmarks";
/// One ball sighting, robot frame.
pub const BALL_KEY: &str = "local.var.robot.ball";
/// A kick the robot just made.
pub const KICK_KEY: &str = "local.var.robot.kick";
/// Eq. (19)'s `f_other` (bool).
pub const GOAL_IN_VIEW_KEY: &str = "local.var.robot.goal_in_view";
/// A cost replacing eq. (19) (float).
pub const COST_KEY: &str = "local.var.robot.cost";
/// The robot is the goalkeeper (bool).
pub const GOALKEEPER_KEY: &str = "local.var.robot.goalkeeper";
/// The robot is fallen (bool).
pub const FALLEN_KEY: &str = "local.var.robot.fallen";
/// The referee put the ball back (a kick-off after a goal): `true` makes the layer
/// forget the ball it tracked, as a robot program that handles the game's restarts says.
pub const BALL_RESET_KEY: &str = "local.var.robot.ball_reset";
/// The robot program heard the referee's whistle now (bool; each `true` is one whistle):
/// under GameController3, whose packets show play and goals 15 s late, it starts play in
/// Set and is a goal in play (`TeamLayer::heard_whistle`).
pub const WHISTLE_KEY: &str = "local.var.robot.whistle";

/// The team ball (floats `[x, y, vx, vy, var_x, cov_xy, var_y, confidence, age_s]`).
pub const TEAM_BALL_KEY: &str = "local.var.team.ball";
/// The goer (int, 0: none).
pub const GOER_KEY: &str = "local.var.team.goer";
/// Whether this robot goes (bool).
pub const GOING_KEY: &str = "local.var.team.going";
/// This robot's cost as posted (float).
pub const COST_OUT_KEY: &str = "local.var.team.cost";
/// Teammates (floats, 5 per teammate: `[id, x, y, θ, silent_s]`).
pub const MATES_KEY: &str = "local.var.team.mates";
/// This robot's own ball (floats `[x, y, vx, vy, var_x, cov_xy, var_y, age_s]`).
pub const OWN_BALL_KEY: &str = "local.var.team.own_ball";
/// The pose the layer holds (floats, as [`POSE_KEY`] without the age).
pub const POSE_OUT_KEY: &str = "local.var.team.pose";
/// Messages this robot may still send now under its budget (int).
pub const BUDGET_KEY: &str = "local.var.team.budget";
/// The layer's own world-model message of its latest tick, in full wire form (bytes:
/// fusion's 75-byte LWM, read with `fusion::LocalWorldModel::from_bytes`), written every
/// tick whatever the league's budget lets it send: what a log, or a reference fed every
/// robot's messages at once (`huddle sim --daemons`), wants.
pub const WORLD_OUT_KEY: &str = "local.var.team.world";
/// The time (float seconds on the driver's clock, as `[t]`; `[]` for none) of the play
/// whistle the layer acts on while the GameController still says Set
/// (`TeamLayer::play_whistle_at`): the daemon's GC listener paces the budget's clock
/// from it (`team::paced_game_remaining`).
pub const PLAY_WHISTLE_KEY: &str = "local.var.team.play_whistle";
/// The time (as [`PLAY_WHISTLE_KEY`]) of the goal's whistle the layer acts on while the
/// GameController still says Playing (`TeamLayer::whistle`, `Whistle::Goal`): out of play,
/// the robots walk to their kick-off places. With [`PLAY_WHISTLE_KEY`] it is the layer's
/// reading of the whistle, which a robot program's body follows ([`parse_whistle_at`]).
pub const GOAL_WHISTLE_KEY: &str = "local.var.team.goal_whistle";
/// The layer's ticks so far (int): it changes every tick, so a program that wrote a
/// cycle's senses can wait for the tick that took them.
pub const TICK_KEY: &str = "local.var.team.tick";

/// Oldest observation the layer takes, s.
pub const MAX_AGE_S: f64 = 10.0;

/// Farthest a pose or a landmark may be from the field's centre, m (and the longest
/// landmark range): every league's field fits many times over. A finite value beyond it
/// (`1e300`) is a program's bug, and the filters' arithmetic overflows on it to infinity
/// and then NaN, which they would carry from then on.
pub const MAX_FIELD_M: f64 = 100.0;

/// The variances (m², rad²) an input's covariance may have on its diagonal: σ from a
/// micrometre to a kilometre. Outside, a filter's update divides by a subnormal or
/// multiplies out of range, and the team ball turned NaN (the attack suite's extreme
/// senses, `docs/attack-suite.md`).
pub const VARIANCE_RANGE: std::ops::RangeInclusive<f64> = 1e-12..=1e6;

/// Why an input is refused.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum ContractError {
    /// The value is not of the key's type.
    #[error("{key} takes {expected}")]
    Type {
        /// The key.
        key: &'static str,
        /// What it takes.
        expected: &'static str,
    },
    /// A float vector of the wrong length.
    #[error("{key} takes {expected} numbers, got {got}")]
    Length {
        /// The key.
        key: &'static str,
        /// What it takes.
        expected: &'static str,
        /// How many it got.
        got: usize,
    },
    /// NaN or infinity.
    #[error("{key}: element {index} is not finite ({value})")]
    NotFinite {
        /// The key.
        key: &'static str,
        /// Which element.
        index: usize,
        /// Its value.
        value: f64,
    },
    /// A covariance that is not symmetric positive definite.
    #[error("{key}: the covariance is not positive definite")]
    Covariance {
        /// The key.
        key: &'static str,
    },
    /// An age out of [0, MAX_AGE_S].
    #[error("{key}: age_s {age_s} is not within [0, {MAX_AGE_S}] s")]
    Age {
        /// The key.
        key: &'static str,
        /// The age given.
        age_s: f64,
    },
    /// A value out of its range.
    #[error("{key}: {what}")]
    Range {
        /// The key.
        key: &'static str,
        /// What is wrong.
        what: &'static str,
    },
}

/// A pose the robot estimated itself.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseInput {
    /// REP-103 mean.
    pub pose: Pose,
    /// Covariance of (x, y, θ).
    pub cov: Matrix3<f64>,
    /// How old it was when written, s.
    pub age_s: f64,
}

/// A ball sighting in the robot frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallInput {
    /// REP-103 robot-frame place, m.
    pub local: Vector2<f64>,
    /// Its covariance.
    pub cov: Matrix2<f64>,
    /// How old it was when written, s.
    pub age_s: f64,
}

/// A kick the robot made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KickInput {
    /// Field-frame direction, rad.
    pub direction_rad: f64,
    /// Ball speed, m/s.
    pub speed_mps: f64,
    /// The robot's own odds that the foot met the ball.
    pub contact_prob: f64,
}

fn floats<'a>(
    key: &'static str,
    value: &'a comms::Value,
    expected: &'static str,
    lengths: &[usize],
) -> Result<&'a [f64], ContractError> {
    floats_where(key, value, expected, |n| lengths.contains(&n))
}

/// A finite float list whose length passes `length_ok` (described by `expected`).
fn floats_where<'a>(
    key: &'static str,
    value: &'a comms::Value,
    expected: &'static str,
    length_ok: impl Fn(usize) -> bool,
) -> Result<&'a [f64], ContractError> {
    let comms::Value::Floats(v) = value else {
        return Err(ContractError::Type {
            key,
            expected: "floats",
        });
    };
    if !length_ok(v.len()) {
        return Err(ContractError::Length {
            key,
            expected,
            got: v.len(),
        });
    }
    if let Some((index, &value)) = v.iter().enumerate().find(|(_, x)| !x.is_finite()) {
        return Err(ContractError::NotFinite { key, index, value });
    }
    Ok(v)
}

fn age(key: &'static str, v: &[f64], at: usize) -> Result<f64, ContractError> {
    let age_s = v.get(at).copied().unwrap_or(0.0);
    if (0.0..=MAX_AGE_S).contains(&age_s) {
        Ok(age_s)
    } else {
        Err(ContractError::Age { key, age_s })
    }
}

/// Whether a symmetric matrix is positive definite (Cholesky succeeds, diagonal > 0).
fn positive_definite<const N: usize>(m: &fusion::nalgebra::SMatrix<f64, N, N>) -> bool {
    (0..N).all(|i| m[(i, i)] > 0.0) && m.cholesky().is_some()
}

/// A covariance the filters can take: positive definite, its variances in
/// [`VARIANCE_RANGE`].
fn usable_covariance<const N: usize>(
    key: &'static str,
    m: &fusion::nalgebra::SMatrix<f64, N, N>,
) -> Result<(), ContractError> {
    if !positive_definite(m) {
        return Err(ContractError::Covariance { key });
    }
    if !(0..N).all(|i| VARIANCE_RANGE.contains(&m[(i, i)])) {
        return Err(ContractError::Range {
            key,
            what: "a variance outside 1e-12..=1e6 (σ from 1 µm to 1 km)",
        });
    }
    Ok(())
}

/// Whether a field-frame place is within [`MAX_FIELD_M`] of the centre.
fn on_field(x: f64, y: f64) -> bool {
    x.hypot(y) <= MAX_FIELD_M
}

/// Parses [`POSE_KEY`].
pub fn parse_pose(value: &comms::Value) -> Result<PoseInput, ContractError> {
    const KEY: &str = POSE_KEY;
    let v = floats(
        KEY,
        value,
        "9 or 10 (x, y, θ, 6 covariance terms, age_s)",
        &[9, 10],
    )?;
    let cov = Matrix3::new(v[3], v[4], v[5], v[4], v[6], v[7], v[5], v[7], v[8]);
    usable_covariance(KEY, &cov)?;
    if !on_field(v[0], v[1]) {
        return Err(ContractError::Range {
            key: KEY,
            what: "a pose more than 100 m from the field's centre",
        });
    }
    Ok(PoseInput {
        pose: Pose {
            at: Vec2::new(v[0], v[1]),
            theta_rad: fusion::wrap_angle(v[2]),
        },
        cov,
        age_s: age(KEY, v, 9)?,
    })
}

/// Parses [`ODOMETRY_KEY`].
pub fn parse_odometry(value: &comms::Value) -> Result<fusion::Odometry, ContractError> {
    let v = floats(ODOMETRY_KEY, value, "3 (forward, left, turn)", &[3])?;
    if v[0].hypot(v[1]) > 5.0 || v[2].abs() > 2.0 * std::f64::consts::PI {
        return Err(ContractError::Range {
            key: ODOMETRY_KEY,
            what: "more than 5 m or a full turn since the previous write",
        });
    }
    Ok(fusion::Odometry {
        forward_m: v[0],
        left_m: v[1],
        turn_rad: v[2],
    })
}

/// Parses [`LANDMARKS_KEY`]: each sighting with its R, in `fusion`'s terms.
pub fn parse_landmarks(
    value: &comms::Value,
) -> Result<Vec<(RangeBearingSighting, Matrix2<f64>)>, ContractError> {
    const KEY: &str = LANDMARKS_KEY;
    let comms::Value::Floats(all) = value else {
        return Err(ContractError::Type {
            key: KEY,
            expected: "floats",
        });
    };
    if all.len() % 6 != 0 || all.len() > 6 * 64 {
        return Err(ContractError::Length {
            key: KEY,
            expected: "6 per sighting (field_x, field_y, range, bearing, σ_range, σ_bearing), at most 64 sightings",
            got: all.len(),
        });
    }
    let v = floats(KEY, value, "", &[all.len()])?;
    v.chunks_exact(6)
        .map(|s| {
            if s[2] < 0.0 || s[4] <= 0.0 || s[5] <= 0.0 {
                return Err(ContractError::Range {
                    key: KEY,
                    what: "a range below 0 or a σ not above 0",
                });
            }
            if !on_field(s[0], s[1])
                || s[2] > MAX_FIELD_M
                || !VARIANCE_RANGE.contains(&(s[4] * s[4]))
                || !VARIANCE_RANGE.contains(&(s[5] * s[5]))
            {
                return Err(ContractError::Range {
                    key: KEY,
                    what: "a landmark or a range beyond 100 m, or a σ outside 1e-6..=1e3",
                });
            }
            Ok((
                RangeBearingSighting {
                    field: Vector2::new(s[0], s[1]),
                    range_m: s[2],
                    bearing_rad: s[3],
                },
                Matrix2::new(s[4] * s[4], 0.0, 0.0, s[5] * s[5]),
            ))
        })
        .collect()
}

/// Parses [`BALL_KEY`].
pub fn parse_ball(value: &comms::Value) -> Result<BallInput, ContractError> {
    const KEY: &str = BALL_KEY;
    let v = floats(
        KEY,
        value,
        "5 or 6 (x, y, var_x, cov_xy, var_y, age_s)",
        &[5, 6],
    )?;
    let cov = Matrix2::new(v[2], v[3], v[3], v[4]);
    usable_covariance(KEY, &cov)?;
    if v[0].hypot(v[1]) > 50.0 {
        return Err(ContractError::Range {
            key: KEY,
            what: "a ball more than 50 m away",
        });
    }
    Ok(BallInput {
        local: Vector2::new(v[0], v[1]),
        cov,
        age_s: age(KEY, v, 5)?,
    })
}

/// Parses [`KICK_KEY`].
pub fn parse_kick(value: &comms::Value) -> Result<KickInput, ContractError> {
    const KEY: &str = KICK_KEY;
    let v = floats(
        KEY,
        value,
        "2 or 3 (direction, speed, contact_prob)",
        &[2, 3],
    )?;
    let contact_prob = v.get(2).copied().unwrap_or(1.0);
    if !(0.0..=20.0).contains(&v[1]) || !(0.0..=1.0).contains(&contact_prob) {
        return Err(ContractError::Range {
            key: KEY,
            what: "speed outside 0–20 m/s or contact_prob outside 0–1",
        });
    }
    Ok(KickInput {
        direction_rad: fusion::wrap_angle(v[0]),
        speed_mps: v[1],
        contact_prob,
    })
}

/// Parses a bool key ([`GOAL_IN_VIEW_KEY`], [`GOALKEEPER_KEY`], [`FALLEN_KEY`],
/// [`BALL_RESET_KEY`], [`WHISTLE_KEY`]).
pub fn parse_bool(key: &'static str, value: &comms::Value) -> Result<bool, ContractError> {
    match value {
        comms::Value::Bool(b) => Ok(*b),
        _ => Err(ContractError::Type {
            key,
            expected: "a bool",
        }),
    }
}

/// Reads [`PLAY_WHISTLE_KEY`] or [`GOAL_WHISTLE_KEY`] (`key`): `[t]`, the whistle the
/// layer acts on, heard at `t` (seconds on the daemon's clock); `[]`, none.
pub fn parse_whistle_at(
    key: &'static str,
    value: &comms::Value,
) -> Result<Option<f64>, ContractError> {
    Ok(floats(key, value, "0 or 1", &[0, 1])?.first().copied())
}

/// Parses [`COST_KEY`].
pub fn parse_cost(value: &comms::Value) -> Result<f64, ContractError> {
    let h = match value {
        comms::Value::Float(h) => *h,
        comms::Value::Int(h) => *h as f64,
        _ => {
            return Err(ContractError::Type {
                key: COST_KEY,
                expected: "a float",
            })
        }
    };
    if h.is_finite() {
        Ok(h)
    } else {
        Err(ContractError::NotFinite {
            key: COST_KEY,
            index: 0,
            value: h,
        })
    }
}

/// Checks the value written to an input `key`; `None` for a key that is not an input.
pub fn check(key: &str, value: &comms::Value) -> Option<Result<(), ContractError>> {
    Some(match key {
        POSE_KEY => parse_pose(value).map(drop),
        ODOMETRY_KEY => parse_odometry(value).map(drop),
        LANDMARKS_KEY => parse_landmarks(value).map(drop),
        BALL_KEY => parse_ball(value).map(drop),
        KICK_KEY => parse_kick(value).map(drop),
        GOAL_IN_VIEW_KEY => parse_bool(GOAL_IN_VIEW_KEY, value).map(drop),
        GOALKEEPER_KEY => parse_bool(GOALKEEPER_KEY, value).map(drop),
        FALLEN_KEY => parse_bool(FALLEN_KEY, value).map(drop),
        BALL_RESET_KEY => parse_bool(BALL_RESET_KEY, value).map(drop),
        WHISTLE_KEY => parse_bool(WHISTLE_KEY, value).map(drop),
        COST_KEY => parse_cost(value).map(drop),
        _ => return None,
    })
}

/// The input keys, for guards and watches.
pub const INPUT_KEYS: [&str; 11] = [
    POSE_KEY,
    ODOMETRY_KEY,
    LANDMARKS_KEY,
    BALL_KEY,
    KICK_KEY,
    GOAL_IN_VIEW_KEY,
    COST_KEY,
    GOALKEEPER_KEY,
    FALLEN_KEY,
    BALL_RESET_KEY,
    WHISTLE_KEY,
];

/// A pose estimate as [`POSE_OUT_KEY`] gives it (REP-103).
pub fn pose_value(est: &PoseEstimate) -> comms::Value {
    let p = frames::from_fusion_pose(est);
    let mut out = vec![p.at.x, p.at.y, p.theta_rad];
    out.extend(upper_triangle(&est.cov));
    comms::Value::Floats(out)
}

/// A 3×3 covariance's upper triangle, row by row (`var_x, cov_xy, cov_xθ, var_y, cov_yθ,
/// var_θ`): the contract's order for poses.
pub fn upper_triangle(c: &Matrix3<f64>) -> [f64; 6] {
    [
        c[(0, 0)],
        c[(0, 1)],
        c[(0, 2)],
        c[(1, 1)],
        c[(1, 2)],
        c[(2, 2)],
    ]
}

/// A ball estimate at `now_s` as [`TEAM_BALL_KEY`] / [`OWN_BALL_KEY`] give it;
/// `confidence` is put before the age when given.
pub fn ball_value(b: &BallEstimate, confidence: Option<f64>, age_s: f64) -> comms::Value {
    let (p, v, c) = (b.position(), b.velocity(), b.position_cov());
    let mut out = vec![p.x, p.y, v.x, v.y, c[(0, 0)], c[(0, 1)], c[(1, 1)]];
    out.extend(confidence);
    out.push(age_s.max(0.0));
    comms::Value::Floats(out)
}

/// No ball: what [`TEAM_BALL_KEY`] / [`OWN_BALL_KEY`] hold once a ball they gave is gone
/// (forgotten at a kick-off, or no longer seen by anyone): no floats.
pub fn no_ball_value() -> comms::Value {
    comms::Value::Floats(Vec::new())
}

/// A ball as the layer publishes it ([`TEAM_BALL_KEY`], [`OWN_BALL_KEY`]), as a robot
/// program reads it back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallOutput {
    /// Field place when published, m.
    pub at: Vec2,
    /// Field velocity, m/s.
    pub velocity: Vec2,
    /// Covariance of the place, m².
    pub cov: Matrix2<f64>,
    /// The global ball confidence (0–1): the team ball's only.
    pub confidence: Option<f64>,
    /// Age of the newest sighting in it when published, s.
    pub age_s: f64,
}

impl BallOutput {
    /// Where it is `dt_s` after it was published, at its published velocity.
    pub fn at_after(&self, dt_s: f64) -> Vec2 {
        self.at + self.velocity * dt_s
    }
}

/// Reads [`TEAM_BALL_KEY`] (9 floats, with the confidence) or [`OWN_BALL_KEY`] (8).
/// `Ok(None)`: `[]`, the layer had a ball and has none now. Any other key is read as the
/// own ball's form.
pub fn parse_ball_output(
    key: &'static str,
    value: &comms::Value,
) -> Result<Option<BallOutput>, ContractError> {
    if matches!(value, comms::Value::Floats(v) if v.is_empty()) {
        return Ok(None);
    }
    let team = key == TEAM_BALL_KEY;
    let v = if team {
        floats(key, value, "9 (or none)", &[9])?
    } else {
        floats(key, value, "8 (or none)", &[8])?
    };
    Ok(Some(BallOutput {
        at: Vec2::new(v[0], v[1]),
        velocity: Vec2::new(v[2], v[3]),
        cov: Matrix2::new(v[4], v[5], v[5], v[6]),
        confidence: team.then_some(v[7]),
        age_s: v[v.len() - 1],
    }))
}

/// The pose the layer holds ([`POSE_OUT_KEY`]), as a robot program reads it back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseOutput {
    /// REP-103 mean.
    pub pose: Pose,
    /// Covariance of (x, y, θ).
    pub cov: Matrix3<f64>,
}

/// Reads [`POSE_OUT_KEY`]: `[x, y, θ]` and the covariance's upper triangle.
pub fn parse_pose_output(value: &comms::Value) -> Result<PoseOutput, ContractError> {
    let v = floats(POSE_OUT_KEY, value, "9", &[9])?;
    Ok(PoseOutput {
        pose: Pose {
            at: Vec2::new(v[0], v[1]),
            theta_rad: v[2],
        },
        cov: Matrix3::new(v[3], v[4], v[5], v[4], v[6], v[7], v[5], v[7], v[8]),
    })
}

/// A teammate as [`MATES_KEY`] gives it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MateOutput {
    /// Its robot id.
    pub id: u8,
    /// Its pose from its messages (REP-103).
    pub pose: Pose,
    /// How long it has been silent, s.
    pub silent_s: f64,
}

/// Reads [`MATES_KEY`]: 5 floats per teammate, `[id, x, y, θ, silent_s]`.
pub fn parse_mates(value: &comms::Value) -> Result<Vec<MateOutput>, ContractError> {
    let key = MATES_KEY;
    let v = floats_where(key, value, "5 per teammate", |n| n % 5 == 0)?;
    v.chunks(5)
        .map(|m| {
            if !(1.0..=255.0).contains(&m[0]) || m[0].fract() != 0.0 {
                return Err(ContractError::Range {
                    key,
                    what: "a teammate's id is not a robot number 1-255",
                });
            }
            Ok(MateOutput {
                id: m[0] as u8,
                pose: Pose {
                    at: Vec2::new(m[1], m[2]),
                    theta_rad: m[3],
                },
                silent_s: m[4],
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use comms::Value;

    #[test]
    fn a_pose_with_its_covariance_and_age_is_taken() {
        let p = parse_pose(&Value::Floats(vec![
            1.0, -2.0, 0.5, 0.01, 0.0, 0.0, 0.01, 0.0, 0.001, 0.02,
        ]))
        .expect("a good pose");
        assert_eq!(p.pose.at, Vec2::new(1.0, -2.0));
        assert!((p.age_s - 0.02).abs() < 1e-12);
    }

    #[test]
    fn every_kind_of_bad_input_is_refused_with_a_reason() {
        let cases: [(&str, Value, &str); 9] = [
            (POSE_KEY, Value::Float(1.0), "takes floats"),
            (POSE_KEY, Value::Floats(vec![0.0; 4]), "takes 9 or 10"),
            (
                POSE_KEY,
                Value::Floats(vec![0.0, 0.0, f64::NAN, 0.1, 0.0, 0.0, 0.1, 0.0, 0.1]),
                "not finite",
            ),
            (
                POSE_KEY,
                Value::Floats(vec![0.0, 0.0, 0.0, 0.1, 0.5, 0.0, 0.1, 0.0, 0.1]),
                "positive definite",
            ),
            (
                BALL_KEY,
                Value::Floats(vec![1.0, 0.0, 0.01, 0.0, 0.01, -1.0]),
                "age_s -1",
            ),
            (
                BALL_KEY,
                Value::Floats(vec![1.0, 0.0, 0.01, 0.0, 0.01, 3600.0]),
                "age_s 3600",
            ),
            (
                BALL_KEY,
                Value::Floats(vec![1.0, f64::INFINITY, 0.01, 0.0, 0.01]),
                "not finite",
            ),
            (KICK_KEY, Value::Floats(vec![0.0, 4.0, 1.5]), "contact_prob"),
            (COST_KEY, Value::Float(f64::NAN), "not finite"),
        ];
        assert_refused(cases);
        assert!(check("local.var.other", &Value::Int(1)).is_none());
    }

    /// Each input is refused by the contract, with an error that names why.
    fn assert_refused<const N: usize>(cases: [(&str, Value, &str); N]) {
        for (key, value, why) in cases {
            let err = check(key, &value)
                .expect("an input key")
                .expect_err(&format!("{key} {value:?} must be refused"));
            assert!(
                err.to_string().contains(why),
                "{key} {value:?}: '{err}' should say '{why}'"
            );
        }
    }

    #[test]
    fn finite_but_absurd_senses_are_refused_before_they_reach_the_filters() {
        // What the attack suite's extreme senses wrote (each one taken before, and the
        // team ball, own ball and pose turned NaN or infinite): a pose 1e300 m away,
        // variances of 5e-324 and 1e300, a landmark σ that squares to 0, a landmark
        // range of 1e15 m. A real robot's values pass.
        let pose =
            |x: f64, var: f64| Value::Floats(vec![x, 0.0, 0.0, var, 0.0, 0.0, 0.01, 0.0, 0.003]);
        let ball = |var: f64| Value::Floats(vec![1.0, 0.0, var, 0.0, 0.01]);
        let landmark =
            |range: f64, sigma: f64| Value::Floats(vec![4.5, 0.0, range, 0.0, sigma, 0.05]);
        let refused: [(&str, Value, &str); 8] = [
            (POSE_KEY, pose(1e300, 0.01), "100 m"),
            (POSE_KEY, pose(0.0, 5e-324), "variance"),
            (POSE_KEY, pose(0.0, 1e300), "variance"),
            (BALL_KEY, ball(5e-324), "variance"),
            (BALL_KEY, ball(1e300), "variance"),
            (LANDMARKS_KEY, landmark(1.0, 1e-300), "σ"),
            (LANDMARKS_KEY, landmark(1e15, 0.1), "range beyond 100 m"),
            (LANDMARKS_KEY, landmark(1.0, 1e300), "σ"),
        ];
        assert_refused(refused);
        for (key, value) in [
            (POSE_KEY, pose(-4.5, 0.0004)),
            (POSE_KEY, pose(12.0, 25.0)),
            (BALL_KEY, ball(1e-6)),
            (LANDMARKS_KEY, landmark(6.0, 0.2)),
        ] {
            assert_eq!(
                check(key, &value),
                Some(Ok(())),
                "{key} {value:?} is a robot's"
            );
        }
    }

    #[test]
    fn outputs_read_back_what_the_layer_writes_and_none_as_empty() {
        let est = BallEstimate {
            t_s: 1.0,
            mean: fusion::nalgebra::Vector4::new(1.0, -2.0, 0.5, 0.0),
            cov: fusion::nalgebra::Matrix4::identity() * 0.01,
        };
        let team = parse_ball_output(TEAM_BALL_KEY, &ball_value(&est, Some(0.8), 0.1))
            .expect("the layer's own form")
            .expect("a ball");
        assert_eq!(team.confidence, Some(0.8));
        assert_eq!((team.at, team.age_s), (Vec2::new(1.0, -2.0), 0.1));
        let own = parse_ball_output(OWN_BALL_KEY, &ball_value(&est, None, 0.2))
            .expect("the layer's own form")
            .expect("a ball");
        assert_eq!(own.confidence, None);
        assert_eq!(
            parse_ball_output(TEAM_BALL_KEY, &no_ball_value()),
            Ok(None),
            "[] is no ball"
        );
        assert!(
            parse_ball_output(TEAM_BALL_KEY, &ball_value(&est, None, 0.2)).is_err(),
            "the team ball carries its confidence"
        );
        let mates = parse_mates(&Value::Floats(vec![2.0, 1.0, 1.0, 0.5, 0.1])).expect("one");
        assert_eq!((mates[0].id, mates[0].silent_s), (2, 0.1));
        assert!(parse_mates(&Value::Floats(vec![0.0, 1.0, 1.0, 0.5, 0.1])).is_err());
        assert!(parse_mates(&Value::Floats(vec![2.0, 1.0])).is_err());
        let pose = PoseEstimate::new(
            0.0,
            1.0,
            0.3,
            fusion::nalgebra::Vector3::new(0.01, 0.02, 0.001),
        );
        let back = parse_pose_output(&pose_value(&pose)).expect("the layer's own form");
        assert!((back.cov[(1, 1)] - pose.cov[(1, 1)]).abs() < 1e-12);
    }
}
