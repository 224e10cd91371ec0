//! MQTT-style key patterns for watches and iteration: `+` matches exactly one level, `#`
//! (only as the last level) matches all remaining levels, anything else matches itself.
//! `*` cannot be a wildcard because it is already a scope; in a pattern's first level it
//! matches every robot's copy of a global binding (`*.var.x` matches `1.var.x`,
//! `2.var.x`, ...), mirroring how `*` reads the newest copy of any owner.

use std::fmt;
use std::str::FromStr;

use thiserror::Error;

use crate::key::{Kind, Scope};

/// A parsed pattern such as `+.var.machine.heuristic` or `2.var.#`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Pattern {
    text: String,
    levels: Vec<Level>,
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
        Ok(Pattern {
            text: s.to_owned(),
            levels,
        })
    }

    /// The pattern as written.
    pub fn as_str(&self) -> &str {
        &self.text
    }

    /// Whether `key` (given as parts, so callers need not build a `Key`) matches.
    pub fn matches_parts(&self, scope: Scope, kind: Kind, path: &str) -> bool {
        let mut levels = self.levels.iter();
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
        let rest = std::iter::once(kind_str).chain(path.split('.'));
        match_levels(levels.as_slice(), rest)
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

fn match_levels<'a>(mut pattern: &[Level], key: impl Iterator<Item = &'a str>) -> bool {
    for part in key {
        match pattern.first() {
            None => return false,
            Some(Level::Rest) => return true,
            Some(Level::One) => {}
            Some(Level::Exact(l)) if l == part => {}
            Some(Level::Exact(_)) => return false,
        }
        pattern = &pattern[1..];
    }
    // `#` also matches zero remaining levels, as in MQTT.
    matches!(pattern, [] | [Level::Rest])
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
