//! Impairing the driver's outgoing datagrams, to rehearse a bad WLAN on real sockets.
//!
//! The model lives outside comms (comms depends on no simulator): the `huddle` binary
//! plugs netsim's `LinkModel` in through [`Impairment`] for `huddle daemon --impair`.
//! The driver asks the model, for every datagram it would send, when each copy should
//! go on the socket (none: lost; two: duplicated), holds the copies in a queue and
//! releases them with tokio timers. The sans-IO replica never knows: what it produced
//! leaves later, or never, exactly as if the air had delayed or lost it.
//!
//! **Outgoing, not incoming.** A WLAN loses and delays a multicast frame on the
//! sender's transmission, so the impairment sits where the driver sends; with every
//! robot running `--impair`, every direction is impaired exactly once. One consequence:
//! all receivers of one multicast frame share its fate (netsim's shared *uplink* loss);
//! unicast copies to `--peer`s get their own random stream per destination. Frames carry
//! ages measured when they were produced, so a held frame arrives looking as old as it
//! is, as after a slow network. Own frames looped back by the kernel are delayed too
//! (the replica ignores them anyway).

use std::net::SocketAddr;

use comms::Instant;

/// A model of what the network does to outgoing datagrams.
pub trait Impairment {
    /// A datagram of `len` bytes for `to` is ready at `now` (the driver's clock): push
    /// onto `copies` when each copy should go on the socket (at or after `now`). Push
    /// nothing to lose it, two times to duplicate it. `now` never goes backwards.
    fn judge(&mut self, now: Instant, to: SocketAddr, len: usize, copies: &mut Vec<Instant>);
}

/// A copy waiting for its time. Ordered by time, then insertion order (unique), so the
/// driver's min-heap of them (through [`std::cmp::Reverse`]) sends copies due at the
/// same instant first-in first-out.
#[derive(PartialEq, Eq, PartialOrd, Ord)]
pub(crate) struct Held {
    pub(crate) at: Instant,
    pub(crate) order: u64,
    pub(crate) payload: std::rc::Rc<[u8]>,
    pub(crate) to: SocketAddr,
}
