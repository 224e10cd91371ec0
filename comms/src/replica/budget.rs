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
//! Priority items ([`crate::Replica::set_priority`]: a goer change, a kick, a referee
//! event) may go at once while the reserve lasts. The game clock is an input: by default
//! the game starts when the replica does; [`crate::Replica::set_game_clock`] sets the
//! remaining time (the GameController's `secsRemaining`, when there is one).

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

    /// One robot's share in a team of `robots`: an equal part of the messages, a tenth
    /// of it (at least one) kept for priority items.
    pub fn share(&self, robots: usize) -> Budget {
        let messages = self.team_messages / robots.max(1) as u64;
        Budget {
            messages,
            game: self.game,
            reserve: (messages / 10).max(1).min(messages),
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

    /// `spl`, `humanoid`, or `N/DURATION` (`600/10min`, `100/60s`).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = || BudgetParseError(s.to_string());
        let t = s.trim();
        if t.eq_ignore_ascii_case("spl") {
            return Ok(BudgetSpec::SPL);
        }
        if t.eq_ignore_ascii_case("humanoid") {
            return Ok(BudgetSpec::HUMANOID);
        }
        let (n, d) = t.split_once('/').ok_or_else(err)?;
        let team_messages: u64 = n.trim().parse().map_err(|_| err())?;
        let d = d.trim();
        let split = d
            .find(|c: char| !(c.is_ascii_digit() || c == '.'))
            .ok_or_else(err)?;
        let (num, unit) = d.split_at(split);
        let num: f64 = num.parse().map_err(|_| err())?;
        let secs = match unit {
            "ms" => num / 1000.0,
            "s" => num,
            "min" => num * 60.0,
            "h" => num * 3600.0,
            _ => return Err(err()),
        };
        if team_messages == 0 || !(secs.is_finite() && secs > 0.0 && secs < 1e9) {
            return Err(err());
        }
        Ok(BudgetSpec {
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
    /// Of them, kept for frames with priority items.
    pub reserve: u64,
}

impl Budget {
    /// The time between two messages when they are spread evenly over the game.
    pub fn interval(&self) -> Duration {
        self.game / u32::try_from(self.messages.max(1)).unwrap_or(u32::MAX)
    }
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
}

impl BudgetState {
    pub(crate) fn new(budget: Budget, start: Instant) -> Self {
        BudgetState {
            budget,
            clock: (start, budget.game),
            sent: 0,
            sent_ordinary: 0,
            sent_reserve: 0,
            last_ordinary: None,
        }
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

    /// Messages left in all.
    pub(crate) fn left(&self) -> u64 {
        self.budget.messages.saturating_sub(self.sent)
    }

    /// Messages sent so far.
    pub(crate) fn sent(&self) -> u64 {
        self.sent
    }

    fn ordinary_left(&self) -> u64 {
        let cap = self.budget.messages.saturating_sub(self.budget.reserve);
        cap.saturating_sub(self.sent_ordinary).min(self.left())
    }

    /// When the next ordinary frame may go (`None`: never again this game).
    pub(crate) fn next_ordinary(&self, now: Instant) -> Option<Instant> {
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

    /// Whether a frame of `class` may go now.
    pub(crate) fn allows(&self, now: Instant, class: Class) -> bool {
        if self.left() == 0 {
            return false;
        }
        let ordinary = self.next_ordinary(now).is_some_and(|t| t <= now);
        match class {
            Class::Ordinary => ordinary,
            Class::Priority => ordinary || self.sent_reserve < self.reserve_open(now),
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
        let ordinary = self.next_ordinary(now).is_some_and(|t| t <= now);
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

    #[test]
    fn league_rules_parse_and_share() {
        assert_eq!("spl".parse::<BudgetSpec>(), Ok(BudgetSpec::SPL));
        assert_eq!(" Humanoid ".parse::<BudgetSpec>(), Ok(BudgetSpec::HUMANOID));
        let custom: BudgetSpec = "600/10min".parse().unwrap();
        assert_eq!(
            (custom.team_messages, custom.game, custom.payload_limit),
            (600, Duration::from_secs(600), None)
        );
        for bad in [
            "", "spl2", "600", "600/", "0/10min", "600/10", "x/10s", "600/-1s",
        ] {
            assert!(bad.parse::<BudgetSpec>().is_err(), "{bad:?} must not parse");
        }
        let share = BudgetSpec::SPL.share(5);
        assert_eq!(
            (share.messages, share.reserve),
            (240, 24),
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
mod replica_tests {
    use std::time::Duration;

    use crate::{Budget, Instant, Key, Replica, ReplicaConfig, Value};

    fn at(ms: u64) -> Instant {
        Instant::from_micros(ms * 1000)
    }

    /// Drives a replica for `until_ms`, writing `*.var.x` every 10 ms and the priority key
    /// `*.var.goer` at each of `priority_at`; returns when each frame went.
    fn run(budget: Budget, until_ms: u64, priority_at: &[u64]) -> (Vec<u64>, Replica) {
        let cfg = ReplicaConfig {
            budget: Some(budget),
            mtu: 128,
            ..ReplicaConfig::new(3, 1)
        };
        let mut r = Replica::new(cfg, 1, at(0)).unwrap();
        let x = Key::parse("*.var.x").unwrap();
        let goer = Key::parse("*.var.goer").unwrap();
        let mut frames = Vec::new();
        for ms in (0..until_ms).step_by(10) {
            r.handle_timeout(at(ms));
            r.set_key(at(ms), &x, Value::Int(ms as i64)).unwrap();
            if priority_at.contains(&ms) {
                r.set_priority(at(ms), &goer, Value::Int(ms as i64))
                    .unwrap();
            }
            while let Some(t) = r.poll_transmit() {
                assert!(t.payload.len() <= 128, "{} bytes", t.payload.len());
                frames.push(ms);
            }
        }
        (frames, r)
    }

    #[test]
    fn a_budgeted_replica_sends_no_more_frames_than_its_share_and_paces_them() {
        // An SPL-like share: 24 messages over 24 s, 4 of them reserved.
        let budget = Budget {
            messages: 24,
            game: Duration::from_secs(24),
            reserve: 4,
        };
        let (frames, r) = run(budget, 30_000, &[]);
        assert_eq!(
            frames.len(),
            20,
            "20 ordinary frames, the reserve kept: {frames:?}"
        );
        assert!(
            frames.windows(2).all(|w| w[1] - w[0] >= 900),
            "about one a second, not a burst: {frames:?}"
        );
        assert_eq!(r.budget_status(), Some((20, 4)));
    }

    #[test]
    fn a_priority_item_goes_at_once_from_the_reserve_and_the_budget_still_holds() {
        let budget = Budget {
            messages: 10,
            game: Duration::from_secs(10),
            reserve: 2,
        };
        let (frames, r) = run(budget, 12_000, &[500, 600, 5_500]);
        assert!(
            frames.contains(&500),
            "the first goer change goes at once: {frames:?}"
        );
        assert!(
            !frames.contains(&600),
            "the second waits: the reserve is paced over the game: {frames:?}"
        );
        assert!(
            frames.contains(&5_500),
            "half a game later the reserve has opened again: {frames:?}"
        );
        assert_eq!(frames.len(), 10, "never beyond the budget: {frames:?}");
        assert_eq!(r.budget_status(), Some((10, 0)));
    }

    #[test]
    fn half_a_game_of_an_spl_robot_that_always_has_news_spends_half_its_share() {
        // An SPL robot of five: 240 messages per 1200 s, 24 reserved; a goer change every
        // second asks for the reserve far more often than it lasts.
        let budget = crate::BudgetSpec::SPL.share(5);
        let priority: Vec<u64> = (0..600_000).step_by(1000).collect();
        let (frames, r) = run(budget, 600_000, &priority);
        let ordinary_half = (240 - 24) / 2;
        assert_eq!(
            frames.len(),
            ordinary_half + 24 / 2,
            "half of the ordinary share and half of the reserve (it is paced too)"
        );
        assert_eq!(r.budget_status(), Some((120, 120)));
    }

    #[test]
    fn a_value_that_cannot_fit_the_leagues_payload_is_refused_when_set() {
        let cfg = ReplicaConfig {
            budget: Some(Budget {
                messages: 10,
                game: Duration::from_secs(10),
                reserve: 1,
            }),
            mtu: 128,
            ..ReplicaConfig::new(3, 1)
        };
        let mut r = Replica::new(cfg, 1, at(0)).unwrap();
        let err = r
            .set(at(0), "*.var.image", Value::Bytes(vec![0; 120]))
            .expect_err("120 bytes of value cannot fit a 128-byte frame");
        assert!(err.to_string().contains("128"), "{err}");
    }
}
