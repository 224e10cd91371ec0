//! A message budget: how many frames this robot may send over a game, paced over the
//! game clock, with a reserve for priority items.
//!
//! Leagues count messages: the RoboCup SPL allows 1,200 per team per game (GameController3
//! `messagesPerTeam`, 10 + 10 minutes of play) of at most 128 bytes of payload; the
//! Humanoid League 12,000 of at most 512. A [`BudgetSpec`] is the league's rule for a
//! team; [`BudgetSpec::share`] is one robot's part of it ([`Budget`]), which its replica
//! never exceeds: every frame it sends is one message, counted exactly.
//!
//! Pacing: a frame of ordinary items may go once `remaining game time / ordinary messages
//! left` has passed since the previous ordinary frame, so what is not spent early is
//! spread over the rest of the game, and the last messages are not spent before the end.
//!
//! Pooling ([`Budget::team`], the default of [`BudgetSpec::share`]): a robot with nothing
//! to say leaves its share to teammates that have. Every frame carries its sender's frame
//! counter, so each replica knows how many frames each teammate has sent up to the last
//! one it heard; the team's frames are paced along one line over the game (its messages
//! less a margin and the room for priority frames, see [`TeamPool`]). A robot under its
//! equal share of the line may send whenever the team is under it; one over its share
//! (borrowing what others left) only while the team is at least one frame per robot
//! under it, so that robots under their share go first and several borrowers deciding at
//! once cannot overrun it. Priority items ([`crate::Replica::set_priority`]: a goer
//! change, a kick, a referee event) may go at once while the team is less than one frame
//! per robot beyond its line, whoever sends them; a robot spending its share alone keeps
//! a fifth of it for its own. At a kick-off, when every claim changes at once, that room
//! starts afresh from the team's count ([`crate::Replica::restart_priority_room`]).
//!
//! What the pool counts, and what holds when frames lie: a teammate's frames count by
//! the frame counter of its current life, at most twice the frames of that life this
//! robot heard plus four, and an earlier life only as far as it was counted while it was
//! current here (a replayed frame of a life never current here counts nothing); only the
//! `robots - 1` ids that count most are summed. That bounds what one forged header can
//! claim, but not what a stream of them can: without a team key any frame can be forged,
//! and with one a whole recorded life of a teammate absent today can be replayed to a
//! robot that never heard it. So the pool has a **floor**: whatever it heard, a robot
//! may send on its own equal part of the line (`⌊own · p⌋` frames by the share `p` of
//! the game played, paced by its credit). A drained pool costs the team its lending,
//! never its voice; and since the floor is the robot's own part, the team stays within
//! its budget (the margin absorbs the few frames by which owners and borrowers deciding
//! at once can overlap). The game clock is an input: by default the game starts when
//! the replica does; [`crate::Replica::set_game_clock`] sets the remaining time (the
//! GameController's `secsRemaining`, when there is one).
//!
//! The league's referee system is the authority on what a team has left: with an
//! [`ExternalCap`] ([`crate::Replica::set_external_budget`], the daemon feeds the
//! GameController's figures twice a second) no frame goes beyond the team's messages left
//! by its figure (less what this robot and the teammates it heard sent since), ordinary
//! frames also keep to its line (`ceil(rate · time left)` kept for the rest of the game),
//! a pooled team counts its frames by it (so a robot restarted mid-game resumes from the
//! GC's figures, not a fresh share), and in states it does not count a frame is free
//! (one per [`FREE_GAP`] at most) and spends nothing.

use std::fmt;
use std::str::FromStr;
use std::time::Duration;

use crate::time::Instant;

/// A league's rule for a whole team.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BudgetSpec {
    /// Messages the team may send over `game`.
    pub team_messages: u64,
    /// The game time they are for.
    pub game: Duration,
    /// Largest payload (a whole frame: header, items and tag), bytes; `None`: the MTU.
    pub payload_limit: Option<usize>,
}

impl BudgetSpec {
    /// RoboCup SPL: 1,200 messages per team per 20-minute game, 128-byte payloads.
    pub const SPL: BudgetSpec = BudgetSpec {
        team_messages: 1200,
        game: Duration::from_secs(1200),
        payload_limit: Some(128),
    };

    /// RoboCup Humanoid League: 12,000 messages per team per 20-minute game, 512-byte
    /// payloads.
    pub const HUMANOID: BudgetSpec = BudgetSpec {
        team_messages: 12_000,
        game: Duration::from_secs(1200),
        payload_limit: Some(512),
    };

    /// One robot's share in a team of `robots`: an equal part of the messages, pooled
    /// with the team's (see the module docs and `TeamPool::priority_ahead`: the team's
    /// priority frames share one frame per robot beyond the team's line). Spent alone
    /// ([`Budget::split`]), a fifth of the equal part (at least one) is kept for the
    /// robot's own priority items (`reserve`).
    ///
    /// Why a fifth: with a tenth (12 per robot per SPL half), the reserve ran dry in
    /// simulated matches, and a goer's stop then waited seconds for its ordinary pacing
    /// while a teammate deferred to it (`huddle sim --budget spl`, 600 s, seeds 4–27: one
    /// goer 89.6 / 88.3% for the VOI / baseline policies with a tenth, 90.9 / 90.4% with a
    /// fifth; conflicts 6.8 → 5.1%).
    pub fn share(&self, robots: usize) -> Budget {
        let robots = robots.max(1) as u64;
        let messages = self.team_messages / robots;
        Budget {
            messages,
            game: self.game,
            reserve: (messages / 5).max(1).min(messages),
            team: Some(TeamPool {
                messages: self.team_messages,
                robots,
            }),
        }
    }
}

/// Why a budget did not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "budget `{0}`: expected spl, humanoid or N/DURATION such as 600/10min (units ms, s, min, h)"
)]
pub struct BudgetParseError(pub String);

impl FromStr for BudgetSpec {
    type Err = BudgetParseError;

    /// `spl`, `humanoid`, or `N/DURATION` (`600/10min`, `100/60s`), optionally with a
    /// payload limit as [`Display`](fmt::Display) writes it (`1200/1200s (≤ 128 B)`,
    /// also `<=`), so a budget printed in a report or a log reads back as the same one.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = || BudgetParseError(s.to_string());
        let mut t = s.trim();
        let mut payload_limit = None;
        if let Some((rule, limit)) = t.split_once('(') {
            let limit = limit.strip_suffix(')').ok_or_else(err)?.trim();
            let limit = limit
                .strip_prefix('≤')
                .or_else(|| limit.strip_prefix("<="))
                .ok_or_else(err)?;
            let bytes = limit.trim().strip_suffix('B').ok_or_else(err)?.trim();
            let bytes: usize = bytes.parse().map_err(|_| err())?;
            if bytes == 0 {
                return Err(err());
            }
            payload_limit = Some(bytes);
            t = rule.trim();
        }
        let mut spec = Self::rule(t).ok_or_else(err)?;
        if payload_limit.is_some() {
            spec.payload_limit = payload_limit;
        }
        Ok(spec)
    }
}

impl BudgetSpec {
    /// The rule part of [`BudgetSpec::from_str`]: a league's name or `N/DURATION`.
    fn rule(t: &str) -> Option<BudgetSpec> {
        if t.eq_ignore_ascii_case("spl") {
            return Some(BudgetSpec::SPL);
        }
        if t.eq_ignore_ascii_case("humanoid") {
            return Some(BudgetSpec::HUMANOID);
        }
        let (n, d) = t.split_once('/')?;
        let team_messages: u64 = n.trim().parse().ok()?;
        let d = d.trim();
        let split = d.find(|c: char| !(c.is_ascii_digit() || c == '.'))?;
        let (num, unit) = d.split_at(split);
        let num: f64 = num.parse().ok()?;
        let secs = match unit {
            "ms" => num / 1000.0,
            "s" => num,
            "min" => num * 60.0,
            "h" => num * 3600.0,
            _ => return None,
        };
        if team_messages == 0 || !(secs.is_finite() && secs > 0.0 && secs < 1e9) {
            return None;
        }
        Some(BudgetSpec {
            team_messages,
            game: Duration::from_secs_f64(secs),
            payload_limit: None,
        })
    }
}

impl fmt::Display for BudgetSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/{}s", self.team_messages, self.game.as_secs_f64())?;
        if let Some(p) = self.payload_limit {
            write!(f, " (≤ {p} B)")?;
        }
        Ok(())
    }
}

/// One robot's budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Budget {
    /// Frames this robot may send over the game.
    pub messages: u64,
    /// The game time they are for.
    pub game: Duration,
    /// Of them, kept for frames with priority items when this robot spends its share
    /// alone (`team` is `None`); a pooled team shares its room for priority frames
    /// instead (`TeamPool`).
    pub reserve: u64,
    /// The team's budget, when the robots pool their ordinary messages (`None`: this
    /// robot spends its `messages` alone).
    pub team: Option<TeamPool>,
}

/// A team's pooled budget.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TeamPool {
    /// Messages the whole team may send over the game.
    pub messages: u64,
    /// Robots in the team.
    pub robots: u64,
}

impl TeamPool {
    /// Frames kept back from the pooled line: three per robot, for teammates' frames not
    /// heard yet (lost, or on their way) and robots that decide at once. Priority frames
    /// count on the line like any other (so ordinary ones wait after them) and may go
    /// up to [`TeamPool::priority_ahead`] frames beyond it, up to half the margin short
    /// of the team's messages: the team never spends more than its budget.
    fn margin(&self) -> u64 {
        3 * self.robots
    }

    /// How far beyond the line the team's priority frames may go: one frame per robot,
    /// shared. Whoever has a goer change or a kick to tell spends them, and ordinary
    /// frames wait until the line has passed the team's frames again.
    ///
    /// Why shared rather than a reserve per robot: the robots at the ball make nearly all
    /// of the goer changes and kicks, and with a fifth of each share kept for each robot
    /// (paced over the game) theirs ran dry while the goalkeeper's went unused; a goer's
    /// stop then waited seconds for its ordinary pacing, and teammates that had not heard
    /// it left the ball to nobody. `huddle sim --budget spl`, 600 s, seeds 4–27, one goer
    /// VOI / baseline: 91.5 / 91.5% with the reserves per robot, 96.9 / 96.5% shared;
    /// blind robots' team-ball RMSE 1.24 / 1.70 m → 1.31 / 1.59 m. How much room: with the
    /// room kept below the line instead (ordinary frames stopping short of it), 2, 3, 4,
    /// 5 and 10 frames gave the baseline 93.6, 95.2, 96.0, 96.9 and 96.6% one goer; one
    /// frame per robot was its best.
    fn priority_ahead(&self) -> u64 {
        self.robots
    }

    /// Frames the team's line reaches by the end of the game: its messages less the
    /// margin and the room for priority frames beyond the line, so that the team is
    /// within its budget pro rata at any time of the game, not only at its end.
    fn usable(&self) -> u64 {
        self.messages
            .saturating_sub(self.margin() + self.priority_ahead())
    }

    /// One robot's equal part of the line (not of its own share less its reserve: the
    /// parts must add up to the line, or the last robot to decide starves).
    fn own_usable(&self) -> u64 {
        self.usable() / self.robots.max(1)
    }
}

impl Budget {
    /// The same share spent alone: no pooling with the team.
    pub fn split(self) -> Budget {
        Budget { team: None, ..self }
    }

    /// The time between two messages when they are spread evenly over the game.
    pub fn interval(&self) -> Duration {
        self.game / u32::try_from(self.messages.max(1)).unwrap_or(u32::MAX)
    }
}

/// The league's referee system's figures for the team's budget (the GameController's
/// `messageBudget` less a safety margin): the authority over this robot's own accounting.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExternalCap {
    /// Whether a frame sent now is counted against the budget.
    pub counted: bool,
    /// Frames the whole team may still send, as of this figure.
    pub team_left: u64,
    /// The league's messages per second of game time: ordinary frames leave
    /// `ceil(rate_per_s · time left)` for the rest of the game.
    pub rate_per_s: f64,
    /// Frames `team_left` keeps short of the referee's own figure: not spent, so a pooled
    /// line does not count them as sent (at the kick-off the team is on its line, not a
    /// margin behind it).
    pub margin: u64,
}

/// The shortest gap between two frames in a state the referee system does not count: its
/// state can lag by one of its periods (500 ms), in which frames thought free are counted.
pub const FREE_GAP: Duration = Duration::from_millis(250);

/// An external figure and the counts of frames when it came.
#[derive(Debug, Clone, Copy)]
struct External {
    cap: ExternalCap,
    /// This robot's frames (counted and free) when the figure came.
    sent_at: u64,
    /// Teammates' frames heard when the figure came.
    heard_at: u64,
}

/// Which allowance a frame draws on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Class {
    /// Ordinary items: paced.
    Ordinary,
    /// At least one priority item: may use the reserve at once.
    Priority,
}

/// A budget in use.
#[derive(Debug, Clone)]
pub(crate) struct BudgetState {
    pub(crate) budget: Budget,
    /// The game clock: at `.0` there were `.1` of play left.
    clock: (Instant, Duration),
    sent: u64,
    sent_ordinary: u64,
    /// Frames drawn on the reserve.
    sent_reserve: u64,
    last_ordinary: Option<Instant>,
    /// Frames teammates have sent, by the frame counters heard (pooled budgets).
    heard: u64,
    /// Pooled: this robot's credit on its equal part, in frames, as of the share of the
    /// game `.1` (it accrues with play, up to [`OWNER_CREDIT_MAX`]).
    credit: (f64, f64),
    /// The referee system's figures, when there are some.
    external: Option<External>,
    /// Frames sent in states the referee system does not count, and the last one's time.
    free: (u64, Option<Instant>),
    /// The team's frames when play last restarted with every claim changing at once (see
    /// [`BudgetState::restart`]): its priority frames have their room from there.
    restart: Option<u64>,
}

/// Frames of its equal part a pooled robot may save up: what it leaves beyond this goes to
/// teammates that borrow, and a robot that borrowed owes nothing (so the robot with the
/// most to say, the one at the ball, is never starved for having said much).
const OWNER_CREDIT_MAX: f64 = 2.0;

impl BudgetState {
    pub(crate) fn new(budget: Budget, start: Instant) -> Self {
        BudgetState {
            budget,
            clock: (start, budget.game),
            sent: 0,
            sent_ordinary: 0,
            sent_reserve: 0,
            last_ordinary: None,
            heard: 0,
            credit: (1.0, 0.0),
            external: None,
            free: (0, None),
            restart: None,
        }
    }

    /// The referee system's newest figures (`None`: there is none; the budget is this
    /// replica's own accounting alone).
    pub(crate) fn set_external(&mut self, cap: Option<ExternalCap>) {
        self.external = cap.map(|cap| External {
            cap,
            sent_at: self.sent + self.free.0,
            heard_at: self.heard,
        });
    }

    /// Whether an external figure is in force.
    pub(crate) fn has_external(&self) -> bool {
        self.external.is_some()
    }

    /// Frames the team may still send by the external figure, less this robot's frames
    /// and the teammates' heard since it came.
    fn external_left(&self, x: &External) -> u64 {
        let since = (self.sent + self.free.0).saturating_sub(x.sent_at)
            + self.heard.saturating_sub(x.heard_at);
        x.cap.team_left.saturating_sub(since)
    }

    /// When the external line lets an ordinary frame go: once `ceil(rate · time left)` is
    /// below the figure's frames left.
    fn external_line_open(&self, now: Instant, x: &External) -> Option<Instant> {
        let left = self.external_left(x);
        if left == 0 {
            return None;
        }
        if x.cap.rate_per_s <= 0.0 {
            return Some(now);
        }
        let until = (left - 1) as f64 / x.cap.rate_per_s;
        let wait = self.remaining(now).as_secs_f64() - until;
        Some(now + Duration::from_secs_f64(wait.clamp(0.0, 1e9)))
    }

    /// Teammates have sent `frames` in all, as far as this robot has heard.
    pub(crate) fn set_heard(&mut self, frames: u64) {
        self.heard = frames;
    }

    /// The team's frames so far, as far as this robot knows (by the external figure when
    /// there is one).
    pub(crate) fn team_sent(&self) -> u64 {
        match (&self.external, self.budget.team) {
            (Some(x), Some(team)) => team
                .messages
                .saturating_sub(self.external_left(x).saturating_add(x.cap.margin)),
            _ => self.sent + self.heard,
        }
    }

    /// The share of the game played at `now`, in [0, 1].
    fn played(&self, now: Instant) -> f64 {
        let game = self.budget.game.as_secs_f64();
        if game <= 0.0 {
            return 1.0;
        }
        ((game - self.remaining(now).as_secs_f64()) / game).clamp(0.0, 1.0)
    }

    /// When the share of the game played reaches `share` (now, if it has).
    fn when_played(&self, now: Instant, share: f64) -> Option<Instant> {
        if share > 1.0 {
            return None;
        }
        let wait = (share - self.played(now)) * self.budget.game.as_secs_f64();
        Some(now + Duration::from_secs_f64(wait.max(0.0)))
    }

    /// The game clock says `remaining` at `now`.
    pub(crate) fn set_clock(&mut self, now: Instant, remaining: Duration) {
        self.clock = (now, remaining);
    }

    /// Play left at `now`.
    pub(crate) fn remaining(&self, now: Instant) -> Duration {
        let (at, left) = self.clock;
        left.saturating_sub(now.saturating_duration_since(at))
    }

    /// Messages left in all: this robot's, or with a pool the team's (as far as this
    /// robot has heard).
    pub(crate) fn left(&self) -> u64 {
        let own = match self.budget.team {
            None => self.budget.messages.saturating_sub(self.sent),
            Some(team) => {
                let cap = team.messages.saturating_sub(team.margin() / 2);
                cap.saturating_sub(self.team_sent())
            }
        };
        match &self.external {
            Some(x) => own.min(self.external_left(x)),
            None => own,
        }
    }

    /// Messages sent so far.
    pub(crate) fn sent(&self) -> u64 {
        self.sent
    }

    fn ordinary_left(&self) -> u64 {
        let cap = self.budget.messages.saturating_sub(self.budget.reserve);
        cap.saturating_sub(self.sent_ordinary).min(self.left())
    }

    /// When the next ordinary frame may go (`None`: never again this game, or until the
    /// external figure changes).
    pub(crate) fn next_ordinary(&self, now: Instant) -> Option<Instant> {
        match &self.external {
            None => self.next_paced(now),
            // At the GameController's zero nothing goes, the pool's floor included, and
            // not a free frame either (its state can lag one period behind a counted
            // one). This arm comes first: `allows` refuses then, and a deadline it
            // refuses would be due forever (a driver spinning on one instant).
            Some(_) if self.left() == 0 => None,
            Some(x) if !x.cap.counted => Some(self.free.1.map_or(now, |t| t + FREE_GAP)),
            Some(x) => {
                let paced = self.next_paced(now)?;
                Some(paced.max(self.external_line_open(now, x)?))
            }
        }
    }

    /// [`BudgetState::next_ordinary`] by this replica's own pacing.
    fn next_paced(&self, now: Instant) -> Option<Instant> {
        if let Some(team) = self.budget.team {
            return self.next_pooled(now, team);
        }
        let left = self.ordinary_left();
        if left == 0 {
            return None;
        }
        let Some(last) = self.last_ordinary else {
            return Some(now);
        };
        let gap = self.remaining(now) / u32::try_from(left).unwrap_or(u32::MAX);
        Some(last + gap)
    }

    /// Pooled: the team's line over the game, `line(p) = ⌊usable · p⌋ + 1` frames by the
    /// time a share `p` of it is played, and this robot's equal share of it likewise.
    fn next_pooled(&self, now: Instant, team: TeamPool) -> Option<Instant> {
        let (usable, own_usable) = (team.usable(), team.own_usable());
        // The floor: this robot's own equal part of the line, paced by its credit, whatever
        // it heard of the team. A pool drained by forged or replayed frame counters (or
        // teammates that truly overspent) falls back to it, never to silence.
        // It goes while the robot is under its own line, `⌊own_usable · p⌋` frames by `p`
        // (so not before its first frame's worth of the game has passed: the pool
        // starts the game), on its credit (so what it left earlier is not spent at once:
        // borrowers have used it).
        let credit = self.credit_at(now, own_usable);
        let own = if self.sent >= self.budget.messages || own_usable == 0 {
            None
        } else {
            let under_line = self.when_played(now, (self.sent + 1) as f64 / own_usable as f64);
            let credited = if credit >= 1.0 {
                Some(now)
            } else {
                self.when_played(now, self.played(now) + (1.0 - credit) / own_usable as f64)
            };
            match (under_line, credited) {
                (Some(a), Some(b)) => Some(a.max(b)),
                _ => None,
            }
        };
        if usable == 0 || self.left() == 0 {
            return own;
        }
        // The line passes `k` frames once ⌊usable · p⌋ ≥ k, i.e. at p = k / usable.
        let team_at = |k: u64| self.when_played(now, k as f64 / usable as f64);
        // Borrowing (beyond its own credit): once the team line is a frame per robot ahead
        // of the team's frames as heard, so that robots under their share go first.
        let as_borrower = team_at(self.team_sent() + team.robots);
        match (own, as_borrower) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }

    /// Pooled: this robot's credit on its equal part at `now`, frames.
    fn credit_at(&self, now: Instant, own_usable: u64) -> f64 {
        let (credit, at) = self.credit;
        (credit + own_usable as f64 * (self.played(now) - at).max(0.0)).min(OWNER_CREDIT_MAX)
    }

    /// Ordinary frames the pacing would let go at `now` before it holds one back: the
    /// team's line less the team's frames (pooled), or this robot's own line less its
    /// frames. Negative while the pacing holds frames back. A sending policy keeps a few
    /// in hand for what cannot wait (a ball that suddenly moves) by asking little of a
    /// budget running short.
    pub(crate) fn headroom(&self, now: Instant) -> i64 {
        let played = self.played(now);
        let line = |usable: u64| (usable as f64 * played).floor() as i64 + 1;
        match self.budget.team {
            Some(team) => line(team.usable()) - self.team_sent() as i64,
            None => {
                let usable = self.budget.messages.saturating_sub(self.budget.reserve);
                line(usable) - self.sent_ordinary as i64
            }
        }
    }

    /// [`BudgetState::headroom`] as priority frames count it: from the team's count at
    /// the latest restart while the line is below it.
    fn priority_headroom(&self, now: Instant) -> i64 {
        let line = self.headroom(now);
        match self.restart {
            Some(at) => line.max(at as i64 - self.team_sent() as i64),
            None => line,
        }
    }

    /// Play restarts with every robot's claim changing at once (a kick-off: the robot
    /// heard the GameController's Set): the team's priority frames get their room,
    /// [`TeamPool::priority_ahead`] frames, afresh from the team's count now, wherever
    /// the line is. Ordinary frames keep to the line, and every frame still counts on it,
    /// so the room is repaid by ordinary frames waiting, and the team's messages, the
    /// margin's half and the referee's figure still bound it. A budget spent alone keeps
    /// its own reserve: nothing changes.
    ///
    /// Why: the attack before a goal spends the room (kicks, goer changes), and under a
    /// clock that stands through Ready and Set nothing refills it: the team met the
    /// whistle beyond its line (median 2–3 frames, up to 8), and the taker's claim waited
    /// seconds for a frame while the kick-off hold ran out and a second robot went for
    /// the ball. `huddle sim --budget spl --game full`, seeds 4–11: the first priority
    /// claim after the whistle waited over 1 s at 40 of 172 (drawn) and 39 of 193
    /// (ideal) kick-offs, with the restart at 1 of 173 and 0 of 168; one goer 97.11 →
    /// 97.40% and 97.25 → 97.52%, blind robots' team ball 1.720 → 1.616 m and 1.080 →
    /// 1.042 m. At Set the team has been silent since Ready, so every robot counts the
    /// same frames and the room is one room.
    pub(crate) fn restart(&mut self) {
        if self.budget.team.is_some() {
            self.restart = Some(self.team_sent());
        }
    }

    /// Whether a frame of `class` may go now.
    pub(crate) fn allows(&self, now: Instant, class: Class) -> bool {
        // Pooled, the floor (its own credit) holds whatever the team's count says.
        let ordinary = self.next_ordinary(now).is_some_and(|t| t <= now);
        if self.left() == 0 {
            // The GameController's zero is final; without one, a pooled robot keeps its
            // own floor whatever the team's count says.
            return ordinary && self.budget.team.is_some() && !self.has_external();
        }
        if self.external.is_some_and(|x| !x.cap.counted) {
            return ordinary;
        }
        match class {
            Class::Ordinary => ordinary,
            Class::Priority => match self.budget.team {
                // Pooled: while the team is less than `priority_ahead` beyond its line,
                // or beyond its count at a restart (see `restart`).
                Some(team) => {
                    ordinary || self.priority_headroom(now) + team.priority_ahead() as i64 > 0
                }
                None => ordinary || self.sent_reserve < self.reserve_open(now),
            },
        }
    }

    /// Reserve frames allowed by `now`: the reserve is paced too (its share of the game so
    /// far, plus one), so an eager first half cannot spend the second half's.
    fn reserve_open(&self, now: Instant) -> u64 {
        let game = self.budget.game.as_secs_f64();
        let played = (game - self.remaining(now).as_secs_f64()).max(0.0);
        let share = (self.budget.reserve as f64 * played / game.max(1e-9)).floor() as u64;
        (share + 1).min(self.budget.reserve)
    }

    /// A frame of `class` went at `now`.
    pub(crate) fn spend(&mut self, now: Instant, class: Class) {
        if self.external.is_some_and(|x| !x.cap.counted) {
            self.free = (self.free.0 + 1, Some(now));
            return;
        }
        let ordinary = self.next_ordinary(now).is_some_and(|t| t <= now);
        if let Some(team) = self.budget.team {
            // Every frame draws on the credit while there is some; borrowing owes nothing.
            let credit = self.credit_at(now, team.own_usable());
            self.credit = ((credit - 1.0).max(0.0), self.played(now));
        }
        self.sent += 1;
        if class == Class::Ordinary || ordinary {
            self.sent_ordinary += 1;
            self.last_ordinary = Some(now);
        } else {
            self.sent_reserve += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(ms: u64) -> Instant {
        Instant::from_micros(ms * 1000)
    }

    fn gc(counted: bool, team_left: u64) -> Option<ExternalCap> {
        Some(ExternalCap {
            counted,
            team_left,
            rate_per_s: 1.0,
            margin: 0,
        })
    }

    /// The GameController says 3 frames are left (after its margin): whatever the robot's
    /// own share says, at most three frames go, priority or not (a pooled team keeps its
    /// own margins on top: none), and then none until it says more.
    #[test]
    fn an_external_figure_is_the_authority_on_frames_left() {
        for (budget, expect) in [
            (BudgetSpec::SPL.share(5).split(), 3),
            (BudgetSpec::SPL.share(5), 0),
        ] {
            let mut b = BudgetState::new(budget, at(0));
            b.set_clock(at(0), Duration::ZERO);
            b.set_external(gc(true, 3));
            let mut sent = 0;
            for ms in (0..5_000).step_by(10) {
                if b.allows(at(ms), Class::Priority) {
                    b.spend(at(ms), Class::Priority);
                    sent += 1;
                }
            }
            assert_eq!(sent, expect, "{budget:?}");
            assert!(b.next_ordinary(at(5_000)).is_none(), "no deadline at 0");
            b.set_external(gc(true, 0));
            assert!(
                !b.allows(at(5_000), Class::Priority),
                "never at the GC's zero"
            );
        }
    }

    /// In a state the GC does not count, frames are free: they spend nothing of the share
    /// and go at most one per FREE_GAP; at the GC's zero nothing goes even then (its state
    /// can lag one period behind a counted one).
    #[test]
    fn frames_the_gc_does_not_count_are_free_but_spaced() {
        let budget = BudgetSpec::SPL.share(5).split();
        let mut b = BudgetState::new(budget, at(0));
        b.set_external(gc(false, 1000));
        let mut sent = Vec::new();
        for ms in (0..1_000).step_by(10) {
            if b.allows(at(ms), Class::Ordinary) {
                b.spend(at(ms), Class::Ordinary);
                sent.push(ms);
            }
        }
        assert_eq!(sent, vec![0, 250, 500, 750], "one per FREE_GAP");
        assert_eq!(b.sent(), 0, "nothing counted");
        b.set_external(gc(false, 0));
        assert!(!b.allows(at(2_000), Class::Ordinary));
    }

    /// A pooled robot restarted mid-game (its own counters at 0) with the GC saying the
    /// team is at its line: it does not spend a fresh share at once, it keeps to the
    /// line; with the team 50 under its line it may go.
    #[test]
    fn a_robot_restarted_mid_game_resumes_from_the_gcs_figures() {
        let budget = BudgetSpec::SPL.share(5);
        let mut b = BudgetState::new(budget, at(0));
        // Second half, 300 s left; the line keeps 300 for the rest and the pool's margins.
        b.set_clock(at(0), Duration::from_secs(300));
        b.set_external(gc(true, 300));
        assert!(!b.allows(at(0), Class::Ordinary), "at the line: no burst");
        assert!(b.headroom(at(0)) <= 0, "headroom {}", b.headroom(at(0)));
        b.set_external(gc(true, 350));
        assert!(b.allows(at(0), Class::Ordinary), "50 under the line");
        // Without the GC's figure the fresh robot would have spent at once.
        let mut fresh = BudgetState::new(budget, at(0));
        fresh.set_clock(at(0), Duration::from_secs(300));
        assert!(fresh.allows(at(0), Class::Ordinary));
    }

    /// The deadline `next_ordinary` gives and what `allows` lets go must agree: a
    /// deadline at or before `now` that `allows` refuses is due forever, and a driver
    /// (the daemon, the netsim harness) spins on it. Found as a hang of a whole game at
    /// the GameController's zero in a free state (Set, Finished).
    #[test]
    fn a_due_ordinary_deadline_is_always_allowed() {
        for budget in [BudgetSpec::SPL.share(5), BudgetSpec::SPL.share(5).split()] {
            for cap in [
                None,
                gc(true, 0),
                gc(true, 1),
                gc(true, 500),
                gc(false, 0),
                gc(false, 1),
                gc(false, 500),
            ] {
                let mut b = BudgetState::new(budget, at(0));
                b.set_clock(at(0), Duration::from_secs(600));
                b.set_external(cap);
                for ms in (0..20_000).step_by(50) {
                    let now = at(ms);
                    let due = b.next_ordinary(now).is_some_and(|t| t <= now);
                    assert_eq!(
                        due,
                        b.allows(now, Class::Ordinary),
                        "{budget:?} {cap:?} at {ms} ms: left {}",
                        b.left()
                    );
                    if due {
                        b.spend(now, Class::Ordinary);
                    }
                }
            }
        }
    }

    /// A kick-off: the attack before the goal spent the team's priority room and the
    /// clock stood through Ready and Set, so the team meets the whistle 6 frames beyond
    /// its line and no priority frame may go (the taker's claim waited seconds for one).
    /// After `restart` (the robot heard Set) the team's five priority frames go at once
    /// and a sixth does not; ordinary frames still wait for the line.
    #[test]
    fn a_restart_gives_the_teams_priority_frames_their_room_afresh() {
        let mut b = BudgetState::new(BudgetSpec::SPL.share(5), at(0));
        // Half the game played: the line is at ⌊1,180 · 0.5⌋ + 1 = 591 frames. This robot
        // sent 120 (beyond its own part, so its floor is shut), teammates 477: 597 in all.
        b.set_clock(at(0), Duration::from_secs(600));
        for _ in 0..120 {
            b.spend(at(0), Class::Ordinary);
        }
        b.set_heard(477);
        assert_eq!(b.headroom(at(0)), -6, "6 beyond the line");
        assert!(
            !b.allows(at(0), Class::Priority),
            "no room before the restart"
        );
        b.restart();
        let mut sent = 0;
        for ms in 0..10 {
            if b.allows(at(ms), Class::Priority) {
                b.spend(at(ms), Class::Priority);
                sent += 1;
            }
        }
        assert_eq!(
            sent, 5,
            "one priority frame per robot from the restart's count"
        );
        assert!(
            !b.allows(at(10), Class::Ordinary),
            "ordinary frames keep to the line"
        );
        // Once the line has passed the count again, the room is the line's as ever.
        let later = at(13_000);
        assert_eq!(b.headroom(later), 1, "13 s on, the line is 1 ahead");
        assert!(b.allows(later, Class::Priority));
    }

    #[test]
    fn league_rules_parse_and_share() {
        assert_eq!("spl".parse::<BudgetSpec>(), Ok(BudgetSpec::SPL));
        assert_eq!(" Humanoid ".parse::<BudgetSpec>(), Ok(BudgetSpec::HUMANOID));
        let custom: BudgetSpec = "600/10min".parse().unwrap();
        assert_eq!(
            (custom.team_messages, custom.game, custom.payload_limit),
            (600, Duration::from_secs(600), None)
        );
        // What Display writes reads back as the same budget, the payload limit included
        // (`huddle sim --daemons --budget spl` hands its budget to each daemon so).
        for spec in [
            BudgetSpec::SPL,
            BudgetSpec::HUMANOID,
            custom,
            BudgetSpec {
                payload_limit: Some(96),
                ..custom
            },
        ] {
            let printed = spec.to_string();
            assert_eq!(printed.parse::<BudgetSpec>(), Ok(spec), "{printed:?}");
        }
        assert_eq!(
            "600/10min (<= 64 B)"
                .parse::<BudgetSpec>()
                .map(|b| b.payload_limit),
            Ok(Some(64))
        );
        for bad in [
            "",
            "spl2",
            "600",
            "600/",
            "0/10min",
            "600/10",
            "x/10s",
            "600/-1s",
            "spl (≤ 0 B)",
            "spl (128 B)",
            "spl (≤ 128)",
            "spl (≤ x B)",
            "(≤ 128 B)",
            "spl (≤ 128 B",
            "600/10min (≤ 128 B) x",
        ] {
            assert!(bad.parse::<BudgetSpec>().is_err(), "{bad:?} must not parse");
        }
        let share = BudgetSpec::SPL.share(5);
        assert_eq!(
            (share.messages, share.reserve),
            (240, 48),
            "an SPL robot of five"
        );
    }

    #[test]
    fn ordinary_frames_are_paced_over_the_remaining_game_and_never_exceed_the_budget() {
        // 10 messages over 10 s, 2 reserved: a robot that wants to send every 10 ms.
        let budget = Budget {
            messages: 10,
            game: Duration::from_secs(10),
            reserve: 2,
            team: None,
        };
        let mut b = BudgetState::new(budget, at(0));
        let mut sent_at = Vec::new();
        for ms in (0..=12_000).step_by(10) {
            if b.allows(at(ms), Class::Ordinary) {
                b.spend(at(ms), Class::Ordinary);
                sent_at.push(ms);
            }
        }
        assert_eq!(sent_at.len(), 8, "8 ordinary messages, 2 kept: {sent_at:?}");
        for w in sent_at.windows(2) {
            assert!(w[1] - w[0] >= 1000, "paced: {sent_at:?}");
        }
        assert!(
            *sent_at.last().unwrap() <= 10_000,
            "spent within the game: {sent_at:?}"
        );
        // The reserve is for priority frames, and then nothing more.
        assert!(b.allows(at(12_000), Class::Priority));
        b.spend(at(12_000), Class::Priority);
        b.spend(at(12_001), Class::Priority);
        assert_eq!(b.left(), 0);
        assert!(
            !b.allows(at(12_002), Class::Priority),
            "never beyond the budget"
        );
    }

    #[test]
    fn what_a_quiet_robot_does_not_spend_is_spread_over_the_rest_of_the_game() {
        let budget = Budget {
            messages: 101,
            game: Duration::from_secs(100),
            reserve: 1,
            team: None,
        };
        let mut b = BudgetState::new(budget, at(0));
        // Silent for 50 s, then eager: 100 ordinary messages over the last 50 s.
        let mut n = 0;
        for ms in (50_000..=100_000).step_by(10) {
            if b.allows(at(ms), Class::Ordinary) {
                b.spend(at(ms), Class::Ordinary);
                n += 1;
            }
        }
        assert!(n >= 95, "the unspent half is used later: {n} of 100");
        // The game clock is an input: the GameController says 10 s are left.
        let mut b = BudgetState::new(budget, at(0));
        b.set_clock(at(0), Duration::from_secs(10));
        assert_eq!(b.remaining(at(4_000)), Duration::from_secs(6));
    }
}

#[cfg(test)]
#[path = "budget_replica_tests.rs"]
mod replica_tests;

#[cfg(test)]
#[path = "budget_gc_tests.rs"]
mod gc_tests;
