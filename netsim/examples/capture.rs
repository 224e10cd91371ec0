//! Writes a trace and a pcap of a short 5-robot competition-WLAN match.
//!
//! `cargo run -p netsim --example capture -- match.pcap match.trace`, then
//! `tshark -r match.pcap` to look at it.

use std::fs::File;
use std::io::BufWriter;
use std::time::Duration;

use netsim::{Action, Dest, Preset, Sim, Time};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let pcap_path = args.next().unwrap_or_else(|| "match.pcap".into());
    let trace_path = args.next().unwrap_or_else(|| "match.trace".into());

    let mut sim = Sim::builder().seed(1).preset(Preset::Competition).build()?;
    let robots = sim.add_nodes(5);
    let team = sim.add_group(&robots)?;
    sim.at(Time::from_secs(1), Action::Isolate(robots[3]))?;
    sim.at(Time::from_secs(2), Action::Rejoin(robots[3]))?;
    for tick in 0..300u64 {
        for &r in &robots {
            let at = Time::from_millis(10 * tick) + Duration::from_micros(u64::from(r.0) * 1300);
            let frame = format!("robot {} tick {tick}", r.0).into_bytes();
            sim.send_at(at, r, Dest::Group(team), frame)?;
        }
    }
    sim.run_until(Time::from_secs(4));
    sim.write_pcap(BufWriter::new(File::create(&pcap_path)?))?;
    sim.write_trace(BufWriter::new(File::create(&trace_path)?))?;
    let stats = sim.network_stats();
    println!(
        "{} events, hash {:016x}; sent {} delivered {} lost {} ({:.1}%); wrote {pcap_path} and {trace_path}",
        sim.trace().event_count(),
        sim.trace().hash(),
        stats.sent,
        stats.delivered,
        stats.lost_total(),
        100.0 * stats.loss_rate()
    );
    Ok(())
}
