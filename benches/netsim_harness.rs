//! Simulated seconds per wall second of a 5-robot team on the `competition` network, each
//! robot sending 100 frames/s:
//! - `network_only`: netsim alone, 5 nodes multicasting a 60-byte frame every 10 ms,
//!   driven as a harness drives it (run to the next send, drain every inbox, send).
//!   Target ≥ 1000× real time.
//! - `replicas`: `huddle::harness` with 5 comms replicas, each robot setting
//!   `*.var.pose` to a new value every 10 ms (one frame each, plus the 10 Hz refresh),
//!   every frame decoded and applied by the four others. Target ≥ 200× real time.
//!
//! Robots are out of phase (robot k acts 2 ms after robot k−1). The trace is recorded
//! (the harness default; its hash is what determinism tests compare). Both ratios are
//! printed after criterion's own report.

#![allow(clippy::disallowed_methods)] // a bench measures wall time on purpose

use std::cell::Cell;
use std::hint::black_box;
use std::time::{Duration, Instant};

use comms::{Key, ReplicaConfig, Value};
use criterion::{criterion_group, criterion_main, Criterion};
use huddle::harness::Harness;
use netsim::{Dest, Preset, Sim, Time};

const ROBOTS: usize = 5;
const FRAME_INTERVAL: Duration = Duration::from_millis(10);
/// About what a replica's one-value frame takes (header, sequence, one update).
const FRAME_BYTES: usize = 60;
const SIMULATED: Duration = Duration::from_secs(10);

fn at(d: Duration) -> Time {
    Time::from_nanos(d.as_nanos() as u64)
}

/// When robot `k` acts for the `n`-th time.
fn send_time(k: usize, n: u32) -> Duration {
    Duration::from_millis(2 * k as u64) + FRAME_INTERVAL * n
}

/// The robot that sends next and when, given how many frames each has sent; `None` once
/// the match is over.
fn next_send(sent: &[u32; ROBOTS]) -> Option<(usize, Duration)> {
    (0..ROBOTS)
        .map(|k| (k, send_time(k, sent[k])))
        .min_by_key(|&(_, t)| t)
        .filter(|&(_, t)| t <= SIMULATED)
}

/// One 10 s match, network only; returns the number of packets received.
fn network_only(seed: u64) -> u64 {
    let mut sim = Sim::builder()
        .seed(seed)
        .preset(Preset::Competition)
        .build()
        .expect("preset is valid");
    let robots = sim.add_nodes(ROBOTS);
    let team = sim.add_group(&robots).expect("robots exist");
    let mut sent = [0u32; ROBOTS];
    let frame = vec![0xA5u8; FRAME_BYTES];
    let mut received = 0u64;
    while let Some((k, due)) = next_send(&sent) {
        sim.run_until(at(due));
        for &r in &robots {
            received += sim.drain(r).count() as u64;
        }
        sim.send(robots[k], Dest::Group(team), frame.as_slice())
            .expect("valid send");
        sent[k] += 1;
    }
    sim.run_until(at(SIMULATED));
    received
}

/// One 10 s match with the replicas; returns the frames robot 5 applied.
fn replicas(seed: u64) -> u64 {
    let net = Sim::builder().preset(Preset::Competition);
    let mut h = Harness::new(ROBOTS, net, ReplicaConfig::new(1, 7), seed).expect("valid");
    h.keep_events(false);
    let pose = Key::parse("*.var.pose").expect("valid key");
    let mut sent = [0u32; ROBOTS];
    while let Some((k, due)) = next_send(&sent) {
        h.run_until(at(due));
        let v = Value::Floats(vec![k as f64, sent[k] as f64 * 0.01, 0.5]);
        h.set(k, &pose, v).expect("own key");
        sent[k] += 1;
    }
    h.run_until(at(SIMULATED));
    h.replica(ROBOTS - 1).expect("alive").stats().frames_in
}

fn measure(c: &mut Criterion, name: &str, run: fn(u64) -> u64) -> f64 {
    let wall = Cell::new(Duration::ZERO);
    let matches = Cell::new(0u64);
    c.bench_function(name, |b| {
        b.iter_custom(|iters| {
            let start = Instant::now();
            for i in 0..iters {
                black_box(run(i));
            }
            let elapsed = start.elapsed();
            wall.set(wall.get() + elapsed);
            matches.set(matches.get() + iters);
            elapsed
        })
    });
    SIMULATED.as_secs_f64() * matches.get() as f64 / wall.get().as_secs_f64()
}

fn bench(c: &mut Criterion) {
    let net = measure(c, "competition_5x100fps_network_only", network_only);
    let team = measure(c, "competition_5x100fps_replicas", replicas);
    println!("network only:  {net:.0}x real time (target >= 1000x)");
    println!("with replicas: {team:.0}x real time (target >= 200x)");
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(10).measurement_time(Duration::from_secs(5));
    targets = bench
}
criterion_main!(benches);
