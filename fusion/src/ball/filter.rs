//! The ball EKF: one predict-and-update step, a fresh track, and the running filter that
//! gates outliers and restarts after a kick it could not follow.

use super::{
    field_observation_shared, BallEstimate, BallModel, BallSighting, FieldObservation, Kick,
};
use crate::kalman::UpdateError;
use crate::pose::PoseEstimate;
use nalgebra::{Matrix2, Matrix4, Vector4};

/// Predicts `est` to the observation's time and applies it (H = [I₂ 0], Joseph form).
/// Returns the new estimate and the observation's Mahalanobis².
///
/// With H = [I₂ 0] everything is a block of P: P Hᵀ is P's first two columns, S is a 2×2
/// inverted in closed form, and the Joseph form expands to
/// P − K (PHᵀ)ᵀ − (PHᵀ) Kᵀ + K S Kᵀ (algebraically identical, no 4×4 (I − KH) products).
/// This is the GWM's hot path.
#[allow(non_snake_case)]
pub fn update(
    model: &BallModel,
    est: &BallEstimate,
    obs: &FieldObservation,
    gate_chi2: Option<f64>,
) -> Result<(BallEstimate, f64), UpdateError> {
    // Borrowed when no time passes (`predict_to` would return a copy of `est`): the GWM
    // updates a state it just predicted to the observation's time.
    let predicted;
    let prior = if obs.t_s <= est.t_s {
        est
    } else {
        predicted = est.predict_to(model, obs.t_s);
        &predicted
    };
    let nu = obs.position - prior.position();
    if !nu.iter().chain(obs.cov.iter()).all(|v| v.is_finite()) {
        return Err(UpdateError::NonFinite);
    }
    let S = prior.position_cov() + obs.cov;
    let det = S[(0, 0)] * S[(1, 1)] - S[(0, 1)] * S[(1, 0)];
    if !(S[(0, 0)] > 0.0 && det > 0.0) {
        return Err(UpdateError::Singular);
    }
    let S_inv = Matrix2::new(S[(1, 1)], -S[(0, 1)], -S[(1, 0)], S[(0, 0)]) / det;
    let d2 = nu.dot(&(S_inv * nu));
    if let Some(threshold) = gate_chi2 {
        if d2 > threshold {
            return Err(UpdateError::Gated {
                mahalanobis_sq: d2,
                threshold,
            });
        }
    }
    let PHt = prior.cov.fixed_view::<4, 2>(0, 0).into_owned();
    let K = PHt * S_inv;
    let KPH = K * PHt.transpose();
    let cov = prior.cov - KPH - KPH.transpose() + K * S * K.transpose();
    let cov = (cov + cov.transpose()) * 0.5;
    debug_assert!(
        cov.iter().all(|v| v.is_finite()),
        "covariance went non-finite"
    );
    Ok((
        BallEstimate {
            t_s: prior.t_s,
            mean: prior.mean + K * nu,
            cov,
        },
        d2,
    ))
}

/// A fresh track from one observation: position from z, velocity zero with a wide variance.
pub fn initial_estimate(
    model: &BallModel,
    obs: &FieldObservation,
    velocity_var: f64,
) -> BallEstimate {
    let mut cov = Matrix4::zeros();
    cov.fixed_view_mut::<2, 2>(0, 0).copy_from(&obs.cov);
    let vv = model.initial_velocity_var(velocity_var);
    cov[(2, 2)] = vv;
    cov[(3, 3)] = vv;
    BallEstimate {
        t_s: obs.t_s,
        mean: Vector4::new(obs.position.x, obs.position.y, 0.0, 0.0),
        cov,
    }
}

/// Settings of a [`BallFilter`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallFilterConfig {
    /// The motion model.
    pub model: BallModel,
    /// Velocity variance of a fresh track (m²/s²).
    pub initial_velocity_var: f64,
    /// χ² (2 dof) beyond which a sighting counts as an outlier and is not applied.
    pub outlier_chi2: f64,
    /// After this many consecutive outliers the track restarts from the latest one (a kick
    /// the motion model could not follow).
    pub reset_after_outliers: u32,
    /// The consecutive outliers must also agree with each other (each within the gate of
    /// a fresh track on the one before), as the GWM's challenge asks: one false ball or
    /// one robot's stray sighting after another's then cannot restart the track on
    /// itself. Off for a robot's own track (its LWM, one camera); on for a filter that
    /// mixes several robots' sightings (the simulator's references).
    pub outliers_must_agree: bool,
    /// k of [`field_observation_shared`]: how many consecutive sightings of one robot share
    /// one pose error (about camera rate × detection rate × the time landmarks take to
    /// renew the pose). 1 treats pose errors as white, which is overconfident.
    pub pose_error_sharing: f64,
}

impl Default for BallFilterConfig {
    fn default() -> Self {
        BallFilterConfig {
            model: BallModel::default(),
            initial_velocity_var: 4.0,
            outlier_chi2: 9.21,
            reset_after_outliers: 2,
            outliers_must_agree: false,
            pose_error_sharing: 10.0,
        }
    }
}

/// What one observation did to a [`BallFilter`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BallUpdate {
    /// There was no track; it now starts here.
    Initialised,
    /// Applied; carries the Mahalanobis².
    Updated(f64),
    /// Not applied (Mahalanobis² beyond the outlier gate).
    Outlier(f64),
    /// Too many outliers in a row: the track restarted from this observation.
    Restarted,
    /// Not applied: non-finite or degenerate input.
    Rejected(UpdateError),
}

/// A running ball EKF fed field-frame observations in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct BallFilter {
    /// Settings.
    pub config: BallFilterConfig,
    estimate: Option<BallEstimate>,
    outliers_in_a_row: u32,
    /// The latest outlier of the current run (with `outliers_must_agree`).
    last_outlier: Option<FieldObservation>,
}

impl BallFilter {
    /// A filter with no track yet.
    pub fn new(config: BallFilterConfig) -> Self {
        BallFilter {
            config,
            estimate: None,
            outliers_in_a_row: 0,
            last_outlier: None,
        }
    }

    /// The latest estimate (at the time of the last observation), if any.
    pub fn estimate(&self) -> Option<&BallEstimate> {
        self.estimate.as_ref()
    }

    /// The estimate predicted to `t_s`.
    pub fn estimate_at(&self, t_s: f64) -> Option<BallEstimate> {
        self.estimate.map(|e| e.predict_to(&self.config.model, t_s))
    }

    /// Applies one observation (an observation older than the track is applied at the
    /// track's time).
    pub fn observe(&mut self, obs: &FieldObservation) -> BallUpdate {
        if !obs
            .position
            .iter()
            .chain(obs.cov.iter())
            .all(|v| v.is_finite())
            || !obs.t_s.is_finite()
        {
            return BallUpdate::Rejected(UpdateError::NonFinite);
        }
        let Some(est) = self.estimate else {
            self.estimate = Some(initial_estimate(
                &self.config.model,
                obs,
                self.config.initial_velocity_var,
            ));
            return BallUpdate::Initialised;
        };
        match update(
            &self.config.model,
            &est,
            obs,
            Some(self.config.outlier_chi2),
        ) {
            Ok((next, d2)) => {
                self.estimate = Some(next);
                self.outliers_in_a_row = 0;
                self.last_outlier = None;
                BallUpdate::Updated(d2)
            }
            Err(UpdateError::Gated { mahalanobis_sq, .. }) => {
                let agrees = !self.config.outliers_must_agree
                    || self.last_outlier.is_none_or(|prev| {
                        let model = &self.config.model;
                        initial_estimate(model, &prev, self.config.initial_velocity_var)
                            .position_mahalanobis_sq(model, obs)
                            .is_some_and(|d2| d2 <= self.config.outlier_chi2)
                    });
                self.outliers_in_a_row = if agrees {
                    self.outliers_in_a_row + 1
                } else {
                    1
                };
                self.last_outlier = Some(*obs);
                if self.outliers_in_a_row >= self.config.reset_after_outliers {
                    self.outliers_in_a_row = 0;
                    self.last_outlier = None;
                    let mut fresh =
                        initial_estimate(&self.config.model, obs, self.config.initial_velocity_var);
                    fresh.t_s = fresh.t_s.max(est.t_s);
                    self.estimate = Some(fresh);
                    BallUpdate::Restarted
                } else {
                    BallUpdate::Outlier(mahalanobis_sq)
                }
            }
            Err(e) => BallUpdate::Rejected(e),
        }
    }

    /// A kick (see [`Kick`]); without a track there is nothing to kick.
    pub fn kick(&mut self, kick: &Kick) {
        if !kick.is_valid() {
            return;
        }
        if let Some(est) = &self.estimate {
            self.estimate = Some(est.kicked(&self.config.model, kick));
            self.outliers_in_a_row = 0;
            self.last_outlier = None;
        }
    }

    /// Applies a measurement of the whole state (`z`, covariance `r`) at `t_s`: a
    /// teammate's track ([`crate::TrackGain`]). Gated on its position like a sighting; a
    /// track that keeps failing the gate restarts the filter on it.
    pub fn measure_state(&mut self, t_s: f64, z: &Vector4<f64>, r: &Matrix4<f64>) -> BallUpdate {
        if !t_s.is_finite() || !z.iter().chain(r.iter()).all(|v| v.is_finite()) {
            return BallUpdate::Rejected(UpdateError::NonFinite);
        }
        let fresh = BallEstimate {
            t_s,
            mean: *z,
            cov: *r,
        };
        let Some(est) = self.estimate else {
            self.estimate = Some(fresh);
            return BallUpdate::Initialised;
        };
        let prior = est.predict_to(&self.config.model, t_s.max(est.t_s));
        let d2 = crate::kalman::mahalanobis_sq(
            &(z.fixed_rows::<2>(0) - prior.position()),
            &(prior.position_cov() + r.fixed_view::<2, 2>(0, 0)),
        );
        if d2.is_none_or(|d2| d2 > self.config.outlier_chi2) {
            self.outliers_in_a_row += 1;
            if self.outliers_in_a_row >= self.config.reset_after_outliers {
                self.outliers_in_a_row = 0;
                self.estimate = Some(BallEstimate {
                    t_s: prior.t_s,
                    ..fresh
                });
                return BallUpdate::Restarted;
            }
            return BallUpdate::Outlier(d2.unwrap_or(f64::INFINITY));
        }
        match crate::kalman::update(
            &prior.mean,
            &prior.cov,
            &(z - prior.mean),
            &Matrix4::identity(),
            r,
            None,
        ) {
            Ok(u) => {
                self.estimate = Some(BallEstimate {
                    t_s: prior.t_s,
                    mean: u.mean,
                    cov: (u.cov + u.cov.transpose()) * 0.5,
                });
                self.outliers_in_a_row = 0;
                self.last_outlier = None;
                BallUpdate::Updated(d2.unwrap_or(0.0))
            }
            Err(e) => BallUpdate::Rejected(e),
        }
    }

    /// Applies a sighting in robot coordinates made from `pose` at `t_s`.
    pub fn sighting(
        &mut self,
        t_s: f64,
        pose: &PoseEstimate,
        sighting: &BallSighting,
    ) -> BallUpdate {
        self.observe(&field_observation_shared(
            t_s,
            pose,
            sighting,
            self.config.pose_error_sharing,
        ))
    }
}
