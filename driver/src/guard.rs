//! Write guards: a check that a relay client's `SETV` of one key must pass before it is
//! written, so that a key can be a command (`local.var.audio.say`) whose bad values get
//! an `ERR` line instead of a silent `OK`; and the daemon's own keys, which clients may
//! read but not write (`ERR 423`).
//!
//! **The daemon's own keys.** A part of the daemon that writes a family of `local` keys
//! owns it while it runs: the team layer `local.var.team.*` (its decisions), the
//! GameController listener `local.var.gc.*` (the game's state, written only when the GC's
//! packet changes it), and the driver itself `local.var.huddle.*` (its counters). A
//! client's write there would make every other program on the robot read a false team
//! decision, game state or count, so the relay refuses it ([`crate::Handle::reserve`], checked
//! by [`GuardedBoard`]); the C node's set calls refuse the same keys with
//! [`read_only_owner`]. The parts' own writes (through a [`crate::Handle`] or the
//! replica) are not checked. Without the part (`--no-team-layer`, no listener) its
//! family is an ordinary local key, for a program that runs its own.

use std::any::Any;
use std::cell::RefCell;
use std::rc::{Rc, Weak};

use comms::relay::{Board, ErrCode, Rejected};
use comms::{Entry, Instant, Key, Kind, Pattern, Replica, Scope, Value};

/// The team layer's outputs (`driver::team`), its while it runs.
pub const TEAM_KEYS: &str = "local.var.team.#";
/// The GameController listener's keys, its while it runs.
pub const GC_KEYS: &str = "local.var.gc.#";
/// The daemon's counters (`huddle stats`), always its own.
pub const COUNTER_KEYS: &str = "local.var.huddle.#";

/// Who writes the daemon's own `key`, if it is one of them: `team` and `gc` say whether
/// the team layer and the GameController listener run (their families are plain keys
/// otherwise); the counters are always the daemon's. The rule every front door applies
/// to a client's write (the relay through [`crate::Handle::reserve`], the C node directly).
pub fn read_only_owner(key: &Key, team: bool, gc: bool) -> Option<&'static str> {
    if key.scope() != Scope::Local || key.kind() != Kind::Var {
        return None;
    }
    let first = key.path().split('.').next().unwrap_or("");
    match first {
        "huddle" => Some(COUNTERS_OWNER),
        "team" if team => Some(TEAM_OWNER),
        "gc" if gc => Some(GC_OWNER),
        _ => None,
    }
}

/// Who writes [`TEAM_KEYS`], as a refusal names it.
pub const TEAM_OWNER: &str = "the team layer (its inputs are local.var.robot.*)";
/// Who writes [`GC_KEYS`].
pub const GC_OWNER: &str = "the GameController listener, from the GC's packets";
/// Who writes [`COUNTER_KEYS`].
pub const COUNTERS_OWNER: &str = "the daemon (its counters)";

/// The refusal of a client's write of `key`, which `owner` writes.
pub fn read_only(key: &Key, owner: &str) -> Rejected {
    Rejected {
        code: ErrCode::ReadOnly,
        text: format!("{key} is written by {owner}; clients may read it, not write it"),
    }
}

/// A family of the daemon's own keys and who writes it, shared (weakly) with the driver.
pub(crate) struct ReadOnlySlot {
    pub(crate) pattern: Pattern,
    pub(crate) owner: &'static str,
}

/// What a guard runs on a client's value: `Ok` lets the write through, `Err` is the
/// client's `ERR` line and nothing is written.
pub(crate) type Check = dyn FnMut(&Value) -> Result<(), Rejected>;

/// A guarded key and its check, shared (weakly) with the driver.
pub(crate) struct GuardSlot {
    pub(crate) key: Key,
    pub(crate) check: RefCell<Box<Check>>,
}

/// A check registered with [`crate::Handle::guard`], or a family of keys made the
/// daemon's own with [`crate::Handle::reserve`]; dropping it removes it.
pub struct Guard {
    _slot: Rc<dyn Any>,
}

impl Guard {
    pub(crate) fn new(slot: Rc<dyn Any>) -> Guard {
        Guard { _slot: slot }
    }
}

/// The replica as a relay session sees it, with the guards in front of its writes.
pub(crate) struct GuardedBoard<'a> {
    pub(crate) replica: &'a mut Replica,
    pub(crate) guards: &'a [Weak<GuardSlot>],
    pub(crate) read_only: &'a [Weak<ReadOnlySlot>],
    /// Writes refused because the key is the daemon's own.
    pub(crate) refused: &'a mut u64,
    /// `CLOK`s refused because the GameController sets the game clock (`ERR 424`).
    pub(crate) clock_refused: &'a mut u64,
}

impl GuardedBoard<'_> {
    /// The daemon's own keys first (nothing else runs for them), then the key's checks.
    fn check(&mut self, key: &Key, value: &Value) -> Result<(), Rejected> {
        let owner = read_only_owner(key, false, false).or_else(|| {
            self.read_only
                .iter()
                .filter_map(Weak::upgrade)
                .find(|slot| slot.pattern.matches(key))
                .map(|slot| slot.owner)
        });
        if let Some(owner) = owner {
            *self.refused += 1;
            return Err(read_only(key, owner));
        }
        for slot in self.guards.iter().filter_map(Weak::upgrade) {
            if slot.key == *key {
                (slot.check.borrow_mut())(value)?;
            }
        }
        Ok(())
    }
}

impl Board for GuardedBoard<'_> {
    fn robot_id(&self) -> u8 {
        Board::robot_id(&*self.replica)
    }

    fn get(&self, key: &Key) -> Option<&Entry> {
        Board::get(&*self.replica, key)
    }

    fn visit(&self, pattern: &Pattern, f: &mut dyn FnMut(&Key, &Entry)) {
        Board::visit(&*self.replica, pattern, f);
    }

    fn set(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), Rejected> {
        self.check(key, &value)?;
        Board::set(&mut *self.replica, now, key, value)
    }

    fn post(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), Rejected> {
        Board::post(&mut *self.replica, now, key, value)
    }

    fn set_priority(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), Rejected> {
        self.check(key, &value)?;
        Board::set_priority(&mut *self.replica, now, key, value)
    }

    fn set_game_clock(
        &mut self,
        now: Instant,
        remaining: std::time::Duration,
    ) -> Result<(), Rejected> {
        Board::set_game_clock(&mut *self.replica, now, remaining).inspect_err(|_| {
            *self.clock_refused += 1;
        })
    }

    fn departed(&self, owner: u8) -> bool {
        Board::departed(&*self.replica, owner)
    }
}
