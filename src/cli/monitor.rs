//! `huddle monitor`: the team monitor in the browser, live from the real robots. A
//! listen-only member of the team's group: it joins, decodes every robot's frames
//! (world models, should-I-go claims, stats, talk) and never sends one.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Args;
use driver::resolve_iface;

use super::transport::{listening_on, TransportArgs};
use monitor::listen::LISTENER_ID;
use monitor::model::Model;
use monitor::server;

/// Arguments of `huddle monitor`.
#[derive(Args, Debug)]
#[command(
    after_help = "Listen-only: the monitor joins the group (or listens on the broadcast \
                  port, with --transport broadcast) and never sends a frame (no \
                  heartbeat, no repair requests), so the team's budget and its members' \
                  peer tables are untouched. With --transport unicast it hears what the \
                  robots send it as one of their --peer addresses. Open the printed address in a browser; \
                  GET /state gives the same picture as JSON."
)]
pub struct MonitorArgs {
    /// --transport, --group, --port, --broadcast: as the team's daemons.
    #[command(flatten)]
    pub transport: TransportArgs,
    /// Interface to listen on: a name (`wlan0`) or its IPv4 address.
    #[arg(long, default_value = "127.0.0.1")]
    pub iface: String,
    /// Team id (as the daemons' `--team`).
    #[arg(long, default_value_t = 0)]
    pub team: u8,
    /// Team key file, when the team's frames are tagged.
    #[arg(long)]
    pub key_file: Option<PathBuf>,
    /// Where to serve the page.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub http: SocketAddr,
    /// Frames each robot may send in a game (a league's message budget, e.g. 1200): the
    /// page shows the share used.
    #[arg(long)]
    pub budget: Option<u64>,
    /// The monitor's own robot id (frames from this id are not decoded).
    #[arg(long, default_value_t = LISTENER_ID)]
    pub listen_id: u8,
}

/// Run `huddle monitor`.
pub fn run(args: MonitorArgs) -> Result<()> {
    let iface = resolve_iface(&args.iface)?;
    let key = match &args.key_file {
        Some(f) => Some(driver::read_key_file(f)?),
        None => None,
    };
    let cfg = args.transport.socket_config(iface, Some(args.team))?;
    let opened = driver::open(&cfg).with_context(|| listening_on(&cfg))?;
    let model = Model::new(args.team, key, args.listen_id, 0, "live", args.budget)?;
    let shared: server::Shared = Arc::new(Mutex::new(model));
    server::spawn(args.http, shared.clone())?;
    tracing::info!("{} (listen-only: nothing is sent)", listening_on(&cfg));
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    rt.block_on(async move {
        let socket = tokio::net::UdpSocket::from_std(opened.socket)?;
        let started = tokio::time::Instant::now();
        let t_ns = move || started.elapsed().as_nanos() as u64;
        let mut ticks = tokio::time::interval(Duration::from_millis(50));
        let ctrl_c = tokio::signal::ctrl_c();
        tokio::pin!(ctrl_c);
        let mut buf = vec![0u8; 65_536];
        loop {
            tokio::select! {
                _ = &mut ctrl_c => break,
                _ = ticks.tick() => {
                    shared.lock().unwrap_or_else(|p| p.into_inner()).advance(t_ns());
                }
                got = socket.recv_from(&mut buf) => {
                    let (len, from) = got.context("receiving")?;
                    let mut model = shared.lock().unwrap_or_else(|p| p.into_inner());
                    model.datagram(t_ns(), from, &buf[..len]);
                }
            }
        }
        anyhow::Ok(())
    })
}
