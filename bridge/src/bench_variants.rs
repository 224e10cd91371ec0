//! `huddle-bridge bench --compare-zenoh`: the latency the bridge adds under each Zenoh
//! configuration a venue could choose, each beside its own floor measured with the same
//! configuration: one Zenoh hop as the bridge takes it (express, blocking) and the
//! bridge's own stages (`@bridge/stats`).
//!
//! Every variant has its own rig, all up at once: a router in this process (none for a
//! direct peer link), a subscriber, a hop publisher, two daemons on a scratch group of
//! their own and a bridge child process configured as the variant says. Idle rigs carry
//! only their daemons' refreshes (which the bridges do not forward). The samples are
//! taken in blocks, round-robin over the variants (`--samples / BLOCK` rounds), so a
//! change of the machine's load falls on every variant alike.

// A benchmark on real sockets: it reads the clock and sleeps.
#![allow(clippy::disallowed_methods)]

use std::collections::HashMap;
use std::path::PathBuf;
use std::process::Child;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant as StdInstant};

use anyhow::{anyhow, Result};
use comms::Value;
use zenoh::qos::CongestionControl;
use zenoh::Wait;

use crate::bench::{bridge_stats, load_average, watch_arrivals, BenchArgs, TEAM};
use crate::harness::{free_port, Daemon, DaemonSpec};

/// Sets (and hops) per variant per round.
const BLOCK: usize = 50;

/// How the bridge reaches the subscriber.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Topology {
    /// Bridge (client) → router → subscriber (client), as a venue has it.
    Router,
    /// Bridge (peer) → subscriber (peer listening): no router.
    PeerDirect,
}

/// One configuration under test.
struct Variant {
    name: &'static str,
    /// Settings on every Zenoh session of the rig (router, subscriber, hop publisher,
    /// bridge), as `(path, JSON value)`.
    zenoh: &'static [(&'static str, &'static str)],
    /// The link protocol of the hop: `tcp` or `udp`.
    link: &'static str,
    topology: Topology,
    /// Further flags of the bridge.
    bridge_args: &'static [&'static str],
    /// The subscriber keeps Zenoh's defaults (the settings are the router's, the
    /// bridge's and the hop publisher's): a venue router that offers the lowlatency
    /// transport to the bridges that ask, while readers do not.
    subscriber_default: bool,
}

const LOWLATENCY: &[(&str, &str)] = &[
    ("transport/unicast/lowlatency", "true"),
    ("transport/unicast/qos/enabled", "false"),
];
const NO_GOSSIP: &[(&str, &str)] = &[("scouting/gossip/enabled", "false")];
const NO_GOSSIP_LOWLATENCY: &[(&str, &str)] = &[
    ("scouting/gossip/enabled", "false"),
    ("transport/unicast/lowlatency", "true"),
    ("transport/unicast/qos/enabled", "false"),
];

fn variants(args: &BenchArgs) -> Vec<Variant> {
    let mut v = vec![
        Variant {
            name: "tcp, router, zenoh defaults (the default)",
            zenoh: &[],
            link: "tcp",
            topology: Topology::Router,
            bridge_args: &[],
            subscriber_default: false,
        },
        Variant {
            name: "  the same, --field-loop thread",
            zenoh: &[],
            link: "tcp",
            topology: Topology::Router,
            bridge_args: &["--field-loop", "thread"],
            subscriber_default: false,
        },
        Variant {
            name: "tcp, router, tx batching off",
            zenoh: &[("transport/link/tx/queue/batching/enabled", "false")],
            link: "tcp",
            topology: Topology::Router,
            bridge_args: &[],
            subscriber_default: false,
        },
        Variant {
            name: "tcp, router, lowlatency + qos off",
            zenoh: LOWLATENCY,
            link: "tcp",
            topology: Topology::Router,
            bridge_args: &[],
            subscriber_default: false,
        },
        Variant {
            name: "  the same, --field-loop tx-runtime",
            zenoh: LOWLATENCY,
            link: "tcp",
            topology: Topology::Router,
            bridge_args: &["--field-loop", "tx-runtime"],
            subscriber_default: false,
        },
        Variant {
            name: "  the same, subscriber on zenoh defaults",
            zenoh: LOWLATENCY,
            link: "tcp",
            topology: Topology::Router,
            bridge_args: &[],
            subscriber_default: true,
        },
        Variant {
            name: "tcp, peer direct (no router)",
            zenoh: NO_GOSSIP,
            link: "tcp",
            topology: Topology::PeerDirect,
            bridge_args: &[],
            subscriber_default: false,
        },
        Variant {
            name: "tcp, peer direct, lowlatency + qos off",
            zenoh: NO_GOSSIP_LOWLATENCY,
            link: "tcp",
            topology: Topology::PeerDirect,
            bridge_args: &[],
            subscriber_default: false,
        },
    ];
    if args.compare_fast_path {
        v.insert(
            1,
            Variant {
                name: "  the same, --no-fast-path",
                zenoh: &[],
                link: "tcp",
                topology: Topology::Router,
                bridge_args: &["--no-fast-path"],
                subscriber_default: false,
            },
        );
    }
    if cfg!(feature = "udp") {
        v.push(Variant {
            name: "udp, router, zenoh defaults",
            zenoh: &[],
            link: "udp",
            topology: Topology::Router,
            bridge_args: &[],
            subscriber_default: false,
        });
    }
    v
}

/// Arrival times at a rig's subscriber, by value.
#[derive(Default)]
struct Arrivals {
    first: Option<StdInstant>,
    hop: HashMap<i64, StdInstant>,
    lat: HashMap<i64, StdInstant>,
}

/// One variant's sessions, daemons and bridge.
struct Rig {
    variant: Variant,
    venue: String,
    hop_key: String,
    publisher: zenoh::Session,
    sub: zenoh::Session,
    _subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
    _router: Option<zenoh::Session>,
    daemons: Vec<Daemon>,
    bridge: Child,
    config_file: PathBuf,
    arrivals: Arc<Mutex<Arrivals>>,
    hop_sent: HashMap<i64, StdInstant>,
    set_at: Arc<Mutex<HashMap<i64, StdInstant>>>,
    watched: Arc<Mutex<HashMap<i64, StdInstant>>>,
}

impl Drop for Rig {
    fn drop(&mut self) {
        let _ = self.bridge.kill();
        let _ = self.bridge.wait();
        let _ = std::fs::remove_file(&self.config_file);
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// A Zenoh configuration: `mode`, endpoints, scouting off, then the variant's settings.
fn session_config(
    mode: &str,
    endpoints: &[(&str, String)],
    settings: &[(&str, &str)],
) -> zenoh::Result<zenoh::Config> {
    let mut cfg = zenoh::Config::default();
    cfg.insert_json5("mode", &format!("\"{mode}\""))?;
    cfg.insert_json5("scouting/multicast/enabled", "false")?;
    for (path, endpoint) in endpoints {
        cfg.insert_json5(path, &format!("[\"{endpoint}\"]"))?;
    }
    for (k, v) in settings {
        cfg.insert_json5(k, v)?;
    }
    Ok(cfg)
}

/// The variant's settings as a JSON5 file for the bridge's `--zenoh-config`.
pub(crate) fn write_config(path: &std::path::Path, settings: &[(&str, &str)]) -> Result<()> {
    let mut root = serde_json::Map::new();
    for (k, v) in settings {
        let chunks: Vec<&str> = k.split('/').collect();
        let mut node = &mut root;
        for c in &chunks[..chunks.len() - 1] {
            node = node
                .entry(c.to_string())
                .or_insert_with(|| serde_json::Value::Object(Default::default()))
                .as_object_mut()
                .ok_or_else(|| anyhow!("{k}: not an object"))?;
        }
        node.insert(
            chunks[chunks.len() - 1].to_owned(),
            serde_json::from_str(v)?,
        );
    }
    std::fs::write(path, serde_json::to_string_pretty(&root)?)?;
    Ok(())
}

impl Rig {
    fn start(index: usize, variant: Variant, exe: &std::path::Path) -> Result<Rig> {
        let venue = format!("bench-v{index}");
        let port = free_port()?;
        let endpoint = format!("{}/127.0.0.1:{port}", variant.link);
        let s = variant.zenoh;
        let zerr = |what: &str| {
            let what = what.to_owned();
            move |e: zenoh::Error| anyhow!("{what}: {e}")
        };
        // With a router: it listens, everyone connects. A direct link: the subscriber
        // listens, the publisher and the bridge connect to it as peers.
        let (router, sub_cfg, pub_cfg, mode) = match variant.topology {
            Topology::Router => {
                let router_cfg =
                    session_config("router", &[("listen/endpoints", endpoint.clone())], s)
                        .map_err(zerr("router config"))?;
                let router = zenoh::open(router_cfg).wait().map_err(zerr("router"))?;
                let client =
                    session_config("client", &[("connect/endpoints", endpoint.clone())], s)
                        .map_err(zerr("client config"))?;
                let sub = if variant.subscriber_default {
                    session_config("client", &[("connect/endpoints", endpoint.clone())], &[])
                        .map_err(zerr("subscriber config"))?
                } else {
                    client.clone()
                };
                (Some(router), sub, client, "client")
            }
            Topology::PeerDirect => {
                let sub = session_config("peer", &[("listen/endpoints", endpoint.clone())], s)
                    .map_err(zerr("subscriber config"))?;
                let publ = session_config("peer", &[("connect/endpoints", endpoint.clone())], s)
                    .map_err(zerr("publisher config"))?;
                (None, sub, publ, "peer")
            }
        };
        let sub = zenoh::open(sub_cfg).wait().map_err(zerr("subscriber"))?;
        let publisher = zenoh::open(pub_cfg).wait().map_err(zerr("publisher"))?;
        let arrivals: Arc<Mutex<Arrivals>> = Arc::default();
        let hop_key = format!("bench_hop/v{index}");
        let lat_key = format!("huddle/@v1/{venue}/{TEAM}/1/var/lat");
        // Two subscribers: `**` never matches the verbatim chunk `@v1`.
        let mut subscribers = Vec::new();
        for expr in [hop_key.clone(), format!("huddle/@v1/{venue}/{TEAM}/**")] {
            let arrivals = arrivals.clone();
            let hop_key = hop_key.clone();
            let lat_key = lat_key.clone();
            subscribers.push(
                sub.declare_subscriber(expr)
                    .callback(move |sample| {
                        let t = StdInstant::now();
                        let key = sample.key_expr().as_str();
                        let i: Option<i64> = sample
                            .payload()
                            .try_to_string()
                            .ok()
                            .and_then(|p| p.parse().ok());
                        let mut a = lock(&arrivals);
                        if key == hop_key {
                            if let Some(i) = i {
                                a.hop.insert(i, t);
                            }
                            return;
                        }
                        a.first.get_or_insert(t);
                        if key == lat_key {
                            if let Some(i) = i {
                                a.lat.insert(i, t);
                            }
                        }
                    })
                    .wait()
                    .map_err(zerr("subscribe"))?,
            );
        }
        let group = driver::scratch_group()?;
        let mut daemons = Vec::new();
        for id in 1..=2 {
            let d = Daemon::start(DaemonSpec::new(id, TEAM, group))?;
            d.set("*.var.up", Value::Int(1));
            daemons.push(d);
        }
        let config_file = std::env::temp_dir().join(format!(
            "huddle-bridge-bench-{}-v{index}.json5",
            std::process::id()
        ));
        write_config(&config_file, s)?;
        let bridge = std::process::Command::new(exe)
            .args(["--team", &TEAM.to_string(), "--venue", &venue, "--group"])
            .arg(group.to_string())
            .args([
                "--iface",
                "127.0.0.1",
                "--mode",
                mode,
                "--connect",
                &endpoint,
            ])
            .arg("--zenoh-config")
            .arg(&config_file)
            .args(variant.bridge_args)
            .env("RUST_LOG", "warn")
            .spawn()?;
        let watched = watch_arrivals(&daemons[1], "1.var.lat");
        Ok(Rig {
            variant,
            venue,
            hop_key,
            publisher,
            sub,
            _subscribers: subscribers,
            _router: router,
            daemons,
            bridge,
            config_file,
            arrivals,
            hop_sent: HashMap::new(),
            set_at: Arc::default(),
            watched,
        })
    }

    /// Waits for the bridge's first sample (its session is up and routed).
    fn ready(&self, deadline: StdInstant) -> bool {
        while StdInstant::now() < deadline {
            if lock(&self.arrivals).first.is_some() {
                return true;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        false
    }

    /// One block: `n` hops as the bridge puts (express, blocking), then `n` sets.
    fn block(&mut self, next: &mut i64, n: usize) {
        for _ in 0..n {
            let i = *next;
            *next += 1;
            self.hop_sent.insert(i, StdInstant::now());
            let _ = self
                .publisher
                .put(self.hop_key.as_str(), i.to_string())
                .congestion_control(CongestionControl::Block)
                .express(true)
                .wait();
            std::thread::sleep(Duration::from_millis(2));
        }
        for _ in 0..n {
            let i = *next;
            *next += 1;
            let set_at = self.set_at.clone();
            self.daemons[0].run(move |h| {
                let t = StdInstant::now();
                let _ = h.set("*.var.lat", Value::Int(i));
                lock(&set_at).insert(i, t);
                None
            });
            std::thread::sleep(Duration::from_millis(4));
        }
        std::thread::sleep(Duration::from_millis(30));
    }
}

/// The unit of every floor: a datagram on loopback to a thread blocked in `recv` (the
/// kernel wakes it; no runtime, no Zenoh). A hop through a router is about four of these
/// (publisher's transmit task, router's receive and transmit, subscriber's receive) plus
/// two TCP segments; the bridge's path adds its own wake-up on the datagram.
struct Wake {
    socket: std::net::UdpSocket,
    to: std::net::SocketAddr,
    sent: Vec<StdInstant>,
    got: Arc<Mutex<Vec<(usize, StdInstant)>>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Wake {
    fn start() -> Result<Wake> {
        let receiver = std::net::UdpSocket::bind("127.0.0.1:0")?;
        let to = receiver.local_addr()?;
        let got: Arc<Mutex<Vec<(usize, StdInstant)>>> = Arc::default();
        let thread = {
            let got = got.clone();
            std::thread::spawn(move || {
                let mut buf = [0u8; 16];
                // Ends at the empty datagram (or an error).
                while let Ok(n) = receiver.recv(&mut buf) {
                    let t = StdInstant::now();
                    if n != 8 {
                        break;
                    }
                    let i = u64::from_le_bytes(buf[..8].try_into().unwrap_or([0; 8]));
                    lock(&got).push((i as usize, t));
                }
            })
        };
        Ok(Wake {
            socket: std::net::UdpSocket::bind("127.0.0.1:0")?,
            to,
            sent: Vec::new(),
            got,
            thread: Some(thread),
        })
    }

    fn block(&mut self, n: usize) {
        for _ in 0..n {
            let i = self.sent.len() as u64;
            self.sent.push(StdInstant::now());
            let _ = self.socket.send_to(&i.to_le_bytes(), self.to);
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// p50 and p99 (ms) and the count.
    fn finish(mut self) -> (f64, f64, usize) {
        let _ = self.socket.send_to(&[], self.to);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        let got = lock(&self.got);
        p50_p99(
            got.iter()
                .filter_map(|(i, t)| {
                    Some(
                        t.saturating_duration_since(*self.sent.get(*i)?)
                            .as_secs_f64(),
                    )
                })
                .collect(),
        )
    }
}

fn quantile(sorted: &[f64], q: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    sorted[((sorted.len() - 1) as f64 * q).round() as usize]
}

/// p50 and p99 in ms of durations in seconds.
fn p50_p99(mut v: Vec<f64>) -> (f64, f64, usize) {
    v.sort_by(f64::total_cmp);
    (quantile(&v, 0.5) * 1e3, quantile(&v, 0.99) * 1e3, v.len())
}

/// Runs the comparison and prints its table.
pub fn run(args: &BenchArgs) -> Result<()> {
    let exe = std::env::current_exe()?;
    let mut rigs = Vec::new();
    println!(
        "zenoh configurations, interleaved in blocks of {BLOCK} (load average {}):",
        load_average()
    );
    for (index, variant) in variants(args).into_iter().enumerate() {
        let name = variant.name;
        match Rig::start(index, variant, &exe) {
            Ok(rig) if rig.ready(StdInstant::now() + Duration::from_secs(10)) => rigs.push(rig),
            Ok(_) => println!("  {name}: no sample within 10 s of the bridge's start; left out"),
            Err(e) => println!("  {name}: could not start ({e:#}); left out"),
        }
    }
    if rigs.is_empty() {
        return Err(anyhow!("no variant started"));
    }
    std::thread::sleep(Duration::from_millis(200));
    let rounds = args.samples.div_ceil(BLOCK).max(1);
    let mut next = 0i64;
    let mut wake = Wake::start()?;
    for _ in 0..rounds {
        wake.block(BLOCK);
        for rig in &mut rigs {
            rig.block(&mut next, BLOCK);
        }
    }
    std::thread::sleep(Duration::from_millis(300));
    let wakes = wake.finish();
    println!(
        "  one wake-up: a loopback datagram to a thread blocked in recv, p50 {:.3} ms  p99 {:.3} ms  (n={})",
        wakes.0, wakes.1, wakes.2
    );
    println!(
        "  {:<42} {:>15} {:>15} {:>15} {:>14} {:>9} {:>7}",
        "variant (p50 / p99 ms)",
        "hop (as bridge)",
        "set -> watch",
        "added",
        "bridge: q, put",
        "floor p50",
        "over"
    );
    for rig in &rigs {
        let a = lock(&rig.arrivals);
        let hop = p50_p99(
            rig.hop_sent
                .iter()
                .filter_map(|(i, t)| {
                    Some(a.hop.get(i)?.saturating_duration_since(*t).as_secs_f64())
                })
                .collect(),
        );
        let set_at = lock(&rig.set_at);
        let watched = lock(&rig.watched);
        let mut to_watch = Vec::new();
        let mut added = Vec::new();
        for (i, t) in set_at.iter() {
            let w = watched
                .get(i)
                .map(|w| w.saturating_duration_since(*t).as_secs_f64());
            if let Some(w) = w {
                to_watch.push(w);
            }
            if let (Some(w), Some(z)) = (w, a.lat.get(i)) {
                added.push(z.saturating_duration_since(*t).as_secs_f64() - w);
            }
        }
        let watch = p50_p99(to_watch);
        let added = p50_p99(added);
        let inside = bridge_stats(&rig.sub, &rig.venue).map(|stats| {
            let t = &stats["timing_us"];
            (
                t["field"]["p50"].as_f64().unwrap_or(f64::NAN),
                t["put"]["p50"].as_f64().unwrap_or(f64::NAN),
            )
        });
        let (q, put) = inside.unwrap_or((f64::NAN, f64::NAN));
        // The hop's time includes its publisher's put call, so the bridge's own put is
        // not added again: on a busy machine a put that wakes the next thread is
        // descheduled for that thread's work, which the hop already holds.
        let floor = hop.0 + q / 1e3;
        println!(
            "  {:<42} {:>6.3} / {:<6.3} {:>6.3} / {:<6.3} {:>6.3} / {:<6.3} {:>6.0}, {:<6.0} {:>9.3} {:>+7.3}   (n={}/{})",
            rig.variant.name,
            hop.0,
            hop.1,
            watch.0,
            watch.1,
            added.0,
            added.1,
            q,
            put,
            floor,
            added.0 - floor,
            hop.2,
            added.2,
        );
    }
    println!(
        "  (hop: one put, express + block, client -> router -> client or peer -> peer; added: per set, set -> sample minus set -> teammate watch; bridge: its datagram -> queued and put, p50 us, @bridge/stats; floor = hop + q: the bridge's put is inside the hop, whose publisher puts too; over = added - floor) load average {}",
        load_average()
    );
    Ok(())
}
