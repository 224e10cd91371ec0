//! `huddle-bridge`: one team's field, listened to, mirrored into Zenoh. See the crate
//! docs and docs/bridge.md.

use anyhow::Result;
use clap::{Parser, Subcommand};
use huddle_bridge::cli::RunArgs;
use huddle_bridge::run::Bridge;

/// A listen-only bridge from a huddle team to Zenoh.
#[derive(Parser, Debug)]
#[command(
    version,
    args_conflicts_with_subcommands = true,
    subcommand_negates_reqs = true
)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    #[command(flatten)]
    run: Option<RunArgs>,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Measure the bridge on loopback: latency added, throughput, first sample.
    Bench(huddle_bridge::bench::BenchArgs),
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "info,zenoh=warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    match (cli.command, cli.run) {
        (Some(Command::Bench(args)), _) => huddle_bridge::bench::run(&args),
        (None, Some(run)) => {
            let bridge = Bridge::start(run.config()?)?;
            bridge.run()?;
            Ok(())
        }
        (None, None) => anyhow::bail!("give --team, --venue and --connect, or `bench`"),
    }
}
