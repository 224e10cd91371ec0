//! Covariances on the wire: σ's on a log scale, correlations as i8, and an encoder that
//! never makes a covariance smaller.
//!
//! The encoder adds the mean's own quantisation variance (Δ²/12) to the diagonal, rounds σ
//! up, shrinks correlations towards zero until the decoded correlation matrix is positive
//! definite, then computes the largest generalised eigenvalue α of (original, decoded) and,
//! if α > 1, scales the σ's up by √α. So the decoded P' satisfies P' ⪰ P: a receiver is
//! never more confident than the sender.

use super::EncodeError;
use nalgebra::SMatrix;

const SIGMA8_MIN: f64 = 1e-4;
const SIGMA16_MIN: f64 = 1e-5;

fn ln_k8() -> f64 {
    6.0 * std::f64::consts::LN_10 / 255.0
}
fn ln_k16() -> f64 {
    7.0 * std::f64::consts::LN_10 / 65535.0
}

/// A σ quantiser: code ↔ value, rounding up on encode.
#[derive(Clone, Copy)]
pub(super) struct SigmaCode {
    min: f64,
    ln_k: f64,
    pub(super) max_code: u32,
}

impl SigmaCode {
    pub(super) const U8: fn() -> SigmaCode = || SigmaCode {
        min: SIGMA8_MIN,
        ln_k: ln_k8(),
        max_code: 255,
    };
    pub(super) const U16: fn() -> SigmaCode = || SigmaCode {
        min: SIGMA16_MIN,
        ln_k: ln_k16(),
        max_code: 65535,
    };

    pub(super) fn decode(&self, code: u32) -> f64 {
        if self.max_code == 255 {
            // The u8 scale is decoded 7 times per message: a table saves the exp().
            static TABLE: std::sync::OnceLock<[f64; 256]> = std::sync::OnceLock::new();
            let table = TABLE
                .get_or_init(|| std::array::from_fn(|q| SIGMA8_MIN * (ln_k8() * q as f64).exp()));
            return table[(code as usize).min(255)];
        }
        self.min * (self.ln_k * code as f64).exp()
    }

    /// Smallest code whose value is ≥ `sigma` (saturating at the top).
    pub(super) fn encode_up(&self, sigma: f64) -> u32 {
        if sigma <= self.min {
            return 0;
        }
        let mut code = ((sigma / self.min).ln() / self.ln_k)
            .ceil()
            .min(self.max_code as f64) as u32;
        // Guard against the last ulp of the logarithm.
        while code < self.max_code && self.decode(code) < sigma {
            code += 1;
        }
        code
    }
}

fn corr_decode(code: i8) -> f64 {
    code as f64 / 127.0
}

/// Encodes a covariance as (σ codes, correlation codes) such that the decoded matrix is
/// positive definite and ⪰ `cov`.
pub(super) fn encode_cov<const N: usize>(
    cov: &SMatrix<f64, N, N>,
    quantum_var: &[f64; N],
    q: SigmaCode,
    field: &'static str,
) -> Result<([u32; N], Vec<i8>), EncodeError> {
    if !cov.iter().all(|v| v.is_finite()) {
        return Err(EncodeError::OutOfRange { field });
    }
    let mut c = (cov + cov.transpose()) * 0.5;
    for i in 0..N {
        c[(i, i)] = c[(i, i)].max(0.0) + quantum_var[i];
    }
    let sd: [f64; N] = std::array::from_fn(|i| c[(i, i)].sqrt());
    let mut rho = Vec::with_capacity(N * (N - 1) / 2);
    for i in 0..N {
        for j in i + 1..N {
            let r = (c[(i, j)] / (sd[i] * sd[j])).clamp(-1.0, 1.0);
            rho.push((r * 127.0).round() as i8);
        }
    }
    // Shrink correlations until the decoded correlation matrix is comfortably PD: with
    // λ_min ≥ 0.05 the rounding of ρ (≤ 1/254 per entry) cannot hide a direction in which
    // the original is much wider, so the σ scale-up below stays small.
    while min_eigenvalue(&corr_matrix::<N>(&rho)) < 0.05 {
        for r in rho.iter_mut() {
            *r = (*r as f64 * 0.9).trunc() as i8;
        }
    }
    let corr = corr_matrix::<N>(&rho);
    let mut codes: [u32; N] = std::array::from_fn(|i| q.encode_up(sd[i]));
    for _ in 0..8 {
        let decoded = decode_cov(&codes, &corr, q);
        let alpha = max_generalised_eigenvalue(&c, &decoded);
        if alpha <= 1.0 {
            return Ok((codes, rho));
        }
        let scale = alpha.sqrt() * (1.0 + 1e-9);
        for code in codes.iter_mut() {
            *code = q.encode_up(q.decode(*code) * scale);
        }
    }
    // Only reachable when σ saturates at the top of the scale.
    Err(EncodeError::OutOfRange { field })
}

/// The symmetric eigen solver on a fixed-size copy of `$m` (N is 2, 3 or 4 here), then
/// `$pick` (`min` or `max`) of its eigenvalues. The generic const size lacks the solver's
/// trait bounds, and a dynamic matrix costs a heap allocation per step of the solver; the
/// arithmetic is the same either way (`eigenvalues_match_the_dynamic_solver`).
macro_rules! symmetric_eigenvalues {
    ($m:expr, $pick:ident) => {{
        let m = $m;
        match N {
            2 => nalgebra::Matrix2::from_iterator(m.iter().copied())
                .symmetric_eigenvalues()
                .$pick(),
            3 => nalgebra::Matrix3::from_iterator(m.iter().copied())
                .symmetric_eigenvalues()
                .$pick(),
            4 => nalgebra::Matrix4::from_iterator(m.iter().copied())
                .symmetric_eigenvalues()
                .$pick(),
            _ => nalgebra::DMatrix::from_iterator(N, N, m.iter().copied())
                .symmetric_eigenvalues()
                .$pick(),
        }
    }};
}
fn min_eigenvalue<const N: usize>(m: &SMatrix<f64, N, N>) -> f64 {
    symmetric_eigenvalues!(m, min)
}

pub(super) fn corr_matrix<const N: usize>(rho: &[i8]) -> SMatrix<f64, N, N> {
    let mut m = SMatrix::<f64, N, N>::identity();
    let mut k = 0;
    for i in 0..N {
        for j in i + 1..N {
            m[(i, j)] = corr_decode(rho[k]);
            m[(j, i)] = m[(i, j)];
            k += 1;
        }
    }
    m
}

pub(super) fn decode_cov<const N: usize>(
    codes: &[u32; N],
    corr: &SMatrix<f64, N, N>,
    q: SigmaCode,
) -> SMatrix<f64, N, N> {
    let d = SMatrix::<f64, N, N>::from_diagonal(&SMatrix::<f64, N, 1>::from_fn(|i, _| {
        q.decode(codes[i])
    }));
    d * corr * d
}

/// λ_max(B⁻¹ A) for symmetric A and PD B: how much B must grow to cover A.
fn max_generalised_eigenvalue<const N: usize>(
    a: &SMatrix<f64, N, N>,
    b: &SMatrix<f64, N, N>,
) -> f64 {
    let Some(chol) = b.cholesky() else {
        return f64::INFINITY;
    };
    let l = chol.l();
    let Some(linv) = l.try_inverse() else {
        return f64::INFINITY;
    };
    let m = linv * a * linv.transpose();
    let m = (m + m.transpose()) * 0.5;
    symmetric_eigenvalues!(&m, max)
}

#[cfg(test)]
mod tests {
    use nalgebra::{DMatrix, SMatrix};

    /// Symmetric matrices from a fixed stream: correlation-like and covariance-like, some
    /// near singular.
    fn matrices<const N: usize>(count: usize) -> Vec<SMatrix<f64, N, N>> {
        let mut x: u64 = 0x5eed_0f_c0_fa_ce;
        let mut next = move || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        (0..count)
            .map(|k| {
                let a =
                    SMatrix::<f64, N, N>::from_fn(|_, _| next() * 10f64.powi((k % 7) as i32 - 3));
                let m = a * a.transpose();
                (m + m.transpose()) * 0.5
            })
            .collect()
    }

    fn check<const N: usize>() {
        for m in matrices::<N>(2000) {
            let dynamic = DMatrix::from_iterator(N, N, m.iter().copied()).symmetric_eigenvalues();
            let (lo, hi) = (dynamic.min(), dynamic.max());
            let fixed = |m: &SMatrix<f64, N, N>| {
                (
                    symmetric_eigenvalues!(m, min),
                    symmetric_eigenvalues!(m, max),
                )
            };
            let (flo, fhi) = fixed(&m);
            assert!(
                flo.to_bits() == lo.to_bits() && fhi.to_bits() == hi.to_bits(),
                "{N}×{N}: fixed ({flo}, {fhi}) against dynamic ({lo}, {hi}) for {m}"
            );
        }
    }

    #[test]
    fn eigenvalues_match_the_dynamic_solver_bit_for_bit() {
        // The encoder's output (bytes on the wire) depends on these to the last bit.
        check::<2>();
        check::<3>();
        check::<4>();
    }
}
