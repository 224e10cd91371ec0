//! Sightings: a ball seen in robot coordinates becomes a field-frame position measurement
//! `z = p + Rot(θ) l` whose noise carries the robot's pose uncertainty,
//! `R = Rot R_l Rotᵀ + J P_pose Jᵀ` with `J = ∂z/∂(x, y, θ)`
//! ([`crate::geometry::robot_to_field_pose_jacobian`]). The filter's update is then linear,
//! `H = [I₂ 0]`.

use crate::geometry::{robot_to_field, robot_to_field_pose_jacobian, rotation};
use crate::pose::PoseEstimate;
use nalgebra::{Matrix2, Vector2};

/// A ball sighting in robot coordinates (x right, y forward) with its noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallSighting {
    /// Where the robot saw the ball.
    pub local: Vector2<f64>,
    /// R_l, the sighting's covariance in robot coordinates (m²).
    pub cov: Matrix2<f64>,
}

/// A position measurement of the ball in the field frame, valid at `t_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldObservation {
    /// When the ball was there.
    pub t_s: f64,
    /// z, field coordinates.
    pub position: Vector2<f64>,
    /// R, including the observer's pose uncertainty.
    pub cov: Matrix2<f64>,
}

/// Turns a sighting by a robot at `pose` into a field-frame observation, carrying the pose
/// covariance into R through the Jacobian of the robot→field transform.
pub fn field_observation(
    t_s: f64,
    pose: &PoseEstimate,
    sighting: &BallSighting,
) -> FieldObservation {
    field_observation_shared(t_s, pose, sighting, 1.0)
}

/// [`field_observation`] with the pose term counted `pose_error_sharing` times:
/// `R = Rot R_l Rotᵀ + k J P_pose Jᵀ`.
///
/// A robot's pose error is not white: it is the same for every sighting the robot makes
/// until landmarks correct it. A filter that adds `J P Jᵀ` to each of N such sightings
/// lets their average shrink the pose error N-fold, which it does not do. Counting it
/// k times, with k the number of sightings a robot makes within its pose error's
/// correlation time, makes those k sightings together carry it exactly once
/// (`(R_l + k P)/k = R_l/k + P`). See [`super::BallFilterConfig::pose_error_sharing`].
pub fn field_observation_shared(
    t_s: f64,
    pose: &PoseEstimate,
    sighting: &BallSighting,
    pose_error_sharing: f64,
) -> FieldObservation {
    let rot = rotation(pose.mean.z);
    let j = robot_to_field_pose_jacobian(&pose.mean, &sighting.local);
    let k = pose_error_sharing.max(1.0);
    let cov = rot * sighting.cov * rot.transpose() + j * pose.cov * j.transpose() * k;
    FieldObservation {
        t_s,
        position: robot_to_field(&pose.mean, &sighting.local),
        cov: (cov + cov.transpose()) * 0.5,
    }
}
