//! huddle-bridge: a listen-only bridge from one huddle team's field to Zenoh.
//!
//! huddle's multicast stays on its link (TTL 1, one group per team); what has to leave
//! the field (to a venue's log server, referees, a lab's other subnet, a ROS 2 stack)
//! leaves through Zenoh, whose routers, ACLs, TLS and ROS 2 bridges are built for it.
//!
//! **What it is.** A passive replica: the same `comms::Replica` the robots run, joined to
//! the team's group (or broadcast port, or as a unicast peer), checking the team key,
//! fed every datagram heard. What that replica would transmit (heartbeat, NACKs) is
//! discarded: the bridge never sends on the field. What it learns goes to one Zenoh
//! session ([`run`]) as samples under [`keys`]' key expressions, decided by the sans-IO
//! [`export::Exporter`] (changes only, a per-key rate cap, `local.*` never, liveliness
//! tokens for presence); a queryable answers `get` from the replica with ages computed at
//! reply time, plus `@bridge/stats` and `@bridge/peers`. With `--ros2` each value also
//! goes out as a CDR `std_msgs` message ([`cdr`]).
//!
//! **What it is not.** Not a relay network (Zenoh routes), not a writer: nothing from
//! Zenoh reaches the field, so a robot's board can only be read through it. Not part of
//! the default `huddle` build: only this crate depends on `zenoh`.
//!
//! ```
//! use huddle_bridge::keys::TeamKeys;
//! use huddle_bridge::export::{ExportConfig, Exporter};
//!
//! let keys = TeamKeys::new("robocup-2026", 7, "huddle_ros").unwrap();
//! assert_eq!(keys.var(2, "ball.dist").unwrap(), "huddle/@v1/robocup-2026/7/2/var/ball/dist");
//! let exporter = Exporter::new(keys, ExportConfig::default());
//! assert_eq!(exporter.stats().values_out, 0);
//! ```

#![forbid(unsafe_code)]

pub mod bench;
pub mod bench_load;
pub mod bench_variants;
pub mod cdr;
pub mod cli;
pub mod export;
pub mod harness;
pub mod keys;
pub mod loadgen;
pub mod outbox;
pub mod run;
pub mod transit;
