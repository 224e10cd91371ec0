//! Naming the network interface the team's group is joined on: `--iface wlan0` or
//! `--iface 192.168.1.12`, and finding that interface's broadcast address for
//! `--transport broadcast`.

use std::io;
use std::net::{IpAddr, Ipv4Addr};

use thiserror::Error;

/// Why an `--iface` argument names no usable interface.
#[derive(Debug, Error)]
pub enum IfaceError {
    /// No interface of that name exists (or it has no address at all).
    #[error("no network interface named {0:?}")]
    NoSuchInterface(String),
    /// The interface exists but has no IPv4 address.
    #[error("interface {0:?} has no IPv4 address")]
    NoIpv4(String),
    /// Listing the interfaces failed.
    #[error("cannot list network interfaces: {0}")]
    List(io::Error),
    /// No interface of this machine has that IPv4 address.
    #[error("no network interface has the address {0}")]
    NotLocal(Ipv4Addr),
    /// The interface has no broadcast address (a point-to-point link such as a VPN).
    #[error(
        "interface {name:?} ({addr}) has no broadcast address (point-to-point?): \
         give one with --broadcast, or use --transport multicast or unicast"
    )]
    NoBroadcast {
        /// The interface's name.
        name: String,
        /// Its address.
        addr: Ipv4Addr,
    },
}

/// Resolves an interface given as an IPv4 address (`127.0.0.1`) or a name (`lo`,
/// `wlan0`) to its first IPv4 address.
pub fn resolve_iface(name_or_addr: &str) -> Result<Ipv4Addr, IfaceError> {
    if let Ok(addr) = name_or_addr.parse::<Ipv4Addr>() {
        return Ok(addr);
    }
    let mut known = false;
    for iface in if_addrs::get_if_addrs().map_err(IfaceError::List)? {
        if iface.name == name_or_addr {
            known = true;
            if let IpAddr::V4(v4) = iface.ip() {
                return Ok(v4);
            }
        }
    }
    Err(if known {
        IfaceError::NoIpv4(name_or_addr.to_owned())
    } else {
        IfaceError::NoSuchInterface(name_or_addr.to_owned())
    })
}

/// The broadcast address of the interface that has the address `iface`, as the kernel
/// reports it (`brd` in `ip addr`).
///
/// Loopback has none, yet Linux routes `127.255.255.255` as a broadcast on `lo` (see
/// `ip route show table local`) and delivers it to every socket bound to it: so any
/// address in 127.0.0.0/8 gives `127.255.255.255`, and tests and demos can run a
/// broadcast team on one machine without a frame leaving it.
pub fn broadcast_address(iface: Ipv4Addr) -> Result<Ipv4Addr, IfaceError> {
    if iface.is_loopback() {
        return Ok(Ipv4Addr::new(127, 255, 255, 255));
    }
    for interface in if_addrs::get_if_addrs().map_err(IfaceError::List)? {
        let if_addrs::IfAddr::V4(v4) = &interface.addr else {
            continue;
        };
        if v4.ip != iface {
            continue;
        }
        // A /31 or /32 has no broadcast address even if the kernel lists one, nor has a
        // point-to-point link.
        if v4.prefixlen >= 31 || interface.is_p2p() {
            return Err(IfaceError::NoBroadcast {
                name: interface.name,
                addr: iface,
            });
        }
        // An address added without `brd` (`ip addr add 10.0.1.12/16 dev wlan0`) lists
        // none, yet the kernel routes the subnet's all-ones address as its broadcast
        // (`ip route show table local`): that is the one.
        return Ok(v4
            .broadcast
            .filter(|brd| *brd != iface)
            .unwrap_or_else(|| Ipv4Addr::from(u32::from(iface) | !u32::from(v4.netmask))));
    }
    Err(IfaceError::NotLocal(iface))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interfaces_resolve_by_address_and_by_name() {
        assert_eq!(resolve_iface("127.0.0.1").unwrap(), Ipv4Addr::LOCALHOST);
        assert_eq!(
            resolve_iface("lo").unwrap(),
            Ipv4Addr::LOCALHOST,
            "the loopback interface is named lo on Linux"
        );
        assert!(matches!(
            resolve_iface("no-such-if0"),
            Err(IfaceError::NoSuchInterface(_))
        ));
    }

    #[test]
    fn loopback_broadcasts_to_127_255_255_255_and_a_foreign_address_is_refused() {
        for lo in [Ipv4Addr::LOCALHOST, Ipv4Addr::new(127, 0, 0, 2)] {
            assert_eq!(
                broadcast_address(lo).unwrap(),
                Ipv4Addr::new(127, 255, 255, 255),
                "{lo}"
            );
        }
        // Whatever interfaces this machine has (nothing is sent): each address with a
        // `brd` gets that one.
        for interface in if_addrs::get_if_addrs().unwrap() {
            if let if_addrs::IfAddr::V4(v4) = &interface.addr {
                if let (Some(brd), false) = (v4.broadcast, v4.ip.is_loopback()) {
                    if v4.prefixlen < 31 && !interface.is_p2p() {
                        assert_eq!(broadcast_address(v4.ip).unwrap(), brd, "{interface:?}");
                    }
                }
            }
        }
        // 192.0.2.1 (TEST-NET-1) is no address of this machine.
        assert!(matches!(
            broadcast_address(Ipv4Addr::new(192, 0, 2, 1)),
            Err(IfaceError::NotLocal(_))
        ));
    }
}
