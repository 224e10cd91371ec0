//! huddle: team communication for robot teams. Each robot holds a blackboard of
//! `key = value` bindings; what it writes under `*.var.` reaches every teammate over
//! multicast (or broadcast, or unicast), where it reads as `<robot>.var.`, stamped on the
//! reader's own clock; `*.talk.` queues deliver messages in order, exactly once.
//!
//! This crate is the front door for Rust robot software: [`open`] a [`Session`] (a
//! `Send + Sync + Clone` handle, usable from any task of an ordinary `#[tokio::main]`
//! program), [`Session::set`] and [`Session::get_as`] values, [`Session::subscribe`] to
//! changes as a [`Stream`](futures_util::Stream) and follow teammates joining and leaving
//! with [`Session::peer_events`]. Values convert with [`Value::as_f64`] and friends or
//! `f64::try_from(&value)`.
//!
//! **What it is not.** The protocol is not here: it is the sans-IO `comms` crate, run by
//! the tokio shell in `driver`. For the lowest latency (an answer sent in the very turn
//! that received the question) run a [`driver::Driver`] on one thread and react with
//! [`driver::Handle::watch`]; that handle is `!Send` on purpose. The team simulator
//! behind `huddle sim` is the `teamsim` crate, re-exported here as [`sim`] and [`field`]
//! with the netsim harness as [`harness`]; the binary's command line is this crate's
//! `main.rs` and `cli` modules.
//!
//! Two robots in one process, on loopback:
//!
//! ```
//! use huddle::{Config, Notice, StreamExt};
//!
//! # #[tokio::main(flavor = "multi_thread", worker_threads = 2)]
//! # async fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let group = huddle::scratch_group()?; // a group no other run uses
//! let one = huddle::open(Config::new(1, 0).group(group)).await?;
//! let mut balls = one.subscribe("+.var.ball.#")?;
//! let two = huddle::open(Config::new(2, 0).group(group)).await?;
//! two.set("*.var.ball.dist", 1.5)?;
//!
//! let wait = std::time::Duration::from_secs(5);
//! let Some(Notice::Changed { key, entry }) = tokio::time::timeout(wait, balls.next()).await?
//! else {
//!     panic!("robot 1 hears robot 2's ball")
//! };
//! assert_eq!(key.to_string(), "2.var.ball.dist");
//! assert_eq!(entry.value.as_f64(), Some(1.5));
//! assert_eq!(one.get_as::<f64>("2.var.ball.dist")?, Some(1.5));
//! # Ok(()) }
//! ```
//!
//! The simulator: two seconds of the default match (five robots, the `competition`
//! network):
//!
//! ```
//! use huddle::sim::{SimConfig, Simulation};
//!
//! let cfg = SimConfig { duration_s: 2.0, seed: 7, ..SimConfig::default() };
//! let mut sim = Simulation::new(cfg).expect("the defaults are valid");
//! sim.run(|_t_s| {});
//! let report = sim.report(0.0);
//! assert!(report.frames_sent > 0, "the robots talked");
//! ```

#![forbid(unsafe_code)]

mod config;
pub mod impair;
pub mod summary;

/// The team simulator behind `huddle sim` (the `teamsim` crate).
pub use teamsim as sim;
/// The simulated field's truth: ball, bodies, cameras (the `teamsim` crate's `field`).
pub use teamsim::field;

pub use comms::{Entry, Instant, Key, Value, ValueType, WrongType};
/// N replicas over a netsim network in virtual time (the `comms-netsim` crate), for the
/// simulator and tests.
pub use comms_netsim as harness;
pub use config::{open, Config};
pub use driver::{
    scratch_group, DriverError as Error, DriverStats as Stats, Notice, PeerEvent, PeerEvents,
    Session, Transport, Updates,
};
pub use futures_util::StreamExt;
/// The crates behind the front door, for what it does not re-export.
pub use {comms, driver};
