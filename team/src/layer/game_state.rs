//! What the GameController's word does to a robot's team layer: play or not, Set and the
//! kick-off hold, scores (a goal forgets the ball), penalties, and the ball put back on
//! the kick-off spot. Part of [`TeamLayer`]; a room of its own so that the layer's file
//! keeps to its tick.

use fusion::{BallEstimate, TeamBall};

use super::{TeamLayer, PENALIZED_COST};
use crate::frames;

/// The kick-off hold lasts this long after the robot hears play, seconds. Tuned on
/// seeds 4–11 (`huddle sim --budget spl --game full`, drawn and ideal worlds): see
/// docs/results/gamecontroller-game-history.md, "Third session".
pub const KICK_OFF_HOLD_S: f64 = 3.0;

/// In the kick-off hold, a robot whose cost is below this takes the kick-off (eq. (19),
/// about metres to the ball: the kicker stands at the centre spot, the rest of the team
/// outside the centre circle, 0.75 m in the SPL, and further).
pub const KICK_OFF_TAKER_COST: f64 = 1.0;

/// In Set the kick-off taker tells its claim this often (see
/// [`TeamLayer::set_kick_off_next`]). Tuned on seeds 4–11 (`huddle sim --budget spl
/// --game full`, both worlds; docs/results/gamecontroller-game.md, "Sixth session"): 1,
/// 2 and 3 were within the games' noise of each other, and one frame a kick-off is the
/// cheapest.
pub const KICK_OFF_SET_CLAIMS: u32 = 1;

/// … at least this far apart, seconds.
pub const KICK_OFF_SET_CLAIM_GAP_S: f64 = 1.5;

/// σ of where the referee puts the ball for a kick-off, per axis, m: on the centre
/// mark, give or take a ball's width.
pub const KICK_OFF_SPOT_SIGMA_M: f64 = 0.1;

/// σ of the velocity of a ball put down for a kick-off, per axis, m/s: it lies still.
pub const KICK_OFF_SPEED_SIGMA_MPS: f64 = 0.05;

/// A whistle the layer acts on before the GameController says so stands this long at
/// most, robot seconds: GameController3 shows play and goals 15 s late
/// (`delayAfterPlaying`, `delayAfterGoal`), and a robot hears the whistle up to a second
/// late and can miss a few of the GC's packets (one every 0.5 s); 5 s covers both. A
/// GameController that still says the same after that was not late: the whistle was not
/// the one the layer took it for (another field's, a free kick's), and the layer goes by
/// the GameController's word again (see [`TeamLayer::heard_whistle`]).
pub const WHISTLE_TRUST_S: f64 = 20.0;

/// With the radio dead, a whistle heard at least this long after a goal's whistle is the
/// kick-off's, seconds (see [`TeamLayer::heard_whistle`]). The two cannot come closer:
/// after a goal the robots walk to their kick-off places in Ready (the head referee ends
/// it once they make no more progress, after 45 s at the latest: the attackers walk
/// back metres into their own half, at a NAO's 0.3 m/s), a referee takes the ball out
/// of the goal to the centre spot, and only then, in Set, comes the kick-off's whistle.
/// 10 s stays below all that and well above a referee's second blow or a detector
/// hearing one whistle twice (a second or two apart).
pub const GOAL_TO_KICK_OFF_MIN_S: f64 = 10.0;

/// … and at most this long after it, seconds: Ready's 45 s at most, Set's few seconds and
/// the time the referee takes to start Ready after the goal's whistle. A whistle later
/// than that (the kick-off's unheard) is more likely the next goal's.
pub const GOAL_TO_KICK_OFF_MAX_S: f64 = 60.0;

/// What a whistle the robot program heard meant to the layer
/// ([`TeamLayer::heard_whistle`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Whistle {
    /// Heard in Set: play started (robot seconds, when).
    PlayStarted(f64),
    /// Heard in play: a goal (robot seconds, when).
    Goal(f64),
}

/// A kick-off placement a tick made (see [`TeamLayer::kick_off_placement`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KickOffPlacement {
    /// The GameController said Set: the team ball was put on the centre spot.
    Set,
    /// The robot heard play: the team ball, if still the Set's placement (no camera and
    /// no kick said otherwise), was put down again at this instant.
    PlayHeard,
}

impl TeamLayer {
    /// Whether the ball is in play: the GameController says Playing (true when there is
    /// no GameController). Out of play (Initial, Standby, Ready, Set, Finished) nobody
    /// plays the ball, so the layer keeps deciding for itself but tells the team nothing
    /// (a penalty aside): a league counts messages in Standby, Ready and Set, and a claim
    /// there is spent on nothing.
    ///
    /// A whistle the robot program heard runs ahead of it (see
    /// [`TeamLayer::heard_whistle`]): after a goal's whistle the layer is out of play
    /// while the GC still says Playing; after play's whistle it is in play while the GC
    /// still says Set.
    ///
    /// Only a word the whistle did not run ahead of undoes it (see `gc_answers`): a silent
    /// GC's last Playing is not its answer to a kick-off whistled after it.
    pub fn set_in_play(&mut self, in_play: bool) {
        self.gc_in_play = in_play;
        if !in_play && self.goal_whistle_at.is_some_and(|at| self.gc_answers(at)) {
            // The GC moved on from the Playing a goal's whistle ran ahead of.
            self.goal_whistle_at = None;
        }
        match self.whistle {
            // The GameController caught up (or moved on: Ready, Finished).
            Some(Whistle::PlayStarted(at)) if in_play && self.gc_answers(at) => {
                self.whistle = None;
            }
            Some(Whistle::Goal(at)) if !in_play && self.gc_answers(at) => self.whistle = None,
            _ => {}
        }
        self.in_play = self.whistled_in_play();
    }

    /// Whether the GameController's word answers a whistle heard at `at_s`: the GC was
    /// heard within [`crate::heartbeat::GC_SILENT_S`] before it, or since (or there is no
    /// heartbeat to tell). A whistle heard while the GC was silent ran ahead of its last
    /// word, which must not undo it: a kick-off's whistle after a goal's in an outage
    /// left the team in play by the GC's last Playing, and the GC's delayed Set, once
    /// heard again, began a kick-off anew (out of play until its Playing).
    fn gc_answers(&self, at_s: f64) -> bool {
        !self.gc_silent(at_s)
    }

    /// In play by the GameController's word and the whistle that runs ahead of it.
    fn whistled_in_play(&self) -> bool {
        match self.whistle {
            Some(Whistle::PlayStarted(_)) => true,
            Some(Whistle::Goal(_)) => false,
            None => self.gc_in_play,
        }
    }

    /// The robot program heard the referee's whistle at `now_s` (robot seconds): contract
    /// key `local.var.robot.whistle`. Under GameController3 the robots learn of play and
    /// of goals 15 s late (its packets show Set for 15 s after the whistle that starts
    /// play, and Playing with the old score for 15 s after a goal): a robot program is
    /// expected to hear the whistle itself. What the whistle means follows the GC's word
    /// when it is heard, as a robot program takes it:
    ///
    /// - **in Set** (the GC says Set, no whistle pending): play started. The layer is in
    ///   play and the kick-off hold starts ([`TeamLayer::set_kick_off_next`]), as if the
    ///   GC had said Playing; the GC's Set that follows is the delayed word of the same
    ///   kick-off, not a new one;
    /// - **in play** (the GC says Playing, or a play whistle is pending: a goal within
    ///   15 s of the kick-off): a goal. The layer forgets the ball ([`TeamLayer::forget_ball`],
    ///   as [`TeamLayer::set_scores`] does when the new score comes) and leaves play until
    ///   the GC says something else than Playing (its Ready for the kick-off);
    /// - anything else (Initial, Standby, Ready, Finished, a goal's whistle pending) changes
    ///   nothing here: out of play the layer has nothing to start. (A whistle in Standby
    ///   sends the robots to Ready: that is the robot program's walk, not the layer's.)
    ///
    /// With the radio dead (the GC silent for [`crate::heartbeat::GC_SILENT_S`]) its last
    /// word can be old news, and two more whistles mean play started:
    ///
    /// - **in Ready** (the GC's last word, [`TeamLayer::set_gc_ready`]): under the rules the
    ///   only whistle that follows Ready is the one that starts play (Set has none before
    ///   it), so the team has gone through a Set it did not hear. Heard with the GC, a
    ///   whistle in Ready is another field's: nothing;
    /// - **after a goal's whistle**, [`GOAL_TO_KICK_OFF_MIN_S`] to [`GOAL_TO_KICK_OFF_MAX_S`]
    ///   after it (pending or expired, the GC not heard since it could have answered): the
    ///   kick-off that follows the goal. Heard with the GC, nothing while the goal's
    ///   whistle is pending, as before.
    ///
    /// Without these the team stood out of play through the kick-off of an outage that
    /// began in Ready, or took the kick-off after a goal for another goal (`huddle sim
    /// --game restarts --budget spl --acoustic --outage 30s@200s`: one goer 0% of the
    /// outage on seed 16, the GC's last word Ready, 87% with the rule; 20% on seed 4, a
    /// goal's Ready that GC3 still showed as Playing, 99% with it). The GC's word, once
    /// heard again, corrects the layer as after any play whistle: its Set is the delayed
    /// word of the kick-off, its Playing catches up, its Ready drops it.
    ///
    /// A whistle stands [`WHISTLE_TRUST_S`] at most: if the GC still says Set (or Playing)
    /// then, the whistle was not what the layer took it for, and the GC's word counts
    /// again. Chosen over trusting it until the GC changes: a goal's whistle the GC never
    /// follows (a goal disallowed, another field's whistle) would otherwise keep the team
    /// out of play, silent, for the rest of the half; a play whistle that was not play
    /// would have it tell claims in Set. Both cost 20 s at most.
    ///
    /// Returns what it meant (`None`: nothing).
    pub fn heard_whistle(&mut self, now_s: f64) -> Option<Whistle> {
        let silent = self.gc_silent(now_s);
        let kick_off_after_goal = silent
            && self.goal_whistle_at.is_some_and(|at| {
                (GOAL_TO_KICK_OFF_MIN_S..=GOAL_TO_KICK_OFF_MAX_S).contains(&(now_s - at))
                    && self.beat.gc_silent_since(at + WHISTLE_TRUST_S)
            });
        let meant = match self.whistle {
            Some(Whistle::PlayStarted(_)) => Some(Whistle::Goal(now_s)),
            _ if kick_off_after_goal => Some(Whistle::PlayStarted(now_s)),
            Some(Whistle::Goal(_)) => None,
            None if self.gc_set => Some(Whistle::PlayStarted(now_s)),
            None if self.gc_in_play => Some(Whistle::Goal(now_s)),
            None if self.gc_ready && silent => Some(Whistle::PlayStarted(now_s)),
            None => None,
        }?;
        self.whistle = Some(meant);
        match meant {
            Whistle::PlayStarted(_) => {
                self.kick_off_next = false;
                self.goal_whistle_at = None;
            }
            Whistle::Goal(_) => {
                self.forget_ball(now_s);
                self.goal_whistle_at = Some(now_s);
            }
        }
        self.in_play = self.whistled_in_play();
        Some(meant)
    }

    /// The time (s) of the play whistle the layer acts on while the GameController still
    /// says Set ([`Whistle::PlayStarted`]), `None` otherwise: what the pacing clock runs
    /// from ([`paced_game_remaining`]). The daemon's tick publishes it at
    /// [`crate::contract::PLAY_WHISTLE_KEY`] for its GC listener; the simulator's
    /// robots hand it to the same call.
    pub fn play_whistle_at(&self) -> Option<f64> {
        match self.whistle {
            Some(Whistle::PlayStarted(at)) => Some(at),
            _ => None,
        }
    }

    /// The time (s) of the goal's whistle the layer acts on while the GameController
    /// still says Playing ([`Whistle::Goal`]), `None` otherwise. The daemon's tick
    /// publishes it at [`crate::contract::GOAL_WHISTLE_KEY`], beside the play whistle, so
    /// that a robot program's body follows the layer's reading of the whistle (to its
    /// kick-off spot after a goal, playing after the kick-off's) instead of one of its
    /// own that knows fewer rules.
    pub fn goal_whistle_at(&self) -> Option<f64> {
        match self.whistle {
            Some(Whistle::Goal(at)) => Some(at),
            _ => None,
        }
    }

    /// The whistle the layer acts on, if the GameController has not caught up.
    pub fn whistle(&self) -> Option<Whistle> {
        self.whistle
    }

    /// A whistle older than [`WHISTLE_TRUST_S`] at `now_s` is dropped: the
    /// GameController's word counts again; a play whistle only on the GC's current word
    /// (heard within [`crate::heartbeat::GC_SILENT_S`], or never heard at all). Called at
    /// each tick.
    pub(super) fn whistle_timeout(&mut self, now_s: f64) {
        let at = match self.whistle {
            Some(Whistle::PlayStarted(at) | Whistle::Goal(at)) => at,
            None => return,
        };
        // A play whistle stands while the GameController is silent (a dead radio): GC3
        // shows Set for 15 s after the kick-off's whistle, and when the WLAN died in
        // those 15 s the whistle expired and the team went back to the GC's last Set,
        // out of play until the GC was heard again (`huddle sim --game restarts --budget
        // spl --outage 30s@200s`, seed 13: no goer for 23 s). A goal's whistle still
        // expires: by then the kick-off after it is near, and the GC's last Playing is
        // what the team goes back to (kept standing, it left the team out of play for
        // the rest of the outage on seeds 3, 7 and 9).
        let stands = matches!(self.whistle, Some(Whistle::PlayStarted(_))) && self.gc_silent(now_s);
        if now_s - at > WHISTLE_TRUST_S && !stands {
            self.whistle = None;
            self.in_play = self.gc_in_play;
        }
    }

    /// Whether the GameController was heard once and not within
    /// [`crate::heartbeat::GC_SILENT_S`] of `now_s`: its last word may be old news.
    fn gc_silent(&self, now_s: f64) -> bool {
        self.beat
            .gc_silent_since(now_s - crate::heartbeat::GC_SILENT_S)
    }

    /// Whether the GameController says Ready: the robots walk to their places for a
    /// kick-off (or a penalty kick), and the next whistle starts play. Only a whistle heard
    /// while the GC is silent goes by it (see [`TeamLayer::heard_whistle`]): the daemon's
    /// tick and the simulator's robots call it with [`TeamLayer::set_in_play`] and
    /// [`TeamLayer::set_kick_off_next`] on each word of the GC's.
    pub fn set_gc_ready(&mut self, ready: bool) {
        self.gc_ready = ready;
    }

    /// Whether the GameController says Set: every robot stands on its kick-off spot, the
    /// ball on the centre spot, and play starts next with a kick-off. From Set until
    /// [`KICK_OFF_HOLD_S`] after the robot hears play, the **kick-off hold**: only a
    /// robot whose own cost is below [`KICK_OFF_TAKER_COST`] (the kicker the rules put
    /// at the centre spot) may claim the ball; every other robot decides as if it had no
    /// ball, on its own cost, not on a claim it told before the restart. The taker tells
    /// its claim in Set, with priority, `KICK_OFF_SET_CLAIMS` times: so at the end of
    /// the hold its teammates hold it and leave it the ball; the others tell nothing.
    ///
    /// Why: out of play nothing is told, and a goal's Ready and Set last longer than a
    /// claim is held under a budget (15 s in the SPL), so at the whistle no robot holds a
    /// fresh claim; and the team comes to a kick-off with no room for priority frames
    /// (under the knock-out clock it stands through Ready and Set, and the attack before
    /// the goal spent the room). Every robot that saw the ball went, and the claims that
    /// would settle it waited seconds for the budget. In a simulated SPL game (seeds
    /// 4–11) 78–86% of all conflict time fell in the first 10 s after a kick-off. The
    /// earlier remedy, every robot telling its cost in Set, spent a counted message per
    /// robot per kick-off, and under a budget with no room those claims did not go out
    /// at all.
    ///
    /// Why the taker's claim in Set (one counted message a kick-off, from the priority
    /// room the replica restarts at Set): at the whistle its claim was otherwise news
    /// only if it changed what the taker told last (35 s and more ago, dropped by every
    /// teammate) and so went as an ordinary frame, if at all; at the game's first
    /// kick-off it was the team's first message, and the pacing line opens no ordinary
    /// frame in the game's first seconds. At the end of the hold a teammate that had not
    /// heard it went too: seeds 4–43 (both worlds), 2.3–2.5 s of conflict at the first
    /// kick-off on average, 0.1–0.2 s with the claim in Set.
    ///
    /// Set also says where the ball is: on the centre spot, so at the next tick every
    /// ball belief goes and the team ball is put there (see [`TeamLayer::forget_ball`]);
    /// a caller whose Set is for a penalty kick (the ball on a penalty mark) must not
    /// call this.
    ///
    /// Returns whether a kick-off begins (the first Set heard): the caller then tells
    /// its replica (`comms::Replica::restart_priority_room`), so that the claims that
    /// change at the whistle find room for priority frames in the team's budget.
    ///
    /// After a whistle heard in Set ([`TeamLayer::heard_whistle`]) the GC's Set is the
    /// delayed word of the kick-off that has started: it begins nothing.
    pub fn set_kick_off_next(&mut self, set: bool) -> bool {
        self.gc_set = set;
        // (A silent GC's last Ready is the one a whistle was heard in: see `gc_answers`.)
        let answers = match self.whistle {
            Some(Whistle::PlayStarted(at)) => self.gc_answers(at),
            _ => false,
        };
        if !set && answers && !self.gc_in_play {
            // The GC left Set for something else than Playing (Ready, Finished).
            self.whistle = None;
            self.in_play = self.gc_in_play;
        }
        let set = set && !matches!(self.whistle, Some(Whistle::PlayStarted(_)));
        let begins = set && !self.kick_off_next;
        if begins {
            self.kick_off_hold_until_s = Some(f64::INFINITY);
            self.kick_off_place = true;
            self.kick_off_claims = (0, f64::NEG_INFINITY);
            self.kick_off_taker_h = None;
        }
        self.kick_off_next = set;
        begins
    }

    /// The kick-off hold at `t_s` (see [`TeamLayer::set_kick_off_next`]): whether it
    /// runs, started once the robot hears play.
    pub(super) fn kick_off_hold(&mut self, t_s: f64) -> bool {
        match self.kick_off_hold_until_s {
            Some(until) if until.is_infinite() && self.in_play && !self.kick_off_next => {
                self.kick_off_hold_until_s = Some(t_s + KICK_OFF_HOLD_S);
            }
            Some(until) if t_s >= until => self.kick_off_hold_until_s = None,
            _ => {}
        }
        self.kick_off_hold_until_s.is_some()
    }

    /// The scores in the newest GameController packet (`now_s`: when it was heard). A
    /// goal is heard when either score rises over the previous packet's: the layer
    /// forgets the ball then ([`TeamLayer::forget_ball`]), as a robot program's ball
    /// reset does, whatever the game state says (GC3 may show Playing for seconds after
    /// a goal). The first packet, or a score that falls (a new game), is no goal.
    /// Returns whether it heard a goal.
    pub fn set_scores(&mut self, own: u8, other: u8, now_s: f64) -> bool {
        let goal = self.scores_heard.is_some_and(|(o, t)| own > o || other > t);
        self.scores_heard = Some((own, other));
        if goal {
            self.forget_ball(now_s);
        }
        goal
    }

    /// The robots the GameController says are penalised (player numbers, this robot's
    /// included; substitutes count: they are not on the field). A penalised robot leaves
    /// the arbitration: it claims nothing (it posts [`PENALIZED_COST`], not going, once,
    /// with priority, and is otherwise silent), and its teammates stop counting its claim
    /// at once, whatever it last said. Called with each new GameController packet.
    pub fn set_penalties(&mut self, penalized: &[u8]) {
        let was = self.penalized();
        self.penalized.iter_mut().for_each(|p| *p = false);
        for &id in penalized {
            if let Some(p) = usize::from(id)
                .checked_sub(1)
                .and_then(|k| self.penalized.get_mut(k))
            {
                *p = true;
            }
        }
        if self.penalized() && !was {
            self.penalty_told = false;
            self.h = PENALIZED_COST;
        }
    }

    /// Its "penalised" claim goes to the replica: the sending policy takes it as told.
    pub(super) fn told_penalty(&mut self) {
        self.penalty_told = true;
        self.untold_claim = None;
        if self.compact {
            self.policy
                .wrote_claim(false, PENALIZED_COST, PENALIZED_COST);
        } else {
            self.policy
                .sent_going(false, PENALIZED_COST, PENALIZED_COST);
        }
    }

    /// Whether the GameController says this robot is penalised.
    pub fn penalized(&self) -> bool {
        self.is_out(self.id)
    }

    /// Whether robot `id` is penalised by the GameController's word.
    pub(super) fn is_out(&self, id: u8) -> bool {
        usize::from(id)
            .checked_sub(1)
            .and_then(|k| self.penalized.get(k))
            .copied()
            .unwrap_or(false)
    }

    /// The game controller says the ball was put back for a kick-off (`now_s` on the
    /// robot's clock): every ball belief goes, and the team ball starts on the kick-off
    /// spot the rules name (the centre spot of the field the robot is calibrated for,
    /// `KICK_OFF_SPOT_SIGMA_M` (0.1 m) for the referee's placement), not with the first message
    /// a teammate can afford to send. Sightings are gated against it and fused with it;
    /// cameras that see the ball elsewhere restart it (see
    /// [`fusion::GlobalModel::place_ball`]).
    ///
    /// Why: every robot forgot the ball at each of a game's ~20 kick-offs, so a robot
    /// that did not see the ball itself held no team ball until a teammate's message
    /// came, seconds under a league's budget (about one message a second for the team).
    pub fn forget_ball(&mut self, now_s: f64) {
        self.lwm.forget_ball();
        let placed = self.kick_off_ball(now_s);
        self.gwm.place_ball(placed);
        self.ball = None;
        self.ball_seen_at_s = None;
        self.team_ball = None;
        // Held too: a daemon publishes it between ticks (a teammate's claim changing
        // makes it decide and publish again), and the old ball must not come back then:
        // what it publishes is the kick-off spot.
        self.team_ball_held = Some(TeamBall {
            estimate: placed,
            gbc: fusion::position_confidence(&placed.position_cov()),
            source: fusion::TeamBallSource::Fused,
        });
    }

    /// The ball on the kick-off spot at `t_s`, as the robot knows the field: at rest, give
    /// or take the referee's placement.
    pub fn kick_off_ball(&self, t_s: f64) -> BallEstimate {
        let at = frames::to_fusion_point(self.cal.field.centre_spot());
        let p = KICK_OFF_SPOT_SIGMA_M.powi(2);
        let v = KICK_OFF_SPEED_SIGMA_MPS.powi(2);
        BallEstimate {
            t_s,
            mean: fusion::nalgebra::Vector4::new(at.x, at.y, 0.0, 0.0),
            cov: fusion::nalgebra::Matrix4::from_diagonal(&fusion::nalgebra::Vector4::new(
                p, p, v, v,
            )),
        }
    }

    /// What the latest tick ([`TeamLayer::sense`]) did for a kick-off: put the team ball
    /// on the centre spot for Set, or heard play (and put it down again if it was still
    /// that placement). A reference of the team ball makes the same placement at the
    /// same instant, by its own rule.
    pub fn kick_off_placement(&self) -> Option<KickOffPlacement> {
        self.tick_placement
    }
}

#[cfg(test)]
#[path = "whistle_tests.rs"]
mod whistle_tests;

/// The game clock the budget paces by at `now_s`, from the GC's figure `gc_remaining`
/// (the game time left its newest packet gives), whether that packet says Set
/// (`gc_says_set`) and the play whistle the layer acts on
/// ([`TeamLayer::play_whistle_at`]). One rule: the daemon's GameController listener and
/// the simulator's robots both pace by it (through `driver::budget_figures`).
///
/// While the layer acts on a play whistle the GC has not caught up with (the GC still
/// says Set), the clock runs from the whistle: the GC's standing figure less the play
/// since the whistle. Without it each packet of GameController3's delayed Set (15 s)
/// set the clock back, the pacing line stood and only the priority room's frames went
/// out: `huddle sim --budget spl --game restarts --whistle 1`, seeds 4–11, 3.6–3.9
/// frames in the first 10 s of a kick-off against 8.5–9.2 under the undelayed referee
/// (docs/results/gamecontroller-game.md, "Eleventh session, the clock"). When the GC
/// says Playing its figure (the true one) rules again.
///
/// A goal's whistle keeps the GC's figure: GameController3 shows Playing with its clock
/// running for 15 s while the game stands in Ready, so the line runs ahead while the
/// layer is out of play and sends next to nothing; the GC's Ready puts the true figure
/// back before the kick-off, so the credit is gone before play needs it.
pub fn paced_game_remaining(
    play_whistle_at: Option<f64>,
    gc_remaining: std::time::Duration,
    gc_says_set: bool,
    now_s: f64,
) -> std::time::Duration {
    match play_whistle_at {
        Some(at) if gc_says_set => {
            let played = (now_s - at).max(0.0);
            gc_remaining.saturating_sub(std::time::Duration::from_secs_f64(played))
        }
        _ => gc_remaining,
    }
}
