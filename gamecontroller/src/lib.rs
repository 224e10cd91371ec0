//! The RoboCup SPL GameController, sans I/O: its packets, the game as a robot follows
//! it, and the team's message budget as the GC's own figures state it.
//!
//! - [`GameControlData`] ("RGme" v18, 118 B, broadcast on port 3838 twice a second): a
//!   checked decoder ([`ControlView`], then the value) and an encoder (for a simulated GC
//!   and for tests). Another version, length or team is an error, never a misread.
//! - [`StatusMessage`] ("RGrt" v4, 32 B, to the GC's address on port 3939 at 0.5–2 Hz):
//!   encoder and decoder; [`StatusInputs`] turns field-frame estimates in metres into it.
//! - [`GameTracker`]: the newest packet by its wrapping `packetNumber` (a stale or
//!   reordered one never moves the game backwards), this team's and robot's figures, the
//!   GC's address, and counters of bad packets.
//! - [`GcBudget`]: the team's budget by the GC's figures ([`GcCap`]: counted or not, the
//!   `messageBudget` less a margin, the game time left over the halves). The pacing is
//!   not here: the daemon's and the simulator's listeners hand these figures to `comms`
//!   (`driver::budget_figures`, `comms::ExternalCap`), whose replica paces by them.
//!
//! What it is not: no sockets, no clock (every time is an argument, a [`Duration`](std::time::Duration)
//! since any origin the caller keeps), no threads. The daemon's listener and the simulator's GC
//! drive it. The layouts and the counting rule are GameController3's
//! (`game_controller_msgs/headers/RoboCupGameControlData.h`,
//! `game_controller_core/src/actions/team_message.rs`). The state the GC shows can lag
//! its true state (up to 15 s after a goal or after Playing starts, 45 s in a kick-off's
//! Ready), but in each of those the shown and the true state are both counted ones; the
//! budget field is always current.
//!
//! ```
//! use std::time::Duration;
//! use gamecontroller::{GameControlData, GameTracker, GcBudget, State};
//!
//! // A simulated GC's packet: team 12 against team 34, Playing, 300 s left in the first
//! // half, 950 messages left.
//! let mut game = GameControlData::new([12, 34]);
//! game.state = State::Playing;
//! game.packet_number = 7;
//! game.secs_remaining = 300;
//! game.team_mut(12).unwrap().message_budget = 950;
//! let bytes = game.encode();
//!
//! let mut tracker = GameTracker::new(12, 3);
//! let gc = "10.0.0.1:3838".parse().unwrap();
//! tracker.receive(Duration::from_secs(100), gc, &bytes).unwrap();
//! assert_eq!(tracker.state(), Some(State::Playing));
//! assert_eq!(tracker.message_budget(), Some(950));
//! assert_eq!(tracker.gc_address(), Some("10.0.0.1:3939".parse().unwrap()));
//!
//! // What the listener hands to the replica's budget: 950 less the margin of 14 for five
//! // robots, counted, with 900 s of game to go (300 of this half and the second).
//! let budget = GcBudget::spl(5);
//! let cap = budget.cap(tracker.game().unwrap(), 12).unwrap();
//! assert!(cap.counted);
//! assert_eq!(cap.team_left, 936);
//! assert_eq!(cap.game_remaining, Duration::from_secs(900));
//! ```

mod budget;
mod control;
mod status;
mod tracker;

#[cfg(test)]
mod tests;

pub use budget::{GcBudget, GcCap};
pub use control::{
    ControlView, GameControlData, GamePhase, RobotInfo, SetPlay, State, TeamInfo,
    GAMECONTROLLER_DATA_PORT, GAMECONTROLLER_STRUCT_HEADER, GAMECONTROLLER_STRUCT_SIZE,
    GAMECONTROLLER_STRUCT_VERSION, KICKING_TEAM_NONE, MAX_NUM_PLAYERS, PENALTY_NONE,
    PENALTY_SUBSTITUTE,
};
pub use status::{
    StatusInputs, StatusMessage, GAMECONTROLLER_RETURN_PORT, GAMECONTROLLER_RETURN_STRUCT_HEADER,
    GAMECONTROLLER_RETURN_STRUCT_SIZE, GAMECONTROLLER_RETURN_STRUCT_VERSION,
};
pub use tracker::{GameTracker, Heard, Received, TrackerStats};

/// Why a GameController packet was dropped.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// Not the structure's exact length (truncated or oversized).
    #[error("{len} bytes, expected {expected}")]
    Length {
        /// The datagram's length.
        len: usize,
        /// The structure's length.
        expected: usize,
    },
    /// The first four bytes are not the structure's header.
    #[error("not a GameController packet (header)")]
    BadHeader,
    /// Another version of the structure.
    #[error("version {0}, this reads {GAMECONTROLLER_STRUCT_VERSION} (RGme) / {GAMECONTROLLER_RETURN_STRUCT_VERSION} (RGrt)")]
    WrongVersion(u8),
    /// A field out of its range.
    #[error("{field} = {value} is out of range")]
    BadField {
        /// The field's name in the C header.
        field: &'static str,
        /// Its value.
        value: u8,
    },
    /// A NaN where the GC takes none (RGrt).
    #[error("a float is NaN")]
    NotANumber,
    /// A game this team does not play in.
    #[error("a game of teams {teams:?}")]
    WrongTeam {
        /// The packet's two team numbers.
        teams: [u8; 2],
    },
}
