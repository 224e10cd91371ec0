//! What a relay session needs from the robot's blackboard: read, iterate, write, post.
//! A bare [`Blackboard`] serves (without talk queues); the daemon plugs in its
//! [`crate::Replica`], so writes through the relay follow exactly the library's rules.

use crate::blackboard::{Blackboard, Entry, SetError};
use crate::key::Key;
use crate::pattern::Pattern;
use crate::replica::{PostError, Replica};
use crate::time::Instant;
use crate::value::Value;

use super::command::Rejected;
use super::error::ErrCode;

/// The blackboard as a relay session sees it.
pub trait Board {
    /// This robot's id (for the greeting).
    fn robot_id(&self) -> u8;
    /// The binding for `key` (`*.var.x`: the newest copy of any owner).
    fn get(&self, key: &Key) -> Option<&Entry>;
    /// Calls `f` for every stored binding matching `pattern`, in key order, keys as
    /// stored (`n.var.x`, never `*`).
    fn visit(&self, pattern: &Pattern, f: &mut dyn FnMut(&Key, &Entry));
    /// Writes a `var` key with the library's rules.
    fn set(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), Rejected>;
    /// Posts a message to an own `talk` queue.
    fn post(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), Rejected>;
    /// [`Board::set`] of an item that may draw on a league budget's priority reserve.
    /// Without a budget (or on a bare blackboard) it is a plain set.
    fn set_priority(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), Rejected> {
        self.set(now, key, value)
    }
    /// The game clock a league budget paces itself over: `remaining` of play left. A
    /// board without a budget has nothing to pace. Refused (`ERR 424`) while the
    /// league's referee system sets the clock (an [`crate::ExternalCap`] is in force).
    fn set_game_clock(
        &mut self,
        now: Instant,
        remaining: std::time::Duration,
    ) -> Result<(), Rejected> {
        let _ = (now, remaining);
        Ok(())
    }
    /// Whether robot `owner` is departed (its values are old news): replies about its
    /// bindings carry the `departed` flag. A bare blackboard knows of no departures.
    fn departed(&self, owner: u8) -> bool {
        let _ = owner;
        false
    }
}

impl From<SetError> for Rejected {
    fn from(e: SetError) -> Rejected {
        let code = match e {
            SetError::Key(_) => ErrCode::BadKey,
            SetError::TalkKey(_) => ErrCode::WrongKind,
            SetError::NotOwner { .. } => ErrCode::NotOwner,
            SetError::TooLarge { .. } => ErrCode::TooLarge,
            SetError::TooManyKeys { .. } => ErrCode::TooMany,
        };
        Rejected {
            code,
            text: e.to_string(),
        }
    }
}

impl Board for Blackboard {
    fn robot_id(&self) -> u8 {
        Blackboard::robot_id(self)
    }

    fn get(&self, key: &Key) -> Option<&Entry> {
        Blackboard::get(self, key)
    }

    fn visit(&self, pattern: &Pattern, f: &mut dyn FnMut(&Key, &Entry)) {
        for (key, entry) in self.iter(pattern) {
            f(&key, entry);
        }
    }

    fn set(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), Rejected> {
        Blackboard::set(self, now, key, value)
            .map(|_| ())
            .map_err(Rejected::from)
    }

    fn post(&mut self, _now: Instant, key: &Key, _value: Value) -> Result<(), Rejected> {
        Err(Rejected {
            code: ErrCode::Unavailable,
            text: format!("{key}: a bare blackboard has no talk queues"),
        })
    }
}

impl From<PostError> for Rejected {
    fn from(e: PostError) -> Rejected {
        let code = match e {
            PostError::Key(_) => ErrCode::BadKey,
            PostError::NotOwnQueue(_) => ErrCode::WrongKind,
            PostError::TooLarge { .. } => ErrCode::TooLarge,
            PostError::TooManyQueues(_) => ErrCode::TooMany,
            // Posting faster than the queue's retention allows: try again later.
            PostError::RetentionFull { .. } => ErrCode::QueueFull,
        };
        Rejected {
            code,
            text: e.to_string(),
        }
    }
}

/// The daemon's board: writes go through the replica, so they are published and follow
/// the same rules as the library's.
impl Board for Replica {
    fn robot_id(&self) -> u8 {
        Replica::robot_id(self)
    }

    fn get(&self, key: &Key) -> Option<&Entry> {
        self.blackboard().get(key)
    }

    fn visit(&self, pattern: &Pattern, f: &mut dyn FnMut(&Key, &Entry)) {
        for (key, entry) in self.iter(pattern) {
            f(&key, entry);
        }
    }

    fn set(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), Rejected> {
        self.set_key(now, key, value).map_err(Rejected::from)
    }

    fn post(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), Rejected> {
        Replica::post(self, now, &key.to_string(), value)
            .map(|_| ())
            .map_err(Rejected::from)
    }

    fn set_priority(&mut self, now: Instant, key: &Key, value: Value) -> Result<(), Rejected> {
        Replica::set_priority(self, now, key, value).map_err(Rejected::from)
    }

    fn set_game_clock(
        &mut self,
        now: Instant,
        remaining: std::time::Duration,
    ) -> Result<(), Rejected> {
        // The referee system's figures bring their own clock (its `secsRemaining` over
        // the halves), fed with every figure: a client's clock would move the pacing line
        // the figures are paced by until the next figure came, and a clock run ahead
        // opens the line early. The referee's clock is the authority while its figures
        // are (from the first on: its last figure stays in force through a silence).
        if self.has_external_budget() {
            return Err(Rejected::new(
                ErrCode::ClockOwned,
                "the game clock is the GameController's while its figures are in force \
                 (the budget paces by its secsRemaining); CLOK is refused",
            ));
        }
        Replica::set_game_clock(self, now, remaining);
        Ok(())
    }

    fn departed(&self, owner: u8) -> bool {
        self.is_departed(owner)
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use super::*;
    use crate::{BudgetSpec, ExternalCap, ReplicaConfig};

    #[test]
    fn a_clients_clock_is_refused_while_the_referees_figures_are_in_force() {
        // Scenario: a replica under the SPL budget takes a client's clock until the
        // referee system's first figure; from then on the clock is the referee's (its
        // figures bring it) and a client's is refused with `ERR 424`, the clock unmoved.
        let at = Instant::from_micros;
        let cfg = ReplicaConfig::new(1, 1).with_budget(&BudgetSpec::SPL, 5);
        let mut r = Replica::new(cfg, 7, at(0)).expect("a replica");
        assert!(Board::set_game_clock(&mut r, at(0), Duration::from_secs(600)).is_ok());
        r.set_game_clock(at(0), Duration::from_secs(300));
        r.set_external_budget(Some(ExternalCap {
            counted: true,
            team_left: 16,
            rate_per_s: 1.0,
            margin: 14,
        }));
        let headroom = r.budget_headroom();
        let refused = Board::set_game_clock(&mut r, at(0), Duration::from_secs(1))
            .expect_err("the referee's clock stands");
        assert_eq!(refused.code, ErrCode::ClockOwned, "{}", refused.text);
        assert_eq!(r.budget_headroom(), headroom, "the clock did not move");
    }
}
