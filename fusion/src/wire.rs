//! The LWM on the wire: 75 bytes, fixed point, little-endian.
//!
//! ```text
//! off  size  field
//!  0    1    version (high nibble, = 3) | flags: bit0 ball present, bit1 observation
//!            present, bit2 / bit3 the batch of message seq−1 / seq−2 present
//!  1    2    seq u16
//!  3    6    pose x, y (i16 mm), θ (i16, π/32768 rad)
//!  9    3    pose σx, σy, σθ (u8 log scale, see below)
//! 12    3    pose ρxy, ρxθ, ρyθ (i8, /127)
//! 15    8    ball x, y (i16 mm), vx, vy (i16 mm/s)
//! 23    4    ball σ of x, y, vx, vy (u8 log)
//! 27    6    ball ρ 01 02 03 12 13 23 (i8)
//! 33    2    time since the ball was seen (u16 ms; 65535 = never or longer)
//! 35    2    SLC, LBC (u8, /255)
//! 37    4    observation x, y (i16 mm)
//! 41    4    observation σx, σy (u16 log, finer)
//! 45    1    observation ρ (i8)
//! 46    2    observation age before the message time (u16 ms)
//! 48   11    the batch of message seq−1 again, same layout as 37..48
//! 59   11    the batch of message seq−2 again
//! 70    1    kick: bit7 present, bits 6–5 its number (mod 4), bits 4–0 its age before
//!            the message time (× 5 ms, ≤ 155 ms)
//! 71    1    kick speed (u8, × 0.05 m/s)
//! 72    1    kick direction (u8, × 2π/256 rad, counter-clockwise from field +x)
//! 73    2    kick σ of speed, of direction (u8 log)
//! ```
//!
//! The two earlier batches are repeats, so that a lost message (or one overwritten on a
//! receiver's blackboard by the next before it was read) loses nothing as long as one of
//! the next two arrives; the GWM takes each batch once, by sequence number. A kick is
//! likewise repeated for [`crate::KICK_REPORTED_FOR_S`] and taken once, by its number.
//! A comms frame carrying the 75 bytes alone is at most 128 bytes (the SPL's message limit)
//! whatever its counters. An HMAC tag adds 16, which takes a keyed team's frame past 128
//! (to 144 at most; the 70-byte version 2 was past it too once its counters grew).
//! The kick's speed and direction steps are added to its σ's (the time step, ≤ 2.5 ms, is
//! not: 1 cm at 4 m/s).
//!
//! A u8 σ code q means `1e-4 · K8^q` (m, rad or m/s) with K8 = 10^(6/255) (5.6 % steps,
//! up to 100); a u16 code means `1e-5 · K16^q` with K16 = 10^(7/65535).
//!
//! **Quantisation never makes a covariance smaller.** The encoder adds the mean's own
//! quantisation variance (Δ²/12) to the diagonal, rounds σ up, shrinks correlations towards
//! zero until the decoded correlation matrix is positive definite, then computes the largest
//! generalised eigenvalue α of (original, decoded) and, if α > 1, scales the σ's up by √α.
//! So the decoded P' satisfies P' ⪰ P: a receiver is never more confident than the sender.
//!
//! Decoding ([`crate::LocalWorldModel::from_bytes`]) is safe on untrusted bytes: every
//! code maps to a finite number, and a correlation block that is not positive definite is a
//! [`DecodeError`], never a panic.

use crate::ball::{BallEstimate, FieldObservation, Kick};
use crate::local::{KickReport, LocalWorldModel};
use crate::pose::PoseEstimate;
use nalgebra::{SMatrix, Vector2, Vector3, Vector4};
use std::f64::consts::PI;
use thiserror::Error;

/// Bytes of an encoded LWM.
pub const LWM_WIRE_LEN: usize = 75;
const VERSION: u8 = 3;
const KICK_AT: usize = 70;
const KICK_PRESENT: u8 = 0x80;
const KICK_AGE_STEP_S: f64 = 0.005;
const KICK_SPEED_STEP_MPS: f64 = 0.05;
const KICK_DIRECTION_STEP_RAD: f64 = 2.0 * PI / 256.0;
const FLAG_BALL: u8 = 1;
const FLAG_OBSERVATION: u8 = 2;
const FLAG_EARLIER: [u8; 2] = [4, 8];
/// Where each observation block starts (the message's own batch, then seq−1, seq−2).
const OBSERVATION_AT: [usize; 3] = [37, 48, 59];
const NEVER_MS: u16 = u16::MAX;

/// Why [`crate::LocalWorldModel::to_bytes`] failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum EncodeError {
    /// A value does not fit its fixed-point field (positions beyond ±32.767 m, speeds
    /// beyond ±32.767 m/s) or is not finite.
    #[error("{field} is out of range or not finite")]
    OutOfRange {
        /// Which field.
        field: &'static str,
    },
}

/// Why [`crate::LocalWorldModel::from_bytes`] rejected a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Error)]
pub enum DecodeError {
    /// The message is not [`LWM_WIRE_LEN`] bytes long.
    #[error("LWM message is {got} bytes, expected {expected}")]
    Length {
        /// Bytes required.
        expected: usize,
        /// Bytes received.
        got: usize,
    },
    /// The version nibble is not one this decoder knows.
    #[error("unknown LWM version {got}")]
    Version {
        /// The version received.
        got: u8,
    },
    /// A correlation block does not form a valid (positive definite) covariance.
    #[error("{field} covariance is not positive definite")]
    NotPositiveDefinite {
        /// Which covariance.
        field: &'static str,
    },
}

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
struct SigmaCode {
    min: f64,
    ln_k: f64,
    max_code: u32,
}

impl SigmaCode {
    const U8: fn() -> SigmaCode = || SigmaCode {
        min: SIGMA8_MIN,
        ln_k: ln_k8(),
        max_code: 255,
    };
    const U16: fn() -> SigmaCode = || SigmaCode {
        min: SIGMA16_MIN,
        ln_k: ln_k16(),
        max_code: 65535,
    };

    fn decode(&self, code: u32) -> f64 {
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
    fn encode_up(&self, sigma: f64) -> u32 {
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
fn encode_cov<const N: usize>(
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

fn min_eigenvalue<const N: usize>(m: &SMatrix<f64, N, N>) -> f64 {
    nalgebra::DMatrix::from_iterator(N, N, m.iter().copied())
        .symmetric_eigenvalues()
        .min()
}

fn corr_matrix<const N: usize>(rho: &[i8]) -> SMatrix<f64, N, N> {
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

fn decode_cov<const N: usize>(
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
    // Generic const sizes lack the eigen solver's bounds; N ≤ 4, so go dynamic.
    nalgebra::DMatrix::from_iterator(N, N, m.iter().copied())
        .symmetric_eigenvalues()
        .max()
}

fn mm(v: f64, field: &'static str) -> Result<i16, EncodeError> {
    let x = (v * 1000.0).round();
    if !x.is_finite() || x.abs() > i16::MAX as f64 {
        return Err(EncodeError::OutOfRange { field });
    }
    Ok(x as i16)
}

fn ms(v: f64) -> u16 {
    if v.is_nan() || v >= NEVER_MS as f64 / 1000.0 {
        NEVER_MS
    } else {
        (v.max(0.0) * 1000.0).round().min((NEVER_MS - 1) as f64) as u16
    }
}

fn unit(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

const MM_VAR: f64 = 1e-6 / 12.0;
const ANGLE_STEP: f64 = PI / 32768.0;

fn put_i16(b: &mut [u8], at: usize, v: i16) {
    b[at..at + 2].copy_from_slice(&v.to_le_bytes());
}
fn put_u16(b: &mut [u8], at: usize, v: u16) {
    b[at..at + 2].copy_from_slice(&v.to_le_bytes());
}
fn get_i16(b: &[u8], at: usize) -> i16 {
    i16::from_le_bytes([b[at], b[at + 1]])
}
fn get_u16(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

/// One ball observation at `at..at + 11`: x, y (i16 mm), σx, σy (u16 log), ρ (i8), age
/// before the message time `t_s` (u16 ms).
fn put_observation(
    b: &mut [u8],
    at: usize,
    obs: &FieldObservation,
    t_s: f64,
) -> Result<(), EncodeError> {
    put_i16(b, at, mm(obs.position.x, "observation x")?);
    put_i16(b, at + 2, mm(obs.position.y, "observation y")?);
    let (codes, rho) = encode_cov(&obs.cov, &[MM_VAR; 2], SigmaCode::U16(), "observation")?;
    put_u16(b, at + 4, codes[0] as u16);
    put_u16(b, at + 6, codes[1] as u16);
    b[at + 8] = rho[0] as u8;
    let age = t_s - obs.t_s;
    if !age.is_finite() || !(-1e-9..=65.0).contains(&age) {
        return Err(EncodeError::OutOfRange {
            field: "observation age",
        });
    }
    // Rounded to the millisecond; the stamp moves by ≤ 0.5 ms.
    put_u16(b, at + 9, ms(age));
    Ok(())
}

fn get_observation(b: &[u8], at: usize, t_s: f64) -> Result<FieldObservation, DecodeError> {
    let corr = corr_matrix::<2>(&[b[at + 8] as i8]);
    if corr.cholesky().is_none() {
        return Err(DecodeError::NotPositiveDefinite {
            field: "observation",
        });
    }
    Ok(FieldObservation {
        t_s: t_s - get_u16(b, at + 9) as f64 / 1000.0,
        position: Vector2::new(
            get_i16(b, at) as f64 / 1000.0,
            get_i16(b, at + 2) as f64 / 1000.0,
        ),
        cov: decode_cov(
            &[get_u16(b, at + 4) as u32, get_u16(b, at + 6) as u32],
            &corr,
            SigmaCode::U16(),
        ),
    })
}

fn put_kick(b: &mut [u8], report: &KickReport, t_s: f64) -> Result<(), EncodeError> {
    let k = &report.kick;
    let out = |field| EncodeError::OutOfRange { field };
    if !k.is_valid() {
        return Err(out("kick"));
    }
    let age = ((t_s - k.t_s) / KICK_AGE_STEP_S).round();
    if !(0.0..=31.0).contains(&age) {
        return Err(out("kick age"));
    }
    let speed = (k.speed_mps / KICK_SPEED_STEP_MPS).round();
    if speed > 255.0 {
        return Err(out("kick speed"));
    }
    let direction = (k.direction_rad.rem_euclid(2.0 * PI) / KICK_DIRECTION_STEP_RAD).round() as u32;
    // The steps' own variance (Δ²/12) goes into the σ's: never more confident than sent.
    let with_step = |sigma: f64, step: f64| (sigma * sigma + step * step / 12.0).sqrt();
    let code = SigmaCode::U8();
    let sigma = |sigma: f64, field| {
        // Past the scale's top the decoded σ would be smaller than the sent one.
        if sigma > code.decode(code.max_code) {
            return Err(out(field));
        }
        Ok(code.encode_up(sigma) as u8)
    };
    b[KICK_AT + 3] = sigma(
        with_step(k.speed_sigma_mps, KICK_SPEED_STEP_MPS),
        "kick speed σ",
    )?;
    b[KICK_AT + 4] = sigma(
        with_step(k.direction_sigma_rad, KICK_DIRECTION_STEP_RAD),
        "kick direction σ",
    )?;
    b[KICK_AT] = KICK_PRESENT | ((report.number & 3) << 5) | age as u8;
    b[KICK_AT + 1] = speed as u8;
    b[KICK_AT + 2] = (direction % 256) as u8;
    Ok(())
}

fn get_kick(b: &[u8], t_s: f64) -> Option<KickReport> {
    let head = b[KICK_AT];
    if head & KICK_PRESENT == 0 {
        return None;
    }
    let code = SigmaCode::U8();
    Some(KickReport {
        number: (head >> 5) & 3,
        kick: Kick {
            t_s: t_s - (head & 0x1f) as f64 * KICK_AGE_STEP_S,
            speed_mps: b[KICK_AT + 1] as f64 * KICK_SPEED_STEP_MPS,
            direction_rad: crate::geometry::wrap_angle(
                b[KICK_AT + 2] as f64 * KICK_DIRECTION_STEP_RAD,
            ),
            speed_sigma_mps: code.decode(b[KICK_AT + 3] as u32),
            direction_sigma_rad: code.decode(b[KICK_AT + 4] as u32),
        },
    })
}

impl LocalWorldModel {
    /// The 75-byte wire form. Times are sent relative to `self.t_s`.
    pub fn to_bytes(&self) -> Result<[u8; LWM_WIRE_LEN], EncodeError> {
        let mut b = [0u8; LWM_WIRE_LEN];
        let mut flags = 0u8;
        put_u16(&mut b, 1, self.seq);

        let p = &self.pose;
        put_i16(&mut b, 3, mm(p.mean.x, "pose x")?);
        put_i16(&mut b, 5, mm(p.mean.y, "pose y")?);
        if !p.mean.z.is_finite() {
            return Err(EncodeError::OutOfRange {
                field: "pose theta",
            });
        }
        let th = crate::geometry::wrap_angle(p.mean.z) / ANGLE_STEP;
        // π wraps to −π on the wire: same angle.
        put_i16(
            &mut b,
            7,
            (th.round() as i32).clamp(-32768, 32768).rem_euclid(65536) as u16 as i16,
        );
        let (codes, rho) = encode_cov(
            &p.cov,
            &[MM_VAR, MM_VAR, ANGLE_STEP * ANGLE_STEP / 12.0],
            SigmaCode::U8(),
            "pose",
        )?;
        for i in 0..3 {
            b[9 + i] = codes[i] as u8;
            b[12 + i] = rho[i] as u8;
        }

        if let Some(ball) = &self.ball {
            flags |= FLAG_BALL;
            let names = ["ball x", "ball y", "ball vx", "ball vy"];
            for (i, name) in names.iter().enumerate() {
                put_i16(&mut b, 15 + 2 * i, mm(ball.mean[i], name)?);
            }
            let (codes, rho) = encode_cov(&ball.cov, &[MM_VAR; 4], SigmaCode::U8(), "ball")?;
            for i in 0..4 {
                b[23 + i] = codes[i] as u8;
            }
            for (k, r) in rho.iter().enumerate() {
                b[27 + k] = *r as u8;
            }
        } else {
            // An absent ball still has to decode as a valid (unit) block.
        }
        put_u16(&mut b, 33, ms(self.ball_seen_age_s));
        b[35] = unit(self.slc);
        b[36] = unit(self.lbc);

        if let Some(obs) = &self.observation {
            flags |= FLAG_OBSERVATION;
            put_observation(&mut b, OBSERVATION_AT[0], obs, self.t_s)?;
        }
        for (k, earlier) in self.earlier.iter().enumerate() {
            if let Some(obs) = earlier {
                flags |= FLAG_EARLIER[k];
                put_observation(&mut b, OBSERVATION_AT[k + 1], obs, self.t_s)?;
            }
        }
        if let Some(report) = &self.kick {
            put_kick(&mut b, report, self.t_s)?;
        }
        b[0] = (VERSION << 4) | flags;
        Ok(b)
    }

    /// Decodes a received LWM whose snapshot holds at `t_s` on the receiver's clock
    /// (reception time minus the age reported with it). Safe on untrusted bytes.
    pub fn from_bytes(bytes: &[u8], t_s: f64) -> Result<LocalWorldModel, DecodeError> {
        if bytes.len() != LWM_WIRE_LEN {
            return Err(DecodeError::Length {
                expected: LWM_WIRE_LEN,
                got: bytes.len(),
            });
        }
        let b = bytes;
        if b[0] >> 4 != VERSION {
            return Err(DecodeError::Version { got: b[0] >> 4 });
        }
        // Version 3 defines all four flag bits.
        let flags = b[0] & 0x0f;
        let seq = get_u16(b, 1);
        let theta = crate::geometry::wrap_angle(get_i16(b, 7) as f64 * ANGLE_STEP);
        let pose_corr = corr_matrix::<3>(&[b[12] as i8, b[13] as i8, b[14] as i8]);
        if pose_corr.cholesky().is_none() {
            return Err(DecodeError::NotPositiveDefinite { field: "pose" });
        }
        let pose = PoseEstimate {
            mean: Vector3::new(
                get_i16(b, 3) as f64 / 1000.0,
                get_i16(b, 5) as f64 / 1000.0,
                theta,
            ),
            cov: decode_cov(
                &[b[9] as u32, b[10] as u32, b[11] as u32],
                &pose_corr,
                SigmaCode::U8(),
            ),
        };
        let ball = if flags & FLAG_BALL != 0 {
            let rho: [i8; 6] = std::array::from_fn(|k| b[27 + k] as i8);
            let corr = corr_matrix::<4>(&rho);
            if corr.cholesky().is_none() {
                return Err(DecodeError::NotPositiveDefinite { field: "ball" });
            }
            Some(BallEstimate {
                t_s,
                mean: Vector4::from_fn(|i, _| get_i16(b, 15 + 2 * i) as f64 / 1000.0),
                cov: decode_cov(
                    &[b[23] as u32, b[24] as u32, b[25] as u32, b[26] as u32],
                    &corr,
                    SigmaCode::U8(),
                ),
            })
        } else {
            None
        };
        let seen = get_u16(b, 33);
        let observation = if flags & FLAG_OBSERVATION != 0 {
            Some(get_observation(b, OBSERVATION_AT[0], t_s)?)
        } else {
            None
        };
        let mut earlier = [None; 2];
        for (k, slot) in earlier.iter_mut().enumerate() {
            if flags & FLAG_EARLIER[k] != 0 {
                *slot = Some(get_observation(b, OBSERVATION_AT[k + 1], t_s)?);
            }
        }
        Ok(LocalWorldModel {
            t_s,
            seq,
            pose,
            ball,
            ball_seen_age_s: if seen == NEVER_MS {
                f64::INFINITY
            } else {
                seen as f64 / 1000.0
            },
            slc: b[35] as f64 / 255.0,
            lbc: b[36] as f64 / 255.0,
            observation,
            earlier,
            kick: get_kick(b, t_s),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix2, Matrix3, Matrix4};
    use proptest::prelude::*;

    fn covers<const N: usize>(decoded: &SMatrix<f64, N, N>, original: &SMatrix<f64, N, N>) -> bool {
        let diff = decoded - original;
        let scale = original.abs().max().max(1e-12);
        nalgebra::DMatrix::from_iterator(N, N, diff.iter().copied())
            .symmetric_eigenvalues()
            .min()
            >= -1e-9 * scale
    }

    fn sample() -> LocalWorldModel {
        LocalWorldModel {
            t_s: 10.0,
            seq: 513,
            pose: PoseEstimate {
                mean: Vector3::new(1.234, -2.5, 3.0),
                cov: Matrix3::new(
                    0.01, 0.002, 0.001, 0.002, 0.02, -0.001, 0.001, -0.001, 0.005,
                ),
            },
            ball: Some(BallEstimate {
                t_s: 10.0,
                mean: Vector4::new(0.5, 0.25, -1.5, 2.0),
                cov: Matrix4::new(
                    0.004, 0.001, 0.002, 0.0, 0.001, 0.003, 0.0, 0.001, 0.002, 0.0, 0.05, 0.01,
                    0.0, 0.001, 0.01, 0.04,
                ),
            }),
            ball_seen_age_s: 0.033,
            slc: 0.8,
            lbc: 0.9,
            observation: Some(FieldObservation {
                t_s: 9.95,
                position: Vector2::new(0.49, 0.2),
                cov: Matrix2::new(0.002, 0.0005, 0.0005, 0.001),
            }),
            earlier: [
                None,
                Some(FieldObservation {
                    t_s: 9.87,
                    position: Vector2::new(0.47, 0.21),
                    cov: Matrix2::new(0.003, 0.0, 0.0, 0.002),
                }),
            ],
            kick: Some(KickReport {
                number: 2,
                kick: Kick {
                    t_s: 9.96,
                    speed_mps: 4.0,
                    direction_rad: -2.5,
                    speed_sigma_mps: 0.2,
                    direction_sigma_rad: 0.08,
                },
            }),
        }
    }

    #[test]
    fn fixture_round_trips_within_one_quantum_and_never_shrinks_a_covariance() {
        let lwm = sample();
        let bytes = lwm.to_bytes().unwrap();
        assert_eq!(bytes.len(), 75);
        assert_eq!(
            bytes[0], 0x3b,
            "version 3, ball, observation and the seq−2 batch present"
        );
        assert_eq!(
            &bytes[70..73],
            &[0x80 | (2 << 5) | 8, 80, 154],
            "kick: present, number 2, 40 ms old; 4.0 m/s; −2.5 rad = 154 × 2π/256"
        );
        assert_eq!(&bytes[1..3], &[0x01, 0x02], "seq 513 little-endian");
        assert_eq!(&bytes[3..5], &1234i16.to_le_bytes(), "pose x in mm");
        let back = LocalWorldModel::from_bytes(&bytes, 20.0).unwrap();
        assert_eq!(back.seq, 513);
        assert!((back.pose.mean - lwm.pose.mean).abs().max() < 1e-3);
        assert!(
            covers(&back.pose.cov, &lwm.pose.cov),
            "pose {}",
            back.pose.cov
        );
        let (b0, b1) = (lwm.ball.unwrap(), back.ball.unwrap());
        assert_eq!(b1.t_s, 20.0, "times move to the receiver's clock");
        assert!((b1.mean - b0.mean).abs().max() <= 0.0005 + 1e-12);
        assert!(covers(&b1.cov, &b0.cov), "ball {}", b1.cov);
        let (o0, o1) = (lwm.observation.unwrap(), back.observation.unwrap());
        assert!(
            (o1.t_s - 19.95).abs() < 1e-9,
            "observation age kept: {}",
            o1.t_s
        );
        assert!(covers(&o1.cov, &o0.cov));
        assert!(
            o1.cov[(0, 0)] < o0.cov[(0, 0)] * 1.01,
            "the observation σ scale is fine"
        );
        assert!((back.ball_seen_age_s - 0.033).abs() < 1e-9);
        assert_eq!(back.earlier[0], None, "an empty batch stays empty");
        let (e0, e1) = (lwm.earlier[1].unwrap(), back.earlier[1].unwrap());
        assert!((e1.t_s - 19.87).abs() < 1e-9, "repeat keeps its age");
        assert!((e1.position - e0.position).abs().max() < 1e-9);
        assert!(covers(&e1.cov, &e0.cov));
        let (k0, k1) = (lwm.kick.unwrap(), back.kick.unwrap());
        assert_eq!(k1.number, 2);
        assert!(
            (k1.kick.t_s - 19.96).abs() < 1e-9,
            "kick time {}",
            k1.kick.t_s
        );
        assert!((k1.kick.speed_mps - 4.0).abs() < 1e-9);
        assert!(
            crate::geometry::wrap_angle(k1.kick.direction_rad - k0.kick.direction_rad).abs()
                <= PI / 256.0
        );
        assert!(
            k1.kick.speed_sigma_mps >= k0.kick.speed_sigma_mps
                && k1.kick.direction_sigma_rad >= k0.kick.direction_sigma_rad,
            "a kick's σ's never shrink on the wire: {:?}",
            k1.kick
        );
    }

    #[test]
    fn a_kick_that_cannot_be_carried_is_an_error_not_a_wrong_message() {
        let mut lwm = sample();
        let kick = |t_s: f64, speed_mps: f64| {
            Some(KickReport {
                number: 0,
                kick: Kick {
                    t_s,
                    speed_mps,
                    direction_rad: 0.0,
                    speed_sigma_mps: 0.1,
                    direction_sigma_rad: 0.1,
                },
            })
        };
        lwm.kick = kick(9.7, 4.0);
        assert_eq!(
            lwm.to_bytes(),
            Err(EncodeError::OutOfRange { field: "kick age" }),
            "300 ms is older than a report lasts"
        );
        lwm.kick = kick(9.99, 20.0);
        assert_eq!(
            lwm.to_bytes(),
            Err(EncodeError::OutOfRange {
                field: "kick speed"
            })
        );
        lwm.kick = kick(9.99, 4.0).map(|mut r| {
            r.kick.speed_sigma_mps = 500.0;
            r
        });
        assert_eq!(
            lwm.to_bytes(),
            Err(EncodeError::OutOfRange {
                field: "kick speed σ"
            }),
            "past the σ scale's top the receiver would be told less than was sent"
        );
        lwm.kick = kick(f64::NAN, 4.0);
        assert_eq!(
            lwm.to_bytes(),
            Err(EncodeError::OutOfRange { field: "kick" })
        );
        lwm.kick = None;
        let bytes = lwm.to_bytes().unwrap();
        assert_eq!(&bytes[70..], &[0; 5], "no kick: five zero bytes");
        assert_eq!(LocalWorldModel::from_bytes(&bytes, 0.0).unwrap().kick, None);
    }

    #[test]
    fn bad_length_version_and_correlations_are_typed_errors() {
        let bytes = sample().to_bytes().unwrap();
        assert_eq!(
            LocalWorldModel::from_bytes(&bytes[..74], 0.0),
            Err(DecodeError::Length {
                expected: 75,
                got: 74
            })
        );
        let mut v = bytes;
        v[0] = 0x2b;
        assert_eq!(
            LocalWorldModel::from_bytes(&v, 0.0),
            Err(DecodeError::Version { got: 2 }),
            "a version-2 sender's 70 bytes padded: refused, not misread"
        );
        let mut v = bytes;
        v[0] = 0x4b;
        assert_eq!(
            LocalWorldModel::from_bytes(&v, 0.0),
            Err(DecodeError::Version { got: 4 })
        );
        let mut v = bytes;
        v[12..15].copy_from_slice(&[127, 127, 0x81]); // ρxy = 1, ρxθ = 1, ρyθ = −1
        assert_eq!(
            LocalWorldModel::from_bytes(&v, 0.0),
            Err(DecodeError::NotPositiveDefinite { field: "pose" })
        );
    }

    fn spd<const N: usize>(entries: &[f64], scale: f64) -> SMatrix<f64, N, N> {
        let a = SMatrix::<f64, N, N>::from_fn(|i, j| entries[(i * N + j) % entries.len()]);
        (a * a.transpose()) * scale + SMatrix::<f64, N, N>::identity() * 1e-8
    }

    proptest! {
        #[test]
        fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..96)) {
            let _ = LocalWorldModel::from_bytes(&bytes, 1.0);
        }

        #[test]
        fn any_75_bytes_decode_to_finite_pd_covariances_or_an_error(mut bytes in proptest::array::uniform32(any::<u8>()), tail in proptest::array::uniform32(any::<u8>()), end in proptest::array::uniform16(any::<u8>()), flags in 0u8..16) {
            let mut all = [0u8; LWM_WIRE_LEN];
            bytes[0] = 0x30 | flags;
            all[..32].copy_from_slice(&bytes);
            all[32..64].copy_from_slice(&tail);
            all[64..].copy_from_slice(&end[..11]);
            if let Ok(lwm) = LocalWorldModel::from_bytes(&all, 1.0) {
                if let Some(k) = lwm.kick {
                    prop_assert!(k.kick.is_valid() && k.kick.t_s <= 1.0 && k.number < 4, "{:?}", k);
                }
                prop_assert!(lwm.pose.cov.cholesky().is_some());
                if let Some(b) = lwm.ball { prop_assert!(b.cov.cholesky().is_some() && b.mean.iter().all(|v| v.is_finite())); }
                for o in lwm.observation.iter().chain(lwm.earlier.iter().flatten()) { prop_assert!(o.cov.cholesky().is_some()); }
            }
        }

        #[test]
        fn encoding_never_makes_the_receiver_more_confident(
            e in proptest::collection::vec(-1.0f64..1.0, 16),
            scale in 1e-6f64..10.0,
            x in -30.0f64..30.0, y in -30.0f64..30.0, th in -10.0f64..10.0,
            v in -20.0f64..20.0, age in 0.0f64..1.0,
        ) {
            let lwm = LocalWorldModel {
                t_s: 5.0,
                seq: 7,
                pose: PoseEstimate { mean: Vector3::new(x, y, th), cov: spd::<3>(&e, scale) },
                ball: Some(BallEstimate { t_s: 5.0, mean: Vector4::new(y, x, v, -v), cov: spd::<4>(&e[3..], scale) }),
                ball_seen_age_s: age,
                slc: 0.5,
                lbc: 0.5,
                observation: Some(FieldObservation { t_s: 5.0 - age, position: Vector2::new(x, y), cov: spd::<2>(&e[7..], scale) }),
                earlier: [Some(FieldObservation { t_s: 4.9 - age, position: Vector2::new(y, x), cov: spd::<2>(&e[9..], scale) }), None],
                kick: Some(KickReport { number: 1, kick: Kick { t_s: 5.0 - age * 0.15, speed_mps: v.abs() / 2.0, direction_rad: th, speed_sigma_mps: scale.sqrt(), direction_sigma_rad: scale.sqrt() } }),
            };
            let back = LocalWorldModel::from_bytes(&lwm.to_bytes().unwrap(), 5.0).unwrap();
            prop_assert!(covers(&back.pose.cov, &lwm.pose.cov));
            prop_assert!(covers(&back.ball.unwrap().cov, &lwm.ball.unwrap().cov));
            prop_assert!(covers(&back.observation.unwrap().cov, &lwm.observation.unwrap().cov));
            prop_assert!(covers(&back.earlier[0].unwrap().cov, &lwm.earlier[0].unwrap().cov));
            prop_assert!((crate::geometry::wrap_angle(back.pose.mean.z - th)).abs() < 1e-4);
            let (k0, k1) = (lwm.kick.unwrap().kick, back.kick.unwrap().kick);
            prop_assert!(k1.speed_sigma_mps >= k0.speed_sigma_mps.min(100.0) && k1.direction_sigma_rad >= k0.direction_sigma_rad.min(100.0));
            prop_assert!((k1.t_s - k0.t_s).abs() <= 0.0025 + 1e-9);
        }
    }
}
