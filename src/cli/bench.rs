//! `huddle bench comms`: the daemon's costs measured on loopback multicast, in one run.
//!
//! (a) raw UDP multicast ping-pong between two threads (std blocking sockets), and
//! (b) ping-pong through two replicas over the real driver, each on its own thread and
//! current-thread runtime (set on A → visible on B → B sets a reply → visible on A; by
//! default both robots' software reacts with `Handle::watch`, `--reply subscribe` uses
//! tasks awaiting subscriptions instead):
//! p50/p99 of each and their ratio; (c) sustained updates/s from A to B with the loss
//! rate; (d) resident memory of a spawned daemon holding 10,000 keys.
//! Everything sends on loopback only (IP_MULTICAST_IF 127.0.0.1, TTL 1). `--transport
//! broadcast` runs (a)–(c) over broadcast to 127.255.255.255 instead, `--transport
//! unicast` between 127.0.0.1 and 127.0.0.2 (each robot's only peer is the other), the
//! baselines on the same transport.

use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use comms::{Key, ReplicaConfig, Value};
use driver::{Driver, DriverConfig, Handle, Notice, SocketConfig, Transport};
use huddle::summary::percentile;
use nix::sched::{sched_setaffinity, CpuSet};
use nix::unistd::Pid;
use serde::Serialize;

use super::relay::RelayClient;
use super::transport::TransportKind;

/// `huddle bench ...`
#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub what: BenchWhat,
}

/// What to measure.
#[derive(Subcommand, Debug)]
pub enum BenchWhat {
    /// Latency, throughput and memory of the multicast driver and daemon.
    Comms(CommsArgs),
}

/// `huddle bench comms`
#[derive(Args, Debug)]
pub struct CommsArgs {
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// Ping-pong round trips per measurement, split into interleaved blocks of raw,
    /// bare tokio and huddle (each block after its own warm-up).
    #[arg(long, default_value_t = 5000, value_parser = at_least_one)]
    pub rounds: usize,
    /// CPU pinning of the two ends of every ping-pong (the same for all three): `none`,
    /// `same` (both ends on CPU 0) or `split` (pinger on CPU 0, ponger on CPU 1).
    #[arg(long, default_value = "none")]
    pub pin: Pin,
    /// How both robots' software reacts in the huddle ping-pong: `watch` (reactions run
    /// inside the driver's turn, `Handle::watch`) or `subscribe` (tasks awaiting
    /// subscriptions, a task wake-up per notice).
    #[arg(long, default_value = "watch")]
    pub reply: Reply,
    /// Updates sent A → B in the throughput run.
    #[arg(long, default_value_t = 2_000_000, value_parser = clap::value_parser!(u64).range(1..))]
    pub updates: u64,
    /// First of the four UDP ports used (each test its own group and port).
    #[arg(long, default_value_t = 38900)]
    pub port: u16,
    /// The transport of the ping-pongs (raw, tokio and huddle alike) and the throughput
    /// run, on loopback: multicast, broadcast (127.255.255.255) or unicast (127.0.0.1 ↔
    /// 127.0.0.2).
    #[arg(long, value_enum, default_value_t = TransportKind::Multicast)]
    pub transport: TransportKind,
    /// Also write every ping-pong round trip to this file as CSV (`what,block,index,
    /// start_us,rtt_us,start_mono_us`; `start_us` from the start of the run,
    /// `start_mono_us` on CLOCK_MONOTONIC, as `perf --clockid monotonic` stamps), to see
    /// what the slow ones have in common.
    #[arg(long, value_name = "FILE")]
    pub dump_rtts: Option<std::path::PathBuf>,
    /// A/A: run the bare-tokio ping-pong a second time in every block, after huddle's,
    /// and report it against the first (`aa` in the JSON): how far apart the p50 and
    /// p99 of two identical systems land in one run.
    #[arg(long)]
    pub aa: bool,
}

/// A count of at least one (no measurement is made of nothing).
fn at_least_one(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(0) => Err("0 measures nothing: give at least 1".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(format!("{s:?} is not a count: {e}")),
    }
}

/// Where the two ends of a ping-pong run.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Pin {
    /// Wherever the scheduler puts them.
    None,
    /// Both on CPU 0.
    Same,
    /// Pinger on CPU 0, ponger on CPU 1.
    Split,
}

impl Pin {
    /// Pins the calling thread as end `end` (0: pinger, 1: ponger). Best effort: a
    /// refusal leaves the thread unpinned.
    fn apply(self, end: usize) {
        let cpu = match self {
            Pin::None => return,
            Pin::Same => 0,
            Pin::Split => end,
        };
        let mut set = CpuSet::new();
        // Pid 0 is the calling thread.
        let pinned = set
            .set(cpu)
            .and_then(|()| sched_setaffinity(Pid::from_raw(0), &set));
        if let Err(e) = pinned {
            tracing::warn!(cpu, "cannot pin the thread ({e}); it runs unpinned");
        }
    }
}

/// How the robots' software in the ping-pong receives a value and answers.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Reply {
    /// `Handle::watch`: a reaction on the driver's task.
    Watch,
    /// `Handle::subscribe`: a task awaiting notices.
    Subscribe,
}

/// The figures, as `--json` prints them.
#[derive(Serialize, Debug)]
pub struct CommsReport {
    pub raw_p50_us: f64,
    pub raw_p99_us: f64,
    pub tokio_p50_us: f64,
    pub tokio_p99_us: f64,
    pub huddle_p50_us: f64,
    pub huddle_p99_us: f64,
    pub p50_ratio: f64,
    pub p99_ratio: f64,
    pub tokio_p50_ratio: f64,
    pub pin: Pin,
    pub reply: Reply,
    pub transport: &'static str,
    pub updates_per_s: f64,
    pub updates_sent: u64,
    pub updates_applied: u64,
    pub frame_loss: f64,
    pub update_loss: f64,
    pub frames_sent: u64,
    pub frames_received: u64,
    pub rss_mb_10k_keys: f64,
    pub recv_buffer_bytes: usize,
    pub build: &'static str,
    /// With `--aa`: the second bare-tokio ping-pong against the first.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub aa: Option<AaReport>,
}

/// Bare tokio against itself in the same run (`--aa`): the noise of the ratios.
#[derive(Serialize, Debug)]
pub struct AaReport {
    pub tokio_b_p50_us: f64,
    pub tokio_b_p99_us: f64,
    pub p50_b_over_a: f64,
    pub p99_b_over_a: f64,
}

fn group(port: u16, last: u8) -> SocketAddrV4 {
    SocketAddrV4::new(Ipv4Addr::new(239, 255, 39, last), port)
}

/// Robot `id`'s loopback address with the unicast transport: 127.0.0.<id>.
fn unicast_iface(id: u8) -> Ipv4Addr {
    Ipv4Addr::new(127, 0, 0, id)
}

/// The socket of robot `id` (1 or 2) on `transport`, on loopback; for unicast, the
/// other robot is its one peer.
fn socket_config(id: u8, g: SocketAddrV4, transport: Transport) -> SocketConfig {
    SocketConfig {
        transport,
        group: g,
        iface: match transport {
            Transport::Unicast => unicast_iface(id),
            _ => Ipv4Addr::LOCALHOST,
        },
        ..SocketConfig::default()
    }
}

/// The two ends of a raw ping-pong on `transport`: each one's blocking socket (with
/// the driver's socket options) and where it sends.
fn raw_ends(g: SocketAddrV4, transport: Transport) -> Result<[(UdpSocket, SocketAddr); 2]> {
    let end = |id: u8| -> Result<(UdpSocket, SocketAddr)> {
        let opened = driver::open(&socket_config(id, g, transport))?;
        let to = match opened.destination {
            Some(to) => SocketAddr::V4(to),
            None => SocketAddr::from((unicast_iface(3 - id), g.port())),
        };
        let s = opened.socket;
        s.set_nonblocking(false)?;
        s.set_read_timeout(Some(Duration::from_secs(2)))?;
        Ok((s, to))
    };
    Ok([end(1)?, end(2)?])
}

/// Round trips as measured: each one's start and its length in µs.
type Rtts = Vec<(Instant, f64)>;

/// p50 and p99 in microseconds of round trips.
fn summarize(mut v: Vec<f64>) -> (f64, f64) {
    v.sort_by(|a, b| a.total_cmp(b));
    let at = |p| percentile(&v, p).expect("at least one round trip was measured");
    (at(0.5), at(0.99))
}

/// Round trips not recorded at the start of every block (caches, branch predictors,
/// the scheduler's idea of the threads).
const WARM_UP_ROUNDS: usize = 200;

/// The ping-pong's datagrams: `P` and the round number (u64 LE) out, the same with `R`
/// back, `Q` to stop the ponger. Both baselines speak it.
fn ping(round: u64) -> [u8; 9] {
    let mut msg = [0u8; 9];
    msg[0] = b'P';
    msg[1..].copy_from_slice(&round.to_le_bytes());
    msg
}

/// Whether `datagram` is the reply to `ping` (the pinger also hears its own pings looped
/// back, and late replies to earlier rounds).
fn is_reply(datagram: &[u8], ping: &[u8; 9]) -> bool {
    datagram.len() == 9 && datagram[0] == b'R' && datagram[1..] == ping[1..]
}

/// What the ponger does with a datagram it heard.
enum Echo {
    /// Send it back (it has been turned into the reply).
    Reply,
    /// Stop.
    Quit,
    /// Its own reply, looped back: nothing.
    Ignore,
}

fn echo(datagram: &mut [u8]) -> Echo {
    match datagram.first() {
        Some(b'P') => {
            datagram[0] = b'R';
            Echo::Reply
        }
        Some(b'Q') => Echo::Quit,
        _ => Echo::Ignore,
    }
}

/// (a): two threads, blocking sockets on one group and port; each skips its own echoes.
fn raw_ping_pong(g: SocketAddrV4, rounds: usize, pin: Pin, transport: Transport) -> Result<Rtts> {
    let [(a, to), (b, back)] = raw_ends(g, transport)?;
    let ponger = named_thread("raw-pong", move || -> Result<()> {
        pin.apply(1);
        let mut buf = [0u8; 64];
        loop {
            let (n, _) = b.recv_from(&mut buf)?;
            match echo(&mut buf[..n]) {
                Echo::Reply => {
                    b.send_to(&buf[..n], back)?;
                }
                Echo::Quit => return Ok(()),
                Echo::Ignore => {}
            }
        }
    });
    // The pinger runs on a thread of its own too, as in the other two measurements.
    let pinger = named_thread("raw-ping", move || -> Result<Rtts> {
        pin.apply(0);
        let mut rtts = Vec::with_capacity(rounds);
        let mut buf = [0u8; 64];
        for i in 0..(WARM_UP_ROUNDS + rounds) as u64 {
            let msg = ping(i);
            let t0 = Instant::now();
            a.send_to(&msg, to)?;
            loop {
                let (n, _) = a.recv_from(&mut buf).context("raw ping-pong: no reply")?;
                if is_reply(&buf[..n], &msg) {
                    break;
                }
            }
            rtts.push((t0, t0.elapsed().as_secs_f64() * 1e6));
        }
        a.send_to(b"Q", to)?;
        Ok(rtts.split_off(WARM_UP_ROUNDS))
    });
    let rtts = pinger.join().expect("pinger thread")?;
    ponger.join().expect("ponger thread")?;
    Ok(rtts)
}

/// Spawns `f` on a thread called `name`: what `/proc/<pid>/task/*/comm` shows, so that the
/// context switches of each ping-pong's threads can be told apart while it runs.
fn named_thread<T: Send + 'static>(
    name: &str,
    f: impl FnOnce() -> T + Send + 'static,
) -> std::thread::JoinHandle<T> {
    std::thread::Builder::new()
        .name(name.to_owned())
        .spawn(f)
        .expect("a thread for the bench")
}

/// Runs `f` on its own thread (pinned as `end`) inside a current-thread runtime and
/// LocalSet, as the driver runs.
fn on_runtime_thread<T: Send + 'static, F, Fut>(
    pin: Pin,
    end: usize,
    f: F,
) -> std::thread::JoinHandle<Result<T>>
where
    F: FnOnce() -> Fut + Send + 'static,
    Fut: std::future::Future<Output = Result<T>>,
{
    named_thread(["tokio-ping", "tokio-pong"][end.min(1)], move || {
        pin.apply(end);
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        tokio::task::LocalSet::new().block_on(&rt, f())
    })
}

/// (a'): the raw ping-pong over tokio sockets, same socket options, threads and runtime
/// set-up as the replicas: the floor that "the cost of tokio" sets for (b).
fn tokio_ping_pong(g: SocketAddrV4, rounds: usize, pin: Pin, transport: Transport) -> Result<Rtts> {
    let [(a, to), (b, back)] = raw_ends(g, transport)?;
    a.set_nonblocking(true)?;
    b.set_nonblocking(true)?;
    let ponger = on_runtime_thread(pin, 1, move || async move {
        let b = tokio::net::UdpSocket::from_std(b)?;
        let mut buf = [0u8; 64];
        loop {
            let (n, _) = b.recv_from(&mut buf).await?;
            match echo(&mut buf[..n]) {
                Echo::Reply => {
                    b.send_to(&buf[..n], back).await?;
                }
                Echo::Quit => return Ok(()),
                Echo::Ignore => {}
            }
        }
    });
    let pinger = on_runtime_thread(pin, 0, move || async move {
        let a = tokio::net::UdpSocket::from_std(a)?;
        let mut rtts = Vec::with_capacity(rounds);
        let mut buf = [0u8; 64];
        for i in 0..(WARM_UP_ROUNDS + rounds) as u64 {
            let msg = ping(i);
            let t0 = Instant::now();
            a.send_to(&msg, to).await?;
            let reply = tokio::time::timeout(Duration::from_secs(2), async {
                loop {
                    let (n, _) = a.recv_from(&mut buf).await?;
                    if is_reply(&buf[..n], &msg) {
                        return Ok::<_, std::io::Error>(());
                    }
                }
            });
            reply
                .await
                .context("tokio ping-pong: no reply within 2 s")??;
            rtts.push((t0, t0.elapsed().as_secs_f64() * 1e6));
        }
        a.send_to(b"Q", to).await?;
        Ok(rtts.split_off(WARM_UP_ROUNDS))
    });
    let rtts = pinger.join().expect("pinger thread")?;
    ponger.join().expect("ponger thread")?;
    Ok(rtts)
}

/// Runs `f` with a driver for robot `id` on its own thread and current-thread runtime;
/// the driver stops when `f` returns.
///
/// The driver is the thread's main future, as in `huddle daemon` (and as the bare-tokio
/// ping-pong's loop is): a datagram wakes it directly. The robot's software (`f`) is a
/// task beside it.
fn on_driver_thread<T: Send + 'static, F, Fut>(
    id: u8,
    (g, transport): (SocketAddrV4, Transport),
    refresh: Duration,
    pin: Pin,
    f: F,
) -> std::thread::JoinHandle<Result<T>>
where
    F: FnOnce(Handle) -> Fut + Send + 'static,
    Fut: std::future::Future<Output = Result<T>> + 'static,
{
    named_thread(
        ["huddle-ping", "huddle-pong"][usize::from(id == 2)],
        move || {
            pin.apply(usize::from(id) - 1);
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()?;
            let local = tokio::task::LocalSet::new();
            local.block_on(&rt, async move {
                let mut cfg =
                    DriverConfig::new(ReplicaConfig::new(id, 0).with_refresh_period(refresh));
                cfg.socket = socket_config(id, g, transport);
                if transport == Transport::Unicast {
                    cfg.peers = vec![SocketAddr::from((unicast_iface(3 - id), g.port()))];
                }
                let driver = Driver::bind(cfg)?;
                let handle = driver.handle();
                let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
                let robot = tokio::task::spawn_local(async move {
                    let out = f(handle).await;
                    let _ = stop_tx.send(());
                    out
                });
                // Ends when the robot's software does (or fails, or panics: the sender is
                // dropped).
                driver
                    .run(async move {
                        let _ = stop_rx.await;
                    })
                    .await?;
                robot.await.context("the robot's task panicked")?
            })
        },
    )
}

async fn next_value(sub: &mut driver::Subscription) -> Result<Value> {
    loop {
        match sub.next().await {
            Some(Notice::Changed { entry, .. }) => return Ok(entry.value),
            Some(_) => {}
            None => bail!("driver stopped"),
        }
    }
}

/// (b): ping on robot 1, pong on robot 2, each on its own thread; both robots' software
/// reacts as `reply` says.
fn huddle_ping_pong(
    g: (SocketAddrV4, Transport),
    rounds: usize,
    pin: Pin,
    reply: Reply,
) -> Result<Rtts> {
    let ready = Arc::new(AtomicBool::new(false));
    let done = Arc::new(AtomicBool::new(false));
    // The ponger's robot waits for the end on this, not on a timer: a timer firing
    // inside the measurement is a wake-up the bare-tokio ping-pong does not have.
    let finished = Arc::new(tokio::sync::Notify::new());
    let (r2, d2, f2) = (ready.clone(), done.clone(), finished.clone());
    let refresh = Duration::from_millis(100);
    let ponger = on_driver_thread(2, g, refresh, pin, move |h| async move {
        // The keys are fixed, as a robot program's are: parsed once.
        let pong = Key::parse("*.var.bench.pong")?;
        match reply {
            Reply::Watch => {
                // B's robot software reacts inside the driver's turn that applied the
                // ping: the reply is sent before the driver reads on.
                let failed = std::rc::Rc::new(std::cell::RefCell::new(None));
                let failed_in = failed.clone();
                let _watch = h.watch("1.var.bench.ping", move |h, notice| {
                    if let Notice::Changed { entry, .. } = notice {
                        if let Err(e) = h.set_key(&pong, entry.value) {
                            failed_in.borrow_mut().get_or_insert(e);
                        }
                    }
                })?;
                r2.store(true, Ordering::Release);
                while !d2.load(Ordering::Acquire) {
                    f2.notified().await;
                }
                let failure = failed.borrow_mut().take();
                if let Some(e) = failure {
                    return Err(e.into());
                }
            }
            Reply::Subscribe => {
                // B's robot software is a task awaiting a subscription.
                let mut pings = h.subscribe("1.var.bench.ping")?;
                r2.store(true, Ordering::Release);
                while !d2.load(Ordering::Acquire) {
                    let wait =
                        tokio::time::timeout(Duration::from_millis(200), next_value(&mut pings));
                    if let Ok(v) = wait.await {
                        h.set_key(&pong, v?)?;
                    }
                }
            }
        }
        Ok(())
    });
    let pinger = on_driver_thread(1, g, refresh, pin, move |h| async move {
        while !ready.load(Ordering::Acquire) {
            tokio::time::sleep(Duration::from_millis(1)).await;
        }
        let total = (WARM_UP_ROUNDS + rounds) as i64;
        let rtts = match reply {
            Reply::Watch => watch_pings(&h, total).await?,
            Reply::Subscribe => {
                let mut pongs = h.subscribe("2.var.bench.pong")?;
                let ping = Key::parse("*.var.bench.ping")?;
                let mut rtts = Vec::with_capacity(rounds);
                for i in 0..total {
                    let t0 = Instant::now();
                    h.set_key(&ping, i)?;
                    let reply = tokio::time::timeout(Duration::from_secs(2), async {
                        loop {
                            if next_value(&mut pongs).await? == Value::Int(i) {
                                return Ok::<_, anyhow::Error>(());
                            }
                        }
                    });
                    reply
                        .await
                        .context("huddle ping-pong: no reply within 2 s")??;
                    rtts.push((t0, t0.elapsed().as_secs_f64() * 1e6));
                }
                rtts
            }
        };
        done.store(true, Ordering::Release);
        finished.notify_one();
        Ok(rtts[WARM_UP_ROUNDS..].to_vec())
    });
    let rtts = pinger.join().expect("pinger thread")?;
    ponger.join().expect("ponger thread")?;
    Ok(rtts)
}

/// Robot 1's side of the ping-pong as a reaction: each pong seen in the driver's turn
/// records the round trip and sets the next ping. Returns every round trip in µs.
async fn watch_pings(h: &Handle, total: i64) -> Result<Rtts> {
    struct Rounds {
        next: i64,
        t0: Instant,
        rtts: Rtts,
        failed: Option<comms::SetError>,
    }
    let rounds = std::rc::Rc::new(std::cell::RefCell::new(Rounds {
        next: 0,
        t0: Instant::now(),
        rtts: Vec::with_capacity(total as usize),
        failed: None,
    }));
    let state = rounds.clone();
    // The reaction says when it is done (or failed); this task waits for that, not on a
    // polling timer (a wake-up inside the measurement the bare-tokio pinger does not
    // have: it showed as slow round trips 20 ms into every block).
    let ended = std::rc::Rc::new(tokio::sync::Notify::new());
    let end = ended.clone();
    let key = Key::parse("*.var.bench.ping")?;
    let first = key.clone();
    let _watch = h.watch("2.var.bench.pong", move |h, notice| {
        let Notice::Changed { entry, .. } = notice else {
            return;
        };
        let ping = {
            let mut r = state.borrow_mut();
            if entry.value != Value::Int(r.next) {
                return;
            }
            let rtt = (r.t0, r.t0.elapsed().as_secs_f64() * 1e6);
            r.rtts.push(rtt);
            r.next += 1;
            if r.next == total {
                end.notify_one();
                return;
            }
            r.t0 = Instant::now();
            r.next
        };
        if let Err(e) = h.set_key(&key, ping) {
            state.borrow_mut().failed.get_or_insert(e);
            end.notify_one();
        }
    })?;
    rounds.borrow_mut().t0 = Instant::now();
    h.set_key(&first, 0)?;
    // The reactions do the work; this task only waits for the end, or finds a stall (no
    // round trip completed in 2 s).
    let mut last = 0;
    loop {
        let woken = tokio::time::timeout(Duration::from_secs(2), ended.notified()).await;
        let mut r = rounds.borrow_mut();
        if let Some(e) = r.failed.take() {
            return Err(e.into());
        }
        if r.next == total {
            return Ok(std::mem::take(&mut r.rtts));
        }
        if woken.is_err() && r.next == last {
            bail!("huddle ping-pong: no reply within 2 s");
        }
        last = r.next;
    }
}

struct Throughput {
    updates_per_s: f64,
    updates_sent: u64,
    updates_applied: u64,
    frames_sent: u64,
    frames_received: u64,
    recv_buffer_bytes: usize,
}

/// (c): robot 1 writes `updates` values over 1,000 keys in batches; robot 2 counts what it
/// applies. The writer keeps at most a window of updates ahead of the reader (as a real
/// producer paced by its control loop would be), so the figure is what B sustains.
/// Frames are counted from the moment both ends hear each other (a frame sent before B
/// joined the group is no loss).
fn throughput(g: (SocketAddrV4, Transport), updates: u64, pin: Pin) -> Result<Throughput> {
    const KEYS: u64 = 1000;
    const WINDOW: u64 = 40_000;
    let applied = Arc::new(AtomicU64::new(0));
    let frames_from_a = Arc::new(AtomicU64::new(0));
    let done = Arc::new(AtomicBool::new(false));
    let (ap, ff, dn) = (applied.clone(), frames_from_a.clone(), done.clone());
    // A long refresh period: the figure is changed values, not periodic re-sends.
    let refresh = Duration::from_secs(5);
    let reader = on_driver_thread(2, g, refresh, pin, move |h| async move {
        loop {
            let s = h.stats();
            ap.store(s.replica.updates_applied, Ordering::Release);
            let from_a = s
                .peers
                .iter()
                .find(|p| p.robot == 1)
                .map_or(0, |p| p.frames);
            ff.store(from_a, Ordering::Release);
            if dn.load(Ordering::Acquire) {
                return Ok(s.io.recv_buffer_bytes);
            }
            tokio::time::sleep(Duration::from_micros(500)).await;
        }
    });
    let writer = on_driver_thread(1, g, refresh, pin, move |h| async move {
        let deadline = Instant::now() + Duration::from_secs(5);
        while frames_from_a.load(Ordering::Acquire) == 0 {
            if Instant::now() > deadline {
                bail!("throughput: robot 2 never heard robot 1");
            }
            h.set("*.var.bench.hello", 1)?;
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
        // Nothing is sent now: let B's counters settle, then take the baselines.
        tokio::time::sleep(Duration::from_millis(10)).await;
        let (frames_base, received_base) = (
            h.stats().replica.frames_out,
            frames_from_a.load(Ordering::Acquire),
        );
        let keys = (0..KEYS)
            .map(|k| Key::parse(&format!("*.var.bench.k{k}")))
            .collect::<Result<Vec<Key>, _>>()?;
        let base = applied.load(Ordering::Acquire);
        let t0 = Instant::now();
        let mut sent = 0u64;
        while sent < updates {
            // Wait without spinning: a spinning writer would take CPU from the reader.
            while sent - (applied.load(Ordering::Acquire) - base).min(sent) > WINDOW {
                tokio::time::sleep(Duration::from_micros(500)).await;
            }
            h.batch(|b| {
                for key in &keys {
                    b.set_key(key, sent as i64)?;
                    sent += 1;
                }
                Ok::<_, comms::SetError>(())
            })?;
            // Let the driver task read our own looped-back frames.
            tokio::task::yield_now().await;
        }
        // Wait until B has everything, or gives up.
        let deadline = Instant::now() + Duration::from_secs(5);
        while applied.load(Ordering::Acquire) - base < sent && Instant::now() < deadline {
            tokio::time::sleep(Duration::from_micros(200)).await;
        }
        let elapsed = t0.elapsed().as_secs_f64();
        let got = applied.load(Ordering::Acquire) - base;
        tokio::time::sleep(Duration::from_millis(50)).await;
        let frames_sent = h.stats().replica.frames_out - frames_base;
        let frames_received = frames_from_a.load(Ordering::Acquire) - received_base;
        Ok(Throughput {
            updates_per_s: got as f64 / elapsed,
            updates_sent: sent,
            updates_applied: got,
            frames_sent,
            frames_received,
            recv_buffer_bytes: 0,
        })
    });
    let tp = writer.join().expect("writer thread");
    done.store(true, Ordering::Release);
    let recv_buffer_bytes = reader.join().expect("reader thread")?;
    Ok(Throughput {
        recv_buffer_bytes,
        ..tp?
    })
}

/// (d): spawn `huddle daemon`, write 10,000 keys through its relay, read VmRSS. A robot
/// holds at most 4,096 own global values (`ReplicaConfig::max_bindings_per_owner`:
/// teammates would refuse more), so 4,000 of the keys are global (each
/// replicated and refreshed) and the other 6,000 `local`.
fn rss_with_10k_keys(g: SocketAddrV4, relay_port: u16) -> Result<f64> {
    const GLOBAL_KEYS: usize = 4_000;
    let dir = std::env::temp_dir().join(format!("huddle-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let relay: SocketAddr = format!("127.0.0.1:{relay_port}").parse()?;
    let mut child = std::process::Command::new(std::env::current_exe()?)
        .args([
            "daemon",
            "--id",
            "9",
            "--group",
            &g.to_string(),
            "--iface",
            "127.0.0.1",
        ])
        .args(["--relay", &relay.to_string()])
        .arg("--config-dir")
        .arg(&dir)
        .env("RUST_LOG", "warn")
        .spawn()
        .context("spawn huddle daemon")?;
    let result = (|| -> Result<f64> {
        let deadline = Instant::now() + Duration::from_secs(10);
        let mut client = loop {
            match RelayClient::connect_addr(relay) {
                Ok(c) => break c,
                Err(_) if Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(20))
                }
                Err(e) => return Err(e),
            }
        };
        for chunk in 0..100 {
            let mut batch = String::new();
            for k in 0..100 {
                let n = chunk * 100 + k;
                let scope = if n < GLOBAL_KEYS { "*" } else { "local" };
                batch += &format!("SETV {scope}.var.bench.key{n:05} {k}\n");
            }
            client.send(batch.trim_end())?;
            for _ in 0..100 {
                let answer = client.line()?;
                if answer != "OK" {
                    bail!("daemon refused a key: {answer}");
                }
            }
        }
        // Let a few refresh periods pass with all keys on the wire.
        std::thread::sleep(Duration::from_millis(500));
        let status = std::fs::read_to_string(format!("/proc/{}/status", child.id()))?;
        let kb: f64 = status
            .lines()
            .find_map(|l| l.strip_prefix("VmRSS:"))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
            .context("no VmRSS in /proc/<pid>/status")?;
        Ok(kb / 1024.0)
    })();
    let _ = child.kill();
    let _ = child.wait();
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// `huddle bench comms`
pub fn run(args: BenchArgs) -> Result<()> {
    let BenchWhat::Comms(args) = args.what;
    let say = |s: &str| {
        if !args.json {
            eprintln!("{s}");
        }
    };
    // The three ping-pongs in interleaved blocks, so that load from other processes on
    // this shared machine falls on all three alike. Short blocks (a quarter of a second
    // or less each) share it out more evenly: with five, one busy second could land on
    // one measurement's block and move its median by a tenth.
    const BLOCKS: usize = 20;
    let per_block = args.rounds.div_ceil(BLOCKS);
    let transport = Transport::from(args.transport);
    let (mut raw, mut bare, mut hud, mut bare_b) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let start = Instant::now();
    // CLOCK_MONOTONIC (what `Instant` reads on Linux) at `start`, so that the dump's
    // times can be put beside a `perf --clockid monotonic` trace of the same run.
    let start_mono_us = nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC)
        .map_or(0.0, |t| t.tv_sec() as f64 * 1e6 + t.tv_nsec() as f64 / 1e3);
    let mut dump = String::new();
    let mut dump_block = |what: &str, block: usize, rtts: &[(Instant, f64)]| {
        if args.dump_rtts.is_some() {
            for (i, (t0, rtt)) in rtts.iter().enumerate() {
                let at = t0.duration_since(start).as_secs_f64() * 1e6;
                let mono = start_mono_us + at;
                dump += &format!("{what},{block},{i},{at:.1},{rtt:.3},{mono:.1}\n");
            }
        }
    };
    let us = |rtts: Rtts| rtts.into_iter().map(|(_, us)| us);
    for block in 0..BLOCKS {
        say(&format!(
            "ping-pong block {} of {BLOCKS}: raw, tokio, huddle{}...",
            block + 1,
            if args.aa { ", tokio again" } else { "" }
        ));
        let g = group(args.port, 1);
        let r = raw_ping_pong(g, per_block, args.pin, transport)?;
        dump_block("raw", block, &r);
        raw.extend(us(r));
        let t = tokio_ping_pong(g, per_block, args.pin, transport)?;
        dump_block("tokio", block, &t);
        bare.extend(us(t));
        let h = huddle_ping_pong(
            (group(args.port + 1, 2), transport),
            per_block,
            args.pin,
            args.reply,
        )?;
        dump_block("huddle", block, &h);
        hud.extend(us(h));
        if args.aa {
            // The same bare-tokio ping-pong again, after huddle's: how far apart two
            // identical systems land in one run.
            let t = tokio_ping_pong(g, per_block, args.pin, transport)?;
            dump_block("tokio-b", block, &t);
            bare_b.extend(us(t));
        }
    }
    if let Some(path) = &args.dump_rtts {
        let header = "what,block,index,start_us,rtt_us,start_mono_us\n";
        std::fs::write(path, format!("{header}{dump}"))
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    let (raw_p50, raw_p99) = summarize(raw);
    let (tokio_p50, tokio_p99) = summarize(bare);
    let (h_p50, h_p99) = summarize(hud);
    let aa = args.aa.then(|| {
        let (p50, p99) = summarize(bare_b);
        AaReport {
            tokio_b_p50_us: p50,
            tokio_b_p99_us: p99,
            p50_b_over_a: p50 / tokio_p50,
            p99_b_over_a: p99 / tokio_p99,
        }
    });
    say("sustained updates A -> B...");
    let tp = throughput((group(args.port + 2, 3), transport), args.updates, args.pin)?;
    say("daemon resident memory with 10,000 keys...");
    let rss = rss_with_10k_keys(group(args.port + 3, 4), args.port + 4)?;
    let report = CommsReport {
        raw_p50_us: raw_p50,
        raw_p99_us: raw_p99,
        tokio_p50_us: tokio_p50,
        tokio_p99_us: tokio_p99,
        huddle_p50_us: h_p50,
        huddle_p99_us: h_p99,
        p50_ratio: h_p50 / raw_p50,
        p99_ratio: h_p99 / raw_p99,
        tokio_p50_ratio: tokio_p50 / raw_p50,
        pin: args.pin,
        reply: args.reply,
        transport: transport.name(),
        updates_per_s: tp.updates_per_s,
        updates_sent: tp.updates_sent,
        updates_applied: tp.updates_applied,
        update_loss: 1.0 - tp.updates_applied as f64 / tp.updates_sent.max(1) as f64,
        frame_loss: (1.0 - tp.frames_received as f64 / tp.frames_sent.max(1) as f64).max(0.0),
        frames_sent: tp.frames_sent,
        frames_received: tp.frames_received,
        rss_mb_10k_keys: rss,
        recv_buffer_bytes: tp.recv_buffer_bytes,
        build: if cfg!(debug_assertions) {
            "debug"
        } else {
            "release"
        },
        aa,
    };
    if args.json {
        outln!("{}", serde_json::to_string(&report)?);
    } else {
        let r = &report;
        outln!(
            "loopback {} ping-pong ({} round trips each, pinning {:?}, reply by {:?}, {} build)",
            r.transport,
            args.rounds,
            r.pin,
            r.reply,
            r.build
        );
        outln!(
            "  raw UDP           p50 {:7.1} us   p99 {:7.1} us",
            r.raw_p50_us,
            r.raw_p99_us
        );
        outln!(
            "  bare tokio        p50 {:7.1} us   p99 {:7.1} us   (p50 {:.2}x raw: the cost of tokio)",
            r.tokio_p50_us, r.tokio_p99_us, r.tokio_p50_ratio
        );
        outln!(
            "  huddle replicas   p50 {:7.1} us   p99 {:7.1} us",
            r.huddle_p50_us,
            r.huddle_p99_us
        );
        outln!(
            "  ratio             p50 {:7.2}      p99 {:7.2}   (target p50 <= 1.5)",
            r.p50_ratio,
            r.p99_ratio
        );
        outln!(
            "sustained A -> B    {:.0} updates/s, {} of {} updates applied, frame loss {:.4}% ({} of {} frames)   (target >= 500000, no loss)",
            r.updates_per_s,
            r.updates_applied,
            r.updates_sent,
            r.frame_loss * 100.0,
            r.frames_sent - r.frames_received.min(r.frames_sent),
            r.frames_sent
        );
        outln!("  receive buffer granted {} bytes", r.recv_buffer_bytes);
        outln!(
            "daemon RSS with 10,000 keys: {:.1} MB   (target <= 20)",
            r.rss_mb_10k_keys
        );
        if let Some(aa) = &r.aa {
            outln!(
                "A/A: bare tokio again p50 {:7.1} us   p99 {:7.1} us   (against the first: p50 {:.3}x, p99 {:.3}x)",
                aa.tokio_b_p50_us, aa.tokio_b_p99_us, aa.p50_b_over_a, aa.p99_b_over_a
            );
        }
    }
    Ok(())
}
