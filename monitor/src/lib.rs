//! monitor: watching a team from outside. A listen-only member of its group
//! ([`listen`]: the same `comms::Replica` every robot runs, never allowed to send), the
//! picture it builds from the team's frames alone ([`model`]: blackboard, peers, each
//! robot's world model, the team ball, the should-I-go claims, frame counters), the
//! browser page and its live updates ([`server`]), and recordings of the traffic
//! ([`pcapng`]). `huddle monitor`, `huddle record`, `huddle replay` and
//! `huddle sim --monitor/--record` are thin commands around it.
//!
//! **What it is not.** Not a robot: it sends nothing and arbitrates nothing; it reads no
//! simulator (a simulated match hands it the truth as a [`model::Truth`], from outside).
//!
//! A recording round trip:
//!
//! ```
//! use std::net::{Ipv4Addr, SocketAddrV4};
//! use monitor::pcapng::{self, Packet, Writer};
//!
//! let packet = Packet {
//!     t_ns: 1_500_000_000,
//!     from: SocketAddrV4::new(Ipv4Addr::new(10, 0, 0, 2), 2000),
//!     to: SocketAddrV4::new(Ipv4Addr::new(224, 0, 0, 1), 2000),
//!     payload: b"a frame".to_vec(),
//! };
//! let mut file = Vec::new();
//! let mut writer = Writer::new(&mut file).expect("a Vec takes every write");
//! writer.write(&packet).expect("written");
//! writer.flush().expect("flushed");
//! drop(writer);
//! assert_eq!(pcapng::read(&file).expect("our own file parses"), vec![packet]);
//! ```

#![forbid(unsafe_code)]

pub mod listen;
pub mod model;
pub mod pcapng;
pub mod server;

pub use listen::value_json;
