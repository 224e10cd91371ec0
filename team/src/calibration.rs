//! What a robot knows of its body, its ball and its field before the match (its
//! [`Calibration`]: what a team measures on its own carpet, never the simulator's truth),
//! and how its world models are set up from that ([`WorldModelConfig`]: the LWM's and the
//! GWM's filters, the ball model the team runs and the table it was tuned with, and how a
//! robot reports its kicks and pushes).

use fusion::{BallFilterConfig, GlobalConfig, LocalConfig, PoseNoise};
use serde::{Deserialize, Serialize};

/// The field's lines as the rules give them, metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FieldGeometry {
    /// Length between the goal lines.
    pub length_m: f64,
    /// Width between the touch lines.
    pub width_m: f64,
    /// Goal mouth width.
    pub goal_width_m: f64,
    /// Carpet beyond the lines up to the boards.
    pub border_m: f64,
}

impl FieldGeometry {
    /// Centre of the opponent goal mouth.
    pub fn opponent_goal(&self) -> crate::geometry::Vec2 {
        crate::geometry::Vec2::new(self.length_m / 2.0, 0.0)
    }

    /// The centre spot, where the referee puts the ball for a kick-off (the field
    /// frame's origin).
    pub fn centre_spot(&self) -> crate::geometry::Vec2 {
        crate::geometry::Vec2::new(0.0, 0.0)
    }

    /// Centre of our own goal mouth.
    pub fn own_goal(&self) -> crate::geometry::Vec2 {
        crate::geometry::Vec2::new(-self.length_m / 2.0, 0.0)
    }

    /// Fixed landmarks a camera can recognise: the four goal posts, the four corners and
    /// the two ends of the halfway line.
    pub fn landmarks(&self) -> [crate::geometry::Vec2; 10] {
        crate::geometry::field_landmarks(self.length_m, self.width_m, self.goal_width_m)
    }
}

/// The ball as the team calibrated it on its carpet.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BallCalibration {
    /// Radius, m.
    pub radius_m: f64,
    /// Constant rolling deceleration, m/s².
    pub rolling_decel_mps2: f64,
    /// Speed-proportional drag, 1/s.
    pub drag_per_s: f64,
    /// Share of the normal speed a board gives back.
    pub restitution: f64,
}

/// A body (ours or an opponent's) as the team knows it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BodyCalibration {
    /// Radius for contacts, m.
    pub radius_m: f64,
    /// Top speed over ground, m/s.
    pub top_speed_mps: f64,
}

/// The robot's kick as the team measured it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct KickCalibration {
    /// Speed the ball leaves at, m/s.
    pub speed_mps: f64,
    /// σ of the direction it leaves in, rad.
    pub direction_sigma_rad: f64,
    /// How far beyond touching (body radius + ball radius) the foot reaches, m.
    pub reach_margin_m: f64,
    /// How far off the heading the ball may lie for the foot to meet it, rad.
    pub max_angle_rad: f64,
}

/// The robot's sensors' noise as the team measured it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SensorCalibration {
    /// Odometry: σ as a fraction of the motion.
    pub odometry_noise_frac: f64,
    /// Camera range σ, m, plus …
    pub range_noise_m: f64,
    /// … this fraction of the range.
    pub range_noise_frac: f64,
    /// Camera bearing σ, rad.
    pub bearing_noise_rad: f64,
}

/// What a robot's brain knows before the match: the nominal figures its team measured.
/// The simulator's world draws its own physics; the brain never sees them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// The field's lines.
    pub field: FieldGeometry,
    /// The ball.
    pub ball: BallCalibration,
    /// Its own body.
    pub body: BodyCalibration,
    /// Opponents' bodies.
    pub opponent: BodyCalibration,
    /// Its kick.
    pub kick: KickCalibration,
    /// Its sensors.
    pub sensors: SensorCalibration,
}

impl Default for Calibration {
    /// A small-size wheeled robot on a 9 × 6 m carpet: the figures huddle's simulator
    /// uses as its nominal world.
    fn default() -> Self {
        Self {
            field: FieldGeometry {
                length_m: 9.0,
                width_m: 6.0,
                goal_width_m: 1.5,
                border_m: 0.5,
            },
            ball: BallCalibration {
                radius_m: 0.05,
                rolling_decel_mps2: 0.6,
                drag_per_s: 0.5,
                restitution: 0.5,
            },
            body: BodyCalibration {
                radius_m: 0.2,
                top_speed_mps: 1.5,
            },
            opponent: BodyCalibration {
                radius_m: 0.2,
                top_speed_mps: 0.6,
            },
            kick: KickCalibration {
                speed_mps: 4.0,
                direction_sigma_rad: 0.08,
                reach_margin_m: 0.08,
                max_angle_rad: 40.0 * std::f64::consts::PI / 180.0,
            },
            sensors: SensorCalibration {
                odometry_noise_frac: 0.05,
                range_noise_m: 0.02,
                range_noise_frac: 0.05,
                bearing_noise_rad: 0.02,
            },
        }
    }
}

/// The gate (χ², 2 dof) the robot's pose filter holds a range/bearing landmark sighting
/// to: see [`WorldModelConfig::calibrated`]. Tuned on seeds 101–110 (tuning; `huddle sim
/// --seed S --duration 300s --team-ball pose_gate=G`), mean over the ten seeds:
///
/// | gate | drawn pose m | drawn team ball m | ideal pose m | ideal team ball m |
/// |---|---|---|---|---|
/// | 15 | 0.0815 | 0.0735 | | |
/// | 30 | 0.0760 | 0.0713 | 0.0359 | 0.0476 |
/// | **60** | **0.0707** | **0.0689** | 0.0355 | 0.0474 |
/// | 100 | 0.0715 | 0.0695 | 0.0355 | 0.0474 |
/// | 300 | 0.0713 | 0.0701 | | |
///
/// Against 30, per seed (drawn): 60 takes 0.0053 ± 0.0024 m (se) off the pose error and
/// 0.0024 ± 0.0025 m off the team ball; 60, 100 and 300 are within noise of each other. A
/// mislabelled landmark (its twin through the centre spot) lies metres off, far beyond
/// any of them; a tight gate also refuses true sightings after a shove the odometry
/// missed.
pub const POSE_GATE_CHI2: f64 = 60.0;
/// Landmark sightings refused in a row after which the pose filter takes itself for lost
/// and widens its covariance ([`fusion::Relocalise`]).
pub const POSE_LOST_AFTER_GATED: u32 = 5;

/// How the robots' world models are set up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldModelConfig {
    /// The LWM: pose EKF and ball EKF. Q and R of the pose EKF are replaced per reading
    /// from the field's noise figures (`player::perception`).
    pub local: LocalConfig,
    /// The GWM (`transit_s` 0: comms' ages include each frame's transit).
    pub global: GlobalConfig,
    /// σ of the start pose a robot is told (it is put on its spot by hand), m.
    pub start_sigma_m: f64,
    /// … and of its start heading, rad.
    pub start_sigma_rad: f64,
    /// σ per odometry reading of the motion odometry cannot see (pushes), m.
    pub push_sigma_m: f64,
    /// σ of a kick's speed as the kicker reports it (its direction σ is the field's kick
    /// noise), m/s.
    pub kick_speed_sigma_mps: f64,
    /// A robot lined up for a kick swings only if its own estimate gives at least this
    /// probability that the ball is within its foot's reach.
    pub kick_min_contact_prob: f64,
    /// A ball a body walks into leaves at this multiple of the closing speed along the
    /// contact normal (0: the robot does not report its pushes).
    pub push_gain: f64,
    /// At most one push report per this long, s (a dribble is a push every few ticks; the
    /// LWM carries one kick report at a time).
    pub push_report_interval_s: f64,
    /// While a body (this robot, a teammate where its last message put it, an opponent its
    /// camera sees) is within this of touching the team ball, m, …
    pub contact_margin_m: f64,
    /// … the team ball's position σ is widened per axis by `push_gain` × the body's speed
    /// towards the ball × this, s: the push it may have had that the robot has not heard of
    /// yet (a teammate's report is a network delay away; an opponent's is never coming).
    /// An opponent counts at its top speed (nobody measures its velocity).
    pub contact_horizon_s: f64,
    /// A push is reported when the robot's own odds that its body touched the ball are at
    /// least this …
    pub push_min_contact_prob: f64,
    /// … and it changes the ball's velocity by at least this, m/s (a dribble's small
    /// pushes are followed by the sightings; each report restarts teammates' team balls).
    pub push_min_change_mps: f64,
    /// How often a teammate at the ball kicks it, per second: the held team ball is
    /// widened by the kicks such a teammate may have made since its latest message's
    /// snapshot that no report has brought yet (see `Robot::unheard_kicks_var`); 0 off.
    pub kick_hazard_per_s: f64,
    /// … counted only for a teammate heard within this long, s (a silent one's place is
    /// not known well enough to say it is at the ball).
    pub kick_hazard_window_s: f64,
}

impl Default for WorldModelConfig {
    fn default() -> Self {
        Self::calibrated(&Calibration::default())
    }
}

impl WorldModelConfig {
    /// The world models of a team calibrated as `cal`: its ball model knows the field's
    /// boards and the friction law the team measured on its carpet.
    pub fn calibrated(cal: &Calibration) -> Self {
        let field = &cal.field;
        // The ball as a team would calibrate it on its carpet: 0.5/s drag plus 0.6 m/s²
        // rolling deceleration, bouncing off the boards with e = 0.5 (σ 0.1: boards and
        // balls vary), and acceleration noise for what nobody reports (opponents' shoves,
        // a body the ball glances off): q(s) = q₀ + q₁ s. Our own pushes are reported like
        // kicks, and the team ball a robot holds is widened while a body closes in on it
        // (`contact_horizon_s`). The pose-error sharing k sets how much of R is pose
        // error; with k = 10 (the rolling model's) a still ball was underconfident at any q.
        // Tuned on seeds 101–110 (`huddle sim --team-ball q0=…,q1=…,sharing=…`, hidden;
        // `--team-q 2.5` is the model before), `competition`, 10 seeds each: team RMSE
        // (root mean square over the seeds), NEES pooled over the samples, per band of the
        // true speed (bounds about [1.8, 2.2] per seed), samples above χ²₂'s 99.9% point,
        // median delivery ratio:
        //
        //   model                              RMSE    NEES  still  rolling  fast  >99.9%  deliv
        //   rolling, q 2.5, k 10 (before)      0.0550  1.03  0.88   0.89     1.72  0.54%   1.004
        //   field, q0 .05 q1 5, k 10, bare     0.0523  1.01  0.76   0.88     1.66  0.58%   0.962
        //   … k 2                              0.0506  1.50  1.31   1.30     2.39  0.88%   0.977
        //   … k 2, push reports                0.0475  1.31  1.24   1.15     2.02  0.64%   1.039
        //   … k 2, pushes, widening 0.1 s      0.0480  1.00  1.07   0.88     1.51  0.33%   1.039
        //   … the same, q1 3                   0.0469  1.09  1.04   0.92     1.78  0.43%   1.010
        //   … the same, q1 8                   0.0495  0.92  0.94   0.82     1.34  0.21%   1.079
        //   … the same, widening 0.05 s        0.0475  1.09  1.11   0.95     1.65  0.35%   1.039
        //   … the same, widening 0.15 s        0.0485  0.95  0.98   0.82     1.46  0.33%   1.035
        //   … the same, k 3                    0.0476  0.89  0.88   0.77     1.38  0.27%   1.035
        //   … the same, no boards              0.0517  1.02  1.05   0.88     1.57  0.31%   1.086
        //   … the same, k 1.5 (chosen then)    0.0474  1.05  1.11   0.91     1.60  0.30%   1.025
        //
        // No setting puts every band inside its bounds. Once the GWM kept teammates'
        // sightings from before a kick whose report came first, nearly all of the tail
        // above the 99.9% point (and all of the fast band's overconfidence) was the first
        // 0.3 s after a teammate's kick, before its report arrived: a beacon hold makes
        // that window up to two beacons long. That is now modelled where it happens (the
        // held ball widened by the kicks a teammate at the ball may have made since its
        // last message, `kick_hazard_per_s`), so the rolling ball's q₁ can come down.
        // Seeds 101–110 again, 300 s, `competition` | `competition-ps`: RMSE over the
        // seeds, mean NEES still/rolling/fast, samples above 99.9%, delivery ratio median
        // and worst:
        //
        //   q1 5, no hazard (before)     0.0489 1.10/0.92/1.55 0.32% 1.039/1.061 | 0.0887 1.06/1.03/2.44 0.64% 1.073/1.093
        //   q1 3, hazard 3/s (chosen)    0.0466 1.01/0.77/1.33 0.19% 1.003/1.030 | 0.0873 0.78/0.60/1.35 0.17% 1.044/1.076
        //   q1 2, hazard 3/s             0.0462 1.03/0.79/1.47 0.30% 1.004/1.014 | 0.0850 0.81/0.61/1.52 0.23% 1.048/1.079
        //   q1 2, hazard 2/s, widen .05  0.0474 1.13/0.94/1.66 0.42% 0.987/1.020 | 0.0872 0.89/0.70/1.62 0.34% 1.038/1.070
        //   q1 1.5, hazard 2/s           0.0473 1.11/0.89/1.62 0.43% 0.995/1.010 | 0.0854 0.85/0.66/1.73 0.34% 1.040/1.066
        //   q1 3, hazard 3/s, k 1        0.0473 1.10/0.86/1.44 0.22% 1.000/1.023 | 0.0873 0.83/0.66/1.41 0.19% 1.051/1.078
        //   q1 3, hazard 3/s, widen .07  0.0472 0.99/0.83/1.36 0.20% 1.003/1.034 | 0.0870 0.79/0.62/1.36 0.18% 1.053/1.069
        //   q1 3, no hazard (ps only)                                        | 0.0845 1.04/1.08/3.41 0.94% 1.050/1.087
        //
        // What is left is underconfidence everywhere (bounds about [1.8, 2.2]): a kick or
        // push nobody has reported yet is a rare large jump, and a Gaussian that covers it
        // is too wide for the many samples where it did not happen; a still ball with no
        // event within a second stays near 1.0 at any q₀ or k.
        //
        // Measured on every sample of seeds 101–110 (`competition`, 374k robot ticks), the
        // band targets (mean NEES 2 in each band, ≤ 0.3% above the 99.9% point) cannot
        // both be met by any covariance of this shape. The report's
        // `above_999_pct_at_mean_2` is the tail a band would have if its covariances were
        // scaled to put its mean at 2 (0.1% for Gaussian errors at any scale): still /
        // rolling / fast / all
        //
        //   team ball as held          mean 1.02/0.77/1.33/0.89  tail 0.19/0.12/0.49/0.19%  at mean 2 0.85/0.95/1.29/1.06%
        //   … not widened (the GWM's)       1.54/1.38/2.46/1.59       0.33/0.51/2.82/0.91%            0.45/0.86/2.19/1.20%
        //   centralized (no network)        1.35/1.36/2.23/1.52       0.16/0.41/1.45/0.57%            0.30/0.63/1.17/0.92%
        //   centralized told every kick     1.47/1.62/2.33/1.74       0.28/0.72/2.04/0.92%            0.39/0.88/1.57/1.09%
        //
        // (`competition-ps`: the team ball at mean 2, 1.50/1.91/1.38/1.78%.) Scaling each
        // of 168 groups of what a robot knows (band × widening × blind or not × its P)
        // to its own mean 2 still leaves 0.64/0.69/0.91%, ps 1.02/0.86/1.51%: the errors
        // are heavier-tailed than Gaussian within every group, even for a filter with no
        // network. Where the held ball is widened (69% of rolling samples) its mean-square
        // error stays 6–9·10⁻⁴ m² per axis whether the widening is 10⁻⁴ or 10⁻² m²: the
        // widening buys the tail of the rare pushes and kicks nobody has reported yet and
        // costs the mean of all the others (widened rolling samples 0.55, unwidened 1.29).
        // Widening along the push's normal and the kicker's heading instead of around the
        // ball lifts the means by about 0.1 and the tail to 0.27% (the robot's code).
        let ball = BallFilterConfig {
            pose_error_sharing: 1.5,
            model: fusion::BallModel::Field(fusion::FieldBall {
                drag_per_s: cal.ball.drag_per_s,
                rolling_decel_mps2: cal.ball.rolling_decel_mps2,
                still_accel_noise_m2_per_s3: 0.05,
                accel_noise_per_speed: 3.0,
                still_below_mps: 0.0,
                boards: Some(fusion::Boards::around(
                    field.length_m,
                    field.width_m,
                    field.border_m,
                    cal.ball.radius_m,
                    cal.ball.restitution,
                    0.1,
                )),
            }),
            ..BallFilterConfig::default()
        };
        Self {
            local: LocalConfig {
                pose_noise: PoseNoise::default(),
                // A landmark named wrongly (its twin through the centre spot, 1 sighting in
                // 100 in the drawn world) lies metres off: ungated, each one yanked the
                // pose and the drawn world's robots were 1.9–2.1 m off on average (#29,
                // seeds 101–104). A run of refusals means the robot, not the landmark, is
                // wrong ([`POSE_LOST_AFTER_GATED`]). The gate's value is tuned at
                // [`POSE_GATE_CHI2`].
                pose_gate_chi2: Some(POSE_GATE_CHI2),
                pose_relocalise: Some(fusion::Relocalise {
                    after_gated: POSE_LOST_AFTER_GATED,
                    sigma_m: 0.5,
                    sigma_rad: 0.3,
                }),
                ball,
            },
            global: GlobalConfig {
                ball: ball.model,
                // χ²₂ at 99.9% rather than 99%: robots push the ball all the time, and
                // with a network delay a tighter gate throws away true sightings on every
                // shove, each one a restart later. A liar is still caught: the consensus
                // and challenge rules, not the gate's width, keep it out.
                gate_chi2: 13.82,
                ..GlobalConfig::default()
            },
            start_sigma_m: 0.05,
            start_sigma_rad: 0.05,
            push_sigma_m: 0.005,
            // The field's kicks leave at `kick_speed_mps` give or take the field's speed
            // noise (5%), as a real foot does: the kicker reports the same σ.
            kick_speed_sigma_mps: 0.2,
            kick_min_contact_prob: 0.5,
            // A ball a body walks into leaves at 1.2× the closing speed (the team's
            // calibration of its robots' bodies and ball).
            push_gain: 1.2,
            push_report_interval_s: 0.08,
            push_min_contact_prob: 0.3,
            push_min_change_mps: 0.0,
            contact_margin_m: 0.1,
            contact_horizon_s: 0.1,
            kick_hazard_per_s: 3.0,
            kick_hazard_window_s: 0.5,
        }
    }
}
