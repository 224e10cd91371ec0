//! player: one of huddle's simulated robots, the part that is not the team layer: its
//! perception (camera frames and odometry turned into the team layer's inputs, with the
//! noise its own calibration says they carry), CMUnited's modes and plays (tactics), and
//! the behaviours that turn a belief into a motion command. Its brain is the product's
//! [`team::TeamLayer`].
//!
//! It is a crate of its own so that the boundary between the simulator's truth and a
//! robot's knowledge is a dependency graph, not a text search: it depends on `team`,
//! `comms` and `fusion` only, so it cannot name the simulator's world or its physical
//! constants. What it knows of its field and body is its [`team::Calibration`]; what it
//! senses is a [`senses::Frame`] and [`senses::Odometry`], made by the simulator.
//!
//! It is not a robot's real perception or motion control: it stands in for them so that
//! `huddle sim` runs the team layer as a robot would.
//!
//! ```
//! use comms::arbitration::ArbitrationParams;
//! use player::behaviour::Position;
//! use player::{BrainConfig, Robot};
//!
//! let cfg = BrainConfig::default();
//! let cal = team::Calibration::default();
//! let robot = Robot::new(2, Position::Field(0), ArbitrationParams::default(),
//!                        team::Pose::default(), &cal, &cfg.team.world_model, 5);
//! assert!(robot.is_field_player() && !robot.going());
//! ```

pub mod behaviour;
pub mod perception;
pub mod play;
pub mod remote;
pub mod robot;
pub mod senses;
pub mod tactics;

pub use robot::{
    BrainConfig, KickAttempt, Order, Percepts, PlayCounts, Robot, TickInput, TickOutput,
};
