//! `huddle record` and `huddle replay`: a team's traffic to a pcapng file, listen-only,
//! and back through the same replica code, as JSON lines.
//!
//! The file format is in `monitor/src/pcapng.rs`: pcapng with one IPv4/UDP packet per
//! datagram and its reception time on the recording machine's clock (nanoseconds), so
//! Wireshark and tshark open it as they are (`tshark -r match.pcapng`).

use std::io::{BufWriter, Write};
use std::net::{SocketAddr, SocketAddrV4};
use std::path::PathBuf;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::{bail, Context, Result};
use clap::Args;
use driver::resolve_iface;

use super::duration;
use super::transport::{listening_on, TransportArgs};
use std::sync::{Arc, Mutex};

use monitor::listen::{Heard, LISTENER_ID, REPLAY_TAIL};
use monitor::model::Model;
use monitor::pcapng::{self, Packet, Writer};
use monitor::server;

/// Arguments of `huddle record`.
#[derive(Args, Debug)]
#[command(
    after_help = "Listen-only: the recorder joins the group (or listens on the broadcast \
                  port, --transport broadcast --port N) and never sends a frame. \
                  Stop it with Ctrl-C or --duration; every datagram is on disk as it arrives."
)]
pub struct RecordArgs {
    /// --transport, --group, --port, --broadcast: as the team's daemons.
    #[command(flatten)]
    pub transport: TransportArgs,
    /// Interface to listen on: a name (`wlan0`) or its IPv4 address.
    #[arg(long, default_value = "127.0.0.1")]
    pub iface: String,
    /// Stop after this long (`30s`, `10min`); without it, until Ctrl-C.
    #[arg(long, value_parser = duration::parse_positive)]
    pub duration: Option<Duration>,
    /// The pcapng file to write.
    pub file: PathBuf,
}

/// Arguments of `huddle replay`.
#[derive(Args, Debug)]
pub struct ReplayArgs {
    /// A recording (`huddle record`, `huddle sim --record`, or any pcapng of the group).
    pub file: PathBuf,
    /// Team id of the frames (as the daemons' `--team`); default: the first frame's.
    #[arg(long)]
    pub team: Option<u8>,
    /// Team key file, when the team's frames are tagged.
    #[arg(long)]
    pub key_file: Option<PathBuf>,
    /// Pace the replay at N times real time (`--speed 1`: as recorded); without it, as
    /// fast as it decodes.
    #[arg(long)]
    pub speed: Option<f64>,
    /// Print every update as a JSON line: {"t", "owner", "key", "type", "value"}.
    #[arg(long)]
    pub json: bool,
    /// Only packets sent to this group and port (default: every UDP packet in the file).
    #[arg(long)]
    pub group: Option<SocketAddrV4>,
    /// The listener's own robot id (frames from this id are not decoded); default: the
    /// highest id no frame in the recording comes from (254 when all are free).
    #[arg(long)]
    pub listen_id: Option<u8>,
    /// Print the team ball over time instead, as the team's world model fuses it from
    /// every robot's local world model: {"t", "x", "y", "gbc"} every 100 ms.
    #[arg(long, conflicts_with = "json")]
    pub world: bool,
    /// Serve the team monitor on this address while replaying (real time unless
    /// --speed), and after it until Ctrl-C.
    #[arg(long, value_name = "ADDR")]
    pub monitor: Option<SocketAddr>,
}

/// Run `huddle record`.
pub fn record(args: RecordArgs) -> Result<()> {
    let iface = resolve_iface(&args.iface)?;
    let cfg = args.transport.socket_config(iface, None)?;
    let opened = driver::open(&cfg).with_context(|| listening_on(&cfg))?;
    // The address the team's frames were sent to, as the recording's destination.
    let to = opened
        .destination
        .unwrap_or(SocketAddrV4::new(iface, cfg.group.port()));
    let file = std::fs::File::create(&args.file)
        .with_context(|| format!("creating {}", args.file.display()))?;
    let mut writer = Writer::new(BufWriter::new(file))
        .with_context(|| format!("writing {}", args.file.display()))?;
    writer.flush()?;
    tracing::info!(
        "recording: {}, to {} (listen-only; receive buffer {} bytes)",
        listening_on(&cfg),
        args.file.display(),
        opened.recv_buffer_granted
    );
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let count = rt.block_on(async {
        let socket = tokio::net::UdpSocket::from_std(opened.socket)?;
        let deadline = args.duration.map(|d| tokio::time::Instant::now() + d);
        let stop = async move {
            match deadline {
                Some(d) => tokio::time::sleep_until(d).await,
                None => std::future::pending().await,
            }
        };
        tokio::pin!(stop);
        let ctrl_c = tokio::signal::ctrl_c();
        tokio::pin!(ctrl_c);
        let mut buf = vec![0u8; 65_536];
        let mut count = 0u64;
        loop {
            tokio::select! {
                _ = &mut stop => break,
                _ = &mut ctrl_c => break,
                got = socket.recv_from(&mut buf) => {
                    let (len, from) = got.context("receiving")?;
                    let SocketAddr::V4(from) = from else { continue };
                    let t_ns = SystemTime::now()
                        .duration_since(UNIX_EPOCH)
                        .map_or(0, |d| d.as_nanos() as u64);
                    writer.write(&Packet { t_ns, from, to, payload: buf[..len].to_vec() })?;
                    writer.flush()?;
                    count += 1;
                }
            }
        }
        anyhow::Ok(count)
    })?;
    writer.flush()?;
    tracing::info!("recorded {count} datagrams to {}", args.file.display());
    Ok(())
}

/// Reads a recording and runs it through the monitor's model (a listen-only replica and
/// a GWM), calling `each` with what each datagram changed (paced at `speed` times real
/// time if given; with `--monitor`, real time unless `--speed` says otherwise).
pub fn replay_file(
    args: &ReplayArgs,
    shared: Option<&server::Shared>,
    mut each: impl FnMut(&Model, &[Heard]) -> Result<()>,
) -> Result<()> {
    let speed = match args.speed {
        Some(s) if !(s.is_finite() && s > 0.0) => {
            bail!("--speed must be a positive number, not {s}")
        }
        Some(s) => Some(s),
        None if args.monitor.is_some() => Some(1.0),
        None => None,
    };
    let (packets, model) = open_recording(args)?;
    let shared = match shared {
        Some(s) => {
            *s.lock().unwrap_or_else(|p| p.into_inner()) = model;
            s.clone()
        }
        None => Arc::new(Mutex::new(model)),
    };
    let started = std::time::Instant::now();
    let lock = || shared.lock().unwrap_or_else(|p| p.into_inner());
    for p in packets
        .iter()
        .filter(|p| args.group.is_none_or(|g| g == p.to))
    {
        if let Some(speed) = speed {
            let due = Duration::from_secs_f64(lock().seconds_at(p.t_ns) / speed);
            if let Some(wait) = due.checked_sub(started.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        let mut model = lock();
        let heard = model.datagram(p.t_ns, SocketAddr::V4(p.from), &p.payload);
        each(&model, &heard)?;
    }
    if let Some(last) = packets.last() {
        let mut model = lock();
        let mut heard = Vec::new();
        model.advance_heard(last.t_ns + REPLAY_TAIL.as_nanos() as u64, &mut heard);
        each(&model, &heard)?;
        model.finish();
    }
    Ok(())
}

/// The packets of a recording and a model for them (team from the first frame unless
/// given, key file read).
fn open_recording(args: &ReplayArgs) -> Result<(Vec<Packet>, Model)> {
    let bytes = read_recording(&args.file)?;
    let packets = pcapng::read(&bytes).with_context(|| format!("{}", args.file.display()))?;
    let key = match &args.key_file {
        Some(f) => Some(driver::read_key_file(f)?),
        None => None,
    };
    let start_ns = packets.first().map_or(0, |p| p.t_ns);
    let team = args
        .team
        .or_else(|| packets.iter().find_map(|p| team_of(&p.payload)))
        .unwrap_or(0);
    let listen_id = args.listen_id.unwrap_or_else(|| {
        let senders: std::collections::BTreeSet<u8> = packets
            .iter()
            .filter_map(|p| comms::wire::peek_origin(&p.payload, team).map(|(id, _)| id))
            .collect();
        (1..=LISTENER_ID)
            .rev()
            .find(|id| !senders.contains(id))
            .unwrap_or(LISTENER_ID)
    });
    let model = Model::new(team, key, listen_id, start_ns, "replay", None)?;
    Ok((packets, model))
}

/// A recording larger than this is refused (a 20-minute match of five robots is about
/// 15 MB): the file is read into memory whole.
pub const MAX_RECORDING_BYTES: u64 = 1 << 30;

/// The bytes of a recording: a regular file of at most [`MAX_RECORDING_BYTES`]. A FIFO,
/// a device (`/dev/zero`) or a socket is refused before anything is read (it may never
/// end); a file that grows while read is read only up to the limit.
pub fn read_recording(path: &std::path::Path) -> Result<Vec<u8>> {
    use std::io::Read as _;
    let meta = std::fs::metadata(path).with_context(|| format!("reading {}", path.display()))?;
    if !meta.file_type().is_file() {
        bail!(
            "{}: not a regular file (a pipe or a device may never end); save the recording \
             to a file first",
            path.display()
        );
    }
    if meta.len() > MAX_RECORDING_BYTES {
        bail!(
            "{}: {} bytes, larger than the {} bytes a replay reads",
            path.display(),
            meta.len(),
            MAX_RECORDING_BYTES
        );
    }
    let file = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(MAX_RECORDING_BYTES + 1)
        .read_to_end(&mut bytes)
        .with_context(|| format!("reading {}", path.display()))?;
    if bytes.len() as u64 > MAX_RECORDING_BYTES {
        bail!(
            "{}: grew beyond the {} bytes a replay reads",
            path.display(),
            MAX_RECORDING_BYTES
        );
    }
    Ok(bytes)
}

/// The team id in a frame's plain header, if it looks like a huddle frame.
pub fn team_of(frame: &[u8]) -> Option<u8> {
    (0..=u8::MAX).find(|&team| comms::wire::peek_origin(frame, team).is_some())
}

/// Run `huddle replay`.
pub fn replay(args: ReplayArgs) -> Result<()> {
    let shared = match args.monitor {
        Some(addr) => {
            let (_, model) = open_recording(&args)?;
            let shared: server::Shared = Arc::new(Mutex::new(model));
            server::spawn(addr, shared.clone())?;
            Some(shared)
        }
        None => None,
    };
    let mut out = std::io::stdout().lock();
    let mut next_world_s = 0.0;
    let mut frames = (0, 0);
    replay_file(&args, shared.as_ref(), |model, heard| {
        frames = (
            model.replica().stats().frames_in,
            model.replica().stats().drops_total(),
        );
        if args.world {
            let t = model.t_s();
            if t >= next_world_s {
                next_world_s = t + WORLD_PERIOD_S;
                if let Some((x, y, gbc)) = model.team_ball() {
                    let line = serde_json::json!({
                        "t": (t * 1e3).round() / 1e3, "x": x, "y": y, "gbc": gbc,
                    });
                    writeln!(out, "{line}")?;
                }
            }
            return Ok(());
        }
        for h in heard {
            if args.json {
                if let Some(line) = h.update_json() {
                    writeln!(out, "{line}")?;
                }
                continue;
            }
            match h {
                Heard::Update {
                    t_s, key, value, ..
                } => writeln!(out, "{t_s:10.3}  {key} = {value}")?,
                Heard::Joined { t_s, robot } => writeln!(out, "{t_s:10.3}  robot {robot} joined")?,
                Heard::Departed { t_s, robot } => {
                    writeln!(out, "{t_s:10.3}  robot {robot} departed")?
                }
                Heard::Conflict { t_s, robot } => {
                    writeln!(out, "{t_s:10.3}  two robots send as {robot}")?
                }
            }
        }
        Ok(())
    })?;
    out.flush()?;
    tracing::info!("{} frames replayed, {} dropped", frames.0, frames.1);
    if let Some(addr) = args.monitor {
        tracing::info!("the recording is over; the monitor stays on http://{addr}/ until Ctrl-C");
        super::monitor_sim::wait_for_ctrl_c()?;
    }
    Ok(())
}

/// How often `--world` prints the team ball, seconds of the recording.
const WORLD_PERIOD_S: f64 = 0.1;
