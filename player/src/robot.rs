//! One of our robots as the simulator runs it: a body's senses and behaviour around the
//! product's team layer ([`team::TeamLayer`], the code `huddle daemon` runs for a real
//! robot). Each control tick it turns its camera frame and odometry into what the team
//! layer takes ([`team::Senses`]), lets the layer update its world models and decide who
//! goes to the ball on **its own replica's blackboard**, plays (CMUnited's modes, a pass
//! or a shot), and hands the layer's blackboard writes back ([`Robot::tick`]), so the
//! replica and the simulated network carry them.
//!
//! A robot has no truth, by construction: a tick takes [`Percepts`] (its camera frame and
//! its odometry, as the simulator made them) and its own clock; the team layer is a crate
//! of its own that cannot name the simulator's world, and its calibration
//! ([`team::Calibration`]) is the robot's, given at construction. A tick returns a
//! [`TickOutput`]: blackboard writes, a motion command and maybe a kick attempt, which the
//! simulator carries out. Whether a kick met the ball is for the world to find out; the
//! robot reports the attempt with its own probability of contact. What each ball is for:
//! - eq. (19) and the goer's approach use the robot's **own** ball relative to its own
//!   pose estimate: both come from the same sightings and the same pose, so a pose error
//!   cancels and the distance is what the camera measured (as on the seed's robots);
//! - everything else that needs the ball (formation, goalkeeper, the pass receiver, a goer
//!   that lost sight of it) uses the **team ball**, which is better than any one robot's;
//! - motion commands are meant in the robot's own frame: the world turns them into field
//!   motion with the robot's true heading (the simulator's `World::command_believed`).

use comms::arbitration::ArbitrationParams;
use comms::{Blackboard, Instant, Key, Value};
use fusion::nalgebra::Vector2;
use fusion::Kick;
use serde::Serialize;
use std::ops::{Deref, DerefMut};

use crate::perception;
pub use team::{
    pass_to_key, seconds, world_local_key, world_local_of, BallBelief, Calibration, TeamConfig,
    TeamLayer, WorldModelConfig, WORLD_LOCAL_KEY,
};

use crate::behaviour::Position;
pub use crate::play::PlayCounts;
use crate::play::{Belief, Tactician};
use crate::senses::{Frame, MotionCommand, Odometry};
use crate::tactics::PassParams;
use team::{Pose, Vec2};

/// How a robot turns sightings into a belief and a belief into play.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BrainConfig {
    /// The team layer: control period, memories, world models, sending policy.
    #[serde(flatten)]
    pub team: TeamConfig,
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
            team: TeamConfig::default(),
            shoot_range_m: 3.0,
            kick_cooldown_s: 1.0,
            pass: PassParams::default(),
        }
    }
}

/// What a robot's sensors gave it this tick: all it knows of the world outside itself.
#[derive(Debug, Clone, Default)]
pub struct Percepts {
    /// The camera frame.
    pub frame: Frame,
    /// Odometry measured over the latest control period.
    pub odometry: Odometry,
}

/// A kick the robot swings: the direction it aims, the receiver (0: a shot), and what it
/// told the team (with its own probability of contact).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KickAttempt {
    /// Field-frame direction, rad, as the robot believes the field is oriented.
    pub direction_rad: f64,
    /// The pass receiver, 0 for a shot.
    pub receiver: i64,
    /// The report it published.
    pub report: Kick,
}

/// What a tick hands back to the simulator.
#[derive(Debug, Clone)]
pub struct TickOutput {
    /// Blackboard writes to make through the robot's replica.
    pub writes: Vec<(Key, Value)>,
    /// They carry a goer change or a kick: under a budget they may use its reserve.
    pub priority: bool,
    /// The motion command, worked out in the field frame as the robot believes it is
    /// posed (`None`: carry on with the previous one).
    pub command: Option<MotionCommand>,
    /// The pose it believes (the frame `command` is meant in).
    pub believed: Pose,
    /// A kick it swings, if any.
    pub kick: Option<KickAttempt>,
}

/// What the referee lets a robot do, as the robot heard it from the GameController.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub enum Order {
    /// Play (Playing, or no referee at all).
    #[default]
    Play,
    /// Walk to its kick-off spot (Ready): its formation home in its own half, the
    /// goalkeeper to its goal.
    KickOffSpot,
    /// Stand still (Initial, Standby, Set, Finished, or penalised).
    Stand,
}

/// One of our robots: a body's senses and play around its team layer, which it derefs to
/// (its world models, its arbitration, what it told the team).
#[derive(Debug, Clone)]
pub struct Robot {
    /// Its team layer: the product's code.
    pub brain: TeamLayer,
    /// The latest camera frame.
    pub frame: Frame,
    /// Its place, mode and play.
    pub tactics: Tactician,
    /// What the referee lets it do; it keeps sensing and telling its team whatever this
    /// says (the team layer runs in every state).
    pub order: Order,
}

impl Deref for Robot {
    type Target = TeamLayer;
    fn deref(&self) -> &TeamLayer {
        &self.brain
    }
}

impl DerefMut for Robot {
    fn deref_mut(&mut self) -> &mut TeamLayer {
        &mut self.brain
    }
}

/// Everything a tick needs from outside the robot.
pub struct TickInput<'a> {
    /// The robot's own clock now (its replica's clock).
    pub local_now: Instant,
    /// What its sensors gave it.
    pub percepts: Percepts,
    /// Its replica's blackboard.
    pub board: &'a Blackboard,
    /// Its last world model written still waits for a frame (a budget's pacing holds
    /// it): the robot writes its newest again, so the frame carries what it knows when it
    /// goes rather than when it decided to send.
    pub world_model_waiting: bool,
    /// Its claim (`HEURISTIC_KEY`) written earlier still waits for a frame.
    pub claim_waiting: bool,
    /// Its replica's budget headroom (`comms::Replica::budget_headroom`), if it has a
    /// budget.
    pub budget_headroom: Option<i64>,
    /// The formation's home spots for the field positions.
    pub homes: &'a [Vec2],
    /// Robot id holding each field position.
    pub holders: &'a [u8],
}

impl Robot {
    /// A robot `id` in `position`, deciding with `params`, put at `pose` (which it is told,
    /// give or take the configured start σ), calibrated as `cal`, in a team of `team`
    /// robots.
    pub fn new(
        id: u8,
        position: Position,
        params: ArbitrationParams,
        pose: Pose,
        cal: &Calibration,
        world_model: &WorldModelConfig,
        team: usize,
    ) -> Self {
        Self {
            brain: TeamLayer::new(
                id,
                position == Position::Goalkeeper,
                params,
                pose,
                cal,
                world_model,
                team,
            ),
            frame: Frame::default(),
            tactics: Tactician::new(position),
            order: Order::Play,
        }
    }

    /// Whether it saw the ball in its latest camera frame.
    pub fn sees_ball(&self) -> bool {
        self.alive && self.frame.ball.is_some()
    }

    /// One control tick: sense, decide, act. Everything the robot knows of its field and
    /// body is its team layer's calibration ([`TeamLayer::cal`]).
    pub fn tick(&mut self, cfg: &BrainConfig, mut input: TickInput<'_>) -> TickOutput {
        let percepts = std::mem::take(&mut input.percepts);
        self.frame = percepts.frame;
        let sensors = self.brain.cal.sensors;
        let marks = self.brain.cal.field.landmarks();
        let landmarks: Vec<_> = self
            .frame
            .landmarks
            .iter()
            .map(|(k, s)| perception::landmark_sighting(&sensors, marks[*k], s))
            .collect();
        let opponents: Vec<Vector2<f64>> = self
            .frame
            .opponents
            .iter()
            .map(|s| {
                let l = s.local();
                Vector2::new(l.x, l.y)
            })
            .collect();
        let odometry = [perception::to_fusion_odometry(&percepts.odometry)];
        let ball: Vec<_> = self
            .frame
            .ball
            .iter()
            .map(|s| (perception::ball_sighting(&sensors, s), 0.0))
            .collect();
        let senses = team::Senses {
            odometry: &odometry,
            landmarks: &landmarks,
            pose: None,
            ball: &ball,
            goal_in_view: self.frame.opponent_goal_in_view,
            opponents: &opponents,
            cost: None,
        };
        let lwm_bytes = self.brain.sense(
            &cfg.team,
            input.local_now,
            &senses,
            input.board,
            input.claim_waiting,
        );
        let (decision, posted) = self.brain.decide(input.board, input.local_now);
        let pass_to = self.brain.goer_pass_to(input.board, input.local_now);
        let acts_as_goer = self.brain.acts_as_goer();
        self.tactics
            .set_mode(self.brain.id, acts_as_goer, &decision, pass_to);
        let now_s = seconds(input.local_now);
        let (receiver, command, kick) = match self.order {
            Order::Play => self.play(cfg, &input, now_s),
            Order::Stand => (0, Some(self.stand()), None),
            Order::KickOffSpot => (0, Some(self.to_kick_off_spot(&input)), None),
        };
        let (writes, priority) = self.brain.finish(
            &cfg.team,
            input.local_now,
            lwm_bytes,
            posted,
            receiver,
            kick.is_some(),
            input.world_model_waiting,
            input.claim_waiting,
            input.budget_headroom,
        );
        TickOutput {
            writes,
            priority,
            command,
            believed: self.pose_belief,
            kick,
        }
    }

    /// Between control ticks: decide again with whatever the replica heard since (see
    /// [`TeamLayer::redecide`]).
    pub fn redecide(
        &mut self,
        board: &Blackboard,
        local_now: Instant,
        world_model_waiting: bool,
    ) -> Vec<(Key, Value)> {
        self.brain.redecide(board, local_now, world_model_waiting)
    }

    /// Play on what it believes: the mode's motion, and a kick it swings (reported to
    /// its team layer at once).
    fn play(
        &mut self,
        cfg: &BrainConfig,
        input: &TickInput<'_>,
        now_s: f64,
    ) -> (i64, Option<MotionCommand>, Option<KickAttempt>) {
        let brain = &mut self.brain;
        let belief = Belief {
            cal: &brain.cal,
            pose: brain.pose_belief,
            ball: brain.best_ball(),
            own_ball: brain.ball.map(|b| b.at),
            opponents: &self.frame.opponents,
        };
        let action = self
            .tactics
            .act(cfg, &belief, now_s, input.homes, input.holders, || {
                brain.contact_probability(now_s)
            });
        // The robot knows what it just tried: its ball, and soon its team's, turns with
        // the kick (weighted by its own odds that the foot met the ball) instead of
        // waiting to see it.
        let kick = action.swing.map(|s| KickAttempt {
            direction_rad: s.direction_rad,
            receiver: s.receiver,
            report: self.brain.report_kick(
                &cfg.team,
                now_s,
                s.direction_rad,
                self.brain.cal.kick.speed_mps,
                s.contact_prob,
            ),
        });
        (action.receiver, action.command, kick)
    }

    /// Stand where it is (in the frame of [`TeamLayer::pose_belief`]).
    fn stand(&self) -> MotionCommand {
        MotionCommand {
            velocity: Vec2::default(),
            heading_rad: self.pose_belief.theta_rad,
        }
    }

    /// Walk to its kick-off spot, facing the centre: the goalkeeper to its goal line, a
    /// field player to its formation home kept in its own half.
    fn to_kick_off_spot(&self, input: &TickInput<'_>) -> MotionCommand {
        let field = self.brain.cal.field;
        let top = self.brain.cal.body.top_speed_mps;
        let pose = self.pose_belief;
        let spot = match self.tactics.position {
            Position::Goalkeeper => Vec2::new(-field.length_m / 2.0 + 0.3, 0.0),
            Position::Field(k) => {
                let home = input.homes.get(k).copied().unwrap_or_default();
                Vec2::new(home.x.min(-0.5), home.y)
            }
        };
        let facing = (Vec2::default() - spot).angle();
        crate::behaviour::go_to(&pose, spot, facing, top)
    }

    /// Switch the robot off: it falls silent. Returns the command that stops it where it
    /// is (in the frame of [`TeamLayer::pose_belief`]).
    pub fn kill(&mut self) -> MotionCommand {
        self.alive = false;
        MotionCommand {
            velocity: Vec2::default(),
            heading_rad: self.pose_belief.theta_rad,
        }
    }
}

#[cfg(test)]
#[path = "robot_tests.rs"]
mod tests;
