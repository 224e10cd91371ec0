//! Blackboard keys: `scope.kind.path`, e.g. `*.var.machine.heuristic`.
//!
//! The first level says whose the binding is (`local`: this robot only, never sent;
//! `*`: global, published by the writer; `n`: robot n's copy), the second what it is
//! (`var`: one value; `talk`: a FIFO message queue), the rest is free. Path levels are
//! non-empty runs of ASCII letters, digits, `-` and `_`; that keeps `+`, `#`, `*`, spaces
//! and quotes free for patterns and the line protocol.

use std::fmt;
use std::str::FromStr;
use std::sync::Arc;

use thiserror::Error;

/// Longest accepted path (the part after `scope.kind.`), in bytes. Keeps a single update
/// well inside any sane MTU.
pub const MAX_PATH_LEN: usize = 200;

/// Lowest and highest valid robot ids (0 and 255 are reserved).
pub const ROBOT_IDS: std::ops::RangeInclusive<u8> = 1..=254;

/// Whose binding a key names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Scope {
    /// `local`: this robot only; never leaves it.
    Local,
    /// `*`: global. Writing publishes the writer's own copy; reading picks the newest copy.
    Global,
    /// `n`: robot n's copy of a global binding (1..=254).
    Robot(u8),
}

/// What a key binds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Kind {
    /// `var`: a single value, overwritten by newer writes.
    Var,
    /// `talk`: a FIFO message queue, delivered exactly once and in order.
    Talk,
}

/// A parsed, validated blackboard key.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Key {
    scope: Scope,
    kind: Kind,
    /// Shared, not owned: the blackboard hands out the keys of stored bindings (every
    /// change event, every notice) as a count increment instead of a copy of the path.
    path: Arc<str>,
}

/// Why a string is not a key.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum KeyError {
    /// The key is empty.
    #[error("empty key")]
    Empty,
    /// Fewer than three levels (`scope.kind.name` is the minimum).
    #[error("key {0:?} needs at least three levels: scope.kind.name")]
    TooFewLevels(String),
    /// The first level is not `local`, `*` or a robot id 1..=254.
    #[error("bad scope {0:?}: expected local, * or a robot id 1..=254")]
    BadScope(String),
    /// The second level is not `var` or `talk`.
    #[error("bad kind {0:?}: expected var or talk")]
    BadKind(String),
    /// Two dots in a row, or a leading/trailing dot.
    #[error("empty level in key {0:?}")]
    EmptyLevel(String),
    /// A path character outside `[A-Za-z0-9_-]`.
    #[error("character {ch:?} not allowed in key {key:?} (letters, digits, - and _ only)")]
    BadChar {
        /// The offending character.
        ch: char,
        /// The whole key as given.
        key: String,
    },
    /// The path is longer than [`MAX_PATH_LEN`].
    #[error("key path is {len} bytes, the limit is {MAX_PATH_LEN}")]
    TooLong {
        /// Path length in bytes.
        len: usize,
    },
}

impl Key {
    /// Builds a key from parts, validating the path.
    pub fn new(scope: Scope, kind: Kind, path: impl Into<String>) -> Result<Key, KeyError> {
        let path = path.into();
        validate_scope(scope)?;
        validate_path(&path)?;
        Ok(Key {
            scope,
            kind,
            path: Arc::from(path),
        })
    }

    /// Parses `scope.kind.path`.
    pub fn parse(s: &str) -> Result<Key, KeyError> {
        KeyRef::parse(s).map(|k| k.to_key())
    }

    /// The key's parts, borrowed.
    pub(crate) fn as_parts(&self) -> KeyRef<'_> {
        KeyRef {
            scope: self.scope,
            kind: self.kind,
            path: &self.path,
        }
    }

    /// The first level.
    pub fn scope(&self) -> Scope {
        self.scope
    }

    /// The second level.
    pub fn kind(&self) -> Kind {
        self.kind
    }

    /// Everything after `scope.kind.`.
    pub fn path(&self) -> &str {
        &self.path
    }

    /// The same kind and path under another scope (e.g. `*.var.x` → `3.var.x`).
    pub fn with_scope(&self, scope: Scope) -> Key {
        Key {
            scope,
            kind: self.kind,
            path: self.path.clone(),
        }
    }

    /// Unchecked constructor for parts already validated (a stored binding's key),
    /// sharing the stored path (no copy).
    pub(crate) fn from_shared(scope: Scope, kind: Kind, path: Arc<str>) -> Key {
        Key { scope, kind, path }
    }

    /// The path as shared with the blackboard (a stored binding's key holds its
    /// allocation).
    pub(crate) fn shared_path(&self) -> &Arc<str> {
        &self.path
    }
}

/// A key's parts borrowed from the text they were parsed from: what a write needs, with
/// no copy of the path (a [`Key`] is built only to be kept).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct KeyRef<'a> {
    pub(crate) scope: Scope,
    pub(crate) kind: Kind,
    pub(crate) path: &'a str,
}

impl<'a> KeyRef<'a> {
    /// Parses `scope.kind.path` as [`Key::parse`] does (same checks, same errors).
    pub(crate) fn parse(s: &'a str) -> Result<KeyRef<'a>, KeyError> {
        if s.is_empty() {
            return Err(KeyError::Empty);
        }
        // `splitn(3, '.')` by hand: every `Handle::set` parses its key, and the
        // searcher's set-up cost more than the two short scans.
        let dot = |from: usize| {
            s.as_bytes()[from..]
                .iter()
                .position(|&b| b == b'.')
                .map(|i| from + i)
        };
        let Some((first, second)) = dot(0).and_then(|a| Some((a, dot(a + 1)?))) else {
            return Err(KeyError::TooFewLevels(s.to_owned()));
        };
        let (scope, kind, path) = (&s[..first], &s[first + 1..second], &s[second + 1..]);
        let scope = parse_scope(scope)?;
        let kind = match kind {
            "var" => Kind::Var,
            "talk" => Kind::Talk,
            "" => return Err(KeyError::EmptyLevel(s.to_owned())),
            other => return Err(KeyError::BadKind(other.to_owned())),
        };
        validate_path(path).map_err(|e| match e {
            KeyError::EmptyLevel(_) => KeyError::EmptyLevel(s.to_owned()),
            KeyError::BadChar { ch, .. } => KeyError::BadChar {
                ch,
                key: s.to_owned(),
            },
            other => other,
        })?;
        Ok(KeyRef { scope, kind, path })
    }

    /// An owned key of these parts.
    pub(crate) fn to_key(self) -> Key {
        Key {
            scope: self.scope,
            kind: self.kind,
            path: Arc::from(self.path),
        }
    }
}

impl fmt::Display for KeyRef<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}.{}", self.scope, self.kind, self.path)
    }
}

fn validate_scope(scope: Scope) -> Result<(), KeyError> {
    match scope {
        Scope::Robot(n) if !ROBOT_IDS.contains(&n) => Err(KeyError::BadScope(n.to_string())),
        _ => Ok(()),
    }
}

/// Parses a first level: `local`, `*` or a robot id without sign or leading zeros.
pub(crate) fn parse_scope(s: &str) -> Result<Scope, KeyError> {
    match s {
        "local" => Ok(Scope::Local),
        "*" => Ok(Scope::Global),
        "" => Err(KeyError::BadScope(String::new())),
        _ => {
            let canonical = s.bytes().all(|b| b.is_ascii_digit()) && !s.starts_with('0');
            match s.parse::<u8>() {
                Ok(n) if canonical && ROBOT_IDS.contains(&n) => Ok(Scope::Robot(n)),
                _ => Err(KeyError::BadScope(s.to_owned())),
            }
        }
    }
}

/// The bytes a path level may hold, ASCII `[A-Za-z0-9_-]`, as a table: one load per byte
/// where the three range tests took several compares and branches.
const LEVEL_BYTE: [bool; 256] = {
    let mut table = [false; 256];
    let mut b = 0;
    while b < 256 {
        let c = b as u8;
        table[b] = c.is_ascii_alphanumeric() || c == b'-' || c == b'_';
        b += 1;
    }
    table
};

/// Checks a dot-separated path (the part after `scope.kind.`).
pub fn validate_path(path: &str) -> Result<(), KeyError> {
    if path.len() > MAX_PATH_LEN {
        return Err(KeyError::TooLong { len: path.len() });
    }
    // One pass over the bytes (every received update is checked here): a level starts
    // after each dot and must not be empty; every other byte is ASCII `[A-Za-z0-9_-]`.
    let mut level_len = 0usize;
    for (i, &b) in path.as_bytes().iter().enumerate() {
        if LEVEL_BYTE[usize::from(b)] {
            level_len += 1;
        } else if b == b'.' {
            if level_len == 0 {
                return Err(KeyError::EmptyLevel(path.to_owned()));
            }
            level_len = 0;
        } else {
            // Report the whole character, which may be multi-byte.
            let ch = path[i..]
                .chars()
                .next()
                .unwrap_or(char::REPLACEMENT_CHARACTER);
            return Err(KeyError::BadChar {
                ch,
                key: path.to_owned(),
            });
        }
    }
    if level_len == 0 {
        return Err(KeyError::EmptyLevel(path.to_owned()));
    }
    Ok(())
}

impl fmt::Display for Scope {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Scope::Local => f.write_str("local"),
            Scope::Global => f.write_str("*"),
            Scope::Robot(n) => write!(f, "{n}"),
        }
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Kind::Var => "var",
            Kind::Talk => "talk",
        })
    }
}

impl fmt::Display for Key {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}.{}", self.scope, self.kind, self.path)
    }
}

impl FromStr for Key {
    type Err = KeyError;
    fn from_str(s: &str) -> Result<Key, KeyError> {
        Key::parse(s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        /// The hand-written split gives the levels `splitn(3, '.')` gave (and the same
        /// error when there are fewer than three), for any string of dots and letters.
        #[test]
        fn a_key_splits_at_its_first_two_dots_as_splitn_did(s in "[a.*0-9]{0,8}") {
            let mut parts = s.splitn(3, '.');
            let scope = parts.next().unwrap_or_default();
            let expected = match (parts.next(), parts.next()) {
                _ if s.is_empty() => Err(KeyError::Empty),
                (Some(kind), Some(path)) => Ok((scope, kind, path)),
                _ => Err(KeyError::TooFewLevels(s.clone())),
            };
            match (KeyRef::parse(&s), expected) {
                (Ok(k), Ok((scope, kind, path))) => {
                    prop_assert_eq!(k.scope, parse_scope(scope).unwrap());
                    prop_assert_eq!(k.kind.to_string(), kind);
                    prop_assert_eq!(k.path, path);
                }
                (Err(e), Err(expected)) => prop_assert_eq!(e, expected),
                // A split that worked may still fail a level's check: the scope's, the
                // kind's or the path's, each with its own error.
                (Err(e), Ok(_)) => prop_assert!(
                    !matches!(e, KeyError::Empty | KeyError::TooFewLevels(_)),
                    "{s:?} has three levels but was refused as {e:?}"
                ),
                (Ok(_), Err(expected)) => {
                    prop_assert!(false, "{s:?} parsed, expected {expected:?}")
                }
            }
        }
    }

    #[test]
    fn the_seeds_example_key_parses_into_its_levels() {
        let k = Key::parse("local.var.machine.config.def.near-ball").unwrap();
        assert_eq!(k.scope(), Scope::Local);
        assert_eq!(k.kind(), Kind::Var);
        assert_eq!(k.path(), "machine.config.def.near-ball");
        assert_eq!(k.to_string(), "local.var.machine.config.def.near-ball");
        assert_eq!(
            Key::parse("*.talk.plan").unwrap().scope(),
            Scope::Global,
            "* is the global scope"
        );
        assert_eq!(Key::parse("254.var.x").unwrap().scope(), Scope::Robot(254));
    }

    /// Every byte, alone as a one-level path and inside `a<byte>b`, is accepted exactly
    /// when it is ASCII `[A-Za-z0-9_-]` (the rule the byte table stands for); a dot
    /// makes an empty level or splits the path.
    #[test]
    fn every_byte_is_judged_as_the_path_rule_says() {
        for b in 0..=255u8 {
            let allowed = b.is_ascii_alphanumeric() || b == b'-' || b == b'_';
            let Ok(one) = std::str::from_utf8(&[b]).map(str::to_owned) else {
                // A lone byte ≥ 0x80 is no `str`; multi-byte characters are refused
                // below as a whole.
                assert!(!allowed, "byte {b:#04x}");
                continue;
            };
            assert_eq!(validate_path(&one).is_ok(), allowed, "byte {b:#04x} alone");
            let inner = format!("a{one}b");
            let expected = allowed || b == b'.';
            assert_eq!(
                validate_path(&inner).is_ok(),
                expected,
                "byte {b:#04x} inside a path"
            );
        }
        assert!(
            matches!(validate_path("a.é"), Err(KeyError::BadChar { ch: 'é', .. })),
            "a multi-byte character is refused whole"
        );
    }

    type Check = fn(&KeyError) -> bool;

    #[test]
    fn malformed_keys_are_typed_errors() {
        let cases: &[(&str, Check)] = &[
            ("", |e| matches!(e, KeyError::Empty)),
            ("local.var", |e| matches!(e, KeyError::TooFewLevels(_))),
            ("0.var.x", |e| matches!(e, KeyError::BadScope(_))),
            ("255.var.x", |e| matches!(e, KeyError::BadScope(_))),
            ("07.var.x", |e| matches!(e, KeyError::BadScope(_))),
            ("+3.var.x", |e| matches!(e, KeyError::BadScope(_))),
            ("robot.var.x", |e| matches!(e, KeyError::BadScope(_))),
            ("*.val.x", |e| matches!(e, KeyError::BadKind(_))),
            ("*..x", |e| matches!(e, KeyError::EmptyLevel(_))),
            ("*.var.a..b", |e| matches!(e, KeyError::EmptyLevel(_))),
            ("*.var.a.", |e| matches!(e, KeyError::EmptyLevel(_))),
            ("*.var.a b", |e| {
                matches!(e, KeyError::BadChar { ch: ' ', .. })
            }),
            ("*.var.a.#", |e| {
                matches!(e, KeyError::BadChar { ch: '#', .. })
            }),
            ("*.var.é", |e| {
                matches!(e, KeyError::BadChar { ch: 'é', .. })
            }),
        ];
        for (input, check) in cases {
            let err = Key::parse(input).expect_err(input);
            assert!(check(&err), "{input:?} gave the wrong error: {err:?}");
        }
        let long = format!("*.var.{}", "a".repeat(MAX_PATH_LEN + 1));
        assert_eq!(
            Key::parse(&long),
            Err(KeyError::TooLong {
                len: MAX_PATH_LEN + 1
            })
        );
    }
}
