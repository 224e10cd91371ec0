//! The GameController listener: the league's referee system, heard on UDP port 3838,
//! on the blackboard and in the budget; this robot's status (RGrt) sent back to it.
//!
//! Every datagram goes through a [`gamecontroller::GameTracker`]: bad ones (length,
//! header, version, fields, another game) and stale ones are counted and ignored. The
//! newest packet is written to `local` keys (this robot only, never sent to the team):
//!
//! | key | type | what |
//! |---|---|---|
//! | `local.var.gc.state` | string | `initial` `ready` `set` `playing` `finished` `standby` |
//! | `local.var.gc.game_phase` | string | `normal` `penalty_shoot` `overtime` `timeout` |
//! | `local.var.gc.set_play` | string | `none` `goal_kick` `pushing_free_kick` `corner_kick` `kick_in` `penalty_kick` |
//! | `local.var.gc.kicking_team` | int | the kicking team's number, 255 none |
//! | `local.var.gc.first_half` | bool | |
//! | `local.var.gc.secs_remaining` | int | seconds left in the half |
//! | `local.var.gc.secondary_time` | int | the secondary clock |
//! | `local.var.gc.score` | int | this team's score |
//! | `local.var.gc.opponent_score` | int | the other team's |
//! | `local.var.gc.budget` | int | the team's messages left by the GC (`messageBudget`) |
//! | `local.var.gc.counted` | bool | whether the GC counts a message sent now |
//! | `local.var.gc.penalty` | int | this robot's penalty code (0 none, 14 substitute) |
//! | `local.var.gc.penalty_secs` | int | seconds till this robot is unpenalised |
//! | `local.var.gc.penalized` | floats | this team's penalised player numbers (this robot's included; substitutes count) |
//!
//! The keys are the listener's while it runs: a relay client's `SETV` of one gets
//! `ERR 423` (a key is written only when the GC's packet changes it, so a client's value
//! would stand until then), as does the C node's set call while its listener runs.
//!
//! The team layer ([`crate::team`]) reads `local.var.gc.penalized` each tick: a penalised
//! robot leaves the arbitration and tells its team, and its teammates stop counting its
//! claim ([`team::TeamLayer::set_penalties`]).
//! It reads the two scores too: either rising is a goal heard, and the layer forgets
//! the ball then ([`team::TeamLayer::set_scores`]), with no robot-program ball reset.
//!
//! Counters go to `local.var.huddle.stats.gc.*` (`huddle stats`): `accepted`, `stale`,
//! `bad_length`, `bad_header`, `wrong_version`, `bad_field`, `wrong_team`, `status_sent`.
//!
//! With a [`GcBudget`], each packet also feeds the replica's budget
//! ([`Handle::set_external_budget`]): the game clock over the halves and the GC's
//! messages left less the margin, which no frame goes beyond. The clock is the GC's from
//! its first packet on: a relay client's `CLOK` gets `ERR 424` (counted in
//! `local.var.huddle.stats.relay_clock_refused`); it used to move the pacing line until
//! the GC's next packet (a `CLOK 1` with 300 s left let the team's last 16 frames go at
//! once, `tests/daemon_gc_wire.rs`). Without a packet for
//! [`GameControllerConfig::lost_after`] the log says so loudly, and the GC's last figure
//! stays in force: frames sent since (this robot's, counted and free, and the teammates'
//! heard) are taken off it, so a silence never unlocks more than the GC last allowed.
//! Across a half-time break in silence the game clock set by the last packet keeps
//! running down (the GC's stops), so the pacing line opens earlier than the GC's would;
//! the cap (last figure less frames since, less the margin) still holds, and free frames
//! in an uncounted state (one per 250 ms) are taken off it too. A robot that never heard
//! a GC is paced by its own accounting from its start.
//!
//! Status packets go to the GC's address (its IP, port 3939) every
//! [`GameControllerConfig::status_period`] once a packet was heard, from
//! `local.var.robot.pose` (floats `[x_m, y_m, theta_rad, ...]`, field frame),
//! `local.var.team.ball` (floats `[x_m, y_m, ..., age_s]`, field frame; its age is the
//! 9th float `age_s` plus the entry's age, -1 when no ball is known)
//! and `local.var.robot.fallen` (bool).
//!
//! The logic is [`GcListener`] over a [`GcBoard`]: [`GameController`] runs it on the
//! daemon's thread with its [`Handle`], the C node (`huddle-ffi`) on a thread of its own
//! with its replica.

use std::cell::RefCell;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};
use std::rc::Rc;
use std::time::Duration;

use comms::{ExternalCap, Value};
use gamecontroller::{GameTracker, GcBudget, StatusInputs, GAMECONTROLLER_RETURN_PORT};
use tokio::net::UdpSocket;

use crate::handle::Handle;

/// The listener's settings.
#[derive(Debug, Clone)]
pub struct GameControllerConfig {
    /// Where to listen (default `0.0.0.0:3838`: the GC broadcasts, and a socket bound to
    /// one unicast address does not receive broadcasts).
    pub listen: SocketAddr,
    /// This team's number in the GC's packets.
    pub team: u8,
    /// This robot's player number (1–20 for status packets).
    pub player: u8,
    /// Pace the replica's budget by the GC's figures.
    pub budget: Option<GcBudget>,
    /// The status packets' period; `None`: none sent.
    pub status_period: Option<Duration>,
    /// The port status packets go to on the GC's IP (3939).
    pub status_port: u16,
    /// The local address status packets leave from.
    pub status_from: SocketAddr,
    /// The GC is taken as gone after this long without a packet.
    pub lost_after: Duration,
}

impl GameControllerConfig {
    /// Defaults for player `player` of team `team`: port 3838 on every interface, status
    /// every 750 ms (1.3 Hz: the GC shows a robot connected if heard within 2 s).
    pub fn new(team: u8, player: u8) -> GameControllerConfig {
        GameControllerConfig {
            listen: SocketAddr::V4(SocketAddrV4::new(
                Ipv4Addr::UNSPECIFIED,
                gamecontroller::GAMECONTROLLER_DATA_PORT,
            )),
            team,
            player,
            budget: None,
            status_period: Some(Duration::from_millis(750)),
            status_port: GAMECONTROLLER_RETURN_PORT,
            status_from: SocketAddr::V4(SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, 0)),
            lost_after: Duration::from_secs(5),
        }
    }
}

/// A running listener; it stops when dropped.
pub struct GameController {
    task: tokio::task::JoinHandle<()>,
    listener: Rc<RefCell<GcListener>>,
    /// `local.var.gc.*` is the listener's while it runs: relay clients get `ERR 423`.
    _read_only: crate::Guard,
}

impl Drop for GameController {
    fn drop(&mut self) {
        self.task.abort();
    }
}

impl GameController {
    /// Binds the sockets and starts the listener on the current `LocalSet`.
    pub fn start(handle: &Handle, config: GameControllerConfig) -> std::io::Result<GameController> {
        let socket = socket2::Socket::new(
            socket2::Domain::for_address(config.listen),
            socket2::Type::DGRAM,
            Some(socket2::Protocol::UDP),
        )?;
        // Several daemons on one host (a team rehearsed on one laptop) all hear the
        // GC's broadcast.
        socket.set_reuse_address(true)?;
        socket.set_reuse_port(true)?;
        socket.set_nonblocking(true)?;
        socket.bind(&config.listen.into())?;
        let listen = UdpSocket::from_std(socket.into())?;
        let status = match config.status_period {
            Some(_) => {
                let s = std::net::UdpSocket::bind(config.status_from)?;
                s.set_nonblocking(true)?;
                Some(UdpSocket::from_std(s)?)
            }
            None => None,
        };
        let listener = Rc::new(RefCell::new(GcListener::new(config)));
        let read_only = handle
            .reserve(crate::guard::GC_KEYS, crate::guard::GC_OWNER)
            .expect("a valid pattern");
        let task = tokio::task::spawn_local(run(handle.clone(), listen, status, listener.clone()));
        Ok(GameController {
            task,
            listener,
            _read_only: read_only,
        })
    }

    /// The tracker's counters and newest packet so far.
    pub fn tracker(&self) -> GameTracker {
        self.listener.borrow().tracker.clone()
    }
}

/// What the listener reads and writes: the daemon's [`Handle`], or a node's replica
/// under its lock.
pub trait GcBoard {
    /// The driver's clock.
    fn now(&self) -> comms::Instant;
    /// Writes `key` (the listener's `local` keys); a refusal is logged and dropped.
    fn set(&mut self, key: &'static str, value: Value);
    /// The value at `key`.
    fn get(&self, key: &str) -> Option<comms::Entry>;
    /// The GC's figures for the replica's budget, as [`Handle::set_external_budget`].
    fn set_external_budget(&mut self, game_remaining: Option<Duration>, cap: Option<ExternalCap>);
}

impl GcBoard for Handle {
    fn now(&self) -> comms::Instant {
        Handle::now(self)
    }

    fn set(&mut self, key: &'static str, value: Value) {
        if let Err(e) = Handle::set(self, key, value) {
            tracing::debug!(key, error = %e, "cannot write");
        }
    }

    fn get(&self, key: &str) -> Option<comms::Entry> {
        Handle::get(self, key).ok().flatten()
    }

    fn set_external_budget(&mut self, game_remaining: Option<Duration>, cap: Option<ExternalCap>) {
        Handle::set_external_budget(self, game_remaining, cap);
    }
}

/// The listener without its sockets or timers: a GC datagram in ([`GcListener::receive`]),
/// a status packet out every [`GameControllerConfig::status_period`]
/// ([`GcListener::status`]), the GC's silence checked every second after the first three
/// ([`GcListener::check`]).
pub struct GcListener {
    config: GameControllerConfig,
    tracker: GameTracker,
    written: Written,
    /// Whether the replica's budget follows the GC now.
    following: bool,
    /// When the last "no GC" warning was.
    warned_at: Option<Duration>,
    status_sent: u64,
}

impl GcListener {
    /// A listener with `config`, having heard nothing.
    pub fn new(config: GameControllerConfig) -> GcListener {
        if config.status_period.is_some() && !(1..=20).contains(&config.player) {
            tracing::warn!(
                player = config.player,
                "GameController: player numbers are 1-20: no status packets will be sent"
            );
        }
        GcListener {
            tracker: GameTracker::new(config.team, config.player),
            config,
            written: Written::default(),
            following: false,
            warned_at: None,
            status_sent: 0,
        }
    }

    /// Its settings.
    pub fn config(&self) -> &GameControllerConfig {
        &self.config
    }

    /// The tracker's counters and newest packet so far.
    pub fn tracker(&self) -> &GameTracker {
        &self.tracker
    }

    /// A datagram from `from` on the GC port: tracked, written, fed to the budget.
    pub fn receive(&mut self, board: &mut impl GcBoard, from: SocketAddr, bytes: &[u8]) {
        let now = since_start(board);
        match self.tracker.receive(now, from, bytes) {
            Ok(gamecontroller::Received::Accepted) => {
                self.written.write(board, &self.tracker);
                if let Some(budget) = &self.config.budget {
                    if !self.following {
                        tracing::info!(%from, "GameController heard: the message budget follows its figures");
                    }
                    self.following = true;
                    feed_budget(board, budget, &self.tracker);
                }
            }
            Ok(gamecontroller::Received::Stale) => {}
            Err(e) => tracing::debug!(%from, error = %e, "GameController packet dropped"),
        }
        self.written.stats(board, &self.tracker, self.status_sent);
    }

    /// The status period's turn: this robot's status to the GC through `send` (the packet
    /// and the GC's status address), if a GC is heard and the player number is valid.
    pub fn status(
        &mut self,
        board: &mut impl GcBoard,
        send: impl FnOnce(&[u8], SocketAddr) -> std::io::Result<usize>,
    ) {
        let now = since_start(board);
        let Some(mut to) = self.tracker.gc_address() else {
            return;
        };
        if !(self.tracker.is_live(now, self.config.lost_after)
            && (1..=20).contains(&self.config.player))
        {
            return;
        }
        to.set_port(self.config.status_port);
        let msg = status_inputs(board).to_message(self.config.player, self.config.team);
        match send(&msg.encode(), to) {
            Ok(_) => self.status_sent += 1,
            Err(e) => tracing::debug!(%to, error = %e, "status packet not sent"),
        }
        self.written.stats(board, &self.tracker, self.status_sent);
    }

    /// The once-a-second check: a GC gone silent gives the budget back to the replica's
    /// own accounting; a GC never heard under a budget is said loudly, once a minute.
    pub fn check(&mut self, board: &mut impl GcBoard) {
        let now = since_start(board);
        let live = self.tracker.is_live(now, self.config.lost_after);
        if self.config.budget.is_none() || live {
            return;
        }
        if self.following {
            // The GC's last figure stays in force: the replica keeps counting this robot's
            // frames and the teammates' heard against it, so the team never goes past the
            // GC's last `messageBudget` less the margin, however long the silence (a GC
            // still counting the team's messages, only its own packets lost, would see no
            // more). The replica's own pacing still applies on top (`next_ordinary` takes
            // the later of the two), so it can only be stricter. Forgetting the figure
            // here let a robot go back to its own accounting from its start: +17 frames
            // in 30 s of silence with 16 left and a margin of 14
            // (`docs/review-30-34/gc_outage.py`).
            self.following = false;
            tracing::warn!(
                "GameController not heard for {:?}: the message budget keeps to its last \
                 figure less the frames sent since, until it is heard again",
                self.config.lost_after
            );
            self.warned_at = Some(now);
        } else if self
            .warned_at
            .is_none_or(|w| now.saturating_sub(w) >= Duration::from_secs(60))
        {
            self.warned_at = Some(now);
            tracing::warn!(
                listen = %self.config.listen,
                "NO GAMECONTROLLER heard: the league budget is paced from this daemon's \
                 start, not the game's clock, and cannot see the team's count; a GC's \
                 messageBudget of 0 would not stop it (--no-gamecontroller to silence)"
            );
        }
    }
}

/// The driver clock as the tracker's time.
fn since_start(board: &impl GcBoard) -> Duration {
    Duration::from_micros(board.now().as_micros())
}

async fn run(
    mut handle: Handle,
    listen: UdpSocket,
    status: Option<UdpSocket>,
    listener: Rc<RefCell<GcListener>>,
) {
    let mut buf = [0u8; 2048];
    let period = listener
        .borrow()
        .config
        .status_period
        .unwrap_or(Duration::from_secs(3600));
    let mut status_tick = tokio::time::interval(period);
    status_tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    // The first check after a grace period: a GC sends twice a second.
    let mut check = tokio::time::interval_at(
        tokio::time::Instant::now() + Duration::from_secs(3),
        Duration::from_secs(1),
    );
    loop {
        tokio::select! {
            r = listen.recv_from(&mut buf) => {
                match r {
                    Ok((len, from)) => listener.borrow_mut().receive(&mut handle, from, &buf[..len]),
                    Err(e) => tracing::debug!(error = %e, "GameController socket"),
                }
            }
            _ = status_tick.tick(), if status.is_some() => {
                if let Some(socket) = &status {
                    listener
                        .borrow_mut()
                        .status(&mut handle, |packet, to| socket.try_send_to(packet, to));
                }
            }
            _ = check.tick() => listener.borrow_mut().check(&mut handle),
        }
    }
}

/// The replica's budget from the GC's newest figures, its clock paced from the play
/// whistle the team layer acts on (which its tick publishes at
/// [`team::contract::PLAY_WHISTLE_KEY`]; a daemon without the layer has none).
fn feed_budget(board: &mut impl GcBoard, budget: &GcBudget, t: &GameTracker) {
    let play_whistle_at = board
        .get(team::contract::PLAY_WHISTLE_KEY)
        .and_then(|e| match e.value {
            Value::Floats(at) => at.first().copied(),
            _ => None,
        });
    let now_s = team::seconds(board.now());
    if let Some((remaining, cap)) = budget_figures(budget, t, play_whistle_at, now_s) {
        board.set_external_budget(Some(remaining), Some(cap));
    }
}

/// What the GC's newest packet in `t` gives a replica's budget at `now_s`: the game time
/// left over the halves and the team's cap (`None`: no packet of this team's game yet).
/// The daemon's listener and the simulator's robots feed their replicas with this. The
/// game time is [`team::paced_game_remaining`]'s: it runs from `play_whistle_at`, the
/// play whistle the team layer acts on ([`team::TeamLayer::play_whistle_at`]), while the
/// packet still says Set (GameController3's delayed copy).
///
/// The line is drawn on what the team may spend, the GC's messages less the margin
/// (1,186 of 1,200 over the game for five robots), so that the margin is never counted
/// as spent: drawn on the whole 1,200, the team was 14 messages behind its line at the
/// kick-off and sent nothing, claims included, for the first 10–20 s of play, while
/// every robot went for the ball (`huddle sim --game full`, seeds 1–3: a 17 s conflict
/// at the first kick-off).
pub fn budget_figures(
    budget: &GcBudget,
    t: &GameTracker,
    play_whistle_at: Option<f64>,
    now_s: f64,
) -> Option<(Duration, ExternalCap)> {
    let cap = budget.cap(t.game()?, t.team_number())?;
    let says_set = t.state() == Some(gamecontroller::State::Set);
    let game_s = 2.0 * budget.half.as_secs_f64();
    let usable = budget.messages_per_game.saturating_sub(budget.margin);
    Some((
        team::paced_game_remaining(play_whistle_at, cap.game_remaining, says_set, now_s),
        ExternalCap {
            counted: cap.counted,
            team_left: u64::from(cap.team_left),
            rate_per_s: if game_s > 0.0 {
                f64::from(usable) / game_s
            } else {
                0.0
            },
            margin: u64::from(budget.margin),
        },
    ))
}

/// This team's penalised player numbers in the GC's newest packet (substitutes count:
/// they are not on the field).
pub fn penalized_players(t: &GameTracker) -> Vec<u8> {
    t.own_team().map_or_else(Vec::new, |team| {
        (1..=gamecontroller::MAX_NUM_PLAYERS as u8)
            .filter(|&n| {
                team.player(n)
                    .is_some_and(|r| r.penalty != gamecontroller::PENALTY_NONE)
            })
            .collect()
    })
}

/// Where `age_s` is in `local.var.team.ball`'s floats
/// (`[x, y, vx, vy, var_x, cov_xy, var_y, confidence, age_s]`, `docs/team-layer.md`).
const TEAM_BALL_AGE_S: usize = 8;

/// The status packet's inputs from the documented keys.
fn status_inputs(board: &impl GcBoard) -> StatusInputs {
    let floats = |key: &str| match board.get(key) {
        Some(e) => match e.value {
            Value::Floats(v) => Some((v, e.stamp)),
            _ => None,
        },
        _ => None,
    };
    let now = board.now();
    let pose = floats("local.var.robot.pose")
        .filter(|(v, _)| v.len() >= 3)
        .map(|(v, _)| [v[0], v[1], v[2]]);
    // The team layer rewrites `local.var.team.ball` every tick: the entry's own age is
    // ~0 always. The ball's age is the value's `age_s` (its 9th float, the newest
    // sighting's age when written) plus the entry's age since. A program's own `[x, y]`
    // without `age_s` has only the entry's age to go by.
    let ball = floats("local.var.team.ball")
        .filter(|(v, _)| v.len() >= 2)
        .map(|(v, stamp)| {
            let since = now.saturating_duration_since(stamp).as_secs_f64();
            let age_s = v.get(TEAM_BALL_AGE_S).copied().unwrap_or(0.0);
            ([v[0], v[1]], age_s + since)
        });
    let fallen = matches!(
        board.get("local.var.robot.fallen"),
        Some(comms::Entry {
            value: Value::Bool(true),
            ..
        })
    );
    StatusInputs { pose, ball, fallen }
}

/// What was last written to the blackboard, so only changes are written.
#[derive(Default)]
struct Written {
    values: Vec<(&'static str, Value)>,
}

impl Written {
    fn put(&mut self, board: &mut impl GcBoard, key: &'static str, value: Value) {
        match self.values.iter_mut().find(|(k, _)| *k == key) {
            Some((_, v)) if *v == value => return,
            Some((_, v)) => *v = value.clone(),
            None => self.values.push((key, value.clone())),
        }
        board.set(key, value);
    }

    fn write(&mut self, handle: &mut impl GcBoard, t: &GameTracker) {
        let Some(g) = t.game() else { return };
        let int = |v: i64| Value::Int(v);
        let text = |s: &str| Value::String(s.to_owned());
        self.put(handle, "local.var.gc.state", text(g.state.name()));
        self.put(handle, "local.var.gc.game_phase", text(g.game_phase.name()));
        self.put(handle, "local.var.gc.set_play", text(g.set_play.name()));
        self.put(
            handle,
            "local.var.gc.kicking_team",
            int(g.kicking_team.into()),
        );
        self.put(handle, "local.var.gc.first_half", Value::Bool(g.first_half));
        self.put(
            handle,
            "local.var.gc.secs_remaining",
            int(g.secs_remaining.into()),
        );
        self.put(
            handle,
            "local.var.gc.secondary_time",
            int(g.secondary_time.into()),
        );
        self.put(
            handle,
            "local.var.gc.counted",
            Value::Bool(g.messages_counted()),
        );
        if let Some(team) = t.own_team() {
            self.put(handle, crate::team::GC_SCORE_KEY, int(team.score.into()));
            self.put(
                handle,
                "local.var.gc.budget",
                int(team.message_budget.into()),
            );
        }
        if let Some(other) = t.opponent() {
            self.put(
                handle,
                crate::team::GC_OPPONENT_SCORE_KEY,
                int(other.score.into()),
            );
        }
        self.put(
            handle,
            crate::team::PENALIZED_KEY,
            Value::Floats(penalized_players(t).into_iter().map(f64::from).collect()),
        );
        if let Some(me) = t.robot(t.player_number()) {
            self.put(handle, "local.var.gc.penalty", int(me.penalty.into()));
            self.put(
                handle,
                "local.var.gc.penalty_secs",
                int(me.secs_till_unpenalised.into()),
            );
        }
    }

    fn stats(&mut self, handle: &mut impl GcBoard, t: &GameTracker, status_sent: u64) {
        let s = t.stats();
        for (key, n) in [
            (crate::team::GC_ACCEPTED_KEY, s.accepted),
            ("local.var.huddle.stats.gc.stale", s.stale),
            ("local.var.huddle.stats.gc.bad_length", s.bad_length),
            ("local.var.huddle.stats.gc.bad_header", s.bad_header),
            ("local.var.huddle.stats.gc.wrong_version", s.wrong_version),
            ("local.var.huddle.stats.gc.bad_field", s.bad_field),
            ("local.var.huddle.stats.gc.wrong_team", s.wrong_team),
            ("local.var.huddle.stats.gc.status_sent", status_sent),
        ] {
            self.put(
                handle,
                key,
                Value::Int(i64::try_from(n).unwrap_or(i64::MAX)),
            );
        }
    }
}

#[cfg(test)]
#[path = "gamecontroller_tests.rs"]
mod tests;
