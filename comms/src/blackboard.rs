//! The blackboard: symbol → value bindings with owner, version and a timestamp on this
//! robot's clock (isocrob-2000 §3.1), usable on its own or inside a [`crate::Replica`].
//!
//! Storage holds `var` bindings only, under `local` (this robot's private values) or a
//! robot id (that robot's copy of a global value; this robot's own copies live under its
//! own id). `*` is a view: writing `*.var.x` writes the own copy, reading it returns the
//! copy with the newest timestamp. `talk` messages are not stored; they are delivered as
//! events by the replica.
//!
//! # Bounds
//!
//! Nothing a teammate (or a forger, without a team key) sends can grow the blackboard
//! without limit or pin a value forever ([`BoardLimits`]):
//! - at most `per_owner` bindings per robot and `remote` bindings of all other robots
//!   together; an update for a new key beyond them is refused ([`Applied::Refused`]) and
//!   nothing stored is lost; this robot's own global values obey `per_owner` too (the
//!   teammates would refuse more), its `local` values `local` ([`SetError::TooManyKeys`]);
//! - the first update of an owner's new incarnation (a restart) removes the bindings the
//!   owner's older incarnations left;
//! - a stored version its owner has not re-sent for `unconfirmed_after`, while lower
//!   versions of the same key keep arriving from the same incarnation, was not the
//!   owner's (every owner re-sends its values each refresh period): the arriving one
//!   replaces it. A late frame inside that window is still stale;
//! - the replica releases a departed owner's bindings after a grace period.
//!
//! Matching a pattern costs what it can match, not the blackboard's size: the scopes
//! and the literal start of the path (`2.var.ball.#`: robot 2's `ball` and `ball.…`) are
//! looked up in per-scope ordered indexes, and only those bindings are checked.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::ops::Bound;
use std::sync::Arc;
use std::time::Duration;

use thiserror::Error;

use crate::key::{Key, KeyError, KeyRef, Kind, Scope};
use crate::pattern::{PathSel, Pattern, ScopeSel};
use crate::time::Instant;
use crate::value::Value;

mod scopes;

use scopes::ScopeTable;

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
    /// A new key beyond the limit of its scope ([`BoardLimits::local`] for `local`,
    /// [`BoardLimits::per_owner`] for this robot's global values). Keys already bound
    /// can still be written.
    #[error("{key}: no room for a new key, {scope} already holds {limit} (the limit)")]
    TooManyKeys {
        /// The key as given.
        key: String,
        /// Where it would be stored (`local`, or this robot's id).
        scope: Scope,
        /// The limit.
        limit: usize,
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
    /// A key not held before, beyond [`BoardLimits::per_owner`] or
    /// [`BoardLimits::remote`]: ignored.
    Refused,
}

/// The bounds of a blackboard (the replica takes them from its
/// [`ReplicaConfig`](crate::ReplicaConfig)).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BoardLimits {
    /// Most bindings per robot (default 4096): another robot's copies, and this robot's
    /// own global values.
    pub per_owner: usize,
    /// Most bindings of all other robots together (default 65536).
    pub remote: usize,
    /// Most `local` bindings (default 65536).
    pub local: usize,
    /// A stored version not received again for this long while lower versions of the
    /// key arrive from the same incarnation is replaced by them (default 300 ms: the
    /// replica's `departed_after`).
    pub unconfirmed_after: Duration,
}

impl Default for BoardLimits {
    fn default() -> BoardLimits {
        BoardLimits {
            per_owner: 4096,
            remote: 65536,
            local: 65536,
            unconfirmed_after: Duration::from_millis(300),
        }
    }
}

/// What the bounds did, counted (the replica mirrors them into its stats).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct BoardCounts {
    /// Updates of new keys refused by a limit.
    pub(crate) refused: u64,
    /// Stored versions never re-sent by their owner, replaced by a lower one.
    pub(crate) unconfirmed_replaced: u64,
    /// Bindings an owner's older incarnation left, removed when a newer one published.
    pub(crate) superseded: u64,
    /// Bindings of departed owners released.
    pub(crate) released: u64,
}

/// A stored binding, where it is stored, whether a change event for it is queued (so an
/// undrained queue holds each binding at most once and stays bounded by their number),
/// and when its version was last received (or written).
#[derive(Clone, Debug)]
struct Slot {
    scope: Scope,
    path: Arc<str>,
    entry: Entry,
    change_queued: bool,
    confirmed: Instant,
}

impl Slot {
    fn key(&self) -> Key {
        Key::from_shared(self.scope, Kind::Var, self.path.clone())
    }
}

/// Where a binding lives in [`Blackboard::slots`]. Ids of removed bindings are reused,
/// and removal takes them out of every index and the change queue first.
pub(crate) type SlotId = u32;

/// The bindings of one scope, found two ways: by hash for the per-update lookups of the
/// hot path (a B-tree walk compares the path against a dozen or more stored paths, and
/// paths of one robot often share long prefixes), and in key order for iteration and
/// prefix lookups. Both share one allocation of each path.
#[derive(Clone, Debug, Default)]
struct ScopeIndex {
    by_path: HashMap<Arc<str>, SlotId, PathHasher>,
    ordered: BTreeMap<Arc<str>, SlotId>,
    /// A robot's scope: the incarnation whose update came last.
    incarnation: Option<u64>,
}

/// The hasher of path lookups: foldhash, several times faster than std's SipHash on
/// short paths (a lookup per update received, per write, per value sent). Seeded per
/// process like std's, so paths a sender chooses cannot be made to collide in advance;
/// only lookups use it (iteration is by the ordered index), so the seed changes no
/// outcome.
pub(crate) type PathHasher = foldhash::fast::RandomState;

/// The set of bindings.
#[derive(Clone, Debug)]
pub struct Blackboard {
    robot_id: u8,
    incarnation: u64,
    slots: Vec<Option<Slot>>,
    free: Vec<SlotId>,
    len: usize,
    /// Bindings of other robots.
    remote_len: usize,
    scopes: ScopeTable,
    /// Per path held in robots' scopes: (robot, slot) of each, in robot order, so that
    /// [`Blackboard::robots_at`] reads every robot's binding of a path after one lookup
    /// instead of one per scope (the arbitration asks several times per control tick;
    /// the walk missed the cache in every scope's table and path).
    robots_by_path: HashMap<Arc<str>, Vec<(u8, SlotId)>, PathHasher>,
    changes: VecDeque<SlotId>,
    limits: BoardLimits,
    /// The latest instant this blackboard was told about (writes, stamps, the replica's
    /// inputs): the reception time of a remote update.
    clock: Instant,
    counts: BoardCounts,
}

impl Blackboard {
    /// An empty blackboard for robot `robot_id` (1..=254; writes of `*.var.x` land in
    /// `robot_id.var.x`), with the default [`BoardLimits`].
    pub fn new(robot_id: u8) -> Blackboard {
        Blackboard::with_limits(robot_id, BoardLimits::default())
    }

    /// An empty blackboard with the given bounds.
    pub fn with_limits(robot_id: u8, limits: BoardLimits) -> Blackboard {
        Blackboard {
            robot_id,
            incarnation: 0,
            slots: Vec::new(),
            free: Vec::new(),
            len: 0,
            remote_len: 0,
            scopes: ScopeTable::default(),
            robots_by_path: HashMap::default(),
            changes: VecDeque::new(),
            limits,
            clock: Instant::ZERO,
            counts: BoardCounts::default(),
        }
    }

    pub(crate) fn set_incarnation(&mut self, incarnation: u64) {
        self.incarnation = incarnation;
    }

    /// The replica's latest `now`: remote updates applied next were received then.
    pub(crate) fn advance_clock(&mut self, now: Instant) {
        self.clock = self.clock.max(now);
    }

    pub(crate) fn counts(&self) -> BoardCounts {
        self.counts
    }

    /// The bounds.
    pub fn limits(&self) -> &BoardLimits {
        &self.limits
    }

    /// This robot's id.
    pub fn robot_id(&self) -> u8 {
        self.robot_id
    }

    fn slot(&self, id: SlotId) -> Option<&Slot> {
        self.slots.get(id as usize).and_then(Option::as_ref)
    }

    fn slot_mut(&mut self, id: SlotId) -> Option<&mut Slot> {
        self.slots.get_mut(id as usize).and_then(Option::as_mut)
    }

    fn find(&self, scope: Scope, path: &str) -> Option<SlotId> {
        self.scopes.get(scope)?.by_path.get(path).copied()
    }

    fn is_remote(&self, scope: Scope) -> bool {
        matches!(scope, Scope::Robot(n) if n != self.robot_id)
    }

    /// Bindings stored under `scope`.
    fn scope_len(&self, scope: Scope) -> usize {
        self.scopes.get(scope).map_or(0, |i| i.by_path.len())
    }

    /// Stores a new binding (the caller checked the limits). `None` only if the slot
    /// numbers ran out, which the limits keep far away.
    fn insert(&mut self, scope: Scope, path: &str, entry: Entry) -> Option<SlotId> {
        let id = match self.free.pop() {
            Some(id) => id,
            None => SlotId::try_from(self.slots.len()).ok()?,
        };
        let path: Arc<str> = Arc::from(path);
        let slot = Slot {
            scope,
            path: path.clone(),
            confirmed: self.clock,
            entry,
            change_queued: true,
        };
        match self.slots.get_mut(id as usize) {
            Some(free) => *free = Some(slot),
            None => self.slots.push(Some(slot)),
        }
        if let Scope::Robot(robot) = scope {
            let held = self.robots_by_path.entry(path.clone()).or_default();
            let k = held.partition_point(|&(other, _)| other < robot);
            held.insert(k, (robot, id));
        }
        let index = self.scopes.get_or_insert(scope);
        index.by_path.insert(path.clone(), id);
        index.ordered.insert(path, id);
        self.len += 1;
        if self.is_remote(scope) {
            self.remote_len += 1;
        }
        self.changes.push_back(id);
        Some(id)
    }

    /// Removes the bindings of `scope` for which `doomed` holds; returns how many.
    fn remove_where(
        &mut self,
        scope: Scope,
        mut doomed: impl FnMut(&str, &Entry) -> bool,
    ) -> usize {
        let remote = self.is_remote(scope);
        let Some(index) = self.scopes.get_mut(scope) else {
            return 0;
        };
        let slots = &mut self.slots;
        let robots_by_path = &mut self.robots_by_path;
        let robot_scope = matches!(scope, Scope::Robot(_));
        let mut removed = Vec::new();
        let mut queued = false;
        index.ordered.retain(|path, &mut id| {
            let Some(slot) = slots.get(id as usize).and_then(Option::as_ref) else {
                return false;
            };
            if !doomed(path, &slot.entry) {
                return true;
            }
            queued |= slot.change_queued;
            if let Some(held) = robot_scope
                .then(|| robots_by_path.get_mut(&**path))
                .flatten()
            {
                held.retain(|&(_, other)| other != id);
                if held.is_empty() {
                    robots_by_path.remove(&**path);
                }
            }
            slots[id as usize] = None;
            removed.push(id);
            false
        });
        if removed.is_empty() {
            return 0;
        }
        index
            .by_path
            .retain(|_, id| slots.get(*id as usize).is_some_and(Option::is_some));
        if index.by_path.is_empty() {
            self.scopes.remove(scope);
        }
        if queued {
            // Before the ids are reused: a queued change of a removed binding goes too.
            self.changes
                .retain(|id| slots.get(*id as usize).is_some_and(Option::is_some));
        }
        let n = removed.len();
        self.free.extend(removed);
        self.len -= n;
        if remote {
            self.remote_len -= n;
        }
        n
    }

    /// Removes every binding of robot `owner` (another robot; this robot's own values
    /// stay); returns how many. The replica calls it for a robot departed longer than
    /// its grace period.
    pub(crate) fn release_owner(&mut self, owner: u8) -> usize {
        if owner == self.robot_id {
            return 0;
        }
        let n = self.remove_where(Scope::Robot(owner), |_, _| true);
        self.counts.released += n as u64;
        n
    }

    /// Number of bindings stored for robot `owner`.
    pub fn owner_len(&self, owner: u8) -> usize {
        self.scope_len(Scope::Robot(owner))
    }

    /// Writes a value at `now`. `local.var.x` stays here; `*.var.x` and
    /// `<own id>.var.x` set this robot's own copy (returned: the key it is stored under).
    /// Every write bumps the version, even with an unchanged value, so freshness
    /// propagates; a change event is queued only when the value differs. A new key
    /// beyond its scope's limit is refused ([`SetError::TooManyKeys`]).
    pub fn set(&mut self, now: Instant, key: &Key, value: Value) -> Result<Key, SetError> {
        let id = self.write(now, key.as_parts(), value)?;
        Ok(self.slot(id).map_or_else(|| key.clone(), |slot| slot.key()))
    }

    /// [`Blackboard::set`] without building the stored key: the binding's slot.
    pub(crate) fn write(
        &mut self,
        now: Instant,
        key: KeyRef<'_>,
        value: Value,
    ) -> Result<SlotId, SetError> {
        self.write_checked(now, key, value, true)
    }

    /// The binding in slot `id` (as [`Blackboard::write`] returned it) was set at `stamp`
    /// (earlier than its write: see `Replica::set_key_built`); nothing if it is gone.
    pub(crate) fn restamp(&mut self, id: SlotId, stamp: Instant) {
        if let Some(slot) = self.slot_mut(id) {
            slot.entry.stamp = stamp;
        }
    }

    /// A write of the replica's own bookkeeping (`local.var.huddle.stats.*`), which a
    /// client's keys filling the local limit must not stop.
    pub(crate) fn write_unlimited(
        &mut self,
        now: Instant,
        key: KeyRef<'_>,
        value: Value,
    ) -> Result<SlotId, SetError> {
        self.write_checked(now, key, value, false)
    }

    fn write_checked(
        &mut self,
        now: Instant,
        key: KeyRef<'_>,
        value: Value,
        limited: bool,
    ) -> Result<SlotId, SetError> {
        let scope = self.storage_scope(key)?;
        self.advance_clock(now);
        let (robot_id, incarnation) = (self.robot_id, self.incarnation);
        let Some(id) = self.find(scope, key.path) else {
            let limit = match scope {
                Scope::Local => self.limits.local,
                _ => self.limits.per_owner,
            };
            let full = limited && self.scope_len(scope) >= limit;
            let entry = Entry {
                value,
                owner: robot_id,
                version: 1,
                incarnation,
                stamp: now,
            };
            return match full {
                false => self.insert(scope, key.path, entry),
                true => None,
            }
            .ok_or_else(|| SetError::TooManyKeys {
                key: key.to_string(),
                scope,
                limit,
            });
        };
        let clock = self.clock;
        let Some(slot) = self.slot_mut(id) else {
            return Ok(id); // indexed slots are stored
        };
        let e = &mut slot.entry;
        let changed = !e.value.same_as(&value);
        e.value = value;
        e.version += 1;
        e.stamp = now;
        e.incarnation = incarnation;
        slot.confirmed = clock;
        if changed && !slot.change_queued {
            slot.change_queued = true;
            self.changes.push_back(id);
        }
        Ok(id)
    }

    /// Where a write of `key` goes, or why it may not be written here.
    pub(crate) fn storage_scope(&self, key: KeyRef<'_>) -> Result<Scope, SetError> {
        if key.kind == Kind::Talk {
            return Err(SetError::TalkKey(key.to_string()));
        }
        match key.scope {
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
    /// once (a restarted robot), and the first update of an incarnation other than the
    /// last one heard from `owner` removes every binding `owner`'s other incarnations
    /// left. Deciding which incarnation is current is the caller's job (the replica
    /// drops frames from retired incarnations). For the same version the earlier stamp
    /// wins: the copy that travelled fastest estimates the set time best. See the
    /// module docs for the limits and for versions the owner never re-sends.
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
        // Received now (the replica's input time); a bare blackboard knows the stamp.
        self.advance_clock(stamp);
        let now = self.clock;
        // One lookup of the scope finds the binding too, unless the owner restarted.
        let mut held = None;
        let mut restarted = false;
        if let Some(index) = self.scopes.get_mut(scope) {
            let previous = index.incarnation.replace(incarnation);
            restarted = previous.is_some_and(|p| p != incarnation);
            held = index.by_path.get(path).copied();
        }
        if restarted {
            // The key being updated stays: the update replaces it below.
            let n = self.remove_where(scope, |p, e| e.incarnation != incarnation && p != path);
            self.counts.superseded += n as u64;
            held = self.find(scope, path);
        }
        let fresh = Entry {
            value,
            owner,
            version,
            incarnation,
            stamp,
        };
        let Some(id) = held else {
            let full = self.scope_len(scope) >= self.limits.per_owner
                || (self.is_remote(scope) && self.remote_len >= self.limits.remote);
            if full || self.insert(scope, path, fresh).is_none() {
                self.counts.refused += 1;
                return Applied::Refused;
            }
            if let Some(index) = self.scopes.get_mut(scope) {
                index.incarnation = Some(incarnation);
            }
            return Applied::Inserted;
        };
        let window = self.limits.unconfirmed_after;
        let Some(slot) = self.slot_mut(id) else {
            return Applied::Refused; // indexed slots are stored
        };
        let e = &mut slot.entry;
        let mut unconfirmed = false;
        if e.incarnation == incarnation && version < e.version {
            if now.saturating_duration_since(slot.confirmed) <= window {
                return Applied::Stale;
            }
            // Never re-sent by its owner, who keeps sending lower versions: not its.
            unconfirmed = true;
        }
        if e.incarnation == incarnation && version == e.version {
            e.stamp = e.stamp.min(stamp);
            slot.confirmed = now;
            return Applied::Refreshed;
        }
        let changed = !e.value.same_as(&fresh.value);
        *e = fresh;
        slot.confirmed = now;
        let queue = changed && !slot.change_queued;
        if queue {
            slot.change_queued = true;
        }
        if unconfirmed {
            self.counts.unconfirmed_replaced += 1;
        }
        if queue {
            self.changes.push_back(id);
        }
        if changed {
            Applied::Changed
        } else {
            Applied::Refreshed
        }
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
                .robots()
                .filter_map(|index| index.by_path.get(key.path()))
                .filter_map(|&id| self.slot(id))
                .map(|slot| &slot.entry)
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
    /// Only the bindings in the scopes the pattern names and under the literal start of
    /// its path are looked at.
    pub fn iter<'a>(&'a self, pattern: &'a Pattern) -> impl Iterator<Item = (Key, &'a Entry)> + 'a {
        self.candidates(pattern)
            .filter(move |slot| pattern.matches_parts(slot.scope, Kind::Var, &slot.path))
            .map(|slot| (slot.key(), &slot.entry))
    }

    /// The bindings [`Blackboard::iter`] looks at for `pattern`, in key order.
    fn candidates<'a>(&'a self, pattern: &Pattern) -> impl Iterator<Item = &'a Slot> + 'a {
        let plan = pattern.var_plan();
        let scopes: Box<dyn Iterator<Item = &'a ScopeIndex> + 'a> = match plan.scopes {
            ScopeSel::All => Box::new(self.scopes.values()),
            ScopeSel::Robots => Box::new(self.scopes.robots()),
            ScopeSel::Some(list) => Box::new(list.into_iter().filter_map(|s| self.scopes.get(s))),
        };
        let path = plan.path;
        scopes
            .flat_map(move |index| -> Box<dyn Iterator<Item = SlotId> + 'a> {
                match &path {
                    PathSel::Any => Box::new(index.ordered.values().copied()),
                    PathSel::Exact(p) => {
                        Box::new(index.by_path.get(p.as_str()).copied().into_iter())
                    }
                    PathSel::Prefix { literal, with_self } => {
                        let itself = with_self
                            .then(|| index.by_path.get(literal.as_str()).copied())
                            .flatten();
                        // `literal.` up to `literal/`: '/' follows '.' in ASCII.
                        let (low, high) = (format!("{literal}."), format!("{literal}/"));
                        let below = index
                            .ordered
                            .range::<str, _>((
                                Bound::Included(low.as_str()),
                                Bound::Excluded(high.as_str()),
                            ))
                            .map(|(_, &id)| id);
                        Box::new(itself.into_iter().chain(below))
                    }
                }
            })
            .filter_map(move |id| self.slot(id))
    }

    /// How many bindings [`Blackboard::iter`] looks at for `pattern` (its cost).
    pub fn visited(&self, pattern: &Pattern) -> usize {
        self.candidates(pattern).count()
    }

    /// The bindings this robot owns under `scope` (for the replica's refresh), in path
    /// order.
    pub(crate) fn scope_entries(&self, scope: Scope) -> impl Iterator<Item = (&str, &Entry)> {
        self.scopes.get(scope).into_iter().flat_map(move |index| {
            index
                .ordered
                .iter()
                .filter_map(move |(p, &id)| Some((&**p, &self.slot(id)?.entry)))
        })
    }

    /// The path of the binding in slot `id`, shared (for the replica's queue of changed
    /// values: no copy of the path per write).
    pub(crate) fn shared_path(&self, id: SlotId) -> Option<&Arc<str>> {
        self.slot(id).map(|slot| &slot.path)
    }

    /// Every robot's own binding of `path`, in robot order: what [`Blackboard::iter`]
    /// gives for `+.var.<path>` in the robots' scopes, without building a key per binding
    /// (the arbitration reads its claims this way several times per control tick).
    pub(crate) fn robots_at<'a>(
        &'a self,
        path: &'a str,
    ) -> impl Iterator<Item = (u8, &'a Entry)> + 'a {
        self.robots_by_path
            .get(path)
            .map_or(&[][..], Vec::as_slice)
            .iter()
            .filter_map(move |&(robot, id)| Some((robot, &self.slot(id)?.entry)))
    }

    /// The binding of `path` in `scope`, read from slot `id` when that slot still holds
    /// it (a slot remembered since a write or a change: no lookup), else looked up.
    pub(crate) fn get_at(&self, id: SlotId, scope: Scope, path: &Arc<str>) -> Option<&Entry> {
        self.at_slot(id, scope, path)
            .or_else(|| self.get_stored(scope, path))
    }

    /// The binding in slot `id` if that slot still holds `path` in `scope`, else `None`
    /// (no lookup). The path is the blackboard's own (from [`Blackboard::shared_path`], a
    /// change's key, or a slot remembered with it), so the same allocation means the same
    /// binding: a removed binding's slot reused for another path has another one, and the
    /// caller's copy keeps this one alive.
    pub(crate) fn at_slot(&self, id: SlotId, scope: Scope, path: &Arc<str>) -> Option<&Entry> {
        self.slot(id)
            .filter(|slot| slot.scope == scope && Arc::ptr_eq(&slot.path, path))
            .map(|slot| &slot.entry)
    }

    /// One stored binding by scope and path.
    pub(crate) fn get_stored(&self, scope: Scope, path: &str) -> Option<&Entry> {
        self.find(scope, path)
            .and_then(|id| self.slot(id))
            .map(|slot| &slot.entry)
    }

    /// Number of stored bindings.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether nothing is stored.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The next key whose value changed (inserted or set to a different value), oldest
    /// first. Changes are coalesced: a key appears at most once until drained. A
    /// binding removed before its change was drained is not reported.
    pub fn poll_change(&mut self) -> Option<Key> {
        self.poll_change_at().map(|(key, _)| key)
    }

    /// [`Blackboard::poll_change`] with the binding's slot, for [`Blackboard::get_at`].
    pub(crate) fn poll_change_at(&mut self) -> Option<(Key, SlotId)> {
        while let Some(id) = self.changes.pop_front() {
            if let Some(slot) = self.slot_mut(id) {
                slot.change_queued = false;
                return Some((slot.key(), id));
            }
        }
        None
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

    #[test]
    fn a_version_its_owner_never_resends_is_replaced_by_the_versions_it_sends() {
        let mut bb = Blackboard::new(1);
        let up = |bb: &mut Blackboard, v: i64, version: u64, at: u64| {
            bb.apply_remote(3, 100, "x".into(), Value::Int(v), version, t(at))
        };
        assert_eq!(up(&mut bb, 1, 10, 0), Applied::Inserted);
        // A forged (or corrupted) version far ahead of the owner's.
        assert_eq!(up(&mut bb, 666, u64::MAX, 5), Applied::Changed);
        // The owner keeps sending its own, lower versions: stale for a while, as a late
        // frame would be...
        assert_eq!(up(&mut bb, 2, 11, 100), Applied::Stale);
        assert_eq!(up(&mut bb, 2, 11, 305), Applied::Stale, "within the window");
        assert_eq!(bb.get(&k("3.var.x")).unwrap().value, Value::Int(666));
        // ...until the forged version has gone unconfirmed for longer than the window.
        assert_eq!(up(&mut bb, 2, 11, 306), Applied::Changed);
        assert_eq!(bb.get(&k("3.var.x")).unwrap().value, Value::Int(2));
        assert_eq!(bb.counts().unconfirmed_replaced, 1);
        // A real newer version, re-sent by its owner, is never undone by a late frame.
        assert_eq!(up(&mut bb, 3, 12, 400), Applied::Changed);
        for at in [500, 600, 700, 800] {
            assert_eq!(up(&mut bb, 3, 12, at), Applied::Refreshed);
            assert_eq!(up(&mut bb, 2, 11, at), Applied::Stale, "late copy at {at}");
        }
    }

    #[test]
    fn a_new_incarnation_removes_what_the_old_one_left() {
        let mut bb = Blackboard::new(1);
        for path in ["a", "b", "c"] {
            bb.apply_remote(3, 100, path.into(), Value::Int(1), 5, t(0));
        }
        bb.apply_remote(4, 7, "a".into(), Value::Int(1), 1, t(0));
        // Robot 3 restarted and publishes only `b`.
        assert_eq!(
            bb.apply_remote(3, 200, "b".into(), Value::Int(2), 1, t(10)),
            Applied::Changed
        );
        assert!(bb.get(&k("3.var.a")).is_none());
        assert!(bb.get(&k("3.var.c")).is_none());
        assert_eq!(bb.get(&k("3.var.b")).unwrap().incarnation, 200);
        assert!(bb.get(&k("4.var.a")).is_some(), "other owners keep theirs");
        assert_eq!((bb.len(), bb.counts().superseded), (2, 2));
        // A change queued for a removed binding is not reported.
        let changes: Vec<String> = std::iter::from_fn(|| bb.poll_change())
            .map(|k| k.to_string())
            .collect();
        assert_eq!(changes, ["3.var.b", "4.var.a"]);
    }

    #[test]
    fn keys_beyond_the_limits_are_refused_and_nothing_stored_is_lost() {
        let limits = BoardLimits {
            per_owner: 3,
            remote: 5,
            local: 2,
            ..BoardLimits::default()
        };
        let mut bb = Blackboard::with_limits(1, limits);
        let up = |bb: &mut Blackboard, owner: u8, path: &str, version: u64| {
            bb.apply_remote(owner, 9, path.into(), Value::Int(1), version, t(0))
        };
        for p in ["a", "b", "c"] {
            assert_eq!(up(&mut bb, 2, p, 1), Applied::Inserted);
        }
        assert_eq!(up(&mut bb, 2, "d", 1), Applied::Refused, "per owner");
        assert_eq!(
            up(&mut bb, 2, "a", 2),
            Applied::Refreshed,
            "held keys still update"
        );
        assert_eq!(up(&mut bb, 3, "a", 1), Applied::Inserted);
        assert_eq!(up(&mut bb, 3, "b", 1), Applied::Inserted);
        assert_eq!(
            up(&mut bb, 3, "c", 1),
            Applied::Refused,
            "all owners together"
        );
        assert_eq!(bb.counts().refused, 2);
        assert_eq!(bb.len(), 5);
        // This robot's own values and local values have limits of their own.
        bb.set(t(0), &k("local.var.a"), Value::Int(1)).unwrap();
        bb.set(t(0), &k("local.var.b"), Value::Int(1)).unwrap();
        assert!(matches!(
            bb.set(t(0), &k("local.var.c"), Value::Int(1)),
            Err(SetError::TooManyKeys {
                scope: Scope::Local,
                limit: 2,
                ..
            })
        ));
        bb.set(t(1), &k("local.var.a"), Value::Int(2)).unwrap();
        for p in ["a", "b", "c"] {
            bb.set(t(0), &k(&format!("*.var.{p}")), Value::Int(1))
                .unwrap();
        }
        assert!(matches!(
            bb.set(t(0), &k("*.var.d"), Value::Int(1)),
            Err(SetError::TooManyKeys { limit: 3, .. })
        ));
        // Releasing an owner makes room, and the freed slots are reused.
        assert_eq!(bb.release_owner(2), 3);
        assert_eq!(bb.release_owner(1), 0, "never this robot's own values");
        assert_eq!(up(&mut bb, 3, "c", 1), Applied::Inserted);
        assert_eq!(bb.len(), 2 + 3 + 3);
        assert!(bb.slots.len() <= 11);
    }

    #[test]
    fn a_pattern_visits_only_what_its_scope_and_literal_prefix_can_match() {
        let limits = BoardLimits {
            per_owner: usize::MAX,
            remote: usize::MAX,
            ..BoardLimits::default()
        };
        let mut bb = Blackboard::with_limits(1, limits);
        // 20,000 keys of other robots and of robot 2 outside `ball`, 4 inside it.
        for owner in 2..=11u8 {
            for i in 0..2000 {
                let path = format!("junk{i}.x");
                bb.apply_remote(owner, 5, path, Value::Int(0), 1, t(0));
            }
        }
        for path in ["ball", "ball.x", "ball.y.z", "ballast", "ball-pit"] {
            bb.apply_remote(2, 5, path.into(), Value::Int(1), 1, t(0));
        }
        let p = Pattern::parse("2.var.ball.#").unwrap();
        let keys: Vec<String> = bb.iter(&p).map(|(k, _)| k.to_string()).collect();
        assert_eq!(keys, ["2.var.ball", "2.var.ball.x", "2.var.ball.y.z"]);
        assert_eq!(bb.visited(&p), 3, "of {} bindings", bb.len());
        let p = Pattern::parse("+.var.ball.+").unwrap();
        assert_eq!(bb.iter(&p).count(), 1);
        assert_eq!(bb.visited(&p), 2, "robot 2's ball.x and ball.y.z");
        let p = Pattern::parse("*.var.junk7.x").unwrap();
        assert_eq!(bb.iter(&p).count(), 10);
        assert_eq!(bb.visited(&p), 10, "one lookup per robot");
        assert_eq!(bb.visited(&Pattern::parse("2.talk.#").unwrap()), 0);
        // Wildcards up front still scan what they must, and match the same as before.
        let p = Pattern::parse("+.var.+.x").unwrap();
        assert_eq!(bb.iter(&p).count(), 20_001);
        assert_eq!(bb.visited(&p), bb.len());
    }

    #[test]
    fn a_remembered_slot_reads_its_binding_and_a_reused_one_is_looked_past() {
        let mut bb = Blackboard::new(1);
        bb.apply_remote(3, 9, "ball".into(), Value::Int(3), 1, t(0));
        let (key, slot) = bb.poll_change_at().expect("inserted");
        let read = |bb: &Blackboard| bb.get_at(slot, key.scope(), key.shared_path()).cloned();
        assert_eq!(read(&bb).map(|e| e.value), Some(Value::Int(3)));
        // Robot 3 is released and its slot goes to robot 4's `pose`: the remembered slot
        // no longer holds robot 3's `ball`, and nothing is read from it.
        assert_eq!(bb.release_owner(3), 1);
        bb.apply_remote(4, 9, "pose".into(), Value::Int(4), 1, t(1));
        let (pose, reused) = bb.poll_change_at().expect("inserted");
        assert_eq!((pose.to_string(), reused), ("4.var.pose".to_string(), slot));
        assert_eq!(read(&bb), None, "robot 3's ball is gone");
        // Robot 3 comes back: its `ball` is found by its path, in whatever slot.
        bb.apply_remote(3, 10, "ball".into(), Value::Int(5), 1, t(2));
        assert_eq!(read(&bb).map(|e| e.value), Some(Value::Int(5)));
        assert_eq!(
            bb.get_at(reused, Scope::Robot(4), pose.shared_path())
                .map(|e| &e.value),
            Some(&Value::Int(4))
        );
    }

    mod robots_at {
        use super::*;
        use crate::Pattern;
        use proptest::prelude::*;

        const PATHS: [&str; 3] = ["machine", "machine.heuristic", "machine.heuristic.x"];

        #[derive(Clone, Debug)]
        enum Op {
            /// Robot, incarnation, path, version.
            Remote(u8, u64, usize, u64),
            Release(u8),
            Own(usize),
            Local(usize),
        }

        fn op() -> impl Strategy<Value = Op> {
            prop_oneof![
                4 => (1u8..=6, 1u64..=3, 0..PATHS.len(), 1u64..=4)
                    .prop_map(|(r, inc, p, v)| Op::Remote(r, inc, p, v)),
                1 => (1u8..=6).prop_map(Op::Release),
                1 => (0..PATHS.len()).prop_map(Op::Own),
                1 => (0..PATHS.len()).prop_map(Op::Local),
            ]
        }

        proptest! {
            /// Robots join, restart under new incarnations (their old bindings go), are
            /// released, and fill their scope to its limit; all the while every robot's
            /// binding of a path is what the pattern `+.var.<path>` finds in the robots'
            /// scopes, in robot order (`+` also matches `local`, which `robots_at` skips).
            #[test]
            fn robots_at_finds_what_the_pattern_finds(
                ops in proptest::collection::vec(op(), 0..60),
            ) {
                let limits = BoardLimits { per_owner: 2, ..BoardLimits::default() };
                let mut bb = Blackboard::with_limits(3, limits);
                for (k, op) in ops.iter().enumerate() {
                    let at = t(10 * k as u64);
                    match *op {
                        Op::Remote(r, inc, p, v) => {
                            let value = Value::Int(k as i64);
                            bb.apply_remote(r, inc, PATHS[p].into(), value, v, at);
                        }
                        Op::Release(r) => {
                            bb.release_owner(r);
                        }
                        Op::Own(p) => {
                            let _ = bb.set(at, &k_of("*", p), Value::Int(k as i64));
                        }
                        Op::Local(p) => {
                            let _ = bb.set(at, &k_of("local", p), Value::Int(k as i64));
                        }
                    }
                    for path in PATHS {
                        let pattern = Pattern::parse(&format!("+.var.{path}")).unwrap();
                        let want: Vec<(u8, *const Entry)> = bb
                            .iter(&pattern)
                            .filter_map(|(key, e)| match key.scope() {
                                Scope::Robot(r) => Some((r, e as *const Entry)),
                                _ => None,
                            })
                            .collect();
                        let got: Vec<(u8, *const Entry)> = bb
                            .robots_at(path)
                            .map(|(r, e)| (r, e as *const Entry))
                            .collect();
                        prop_assert_eq!(got, want, "{} after {:?}", path, &ops[..=k]);
                    }
                }
            }
        }

        fn k_of(scope: &str, p: usize) -> Key {
            k(&format!("{scope}.var.{}", PATHS[p]))
        }
    }
}
