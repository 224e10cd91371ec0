//! A first slot whose own tones the room spread too far apart for the rules: the tracked
//! frame's weak tones judged against its own loud ones.
//!
//! The room puts a frame's six tones 10–35 dB apart (a tone on a peak of the response,
//! another in a notch). The rules drop a tone more than 25 dB below the loudest tone
//! (`DYNAMIC_RANGE`, rules.rs: sidelobes, a loudspeaker's harmonics) and, in a crowd of
//! present tones, one more than 10 dB below the fourth loudest (`CROWD_RANGE`; the
//! tracked sender's within 15 dB, `OWN_CROWD_RANGE`). Where the loudest tones are the
//! frame's own, the weak basic loses its vote with them and the slot is refused: short
//! messages over babble at 0 dB, tuning rows of seeds 62–67 and the old rows below 99%
//! (26015, 28009, 29015, 30015, 31009), 40 of 172 losses were refused by the rules on the
//! first slot; 19 of them had a basic whose two missing tones sat 25.2–29.9 dB below the
//! loudest tone, the frame's own data (or sender) tone on a peak (e.g. 64015 at 1233.8 s:
//! sender tones k1 and k25 at 53 and 86 per window, 17–19 dB above the noise, against the
//! data's k35 at 34,857), and 5 a data basic with its tones in a crowd 10–15 dB below the
//! fourth loudest (e.g. 67009 at 1955.0 s: k52 at 13 against k50 at 210).
//!
//! So when the rules refuse a first slot, they are asked again with the tracked frame's
//! own six tones present down to [`OWN_DYNAMIC_RANGE`] below the loudest tone and, in a
//! crowd, its data's as well as its sender's within the sender's allowance; the slot is
//! taken only if that gives **exactly the tracked frame** with a loudest tone of its own
//! (so the spread is the room's on this frame, not a foreign loud sound's). Nothing else
//! is relaxed: the tones must still pass the Gamma threshold and the leakage test, rivals
//! are judged as before, and every check after the rules (through the slot, both halves,
//! above the neighbours, steady, basics together, second transmitter, background, stray
//! tones, one scale) applies to them as to any.

use super::rules::OwnTones;
use super::tracking::{Stage, Tracking};
use super::Decoder;
use crate::tones::{Frame, SENDER_COUNT, TONE_COUNT};

/// Least share of the loudest tone's excess an own tone of the tracked frame keeps to
/// count on a first slot the rules refused (−30 dB). The 19 refused basics on the tuning
/// rows had their second tone 25.2–29.9 dB below the loudest; Hann leakage from an
/// adjacent tone (−31 dB) is still caught by the leakage test (−20 dB of a neighbour).
pub(super) const OWN_DYNAMIC_RANGE: f64 = 0.001;

impl Decoder {
    /// The rules again on a first slot of `t` they refused (sums `sums` over `count`
    /// windows, per-tone false-alarm `p_tone` and `p_rival`), with the tracked frame's own
    /// tones judged against its own (see the module's comment): the frame and the tones
    /// present, when that gives exactly the tracked frame and the loudest tone is one of
    /// its six.
    pub(super) fn own_tones_rules(
        t: &Tracking,
        sums: &[f64; TONE_COUNT],
        count: usize,
        p_tone: f64,
        p_rival: f64,
    ) -> Option<(Frame, [bool; TONE_COUNT])> {
        if t.stage != Stage::Slot1 {
            return None;
        }
        let tracked = Frame {
            sender: t.sender,
            data: t.data[0],
        };
        own_tones_decision(tracked, sums, count, p_tone, p_rival)
    }
}

/// The decision of [`Decoder::own_tones_rules`] on the tracked frame `tracked`.
pub(super) fn own_tones_decision(
    tracked: Frame,
    sums: &[f64; TONE_COUNT],
    count: usize,
    p_tone: f64,
    p_rival: f64,
) -> Option<(Frame, [bool; TONE_COUNT])> {
    let loudest = (0..TONE_COUNT).max_by(|&a, &b| sums[a].total_cmp(&sums[b]))?;
    if !tracked.tones().contains(&loudest) {
        return None;
    }
    let own = OwnTones {
        sender: Some(tracked.sender.index() as usize),
        data: Some(SENDER_COUNT + tracked.data as usize),
        dynamic_range: OWN_DYNAMIC_RANGE,
    };
    match Decoder::apply_rules_with(sums, count, p_tone, p_rival, own, |_, _| true) {
        (Some(frame), present) if frame == tracked => Some((frame, present)),
        _ => None,
    }
}
