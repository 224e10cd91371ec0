//! driver: huddle's I/O shell around the sans-IO `comms` core, as quinn is around
//! quinn-proto. It runs a [`comms::Replica`] over a tokio + socket2 UDP socket, with its
//! timers, relay sessions ([`serve`] is the relay's TCP side) and in-process
//! subscribers, and it reads what the core may not: configuration files
//! ([`load_config_files`], [`read_key_file`]: regular files only, size-limited), network
//! interfaces ([`resolve_iface`]), the OS's random source
//! for a replica's incarnation and the monotonic clock (which a test or `huddle sim
//! --daemons` may skew on purpose: [`ClockSkew`]).
//!
//! Frames reach the team by one of three [`Transport`]s, as leagues require: multicast
//! to a group (the default, the seed's), UDP broadcast to the interface's broadcast
//! address (RoboCup SPL: port 10000 + team), or unicast to each listed peer only.
//!
//! **What it is not.** No protocol logic: every frame, version, talk sequence and relay
//! reply is decided by `comms`, which netsim also drives in virtual time, so a test in
//! simulation checks the code that runs here.
//!
//! One task owns everything (socket, replica, timers, watchers) and everything runs on
//! one thread: a hand-off between threads costs a full wake-up, several times the
//! loopback multicast round trip. So the driver and its
//! [`Handle`]s are `!Send`: run them on a current-thread runtime or inside a
//! [`tokio::task::LocalSet`]. The handle works synchronously on the shared state: a
//! [`Handle::set`] updates the replica and sends the resulting frame before it returns.
//!
//! The run loop is str0m's: wait for a datagram, a deadline or a wake-up; feed it in;
//! then drain the outputs (`poll_transmit` → socket, `poll_event` → relay sessions,
//! watches and subscribers) until the replica has nothing more to say.
//!
//! Robot software reacts to changes in one of two ways. A [`Subscription`] is awaited by
//! a task: each notice costs a task wake-up before the task can answer. A [`Watch`]
//! ([`Handle::watch`]) runs a short reaction on the driver's own task, in the turn that
//! applied the change: an answer set from it is on the wire before the driver reads the
//! next datagram, which is the lowest latency this driver offers.
//!
//! When the radio fails, [`audio::Audio`] lets the daemon speak and listen with the
//! 72-tone codec over raw PCM pipes to shell commands (`arecord`, `aplay`, files): heard
//! messages become blackboard writes, and a relay client's `SETV local.var.audio.say`
//! is checked by a write guard ([`Handle::guard`]) and queued for the loudspeaker.
//! The daemon's own keys (the team layer's outputs, the GameController's state, the
//! counters) are read-only to relay clients ([`Handle::reserve`], `ERR 423`).
//!
//! To rehearse a bad WLAN, [`Driver::set_impairment`] passes every outgoing datagram
//! through an [`Impairment`] model (`huddle daemon --impair` plugs in netsim's link
//! model): lost datagrams are never sent, the others wait in a queue released by the
//! same timer as the replica's deadlines.
//!
//! ```no_run
//! # async fn demo() -> Result<(), Box<dyn std::error::Error>> {
//! use driver::{Driver, DriverConfig};
//! use comms::ReplicaConfig;
//!
//! let mut config = DriverConfig::new(ReplicaConfig::new(1, 0));
//! config.socket.group = "239.255.42.1:47000".parse()?;
//! let driver = Driver::bind(config)?; // inside a current-thread runtime / LocalSet
//! let handle = driver.handle();
//! let mut balls = handle.subscribe("+.var.ball.#")?;
//! tokio::task::spawn_local(driver.run(std::future::pending()));
//! handle.set("*.var.ball.dist", 1.5)?;
//! while let Some(notice) = balls.next().await {
//!     println!("{notice:?}");
//! }
//! # Ok(()) }
//! ```

#![forbid(unsafe_code)]

pub mod audio;
mod config_files;
mod gamecontroller;
mod guard;
mod handle;
mod iface;
mod impair;
mod incarnation;
mod notice;
mod rate_limit;
mod relay;
mod run;
mod session;
mod socket;
mod state;
pub mod team;

pub use config_files::{
    load_config, load_config_files, read_key_file, read_regular_file, FileError, KeyFileError,
    LoadConfigError, LoadedConfig, MAX_CONFIG_FILE_BYTES, MAX_KEY_FILE_BYTES,
};
pub use gamecontroller::{
    budget_figures, penalized_players, GameController, GameControllerConfig, GcBoard, GcListener,
};
pub use guard::{
    read_only, read_only_owner, Guard, COUNTERS_OWNER, COUNTER_KEYS, GC_KEYS, GC_OWNER, TEAM_KEYS,
    TEAM_OWNER,
};
pub use handle::{Batch, DriverStats, Handle, Watch};
pub use iface::{broadcast_address, resolve_iface, IfaceError};
pub use impair::Impairment;
pub use incarnation::new_incarnation;
pub use notice::{Notice, Subscription};
pub use rate_limit::RateLimit;
pub use relay::serve;
pub use run::{Driver, DriverConfig, DriverError, DEFAULT_MAX_RELAY_CLIENTS};
pub use session::{PeerEvent, PeerEvents, Session, Updates};
pub use socket::{
    broadcast_destination, open, open_broadcast, open_multicast, open_unicast, scratch_group,
    Opened, SocketConfig, SocketError, Transport,
};
pub use state::{Clock, ClockSkew, ClockSkewError, IoStats};
