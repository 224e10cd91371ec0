//! [`GcBudget`]: the team's budget as the GameController's own figures state it.
//!
//! The GC is the authority on the budget: its `messageBudget` is what the team may still
//! send, and one message sent at 0 makes the team illegal (its score is set to 0 and every
//! later goal is void). This module reads those figures; the pacing itself is `comms`'
//! (`ExternalCap`, fed by the daemon's and the simulator's GC listeners with
//! `driver::budget_figures`, which draws on [`GcBudget::cap`]):
//!
//! - the clock is the GC's: `secsRemaining` of this half plus a whole second half while
//!   in the first (the break and timeouts do not run it down);
//! - only the states the GC counts spend messages ([`GameControlData::messages_counted`]);
//! - the team keeps [`GcBudget::margin`] short of the GC's figure: the GC tells its count
//!   only twice a second, and teammates' frames sent since may not have been heard yet;
//! - extra time needs nothing special: the GC adds 60 messages per extra minute to
//!   `messageBudget` and the minute to the clock;
//! - a robot restarted mid-game knows as much as one that ran all along: all it needs is
//!   the GC's next packet.
//!
//! The scenarios (a greedy team never illegal, a restarted robot, extra time) are tested
//! where the pacing runs: `comms/src/replica/budget_gc_tests.rs`.

use std::time::Duration;

use crate::control::{GameControlData, GamePhase};

/// The team's league budget and how much of it is kept back.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GcBudget {
    /// Robots in the team (the margin is drawn for them).
    pub robots: u8,
    /// One half's length (SPL: 600 s).
    pub half: Duration,
    /// Messages per team per game (SPL: 1,200, GameController3 `messagesPerTeam`).
    pub messages_per_game: u32,
    /// Messages kept short of the GC's figure.
    pub margin: u32,
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
}

impl GcBudget {
    /// The SPL's rule for a team of `robots`: 1,200 messages over two 10-minute halves.
    /// The margin is two frames per robot and four more (what a team paced at about one
    /// message a second can send in one GC period, twice over, plus frames in flight).
    pub fn spl(robots: u8) -> GcBudget {
        let robots = robots.max(1);
        GcBudget {
            robots,
            half: Duration::from_secs(600),
            messages_per_game: 1200,
            margin: 2 * u32::from(robots) + 4,
        }
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
        })
    }
}
