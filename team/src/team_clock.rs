//! The team's clock for the acoustic fallback's slots, from the replica's own clock
//! estimates: no extra message, no server, and it keeps running when the radio fails.
//!
//! Every frame the replica sends carries the sender's clock (a u32 of microseconds) and
//! echoes a teammate's, so each robot keeps an estimate of every teammate's clock offset
//! and drift (`comms::PeerInfo::clock_offset_us`, extrapolated with the fitted drift to
//! the replica's now). The team clock is the clock of a **reference** robot, modulo
//! 2^32 µs (71.6 min, the wire's range): the lowest id among this robot and the
//! teammates heard recently (within [`RECENT_S`], or still present to the replica: under
//! a league's budget, several message intervals) whose clock it knows: by the echo
//! estimate, or until one exists by the frames' send stamps alone
//! (`PeerInfo::clock_offset_one_way_us`, early by a typical transit). Under a budget an
//! echo needs a teammate's frame within 655 ms of one of ours, and in a 95 s match most
//! robots had an echo estimate of one or two teammates: each read a different reference,
//! seconds apart, until the stamps gave everyone robot 1's clock. Robot 1 so reads its own
//! clock, its teammates read robot 1's through their estimates, and they agree to the
//! estimate's error (the path asymmetry, a few ms on a WLAN: `tests/shared_time.rs`).
//!
//! The acoustic fallback's clock ([`TeamClock::among`]) takes its reference among the
//! field players only: in a game under a budget the goalkeeper (no slot, little to tell)
//! can go unheard for over a minute, and the robots gave it up at different moments, one
//! of them 1.5 s into an outage.
//!
//! **It does not move when the radio fails.** A reference is only given up for a lower
//! id heard recently, or when it has not been heard for [`REFERENCE_LOST_S`], nor is
//! present, while some other teammate is heard within [`RECENT_S`] (the radio works; the
//! reference is gone). In an outage nobody is
//! heard, so every robot keeps the reference it had and extrapolates its estimate with
//! the fitted drift (tens of ppm: 30 ppm is 1.8 ms a minute, far inside a slot's guard).
//! Robots that chose different references (one never heard robot 1) disagree by
//! seconds; they agree again one round trip after they hear each other.
//!
//! **The wrap.** Team time runs from 0 to 4,294.967 s and starts again; a slot that
//! does not fit before the wrap is never sounded ([`TeamClock::next_slot`]), so every
//! robot skips the same partial slot at the same instant.

use comms::{Instant, PeerInfo};

/// Team time wraps here, µs (the wire's u32 clock).
pub const WRAP_US: i64 = 1 << 32;
/// Team time wraps here, s.
pub const WRAP_S: f64 = WRAP_US as f64 * 1e-6;
/// A teammate counts as heard recently for the choice of the reference within this, s.
pub const RECENT_S: f64 = 2.0;
/// A reference not heard for this long (nor present), while some other teammate is, is
/// given up, s. Long, because robots give it up at different moments (each lost different
/// frames) and read different clocks until all have: under a league's budget a quiet
/// goalkeeper's frames come tens of seconds apart, and with 10 s one robot that had
/// missed two of them gave it up while its teammates kept it (`huddle sim --acoustic
/// --budget spl`, seed 4).
pub const REFERENCE_LOST_S: f64 = 60.0;

/// The team's clock as this robot reads it: which robot is the reference and the offset
/// of its clock from this robot's (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TeamClock {
    me: u8,
    /// The lowest id that may be the reference (see [`TeamClock::among`]).
    lowest: u8,
    /// The reference robot.
    reference: u8,
    /// The reference's clock minus this robot's, µs (0 when it is this robot).
    offset_us: i64,
}

impl TeamClock {
    /// Robot `me`'s team clock before it heard anyone: its own.
    pub fn new(me: u8) -> TeamClock {
        TeamClock::among(me, 1)
    }

    /// Robot `me`'s team clock, its reference chosen among the robots from id `lowest`
    /// up: the acoustic fallback's are the field players (the slots' first id), because
    /// in a game under a league's budget the goalkeeper, which has no slot and tells the
    /// team little, went unheard for over a minute, and a robot that gave it up 1.5 s
    /// into an outage read another robot's clock and sounded a second off its slots
    /// (`huddle sim --game restarts --budget spl --acoustic --outage 30s@200s`, seed 8:
    /// 72 collisions, one goer 54% of the outage). A robot below `lowest` reads its own
    /// clock only until it hears one of them.
    pub fn among(me: u8, lowest: u8) -> TeamClock {
        TeamClock {
            me,
            lowest,
            reference: me,
            offset_us: 0,
        }
    }

    /// How this robot ranks `id` as a reference: lower is better; its own clock, when it
    /// may not be the reference, worst.
    fn rank(&self, id: u8) -> u16 {
        if id == self.me && self.me < self.lowest {
            u16::MAX
        } else {
            u16::from(id)
        }
    }

    /// The reference robot now.
    pub fn reference(&self) -> u8 {
        self.reference
    }

    /// The reference's clock minus this robot's, µs.
    pub fn offset_us(&self) -> i64 {
        self.offset_us
    }

    /// Takes the replica's view of its teammates at `now` (`Replica::peers`, whose
    /// offsets are extrapolated to the replica's now).
    pub fn update(&mut self, now: Instant, peers: impl IntoIterator<Item = PeerInfo>) {
        let age = |heard: Instant| now.saturating_duration_since(heard).as_secs_f64();
        // The lowest id heard recently, with its offset.
        let mut best: Option<(u8, i64)> = None;
        let mut current: Option<(i64, bool, Instant)> = None;
        // Whether some teammate's frames arrive now: the radio works.
        let mut radio_works = false;
        for p in peers {
            if p.robot == self.me || p.robot < self.lowest {
                continue;
            }
            // The echo estimate, else the send stamps' (a few ms coarser, but there from
            // the first frame: under a league's budget echoes may take minutes).
            let Some(offset) = p.clock_offset_us.or(p.clock_offset_one_way_us) else {
                continue;
            };
            // Recent: the replica still counts it present (under a budget, three message
            // intervals and more), or heard within RECENT_S.
            let heard = age(p.last_heard) <= RECENT_S;
            radio_works |= heard;
            let recent = p.present || heard;
            if p.robot == self.reference {
                current = Some((offset, recent, p.last_heard));
            }
            if recent && best.is_none_or(|(id, _)| p.robot < id) {
                best = Some((p.robot, offset));
            }
        }
        // A lower id heard recently (or this robot itself) always wins: every robot that
        // hears the team converges on the same reference.
        let lowest_recent = match best {
            Some((id, _)) if self.rank(id) < self.rank(self.me) => id,
            _ => self.me,
        };
        let lost = self.reference != self.me
            && radio_works
            && current.is_none_or(|(_, recent, heard)| !recent && age(heard) > REFERENCE_LOST_S);
        if self.rank(lowest_recent) < self.rank(self.reference) || lost {
            self.reference = lowest_recent;
            self.offset_us = best
                .filter(|(id, _)| *id == lowest_recent)
                .map_or(0, |(_, offset)| offset);
            return;
        }
        if let Some((offset, _, _)) = current {
            // Its estimate, extrapolated by the replica, also while it is not heard.
            self.offset_us = offset;
        }
    }

    /// Team time at `local` (this robot's clock), s, in `0 .. WRAP_S`.
    pub fn team_s(&self, local: Instant) -> f64 {
        let us = i64::try_from(local.as_micros()).unwrap_or(i64::MAX);
        us.wrapping_add(self.offset_us).rem_euclid(WRAP_US) as f64 * 1e-6
    }

    /// Team time at `local_s` (this robot's clock, s), s, in `0 .. WRAP_S`.
    pub fn team_at_s(&self, local_s: f64) -> f64 {
        (local_s + self.offset_us as f64 * 1e-6).rem_euclid(WRAP_S)
    }

    /// The first start at or after `local_s` (this robot's clock, s) of a slot at
    /// `offset_s` into each cycle of `cycle_s` (team time), on this robot's clock; slots
    /// that would not end before the wrap (`slot_s` long) are skipped.
    pub fn next_slot(&self, local_s: f64, offset_s: f64, cycle_s: f64, slot_s: f64) -> f64 {
        let team = self.team_at_s(local_s);
        let n = ((team - offset_s) / cycle_s).ceil().max(0.0);
        let mut start = offset_s + n * cycle_s;
        if start + slot_s > WRAP_S {
            start = WRAP_S + offset_s;
        }
        local_s + (start - team)
    }

    /// A time heard on team time `team_s` brought next to `near_s` (team time too) across
    /// the wrap: a message sounded just after the wrap and heard just before it by a
    /// slightly fast clock is in the new epoch's first slot.
    pub fn near(team_s: f64, near_s: f64) -> f64 {
        if team_s - near_s > WRAP_S / 2.0 {
            team_s - WRAP_S
        } else if near_s - team_s > WRAP_S / 2.0 {
            team_s + WRAP_S
        } else {
            team_s
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn peer(robot: u8, offset_us: Option<i64>, last_heard_s: f64) -> PeerInfo {
        PeerInfo {
            robot,
            incarnation: 1,
            last_heard: Instant::from_micros((last_heard_s * 1e6) as u64),
            present: true,
            frames: 10,
            conflicting: false,
            clock_offset_us: offset_us,
            clock_drift_ppm: Some(0.0),
            round_trip: Some(Duration::from_millis(2)),
            clock_samples: 5,
            clock_offset_one_way_us: offset_us.map(|o| o - 2_000),
        }
    }

    /// The replica no longer counts it present (silent beyond its departed_after).
    fn gone(p: PeerInfo) -> PeerInfo {
        PeerInfo {
            present: false,
            ..p
        }
    }

    fn at(s: f64) -> Instant {
        Instant::from_micros((s * 1e6) as u64)
    }

    #[test]
    fn among_the_field_players_a_quiet_goalkeeper_is_never_the_reference() {
        // Robot 1, the goalkeeper, has no slot; the slots are robots 2 onwards.
        let (one, two) = (Some(5_000_000), Some(-3_000_000));
        let mut three = TeamClock::among(3, 2);
        three.update(at(10.0), [peer(1, one, 9.9), peer(2, two, 9.9)]);
        assert_eq!(
            three.reference(),
            2,
            "robot 2's clock, robot 1 heard or not"
        );
        assert_eq!(three.offset_us(), -3_000_000);
        // Robot 1 goes quiet for a minute and more (a goalkeeper under a budget): nothing
        // moves, in an outage or not.
        three.update(at(80.0), [gone(peer(1, one, 9.9)), peer(2, two, 79.9)]);
        three.update(
            at(81.5),
            [gone(peer(1, one, 9.9)), gone(peer(2, two, 79.9))],
        );
        assert_eq!((three.reference(), three.offset_us()), (2, -3_000_000));
        // The goalkeeper reads its own clock only until it hears a field player.
        let mut keeper = TeamClock::among(1, 2);
        keeper.update(at(1.0), []);
        assert_eq!(keeper.reference(), 1);
        keeper.update(at(2.0), [peer(3, Some(700), 1.9)]);
        assert_eq!((keeper.reference(), keeper.offset_us()), (3, 700));
        keeper.update(
            at(3.0),
            [peer(3, Some(700), 2.9), peer(2, Some(-8_000_000), 2.9)],
        );
        assert_eq!(keeper.reference(), 2, "the lowest field player heard");
        assert_eq!(
            TeamClock::new(3).reference(),
            3,
            "new(): every id may be the reference"
        );
    }

    #[test]
    fn robots_that_hear_each_other_read_the_lowest_ids_clock() {
        // Robot 1's clock is 5 s ahead of robot 3's and 2 s behind robot 2's.
        let mut three = TeamClock::new(3);
        three.update(
            at(100.0),
            [
                peer(1, Some(5_000_000), 99.9),
                peer(2, Some(7_000_000), 99.9),
            ],
        );
        assert_eq!(three.reference(), 1, "the lowest id heard is the reference");
        let mut one = TeamClock::new(1);
        one.update(at(105.0), [peer(3, Some(-5_000_000), 104.9)]);
        assert_eq!(one.reference(), 1, "robot 1 reads its own clock");
        assert!(
            (three.team_s(at(100.0)) - one.team_s(at(105.0))).abs() < 1e-9,
            "the same instant reads the same team time: {} vs {}",
            three.team_s(at(100.0)),
            one.team_s(at(105.0))
        );
    }

    #[test]
    fn an_outage_keeps_the_reference_and_its_extrapolated_estimate() {
        let mut c = TeamClock::new(4);
        c.update(
            at(50.0),
            [peer(2, Some(1_000), 49.95), peer(3, Some(2_000), 49.95)],
        );
        assert_eq!(c.reference(), 2);
        // The radio fails: nobody is heard any more (nor present, to the replica, after
        // its departed_after); the replica still extrapolates.
        for k in 1..100 {
            let now = 50.0 + f64::from(k);
            c.update(
                at(now),
                [
                    gone(peer(2, Some(1_000 + k as i64), 49.95)),
                    gone(peer(3, Some(2_000), 49.95)),
                ],
            );
            assert_eq!(c.reference(), 2, "at {now} s the reference holds");
        }
        assert_eq!(c.offset_us(), 1_099, "the extrapolated offset is followed");
        // The radio comes back without robot 2 (it is gone): robot 3 takes over once
        // robot 2 has been missed for REFERENCE_LOST_S while robot 3 is heard.
        c.update(
            at(155.0),
            [
                gone(peer(2, Some(1_200), 49.95)),
                peer(3, Some(2_500), 154.9),
            ],
        );
        assert_eq!(
            c.reference(),
            3,
            "a reference gone while the radio works is replaced"
        );
        assert_eq!(c.offset_us(), 2_500);
    }

    #[test]
    fn a_moment_without_the_reference_does_not_move_the_clock() {
        let mut c = TeamClock::new(3);
        c.update(
            at(10.0),
            [peer(1, Some(300), 9.99), peer(2, Some(400), 9.99)],
        );
        // Robot 1 falls silent for 3 s (lost frames) while robot 2 is heard.
        c.update(
            at(13.0),
            [gone(peer(1, Some(300), 10.0)), peer(2, Some(400), 12.99)],
        );
        assert_eq!(c.reference(), 1, "a short silence is no reason to switch");
        // Until an estimate or a stamp exists, a teammate cannot be the reference.
        let mut d = TeamClock::new(3);
        let unknown = PeerInfo {
            clock_offset_one_way_us: None,
            ..peer(1, None, 0.99)
        };
        d.update(at(1.0), [unknown]);
        assert_eq!(
            d.reference(),
            3,
            "no estimate of robot 1 yet: its own clock"
        );
    }

    #[test]
    fn under_a_budget_the_send_stamps_and_presence_keep_the_team_on_robot_1() {
        // A league's budget: frames seconds apart, echoes rarer still. Robot 4 has an
        // echo estimate of robot 3 only; of robot 1 it has the send stamps (its clock
        // 7.18 s ahead, less a 20 ms transit). Robot 1 was last heard 8 s ago, but the
        // replica still counts it present (three message intervals and more).
        let mut four = TeamClock::new(4);
        let one = PeerInfo {
            clock_offset_us: None,
            clock_offset_one_way_us: Some(7_180_000 - 20_000),
            ..peer(1, None, 92.0)
        };
        four.update(at(100.0), [one.clone(), peer(3, Some(230_000), 99.0)]);
        assert_eq!(
            four.reference(),
            1,
            "robot 1 by its stamps, though 8 s silent"
        );
        // Robot 3 reads robot 1 by an echo estimate: the two agree within the transit.
        let mut three = TeamClock::new(3);
        three.update(at(100.0), [peer(1, Some(7_180_000), 99.0)]);
        let apart = (four.team_s(at(100.0)) - three.team_s(at(100.0))).abs();
        assert!(
            apart < 0.05,
            "robots 3 and 4 read the team clock {apart} s apart"
        );
        // Robot 1 stays silent 15 s more, still present: it is not given up.
        four.update(at(115.0), [one.clone(), peer(3, Some(230_000), 114.0)]);
        assert_eq!(four.reference(), 1, "a present reference is kept");
        // The radio fails. Robot 1, silent longest, leaves the replica's present list
        // first while robot 3 is still counted present: nobody is heard, so it is the
        // outage, not robot 1 gone, and the reference holds.
        four.update(at(130.0), [gone(one), peer(3, Some(230_000), 114.0)]);
        assert_eq!(four.reference(), 1, "in an outage the reference holds");
    }

    #[test]
    fn the_next_slot_skips_the_partial_slot_before_the_wrap() {
        let c = TeamClock::new(1);
        let (cycle, slot) = (2.1, 0.7);
        // Ordinary: the slot 0.7 s into each 2.1 s cycle starts at 9.1 s, then 11.2 s.
        let next = c.next_slot(10.0, 0.7, cycle, slot);
        assert!((next - 11.2).abs() < 1e-9, "{next}");
        assert!(
            (c.next_slot(9.1, 0.7, cycle, slot) - 9.1).abs() < 1e-9,
            "a start is its own next"
        );
        // Just before the wrap, a slot that would straddle it is skipped.
        let late = WRAP_S - 0.5;
        let next = c.next_slot(late, 0.0, cycle, slot);
        assert!((next - WRAP_S).abs() < 1e-6, "{next} vs the wrap {WRAP_S}");
        assert!((TeamClock::near(WRAP_S - 0.01, 0.2) + 0.01).abs() < 1e-6);
    }
}
