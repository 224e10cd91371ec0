//! The few distributions the detector's thresholds come from.
//!
//! Under noise alone, the power in one tone's bin of one Hann-windowed FFT, divided by
//! the noise floor, is exponential with mean 1 (a χ² with 2 degrees of freedom over 2).
//! Half-overlapping Hann windows are almost independent (power correlation ≈ 0.03), so a
//! sum over `n` windows is close to Gamma(n, 1) and a sum over the six tones of a frame
//! close to Gamma(6n, 1). Thresholds are upper quantiles of these, chosen for a stated
//! false-alarm probability (see `decoder`), not tuned to any test.

/// `z` with `P(Z > z) = p` for a standard normal `Z`, `0 < p ≤ 0.5`
/// (Abramowitz & Stegun 26.2.23, absolute error < 4.5e-4).
pub(crate) fn normal_upper_quantile(p: f64) -> f64 {
    let p = p.clamp(1e-300, 0.5);
    let t = (-2.0 * p.ln()).sqrt();
    t - (2.515517 + 0.802853 * t + 0.010328 * t * t)
        / (1.0 + 1.432788 * t + 0.189269 * t * t + 0.001308 * t * t * t)
}

/// `x` with `P(X > x) = p` for `X ~ Gamma(shape, 1)` (Wilson–Hilferty cube-root normal
/// approximation; within a few percent down to shape 1 and p = 1e-12).
pub(crate) fn gamma_upper_quantile(shape: f64, p: f64) -> f64 {
    let z = normal_upper_quantile(p);
    let c = 1.0 / (9.0 * shape.max(1e-9));
    shape * (1.0 - c + z * c.sqrt()).max(0.0).powi(3)
}

/// `ln I0(x)`, the modified Bessel function of order 0 (A&S 9.8.1–9.8.2, relative error
/// < 2e-7), for the likelihood of a steady tone in noise.
pub(crate) fn ln_bessel_i0(x: f64) -> f64 {
    let ax = x.abs();
    if ax < 3.75 {
        let y = (x / 3.75).powi(2);
        (1.0 + y
            * (3.5156229
                + y * (3.0899424
                    + y * (1.2067492 + y * (0.2659732 + y * (0.0360768 + y * 0.0045813))))))
            .ln()
    } else {
        let y = 3.75 / ax;
        let poly = 0.39894228
            + y * (0.01328592
                + y * (0.00225319
                    + y * (-0.00157565
                        + y * (0.00916281
                            + y * (-0.02057706
                                + y * (0.02635537 + y * (-0.01647633 + y * 0.00392377)))))));
        ax - 0.5 * ax.ln() + poly.ln()
    }
}

/// Log-likelihood of a normalised power `r` (noise mean 1) given a steady tone whose
/// expected excess power is `lambda`: the non-central χ² with 2 degrees of freedom.
pub(crate) fn ln_tone_likelihood(r: f64, lambda: f64) -> f64 {
    -(r + lambda) + ln_bessel_i0(2.0 * (lambda * r).max(0.0).sqrt())
}

/// Share of a Hann window's area in its first `x` (0 … 1) of length.
pub(crate) fn hann_area_before(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x - (2.0 * std::f64::consts::PI * x).sin() / (2.0 * std::f64::consts::PI)
}

/// Share of the Hann area of the window `[start, start + len)` that lies inside `[a, b)`
/// (all in samples): the amplitude a tone sounding only during `[a, b)` keeps in that
/// window's FFT bin.
pub(crate) fn hann_share_inside(start: f64, len: f64, a: f64, b: f64) -> f64 {
    let xa = (a - start) / len;
    let xb = (b - start) / len;
    (hann_area_before(xb) - hann_area_before(xa)).max(0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_quantiles_match_exact_values() {
        // Gamma(1, 1) is Exp(1): the upper quantile is -ln p.
        for p in [1e-2, 3e-3, 1e-4] {
            let q = gamma_upper_quantile(1.0, p);
            let exact = -f64::ln(p);
            // Wilson–Hilferty errs high (conservative) in the far tail of small shapes.
            assert!((q / exact - 1.0).abs() < 0.06, "p {p}: {q} vs {exact}");
        }
        // Exact values from the Poisson-sum form of the integer-shape Gamma tail:
        // Gamma(14) at 3e-3 is 26.46; Gamma(84) at 1e-12 is 165.43.
        let q = gamma_upper_quantile(14.0, 3e-3);
        assert!((q - 26.46).abs() < 0.3, "{q}");
        let q = gamma_upper_quantile(84.0, 1e-12);
        assert!((q / 165.43 - 1.0).abs() < 0.03, "{q}");
    }

    #[test]
    fn bessel_matches_tabulated_values() {
        // I0(1) = 1.266066, I0(5) = 27.239872, I0(50) = 2.93255378e20.
        assert!((ln_bessel_i0(1.0) - 1.266066f64.ln()).abs() < 1e-6);
        assert!((ln_bessel_i0(5.0) - 27.239872f64.ln()).abs() < 1e-6);
        assert!((ln_bessel_i0(50.0) - 2.93255378e20f64.ln()).abs() < 1e-6);
    }

    #[test]
    fn hann_area_is_symmetric_and_splits() {
        for x in [0.0, 0.1, 0.3, 0.5] {
            // The Hann window is symmetric: the area before x equals the area after 1 − x.
            let after = 1.0 - hann_area_before(1.0 - x);
            assert!((hann_area_before(x) - after).abs() < 1e-12, "x {x}");
        }
        assert!((hann_share_inside(0.0, 100.0, -10.0, 50.0) - 0.5).abs() < 1e-12);
        assert_eq!(hann_share_inside(0.0, 100.0, 100.0, 200.0), 0.0);
    }
}
