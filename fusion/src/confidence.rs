//! Confidences in [0, 1] (tsinghua-2005 §6: SLC, LBC, GBC) derived from covariances, so that
//! they mean the same thing on every robot: `1 / (1 + u²/u_ref²)` where `u²` is the mean
//! positional variance per axis and `u_ref` = [`REFERENCE_RADIUS_M`]. A confidence of 0.5
//! means a 1-σ radius of about 0.3 m per axis.

use nalgebra::{Matrix2, Matrix3};

/// The 1-σ radius at which a confidence is 0.5.
pub const REFERENCE_RADIUS_M: f64 = 0.3;

/// Confidence of a 2-D position with covariance `cov`.
pub fn position_confidence(cov: &Matrix2<f64>) -> f64 {
    let u2 = 0.5 * cov.trace();
    if !u2.is_finite() {
        return 0.0;
    }
    1.0 / (1.0 + u2.max(0.0) / (REFERENCE_RADIUS_M * REFERENCE_RADIUS_M))
}

/// Self-localisation confidence: the position variance plus the heading variance seen at a
/// 1 m lever (a heading error of 0.3 rad moves a sighting 1 m away by 0.3 m).
pub fn pose_confidence(cov: &Matrix3<f64>) -> f64 {
    let lever = Matrix2::identity() * cov[(2, 2)];
    position_confidence(&(cov.fixed_view::<2, 2>(0, 0).into_owned() + lever))
}
