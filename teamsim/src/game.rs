//! `huddle sim --game full`: the match played under a simulated GameController
//! ([`Referee`]).
//!
//! Each step the referee runs to the step's instant; every 500 ms its packet's encoded
//! bytes go to each robot (lost as often as the network loses a group-addressed frame),
//! and each robot decodes them through its own [`GameTracker`]. From what the robot heard
//! (never the referee's truth) it feeds its replica's budget with
//! [`driver::budget_figures`] (what `huddle daemon` does with each packet), tells its team
//! layer who is penalised ([`driver::penalized_players`]) and takes its order: play in
//! Playing, walk to its kick-off spot in Ready, stand otherwise; a robot whose program
//! heard the referee's whistle (`GameScript::whistle`) goes by it ahead of the packets,
//! which show GameController3's delayed state. The referee counts every
//! frame the team's replicas send, with its size, in the state it was sent in.
//!
//! A goal reaches a robot the same way: when a packet it receives carries a higher score
//! than the one before, its team layer forgets the ball and puts it on the centre spot
//! ([`team::TeamLayer::set_scores`], what the daemon's tick does with the listener's
//! `gc.score` keys); a robot that received no such packet before Set puts the ball down
//! at Set ([`team::TeamLayer::set_kick_off_next`]). Each robot's delivery reference puts
//! the ball down when its robot does; the references that see the whole team when the
//! first robot does. The report says how long after each goal the robots learnt it
//! ([`GoalNews`]). Before the tenth session every robot forgot the ball at the goal's true
//! instant, which no robot can know.
//!
//! The field follows the referee's truth: outside Playing the ball lies on the centre spot
//! and the opponents on their kick-off spots; a penalised robot's body is carried to the
//! sideline, off the field (no body on it: nothing there shoves it, see
//! [`crate::field::World::set_off_field`]), and comes back when its penalty timer (45 s
//! of Ready and Playing) has run,
//! on the touchline in its own half on the side away from the ball (it is told where, as
//! a team is by the rules). Arbitration and world-model figures are sampled in Playing
//! only, and the world-model figures (pose, team ball, blind robots) only of robots on
//! the field: a penalised robot is not playing and its camera sees no field, and the
//! 600 s run they are compared with has none. The report keeps the figures with the
//! penalised robots counted too (`game_with_penalised`), the definition before the
//! seventh session, so the change hides nothing.

use std::net::SocketAddr;
use std::time::Duration;

use gamecontroller::{GameTracker, GcBudget, State};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::referee::{program_order, GameScript, GameTally, GcBooks, Referee, RefereeEvent};
use super::robot;
use super::Simulation;
use crate::field::geometry::{Pose, Vec2};
use team::Whistle;

/// Our team's number in the simulated game (any; the opponents are `OUR_TEAM + 1`).
pub const OUR_TEAM: u8 = 12;

/// The report's kick-off window: the first this many seconds of each stretch of Playing
/// (a kick-off from the formation, the ball on the centre spot), seconds.
pub const KICK_OFF_WINDOW_S: f64 = 10.0;

/// The report's bins of Playing by time since its stretch's kick-off, seconds (lower
/// edges; the last runs to the stretch's end): whether the game's open play differs from
/// the 600 s run by how long ago the team stood in its kick-off formation.
pub const SINCE_KICK_OFF_BINS_S: [f64; 5] = [0.0, KICK_OFF_WINDOW_S, 30.0, 60.0, 120.0];

/// Where the arbitration's ball-visible time went, by the part of the game it fell in
/// (kick-off windows, time with one of our robots penalised), in Playing only.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct PlayBreakdown {
    /// Ball-visible seconds.
    pub visible_s: f64,
    /// Of them, with two or more goers.
    pub conflict_s: f64,
    /// Of them, with no goer.
    pub no_goer_s: f64,
    /// Team-ball samples of blind robots in this part (see [`crate::metrics`]: a robot
    /// that has not seen the ball itself within its ball memory).
    pub blind_samples: u64,
    /// Their team-ball RMSE, m.
    pub blind_rmse_m: f64,
    /// Frames the team sent in this part (the pace its open play ran at: the 600 s run
    /// sends about one a second).
    pub messages: u64,
    #[serde(skip)]
    blind_sq_sum_m2: f64,
}

impl PlayBreakdown {
    fn add(&mut self, dt_s: f64, visible: bool, goers: usize) {
        if !visible {
            return;
        }
        self.visible_s += dt_s;
        match goers {
            0 => self.no_goer_s += dt_s,
            1 => {}
            _ => self.conflict_s += dt_s,
        }
    }

    fn rounded(self) -> Self {
        let r = |x: f64| (x * 100.0).round() / 100.0;
        let rmse = if self.blind_samples > 0 {
            (self.blind_sq_sum_m2 / self.blind_samples as f64).sqrt()
        } else {
            0.0
        };
        Self {
            visible_s: r(self.visible_s),
            conflict_s: r(self.conflict_s),
            no_goer_s: r(self.no_goer_s),
            blind_samples: self.blind_samples,
            blind_rmse_m: (rmse * 1e4).round() / 1e4,
            messages: self.messages,
            blind_sq_sum_m2: self.blind_sq_sum_m2,
        }
    }
}

/// What the referee's books say at the end (flattened into the report; absent without
/// `--game`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GameReport {
    /// The world-model figures with the penalised robots' samples counted too (the
    /// report's main figures leave them out, see the module docs).
    pub game_with_penalised: WithPenalised,
    /// The referee's books (score, the GC's count, illegal, packets, whistles heard).
    #[serde(flatten)]
    pub books: GcBooks,
    /// Arbitration in the first `KICK_OFF_WINDOW_S` (10 s) of each stretch of Playing.
    pub game_kick_off: PlayBreakdown,
    /// Arbitration while one of our robots is penalised (outside kick-off windows).
    pub game_penalised: PlayBreakdown,
    /// Arbitration in the rest of Playing.
    pub game_open_play: PlayBreakdown,
    /// Counted frames sent outside Playing (Standby, Ready, Set): what the restarts took
    /// from the budget that paces open play.
    pub game_messages_outside_play: u64,
    /// All of Playing (penalties too) by time since the stretch's kick-off, one part per
    /// bin of [`SINCE_KICK_OFF_BINS_S`].
    pub game_since_kick_off: Vec<PlayBreakdown>,
    /// How long after each goal each robot learnt of it (from the GC's packets, or,
    /// since the eleventh session, its program's whistle).
    pub game_goal_news: GoalNews,
}

/// Pose, team-ball and blind-robot RMSE over every robot's samples in Playing, penalised
/// robots off the field included, and how many samples those robots added.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct WithPenalised {
    /// Pose position RMSE, m.
    pub pose_rmse_m: f64,
    /// Team-ball RMSE, m.
    pub team_ball_rmse_m: f64,
    /// Team-ball RMSE of blind robots, m.
    pub blind_team_ball_rmse_m: f64,
    /// Pose samples of penalised robots (left out of `pose_rmse_m` in the main figures).
    pub penalised_pose_samples: u64,
    /// Team-ball samples of penalised robots (all of them blind: off the field).
    pub penalised_ball_samples: u64,
    /// Of them, blind.
    pub penalised_blind_samples: u64,
    #[serde(skip)]
    sums: [(u64, f64); 3],
}

impl WithPenalised {
    fn add(&mut self, k: usize, sq_m2: f64) {
        self.sums[k].0 += 1;
        self.sums[k].1 += sq_m2;
    }

    fn rounded(&self) -> WithPenalised {
        let rmse = |(n, sq): (u64, f64)| {
            if n > 0 {
                (10_000.0 * (sq / n as f64).sqrt()).round() / 10_000.0
            } else {
                0.0
            }
        };
        WithPenalised {
            pose_rmse_m: rmse(self.sums[0]),
            team_ball_rmse_m: rmse(self.sums[1]),
            blind_team_ball_rmse_m: rmse(self.sums[2]),
            ..*self
        }
    }
}

impl std::fmt::Display for GameReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}", self.books)?;
        let share = |b: &PlayBreakdown| {
            let pct = |x: f64| {
                if b.visible_s > 0.0 {
                    100.0 * x / b.visible_s
                } else {
                    0.0
                }
            };
            format!(
                "{:.0} s, conflict {:.1}%, no goer {:.1}%, blind {:.3} m",
                b.visible_s,
                pct(b.conflict_s),
                pct(b.no_goer_s),
                b.blind_rmse_m
            )
        };
        write!(
            f,
            "\nball visible in play   {} kick-offs (first {KICK_OFF_WINDOW_S:.0} s): {}; penalised: {}; open play: {}",
            self.books.game_kick_offs,
            share(&self.game_kick_off),
            share(&self.game_penalised),
            share(&self.game_open_play)
        )?;
        let w = &self.game_with_penalised;
        write!(
            f,
            "\nwith penalised robots  pose RMSE {:.3} m, team ball {:.3} m, blind {:.3} m ({} pose, {} ball samples of penalised robots; the figures above leave them out)",
            w.pose_rmse_m,
            w.team_ball_rmse_m,
            w.blind_team_ball_rmse_m,
            w.penalised_pose_samples,
            w.penalised_ball_samples
        )?;
        let n = &self.game_goal_news;
        write!(
            f,
            "\ngoals heard           {} goals; robots learnt them {:.2} s after on average (the first {:.2} s, the last at most {:.2} s), {} from a packet's score, {} only at Set",
            n.goals, n.mean_after_s, n.first_mean_after_s, n.max_after_s, n.from_score, n.at_set
        )
    }
}

/// The referee and what each robot heard of it.
#[derive(Debug, Clone)]
pub(crate) struct Game {
    pub(crate) referee: Referee,
    script: GameScript,
    trackers: Vec<GameTracker>,
    budget: Option<GcBudget>,
    rng: ChaCha8Rng,
    loss: f64,
    gc: SocketAddr,
    /// Packets, losses, penalties, kick-offs and whistles, for the books.
    tally: GameTally,
    opponent_spots: Vec<Pose>,
    /// When the current stretch of Playing began, if play runs.
    playing_since_s: Option<f64>,
    kick_off: PlayBreakdown,
    penalised: PlayBreakdown,
    open_play: PlayBreakdown,
    with_penalised: WithPenalised,
    messages_outside_play: u64,
    since_kick_off: [PlayBreakdown; SINCE_KICK_OFF_BINS_S.len()],
    /// When each goal the referee counted was scored, simulated seconds.
    goal_times_s: Vec<f64>,
    /// How many of those goals each robot's team layer has learnt of.
    goals_known: Vec<usize>,
    /// How many of them the references that see the whole team have been told of (at
    /// the first robot's hearing).
    goals_told_references: usize,
    /// When and how each robot learnt each goal.
    goals_heard: Vec<GoalHeard>,
    /// Robots that receive no packet now (see [`Simulation::set_gc_deaf`]).
    deaf: Vec<bool>,
    /// The whistle draws (apart from the packets' losses, which stay as they were).
    whistle_rng: ChaCha8Rng,
    /// When each robot's program will hear the whistles it is to hear, simulated s.
    whistles: Vec<Vec<f64>>,
    /// Each robot's program heard the whistle in Standby: it walks to Ready.
    standby_whistle: Vec<bool>,
}

/// How one robot learnt of one goal (`huddle sim --game`): from the first GameController
/// packet it received with the new score ([`team::TeamLayer::set_scores`]), or, if it
/// received none before Set, at Set (the kick-off placement,
/// [`team::TeamLayer::set_kick_off_next`]).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GoalHeard {
    /// The goal, counted from 0 in the game.
    pub goal: usize,
    /// Our robot (player number).
    pub robot: u8,
    /// When it learnt it, simulated seconds.
    pub at_s: f64,
    /// How long after the goal, seconds.
    pub after_s: f64,
    /// At Set (no packet with the new score reached it before): its team layer puts the
    /// ball on the centre spot at its next tick.
    pub at_set: bool,
}

/// How long after a goal the robots learnt of it, over every (robot, goal) (in the
/// report of a `--game` run).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct GoalNews {
    /// Goals the referee counted.
    pub goals: u32,
    /// (robot, goal) pairs learnt from a packet's score.
    pub from_score: u32,
    /// Pairs learnt only at Set.
    pub at_set: u32,
    /// Mean delay after the goal, seconds, over every pair learnt.
    pub mean_after_s: f64,
    /// The longest delay, seconds.
    pub max_after_s: f64,
    /// Mean delay of the first robot to learn each goal, seconds (when the references
    /// that see the whole team put the ball down).
    pub first_mean_after_s: f64,
}

impl Game {
    /// The game of `script` for a team of `robots`; `budget`: the replicas' budgets
    /// follow the GC; `loss`: the chance a robot misses a packet.
    pub(crate) fn new(
        script: GameScript,
        robots: usize,
        budget: Option<GcBudget>,
        loss: f64,
        opponent_spots: Vec<Pose>,
        seed: u64,
    ) -> Game {
        Game {
            referee: Referee::new(script.clone(), OUR_TEAM, OUR_TEAM + 1, 0.0),
            script,
            trackers: (0..robots)
                .map(|i| GameTracker::new(OUR_TEAM, comms_netsim::robot_id(i)))
                .collect(),
            budget,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x0063_0063_0063_0063),
            loss: loss.clamp(0.0, 1.0),
            gc: SocketAddr::from(([10, 0, 0, 1], gamecontroller::GAMECONTROLLER_DATA_PORT)),
            tally: GameTally::default(),
            opponent_spots,
            playing_since_s: None,
            kick_off: PlayBreakdown::default(),
            penalised: PlayBreakdown::default(),
            open_play: PlayBreakdown::default(),
            with_penalised: WithPenalised::default(),
            messages_outside_play: 0,
            since_kick_off: Default::default(),
            goal_times_s: Vec::new(),
            goals_known: vec![0; robots],
            whistle_rng: ChaCha8Rng::seed_from_u64(seed ^ 0x7768_6973_746c_6521),
            whistles: vec![Vec::new(); robots],
            standby_whistle: vec![false; robots],
            goals_told_references: 0,
            goals_heard: Vec::new(),
            deaf: vec![false; robots],
        }
    }

    /// The referee whistled at `t_s`: each robot's program is to hear it (or not) as the
    /// script's [`crate::referee::WhistleHearing`] draws.
    fn whistle(&mut self, t_s: f64) {
        self.tally.whistle(
            self.script.whistle,
            &mut self.whistle_rng,
            t_s,
            &mut self.whistles,
        );
    }

    /// Robot `i` learnt of every goal up to the `known`-th at `t_s` (`at_set`: at Set, no
    /// packet with the new score having reached it). Returns whether it was the first
    /// robot to learn of one of them (the references that see the whole team put the
    /// ball down then).
    fn learnt_goals(&mut self, i: usize, known: usize, t_s: f64, at_set: bool) -> bool {
        let known = known.min(self.goal_times_s.len());
        let Some(before) = self.goals_known.get(i).copied() else {
            return false;
        };
        if known <= before {
            return false;
        }
        for goal in before..known {
            self.goals_heard.push(GoalHeard {
                goal,
                robot: comms_netsim::robot_id(i),
                at_s: t_s,
                after_s: t_s - self.goal_times_s[goal],
                at_set,
            });
        }
        self.goals_known[i] = known;
        let first = known > self.goals_told_references;
        self.goals_told_references = self.goals_told_references.max(known);
        first
    }

    fn goal_news(&self) -> GoalNews {
        let r3 = |x: f64| (x * 1000.0).round() / 1000.0;
        let n = self.goals_heard.len();
        let mean = |it: &mut dyn Iterator<Item = f64>, n: usize| {
            if n > 0 {
                r3(it.sum::<f64>() / n as f64)
            } else {
                0.0
            }
        };
        let firsts: Vec<f64> = (0..self.goal_times_s.len())
            .filter_map(|g| {
                self.goals_heard
                    .iter()
                    .filter(|h| h.goal == g)
                    .map(|h| h.after_s)
                    .reduce(f64::min)
            })
            .collect();
        let at_set = self.goals_heard.iter().filter(|h| h.at_set).count();
        GoalNews {
            goals: u32::try_from(self.goal_times_s.len()).unwrap_or(u32::MAX),
            from_score: u32::try_from(n - at_set).unwrap_or(u32::MAX),
            at_set: u32::try_from(at_set).unwrap_or(u32::MAX),
            mean_after_s: mean(&mut self.goals_heard.iter().map(|h| h.after_s), n),
            max_after_s: r3(self
                .goals_heard
                .iter()
                .map(|h| h.after_s)
                .fold(0.0, f64::max)),
            first_mean_after_s: mean(&mut firsts.iter().copied(), firsts.len()),
        }
    }

    /// A pose sample (its squared position error) of a robot on the field or, `off`,
    /// penalised off it: counted in [`GameReport::game_with_penalised`].
    pub(crate) fn sample_pose(&mut self, sq_m2: f64, off: bool) {
        self.with_penalised.add(0, sq_m2);
        self.with_penalised.penalised_pose_samples += u64::from(off);
    }

    /// A team-ball sample (squared error) of a robot, `blind` or not, on the field or
    /// (`off`) not: counted in [`GameReport::game_with_penalised`].
    pub(crate) fn sample_team_ball(&mut self, sq_m2: f64, blind: bool, off: bool) {
        self.with_penalised.add(1, sq_m2);
        if blind {
            self.with_penalised.add(2, sq_m2);
        }
        self.with_penalised.penalised_ball_samples += u64::from(off);
        self.with_penalised.penalised_blind_samples += u64::from(off && blind);
    }

    /// The arbitration's sample of `dt_s` ending at `t_s` (see [`Metrics::sample`]), put
    /// in its part of the game.
    ///
    /// [`Metrics::sample`]: crate::metrics::Metrics::sample
    pub(crate) fn sample_play(&mut self, t_s: f64, dt_s: f64, visible: bool, goers: usize) {
        if !self.referee.playing() {
            self.playing_since_s = None;
            return;
        }
        let since = *self.playing_since_s.get_or_insert_with(|| {
            self.tally.kick_offs += 1;
            t_s - dt_s
        });
        let penalised =
            (0..self.trackers.len()).any(|i| self.referee.penalised(comms_netsim::robot_id(i)));
        let part = if t_s - since <= KICK_OFF_WINDOW_S {
            &mut self.kick_off
        } else if penalised {
            &mut self.penalised
        } else {
            &mut self.open_play
        };
        part.add(dt_s, visible, goers);
        self.since_kick_off[since_bin(t_s - since)].add(dt_s, visible, goers);
    }

    /// A blind robot's team-ball sample at `t_s` (its squared error), put in its part of
    /// the game as [`Game::sample_play`] puts the arbitration's.
    pub(crate) fn sample_blind(&mut self, t_s: f64, sq_m2: f64) {
        if let Some(part) = self.part_at(t_s) {
            part.blind_samples += 1;
            part.blind_sq_sum_m2 += sq_m2;
        }
        if let Some(bin) = self.bin_at(t_s) {
            bin.blind_samples += 1;
            bin.blind_sq_sum_m2 += sq_m2;
        }
    }

    /// The bin of [`SINCE_KICK_OFF_BINS_S`] `t_s` falls in (`None` outside Playing).
    fn bin_at(&mut self, t_s: f64) -> Option<&mut PlayBreakdown> {
        if !self.referee.playing() {
            return None;
        }
        let since = self.playing_since_s.map_or(0.0, |s| t_s - s);
        Some(&mut self.since_kick_off[since_bin(since)])
    }

    /// The part of Playing `t_s` falls in, as [`Game::sample_play`] puts the
    /// arbitration's samples (`None` outside Playing).
    fn part_at(&mut self, t_s: f64) -> Option<&mut PlayBreakdown> {
        if !self.referee.playing() {
            return None;
        }
        let penalised =
            (0..self.trackers.len()).any(|i| self.referee.penalised(comms_netsim::robot_id(i)));
        Some(match self.playing_since_s {
            Some(since) if t_s - since > KICK_OFF_WINDOW_S => {
                if penalised {
                    &mut self.penalised
                } else {
                    &mut self.open_play
                }
            }
            // The stretch's first sample comes before its arbitration sample starts it.
            _ => &mut self.kick_off,
        })
    }

    /// A frame the team sent at `t_s`, for the pace of each part of the game.
    fn sample_message(&mut self, t_s: f64) {
        if let Some(bin) = self.bin_at(t_s) {
            bin.messages += 1;
        }
        if let Some(part) = self.part_at(t_s) {
            part.messages += 1;
        } else if self.referee.data().messages_counted() {
            self.messages_outside_play += 1;
        }
    }

    /// The referee's books as the report shows them.
    pub(crate) fn report(&self) -> GameReport {
        GameReport {
            game_with_penalised: self.with_penalised.rounded(),
            books: self.referee.books_with(&self.tally),
            game_kick_off: self.kick_off.rounded(),
            game_penalised: self.penalised.rounded(),
            game_open_play: self.open_play.rounded(),
            game_messages_outside_play: self.messages_outside_play,
            game_since_kick_off: self.since_kick_off.iter().map(|b| b.rounded()).collect(),
            game_goal_news: self.goal_news(),
        }
    }
}

/// Lower edges of the report's bins of blind robots' team-ball error by the age of the
/// newest ball a teammate told them (seconds; the last bin also holds "never told").
pub const TOLD_AGE_BINS_S: [f64; 5] = [0.0, 1.0, 2.0, 4.0, 8.0];

/// One bin of `BlindByToldAge` (the ball's blindness by the age it was told at).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct ToldAgeBin {
    /// Lower edge, seconds.
    pub from_s: f64,
    /// Blind robots' team-ball samples.
    pub samples: u64,
    /// Their team-ball RMSE, m.
    pub rmse_m: f64,
    /// Their share of the squared error of every blind sample, %.
    pub share_of_sq_pct: f64,
}

/// Blind robots' team-ball error by how old the newest ball a teammate told them was
/// (its message's ball time against the robot's clock), in the samples the main figures
/// count: is a blind robot's error stale news (nobody told it lately under the budget's
/// pace) or fresh news that was wrong?
#[derive(Debug, Clone, Default)]
pub(crate) struct BlindByToldAge {
    sums: [(u64, f64); TOLD_AGE_BINS_S.len()],
}

impl BlindByToldAge {
    /// A blind sample of squared error `sq_m2` whose newest told ball is `age_s` old
    /// (`None`: no teammate told one).
    pub(crate) fn add(&mut self, age_s: Option<f64>, sq_m2: f64) {
        let bin = age_s.map_or(TOLD_AGE_BINS_S.len() - 1, |a| {
            TOLD_AGE_BINS_S.iter().rposition(|&e| a >= e).unwrap_or(0)
        });
        self.sums[bin].0 += 1;
        self.sums[bin].1 += sq_m2;
    }

    pub(crate) fn report(&self) -> Vec<ToldAgeBin> {
        let total: f64 = self.sums.iter().map(|s| s.1).sum();
        TOLD_AGE_BINS_S
            .iter()
            .zip(&self.sums)
            .map(|(&from_s, &(n, sq))| ToldAgeBin {
                from_s,
                samples: n,
                rmse_m: if n > 0 {
                    ((sq / n as f64).sqrt() * 1e4).round() / 1e4
                } else {
                    0.0
                },
                share_of_sq_pct: if total > 0.0 {
                    (1000.0 * sq / total).round() / 10.0
                } else {
                    0.0
                },
            })
            .collect()
    }
}

/// The bin of [`SINCE_KICK_OFF_BINS_S`] for `since_s` of Playing.
fn since_bin(since_s: f64) -> usize {
    SINCE_KICK_OFF_BINS_S
        .iter()
        .rposition(|&edge| since_s > edge)
        .unwrap_or(0)
}

impl Simulation {
    /// The simulated GameController's books (its truth, not what a robot heard), when the
    /// match is played under one (`--game`).
    pub fn referee(&self) -> Option<&Referee> {
        self.game.as_ref().map(|g| &g.referee)
    }

    /// Whether arbitration and world-model figures are sampled now: always without a
    /// referee, in Playing with one.
    pub(super) fn in_play(&self) -> bool {
        self.game.as_ref().is_none_or(|g| g.referee.playing())
    }

    /// The referee counts the frames the team sent since the last call, each in the
    /// state it is in now.
    pub(super) fn referee_count(&mut self, t_s: f64) {
        let Some(game) = &mut self.game else { return };
        for (_, len) in self.harness.take_sent() {
            game.sample_message(t_s);
            game.referee.team_message(t_s, len);
        }
    }

    /// The referee's part of a step at `t_s`, before the robots tick: the game runs on,
    /// its packet reaches the robots, the field follows its decisions.
    pub(super) fn referee_step(&mut self, t_s: f64) {
        let Some(game) = &mut self.game else { return };
        let events = game.referee.advance(t_s);
        for e in events {
            self.referee_event(e, t_s);
        }
        let Some(game) = &mut self.game else { return };
        let mut goal_heard = Vec::new();
        let mut first_heard = false;
        if let Some(bytes) = game.referee.packet(t_s) {
            game.tally.packets += 1;
            for i in 0..self.robots.len() {
                // (The draw is made for a deaf robot too: deafening one robot leaves the
                // others' receptions as they were.)
                let lost = game.rng.random::<f64>() < game.loss;
                // A WLAN outage (`--outage`) takes the GameController's packets too.
                let outage = self.cfg.outage.is_some_and(|o| o.contains(t_s));
                if lost || outage || game.deaf.get(i).copied().unwrap_or(false) {
                    game.tally.packets_lost += 1;
                    continue;
                }
                let local = self.harness.local_now(i);
                let now = Duration::from_micros(local.as_micros());
                let tracker = &mut game.trackers[i];
                if tracker.receive(now, game.gc, &bytes) != Ok(gamecontroller::Received::Accepted) {
                    continue;
                }
                // The radio's heartbeat (`team::heartbeat`), as the daemon's layer takes
                // it from its listener.
                self.robots[i].heard_gamecontroller(robot::seconds(local));
                // What the daemon does with each packet (driver::gamecontroller).
                if let (Some(budget), Some(replica)) = (&game.budget, self.harness.replica_mut(i)) {
                    let whistle = self.robots[i].play_whistle_at();
                    let now_s = robot::seconds(local);
                    if let Some((remaining, cap)) =
                        driver::budget_figures(budget, tracker, whistle, now_s)
                    {
                        replica.set_game_clock(local, remaining);
                        replica.set_external_budget(Some(cap));
                    }
                }
                self.robots[i].set_penalties(&driver::penalized_players(tracker));
                // A goal is news to a robot when its packet's score says so: the daemon's
                // `TeamLayer::set_scores` on the listener's `gc.score` keys (which it reads
                // at its next tick; here at the packet, as the penalties above).
                let scores = (tracker.score(), tracker.opponent().map(|t| t.score));
                if let (Some(own), Some(other)) = scores {
                    if self.robots[i].set_scores(own, other, robot::seconds(local)) {
                        let known = usize::from(own) + usize::from(other);
                        first_heard |= game.learnt_goals(i, known, t_s, false);
                        goal_heard.push(i);
                    }
                }
            }
        }
        // Each robot that heard a goal: its delivery reference puts the ball on the centre
        // spot on its clock, as its team layer just did; the references that see the
        // whole team put it there when the first robot hears of the goal (the team knows
        // no sooner).
        for &i in &goal_heard {
            let now_s = robot::seconds(self.harness.local_now(i));
            self.delivery[i].place(self.robots[i].kick_off_ball(now_s));
        }
        if first_heard {
            self.place_whole_team_references(t_s, false);
        }
        let Some(game) = &mut self.game else { return };
        // The robots that hear Set now: the references place the ball as they do.
        let mut set_heard = Vec::new();
        let mut whistle_first = false;
        // Each robot's order from what it heard; a body off the field stands.
        for i in 0..self.robots.len() {
            let heard = game.trackers[i].state();
            let penalised = game.trackers[i].penalized() == Some(true)
                || game.referee.penalised(comms_netsim::robot_id(i));
            self.robots[i].set_gc_ready(heard == Some(State::Ready));
            self.robots[i].set_in_play(heard.is_none_or(|s| s == State::Playing));
            if self.robots[i].set_kick_off_next(heard == Some(State::Set)) {
                // A goal it had not heard of (every packet with the new score lost to
                // it) goes with the ball the layer puts down at Set.
                let known = game.goal_times_s.len();
                game.learnt_goals(i, known, t_s, true);
                // What the daemon does at Set (driver::team).
                let local = self.harness.local_now(i);
                if let Some(replica) = self.harness.replica_mut(i) {
                    replica.restart_priority_room(local);
                }
                set_heard.push(i);
            }
            // The program hears the whistle (its own microphone, not the packets): in
            // Standby it walks to Ready; otherwise its team layer takes it as the daemon
            // does with `local.var.robot.whistle` (`TeamLayer::heard_whistle`).
            let due = game.whistles[i].iter().filter(|&&at| at <= t_s).count();
            game.whistles[i].retain(|&at| at > t_s);
            if heard != Some(State::Standby) {
                game.standby_whistle[i] = false;
            }
            if due > 0 && !penalised {
                if heard == Some(State::Standby) {
                    game.standby_whistle[i] = true;
                } else {
                    let local = robot::seconds(self.harness.local_now(i));
                    if let Some(Whistle::Goal(_)) = self.robots[i].heard_whistle(local) {
                        // The goal's news, from the whistle: the layer forgot the ball.
                        let known = game.goal_times_s.len();
                        if game.learnt_goals(i, known, t_s, false) {
                            whistle_first = true;
                        }
                        self.delivery[i].place(self.robots[i].kick_off_ball(local));
                    }
                }
            }
            // Its body follows its program: the whistle runs ahead of the packets. After
            // a goal's whistle a program walks to its kick-off spot (the goal's Ready,
            // which the GC shows 15 s late), as a robot program that hears it does.
            self.robots[i].order = program_order(
                heard,
                penalised,
                self.robots[i].whistle(),
                game.standby_whistle[i],
            );
        }
        // The delivery references are placed at each robot's next tick, where its team
        // layer places the ball (see `feed_references`).
        if !set_heard.is_empty() {
            self.place_whole_team_references(self.time_s(), false);
        }
        if whistle_first {
            self.place_whole_team_references(t_s, false);
        }
    }

    /// After the world's step: outside Playing the ball and the opponents wait on their
    /// kick-off spots; penalised bodies stay on the sideline.
    pub(super) fn referee_hold(&mut self) {
        let Some(game) = &self.game else { return };
        if !game.referee.playing() {
            self.world.ball.at = Vec2::default();
            self.world.ball.velocity = Vec2::default();
            for (body, spot) in self.world.opponents.iter_mut().zip(&game.opponent_spots) {
                body.pose = *spot;
                body.velocity = Vec2::default();
            }
        }
        for i in 0..self.robots.len() {
            if game.referee.penalised(comms_netsim::robot_id(i)) {
                self.world.robots[i].pose = sideline_spot(&self.cfg, i);
                self.world.robots[i].velocity = Vec2::default();
            }
        }
    }

    /// A goal in the world, for the referee (`for_us`: ours).
    pub(super) fn referee_goal(&mut self, t_s: f64, for_us: bool) {
        if let Some(game) = &mut self.game {
            let events = game.referee.goal(t_s, for_us);
            if !events.is_empty() {
                game.goal_times_s.push(t_s);
            }
            for e in events {
                self.referee_event(e, t_s);
            }
        }
    }

    /// Robot `i` (index) receives no GameController packet while `deaf` (its wireless
    /// down, or every packet lost to it): for tests of what a robot does on what it
    /// did not hear. No effect without `--game`.
    pub fn set_gc_deaf(&mut self, i: usize, deaf: bool) {
        if let Some(d) = self.game.as_mut().and_then(|g| g.deaf.get_mut(i)) {
            *d = deaf;
        }
    }

    /// When and how each robot learnt of each goal (empty without `--game`).
    pub fn goals_heard(&self) -> &[GoalHeard] {
        self.game.as_ref().map_or(&[], |g| &g.goals_heard)
    }

    /// What the field and the robots' programs make of the referee's event at `t_s`.
    fn referee_event(&mut self, e: RefereeEvent, t_s: f64) {
        match e {
            RefereeEvent::State(_) => {}
            RefereeEvent::Whistle => {
                if let Some(g) = &mut self.game {
                    g.whistle(t_s);
                }
            }
            RefereeEvent::Penalised(id) => {
                let Some(i) = usize::from(id)
                    .checked_sub(1)
                    .filter(|&i| i < self.robots.len())
                else {
                    return;
                };
                if let Some(g) = &mut self.game {
                    g.tally.penalties += 1;
                }
                // Picked up and put on the sideline: it looks around and knows it.
                let spot = sideline_spot(&self.cfg, i);
                self.world.robots[i].pose = spot;
                self.world.robots[i].velocity = Vec2::default();
                self.world.set_off_field(i, true);
                let wm = self.cfg.brain.team.world_model;
                self.robots[i].place(spot, &wm);
            }
            RefereeEvent::Unpenalised(id) => {
                let Some(i) = usize::from(id)
                    .checked_sub(1)
                    .filter(|&i| i < self.robots.len())
                else {
                    return;
                };
                // Back on the touchline in its own half, on the side away from the ball,
                // facing into the field: the spot the rules name, so the robot knows it.
                let f = &self.cfg.field;
                let side = if self.world.ball.at.y > 0.0 {
                    -1.0
                } else {
                    1.0
                };
                let spot = Pose {
                    at: Vec2::new(-f.length_m / 4.0, side * f.width_m / 2.0),
                    theta_rad: -side * std::f64::consts::FRAC_PI_2,
                };
                self.world.robots[i].pose = spot;
                self.world.robots[i].velocity = Vec2::default();
                self.world.set_off_field(i, false);
                let wm = self.cfg.brain.team.world_model;
                self.robots[i].place(spot, &wm);
            }
        }
    }
}

/// Where penalised robot `i` waits: beyond the touchline of its own half, robots apart.
fn sideline_spot(cfg: &super::SimConfig, i: usize) -> Pose {
    let f = &cfg.field;
    Pose {
        at: Vec2::new(-0.5 - 0.6 * i as f64, -(f.width_m / 2.0 + 0.6 * f.border_m)),
        theta_rad: std::f64::consts::FRAC_PI_2,
    }
}
