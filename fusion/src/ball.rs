//! The ball EKF: position and velocity in the field frame with rolling friction
//! (tsinghua-2005 §4.3; cmunited-97-perception §2.3 for prediction ahead in time).
//!
//! # Model
//! State `(x, y, vx, vy)`. Between sightings the velocity decays exponentially,
//! `dv/dt = −c v + w(t)`, with `c = friction_per_s` and `w` white acceleration noise of
//! spectral density `q = accel_noise_m2_per_s3` on each axis. Its exact discretisation over
//! `dt` (a = e^{−c dt}, g = (1 − a)/c, which is `dt` when c = 0) is
//!
//! ```text
//! F = [1 0 g 0; 0 1 0 g; 0 0 a 0; 0 0 0 a]
//! Q_pp = q/c³ (c dt − 2(1 − a) + (1 − a²)/2)
//! Q_pv = q/c² ((1 − a) − (1 − a²)/2)
//! Q_vv = q/(2c) (1 − a²)
//! ```
//! per axis (the cross-axis blocks are zero); for `c dt < 10⁻³` the series
//! `q dt³ (1/3 − u/4 + 7u²/60)`, `q dt² (1/2 − u/2 + 7u²/24)`, `q dt (1 − u + 2u²/3)`
//! (`u = c dt`) is used to avoid cancellation. A free-rolling ball therefore stops after
//! travelling `v/c`.
//!
//! The seed's static model is [`BallModel::Static`]: the velocity is held at zero and the
//! position drifts as a random walk.
//!
//! # Sightings
//! A sighting is in robot coordinates. It is turned into a field-frame position
//! measurement `z = p + Rot(θ) l` whose noise carries the robot's pose uncertainty:
//! `R = Rot R_l Rotᵀ + J P_pose Jᵀ`, with `J = ∂z/∂(x, y, θ)`
//! ([`crate::geometry::robot_to_field_pose_jacobian`]). The update is then linear,
//! `H = [I₂ 0]`.

use crate::geometry::{robot_to_field, robot_to_field_pose_jacobian, rotation};
use crate::kalman::{self, UpdateError};
use crate::pose::PoseEstimate;
use nalgebra::{Matrix2, Matrix4, Vector2, Vector4};

/// How the ball moves between sightings.
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
    /// `velocity_var_m2ps2` is tr P_vv, used only to linearise [`BallModel::Friction`]. For the linear models this is `(F x, F, Q)` of [`Self::transition`].
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
        let BallModel::Friction {
            drag_per_s: c,
            rolling_decel_mps2: mu,
            accel_noise_m2_per_s3: q,
        } = *self
        else {
            let (F, Q) = self.transition(dt);
            return (F * x, F, Q);
        };
        let (_, Q) = BallModel::Rolling {
            friction_per_s: c,
            accel_noise_m2_per_s3: q,
        }
        .transition(dt);
        let v = Vector2::new(x.z, x.w);
        let s = v.norm();
        let s = if s.is_finite() { s } else { 0.0 };
        // The mean rolls at its own speed; P is linearised at the speed the velocity
        // uncertainty spans, √(s² + tr P_vv): at the mean itself a ball believed at rest
        // would have F_vv = 0, and a fresh track (v = 0, wide P_vv) would lose its velocity
        // variance in one step, which a ball that may have just been kicked does not.
        let (d, s_next, _, _, _) = friction_roll(c, mu, s, dt);
        let s_lin = (s * s + velocity_var_m2ps2.max(0.0)).sqrt();
        let (d_lin, s_next_lin, g, a, _) = friction_roll(c, mu, s_lin, dt);
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

    /// F and Q over `dt_s` (negative `dt_s` is treated as 0). For [`BallModel::Friction`]
    /// this is its drag-only linearisation; predict with [`Self::propagate`] instead.
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
            BallModel::Rolling {
                friction_per_s: c,
                accel_noise_m2_per_s3: q,
            } => {
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
    fn initial_velocity_var(&self, rolling_var: f64) -> f64 {
        match self {
            BallModel::Rolling { .. } | BallModel::Friction { .. } => rolling_var,
            BallModel::Static { .. } => 0.0,
        }
    }
}

/// A ball at speed `s` rolling for `dt` under drag `c` and rolling deceleration `mu`:
/// (distance, final speed, ∂distance/∂s, ∂(final speed)/∂s, stop time). The derivatives
/// hold through the stop too: the speed is 0 there, so the stop time's own dependence on s
/// adds nothing.
fn friction_roll(c: f64, mu: f64, s: f64, dt: f64) -> (f64, f64, f64, f64, f64) {
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
        let g = -(-c * tau).exp_m1() / c;
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

/// A ball estimate at time `t_s`: mean (x, y, vx, vy) in m and m/s, covariance P.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallEstimate {
    /// When the estimate holds (s, on the owner's clock).
    pub t_s: f64,
    /// (x, y, vx, vy).
    pub mean: Vector4<f64>,
    /// P, 4×4.
    pub cov: Matrix4<f64>,
}

impl BallEstimate {
    /// The position (x, y).
    pub fn position(&self) -> Vector2<f64> {
        Vector2::new(self.mean.x, self.mean.y)
    }

    /// The velocity (vx, vy).
    pub fn velocity(&self) -> Vector2<f64> {
        Vector2::new(self.mean.z, self.mean.w)
    }

    /// The 2×2 position block of P.
    pub fn position_cov(&self) -> Matrix2<f64> {
        self.cov.fixed_view::<2, 2>(0, 0).into_owned()
    }

    /// The estimate predicted to `t_s` (x⁻ = F x, P⁻ = F P Fᵀ + Q). Any future time works, so
    /// this is also the interception query; a `t_s` before `self.t_s` returns `self`.
    #[allow(non_snake_case)]
    pub fn predict_to(&self, model: &BallModel, t_s: f64) -> BallEstimate {
        if t_s <= self.t_s {
            return *self;
        }
        let velocity_var = self.cov[(2, 2)] + self.cov[(3, 3)];
        let (mean, F, Q) = model.propagate(&self.mean, velocity_var, t_s - self.t_s);
        let cov = F * self.cov * F.transpose() + Q;
        BallEstimate {
            t_s,
            mean,
            cov: (cov + cov.transpose()) * 0.5,
        }
    }

    /// Squared Mahalanobis distance between this estimate's position and `obs` (both at
    /// `obs.t_s` after prediction), using S = P_pos + R.
    pub fn position_mahalanobis_sq(
        &self,
        model: &BallModel,
        obs: &FieldObservation,
    ) -> Option<f64> {
        let p = self.predict_to(model, obs.t_s);
        kalman::mahalanobis_sq(
            &(obs.position - p.position()),
            &(p.position_cov() + obs.cov),
        )
    }
}

/// A kick as the kicker commanded it: at `t_s` the ball leaves at `speed_mps` towards
/// `direction_rad` (field frame, counter-clockwise from +x), each with the kicker's own
/// σ. A robot knows its kicks before anyone sees them; published with its LWM, a kick
/// turns every teammate's team ball the moment it arrives instead of several sightings
/// later.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kick {
    /// When the foot met the ball (s, on the owner's clock).
    pub t_s: f64,
    /// Speed right after the kick (m/s).
    pub speed_mps: f64,
    /// Direction of the kick in the field frame (rad).
    pub direction_rad: f64,
    /// σ of the speed (m/s).
    pub speed_sigma_mps: f64,
    /// σ of the direction (rad).
    pub direction_sigma_rad: f64,
}

impl Kick {
    /// The ball's velocity right after the kick and its covariance: the polar σ's through
    /// the Jacobian of (s, φ) ↦ s (cos φ, sin φ), the across-track σ at least the speed σ
    /// (a slow kick's direction says little, and a zero-speed one would leave the
    /// covariance singular).
    pub fn velocity(&self) -> (Vector2<f64>, Matrix2<f64>) {
        let (sin, cos) = self.direction_rad.sin_cos();
        let s = self.speed_mps;
        let along = self.speed_sigma_mps;
        let across = (s * self.direction_sigma_rad).max(along);
        let rot = Matrix2::new(cos, -sin, sin, cos);
        let polar = Matrix2::new(along * along, 0.0, 0.0, across * across);
        (
            Vector2::new(s * cos, s * sin),
            rot * polar * rot.transpose(),
        )
    }

    /// Whether every number is finite, the speed non-negative and the σ's positive.
    pub fn is_valid(&self) -> bool {
        [
            self.t_s,
            self.speed_mps,
            self.direction_rad,
            self.speed_sigma_mps,
            self.direction_sigma_rad,
        ]
        .iter()
        .all(|v| v.is_finite())
            && self.speed_mps >= 0.0
            && self.speed_sigma_mps > 0.0
            && self.direction_sigma_rad > 0.0
    }
}

impl BallEstimate {
    /// This track kicked: predicted to the kick (or left at its own time if the kick is
    /// older), the velocity replaced by the kick's, the position kept with its variance.
    /// The position–velocity correlation goes: the new velocity is the foot's, not
    /// something learnt from where the ball was. A static model has no velocity to set.
    pub fn kicked(&self, model: &BallModel, kick: &Kick) -> BallEstimate {
        let mut est = self.predict_to(model, kick.t_s);
        if matches!(model, BallModel::Static { .. }) {
            return est;
        }
        let (v, v_cov) = kick.velocity();
        est.mean.z = v.x;
        est.mean.w = v.y;
        let p = est.position_cov();
        est.cov = Matrix4::zeros();
        est.cov.fixed_view_mut::<2, 2>(0, 0).copy_from(&p);
        est.cov.fixed_view_mut::<2, 2>(2, 2).copy_from(&v_cov);
        est
    }
}

/// A ball sighting in robot coordinates (x right, y forward) with its noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallSighting {
    /// Where the robot saw the ball.
    pub local: Vector2<f64>,
    /// R_l, the sighting's covariance in robot coordinates (m²).
    pub cov: Matrix2<f64>,
}

/// A position measurement of the ball in the field frame, valid at `t_s`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldObservation {
    /// When the ball was there.
    pub t_s: f64,
    /// z, field coordinates.
    pub position: Vector2<f64>,
    /// R, including the observer's pose uncertainty.
    pub cov: Matrix2<f64>,
}

/// Turns a sighting by a robot at `pose` into a field-frame observation, carrying the pose
/// covariance into R through the Jacobian of the robot→field transform.
pub fn field_observation(
    t_s: f64,
    pose: &PoseEstimate,
    sighting: &BallSighting,
) -> FieldObservation {
    field_observation_shared(t_s, pose, sighting, 1.0)
}

/// [`field_observation`] with the pose term counted `pose_error_sharing` times:
/// `R = Rot R_l Rotᵀ + k J P_pose Jᵀ`.
///
/// A robot's pose error is not white: it is the same for every sighting the robot makes
/// until landmarks correct it. A filter that adds `J P Jᵀ` to each of N such sightings
/// lets their average shrink the pose error N-fold, which it does not do. Counting it
/// k times, with k the number of sightings a robot makes within its pose error's
/// correlation time, makes those k sightings together carry it exactly once
/// (`(R_l + k P)/k = R_l/k + P`). See [`BallFilterConfig::pose_error_sharing`].
pub fn field_observation_shared(
    t_s: f64,
    pose: &PoseEstimate,
    sighting: &BallSighting,
    pose_error_sharing: f64,
) -> FieldObservation {
    let rot = rotation(pose.mean.z);
    let j = robot_to_field_pose_jacobian(&pose.mean, &sighting.local);
    let k = pose_error_sharing.max(1.0);
    let cov = rot * sighting.cov * rot.transpose() + j * pose.cov * j.transpose() * k;
    FieldObservation {
        t_s,
        position: robot_to_field(&pose.mean, &sighting.local),
        cov: (cov + cov.transpose()) * 0.5,
    }
}

/// Predicts `est` to the observation's time and applies it (H = [I₂ 0], Joseph form).
/// Returns the new estimate and the observation's Mahalanobis².
///
/// With H = [I₂ 0] everything is a block of P: P Hᵀ is P's first two columns, S is a 2×2
/// inverted in closed form, and the Joseph form expands to
/// P − K (PHᵀ)ᵀ − (PHᵀ) Kᵀ + K S Kᵀ (algebraically identical, no 4×4 (I − KH) products).
/// This is the GWM's hot path.
#[allow(non_snake_case)]
pub fn update(
    model: &BallModel,
    est: &BallEstimate,
    obs: &FieldObservation,
    gate_chi2: Option<f64>,
) -> Result<(BallEstimate, f64), UpdateError> {
    let prior = est.predict_to(model, obs.t_s);
    let nu = obs.position - prior.position();
    if !nu.iter().chain(obs.cov.iter()).all(|v| v.is_finite()) {
        return Err(UpdateError::NonFinite);
    }
    let S = prior.position_cov() + obs.cov;
    let det = S[(0, 0)] * S[(1, 1)] - S[(0, 1)] * S[(1, 0)];
    if !(S[(0, 0)] > 0.0 && det > 0.0) {
        return Err(UpdateError::Singular);
    }
    let S_inv = Matrix2::new(S[(1, 1)], -S[(0, 1)], -S[(1, 0)], S[(0, 0)]) / det;
    let d2 = nu.dot(&(S_inv * nu));
    if let Some(threshold) = gate_chi2 {
        if d2 > threshold {
            return Err(UpdateError::Gated {
                mahalanobis_sq: d2,
                threshold,
            });
        }
    }
    let PHt = prior.cov.fixed_view::<4, 2>(0, 0).into_owned();
    let K = PHt * S_inv;
    let KPH = K * PHt.transpose();
    let cov = prior.cov - KPH - KPH.transpose() + K * S * K.transpose();
    let cov = (cov + cov.transpose()) * 0.5;
    debug_assert!(
        cov.iter().all(|v| v.is_finite()),
        "covariance went non-finite"
    );
    Ok((
        BallEstimate {
            t_s: prior.t_s,
            mean: prior.mean + K * nu,
            cov,
        },
        d2,
    ))
}

/// A fresh track from one observation: position from z, velocity zero with a wide variance.
pub fn initial_estimate(
    model: &BallModel,
    obs: &FieldObservation,
    velocity_var: f64,
) -> BallEstimate {
    let mut cov = Matrix4::zeros();
    cov.fixed_view_mut::<2, 2>(0, 0).copy_from(&obs.cov);
    let vv = model.initial_velocity_var(velocity_var);
    cov[(2, 2)] = vv;
    cov[(3, 3)] = vv;
    BallEstimate {
        t_s: obs.t_s,
        mean: Vector4::new(obs.position.x, obs.position.y, 0.0, 0.0),
        cov,
    }
}

/// Settings of a [`BallFilter`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallFilterConfig {
    /// The motion model.
    pub model: BallModel,
    /// Velocity variance of a fresh track (m²/s²).
    pub initial_velocity_var: f64,
    /// χ² (2 dof) beyond which a sighting counts as an outlier and is not applied.
    pub outlier_chi2: f64,
    /// After this many consecutive outliers the track restarts from the latest one (a kick
    /// the motion model could not follow).
    pub reset_after_outliers: u32,
    /// k of [`field_observation_shared`]: how many consecutive sightings of one robot share
    /// one pose error (about camera rate × detection rate × the time landmarks take to
    /// renew the pose). 1 treats pose errors as white, which is overconfident.
    pub pose_error_sharing: f64,
}

impl Default for BallFilterConfig {
    fn default() -> Self {
        BallFilterConfig {
            model: BallModel::default(),
            initial_velocity_var: 4.0,
            outlier_chi2: 9.21,
            reset_after_outliers: 2,
            pose_error_sharing: 10.0,
        }
    }
}

/// What one observation did to a [`BallFilter`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum BallUpdate {
    /// There was no track; it now starts here.
    Initialised,
    /// Applied; carries the Mahalanobis².
    Updated(f64),
    /// Not applied (Mahalanobis² beyond the outlier gate).
    Outlier(f64),
    /// Too many outliers in a row: the track restarted from this observation.
    Restarted,
    /// Not applied: non-finite or degenerate input.
    Rejected(UpdateError),
}

/// A running ball EKF fed field-frame observations in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct BallFilter {
    /// Settings.
    pub config: BallFilterConfig,
    estimate: Option<BallEstimate>,
    outliers_in_a_row: u32,
}

impl BallFilter {
    /// A filter with no track yet.
    pub fn new(config: BallFilterConfig) -> Self {
        BallFilter {
            config,
            estimate: None,
            outliers_in_a_row: 0,
        }
    }

    /// The latest estimate (at the time of the last observation), if any.
    pub fn estimate(&self) -> Option<&BallEstimate> {
        self.estimate.as_ref()
    }

    /// The estimate predicted to `t_s`.
    pub fn estimate_at(&self, t_s: f64) -> Option<BallEstimate> {
        self.estimate.map(|e| e.predict_to(&self.config.model, t_s))
    }

    /// Applies one observation (an observation older than the track is applied at the
    /// track's time).
    pub fn observe(&mut self, obs: &FieldObservation) -> BallUpdate {
        if !obs
            .position
            .iter()
            .chain(obs.cov.iter())
            .all(|v| v.is_finite())
            || !obs.t_s.is_finite()
        {
            return BallUpdate::Rejected(UpdateError::NonFinite);
        }
        let Some(est) = self.estimate else {
            self.estimate = Some(initial_estimate(
                &self.config.model,
                obs,
                self.config.initial_velocity_var,
            ));
            return BallUpdate::Initialised;
        };
        match update(
            &self.config.model,
            &est,
            obs,
            Some(self.config.outlier_chi2),
        ) {
            Ok((next, d2)) => {
                self.estimate = Some(next);
                self.outliers_in_a_row = 0;
                BallUpdate::Updated(d2)
            }
            Err(UpdateError::Gated { mahalanobis_sq, .. }) => {
                self.outliers_in_a_row += 1;
                if self.outliers_in_a_row >= self.config.reset_after_outliers {
                    self.outliers_in_a_row = 0;
                    let mut fresh =
                        initial_estimate(&self.config.model, obs, self.config.initial_velocity_var);
                    fresh.t_s = fresh.t_s.max(est.t_s);
                    self.estimate = Some(fresh);
                    BallUpdate::Restarted
                } else {
                    BallUpdate::Outlier(mahalanobis_sq)
                }
            }
            Err(e) => BallUpdate::Rejected(e),
        }
    }

    /// A kick (see [`Kick`]); without a track there is nothing to kick.
    pub fn kick(&mut self, kick: &Kick) {
        if !kick.is_valid() {
            return;
        }
        if let Some(est) = &self.estimate {
            self.estimate = Some(est.kicked(&self.config.model, kick));
            self.outliers_in_a_row = 0;
        }
    }

    /// Applies a sighting in robot coordinates made from `pose` at `t_s`.
    pub fn sighting(
        &mut self,
        t_s: f64,
        pose: &PoseEstimate,
        sighting: &BallSighting,
    ) -> BallUpdate {
        self.observe(&field_observation_shared(
            t_s,
            pose,
            sighting,
            self.config.pose_error_sharing,
        ))
    }
}

/// The reference a team's fusion is measured against: one ball filter, same model, fed every
/// robot's raw sightings (each with that robot's pose estimate) at once, with no network.
/// Feed sightings in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct CentralizedBall {
    filter: BallFilter,
}

impl CentralizedBall {
    /// A centralized filter with the given settings.
    pub fn new(config: BallFilterConfig) -> Self {
        CentralizedBall {
            filter: BallFilter::new(config),
        }
    }

    /// Applies a sighting that a robot at `pose` made at `t_s`.
    pub fn sighting(
        &mut self,
        t_s: f64,
        pose: &PoseEstimate,
        sighting: &BallSighting,
    ) -> BallUpdate {
        self.filter.sighting(t_s, pose, sighting)
    }

    /// A robot's kick, at once (it is a control input the team knows, not a sighting).
    pub fn kick(&mut self, kick: &Kick) {
        self.filter.kick(kick);
    }

    /// The estimate predicted to `t_s`.
    pub fn estimate_at(&self, t_s: f64) -> Option<BallEstimate> {
        self.filter.estimate_at(t_s)
    }

    /// Drops the track (the ball was put elsewhere by hand).
    pub fn forget(&mut self) {
        self.filter = BallFilter::new(self.filter.config);
    }
}

/// The centralized filter under a network's information pattern: the same filter as
/// [`CentralizedBall`], fed at one robot with exactly the ball information that has reached
/// that robot so far (its own sightings and kicks at once, each teammate's batches and
/// kick reports when its message arrives, in whatever order they arrive). It is the
/// reference for a fusion over that information: what the centralized filter itself makes
/// of what this network delivered (not a proof of optimality — it is the same gated EKF),
/// so a team ball's RMSE over this one's measures the fusion, and this one's over the
/// centralized filter's measures the network.
///
/// Observations are kept for `window_s` so that a late one slots in at its own time; an
/// estimate replays them over the settled state (a clone and a few updates).
#[derive(Debug, Clone, PartialEq)]
pub struct NetworkLimitedBall {
    settled: BallFilter,
    /// Events at or after `settled_until_s`, in time order.
    recent: Vec<Event>,
    settled_until_s: f64,
    window_s: f64,
    late: u64,
}

/// What the reference replays.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Event {
    Seen(FieldObservation),
    Kicked(Kick),
}

impl Event {
    fn t_s(&self) -> f64 {
        match self {
            Event::Seen(o) => o.t_s,
            Event::Kicked(k) => k.t_s,
        }
    }

    fn apply(&self, filter: &mut BallFilter) {
        match self {
            Event::Seen(o) => {
                filter.observe(o);
            }
            Event::Kicked(k) => filter.kick(k),
        }
    }
}

impl NetworkLimitedBall {
    /// A reference with the given filter settings that keeps observations re-orderable for
    /// `window_s` (longer than the network's worst delay plus the repeats' reach).
    pub fn new(config: BallFilterConfig, window_s: f64) -> Self {
        NetworkLimitedBall {
            settled: BallFilter::new(config),
            recent: Vec::new(),
            settled_until_s: f64::NEG_INFINITY,
            window_s,
            late: 0,
        }
    }

    fn insert(&mut self, event: Event) -> bool {
        let t_s = event.t_s();
        if t_s < self.settled_until_s {
            self.late += 1;
            return false;
        }
        let at = self.recent.partition_point(|p| p.t_s() <= t_s);
        self.recent.insert(at, event);
        true
    }

    /// One observation, whenever it arrives; `false` (and counted) if it is older than
    /// the settled state and cannot be used.
    pub fn observe(&mut self, obs: &FieldObservation) -> bool {
        self.insert(Event::Seen(*obs))
    }

    /// A kick, whenever its report arrives; `false` (and counted) if too late.
    pub fn kick(&mut self, kick: &Kick) -> bool {
        self.insert(Event::Kicked(*kick))
    }

    /// Settles every event older than `now_s − window_s` into the filter for good.
    pub fn settle(&mut self, now_s: f64) {
        let until = now_s - self.window_s;
        if until <= self.settled_until_s {
            return;
        }
        self.settled_until_s = until;
        let n = self.recent.partition_point(|p| p.t_s() < until);
        for event in self.recent.drain(..n) {
            event.apply(&mut self.settled);
        }
    }

    /// The estimate from everything received, predicted to `t_s`.
    pub fn estimate_at(&self, t_s: f64) -> Option<BallEstimate> {
        let mut filter = self.settled.clone();
        for event in &self.recent {
            event.apply(&mut filter);
        }
        filter.estimate_at(t_s)
    }

    /// Events that arrived after their time had settled.
    pub fn late(&self) -> u64 {
        self.late
    }

    /// Drops the track and ignores information from before `t_s` (the ball was put
    /// elsewhere by hand).
    pub fn forget(&mut self, t_s: f64) {
        self.settled = BallFilter::new(self.settled.config);
        self.recent.clear();
        self.settled_until_s = t_s;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        assert!(
            (field_observation(1.0, &pose, &s).cov - Matrix2::identity() * 1e-4).norm() < 1e-12
        );
    }

    #[test]
    fn the_block_update_is_the_general_joseph_update() {
        let model = BallModel::default();
        let est = BallEstimate {
            t_s: 1.0,
            mean: Vector4::new(0.5, -0.2, 1.0, 0.3),
            cov: Matrix4::new(
                0.04, 0.01, 0.02, 0.0, 0.01, 0.03, 0.0, 0.01, 0.02, 0.0, 0.5, 0.1, 0.0, 0.01, 0.1,
                0.4,
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
    }

    use nalgebra::{Matrix3, Vector3};
}
