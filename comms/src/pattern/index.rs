//! Listeners (a driver's watches and subscribers) found by the keys their patterns can
//! match, so that a change is matched only against the patterns that might match it.

use std::collections::HashMap;

use crate::blackboard::PathHasher;
use crate::key::{Kind, Scope};

use super::{Head, Pattern};

/// Values registered under patterns, visited for a key in registration order: for every
/// change a driver tells, the ones whose pattern matches the key.
///
/// A pattern that names one path (`2.var.ball.x`, `+.var.ball.x`) is found by that path
/// with one lookup; one whose path starts with literal levels (`2.var.ball.#`) by that
/// start, looked up once per level of the key's path (only while such patterns are
/// registered); the others (`#`, `+.var.+.x`) are matched one by one, as before.
///
/// ```
/// use comms::{Kind, Pattern, PatternIndex, Scope};
///
/// let mut watches = PatternIndex::new();
/// watches.insert(Pattern::parse("2.var.ball.x").unwrap(), "exact");
/// watches.insert(Pattern::parse("+.var.ball.#").unwrap(), "below ball");
/// watches.insert(Pattern::parse("+.var.pose").unwrap(), "pose");
/// let mut told = Vec::new();
/// watches.visit_matching(Scope::Robot(2), Kind::Var, "ball.x", |who| {
///     told.push(*who);
///     true // keep it
/// });
/// assert_eq!(told, ["exact", "below ball"]);
/// ```
#[derive(Debug)]
pub struct PatternIndex<T> {
    /// Entries by id; `None` for a removed one (its id is reused).
    entries: Vec<Option<Indexed<T>>>,
    free: Vec<usize>,
    /// Ids of the entries whose pattern's path starts with a literal, by that literal.
    by_literal: HashMap<Box<str>, Vec<usize>, PathHasher>,
    /// Entries in `by_literal` whose literal is followed by a wildcard.
    prefixes: usize,
    /// Ids of the entries matched one by one.
    scanned: Vec<usize>,
    /// Every entry's id, in registration order: while there are few, a visit walks these
    /// instead (a hash of the key's path costs more than comparing it with a few).
    in_order: Vec<usize>,
    next_order: u64,
    /// The candidates of one visit (kept for its allocation).
    scratch: Vec<Candidate>,
}

/// Up to this many entries a visit checks each in turn instead of looking the key up.
const SCANNED_UP_TO: usize = 8;

#[derive(Debug)]
struct Indexed<T> {
    pattern: Pattern,
    /// `Some((literal, exact))`: filed in `by_literal` under `literal`.
    literal: Option<(Box<str>, bool)>,
    /// Registration order.
    order: u64,
    value: T,
}

/// An entry that may match, and whether its path is already known to.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    order: u64,
    id: usize,
    path_matched: bool,
}

impl<T> Default for PatternIndex<T> {
    fn default() -> PatternIndex<T> {
        PatternIndex {
            entries: Vec::new(),
            free: Vec::new(),
            by_literal: HashMap::default(),
            prefixes: 0,
            scanned: Vec::new(),
            in_order: Vec::new(),
            next_order: 0,
            scratch: Vec::new(),
        }
    }
}

impl<T> PatternIndex<T> {
    /// An empty index.
    pub fn new() -> PatternIndex<T> {
        PatternIndex::default()
    }

    /// Registers `value` under `pattern`; it is visited after those registered before.
    pub fn insert(&mut self, pattern: Pattern, value: T) {
        let literal = pattern
            .path_literal()
            .map(|(literal, exact)| (literal.into_boxed_str(), exact));
        let order = self.next_order;
        self.next_order += 1;
        let id = self.free.pop().unwrap_or(self.entries.len());
        match &literal {
            Some((literal, exact)) => {
                self.by_literal.entry(literal.clone()).or_default().push(id);
                self.prefixes += usize::from(!exact);
            }
            None => self.scanned.push(id),
        }
        let entry = Some(Indexed {
            pattern,
            literal,
            order,
            value,
        });
        match self.entries.get_mut(id) {
            Some(free) => *free = entry,
            None => self.entries.push(entry),
        }
        self.in_order.push(id);
    }

    /// Number of values registered.
    pub fn len(&self) -> usize {
        self.entries.len() - self.free.len()
    }

    /// Whether nothing is registered.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Calls `visit` with every value whose pattern matches the key `scope.kind.path`, in
    /// registration order; a value for which it returns `false` is removed.
    pub fn visit_matching(
        &mut self,
        scope: Scope,
        kind: Kind,
        path: &str,
        mut visit: impl FnMut(&mut T) -> bool,
    ) {
        if self.in_order.len() <= SCANNED_UP_TO {
            return self.visit_scanning(scope, kind, path, visit);
        }
        let mut candidates = std::mem::take(&mut self.scratch);
        candidates.clear();
        let entries = &self.entries;
        let mut add = |ids: &[usize], whole_path: bool| {
            for &id in ids {
                let Some(e) = entries.get(id).and_then(Option::as_ref) else {
                    continue;
                };
                let exact = e.literal.as_ref().is_some_and(|(_, exact)| *exact);
                // Under a proper prefix of the key's path only prefixes can match.
                if whole_path || !exact {
                    candidates.push(Candidate {
                        order: e.order,
                        id,
                        path_matched: whole_path && exact,
                    });
                }
            }
        };
        if !self.by_literal.is_empty() {
            if let Some(ids) = self.by_literal.get(path) {
                add(ids, true);
            }
            if self.prefixes > 0 {
                for (i, _) in path.match_indices('.') {
                    if let Some(ids) = self.by_literal.get(&path[..i]) {
                        add(ids, false);
                    }
                }
            }
        }
        add(&self.scanned, false);
        if candidates.len() > 1 {
            candidates.sort_unstable_by_key(|c| c.order);
        }
        for c in &candidates {
            let Some(e) = self.entries.get_mut(c.id).and_then(Option::as_mut) else {
                continue;
            };
            let matched = match e.pattern.head(scope, kind) {
                Head::All => true,
                Head::Nothing => false,
                Head::Path(_) if c.path_matched => true,
                Head::Path(levels) => super::match_path(levels, path.as_bytes()),
            };
            if matched && !visit(&mut e.value) {
                self.remove(c.id);
            }
        }
        self.scratch = candidates;
    }

    /// [`PatternIndex::visit_matching`] over a few entries: each checked in turn, a
    /// literal path compared first.
    fn visit_scanning(
        &mut self,
        scope: Scope,
        kind: Kind,
        path: &str,
        mut visit: impl FnMut(&mut T) -> bool,
    ) {
        let mut k = 0;
        while let Some(&id) = self.in_order.get(k) {
            k += 1;
            let Some(e) = self.entries.get_mut(id).and_then(Option::as_mut) else {
                continue;
            };
            let exact = match &e.literal {
                Some((literal, true)) if **literal != *path => continue,
                Some((_, exact)) => *exact,
                None => false,
            };
            let matched = match e.pattern.head(scope, kind) {
                Head::All => true,
                Head::Nothing => false,
                Head::Path(_) if exact => true,
                Head::Path(levels) => super::match_path(levels, path.as_bytes()),
            };
            if matched && !visit(&mut e.value) {
                self.remove(id);
                k -= 1;
            }
        }
    }

    /// Keeps the values for which `keep` holds (in registration order), removes the
    /// others.
    pub fn retain(&mut self, mut keep: impl FnMut(&mut T) -> bool) {
        for id in 0..self.entries.len() {
            let drop = self.entries[id]
                .as_mut()
                .is_some_and(|e| !keep(&mut e.value));
            if drop {
                self.remove(id);
            }
        }
    }

    /// Removes every value, handing each over.
    pub fn drain(&mut self) -> impl Iterator<Item = T> + '_ {
        self.by_literal.clear();
        self.scanned.clear();
        self.in_order.clear();
        self.free.clear();
        self.prefixes = 0;
        self.entries.drain(..).flatten().map(|e| e.value)
    }

    fn remove(&mut self, id: usize) {
        let Some(e) = self.entries.get_mut(id).and_then(Option::take) else {
            return;
        };
        match &e.literal {
            Some((literal, exact)) => {
                if let Some(ids) = self.by_literal.get_mut(literal) {
                    ids.retain(|&other| other != id);
                    if ids.is_empty() {
                        self.by_literal.remove(literal);
                    }
                }
                self.prefixes -= usize::from(!exact);
            }
            None => self.scanned.retain(|&other| other != id),
        }
        self.in_order.retain(|&other| other != id);
        self.free.push(id);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const PATTERNS: &[&str] = &[
        "#",
        "2.#",
        "+.var.ball.x",
        "2.var.ball.x",
        "*.var.ball",
        "+.var.ball.#",
        "local.var.ball.+",
        "2.+.ball.#",
        "+.var.+.x",
        "+.talk.plan",
        "3.var.ball.x.y",
        "2.var",
        "x.var.ball",
    ];
    const PATHS: &[&str] = &["ball", "ball.x", "ball.x.y", "ballast", "plan", "x"];

    fn scope() -> impl Strategy<Value = Scope> {
        prop_oneof![
            Just(Scope::Local),
            Just(Scope::Global),
            (1u8..=4).prop_map(Scope::Robot),
        ]
    }

    #[derive(Clone, Debug)]
    enum Op {
        Insert(usize),
        /// Visit a key, removing the listeners whose number is odd when `drop_odd`.
        Visit(Scope, Kind, usize, bool),
        /// Keep only the listeners whose number is not a multiple of this.
        Retain(u64),
    }

    fn op() -> impl Strategy<Value = Op> {
        prop_oneof![
            2 => (0..PATTERNS.len()).prop_map(Op::Insert),
            4 => (scope(), prop_oneof![Just(Kind::Var), Just(Kind::Talk)], 0..PATHS.len(), any::<bool>())
                .prop_map(|(s, k, p, d)| Op::Visit(s, k, p, d)),
            1 => (2u64..5).prop_map(Op::Retain),
        ]
    }

    proptest! {
        /// Listeners come and go; every visit reaches, in registration order, exactly
        /// the listeners a scan of every pattern with `matches_parts` would.
        #[test]
        fn a_visit_reaches_what_matching_every_pattern_reaches(
            ops in proptest::collection::vec(op(), 0..60),
        ) {
            let mut index = PatternIndex::new();
            let mut model: Vec<(Pattern, u64)> = Vec::new();
            let mut next = 0u64;
            for op in ops {
                match op {
                    Op::Insert(p) => {
                        let pattern = Pattern::parse(PATTERNS[p]).unwrap();
                        index.insert(pattern.clone(), next);
                        model.push((pattern, next));
                        next += 1;
                    }
                    Op::Visit(scope, kind, p, drop_odd) => {
                        let path = PATHS[p];
                        let mut got = Vec::new();
                        index.visit_matching(scope, kind, path, |n| {
                            got.push(*n);
                            !(drop_odd && *n % 2 == 1)
                        });
                        let want: Vec<u64> = model
                            .iter()
                            .filter(|(pat, _)| pat.matches_parts(scope, kind, path))
                            .map(|(_, n)| *n)
                            .collect();
                        prop_assert_eq!(&got, &want, "{:?} {:?} {}", scope, kind, path);
                        model.retain(|(_, n)| !(drop_odd && n % 2 == 1 && want.contains(n)));
                    }
                    Op::Retain(m) => {
                        index.retain(|n| *n % m != 0);
                        model.retain(|(_, n)| n % m != 0);
                    }
                }
                prop_assert_eq!(index.len(), model.len());
            }
            let left: Vec<u64> = index.drain().collect();
            let mut want: Vec<u64> = model.iter().map(|(_, n)| *n).collect();
            let mut got = left;
            got.sort_unstable();
            want.sort_unstable();
            prop_assert_eq!(got, want);
            prop_assert!(index.is_empty());
        }
    }
}
