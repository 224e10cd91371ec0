//! Changed values waiting for a frame.

use std::collections::{HashSet, VecDeque};
use std::sync::Arc;

use crate::blackboard::{PathHasher, SlotId};

/// Changed values waiting for a frame, in the order they first changed; a value set again
/// while it waits keeps its place. The value that has waited longest goes first, so a
/// large value that did not fit beside others (a world model beside an arbitration cost
/// in a 128-byte league frame) goes at the head of the next frame instead of being
/// starved by small values set again at every tick.
///
/// Paths are the blackboard's own (shared): marking a value changed copies no string.
/// Each comes with the slot its binding was written to, so the frame that sends it reads
/// the binding there instead of looking it up ([`crate::Blackboard`]'s `get_at`).
///
/// A short queue (the usual case: a robot sets a few values per tick, and a frame takes
/// them all) is searched by a scan of its few paths; the hash set of members is built
/// only once the queue holds [`INDEXED_FROM`] paths, and emptied with it. Hashing a path
/// on every write and every send cost more than the scan.
#[derive(Debug, Default)]
pub(super) struct DirtyQueue {
    order: VecDeque<(Arc<str>, SlotId)>,
    /// The paths in `order`, while the queue is indexed; empty otherwise.
    members: HashSet<Arc<str>, PathHasher>,
}

/// The length from which membership is looked up by hash.
const INDEXED_FROM: usize = 8;

impl DirtyQueue {
    /// Whether membership is kept in `members` (else a scan of `order` answers).
    fn indexed(&self) -> bool {
        !self.members.is_empty()
    }

    fn position(&self, path: &str) -> Option<usize> {
        self.order.iter().position(|(p, _)| **p == *path)
    }

    /// Marks `path`, written to `slot`, changed (if it already waits it keeps its place).
    pub(super) fn insert(&mut self, path: &Arc<str>, slot: SlotId) {
        if !self.indexed() {
            if let Some(i) = self.position(path) {
                self.order[i].1 = slot;
                return;
            }
            if self.order.len() + 1 < INDEXED_FROM {
                self.order.push_back((path.clone(), slot));
                return;
            }
            self.members
                .extend(self.order.iter().map(|(p, _)| p.clone()));
        }
        // Indexed, a path already waiting keeps the slot it came with: a binding's slot
        // changes only if it was removed and written again, and `get_at` then finds it
        // by its path.
        if self.members.insert(path.clone()) {
            self.order.push_back((path.clone(), slot));
        }
    }

    pub(super) fn is_empty(&self) -> bool {
        self.order.is_empty()
    }

    pub(super) fn contains(&self, path: &str) -> bool {
        if self.indexed() {
            self.members.contains(path)
        } else {
            self.position(path).is_some()
        }
    }

    /// The waiting paths, longest-waiting first.
    pub(super) fn iter(&self) -> impl Iterator<Item = &Arc<str>> {
        self.order.iter().map(|(p, _)| p)
    }

    /// The `i`-th waiting path and the slot it was written to.
    pub(super) fn get(&self, i: usize) -> Option<(&Arc<str>, SlotId)> {
        self.order.get(i).map(|(p, slot)| (p, *slot))
    }

    /// Takes the `i`-th waiting path out of the queue.
    pub(super) fn remove_at(&mut self, i: usize) -> Option<Arc<str>> {
        let (path, _) = self.order.remove(i)?;
        if self.indexed() {
            self.members.remove(&*path);
        }
        Some(path)
    }

    /// Takes `path` out of the queue, wherever it waits.
    pub(super) fn remove(&mut self, path: &str) -> bool {
        if self.indexed() && !self.members.remove(path) {
            return false;
        }
        match self.position(path) {
            Some(i) => {
                self.order.remove(i);
                true
            }
            None => false,
        }
    }

    pub(super) fn pop_first(&mut self) -> Option<Arc<str>> {
        self.remove_at(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[derive(Clone, Debug)]
    enum Op {
        Insert(u8),
        Remove(u8),
        RemoveAt(u8),
        PopFirst,
    }

    fn op() -> impl Strategy<Value = Op> {
        // 24 paths: the queue crosses `INDEXED_FROM` both ways.
        prop_oneof![
            3 => (0u8..24).prop_map(Op::Insert),
            1 => (0u8..24).prop_map(Op::Remove),
            1 => (0u8..12).prop_map(Op::RemoveAt),
            1 => Just(Op::PopFirst),
        ]
    }

    proptest! {
        /// Scanned while short, hashed while long: the queue answers as a plain
        /// first-changed-first list with a membership set would, after every step.
        #[test]
        fn the_queue_behaves_as_a_list_in_first_changed_order(
            ops in proptest::collection::vec(op(), 0..200)
        ) {
            let paths: Vec<Arc<str>> = (0..24).map(|i| Arc::from(format!("p.{i}"))).collect();
            let mut q = DirtyQueue::default();
            let mut model: Vec<Arc<str>> = Vec::new();
            for op in ops {
                match op {
                    Op::Insert(i) => {
                        let p = &paths[usize::from(i)];
                        q.insert(p, u32::from(i));
                        if !model.contains(p) {
                            model.push(p.clone());
                        }
                    }
                    Op::Remove(i) => {
                        let p = &paths[usize::from(i)];
                        let was = model.iter().position(|m| m == p);
                        if let Some(at) = was {
                            model.remove(at);
                        }
                        prop_assert_eq!(q.remove(p), was.is_some());
                    }
                    Op::RemoveAt(i) => {
                        let i = usize::from(i);
                        let expected = (i < model.len()).then(|| model.remove(i));
                        prop_assert_eq!(q.remove_at(i), expected);
                    }
                    Op::PopFirst => {
                        let expected = (!model.is_empty()).then(|| model.remove(0));
                        prop_assert_eq!(q.pop_first(), expected);
                    }
                }
                let order: Vec<Arc<str>> = q.iter().cloned().collect();
                prop_assert_eq!(&order, &model);
                prop_assert_eq!(q.is_empty(), model.is_empty());
                for p in &paths {
                    prop_assert_eq!(q.contains(p), model.contains(p), "{}", p);
                }
                // The index, when kept, holds exactly the queue's paths.
                prop_assert!(q.members.is_empty() || q.members.len() == q.order.len());
            }
        }
    }

    #[test]
    fn a_value_set_again_keeps_its_place_and_the_longest_waiting_goes_first() {
        let mut q = DirtyQueue::default();
        let (world, machine): (Arc<str>, Arc<str>) =
            ("world.local".into(), "machine.heuristic".into());
        q.insert(&world, 0);
        q.insert(&machine, 1);
        q.insert(&world, 0);
        let order: Vec<&str> = q.iter().map(|p| &**p).collect();
        assert_eq!(order, ["world.local", "machine.heuristic"]);
        assert!(q.remove("world.local"));
        q.insert(&world, 0);
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
