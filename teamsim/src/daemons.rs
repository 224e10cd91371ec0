//! `huddle sim --daemons`: the same match, with each robot's team layer in a real
//! `huddle daemon` on loopback instead of in this process. The simulated robots are robot
//! programs ([`player::remote::RemoteRobot`]): each control tick they write what they
//! sensed to their daemon's `local.var.robot.*` keys through the relay, and play on what
//! the daemon's team layer last published on `local.var.team.*` (watched with `REFR 0`,
//! so each output arrives as it is written). The daemons talk to each other over a
//! scratch multicast group on 127.0.0.1, each sender impaired by netsim's link model
//! (`huddle daemon --impair`), so the network is the preset's. The world runs at real
//! time: one physics step per 10 ms of wall clock.
//!
//! The report carries the figures the in-process report has where they mean the same
//! thing here: exactly one goer over ball-visible time, the team ball's error against the
//! truth (each robot's `local.var.team.ball` carried forward by its published velocity to
//! the instant it is judged), the central reference, messages sent. The central reference
//! is the in-process one: the team's own fusion (a `fusion::GlobalModel` with the team's
//! settings) hearing every robot's world-model message of every tick at once, in full
//! whatever the budget lets the robot send (each layer's `local.var.team.world`, watched
//! on its relay), and put on the centre spot at a kick-off. What it cannot have: the
//! references that need a replica's inside (delivery, delayed-centralized) and the
//! world-model NEES bands.
//!
//! In the drawn world each daemon also gets its robot's clock as the match draws it in
//! process (`huddle daemon --clock-offset --clock-drift-ppm`): an offset of up to 20 s and
//! a drift of some tens of ppm, so the replicas' clock estimates and the receiver-side
//! times are exercised as they are in process.
//!
//! The in-process run it is judged against is one draw: the same seed in process swings
//! by chance as much as the daemons' match does (a 1 ms change of the network's latency
//! moves its team-ball RMSE by up to a third), so [`in_process`] plays it again with the
//! latency moved by each of [`SPREAD_LATENCY_US`] and reports that spread and its median.
//!
//! `HUDDLE_DAEMONS_TRACE=1` prints each team-ball sample (time, robot, error, ball speed,
//! how far the world ran behind the wall clock), each goal, and each robot's pose error
//! per tick (and in the in-process run per step) to stderr, for finding where an error
//! comes from (`scripts/daemons-trace.py`).
//!
//! Under `--game` the match is played under the simulated GameController, its packets sent
//! over UDP on loopback to each daemon's listener and the team's frames counted as the GC
//! counts them: [`super::daemons_game`].
//!
//! Networking rule: everything binds 127.0.0.1 and uses an organisation-local scratch
//! group (`driver::scratch_group`) with `IP_MULTICAST_IF` 127.0.0.1.

// A real-time loop over real processes: it reads the wall clock and sleeps.
#![allow(clippy::disallowed_methods)]

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::net::{Ipv4Addr, SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use comms::relay::Binding;
use comms::Value;
use fusion::{BallEstimate, LocalWorldModel};
use player::remote::{start_pose_value, RemoteRobot, TeamView};
use player::Percepts;
use team::contract;

use super::daemons_air::{self, Air};
pub use super::daemons_air::{AirCounts, DaemonsOutage};
use super::daemons_game::{self, GcSide};
pub use super::daemons_in_process::{
    in_process, run_in_process, InProcess, SpreadRun, SPREAD_LATENCY_US,
};
pub use super::daemons_report::{DaemonsReport, Spread};
use super::references::CentralFusion;
use super::{Metrics, SimConfig, Simulation, Transport};
use crate::field::geometry::Pose;
use crate::field::World;

/// Where a daemon's counters are (`local.var.huddle.stats.NAME`).
const STATS_PREFIX: &str = "local.var.huddle.stats.";

/// The longest a robot program waits for its layer's tick on the senses it just wrote.
const FRESH_WAIT: Duration = Duration::from_millis(8);

/// How `--daemons` runs the team.
#[derive(Debug, Clone)]
pub struct DaemonsOptions {
    /// The `huddle` binary to start as `huddle daemon`.
    pub exe: PathBuf,
    /// netsim spec for each daemon's `--impair` (`None`: the match's network as a spec).
    pub impair: Option<String>,
    /// Keep each daemon's log (`RUST_LOG=info`) in this directory.
    pub log_dir: Option<PathBuf>,
}

/// Why a `--daemons` match could not run.
#[derive(Debug, thiserror::Error)]
pub enum DaemonsError {
    /// The match's configuration is not one daemons can play.
    #[error("{0}")]
    Config(String),
    /// Starting or talking to a daemon failed.
    #[error("{what}: {source}")]
    Io {
        /// What was being done.
        what: String,
        /// The failure.
        source: std::io::Error,
    },
    /// A daemon stopped during the match.
    #[error("robot {id}'s daemon exited during the match ({status}); its log: {log}")]
    Exited {
        /// The robot.
        id: u8,
        /// Its exit status.
        status: String,
        /// Where its log is.
        log: String,
    },
    /// The simulation could not be set up.
    #[error(transparent)]
    Sim(#[from] super::SimError),
}

fn io(what: impl Into<String>) -> impl FnOnce(std::io::Error) -> DaemonsError {
    let what = what.into();
    move |source| DaemonsError::Io { what, source }
}

/// What a robot's relay reader has seen.
#[derive(Debug, Default)]
struct Heard {
    view: TeamView,
    /// When each ball output, the pose and the latest tick count arrived.
    pose_at: Option<Instant>,
    tick_at: Option<Instant>,
    own_ball_at: Option<Instant>,
    team_ball_at: Option<Instant>,
    /// Each robot's announced pass receiver.
    pass_to: BTreeMap<u8, u8>,
    errors: u64,
    refusals: Vec<String>,
    /// The daemon's counters asked for at the end (`GETV local.var.huddle.stats.NAME`),
    /// by NAME (`frames_out`, `audio.fallback_heard`, …).
    stats: BTreeMap<String, u64>,
    /// Resets told whose marking `GETV` has not come back yet: until it does, every ball
    /// heard may be from before the reset, so the robot plays on none.
    resets_pending: u32,
    /// The layer's own world-model messages (`local.var.team.world`) since the central
    /// reference last took them, in order.
    lwms: Vec<Vec<u8>>,
    /// Under `--game`: the daemon's `local.var.gc.state` and `local.var.gc.penalty`.
    gc_state: Option<String>,
    gc_penalty: i64,
}

/// A robot's daemon: its process and its relay connection.
struct Daemon {
    id: u8,
    child: Child,
    log: PathBuf,
    writer: TcpStream,
    heard: Arc<Mutex<Heard>>,
    /// Signalled by the relay reader when a tick arrives (the program blocks on it, as a
    /// robot program blocks on its socket, instead of polling).
    ticked: Arc<Condvar>,
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Daemon {
    fn send(&mut self, lines: &str) -> Result<(), DaemonsError> {
        self.writer
            .write_all(lines.as_bytes())
            .map_err(io(format!("writing to robot {}'s relay", self.id)))
    }

    fn check_alive(&mut self) -> Result<(), DaemonsError> {
        match self.child.try_wait() {
            Ok(Some(status)) => Err(DaemonsError::Exited {
                id: self.id,
                status: status.to_string(),
                log: self.log.display().to_string(),
            }),
            _ => Ok(()),
        }
    }
}

/// The relay lines that write `writes`, one `SETV` each.
fn setv_lines(writes: &[(&str, Value)]) -> String {
    writes
        .iter()
        .map(|(key, value)| format!("SETV {key} {value}\n"))
        .collect()
}

/// The netsim spec of the match's network, for `huddle daemon --impair`.
pub fn impair_spec(cfg: &SimConfig) -> String {
    let n = &cfg.network;
    let mut spec = format!("preset={}", n.preset.name());
    if let Some(loss) = n.loss {
        spec.push_str(&format!(",loss={loss}"));
    }
    if let Some(l) = n.latency {
        spec.push_str(&format!(",delay={}us", l.as_micros()));
    }
    if let Some(j) = n.jitter {
        spec.push_str(&format!(",jitter={}us", j.as_micros()));
    }
    if let Some(d) = n.dtim_period {
        let beacon_us = 102_400 * u64::from(d);
        spec.push_str(&format!(",beacon={beacon_us}us"));
    }
    spec
}

fn free_tcp_port() -> Result<u16, DaemonsError> {
    let l = std::net::TcpListener::bind((Ipv4Addr::LOCALHOST, 0))
        .map_err(io("finding a free relay port"))?;
    Ok(l.local_addr()
        .map_err(io("finding a free relay port"))?
        .port())
}

/// Starts robot `id`'s daemon and connects to its relay; `gc_args` point its
/// GameController listener at the simulated referee (`--game`).
#[allow(clippy::too_many_arguments)]
fn start_daemon(
    id: u8,
    cfg: &SimConfig,
    opts: &DaemonsOptions,
    group: std::net::SocketAddrV4,
    spec: &str,
    clock: netsim::NodeClock,
    dir: &Path,
    gc_args: &[String],
    extra: &[String],
) -> Result<Daemon, DaemonsError> {
    let relay: SocketAddr = (Ipv4Addr::LOCALHOST, free_tcp_port()?).into();
    let log = dir.join(format!("daemon-{id}.log"));
    let log_file =
        std::fs::File::create(&log).map_err(io(format!("creating {}", log.display())))?;
    let mut cmd = Command::new(&opts.exe);
    cmd.args(["daemon", "--id", &id.to_string()])
        .args(["--group", &group.to_string(), "--iface", "127.0.0.1"])
        .args(["--relay", &relay.to_string()])
        .arg("--config-dir")
        .arg(dir)
        .args(["--team-size", &cfg.robots.to_string()])
        .args(["--impair", spec])
        .args([
            "--impair-seed",
            &(cfg.seed * 1000 + u64::from(id)).to_string(),
        ])
        .args([
            "--refresh",
            &format!("{}ms", cfg.refresh_period.as_millis().max(1)),
        ]);
    if let Some(b) = &cfg.budget {
        // The simulated team pools its budget (every robot runs huddle).
        cmd.args(["--budget", &b.to_string(), "--budget-pool"]);
        if gc_args.is_empty() {
            // No GameController: the budget paces itself, as the daemon does without one.
            cmd.arg("--no-gamecontroller");
        }
    }
    cmd.args(gc_args).args(extra);
    let policy = clap::ValueEnum::to_possible_value(&cfg.brain.team.send_policy)
        .map(|v| v.get_name().to_owned())
        .unwrap_or_else(|| "every".into());
    cmd.args(["--policy", &policy]);
    if clock != netsim::NodeClock::IDEAL {
        // The robot's clock as the match drew it in process (`--world drawn`): the
        // replica's times, the layer's and the teammates' estimates of it run on it.
        cmd.args([
            "--clock-offset",
            &format!("{}us", clock.offset().as_micros()),
        ])
        .args(["--clock-drift-ppm", &clock.drift_ppm().to_string()]);
    }
    if cfg.compensate_latency {
        // As the in-process team sets it: the network's expected delay.
        let l = cfg.arbitration.latency_compensation;
        let l = if l.is_zero() { cfg.expected_delay() } else { l };
        cmd.args(["--latency-compensation", &format!("{}us", l.as_micros())]);
    }
    // HUDDLE_DAEMONS_LOG overrides the daemons' filter (e.g. `info,driver::team=debug`
    // with `--daemon-logs`, to trace the team layer's decisions).
    let filter = std::env::var("HUDDLE_DAEMONS_LOG").unwrap_or_else(|_| {
        if opts.log_dir.is_some() {
            "info"
        } else {
            "warn"
        }
        .to_owned()
    });
    // A simulator stopped by Ctrl-C or killed (a CI timeout) runs no destructors: the
    // daemon stops with it rather than run on holding its ports and speakers.
    cmd.args(["--parent-pid", &std::process::id().to_string()]);
    cmd.env("RUST_LOG", filter)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::from(log_file));
    let mut child = cmd
        .spawn()
        .map_err(io(format!("starting {} daemon", opts.exe.display())))?;
    // Wait for its relay to answer.
    let deadline = Instant::now() + Duration::from_secs(20);
    let stream = loop {
        match TcpStream::connect(relay) {
            Ok(s) => break s,
            Err(e) => {
                if let Ok(Some(status)) = child.try_wait() {
                    return Err(DaemonsError::Exited {
                        id,
                        status: status.to_string(),
                        log: log.display().to_string(),
                    });
                }
                if Instant::now() > deadline {
                    let _ = child.kill();
                    return Err(DaemonsError::Io {
                        what: format!("robot {id}'s relay at {relay} never answered"),
                        source: e,
                    });
                }
                std::thread::sleep(Duration::from_millis(20));
            }
        }
    };
    let _ = stream.set_nodelay(true);
    let reader = stream.try_clone().map_err(io("cloning a relay socket"))?;
    let heard = Arc::new(Mutex::new(Heard::default()));
    let ticked = Arc::new(Condvar::new());
    let (sink, signal) = (Arc::clone(&heard), Arc::clone(&ticked));
    std::thread::Builder::new()
        .name(format!("relay-{id}"))
        .spawn(move || read_relay(id, reader, &sink, &signal))
        .map_err(io("starting a relay reader"))?;
    Ok(Daemon {
        id,
        child,
        log,
        writer: stream,
        heard,
        ticked,
    })
}

/// Reads robot `id`'s relay until it closes: outputs into the view, errors counted.
fn read_relay(id: u8, stream: TcpStream, heard: &Mutex<Heard>, ticked: &Condvar) {
    let mut lines = BufReader::new(stream).lines();
    while let Some(Ok(line)) = lines.next() {
        let mut h = heard.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(text) = line.strip_prefix("ERR ") {
            h.errors += 1;
            if h.errors <= 5 {
                tracing::warn!(robot = id, "relay refused a write: {text}");
                h.refusals.push(format!("robot {id}: {text}"));
            }
            continue;
        }
        let Some(b) = Binding::parse(&line) else {
            continue;
        };
        if b.key == "local.var.audio.heard" {
            eprintln!(
                "heard robot={id} wall={:.3} {}",
                daemons_air::wall_s(),
                b.value
            );
            continue;
        }
        let Ok(value) = comms::literal::parse_literal(&b.value) else {
            continue;
        };
        let now = Instant::now();
        if let Some(name) = b.key.strip_prefix(STATS_PREFIX) {
            if let Value::Int(n) = value {
                h.stats
                    .insert(name.to_owned(), u64::try_from(n).unwrap_or(0));
            }
            continue;
        }
        if b.key == "local.var.gc.state" {
            if let Value::String(s) = value {
                h.gc_state = Some(s);
            }
            continue;
        }
        if b.key == "local.var.gc.penalty" {
            if let Value::Int(p) = value {
                h.gc_penalty = p;
            }
            continue;
        }
        if b.key == contract::TICK_KEY {
            if line.starts_with("VAL ") {
                // The answer to the GETV sent right after a ball reset: every ball pushed
                // before it is of the ball that is gone, every one after it is new.
                h.view.own_ball = None;
                h.view.team_ball = None;
                h.resets_pending = h.resets_pending.saturating_sub(1);
            } else {
                h.tick_at = Some(now);
                ticked.notify_all();
            }
            continue;
        }
        if b.key == contract::WORLD_OUT_KEY {
            if let Value::Bytes(bytes) = value {
                h.lwms.push(bytes);
            }
            continue;
        }
        if let Some(owner) = b.key.strip_suffix(".var.machine.pass_to") {
            if let (Ok(owner), Value::Int(to)) = (owner.parse::<u8>(), &value) {
                h.pass_to.insert(owner, u8::try_from(*to).unwrap_or(0));
            }
            continue;
        }
        if h.view.take(&b.key, &value, b.age_ms as f64 * 1e-3) {
            match b.key.as_str() {
                contract::OWN_BALL_KEY => h.own_ball_at = Some(now),
                contract::TEAM_BALL_KEY => h.team_ball_at = Some(now),
                contract::POSE_OUT_KEY => h.pose_at = Some(now),
                _ => {}
            }
        }
    }
}

/// The view robot `i` plays on at `now`: what it heard, the balls' time since they were
/// published brought up to `now`.
fn view_at(heard: &Heard, now: Instant) -> TeamView {
    let mut view = heard.view.clone();
    if heard.resets_pending > 0 {
        // The program told its layer the ball was put back and has not yet read past
        // that point: what it holds is of the old ball (a robot program knows when it
        // reset, as this one does).
        view.own_ball = None;
        view.team_ball = None;
    }
    let since = |at: Option<Instant>, published: f64| {
        published + at.map_or(0.0, |a| now.saturating_duration_since(a).as_secs_f64())
    };
    if let Some((b, s)) = view.own_ball {
        view.own_ball = Some((b, since(heard.own_ball_at, s)));
    }
    view.pose_since_s = since(heard.pose_at, view.pose_since_s);
    if let Some((b, s)) = view.team_ball {
        view.team_ball = Some((b, since(heard.team_ball_at, s)));
    }
    view.pass_to = (view.goer != 0)
        .then(|| heard.pass_to.get(&view.goer).copied())
        .flatten()
        .filter(|&r| r != 0);
    view
}

/// Runs the match `cfg` with each robot's team layer in a daemon, in real time, calling
/// `progress(seconds played)` every step.
pub fn run(
    cfg: &SimConfig,
    opts: &DaemonsOptions,
    mut progress: impl FnMut(f64),
) -> Result<DaemonsReport, DaemonsError> {
    if cfg.transport != Transport::Multicast {
        return Err(DaemonsError::Config(
            "--daemons plays over a loopback multicast group: use --transport multicast".into(),
        ));
    }
    daemons_air::check(cfg)?;
    // The lineup, the world and each robot's start belief, exactly as in process.
    let setup = Simulation::new(cfg.clone())?;
    let homes = setup.homes().to_vec();
    let holders = setup.holders().to_vec();
    let mut world: World = setup.world.clone();
    let calibration = setup.robots[0].brain.cal;
    let wm = cfg.brain.team.world_model;
    let mut robots: Vec<RemoteRobot> = setup
        .robots
        .iter()
        .map(|r| RemoteRobot::new(r.id, r.tactics.position, calibration))
        .collect();
    let starts: Vec<_> = setup.robots.iter().map(|r| r.pose_belief).collect();
    // Each robot's clock as drawn for the match (the ideal clock outside the drawn world).
    let clocks: Vec<netsim::NodeClock> = (0..robots.len())
        .map(|i| {
            let net = setup.harness.net();
            net.node_clock(setup.harness.node(i)).unwrap_or_default()
        })
        .collect();
    // The central reference as the in-process match builds it (the team's fusion, its
    // settings), and the ball the robots put on the centre spot at a kick-off.
    let mut central: CentralFusion = setup.central.clone();
    let kick_off: BallEstimate = setup.robots[0].kick_off_ball(0.0);
    drop(setup);

    // Read once: the trace is asked for per robot and per step.
    let trace = trace();
    let spec = opts.impair.clone().unwrap_or_else(|| impair_spec(cfg));
    let group = driver::scratch_group().map_err(io("picking a scratch group"))?;
    // Under `--game`: the referee, listening to the group before the daemons start.
    let mut gc = match cfg.game.clone() {
        Some(script) => Some(GcSide::start(cfg, script, group, &world)?),
        None => None,
    };
    let dir = match &opts.log_dir {
        Some(d) => d.clone(),
        None => std::env::temp_dir().join(format!(
            "huddle-sim-daemons-{}-{}",
            std::process::id(),
            cfg.seed
        )),
    };
    std::fs::create_dir_all(&dir).map_err(io(format!("creating {}", dir.display())))?;
    // Under `--acoustic`: the room between the daemons' loudspeakers and microphones,
    // its FIFOs made before the daemons open them.
    let ids: Vec<u8> = robots.iter().map(|r| r.id).collect();
    let air = if cfg.acoustic.enabled {
        Some(Air::start(cfg, &dir, &ids, world.robot_positions())?)
    } else {
        None
    };
    // Under `--outage`: the instant the match will start, fixed now so that every daemon
    // can be told when the outage begins from its own start (they fail together).
    let anchor = Instant::now()
        + cfg
            .outage
            .map_or(Duration::ZERO, |_| daemons_air::OUTAGE_LEAD);
    let mut daemons = Vec::with_capacity(robots.len());
    for (i, (r, &clock)) in robots.iter().zip(&clocks).enumerate() {
        let gc_args = gc.as_ref().map_or_else(Vec::new, |g| g.daemon_args(i));
        let match_in = anchor.saturating_duration_since(Instant::now());
        let air_args = daemons_air::daemon_args(cfg, &dir, r.id, match_in);
        daemons.push(start_daemon(
            r.id, cfg, opts, group, &spec, clock, &dir, &gc_args, &air_args,
        )?);
    }
    // Each program says who it is and where it was put, then watches its layer.
    for ((d, r), start) in daemons.iter_mut().zip(&robots).zip(&starts) {
        let mut hello = String::new();
        let keeper = !r.is_field_player();
        hello += &format!(
            "SETV {} {}\n",
            contract::GOALKEEPER_KEY,
            Value::Bool(keeper)
        );
        hello += &format!(
            "SETV {} {}\n",
            contract::POSE_KEY,
            start_pose_value(start, wm.start_sigma_m, wm.start_sigma_rad)
        );
        if gc.is_some() {
            // The game as its daemon's listener wrote it, as a robot program reads it.
            hello += "ADDW local.var.gc.state\nADDW local.var.gc.penalty\n";
        }
        hello += "ADDW local.var.team.#\nADDW +.var.machine.pass_to\n";
        if air.is_some() && trace {
            // What its microphone's decoder heard, for the trace.
            hello += "ADDW local.var.audio.heard\n";
        }
        hello += "REFR 0\n";
        d.send(&hello)?;
    }

    // A program tells its layer where the referee put it.
    let place = |d: &mut Daemon, spot: &Pose| {
        let pose = start_pose_value(spot, wm.start_sigma_m, wm.start_sigma_rad);
        d.send(&format!("SETV {} {pose}\n", contract::POSE_KEY))
    };
    let n = robots.len();
    let dt = cfg.physics_dt_s;
    let period = cfg.brain.team.control_period_s;
    let mut next_tick_s: Vec<f64> = (0..n)
        .map(|i| period * (1.0 + i as f64 / n as f64))
        .collect();
    let mut metrics = Metrics::default();
    let (mut central_messages, mut central_refused) = (0u64, 0u64);
    let (mut team_sq, mut team_n, mut central_sq) = (0.0, 0u64, 0.0);
    let (mut blind_sq, mut blind_n) = (0.0, 0u64);
    let (mut pose_sq, mut pose_n) = (0.0, 0u64);
    let mut kick_attempts = 0u64;
    let mut late_steps = 0u64;
    let mut stale_views = 0u64;
    // Per fresh view: from writing the cycle's senses to playing on its tick, µs.
    let mut view_lags_us: Vec<u64> = Vec::new();
    // Per step: how far behind the wall clock the world ran, µs.
    let mut behind_us: Vec<u64> = Vec::new();
    let steps = (cfg.duration_s / dt).round() as u64;
    if let Some(wait) = anchor.checked_duration_since(Instant::now()) {
        std::thread::sleep(wait);
    }
    let started = Instant::now();
    // Under `--outage`: the window every daemon's radio is down, on the match's clock.
    let outage_window = daemons_air::outage_window(cfg, anchor, started);
    let mut outage_figures = super::acoustic::OutageFigures::default();
    let mut last_named: Vec<(u8, bool)> = Vec::new();
    for step in 0..steps {
        let t = step as f64 * dt;
        let due = started + Duration::from_secs_f64(t);
        let now = Instant::now();
        if now < due {
            std::thread::sleep(due - now);
        } else if now - due > Duration::from_secs_f64(dt) {
            late_steps += 1;
        }
        behind_us.push(Instant::now().saturating_duration_since(due).as_micros() as u64);
        if let Some(g) = &mut gc {
            if g.over() {
                break;
            }
            // Robots the referee carried off or back: each program tells its layer where.
            // The WLAN's outage takes the GameController's packets too.
            let radio_down = outage_window.is_some_and(|o| o.contains(t));
            for (i, spot) in g.step(t, &mut world, &robots, &homes, cfg, radio_down)? {
                place(&mut daemons[i], &spot)?;
            }
        }
        let in_play = gc.as_ref().is_none_or(|g| g.playing());
        if step % 100 == 0 {
            for d in &mut daemons {
                d.check_alive()?;
            }
        }
        let mut ticked = Vec::new();
        for i in 0..n {
            if next_tick_s[i] > t + 1e-9 {
                continue;
            }
            next_tick_s[i] += period;
            let percepts = Percepts {
                frame: world.look(i),
                odometry: world.read_odometry(i),
            };
            let marks_seen = percepts.frame.landmarks.len();
            // Write the cycle's senses (odometry last: the layer ticks on it), then wait
            // for the layer's pose from that tick, as a robot program reading its
            // team's decisions each cycle does; a layer slower than a few ms leaves the
            // robot to play on what it last had.
            let clock = |at: Instant| at.saturating_duration_since(started).as_secs_f64();
            // Under `--game`: the program reads the GC's word its daemon's listener wrote
            // and hears the whistle (it tells its layer, before the senses its layer
            // ticks on); its order waits for that tick's reading of the whistle.
            let game = gc.as_mut().map(|g| {
                let h = daemons[i].heard.lock().unwrap_or_else(|e| e.into_inner());
                let (state, penalty) = (h.gc_state.clone(), h.gc_penalty);
                drop(h);
                let whistled = g.hears_whistle(i, t, state.as_deref(), penalty);
                (whistled, state, penalty)
            });
            let mut lines = match &game {
                Some((true, ..)) => format!("SETV {} true\n", contract::WHISTLE_KEY),
                _ => String::new(),
            };
            let senses = robots[i].sense(clock(Instant::now()), percepts);
            lines += &setv_lines(&senses);
            let sent = Instant::now();
            daemons[i].send(&lines)?;
            let fresh = sent + FRESH_WAIT;
            let d = &daemons[i];
            let mut heard = d.heard.lock().unwrap_or_else(|e| e.into_inner());
            let (view, now, fresh_view) = loop {
                let now = Instant::now();
                if heard.tick_at.is_some_and(|a| a > sent) {
                    view_lags_us.push(now.duration_since(sent).as_micros() as u64);
                    break (view_at(&heard, now), now, true);
                }
                if now >= fresh {
                    stale_views += 1;
                    break (view_at(&heard, now), now, false);
                }
                heard = d
                    .ticked
                    .wait_timeout(heard, fresh - now)
                    .unwrap_or_else(|e| e.into_inner())
                    .0;
            };
            drop(heard);
            // Its body follows its layer's reading of the whistle (the daemon's, with the
            // rules for a silent GC), read with the tick's outputs.
            let order = match (&gc, game) {
                (Some(g), Some((_, state, penalty))) => {
                    Some(g.order(i, state.as_deref(), penalty, view.whistle()))
                }
                _ => None,
            };
            robots[i].view = view;
            let mut out = robots[i].act(&cfg.brain, clock(now), 0.0, &homes, &holders);
            if let Some(order) = order.filter(|_| robots[i].view.pose.is_some()) {
                // Outside play it walks or stands: no kick, so no kick's report (its
                // senses went above, in every state).
                if let Some(c) = daemons_game::command(order, &robots[i], &out.believed, &homes) {
                    out.command = Some(c);
                    out.kick = None;
                    out.writes.retain(|(key, _)| *key != contract::KICK_KEY);
                }
            }
            if let Some(g) = &mut gc {
                g.judge_claim(robots[i].id, robots[i].view.goer, t);
            }
            if !out.writes.is_empty() {
                daemons[i].send(&setv_lines(&out.writes))?;
            }
            if let Some(cmd) = out.command {
                world.command_believed(i, cmd, &out.believed);
            }
            if let Some(k) = &out.kick {
                kick_attempts += 1;
                let off =
                    fusion::wrap_angle(world.robots[i].pose.theta_rad - out.believed.theta_rad);
                world.kick(i, k.direction_rad + off);
            }
            if robots[i].view.pose.is_some() && on_field(&gc, robots[i].id) {
                // The pose it played on: the layer's, brought up to now by its odometry.
                let pose = out.believed;
                let truth = world.robots[i].pose.at;
                pose_sq += truth.distance(pose.at).powi(2);
                pose_n += 1;
                if trace {
                    let layer = robots[i]
                        .view
                        .pose
                        .map_or(f64::NAN, |p| truth.distance(p.0.at));
                    let heading =
                        fusion::wrap_angle(world.robots[i].pose.theta_rad - pose.theta_rad);
                    eprintln!(
                        "pose t={t:.2} robot={} err={:.4} layer_err={:.4} heading={heading:.4} since_ms={:.1} fresh={} marks={marks_seen} at={:.2},{:.2} gaps={:.2?}",
                        robots[i].id,
                        truth.distance(pose.at),
                        layer,
                        robots[i].view.pose_since_s * 1e3,
                        fresh_view,
                        truth.x,
                        truth.y,
                        gaps(&world, i)
                    );
                }
            }
            // The messages its layer wrote, this tick's among them when the view is
            // fresh (the layer writes its world model before its tick count), into the
            // central reference on the world's clock: each holds at the tick its senses
            // were taken.
            let lwms = std::mem::take(
                &mut daemons[i]
                    .heard
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .lwms,
            );
            for bytes in lwms {
                match LocalWorldModel::from_bytes(&bytes, t) {
                    Ok(lwm) => {
                        central.lwm(robots[i].id, &lwm, t);
                        central_messages += 1;
                    }
                    Err(_) => central_refused += 1,
                }
            }
            ticked.push(i);
        }
        let visible = in_play
            && robots
                .iter()
                .any(|r| r.is_field_player() && r.sees_ball() && on_field(&gc, r.id));
        if visible {
            let truth = world.ball.at;
            let c = central.estimate_at(t);
            for &i in ticked.iter().filter(|&&i| on_field(&gc, robots[i].id)) {
                let r = &robots[i];
                let (Some(team), Some(c)) = (r.view.team_ball_now(0.0), c) else {
                    continue;
                };
                let e2 = team.distance(truth).powi(2);
                let c2 = (c.position() - fusion::nalgebra::Vector2::new(truth.x, truth.y))
                    .norm_squared();
                if trace {
                    eprintln!(
                        "trace t={t:.2} robot={} err={:.3} speed={:.2} team={team:?} truth={truth:?} sees={} behind_ms={:.1}",
                        r.id,
                        e2.sqrt(),
                        world.ball.velocity.norm(),
                        r.sees_ball(),
                        behind_us.last().copied().unwrap_or(0) as f64 / 1e3
                    );
                }
                team_sq += e2;
                central_sq += c2;
                team_n += 1;
                if !r.sees_ball()
                    && r.view
                        .own_ball
                        .is_none_or(|(b, s)| b.age_s + s > cfg.brain.team.ball_memory_s)
                {
                    blind_sq += e2;
                    blind_n += 1;
                }
            }
        }
        let goal = world.step(dt);
        if let Some(goal) = goal {
            if trace {
                eprintln!("goal t={t:.2} ball now {:?}", world.ball.at);
            }
            // The referee puts the ball back on the centre spot; each robot program tells
            // its layer, as the in-process robots are told.
            central.place(BallEstimate {
                t_s: t + dt,
                ..kick_off
            });
            if let Some(g) = &mut gc {
                // The referee's goal: Ready and Set, then a kick-off. The layers learn it
                // from the GC's packets (their scores) or their programs' whistles, as a
                // daemon on a field does.
                let for_us = goal == crate::field::Goal::For;
                for (i, spot) in g.goal(t + dt, for_us, &mut world, &robots, &homes, cfg) {
                    place(&mut daemons[i], &spot)?;
                }
            }
            for (d, r) in daemons.iter_mut().zip(&mut robots).filter(|_| gc.is_none()) {
                d.heard
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .resets_pending += 1;
                let (key, value) = r.ball_reset();
                // The GETV marks the reset's place in the relay's ordered output.
                d.send(&format!(
                    "SETV {key} {value}\nGETV {}\n",
                    contract::TICK_KEY
                ))?;
            }
        }
        if let Some(g) = &gc {
            g.hold(&mut world, cfg);
        }
        let goers: Vec<u8> = robots
            .iter()
            .filter(|r| r.is_field_player() && r.view.going && on_field(&gc, r.id))
            .map(|r| r.id)
            .collect();
        metrics.sample(t + dt, dt, visible, &goers);
        if trace {
            // Who each robot names and whether it goes, when that changes.
            let named: Vec<(u8, bool)> =
                robots.iter().map(|r| (r.view.goer, r.view.going)).collect();
            if named != last_named {
                let ball = world.ball.at;
                let d: Vec<String> = world
                    .robots
                    .iter()
                    .map(|b| format!("{:.2}", b.pose.at.distance(ball)))
                    .collect();
                eprintln!(
                    "goers t={:.2} named={named:?} distance=[{}]",
                    t + dt,
                    d.join(", ")
                );
                last_named = named;
            }
        }
        if let Some(o) = &outage_window {
            let near = |g: u8| {
                // The truth, for the figures only (as in process).
                let ball = world.ball.at;
                let distance = |i: usize| world.robots[i].pose.at.distance(ball);
                let field = (0..n)
                    .filter(|&i| robots[i].is_field_player() && on_field(&gc, robots[i].id))
                    .map(distance);
                let goer = robots.iter().position(|r| r.id == g).map(distance);
                super::acoustic::is_near(goer, field)
            };
            outage_figures.sample(o, t + dt, dt, visible, &goers, near);
        }
        if let Some(a) = &air {
            a.set_positions(world.robot_positions());
        }
        progress(t + dt);
    }
    let played_s = started.elapsed().as_secs_f64();
    let air = air.map(Air::stop);
    // What each daemon sent, and under `--outage` what its fallback did, from its own
    // counters.
    let mut names = vec!["frames_out"];
    if outage_window.is_some() {
        names.push("impair_dropped");
    }
    if air.is_some() {
        names.extend([
            "audio.fallback_sounded",
            "audio.fallback_heard",
            "audio.fallback_busy",
            "audio.heard",
        ]);
    }
    let ask: String = names
        .iter()
        .map(|name| format!("GETV {STATS_PREFIX}{name}\n"))
        .collect();
    for d in &mut daemons {
        d.send(&ask)?;
    }
    let answered = |d: &Daemon| {
        d.heard
            .lock()
            .is_ok_and(|h| names.iter().all(|name| h.stats.contains_key(*name)))
    };
    let deadline = Instant::now() + Duration::from_secs(3);
    while Instant::now() < deadline && !daemons.iter().all(answered) {
        std::thread::sleep(Duration::from_millis(10));
    }
    let stat = |d: &Daemon, name: &str| {
        d.heard
            .lock()
            .map_or(0, |h| h.stats.get(name).copied().unwrap_or(0))
    };
    let total = |name: &str| daemons.iter().map(|d| stat(d, name)).sum::<u64>();
    let per_robot: Vec<u64> = daemons.iter().map(|d| stat(d, "frames_out")).collect();
    let outage = outage_window.map(|o| DaemonsOutage {
        windows: outage_figures.windows(&o, cfg.acoustic.enabled),
        acoustic_sounded: total("audio.fallback_sounded"),
        acoustic_heard: total("audio.fallback_heard"),
        acoustic_busy: total("audio.fallback_busy"),
        audio_heard: total("audio.heard"),
        radio_dropped: total("impair_dropped"),
        air: air.clone(),
    });
    let relay_errors = daemons
        .iter()
        .map(|d| d.heard.lock().map_or(0, |h| h.errors))
        .sum();
    let relay_refusals: Vec<String> = daemons
        .iter()
        .flat_map(|d| {
            d.heard
                .lock()
                .map_or_else(|_| Vec::new(), |h| h.refusals.clone())
        })
        .take(3)
        .collect();
    // The frames still in flight when the daemons said what they sent, then the books.
    let game = gc.as_mut().map(|g| {
        std::thread::sleep(Duration::from_millis(50));
        g.count_frames(played_s);
        g.report()
    });
    drop(gc);
    for d in &mut daemons {
        let _ = d.send("QUIT\n");
    }
    drop(daemons);
    if opts.log_dir.is_none() {
        let _ = std::fs::remove_dir_all(&dir);
    }
    let rmse = |sq: f64, n: u64| {
        if n == 0 {
            f64::NAN
        } else {
            (sq / n as f64).sqrt()
        }
    };
    let r3 = |x: f64| (x * 1000.0).round() / 1000.0;
    let r4 = |x: f64| (x * 10_000.0).round() / 10_000.0;
    let team_rmse = rmse(team_sq, team_n);
    let central_rmse = rmse(central_sq, team_n);
    Ok(DaemonsReport {
        mode: "daemons",
        budget: cfg.budget.map(|b| b.to_string()),
        robots: n,
        duration_s: r3(played_s),
        preset: cfg.network.preset.name().to_string(),
        impair: spec,
        seed: cfg.seed,
        ball_visible_s: r3(metrics.visible_s),
        exactly_one_goer_pct: r3(metrics.exactly_one_pct()),
        conflict_pct: r3(metrics.conflict_pct()),
        no_goer_pct: r3(metrics.no_goer_pct()),
        longest_conflict_ms: r3(metrics.longest_conflict_s * 1e3),
        handovers: metrics.handovers,
        goals_for: world.goals_for,
        goals_against: world.goals_against,
        kick_attempts,
        team_messages_sent: per_robot.iter().sum(),
        messages_per_robot: per_robot,
        team_ball_rmse_m: r4(team_rmse),
        centralized_rmse_m: r4(central_rmse),
        central_messages,
        central_refused,
        rmse_ratio: r3(team_rmse / central_rmse),
        team_ball_samples: team_n,
        blind_samples: blind_n,
        blind_team_ball_rmse_m: r4(rmse(blind_sq, blind_n)),
        pose_rmse_m: r4(rmse(pose_sq, pose_n)),
        relay_errors,
        relay_refusals,
        late_steps,
        stale_views,
        view_lag_ms: Spread::of_us(view_lags_us),
        behind_ms: Spread::of_us(behind_us),
        clocks: clocks
            .iter()
            .map(|c| [c.offset().as_secs_f64(), c.drift_ppm()])
            .collect(),
        in_process: None,
        game,
        outage,
    })
}

/// Whether `HUDDLE_DAEMONS_TRACE` asks for the trace.
pub(super) fn trace() -> bool {
    std::env::var_os("HUDDLE_DAEMONS_TRACE").is_some()
}

/// Whether robot `id`'s figures are sampled now: always without a referee; under one,
/// in Playing and on the field.
fn on_field(gc: &Option<GcSide>, id: u8) -> bool {
    gc.as_ref().is_none_or(|g| g.playing() && !g.penalised(id))
}

/// How far robot `i` is from the nearest teammate's and the nearest opponent's body
/// centre, m (two bodies touch at 0.4 m), for the trace: in the drawn world odometry sees
/// only part of a shove, so bodies pressing on each other make pose errors.
pub(super) fn gaps(world: &World, i: usize) -> (f64, f64) {
    let me = world.robots[i].pose.at;
    let mate = world
        .robots
        .iter()
        .enumerate()
        .filter(|(j, _)| *j != i)
        .map(|(_, b)| b.pose.at.distance(me))
        .fold(f64::INFINITY, f64::min);
    let opp = world
        .opponents
        .iter()
        .map(|b| b.pose.at.distance(me))
        .fold(f64::INFINITY, f64::min);
    (mate, opp)
}
