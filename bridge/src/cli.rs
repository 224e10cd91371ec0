//! `huddle-bridge`'s command line: the daemon's team flags, the Zenoh session's, and
//! what to export.

use std::net::{Ipv4Addr, SocketAddrV4};
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use driver::{SocketConfig, Transport};

use crate::export::ExportConfig;
use crate::keys::TeamKeys;
use crate::run::{BridgeConfig, FieldLoop, PutVia};

/// The flags of a running bridge.
#[derive(Args, Debug, Clone)]
pub struct RunArgs {
    /// Team id (as the daemons' --team).
    #[arg(long)]
    pub team: u8,
    /// The venue's name: the third chunk of every key (`huddle/@v1/<venue>/…`);
    /// letters, digits, '-' and '_'.
    #[arg(long)]
    pub venue: String,
    /// How frames reach the team, as the daemons' --transport. With unicast, list the
    /// bridge's `<iface>:<port>` as a `--peer` of every daemon.
    #[arg(long, value_enum, default_value_t = TransportKind::Multicast)]
    pub transport: TransportKind,
    /// Multicast group and port [default: 224.0.0.1:2000].
    #[arg(long, value_name = "ADDR:PORT")]
    pub group: Option<SocketAddrV4>,
    /// UDP port of --transport broadcast or unicast [default: 10000 + team].
    #[arg(long)]
    pub port: Option<u16>,
    /// Broadcast address of --transport broadcast [default: the interface's].
    #[arg(long, value_name = "ADDR")]
    pub broadcast: Option<Ipv4Addr>,
    /// Interface, by name or IPv4 address (loopback by default).
    #[arg(long, default_value = "127.0.0.1")]
    pub iface: String,
    /// The team key file, as the daemons': frames without a valid tag are dropped.
    #[arg(long)]
    pub key_file: Option<PathBuf>,
    /// The listening replica's robot id: one no robot of the team uses.
    #[arg(long, default_value_t = 254)]
    pub listener_id: u8,
    /// Zenoh endpoint to connect to (repeatable): `tcp/10.0.0.1:7447`,
    /// `tls/router.venue:7447`.
    #[arg(long, value_name = "ENDPOINT")]
    pub connect: Vec<String>,
    /// Zenoh endpoint to listen on (repeatable; peer mode).
    #[arg(long, value_name = "ENDPOINT")]
    pub listen: Vec<String>,
    /// Zenoh session mode.
    #[arg(long, value_enum, default_value_t = Mode::Client)]
    pub mode: Mode,
    /// A Zenoh configuration file (JSON5) for TLS, mTLS and user/password; --mode,
    /// --connect and --listen override its values, and multicast scouting is always off.
    #[arg(long, value_name = "FILE")]
    pub zenoh_config: Option<PathBuf>,
    /// The most samples per second of one key (`10Hz`, `10`): the newest value at the end
    /// of each period goes, the ones between are skipped. Default: every change.
    #[arg(long, value_name = "RATE", value_parser = parse_rate)]
    pub max_rate: Option<Duration>,
    /// Also publish every value as a ROS 2 std_msgs message in CDR under
    /// `<--ros2-prefix>/<venue>/team<N>/robot<R>/<path>`.
    #[arg(long)]
    pub ros2: bool,
    /// First chunk of the --ros2 keys.
    #[arg(long, default_value = "huddle_ros")]
    pub ros2_prefix: String,
    /// Hand every sample to the publisher thread: the field task never puts itself.
    /// By default it puts a datagram's few samples itself when nothing waits, from Zenoh's
    /// TX runtime, which removes two thread wake-ups from a sample's path (0.12-0.14 ms
    /// p50 on the loaded test machine, docs/bridge.md); a Zenoh queue that fills at once
    /// can then hold the field task up to Zenoh's block timeout. Needs Zenoh's TX runtime
    /// configured (`ZENOH_RUNTIME`, which the binary sets to two TX workers if unset).
    #[arg(long)]
    pub no_fast_path: bool,
    /// Where the field side runs: `auto` (a task on Zenoh's TX runtime, or its own thread
    /// when the Zenoh configuration turns on the lowlatency transport), `tx-runtime`, or
    /// `thread` (a dedicated thread with a blocking receive that puts itself).
    #[arg(long, value_enum, default_value_t = FieldLoopArg::Auto)]
    pub field_loop: FieldLoopArg,
    /// How a sample's key reaches Zenoh: `declared` (each key declared once, puts carry
    /// its numeric id) or `string` (the key's text in every put), for comparison.
    #[arg(long, value_enum, default_value_t = PutViaArg::Declared)]
    pub put_via: PutViaArg,
    /// Operations the outbox holds in order (every version of a key) before it falls back
    /// to the latest value per key; it also falls back when the oldest waited 0.5 s.
    /// 0 merges every superseded value at once (the bridge before the seventh session).
    #[arg(long, default_value_t = crate::outbox::CAPACITY)]
    pub outbox_capacity: usize,
}

/// `--put-via`.
#[derive(ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PutViaArg {
    /// Each key declared once.
    #[default]
    Declared,
    /// The key's text in every put.
    String,
}

/// `--field-loop`.
#[derive(ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FieldLoopArg {
    /// `thread` with Zenoh's lowlatency transport, otherwise `tx-runtime`.
    #[default]
    Auto,
    /// A task on Zenoh's TX runtime.
    TxRuntime,
    /// A thread of its own, blocking on the socket.
    Thread,
}

/// `--transport`.
#[derive(ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TransportKind {
    /// The multicast --group.
    #[default]
    Multicast,
    /// UDP broadcast on the interface (RoboCup SPL).
    Broadcast,
    /// Unicast to `<iface>:<port>`: the daemons list the bridge as a `--peer`.
    Unicast,
}

/// `--mode`.
#[derive(ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Mode {
    /// Connect to a router.
    #[default]
    Client,
    /// A peer: connect to and listen on the given endpoints.
    Peer,
}

/// `10Hz`, `10hz` or `10`: the period of that rate.
pub fn parse_rate(s: &str) -> Result<Duration, String> {
    let t = s.trim();
    let number = t
        .strip_suffix("Hz")
        .or_else(|| t.strip_suffix("hz"))
        .unwrap_or(t)
        .trim();
    let hz: f64 = number
        .parse()
        .map_err(|_| format!("{s:?} is not a rate such as 10Hz"))?;
    if !(hz.is_finite() && hz > 0.0 && hz <= 1e6) {
        return Err(format!("{s:?}: the rate must be in (0, 1e6] Hz"));
    }
    Ok(Duration::from_secs_f64(1.0 / hz))
}

impl RunArgs {
    /// The bridge's configuration.
    pub fn config(&self) -> Result<BridgeConfig> {
        let iface = driver::resolve_iface(&self.iface)
            .with_context(|| format!("--iface {}", self.iface))?;
        let transport = match self.transport {
            TransportKind::Multicast => Transport::Multicast,
            TransportKind::Broadcast => Transport::Broadcast,
            TransportKind::Unicast => Transport::Unicast,
        };
        let group = match transport {
            Transport::Multicast => {
                if self.port.is_some() {
                    bail!("with --transport multicast the port is --group's");
                }
                self.group
                    .unwrap_or(SocketAddrV4::new(Ipv4Addr::new(224, 0, 0, 1), 2000))
            }
            _ => {
                if self.group.is_some() {
                    bail!("--group is for --transport multicast; use --port");
                }
                let port = self.port.unwrap_or(10_000 + u16::from(self.team));
                SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, port)
            }
        };
        let socket = SocketConfig {
            transport,
            group,
            broadcast: self.broadcast,
            iface,
            ..SocketConfig::default()
        };
        let team_key = match &self.key_file {
            Some(path) => Some(
                driver::read_key_file(path)
                    .with_context(|| format!("--key-file {}", path.display()))?,
            ),
            None => None,
        };
        if !comms::ROBOT_IDS.contains(&self.listener_id) {
            bail!("--listener-id {} is outside 1..=254", self.listener_id);
        }
        let keys = TeamKeys::new(&self.venue, self.team, &self.ros2_prefix)?;
        Ok(BridgeConfig {
            socket,
            team: self.team,
            team_key,
            listener_id: self.listener_id,
            keys,
            export: ExportConfig {
                min_interval: self.max_rate,
                ros2: self.ros2,
            },
            zenoh: self.zenoh_config()?,
            fast_path: !self.no_fast_path,
            field_loop: match self.field_loop {
                FieldLoopArg::Auto => FieldLoop::Auto,
                FieldLoopArg::TxRuntime => FieldLoop::TxRuntime,
                FieldLoopArg::Thread => FieldLoop::Thread,
            },
            outbox_capacity: self.outbox_capacity,
            put_via: match self.put_via {
                PutViaArg::Declared => PutVia::Declared,
                PutViaArg::String => PutVia::String,
            },
        })
    }

    fn zenoh_config(&self) -> Result<zenoh::Config> {
        let mut cfg = match &self.zenoh_config {
            Some(path) => zenoh::Config::from_file(path)
                .map_err(|e| anyhow::anyhow!("--zenoh-config {}: {e}", path.display()))?,
            None => zenoh::Config::default(),
        };
        let mode = match self.mode {
            Mode::Client => "\"client\"",
            Mode::Peer => "\"peer\"",
        };
        let set = |cfg: &mut zenoh::Config, key: &str, value: String| {
            cfg.insert_json5(key, &value)
                .map_err(|e| anyhow::anyhow!("zenoh config {key} = {value}: {e}"))
        };
        set(&mut cfg, "mode", mode.to_owned())?;
        if !self.connect.is_empty() {
            set(
                &mut cfg,
                "connect/endpoints",
                serde_json::to_string(&self.connect)?,
            )?;
        }
        if !self.listen.is_empty() {
            set(
                &mut cfg,
                "listen/endpoints",
                serde_json::to_string(&self.listen)?,
            )?;
        }
        if self.connect.is_empty() && self.zenoh_config.is_none() && self.mode == Mode::Client {
            bail!("a client needs a router: --connect tcp/HOST:7447 (or --zenoh-config)");
        }
        set(&mut cfg, "scouting/multicast/enabled", "false".into())?;
        Ok(cfg)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates() {
        assert_eq!(parse_rate("10Hz"), Ok(Duration::from_millis(100)));
        assert_eq!(parse_rate("4"), Ok(Duration::from_millis(250)));
        assert!(parse_rate("0Hz").is_err());
        assert!(parse_rate("fast").is_err());
        assert!(parse_rate("NaN").is_err());
    }
}
