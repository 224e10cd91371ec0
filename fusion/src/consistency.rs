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

/// χ²₂'s 99.9 % point, −2 ln 0.001: a 2-D NEES above it should happen once in a thousand.
pub const CHI2_2DOF_999: f64 = 13.815_510_557_964_274;

/// The standard normal CDF Φ(x), by Abramowitz & Stegun 7.1.26 (|error| < 1.5·10⁻⁷).
pub fn normal_cdf(x: f64) -> f64 {
    let z = x.abs() / std::f64::consts::SQRT_2;
    let t = 1.0 / (1.0 + 0.327_591_1 * z);
    let poly = t
        * (0.254_829_592
            + t * (-0.284_496_736
                + t * (1.421_413_741 + t * (-1.453_152_027 + t * 1.061_405_429))));
    let erfc = poly * (-z * z).exp();
    if x >= 0.0 {
        1.0 - 0.5 * erfc
    } else {
        0.5 * erfc
    }
}

/// How many independent samples a correlated series is worth, by the method of batch
/// means: cut it into batches of `batch` consecutive samples; the variance of the batch
/// means is s_B² ≈ s²·τ/batch for an integrated autocorrelation time τ (in samples), so
/// n_eff = n/τ = n·s² / (batch·s_B²), at most n.
/// Batches must be long against the correlation time; fewer than 10 batches (or a
/// constant series) give `None`.
pub fn batch_means_effective_samples(series: &[f64], batch: usize) -> Option<f64> {
    let batch = batch.max(1);
    let batches = series.len() / batch;
    if batches < 10 {
        return None;
    }
    let used = &series[..batches * batch];
    let n = used.len() as f64;
    let mean = used.iter().sum::<f64>() / n;
    let var = used.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let means: Vec<f64> = used
        .chunks(batch)
        .map(|c| c.iter().sum::<f64>() / batch as f64)
        .collect();
    let var_b = means.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (batches as f64 - 1.0);
    if !(var > 0.0 && var_b > 0.0) {
        return None;
    }
    Some((n * var / (batch as f64 * var_b)).min(n))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_normal_cdf_matches_the_tables() {
        for (x, p) in [
            (0.0, 0.5),
            (1.0, 0.841_344_7),
            (-1.959_964, 0.025),
            (3.0, 0.998_650_1),
        ] {
            assert!(
                (normal_cdf(x) - p).abs() < 2e-7,
                "Φ({x}) = {}",
                normal_cdf(x)
            );
        }
    }

    #[test]
    fn batch_means_count_a_repeated_series_once_per_repeat() {
        // Each independent value repeated 20 times: 500 values worth 500, not 10,000.
        let mut state = 12_345u64;
        let mut series = Vec::new();
        for _ in 0..500 {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            let x = (state >> 11) as f64 / (1u64 << 53) as f64;
            series.extend(std::iter::repeat_n(x, 20));
        }
        let n = batch_means_effective_samples(&series, 200).expect("enough batches");
        assert!((300.0..800.0).contains(&n), "effective samples {n}");
        let white: Vec<f64> = series.iter().step_by(20).copied().collect();
        let m = batch_means_effective_samples(&white, 10).expect("enough batches");
        assert!(m > 250.0, "independent values count fully: {m}");
        assert_eq!(batch_means_effective_samples(&[1.0; 50], 2), None);
    }

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
