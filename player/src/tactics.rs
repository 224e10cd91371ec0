//! What the team does around the ball once arbitration has named the goer: CMUnited-97's
//! team modes (§3.2) and its pass-or-shoot choice by the obstruction-free-index
//! (cmunited-97-perception §3.2.2). Field behaviour, not team communication: who goes is
//! `comms::arbitration`'s decision, read here as a [`Decision`].

use comms::arbitration::Decision;

use team::Vec2;

/// CMUnited-97's team modes (§3.2): the goer is active, the robot it intends to pass
/// to is auxiliary, the rest hold their formation positions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Mode {
    /// Going to the ball: passes or shoots.
    Active,
    /// The intended receiver of the active robot's pass.
    Auxiliary,
    /// Holding its formation position, facing the ball.
    Inactive,
    /// The goalkeeper: never competes for the ball.
    Goaltend,
}

/// The key the active robot announces its intended receiver on (`Int`, 0 = shooting).
pub const PASS_TO_KEY: &str = "*.var.machine.pass_to";

/// The mode of robot `me`, given the decision and the active robot's announced receiver.
pub fn mode(me: u8, goalkeeper: bool, decision: &Decision, pass_to: Option<u8>) -> Mode {
    if goalkeeper {
        Mode::Goaltend
    } else if decision.should_go(me) {
        Mode::Active
    } else if pass_to == Some(me) && decision.goer.is_some() {
        Mode::Auxiliary
    } else {
        Mode::Inactive
    }
}

/// The constants of the obstruction-free-index (cmunited-97-perception §3.2.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PassParams {
    /// Opponents farther than this from the segment do not count, metres.
    pub min_dist_m: f64,
    /// Distances along the segment are capped here, metres: beyond it an opponent has
    /// time to block anyway.
    pub max_denominator_m: f64,
}

impl Default for PassParams {
    fn default() -> Self {
        Self {
            min_dist_m: 1.0,
            max_denominator_m: 3.0,
        }
    }
}

/// The obstruction-free-index of the segment from `origin` (where the ball is kicked)
/// to `target`: 1 for a clear path, smaller the closer opponents stand to the line and
/// the farther they are from the origin along it.
pub fn obstruction_free_index(
    params: &PassParams,
    origin: Vec2,
    target: Vec2,
    opponents: &[Vec2],
) -> f64 {
    let d = target - origin;
    let len = d.dot(d).sqrt();
    let mut index = 1.0;
    for &o in opponents {
        let r = o - origin;
        // y: distance along the segment from its origin (clamped to the segment);
        // x: distance from the opponent to the segment.
        let (x, y) = if len > 0.0 {
            let along = (r.dot(d) / len).clamp(0.0, len);
            let foot = origin + d * along / len;
            let off = o - foot;
            ((off.x.powi(2) + off.y.powi(2)).sqrt(), along)
        } else {
            (r.dot(r).sqrt(), 0.0)
        };
        if x < params.min_dist_m && x < y {
            index *= x / params.max_denominator_m.min(y);
        }
    }
    index
}

/// What the active robot does with the ball.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Play {
    /// Shoot at the goal; the value is the shot's obstruction-free-index.
    Shoot { value: f64 },
    /// Pass to a teammate; the value is the product of the two segments' indices.
    Pass { to: u8, value: f64 },
}

/// Choose pass or shot (cmunited-97-perception §3.2.2): the shot is worth the index of
/// ball→goal; a pass to receiver r is worth index(ball→r) · index(r→goal). The maximum
/// wins; ties prefer the shot (no second kick to get wrong).
pub fn choose_play(
    params: &PassParams,
    ball: Vec2,
    goal: Vec2,
    receivers: &[(u8, Vec2)],
    opponents: &[Vec2],
) -> Play {
    let shot = obstruction_free_index(params, ball, goal, opponents);
    let mut play = Play::Shoot { value: shot };
    let mut best = shot;
    for &(id, at) in receivers {
        let value = obstruction_free_index(params, ball, at, opponents)
            * obstruction_free_index(params, at, goal, opponents);
        if value > best {
            best = value;
            play = Play::Pass { to: id, value };
        }
    }
    play
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use comms::arbitration::{decide, ArbitrationParams, Candidate, Posted};

    use super::*;

    fn fresh(robot: u8, h: f64) -> Candidate {
        Candidate {
            robot,
            posted: Posted { h, going: false },
            age: Duration::from_millis(20),
        }
    }

    #[test]
    fn modes_follow_the_decision() {
        let p = ArbitrationParams::default();
        let d = decide(&p, &[fresh(1, 1.0), fresh(2, 2.0), fresh(3, 3.0)]);
        assert_eq!(mode(1, false, &d, Some(3)), Mode::Active);
        assert_eq!(mode(3, false, &d, Some(3)), Mode::Auxiliary);
        assert_eq!(mode(2, false, &d, Some(3)), Mode::Inactive);
        assert_eq!(mode(4, true, &d, Some(3)), Mode::Goaltend);
    }

    #[test]
    fn an_opponent_on_the_line_far_from_the_ball_blocks_more_than_one_near_it() {
        let pp = PassParams::default();
        let (origin, target) = (Vec2::new(0.0, 0.0), Vec2::new(4.0, 0.0));
        let clear = obstruction_free_index(&pp, origin, target, &[]);
        assert_eq!(clear, 1.0);
        let near = obstruction_free_index(&pp, origin, target, &[Vec2::new(0.5, 0.2)]);
        let far = obstruction_free_index(&pp, origin, target, &[Vec2::new(3.0, 0.2)]);
        // near: x=0.2, y=0.5 → 0.2/0.5 = 0.4; far: x=0.2, y=3 → 0.2/3.
        assert!((near - 0.4).abs() < 1e-12, "near index {near}");
        assert!((far - 0.2 / 3.0).abs() < 1e-12, "far index {far}");
        let off = obstruction_free_index(&pp, origin, target, &[Vec2::new(2.0, 1.5)]);
        assert_eq!(off, 1.0, "an opponent beyond min-dist does not count");
    }

    #[test]
    fn a_blocked_shot_becomes_a_pass_to_the_open_teammate() {
        let pp = PassParams::default();
        let (ball, goal) = (Vec2::new(0.0, 0.0), Vec2::new(4.5, 0.0));
        let open_wing = [(3, Vec2::new(2.0, 2.5))];
        // A defender stands on the shooting line; teammate 3 is open on the wing.
        let opponents = [Vec2::new(3.0, 0.1)];
        let play = choose_play(&pp, ball, goal, &open_wing, &opponents);
        assert!(matches!(play, Play::Pass { to: 3, .. }), "{play:?}");
        // With the line clear, the robot shoots.
        let play = choose_play(&pp, ball, goal, &open_wing, &[]);
        assert!(matches!(play, Play::Shoot { .. }), "{play:?}");
    }
}
