//! [`GameTracker`]: the game as this robot last heard it from the GameController.
//!
//! Packets can arrive late, twice or out of order (a WLAN retries unicast but not
//! broadcast; two access points may both forward one). The tracker keeps the newest by
//! `packetNumber`, a u8 that wraps: a packet up to 127 ahead of the last one accepted is
//! newer, anything else (the same number, or up to 128 behind) is stale and ignored, so
//! the game state never moves backwards. A GC that restarts numbers from 0, or one not
//! heard for [`GameTracker::RESYNC_AFTER`], is taken afresh.

use std::net::SocketAddr;
use std::time::Duration;

use crate::control::{GameControlData, GamePhase, RobotInfo, SetPlay, State, TeamInfo};
use crate::DecodeError;

/// Counts of what the tracker received.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TrackerStats {
    /// Packets taken as the newest.
    pub accepted: u64,
    /// Valid packets ignored: a packet number already seen or older than the newest.
    pub stale: u64,
    /// Packets of the wrong length (truncated or oversized).
    pub bad_length: u64,
    /// Packets not starting with "RGme".
    pub bad_header: u64,
    /// Packets of another version than 18.
    pub wrong_version: u64,
    /// Packets with a state, phase, set play or half flag out of range.
    pub bad_field: u64,
    /// Packets of a game this team does not play in.
    pub wrong_team: u64,
}

impl TrackerStats {
    /// Packets dropped as bad (not counting stale ones).
    pub fn bad(&self) -> u64 {
        self.bad_length + self.bad_header + self.wrong_version + self.bad_field + self.wrong_team
    }
}

/// What became of a valid packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Received {
    /// The newest packet: the tracker shows it now.
    Accepted,
    /// Older than (or the same as) the newest: ignored.
    Stale,
}

/// The newest packet and where and when it came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Heard {
    /// The packet.
    pub data: GameControlData,
    /// The GameController's address (send status packets to its IP, port 3939).
    pub from: SocketAddr,
    /// When it was received, on the caller's clock.
    pub at: Duration,
}

/// The game as the GameController last told it, for one robot of one team.
#[derive(Debug, Clone)]
pub struct GameTracker {
    team: u8,
    player: u8,
    latest: Option<Heard>,
    stats: TrackerStats,
}

impl GameTracker {
    /// A packet heard after this long without one starts afresh whatever its number (the
    /// GC sends every 500 ms: this is four missed in a row, or a restarted GC).
    pub const RESYNC_AFTER: Duration = Duration::from_secs(2);

    /// A tracker for player `player` (1–20) of team `team`.
    pub fn new(team: u8, player: u8) -> GameTracker {
        GameTracker {
            team,
            player,
            latest: None,
            stats: TrackerStats::default(),
        }
    }

    /// This tracker's team number.
    pub fn team_number(&self) -> u8 {
        self.team
    }

    /// This tracker's player number.
    pub fn player_number(&self) -> u8 {
        self.player
    }

    /// Takes an untrusted datagram received at `now` from `from`. An error says why it
    /// was dropped (and is counted in [`GameTracker::stats`]); nothing already held
    /// changes then.
    pub fn receive(
        &mut self,
        now: Duration,
        from: SocketAddr,
        bytes: &[u8],
    ) -> Result<Received, DecodeError> {
        match GameControlData::decode_for_team(bytes, self.team) {
            Ok(data) => Ok(self.accept(now, from, data)),
            Err(e) => {
                let s = &mut self.stats;
                match e {
                    DecodeError::Length { .. } => s.bad_length += 1,
                    DecodeError::BadHeader => s.bad_header += 1,
                    DecodeError::WrongVersion(_) => s.wrong_version += 1,
                    DecodeError::BadField { .. } | DecodeError::NotANumber => s.bad_field += 1,
                    DecodeError::WrongTeam { .. } => s.wrong_team += 1,
                }
                Err(e)
            }
        }
    }

    /// Takes a packet already decoded (a simulated GC hands its value straight in).
    /// A packet of another game is counted as wrong team and ignored.
    pub fn accept(&mut self, now: Duration, from: SocketAddr, data: GameControlData) -> Received {
        if data.team(self.team).is_none() {
            self.stats.wrong_team += 1;
            return Received::Stale;
        }
        if let Some(last) = &self.latest {
            let silent = now.saturating_sub(last.at) >= Self::RESYNC_AFTER;
            let ahead = data.packet_number.wrapping_sub(last.data.packet_number);
            // A restarted GC numbers from 0 again; a packet a few behind the newest is
            // reordered, not a restart, so only a 0 more than 16 behind counts as one.
            let restarted = data.packet_number == 0 && (128..=239).contains(&ahead);
            if !silent && !restarted && !(1..=127).contains(&ahead) {
                self.stats.stale += 1;
                return Received::Stale;
            }
        }
        self.stats.accepted += 1;
        self.latest = Some(Heard {
            data,
            from,
            at: now,
        });
        Received::Accepted
    }

    /// Counts of what was received.
    pub fn stats(&self) -> TrackerStats {
        self.stats
    }

    /// The newest packet, if any was heard.
    pub fn latest(&self) -> Option<&Heard> {
        self.latest.as_ref()
    }

    /// The newest packet's game, if any was heard.
    pub fn game(&self) -> Option<&GameControlData> {
        self.latest.as_ref().map(|h| &h.data)
    }

    /// Whether a packet was heard within `within` of `now`.
    pub fn is_live(&self, now: Duration, within: Duration) -> bool {
        self.latest
            .as_ref()
            .is_some_and(|h| now.saturating_sub(h.at) <= within)
    }

    /// The GameController's address (its IP with the status port, 3939).
    pub fn gc_address(&self) -> Option<SocketAddr> {
        self.latest.as_ref().map(|h| {
            let mut a = h.from;
            a.set_port(crate::GAMECONTROLLER_RETURN_PORT);
            a
        })
    }

    /// The game's state.
    pub fn state(&self) -> Option<State> {
        self.game().map(|g| g.state)
    }

    /// The game's phase.
    pub fn game_phase(&self) -> Option<GamePhase> {
        self.game().map(|g| g.game_phase)
    }

    /// The set play in progress.
    pub fn set_play(&self) -> Option<SetPlay> {
        self.game().map(|g| g.set_play)
    }

    /// The kicking team's number (255: none).
    pub fn kicking_team(&self) -> Option<u8> {
        self.game().map(|g| g.kicking_team)
    }

    /// Whether this team kicks next (kick-off, free kick...).
    pub fn we_kick(&self) -> Option<bool> {
        self.kicking_team().map(|k| k == self.team)
    }

    /// Whether the game is in its first half.
    pub fn first_half(&self) -> Option<bool> {
        self.game().map(|g| g.first_half)
    }

    /// Seconds left in the half, as of the newest packet.
    pub fn secs_remaining(&self) -> Option<i16> {
        self.game().map(|g| g.secs_remaining)
    }

    /// The secondary clock, as of the newest packet.
    pub fn secondary_time(&self) -> Option<i16> {
        self.game().map(|g| g.secondary_time)
    }

    /// This team's block.
    pub fn own_team(&self) -> Option<&TeamInfo> {
        self.game().and_then(|g| g.team(self.team))
    }

    /// The other team's block.
    pub fn opponent(&self) -> Option<&TeamInfo> {
        self.game()
            .and_then(|g| g.teams.iter().find(|t| t.team_number != self.team))
    }

    /// This team's score.
    pub fn score(&self) -> Option<u8> {
        self.own_team().map(|t| t.score)
    }

    /// Messages the GC says this team may still send.
    pub fn message_budget(&self) -> Option<u16> {
        self.own_team().map(|t| t.message_budget)
    }

    /// Player `number`'s entry in this team.
    pub fn robot(&self, number: u8) -> Option<RobotInfo> {
        self.own_team().and_then(|t| t.player(number)).copied()
    }

    /// This robot's penalty code (0: none).
    pub fn own_penalty(&self) -> Option<u8> {
        self.robot(self.player).map(|r| r.penalty)
    }

    /// Seconds till this robot's penalty ends.
    pub fn own_secs_till_unpenalised(&self) -> Option<u8> {
        self.robot(self.player).map(|r| r.secs_till_unpenalised)
    }

    /// Whether this robot is penalized (substitutes count as penalized: they are not on
    /// the field).
    pub fn penalized(&self) -> Option<bool> {
        self.own_penalty().map(|p| p != crate::PENALTY_NONE)
    }

    /// Whether the GC counts a message sent now (see [`GameControlData::messages_counted`]).
    pub fn messages_counted(&self) -> Option<bool> {
        self.game().map(GameControlData::messages_counted)
    }
}
