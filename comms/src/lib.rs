//! comms: huddle's blackboard, its wire format and the sans-IO replication core.
//! (lib.rs essay: being written.)

mod blackboard;
mod config;
pub mod driver;
mod key;
pub mod literal;
mod pattern;
pub mod relay;
mod replica;
mod stats;
mod talk;
mod time;
mod value;
pub mod wire;

pub use blackboard::{Applied, Blackboard, Entry, SetError};
pub use config::{load_config, parse_config, ConfigEntry, ConfigError, LineError};
pub use key::{validate_path, Key, KeyError, Kind, Scope, MAX_PATH_LEN, ROBOT_IDS};
pub use literal::{parse_literal, parse_literal_prefix, LiteralError};
pub use pattern::{Pattern, PatternError};
pub use replica::{ConfigInvalid, Destination, Event, PostError, Replica, ReplicaConfig, Transmit};
pub use stats::{DropReason, PeerInfo, Stats};
pub use talk::TalkLimits;
pub use time::Instant;
pub use value::{UnknownType, Value, ValueType};
