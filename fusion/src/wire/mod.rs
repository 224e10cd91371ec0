//! The LWM on the wire: 75 bytes, fixed point, little-endian.
//!
//! ```text
//! off  size  field
//!  0    1    version (high nibble, = 4) | flags: bit0 ball present, bit1 observation
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
//! 46    2    observation age before the message time (low 12 bits, ms, ≤ 4.095 s); the
//!            top 4 bits of the message's own batch carry the kick's contact probability
//!            c (p = (c + 1)/16), those of the repeated batches are 0
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
//! (to 144 at most).
//!
//! **The compact form** ([`LocalWorldModel::to_compact_bytes`], [`LWM_COMPACT_LEN`] = 43
//! bytes, version 5) carries no observation batches: bytes 0..37 as above (flag bits 1–3
//! clear), the kick block (70..75 above) at 37..42, and the kick's contact probability
//! in the high nibble of byte 42. It is for sparse messages (a league's message budget),
//! where a receiver takes the sender's ball track rather than its batches (the GWM's
//! `track_after_s`), and it leaves room in a 128-byte frame for the arbitration's cost.
//! [`LocalWorldModel::from_bytes`] reads both forms.
//! The kick's speed and direction steps are added to its σ's (the time step, ≤ 2.5 ms, is
//! not: 1 cm at 4 m/s).
//!
//! A u8 σ code q means `1e-4 · K8^q` (m, rad or m/s) with K8 = 10^(6/255) (5.6 % steps,
//! up to 100); a u16 code means `1e-5 · K16^q` with K16 = 10^(7/65535).
//!
//! **Quantisation never makes a covariance smaller**: the decoded P' satisfies P' ⪰ P, so a
//! receiver is never more confident than the sender (how: the `covariance` module).
//!
//! Decoding ([`crate::LocalWorldModel::from_bytes`]) is safe on untrusted bytes: every
//! code maps to a finite number, and a correlation block that is not positive definite is a
//! [`DecodeError`], never a panic.

mod covariance;

use crate::ball::{BallEstimate, FieldObservation, Kick};
use crate::local::{KickReport, LocalWorldModel};
use crate::pose::PoseEstimate;
use covariance::{corr_matrix, decode_cov, encode_cov, encode_observation_cov, SigmaCode};
use nalgebra::{Vector2, Vector3, Vector4};
use std::f64::consts::PI;
use thiserror::Error;

/// Bytes of an encoded LWM.
pub const LWM_WIRE_LEN: usize = 75;
/// Bytes of an LWM in the compact form (no observation batches).
pub const LWM_COMPACT_LEN: usize = 43;
/// The compact form's version.
const COMPACT_VERSION: u8 = 5;
/// Where the compact form keeps the fixed part, the kick block and the contact nibble.
const COMPACT_FIXED: usize = 37;
const COMPACT_KICK_AT: usize = 37;
const COMPACT_CONTACT_AT: usize = 42;
/// Version 4 added the kick's contact probability (top bits of byte 47).
const VERSION: u8 = 4;
/// Where the contact probability's 4 bits sit: the high byte of the own batch's age.
const CONTACT_AT: usize = OBSERVATION_AT[0] + 10;
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
    /// The message is neither [`LWM_WIRE_LEN`] nor [`LWM_COMPACT_LEN`] bytes long.
    #[error("LWM message is {got} bytes, expected {expected}")]
    Length {
        /// Bytes required.
        expected: usize,
        /// Bytes received.
        got: usize,
    },
    /// A compact message sets bits its form does not have (batch flags, the low nibble
    /// of its contact byte).
    #[error("compact LWM message sets bits its form does not have")]
    Compact,
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
    let (codes, rho) = encode_observation_cov(&obs.cov)?;
    put_u16(b, at + 4, codes[0] as u16);
    put_u16(b, at + 6, codes[1] as u16);
    b[at + 8] = rho as u8;
    let age = t_s - obs.t_s;
    if !age.is_finite() || !(-1e-9..=4.095).contains(&age) {
        return Err(EncodeError::OutOfRange {
            field: "observation age",
        });
    }
    // Rounded to the millisecond; the stamp moves by ≤ 0.5 ms.
    put_u16(b, at + 9, ms(age));
    Ok(())
}

/// When the observation at `at` was made, for a message whose snapshot holds at `t_s`.
fn observation_time(b: &[u8], at: usize, t_s: f64) -> f64 {
    t_s - (get_u16(b, at + 9) & 0x0fff) as f64 / 1000.0
}

fn get_observation(b: &[u8], at: usize, t_s: f64) -> Result<FieldObservation, DecodeError> {
    let corr = corr_matrix::<2>(&[b[at + 8] as i8]);
    if corr.cholesky().is_none() {
        return Err(DecodeError::NotPositiveDefinite {
            field: "observation",
        });
    }
    Ok(FieldObservation {
        t_s: observation_time(b, at, t_s),
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
    let contact = (k.contact_prob * 16.0).round().clamp(1.0, 16.0) as u8 - 1;
    b[CONTACT_AT] |= contact << 4;
    b[KICK_AT + 1] = speed as u8;
    b[KICK_AT + 2] = (direction % 256) as u8;
    Ok(())
}

/// When the kick whose head byte is `head` was swung, for a message whose snapshot holds
/// at `t_s`.
fn kick_time(head: u8, t_s: f64) -> f64 {
    t_s - (head & 0x1f) as f64 * KICK_AGE_STEP_S
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
            t_s: kick_time(head, t_s),
            speed_mps: b[KICK_AT + 1] as f64 * KICK_SPEED_STEP_MPS,
            direction_rad: crate::geometry::wrap_angle(
                b[KICK_AT + 2] as f64 * KICK_DIRECTION_STEP_RAD,
            ),
            speed_sigma_mps: code.decode(b[KICK_AT + 3] as u32),
            direction_sigma_rad: code.decode(b[KICK_AT + 4] as u32),
            contact_prob: f64::from((b[CONTACT_AT] >> 4) + 1) / 16.0,
        },
    })
}

impl LocalWorldModel {
    /// The 75-byte wire form. Times are sent relative to `self.t_s`. Quantising never makes
    /// a covariance smaller: each one decodes to a P' ⪰ P, so a receiver is never more
    /// confident than the sender.
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

    /// The compact wire form (see the module docs): the snapshot and the kick, no
    /// observation batches.
    pub fn to_compact_bytes(&self) -> Result<[u8; LWM_COMPACT_LEN], EncodeError> {
        let bare = LocalWorldModel {
            observation: None,
            earlier: [None; 2],
            ..*self
        };
        let full = bare.to_bytes()?;
        let mut b = [0u8; LWM_COMPACT_LEN];
        b[..COMPACT_FIXED].copy_from_slice(&full[..COMPACT_FIXED]);
        b[0] = (COMPACT_VERSION << 4) | (full[0] & FLAG_BALL);
        b[COMPACT_KICK_AT..COMPACT_KICK_AT + 5].copy_from_slice(&full[KICK_AT..KICK_AT + 5]);
        b[COMPACT_CONTACT_AT] = full[CONTACT_AT] & 0xf0;
        Ok(b)
    }

    /// Decodes a received LWM, in either form, whose snapshot holds at `t_s` on the
    /// receiver's clock (reception time minus the age reported with it). Safe on
    /// untrusted bytes.
    pub fn from_bytes(bytes: &[u8], t_s: f64) -> Result<LocalWorldModel, DecodeError> {
        if bytes.len() == LWM_COMPACT_LEN {
            let c = bytes;
            if c[0] >> 4 != COMPACT_VERSION {
                return Err(DecodeError::Version { got: c[0] >> 4 });
            }
            if c[0] & !FLAG_BALL & 0x0f != 0 || c[COMPACT_CONTACT_AT] & 0x0f != 0 {
                return Err(DecodeError::Compact);
            }
            // Back to the full layout, with no batches, and decoded as one.
            let mut b = [0u8; LWM_WIRE_LEN];
            b[..COMPACT_FIXED].copy_from_slice(&c[..COMPACT_FIXED]);
            b[0] = (VERSION << 4) | (c[0] & FLAG_BALL);
            b[KICK_AT..KICK_AT + 5].copy_from_slice(&c[COMPACT_KICK_AT..COMPACT_KICK_AT + 5]);
            b[CONTACT_AT] = c[COMPACT_CONTACT_AT];
            return Self::from_bytes(&b, t_s);
        }
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

    /// This LWM, decoded from `bytes` by [`Self::from_bytes`] at some time, as decoding
    /// the same bytes at `t_s` gives it, bit for bit, without decoding them again: a
    /// second reader of one message (the simulator's delivery reference, beside the
    /// robot's own GWM) places it at another time. Only the times change, and they are
    /// read from the bytes again rather than shifted (`t + (b − a)` is not `b − age` in
    /// floating point). `None` if `bytes` are not an LWM or do not carry the batches
    /// this one holds; if this LWM was not decoded from `bytes`, the answer is not theirs
    /// either.
    pub fn retimed(&self, bytes: &[u8], t_s: f64) -> Option<LocalWorldModel> {
        let (kick_head, batches) = match bytes.len() {
            LWM_WIRE_LEN => (bytes[KICK_AT], Some(bytes)),
            // The compact form carries no batches.
            LWM_COMPACT_LEN => (bytes[COMPACT_KICK_AT], None),
            _ => return None,
        };
        let mut l = *self;
        l.t_s = t_s;
        if let Some(ball) = &mut l.ball {
            ball.t_s = t_s;
        }
        let slots = std::iter::once(&mut l.observation).chain(l.earlier.iter_mut());
        for (slot, at) in slots.zip(OBSERVATION_AT) {
            if let Some(obs) = slot {
                obs.t_s = observation_time(batches?, at, t_s);
            }
        }
        if let Some(report) = &mut l.kick {
            report.kick.t_s = kick_time(kick_head, t_s);
        }
        Some(l)
    }
}

#[cfg(test)]
mod tests;
