//! A teammate's LWM as received off the network: arbitrary bytes into the decoder and the
//! GWM. Must never panic; whatever decodes has finite numbers and positive-definite
//! covariances, re-encodes without panicking, and leaves the team ball finite.
#![no_main]

use fusion::{GlobalConfig, GlobalModel, LocalWorldModel};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut gwm = GlobalModel::new(2, GlobalConfig::default());
    // The same bytes as several messages in a row, 40 ms apart: the second and later
    // ones are duplicates or (with the sequence number bumped) news.
    for k in 0..3u16 {
        let now_s = 1.0 + 0.04 * f64::from(k);
        let mut bytes = data.to_vec();
        if bytes.len() >= 3 {
            let seq = u16::from_le_bytes([bytes[1], bytes[2]]).wrapping_add(k);
            bytes[1..3].copy_from_slice(&seq.to_le_bytes());
        }
        let Ok(lwm) = LocalWorldModel::from_bytes(&bytes, now_s) else {
            return;
        };
        assert!(lwm.pose.cov.cholesky().is_some(), "pose covariance");
        if let Some(ball) = &lwm.ball {
            assert!(ball.mean.iter().all(|v| v.is_finite()));
            assert!(ball.cov.cholesky().is_some(), "ball covariance");
        }
        let _ = lwm.to_bytes();
        let _ = gwm.receive(1, &bytes, now_s, 0.01);
        if let Some(team) = gwm.team_ball(now_s + 0.1, None) {
            assert!(
                team.estimate.mean.iter().all(|v| v.is_finite()),
                "team ball {:?}",
                team.estimate
            );
        }
    }
});
