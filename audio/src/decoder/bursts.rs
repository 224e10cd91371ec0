//! Whether a first frame is one the background assembled: a weak frame in a crowded
//! band. The per-tone checks of `confirm.rs` (both halves, above the neighbourhood,
//! steadiness) judge each vote tone alone; at a typical tone of 5–9 dB per window they
//! have no power left (a steady tone that weak reads below the noise mean one window in
//! ten), and a crowd or two talkers in a hall put tones at that level all over the band.
//! The messages of the babble rows at 0 dB are not that weak, and in white noise, where
//! they are, the band around them is empty.

use super::confirm::{typical_level, HALL_CLEAR_LEVEL};
use crate::tones::{Frame, TONE_COUNT};

/// Least typical tone level (per-window excess, 10 dB) of a first frame in a crowded
/// band (see [`assembled_by_background`]). The messages of the 0 dB babble rows
/// sit at 11 dB and above (tuning rows 52009 and 52018: 2 of 1,989 first slots at
/// 10.9 dB, none below), the frames a crowd or two talkers assembled in 10 h of
/// backgrounds at 5–9 dB (tuning seeds 14–23: four of the eight false messages).
pub(super) const WEAK_LEVEL: f64 = 10.0;
/// Present tones outside the frame that make the band crowded: under Gaussian noise, 66
/// tones at `P_TONE_CONFIRM` (1e-2) give 8 or more about once in 10⁵ slots, so the dry
/// rows at −13 dB (weak frames in white noise) are not touched.
pub(super) const CROWD: usize = 8;

/// Why a first frame (its `present` tones at per-window excess `level`) is one the
/// background assembled rather than a transmitter's, if it is: it is weak
/// ([`WEAK_LEVEL`]) in a crowded band ([`CROWD`] other tones present), none of its
/// tones at the hall level (`HALL_CLEAR_LEVEL`, 15 dB).
pub(super) fn assembled_by_background(
    frame: Frame,
    present: &[bool; TONE_COUNT],
    level: &[f64; TONE_COUNT],
) -> Option<String> {
    let typical = typical_level(frame, present, level);
    let own = frame.tones();
    let crowd = (0..TONE_COUNT)
        .filter(|k| present[*k] && !own.contains(k))
        .count();
    // A frame with a tone at the hall level is not one babble assembled (its frames
    // have no tone at 15 dB): in a hall a message's median tone sits under 10 dB now
    // and then, pulled down by tones in the room's notches, while one of its tones
    // rings far above the talkers (tuning row 52024 at 890.59 s: 9.2 dB typical,
    // k68 at 81 per window, refused without this).
    let loudest = own
        .iter()
        .filter(|&&k| present[k])
        .map(|&k| level[k])
        .fold(0.0f64, f64::max);
    if typical < WEAK_LEVEL && crowd >= CROWD && loudest < HALL_CLEAR_LEVEL {
        return Some(format!(
            "weak frame ({:.1} dB) among {crowd} other tones",
            10.0 * typical.max(1e-12).log10()
        ));
    }
    None
}
