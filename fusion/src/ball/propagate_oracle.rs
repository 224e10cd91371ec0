//! The ball prediction as it was before it was made cheaper (e3f2b1c: every roll worked
//! out, e^{−c·dt} − 1 up to three times, the board check's roll always computed, the 4×4
//! products with I and 0 always done, the speed's hypot taken twice), kept verbatim as an oracle: the cheaper code must
//! give the same doubles, bit for bit, or the simulator's figures move.

#![allow(non_snake_case)]

use super::{Boards, FieldBall, MAX_BOUNCES};
use crate::ball::BallModel;
use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};
use proptest::prelude::*;

fn old_transition(c: f64, q: f64, dt_s: f64) -> (Matrix4<f64>, Matrix4<f64>) {
    let dt = dt_s.max(0.0);
    let u = c * dt;
    let (a, g, qpp, qpv, qvv) = if u < 1e-3 {
        (
            1.0 - u + u * u / 2.0,
            dt * (1.0 - u / 2.0 + u * u / 6.0),
            q * dt.powi(3) * (1.0 / 3.0 - u / 4.0 + 7.0 * u * u / 60.0),
            q * dt * dt * (0.5 - u / 2.0 + 7.0 * u * u / 24.0),
            q * dt * (1.0 - u + 2.0 * u * u / 3.0),
        )
    } else {
        let e1 = -(-u).exp_m1(); // 1 − a
        let e2 = -(-2.0 * u).exp_m1(); // 1 − a²
        (
            1.0 - e1,
            e1 / c,
            q / c.powi(3) * (u - 2.0 * e1 + e2 / 2.0),
            q / (c * c) * (e1 - e2 / 2.0),
            q / (2.0 * c) * e2,
        )
    };
    let F = Matrix4::new(
        1.0, 0.0, g, 0.0, //
        0.0, 1.0, 0.0, g, //
        0.0, 0.0, a, 0.0, //
        0.0, 0.0, 0.0, a,
    );
    let Q = Matrix4::new(
        qpp, 0.0, qpv, 0.0, //
        0.0, qpp, 0.0, qpv, //
        qpv, 0.0, qvv, 0.0, //
        0.0, qpv, 0.0, qvv,
    );
    (F, Q)
}

fn old_friction_propagate(
    c: f64,
    mu: f64,
    q_of: impl Fn(f64) -> f64,
    x: &Vector4<f64>,
    velocity_var_m2ps2: f64,
    dt: f64,
) -> (Vector4<f64>, Matrix4<f64>, Matrix4<f64>) {
    let v = Vector2::new(x.z, x.w);
    let s = v.norm();
    let s = if s.is_finite() { s } else { 0.0 };
    let (d, s_next, _, _, _) = old_friction_roll(c, mu, s, dt);
    let s_lin = (s * s + velocity_var_m2ps2.max(0.0)).sqrt();
    let (_, Q) = old_transition(c, q_of(s), dt);
    let (d_lin, s_next_lin, g, a, _) = old_friction_roll(c, mu, s_lin, dt);
    let mut F = Matrix4::identity();
    let (across_p, across_v) = if s_lin > 0.0 {
        (d_lin / s_lin, s_next_lin / s_lin)
    } else {
        (g, a)
    };
    let (along, across) = if s > 0.0 {
        let u = v / s;
        let along = u * u.transpose();
        (along, Matrix2::identity() - along)
    } else {
        (Matrix2::identity() * 0.5, Matrix2::identity() * 0.5)
    };
    let dp_dv = along * g + across * across_p;
    let dv_dv = along * a + across * across_v;
    F.fixed_view_mut::<2, 2>(0, 2).copy_from(&dp_dv);
    F.fixed_view_mut::<2, 2>(2, 2).copy_from(&dv_dv);
    let (p, vn) = if s > 0.0 {
        let u = v / s;
        (Vector2::new(x.x, x.y) + u * d, u * s_next)
    } else {
        (Vector2::new(x.x, x.y), Vector2::zeros())
    };
    (Vector4::new(p.x, p.y, vn.x, vn.y), F, Q)
}

fn old_friction_roll(c: f64, mu: f64, s: f64, dt: f64) -> (f64, f64, f64, f64, f64) {
    let t_stop = if mu <= 0.0 {
        f64::INFINITY
    } else if c * s / mu < 1e-9 {
        s / mu
    } else {
        (c * s / mu).ln_1p() / c
    };
    let stopped = dt >= t_stop;
    let tau = dt.min(t_stop);
    let (g, gg) = if c * tau < 1e-6 {
        (tau, tau * tau / 2.0)
    } else {
        let g = -(-c * tau).exp_m1() / c;
        (g, (tau - g) / c)
    };
    let a = 1.0 - c * g;
    let s_next = if stopped {
        0.0
    } else {
        (s * a - mu * g).max(0.0)
    };
    let d = (s * g - mu * gg).max(0.0);
    (d, s_next, g, if stopped { 0.0 } else { a }, t_stop)
}

fn old_distance_to_board(boards: &Boards, x: &Vector4<f64>) -> Option<(usize, f64)> {
    let s = x.z.hypot(x.w);
    if !(s > 0.0 && s.is_finite()) {
        return None;
    }
    (0..2)
        .filter_map(|a| {
            let u = x[a + 2] / s;
            if u == 0.0 {
                return None;
            }
            let d = (boards.half(a).copysign(u) - x[a]) / u;
            (d >= 0.0).then_some((a, d))
        })
        .min_by(|p, q| p.1.total_cmp(&q.1))
}

fn old_field_propagate(
    ball: &FieldBall,
    x: &Vector4<f64>,
    velocity_var_m2ps2: f64,
    dt: f64,
) -> (Vector4<f64>, Matrix4<f64>, Matrix4<f64>) {
    let (c, mu) = (ball.drag_per_s, ball.rolling_decel_mps2);
    let step = |x: &Vector4<f64>, dt: f64| {
        old_friction_propagate(c, mu, |s| ball.accel_noise(s), x, velocity_var_m2ps2, dt)
    };
    let Some(boards) = ball.boards else {
        return step(x, dt);
    };
    let (mut mean, mut F, mut Q) = (*x, Matrix4::identity(), Matrix4::zeros());
    let mut left = dt;
    for _ in 0..MAX_BOUNCES {
        if let Some(axis) = boards.outward(&mean) {
            boards.reflect(axis, false, mu, &mut mean, &mut F, &mut Q);
            continue;
        }
        let Some((axis, to_board)) = old_distance_to_board(&boards, &mean) else {
            break;
        };
        let s = mean.z.hypot(mean.w);
        let (rolled, _, _, _, t_stop) = old_friction_roll(c, mu, s, left);
        if rolled <= to_board {
            break;
        }
        let (mut lo, mut hi) = (0.0, left.min(t_stop));
        for _ in 0..48 {
            let mid = 0.5 * (lo + hi);
            if old_friction_roll(c, mu, s, mid).0 < to_board {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let t_hit = hi;
        let (m, f, q) = step(&mean, t_hit);
        mean = m;
        F = f * F;
        Q = f * Q * f.transpose() + q;
        boards.reflect(axis, true, mu, &mut mean, &mut F, &mut Q);
        left -= t_hit;
    }
    let (m, f, q) = step(&mean, left);
    (m, f * F, f * Q * f.transpose() + q)
}

/// The bits of every number of a prediction, so that −0 against +0 and NaN payloads count.
fn bits(p: &(Vector4<f64>, Matrix4<f64>, Matrix4<f64>)) -> Vec<u64> {
    p.0.iter()
        .chain(p.1.iter())
        .chain(p.2.iter())
        .map(|v| v.to_bits())
        .collect()
}

/// A field's ball: drag and rolling deceleration from a calibration's range (zero too),
/// with or without boards (the team's: 9 × 6 m, 0.7 m of carpet).
fn field_ball() -> impl Strategy<Value = FieldBall> {
    (
        prop_oneof![Just(0.0), 0.0..2.0f64],
        prop_oneof![Just(0.0), 0.0..1.5f64],
        0.0..1.0f64,
        0.0..6.0f64,
        prop_oneof![Just(0.0), 0.0..0.3f64],
        any::<bool>(),
        0.0..1.0f64,
    )
        .prop_map(|(c, mu, q0, q1, still, with_boards, e)| FieldBall {
            drag_per_s: c,
            rolling_decel_mps2: mu,
            still_accel_noise_m2_per_s3: q0,
            accel_noise_per_speed: q1,
            still_below_mps: still,
            boards: with_boards.then(|| Boards::around(9.0, 6.0, 0.7, 0.05, e, 0.1)),
        })
}

/// A ball anywhere on the carpet (or a little beyond a board, as a sighting's noise puts
/// it), at rest, creeping, rolling or just kicked, along an axis or not.
fn state() -> impl Strategy<Value = Vector4<f64>> {
    let speed = prop_oneof![Just(0.0), -0.05..0.05f64, -8.0..8.0f64];
    (-5.5..5.5f64, -4.0..4.0f64, speed.clone(), speed)
        .prop_map(|(x, y, vx, vy)| Vector4::new(x, y, vx, vy))
}

/// How far ahead: a camera frame, a message's delay, a replay's window, an interception
/// query seconds ahead; zero and negative too.
fn step_s() -> impl Strategy<Value = f64> {
    prop_oneof![
        Just(0.0),
        Just(-0.01),
        0.0..0.05f64,
        0.0..0.6f64,
        0.0..8.0f64
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20_000))]

    /// A ball on the field predicted by the cheaper code and by the old one: the same
    /// doubles, through bounces, stops and a ball already beyond a board.
    #[test]
    fn the_field_prediction_is_the_old_one_to_the_bit(
        ball in field_ball(),
        x in state(),
        velocity_var in prop_oneof![Just(0.0), 0.0..5.0f64],
        dt in step_s(),
    ) {
        let dt = dt.max(0.0);
        let new = BallModel::Field(ball).propagate(&x, velocity_var, dt);
        let old = old_field_propagate(&ball, &x, velocity_var, dt);
        prop_assert_eq!(bits(&new), bits(&old), "state {} over {} s", x, dt);
    }

    /// The friction law without boards and the rolling model's F and Q: the same doubles.
    #[test]
    fn the_friction_and_rolling_predictions_are_the_old_ones_to_the_bit(
        ball in field_ball(),
        x in state(),
        velocity_var in prop_oneof![Just(0.0), 0.0..5.0f64],
        dt in step_s(),
    ) {
        let (c, mu, q) =
            (ball.drag_per_s, ball.rolling_decel_mps2, ball.still_accel_noise_m2_per_s3);
        let friction = BallModel::Friction {
            drag_per_s: c,
            rolling_decel_mps2: mu,
            accel_noise_m2_per_s3: q,
        };
        let new = friction.propagate(&x, velocity_var, dt);
        let old = old_friction_propagate(c, mu, |_| q, &x, velocity_var, dt.max(0.0));
        prop_assert_eq!(bits(&new), bits(&old), "state {} over {} s", x, dt);
        let rolling = BallModel::Rolling { friction_per_s: c, accel_noise_m2_per_s3: q };
        let (F, Q) = rolling.transition(dt);
        let (oF, oQ) = old_transition(c, q, dt);
        let z = Vector4::zeros();
        prop_assert_eq!(bits(&(z, F, Q)), bits(&(z, oF, oQ)), "rolling over {} s", dt);
    }
}

/// The cases the fast paths stand on, spelled out: a ball rolling at a board it reaches
/// within the step (bisection and bounce), one that stops just short, and one sitting
/// beyond a board moving out.
#[test]
fn the_prediction_is_the_old_one_at_the_boards() {
    let ball = FieldBall {
        drag_per_s: 0.3,
        rolling_decel_mps2: 0.5,
        still_accel_noise_m2_per_s3: 0.05,
        accel_noise_per_speed: 3.0,
        still_below_mps: 0.0,
        boards: Some(Boards::around(9.0, 6.0, 0.7, 0.05, 0.5, 0.1)),
    };
    let half_x = ball.boards.expect("boards").half_x_m;
    for (x, dt) in [
        (Vector4::new(4.0, 0.0, 3.0, 0.4), 0.5),
        (Vector4::new(half_x - 0.3, 0.1, 1.0, 0.0), 0.35),
        (Vector4::new(half_x - 0.3, 0.1, 1.0, 0.0), 5.0),
        (Vector4::new(half_x + 0.02, 2.0, 0.5, -0.2), 0.04),
        (Vector4::new(4.5, 3.2, 2.0, 2.0), 1.0),
        (Vector4::new(0.0, 0.0, 0.0, 0.0), 0.04),
    ] {
        let new = BallModel::Field(ball).propagate(&x, 0.3, dt);
        let old = old_field_propagate(&ball, &x, 0.3, dt);
        assert_eq!(bits(&new), bits(&old), "state {x} over {dt} s");
    }
}
