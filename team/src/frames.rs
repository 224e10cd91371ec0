//! The two frame conventions, and the noise of a robot's own readings.
//!
//! huddle's robots, the relay contract and the simulator use ROS REP-103: the robot frame
//! has +x forward and +y left, and a heading θ is measured from field +x. `fusion` (the
//! seed's Fig. 6) has +y forward and +x right, with θ = 0 facing field +y. So
//! θ_fusion = θ − π/2 and a point (f, l) seen by the robot is (−l, f) to `fusion`.
//! Odometry means the same in both (forward, left, turn); the field frames are the same.

use std::f64::consts::FRAC_PI_2;

use fusion::nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use fusion::{wrap_angle, BallSighting, PoseEstimate};

use crate::calibration::SensorCalibration;
use crate::geometry::{Pose, Vec2};

/// A pose (REP-103) as a `fusion` pose estimate with covariance `cov` (x, y, θ; the
/// heading's variance is the same in both conventions).
pub fn to_fusion_pose(pose: &Pose, cov: Matrix3<f64>) -> PoseEstimate {
    PoseEstimate {
        mean: Vector3::new(pose.at.x, pose.at.y, wrap_angle(pose.theta_rad - FRAC_PI_2)),
        cov,
    }
}

/// A `fusion` pose estimate's mean in REP-103.
pub fn from_fusion_pose(est: &PoseEstimate) -> Pose {
    Pose {
        at: Vec2::new(est.mean.x, est.mean.y),
        theta_rad: wrap_angle(est.mean.z + FRAC_PI_2),
    }
}

/// A field point as `fusion` takes it (both field frames are the same).
pub fn to_fusion_point(p: Vec2) -> Vector2<f64> {
    Vector2::new(p.x, p.y)
}

/// A `fusion` field point as a [`Vec2`].
pub fn from_fusion_point(v: &Vector2<f64>) -> Vec2 {
    Vec2::new(v.x, v.y)
}

/// A point in the robot frame (REP-103: x forward, y left) with its covariance, as a
/// `fusion` ball sighting (x right, y forward).
pub fn ball_sighting_from_rep103(local: Vector2<f64>, cov: Matrix2<f64>) -> BallSighting {
    // (f, l) → (−l, f): J = [[0, −1], [1, 0]].
    let j = Matrix2::new(0.0, -1.0, 1.0, 0.0);
    let c = j * cov * j.transpose();
    BallSighting {
        local: Vector2::new(-local.y, local.x),
        cov: (c + c.transpose()) * 0.5,
    }
}

/// Q of one odometry reading, `diag(q_right, q_forward, q_θ)`: odometry's error has
/// σ = k·d (translation, d the distance travelled) and k·(|Δθ| + 0.2·d) (turn),
/// k = the calibrated `odometry_noise_frac`. The measured motion stands in for the true
/// one. `pushed_m` adds a floor for what odometry never sees (robots shoving each other).
pub fn odometry_q(
    odo: &fusion::Odometry,
    sensors: &SensorCalibration,
    pushed_m: f64,
) -> Matrix3<f64> {
    let noise_frac = sensors.odometry_noise_frac;
    let d = odo.forward_m.hypot(odo.left_m);
    let s_xy = noise_frac * d;
    let s_th = noise_frac * (odo.turn_rad.abs() + 0.2 * d);
    let floor = pushed_m * pushed_m;
    Matrix3::from_diagonal(&Vector3::new(
        s_xy * s_xy + floor,
        s_xy * s_xy + floor,
        s_th * s_th + 1e-8,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_ahead_and_left_is_at_the_same_field_place_in_both_conventions() {
        let pose = Pose {
            at: Vec2::new(1.0, -2.0),
            theta_rad: 0.7,
        };
        let local = Vector2::new(2.0, 0.5);
        let rep = pose.to_field(Vec2::new(local.x, local.y));
        let est = to_fusion_pose(&pose, Matrix3::identity());
        let s = ball_sighting_from_rep103(local, Matrix2::identity() * 0.01);
        let f = fusion::robot_to_field(&est.mean, &s.local);
        assert!(
            (f.x - rep.x).abs() < 1e-12 && (f.y - rep.y).abs() < 1e-12,
            "REP-103 {rep:?} against fusion {f:?}"
        );
        let back = from_fusion_pose(&est);
        assert!(back.at.distance(pose.at) < 1e-12 && (back.theta_rad - 0.7).abs() < 1e-12);
    }

    #[test]
    fn a_sighting_uncertain_along_the_line_of_sight_stays_so_after_the_turn() {
        // σ 0.3 m forward, 0.1 m sideways in REP-103: fusion's forward is +y.
        let s =
            ball_sighting_from_rep103(Vector2::new(2.0, 0.0), Matrix2::new(0.09, 0.0, 0.0, 0.01));
        assert!((s.cov[(1, 1)] - 0.09).abs() < 1e-12 && (s.cov[(0, 0)] - 0.01).abs() < 1e-12);
    }
}
