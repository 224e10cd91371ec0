//! The multicast UDP socket, set up with socket2 the way a team on one WLAN (or one
//! laptop) needs it.

use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};

use socket2::{Domain, Protocol, Socket, Type};
use thiserror::Error;

/// How the socket is opened.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SocketConfig {
    /// Multicast group and port (the seed's `224.0.0.1:2000` by default).
    pub group: SocketAddrV4,
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
            group: SocketAddrV4::new(Ipv4Addr::new(224, 0, 0, 1), 2000),
            iface: Ipv4Addr::LOCALHOST,
            ttl: 1,
            recv_buffer_bytes: 4 << 20,
        }
    }
}

/// Why the multicast socket could not be set up.
#[derive(Debug, Error)]
pub enum SocketError {
    /// The group address is not an IPv4 multicast address.
    #[error("{0} is not an IPv4 multicast address (224.0.0.0/4)")]
    NotMulticast(Ipv4Addr),
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
    /// Non-blocking, bound to `0.0.0.0:<group port>` (so teammates' `--peer` unicast
    /// arrives too), member of the group on the interface.
    pub socket: std::net::UdpSocket,
    /// `SO_RCVBUF` as the kernel reports it (Linux doubles the request and caps it at
    /// `net.core.rmem_max`).
    pub recv_buffer_granted: usize,
}

/// Opens the multicast socket: `SO_REUSEADDR` + `SO_REUSEPORT` (several replicas may
/// share the port on one host: only the sender id in a frame tells them apart), a large
/// receive buffer, bind, join, `IP_MULTICAST_IF`, TTL, loop on.
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
    let bind: SocketAddr = SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, port).into();
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
    socket.set_multicast_if_v4(&cfg.iface).map_err(iface)?;
    socket.set_multicast_ttl_v4(cfg.ttl).map_err(iface)?;
    socket.set_multicast_loop_v4(true).map_err(iface)?;
    socket.set_nonblocking(true).map_err(open)?;
    Ok(Opened {
        socket: socket.into(),
        recv_buffer_granted,
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
