//! Robot kinematics: an omnidirectional base with a top speed, an acceleration limit and
//! a turn-rate limit, and the odometry it reports.

use fusion::wrap_angle;

use super::geometry::{Pose, Vec2};
pub use player::senses::{MotionCommand, Odometry};
use serde::Serialize;

/// Limits of a robot's base.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Kinematics {
    /// Top speed over ground, m/s.
    pub top_speed_mps: f64,
    /// Largest change of velocity per second, m/s².
    pub accel_mps2: f64,
    /// Largest turn rate, rad/s.
    pub turn_rate_rps: f64,
    /// Body radius for contacts, metres.
    pub radius_m: f64,
}

impl Default for Kinematics {
    fn default() -> Self {
        // A small-size wheeled robot: fast enough to cross the field in a few seconds.
        Self {
            top_speed_mps: 1.5,
            accel_mps2: 3.0,
            turn_rate_rps: 4.0,
            radius_m: 0.2,
        }
    }
}

/// A robot's body on the field: its true pose and velocity.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Body {
    /// True pose.
    pub pose: Pose,
    /// True velocity, field frame, m/s.
    pub velocity: Vec2,
}

impl Body {
    /// Advance `dt_s` under `cmd` within `kin`'s limits; returns the true odometry of the step.
    pub fn step(&mut self, kin: &Kinematics, cmd: &MotionCommand, dt_s: f64) -> Odometry {
        let want = cmd.velocity.clamp_norm(kin.top_speed_mps);
        let dv = (want - self.velocity).clamp_norm(kin.accel_mps2 * dt_s);
        self.velocity = self.velocity + dv;
        let turn_max = kin.turn_rate_rps * dt_s;
        let turn = wrap_angle(cmd.heading_rad - self.pose.theta_rad).clamp(-turn_max, turn_max);
        let start = self.pose;
        self.pose.at = self.pose.at + self.velocity * dt_s;
        self.pose.theta_rad = wrap_angle(self.pose.theta_rad + turn);
        let local = start.to_local(self.pose.at);
        Odometry {
            forward_m: local.x,
            left_m: local.y,
            turn_rad: turn,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_robot_never_exceeds_its_top_speed_and_reaches_it_after_the_ramp() {
        let kin = Kinematics::default();
        let mut b = Body::default();
        let cmd = MotionCommand {
            velocity: Vec2::new(10.0, 0.0),
            heading_rad: 0.0,
        };
        for _ in 0..100 {
            b.step(&kin, &cmd, 0.01);
            assert!(b.velocity.norm() <= kin.top_speed_mps + 1e-9);
        }
        // 1.5 m/s at 3 m/s² takes 0.5 s; after 1 s the robot is at top speed.
        assert!((b.velocity.norm() - kin.top_speed_mps).abs() < 1e-9);
        // Distance: 0.375 m ramping plus 0.75 m at speed (within a step's rounding).
        assert!((b.pose.at.x - 1.125).abs() < 0.02, "x = {}", b.pose.at.x);
    }

    #[test]
    fn odometry_composes_like_the_motion_it_measures() {
        let kin = Kinematics::default();
        let mut b = Body::default();
        let start = b.pose;
        let mut odo = Odometry::default();
        for i in 0..50 {
            let cmd = MotionCommand {
                velocity: Vec2::new(0.5, 0.3 * f64::from(i % 3)),
                heading_rad: 1.0,
            };
            odo = odo.then(b.step(&kin, &cmd, 0.02));
        }
        let predicted = start.to_field(Vec2::new(odo.forward_m, odo.left_m));
        assert!(
            predicted.distance(b.pose.at) < 1e-9,
            "{predicted:?} vs {:?}",
            b.pose.at
        );
        assert!((odo.turn_rad - b.pose.theta_rad).abs() < 1e-9);
    }
}
