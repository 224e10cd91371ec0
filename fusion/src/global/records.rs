//! The GWM's per-robot records, found by id in one step.

/// Robot id → record, in id order: what a `BTreeMap<u8, T>` gave (the same
/// order for every walk), but a lookup is one read of a table instead of a search through
/// the node's keys (a branch per key, mispredicted at every message: each message comes
/// from another robot).
#[derive(Debug, Clone, PartialEq)]
pub(super) struct Records<T> {
    /// The ids, ascending.
    ids: Vec<u8>,
    /// Their records, in the same order.
    recs: Vec<T>,
    /// Per id: 1 + its place in `ids`, or 0 for none.
    at: Box<[u16; 256]>,
}

impl<T> Default for Records<T> {
    fn default() -> Self {
        Records {
            ids: Vec::new(),
            recs: Vec::new(),
            at: Box::new([0; 256]),
        }
    }
}

impl<T> Records<T> {
    fn place(&self, id: u8) -> Option<usize> {
        usize::from(self.at[usize::from(id)]).checked_sub(1)
    }

    /// Robot `id`'s record, made by `new` if it has none.
    pub(super) fn get_or_insert_with(&mut self, id: u8, new: impl FnOnce() -> T) -> &mut T {
        let k = match self.place(id) {
            Some(k) => k,
            None => {
                let k = self.ids.partition_point(|&other| other < id);
                self.ids.insert(k, id);
                self.recs.insert(k, new());
                for (j, &other) in self.ids.iter().enumerate().skip(k) {
                    self.at[usize::from(other)] = u16::try_from(j + 1).expect("at most 256 ids");
                }
                k
            }
        };
        &mut self.recs[k]
    }

    /// Robot `id`'s record.
    pub(super) fn get(&self, id: &u8) -> Option<&T> {
        self.place(*id).map(|k| &self.recs[k])
    }

    /// Robot `id`'s record, to change.
    pub(super) fn get_mut(&mut self, id: &u8) -> Option<&mut T> {
        self.place(*id).map(|k| &mut self.recs[k])
    }

    /// The records in id order.
    pub(super) fn values(&self) -> std::slice::Iter<'_, T> {
        self.recs.iter()
    }

    /// The records in id order, to change.
    pub(super) fn values_mut(&mut self) -> std::slice::IterMut<'_, T> {
        self.recs.iter_mut()
    }

    /// (id, record) in id order.
    pub(super) fn iter(&self) -> impl Iterator<Item = (&u8, &T)> {
        self.ids.iter().zip(&self.recs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::BTreeMap;

    proptest! {
        /// Whatever order robots are first heard in, the records walk in id order and
        /// each id finds its own, as the B-tree it replaces did.
        #[test]
        fn records_behave_as_a_btree_map(ops in proptest::collection::vec((any::<u8>(), 0u32..1000), 0..300)) {
            let mut records = Records::default();
            let mut model = BTreeMap::new();
            for (id, v) in ops {
                *records.get_or_insert_with(id, || 0) += v;
                *model.entry(id).or_insert(0) += v;
                prop_assert_eq!(records.get(&id), model.get(&id));
                prop_assert_eq!(records.get(&id.wrapping_add(1)), model.get(&id.wrapping_add(1)));
            }
            prop_assert!(records.iter().eq(model.iter()), "in id order");
            prop_assert!(records.values().eq(model.values()));
            for r in records.values_mut() {
                *r += 1;
            }
            prop_assert!(records.get_mut(&7).copied() == model.get(&7).map(|v| v + 1));
        }
    }
}
