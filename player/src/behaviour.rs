//! What robots do with what they believe: formation positions (CMUnited-97 §3.2.1), the
//! goer's approach and push toward the goal, the goalkeeper. Pure functions from a belief
//! and the field's lines (as the rules give them: [`FieldGeometry`]) to a
//! [`MotionCommand`]; no decisions about *who* goes (that is the team layer's).

use team::calibration::FieldGeometry;
use team::{Pose, Vec2};

use crate::senses::MotionCommand;

/// Gain of the position controller, 1/s: the speed asked for per metre to go.
const POSITION_GAIN: f64 = 3.0;

/// A robot's place in the team.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Position {
    /// Keeps the goal; never competes for the ball.
    Goalkeeper,
    /// A field position: index into [`formation_homes`].
    Field(usize),
}

/// The formation's home spots for `field_players` players, field frame, metres, for a
/// ball at the centre spot: CMUnited-97's goalkeeper + defender + midfielder + two
/// attackers for five robots, and more positions as the team grows.
pub fn formation_homes(cfg: &FieldGeometry, field_players: usize) -> Vec<Vec2> {
    let (hx, hy) = (cfg.length_m / 2.0, cfg.width_m / 2.0);
    // Normalised spots in order of filling: defender, midfielder, two attackers, …
    const SPOTS: [Vec2; 10] = [
        Vec2::new(-0.55, 0.0),
        Vec2::new(-0.1, 0.0),
        Vec2::new(0.4, 0.5),
        Vec2::new(0.4, -0.5),
        Vec2::new(-0.5, 0.6),
        Vec2::new(-0.5, -0.6),
        Vec2::new(0.1, 0.7),
        Vec2::new(0.1, -0.7),
        Vec2::new(0.7, 0.0),
        Vec2::new(-0.25, 0.35),
    ];
    (0..field_players)
        .map(|k| {
            let spot = SPOTS[k % SPOTS.len()];
            // Wrap-around spots (more than ten field players) are nudged apart.
            let lap = (k / SPOTS.len()) as f64 * 0.1;
            Vec2::new((spot.x + lap) * hx, (spot.y - lap) * hy)
        })
        .collect()
}

/// A home spot moved with the ball: positions are regions, not points (CMUnited-97
/// §3.2.1), so the team shifts toward where the ball is, within the field.
pub fn flexible_home(cfg: &FieldGeometry, home: Vec2, ball: Option<Vec2>) -> Vec2 {
    let b = ball.unwrap_or_default();
    let (hx, hy) = (cfg.length_m / 2.0 - 0.3, cfg.width_m / 2.0 - 0.3);
    Vec2::new(
        (home.x + 0.35 * b.x).clamp(-hx, hx),
        (home.y + 0.25 * b.y).clamp(-hy, hy),
    )
}

/// The forward positions a field position considers passing to (CMUnited-97 §3.2.2):
/// those whose home spot is farther up the field.
pub fn receivers_of(homes: &[Vec2], k: usize) -> Vec<usize> {
    (0..homes.len())
        .filter(|&j| j != k && homes[j].x > homes[k].x + 0.5)
        .collect()
}

/// Drive toward `target` (slowing down when close), turning to `heading_rad`.
pub fn go_to(pose: &Pose, target: Vec2, heading_rad: f64, top_speed_mps: f64) -> MotionCommand {
    MotionCommand {
        velocity: ((target - pose.at) * POSITION_GAIN).clamp_norm(top_speed_mps),
        heading_rad,
    }
}

/// What the goer does next.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GoerAction {
    /// The motion.
    pub motion: MotionCommand,
    /// Whether the robot is behind the ball, lined up with `aim`: it may kick now.
    pub lined_up: bool,
}

/// The goer's skill: get behind the ball on the line from `aim` through the ball (going
/// around it if the robot is on the wrong side), keep facing the ball so the camera keeps
/// it, and once lined up push through it toward `aim`. `contact_m`: body radius + ball
/// radius, where the body touches the ball.
pub fn approach_and_push(
    contact_m: f64,
    pose: &Pose,
    ball: Vec2,
    aim: Vec2,
    top_speed_mps: f64,
) -> GoerAction {
    let dir = (aim - ball).with_norm(1.0);
    let contact = contact_m;
    let rel = ball - pose.at;
    let along = rel.dot(dir); // > 0: the robot is behind the ball
    let across = rel.x * dir.y - rel.y * dir.x;
    let lined_up = along > 0.0 && along < contact + 0.25 && across.abs() < 0.08;
    let heading = rel.angle();
    if lined_up || (along > 0.0 && along < contact + 0.35 && across.abs() < 0.12) {
        // Push: aim a little beyond the ball so the robot drives through it.
        let target = ball + dir * 0.5;
        return GoerAction {
            motion: MotionCommand {
                velocity: (target - pose.at).with_norm(top_speed_mps * 0.7),
                heading_rad: dir.angle(),
            },
            lined_up,
        };
    }
    let behind = ball - dir * (contact + 0.15);
    let target = if along < contact + 0.05 {
        // On the wrong side or beside the ball: swing wide around it.
        let side = if across >= 0.0 { -1.0 } else { 1.0 };
        let perp = Vec2::new(-dir.y, dir.x) * side;
        ball - dir * (contact + 0.3) + perp * (contact + 0.3)
    } else {
        behind
    };
    GoerAction {
        motion: go_to(pose, target, heading, top_speed_mps),
        lined_up: false,
    }
}

/// The goalkeeper (CMUnited-97 §3.2.3, without prediction): on its goal line, even with
/// the ball's lateral coordinate, never beyond the posts, facing the ball.
pub fn keep_goal(
    cfg: &FieldGeometry,
    pose: &Pose,
    ball: Option<Vec2>,
    top_speed_mps: f64,
) -> MotionCommand {
    let line_x = -cfg.length_m / 2.0 + 0.3;
    let post = cfg.goal_width_m / 2.0;
    let y = ball.map_or(0.0, |b| b.y.clamp(-post, post));
    let heading = ball.map_or(0.0, |b| (b - pose.at).angle());
    go_to(pose, Vec2::new(line_x, y), heading, top_speed_mps)
}

/// Hold a spot facing the ball; with no idea where the ball is, turn to look for it.
pub fn hold(pose: &Pose, spot: Vec2, ball: Option<Vec2>, top_speed_mps: f64) -> MotionCommand {
    let heading = match ball {
        Some(b) => (b - pose.at).angle(),
        None => pose.theta_rad + 0.6,
    };
    go_to(pose, spot, heading, top_speed_mps)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn five_robots_make_cmunited_s_formation_and_passes_go_forward() {
        let cfg = team::Calibration::default().field;
        let homes = formation_homes(&cfg, 4);
        assert!(
            homes[0].x < homes[1].x && homes[1].x < homes[2].x,
            "defender, midfielder, attackers"
        );
        assert_eq!(
            receivers_of(&homes, 0),
            vec![1, 2, 3],
            "the defender passes to anyone ahead"
        );
        assert!(
            receivers_of(&homes, 2).is_empty(),
            "attackers do not pass back"
        );
    }
}
