//! Plane geometry in the field frame: metres, radians, x toward the opponent goal.
//! Headings are wrapped into (-π, π] by `fusion::wrap_angle`, the one wrap the sim and
//! the filters share.

use serde::Serialize;
use std::ops::{Add, Div, Mul, Sub};

/// A point or a vector on the field, metres.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Vec2 {
    /// Metres along the field, toward the opponent goal.
    pub x: f64,
    /// Metres across the field, to the left when facing the opponent goal.
    pub y: f64,
}

impl Vec2 {
    /// The vector (x, y).
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    /// The unit vector at `angle_rad`.
    pub fn from_angle(angle_rad: f64) -> Self {
        Self::new(angle_rad.cos(), angle_rad.sin())
    }

    /// Euclidean length.
    pub fn norm(self) -> f64 {
        self.x.hypot(self.y)
    }

    /// Distance to `other`.
    pub fn distance(self, other: Vec2) -> f64 {
        (self - other).norm()
    }

    /// Direction of the vector, radians in (-π, π].
    pub fn angle(self) -> f64 {
        self.y.atan2(self.x)
    }

    /// Dot product.
    pub fn dot(self, other: Vec2) -> f64 {
        self.x * other.x + self.y * other.y
    }

    /// The vector scaled to length `len` (zero stays zero).
    pub fn with_norm(self, len: f64) -> Self {
        let n = self.norm();
        if n > 1e-12 {
            self * (len / n)
        } else {
            Vec2::default()
        }
    }

    /// The vector with its length capped at `max`.
    pub fn clamp_norm(self, max: f64) -> Self {
        if self.norm() > max {
            self.with_norm(max)
        } else {
            self
        }
    }

    /// Rotated by `angle_rad`.
    pub fn rotate(self, angle_rad: f64) -> Self {
        let (s, c) = angle_rad.sin_cos();
        Self::new(c * self.x - s * self.y, s * self.x + c * self.y)
    }
}

impl Add for Vec2 {
    type Output = Vec2;
    fn add(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x + o.x, self.y + o.y)
    }
}

impl Sub for Vec2 {
    type Output = Vec2;
    fn sub(self, o: Vec2) -> Vec2 {
        Vec2::new(self.x - o.x, self.y - o.y)
    }
}

impl Mul<f64> for Vec2 {
    type Output = Vec2;
    fn mul(self, k: f64) -> Vec2 {
        Vec2::new(self.x * k, self.y * k)
    }
}

impl Div<f64> for Vec2 {
    type Output = Vec2;
    fn div(self, k: f64) -> Vec2 {
        Vec2::new(self.x / k, self.y / k)
    }
}

/// A robot's pose: position (metres) and heading (radians, 0 = toward the opponent goal).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Pose {
    /// Position, metres.
    pub at: Vec2,
    /// Heading, radians in (-π, π].
    pub theta_rad: f64,
}

impl Pose {
    /// A point given in this pose's frame (x forward, y left), in the field frame.
    pub fn to_field(&self, local: Vec2) -> Vec2 {
        self.at + local.rotate(self.theta_rad)
    }

    /// A field point in this pose's frame.
    pub fn to_local(&self, field: Vec2) -> Vec2 {
        (field - self.at).rotate(-self.theta_rad)
    }
}

/// Where an SPL field's fixed landmarks are, for a field of `length_m` × `width_m` with
/// goals `goal_width_m` wide (centre at the origin, x along the length): the four goal
/// posts, the four corners and the two ends of the halfway line. The simulated world
/// calls it with the field's true size, a robot's brain with the size it was told.
pub fn field_landmarks(length_m: f64, width_m: f64, goal_width_m: f64) -> [Vec2; 10] {
    let (hx, hy, gy) = (length_m / 2.0, width_m / 2.0, goal_width_m / 2.0);
    [
        Vec2::new(hx, gy),
        Vec2::new(hx, -gy),
        Vec2::new(-hx, gy),
        Vec2::new(-hx, -gy),
        Vec2::new(hx, hy),
        Vec2::new(hx, -hy),
        Vec2::new(-hx, hy),
        Vec2::new(-hx, -hy),
        Vec2::new(0.0, hy),
        Vec2::new(0.0, -hy),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn local_and_field_frames_invert_each_other() {
        let pose = Pose {
            at: Vec2::new(1.0, -2.0),
            theta_rad: 0.7,
        };
        let p = Vec2::new(-0.3, 4.1);
        let back = pose.to_field(pose.to_local(p));
        assert!(back.distance(p) < 1e-12, "{back:?} != {p:?}");
        // A point straight ahead of a robot facing +y is at local (d, 0).
        let up = Pose {
            at: Vec2::default(),
            theta_rad: std::f64::consts::FRAC_PI_2,
        };
        let l = up.to_local(Vec2::new(0.0, 2.0));
        assert!((l.x - 2.0).abs() < 1e-12 && l.y.abs() < 1e-12, "{l:?}");
    }

    #[test]
    fn headings_wrap_into_the_half_open_interval() {
        use fusion::wrap_angle;
        use std::f64::consts::PI;
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI / 2.0 - 2.0 * PI) + PI / 2.0).abs() < 1e-12);
    }
}
