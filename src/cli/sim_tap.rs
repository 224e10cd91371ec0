//! What a listener beside robot 1 hears in a simulated match: every datagram delivered
//! to robot 1's node (its own frames too, looped back as on a real host), read from the
//! simulated network's trace as the match runs. The times are the network's global
//! virtual time; a match starts at the Unix epoch.

use std::net::{Ipv4Addr, SocketAddrV4};

use huddle::sim::Simulation;
use netsim::TraceKind;

use monitor::pcapng::Packet;

/// The group a simulated match's packets are addressed to in a recording (netsim's pcap
/// convention: group 1 is 224.0.0.1, port 2000).
pub const SIM_GROUP: SocketAddrV4 = SocketAddrV4::new(Ipv4Addr::new(224, 0, 0, 1), 2000);

/// Reads new deliveries from a simulation's trace.
#[derive(Default)]
pub struct SimTap {
    next: usize,
}

impl SimTap {
    /// A tap that starts at the beginning of the trace.
    pub fn new() -> Self {
        Self::default()
    }

    /// Calls `each` with every datagram delivered to robot 1 since the last call.
    pub fn drain(&mut self, sim: &Simulation, mut each: impl FnMut(Packet)) {
        let listener = sim.harness.node(0);
        let events = sim.harness.net().trace().events();
        for event in events.get(self.next..).unwrap_or_default() {
            let TraceKind::Deliver {
                from, to, bytes, ..
            } = &event.kind
            else {
                continue;
            };
            if *to != listener {
                continue;
            }
            let [hi, lo] = from.0.to_be_bytes();
            each(Packet {
                t_ns: event.at.as_nanos(),
                from: SocketAddrV4::new(Ipv4Addr::new(10, 0, hi, lo), 2000),
                to: SIM_GROUP,
                payload: bytes.to_vec(),
            });
        }
        self.next = events.len();
    }
}
