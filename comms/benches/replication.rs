//! Replication hot path: five robots publish their local world model (75 bytes, the size
//! of fusion's encoded LWM) and four scalars each; one teammate decodes and applies all 25
//! entries. Reported as entries/s (target: ≥ 1,000,000 on one core). Also prints the bytes
//! on the wire of one robot's world-model frame, with and without a team key, against the
//! RoboCup SPL message limit of 128 bytes.
//!
//! Each benchmark runs twice: `replication` measures wall time; `replication-cpu` measures
//! this thread's CPU time (Linux `CLOCK_THREAD_CPUTIME_ID`), which is what "entries per
//! second on one core" means on a machine shared with other work.
//!
//! Run: `cargo bench -p comms --bench replication -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;
use std::net::SocketAddr;
use std::time::Duration;

use comms::wire::{decode_frame, TeamKey};
use comms::{Instant, Replica, ReplicaConfig, Value};
use criterion::measurement::{Measurement, ValueFormatter, WallTime};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

const ROBOTS: u8 = 5;
const ENTRIES_PER_ROBOT: u64 = 5;
const KEY: &[u8] = b"team key for the bench, 32 bytes";

/// Bytes of a local world model as fusion encodes it (`fusion::LWM_WIRE_LEN`; comms does
/// not depend on fusion, so the size is written here).
const WORLD_MODEL_LEN: usize = 75;

/// A stand-in for an encoded local world model: [`WORLD_MODEL_LEN`] bytes that change
/// every tick.
fn world_model(robot: u8, tick: u64) -> Value {
    let bytes = (0..WORLD_MODEL_LEN)
        .map(|i| {
            (tick as u8)
                .wrapping_mul(31)
                .wrapping_add((i as u8).wrapping_mul(97))
                .wrapping_add(robot)
        })
        .collect();
    Value::Bytes(bytes)
}

fn publish(r: &mut Replica, now: Instant, tick: u64) {
    let id = r.robot_id();
    r.set(now, "*.var.world.local", world_model(id, tick))
        .unwrap();
    r.set(
        now,
        "*.var.machine.heuristic",
        Value::Float(tick as f64 * 0.01 + id as f64),
    )
    .unwrap();
    r.set(now, "*.var.machine.mode", Value::Int((tick % 3) as i64))
        .unwrap();
    r.set(
        now,
        "*.var.machine.role",
        Value::String(["active", "auxiliary", "inactive"][(tick % 3) as usize].into()),
    )
    .unwrap();
    r.set(now, "*.var.ball.seen", Value::Bool(tick.is_multiple_of(2)))
        .unwrap();
}

fn team(keyed: bool) -> (Vec<Replica>, Replica) {
    let cfg = |id| {
        let c = ReplicaConfig::new(id, 7);
        if keyed {
            c.with_team_key(KEY)
        } else {
            c
        }
    };
    let t0 = Instant::ZERO;
    let senders = (1..=ROBOTS)
        .map(|id| Replica::new(cfg(id), id as u64 * 1000 + 1, t0).unwrap())
        .collect();
    let receiver = Replica::new(cfg(ROBOTS + 1), 42, t0).unwrap();
    (senders, receiver)
}

fn bench_wall(c: &mut Criterion<WallTime>) {
    print_world_model_size();
    bench_replication(c, "replication");
}

fn bench_cpu(c: &mut Criterion<ThreadCpu>) {
    bench_replication(c, "replication-cpu");
}

fn bench_replication<M: Measurement>(c: &mut Criterion<M>, group_name: &str) {
    let from = SocketAddr::from(([127, 0, 0, 1], 2000));
    let mut group = c.benchmark_group(group_name);
    group.throughput(Throughput::Elements(ROBOTS as u64 * ENTRIES_PER_ROBOT));
    for keyed in [false, true] {
        let name = if keyed {
            "set+encode+decode+apply, hmac"
        } else {
            "set+encode+decode+apply"
        };
        let (mut senders, mut receiver) = team(keyed);
        let mut tick = 0u64;
        group.bench_function(name, |b| {
            b.iter(|| {
                tick += 1;
                let now = Instant::from_micros(tick * 1000);
                for s in &mut senders {
                    publish(s, now, tick);
                    while let Some(t) = s.poll_transmit() {
                        receiver.handle_datagram(now, from, black_box(&t.payload));
                    }
                }
                while let Some(e) = receiver.poll_event() {
                    black_box(e);
                }
            })
        });
        assert_eq!(
            receiver.stats().drops_total(),
            0,
            "the bench must apply, not drop"
        );
        assert!(receiver.stats().updates_applied > 0);
    }

    // Decoding alone, for comparison: the same five frames, already encoded.
    let (mut senders, _) = team(false);
    let frames: Vec<Vec<u8>> = senders
        .iter_mut()
        .flat_map(|s| {
            publish(s, Instant::from_micros(1000), 1);
            std::iter::from_fn(|| s.poll_transmit().map(|t| t.payload)).collect::<Vec<_>>()
        })
        .collect();
    group.bench_function("decode only", |b| {
        b.iter(|| {
            for f in &frames {
                black_box(decode_frame(black_box(f), 7, None).unwrap());
            }
        })
    });
    group.finish();
}

fn print_world_model_size() {
    for keyed in [false, true] {
        let mut cfg = ReplicaConfig::new(3, 7);
        if keyed {
            cfg = cfg.with_team_key(KEY);
        }
        let mut r = Replica::new(cfg, 0x5eed_5eed_5eed_5eed, Instant::ZERO).unwrap();
        r.handle_timeout(Instant::ZERO);
        while r.poll_transmit().is_some() {}
        // Ten minutes into a match at 30 Hz: the version and frame seq are multi-byte.
        let mut now = Instant::ZERO;
        for tick in 0..18_000 {
            now += Duration::from_micros(33_333);
            r.set(now, "*.var.world.local", world_model(3, tick))
                .unwrap();
            while r.poll_transmit().is_some() {}
        }
        r.set(now, "*.var.world.local", world_model(3, 18_000))
            .unwrap();
        let frame = r.poll_transmit().unwrap().payload;
        assert!(decode_frame(&frame, 7, keyed.then(|| TeamKey::new(KEY)).as_ref()).is_ok());
        println!(
            "wire size of one robot's local world model frame ({WORLD_MODEL_LEN}-byte model, {}): {} bytes (SPL limit 128)",
            if keyed { "with 16-byte HMAC tag" } else { "no team key" },
            frame.len()
        );
    }
}

/// CPU time of the calling thread, in nanoseconds.
struct ThreadCpu;

#[cfg(target_os = "linux")]
fn thread_cpu_ns() -> u64 {
    use nix::time::{clock_gettime, ClockId};
    let ts = clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID)
        .expect("clock_gettime(CLOCK_THREAD_CPUTIME_ID) failed");
    ts.tv_sec() as u64 * 1_000_000_000 + ts.tv_nsec() as u64
}

#[cfg(not(target_os = "linux"))]
#[allow(clippy::disallowed_methods)] // a bench measures time; the library never does
fn thread_cpu_ns() -> u64 {
    // No portable thread CPU clock: fall back to wall time elsewhere.
    use std::sync::OnceLock;
    static START: OnceLock<std::time::Instant> = OnceLock::new();
    START
        .get_or_init(std::time::Instant::now)
        .elapsed()
        .as_nanos() as u64
}

impl Measurement for ThreadCpu {
    type Intermediate = u64;
    type Value = u64;
    fn start(&self) -> u64 {
        thread_cpu_ns()
    }
    fn end(&self, start: u64) -> u64 {
        thread_cpu_ns().saturating_sub(start)
    }
    fn add(&self, a: &u64, b: &u64) -> u64 {
        a + b
    }
    fn zero(&self) -> u64 {
        0
    }
    fn to_f64(&self, v: &u64) -> f64 {
        *v as f64
    }
    fn formatter(&self) -> &dyn ValueFormatter {
        &CpuFormatter
    }
}

struct CpuFormatter;

impl ValueFormatter for CpuFormatter {
    fn scale_values(&self, typical_ns: f64, values: &mut [f64]) -> &'static str {
        let (div, unit) = match typical_ns {
            t if t < 1e3 => (1.0, "ns cpu"),
            t if t < 1e6 => (1e3, "µs cpu"),
            _ => (1e6, "ms cpu"),
        };
        values.iter_mut().for_each(|v| *v /= div);
        unit
    }

    fn scale_throughputs(
        &self,
        typical_ns: f64,
        throughput: &Throughput,
        values: &mut [f64],
    ) -> &'static str {
        let per_iter = match throughput {
            Throughput::Elements(n) | Throughput::Bytes(n) | Throughput::BytesDecimal(n) => {
                *n as f64
            }
            _ => 1.0,
        };
        let typical = per_iter * 1e9 / typical_ns;
        let (div, unit) = if typical >= 1e6 {
            (1e6, "Melem/s per core")
        } else {
            (1e3, "Kelem/s per core")
        };
        values
            .iter_mut()
            .for_each(|v| *v = per_iter * 1e9 / *v / div);
        unit
    }

    fn scale_for_machines(&self, _values: &mut [f64]) -> &'static str {
        "ns"
    }
}

criterion_group!(wall, bench_wall);
criterion_group! {
    name = cpu;
    config = Criterion::default().with_measurement(ThreadCpu);
    targets = bench_cpu
}
criterion_main!(wall, cpu);
