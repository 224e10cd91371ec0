//! A simulated GameController: the referee of `huddle sim --game full`, sans I/O.
//!
//! [`Referee`] runs a whole SPL game as GameController3 does and keeps its books: the
//! states (Initial → Standby → Ready → Set → Playing, Finished), two halves and the break
//! between them, the game clock (it runs in Playing only), goals with their Ready/Set
//! restarts (the conceding team kicks off), penalties (a robot removed for 45 s) and the
//! team's message budget as the GC counts it:
//!
//! - a team message is counted when the true state is Standby, Ready, Set or Playing
//!   ([`GameControlData::messages_counted`]); each takes 1 from `messageBudget` (1,200 per
//!   game, not refilled at half-time);
//! - a message over 128 B, or one sent while the budget is 0, makes the team illegal
//!   (GameController3 `team_message.rs`): the report says whether that ever happened.
//!
//! It broadcasts a [`GameControlData`] every 500 ms ([`Referee::packet`]); the simulator
//! hands each robot the packet's **encoded bytes**, which the robot decodes through its
//! own [`gamecontroller::GameTracker`] and feeds to its replica's budget exactly as
//! `huddle daemon` does (`driver::gamecontroller`).
//!
//! Penalties run on GameController3's penalty timer (`actions/penalize.rs`,
//! `timer.rs`): it counts down in Ready and Playing only (`RunCondition::ReadyOrPlaying`:
//! not in Set, Initial, Standby or Finished), so a penalty that spans a goal's restart
//! lasts its 45 s plus the Set; at 0 the robot is put back (the GC clips the timer at 0
//! and the assistant referee returns the robot then). A half's end stops the timers
//! (`FinishHalf`) and the robots stay off until the half-time switch, half way through
//! the break, unpenalises them all (`SwitchHalf`).
//!
//! **What it shows** ([`Referee::shown`], the packets) is GameController3's *delayed
//! copy* of the game, as GC3 forms it (`game_controller_runtime` sends
//! `get_game(true)`; `action.rs` `fork`, `lib.rs` `DelayHandler`, `apply_delayed`), with
//! the league's delays ([`GcDelays`], `config/*/params.yaml`: 15, 15 and 45 s):
//!
//! - **Set → Playing** (`free_set_play.rs`, `delayAfterPlaying`): the packets say Set,
//!   with the clock as it stood, for 15 s after the whistle (a robot is expected to hear
//!   the whistle itself);
//! - **a goal** (`goal.rs`, `delayAfterGoal`): the packets say Playing with the old score
//!   (the clock running on in the copy) for 15 s, then Ready with the new score (the
//!   goal is not applied to the copy); a goal during the Set delay forks a new copy, so
//!   the packets jump from Set to Playing with the old score;
//! - **Standby → Ready** for a half's kick-off (`start_set_play.rs`, `delayAfterReady`):
//!   the packets say Standby for 45 s, or until the operator calls Set, whichever comes
//!   first: the Set is illegal in the copy (still Standby) and `apply_delayed` ends the
//!   delay then (with the SPL's `readyDuration` of 45 s the timer's own Set ends it at
//!   45 s, the same instant);
//! - the team's `messageBudget` and the penalties are current (every action is applied to
//!   the copy too), and a half's end ends a delay (`FinishHalf` in the copy, or illegal
//!   there).
//!
//! The field, the message count and the report go by the **true** state ([`Referee::data`]).
//! [`GcDelays::none`] is GameController3's `test.no_delay` (`huddle sim --gc-delays none`):
//! the packets show the true state, the referee of the tenth session and before.
//!
//! What it simplifies: the clock stands in Ready and Set (GameController3's rule for a
//! "long" game, a knock-out one; in other games it runs on after the half's first
//! kick-off), a goal's Ready and Set take fixed times ([`GameScript`]), the delayed copy's
//! own penalty timers are not run apart (its penalties are the true ones), and the mercy
//! rule (10 goals ahead ends the game, with no delay) is not modelled.
//!
//! A goal ([`Referee::goal`]) changes the score and the state (to Ready) at the step the
//! ball crosses the line: the operator presses "goal" at once. On a real field the
//! operator presses it after the referee's whistle, seconds later (not modelled: no
//! operator delay is added), so the packets here carry a goal sooner than a real GC's.
//! The robots learn it only from those packets, each from the first one with the new
//! score that reaches it (`TeamLayer::set_scores`), or at Set if none did.
//!
//! No clock and no randomness of its own: every call takes the simulated time, seconds
//! ([`WhistleHearing::hear`] draws from its caller's generator).

use gamecontroller::{GameControlData, SetPlay, State, KICKING_TEAM_NONE};
use player::robot::Order;
use rand::RngExt;
use serde::Serialize;
use team::Whistle;

/// GameController3's `PENALTY_SPL_PLAYER_PUSHING`: the scripted penalties' code.
pub const PENALTY_PUSHING: u8 = 2;

/// Largest team message the SPL allows, bytes.
pub const MAX_MESSAGE_BYTES: usize = 128;

/// The GC broadcasts its packet this often, seconds.
pub const PACKET_PERIOD_S: f64 = 0.5;

/// One scripted penalty.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ScriptedPenalty {
    /// Our player number (robot id).
    pub robot: u8,
    /// The half (1 or 2).
    pub half: u8,
    /// After this much play in the half, seconds.
    pub after_play_s: f64,
}

/// GameController3's delays of the state it sends the robots (`params.yaml`'s
/// `delayAfterPlaying`, `delayAfterGoal`, `delayAfterReady`; see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GcDelays {
    /// Set shown after the whistle that starts play, seconds (GC3: 15).
    pub after_playing_s: f64,
    /// Playing with the old score shown after a goal, seconds (GC3: 15).
    pub after_goal_s: f64,
    /// Standby shown after a half's Standby → Ready, seconds (GC3: 45; the operator's Set
    /// ends it sooner).
    pub after_ready_s: f64,
}

impl GcDelays {
    /// The league's (GameController3's `config/champions_cup/params.yaml`): 15, 15, 45 s.
    pub fn gc3() -> GcDelays {
        GcDelays {
            after_playing_s: 15.0,
            after_goal_s: 15.0,
            after_ready_s: 45.0,
        }
    }

    /// No delay (GameController3's `test.no_delay`): the packets show the true state.
    pub fn none() -> GcDelays {
        GcDelays {
            after_playing_s: 0.0,
            after_goal_s: 0.0,
            after_ready_s: 0.0,
        }
    }
}

/// How the robot programs hear the referee's whistle (the robots' side of the game, not
/// the team layer's): each robot hears each whistle (Standby → Ready, the kick-off's
/// Set → Playing, a goal) with probability `p_heard`, after a delay drawn uniformly
/// from `delay_s`; one that misses it goes by the GC's (delayed) packets. The
/// simulator tells the program's whistle to its team layer through the daemon's path
/// (`TeamLayer::heard_whistle`, contract key `local.var.robot.whistle`).
///
/// The default ([`WhistleHearing::typical`], 90%, 0.2–1.0 s) is an assumption, not a
/// measurement: SPL teams' whistle detectors are reported to hear most whistles on a
/// quiet field and to miss some in a loud hall; the delay is a detector's window of
/// a few hundred ms and the time a program takes to act on it.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct WhistleHearing {
    /// The chance a robot hears a whistle.
    pub p_heard: f64,
    /// How late it hears it, seconds: drawn uniformly between the two.
    pub delay_s: (f64, f64),
}

impl WhistleHearing {
    /// 90% of whistles heard, 0.2–1.0 s late.
    pub fn typical() -> WhistleHearing {
        WhistleHearing {
            p_heard: 0.9,
            delay_s: (0.2, 1.0),
        }
    }

    /// No robot program hears a whistle: the team goes by the GC's packets alone.
    pub fn deaf() -> WhistleHearing {
        WhistleHearing {
            p_heard: 0.0,
            ..WhistleHearing::typical()
        }
    }
}

impl WhistleHearing {
    /// One robot program's hearing of a whistle blown at `t_s`: when it hears it
    /// (simulated seconds), or `None` if it misses it. Two draws from `rng` whether it
    /// hears or not, so one robot's luck leaves the others' draws as they were. The
    /// in-process game and `--daemons --game` both draw with this.
    pub fn hear(&self, rng: &mut impl rand::Rng, t_s: f64) -> Option<f64> {
        let hears = rng.random::<f64>() < self.p_heard;
        let u = rng.random::<f64>();
        hears.then(|| t_s + self.delay_s.0 + u * (self.delay_s.1 - self.delay_s.0).max(0.0))
    }
}

/// What a game's caller tallies of the referee's packets and events: the caller's part
/// of [`GcBooks`], one struct for the in-process game and the `--daemons` game.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct GameTally {
    pub(crate) penalties: u32,
    pub(crate) kick_offs: u32,
    pub(crate) packets: u64,
    pub(crate) packets_lost: u64,
    pub(crate) whistles_heard: u32,
    pub(crate) whistles_missed: u32,
}

impl GameTally {
    /// The referee whistled at `t_s`: each robot's program hears it (when, pushed on its
    /// list in `due`) or misses it, as `hearing` draws from `rng`.
    pub(crate) fn whistle(
        &mut self,
        hearing: WhistleHearing,
        rng: &mut impl rand::Rng,
        t_s: f64,
        due: &mut [Vec<f64>],
    ) {
        for heard in due {
            match hearing.hear(rng, t_s) {
                Some(at) => {
                    heard.push(at);
                    self.whistles_heard += 1;
                }
                None => self.whistles_missed += 1,
            }
        }
    }
}

/// What a robot program does on what it heard of the referee: the one rule of the
/// in-process robots and of the `--daemons` programs. `heard`: the state the GC's
/// packets show it (`None`: none heard yet); `penalised`: it is (its packets say so, or
/// it stands on the sideline); `whistle`: a whistle it heard that the GC has not caught
/// up with (play started: it plays; a goal: it walks to its kick-off spot, the goal's
/// Ready that the GC shows 15 s late); `standby_whistle`: it heard the whistle that ends
/// a half's Standby (the half's Ready, which the GC shows up to 45 s late).
pub fn program_order(
    heard: Option<State>,
    penalised: bool,
    whistle: Option<Whistle>,
    standby_whistle: bool,
) -> Order {
    match (heard, whistle) {
        _ if penalised => Order::Stand,
        (_, Some(Whistle::PlayStarted(_))) => Order::Play,
        (_, Some(Whistle::Goal(_))) => Order::KickOffSpot,
        (Some(State::Playing), _) => Order::Play,
        (Some(State::Ready), _) => Order::KickOffSpot,
        (Some(State::Standby), _) if standby_whistle => Order::KickOffSpot,
        _ => Order::Stand,
    }
}

/// How the game goes: the league's timings and the scripted penalties.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GameScript {
    /// Halves played: 2 for a game; 1 for the 600 s run's like-for-like counterpart
    /// ([`GameScript::one_half`]): the game ends at the first half's end, no break.
    pub halves: u8,
    /// A half's playing time, seconds (SPL: 600).
    pub half_s: f64,
    /// The half-time break, seconds (SPL: 600).
    pub break_s: f64,
    /// Initial before each half, seconds.
    pub initial_s: f64,
    /// Standby before each half's first Ready, seconds.
    pub standby_s: f64,
    /// Ready before each kick-off, seconds (the rules allow up to 45).
    pub ready_s: f64,
    /// Set before each kick-off, seconds.
    pub set_s: f64,
    /// Finished shown at the end of the game before the simulation stops, seconds.
    pub finished_s: f64,
    /// How long a penalised robot stays off the field, seconds (SPL: 45).
    pub penalty_s: f64,
    /// Team messages per game (SPL: 1,200).
    pub messages_per_game: u16,
    /// The penalties, in any order.
    pub penalties: Vec<ScriptedPenalty>,
    /// How late the packets show the game ([`GcDelays::gc3`] by default).
    pub delays: GcDelays,
    /// How the robot programs hear the whistle ([`WhistleHearing::typical`] by default).
    pub whistle: WhistleHearing,
}

impl GameScript {
    /// An SPL game (two 10-minute halves, a 10-minute break) with two penalties: robot
    /// 3 after 200 s of the first half, robot 4 after 300 s of the second (when a team
    /// has them; the last robot otherwise).
    pub fn spl_full(robots: usize) -> GameScript {
        let last = u8::try_from(robots.max(1)).unwrap_or(u8::MAX);
        GameScript {
            halves: 2,
            half_s: 600.0,
            break_s: 600.0,
            initial_s: 10.0,
            standby_s: 10.0,
            ready_s: 30.0,
            set_s: 5.0,
            finished_s: 5.0,
            penalty_s: 45.0,
            messages_per_game: 1200,
            penalties: vec![
                ScriptedPenalty {
                    robot: 3.min(last),
                    half: 1,
                    after_play_s: 200.0,
                },
                ScriptedPenalty {
                    robot: 4.min(last),
                    half: 2,
                    after_play_s: 300.0,
                },
            ],
            delays: GcDelays::gc3(),
            whistle: WhistleHearing::typical(),
        }
    }

    /// The 600 s run's like-for-like counterpart (`huddle sim --game restarts`): one
    /// 10-minute half under the referee, with the game's Initial/Standby/Ready/Set
    /// before its kick-off and the game's Ready/Set restart from the formation after
    /// every goal, but no break, no penalties. What is left between it and the full
    /// game is the second half, the break and the penalties.
    pub fn one_half() -> GameScript {
        GameScript {
            halves: 1,
            penalties: Vec::new(),
            ..GameScript::spl_full(1)
        }
    }

    /// The game's length if no goal is scored, seconds (each goal adds a Ready and a Set).
    pub fn length_s(&self) -> f64 {
        let half = self.initial_s + self.standby_s + self.ready_s + self.set_s + self.half_s;
        if self.halves <= 1 {
            half + self.finished_s
        } else {
            2.0 * half + self.break_s + self.finished_s
        }
    }
}

/// Something the referee did that the field must show.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RefereeEvent {
    /// The true state changed.
    State(State),
    /// Our robot (player number) was penalised: carry it off the field.
    Penalised(u8),
    /// Our robot's penalty is over: put it back on the field.
    Unpenalised(u8),
    /// The referee whistled: Standby → Ready, Set → Playing, or a goal (with the goal's
    /// `State(Ready)`). What the robots may hear, the packets aside.
    Whistle,
}

/// The GC's count of the team's messages.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct MessageCount {
    /// Messages in counted states (each took one from `messageBudget`).
    pub counted: u64,
    /// Messages in states the GC does not count (Initial, Finished, the break).
    pub uncounted: u64,
    /// Messages over 128 B.
    pub oversized: u64,
    /// Messages that made the team illegal (over 128 B, or counted at a budget of 0).
    pub illegal: u64,
    /// When the team first became illegal, simulated seconds.
    pub illegal_at_s: Option<f64>,
}

/// The referee's books at a game's end as both reports show them (flattened into the
/// in-process [`crate::GameReport`] and the `--daemons` one,
/// [`crate::daemons_game::DaemonsGameReport`]). [`Referee::books`] fills what the
/// referee keeps; the tallies of what its caller does with it (penalties carried off,
/// kick-offs, packets sent and lost, whistles heard) come from the caller.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct GcBooks {
    /// The team became illegal at least once (a message over 128 B or at a budget of 0).
    pub game_illegal: bool,
    /// Messages that made the team illegal.
    pub game_illegal_messages: u64,
    /// When it first became illegal, game seconds.
    pub game_illegal_at_s: Option<f64>,
    /// Messages the GC counted (sent in Standby, Ready, Set or Playing).
    pub game_messages_counted: u64,
    /// Frames sent in states the GC does not count (Initial, Finished, the break).
    pub game_messages_uncounted: u64,
    /// Messages over 128 B.
    pub game_messages_oversized: u64,
    /// The GC's `messageBudget` for the team at the end.
    pub game_budget_left: u16,
    /// Counted messages as a share of the game's budget, %.
    pub game_budget_used_pct: f64,
    /// The score, ours first.
    pub game_score: [u8; 2],
    /// Seconds of Playing.
    pub game_playing_s: f64,
    /// Penalties given to our robots (the caller's tally).
    pub game_penalties: u32,
    /// Stretches of Playing, each beginning with a kick-off (the caller's tally).
    pub game_kick_offs: u32,
    /// GC packets sent (the caller's tally).
    pub game_packets: u64,
    /// Packet receptions lost on the way to the robots (the caller's tally).
    pub game_packets_lost: u64,
    /// (robot, whistle) pairs the robot programs heard ([`WhistleHearing`]; the
    /// caller's tally).
    pub game_whistles_heard: u32,
    /// … and missed.
    pub game_whistles_missed: u32,
}

impl std::fmt::Display for GcBooks {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "game                  score {}–{}, {:.0} s played, {} kick-offs, {} penalties; {} GC packets ({} receptions lost); whistles {} heard, {} missed",
            self.game_score[0],
            self.game_score[1],
            self.game_playing_s,
            self.game_kick_offs,
            self.game_penalties,
            self.game_packets,
            self.game_packets_lost,
            self.game_whistles_heard,
            self.game_whistles_missed
        )?;
        write!(
            f,
            "GC's count            {} counted ({:.1}% of the budget, {} left), {} in uncounted states, {} over 128 B; illegal: {}",
            self.game_messages_counted,
            self.game_budget_used_pct,
            self.game_budget_left,
            self.game_messages_uncounted,
            self.game_messages_oversized,
            match self.game_illegal_at_s {
                Some(t) => format!("YES, {} messages, first at {t:.1} s", self.game_illegal_messages),
                None => "never".to_string(),
            }
        )
    }
}

/// Where the game is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Stage {
    /// Before the half's first Ready (Initial, then Standby).
    Start,
    /// Ready, Set or Playing in a half.
    Half,
    /// The half-time break (Finished).
    Break,
    /// The game is over (Finished).
    Over,
}

/// GameController3's delayed copy of the game while a delay runs (its `DelayHandler`).
#[derive(Debug, Clone)]
struct Delayed {
    /// The copy: the game as it was when the delay began.
    data: GameControlData,
    /// When the delay ends, seconds.
    until_s: f64,
    /// The copy's own play left in the half (its clock runs in Playing), seconds.
    play_left_s: f64,
}

/// The simulated GameController. See the module docs.
#[derive(Debug, Clone)]
pub struct Referee {
    script: GameScript,
    ours: u8,
    data: GameControlData,
    stage: Stage,
    /// When the current state ends (Initial, Standby, Ready, Set, the break), seconds.
    state_until_s: f64,
    /// Play left in the half, seconds.
    play_left_s: f64,
    /// Penalties still to come, and those running: (robot, penalty time left, seconds;
    /// it counts down in Ready and Playing only, as GameController3's penalty timer).
    to_come: Vec<ScriptedPenalty>,
    running: Vec<(u8, f64)>,
    next_packet_s: f64,
    count: MessageCount,
    /// Seconds spent in each state (for the report).
    playing_s: f64,
    last_s: f64,
    /// The delayed copy the packets show while a delay runs.
    delayed: Option<Delayed>,
    /// What the packets show: the delayed copy, or the true game, as of the last step
    /// (read through [`Referee::shown`], which brings its budgets up to date).
    shown: GameControlData,
}

impl Referee {
    /// A game of our team `ours` against `theirs`, starting at `now_s` in Initial.
    pub fn new(script: GameScript, ours: u8, theirs: u8, now_s: f64) -> Referee {
        let mut data = GameControlData::new([ours, theirs]);
        data.secs_remaining = script.half_s.round() as i16;
        for t in &mut data.teams {
            t.message_budget = script.messages_per_game;
        }
        // We kick off the first half (the coin toss's winner, fixed for a seed-free script).
        data.kicking_team = ours;
        Referee {
            ours,
            stage: Stage::Start,
            state_until_s: now_s + script.initial_s,
            play_left_s: script.half_s,
            to_come: script.penalties.clone(),
            running: Vec::new(),
            next_packet_s: now_s,
            count: MessageCount::default(),
            playing_s: 0.0,
            last_s: now_s,
            delayed: None,
            shown: data,
            data,
            script,
        }
    }

    /// The game as the packets show it now: GameController3's delayed copy while a delay
    /// runs (see the module docs), the true game otherwise; with what every action keeps
    /// current in the copy, from the true game: the packet's number, the budgets as
    /// counted up to now (messages come between the referee's steps) and the penalties.
    pub fn shown(&self) -> GameControlData {
        let mut shown = self.shown;
        shown.packet_number = self.data.packet_number;
        for (s, t) in shown.teams.iter_mut().zip(&self.data.teams) {
            s.message_budget = t.message_budget;
            s.players = t.players;
        }
        shown
    }

    /// Whether a delay runs now: the packets show the game as it was.
    pub fn delayed(&self) -> bool {
        self.delayed.is_some()
    }

    /// The true game (the GC's own, undelayed; the packets show [`Referee::shown`]).
    pub fn data(&self) -> &GameControlData {
        &self.data
    }

    /// The true state.
    pub fn state(&self) -> State {
        self.data.state
    }

    /// Whether the ball is in play.
    pub fn playing(&self) -> bool {
        self.data.state == State::Playing
    }

    /// Whether the game is over.
    pub fn over(&self) -> bool {
        self.stage == Stage::Over && self.last_s >= self.state_until_s
    }

    /// Whether our robot `robot` is penalised now.
    pub fn penalised(&self, robot: u8) -> bool {
        self.running.iter().any(|&(r, _)| r == robot)
    }

    /// The team's messages as the GC counted them.
    pub fn count(&self) -> MessageCount {
        self.count
    }

    /// Our team's `messageBudget` now.
    pub fn budget_left(&self) -> u16 {
        self.data.team(self.ours).map_or(0, |t| t.message_budget)
    }

    /// Seconds of Playing so far.
    pub fn playing_s(&self) -> f64 {
        self.playing_s
    }

    /// The books as the reports show them, with the caller's tallies `t`.
    pub(crate) fn books_with(&self, t: &GameTally) -> GcBooks {
        GcBooks {
            game_penalties: t.penalties,
            game_kick_offs: t.kick_offs,
            game_packets: t.packets,
            game_packets_lost: t.packets_lost,
            game_whistles_heard: t.whistles_heard,
            game_whistles_missed: t.whistles_missed,
            ..self.books()
        }
    }

    /// The books as the reports show them, the caller's tallies at 0 (see [`GcBooks`]).
    pub fn books(&self) -> GcBooks {
        let c = self.count;
        let score = |n: u8| self.data.team(n).map_or(0, |t| t.score);
        let r3 = |x: f64| (x * 1000.0).round() / 1000.0;
        GcBooks {
            game_illegal: c.illegal > 0,
            game_illegal_messages: c.illegal,
            game_illegal_at_s: c.illegal_at_s.map(r3),
            game_messages_counted: c.counted,
            game_messages_uncounted: c.uncounted,
            game_messages_oversized: c.oversized,
            game_budget_left: self.budget_left(),
            game_budget_used_pct: (1000.0 * c.counted as f64
                / f64::from(self.script.messages_per_game.max(1)))
            .round()
                / 10.0,
            game_score: [score(self.ours), score(self.theirs())],
            game_playing_s: r3(self.playing_s),
            ..GcBooks::default()
        }
    }

    /// Runs the game up to `now_s`; returns what happened, in order.
    pub fn advance(&mut self, now_s: f64) -> Vec<RefereeEvent> {
        let mut events = Vec::new();
        let dt = (now_s - self.last_s).max(0.0);
        self.last_s = now_s;
        let state = self.data.state;
        if state == State::Playing {
            self.playing_s += dt;
            self.play_left_s -= dt;
            let played = self.script.half_s - self.play_left_s;
            let half = if self.data.first_half { 1 } else { 2 };
            let (due, later): (Vec<_>, Vec<_>) = self
                .to_come
                .iter()
                .copied()
                .partition(|p| p.half == half && played >= p.after_play_s);
            self.to_come = later;
            for p in due {
                if !self.penalised(p.robot) {
                    self.running.push((p.robot, self.script.penalty_s));
                    events.push(RefereeEvent::Penalised(p.robot));
                }
            }
        }
        // GameController3's penalty timer runs in Ready and Playing only; a half's end
        // stops it (the state is Finished then).
        if matches!(state, State::Ready | State::Playing) && self.stage == Stage::Half {
            for (_, left) in &mut self.running {
                *left -= dt;
            }
            let (over, still): (Vec<_>, Vec<_>) = self
                .running
                .iter()
                .copied()
                .partition(|&(_, left)| left <= 1e-9);
            self.running = still;
            events.extend(over.into_iter().map(|(r, _)| RefereeEvent::Unpenalised(r)));
        }
        match (self.stage, state) {
            (Stage::Start, State::Initial) if now_s >= self.state_until_s => {
                self.enter(State::Standby, now_s + self.script.standby_s, &mut events);
            }
            (Stage::Start, State::Standby) if now_s >= self.state_until_s => {
                self.stage = Stage::Half;
                self.fork(now_s, self.script.delays.after_ready_s);
                events.push(RefereeEvent::Whistle);
                self.enter(State::Ready, now_s + self.script.ready_s, &mut events);
            }
            (Stage::Half, State::Ready) if now_s >= self.state_until_s => {
                // The operator's Set is illegal in a copy still in Standby: the delay ends.
                self.delayed = None;
                self.enter(State::Set, now_s + self.script.set_s, &mut events);
            }
            (Stage::Half, State::Set) if now_s >= self.state_until_s => {
                self.fork(now_s, self.script.delays.after_playing_s);
                events.push(RefereeEvent::Whistle);
                self.enter(State::Playing, f64::INFINITY, &mut events);
            }
            (Stage::Half, State::Playing) if self.play_left_s <= 0.0 => {
                self.play_left_s = 0.0;
                // `FinishHalf` ends the copy's delay (it is illegal in it, or finishes it).
                self.delayed = None;
                // A half's end stops the penalty timers; the robots stay off until the
                // half-time switch (or the game's end).
                if self.data.first_half && self.script.halves > 1 {
                    self.stage = Stage::Break;
                    self.enter(State::Finished, now_s + self.script.break_s, &mut events);
                } else {
                    self.stage = Stage::Over;
                    self.enter(State::Finished, now_s + self.script.finished_s, &mut events);
                }
            }
            (Stage::Break, _)
                if !self.running.is_empty()
                    && now_s >= self.state_until_s - self.script.break_s / 2.0 =>
            {
                // GameController3's `SwitchHalf`, half way through the break: every
                // penalised robot (substitutes aside) is back.
                events.extend(
                    self.running
                        .drain(..)
                        .map(|(r, _)| RefereeEvent::Unpenalised(r)),
                );
            }
            (Stage::Break, _) if now_s >= self.state_until_s => {
                // The second half: the other team kicks off.
                self.data.first_half = false;
                self.play_left_s = self.script.half_s;
                self.data.kicking_team = self.theirs();
                self.stage = Stage::Start;
                self.enter(State::Initial, now_s + self.script.initial_s, &mut events);
            }
            _ => {}
        }
        if let Some(d) = &mut self.delayed {
            if d.data.state == State::Playing {
                d.play_left_s = (d.play_left_s - dt).max(0.0);
            }
            if now_s >= d.until_s {
                self.delayed = None;
            }
        }
        self.refresh(now_s);
        events
    }

    /// GameController3's `fork`: the packets show the game as it is now (before the
    /// action that calls it) for `delay_s` (none at 0).
    fn fork(&mut self, now_s: f64, delay_s: f64) {
        self.delayed = (delay_s > 0.0).then_some(Delayed {
            data: self.data,
            until_s: now_s + delay_s,
            play_left_s: self.play_left_s,
        });
    }

    /// A goal: `for_us` says whose. Counted in Playing only; the conceding team kicks
    /// off after Ready and Set.
    pub fn goal(&mut self, now_s: f64, for_us: bool) -> Vec<RefereeEvent> {
        let mut events = Vec::new();
        if self.data.state != State::Playing {
            return events;
        }
        let (scorer, conceding) = if for_us {
            (self.ours, self.theirs())
        } else {
            (self.theirs(), self.ours)
        };
        // The copy forked before the goal: Playing, the old score (a goal within the Set
        // delay forks anew, as GameController3's `Goal` does).
        self.fork(now_s, self.script.delays.after_goal_s);
        events.push(RefereeEvent::Whistle);
        if let Some(t) = self.data.team_mut(scorer) {
            t.score = t.score.saturating_add(1);
        }
        self.data.kicking_team = conceding;
        self.enter(State::Ready, now_s + self.script.ready_s, &mut events);
        self.refresh(now_s);
        events
    }

    /// One message of our team, `len` bytes, sent at `now_s`: counted as the GC counts.
    pub fn team_message(&mut self, now_s: f64, len: usize) {
        let mut illegal = false;
        if len > MAX_MESSAGE_BYTES {
            self.count.oversized += 1;
            illegal = true;
        }
        if self.data.messages_counted() {
            self.count.counted += 1;
            let ours = self.ours;
            if let Some(t) = self.data.team_mut(ours) {
                if t.message_budget == 0 {
                    illegal = true;
                } else {
                    t.message_budget -= 1;
                }
            }
        } else {
            self.count.uncounted += 1;
        }
        if illegal {
            self.count.illegal += 1;
            self.count.illegal_at_s.get_or_insert(now_s);
        }
    }

    /// The packet the GC broadcasts at `now_s`, if one is due (every 500 ms).
    pub fn packet(
        &mut self,
        now_s: f64,
    ) -> Option<[u8; gamecontroller::GAMECONTROLLER_STRUCT_SIZE]> {
        if now_s + 1e-9 < self.next_packet_s {
            return None;
        }
        self.next_packet_s += PACKET_PERIOD_S;
        self.data.packet_number = self.data.packet_number.wrapping_add(1);
        Some(self.shown().encode())
    }

    fn theirs(&self) -> u8 {
        self.data
            .teams
            .iter()
            .map(|t| t.team_number)
            .find(|&n| n != self.ours)
            .unwrap_or(self.ours)
    }

    fn enter(&mut self, state: State, until_s: f64, events: &mut Vec<RefereeEvent>) {
        self.data.state = state;
        self.data.set_play = SetPlay::None;
        self.state_until_s = until_s;
        events.push(RefereeEvent::State(state));
    }

    /// The packet's clocks and penalties from the books.
    fn refresh(&mut self, now_s: f64) {
        self.data.secs_remaining = self.play_left_s.ceil().clamp(0.0, 32767.0) as i16;
        let secondary = match self.data.state {
            State::Ready | State::Set | State::Initial | State::Standby => {
                self.state_until_s - now_s
            }
            State::Finished if self.stage == Stage::Break => self.state_until_s - now_s,
            _ => 0.0,
        };
        self.data.secondary_time = secondary.ceil().clamp(0.0, 32767.0) as i16;
        if self.stage == Stage::Over {
            self.data.kicking_team = KICKING_TEAM_NONE;
        }
        let running = self.running.clone();
        let ours = self.ours;
        if let Some(t) = self.data.team_mut(ours) {
            for (k, p) in t.players.iter_mut().enumerate() {
                let id = u8::try_from(k + 1).unwrap_or(u8::MAX);
                match running.iter().find(|&&(r, _)| r == id) {
                    Some(&(_, left)) => {
                        p.penalty = PENALTY_PUSHING;
                        p.secs_till_unpenalised = left.ceil().clamp(0.0, 255.0) as u8;
                    }
                    None => *p = gamecontroller::RobotInfo::default(),
                }
            }
        }
        self.shown = match &self.delayed {
            None => self.data,
            // The copy with its own clock ([`Referee::shown`] puts in what is current).
            Some(d) => {
                let mut shown = d.data;
                shown.secs_remaining = d.play_left_s.ceil().clamp(0.0, 32767.0) as i16;
                shown
            }
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs the referee in 10 ms steps to `until_s`, collecting its events.
    fn run_to(r: &mut Referee, from_s: f64, until_s: f64) -> Vec<(f64, RefereeEvent)> {
        let mut out = Vec::new();
        let mut t = from_s;
        while t < until_s {
            t += 0.01;
            out.extend(r.advance(t).into_iter().map(|e| (t, e)));
        }
        out
    }

    #[test]
    fn a_goalless_game_runs_the_spl_timeline_and_counts_only_counted_states() {
        // Script: two 600 s halves, a 600 s break, two penalties. One message a second
        // throughout: the GC counts those in Standby, Ready, Set and Playing only.
        let script = GameScript::spl_full(5);
        let length = script.length_s();
        let mut r = Referee::new(script, 12, 34, 0.0);
        let mut events = Vec::new();
        let mut t = 0.0;
        while !r.over() {
            events.extend(run_to(&mut r, t, t + 1.0));
            t += 1.0;
            r.team_message(t, 100);
            assert!(t < length + 10.0, "the game ends");
        }
        let states: Vec<State> = events
            .iter()
            .filter_map(|(_, e)| match e {
                RefereeEvent::State(s) => Some(*s),
                _ => None,
            })
            .collect();
        use State::*;
        assert_eq!(
            states,
            [
                Standby, Ready, Set, Playing, Finished, Initial, Standby, Ready, Set, Playing,
                Finished
            ],
            "the SPL's order of states"
        );
        let pens: Vec<_> = events
            .iter()
            .filter(|(_, e)| matches!(e, RefereeEvent::Penalised(_) | RefereeEvent::Unpenalised(_)))
            .collect();
        assert_eq!(pens.len(), 4, "two penalties, each with its end: {pens:?}");
        let (on, off) = (pens[0].0, pens[1].0);
        assert!(
            (off - on - 45.0).abs() < 0.02,
            "45 s off the field: {pens:?}"
        );
        let c = r.count();
        // Counted: 10 s Standby + 35 s Ready/Set + 600 s play, twice.
        assert!(
            (c.counted as f64 - 2.0 * 645.0).abs() <= 3.0,
            "counted {c:?}"
        );
        assert_eq!(
            c.illegal,
            c.counted - 1200,
            "every counted message past 1,200 is illegal: {c:?}"
        );
        assert_eq!(r.budget_left(), 0);
        assert!(c.illegal_at_s.is_some());
    }

    #[test]
    fn a_goal_restarts_with_ready_and_set_and_the_conceding_team_kicks_off() {
        let mut r = Referee::new(GameScript::spl_full(5), 12, 34, 0.0);
        run_to(&mut r, 0.0, 60.0);
        assert!(
            r.playing(),
            "playing after 55 s of Initial/Standby/Ready/Set"
        );
        let left = r.data().secs_remaining;
        assert!(r
            .goal(60.0, true)
            .contains(&RefereeEvent::State(State::Ready)));
        assert_eq!(r.data().team(12).map(|t| t.score), Some(1));
        assert_eq!(r.data().kicking_team, 34, "the conceding team kicks off");
        run_to(&mut r, 60.0, 91.0);
        assert_eq!(r.state(), State::Set, "30 s of Ready");
        assert_eq!(
            r.data().secs_remaining,
            left,
            "the clock stands in Ready and Set"
        );
        run_to(&mut r, 91.0, 96.0);
        assert!(r.playing(), "5 s of Set");
        // A goal outside Playing is not a goal.
        let mut r2 = Referee::new(GameScript::spl_full(5), 12, 34, 0.0);
        assert!(r2.goal(1.0, false).is_empty());
        assert_eq!(r2.data().team(34).map(|t| t.score), Some(0));
    }

    #[test]
    fn a_penalty_counts_in_ready_and_playing_only_as_the_gcs_penalty_timer() {
        // Robot 3 is penalised after 200 s of the first half's play (play begins at 55 s:
        // at 255 s). A goal at 260 s: Ready 30 s (the timer runs), Set 5 s (it stands),
        // then Playing. 5 + 30 + 10 = 45 s of timer: it is back at 305 s, 50 s after it
        // was picked up.
        let mut r = Referee::new(GameScript::spl_full(5), 12, 34, 0.0);
        let picked = run_to(&mut r, 0.0, 260.0);
        let on = picked
            .iter()
            .find(|(_, e)| *e == RefereeEvent::Penalised(3))
            .map(|(t, _)| *t)
            .expect("robot 3 penalised");
        // (10 ms steps: each state change lands on the step after it is due.)
        assert!((on - 255.0).abs() < 0.1, "after 200 s of play: {on}");
        assert!(r
            .goal(260.0, false)
            .contains(&RefereeEvent::State(State::Ready)));
        let after = run_to(&mut r, 260.0, 400.0);
        let off = after
            .iter()
            .find(|(_, e)| *e == RefereeEvent::Unpenalised(3))
            .map(|(t, _)| *t)
            .expect("robot 3 back");
        assert!(
            (off - on - 50.0).abs() < 0.1,
            "45 s of Ready and Playing, and the 5 s of Set on top: back after {:.2} s",
            off - on
        );
        // The packet counts down the timer, not the wall clock: it stands through Set at
        // the 10 s left (11 as the GC rounds up, the steps landing late).
        let mut r = Referee::new(GameScript::spl_full(5), 12, 34, 0.0);
        run_to(&mut r, 0.0, 260.0);
        r.goal(260.0, false);
        let secs = |r: &Referee| {
            r.data()
                .team(12)
                .map(|t| t.players[2].secs_till_unpenalised)
        };
        run_to(&mut r, 260.0, 291.0);
        assert_eq!(r.state(), State::Set);
        let early = secs(&r);
        run_to(&mut r, 291.0, 294.5);
        assert_eq!(r.state(), State::Set);
        assert!(
            early == secs(&r) && early.is_some_and(|s| (10..=11).contains(&s)),
            "in Set the timer stands at 10 s: {early:?}, then {:?}",
            secs(&r)
        );
    }

    #[test]
    fn a_penalty_at_the_half_s_end_lasts_until_the_half_time_switch() {
        // The whole 45 s cannot run: robot 3 is picked up 20 s before the half ends. The
        // timer stops in Finished and GameController3 unpenalises everyone half way
        // through the break.
        let mut script = GameScript::spl_full(5);
        script.penalties[0].after_play_s = 580.0;
        let mut r = Referee::new(script, 12, 34, 0.0);
        let events = run_to(&mut r, 0.0, 1300.0);
        let at = |e: RefereeEvent| events.iter().find(|(_, x)| *x == e).map(|(t, _)| *t);
        let (on, off) = (
            at(RefereeEvent::Penalised(3)).expect("penalised"),
            at(RefereeEvent::Unpenalised(3)).expect("back"),
        );
        let finished = at(RefereeEvent::State(State::Finished)).expect("half time");
        assert!((on - 635.0).abs() < 0.1, "{on}");
        assert!(
            (off - (finished + 300.0)).abs() < 0.1,
            "back at the switch, 300 s into the break: {off} (half over at {finished})"
        );
    }

    #[test]
    fn a_message_over_128_bytes_or_at_zero_makes_the_team_illegal() {
        let mut script = GameScript::spl_full(5);
        script.messages_per_game = 2;
        let mut r = Referee::new(script, 12, 34, 0.0);
        r.team_message(0.0, 129);
        assert_eq!(r.count().illegal, 1, "oversized, even when uncounted");
        assert_eq!(r.count().uncounted, 1);
        run_to(&mut r, 0.0, 11.0);
        assert_eq!(r.state(), State::Standby);
        r.team_message(11.0, 60);
        r.team_message(11.0, 60);
        assert_eq!((r.budget_left(), r.count().illegal), (0, 1));
        r.team_message(11.1, 60);
        assert_eq!(r.count().illegal, 2, "one message at 0 is one too many");
    }

    #[test]
    fn packets_go_every_half_second_and_decode_with_the_penalty() {
        let mut r = Referee::new(GameScript::spl_full(5), 12, 34, 0.0);
        let mut tracker = gamecontroller::GameTracker::new(12, 3);
        let from = "10.0.0.1:3838".parse().expect("an address");
        let mut sent: i32 = 0;
        let mut t = 0.0;
        while t < 300.0 {
            t += 0.01;
            r.advance(t);
            if let Some(bytes) = r.packet(t) {
                sent += 1;
                tracker
                    .receive(std::time::Duration::from_secs_f64(t), from, &bytes)
                    .expect("the GC's own packets decode");
            }
        }
        assert!((sent - 600).abs() <= 1, "{sent} packets in 300 s");
        // Robot 3 is penalised after 200 s of play (play began at 55 s): off till 300 s.
        assert_eq!(tracker.penalized(), Some(true), "robot 3 is off the field");
        assert!(tracker.own_secs_till_unpenalised().is_some_and(|s| s <= 45));
        assert_eq!(tracker.state(), Some(State::Playing));
    }

    /// The state and our score the packets show now (decoded, as a robot hears them).
    fn heard(r: &Referee) -> (State, u8) {
        let d = GameControlData::decode(&r.shown().encode()).expect("the GC's own packet");
        (d.state, d.team(12).map_or(0, |t| t.score))
    }

    #[test]
    fn the_packets_show_gamecontroller3_s_delayed_copy_and_the_current_budget() {
        // Script: the SPL game with GC3's delays (15 s after play, 15 s after a goal,
        // 45 s after Standby → Ready). Standby ends at 20 s, Ready at 50 s (the operator's
        // Set), Set at 55 s; a goal for us at 100 s.
        let mut r = Referee::new(GameScript::spl_full(5), 12, 34, 0.0);
        run_to(&mut r, 0.0, 30.0);
        assert_eq!(r.state(), State::Ready);
        assert_eq!(
            heard(&r).0,
            State::Standby,
            "Standby shown into the half's Ready"
        );
        run_to(&mut r, 30.0, 51.0);
        assert_eq!(
            (r.state(), heard(&r).0),
            (State::Set, State::Set),
            "the operator's Set ends the Standby delay (30 s < 45 s)"
        );
        run_to(&mut r, 51.0, 60.0);
        assert!(r.playing());
        assert_eq!(heard(&r).0, State::Set, "Set shown 5 s after the whistle");
        r.team_message(60.0, 60);
        r.packet(60.0);
        let d = GameControlData::decode(&r.shown().encode()).expect("decodes");
        assert_eq!(
            d.team(12).map(|t| t.message_budget),
            Some(r.budget_left()),
            "the budget in the packets is current"
        );
        run_to(&mut r, 60.0, 70.1);
        assert_eq!(
            heard(&r).0,
            State::Playing,
            "Playing shown 15 s after the whistle"
        );
        run_to(&mut r, 70.1, 100.0);
        r.goal(100.0, true);
        assert_eq!(r.state(), State::Ready);
        run_to(&mut r, 100.0, 114.9);
        assert_eq!(
            heard(&r),
            (State::Playing, 0),
            "Playing with the old score for 15 s after the goal"
        );
        let clock = r.shown().secs_remaining;
        assert!(
            clock < r.data().secs_remaining,
            "the copy's clock ran on in its Playing: {clock} vs {}",
            r.data().secs_remaining
        );
        run_to(&mut r, 114.9, 115.1);
        assert_eq!(
            heard(&r),
            (State::Ready, 1),
            "then Ready with the new score"
        );
        // Without delays (GC3's `test.no_delay`) the packets show the truth.
        let script = GameScript {
            delays: GcDelays::none(),
            ..GameScript::spl_full(5)
        };
        let mut r = Referee::new(script, 12, 34, 0.0);
        run_to(&mut r, 0.0, 56.0);
        assert_eq!(heard(&r).0, State::Playing, "no delay: Playing at once");
    }

    #[test]
    fn a_goal_in_the_set_delay_forks_a_new_copy_showing_playing_with_the_old_score() {
        let mut r = Referee::new(GameScript::spl_full(5), 12, 34, 0.0);
        run_to(&mut r, 0.0, 60.0);
        assert_eq!(heard(&r).0, State::Set);
        r.goal(60.0, false);
        run_to(&mut r, 60.0, 74.0);
        assert_eq!(
            heard(&r),
            (State::Playing, 0),
            "the Goal forked the pre-goal game: Playing, 0–0"
        );
        run_to(&mut r, 74.0, 75.1);
        let d = GameControlData::decode(&r.shown().encode()).expect("decodes");
        assert_eq!(
            (d.state, d.team(34).map(|t| t.score)),
            (State::Ready, Some(1)),
            "Ready with their goal 15 s after it"
        );
    }
}
