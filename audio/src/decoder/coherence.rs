//! Whether a frame's two basics are one transmitter's: they begin and end together. A
//! robot sounds its sender basic and its data basic as one frame, so both start at the
//! onset and both hold their level to the slot's end (the room changes each tone's
//! level, not when it sounds). Two robots sounding at once, one a fraction of a tone
//! after the other, put one robot's sender basic and the other's data basic in the same
//! slot: the decoder's onset falls between theirs, and one basic fades out before the
//! slot ends while the other comes in after it begins.

use super::confirm::{P_TONE_CONFIRM, P_TONE_RIVAL};
use super::tracking::Tracking;
use super::Decoder;
use crate::significance::gamma_upper_quantile;
use crate::significance::hann_share_inside;
use crate::tones::{basic_tones, Frame, Sender, BASIC_COUNT, SENDER_COUNT, TONE_COUNT};

/// Parts of the slot each basic must sound in (see [`Decoder::basics_sound_together`]).
const PARTS: usize = 4;
/// Least share of its slot-mean excess a basic's vote tones keep in each part of the slot
/// (−5 dB): far below what a steady tone keeps there, even building up in a T60 2 s hall
/// (about half of its level in the first quarter) or losing a loud early arrival (a
/// tone in a notch of the room), and far above what a basic that began or ended a
/// quarter of a slot away from the onset or the end keeps.
const PART_SHARE: f64 = 0.3;

/// Most share of its level in a second slot another robot's sender may have held in the
/// quarter before it to have begun with the slot (see `Decoder::sender_began_with_slot`):
/// a sender that began 0.09 s before the slot (a third of a quarter) holds about 0.4;
/// one that began earlier sounds its data before the slot too, which
/// `Decoder::second_data_began_before` catches.
const BEGAN_SHARE: f64 = 0.7;
/// ... and under this share of what the tracked sender's own tones held there.
const OWN_SHARE_RATIO: f64 = 0.5;
/// Share of its slot-mean excess a basic keeps in a quarter it *holds* (−2 dB).
const HOLD_SHARE: f64 = 0.6;
/// Noise allowance of that test, standard deviations of the part's summed excess.
const PART_NOISE_Z: f64 = 3.0;
/// Variance inflation of a sum over half-overlapping Hann windows (their powers are
/// correlated): a sum of m windows spreads like about 1.5 m independent ones.
const OVERLAP_INFLATION: f64 = 1.5;

/// Whether a part of the slot, `n` windows that summed `observed` where the basic's level
/// over the slot gives `expected`, is one the basic faded from: under [`PART_SHARE`] of
/// it beyond [`PART_NOISE_Z`] standard deviations of the part's sum (a window's variance
/// `variance`, inflated by the windows' overlap).
fn faded(observed: f64, expected: f64, variance: f64, n: usize) -> bool {
    let spread = (OVERLAP_INFLATION * variance * n as f64).sqrt();
    observed < PART_SHARE * expected - PART_NOISE_Z * spread
}

impl Decoder {
    /// Whether the frame's two basics (its `present` tones) sound together through the
    /// slot `[a, b)` at `scale`; the reason when they do not, for the trace.
    ///
    /// Each basic's excess is summed over the windows centred in each quarter of the slot
    /// and set against its mean over the slot. A basic has *faded* from a quarter when it
    /// keeps less than [`PART_SHARE`] of its mean there, beyond the noise
    /// ([`PART_NOISE_Z`] standard deviations of a steady tone's non-central χ² windows),
    /// and *holds* it when it keeps [`HOLD_SHARE`]. The slot is refused when
    /// - one basic faded from a quarter the other holds: they began or ended apart, as two
    ///   robots' frames do (lab T60 1.2 s at 10 dB, row 990033 at 296.92 s: sender 1
    ///   sounded data 7 from 296.58 s, its sender tones weak in that room, and sender 0
    ///   began 0.5 s later; the slot found between them passed as sender 0 with data 7,
    ///   the data tones gone from 297.60 s while the sender's sounded on);
    /// - or the frame (its tones together) faded from the last quarter and did not sound in the quarter of
    ///   a slot before the onset either: it lasted under three quarters of a tone (a
    ///   burst of speech after digital silence, talkers T60 1.2 s, backgrounds seed 939 at
    ///   2302.85 s). A frame found late, its onset on the end of an earlier message,
    ///   fades from the last quarter too, but it sounded before the onset.
    pub(super) fn basics_sound_together(
        &self,
        frame: Frame,
        present: &[bool; TONE_COUNT],
        scale: usize,
        a: f64,
        b: f64,
    ) -> Result<(), String> {
        let window_len = self.geometry.window_len as f64;
        if b - a < PARTS as f64 * window_len {
            // A part shorter than a window (tones of a few windows): no verdict.
            return Ok(());
        }
        let basics = [
            frame.sender.index() as usize,
            SENDER_COUNT + usize::from(frame.data),
        ];
        let mut verdicts = Vec::with_capacity(2);
        for basic in basics {
            let tones: Vec<usize> = basic_tones(basic)
                .into_iter()
                .filter(|&k| present[k])
                .collect();
            match self.quarters(&tones, scale, a, b) {
                Some(q) => verdicts.push((basic, q)),
                None => return Ok(()),
            }
        }
        for part in 0..PARTS {
            for (i, (basic, q)) in verdicts.iter().enumerate() {
                let (_, other) = &verdicts[1 - i];
                if q.faded[part] && other.held[part] {
                    return Err(format!(
                        "basic {basic} holds {:.2} of its level in quarter {} where the other holds {:.2}",
                        q.share[part],
                        part + 1,
                        other.share[part]
                    ));
                }
            }
        }
        // The frame as a whole (a weak basic alone is too noisy to call faded).
        let tones: Vec<usize> = frame.tones().into_iter().filter(|&k| present[k]).collect();
        let whole = self.quarters(&tones, scale, a, b);
        if let Some(whole) = whole.filter(|q| q.faded[PARTS - 1]) {
            let quarter = (b - a) / PARTS as f64;
            if let Some((observed, n)) = self.part_excess(&tones, scale, a - quarter, a) {
                let expected = whole.mean * n as f64;
                if faded(observed, expected, whole.variance, n) {
                    return Err(format!(
                        "the frame faded from the last quarter and sounded {:.2} of its level before the onset",
                        observed / expected
                    ));
                }
            }
        }
        Ok(())
    }

    /// Another robot's sender that began with the second slot `[a, b)` of the tracked
    /// long message `t`, whose decided frame is `frame` (slot sums `sums` over `count`
    /// windows), and sounds through it: all three of its tones out of the noise (at any
    /// level, not only within the rules' dynamic range: the room can put a sender 20 dB
    /// under its data; a tone beside one of `frame`'s data tones is left out, as that
    /// tone's leakage begins with the slot too), each quarter held, and in the quarter before under [`BEGAN_SHARE`]
    /// of its slot level and under [`OWN_SHARE_RATIO`] of the share `t`'s own sender
    /// held there: its basic, when so. (Two tones of three, or no comparison with the own
    /// sender, let babble and a room's build-up through: one-robot long tuning rows lost
    /// 16 and 10 messages of 60,000; with these, 1.) A robot that begins with our second slot sounds its
    /// first frame there, and its data tones then begin with the slot as a second frame's
    /// do; if ours lies in the room's notches, its data passes for ours (lab T60 0.5 s,
    /// tuning row 91031 at 612.75 s: sender 1 began about 0.09 s before sender 2's second
    /// slot, holding 0.37 of its level in the quarter before, its sender tones 10–20 dB
    /// under its data in the room, its data 11 taken for sender 2's 17, whose tones were
    /// lost: a wrong long message; report row 1007031 at 1015 s alike). Which data is
    /// whose cannot be told: nothing is reported.
    pub(super) fn sender_began_with_slot(
        &self,
        t: &Tracking,
        frame: Frame,
        sums: &[f64; TONE_COUNT],
        count: usize,
        a: f64,
        b: f64,
    ) -> Option<usize> {
        let floor = gamma_upper_quantile(count.max(1) as f64, P_TONE_CONFIRM);
        let data_tones = basic_tones(SENDER_COUNT + usize::from(frame.data));
        let beside_data = |k: usize| data_tones.iter().any(|&d| d.abs_diff(k) == 1);
        let present: [bool; TONE_COUNT] =
            std::array::from_fn(|k| sums[k] >= floor && !beside_data(k));
        let quarter = (b - a) / PARTS as f64;
        // The share of its slot level `tones` held in the quarter before, and whether
        // they held their level in each quarter of the slot.
        let before_share = |tones: &[usize]| -> Option<(f64, bool)> {
            let q = self.quarters(tones, t.scale, a, b)?;
            let (before, n) = self.part_excess(tones, t.scale, a - quarter, a)?;
            Some((before / (q.mean * n as f64), q.held.iter().all(|&h| h)))
        };
        // Our own sender sounded through the first slot: a room still building up raises
        // it into the second, and its leakage onto a neighbouring sender's tones with it
        // (one-robot long rows at T60 1.2–2 s lost messages to that).
        let own = t.sender.index() as usize;
        let own_share = before_share(&basic_tones(own)).map_or(1.0, |(share, _)| share);
        (0..SENDER_COUNT).filter(|&s| s != own).find(|&s| {
            let tones: Vec<usize> = basic_tones(s).into_iter().filter(|&k| present[k]).collect();
            tones.len() == 3
                && before_share(&tones).is_some_and(|(share, held)| {
                    held && share < BEGAN_SHARE && share < OWN_SHARE_RATIO * own_share
                })
        })
    }

    /// Whether the second slot `[a, b)` of the tracked long message `t` decided a data
    /// basic (`data`, other than the first slot's) that already sounded in the quarter of
    /// a slot before it began, at [`HOLD_SHARE`] of its level in the slot or more beyond
    /// the noise, while the first frame had not sounded before its own onset: the share
    /// it held, when so. A robot's second frame begins with its slot; data sounding
    /// through the end of a first slot whose onset was not late is another robot's frame
    /// that began there (lab T60 0.5 s, tuning row 18031 at 1530.56 s: sender 1's data 11
    /// began 0.19 s before sender 2's second slot, sender 2's second data 20 lay in the
    /// room's notches, and the slot passed as sender 2's long 284). When the first frame
    /// sounded before its onset (at [`PART_SHARE`] of its level or more), the onset was
    /// late and the second frame did begin before the slot: no verdict (with this test
    /// alone, the two-robot tuning rows lost 194 messages of 30,000).
    pub(super) fn second_data_began_before(
        &self,
        t: &Tracking,
        data: u8,
        present: &[bool; TONE_COUNT],
        a: f64,
        b: f64,
    ) -> Option<f64> {
        let tones: Vec<usize> = basic_tones(SENDER_COUNT + usize::from(data))
            .into_iter()
            .filter(|&k| present[k])
            .collect();
        let q = self.quarters(&tones, t.scale, a, b)?;
        let quarter = (b - a) / PARTS as f64;
        let (observed, n) = self.part_excess(&tones, t.scale, a - quarter, a)?;
        let expected = q.mean * n as f64;
        let spread = (OVERLAP_INFLATION * q.variance * n as f64).sqrt();
        if observed < HOLD_SHARE * expected || observed < PART_NOISE_Z * spread {
            return None;
        }
        // The first frame, over the first slot and the quarter before it.
        let first = Frame {
            sender: t.sender,
            data: t.data[0],
        };
        let tones: Vec<usize> = first
            .tones()
            .into_iter()
            .filter(|&k| t.present[k])
            .collect();
        let slot = self.geometry.slot_samples;
        let q1 = self.quarters(&tones, t.scale, t.onset, t.onset + slot)?;
        let (before, m) = self.part_excess(&tones, t.scale, t.onset - quarter, t.onset)?;
        (before < PART_SHARE * q1.mean * m as f64).then_some(observed / expected)
    }

    /// A second transmitter's basic under the frame: a sender or data basic other than the
    /// frame's with 2 of its 3 tones `present` and at the rival level ([`P_TONE_RIVAL`])
    /// whose votes sound like a transmitter's (through both halves, above their
    /// neighbours, steadily: the tests of the frame's own votes), at any level. The rules
    /// let a rival refuse a frame only within 6 dB of the frame's basic; below that the
    /// frame's basics are taken as one robot's. Two robots sounding at once a few
    /// hundredths of a second apart, each with one basic loud and one in the room's
    /// notches, make a frame of one robot's sender and the other's data, each rival 7–8 dB
    /// under it (hall T60 2 s, row 990036 at 1049.96 s: sender 0 over data 2 of sender 1,
    /// whose sender tones read 6 and 8 against sender 0's 39 and 62; lab T60 0.5 s, row
    /// 18031 at 1023.53 s). Which data is whose cannot be told: nothing is reported.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn second_transmitter(
        &self,
        frame: Frame,
        present: &[bool; TONE_COUNT],
        sums: &[f64; TONE_COUNT],
        count: usize,
        scale: usize,
        a: f64,
        b: f64,
    ) -> Option<usize> {
        let rival = gamma_upper_quantile(count.max(1) as f64, P_TONE_RIVAL);
        let [own_sender, own_data] = [
            frame.sender.index() as usize,
            SENDER_COUNT + usize::from(frame.data),
        ];
        (0..BASIC_COUNT)
            .filter(|&basic| basic != own_sender && basic != own_data)
            .filter(|&basic| {
                basic_tones(basic)
                    .into_iter()
                    .filter(|&k| present[k] && sums[k] >= rival)
                    .count()
                    >= 2
            })
            .find(|&basic| {
                let candidate = if basic < SENDER_COUNT {
                    Frame {
                        sender: Sender::from_index(basic as u8).unwrap_or(frame.sender),
                        data: frame.data,
                    }
                } else {
                    Frame {
                        sender: frame.sender,
                        data: (basic - SENDER_COUNT) as u8,
                    }
                };
                self.sounds_like_tones(candidate, present, sums, count, scale, a, b)
            })
    }

    /// The excess of `tones` at `scale` summed over the windows wholly (≥ 90% of their
    /// Hann area) inside `[from, to)`, and how many there are; `None` when none are.
    fn part_excess(
        &self,
        tones: &[usize],
        scale: usize,
        from: f64,
        to: f64,
    ) -> Option<(f64, usize)> {
        let window_len = self.geometry.window_len as f64;
        let (mut sum, mut n) = (0.0, 0usize);
        for w in &self.history {
            if hann_share_inside(w.start as f64, window_len, from, to) >= 0.9 {
                sum += Self::excess(w, scale, tones);
                n += 1;
            }
        }
        (n > 0).then_some((sum, n))
    }

    /// How `tones` at `scale` fill each quarter of the slot `[a, b)` (see
    /// [`Decoder::basics_sound_together`]); `None` when a quarter holds no window or the
    /// tones have no excess.
    fn quarters(&self, tones: &[usize], scale: usize, a: f64, b: f64) -> Option<Quarters> {
        let window_len = self.geometry.window_len as f64;
        let mut parts = [(0.0f64, 0usize); PARTS];
        let mut per_tone = vec![0.0f64; tones.len()];
        for w in &self.history {
            let start = w.start as f64;
            if hann_share_inside(start, window_len, a, b) < 0.9 {
                continue;
            }
            let centre = start + 0.5 * window_len;
            let part =
                (((centre - a) / (b - a) * PARTS as f64).floor().max(0.0) as usize).min(PARTS - 1);
            parts[part].0 += Self::excess(w, scale, tones);
            parts[part].1 += 1;
            for (sum, &k) in per_tone.iter_mut().zip(tones) {
                *sum += f64::from(w.r[scale * TONE_COUNT + k]) - 1.0;
            }
        }
        let windows: usize = parts.iter().map(|p| p.1).sum();
        if tones.is_empty() || parts.iter().any(|p| p.1 == 0) {
            return None;
        }
        let mean = parts.iter().map(|p| p.0).sum::<f64>() / windows as f64;
        if mean <= 0.0 {
            return None;
        }
        // A window of a steady tone of excess λ (noise mean 1) has variance 1 + 2λ.
        let variance: f64 = per_tone
            .iter()
            .map(|&s| 1.0 + 2.0 * (s / windows as f64).max(0.0))
            .sum();
        let mut q = Quarters {
            mean,
            variance,
            share: [0.0; PARTS],
            faded: [false; PARTS],
            held: [false; PARTS],
        };
        for (i, &(observed, n)) in parts.iter().enumerate() {
            let expected = mean * n as f64;
            q.share[i] = observed / expected;
            q.faded[i] = faded(observed, expected, variance, n);
            q.held[i] = observed >= HOLD_SHARE * expected;
        }
        Some(q)
    }
}

/// How a basic's tones fill the quarters of a slot.
struct Quarters {
    /// Mean excess per window over the slot.
    mean: f64,
    /// Variance of one window's summed excess under a steady tone at that level.
    variance: f64,
    /// Each quarter's excess over its share of the mean.
    share: [f64; PARTS],
    /// Below [`PART_SHARE`] of it, beyond the noise.
    faded: [bool; PARTS],
    /// At [`HOLD_SHARE`] of it or more.
    held: [bool; PARTS],
}
