//! [`TeamLayer`]: one robot's team behaviour, from what it sensed to what it tells its
//! team. The daemon, the C node and the simulator's robots all run it.
//!
//! A control tick has three steps, in this order (the simulator's robot puts its
//! behaviour between the second and the third; the daemon has none):
//! 1. [`TeamLayer::sense`]: odometry and landmarks (or a pose estimate the robot made
//!    itself) into the pose EKF, a ball sighting into the ball EKF, teammates' new LWMs
//!    from the replica's blackboard into the GWM, its own push of the ball reported, the
//!    team ball; returns the LWM to publish.
//! 2. [`TeamLayer::decide`]: the cost (eq. 19 from its own ball, or the robot's own), the
//!    should-I-go arbitration on the claims the blackboard holds (or on what the acoustic
//!    fallback heard while the radio is silent).
//! 3. [`TeamLayer::finish`]: the sending policy decides what goes to the team; returns
//!    the blackboard writes and whether they may draw on the budget's reserve.
//!
//! Between ticks [`TeamLayer::redecide`] reacts to a teammate's claim as it arrives.

use std::time::Duration;

use comms::arbitration::{self, heuristic, Arbiter, ArbitrationParams, BallView, Decision, Posted};
use comms::{Blackboard, Instant, Key, Scope, Value};
use fusion::nalgebra::{Matrix2, Vector2};
use fusion::{
    BallEstimate, BallSighting, GlobalModel, Kick, LocalModel, LocalWorldModel, PoseEstimate,
    RangeBearingSighting, TeamBall,
};
use serde::Serialize;

use crate::acoustic::SoundFallback;
use crate::calibration::{Calibration, WorldModelConfig};
use crate::frames;
use crate::geometry::{Pose, Vec2};
use crate::policy::{self, Action, PolicyState, SendPolicy};
use keys::LayerKeys;

mod contact;
mod game_state;
mod keys;
mod teammates;
pub use contact::contact_probability;
#[cfg(test)]
use game_state::KICK_OFF_SPOT_SIGMA_M;
pub use game_state::{
    paced_game_remaining, KickOffPlacement, Whistle, GOAL_TO_KICK_OFF_MAX_S,
    GOAL_TO_KICK_OFF_MIN_S, KICK_OFF_HOLD_S, KICK_OFF_SET_CLAIMS, KICK_OFF_SET_CLAIM_GAP_S,
    KICK_OFF_TAKER_COST, WHISTLE_TRUST_S,
};

/// Where every robot publishes its LWM (`Bytes`, [`fusion::LWM_WIRE_LEN`] of them).
pub const WORLD_LOCAL_KEY: &str = "*.var.world.local";

/// The cost a penalised robot posts on the claim key (with `going` false): it is off the
/// field (the GameController removed it) and claims nothing. Any cost at or above the
/// no-ball cost already counts for nothing in the arbitration; this one also tells a
/// teammate that has not heard the GameController's packet that the robot is out.
pub const PENALIZED_COST: f64 = 1.0e6;

/// The key the active robot announces its intended pass receiver on (`Int`, 0 = shot).
pub const PASS_TO_KEY: &str = "*.var.machine.pass_to";

/// The key every robot publishes its LWM to ([`WORLD_LOCAL_KEY`]).
pub fn world_local_key() -> Key {
    Key::parse(WORLD_LOCAL_KEY).expect("a valid key")
}

/// The key robot `id`'s LWM is held under on a teammate's blackboard.
pub fn world_local_of(id: u8) -> Key {
    Key::new(Scope::Robot(id), comms::Kind::Var, "world.local").expect("a valid key")
}

/// The key the pass receiver is announced on ([`PASS_TO_KEY`]).
pub fn pass_to_key() -> Key {
    Key::parse(PASS_TO_KEY).expect("PASS_TO_KEY is a valid key")
}

/// Under a league's budget a robot's messages come `interval` apart at best: what it said
/// last holds until it says otherwise (a goer change goes at once, from the reserve), so
/// teammates hold its claim and its world model three intervals, and each message carries
/// one tick's sightings while the sender's track holds them all. The simulator and the
/// daemon set a budgeted team up the same way.
pub fn adapt_to_budget(
    params: &mut ArbitrationParams,
    world_model: &mut WorldModelConfig,
    interval: Duration,
) {
    let hold = interval * 3;
    params.stale_after = params.stale_after.max(hold);
    world_model.global.stale_after_s = world_model.global.stale_after_s.max(hold.as_secs_f64());
    world_model.global.track_after_s = Some(0.0);
}

/// A robot clock reading in seconds.
pub fn seconds(t: Instant) -> f64 {
    t.as_micros() as f64 * 1e-6
}

/// A teammate's velocity is measured between its messages' poses at least this far apart,
/// s.
const TEAMMATE_VELOCITY_BASELINE_S: f64 = 0.2;

/// How the team layer runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TeamConfig {
    /// Control period, seconds (one camera frame per tick).
    pub control_period_s: f64,
    /// A ball not seen for longer than this is forgotten (`f_ball` = 0), seconds.
    pub ball_memory_s: f64,
    /// The opponent goal counts as in view if seen within this long, seconds (one missed
    /// detection must not add |k1| to the cost).
    pub goal_memory_s: f64,
    /// The team ball is used when its global ball confidence (GBC) is at least this
    /// (0.25: a 1-σ radius of about 0.5 m); below, the robot goes by its own ball.
    pub team_ball_min_gbc: f64,
    /// The world models.
    #[serde(skip)]
    pub world_model: WorldModelConfig,
    /// When the robot tells the team what it knows.
    pub send_policy: SendPolicy,
}

impl Default for TeamConfig {
    fn default() -> Self {
        Self {
            control_period_s: 0.04,
            ball_memory_s: 0.5,
            goal_memory_s: 0.15,
            team_ball_min_gbc: 0.25,
            world_model: WorldModelConfig::default(),
            send_policy: SendPolicy::Every,
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

/// What the robot sensed over the latest control period: all the layer knows of the
/// world outside the robot. Its pose comes from odometry and landmarks (the layer's pose
/// EKF) or from `pose`, the robot's own estimate.
#[derive(Debug, Clone, Default)]
pub struct Senses<'a> {
    /// Odometry readings over the latest control period, oldest first (REP-103:
    /// forward, left, turn).
    pub odometry: &'a [fusion::Odometry],
    /// Landmarks at known field places, as range and bearing with their R.
    pub landmarks: &'a [(RangeBearingSighting, Matrix2<f64>)],
    /// The robot's own pose estimate (REP-103 mean, covariance of x, y, θ), replacing
    /// the pose EKF's.
    pub pose: Option<(Pose, fusion::nalgebra::Matrix3<f64>)>,
    /// Ball sightings in `fusion`'s robot frame (see
    /// [`frames::ball_sighting_from_rep103`]), oldest first, each with how old it was at
    /// this tick, s.
    pub ball: &'a [(BallSighting, f64)],
    /// The opponent goal is in view (eq. 19's `f_other`).
    pub goal_in_view: bool,
    /// Opponents seen now, robot frame (REP-103, m): a body at the ball may push it.
    pub opponents: &'a [Vector2<f64>],
    /// A cost the robot computed itself, replacing eq. (19) from its own ball.
    pub cost: Option<f64>,
}

/// One robot's team behaviour. See the module docs for the tick's steps.
#[derive(Debug, Clone)]
pub struct TeamLayer {
    /// Robot id, 1–254.
    pub id: u8,
    /// Its side of the arbitration.
    pub arbiter: Arbiter,
    /// What it knows of its body, ball and field.
    pub cal: Calibration,
    /// Where it believes it is (its LWM's pose).
    pub pose_belief: Pose,
    /// Odometry over the latest control period.
    pub odometry: fusion::Odometry,
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
    /// [`TeamLayer::acts_as_goer`]).
    untold_claim: Option<Posted>,
    /// … and whether one of them claimed to be going.
    rival_going: bool,
    /// The team ball at its latest tick (when its GBC is high enough to use).
    pub team_ball: Option<TeamBall>,
    /// The team ball at its latest tick whatever its GBC, as the robot holds it (widened
    /// at contact, see [`WorldModelConfig::contact_horizon_s`]).
    pub team_ball_held: Option<TeamBall>,
    /// The kick or push it reported at its latest tick, if any.
    pub kicked: Option<Kick>,
    /// Its ball sighting of the latest tick, in `fusion`'s robot frame.
    pub ball_sighting: Option<BallSighting>,
    /// Whether its own ball filter took that sighting (not gated out as an outlier, as a
    /// false ball is): only such a sighting reaches its teammates, in its batch.
    pub ball_sighting_taken: bool,
    /// Ticks in a row at which its own ball track took a sighting (1 on a fresh or
    /// restarted track): a false ball is one camera frame, a real one is seen again.
    pub ball_seen_run: u32,
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
    /// Whether it is switched on (a dead robot neither senses, decides nor sends).
    pub alive: bool,
    goalkeeper: bool,
    pass_to_posted: i64,
    /// The world model of the latest tick, as published (written or not).
    latest_lwm: Option<Value>,
    /// The latest tick's time: when `latest_lwm` was built (this robot's clock).
    latest_lwm_built: Instant,
    /// What the latest tick did to the team ball for a kick-off (see
    /// [`TeamLayer::kick_off_placement`]).
    tick_placement: Option<KickOffPlacement>,
    push_reported_at_s: f64,
    decided_at_s: f64,
    /// Per teammate (index = id − 1): the (incarnation, version) of its LWM fed last.
    heard: Vec<Option<(u64, u64)>>,
    /// Per teammate (index = id − 1): the (incarnation, version) of the entry whose LWM
    /// its GWM's record holds as taken (see [`TeamLayer::decoded_lwm`]; the LWM itself is
    /// not copied again here).
    decoded: Vec<Option<(u64, u64)>>,
    /// The keys it reads and writes at every tick, built once (a key's path is parsed
    /// and allocated; a clone shares it).
    keys: LayerKeys,
    /// Per teammate (index = id − 1): the time and place of the message its velocity was
    /// last measured to, and that velocity (field frame).
    teammate_motion: Vec<Option<TeammateMotion>>,
    /// What it last told the team, for the sending policy.
    policy: PolicyState,
    /// The acoustic fallback, when the team uses it (see [`crate::acoustic`]).
    pub sound: Option<SoundFallback>,
    /// Whether it goes by the fallback's decision while the radio is silent (`None`: the
    /// arbiter decides).
    sound_going: Option<bool>,
    /// When the GameController and the teammates were last heard: whether the radio works.
    beat: crate::heartbeat::RadioHeartbeat,
    /// Per robot (index = id − 1): the GameController says it is penalised (this robot
    /// included). See [`TeamLayer::set_penalties`].
    penalized: Vec<bool>,
    /// While penalised: its "penalised" claim was handed to the replica.
    penalty_told: bool,
    /// The ball is in play (the GameController says Playing, or there is none).
    in_play: bool,
    /// The GameController says Set: a kick-off comes next (see
    /// [`TeamLayer::set_kick_off_next`]).
    kick_off_next: bool,
    /// The kick-off hold (see [`TeamLayer::set_kick_off_next`]): until when, robot
    /// seconds; infinite from Set until it hears play.
    kick_off_hold_until_s: Option<f64>,
    /// In the hold, and not the kick-off taker: it leaves the ball to the taker.
    kick_off_yield: bool,
    /// This kick-off's taker: the cost at which it first claimed the ball in Set or the
    /// hold. It keeps the claim at that cost until the hold ends (see
    /// [`TeamLayer::set_kick_off_next`]).
    kick_off_taker_h: Option<f64>,
    /// In Set, as the taker: how often it told the team its claim, and when last (see
    /// [`TeamLayer::set_kick_off_next`]).
    kick_off_claims: (u32, f64),
    /// The GameController has just said Set: at the next tick the ball is put back on the
    /// kick-off spot (see [`TeamLayer::forget_ball`]).
    kick_off_place: bool,
    /// The ball was in play at the latest tick.
    was_in_play: bool,
    /// The scores (this team's, the other's) in the newest GameController packet heard.
    scores_heard: Option<(u8, u8)>,
    /// The GameController's own word: Playing (or none), and Set (see
    /// [`TeamLayer::heard_whistle`]: a whistle can run ahead of it).
    gc_in_play: bool,
    gc_set: bool,
    /// … and Ready (see [`TeamLayer::set_gc_ready`]).
    gc_ready: bool,
    /// When the robot program last heard a goal's whistle the GameController has not
    /// answered (robot seconds), kept after the whistle itself expires: with the radio
    /// dead, the next whistle is the kick-off's (see [`TeamLayer::heard_whistle`]).
    goal_whistle_at: Option<f64>,
    /// The whistle the robot program heard, while the GameController has not caught up
    /// (see [`TeamLayer::heard_whistle`]).
    whistle: Option<game_state::Whistle>,
}

/// The robot id at index `k` of a team's per-robot vectors.
fn robot_id(k: usize) -> u8 {
    u8::try_from(k + 1).unwrap_or(u8::MAX)
}

impl TeamLayer {
    /// Robot `id`'s team layer, deciding with `params`, calibrated as `cal`, started at
    /// `pose` (which it is told, give or take the configured start σ), in a team of
    /// `team` robots (ids 1..=team).
    pub fn new(
        id: u8,
        goalkeeper: bool,
        params: ArbitrationParams,
        pose: Pose,
        cal: &Calibration,
        world_model: &WorldModelConfig,
        team: usize,
    ) -> Self {
        let start = frames::to_fusion_pose(
            &pose,
            fusion::nalgebra::Matrix3::from_diagonal(&fusion::nalgebra::Vector3::new(
                world_model.start_sigma_m.powi(2),
                world_model.start_sigma_m.powi(2),
                world_model.start_sigma_rad.powi(2),
            )),
        );
        Self {
            id,
            arbiter: Arbiter::new(id, goalkeeper, params),
            cal: *cal,
            pose_belief: pose,
            odometry: fusion::Odometry::default(),
            ball: None,
            lwm: LocalModel::new(world_model.local, start),
            gwm: GlobalModel::new(id, world_model.global),
            compact: world_model.global.track_after_s.is_some(),
            rival_cost: None,
            untold_claim: None,
            rival_going: false,
            team_ball: None,
            team_ball_held: None,
            kicked: None,
            ball_sighting: None,
            ball_sighting_taken: false,
            ball_seen_run: 0,
            goal_seen_at_s: None,
            ball_seen_at_s: None,
            h: params.no_ball_cost,
            decision: Decision {
                goer: None,
                goer_cost: f64::INFINITY,
            },
            claim_ages: Vec::new(),
            alive: true,
            goalkeeper,
            pass_to_posted: 0,
            latest_lwm: None,
            latest_lwm_built: Instant::ZERO,
            tick_placement: None,
            push_reported_at_s: f64::NEG_INFINITY,
            decided_at_s: 0.0,
            heard: vec![None; team],
            decoded: vec![None; team],
            keys: LayerKeys::new(team),
            teammate_motion: vec![None; team],
            policy: PolicyState::default(),
            sound: None,
            sound_going: None,
            beat: crate::heartbeat::RadioHeartbeat::default(),
            penalized: vec![false; team.max(usize::from(id))],
            penalty_told: false,
            in_play: true,
            kick_off_next: false,
            kick_off_hold_until_s: None,
            kick_off_yield: false,
            kick_off_taker_h: None,
            kick_off_claims: (0, f64::NEG_INFINITY),
            kick_off_place: false,
            was_in_play: true,
            scores_heard: None,
            gc_in_play: true,
            gc_set: false,
            gc_ready: false,
            goal_whistle_at: None,
            whistle: None,
        }
    }

    /// The robot was put down at `pose` by hand (a penalised robot re-enters at a spot
    /// the rules name): it believes it, give or take the configured start σ.
    pub fn place(&mut self, pose: Pose, world_model: &WorldModelConfig) {
        let cov = fusion::nalgebra::Matrix3::from_diagonal(&fusion::nalgebra::Vector3::new(
            world_model.start_sigma_m.powi(2),
            world_model.start_sigma_m.powi(2),
            world_model.start_sigma_rad.powi(2),
        ));
        self.lwm.set_pose(frames::to_fusion_pose(&pose, cov));
        self.pose_belief = pose;
    }

    /// Whether it competes for the ball.
    pub fn is_field_player(&self) -> bool {
        !self.goalkeeper
    }

    /// Whether it is the goalkeeper.
    pub fn is_goalkeeper(&self) -> bool {
        self.goalkeeper
    }

    /// Make it the goalkeeper (it never competes for the ball) or a field player.
    pub fn set_goalkeeper(&mut self, goalkeeper: bool) {
        if goalkeeper != self.goalkeeper {
            self.goalkeeper = goalkeeper;
            let params = *self.arbiter.params();
            self.arbiter = Arbiter::new(self.id, goalkeeper, params);
        }
    }

    /// Whether it is going to the ball now.
    ///
    /// A goer that decided to stop while its "not going" waits for a frame goes on: its
    /// teammates still hold its claim and none of them goes, so stopping unannounced
    /// would leave the ball to nobody.
    pub fn going(&self) -> bool {
        self.alive && !self.penalized() && self.acts_as_goer()
    }

    /// Whether it decided to go: by the fallback while the radio is silent, else by the
    /// arbiter.
    pub fn claims_ball(&self) -> bool {
        self.sound_going.unwrap_or_else(|| self.arbiter.going())
    }

    /// Whether it plays the ball: it claims it, or it stopped claiming while no teammate
    /// claims and its teammates have not heard the stop yet (not in the kick-off hold,
    /// where a robot other than the taker leaves the ball to it: see
    /// [`TeamLayer::set_kick_off_next`]).
    pub fn acts_as_goer(&self) -> bool {
        self.claims_ball()
            || (!self.kick_off_yield
                && !self.rival_going
                && self.untold_claim.is_some_and(|c| !c.going))
    }

    /// Step 1 of a tick at `local_now` (the robot's clock): what it sensed into its world
    /// models, teammates' new LWMs from `board` into its GWM. `claim_waiting`: its claim
    /// written earlier still waits for a frame. Returns the LWM to write to
    /// [`WORLD_LOCAL_KEY`].
    pub fn sense(
        &mut self,
        cfg: &TeamConfig,
        local_now: Instant,
        senses: &Senses<'_>,
        board: &Blackboard,
        claim_waiting: bool,
    ) -> Option<Value> {
        let wm = &cfg.world_model;
        let now_s = seconds(local_now);
        self.kicked = None;
        self.tick_placement = None;
        if std::mem::take(&mut self.kick_off_place) {
            // Set: the ball lies on the kick-off spot, whatever the robot tracked before
            // (a half's kick-off has no goal, so nothing was reset).
            self.forget_ball(now_s);
            self.tick_placement = Some(KickOffPlacement::Set);
        }
        if !claim_waiting {
            self.untold_claim = None;
        }
        // The period's motion, for its own velocity: the readings added up.
        self.odometry = senses
            .odometry
            .iter()
            .fold(fusion::Odometry::default(), |a, o| fusion::Odometry {
                forward_m: a.forward_m + o.forward_m,
                left_m: a.left_m + o.left_m,
                turn_rad: a.turn_rad + o.turn_rad,
            });
        if let Some((pose, cov)) = senses.pose {
            self.lwm.set_pose(frames::to_fusion_pose(&pose, cov));
        } else {
            let pf = self.lwm.pose_filter_mut();
            for odo in senses.odometry {
                pf.noise.q = frames::odometry_q(odo, &self.cal.sensors, wm.push_sigma_m);
                pf.odometry(odo);
            }
            for (sighting, r) in senses.landmarks {
                pf.noise.r_range_bearing = *r;
                // A degenerate sighting (the robot on the landmark) is skipped.
                let _ = pf.range_bearing(sighting);
            }
        }
        self.pose_belief = frames::from_fusion_pose(self.lwm.pose());

        self.ball_sighting = senses.ball.last().map(|(s, _)| *s);
        self.ball_sighting_taken = false;
        let mut run = 0;
        for (s, age_s) in senses.ball {
            let seen_s = now_s - age_s;
            run = match self.lwm.ball_sighting(seen_s, s) {
                fusion::BallUpdate::Updated(_) => self.ball_seen_run.max(run) + 1,
                fusion::BallUpdate::Initialised | fusion::BallUpdate::Restarted => 1,
                _ => 0,
            };
            self.ball_sighting_taken = run > 0;
            self.ball_seen_at_s = Some(self.ball_seen_at_s.map_or(seen_s, |t| t.max(seen_s)));
        }
        self.ball_seen_run = run;
        if senses.goal_in_view {
            self.goal_seen_at_s = Some(now_s);
        }
        let recent = self
            .ball_seen_at_s
            .filter(|&seen| now_s - seen <= cfg.ball_memory_s);
        let own = self.lwm.ball_at(now_s);
        self.ball = recent.and_then(|seen_at_s| {
            own.map(|b| BallBelief {
                at: frames::from_fusion_point(&b.position()),
                seen_at_s,
            })
        });

        self.hear_teammates(board, local_now);
        if let Some(push) = self.push_report(cfg, now_s) {
            // Its own ball, and with the next message its team's, turns with the push
            // instead of several sightings later (as with a kick).
            self.lwm.kick(&push);
            self.kicked = Some(push);
            self.push_reported_at_s = now_s;
        }
        // Put back for a kick-off, the ball stays on the spot until play: the referee
        // holds it there. If the team ball is still that placement when the robot hears
        // play (no camera and no kick said otherwise), it is put down again then, so at
        // the whistle it is as sure as the placement, not a Ready and a Set's worth of
        // prediction old.
        self.whistle_timeout(now_s);
        let play_heard = self.in_play && !self.was_in_play;
        self.was_in_play = self.in_play;
        if play_heard {
            self.tick_placement = Some(KickOffPlacement::PlayHeard);
            if self.gwm.is_placed() {
                self.gwm.place_ball(self.kick_off_ball(now_s));
            }
        }
        let msg = self.lwm.publish(now_s);
        self.gwm.ingest(self.id, &msg, now_s);
        self.track_teammates(now_s);
        self.team_ball_held = self
            .gwm
            .team_ball(now_s, own.as_ref())
            .map(|b| self.widened_at_contact(cfg, now_s, senses.opponents, b));
        self.team_ball = self
            .team_ball_held
            .filter(|b| b.gbc >= cfg.team_ball_min_gbc);
        let bytes = if self.compact {
            msg.to_compact_bytes()
                .ok()
                .map(|b| Value::Bytes(b.to_vec()))
        } else {
            msg.to_bytes().ok().map(|b| Value::Bytes(b.to_vec()))
        };
        self.h = match senses.cost {
            Some(h) => h,
            None => {
                let facing = self
                    .goal_seen_at_s
                    .is_some_and(|s| now_s - s <= cfg.goal_memory_s);
                let view = self.ball.map(|b| BallView {
                    distance_m: b.at.distance(self.pose_belief.at),
                    facing_opponent_goal: facing,
                });
                heuristic(self.arbiter.params(), view)
            }
        };
        if self.penalized() {
            // Off the field: whatever it sees, it claims nothing.
            self.h = PENALIZED_COST;
        }
        if self.compact {
            // Only a budget's ride-along reads it (see `redecide`).
            self.latest_lwm.clone_from(&bytes);
            self.latest_lwm_built = local_now;
        }
        bytes
    }

    /// Step 2: run the arbitration on the current cost and what the replica has heard (by
    /// the acoustic fallback's claims while the radio is silent).
    pub fn decide(&mut self, board: &Blackboard, local_now: Instant) -> (Decision, Posted) {
        let t_s = seconds(local_now);
        let mut heard = arbitration::heard(board, local_now);
        let stale_after = self.arbiter.params().stale_after;
        let in_play = self.in_play && !self.penalized();
        let (id, beat) = (self.id, self.beat);
        // Whether the fallback decides, on every claim told (a penalised teammate's "I am
        // out" too: the fallback hands back to the radio once each teammate has told one
        // since an outage), so before the penalised are dropped below.
        let silent = self.sound.as_mut().is_some_and(|sound| {
            if !in_play {
                sound.out_of_play();
                return false;
            }
            sound.radio(id, &heard, stale_after, &beat, t_s)
        });
        // A penalised teammate is off the field: its last claim (going, perhaps) no longer
        // counts, by the GameController's word or by its own.
        heard.retain(|c| {
            c.robot == self.id || !(self.is_out(c.robot) || c.posted.h >= PENALIZED_COST)
        });
        let dt = Duration::from_secs_f64((t_s - self.decided_at_s).max(0.0));
        self.decided_at_s = t_s;
        let fallback = self
            .sound
            .as_mut()
            .filter(|_| silent)
            .map(|sound| sound.candidates(id, t_s, &heard));
        // A teammate the GameController penalised is off the field, by sound as by radio.
        let fallback = fallback.map(|mut claims| {
            claims.retain(|c| c.robot == self.id || !self.is_out(c.robot));
            claims
        });
        let holding = self.kick_off_hold(t_s);
        if !holding || self.penalized() {
            self.kick_off_taker_h = None;
        }
        let taker_h = self.kick_off_taker_h;
        self.kick_off_yield = holding && taker_h.is_none() && self.h >= KICK_OFF_TAKER_COST;
        if holding && self.compact {
            // What it told before the restart is long stale at its teammates.
            self.arbiter.set_told(None);
        }
        let cost = if self.kick_off_yield {
            self.h.max(self.arbiter.params().no_ball_cost)
        } else if let Some(taker_h) = taker_h {
            // The taker keeps the kick-off through its kick until the hold ends: its
            // teammates leave the ball to it until then whatever it sees after the kick,
            // and it lets go only when they may take it.
            self.h.min(taker_h)
        } else {
            self.h
        };
        let (decision, posted) = match fallback {
            None => {
                self.sound_going = None;
                if let Some(sound) = &mut self.sound {
                    // Some teammates' radio is silent, not all: what they sounded stands
                    // in for their stale radio claims.
                    let by_sound = sound.sounded_for_stale(self.id, t_s, &heard, stale_after);
                    if !by_sound.is_empty() {
                        heard.retain(|c| by_sound.iter().all(|s| s.robot != c.robot));
                        heard.extend(by_sound);
                    }
                }
                let (decision, posted) = self.arbiter.tick(dt, cost, &heard);
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
        if holding && !self.kick_off_yield && posted.going && self.kick_off_taker_h.is_none() {
            self.kick_off_taker_h = Some(cost);
        }
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
                .filter(|c| c.robot != self.id && c.posted.h < params.no_ball_cost)
                .map(|c| (c.robot, c.age)),
        );
        (decision, posted)
    }

    /// The pass receiver the goer `decision` names announces, as `board` holds it.
    pub fn goer_pass_to(&self, board: &Blackboard, local_now: Instant) -> Option<u8> {
        let params = self.arbiter.params();
        self.decision.goer.filter(|&g| g != self.id).and_then(|g| {
            let key = self.keys.pass_to_of(g)?;
            match board
                .get_fresher_than(local_now, &key, params.stale_after)?
                .value
            {
                Value::Int(r) => u8::try_from(r).ok(),
                _ => None,
            }
        })
    }

    /// A kick the robot just swung at `now_s` in field direction `direction_rad`, with
    /// its own odds `contact_prob` that the foot met the ball: its ball, and with its next
    /// message its team's, turns with the kick instead of waiting to see it. Returns the
    /// report.
    pub fn report_kick(
        &mut self,
        cfg: &TeamConfig,
        now_s: f64,
        direction_rad: f64,
        speed_mps: f64,
        contact_prob: f64,
    ) -> Kick {
        let kick = Kick {
            t_s: now_s,
            speed_mps,
            direction_rad,
            speed_sigma_mps: cfg.world_model.kick_speed_sigma_mps,
            direction_sigma_rad: self.cal.kick.direction_sigma_rad,
            contact_prob,
        };
        self.lwm.kick(&kick);
        self.kicked = Some(kick);
        kick
    }

    /// Step 3: the sending policy on what the tick found. `lwm`: what
    /// [`TeamLayer::sense`] returned; `posted`: what [`TeamLayer::decide`] returned;
    /// `receiver`: the pass receiver it announces (0: none); `kicked`: it kicked at this
    /// tick; `world_model_waiting` / `claim_waiting`: its last world model / claim still
    /// wait for a frame; `headroom`: its replica's budget headroom, if it has a budget.
    /// Returns the writes to make through the replica, and whether they may draw on the
    /// budget's reserve (a goer change or a kick).
    #[allow(clippy::too_many_arguments)]
    pub fn finish(
        &mut self,
        cfg: &TeamConfig,
        local_now: Instant,
        lwm: Option<Value>,
        posted: Posted,
        receiver: i64,
        kicked: bool,
        world_model_waiting: bool,
        claim_waiting: bool,
        headroom: Option<i64>,
    ) -> (Vec<(Key, Value)>, bool) {
        let t = seconds(local_now);
        if self.beat.dead(t) {
            // Nobody would hear it, and a league counts it: the team's frames into a dead
            // radio left it paced into silence for a minute after a 30 s outage. What
            // changed meanwhile is told when the radio is back (nothing was told since).
            return (Vec::new(), false);
        }
        let mut writes = vec![(arbitration::heuristic_key(), Value::from(posted))];
        if self.penalized() {
            // It tells the team once that it is out (a goer's teammates must not wait
            // for it), then keeps quiet: its world model off the field helps nobody.
            if self.penalty_told {
                return (Vec::new(), false);
            }
            self.told_penalty();
            let out = Posted {
                h: PENALIZED_COST,
                going: false,
            };
            return (vec![(arbitration::heuristic_key(), Value::from(out))], true);
        }
        // In Set the taker tells its claim (see `set_kick_off_next`).
        let set_claim = !self.in_play
            && self.kick_off_next
            && self.kick_off_claims.0 < KICK_OFF_SET_CLAIMS
            && t - self.kick_off_claims.1 >= KICK_OFF_SET_CLAIM_GAP_S
            && self.alive
            && self.is_field_player()
            && !self.kick_off_yield
            && posted.going;
        if !self.in_play && !set_claim {
            return (Vec::new(), false);
        }
        if let Some(bytes) = lwm {
            writes.push((self.keys.world_local.clone(), bytes));
        }
        let receiver_changed = receiver != self.pass_to_posted;
        let now = policy::Now {
            t_s: t,
            pose: self.pose_belief,
            ball: self.ball.and(self.lwm.ball_at(t)),
            ball_confirmed: self.ball_seen_run >= policy::VOI_CONFIRM_TICKS,
            going: self.claims_ball(),
            team_ball_stale: self.team_ball.is_none(),
            kicked,
            model: &cfg.world_model.local.ball.model,
            // What teammates last told the team about the ball: the freshest track heard.
            // (Only VOI weighs it: no copy of every teammate's model per tick for the rest.)
            told: (cfg.send_policy == SendPolicy::Voi)
                .then(|| {
                    self.gwm
                        .teammates_iter(t)
                        .filter_map(|m| m.lwm.ball)
                        .max_by(|a, b| a.t_s.total_cmp(&b.t_s))
                })
                .flatten(),
            headroom,
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
        let mut action =
            self.policy
                .decide(cfg.send_policy, &now, world_model_waiting, claim_waiting);
        if set_claim {
            self.kick_off_claims = (self.kick_off_claims.0 + 1, t);
            action = self.policy.insist();
        }
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
            writes.push((self.keys.pass_to.clone(), Value::Int(receiver)));
        }
        (writes, priority)
    }

    /// Between control ticks: decide again on the latest cost with whatever the replica
    /// heard since (a robot reacts to a teammate's claim when it arrives, not at its next
    /// camera frame). Returns the writes to make if its claim changed: the claim, with
    /// priority, and under a budget its latest tick's world model when none waits already
    /// (`world_model_waiting`) and that tick's did not go: the claim's frame is spent
    /// anyway.
    pub fn redecide(
        &mut self,
        board: &Blackboard,
        local_now: Instant,
        world_model_waiting: bool,
    ) -> Vec<(Key, Value)> {
        if !self.alive || !self.in_play {
            return Vec::new();
        }
        let was = self.claims_ball();
        let (_, posted) = self.decide(board, local_now);
        if posted.going == was {
            return Vec::new();
        }
        let mut writes = vec![(arbitration::heuristic_key(), Value::from(posted))];
        if self.penalized() {
            // Just penalised: this is its "penalised" claim (see `finish`), alone.
            self.told_penalty();
            return writes;
        }
        let cost = self.arbiter.params().effective_cost(&posted);
        if self.compact {
            // Told once it went out (see `Arbiter::set_told`).
            self.policy.wrote_claim(posted.going, posted.h, cost);
            self.untold_claim = Some(posted);
            if let Some(lwm) = self.latest_lwm.clone() {
                if !world_model_waiting && self.policy.world_model_rides() {
                    writes.push((self.keys.world_local.clone(), lwm));
                }
            }
        } else {
            self.policy.sent_going(posted.going, posted.h, cost);
        }
        writes
    }

    /// What this robot sounds if its slot begins now (`t_s`, its clock): its claim while
    /// the radio is stale, in play (never out of play or penalised: see
    /// [`crate::acoustic::SoundFallback::out_of_play`]).
    pub fn sound_claim(&mut self, t_s: f64) -> Option<audio::Message> {
        if !self.alive || !self.in_play || self.penalized() {
            return None;
        }
        let posted = Posted {
            h: self.h,
            going: self.claims_ball(),
        };
        self.sound.as_mut()?.claim(self.id, posted, t_s)
    }

    /// This robot accepted a GameController packet at `t_s` (its clock): the radio's
    /// heartbeat (see [`crate::heartbeat`]).
    pub fn heard_gamecontroller(&mut self, t_s: f64) {
        self.beat.heard_gamecontroller(t_s);
    }

    /// The replica's view of the teammates at `now` (`comms::Replica::peers`): when a
    /// teammate was last heard, for the radio's heartbeat. Call it every tick.
    pub fn heard_teammates(
        &mut self,
        now: Instant,
        peers: impl IntoIterator<Item = comms::PeerInfo>,
    ) {
        if let Some(last) = peers.into_iter().map(|p| p.last_heard).max() {
            let ago = now.saturating_duration_since(last);
            self.beat.heard_teammate(seconds(now) - ago.as_secs_f64());
        }
    }

    /// Whether the radio is dead at `t_s` by the GameController's heartbeat (see
    /// [`crate::heartbeat::RadioHeartbeat::dead`]): the layer then tells the team
    /// nothing, and the acoustic fallback decides.
    pub fn radio_dead(&self, t_s: f64) -> bool {
        self.beat.dead(t_s)
    }

    /// The replica's view of the teammates at `now` (`comms::Replica::peers`): the acoustic
    /// fallback's slots run on the team clock it gives (see [`crate::acoustic::TeamClock`]).
    /// Call it every tick; nothing without the fallback.
    pub fn update_team_clock(
        &mut self,
        now: Instant,
        peers: impl IntoIterator<Item = comms::PeerInfo>,
    ) {
        if let Some(sound) = &mut self.sound {
            sound.update_clock(now, peers);
        }
    }

    /// When this robot's next acoustic slot starts, at or after `t_s` (its clock, s):
    /// call [`TeamLayer::sound_claim`] then. `None` without the fallback or a slot.
    pub fn next_sound_slot(&self, t_s: f64) -> Option<f64> {
        self.sound.as_ref()?.next_slot(self.id, t_s)
    }

    /// A message this robot's microphone decoder produced, its start on this robot's
    /// clock, s.
    pub fn hear_sound(&mut self, message: &audio::Message, start_s: f64) {
        if let (Some(sound), true) = (&mut self.sound, self.alive) {
            sound.hear(self.id, message, start_s);
        }
    }

    /// The team ball if there is a usable one, else the robot's own.
    pub fn best_ball(&self) -> Option<Vec2> {
        self.team_ball
            .map(|b| frames::from_fusion_point(&b.estimate.position()))
            .or(self.ball.map(|b| b.at))
    }

    /// When the world model [`TeamLayer::redecide`] lets ride along was built: its tick
    /// (this robot's clock). The caller writes it stamped so
    /// (`comms::Replica::set_key_built`): a teammate then places the snapshot at the
    /// instant it holds, not up to a control period later (#29's seventh session: under
    /// the SPL budget teammates placed messages 16 ms late on average, up to 50 ms).
    pub fn world_model_built(&self) -> Instant {
        self.latest_lwm_built
    }

    /// The pose estimate the layer holds (`fusion`'s convention).
    pub fn pose_estimate(&self) -> &PoseEstimate {
        self.lwm.pose()
    }

    /// Its own ball estimate now, if it saw the ball within its ball memory.
    pub fn own_ball(&self, now_s: f64) -> Option<BallEstimate> {
        self.ball.and(self.lwm.ball_at(now_s))
    }

    /// Teammate `id`'s LWM as [`TeamLayer::sense`] decoded it from the blackboard entry
    /// of `incarnation` and `version` (on this robot's clock, placed by the entry's age),
    /// if that entry is the one it decoded last: a second reader of the same message (the
    /// simulator's delivery reference) retimes it
    /// ([`fusion::LocalWorldModel::retimed`]) instead of decoding it again.
    pub fn decoded_lwm(&self, id: u8, incarnation: u64, version: u64) -> Option<&LocalWorldModel> {
        let k = usize::from(id).checked_sub(1)?;
        if *self.decoded.get(k)? != Some((incarnation, version)) {
            return None;
        }
        // The GWM's record, unless a kick-off's placement has dropped its ball since.
        self.gwm.received(id)
    }
}

#[cfg(test)]
#[path = "layer_tests.rs"]
mod tests;
