//! Filter consistency: is an estimator's claimed covariance honest?
//!
//! An honest estimator's normalised estimation error squared, NEES = eᵀ P⁻¹ e, is χ² with
//! as many degrees of freedom as the state. The mean of `n` independent NEES samples of a
//! `dof`-D state is therefore χ²_{dof·n} / n; when it falls below [`nees_bounds`] the
//! filter is underconfident (P too wide), above them overconfident (P too narrow).

/// The standard normal's 97.5 % quantile: two-sided 95 % bounds sit at ±`Z_975`.
pub const Z_975: f64 = 1.959964;

/// The χ² quantile of `dof` degrees of freedom at the probability whose standard normal
/// quantile is `z`, by the Wilson–Hilferty approximation
/// `k (1 − 2/(9k) + z √(2/(9k)))³` (`k = dof`; within 0.1 % for k ≥ 10).
pub fn chi_square_quantile(dof: f64, z: f64) -> f64 {
    let k = dof;
    k * (1.0 - 2.0 / (9.0 * k) + z * (2.0 / (9.0 * k)).sqrt()).powi(3)
}

/// Two-sided 95 % bounds on the mean of `samples` independent NEES samples of a `dof`-D
/// state: χ²_{dof·n}(0.025, 0.975) / n with `n = max(samples, 1)`, Wilson–Hilferty.
pub fn nees_bounds(dof: u64, samples: u64) -> (f64, f64) {
    let k = (dof * samples.max(1)) as f64;
    let n = samples.max(1) as f64;
    (
        chi_square_quantile(k, -Z_975) / n,
        chi_square_quantile(k, Z_975) / n,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bounds_match_the_tables() {
        // χ²₆₀₀(0.025) = 534.02, χ²₆₀₀(0.975) = 669.77 (exact, by the incomplete gamma
        // function), over 300 samples.
        let (lo, hi) = nees_bounds(2, 300);
        assert!((lo - 534.02 / 300.0).abs() < 0.001, "{lo}");
        assert!((hi - 669.77 / 300.0).abs() < 0.001, "{hi}");
        // χ²₂₀₀(0.025) = 162.73, χ²₂₀₀(0.975) = 241.06 (4 dof, 50 runs).
        let (lo, hi) = nees_bounds(4, 50);
        assert!((lo - 162.73 / 50.0).abs() < 0.001, "{lo}");
        assert!((hi - 241.06 / 50.0).abs() < 0.001, "{hi}");
    }

    #[test]
    fn no_samples_are_bounded_like_one() {
        assert_eq!(nees_bounds(3, 0), nees_bounds(3, 1));
    }
}
