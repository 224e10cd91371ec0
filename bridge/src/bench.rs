//! `huddle-bridge bench`: the bridge measured on loopback against baselines from the
//! same run. A Zenoh router and a subscriber run in this process, daemons run
//! in-process on a scratch group ([`crate::harness`]), and the bridge is a child
//! process (this binary, started as `huddle-bridge --team … --connect …`) so that its
//! CPU time is its own.
//!
//! Printed, in order:
//! 1. first sample: from the bridge's start to the first sample at the subscriber;
//! 2. one Zenoh hop (client → router → client) and set → teammate watch, the baselines;
//!    set → Zenoh sample through the bridge; and the latency the bridge adds, per set:
//!    (set → sample) − (set → teammate watch), p50 / p99;
//! 3. load: first the baseline, a plain Zenoh client putting the same keys as fast as
//!    blocking congestion control lets it, to the same subscriber, for `--seconds`: what
//!    this machine's Zenoh path carries; then `--keys` keys at `--rate` Hz from
//!    `--daemons` daemons for `--seconds` through the bridge: updates/s offered, samples
//!    received (and their ratio to the baseline), values merged in the bridge's outbox,
//!    whether every key's final value arrived, and the bridge's CPU (cores).

// A benchmark on real sockets: it reads the clock and sleeps.
#![allow(clippy::disallowed_methods)]

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant as StdInstant};

use anyhow::{bail, Context, Result};
use clap::Args;
use comms::Value;
use driver::Notice;
use zenoh::qos::CongestionControl;
use zenoh::Wait;

use crate::harness::{client, free_port, router, Daemon, DaemonSpec};

/// `huddle-bridge bench` flags.
#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    /// Latency samples (one set every 4 ms).
    #[arg(long, default_value_t = 500)]
    pub samples: usize,
    /// Keys of the load phase, shared among the daemons.
    #[arg(long, default_value_t = 1000)]
    pub keys: usize,
    /// Rate of every key in the load phase, Hz.
    #[arg(long, default_value_t = 100)]
    pub rate: u32,
    /// Daemons of the load phase.
    #[arg(long, default_value_t = 4)]
    pub daemons: u8,
    /// Length of the load phase, seconds.
    #[arg(long, default_value_t = 10)]
    pub seconds: u64,
    /// Also run a second bridge with `--no-fast-path` (every put handed to the publisher
    /// thread), to compare the two paths in the same run.
    #[arg(long)]
    pub compare_fast_path: bool,
    /// Also compare Zenoh configurations a venue could choose (tx batching off, the
    /// lowlatency transport, a direct peer link, UDP when built with `--features udp`)
    /// and the bridge's field loop, each beside one hop under the same configuration,
    /// interleaved ([`crate::bench_variants`]).
    #[arg(long)]
    pub compare_zenoh: bool,
    /// A Zenoh setting `PATH=JSON` (repeatable) for the main router, subscriber,
    /// publisher and every bridge of the first-sample, latency and load phases:
    /// `--zenoh-set transport/unicast/lowlatency=true --zenoh-set
    /// transport/unicast/qos/enabled=false` runs them all on the lowlatency transport.
    #[arg(long, value_name = "PATH=JSON", value_parser = parse_setting)]
    pub zenoh_set: Vec<(String, String)>,
    /// With `--zenoh-set`: the subscriber session keeps Zenoh's defaults (a router that
    /// offers the lowlatency transport to the bridge, to readers that do not ask).
    #[arg(long)]
    pub zenoh_subscriber_default: bool,
    /// The bridges' `--zenoh-config` file, written from `--zenoh-set`.
    #[arg(skip)]
    pub zenoh_file: Option<std::path::PathBuf>,
    /// Where the load phase's field traffic comes from: pre-encoded frames replayed by
    /// one sender (the robots' replicas run ahead of time), or live daemons.
    #[arg(long, value_enum, default_value_t = LoadFrom::Frames)]
    pub load_from: LoadFrom,
    /// Only the load phase with pre-encoded frames (no first sample, latency or
    /// baseline): for tracing the load phase quickly.
    #[arg(long)]
    pub load_only: bool,
    /// An extra argument for the load phase's bridge (repeatable), e.g.
    /// `--load-bridge-arg=--put-via=string`.
    #[arg(long, allow_hyphen_values = true)]
    pub load_bridge_arg: Vec<String>,
}

/// `--load-from`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum LoadFrom {
    /// Pre-encoded frames from one sender thread ([`crate::loadgen`]).
    Frames,
    /// Daemons in this process (their runtimes compete with the bridge for the CPU).
    Daemons,
}

fn parse_setting(s: &str) -> Result<(String, String), String> {
    let (path, value) = s
        .split_once('=')
        .ok_or_else(|| format!("{s:?}: expected PATH=JSON"))?;
    serde_json::from_str::<serde_json::Value>(value)
        .map_err(|e| format!("{s:?}: the value is not JSON: {e}"))?;
    Ok((path.to_owned(), value.to_owned()))
}

/// The 1-minute load average, as /proc/loadavg says.
pub fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .unwrap_or_default()
        .split_whitespace()
        .next()
        .unwrap_or("?")
        .to_owned()
}

/// The bench's team.
pub const TEAM: u8 = 7;
const VENUE: &str = "bench";
/// The venue of the `--compare-fast-path` bridge (`--no-fast-path`).
const VENUE_FAST: &str = "bench-handover";

/// What the subscriber saw.
#[derive(Default)]
struct Seen {
    first: Option<StdInstant>,
    samples: u64,
    /// The latency key's arrivals, by value.
    lat: HashMap<i64, StdInstant>,
    /// The same through the `--compare-fast-path` bridge (`--no-fast-path`).
    lat_fast: HashMap<i64, StdInstant>,
    /// The hop key's arrivals, by value.
    hop: HashMap<i64, StdInstant>,
    /// The express hop key's arrivals, by value.
    hop_express: HashMap<i64, StdInstant>,
    /// Samples of the raw throughput baseline.
    raw: u64,
    /// The last payload of every key.
    last: HashMap<String, String>,
}

/// Runs the bench and prints its figures.
pub fn run(args: &BenchArgs) -> Result<()> {
    if args.daemons == 0 || args.keys == 0 || args.rate == 0 {
        bail!("--daemons, --keys and --rate must be positive");
    }
    let mut args = args.clone();
    let args = &mut args;
    let settings: Vec<(&str, &str)> = args
        .zenoh_set
        .iter()
        .map(|(k, v)| (k.as_str(), v.as_str()))
        .collect();
    let settings = &settings[..];
    if !settings.is_empty() {
        let path =
            std::env::temp_dir().join(format!("huddle-bridge-bench-{}.json5", std::process::id()));
        crate::bench_variants::write_config(&path, settings)?;
        println!("zenoh settings of every session and bridge: {settings:?}");
        args.zenoh_file = Some(path);
    }
    let result = run_with(args, settings);
    if let Some(path) = &args.zenoh_file {
        let _ = std::fs::remove_file(path);
    }
    result
}

fn run_with(args: &BenchArgs, settings: &[(&str, &str)]) -> Result<()> {
    let port = free_port()?;
    let _router = router(port, settings).map_err(|e| anyhow::anyhow!("router: {e}"))?;
    let group = driver::scratch_group()?;
    let seen = Arc::new(Mutex::new(Seen::default()));
    let sub_settings = if args.zenoh_subscriber_default {
        &[][..]
    } else {
        settings
    };
    let sub_session = client(port, sub_settings).map_err(|e| anyhow::anyhow!("subscriber: {e}"))?;
    if args.load_only {
        return crate::bench_load::run(args, port, &sub_session, f64::NAN);
    }
    let lat_key = format!("huddle/@v1/{VENUE}/{TEAM}/1/var/lat");
    let _sub = {
        let seen = seen.clone();
        let lat_key = lat_key.clone();
        sub_session
            .declare_subscriber(format!("huddle/@v1/{VENUE}/{TEAM}/**"))
            .callback(move |s| {
                let t = StdInstant::now();
                let key = s.key_expr().as_str();
                let payload = s.payload().try_to_string().unwrap_or_default().into_owned();
                let mut seen = seen.lock().unwrap_or_else(|p| p.into_inner());
                seen.first.get_or_insert(t);
                seen.samples += 1;
                if key == lat_key {
                    if let Ok(i) = payload.parse() {
                        seen.lat.insert(i, t);
                    }
                }
                seen.last.insert(key.to_owned(), payload);
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("subscribe: {e}"))?
    };
    let _handover_sub = {
        let seen = seen.clone();
        sub_session
            .declare_subscriber(format!("huddle/@v1/{VENUE_FAST}/{TEAM}/1/var/lat"))
            .callback(move |s| {
                let t = StdInstant::now();
                let payload = s.payload().try_to_string().unwrap_or_default().into_owned();
                if let Ok(i) = payload.parse() {
                    let mut seen = seen.lock().unwrap_or_else(|p| p.into_inner());
                    seen.lat_fast.insert(i, t);
                }
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("subscribe: {e}"))?
    };
    let _hop_sub = {
        let seen = seen.clone();
        sub_session
            .declare_subscriber("bench_hop/**")
            .callback(move |s| {
                let t = StdInstant::now();
                let key = s.key_expr().as_str();
                let mut seen = seen.lock().unwrap_or_else(|p| p.into_inner());
                if key.starts_with("bench_hop/raw") {
                    // The same work per sample as the bridge's samples get.
                    let payload = s.payload().try_to_string().unwrap_or_default().into_owned();
                    seen.raw += 1;
                    seen.last.insert(key.to_owned(), payload);
                    return;
                }
                let i = s
                    .payload()
                    .try_to_string()
                    .ok()
                    .and_then(|p| p.parse().ok());
                if let Some(i) = i {
                    if key == "bench_hop/express" {
                        seen.hop_express.insert(i, t);
                    } else {
                        seen.hop.insert(i, t);
                    }
                }
            })
            .wait()
            .map_err(|e| anyhow::anyhow!("subscribe: {e}"))?
    };

    let mut daemons = Vec::new();
    for id in 1..=args.daemons.max(2) {
        daemons.push(Daemon::start(DaemonSpec::new(id, TEAM, group))?);
    }
    for d in &daemons {
        d.set("*.var.up", Value::Int(1));
    }
    std::thread::sleep(Duration::from_millis(300));

    // 1. First sample after the bridge starts.
    let exe = std::env::current_exe()?;
    let started = StdInstant::now();
    let mut child =
        spawn_bridge(args, &exe, VENUE, group, port, &[]).context("starting the bridge")?;
    let pid = child.id();
    let mut handover = if args.compare_fast_path {
        Some(
            spawn_bridge(args, &exe, VENUE_FAST, group, port, &["--no-fast-path"])
                .context("starting the second bridge")?,
        )
    } else {
        None
    };
    let result = measure(
        args,
        settings,
        &daemons,
        &seen,
        &sub_session,
        port,
        started,
        pid,
        &lat_key,
    );
    for c in std::iter::once(&mut child).chain(handover.as_mut()) {
        let _ = c.kill();
        let _ = c.wait();
    }
    let raw_rate = result?;
    drop(daemons);
    if args.compare_zenoh {
        crate::bench_variants::run(args)?;
    }
    if args.load_from == LoadFrom::Frames {
        crate::bench_load::run(args, port, &sub_session, raw_rate)?;
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn measure(
    args: &BenchArgs,
    settings: &[(&str, &str)],
    daemons: &[Daemon],
    seen: &Arc<Mutex<Seen>>,
    sub_session: &zenoh::Session,
    port: u16,
    started: StdInstant,
    pid: u32,
    lat_key: &str,
) -> Result<f64> {
    let lock = || seen.lock().unwrap_or_else(|p| p.into_inner());
    let deadline = started + Duration::from_secs(10);
    let first = loop {
        if let Some(t) = lock().first {
            break t;
        }
        if StdInstant::now() > deadline {
            bail!("no sample within 10 s of the bridge's start");
        }
        std::thread::sleep(Duration::from_millis(1));
    };
    println!("huddle-bridge bench (loopback, same run)");
    println!(
        "first sample after the bridge started: {:.0} ms (target <= 1000 ms)",
        ms(first - started)
    );

    // 2. Baselines and latency.
    let publisher = client(port, settings).map_err(|e| anyhow::anyhow!("publisher: {e}"))?;
    let mut hop_sent = HashMap::new();
    for i in 0..args.samples as i64 {
        hop_sent.insert(i, StdInstant::now());
        let _ = publisher.put("bench_hop/x", i.to_string()).wait();
        std::thread::sleep(Duration::from_millis(2));
    }
    // The bridge puts a lone value express with blocking congestion control: the same
    // hop, as the bridge takes it.
    let mut express_sent = HashMap::new();
    for i in 0..args.samples as i64 {
        express_sent.insert(i, StdInstant::now());
        let _ = publisher
            .put("bench_hop/express", i.to_string())
            .congestion_control(CongestionControl::Block)
            .express(true)
            .wait();
        std::thread::sleep(Duration::from_millis(2));
    }
    let set_at: Arc<Mutex<HashMap<i64, StdInstant>>> = Arc::default();
    let watched = watch_arrivals(&daemons[1], "1.var.lat");
    std::thread::sleep(Duration::from_millis(50));
    for i in 0..args.samples as i64 {
        let set_at = set_at.clone();
        daemons[0].run(move |h| {
            let t = StdInstant::now();
            let _ = h.set("*.var.lat", Value::Int(i));
            set_at
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .insert(i, t);
            None
        });
        std::thread::sleep(Duration::from_millis(4));
    }
    std::thread::sleep(Duration::from_millis(300));
    let (hop, hop_express): (Vec<Duration>, Vec<Duration>) = {
        let s = lock();
        let arrivals = |sent: &HashMap<i64, StdInstant>, got: &HashMap<i64, StdInstant>| {
            sent.iter()
                .filter_map(|(i, t)| got.get(i).map(|r| r.saturating_duration_since(*t)))
                .collect()
        };
        (
            arrivals(&hop_sent, &s.hop),
            arrivals(&express_sent, &s.hop_express),
        )
    };
    let (to_watch, to_zenoh, added) = {
        let s = lock();
        let set_at = set_at.lock().unwrap_or_else(|p| p.into_inner());
        let watched = watched.lock().unwrap_or_else(|p| p.into_inner());
        let mut to_watch = Vec::new();
        let mut to_zenoh = Vec::new();
        let mut added = Vec::new();
        for (i, t) in set_at.iter() {
            let w = watched.get(i).map(|w| w.saturating_duration_since(*t));
            let z = s.lat.get(i).map(|z| z.saturating_duration_since(*t));
            if let Some(w) = w {
                to_watch.push(w);
            }
            if let Some(z) = z {
                to_zenoh.push(z);
            }
            if let (Some(w), Some(z)) = (w, z) {
                added.push(z.as_secs_f64() - w.as_secs_f64());
            }
        }
        (to_watch, to_zenoh, added)
    };
    println!(
        "latency over {} sets (received: watch {}, zenoh {}):",
        args.samples,
        to_watch.len(),
        to_zenoh.len()
    );
    print_row("  one zenoh hop (client->router->client)", &hop);
    print_row(
        "  the same hop, express + block (as the bridge)",
        &hop_express,
    );
    print_row("  set -> teammate watch", &to_watch);
    print_row("  set -> zenoh sample via the bridge", &to_zenoh);
    let mut added_sorted = added;
    added_sorted.sort_by(f64::total_cmp);
    println!(
        "  added by the bridge (per set: zenoh - watch): p50 {:.3} ms  p99 {:.3} ms  (targets 0.25 / 1 ms; floor: one zenoh hop p50 {:.3} ms)",
        quantile_f(&added_sorted, 0.5) * 1e3,
        quantile_f(&added_sorted, 0.99) * 1e3,
        quantile(&sorted(&hop), 0.5).as_secs_f64() * 1e3,
    );
    let _ = lat_key;
    if args.compare_fast_path {
        let s = lock();
        let watched = watched.lock().unwrap_or_else(|p| p.into_inner());
        let set_at = set_at.lock().unwrap_or_else(|p| p.into_inner());
        let mut added: Vec<f64> = set_at
            .iter()
            .filter_map(|(i, t)| {
                let w = watched.get(i)?.saturating_duration_since(*t);
                let z = s.lat_fast.get(i)?.saturating_duration_since(*t);
                Some(z.as_secs_f64() - w.as_secs_f64())
            })
            .collect();
        added.sort_by(f64::total_cmp);
        println!(
            "  added by a second bridge with --no-fast-path (same run, n={}): p50 {:.3} ms  p99 {:.3} ms",
            added.len(),
            quantile_f(&added, 0.5) * 1e3,
            quantile_f(&added, 0.99) * 1e3,
        );
    }
    let venues: &[(&str, &str)] = if args.compare_fast_path {
        &[(VENUE, "default"), (VENUE_FAST, "--no-fast-path")]
    } else {
        &[(VENUE, "default")]
    };
    for (venue, name) in venues {
        if let Some(stats) = bridge_stats(sub_session, venue) {
            let t = &stats["timing_us"];
            println!(
                "  inside the bridge ({name}), p50/p99 us: datagram -> queued {}/{}, queued -> put {}/{}, put {}/{} ({} fast-path batches, {} handed over)",
                t["field"]["p50"], t["field"]["p99"], t["handoff"]["p50"], t["handoff"]["p99"],
                t["put"]["p50"], t["put"]["p99"], t["inline_puts"], t["handed_over"]
            );
        }
    }
    println!(
        "  load average {}",
        std::fs::read_to_string("/proc/loadavg")
            .unwrap_or_default()
            .split_whitespace()
            .take(3)
            .collect::<Vec<_>>()
            .join(" ")
    );

    // 3. Load. The baseline: a plain client puts the same number of keys round-robin,
    // as fast as blocking congestion control lets it, for the same time.
    let raw_before = lock().raw;
    let own_before = cpu_ticks(std::process::id());
    let raw_t0 = StdInstant::now();
    let raw_keys: Vec<String> = (0..args.keys)
        .map(|j| format!("bench_hop/raw/k{j}"))
        .collect();
    let mut raw_put = 0u64;
    while raw_t0.elapsed() < Duration::from_secs(args.seconds) {
        for key in &raw_keys {
            let _ = publisher
                .put(key.as_str(), raw_put.to_string())
                .congestion_control(CongestionControl::Block)
                .wait();
            raw_put += 1;
        }
    }
    let raw_secs = raw_t0.elapsed().as_secs_f64();
    let own_raw = cpu_ticks(std::process::id())
        .zip(own_before)
        .map(|(b, a)| (b - a) as f64 / 100.0 / raw_secs);
    std::thread::sleep(Duration::from_millis(500));
    let raw_got = lock().raw - raw_before;
    println!(
        "load baseline: a zenoh client putting {} keys round-robin (block) to the same subscriber for {:.1} s: put {:.0}/s, received {:.0}/s",
        args.keys,
        raw_secs,
        raw_put as f64 / raw_secs,
        raw_got as f64 / raw_secs
    );
    if let Some(cores) = own_raw {
        println!("  this process (router, publisher, subscriber): {cores:.2} cores");
    }
    let raw_rate = raw_got as f64 / raw_secs;
    if args.load_from == LoadFrom::Frames {
        return Ok(raw_rate);
    }

    let n = daemons.len().min(args.daemons as usize);
    let per = args.keys.div_ceil(n);
    let period = Duration::from_secs_f64(1.0 / f64::from(args.rate));
    let ticks = args.seconds * u64::from(args.rate);
    let (done_tx, done_rx) = std::sync::mpsc::channel::<(u8, u64)>();
    let before_samples = lock().samples;
    let cpu_before = cpu_ticks(pid);
    let own_before = cpu_ticks(std::process::id());
    let t0 = StdInstant::now();
    let mut offered = 0u64;
    for (k, d) in daemons.iter().take(n).enumerate() {
        let count = per.min(args.keys.saturating_sub(k * per));
        offered += count as u64 * ticks;
        let keys: Vec<String> = (0..count).map(|j| format!("*.var.load.k{j}")).collect();
        let done = done_tx.clone();
        let id = d.id;
        d.run(move |h| {
            let h = h.clone();
            tokio::task::spawn_local(async move {
                let mut interval = tokio::time::interval(period);
                interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Burst);
                for tick in 1..=ticks {
                    interval.tick().await;
                    h.batch(|b| {
                        for key in &keys {
                            let _ = b.set(key, Value::Int(tick as i64));
                        }
                    });
                }
                let _ = done.send((id, ticks));
            });
            None
        });
    }
    drop(done_tx);
    let finished: Vec<(u8, u64)> = done_rx.iter().collect();
    let elapsed = t0.elapsed();
    let cpu_after = cpu_ticks(pid);
    let own_after = cpu_ticks(std::process::id());
    std::thread::sleep(Duration::from_millis(1500));
    let (received, missing) = {
        let s = lock();
        let received = s.samples - before_samples;
        let mut missing = 0;
        for (k, (id, last)) in finished.iter().enumerate() {
            let count = per.min(args.keys.saturating_sub(k * per));
            for j in 0..count {
                let key = format!("huddle/@v1/{VENUE}/{TEAM}/{id}/var/load/k{j}");
                if s.last.get(&key).map(String::as_str) != Some(last.to_string().as_str()) {
                    missing += 1;
                }
            }
        }
        (received, missing)
    };
    let secs = elapsed.as_secs_f64();
    println!(
        "load: {} keys at {} Hz from {} daemons for {:.1} s",
        args.keys, args.rate, n, secs
    );
    println!(
        "  offered {:.0} updates/s, samples received {:.0}/s ({:.1}% of offered, {:.2}x the baseline's), keys whose final value did not arrive: {} of {}",
        offered as f64 / secs,
        received as f64 / secs,
        100.0 * received as f64 / offered.max(1) as f64,
        received as f64 / secs / raw_rate.max(1.0),
        missing,
        args.keys
    );
    if missing > 0 {
        // What a subscriber following the protocol does when the bridge's token appears
        // again (a link closed): get the prefix.
        let mut recovered = 0;
        if let Ok(replies) = sub_session
            .get(format!("huddle/@v1/{VENUE}/{TEAM}/*/var/load/**"))
            .wait()
        {
            let mut s = lock();
            while let Ok(Some(reply)) = replies.recv_timeout(Duration::from_secs(5)) {
                if let Ok(sample) = reply.into_result() {
                    let payload = sample.payload().try_to_string().unwrap_or_default();
                    s.last
                        .insert(sample.key_expr().as_str().to_owned(), payload.into_owned());
                }
            }
            for (k, (id, last)) in finished.iter().enumerate() {
                let count = per.min(args.keys.saturating_sub(k * per));
                for j in 0..count {
                    let key = format!("huddle/@v1/{VENUE}/{TEAM}/{id}/var/load/k{j}");
                    if s.last.get(&key).map(String::as_str) == Some(last.to_string().as_str()) {
                        recovered += 1;
                    }
                }
            }
        }
        println!(
            "  after one get of the prefix (the protocol's recovery): {} of {} keys hold their final value",
            recovered, args.keys
        );
    }
    match (cpu_before, cpu_after) {
        (Some(a), Some(b)) => println!(
            "  bridge CPU: {:.2} cores (target < 1)",
            (b - a) as f64 / 100.0 / secs
        ),
        _ => println!("  bridge CPU: /proc/{pid}/stat unreadable"),
    }
    if let (Some(a), Some(b)) = (own_before, own_after) {
        println!(
            "  this process (router, subscriber, {n} daemons): {:.2} cores; load average {}",
            (b - a) as f64 / 100.0 / secs,
            std::fs::read_to_string("/proc/loadavg")
                .unwrap_or_default()
                .split_whitespace()
                .next()
                .unwrap_or("?")
        );
    }
    if let Some(stats) = bridge_stats(sub_session, VENUE) {
        println!("  @bridge/stats: {stats}");
    }
    Ok(raw_rate)
}

/// The bridge's `@bridge/stats` of `venue`.
pub fn bridge_stats(session: &zenoh::Session, venue: &str) -> Option<serde_json::Value> {
    session
        .get(format!("huddle/@v1/{venue}/{TEAM}/@bridge/stats"))
        .wait()
        .ok()
        .and_then(|replies| replies.recv_timeout(Duration::from_secs(2)).ok().flatten())
        .and_then(|reply| reply.into_result().ok())
        .and_then(|sample| serde_json::from_slice(&sample.payload().to_bytes()).ok())
}

/// utime + stime of `pid`, in clock ticks (100 per second on Linux).
pub fn cpu_ticks(pid: u32) -> Option<u64> {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    // The command name may hold spaces: fields start after the last ')'.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let utime: u64 = fields.get(11)?.parse().ok()?;
    let stime: u64 = fields.get(12)?.parse().ok()?;
    Some(utime + stime)
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

fn sorted(v: &[Duration]) -> Vec<Duration> {
    let mut v = v.to_vec();
    v.sort();
    v
}

fn quantile(sorted: &[Duration], q: f64) -> Duration {
    if sorted.is_empty() {
        return Duration::ZERO;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn quantile_f(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

fn print_row(name: &str, v: &[Duration]) {
    let s = sorted(v);
    println!(
        "{name:<44} p50 {:.3} ms  p99 {:.3} ms  (n={})",
        ms(quantile(&s, 0.5)),
        ms(quantile(&s, 0.99)),
        s.len()
    );
}

/// Starts this binary as a bridge for the bench's team in `venue`, on the scratch `group`
/// over loopback, connected to the bench's router on `port`; `extra` flags added, and
/// `--zenoh-set`'s settings.
pub(crate) fn spawn_bridge(
    args: &BenchArgs,
    exe: &std::path::Path,
    venue: &str,
    group: impl std::fmt::Display,
    port: u16,
    extra: &[&str],
) -> std::io::Result<std::process::Child> {
    std::process::Command::new(exe)
        .args(["--team", &TEAM.to_string(), "--venue", venue, "--group"])
        .arg(group.to_string())
        .args(["--iface", "127.0.0.1"])
        .args(extra)
        .args(
            args.zenoh_file
                .iter()
                .flat_map(|f| [std::ffi::OsStr::new("--zenoh-config"), f.as_os_str()]),
        )
        .arg("--connect")
        .arg(format!("tcp/127.0.0.1:{port}"))
        .env("RUST_LOG", "warn")
        .spawn()
}

/// When each value of the integer key `key` (a sample's number) reached `daemon`'s program:
/// the teammate's side of a latency figure.
pub(crate) fn watch_arrivals(
    daemon: &Daemon,
    key: &'static str,
) -> Arc<Mutex<HashMap<i64, StdInstant>>> {
    let watched: Arc<Mutex<HashMap<i64, StdInstant>>> = Arc::default();
    let arrivals = watched.clone();
    daemon.run(move |h| {
        h.watch(key, move |_, notice| {
            let t = StdInstant::now();
            if let Notice::Changed { entry, .. } = notice {
                if let Value::Int(i) = entry.value {
                    arrivals
                        .lock()
                        .unwrap_or_else(|p| p.into_inner())
                        .insert(i, t);
                }
            }
        })
        .ok()
    });
    watched
}
