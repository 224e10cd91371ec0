//! Naming the network interface the team's group is joined on: `--iface wlan0` or
//! `--iface 192.168.1.12`.

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
}
