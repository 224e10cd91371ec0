//! [`Measured`]: one piece of ball information for the team track, as the GWM keeps it
//! in its re-orderable window.

use crate::ball::{update, BallEstimate, BallModel, FieldObservation, Kick};
use crate::kalman;
use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};
use std::ops::Deref;

/// One piece of ball information for the team track: a position batch (what a camera
/// saw), the new information in a teammate's track (sparse messages), whose position
/// part gates, challenges and orders it like a batch, or a kick, which sits among them at
/// its own time (so a sighting made before it that arrives after its report still slots
/// in before it, and the kick is applied again on top).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Measured {
    /// The observation; for a kick, only its time counts.
    pub(super) obs: FieldObservation,
    /// The whole state (x, y, vx, vy) measured, with its covariance, when it came from a
    /// track; `obs` is then its position part.
    pub(super) state: Option<(Vector4<f64>, Matrix4<f64>)>,
    /// A kick applied at `obs.t_s` (not gated: it was taken when its report came).
    pub(super) kick: Option<Kick>,
}

impl Deref for Measured {
    type Target = FieldObservation;
    fn deref(&self) -> &FieldObservation {
        &self.obs
    }
}

impl From<FieldObservation> for Measured {
    fn from(obs: FieldObservation) -> Self {
        Measured {
            obs,
            state: None,
            kick: None,
        }
    }
}

impl Measured {
    /// A kick, to sit among the observations at its time.
    pub(super) fn kick(kick: &Kick) -> Self {
        Measured {
            obs: FieldObservation {
                t_s: kick.t_s,
                position: Vector2::zeros(),
                cov: Matrix2::zeros(),
            },
            state: None,
            kick: Some(*kick),
        }
    }

    /// `est` updated by this measurement at its time (`None`: it could not be applied).
    pub(super) fn apply(&self, model: &BallModel, est: &BallEstimate) -> Option<BallEstimate> {
        if let Some(kick) = &self.kick {
            return Some(est.kicked(model, kick));
        }
        let Some((z, r)) = self.state else {
            return update(model, est, &self.obs, None).ok().map(|(e, _)| e);
        };
        let prior = est.predict_to(model, self.obs.t_s);
        let u = kalman::update(
            &prior.mean,
            &prior.cov,
            &(z - prior.mean),
            &Matrix4::identity(),
            &r,
            None,
        )
        .ok()?;
        Some(BallEstimate {
            t_s: prior.t_s,
            mean: u.mean,
            cov: (u.cov + u.cov.transpose()) * 0.5,
        })
    }
}
