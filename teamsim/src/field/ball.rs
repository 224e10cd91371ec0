//! The ball: rolls with friction, bounces off the boards around the carpet, and is
//! pushed or kicked by robots.

use super::geometry::Vec2;
use serde::Serialize;

/// How the ball rolls.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BallConfig {
    /// Radius, metres.
    pub radius_m: f64,
    /// Constant rolling deceleration, m/s².
    pub rolling_decel_mps2: f64,
    /// Speed-proportional drag, 1/s.
    pub drag_per_s: f64,
    /// Fraction of the normal speed kept after hitting a board.
    pub restitution: f64,
}

impl Default for BallConfig {
    fn default() -> Self {
        // A kick at 4 m/s rolls about 5 m on carpet.
        Self {
            radius_m: 0.05,
            rolling_decel_mps2: 0.6,
            drag_per_s: 0.5,
            restitution: 0.5,
        }
    }
}

/// The ball's true state.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Ball {
    /// Position, metres.
    pub at: Vec2,
    /// Velocity, m/s.
    pub velocity: Vec2,
}

impl Ball {
    /// Roll for `dt_s`, bouncing inside the rectangle |x| ≤ `half_x_m`, |y| ≤ `half_y_m`.
    pub fn step(&mut self, cfg: &BallConfig, dt_s: f64, half_x_m: f64, half_y_m: f64) {
        let speed = self.velocity.norm();
        let slowed =
            (speed * (1.0 - cfg.drag_per_s * dt_s) - cfg.rolling_decel_mps2 * dt_s).max(0.0);
        self.velocity = self.velocity.with_norm(slowed);
        self.at = self.at + self.velocity * dt_s;
        let (hx, hy) = (half_x_m - cfg.radius_m, half_y_m - cfg.radius_m);
        if self.at.x.abs() > hx {
            self.at.x = hx.copysign(self.at.x);
            self.velocity.x = -self.velocity.x * cfg.restitution;
        }
        if self.at.y.abs() > hy {
            self.at.y = hy.copysign(self.at.y);
            self.velocity.y = -self.velocity.y * cfg.restitution;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_kicked_ball_slows_down_and_stops() {
        let cfg = BallConfig::default();
        let mut b = Ball {
            at: Vec2::default(),
            velocity: Vec2::new(4.0, 0.0),
        };
        for _ in 0..2000 {
            b.step(&cfg, 0.01, 100.0, 100.0);
        }
        assert_eq!(b.velocity.norm(), 0.0, "friction must stop the ball");
        assert!(b.at.x > 3.0 && b.at.x < 8.0, "rolled {} m", b.at.x);
    }

    #[test]
    fn the_ball_bounces_off_the_boards_and_loses_speed() {
        let cfg = BallConfig::default();
        let mut b = Ball {
            at: Vec2::new(0.9, 0.0),
            velocity: Vec2::new(3.0, 0.0),
        };
        b.step(&cfg, 0.1, 1.0, 1.0);
        assert!(b.velocity.x < 0.0 && b.velocity.x.abs() < 3.0 * cfg.restitution + 1e-9);
        assert!(b.at.x <= 1.0 - cfg.radius_m);
    }
}
