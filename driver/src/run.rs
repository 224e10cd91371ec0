//! The driver task: one task owning the socket, the replica, its timers, relay sessions
//! and in-process subscribers; what they share is in `state.rs`.

use std::cell::RefCell;
use std::collections::{BTreeMap, BinaryHeap, VecDeque};
use std::future::Future;
use std::io;
use std::net::SocketAddr;
use std::rc::Rc;
use std::task::Poll;

use thiserror::Error;
use tokio::net::UdpSocket;

use comms::relay::SessionLimits;
use comms::{ConfigInvalid, Key, PatternIndex, Replica, ReplicaConfig, SetError, Value};

use crate::handle::Handle;
use crate::impair::Impairment;
use crate::incarnation::new_incarnation;
use crate::rate_limit::RateLimit;
use crate::socket::{open, open_unicast, SocketConfig, SocketError, Transport};
use crate::state::{
    run_reactions, Clock, ClockSkew, Inner, IoStats, Nudge, KEY_WARNING_PERIOD, SEND_WARNING_PERIOD,
};

/// Datagrams handled per wake-up before the loop looks at timers and wake-ups again.
const RECV_BATCH: usize = 256;
/// Rounds of reading and reacting per wake-up (each ends at a datagram that gave a
/// watch, subscriber or relay session something to do) before the loop looks at timers,
/// the backlog and shutdown again.
const READ_ROUNDS: usize = 16;
/// Shutdown is looked at on every pass that finds nothing to read, and first on every
/// this many passes, so that a flood of datagrams cannot hold it off.
const SHUTDOWN_EVERY: u32 = 16;

/// Everything the driver needs to start.
#[derive(Clone, Debug)]
pub struct DriverConfig {
    /// The replica's settings (robot and team id, refresh period, MTU, key, talk).
    pub replica: ReplicaConfig,
    /// The team's socket: transport (multicast, broadcast, unicast), group or port,
    /// interface.
    pub socket: SocketConfig,
    /// Teammates that also get every frame by unicast (WLAN access points often drop
    /// or delay multicast). Duplicates are harmless. With peers, a second socket bound to
    /// `<iface>:<port>` sends to them and receives their unicast; datagrams on it from any
    /// other address are dropped (counted in [`IoStats::unicast_refused`]). Without peers
    /// no unicast is received at all. Note: on one host, unicast to a port shared by
    /// several replicas reaches only one of them.
    ///
    /// With [`Transport::Unicast`] the peers are the only destinations and the only
    /// accepted senders, on the one socket bound to `<iface>:<port>`; at least one is
    /// needed.
    pub peers: Vec<SocketAddr>,
    /// Values set before the first frame goes out (`config.dat`, `config-<id>.dat`).
    pub start_values: Vec<(Key, Value)>,
    /// Notices an in-process subscriber may leave unread before the oldest are dropped
    /// (it then gets [`crate::Notice::Lagged`]).
    pub subscriber_backlog: usize,
    /// Limits of each relay session.
    pub session_limits: SessionLimits,
    /// Relay clients served at once (default [`DEFAULT_MAX_RELAY_CLIENTS`]): a
    /// connection beyond gets one line `ERR 503 ...` and is closed, counted in
    /// [`IoStats::relay_clients_refused`]; the clients already connected are unaffected.
    /// Each session holds up to a line and 1 MiB of output, so one host opening
    /// thousands of connections could otherwise take the daemon's memory and descriptors.
    pub max_relay_clients: usize,
    /// The incarnation; `None`: a random one (it must differ between starts).
    pub incarnation: Option<u64>,
    /// A deliberate error of this robot's clock, for rehearsing a team whose clocks
    /// disagree on one machine ([`ClockSkew`]); none by default.
    pub clock_skew: ClockSkew,
}

/// Relay clients a driver serves at once unless configured otherwise
/// ([`DriverConfig::max_relay_clients`], `huddle daemon --max-clients`).
pub const DEFAULT_MAX_RELAY_CLIENTS: usize = 64;

impl DriverConfig {
    /// Defaults around `replica`: the seed's group `224.0.0.1:2000` on loopback, TTL 1,
    /// a 4 MiB receive buffer, no peers.
    pub fn new(replica: ReplicaConfig) -> DriverConfig {
        // The driver runs the team layer: its keys go by index unless the application
        // registered a table of its own (which must then include them).
        let replica = if replica.known_paths.is_empty() {
            replica.with_known_paths(team::known_paths())
        } else {
            replica
        };
        DriverConfig {
            replica,
            socket: SocketConfig::default(),
            peers: Vec::new(),
            start_values: Vec::new(),
            subscriber_backlog: 4096,
            session_limits: SessionLimits::default(),
            max_relay_clients: DEFAULT_MAX_RELAY_CLIENTS,
            incarnation: None,
            clock_skew: ClockSkew::NONE,
        }
    }
}

/// Why the driver could not start.
#[derive(Debug, Error)]
pub enum DriverError {
    /// The team's socket could not be set up.
    #[error(transparent)]
    Socket(#[from] SocketError),
    /// [`Transport::Unicast`] without a peer: no frame would go anywhere.
    #[error("the unicast transport sends to each --peer only, and none is given")]
    NoPeers,
    /// The replica configuration is invalid.
    #[error("invalid replica configuration: {0}")]
    Replica(#[from] ConfigInvalid),
    /// A start value was refused (e.g. a config line sets another robot's key).
    #[error("start value {key}: {source}")]
    StartValue {
        /// The key.
        key: String,
        /// Why.
        source: SetError,
    },
    /// Registering the socket with tokio failed (no runtime?).
    #[error("cannot register the socket with tokio: {0}")]
    Runtime(io::Error),
    /// Receiving or waiting on the socket failed for good.
    #[error("socket error: {0}")]
    Io(io::Error),
}

/// What a call of [`Driver::receive_batch`] left behind.
struct Batch {
    /// A watch has reactions queued, or a subscriber or relay session got a notice.
    woke: bool,
    /// Every socket said "would block": nothing more to read until the next wake-up.
    drained: bool,
}

/// What ended a wait of the run loop.
enum Cause {
    Shutdown,
    Readable,
    Deadline,
    Writable,
    Nudged,
}

/// The driver: owns the socket and the replica; run it with [`Driver::run`].
pub struct Driver {
    inner: Rc<RefCell<Inner>>,
    socket: Rc<UdpSocket>,
    unicast: Option<Rc<UdpSocket>>,
    /// `socket` takes datagrams from peers only (the unicast transport).
    peers_only: bool,
    wake: Rc<Nudge>,
}

/// The transport's sockets, registered with the current tokio runtime: what
/// [`Driver::bind`] and [`crate::Session::open`] both open.
pub(crate) struct Sockets {
    /// The team's socket (the group's for multicast).
    pub(crate) team: UdpSocket,
    /// A second socket for `--peer` unicast copies beside multicast or broadcast.
    pub(crate) unicast: Option<UdpSocket>,
    /// Where frames to the team go (none for unicast: each peer gets its copy).
    pub(crate) destination: Option<SocketAddr>,
    /// `team` takes datagrams from peers only (the unicast transport).
    pub(crate) peers_only: bool,
    /// The receive buffer the kernel granted the team's socket, bytes.
    pub(crate) recv_buffer_granted: usize,
}

/// Opens the sockets `config` asks for.
pub(crate) fn open_sockets(config: &DriverConfig) -> Result<Sockets, DriverError> {
    let peers_only = config.socket.transport == Transport::Unicast;
    if peers_only && config.peers.is_empty() {
        return Err(DriverError::NoPeers);
    }
    let opened = open(&config.socket)?;
    let destination = opened.destination.map(SocketAddr::V4);
    let team = UdpSocket::from_std(opened.socket).map_err(DriverError::Runtime)?;
    let unicast = if config.peers.is_empty() || peers_only {
        None
    } else {
        let std_socket = open_unicast(&config.socket)?;
        Some(UdpSocket::from_std(std_socket).map_err(DriverError::Runtime)?)
    };
    Ok(Sockets {
        team,
        unicast,
        destination,
        peers_only,
        recv_buffer_granted: opened.recv_buffer_granted,
    })
}

/// The replica `config` describes in this life (`incarnation`, or a new one), its start
/// values set and their events dropped.
pub(crate) fn start_replica(
    config: ReplicaConfig,
    incarnation: Option<u64>,
    start_values: Vec<(Key, Value)>,
    clock: &Clock,
) -> Result<Replica, DriverError> {
    let incarnation = incarnation.unwrap_or_else(new_incarnation);
    let mut replica = Replica::new(config, incarnation, clock.now())?;
    for (key, value) in start_values {
        replica
            .set_key(clock.now(), &key, value)
            .map_err(|source| DriverError::StartValue {
                key: key.to_string(),
                source,
            })?;
    }
    // Start values are this robot's business, not changes anyone waits for.
    while replica.poll_event().is_some() {}
    Ok(replica)
}

impl Driver {
    /// Opens the transport's socket (joining the group for multicast) and starts the
    /// replica with the start values. Call it inside a tokio runtime (the socket
    /// registers with its reactor).
    pub fn bind(config: DriverConfig) -> Result<Driver, DriverError> {
        let transport = config.socket.transport;
        let Sockets {
            team,
            unicast,
            destination,
            peers_only,
            recv_buffer_granted,
        } = open_sockets(&config)?;
        let socket = Rc::new(team);
        let unicast = unicast.map(Rc::new);
        let clock = Clock::skewed(config.clock_skew);
        let replica = start_replica(
            config.replica,
            config.incarnation,
            config.start_values,
            &clock,
        )?;
        let wake = Rc::new(Nudge::default());
        let inner = Inner {
            clock,
            replica,
            socket: socket.clone(),
            unicast: unicast.clone(),
            destination,
            peers: config.peers,
            backlog: VecDeque::new(),
            subscribers: PatternIndex::new(),
            watches: PatternIndex::new(),
            reactions: VecDeque::new(),
            reacting: false,
            guards: Vec::new(),
            read_only: Vec::new(),
            subscriber_backlog: config.subscriber_backlog.max(1),
            sessions: BTreeMap::new(),
            next_session: 0,
            session_limits: config.session_limits,
            max_relay_clients: config.max_relay_clients,
            clients_refused_warnings: RateLimit::new(SEND_WARNING_PERIOD),
            io: IoStats {
                recv_buffer_bytes: recv_buffer_granted,
                ..IoStats::default()
            },
            io_mirrored: None,
            wake: wake.clone(),
            impairment: None,
            held: BinaryHeap::new(),
            held_order: 0,
            copies: Vec::new(),
            handed_up: 0,
            key_mismatch: RateLimit::new(KEY_WARNING_PERIOD),
            send_failures: RateLimit::new(SEND_WARNING_PERIOD),
            give_up_warnings: RateLimit::new(SEND_WARNING_PERIOD),
            tx_buf: Vec::with_capacity(2048),
        };
        tracing::info!(
            robot = inner.replica.robot_id(),
            %transport,
            to = %destination.map_or_else(|| "each peer".to_owned(), |d| d.to_string()),
            port = config.socket.group.port(),
            iface = %config.socket.iface,
            recv_buffer_bytes = recv_buffer_granted,
            requested = config.socket.recv_buffer_bytes,
            peers = inner.peers.len(),
            "{transport} socket ready"
        );
        Ok(Driver {
            inner: Rc::new(RefCell::new(inner)),
            socket,
            unicast,
            peers_only,
            wake,
        })
    }

    /// Passes every outgoing datagram through `impairment` from now on (`None`: send
    /// directly again; copies already held still leave at their times). See
    /// [`Impairment`] for why outgoing.
    pub fn set_impairment(&self, impairment: Option<Box<dyn Impairment>>) {
        self.inner.borrow_mut().impairment = impairment;
    }

    /// A handle for reading, writing and subscribing from tasks on this thread.
    pub fn handle(&self) -> Handle {
        Handle::new(self.inner.clone())
    }

    /// Runs until `shutdown` completes: receives datagrams, runs timers, sends. On
    /// return, subscriptions end (their `next` gives `None`).
    pub async fn run(self, shutdown: impl Future<Output = ()>) -> Result<(), DriverError> {
        let result = self.run_loop(shutdown).await;
        let mut inner = self.inner.borrow_mut();
        for weak in inner.subscribers.drain() {
            if let Some(sub) = weak.upgrade() {
                sub.borrow_mut().close();
            }
        }
        for slot in inner.sessions.values() {
            slot.notify.notify_one();
        }
        result
    }

    async fn run_loop(&self, shutdown: impl Future<Output = ()>) -> Result<(), DriverError> {
        tokio::pin!(shutdown);
        let clock = self.inner.borrow().clock;
        // The first frame (heartbeat, start values) goes out at once.
        self.inner.borrow_mut().pump();
        let far = || tokio::time::Instant::now() + std::time::Duration::from_secs(3600);
        let sleep = tokio::time::sleep_until(far());
        tokio::pin!(sleep);
        // The sleep was polled (and found pending) at its current deadline: the timer
        // holds this task's waker and wakes it when due, so until then a pass need not
        // poll it again (one idle pass per datagram).
        let mut sleep_armed = false;
        let mut pass: u32 = 0;
        let mut buf = vec![0u8; 65_536];
        loop {
            // One hand-written poll instead of `select!`: nothing is built, registered
            // and dropped again on every pass (the socket keeps one waker per direction,
            // the nudge one waker), which matters at one pass per datagram.
            let cause = std::future::poll_fn(|cx| {
                pass = pass.wrapping_add(1);
                if pass.is_multiple_of(SHUTDOWN_EVERY) && shutdown.as_mut().poll(cx).is_ready() {
                    return Poll::Ready(Ok(Cause::Shutdown));
                }
                if let Poll::Ready(ready) = self.socket.poll_recv_ready(cx) {
                    return Poll::Ready(ready.map(|()| Cause::Readable));
                }
                if let Some(unicast) = &self.unicast {
                    if let Poll::Ready(ready) = unicast.poll_recv_ready(cx) {
                        return Poll::Ready(ready.map(|()| Cause::Readable));
                    }
                }
                // Nothing to read: only now shutdown, the timers and the backlog are
                // looked at.
                if shutdown.as_mut().poll(cx).is_ready() {
                    return Poll::Ready(Ok(Cause::Shutdown));
                }
                // A pass that finds a datagram (most passes, under traffic) skips the
                // walk over peers and inboxes for a deadline that every frame heard
                // moves anyway.
                let (deadline, backlog) = {
                    let inner = self.inner.borrow();
                    // The socket the oldest waiting frame leaves from.
                    let backlog = inner
                        .backlog
                        .front()
                        .map(|(_, to)| inner.socket_for(*to).clone());
                    (inner.next_deadline(), backlog)
                };
                let at = deadline.map(|t| clock.to_tokio(t)).unwrap_or_else(far);
                if sleep.deadline() != at {
                    sleep.as_mut().reset(at);
                    sleep_armed = false;
                }
                if !sleep_armed || sleep.is_elapsed() {
                    if sleep.as_mut().poll(cx).is_ready() {
                        sleep_armed = false;
                        return Poll::Ready(Ok(Cause::Deadline));
                    }
                    sleep_armed = true;
                }
                if let Some(socket) = &backlog {
                    if let Poll::Ready(ready) = socket.poll_send_ready(cx) {
                        return Poll::Ready(ready.map(|()| Cause::Writable));
                    }
                }
                self.wake.poll(cx).map(|()| Ok(Cause::Nudged))
            })
            .await
            .map_err(DriverError::Io)?;
            match cause {
                Cause::Shutdown => return Ok(()),
                Cause::Readable => {
                    for _ in 0..READ_ROUNDS {
                        let handed_before = self.inner.borrow().handed_up;
                        let batch = self.receive_batch(&mut buf)?;
                        if batch.woke {
                            // Watches react (and answer) right here, in this turn.
                            run_reactions(&self.inner);
                            if self.inner.borrow().handed_up != handed_before {
                                // A subscriber or relay session has a notice: let it
                                // run (and answer) before this task reads on, so the
                                // read that finds the socket empty is not on the
                                // critical path of a reply.
                                tokio::task::yield_now().await;
                            }
                        }
                        // A batch that stopped at a datagram with work for others left
                        // the socket readable: read on at once, without a pass through
                        // the wait (its readiness check, the shutdown future).
                        if batch.drained || !batch.woke {
                            break;
                        }
                    }
                }
                Cause::Deadline => {
                    self.inner.borrow_mut().handle_timeout();
                    run_reactions(&self.inner);
                }
                Cause::Writable => self.inner.borrow_mut().flush_backlog(),
                Cause::Nudged => run_reactions(&self.inner),
            }
        }
    }

    /// Reads and handles datagrams until the socket is empty, [`RECV_BATCH`] were read,
    /// or one of them gave a waiting task or a watch something to do; says whether that
    /// happened and whether the sockets are empty.
    ///
    /// With peers, the team's and the unicast socket take turns, so neither starves the
    /// other; unicast from anyone but a configured peer is dropped and counted (with the
    /// unicast transport, on its one socket).
    fn receive_batch(&self, buf: &mut [u8]) -> Result<Batch, DriverError> {
        let mut inner = self.inner.borrow_mut();
        let handed_before = inner.handed_up;
        let sockets = [Some(&self.socket), self.unicast.as_ref()];
        let mut drained = sockets.map(|s| s.is_none());
        let mut turn = 0;
        for _ in 0..RECV_BATCH {
            if drained[turn] {
                turn ^= 1;
            }
            let (Some(socket), false) = (sockets[turn], drained[turn]) else {
                break; // both drained
            };
            let unicast = turn == 1 || self.peers_only;
            let read = socket.try_recv_from(buf);
            if read
                .as_ref()
                .is_err_and(|e| e.kind() == io::ErrorKind::WouldBlock)
            {
                drained[turn] = true;
            }
            turn ^= 1;
            match read {
                Ok((_, from)) if unicast && !inner.peers.contains(&from) => {
                    inner.io.datagrams_received += 1;
                    inner.io.unicast_refused += 1;
                    tracing::debug!(%from, "unicast from an address that is not a --peer dropped");
                }
                Ok((n, from)) => {
                    inner.io.datagrams_received += 1;
                    // Every frame sent comes back: the replica skips its own unread, so
                    // the clock is not read for it (a read per datagram was a sixth of
                    // the clock reads of a round trip).
                    let bytes = &buf[..n];
                    if inner.replica.is_own_frame(bytes) {
                        // Counted and skipped: it moves no clock, changes no value and
                        // gives nothing to send or tell (the pump after the batch runs
                        // anyway).
                        let now = inner.replica.now();
                        inner.replica.handle_datagram(now, from, bytes);
                        continue;
                    }
                    let now = inner.clock.now();
                    inner.replica.handle_datagram(now, from, bytes);
                    inner.pump();
                    if inner.handed_up != handed_before || !inner.reactions.is_empty() {
                        return Ok(Batch {
                            woke: true,
                            drained: false,
                        });
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => continue,
                // An ICMP error from an earlier unicast send to a `--peer` that is down
                // surfaces here on Linux; it is no reason to stop.
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::ConnectionRefused
                            | io::ErrorKind::HostUnreachable
                            | io::ErrorKind::NetworkUnreachable
                    ) =>
                {
                    tracing::debug!(error = %e, "an earlier send was not delivered");
                    continue;
                }
                Err(e) => return Err(DriverError::Io(e)),
            }
        }
        inner.pump();
        Ok(Batch {
            woke: inner.handed_up != handed_before || !inner.reactions.is_empty(),
            drained: drained.iter().all(|&d| d),
        })
    }
}
