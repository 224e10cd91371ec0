//! A replica's settings, and why a set of them is refused.

use std::time::Duration;

use thiserror::Error;

use crate::blackboard::BoardLimits;
use crate::key::ROBOT_IDS;
use crate::talk::TalkLimits;
use crate::wire::{KnownPaths, MAX_FRAME_LEN, MIN_MTU};

/// Settings of a replica. Every robot of a team should use the same `team_id`,
/// `refresh_period`, `mtu` and `team_key`.
#[derive(Clone, Debug, PartialEq)]
pub struct ReplicaConfig {
    /// This robot's id, 1..=254.
    pub robot_id: u8,
    /// The team's id; frames of other teams are dropped.
    pub team_id: u8,
    /// Every own global value is re-sent this often (default 100 ms), repairing losses;
    /// it is also the heartbeat period.
    pub refresh_period: Duration,
    /// Largest frame sent and accepted, in bytes (default 1200; 64..=65507).
    pub mtu: usize,
    /// A peer silent this long is reported departed (default 3 refresh periods).
    pub departed_after: Duration,
    /// With a key, every frame carries a truncated HMAC-SHA256 tag, untagged, badly
    /// tagged and replayed frames are dropped.
    pub team_key: Option<Vec<u8>>,
    /// Talk queue limits and timers.
    pub talk: TalkLimits,
    /// Most bindings stored per robot (default 4096): each teammate's copies, and this
    /// robot's own global values (teammates would refuse more). An update for a new key
    /// beyond it is refused and counted (`updates_refused`).
    pub max_bindings_per_owner: usize,
    /// Most bindings of all teammates together (default 65536).
    pub max_remote_bindings: usize,
    /// Most `local` bindings (default 65536); a write of a new one beyond it is
    /// refused ([`SetError::TooManyKeys`](crate::SetError::TooManyKeys)).
    pub max_local_bindings: usize,
    /// A departed robot's values stay readable (the relay marks them `departed`) this
    /// long after its departure, then they are released (default 60 s).
    pub release_departed_after: Duration,
    /// A message budget ([`crate::Budget`]): frames are counted and paced, the
    /// periodic refresh only fills frames that go anyway, and no frame goes beyond it.
    /// `None` (the default): no limit. A league's payload limit is the `mtu`.
    pub budget: Option<super::Budget>,
    /// Estimate each teammate's clock from the stamps and echoes in its frames and add
    /// each frame's own transit to the ages of its values (default on). Off: every frame
    /// is taken to have travelled `default_transit` (ages leave the transit out, as
    /// before version 3 of the wire format, when that is zero).
    pub clock_sync: bool,
    /// The transit assumed for a frame from a teammate whose clock is not estimated yet
    /// (its first round trip), or with `clock_sync` off (default 0: until the first echo,
    /// ages leave the transit out).
    pub default_transit: Duration,
    /// Paths sent as a one-byte index instead of as text (item 4 of the wire format): the
    /// application's table, the same on every robot of the team (huddle's team layer
    /// registers its own, `team::known_paths()`). Default: empty.
    pub known_paths: KnownPaths,
    /// Frames go out in format 3 ([`crate::wire::LEGACY_VERSION`]) while a present teammate's last
    /// frame was in format 3: an older build that cannot read format 4 keeps hearing this
    /// robot during a rolling upgrade (default on). Off: always format 4.
    pub legacy_fallback: bool,
}

impl ReplicaConfig {
    /// Defaults for robot `robot_id` of team `team_id`.
    pub fn new(robot_id: u8, team_id: u8) -> ReplicaConfig {
        ReplicaConfig {
            robot_id,
            team_id,
            refresh_period: Duration::from_millis(100),
            mtu: 1200,
            departed_after: Duration::from_millis(300),
            team_key: None,
            talk: TalkLimits::default(),
            max_bindings_per_owner: 4096,
            max_remote_bindings: 65536,
            max_local_bindings: 65536,
            release_departed_after: Duration::from_secs(60),
            budget: None,
            clock_sync: true,
            default_transit: Duration::ZERO,
            known_paths: KnownPaths::EMPTY,
            legacy_fallback: true,
        }
    }

    /// Sets the refresh period and, with it, `departed_after` to three periods.
    pub fn with_refresh_period(mut self, period: Duration) -> ReplicaConfig {
        self.refresh_period = period;
        self.departed_after = period * 3;
        self
    }

    /// Spends `robots`' equal share of the league's `spec`: the budget, frames within the
    /// league's payload (the MTU lowered to it), and a teammate taken for departed only
    /// after three of its message intervals (plus 10 s), not three refresh periods:
    /// under a budget silence is the norm.
    pub fn with_budget(mut self, spec: &super::BudgetSpec, robots: usize) -> ReplicaConfig {
        let share = spec.share(robots);
        if let Some(limit) = spec.payload_limit {
            self.mtu = self.mtu.min(limit);
        }
        self.departed_after = self
            .departed_after
            .max(share.interval() * 3 + Duration::from_secs(10));
        self.budget = Some(share);
        self
    }

    /// Sets the table of paths sent as an index (see [`ReplicaConfig::known_paths`]).
    pub fn with_known_paths(mut self, known: KnownPaths) -> ReplicaConfig {
        self.known_paths = known;
        self
    }

    /// Sets the team key.
    pub fn with_team_key(mut self, key: impl Into<Vec<u8>>) -> ReplicaConfig {
        self.team_key = Some(key.into());
        self
    }

    /// The blackboard bounds these settings give.
    pub(super) fn board_limits(&self) -> BoardLimits {
        BoardLimits {
            per_owner: self.max_bindings_per_owner,
            remote: self.max_remote_bindings,
            local: self.max_local_bindings,
            unconfirmed_after: self.departed_after,
        }
    }

    /// Whether a replica can work with these settings.
    pub(super) fn validate(&self) -> Result<(), ConfigInvalid> {
        if !ROBOT_IDS.contains(&self.robot_id) {
            return Err(ConfigInvalid::RobotId(self.robot_id));
        }
        if !(MIN_MTU..=MAX_FRAME_LEN).contains(&self.mtu) {
            return Err(ConfigInvalid::Mtu(self.mtu));
        }
        if self.refresh_period.is_zero() || self.departed_after.is_zero() {
            return Err(ConfigInvalid::Period);
        }
        if self.default_transit > super::clock::MAX_TRANSIT {
            return Err(ConfigInvalid::DefaultTransit(self.default_transit));
        }
        let t = &self.talk;
        if t.retain == 0 || t.window == 0 || t.max_queues == 0 {
            return Err(ConfigInvalid::TalkLimits);
        }
        Ok(())
    }
}

/// Why a [`ReplicaConfig`] was refused.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum ConfigInvalid {
    /// `robot_id` outside 1..=254.
    #[error("robot id {0} is outside 1..=254")]
    RobotId(u8),
    /// `mtu` outside [`wire::MIN_MTU`](MIN_MTU)..=[`wire::MAX_FRAME_LEN`](MAX_FRAME_LEN).
    #[error("mtu {0} is outside {MIN_MTU}..={MAX_FRAME_LEN} bytes")]
    Mtu(usize),
    /// A zero refresh period or departure limit.
    #[error("refresh period and departure limit must be positive")]
    Period,
    /// A default transit beyond the largest believed (1 s).
    #[error("default transit {0:?} is over a second")]
    DefaultTransit(Duration),
    /// Talk limits of zero.
    #[error("talk retain, window and max_queues must be at least 1")]
    TalkLimits,
}
