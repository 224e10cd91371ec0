//! Covariances on the wire: σ's on a log scale, correlations as i8, and an encoder that
//! never makes a covariance smaller.
//!
//! The encoder adds the mean's own quantisation variance (Δ²/12) to the diagonal, rounds σ
//! up, shrinks correlations towards zero until the decoded correlation matrix is positive
//! definite, then computes the largest generalised eigenvalue α of (original, decoded) and,
//! if α > 1, scales the σ's up by √α. So the decoded P' satisfies P' ⪰ P: a receiver is
//! never more confident than the sender.

use super::{EncodeError, MM_VAR};
use nalgebra::{Matrix2, SMatrix};
use std::cell::RefCell;

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
    while min_eigenvalue_below(&corr_matrix::<N>(&rho), 0.05) {
        for r in rho.iter_mut() {
            *r = (*r as f64 * 0.9).trunc() as i8;
        }
    }
    let corr = corr_matrix::<N>(&rho);
    let mut codes: [u32; N] = std::array::from_fn(|i| q.encode_up(sd[i]));
    for _ in 0..8 {
        let decoded = decode_cov(&codes, &corr, q);
        let Some(alpha) = growth_needed(&c, &decoded) else {
            return Ok((codes, rho));
        };
        let scale = alpha.sqrt() * (1.0 + 1e-9);
        for code in codes.iter_mut() {
            *code = q.encode_up(q.decode(*code) * scale);
        }
    }
    // Only reachable when σ saturates at the top of the scale.
    Err(EncodeError::OutOfRange { field })
}

/// [`encode_cov`] of a ball observation's covariance (the u16 scale), remembered: each
/// observation batch goes out three times (in its own message and as the repeat in the
/// next two), and the answer depends on nothing but the covariance's bits. A small
/// direct-mapped table per thread (one robot's three batches, or a simulated team's
/// fifteen), checked on the whole key; errors are not kept.
pub(super) fn encode_observation_cov(cov: &Matrix2<f64>) -> Result<([u32; 2], i8), EncodeError> {
    type Kept = Option<([u64; 4], [u32; 2], i8)>;
    thread_local! {
        static KEPT: RefCell<[Kept; OBSERVATION_SLOTS]> =
            const { RefCell::new([None; OBSERVATION_SLOTS]) };
    }
    let bits: [u64; 4] = std::array::from_fn(|i| cov.as_slice()[i].to_bits());
    let slot = observation_slot(&bits);
    if let Some((codes, rho)) = KEPT.with_borrow(|kept| {
        kept[slot].and_then(|(key, codes, rho)| (key == bits).then_some((codes, rho)))
    }) {
        return Ok((codes, rho));
    }
    let (codes, rho) = encode_cov(cov, &[MM_VAR; 2], SigmaCode::U16(), "observation")?;
    KEPT.with_borrow_mut(|kept| kept[slot] = Some((bits, codes, rho[0])));
    Ok((codes, rho[0]))
}

const OBSERVATION_SLOTS: usize = 64;

fn observation_slot(bits: &[u64; 4]) -> usize {
    let h = bits
        .iter()
        .fold(0u64, |h, b| (h ^ b).wrapping_mul(0x9e37_79b9_7f4a_7c15));
    (h >> 58) as usize % OBSERVATION_SLOTS
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

/// How far past a bound a Cholesky factorisation settles an eigenvalue question without
/// the eigen solver: far more than either one's rounding (about 1e-15 here), so the answer
/// is the one the solver would give. Only a matrix within this of the bound goes to the
/// solver. (Every message encodes three covariances, and the solver was a tenth of the
/// simulator's time.)
const SURE_MARGIN: f64 = 1e-6;

/// Whether the smallest eigenvalue of the symmetric `m` is below `bound`, as the eigen
/// solver finds it.
fn min_eigenvalue_below<const N: usize>(m: &SMatrix<f64, N, N>, bound: f64) -> bool {
    let shifted = m - SMatrix::<f64, N, N>::identity() * (bound + SURE_MARGIN);
    if shifted.cholesky().is_some() {
        // Positive definite: every eigenvalue is above the bound by the margin.
        return false;
    }
    min_eigenvalue(m) < bound
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

/// λ_max(B⁻¹ A) for symmetric A and PD B: how much B must grow to cover A (the encoder
/// asks [`growth_needed`]; this is what that must agree with).
#[cfg(test)]
fn max_generalised_eigenvalue<const N: usize>(
    a: &SMatrix<f64, N, N>,
    b: &SMatrix<f64, N, N>,
) -> f64 {
    match whitened(a, b) {
        Some(m) => symmetric_eigenvalues!(&m, max),
        None => f64::INFINITY,
    }
}

/// `L⁻¹ A L⁻ᵀ` (symmetrised) for B = L Lᵀ: its eigenvalues are those of B⁻¹ A. `None`
/// when B is not positive definite.
fn whitened<const N: usize>(
    a: &SMatrix<f64, N, N>,
    b: &SMatrix<f64, N, N>,
) -> Option<SMatrix<f64, N, N>> {
    let l = b.cholesky()?.l();
    let linv = l.try_inverse()?;
    let m = linv * a * linv.transpose();
    Some((m + m.transpose()) * 0.5)
}

/// [`max_generalised_eigenvalue`] when B does not cover A (above 1, or not a number),
/// `None` when it does: the encoder's test, settled by one Cholesky factorisation unless
/// λ_max is within [`SURE_MARGIN`] of 1.
fn growth_needed<const N: usize>(a: &SMatrix<f64, N, N>, b: &SMatrix<f64, N, N>) -> Option<f64> {
    let Some(m) = whitened(a, b) else {
        return Some(f64::INFINITY);
    };
    let room = SMatrix::<f64, N, N>::identity() * (1.0 - SURE_MARGIN) - m;
    if room.cholesky().is_some() {
        // Every eigenvalue of B⁻¹ A is below 1 by the margin.
        return None;
    }
    let alpha = symmetric_eigenvalues!(&m, max);
    // As `alpha <= 1.0` decided: a NaN needs growth.
    (alpha > 1.0 || alpha.is_nan()).then_some(alpha)
}

#[cfg(test)]
mod tests {
    use nalgebra::{DMatrix, SMatrix};

    /// Symmetric matrices from a fixed stream: correlation-like and covariance-like, some
    /// near singular.
    fn matrices<const N: usize>(count: usize) -> Vec<SMatrix<f64, N, N>> {
        let mut x: u64 = 0x5eed_0fc0_face;
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

    fn check_shortcuts<const N: usize>() {
        use super::{
            corr_matrix, growth_needed, max_generalised_eigenvalue, min_eigenvalue,
            min_eigenvalue_below,
        };
        let mut x: u64 = 77;
        let mut byte = move || {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (x >> 56) as u8 as i8
        };
        for _ in 0..20_000 {
            let rho: Vec<i8> = (0..N * (N - 1) / 2).map(|_| byte()).collect();
            let corr = corr_matrix::<N>(&rho);
            for bound in [0.05, 0.3] {
                assert_eq!(
                    min_eigenvalue_below(&corr, bound),
                    min_eigenvalue(&corr) < bound,
                    "{N}×{N} correlations {rho:?}, bound {bound}"
                );
            }
        }
        let ms = matrices::<N>(2000);
        for pair in ms.windows(2) {
            let (a, b) = (
                &pair[0],
                &(pair[1] + SMatrix::<f64, N, N>::identity() * 1e-3),
            );
            // λ_max around 1 (within the margin and just outside it) and well either side.
            let alpha0 = max_generalised_eigenvalue(a, b);
            for scale in [0.5, 0.999_998, 0.999_999_9, 1.0, 1.000_000_1, 2.0] {
                let a = a * (scale / alpha0);
                let alpha = max_generalised_eigenvalue(&a, b);
                let want = (alpha > 1.0 || alpha.is_nan()).then_some(alpha);
                let got = growth_needed(&a, b);
                assert!(
                    got.map(f64::to_bits) == want.map(f64::to_bits),
                    "{N}×{N}: {got:?} against the solver's {want:?}"
                );
            }
        }
    }

    /// A simulated team's observation batches, each encoded three times in turn, with
    /// more live batches than the table has slots (so kept answers are overwritten and
    /// slots collide): every answer is the one worked out afresh.
    #[test]
    fn a_kept_observation_code_is_the_one_worked_out_afresh() {
        use super::{encode_cov, encode_observation_cov, SigmaCode, MM_VAR};
        use nalgebra::Matrix2;
        let covs: Vec<Matrix2<f64>> = matrices::<2>(400).into_iter().map(|m| m * 1e-3).collect();
        let mut asked = 0;
        for round in 0..3 {
            for (k, cov) in covs.iter().enumerate() {
                // Batch k goes out in messages k, k + 1 and k + 2.
                let repeats = [1, 2].map(|back| k.checked_sub(back).map(|j| &covs[j]));
                for c in std::iter::once(Some(cov)).chain(repeats).flatten() {
                    let fresh = encode_cov(c, &[MM_VAR; 2], SigmaCode::U16(), "observation")
                        .map(|(codes, rho)| (codes, rho[0]));
                    assert_eq!(
                        encode_observation_cov(c),
                        fresh,
                        "round {round}, batch {k}: {c:?}"
                    );
                    asked += 1;
                }
            }
        }
        assert_eq!(asked, 3 * (3 * 400 - 3));
    }

    #[test]
    fn cholesky_shortcuts_answer_as_the_eigen_solver_does() {
        check_shortcuts::<2>();
        check_shortcuts::<3>();
        check_shortcuts::<4>();
    }

    #[test]
    fn eigenvalues_match_the_dynamic_solver_bit_for_bit() {
        // The encoder's output (bytes on the wire) depends on these to the last bit.
        check::<2>();
        check::<3>();
        check::<4>();
    }
}
