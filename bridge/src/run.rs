//! The bridge's I/O: the team's socket (listen only), the listening replica, one Zenoh
//! session. The field side is one task on Zenoh's TX runtime (the runtime whose worker
//! writes Zenoh's links): it awaits each datagram (or the next deadline), feeds it to
//! the replica, discards the replica's transmits, hands its events to the [`Exporter`]
//! and queues the resulting operations in the [`Outbox`]. A publisher thread
//! hands what waits there to Zenoh with blocking congestion control, so Zenoh drops
//! nothing. Every version waits in order in the outbox up to its capacity; only when Zenoh
//! blocks longer (a slow subscriber, a busy router) are superseded values merged away
//! there, and every key's last value still goes, while the field side
//! never waits for Zenoh. The queryables run on Zenoh's threads and read the same replica
//! under the same mutex.
//!
//! **The fast path** (the default; `--no-fast-path` turns it off). Waking the publisher thread is a scheduler
//! hand-over per sample, and a put from any thread then wakes Zenoh's transmit task on
//! its TX worker: two thread wake-ups before a sample leaves. With the fast path, when
//! nothing waits, the publisher is idle and no put has been slow in the last second, the
//! field task puts the datagram's few samples itself. Being on the TX runtime, the put
//! schedules Zenoh's transmit task on the same worker, where it runs as soon as the field
//! task yields (it does, after each put): no thread wake-up at all between the datagram
//! and the socket write. Its price: a Zenoh queue that fills at once (a router stalling
//! after a second of fast puts) holds the field task up to Zenoh's block timeout; the
//! binary gives the TX runtime a second worker so that Zenoh's transmit task can run
//! meanwhile. One of the two puts at a time, so samples keep their order.
//!
//! **The field loop** ([`FieldLoop`], `--field-loop`). With Zenoh's lowlatency transport
//! (`transport/unicast/lowlatency`, docs/bridge.md) there is no transmit task: a put
//! writes the link from the calling thread, through `block_in_place`, which on a runtime
//! worker first hands the worker's queue to another thread. So with it the field side
//! runs on a thread of its own instead, blocking on the socket: the kernel wakes that
//! thread with the datagram and the same thread writes the sample to the router.
//!
//! **Zenoh going away.** The bridge declares a liveliness token
//! `…/<team>/@bridge/alive`: a subscriber that sees it appear (at start, or again after
//! its own link or the router came back) gets the team's prefix and recovers every value
//! it missed. When the bridge's own session comes back (checked by the publisher thread),
//! it puts every key's current value once more. On SIGTERM/SIGINT
//! ([`Bridge::shutdown_flag`]) the datagrams left in the socket are read, the outbox is
//! handed over, a flush barrier (`flush_barrier`) waits until the router has routed
//! every put, and the session is closed.

mod query;

use std::collections::HashMap;
use std::io;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Duration;

use comms::{DropReason, Event, Instant, Replica, ReplicaConfig};
use driver::{Clock, SocketConfig};
use thiserror::Error;
use zenoh::bytes::Encoding;
use zenoh::key_expr::KeyExpr;
use zenoh::liveliness::LivelinessToken;
use zenoh::qos::CongestionControl;
use zenoh::query::ConsolidationMode;
use zenoh::sample::Locality;
use zenoh::{Session, Wait};

use crate::export::{ExportConfig, Exporter, Op, Sample};
use crate::keys::TeamKeys;
use crate::outbox::Outbox;
use crate::transit::Heard;
use query::{answer_bridge, answer_values};

/// A put longer than this counts as slow: Zenoh's queue was full (or the machine very
/// busy), and the field thread leaves puts to the publisher thread for [`SLOW_HOLD`].
const SLOW_PUT: Duration = Duration::from_millis(2);
/// The most samples the field task puts in one turn on the fast path: well inside one of
/// Zenoh's batches (64 kB), so a turn never needs a second free batch (Zenoh's data queue
/// has two) while the transmit task it woke waits behind it on the same worker.
const FAST_MAX_OPS: usize = 32;
/// How long after a slow put the field thread does not put itself.
const SLOW_HOLD: Duration = Duration::from_secs(1);
/// How often the session's router or peer is checked.
const ZENOH_CHECK: Duration = Duration::from_millis(250);
/// How long the shutdown waits for the flush barrier ([`flush_barrier`]).
const FLUSH_TIMEOUT: Duration = Duration::from_secs(10);

/// Everything the bridge needs to start.
pub struct BridgeConfig {
    /// The team's socket (transport, group or port, interface).
    pub socket: SocketConfig,
    /// The team id.
    pub team: u8,
    /// The team key, if the team signs its frames.
    pub team_key: Option<Vec<u8>>,
    /// The listening replica's robot id (one no robot of the team uses).
    pub listener_id: u8,
    /// Key expressions.
    pub keys: TeamKeys,
    /// What to export.
    pub export: ExportConfig,
    /// The Zenoh session's configuration (mode, endpoints, TLS, auth).
    pub zenoh: zenoh::Config,
    /// Whether the field thread may put samples itself (see the module docs).
    pub fast_path: bool,
    /// Where the field side runs.
    pub field_loop: FieldLoop,
    /// How a sample's key reaches Zenoh ([`PutVia`]).
    pub put_via: PutVia,
    /// Operations the outbox holds in order before it merges ([`crate::outbox`]); 0
    /// merges every superseded value at once (the bridge before the seventh session).
    pub outbox_capacity: usize,
}

/// How the bridge names a sample's key to Zenoh.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PutVia {
    /// Each key declared once (`Session::declare_keyexpr`, up to [`MAX_DECLARED`] keys):
    /// a put then carries a numeric id the session's routing tables resolve directly,
    /// with the routes cached on the key's resource, instead of a string to validate
    /// and match against every subscription per put (docs/bridge.md, seventh session).
    #[default]
    Declared,
    /// A string key per put (what the bridge did until the seventh session).
    String,
}

/// The most keys declared to Zenoh ([`PutVia::Declared`]); further keys are put by
/// string. A venue's team has about 11 robots × 20 keys; this bounds a misbehaving team.
pub const MAX_DECLARED: usize = 16_384;

/// The declared key expressions of the puts ([`PutVia::Declared`]).
struct PutKeys {
    via: PutVia,
    declared: Mutex<HashMap<String, KeyExpr<'static>>>,
}

impl PutKeys {
    fn new(via: PutVia) -> PutKeys {
        PutKeys {
            via,
            declared: Mutex::new(HashMap::new()),
        }
    }

    /// The key expression to put `key` on: declared once, then reused.
    fn get(&self, session: &Session, key: String) -> zenoh::Result<KeyExpr<'static>> {
        if self.via == PutVia::String {
            return KeyExpr::try_from(key);
        }
        let mut declared = self.declared.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(k) = declared.get(&key) {
            return Ok(k.clone());
        }
        if declared.len() >= MAX_DECLARED {
            if declared.len() == MAX_DECLARED {
                tracing::warn!(
                    "{MAX_DECLARED} keys declared to zenoh: further keys are put by string"
                );
            }
            return KeyExpr::try_from(key);
        }
        let k = session.declare_keyexpr(key.clone()).wait()?;
        declared.insert(key, k.clone());
        Ok(k)
    }
}

/// Where the field side (receive, replica, exporter, fast-path puts) runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FieldLoop {
    /// [`FieldLoop::TxRuntime`], unless the Zenoh configuration asks for the lowlatency
    /// transport (`transport/unicast/lowlatency: true`): then [`FieldLoop::Thread`].
    #[default]
    Auto,
    /// A task on Zenoh's TX runtime: a put wakes Zenoh's transmit task on the same worker.
    TxRuntime,
    /// A thread of its own with a blocking receive. With the lowlatency transport a put
    /// writes the link from the calling thread (zenoh-transport's
    /// `TransportUnicastLowlatency::send`, via `block_in_place`): from here that is one
    /// `write` and no thread wake-up at all, where on a runtime worker `block_in_place`
    /// would first hand the worker's queue to another thread.
    Thread,
}

impl FieldLoop {
    /// `Auto` decided by the session's configuration.
    fn resolve(self, zenoh: &zenoh::Config) -> FieldLoop {
        match self {
            FieldLoop::Auto if lowlatency(zenoh) => FieldLoop::Thread,
            FieldLoop::Auto => FieldLoop::TxRuntime,
            chosen => chosen,
        }
    }
}

/// Whether `cfg` asks for Zenoh's lowlatency unicast transport (used only if the other
/// end asks too).
pub fn lowlatency(cfg: &zenoh::Config) -> bool {
    cfg.get_json("transport/unicast/lowlatency")
        .is_ok_and(|v| v.trim() == "true")
}

/// Why the bridge could not start.
#[derive(Debug, Error)]
pub enum BridgeError {
    /// The team's socket could not be opened.
    #[error("cannot listen to the team: {0}")]
    Socket(#[from] driver::SocketError),
    /// A socket option failed.
    #[error("socket: {0}")]
    Io(#[from] io::Error),
    /// The listening replica's configuration is invalid.
    #[error("listening replica: {0}")]
    Replica(#[from] comms::ConfigInvalid),
    /// Zenoh refused the configuration or could not open the session.
    #[error("zenoh: {0}")]
    Zenoh(String),
}

fn zerr(e: impl std::fmt::Display) -> BridgeError {
    BridgeError::Zenoh(e.to_string())
}

/// Counters of the field side and the Zenoh side.
#[derive(Clone, Debug, Default)]
pub struct IoCounters {
    /// Datagrams received from the team's socket.
    pub datagrams: u64,
    /// Receive errors other than timeouts.
    pub recv_errors: u64,
    /// Frames the listening replica wanted to send and the bridge discarded (it never
    /// sends on the field).
    pub transmits_discarded: u64,
    /// Puts Zenoh refused.
    pub put_errors: u64,
    /// Samples Zenoh accepted (each put of a value or talk message; a `--ros2` copy not
    /// counted): what left the bridge, to compare with what a subscriber received.
    pub puts: u64,
    /// Time spent inside those puts, µs: Zenoh's pushback (a put that blocks on a full
    /// queue) shows here.
    pub put_us: u64,
    /// Liveliness declarations Zenoh refused.
    pub token_errors: u64,
    /// Queries answered.
    pub queries: u64,
    /// Replies sent.
    pub replies: u64,
    /// Queries refused (a payload: the bridge takes no input from Zenoh).
    pub queries_refused: u64,
    /// Times the session lost its last router or peer.
    pub zenoh_lost: u64,
    /// Times it found one again (every key's value was put once more).
    pub zenoh_back: u64,
    /// Batches of samples the field thread put itself (the fast path).
    pub inline_puts: u64,
    /// Batches handed over to the publisher thread.
    pub handed_over: u64,
}

/// The last few thousand durations of one step, in µs, for `@bridge/stats`.
#[derive(Debug, Default)]
struct Ring {
    us: Vec<u32>,
    next: usize,
}

impl Ring {
    const LEN: usize = 4096;

    fn push(&mut self, d: Duration) {
        let us = u32::try_from(d.as_micros()).unwrap_or(u32::MAX);
        if self.us.len() < Self::LEN {
            self.us.push(us);
        } else {
            self.us[self.next] = us;
        }
        self.next = (self.next + 1) % Self::LEN;
    }

    fn json(&self) -> serde_json::Value {
        let mut v = self.us.clone();
        v.sort_unstable();
        let q = |q: f64| {
            v.get(((v.len().saturating_sub(1)) as f64 * q).round() as usize)
                .copied()
        };
        serde_json::json!({ "n": v.len(), "p50": q(0.5), "p99": q(0.99) })
    }
}

/// Where a sample's time in the bridge goes (see the module docs).
#[derive(Debug, Default)]
struct Timings {
    /// From the datagram's reception to its samples queued.
    field: Ring,
    /// From queued to taken by the publisher thread (the hand-over; 0 on the fast path).
    handoff: Ring,
    /// One put (Zenoh copying the sample into its queue).
    put: Ring,
}

/// The state the field thread and the queryables share.
struct Core {
    replica: Replica,
    team: u8,
    team_key: Option<comms::wire::TeamKey>,
    exporter: Exporter,
    /// What waits for the publisher thread.
    outbox: Outbox,
    io: IoCounters,
    reported_drops: Vec<DropReason>,
    timings: Timings,
    /// A thread is putting (the publisher, or the field thread on the fast path).
    putting: bool,
    /// No fast path before this (a put was slow).
    slow_until: Option<Instant>,
    /// The fast path is allowed at all.
    fast_path: bool,
}

impl Core {
    fn drain(&mut self, now: Instant) {
        while self.replica.poll_transmit().is_some() {
            self.io.transmits_discarded += 1;
        }
        while let Some(event) = self.replica.poll_event() {
            match &event {
                Event::FrameDropped { from, reason } if !self.reported_drops.contains(reason) => {
                    self.reported_drops.push(*reason);
                    tracing::warn!(
                        "dropped a frame from {from}: {reason} (counted in @bridge/stats; \
                         logged once per reason)"
                    );
                }
                Event::PeerJoined { robot, incarnation } => {
                    tracing::info!("robot {robot} joined (incarnation {incarnation:016x})")
                }
                Event::PeerRestarted {
                    robot,
                    new_incarnation,
                    ..
                } => tracing::info!("robot {robot} restarted ({new_incarnation:016x})"),
                Event::PeerDeparted { robot } => tracing::info!("robot {robot} departed"),
                Event::IncarnationConflict { robot, .. } => {
                    tracing::warn!("two robots send as {robot}")
                }
                _ => {}
            }
            self.exporter.handle_event(now, &self.replica, event);
        }
    }

    fn advance(&mut self, now: Instant) {
        while let Some(deadline) = self.replica.poll_timeout() {
            if deadline > now {
                break;
            }
            self.replica.handle_timeout(deadline);
            self.drain(deadline);
        }
        self.exporter.handle_timeout(now, &self.replica);
    }

    fn next_deadline(&self) -> Option<Instant> {
        match (self.replica.poll_timeout(), self.exporter.poll_timeout()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    fn stats_json(&self, now: Instant) -> serde_json::Value {
        let s = self.replica.stats();
        let e = self.exporter.stats();
        let io = &self.io;
        let drops: serde_json::Map<String, serde_json::Value> = DropReason::ALL
            .iter()
            .map(|r| (r.name().to_owned(), s.drops(*r).into()))
            .collect();
        serde_json::json!({
            "uptime_s": now.saturating_duration_since(Instant::from_micros(0)).as_secs_f64(),
            "field": {
                "datagrams": io.datagrams,
                "recv_errors": io.recv_errors,
                "frames_in": s.frames_in,
                "bytes_in": s.bytes_in,
                "updates_applied": s.updates_applied,
                "updates_stale": s.updates_stale,
                "drops": drops,
                "frames_sent": 0,
                "transmits_discarded": io.transmits_discarded,
            },
            "transit": {
                "floor_us": self.exporter.transit().floor().as_micros() as u64,
                "round_trips": self.exporter.transit().stats().round_trips,
                "implausible": self.exporter.transit().stats().implausible,
                "implausible_round_trips": self.exporter.transit().stats().implausible_round_trips,
                "anchors": self.exporter.transit().stats().anchors,
                "implausible_anchors": self.exporter.transit().stats().implausible_anchors,
                "anchor_held": e.anchor_held,
                "unanchored_out": e.unanchored_out,
            },
            "export": {
                "values_out": e.values_out,
                "talk_out": e.talk_out,
                "unchanged_skipped": e.unchanged_skipped,
                "old_life_dropped": e.old_life_dropped,
                "rate_held": e.rate_held,
                "unmappable": e.unmappable,
                "ros2_unmappable": e.ros2_unmappable,
                "alive_declared": e.alive_declared,
                "alive_withdrawn": e.alive_withdrawn,
                "coalesced": self.outbox.stats().coalesced,
                "outbox_high_water": self.outbox.stats().high_water,
                "republished": e.republished,
            },
            "timing_us": {
                "field": self.timings.field.json(),
                "handoff": self.timings.handoff.json(),
                "put": self.timings.put.json(),
                "inline_puts": io.inline_puts,
                "handed_over": io.handed_over,
            },
            "zenoh": {
                "put_errors": io.put_errors,
                "puts": io.puts,
                "put_us": io.put_us,
                "token_errors": io.token_errors,
                "queries": io.queries,
                "replies": io.replies,
                "queries_refused": io.queries_refused,
                "lost": io.zenoh_lost,
                "back": io.zenoh_back,
            },
        })
    }

    fn peers_json(&self, now: Instant) -> serde_json::Value {
        let peers: Vec<_> = self
            .replica
            .peers()
            .map(|p| {
                serde_json::json!({
                    "robot": p.robot,
                    "incarnation": format!("{:016x}", p.incarnation),
                    "present": p.present,
                    "frames": p.frames,
                    "silent_ms": now.saturating_duration_since(p.last_heard).as_secs_f64() * 1e3,
                    "conflicting": p.conflicting,
                })
            })
            .collect();
        serde_json::Value::Array(peers)
    }
}

/// The core and the signal that the outbox has something (or that the bridge stops).
type Shared = Arc<(Mutex<Core>, Condvar)>;

/// A bridge that is up: socket open, session open, queryables declared.
pub struct Bridge {
    socket: std::net::UdpSocket,
    core: Shared,
    clock: Clock,
    session: Session,
    _queryables: Vec<zenoh::query::Queryable<()>>,
    /// `…/@bridge/alive`: subscribers get the prefix when it appears.
    _alive: LivelinessToken,
    keys: TeamKeys,
    shutdown: Arc<AtomicBool>,
    field_loop: FieldLoop,
    put_keys: Arc<PutKeys>,
}

/// The publisher thread's side: the session and the liveliness tokens it declared.
struct Publisher {
    core: Shared,
    clock: Clock,
    session: Session,
    put_keys: Arc<PutKeys>,
    tokens: HashMap<u8, LivelinessToken>,
    shutdown: Arc<AtomicBool>,
}

fn lock(core: &Mutex<Core>) -> MutexGuard<'_, Core> {
    // A panic elsewhere while holding the lock leaves counters possibly stale, never
    // memory unsafe: carry on with the data.
    core.lock().unwrap_or_else(|p| p.into_inner())
}

impl Bridge {
    /// Opens the team's socket and the Zenoh session and declares the queryables.
    pub fn start(cfg: BridgeConfig) -> Result<Bridge, BridgeError> {
        let opened = driver::open(&cfg.socket)?;
        tracing::info!(
            "listening to team {} on {} {} via {} (receive buffer {} bytes); sending nothing",
            cfg.team,
            cfg.socket.transport,
            cfg.socket.group,
            cfg.socket.iface,
            opened.recv_buffer_granted
        );
        let socket = opened.socket;
        socket.set_nonblocking(false)?;
        let clock = Clock::new();
        // The robots' team layers send their keys by index: the listener reads them with
        // the same table (without it they would be skipped and counted).
        let mut rcfg =
            ReplicaConfig::new(cfg.listener_id, cfg.team).with_known_paths(team::known_paths());
        if let Some(key) = &cfg.team_key {
            rcfg = rcfg.with_team_key(key.clone());
        }
        let replica = Replica::new(rcfg, 1, clock.now())?;
        let field_loop = cfg.field_loop.resolve(&cfg.zenoh);
        tracing::info!("field side: {field_loop:?}");
        let mut core = Core {
            team_key: cfg.team_key.as_deref().map(comms::wire::TeamKey::new),
            team: cfg.team,
            replica,
            exporter: Exporter::new(cfg.keys.clone(), cfg.export),
            outbox: Outbox::with_limits(cfg.outbox_capacity, crate::outbox::MAX_WAIT),
            io: IoCounters::default(),
            reported_drops: Vec::new(),
            timings: Timings::default(),
            putting: false,
            slow_until: None,
            fast_path: cfg.fast_path
                && (field_loop == FieldLoop::Thread || tx_runtime_configured()),
        };
        core.drain(clock.now());
        let core: Shared = Arc::new((Mutex::new(core), Condvar::new()));

        let mut zcfg = cfg.zenoh;
        // Explicit endpoints only: no multicast scouting from the bridge.
        zcfg.insert_json5("scouting/multicast/enabled", "false")
            .map_err(zerr)?;
        let session = zenoh::open(zcfg).wait().map_err(zerr)?;
        tracing::info!("zenoh session {} open", session.zid());

        let values = {
            let core = core.clone();
            session
                .declare_queryable(cfg.keys.all())
                .callback(move |q| answer_values(&core.0, &clock, &q))
                .wait()
                .map_err(zerr)?
        };
        let bridge_keys = {
            let core = core.clone();
            let keys = cfg.keys.clone();
            session
                .declare_queryable(keys.bridge("*"))
                .callback(move |q| answer_bridge(&core.0, &clock, &keys, &q))
                .wait()
                .map_err(zerr)?
        };
        let alive = session
            .liveliness()
            .declare_token(cfg.keys.bridge("alive"))
            .wait()
            .map_err(zerr)?;
        Ok(Bridge {
            socket,
            core,
            clock,
            session,
            _queryables: vec![values, bridge_keys],
            _alive: alive,
            keys: cfg.keys,
            shutdown: Arc::new(AtomicBool::new(false)),
            field_loop,
            put_keys: Arc::new(PutKeys::new(cfg.put_via)),
        })
    }

    /// A flag that stops [`Bridge::run`] within 50 ms when set.
    pub fn shutdown_flag(&self) -> Arc<AtomicBool> {
        self.shutdown.clone()
    }

    /// The key expressions in use.
    pub fn keys(&self) -> &TeamKeys {
        &self.keys
    }

    /// Runs the field side until the shutdown flag is set (and the publisher thread
    /// beside it, which hands over what is still queued before it ends); then closes the
    /// session, which writes out what Zenoh still queues.
    pub fn run(self) -> Result<(), BridgeError> {
        // The publisher stops when told here, after the field side's last values are in
        // the outbox, not at the signal (it would leave what is read after it behind).
        let publisher_stop = Arc::new(AtomicBool::new(false));
        let publisher = Publisher {
            core: self.core.clone(),
            clock: self.clock,
            session: self.session.clone(),
            put_keys: self.put_keys.clone(),
            tokens: HashMap::new(),
            shutdown: publisher_stop.clone(),
        };
        let publisher: JoinHandle<()> = std::thread::Builder::new()
            .name("zenoh-publisher".into())
            .spawn(move || publisher.run())?;
        let field = Field {
            socket: self.socket.try_clone()?,
            core: self.core.clone(),
            clock: self.clock,
            session: self.session.clone(),
            put_keys: self.put_keys.clone(),
            shutdown: self.shutdown.clone(),
        };
        let result = if self.field_loop == FieldLoop::Thread {
            // This thread is the field side's own.
            field.run_thread()
        } else {
            // On Zenoh's TX runtime, the one that writes Zenoh's links: a put there wakes
            // Zenoh's transmit task on the same worker thread (it runs as soon as the
            // field task yields) instead of waking another thread (docs/bridge.md).
            let (done_tx, done_rx) = std::sync::mpsc::channel();
            zenoh_runtime::ZRuntime::TX.spawn(async move {
                let _ = done_tx.send(field.run().await);
            });
            done_rx
                .recv()
                .unwrap_or_else(|_| Err(BridgeError::Zenoh("the field task ended".into())))
        };
        // What the robots sent before the stop still goes (the publisher thread hands it
        // over before it ends).
        let mut buf = vec![0u8; 65_536];
        let result = result.and(self.read_what_is_left(&mut buf));
        self.shutdown.store(true, Ordering::Relaxed);
        publisher_stop.store(true, Ordering::Relaxed);
        self.core.1.notify_all();
        let _ = publisher.join();
        let (values_out, held_until) = {
            let core = lock(&self.core.0);
            let e = core.exporter.stats();
            tracing::info!(
                "at stop: {} values out, {} anchor-held, {} rate-held, {} unanchored out, {} waiting in the outbox",
                e.values_out,
                e.anchor_held,
                e.rate_held,
                e.unanchored_out,
                core.outbox.len()
            );
            (e.values_out, core.exporter.poll_timeout())
        };
        if let Some(t) = held_until {
            tracing::warn!("at stop, values still held until {t:?}");
        }
        flush_barrier(&self.session, &self.keys, self.clock);
        drop(self._queryables);
        if let Err(e) = self.session.close().wait() {
            tracing::warn!("closing the zenoh session: {e}");
        }
        tracing::info!("stopped: {values_out} values out, the outbox and Zenoh's queue flushed");
        result
    }

    /// On shutdown: what the robots sent before it is still in the socket's buffer;
    /// read it (up to a bound) so that its values go out with the flush.
    fn read_what_is_left(&self, buf: &mut [u8]) -> Result<(), BridgeError> {
        self.socket.set_nonblocking(true)?;
        let mut core = lock(&self.core.0);
        let core = &mut *core;
        let mut read = 0;
        while read < 100_000 {
            let Ok((n, from)) = self.socket.recv_from(buf) else {
                break;
            };
            read += 1;
            core.io.datagrams += 1;
            feed(core, self.clock.now(), from, &buf[..n]);
        }
        let now = self.clock.now();
        core.advance(now);
        for op in core.exporter.drain_ops() {
            core.outbox.push(now, op);
        }
        if read > 0 {
            tracing::info!("stopping: read the {read} datagrams left in the socket");
        }
        Ok(())
    }
}

/// The field side: the team's socket, read on Zenoh's TX runtime (see [`Bridge::run`]).
struct Field {
    socket: std::net::UdpSocket,
    core: Shared,
    clock: Clock,
    session: Session,
    put_keys: Arc<PutKeys>,
    shutdown: Arc<AtomicBool>,
}

impl Field {
    /// How long to wait for the next datagram: until the replica's or the exporter's next
    /// deadline, within [100 µs, 50 ms].
    fn wait(&self) -> Duration {
        let core = lock(&self.core.0);
        let now = self.clock.now();
        core.next_deadline()
            .map_or(Duration::from_millis(50), |d| {
                d.saturating_duration_since(now)
            })
            .clamp(Duration::from_micros(100), Duration::from_millis(50))
    }

    /// After a wake-up (`got`: a datagram in `buf`, or `None` at a deadline): feeds the
    /// replica, queues the exporter's operations in the outbox, and returns what the field
    /// side puts itself (the fast path); otherwise the publisher thread was woken.
    fn on_wake(
        &self,
        got: Option<io::Result<(usize, SocketAddr)>>,
        buf: &[u8],
    ) -> Option<(Instant, Vec<Op>)> {
        let now = self.clock.now();
        let mut core = lock(&self.core.0);
        let datagram = matches!(got, Some(Ok(_)));
        match got {
            Some(Ok((n, from))) => {
                core.io.datagrams += 1;
                feed(&mut core, now, from, &buf[..n]);
            }
            // The next deadline came first.
            None => {}
            Some(Err(e))
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock
                        | io::ErrorKind::TimedOut
                        | io::ErrorKind::Interrupted
                ) => {}
            Some(Err(e)) => {
                core.io.recv_errors += 1;
                tracing::warn!("receive: {e}");
            }
        }
        core.advance(now);
        let core = &mut *core;
        for op in core.exporter.drain_ops() {
            core.outbox.push(now, op);
        }
        if datagram && !core.outbox.is_empty() {
            core.timings
                .field
                .push(self.clock.now().saturating_duration_since(now));
        }
        self.fast_path(core, now)
    }

    /// Puts what [`Field::on_wake`] returned, then lets the publisher thread go on.
    fn put_here(&self, taken: Instant, ops: Vec<Op>) {
        let slow = put_samples(
            &self.session,
            &self.put_keys,
            &self.clock,
            taken,
            ops,
            &self.core.0,
        );
        let mut core = lock(&self.core.0);
        core.putting = false;
        if slow {
            core.slow_until = Some(self.clock.now() + SLOW_HOLD);
        }
        if !core.outbox.is_empty() {
            self.core.1.notify_one();
        }
    }

    /// The field side as a task on Zenoh's TX runtime ([`FieldLoop::TxRuntime`]).
    async fn run(self) -> Result<(), BridgeError> {
        self.socket.set_nonblocking(true)?;
        let socket = tokio::net::UdpSocket::from_std(self.socket.try_clone()?)?;
        let mut buf = vec![0u8; 65_536];
        while !self.shutdown.load(Ordering::Relaxed) {
            let wait = self.wait();
            let got = tokio::time::timeout(wait, socket.recv_from(&mut buf))
                .await
                .ok();
            if let Some((taken, ops)) = self.on_wake(got, &buf) {
                self.put_here(taken, ops);
                // The put woke Zenoh's transmit task onto this worker: let it write the
                // batch now, before the next datagram (and before a second batch could
                // be needed: a put waiting for a free batch here would wait for a task
                // queued behind it).
                tokio::task::yield_now().await;
            }
        }
        Ok(())
    }

    /// The field side on a thread of its own ([`FieldLoop::Thread`]): a blocking receive
    /// (the kernel wakes this thread, no runtime in between), puts from here. A put that
    /// waits for a free batch waits for Zenoh's transmit task on Zenoh's own threads, so
    /// nothing here needs a second worker or a yield.
    fn run_thread(self) -> Result<(), BridgeError> {
        self.socket.set_nonblocking(false)?;
        let mut buf = vec![0u8; 65_536];
        let mut timeout = Duration::ZERO;
        while !self.shutdown.load(Ordering::Relaxed) {
            let wait = self.wait();
            // A socket option per change only: at a steady deadline it is set once.
            if wait != timeout {
                self.socket.set_read_timeout(Some(wait))?;
                timeout = wait;
            }
            let got = match self.socket.recv_from(&mut buf) {
                Err(e)
                    if matches!(
                        e.kind(),
                        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                    ) =>
                {
                    None
                }
                r => Some(r),
            };
            if let Some((taken, ops)) = self.on_wake(got, &buf) {
                self.put_here(taken, ops);
            }
        }
        Ok(())
    }

    /// What the field thread puts itself (see the module docs); otherwise wakes the
    /// publisher thread if something waits.
    fn fast_path(&self, core: &mut Core, now: Instant) -> Option<(Instant, Vec<Op>)> {
        if core.outbox.is_empty() {
            return None;
        }
        let fast = core.fast_path
            && !core.putting
            && core.outbox.len() <= FAST_MAX_OPS
            && core.slow_until.is_none_or(|t| now >= t)
            && core.outbox.only_samples();
        if !fast {
            self.core.1.notify_one();
            return None;
        }
        core.putting = true;
        core.io.inline_puts += 1;
        core.timings.handoff.push(Duration::ZERO);
        let taken = self.clock.now();
        Some((taken, core.outbox.take(taken)))
    }
}

impl Publisher {
    /// Whether the session has a router or peer; logs and counts a loss, and puts every
    /// key's value once more when one is back.
    fn check_zenoh(&self, was: bool) -> bool {
        let info = self.session.info();
        let now =
            info.routers_zid().wait().next().is_some() || info.peers_zid().wait().next().is_some();
        if was && !now {
            lock(&self.core.0).io.zenoh_lost += 1;
            tracing::warn!(
                "zenoh: no router or peer reachable; samples go nowhere until one is back, \
                 then every key's value goes once more (the field side carries on)"
            );
        } else if !was && now {
            let n = {
                let mut core = lock(&self.core.0);
                let core = &mut *core;
                core.io.zenoh_back += 1;
                let at = self.clock.now();
                let n = core.exporter.republish(at, &core.replica);
                for op in core.exporter.drain_ops() {
                    core.outbox.push(at, op);
                }
                n
            };
            self.core.1.notify_one();
            tracing::info!("zenoh: connected again; every key's value goes once more ({n})");
        }
        now
    }

    /// Hands the outbox's operations to Zenoh until the bridge stops, then what is left.
    fn run(mut self) {
        let mut next_check = self.clock.now();
        let mut connected = true;
        loop {
            let now = self.clock.now();
            if now >= next_check && !self.shutdown.load(Ordering::Relaxed) {
                next_check = now + ZENOH_CHECK;
                connected = self.check_zenoh(connected);
            }
            let ops = {
                let mut core = lock(&self.core.0);
                while (core.outbox.is_empty() || core.putting)
                    && !self.shutdown.load(Ordering::Relaxed)
                    && self.clock.now() < next_check
                {
                    core = self
                        .core
                        .1
                        .wait_timeout(core, Duration::from_millis(50))
                        .map(|(g, _)| g)
                        .unwrap_or_else(|p| p.into_inner().0);
                }
                if core.putting
                    || (core.outbox.is_empty() && !self.shutdown.load(Ordering::Relaxed))
                {
                    continue; // time to check the session
                }
                if core.outbox.is_empty() {
                    return; // stopping, nothing left
                }
                let now = self.clock.now();
                let since = core.outbox.waiting_since();
                if let Some(since) = since {
                    core.timings
                        .handoff
                        .push(now.saturating_duration_since(since));
                }
                core.putting = true;
                core.io.handed_over += 1;
                (now, core.outbox.take(now))
            };
            self.apply(ops.0, ops.1);
        }
    }

    fn apply(&mut self, taken: Instant, ops: Vec<Op>) {
        let mut token_errors = 0;
        let mut samples = Vec::with_capacity(ops.len());
        let put = |samples| {
            put_samples(
                &self.session,
                &self.put_keys,
                &self.clock,
                taken,
                samples,
                &self.core.0,
            )
        };
        for op in ops {
            match op {
                sample @ (Op::Put(_) | Op::Talk(_)) => samples.push(sample),
                Op::Alive { robot, key, .. } => {
                    // Samples before a liveliness change go before it.
                    put(std::mem::take(&mut samples));
                    match self.session.liveliness().declare_token(key).wait() {
                        Ok(token) => {
                            if let Some(old) = self.tokens.insert(robot, token) {
                                let _ = old.undeclare().wait();
                            }
                        }
                        Err(e) => {
                            token_errors += 1;
                            tracing::warn!("liveliness token of robot {robot}: {e}");
                        }
                    }
                }
                Op::Gone { robot } => {
                    put(std::mem::take(&mut samples));
                    if let Some(token) = self.tokens.remove(&robot) {
                        if let Err(e) = token.undeclare().wait() {
                            token_errors += 1;
                            tracing::warn!("withdrawing robot {robot}'s token: {e}");
                        }
                    }
                }
            }
        }
        let slow = put(samples);
        let mut core = lock(&self.core.0);
        core.putting = false;
        core.io.token_errors += token_errors;
        if slow {
            core.slow_until = Some(self.clock.now() + SLOW_HOLD);
        }
    }
}

/// Whether Zenoh's TX runtime was configured (`ZENOH_RUNTIME` names `tx`, as the binary
/// sets it: two workers). With Zenoh's default single TX worker a fast-path put that
/// waits for a free batch would hold the one thread Zenoh's transmit task needs; a
/// program embedding [`Bridge`] without configuring it gets the hand-over path.
fn tx_runtime_configured() -> bool {
    let configured =
        std::env::var(zenoh_runtime::ZENOH_RUNTIME_ENV).is_ok_and(|v| v.contains("tx"));
    if !configured {
        tracing::info!(
            "ZENOH_RUNTIME does not configure Zenoh's TX runtime: every put goes through the \
             publisher thread (set it to '(tx: (worker_threads: 2))' for the fast path)"
        );
    }
    configured
}

/// Waits until the router has routed every put this session made before it: a `get` on
/// `…/@bridge/flush` that only the router can answer (no local queryable; the router never
/// routes a query back to its source, and nobody else serves that key). It travels on
/// the puts' priority queue and link, behind them; the router handles a link's messages
/// in order, pushing each put into its subscribers' queues (blocking as the puts asked)
/// before it sees the query and sends the final reply. So when the reply arrives the
/// bridge's own queue is empty and every put is past the router: closing the session then
/// loses nothing. Without the barrier the close wrote out Zenoh's queue with a per-batch
/// timeout, which a router blocked on a slow subscriber let run out (values lost in 4 of
/// 6 loaded runs). A router whose ACL denies the query (allow the bridge's subject
/// `query` ingress on `…/@bridge/flush`, docs/bridge.md) or that is gone makes the
/// barrier wait [`FLUSH_TIMEOUT`]; then the bridge closes anyway, and says so.
fn flush_barrier(session: &Session, keys: &TeamKeys, clock: Clock) -> bool {
    let t0 = clock.now();
    let replies = match session
        .get(keys.bridge("flush"))
        .allowed_destination(Locality::Remote)
        .consolidation(ConsolidationMode::None)
        .congestion_control(CongestionControl::Block)
        .timeout(FLUSH_TIMEOUT)
        .wait()
    {
        Ok(replies) => replies,
        Err(e) => {
            tracing::warn!("flush barrier not sent ({e}): closing without it");
            return false;
        }
    };
    let mut timed_out = false;
    // The channel closes at the router's final reply (or at the timeout, after an error
    // reply saying so).
    while let Ok(reply) = replies.recv() {
        if let Err(e) = reply.result() {
            timed_out |= e.payload().try_to_string().is_ok_and(|p| p == "Timeout");
        }
    }
    let took = clock.now().saturating_duration_since(t0);
    if timed_out {
        tracing::warn!(
            "flush barrier: no answer from the router within {FLUSH_TIMEOUT:?} (gone, or its ACL \
             denies this bridge a query on {}); closing: what Zenoh still queues may be lost",
            keys.bridge("flush")
        );
    } else {
        tracing::info!(
            "flush barrier: the router routed every put ({:.1} ms)",
            took.as_secs_f64() * 1e3
        );
    }
    !timed_out
}

/// Puts `ops` (values and talk messages, taken from the outbox at `taken`) in order,
/// with blocking congestion control (Zenoh drops nothing the outbox handed it; the outbox
/// merged what was superseded if Zenoh blocked it full). A lone sample goes express (not held
/// for a batch); under load Zenoh batches. Counts errors and the put times; returns
/// whether a put was slow.
fn put_samples(
    session: &Session,
    keys: &PutKeys,
    clock: &Clock,
    taken: Instant,
    ops: Vec<Op>,
    core: &Mutex<Core>,
) -> bool {
    if ops.is_empty() {
        return false;
    }
    let express = ops.len() == 1;
    let mut put_errors = 0;
    let mut puts = 0;
    let mut times = Vec::with_capacity(ops.len());
    for op in ops {
        let (Op::Put(sample) | Op::Talk(sample)) = op else {
            continue;
        };
        let t0 = clock.now();
        // Zenoh's timestamp first (the moment of publication, for a subscriber that wants
        // one; never the age's source), then the age brought up to this moment: the
        // time since `taken` (earlier puts of the batch) is added.
        let timestamp = session.new_timestamp();
        let sample = sample.aged(clock.now().saturating_duration_since(taken));
        match put(session, keys, sample, timestamp, express) {
            Ok(()) => puts += 1,
            Err(e) => {
                put_errors += 1;
                tracing::debug!("put: {e}");
            }
        }
        times.push(clock.now().saturating_duration_since(t0));
    }
    let mut core = lock(core);
    if core.io.put_errors == 0 && put_errors > 0 {
        tracing::warn!("zenoh refused a put (counted in @bridge/stats put_errors)");
    }
    core.io.put_errors += put_errors;
    core.io.puts += puts;
    let mut slow = false;
    for t in times {
        slow |= t > SLOW_PUT;
        core.io.put_us += t.as_micros() as u64;
        core.timings.put.push(t);
    }
    slow
}

fn put(
    session: &Session,
    keys: &PutKeys,
    sample: Sample,
    timestamp: zenoh::time::Timestamp,
    express: bool,
) -> zenoh::Result<()> {
    let attachment = sample.attachment();
    if let Some((key, cdr)) = sample.ros2 {
        session
            .put(keys.get(session, key)?, cdr)
            .encoding(Encoding::APPLICATION_CDR)
            .congestion_control(CongestionControl::Block)
            .express(express)
            .wait()?;
    }
    session
        .put(keys.get(session, sample.key)?, sample.payload)
        .encoding(Encoding::TEXT_PLAIN)
        .attachment(attachment)
        .timestamp(timestamp)
        .congestion_control(CongestionControl::Block)
        .express(express)
        .wait()
}

fn feed(core: &mut Core, now: Instant, from: SocketAddr, bytes: &[u8]) {
    core.advance(now);
    // The frame's header is read (and its tag checked) once more here for its clock
    // fields, without allocating; the replica decides what it applies, and counts what
    // it drops.
    if let Ok(frame) = comms::wire::decode_frame_with(
        bytes,
        core.team,
        core.team_key.as_ref(),
        comms::wire::KnownPaths::none(),
    ) {
        core.exporter.frame(now, Heard::from(&frame));
    }
    core.replica.handle_datagram(now, from, bytes);
    core.drain(now);
    core.exporter.frame_done();
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `auto` follows the session's configuration: the lowlatency transport (no transmit
    /// task; a put writes the link from the caller) gets the field side its own thread.
    #[test]
    fn the_lowlatency_transport_gets_the_field_side_its_own_thread() {
        let mut cfg = zenoh::Config::default();
        assert_eq!(FieldLoop::Auto.resolve(&cfg), FieldLoop::TxRuntime);
        cfg.insert_json5("transport/unicast/lowlatency", "true")
            .unwrap();
        cfg.insert_json5("transport/unicast/qos/enabled", "false")
            .unwrap();
        assert_eq!(FieldLoop::Auto.resolve(&cfg), FieldLoop::Thread);
        assert_eq!(
            FieldLoop::TxRuntime.resolve(&cfg),
            FieldLoop::TxRuntime,
            "an explicit --field-loop wins"
        );
    }
}
