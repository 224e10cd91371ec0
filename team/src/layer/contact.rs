//! The ball at a robot's body: what the robot's own motion and its teammates' do to the
//! ball between messages — its own push reported as a kick, the estimate widened while a
//! body is at the ball, a silent teammate's possible kick — and the odds that its foot
//! reaches the ball. Part of [`TeamLayer`]; a room of its own so that the layer's file
//! keeps to its tick.

use fusion::nalgebra::{Matrix2, Vector2};
use fusion::{Kick, TeamBall};

use super::{robot_id, TeamConfig, TeamLayer};
use crate::calibration::{Calibration, WorldModelConfig};
use crate::frames;
use crate::geometry::Vec2;

impl TeamLayer {
    /// Its own velocity over the latest control period, field frame: odometry turned by
    /// the heading halfway through it.
    pub fn own_velocity(&self, cfg: &TeamConfig) -> Vector2<f64> {
        let o = &self.odometry;
        let heading = self.pose_belief.theta_rad - 0.5 * o.turn_rad;
        let moved = Vec2::new(o.forward_m, o.left_m).rotate(heading);
        Vector2::new(moved.x, moved.y) / cfg.control_period_s
    }

    /// `ball` with its position variance widened while a body is at it and moving into
    /// it: the robot itself (its odometry), a teammate where its latest message put it (its
    /// velocity between its last two), an opponent its camera sees now (at its top speed).
    /// A body there pushes the ball at moments nobody has told this robot of yet: by
    /// `push_gain` × its closing speed (its velocity less the ball's, along the line
    /// between them) × [`WorldModelConfig::contact_horizon_s`] per body.
    /// Only the estimate the robot holds is widened, not the filter's state (a push, once
    /// seen or reported, is in it).
    pub(super) fn widened_at_contact(
        &self,
        cfg: &TeamConfig,
        now_s: f64,
        opponents: &[Vector2<f64>],
        mut ball: TeamBall,
    ) -> TeamBall {
        let wm = &cfg.world_model;
        if wm.contact_horizon_s <= 0.0 && wm.kick_hazard_per_s <= 0.0 {
            return ball;
        }
        let cal = &self.cal;
        let (at, v_ball) = (ball.estimate.position(), ball.estimate.velocity());
        let reach = |radius: f64| radius + cal.ball.radius_m + wm.contact_margin_m;
        // σ of the unheard push of a body at `p` moving at `v`, if it is at the ball.
        let sigma = |p: Vector2<f64>, v: Vector2<f64>, radius: f64| {
            let rel = at - p;
            let d = rel.norm();
            if d > reach(radius) || d < 1e-9 {
                return 0.0;
            }
            wm.push_gain * (v - v_ball).dot(&(rel / d)).max(0.0) * wm.contact_horizon_s
        };
        let own = self.lwm.pose();
        let ours = cal.body.radius_m;
        let mut var = sigma(
            Vector2::new(own.mean.x, own.mean.y),
            self.own_velocity(cfg),
            ours,
        )
        .powi(2);
        for (k, m) in self.teammate_motion.iter().enumerate() {
            if robot_id(k) == self.id {
                continue;
            }
            if let Some(m) = m {
                var += sigma(m.at, m.velocity, ours).powi(2);
            }
        }
        let top = cal.opponent.top_speed_mps;
        for o in opponents {
            let p = frames::to_fusion_point(self.pose_belief.to_field(Vec2::new(o.x, o.y)));
            // Its velocity is unknown: as if it came straight at the ball at top speed.
            let towards = (at - p).try_normalize(1e-9).unwrap_or_else(Vector2::zeros) * top;
            var += sigma(p, towards, cal.opponent.radius_m).powi(2);
        }
        var += self.unheard_kicks_var(wm, now_s, at);
        if var > 0.0 {
            ball.estimate.cov[(0, 0)] += var;
            ball.estimate.cov[(1, 1)] += var;
            ball.gbc = fusion::position_confidence(&ball.estimate.position_cov());
        }
        ball
    }

    /// Per-axis variance of the kicks teammates at the ball (their latest messages put
    /// them within a foot's reach of the ball they saw, or of `at`) may have made since
    /// those messages' snapshots, that no report has brought yet: a kick at a uniform
    /// instant in the unheard window w, with probability λw (λ =
    /// [`WorldModelConfig::kick_hazard_per_s`]), would have carried the ball v(w − τ) in a
    /// direction nobody here knows yet, so E|Δ|² = λ v² w³ / 3, half per axis. A beacon
    /// hold makes w two beacons long, and that is when a teammate's kick is most
    /// surprising.
    fn unheard_kicks_var(&self, wm: &WorldModelConfig, now_s: f64, at: Vector2<f64>) -> f64 {
        if wm.kick_hazard_per_s <= 0.0 {
            return 0.0;
        }
        let cal = &self.cal;
        let reach =
            cal.body.radius_m + cal.ball.radius_m + cal.kick.reach_margin_m + wm.contact_margin_m;
        let v = cal.kick.speed_mps;
        self.gwm
            .teammates_iter(now_s)
            .filter(|t| {
                // At the ball as it saw it (the geometry its foot goes by), else as the
                // team ball has it.
                let ball = t.lwm.ball.map_or(at, |b| b.position());
                let p = Vector2::new(t.pose.mean.x, t.pose.mean.y);
                t.silent_for_s <= wm.kick_hazard_window_s && (p - ball).norm() <= reach
            })
            .map(|t| wm.kick_hazard_per_s * v * v * t.silent_for_s.powi(3) / 6.0)
            .sum()
    }

    /// A push of the ball by the robot's own body over the latest control period, as the
    /// robot knows it: its own velocity from odometry, its own ball estimate relative to
    /// its own pose. When the ball is at its body (its odds of touching, from both
    /// estimates' uncertainty, at least [`WorldModelConfig::push_min_contact_prob`]) and
    /// the body closed in on it, the ball takes `push_gain` × the closing speed along the
    /// contact normal: reported as a [`Kick`] with those odds as its contact probability,
    /// so every filter takes it as the mixture "pushed or not". Opponents' pushes are not
    /// known to anyone: the ball model's noise covers them.
    pub fn push_report(&self, cfg: &TeamConfig, now_s: f64) -> Option<Kick> {
        let wm = &cfg.world_model;
        if wm.push_gain <= 0.0 || now_s - self.push_reported_at_s < wm.push_report_interval_s {
            return None;
        }
        // Only a ball it has seen itself lately: a remembered one is not where it walks.
        self.ball?;
        let ball = self.lwm.ball_at(now_s)?;
        let pose = self.lwm.pose();
        let rel = ball.position() - Vector2::new(pose.mean.x, pose.mean.y);
        let d = rel.norm();
        if d < 1e-6 {
            return None;
        }
        let n = rel / d;
        let v_body = self.own_velocity(cfg);
        let v_ball = ball.velocity();
        let closing = (v_body - v_ball).dot(&n);
        if closing <= 0.0 {
            return None;
        }
        let touch = self.cal.body.radius_m + self.cal.ball.radius_m;
        let cov = ball.position_cov() + pose.cov.fixed_view::<2, 2>(0, 0);
        let sigma_d = (n.transpose() * cov * n)[(0, 0)].max(1e-12).sqrt();
        let contact_prob = fusion::consistency::normal_cdf((touch - d) / sigma_d).clamp(0.0, 1.0);
        if contact_prob < wm.push_min_contact_prob || contact_prob <= 0.0 {
            return None;
        }
        let gained = n * (wm.push_gain * closing);
        if gained.norm() < wm.push_min_change_mps {
            return None;
        }
        let v_after = v_ball + gained;
        let across = Vector2::new(-n.y, n.x);
        let sigma_across = (across.transpose() * cov * across)[(0, 0)].max(0.0).sqrt();
        // The contact normal is as uncertain as the ball's place around the body; the
        // speed as the ball's own velocity and the closing speed (odometry's 5%, the
        // body's acceleration within the period).
        let speed_sigma = (0.5 * (ball.cov[(2, 2)] + ball.cov[(3, 3)])
            + (0.25 * gained.norm()).powi(2))
        .sqrt()
        .max(0.05);
        Some(Kick {
            t_s: now_s,
            speed_mps: v_after.norm(),
            direction_rad: v_after.y.atan2(v_after.x),
            speed_sigma_mps: speed_sigma,
            direction_sigma_rad: (sigma_across / touch).clamp(0.05, 1.0),
            contact_prob,
        })
    }

    /// The robot's own probability that its foot would meet the ball now: its ball
    /// estimate relative to its pose estimate, both uncertainties included, against its
    /// foot's reach (range and opening angle; its own body's geometry). Range and the
    /// lateral margin are taken as independent normals.
    pub fn contact_probability(&self, now_s: f64) -> f64 {
        let Some(ball) = self.lwm.ball_at(now_s) else {
            return 0.0;
        };
        contact_probability(
            &self.cal,
            self.lwm.pose(),
            ball.position(),
            ball.position_cov(),
        )
    }
}

/// The odds that a robot posed at `pose` (fusion's convention, with its covariance)
/// reaches a ball at field point `ball` (covariance `ball_cov`) with its foot: the ball
/// within its reach and within its kick's angle, both estimates' uncertainty carried
/// into its own frame. What [`TeamLayer::contact_probability`] asks of its own estimates;
/// a robot program that reads the layer's pose and ball from the daemon asks the same.
pub fn contact_probability(
    cal: &Calibration,
    pose: &fusion::PoseEstimate,
    ball: Vector2<f64>,
    ball_cov: Matrix2<f64>,
) -> f64 {
    // REP-103's heading (x forward), from fusion's (y forward).
    let (sin, cos) = frames::from_fusion_pose(pose).theta_rad.sin_cos();
    // Field → robot frame, x forward.
    let rot = Matrix2::new(cos, sin, -sin, cos);
    let d_field = ball - Vector2::new(pose.mean.x, pose.mean.y);
    let rel = rot * d_field;
    let cov_field = ball_cov + pose.cov.fixed_view::<2, 2>(0, 0);
    let mut cov = rot * cov_field * rot.transpose();
    // The heading's σ moves the ball sideways by its distance.
    cov[(1, 1)] += rel.norm_squared() * pose.cov[(2, 2)];
    let reach = cal.body.radius_m + cal.ball.radius_m + cal.kick.reach_margin_m;
    let d = rel.norm();
    let along = if d > 1e-9 {
        rel / d
    } else {
        Vector2::new(1.0, 0.0)
    };
    let sigma_d = (along.transpose() * cov * along)[(0, 0)].max(1e-12).sqrt();
    let p_range = fusion::consistency::normal_cdf((reach - d) / sigma_d);
    let lateral_room = rel.x.max(0.0) * cal.kick.max_angle_rad.tan() - rel.y.abs();
    let p_angle = fusion::consistency::normal_cdf(lateral_room / cov[(1, 1)].max(1e-12).sqrt());
    (p_range * p_angle).clamp(0.0, 1.0)
}
