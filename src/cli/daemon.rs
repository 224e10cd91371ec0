//! `huddle daemon`: one robot's replica on the team's multicast group (or broadcast
//! port, or unicast peers: `--transport`), with the relay port for programs in any
//! language (isocrob-2000's Proxy and Relay μAgents).

use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;

use super::duration;
use super::relay::RelayTarget;
use super::transport::TransportArgs;
use comms::ReplicaConfig;
use driver::{resolve_iface, Driver, DriverConfig};
use huddle::impair::LinkImpairment;

/// Arguments of `huddle daemon`.
#[derive(Args, Debug, Clone)]
pub struct DaemonArgs {
    /// This robot's id, 1..=254 (default: the ROBOT_ID environment variable).
    #[arg(long, value_parser = clap::value_parser!(u8).range(1..=254))]
    pub id: Option<u8>,
    /// Team id: frames of other teams are dropped.
    #[arg(long, default_value_t = 0)]
    pub team: u8,
    /// --transport, --group, --port, --broadcast.
    #[command(flatten)]
    pub transport: TransportArgs,
    /// Interface, by name (wlan0) or IPv4 address: multicast membership and
    /// IP_MULTICAST_IF, the broadcast address, the unicast address. Loopback by
    /// default, so nothing leaves this machine unless asked.
    #[arg(long, default_value = "127.0.0.1")]
    pub iface: String,
    /// Also send every frame by unicast to this teammate (repeatable); with --transport
    /// unicast, to these only (then at least one is needed). Unicast is received on
    /// <iface>:<port> from the listed peers only; without --peer, none is.
    #[arg(long = "peer", value_name = "ADDR:PORT")]
    pub peers: Vec<SocketAddr>,
    /// Relay listening address: host:port, a port (on 127.0.0.1) or a host name (port
    /// 2001); any other than loopback must be given explicitly.
    #[arg(long, env = "HUDDLE_RELAY", default_value = "127.0.0.1:2001")]
    pub relay: RelayTarget,
    /// Relay clients served at once: a connection beyond gets one line `ERR 503 too many
    /// relay clients ...` and is closed (counted in `huddle stats` as
    /// relay_clients_refused); clients already connected are unaffected.
    #[arg(long, value_name = "N", default_value_t = driver::DEFAULT_MAX_RELAY_CLIENTS as u32,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub max_clients: u32,
    /// Directory of config.dat and config-<id>.dat.
    #[arg(long, default_value = ".")]
    pub config_dir: PathBuf,
    /// Team key file: frames are tagged with HMAC-SHA256 under its contents (trailing
    /// whitespace ignored); untagged or badly tagged frames are dropped.
    #[arg(long)]
    pub key_file: Option<PathBuf>,
    /// Refresh period of every global value (`100ms`, `1s`).
    #[arg(long, default_value = "100ms", value_parser = duration::parse_positive)]
    pub refresh: Duration,
    /// The team's message budget: `spl` (1200 per 20-minute game, frames of at most 128
    /// bytes), `humanoid` (12,000, 512 bytes) or N/DURATION (`600/10min`). This robot
    /// spends its equal share (see --team-size), paced over the game from the daemon's
    /// start, a fifth kept for priority items; frames never exceed the league's payload
    /// and a value that cannot fit one is refused at SETV. With a GameController
    /// (--gamecontroller, on by default with `spl`), the pacing follows its game clock,
    /// only the states it counts spend messages, and its count of the team's messages
    /// left is the authority: nothing goes within a margin of its 0. Default: no budget.
    #[arg(long, value_name = "SPEC")]
    pub budget: Option<comms::BudgetSpec>,
    /// Robots sharing the --budget.
    #[arg(long, default_value_t = 5, value_parser = clap::value_parser!(u8).range(1..=254))]
    pub team_size: u8,
    /// Pool the --budget with the team: a robot with nothing to say leaves its share to
    /// teammates that have, each knowing the team's spending from teammates' frame
    /// counters, and priority items share the team's room of one frame per robot beyond
    /// the pacing (instead of a fifth of each share). Only when every robot of the team runs huddle with the same --budget:
    /// the frames of a teammate that does not count (other software) use up the pool.
    #[arg(long, requires = "budget")]
    pub budget_pool: bool,
    /// Do not run the team layer (world model, team ball, should-I-go, sending policy:
    /// docs/team-layer.md). It is on by default, and stays dormant, sending nothing of
    /// its own, until a robot program writes `local.var.robot.pose` or
    /// `local.var.robot.odometry`.
    #[arg(long)]
    pub no_team_layer: bool,
    /// The team layer's sending policy: every (each control tick), baseline (B-Human-style
    /// thresholds), voi (value of information). Default: voi under a --budget, every
    /// without one.
    #[arg(long, value_enum)]
    pub policy: Option<team::SendPolicy>,
    /// The WLAN's expected one-way delay (`10ms`): the team layer's arbitration
    /// compensates a teammate's claim for it, as the simulator's robots do for theirs.
    /// Default: none.
    #[arg(long, value_name = "DURATION", value_parser = duration::parse)]
    pub latency_compensation: Option<std::time::Duration>,
    /// Listen to the league's GameController (RoboCup SPL, UDP port 3838): the game's
    /// state, penalties and score go to `local.var.gc.*`, this robot's status (RGrt) goes
    /// back to it, and under --budget the pacing follows its clock and its count of the
    /// team's messages. On by default with --budget spl.
    #[arg(long, overrides_with = "no_gamecontroller")]
    pub gamecontroller: bool,
    /// Do not listen to a GameController, even with --budget spl.
    #[arg(long, overrides_with = "gamecontroller")]
    pub no_gamecontroller: bool,
    /// Where the GameController's packets are received (its broadcasts reach a socket
    /// bound to every interface only).
    #[arg(long, value_name = "ADDR:PORT", default_value = "0.0.0.0:3838")]
    pub gc_listen: SocketAddr,
    /// The port this robot's status packets go to on the GameController's address.
    #[arg(long, value_name = "PORT", default_value_t = 3939)]
    pub gc_status_port: u16,
    /// Multicast TTL.
    #[arg(long, default_value_t = 1)]
    pub ttl: u32,
    /// Impair every outgoing datagram with netsim's link model, to rehearse a bad WLAN:
    /// a netsim spec such as `loss=20%,delay=50ms,jitter=20ms` or `preset=competition`
    /// (then refined: `preset=competition,loss=5%`). Outgoing only: with every robot
    /// impaired, each direction is impaired once.
    #[arg(long, value_name = "SPEC")]
    pub impair: Option<String>,
    /// Seed of the impairment's random draws (default: the robot id, so that robots
    /// of one team lose different frames and a rerun draws the same fates).
    #[arg(long, value_name = "N")]
    pub impair_seed: Option<u64>,
    /// Rehearse a WLAN outage: every outgoing datagram is lost for DURATION from START
    /// after this daemon's start (`30s@20s`), as `huddle sim --outage`. Give every robot
    /// the same outage and the team's radio is silent both ways (with --audio-fallback,
    /// the team then decides who goes by sound).
    #[arg(long, value_name = "DURATION@START", value_parser = crate::cli::sim::parse_outage)]
    pub outage: Option<(Duration, Duration)>,
    /// Stop (as on SIGTERM) when process PID, this daemon's parent, exits: for a launcher
    /// or supervisor that starts the daemon and must not leave it running if it dies
    /// itself (Linux; `huddle sim --daemons` passes its own). Refused if PID is not the
    /// parent: it has already exited.
    #[arg(long, value_name = "PID")]
    pub parent_pid: Option<u32>,
    /// For tests and `huddle sim --daemons`: this daemon's clock reads DURATION when it
    /// starts, as if its robot's clock had been set apart from its teammates'. The
    /// replica, the team layer and every age on the relay run on that clock, and the
    /// teammates estimate it from echoes as they do a real robot's. A robot on the field
    /// needs neither this nor --clock-drift-ppm.
    #[arg(long, value_name = "DURATION", value_parser = duration::parse, help_heading = "Testing")]
    pub clock_offset: Option<Duration>,
    /// For tests and `huddle sim --daemons`: this daemon's clock gains PPM microseconds a
    /// second (loses, if negative), as a robot's crystal does; within ±100000.
    #[arg(
        long,
        value_name = "PPM",
        allow_negative_numbers = true,
        help_heading = "Testing"
    )]
    pub clock_drift_ppm: Option<f64>,
    #[command(flatten)]
    pub audio: AudioFlags,
}

/// The daemon's acoustic messaging (`huddle daemon --audio-in … --audio-out …`).
#[derive(Args, Debug, Clone)]
#[command(next_help_heading = "Acoustic messaging")]
pub struct AudioFlags {
    /// Listen: run CMD with `sh -c` and decode its stdout as raw mono s16le PCM at
    /// --audio-rate (`arecord -t raw -f S16_LE -r 16000 -c 1`, `cat msg.raw`,
    /// `sox msg.wav -t raw -r 16000 -e signed -b 16 -c 1 -`). Each decoded message is
    /// written once to --audio-heard as the string `seq=N kind=short|long sender=S
    /// data=D start_us=T snr_db=X` (T: when it began, µs on this daemon's clock, as the
    /// stats' last_heard_us). See --audio-in-restart for when CMD ends.
    #[arg(long, value_name = "CMD")]
    pub audio_in: Option<String>,
    /// Speak: run CMD with `sh -c` once and write raw mono s16le PCM to its stdin
    /// (`aplay -t raw -f S16_LE -r 16000 -c 1`, `cat > said.raw`). A relay client says a
    /// message with `SETV local.var.audio.say "short 1 7"` (`[short|long] SENDER DATA`,
    /// SENDER 0-2, DATA 0-20 short or 0-440 long): an invalid one is ERR 412, a full
    /// queue ERR 430. Messages sound one at a time in order, each followed by
    /// --audio-gap of silence: one per frames x --audio-tone + --audio-gap (2 s for a
    /// short, 3 s for a long message at the defaults). If CMD exits, the message being
    /// written is lost (counted) and CMD restarts for the next one (backoff 1 s .. 30 s).
    #[arg(long, value_name = "CMD")]
    pub audio_out: Option<String>,
    /// Sample rate of both pipes, Hz.
    #[arg(long, value_name = "HZ", default_value_t = 16_000)]
    pub audio_rate: u32,
    /// Tone duration (one frame) the team uses, as `huddle audio --duration`.
    #[arg(long, value_name = "DURATION", default_value = "1s", value_parser = duration::parse_positive)]
    pub audio_tone: Duration,
    /// Silence after each message said.
    #[arg(long, value_name = "DURATION", default_value = "1s", value_parser = duration::parse)]
    pub audio_gap: Duration,
    /// Messages that may wait to be said besides the one sounding.
    #[arg(long, value_name = "N", default_value_t = 8)]
    pub audio_queue: usize,
    /// Key of heard messages: `*.var.audio.heard` (the team sees what this robot heard)
    /// or `local.var.audio.heard` (this robot only).
    #[arg(long, value_name = "KEY", default_value = "*.var.audio.heard")]
    pub audio_heard: String,
    /// When --audio-in's command runs again after it ends: `on-failure` (non-zero
    /// status, signal, or it cannot start; status 0 is the end of the stream, e.g. a
    /// file played once), `always`, `never`. Restarts wait 1 s, doubling to 30 s (back
    /// to 1 s after a run of 30 s). Counters: `huddle stats` (audio.*).
    #[arg(long, value_enum, value_name = "WHEN", default_value_t = RestartFlag::OnFailure)]
    pub audio_in_restart: RestartFlag,
    /// The team layer's acoustic fallback: while no teammate's claim has come by radio
    /// within the arbitration's staleness limit (the WLAN failed), this robot sounds its
    /// should-I-go claim in its own slot of a cycle on the team clock (one slot per field
    /// player, robot 1 left out in teams of 3 or more; a slot is --audio-tone +
    /// --audio-fallback-guard), and the team decides who goes on the claims each robot's
    /// decoder hears. Needs --audio-in, --audio-out, the team layer and the `three` plan;
    /// a tone of 400ms suits a hall (1 s works, slower). `say` messages still go out,
    /// but a slot that comes while one waits or sounds is let go (audio.fallback_busy).
    #[arg(long)]
    pub audio_fallback: bool,
    /// Silence after each fallback claim before the next robot's slot: it must cover the
    /// room's tail, the decoder's end test and the team clock's error.
    #[arg(long, value_name = "DURATION", default_value = "300ms", value_parser = duration::parse)]
    pub audio_fallback_guard: Duration,
    /// Team plan every robot of the team speaks, as `huddle audio --team`: `three` (the
    /// seed's: SENDER 0-2, DATA 0-20 short, 0-440 long), `six` (ROBOT 0-5, VALUE 0-9
    /// short, 0-99 long) or `checked` (ROBOT 0-2, VALUE 0-9 short, 0-120 long; a long
    /// message cut to one frame, or two short messages run together, is never read as a
    /// message: it is dropped and counted as audio.refused; two robots sounding at once
    /// can still, rarely, cross into a valid message). Under `six` and `checked`,
    /// `say` takes `[short|long] ROBOT VALUE` and heard values end with `plan=P robot=R
    /// value=V`.
    #[arg(long, value_name = "PLAN", default_value_t = audio::TeamPlan::Three)]
    pub audio_team: audio::TeamPlan,
}

/// `--audio-in-restart`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RestartFlag {
    /// After a failure only.
    OnFailure,
    /// After every end.
    Always,
    /// Never.
    Never,
}

impl AudioFlags {
    /// The driver's audio configuration, if audio is asked for.
    pub fn config(&self) -> Option<driver::audio::AudioConfig> {
        if self.audio_in.is_none() && self.audio_out.is_none() {
            return None;
        }
        Some(driver::audio::AudioConfig {
            input: self.audio_in.clone(),
            output: self.audio_out.clone(),
            sample_rate_hz: self.audio_rate,
            tone_duration: self.audio_tone,
            gap: self.audio_gap,
            queue: self.audio_queue,
            heard_key: self.audio_heard.clone(),
            say_key: "local.var.audio.say".into(),
            restart: match self.audio_in_restart {
                RestartFlag::OnFailure => driver::audio::Restart::OnFailure,
                RestartFlag::Always => driver::audio::Restart::Always,
                RestartFlag::Never => driver::audio::Restart::Never,
            },
            team: self.audio_team,
        })
    }
}

/// The `--impair` model, if asked for, seeded by `--impair-seed` or the robot id.
pub fn impairment(args: &DaemonArgs, robot_id: u8) -> Result<Option<LinkImpairment>> {
    let Some(spec) = &args.impair else {
        if args.impair_seed.is_some() {
            bail!("--impair-seed needs --impair SPEC");
        }
        return Ok(None);
    };
    let config: netsim::LinkConfig = spec.parse().with_context(|| format!("--impair {spec:?}"))?;
    let seed = args.impair_seed.unwrap_or(u64::from(robot_id));
    let model = LinkImpairment::new(config, seed).with_context(|| format!("--impair {spec:?}"))?;
    Ok(Some(model))
}

/// `--audio-fallback` needs a microphone, a loudspeaker, the team layer and the seed's
/// plan (a claim uses every sender basic and data value).
fn check_fallback(args: &DaemonArgs) -> Result<()> {
    let a = &args.audio;
    if !a.audio_fallback {
        return Ok(());
    }
    if a.audio_in.is_none() || a.audio_out.is_none() {
        bail!("--audio-fallback needs --audio-in CMD (to hear claims) and --audio-out CMD (to sound them)");
    }
    if args.no_team_layer {
        bail!("--audio-fallback is the team layer's: it cannot run with --no-team-layer");
    }
    if a.audio_team != audio::TeamPlan::Three {
        bail!(
            "--audio-fallback sounds claims on the `three` plan (3 x 21 values, the slot names \
             the robot); --audio-team {} would refuse them",
            a.audio_team
        );
    }
    Ok(())
}

/// The GameController listener's settings, if it is on (`--gamecontroller`, or by
/// default with `--budget spl`).
pub fn gamecontroller_config(
    args: &DaemonArgs,
    robot_id: u8,
) -> Option<driver::GameControllerConfig> {
    let spl = args.budget == Some(comms::BudgetSpec::SPL);
    if args.no_gamecontroller || !(args.gamecontroller || spl) {
        return None;
    }
    let mut config = driver::GameControllerConfig::new(args.team, robot_id);
    config.listen = args.gc_listen;
    config.status_port = args.gc_status_port;
    if let Some(spec) = args.budget {
        let mut budget = gamecontroller::GcBudget::spl(args.team_size);
        budget.messages_per_game = u32::try_from(spec.team_messages).unwrap_or(u32::MAX);
        budget.half = spec.game / 2;
        config.budget = Some(budget);
    }
    Some(config)
}

/// Builds the driver configuration from the arguments: robot id, config files, key.
pub fn driver_config(args: &DaemonArgs) -> Result<DriverConfig> {
    let id = match args.id {
        Some(id) => id,
        None => {
            let raw = std::env::var("ROBOT_ID")
                .map_err(|_| anyhow!("no robot id: pass --id N or set ROBOT_ID"))?;
            raw.trim()
                .parse()
                .with_context(|| format!("ROBOT_ID={raw:?} is not a robot id 1..=254"))?
        }
    };
    if !comms::ROBOT_IDS.contains(&id) {
        bail!("robot id {id} is outside 1..=254");
    }
    if args.refresh.is_zero() {
        bail!("--refresh must be positive");
    }
    let mut replica = ReplicaConfig::new(id, args.team)
        .with_refresh_period(args.refresh)
        .with_known_paths(team::known_paths());
    if let Some(spec) = args.budget {
        let share = spec.share(usize::from(args.team_size));
        if share.messages == 0 {
            bail!(
                "--budget {spec}: a share of 0 messages for each of {} robots",
                args.team_size
            );
        }
        replica = replica.with_budget(&spec, usize::from(args.team_size));
        if !args.budget_pool {
            replica.budget = replica.budget.map(comms::Budget::split);
        }
        let priority = if args.budget_pool {
            format!("priority items share {} frames ahead", args.team_size)
        } else {
            format!("{} reserved for priority items", share.reserve)
        };
        tracing::info!(
            "budget: {spec}: this robot's share {} messages per {:?} ({priority}), frames ≤ {} B",
            share.messages,
            share.game,
            replica.mtu
        );
    }
    // Say what was loaded (never the key itself): a robot that cannot hear its team
    // usually runs with another key or config than its teammates.
    match &args.key_file {
        Some(file) => {
            let key = driver::read_key_file(file)?;
            tracing::info!(
                "team key: {} (untagged or badly tagged frames are dropped)",
                file.display()
            );
            replica = replica.with_team_key(key);
        }
        None => tracing::info!("team key: none (frames are not authenticated)"),
    }
    let loaded = driver::load_config_files(&args.config_dir, id)?;
    tracing::info!(
        "config: {} ({})",
        loaded.summary(),
        args.config_dir.display()
    );
    let entries = loaded.entries;
    let mut config = DriverConfig::new(replica);
    config.start_values = entries.into_iter().map(|e| (e.key, e.value)).collect();
    let iface = resolve_iface(&args.iface)?;
    config.socket = args.transport.socket_config(iface, Some(args.team))?;
    config.socket.ttl = args.ttl;
    config.peers = args.peers.clone();
    config.max_relay_clients = args.max_clients as usize;
    if config.socket.transport == driver::Transport::Unicast && config.peers.is_empty() {
        bail!("--transport unicast sends to each --peer only: give at least one --peer ADDR:PORT");
    }
    if args.clock_offset.is_some() || args.clock_drift_ppm.is_some() {
        let offset = args.clock_offset.unwrap_or_default();
        let drift_ppm = args.clock_drift_ppm.unwrap_or(0.0);
        config.clock_skew = driver::ClockSkew::new(offset, drift_ppm)
            .context("--clock-offset / --clock-drift-ppm")?;
        tracing::warn!(
            ?offset,
            drift_ppm,
            "the daemon's clock is skewed on purpose (--clock-offset/--clock-drift-ppm)"
        );
    }
    Ok(config)
}

/// `--parent-pid`: the kernel sends this process SIGTERM when its parent exits
/// (PR_SET_PDEATHSIG), which the daemon takes as an order to stop.
#[cfg(target_os = "linux")]
fn stop_with_parent(pid: u32) -> Result<()> {
    nix::sys::prctl::set_pdeathsig(nix::sys::signal::Signal::SIGTERM)
        .context("--parent-pid: prctl(PR_SET_PDEATHSIG)")?;
    // Checked after the prctl: a parent that exited before it would never signal.
    let parent = nix::unistd::getppid().as_raw();
    if u32::try_from(parent).ok() != Some(pid) {
        anyhow::bail!("--parent-pid {pid}: the parent is process {parent} (has {pid} exited?)");
    }
    Ok(())
}

#[cfg(not(target_os = "linux"))]
fn stop_with_parent(_pid: u32) -> Result<()> {
    anyhow::bail!("--parent-pid needs Linux (PR_SET_PDEATHSIG)")
}

/// Runs the daemon until SIGINT or SIGTERM.
pub fn run(args: DaemonArgs) -> Result<()> {
    let config = driver_config(&args)?;
    let impair = impairment(&args, config.replica.robot_id)?;
    check_fallback(&args)?;
    if let Some(pid) = args.parent_pid {
        stop_with_parent(pid)?;
    }
    // One thread for socket, replica, timers and relay clients: a hand-off between threads
    // costs a full wake-up, several times a loopback round trip, and the driver and its
    // handles are `!Send` for that reason.
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let local = tokio::task::LocalSet::new();
    local.block_on(&runtime, async move {
        let relay_addrs = args.relay.resolve()?;
        let relay = std::net::TcpListener::bind(&relay_addrs[..]).map_err(|e| {
            anyhow!(
                "cannot open the relay port {}: {e}{}",
                args.relay,
                if e.kind() == std::io::ErrorKind::AddrInUse {
                    " (is another daemon using it? pick another with --relay)"
                } else {
                    ""
                }
            )
        })?;
        relay.set_nonblocking(true)?;
        let relay = tokio::net::TcpListener::from_std(relay)?;
        let driver = Driver::bind(config)?;
        if let Some(model) = &impair {
            tracing::warn!(
                spec = %model.config(),
                "--impair: outgoing datagrams pass through netsim's link model"
            );
        }
        match (impair, args.outage) {
            (impair, Some((duration, start))) => {
                tracing::warn!(
                    ?duration,
                    ?start,
                    "--outage: every outgoing datagram is lost in the window"
                );
                let origin = driver.handle().now();
                let outage = huddle::impair::Outage::new(impair, duration, start, origin);
                driver.set_impairment(Some(Box::new(outage)));
            }
            (Some(model), None) => driver.set_impairment(Some(Box::new(model))),
            (None, None) => {}
        }
        let handle = driver.handle();
        let _gc = match gamecontroller_config(&args, handle.robot_id()) {
            Some(config) => {
                let listen = config.listen;
                match driver::GameController::start(&handle, config) {
                    Ok(gc) => {
                        tracing::info!(
                            %listen,
                            team = args.team,
                            "GameController: listening (local.var.gc.*), status packets to its port {}",
                            args.gc_status_port
                        );
                        Some(gc)
                    }
                    // Asked for: a robot that cannot hear the GC must not play unaware.
                    Err(e) if args.gamecontroller => {
                        bail!("cannot listen for the GameController on {listen}: {e}")
                    }
                    // On by default with --budget spl: run as before, loudly.
                    Err(e) => {
                        tracing::error!(
                            %listen,
                            error = %e,
                            "CANNOT LISTEN FOR THE GAMECONTROLLER: the budget is paced from this \
                             daemon's start and cannot see the team's count"
                        );
                        None
                    }
                }
            }
            None => {
                if args.budget == Some(comms::BudgetSpec::SPL) {
                    tracing::warn!(
                        "--budget spl with --no-gamecontroller: the budget is paced from this \
                         daemon's start and cannot see the team's count as the GameController keeps it"
                    );
                }
                None
            }
        };
        let _audio = match args.audio.config() {
            Some(config) => {
                let audio = driver::audio::Audio::start(&handle, config.clone())
                    .context("starting audio")?;
                tracing::info!(
                    input = config.input.as_deref().unwrap_or("-"),
                    output = config.output.as_deref().unwrap_or("-"),
                    heard = %config.heard_key,
                    "audio: listening and speaking through pipes"
                );
                Some(audio)
            }
            None => None,
        };
        tracing::info!(
            robot = handle.robot_id(),
            relay = %args.relay,
            "huddle daemon running"
        );
        let _team = (!args.no_team_layer).then(|| {
            let team_size = usize::from(args.team_size);
            let interval = args.budget.map(|spec| spec.share(team_size).interval());
            let mut cfg = driver::team::TeamLayerConfig::new(team_size, interval);
            if let Some(p) = args.policy {
                cfg.team.send_policy = p;
            }
            if let Some(l) = args.latency_compensation {
                cfg.params.latency_compensation = l;
            }
            tracing::info!(
                policy = ?cfg.team.send_policy,
                "team layer: waiting for local.var.robot.pose or .odometry (docs/team-layer.md)"
            );
            let fallback = if args.audio.audio_fallback {
                let acoustic = team::acoustic::AcousticConfig {
                    enabled: true,
                    tone_s: args.audio.audio_tone.as_secs_f64(),
                    guard_s: args.audio.audio_fallback_guard.as_secs_f64(),
                    ..team::acoustic::AcousticConfig::default()
                };
                cfg.acoustic = Some(acoustic);
                let plan = team::acoustic::SlotPlan::for_team(team_size, acoustic.slot_s());
                tracing::info!(
                    slots = plan.slots,
                    first = plan.first_id,
                    cycle_s = plan.cycle_s(),
                    "audio fallback: claims sounded in this robot's slot while the radio is silent"
                );
                _audio.as_ref().and_then(driver::audio::Audio::fallback)
            } else {
                None
            };
            driver::team::start_with_fallback(&handle, cfg, fallback)
        });
        let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
        let mut relay_stop = stop_rx.clone();
        tokio::task::spawn_local(driver::serve(relay, handle, async move {
            let _ = relay_stop.wait_for(|s| *s).await;
        }));
        let signals = async move {
            shutdown_signal().await;
            let _ = stop_tx.send(true);
        };
        driver.run(signals).await?;
        tracing::info!("huddle daemon stopped");
        drop(stop_rx);
        Ok(())
    })
}

/// SIGINT (Ctrl-C) or SIGTERM.
async fn shutdown_signal() {
    use tokio::signal::unix::{signal, SignalKind};
    let mut term = match signal(SignalKind::terminate()) {
        Ok(s) => s,
        Err(e) => {
            tracing::warn!(error = %e, "cannot watch SIGTERM; Ctrl-C still works");
            let _ = tokio::signal::ctrl_c().await;
            return;
        }
    };
    tokio::select! {
        _ = tokio::signal::ctrl_c() => tracing::info!("SIGINT: shutting down"),
        _ = term.recv() => tracing::info!("SIGTERM: shutting down"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        daemon: DaemonArgs,
    }

    fn gc(args: &[&str]) -> Option<driver::GameControllerConfig> {
        let cli = Cli::try_parse_from(["huddle"].iter().chain(args)).expect("parses");
        gamecontroller_config(&cli.daemon, 3)
    }

    #[test]
    fn the_clock_flags_skew_the_daemon_s_clock_and_out_of_range_ones_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let dir = dir.path().to_str().unwrap().to_owned();
        let config = |args: &[&str]| {
            let head = ["huddle", "--id", "2", "--config-dir", dir.as_str()];
            let cli = Cli::try_parse_from(head.iter().chain(args)).expect("parses");
            driver_config(&cli.daemon)
        };
        let skewed = config(&["--clock-offset", "12500ms", "--clock-drift-ppm", "-30"])
            .expect("a skew within range");
        assert_eq!(
            skewed.clock_skew,
            driver::ClockSkew::new(Duration::from_millis(12_500), -30.0).unwrap()
        );
        assert_eq!(
            config(&[]).unwrap().clock_skew,
            driver::ClockSkew::NONE,
            "the machine's clock unless asked"
        );
        let err = config(&["--clock-drift-ppm", "200000"]).expect_err("out of range");
        assert!(format!("{err:#}").contains("--clock-drift-ppm"), "{err:#}");
    }

    #[test]
    fn the_gamecontroller_is_on_by_default_under_an_spl_budget_only() {
        let spl = gc(&["--budget", "spl", "--team", "12"]).expect("on with --budget spl");
        assert_eq!((spl.team, spl.player), (12, 3));
        assert_eq!(spl.listen, "0.0.0.0:3838".parse().unwrap());
        let budget = spl.budget.expect("the budget follows the GC");
        assert_eq!((budget.messages_per_game, budget.robots), (1200, 5));
        assert!(gc(&[]).is_none(), "off without a budget");
        assert!(
            gc(&["--budget", "humanoid"]).is_none(),
            "off for another league"
        );
        assert!(gc(&["--budget", "spl", "--no-gamecontroller"]).is_none());
        let asked = gc(&["--gamecontroller"]).expect("on when asked");
        assert!(asked.budget.is_none(), "no budget to feed");
        assert!(
            gc(&["--gamecontroller", "--no-gamecontroller"]).is_none(),
            "the last flag wins"
        );
    }
}
