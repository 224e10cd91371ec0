//! The GameController listener of a node: the daemon's own logic
//! ([`driver::GcListener`]: the tracker, the `local.var.gc.*` keys, the budget fed from
//! the GC's figures, the status packets, the GC's silence) on a thread of the node's own,
//! with blocking sockets, writing to the node's replica under its lock.
//!
//! One difference from the daemon: when a packet moves the budget's next deadline sooner,
//! the receive thread sees it at its next wake-up, at most `STOP_CHECK` (20 ms) later.

use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

use comms::{Entry, ExternalCap, Instant, Value};
use driver::{GameControllerConfig, GcBoard, GcListener};

use crate::engine::{Shared, State, STOP_CHECK};
use crate::error::*;

/// The node's replica as the listener's board, at one instant under the node's lock.
struct NodeBoard<'a> {
    state: &'a mut State,
    now: Instant,
}

impl GcBoard for NodeBoard<'_> {
    fn now(&self) -> Instant {
        self.now
    }

    fn set(&mut self, key: &'static str, value: Value) {
        // The listener's own `local` keys: a refusal would be a bug, and there is no log.
        let _ = self.state.replica.set(self.now, key, value);
    }

    fn get(&self, key: &str) -> Option<Entry> {
        self.state.replica.get(key).ok().flatten().cloned()
    }

    fn set_external_budget(&mut self, game_remaining: Option<Duration>, cap: Option<ExternalCap>) {
        if let Some(remaining) = game_remaining {
            self.state.replica.set_game_clock(self.now, remaining);
        }
        self.state.replica.set_external_budget(cap);
    }
}

/// The sockets the daemon's listener opens: the GC port (shared, so several nodes or
/// daemons on one host all hear the GC's broadcast) and, for status packets, one of its own.
pub(crate) fn open(
    config: &GameControllerConfig,
) -> Result<(UdpSocket, Option<UdpSocket>), Failure> {
    let network = |e: std::io::Error| {
        Failure::new(
            HUDDLE_E_NETWORK,
            format!(
                "cannot listen for the GameController on {}: {e}",
                config.listen
            ),
        )
    };
    let socket = socket2::Socket::new(
        socket2::Domain::for_address(config.listen),
        socket2::Type::DGRAM,
        Some(socket2::Protocol::UDP),
    )
    .map_err(network)?;
    socket.set_reuse_address(true).map_err(network)?;
    socket.set_reuse_port(true).map_err(network)?;
    socket.bind(&config.listen.into()).map_err(network)?;
    let listen: UdpSocket = socket.into();
    listen.set_read_timeout(Some(STOP_CHECK)).map_err(network)?;
    let status = match config.status_period {
        Some(_) => Some(UdpSocket::bind(config.status_from).map_err(network)?),
        None => None,
    };
    Ok((listen, status))
}

/// The listener's thread: datagrams from the GC, a status packet every status period, the
/// silence check every second after the first three, until the node stops.
pub(crate) fn run(
    shared: &Arc<Shared>,
    listen: UdpSocket,
    status: Option<UdpSocket>,
    mut listener: GcListener,
) {
    let mut buf = [0u8; 2048];
    let start = shared.clock.now();
    let status_period = listener.config().status_period;
    let mut next_status = status_period.map(|p| start + p);
    let mut next_check = start + Duration::from_secs(3);
    while !shared.stopping.load(Ordering::Relaxed) {
        let received = match listen.recv_from(&mut buf) {
            Ok(got) => Some(got),
            Err(e) if crate::engine::is_transient(&e) => None,
            Err(e) => {
                if !shared.stopping.load(Ordering::Relaxed) {
                    eprintln!("huddle node: GameController listener stopped: {e}");
                }
                return;
            }
        };
        let mut state = shared.lock();
        if !state.running() {
            return;
        }
        let now = shared.clock.now();
        let mut board = NodeBoard {
            state: &mut state,
            now,
        };
        if let Some((n, from)) = received {
            listener.receive(&mut board, from, &buf[..n]);
        }
        if let (Some(at), Some(period), Some(socket)) = (next_status, status_period, &status) {
            if at <= now {
                listener.status(&mut board, |packet, to: SocketAddr| {
                    socket.send_to(packet, to)
                });
                next_status = Some(now + period);
            }
        }
        if next_check <= now {
            listener.check(&mut board);
            next_check = now + Duration::from_secs(1);
        }
        state.pump(now);
    }
}
