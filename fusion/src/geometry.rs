//! Field and robot frames (tsinghua-2005 eqs. (2), (3)).
//!
//! The field frame is fixed to the pitch. The robot frame has its origin under the robot,
//! +y forward (the heading) and +x to the right, so it is right-handed with z up and a
//! pose angle θ = 0 means "facing field +y"; θ grows counter-clockwise (a left turn).
//! A point `l` in robot coordinates is `p + Rot(θ) l` in field coordinates (eq. (2)), and a
//! field point `g` is `Rot(θ)ᵀ (g − p)` in robot coordinates (eq. (3), eq. (8)).

use nalgebra::{Matrix2, Matrix2x3, Vector2, Vector3};
use std::f64::consts::PI;

/// Wraps an angle to (−π, π].
pub fn wrap_angle(angle_rad: f64) -> f64 {
    let r = angle_rad.rem_euclid(2.0 * PI);
    if r > PI {
        r - 2.0 * PI
    } else {
        r
    }
}

/// The rotation `Rot(θ)` taking robot-frame vectors to field-frame vectors (eq. (2)).
pub fn rotation(theta_rad: f64) -> Matrix2<f64> {
    let (s, c) = theta_rad.sin_cos();
    Matrix2::new(c, -s, s, c)
}

/// Robot-frame point `local` seen from `pose = (x, y, θ)`, in field coordinates (eq. (2)).
pub fn robot_to_field(pose: &Vector3<f64>, local: &Vector2<f64>) -> Vector2<f64> {
    Vector2::new(pose.x, pose.y) + rotation(pose.z) * local
}

/// Field point `field` in the robot frame of `pose` (eq. (3), eq. (8)):
/// `l_x = (b_x − x) cos θ + (b_y − y) sin θ`, `l_y = −(b_x − x) sin θ + (b_y − y) cos θ`.
pub fn field_to_robot(pose: &Vector3<f64>, field: &Vector2<f64>) -> Vector2<f64> {
    rotation(pose.z).transpose() * (field - Vector2::new(pose.x, pose.y))
}

/// Jacobian of [`robot_to_field`] with respect to the pose `(x, y, θ)`: `[I | Rot'(θ) l]`.
/// It is how a robot's pose uncertainty is carried into what it reports in field coordinates.
pub fn robot_to_field_pose_jacobian(pose: &Vector3<f64>, local: &Vector2<f64>) -> Matrix2x3<f64> {
    let (s, c) = pose.z.sin_cos();
    Matrix2x3::new(
        1.0,
        0.0,
        -s * local.x - c * local.y,
        0.0,
        1.0,
        c * local.x - s * local.y,
    )
}

/// Jacobian of [`field_to_robot`] with respect to the pose `(x, y, θ)`: the landmark
/// measurement matrix H of the pose EKF (the seed never writes it out; this is ∂(8)/∂(x, y, θ)).
pub fn field_to_robot_pose_jacobian(pose: &Vector3<f64>, field: &Vector2<f64>) -> Matrix2x3<f64> {
    let (s, c) = pose.z.sin_cos();
    let dx = field.x - pose.x;
    let dy = field.y - pose.y;
    Matrix2x3::new(-c, -s, -dx * s + dy * c, s, -c, -dx * c - dy * s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_is_half_open_at_minus_pi() {
        assert_eq!(wrap_angle(PI), PI);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-15, "−π maps to +π");
        assert!((wrap_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!((wrap_angle(-7.0) - (-7.0 + 2.0 * PI)).abs() < 1e-12);
    }

    #[test]
    fn frames_round_trip_and_match_the_seed() {
        // Facing field +x (θ = −π/2): a ball 1 m ahead is at field (x + 1, y).
        let pose = Vector3::new(1.0, 2.0, -PI / 2.0);
        let ahead = robot_to_field(&pose, &Vector2::new(0.0, 1.0));
        assert!((ahead - Vector2::new(2.0, 2.0)).norm() < 1e-12, "{ahead}");
        let back = field_to_robot(&pose, &ahead);
        assert!((back - Vector2::new(0.0, 1.0)).norm() < 1e-12);
    }

    #[test]
    fn jacobians_match_finite_differences() {
        let pose = Vector3::new(0.3, -1.2, 0.7);
        let l = Vector2::new(0.4, 1.5);
        let g = Vector2::new(2.0, 1.0);
        let h = 1e-6;
        let ja = robot_to_field_pose_jacobian(&pose, &l);
        let jb = field_to_robot_pose_jacobian(&pose, &g);
        for k in 0..3 {
            let mut dp = pose;
            dp[k] += h;
            let na = (robot_to_field(&dp, &l) - robot_to_field(&pose, &l)) / h;
            let nb = (field_to_robot(&dp, &g) - field_to_robot(&pose, &g)) / h;
            assert!((na - ja.column(k)).norm() < 1e-5, "robot→field column {k}");
            assert!((nb - jb.column(k)).norm() < 1e-5, "field→robot column {k}");
        }
    }
}
