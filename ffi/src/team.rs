//! Typed calls for the team layer's keys (docs/team-layer.md): the robot program's
//! inputs (`local.var.robot.*`) and the layer's outputs (`local.var.team.*`), as thin
//! wrappers over the typed float-vector set and get, in the contract's order and units
//! (field frame, metres, radians, seconds; covariances as their upper triangle).
//!
//! The node runs the team layer itself, the code `huddle daemon` runs for its robot
//! (`driver::team::TeamCore`, see `engine`): the inputs written here (or with any set
//! call on their keys) feed it, and it writes the outputs read here every tick, so a C
//! program gets the team ball, the goer and whether it goes without a daemon. Inputs are
//! checked by the contract the daemon's relay guards run (`team::contract`: finite
//! numbers, a positive definite covariance, `age_s` in 0..=10, ranges): a bad one is
//! refused with `HUDDLE_E_VALUE` and the contract's reason, and nothing is written.
//! With `no_team_layer` set, the calls still check their values, and the output keys
//! hold whatever the program writes there.

use std::ffi::c_int;

use comms::Value;

use crate::error::*;
use crate::node::{get_value, huddle_node, set_value};
use crate::typed::{read_array, wrong_type};

/// The team ball (`local.var.team.ball`), field frame.
#[repr(C)]
#[allow(non_camel_case_types)]
pub struct huddle_team_ball {
    /// Position, m.
    pub x: f64,
    /// Position, m.
    pub y: f64,
    /// Velocity, m/s.
    pub vx: f64,
    /// Velocity, m/s.
    pub vy: f64,
    /// Position covariance, m²: var_x, cov_xy, var_y.
    pub cov: [f64; 3],
    /// The global ball confidence, 0..=1.
    pub confidence: f64,
    /// Age of the newest sighting in it, s.
    pub age_s: f64,
}

/// A pose with covariance (`local.var.team.pose`), field frame.
#[repr(C)]
#[allow(non_camel_case_types)]
pub struct huddle_pose {
    /// Position, m.
    pub x: f64,
    /// Position, m.
    pub y: f64,
    /// Heading, rad, counter-clockwise from +x.
    pub theta: f64,
    /// Covariance of (x, y, θ), upper triangle: var_x, cov_xy, cov_xθ, var_y, cov_yθ,
    /// var_θ.
    pub cov: [f64; 6],
}

/// A teammate as the team layer knows it (`local.var.team.mates`).
#[repr(C)]
#[allow(non_camel_case_types)]
pub struct huddle_teammate {
    /// Its robot id.
    pub robot: u8,
    /// Its pose from its messages, field frame (m, m, rad).
    pub x: f64,
    /// See `x`.
    pub y: f64,
    /// See `x`.
    pub theta: f64,
    /// How long it has been silent, s.
    pub silent_s: f64,
}

fn bad(what: &str, why: impl std::fmt::Display) -> Failure {
    Failure::new(HUDDLE_E_VALUE, format!("{what}: {why}; nothing written"))
}

/// The team layer's own check of a value for input `key` (`team::contract`, the one the
/// daemon's relay guards run): a refusal is `HUDDLE_E_VALUE` with its reason.
fn contract(key: &'static str, value: &Value) -> Result<(), Failure> {
    match team::contract::check(key, value) {
        // The contract's reason names the key already.
        Some(Err(e)) => Err(Failure::new(
            HUDDLE_E_VALUE,
            format!("{e}; nothing written"),
        )),
        _ => Ok(()),
    }
}

/// Runs `body` for a team call: the checks, then the set.
///
/// # Safety
///
/// `err` is NULL or writable.
unsafe fn team_set(err: *mut huddle_error, body: impl FnOnce() -> Result<(), Failure>) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe { guard(err, -1, || body().map(|()| 0)) }
}

/// Writes the robot's own pose estimate to `local.var.robot.pose`: field frame (m, m,
/// rad), `cov` the 6-element upper triangle of its (x, y, θ) covariance, `age_s` how old
/// the estimate already is (0..=10 s). Returns 0, or -1 (`HUDDLE_E_VALUE`: not finite,
/// covariance not positive definite, age out of range).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `cov` is NULL or readable for 6 doubles; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_robot_pose(
    node: *mut huddle_node,
    x: f64,
    y: f64,
    theta: f64,
    cov: *const f64,
    age_s: f64,
    err: *mut huddle_error,
) -> c_int {
    let what = team::contract::POSE_KEY;
    // SAFETY: `err` forwarded; `cov` readable for 6 doubles as the caller promises.
    unsafe {
        team_set(err, || {
            let cov = read_array(cov, 6, "cov")?;
            let mut v = vec![x, y, theta];
            v.extend_from_slice(cov);
            v.push(age_s);
            let value = Value::Floats(v);
            contract(what, &value)?;
            set_value(node, what, value, false)
        })
    }
}

/// Writes one ball sighting to `local.var.robot.ball`: robot frame (m), `cov` the
/// 3-element upper triangle of its covariance (m²), `age_s` how old it is (0..=10 s).
/// Write it when the camera sees the ball, not again otherwise. Returns 0, or -1
/// (`HUDDLE_E_VALUE`).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `cov` is NULL or readable for 3 doubles; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_robot_ball(
    node: *mut huddle_node,
    x: f64,
    y: f64,
    cov: *const f64,
    age_s: f64,
    err: *mut huddle_error,
) -> c_int {
    let what = team::contract::BALL_KEY;
    // SAFETY: `err` forwarded; `cov` readable for 3 doubles as the caller promises.
    unsafe {
        team_set(err, || {
            let cov = read_array(cov, 3, "cov")?;
            let mut v = vec![x, y];
            v.extend_from_slice(cov);
            v.push(age_s);
            let value = Value::Floats(v);
            contract(what, &value)?;
            set_value(node, what, value, false)
        })
    }
}

/// Writes the motion since the previous odometry write to `local.var.robot.odometry`:
/// robot frame, `forward` and `left` in m, `turn` in rad. Returns 0, or -1.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_robot_odometry(
    node: *mut huddle_node,
    forward: f64,
    left: f64,
    turn: f64,
    err: *mut huddle_error,
) -> c_int {
    let what = team::contract::ODOMETRY_KEY;
    // SAFETY: forwarded from the caller.
    unsafe {
        team_set(err, || {
            let value = Value::Floats(vec![forward, left, turn]);
            contract(what, &value)?;
            set_value(node, what, value, false)
        })
    }
}

/// Writes a kick the robot just made to `local.var.robot.kick`: field-frame `direction`
/// (rad), ball `speed` (m/s, ≥ 0), `contact_prob` its own odds the foot met the ball
/// (0..=1). A kick matters to the team at once: it goes on the priority path. Returns 0,
/// or -1.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_robot_kick(
    node: *mut huddle_node,
    direction: f64,
    speed: f64,
    contact_prob: f64,
    err: *mut huddle_error,
) -> c_int {
    let what = team::contract::KICK_KEY;
    // SAFETY: forwarded from the caller.
    unsafe {
        team_set(err, || {
            let value = Value::Floats(vec![direction, speed, contact_prob]);
            contract(what, &value)?;
            set_value(node, what, value, true)
        })
    }
}

/// Writes landmark sightings to `local.var.robot.landmarks`: `count` sightings of 6
/// doubles each at `sightings`: `field_x, field_y, range, bearing, sigma_range,
/// sigma_bearing` (m, rad; sigmas > 0). Returns 0, or -1.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `sightings` is readable for `6 * count` doubles (NULL when `count` is 0); `err` is
/// NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_robot_landmarks(
    node: *mut huddle_node,
    sightings: *const f64,
    count: usize,
    err: *mut huddle_error,
) -> c_int {
    let what = team::contract::LANDMARKS_KEY;
    // SAFETY: forwarded from the caller: `6 * count` readable doubles.
    unsafe {
        team_set(err, || {
            let n = count
                .checked_mul(6)
                .ok_or_else(|| bad(what, "count overflows"))?;
            let value = Value::Floats(read_array(sightings, n, "sightings")?.to_vec());
            contract(what, &value)?;
            set_value(node, what, value, false)
        })
    }
}

/// Reads who goes to the ball: `goer` gets the robot the team layer says goes
/// (`local.var.team.goer`, 0: none), `going` 1 if it is this robot
/// (`local.var.team.going`), else 0. Returns 1, 0 while the layer has not decided yet
/// (dormant: no pose or odometry written; or no team layer), -1 on error
/// (`HUDDLE_E_TYPE`).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `goer`, `going` and `err` are NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_get_team_goer(
    node: *mut huddle_node,
    goer: *mut u8,
    going: *mut std::ffi::c_int,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises both are NULL or valid for writes.
        let (goer, going) = unsafe { (goer.as_mut(), going.as_mut()) };
        let goer = goer.ok_or_else(|| Failure::null("goer"))?;
        let going = going.ok_or_else(|| Failure::null("going"))?;
        // One read under one lock: a tick between two reads could pair a goer with
        // another tick's `going`.
        let read = crate::node::lookup(node)?.with_state(|state, _| {
            let get = |key| {
                state
                    .replica
                    .get(key)
                    .ok()
                    .flatten()
                    .map(|e| e.value.clone())
            };
            (
                get(team::contract::GOER_KEY),
                get(team::contract::GOING_KEY),
            )
        })?;
        Ok(match read {
            (None, _) | (_, None) => 0,
            (Some(Value::Int(g)), Some(Value::Bool(me))) => {
                *goer = u8::try_from(g).map_err(|_| {
                    Failure::new(
                        HUDDLE_E_TYPE,
                        format!("local.var.team.goer holds {g}, not a robot id"),
                    )
                })?;
                *going = c_int::from(me);
                1
            }
            (Some(Value::Int(_)), Some(other)) => {
                return Err(wrong_type(team::contract::GOING_KEY, &other, "bool"))
            }
            (Some(other), _) => return Err(wrong_type(team::contract::GOER_KEY, &other, "int")),
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Reads output `key` through the contract's parser (`team::contract`, the reading the
/// simulator's robot programs use too): absent is `Ok(None)`; a value that is not what
/// the contract says is `HUDDLE_E_TYPE` with the contract's reason.
fn team_output<T>(
    node: *mut huddle_node,
    key: &'static str,
    parse: impl FnOnce(&Value) -> Result<T, team::contract::ContractError>,
) -> Result<Option<T>, Failure> {
    match get_value(node, key)? {
        None => Ok(None),
        Some(v) => parse(&v)
            .map(Some)
            .map_err(|e| Failure::new(HUDDLE_E_TYPE, e.to_string())),
    }
}

/// Reads the team ball (`local.var.team.ball`) into `out`. Returns 1, 0 while there is
/// none (no robot has seen the ball, it was forgotten at a kick-off, or no team layer
/// runs), -1 on error (`HUDDLE_E_TYPE`: the key holds
/// something else than the contract's 9 floats).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_get_team_ball(
    node: *mut huddle_node,
    out: *mut huddle_team_ball,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises `out` is NULL or valid for writes.
        let out = unsafe { out.as_mut() }.ok_or_else(|| Failure::null("out"))?;
        let key = team::contract::TEAM_BALL_KEY;
        let ball = team_output(node, key, |v| team::contract::parse_ball_output(key, v))?;
        Ok(match ball.flatten() {
            Some(b) => {
                *out = huddle_team_ball {
                    x: b.at.x,
                    y: b.at.y,
                    vx: b.velocity.x,
                    vy: b.velocity.y,
                    cov: [b.cov[(0, 0)], b.cov[(0, 1)], b.cov[(1, 1)]],
                    confidence: b.confidence.unwrap_or(0.0),
                    age_s: b.age_s,
                };
                1
            }
            // Absent, or `[]`: the layer has no team ball now.
            None => 0,
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Reads the pose the team layer holds for this robot (`local.var.team.pose`) into
/// `out`. Returns 1, 0 when there is none, -1 on error (`HUDDLE_E_TYPE`).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_get_team_pose(
    node: *mut huddle_node,
    out: *mut huddle_pose,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises `out` is NULL or valid for writes.
        let out = unsafe { out.as_mut() }.ok_or_else(|| Failure::null("out"))?;
        let key = team::contract::POSE_OUT_KEY;
        Ok(
            match team_output(node, key, team::contract::parse_pose_output)? {
                Some(p) => {
                    *out = huddle_pose {
                        x: p.pose.at.x,
                        y: p.pose.at.y,
                        theta: p.pose.theta_rad,
                        cov: team::contract::upper_triangle(&p.cov),
                    };
                    1
                }
                None => 0,
            },
        )
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Reads the teammates (`local.var.team.mates`) into `out` (room for `cap`); `count`
/// gets how many there are. `out` NULL and `cap` 0: only the count. Returns 1, 0 when
/// the key is absent, -1 on error (`HUDDLE_E_BUFFER` when `cap < count`, nothing copied;
/// `HUDDLE_E_TYPE`).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `out` is NULL or writable for `cap` teammates; `count` is NULL or writable; `err` is
/// NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_get_team_mates(
    node: *mut huddle_node,
    out: *mut huddle_teammate,
    cap: usize,
    count: *mut usize,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises `count` is NULL or valid for writes.
        let count = unsafe { count.as_mut() }.ok_or_else(|| Failure::null("count"))?;
        let key = team::contract::MATES_KEY;
        let Some(mates) = team_output(node, key, team::contract::parse_mates)? else {
            *count = 0;
            return Ok(0);
        };
        let mates: Vec<huddle_teammate> = mates
            .into_iter()
            .map(|m| huddle_teammate {
                robot: m.id,
                x: m.pose.at.x,
                y: m.pose.at.y,
                theta: m.pose.theta_rad,
                silent_s: m.silent_s,
            })
            .collect();
        *count = mates.len();
        if out.is_null() && cap == 0 {
            return Ok(1);
        }
        if out.is_null() {
            return Err(Failure::null("out"));
        }
        if mates.len() > cap {
            return Err(Failure::new(
                HUDDLE_E_BUFFER,
                format!("{} teammates, room for {cap}", mates.len()),
            ));
        }
        for (i, mate) in mates.into_iter().enumerate() {
            // SAFETY: non-NULL, and the caller promises `cap > i` writable teammates.
            unsafe { out.add(i).write(mate) };
        }
        Ok(1)
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2×2 upper triangle as a ball sighting, a 3×3 one as a pose: what `contract` says.
    fn positive_definite(upper: &[f64]) -> bool {
        let (key, mut v) = match upper.len() {
            6 => (team::contract::POSE_KEY, vec![0.0, 0.0, 0.0]),
            _ => (team::contract::BALL_KEY, vec![1.0, 0.0]),
        };
        v.extend_from_slice(upper);
        contract(key, &Value::Floats(v)).is_ok()
    }

    #[test]
    fn covariances_must_be_positive_definite_by_their_leading_minors() {
        assert!(positive_definite(&[0.04, 0.0, 0.04]));
        assert!(positive_definite(&[0.1, 0.01, 0.0, 0.1, 0.0, 0.01]));
        assert!(!positive_definite(&[0.04, 0.05, 0.04]), "det < 0");
        assert!(!positive_definite(&[-1.0, 0.0, 1.0]), "negative variance");
        // Leading minors 1, 1 but det = -3: indefinite in θ.
        assert!(!positive_definite(&[1.0, 0.0, 2.0, 1.0, 0.0, 1.0]));
        assert!(!positive_definite(&[1.0, 0.0]), "wrong length");
    }
}
