//! The ball EKF's unit tests: the motion model, sightings, the update, kicks and the
//! references.

use super::*;
use crate::kalman;
use crate::pose::PoseEstimate;
use nalgebra::{Matrix2, Matrix3, Matrix4, Vector2, Vector3, Vector4};

#[test]
fn transition_matches_the_continuous_model() {
    let model = BallModel::Rolling {
        friction_per_s: 0.8,
        accel_noise_m2_per_s3: 0.3,
    };
    // Composition: two half steps equal one step (F and Q alike), on both sides of the
    // series switch-over.
    for dt in [1e-4, 3e-3, 0.1, 1.7] {
        let (f1, q1) = model.transition(dt);
        let (fh, qh) = model.transition(dt / 2.0);
        let f2 = fh * fh;
        let q2 = fh * qh * fh.transpose() + qh;
        assert!((f1 - f2).abs().max() < 1e-12, "F at dt {dt}");
        assert!(
            (q1 - q2).abs().max() < 1e-12 * (1.0 + q1.abs().max()),
            "Q at dt {dt}"
        );
    }
    // A ball at 2 m/s with c = 0.8 stops 2.5 m further on.
    let est = BallEstimate {
        t_s: 0.0,
        mean: Vector4::new(0.0, 0.0, 2.0, 0.0),
        cov: Matrix4::zeros(),
    };
    let far = est.predict_to(&model, 100.0);
    assert!(
        (far.mean.x - 2.5).abs() < 1e-9 && far.mean.z.abs() < 1e-9,
        "{}",
        far.mean
    );
}

#[test]
fn the_friction_model_rolls_like_the_field_and_its_jacobian_is_the_derivative() {
    // The field's ball: 0.5/s drag, 0.6 m/s² rolling friction, integrated in 1 ms steps.
    let model = BallModel::Friction {
        drag_per_s: 0.5,
        rolling_decel_mps2: 0.6,
        accel_noise_m2_per_s3: 0.0,
    };
    let x = Vector4::new(0.0, 0.0, 2.4, 3.2);
    let (mut p, mut v) = (Vector2::<f64>::zeros(), Vector2::new(2.4_f64, 3.2));
    for _ in 0..500 {
        let s = v.norm();
        let slowed = (s * (1.0 - 0.5e-3) - 0.6e-3).max(0.0);
        v = if s > 0.0 { v * (slowed / s) } else { v };
        p += v * 1e-3;
    }
    let (m, _, _) = model.propagate(&x, 0.0, 0.5);
    assert!((m.xy() - p).norm() < 5e-3, "rolled to {m} vs field {p}");
    assert!((Vector2::new(m.z, m.w) - v).norm() < 5e-3);
    // A ball at 0.2 m/s stops within 0.5 s and stays stopped.
    let (m, _, _) = model.propagate(&Vector4::new(1.0, 1.0, 0.2, 0.0), 0.0, 2.0);
    assert!(m.z == 0.0 && m.w == 0.0 && m.x > 1.0 && m.x < 1.04, "{m}");
    // With no velocity uncertainty P is linearised at the mean: F is ∂f/∂x.
    for dt in [0.03, 0.1, 5.0] {
        let (_, f, _) = model.propagate(&x, 0.0, dt);
        for j in 0..4 {
            let h = 1e-6;
            let (mut up, mut dn) = (x, x);
            up[j] += h;
            dn[j] -= h;
            let col =
                (model.propagate(&up, 0.0, dt).0 - model.propagate(&dn, 0.0, dt).0) / (2.0 * h);
            assert!(
                (col - f.column(j)).abs().max() < 1e-6,
                "dt {dt}, column {j}: {col} vs {}",
                f.column(j)
            );
        }
    }
    // At rest with a wide velocity variance (a fresh track) the variance survives.
    let (_, f, _) = model.propagate(&Vector4::zeros(), 4.0, 0.03);
    assert!(f[(2, 2)] > 0.9 && f[(3, 3)] > 0.9, "{f}");
}

#[test]
fn frictionless_noise_is_the_textbook_white_acceleration_q() {
    let model = BallModel::Rolling {
        friction_per_s: 0.0,
        accel_noise_m2_per_s3: 2.0,
    };
    let (_, q) = model.transition(0.5);
    assert!((q[(0, 0)] - 2.0 * 0.125 / 3.0).abs() < 1e-15);
    assert!((q[(0, 2)] - 2.0 * 0.25 / 2.0).abs() < 1e-15);
    assert!((q[(2, 2)] - 1.0).abs() < 1e-15);
}

#[test]
fn pose_uncertainty_widens_the_observation_across_the_line_of_sight() {
    // Facing +y, the ball 3 m ahead; a heading σ of 0.1 rad adds (0.3 m)² sideways (x).
    let mut pose = PoseEstimate::new(0.0, 0.0, 0.0, Vector3::new(0.0, 0.0, 0.01));
    let s = BallSighting {
        local: Vector2::new(0.0, 3.0),
        cov: Matrix2::identity() * 1e-4,
    };
    let obs = field_observation(1.0, &pose, &s);
    assert!((obs.position - Vector2::new(0.0, 3.0)).norm() < 1e-12);
    assert!(
        (obs.cov[(0, 0)] - (1e-4 + 0.09)).abs() < 1e-9,
        "{}",
        obs.cov
    );
    assert!((obs.cov[(1, 1)] - 1e-4).abs() < 1e-9);
    pose.cov = Matrix3::zeros();
    assert!((field_observation(1.0, &pose, &s).cov - Matrix2::identity() * 1e-4).norm() < 1e-12);
}

#[test]
fn the_block_update_is_the_general_joseph_update() {
    let model = BallModel::default();
    let est = BallEstimate {
        t_s: 1.0,
        mean: Vector4::new(0.5, -0.2, 1.0, 0.3),
        cov: Matrix4::new(
            0.04, 0.01, 0.02, 0.0, 0.01, 0.03, 0.0, 0.01, 0.02, 0.0, 0.5, 0.1, 0.0, 0.01, 0.1, 0.4,
        ),
    };
    let obs = FieldObservation {
        t_s: 1.0,
        position: Vector2::new(0.6, -0.1),
        cov: Matrix2::new(0.01, 0.002, 0.002, 0.02),
    };
    let (fast, d2) = update(&model, &est, &obs, None).unwrap();
    let h = nalgebra::Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0);
    let general = kalman::update(
        &est.mean,
        &est.cov,
        &(obs.position - est.position()),
        &h,
        &obs.cov,
        None,
    )
    .unwrap();
    assert!((fast.mean - general.mean).abs().max() < 1e-12);
    assert!((fast.cov - general.cov).abs().max() < 1e-12);
    assert!((d2 - general.mahalanobis_sq).abs() < 1e-12);
}

#[test]
fn a_kick_restarts_the_track_after_two_outliers() {
    let mut f = BallFilter::new(BallFilterConfig::default());
    let r = Matrix2::identity() * 1e-3;
    for k in 0..30 {
        let obs = FieldObservation {
            t_s: k as f64 * 0.03,
            position: Vector2::new(1.0, 1.0),
            cov: r,
        };
        f.observe(&obs);
    }
    let away = |t: f64| FieldObservation {
        t_s: t,
        position: Vector2::new(2.5, 1.0),
        cov: r,
    };
    assert!(matches!(f.observe(&away(0.93)), BallUpdate::Outlier(_)));
    assert_eq!(f.observe(&away(0.96)), BallUpdate::Restarted);
    assert!((f.estimate().unwrap().position() - Vector2::new(2.5, 1.0)).norm() < 1e-12);
}

/// A filter that mixes several robots' sightings (the simulator's references): one
/// robot's stray sighting and then another's false ball, metres apart, are two outliers in
/// a row; restarting on them put the track on the false ball (#29, drawn world, seed 110:
/// 6.7 m off). With `outliers_must_agree` the run restarts with each outlier that
/// disagrees with the one before, and the track moves only on two that agree.
#[test]
fn outliers_that_disagree_do_not_restart_a_mixed_track() {
    let r = Matrix2::identity() * 1e-3;
    let at = |t: f64, x: f64, y: f64| FieldObservation {
        t_s: t,
        position: Vector2::new(x, y),
        cov: r,
    };
    let settled = |agree: bool| {
        let mut f = BallFilter::new(BallFilterConfig {
            outliers_must_agree: agree,
            ..BallFilterConfig::default()
        });
        for k in 0..30 {
            f.observe(&at(k as f64 * 0.03, 1.0, 1.0));
        }
        f
    };
    let (stray, false_ball) = (at(0.93, 1.5, 1.0), at(0.94, -3.0, -2.0));
    let mut plain = settled(false);
    plain.observe(&stray);
    assert_eq!(
        plain.observe(&false_ball),
        BallUpdate::Restarted,
        "the old rule"
    );
    let mut mixed = settled(true);
    assert!(matches!(mixed.observe(&stray), BallUpdate::Outlier(_)));
    assert!(matches!(mixed.observe(&false_ball), BallUpdate::Outlier(_)));
    let p = mixed.estimate().unwrap().position();
    assert!(
        (p - Vector2::new(1.0, 1.0)).norm() < 1e-6,
        "kept the ball: {p}"
    );
    // A kick: two sightings that agree with each other restart it where the ball went.
    assert!(matches!(
        mixed.observe(&at(0.96, 2.5, 1.0)),
        BallUpdate::Outlier(_)
    ));
    assert_eq!(mixed.observe(&at(0.99, 2.52, 1.0)), BallUpdate::Restarted);
}

#[test]
fn the_network_limited_reference_is_the_centralized_filter_fed_out_of_order() {
    // A ball rolling along x, seen by robot A every 40 ms and by robot B every 40 ms
    // (offset 20 ms). B's observations reach the reference 100 ms late, A's at once:
    // once everything has arrived it must equal the centralized filter fed in time
    // order.
    let cfg = BallFilterConfig::default();
    let obs = |t: f64| FieldObservation {
        t_s: t,
        position: Vector2::new(1.0 + 0.8 * t + 0.01 * (7.0 * t).sin(), 0.5),
        cov: Matrix2::identity() * 4e-4,
    };
    let times: Vec<f64> = (0..50).map(|k| k as f64 * 0.02).collect();
    let mut central = CentralizedBall::new(cfg);
    for &t in &times {
        central.filter.observe(&obs(t));
    }
    let mut reference = NetworkLimitedBall::new(cfg, 0.3);
    let mut late_b: Vec<f64> = Vec::new();
    for (k, &t) in times.iter().enumerate() {
        if k % 2 == 0 {
            assert!(reference.observe(&obs(t)), "A's own sighting at {t}");
        } else {
            late_b.push(t);
        }
        // B's observations from 100 ms ago arrive now.
        while late_b.first().is_some_and(|&tb| tb <= t - 0.1 + 1e-9) {
            assert!(
                reference.observe(&obs(late_b.remove(0))),
                "B's, 100 ms late"
            );
        }
        reference.settle(t);
    }
    for tb in late_b {
        assert!(reference.observe(&obs(tb)));
    }
    let (a, b) = (
        reference.estimate_at(1.2).unwrap(),
        central.estimate_at(1.2).unwrap(),
    );
    assert!(
        (a.mean - b.mean).norm() < 1e-9 && (a.cov - b.cov).norm() < 1e-9,
        "reference {} vs centralized {}",
        a.mean,
        b.mean
    );
    // Something older than the window can no longer be placed: refused and counted.
    assert!(!reference.observe(&obs(0.1)), "0.1 s is settled by now");
    assert_eq!(reference.late(), 1);
}

#[test]
fn a_teammate_track_is_a_measurement_of_the_whole_state() {
    // Robot A saw the ball at (1, 0.5) standing still; a teammate's compact message says
    // it is rolling at 1 m/s along x from (1.02, 0.5), well measured: the reference takes
    // the velocity from the track and the position from both.
    let cfg = BallFilterConfig::default();
    let mut reference = NetworkLimitedBall::new(cfg, 0.3);
    let seen = FieldObservation {
        t_s: 1.0,
        position: Vector2::new(1.0, 0.5),
        cov: Matrix2::identity() * 4e-4,
    };
    assert!(reference.observe(&seen));
    let gain = crate::TrackGain {
        t_s: 1.0,
        mean: Vector4::new(1.02, 0.5, 1.0, 0.0),
        cov: Matrix4::from_diagonal(&Vector4::new(4e-4, 4e-4, 1e-3, 1e-3)),
    };
    assert!(reference.track(&gain));
    let b = reference.estimate_at(1.0).expect("a ball");
    assert!(
        (b.position().x - 1.01).abs() < 0.005 && b.velocity().x > 0.9,
        "the sighting and the track fused: {}",
        b.mean
    );
    // A track far from the ball fails the gate and leaves it where it was.
    let far = crate::TrackGain {
        t_s: 1.01,
        mean: Vector4::new(4.0, -2.0, 0.0, 0.0),
        ..gain
    };
    assert!(reference.track(&far));
    let c = reference.estimate_at(1.01).expect("a ball");
    assert!(
        (c.position() - b.predict_to(&cfg.model, 1.01).position()).norm() < 1e-9,
        "an outlying track is not fused: {}",
        c.mean
    );
}

#[test]
fn a_kick_sets_the_velocity_and_keeps_the_position() {
    let model = BallModel::Rolling {
        friction_per_s: 1.0,
        accel_noise_m2_per_s3: 1.0,
    };
    let resting = BallEstimate {
        t_s: 2.0,
        mean: Vector4::new(1.0, -0.5, 0.1, 0.0),
        cov: Matrix4::from_diagonal(&Vector4::new(1e-3, 2e-3, 0.5, 0.5)),
    };
    // Straight up the field (+y) at 4 m/s: the speed σ lies along y, the direction σ
    // across it, scaled by the speed.
    let kick = Kick {
        t_s: 2.1,
        speed_mps: 4.0,
        direction_rad: std::f64::consts::FRAC_PI_2,
        speed_sigma_mps: 0.2,
        direction_sigma_rad: 0.08,
        contact_prob: 1.0,
    };
    let kicked = resting.kicked(&model, &kick);
    let before = resting.predict_to(&model, 2.1);
    assert_eq!(kicked.t_s, 2.1, "the kick happens at its own time");
    assert!((kicked.position() - before.position()).norm() < 1e-12);
    assert!((kicked.position_cov() - before.position_cov()).norm() < 1e-12);
    assert!((kicked.velocity() - Vector2::new(0.0, 4.0)).norm() < 1e-12);
    let v_cov = kicked.cov.fixed_view::<2, 2>(2, 2).into_owned();
    assert!(
        (v_cov[(0, 0)] - (4.0f64 * 0.08).powi(2)).abs() < 1e-12,
        "across: {v_cov}"
    );
    assert!((v_cov[(1, 1)] - 0.04).abs() < 1e-12, "along: {v_cov}");
    assert_eq!(
        kicked.cov.fixed_view::<2, 2>(0, 2).into_owned(),
        Matrix2::zeros(),
        "the foot's velocity owes nothing to where the ball was"
    );
    let still = BallModel::Static {
        drift_m2_per_s: 0.01,
    };
    assert_eq!(
        resting.kicked(&still, &kick).mean,
        resting.predict_to(&still, 2.1).mean,
        "a static model has no velocity to kick"
    );

    // A kick the kicker gives even odds: the mixture of kicked and untouched.
    let unsure = Kick {
        contact_prob: 0.5,
        ..kick
    };
    let mixed = resting.kicked(&model, &unsure);
    let expect_v = (Vector2::new(0.0, 4.0) + before.velocity()) * 0.5;
    assert!(
        (mixed.velocity() - expect_v).norm() < 1e-12,
        "halfway between the foot's and the ball's own velocity"
    );
    let d = Vector2::new(0.0, 4.0) - before.velocity();
    let mixed_vv = mixed.cov.fixed_view::<2, 2>(2, 2).into_owned();
    let expect_vv = (v_cov + before.cov.fixed_view::<2, 2>(2, 2)) * 0.5 + d * d.transpose() * 0.25;
    assert!(
        (mixed_vv - expect_vv).norm() < 1e-12,
        "the spread between the two outcomes is in the covariance: {mixed_vv}"
    );
    assert!(
        mixed.cov.cholesky().is_some(),
        "a mixture's covariance is positive definite"
    );
    assert!(
        (mixed.position_cov() - before.position_cov()).norm() < 1e-12,
        "a kick moves no ball at its instant"
    );
}

/// The field's ball as `huddle sim` rolls it (drag, rolling deceleration, boards with
/// restitution), integrated in 1 ms steps: what the field model is checked against.
fn roll_on_the_field(x: Vector4<f64>, boards: &Boards, seconds: f64) -> Vector4<f64> {
    let (mut p, mut v) = (Vector2::new(x.x, x.y), Vector2::new(x.z, x.w));
    let dt = 1e-3;
    for _ in 0..(seconds / dt).round() as usize {
        let s = v.norm();
        let slowed = (s * (1.0 - 0.5 * dt) - 0.6 * dt).max(0.0);
        v = if s > 0.0 { v * (slowed / s) } else { v };
        p += v * dt;
        for (a, half) in [(0, boards.half_x_m), (1, boards.half_y_m)] {
            if p[a].abs() > half {
                p[a] = half.copysign(p[a]);
                v[a] = -v[a] * boards.restitution;
            }
        }
    }
    Vector4::new(p.x, p.y, v.x, v.y)
}

fn field_model(boards: Option<Boards>) -> BallModel {
    BallModel::Field(FieldBall {
        drag_per_s: 0.5,
        rolling_decel_mps2: 0.6,
        still_accel_noise_m2_per_s3: 0.05,
        accel_noise_per_speed: 5.0,
        still_below_mps: 0.0,
        boards,
    })
}

#[test]
fn a_ball_rolling_into_the_boards_bounces_back_as_the_field_does() {
    // The default field: 9 × 6 m, 0.5 m of carpet beyond the lines, a 5 cm ball, e = 0.5.
    let boards = Boards::around(9.0, 6.0, 0.5, 0.05, 0.5, 0.1);
    assert!((boards.half_x_m - 4.95).abs() < 1e-12 && (boards.half_y_m - 3.45).abs() < 1e-12);
    let model = field_model(Some(boards));
    // 3 m/s towards the +x board from 0.5 m before it, and one into a corner.
    for x in [
        Vector4::new(4.45, 0.3, 3.0, 0.4),
        Vector4::new(4.6, 3.1, 2.0, 2.0),
    ] {
        for dt in [0.1, 0.3, 1.0, 4.0] {
            let (m, _, _) = model.propagate(&x, 0.0, dt);
            let field = roll_on_the_field(x, &boards, dt);
            assert!(
                (m - field).norm() < 0.02,
                "from {x} over {dt} s: model {m} vs field {field}"
            );
            assert!(m.x.abs() <= boards.half_x_m + 1e-9 && m.y.abs() <= boards.half_y_m + 1e-9);
        }
    }
    // Without boards the same prediction goes through the board.
    let (m, _, _) = field_model(None).propagate(&Vector4::new(4.45, 0.3, 3.0, 0.4), 0.0, 1.0);
    assert!(m.x > boards.half_x_m, "no boards, no bounce: {m}");
}

#[test]
fn a_bounce_reflects_the_gaussian_and_its_jacobian_is_the_derivative() {
    let boards = Boards::around(9.0, 6.0, 0.5, 0.05, 0.5, 0.0);
    let model = field_model(Some(boards));
    let x = Vector4::new(4.6, 0.2, 2.5, 0.5);
    let dt = 0.4;
    let (m, f, _) = model.propagate(&x, 0.0, dt);
    assert!(m.z < 0.0, "it came back: {m}");
    // F across the bounce is ∂f/∂x (the saltation matrix makes it so): a ball further
    // along x hit the board earlier and is now e times as much short of the mean.
    for j in 0..4 {
        let h = 1e-6;
        let (mut up, mut dn) = (x, x);
        up[j] += h;
        dn[j] -= h;
        let col = (model.propagate(&up, 0.0, dt).0 - model.propagate(&dn, 0.0, dt).0) / (2.0 * h);
        assert!(
            (col - f.column(j)).abs().max() < 1e-3 * (1.0 + col.abs().max()),
            "column {j}: {col} vs {}",
            f.column(j)
        );
    }
    assert!(
        f[(0, 0)] < 0.0 && f[(2, 2)] < 0.0,
        "x and vx turn over: {f}"
    );
    // The restitution's σ widens the normal velocity, not the tangential one.
    let unsure = field_model(Some(Boards {
        restitution_sigma: 0.1,
        ..boards
    }));
    let est = BallEstimate {
        t_s: 0.0,
        mean: x,
        cov: Matrix4::from_diagonal(&Vector4::new(1e-4, 1e-4, 1e-3, 1e-3)),
    };
    let (sure, loose) = (est.predict_to(&model, dt), est.predict_to(&unsure, dt));
    let (normal, tangential) = (
        loose.cov[(2, 2)] - sure.cov[(2, 2)],
        loose.cov[(3, 3)] - sure.cov[(3, 3)],
    );
    assert!(normal > 0.01, "{}", loose.cov);
    // (The friction law couples the two a little once the direction has turned.)
    assert!(tangential.abs() < 0.1 * normal, "{normal} vs {tangential}");
    assert!(loose.cov.cholesky().is_some(), "P stays positive definite");
}

#[test]
fn a_mean_already_beyond_the_board_is_put_back_without_shrinking_p() {
    // A sighting's noise put the estimate 2 cm beyond the board, moving out slowly: it
    // bounced, but nothing says where it is better than before.
    let boards = Boards::around(9.0, 6.0, 0.5, 0.05, 0.5, 0.1);
    let model = field_model(Some(boards));
    let est = BallEstimate {
        t_s: 0.0,
        mean: Vector4::new(4.97, 0.0, 0.2, 0.0),
        cov: Matrix4::from_diagonal(&Vector4::new(4e-4, 4e-4, 0.01, 0.01)),
    };
    let next = est.predict_to(&model, 0.04);
    assert!(
        next.mean.x <= boards.half_x_m && next.mean.z < 0.0,
        "{}",
        next.mean
    );
    assert!(next.cov[(0, 0)] >= est.cov[(0, 0)], "{}", next.cov);
}

#[test]
fn a_still_ball_is_predicted_tighter_than_a_fast_one() {
    let model = field_model(None);
    let at = |v: f64| BallEstimate {
        t_s: 0.0,
        mean: Vector4::new(0.0, 0.0, v, 0.0),
        cov: Matrix4::from_diagonal(&Vector4::new(1e-4, 1e-4, 1e-4, 1e-4)),
    };
    let (still, fast) = (
        at(0.0).predict_to(&model, 0.1),
        at(3.0).predict_to(&model, 0.1),
    );
    // q = 0.05 at rest, 15.05 at 3 m/s.
    assert!(
        fast.cov[(1, 1)] > 50.0 * (still.cov[(1, 1)] - 1e-4),
        "still {} vs fast {}",
        still.cov,
        fast.cov
    );
}

/// What [`NetworkLimitedBall`] is defined to be, computed the slow way: the settled filter
/// with every kept event applied in time order, from scratch at every question.
struct ReplayEverything {
    settled: BallFilter,
    recent: Vec<(f64, ReplayEvent)>,
    settled_until_s: f64,
    window_s: f64,
}

#[derive(Clone, Copy)]
enum ReplayEvent {
    Seen(FieldObservation),
    Kicked(Kick),
    Track(crate::TrackGain),
}

impl ReplayEvent {
    fn apply(&self, filter: &mut BallFilter) {
        match self {
            ReplayEvent::Seen(o) => {
                filter.observe(o);
            }
            ReplayEvent::Kicked(k) => filter.kick(k),
            ReplayEvent::Track(g) => {
                filter.measure_state(g.t_s, &g.mean, &g.cov);
            }
        }
    }
}

impl ReplayEverything {
    fn insert(&mut self, t_s: f64, event: ReplayEvent) -> bool {
        if t_s < self.settled_until_s {
            return false;
        }
        let at = self.recent.partition_point(|(t, _)| *t <= t_s);
        self.recent.insert(at, (t_s, event));
        true
    }

    fn settle(&mut self, now_s: f64) {
        let until = now_s - self.window_s;
        if until <= self.settled_until_s {
            return;
        }
        self.settled_until_s = until;
        let n = self.recent.partition_point(|(t, _)| *t < until);
        for (_, e) in self.recent.drain(..n) {
            e.apply(&mut self.settled);
        }
    }

    fn estimate_at(&self, t_s: f64) -> Option<BallEstimate> {
        let mut filter = self.settled.clone();
        for (_, e) in &self.recent {
            e.apply(&mut filter);
        }
        filter.estimate_at(t_s)
    }
}

fn estimate_bits(e: Option<BallEstimate>) -> Option<Vec<u64>> {
    e.map(|e| {
        std::iter::once(e.t_s)
            .chain(e.mean.iter().copied())
            .chain(e.cov.iter().copied())
            .map(f64::to_bits)
            .collect()
    })
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(2_000))]

    /// A robot's delivery reference: its own sightings at once, two teammates' sightings,
    /// kicks and tracks up to 0.6 s late (so some arrive after their time settled), and
    /// questions (estimates, settling) in between, on the field model with boards. The
    /// reference that replays late events only when asked, from its kept states, answers
    /// every question with the same doubles as replaying everything kept from scratch.
    #[test]
    fn the_delivery_reference_is_the_filter_replayed_from_scratch(
        steps in proptest::collection::vec(
            (
                0.005..0.04f64,
                proptest::collection::vec(
                    (0u8..4, 0.0..0.6f64, -4.0..4.0f64, -3.0..3.0f64, 0.0..3.0f64),
                    0..4,
                ),
                0u8..3,
            ),
            1..60,
        ),
    ) {
        let cfg = BallFilterConfig {
            outliers_must_agree: true,
            model: field_model(Some(Boards::around(9.0, 6.0, 0.7, 0.05, 0.5, 0.1))),
            ..BallFilterConfig::default()
        };
        let mut lazy = NetworkLimitedBall::new(cfg, 0.3);
        let mut slow = ReplayEverything {
            settled: BallFilter::new(cfg),
            recent: Vec::new(),
            settled_until_s: f64::NEG_INFINITY,
            window_s: 0.3,
        };
        let mut now = 0.0;
        for (dt, arrivals, question) in steps {
            now += dt;
            for (kind, late, x, y, speed) in arrivals {
                let t_s = now - late;
                let (taken, kept) = match kind {
                    0 | 1 => {
                        let obs = FieldObservation {
                            t_s,
                            position: Vector2::new(x, y),
                            cov: Matrix2::identity() * (0.002 + 0.01 * speed),
                        };
                        (lazy.observe(&obs), slow.insert(t_s, ReplayEvent::Seen(obs)))
                    }
                    2 => {
                        let kick = Kick {
                            t_s,
                            speed_mps: speed,
                            direction_rad: x,
                            speed_sigma_mps: 0.3,
                            direction_sigma_rad: 0.2,
                            contact_prob: 0.9,
                        };
                        (lazy.kick(&kick), slow.insert(t_s, ReplayEvent::Kicked(kick)))
                    }
                    _ => {
                        let gain = crate::TrackGain {
                            t_s,
                            mean: Vector4::new(x, y, speed, -0.5 * speed),
                            cov: Matrix4::from_diagonal(&Vector4::new(0.01, 0.01, 0.2, 0.2)),
                        };
                        (lazy.track(&gain), slow.insert(t_s, ReplayEvent::Track(gain)))
                    }
                };
                proptest::prop_assert_eq!(taken, kept, "taken or refused alike at {}", t_s);
            }
            match question {
                0 => {
                    lazy.settle(now);
                    slow.settle(now);
                }
                1 => {}
                _ => {
                    lazy.settle(now);
                    slow.settle(now);
                    proptest::prop_assert_eq!(
                        estimate_bits(lazy.estimate_at(now + 0.02)),
                        estimate_bits(slow.estimate_at(now + 0.02)),
                        "after settling at {}", now
                    );
                }
            }
            proptest::prop_assert_eq!(
                estimate_bits(lazy.estimate_at(now)),
                estimate_bits(slow.estimate_at(now)),
                "at {}", now
            );
        }
    }
}
