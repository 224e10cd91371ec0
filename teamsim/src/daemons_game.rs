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
//!   at the tick of the cycle's senses (`TeamLayer::heard_whistle`). Its body follows
//!   the layer's reading of the whistle, ahead of the GC's late packets, as the daemon
//!   publishes it with that tick's outputs (`local.var.team.play_whistle`,
//!   `local.var.team.goal_whistle`; [`player::remote::TeamView::whistle`]): it plays
//!   from a play whistle, walks to its kick-off spot from a goal's; the program's own
//!   reading (`ProgramEars`) is only the whistle that ends Standby (the half's Ready),
//!   which the layer leaves to it. So with the GC silent it plays from the whistle heard
//!   in Ready and from the kick-off's after a goal, as its layer does.
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
use team::Whistle;

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

/// What a robot program makes of the whistles it hears, beyond telling its layer: only
/// the whistle that ends a half's Standby (the half's Ready, which GameController3 shows
/// up to 45 s late), which sends its body to its kick-off spot; the layer has nothing to
/// start there (`TeamLayer::heard_whistle`). Every other whistle's meaning is the layer's,
/// read back from its daemon ([`player::remote::TeamView::whistle`]): the layer knows what
/// a whistle means while the GC is silent (play started in its last Ready, the kick-off
/// 10–60 s after a goal's whistle), and a program with a reading of its own would stand
/// on its kick-off spot while its layer plays. (Until round 24 this kept a copy of the
/// layer's older rules, heard in Set: play; in Playing: a goal.)
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct ProgramEars {
    standby: bool,
}

impl ProgramEars {
    /// Its daemon says `heard`; `whistled`: it hears a whistle now.
    fn tick(&mut self, heard: Option<State>, whistled: bool) {
        self.standby &= heard == Some(State::Standby);
        self.standby |= whistled && heard == Some(State::Standby);
    }

    /// Its order ([`program_order`], the in-process robots' rule) on the GC's word
    /// `heard`, `penalised`, and `told`: the whistle its layer acts on, as its daemon
    /// published it at the tick that took the program's senses (and whistle).
    fn order(&self, heard: Option<State>, penalised: bool, told: Option<Whistle>) -> Order {
        program_order(heard, penalised, told, self.standby)
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
    /// `local.var.robot.whistle` then, before the senses its layer ticks on). A penalised
    /// program (its daemon says so, or it stands on the sideline) acts on no whistle.
    pub(crate) fn hears_whistle(
        &mut self,
        i: usize,
        t_s: f64,
        state: Option<&str>,
        penalty: i64,
    ) -> bool {
        let heard = state.and_then(state_named);
        let penalised = self.program_penalised(i, penalty);
        let Some(due) = self.whistles.get_mut(i) else {
            return false;
        };
        let whistled = due.iter().any(|&at| at <= t_s) && !penalised;
        due.retain(|&at| at > t_s);
        if let Some(ears) = self.ears.get_mut(i) {
            ears.tick(heard, whistled);
        }
        whistled
    }

    /// Robot `i`'s order once its layer ticked on the cycle's senses: on `state` and
    /// `penalty` as [`GcSide::hears_whistle`] took them, and `told`, the whistle its layer
    /// acts on ([`player::remote::TeamView::whistle`], read with that tick's outputs).
    /// When the tick comes too late for the cycle the program goes by the last one it
    /// read, as a real program would: a tick (40 ms) behind its layer.
    pub(crate) fn order(
        &self,
        i: usize,
        state: Option<&str>,
        penalty: i64,
        told: Option<Whistle>,
    ) -> Order {
        let heard = state.and_then(state_named);
        let penalised = self.program_penalised(i, penalty);
        match self.ears.get(i) {
            Some(ears) => ears.order(heard, penalised, told),
            None => program_order(heard, penalised, None, false),
        }
    }

    /// Whether robot `i`'s program takes itself for penalised: its daemon says so
    /// (`penalty`), or the referee carried its body to the sideline.
    fn program_penalised(&self, i: usize, penalty: i64) -> bool {
        penalty != 0 || self.referee.penalised(comms_netsim::robot_id(i))
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
    use comms::{Replica, ReplicaConfig, Value};
    use driver::team::{TeamCore, TeamLayerConfig};
    use player::remote::TeamView;
    use team::contract;

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

    /// Robot 2's program and its daemon's team layer: the driver's `TeamCore` on a
    /// replica, ticked at each of the program's cycles as `huddle daemon` ticks it. The
    /// program reads the GC's word its daemon's listener wrote, tells its layer the
    /// whistles it hears, and after the tick reads back the layer's outputs
    /// (`local.var.team.play_whistle`, `local.var.team.goal_whistle`) into its view, as
    /// `huddle sim --daemons --game`'s programs do over the relay.
    struct ProgramAndDaemon {
        core: TeamCore,
        replica: Replica,
        ears: ProgramEars,
        view: TeamView,
        packets: i64,
    }

    /// A program cycle every 40 ms (the layer's control period).
    const CYCLE_US: u64 = 40_000;

    impl ProgramAndDaemon {
        fn new() -> Self {
            let now = comms::Instant::from_micros(0);
            let mut core = TeamCore::new(2, TeamLayerConfig::new(3, None));
            let config = ReplicaConfig::new(2, 0).with_known_paths(team::known_paths());
            let replica = Replica::new(config, 7, now).expect("a valid replica");
            let pose = Value::Floats(vec![0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.001]);
            core.input(contract::POSE_KEY, &pose, now)
                .expect("a valid pose");
            ProgramAndDaemon {
                core,
                replica,
                ears: ProgramEars::default(),
                view: TeamView::default(),
                packets: 0,
            }
        }

        /// The program's cycles from `from_s` to before `to_s`: its daemon's listener
        /// shows `state` and accepts a GC packet every 0.5 s if `gc_heard` (not during
        /// an outage); the program hears the referee's whistle at each of `whistles_s`.
        /// Its order at each cycle, with the cycle's time.
        fn cycles(
            &mut self,
            (from_s, to_s): (f64, f64),
            state: &str,
            gc_heard: bool,
            whistles_s: &[f64],
        ) -> Vec<(f64, Order)> {
            let us = |s: f64| (s * 1e6).round() as u64;
            let whistles_us: Vec<u64> = whistles_s.iter().map(|&s| us(s)).collect();
            let mut orders = Vec::new();
            let mut t_us = us(from_s);
            while t_us < us(to_s) {
                let now = comms::Instant::from_micros(t_us);
                let t_s = team::seconds(now);
                self.replica
                    .set(now, driver::team::GC_STATE_KEY, Value::String(state.into()))
                    .expect("a local key");
                if gc_heard && t_us.is_multiple_of(500_000) {
                    self.packets += 1;
                    self.replica
                        .set(now, driver::team::GC_ACCEPTED_KEY, Value::Int(self.packets))
                        .expect("a local key");
                }
                let heard = state_named(state);
                let whistled = whistles_us.contains(&t_us);
                self.ears.tick(heard, whistled);
                if whistled {
                    self.core
                        .input(contract::WHISTLE_KEY, &Value::Bool(true), now)
                        .expect("a valid whistle");
                }
                self.core
                    .input(contract::ODOMETRY_KEY, &Value::Floats(vec![0.0; 3]), now)
                    .expect("valid odometry");
                self.core.tick(&mut self.replica, now);
                for key in [contract::PLAY_WHISTLE_KEY, contract::GOAL_WHISTLE_KEY] {
                    if let Some(e) = self.replica.get(key).expect("a valid key") {
                        self.view.take(key, &e.value, 0.0);
                    }
                }
                orders.push((t_s, self.ears.order(heard, false, self.view.whistle())));
                t_us += CYCLE_US;
            }
            orders
        }
    }

    /// The first cycle of `orders` in `[from_s, to_s)` whose order is not `want`.
    fn first_other(
        orders: &[(f64, Order)],
        (from_s, to_s): (f64, f64),
        want: Order,
    ) -> Option<(f64, Order)> {
        orders
            .iter()
            .copied()
            .find(|&(t, o)| (from_s..to_s).contains(&t) && o != want)
    }

    #[test]
    fn a_program_plays_from_the_whistle_its_layer_heard_in_set_until_the_gc_catches_up() {
        // Scenario (the GC heard all along): the GC shows Set; the program hears play's
        // whistle at 10 s; the GC shows Set until 25 s (GameController3's 15 s), then
        // Playing; a goal's whistle at 100 s while it shows Playing, its Ready at 115 s;
        // a whistle in Set at 200 s the GC never follows; Standby's whistle at 300 s.
        let mut robot = ProgramAndDaemon::new();
        let mut orders = robot.cycles((0.0, 25.0), "set", true, &[10.0]);
        orders.extend(robot.cycles((25.0, 115.0), "playing", true, &[100.0]));
        orders.extend(robot.cycles((115.0, 130.0), "ready", true, &[]));
        orders.extend(robot.cycles((130.0, 300.0), "set", true, &[200.0]));
        orders.extend(robot.cycles((300.0, 340.0), "standby", true, &[300.0]));
        orders.extend(robot.cycles((340.0, 370.0), "ready", true, &[]));
        orders.extend(robot.cycles((370.0, 371.0), "set", true, &[]));
        let cases = [
            ((0.0, 10.0), Order::Stand, "Set, no whistle yet"),
            (
                (10.0, 100.0),
                Order::Play,
                "play's whistle heard in Set, the GC's late Set, then its Playing",
            ),
            (
                (100.0, 130.0),
                Order::KickOffSpot,
                "a goal's whistle in Playing, then the GC's Ready",
            ),
            ((130.0, 200.0), Order::Stand, "Set"),
            (
                (200.0, 220.0),
                Order::Play,
                "a whistle in Set: play started",
            ),
            // The layer drops it after WHISTLE_TRUST_S at its next sense; published a tick later.
            (
                (220.2, 300.0),
                Order::Stand,
                "the GC's Set again after the trust",
            ),
            (
                (300.0, 370.0),
                Order::KickOffSpot,
                "Standby's whistle, then the GC's Ready",
            ),
            ((370.0, 371.0), Order::Stand, "Standby's whistle is done"),
        ];
        for (window, want, story) in cases {
            assert_eq!(
                first_other(&orders, window, want),
                None,
                "{story}: {want:?} from {window:?}"
            );
        }
    }

    #[test]
    fn with_the_gc_silent_in_ready_the_program_plays_from_the_whistle_its_layer_took() {
        // Scenario: the GC's last word is Ready; the program hears another field's whistle
        // at 201 s (the GC heard: nothing); the WLAN dies at 203 s; at 210 s the program
        // hears the kick-off's whistle (under the rules the only one after Ready); the
        // radio is back at 220 s, the GC showing its delayed Set (GameController3 shows it
        // for 15 s after the whistle), then Playing at 225 s. Its layer takes the whistle
        // for play started (`TeamLayer::heard_whistle`) and its body plays with it: the
        // old `ProgramEars` read a whistle in Ready as nothing and kept it on its kick-off
        // spot, then standing through the GC's late Set.
        let mut robot = ProgramAndDaemon::new();
        let mut orders = robot.cycles((180.0, 203.0), "ready", true, &[201.0]);
        orders.extend(robot.cycles((203.0, 220.0), "ready", false, &[210.0]));
        orders.extend(robot.cycles((220.0, 225.0), "set", true, &[]));
        orders.extend(robot.cycles((225.0, 240.0), "playing", true, &[]));
        assert_eq!(
            first_other(&orders, (180.0, 210.0), Order::KickOffSpot),
            None,
            "Ready: to the kick-off spot, another field's whistle (the GC heard) changes nothing"
        );
        assert_eq!(
            first_other(&orders, (210.0, 240.0), Order::Play),
            None,
            "the kick-off's whistle with the GC silent in Ready: play, through the GC's late Set"
        );
    }

    #[test]
    fn a_whistle_20_s_after_a_goal_s_with_the_gc_silent_is_the_kick_off_for_the_program_too() {
        // Scenario: the GC shows Playing (GameController3 shows it for 15 s after a goal);
        // the program hears a goal's whistle at 100 s; the WLAN dies at 105 s, the GC's
        // last word Playing; the kick-off's whistle at 120 s, 20 s after the goal's
        // (`GOAL_TO_KICK_OFF_MIN_S..MAX_S`); the radio is back at 130 s, the GC showing its
        // delayed Set until 135 s, then Playing. Its layer takes the second whistle for
        // the kick-off and its body plays from it: the old `ProgramEars` kept the goal's
        // whistle pending (its body on the kick-off spot) and then stood through the GC's
        // late Set, for 15 s of play.
        let mut robot = ProgramAndDaemon::new();
        let mut orders = robot.cycles((90.0, 105.0), "playing", true, &[100.0]);
        orders.extend(robot.cycles((105.0, 130.0), "playing", false, &[120.0]));
        orders.extend(robot.cycles((130.0, 135.0), "set", true, &[]));
        orders.extend(robot.cycles((135.0, 150.0), "playing", true, &[]));
        assert_eq!(
            first_other(&orders, (90.0, 100.0), Order::Play),
            None,
            "in play"
        );
        assert_eq!(
            first_other(&orders, (100.0, 120.0), Order::KickOffSpot),
            None,
            "the goal's whistle: to the kick-off spot while the GC is silent on Playing"
        );
        assert_eq!(
            first_other(&orders, (120.0, 150.0), Order::Play),
            None,
            "the kick-off's whistle 20 s later: play, through the GC's late Set"
        );
    }

    #[test]
    fn a_kick_off_whistled_before_the_wlan_died_keeps_the_program_playing() {
        // Scenario (round 22's rule): the GC shows Set; the program hears the kick-off's
        // whistle at 10 s; the WLAN dies at 12 s, the GC's last word Set (GameController3
        // shows it until 25 s); the radio is back at 45 s showing Playing. The layer's
        // play whistle stands while the GC is silent, so the body plays throughout: the
        // old `ProgramEars` dropped it after WHISTLE_TRUST_S (30 s) and stood on the
        // silent GC's Set until 45 s.
        let mut robot = ProgramAndDaemon::new();
        let mut orders = robot.cycles((0.0, 12.0), "set", true, &[10.0]);
        orders.extend(robot.cycles((12.0, 45.0), "set", false, &[]));
        orders.extend(robot.cycles((45.0, 50.0), "playing", true, &[]));
        assert_eq!(first_other(&orders, (0.0, 10.0), Order::Stand), None, "Set");
        assert_eq!(
            first_other(&orders, (10.0, 50.0), Order::Play),
            None,
            "the kick-off's whistle, the GC silent on its last Set: play until the GC is back"
        );
    }
}
