//! pcap and text trace output, read back by an independent parser.

use netsim::{Dest, Preset, Sim, Time, TraceKind};

/// Three robots on the competition WLAN: multicast chatter plus one unicast.
fn small_match() -> Sim {
    let mut sim = Sim::builder()
        .seed(12)
        .preset(Preset::Competition)
        .build()
        .unwrap();
    let robots = sim.add_nodes(3);
    let team = sim.add_group(&robots).unwrap();
    for tick in 0..50u64 {
        for &r in &robots {
            let payload = format!("robot {} tick {tick}", r.0).into_bytes();
            sim.send_at(
                Time::from_millis(20 * tick + u64::from(r.0)),
                r,
                Dest::Group(team),
                payload,
            )
            .unwrap();
        }
    }
    sim.send_at(
        Time::from_millis(7),
        robots[0],
        Dest::Node(robots[2]),
        b"pass!".to_vec(),
    )
    .unwrap();
    sim.run_until(Time::from_secs(3));
    sim
}

struct Record {
    ts_ns: u64,
    frame: Vec<u8>,
    orig_len: u32,
}

/// Reads a little-endian nanosecond pcap, checking the global header.
fn read_pcap(bytes: &[u8]) -> Vec<Record> {
    let u32_at = |at: usize| u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
    let u16_at = |at: usize| u16::from_le_bytes(bytes[at..at + 2].try_into().unwrap());
    assert_eq!(u32_at(0), 0xa1b2_3c4d, "nanosecond pcap magic");
    assert_eq!((u16_at(4), u16_at(6)), (2, 4), "pcap version 2.4");
    assert_eq!(u32_at(16), 65_535, "snaplen");
    assert_eq!(u32_at(20), 1, "LINKTYPE_ETHERNET");
    let mut records = Vec::new();
    let mut at = 24;
    while at < bytes.len() {
        let ts_ns = u64::from(u32_at(at)) * 1_000_000_000 + u64::from(u32_at(at + 4));
        let incl = u32_at(at + 8) as usize;
        let orig_len = u32_at(at + 12);
        let frame = bytes[at + 16..at + 16 + incl].to_vec();
        records.push(Record {
            ts_ns,
            frame,
            orig_len,
        });
        at += 16 + incl;
    }
    records
}

#[test]
fn every_delivery_is_one_well_formed_udp_frame_at_its_arrival_time() {
    let sim = small_match();
    let mut pcap = Vec::new();
    sim.write_pcap(&mut pcap).unwrap();
    let records = read_pcap(&pcap);
    let deliveries: Vec<_> = sim
        .trace()
        .events()
        .iter()
        .filter_map(|e| match &e.kind {
            TraceKind::Deliver {
                from,
                to,
                dest,
                bytes,
                ..
            } => Some((e.at, *from, *to, *dest, bytes.clone())),
            _ => None,
        })
        .collect();
    assert!(deliveries.len() > 300, "{} deliveries", deliveries.len());
    assert_eq!(
        records.len(),
        deliveries.len(),
        "one record per delivered copy"
    );
    let mut saw_unicast = false;
    for (r, (at, from, to, dest, payload)) in records.iter().zip(&deliveries) {
        let f = &r.frame;
        assert_eq!(r.ts_ns, at.as_nanos());
        assert_eq!(r.orig_len as usize, f.len());
        assert_eq!(
            &f[0..6],
            &[2, 0, 0, 0, 0, to.0 as u8],
            "eth.dst is the receiver"
        );
        assert_eq!(
            &f[6..12],
            &[2, 0, 0, 0, 0, from.0 as u8],
            "eth.src is the sender"
        );
        assert_eq!(&f[12..14], &[0x08, 0x00], "IPv4");
        let ip = &f[14..34];
        assert_eq!(ip[0], 0x45);
        assert_eq!(
            usize::from(u16::from_be_bytes([ip[2], ip[3]])),
            f.len() - 14
        );
        assert_eq!(ip[9], 17, "UDP");
        let mut sum: u32 = ip
            .chunks(2)
            .map(|w| u32::from(u16::from_be_bytes([w[0], w[1]])))
            .sum();
        sum = (sum & 0xffff) + (sum >> 16);
        assert_eq!(sum, 0xffff, "IPv4 header checksum verifies");
        assert_eq!(&ip[12..16], &[10, 0, 0, from.0 as u8]);
        match dest {
            Dest::Group(_) => assert_eq!(&ip[16..20], &[224, 0, 0, 1], "group 1 is 224.0.0.1"),
            Dest::Node(n) => {
                saw_unicast = true;
                assert_eq!(&ip[16..20], &[10, 0, 0, n.0 as u8]);
            }
        }
        let udp = &f[34..42];
        assert_eq!(u16::from_be_bytes([udp[0], udp[1]]), 2000);
        assert_eq!(u16::from_be_bytes([udp[2], udp[3]]), 2000);
        assert_eq!(
            usize::from(u16::from_be_bytes([udp[4], udp[5]])),
            8 + payload.len()
        );
        assert_eq!(&f[42..], &payload[..]);
    }
    assert!(saw_unicast, "seed 12: the unicast pass to robot 3 arrives");
}

#[test]
fn the_text_trace_has_one_parseable_line_per_event() {
    let sim = small_match();
    let mut text = Vec::new();
    sim.write_trace(&mut text).unwrap();
    let text = String::from_utf8(text).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), sim.trace().events().len());
    let mut last = 0.0f64;
    for line in &lines {
        let mut words = line.split(' ');
        let t: f64 = words.next().unwrap().trim_end_matches('s').parse().unwrap();
        assert!(t >= last, "lines are in time order: {line}");
        last = t;
        let verb = words.next().unwrap();
        assert!(
            ["send", "drop", "deliver", "action"].contains(&verb),
            "{line}"
        );
    }
    assert!(
        lines[0].starts_with("0.001000000s send tx=0 n1->g1 len=14 hash="),
        "{}",
        lines[0]
    );
}
