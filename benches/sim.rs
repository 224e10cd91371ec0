//! Simulated seconds per wall second of `huddle sim` with its defaults (5 robots, 3
//! opponents, the `competition` network, physics at 100 Hz, control at 25 Hz). Target:
//! ≥ 100× real time. Criterion reports the throughput as "elements" per second, one
//! element being one simulated second: the figure *is* the speed-up over real time.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use huddle::sim::{SimConfig, Simulation};

/// Simulated seconds per iteration: long enough that set-up is noise.
const SIMULATED_S: f64 = 20.0;

fn sim_defaults(c: &mut Criterion) {
    let mut group = c.benchmark_group("huddle_sim");
    group.sample_size(10);
    group.throughput(Throughput::Elements(SIMULATED_S as u64));
    group.bench_function("defaults_simulated_s", |b| {
        b.iter(|| {
            let cfg = SimConfig {
                duration_s: SIMULATED_S,
                ..SimConfig::default()
            };
            let mut sim = Simulation::new(cfg).expect("defaults are valid");
            sim.run(|_| {});
            std::hint::black_box(sim.metrics.visible_s)
        })
    });
    group.finish();
}

criterion_group!(benches, sim_defaults);
criterion_main!(benches);
