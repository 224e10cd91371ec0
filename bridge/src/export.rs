//! What the bridge publishes, decided without I/O: the listening replica's events in,
//! Zenoh operations out ([`Op`]), time as an argument (the sans-IO rule of `comms`).
//!
//! - A value goes out when its `(incarnation, version)` is newer than the one last
//!   published for its key: a refresh (same version) never does, and neither does a late
//!   value of a robot's earlier life.
//! - With a rate cap (`--max-rate 10Hz`), a key publishes at most once per period; the
//!   newest value at the end of the period goes then (never a value in between).
//! - `local.*` keys never leave: only keys owned by a robot id are exported.
//! - Presence: a robot's life is a liveliness token; a restart withdraws the old token
//!   and declares the new one, a departure withdraws it.
//!
//! The age in each sample's attachment is measured on the bridge's clock from the
//! replica's stamp (reception − the sender's reported age) plus the transit of the frame
//! that brought the value ([`crate::transit`]), never from Zenoh's timestamps, which are
//! a hybrid logical clock on wall time. The exporter owns the transit estimator: a value
//! whose sender's clock is not anchored by an echo yet waits for it (at most
//! [`crate::transit::ANCHOR_WAIT`] after the bridge first heard that robot's life), so
//! that no age goes out below the true one while the bridge warms up.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::time::Duration;

use comms::{Entry, Event, Instant, Key, Kind, Replica, Scope, Value};

use crate::cdr;
use crate::keys::TeamKeys;
use crate::transit::{FrameTiming, Heard, TransitEstimator};

/// What the bridge exports and how often.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ExportConfig {
    /// The shortest time between two samples of one key (`--max-rate`); `None`: no cap.
    pub min_interval: Option<Duration>,
    /// Also publish each value as a ROS 2 `std_msgs` message in CDR (`--ros2`).
    pub ros2: bool,
}

/// One thing to do on the Zenoh side.
#[derive(Clone, Debug, PartialEq)]
pub enum Op {
    /// Publish a value's sample (a newer value of the same key may supersede it before
    /// it goes: [`crate::outbox`]).
    Put(Sample),
    /// Publish a talk message (each one goes).
    Talk(Sample),
    /// Declare the liveliness token of `robot`'s life `incarnation` at `key`.
    Alive {
        /// The robot.
        robot: u8,
        /// Its incarnation.
        incarnation: u64,
        /// The token's key.
        key: String,
    },
    /// Withdraw `robot`'s liveliness token (a Zenoh DELETE for subscribers).
    Gone {
        /// The robot.
        robot: u8,
    },
}

/// A value as published (or as a query's reply).
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// The key expression.
    pub key: String,
    /// The relay's literal text (`2.5`, `"x"`, `[1,2]`, `0x0a`).
    pub payload: String,
    /// What the attachment says; kept as numbers until the put, so that the time a value
    /// waits in the outbox is added without re-parsing text.
    pub meta: Meta,
    /// With `--ros2`: the ROS-style key and the CDR message.
    pub ros2: Option<(String, Vec<u8>)>,
}

/// A sample's attachment, as numbers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Meta {
    /// A value: its life, version and age at the bridge.
    Value {
        /// The owner's incarnation.
        incarnation: u64,
        /// The value's version.
        version: u64,
        /// Its age at the bridge.
        age: Duration,
    },
    /// A talk message: its sender's life and the message's sequence number.
    Talk {
        /// The sender's incarnation.
        incarnation: u64,
        /// The message's sequence number.
        seq: u64,
    },
}

impl Sample {
    /// `incarnation=<16 hex> version=<n> age_us=<n>` (talk: `incarnation=… seq=<n>`).
    pub fn attachment(&self) -> String {
        match self.meta {
            Meta::Value {
                incarnation,
                version,
                age,
            } => attachment(incarnation, version, age),
            Meta::Talk { incarnation, seq } => {
                format!("incarnation={incarnation:016x} seq={seq}")
            }
        }
    }

    /// The same sample `waited` older (talk messages carry no age).
    pub fn aged(mut self, waited: Duration) -> Sample {
        if let Meta::Value { age, .. } = &mut self.meta {
            *age += waited;
        }
        self
    }
}

/// The attachment text: incarnation, version, and the age at the bridge.
pub fn attachment(incarnation: u64, version: u64, age: Duration) -> String {
    format!(
        "incarnation={incarnation:016x} version={version} age_us={}",
        age.as_micros()
    )
}

/// Parses an [`attachment`] back: `(incarnation, version, age)`.
pub fn parse_attachment(text: &str) -> Option<(u64, u64, Duration)> {
    let mut inc = None;
    let mut ver = None;
    let mut age = None;
    for field in text.split_ascii_whitespace() {
        let (name, value) = field.split_once('=')?;
        match name {
            "incarnation" => inc = u64::from_str_radix(value, 16).ok(),
            "version" => ver = value.parse().ok(),
            "age_us" => age = value.parse().ok().map(Duration::from_micros),
            _ => {}
        }
    }
    Some((inc?, ver?, age?))
}

/// Counters of the export side (the `@bridge/stats` reply has them).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ExportStats {
    /// Value samples handed to Zenoh.
    pub values_out: u64,
    /// Talk messages handed to Zenoh.
    pub talk_out: u64,
    /// Changes with a version already published (not sent).
    pub unchanged_skipped: u64,
    /// Values of a robot's earlier life that arrived late (not sent).
    pub old_life_dropped: u64,
    /// Changes held back by `--max-rate` (the newest went at the end of the period).
    pub rate_held: u64,
    /// Keys that had no key expression (logged once each).
    pub unmappable: u64,
    /// Values with no ROS 2 topic under `--ros2` (logged once each).
    pub ros2_unmappable: u64,
    /// Liveliness tokens declared and withdrawn.
    pub alive_declared: u64,
    /// Liveliness tokens withdrawn.
    pub alive_withdrawn: u64,
    /// Changes held while their sender's clock was not anchored yet (the bridge's first
    /// moments with a robot's life).
    pub anchor_held: u64,
    /// Values that went out unanchored: the sender was not anchored within
    /// [`crate::transit::ANCHOR_WAIT`] (a robot alone has no teammate to echo), so their
    /// transit is the lower bound.
    pub unanchored_out: u64,
    /// Values published once more after Zenoh came back ([`Exporter::republish`]).
    pub republished: u64,
}

#[derive(Debug, Default)]
struct KeyState {
    /// `(incarnation, version)` last published.
    published: Option<(u64, u64)>,
    last_put: Option<Instant>,
    /// A change waits for the rate cap.
    held: bool,
    /// The timing of the frame that brought the current value (see [`crate::transit`]):
    /// its transit is added to the replica's age, which leaves it out.
    timing: Option<FrameTiming>,
}

/// The export decisions; see the module docs.
#[derive(Debug)]
pub struct Exporter {
    keys: TeamKeys,
    cfg: ExportConfig,
    state: HashMap<Key, KeyState>,
    held: BTreeSet<(Instant, Key)>,
    alive: BTreeMap<u8, u64>,
    /// Paths already reported as unmappable (logged once).
    reported: BTreeSet<String>,
    ops: Vec<Op>,
    stats: ExportStats,
    transit: TransitEstimator,
    /// The timing of the frame whose events are being handled.
    frame: Option<FrameTiming>,
    /// Keys waiting for their sender's anchor, by sender: `(deadline, key)` as in `held`.
    awaiting: BTreeMap<u8, Vec<(Instant, Key)>>,
}

impl Exporter {
    /// An exporter for `keys`.
    pub fn new(keys: TeamKeys, cfg: ExportConfig) -> Exporter {
        Exporter {
            keys,
            cfg,
            state: HashMap::new(),
            held: BTreeSet::new(),
            alive: BTreeMap::new(),
            reported: BTreeSet::new(),
            ops: Vec::new(),
            stats: ExportStats::default(),
            transit: TransitEstimator::new(),
            frame: None,
            awaiting: BTreeMap::new(),
        }
    }

    /// The key expressions in use.
    pub fn keys(&self) -> &TeamKeys {
        &self.keys
    }

    /// The counters.
    pub fn stats(&self) -> &ExportStats {
        &self.stats
    }

    /// Robots whose token is declared, with their incarnation.
    pub fn alive(&self) -> &BTreeMap<u8, u64> {
        &self.alive
    }

    /// The transit estimator (its counters and floor for `@bridge/stats`).
    pub fn transit(&self) -> &TransitEstimator {
        &self.transit
    }

    /// Takes the header of a frame received at `now` whose events come next: the age of
    /// a value it changes is the replica's plus the frame's transit. If it anchors its
    /// sender's clock, that sender's waiting values go at the next
    /// [`Exporter::handle_timeout`].
    pub fn frame(&mut self, now: Instant, heard: Heard) {
        let timing = self.transit.heard(now, heard);
        if self.transit.anchored(&timing) {
            if let Some(waiting) = self.awaiting.remove(&timing.sender) {
                for (due, key) in waiting {
                    if self.held.remove(&(due, key.clone())) {
                        self.held.insert((now, key));
                    }
                }
            }
        }
        self.frame = Some(timing);
    }

    /// The frame's events are handled: events after this (a timeout's) have no frame.
    pub fn frame_done(&mut self) {
        self.frame = None;
    }

    /// Takes one event of `replica` (drained by the caller at `now`).
    pub fn handle_event(&mut self, now: Instant, replica: &Replica, event: Event) {
        match event {
            Event::ValueChanged { key } => {
                if matches!(key.scope(), Scope::Robot(_)) {
                    self.state.entry(key.clone()).or_default().timing = self.frame;
                }
                self.value_changed(now, replica, key)
            }
            Event::TalkDelivered {
                queue,
                from,
                seq,
                value,
            } => self.talk(from, &queue, seq, &value, replica),
            Event::PeerJoined { robot, incarnation } => self.declare(robot, incarnation),
            Event::PeerRestarted {
                robot,
                new_incarnation,
                ..
            } => self.declare(robot, new_incarnation),
            Event::PeerDeparted { robot } => self.withdraw(robot),
            Event::IncarnationConflict { .. }
            | Event::TalkGivenUp { .. }
            | Event::FrameDropped { .. } => {}
        }
    }

    /// The next rate-cap deadline.
    pub fn poll_timeout(&self) -> Option<Instant> {
        self.held.first().map(|(t, _)| *t)
    }

    /// Publishes what the rate cap (or a sender's anchor) held until `now`, the replica's
    /// newest value.
    pub fn handle_timeout(&mut self, now: Instant, replica: &Replica) {
        if !self.awaiting.is_empty() {
            // Entries whose deadline passed were released through `held`.
            self.awaiting.retain(|_, keys| {
                keys.retain(|(due, _)| *due > now);
                !keys.is_empty()
            });
        }
        while let Some((due, key)) = self.held.first().cloned() {
            if due > now {
                break;
            }
            self.held.pop_first();
            if let Some(s) = self.state.get_mut(&key) {
                s.held = false;
            }
            self.value_changed(now, replica, key);
        }
    }

    /// Queues the value last published of every key once more (after Zenoh came back: a
    /// value in flight when a link closed may never have arrived). Keys whose newer value
    /// is held (rate cap, anchor) are left to go when released. Returns how many.
    pub fn republish(&mut self, now: Instant, replica: &Replica) -> usize {
        let keys: Vec<Key> = self
            .state
            .iter()
            .filter(|(_, s)| s.published.is_some() && !s.held)
            .map(|(k, _)| k.clone())
            .collect();
        let mut n = 0;
        for key in keys {
            let Some(entry) = replica.blackboard().get(&key) else {
                continue;
            };
            let published = self.state.get(&key).and_then(|s| s.published);
            if published != Some((entry.incarnation, entry.version)) {
                continue; // a newer value is on its way already
            }
            if let Some(sample) = self.sample(now, &key, entry) {
                self.ops.push(Op::Put(sample));
                n += 1;
            }
        }
        self.stats.republished += n as u64;
        n
    }

    /// The operations decided so far, oldest first.
    pub fn drain_ops(&mut self) -> std::vec::Drain<'_, Op> {
        self.ops.drain(..)
    }

    /// The sample `entry` at `key` makes at `now` (a query's reply uses it too): `None`
    /// for keys that never leave or cannot map.
    pub fn sample(&mut self, now: Instant, key: &Key, entry: &Entry) -> Option<Sample> {
        let Scope::Robot(owner) = key.scope() else {
            return None; // local.* never leaves
        };
        if key.kind() != Kind::Var {
            return None;
        }
        let zkey = match self.keys.var(owner, key.path()) {
            Ok(k) => k,
            Err(e) => {
                self.stats.unmappable += 1;
                if self.reported.insert(key.path().to_owned()) {
                    tracing::warn!("not exported: {e}");
                }
                return None;
            }
        };
        let ros2 = if self.cfg.ros2 {
            self.ros2(owner, key.path(), &entry.value)
        } else {
            None
        };
        let transit = self
            .state
            .get(key)
            .and_then(|s| s.timing)
            .map_or(Duration::ZERO, |t| self.transit.transit(&t));
        Some(Sample {
            key: zkey,
            payload: entry.value.to_string(),
            meta: Meta::Value {
                incarnation: entry.incarnation,
                version: entry.version,
                age: entry.age(now) + transit,
            },
            ros2,
        })
    }

    fn ros2(&mut self, owner: u8, path: &str, value: &Value) -> Option<(String, Vec<u8>)> {
        match self.keys.ros2(owner, path) {
            Ok(k) => Some((k, cdr::encode(value))),
            Err(e) => {
                self.stats.ros2_unmappable += 1;
                if self.reported.insert(format!("ros2:{path}")) {
                    tracing::warn!("no ROS 2 topic: {e}");
                }
                None
            }
        }
    }

    fn value_changed(&mut self, now: Instant, replica: &Replica, key: Key) {
        let Scope::Robot(owner) = key.scope() else {
            return; // the listener's own local values (its stats mirror)
        };
        let Some(entry) = replica.blackboard().get(&key) else {
            return; // released meanwhile
        };
        if self
            .alive
            .get(&owner)
            .is_some_and(|&cur| entry.incarnation < cur)
        {
            self.stats.old_life_dropped += 1;
            return;
        }
        let id = (entry.incarnation, entry.version);
        let state = self.state.entry(key.clone()).or_default();
        if state.held {
            return; // the newest value goes when the period ends
        }
        match state.published {
            Some(old) if old >= id => {
                if old.0 > id.0 {
                    self.stats.old_life_dropped += 1;
                } else {
                    self.stats.unchanged_skipped += 1;
                }
                return;
            }
            _ => {}
        }
        // The sender's clock is not anchored yet: wait for its first echo (released by
        // `frame`), or until the deadline, when the value goes with the lower bound.
        if let Some(timing) = state.timing {
            if !self.transit.anchored(&timing) {
                match self.transit.anchor_deadline(&timing) {
                    Some(due) if due > now => {
                        state.held = true;
                        self.stats.anchor_held += 1;
                        self.held.insert((due, key.clone()));
                        self.awaiting
                            .entry(timing.sender)
                            .or_default()
                            .push((due, key));
                        return;
                    }
                    _ => self.stats.unanchored_out += 1,
                }
            }
        }
        if let (Some(min), Some(last)) = (self.cfg.min_interval, state.last_put) {
            let due = last + min;
            if due > now {
                state.held = true;
                self.stats.rate_held += 1;
                self.held.insert((due, key));
                return;
            }
        }
        state.published = Some(id);
        state.last_put = Some(now);
        if let Some(sample) = self.sample(now, &key, entry) {
            self.stats.values_out += 1;
            self.ops.push(Op::Put(sample));
        }
    }

    fn talk(&mut self, from: u8, queue: &str, seq: u64, value: &Value, replica: &Replica) {
        let Ok(key) = self.keys.talk(from, queue) else {
            self.stats.unmappable += 1;
            return;
        };
        let incarnation = replica
            .peers()
            .find(|p| p.robot == from)
            .map_or(0, |p| p.incarnation);
        self.stats.talk_out += 1;
        self.ops.push(Op::Talk(Sample {
            key,
            payload: value.to_string(),
            meta: Meta::Talk { incarnation, seq },
            ros2: None,
        }));
    }

    fn declare(&mut self, robot: u8, incarnation: u64) {
        match self.alive.get(&robot) {
            Some(&cur) if cur == incarnation => return,
            Some(_) => self.withdraw(robot),
            None => {}
        }
        self.alive.insert(robot, incarnation);
        self.stats.alive_declared += 1;
        self.ops.push(Op::Alive {
            robot,
            incarnation,
            key: self.keys.alive(robot, incarnation),
        });
    }

    fn withdraw(&mut self, robot: u8) {
        if self.alive.remove(&robot).is_some() {
            self.stats.alive_withdrawn += 1;
            self.ops.push(Op::Gone { robot });
        }
    }
}

#[cfg(test)]
mod tests;
