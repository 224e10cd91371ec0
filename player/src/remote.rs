//! One of our robots as a robot program driving a `huddle daemon`: the same perception,
//! modes and plays as [`crate::Robot`], but its team layer runs in the daemon and it talks
//! to it only through the contract's keys (`docs/team-layer.md`), as any robot program
//! would. Sans-IO: a tick takes what the robot sensed and what it last read from the
//! daemon's `local.var.team.*` outputs ([`TeamView`]), and returns the
//! `local.var.robot.*` writes to make and the motion to carry out. `huddle sim --daemons`
//! moves the bytes.
//!
//! What the contract gives a robot program is what this robot plays on: its pose as the
//! layer holds it, its own ball and the team ball (each with covariance and age), the
//! goer and whether it goes. Its odds of meeting the ball with a kick come from the same
//! function the layer uses ([`team::contact_probability`]), on those outputs.

use comms::arbitration::Decision;
use comms::Value;
use fusion::nalgebra::{Matrix3, Vector2};
use fusion::Kick;
use team::contract;
use team::{Calibration, Pose, Vec2};

use crate::behaviour::Position;
use crate::perception;
use crate::play::{Belief, Tactician};
use crate::robot::{BrainConfig, KickAttempt, Percepts};
use crate::senses::{Frame, MotionCommand, Odometry};

/// A ball as the layer publishes it (`local.var.team.ball`, `local.var.team.own_ball`):
/// the contract's reading of it.
pub type PublishedBall = contract::BallOutput;

/// What the robot program last read from its daemon's team layer.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TeamView {
    /// `local.var.team.pose`: the pose the layer holds, with its covariance.
    pub pose: Option<(Pose, Matrix3<f64>)>,
    /// Seconds since that pose was published.
    pub pose_since_s: f64,
    /// `local.var.team.own_ball`, and seconds since it was published.
    pub own_ball: Option<(PublishedBall, f64)>,
    /// `local.var.team.ball`, and seconds since it was published.
    pub team_ball: Option<(PublishedBall, f64)>,
    /// `local.var.team.goer` (0: none).
    pub goer: u8,
    /// `local.var.team.going`.
    pub going: bool,
    /// The goer's announced pass receiver (`n.var.machine.pass_to` of the goer).
    pub pass_to: Option<u8>,
    /// `local.var.team.play_whistle`: the play whistle the layer acts on (when, on the
    /// daemon's clock), the GameController not yet showing Playing.
    pub play_whistle_at: Option<f64>,
    /// `local.var.team.goal_whistle`: the goal's whistle the layer acts on, the
    /// GameController still showing Playing.
    pub goal_whistle_at: Option<f64>,
}

impl TeamView {
    /// Takes one output binding `key = value` read from the daemon; `false` when the
    /// key is not an output this robot plays on or the value does not parse.
    pub fn take(&mut self, key: &str, value: &Value, since_s: f64) -> bool {
        match key {
            contract::POSE_OUT_KEY => match contract::parse_pose_output(value) {
                Ok(p) => {
                    self.pose = Some((p.pose, p.cov));
                    self.pose_since_s = since_s;
                    true
                }
                Err(_) => false,
            },
            contract::OWN_BALL_KEY | contract::TEAM_BALL_KEY => {
                let team = key == contract::TEAM_BALL_KEY;
                let form = if team {
                    contract::TEAM_BALL_KEY
                } else {
                    contract::OWN_BALL_KEY
                };
                // `[]` (no ball now) and a malformed value both leave no ball.
                let held = contract::parse_ball_output(form, value)
                    .ok()
                    .flatten()
                    .map(|b| (b, since_s));
                *(if team {
                    &mut self.team_ball
                } else {
                    &mut self.own_ball
                }) = held;
                held.is_some()
            }
            contract::GOER_KEY => match value {
                Value::Int(g) => {
                    self.goer = u8::try_from(*g).unwrap_or(0);
                    true
                }
                _ => false,
            },
            contract::GOING_KEY => match value {
                Value::Bool(b) => {
                    self.going = *b;
                    true
                }
                _ => false,
            },
            // A malformed value leaves the reading as it was.
            contract::PLAY_WHISTLE_KEY => {
                contract::parse_whistle_at(contract::PLAY_WHISTLE_KEY, value)
                    .map(|at| self.play_whistle_at = at)
                    .is_ok()
            }
            contract::GOAL_WHISTLE_KEY => {
                contract::parse_whistle_at(contract::GOAL_WHISTLE_KEY, value)
                    .map(|at| self.goal_whistle_at = at)
                    .is_ok()
            }
            _ => false,
        }
    }

    /// The layer's reading of the referee's whistle, as its daemon published it: play
    /// started (the program plays while the GC still shows its late Set, or its last Ready
    /// with the radio dead), a goal (it walks to its kick-off spot while the GC still shows
    /// Playing), or none (the GC's word counts). What a program's body should follow
    /// rather than a reading of its own: the layer knows the rules for a silent GC.
    pub fn whistle(&self) -> Option<team::Whistle> {
        match (self.play_whistle_at, self.goal_whistle_at) {
            (Some(at), _) => Some(team::Whistle::PlayStarted(at)),
            (None, Some(at)) => Some(team::Whistle::Goal(at)),
            (None, None) => None,
        }
    }

    /// The team ball now, `dt_s` after it was read (its age since publication added).
    pub fn team_ball_now(&self, dt_s: f64) -> Option<Vec2> {
        self.team_ball.map(|(b, since)| b.at_after(since + dt_s))
    }

    /// Forgets the balls the layer stopped publishing: it writes them every tick while
    /// it holds them, so one not rewritten for `stale_s` is one it let go of (after a
    /// ball reset, say), however young the value's own age says it is.
    pub fn drop_stale(&mut self, stale_s: f64) {
        self.own_ball = self.own_ball.filter(|&(_, since)| since <= stale_s);
        self.team_ball = self.team_ball.filter(|&(_, since)| since <= stale_s);
    }
}

/// The contract's inputs for one tick of senses, calibrated as `cal`: the landmarks seen (with their field places, from the field's lines as the robot knows
/// them), a ball sighting in the robot frame with its covariance, and whether the
/// opponent goal is in view, and last the odometry (the daemon's layer ticks when it
/// arrives).
pub fn contract_inputs(cal: &Calibration, percepts: &Percepts) -> Vec<(&'static str, Value)> {
    let cam = &cal.sensors;
    let sigma_r = |r: f64| perception::range_sigma(cam, r);
    let mut out = Vec::new();
    let marks = cal.field.landmarks();
    let seen: Vec<f64> = percepts
        .frame
        .landmarks
        .iter()
        .filter_map(|(k, s)| marks.get(*k).map(|m| (m, s)))
        .flat_map(|(m, s)| {
            [
                m.x,
                m.y,
                s.range_m,
                s.bearing_rad,
                sigma_r(s.range_m),
                cam.bearing_noise_rad,
            ]
        })
        .collect();
    if !seen.is_empty() {
        out.push((contract::LANDMARKS_KEY, Value::Floats(seen)));
    }
    if let Some(s) = &percepts.frame.ball {
        let (local, cov) = perception::ball_rep103(cam, s);
        out.push((
            contract::BALL_KEY,
            Value::Floats(vec![
                local.x,
                local.y,
                cov[(0, 0)],
                cov[(0, 1)],
                cov[(1, 1)],
            ]),
        ));
    }
    out.push((
        contract::GOAL_IN_VIEW_KEY,
        Value::Bool(percepts.frame.opponent_goal_in_view),
    ));
    // Last: the layer ticks on the odometry, with everything written before it.
    let o = &percepts.odometry;
    out.push((
        contract::ODOMETRY_KEY,
        Value::Floats(vec![o.forward_m, o.left_m, o.turn_rad]),
    ));
    out
}

/// The pose a robot is told at its start spot, as the contract's `local.var.robot.pose`:
/// the spot, with the start σ the team configures.
pub fn start_pose_value(pose: &Pose, sigma_m: f64, sigma_rad: f64) -> Value {
    let (vm, vr) = (sigma_m.max(1e-3).powi(2), sigma_rad.max(1e-3).powi(2));
    Value::Floats(vec![
        pose.at.x,
        pose.at.y,
        pose.theta_rad,
        vm,
        0.0,
        0.0,
        vm,
        0.0,
        vr,
    ])
}

/// What a tick hands back.
#[derive(Debug, Clone)]
pub struct RemoteTick {
    /// Writes to make through the daemon's relay.
    pub writes: Vec<(&'static str, Value)>,
    /// The motion command, in the field frame as the robot believes it is posed.
    pub command: Option<MotionCommand>,
    /// The pose it believes.
    pub believed: Pose,
    /// A kick it swings, if any.
    pub kick: Option<KickAttempt>,
}

/// A robot whose team layer runs in a daemon.
#[derive(Debug, Clone)]
pub struct RemoteRobot {
    /// Its id.
    pub id: u8,
    /// Its place, mode and play.
    pub tactics: Tactician,
    /// What it knows of its field, body, ball and kick.
    pub cal: Calibration,
    /// The latest camera frame.
    pub frame: Frame,
    /// What it last read from the daemon.
    pub view: TeamView,
    /// The odometry it wrote, with when (its clock): what the layer's pose may not hold
    /// yet.
    odometry_log: std::collections::VecDeque<(f64, Odometry)>,
}

impl RemoteRobot {
    /// Robot `id` in `position`, calibrated as `cal`.
    pub fn new(id: u8, position: Position, cal: Calibration) -> Self {
        Self {
            id,
            tactics: Tactician::new(position),
            cal,
            frame: Frame::default(),
            view: TeamView::default(),
            odometry_log: std::collections::VecDeque::new(),
        }
    }

    /// The referee put the ball back: the write that tells the layer. The robot plays
    /// on no ball rather than the old one until the layer publishes again; whoever reads
    /// the layer's outputs must drop the balls published before the reset (the relay's
    /// output is in order: a `GETV` right after the reset marks the point).
    pub fn ball_reset(&mut self) -> (&'static str, Value) {
        self.view.own_ball = None;
        self.view.team_ball = None;
        (contract::BALL_RESET_KEY, Value::Bool(true))
    }

    /// The layer's pose brought up to `now_s`: the published pose followed by the motion
    /// the robot wrote after it was published (the layer had not integrated it yet), as
    /// a robot program dead-reckons between its localisation's updates.
    fn pose_now(&mut self, now_s: f64) -> Option<(Pose, Matrix3<f64>)> {
        let (pose, cov) = self.view.pose?;
        let published_s = now_s - self.view.pose_since_s;
        // Motion written more than a second before the pose is long in it.
        while self
            .odometry_log
            .front()
            .is_some_and(|&(t, _)| t < published_s - 1.0)
        {
            self.odometry_log.pop_front();
        }
        let since = self
            .odometry_log
            .iter()
            .filter(|&&(t, _)| t > published_s)
            .fold(Odometry::default(), |a, &(_, o)| a.then(o));
        let at = pose.to_field(Vec2::new(since.forward_m, since.left_m));
        Some((
            Pose {
                at,
                theta_rad: fusion::wrap_angle(pose.theta_rad + since.turn_rad),
            },
            cov,
        ))
    }

    /// Whether it is a field player (not the goalkeeper).
    pub fn is_field_player(&self) -> bool {
        !self.tactics.goalkeeper()
    }

    /// Whether it saw the ball in its latest camera frame.
    pub fn sees_ball(&self) -> bool {
        self.frame.ball.is_some()
    }

    /// Its own ball, if seen within `memory_s`, `dt_s` after its latest read.
    fn own_ball(&self, memory_s: f64, dt_s: f64) -> Option<Vec2> {
        self.view
            .own_ball
            .filter(|(b, since)| b.age_s + since + dt_s <= memory_s)
            .map(|(b, since)| b.at_after(since + dt_s))
    }

    /// One control tick at `now_s` on the robot's clock, `dt_s` after the view was
    /// last updated: what it sensed goes to the daemon, it plays on what the daemon's
    /// layer last told it ([`RemoteRobot::sense`] then [`RemoteRobot::act`]).
    pub fn tick(
        &mut self,
        cfg: &BrainConfig,
        now_s: f64,
        percepts: Percepts,
        dt_s: f64,
        homes: &[Vec2],
        holders: &[u8],
    ) -> RemoteTick {
        let mut writes = self.sense(now_s, percepts);
        let mut out = self.act(cfg, now_s, dt_s, homes, holders);
        writes.append(&mut out.writes);
        out.writes = writes;
        out
    }

    /// The first half of a tick at `now_s`: what the robot sensed, as the contract's
    /// writes, its odometry last (the write that closes a cycle: the layer ticks on it).
    pub fn sense(&mut self, now_s: f64, percepts: Percepts) -> Vec<(&'static str, Value)> {
        let writes = contract_inputs(&self.cal, &percepts);
        self.odometry_log.push_back((now_s, percepts.odometry));
        self.frame = percepts.frame;
        writes
    }

    /// The second half: play on the view, `dt_s` after it was last updated. The writes
    /// returned are a kick's report, if it swings.
    pub fn act(
        &mut self,
        cfg: &BrainConfig,
        now_s: f64,
        dt_s: f64,
        homes: &[Vec2],
        holders: &[u8],
    ) -> RemoteTick {
        let mut writes = Vec::new();
        // Five of the layer's ticks without a rewrite: it no longer holds that ball.
        self.view.drop_stale(5.0 * cfg.team.control_period_s);
        let Some((pose, pose_cov)) = self.pose_now(now_s) else {
            // The layer has not published a pose yet: nothing to play on.
            return RemoteTick {
                writes,
                command: None,
                believed: Pose::default(),
                kick: None,
            };
        };
        let decision = Decision {
            goer: (self.view.goer != 0).then_some(self.view.goer),
            goer_cost: 0.0,
        };
        self.tactics
            .set_mode(self.id, self.view.going, &decision, self.view.pass_to);
        let own_ball = self.own_ball(cfg.team.ball_memory_s, dt_s);
        // The team ball only while the team is sure enough of it, as the in-process
        // robot plays ([`team::TeamConfig::team_ball_min_gbc`]); below, its own ball.
        let team_ball = self
            .view
            .team_ball
            .filter(|(b, _)| b.confidence.is_none_or(|c| c >= cfg.team.team_ball_min_gbc))
            .map(|(b, since)| b.at_after(since + dt_s));
        let belief = Belief {
            cal: &self.cal,
            pose,
            ball: team_ball.or(own_ball),
            own_ball,
            opponents: &self.frame.opponents,
        };
        let cal = &self.cal;
        let own = self.view.own_ball;
        let action = self.tactics.act(cfg, &belief, now_s, homes, holders, || {
            own.map_or(0.0, |(b, since)| {
                let at = b.at_after(since + dt_s);
                let est = team::frames::to_fusion_pose(&pose, pose_cov);
                team::contact_probability(cal, &est, Vector2::new(at.x, at.y), b.cov)
            })
        });
        let kick = action.swing.map(|s| {
            let speed = self.cal.kick.speed_mps;
            writes.push((
                contract::KICK_KEY,
                Value::Floats(vec![s.direction_rad, speed, s.contact_prob]),
            ));
            KickAttempt {
                direction_rad: s.direction_rad,
                receiver: s.receiver,
                report: Kick {
                    t_s: now_s,
                    speed_mps: speed,
                    direction_rad: s.direction_rad,
                    speed_sigma_mps: cfg.team.world_model.kick_speed_sigma_mps,
                    direction_sigma_rad: self.cal.kick.direction_sigma_rad,
                    contact_prob: s.contact_prob,
                },
            }
        });
        RemoteTick {
            writes,
            command: action.command,
            believed: pose,
            kick,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::senses::Sighting;

    #[test]
    fn every_input_a_tick_writes_is_one_the_daemon_takes() {
        // A frame with a ball 2 m ahead-left, two landmarks and some odometry: each write
        // must pass the contract's check, exactly as the daemon's guards run it.
        let cal = Calibration::default();
        let percepts = Percepts {
            frame: Frame {
                ball: Some(Sighting {
                    range_m: 2.0,
                    bearing_rad: 0.3,
                }),
                opponent_goal_in_view: true,
                landmarks: vec![
                    (
                        0,
                        Sighting {
                            range_m: 3.0,
                            bearing_rad: -0.2,
                        },
                    ),
                    (
                        3,
                        Sighting {
                            range_m: 4.5,
                            bearing_rad: 1.0,
                        },
                    ),
                ],
                opponents: vec![],
            },
            odometry: Odometry {
                forward_m: 0.02,
                left_m: 0.0,
                turn_rad: 0.01,
            },
        };
        let writes = contract_inputs(&cal, &percepts);
        let keys: Vec<&str> = writes.iter().map(|(k, _)| *k).collect();
        assert_eq!(
            keys,
            [
                contract::LANDMARKS_KEY,
                contract::BALL_KEY,
                contract::GOAL_IN_VIEW_KEY,
                contract::ODOMETRY_KEY,
            ]
        );
        for (key, value) in &writes {
            assert!(
                !matches!(contract::check(key, value), Some(Err(_))),
                "{key} = {value:?} is refused: {:?}",
                contract::check(key, value)
            );
        }
        // The ball is where the camera put it, in the robot frame.
        let b = contract::parse_ball(&writes[1].1).expect("a ball the contract takes");
        assert!((b.local.x - 2.0 * 0.3f64.cos()).abs() < 1e-12);
        assert!((b.local.y - 2.0 * 0.3f64.sin()).abs() < 1e-12);
        let start = start_pose_value(&Pose::default(), 0.1, 0.05);
        assert!(
            contract::parse_pose(&start).is_ok(),
            "the start pose is taken"
        );
    }

    #[test]
    fn a_ball_at_the_robots_feet_is_a_sighting_the_daemon_takes() {
        // `huddle sim --daemons --game`, seed 6, the deaf game: after a goal the referee
        // holds the ball on the centre spot while the programs, 15 s behind the GC, still
        // play and walk onto it. The camera's range noise (σ 0.02 m there) clamps its range
        // to 0, and the covariance the program wrote had no bearing term left (r·σ_b = 0):
        // singular, so the daemon refused the write (`ERR 412 … not positive definite`, a
        // relay error in the test). A real camera sees a ball at its feet too. Every range
        // from 0 up, at any bearing, is a ball the contract takes, where the camera saw it.
        let cal = Calibration::default();
        for range_m in [0.0, 1e-9, 1e-6, 1e-4, 0.005, 0.02, 0.25] {
            for bearing_rad in [0.0, 0.4, -1.2, std::f64::consts::FRAC_PI_2, 3.0] {
                let percepts = Percepts {
                    frame: Frame {
                        ball: Some(Sighting {
                            range_m,
                            bearing_rad,
                        }),
                        ..Frame::default()
                    },
                    odometry: Odometry::default(),
                };
                let writes = contract_inputs(&cal, &percepts);
                let (_, value) = writes
                    .iter()
                    .find(|(k, _)| *k == contract::BALL_KEY)
                    .expect("a ball write");
                let b = contract::parse_ball(value).unwrap_or_else(|e| {
                    panic!("a ball {range_m} m away at {bearing_rad} rad ({value}) is refused: {e}")
                });
                let seen = Vector2::new(range_m * bearing_rad.cos(), range_m * bearing_rad.sin());
                assert!(
                    (b.local - seen).norm() < 1e-12,
                    "{range_m} m, {bearing_rad} rad"
                );
            }
        }
    }

    #[test]
    fn a_team_ball_the_team_is_unsure_of_is_not_played() {
        // Robot 2 goes; it has no ball of its own, and the team ball 2 m ahead has a
        // confidence of 0.1, under the 0.25 the in-process robot needs before it plays on
        // the team ball: it has no ball to play, so it gives no new command, as the
        // in-process robot does (`huddle sim --daemons` played on it and walked to balls
        // the team had lost). With a confidence of 0.9 it heads for that ball.
        let cfg = BrainConfig::default();
        let homes = [Vec2::new(-2.0, 0.0)];
        let play = |confidence: f64| {
            let mut r = RemoteRobot::new(2, Position::Field(0), Calibration::default());
            let pose = vec![0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.001];
            assert!(r
                .view
                .take(contract::POSE_OUT_KEY, &Value::Floats(pose), 0.0));
            let ball = vec![2.0, 0.0, 0.0, 0.0, 0.3, 0.0, 0.3, confidence, 0.5];
            assert!(r
                .view
                .take(contract::TEAM_BALL_KEY, &Value::Floats(ball), 0.0));
            assert!(r.view.take(contract::GOER_KEY, &Value::Int(2), 0.0));
            assert!(r.view.take(contract::GOING_KEY, &Value::Bool(true), 0.0));
            r.tick(&cfg, 1.0, Percepts::default(), 0.02, &homes, &[2])
                .command
        };
        assert!(
            play(0.1).is_none(),
            "no command toward a team ball of confidence 0.1"
        );
        let sure = play(0.9).expect("a command toward a team ball of confidence 0.9");
        assert!(
            sure.velocity.x > 0.0,
            "it heads for the ball it is sure of: {sure:?}"
        );
    }

    #[test]
    fn a_goer_told_by_its_daemon_plays_the_ball_it_was_told_about() {
        // The daemon says: this robot (2) goes; its pose is at the origin facing +x; its
        // own ball 1 m ahead. It heads for the ball.
        let cal = Calibration::default();
        let mut r = RemoteRobot::new(2, Position::Field(0), cal);
        let pose = |v: Vec<f64>| Value::Floats(v);
        assert!(r.view.take(
            contract::POSE_OUT_KEY,
            &pose(vec![0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.001]),
            0.0
        ));
        let ball = Value::Floats(vec![1.0, 0.0, 0.0, 0.0, 0.01, 0.0, 0.01, 0.05]);
        assert!(r.view.take(contract::OWN_BALL_KEY, &ball, 0.0));
        assert!(r.view.take(contract::GOER_KEY, &Value::Int(2), 0.0));
        assert!(r.view.take(contract::GOING_KEY, &Value::Bool(true), 0.0));
        assert!(
            !r.view.take(contract::GOING_KEY, &Value::Int(1), 0.0),
            "a wrong type is not taken"
        );
        let cfg = BrainConfig::default();
        let homes = [Vec2::new(-2.0, 0.0)];
        let out = r.tick(&cfg, 1.0, Percepts::default(), 0.02, &homes, &[2]);
        assert_eq!(r.tactics.mode, crate::tactics::Mode::Active);
        let cmd = out.command.expect("a motion");
        assert!(cmd.velocity.x > 0.0, "it heads for the ball: {cmd:?}");
        // Told another robot goes, it holds its place instead.
        assert!(r.view.take(contract::GOER_KEY, &Value::Int(3), 0.0));
        assert!(r.view.take(contract::GOING_KEY, &Value::Bool(false), 0.0));
        let out = r.tick(&cfg, 1.04, Percepts::default(), 0.02, &homes, &[2]);
        assert_eq!(r.tactics.mode, crate::tactics::Mode::Inactive);
        assert!(out.kick.is_none());
    }
}
