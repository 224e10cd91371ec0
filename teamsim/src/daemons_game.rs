//! `huddle sim --daemons --game`: the `--daemons` match ([`super::daemons`]) played under
//! the simulated GameController ([`Referee`]), its packets sent over real UDP sockets.
//!
//! - **Packets.** Every 500 ms the referee's RGme v18 bytes ([`Referee::packet`]) go by
//!   unicast from a socket on 127.0.0.1 to each daemon's GameController listener, bound to
//!   a loopback port of the run's own (`huddle daemon --gamecontroller --gc-listen
//!   127.0.0.1:<port>`; never port 3838). Each daemon misses a packet with the chance the
//!   match's network loses a frame to one receiver (`NetworkConfig::mean_loss`, drawn from
//!   the seed, as `--game` in process draws it).
//! - **The count.** The referee counts the team's messages as the GC does: it listens to
//!   the scratch group on loopback and takes every frame the daemons put on it, with its
//!   size, in the referee's true state at the step it arrived ([`Referee::team_message`]).
//!   "Illegal" and "budget used" are the real daemons' figures. A frame a daemon's
//!   `--impair` loses never reaches the group, nor would it reach a real GC: under a lossy
//!   preset the GC's total is below the daemons' `frames_out`.
//! - **The robot programs** follow the states they hear **through their daemon's
//!   `local.var.gc.state` and `local.var.gc.penalty` keys** (watched on the relay), as a
//!   real robot program reads them: they play in Playing, walk to their kick-off spots in
//!   Ready (the in-process robot's `Order::KickOffSpot`), stand otherwise and while their
//!   daemon says they are penalised. Nothing else of the game is told to them: their team
//!   layers learn goals, penalties and Set from the listener themselves.
//! - **The whistle.** Each program hears each of the referee's whistles as the in-process
//!   robots do (the script's [`WhistleHearing`](super::referee::WhistleHearing),
//!   `huddle sim --whistle P`, drawn by `GameTally::whistle` from a generator of its
//!   own, so the packets' losses do not move) and writes `local.var.robot.whistle true`
//!   to its daemon, as the Python client's `whistle()` does; its daemon's layer takes it
//!   at its next tick
//!   (`TeamLayer::heard_whistle`). Its body follows its own reading of the whistle
//!   (`ProgramEars`) ahead of the GC's late packets: it plays from a whistle heard in Set,
//!   walks to its kick-off spot from one heard in Playing (a goal) or in Standby.
//! - **Senses.** A program writes what it senses every tick in every state (its pose,
//!   odometry, landmarks, ball): outside Playing it only stops playing (no kick, so no
//!   kick report); what its layer tells the team then is the layer's decision.
//! - **The world** is the in-process game's: outside Playing the ball lies on the centre
//!   spot and the opponents on their kick-off spots; a penalised robot's body waits on the
//!   sideline off the field (its program tells its layer where it was put, as the
//!   in-process robot is placed) and comes back on the touchline when its penalty timer
//!   has run. Goals are the referee's ([`Referee::goal`]): Ready and Set, a kick-off from
//!   the formation.
//! - **Status packets.** The referee's status port (127.0.0.1, a port of the run's own,
//!   each daemon's `--gc-status-port`) counts each robot's RGrt packets and the longest
//!   gap between two of them (the GC shows a robot as connected if heard within 2 s).
//!
//! Arbitration and team-ball figures are sampled in Playing only, team-ball ones of robots
//! on the field only, as in process.

// A real-time loop over real sockets: it reads the wall clock.
#![allow(clippy::disallowed_methods)]

use std::collections::BTreeMap;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use gamecontroller::{State, StatusMessage};
use player::behaviour::Position;
use player::remote::RemoteRobot;
use player::robot::Order;
use player::senses::MotionCommand;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::daemons::DaemonsError;
use super::game::{KICK_OFF_WINDOW_S, OUR_TEAM};
use super::referee::{program_order, GameScript, GameTally, GcBooks, Referee, RefereeEvent};
use crate::field::geometry::{Pose, Vec2};
use crate::field::World;
use crate::SimConfig;
use team::{Whistle, WHISTLE_TRUST_S};

/// A penalised robot's teammates are judged this long after its penalty began (four of
/// the GC's packets: time for one to reach them through a lossy network), seconds.
pub const CLAIM_GRACE_S: f64 = 2.0;

/// The GC shows a robot as connected if it heard it within this long, seconds.
pub const CONNECTED_WITHIN_S: f64 = 2.0;

/// One robot's status packets as the referee's return port heard them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StatusFigures {
    /// Its player number.
    pub robot: u8,
    /// RGrt packets heard.
    pub packets: u64,
    /// The longest time without one, from the referee's first packet to the game's end
    /// (the first one's wait included), seconds.
    pub longest_gap_s: f64,
}

/// The referee's books of a `--daemons --game` match (in [`super::daemons::DaemonsReport`]).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DaemonsGameReport {
    /// The referee's books (score, the GC's count, illegal, packets, whistles heard), as
    /// the in-process report has them.
    #[serde(flatten)]
    pub books: GcBooks,
    /// At each kick-off, the farthest any robot on the field stood from its kick-off
    /// spot, m (did they walk there in Ready?).
    pub kick_off_spot_error_m: Vec<f64>,
    /// Robot ticks in Playing at which a teammate of a robot penalised more than
    /// [`CLAIM_GRACE_S`] ago was judged (its layer's goer read).
    pub penalised_claims_checked: u64,
    /// … at which its layer still named the penalised robot the goer.
    pub penalised_claims_held: u64,
    /// Each robot's status packets.
    pub status: Vec<StatusFigures>,
    /// RGrt packets the return port could not read.
    pub status_bad: u64,
    /// Team frames the GC heard in the first `KICK_OFF_WINDOW_S` (10 s) of each stretch of
    /// Playing (true time; the in-process report's `game_kick_off.messages`).
    pub game_kick_off_messages: u64,
}

impl std::fmt::Display for DaemonsGameReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "{}", self.books)?;
        writeln!(
            f,
            "kick-offs             {} frames in the first {KICK_OFF_WINDOW_S:.0} s of play ({:.2} a kick-off); farthest from its spot at each: {:?} m",
            self.game_kick_off_messages,
            self.game_kick_off_messages as f64 / f64::from(self.books.game_kick_offs.max(1)),
            self.kick_off_spot_error_m
        )?;
        writeln!(
            f,
            "penalised claims      {} of {} teammate ticks still named a penalised robot the goer",
            self.penalised_claims_held, self.penalised_claims_checked
        )?;
        let status: Vec<String> = self
            .status
            .iter()
            .map(|s| format!("{}: {} (gap {:.2} s)", s.robot, s.packets, s.longest_gap_s))
            .collect();
        write!(
            f,
            "status packets        {}; {} unreadable",
            status.join(", "),
            self.status_bad
        )
    }
}

/// The state a daemon's listener wrote (`local.var.gc.state`), as a program reads it.
fn state_named(name: &str) -> Option<State> {
    [
        State::Initial,
        State::Ready,
        State::Set,
        State::Playing,
        State::Finished,
        State::Standby,
    ]
    .into_iter()
    .find(|s| s.name() == name)
}

/// What a robot program makes of the whistles it heard while the GC's packets lag (its
/// body goes by it; its team layer reads the same whistle from `local.var.robot.whistle`
/// with the same meaning, `TeamLayer::heard_whistle`): heard in Set, play started; heard
/// in Playing, or with play's whistle still ahead of the GC, a goal; in Standby, the
/// half's Ready. The GC's word counts again once it shows what the whistle said (or
/// anything else after a goal), or [`WHISTLE_TRUST_S`] after the whistle.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct ProgramEars {
    whistle: Option<Whistle>,
    standby: bool,
}

impl ProgramEars {
    /// At `t_s` the program's daemon says `heard`; `whistled`: it hears a whistle now.
    fn tick(&mut self, heard: Option<State>, t_s: f64, whistled: bool) {
        self.whistle = match self.whistle {
            Some(Whistle::PlayStarted(_)) if heard == Some(State::Playing) => None,
            Some(Whistle::Goal(_)) if heard != Some(State::Playing) => None,
            Some(Whistle::PlayStarted(at) | Whistle::Goal(at)) if t_s - at > WHISTLE_TRUST_S => {
                None
            }
            w => w,
        };
        self.standby &= heard == Some(State::Standby);
        if !whistled {
            return;
        }
        self.whistle = match (self.whistle, heard) {
            (Some(Whistle::Goal(at)), _) => Some(Whistle::Goal(at)),
            (Some(Whistle::PlayStarted(_)), _) | (None, Some(State::Playing)) => {
                Some(Whistle::Goal(t_s))
            }
            (None, Some(State::Set)) => Some(Whistle::PlayStarted(t_s)),
            (None, _) => None,
        };
        self.standby |= heard == Some(State::Standby);
    }
}

/// Robot `r`'s kick-off spot (the in-process robot's): the goalkeeper on its goal line,
/// a field player at its formation home kept in its own half.
fn kick_off_spot(r: &RemoteRobot, homes: &[Vec2]) -> Vec2 {
    let field = r.cal.field;
    match r.tactics.position {
        Position::Goalkeeper => Vec2::new(-field.length_m / 2.0 + 0.3, 0.0),
        Position::Field(k) => {
            let home = homes.get(k).copied().unwrap_or_default();
            Vec2::new(home.x.min(-0.5), home.y)
        }
    }
}

/// The command of `order` for robot `r` believing itself at `pose`; `None`: play on.
pub(crate) fn command(
    order: Order,
    r: &RemoteRobot,
    pose: &Pose,
    homes: &[Vec2],
) -> Option<MotionCommand> {
    match order {
        Order::Play => None,
        Order::Stand => Some(MotionCommand {
            velocity: Vec2::default(),
            heading_rad: pose.theta_rad,
        }),
        Order::KickOffSpot => {
            let spot = kick_off_spot(r, homes);
            let facing = (Vec2::default() - spot).angle();
            Some(player::behaviour::go_to(
                pose,
                spot,
                facing,
                r.cal.body.top_speed_mps,
            ))
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct StatusBook {
    packets: u64,
    last: Instant,
    longest_gap: Duration,
}

/// The referee's side of a `--daemons --game` match: its sockets and its books.
pub(crate) struct GcSide {
    referee: Referee,
    script: GameScript,
    sender: UdpSocket,
    /// Each daemon's listener address (robot index order).
    pub(crate) listeners: Vec<SocketAddr>,
    /// The port the daemons' status packets go to, on the sender's address.
    pub(crate) status_port: u16,
    frames: Arc<Mutex<Vec<usize>>>,
    status: Arc<Mutex<(BTreeMap<u8, StatusBook>, u64)>>,
    first_packet_at: Option<Instant>,
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    rng: ChaCha8Rng,
    loss: f64,
    /// Packets, losses, penalties, kick-offs and whistles, for the books.
    tally: GameTally,
    kick_off_spot_error_m: Vec<f64>,
    opponent_spots: Vec<Pose>,
    penalised_at: BTreeMap<u8, f64>,
    claims_checked: u64,
    claims_held: u64,
    robots: usize,
    /// The programs' hearing of the whistle: its draws, when each program will hear the
    /// whistles it is to hear, what each made of those heard, and the books.
    whistle_rng: ChaCha8Rng,
    whistles: Vec<Vec<f64>>,
    ears: Vec<ProgramEars>,
    /// When the current stretch of Playing began (true time), and the team's frames the
    /// GC heard in the first [`KICK_OFF_WINDOW_S`] of each.
    playing_since_s: Option<f64>,
    kick_off_frames: u64,
}

impl Drop for GcSide {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

fn io(what: &str) -> impl FnOnce(std::io::Error) -> DaemonsError + '_ {
    move |source| DaemonsError::Io {
        what: what.to_string(),
        source,
    }
}

fn free_udp_port() -> Result<u16, DaemonsError> {
    let s = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).map_err(io("finding a free UDP port"))?;
    Ok(s.local_addr()
        .map_err(io("finding a free UDP port"))?
        .port())
}

impl GcSide {
    /// The referee of `script` for `cfg`'s team, listening to `group` on loopback, before
    /// the daemons start (so that it hears their first frame).
    pub(crate) fn start(
        cfg: &SimConfig,
        script: GameScript,
        group: SocketAddrV4,
        world: &World,
    ) -> Result<GcSide, DaemonsError> {
        let n = cfg.robots;
        let sender = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0))
            .map_err(io("binding the GameController's socket"))?;
        let listeners = (0..n)
            .map(|_| free_udp_port().map(|p| SocketAddr::from((Ipv4Addr::LOCALHOST, p))))
            .collect::<Result<Vec<_>, _>>()?;
        let stop = Arc::new(AtomicBool::new(false));
        // The team's frames, as the GC hears them on the team's port.
        let socket_cfg = driver::SocketConfig {
            group,
            iface: Ipv4Addr::LOCALHOST,
            ..driver::SocketConfig::default()
        };
        let opened = driver::open_multicast(&socket_cfg).map_err(|e| DaemonsError::Io {
            what: "joining the team's group to count its frames".into(),
            source: std::io::Error::other(e.to_string()),
        })?;
        let team = opened.socket;
        team.set_nonblocking(false)
            .map_err(io("setting the group socket blocking"))?;
        team.set_read_timeout(Some(Duration::from_millis(100)))
            .map_err(io("setting the group socket's timeout"))?;
        let frames = Arc::new(Mutex::new(Vec::new()));
        let (sink, halt) = (Arc::clone(&frames), Arc::clone(&stop));
        let counter = std::thread::Builder::new()
            .name("gc-count".into())
            .spawn(move || {
                let mut buf = [0u8; 2048];
                while !halt.load(Ordering::Relaxed) {
                    if let Ok(len) = team.recv(&mut buf) {
                        sink.lock().unwrap_or_else(|e| e.into_inner()).push(len);
                    }
                }
            })
            .map_err(io("starting the frame counter"))?;
        // The robots' status packets.
        let ret = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0))
            .map_err(io("binding the GameController's return port"))?;
        let status_port = ret
            .local_addr()
            .map_err(io("reading the return port"))?
            .port();
        ret.set_read_timeout(Some(Duration::from_millis(100)))
            .map_err(io("setting the return port's timeout"))?;
        let status = Arc::new(Mutex::new((BTreeMap::new(), 0u64)));
        let (book, halt) = (Arc::clone(&status), Arc::clone(&stop));
        let listener = std::thread::Builder::new()
            .name("gc-status".into())
            .spawn(move || {
                let mut buf = [0u8; 256];
                while !halt.load(Ordering::Relaxed) {
                    let Ok(len) = ret.recv(&mut buf) else {
                        continue;
                    };
                    let now = Instant::now();
                    let mut b = book.lock().unwrap_or_else(|e| e.into_inner());
                    match StatusMessage::decode(&buf[..len]) {
                        Ok(m) if m.team_num == OUR_TEAM => {
                            let e = b.0.entry(m.player_num).or_insert(StatusBook {
                                packets: 0,
                                last: now,
                                longest_gap: Duration::ZERO,
                            });
                            e.packets += 1;
                            e.longest_gap = e.longest_gap.max(now.duration_since(e.last));
                            e.last = now;
                        }
                        _ => b.1 += 1,
                    }
                }
            })
            .map_err(io("starting the status listener"))?;
        Ok(GcSide {
            referee: Referee::new(script.clone(), OUR_TEAM, OUR_TEAM + 1, 0.0),
            script,
            sender,
            listeners,
            status_port,
            frames,
            status,
            first_packet_at: None,
            stop,
            threads: vec![counter, listener],
            rng: ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x0063_0063_0063_0063),
            loss: cfg.network.mean_loss().clamp(0.0, 1.0),
            tally: GameTally::default(),
            kick_off_spot_error_m: Vec::new(),
            opponent_spots: world.opponents.iter().map(|b| b.pose).collect(),
            penalised_at: BTreeMap::new(),
            claims_checked: 0,
            claims_held: 0,
            robots: n,
            whistle_rng: ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x7768_6973_746c_6521),
            whistles: vec![Vec::new(); n],
            ears: vec![ProgramEars::default(); n],
            playing_since_s: None,
            kick_off_frames: 0,
        })
    }

    /// The `huddle daemon` arguments that point robot `i`'s listener here.
    pub(crate) fn daemon_args(&self, i: usize) -> Vec<String> {
        vec![
            "--gamecontroller".into(),
            "--team".into(),
            OUR_TEAM.to_string(),
            "--gc-listen".into(),
            self.listeners[i].to_string(),
            "--gc-status-port".into(),
            self.status_port.to_string(),
        ]
    }

    /// Whether the ball is in play.
    pub(crate) fn playing(&self) -> bool {
        self.referee.playing()
    }

    /// Whether the game is over.
    pub(crate) fn over(&self) -> bool {
        self.referee.over()
    }

    /// Whether robot `id` is penalised (the referee's truth).
    pub(crate) fn penalised(&self, id: u8) -> bool {
        self.referee.penalised(id)
    }

    /// Counts every frame heard since the last call in the state the referee is in now
    /// (the state it was in when they arrived, within a step).
    pub(crate) fn count_frames(&mut self, t_s: f64) {
        let heard = std::mem::take(&mut *self.frames.lock().unwrap_or_else(|e| e.into_inner()));
        let kick_off = self
            .playing_since_s
            .is_some_and(|since| t_s - since <= KICK_OFF_WINDOW_S);
        for len in heard {
            self.kick_off_frames += u64::from(kick_off);
            self.referee.team_message(t_s, len);
        }
    }

    /// The referee's step at `t_s`, before the robots tick: frames counted, the game run
    /// on, its packet sent. Returns the robots (index) the referee carried to a new spot,
    /// with where: their programs tell their layers.
    pub(crate) fn step(
        &mut self,
        t_s: f64,
        world: &mut World,
        robots: &[RemoteRobot],
        homes: &[Vec2],
        cfg: &SimConfig,
        radio_down: bool,
    ) -> Result<Vec<(usize, Pose)>, DaemonsError> {
        self.count_frames(t_s);
        let mut placed = Vec::new();
        for e in self.referee.advance(t_s) {
            self.event(e, t_s, world, robots, homes, cfg, &mut placed);
        }
        if let Some(bytes) = self.referee.packet(t_s) {
            self.tally.packets += 1;
            self.first_packet_at.get_or_insert_with(Instant::now);
            for to in &self.listeners {
                // (Drawn in an outage too, so that it moves no other draw.)
                let lost = self.rng.random::<f64>() < self.loss;
                if lost || radio_down {
                    self.tally.packets_lost += 1;
                    continue;
                }
                self.sender
                    .send_to(&bytes, to)
                    .map_err(io("sending the GameController's packet"))?;
            }
        }
        Ok(placed)
    }

    #[allow(clippy::too_many_arguments)]
    fn event(
        &mut self,
        e: RefereeEvent,
        t_s: f64,
        world: &mut World,
        robots: &[RemoteRobot],
        homes: &[Vec2],
        cfg: &SimConfig,
        placed: &mut Vec<(usize, Pose)>,
    ) {
        let index = |id: u8| usize::from(id).checked_sub(1).filter(|&i| i < self.robots);
        match e {
            RefereeEvent::State(State::Playing) => {
                self.tally.kick_offs += 1;
                self.playing_since_s = Some(t_s);
                let far = robots
                    .iter()
                    .enumerate()
                    .filter(|(_, r)| !self.referee.penalised(r.id))
                    .map(|(i, r)| world.robots[i].pose.at.distance(kick_off_spot(r, homes)))
                    .fold(0.0, f64::max);
                self.kick_off_spot_error_m
                    .push((far * 1000.0).round() / 1000.0);
            }
            RefereeEvent::State(_) => self.playing_since_s = None,
            RefereeEvent::Whistle => {
                self.tally.whistle(
                    self.script.whistle,
                    &mut self.whistle_rng,
                    t_s,
                    &mut self.whistles,
                );
            }
            RefereeEvent::Penalised(id) => {
                let Some(i) = index(id) else { return };
                self.tally.penalties += 1;
                self.penalised_at.insert(id, t_s);
                let spot = sideline_spot(cfg, i);
                world.robots[i].pose = spot;
                world.robots[i].velocity = Vec2::default();
                world.set_off_field(i, true);
                placed.push((i, spot));
            }
            RefereeEvent::Unpenalised(id) => {
                let Some(i) = index(id) else { return };
                self.penalised_at.remove(&id);
                let f = &cfg.field;
                let side = if world.ball.at.y > 0.0 { -1.0 } else { 1.0 };
                let spot = Pose {
                    at: Vec2::new(-f.length_m / 4.0, side * f.width_m / 2.0),
                    theta_rad: -side * std::f64::consts::FRAC_PI_2,
                };
                world.robots[i].pose = spot;
                world.robots[i].velocity = Vec2::default();
                world.set_off_field(i, false);
                placed.push((i, spot));
            }
        }
    }

    /// A goal in the world at `t_s` (`for_us`: ours): the referee's events as
    /// [`GcSide::step`] takes them (its whistle among them).
    pub(crate) fn goal(
        &mut self,
        t_s: f64,
        for_us: bool,
        world: &mut World,
        robots: &[RemoteRobot],
        homes: &[Vec2],
        cfg: &SimConfig,
    ) -> Vec<(usize, Pose)> {
        let mut placed = Vec::new();
        for e in self.referee.goal(t_s, for_us) {
            self.event(e, t_s, world, robots, homes, cfg, &mut placed);
        }
        placed
    }

    /// Robot `i`'s program at `t_s`, its daemon's listener having written `state` and
    /// `penalty` (`local.var.gc.*`): whether it hears a whistle now (it writes
    /// `local.var.robot.whistle` then), and its order ([`program_order`], the in-process
    /// robots' rule). A penalised program (its daemon says so, or it stands on the
    /// sideline) acts on no whistle.
    pub(crate) fn program(
        &mut self,
        i: usize,
        t_s: f64,
        state: Option<&str>,
        penalty: i64,
    ) -> (bool, Order) {
        let heard = state.and_then(state_named);
        let penalised = penalty != 0 || self.referee.penalised(comms_netsim::robot_id(i));
        let Some(due) = self.whistles.get_mut(i) else {
            return (false, program_order(heard, penalised, None, false));
        };
        let whistled = due.iter().any(|&at| at <= t_s) && !penalised;
        due.retain(|&at| at > t_s);
        let ears = &mut self.ears[i];
        ears.tick(heard, t_s, whistled);
        (
            whistled,
            program_order(heard, penalised, ears.whistle, ears.standby),
        )
    }

    /// After the world's step: outside Playing the ball and the opponents wait on their
    /// kick-off spots; penalised bodies stay on the sideline.
    pub(crate) fn hold(&self, world: &mut World, cfg: &SimConfig) {
        if !self.referee.playing() {
            world.ball.at = Vec2::default();
            world.ball.velocity = Vec2::default();
            for (body, spot) in world.opponents.iter_mut().zip(&self.opponent_spots) {
                body.pose = *spot;
                body.velocity = Vec2::default();
            }
        }
        for i in 0..self.robots {
            if self.referee.penalised(comms_netsim::robot_id(i)) {
                world.robots[i].pose = sideline_spot(cfg, i);
                world.robots[i].velocity = Vec2::default();
            }
        }
    }

    /// Robot `id` (on the field) read `goer` from its layer at `t_s` in Playing: does it
    /// still count a claim of a teammate penalised more than [`CLAIM_GRACE_S`] ago?
    pub(crate) fn judge_claim(&mut self, id: u8, goer: u8, t_s: f64) {
        if !self.referee.playing() || self.referee.penalised(id) {
            return;
        }
        let judged: Vec<u8> = self
            .penalised_at
            .iter()
            .filter(|&(_, &at)| t_s - at > CLAIM_GRACE_S)
            .map(|(&p, _)| p)
            .collect();
        if judged.is_empty() {
            return;
        }
        self.claims_checked += 1;
        if judged.contains(&goer) {
            self.claims_held += 1;
        }
    }

    /// The books at the end.
    pub(crate) fn report(&self) -> DaemonsGameReport {
        let end = Instant::now();
        let start = self.first_packet_at.unwrap_or(end);
        let (books, bad) = self.status.lock().map_or_else(
            |e| {
                let g = e.into_inner();
                (g.0.clone(), g.1)
            },
            |g| (g.0.clone(), g.1),
        );
        let status = (0..self.robots)
            .map(|i| {
                let id = comms_netsim::robot_id(i);
                let gap = match books.get(&id) {
                    Some(b) => b
                        .longest_gap
                        .max(end.saturating_duration_since(b.last))
                        .as_secs_f64(),
                    None => end.saturating_duration_since(start).as_secs_f64(),
                };
                StatusFigures {
                    robot: id,
                    packets: books.get(&id).map_or(0, |b| b.packets),
                    longest_gap_s: (gap * 1000.0).round() / 1000.0,
                }
            })
            .collect();
        DaemonsGameReport {
            books: self.referee.books_with(&self.tally),
            kick_off_spot_error_m: self.kick_off_spot_error_m.clone(),
            penalised_claims_checked: self.claims_checked,
            penalised_claims_held: self.claims_held,
            status,
            status_bad: bad,
            game_kick_off_messages: self.kick_off_frames,
        }
    }
}

/// Where penalised robot `i` waits: beyond the touchline of its own half, robots apart
/// (the in-process game's spot).
fn sideline_spot(cfg: &SimConfig, i: usize) -> Pose {
    let f = &cfg.field;
    Pose {
        at: Vec2::new(-0.5 - 0.6 * i as f64, -(f.width_m / 2.0 + 0.6 * f.border_m)),
        theta_rad: std::f64::consts::FRAC_PI_2,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_robot_program_follows_the_state_its_daemon_wrote() {
        // No whistle heard: the order of the state's name, as the daemon writes it.
        let order = |state: &str, penalised: bool| {
            program_order(state_named(state), penalised, None, false)
        };
        assert_eq!(order("playing", false), Order::Play);
        assert_eq!(order("ready", false), Order::KickOffSpot);
        assert_eq!(order("set", false), Order::Stand);
        assert_eq!(order("", false), Order::Stand, "nothing heard: it stands");
        assert_eq!(
            order("playing", true),
            Order::Stand,
            "a penalised robot stands whatever the state"
        );
    }

    #[test]
    fn a_program_plays_from_the_whistle_it_heard_in_set_until_the_gc_catches_up() {
        // Scenario: the GC shows Set; the program hears play's whistle at 10 s; the GC
        // shows Set until 25 s (GameController3's 15 s), then Playing; a goal's whistle
        // at 100 s while it shows Playing, its Ready at 115 s.
        let mut ears = ProgramEars::default();
        let set = Some(State::Set);
        let order = |e: &ProgramEars, heard| program_order(heard, false, e.whistle, e.standby);
        ears.tick(set, 9.9, false);
        assert_eq!(order(&ears, set), Order::Stand, "Set, no whistle yet");
        ears.tick(set, 10.0, true);
        assert_eq!(
            order(&ears, set),
            Order::Play,
            "play's whistle heard in Set"
        );
        ears.tick(set, 24.9, false);
        assert_eq!(order(&ears, set), Order::Play, "the GC's late Set");
        ears.tick(Some(State::Playing), 25.0, false);
        assert_eq!(ears.whistle, None, "the GC caught up");
        ears.tick(Some(State::Playing), 100.0, true);
        assert_eq!(
            order(&ears, Some(State::Playing)),
            Order::KickOffSpot,
            "a goal's whistle in Playing: to the kick-off spot"
        );
        ears.tick(Some(State::Ready), 115.0, false);
        assert_eq!(
            (ears.whistle, order(&ears, Some(State::Ready))),
            (None, Order::KickOffSpot)
        );
        // A whistle the GC never follows stands WHISTLE_TRUST_S at most.
        ears.tick(set, 200.0, true);
        ears.tick(set, 200.0 + WHISTLE_TRUST_S + 0.1, false);
        assert_eq!(
            order(&ears, set),
            Order::Stand,
            "the GC's Set again after the trust"
        );
        // In Standby the whistle sends it to Ready's spot until the GC shows Ready.
        ears.tick(Some(State::Standby), 300.0, true);
        assert_eq!(order(&ears, Some(State::Standby)), Order::KickOffSpot);
        ears.tick(Some(State::Ready), 340.0, false);
        ears.tick(Some(State::Set), 370.0, false);
        assert_eq!(
            order(&ears, Some(State::Set)),
            Order::Stand,
            "Standby's whistle is done"
        );
    }
}
