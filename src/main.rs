//! The `huddle` command: daemon, command-line clients, simulator, audio and fusion tools.

use anyhow::Result;
use clap::{Parser, Subcommand};

mod cli;

/// huddle: team communication and world-model fusion for robot teams.
#[derive(Parser, Debug)]
#[command(name = "huddle", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Acoustic messaging: encode, decode, listen, eval.
    Audio(cli::audio::AudioArgs),
    /// World-model tools: offline pose EKF replay.
    Fusion(cli::fusion::FusionArgs),
    /// Simulate a match over a simulated network and report on arbitration (the default).
    Sim(cli::sim::SimArgs),
}

fn main() -> Result<()> {
    cli::init_tracing();
    let cli = Cli::parse();
    match cli.command {
        Some(Command::Audio(args)) => cli::audio::run(args),
        Some(Command::Fusion(args)) => cli::fusion::run(args),
        Some(Command::Sim(args)) => cli::sim::run(args),
        // The README's main command: `cargo run --release` runs the built-in match.
        None => cli::sim::run(cli::sim::SimArgs::default()),
    }
}
