//! `huddle-bridge`: one team's field, listened to, mirrored into Zenoh. See the crate
//! docs and docs/bridge.md.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

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
    // The field task runs on Zenoh's TX runtime and may put there (the fast path): a put
    // that has to wait for a free batch waits for Zenoh's transmit task, which then needs a
    // second worker to run on. Zenoh reads this once, at its first use (none yet).
    if std::env::var_os(zenoh_runtime::ZENOH_RUNTIME_ENV).is_none() {
        std::env::set_var(
            zenoh_runtime::ZENOH_RUNTIME_ENV,
            "(tx: (worker_threads: 2))",
        );
    }
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
            stop_on_signal(bridge.shutdown_flag())?;
            bridge.run()?;
            Ok(())
        }
        (None, None) => anyhow::bail!("give --team, --venue and --connect, or `bench`"),
    }
}

/// SIGTERM or SIGINT stops the bridge cleanly: what waits in its outbox and in Zenoh's
/// queue is written out before the session closes (the latest-value guarantee holds
/// through a shutdown). A second signal is not needed; a SIGKILL loses the queue.
fn stop_on_signal(flag: Arc<AtomicBool>) -> Result<()> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_io()
        .build()?;
    std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || {
            rt.block_on(async {
                let Ok(mut term) =
                    tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
                else {
                    tracing::warn!("no SIGTERM handler: a SIGTERM ends the bridge unflushed");
                    let _ = tokio::signal::ctrl_c().await;
                    return;
                };
                tokio::select! {
                    _ = tokio::signal::ctrl_c() => {}
                    _ = term.recv() => {}
                }
            });
            tracing::info!("stopping: flushing the outbox and Zenoh's queue");
            flag.store(true, Ordering::Relaxed);
        })?;
    Ok(())
}
