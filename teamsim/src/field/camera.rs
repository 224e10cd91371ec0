//! A robot's camera: a limited field of view and range, detections that sometimes fail,
//! and noisy range and bearing in the robot's own frame.

use fusion::wrap_angle;

use super::geometry::{Pose, Vec2};
pub use player::senses::{Frame, Sighting};
use rand::RngExt;
use serde::Serialize;

/// What the camera can see and how well.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CameraConfig {
    /// Full horizontal field of view, radians.
    pub fov_rad: f64,
    /// Farthest the ball is detected, metres.
    pub ball_range_m: f64,
    /// Farthest goals, landmarks and robots are detected, metres (they are bigger).
    pub landmark_range_m: f64,
    /// Probability that an object in view is detected in one frame.
    pub detect_prob: f64,
    /// Range noise: standard deviation, metres, plus …
    pub range_noise_m: f64,
    /// … this fraction of the range (far objects are measured worse).
    pub range_noise_frac: f64,
    /// Bearing noise, standard deviation, radians.
    pub bearing_noise_rad: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            fov_rad: 70f64.to_radians(),
            ball_range_m: 5.0,
            landmark_range_m: 9.0,
            detect_prob: 0.95,
            range_noise_m: 0.02,
            range_noise_frac: 0.05,
            bearing_noise_rad: 0.02,
        }
    }
}

/// Whether `target` is within the view cone of `pose` up to `range_m`.
pub fn in_view(cfg: &CameraConfig, pose: &Pose, target: Vec2, range_m: f64) -> bool {
    let rel = target - pose.at;
    let d = rel.norm();
    d <= range_m && wrap_angle(rel.angle() - pose.theta_rad).abs() <= cfg.fov_rad / 2.0
}

/// A standard normal sample (Box–Muller; one value per call keeps the stream simple).
pub fn standard_normal(rng: &mut impl RngExt) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>(); // (0, 1]: ln is finite
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// A noisy sighting of `target` from `pose`, or `None` if out of view or missed.
pub fn sight(
    cfg: &CameraConfig,
    pose: &Pose,
    target: Vec2,
    range_m: f64,
    rng: &mut impl RngExt,
) -> Option<Sighting> {
    if !in_view(cfg, pose, target, range_m) || rng.random::<f64>() >= cfg.detect_prob {
        return None;
    }
    let local = pose.to_local(target);
    let d = local.norm();
    let sd = cfg.range_noise_m + cfg.range_noise_frac * d;
    Some(Sighting {
        range_m: (d + sd * standard_normal(rng)).max(0.0),
        bearing_rad: wrap_angle(local.angle() + cfg.bearing_noise_rad * standard_normal(rng)),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn the_camera_sees_ahead_within_range_and_not_behind() {
        let cfg = CameraConfig {
            detect_prob: 1.0,
            ..Default::default()
        };
        let pose = Pose::default();
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        assert!(sight(&cfg, &pose, Vec2::new(2.0, 0.3), 5.0, &mut rng).is_some());
        assert!(
            sight(&cfg, &pose, Vec2::new(-2.0, 0.0), 5.0, &mut rng).is_none(),
            "behind"
        );
        assert!(
            sight(&cfg, &pose, Vec2::new(6.0, 0.0), 5.0, &mut rng).is_none(),
            "too far"
        );
        assert!(
            sight(&cfg, &pose, Vec2::new(1.0, 1.5), 5.0, &mut rng).is_none(),
            "56° off axis"
        );
    }

    #[test]
    fn range_noise_grows_with_distance_as_configured() {
        let cfg = CameraConfig {
            detect_prob: 1.0,
            ..Default::default()
        };
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let n = 20_000;
        let errs: Vec<f64> = (0..n)
            .map(|_| {
                sight(&cfg, &Pose::default(), Vec2::new(4.0, 0.0), 5.0, &mut rng)
                    .unwrap()
                    .range_m
                    - 4.0
            })
            .collect();
        let mean = errs.iter().sum::<f64>() / n as f64;
        let sd = (errs.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
        // Configured: 0.02 + 0.05 · 4 = 0.22 m.
        assert!(mean.abs() < 0.01, "unbiased, got mean {mean}");
        assert!((sd - 0.22).abs() < 0.01, "sd {sd} should be 0.22 m");
    }
}
