//! `RoboCupGameControlReturnData` ("RGrt", version 4): each robot's status, unicast to the
//! GameController's address on UDP port 3939 at 0.5–2 Hz. The GC shows a player as
//! connected when it heard one within 2 s.
//!
//! Layout (32 bytes, little-endian): header "RGrt", version (4), playerNum, teamNum,
//! fallen (0/1), pose[3] (f32: x mm, y mm, θ rad, field frame, +x towards the goal the
//! team attacks), ballAge (f32 s, -1 if never seen), ball[2] (f32 mm, relative to the
//! robot). GameController3 rejects a NaN in any float, a player number outside 1–20 and
//! a `fallen` other than 0 or 1; [`StatusMessage::encode`] never produces one of those.

use crate::DecodeError;

/// UDP port the robots send their status to.
pub const GAMECONTROLLER_RETURN_PORT: u16 = 3939;
/// The packet's first four bytes.
pub const GAMECONTROLLER_RETURN_STRUCT_HEADER: [u8; 4] = *b"RGrt";
/// The version this crate reads and writes.
pub const GAMECONTROLLER_RETURN_STRUCT_VERSION: u8 = 4;
/// The packet's exact length, bytes.
pub const GAMECONTROLLER_RETURN_STRUCT_SIZE: usize = 32;

/// One robot's status (`RoboCupGameControlReturnData`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StatusMessage {
    /// Player number, 1–20.
    pub player_num: u8,
    /// Team number.
    pub team_num: u8,
    /// Whether the robot is fallen.
    pub fallen: bool,
    /// x mm, y mm, θ rad in the field frame.
    pub pose: [f32; 3],
    /// Seconds since the robot last saw the ball, -1 if it has not.
    pub ball_age: f32,
    /// The ball relative to the robot, mm (x forward, y left).
    pub ball: [f32; 2],
}

impl StatusMessage {
    /// A status with an unknown pose (0, 0, 0) and no ball seen.
    pub fn new(player_num: u8, team_num: u8) -> StatusMessage {
        StatusMessage {
            player_num,
            team_num,
            fallen: false,
            pose: [0.0; 3],
            ball_age: -1.0,
            ball: [0.0; 2],
        }
    }

    /// The packet's 32 bytes. A NaN float goes as 0 (a ball age as -1, unknown) and an
    /// infinite one as the largest finite value of its sign, so that the GC never drops
    /// the packet.
    pub fn encode(&self) -> [u8; GAMECONTROLLER_RETURN_STRUCT_SIZE] {
        fn clean(v: f32, nan: f32) -> f32 {
            if v.is_nan() {
                nan
            } else {
                v.clamp(f32::MIN, f32::MAX)
            }
        }
        let mut b = [0u8; GAMECONTROLLER_RETURN_STRUCT_SIZE];
        b[0..4].copy_from_slice(&GAMECONTROLLER_RETURN_STRUCT_HEADER);
        b[4] = GAMECONTROLLER_RETURN_STRUCT_VERSION;
        b[5] = self.player_num;
        b[6] = self.team_num;
        b[7] = u8::from(self.fallen);
        let floats = [
            clean(self.pose[0], 0.0),
            clean(self.pose[1], 0.0),
            clean(self.pose[2], 0.0),
            clean(self.ball_age, -1.0),
            clean(self.ball[0], 0.0),
            clean(self.ball[1], 0.0),
        ];
        for (i, f) in floats.iter().enumerate() {
            b[8 + 4 * i..12 + 4 * i].copy_from_slice(&f.to_le_bytes());
        }
        b
    }

    /// Reads an untrusted datagram with GameController3's checks (a simulated GC, a test).
    pub fn decode(bytes: &[u8]) -> Result<StatusMessage, DecodeError> {
        if bytes.len() >= 4 && bytes[0..4] != GAMECONTROLLER_RETURN_STRUCT_HEADER {
            return Err(DecodeError::BadHeader);
        }
        if bytes.len() >= 5 && bytes[4] != GAMECONTROLLER_RETURN_STRUCT_VERSION {
            return Err(DecodeError::WrongVersion(bytes[4]));
        }
        let b: &[u8; GAMECONTROLLER_RETURN_STRUCT_SIZE] =
            bytes.try_into().map_err(|_| DecodeError::Length {
                len: bytes.len(),
                expected: GAMECONTROLLER_RETURN_STRUCT_SIZE,
            })?;
        if !(1..=20).contains(&b[5]) {
            return Err(DecodeError::BadField {
                field: "playerNum",
                value: b[5],
            });
        }
        let fallen = match b[7] {
            0 => false,
            1 => true,
            v => {
                return Err(DecodeError::BadField {
                    field: "fallen",
                    value: v,
                })
            }
        };
        let f = |i: usize| {
            f32::from_le_bytes([b[8 + 4 * i], b[9 + 4 * i], b[10 + 4 * i], b[11 + 4 * i]])
        };
        let floats = [f(0), f(1), f(2), f(3), f(4), f(5)];
        if floats.iter().any(|v| v.is_nan()) {
            return Err(DecodeError::NotANumber);
        }
        Ok(StatusMessage {
            player_num: b[5],
            team_num: b[6],
            fallen,
            pose: [floats[0], floats[1], floats[2]],
            ball_age: floats[3],
            ball: [floats[4], floats[5]],
        })
    }
}

/// A robot's estimates in the field frame, metres, and what [`StatusMessage`] makes of
/// them: the ball relative to the robot in millimetres.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StatusInputs {
    /// `[x_m, y_m, theta_rad]` in the field frame, if the robot knows its pose.
    pub pose: Option<[f64; 3]>,
    /// `[x_m, y_m]` of the ball in the field frame, and its age in seconds, if known.
    pub ball: Option<([f64; 2], f64)>,
    /// Whether the robot is fallen.
    pub fallen: bool,
}

impl StatusInputs {
    /// The status message for player `player_num` of `team_num`. Without a pose the ball
    /// cannot be made relative: it goes as unknown (age -1). Non-finite inputs count as
    /// unknown: the message never carries NaN.
    pub fn to_message(&self, player_num: u8, team_num: u8) -> StatusMessage {
        let mut m = StatusMessage::new(player_num, team_num);
        m.fallen = self.fallen;
        let pose = self.pose.filter(|p| p.iter().all(|v| v.is_finite()));
        if let Some([x, y, th]) = pose {
            m.pose = [(x * 1000.0) as f32, (y * 1000.0) as f32, th as f32];
            let ball = self
                .ball
                .filter(|([bx, by], age)| bx.is_finite() && by.is_finite() && age.is_finite());
            if let Some(([bx, by], age)) = ball {
                let (dx, dy) = (bx - x, by - y);
                let (s, c) = th.sin_cos();
                m.ball = [
                    ((c * dx + s * dy) * 1000.0) as f32,
                    ((-s * dx + c * dy) * 1000.0) as f32,
                ];
                m.ball_age = age.max(0.0) as f32;
            }
        }
        m
    }
}
