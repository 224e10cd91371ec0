//! netsim: a deterministic network simulator in virtual time, and the link model behind it.
//!
//! It lets a whole robot team run in one process, repeatably and far faster than real
//! time, on the same sans-IO protocol code that runs on the robots. Nodes exchange
//! datagrams over one-way links and multicast groups; each link delays, jitters, loses
//! (independently and in Gilbert–Elliott bursts), duplicates, reorders and rate-limits
//! packets, all drawn from a random stream of its own derived from one master seed. The
//! same seed gives the same run byte for byte (compare [`Trace::hash`]); retuning one
//! link never changes what happens on another.
//!
//! It is **not** a packet-level model of 802.11 or IP: there are no retransmissions,
//! fragmentation or congestion control, and a payload is delivered as given (bandwidth
//! counts payload bytes only). Each one-way link has its own queue: the air is not a
//! medium shared between links, so a multicast to four receivers is serialised four times
//! in parallel. It never reads a clock, sleeps, or opens a socket. It depends on nothing
//! else in huddle.
//!
//! # Pieces
//!
//! - [`Time`]: nanoseconds since the start (a `u64` newtype); spans are [`std::time::Duration`].
//! - [`LinkConfig`] (what a link does; parses from spec strings such as
//!   `"loss=20%,delay=50ms,jitter=20ms"`, see [`spec`]) and [`LinkModel`] (a config with
//!   its random stream, burst state and bandwidth queue). [`LinkModel`] is sans-IO and
//!   usable alone: a real-socket driver calls [`LinkModel::transmit`]`(now, len)` and holds
//!   the datagram until the returned times.
//! - [`UplinkConfig`]: the part of the loss shared by all receivers of one transmission
//!   (the sender's radio hop); links add the per-receiver part.
//! - [`Preset`]: `lan`, `wlan`, `competition` (20% loss with bursts, 20 ms ± 10 ms, power
//!   save off) and `competition-ps` (the same with multicast held to DTIM beacons every
//!   204.8 ms).
//! - [`Sim`]: nodes, groups, the event queue, fault verbs ([`Sim::partition`],
//!   [`Sim::isolate`], [`Sim::repair`], [`Sim::heal`], or [`Sim::at`] for a schedule),
//!   per-node clocks ([`NodeClock`]), statistics ([`LinkStats`]), the [`Trace`] and
//!   [`pcap`] output.
//!
//! # Driving it from a harness
//!
//! A harness runs sans-IO replicas, each with its own timer, over one `Sim`. Time only
//! moves inside `run_until`, so the loop is: find the earliest of the network's next
//! event and every replica's deadline (a replica's deadline is on its own clock: convert
//! it with [`NodeClock::to_global`]); `run_until` that instant; hand each node what it
//! received ([`Sim::recv`], with [`Delivery::local_at`] as the receive timestamp on the
//! node's clock) and fire the due timers; then send whatever the replicas produced with
//! [`Sim::send`] (at the current time) and go round again. Loopback copies arrive at the
//! current instant, so the next `run_until(now)` hands them over.
//!
//! # Example
//!
//! ```
//! use netsim::{Dest, Preset, Sim, Time};
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut sim = Sim::builder().seed(42).preset(Preset::Lan).build()?;
//! let robots = sim.add_nodes(3);
//! let team = sim.add_group(&robots)?;
//!
//! sim.send(robots[0], Dest::Group(team), b"ball at 1.0 2.0".to_vec())?;
//! sim.run_until(Time::from_millis(10));
//!
//! let got = sim.recv(robots[2]).expect("a LAN does not lose packets");
//! assert_eq!(got.from, robots[0]);
//! assert_eq!(&got.bytes[..], b"ball at 1.0 2.0");
//! assert!(got.at > Time::ZERO && got.at < Time::from_millis(1), "about 100 µs on a LAN");
//! assert!(sim.recv(robots[0]).is_some(), "the sender hears its own multicast (loop on)");
//! assert_eq!(sim.link_stats(robots[0], robots[1]).unwrap().delivered, 1);
//! # Ok(())
//! # }
//! ```

#![forbid(unsafe_code)]

mod burst;
mod clock;
mod impairment;
mod link;
pub mod pcap;
mod preset;
mod seed;
mod sim;
pub mod spec;
mod stats;
mod time;
mod trace;

pub use clock::{ClockError, NodeClock, MAX_DRIFT_PPM};
pub use impairment::{
    ConfigError, GilbertElliott, JitterDist, LinkConfig, UplinkConfig, DEFAULT_QUEUE_LIMIT,
    PARETO_SHAPE,
};
pub use link::{DropReason, LinkModel, Verdict};
pub use preset::{dtim_interval, Preset, BEACON_INTERVAL, DEFAULT_DTIM_PERIOD};
pub use sim::{Action, ActionError, Delivery, Dest, GroupId, NodeId, SendError, Sim, SimBuilder};
pub use spec::{parse_duration, parse_probability, SpecError};
pub use stats::LinkStats;
pub use time::Time;
pub use trace::{Trace, TraceEvent, TraceKind};
