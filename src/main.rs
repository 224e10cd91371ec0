//! The `huddle` command: daemon, command-line clients, simulator, audio and fusion tools.

#![forbid(unsafe_code)]

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
    /// Run one robot's replica on the team's multicast group, with the relay port.
    Daemon(cli::daemon::DaemonArgs),
    /// Read a key through a daemon's relay.
    Get(cli::clients::GetArgs),
    /// Write a key (or post to a talk queue) through a daemon's relay.
    Set(cli::clients::SetArgs),
    /// Live table of the keys matching patterns (the seed's Monitor).
    Watch(cli::clients::WatchArgs),
    /// A daemon's counters: frames, drops by reason, peers.
    Stats(cli::clients::StatsArgs),
    /// Measurements: `huddle bench comms`.
    Bench(cli::bench::BenchArgs),
}

fn main() -> Result<()> {
    cli::init_tracing();
    let cli = Cli::parse();
    match cli.command {
        Some(Command::Audio(args)) => cli::audio::run(args),
        Some(Command::Fusion(args)) => cli::fusion::run(args),
        Some(Command::Sim(args)) => cli::sim::run(args),
        Some(Command::Daemon(args)) => cli::daemon::run(args),
        Some(Command::Get(args)) => cli::clients::get(args),
        Some(Command::Set(args)) => cli::clients::set(args),
        Some(Command::Watch(args)) => cli::clients::watch(args),
        Some(Command::Stats(args)) => cli::clients::stats(args),
        Some(Command::Bench(args)) => cli::bench::run(args),
        // The README's main command: `cargo run --release` runs the built-in match.
        None => cli::sim::run(cli::sim::SimArgs::default()),
    }
}
