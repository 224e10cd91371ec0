//! MQTT-style key patterns for watches and iteration: `+` matches exactly one level, `#`
//! (only as the last level) matches all remaining levels, anything else matches itself.
//! `*` cannot be a wildcard because it is already a scope; in a pattern's first level it
//! matches every robot's copy of a global binding (`*.var.x` matches `1.var.x`,
//! `2.var.x`, ...), mirroring how `*` reads the newest copy of any owner.

use std::fmt;
use std::str::FromStr;

use thiserror::Error;

use crate::key::{Kind, Scope};

mod index;

pub use index::PatternIndex;

/// A parsed pattern such as `+.var.machine.heuristic` or `2.var.#`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Pattern {
    text: String,
    levels: Vec<Level>,
    /// What the first level accepts, decided once at parse time: every notice a driver
    /// dispatches is matched against every watch and subscriber, so the robot id in
    /// `2.var.x` is not parsed again per match.
    first: FirstLevel,
    /// What the second level accepts, decided once too (no string compare per match).
    second: SecondLevel,
}

/// The kinds a pattern's second level accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum SecondLevel {
    /// None: the pattern has one level (`#` is decided by the first).
    Missing,
    /// `#`: every kind and path.
    Rest,
    /// `+`: either kind; the path decides.
    One,
    /// `var` or `talk`; the path decides.
    Kind(Kind),
    /// Anything else: no key.
    Never,
}

/// The scopes a pattern's first level accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FirstLevel {
    /// `#`: every key.
    Rest,
    /// `+`: every scope.
    One,
    /// `*`: the global scope and every robot's.
    Robots,
    /// `local`.
    Local,
    /// A robot id written without sign or leading zero.
    Robot(u8),
    /// Anything else: no key.
    Never,
}

#[derive(Clone, Debug, PartialEq, Eq)]
enum Level {
    Exact(String),
    One,
    Rest,
}

/// Why a string is not a pattern.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum PatternError {
    /// The pattern is empty.
    #[error("empty pattern")]
    Empty,
    /// Two dots in a row, or a leading/trailing dot.
    #[error("empty level in pattern {0:?}")]
    EmptyLevel(String),
    /// `#` somewhere other than the last level.
    #[error("'#' must be the last level in pattern {0:?}")]
    HashNotLast(String),
    /// `+` or `#` mixed with other characters in one level (`a+`).
    #[error("wildcard must fill a whole level in pattern {0:?}")]
    PartialWildcard(String),
}

impl Pattern {
    /// Parses a pattern.
    pub fn parse(s: &str) -> Result<Pattern, PatternError> {
        if s.is_empty() {
            return Err(PatternError::Empty);
        }
        let raw: Vec<&str> = s.split('.').collect();
        let mut levels = Vec::with_capacity(raw.len());
        for (i, level) in raw.iter().enumerate() {
            let parsed = match *level {
                "" => return Err(PatternError::EmptyLevel(s.to_owned())),
                "+" => Level::One,
                "#" if i + 1 == raw.len() => Level::Rest,
                "#" => return Err(PatternError::HashNotLast(s.to_owned())),
                l if l.contains(['+', '#']) => {
                    return Err(PatternError::PartialWildcard(s.to_owned()))
                }
                l => Level::Exact(l.to_owned()),
            };
            levels.push(parsed);
        }
        let first = match &levels[0] {
            Level::Rest => FirstLevel::Rest,
            Level::One => FirstLevel::One,
            Level::Exact(l) => match l.as_str() {
                "*" => FirstLevel::Robots,
                "local" => FirstLevel::Local,
                l => match l.parse::<u8>() {
                    Ok(n) if !l.starts_with('0') => FirstLevel::Robot(n),
                    _ => FirstLevel::Never,
                },
            },
        };
        let second = match levels.get(1) {
            None => SecondLevel::Missing,
            Some(Level::Rest) => SecondLevel::Rest,
            Some(Level::One) => SecondLevel::One,
            Some(Level::Exact(l)) => match l.as_str() {
                "var" => SecondLevel::Kind(Kind::Var),
                "talk" => SecondLevel::Kind(Kind::Talk),
                _ => SecondLevel::Never,
            },
        };
        Ok(Pattern {
            text: s.to_owned(),
            levels,
            first,
            second,
        })
    }

    /// The pattern as written.
    pub fn as_str(&self) -> &str {
        &self.text
    }

    /// Whether `key` (given as parts, so callers need not build a `Key`) matches.
    pub fn matches_parts(&self, scope: Scope, kind: Kind, path: &str) -> bool {
        match self.head(scope, kind) {
            Head::All => true,
            Head::Nothing => false,
            Head::Path(path_levels) => match_path(path_levels, path.as_bytes()),
        }
    }

    /// What the scope and kind of a key decide: all of it (`#`, `2.#`), nothing (another
    /// scope or kind), or that the path levels decide.
    fn head(&self, scope: Scope, kind: Kind) -> Head<'_> {
        let scope_ok = match self.first {
            FirstLevel::Rest => return Head::All,
            FirstLevel::One => true,
            FirstLevel::Robots => matches!(scope, Scope::Global | Scope::Robot(_)),
            FirstLevel::Local => scope == Scope::Local,
            FirstLevel::Robot(n) => scope == Scope::Robot(n),
            FirstLevel::Never => false,
        };
        if !scope_ok {
            return Head::Nothing;
        }
        match self.second {
            SecondLevel::Missing | SecondLevel::Never => Head::Nothing,
            SecondLevel::Rest => Head::All,
            SecondLevel::Kind(k) if k != kind => Head::Nothing,
            SecondLevel::One | SecondLevel::Kind(_) => Head::Path(&self.levels[2..]),
        }
    }

    /// The literal start of every path this pattern matches, if its path begins with a
    /// literal level: the levels up to the first wildcard, joined with dots, and whether
    /// that is all of it (the pattern names one path). `None` for a pattern whose path
    /// may begin anywhere (`#`, `2.#`, `+.var.+.x`) or that has no path level.
    fn path_literal(&self) -> Option<(String, bool)> {
        if self.first == FirstLevel::Rest || matches!(self.levels.get(1), Some(Level::Rest)) {
            return None;
        }
        let path = self.levels.get(2..)?;
        let literal: Vec<&str> = path
            .iter()
            .map_while(|level| match level {
                Level::Exact(l) => Some(l.as_str()),
                _ => None,
            })
            .collect();
        if literal.is_empty() {
            return None;
        }
        Some((literal.join("."), literal.len() == path.len()))
    }

    /// Whether a parsed key matches.
    pub fn matches(&self, key: &crate::Key) -> bool {
        self.matches_parts(key.scope(), key.kind(), key.path())
    }

    /// Where the `var` bindings this pattern can match are, for an indexed lookup: the
    /// scopes to look in and the literal start of the path. A superset: candidates are
    /// still checked with [`Pattern::matches_parts`].
    pub(crate) fn var_plan(&self) -> VarPlan {
        let nothing = VarPlan {
            scopes: ScopeSel::Some(Vec::new()),
            path: PathSel::Any,
        };
        let scopes = match self.levels.first() {
            Some(Level::Rest) => {
                return VarPlan {
                    scopes: ScopeSel::All,
                    path: PathSel::Any,
                }
            }
            Some(Level::One) => ScopeSel::All,
            Some(Level::Exact(l)) => match l.as_str() {
                "*" => ScopeSel::Robots,
                "local" => ScopeSel::Some(vec![Scope::Local]),
                l => match crate::key::parse_scope(l) {
                    Ok(scope @ Scope::Robot(_)) => ScopeSel::Some(vec![scope]),
                    _ => return nothing,
                },
            },
            None => return nothing,
        };
        match self.levels.get(1) {
            Some(Level::Rest) => {
                return VarPlan {
                    scopes,
                    path: PathSel::Any,
                }
            }
            Some(Level::One) => {}
            Some(Level::Exact(l)) if l == "var" => {}
            _ => return nothing,
        }
        let mut literal = String::new();
        for level in &self.levels[2..] {
            let with_self = match level {
                Level::Exact(l) => {
                    if !literal.is_empty() {
                        literal.push('.');
                    }
                    literal.push_str(l);
                    continue;
                }
                Level::One => false,
                Level::Rest => true,
            };
            let path = if literal.is_empty() {
                PathSel::Any
            } else {
                PathSel::Prefix { literal, with_self }
            };
            return VarPlan { scopes, path };
        }
        if literal.is_empty() {
            // `n.var`: a key has at least one path level.
            return nothing;
        }
        VarPlan {
            scopes,
            path: PathSel::Exact(literal),
        }
    }
}

/// What a key's scope and kind decide about a match ([`Pattern::head`]).
enum Head<'a> {
    All,
    Nothing,
    /// The path levels of the pattern decide.
    Path(&'a [Level]),
}

/// Which stored `var` bindings a pattern can match ([`Pattern::var_plan`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct VarPlan {
    pub(crate) scopes: ScopeSel,
    pub(crate) path: PathSel,
}

/// The scopes a pattern's first level selects.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum ScopeSel {
    /// Every scope (`+`, `#`).
    All,
    /// Every robot's scope (`*`).
    Robots,
    /// These (none: the pattern matches no `var` binding).
    Some(Vec<Scope>),
}

/// The paths a pattern selects within a scope.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum PathSel {
    /// Any path (the first path level is a wildcard).
    Any,
    /// Exactly this path (no wildcard).
    Exact(String),
    /// Paths below `literal` (`literal.…`), and `literal` itself if `with_self` (`#`
    /// matches zero levels).
    Prefix { literal: String, with_self: bool },
}

/// Whether the key levels in `path` (split at its dots) match `pattern`, walking the
/// bytes once: a literal level is a prefix compare, not a split and a string compare.
fn match_path(mut pattern: &[Level], mut path: &[u8]) -> bool {
    // `path` holds at least one (maybe empty) level here.
    loop {
        let (level_len, tail) = match pattern.split_first() {
            None => return false,
            Some((Level::Rest, _)) => return true,
            Some((Level::One, tail)) => {
                let len = path.iter().position(|&b| b == b'.').unwrap_or(path.len());
                (len, tail)
            }
            Some((Level::Exact(l), tail)) => {
                // A literal holds no dot: equal to the key's level if it is a prefix
                // followed by a dot or the end.
                let l = l.as_bytes();
                if !path.starts_with(l) || path.get(l.len()).is_some_and(|&b| b != b'.') {
                    return false;
                }
                (l.len(), tail)
            }
        };
        if level_len == path.len() {
            // That was the key's last level. `#` also matches zero remaining levels,
            // as in MQTT.
            return matches!(tail, [] | [Level::Rest]);
        }
        path = &path[level_len + 1..];
        pattern = tail;
    }
}

impl fmt::Display for Pattern {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.text)
    }
}

impl FromStr for Pattern {
    type Err = PatternError;
    fn from_str(s: &str) -> Result<Pattern, PatternError> {
        Pattern::parse(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Key;
    use proptest::prelude::*;

    /// The matcher as it was before `match_path` and the parsed first level (a split
    /// and a string compare per level, the robot id parsed per match): the reference
    /// the fast one must agree with.
    fn reference_matches(p: &Pattern, scope: Scope, kind: Kind, path: &str) -> bool {
        let mut levels = p.levels.iter();
        let scope_ok = match levels.next() {
            Some(Level::One) => true,
            Some(Level::Rest) => return true,
            Some(Level::Exact(l)) => match (l.as_str(), scope) {
                ("*", Scope::Global | Scope::Robot(_)) => true,
                ("local", Scope::Local) => true,
                (l, Scope::Robot(n)) => l.parse::<u8>().ok() == Some(n) && !l.starts_with('0'),
                _ => false,
            },
            None => false,
        };
        if !scope_ok {
            return false;
        }
        let kind_str = match kind {
            Kind::Var => "var",
            Kind::Talk => "talk",
        };
        let mut pattern = levels.as_slice();
        for part in std::iter::once(kind_str).chain(path.split('.')) {
            match pattern.first() {
                None => return false,
                Some(Level::Rest) => return true,
                Some(Level::One) => {}
                Some(Level::Exact(l)) if l == part => {}
                Some(Level::Exact(_)) => return false,
            }
            pattern = &pattern[1..];
        }
        matches!(pattern, [] | [Level::Rest])
    }

    /// Levels drawn from a small alphabet, so that patterns and keys often agree.
    fn level() -> impl Strategy<Value = String> {
        prop_oneof![
            Just("a".to_owned()),
            Just("ab".to_owned()),
            Just("b".to_owned()),
            Just("var".to_owned()),
            Just("talk".to_owned()),
            Just("2".to_owned()),
            Just("*".to_owned()),
            Just("local".to_owned()),
            Just("+".to_owned()),
            Just("#".to_owned()),
            Just(String::new()),
            "[a-c0-9]{1,3}",
        ]
    }

    proptest! {
        /// The byte-walking matcher gives exactly the old split-and-compare answer, for
        /// every pattern that parses and any path (empty levels and trailing dots too).
        #[test]
        fn the_fast_matcher_agrees_with_the_reference(
            pattern in proptest::collection::vec(level(), 1..6),
            scope in prop_oneof![
                Just(Scope::Local),
                Just(Scope::Global),
                (0u8..=12).prop_map(Scope::Robot),
            ],
            talk in any::<bool>(),
            path in proptest::collection::vec(level(), 1..6),
        ) {
            let Ok(p) = Pattern::parse(&pattern.join(".")) else {
                return Ok(());
            };
            let kind = if talk { Kind::Talk } else { Kind::Var };
            let path = path.join(".");
            prop_assert_eq!(
                p.matches_parts(scope, kind, &path),
                reference_matches(&p, scope, kind, &path),
                "pattern {} against {:?} {:?} {:?}", p, scope, kind, path
            );
        }
    }

    fn m(pattern: &str, key: &str) -> bool {
        Pattern::parse(pattern)
            .unwrap()
            .matches(&Key::parse(key).unwrap())
    }

    #[test]
    fn plus_matches_one_level_and_hash_the_rest() {
        assert!(m("+.var.machine.heuristic", "3.var.machine.heuristic"));
        assert!(m("+.var.machine.heuristic", "local.var.machine.heuristic"));
        assert!(!m("+.var.machine.heuristic", "3.var.machine.heuristic.x"));
        assert!(m("2.var.#", "2.var.a.b.c"));
        assert!(!m("2.var.#", "3.var.a"));
        assert!(m("#", "local.talk.q"));
        assert!(m("local.+.x", "local.talk.x"));
        assert!(!m("local.var.x.#", "local.var.y"));
        assert!(m("local.var.x.#", "local.var.x"), "# matches zero levels");
    }

    #[test]
    fn star_in_a_pattern_means_any_robots_copy() {
        assert!(m("*.var.x", "7.var.x"));
        assert!(m("*.var.x", "*.var.x"));
        assert!(
            !m("*.var.x", "local.var.x"),
            "local values are nobody's global copy"
        );
        assert!(!m("07.var.x", "7.var.x"));
    }

    #[test]
    fn the_plan_names_the_scopes_and_the_literal_start_of_the_path() {
        let plan = |p: &str| Pattern::parse(p).unwrap().var_plan();
        let prefix = |l: &str, with_self| PathSel::Prefix {
            literal: l.into(),
            with_self,
        };
        let two = ScopeSel::Some(vec![Scope::Robot(2)]);
        assert_eq!(plan("2.var.ball.#").scopes, two);
        assert_eq!(plan("2.var.ball.#").path, prefix("ball", true));
        assert_eq!(plan("2.+.ball.+.x").path, prefix("ball", false));
        assert_eq!(plan("2.var.a.b").path, PathSel::Exact("a.b".into()));
        assert_eq!(plan("*.var.a").scopes, ScopeSel::Robots);
        assert_eq!(plan("+.var.+.x").scopes, ScopeSel::All);
        assert_eq!(plan("+.var.+.x").path, PathSel::Any);
        assert_eq!(plan("local.#").path, PathSel::Any);
        let none = ScopeSel::Some(Vec::new());
        for p in ["2.talk.x", "07.var.x", "robot.var.x", "2.var", "2"] {
            assert_eq!(plan(p).scopes, none, "{p} matches no var binding");
        }
    }

    #[test]
    fn malformed_patterns_are_typed_errors() {
        assert_eq!(Pattern::parse(""), Err(PatternError::Empty));
        assert!(matches!(
            Pattern::parse("a.#.b"),
            Err(PatternError::HashNotLast(_))
        ));
        assert!(matches!(
            Pattern::parse("a..b"),
            Err(PatternError::EmptyLevel(_))
        ));
        assert!(matches!(
            Pattern::parse("a.b+"),
            Err(PatternError::PartialWildcard(_))
        ));
    }
}
