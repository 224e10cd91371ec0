//! What a long message's second slot may carry besides its frame without being someone
//! else's signal: the tones the stray test (`Decoder::has_stray_tone`, confirm.rs) lets
//! go on a second slot only.

use super::tracking::{Stage, Tracking};
use super::Decoder;
use crate::tones::{basic_tones, Frame, BASIC_COUNT, SENDER_COUNT, TONE_COUNT};

impl Decoder {
    /// The tones outside `frame` that are no stray on the second slot `[a, b)` of `t`
    /// (tones `present`, per-window excess `level`): the first frame's data dying away
    /// (see `Decoder::first_data_tail`), and a **lone data tone**, a present tone of a
    /// data basic none of whose two other tones is present, save the first frame's data
    /// basic. Nothing on a first slot, and no lone tone when the frame decided there
    /// carries the first frame's data again.
    ///
    /// On a second slot the sender is known: the first slot passed every check, and the
    /// sender must hold its level through this one. What the stray test guards against
    /// there is another transmitter sounding under the slot, whose data could be taken
    /// for ours; a transmitter sounds each basic on three tones, and one tone of a data
    /// basic makes no data vote and no frame. In a babble hall at 0 dB a talker's
    /// harmonic, held through the slot and smeared by the room, reaches the level of the
    /// second frame's median tone now and then and refused the slot (long hall-2 0 dB:
    /// 22 of 119 lost on check row 993030, 51 of 201 on tuning row 39030, the largest
    /// class; 42 of those 51 for lone tones alone, nearly all on data basics, k3-k20 and
    /// k36-k42, 650-2,500 Hz). A lone tone of a sender basic is still a stray (another
    /// robot's sender with its other tones in the room's notches: its data tones may be
    /// the slot's data), and so is a first-data tone that holds its level (the first
    /// frame going on); every tone of a basic with two tones present is judged as before.
    pub(super) fn second_slot_own_tones(
        &self,
        t: &Tracking,
        frame: Frame,
        present: &[bool; TONE_COUNT],
        a: f64,
        b: f64,
        level: &[f64; TONE_COUNT],
    ) -> [bool; TONE_COUNT] {
        let mut own = self.first_data_tail(t, a, b, level);
        if t.stage != Stage::Slot2 {
            return own;
        }
        if frame.data == t.data[0] {
            // The first frame's data again: in a hall its tail sounds through the second
            // slot with two votes, and a lone loud tone may then be the true second
            // data's, its other tones in the room's notches (check row 992030 at
            // 1989.81 s: data 13's tail, k40 at 34 per window, decided, and data 17's k20
            // at 333, alone, let go: a wrong message). Judged as before.
            return own;
        }
        let first_data = SENDER_COUNT + usize::from(t.data[0]);
        let frame_tones = frame.tones();
        for (k, lone) in own.iter_mut().enumerate() {
            let basic = k % BASIC_COUNT;
            if *lone || !present[k] || frame_tones.contains(&k) {
                continue;
            }
            if basic < SENDER_COUNT || basic == first_data {
                continue;
            }
            *lone = basic_tones(basic).iter().all(|&j| j == k || !present[j]);
        }
        own
    }
}

impl Decoder {
    /// Of the data basics `data` with two votes `present` on the second slot `[a, b)` of
    /// `t` (slot sums `sums` over `count` windows), when there are several: those whose
    /// votes, with the sender's, sound like a transmitter's tones (each vote holds in each
    /// half, stands above its neighbours and sounds steadily: the checks the decided frame
    /// must pass anyway, see `Decoder::sounds_like_tones`). One data basic, or none,
    /// is returned as it is, and so are all when only the first frame's data would stay.
    ///
    /// A second frame's data tones sound through their slot from its start; in a babble
    /// hall at 0 dB the talkers' harmonics give some other data basic two votes now and
    /// then, smeared by the room, a syllable at a time, and the second slot was refused as
    /// ambiguous (long hall-2 0 dB, tuning row 39030: 46 of 166 lost, the largest class,
    /// 42 of them for other data basics with two votes). Someone else's data that does
    /// sound like a transmitter's keeps the slot ambiguous, and the frame decided still
    /// goes through every check of a slot (a rival's loud tones are strays there).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn second_data_that_sound(
        &self,
        t: &Tracking,
        data: Vec<usize>,
        present: &[bool; TONE_COUNT],
        sums: &[f64; TONE_COUNT],
        count: usize,
        a: f64,
        b: f64,
    ) -> Vec<usize> {
        if data.len() <= 1 {
            return data;
        }
        let first_data = SENDER_COUNT + usize::from(t.data[0]);
        let sounding: Vec<usize> = data
            .iter()
            .copied()
            .filter(|&d| {
                let frame = Frame {
                    sender: t.sender,
                    data: (d - SENDER_COUNT) as u8,
                };
                self.sounds_like_tones(frame, present, sums, count, t.scale, a, b)
            })
            .collect();
        if sounding == [first_data] {
            // The first frame's data is never decided by this filter: its tail can sound
            // steadily enough through a second slot while the true second data, in the
            // room's notches, does not (see `Decoder::second_slot_own_tones`).
            return data;
        }
        sounding
    }
}
