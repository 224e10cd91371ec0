//! The `huddle` package: it ties the crates together. It holds what needs more than one of
//! them: the harness that runs comms replicas over netsim, and the field simulator behind
//! `huddle sim`. The protocol itself lives in `comms`, the filters in `fusion`, the tone
//! codec in `audio` and the network model in `netsim`, the sockets in `driver`; this crate
//! adds no protocol logic. Its field behaviour (formations, CMUnited-97's modes and
//! pass-or-shoot choice) sits in [`field`], above the team communication it uses.
//!
//! **What it is not.** Not a library robots link for communication (that is `comms`,
//! with `driver` around it): the simulator here plays robots whose software is written
//! for the simulation.
//!
//! Two seconds of the default match (five robots, the `competition` network):
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

pub mod field;
pub mod harness;
pub mod impair;
pub mod sim;
pub mod summary;
