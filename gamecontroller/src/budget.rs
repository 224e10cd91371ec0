//! [`GcBudget`]: pacing a team's messages by the GameController's own figures.
//!
//! The GC is the authority on the budget: its `messageBudget` is what the team may still
//! send, and one message sent at 0 makes the team illegal (its score is set to 0 and every
//! later goal is void). So the pacing is a pure function of the GC's newest figures and of
//! what the team sent since them:
//!
//! - the clock is the GC's: `secsRemaining` of this half plus a whole second half while
//!   in the first (the break and timeouts do not run it down);
//! - only the states the GC counts spend messages ([`GameControlData::messages_counted`]);
//!   in the others a frame is free;
//! - the team keeps [`GcBudget::margin`] short of the GC's figure: the GC tells its count
//!   only twice a second, and teammates' frames sent since may not have been heard yet;
//! - ordinary frames keep to a line that leaves `ceil(rate · time left)` messages for the
//!   rest of the game, and [`GcBudget::reserve`] more for priority frames, which may go
//!   down to the line less one frame per robot, and never below the margin;
//! - extra time needs nothing special: the GC adds 60 messages per extra minute to
//!   `messageBudget` and the minute to the clock, the same rate the line keeps;
//! - a robot restarted mid-game knows as much as one that ran all along: all it needs is
//!   the GC's next packet.

use std::time::Duration;

use crate::control::{GameControlData, GamePhase, State};

/// The team's league budget and how much of it is kept back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GcBudget {
    /// Robots in the team (each may send while it has not heard the others).
    pub robots: u8,
    /// One half's length (SPL: 600 s).
    pub half: Duration,
    /// Messages per team per game (SPL: 1,200, GameController3 `messagesPerTeam`).
    pub messages_per_game: u32,
    /// Messages kept short of the GC's figure.
    pub margin: u32,
    /// Messages ordinary frames leave to priority frames.
    pub reserve: u32,
}

/// What the GC's newest packet says about the budget, for one team.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GcCap {
    /// Whether a message sent now is counted.
    pub counted: bool,
    /// Messages the team may still send: the GC's `messageBudget` less the margin.
    pub team_left: u32,
    /// The GC's `messageBudget` as it said it.
    pub message_budget: u16,
    /// Game time left over the halves, as of the packet.
    pub game_remaining: Duration,
    /// Whether the game clock runs (Playing): otherwise the time left stands still.
    pub clock_running: bool,
}

/// Which allowance a frame draws on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MessageClass {
    /// Ordinary news: paced along the line.
    Ordinary,
    /// A goer change, a kick, a referee event: may go ahead of the line.
    Priority,
}

/// Whether a frame may go now.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// The GC does not count messages now: the frame costs nothing.
    Free,
    /// The frame may go and will be counted.
    Send,
    /// The pacing holds it back for now.
    Wait,
    /// Nothing may go until the GC's figure grows (extra time): the team is at its margin.
    Exhausted,
}

impl Decision {
    /// Whether the frame may go.
    pub fn may_send(self) -> bool {
        matches!(self, Decision::Free | Decision::Send)
    }
}

impl GcBudget {
    /// The SPL's rule for a team of `robots`: 1,200 messages over two 10-minute halves.
    /// The margin is two frames per robot and four more (what a team paced at about one
    /// message a second can send in one GC period, twice over, plus frames in flight);
    /// the reserve two per robot.
    pub fn spl(robots: u8) -> GcBudget {
        let robots = robots.max(1);
        GcBudget {
            robots,
            half: Duration::from_secs(600),
            messages_per_game: 1200,
            margin: 2 * u32::from(robots) + 4,
            reserve: 2 * u32::from(robots),
        }
    }

    /// Messages per second of game time the line allows.
    pub fn rate_per_s(&self) -> f64 {
        let game = 2.0 * self.half.as_secs_f64();
        if game <= 0.0 {
            return 0.0;
        }
        f64::from(self.messages_per_game) / game
    }

    /// Game time left over the halves in `game`: this half's `secsRemaining` (none once
    /// over time) and a whole half more in the first. The shoot-out has none.
    pub fn game_remaining(&self, game: &GameControlData) -> Duration {
        if game.game_phase == GamePhase::PenaltyShoot {
            return Duration::ZERO;
        }
        let this_half = Duration::from_secs(game.secs_remaining.max(0) as u64);
        if game.first_half {
            this_half + self.half
        } else {
            this_half
        }
    }

    /// The budget as `game` states it for team `team` (`None`: not this team's game).
    pub fn cap(&self, game: &GameControlData, team: u8) -> Option<GcCap> {
        let t = game.team(team)?;
        Some(GcCap {
            counted: game.messages_counted(),
            team_left: u32::from(t.message_budget).saturating_sub(self.margin),
            message_budget: t.message_budget,
            game_remaining: self.game_remaining(game),
            clock_running: game.state == State::Playing
                && game.game_phase != GamePhase::PenaltyShoot,
        })
    }

    /// Messages the line keeps for the game left after `elapsed` since `cap`'s packet.
    pub fn line(&self, cap: &GcCap, elapsed: Duration) -> u32 {
        let left = if cap.clock_running {
            cap.game_remaining.saturating_sub(elapsed)
        } else {
            cap.game_remaining
        };
        (self.rate_per_s() * left.as_secs_f64())
            .ceil()
            .min(f64::from(u32::MAX)) as u32
    }

    /// May a frame of `class` go, `elapsed` after `cap`'s packet arrived, when the team
    /// has sent `spent_since` frames since (this robot's and the teammates' heard)?
    pub fn decide(
        &self,
        cap: &GcCap,
        spent_since: u32,
        elapsed: Duration,
        class: MessageClass,
    ) -> Decision {
        if !cap.counted {
            return Decision::Free;
        }
        let left = cap.team_left.saturating_sub(spent_since);
        if left == 0 {
            return Decision::Exhausted;
        }
        let line = self.line(cap, elapsed);
        let go = match class {
            MessageClass::Ordinary => left > line.saturating_add(self.reserve),
            MessageClass::Priority => left + u32::from(self.robots) > line,
        };
        if go {
            Decision::Send
        } else {
            Decision::Wait
        }
    }
}
