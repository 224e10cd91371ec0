//! A ball estimate: mean and covariance at a time, predicted to any other.

use super::{BallModel, FieldObservation};
use crate::kalman;
use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};

/// A ball estimate at time `t_s`: mean (x, y, vx, vy) in m and m/s, covariance P.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallEstimate {
    /// When the estimate holds (s, on the owner's clock).
    pub t_s: f64,
    /// (x, y, vx, vy).
    pub mean: Vector4<f64>,
    /// P, 4×4.
    pub cov: Matrix4<f64>,
}

impl BallEstimate {
    /// The position (x, y).
    pub fn position(&self) -> Vector2<f64> {
        Vector2::new(self.mean.x, self.mean.y)
    }

    /// The velocity (vx, vy).
    pub fn velocity(&self) -> Vector2<f64> {
        Vector2::new(self.mean.z, self.mean.w)
    }

    /// The 2×2 position block of P.
    pub fn position_cov(&self) -> Matrix2<f64> {
        self.cov.fixed_view::<2, 2>(0, 0).into_owned()
    }

    /// The estimate predicted to `t_s` (x⁻ = F x, P⁻ = F P Fᵀ + Q). Any future time works, so
    /// this is also the interception query; a `t_s` before `self.t_s` returns `self`.
    #[allow(non_snake_case)]
    pub fn predict_to(&self, model: &BallModel, t_s: f64) -> BallEstimate {
        if t_s <= self.t_s {
            return *self;
        }
        let velocity_var = self.cov[(2, 2)] + self.cov[(3, 3)];
        let (mean, F, Q) = model.propagate(&self.mean, velocity_var, t_s - self.t_s);
        let cov = F * self.cov * F.transpose() + Q;
        BallEstimate {
            t_s,
            mean,
            cov: (cov + cov.transpose()) * 0.5,
        }
    }

    /// Squared Mahalanobis distance between this estimate's position and `obs` (both at
    /// `obs.t_s` after prediction), using S = P_pos + R.
    pub fn position_mahalanobis_sq(
        &self,
        model: &BallModel,
        obs: &FieldObservation,
    ) -> Option<f64> {
        // No copy of `self` when no time passes (see `predict_to`).
        let predicted;
        let p = if obs.t_s <= self.t_s {
            self
        } else {
            predicted = self.predict_to(model, obs.t_s);
            &predicted
        };
        kalman::mahalanobis_sq(
            &(obs.position - p.position()),
            &(p.position_cov() + obs.cov),
        )
    }
}
