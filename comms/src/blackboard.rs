//! The blackboard: symbol → value bindings with owner, version and a timestamp on this
//! robot's clock (isocrob-2000 §3.1), usable on its own or inside a [`crate::Replica`].
//!
//! Storage holds `var` bindings only, under `local` (this robot's private values) or a
//! robot id (that robot's copy of a global value; this robot's own copies live under its
//! own id). `*` is a view: writing `*.var.x` writes the own copy, reading it returns the
//! copy with the newest timestamp. `talk` messages are not stored; they are delivered as
//! events by the replica.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::time::Duration;

use thiserror::Error;

use crate::key::{Key, KeyError, Kind, Scope};
use crate::pattern::Pattern;
use crate::time::Instant;
use crate::value::Value;

/// One binding as stored.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    /// The bound value.
    pub value: Value,
    /// The robot that wrote it (this robot for `local` values).
    pub owner: u8,
    /// The owner's write counter for this key; starts at 1 and grows by one per write
    /// within one incarnation of the owner.
    pub version: u64,
    /// The owner's incarnation (random per start) when it wrote this version.
    pub incarnation: u64,
    /// When the value was set, on **this** robot's clock. For a value from the network:
    /// reception time minus the age the owner reported.
    pub stamp: Instant,
}

impl Entry {
    /// Time since the value was set, by this robot's clock.
    pub fn age(&self, now: Instant) -> Duration {
        now.saturating_duration_since(self.stamp)
    }
}

/// Why a write was refused.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum SetError {
    /// The key does not parse.
    #[error(transparent)]
    Key(#[from] KeyError),
    /// `talk` keys are queues: post to them instead.
    #[error("{0} is a talk queue: post messages to it instead of setting it")]
    TalkKey(String),
    /// `n.var.*` belongs to robot n; only n writes it (through `*.var.*`).
    #[error("{key} belongs to robot {owner}; this robot is {me}")]
    NotOwner {
        /// The key as given.
        key: String,
        /// Its owner.
        owner: u8,
        /// This robot.
        me: u8,
    },
    /// A global value too large to fit in one frame of the configured MTU.
    #[error("{key}: the update takes {bytes} bytes, more than one frame holds ({mtu} byte MTU)")]
    TooLarge {
        /// The key as given.
        key: String,
        /// Encoded update size.
        bytes: usize,
        /// Configured MTU.
        mtu: usize,
    },
}

/// What [`Blackboard::apply_remote`] did with an update.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Applied {
    /// A key not held before.
    Inserted,
    /// A newer version with a different value.
    Changed,
    /// A newer version with the same value, or the same version again (a refresh): the
    /// stamp may have moved, the value did not.
    Refreshed,
    /// An older version than the one held: ignored.
    Stale,
}

/// A stored binding, its key as stored, and whether a change event for it is queued (so an
/// undrained queue holds each binding at most once and stays bounded by their number).
#[derive(Clone, Debug)]
struct Slot {
    key: Key,
    entry: Entry,
    change_queued: bool,
}

/// Where a binding lives in [`Blackboard::slots`]. Bindings are never removed, so an id
/// stays valid for the blackboard's life.
pub(crate) type SlotId = u32;

/// The bindings of one scope, found two ways: by hash for the per-update lookups of the
/// hot path (a B-tree walk compares the path against a dozen or more stored paths, and
/// paths of one robot often share long prefixes), and in key order for iteration.
#[derive(Clone, Debug, Default)]
struct ScopeIndex {
    by_path: HashMap<String, SlotId>,
    ordered: BTreeMap<String, SlotId>,
}

/// The set of bindings.
#[derive(Clone, Debug)]
pub struct Blackboard {
    robot_id: u8,
    incarnation: u64,
    slots: Vec<Slot>,
    scopes: BTreeMap<Scope, ScopeIndex>,
    changes: VecDeque<SlotId>,
}

impl Blackboard {
    /// An empty blackboard for robot `robot_id` (1..=254; writes of `*.var.x` land in
    /// `robot_id.var.x`).
    pub fn new(robot_id: u8) -> Blackboard {
        Blackboard {
            robot_id,
            incarnation: 0,
            slots: Vec::new(),
            scopes: BTreeMap::new(),
            changes: VecDeque::new(),
        }
    }

    pub(crate) fn set_incarnation(&mut self, incarnation: u64) {
        self.incarnation = incarnation;
    }

    /// This robot's id.
    pub fn robot_id(&self) -> u8 {
        self.robot_id
    }

    fn find(&self, scope: Scope, path: &str) -> Option<SlotId> {
        self.scopes.get(&scope)?.by_path.get(path).copied()
    }

    fn insert(&mut self, scope: Scope, path: &str, entry: Entry) -> SlotId {
        let id = SlotId::try_from(self.slots.len()).expect("fewer than 2^32 bindings");
        self.slots.push(Slot {
            key: Key::from_valid_parts(scope, Kind::Var, path.to_owned()),
            entry,
            change_queued: true,
        });
        let index = self.scopes.entry(scope).or_default();
        index.by_path.insert(path.to_owned(), id);
        index.ordered.insert(path.to_owned(), id);
        self.changes.push_back(id);
        id
    }

    /// Writes a value at `now`. `local.var.x` stays here; `*.var.x` and
    /// `<own id>.var.x` set this robot's own copy (returned: the key it is stored under).
    /// Every write bumps the version, even with an unchanged value, so freshness
    /// propagates; a change event is queued only when the value differs.
    pub fn set(&mut self, now: Instant, key: &Key, value: Value) -> Result<Key, SetError> {
        let id = self.write(now, key, value)?;
        Ok(self.slots[id as usize].key.clone())
    }

    /// [`Blackboard::set`] without building the stored key: the binding's slot.
    pub(crate) fn write(
        &mut self,
        now: Instant,
        key: &Key,
        value: Value,
    ) -> Result<SlotId, SetError> {
        let scope = self.storage_scope(key)?;
        let (robot_id, incarnation) = (self.robot_id, self.incarnation);
        let Some(id) = self.find(scope, key.path()) else {
            let entry = Entry {
                value,
                owner: robot_id,
                version: 1,
                incarnation,
                stamp: now,
            };
            return Ok(self.insert(scope, key.path(), entry));
        };
        let slot = &mut self.slots[id as usize];
        let e = &mut slot.entry;
        let changed = !e.value.same_as(&value);
        e.value = value;
        e.version += 1;
        e.stamp = now;
        e.incarnation = incarnation;
        if changed && !slot.change_queued {
            slot.change_queued = true;
            self.changes.push_back(id);
        }
        Ok(id)
    }

    /// Where a write of `key` goes, or why it may not be written here.
    pub(crate) fn storage_scope(&self, key: &Key) -> Result<Scope, SetError> {
        if key.kind() == Kind::Talk {
            return Err(SetError::TalkKey(key.to_string()));
        }
        match key.scope() {
            Scope::Local => Ok(Scope::Local),
            Scope::Global => Ok(Scope::Robot(self.robot_id)),
            Scope::Robot(n) if n == self.robot_id => Ok(Scope::Robot(n)),
            Scope::Robot(n) => Err(SetError::NotOwner {
                key: key.to_string(),
                owner: n,
                me: self.robot_id,
            }),
        }
    }

    /// Applies another robot's update to `owner.var.path`. Newer versions replace older
    /// ones; an update from a different incarnation than the stored one replaces it at
    /// once (a restarted robot). Deciding which incarnation is current is the caller's
    /// job (the replica drops frames from retired incarnations). For the same version the
    /// earlier stamp wins: the copy that travelled fastest estimates the set time best.
    pub fn apply_remote(
        &mut self,
        owner: u8,
        incarnation: u64,
        path: String,
        value: Value,
        version: u64,
        stamp: Instant,
    ) -> Applied {
        self.apply_remote_path(owner, incarnation, &path, value, version, stamp)
    }

    /// [`Blackboard::apply_remote`] with a borrowed path: the receive path allocates
    /// nothing for a key already held.
    pub(crate) fn apply_remote_path(
        &mut self,
        owner: u8,
        incarnation: u64,
        path: &str,
        value: Value,
        version: u64,
        stamp: Instant,
    ) -> Applied {
        let scope = Scope::Robot(owner);
        let fresh = Entry {
            value,
            owner,
            version,
            incarnation,
            stamp,
        };
        let Some(id) = self.find(scope, path) else {
            self.insert(scope, path, fresh);
            return Applied::Inserted;
        };
        let slot = &mut self.slots[id as usize];
        let e = &mut slot.entry;
        if e.incarnation == incarnation && version < e.version {
            return Applied::Stale;
        }
        if e.incarnation == incarnation && version == e.version {
            e.stamp = e.stamp.min(stamp);
            return Applied::Refreshed;
        }
        let changed = !e.value.same_as(&fresh.value);
        *e = fresh;
        if !changed {
            return Applied::Refreshed;
        }
        if !slot.change_queued {
            slot.change_queued = true;
            self.changes.push_back(id);
        }
        Applied::Changed
    }

    /// The binding for `key`: `local.var.x`, `n.var.x`, or for `*.var.x` the copy with
    /// the newest stamp (ties: the lowest robot id). `talk` keys have no binding.
    pub fn get(&self, key: &Key) -> Option<&Entry> {
        if key.kind() == Kind::Talk {
            return None;
        }
        match key.scope() {
            Scope::Global => self
                .scopes
                .range(Scope::Robot(1)..=Scope::Robot(254))
                .filter_map(|(_, index)| index.by_path.get(key.path()))
                .map(|&id| &self.slots[id as usize].entry)
                .fold(None, |best: Option<&Entry>, e| match best {
                    Some(b) if b.stamp >= e.stamp => Some(b),
                    _ => Some(e),
                }),
            scope => self.get_stored(scope, key.path()),
        }
    }

    /// [`Blackboard::get`], but only if the value is at most `max_age` old at `now`.
    pub fn get_fresher_than(&self, now: Instant, key: &Key, max_age: Duration) -> Option<&Entry> {
        self.get(key).filter(|e| e.age(now) <= max_age)
    }

    /// Every stored binding whose key matches `pattern`, in key order (local first,
    /// then by robot id, then by path). Keys come out as stored (`n.var.x`, never `*`).
    pub fn iter<'a>(&'a self, pattern: &'a Pattern) -> impl Iterator<Item = (Key, &'a Entry)> + 'a {
        self.scopes.iter().flat_map(move |(scope, index)| {
            index
                .ordered
                .iter()
                .filter(move |(path, _)| pattern.matches_parts(*scope, Kind::Var, path))
                .map(move |(_, &id)| {
                    let slot = &self.slots[id as usize];
                    (slot.key.clone(), &slot.entry)
                })
        })
    }

    /// The bindings this robot owns under `scope` (for the replica's refresh), in path
    /// order.
    pub(crate) fn scope_entries(&self, scope: Scope) -> impl Iterator<Item = (&String, &Entry)> {
        self.scopes.get(&scope).into_iter().flat_map(move |index| {
            index
                .ordered
                .iter()
                .map(move |(p, &id)| (p, &self.slots[id as usize].entry))
        })
    }

    /// One stored binding by scope and path.
    pub(crate) fn get_stored(&self, scope: Scope, path: &str) -> Option<&Entry> {
        self.find(scope, path)
            .map(|id| &self.slots[id as usize].entry)
    }

    /// Number of stored bindings.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether nothing is stored.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The next key whose value changed (inserted or set to a different value), oldest
    /// first. Changes are coalesced: a key appears at most once until drained.
    pub fn poll_change(&mut self) -> Option<Key> {
        let id = self.changes.pop_front()?;
        let slot = &mut self.slots[id as usize];
        slot.change_queued = false;
        Some(slot.key.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn k(s: &str) -> Key {
        Key::parse(s).unwrap()
    }
    fn t(ms: u64) -> Instant {
        Instant::from_micros(ms * 1000)
    }

    #[test]
    fn writing_a_global_sets_the_own_copy_and_reading_star_picks_the_newest() {
        let mut bb = Blackboard::new(2);
        let stored = bb
            .set(t(10), &k("*.var.ball.dist"), Value::Float(1.5))
            .unwrap();
        assert_eq!(stored.to_string(), "2.var.ball.dist");
        assert_eq!(
            bb.get(&k("2.var.ball.dist")).unwrap().value,
            Value::Float(1.5)
        );
        // Robot 5's copy arrives later by our clock: `*` now reads robot 5's.
        bb.apply_remote(5, 9, "ball.dist".into(), Value::Float(0.7), 1, t(20));
        let newest = bb.get(&k("*.var.ball.dist")).unwrap();
        assert_eq!((newest.owner, &newest.value), (5, &Value::Float(0.7)));
        assert_eq!(
            bb.get(&k("2.var.ball.dist")).unwrap().value,
            Value::Float(1.5),
            "each owner keeps its own copy"
        );
        assert!(bb.get(&k("local.var.ball.dist")).is_none());
    }

    #[test]
    fn other_robots_copies_and_talk_queues_cannot_be_set() {
        let mut bb = Blackboard::new(2);
        assert!(matches!(
            bb.set(t(0), &k("3.var.x"), Value::Int(1)),
            Err(SetError::NotOwner {
                owner: 3,
                me: 2,
                ..
            })
        ));
        assert!(matches!(
            bb.set(t(0), &k("*.talk.x"), Value::Int(1)),
            Err(SetError::TalkKey(_))
        ));
        assert!(bb.set(t(0), &k("2.var.x"), Value::Int(1)).is_ok());
    }

    #[test]
    fn older_versions_never_overwrite_newer_and_restarts_are_accepted() {
        let mut bb = Blackboard::new(1);
        let path = || "x".to_string();
        assert_eq!(
            bb.apply_remote(3, 100, path(), Value::Int(2), 2, t(5)),
            Applied::Inserted
        );
        assert_eq!(
            bb.apply_remote(3, 100, path(), Value::Int(1), 1, t(9)),
            Applied::Stale
        );
        assert_eq!(bb.get(&k("3.var.x")).unwrap().value, Value::Int(2));
        assert_eq!(
            bb.apply_remote(3, 100, path(), Value::Int(2), 2, t(3)),
            Applied::Refreshed
        );
        assert_eq!(
            bb.get(&k("3.var.x")).unwrap().stamp,
            t(3),
            "earliest stamp kept"
        );
        // Robot 3 restarted: version 1 of the new incarnation replaces version 2.
        assert_eq!(
            bb.apply_remote(3, 777, path(), Value::Int(9), 1, t(50)),
            Applied::Changed
        );
        let e = bb.get(&k("3.var.x")).unwrap();
        assert_eq!(
            (e.version, e.incarnation, &e.value),
            (1, 777, &Value::Int(9))
        );
    }

    #[test]
    fn freshness_uses_this_robots_stamps() {
        let mut bb = Blackboard::new(1);
        bb.set(t(100), &k("local.var.v"), Value::Bool(true))
            .unwrap();
        let key = k("local.var.v");
        assert!(bb
            .get_fresher_than(t(150), &key, Duration::from_millis(50))
            .is_some());
        assert!(bb
            .get_fresher_than(t(151), &key, Duration::from_millis(50))
            .is_none());
    }

    #[test]
    fn change_events_are_coalesced_per_key_and_skip_unchanged_writes() {
        let mut bb = Blackboard::new(1);
        let key = k("local.var.a");
        bb.set(t(0), &key, Value::Int(1)).unwrap();
        bb.set(t(1), &key, Value::Int(2)).unwrap();
        bb.set(t(2), &k("*.var.b"), Value::Int(2)).unwrap();
        assert_eq!(bb.poll_change(), Some(key.clone()));
        assert_eq!(bb.poll_change(), Some(k("1.var.b")));
        assert_eq!(bb.poll_change(), None);
        bb.set(t(3), &key, Value::Int(2)).unwrap();
        assert_eq!(bb.poll_change(), None, "same value: no event");
        assert_eq!(
            bb.get(&key).unwrap().version,
            3,
            "but the version still moves"
        );
    }

    #[test]
    fn iteration_filters_by_pattern_in_key_order() {
        let mut bb = Blackboard::new(1);
        bb.set(t(0), &k("*.var.machine.heuristic"), Value::Float(3.0))
            .unwrap();
        bb.set(t(0), &k("local.var.machine.heuristic"), Value::Float(1.0))
            .unwrap();
        bb.apply_remote(4, 1, "machine.heuristic".into(), Value::Float(2.0), 1, t(0));
        bb.apply_remote(2, 1, "machine.mode".into(), Value::Int(1), 1, t(0));
        let p = Pattern::parse("+.var.machine.heuristic").unwrap();
        let keys: Vec<String> = bb.iter(&p).map(|(k, _)| k.to_string()).collect();
        assert_eq!(
            keys,
            [
                "local.var.machine.heuristic",
                "1.var.machine.heuristic",
                "4.var.machine.heuristic"
            ]
        );
        let p = Pattern::parse("2.var.#").unwrap();
        assert_eq!(bb.iter(&p).count(), 1);
    }
}
