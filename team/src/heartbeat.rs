//! Whether the radio works, told apart from a quiet one by the GameController's packets.
//!
//! The GameController sends a packet every 0.5 s over the same WLAN as the team's frames,
//! whatever the team's budget. Under a league's budget a claim holds 15 s, and out of play
//! nobody tells one, so a claim's age does not say whether the radio works; the
//! GameController's packets do. [`RadioHeartbeat`] keeps when this robot last heard the
//! GameController and when it last heard any teammate; the team layer asks it whether the
//! radio is dead (hold the frames nobody would hear, and let the acoustic fallback decide)
//! or working (claims are only old). A team that never hears a GameController (a lab) gets
//! neither answer, and goes by the claims' age as before.
//!
//! ```
//! use team::heartbeat::{RadioHeartbeat, GC_SILENT_S};
//! let mut beat = RadioHeartbeat::default();
//! beat.heard_gamecontroller(10.0);
//! beat.heard_teammate(10.2);
//! assert!(beat.working(11.0) && !beat.dead(11.0));
//! assert!(beat.dead(10.2 + GC_SILENT_S + 0.1), "neither the GC nor a teammate for 3 s");
//! ```

/// A robot that heard the GameController before and has heard neither it nor any
/// teammate for this long takes the radio for dead, s: six packets in a row lost at 20%
/// loss (6·10⁻⁵) and no teammate's frame either (under the SPL's budget the team sends
/// about one a second) is about once a day per robot. A robot that heard the
/// GameController within this long takes the radio for working.
pub const GC_SILENT_S: f64 = 3.0;

/// A teammate heard this long after the GameController's last packet shows the radio
/// outlived the GameController, s (two of its packet periods: in a real outage the last
/// frame of each comes within a period or so of the other).
pub const TEAM_AFTER_GC_S: f64 = 1.0;

/// A GameController silent this long is forgotten, s: the heartbeat gives no answer again
/// and the claims' age decides, as in a lab. While the radio is dead the layer holds its
/// frames, so a team that fell quiet when the GameController was closed for good (after a
/// game, every robot out of play) would otherwise hold them until it heard one again.
pub const GC_FORGOTTEN_S: f64 = 120.0;

/// When this robot last heard the GameController and any teammate (its clock, s).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RadioHeartbeat {
    gc_heard_s: Option<f64>,
    mate_heard_s: Option<f64>,
}

impl RadioHeartbeat {
    /// A GameController packet was accepted at `at_s`.
    pub fn heard_gamecontroller(&mut self, at_s: f64) {
        self.gc_heard_s = Some(self.gc_heard_s.map_or(at_s, |t| t.max(at_s)));
    }

    /// A teammate's frame was heard at `at_s`.
    pub fn heard_teammate(&mut self, at_s: f64) {
        self.mate_heard_s = Some(self.mate_heard_s.map_or(at_s, |t| t.max(at_s)));
    }

    /// Whether the GameController was heard within [`GC_SILENT_S`] of `now_s`: the radio
    /// works, however old the claims.
    pub fn working(&self, now_s: f64) -> bool {
        self.gc_heard_s.is_some_and(|t| now_s - t <= GC_SILENT_S)
    }

    /// Whether the radio is dead at `now_s`: the GameController was heard once, neither it
    /// nor any teammate has been for [`GC_SILENT_S`], and no teammate was heard after the
    /// GameController fell silent (more than [`TEAM_AFTER_GC_S`] after its last packet:
    /// then the GameController went, or this robot stopped hearing it, not the radio).
    /// Without that last condition a robot deaf to the GameController alone took the
    /// radio for dead at every 3 s gap in the team's frames, common under a budget, and
    /// held its own. A GameController silent for [`GC_FORGOTTEN_S`] is forgotten.
    pub fn dead(&self, now_s: f64) -> bool {
        let Some(gc) = self.gc_heard_s else {
            return false;
        };
        let silent_s = now_s - gc;
        silent_s > GC_SILENT_S
            && silent_s <= GC_FORGOTTEN_S
            && self
                .mate_heard_s
                .is_none_or(|m| now_s - m > GC_SILENT_S && m <= gc + TEAM_AFTER_GC_S)
    }

    /// When the radio last carried anything: the GameController or a teammate, s.
    pub fn last_heard_s(&self) -> Option<f64> {
        match (self.gc_heard_s, self.mate_heard_s) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        }
    }

    /// Whether the GameController was heard once, and not since `t_s`.
    pub fn gc_silent_since(&self, t_s: f64) -> bool {
        self.gc_heard_s.is_some_and(|g| g <= t_s)
    }

    /// Whether any teammate was ever heard: a radio that never carried a teammate's
    /// frame has not failed (a robot starting up).
    pub fn heard_a_teammate(&self) -> bool {
        self.mate_heard_s.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_radio_is_dead_when_the_gamecontroller_and_the_team_fall_silent_together() {
        let mut beat = RadioHeartbeat::default();
        assert!(
            !beat.dead(100.0) && !beat.working(100.0),
            "no GC ever: no answer"
        );
        // The WLAN fails just after 10.4 s: the GC's last packet at 10 s, a teammate's
        // last frame at 10.4 s.
        beat.heard_gamecontroller(10.0);
        beat.heard_teammate(10.4);
        assert!(!beat.working(13.1), "the GC silent for 3.1 s");
        assert!(!beat.dead(13.1), "a teammate heard 2.7 s ago");
        assert!(beat.dead(13.5), "neither for 3.1 s");
        beat.heard_gamecontroller(15.7);
        assert!(
            beat.working(15.8) && !beat.dead(15.8),
            "back with the GC's next packet"
        );
        beat.heard_gamecontroller(14.0);
        assert!(
            beat.working(18.6),
            "an older packet does not move the last heard back"
        );
    }

    #[test]
    fn a_gamecontroller_silent_for_two_minutes_is_forgotten() {
        let mut beat = RadioHeartbeat::default();
        beat.heard_gamecontroller(10.0);
        beat.heard_teammate(10.2);
        assert!(beat.dead(129.9), "a long outage is still an outage");
        assert!(
            !beat.dead(130.1) && !beat.working(130.1),
            "then no answer: the claims' age decides, as in a lab"
        );
    }

    #[test]
    fn a_robot_deaf_to_the_gamecontroller_alone_never_takes_the_radio_for_dead() {
        // The GC's packets stop reaching this robot at 10 s; its teammates' frames still
        // come, a few seconds apart as under a budget.
        let mut beat = RadioHeartbeat::default();
        beat.heard_gamecontroller(10.0);
        beat.heard_teammate(9.0);
        assert!(!beat.dead(12.9));
        assert!(beat.dead(13.1), "nothing heard since: it cannot tell yet");
        beat.heard_teammate(13.5);
        for t in [16.6, 20.0, 60.0] {
            assert!(
                !beat.dead(t),
                "a teammate was heard after the GC fell silent: the radio works ({t} s)"
            );
        }
    }
}
