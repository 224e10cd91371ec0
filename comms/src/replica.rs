//! The replication state machine (sans-IO): one robot's blackboard plus everything needed
//! to keep the team's copies in step over a lossy multicast group.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::net::SocketAddr;
use std::time::Duration;

use thiserror::Error;

use crate::blackboard::{Applied, Blackboard, Entry, SetError};
use crate::key::{Key, KeyError, Kind, Scope, ROBOT_IDS};
use crate::pattern::Pattern;
use crate::stats::{DropReason, PeerInfo, Stats};
use crate::talk::{Delivery, Inbox, Outbox, TalkLimits};
use crate::time::{duration_to_micros, Instant};
use crate::value::Value;
use crate::wire::{
    self, FrameWriter, Item, ItemRef, TeamKey, HEADER_LEN, MAX_FRAME_LEN, MIN_MTU, TAG_LEN,
};

/// How many of a peer's past incarnations are remembered (their late frames are dropped).
const RETIRED_INCARNATIONS: usize = 8;

/// Settings of a replica. Every robot of a team should use the same `team_id`,
/// `refresh_period`, `mtu` and `team_key`.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplicaConfig {
    /// This robot's id, 1..=254.
    pub robot_id: u8,
    /// The team's id; frames of other teams are dropped.
    pub team_id: u8,
    /// Every own global value is re-sent this often (default 100 ms), repairing losses;
    /// it is also the heartbeat period.
    pub refresh_period: Duration,
    /// Largest frame sent and accepted, in bytes (default 1200; 64..=65507).
    pub mtu: usize,
    /// A peer silent this long is reported departed (default 3 refresh periods).
    pub departed_after: Duration,
    /// With a key, every frame carries a truncated HMAC-SHA256 tag, untagged, badly
    /// tagged and replayed frames are dropped.
    pub team_key: Option<Vec<u8>>,
    /// Talk queue limits and timers.
    pub talk: TalkLimits,
}

impl ReplicaConfig {
    /// Defaults for robot `robot_id` of team `team_id`.
    pub fn new(robot_id: u8, team_id: u8) -> ReplicaConfig {
        ReplicaConfig {
            robot_id,
            team_id,
            refresh_period: Duration::from_millis(100),
            mtu: 1200,
            departed_after: Duration::from_millis(300),
            team_key: None,
            talk: TalkLimits::default(),
        }
    }

    /// Sets the refresh period and, with it, `departed_after` to three periods.
    pub fn with_refresh_period(mut self, period: Duration) -> ReplicaConfig {
        self.refresh_period = period;
        self.departed_after = period * 3;
        self
    }

    /// Sets the team key.
    pub fn with_team_key(mut self, key: impl Into<Vec<u8>>) -> ReplicaConfig {
        self.team_key = Some(key.into());
        self
    }
}

/// Why a [`ReplicaConfig`] was refused.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum ConfigInvalid {
    /// `robot_id` outside 1..=254.
    #[error("robot id {0} is outside 1..=254")]
    RobotId(u8),
    /// `mtu` outside [`wire::MIN_MTU`]..=[`wire::MAX_FRAME_LEN`].
    #[error("mtu {0} is outside {MIN_MTU}..={MAX_FRAME_LEN} bytes")]
    Mtu(usize),
    /// A zero refresh period or departure limit.
    #[error("refresh period and departure limit must be positive")]
    Period,
    /// Talk limits of zero.
    #[error("talk retain, window and max_queues must be at least 1")]
    TalkLimits,
}

/// Why a talk message was refused.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum PostError {
    /// The key does not parse.
    #[error(transparent)]
    Key(#[from] KeyError),
    /// Only `*.talk.<queue>` (or this robot's own `n.talk.<queue>`) can be posted to.
    #[error("{0} is not a talk queue of this robot (post to *.talk.<queue>)")]
    NotOwnQueue(String),
    /// The message would not fit in one frame.
    #[error("{key}: the message takes {bytes} bytes, more than one frame holds ({mtu} byte MTU)")]
    TooLarge {
        /// The key as given.
        key: String,
        /// Encoded item size.
        bytes: usize,
        /// Configured MTU.
        mtu: usize,
    },
    /// This robot already has `talk.max_queues` queues.
    #[error("too many talk queues (limit {0})")]
    TooManyQueues(usize),
}

/// Where a [`Transmit`] goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum Destination {
    /// The team's multicast group (every frame today: repairs help every receiver).
    Group,
}

/// A datagram to send.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Transmit {
    /// Where to.
    pub destination: Destination,
    /// The frame, at most `mtu` bytes.
    pub payload: Vec<u8>,
}

/// Something the application may want to react to.
#[derive(Clone, Debug, PartialEq)]
pub enum Event {
    /// A stored value was inserted or changed (read it with [`Replica::get`]).
    /// Coalesced per key until drained; a refresh with the same value is no change.
    ValueChanged {
        /// The key as stored: `local.var.x` or `n.var.x`.
        key: Key,
    },
    /// The next message of a teammate's talk queue.
    TalkDelivered {
        /// Queue path (`plan` for `n.talk.plan`).
        queue: String,
        /// The sender.
        from: u8,
        /// Its sequence number (per queue and sender incarnation, from 1).
        seq: u64,
        /// The message.
        value: Value,
    },
    /// Messages `first..=last` of a teammate's queue could not be recovered.
    TalkGivenUp {
        /// Queue path.
        queue: String,
        /// The sender.
        from: u8,
        /// First lost sequence number.
        first: u64,
        /// Last lost sequence number.
        last: u64,
    },
    /// A robot was heard for the first time, or again after departing.
    PeerJoined {
        /// Its id.
        robot: u8,
        /// Its incarnation.
        incarnation: u64,
    },
    /// A robot came back with a new incarnation: its values replace the old ones at once.
    PeerRestarted {
        /// Its id.
        robot: u8,
        /// The incarnation it had.
        old_incarnation: u64,
        /// The one it has now.
        new_incarnation: u64,
    },
    /// A robot was silent for longer than `departed_after`. Its values stay stored (and
    /// age); arbitration should ignore stale values by their stamps.
    PeerDeparted {
        /// Its id.
        robot: u8,
    },
    /// A datagram was dropped (also counted in [`Stats`]).
    FrameDropped {
        /// Its source address.
        from: SocketAddr,
        /// Why.
        reason: DropReason,
    },
}

/// Replay protection: the highest sequence number seen and a 64-frame window below it.
#[derive(Debug, Default)]
struct ReplayWindow {
    highest: u64,
    seen: u64,
}

impl ReplayWindow {
    fn accept(&mut self, seq: u64) -> bool {
        if seq > self.highest {
            let shift = seq - self.highest;
            self.seen = if shift >= 64 { 0 } else { self.seen << shift };
            self.seen |= 1;
            self.highest = seq;
            return true;
        }
        let back = self.highest - seq;
        if back >= 64 || self.seen & (1 << back) != 0 {
            return false;
        }
        self.seen |= 1 << back;
        true
    }
}

#[derive(Debug)]
struct Peer {
    incarnation: u64,
    retired: VecDeque<u64>,
    last_heard: Instant,
    present: bool,
    frames: u64,
    replay: ReplayWindow,
    inboxes: BTreeMap<String, Inbox>,
}

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
    dirty: BTreeSet<String>,
    refresh_queue: VecDeque<String>,
    talk_out: VecDeque<(String, u64)>,
    heads_out: BTreeSet<String>,
    nacks_out: VecDeque<(u8, String, u64, u64)>,
    outboxes: BTreeMap<String, Outbox>,
    peers: BTreeMap<u8, Peer>,
    events: VecDeque<Event>,
    stats: Stats,
    deliveries: Vec<Delivery>,
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
        if !ROBOT_IDS.contains(&config.robot_id) {
            return Err(ConfigInvalid::RobotId(config.robot_id));
        }
        if !(MIN_MTU..=MAX_FRAME_LEN).contains(&config.mtu) {
            return Err(ConfigInvalid::Mtu(config.mtu));
        }
        if config.refresh_period.is_zero() || config.departed_after.is_zero() {
            return Err(ConfigInvalid::Period);
        }
        let t = &config.talk;
        if t.retain == 0 || t.window == 0 || t.max_queues == 0 {
            return Err(ConfigInvalid::TalkLimits);
        }
        let mut board = Blackboard::new(config.robot_id);
        board.set_incarnation(incarnation);
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
            dirty: BTreeSet::new(),
            refresh_queue: VecDeque::new(),
            talk_out: VecDeque::new(),
            heads_out: BTreeSet::new(),
            nacks_out: VecDeque::new(),
            outboxes: BTreeMap::new(),
            peers: BTreeMap::new(),
            events: VecDeque::new(),
            stats: Stats::default(),
            deliveries: Vec::new(),
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

    /// The configuration.
    pub fn config(&self) -> &ReplicaConfig {
        &self.cfg
    }

    /// The blackboard, read-only.
    pub fn blackboard(&self) -> &Blackboard {
        &self.board
    }

    fn advance(&mut self, now: Instant) {
        self.now = self.now.max(now);
    }

    /// Bytes a frame spends besides its items, at worst.
    fn frame_overhead(&self) -> usize {
        HEADER_LEN + 9 + 3 + if self.key.is_some() { TAG_LEN } else { 0 }
    }

    /// Sets `key` (`local.var.x`, `*.var.x` or `<own id>.var.x`) at `now`. Global
    /// values go out with the next [`Replica::poll_transmit`].
    pub fn set(&mut self, now: Instant, key: &str, value: Value) -> Result<(), SetError> {
        let key = Key::parse(key)?;
        self.set_key(now, &key, value)
    }

    /// [`Replica::set`] with a parsed key.
    pub fn set_key(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), SetError> {
        self.advance(now);
        let scope = self.board.storage_scope(key)?;
        let global = scope != Scope::Local;
        if global {
            let bytes = wire::item_len(ItemRef::Update {
                path: key.path(),
                value: &value,
                version: u64::MAX,
                age_us: u64::MAX,
            });
            if bytes + self.frame_overhead() > self.cfg.mtu {
                return Err(SetError::TooLarge {
                    key: key.to_string(),
                    bytes,
                    mtu: self.cfg.mtu,
                });
            }
        }
        self.board.write(now, key, value)?;
        if global {
            self.dirty.insert(key.path().to_owned());
        }
        Ok(())
    }

    /// Posts a message to this robot's queue `*.talk.<queue>`; every teammate receives
    /// it once, in order, as [`Event::TalkDelivered`] (this robot does not). Returns its
    /// sequence number.
    pub fn post(&mut self, now: Instant, key: &str, value: Value) -> Result<u64, PostError> {
        self.advance(now);
        let key = Key::parse(key)?;
        let own =
            matches!(key.scope(), Scope::Global) || key.scope() == Scope::Robot(self.cfg.robot_id);
        if key.kind() != Kind::Talk || !own {
            return Err(PostError::NotOwnQueue(key.to_string()));
        }
        let bytes = wire::item_len(ItemRef::Talk {
            queue: key.path(),
            seq: u64::MAX,
            value: &value,
        });
        if bytes + self.frame_overhead() > self.cfg.mtu {
            return Err(PostError::TooLarge {
                key: key.to_string(),
                bytes,
                mtu: self.cfg.mtu,
            });
        }
        if !self.outboxes.contains_key(key.path())
            && self.outboxes.len() >= self.cfg.talk.max_queues
        {
            return Err(PostError::TooManyQueues(self.cfg.talk.max_queues));
        }
        let outbox = self.outboxes.entry(key.path().to_owned()).or_default();
        let seq = outbox.post(value, self.cfg.talk.retain);
        self.talk_out.push_back((key.path().to_owned(), seq));
        Ok(seq)
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

    /// Every robot heard so far.
    pub fn peers(&self) -> impl Iterator<Item = PeerInfo> + '_ {
        self.peers.iter().map(|(&robot, p)| PeerInfo {
            robot,
            incarnation: p.incarnation,
            last_heard: p.last_heard,
            present: p.present,
            frames: p.frames,
        })
    }

    fn drop_frame(&mut self, from: SocketAddr, reason: DropReason) {
        self.stats.count_drop(reason);
        self.events.push_back(Event::FrameDropped { from, reason });
    }

    /// Feeds one received datagram. Never panics; anything wrong with it is a counted
    /// drop and an [`Event::FrameDropped`], and nothing stored is lost.
    pub fn handle_datagram(&mut self, now: Instant, from: SocketAddr, bytes: &[u8]) {
        self.advance(now);
        self.stats.frames_in += 1;
        self.stats.bytes_in += bytes.len() as u64;
        if bytes.len() > self.cfg.mtu {
            return self.drop_frame(from, DropReason::Oversized);
        }
        // Our own frame, looped back by the kernel (every frame we send comes back): the
        // plain header names its sender, so it is skipped before the body is decoded or
        // the tag checked. A forged copy of our own header is ignored the same way, which
        // is all a checked one would get.
        if wire::peek_origin(bytes, self.cfg.team_id) == Some((self.cfg.robot_id, self.incarnation))
        {
            self.stats.own_frames += 1;
            return;
        }
        let frame = match wire::decode_frame(bytes, self.cfg.team_id, self.key.as_ref()) {
            Ok(frame) => frame,
            Err(e) => return self.drop_frame(from, DropReason::from(&e)),
        };
        let sender = frame.sender;
        if sender == self.cfg.robot_id {
            if frame.incarnation == self.incarnation {
                self.stats.own_frames += 1;
                return;
            }
            return self.drop_frame(from, DropReason::RobotIdConflict);
        }
        if let Err(reason) = self.admit(now, sender, frame.incarnation, frame.seq) {
            return self.drop_frame(from, reason);
        }
        let limits = self.cfg.talk.clone();
        for item in frame.items {
            match item {
                Item::Update {
                    path,
                    value,
                    version,
                    age_us,
                } => {
                    let stamp = now.saturating_sub(Duration::from_micros(age_us));
                    match self.board.apply_remote_path(
                        sender,
                        frame.incarnation,
                        &path,
                        value,
                        version,
                        stamp,
                    ) {
                        Applied::Stale => self.stats.updates_stale += 1,
                        _ => self.stats.updates_applied += 1,
                    }
                }
                Item::Talk { queue, seq, value } => {
                    let mut out = std::mem::take(&mut self.deliveries);
                    if let Some(inbox) = self.inbox(sender, &queue) {
                        inbox.on_message(now, seq, value, &limits, &mut out);
                    }
                    self.hand_up(sender, &queue, &mut out);
                    self.deliveries = out;
                }
                Item::TalkHead { queue, first, last } => {
                    let mut out = std::mem::take(&mut self.deliveries);
                    if let Some(inbox) = self.inbox(sender, &queue) {
                        inbox.on_head(now, first, last, &limits, &mut out);
                    }
                    self.hand_up(sender, &queue, &mut out);
                    self.deliveries = out;
                }
                Item::Nack {
                    target,
                    queue,
                    first,
                    last,
                } if target == self.cfg.robot_id => self.repair(now, &queue, first, last),
                Item::Nack { .. } => {}
            }
        }
    }

    /// Peer bookkeeping for a valid frame: join, restart, replay check.
    fn admit(
        &mut self,
        now: Instant,
        sender: u8,
        incarnation: u64,
        seq: u64,
    ) -> Result<(), DropReason> {
        let keyed = self.key.is_some();
        let mut joined = true;
        let peer = match self.peers.get_mut(&sender) {
            None => {
                self.events.push_back(Event::PeerJoined {
                    robot: sender,
                    incarnation,
                });
                self.peers.entry(sender).or_insert(Peer {
                    incarnation,
                    retired: VecDeque::new(),
                    last_heard: now,
                    present: true,
                    frames: 0,
                    replay: ReplayWindow::default(),
                    inboxes: BTreeMap::new(),
                })
            }
            Some(peer) if peer.incarnation != incarnation => {
                if peer.retired.contains(&incarnation) {
                    return Err(DropReason::RetiredIncarnation);
                }
                let old = std::mem::replace(&mut peer.incarnation, incarnation);
                peer.retired.push_back(old);
                if peer.retired.len() > RETIRED_INCARNATIONS {
                    peer.retired.pop_front();
                }
                peer.replay = ReplayWindow::default();
                peer.present = true;
                // The old incarnation's queues can no longer be repaired.
                for (queue, mut inbox) in std::mem::take(&mut peer.inboxes) {
                    inbox.flush(&mut self.deliveries);
                    Self::hand_up_into(
                        &mut self.events,
                        &mut self.stats,
                        &mut self.deliveries,
                        sender,
                        &queue,
                    );
                }
                self.events.push_back(Event::PeerRestarted {
                    robot: sender,
                    old_incarnation: old,
                    new_incarnation: incarnation,
                });
                peer
            }
            Some(peer) => {
                joined = !peer.present;
                if joined {
                    peer.present = true;
                    self.events.push_back(Event::PeerJoined {
                        robot: sender,
                        incarnation,
                    });
                }
                peer
            }
        };
        if keyed && !peer.replay.accept(seq) {
            return Err(DropReason::Replay);
        }
        peer.last_heard = now;
        peer.frames += 1;
        self.stats.last_heard.insert(sender, now);
        if joined {
            self.refresh_for_newcomer(now);
        }
        Ok(())
    }

    /// A robot appeared, came back after departing, or restarted: it may have missed
    /// (or lost) everything we own, so it gets a full refresh and our talk heads now
    /// instead of up to a refresh period later. The periodic schedule is untouched, so
    /// this is an extra copy, which on a lossy network is also an extra chance. At most
    /// one per quarter period: a refresh that recent reaches the newcomer as well when
    /// several robots come back at once (after a team-wide outage).
    fn refresh_for_newcomer(&mut self, now: Instant) {
        let quiet = self.cfg.refresh_period / 4;
        if self.last_full_refresh.is_none_or(|t| t + quiet <= now) {
            self.queue_full_refresh(now);
        }
    }

    /// Queues every own global value and every own talk head, and a heartbeat.
    fn queue_full_refresh(&mut self, now: Instant) {
        let own = Scope::Robot(self.cfg.robot_id);
        self.refresh_queue = self
            .board
            .scope_entries(own)
            .map(|(p, _)| p.clone())
            .collect();
        self.heads_out.extend(self.outboxes.keys().cloned());
        self.heartbeat_due = true;
        self.last_full_refresh = Some(now);
    }

    fn inbox(&mut self, sender: u8, queue: &str) -> Option<&mut Inbox> {
        let max = self.cfg.talk.max_queues;
        let peer = self.peers.get_mut(&sender)?;
        if !peer.inboxes.contains_key(queue) {
            if peer.inboxes.len() >= max {
                self.stats.talk_queue_overflow += 1;
                return None;
            }
            peer.inboxes.insert(queue.to_owned(), Inbox::default());
        }
        peer.inboxes.get_mut(queue)
    }

    fn hand_up(&mut self, sender: u8, queue: &str, out: &mut Vec<Delivery>) {
        Self::hand_up_into(&mut self.events, &mut self.stats, out, sender, queue);
    }

    fn hand_up_into(
        events: &mut VecDeque<Event>,
        stats: &mut Stats,
        deliveries: &mut Vec<Delivery>,
        from: u8,
        queue: &str,
    ) {
        for d in deliveries.drain(..) {
            events.push_back(match d {
                Delivery::Message { seq, value } => {
                    stats.talk_delivered += 1;
                    Event::TalkDelivered {
                        queue: queue.to_owned(),
                        from,
                        seq,
                        value,
                    }
                }
                Delivery::GivenUp { first, last } => {
                    stats.talk_given_up = stats.talk_given_up.saturating_add(last - first + 1);
                    Event::TalkGivenUp {
                        queue: queue.to_owned(),
                        from,
                        first,
                        last,
                    }
                }
            });
        }
    }

    /// A teammate asked for `first..=last` of our queue.
    fn repair(&mut self, now: Instant, queue: &str, first: u64, last: u64) {
        let Some(outbox) = self.outboxes.get_mut(queue) else {
            return;
        };
        // A resend within half a NACK interval already answers this request.
        let quiet = self.cfg.talk.nack_interval / 2;
        for seq in outbox.to_resend(first, last, now, quiet) {
            outbox.mark_sent(seq, now);
            self.talk_out.push_back((queue.to_owned(), seq));
            self.stats.talk_resent += 1;
        }
        if first < outbox.first() || last > outbox.last() {
            // Some of it is gone (or never existed): the head tells them to give up.
            self.heads_out.insert(queue.to_owned());
        }
    }

    /// Runs timers due at `now`: the periodic refresh and heartbeat, departures, NACKs
    /// and talk give-ups. Call it when [`Replica::poll_timeout`] is reached (calling it
    /// earlier is harmless).
    pub fn handle_timeout(&mut self, now: Instant) {
        self.advance(now);
        if now >= self.next_refresh {
            self.next_refresh += self.cfg.refresh_period;
            if self.next_refresh <= now {
                self.next_refresh = now + self.cfg.refresh_period;
            }
            self.queue_full_refresh(now);
            self.mirror_stats(now);
        }
        let limits = self.cfg.talk.clone();
        let departed_after = self.cfg.departed_after;
        let mut nacks = Vec::new();
        let mut handed = Vec::new();
        for (&robot, peer) in &mut self.peers {
            if peer.present && peer.last_heard + departed_after <= now {
                peer.present = false;
                self.events.push_back(Event::PeerDeparted { robot });
            }
            for (queue, inbox) in &mut peer.inboxes {
                for (first, last) in inbox.on_timeout(now, &limits, &mut self.deliveries) {
                    nacks.push((robot, queue.clone(), first, last));
                }
                if !self.deliveries.is_empty() {
                    handed.push((robot, queue.clone(), std::mem::take(&mut self.deliveries)));
                }
            }
        }
        for (robot, queue, mut d) in handed {
            Self::hand_up_into(&mut self.events, &mut self.stats, &mut d, robot, &queue);
        }
        self.stats.nacks_sent += nacks.len() as u64;
        self.nacks_out.extend(nacks);
    }

    /// Mirrors the counters into `local.var.huddle.stats.*`.
    fn mirror_stats(&mut self, now: Instant) {
        let s = &self.stats;
        let mut values: Vec<(String, i64)> = vec![
            ("frames_in".into(), s.frames_in as i64),
            ("frames_out".into(), s.frames_out as i64),
            ("bytes_in".into(), s.bytes_in as i64),
            ("bytes_out".into(), s.bytes_out as i64),
            ("updates_applied".into(), s.updates_applied as i64),
            ("updates_stale".into(), s.updates_stale as i64),
            ("talk_delivered".into(), s.talk_delivered as i64),
            ("talk_given_up".into(), s.talk_given_up as i64),
            ("talk_resent".into(), s.talk_resent as i64),
            ("nacks_sent".into(), s.nacks_sent as i64),
            ("drops.total".into(), s.drops_total() as i64),
        ];
        values.extend(
            DropReason::ALL
                .iter()
                .map(|r| (format!("drops.{}", r.name()), s.drops(*r) as i64)),
        );
        values.extend(
            s.last_heard
                .iter()
                .map(|(robot, t)| (format!("peer.{robot}.last_heard_us"), t.as_micros() as i64)),
        );
        for (name, v) in values {
            let key =
                Key::from_valid_parts(Scope::Local, Kind::Var, format!("huddle.stats.{name}"));
            let unchanged = self
                .board
                .get(&key)
                .is_some_and(|e| e.value == Value::Int(v));
            if !unchanged {
                // A local key of valid shape: this cannot fail.
                let _ = self.board.set(now, &key, Value::Int(v));
            }
        }
    }

    /// When [`Replica::handle_timeout`] should next be called.
    pub fn poll_timeout(&self) -> Option<Instant> {
        let limits = &self.cfg.talk;
        let mut next = self.next_refresh;
        for peer in self.peers.values() {
            if peer.present {
                next = next.min(peer.last_heard + self.cfg.departed_after);
            }
            for inbox in peer.inboxes.values() {
                if let Some(t) = inbox.deadline(limits) {
                    next = next.min(t);
                }
            }
        }
        Some(next)
    }

    /// The next event, oldest first (value changes after the other events).
    pub fn poll_event(&mut self) -> Option<Event> {
        if let Some(e) = self.events.pop_front() {
            return Some(e);
        }
        self.board
            .poll_change()
            .map(|key| Event::ValueChanged { key })
    }

    /// The next frame to send, at most `mtu` bytes: NACKs, talk messages, changed
    /// values, the periodic refresh and talk heads, in that order of priority. Ages in it
    /// are measured to the latest `now` given to any input.
    pub fn poll_transmit(&mut self) -> Option<Transmit> {
        let pending = !(self.nacks_out.is_empty()
            && self.talk_out.is_empty()
            && self.dirty.is_empty()
            && self.refresh_queue.is_empty()
            && self.heads_out.is_empty());
        if !pending && !self.heartbeat_due {
            return None;
        }
        let me = Scope::Robot(self.cfg.robot_id);
        let now = self.now;
        let mut w = FrameWriter::new(
            self.cfg.team_id,
            self.cfg.robot_id,
            self.incarnation,
            self.seq + 1,
            self.cfg.mtu,
            self.key.as_ref(),
        );
        let mut full = false;
        while let Some((target, queue, first, last)) = self.nacks_out.front() {
            if !w.push(ItemRef::Nack {
                target: *target,
                queue,
                first: *first,
                last: *last,
            }) {
                full = true;
                break;
            }
            self.nacks_out.pop_front();
        }
        while !full {
            let Some((queue, seq)) = self.talk_out.front() else {
                break;
            };
            if let Some(outbox) = self.outboxes.get_mut(queue) {
                if let Some(value) = outbox.get(*seq) {
                    if !w.push(ItemRef::Talk {
                        queue,
                        seq: *seq,
                        value,
                    }) {
                        full = true;
                        break;
                    }
                    outbox.mark_sent(*seq, now);
                }
            }
            self.talk_out.pop_front();
        }
        while !full {
            let Some(path) = self.dirty.first() else {
                break;
            };
            if let Some(e) = self.board.get_stored(me, path) {
                if !w.push(update_ref(path, e, now)) {
                    full = true;
                    break;
                }
            }
            self.dirty.pop_first();
        }
        while !full {
            let Some(path) = self.refresh_queue.front() else {
                break;
            };
            if let Some(e) = self.board.get_stored(me, path) {
                if !self.dirty.contains(path) && !w.push(update_ref(path, e, now)) {
                    full = true;
                    break;
                }
            }
            self.refresh_queue.pop_front();
        }
        if !full {
            while let Some(queue) = self.heads_out.first() {
                if let Some(outbox) = self.outboxes.get(queue) {
                    if !w.push(ItemRef::TalkHead {
                        queue,
                        first: outbox.first(),
                        last: outbox.last(),
                    }) {
                        break;
                    }
                }
                self.heads_out.pop_first();
            }
        }
        if w.is_empty() && pending {
            // Cannot happen (set and post refuse items that do not fit an empty frame),
            // but never stall on one: skip the item that did not fit.
            if self.nacks_out.pop_front().is_none()
                && self.talk_out.pop_front().is_none()
                && self.dirty.pop_first().is_none()
                && self.refresh_queue.pop_front().is_none()
            {
                self.heads_out.pop_first();
            }
        }
        self.heartbeat_due = false;
        self.seq += 1;
        let payload = w.finish();
        self.stats.frames_out += 1;
        self.stats.bytes_out += payload.len() as u64;
        Some(Transmit {
            destination: Destination::Group,
            payload,
        })
    }
}

fn update_ref<'a>(path: &'a str, e: &'a Entry, now: Instant) -> ItemRef<'a> {
    ItemRef::Update {
        path,
        value: &e.value,
        version: e.version,
        age_us: duration_to_micros(e.age(now)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn t(ms: u64) -> Instant {
        Instant::from_micros(ms * 1000)
    }
    fn addr() -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], 2000))
    }
    fn robot(id: u8, incarnation: u64) -> Replica {
        Replica::new(ReplicaConfig::new(id, 7), incarnation, t(0)).unwrap()
    }
    fn frames(r: &mut Replica) -> Vec<Vec<u8>> {
        std::iter::from_fn(|| r.poll_transmit().map(|t| t.payload)).collect()
    }
    fn deliver(now: Instant, frames: &[Vec<u8>], to: &mut Replica) {
        for f in frames {
            to.handle_datagram(now, addr(), f);
        }
    }
    fn events(r: &mut Replica) -> Vec<Event> {
        std::iter::from_fn(|| r.poll_event()).collect()
    }

    #[test]
    fn a_global_write_reaches_a_teammate_as_the_writers_copy() {
        let (mut a, mut b) = (robot(1, 11), robot(2, 22));
        a.set(t(5), "*.var.ball.dist", Value::Float(1.5)).unwrap();
        a.set(t(5), "local.var.secret", Value::Int(1)).unwrap();
        let out = frames(&mut a);
        assert_eq!(out.len(), 1, "one change, one frame");
        deliver(t(6), &out, &mut b);
        let e = b
            .get("1.var.ball.dist")
            .unwrap()
            .expect("robot 2 holds robot 1's copy");
        assert_eq!((e.owner, e.version, &e.value), (1, 1, &Value::Float(1.5)));
        assert_eq!(e.stamp, t(6), "age 0 at send time: stamped at reception");
        assert_eq!(b.get("*.var.ball.dist").unwrap().map(|e| e.owner), Some(1));
        assert!(
            b.get("1.var.secret").unwrap().is_none(),
            "local values never leave"
        );
        assert_eq!(
            a.get("1.var.ball.dist").unwrap().map(|e| e.owner),
            Some(1),
            "the writer reads its own copy as 1.var.x"
        );
        let evs = events(&mut b);
        assert!(
            evs.contains(&Event::PeerJoined {
                robot: 1,
                incarnation: 11
            }),
            "{evs:?}"
        );
        assert!(evs.contains(&Event::ValueChanged {
            key: Key::parse("1.var.ball.dist").unwrap()
        }));
        assert_eq!(
            a.poll_transmit(),
            None,
            "nothing left to send until the next tick"
        );
    }

    #[test]
    fn a_periodically_resent_old_value_does_not_look_fresh() {
        let (mut a, mut b) = (robot(1, 11), robot(2, 22));
        a.set(t(0), "*.var.x", Value::Int(4)).unwrap();
        frames(&mut a); // lost
        a.handle_timeout(t(0));
        frames(&mut a); // lost too
        a.handle_timeout(t(100));
        let refresh = frames(&mut a);
        assert!(!refresh.is_empty(), "the refresh re-sends every global");
        deliver(t(104), &refresh, &mut b);
        let e = b.get("1.var.x").unwrap().unwrap();
        assert_eq!(
            e.stamp,
            t(4),
            "reception 104 ms minus the reported 100 ms age"
        );
        assert!(
            b.get_fresher(t(104), "1.var.x", Duration::from_millis(50))
                .unwrap()
                .is_none(),
            "set 100 ms ago on the sender: not fresh, though just received"
        );
    }

    #[test]
    fn older_updates_never_overwrite_newer_ones_whatever_the_arrival_order() {
        let (mut a, mut b) = (robot(1, 11), robot(2, 22));
        a.set(t(0), "*.var.x", Value::Int(1)).unwrap();
        let old = frames(&mut a);
        a.set(t(1), "*.var.x", Value::Int(2)).unwrap();
        let new = frames(&mut a);
        deliver(t(2), &new, &mut b);
        deliver(t(3), &old, &mut b);
        deliver(t(4), &new, &mut b);
        let e = b.get("1.var.x").unwrap().unwrap();
        assert_eq!((e.value.clone(), e.version), (Value::Int(2), 2));
        assert_eq!(b.stats().updates_stale, 1);
    }

    #[test]
    fn a_restarted_robot_is_accepted_at_once_and_its_old_frames_are_dropped() {
        let (mut a, mut b) = (robot(1, 11), robot(2, 22));
        for v in 0..3 {
            a.set(t(v), "*.var.x", Value::Int(v as i64)).unwrap();
        }
        let before_restart = frames(&mut a);
        deliver(t(5), &before_restart, &mut b);
        let mut a2 = robot(1, 99);
        a2.set(t(10), "*.var.x", Value::Int(42)).unwrap();
        deliver(t(11), &frames(&mut a2), &mut b);
        let e = b.get("1.var.x").unwrap().unwrap();
        assert_eq!(
            (e.value.clone(), e.version, e.incarnation),
            (Value::Int(42), 1, 99)
        );
        assert!(events(&mut b).contains(&Event::PeerRestarted {
            robot: 1,
            old_incarnation: 11,
            new_incarnation: 99
        }));
        deliver(t(12), &before_restart, &mut b);
        assert_eq!(b.get("1.var.x").unwrap().unwrap().value, Value::Int(42));
        assert_eq!(b.stats().drops(DropReason::RetiredIncarnation), 1);
    }

    #[test]
    fn a_silent_robot_departs_after_three_refresh_periods_and_rejoins() {
        let (mut a, mut b) = (robot(1, 11), robot(2, 22));
        a.handle_timeout(t(0));
        deliver(t(10), &frames(&mut a), &mut b);
        events(&mut b);
        assert!(
            b.poll_timeout().unwrap() <= t(310),
            "b must wake for the departure"
        );
        b.handle_timeout(t(309));
        assert!(!events(&mut b).contains(&Event::PeerDeparted { robot: 1 }));
        b.handle_timeout(t(310));
        assert!(events(&mut b).contains(&Event::PeerDeparted { robot: 1 }));
        assert!(!b.peers().next().unwrap().present);
        a.handle_timeout(t(400));
        deliver(t(400), &frames(&mut a), &mut b);
        assert!(events(&mut b).contains(&Event::PeerJoined {
            robot: 1,
            incarnation: 11
        }));
    }

    #[test]
    fn a_robot_that_reappears_gets_a_full_refresh_at_once() {
        let (mut a, mut b) = (robot(1, 11), robot(2, 22));
        b.set(t(0), "*.var.y", Value::Int(5)).unwrap();
        b.handle_timeout(t(0));
        frames(&mut b);
        a.handle_timeout(t(0));
        deliver(t(10), &frames(&mut a), &mut b);
        assert!(
            frames(&mut b).is_empty(),
            "b's refresh of 10 ms ago serves a newcomer heard now: no extra copy"
        );
        b.handle_timeout(t(310));
        assert!(events(&mut b).contains(&Event::PeerDeparted { robot: 1 }));
        frames(&mut b); // the periodic refresh at 310 ms, lost while a is away
        a.handle_timeout(t(340));
        deliver(t(350), &frames(&mut a), &mut b);
        let extra = frames(&mut b);
        assert!(
            !extra.is_empty(),
            "a reappears at 350 ms: b re-sends what it owns now, not at 410 ms"
        );
        let mut c = robot(3, 33);
        deliver(t(351), &extra, &mut c);
        assert_eq!(
            c.get("2.var.y").unwrap().map(|e| e.value.clone()),
            Some(Value::Int(5)),
            "the extra copy is a full refresh"
        );
        assert_eq!(
            b.poll_timeout(),
            Some(t(410)),
            "the periodic schedule is unchanged"
        );
    }

    #[test]
    fn a_large_blackboard_spans_several_frames_none_above_the_mtu() {
        let (mut a, mut b) = (robot(1, 11), robot(2, 22));
        for i in 0..100 {
            a.set(
                t(0),
                &format!("*.var.item{i}"),
                Value::Bytes(vec![i as u8; 50]),
            )
            .unwrap();
        }
        frames(&mut a);
        a.handle_timeout(t(100));
        let refresh = frames(&mut a);
        assert!(refresh.len() >= 5, "{} frames for ~6 KB", refresh.len());
        assert!(
            refresh.iter().all(|f| f.len() <= 1200),
            "sizes {:?}",
            refresh.iter().map(Vec::len).collect::<Vec<_>>()
        );
        deliver(t(101), &refresh, &mut b);
        assert_eq!(b.iter(&Pattern::parse("1.var.#").unwrap()).count(), 100);
    }

    #[test]
    fn bad_datagrams_are_counted_drops_that_lose_nothing() {
        let (mut a, mut b) = (robot(1, 11), robot(2, 22));
        a.set(t(0), "*.var.x", Value::Int(1)).unwrap();
        deliver(t(1), &frames(&mut a), &mut b);
        let mut other_team = Replica::new(ReplicaConfig::new(3, 8), 3, t(0)).unwrap();
        other_team.set(t(0), "*.var.x", Value::Int(9)).unwrap();
        deliver(t(2), &frames(&mut other_team), &mut b);
        b.handle_datagram(t(3), addr(), b"hello");
        b.handle_datagram(t(3), addr(), &[]);
        b.handle_datagram(t(3), addr(), &vec![0x48; 5000]);
        a.set(t(4), "*.var.x", Value::Int(2)).unwrap();
        let good = frames(&mut a).remove(0);
        b.handle_datagram(t(5), addr(), &good[..good.len() - 2]);
        let s = b.stats();
        assert_eq!(
            [
                DropReason::OtherTeam,
                DropReason::BadMagic,
                DropReason::TooShort,
                DropReason::Oversized,
                DropReason::Malformed
            ]
            .map(|r| s.drops(r)),
            [1, 1, 1, 1, 1]
        );
        assert_eq!(
            b.get("1.var.x").unwrap().unwrap().value,
            Value::Int(1),
            "still the last good value"
        );
        assert!(b.get("3.var.x").unwrap().is_none());
        assert!(events(&mut b).iter().any(|e| matches!(
            e,
            Event::FrameDropped {
                reason: DropReason::OtherTeam,
                ..
            }
        )));
        b.handle_timeout(t(100));
        let mirrored = b
            .get("local.var.huddle.stats.drops.other_team")
            .unwrap()
            .unwrap();
        assert_eq!(mirrored.value, Value::Int(1));
        assert_eq!(
            b.get("local.var.huddle.stats.drops.total")
                .unwrap()
                .unwrap()
                .value,
            Value::Int(5)
        );
    }

    #[test]
    fn with_a_team_key_forged_untagged_and_replayed_frames_are_dropped() {
        let keyed = |id, inc, key: &[u8]| {
            Replica::new(ReplicaConfig::new(id, 7).with_team_key(key), inc, t(0)).unwrap()
        };
        let (mut a, mut b) = (keyed(1, 11, b"k1"), keyed(2, 22, b"k1"));
        a.set(t(0), "*.var.x", Value::Int(1)).unwrap();
        let f1 = frames(&mut a);
        deliver(t(1), &f1, &mut b);
        assert_eq!(b.get("1.var.x").unwrap().unwrap().value, Value::Int(1));
        a.set(t(2), "*.var.x", Value::Int(2)).unwrap();
        deliver(t(3), &frames(&mut a), &mut b);
        deliver(t(4), &f1, &mut b);
        assert_eq!(
            b.stats().drops(DropReason::Replay),
            1,
            "same incarnation, old seq"
        );
        let mut plain = robot(3, 33);
        plain.set(t(0), "*.var.x", Value::Int(3)).unwrap();
        deliver(t(5), &frames(&mut plain), &mut b);
        let mut forger = keyed(4, 44, b"guess");
        forger.set(t(0), "*.var.x", Value::Int(4)).unwrap();
        deliver(t(6), &frames(&mut forger), &mut b);
        assert_eq!(b.stats().drops(DropReason::MissingTag), 1);
        assert_eq!(b.stats().drops(DropReason::BadTag), 1);
        assert_eq!(b.get("*.var.x").unwrap().unwrap().value, Value::Int(2));
    }

    #[test]
    fn a_world_model_update_is_at_most_128_bytes_on_the_wire() {
        let cfg = ReplicaConfig::new(3, 7).with_team_key(vec![9u8; 32]);
        let mut r = Replica::new(cfg, 0xdead_beef_dead_beef, t(0)).unwrap();
        r.handle_timeout(t(0));
        frames(&mut r);
        for i in 0..70_000u64 {
            // A long match: large version and seq varints.
            r.set(t(i), "*.var.world.local", Value::Bytes(vec![i as u8; 40]))
                .unwrap();
            if i % 1000 == 0 {
                frames(&mut r);
            }
        }
        let f = frames(&mut r);
        assert_eq!(f.len(), 1);
        assert!(
            f[0].len() <= 128,
            "world model frame is {} bytes",
            f[0].len()
        );
    }

    #[test]
    fn writes_that_cannot_be_replicated_are_refused() {
        let mut a = robot(1, 11);
        assert!(matches!(
            a.set(t(0), "2.var.x", Value::Int(1)),
            Err(SetError::NotOwner { owner: 2, .. })
        ));
        assert!(matches!(
            a.set(t(0), "*.var.big", Value::Bytes(vec![0; 1200])),
            Err(SetError::TooLarge { .. })
        ));
        assert!(
            a.set(t(0), "local.var.big", Value::Bytes(vec![0; 5000]))
                .is_ok(),
            "local values have no size limit"
        );
        assert!(matches!(
            a.set(t(0), "*.talk.q", Value::Int(1)),
            Err(SetError::TalkKey(_))
        ));
        assert!(matches!(
            a.post(t(0), "*.var.q", Value::Int(1)),
            Err(PostError::NotOwnQueue(_))
        ));
        assert!(matches!(
            a.post(t(0), "2.talk.q", Value::Int(1)),
            Err(PostError::NotOwnQueue(_))
        ));
        assert!(matches!(
            a.post(t(0), "*.talk.q", Value::Bytes(vec![0; 1200])),
            Err(PostError::TooLarge { .. })
        ));
        assert_eq!(a.post(t(0), "1.talk.q", Value::Int(1)), Ok(1));
        assert_eq!(a.post(t(0), "*.talk.q", Value::Int(2)), Ok(2));
        assert!(matches!(
            Replica::new(ReplicaConfig::new(0, 7), 1, t(0)),
            Err(ConfigInvalid::RobotId(0))
        ));
    }

    #[test]
    fn own_looped_back_frames_are_ignored_and_a_twin_id_is_reported() {
        let mut a = robot(1, 11);
        a.set(t(0), "*.var.x", Value::Int(1)).unwrap();
        let own = frames(&mut a);
        deliver(t(1), &own, &mut a);
        assert_eq!((a.stats().own_frames, a.stats().drops_total()), (1, 0));
        let mut twin = robot(1, 12);
        twin.set(t(0), "*.var.x", Value::Int(5)).unwrap();
        deliver(t(1), &frames(&mut twin), &mut a);
        assert_eq!(a.stats().drops(DropReason::RobotIdConflict), 1);
        assert_eq!(a.get("1.var.x").unwrap().unwrap().value, Value::Int(1));
    }

    #[test]
    fn a_lost_talk_message_is_repaired_by_nack_and_delivered_in_order() {
        let (mut a, mut b) = (robot(1, 11), robot(2, 22));
        b.handle_timeout(t(0)); // start-up heartbeat, so the next wake-up is a talk timer
        frames(&mut b);
        let mut wire_ab = Vec::new();
        for i in 1..=3 {
            a.post(t(0), "*.talk.plan", Value::Int(i)).unwrap();
            wire_ab.push(frames(&mut a));
        }
        deliver(t(1), &wire_ab[0], &mut b);
        deliver(t(1), &wire_ab[2], &mut b); // message 2 lost
        let got: Vec<i64> = events(&mut b)
            .into_iter()
            .filter_map(|e| match e {
                Event::TalkDelivered {
                    value: Value::Int(v),
                    ..
                } => Some(v),
                _ => None,
            })
            .collect();
        assert_eq!(got, [1], "3 waits for 2");
        let wake = b.poll_timeout().unwrap();
        assert_eq!(
            wake,
            t(21),
            "first NACK one nack_interval after the gap appeared"
        );
        b.handle_timeout(wake);
        let nack = frames(&mut b);
        deliver(t(22), &nack, &mut a);
        assert_eq!(a.stats().talk_resent, 1);
        deliver(t(23), &frames(&mut a), &mut b);
        let got: Vec<(u64, Value)> = events(&mut b)
            .into_iter()
            .filter_map(|e| match e {
                Event::TalkDelivered {
                    seq,
                    value,
                    from: 1,
                    ..
                } => Some((seq, value)),
                _ => None,
            })
            .collect();
        assert_eq!(got, [(2, Value::Int(2)), (3, Value::Int(3))]);
    }

    #[test]
    fn an_unrepairable_talk_gap_is_given_up_with_an_event() {
        let mut cfg = ReplicaConfig::new(1, 7);
        cfg.talk.retain = 2;
        let mut a = Replica::new(cfg, 11, t(0)).unwrap();
        let mut b = robot(2, 22);
        for i in 1..=5 {
            a.post(t(0), "*.talk.q", Value::Int(i)).unwrap();
        }
        frames(&mut a); // all lost
        a.handle_timeout(t(100));
        deliver(t(100), &frames(&mut a), &mut b);
        let evs: Vec<Event> = events(&mut b)
            .into_iter()
            .filter(|e| matches!(e, Event::TalkGivenUp { .. } | Event::TalkDelivered { .. }))
            .collect();
        assert_eq!(
            evs,
            [Event::TalkGivenUp {
                queue: "q".into(),
                from: 1,
                first: 1,
                last: 3
            }],
            "only 4 and 5 are still held"
        );
        b.handle_timeout(t(120));
        deliver(t(121), &frames(&mut b), &mut a);
        deliver(t(122), &frames(&mut a), &mut b);
        let seqs: Vec<u64> = events(&mut b)
            .into_iter()
            .filter_map(|e| match e {
                Event::TalkDelivered { seq, .. } => Some(seq),
                _ => None,
            })
            .collect();
        assert_eq!(seqs, [4, 5]);
        assert_eq!(b.stats().talk_given_up, 3);
    }

    #[test]
    fn a_restart_gives_up_the_old_queues_holes_and_starts_the_new_queue_at_one() {
        let (mut a, mut b) = (robot(1, 11), robot(2, 22));
        let mut sent = Vec::new();
        for i in 1..=3 {
            a.post(t(0), "*.talk.q", Value::Int(i)).unwrap();
            sent.push(frames(&mut a));
        }
        deliver(t(1), &sent[0], &mut b);
        deliver(t(1), &sent[2], &mut b); // 2 is lost, then robot 1 reboots
        events(&mut b);
        let mut a2 = robot(1, 12);
        a2.post(t(50), "*.talk.q", Value::Int(100)).unwrap();
        deliver(t(51), &frames(&mut a2), &mut b);
        let talk: Vec<Event> = events(&mut b)
            .into_iter()
            .filter(|e| matches!(e, Event::TalkDelivered { .. } | Event::TalkGivenUp { .. }))
            .collect();
        let delivered = |seq, v| Event::TalkDelivered {
            queue: "q".into(),
            from: 1,
            seq,
            value: Value::Int(v),
        };
        assert_eq!(
            talk,
            [
                Event::TalkGivenUp {
                    queue: "q".into(),
                    from: 1,
                    first: 2,
                    last: 2
                },
                delivered(3, 3),
                delivered(1, 100),
            ],
            "the old incarnation's gap is reported, its tail delivered, the new queue starts at 1"
        );
    }

    #[test]
    fn configurations_that_cannot_work_are_refused() {
        let with = |f: fn(&mut ReplicaConfig)| {
            let mut cfg = ReplicaConfig::new(1, 7);
            f(&mut cfg);
            Replica::new(cfg, 1, t(0)).err()
        };
        assert_eq!(with(|c| c.mtu = 63), Some(ConfigInvalid::Mtu(63)));
        assert_eq!(with(|c| c.mtu = 70_000), Some(ConfigInvalid::Mtu(70_000)));
        assert_eq!(
            with(|c| c.refresh_period = Duration::ZERO),
            Some(ConfigInvalid::Period)
        );
        assert_eq!(with(|c| c.talk.window = 0), Some(ConfigInvalid::TalkLimits));
        assert_eq!(
            with(|c| c.robot_id = 255),
            Some(ConfigInvalid::RobotId(255))
        );
        assert_eq!(with(|_| {}), None);
        let cfg = ReplicaConfig::new(1, 7).with_refresh_period(Duration::from_millis(50));
        assert_eq!(cfg.departed_after, Duration::from_millis(150));
    }

    proptest::proptest! {
        #[test]
        fn any_well_formed_frame_from_a_teammate_is_handled_without_panic(
            frames in proptest::collection::vec(crate::wire::tests::any_frame(), 1..6),
            later_ms in 0u64..5_000,
        ) {
            let mut r = robot(9, 99);
            for (i, mut f) in frames.into_iter().enumerate() {
                f.team = 7;
                if i % 2 == 0 {
                    // Half of them name this robot in their NACKs.
                    for item in &mut f.items {
                        if let Item::Nack { target, .. } = item {
                            *target = 9;
                        }
                    }
                }
                r.handle_datagram(t(i as u64), addr(), &wire::encode_frame(&f, None));
            }
            r.post(t(10), "*.talk.q", Value::Int(1)).unwrap();
            for now in [t(20), t(40), t(1_100), t(later_ms + 1_100)] {
                r.handle_timeout(now);
                while r.poll_transmit().is_some() {}
                while r.poll_event().is_some() {}
            }
            let s = r.stats();
            let expected = s.drops(DropReason::RobotIdConflict) + s.drops(DropReason::RetiredIncarnation);
            proptest::prop_assert_eq!(s.drops_total(), expected, "well-formed frames decode");
        }
    }
}
