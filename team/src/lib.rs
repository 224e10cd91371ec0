//! team: huddle's team layer, the code that makes robots a team. For one robot it runs
//! the local world model (pose and ball EKFs, from the robot's own pose estimate or from
//! raw odometry and landmark sightings), the global world model (the team ball with its
//! covariance and age, teammates' poses) from the LWMs teammates publish, the should-I-go
//! arbitration loop (told claims, keepalives, the goer's priority frames), kick and push
//! reports, the sending policy under a league's budget (`voi` by default there;
//! `baseline` and `every` for comparison), and the acoustic fallback while the WLAN is
//! down.
//!
//! It is sans-IO like `comms`: time, seeds and calibration are arguments, and it never
//! reads a clock, a socket or the simulator's truth (it cannot: it depends on `comms`,
//! `fusion` and `audio` only). Its inputs are what a robot senses and its replica's
//! blackboard; its outputs are blackboard writes. `huddle daemon` runs it for its robot
//! from the `local.var.robot.*` keys of `docs/team-layer.md`; the
//! simulator's robots run it around their simulated senses and behaviour.
//!
//! It is not a localisation system, a behaviour engine or a motion planner: the robot
//! program keeps those.
//!
//! ```
//! use comms::arbitration::ArbitrationParams;
//! use comms::{Blackboard, Instant};
//! use team::{Calibration, Pose, Senses, TeamConfig, TeamLayer, Vec2};
//!
//! let cfg = TeamConfig::default();
//! let cal = Calibration::default();
//! let start = Pose { at: Vec2::new(-1.0, 0.0), theta_rad: 0.0 };
//! let mut robot = TeamLayer::new(2, false, ArbitrationParams::default(), start, &cal, &cfg.world_model, 5);
//! let board = Blackboard::new(2);
//! let now = Instant::from_micros(40_000);
//! // The robot saw nothing this tick: its world model still publishes its pose.
//! let lwm = robot.sense(&cfg, now, &Senses::default(), &board, false);
//! let (decision, posted) = robot.decide(&board, now);
//! let (writes, _priority) = robot.finish(&cfg, now, lwm, posted, 0, false, false, false, None);
//! assert!(decision.goer.is_none() && !writes.is_empty());
//! ```

pub mod acoustic;
pub mod calibration;
pub mod contract;
pub mod frames;
pub mod geometry;
pub mod heartbeat;
mod layer;
pub mod policy;
mod team_clock;

pub use calibration::{Calibration, WorldModelConfig};
pub use geometry::{Pose, Vec2};
pub use layer::{
    adapt_to_budget, contact_probability, paced_game_remaining, pass_to_key, seconds,
    world_local_key, world_local_of, BallBelief, KickOffPlacement, Senses, TeamConfig, TeamLayer,
    Whistle, GOAL_TO_KICK_OFF_MAX_S, GOAL_TO_KICK_OFF_MIN_S, KICK_OFF_HOLD_S, KICK_OFF_TAKER_COST,
    PASS_TO_KEY, PENALIZED_COST, WHISTLE_TRUST_S, WORLD_LOCAL_KEY,
};
pub use policy::SendPolicy;

/// The team layer's keys sent as a one-byte index on the wire (comms' item 4): its
/// arbitration claim, world model, pass receiver and heard tones, in the order format 3
/// fixed them (robots on older builds read them so). Append only: an index, once given,
/// is part of every build's format. Every robot of a team registers the same table
/// (`ReplicaConfig::with_known_paths`).
pub const KNOWN_PATHS: [&str; 4] = [
    "machine.heuristic",
    "world.local",
    "machine.pass_to",
    "audio.heard",
];

/// [`KNOWN_PATHS`] as the table a replica takes.
pub fn known_paths() -> comms::wire::KnownPaths {
    comms::wire::KnownPaths::new(KNOWN_PATHS).expect("the team layer's paths are valid keys")
}
