//! Simulated seconds per wall second: 5 robots each multicasting 100 frames/s of 200 bytes
//! over the competition preset, network only, driven the way a harness drives it
//! (run to the next send, drain every inbox, send). Target ≥ 1000× real time.

#![allow(clippy::disallowed_methods)] // a bench measures wall time on purpose

use std::cell::Cell;
use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion};
use netsim::{Dest, Preset, Sim, Time};

const ROBOTS: usize = 5;
const FRAME_INTERVAL: Duration = Duration::from_millis(10);
const FRAME_BYTES: usize = 200;
const SIMULATED: Duration = Duration::from_secs(10);

/// Runs one 10 s match; returns the number of packets received.
fn run_match(seed: u64, record_trace: bool) -> u64 {
    let mut sim = Sim::builder()
        .seed(seed)
        .preset(Preset::Competition)
        .record_trace(record_trace)
        .build()
        .expect("preset is valid");
    let robots = sim.add_nodes(ROBOTS);
    let team = sim.add_group(&robots).expect("robots exist");
    // Robots are not in phase: robot k sends 2 ms after robot k-1.
    let mut next_send: Vec<Time> = (0..ROBOTS)
        .map(|k| Time::ZERO + Duration::from_millis(2 * k as u64))
        .collect();
    let end = Time::ZERO + SIMULATED;
    let frame = vec![0xA5u8; FRAME_BYTES];
    let mut received = 0u64;
    loop {
        let (k, &due) = next_send
            .iter()
            .enumerate()
            .min_by_key(|(_, t)| **t)
            .expect("robots");
        if due > end {
            break;
        }
        sim.run_until(due);
        for &r in &robots {
            received += sim
                .drain(r)
                .map(|d| d.bytes.len() as u64 / FRAME_BYTES as u64)
                .sum::<u64>();
        }
        sim.send(robots[k], Dest::Group(team), frame.as_slice())
            .expect("valid send");
        next_send[k] = due + FRAME_INTERVAL;
    }
    sim.run_until(end);
    received
}

fn bench(c: &mut Criterion) {
    for record_trace in [true, false] {
        let name = if record_trace {
            "competition_5x100fps_trace_on"
        } else {
            "competition_5x100fps_trace_off"
        };
        let wall = Cell::new(Duration::ZERO);
        let matches = Cell::new(0u32);
        c.bench_function(name, |b| {
            b.iter_custom(|iters| {
                let start = Instant::now();
                for i in 0..iters {
                    black_box(run_match(i, record_trace));
                }
                let elapsed = start.elapsed();
                wall.set(wall.get() + elapsed);
                matches.set(matches.get() + iters as u32);
                elapsed
            })
        });
        let simulated_s = SIMULATED.as_secs_f64() * f64::from(matches.get());
        println!(
            "{name}: {:.0}x real time ({simulated_s:.0} simulated s in {:.2} wall s)",
            simulated_s / wall.get().as_secs_f64(),
            wall.get().as_secs_f64()
        );
    }
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(Duration::from_secs(5));
    targets = bench
}
criterion_main!(benches);
