//! The ball on a real field ([`FieldBall`]): the field's friction law (drag plus a constant
//! rolling deceleration), the boards it bounces off, and process noise that grows with its
//! speed, so that a ball at rest is not predicted as loosely as one that was just kicked.
//!
//! A bounce is a jump of the state at the instant the ball's centre meets a board: the
//! normal velocity reverses and keeps the fraction `e` of itself. The prediction finds that
//! instant on the mean's own path (the friction law's distance is monotonic in time, so a
//! bisection finds it), rolls to it, reflects, and rolls on. P goes through the jump by its
//! saltation matrix: for a board across x (at x = H), a ball that was δ further along x
//! hit δ/vₓ earlier and is now e·δ short of where the mean is, and its normal velocity
//! error turns over and shrinks by e: `Ξ = diag(−e, 1, −e, 1)` for the drag-only law,
//! plus, since the rolling deceleration pulls along a direction the bounce turns, the
//! velocity rows of x's column get (a⁺ − R a⁻)/vₓ (the general saltation matrix
//! `R + (f⁺ − R f⁻) ∂g / (∂g f⁻)` with the board g = x − H and R the reset's Jacobian).
//! The restitution's own uncertainty σₑ adds (σₑ vₓ)² to vₓ's variance.

use super::motion::{friction_propagate, friction_roll};
use nalgebra::{Matrix4, Vector4};

/// Bounces per prediction step that are followed (a corner is two); a longer step is rolled
/// on without further boards after these.
const MAX_BOUNCES: usize = 4;

/// The boards around the carpet, where the ball's centre meets them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Boards {
    /// The ball's centre meets a board at |x| = this (m): half the field's length plus the
    /// border, less the ball's radius.
    pub half_x_m: f64,
    /// … and at |y| = this (m).
    pub half_y_m: f64,
    /// e: the fraction of the normal speed the ball keeps.
    pub restitution: f64,
    /// σ of e (boards are not uniform, the ball is not perfectly round).
    pub restitution_sigma: f64,
}

impl Boards {
    /// The boards of a field `length_m` × `width_m` between the lines, with `border_m` of
    /// carpet beyond them, for a ball of `ball_radius_m`.
    pub fn around(
        length_m: f64,
        width_m: f64,
        border_m: f64,
        ball_radius_m: f64,
        restitution: f64,
        restitution_sigma: f64,
    ) -> Self {
        Boards {
            half_x_m: length_m / 2.0 + border_m - ball_radius_m,
            half_y_m: width_m / 2.0 + border_m - ball_radius_m,
            restitution,
            restitution_sigma,
        }
    }

    fn half(&self, axis: usize) -> f64 {
        if axis == 0 {
            self.half_x_m
        } else {
            self.half_y_m
        }
    }

    /// An axis on which the mean is at or beyond a board and moving further out.
    fn outward(&self, x: &Vector4<f64>) -> Option<usize> {
        (0..2).find(|&a| x[a].abs() >= self.half(a) && x[a] * x[a + 2] > 0.0)
    }

    /// Along its path, how far the mean rolls before its centre meets a board, and which;
    /// with the mean's speed `|v|` (hypot), which the caller needs too.
    fn distance_to_board(&self, x: &Vector4<f64>) -> Option<(usize, f64, f64)> {
        let s = x.z.hypot(x.w);
        if !(s > 0.0 && s.is_finite()) {
            return None;
        }
        (0..2)
            .filter_map(|a| {
                let u = x[a + 2] / s;
                if u == 0.0 {
                    return None;
                }
                let d = (self.half(a).copysign(u) - x[a]) / u;
                (d >= 0.0).then_some((a, d, s))
            })
            .min_by(|p, q| p.1.total_cmp(&q.1))
    }

    /// The bounce on `axis` applied to a prediction, the restitution's uncertainty added
    /// to the normal velocity. `crossed`: the mean met the board during the step, at the
    /// board now: F and Q go through the saltation matrix. Otherwise the mean was already
    /// beyond it (a sighting's noise put it there, or a ball lies against the board): it
    /// is put on the board and its normal velocity turned, but P is not shrunk, since
    /// nothing says how far beyond the board the ball is not.
    #[allow(non_snake_case)]
    fn reflect(
        &self,
        axis: usize,
        crossed: bool,
        mu: f64,
        mean: &mut Vector4<f64>,
        F: &mut Matrix4<f64>,
        Q: &mut Matrix4<f64>,
    ) {
        let e = self.restitution;
        let wall = self.half(axis).copysign(mean[axis]);
        let v_normal = mean[axis + 2];
        mean[axis] = wall;
        mean[axis + 2] = -e * v_normal;
        let mut xi = Matrix4::identity();
        if crossed {
            xi[(axis, axis)] = -e;
            xi[(axis + 2, axis + 2)] = -e;
            // The rolling deceleration pulls along the direction of motion, which the
            // bounce turns: (a⁺ − R a⁻)/vₙ into the normal-position column (the drag
            // terms cancel).
            let other = 1 - axis;
            let v_t = mean[other + 2];
            let (before, after) = (v_normal.hypot(v_t), (e * v_normal).hypot(v_t));
            if before > 0.0 && after > 0.0 && v_normal != 0.0 {
                let (inv_b, inv_a) = (1.0 / before, 1.0 / after);
                xi[(axis + 2, axis)] = -mu * e * (inv_b - inv_a);
                xi[(other + 2, axis)] = -mu * v_t * (inv_a - inv_b) / v_normal;
            }
        } else {
            xi[(axis + 2, axis + 2)] = -1.0;
        }
        *F = xi * *F;
        *Q = xi * *Q * xi.transpose();
        Q[(axis + 2, axis + 2)] += (self.restitution_sigma * v_normal).powi(2);
    }
}

/// The ball as a robot team would calibrate it on its field: `dv/dt = −c v − μ v/|v| + w`
/// (the [`super::BallModel::Friction`] law) inside [`Boards`], with white acceleration
/// noise w whose spectral density grows with the mean's speed s beyond a still ball's,
/// `q(s) = still_accel_noise + accel_noise_per_speed · max(0, s − still_below)` (the few
/// cm/s of noise in a still ball's velocity estimate do not loosen it). What the noise stands for is what nobody reports: opponents' shoves, a bounce
/// off a robot's body, kicks that did something else than reported. A ball at rest is
/// pushed now and then; one that moves fast was just kicked or bounced and its next
/// surprise is proportionally bigger.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldBall {
    /// c: speed-proportional drag (1/s).
    pub drag_per_s: f64,
    /// μ: constant rolling deceleration (m/s²).
    pub rolling_decel_mps2: f64,
    /// q of a ball at rest, per axis (m²/s³).
    pub still_accel_noise_m2_per_s3: f64,
    /// What q grows by per m/s of speed beyond `still_below_mps` (m²/s³ per m/s).
    pub accel_noise_per_speed: f64,
    /// Below this speed the ball counts as still (m/s).
    pub still_below_mps: f64,
    /// The boards, if the model knows them.
    pub boards: Option<Boards>,
}

impl FieldBall {
    /// q at speed `speed_mps` (m²/s³).
    pub fn accel_noise(&self, speed_mps: f64) -> f64 {
        self.still_accel_noise_m2_per_s3
            + self.accel_noise_per_speed * (speed_mps - self.still_below_mps).max(0.0)
    }

    /// The mean predicted over `dt` with F and Q (see the module docs).
    #[allow(non_snake_case)]
    pub(super) fn propagate(
        &self,
        x: &Vector4<f64>,
        velocity_var_m2ps2: f64,
        dt: f64,
    ) -> (Vector4<f64>, Matrix4<f64>, Matrix4<f64>) {
        let (c, mu) = (self.drag_per_s, self.rolling_decel_mps2);
        let step = |x: &Vector4<f64>, dt: f64| {
            friction_propagate(c, mu, |s| self.accel_noise(s), x, velocity_var_m2ps2, dt)
        };
        let Some(boards) = self.boards else {
            return step(x, dt);
        };
        let (mut mean, mut F, mut Q) = (*x, Matrix4::identity(), Matrix4::zeros());
        let mut bounced = false;
        let mut left = dt;
        for _ in 0..MAX_BOUNCES {
            // A mean already beyond a board and moving out (a sighting's noise put it
            // there): it has bounced.
            if let Some(axis) = boards.outward(&mean) {
                boards.reflect(axis, false, mu, &mut mean, &mut F, &mut Q);
                bounced = true;
                continue;
            }
            let Some((axis, to_board, s)) = boards.distance_to_board(&mean) else {
                break;
            };
            // The speed only falls, so the ball rolls at most s·left; the computed roll
            // keeps that bound too (its ∫e^{−ct} is below τ ≤ left by far more than its
            // rounding, and the rolling term only subtracts), so a board further off is
            // not met, and the roll need not be worked out (most predictions).
            if c >= 0.0 && mu >= 0.0 && s * left <= to_board {
                break;
            }
            let (rolled, _, _, _, t_stop) = friction_roll(c, mu, s, left);
            if rolled <= to_board {
                break;
            }
            // The distance rolled grows monotonically until the ball stops: bisect for
            // the instant it equals the distance to the board.
            let (mut lo, mut hi) = (0.0, left.min(t_stop));
            for _ in 0..48 {
                let mid = 0.5 * (lo + hi);
                if friction_roll(c, mu, s, mid).0 < to_board {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let t_hit = hi;
            let (m, f, q) = step(&mean, t_hit);
            mean = m;
            F = f * F;
            Q = f * Q * f.transpose() + q;
            boards.reflect(axis, true, mu, &mut mean, &mut F, &mut Q);
            bounced = true;
            left -= t_hit;
        }
        let (m, f, q) = step(&mean, left);
        // Without a bounce F is I and Q is 0: with every entry of f and q finite and of
        // positive sign, f·I is f and f·0·fᵀ + q is q to the bit (products by 1 and by +0,
        // sums with +0), so the three 4×4 products are skipped.
        let plain = |m: &Matrix4<f64>| m.iter().all(|v| v.is_finite() && v.is_sign_positive());
        if !bounced && plain(&f) && plain(&q) {
            return (m, f, q);
        }
        (m, f * F, f * Q * f.transpose() + q)
    }
}

#[cfg(test)]
#[path = "propagate_oracle.rs"]
mod propagate_oracle;
