//! The field simulator: a rectangle of carpet, a ball, our robots and a few opponents, in
//! simulated time. It knows the truth (true poses, the true ball) and gives each robot
//! only what its camera and wheels would: noisy sightings in the robot's frame and noisy
//! odometry. What robots decide lives in [`behaviour`] and in the `player` crate; the world only
//! moves bodies, rolls the ball, resolves contacts and kicks, and counts goals.
//!
//! Not modelled: robots' shapes beyond a disc, occlusions, the ball leaving the ground.

pub mod ball;
pub mod behaviour;
pub mod body;
pub mod camera;
pub mod geometry;
/// CMUnited's modes and plays: the simulated player's ([`player::tactics`]).
pub use player::tactics;

use ball::{Ball, BallConfig};
use body::{Body, Kinematics, MotionCommand, Odometry};
use camera::{sight, standard_normal, CameraConfig, Frame, Sighting};
use fusion::wrap_angle;
use geometry::{Pose, Vec2};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

/// The field's size and the simulated physics.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FieldConfig {
    /// Length between the goal lines, metres.
    pub length_m: f64,
    /// Width between the touch lines, metres.
    pub width_m: f64,
    /// Goal mouth width, metres.
    pub goal_width_m: f64,
    /// Carpet beyond the lines up to the boards, metres.
    pub border_m: f64,
    /// Our robots' bases.
    pub kinematics: Kinematics,
    /// Opponents' bases (slower: they are obstacles that chase the ball, not a team).
    pub opponent_kinematics: Kinematics,
    /// The ball.
    pub ball: BallConfig,
    /// Every robot's camera.
    pub camera: CameraConfig,
    /// Odometry noise: standard deviation as a fraction of the motion.
    pub odometry_noise_frac: f64,
    /// Speed of a kick, m/s.
    pub kick_speed_mps: f64,
    /// Standard deviation of a kick's speed, as a fraction of it (a real foot is not
    /// exact).
    pub kick_speed_noise_frac: f64,
    /// Standard deviation of a kick's direction, radians.
    pub kick_noise_rad: f64,
    /// A ball a body walks into leaves at this multiple of the closing speed along the
    /// contact normal.
    pub push_gain: f64,
    /// Odometry's systematic scale error: it reports this multiple of the motion (wheel
    /// radius miscalibrated, carpet).
    pub odometry_scale: f64,
    /// The share of a shove by another body that odometry sees (1: wheels roll with the
    /// body; 0: a shove slips the wheels and odometry never knows).
    pub shove_seen_frac: f64,
    /// Probability that a camera frame reports a ball that is not there (a white blob).
    pub false_ball_per_frame: f64,
    /// Probability that a landmark the camera detects is taken for its twin on the other
    /// half (the field is point-symmetric: a goal post, corner or halfway-line end looks
    /// like the one mirrored through the centre spot).
    pub landmark_confusion: f64,
}

/// How far beyond touching (robot radius + ball radius) a robot's foot reaches, metres.
pub const KICK_REACH_MARGIN_M: f64 = 0.08;
/// How far off its heading a ball may lie for the foot to meet it, radians (40°).
pub const KICK_MAX_ANGLE_RAD: f64 = 40.0 * std::f64::consts::PI / 180.0;

impl Default for FieldConfig {
    fn default() -> Self {
        Self {
            length_m: 9.0,
            width_m: 6.0,
            goal_width_m: 1.5,
            border_m: 0.5,
            kinematics: Kinematics::default(),
            opponent_kinematics: Kinematics {
                top_speed_mps: 0.6,
                ..Kinematics::default()
            },
            ball: BallConfig::default(),
            camera: CameraConfig::default(),
            odometry_noise_frac: 0.05,
            kick_speed_mps: 4.0,
            kick_speed_noise_frac: 0.05,
            kick_noise_rad: 0.08,
            push_gain: 1.2,
            odometry_scale: 1.0,
            shove_seen_frac: 1.0,
            false_ball_per_frame: 0.0,
            landmark_confusion: 0.0,
        }
    }
}

/// How a match's physics are drawn around the nominal field (`huddle sim --world drawn`).
/// Each figure is the nominal one (what a team measures and its robots' calibration
/// holds) times a factor drawn once per match from the seed:
///
/// | figure | draw |
/// |---|---|
/// | ball drag, rolling deceleration | × (1 + 0.15·N), at least × 0.5 |
/// | board restitution | + 0.1·N, within [0.2, 0.8] |
/// | push gain | × (1 + 0.15·N), at least × 0.5 |
/// | kick speed | × (1 + 0.05·N) |
/// | kick direction σ, camera range and bearing σ, odometry σ | × e^(0.2·N) |
/// | odometry scale | 1 + 0.03·N |
/// | share of a shove odometry sees | U(0, 0.5) |
/// | false balls | 1 frame in 500 (one every 20 s at 25 Hz) |
/// | landmark confusion | 1 landmark sighting in 100 named as its mirror twin |
///
/// N is a standard normal. The simulation adds per robot: a start pose off by its
/// start σ, and a clock with an offset U(0, 20) s and a drift N(0, 30) ppm.
pub fn drawn_field(nominal: &FieldConfig, seed: u64) -> FieldConfig {
    // Its own stream: the match's other noise is unchanged by the draw.
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5eed_f1e1_d000_0000);
    let mut n = || standard_normal(&mut rng);
    let mut f = *nominal;
    f.ball.drag_per_s *= (1.0 + 0.15 * n()).max(0.5);
    f.ball.rolling_decel_mps2 *= (1.0 + 0.15 * n()).max(0.5);
    f.ball.restitution = (f.ball.restitution + 0.1 * n()).clamp(0.2, 0.8);
    f.push_gain *= (1.0 + 0.15 * n()).max(0.5);
    f.kick_speed_mps *= (1.0 + 0.05 * n()).max(0.5);
    f.kick_noise_rad *= (0.2 * n()).exp();
    f.camera.range_noise_m *= (0.2 * n()).exp();
    f.camera.range_noise_frac *= (0.2 * n()).exp();
    f.camera.bearing_noise_rad *= (0.2 * n()).exp();
    f.odometry_noise_frac *= (0.2 * n()).exp();
    f.odometry_scale = 1.0 + 0.03 * n();
    let u = (0.5 * n()).abs().min(1.0) * 0.5; // within [0, 0.5]
    f.shove_seen_frac = u;
    f.false_ball_per_frame = 0.002;
    f.landmark_confusion = 0.01;
    f
}

impl FieldConfig {
    /// The calibration a team would measure on this field if it measured perfectly: the
    /// world's own constants. The simulator hands it to robots only when asked to
    /// (`SimConfig::calibration` unset); robots never see the world itself.
    pub fn exact_calibration(&self) -> team::Calibration {
        team::Calibration {
            field: team::calibration::FieldGeometry {
                length_m: self.length_m,
                width_m: self.width_m,
                goal_width_m: self.goal_width_m,
                border_m: self.border_m,
            },
            ball: team::calibration::BallCalibration {
                radius_m: self.ball.radius_m,
                rolling_decel_mps2: self.ball.rolling_decel_mps2,
                drag_per_s: self.ball.drag_per_s,
                restitution: self.ball.restitution,
            },
            body: team::calibration::BodyCalibration {
                radius_m: self.kinematics.radius_m,
                top_speed_mps: self.kinematics.top_speed_mps,
            },
            opponent: team::calibration::BodyCalibration {
                radius_m: self.opponent_kinematics.radius_m,
                top_speed_mps: self.opponent_kinematics.top_speed_mps,
            },
            kick: team::calibration::KickCalibration {
                speed_mps: self.kick_speed_mps,
                direction_sigma_rad: self.kick_noise_rad,
                reach_margin_m: KICK_REACH_MARGIN_M,
                max_angle_rad: KICK_MAX_ANGLE_RAD,
            },
            sensors: team::calibration::SensorCalibration {
                odometry_noise_frac: self.odometry_noise_frac,
                range_noise_m: self.camera.range_noise_m,
                range_noise_frac: self.camera.range_noise_frac,
                bearing_noise_rad: self.camera.bearing_noise_rad,
            },
        }
    }

    /// Centre of the opponent goal mouth.
    pub fn opponent_goal(&self) -> Vec2 {
        Vec2::new(self.length_m / 2.0, 0.0)
    }

    /// Centre of our own goal mouth.
    pub fn own_goal(&self) -> Vec2 {
        Vec2::new(-self.length_m / 2.0, 0.0)
    }

    /// Fixed landmarks a camera can recognise: the four goal posts, the four corners and
    /// the two ends of the halfway line.
    pub fn landmarks(&self) -> [Vec2; 10] {
        team::geometry::field_landmarks(self.length_m, self.width_m, self.goal_width_m)
    }
}

/// Which goal the ball went into.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Goal {
    /// Into the opponent goal: we scored.
    For,
    /// Into our goal.
    Against,
}

/// The whole field's true state.
#[derive(Debug, Clone)]
pub struct World {
    cfg: FieldConfig,
    /// Our robots' bodies (index = robot id − 1).
    pub robots: Vec<Body>,
    /// Opponents' bodies.
    pub opponents: Vec<Body>,
    /// The ball.
    pub ball: Ball,
    /// Goals we scored.
    pub goals_for: u32,
    /// Goals scored against us.
    pub goals_against: u32,
    commands: Vec<MotionCommand>,
    odometry: Vec<Odometry>,
    /// Per robot: carried off the field (a penalty), so no body on it: see
    /// [`World::set_off_field`].
    off_field: Vec<bool>,
    /// One random stream per robot (camera, odometry) and one for the world, so that
    /// adding a robot does not change what the others see.
    robot_rngs: Vec<ChaCha8Rng>,
    world_rng: ChaCha8Rng,
}

impl World {
    /// Where each of our robots stands, m (the truth), in robot order.
    pub fn robot_positions(&self) -> Vec<(f64, f64)> {
        self.robots
            .iter()
            .map(|b| (b.pose.at.x, b.pose.at.y))
            .collect()
    }

    /// A world with `robots` robots at `starts` (poses), `opponents` opponents spread over
    /// the opponent half, and the ball at the centre spot; `seed` fixes all noise.
    pub fn new(cfg: FieldConfig, starts: &[Pose], opponents: usize, seed: u64) -> Self {
        let robots: Vec<Body> = starts
            .iter()
            .map(|&pose| Body {
                pose,
                velocity: Vec2::default(),
            })
            .collect();
        let opponents = (0..opponents)
            .map(|i| {
                let y = (i as f64 + 0.5) / opponents as f64 - 0.5;
                Body {
                    pose: Pose {
                        at: Vec2::new(cfg.length_m * 0.25, y * cfg.width_m * 0.8),
                        theta_rad: std::f64::consts::PI,
                    },
                    velocity: Vec2::default(),
                }
            })
            .collect();
        let n = robots.len();
        let mut world_rng = ChaCha8Rng::seed_from_u64(seed);
        let robot_rngs = (0..n)
            .map(|_| ChaCha8Rng::seed_from_u64(world_rng.random()))
            .collect();
        Self {
            cfg,
            robots,
            opponents,
            ball: Ball::default(),
            goals_for: 0,
            goals_against: 0,
            commands: vec![MotionCommand::default(); n],
            odometry: vec![Odometry::default(); n],
            off_field: vec![false; n],
            robot_rngs,
            world_rng,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &FieldConfig {
        &self.cfg
    }

    /// Robot `i` was carried off the field (`true`: a referee's penalty) or put back on
    /// it. Off the field its body takes part in no contact: the ball and every other body
    /// pass it by, so nothing shoves it and its odometry reads only its own motion.
    ///
    /// Why: a penalised robot waits beyond the touchline, where play along the line ran
    /// into it. A teammate chasing the ball there pushed it every physics step, the
    /// referee put it back after each (`teamsim::game`), and its odometry read the shoves
    /// but not the put-backs: about 2 m/s of motion while it stood, its pose belief
    /// walked metres off (ideal world, seed 9: robot 3 at 445 s).
    pub fn set_off_field(&mut self, i: usize, off: bool) {
        if let Some(o) = self.off_field.get_mut(i) {
            *o = off;
        }
    }

    /// Whether robot `i` is off the field (see [`World::set_off_field`]).
    pub fn off_field(&self, i: usize) -> bool {
        self.off_field.get(i).copied().unwrap_or(false)
    }

    /// Set robot `i`'s motion command (kept until the next one).
    pub fn command(&mut self, i: usize, cmd: MotionCommand) {
        self.commands[i] = cmd;
    }

    /// Set robot `i`'s motion command as the robot means it: `cmd` is worked out in the
    /// field frame *as the robot believes it is posed* (`believed`), and the robot's base
    /// carries it out in its own frame. So a robot that is wrong about its heading drives
    /// (and turns) wrong by that much, as a real one would.
    pub fn command_believed(&mut self, i: usize, cmd: MotionCommand, believed: &Pose) {
        let truth = self.robots[i].pose.theta_rad;
        let off = wrap_angle(truth - believed.theta_rad);
        self.commands[i] = MotionCommand {
            velocity: cmd.velocity.rotate(off),
            heading_rad: wrap_angle(cmd.heading_rad + off),
        };
    }

    /// Robot `i` tries to kick the ball toward `direction_rad` (as the robot believes the
    /// field is oriented: its heading error turns the kick by as much). It works only
    /// when the ball is within the foot's reach in front of the robot (within
    /// [`KICK_MAX_ANGLE_RAD`] of its heading, [`KICK_REACH_MARGIN_M`] beyond touching);
    /// the ball leaves at the kick speed with the configured speed and direction noise.
    /// Returns whether the foot met the ball.
    pub fn kick(&mut self, i: usize, direction_rad: f64) -> bool {
        let pose = self.robots[i].pose;
        let rel = pose.to_local(self.ball.at);
        let reach = self.cfg.kinematics.radius_m + self.cfg.ball.radius_m + KICK_REACH_MARGIN_M;
        if rel.norm() > reach || rel.angle().abs() > KICK_MAX_ANGLE_RAD {
            return false;
        }
        let rng = &mut self.robot_rngs[i];
        let noise = self.cfg.kick_noise_rad * standard_normal(rng);
        let speed = self.cfg.kick_speed_mps
            * (1.0 + self.cfg.kick_speed_noise_frac * standard_normal(rng)).max(0.0);
        self.ball.velocity = Vec2::from_angle(direction_rad + noise) * speed;
        true
    }

    /// One camera frame of robot `i` (uses robot `i`'s noise stream only).
    pub fn look(&mut self, i: usize) -> Frame {
        self.look_reusing(i, Frame::default())
    }

    /// [`World::look`], its sightings written into `spare`'s vectors (an earlier frame's:
    /// what they held is dropped), so that a frame per robot per tick allocates nothing.
    pub fn look_reusing(&mut self, i: usize, spare: Frame) -> Frame {
        let Frame {
            mut landmarks,
            mut opponents,
            ..
        } = spare;
        landmarks.clear();
        opponents.clear();
        let cam = self.cfg.camera;
        let pose = self.robots[i].pose;
        let rng = &mut self.robot_rngs[i];
        let mut ball = sight(&cam, &pose, self.ball.at, cam.ball_range_m, rng);
        if self.cfg.false_ball_per_frame > 0.0
            && rng.random::<f64>() < self.cfg.false_ball_per_frame
        {
            // A white blob taken for the ball, anywhere in view.
            ball = Some(Sighting {
                range_m: 0.5 + (cam.ball_range_m - 0.5) * rng.random::<f64>(),
                bearing_rad: cam.fov_rad * (rng.random::<f64>() - 0.5),
            });
        }
        let goal = self.cfg.opponent_goal();
        let opponent_goal_in_view = camera::in_view(&cam, &pose, goal, cam.landmark_range_m)
            && rng.random::<f64>() < cam.detect_prob;
        let marks = self.cfg.landmarks();
        let confusion = self.cfg.landmark_confusion;
        landmarks.extend(marks.iter().enumerate().filter_map(|(k, &p)| {
            let s = sight(&cam, &pose, p, cam.landmark_range_m, rng)?;
            // Only a world with confusion draws for it: the ideal stream is unchanged.
            if confusion > 0.0 && rng.random::<f64>() < confusion {
                let twin = Vec2::default() - p;
                let k = marks
                    .iter()
                    .position(|&m| m.distance(twin) < 1e-9)
                    .unwrap_or(k);
                return Some((k, s));
            }
            Some((k, s))
        }));
        opponents.extend(
            self.opponents
                .iter()
                .filter_map(|o| sight(&cam, &pose, o.pose.at, cam.landmark_range_m, rng)),
        );
        Frame {
            ball,
            opponent_goal_in_view,
            landmarks,
            opponents,
        }
    }

    /// Robot `i`'s noisy odometry since the previous call.
    pub fn read_odometry(&mut self, i: usize) -> Odometry {
        let o = std::mem::take(&mut self.odometry[i]);
        let scale = self.cfg.odometry_scale;
        let o = Odometry {
            forward_m: o.forward_m * scale,
            left_m: o.left_m * scale,
            turn_rad: o.turn_rad * scale,
        };
        let k = self.cfg.odometry_noise_frac;
        let rng = &mut self.robot_rngs[i];
        let d = o.forward_m.hypot(o.left_m);
        Odometry {
            forward_m: o.forward_m + k * d * standard_normal(rng),
            left_m: o.left_m + k * d * standard_normal(rng),
            turn_rad: o.turn_rad + k * (o.turn_rad.abs() + 0.2 * d) * standard_normal(rng),
        }
    }

    /// Advance the world by `dt_s`: move robots and opponents, roll the ball, resolve
    /// contacts, detect goals (the ball is put back on the centre spot).
    pub fn step(&mut self, dt_s: f64) -> Option<Goal> {
        let kin = self.cfg.kinematics;
        let starts: Vec<Pose> = self.robots.iter().map(|b| b.pose).collect();
        for (i, body) in self.robots.iter_mut().enumerate() {
            body.step(&kin, &self.commands[i], dt_s);
        }
        let okin = self.cfg.opponent_kinematics;
        for k in 0..self.opponents.len() {
            let cmd = behaviour::opponent_command(
                &self.cfg,
                k,
                &self.opponents[k],
                &self.opponents,
                &self.ball,
            );
            self.opponents[k].step(&okin, &cmd, dt_s);
        }
        let half_x = self.cfg.length_m / 2.0 + self.cfg.border_m;
        let half_y = self.cfg.width_m / 2.0 + self.cfg.border_m;
        let before = self.ball.at;
        self.ball.step(&self.cfg.ball, dt_s, half_x, half_y);
        let driven: Vec<Vec2> = self.robots.iter().map(|b| b.pose.at).collect();
        self.resolve_contacts();
        for b in self.robots.iter_mut().chain(self.opponents.iter_mut()) {
            b.pose.at.x = b.pose.at.x.clamp(-half_x, half_x);
            b.pose.at.y = b.pose.at.y.clamp(-half_y, half_y);
        }
        // Odometry measures how the body moved under its own wheels: a shove by another
        // body slips the wheels, and odometry sees only `shove_seen_frac` of it (1: every
        // motion, the boards included), with the configured noise on top.
        let unseen = 1.0 - self.cfg.shove_seen_frac;
        for (i, (start, body)) in starts.iter().zip(&self.robots).enumerate() {
            let shove = body.pose.at - driven[i];
            let local = start.to_local(body.pose.at - shove * unseen);
            let o = Odometry {
                forward_m: local.x,
                left_m: local.y,
                turn_rad: wrap_angle(body.pose.theta_rad - start.theta_rad),
            };
            self.odometry[i] = self.odometry[i].then(o);
        }
        let goal = self.goal_crossed(before, self.ball.at);
        if let Some(g) = goal {
            match g {
                Goal::For => self.goals_for += 1,
                Goal::Against => self.goals_against += 1,
            }
            // Kick-off: the ball back near the centre spot, robots keep their places.
            let jitter = Vec2::new(
                0.3 * standard_normal(&mut self.world_rng),
                0.3 * standard_normal(&mut self.world_rng),
            );
            self.ball = Ball {
                at: jitter,
                velocity: Vec2::default(),
            };
        }
        goal
    }

    fn goal_crossed(&self, before: Vec2, after: Vec2) -> Option<Goal> {
        let hx = self.cfg.length_m / 2.0;
        let mouth = self.cfg.goal_width_m / 2.0;
        if before.x < hx && after.x >= hx && after.y.abs() < mouth {
            Some(Goal::For)
        } else if before.x > -hx && after.x <= -hx && after.y.abs() < mouth {
            Some(Goal::Against)
        } else {
            None
        }
    }

    /// Bodies push the ball (it takes their approach speed) and push each other apart.
    fn resolve_contacts(&mut self) {
        let ball_r = self.cfg.ball.radius_m;
        let (kr, okr) = (
            self.cfg.kinematics.radius_m,
            self.cfg.opponent_kinematics.radius_m,
        );
        let n = self.robots.len();
        for k in 0..n + self.opponents.len() {
            if k < n && self.off_field[k] {
                continue;
            }
            let (body, r) = if k < n {
                (&self.robots[k], kr)
            } else {
                (&self.opponents[k - n], okr)
            };
            let rel = self.ball.at - body.pose.at;
            let d = rel.norm();
            if d < r + ball_r && d > 1e-9 {
                let normal = rel * (1.0 / d);
                self.ball.at = body.pose.at + normal * (r + ball_r);
                let closing = (body.velocity - self.ball.velocity).dot(normal);
                if closing > 0.0 {
                    // A little faster than the body: the ball rolls off ahead of it.
                    self.ball.velocity =
                        self.ball.velocity + normal * (closing * self.cfg.push_gain);
                }
            }
        }
        let mut bodies: Vec<(bool, usize)> = (0..n)
            .filter(|&i| !self.off_field[i])
            .map(|i| (true, i))
            .collect();
        bodies.extend((0..self.opponents.len()).map(|i| (false, i)));
        for a in 0..bodies.len() {
            for b in a + 1..bodies.len() {
                let pa = self.body(bodies[a]).pose.at;
                let pb = self.body(bodies[b]).pose.at;
                let ra = if bodies[a].0 { kr } else { okr };
                let rb = if bodies[b].0 { kr } else { okr };
                let rel = pb - pa;
                let d = rel.norm();
                if d < ra + rb && d > 1e-9 {
                    let push = rel * ((ra + rb - d) / d / 2.0);
                    self.body_mut(bodies[a]).pose.at = pa - push;
                    self.body_mut(bodies[b]).pose.at = pb + push;
                }
            }
        }
    }

    fn body(&self, (ours, i): (bool, usize)) -> &Body {
        if ours {
            &self.robots[i]
        } else {
            &self.opponents[i]
        }
    }

    fn body_mut(&mut self, (ours, i): (bool, usize)) -> &mut Body {
        if ours {
            &mut self.robots[i]
        } else {
            &mut self.opponents[i]
        }
    }

    /// Whether `pose` would see the ball now, ignoring detection failures and noise.
    pub fn ball_in_view(&self, pose: &Pose) -> bool {
        camera::in_view(
            &self.cfg.camera,
            pose,
            self.ball.at,
            self.cfg.camera.ball_range_m,
        )
    }

    /// Angle from a point to the opponent goal centre.
    pub fn bearing_to_opponent_goal(&self, from: Vec2) -> f64 {
        wrap_angle((self.cfg.opponent_goal() - from).angle())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_daemon_s_default_calibration_is_the_simulator_s_nominal_world() {
        // `huddle daemon` runs its team layer with `Calibration::default()`; `huddle sim
        // --daemons` compares it with robots calibrated to the nominal field, so the two
        // must be the same figures.
        assert_eq!(
            FieldConfig::default().exact_calibration(),
            team::Calibration::default()
        );
    }

    #[test]
    fn a_ball_rolled_into_the_opponent_goal_counts_and_is_put_back() {
        let mut w = World::new(FieldConfig::default(), &[], 0, 1);
        w.ball = Ball {
            at: Vec2::new(4.0, 0.2),
            velocity: Vec2::new(3.0, 0.0),
        };
        let mut scored = None;
        for _ in 0..100 {
            if let Some(g) = w.step(0.01) {
                scored = Some(g);
                break;
            }
        }
        assert_eq!(scored, Some(Goal::For));
        assert_eq!(w.goals_for, 1);
        assert!(
            w.ball.at.norm() < 1.5,
            "ball back near the centre: {:?}",
            w.ball.at
        );
    }

    #[test]
    fn a_robot_driving_into_the_ball_pushes_it_ahead() {
        let start = Pose {
            at: Vec2::new(-1.0, 0.0),
            theta_rad: 0.0,
        };
        let mut w = World::new(FieldConfig::default(), &[start], 0, 2);
        w.command(
            0,
            MotionCommand {
                velocity: Vec2::new(1.0, 0.0),
                heading_rad: 0.0,
            },
        );
        for _ in 0..300 {
            w.step(0.01);
        }
        assert!(w.ball.at.x > w.robots[0].pose.at.x, "the ball stays ahead");
        assert!(
            w.ball.at.x > 1.0,
            "and was carried forward: {:?}",
            w.ball.at
        );
    }

    #[test]
    fn a_kick_only_works_when_the_ball_is_at_the_robots_front() {
        let start = Pose {
            at: Vec2::new(-0.27, 0.0),
            theta_rad: 0.0,
        };
        let mut w = World::new(FieldConfig::default(), &[start], 0, 3);
        assert!(w.kick(0, 0.0), "ball right in front");
        assert!(w.ball.velocity.x > 3.0);
        w.ball = Ball::default();
        w.robots[0].pose.theta_rad = std::f64::consts::PI;
        assert!(!w.kick(0, 0.0), "ball behind the robot");
    }

    #[test]
    fn a_confused_landmark_is_named_as_its_mirror_twin_at_the_documented_rate() {
        // A robot on the centre spot facing the opponent goal sees the goal posts and the
        // corners of that half; with the camera's noise off every sighting lands on the
        // landmark it is named as, or on its twin mirrored through the centre spot.
        let mut cfg = FieldConfig::default();
        cfg.camera.detect_prob = 1.0;
        cfg.camera.range_noise_m = 0.0;
        cfg.camera.range_noise_frac = 0.0;
        cfg.camera.bearing_noise_rad = 0.0;
        cfg.landmark_confusion = 0.1;
        let marks = cfg.landmarks();
        let mut w = World::new(cfg, &[Pose::default()], 0, 11);
        let (mut right, mut twin) = (0u32, 0u32);
        for _ in 0..2000 {
            for (k, s) in w.look(0).landmarks {
                let seen = s.local();
                if seen.distance(marks[k]) < 1e-6 {
                    right += 1;
                } else {
                    assert!(
                        seen.distance(Vec2::default() - marks[k]) < 1e-6,
                        "landmark {k} seen at {seen:?}: neither it nor its twin"
                    );
                    twin += 1;
                }
            }
        }
        let rate = f64::from(twin) / f64::from(right + twin);
        assert!(
            (rate - 0.1).abs() < 0.01,
            "seed 11: {twin} of {} sightings confused ({rate:.3}), configured 0.1",
            right + twin
        );
        cfg.landmark_confusion = 0.0;
        let mut w = World::new(cfg, &[Pose::default()], 0, 11);
        assert!(
            (0..200).all(|_| w
                .look(0)
                .landmarks
                .iter()
                .all(|(k, s)| s.local().distance(marks[*k]) < 1e-6)),
            "without confusion every landmark is named right"
        );
    }
}
