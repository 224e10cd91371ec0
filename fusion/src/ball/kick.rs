//! A kick as the kicker commanded it, and what it does to a ball estimate.

use super::{BallEstimate, BallModel};
use nalgebra::{Matrix2, Matrix4, Vector2};

/// A kick as the kicker commanded it: at `t_s` the ball leaves at `speed_mps` towards
/// `direction_rad` (field frame, counter-clockwise from +x), each with the kicker's own
/// σ. A robot knows its kicks before anyone sees them; published with its LWM, a kick
/// turns every teammate's team ball the moment it arrives instead of several sightings
/// later.
///
/// A kicker does not know that its foot met the ball: it knows where it believed the ball
/// was. So a kick is an *attempt* with the kicker's own probability of contact
/// (`contact_prob`, from its ball and pose estimates); a miss is reported too, with the
/// probability the kicker gave it, and a filter takes the kick as the two-way mixture
/// "kicked with probability p, untouched otherwise" (see [`BallEstimate::kicked`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kick {
    /// When the foot met the ball (s, on the owner's clock).
    pub t_s: f64,
    /// Speed right after the kick (m/s).
    pub speed_mps: f64,
    /// Direction of the kick in the field frame (rad).
    pub direction_rad: f64,
    /// σ of the speed (m/s).
    pub speed_sigma_mps: f64,
    /// σ of the direction (rad).
    pub direction_sigma_rad: f64,
    /// The kicker's probability that the foot met the ball, in (0, 1].
    pub contact_prob: f64,
}

impl Kick {
    /// The ball's velocity right after the kick and its covariance: the polar σ's through
    /// the Jacobian of (s, φ) ↦ s (cos φ, sin φ), the across-track σ at least the speed σ
    /// (a slow kick's direction says little, and a zero-speed one would leave the
    /// covariance singular).
    pub fn velocity(&self) -> (Vector2<f64>, Matrix2<f64>) {
        let (sin, cos) = self.direction_rad.sin_cos();
        let s = self.speed_mps;
        let along = self.speed_sigma_mps;
        let across = (s * self.direction_sigma_rad).max(along);
        let rot = Matrix2::new(cos, -sin, sin, cos);
        let polar = Matrix2::new(along * along, 0.0, 0.0, across * across);
        (
            Vector2::new(s * cos, s * sin),
            rot * polar * rot.transpose(),
        )
    }

    /// Whether every number is finite, the speed non-negative and the σ's positive.
    pub fn is_valid(&self) -> bool {
        [
            self.t_s,
            self.speed_mps,
            self.direction_rad,
            self.speed_sigma_mps,
            self.direction_sigma_rad,
        ]
        .iter()
        .all(|v| v.is_finite())
            && self.speed_mps >= 0.0
            && self.speed_sigma_mps > 0.0
            && self.direction_sigma_rad > 0.0
            && self.contact_prob > 0.0
            && self.contact_prob <= 1.0
    }
}

impl BallEstimate {
    /// This track kicked: predicted to the kick (or left at its own time if the kick is
    /// older), the velocity replaced by the kick's, the position kept with its variance.
    /// The position–velocity correlation goes: the new velocity is the foot's, not
    /// something learnt from where the ball was. A static model has no velocity to set.
    ///
    /// With a contact probability p < 1 the result is the moment-matched mixture of the
    /// kicked track (weight p) and the untouched one (1 − p): velocity mean
    /// p·v_k + (1 − p)·v, covariance p·P_k + (1 − p)·P + p(1 − p)·ΔΔᵀ over the velocity
    /// block (Δ = v_k − v), the position block and the untouched track's position–velocity
    /// correlation (scaled by 1 − p) kept. The next sightings tell which it was.
    pub fn kicked(&self, model: &BallModel, kick: &Kick) -> BallEstimate {
        let mut est = self.predict_to(model, kick.t_s);
        if matches!(model, BallModel::Static { .. }) {
            return est;
        }
        let (v, v_cov) = kick.velocity();
        let p = kick.contact_prob.clamp(0.0, 1.0);
        let q = 1.0 - p;
        let old_v = est.velocity();
        let old_vv: Matrix2<f64> = est.cov.fixed_view::<2, 2>(2, 2).into_owned();
        let old_pv: Matrix2<f64> = est.cov.fixed_view::<2, 2>(0, 2).into_owned();
        let delta = v - old_v;
        let mean_v = v * p + old_v * q;
        let vv = v_cov * p + old_vv * q + delta * delta.transpose() * (p * q);
        est.mean.z = mean_v.x;
        est.mean.w = mean_v.y;
        let pos = est.position_cov();
        est.cov = Matrix4::zeros();
        est.cov.fixed_view_mut::<2, 2>(0, 0).copy_from(&pos);
        est.cov.fixed_view_mut::<2, 2>(2, 2).copy_from(&vv);
        let pv = old_pv * q;
        est.cov.fixed_view_mut::<2, 2>(0, 2).copy_from(&pv);
        est.cov
            .fixed_view_mut::<2, 2>(2, 0)
            .copy_from(&pv.transpose());
        est
    }
}
