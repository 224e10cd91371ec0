//! The opponents' simple play. Our robots' behaviours are the simulated player's
//! ([`player::behaviour`], re-exported here); the opponents see the true ball: they are
//! part of the environment, not a team under test.

use super::ball::Ball;
use super::body::{Body, MotionCommand};
use super::geometry::Vec2;
use super::FieldConfig;
pub use player::behaviour::*;

/// The opponents: one keeps their goal, the one nearest the ball pushes it toward our
/// goal, the rest hold zones that shift with the ball. They see the true ball: they are
/// part of the environment, not a team under test.
pub fn opponent_command(
    cfg: &FieldConfig,
    k: usize,
    me: &Body,
    others: &[Body],
    ball: &Ball,
) -> MotionCommand {
    let top = cfg.opponent_kinematics.top_speed_mps;
    let b = ball.at;
    if k == 0 {
        let post = cfg.goal_width_m / 2.0;
        let at = Vec2::new(cfg.length_m / 2.0 - 0.3, b.y.clamp(-post, post));
        return go_to(&me.pose, at, (b - me.pose.at).angle(), top);
    }
    let my_d = me.pose.at.distance(b);
    let nearest = others
        .iter()
        .enumerate()
        .filter(|&(j, _)| j != 0 && j != k)
        .all(|(j, o)| {
            let d = o.pose.at.distance(b);
            my_d < d || (my_d == d && k < j)
        });
    if nearest {
        approach_and_push(
            cfg.kinematics.radius_m + cfg.ball.radius_m,
            &me.pose,
            b,
            cfg.own_goal(),
            top,
        )
        .motion
    } else {
        let n = others.len().max(2) - 1;
        let y = ((k - 1) as f64 + 0.5) / n as f64 - 0.5;
        let zone = Vec2::new(cfg.length_m * 0.15 + 0.3 * b.x, y * cfg.width_m * 0.7);
        hold(&me.pose, zone, Some(b), top)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::body::Kinematics;
    use crate::field::geometry::Pose;

    #[test]
    fn a_goer_in_front_of_the_ball_goes_around_it_and_pushes_it_toward_the_goal() {
        let cfg = FieldConfig::default();
        let kin = Kinematics::default();
        let mut body = Body {
            pose: Pose {
                at: Vec2::new(1.0, 0.1),
                theta_rad: std::f64::consts::PI,
            },
            velocity: Vec2::default(),
        };
        let mut ball = Ball::default();
        let aim = cfg.opponent_goal();
        for _ in 0..600 {
            let a = approach_and_push(
                kin.radius_m + cfg.ball.radius_m,
                &body.pose,
                ball.at,
                aim,
                kin.top_speed_mps,
            );
            body.step(&kin, &a.motion, 0.01);
            // Contact: the ball is pushed out of the robot's disc.
            let rel = ball.at - body.pose.at;
            let r = kin.radius_m + cfg.ball.radius_m;
            if rel.norm() < r {
                ball.at = body.pose.at + rel.with_norm(r);
            }
        }
        assert!(
            ball.at.x > 0.8,
            "the ball moved toward the opponent goal: {:?}",
            ball.at
        );
        assert!(
            body.pose.at.x < ball.at.x,
            "the robot ended up behind the ball"
        );
    }
}
