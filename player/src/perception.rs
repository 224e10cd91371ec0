//! What a simulated robot's senses mean to its team layer: camera sightings as `fusion`
//! measurements, with the noise the robot's own calibration ([`SensorCalibration`]) says
//! they carry. The frame conventions are the team layer's ([`team::frames`]).
//!
//! Frames. The field simulator's robot frame has +x forward and +y left, and a heading
//! θ_sim measured from field +x; `fusion` (the seed's Fig. 6) has +y forward and +x right,
//! with θ = 0 facing field +y. So θ_fusion = θ_sim − π/2 and a point (f, l) seen by the
//! camera is (−l, f) to `fusion`. Odometry means the same in both (forward, left, turn).

use fusion::nalgebra::{Matrix2, Vector2};
use fusion::{BallSighting, RangeBearingSighting};

use crate::senses::{Odometry, Sighting};
use team::calibration::SensorCalibration;
use team::Vec2;

pub use team::frames::{from_fusion_point, from_fusion_pose, to_fusion_point, to_fusion_pose};

/// Odometry as `fusion` takes it.
pub fn to_fusion_odometry(odo: &Odometry) -> fusion::Odometry {
    fusion::Odometry {
        forward_m: odo.forward_m,
        left_m: odo.left_m,
        turn_rad: odo.turn_rad,
    }
}

/// σ of a range measured at `range_m`.
pub fn range_sigma(cam: &SensorCalibration, range_m: f64) -> f64 {
    cam.range_noise_m + cam.range_noise_frac * range_m
}

/// A landmark at `field` seen as range and bearing, and R of that sighting.
pub fn landmark_sighting(
    cam: &SensorCalibration,
    field: Vec2,
    s: &Sighting,
) -> (RangeBearingSighting, Matrix2<f64>) {
    let sr = range_sigma(cam, s.range_m);
    (
        RangeBearingSighting {
            field: to_fusion_point(field),
            range_m: s.range_m,
            bearing_rad: s.bearing_rad,
        },
        Matrix2::new(sr * sr, 0.0, 0.0, cam.bearing_noise_rad.powi(2)),
    )
}

/// A ball sighting as the contract takes it: a robot-frame point (REP-103: x forward,
/// y left) and its covariance, the range and bearing noise carried through the Jacobian
/// of the polar → Cartesian map. The bearing's lever arm is at least the range's σ: a
/// ball at the robot's feet (a range within its noise of 0, which a camera may report as
/// 0) is uncertain across the line of sight too, where the bare Jacobian (`r·σ_b` → 0)
/// gave a singular covariance the contract refuses (`docs/results/sim-daemons.md`,
/// "The refused ball"). Beyond `σ_r` (0.021 m by default) nothing changes.
pub fn ball_rep103(cam: &SensorCalibration, s: &Sighting) -> (Vector2<f64>, Matrix2<f64>) {
    let (r, b) = (s.range_m, s.bearing_rad);
    let (sin, cos) = b.sin_cos();
    let sr = range_sigma(cam, r);
    // ∂(r cos b, r sin b)/∂(r, b), the bearing's column at an arm of at least σ_r.
    let arm = r.max(sr);
    let j = Matrix2::new(cos, -arm * sin, sin, arm * cos);
    let d = Matrix2::new(sr * sr, 0.0, 0.0, cam.bearing_noise_rad.powi(2));
    let cov = j * d * j.transpose();
    (
        Vector2::new(r * cos, r * sin),
        (cov + cov.transpose()) * 0.5,
    )
}

/// A ball sighting in `fusion`'s robot coordinates: [`ball_rep103`] turned into fusion's
/// frame, as the team layer turns a robot program's sighting.
pub fn ball_sighting(cam: &SensorCalibration, s: &Sighting) -> BallSighting {
    let (local, cov) = ball_rep103(cam, s);
    team::frames::ball_sighting_from_rep103(local, cov)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fusion::nalgebra::Matrix3;
    use team::Pose;

    #[test]
    fn both_conventions_put_a_seen_ball_at_the_same_field_point() {
        let pose = Pose {
            at: Vec2::new(1.0, -2.0),
            theta_rad: 0.7,
        };
        let s = Sighting {
            range_m: 2.5,
            bearing_rad: -0.3,
        };
        let sim = pose.to_field(s.local());
        let est = to_fusion_pose(&pose, Matrix3::identity());
        let f = fusion::robot_to_field(
            &est.mean,
            &ball_sighting(&team::Calibration::default().sensors, &s).local,
        );
        assert!((f.x - sim.x).abs() < 1e-12 && (f.y - sim.y).abs() < 1e-12);
        let back = from_fusion_pose(&est);
        assert!(back.at.distance(pose.at) < 1e-12 && (back.theta_rad - 0.7).abs() < 1e-12);
    }

    #[test]
    fn odometry_moves_the_pose_the_same_way_in_both_conventions() {
        let pose = Pose {
            at: Vec2::new(0.5, 0.5),
            theta_rad: 2.0,
        };
        let odo = Odometry {
            forward_m: 0.3,
            left_m: -0.1,
            turn_rad: 0.2,
        };
        let sim = pose.to_field(Vec2::new(odo.forward_m, odo.left_m));
        let est = fusion::pose_predict(
            &to_fusion_pose(&pose, Matrix3::zeros()),
            &to_fusion_odometry(&odo),
            &Matrix3::zeros(),
        );
        assert!((est.mean.x - sim.x).abs() < 1e-12 && (est.mean.y - sim.y).abs() < 1e-12);
        assert!((from_fusion_pose(&est).theta_rad - 2.2).abs() < 1e-12);
    }

    #[test]
    fn a_ball_straight_ahead_is_uncertain_along_the_line_of_sight_by_the_range_noise() {
        let cam = team::Calibration::default().sensors;
        let b = ball_sighting(
            &cam,
            &Sighting {
                range_m: 2.0,
                bearing_rad: 0.0,
            },
        );
        // Forward is fusion's +y: σ_y = 0.02 + 0.05·2 = 0.12 m; σ_x = 2 m · 0.02 rad.
        assert!((b.cov[(1, 1)] - 0.12f64.powi(2)).abs() < 1e-12);
        assert!((b.cov[(0, 0)] - 0.04f64.powi(2)).abs() < 1e-12);
    }
}
