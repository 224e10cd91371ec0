//! The `huddle` package: it ties the crates together. It holds what needs more than one of
//! them: the harness that runs comms replicas over netsim, and the field simulator behind
//! `huddle sim`. The protocol itself lives in `comms`, the filters in `fusion`, the tone
//! codec in `audio` and the network model in `netsim`; this crate adds no protocol logic.

#![forbid(unsafe_code)]

pub mod field;
pub mod harness;
pub mod impair;
pub mod sim;
pub mod summary;
