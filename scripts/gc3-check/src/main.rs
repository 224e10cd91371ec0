//! gc3-check: the league's own GameController (RoboCup-SPL/GameController3, its runtime,
//! headless) referees a shortened game of `huddle daemon`s, and its books are checked
//! against what the daemons say they sent.
//!
//! It is not huddle's code that counts here: the GC3 runtime receives the team's
//! datagrams on its own socket (port 10000 + team), applies its own `TeamMessage` action
//! (counted only in Standby, Ready, Set and Playing; illegal over 128 B or at a budget of
//! 0), broadcasts its own RGme packets every 500 ms, and marks a player connected from its
//! own RGrt decoder. Its log file is read back after the game.
//!
//! Checks (each printed PASS/FAIL; the exit code is 1 if any fails):
//! 1. the datagrams GC3 received equal the sum of the daemons' `frames_out`;
//! 2. GC3's counted messages equal its budget's fall (`messagesPerTeam − messageBudget`);
//! 3. the team is never illegal (`illegalCommunication` false in every state GC3 showed);
//! 4. every robot shows as connected (status Good) throughout Playing;
//! 5. the team is never over budget: GC3's `messageBudget` never reaches 0 while a
//!    message is counted at 0 (implied by 3) and ends at or above 0.
//!
//! Besides the checks it reports what GC3's delayed copy costs the team's play: GC3
//! sends robots Set for 15 s after the whistle that starts play (`delayAfterPlaying`),
//! so a daemon that only reads the GC sits out the kick-off. The robot programs here
//! hear each whistle the operator blows (kick-offs and goals, `--whistle on`, the
//! default) and write `local.var.robot.whistle`, as a program with a whistle detector
//! does; `--whistle off` is a team without one. From GC3's own log: the team's frames
//! in the first 10 s after each kick-off whistle, against 10 s of later play.
//!
//! Run inside a network namespace (scripts/gc3-check.sh makes one with a veth pair), so
//! the broadcasts never leave the machine.

// A real-time check: GameController3's runtime and real daemons run on the wall clock.
#![allow(clippy::disallowed_methods)]

use std::collections::BTreeMap;
use std::net::IpAddr;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use enum_map::enum_map;
use game_controller_core::action::VAction;
use game_controller_core::actions::{
    FinishHalf, FreeSetPlay, Goal, Penalize, StartSetPlay, Unpenalize, WaitForReady,
};
use game_controller_core::log::{LogEntry, TimestampedLogEntry};
use game_controller_core::types::{
    Color, CompetitionParams, Game, GameParams, Penalty, PenaltyCall, Phase, PlayerNumber, SetPlay,
    Side, SideMapping, State, TeamParams, TestParams,
};
use game_controller_runtime::launch::{
    CompetitionSettings, LaunchSettings, LogSettings, NetworkInterface, NetworkSettings, Team,
    WindowSettings,
};
use game_controller_runtime::{shutdown_runtime, start_runtime};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::TcpStream;

/// Our team's number (any that GC3's teams.yaml knows; 12 and 13 play).
const TEAM: u8 = 12;
const OPPONENT: u8 = 13;
/// The daemons' relay ports: RELAY_BASE + robot id.
const RELAY_BASE: u16 = 21_000;

struct Args {
    gc3: PathBuf,
    huddle: PathBuf,
    work: PathBuf,
    robots: u8,
    half_s: u64,
    messages: u16,
    iface: IpAddr,
    broadcast: IpAddr,
    iface_name: String,
    write_ms: u64,
    whistle: bool,
}

fn args() -> Result<Args> {
    let mut a = Args {
        gc3: PathBuf::new(),
        huddle: PathBuf::new(),
        work: std::env::temp_dir().join(format!("gc3-check-{}", std::process::id())),
        robots: 3,
        half_s: 60,
        messages: 120,
        iface: "10.0.0.1".parse()?,
        broadcast: "10.0.255.255".parse()?,
        iface_name: "gc0".into(),
        write_ms: 100,
        whistle: true,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut val = || it.next().with_context(|| format!("{flag} needs a value"));
        match flag.as_str() {
            "--gc3" => a.gc3 = val()?.into(),
            "--huddle" => a.huddle = val()?.into(),
            "--work" => a.work = val()?.into(),
            "--robots" => a.robots = val()?.parse()?,
            "--half-s" => a.half_s = val()?.parse()?,
            "--messages" => a.messages = val()?.parse()?,
            "--iface" => a.iface = val()?.parse()?,
            "--broadcast" => a.broadcast = val()?.parse()?,
            "--iface-name" => a.iface_name = val()?,
            "--write-ms" => a.write_ms = val()?.parse()?,
            "--whistle" => {
                a.whistle = match val()?.as_str() {
                    "on" => true,
                    "off" => false,
                    other => bail!("--whistle on|off, not {other}"),
                }
            }
            _ => bail!("unknown flag {flag}"),
        }
    }
    if a.gc3.as_os_str().is_empty() || a.huddle.as_os_str().is_empty() {
        bail!("usage: gc3-check --gc3 GC3_SOURCE --huddle HUDDLE_BIN [--robots N] [--half-s S] [--messages M] [--whistle on|off]");
    }
    Ok(a)
}

/// The competition: GameController3's Champions Cup rules, with the halves, the break, the
/// kick-off's Ready and a pick-up penalty shortened, and the budget scaled with the halves
/// (the SPL's rate: 1,200 over 1,200 s is one message a second).
fn params(a: &Args) -> Result<CompetitionParams> {
    let path = a.gc3.join("config/champions_cup/params.yaml");
    let mut p: CompetitionParams = serde_yaml::from_reader(
        std::fs::File::open(&path).with_context(|| format!("{}", path.display()))?,
    )?;
    p.name = "huddle check".into();
    p.half_duration = Duration::from_secs(a.half_s);
    p.half_time_break_duration = Duration::from_secs(20);
    p.messages_per_team = a.messages;
    p.set_plays[SetPlay::KickOff].ready_duration = Duration::from_secs(15);
    p.penalties[Penalty::PickedUp].duration = Duration::from_secs(15);
    Ok(p)
}

/// What the GC showed, gathered from each UI state the runtime sent.
#[derive(Default)]
struct Seen {
    game: Option<Game>,
    /// Per player 1..=20 of our team: its connection status (0 offline, 1 bad, 2 good).
    connection: Vec<u8>,
    illegal_ever: bool,
    min_budget: Option<u16>,
    states: u64,
}

fn spawn_daemon(a: &Args, id: u8) -> Result<Child> {
    let dir = a.work.join(format!("robot{id}"));
    std::fs::create_dir_all(&dir)?;
    let log = std::fs::File::create(a.work.join(format!("daemon{id}.log")))?;
    let budget = format!("{}/{}s", a.messages, 2 * a.half_s);
    Command::new(&a.huddle)
        .args([
            "daemon",
            "--id",
            &id.to_string(),
            "--team",
            &TEAM.to_string(),
        ])
        .args(["--iface", &a.iface.to_string(), "--transport", "broadcast"])
        .args(["--budget", &budget, "--gamecontroller"])
        .args(["--team-size", &a.robots.to_string()])
        .args([
            "--relay",
            &format!("127.0.0.1:{}", RELAY_BASE + u16::from(id)),
        ])
        .arg("--config-dir")
        .arg(&dir)
        .env("RUST_LOG", "info")
        .stdin(Stdio::null())
        .stdout(log.try_clone()?)
        .stderr(log)
        .spawn()
        .with_context(|| format!("cannot start {}", a.huddle.display()))
}

/// A robot program: writes its pose and a new small value every `every` through the
/// relay, as a robot program would, so that the team layer runs and the daemon always
/// has news and the budget binds. Each time
/// `whistles` goes up it writes the whistle, `0.2 · id` s late (a detector's delay).
async fn writer(
    id: u8,
    every: Duration,
    stop: Arc<AtomicBool>,
    whistles: Arc<AtomicU64>,
) -> Result<u64> {
    let addr = format!("127.0.0.1:{}", RELAY_BASE + u16::from(id));
    let stream = loop {
        match TcpStream::connect(&addr).await {
            Ok(s) => break s,
            Err(_) if !stop.load(Ordering::Relaxed) => {
                tokio::time::sleep(Duration::from_millis(100)).await
            }
            Err(e) => return Err(e.into()),
        }
    };
    let (r, mut w) = stream.into_split();
    let mut lines = BufReader::new(r).lines();
    lines.next_line().await?; // the greeting
    let mut n = 0u64;
    let mut heard = 0u64;
    let mut due: Option<Instant> = None;
    while !stop.load(Ordering::Relaxed) {
        let blown = whistles.load(Ordering::Relaxed);
        if blown > heard {
            heard = blown;
            due = Some(Instant::now() + Duration::from_millis(200 * u64::from(id)));
        }
        if due.is_some_and(|at| Instant::now() >= at) {
            due = None;
            w.write_all(b"SETV local.var.robot.whistle true\n").await?;
            let reply = lines.next_line().await?.unwrap_or_default();
            if !reply.starts_with("OK") {
                bail!("robot {id}: the whistle's SETV answered {reply:?}");
            }
        }
        n += 1;
        // Its pose (the team layer runs on it: it reads the whistle at its ticks) and a
        // new value the team shares.
        let x = f64::from(id) - 2.0;
        for line in [
            format!(
                "SETV local.var.robot.pose [{x}, -1.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.003]\n"
            ),
            format!("SETV *.var.check.n{id} {n}\n"),
        ] {
            w.write_all(line.as_bytes()).await?;
            let reply = lines.next_line().await?.unwrap_or_default();
            if !reply.starts_with("OK") {
                bail!("robot {id}: {} answered {reply:?}", line.trim());
            }
        }
        tokio::time::sleep(every).await;
    }
    Ok(n)
}

/// `frames_out` of daemon `id`, from `huddle stats --json`.
fn frames_out(a: &Args, id: u8) -> Result<u64> {
    let out = Command::new(&a.huddle)
        .args(["stats", "--json", "--relay"])
        .arg(format!("127.0.0.1:{}", RELAY_BASE + u16::from(id)))
        .output()?;
    let v: serde_json::Value = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("huddle stats: {}", String::from_utf8_lossy(&out.stderr)))?;
    let f = &v["frames_out"];
    f.as_u64()
        .or_else(|| f.as_str().and_then(|s| s.parse().ok()))
        .with_context(|| format!("no frames_out in {v}"))
}

fn secs(t: &game_controller_core::timer::Timer) -> f64 {
    t.get_remaining().as_seconds_f64()
}

#[tokio::main]
async fn main() -> Result<()> {
    let a = args()?;
    std::fs::create_dir_all(&a.work)?;
    let config = a.work.join("config");
    std::fs::create_dir_all(config.join("huddle_check"))?;
    let p = params(&a)?;
    std::fs::write(
        config.join("huddle_check/params.yaml"),
        serde_yaml::to_string(&p)?,
    )?;
    std::fs::write(
        config.join("huddle_check/teams.yaml"),
        format!("- 0\n- {TEAM}\n- {OPPONENT}\n"),
    )?;
    let teams: Vec<Team> =
        serde_yaml::from_reader(std::fs::File::open(a.gc3.join("config/teams.yaml"))?)?;
    let settings = LaunchSettings {
        competition: CompetitionSettings {
            id: "huddle_check".into(),
        },
        game: GameParams {
            teams: enum_map! {
                Side::Home => TeamParams { number: TEAM, field_player_color: Color::Blue, goalkeeper_color: Color::Yellow },
                Side::Away => TeamParams { number: OPPONENT, field_player_color: Color::Red, goalkeeper_color: Color::Black },
            },
            long: false,
            kick_off_side: Side::Home,
            side_mapping: SideMapping::HomeDefendsLeftGoal,
            test: TestParams::default(),
        },
        window: WindowSettings { fullscreen: false },
        network: NetworkSettings {
            interface: a.iface_name.clone(),
            broadcast: false,
            multicast: false,
        },
        log: LogSettings {
            sync: false,
            replay: None,
        },
    };
    let interfaces = [NetworkInterface {
        id: a.iface_name.clone(),
        address: a.iface,
        broadcast: a.broadcast,
    }];
    let seen = Arc::new(Mutex::new(Seen::default()));
    let sink = seen.clone();
    let logs = a.work.join("logs");
    let runtime = start_runtime(
        &config,
        &logs,
        &settings,
        &teams,
        &interfaces,
        Box::new(move |ui| {
            let v = serde_json::to_value(&ui)?;
            let game: Game = serde_json::from_value(v["game"].clone())?;
            let mut s = sink.lock().unwrap();
            let ours = &game.teams[Side::Home];
            s.illegal_ever |= ours.illegal_communication;
            s.min_budget = Some(
                s.min_budget
                    .map_or(ours.message_budget, |m| m.min(ours.message_budget)),
            );
            s.connection = v["connectionStatus"]["home"]
                .as_array()
                .map(|xs| xs.iter().map(|x| x.as_u64().unwrap_or(0) as u8).collect())
                .unwrap_or_default();
            s.game = Some(game);
            s.states += 1;
            Ok(())
        }),
    )
    .await
    .context("GameController3's runtime did not start")?;
    runtime.ui_notify.notify_one();
    let act = |action: VAction| {
        let _ = runtime.action_sender.send(action);
    };

    let mut daemons = Vec::new();
    for id in 1..=a.robots {
        daemons.push((id, spawn_daemon(&a, id)?));
    }
    let stop = Arc::new(AtomicBool::new(false));
    let whistles = Arc::new(AtomicU64::new(0));
    let writers: Vec<_> = (1..=a.robots)
        .map(|id| {
            let every = Duration::from_millis(a.write_ms);
            tokio::spawn(writer(id, every, stop.clone(), whistles.clone()))
        })
        .collect();
    // The operator blows the whistle with the action; the programs hear it if asked to.
    let blow = || {
        if a.whistle {
            whistles.fetch_add(1, Ordering::Relaxed);
        }
    };

    // The operator's script: Initial → Standby → kick-off (Ready, Set) → Playing; a goal
    // and a pick-up penalty in the first half; the break; the second half; Finished.
    let start = Instant::now();
    let mut set_since: Option<Instant> = None;
    let mut whistled = false;
    let mut initial_since = Some(start);
    let mut goal_given = false;
    let mut penalised = false;
    let mut polls_playing = 0u64;
    let mut disconnected: BTreeMap<u8, u64> = BTreeMap::new();
    let mut finished_at: Option<Instant> = None;
    let mut trace = Vec::new();
    let mut last_state = None;
    loop {
        tokio::time::sleep(Duration::from_millis(100)).await;
        let (game, connection) = {
            let s = seen.lock().unwrap();
            match &s.game {
                Some(g) => (g.clone(), s.connection.clone()),
                None => continue,
            }
        };
        let t = start.elapsed().as_secs_f64();
        if last_state != Some((game.phase, game.state)) {
            trace.push(format!("{t:6.1} s {:?} {:?}", game.phase, game.state));
            last_state = Some((game.phase, game.state));
        }
        let primary = secs(&game.primary_timer);
        match game.state {
            State::Initial => {
                let since = *initial_since.get_or_insert_with(Instant::now);
                let wait = if game.phase == Phase::FirstHalf {
                    Duration::from_secs(5)
                } else {
                    Duration::from_secs(3)
                };
                if since.elapsed() >= wait {
                    act(VAction::WaitForReady(WaitForReady));
                }
            }
            State::Standby => {
                initial_since = None;
                let side = if game.phase == Phase::FirstHalf {
                    Side::Home
                } else {
                    Side::Away
                };
                act(VAction::StartSetPlay(StartSetPlay {
                    side: Some(side),
                    set_play: SetPlay::KickOff,
                }));
            }
            State::Set => {
                let since = *set_since.get_or_insert_with(Instant::now);
                if since.elapsed() >= Duration::from_secs(3) {
                    if !whistled {
                        whistled = true;
                        blow();
                    }
                    act(VAction::FreeSetPlay(FreeSetPlay));
                }
            }
            State::Playing => {
                set_since = None;
                whistled = false;
                polls_playing += 1;
                // Connected: every robot heard within 2 s (GC3's "good"), once play runs.
                for id in 1..=a.robots {
                    if connection.get(usize::from(id - 1)).copied() != Some(2) {
                        *disconnected.entry(id).or_default() += 1;
                    }
                }
                let first = game.phase == Phase::FirstHalf;
                if first && !goal_given && primary <= a.half_s as f64 * 0.6 {
                    goal_given = true;
                    blow();
                    act(VAction::Goal(Goal { side: Side::Home }));
                } else if first && !penalised && primary <= a.half_s as f64 * 0.4 {
                    penalised = true;
                    act(VAction::Penalize(Penalize {
                        side: Side::Home,
                        player: Some(PlayerNumber::new(2)),
                        call: PenaltyCall::RequestForPickUp,
                    }));
                } else if primary <= 0.0 {
                    act(VAction::FinishHalf(FinishHalf));
                }
            }
            State::Finished if game.phase == Phase::SecondHalf => {
                let at = *finished_at.get_or_insert_with(Instant::now);
                if at.elapsed() >= Duration::from_secs(3) {
                    break;
                }
            }
            _ => {}
        }
        if penalised {
            // Back on as soon as GC3 allows (its penalty timer at 0).
            act(VAction::Unpenalize(Unpenalize {
                side: Side::Home,
                player: PlayerNumber::new(2),
                force: false,
            }));
        }
        if t > 20.0 * a.half_s as f64 {
            bail!("the game did not end (trace: {trace:?})");
        }
    }

    // The end: the programs stop writing, the daemons fall quiet, their counts are read,
    // then GC3 shuts down and its log is read back.
    stop.store(true, Ordering::Relaxed);
    for w in writers {
        let _ = w.await;
    }
    let mut sent = BTreeMap::new();
    let settle = Instant::now();
    loop {
        tokio::time::sleep(Duration::from_secs(2)).await;
        let now: BTreeMap<u8, u64> = (1..=a.robots)
            .map(|id| Ok((id, frames_out(&a, id)?)))
            .collect::<Result<_>>()?;
        let quiet = now == sent;
        sent = now;
        if quiet || settle.elapsed() > Duration::from_secs(30) {
            break;
        }
    }
    for (_, d) in &mut daemons {
        let _ = d.kill();
        let _ = d.wait();
    }
    tokio::time::sleep(Duration::from_millis(500)).await;
    shutdown_runtime(&runtime).await;

    let log = std::fs::read_dir(&logs)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .find(|p| p.extension().is_some_and(|x| x == "yaml"))
        .context("GC3 wrote no log")?;
    let entries: Vec<TimestampedLogEntry> = serde_yaml::from_reader(std::fs::File::open(&log)?)
        .with_context(|| format!("GC3's log {}", log.display()))?;
    let mut received = 0u64;
    let mut longest = 0usize;
    let mut counted = 0u64;
    // When GC3 logged each kick-off's whistle (the true Playing) and each team frame.
    let mut kick_offs: Vec<f64> = Vec::new();
    // When each stretch of true play ended (a goal or the half's end).
    let mut play_ends: Vec<f64> = Vec::new();
    let mut frames_at: Vec<f64> = Vec::new();
    for e in &entries {
        let t = e.timestamp.as_secs_f64();
        match &e.entry {
            LogEntry::TeamMessage(m) if m.team == TEAM => {
                received += 1;
                longest = longest.max(m.data.len());
                frames_at.push(t);
            }
            LogEntry::Action(la) => match &la.action {
                VAction::TeamMessage(tm) if tm.side == Side::Home => counted += 1,
                VAction::FreeSetPlay(_) if kick_offs.len() == play_ends.len() => kick_offs.push(t),
                VAction::Goal(_) | VAction::FinishHalf(_) if kick_offs.len() > play_ends.len() => {
                    play_ends.push(t)
                }
                _ => {}
            },
            _ => {}
        }
    }
    let frames_between =
        |from: f64, to: f64| frames_at.iter().filter(|&&f| f >= from && f < to).count() as f64;
    // The first 10 s after each whistle (GC3 still shows Set), and 10 s of play after
    // the delay (from 20 s on) for comparison.
    let first_10s: Vec<f64> = kick_offs
        .iter()
        .zip(&play_ends)
        .map(|(&k, &end)| frames_between(k, end.min(k + 10.0)))
        .collect();
    // Play after GC3 has caught up (15 s on), as frames per 10 s.
    let later_10s: Vec<f64> = kick_offs
        .iter()
        .zip(&play_ends)
        .filter(|(&k, &end)| end > k + 20.0)
        .map(|(&k, &end)| 10.0 * frames_between(k + 15.0, end) / (end - k - 15.0))
        .collect();
    let mean = |xs: &[f64]| xs.iter().sum::<f64>() / xs.len().max(1) as f64;
    let s = seen.lock().unwrap();
    let final_game = s.game.clone().context("GC3 showed no state")?;
    let ours = &final_game.teams[Side::Home];
    let budget_fall = u64::from(a.messages) - u64::from(ours.message_budget);
    let total_sent: u64 = sent.values().sum();

    let report = serde_json::json!({
        "robots": a.robots,
        "half_s": a.half_s,
        "messages_per_team": a.messages,
        "gc3_received": received,
        "gc3_counted": counted,
        "gc3_budget_left": ours.message_budget,
        "gc3_budget_min_seen": s.min_budget,
        "gc3_budget_used_pct": (1000.0 * budget_fall as f64 / f64::from(a.messages)).round() / 10.0,
        "gc3_illegal_ever": s.illegal_ever,
        "gc3_score": [ours.score, final_game.teams[Side::Away].score],
        "gc3_states_seen": s.states,
        "longest_datagram_bytes": longest,
        "whistle": a.whistle,
        "kick_off_whistles_s": kick_offs,
        "frames_first_10s_after_whistle": first_10s,
        "play_ends_s": play_ends,
        "frames_per_10s_of_play_from_15s_after_whistle": later_10s,
        "daemons_frames_out": sent,
        "daemons_frames_out_total": total_sent,
        "playing_polls": polls_playing,
        "disconnected_polls": disconnected,
        "trace": trace,
        "log": log,
    });
    println!("{}", serde_json::to_string_pretty(&report)?);
    let checks = [
        (
            "GC3 received exactly the frames the daemons say they sent",
            received == total_sent,
            format!("{received} received, {total_sent} sent ({sent:?})"),
        ),
        (
            "GC3's counted messages equal its budget's fall",
            counted == budget_fall,
            format!(
                "{counted} counted, budget {} → {}",
                a.messages, ours.message_budget
            ),
        ),
        (
            "the team is never illegal (no message at 0, none over 128 B)",
            !s.illegal_ever && !ours.illegal_communication && longest <= 128,
            format!("illegal ever: {}, longest {longest} B", s.illegal_ever),
        ),
        (
            "every robot shows as connected throughout Playing",
            disconnected.is_empty() && polls_playing > 0,
            format!("{polls_playing} polls in Playing, not good: {disconnected:?}"),
        ),
        (
            "the team spent its budget (≥ 80% of it; the margin is 10 of 120)",
            budget_fall * 10 >= u64::from(a.messages) * 8,
            format!("{budget_fall} of {}", a.messages),
        ),
    ];
    println!(
        "INFO whistle {}: team frames in the 10 s after each kick-off whistle {:.1} (per kick-off {:?}), per 10 s of play from 15 s on (GC3 caught up) {:.1} ({:?})",
        if a.whistle { "heard" } else { "not heard" },
        mean(&first_10s),
        first_10s,
        mean(&later_10s),
        later_10s
    );
    let mut ok = true;
    for (what, pass, detail) in &checks {
        println!("{} {what}: {detail}", if *pass { "PASS" } else { "FAIL" });
        ok &= pass;
    }
    drop(s);
    if !ok {
        std::process::exit(1);
    }
    Ok(())
}
