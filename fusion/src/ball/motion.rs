//! How the ball moves between sightings: the motion models and their exact discretisation.

use super::FieldBall;
use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};

/// How the ball moves between sightings.
///
/// State `(x, y, vx, vy)` in the field frame. In [`BallModel::Rolling`] the velocity
/// decays exponentially, `dv/dt = −c v + w(t)`, with `c = friction_per_s` and `w` white
/// acceleration noise of spectral density `q = accel_noise_m2_per_s3` on each axis. Its
/// exact discretisation over `dt` (a = e^{−c dt}, g = (1 − a)/c, which is `dt` when c = 0) is
///
/// ```text
/// F = [1 0 g 0; 0 1 0 g; 0 0 a 0; 0 0 0 a]
/// Q_pp = q/c³ (c dt − 2(1 − a) + (1 − a²)/2)
/// Q_pv = q/c² ((1 − a) − (1 − a²)/2)
/// Q_vv = q/(2c) (1 − a²)
/// ```
/// per axis (the cross-axis blocks are zero); for `c dt < 10⁻³` the series
/// `q dt³ (1/3 − u/4 + 7u²/60)`, `q dt² (1/2 − u/2 + 7u²/24)`, `q dt (1 − u + 2u²/3)`
/// (`u = c dt`) is used to avoid cancellation. A free-rolling ball therefore stops after
/// travelling `v/c`.
///
/// The seed's static model is [`BallModel::Static`]: the velocity is held at zero and the
/// position drifts as a random walk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BallModel {
    /// Rolling with exponential velocity decay and white acceleration noise.
    Rolling {
        /// c: velocity decay rate (1/s). 0 means no friction.
        friction_per_s: f64,
        /// q: acceleration noise spectral density per axis (m²/s³).
        accel_noise_m2_per_s3: f64,
    },
    /// The field's own friction: speed-proportional drag plus a constant rolling
    /// deceleration along the direction of motion, `dv/dt = −c v − μ v/|v| + w(t)`, which
    /// stops the ball in finite time. Nonlinear: the mean follows the exact solution and P
    /// the Jacobian at the mean (see [`BallModel::propagate`]); Q is the drag-only one of
    /// [`BallModel::Rolling`].
    Friction {
        /// c: speed-proportional drag (1/s).
        drag_per_s: f64,
        /// μ: constant rolling deceleration (m/s²).
        rolling_decel_mps2: f64,
        /// q: acceleration noise spectral density per axis (m²/s³).
        accel_noise_m2_per_s3: f64,
    },
    /// [`BallModel::Friction`] inside the field's boards, with process noise that grows
    /// with the speed (see [`FieldBall`]).
    Field(FieldBall),
    /// The seed's static model: the ball stays where it is, up to a random walk of the given
    /// spectral density (m²/s) per axis; the velocity is zero with zero variance.
    Static {
        /// Position random-walk spectral density (m²/s).
        drift_m2_per_s: f64,
    },
}

impl Default for BallModel {
    fn default() -> Self {
        BallModel::Rolling {
            friction_per_s: 0.5,
            accel_noise_m2_per_s3: 0.5,
        }
    }
}

impl BallModel {
    /// The mean `x` predicted over `dt_s`, with F and Q (negative `dt_s` is treated as 0);
    /// `velocity_var_m2ps2` is tr P_vv, used only to linearise [`BallModel::Friction`]. For
    /// the linear models this is `(F x, F, Q)` of [`Self::transition`].
    ///
    /// [`BallModel::Friction`]: with speed s, `ds/dt = −c s − μ`, so
    /// `s(t) = (s + m) e^{−ct} − m` (`m = μ/c`) until it stops at `t* = ln(1 + s/m)/c`;
    /// over `τ = min(dt, t*)` the ball travels `d = (s + m)(1 − e^{−cτ})/c − m τ` along
    /// its direction `u`. The Jacobian splits along and across `u`: along it
    /// `∂d/∂s = (1 − e^{−cτ})/c`, `∂s'/∂s = e^{−cτ}` (0 once stopped — the boundary terms
    /// vanish because the speed is 0 at t*); across it `d/s` and `s'/s`. F is taken at the
    /// speed `√(s² + tr P_vv)` rather than at s itself, which is the true Jacobian when
    /// the velocity is known and stays smooth at rest (see the body).
    #[allow(non_snake_case)]
    pub fn propagate(
        &self,
        x: &Vector4<f64>,
        velocity_var_m2ps2: f64,
        dt_s: f64,
    ) -> (Vector4<f64>, Matrix4<f64>, Matrix4<f64>) {
        let dt = dt_s.max(0.0);
        match *self {
            BallModel::Friction {
                drag_per_s,
                rolling_decel_mps2,
                accel_noise_m2_per_s3,
            } => friction_propagate(
                drag_per_s,
                rolling_decel_mps2,
                |_| accel_noise_m2_per_s3,
                x,
                velocity_var_m2ps2,
                dt,
            ),
            BallModel::Field(field) => field.propagate(x, velocity_var_m2ps2, dt),
            _ => {
                let (F, Q) = self.transition(dt);
                (F * x, F, Q)
            }
        }
    }

    /// F and Q over `dt_s` (negative `dt_s` is treated as 0). For [`BallModel::Friction`]
    /// and [`BallModel::Field`] this is the drag-only linearisation (the latter's at rest,
    /// without boards); predict with [`Self::propagate`] instead.
    #[allow(non_snake_case)]
    pub fn transition(&self, dt_s: f64) -> (Matrix4<f64>, Matrix4<f64>) {
        let dt = dt_s.max(0.0);
        match *self {
            BallModel::Friction {
                drag_per_s,
                accel_noise_m2_per_s3,
                ..
            } => BallModel::Rolling {
                friction_per_s: drag_per_s,
                accel_noise_m2_per_s3,
            }
            .transition(dt),
            BallModel::Field(f) => BallModel::Rolling {
                friction_per_s: f.drag_per_s,
                accel_noise_m2_per_s3: f.still_accel_noise_m2_per_s3,
            }
            .transition(dt),
            BallModel::Rolling {
                friction_per_s: c,
                accel_noise_m2_per_s3: q,
            } => rolling_transition(c, q, dt, &mut Decay::new(c, dt)),
            BallModel::Static { drift_m2_per_s } => {
                let mut F = Matrix4::zeros();
                F[(0, 0)] = 1.0;
                F[(1, 1)] = 1.0;
                let mut Q = Matrix4::zeros();
                Q[(0, 0)] = drift_m2_per_s * dt;
                Q[(1, 1)] = drift_m2_per_s * dt;
                (F, Q)
            }
        }
    }

    /// The velocity variance a fresh track starts with: none for the static model.
    pub(super) fn initial_velocity_var(&self, rolling_var: f64) -> f64 {
        match self {
            BallModel::Rolling { .. } | BallModel::Friction { .. } | BallModel::Field(_) => {
                rolling_var
            }
            BallModel::Static { .. } => 0.0,
        }
    }
}

/// e^{−c·dt} − 1 for one prediction's `c` and `dt`, worked out at most once: a friction
/// prediction needs it up to three times (Q's discretisation, the mean's roll, and the roll
/// at the linearisation speed when neither stops within `dt`), each time the same call on
/// the same argument, so sharing it changes no bit of the result.
struct Decay {
    c: f64,
    dt: f64,
    em1: Option<f64>,
}

impl Decay {
    fn new(c: f64, dt: f64) -> Self {
        Decay { c, dt, em1: None }
    }

    /// `(−c·τ).exp_m1()`, from the one worked out for `dt` when `τ` is `dt`. (`−(c·dt)`
    /// and `(−c)·dt` are the same double: the product's sign and magnitude are separate.)
    fn exp_m1(&mut self, c: f64, tau: f64) -> f64 {
        if c.to_bits() == self.c.to_bits() && tau.to_bits() == self.dt.to_bits() {
            let (c, dt) = (self.c, self.dt);
            *self.em1.get_or_insert_with(|| (-c * dt).exp_m1())
        } else {
            (-c * tau).exp_m1()
        }
    }
}

/// [`BallModel::Rolling`]'s F and Q over `dt` (see [`BallModel::transition`]).
#[allow(non_snake_case)]
fn rolling_transition(c: f64, q: f64, dt: f64, decay: &mut Decay) -> (Matrix4<f64>, Matrix4<f64>) {
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
        let e1 = -decay.exp_m1(c, dt); // 1 − a
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

/// [`BallModel::Friction`]'s prediction over `dt` (see [`BallModel::propagate`]), with the
/// acceleration noise `q_of(s)` a function of the mean's speed.
#[allow(non_snake_case)]
pub(super) fn friction_propagate(
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
    // The mean rolls at its own speed; P is linearised at the speed the velocity
    // uncertainty spans, √(s² + tr P_vv): at the mean itself a ball believed at rest
    // would have F_vv = 0, and a fresh track (v = 0, wide P_vv) would lose its velocity
    // variance in one step, which a ball that may have just been kicked does not.
    let mut decay = Decay::new(c, dt);
    let (d, s_next, _, _, _) = friction_roll_with(c, mu, s, dt, &mut decay);
    let s_lin = (s * s + velocity_var_m2ps2.max(0.0)).sqrt();
    // `BallModel::Rolling { c, q_of(s) }.transition(dt)`, sharing e^{−c·dt} − 1.
    let (_, Q) = rolling_transition(c, q_of(s), dt.max(0.0), &mut decay);
    let (d_lin, s_next_lin, g, a, _) = friction_roll_with(c, mu, s_lin, dt, &mut decay);
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
        // No direction: every direction is as likely, so average the two.
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

/// A ball at speed `s` rolling for `dt` under drag `c` and rolling deceleration `mu`:
/// (distance, final speed, ∂distance/∂s, ∂(final speed)/∂s, stop time). The derivatives
/// hold through the stop too: the speed is 0 there, so the stop time's own dependence on s
/// adds nothing.
pub(super) fn friction_roll(c: f64, mu: f64, s: f64, dt: f64) -> (f64, f64, f64, f64, f64) {
    friction_roll_with(c, mu, s, dt, &mut Decay::new(c, dt))
}

/// [`friction_roll`] with e^{−c·dt} − 1 shared with the other rolls of one prediction.
fn friction_roll_with(
    c: f64,
    mu: f64,
    s: f64,
    dt: f64,
    decay: &mut Decay,
) -> (f64, f64, f64, f64, f64) {
    let t_stop = if mu <= 0.0 {
        f64::INFINITY
    } else if c * s / mu < 1e-9 {
        s / mu
    } else {
        (c * s / mu).ln_1p() / c
    };
    let stopped = dt >= t_stop;
    let tau = dt.min(t_stop);
    // g = ∫₀^τ e^{−ct} dt and ∫₀^τ g(t) dt, written so that c → 0 stays exact.
    let (g, gg) = if c * tau < 1e-6 {
        (tau, tau * tau / 2.0)
    } else {
        let g = -decay.exp_m1(c, tau) / c;
        (g, (tau - g) / c)
    };
    let a = 1.0 - c * g; // e^{−cτ}
                         // s(t) = s e^{−ct} − μ g(t); the distance is its integral.
    let s_next = if stopped {
        0.0
    } else {
        (s * a - mu * g).max(0.0)
    };
    let d = (s * g - mu * gg).max(0.0);
    (d, s_next, g, if stopped { 0.0 } else { a }, t_stop)
}
