//! The EKF measurement update shared by every filter here: Kalman gain, optional
//! Mahalanobis gate, Joseph-form covariance.

use nalgebra::{SMatrix, SVector};
use thiserror::Error;

/// Why a measurement update did not change the estimate.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum UpdateError {
    /// The innovation's squared Mahalanobis distance exceeded the gate; the estimate is unchanged.
    #[error("measurement gated out: Mahalanobis² {mahalanobis_sq:.3} > {threshold:.3}")]
    Gated {
        /// νᵀ S⁻¹ ν of the rejected measurement.
        mahalanobis_sq: f64,
        /// The χ² threshold that was in force.
        threshold: f64,
    },
    /// The innovation covariance S = H P Hᵀ + R was not positive definite.
    #[error("innovation covariance is not positive definite")]
    Singular,
    /// The measurement or its noise held a NaN or an infinity.
    #[error("measurement is not finite")]
    NonFinite,
}

/// One accepted update: the new mean and covariance, and the measurement's Mahalanobis².
pub(crate) struct Updated<const N: usize> {
    pub mean: SVector<f64, N>,
    pub cov: SMatrix<f64, N, N>,
    pub mahalanobis_sq: f64,
}

/// Squared Mahalanobis distance of `innovation` under `s`, or `None` if `s` is not PD.
pub(crate) fn mahalanobis_sq<const M: usize>(
    innovation: &SVector<f64, M>,
    s: &SMatrix<f64, M, M>,
) -> Option<f64> {
    let chol = s.cholesky()?;
    Some(innovation.dot(&chol.solve(innovation)))
}

/// x⁺ = x + K ν, P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ, with K = P Hᵀ S⁻¹, S = H P Hᵀ + R.
#[allow(non_snake_case)]
pub(crate) fn update<const N: usize, const M: usize>(
    mean: &SVector<f64, N>,
    P: &SMatrix<f64, N, N>,
    innovation: &SVector<f64, M>,
    H: &SMatrix<f64, M, N>,
    R: &SMatrix<f64, M, M>,
    gate_chi2: Option<f64>,
) -> Result<Updated<N>, UpdateError> {
    if !innovation.iter().all(|v| v.is_finite()) || !R.iter().all(|v| v.is_finite()) {
        return Err(UpdateError::NonFinite);
    }
    let PHt = P * H.transpose();
    let S = H * PHt + R;
    let chol = S.cholesky().ok_or(UpdateError::Singular)?;
    let d2 = innovation.dot(&chol.solve(innovation));
    if let Some(threshold) = gate_chi2 {
        if d2 > threshold {
            return Err(UpdateError::Gated {
                mahalanobis_sq: d2,
                threshold,
            });
        }
    }
    // K = P Hᵀ S⁻¹ = (S⁻¹ H P)ᵀ since S and P are symmetric.
    let K = chol.solve(&PHt.transpose()).transpose();
    let I_KH = SMatrix::<f64, N, N>::identity() - K * H;
    let cov = I_KH * P * I_KH.transpose() + K * R * K.transpose();
    let cov = (cov + cov.transpose()) * 0.5;
    let mean = mean + K * innovation;
    debug_assert!(
        cov.iter().all(|v| v.is_finite()),
        "covariance went non-finite"
    );
    Ok(Updated {
        mean,
        cov,
        mahalanobis_sq: d2,
    })
}
