//! Reading start-up configuration files: `config.dat`, then `config-<id>.dat`
//! (isocrob-2000 §3.1), parsed by [`comms::parse_config`].

use std::path::{Path, PathBuf};

use thiserror::Error;

use comms::{ConfigEntry, ConfigError};

/// Why the configuration files could not be loaded.
#[derive(Debug, Error)]
pub enum LoadConfigError {
    /// The file exists but could not be read.
    #[error("{}: {source}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A line of it does not parse.
    #[error(transparent)]
    Parse(#[from] ConfigError),
}

/// Reads `dir/config.dat` then `dir/config-<robot_id>.dat`, skipping missing files, and
/// returns their entries in order (apply them in order: later ones override).
pub fn load_config(dir: &Path, robot_id: u8) -> Result<Vec<ConfigEntry>, LoadConfigError> {
    let mut entries = Vec::new();
    for name in ["config.dat".to_string(), format!("config-{robot_id}.dat")] {
        let file = dir.join(name);
        let text = match std::fs::read_to_string(&file) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
            Err(source) => return Err(LoadConfigError::Io { file, source }),
        };
        entries.extend(comms::parse_config(&file, &text)?);
    }
    Ok(entries)
}

#[cfg(test)]
mod tests {
    use super::*;
    use comms::Value;

    #[test]
    fn per_robot_file_comes_after_the_common_one_and_missing_files_are_skipped() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("config.dat"), "local.var.x = 1\n").unwrap();
        std::fs::write(dir.path().join("config-4.dat"), "local.var.x = 2\n").unwrap();
        let entries = load_config(dir.path(), 4);
        let only_common = load_config(dir.path(), 5);
        let values: Vec<Value> = entries.unwrap().into_iter().map(|e| e.value).collect();
        assert_eq!(values, [Value::Int(1), Value::Int(2)]);
        assert_eq!(only_common.unwrap().len(), 1, "no config-5.dat");
    }

    #[test]
    fn a_bad_line_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("config.dat"), "local.var.x = nonsense\n").unwrap();
        let err = load_config(dir.path(), 1).unwrap_err().to_string();
        assert!(err.contains("config.dat:1: bad value"), "got {err:?}");
    }
}
