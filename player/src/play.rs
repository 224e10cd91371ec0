//! A tick's play from what the robot believes: its mode (CMUnited's), and for the active
//! robot the pass or shot, the approach and the kick. Shared by the robot whose team layer
//! runs in the same process ([`crate::Robot`]) and the one whose team layer runs in a
//! `huddle daemon` ([`crate::remote::RemoteRobot`]): what differs between the two is only
//! where the belief comes from, and where a kick is reported to.

use comms::arbitration::Decision;
use serde::Serialize;
use team::calibration::FieldGeometry;
use team::{Calibration, Pose, Vec2};

use crate::behaviour::{self, Position};
use crate::robot::BrainConfig;
use crate::senses::{MotionCommand, Sighting};
use crate::tactics::{choose_play, mode, Mode, Play};

/// Counts of what the active robots tried (whether the foot met the ball is the world's
/// business: see the simulation's counts).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct PlayCounts {
    /// Shots attempted.
    pub shots: u32,
    /// Passes attempted.
    pub passes: u32,
}

/// What the play of a tick rests on: the robot's beliefs, whoever holds them.
#[derive(Debug, Clone, Copy)]
pub struct Belief<'a> {
    /// What the robot knows of its field, body, ball and kick.
    pub cal: &'a Calibration,
    /// Its pose estimate.
    pub pose: Pose,
    /// The best ball it has: the team ball, else its own.
    pub ball: Option<Vec2>,
    /// Its own ball (its sightings relative to its own pose), while it is recent.
    pub own_ball: Option<Vec2>,
    /// Opponents its camera sees now.
    pub opponents: &'a [Sighting],
}

/// A kick the robot decided to swing: where to, for whom, with what odds of contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Swing {
    /// Field-frame direction, rad, as the robot believes the field is oriented.
    pub direction_rad: f64,
    /// The pass receiver, 0 for a shot.
    pub receiver: i64,
    /// Its own odds that the foot meets the ball.
    pub contact_prob: f64,
}

/// What one tick of play gives back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Action {
    /// The pass receiver the robot announces (0: none).
    pub receiver: i64,
    /// The motion command (`None`: carry on with the previous one).
    pub command: Option<MotionCommand>,
    /// A kick it swings now.
    pub swing: Option<Swing>,
}

/// A robot's play: its place in the team, its mode, what it chose, what it tried.
#[derive(Debug, Clone)]
pub struct Tactician {
    /// Its place in the formation.
    pub position: Position,
    /// Its CMUnited mode.
    pub mode: Mode,
    /// The play it has chosen while active.
    pub play: Option<Play>,
    /// Shots and passes kicked.
    pub counts: PlayCounts,
    kick_ready_at_s: f64,
}

impl Tactician {
    /// A robot in `position`, inactive until its first decision.
    pub fn new(position: Position) -> Self {
        Self {
            position,
            mode: Mode::Inactive,
            play: None,
            counts: PlayCounts::default(),
            kick_ready_at_s: 0.0,
        }
    }

    /// Whether it keeps goal.
    pub fn goalkeeper(&self) -> bool {
        self.position == Position::Goalkeeper
    }

    /// The mode of robot `id` for this tick: `acts_as_goer` (the team layer says it
    /// plays the ball), else the decision and the goer's announced receiver.
    pub fn set_mode(
        &mut self,
        id: u8,
        acts_as_goer: bool,
        decision: &Decision,
        pass_to: Option<u8>,
    ) {
        let goalkeeper = self.goalkeeper();
        self.mode = if goalkeeper {
            Mode::Goaltend
        } else if acts_as_goer {
            Mode::Active
        } else {
            match mode(id, goalkeeper, decision, pass_to) {
                Mode::Active => Mode::Inactive, // still listening after a start
                m => m,
            }
        };
    }

    /// Move (and maybe kick) according to the mode. `contact_probability` is asked only
    /// when the robot is lined up for a kick: its own odds that the foot meets the ball.
    pub fn act(
        &mut self,
        cfg: &BrainConfig,
        belief: &Belief<'_>,
        now_s: f64,
        homes: &[Vec2],
        holders: &[u8],
        contact_probability: impl FnOnce() -> f64,
    ) -> Action {
        let field: &FieldGeometry = &belief.cal.field;
        let top = belief.cal.body.top_speed_mps;
        let pose = belief.pose;
        let ball = belief.ball;
        let my_home = |k: usize| behaviour::flexible_home(field, homes[k], ball);
        let cmd = match (self.mode, self.position) {
            (_, Position::Goalkeeper) => behaviour::keep_goal(field, &pose, ball, top),
            (Mode::Active, Position::Field(k)) => {
                // Its own ball, relative to its own pose: the geometry the camera measured.
                // No ball at all: it carries on as it was.
                let Some(b) = belief.own_ball.or(ball) else {
                    return Action {
                        receiver: 0,
                        command: None,
                        swing: None,
                    };
                };
                let goal = field.opponent_goal();
                let receivers: Vec<(u8, Vec2)> = behaviour::receivers_of(homes, k)
                    .into_iter()
                    .map(|j| {
                        let at = behaviour::flexible_home(field, homes[j], ball);
                        (holders[j], at)
                    })
                    .collect();
                let opponents: Vec<Vec2> = belief
                    .opponents
                    .iter()
                    .map(|s| pose.to_field(s.local()))
                    .collect();
                let play = choose_play(&cfg.pass, b, goal, &receivers, &opponents);
                self.play = Some(play);
                let (aim, receiver) = match play {
                    Play::Pass { to, .. } => {
                        let at = receivers.iter().find(|r| r.0 == to).map_or(goal, |r| r.1);
                        (at, i64::from(to))
                    }
                    Play::Shoot { .. } => (goal, 0),
                };
                let contact = belief.cal.body.radius_m + belief.cal.ball.radius_m;
                let action = behaviour::approach_and_push(contact, &pose, b, aim, top);
                let in_range = receiver != 0 || b.distance(goal) <= cfg.shoot_range_m;
                let mut swing = None;
                if action.lined_up && in_range && now_s >= self.kick_ready_at_s {
                    let contact_prob = contact_probability();
                    if contact_prob >= cfg.team.world_model.kick_min_contact_prob {
                        self.kick_ready_at_s = now_s + cfg.kick_cooldown_s;
                        if receiver != 0 {
                            self.counts.passes += 1;
                        } else {
                            self.counts.shots += 1;
                        }
                        swing = Some(Swing {
                            direction_rad: (aim - b).angle(),
                            receiver,
                            contact_prob,
                        });
                    }
                }
                return Action {
                    receiver,
                    command: Some(action.motion),
                    swing,
                };
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
        Action {
            receiver: 0,
            command: Some(cmd),
            swing: None,
        }
    }
}
