//! pcap output: what each node received, as Ethernet/IPv4/UDP frames `tshark` can read.
//!
//! Classic libpcap format with nanosecond timestamps (magic `0xa1b23c4d`), link type
//! Ethernet. One record per delivered copy, stamped with its global arrival time. The
//! headers are synthetic: node `n` is `10.0.0.n` (`10.0.hi.lo` above 255) with MAC
//! `02:00:00:00:hi:lo`; group `g` is `224.0.0.g`; both UDP ports are 2000 (the seed's
//! multicast port). The capture point is the receiver: the Ethernet destination is always
//! the receiving node's MAC, so `eth.dst` says who got a multicast copy. The IPv4
//! identification field holds the packet's number on its link (low 16 bits), and the UDP
//! checksum is 0 (none, allowed in IPv4).

use std::io::{self, Write};
use std::net::SocketAddrV4;

use crate::sim::{Dest, GroupId, NodeId};
use crate::trace::{Trace, TraceKind};

/// The UDP source and destination port of every captured packet.
pub const UDP_PORT: u16 = 2000;
/// pcap magic for nanosecond-resolution timestamps.
pub const PCAP_MAGIC_NS: u32 = 0xa1b2_3c4d;
/// pcap link type for Ethernet.
pub const LINKTYPE_ETHERNET: u32 = 1;
/// Largest frame written whole; longer payloads are truncated in the capture.
pub const SNAPLEN: u32 = 65_535;

const ETH_HEADER: usize = 14;
const IPV4_HEADER: usize = 20;
const UDP_HEADER: usize = 8;

/// The synthetic IPv4 address of a node.
pub fn node_ipv4(node: NodeId) -> [u8; 4] {
    let [hi, lo] = node.0.to_be_bytes();
    [10, 0, hi, lo]
}

/// The synthetic IPv4 multicast address of a group.
pub fn group_ipv4(group: GroupId) -> [u8; 4] {
    let [hi, lo] = group.0.to_be_bytes();
    [224, 0, hi, lo]
}

fn node_mac(node: NodeId) -> [u8; 6] {
    let [hi, lo] = node.0.to_be_bytes();
    [0x02, 0, 0, 0, hi, lo]
}

/// Writes every recorded delivery of `trace` as a pcap file.
pub fn write_pcap<W: Write>(trace: &Trace, mut out: W) -> io::Result<()> {
    let mut header = Vec::with_capacity(24);
    header.extend_from_slice(&PCAP_MAGIC_NS.to_le_bytes());
    header.extend_from_slice(&2u16.to_le_bytes());
    header.extend_from_slice(&4u16.to_le_bytes());
    header.extend_from_slice(&0i32.to_le_bytes()); // thiszone: UTC
    header.extend_from_slice(&0u32.to_le_bytes()); // sigfigs
    header.extend_from_slice(&SNAPLEN.to_le_bytes());
    header.extend_from_slice(&LINKTYPE_ETHERNET.to_le_bytes());
    out.write_all(&header)?;
    let mut frame = Vec::new();
    for event in trace.events() {
        let TraceKind::Deliver {
            from,
            to,
            seq,
            dest,
            bytes,
            ..
        } = &event.kind
        else {
            continue;
        };
        let orig_len = ETH_HEADER + IPV4_HEADER + UDP_HEADER + bytes.len();
        frame.clear();
        build_frame(&mut frame, *from, *to, *dest, *seq, bytes);
        frame.truncate(SNAPLEN as usize);
        let ns = event.at.as_nanos();
        let mut record = [0u8; 16];
        record[0..4].copy_from_slice(&((ns / 1_000_000_000) as u32).to_le_bytes());
        record[4..8].copy_from_slice(&((ns % 1_000_000_000) as u32).to_le_bytes());
        record[8..12].copy_from_slice(&(frame.len() as u32).to_le_bytes());
        record[12..16].copy_from_slice(&u32::try_from(orig_len).unwrap_or(u32::MAX).to_le_bytes());
        out.write_all(&record)?;
        out.write_all(&frame)?;
    }
    out.flush()
}

fn build_frame(
    frame: &mut Vec<u8>,
    from: NodeId,
    to: NodeId,
    dest: Dest,
    seq: u64,
    payload: &[u8],
) {
    frame.extend_from_slice(&node_mac(to));
    frame.extend_from_slice(&node_mac(from));
    frame.extend_from_slice(&0x0800u16.to_be_bytes());

    let (dst_ip, ttl) = match dest {
        Dest::Node(n) => (node_ipv4(n), 64),
        // Link-local multicast, as the seed's 224.0.0.1, goes out with TTL 1.
        Dest::Group(g) => (group_ipv4(g), 1),
    };
    push_ipv4_udp(
        frame,
        SocketAddrV4::new(node_ipv4(from).into(), UDP_PORT),
        SocketAddrV4::new(dst_ip.into(), UDP_PORT),
        ttl,
        seq as u16,
        payload,
    );
}

/// Appends an IPv4 header (no options, checksummed, identification `id`) and a UDP
/// header (checksum 0: none, allowed in IPv4) for `payload`, then the payload. Lengths
/// that do not fit 16 bits saturate.
pub fn push_ipv4_udp(
    out: &mut Vec<u8>,
    from: SocketAddrV4,
    to: SocketAddrV4,
    ttl: u8,
    id: u16,
    payload: &[u8],
) {
    let ip_len = u16::try_from(IPV4_HEADER + UDP_HEADER + payload.len()).unwrap_or(u16::MAX);
    let udp_len = u16::try_from(UDP_HEADER + payload.len()).unwrap_or(u16::MAX);
    let mut ip = [0u8; IPV4_HEADER];
    ip[0] = 0x45; // version 4, 5 words of header
    ip[2..4].copy_from_slice(&ip_len.to_be_bytes());
    ip[4..6].copy_from_slice(&id.to_be_bytes());
    ip[8] = ttl;
    ip[9] = 17; // UDP
    ip[12..16].copy_from_slice(&from.ip().octets());
    ip[16..20].copy_from_slice(&to.ip().octets());
    let checksum = ipv4_checksum(&ip);
    ip[10..12].copy_from_slice(&checksum.to_be_bytes());
    out.extend_from_slice(&ip);
    out.extend_from_slice(&from.port().to_be_bytes());
    out.extend_from_slice(&to.port().to_be_bytes());
    out.extend_from_slice(&udp_len.to_be_bytes());
    out.extend_from_slice(&0u16.to_be_bytes());
    out.extend_from_slice(payload);
}

/// The Internet checksum (RFC 1071) of a header whose checksum field is zero.
pub fn ipv4_checksum(header: &[u8]) -> u16 {
    let mut sum: u32 = header
        .chunks(2)
        .map(|w| u32::from(u16::from_be_bytes([w[0], *w.get(1).unwrap_or(&0)])))
        .sum();
    while sum > 0xffff {
        sum = (sum & 0xffff) + (sum >> 16);
    }
    !(sum as u16)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checksum_matches_a_known_header() {
        // The worked example from Wikipedia's "IPv4 header checksum" article.
        let header = [
            0x45, 0x00, 0x00, 0x73, 0x00, 0x00, 0x40, 0x00, 0x40, 0x11, 0x00, 0x00, 0xc0, 0xa8,
            0x00, 0x01, 0xc0, 0xa8, 0x00, 0xc7,
        ];
        assert_eq!(ipv4_checksum(&header), 0xb861);
    }
}
