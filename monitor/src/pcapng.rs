//! Recordings of a team's traffic as pcapng, the format Wireshark and tshark open.
//!
//! What `huddle record` and `huddle sim --record` write, and `huddle replay` reads:
//!
//! - one Section Header Block (little-endian), one Interface Description Block with link
//!   type `LINKTYPE_IPV4` (228: each packet starts at its IPv4 header), snap length
//!   65535 and `if_tsresol` 9 (nanosecond timestamps), named `huddle` in `if_name`;
//! - one Enhanced Packet Block per datagram received, stamped with its reception time on
//!   the recording machine's clock (nanoseconds since the Unix epoch; a simulated match
//!   starts at the epoch), holding a synthetic IPv4 + UDP header (the sender's address and
//!   port, the group's address and port, TTL 1, UDP checksum 0) and the huddle frame.
//!
//! The reader is for untrusted files: any byte sequence gives packets or a
//! [`CaptureError`], never a panic. It also reads other pcapng files of UDP over IPv4 (link
//! types Ethernet, raw IP and IPv4, either byte order, any `if_tsresol`), skipping blocks
//! and packets that are not UDP over IPv4.

use std::io::{self, Write};
use std::net::{Ipv4Addr, SocketAddrV4};

use thiserror::Error;

/// pcapng link type: packets begin with an IPv4 header.
pub const LINKTYPE_IPV4: u16 = 228;
const LINKTYPE_ETHERNET: u16 = 1;
const LINKTYPE_RAW: u16 = 101;
const SNAPLEN: u32 = 65_535;
const BLOCK_SHB: u32 = 0x0A0D_0D0A;
const BLOCK_IDB: u32 = 1;
const BLOCK_EPB: u32 = 6;
const BYTE_ORDER_MAGIC: u32 = 0x1A2B_3C4D;
const IPV4_HEADER: usize = 20;
const UDP_HEADER: usize = 8;
/// A block larger than this is taken for a damaged file, not read.
const MAX_BLOCK: usize = 1 << 24;

/// One captured datagram.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Packet {
    /// Reception time, nanoseconds since the Unix epoch (the recorder's clock).
    pub t_ns: u64,
    /// Who sent it.
    pub from: SocketAddrV4,
    /// Where it was sent (the team's group and port).
    pub to: SocketAddrV4,
    /// The UDP payload: a huddle frame.
    pub payload: Vec<u8>,
}

/// Why a recording could not be read.
#[derive(Debug, Error, PartialEq, Eq)]
pub enum CaptureError {
    /// The file does not begin with a pcapng Section Header Block.
    #[error("not a pcapng file (it does not begin with a section header block)")]
    NotPcapng,
    /// A block's length runs past the end of the file or is malformed.
    #[error("damaged pcapng block at byte {offset}: {what}")]
    Damaged {
        /// Where the block starts.
        offset: usize,
        /// What is wrong with it.
        what: &'static str,
    },
}

/// Writes a recording: the headers at once, then one block per [`Writer::write`].
pub struct Writer<W: Write> {
    out: W,
    buf: Vec<u8>,
}

impl<W: Write> Writer<W> {
    /// Writes the section and interface headers.
    pub fn new(mut out: W) -> io::Result<Self> {
        let mut b = Vec::with_capacity(64);
        // Section header: byte-order magic, version 1.0, section length unknown (-1).
        b.extend_from_slice(&BLOCK_SHB.to_le_bytes());
        b.extend_from_slice(&28u32.to_le_bytes());
        b.extend_from_slice(&BYTE_ORDER_MAGIC.to_le_bytes());
        b.extend_from_slice(&1u16.to_le_bytes());
        b.extend_from_slice(&0u16.to_le_bytes());
        b.extend_from_slice(&(-1i64).to_le_bytes());
        b.extend_from_slice(&28u32.to_le_bytes());
        // Interface description: IPv4, snaplen, if_name "huddle", if_tsresol 9.
        let mut opts = Vec::new();
        push_option(&mut opts, 2, b"huddle");
        push_option(&mut opts, 9, &[9]);
        opts.extend_from_slice(&[0, 0, 0, 0]); // opt_endofopt
        let len = (20 + opts.len()) as u32;
        b.extend_from_slice(&BLOCK_IDB.to_le_bytes());
        b.extend_from_slice(&len.to_le_bytes());
        b.extend_from_slice(&LINKTYPE_IPV4.to_le_bytes());
        b.extend_from_slice(&0u16.to_le_bytes());
        b.extend_from_slice(&SNAPLEN.to_le_bytes());
        b.extend_from_slice(&opts);
        b.extend_from_slice(&len.to_le_bytes());
        out.write_all(&b)?;
        Ok(Self {
            out,
            buf: Vec::new(),
        })
    }

    /// Appends one datagram (payloads beyond the snap length are cut in the capture).
    pub fn write(&mut self, packet: &Packet) -> io::Result<()> {
        let mut data = Vec::with_capacity(IPV4_HEADER + UDP_HEADER + packet.payload.len());
        build_ipv4_udp(&mut data, packet);
        let orig_len = data.len() as u32;
        data.truncate(SNAPLEN as usize);
        let padded = data.len().div_ceil(4) * 4;
        let len = (32 + padded) as u32;
        let b = &mut self.buf;
        b.clear();
        b.extend_from_slice(&BLOCK_EPB.to_le_bytes());
        b.extend_from_slice(&len.to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes()); // interface 0
        b.extend_from_slice(&((packet.t_ns >> 32) as u32).to_le_bytes());
        b.extend_from_slice(&(packet.t_ns as u32).to_le_bytes());
        b.extend_from_slice(&(data.len() as u32).to_le_bytes());
        b.extend_from_slice(&orig_len.to_le_bytes());
        b.extend_from_slice(&data);
        b.resize(28 + padded, 0);
        b.extend_from_slice(&len.to_le_bytes());
        self.out.write_all(b)
    }

    /// Flushes what was written to the underlying writer.
    pub fn flush(&mut self) -> io::Result<()> {
        self.out.flush()
    }
}

fn push_option(opts: &mut Vec<u8>, code: u16, value: &[u8]) {
    opts.extend_from_slice(&code.to_le_bytes());
    opts.extend_from_slice(&(value.len() as u16).to_le_bytes());
    opts.extend_from_slice(value);
    opts.resize(opts.len().div_ceil(4) * 4, 0);
}

/// The packet as raw IPv4/UDP (netsim's headers: TTL 1, link-local multicast; no UDP
/// checksum).
fn build_ipv4_udp(out: &mut Vec<u8>, p: &Packet) {
    netsim::pcap::push_ipv4_udp(out, p.from, p.to, 1, 0, &p.payload);
}

/// An interface as its description block gave it.
#[derive(Clone, Copy)]
struct Interface {
    link_type: u16,
    /// Nanoseconds per timestamp unit (numerator, denominator).
    ns_per_unit: (u64, u64),
}

/// Reads every UDP-over-IPv4 packet of a pcapng file, in file order.
pub fn read(bytes: &[u8]) -> Result<Vec<Packet>, CaptureError> {
    let mut packets = Vec::new();
    let mut big_endian = false;
    let mut interfaces: Vec<Interface> = Vec::new();
    let mut at = 0;
    let mut first = true;
    while at < bytes.len() {
        let damaged = |what| CaptureError::Damaged { offset: at, what };
        let head = bytes.get(at..at + 12).ok_or_else(|| {
            if first {
                CaptureError::NotPcapng
            } else {
                damaged("truncated block header")
            }
        })?;
        let kind_le = u32::from_le_bytes([head[0], head[1], head[2], head[3]]);
        if kind_le == BLOCK_SHB {
            let magic = [head[8], head[9], head[10], head[11]];
            big_endian = if u32::from_le_bytes(magic) == BYTE_ORDER_MAGIC {
                false
            } else if u32::from_be_bytes(magic) == BYTE_ORDER_MAGIC {
                true
            } else {
                return Err(if first {
                    CaptureError::NotPcapng
                } else {
                    damaged("bad byte-order magic")
                });
            };
            interfaces.clear();
        } else if first {
            return Err(CaptureError::NotPcapng);
        }
        first = false;
        let u32_at = |b: &[u8], i: usize| -> Option<u32> {
            let w: [u8; 4] = b.get(i..i + 4)?.try_into().ok()?;
            Some(if big_endian {
                u32::from_be_bytes(w)
            } else {
                u32::from_le_bytes(w)
            })
        };
        let u16_at = |b: &[u8], i: usize| -> Option<u16> {
            let w: [u8; 2] = b.get(i..i + 2)?.try_into().ok()?;
            Some(if big_endian {
                u16::from_be_bytes(w)
            } else {
                u16::from_le_bytes(w)
            })
        };
        let kind = u32_at(head, 0).unwrap_or(0);
        let len = u32_at(head, 4).unwrap_or(0) as usize;
        if len < 12 || !len.is_multiple_of(4) || len > MAX_BLOCK {
            return Err(damaged("bad block length"));
        }
        let block = bytes
            .get(at..at + len)
            .ok_or_else(|| damaged("block runs past the end of the file"))?;
        if u32_at(block, len - 4) != Some(len as u32) {
            return Err(damaged("trailing block length differs"));
        }
        let body = &block[8..len - 4];
        match kind {
            BLOCK_IDB => {
                let link_type = u16_at(body, 0).ok_or_else(|| damaged("short interface"))?;
                let mut ns_per_unit = (1_000, 1); // default: microseconds
                let mut o = 8;
                while let (Some(code), Some(olen)) = (u16_at(body, o), u16_at(body, o + 2)) {
                    let olen = olen as usize;
                    if code == 0 {
                        break;
                    }
                    let value = body
                        .get(o + 4..o + 4 + olen)
                        .ok_or_else(|| damaged("option runs past its block"))?;
                    if code == 9 && olen == 1 {
                        ns_per_unit = tsresol(value[0]);
                    }
                    o += 4 + olen.div_ceil(4) * 4;
                }
                interfaces.push(Interface {
                    link_type,
                    ns_per_unit,
                });
            }
            BLOCK_EPB => {
                let iface = u32_at(body, 0).ok_or_else(|| damaged("short packet block"))?;
                let hi = u32_at(body, 4).ok_or_else(|| damaged("short packet block"))?;
                let lo = u32_at(body, 8).ok_or_else(|| damaged("short packet block"))?;
                let caplen = u32_at(body, 12).ok_or_else(|| damaged("short packet block"))?;
                let data = body
                    .get(20..20 + caplen as usize)
                    .ok_or_else(|| damaged("packet runs past its block"))?;
                let iface = *interfaces
                    .get(iface as usize)
                    .ok_or_else(|| damaged("packet on an undescribed interface"))?;
                let units = (u64::from(hi) << 32) | u64::from(lo);
                let (num, den) = iface.ns_per_unit;
                let t_ns = (u128::from(units) * u128::from(num) / u128::from(den))
                    .try_into()
                    .unwrap_or(u64::MAX);
                if let Some(p) = parse_udp(iface.link_type, data, t_ns) {
                    packets.push(p);
                }
            }
            _ => {} // section headers handled above; statistics, names, comments skipped
        }
        at += len;
    }
    if first {
        return Err(CaptureError::NotPcapng);
    }
    Ok(packets)
}

/// `if_tsresol`: high bit clear, 10^-v s; set, 2^-v s; as nanoseconds per unit.
fn tsresol(v: u8) -> (u64, u64) {
    let exp = u32::from(v & 0x7f);
    if v & 0x80 == 0 {
        if exp <= 9 {
            (10u64.pow(9 - exp), 1)
        } else {
            (1, 10u64.checked_pow(exp - 9).unwrap_or(u64::MAX))
        }
    } else {
        (1_000_000_000, 1u64.checked_shl(exp).unwrap_or(u64::MAX))
    }
}

fn parse_udp(link_type: u16, data: &[u8], t_ns: u64) -> Option<Packet> {
    let ip = match link_type {
        LINKTYPE_IPV4 | LINKTYPE_RAW => data,
        LINKTYPE_ETHERNET if data.get(12..14)? == [0x08, 0x00] => data.get(14..)?,
        _ => return None,
    };
    if ip.first()? >> 4 != 4 || ip.get(9)? != &17 {
        return None;
    }
    let ihl = usize::from(ip[0] & 0x0f) * 4;
    let total = usize::from(u16::from_be_bytes([*ip.get(2)?, *ip.get(3)?]));
    let ip = ip.get(..total.max(ihl).min(ip.len()))?;
    let src = Ipv4Addr::new(*ip.get(12)?, ip[13], ip[14], ip[15]);
    let dst = Ipv4Addr::new(*ip.get(16)?, ip[17], ip[18], ip[19]);
    let udp = ip.get(ihl..)?;
    let sport = u16::from_be_bytes([*udp.first()?, *udp.get(1)?]);
    let dport = u16::from_be_bytes([*udp.get(2)?, *udp.get(3)?]);
    let udp_len = usize::from(u16::from_be_bytes([*udp.get(4)?, *udp.get(5)?]));
    let end = udp_len.clamp(UDP_HEADER, udp.len().max(UDP_HEADER));
    let payload = udp.get(UDP_HEADER..end)?.to_vec();
    Some(Packet {
        t_ns,
        from: SocketAddrV4::new(src, sport),
        to: SocketAddrV4::new(dst, dport),
        payload,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Vec<Packet> {
        vec![
            Packet {
                t_ns: 1_700_000_000_123_456_789,
                from: "127.0.0.1:40000".parse().unwrap(),
                to: "239.255.1.2:2000".parse().unwrap(),
                payload: b"HD\x02frame".to_vec(),
            },
            Packet {
                t_ns: 1_700_000_000_223_456_789,
                from: "10.0.0.2:2000".parse().unwrap(),
                to: "224.0.0.1:2000".parse().unwrap(),
                payload: vec![7; 1201],
            },
        ]
    }

    fn write_all(packets: &[Packet]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut w = Writer::new(&mut out).unwrap();
        for p in packets {
            w.write(p).unwrap();
        }
        w.flush().unwrap();
        out
    }

    #[test]
    fn what_is_written_reads_back() {
        let packets = sample();
        let bytes = write_all(&packets);
        assert_eq!(read(&bytes).unwrap(), packets);
        // Byte fixture of the headers: section header, then the interface block.
        assert_eq!(&bytes[..4], &[0x0a, 0x0d, 0x0d, 0x0a]);
        assert_eq!(&bytes[8..12], &[0x4d, 0x3c, 0x2b, 0x1a]);
        assert_eq!(&bytes[28..32], &[1, 0, 0, 0]);
        assert_eq!(&bytes[36..38], &[228, 0]); // LINKTYPE_IPV4
        assert_eq!(read(&write_all(&[])).unwrap(), vec![]);
    }

    #[test]
    fn the_ip_header_checksum_is_valid() {
        let mut data = Vec::new();
        build_ipv4_udp(&mut data, &sample()[0]);
        assert_eq!(netsim::pcap::ipv4_checksum(&data[..IPV4_HEADER]), 0);
    }

    #[test]
    fn damaged_files_are_errors_not_panics() {
        assert_eq!(read(b""), Err(CaptureError::NotPcapng));
        assert_eq!(
            read(b"hello world, not a capture"),
            Err(CaptureError::NotPcapng)
        );
        let bytes = write_all(&sample());
        for cut in 1..bytes.len() {
            let _ = read(&bytes[..cut]);
        }
        assert!(read(&bytes[..bytes.len() - 1]).is_err());
        // Flip every byte in turn: errors or packets, never a panic.
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0xff;
            let _ = read(&b);
        }
        // A seeded stream of garbage after a valid header.
        let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
        for _ in 0..2000 {
            let mut b = bytes[..60].to_vec();
            for _ in 0..(x % 97) {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                b.push(x as u8);
            }
            let _ = read(&b);
        }
    }

    #[test]
    fn timestamp_resolutions_convert_to_nanoseconds() {
        assert_eq!(tsresol(6), (1_000, 1));
        assert_eq!(tsresol(9), (1, 1));
        assert_eq!(tsresol(0x80 | 10), (1_000_000_000, 1024));
        let _ = tsresol(0xff);
        let _ = tsresol(0x7f);
    }
}
