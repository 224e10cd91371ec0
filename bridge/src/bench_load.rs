//! The load phase of `huddle-bridge bench` with pre-encoded field traffic
//! ([`crate::loadgen`]): one thread replays the robots' frames on a scratch group at their
//! times, a bridge (a child process: its CPU is its own) mirrors them into Zenoh, and a
//! lean subscriber (an atomic counter and the last value per key) counts on the Zenoh
//! side. Daemons are not in the picture: on a 2-core machine their runtimes, timers and
//! sockets starved the bridge they were meant to load (docs/bridge.md).

// A benchmark on real sockets: it reads the clock and sleeps.
#![allow(clippy::disallowed_methods)]

use std::sync::atomic::{AtomicI64, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant as StdInstant};

use anyhow::{Context, Result};
use zenoh::Wait;

use crate::bench::{bridge_stats, cpu_ticks, load_average, BenchArgs, TEAM};
use crate::loadgen;

const VENUE: &str = "bench-load";

/// What the lean subscriber keeps.
struct Lean {
    samples: AtomicU64,
    /// The last value of robot r's key j at `(r - 1) * per + j`.
    last: Vec<AtomicI64>,
    per: usize,
}

impl Lean {
    fn record(&self, key: &str, payload: &[u8]) {
        self.samples.fetch_add(1, Ordering::Relaxed);
        // huddle/@v1/bench-load/7/<robot>/var/load/k<j>
        let mut chunks = key.split('/').skip(4);
        let robot: Option<usize> = chunks.next().and_then(|r| r.parse().ok());
        let j: Option<usize> = chunks
            .nth(2)
            .and_then(|k| k.strip_prefix('k'))
            .and_then(|j| j.parse().ok());
        let value: Option<i64> = std::str::from_utf8(payload)
            .ok()
            .and_then(|p| p.parse().ok());
        if let (Some(r), Some(j), Some(v)) = (robot, j, value) {
            if let Some(slot) = r
                .checked_sub(1)
                .and_then(|r| self.last.get(r * self.per + j))
            {
                slot.fetch_max(v, Ordering::Relaxed);
            }
        }
    }
}

/// One second of the load phase, stage by stage: the bridge's counters (`@bridge/stats`,
/// fetched by a monitor thread once a second), the subscriber's count and the CPU.
#[derive(Clone, Debug, Default)]
struct Stage {
    datagrams: u64,
    applied: u64,
    values_out: u64,
    coalesced: u64,
    puts: u64,
    put_us: u64,
    batches: u64,
    received: u64,
    bridge_ticks: u64,
    own_ticks: u64,
}

impl Stage {
    fn now(session: &zenoh::Session, lean: &Lean, pid: u32) -> Option<Stage> {
        let s = bridge_stats(session, VENUE)?;
        let n = |v: &serde_json::Value| v.as_u64().unwrap_or(0);
        Some(Stage {
            datagrams: n(&s["field"]["datagrams"]),
            applied: n(&s["field"]["updates_applied"]),
            values_out: n(&s["export"]["values_out"]),
            coalesced: n(&s["export"]["coalesced"]),
            puts: n(&s["zenoh"]["puts"]),
            put_us: n(&s["zenoh"]["put_us"]),
            batches: n(&s["timing_us"]["inline_puts"]) + n(&s["timing_us"]["handed_over"]),
            received: lean.samples.load(Ordering::Relaxed),
            bridge_ticks: cpu_ticks(pid).unwrap_or(0),
            own_ticks: cpu_ticks(std::process::id()).unwrap_or(0),
        })
    }

    fn minus(&self, o: &Stage) -> Stage {
        Stage {
            datagrams: self.datagrams - o.datagrams,
            applied: self.applied - o.applied,
            values_out: self.values_out - o.values_out,
            coalesced: self.coalesced - o.coalesced,
            puts: self.puts - o.puts,
            put_us: self.put_us - o.put_us,
            batches: self.batches - o.batches,
            received: self.received - o.received,
            bridge_ticks: self.bridge_ticks.saturating_sub(o.bridge_ticks),
            own_ticks: self.own_ticks.saturating_sub(o.own_ticks),
        }
    }
}

/// Samples [`Stage`] once a second until `stop`; returns the samples with their times.
fn monitor(
    session: zenoh::Session,
    lean: Arc<Lean>,
    pid: u32,
    stop: Arc<std::sync::atomic::AtomicBool>,
) -> std::thread::JoinHandle<Vec<(StdInstant, Stage)>> {
    std::thread::spawn(move || {
        let mut out = Vec::new();
        let mut next = StdInstant::now();
        while !stop.load(Ordering::Relaxed) {
            if let Some(s) = Stage::now(&session, &lean, pid) {
                out.push((StdInstant::now(), s));
            }
            next += Duration::from_secs(1);
            std::thread::sleep(next.saturating_duration_since(StdInstant::now()));
        }
        out
    })
}

/// Prints the per-second stages between consecutive samples.
fn print_stages(samples: &[(StdInstant, Stage)]) {
    println!(
        "  per second, stage by stage (bridge: datagrams in, updates applied, values out of the exporter, merged in the outbox, puts Zenoh accepted, time inside puts, put batches; subscriber: samples received; CPU cores):"
    );
    println!(
        "    {:>5} {:>9} {:>9} {:>9} {:>9} {:>9} {:>8} {:>8} {:>9} {:>6} {:>6}",
        "s",
        "datagrams",
        "applied",
        "out",
        "merged",
        "puts",
        "put ms",
        "batches",
        "received",
        "bridge",
        "bench"
    );
    for w in samples.windows(2) {
        let dt = (w[1].0 - w[0].0).as_secs_f64().max(1e-3);
        let d = w[1].1.minus(&w[0].1);
        let r = |x: u64| (x as f64 / dt).round() as u64;
        println!(
            "    {:>5.1} {:>9} {:>9} {:>9} {:>9} {:>9} {:>8.0} {:>8} {:>9} {:>6.2} {:>6.2}",
            (w[1].0 - samples[0].0).as_secs_f64(),
            r(d.datagrams),
            r(d.applied),
            r(d.values_out),
            r(d.coalesced),
            r(d.puts),
            d.put_us as f64 / 1e3 / dt,
            r(d.batches),
            r(d.received),
            d.bridge_ticks as f64 / 100.0 / dt,
            d.own_ticks as f64 / 100.0 / dt,
        );
    }
}

/// Runs the load phase; `raw_rate` is the same run's plain-Zenoh baseline (samples/s).
pub fn run(args: &BenchArgs, port: u16, session: &zenoh::Session, raw_rate: f64) -> Result<()> {
    let t = StdInstant::now();
    let traffic = loadgen::generate(TEAM, args.daemons, args.keys, args.rate, args.seconds);
    println!(
        "load (pre-encoded frames, one sender): {} keys at {} Hz from {} robots for {} s: {} datagrams, {} updates, encoded in {:.1} s",
        args.keys,
        args.rate,
        traffic.robots.len(),
        args.seconds,
        traffic.frames.len(),
        traffic.updates,
        t.elapsed().as_secs_f64()
    );
    let per = traffic.robots.iter().map(|(_, n)| *n).max().unwrap_or(0);
    let lean = Arc::new(Lean {
        samples: AtomicU64::new(0),
        last: (0..per * traffic.robots.len())
            .map(|_| AtomicI64::new(i64::MIN))
            .collect(),
        per,
    });
    let _sub = {
        let lean = lean.clone();
        session
            .declare_subscriber(format!("huddle/@v1/{VENUE}/{TEAM}/*/var/load/*"))
            .callback(move |s| lean.record(s.key_expr().as_str(), &s.payload().to_bytes()))
            .wait()
            .map_err(|e| anyhow::anyhow!("subscribe: {e}"))?
    };
    let group = driver::scratch_group()?;
    let extra: Vec<&str> = args.load_bridge_arg.iter().map(String::as_str).collect();
    let mut bridge =
        crate::bench::spawn_bridge(args, &std::env::current_exe()?, VENUE, group, port, &extra)
            .context("starting the load bridge")?;
    let result = replay(args, session, &traffic, &lean, group, bridge.id(), raw_rate);
    let _ = bridge.kill();
    let _ = bridge.wait();
    result
}

fn replay(
    args: &BenchArgs,
    session: &zenoh::Session,
    traffic: &loadgen::Traffic,
    lean: &Arc<Lean>,
    group: std::net::SocketAddrV4,
    pid: u32,
    raw_rate: f64,
) -> Result<()> {
    // The bridge is up when its token is on the router.
    let up = StdInstant::now();
    loop {
        let alive = session
            .liveliness()
            .get(format!("huddle/@v1/{VENUE}/{TEAM}/@bridge/alive"))
            .wait()
            .ok()
            .and_then(|r| r.recv_timeout(Duration::from_secs(2)).ok().flatten())
            .is_some_and(|reply| reply.result().is_ok());
        if alive {
            break;
        }
        anyhow::ensure!(
            up.elapsed() < Duration::from_secs(20),
            "the load bridge did not come up"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let cfg = driver::SocketConfig {
        group,
        ..driver::SocketConfig::default()
    };
    let socket = driver::open(&cfg)?.socket;
    socket.set_nonblocking(false)?;
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let stages = monitor(session.clone(), lean.clone(), pid, stop.clone());
    let warm_up = Duration::from_secs(1);
    let t0 = StdInstant::now();
    let mut window: Option<(StdInstant, u64, Option<u64>, Option<u64>)> = None;
    let mut per_second = Vec::new();
    let mut next_second = t0 + warm_up + Duration::from_secs(1);
    let mut second_mark = 0u64;
    let mut late_max = Duration::ZERO;
    let mut send_errors = 0u64;
    for f in &traffic.frames {
        let due = t0 + f.at;
        let now = StdInstant::now();
        if due > now {
            std::thread::sleep(due - now);
        } else {
            late_max = late_max.max(now - due);
        }
        if window.is_none() && f.at >= warm_up {
            let n = lean.samples.load(Ordering::Relaxed);
            second_mark = n;
            window = Some((
                StdInstant::now(),
                n,
                cpu_ticks(pid),
                cpu_ticks(std::process::id()),
            ));
        }
        if window.is_some() && StdInstant::now() >= next_second {
            let n = lean.samples.load(Ordering::Relaxed);
            per_second.push(n - second_mark);
            second_mark = n;
            next_second += Duration::from_secs(1);
        }
        if socket.send_to(&f.bytes, group).is_err() {
            send_errors += 1;
        }
    }
    let end = StdInstant::now();
    let (start, n0, bridge0, own0) = window.context("no frame after the warm-up")?;
    let bridge1 = cpu_ticks(pid);
    let own1 = cpu_ticks(std::process::id());
    let secs = (end - start).as_secs_f64();
    // Wait (an event, generous timeout) for every final value, then count.
    let wait = StdInstant::now();
    let missing = || {
        lean.last
            .iter()
            .enumerate()
            .filter(|(i, v)| {
                let r = i / lean.per;
                let j = i % lean.per;
                traffic.robots.get(r).is_some_and(|(_, n)| j < *n)
                    && v.load(Ordering::Relaxed) != traffic.final_value
            })
            .count()
    };
    while missing() > 0 && wait.elapsed() < Duration::from_secs(10) {
        std::thread::sleep(Duration::from_millis(10));
    }
    stop.store(true, Ordering::Relaxed);
    let stages = stages.join().unwrap_or_default();
    let n1 = lean.samples.load(Ordering::Relaxed);
    let received_in_window = n1 - n0;
    let offered = traffic.updates as f64 / (args.seconds as f64);
    println!(
        "  sender: offered {offered:.0} updates/s over {secs:.1} s (late by up to {:.1} ms; {send_errors} send errors)",
        late_max.as_secs_f64() * 1e3
    );
    let baseline = if raw_rate.is_finite() {
        format!(
            " ({:.2}x the baseline's {raw_rate:.0}/s)",
            received_in_window as f64 / secs / raw_rate.max(1.0)
        )
    } else {
        String::new()
    };
    println!(
        "  received {:.0} samples/s{baseline}; per second: {per_second:?}",
        received_in_window as f64 / secs,
    );
    println!(
        "  keys whose final value did not arrive: {} of {} (waited {:.1} s after the last frame)",
        missing(),
        args.keys,
        wait.elapsed().as_secs_f64()
    );
    print_stages(&stages);
    let stats = bridge_stats(session, VENUE);
    let bridge_cores = bridge0
        .zip(bridge1)
        .map(|(a, b)| (b - a) as f64 / 100.0 / secs);
    if let Some(cores) = bridge_cores {
        // CPU seconds per second over updates per second.
        let per_update = cores / offered.max(1.0);
        println!(
            "  bridge CPU: {cores:.2} cores (target < 1); {:.2} us of CPU per update offered, i.e. about {:.0} k updates/s per core",
            per_update * 1e6,
            1e-3 / per_update.max(1e-12)
        );
    }
    if let (Some(a), Some(b)) = (own0, own1) {
        println!(
            "  this process (router, lean subscriber, sender): {:.2} cores; load average {}",
            (b - a) as f64 / 100.0 / secs,
            load_average()
        );
    }
    if let Some(s) = stats {
        println!(
            "  @bridge/stats: datagrams {}, updates applied {}, values out {}, coalesced {}, puts {} ({} ms inside), outbox high water {}, timing_us {}",
            s["field"]["datagrams"],
            s["field"]["updates_applied"],
            s["export"]["values_out"],
            s["export"]["coalesced"],
            s["zenoh"]["puts"],
            s["zenoh"]["put_us"].as_u64().unwrap_or(0) / 1000,
            s["export"]["outbox_high_water"],
            s["timing_us"]
        );
    }
    Ok(())
}
