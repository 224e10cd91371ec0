//! The state a driver shares with its handles and relay connections on its one thread:
//! the replica, the sockets it sends on, the send backlog, relay sessions, subscribers,
//! watches and their queued reactions. Every method runs synchronously inside a turn of
//! the driver task or of a handle call; the task itself is in `driver.rs`.

use std::cell::{Cell, RefCell};
use std::cmp::Reverse;
use std::collections::{BTreeMap, BinaryHeap, VecDeque};
use std::io;
use std::net::SocketAddr;
use std::rc::{Rc, Weak};
use std::task::{Context, Poll, Waker};

use tokio::net::UdpSocket;
use tokio::sync::Notify;

use comms::relay::{Session, SessionLimits};
use comms::{DropReason, Event, Instant, Kind, PatternIndex, Replica, Scope, Value};

use crate::guard::{GuardSlot, GuardedBoard, ReadOnlySlot};
use crate::impair::{Held, Impairment};
use crate::notice::{Notice, SubQueue};
use crate::rate_limit::RateLimit;

/// Frames kept while the kernel's send buffer is full; beyond this they are dropped
/// (and counted): the periodic refresh repairs values, NACKs repair talk.
const SEND_BACKLOG_FRAMES: usize = 1024;
/// Copies an [`Impairment`] may hold back at once; beyond this they are dropped (and
/// counted), so a model with huge delays cannot exhaust memory.
const HELD_LIMIT: usize = 65_536;
/// At most one warning per this period about frames dropped for a team-key mismatch.
pub(crate) const KEY_WARNING_PERIOD: std::time::Duration = std::time::Duration::from_secs(10);
/// At most one warning per this period about sends the OS refused.
pub(crate) const SEND_WARNING_PERIOD: std::time::Duration = std::time::Duration::from_secs(10);

/// The monotonic clock an I/O shell hands to the replica: microseconds since it started,
/// read through a [`ClockSkew`] when one is asked for (none by default).
#[derive(Clone, Copy, Debug)]
pub struct Clock {
    origin: std::time::Instant,
    skew: ClockSkew,
}

impl Default for Clock {
    fn default() -> Clock {
        Clock::new()
    }
}

impl Clock {
    /// A clock starting at zero now.
    // The I/O shell is the one place that reads the clock: it hands `now` to the sans-IO
    // replica.
    #[allow(clippy::disallowed_methods)]
    pub fn new() -> Clock {
        Clock::skewed(ClockSkew::NONE)
    }

    /// A clock that reads `skew`'s offset now and gains its drift from then on.
    #[allow(clippy::disallowed_methods)]
    pub fn skewed(skew: ClockSkew) -> Clock {
        Clock {
            origin: std::time::Instant::now(),
            skew,
        }
    }

    /// Microseconds since [`Clock::new`] (plus the skew), as the replica's time.
    #[must_use]
    pub fn now(&self) -> Instant {
        let us = u64::try_from(self.origin.elapsed().as_micros()).unwrap_or(u64::MAX);
        Instant::from_micros(self.local_us(us))
    }

    /// What the clock reads `real_us` after its start.
    fn local_us(&self, real_us: u64) -> u64 {
        let ClockSkew {
            offset_us,
            drift_ppb,
        } = self.skew;
        if drift_ppb == 0 {
            return real_us.saturating_add(offset_us);
        }
        let real = i128::from(real_us);
        let gained = (real * i128::from(drift_ppb)).div_euclid(NS_PER_S);
        let local = i128::from(offset_us) + real + gained;
        u64::try_from(local.max(0)).unwrap_or(u64::MAX)
    }

    /// The real time after its start at which the clock reads `local_us`, rounded up (a
    /// timer set there finds its deadline due), 0 for a reading before the start.
    fn real_us(&self, local_us: u64) -> u64 {
        let since = local_us.saturating_sub(self.skew.offset_us);
        if self.skew.drift_ppb == 0 {
            return since;
        }
        let rate = NS_PER_S + i128::from(self.skew.drift_ppb);
        let real = (i128::from(since) * NS_PER_S + rate - 1) / rate;
        u64::try_from(real.max(0)).unwrap_or(u64::MAX)
    }

    pub(crate) fn to_tokio(self, t: Instant) -> tokio::time::Instant {
        let at = self.origin + std::time::Duration::from_micros(self.real_us(t.as_micros()));
        tokio::time::Instant::from_std(at)
    }
}

const NS_PER_S: i128 = 1_000_000_000;

/// A deliberate error of a driver's clock, as netsim gives each simulated robot: the
/// clock reads `offset` at the driver's start and gains `drift_ppm` microseconds per
/// second (loses, if negative). For rehearsing on one machine a team whose clocks
/// disagree, as real robots' do: `huddle daemon --clock-offset --clock-drift-ppm`, which
/// `huddle sim --daemons` gives each daemon from its robot's drawn clock. The replica,
/// the team layer and every age a relay client reads are on this clock; teammates
/// estimate it from echoes as they would a real robot's. A robot on the field runs with
/// none.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ClockSkew {
    offset_us: u64,
    drift_ppb: i64,
}

/// Why a [`ClockSkew`] cannot be used.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum ClockSkewError {
    /// The drift is not a number within ±[`ClockSkew::MAX_DRIFT_PPM`].
    #[error(
        "clock drift {drift_ppm} ppm is not a number within ±{} ppm",
        ClockSkew::MAX_DRIFT_PPM
    )]
    Drift {
        /// The drift asked for.
        drift_ppm: f64,
    },
    /// The offset is beyond [`ClockSkew::MAX_OFFSET`].
    #[error("clock offset {offset:?} is beyond {:?}", ClockSkew::MAX_OFFSET)]
    Offset {
        /// The offset asked for.
        offset: std::time::Duration,
    },
}

impl ClockSkew {
    /// No skew: the machine's clock.
    pub const NONE: ClockSkew = ClockSkew {
        offset_us: 0,
        drift_ppb: 0,
    };
    /// The largest drift taken (netsim's limit: 10%).
    pub const MAX_DRIFT_PPM: f64 = 100_000.0;
    /// The largest offset taken (a day).
    pub const MAX_OFFSET: std::time::Duration = std::time::Duration::from_secs(86_400);

    /// A clock reading `offset` at start and gaining `drift_ppm` µs per second.
    pub fn new(offset: std::time::Duration, drift_ppm: f64) -> Result<ClockSkew, ClockSkewError> {
        if !drift_ppm.is_finite() || drift_ppm.abs() > Self::MAX_DRIFT_PPM {
            return Err(ClockSkewError::Drift { drift_ppm });
        }
        if offset > Self::MAX_OFFSET {
            return Err(ClockSkewError::Offset { offset });
        }
        Ok(ClockSkew {
            offset_us: u64::try_from(offset.as_micros()).unwrap_or(u64::MAX),
            drift_ppb: (drift_ppm * 1000.0).round() as i64,
        })
    }

    /// The clock's reading at start.
    pub fn offset(&self) -> std::time::Duration {
        std::time::Duration::from_micros(self.offset_us)
    }

    /// Its drift, ppm.
    pub fn drift_ppm(&self) -> f64 {
        self.drift_ppb as f64 / 1000.0
    }
}

/// A relay session and how to wake its connection.
pub(crate) struct SessionSlot {
    pub(crate) session: Session,
    pub(crate) notify: Rc<Notify>,
}

/// Counters of the I/O layer itself (the replica counts the protocol).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct IoStats {
    /// `SO_RCVBUF` granted by the kernel.
    pub recv_buffer_bytes: usize,
    /// Datagrams sent (to the group or broadcast address, and to peers).
    pub datagrams_sent: u64,
    /// Datagrams received (on the team's socket and, with peers, the unicast socket).
    pub datagrams_received: u64,
    /// Unicast datagrams refused because they did not come from a configured peer. The
    /// check is on the source address, which anyone on the network can forge: it keeps
    /// strays out, it is not authentication (a team key is). Mirrored to
    /// `local.var.huddle.stats.unicast_refused` (`huddle stats`).
    pub unicast_refused: u64,
    /// `LOST` lines not sent to relay clients over their rate limit
    /// ([`comms::relay::LOST_LINES_PER_S`]); mirrored to
    /// `local.var.huddle.stats.relay_lost_suppressed`.
    pub relay_lost_suppressed: u64,
    /// Sends that failed with an error other than a full buffer (a peer or network
    /// unreachable, a broadcast refused): logged, at most one warning per 10 s;
    /// mirrored to `local.var.huddle.stats.send_errors`.
    pub send_errors: u64,
    /// Frames dropped because the send backlog was full (the kernel's send buffer was
    /// full while 1,024 frames waited); mirrored to
    /// `local.var.huddle.stats.send_backlog_drops`.
    pub send_backlog_drops: u64,
    /// Relay clients cut off for not reading their output; mirrored to
    /// `local.var.huddle.stats.relay_cutoffs`.
    pub relay_cutoffs: u64,
    /// Relay clients' writes refused because the key is the daemon's own (`ERR 423`,
    /// [`crate::Handle::reserve`]); mirrored to
    /// `local.var.huddle.stats.relay_read_only_refused`.
    pub relay_read_only_refused: u64,
    /// Relay clients' `CLOK`s refused because a GameController's figures set the game
    /// clock (`ERR 424`); mirrored to `local.var.huddle.stats.relay_clock_refused`.
    pub relay_clock_refused: u64,
    /// Relay clients' watch patterns and keys refused for not being ASCII (`ERR 411`,
    /// `ERR 410`; keys are ASCII, such a pattern would never match); mirrored to
    /// `local.var.huddle.stats.relay_non_ascii_refused`.
    pub relay_non_ascii_refused: u64,
    /// Relay connections refused because [`crate::DriverConfig::max_relay_clients`]
    /// clients were connected (each got one `ERR 503` line and was closed); mirrored to
    /// `local.var.huddle.stats.relay_clients_refused`.
    pub relay_clients_refused: u64,
    /// Datagrams an [`Impairment`] lost (or that found its hold queue full); mirrored to
    /// `local.var.huddle.stats.impair_dropped`.
    pub impair_dropped: u64,
    /// Extra copies an [`Impairment`] made (duplicates).
    pub impair_duplicated: u64,
}

impl IoStats {
    /// Every count of something dropped or refused, by the name it has under
    /// `local.var.huddle.stats.` (and in `huddle stats`).
    pub fn dropped(&self) -> [(&'static str, u64); 10] {
        [
            ("unicast_refused", self.unicast_refused),
            ("relay_lost_suppressed", self.relay_lost_suppressed),
            ("relay_cutoffs", self.relay_cutoffs),
            ("relay_read_only_refused", self.relay_read_only_refused),
            ("relay_clock_refused", self.relay_clock_refused),
            ("relay_non_ascii_refused", self.relay_non_ascii_refused),
            ("relay_clients_refused", self.relay_clients_refused),
            ("send_backlog_drops", self.send_backlog_drops),
            ("send_errors", self.send_errors),
            ("impair_dropped", self.impair_dropped),
        ]
    }

    /// Mirrors [`IoStats::dropped`] into `local.var.huddle.stats.*` of `replica`, where
    /// `huddle stats` and every relay client read the replica's own counters. `last` is
    /// what the previous call mirrored: nothing is looked at while no count moved (the
    /// driver calls this at every timer); then each key is written if it differs. The
    /// replica mirrors its own counters at its refresh; the driver and
    /// [`crate::Session`] call this at their timers.
    pub(crate) fn mirror(&self, last: &mut Option<[u64; 10]>, replica: &mut Replica, now: Instant) {
        let counts = self.dropped().map(|(_, n)| n);
        if *last == Some(counts) {
            return;
        }
        *last = Some(counts);
        for (name, count) in self.dropped() {
            let key = format!("local.var.huddle.stats.{name}");
            let value = Value::Int(i64::try_from(count).unwrap_or(i64::MAX));
            let same = replica
                .get(&key)
                .ok()
                .flatten()
                .is_some_and(|e| e.value == value);
            if !same {
                // A local key of valid shape: only the local-key limit could refuse it.
                let _ = replica.set(now, &key, value);
            }
        }
    }
}

/// The state shared by the driver task, its handles and the relay connections.
pub(crate) struct Inner {
    pub(crate) clock: Clock,
    pub(crate) replica: Replica,
    pub(crate) socket: Rc<UdpSocket>,
    /// The `--peer` socket (`<iface>:<port>`), only when peers are configured and the
    /// transport is not unicast (then `socket` is that socket).
    pub(crate) unicast: Option<Rc<UdpSocket>>,
    /// The group or broadcast address every frame goes to; `None` with unicast.
    pub(crate) destination: Option<SocketAddr>,
    pub(crate) peers: Vec<SocketAddr>,
    pub(crate) backlog: VecDeque<(Vec<u8>, SocketAddr)>,
    /// Subscriptions ([`crate::Handle::subscribe`]), found by the keys their patterns
    /// can match: a change is matched only against those that might match it.
    pub(crate) subscribers: PatternIndex<Weak<RefCell<SubQueue>>>,
    /// Reactions registered with [`crate::Handle::watch`], indexed the same way.
    pub(crate) watches: PatternIndex<Weak<WatchSlot>>,
    /// Reactions due, run once the shared state is no longer borrowed.
    pub(crate) reactions: VecDeque<(Weak<WatchSlot>, Notice)>,
    /// Reactions are running further up the stack.
    pub(crate) reacting: bool,
    /// Checks in front of relay clients' writes of some keys ([`crate::Handle::guard`]).
    pub(crate) guards: Vec<Weak<GuardSlot>>,
    /// Families of keys relay clients may not write ([`crate::Handle::reserve`]).
    pub(crate) read_only: Vec<Weak<ReadOnlySlot>>,
    pub(crate) subscriber_backlog: usize,
    pub(crate) sessions: BTreeMap<u64, SessionSlot>,
    pub(crate) next_session: u64,
    pub(crate) session_limits: SessionLimits,
    /// Relay clients served at once at most ([`crate::DriverConfig::max_relay_clients`]).
    pub(crate) max_relay_clients: usize,
    /// Warnings about relay connections refused over that cap, rate-limited.
    pub(crate) clients_refused_warnings: RateLimit,
    pub(crate) io: IoStats,
    /// The counts [`IoStats::mirror`] last wrote.
    pub(crate) io_mirrored: Option<[u64; 10]>,
    /// Wakes the driver task when deadlines or the backlog changed from outside it.
    pub(crate) wake: Rc<Nudge>,
    /// Outgoing impairment (`huddle daemon --impair`), and the copies it holds back.
    pub(crate) impairment: Option<Box<dyn Impairment>>,
    pub(crate) held: BinaryHeap<Reverse<Held>>,
    pub(crate) held_order: u64,
    pub(crate) copies: Vec<Instant>,
    /// Notices handed to subscribers and relay sessions so far: tells the receive loop
    /// that a task is now waiting to run.
    pub(crate) handed_up: u64,
    /// Warnings about frames dropped for a team-key mismatch, rate-limited.
    pub(crate) key_mismatch: RateLimit,
    /// Warnings about sends the OS refused, rate-limited.
    pub(crate) send_failures: RateLimit,
    /// Warnings about given-up talk messages.
    pub(crate) give_up_warnings: RateLimit,
    /// The buffer every outgoing frame is written into (reused: no allocation per frame).
    pub(crate) tx_buf: Vec<u8>,
}

impl Inner {
    /// Drains the replica: frames to the socket, events to sessions and subscribers.
    pub(crate) fn pump(&mut self) {
        let mut payload = std::mem::take(&mut self.tx_buf);
        while self.replica.poll_transmit_into(&mut payload).is_some() {
            for i in 0..self.peers.len() {
                let peer = self.peers[i];
                self.emit(&payload, peer);
            }
            if let Some(destination) = self.destination {
                self.emit(&payload, destination);
            }
        }
        self.tx_buf = payload;
        self.dispatch_events();
    }

    /// Sends now, or through the impairment: lost, or held for its copies' times.
    fn emit(&mut self, payload: &[u8], to: SocketAddr) {
        let Some(model) = self.impairment.as_mut() else {
            return self.send(payload, to);
        };
        let now = self.clock.now();
        let mut copies = std::mem::take(&mut self.copies);
        copies.clear();
        model.judge(now, to, payload.len(), &mut copies);
        if copies.is_empty() {
            self.io.impair_dropped += 1;
        }
        self.io.impair_duplicated += copies.len().saturating_sub(1) as u64;
        let earliest = self.held.peek().map(|Reverse(h)| h.at);
        let shared: Rc<[u8]> = Rc::from(payload);
        for &at in &copies {
            if self.held.len() >= HELD_LIMIT {
                self.io.impair_dropped += 1;
                continue;
            }
            self.held_order += 1;
            self.held.push(Reverse(Held {
                at,
                order: self.held_order,
                payload: shared.clone(),
                to,
            }));
        }
        self.copies = copies;
        if self.held.peek().map(|Reverse(h)| h.at) != earliest {
            // The driver task may be asleep until a later deadline.
            self.wake.notify_one();
        }
    }

    /// Sends every held copy whose time has come.
    fn release_held(&mut self) {
        let now = self.clock.now();
        while self.held.peek().is_some_and(|Reverse(h)| h.at <= now) {
            let Some(Reverse(h)) = self.held.pop() else {
                break;
            };
            self.send(&h.payload, h.to);
        }
    }

    /// The socket a datagram to `to` leaves from: the unicast one for peers (when open),
    /// the team's socket otherwise.
    pub(crate) fn socket_for(&self, to: SocketAddr) -> &Rc<UdpSocket> {
        match &self.unicast {
            Some(unicast) if Some(to) != self.destination => unicast,
            _ => &self.socket,
        }
    }

    /// Counts a send the OS refused and says so, at most once per
    /// [`SEND_WARNING_PERIOD`]: a peer that is down must not flood the log.
    fn send_failed(&mut self, to: SocketAddr, error: &io::Error) {
        self.io.send_errors += 1;
        tracing::debug!(%to, %error, "send failed");
        if let Some(count) = self.send_failures.record(self.clock.now()) {
            tracing::warn!(
                count,
                latest_to = %to,
                latest_error = %error,
                "{count} send(s) refused by the OS since the last such warning (at most one \
                 every 10 s)"
            );
        }
    }

    fn send(&mut self, payload: &[u8], to: SocketAddr) {
        if !self.backlog.is_empty() {
            return self.enqueue(payload.to_vec(), to);
        }
        match self.socket_for(to).try_send_to(payload, to) {
            Ok(_) => self.io.datagrams_sent += 1,
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                self.enqueue(payload.to_vec(), to);
                self.wake.notify_one();
            }
            Err(e) => self.send_failed(to, &e),
        }
    }

    fn enqueue(&mut self, payload: Vec<u8>, to: SocketAddr) {
        if self.backlog.len() >= SEND_BACKLOG_FRAMES {
            self.io.send_backlog_drops += 1;
        } else {
            self.backlog.push_back((payload, to));
        }
    }

    /// Sends what the backlog holds until the kernel refuses again.
    pub(crate) fn flush_backlog(&mut self) {
        while let Some((payload, to)) = self.backlog.front() {
            let to = *to;
            match self.socket_for(to).try_send_to(payload, to) {
                Ok(_) => self.io.datagrams_sent += 1,
                Err(e) if e.kind() == io::ErrorKind::WouldBlock => return,
                Err(e) => self.send_failed(to, &e),
            }
            self.backlog.pop_front();
        }
    }

    fn dispatch_events(&mut self) {
        // The clock is read only if a relay session needs it (not on every pump).
        let clock = self.clock;
        let mut now = None;
        while let Some((event, at)) = self.replica.poll_event_at() {
            match event {
                Event::ValueChanged { key } => {
                    for slot in self.sessions.values_mut() {
                        if slot.session.wants_changes() {
                            let before = slot.session.pending_output().len();
                            let now = *now.get_or_insert_with(|| clock.now());
                            slot.session.handle_change(now, &key, &self.replica);
                            self.handed_up += u64::from(wake_if_changed(slot, before));
                        }
                    }
                    // Only the watches and subscribers whose patterns may match are
                    // looked at (most changes, this robot's own writes among them, meet
                    // none); the binding is read (once, from the slot the change came
                    // with) and cloned only for a listener whose pattern matches.
                    let matches = (key.scope(), key.kind(), key.path());
                    let replica = &self.replica;
                    let mut entry = None;
                    let mut notice = || {
                        let entry = *entry.get_or_insert_with(|| match at {
                            Some(at) => replica.changed_entry(&key, at),
                            None => replica.blackboard().get(&key),
                        });
                        entry.map(|entry| Notice::Changed {
                            key: key.clone(),
                            entry: entry.clone(),
                        })
                    };
                    queue_reactions(&mut self.watches, &mut self.reactions, matches, &mut notice);
                    self.handed_up += deliver(&mut self.subscribers, matches, &mut notice);
                }
                Event::TalkDelivered {
                    queue,
                    from,
                    seq,
                    value,
                } => {
                    for slot in self.sessions.values_mut() {
                        let before = slot.session.pending_output().len();
                        slot.session.handle_talk(from, &queue, &value);
                        self.handed_up += u64::from(wake_if_changed(slot, before));
                    }
                    let mut notice = || {
                        Some(Notice::Talk {
                            from,
                            queue: queue.clone(),
                            seq,
                            value: value.clone(),
                        })
                    };
                    let matches = (Scope::Robot(from), Kind::Talk, queue.as_str());
                    queue_reactions(&mut self.watches, &mut self.reactions, matches, &mut notice);
                    self.handed_up += deliver(&mut self.subscribers, matches, &mut notice);
                }
                Event::TalkGivenUp {
                    queue,
                    from,
                    first,
                    last,
                } => {
                    let now = *now.get_or_insert_with(|| clock.now());
                    // Unkeyed talk heads can cause give-ups as fast as they are sent: one
                    // warning per period, with the count it stands for.
                    if let Some(times) = self.give_up_warnings.record(now) {
                        tracing::warn!(from, %queue, first, last, times, "talk messages given up");
                    }
                    for slot in self.sessions.values_mut() {
                        let before = slot.session.pending_output().len();
                        let suppressed = slot.session.lost_suppressed();
                        slot.session
                            .handle_talk_lost(now, from, &queue, first, last);
                        self.io.relay_lost_suppressed +=
                            slot.session.lost_suppressed() - suppressed;
                        self.handed_up += u64::from(wake_if_changed(slot, before));
                    }
                    let mut notice = || {
                        Some(Notice::TalkLost {
                            from,
                            queue: queue.clone(),
                            first,
                            last,
                        })
                    };
                    let matches = (Scope::Robot(from), Kind::Talk, queue.as_str());
                    queue_reactions(&mut self.watches, &mut self.reactions, matches, &mut notice);
                    self.handed_up += deliver(&mut self.subscribers, matches, &mut notice);
                }
                Event::PeerJoined { robot, incarnation } => {
                    tracing::info!(
                        robot,
                        incarnation = format_args!("{incarnation:016x}"),
                        "peer joined"
                    )
                }
                Event::PeerRestarted {
                    robot,
                    new_incarnation,
                    ..
                } => tracing::info!(
                    robot,
                    incarnation = format_args!("{new_incarnation:016x}"),
                    "peer restarted"
                ),
                Event::PeerDeparted { robot } => tracing::info!(robot, "peer departed"),
                // The replica reports each pair at most once a second.
                Event::IncarnationConflict {
                    robot,
                    current,
                    other,
                } => tracing::error!(
                    robot,
                    current = format_args!("{current:016x}"),
                    other = format_args!("{other:016x}"),
                    "two robots are sending with id {robot}: frames of the other incarnation \
                     are dropped while the current one is heard"
                ),
                Event::FrameDropped { from, reason } => {
                    tracing::debug!(%from, %reason, "datagram dropped");
                    let key_mismatch = matches!(
                        reason,
                        DropReason::MissingTag | DropReason::UnexpectedTag | DropReason::BadTag
                    );
                    if key_mismatch {
                        let now = *now.get_or_insert_with(|| clock.now());
                        if let Some(count) = self.key_mismatch.record(now) {
                            tracing::warn!(
                                count,
                                latest_from = %from,
                                latest_reason = %reason,
                                "{count} frame(s) dropped for a team-key mismatch since the \
                                 last such warning (at most one every 10 s): does every \
                                 robot use the same --key-file?"
                            );
                        }
                    }
                }
            }
        }
    }

    /// The earliest deadline of the replica, the relay sessions and held copies.
    pub(crate) fn next_deadline(&self) -> Option<Instant> {
        let sessions = self
            .sessions
            .values()
            .filter_map(|s| s.session.poll_timeout());
        self.replica
            .poll_timeout()
            .into_iter()
            .chain(sessions)
            .chain(self.held.peek().map(|Reverse(h)| h.at))
            .min()
    }

    pub(crate) fn handle_timeout(&mut self) {
        self.release_held();
        let now = self.clock.now();
        self.replica.handle_timeout(now);
        self.mirror_io(now);
        for slot in self.sessions.values_mut() {
            if slot.session.poll_timeout().is_some_and(|t| t <= now) {
                let before = slot.session.pending_output().len();
                slot.session.handle_timeout(now, &self.replica);
                wake_if_changed(slot, before);
            }
        }
        self.pump();
    }

    /// Mirrors the I/O counters into `local.var.huddle.stats.*` ([`IoStats::mirror`]).
    fn mirror_io(&mut self, now: Instant) {
        self.io
            .mirror(&mut self.io_mirrored, &mut self.replica, now);
    }

    /// A new relay session: its id and the notifier its connection waits on; `None`, and
    /// counted in [`IoStats::relay_clients_refused`], when `max_relay_clients` sessions
    /// are open (a warning at most every 10 s says so).
    pub(crate) fn open_session(&mut self) -> Option<(u64, Rc<Notify>)> {
        if self.sessions.len() >= self.max_relay_clients {
            self.io.relay_clients_refused += 1;
            if let Some(n) = self.clients_refused_warnings.record(self.clock.now()) {
                tracing::warn!(
                    refused = n,
                    max = self.max_relay_clients,
                    "relay connections refused: as many clients as --max-clients are connected"
                );
            }
            self.wake.notify_one(); // the mirror runs at the driver's timers
            return None;
        }
        let id = self.next_session;
        self.next_session += 1;
        let notify = Rc::new(Notify::new());
        let session = Session::new(self.replica.robot_id(), self.session_limits.clone());
        self.sessions.insert(
            id,
            SessionSlot {
                session,
                notify: notify.clone(),
            },
        );
        Some((id, notify))
    }

    /// Feeds a relay client's bytes to its session; writes go through the replica.
    pub(crate) fn session_input(&mut self, id: u64, bytes: &[u8]) {
        let now = self.clock.now();
        let Some(slot) = self.sessions.get_mut(&id) else {
            return;
        };
        let timer_before = slot.session.poll_timeout();
        let non_ascii_before = slot.session.non_ascii_refused();
        self.guards.retain(|g| g.strong_count() > 0);
        let mut board = GuardedBoard {
            replica: &mut self.replica,
            guards: &self.guards,
            read_only: &self.read_only,
            refused: &mut self.io.relay_read_only_refused,
            clock_refused: &mut self.io.relay_clock_refused,
        };
        slot.session.handle_input(now, bytes, &mut board);
        self.io.relay_non_ascii_refused += slot.session.non_ascii_refused() - non_ascii_before;
        if slot.session.poll_timeout() != timer_before {
            self.wake.notify_one();
        }
        self.pump();
        if !self.reactions.is_empty() {
            // The caller holds the shared state: the driver task runs them.
            self.wake.notify_one();
        }
    }
}

/// Wakes the session's connection if it has something new to write; returns whether.
fn wake_if_changed(slot: &mut SessionSlot, before: usize) -> bool {
    let after = slot.session.pending_output().len();
    let wake = after != before || slot.session.is_finished();
    if wake {
        slot.notify.notify_one();
    }
    wake
}

/// The key a notice is about, as parts: scope, kind, path.
type About<'a> = (Scope, Kind, &'a str);

/// Queues a notice for every live watch whose pattern matches the key (`notice` gives
/// none when there is nothing to tell); forgets dropped ones it meets.
fn queue_reactions(
    watches: &mut PatternIndex<Weak<WatchSlot>>,
    reactions: &mut VecDeque<(Weak<WatchSlot>, Notice)>,
    (scope, kind, path): About<'_>,
    notice: &mut impl FnMut() -> Option<Notice>,
) {
    watches.visit_matching(scope, kind, path, |weak| {
        if weak.strong_count() == 0 {
            return false;
        }
        if let Some(notice) = notice() {
            reactions.push_back((weak.clone(), notice));
        }
        true
    });
}

/// Hands a notice to every live subscriber whose pattern matches the key (`notice` gives
/// none when there is nothing to tell); forgets dropped ones it meets. Returns how many
/// got it.
fn deliver(
    subscribers: &mut PatternIndex<Weak<RefCell<SubQueue>>>,
    (scope, kind, path): About<'_>,
    notice: &mut impl FnMut() -> Option<Notice>,
) -> u64 {
    let mut handed = 0;
    subscribers.visit_matching(scope, kind, path, |weak| {
        let Some(sub) = weak.upgrade() else {
            return false;
        };
        if let Some(notice) = notice() {
            sub.borrow_mut().push(notice);
            handed += 1;
        }
        true
    });
    handed
}

/// Wakes the driver task from its handles (deadlines or the backlog changed, reactions
/// are due): a flag and one waker, all on one thread.
#[derive(Default)]
pub(crate) struct Nudge {
    pending: Cell<bool>,
    waker: RefCell<Option<Waker>>,
}

impl Nudge {
    /// Makes the driver's next (or current) wait end.
    pub(crate) fn notify_one(&self) {
        self.pending.set(true);
        if let Some(waker) = self.waker.borrow_mut().take() {
            waker.wake();
        }
    }

    pub(crate) fn poll(&self, cx: &mut Context<'_>) -> Poll<()> {
        if self.pending.replace(false) {
            return Poll::Ready(());
        }
        let mut slot = self.waker.borrow_mut();
        if !slot.as_ref().is_some_and(|w| w.will_wake(cx.waker())) {
            *slot = Some(cx.waker().clone());
        }
        Poll::Pending
    }
}

/// What a watch runs: the robot's reaction to a notice, given the shared state to make a
/// handle from (`Handle::watch` wraps the robot's closure).
pub(crate) type Reaction = dyn FnMut(&Rc<RefCell<Inner>>, Notice);

/// A watch's reaction, shared (weakly) with the driver (which files it under its
/// pattern).
pub(crate) struct WatchSlot {
    pub(crate) reaction: RefCell<Box<Reaction>>,
}

/// Runs the reactions the driver has queued, unless some are already running further
/// up the stack (a reaction that writes queues more; the outermost call runs them).
/// The shared state is not borrowed while a reaction runs, so it may use the handle.
pub(crate) fn run_reactions(inner: &Rc<RefCell<Inner>>) {
    {
        let mut state = inner.borrow_mut();
        if state.reacting || state.reactions.is_empty() {
            return;
        }
        state.reacting = true;
    }
    loop {
        let next = inner.borrow_mut().reactions.pop_front();
        let Some((slot, notice)) = next else { break };
        // A watch dropped after its notice was queued no longer reacts.
        if let Some(slot) = Weak::upgrade(&slot) {
            (slot.reaction.borrow_mut())(inner, notice);
        }
    }
    inner.borrow_mut().reacting = false;
}

#[cfg(test)]
mod clock_tests {
    use super::{Clock, ClockSkew, ClockSkewError};
    use std::time::Duration;

    #[test]
    fn a_skewed_clock_reads_its_offset_and_gains_its_drift() {
        // A robot whose clock read 20 s when its daemon started and gains 250 µs a second.
        let clock = Clock::skewed(ClockSkew::new(Duration::from_secs(20), 250.0).unwrap());
        assert_eq!(clock.local_us(0), 20_000_000);
        assert_eq!(
            clock.local_us(100_000_000),
            20_000_000 + 100_000_000 + 25_000,
            "100 s later it has gained 25 ms"
        );
        let losing = Clock::skewed(ClockSkew::new(Duration::ZERO, -30.0).unwrap());
        assert_eq!(losing.local_us(1_000_000_000), 1_000_000_000 - 30_000);
        let read = clock.now().as_micros();
        assert!(
            (20_000_000..21_000_000).contains(&read),
            "a skewed clock reads its offset at start, read {read} µs"
        );
    }

    #[test]
    fn a_deadline_on_a_skewed_clock_is_due_when_the_timer_for_it_fires() {
        // The driver arms its timer at `to_tokio(deadline)`: there the replica must find
        // the deadline due, or the loop would wake and sleep again on one instant.
        for skew in [
            ClockSkew::NONE,
            ClockSkew::new(Duration::from_micros(7_654_321), 31.7).unwrap(),
            ClockSkew::new(Duration::from_secs(3), -29.3).unwrap(),
            ClockSkew::new(Duration::from_millis(1), 99_999.0).unwrap(),
        ] {
            let clock = Clock::skewed(skew);
            for local in (0..2_000_000_000u64)
                .step_by(7_777_777)
                .chain([u64::MAX / 4])
            {
                let real = clock.real_us(local);
                if local >= skew.offset_us {
                    assert!(
                        clock.local_us(real) >= local,
                        "{skew:?}: the timer for {local} µs fires at {real} µs real, which reads {}",
                        clock.local_us(real)
                    );
                    assert!(
                        real == 0 || clock.local_us(real - 1) < local,
                        "{skew:?}: the timer for {local} µs fires late, at {real} µs real"
                    );
                } else {
                    assert_eq!(real, 0, "a reading before the start is due at once");
                }
            }
        }
    }

    #[test]
    fn a_skew_out_of_range_is_refused() {
        assert!(matches!(
            ClockSkew::new(Duration::ZERO, f64::NAN),
            Err(ClockSkewError::Drift { .. })
        ));
        assert!(matches!(
            ClockSkew::new(Duration::ZERO, -100_001.0),
            Err(ClockSkewError::Drift { .. })
        ));
        assert!(matches!(
            ClockSkew::new(Duration::from_secs(2 * 86_400), 0.0),
            Err(ClockSkewError::Offset { .. })
        ));
        let ok = ClockSkew::new(Duration::from_millis(1500), -12.5).unwrap();
        assert_eq!(
            (ok.offset(), ok.drift_ppm()),
            (Duration::from_millis(1500), -12.5)
        );
    }
}

#[cfg(test)]
#[path = "mirror_tests.rs"]
mod mirror_tests;
