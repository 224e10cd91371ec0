//! `--transport multicast|broadcast|unicast` and the addresses that go with it, shared
//! by the commands that open the team's socket: `huddle daemon` sends and receives on
//! it, `huddle monitor` and `huddle record` only listen.

use std::net::{Ipv4Addr, SocketAddrV4};

use anyhow::{bail, Result};
use clap::{Args, ValueEnum};
use driver::{SocketConfig, Transport};

/// The seed's group and port (isocrob-2000), the multicast default.
pub const DEFAULT_GROUP: SocketAddrV4 = SocketAddrV4::new(Ipv4Addr::new(224, 0, 0, 1), 2000);

/// The RoboCup SPL team port: team messages are broadcast to 10000 + team number.
pub fn league_port(team: u8) -> u16 {
    10_000 + u16::from(team)
}

/// How frames reach the team (`--transport`).
#[derive(ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TransportKind {
    /// To the multicast --group (the seed's; MSL teams).
    #[default]
    Multicast,
    /// UDP broadcast to the interface's broadcast address (RoboCup SPL).
    Broadcast,
    /// To each --peer only: access points retry unicast and do not hold it for the beacon.
    Unicast,
}

impl From<TransportKind> for Transport {
    fn from(kind: TransportKind) -> Transport {
        match kind {
            TransportKind::Multicast => Transport::Multicast,
            TransportKind::Broadcast => Transport::Broadcast,
            TransportKind::Unicast => Transport::Unicast,
        }
    }
}

/// The transport flags.
#[derive(Args, Debug, Clone, Default)]
pub struct TransportArgs {
    /// How frames reach the team: multicast to --group; broadcast to the interface's
    /// broadcast address (RoboCup SPL; 127.255.255.255 on loopback); unicast to each
    /// --peer only.
    #[arg(long, value_enum, default_value_t = TransportKind::Multicast)]
    pub transport: TransportKind,
    /// Multicast group and port (multicast only) [default: 224.0.0.1:2000, the seed's;
    /// teams use their own, e.g. 239.x].
    #[arg(long, value_name = "ADDR:PORT")]
    pub group: Option<SocketAddrV4>,
    /// UDP port of --transport broadcast or unicast [default: 10000 + team, the SPL
    /// team port].
    #[arg(long)]
    pub port: Option<u16>,
    /// Broadcast address of --transport broadcast [default: the interface's, as `ip addr`
    /// shows it after `brd`].
    #[arg(long, value_name = "ADDR")]
    pub broadcast: Option<Ipv4Addr>,
}

impl TransportArgs {
    /// The socket configuration on `iface`. `team`: the team id, for the broadcast and
    /// unicast port default (10000 + team); `None` where the command has no team, which
    /// then needs `--port`.
    pub fn socket_config(&self, iface: Ipv4Addr, team: Option<u8>) -> Result<SocketConfig> {
        let transport = Transport::from(self.transport);
        if self.broadcast.is_some() && transport != Transport::Broadcast {
            bail!("--broadcast is for --transport broadcast");
        }
        let group = match transport {
            Transport::Multicast => {
                if self.port.is_some() {
                    bail!("with --transport multicast the port is --group's: --group ADDR:PORT");
                }
                self.group.unwrap_or(DEFAULT_GROUP)
            }
            Transport::Broadcast | Transport::Unicast => {
                if let Some(group) = self.group {
                    bail!(
                        "--group {group} is a multicast group, and --transport {transport} \
                         has none: give the port with --port"
                    );
                }
                let port = match (self.port, team) {
                    (Some(port), _) => port,
                    (None, Some(team)) => league_port(team),
                    (None, None) => bail!(
                        "--transport {transport} needs --port N here (the SPL team port is \
                         10000 + team number)"
                    ),
                };
                if port == 0 {
                    bail!("--port 0: give the team's port");
                }
                SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, port)
            }
        };
        Ok(SocketConfig {
            transport,
            group,
            iface,
            broadcast: self.broadcast,
            ..SocketConfig::default()
        })
    }
}

/// What a listener opens, in words: "listening to the multicast group 239.7.7.7:2000 on
/// 10.0.0.5", for logs and error context.
pub fn listening_on(cfg: &SocketConfig) -> String {
    let port = cfg.group.port();
    match cfg.transport {
        Transport::Multicast => format!(
            "listening to the multicast group {} on {}",
            cfg.group, cfg.iface
        ),
        Transport::Broadcast => match driver::broadcast_destination(cfg) {
            Ok(to) => format!("listening to broadcasts to {to} (interface {})", cfg.iface),
            Err(_) => format!("listening to broadcasts on port {port} of {}", cfg.iface),
        },
        Transport::Unicast => format!(
            "listening to unicast to {}:{port} (the robots must list it with --peer)",
            cfg.iface
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(transport: TransportKind) -> TransportArgs {
        TransportArgs {
            transport,
            ..TransportArgs::default()
        }
    }

    #[test]
    fn defaults_are_the_seeds_group_and_the_spl_team_port() {
        let lo = Ipv4Addr::LOCALHOST;
        let cfg = args(TransportKind::Multicast)
            .socket_config(lo, Some(7))
            .unwrap();
        assert_eq!(
            (cfg.transport, cfg.group),
            (Transport::Multicast, DEFAULT_GROUP)
        );
        for kind in [TransportKind::Broadcast, TransportKind::Unicast] {
            let cfg = args(kind).socket_config(lo, Some(7)).unwrap();
            assert_eq!(cfg.group.port(), 10_007, "{kind:?}");
            assert_eq!(cfg.transport, Transport::from(kind));
        }
        let port = TransportArgs {
            port: Some(4000),
            ..args(TransportKind::Broadcast)
        };
        assert_eq!(port.socket_config(lo, None).unwrap().group.port(), 4000);
    }

    #[test]
    fn mismatched_flags_are_clear_errors() {
        let lo = Ipv4Addr::LOCALHOST;
        let cases = [
            (
                TransportArgs {
                    group: Some(DEFAULT_GROUP),
                    ..args(TransportKind::Broadcast)
                },
                "has none: give the port with --port",
            ),
            (
                TransportArgs {
                    port: Some(3000),
                    ..args(TransportKind::Multicast)
                },
                "the port is --group's",
            ),
            (
                TransportArgs {
                    broadcast: Some(Ipv4Addr::new(10, 0, 255, 255)),
                    ..args(TransportKind::Unicast)
                },
                "--broadcast is for --transport broadcast",
            ),
            (args(TransportKind::Unicast), "needs --port N here"),
        ];
        for (a, expected) in cases {
            let err = a.socket_config(lo, None).unwrap_err().to_string();
            assert!(err.contains(expected), "{a:?}: {err}");
        }
    }
}
