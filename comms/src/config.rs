//! The text of start-up configuration files: `config.dat`, then `config-<id>.dat`
//! (isocrob-2000 §3.1). Reading the files is the driver's job (`driver::load_config`);
//! this module only parses text.
//!
//! One `key = value` per line; blank lines and `#` comments (whole-line, or after the
//! value) are ignored; values use the literal syntax of [`crate::literal`]. A missing
//! file is skipped (a robot may have no per-robot overrides); any bad line is an error
//! that names the file and the 1-based line number. Later lines win, so
//! `config-<id>.dat` overrides `config.dat`.

use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::key::{Key, KeyError};
use crate::literal::{parse_literal_prefix, LiteralError};
use crate::value::Value;

/// One `key = value` line.
#[derive(Clone, Debug, PartialEq)]
pub struct ConfigEntry {
    /// The key as written (`local.var.x`, `*.var.x`).
    pub key: Key,
    /// The value.
    pub value: Value,
    /// The file it came from.
    pub file: PathBuf,
    /// Its 1-based line number.
    pub line: usize,
}

/// Why a configuration text does not parse.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum ConfigError {
    /// A line is not `key = value`.
    #[error("{}:{line}: {reason}", file.display())]
    Line {
        /// The file.
        file: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What is wrong with it.
        reason: LineError,
    },
}

/// What is wrong with one configuration line.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum LineError {
    /// No `=` between key and value.
    #[error("expected `key = value`")]
    MissingEquals,
    /// The key does not parse.
    #[error("bad key: {0}")]
    Key(#[from] KeyError),
    /// The value does not parse.
    #[error("bad value: {0}")]
    Value(#[from] LiteralError),
    /// Text after the value that is not a `#` comment.
    #[error("unexpected text after the value: {0:?}")]
    Trailing(String),
}

/// Parses the text of one configuration file; `file` is only used in errors and entries.
pub fn parse_config(file: &Path, text: &str) -> Result<Vec<ConfigEntry>, ConfigError> {
    let mut entries = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let at = |reason: LineError| ConfigError::Line {
            file: file.to_owned(),
            line: i + 1,
            reason,
        };
        let (key, rest) = line
            .split_once('=')
            .ok_or_else(|| at(LineError::MissingEquals))?;
        let key = Key::parse(key.trim()).map_err(|e| at(e.into()))?;
        let (value, rest) = parse_literal_prefix(rest).map_err(|e| at(e.into()))?;
        let rest = rest.trim();
        if !(rest.is_empty() || rest.starts_with('#')) {
            return Err(at(LineError::Trailing(rest.to_owned())));
        }
        entries.push(ConfigEntry {
            key,
            value,
            file: file.to_owned(),
            line: i + 1,
        });
    }
    Ok(entries)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_config_file_with_comments_and_every_literal_parses() {
        let text = "# defender settings\n\
                    local.var.machine.config.def.near-ball = 0.5\n\
                    \n\
                    *.var.team.name = \"ISocRob # 1\"   # trailing comment\n\
                    local.var.kicker.pulse_ms=125\n\
                    local.var.flags = [1, 2.5]\n";
        let entries = parse_config(Path::new("config.dat"), text).unwrap();
        let got: Vec<(String, Value, usize)> = entries
            .iter()
            .map(|e| (e.key.to_string(), e.value.clone(), e.line))
            .collect();
        assert_eq!(
            got,
            vec![
                (
                    "local.var.machine.config.def.near-ball".into(),
                    Value::Float(0.5),
                    2
                ),
                (
                    "*.var.team.name".into(),
                    Value::String("ISocRob # 1".into()),
                    4
                ),
                ("local.var.kicker.pulse_ms".into(), Value::Int(125), 5),
                ("local.var.flags".into(), Value::Floats(vec![1.0, 2.5]), 6),
            ]
        );
    }

    #[test]
    fn a_bad_line_names_file_and_line() {
        let text = "local.var.a = 1\nlocal.var.b = nonsense\n";
        let err = parse_config(Path::new("conf/config-3.dat"), text).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.starts_with("conf/config-3.dat:2: bad value"),
            "got {msg:?}"
        );
        for (text, want) in [
            ("just words", "MissingEquals"),
            ("local.x = 1", "Key"),
            ("local.var.x = 1 2", "Trailing"),
        ] {
            let err = parse_config(Path::new("c"), text).unwrap_err();
            assert!(format!("{err:?}").contains(want), "{text:?} gave {err:?}");
        }
    }
}
