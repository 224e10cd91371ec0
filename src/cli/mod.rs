//! One module per subcommand; each owns its clap arguments and its `run`.

// The commands run in real time: timing a run, pacing a display, waiting for a daemon.
#![allow(clippy::disallowed_methods)]

pub mod audio;
pub mod bench;
pub mod clients;
pub mod daemon;
pub mod fusion;
pub mod sim;

/// Logs go to stderr, filtered by `RUST_LOG` (default `info`).
pub fn init_tracing() {
    use tracing_subscriber::EnvFilter;
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .try_init();
}
