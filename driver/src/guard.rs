//! Write guards: a check that a relay client's `SETV` of one key must pass before it is
//! written, so that a key can be a command (`local.var.audio.say`) whose bad values get
//! an `ERR` line instead of a silent `OK`.

use std::cell::RefCell;
use std::rc::{Rc, Weak};

use comms::relay::{Board, Rejected};
use comms::{Entry, Instant, Key, Pattern, Replica, Value};

/// What a guard runs on a client's value: `Ok` lets the write through, `Err` is the
/// client's `ERR` line and nothing is written.
pub(crate) type Check = dyn FnMut(&Value) -> Result<(), Rejected>;

/// A guarded key and its check, shared (weakly) with the driver.
pub(crate) struct GuardSlot {
    pub(crate) key: Key,
    pub(crate) check: RefCell<Box<Check>>,
}

/// A check registered with [`crate::Handle::guard`]; dropping it removes the check.
pub struct Guard {
    _slot: Rc<GuardSlot>,
}

impl Guard {
    pub(crate) fn new(slot: Rc<GuardSlot>) -> Guard {
        Guard { _slot: slot }
    }
}

/// The replica as a relay session sees it, with the guards in front of its writes.
pub(crate) struct GuardedBoard<'a> {
    pub(crate) replica: &'a mut Replica,
    pub(crate) guards: &'a [Weak<GuardSlot>],
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
        for slot in self.guards.iter().filter_map(Weak::upgrade) {
            if slot.key == *key {
                (slot.check.borrow_mut())(&value)?;
            }
        }
        Board::set(&mut *self.replica, now, key, value)
    }

    fn post(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), Rejected> {
        Board::post(&mut *self.replica, now, key, value)
    }

    fn set_priority(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), Rejected> {
        for slot in self.guards.iter().filter_map(Weak::upgrade) {
            if slot.key == *key {
                (slot.check.borrow_mut())(&value)?;
            }
        }
        Board::set_priority(&mut *self.replica, now, key, value)
    }

    fn set_game_clock(&mut self, now: Instant, remaining: std::time::Duration) {
        Board::set_game_clock(&mut *self.replica, now, remaining);
    }

    fn departed(&self, owner: u8) -> bool {
        Board::departed(&*self.replica, owner)
    }
}
