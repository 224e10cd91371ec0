//! `huddle sim`: a simulated match of a whole team over a simulated network, and the
//! arbitration report. Also what `huddle` runs with no subcommand.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use huddle::sim::{NetworkConfig, SimConfig, Simulation};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use netsim::Preset;

use super::duration;

/// Arguments of `huddle sim`.
#[derive(Args, Debug, Clone)]
pub struct SimArgs {
    /// Robots on our team (robot 1 keeps goal when there are three or more).
    #[arg(long, default_value_t = 5)]
    pub robots: usize,
    /// Opponents on the field (obstacles that chase the ball).
    #[arg(long, default_value_t = 3)]
    pub opponents: usize,
    /// Simulated duration, with its unit: `300s`, `5min`.
    #[arg(long, default_value = "300s", value_parser = duration::parse)]
    pub duration: Duration,
    /// Network preset: lan, wlan, competition (power save off), competition-ps (multicast
    /// held to DTIM beacons).
    #[arg(long, default_value = "competition")]
    pub preset: Preset,
    /// DTIM period in beacons of 102.4 ms: multicast is held to every Nth beacon
    /// (competition-ps: 2). Given with another preset, it adds the hold.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=255))]
    pub dtim: Option<u32>,
    /// The team's message budget: `spl` (1200 per 20-minute game, 128-byte frames),
    /// `humanoid` (12,000, 512 bytes) or N/DURATION (`600/10min`); pooled by the robots,
    /// whose priority items (goer changes, kicks) share a room of one frame per robot
    /// beyond the pacing. Default: none.
    #[arg(long)]
    pub budget: Option<comms::BudgetSpec>,
    /// When robots send: every (each control tick), baseline (B-Human-style thresholds),
    /// voi (value of information). Default: voi under a budget, every without one.
    #[arg(long, value_enum)]
    pub policy: Option<huddle::sim::policy::SendPolicy>,
    /// The world: ideal (its physics are exactly the robots' calibration; ideal clocks)
    /// or drawn (physics drawn per match around the nominal field, which the robots'
    /// calibration keeps; start poses off by their σ; clocks with offsets and drifts;
    /// docs/sim-world.md).
    #[arg(long, value_enum, default_value = "drawn")]
    pub world: WorldKind,
    /// How frames travel: multicast, broadcast (SPL), unicast (one copy per teammate).
    #[arg(long, value_enum, default_value = "multicast")]
    pub transport: huddle::sim::Transport,
    /// Run the match once per point of a sweep and print one row each: `delay` (the
    /// one-way link delay at 0, 10, 20, 50, 100 and 200 ms, jitter half of it).
    #[arg(long, value_enum)]
    pub sweep: Option<Sweep>,
    /// Give every reference filter this acceleration noise (m²/s³) instead of its tuned
    /// one: for tuning the references, each for its own RMSE.
    #[arg(long, hide = true)]
    pub reference_q: Option<f64>,
    /// Give every reference filter this growth of its acceleration noise per m/s of speed
    /// (with `--reference-q` as the noise at rest): for tuning the references.
    #[arg(long, hide = true)]
    pub reference_q_speed: Option<f64>,
    /// Give the robots the ball model before the field model, for comparison: the rolling
    /// model (exponential decay 1/s, no boards) with this acceleration noise (m²/s³),
    /// pose-error sharing 10, no push reports, no widening at contact.
    #[arg(long, hide = true)]
    pub team_q: Option<f64>,
    /// Seed the network's loss and latency draws with this instead of `--seed` (the
    /// match's world the same): for measuring how far a figure moves with the network's
    /// luck alone (#29).
    #[arg(long, hide = true)]
    pub net_seed: Option<u64>,
    /// Place every teammate message in the delivery reference this many ms after its true
    /// build time (the match itself unchanged): for measuring the delivery ratio's own
    /// sensitivity (#29).
    #[arg(long, hide = true, allow_hyphen_values = true)]
    pub delivery_shift_ms: Option<f64>,
    /// Feed the delivery reference what the team's GWM had: `stamps` (each teammate
    /// message at the team's own stamp), `own` (the robot's own message as published), or
    /// `both` (#29's diagnostics).
    #[arg(long, hide = true, value_enum)]
    pub delivery_as_team: Option<DeliveryAsTeam>,
    /// Place each teammate message in the delivery reference up to this many ms off its
    /// true build time (uniform, a fixed hash per message; salted by `--net-seed` or
    /// `--seed`): a stamp error of the team's size that carries no information (#29).
    #[arg(long, hide = true)]
    pub delivery_jitter_ms: Option<f64>,
    /// Tune the robots' field ball model: comma-separated `q0=…` (noise at rest, m²/s³),
    /// `q1=…` (its growth per m/s), `sharing=…` (pose-error sharing k), `rest_sigma=…`,
    /// `boards=0|1`, `push=0|1` (own pushes reported), `push_prob=…`, `push_every=…` (s).
    #[arg(long, hide = true)]
    pub team_ball: Option<String>,
    /// Independent loss per receiver, `20%` or `0.2` (replaces the preset's loss model).
    #[arg(long, value_parser = parse_fraction)]
    pub loss: Option<f64>,
    /// One-way latency, `50ms` (replaces the preset's).
    #[arg(long, value_parser = duration::parse)]
    pub latency: Option<Duration>,
    /// Latency jitter, `20ms` (replaces the preset's).
    #[arg(long, value_parser = duration::parse)]
    pub jitter: Option<Duration>,
    /// Seed of everything random: the same seed gives the same match.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write a picture of the field and the goer timeline to this SVG file.
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Print the report as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Write what a listener beside robot 1 hears to this pcapng file (as `huddle
    /// record` does), for `huddle replay`.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Pace the match at N times real time (`--speed 1`: real time); without it, as fast
    /// as it computes.
    #[arg(long)]
    pub speed: Option<f64>,
    /// Serve the live team monitor on this address (`127.0.0.1:8080`) while the match
    /// runs, and after it until Ctrl-C; paced at real time unless --speed says otherwise.
    #[arg(long, value_name = "ADDR")]
    pub monitor: Option<std::net::SocketAddr>,
    /// Switch robot ID off at simulated time T (it stops and falls silent): `3@20s`.
    #[arg(long, value_name = "ID@T", value_parser = super::monitor_sim::parse_kill)]
    pub kill: Vec<(u8, Duration)>,
    /// A WLAN outage, DURATION@START: every link down for DURATION from START (`30s@120s`).
    /// The report adds the outage's arbitration figures.
    #[arg(long, value_name = "DURATION@START", value_parser = parse_outage)]
    pub outage: Option<(Duration, Duration)>,
    /// Fall back on sound when the radio is stale: each robot sounds its claim as tones
    /// in its own slot and decides on what its microphone's decoder hears.
    #[arg(long)]
    pub acoustic: bool,
    /// Tone length of the acoustic messages (`150ms`; 60 ms to 5 s).
    #[arg(long, value_parser = duration::parse)]
    pub tone: Option<Duration>,
    /// Silence after each acoustic message before the next robot's slot (`300ms`).
    #[arg(long, value_parser = duration::parse)]
    pub guard: Option<Duration>,
    /// Hysteresis margin of the acoustic fallback's decision, m (default: the
    /// arbitration's).
    #[arg(long, value_name = "M")]
    pub acoustic_hysteresis: Option<f64>,
    /// Hold a teammate's claim to be going at full weight even when its last slot went
    /// by unheard (default: such a claim loses the goer's margin).
    #[arg(long)]
    pub acoustic_no_doubt: bool,
    /// The crowd's noise as the in-band SNR of one robot's sound heard 1 m away, dB.
    #[arg(long, value_name = "DB", allow_hyphen_values = true)]
    pub crowd_snr: Option<f64>,
    /// The room's reverberation time T60 (`1s`).
    #[arg(long, value_parser = duration::parse)]
    pub t60: Option<Duration>,
    /// Distance at which the room's reverberant field is as loud as a robot's direct
    /// sound, m.
    #[arg(long, value_name = "M")]
    pub critical_distance: Option<f64>,
    /// Run each robot's team layer in a real `huddle daemon` on loopback (a scratch
    /// multicast group, each daemon's sends impaired as the network says), the simulated
    /// robots feeding their daemons through the relay as robot programs do, in real
    /// time. The report adds the same match in process for comparison.
    #[arg(long)]
    pub daemons: bool,
    /// With --daemons: each daemon's `--impair` spec (default: the match's network).
    #[arg(long, value_name = "SPEC", requires = "daemons")]
    pub impair: Option<String>,
    /// With --daemons: keep each daemon's log (at info level) in this directory.
    #[arg(long, value_name = "DIR", requires = "daemons")]
    pub daemon_logs: Option<PathBuf>,
    /// Play a whole game under a simulated GameController: `full` (two 10-minute halves
    /// and a 10-minute break, Initial/Standby/Ready/Set/Playing/Finished, goals with their
    /// Ready/Set restarts, two 45 s penalties, the GC's count of the team's messages).
    /// The robots hear its packets and, under `--budget spl`, pace by its figures as
    /// `huddle daemon` does; the report says whether the team was ever illegal.
    /// `restarts`: one 10-minute half under the same referee, no break, no penalties
    /// (the 600 s run restarting from the formation after each goal, as a game does).
    /// `--duration` is ignored: the game ends when the referee says so. With --daemons
    /// the referee sends its packets over UDP on loopback to each daemon's listener
    /// (real time: a game lasts its length).
    #[arg(long, value_enum)]
    pub game: Option<GameKind>,
    /// With --game: how late the referee's packets show the game. `gc3` (the default):
    /// as GameController3 sends it with the league's delays (Set for 15 s after play
    /// starts, Playing with the old score for 15 s after a goal, Standby up to 45 s into a
    /// half's Ready); `none`: the true state at once (GC3's `test.no_delay`, the referee
    /// before the eleventh session).
    #[arg(long, value_enum, default_value = "gc3", requires = "game")]
    pub gc_delays: GcDelayKind,
    /// With --game: the chance each robot program hears each referee's whistle (play
    /// starts, a goal, Standby → Ready), 0.2–1.0 s late, and tells its team layer
    /// (`local.var.robot.whistle`; with --daemons it writes the key to its daemon over
    /// the relay); 0: no program hears one, the team goes by the GC's packets alone.
    #[arg(long, value_name = "P", default_value_t = 0.9, requires = "game")]
    pub whistle: f64,
}

/// How late `--game`'s packets show the game (`--gc-delays`).
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum GcDelayKind {
    /// GameController3's delays with the league's parameters (15 s, 15 s, 45 s).
    Gc3,
    /// No delay: the packets show the true state.
    None,
}

/// A game `--game` plays.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum GameKind {
    /// Two 10-minute halves, a 10-minute break, two penalties.
    Full,
    /// One 10-minute half, no break, no penalties: the 600 s run with the game's
    /// kick-off sequence (Ready, Set, the whistle) at its start and after every goal,
    /// the like-for-like counterpart of the full game (#34).
    Restarts,
}

/// `30s@120s`: an outage of 30 s starting at 120 s.
pub(crate) fn parse_outage(s: &str) -> Result<(Duration, Duration), String> {
    let (d, at) = s
        .split_once('@')
        .ok_or_else(|| format!("outage {s:?}: expected DURATION@START, e.g. 30s@120s"))?;
    Ok((duration::parse(d.trim())?, duration::parse(at.trim())?))
}

/// What the delivery reference is fed from the team's GWM (`--delivery-as-team`, #29's
/// diagnostics); a value clap does not know is refused, not read as "none".
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum DeliveryAsTeam {
    /// Each teammate message at the team's own stamp.
    Stamps,
    /// The robot's own message as published.
    Own,
    /// Both.
    Both,
}

impl Default for SimArgs {
    fn default() -> Self {
        Self {
            robots: 5,
            opponents: 3,
            duration: Duration::from_secs(300),
            preset: Preset::Competition,
            loss: None,
            latency: None,
            jitter: None,
            dtim: None,
            budget: None,
            policy: None,
            world: WorldKind::Drawn,
            transport: huddle::sim::Transport::Multicast,
            sweep: None,
            reference_q: None,
            reference_q_speed: None,
            team_q: None,
            net_seed: None,
            delivery_shift_ms: None,
            delivery_as_team: None,
            delivery_jitter_ms: None,
            team_ball: None,
            seed: 1,
            svg: None,
            json: false,
            record: None,
            speed: None,
            monitor: None,
            kill: Vec::new(),
            outage: None,
            acoustic: false,
            tone: None,
            guard: None,
            acoustic_hysteresis: None,
            acoustic_no_doubt: false,
            crowd_snr: None,
            t60: None,
            critical_distance: None,
            daemons: false,
            impair: None,
            daemon_logs: None,
            game: None,
            gc_delays: GcDelayKind::Gc3,
            whistle: 0.9,
        }
    }
}

/// What `--sweep` varies.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sweep {
    /// The one-way link delay (jitter half of it).
    Delay,
}

/// The delays `--sweep delay` runs, ms.
const SWEEP_DELAYS_MS: [u64; 6] = [0, 10, 20, 50, 100, 200];

/// `20%` or `0.2`, within 0..=1.
fn parse_fraction(s: &str) -> Result<f64, String> {
    netsim::parse_probability("probability", s.trim()).map_err(|e| e.to_string())
}

/// Run `huddle sim`.
pub fn run(args: SimArgs) -> Result<()> {
    if args.robots == 0 {
        bail!("--robots must be at least 1");
    }
    if let Some(sweep) = args.sweep {
        return run_sweep(&args, sweep);
    }
    let cfg = config(&args);
    if args.daemons {
        return run_daemons(&args, cfg);
    }
    let length_ms = (cfg.game.as_ref().map_or(cfg.duration_s, |g| g.length_s()) * 1e3) as u64;
    let mut sim = Simulation::new(cfg).context("setting up the simulation")?;
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(Some(length_ms), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} simulating {bar:40} {pos}/{len} ms simulated ({eta})",
        )
        .expect("a valid template"),
    );
    let started = Instant::now();
    let stepping = super::monitor_sim::Stepping {
        record: args.record.as_deref(),
        speed: args.speed,
        monitor: args.monitor,
        kill: &args.kill,
        robots: args.robots,
    };
    if stepping.wanted() {
        super::monitor_sim::run(&mut sim, &stepping, &bar)?;
    }
    sim.run(|t_s| bar.set_position((t_s * 1e3) as u64));
    let wall_s = started.elapsed().as_secs_f64();
    bar.finish_and_clear();
    let report = sim.report(wall_s);
    if let Some(path) = &args.svg {
        std::fs::write(path, huddle::sim::svg::render(&sim))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if args.json {
        outln!("{}", serde_json::to_string(&report)?);
    } else {
        outln!("{report}");
        if let Some(path) = &args.svg {
            outln!("picture               {}", path.display());
        }
    }
    Ok(())
}

/// `--daemons`: the match with each robot's team layer in a daemon, then the same match
/// in process for the ratio.
fn run_daemons(args: &SimArgs, cfg: SimConfig) -> Result<()> {
    if args.svg.is_some()
        || args.record.is_some()
        || args.monitor.is_some()
        || !args.kill.is_empty()
    {
        bail!("--daemons does not take --svg, --record, --monitor or --kill");
    }
    let opts = huddle::sim::daemons::DaemonsOptions {
        exe: std::env::current_exe().context("finding the huddle binary")?,
        impair: args.impair.clone(),
        log_dir: args.daemon_logs.clone(),
    };
    let bar = if std::io::stderr().is_terminal() {
        let length_s = cfg
            .game
            .as_ref()
            .map_or(args.duration.as_secs_f64(), |g| g.length_s());
        ProgressBar::with_draw_target(Some((length_s * 1e3) as u64), ProgressDrawTarget::stderr())
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("{spinner} daemons playing {bar:40} {pos}/{len} ms ({eta})")
            .expect("a valid template"),
    );
    let mut report =
        huddle::sim::daemons::run(&cfg, &opts, |t_s| bar.set_position((t_s * 1e3) as u64))
            .context("playing the match with daemons")?;
    bar.finish_and_clear();
    report.in_process = Some(
        huddle::sim::daemons::in_process(&cfg, report.team_ball_rmse_m)
            .context("playing the match in process")?,
    );
    if args.json {
        outln!("{}", serde_json::to_string(&report)?);
    } else {
        outln!("{report}");
    }
    Ok(())
}

/// Which world a match is played in (`--world`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum WorldKind {
    /// Physics exactly the robots' calibration, ideal clocks.
    Ideal,
    /// Physics drawn per match around the nominal field, start errors, real clocks.
    Drawn,
}

/// The match `args` describe.
fn config(args: &SimArgs) -> SimConfig {
    let mut brain = huddle::sim::BrainConfig::default();
    brain.team.send_policy = team::policy::SendPolicy::default_for(args.budget.is_some());
    if let Some(p) = args.policy {
        brain.team.send_policy = p;
    }
    if let Some(q) = args.team_q {
        let wm = &mut brain.team.world_model;
        wm.local.ball.model = fusion::BallModel::Rolling {
            friction_per_s: 1.0,
            accel_noise_m2_per_s3: q,
        };
        wm.local.ball.pose_error_sharing = 10.0;
        wm.push_gain = 0.0;
        wm.contact_horizon_s = 0.0;
        wm.global.ball = wm.local.ball.model;
    }
    if let Some(spec) = &args.team_ball {
        tune_team_ball(&mut brain.team.world_model, spec);
    }
    let game = args.game.map(|g| {
        let mut script = match g {
            GameKind::Full => huddle::sim::referee::GameScript::spl_full(args.robots),
            GameKind::Restarts => huddle::sim::referee::GameScript::one_half(),
        };
        script.delays = match args.gc_delays {
            GcDelayKind::Gc3 => huddle::sim::referee::GcDelays::gc3(),
            GcDelayKind::None => huddle::sim::referee::GcDelays::none(),
        };
        script.whistle.p_heard = args.whistle.clamp(0.0, 1.0);
        script
    });
    // A game ends when its referee says so; the duration only caps it (an hour of goals).
    let duration_s = game
        .as_ref()
        .map_or(args.duration.as_secs_f64(), |g| g.length_s() + 3600.0);
    SimConfig {
        brain,
        drawn_world: args.world == WorldKind::Drawn,
        robots: args.robots,
        opponents: args.opponents,
        duration_s,
        game,
        network: NetworkConfig {
            preset: args.preset,
            loss: args.loss,
            latency: args.latency,
            jitter: args.jitter,
            dtim_period: args.dtim,
        },
        seed: args.seed,
        budget: args.budget,
        transport: args.transport,
        outage: args
            .outage
            .map(|(d, at)| huddle::sim::acoustic::OutageConfig {
                start_s: at.as_secs_f64(),
                duration_s: d.as_secs_f64(),
            }),
        acoustic: {
            let mut a = huddle::sim::acoustic::AcousticConfig {
                enabled: args.acoustic,
                ..Default::default()
            };
            if let Some(t) = args.tone {
                a.tone_s = t.as_secs_f64();
            }
            if let Some(g) = args.guard {
                a.guard_s = g.as_secs_f64();
            }
            a.doubt_going = !args.acoustic_no_doubt;
            if args.acoustic_hysteresis.is_some() {
                a.hysteresis_m = args.acoustic_hysteresis;
            }
            if let Some(snr) = args.crowd_snr {
                a.crowd_snr_db_at_1m = snr;
            }
            if let Some(m) = args.critical_distance {
                a.critical_distance_m = m;
            }
            if let Some(t) = args.t60 {
                a.t60_s = t.as_secs_f64();
            }
            a
        },
        references: match args.reference_q {
            Some(q) => huddle::sim::ReferenceConfig::with_q(
                huddle::sim::WorldModelConfig::default().local.ball,
                q,
                args.reference_q_speed.unwrap_or(0.0),
            ),
            None => huddle::sim::ReferenceConfig::default(),
        }
        .with_delivery_shift(args.delivery_shift_ms.unwrap_or(0.0) / 1000.0)
        .with_delivery_as_team(match args.delivery_as_team {
            Some(DeliveryAsTeam::Stamps) => (true, false),
            Some(DeliveryAsTeam::Own) => (false, true),
            Some(DeliveryAsTeam::Both) => (true, true),
            None => (false, false),
        })
        .with_delivery_jitter(
            args.delivery_jitter_ms.unwrap_or(0.0) / 1000.0,
            args.net_seed.unwrap_or(args.seed),
        ),
        network_seed: args.net_seed,
        ..SimConfig::default()
    }
}

/// `--team-ball`'s tuning settings (a hidden flag: an unknown or malformed one is ignored
/// with a warning).
fn tune_team_ball(wm: &mut huddle::sim::WorldModelConfig, spec: &str) {
    for item in spec.split(',').filter(|s| !s.trim().is_empty()) {
        let Some((k, v)) = item.split_once('=') else {
            tracing::warn!("--team-ball: {item:?} is not key=value");
            continue;
        };
        let Ok(v) = v.trim().parse::<f64>() else {
            tracing::warn!("--team-ball: {item:?} is not a number");
            continue;
        };
        let model = &mut wm.local.ball.model;
        match (k.trim(), model) {
            ("q0", fusion::BallModel::Field(f)) => f.still_accel_noise_m2_per_s3 = v,
            ("q1", fusion::BallModel::Field(f)) => f.accel_noise_per_speed = v,
            ("s0", fusion::BallModel::Field(f)) => f.still_below_mps = v,
            ("rest_sigma", fusion::BallModel::Field(f)) => {
                if let Some(b) = &mut f.boards {
                    b.restitution_sigma = v;
                }
            }
            ("boards", fusion::BallModel::Field(f)) if v == 0.0 => f.boards = None,
            ("sharing", _) => wm.local.ball.pose_error_sharing = v,
            ("push", _) if v == 0.0 => wm.push_gain = 0.0,
            ("push_prob", _) => wm.push_min_contact_prob = v,
            ("push_every", _) => wm.push_report_interval_s = v,
            ("push_min", _) => wm.push_min_change_mps = v,
            ("contact_horizon", _) => wm.contact_horizon_s = v,
            ("contact_margin", _) => wm.contact_margin_m = v,
            ("kick_hazard", _) => wm.kick_hazard_per_s = v,
            ("kick_hazard_window", _) => wm.kick_hazard_window_s = v,
            ("own_restart", _) => wm.global.own_restart_after = v as u32,
            ("mate_restart", _) => wm.global.teammate_restart_after = v as u32,
            ("gate", _) => wm.global.gate_chi2 = v,
            ("push_sigma", _) => wm.push_sigma_m = v,
            // The pose filter's landmark gate (χ², 2 dof; 0: ungated), for tuning it.
            ("pose_gate", _) => wm.local.pose_gate_chi2 = (v > 0.0).then_some(v),
            _ => tracing::warn!("--team-ball: {item:?} not applied"),
        }
    }
    wm.global.ball = wm.local.ball.model;
}

/// `--sweep`: the same match at each point, two at a time (one per core), one row each
/// (or one JSON array of reports).
fn run_sweep(args: &SimArgs, sweep: Sweep) -> Result<()> {
    if args.svg.is_some() || args.record.is_some() || args.monitor.is_some() {
        bail!("--sweep runs many matches: --svg, --record and --monitor take one");
    }
    let configs: Vec<SimConfig> = match sweep {
        Sweep::Delay => SWEEP_DELAYS_MS
            .iter()
            .map(|&ms| {
                let mut cfg = config(args);
                cfg.network.latency = Some(Duration::from_millis(ms));
                cfg.network.jitter = Some(Duration::from_millis(ms) / 2);
                cfg
            })
            .collect(),
    };
    let workers = std::thread::available_parallelism().map_or(1, |n| n.get().min(4));
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results: std::sync::Mutex<Vec<Option<huddle::sim::Report>>> =
        std::sync::Mutex::new(vec![None; configs.len()]);
    std::thread::scope(|scope| -> Result<()> {
        let handles: Vec<_> = (0..workers)
            .map(|_| {
                scope.spawn(|| -> Result<()> {
                    loop {
                        let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(cfg) = configs.get(k) else {
                            return Ok(());
                        };
                        let started = Instant::now();
                        let mut sim =
                            Simulation::new(cfg.clone()).context("setting up the simulation")?;
                        sim.run(|_| {});
                        let report = sim.report(started.elapsed().as_secs_f64());
                        results.lock().expect("no worker panics")[k] = Some(report);
                    }
                })
            })
            .collect();
        for h in handles {
            h.join().expect("a sweep worker panicked")?;
        }
        Ok(())
    })?;
    let reports: Vec<huddle::sim::Report> = results
        .into_inner()
        .expect("no worker panics")
        .into_iter()
        .flatten()
        .collect();
    if args.json {
        outln!("{}", serde_json::to_string(&reports)?);
        return Ok(());
    }
    outln!(
        "huddle sim --sweep delay: {} robots, {:.0} s each, preset {}, seed {}",
        args.robots,
        args.duration.as_secs_f64(),
        args.preset,
        args.seed
    );
    outln!("{}", huddle::sim::SweepRow::header());
    for r in &reports {
        outln!("{}", huddle::sim::SweepRow(r));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_and_fractions_parse_as_written_in_the_issue() {
        assert_eq!(duration::parse("300s"), Ok(Duration::from_secs(300)));
        assert_eq!(duration::parse("50ms"), Ok(Duration::from_millis(50)));
        assert_eq!(duration::parse("5min"), Ok(Duration::from_secs(300)));
        assert!(duration::parse("5 parsecs").is_err());
        assert_eq!(parse_fraction("20%"), Ok(0.2));
        assert_eq!(parse_fraction("0.3"), Ok(0.3));
        assert!(parse_fraction("120%").is_err());
    }

    #[test]
    fn a_duration_without_a_unit_is_refused_not_guessed() {
        // Read as seconds, `--latency 50` would be a typo that silently ruins a run.
        let err = duration::parse("50").expect_err("no unit");
        assert!(
            err.contains("50ms") && err.contains("50s"),
            "the error shows the form: {err}"
        );
    }
}
