//! What runs a node: the `comms::Replica` behind a mutex with the multicast socket, and a
//! receive thread for datagrams and timers.
//!
//! The calls of the C API work on the caller's own thread, as `driver::Handle::set`
//! works on the driver's task: lock, hand the write to the replica, send every frame it
//! outputs, queue its events, unlock. A `set` or `post` has sent its frame when it
//! returns, with no hand-off to another thread on the way (that hand-off, a thread
//! wake-up, cost more than the loopback round trip itself).
//!
//! The receive thread blocks in `recv_from` until a datagram arrives or the replica's
//! next deadline (`poll_timeout`) comes, and feeds either to the replica under the same
//! lock. Stopping sets a flag the thread sees within [`STOP_CHECK`].
//!
//! The team layer (`driver::team::TeamCore`, the code `huddle daemon` runs for its robot)
//! runs under the same lock: every write of a `local.var.robot.*` input is checked by
//! its contract and taken ([`State::set`]); it ticks every control period on the receive
//! thread, and at once on the caller's thread when a pose or odometry write closes the
//! program's cycle (at most twice a period, as the daemon); a teammate's changed claim
//! makes it decide again as the change is drained ([`State::pump`]).
//!
//! Like `driver::Driver` without relay or impairment: the sockets are the driver's
//! (`driver::open` for the transport, multicast, broadcast or unicast, and
//! `driver::open_unicast` for listed peers), every frame goes to the group or broadcast
//! address and to each peer, as the driver sends it; datagrams on a unicast socket are
//! taken from listed peers only. The clock is microseconds since the node started.

use std::collections::VecDeque;
use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use comms::{Event, Instant, Pattern, Replica, Scope, Value};
use driver::team::{Pacer, TeamCore, TeamLayerConfig};
use driver::{new_incarnation, Clock, DriverConfig, Transport};

use crate::error::*;
use crate::event::NodeEvent;

/// Events a node keeps for `huddle_node_next_event` before it drops the oldest (and says
/// so with `HUDDLE_EVENT_LAGGED`).
const EVENT_CAPACITY: usize = 65_536;
/// The longest the receive thread waits before it looks at the stop flag again: how long
/// `huddle_node_stop` may take at most (a blocked `recv_from` cannot be woken portably
/// without sending something the teammates would also receive).
pub(crate) const STOP_CHECK: Duration = Duration::from_millis(20);
/// The longest a send may wait for room in the kernel's send buffer; past it the frame is
/// dropped (the periodic refresh repairs values, NACKs repair talk).
const SEND_TIMEOUT: Duration = Duration::from_millis(50);

/// Events waiting for the caller, and how it waits for them.
#[derive(Default)]
pub(crate) struct EventQueue {
    queue: Mutex<(VecDeque<NodeEvent>, u64)>,
    ready: Condvar,
}

impl EventQueue {
    fn lock(&self) -> MutexGuard<'_, (VecDeque<NodeEvent>, u64)> {
        self.queue.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn push(&self, event: NodeEvent) {
        let mut q = self.lock();
        if q.0.len() >= EVENT_CAPACITY {
            q.0.pop_front();
            q.1 += 1;
        }
        q.0.push_back(event);
        drop(q);
        self.ready.notify_all();
    }

    /// The next event, waiting up to `timeout` for one.
    pub(crate) fn pop(&self, timeout: Duration) -> Option<NodeEvent> {
        let mut q = self.lock();
        if q.0.is_empty() && q.1 == 0 && !timeout.is_zero() {
            q = self
                .ready
                .wait_timeout_while(q, timeout, |q| q.0.is_empty() && q.1 == 0)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
        if q.1 > 0 {
            return Some(NodeEvent::Lagged(std::mem::take(&mut q.1)));
        }
        q.0.pop_front()
    }
}

/// The replica and what it sends through; one lock for both, so frames leave in the
/// order the replica made them.
pub(crate) struct State {
    pub(crate) replica: Replica,
    /// `None` once the node is stopped: calls still in flight then fail.
    sockets: Option<Sockets>,
    /// The group or broadcast address every frame goes to; `None` with unicast.
    destination: Option<SocketAddr>,
    /// Teammates that get every frame by unicast too (or only, with unicast).
    peers: Vec<SocketAddr>,
    events: Arc<EventQueue>,
    /// Patterns whose value changes are queued as events (`huddle_node_watch`).
    pub(crate) watches: Vec<Pattern>,
    /// Datagram counters for `huddle_node_stats`.
    pub(crate) io: Io,
    /// The robot's team layer, unless the config turned it off.
    team: Option<TeamRun>,
    /// Whether the GameController listener runs (`local.var.gc.*` is then its own).
    gc: bool,
    /// Teammates' should-I-go claims (`+.var.machine.heuristic`, as the daemon's layer
    /// watches them).
    claims: Pattern,
    /// The frame buffer `drain` reuses (`poll_transmit_into`): no allocation per frame.
    frame: Vec<u8>,
}

/// The team layer on the node and when it ticks.
struct TeamRun {
    core: TeamCore,
    period: Duration,
    /// The next timer tick; `None` while the layer is dormant (no pose or odometry yet).
    next: Option<Instant>,
    /// Whether a closing cycle ticks (the daemon's rule).
    pacer: Pacer,
}

impl TeamRun {
    fn new(robot: u8, cfg: TeamLayerConfig) -> TeamRun {
        let core = TeamCore::new(robot, cfg);
        let period = core.period();
        TeamRun {
            period,
            core,
            next: None,
            pacer: Pacer::new(period),
        }
    }

    /// The timer's tick.
    fn tick(&mut self, replica: &mut Replica, now: Instant) {
        self.pacer.timer(since_start(now));
        self.core.tick(replica, now);
        self.next = Some(now + self.period);
    }
}

/// The pacer's time: since the node's clock started.
fn since_start(now: Instant) -> Duration {
    now.saturating_duration_since(Instant::ZERO)
}

/// The node's sockets: the transport's, and the `--peer` one when peers are listed and
/// the transport is not unicast (with unicast, `team` is that socket).
struct Sockets {
    team: UdpSocket,
    unicast: Option<UdpSocket>,
}

/// What the node's sockets did.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Io {
    pub(crate) datagrams_sent: u64,
    pub(crate) datagrams_received: u64,
    pub(crate) send_errors: u64,
    /// Datagrams on a unicast socket from an address that is not a listed peer.
    pub(crate) unicast_refused: u64,
}

impl State {
    /// Writes `value` to `key` for the robot program with `write` (a set, or a set on the
    /// priority path). The node's own keys are refused (`HUDDLE_E_KEY`, see
    /// [`State::not_read_only`]). A team-layer input is checked by its contract first
    /// (`HUDDLE_E_VALUE`, nothing written), then taken; a pose or odometry closes the
    /// program's cycle and the layer ticks at once by the daemon's rule
    /// ([`driver::team::Pacer`]: not within half a period of the last cycle's tick, but
    /// at once after a tick of the timer standing in for a late cycle). An input `write` then
    /// refuses was still taken, as at the daemon's guard: that cannot happen, the input
    /// keys being valid `local` keys.
    pub(crate) fn set(
        &mut self,
        now: Instant,
        key: &str,
        value: Value,
        write: impl FnOnce(&mut Replica, Value) -> Result<(), Failure>,
    ) -> Result<(), Failure> {
        self.not_read_only(key)?;
        let closes_cycle = match &mut self.team {
            Some(team) => team
                .core
                .input(key, &value, now)
                .map_err(|e| Failure::new(HUDDLE_E_VALUE, format!("{e}; nothing written")))?,
            None => false,
        };
        write(&mut self.replica, value)?;
        if let Some(team) = self.team.as_mut().filter(|_| closes_cycle) {
            if team.pacer.cycle(since_start(now)) {
                team.core.tick(&mut self.replica, now);
                // While the program drives, the timer only stands in for a missed cycle:
                // it must not tick just before the next cycle closes.
                team.next = Some(now + team.period * 3 / 2);
            }
        }
        Ok(())
    }

    /// Refuses the node's own keys (`HUDDLE_E_KEY`), as the daemon's relay does with
    /// `ERR 423` (`driver::read_only_owner`): the team layer's outputs while it runs, the
    /// GameController listener's keys while it runs, the counters always.
    fn not_read_only(&self, key: &str) -> Result<(), Failure> {
        if !key.starts_with("local.var.") {
            return Ok(());
        }
        let Ok(parsed) = comms::Key::parse(key) else {
            return Ok(()); // the write itself says what is wrong with it
        };
        match driver::read_only_owner(&parsed, self.team.is_some(), self.gc) {
            Some(owner) => Err(Failure::new(
                HUDDLE_E_KEY,
                format!(
                    "{}; nothing written",
                    driver::read_only(&parsed, owner).text
                ),
            )),
            None => Ok(()),
        }
    }

    /// The team layer's timer: its tick if due, and when the next one is.
    fn team_timer(&mut self, now: Instant) -> Option<Instant> {
        let team = self.team.as_mut()?;
        if team.next.is_some_and(|t| t <= now) {
            team.tick(&mut self.replica, now);
        }
        team.next
    }

    /// Drains the replica: frames to the group, events to the queue; a teammate's claim
    /// among the changes makes the team layer decide again, and what that writes is
    /// drained too.
    pub(crate) fn pump(&mut self, now: Instant) {
        let own = Scope::Robot(self.replica.robot_id());
        // The layer's reaction writes only this robot's keys: the second round drains
        // them and ends.
        while self.drain(own) {
            match &mut self.team {
                Some(team) => team.core.react(&mut self.replica, now),
                None => break,
            }
        }
    }

    /// [`State::pump`] once; whether a teammate's claim changed.
    fn drain(&mut self, own: Scope) -> bool {
        let mut claim = false;
        while self.replica.poll_transmit_into(&mut self.frame).is_some() {
            let Some(sockets) = &self.sockets else {
                continue;
            };
            // As the driver sends: to each peer (from the peer socket when there is one),
            // then to the group or broadcast address.
            let peer_socket = sockets.unicast.as_ref().unwrap_or(&sockets.team);
            let targets = self.peers.iter().map(|p| (peer_socket, *p));
            let group = self.destination.map(|d| (&sockets.team, d));
            for (socket, to) in targets.chain(group) {
                // A failed send is a lost datagram, which the protocol repairs.
                match socket.send_to(&self.frame, to) {
                    Ok(_) => self.io.datagrams_sent += 1,
                    Err(_) => self.io.send_errors += 1,
                }
            }
        }
        while let Some(event) = self.replica.poll_event() {
            if let Event::ValueChanged { key } = &event {
                claim |= key.scope() != own && self.claims.matches(key);
                if self.watches.iter().any(|p| p.matches(key)) {
                    if let Ok(Some(entry)) = self.replica.get(&key.to_string()) {
                        self.events.push(NodeEvent::Changed {
                            key: key.to_string(),
                            owner: entry.owner,
                            value: entry.value.clone(),
                        });
                    }
                }
                continue;
            }
            if let Some(event) = node_event(event) {
                self.events.push(event);
            }
        }
        claim
    }

    /// Whether the node still runs (a call racing `huddle_node_stop` may find it not).
    pub(crate) fn running(&self) -> bool {
        self.sockets.is_some()
    }
}

/// What the node reports of a replica event: talk, peers, another robot with this id, and
/// anything unexpected (a variant a later comms adds). Value changes are queued only for
/// watched patterns (`State::pump`); dropped frames are counted in the stats (they would
/// flood the queue).
fn node_event(event: Event) -> Option<NodeEvent> {
    Some(match event {
        Event::TalkDelivered {
            queue,
            from,
            seq,
            value,
        } => NodeEvent::Talk {
            from,
            queue,
            seq,
            value,
        },
        Event::TalkGivenUp {
            queue,
            from,
            first,
            last,
        } => NodeEvent::TalkLost {
            from,
            queue,
            first,
            last,
        },
        Event::PeerJoined { robot, incarnation } => NodeEvent::Joined { robot, incarnation },
        Event::PeerRestarted {
            robot,
            new_incarnation,
            ..
        } => NodeEvent::Restarted {
            robot,
            incarnation: new_incarnation,
        },
        Event::PeerDeparted { robot } => NodeEvent::Departed { robot },
        Event::IncarnationConflict { robot, other, .. } => NodeEvent::IdConflict {
            robot,
            incarnation: other,
        },
        Event::ValueChanged { .. } | Event::FrameDropped { .. } => return None,
        #[allow(unreachable_patterns)] // variants a later comms adds
        other => NodeEvent::Other {
            robot: 0,
            description: format!("{other:?}"),
        },
    })
}

/// Shared by the C-facing side and the receive thread.
pub(crate) struct Shared {
    state: Mutex<State>,
    pub(crate) clock: Clock,
    pub(crate) events: Arc<EventQueue>,
    pub(crate) stopping: AtomicBool,
}

impl Shared {
    pub(crate) fn lock(&self) -> MutexGuard<'_, State> {
        // A panic under the lock (caught at the boundary) leaves the replica usable: it
        // never panics half-way through a change by design, and a poisoned lock must not
        // turn every later call into a panic.
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// A running node's engine: the shared state and the receive thread.
pub(crate) struct Engine {
    pub(crate) shared: Arc<Shared>,
    threads: Mutex<Vec<JoinHandle<()>>>,
}

impl Engine {
    /// Opens the socket, starts the replica with the start values, sends its first frame
    /// and starts the receive thread.
    pub(crate) fn start(
        config: DriverConfig,
        team_layer: Option<TeamLayerConfig>,
    ) -> Result<Engine, Failure> {
        let transport = config.socket.transport;
        let peers_only = transport == Transport::Unicast;
        if peers_only && config.peers.is_empty() {
            return Err(Failure::new(
                HUDDLE_E_CONFIG,
                "the unicast transport sends to each peer only, and none is given",
            ));
        }
        let network = |e: driver::SocketError| Failure::new(HUDDLE_E_NETWORK, e.to_string());
        let opened = driver::open(&config.socket).map_err(network)?;
        let destination = opened.destination.map(SocketAddr::V4);
        let team = blocking(opened.socket, &config)?;
        let unicast = if config.peers.is_empty() || peers_only {
            None
        } else {
            let socket = driver::open_unicast(&config.socket).map_err(network)?;
            Some(blocking(socket, &config)?)
        };
        let clone = |s: &UdpSocket| {
            s.try_clone().map_err(|e| {
                Failure::new(HUDDLE_E_NETWORK, format!("cannot share the socket: {e}"))
            })
        };
        // Each socket gets a receive thread; the peers-only filter where unicast arrives.
        let mut receivers = vec![(clone(&team)?, peers_only)];
        if let Some(unicast) = &unicast {
            receivers.push((clone(unicast)?, true));
        }

        let clock = Clock::new();
        let incarnation = config.incarnation.unwrap_or_else(new_incarnation);
        let mut replica = Replica::new(config.replica, incarnation, clock.now())
            .map_err(|e| Failure::new(HUDDLE_E_CONFIG, format!("invalid configuration: {e}")))?;
        for (key, value) in config.start_values {
            replica
                .set_key(clock.now(), &key, value)
                .map_err(|e| Failure::new(HUDDLE_E_CONFIG, format!("start value {key}: {e}")))?;
        }
        // Start values are this robot's business, not changes anyone waits for.
        while replica.poll_event().is_some() {}
        let robot_id = replica.robot_id();

        let events = Arc::new(EventQueue::default());
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                replica,
                sockets: Some(Sockets { team, unicast }),
                destination,
                peers: config.peers.clone(),
                events: events.clone(),
                watches: Vec::new(),
                io: Io::default(),
                team: team_layer.map(|cfg| TeamRun::new(robot_id, cfg)),
                gc: false,
                claims: Pattern::parse("+.var.machine.heuristic").expect("a valid pattern"),
                frame: Vec::with_capacity(2048),
            }),
            clock,
            events,
            stopping: AtomicBool::new(false),
        });
        // The first frame (heartbeat, start values) goes out at once.
        shared.lock().pump(shared.clock.now());
        let robot = shared.lock().replica.robot_id();
        let engine = Engine {
            shared,
            threads: Mutex::new(Vec::new()),
        };
        for (socket, peers_only) in receivers {
            let for_thread = engine.shared.clone();
            let accept = peers_only.then(|| config.peers.clone());
            let thread = std::thread::Builder::new()
                .name(format!("huddle-node-{robot}"))
                .spawn(move || receive_loop(&for_thread, socket, accept))
                .map_err(|e| {
                    Failure::new(HUDDLE_E_INTERNAL, format!("cannot start a thread: {e}"))
                });
            match thread {
                Ok(thread) => engine.threads().push(thread),
                Err(e) => {
                    engine.stop();
                    return Err(e);
                }
            }
        }
        Ok(engine)
    }

    /// Starts the GameController listener on a thread of its own (`crate::gc`); it stops
    /// with the node.
    pub(crate) fn start_gc(&self, config: driver::GameControllerConfig) -> Result<(), Failure> {
        let (listen, status) = crate::gc::open(&config)?;
        if let Some(status) = &status {
            status.set_write_timeout(Some(SEND_TIMEOUT)).map_err(|e| {
                Failure::new(
                    HUDDLE_E_NETWORK,
                    format!("GameController status socket: {e}"),
                )
            })?;
        }
        let shared = self.shared.clone();
        // From now on `local.var.gc.*` is the listener's, as at the daemon's relay.
        shared.lock().gc = true;
        let listener = driver::GcListener::new(config);
        let thread = std::thread::Builder::new()
            .name("huddle-node-gc".into())
            .spawn(move || crate::gc::run(&shared, listen, status, listener))
            .map_err(|e| Failure::new(HUDDLE_E_INTERNAL, format!("cannot start a thread: {e}")))?;
        self.threads().push(thread);
        Ok(())
    }

    fn threads(&self) -> MutexGuard<'_, Vec<JoinHandle<()>>> {
        self.threads.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Runs `f` on the replica under the node's lock, on the caller's thread; then sends
    /// what it output and queues its events. Fails once the node is stopped.
    pub(crate) fn with_state<R>(
        &self,
        f: impl FnOnce(&mut State, Instant) -> R,
    ) -> Result<R, Failure> {
        let mut state = self.shared.lock();
        if !state.running() {
            return Err(Failure::stopped("node"));
        }
        let now = self.shared.clock.now();
        let result = f(&mut state, now);
        state.pump(now);
        Ok(result)
    }

    /// Ends the receive thread, waits for it and closes the socket; a second call does
    /// nothing. Calls in flight on other threads finish before it or fail after it.
    pub(crate) fn stop(&self) {
        let running = std::mem::take(&mut *self.threads());
        self.shared.stopping.store(true, Ordering::Relaxed);
        self.shared.lock().sockets = None;
        for thread in running {
            // A panic on the receive thread was already reported there; nothing to add.
            let _ = thread.join();
        }
    }
}

/// `socket` made blocking with the node's timeouts.
fn blocking(socket: UdpSocket, config: &DriverConfig) -> Result<UdpSocket, Failure> {
    let network = |e: io::Error| {
        Failure::new(
            HUDDLE_E_NETWORK,
            format!(
                "cannot set up the {} socket on port {}: {e}",
                config.socket.transport,
                config.socket.group.port()
            ),
        )
    };
    socket.set_nonblocking(false).map_err(network)?;
    socket
        .set_write_timeout(Some(SEND_TIMEOUT))
        .map_err(network)?;
    socket.set_read_timeout(Some(STOP_CHECK)).map_err(network)?;
    Ok(socket)
}

/// The receive thread: datagrams and deadlines into the replica until the node stops.
/// One lock per wake-up: the datagram, a deadline that came, the frames and events they
/// caused, and the time to the next deadline.
/// `accept`: the only senders taken (a unicast socket's listed peers); `None`: any.
fn receive_loop(shared: &Shared, socket: UdpSocket, accept: Option<Vec<SocketAddr>>) {
    let mut buf = vec![0u8; 65_536];
    let mut received = None;
    let mut timeout = STOP_CHECK;
    while !shared.stopping.load(Ordering::Relaxed) {
        let wait = {
            let mut state = shared.lock();
            let now = shared.clock.now();
            if let Some((n, from)) = received.take() {
                if accept.as_ref().is_none_or(|peers| peers.contains(&from)) {
                    state.io.datagrams_received += 1;
                    state.replica.handle_datagram(now, from, &buf[..n]);
                } else {
                    state.io.unicast_refused += 1;
                }
            }
            if state.replica.poll_timeout().is_some_and(|t| t <= now) {
                state.replica.handle_timeout(now);
            }
            let team_tick = state.team_timer(now);
            state.pump(now);
            state
                .replica
                .poll_timeout()
                .into_iter()
                .chain(team_tick)
                .min()
                .map_or(STOP_CHECK, |t| t.saturating_duration_since(now))
        };
        // Whole milliseconds, rounded up (as tokio's timers, which the driver uses): the
        // timeout changes, and costs a system call, only when the deadline comes near.
        // Never zero, which would mean "forever" to the OS.
        let wait = Duration::from_millis(wait.as_micros().div_ceil(1000) as u64)
            .clamp(Duration::from_millis(1), STOP_CHECK);
        if wait != timeout && socket.set_read_timeout(Some(wait)).is_ok() {
            timeout = wait;
        }
        match socket.recv_from(&mut buf) {
            Ok(got) => received = Some(got),
            Err(e) if is_transient(&e) => {}
            Err(e) => {
                if !shared.stopping.load(Ordering::Relaxed) {
                    // The C caller has no log: stderr is all there is.
                    eprintln!("huddle node: receiving stopped: {e}");
                }
                return;
            }
        }
    }
}

/// An error `recv_from` may give that is no reason to stop: the wait timed out, a
/// signal interrupted it, an ICMP error of an earlier send surfaced.
pub(crate) fn is_transient(e: &io::Error) -> bool {
    matches!(
        e.kind(),
        io::ErrorKind::WouldBlock
            | io::ErrorKind::TimedOut
            | io::ErrorKind::Interrupted
            | io::ErrorKind::ConnectionRefused
    )
}
