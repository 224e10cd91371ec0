//! The team's UDP sockets, set up with socket2 the way a team on one WLAN (or one
//! laptop) needs it: one per [`Transport`] (multicast, broadcast, unicast), and the
//! unicast socket that `--peer` asks for.
//!
//! The multicast socket is bound to the group address itself (not `0.0.0.0`), with
//! `IP_MULTICAST_ALL` off on Linux: it hears only datagrams sent to its own group and
//! port, never unicast and never another group that shares the port. Unicast from
//! teammates arrives on a second socket ([`open_unicast`]), opened only when peers are
//! configured, whose datagrams the driver accepts from the listed peers alone.
//!
//! The broadcast socket is built the same way, bound to the interface's broadcast
//! address (RoboCup SPL: `10.0.255.255:10000 + team`): it hears the team's broadcasts
//! (its own included, which the replica recognises by sender and incarnation) and no
//! unicast. The unicast transport has no group at all: its one socket is the `--peer`
//! socket.

use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};

use socket2::{Domain, Protocol, Socket, Type};
use thiserror::Error;

use crate::iface::{broadcast_address, IfaceError};

/// How frames reach the team. Leagues differ: the MSL's RtDB multicasts, the SPL requires
/// UDP broadcast to port 10000 + team, and on a WLAN whose access point loses or holds
/// group frames, unicast to each teammate is what gets through (the MAC retries unicast,
/// and an access point does not hold it for the DTIM beacon).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Transport {
    /// Every frame to the multicast group ([`SocketConfig::group`]).
    #[default]
    Multicast,
    /// Every frame to the interface's broadcast address (or
    /// [`SocketConfig::broadcast`]) on the port of [`SocketConfig::group`].
    Broadcast,
    /// Every frame to each peer only; no group, no broadcast. Needs peers.
    Unicast,
}

impl Transport {
    /// Every transport, in `--help` order.
    pub const ALL: [Transport; 3] = [
        Transport::Multicast,
        Transport::Broadcast,
        Transport::Unicast,
    ];

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Transport::Multicast => "multicast",
            Transport::Broadcast => "broadcast",
            Transport::Unicast => "unicast",
        }
    }
}

impl std::fmt::Display for Transport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How the socket is opened.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SocketConfig {
    /// Multicast, broadcast or unicast.
    pub transport: Transport,
    /// Multicast group and port (the seed's `224.0.0.1:2000` by default). With the
    /// other transports only the port is used.
    pub group: SocketAddrV4,
    /// Broadcast address for [`Transport::Broadcast`]; `None`: the interface's
    /// (`127.255.255.255` on loopback, see [`crate::broadcast_address`]).
    pub broadcast: Option<Ipv4Addr>,
    /// The interface's IPv4 address: `IP_MULTICAST_IF` and the membership. Default
    /// `127.0.0.1`, so nothing leaves the machine unless an interface is named.
    pub iface: Ipv4Addr,
    /// Multicast TTL (default 1: never routed off the link).
    pub ttl: u32,
    /// `SO_RCVBUF` to ask for (default 4 MiB: bursts overflow the usual 208 KiB).
    pub recv_buffer_bytes: usize,
}

impl Default for SocketConfig {
    fn default() -> SocketConfig {
        SocketConfig {
            transport: Transport::Multicast,
            group: SocketAddrV4::new(Ipv4Addr::new(224, 0, 0, 1), 2000),
            broadcast: None,
            iface: Ipv4Addr::LOCALHOST,
            ttl: 1,
            recv_buffer_bytes: 4 << 20,
        }
    }
}

/// Why the team's socket could not be set up.
#[derive(Debug, Error)]
pub enum SocketError {
    /// The group address is not an IPv4 multicast address.
    #[error("{0} is not an IPv4 multicast address (224.0.0.0/4)")]
    NotMulticast(Ipv4Addr),
    /// The broadcast address given is unusable: multicast, unspecified, or the limited
    /// broadcast `255.255.255.255`, which leaves by whichever interface the routing
    /// table picks rather than the one named.
    #[error(
        "{0} cannot be the broadcast address: give the interface's directed broadcast \
         address (e.g. 10.0.255.255), or leave it out to use the interface's"
    )]
    NotBroadcast(Ipv4Addr),
    /// The interface has no broadcast address, or is not an interface of this host.
    #[error(transparent)]
    Iface(#[from] IfaceError),
    /// Creating, configuring or binding the socket failed.
    #[error("cannot open a UDP socket on port {port}: {source}")]
    Open {
        /// The port.
        port: u16,
        /// The OS error.
        source: io::Error,
    },
    /// `IP_ADD_MEMBERSHIP` failed (no such interface, no multicast route...).
    #[error("cannot join multicast group {group} on interface {iface}: {source}")]
    Join {
        /// The group.
        group: Ipv4Addr,
        /// The interface address.
        iface: Ipv4Addr,
        /// The OS error.
        source: io::Error,
    },
    /// `IP_MULTICAST_IF`, TTL or loop could not be set.
    #[error("cannot send multicast through interface {iface}: {source}")]
    Interface {
        /// The interface address.
        iface: Ipv4Addr,
        /// The OS error.
        source: io::Error,
    },
}

/// A multicast group and port that no other test, benchmark or demo run on this host is
/// using: a free UDP port (the kernel's choice) and an organisation-local group
/// (239.255.0.0/16) drawn from the process id and a counter. Two runs of the test suite on
/// one machine then never hear each other's frames. Use it with the loopback interface.
pub fn scratch_group() -> io::Result<SocketAddrV4> {
    use std::sync::atomic::{AtomicU32, Ordering};
    static NEXT: AtomicU32 = AtomicU32::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    let port = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0))?
        .local_addr()?
        .port();
    let pid = std::process::id();
    // 239.255.0.x and 239.255.255.x are avoided: some stacks treat them specially.
    let third = (pid % 254 + 1) as u8;
    let fourth = ((pid / 254).wrapping_add(n) % 254 + 1) as u8;
    Ok(SocketAddrV4::new(
        Ipv4Addr::new(239, 255, third, fourth),
        port,
    ))
}

/// The socket as opened, with what the kernel granted.
#[derive(Debug)]
pub struct Opened {
    /// Non-blocking. Multicast: bound to `<group>:<port>`, member of the group on the
    /// interface: it receives that group's datagrams only (no unicast, no other group).
    /// Broadcast: bound to `<broadcast address>:<port>`, `SO_BROADCAST` on. Unicast:
    /// bound to `<iface>:<port>` (see [`open_unicast`]).
    pub socket: std::net::UdpSocket,
    /// `SO_RCVBUF` as the kernel reports it (Linux doubles the request and caps it at
    /// `net.core.rmem_max`).
    pub recv_buffer_granted: usize,
    /// Where every frame goes: the group, or the broadcast address, and the port;
    /// `None` for unicast (to each peer only).
    pub destination: Option<SocketAddrV4>,
}

/// Opens the socket of `cfg.transport`: [`open_multicast`], [`open_broadcast`] or, for
/// unicast, a socket like [`open_unicast`]'s that does not share its port.
pub fn open(cfg: &SocketConfig) -> Result<Opened, SocketError> {
    match cfg.transport {
        Transport::Multicast => open_multicast(cfg),
        Transport::Broadcast => open_broadcast(cfg),
        // The transport's only socket: a second replica on this port would silently
        // take half the unicast, so the port is not shared (a clear "in use" instead).
        Transport::Unicast => unicast_opened(cfg, false),
    }
}

/// The broadcast address `cfg` sends to: [`SocketConfig::broadcast`] if set (checked),
/// else the interface's.
pub fn broadcast_destination(cfg: &SocketConfig) -> Result<SocketAddrV4, SocketError> {
    let address = match cfg.broadcast {
        Some(address) => {
            if address.is_multicast() || address.is_unspecified() || address.is_broadcast() {
                return Err(SocketError::NotBroadcast(address));
            }
            address
        }
        None => broadcast_address(cfg.iface)?,
    };
    Ok(SocketAddrV4::new(address, cfg.group.port()))
}

/// Opens the broadcast socket: `SO_BROADCAST` (without it Linux refuses the send with
/// `EACCES`), `SO_REUSEADDR` + `SO_REUSEPORT` (replicas on one host share the port), a
/// large receive buffer, bound to the broadcast address and port, so that it hears the
/// team's broadcasts and no unicast. Frames leave by the interface whose subnet the
/// address belongs to (the kernel's broadcast route), from that interface's address.
pub fn open_broadcast(cfg: &SocketConfig) -> Result<Opened, SocketError> {
    let destination = broadcast_destination(cfg)?;
    let port = destination.port();
    let open = |source| SocketError::Open { port, source };
    let socket = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP)).map_err(open)?;
    socket.set_reuse_address(true).map_err(open)?;
    socket.set_reuse_port(true).map_err(open)?;
    socket.set_broadcast(true).map_err(open)?;
    let _ = socket.set_recv_buffer_size(cfg.recv_buffer_bytes);
    let recv_buffer_granted = socket.recv_buffer_size().map_err(open)?;
    let bind: SocketAddr = destination.into();
    socket.bind(&bind.into()).map_err(open)?;
    socket.set_nonblocking(true).map_err(open)?;
    Ok(Opened {
        socket: socket.into(),
        recv_buffer_granted,
        destination: Some(destination),
    })
}

/// Opens the multicast socket: `SO_REUSEADDR` + `SO_REUSEPORT` (several replicas may
/// share the port on one host: only the sender id in a frame tells them apart), a large
/// receive buffer, bind to the group address and port, join, `IP_MULTICAST_ALL` off
/// (Linux), `IP_MULTICAST_IF`, TTL, loop on.
pub fn open_multicast(cfg: &SocketConfig) -> Result<Opened, SocketError> {
    let group = *cfg.group.ip();
    if !group.is_multicast() {
        return Err(SocketError::NotMulticast(group));
    }
    let port = cfg.group.port();
    let open = |source| SocketError::Open { port, source };
    let socket = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP)).map_err(open)?;
    socket.set_reuse_address(true).map_err(open)?;
    socket.set_reuse_port(true).map_err(open)?;
    // A refusal here is not fatal: report what we got instead.
    let _ = socket.set_recv_buffer_size(cfg.recv_buffer_bytes);
    let recv_buffer_granted = socket.recv_buffer_size().map_err(open)?;
    // Bound to the group: the kernel delivers only datagrams addressed to it (a unicast
    // to this host's address or another group on the same port does not match).
    let bind: SocketAddr = SocketAddrV4::new(group, port).into();
    socket.bind(&bind.into()).map_err(open)?;
    socket
        .join_multicast_v4(&group, &cfg.iface)
        .map_err(|source| SocketError::Join {
            group,
            iface: cfg.iface,
            source,
        })?;
    let iface = |source| SocketError::Interface {
        iface: cfg.iface,
        source,
    };
    // Linux delivers a group's datagrams to every socket bound to the port whenever *any*
    // socket of the host joined that group; off, only this socket's own memberships count.
    #[cfg(target_os = "linux")]
    socket.set_multicast_all_v4(false).map_err(open)?;
    socket.set_multicast_if_v4(&cfg.iface).map_err(iface)?;
    socket.set_multicast_ttl_v4(cfg.ttl).map_err(iface)?;
    socket.set_multicast_loop_v4(true).map_err(iface)?;
    socket.set_nonblocking(true).map_err(open)?;
    Ok(Opened {
        socket: socket.into(),
        recv_buffer_granted,
        destination: Some(cfg.group),
    })
}

/// Opens the unicast socket for `--peer` traffic: bound to `<iface>:<group port>`
/// (`SO_REUSEADDR` + `SO_REUSEPORT`, a large receive buffer, non-blocking). Frames to
/// peers leave from it, so a teammate sees them come from this address; what arrives on
/// it is accepted by the driver only from the configured peers.
pub fn open_unicast(cfg: &SocketConfig) -> Result<std::net::UdpSocket, SocketError> {
    unicast_opened(cfg, true).map(|opened| opened.socket)
}

/// The unicast socket on `<iface>:<port>`; `shared`: `SO_REUSEADDR` + `SO_REUSEPORT`.
fn unicast_opened(cfg: &SocketConfig, shared: bool) -> Result<Opened, SocketError> {
    let port = cfg.group.port();
    let open = |source| SocketError::Open { port, source };
    let socket = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP)).map_err(open)?;
    if shared {
        socket.set_reuse_address(true).map_err(open)?;
        socket.set_reuse_port(true).map_err(open)?;
    }
    let _ = socket.set_recv_buffer_size(cfg.recv_buffer_bytes);
    let recv_buffer_granted = socket.recv_buffer_size().map_err(open)?;
    let bind: SocketAddr = SocketAddrV4::new(cfg.iface, port).into();
    socket.bind(&bind.into()).map_err(open)?;
    socket.set_nonblocking(true).map_err(open)?;
    Ok(Opened {
        socket: socket.into(),
        recv_buffer_granted,
        destination: None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scratch_groups_differ_within_a_run() {
        let (a, b) = (scratch_group().unwrap(), scratch_group().unwrap());
        assert!(a.ip().is_multicast() && b.ip().is_multicast(), "{a} {b}");
        assert_ne!(a.ip(), b.ip(), "two calls give two groups");
    }

    #[test]
    fn a_unicast_group_and_a_foreign_interface_are_clear_errors() {
        let cfg = SocketConfig {
            group: "127.0.0.1:47110".parse().unwrap(),
            ..SocketConfig::default()
        };
        assert!(matches!(
            open_multicast(&cfg),
            Err(SocketError::NotMulticast(_))
        ));
        // 192.0.2.1 (TEST-NET-1) is no interface of this machine: the join fails.
        let cfg = SocketConfig {
            group: scratch_group().unwrap(),
            iface: Ipv4Addr::new(192, 0, 2, 1),
            ..SocketConfig::default()
        };
        assert!(matches!(
            open_multicast(&cfg),
            Err(SocketError::Join { .. })
        ));
    }

    /// The first datagram `socket` receives (blocking, with a generous timeout).
    fn first_received(socket: &std::net::UdpSocket) -> Vec<u8> {
        let mut buf = [0u8; 64];
        socket.set_nonblocking(false).unwrap();
        socket
            .set_read_timeout(Some(std::time::Duration::from_secs(5)))
            .unwrap();
        let (n, _) = socket.recv_from(&mut buf).expect("a datagram arrives");
        buf[..n].to_vec()
    }

    // Loopback delivery happens inside `send_to`, in order: a marker sent to the group
    // after the probe arrives after it, so "the first datagram is the marker" means the
    // probe was not delivered, with no waiting for something not to happen.

    #[test]
    fn a_member_does_not_receive_unicast_to_its_port() {
        let cfg = SocketConfig {
            group: scratch_group().unwrap(),
            ..SocketConfig::default()
        };
        let member = open_multicast(&cfg).unwrap().socket;
        let tx = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
        tx.send_to(b"unicast", (Ipv4Addr::LOCALHOST, cfg.group.port()))
            .unwrap();
        let sender = open_multicast(&cfg).unwrap().socket;
        sender.send_to(b"marker", cfg.group).unwrap();
        assert_eq!(first_received(&member), b"marker");
    }

    #[test]
    fn a_member_does_not_receive_another_group_on_the_same_port() {
        let ours = SocketConfig {
            group: scratch_group().unwrap(),
            ..SocketConfig::default()
        };
        let mut other_group = *scratch_group().unwrap().ip();
        if other_group == *ours.group.ip() {
            other_group = Ipv4Addr::from(u32::from(other_group) ^ 1);
        }
        let theirs = SocketConfig {
            group: SocketAddrV4::new(other_group, ours.group.port()),
            ..ours.clone()
        };
        let member = open_multicast(&ours).unwrap().socket;
        // Another member of the other group on this host, on the same port.
        let neighbour = open_multicast(&theirs).unwrap().socket;
        neighbour.send_to(b"other group", theirs.group).unwrap();
        assert_eq!(first_received(&neighbour), b"other group");
        neighbour.send_to(b"marker", ours.group).unwrap();
        assert_eq!(first_received(&member), b"marker");
    }

    #[test]
    fn the_unicast_socket_receives_unicast_to_the_interface_and_port() {
        let cfg = SocketConfig {
            group: scratch_group().unwrap(),
            ..SocketConfig::default()
        };
        let unicast = open_unicast(&cfg).unwrap();
        let tx = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
        tx.send_to(b"unicast", (Ipv4Addr::LOCALHOST, cfg.group.port()))
            .unwrap();
        assert_eq!(first_received(&unicast), b"unicast");
    }

    fn broadcast_cfg() -> SocketConfig {
        SocketConfig {
            transport: Transport::Broadcast,
            group: scratch_group().unwrap(),
            ..SocketConfig::default()
        }
    }

    #[test]
    fn broadcast_on_loopback_reaches_every_socket_on_the_port_and_no_unicast() {
        let cfg = broadcast_cfg();
        let a = open(&cfg).unwrap();
        let b = open(&cfg).unwrap();
        let to = SocketAddrV4::new(Ipv4Addr::new(127, 255, 255, 255), cfg.group.port());
        assert_eq!(a.destination, Some(to));
        // A unicast to the port on 127.0.0.1 is not for the broadcast sockets.
        let tx = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
        tx.send_to(b"unicast", (Ipv4Addr::LOCALHOST, cfg.group.port()))
            .unwrap();
        a.socket.send_to(b"hello", to).unwrap();
        // Both hear it, the sender too (its own echo, from 127.0.0.1:<port>).
        for s in [&b.socket, &a.socket] {
            let mut buf = [0u8; 16];
            s.set_nonblocking(false).unwrap();
            s.set_read_timeout(Some(std::time::Duration::from_secs(2)))
                .unwrap();
            let (n, from) = s.recv_from(&mut buf).expect("the broadcast arrives");
            assert_eq!(&buf[..n], b"hello");
            assert_eq!(
                from,
                SocketAddr::from((Ipv4Addr::LOCALHOST, cfg.group.port()))
            );
        }
    }

    #[test]
    fn without_so_broadcast_the_kernel_refuses_a_broadcast() {
        // Why open_broadcast sets it: EACCES otherwise (and the driver counts that).
        let tx = std::net::UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
        let err = tx
            .send_to(b"x", (Ipv4Addr::new(127, 255, 255, 255), 9))
            .unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::PermissionDenied, "{err}");
    }

    #[test]
    fn unusable_broadcast_addresses_are_clear_errors() {
        for bad in ["255.255.255.255", "0.0.0.0", "239.1.2.3"] {
            let cfg = SocketConfig {
                broadcast: Some(bad.parse().unwrap()),
                ..broadcast_cfg()
            };
            let err = open(&cfg).unwrap_err();
            assert!(matches!(err, SocketError::NotBroadcast(_)), "{bad}: {err}");
            assert!(err.to_string().contains(bad), "{err}");
        }
        let cfg = SocketConfig {
            iface: Ipv4Addr::new(192, 0, 2, 1),
            ..broadcast_cfg()
        };
        let err = open(&cfg).unwrap_err();
        assert!(
            matches!(err, SocketError::Iface(IfaceError::NotLocal(_))),
            "{err}"
        );
    }

    #[test]
    fn the_unicast_transport_does_not_share_its_port() {
        let cfg = SocketConfig {
            transport: Transport::Unicast,
            group: scratch_group().unwrap(),
            ..SocketConfig::default()
        };
        let first = open(&cfg).unwrap();
        assert_eq!(first.destination, None);
        let err = open(&cfg).unwrap_err();
        assert!(
            matches!(&err, SocketError::Open { source, .. } if source.kind() == io::ErrorKind::AddrInUse),
            "{err}"
        );
    }

    #[test]
    fn two_sockets_share_a_port_and_hear_each_other_on_loopback() {
        let cfg = SocketConfig {
            group: scratch_group().unwrap(),
            ..SocketConfig::default()
        };
        let a = open_multicast(&cfg).unwrap();
        let b = open_multicast(&cfg).unwrap();
        assert!(
            a.recv_buffer_granted >= 256 * 1024,
            "asked for 4 MiB, got {}",
            a.recv_buffer_granted
        );
        a.socket.send_to(b"hello", cfg.group).unwrap();
        let mut buf = [0u8; 16];
        for s in [&b.socket, &a.socket] {
            s.set_nonblocking(false).unwrap();
            s.set_read_timeout(Some(std::time::Duration::from_secs(2)))
                .unwrap();
            let (n, _) = s
                .recv_from(&mut buf)
                .expect("multicast loop delivers to both");
            assert_eq!(&buf[..n], b"hello");
        }
    }
}
