//! One of our robots as the simulator runs it: what it sensed, what it believes, what it
//! decided and what it does. Each control tick it reads its camera and odometry, computes
//! eq. (19), reads its teammates' costs from **its own replica's blackboard**, decides with
//! `comms::arbitration`, and acts. Everything it tells the team goes back out as
//! blackboard writes (returned by [`Robot::tick`]), so the replica and the simulated
//! network carry it.
//!
//! Self-localisation is the true pose for now (`pose_belief`); the sightings and the
//! odometry a world model needs are kept on the struct for the fusion layer to use.

use comms::arbitration::{
    self, choose_play, heuristic, mode, Arbiter, ArbitrationParams, BallView, Decision, Mode,
    PassParams, Play, Posted,
};
use comms::{Blackboard, Instant, Key, Scope, Value};
use serde::Serialize;
use std::time::Duration;

use crate::field::behaviour::{self, Position};
use crate::field::body::{MotionCommand, Odometry};
use crate::field::camera::Frame;
use crate::field::geometry::{Pose, Vec2};
use crate::field::World;

/// The key the active robot announces its intended pass receiver on (`Int`, 0 = shot).
pub fn pass_to_key() -> Key {
    Key::parse(arbitration::PASS_TO_KEY).expect("PASS_TO_KEY is a valid key")
}

/// How a robot turns sightings into a belief and a belief into play.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BrainConfig {
    /// Control period, seconds (one camera frame per tick).
    pub control_period_s: f64,
    /// A ball not seen for longer than this is forgotten (`f_ball` = 0), seconds.
    pub ball_memory_s: f64,
    /// Weight of a new ball sighting in the smoothed ball position (1 = no smoothing).
    pub ball_smoothing: f64,
    /// The opponent goal counts as in view if seen within this long, seconds (one missed
    /// detection must not add |k1| to the cost).
    pub goal_memory_s: f64,
    /// The active robot shoots when the goal is this close, metres; farther, it pushes.
    pub shoot_range_m: f64,
    /// Time between two kicks of one robot, seconds.
    pub kick_cooldown_s: f64,
    /// Pass or shot: the constants of the obstruction-free-index.
    #[serde(skip)]
    pub pass: PassParams,
}

impl Default for BrainConfig {
    fn default() -> Self {
        Self {
            control_period_s: 0.04,
            ball_memory_s: 0.5,
            ball_smoothing: 0.4,
            goal_memory_s: 0.15,
            shoot_range_m: 3.0,
            kick_cooldown_s: 1.0,
            pass: PassParams::default(),
        }
    }
}

/// A robot's idea of where the ball is.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BallBelief {
    /// Smoothed position, field frame, metres.
    pub at: Vec2,
    /// When it was last seen, seconds of simulated time.
    pub seen_at_s: f64,
}

/// Counts of what the active robots did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct PlayCounts {
    /// Shots kicked.
    pub shots: u32,
    /// Passes kicked.
    pub passes: u32,
}

/// One of our robots.
#[derive(Debug, Clone)]
pub struct Robot {
    /// Robot id, 1–254 (index in the world + 1).
    pub id: u8,
    /// Its place in the formation.
    pub position: Position,
    /// Its side of the arbitration.
    pub arbiter: Arbiter,
    /// The latest camera frame.
    pub frame: Frame,
    /// Odometry measured over the latest control period.
    pub odometry: Odometry,
    /// Where it believes it is (the true pose until a world model is plugged in).
    pub pose_belief: Pose,
    /// Where it believes the ball is, if it has seen it recently.
    pub ball: Option<BallBelief>,
    /// When it last saw the opponent goal, seconds.
    pub goal_seen_at_s: Option<f64>,
    /// Its latest cost, eq. (19).
    pub h: f64,
    /// The team decision as it sees it.
    pub decision: Decision,
    /// Its CMUnited mode.
    pub mode: Mode,
    /// The play it has chosen while active.
    pub play: Option<Play>,
    /// Shots and passes kicked.
    pub counts: PlayCounts,
    /// Whether it is switched on (a dead robot neither senses, decides nor sends).
    pub alive: bool,
    pass_to_posted: i64,
    kick_ready_at_s: f64,
    decided_at_s: f64,
}

/// Everything a tick needs from outside the robot.
pub struct TickInput<'a> {
    /// Simulated time now, seconds.
    pub t_s: f64,
    /// The robot's own clock now (its replica's clock).
    pub local_now: Instant,
    /// Its replica's blackboard.
    pub board: &'a Blackboard,
    /// The formation's home spots for the field positions.
    pub homes: &'a [Vec2],
    /// Robot id holding each field position.
    pub holders: &'a [u8],
}

impl Robot {
    /// A robot `id` in `position`, deciding with `params`.
    pub fn new(id: u8, position: Position, params: ArbitrationParams, pose: Pose) -> Self {
        Self {
            id,
            position,
            arbiter: Arbiter::new(id, position == Position::Goalkeeper, params),
            frame: Frame::default(),
            odometry: Odometry::default(),
            pose_belief: pose,
            ball: None,
            goal_seen_at_s: None,
            h: params.no_ball_cost,
            decision: Decision {
                goer: None,
                goer_cost: f64::INFINITY,
            },
            mode: Mode::Inactive,
            play: None,
            counts: PlayCounts::default(),
            alive: true,
            pass_to_posted: 0,
            kick_ready_at_s: 0.0,
            decided_at_s: 0.0,
        }
    }

    /// Whether it competes for the ball.
    pub fn is_field_player(&self) -> bool {
        self.position != Position::Goalkeeper
    }

    /// Whether it saw the ball in its latest camera frame.
    pub fn sees_ball(&self) -> bool {
        self.alive && self.frame.ball.is_some()
    }

    /// Whether it is going to the ball now.
    pub fn going(&self) -> bool {
        self.alive && self.arbiter.going()
    }

    /// One control tick: sense, decide, act. Returns the blackboard writes to make
    /// through the robot's replica.
    pub fn tick(
        &mut self,
        world: &mut World,
        cfg: &BrainConfig,
        input: TickInput<'_>,
    ) -> Vec<(Key, Value)> {
        let i = usize::from(self.id - 1);
        let t = input.t_s;
        self.frame = world.look(i);
        self.odometry = world.read_odometry(i);
        self.pose_belief = world.robots[i].pose;
        self.update_ball(cfg, t);
        if self.frame.opponent_goal_in_view {
            self.goal_seen_at_s = Some(t);
        }

        let params = *self.arbiter.params();
        let facing = self
            .goal_seen_at_s
            .is_some_and(|s| t - s <= cfg.goal_memory_s);
        let view = self.ball.map(|b| BallView {
            distance_m: b.at.distance(self.pose_belief.at),
            facing_opponent_goal: facing,
        });
        self.h = heuristic(&params, view);
        let (decision, posted) = self.decide(t, input.board, input.local_now);
        let pass_to = decision.goer.filter(|&g| g != self.id).and_then(|g| {
            let key = Key::new(Scope::Robot(g), comms::Kind::Var, pass_to_key().path()).ok()?;
            match input
                .board
                .get_fresher_than(input.local_now, &key, params.stale_after)?
                .value
            {
                Value::Int(r) => u8::try_from(r).ok(),
                _ => None,
            }
        });
        let goalkeeper = self.position == Position::Goalkeeper;
        self.mode = if goalkeeper {
            Mode::Goaltend
        } else if self.arbiter.going() {
            Mode::Active
        } else {
            match mode(self.id, goalkeeper, &decision, pass_to) {
                Mode::Active => Mode::Inactive, // still listening after a start
                m => m,
            }
        };

        let mut writes = vec![(arbitration::heuristic_key(), Value::from(posted))];
        let receiver = self.act(world, cfg, &input);
        if receiver != self.pass_to_posted {
            self.pass_to_posted = receiver;
            writes.push((pass_to_key(), Value::Int(receiver)));
        }
        writes
    }

    /// Run the arbitration on the current cost and what the replica has heard.
    fn decide(&mut self, t_s: f64, board: &Blackboard, local_now: Instant) -> (Decision, Posted) {
        let heard = arbitration::heard(board, local_now);
        let dt = Duration::from_secs_f64((t_s - self.decided_at_s).max(0.0));
        self.decided_at_s = t_s;
        let (decision, posted) = self.arbiter.tick(dt, self.h, &heard);
        self.decision = decision;
        (decision, posted)
    }

    /// Between control ticks: decide again on the latest cost with whatever the replica
    /// heard since (a robot reacts to a teammate's claim when it arrives, not at its next
    /// camera frame). Returns the write to make if its claim changed.
    pub fn redecide(
        &mut self,
        t_s: f64,
        board: &Blackboard,
        local_now: Instant,
    ) -> Option<(Key, Value)> {
        if !self.alive {
            return None;
        }
        let was = self.arbiter.going();
        let (_, posted) = self.decide(t_s, board, local_now);
        (posted.going != was).then(|| (arbitration::heuristic_key(), Value::from(posted)))
    }

    fn update_ball(&mut self, cfg: &BrainConfig, t: f64) {
        if let Some(s) = self.frame.ball {
            let seen = self.pose_belief.to_field(s.local());
            let at = match self.ball {
                Some(b) if t - b.seen_at_s <= cfg.ball_memory_s => {
                    b.at * (1.0 - cfg.ball_smoothing) + seen * cfg.ball_smoothing
                }
                _ => seen,
            };
            self.ball = Some(BallBelief { at, seen_at_s: t });
        } else if self
            .ball
            .is_some_and(|b| t - b.seen_at_s > cfg.ball_memory_s)
        {
            self.ball = None;
        }
    }

    /// Move (and maybe kick) according to the mode; returns the pass receiver to
    /// announce (0: none).
    fn act(&mut self, world: &mut World, cfg: &BrainConfig, input: &TickInput<'_>) -> i64 {
        let i = usize::from(self.id - 1);
        let field = *world.config();
        let top = field.kinematics.top_speed_mps;
        let pose = self.pose_belief;
        let ball = self.ball.map(|b| b.at);
        let my_home = |k: usize| behaviour::flexible_home(&field, input.homes[k], ball);
        let cmd = match (self.mode, self.position) {
            (_, Position::Goalkeeper) => behaviour::keep_goal(&field, &pose, ball, top),
            (Mode::Active, Position::Field(k)) => {
                let Some(b) = ball else {
                    return 0;
                };
                let goal = field.opponent_goal();
                let receivers: Vec<(u8, (f64, f64))> = behaviour::receivers_of(input.homes, k)
                    .into_iter()
                    .map(|j| {
                        let at = behaviour::flexible_home(&field, input.homes[j], ball);
                        (input.holders[j], (at.x, at.y))
                    })
                    .collect();
                let opponents: Vec<(f64, f64)> = self
                    .frame
                    .opponents
                    .iter()
                    .map(|s| {
                        let p = pose.to_field(s.local());
                        (p.x, p.y)
                    })
                    .collect();
                let play = choose_play(
                    &cfg.pass,
                    (b.x, b.y),
                    (goal.x, goal.y),
                    &receivers,
                    &opponents,
                );
                self.play = Some(play);
                let (aim, receiver) = match play {
                    Play::Pass { to, .. } => {
                        let at = receivers
                            .iter()
                            .find(|r| r.0 == to)
                            .map_or(goal, |r| Vec2::new(r.1 .0, r.1 .1));
                        (at, i64::from(to))
                    }
                    Play::Shoot { .. } => (goal, 0),
                };
                let action = behaviour::approach_and_push(&field, &pose, b, aim, top);
                world.command(i, action.motion);
                let in_range = receiver != 0 || b.distance(goal) <= cfg.shoot_range_m;
                if action.lined_up
                    && in_range
                    && input.t_s >= self.kick_ready_at_s
                    && world.kick(i, (aim - b).angle())
                {
                    self.kick_ready_at_s = input.t_s + cfg.kick_cooldown_s;
                    if receiver != 0 {
                        self.counts.passes += 1;
                    } else {
                        self.counts.shots += 1;
                    }
                }
                return receiver;
            }
            (Mode::Auxiliary, Position::Field(k)) => match ball {
                // The intended receiver meets a ball that comes its way.
                Some(b) if b.distance(pose.at) < 2.0 => {
                    behaviour::go_to(&pose, b, (b - pose.at).angle(), top)
                }
                _ => behaviour::hold(&pose, my_home(k), ball, top),
            },
            (_, Position::Field(k)) => behaviour::hold(&pose, my_home(k), ball, top),
        };
        self.play = None;
        world.command(i, cmd);
        0
    }

    /// Switch the robot off: it stops where it is and falls silent.
    pub fn kill(&mut self, world: &mut World) {
        self.alive = false;
        world.command(
            usize::from(self.id - 1),
            MotionCommand {
                velocity: Vec2::default(),
                heading_rad: self.pose_belief.theta_rad,
            },
        );
    }
}
