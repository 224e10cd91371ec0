//! The pose EKF on simulated walks: it recovers from a bad start, and its covariance is honest.

mod scenario;

use fusion::nalgebra::Vector3;
use fusion::wrap_angle;
use scenario::{nees3, nees_bounds, walk_pose};

#[test]
fn a_pose_started_one_metre_and_half_a_radian_off_converges() {
    for seed in 0..10 {
        // The filter starts 1 m (0.6, −0.8) and 0.5 rad away from the truth.
        let offset = Vector3::new(0.6, -0.8, 0.5);
        let track = walk_pose(seed, Some(offset), Vector3::new(1.0, 1.0, 0.25), 15.0);
        let (_, truth, est) = track.last().unwrap();
        let pos_err = (truth.xy() - est.mean.xy()).norm();
        let th_err = wrap_angle(truth.z - est.mean.z).abs();
        assert!(
            pos_err < 0.1 && th_err < 0.05,
            "seed {seed}: still {pos_err:.3} m, {th_err:.3} rad off after 15 s"
        );
        // And it got there within the first 5 s of landmark sightings.
        let (_, t5, e5) = track.iter().find(|(t, _, _)| *t >= 5.0).unwrap();
        assert!(
            (t5.xy() - e5.mean.xy()).norm() < 0.2,
            "seed {seed}: slow to converge"
        );
    }
}

#[test]
fn pose_nees_over_fifty_walks_is_inside_the_95_percent_bounds() {
    let runs = 50;
    let mut total = 0.0;
    let mut n = 0usize;
    for seed in 0..runs {
        // A consistent start: the initial error is drawn from the P0 the filter is given.
        let track = walk_pose(1000 + seed, None, Vector3::new(0.01, 0.01, 0.003), 20.0);
        for (_, truth, est) in track.iter().filter(|(t, _, _)| *t >= 2.0) {
            total += nees3(est, truth);
            n += 1;
        }
    }
    let anees = total / n as f64;
    let (lo, hi) = nees_bounds(3, runs);
    eprintln!("pose ANEES over {runs} walks: {anees:.3} (95 % bounds [{lo:.3}, {hi:.3}])");
    assert!(
        (lo..=hi).contains(&anees),
        "pose ANEES {anees:.3} outside [{lo:.3}, {hi:.3}] over {runs} walks"
    );
}
