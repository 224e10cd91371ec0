//! Changed values waiting for a frame.

use std::collections::{HashSet, VecDeque};
use std::sync::Arc;

use crate::blackboard::PathHasher;

/// Changed values waiting for a frame, in the order they first changed; a value set again
/// while it waits keeps its place. The value that has waited longest goes first, so a
/// large value that did not fit beside others (a world model beside an arbitration cost
/// in a 128-byte league frame) goes at the head of the next frame instead of being
/// starved by small values set again at every tick.
///
/// Paths are the blackboard's own (shared): marking a value changed copies no string.
#[derive(Debug, Default)]
pub(super) struct DirtyQueue {
    order: VecDeque<Arc<str>>,
    members: HashSet<Arc<str>, PathHasher>,
}

impl DirtyQueue {
    /// Marks `path` changed (a no-op if it already waits).
    pub(super) fn insert(&mut self, path: &Arc<str>) {
        if self.members.insert(path.clone()) {
            self.order.push_back(path.clone());
        }
    }

    pub(super) fn is_empty(&self) -> bool {
        self.order.is_empty()
    }

    pub(super) fn contains(&self, path: &str) -> bool {
        self.members.contains(path)
    }

    /// The waiting paths, longest-waiting first.
    pub(super) fn iter(&self) -> impl Iterator<Item = &Arc<str>> {
        self.order.iter()
    }

    /// The `i`-th waiting path.
    pub(super) fn get(&self, i: usize) -> Option<&Arc<str>> {
        self.order.get(i)
    }

    /// Takes the `i`-th waiting path out of the queue.
    pub(super) fn remove_at(&mut self, i: usize) -> Option<Arc<str>> {
        let path = self.order.remove(i)?;
        self.members.remove(&*path);
        Some(path)
    }

    /// Takes `path` out of the queue, wherever it waits.
    pub(super) fn remove(&mut self, path: &str) -> bool {
        if !self.members.remove(path) {
            return false;
        }
        if let Some(i) = self.order.iter().position(|p| **p == *path) {
            self.order.remove(i);
        }
        true
    }

    pub(super) fn pop_first(&mut self) -> Option<Arc<str>> {
        self.remove_at(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_value_set_again_keeps_its_place_and_the_longest_waiting_goes_first() {
        let mut q = DirtyQueue::default();
        let (world, machine): (Arc<str>, Arc<str>) =
            ("world.local".into(), "machine.heuristic".into());
        q.insert(&world);
        q.insert(&machine);
        q.insert(&world);
        let order: Vec<&str> = q.iter().map(|p| &**p).collect();
        assert_eq!(order, ["world.local", "machine.heuristic"]);
        assert!(q.remove("world.local"));
        q.insert(&world);
        let order: Vec<&str> = q.iter().map(|p| &**p).collect();
        assert_eq!(
            order,
            ["machine.heuristic", "world.local"],
            "sent and set again: to the back of the line"
        );
        assert_eq!(q.pop_first().as_deref(), Some("machine.heuristic"));
        assert_eq!(q.iter().count(), 1);
        assert!(!q.contains("machine.heuristic"));
    }
}
