//! One module per subcommand; each owns its clap arguments and its `run`. Shared by all:
//! the duration syntax (`duration`), the relay address and connection (`relay`), logs,
//! and output that ends quietly when the reader goes away (`outln!`).

// The commands run in real time: timing a run, pacing a display, waiting for a daemon.
#![allow(clippy::disallowed_methods)]

/// `println!` that returns the write error (`?`) instead of panicking, so that
/// `huddle … | head -1` ends quietly when `head` stops reading.
macro_rules! outln {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        writeln!(std::io::stdout(), $($arg)*)?
    }};
}

pub mod audio;
pub mod bench;
pub mod clients;
pub mod daemon;
pub mod duration;
pub mod feed;
pub mod fusion;
pub mod generate;
pub mod hz;
pub mod monitor;
pub mod monitor_sim;
pub mod record;
pub mod relay;
pub mod sim;
pub mod sim_tap;
pub mod transport;
pub mod watch;

use std::io::IsTerminal;

/// Logs go to stderr, coloured only when stderr is a terminal (and `NO_COLOR` is unset).
/// The level: `-q` warnings, `-qq` errors only, `-v` debug, `-vv` trace; without
/// either, `RUST_LOG` (default `info`).
pub fn init_tracing(verbose: u8, quiet: u8) {
    use tracing_subscriber::EnvFilter;
    let level = match (verbose, quiet) {
        (0, 0) => None,
        (0, 1) => Some("warn"),
        (0, _) => Some("error"),
        (1, _) => Some("debug"),
        _ => Some("trace"),
    };
    let filter = match level {
        Some(level) => EnvFilter::new(level),
        None => EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info")),
    };
    let colour = std::io::stderr().is_terminal() && std::env::var_os("NO_COLOR").is_none();
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_ansi(colour)
        .with_writer(std::io::stderr)
        .try_init();
}

/// Whether an error is the reader of our output going away (`| head`): not worth a word.
pub fn is_broken_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|cause| {
        cause
            .downcast_ref::<std::io::Error>()
            .is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}
