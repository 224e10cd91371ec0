//! The blackboard's per-scope indexes, found by the scope's number instead of a search.
//!
//! Every update received, every write and every value sent looks up its scope first; a
//! `BTreeMap<Scope, _>` search compared the scope against each held one (a sixth of a
//! lookup's instructions). Here a scope is an index into a table (`local` 0, `*` 1,
//! robot n at n + 2: the order of [`Scope`]'s `Ord`), and the scopes held are kept in
//! that order for iteration.

use crate::key::Scope;

use super::ScopeIndex;

/// Indexes of the scopes that hold bindings, by scope number.
#[derive(Clone, Debug, Default)]
pub(super) struct ScopeTable {
    /// By scope number; grown on demand up to the highest scope held.
    tables: Vec<Option<Box<ScopeIndex>>>,
    /// The numbers of the scopes held, ascending (the scopes' key order).
    held: Vec<u16>,
}

/// A scope's place in the table, in [`Scope`]'s order.
fn number(scope: Scope) -> usize {
    match scope {
        Scope::Local => 0,
        Scope::Global => 1,
        Scope::Robot(n) => usize::from(n) + 2,
    }
}

impl ScopeTable {
    pub(super) fn get(&self, scope: Scope) -> Option<&ScopeIndex> {
        self.tables.get(number(scope))?.as_deref()
    }

    pub(super) fn get_mut(&mut self, scope: Scope) -> Option<&mut ScopeIndex> {
        self.tables.get_mut(number(scope))?.as_deref_mut()
    }

    /// The index of `scope`, made empty if it held nothing.
    pub(super) fn get_or_insert(&mut self, scope: Scope) -> &mut ScopeIndex {
        let n = number(scope);
        if self.tables.len() <= n {
            self.tables.resize_with(n + 1, || None);
        }
        let table = &mut self.tables[n];
        if table.is_none() {
            let k = self.held.partition_point(|&h| usize::from(h) < n);
            self.held.insert(k, n as u16);
        }
        table.get_or_insert_with(Box::default)
    }

    /// Forgets `scope`'s index.
    pub(super) fn remove(&mut self, scope: Scope) {
        let n = number(scope);
        if let Some(table) = self.tables.get_mut(n) {
            if table.take().is_some() {
                self.held.retain(|&h| usize::from(h) != n);
            }
        }
    }

    /// The held scopes' indexes numbered in `range`, in key order.
    fn numbered(
        &self,
        range: std::ops::RangeInclusive<usize>,
    ) -> impl Iterator<Item = &ScopeIndex> + '_ {
        let from = self
            .held
            .partition_point(|&h| usize::from(h) < *range.start());
        let to = self
            .held
            .partition_point(|&h| usize::from(h) <= *range.end());
        self.held[from..to]
            .iter()
            .filter_map(|&n| self.tables.get(usize::from(n))?.as_deref())
    }

    /// Every held scope's index, in key order (local first, then robots by id).
    pub(super) fn values(&self) -> impl Iterator<Item = &ScopeIndex> + '_ {
        self.numbered(0..=usize::MAX)
    }

    /// The indexes of robots 1..=254, in robot order.
    pub(super) fn robots(&self) -> impl Iterator<Item = &ScopeIndex> + '_ {
        self.numbered(number(Scope::Robot(1))..=number(Scope::Robot(254)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::collections::BTreeMap;

    fn scope() -> impl Strategy<Value = Scope> {
        prop_oneof![
            Just(Scope::Local),
            Just(Scope::Global),
            any::<u8>().prop_map(Scope::Robot),
        ]
    }

    proptest! {
        /// Scopes are added and removed at random; the table finds, iterates and ranges
        /// over them as the `BTreeMap<Scope, _>` it replaced does (told apart by the
        /// incarnation each index carries).
        #[test]
        fn the_table_holds_what_an_ordered_map_holds(
            ops in proptest::collection::vec((scope(), any::<bool>()), 0..80),
        ) {
            let mut table = ScopeTable::default();
            let mut map: BTreeMap<Scope, u64> = BTreeMap::new();
            for (k, &(scope, add)) in ops.iter().enumerate() {
                if add {
                    table.get_or_insert(scope).incarnation = Some(k as u64);
                    map.insert(scope, k as u64);
                } else {
                    table.remove(scope);
                    map.remove(&scope);
                }
                let tag = |i: &ScopeIndex| i.incarnation.unwrap_or(u64::MAX);
                for (s, &want) in &map {
                    prop_assert_eq!(table.get(*s).map(tag), Some(want));
                }
                prop_assert_eq!(table.get(scope).map(tag), map.get(&scope).copied());
                let all: Vec<u64> = table.values().map(tag).collect();
                prop_assert_eq!(all, map.values().copied().collect::<Vec<_>>());
                let robots: Vec<u64> = table.robots().map(tag).collect();
                let want: Vec<u64> = map
                    .range(Scope::Robot(1)..=Scope::Robot(254))
                    .map(|(_, &v)| v)
                    .collect();
                prop_assert_eq!(robots, want);
            }
        }
    }
}
