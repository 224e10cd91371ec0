//! The replication state machine (sans-IO): one robot's blackboard plus everything needed
//! to keep the team's copies in step over a lossy multicast group.
//!
//! One type, [`Replica`], with its parts in files named for what they do:
//!
//! - `config.rs`: [`ReplicaConfig`], and [`ConfigInvalid`] for one that cannot work;
//! - `events.rs`: what comes out: [`Event`]s, and [`Transmit`]s with their [`Destination`];
//! - `receive.rs`: [`Replica::handle_datagram`]: a received frame checked and applied;
//! - `clock.rs`: shared time from the traffic: each teammate's clock estimated from the
//!   send stamps and echoes its frames carry, and from it each frame's transit;
//! - `peers.rs`: the peer table: joins, restarts (incarnations, the retired ones whose
//!   late frames are dropped) and the replay window of keyed teams;
//! - `talk.rs`: posting to own talk queues, delivering teammates' messages in order, NACK
//!   repair;
//! - `timers.rs`: [`Replica::handle_timeout`] and [`Replica::poll_timeout`]: the periodic
//!   refresh (and the extra one for a newcomer), departures, talk timers, the stats mirror;
//! - `transmit.rs`: [`Replica::poll_transmit`]: pending changes packed into frames
//!   within the MTU;
//! - this file: the state itself, writes and reads.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::atomic::AtomicU64;
use std::sync::Arc;
use std::time::Duration;

use crate::blackboard::{Applied, Blackboard, Entry, SetError, SlotId};
use crate::key::{Key, KeyError, KeyRef, Kind, Scope};
use crate::pattern::Pattern;
use crate::stats::Stats;
use crate::talk::{Delivery, Outbox};
use crate::time::Instant;
use crate::value::Value;
use crate::wire::{self, ItemRef, TeamKey};

mod budget;
mod clock;
mod config;
mod dirty;
mod events;
mod peers;
mod receive;
mod talk;
mod timers;
mod transmit;

pub use budget::{Budget, BudgetParseError, BudgetSpec, ExternalCap, FREE_GAP};
pub use config::{ConfigInvalid, ReplicaConfig};
pub use events::{Destination, Event, Transmit};
pub use peers::ordered_incarnation;
use peers::Peer;
pub use talk::PostError;

/// Where a changed binding is stored, from [`Replica::poll_event_at`] for
/// [`Replica::changed_entry`]; opaque.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChangeAt(SlotId);

/// One robot's replicated blackboard. See the crate docs for the run loop.
#[derive(Debug)]
pub struct Replica {
    cfg: ReplicaConfig,
    key: Option<TeamKey>,
    incarnation: u64,
    board: Blackboard,
    /// Latest `now` seen by any input: ages in outgoing frames are measured to it.
    now: Instant,
    seq: u64,
    next_refresh: Instant,
    /// When the last full refresh (periodic, or for a joining peer) was queued.
    last_full_refresh: Option<Instant>,
    heartbeat_due: bool,
    dirty: dirty::DirtyQueue,
    refresh_queue: VecDeque<String>,
    talk_out: VecDeque<(String, u64)>,
    heads_out: BTreeSet<String>,
    nacks_out: VecDeque<(u8, String, u64, u64)>,
    outboxes: BTreeMap<String, Outbox>,
    /// Bytes held in all talk reorder buffers (bounded by `talk.buffered_bytes_total`).
    talk_buffered: usize,
    /// When a frame with this robot's id and another incarnation was last reported.
    own_conflict_reported: Option<Instant>,
    peers: BTreeMap<u8, Peer>,
    /// Own recent frames (seq, send time), for teammates' echoes.
    sent: clock::SentLog,
    /// The transit of the latest frames whose transit was estimated (any teammate, a
    /// running mean, µs): what a frame from a teammate with no clock estimate yet (or
    /// any more: under a league's budget echoes are seconds apart) is taken to have
    /// had, rather than `default_transit`.
    transit_seen_us: Option<f64>,
    events: VecDeque<Event>,
    stats: Stats,
    /// Where `local.var.huddle.stats.*` are stored (see `timers::StatsMirror`).
    stats_mirror: timers::StatsMirror,
    deliveries: Vec<Delivery>,
    /// The message budget in use, if the configuration has one.
    budget: Option<budget::BudgetState>,
    /// Own global paths set with priority and not sent since.
    urgent: BTreeSet<Arc<str>>,
    /// Under a budget: frames that went with NACKs and re-sends only (at most half).
    repair_frames: u64,
    /// The paths of a frame's news, kept only while it is built (its capacity reused).
    sent_scratch: Vec<Arc<str>>,
    /// A received frame's items, kept only while it is applied (its capacity reused:
    /// see `receive::recycle`).
    item_scratch: Vec<wire::ItemView<'static>>,
    /// [`Replica::poll_timeout`]'s last answer in microseconds, or `timers::STALE` once
    /// an input may have changed what it reads (see `timers_may_change`). A driver asks
    /// it far more often than anything changes: the simulator's harness asks every
    /// replica twice per delivery to any one of them. An atomic, not a `Cell`, so that a
    /// `Replica` stays `Sync`; only `&mut self` paths clear it.
    timeout_cache: AtomicU64,
}

impl Replica {
    /// A replica for `config`, started at `now`. `incarnation` must differ between
    /// starts of the same robot (use a random number from the driver's RNG): it is how
    /// teammates tell a restart from old frames. The first frame goes out at once.
    pub fn new(
        config: ReplicaConfig,
        incarnation: u64,
        now: Instant,
    ) -> Result<Replica, ConfigInvalid> {
        config.validate()?;
        let config_budget = config.budget;
        let mut board = Blackboard::with_limits(config.robot_id, config.board_limits());
        board.set_incarnation(incarnation);
        board.advance_clock(now);
        Ok(Replica {
            key: config.team_key.as_deref().map(TeamKey::new),
            cfg: config,
            incarnation,
            board,
            now,
            seq: 0,
            next_refresh: now,
            last_full_refresh: None,
            heartbeat_due: false,
            dirty: dirty::DirtyQueue::default(),
            refresh_queue: VecDeque::new(),
            talk_out: VecDeque::new(),
            heads_out: BTreeSet::new(),
            nacks_out: VecDeque::new(),
            outboxes: BTreeMap::new(),
            talk_buffered: 0,
            own_conflict_reported: None,
            peers: BTreeMap::new(),
            sent: clock::SentLog::default(),
            transit_seen_us: None,
            events: VecDeque::new(),
            stats: Stats::default(),
            stats_mirror: timers::StatsMirror::default(),
            deliveries: Vec::new(),
            budget: config_budget.map(|b| budget::BudgetState::new(b, now)),
            urgent: BTreeSet::new(),
            repair_frames: 0,
            sent_scratch: Vec::new(),
            item_scratch: Vec::new(),
            timeout_cache: AtomicU64::new(timers::STALE),
        })
    }

    /// This robot's id.
    pub fn robot_id(&self) -> u8 {
        self.cfg.robot_id
    }

    /// This start's incarnation.
    pub fn incarnation(&self) -> u64 {
        self.incarnation
    }

    /// The latest `now` any input has brought.
    pub fn now(&self) -> Instant {
        self.now
    }

    /// Whether `bytes` carry this replica's own plain header (team, id and incarnation):
    /// a frame of its own looped back, which [`Replica::handle_datagram`] counts and skips
    /// unread. A driver need not read its clock for one (`now()` serves).
    pub fn is_own_frame(&self, bytes: &[u8]) -> bool {
        wire::peek_origin(bytes, self.cfg.team_id) == Some((self.cfg.robot_id, self.incarnation))
    }

    /// The configuration.
    pub fn config(&self) -> &ReplicaConfig {
        &self.cfg
    }

    /// The blackboard, read-only.
    pub fn blackboard(&self) -> &Blackboard {
        &self.board
    }

    fn advance(&mut self, now: Instant) {
        self.timers_may_change();
        self.now = self.now.max(now);
        self.board.advance_clock(now);
        self.note_team_frames();
    }

    /// Applies one received update (stamped on this robot's clock) and counts it.
    pub(super) fn apply_update(
        &mut self,
        sender: u8,
        incarnation: u64,
        path: &str,
        value: Value,
        version: u64,
        stamp: Instant,
    ) {
        match self
            .board
            .apply_remote_path(sender, incarnation, path, value, version, stamp)
        {
            Applied::Stale => self.stats.updates_stale += 1,
            Applied::Refused => {}
            Applied::Inserted | Applied::Changed | Applied::Refreshed => {
                self.stats.updates_applied += 1
            }
        }
        self.sync_board_counts();
    }

    /// Copies what the blackboard's bounds did into the stats.
    pub(super) fn sync_board_counts(&mut self) {
        let c = self.board.counts();
        let s = &mut self.stats;
        s.updates_refused = c.refused;
        s.updates_unconfirmed_replaced = c.unconfirmed_replaced;
        s.bindings_superseded = c.superseded;
        s.bindings_released = c.released;
    }

    /// Whether robot `robot` was heard and is now departed (silent for longer than
    /// `departed_after`). Its values are still stored until
    /// `release_departed_after` has passed.
    pub fn is_departed(&self, robot: u8) -> bool {
        self.peers.get(&robot).is_some_and(|p| !p.present)
    }

    /// Sets `key` (`local.var.x`, `*.var.x` or `<own id>.var.x`) at `now`. Global
    /// values go out with the next [`Replica::poll_transmit`].
    pub fn set(&mut self, now: Instant, key: &str, value: Value) -> Result<(), SetError> {
        // Parsed in place: a write of a key already held copies no string.
        self.set_parts(now, KeyRef::parse(key)?, value).map(drop)
    }

    /// [`Replica::set`] with a parsed key.
    pub fn set_key(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), SetError> {
        self.set_parts(now, key.as_parts(), value).map(drop)
    }

    /// [`Replica::set_key`] for a value built at `built`, before `now` (a snapshot written
    /// late: a tick's world model riding along a claim decided between ticks). Its binding
    /// is stamped at `built` (never after `now`), so the age it carries on the wire, and
    /// every receiver's stamp, are its build time's: a receiver places it where it holds,
    /// not up to a control period later. Costs no byte: the age field is there anyway
    /// (a varint: one more byte at most when the age crosses 16.4 ms; a frame's fit is
    /// checked at the widest age).
    pub fn set_key_built(
        &mut self,
        now: Instant,
        key: &Key,
        value: Value,
        built: Instant,
    ) -> Result<(), SetError> {
        let slot = self.set_parts(now, key.as_parts(), value)?;
        if built < now {
            self.board.restamp(slot, built);
        }
        Ok(())
    }

    /// Writes `key`; returns the slot it is stored in.
    fn set_parts(
        &mut self,
        now: Instant,
        key: KeyRef<'_>,
        value: Value,
    ) -> Result<SlotId, SetError> {
        self.timers_may_change();
        self.advance(now);
        let scope = self.board.storage_scope(key)?;
        let global = scope != Scope::Local;
        if global {
            let (version, age_us) = self.widest_version_and_age();
            let item = ItemRef::Update {
                path: key.path,
                value: &value,
                version,
                age_us,
            };
            let room = self.cfg.mtu.saturating_sub(self.frame_overhead());
            // With its path spelled out the item is at least as long as with an index:
            // if that fits, the known-path table need not be searched.
            let bytes = match wire::item_len(item) {
                n if n <= room => n,
                _ => wire::item_len_coded(item, self.known_paths()),
            };
            if bytes > room {
                return Err(SetError::TooLarge {
                    key: key.to_string(),
                    bytes,
                    mtu: self.cfg.mtu,
                });
            }
        }
        let slot = self.board.write(now, key, value)?;
        if global {
            if let Some(path) = self.board.shared_path(slot) {
                self.dirty.insert(path, slot);
            }
        }
        Ok(slot)
    }

    /// [`Replica::set_key`] for an item that must not wait for the budget's pacing (a
    /// goer change, a kick, a referee event): the next frame draws on the budget's reserve
    /// if the ordinary allowance is not open. Without a budget it is `set_key`.
    pub fn set_priority(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), SetError> {
        self.set_key(now, key, value)?;
        if self.budget.is_some() && key.scope() != Scope::Local {
            self.urgent.insert(Arc::from(key.path()));
        }
        Ok(())
    }

    /// Play restarts from a set piece at which every robot's claim changes at once (a
    /// kick-off: call it when the GameController's Set is heard): a pooled budget gives
    /// the team's priority frames their room afresh from the team's count at `now`,
    /// wherever its pacing line is (see [`Budget`]). Without a pooled budget it is
    /// ignored.
    pub fn restart_priority_room(&mut self, now: Instant) {
        self.advance(now);
        if let Some(b) = &mut self.budget {
            b.restart();
        }
    }

    /// The game clock: at `now`, `remaining` of play are left (the GameController's
    /// remaining time). The budget paces over it; without a budget it is ignored.
    pub fn set_game_clock(&mut self, now: Instant, remaining: Duration) {
        self.timers_may_change();
        if let Some(b) = &mut self.budget {
            b.set_clock(now, remaining);
        }
    }

    /// The league's referee system's figures for the team's budget, the authority over
    /// this replica's own accounting (see [`ExternalCap`]); `None` goes back to the
    /// replica's own. Without a budget it is ignored.
    pub fn set_external_budget(&mut self, cap: Option<ExternalCap>) {
        self.timers_may_change();
        // The teammates' frames heard so far are in the figure's "before".
        let heard = self.peers.values().map(Peer::frames_sent).sum();
        if let Some(b) = &mut self.budget {
            b.set_heard(heard);
            b.set_external(cap);
        }
    }

    /// Whether the referee system's figures are in force ([`Replica::set_external_budget`]
    /// gave one, and no `None` since).
    pub fn has_external_budget(&self) -> bool {
        self.budget.as_ref().is_some_and(|b| b.has_external())
    }

    /// Whether this robot's value at `key` changed and waits for a frame (a budget's
    /// pacing holds it): a caller that wants the newest value to go, not the one it had
    /// when it decided to send, sets it again until this is false.
    pub fn is_pending(&self, key: &Key) -> bool {
        self.dirty.contains(key.path())
    }

    /// With a budget: ordinary frames its pacing would let go now before it holds one
    /// back (negative while it holds frames back); see [`Budget`].
    pub fn budget_headroom(&self) -> Option<i64> {
        self.budget.as_ref().map(|b| b.headroom(self.now))
    }

    /// Tells a pooled budget, or one under an external cap (whose figure the teammates'
    /// frames since use up), how many frames teammates have sent. Pooled, of every id
    /// heard only the `robots - 1` that count most (a team of `robots` has no more
    /// teammates, so frames forged under 250 other ids count as at most that many).
    fn note_team_frames(&mut self) {
        if let Some(b) = &mut self.budget {
            let pooled = b.budget.team;
            if pooled.is_some() || b.has_external() {
                let mut counts: Vec<u64> = self.peers.values().map(Peer::frames_sent).collect();
                if let Some(team) = pooled {
                    let teammates = usize::try_from(team.robots.saturating_sub(1)).unwrap_or(0);
                    if counts.len() > teammates {
                        counts.select_nth_unstable_by(teammates, |a, b| b.cmp(a));
                        counts.truncate(teammates);
                    }
                }
                b.set_heard(counts.iter().fold(0u64, |a, &c| a.saturating_add(c)));
            }
        }
    }

    /// With a budget: messages this robot sent so far, and messages left (its own, or
    /// with a pooled budget the team's as far as this robot has heard).
    pub fn budget_status(&self) -> Option<(u64, u64)> {
        self.budget.as_ref().map(|b| (b.sent(), b.left()))
    }

    /// The binding for `key` (see [`Blackboard::get`]; `*.var.x` is the newest copy).
    pub fn get(&self, key: &str) -> Result<Option<&Entry>, KeyError> {
        Ok(self.board.get(&Key::parse(key)?))
    }

    /// [`Replica::get`], only if at most `max_age` old at `now` by this robot's stamps.
    pub fn get_fresher(
        &self,
        now: Instant,
        key: &str,
        max_age: Duration,
    ) -> Result<Option<&Entry>, KeyError> {
        Ok(self.board.get_fresher_than(now, &Key::parse(key)?, max_age))
    }

    /// Every stored binding matching `pattern`, in key order.
    pub fn iter<'a>(&'a self, pattern: &'a Pattern) -> impl Iterator<Item = (Key, &'a Entry)> + 'a {
        self.board.iter(pattern)
    }

    /// The counters.
    pub fn stats(&self) -> &Stats {
        &self.stats
    }

    /// The next event, oldest first (value changes after the other events).
    pub fn poll_event(&mut self) -> Option<Event> {
        self.poll_event_at().map(|(event, _)| event)
    }

    /// [`Replica::poll_event`], and for an [`Event::ValueChanged`] where the binding is
    /// stored: [`Replica::changed_entry`] reads it from there without a lookup (a driver
    /// telling its listeners reads every change it matches).
    pub fn poll_event_at(&mut self) -> Option<(Event, Option<ChangeAt>)> {
        if let Some(e) = self.events.pop_front() {
            return Some((e, None));
        }
        self.board
            .poll_change_at()
            .map(|(key, slot)| (Event::ValueChanged { key }, Some(ChangeAt(slot))))
    }

    /// The binding a change polled with [`Replica::poll_event_at`] is about, as it is now:
    /// what `blackboard().get(key)` returns, read from the slot `at` while that still
    /// holds it (else looked up).
    pub fn changed_entry(&self, key: &Key, at: ChangeAt) -> Option<&Entry> {
        match key.kind() {
            Kind::Var => self.board.get_at(at.0, key.scope(), key.shared_path()),
            Kind::Talk => None,
        }
    }
}

#[cfg(test)]
mod bounds_tests;
#[cfg(test)]
mod clock_tests;
#[cfg(test)]
mod nack_tests;
#[cfg(test)]
mod tests;
#[cfg(test)]
mod timer_cache_tests;
