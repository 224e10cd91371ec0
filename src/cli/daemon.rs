//! `huddle daemon`: one robot's replica on the team's multicast group (or broadcast
//! port, or unicast peers: `--transport`), with the relay port for programs in any
//! language (isocrob-2000's Proxy and Relay μAgents).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;

use super::duration;
use super::relay::RelayTarget;
use super::transport::TransportArgs;
use comms::ReplicaConfig;
use driver::{resolve_iface, Driver, DriverConfig};
use huddle::impair::LinkImpairment;

/// Arguments of `huddle daemon`.
#[derive(Args, Debug, Clone)]
pub struct DaemonArgs {
    /// This robot's id, 1..=254 (default: the ROBOT_ID environment variable).
    #[arg(long)]
    pub id: Option<u8>,
    /// Team id: frames of other teams are dropped.
    #[arg(long, default_value_t = 0)]
    pub team: u8,
    /// --transport, --group, --port, --broadcast.
    #[command(flatten)]
    pub transport: TransportArgs,
    /// Interface, by name (wlan0) or IPv4 address: multicast membership and
    /// IP_MULTICAST_IF, the broadcast address, the unicast address. Loopback by
    /// default, so nothing leaves this machine unless asked.
    #[arg(long, default_value = "127.0.0.1")]
    pub iface: String,
    /// Also send every frame by unicast to this teammate (repeatable); with --transport
    /// unicast, to these only (then at least one is needed). Unicast is received on
    /// <iface>:<port> from the listed peers only; without --peer, none is.
    #[arg(long = "peer", value_name = "ADDR:PORT")]
    pub peers: Vec<SocketAddr>,
    /// Relay listening address: host:port, a port (on 127.0.0.1) or a host name (port
    /// 2001); any other than loopback must be given explicitly.
    #[arg(long, env = "HUDDLE_RELAY", default_value = "127.0.0.1:2001")]
    pub relay: RelayTarget,
    /// Directory of config.dat and config-<id>.dat.
    #[arg(long, default_value = ".")]
    pub config_dir: PathBuf,
    /// Team key file: frames are tagged with HMAC-SHA256 under its contents (trailing
    /// whitespace ignored); untagged or badly tagged frames are dropped.
    #[arg(long)]
    pub key_file: Option<PathBuf>,
    /// Refresh period of every global value (`100ms`, `1s`).
    #[arg(long, default_value = "100ms", value_parser = duration::parse_positive)]
    pub refresh: Duration,
    /// Multicast TTL.
    #[arg(long, default_value_t = 1)]
    pub ttl: u32,
    /// Impair every outgoing datagram with netsim's link model, to rehearse a bad WLAN:
    /// a netsim spec such as `loss=20%,delay=50ms,jitter=20ms` or `preset=competition`
    /// (then refined: `preset=competition,loss=5%`). Outgoing only: with every robot
    /// impaired, each direction is impaired once.
    #[arg(long, value_name = "SPEC")]
    pub impair: Option<String>,
    /// Seed of the impairment's random draws (default: the robot id, so that robots
    /// of one team lose different frames and a rerun draws the same fates).
    #[arg(long, value_name = "N")]
    pub impair_seed: Option<u64>,
}

/// The `--impair` model, if asked for, seeded by `--impair-seed` or the robot id.
pub fn impairment(args: &DaemonArgs, robot_id: u8) -> Result<Option<LinkImpairment>> {
    let Some(spec) = &args.impair else {
        if args.impair_seed.is_some() {
            bail!("--impair-seed needs --impair SPEC");
        }
        return Ok(None);
    };
    let config: netsim::LinkConfig = spec.parse().with_context(|| format!("--impair {spec:?}"))?;
    let seed = args.impair_seed.unwrap_or(u64::from(robot_id));
    let model = LinkImpairment::new(config, seed).with_context(|| format!("--impair {spec:?}"))?;
    Ok(Some(model))
}

/// Builds the driver configuration from the arguments: robot id, config files, key.
pub fn driver_config(args: &DaemonArgs) -> Result<DriverConfig> {
    let id = match args.id {
        Some(id) => id,
        None => {
            let raw = std::env::var("ROBOT_ID")
                .map_err(|_| anyhow!("no robot id: pass --id N or set ROBOT_ID"))?;
            raw.trim()
                .parse()
                .with_context(|| format!("ROBOT_ID={raw:?} is not a robot id 1..=254"))?
        }
    };
    if !comms::ROBOT_IDS.contains(&id) {
        bail!("robot id {id} is outside 1..=254");
    }
    if args.refresh.is_zero() {
        bail!("--refresh must be positive");
    }
    let mut replica = ReplicaConfig::new(id, args.team).with_refresh_period(args.refresh);
    // Say what was loaded (never the key itself): a robot that cannot hear its team
    // usually runs with another key or config than its teammates.
    match &args.key_file {
        Some(file) => {
            let key = driver::read_key_file(file)?;
            tracing::info!(
                "team key: {} (untagged or badly tagged frames are dropped)",
                file.display()
            );
            replica = replica.with_team_key(key);
        }
        None => tracing::info!("team key: none (frames are not authenticated)"),
    }
    let loaded = driver::load_config_files(&args.config_dir, id)?;
    tracing::info!(
        "config: {} ({})",
        loaded.summary(),
        args.config_dir.display()
    );
    let entries = loaded.entries;
    let mut config = DriverConfig::new(replica);
    config.start_values = entries.into_iter().map(|e| (e.key, e.value)).collect();
    let iface = resolve_iface(&args.iface)?;
    config.socket = args.transport.socket_config(iface, Some(args.team))?;
    config.socket.ttl = args.ttl;
    config.peers = args.peers.clone();
    if config.socket.transport == driver::Transport::Unicast && config.peers.is_empty() {
        bail!("--transport unicast sends to each --peer only: give at least one --peer ADDR:PORT");
    }
    Ok(config)
}

/// Runs the daemon until SIGINT or SIGTERM.
pub fn run(args: DaemonArgs) -> Result<()> {
    let config = driver_config(&args)?;
    let impair = impairment(&args, config.replica.robot_id)?;
    // One thread for socket, replica, timers and relay clients: a hand-off between threads
    // costs a full wake-up, several times a loopback round trip, and the driver and its
    // handles are `!Send` for that reason.
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let local = tokio::task::LocalSet::new();
    local.block_on(&runtime, async move {
        let relay_addrs = args.relay.resolve()?;
        let relay = std::net::TcpListener::bind(&relay_addrs[..]).map_err(|e| {
            anyhow!(
                "cannot open the relay port {}: {e}{}",
                args.relay,
                if e.kind() == std::io::ErrorKind::AddrInUse {
                    " (is another daemon using it? pick another with --relay)"
                } else {
                    ""
                }
            )
        })?;
        relay.set_nonblocking(true)?;
        let relay = tokio::net::TcpListener::from_std(relay)?;
        let driver = Driver::bind(config)?;
        if let Some(model) = impair {
            tracing::warn!(
                spec = %model.config(),
                "--impair: outgoing datagrams pass through netsim's link model"
            );
            driver.set_impairment(Some(Box::new(model)));
        }
        let handle = driver.handle();
        tracing::info!(
            robot = handle.robot_id(),
            relay = %args.relay,
            "huddle daemon running"
        );
        let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
        let mut relay_stop = stop_rx.clone();
        tokio::task::spawn_local(driver::serve(relay, handle, async move {
            let _ = relay_stop.wait_for(|s| *s).await;
        }));
        let signals = async move {
            shutdown_signal().await;
            let _ = stop_tx.send(true);
        };
        driver.run(signals).await?;
        tracing::info!("huddle daemon stopped");
        drop(stop_rx);
        Ok(())
    })
}

/// SIGINT (Ctrl-C) or SIGTERM.
async fn shutdown_signal() {
    use tokio::signal::unix::{signal, SignalKind};
    let mut term = match signal(SignalKind::terminate()) {
        Ok(s) => s,
        Err(e) => {
            tracing::warn!(error = %e, "cannot watch SIGTERM; Ctrl-C still works");
            let _ = tokio::signal::ctrl_c().await;
            return;
        }
    };
    tokio::select! {
        _ = tokio::signal::ctrl_c() => tracing::info!("SIGINT: shutting down"),
        _ = term.recv() => tracing::info!("SIGTERM: shutting down"),
    }
}
