//! The kick scenario the kick-report tests share: robots publish at 25 Hz with a
//! sighting per message; the ball rests at the origin until a robot 0.2 m behind it,
//! facing it, kicks it along +x at 4 m/s at t = 1 s. No friction, so the truth is
//! x = 4 (t − 1).

#![allow(dead_code)]

use fusion::nalgebra::{Matrix2, Vector2, Vector3};
use fusion::{
    BallFilterConfig, BallModel, BallSighting, Kick, LocalConfig, LocalModel, PoseEstimate,
};

pub const PERIOD_S: f64 = 0.04;
pub const KICK_T_S: f64 = 1.0;
pub const SPEED_MPS: f64 = 4.0;

pub fn model() -> BallModel {
    BallModel::Rolling {
        friction_per_s: 0.0,
        accel_noise_m2_per_s3: 0.05,
    }
}

pub fn truth_x(t_s: f64) -> f64 {
    SPEED_MPS * (t_s - KICK_T_S).max(0.0)
}

/// The kick, as the kicker reports it.
pub fn kick() -> Kick {
    Kick {
        t_s: KICK_T_S,
        speed_mps: SPEED_MPS,
        direction_rad: 0.0,
        speed_sigma_mps: 0.2,
        direction_sigma_rad: 0.08,
        contact_prob: 1.0,
    }
}

/// The LWM of a robot `behind_m` behind the ball's line, facing +y, told its pose.
pub fn local_model(behind_m: f64) -> LocalModel {
    let start = PoseEstimate::new(0.0, -behind_m, 0.0, Vector3::new(1e-4, 1e-4, 1e-5));
    let config = LocalConfig {
        ball: BallFilterConfig {
            model: model(),
            ..BallFilterConfig::default()
        },
        ..LocalConfig::default()
    };
    LocalModel::new(config, start)
}

/// A robot `behind_m` behind the ball at (x, 0), facing +y: it sees it at (x, behind).
pub fn sighting(x: f64, behind_m: f64) -> BallSighting {
    BallSighting {
        local: Vector2::new(x, behind_m),
        cov: Matrix2::identity() * 4e-4,
    }
}
