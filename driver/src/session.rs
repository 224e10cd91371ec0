//! [`Session`]: the replica behind a mutex, for programs with a multi-threaded runtime.
//!
//! The same idea as the C node's engine (ffi/src/engine.rs), on tokio: a call works on
//! the caller's own thread (lock, hand the write to the replica, send every frame it
//! outputs with a non-blocking send, queue its notices, unlock), so a `set` has sent its
//! frame when it returns with no hand-off to another thread; one spawned task receives
//! datagrams, runs the replica's deadlines and sends what the kernel could not take at
//! once. The handle is `Send + Sync + Clone`; notices reach tasks as [`Stream`]s.
//!
//! What it leaves to [`crate::Driver`]: the relay server, write guards, impairment and
//! the in-turn [`crate::Handle::watch`], all of which live on the driver's one thread.

use std::collections::VecDeque;
use std::io;
use std::net::SocketAddr;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, Weak};
use std::task::{Context, Poll, Waker};
use std::time::Duration;

use futures_core::Stream;
use tokio::net::UdpSocket;
use tokio::sync::Notify;

use comms::{
    Entry, Event, Instant, Key, KeyError, Kind, Pattern, PatternError, PostError, Replica, Scope,
    SetError, Value,
};

use crate::handle::DriverStats;
use crate::notice::Notice;
use crate::run::{open_sockets, start_replica, DriverConfig, DriverError, Sockets};
use crate::state::{Clock, IoStats};

/// Frames kept while the kernel's send buffer is full; beyond this they are dropped and
/// counted, as the driver does (the refresh repairs values, NACKs repair talk).
const SEND_BACKLOG_FRAMES: usize = 1024;

/// A teammate came, came back with a new incarnation, fell silent, or shares our id.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PeerEvent {
    /// A robot was heard for the first time.
    Joined {
        /// Its id.
        robot: u8,
        /// Its incarnation (random per start).
        incarnation: u64,
    },
    /// A robot restarted: a new incarnation under a known id.
    Restarted {
        /// Its id.
        robot: u8,
        /// Its new incarnation.
        incarnation: u64,
    },
    /// A robot was silent longer than the replica's `departed_after`.
    Departed {
        /// Its id.
        robot: u8,
    },
    /// Another robot sends with this robot's id (or two robots share an id).
    IdConflict {
        /// The id.
        robot: u8,
        /// The other sender's incarnation.
        incarnation: u64,
    },
    /// The reader fell behind: this many older peer events were dropped.
    Lagged(u64),
}

/// A bounded queue between the session and one stream; the oldest items go first when
/// it is full, and the stream then says how many with its lag item.
struct Feed<T> {
    queue: VecDeque<T>,
    capacity: usize,
    lagged: u64,
    waker: Option<Waker>,
    closed: bool,
}

impl<T> Feed<T> {
    fn new(capacity: usize) -> Arc<Mutex<Feed<T>>> {
        Arc::new(Mutex::new(Feed {
            queue: VecDeque::new(),
            capacity,
            lagged: 0,
            waker: None,
            closed: false,
        }))
    }

    fn push(&mut self, item: T) {
        if self.queue.len() >= self.capacity {
            self.queue.pop_front();
            self.lagged += 1;
        }
        self.queue.push_back(item);
        if let Some(w) = self.waker.take() {
            w.wake();
        }
    }

    fn close(&mut self) {
        self.closed = true;
        if let Some(w) = self.waker.take() {
            w.wake();
        }
    }

    fn poll(&mut self, cx: &mut Context<'_>, lag: impl FnOnce(u64) -> T) -> Poll<Option<T>> {
        if self.lagged > 0 {
            return Poll::Ready(Some(lag(std::mem::take(&mut self.lagged))));
        }
        if let Some(item) = self.queue.pop_front() {
            return Poll::Ready(Some(item));
        }
        if self.closed {
            return Poll::Ready(None);
        }
        self.waker = Some(cx.waker().clone());
        Poll::Pending
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // Nothing under these locks panics half-way through a change; a poisoned lock must
    // not turn every later call into a panic.
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Changes and talk matching a pattern, as a [`Stream`] of [`Notice`]s; see
/// [`Session::subscribe`]. It ends when the session closes.
pub struct Updates {
    feed: Arc<Mutex<Feed<Notice>>>,
}

impl Stream for Updates {
    type Item = Notice;

    fn poll_next(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<Notice>> {
        lock(&self.feed).poll(cx, Notice::Lagged)
    }
}

/// Teammates joining, restarting and leaving, as a [`Stream`]; see
/// [`Session::peer_events`]. It ends when the session closes.
pub struct PeerEvents {
    feed: Arc<Mutex<Feed<PeerEvent>>>,
}

impl Stream for PeerEvents {
    type Item = PeerEvent;

    fn poll_next(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Option<PeerEvent>> {
        lock(&self.feed).poll(cx, PeerEvent::Lagged)
    }
}

/// The replica and what it sends through; one lock for both, so frames leave in the
/// order the replica made them.
struct State {
    replica: Replica,
    team: Arc<UdpSocket>,
    /// The `--peer` socket, when peers are listed and the transport is not unicast.
    unicast: Option<Arc<UdpSocket>>,
    /// The group or broadcast address every frame goes to; `None` with unicast.
    destination: Option<SocketAddr>,
    peers: Vec<SocketAddr>,
    /// The frame buffer `pump` reuses (`poll_transmit_into`): no allocation per frame.
    frame: Vec<u8>,
    backlog: VecDeque<(Vec<u8>, SocketAddr)>,
    updates: Vec<(Pattern, Weak<Mutex<Feed<Notice>>>)>,
    peer_events: Vec<Weak<Mutex<Feed<PeerEvent>>>>,
    feed_capacity: usize,
    io: IoStats,
    /// The counts [`IoStats::mirror`] last wrote to `local.var.huddle.stats.*`.
    io_mirrored: Option<[u64; 10]>,
    /// The deadline the receive task sleeps until: a call that makes an earlier one (or
    /// fills the backlog) wakes it.
    sleeping_until: Option<Instant>,
    closed: bool,
}

impl State {
    /// Drains the replica: frames to the sockets, events to the streams. Returns whether
    /// the receive task must look again (an earlier deadline, a backlog to flush).
    fn pump(&mut self) -> bool {
        // The kept buffer is taken out while `send` borrows `self`, then put back.
        let mut frame = std::mem::take(&mut self.frame);
        while self.replica.poll_transmit_into(&mut frame).is_some() {
            for i in 0..self.peers.len() {
                let peer = self.peers[i];
                self.send(&frame, peer);
            }
            if let Some(destination) = self.destination {
                self.send(&frame, destination);
            }
        }
        self.frame = frame;
        while let Some(event) = self.replica.poll_event() {
            self.dispatch(event);
        }
        let deadline = self.replica.poll_timeout();
        let earlier = match (deadline, self.sleeping_until) {
            (Some(new), Some(old)) => new < old,
            (new, old) => new.is_some() && old.is_none(),
        };
        earlier || !self.backlog.is_empty()
    }

    fn socket_for(&self, to: SocketAddr) -> &Arc<UdpSocket> {
        match &self.unicast {
            Some(unicast) if Some(to) != self.destination => unicast,
            _ => &self.team,
        }
    }

    fn send(&mut self, payload: &[u8], to: SocketAddr) {
        if self.closed {
            return;
        }
        if self.backlog.is_empty() {
            match self.socket_for(to).try_send_to(payload, to) {
                Ok(_) => return self.io.datagrams_sent += 1,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => {}
                Err(e) => {
                    tracing::debug!(%to, error = %e, "send failed");
                    return self.io.send_errors += 1;
                }
            }
        }
        if self.backlog.len() >= SEND_BACKLOG_FRAMES {
            self.io.send_backlog_drops += 1;
        } else {
            self.backlog.push_back((payload.to_vec(), to));
        }
    }

    /// Mirrors the I/O counters (a full backlog's drops among them) into
    /// `local.var.huddle.stats.*`, as the driver does.
    fn mirror_io(&mut self, now: Instant) {
        let State {
            io,
            io_mirrored,
            replica,
            ..
        } = self;
        io.mirror(io_mirrored, replica, now);
    }

    /// Sends what the backlog holds until the kernel refuses again.
    fn flush_backlog(&mut self) {
        while let Some((payload, to)) = self.backlog.front() {
            let to = *to;
            match self.socket_for(to).try_send_to(payload, to) {
                Ok(_) => self.io.datagrams_sent += 1,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => return,
                Err(_) => self.io.send_errors += 1,
            }
            self.backlog.pop_front();
        }
    }

    fn deliver(&mut self, matches: impl Fn(&Pattern) -> bool, notice: impl Fn() -> Notice) {
        self.updates.retain(|(pattern, feed)| {
            let Some(feed) = feed.upgrade() else {
                return false; // the stream was dropped
            };
            if matches(pattern) {
                lock(&feed).push(notice());
            }
            true
        });
    }

    fn peer_event(&mut self, event: PeerEvent) {
        self.peer_events.retain(|feed| match feed.upgrade() {
            Some(feed) => {
                lock(&feed).push(event.clone());
                true
            }
            None => false,
        });
    }

    fn dispatch(&mut self, event: Event) {
        match event {
            Event::ValueChanged { key } => {
                let matches = |p: &Pattern| p.matches(&key);
                // Most changes (this robot's own writes among them) have no listener.
                if !self.updates.iter().any(|(p, _)| matches(p)) {
                    return;
                }
                if let Some(entry) = self.replica.blackboard().get(&key).cloned() {
                    let notice = || Notice::Changed {
                        key: key.clone(),
                        entry: entry.clone(),
                    };
                    self.deliver(matches, notice);
                }
            }
            Event::TalkDelivered {
                queue,
                from,
                seq,
                value,
            } => {
                let matches = |p: &Pattern| p.matches_parts(Scope::Robot(from), Kind::Talk, &queue);
                let notice = || Notice::Talk {
                    from,
                    queue: queue.clone(),
                    seq,
                    value: value.clone(),
                };
                self.deliver(matches, notice);
            }
            Event::TalkGivenUp {
                queue,
                from,
                first,
                last,
            } => {
                let matches = |p: &Pattern| p.matches_parts(Scope::Robot(from), Kind::Talk, &queue);
                let notice = || Notice::TalkLost {
                    from,
                    queue: queue.clone(),
                    first,
                    last,
                };
                self.deliver(matches, notice);
            }
            Event::PeerJoined { robot, incarnation } => {
                self.peer_event(PeerEvent::Joined { robot, incarnation })
            }
            Event::PeerRestarted {
                robot,
                new_incarnation,
                ..
            } => self.peer_event(PeerEvent::Restarted {
                robot,
                incarnation: new_incarnation,
            }),
            Event::PeerDeparted { robot } => self.peer_event(PeerEvent::Departed { robot }),
            Event::IncarnationConflict { robot, other, .. } => {
                self.peer_event(PeerEvent::IdConflict {
                    robot,
                    incarnation: other,
                })
            }
            // Counted in the replica's stats; a stream of them would flood.
            Event::FrameDropped { .. } => {}
        }
    }

    fn close(&mut self) {
        self.closed = true;
        for (_, feed) in self.updates.drain(..) {
            if let Some(feed) = feed.upgrade() {
                lock(&feed).close();
            }
        }
        for feed in self.peer_events.drain(..) {
            if let Some(feed) = feed.upgrade() {
                lock(&feed).close();
            }
        }
    }
}

/// What the handles and the receive task share.
struct Shared {
    state: Mutex<State>,
    clock: Clock,
    /// Wakes the receive task: an earlier deadline, a backlog, closing.
    wake: Notify,
    closing: AtomicBool,
}

/// Closes the session when the last [`Session`] clone is dropped (the receive task holds
/// the shared state, not this).
struct Owner(Arc<Shared>);

impl Drop for Owner {
    fn drop(&mut self) {
        close(&self.0);
    }
}

fn close(shared: &Shared) {
    shared.closing.store(true, Ordering::Release);
    lock(&shared.state).close();
    shared.wake.notify_one();
}

/// One robot's replica on the team's network, for any task on any thread: `Send`,
/// `Sync` and cheap to clone (an `Arc`). Every call is synchronous: a `set` or `post`
/// has sent its frame when it returns. The session closes when the last clone is dropped
/// or [`Session::close`] is called; its streams then end.
///
/// For the lowest latency (an answer sent in the very turn that received the question)
/// and for the relay server, run a [`crate::Driver`] on one thread instead.
#[derive(Clone)]
pub struct Session {
    shared: Arc<Shared>,
    _owner: Arc<Owner>,
}

impl Session {
    /// Opens the transport's socket(s), starts the replica with the start values, sends
    /// its first frame and spawns its receive task on the current tokio runtime (any
    /// flavour).
    pub async fn open(config: DriverConfig) -> Result<Session, DriverError> {
        let Sockets {
            team,
            unicast,
            destination,
            peers_only,
            recv_buffer_granted,
        } = open_sockets(&config)?;
        let team = Arc::new(team);
        let unicast = unicast.map(Arc::new);
        let clock = Clock::skewed(config.clock_skew);
        let replica = start_replica(
            config.replica,
            config.incarnation,
            config.start_values,
            &clock,
        )?;
        let mut state = State {
            replica,
            team: team.clone(),
            unicast: unicast.clone(),
            destination,
            peers: config.peers,
            frame: Vec::with_capacity(2048),
            backlog: VecDeque::new(),
            updates: Vec::new(),
            peer_events: Vec::new(),
            feed_capacity: config.subscriber_backlog.max(1),
            io: IoStats {
                recv_buffer_bytes: recv_buffer_granted,
                ..IoStats::default()
            },
            io_mirrored: None,
            sleeping_until: None,
            closed: false,
        };
        // The first frame (heartbeat, start values) goes out at once.
        state.pump();
        let shared = Arc::new(Shared {
            state: Mutex::new(state),
            clock,
            wake: Notify::new(),
            closing: AtomicBool::new(false),
        });
        tokio::spawn(receive(shared.clone(), team, unicast, peers_only));
        Ok(Session {
            _owner: Arc::new(Owner(shared.clone())),
            shared,
        })
    }

    /// Runs `f` on the state at the session's clock, then sends what it queued and wakes
    /// the receive task if its deadline moved earlier.
    fn with<R>(&self, f: impl FnOnce(&mut State, Instant) -> R) -> R {
        let (result, wake) = {
            let mut state = lock(&self.shared.state);
            let now = self.shared.clock.now();
            let result = f(&mut state, now);
            (result, state.pump())
        };
        if wake {
            self.shared.wake.notify_one();
        }
        result
    }

    /// This robot's id.
    pub fn robot_id(&self) -> u8 {
        lock(&self.shared.state).replica.robot_id()
    }

    /// The session's clock: the timeline of every entry's `stamp`.
    pub fn now(&self) -> Instant {
        self.shared.clock.now()
    }

    /// Sets `local.var.x`, `*.var.x` or `<own id>.var.x`; a global value is published
    /// before this returns.
    pub fn set(&self, key: &str, value: impl Into<Value>) -> Result<(), SetError> {
        let value = value.into();
        self.with(|state, now| state.replica.set(now, key, value))
    }

    /// Posts a message to this robot's `*.talk.<queue>`; returns its sequence number.
    pub fn post(&self, key: &str, value: impl Into<Value>) -> Result<u64, PostError> {
        let value = value.into();
        self.with(|state, now| state.replica.post(now, key, value))
    }

    /// The binding for `key` (`*.var.x`: the newest copy), cloned.
    pub fn get(&self, key: &str) -> Result<Option<Entry>, KeyError> {
        Ok(lock(&self.shared.state).replica.get(key)?.cloned())
    }

    /// The value of `key` as a `T` (`f64`, `i64`, `bool`, `String`, `Vec<f64>`, ...):
    /// `None` when it is unbound or of another type.
    pub fn get_as<T>(&self, key: &str) -> Result<Option<T>, KeyError>
    where
        T: for<'v> TryFrom<&'v Value>,
    {
        let state = lock(&self.shared.state);
        let entry = state.replica.get(key)?;
        Ok(entry.and_then(|e| T::try_from(&e.value).ok()))
    }

    /// [`Session::get`], only if at most `max_age` old.
    pub fn get_fresher(&self, key: &str, max_age: Duration) -> Result<Option<Entry>, KeyError> {
        let state = lock(&self.shared.state);
        let now = self.shared.clock.now();
        Ok(state.replica.get_fresher(now, key, max_age)?.cloned())
    }

    /// Every binding matching `pattern` now, in key order.
    pub fn snapshot(&self, pattern: &str) -> Result<Vec<(Key, Entry)>, PatternError> {
        let pattern = Pattern::parse(pattern)?;
        let state = lock(&self.shared.state);
        Ok(state
            .replica
            .iter(&pattern)
            .map(|(k, e)| (k, e.clone()))
            .collect())
    }

    /// A [`Stream`] of every change of a binding and every talk message matching
    /// `pattern` (`+.var.ball.#`, `+.talk.plan`), from now on. A reader that falls more
    /// than the configured backlog behind gets [`Notice::Lagged`].
    pub fn subscribe(&self, pattern: &str) -> Result<Updates, PatternError> {
        let pattern = Pattern::parse(pattern)?;
        let mut state = lock(&self.shared.state);
        let feed = Feed::new(state.feed_capacity);
        if state.closed {
            lock(&feed).close();
        }
        state.updates.push((pattern, Arc::downgrade(&feed)));
        Ok(Updates { feed })
    }

    /// A [`Stream`] of teammates joining, restarting and departing, from now on
    /// (teammates already heard are in [`Session::stats`]).
    pub fn peer_events(&self) -> PeerEvents {
        let mut state = lock(&self.shared.state);
        let feed = Feed::new(state.feed_capacity);
        if state.closed {
            lock(&feed).close();
        }
        state.peer_events.push(Arc::downgrade(&feed));
        PeerEvents { feed }
    }

    /// Runs `f` on the replica itself at the session's clock, then sends what it queued
    /// (priority writes, the budget, the game clock). `f` must be short: every other
    /// call waits for it.
    pub fn with_replica<R>(&self, f: impl FnOnce(&mut Replica, Instant) -> R) -> R {
        self.with(|state, now| f(&mut state.replica, now))
    }

    /// The counters and peers.
    pub fn stats(&self) -> DriverStats {
        let state = lock(&self.shared.state);
        DriverStats {
            replica: state.replica.stats().clone(),
            io: state.io,
            peers: state.replica.peers().collect(),
            now: self.shared.clock.now(),
        }
    }

    /// Stops the receive task and closes the sockets for every clone; the streams end.
    /// Later writes change the replica but send nothing.
    pub fn close(&self) {
        close(&self.shared);
    }

    /// Fills the send backlog (8-byte frames to the group), as a send buffer full for
    /// long would have, then sets `key`: its frame meets the limit. The backlog drops
    /// counted so far.
    #[cfg(test)]
    pub(crate) fn fill_backlog_and_set_for_test(&self, key: &str, value: i64) -> u64 {
        self.with(|state, now| {
            let to = state.destination.expect("a group");
            while state.backlog.len() < SEND_BACKLOG_FRAMES {
                state.backlog.push_back((vec![0u8; 8], to));
            }
            state
                .replica
                .set(now, key, Value::Int(value))
                .expect("an own key");
        });
        lock(&self.shared.state).io.send_backlog_drops
    }
}

/// The receive task: datagrams, deadlines and the send backlog until the session closes.
async fn receive(
    shared: Arc<Shared>,
    team: Arc<UdpSocket>,
    unicast: Option<Arc<UdpSocket>>,
    peers_only: bool,
) {
    let mut buf = vec![0u8; 65_536];
    let mut spare = vec![0u8; 65_536];
    let far = Duration::from_secs(3600);
    loop {
        if shared.closing.load(Ordering::Acquire) {
            return;
        }
        let (deadline, backlog) = {
            let mut state = lock(&shared.state);
            state.sleeping_until = state.replica.poll_timeout();
            let backlog = state
                .backlog
                .front()
                .map(|(_, to)| state.socket_for(*to).clone());
            (state.sleeping_until, backlog)
        };
        let sleep = match deadline {
            Some(t) => t.saturating_duration_since(shared.clock.now()),
            None => far,
        };
        let writable = async {
            match &backlog {
                Some(socket) => socket.writable().await,
                None => std::future::pending().await,
            }
        };
        let from_peer = async {
            match &unicast {
                Some(socket) => socket.recv_from(&mut spare).await,
                None => std::future::pending().await,
            }
        };
        tokio::select! {
            biased;
            () = shared.wake.notified() => {}
            got = team.recv_from(&mut buf) => {
                if !input(&shared, got, &buf, peers_only) {
                    return;
                }
            }
            got = from_peer => {
                if !input(&shared, got, &spare, true) {
                    return;
                }
            }
            Ok(()) = writable => lock(&shared.state).flush_backlog(),
            () = tokio::time::sleep(sleep) => {
                let mut state = lock(&shared.state);
                let now = shared.clock.now();
                state.replica.handle_timeout(now);
                state.mirror_io(now);
                state.pump();
            }
        }
    }
}

/// One datagram (or receive error) into the replica; `false`: the socket failed for good.
fn input(
    shared: &Shared,
    got: io::Result<(usize, SocketAddr)>,
    buf: &[u8],
    peers_only: bool,
) -> bool {
    let mut state = lock(&shared.state);
    match got {
        Ok((_, from)) if peers_only && !state.peers.contains(&from) => {
            state.io.datagrams_received += 1;
            state.io.unicast_refused += 1;
        }
        Ok((n, from)) => {
            state.io.datagrams_received += 1;
            let now = shared.clock.now();
            state.replica.handle_datagram(now, from, &buf[..n]);
            state.pump();
        }
        // An ICMP error of an earlier unicast send to a peer that is down: no reason
        // to stop.
        Err(e)
            if matches!(
                e.kind(),
                io::ErrorKind::ConnectionRefused
                    | io::ErrorKind::HostUnreachable
                    | io::ErrorKind::NetworkUnreachable
                    | io::ErrorKind::Interrupted
            ) =>
        {
            tracing::debug!(error = %e, "an earlier send was not delivered");
        }
        Err(e) => {
            tracing::warn!(error = %e, "receiving stopped");
            state.close();
            return false;
        }
    }
    true
}
