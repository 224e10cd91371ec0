//! comms: huddle's blackboard and the sans-IO protocol that replicates it across a team.
//!
//! **What it is.** A [`Blackboard`] of symbol → value bindings after ISocRob's
//! `hal-blackboard` (isocrob-2000 §3.1): dot-separated [`Key`]s whose first level is
//! `local` (this robot only), `*` (global) or a robot id, whose second level is `var` (a
//! value) or `talk` (a message queue); typed [`Value`]s; every entry stamped on **this**
//! robot's clock. A [`Replica`] owns a blackboard and keeps the team's copies in step over
//! one lossy multicast group: writing `*.var.x` on robot n publishes it, and every robot
//! (n too) reads it as `n.var.x`; reading `*.var.x` gives the newest copy. Around it: the
//! value [literal] syntax and type names shared with the relay protocol and config files,
//! MQTT-style [`Pattern`]s (`+.var.machine.heuristic`, `2.var.#`), `config.dat` parsing
//! ([`parse_config`]) and the frame format ([`wire`]).
//!
//! **What it is not.** No sockets, threads, clocks or randomness: the replica is a state
//! machine in the quinn / str0m style. Time comes in as [`Instant`] (microseconds on the
//! robot's monotonic clock, read by the driver), the incarnation number comes from the
//! driver's RNG, and datagrams go in and out as byte slices. The tokio/socket2 driver, the
//! relay TCP server and configuration file loading are the `driver` crate; netsim runs
//! the very same machine in virtual time.
//!
//! # The run loop
//!
//! After **every** input (`handle_datagram`, `handle_timeout`, `set`, `post`), drain
//! [`Replica::poll_transmit`] (send each payload to the team group) and
//! [`Replica::poll_event`] until both return `None`, then sleep until
//! [`Replica::poll_timeout`] or the next datagram, whichever comes first, and call
//! [`Replica::handle_timeout`] when the deadline passes. Changes made by one input go out
//! together in as few frames as fit the MTU; ages in a frame are measured to the latest
//! `now` any input carried, so draining at once keeps them exact.
//!
//! # What goes over the wire
//!
//! A frame (see [`wire`]) carries an 18-byte header (magic, version, flags, team, sender,
//! incarnation, send stamp), optionally a 5-byte echo of one teammate's frame, a sequence
//! number and items: updates `(path, value, version, age)`, talk messages, talk heads and
//! NACKs, and optionally a 16-byte truncated HMAC-SHA256 tag. The receiver stamps an
//! update at *reception time − the frame's transit − reported age* on its own clock, so
//! no robot compares clocks in the API and a re-sent old value never looks fresh.
//!
//! **Shared time.** The transit is estimated per frame from the traffic itself, NTP-style
//! with no extra message and no server: every frame carries the sender's clock at send (a
//! u32 of microseconds, wrapping every 71.6 minutes) and echoes one teammate (rotating to
//! the one whose echo is oldest): which of its frames was heard last and how long it was
//! held. Each robot so measures round trips to every teammate and keeps, per teammate, an
//! estimate of that teammate's clock offset and drift against its own (shortest round
//! trip per second over the last minute, a weighted line fit); a frame's transit is then
//! its reception minus its send stamp brought to this robot's clock. So ages read through
//! [`Blackboard`], `get`, the relay's `GETV`/`VAL`/`UPD` and the C API include the time on
//! the air, queues and an access point's beacon hold, frame by frame. Until a teammate's
//! first echo comes back (one round trip) its frames are taken to have travelled
//! `ReplicaConfig::default_transit` (default 0: the age then leaves the transit out, as
//! before); `ReplicaConfig::clock_sync = false` keeps that for good. The estimate is
//! internal; [`PeerInfo`] shows it for diagnostics (offset, drift, round trip, samples).
//! What it cannot remove is a path's asymmetry: half the difference between the two
//! directions' delays in the shortest round trips (a few ms on a WLAN; more when an
//! access point holds multicast to DTIM beacons, see `tests/shared_time.rs`). Echoes
//! naming a frame not sent recently, with a round trip outside 0..1 s, or far from the
//! estimate are refused and counted; a send stamp implying a transit outside −50 ms..1 s
//! falls back to the default. Versions count per
//! (owner, key) within an owner's incarnation: older updates never overwrite newer ones.
//! Incarnations are ordered (a later start has a larger one, see [`ordered_incarnation`]):
//! a larger one is a restart, accepted at once; frames of a smaller one are dropped. Every own global value is re-sent each `refresh_period` (default 100 ms),
//! which repairs losses and is the heartbeat; a robot silent for `departed_after`
//! (default 300 ms) is reported departed. A robot heard for the first time, again after
//! departing, or restarted gets an extra full refresh at once (unless one went out in
//! the last quarter period), so a healed partition or a reboot does not wait for the
//! schedule. A frame's overhead is the 18-byte header, the 5-byte echo (on most frames
//! of a team), the seq and item-count varints (1 to 9 bytes each, growing with the
//! counters) and the 16-byte tag when keyed; each update
//! adds its path, value, version and age ([`wire`] has the exact sizes).
//!
//! `talk` queues (`*.talk.q`) deliver each message to every teammate exactly once and in
//! order despite loss, duplication and reordering: per-queue sequence numbers, gap
//! detection, NACK-driven repair from a bounded retention buffer, and an explicit
//! [`Event::TalkGivenUp`] when a message cannot be recovered (never silent loss).
//!
//! # Security model
//!
//! **With a team key** (`ReplicaConfig::with_team_key`, `huddle daemon --key-file`), every
//! frame carries a truncated HMAC-SHA256 tag over its bytes, so nothing an outsider on the
//! WLAN sends can change this robot's state: unsigned and badly signed frames are dropped
//! and counted. Within an incarnation a 64-frame replay window drops repeated and too old
//! frames. A frame recorded in a robot's earlier life and replayed later changes nothing
//! at a receiver that has heard the robot's current life: its incarnation is smaller, so it
//! is dropped, never applied and never taken for a restart. A receiver that has never
//! heard the robot accepts the first life it hears, until it hears a newer one. The key
//! does not hide the contents (frames are signed, not encrypted) and does not protect
//! against a teammate that holds the key.
//!
//! **Without a key**, a team trusts its LAN: any host can write any robot's values. What
//! is still bounded is the damage one stray or misconfigured sender can do: a frame with a
//! forged newer incarnation costs the real robot at most `departed_after` and a few frames
//! (it keeps sending in its life and is heard again); two robots sending with one id are
//! reported ([`Event::IncarnationConflict`], `id_conflicts`) and the older takes over
//! again within `departed_after` of the newer leaving; a forged version or talk head cannot
//! pin a value or silence a queue; bindings per owner and in total, talk reorder buffers
//! and repairs have bounds that cannot be exceeded from the network.
//!
//! # Panic policy
//!
//! Nothing received from the network, read from a file or typed by a user panics:
//! malformed datagrams become counted drops ([`Stats`], [`DropReason`], mirrored into
//! `local.var.huddle.stats.*` at each refresh), bad keys, literals and config lines become
//! typed errors. `comms/fuzz` holds a cargo-fuzz target for frame decoding:
//! `cd comms/fuzz && cargo +nightly fuzz run decode_frame` (needs `cargo install
//! cargo-fuzz`; not run in CI).
//!
//! # Example
//!
//! Two robots, joined by a loop that hands every frame to the other one:
//!
//! ```
//! use std::net::SocketAddr;
//! use std::time::Duration;
//! use comms::{Event, Instant, Replica, ReplicaConfig, Value};
//!
//! let t0 = Instant::from_micros(0);
//! let mut robot1 = Replica::new(ReplicaConfig::new(1, 7), 0x1111, t0).unwrap();
//! let mut robot2 = Replica::new(ReplicaConfig::new(2, 7), 0x2222, t0).unwrap();
//! let from = SocketAddr::from(([127, 0, 0, 1], 2000));
//!
//! // Robot 1 publishes its cost to reach the ball and posts a plan to its talk queue.
//! robot1.set(t0, "*.var.machine.heuristic", Value::Float(2.5)).unwrap();
//! robot1.set(t0, "local.var.debug", Value::from("never leaves robot 1")).unwrap();
//! robot1.post(t0, "*.talk.plan", Value::from("pass to 2")).unwrap();
//!
//! // 3 ms later the frames arrive at robot 2.
//! let t1 = t0 + Duration::from_millis(3);
//! while let Some(transmit) = robot1.poll_transmit() {
//!     robot2.handle_datagram(t1, from, &transmit.payload);
//! }
//!
//! let cost = robot2.get("1.var.machine.heuristic").unwrap().expect("replicated");
//! assert_eq!(cost.value, Value::Float(2.5));
//! assert_eq!(cost.owner, 1);
//! assert_eq!(
//!     cost.age(t1),
//!     Duration::ZERO,
//!     "stamped at reception − the sender's age − the default transit (0): no echo yet"
//! );
//! assert!(robot2.get("1.var.debug").unwrap().is_none());
//! // `*` reads the newest copy of any owner.
//! assert_eq!(robot2.get("*.var.machine.heuristic").unwrap().unwrap().owner, 1);
//!
//! let mut plan = None;
//! while let Some(event) = robot2.poll_event() {
//!     if let Event::TalkDelivered { queue, from, seq, value } = event {
//!         plan = Some((queue, from, seq, value));
//!     }
//! }
//! assert_eq!(plan, Some(("plan".into(), 1, 1, Value::from("pass to 2"))));
//! ```

#![forbid(unsafe_code)]

pub mod arbitration;
mod blackboard;
mod config;
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

pub use blackboard::{Applied, Blackboard, BoardLimits, Entry, SetError};
pub use config::{parse_config, ConfigEntry, ConfigError, LineError};
pub use key::{validate_path, Key, KeyError, Kind, Scope, MAX_PATH_LEN, ROBOT_IDS};
pub use literal::{parse_literal, parse_literal_prefix, LiteralError};
pub use pattern::{Pattern, PatternError, PatternIndex};
pub use replica::{
    ordered_incarnation, Budget, BudgetParseError, BudgetSpec, ChangeAt, ConfigInvalid,
    Destination, Event, ExternalCap, PostError, Replica, ReplicaConfig, Transmit, FREE_GAP,
};
pub use stats::{DropReason, PeerInfo, Stats};
pub use talk::TalkLimits;
pub use time::Instant;
pub use value::{UnknownType, Value, ValueType, WrongType};
