//! The table of known paths: key paths an application registers so that frames carry
//! them as a one-byte index (item 4) instead of as text.

use std::sync::Arc;

use thiserror::Error;

use crate::key::validate_path;

/// Most entries a table holds: an index stays a one-byte varint.
pub const MAX_KNOWN_PATHS: usize = 250;

/// Paths sent as an index, registered by the application (huddle's team layer registers
/// its own keys: `team::known_paths()`). Every robot of a team must register the same
/// table in the same order, and a table only grows at its end: an index, once given, means
/// that path for every build of the application. A reader whose table is shorter than the
/// sender's skips (and counts) updates of the indices it lacks, as it does unknown items.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct KnownPaths {
    /// Shared: a replica clones its table for each frame it reads (no allocation).
    paths: Option<Arc<[String]>>,
}

/// Why a table of known paths was refused.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum KnownPathsError {
    /// An entry is not a valid key path.
    #[error("known path {path:?}: {reason}")]
    BadPath {
        /// The entry.
        path: String,
        /// Why it is not a key path.
        reason: String,
    },
    /// The same path twice.
    #[error("known path {0:?} is registered twice")]
    Duplicate(String),
    /// More than [`MAX_KNOWN_PATHS`] entries.
    #[error("{0} known paths: at most {MAX_KNOWN_PATHS}")]
    TooMany(usize),
}

impl KnownPaths {
    /// The empty table: every path goes as text.
    pub const EMPTY: KnownPaths = KnownPaths { paths: None };

    /// A reference to the empty table, for as long as needed.
    pub fn none() -> &'static KnownPaths {
        static NONE: KnownPaths = KnownPaths::EMPTY;
        &NONE
    }

    /// A table of `paths`, index 0 first.
    pub fn new<I, S>(paths: I) -> Result<KnownPaths, KnownPathsError>
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        let paths: Vec<String> = paths.into_iter().map(Into::into).collect();
        if paths.len() > MAX_KNOWN_PATHS {
            return Err(KnownPathsError::TooMany(paths.len()));
        }
        for (i, p) in paths.iter().enumerate() {
            validate_path(p).map_err(|e| KnownPathsError::BadPath {
                path: p.clone(),
                reason: e.to_string(),
            })?;
            if paths[..i].contains(p) {
                return Err(KnownPathsError::Duplicate(p.clone()));
            }
        }
        Ok(KnownPaths {
            paths: (!paths.is_empty()).then(|| paths.into()),
        })
    }

    fn slice(&self) -> &[String] {
        self.paths.as_deref().unwrap_or_default()
    }

    /// The index of `path`, if registered.
    pub fn index(&self, path: &str) -> Option<u8> {
        // A handful of entries: a scan beats hashing the path.
        self.slice()
            .iter()
            .position(|p| p == path)
            .and_then(|i| u8::try_from(i).ok())
    }

    /// The path at `index`.
    pub fn get(&self, index: u64) -> Option<&str> {
        usize::try_from(index)
            .ok()
            .and_then(|i| self.slice().get(i))
            .map(String::as_str)
    }

    /// Entries registered.
    pub fn len(&self) -> usize {
        self.slice().len()
    }

    /// Whether none is.
    pub fn is_empty(&self) -> bool {
        self.slice().is_empty()
    }

    /// The entries, index 0 first.
    pub fn iter(&self) -> impl Iterator<Item = &str> {
        self.slice().iter().map(String::as_str)
    }
}
