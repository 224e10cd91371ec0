//! The `huddle` command: daemon, command-line clients, simulator, audio and fusion tools.

#![forbid(unsafe_code)]

use std::process::ExitCode;

use anyhow::Result;
use clap::{ArgAction, CommandFactory, Parser, Subcommand};

mod cli;

/// huddle: team communication and world-model fusion for robot teams.
#[derive(Parser, Debug)]
#[command(name = "huddle", version, about, long_about = None)]
struct Cli {
    /// More log output: -v debug, -vv trace (instead of RUST_LOG).
    #[arg(short, long, action = ArgAction::Count, global = true)]
    verbose: u8,
    /// Less log output: -q warnings only, -qq errors only (instead of RUST_LOG).
    #[arg(short, long, action = ArgAction::Count, global = true, conflicts_with = "verbose")]
    quiet: u8,
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
    /// List the keys bound on a daemon (all, or those matching a pattern).
    Keys(cli::clients::KeysArgs),
    /// Stream changes as they happen, one line each (time, owner, key, value, age).
    Echo(cli::clients::EchoArgs),
    /// Live table of the keys matching patterns (the seed's Monitor).
    Watch(cli::watch::WatchArgs),
    /// How often keys change: rate, jitter and age per key (like `ros2 topic hz`).
    Hz(cli::hz::HzArgs),
    /// A daemon's counters: frames, drops by reason, peers.
    Stats(cli::clients::StatsArgs),
    /// The team monitor in the browser, live; listen-only (never sends a frame).
    Monitor(cli::monitor::MonitorArgs),
    /// Record a team's traffic to a pcapng file, listen-only (never sends a frame).
    Record(cli::record::RecordArgs),
    /// Decode a recording through the replica code: updates as text or JSON lines.
    Replay(cli::record::ReplayArgs),
    /// Measurements: `huddle bench comms`.
    Bench(cli::bench::BenchArgs),
    /// Print a shell completion script: `huddle completions bash > /etc/bash_completion.d/huddle`.
    Completions(cli::generate::CompletionsArgs),
    /// Print the man page (roff): `huddle man > huddle.1`; `--dir DIR`: one per subcommand.
    Man(cli::generate::ManArgs),
}

fn run(command: Option<Command>) -> Result<()> {
    match command {
        Some(Command::Audio(args)) => cli::audio::run(args),
        Some(Command::Fusion(args)) => cli::fusion::run(args),
        Some(Command::Sim(args)) => cli::sim::run(args),
        Some(Command::Daemon(args)) => cli::daemon::run(args),
        Some(Command::Get(args)) => cli::clients::get(args),
        Some(Command::Set(args)) => cli::clients::set(args),
        Some(Command::Keys(args)) => cli::clients::keys(args),
        Some(Command::Echo(args)) => cli::clients::echo(args),
        Some(Command::Watch(args)) => cli::watch::watch(args),
        Some(Command::Hz(args)) => cli::hz::run(args),
        Some(Command::Stats(args)) => cli::clients::stats(args),
        Some(Command::Monitor(args)) => cli::monitor::run(args),
        Some(Command::Record(args)) => cli::record::record(args),
        Some(Command::Replay(args)) => cli::record::replay(args),
        Some(Command::Bench(args)) => cli::bench::run(args),
        Some(Command::Completions(args)) => cli::generate::completions(args, Cli::command()),
        Some(Command::Man(args)) => cli::generate::man(args, Cli::command()),
        // The README's main command: `cargo run --release` runs the built-in match.
        None => cli::sim::run(cli::sim::SimArgs::default()),
    }
}

fn main() -> ExitCode {
    // Output a reader stopped reading (`huddle sim | head -1`) is no reason for a panic
    // message; anything else that panics is a bug and is reported as usual.
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let text = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if text.contains("Broken pipe") {
            std::process::exit(0);
        }
        default_hook(info);
    }));
    let cli = Cli::parse();
    cli::init_tracing(cli.verbose, cli.quiet);
    match run(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) if cli::is_broken_pipe(&e) => ExitCode::SUCCESS,
        Err(e) => {
            // `{:#}`: the message and its causes on one line, never a backtrace, whatever
            // RUST_BACKTRACE says: these are the user's errors, not the program's.
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}
