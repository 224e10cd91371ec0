//! Reading start-up files: `config.dat`, then `config-<id>.dat` (isocrob-2000 §3.1),
//! parsed by [`comms::parse_config`], and the team key file.
//!
//! Every file is checked before it is read: it must be a regular file (a FIFO or a
//! device would block the daemon or never end: `--key-file /dev/zero`), and it is read
//! with a size limit, so a wrong path is a clear error instead of a hang or an
//! exhausted memory.

use std::fmt;
use std::io::Read;
use std::path::{Path, PathBuf};

use thiserror::Error;

use comms::{ConfigEntry, ConfigError};

/// Largest `config.dat` / `config-<id>.dat` read (16 MiB: far beyond any real config).
pub const MAX_CONFIG_FILE_BYTES: u64 = 16 << 20;
/// Largest team key file read (4 KiB: an HMAC key longer than SHA-256's 64-byte block
/// is hashed down anyway).
pub const MAX_KEY_FILE_BYTES: u64 = 4096;

/// Why a start-up file could not be read.
#[derive(Debug, Error)]
pub enum FileError {
    /// Opening, inspecting or reading it failed.
    #[error("{}: {source}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// It is not a regular file (a directory, FIFO, socket or device).
    #[error("{}: not a regular file (it is a {kind})", file.display())]
    NotRegular {
        /// The file.
        file: PathBuf,
        /// What it is instead.
        kind: &'static str,
    },
    /// It is larger than the limit.
    #[error("{}: larger than {limit} bytes", file.display())]
    TooLarge {
        /// The file.
        file: PathBuf,
        /// The limit.
        limit: u64,
    },
}

/// Why the configuration files could not be loaded.
#[derive(Debug, Error)]
pub enum LoadConfigError {
    /// The configuration directory does not exist or is not a directory.
    #[error("config dir {}: {reason}", dir.display())]
    Dir {
        /// The directory.
        dir: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// A file exists but could not be read.
    #[error(transparent)]
    File(#[from] FileError),
    /// The file is not UTF-8 text.
    #[error("{}: not UTF-8 text", file.display())]
    NotText {
        /// The file.
        file: PathBuf,
    },
    /// A line of it does not parse.
    #[error(transparent)]
    Parse(#[from] ConfigError),
}

/// Why the team key file could not be used.
#[derive(Debug, Error)]
pub enum KeyFileError {
    /// It could not be read (missing, not a regular file, too large).
    #[error("key file {0}")]
    File(#[from] FileError),
    /// It holds nothing but whitespace.
    #[error("key file {}: empty", .0.display())]
    Empty(PathBuf),
}

/// What [`load_config_files`] found.
#[derive(Debug, Clone, Default)]
pub struct LoadedConfig {
    /// The entries, in order (apply them in order: later ones override).
    pub entries: Vec<ConfigEntry>,
    /// The files read, in order (the ones that exist).
    pub files: Vec<PathBuf>,
}

impl LoadedConfig {
    /// One line for the log: `3 values from config.dat, config-2.dat`, or
    /// `no config.dat or config-<id>.dat in <dir>`.
    pub fn summary(&self) -> impl fmt::Display + '_ {
        Summary(self)
    }
}

struct Summary<'a>(&'a LoadedConfig);

impl fmt::Display for Summary<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let loaded = self.0;
        if loaded.files.is_empty() {
            return f.write_str("no config files");
        }
        let n = loaded.entries.len();
        write!(f, "{n} value{} from ", if n == 1 { "" } else { "s" })?;
        for (i, file) in loaded.files.iter().enumerate() {
            if i > 0 {
                f.write_str(", ")?;
            }
            let name = file.file_name().unwrap_or(file.as_os_str());
            write!(f, "{}", Path::new(name).display())?;
        }
        Ok(())
    }
}

/// What a non-regular file is, for the error message.
fn kind_of(meta: &std::fs::Metadata) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    if t.is_dir() {
        "directory"
    } else if t.is_fifo() {
        "FIFO"
    } else if t.is_socket() {
        "socket"
    } else if t.is_char_device() {
        "character device"
    } else if t.is_block_device() {
        "block device"
    } else {
        "special file"
    }
}

/// Reads a regular file of at most `limit` bytes. `Ok(None)` if it does not exist.
///
/// The path is inspected before it is opened (opening a FIFO for reading blocks until a
/// writer comes), and the opened file again (in case the path changed in between); the
/// read stops one byte past the limit whatever the metadata said.
pub fn read_regular_file(file: &Path, limit: u64) -> Result<Option<Vec<u8>>, FileError> {
    let io = |source| FileError::Io {
        file: file.to_owned(),
        source,
    };
    let check = |meta: &std::fs::Metadata| {
        if !meta.is_file() {
            return Err(FileError::NotRegular {
                file: file.to_owned(),
                kind: kind_of(meta),
            });
        }
        if meta.len() > limit {
            return Err(FileError::TooLarge {
                file: file.to_owned(),
                limit,
            });
        }
        Ok(())
    };
    match std::fs::metadata(file) {
        Ok(meta) => check(&meta)?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(io(e)),
    }
    let opened = std::fs::File::open(file).map_err(io)?;
    check(&opened.metadata().map_err(io)?)?;
    let mut bytes = Vec::new();
    opened
        .take(limit.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(io)?;
    if bytes.len() as u64 > limit {
        return Err(FileError::TooLarge {
            file: file.to_owned(),
            limit,
        });
    }
    Ok(Some(bytes))
}

/// Reads the team key: a regular file of at most [`MAX_KEY_FILE_BYTES`], trailing
/// whitespace dropped, not empty.
pub fn read_key_file(file: &Path) -> Result<Vec<u8>, KeyFileError> {
    let bytes = read_regular_file(file, MAX_KEY_FILE_BYTES)?.ok_or_else(|| FileError::Io {
        file: file.to_owned(),
        source: std::io::ErrorKind::NotFound.into(),
    })?;
    let key = bytes.trim_ascii_end();
    if key.is_empty() {
        return Err(KeyFileError::Empty(file.to_owned()));
    }
    Ok(key.to_vec())
}

/// Reads `dir/config.dat` then `dir/config-<robot_id>.dat`, skipping missing files, and
/// returns their entries in order (apply them in order: later ones override) with the
/// files read. `dir` itself must exist; each file must be a regular file of at most
/// [`MAX_CONFIG_FILE_BYTES`].
pub fn load_config_files(dir: &Path, robot_id: u8) -> Result<LoadedConfig, LoadConfigError> {
    let dir_error = |reason: String| LoadConfigError::Dir {
        dir: dir.to_owned(),
        reason,
    };
    match std::fs::metadata(dir) {
        Ok(meta) if meta.is_dir() => {}
        Ok(meta) => return Err(dir_error(format!("not a directory (a {})", kind_of(&meta)))),
        Err(e) => return Err(dir_error(e.to_string())),
    }
    let mut loaded = LoadedConfig::default();
    for name in ["config.dat".to_string(), format!("config-{robot_id}.dat")] {
        let file = dir.join(name);
        let Some(bytes) = read_regular_file(&file, MAX_CONFIG_FILE_BYTES)? else {
            continue;
        };
        let text = String::from_utf8(bytes)
            .map_err(|_| LoadConfigError::NotText { file: file.clone() })?;
        loaded.entries.extend(comms::parse_config(&file, &text)?);
        loaded.files.push(file);
    }
    Ok(loaded)
}

/// [`load_config_files`] without the list of files.
pub fn load_config(dir: &Path, robot_id: u8) -> Result<Vec<ConfigEntry>, LoadConfigError> {
    load_config_files(dir, robot_id).map(|loaded| loaded.entries)
}

#[cfg(test)]
mod tests {
    use super::*;
    use comms::Value;

    fn mkfifo(path: &Path) {
        let status = std::process::Command::new("mkfifo")
            .arg(path)
            .status()
            .expect("run mkfifo");
        assert!(status.success(), "mkfifo {}", path.display());
    }

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
    fn the_summary_names_the_files_read_and_counts_the_values() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("config.dat"),
            "local.var.x = 1\n*.var.y = 2\n",
        )
        .unwrap();
        std::fs::write(dir.path().join("config-2.dat"), "local.var.x = 3\n").unwrap();
        let loaded = load_config_files(dir.path(), 2).unwrap();
        assert_eq!(
            loaded.summary().to_string(),
            "3 values from config.dat, config-2.dat"
        );
        let loaded = load_config_files(dir.path(), 5).unwrap();
        assert_eq!(loaded.summary().to_string(), "2 values from config.dat");
        let empty = tempfile::tempdir().unwrap();
        let loaded = load_config_files(empty.path(), 5).unwrap();
        assert_eq!(loaded.summary().to_string(), "no config files");
    }

    #[test]
    fn a_bad_line_is_an_error_naming_the_file() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("config.dat"), "local.var.x = nonsense\n").unwrap();
        let err = load_config(dir.path(), 1).unwrap_err().to_string();
        assert!(err.contains("config.dat:1: bad value"), "got {err:?}");
    }

    #[test]
    fn a_missing_config_dir_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("no-such-dir");
        let err = load_config(&missing, 1).unwrap_err();
        assert!(matches!(err, LoadConfigError::Dir { .. }), "{err:?}");
        assert!(err.to_string().contains("no-such-dir"), "{err}");
        std::fs::write(dir.path().join("plain"), "").unwrap();
        let err = load_config(&dir.path().join("plain"), 1).unwrap_err();
        assert!(err.to_string().contains("not a directory"), "{err}");
    }

    #[test]
    fn a_fifo_config_is_refused_without_blocking() {
        let dir = tempfile::tempdir().unwrap();
        mkfifo(&dir.path().join("config.dat"));
        let err = load_config(dir.path(), 1).unwrap_err();
        assert!(
            err.to_string()
                .contains("not a regular file (it is a FIFO)"),
            "{err}"
        );
        let dir = tempfile::tempdir().unwrap();
        mkfifo(&dir.path().join("config-3.dat"));
        let err = load_config(dir.path(), 3).unwrap_err().to_string();
        assert!(err.contains("config-3.dat: not a regular file"), "{err}");
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("config.dat")).unwrap();
        let err = load_config(dir.path(), 3).unwrap_err().to_string();
        assert!(err.contains("it is a directory"), "{err}");
    }

    #[test]
    fn the_key_file_must_be_a_small_regular_file() {
        let dir = tempfile::tempdir().unwrap();
        let key = dir.path().join("team.key");
        std::fs::write(&key, "secret \n").unwrap();
        assert_eq!(read_key_file(&key).unwrap(), b"secret");

        let err = read_key_file(Path::new("/dev/zero"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("not a regular file"), "{err}");

        let fifo = dir.path().join("fifo.key");
        mkfifo(&fifo);
        let err = read_key_file(&fifo).unwrap_err().to_string();
        assert!(err.contains("it is a FIFO"), "{err}");

        let big = dir.path().join("big.key");
        std::fs::write(&big, vec![b'k'; MAX_KEY_FILE_BYTES as usize + 1]).unwrap();
        let err = read_key_file(&big).unwrap_err().to_string();
        assert!(err.contains("larger than 4096 bytes"), "{err}");

        std::fs::write(&key, " \n\t").unwrap();
        assert!(matches!(read_key_file(&key), Err(KeyFileError::Empty(_))));
        let err = read_key_file(&dir.path().join("missing.key"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("missing.key"), "{err}");
    }
}
