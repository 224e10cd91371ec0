//! `RoboCupGameControlData` ("RGme", version 18): what the GameController broadcasts to
//! the robots on UDP port 3838 twice a second.
//!
//! Layout (GameController3 `game_controller_msgs/headers/RoboCupGameControlData.h`,
//! little-endian, packed by natural alignment to 118 bytes):
//!
//! ```text
//! 0  header "RGme"      4  version (18)      5  packetNumber    6  playersPerTeam
//! 7  competitionPhase   8  competitionType   9  gamePhase      10  state
//! 11 setPlay           12  firstHalf        13  kickingTeam    14  secsRemaining (i16)
//! 16 secondaryTime (i16)                    18  teams[0]       68  teams[1]
//! TeamInfo (50 B): teamNumber, fieldPlayerColour, goalkeeperColour, goalkeeper, score,
//!   penaltyShot, singleShots (u16), messageBudget (u16), players[20] {penalty, secsTillUnpenalised}
//! ```
//!
//! Parsing is in two steps, as smoltcp does: [`ControlView::new`] checks the length, the
//! header and the version (safe on any bytes), then [`ControlView::to_data`] validates
//! each enumerated field into a [`GameControlData`]. A packet of another version, length
//! or team is an error, never a misread value.

use crate::DecodeError;

/// UDP port the GameController broadcasts `RoboCupGameControlData` to.
pub const GAMECONTROLLER_DATA_PORT: u16 = 3838;
/// The packet's first four bytes.
pub const GAMECONTROLLER_STRUCT_HEADER: [u8; 4] = *b"RGme";
/// The version this crate reads and writes.
pub const GAMECONTROLLER_STRUCT_VERSION: u8 = 18;
/// The packet's exact length, bytes.
pub const GAMECONTROLLER_STRUCT_SIZE: usize = 118;
/// Players per team in the packet (`MAX_NUM_PLAYERS`).
pub const MAX_NUM_PLAYERS: usize = 20;
/// `kickingTeam` when no team kicks.
pub const KICKING_TEAM_NONE: u8 = 255;

const TEAM_OFFSET: usize = 18;
const TEAM_SIZE: usize = 50;

/// The game's state (`STATE_*`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum State {
    /// `STATE_INITIAL` (0); also what a timeout shows.
    Initial,
    /// `STATE_READY` (1).
    Ready,
    /// `STATE_SET` (2).
    Set,
    /// `STATE_PLAYING` (3).
    Playing,
    /// `STATE_FINISHED` (4): a half is over.
    Finished,
    /// `STATE_STANDBY` (5).
    Standby,
}

impl State {
    /// The state's code in the packet.
    pub fn code(self) -> u8 {
        match self {
            State::Initial => 0,
            State::Ready => 1,
            State::Set => 2,
            State::Playing => 3,
            State::Finished => 4,
            State::Standby => 5,
        }
    }

    fn from_code(c: u8) -> Option<State> {
        Some(match c {
            0 => State::Initial,
            1 => State::Ready,
            2 => State::Set,
            3 => State::Playing,
            4 => State::Finished,
            5 => State::Standby,
            _ => return None,
        })
    }

    /// The state's name as the blackboard shows it (`playing`).
    pub fn name(self) -> &'static str {
        match self {
            State::Initial => "initial",
            State::Ready => "ready",
            State::Set => "set",
            State::Playing => "playing",
            State::Finished => "finished",
            State::Standby => "standby",
        }
    }
}

/// The game's phase (`GAME_PHASE_*`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum GamePhase {
    /// `GAME_PHASE_NORMAL` (0): a half.
    Normal,
    /// `GAME_PHASE_PENALTYSHOOT` (1).
    PenaltyShoot,
    /// `GAME_PHASE_OVERTIME` (2): defined by the header, not sent by GameController3.
    Overtime,
    /// `GAME_PHASE_TIMEOUT` (3): a team's or the referee's timeout (the state shows Initial).
    Timeout,
}

impl GamePhase {
    /// The phase's code in the packet.
    pub fn code(self) -> u8 {
        match self {
            GamePhase::Normal => 0,
            GamePhase::PenaltyShoot => 1,
            GamePhase::Overtime => 2,
            GamePhase::Timeout => 3,
        }
    }

    fn from_code(c: u8) -> Option<GamePhase> {
        Some(match c {
            0 => GamePhase::Normal,
            1 => GamePhase::PenaltyShoot,
            2 => GamePhase::Overtime,
            3 => GamePhase::Timeout,
            _ => return None,
        })
    }

    /// The phase's name (`normal`, `penalty_shoot`, `overtime`, `timeout`).
    pub fn name(self) -> &'static str {
        match self {
            GamePhase::Normal => "normal",
            GamePhase::PenaltyShoot => "penalty_shoot",
            GamePhase::Overtime => "overtime",
            GamePhase::Timeout => "timeout",
        }
    }
}

/// The set play in progress (`SET_PLAY_*`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SetPlay {
    /// `SET_PLAY_NONE` (0), also during a kick-off.
    None,
    /// `SET_PLAY_GOAL_KICK` (1).
    GoalKick,
    /// `SET_PLAY_PUSHING_FREE_KICK` (2).
    PushingFreeKick,
    /// `SET_PLAY_CORNER_KICK` (3).
    CornerKick,
    /// `SET_PLAY_KICK_IN` (4).
    KickIn,
    /// `SET_PLAY_PENALTY_KICK` (5).
    PenaltyKick,
}

impl SetPlay {
    /// The set play's code in the packet.
    pub fn code(self) -> u8 {
        match self {
            SetPlay::None => 0,
            SetPlay::GoalKick => 1,
            SetPlay::PushingFreeKick => 2,
            SetPlay::CornerKick => 3,
            SetPlay::KickIn => 4,
            SetPlay::PenaltyKick => 5,
        }
    }

    fn from_code(c: u8) -> Option<SetPlay> {
        Some(match c {
            0 => SetPlay::None,
            1 => SetPlay::GoalKick,
            2 => SetPlay::PushingFreeKick,
            3 => SetPlay::CornerKick,
            4 => SetPlay::KickIn,
            5 => SetPlay::PenaltyKick,
            _ => return None,
        })
    }

    /// The set play's name as the blackboard shows it (`corner_kick`).
    pub fn name(self) -> &'static str {
        match self {
            SetPlay::None => "none",
            SetPlay::GoalKick => "goal_kick",
            SetPlay::PushingFreeKick => "pushing_free_kick",
            SetPlay::CornerKick => "corner_kick",
            SetPlay::KickIn => "kick_in",
            SetPlay::PenaltyKick => "penalty_kick",
        }
    }
}

/// `PENALTY_NONE`: the robot plays.
pub const PENALTY_NONE: u8 = 0;
/// `PENALTY_SUBSTITUTE`: the robot is a substitute, not on the field.
pub const PENALTY_SUBSTITUTE: u8 = 14;

/// One player's entry (`RobotInfo`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct RobotInfo {
    /// `PENALTY_*` code (0: none, 14: substitute; the SPL's in between). Kept as the
    /// number: new penalty codes must not make a packet unreadable.
    pub penalty: u8,
    /// The GC's estimate of the seconds till the penalty ends.
    pub secs_till_unpenalised: u8,
}

/// One team's block (`TeamInfo`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TeamInfo {
    /// The team's number.
    pub team_number: u8,
    /// `TEAM_*` colour of the field players.
    pub field_player_colour: u8,
    /// `TEAM_*` colour of the goalkeeper.
    pub goalkeeper_colour: u8,
    /// The goalkeeper's player number (1–20).
    pub goalkeeper: u8,
    /// The team's score.
    pub score: u8,
    /// Penalty shot counter, or fallback mode flag outside the shoot-out.
    pub penalty_shot: u8,
    /// Bits of penalty shot success.
    pub single_shots: u16,
    /// Team messages the team may still send this game: the authority on the budget.
    pub message_budget: u16,
    /// The players, player number `n` at index `n - 1`.
    pub players: [RobotInfo; MAX_NUM_PLAYERS],
}

impl TeamInfo {
    /// A team with no score, no penalties and `message_budget` left (for simulators).
    pub fn new(team_number: u8, message_budget: u16) -> TeamInfo {
        TeamInfo {
            team_number,
            field_player_colour: 0,
            goalkeeper_colour: 0,
            goalkeeper: 1,
            score: 0,
            penalty_shot: 0,
            single_shots: 0,
            message_budget,
            players: [RobotInfo::default(); MAX_NUM_PLAYERS],
        }
    }

    /// Player `number`'s entry (1–20), `None` outside that range.
    pub fn player(&self, number: u8) -> Option<&RobotInfo> {
        self.players.get(usize::from(number).checked_sub(1)?)
    }
}

/// A whole `RoboCupGameControlData` packet, validated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct GameControlData {
    /// Incremented with each packet sent, wrapping.
    pub packet_number: u8,
    /// Players per team.
    pub players_per_team: u8,
    /// `COMPETITION_PHASE_*` (0 round robin, 1 play-off).
    pub competition_phase: u8,
    /// `COMPETITION_TYPE_*` (0 normal, 1 most passes).
    pub competition_type: u8,
    /// The game's phase.
    pub game_phase: GamePhase,
    /// The game's state as the GC shows it (it can lag the true state: see the crate docs).
    pub state: State,
    /// The set play in progress.
    pub set_play: SetPlay,
    /// Whether the game is in its first half.
    pub first_half: bool,
    /// The team number of the team to kick, or [`KICKING_TEAM_NONE`].
    pub kicking_team: u8,
    /// Seconds left in the half (negative once over time).
    pub secs_remaining: i16,
    /// Seconds of the secondary clock (ready, free ball, break, penalty...).
    pub secondary_time: i16,
    /// The two teams.
    pub teams: [TeamInfo; 2],
}

impl GameControlData {
    /// A packet of the first half's Initial state between `teams` with SPL defaults
    /// (1,200 messages each, 600 s on the clock): a start for a simulated GC.
    pub fn new(teams: [u8; 2]) -> GameControlData {
        GameControlData {
            packet_number: 0,
            players_per_team: 5,
            competition_phase: 0,
            competition_type: 0,
            game_phase: GamePhase::Normal,
            state: State::Initial,
            set_play: SetPlay::None,
            first_half: true,
            kicking_team: teams[0],
            secs_remaining: 600,
            secondary_time: 0,
            teams: [TeamInfo::new(teams[0], 1200), TeamInfo::new(teams[1], 1200)],
        }
    }

    /// Reads an untrusted datagram: [`ControlView::new`], then [`ControlView::to_data`].
    pub fn decode(bytes: &[u8]) -> Result<GameControlData, DecodeError> {
        ControlView::new(bytes)?.to_data()
    }

    /// [`GameControlData::decode`], and the packet must name `team` as one of its teams.
    pub fn decode_for_team(bytes: &[u8], team: u8) -> Result<GameControlData, DecodeError> {
        let data = Self::decode(bytes)?;
        if data.team(team).is_none() {
            return Err(DecodeError::WrongTeam {
                teams: [data.teams[0].team_number, data.teams[1].team_number],
            });
        }
        Ok(data)
    }

    /// Team `number`'s block, if the packet has it.
    pub fn team(&self, number: u8) -> Option<&TeamInfo> {
        self.teams.iter().find(|t| t.team_number == number)
    }

    /// Team `number`'s block, mutable (for a simulated GC).
    pub fn team_mut(&mut self, number: u8) -> Option<&mut TeamInfo> {
        self.teams.iter_mut().find(|t| t.team_number == number)
    }

    /// Whether the GC counts a team message sent now: GameController3's
    /// `TeamMessage::is_legal` counts it when the game is not in the penalty shoot-out and
    /// the state is Standby, Ready, Set or Playing (a timeout shows Initial, the half-time
    /// break Finished or Initial: not counted).
    pub fn messages_counted(&self) -> bool {
        self.game_phase != GamePhase::PenaltyShoot
            && matches!(
                self.state,
                State::Standby | State::Ready | State::Set | State::Playing
            )
    }

    /// The packet's 118 bytes.
    pub fn encode(&self) -> [u8; GAMECONTROLLER_STRUCT_SIZE] {
        let mut b = [0u8; GAMECONTROLLER_STRUCT_SIZE];
        b[0..4].copy_from_slice(&GAMECONTROLLER_STRUCT_HEADER);
        b[4] = GAMECONTROLLER_STRUCT_VERSION;
        b[5] = self.packet_number;
        b[6] = self.players_per_team;
        b[7] = self.competition_phase;
        b[8] = self.competition_type;
        b[9] = self.game_phase.code();
        b[10] = self.state.code();
        b[11] = self.set_play.code();
        b[12] = u8::from(self.first_half);
        b[13] = self.kicking_team;
        b[14..16].copy_from_slice(&self.secs_remaining.to_le_bytes());
        b[16..18].copy_from_slice(&self.secondary_time.to_le_bytes());
        for (i, t) in self.teams.iter().enumerate() {
            let o = TEAM_OFFSET + i * TEAM_SIZE;
            b[o] = t.team_number;
            b[o + 1] = t.field_player_colour;
            b[o + 2] = t.goalkeeper_colour;
            b[o + 3] = t.goalkeeper;
            b[o + 4] = t.score;
            b[o + 5] = t.penalty_shot;
            b[o + 6..o + 8].copy_from_slice(&t.single_shots.to_le_bytes());
            b[o + 8..o + 10].copy_from_slice(&t.message_budget.to_le_bytes());
            for (p, r) in t.players.iter().enumerate() {
                b[o + 10 + 2 * p] = r.penalty;
                b[o + 11 + 2 * p] = r.secs_till_unpenalised;
            }
        }
        b
    }
}

/// A checked view over an RGme packet: exactly 118 bytes, the header "RGme", version 18.
/// Safe on any input; the fields' values are checked by [`ControlView::to_data`].
#[derive(Debug, Clone, Copy)]
pub struct ControlView<'a> {
    bytes: &'a [u8; GAMECONTROLLER_STRUCT_SIZE],
}

impl<'a> ControlView<'a> {
    /// Checks the length, the header and the version.
    pub fn new(bytes: &'a [u8]) -> Result<ControlView<'a>, DecodeError> {
        if bytes.len() >= 4 && bytes[0..4] != GAMECONTROLLER_STRUCT_HEADER {
            return Err(DecodeError::BadHeader);
        }
        if bytes.len() >= 5 && bytes[4] != GAMECONTROLLER_STRUCT_VERSION {
            return Err(DecodeError::WrongVersion(bytes[4]));
        }
        let bytes: &[u8; GAMECONTROLLER_STRUCT_SIZE] =
            bytes.try_into().map_err(|_| DecodeError::Length {
                len: bytes.len(),
                expected: GAMECONTROLLER_STRUCT_SIZE,
            })?;
        Ok(ControlView { bytes })
    }

    /// The packet number, without validating the rest.
    pub fn packet_number(&self) -> u8 {
        self.bytes[5]
    }

    /// Validates the enumerated fields and returns the packet's value.
    pub fn to_data(&self) -> Result<GameControlData, DecodeError> {
        let b = self.bytes;
        let bad = |field: &'static str, value: u8| DecodeError::BadField { field, value };
        let game_phase = GamePhase::from_code(b[9]).ok_or(bad("gamePhase", b[9]))?;
        let state = State::from_code(b[10]).ok_or(bad("state", b[10]))?;
        let set_play = SetPlay::from_code(b[11]).ok_or(bad("setPlay", b[11]))?;
        let first_half = match b[12] {
            0 => false,
            1 => true,
            v => return Err(bad("firstHalf", v)),
        };
        let u16_at = |o: usize| u16::from_le_bytes([b[o], b[o + 1]]);
        let team = |i: usize| {
            let o = TEAM_OFFSET + i * TEAM_SIZE;
            let mut players = [RobotInfo::default(); MAX_NUM_PLAYERS];
            for (p, r) in players.iter_mut().enumerate() {
                *r = RobotInfo {
                    penalty: b[o + 10 + 2 * p],
                    secs_till_unpenalised: b[o + 11 + 2 * p],
                };
            }
            TeamInfo {
                team_number: b[o],
                field_player_colour: b[o + 1],
                goalkeeper_colour: b[o + 2],
                goalkeeper: b[o + 3],
                score: b[o + 4],
                penalty_shot: b[o + 5],
                single_shots: u16_at(o + 6),
                message_budget: u16_at(o + 8),
                players,
            }
        };
        Ok(GameControlData {
            packet_number: b[5],
            players_per_team: b[6],
            competition_phase: b[7],
            competition_type: b[8],
            game_phase,
            state,
            set_play,
            first_half,
            kicking_team: b[13],
            secs_remaining: u16_at(14) as i16,
            secondary_time: u16_at(16) as i16,
            teams: [team(0), team(1)],
        })
    }
}
