//! One of our robots as the simulator runs it: what it sensed, what it believes, what it
//! decided and what it does. Each control tick it reads its camera and odometry, computes
//! eq. (19), reads its teammates' costs from **its own replica's blackboard**, decides with
//! `comms::arbitration`, and acts. Everything it tells the team goes back out as
//! blackboard writes (returned by [`Robot::tick`]), so the replica and the simulated
//! network carry it.
//!
//! A robot has no truth, by construction: this module never sees the simulator's
//! [`World`](crate::field::World). A tick takes [`Percepts`] (its camera frame and its
//! odometry, as the simulator made them) and its own clock, and returns a [`TickOutput`]:
//! blackboard writes, a motion command and maybe a kick attempt, which the simulator
//! carries out. Whether a kick met the ball is for the world to find out; the robot
//! reports the attempt with its own probability of contact. Its pose is its local world model's (`fusion::LocalModel`: a pose
//! EKF on its noisy odometry and landmark sightings), its ball is its own ball EKF, and the
//! team ball is its global world model's (`fusion::GlobalModel`), fused from the LWMs its
//! teammates publish as `*.var.world.local` and its replica hands it with receiver-side
//! ages. What each is used for:
//! - eq. (19) and the goer's approach use the robot's **own** ball relative to its own
//!   pose estimate: both come from the same sightings and the same pose, so a pose error
//!   cancels and the distance is what the camera measured (as on the seed's robots);
//! - everything else that needs the ball (formation, goalkeeper, the pass receiver, a goer
//!   that lost sight of it) uses the **team ball**, which is better than any one robot's;
//! - motion commands are meant in the robot's own frame: the world turns them into field
//!   motion with the robot's true heading ([`World::command_believed`](crate::field::World::command_believed)).

use comms::arbitration::{self, heuristic, Arbiter, ArbitrationParams, BallView, Decision, Posted};
use comms::{Blackboard, Instant, Key, Scope, Value};
use fusion::nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use fusion::{BallSighting, GlobalModel, Kick, LocalModel, TeamBall};
use serde::Serialize;
use std::time::Duration;

use super::perception;
use super::policy::Action;
pub use super::world_model::WorldModelConfig;

use crate::field::behaviour::{self, Position};
use crate::field::body::{MotionCommand, Odometry};
use crate::field::camera::Frame;
use crate::field::geometry::{Pose, Vec2};
use crate::field::tactics::{self, choose_play, mode, Mode, PassParams, Play};
use crate::field::{FieldConfig, KICK_MAX_ANGLE_RAD, KICK_REACH_MARGIN_M};

/// Where a teammate is and how it moves, from its messages.
#[derive(Debug, Clone, Copy, PartialEq)]
struct TeammateMotion {
    /// The time and place its velocity was last measured to (field frame).
    anchor: (f64, Vector2<f64>),
    /// That velocity, m/s.
    velocity: Vector2<f64>,
    /// Its latest pose's place.
    at: Vector2<f64>,
}

/// A teammate's velocity is measured between its messages' poses at least this far apart,
/// s.
const TEAMMATE_VELOCITY_BASELINE_S: f64 = 0.2;

/// The key the active robot announces its intended pass receiver on (`Int`, 0 = shot).
pub fn pass_to_key() -> Key {
    Key::parse(tactics::PASS_TO_KEY).expect("PASS_TO_KEY is a valid key")
}

/// Where every robot publishes its LWM (`Bytes`, [`fusion::LWM_WIRE_LEN`] of them).
pub const WORLD_LOCAL_KEY: &str = "*.var.world.local";

/// The key every robot publishes its LWM to ([`WORLD_LOCAL_KEY`]).
pub fn world_local_key() -> Key {
    Key::parse(WORLD_LOCAL_KEY).expect("a valid key")
}

/// A robot clock reading in seconds.
pub fn seconds(t: Instant) -> f64 {
    t.as_micros() as f64 * 1e-6
}

/// The key robot `id`'s LWM is held under on a teammate's blackboard.
pub fn world_local_of(id: u8) -> Key {
    Key::new(Scope::Robot(id), comms::Kind::Var, "world.local").expect("a valid key")
}

/// How a robot turns sightings into a belief and a belief into play.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BrainConfig {
    /// Control period, seconds (one camera frame per tick).
    pub control_period_s: f64,
    /// A ball not seen for longer than this is forgotten (`f_ball` = 0), seconds.
    pub ball_memory_s: f64,
    /// The opponent goal counts as in view if seen within this long, seconds (one missed
    /// detection must not add |k1| to the cost).
    pub goal_memory_s: f64,
    /// The active robot shoots when the goal is this close, metres; farther, it pushes.
    pub shoot_range_m: f64,
    /// Time between two kicks of one robot, seconds.
    pub kick_cooldown_s: f64,
    /// The team ball is used when its global ball confidence (GBC) is at least this
    /// (0.25: a 1-σ radius of about 0.5 m); below, the robot goes by its own ball or looks
    /// for it.
    pub team_ball_min_gbc: f64,
    /// Pass or shot: the constants of the obstruction-free-index.
    #[serde(skip)]
    pub pass: PassParams,
    /// The world models.
    #[serde(skip)]
    pub world_model: WorldModelConfig,
    /// When the robot tells the team what it knows.
    pub send_policy: super::policy::SendPolicy,
}

impl Default for BrainConfig {
    fn default() -> Self {
        Self {
            control_period_s: 0.04,
            ball_memory_s: 0.5,
            goal_memory_s: 0.15,
            shoot_range_m: 3.0,
            kick_cooldown_s: 1.0,
            team_ball_min_gbc: 0.25,
            pass: PassParams::default(),
            world_model: WorldModelConfig::default(),
            send_policy: super::policy::SendPolicy::Every,
        }
    }
}

/// A robot's idea of where the ball is, from its own sightings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct BallBelief {
    /// Its own ball EKF's position now, field frame, metres.
    pub at: Vec2,
    /// When it was last seen, seconds on the robot's clock.
    pub seen_at_s: f64,
}

/// Counts of what the active robots tried (whether the foot met the ball is the world's
/// business: see the simulation's counts).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct PlayCounts {
    /// Shots attempted.
    pub shots: u32,
    /// Passes attempted.
    pub passes: u32,
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
    /// Where it believes it is (its LWM's pose).
    pub pose_belief: Pose,
    /// Where it believes the ball is from its own sightings, if it has seen it recently.
    pub ball: Option<BallBelief>,
    /// Its local world model.
    pub lwm: LocalModel,
    /// Its global world model.
    pub gwm: GlobalModel,
    /// Messages are sparse (a league's budget): publish the compact LWM, which leaves room
    /// for the arbitration's cost in a 128-byte frame (teammates take the track, not the
    /// batches).
    compact: bool,
    /// The lowest effective cost among teammates at the latest decision.
    rival_cost: Option<f64>,
    /// A claim change written between ticks that has not gone out yet (a budget's pacing
    /// holds it): a goer that stopped keeps going until its team can know (see
    /// [`Robot::going`]).
    untold_claim: Option<Posted>,
    /// … and whether one of them claimed to be going.
    rival_going: bool,
    /// The team ball at its latest tick (when its GBC is high enough to use).
    pub team_ball: Option<TeamBall>,
    /// The team ball at its latest tick whatever its GBC, as the robot holds it (widened
    /// at contact, see [`WorldModelConfig::contact_horizon_s`]).
    pub team_ball_held: Option<TeamBall>,
    /// The kick it attempted at its latest tick, if any.
    pub kicked: Option<Kick>,
    /// Its ball sighting of the latest tick, in `fusion`'s robot frame.
    pub ball_sighting: Option<BallSighting>,
    /// When it last saw the opponent goal, seconds.
    pub goal_seen_at_s: Option<f64>,
    /// When it last saw the ball, seconds.
    pub ball_seen_at_s: Option<f64>,
    /// Its latest cost, eq. (19).
    pub h: f64,
    /// The team decision as it sees it.
    pub decision: Decision,
    /// The teammates' claims it decided on last, those with a ball (cost below the
    /// no-ball cost): (robot, receiver-side age).
    pub claim_ages: Vec<(u8, Duration)>,
    /// Its CMUnited mode.
    pub mode: Mode,
    /// The play it has chosen while active.
    pub play: Option<Play>,
    /// Shots and passes kicked.
    pub counts: PlayCounts,
    /// Whether it is switched on (a dead robot neither senses, decides nor sends).
    pub alive: bool,
    pass_to_posted: i64,
    /// The world model of the latest tick, as published (written or not).
    latest_lwm: Option<Value>,
    kick_ready_at_s: f64,
    push_reported_at_s: f64,
    decided_at_s: f64,
    /// Per teammate (index = id − 1): the (incarnation, version) of its LWM fed last.
    heard: Vec<Option<(u64, u64)>>,
    /// Per teammate (index = id − 1): the time and place of the message its velocity was
    /// last measured to, and that velocity (field frame).
    teammate_motion: Vec<Option<TeammateMotion>>,
    /// What it last told the team, for the sending policy.
    policy: super::policy::PolicyState,
    /// The acoustic fallback, when the team uses it (see [`super::acoustic`]).
    pub sound: Option<super::acoustic::SoundFallback>,
    /// Whether it goes by the fallback's decision while the radio is silent (`None`: the
    /// arbiter decides).
    sound_going: Option<bool>,
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
    /// give or take the configured start σ), in a team of `team` robots.
    pub fn new(
        id: u8,
        position: Position,
        params: ArbitrationParams,
        pose: Pose,
        world_model: &WorldModelConfig,
        team: usize,
    ) -> Self {
        let start = perception::to_fusion_pose(
            &pose,
            Matrix3::from_diagonal(&Vector3::new(
                world_model.start_sigma_m.powi(2),
                world_model.start_sigma_m.powi(2),
                world_model.start_sigma_rad.powi(2),
            )),
        );
        Self {
            id,
            position,
            arbiter: Arbiter::new(id, position == Position::Goalkeeper, params),
            frame: Frame::default(),
            odometry: Odometry::default(),
            pose_belief: pose,
            ball: None,
            lwm: LocalModel::new(world_model.local, start),
            gwm: GlobalModel::new(id, world_model.global),
            compact: world_model.global.track_after_s.is_some(),
            rival_cost: None,
            untold_claim: None,
            rival_going: false,
            kicked: None,
            team_ball: None,
            team_ball_held: None,
            ball_sighting: None,
            goal_seen_at_s: None,
            ball_seen_at_s: None,
            h: params.no_ball_cost,
            decision: Decision {
                goer: None,
                goer_cost: f64::INFINITY,
            },
            claim_ages: Vec::new(),
            mode: Mode::Inactive,
            play: None,
            counts: PlayCounts::default(),
            alive: true,
            pass_to_posted: 0,
            latest_lwm: None,
            kick_ready_at_s: 0.0,
            push_reported_at_s: f64::NEG_INFINITY,
            decided_at_s: 0.0,
            heard: vec![None; team],
            teammate_motion: vec![None; team],
            policy: Default::default(),
            sound: None,
            sound_going: None,
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
    ///
    /// A goer that decided to stop while its "not going" waits for a frame goes on: its
    /// teammates still hold its claim and none of them goes, so stopping unannounced
    /// would leave the ball to nobody.
    pub fn going(&self) -> bool {
        self.alive && self.acts_as_goer()
    }

    /// Whether it decided to go: by the fallback while the radio is silent, else by the
    /// arbiter.
    fn claims_ball(&self) -> bool {
        self.sound_going.unwrap_or_else(|| self.arbiter.going())
    }

    /// Whether it plays the ball: it claims it, or it stopped claiming while no teammate
    /// claims and its teammates have not heard the stop yet.
    fn acts_as_goer(&self) -> bool {
        self.claims_ball() || (!self.rival_going && self.untold_claim.is_some_and(|c| !c.going))
    }

    /// One control tick: sense, decide, act. `field` is what the robot knows of the field
    /// beforehand (its geometry, its own body and sensors' calibration).
    pub fn tick(
        &mut self,
        field: &FieldConfig,
        cfg: &BrainConfig,
        mut input: TickInput<'_>,
    ) -> TickOutput {
        let t = seconds(input.local_now);
        self.kicked = None;
        if !input.claim_waiting {
            self.untold_claim = None;
        }
        let percepts = std::mem::take(&mut input.percepts);
        self.frame = percepts.frame;
        self.odometry = percepts.odometry;
        let lwm_bytes = self.perceive(field, cfg, &input);
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
        } else if self.acts_as_goer() {
            Mode::Active
        } else {
            match mode(self.id, goalkeeper, &decision, pass_to) {
                Mode::Active => Mode::Inactive, // still listening after a start
                m => m,
            }
        };

        let mut writes = vec![(arbitration::heuristic_key(), Value::from(posted))];
        if self.compact {
            // Only a budget's ride-along reads it (see `redecide`).
            self.latest_lwm.clone_from(&lwm_bytes);
        }
        if let Some(bytes) = lwm_bytes {
            writes.push((world_local_key(), bytes));
        }
        let (receiver, command, kick) = self.act(field, cfg, &input);
        let receiver_changed = receiver != self.pass_to_posted;
        let now = super::policy::Now {
            t_s: t,
            pose: self.pose_belief,
            ball: self.ball.and(self.lwm.ball_at(t)),
            going: self.claims_ball(),
            team_ball_stale: self.team_ball.is_none(),
            kicked: kick.is_some(),
            model: &cfg.world_model.local.ball.model,
            // What teammates last told the team about the ball: the freshest track heard.
            // (Only VOI weighs it: no copy of every teammate's model per tick for the rest.)
            told: (cfg.send_policy == super::policy::SendPolicy::Voi)
                .then(|| {
                    self.gwm
                        .teammates(t)
                        .iter()
                        .filter_map(|m| m.lwm.ball)
                        .max_by(|a, b| a.t_s.total_cmp(&b.t_s))
                })
                .flatten(),
            headroom: input.budget_headroom,
            gate_chi2: self.gwm.config().gate_chi2,
            cost: self.arbiter.params().effective_cost(&posted),
            h: posted.h,
            rival_cost: self.rival_cost,
            rival_going: self.rival_going,
            keepalive_s: self
                .compact
                .then(|| self.arbiter.params().stale_after.as_secs_f64() / 2.0),
            frame_anyway: receiver_changed,
        };
        let action = self.policy.decide(
            cfg.send_policy,
            &now,
            input.world_model_waiting,
            input.claim_waiting,
        );
        if self.compact {
            // Sparse messages: decide on the claim teammates hold (see `set_told`).
            self.arbiter.set_told(self.policy.told());
        }
        let priority = action == (Action::Send { priority: true });
        match action {
            // The claim written with the world model is the newest.
            Action::Send { .. } => self.untold_claim = None,
            Action::Quiet => writes.clear(),
        }
        if receiver_changed {
            self.pass_to_posted = receiver;
            writes.push((pass_to_key(), Value::Int(receiver)));
        }
        TickOutput {
            writes,
            priority,
            command,
            believed: self.pose_belief,
            kick,
        }
    }

    /// Run the arbitration on the current cost and what the replica has heard (by the
    /// acoustic fallback's claims while the radio is silent).
    fn decide(&mut self, t_s: f64, board: &Blackboard, local_now: Instant) -> (Decision, Posted) {
        let heard = arbitration::heard(board, local_now);
        let dt = Duration::from_secs_f64((t_s - self.decided_at_s).max(0.0));
        self.decided_at_s = t_s;
        let stale_after = self.arbiter.params().stale_after;
        let fallback = self.sound.as_mut().and_then(|sound| {
            sound
                .radio(self.id, &heard, stale_after)
                .then(|| sound.candidates(self.id, t_s, &heard))
        });
        let (decision, posted) = match fallback {
            None => {
                self.sound_going = None;
                let (decision, posted) = self.arbiter.tick(dt, self.h, &heard);
                if let Some(sound) = &mut self.sound {
                    sound.posted(t_s, posted);
                }
                (decision, posted)
            }
            Some(claims) => {
                let decision = self
                    .sound
                    .as_ref()
                    .map_or(self.decision, |s| s.decide(&claims));
                // The arbiter follows on the same claims, so that it carries on from
                // about the same place when the radio comes back.
                let (_, mut posted) = self.arbiter.tick(dt, self.h, &claims);
                posted.going = self.is_field_player() && decision.should_go(self.id);
                self.sound_going = Some(posted.going);
                (decision, posted)
            }
        };
        self.decision = decision;
        let params = *self.arbiter.params();
        let rivals = || {
            heard
                .iter()
                .filter(|c| c.robot != self.id && params.counts(c))
        };
        // With no teammate in the running, the bar to beat is the no-ball cost: a robot
        // that told "no ball" and now sees one has news.
        self.rival_cost = rivals()
            .map(|c| params.effective_cost(&c.posted))
            .min_by(f64::total_cmp)
            .or(Some(params.no_ball_cost));
        self.rival_going = rivals().any(|c| c.posted.going);
        self.claim_ages.clear();
        self.claim_ages.extend(
            heard
                .iter()
                .filter(|c| c.robot != self.id && c.posted.h < self.arbiter.params().no_ball_cost)
                .map(|c| (c.robot, c.age)),
        );
        (decision, posted)
    }

    /// Between control ticks: decide again on the latest cost with whatever the replica
    /// heard since (a robot reacts to a teammate's claim when it arrives, not at its next
    /// camera frame); `t_s` is the robot's clock in seconds. Returns the writes to make if
    /// its claim changed: the claim, with priority, and under a budget its latest tick's
    /// world model when none waits already (`world_model_waiting`) and that tick's did
    /// not go: the claim's frame is spent anyway.
    pub fn redecide(
        &mut self,
        t_s: f64,
        board: &Blackboard,
        local_now: Instant,
        world_model_waiting: bool,
    ) -> Vec<(Key, Value)> {
        if !self.alive {
            return Vec::new();
        }
        let was = self.claims_ball();
        let (_, posted) = self.decide(t_s, board, local_now);
        if posted.going == was {
            return Vec::new();
        }
        let mut writes = vec![(arbitration::heuristic_key(), Value::from(posted))];
        let cost = self.arbiter.params().effective_cost(&posted);
        if self.compact {
            // Told once it went out (see `Arbiter::set_told`).
            self.policy.wrote_claim(posted.going, posted.h, cost);
            self.untold_claim = Some(posted);
            if let Some(lwm) = self.latest_lwm.clone() {
                if !world_model_waiting && self.policy.world_model_rides() {
                    writes.push((world_local_key(), lwm));
                }
            }
        } else {
            self.policy.sent_going(posted.going, posted.h, cost);
        }
        writes
    }

    /// What this robot sounds if its slot begins now (`t_s`, its clock): its claim while
    /// the radio is stale.
    pub fn sound_claim(&mut self, t_s: f64) -> Option<audio::Message> {
        if !self.alive {
            return None;
        }
        let posted = Posted {
            h: self.h,
            going: self.claims_ball(),
        };
        self.sound.as_mut()?.claim(self.id, posted, t_s)
    }

    /// A message this robot's microphone decoder produced, its start on this robot's
    /// clock, s.
    pub fn hear_sound(&mut self, message: &audio::Message, start_s: f64) {
        if let (Some(sound), true) = (&mut self.sound, self.alive) {
            sound.hear(self.id, message, start_s);
        }
    }

    /// The world models' part of a tick: odometry and landmarks into the pose EKF, the ball
    /// sighting into the ball EKF, teammates' new LWMs into the GWM, then publish. Returns
    /// the LWM to write to `*.var.world.local`.
    fn perceive(
        &mut self,
        field: &FieldConfig,
        cfg: &BrainConfig,
        input: &TickInput<'_>,
    ) -> Option<Value> {
        let wm = &cfg.world_model;
        let cam = field.camera;
        let now_s = seconds(input.local_now);
        let pf = self.lwm.pose_filter_mut();
        pf.noise.q =
            perception::odometry_q(&self.odometry, field.odometry_noise_frac, wm.push_sigma_m);
        pf.odometry(&perception::to_fusion_odometry(&self.odometry));
        let landmarks = field.landmarks();
        for (k, s) in &self.frame.landmarks {
            let (sighting, r) = perception::landmark_sighting(&cam, landmarks[*k], s);
            pf.noise.r_range_bearing = r;
            // A degenerate sighting (the robot on the landmark) is skipped.
            let _ = pf.range_bearing(&sighting);
        }
        self.pose_belief = perception::from_fusion_pose(self.lwm.pose());

        self.ball_sighting = self.frame.ball.map(|s| perception::ball_sighting(&cam, &s));
        if let Some(s) = &self.ball_sighting {
            self.lwm.ball_sighting(now_s, s);
            self.ball_seen_at_s = Some(now_s);
        }
        let recent = self
            .ball_seen_at_s
            .filter(|&seen| now_s - seen <= cfg.ball_memory_s);
        let own = self.lwm.ball_at(now_s);
        self.ball = recent.and_then(|seen_at_s| {
            own.map(|b| BallBelief {
                at: perception::from_fusion_point(&b.position()),
                seen_at_s,
            })
        });

        for j in 0..self.heard.len() {
            let id = crate::harness::robot_id(j);
            if id == self.id {
                continue;
            }
            let Some(e) = input.board.get(&world_local_of(id)) else {
                continue;
            };
            if self.heard[j] == Some((e.incarnation, e.version)) {
                continue;
            }
            self.heard[j] = Some((e.incarnation, e.version));
            if let Value::Bytes(bytes) = &e.value {
                let age_s = e.age(input.local_now).as_secs_f64();
                // A malformed message is the sender's bug; the GWM just does not take it.
                if let Ok(lwm) = self.gwm.decode(bytes, now_s, age_s) {
                    self.gwm.ingest(id, &lwm, now_s);
                }
            }
        }
        if let Some(push) = self.push_report(field, cfg, now_s) {
            // Its own ball, and with the next message its team's, turns with the push
            // instead of several sightings later (as with a kick).
            self.lwm.kick(&push);
            self.kicked = Some(push);
            self.push_reported_at_s = now_s;
        }
        let msg = self.lwm.publish(now_s);
        self.gwm.ingest(self.id, &msg, now_s);
        self.track_teammates(now_s);
        self.team_ball_held = self
            .gwm
            .team_ball(now_s, own.as_ref())
            .map(|b| self.widened_at_contact(field, cfg, now_s, b));
        self.team_ball = self
            .team_ball_held
            .filter(|b| b.gbc >= cfg.team_ball_min_gbc);
        if self.compact {
            msg.to_compact_bytes()
                .ok()
                .map(|b| Value::Bytes(b.to_vec()))
        } else {
            msg.to_bytes().ok().map(|b| Value::Bytes(b.to_vec()))
        }
    }

    /// Each teammate's velocity from its messages' poses at least
    /// [`TEAMMATE_VELOCITY_BASELINE_S`] apart (over one message interval a pose's noise
    /// would swamp it; what the GWM keeps is the latest pose only).
    fn track_teammates(&mut self, now_s: f64) {
        for t in self.gwm.teammates(now_s) {
            let Some(slot) = usize::from(t.id)
                .checked_sub(1)
                .and_then(|k| self.teammate_motion.get_mut(k))
            else {
                continue;
            };
            let (t_s, at) = (t.lwm.t_s, Vector2::new(t.pose.mean.x, t.pose.mean.y));
            *slot = Some(match *slot {
                Some(m) if t_s >= m.anchor.0 && t_s - m.anchor.0 < TEAMMATE_VELOCITY_BASELINE_S => {
                    TeammateMotion { at, ..m }
                }
                Some(m)
                    if t_s > m.anchor.0
                        && t_s - m.anchor.0 < 4.0 * TEAMMATE_VELOCITY_BASELINE_S =>
                {
                    TeammateMotion {
                        anchor: (t_s, at),
                        velocity: (at - m.anchor.1) / (t_s - m.anchor.0),
                        at,
                    }
                }
                _ => TeammateMotion {
                    anchor: (t_s, at),
                    velocity: Vector2::zeros(),
                    at,
                },
            });
        }
    }

    /// Its own velocity over the latest control period, field frame: odometry turned by
    /// the heading halfway through it.
    fn own_velocity(&self, cfg: &BrainConfig) -> Vector2<f64> {
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
    fn widened_at_contact(
        &self,
        field: &FieldConfig,
        cfg: &BrainConfig,
        now_s: f64,
        mut ball: TeamBall,
    ) -> TeamBall {
        let wm = &cfg.world_model;
        if wm.contact_horizon_s <= 0.0 && wm.kick_hazard_per_s <= 0.0 {
            return ball;
        }
        let (at, v_ball) = (ball.estimate.position(), ball.estimate.velocity());
        let reach = |radius: f64| radius + field.ball.radius_m + wm.contact_margin_m;
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
        let ours = field.kinematics.radius_m;
        let mut var = sigma(
            Vector2::new(own.mean.x, own.mean.y),
            self.own_velocity(cfg),
            ours,
        )
        .powi(2);
        for (k, m) in self.teammate_motion.iter().enumerate() {
            if crate::harness::robot_id(k) == self.id {
                continue;
            }
            if let Some(m) = m {
                var += sigma(m.at, m.velocity, ours).powi(2);
            }
        }
        let top = field.opponent_kinematics.top_speed_mps;
        for s in &self.frame.opponents {
            let p = perception::to_fusion_point(self.pose_belief.to_field(s.local()));
            // Its velocity is unknown: as if it came straight at the ball at top speed.
            let towards = (at - p).try_normalize(1e-9).unwrap_or_else(Vector2::zeros) * top;
            var += sigma(p, towards, field.opponent_kinematics.radius_m).powi(2);
        }
        var += self.unheard_kicks_var(field, wm, now_s, at);
        if var > 0.0 {
            ball.estimate.cov[(0, 0)] += var;
            ball.estimate.cov[(1, 1)] += var;
            ball.gbc = fusion::position_confidence(&ball.estimate.position_cov());
        }
        ball
    }

    /// Per-axis variance of the kicks teammates at the ball (their latest messages put
    /// them within a foot's reach of the ball they saw, or of `at`) may have made since those messages'
    /// snapshots, that no report has brought yet: a kick at a uniform instant in the
    /// unheard window w, with probability λw (λ = [`WorldModelConfig::kick_hazard_per_s`]),
    /// would have carried the ball v(w − τ) in a direction nobody here knows yet, so
    /// E|Δ|² = λ v² w³ / 3, half per axis. A beacon hold makes w two beacons long, and
    /// that is when a teammate's kick is most surprising.
    fn unheard_kicks_var(
        &self,
        field: &FieldConfig,
        wm: &WorldModelConfig,
        now_s: f64,
        at: Vector2<f64>,
    ) -> f64 {
        if wm.kick_hazard_per_s <= 0.0 {
            return 0.0;
        }
        let reach = field.kinematics.radius_m
            + field.ball.radius_m
            + KICK_REACH_MARGIN_M
            + wm.contact_margin_m;
        let v = field.kick_speed_mps;
        self.gwm
            .teammates(now_s)
            .iter()
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

    /// The team ball if there is a usable one, else the robot's own.
    fn best_ball(&self) -> Option<Vec2> {
        self.team_ball
            .map(|b| perception::from_fusion_point(&b.estimate.position()))
            .or(self.ball.map(|b| b.at))
    }

    /// Move (and maybe kick) according to the mode; returns the pass receiver to
    /// announce (0: none), the motion command and a kick attempt.
    fn act(
        &mut self,
        field: &FieldConfig,
        cfg: &BrainConfig,
        input: &TickInput<'_>,
    ) -> (i64, Option<MotionCommand>, Option<KickAttempt>) {
        let now_s = seconds(input.local_now);
        let top = field.kinematics.top_speed_mps;
        let pose = self.pose_belief;
        let ball = self.best_ball();
        let own_ball = self.ball.map(|b| b.at);
        let my_home = |k: usize| behaviour::flexible_home(field, input.homes[k], ball);
        let cmd = match (self.mode, self.position) {
            (_, Position::Goalkeeper) => behaviour::keep_goal(field, &pose, ball, top),
            (Mode::Active, Position::Field(k)) => {
                // Its own ball, relative to its own pose: the geometry the camera measured.
                // No ball at all: it carries on as it was.
                let Some(b) = own_ball.or(ball) else {
                    return (0, None, None);
                };
                let goal = field.opponent_goal();
                let receivers: Vec<(u8, Vec2)> = behaviour::receivers_of(input.homes, k)
                    .into_iter()
                    .map(|j| {
                        let at = behaviour::flexible_home(field, input.homes[j], ball);
                        (input.holders[j], at)
                    })
                    .collect();
                let opponents: Vec<Vec2> = self
                    .frame
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
                let action = behaviour::approach_and_push(field, &pose, b, aim, top);
                let in_range = receiver != 0 || b.distance(goal) <= cfg.shoot_range_m;
                let direction_rad = (aim - b).angle();
                let mut attempt = None;
                if action.lined_up && in_range && now_s >= self.kick_ready_at_s {
                    let contact_prob = self.contact_probability(field, now_s);
                    if contact_prob >= cfg.world_model.kick_min_contact_prob {
                        // The robot knows what it just tried: its ball, and soon its
                        // team's, turns with the kick (weighted by its own odds that the
                        // foot met the ball) instead of waiting to see it.
                        let kick = Kick {
                            t_s: now_s,
                            speed_mps: field.kick_speed_mps,
                            direction_rad,
                            speed_sigma_mps: cfg.world_model.kick_speed_sigma_mps,
                            direction_sigma_rad: field.kick_noise_rad,
                            contact_prob,
                        };
                        self.lwm.kick(&kick);
                        self.kicked = Some(kick);
                        self.kick_ready_at_s = now_s + cfg.kick_cooldown_s;
                        if receiver != 0 {
                            self.counts.passes += 1;
                        } else {
                            self.counts.shots += 1;
                        }
                        attempt = Some(KickAttempt {
                            direction_rad,
                            receiver,
                            report: kick,
                        });
                    }
                }
                return (receiver, Some(action.motion), attempt);
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
        (0, Some(cmd), None)
    }

    /// A push of the ball by the robot's own body over the latest control period, as the
    /// robot knows it: its own velocity from odometry, its own ball estimate relative to
    /// its own pose. When the ball is at its body (its odds of touching, from both
    /// estimates' uncertainty, at least [`WorldModelConfig::push_min_contact_prob`]) and
    /// the body closed in on it, the ball takes `push_gain` × the closing speed along the
    /// contact normal: reported as a [`Kick`] with those odds as its contact probability,
    /// so every filter takes it as the mixture "pushed or not". Opponents' pushes are not
    /// known to anyone: the ball model's noise covers them.
    fn push_report(&self, field: &FieldConfig, cfg: &BrainConfig, now_s: f64) -> Option<Kick> {
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
        let touch = field.kinematics.radius_m + field.ball.radius_m;
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
    fn contact_probability(&self, field: &FieldConfig, now_s: f64) -> f64 {
        let Some(ball) = self.lwm.ball_at(now_s) else {
            return 0.0;
        };
        let pose = self.lwm.pose();
        // The simulator's heading (x forward), from fusion's (y forward).
        let (sin, cos) = perception::from_fusion_pose(pose).theta_rad.sin_cos();
        // Field → robot frame, x forward.
        let rot = Matrix2::new(cos, sin, -sin, cos);
        let d_field = ball.position() - Vector2::new(pose.mean.x, pose.mean.y);
        let rel = rot * d_field;
        let cov_field = ball.position_cov() + pose.cov.fixed_view::<2, 2>(0, 0);
        let mut cov = rot * cov_field * rot.transpose();
        // The heading's σ moves the ball sideways by its distance.
        cov[(1, 1)] += rel.norm_squared() * pose.cov[(2, 2)];
        let reach = field.kinematics.radius_m + field.ball.radius_m + KICK_REACH_MARGIN_M;
        let d = rel.norm();
        let along = if d > 1e-9 {
            rel / d
        } else {
            Vector2::new(1.0, 0.0)
        };
        let sigma_d = (along.transpose() * cov * along)[(0, 0)].max(1e-12).sqrt();
        let p_range = fusion::consistency::normal_cdf((reach - d) / sigma_d);
        let lateral_room = rel.x.max(0.0) * KICK_MAX_ANGLE_RAD.tan() - rel.y.abs();
        let p_angle = fusion::consistency::normal_cdf(lateral_room / cov[(1, 1)].max(1e-12).sqrt());
        (p_range * p_angle).clamp(0.0, 1.0)
    }

    /// The game controller says the ball was put back for a kick-off (`now_s` on the
    /// robot's clock): every ball belief goes.
    pub fn forget_ball(&mut self, now_s: f64) {
        self.lwm.forget_ball();
        self.gwm.forget_ball(now_s);
        self.ball = None;
        self.ball_seen_at_s = None;
        self.team_ball = None;
    }

    /// Switch the robot off: it falls silent. Returns the command that stops it where it
    /// is (in the frame of [`Robot::pose_belief`]).
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
