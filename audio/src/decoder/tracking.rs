//! Following a found frame to a report: decide its first slot, run the end test, decide a
//! second slot if the sender continued, and report a short or a long message (or nothing).

use super::confirm::{P_TONE_CONFIRM, P_TONE_RIVAL};
use super::end_test::{EndTest, EndVerdict, SPRT_HORIZON};
use super::rules::is_leakage;
use super::search::{Blocked, Recent};
use super::{median, Decoder, Detection};
use crate::significance::{gamma_upper_quantile, hann_share_inside};
use crate::tones::{basic_tones, Frame, Message, Sender, BASIC_COUNT, SENDER_COUNT, TONE_COUNT};

/// Share of a decided frame's level its tail must fall below before the search looks for
/// that frame again (−25 dB).
const TAIL_QUIET: f64 = 0.003;
/// Six-tone excess per window that counts as noise (2.5 σ of six Exp(1) powers).
const TAIL_NOISE_EXCESS: f64 = 6.1;

/// How long after a decided transmission's end its frame found again at a fraction of
/// its level counts as its tail, slots (a tail of T60 2.5 s is −72 dB by then).
const RECENT_SLOTS: f64 = 3.0;

/// Least share of its first-slot level (per-window excess) a sender tone keeps over a
/// second slot to count for the sender's vote there (−5 dB, what the sender's tones must
/// keep through a second slot's second half; see [`Decoder::second_slot_rules`]).
const SECOND_SLOT_SENDER_SHARE: f64 = 0.3;
/// Noise allowance of that test, standard deviations of the tone's slot mean.
const SECOND_SLOT_SENDER_Z: f64 = 2.0;
/// The first frame's data basic in the second slot is its reverberant tail when its
/// tones' excess over the slot's second half is below this share of the first half's
/// (−6 dB; a tail of T60 2.5 s falls 12 dB from one half to the next, a tone holds) and
/// the slot's level below [`SECOND_SLOT_SENDER_SHARE`] of the first slot's.
const ECHO_HALF_SHARE: f64 = 0.25;

/// A refused first slot is decided again at onsets up to this many hops earlier (0.26 s
/// at a 1 s tone), the first that passes standing (see `Decoder::decide_slot`).
const RETRY_HOPS: usize = 4;

/// A rival sender whose two loudest tones hold less than this share of their slot level
/// over a retried first slot's first fifth began inside it (see `Decoder::decide_slot`).
const RIVAL_BEGAN_SHARE: f64 = 0.3;

/// The transmission being followed.
#[derive(Clone, Debug)]
pub(super) struct Tracking {
    pub(super) sender: Sender,
    /// Data of the first and second slot (the second equals the first until decided).
    pub(super) data: [u8; 2],
    /// Frequency scale the frame was found at.
    pub(super) scale: usize,
    /// First sample of the first slot.
    pub(super) onset: f64,
    /// The onset was re-estimated once the whole first slot had been heard.
    onset_refined: bool,
    /// The onset estimated when the frame was found.
    found_onset: f64,
    pub(super) stage: Stage,
    /// Per-window excess power of each tone measured in the last decided slot.
    pub(super) level: [f64; TONE_COUNT],
    /// Tones present in the last decided slot.
    pub(super) present: [bool; TONE_COUNT],
    /// Noise level during the last decided slot.
    pub(super) noise: f64,
}

// The end test's evidence per data basic makes `EndTest` a few hundred bytes; there is one
// `Stage` per decoder, so boxing it would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Stage {
    /// Waiting for the windows of the first slot.
    Slot1,
    /// The end test after slot 1 or 2.
    EndTest(EndTest),
    /// Waiting for the windows of the second slot.
    Slot2,
    /// The end test after the second slot (ending at this sample) found the sender going
    /// on (`true`) or could not tell: waiting for the second half of a would-be third
    /// slot.
    LateCheckLong(f64, bool),
}

/// Whether tracking can go on with what has been heard, or must wait for more.
enum Step {
    Again,
    Wait,
}

impl Decoder {
    /// Starts following `frame`, found at `scale`.
    pub(super) fn start_tracking(&mut self, frame: Frame, scale: usize) {
        let Some(onset) = self.estimate_onset(frame, scale) else {
            return;
        };
        if matches!(self.failed_transmission, Some((sender, end)) if sender == frame.sender && onset < end)
        {
            self.note(onset, || {
                format!("{frame:?} inside its sender's failed transmission: not tracked")
            });
            return;
        }
        self.note(onset, || format!("found {frame:?} at scale {scale}"));
        self.tracking = Some(Tracking {
            sender: frame.sender,
            data: [frame.data, frame.data],
            scale,
            onset,
            onset_refined: false,
            found_onset: onset,
            stage: Stage::Slot1,
            level: [0.0; TONE_COUNT],
            present: [false; TONE_COUNT],
            noise: 1.0,
        });
        self.advance_tracking();
    }

    /// Moves the tracked transmission on as far as the audio heard allows.
    pub(super) fn advance_tracking(&mut self) {
        while let Some(t) = self.tracking.clone() {
            let step = match t.stage {
                Stage::Slot1 | Stage::Slot2 => self.decide_slot(&t),
                Stage::EndTest(test) => self.end_test(&t, test),
                Stage::LateCheckLong(end, went_on) => self.late_check_long(&t, end, went_on),
            };
            if let Step::Wait = step {
                return;
            }
        }
    }

    /// Decides the tracked transmission's current slot once all its windows are in: the
    /// end test follows a slot that passes; a slot that fails ends the transmission.
    fn decide_slot(&mut self, t: &Tracking) -> Step {
        let first = t.stage == Stage::Slot1;
        let slot_len = self.geometry.slot_samples;
        let quarter = 0.25 * self.geometry.window_len as f64;
        let a = if first { t.onset } else { t.onset + slot_len };
        let b = a + slot_len;
        if self.latest_window_end() < b + quarter && !self.eof {
            return Step::Wait;
        }
        if first && !t.onset_refined {
            self.refine_onset(t);
            return Step::Again;
        }
        let mut a = a;
        let mut b = b;
        let mut decision = self.confirm_slot(t, a, b);
        // A first slot refused at its estimated onset is decided again a hop earlier, up
        // to RETRY_HOPS, on the same frame (sender and data as found). In a reverberant
        // room a frame builds up over its first windows and the onset estimate comes out
        // late (tuning rows 11018, 20015: a quarter of the lost short messages 0.1-0.3 s
        // late); the slot then ends in whatever follows the frame, a talker's vowel or
        // harmonic, and a vote, stray or rival there refuses it. Told the true start, a
        // reference decoder picks every one of those frames (median margin 13 dB; see
        // `evaluation::OracleVerdict`). Every check of a slot still applies to the
        // earlier slot; the search never offers a frame whose data it did not find.
        if first && decision.is_none() {
            let hop = self.geometry.hop as f64;
            // The retry is for a frame found late, not a way past a second robot: a sender
            // that sounded over the slot at the found onset and began inside the earlier
            // slot together with the frame's data (our sender sounding before) is the
            // robot whose data that is. Two robots a fraction of a slot apart (report
            // row 1012031 at 862.52 s: LeftAttacker's long from 862.1 s, Goalkeeper's
            // short from 862.6 s): the found slot had both senders' votes; three hops
            // earlier Goalkeeper's sender, begun 0.1 s into that slot, read one empty
            // window, passed for "not steady", and LeftAttacker's sender was decided with
            // Goalkeeper's data, a wrong message. (Refusing every retry such a sender
            // sounds over cost 17 of that row's 658 messages: beside another robot a frame
            // found late is common, and its data its own.) Looked at only for a retry that
            // passes: most refused first slots have none.
            for j in 1..=RETRY_HOPS {
                let a2 = a - j as f64 * hop;
                if a2 < self.floor as f64 {
                    break;
                }
                let retry = self
                    .confirm_slot(t, a2, a2 + slot_len)
                    .filter(|s| s.frame.sender == t.sender && s.frame.data == t.data[0])
                    .filter(|_| {
                        let rivals = self.rival_senders(t, a, b);
                        let began = self.rival_senders_beginning(t, &rivals, a2, a2 + slot_len);
                        let kept = began.first().copied();
                        if let Some(r) = kept {
                            self.note(a2, || {
                                format!("retry slot 1: sender basic {r} of the found slot began inside it")
                            });
                        }
                        kept.is_none()
                    });
                self.note(a2, || {
                    format!(
                        "retry slot 1 at -{j} hops: {}",
                        if retry.is_some() { "passes" } else { "refused" }
                    )
                });
                if retry.is_some() {
                    if let Some(tr) = self.tracking.as_mut() {
                        tr.onset = a2;
                    }
                    a = a2;
                    b = a2 + slot_len;
                    decision = retry;
                    break;
                }
            }
        }
        // A second slot the checks refused, decided by its data basics' median windows
        // (see `second_slot_by_sums.rs`).
        let decision = match decision {
            None if !first => self.second_slot_by_sums(t, a, b),
            decided => decided,
        };
        let decision = decision.filter(|_| {
            first || {
                let holds = self.second_frame_holds_its_level(t, a, b);
                if !holds {
                    self.note(a, || {
                        "second slot: sender does not hold its level".to_string()
                    });
                }
                holds
            }
        });
        // A first slot inside the failed slot of its sender must decide a frame whose data
        // began with it (see `Decoder::data_begins_later`); otherwise it fails like any
        // first slot, and the replay after it moves on.
        let decision = decision.filter(|slot| {
            let inside_failed = first
                && matches!(self.failed_slot, Some((sender, end)) if sender == t.sender && a < end);
            let later = inside_failed
                .then(|| self.data_begins_later(slot.frame, t.scale, a, b))
                .flatten();
            if let Some(data_onset) = later {
                self.note(a, || {
                    format!(
                        "first slot inside the sender's failed slot: data {} begins at {:.2} s",
                        slot.frame.data,
                        data_onset / self.rate()
                    )
                });
            }
            later.is_none()
        });
        let Some(slot) = decision else {
            // A first slot of the sender just decided, starting within half a tone of that
            // transmission's end, is its reverberant tail (plus babble), not a long
            // message's first frame: by the protocol the sender's next message comes
            // later, and must not be taken for a second frame of this one.
            // A failed second slot ends its transmission (a long message has two frames):
            // a frame after it is not the second half of anything.
            let tail_of_recent = self
                .recent
                .is_some_and(|r| r.frame.sender == t.sender && a - r.end < SPRT_HORIZON * slot_len);
            if first && !tail_of_recent {
                self.failed_slot = Some((t.sender, b));
            }
            if !first
                && !self.second_slot_was_long(t, a, b)
                && (self.sender_stopped_late(t, a) || self.short_stopped_late(t, a))
            {
                // The end test took the first frame's tail for a second frame: it was a
                // short message after all.
                self.report_late_short(t, a);
                return Step::Wait;
            }
            if first {
                // A first slot that fails was someone else's sound (babble, a tail, a
                // burst) or a frame found at the wrong onset: the search resumes just
                // after its onset rather than after the slot, so a message that began
                // during it is still found with its own onset; the failed frame itself
                // is skipped until the slot's end.
                let frame = Frame {
                    sender: t.sender,
                    data: t.data[0],
                };
                self.tracking = None;
                self.blocked = Some(Blocked {
                    frame,
                    scale: t.scale,
                    quiet_below: 0.0,
                    quiet: 0,
                    until: Some(b.max(0.0) as u64),
                    fresh_start: false,
                });
                let window_len = self.geometry.window_len as f64;
                let from = t.found_onset.min(a) - window_len;
                let resume =
                    (from.max(0.0).floor() as u64).max(self.floor + self.geometry.hop as u64);
                self.pending_replay = Some(resume);
            } else {
                // A failed second slot ends its transmission. A message of another robot
                // may have begun during that slot (in a babble hall the end test takes a
                // short message's tail for a continuation now and then, and the second
                // slot is then the tail plus talkers): the search resumes at the second
                // slot's start, as after a failed first slot, so that message is found at
                // its onset rather than at this slot's end. The tracked sender's frames
                // beginning before this end are its own second frame or tail, never a
                // message (a robot leaves half a tone of silence between messages).
                self.end_transmission(b, false);
                self.failed_transmission = Some((t.sender, b));
                self.pending_replay = Some(a.max(0.0).floor() as u64);
            }
            return Step::Wait;
        };
        let mut next = t.clone();
        if first {
            next.onset = a;
        }
        let slot = if first {
            self.refit_scale(&mut next, slot, a, b)
        } else {
            slot
        };
        next.data[if first { 0 } else { 1 }] = slot.frame.data;
        if first {
            next.data[1] = slot.frame.data;
        }
        next.level = slot.level;
        next.present = slot.present;
        next.noise = slot.noise;
        // A frame of data no long message begins with (the checked plan's short data) is
        // no second frame whatever sounded before it: what the sender's tones before the
        // onset were is its own previous message's tail (the robot waited half a tone;
        // short lab T60 1.2 s 0 dB, tuning draws S = 111–122: 8 of the 67 lost short
        // messages were dropped so at some onset, e.g. 114015 at 599.69 s), unless its
        // data was sounding at its level there too: a frame that began before its onset.
        let short_only = first && self.config.team.frame_is_short_only(next.data[0]) && {
            let quarter = 0.25 * self.geometry.slot_samples;
            let data = SENDER_COUNT + usize::from(next.data[0]);
            !self.basic_keeps_level(&next, data, a - quarter, a)
        };
        if first && !short_only && self.continues_earlier_frame(&next, a) {
            self.note(a, || {
                "first slot continues an earlier frame: dropped".to_string()
            });
            self.end_transmission(b, false);
            return Step::Wait;
        }
        let next_index = self.history.front().map(|w| w.index).unwrap_or(0);
        next.stage = Stage::EndTest(EndTest::new(if first { 1 } else { 2 }, b, next_index));
        self.tracking = Some(next);
        Step::Again
    }

    /// After the end test on the second slot (ending at `end`) found the sender going on,
    /// or could not tell: once the second half of a would-be third slot is heard, a
    /// sender plainly silent there makes the two slots a long message; otherwise the
    /// frame sounded too long and is not a message.
    ///
    /// In a hall the second frame's own tail, with babble on its tones, passes for a
    /// continuation now and then (T60 1.2 s at 0 dB in-band: about one long message in
    /// 30 was lost so). Both slots have passed every check by then, and no message of the
    /// protocol has a third frame; what the wait rules out is the sender's next message
    /// (at least half a tone later, so still sounding at the start of the judged span).
    fn late_check_long(&mut self, t: &Tracking, end: f64, went_on: bool) -> Step {
        let slot_len = self.geometry.slot_samples;
        let quarter = 0.25 * self.geometry.window_len as f64;
        if self.latest_window_end() < end + slot_len + quarter && !self.eof {
            return Step::Wait;
        }
        // The sender's next message may begin in the judged span (it waits just over
        // half a tone): its sender tones sound there, its data is another basic. The
        // second frame's data plainly stopped ends the message as well (long lab-1.2
        // 0 dB, tuning draws S = 94–97: 4 of the 57 lost long messages were lost so,
        // both slots passed, the sender's next message found 0.65–0.75 s after).
        let sender_stopped = self.sender_stopped_late(t, end);
        // … once the sender fell silent for the gap a robot leaves between messages (below
        // the second frame's level over the second quarter of a slot after its end):
        // tones that go straight on are a frame that sounded too long, whatever its data.
        let data_stopped = !sender_stopped && self.data_stopped_after_gap(t, t.data[1], end);
        let stopped = sender_stopped || data_stopped;
        self.note(end, || {
            format!("late check after slot 2: stopped {stopped} (data stopped {data_stopped})")
        });
        if stopped {
            let value = 21 * u16::from(t.data[0]) + u16::from(t.data[1]);
            let message = Message::Long {
                sender: t.sender,
                value,
            };
            let decided_at = self.latest_window_end();
            self.report(t, message, end, decided_at);
            self.end_transmission(end, false);
            self.pending_replay = Some(end.max(0.0).floor() as u64);
        } else {
            // As before the wait: a frame that went on is blocked until it stops.
            self.end_transmission(end, went_on);
        }
        Step::Wait
    }

    /// Under the checked plan, whether the failed second slot `[a, b)` of `t` still read as
    /// the same sender with data only a long message's frames carry: the sender was in a
    /// long message, so its first slot, if it decided data of a short, was not the sender's
    /// frame (another robot's data crossed in), and is no short message either.
    ///
    /// Tuning draw 113, row 34 (two robots, hall T60 1.2 s, 10 dB), 735.09 s: the first
    /// slot decided RightAttacker's sender (its long 245 from 734.72 s) with LeftAttacker's
    /// data 6 (from 734.91 s); the second slot read RightAttacker's data 14, its true second
    /// frame, and was refused (not steady); half a slot later the sender had stopped, and
    /// the first frame came out as a wrong short (main's decoder too).
    fn second_slot_was_long(&self, t: &Tracking, a: f64, b: f64) -> bool {
        let plan = self.config.team;
        if !plan.frame_is_short_only(t.data[0]) {
            return false;
        }
        let Some(slot) = self.integrate_slot(t.scale, a, b) else {
            return false;
        };
        let own = Some(t.sender.index() as usize);
        let by_rules = Self::apply_rules(
            &slot.sums,
            slot.count,
            P_TONE_CONFIRM,
            P_TONE_RIVAL,
            own,
            |_, _| true,
        )
        .0;
        let frame = by_rules.or_else(|| self.second_slot_rules(t, a, b).map(|(f, _)| f));
        let long = frame.is_some_and(|f| f.sender == t.sender && plan.frame_is_long_only(f.data));
        if long {
            self.note(a, || {
                format!(
                    "second slot read data {} of a long message: no late short",
                    frame.map_or(0, |f| f.data)
                )
            });
        }
        long
    }

    /// Reports the first slot of `t`, ending at `end`, as a short message decided late,
    /// and searches again from its end (a message that began meanwhile is still found at
    /// its onset).
    fn report_late_short(&mut self, t: &Tracking, end: f64) {
        let message = Message::Short {
            sender: t.sender,
            data: t.data[0],
        };
        let decided_at = self.latest_window_end();
        self.report(t, message, end, decided_at);
        self.end_transmission(end, false);
        self.pending_replay = Some(end.max(0.0).floor() as u64);
    }

    /// The sender basics other than `t`'s with two tones present over `[a, b)` (the
    /// confirming level, leakage from a louder neighbour left out).
    fn rival_senders(&self, t: &Tracking, a: f64, b: f64) -> Vec<usize> {
        let Some(slot) = self.integrate_slot(t.scale, a, b) else {
            return Vec::new();
        };
        let n = slot.count.max(1) as f64;
        let floor = gamma_upper_quantile(n, P_TONE_CONFIRM);
        let own = t.sender.index() as usize;
        (0..SENDER_COUNT)
            .filter(|&s| s != own)
            .filter(|&s| {
                basic_tones(s)
                    .iter()
                    .filter(|&&k| slot.sums[k] >= floor && !is_leakage(&slot.sums, n, k))
                    .count()
                    >= 2
            })
            .collect()
    }

    /// Of the sender basics `rivals`, those that began inside `[a, b)`: their two loudest
    /// tones over the slot's first fifth below [`RIVAL_BEGAN_SHARE`] of their level over
    /// the slot.
    fn rival_senders_beginning(
        &self,
        t: &Tracking,
        rivals: &[usize],
        a: f64,
        b: f64,
    ) -> Vec<usize> {
        let (Some(slot), Some(early)) = (
            self.integrate_slot(t.scale, a, b),
            self.integrate_slot(t.scale, a, a + 0.2 * (b - a)),
        ) else {
            return Vec::new();
        };
        let began = |basic: usize| {
            let mut tones = basic_tones(basic);
            tones.sort_by(|&x, &y| slot.level[y].total_cmp(&slot.level[x]));
            let level: f64 = tones[..2].iter().map(|&k| slot.level[k]).sum();
            let before: f64 = tones[..2].iter().map(|&k| early.level[k]).sum();
            level > 0.0 && before < RIVAL_BEGAN_SHARE * level
        };
        // Only where the frame's data began inside the slot with it, and the frame's
        // sender did not: the data is the other robot's.
        if !began(SENDER_COUNT + usize::from(t.data[0])) || began(t.sender.index() as usize) {
            return Vec::new();
        }
        rivals.iter().copied().filter(|&r| began(r)).collect()
    }

    /// Re-estimates the onset once the whole first slot has been heard. Tracking can start
    /// two windows into a loud frame, when the edge refinement has a plateau of two noisy
    /// windows to go by; a first slot that starts late catches the second frame's data as
    /// a rival.
    fn refine_onset(&mut self, t: &Tracking) {
        let frame = Frame {
            sender: t.sender,
            data: t.data[0],
        };
        let onset = self.estimate_onset(frame, t.scale).unwrap_or(t.onset);
        if let Some(tr) = self.tracking.as_mut() {
            tr.onset = onset;
            tr.onset_refined = true;
        }
    }

    /// Moves the end test after a slot on; acts on its verdict when there is one.
    fn end_test(&mut self, t: &Tracking, mut test: EndTest) -> Step {
        let Some((continues, decided_at)) = self.decide_end(t, &mut test) else {
            if let Some(tr) = self.tracking.as_mut() {
                tr.stage = Stage::EndTest(test);
            }
            return Step::Wait;
        };
        let decided_at = decided_at.unwrap_or_else(|| self.latest_window_end());
        let slot_end = test.slot_end;
        self.note(slot_end, || {
            format!("end test after slot {}: {continues:?}", test.slot)
        });
        match (test.slot, continues) {
            (1, EndVerdict::Unclear) => {
                // The sender went on but no data basic did at the first frame's level (in
                // a hall each tone has its own level: a second frame's data in a notch of
                // the room sounds 10-20 dB below the first's): the second slot is decided
                // on its own evidence, as after "continues". A second frame that passes
                // every check of a slot, and holds the sender's level through its second
                // half, is one; a second slot that fails falls back to the late check a
                // failed second slot gets (a sender plainly silent half a slot on makes
                // the first slot a short message), as the wait here did. Lab T60 2.0 s at
                // 0 dB, tuning rows 11027, 14027, 15027: 25 of 105 lost long messages
                // ended here, their second frame found later by the search and dropped
                // as the continuation of an earlier frame.
                if let Some(tr) = self.tracking.as_mut() {
                    tr.stage = Stage::Slot2;
                }
            }
            (1, EndVerdict::Stopped) => {
                let message = Message::Short {
                    sender: t.sender,
                    data: t.data[0],
                };
                self.report(t, message, slot_end, decided_at);
                self.end_transmission(slot_end, false);
            }
            (1, EndVerdict::Continues) => {
                if let Some(tr) = self.tracking.as_mut() {
                    tr.stage = Stage::Slot2;
                }
            }
            (_, verdict @ (EndVerdict::Unclear | EndVerdict::Continues)) => {
                // A long message has two frames: a sender going on past them is the
                // second frame's tail, or not a message (see `late_check_long`).
                if let Some(tr) = self.tracking.as_mut() {
                    tr.stage = Stage::LateCheckLong(slot_end, verdict == EndVerdict::Continues);
                }
            }
            (_, EndVerdict::Stopped) => {
                let value = 21 * u16::from(t.data[0]) + u16::from(t.data[1]);
                let message = Message::Long {
                    sender: t.sender,
                    value,
                };
                self.report(t, message, slot_end, decided_at);
                self.end_transmission(slot_end, false);
            }
        }
        Step::Again
    }

    fn report(&mut self, t: &Tracking, message: Message, end: f64, decided_at: f64) {
        let rate = self.rate();
        let median = median(
            (0..TONE_COUNT)
                .filter(|&k| t.present[k])
                .map(|k| t.level[k])
                .collect(),
        );
        self.note(end, || {
            format!(
                "report {message} (plan allows: {})",
                self.config.team.decode(&message).is_some()
            )
        });
        let detection = Detection {
            message,
            start_s: t.onset / rate,
            end_s: end / rate,
            decided_at_s: decided_at / rate,
            frequency_scale: 1.0 + self.geometry.scales[t.scale],
            tone_snr_db: 10.0 * median.max(1e-12).log10(),
        };
        if self.config.team.decode(&message).is_none() {
            // Not a message of the team's plan (e.g. data 20, or a long message across
            // two banks of the six-robot plan): someone else's, or a wrong decision.
            if self.refused.len() >= super::REFUSED_KEPT {
                self.refused.pop_front();
            }
            self.refused.push_back(detection);
            return;
        }
        self.output.push_back(detection);
    }

    /// The rules on a long message's second slot `[a, b)` of `t`, for when the seed's rules
    /// (see `Decoder::apply_rules`) refused it: the frame it sounds, and the tones present.
    ///
    /// The two frames of a long message come from one transmitter through one room, and
    /// the sender is already known from the first slot. In a T60 2.0 s lab a sender sounds
    /// one loud tone and one 15-25 dB below it (a notch of the room); in the first slot
    /// that weak tone counted, in the second the rules' relative tests (25 dB below the
    /// loudest tone, or a crowd's range) measured it against the second frame's data
    /// tones, which sounded louder, and the sender lost its vote at the same level (lab
    /// T60 2.0 s at 0 dB, tuning rows 11027, 14027, 15027: 16 of 25 second slots refused
    /// by the rules, e.g. k49 at 14 per window in both slots against k41 at 8,060). And
    /// the first frame's data rings on into the second slot: at T60 2.0 s a third of a
    /// second later still within 10 dB, so it was a rival data basic now and then.
    ///
    /// So, on the second slot: a sender tone that was present in the first slot counts
    /// when it stands out of the noise (the Gamma quantile at [`P_TONE_CONFIRM`]), is no
    /// neighbour's leakage and keeps [`SECOND_SLOT_SENDER_SHARE`] of its first-slot level;
    /// the first frame's data basic is no rival when it dies away through the slot (its
    /// tail, [`ECHO_HALF_SHARE`]); and then exactly one data basic must have two of its
    /// tones present, and no other sender basic two of its own at [`P_TONE_RIVAL`]
    /// (stricter than the rules, which let a weak rival go). The frame still goes through
    /// every check of a slot after this (frame energy, sounding through, each vote in each
    /// half, above its neighbours, steady, strays, one scale), and the sender must hold its
    /// level through the slot's second half. A first frame's data alone, dying away, is
    /// never a second frame: a long message whose second data cannot be told is lost, not
    /// decoded with the first frame's data twice.
    pub(super) fn second_slot_rules(
        &self,
        t: &Tracking,
        a: f64,
        b: f64,
    ) -> Option<(Frame, [bool; TONE_COUNT])> {
        let slot = self.integrate_slot(t.scale, a, b)?;
        let (sums, count) = (&slot.sums, slot.count);
        let n = count.max(1) as f64;
        let own = t.sender.index() as usize;
        let (_, mut present) = Self::apply_rules(
            sums,
            count,
            P_TONE_CONFIRM,
            P_TONE_RIVAL,
            Some(own),
            |_, _| true,
        );
        let threshold = gamma_upper_quantile(n, P_TONE_CONFIRM);
        let rival_threshold = gamma_upper_quantile(n, P_TONE_RIVAL);
        let excess = |k: usize| sums[k] - n;
        // The sender's tones, on the first slot's noise level.
        let to_first = slot.noise / t.noise;
        for k in basic_tones(own) {
            if !t.present[k] || t.level[k] <= 0.0 || present[k] {
                continue;
            }
            let level = excess(k) / n * to_first;
            let spread = ((1.0 + 2.0 * t.level[k]) / n).sqrt();
            present[k] = sums[k] >= threshold
                && !is_leakage(sums, n, k)
                && level >= SECOND_SLOT_SENDER_SHARE * t.level[k] - SECOND_SLOT_SENDER_Z * spread;
        }
        let votes = |present: &[bool; TONE_COUNT], b: usize| {
            basic_tones(b).iter().filter(|&&k| present[k]).count()
        };
        if votes(&present, own) < 2 {
            return None;
        }
        let strong = |b: usize| {
            basic_tones(b)
                .iter()
                .filter(|&&k| present[k] && sums[k] >= rival_threshold)
                .count()
        };
        if (0..SENDER_COUNT).any(|b| b != own && strong(b) >= 2) {
            return None;
        }
        // The first frame's data dying away through the slot: its tail.
        let first_data = SENDER_COUNT + usize::from(t.data[0]);
        let echo = self.dies_away(t, first_data, a, b, &slot.level);
        if echo {
            for k in basic_tones(first_data) {
                present[k] = false;
            }
        }
        let data: Vec<usize> = (SENDER_COUNT..BASIC_COUNT)
            .filter(|&b| votes(&present, b) >= 2)
            .collect();
        let data = self.second_data_that_sound(t, data, &present, sums, count, a, b);
        let &[d] = data.as_slice() else {
            return None;
        };
        let frame = Frame {
            sender: t.sender,
            data: (d - SENDER_COUNT) as u8,
        };
        self.note(a, || {
            format!(
                "second slot by the first: {frame:?} (first data's tail {})",
                if echo { "let go" } else { "none" }
            )
        });
        Some((frame, present))
    }

    /// Whether basic `basic`'s tones in the second slot `[a, b)` of `t` (per-window excess
    /// `level` over the slot) are the first slot's tail: below
    /// [`SECOND_SLOT_SENDER_SHARE`] of their first-slot level, and falling from the slot's
    /// first half to its second below [`ECHO_HALF_SHARE`].
    pub(super) fn dies_away(
        &self,
        t: &Tracking,
        basic: usize,
        a: f64,
        b: f64,
        level: &[f64],
    ) -> bool {
        let tones = basic_tones(basic);
        let now: f64 = tones.iter().map(|&k| level[k]).sum();
        let before: f64 = tones.iter().map(|&k| t.level[k]).sum();
        if before <= 0.0 || now >= SECOND_SLOT_SENDER_SHARE * before {
            return false;
        }
        let mid = 0.5 * (a + b);
        let half = |from: f64, to: f64| -> Option<f64> {
            let s = self.integrate_slot(t.scale, from, to)?;
            Some(tones.iter().map(|&k| s.level[k]).sum())
        };
        match (half(a, mid), half(mid, b)) {
            (Some(early), Some(late)) => late < ECHO_HALF_SHARE * early,
            _ => false,
        }
    }

    /// The tones of the first frame's data basic that are its reverberant tail in the
    /// second slot `[a, b)` of `t` (per-window excess `level` over the slot), tone by
    /// tone: quieter than in the first slot and falling from the slot's first half to its
    /// second below [`ECHO_HALF_SHARE`] (a tone that holds never does). Such a tone is
    /// the first frame's own, known to be ours and dying away, and is no stray of someone
    /// else's signal in the second slot (see `Decoder::has_stray_tone`).
    ///
    /// At T60 1.2 s a first frame's loud data tone still sounds in the second slot at a
    /// twentieth of its level, steadily falling, often as loud as the second frame's
    /// median tone (long lab-1.2 0 dB, tuning row 22021: 5 of 16 second slots refused as
    /// "stray tone" were refused for the first data's tail alone, e.g. 2811.69 s: k37 at
    /// 2,515 per window in the first slot, 122 in the second, 1.9 times the second frame's
    /// median tone). Every tone of any other basic is judged as before, and a tone that
    /// holds its level is never let go.
    pub(super) fn first_data_tail(
        &self,
        t: &Tracking,
        a: f64,
        b: f64,
        level: &[f64; TONE_COUNT],
    ) -> [bool; TONE_COUNT] {
        let mut tail = [false; TONE_COUNT];
        if t.stage != Stage::Slot2 {
            return tail;
        }
        let tones = basic_tones(SENDER_COUNT + usize::from(t.data[0]));
        let fading: Vec<usize> = tones
            .iter()
            .copied()
            .filter(|&k| t.level[k] > 0.0 && level[k] < t.level[k])
            .collect();
        if fading.is_empty() {
            return tail;
        }
        let mid = 0.5 * (a + b);
        let (Some(early), Some(late)) = (
            self.integrate_slot(t.scale, a, mid),
            self.integrate_slot(t.scale, mid, b),
        ) else {
            return tail;
        };
        for k in fading {
            tail[k] = early.level[k] > 0.0 && late.level[k] < ECHO_HALF_SHARE * early.level[k];
        }
        tail
    }

    /// Moves the tracked transmission `next` to the frequency scale its decided first slot
    /// `[a, b)` sounds at (the scale at which the present tones of `slot`'s frame hold the
    /// most excess power over the slot's windows), re-measuring the slot's levels there;
    /// the end test and the second slot are then read at that scale. The same scale when
    /// no other reads more.
    ///
    /// The search finds a frame at the scale its coarse sums peak at, and those sums also
    /// hold whatever sounded before the frame, in a room the tail of the previous message
    /// (another robot, another clock). The first slot's checks look for a common scale of
    /// their own (see `Decoder::has_off_grid_tone`), so a first slot passes where its
    /// tones sit a few scales from the found one; the second slot, read at the found
    /// scale, then lost a few dB on every tone and failed the off-grid test or a vote
    /// (long lab-1.2 0 dB, tuning rows 82021–87021: 5 of the 16 second slots refused as
    /// off grid read 3–40 times more on their tones at another scale, e.g. 85021 at
    /// 28.59 s: k46 at 197 on the found scale against 5,084 at its best). A sender's clock
    /// does not move between its two frames.
    fn refit_scale(
        &self,
        next: &mut Tracking,
        slot: super::confirm::SlotDecision,
        a: f64,
        b: f64,
    ) -> super::confirm::SlotDecision {
        let window_len = self.geometry.window_len as f64;
        let tones: Vec<usize> = slot
            .frame
            .tones()
            .into_iter()
            .filter(|&k| slot.present[k])
            .collect();
        let mut totals = vec![0.0f64; self.geometry.scale_count()];
        for w in &self.history {
            if hann_share_inside(w.start as f64, window_len, a, b) < 0.9 {
                continue;
            }
            for (j, total) in totals.iter_mut().enumerate() {
                *total += Self::excess(w, j, &tones);
            }
        }
        let Some(best) = (0..totals.len()).max_by(|&x, &y| totals[x].total_cmp(&totals[y])) else {
            return slot;
        };
        // Neighbouring scales that put every tone in the same bins read alike: only a
        // scale that reads more moves the tracking.
        if totals[best] <= totals.get(next.scale).copied().unwrap_or(f64::INFINITY) {
            return slot;
        }
        let Some(sums) = self.integrate_slot(best, a, b) else {
            return slot;
        };
        self.note(a, || {
            format!(
                "scale refit {} -> {best} ({:.0} -> {:.0})",
                next.scale, totals[next.scale], totals[best]
            )
        });
        next.scale = best;
        super::confirm::SlotDecision {
            level: sums.level,
            noise: sums.noise,
            ..slot
        }
    }

    /// Closes the tracked transmission at `end`; `too_long` blocks its frame until it stops.
    fn end_transmission(&mut self, end: f64, too_long: bool) {
        if let Some(t) = self.tracking.take() {
            // Also after a decided transmission: in a hall its frame goes on as a
            // reverberant tail, which the search would find again (and fail on), so the
            // frame is not searched for until it has fallen quiet.
            if too_long || t.level.iter().any(|&l| l > 0.0) {
                let frame = Frame {
                    sender: t.sender,
                    data: t.data[1],
                };
                let tones = frame.tones();
                let level: f64 = tones.iter().map(|&k| t.level[k]).sum();
                self.blocked = Some(if too_long {
                    Blocked {
                        frame,
                        scale: t.scale,
                        quiet_below: 0.25 * level,
                        quiet: 0,
                        until: None,
                        fresh_start: true,
                    }
                } else {
                    self.recent = Some(Recent {
                        frame,
                        level,
                        end,
                        until: (end + RECENT_SLOTS * self.geometry.slot_samples).max(0.0) as u64,
                    });
                    // A tail is quiet 25 dB down or within noise (2.5 σ of six tones'
                    // excess); the same frame sent again (by the protocol at least half a
                    // tone later) is searched for from then on at the latest (the decay
                    // check keeps the search off the tail that may still sound).
                    Blocked {
                        frame,
                        scale: t.scale,
                        quiet_below: (TAIL_QUIET * level).max(TAIL_NOISE_EXCESS),
                        quiet: 0,
                        until: Some((end + 0.5 * self.geometry.slot_samples).max(0.0) as u64),
                        fresh_start: true,
                    }
                });
            }
        }
        self.reset_sliding(end.max(0.0).floor() as u64);
    }
}

#[cfg(test)]
#[path = "tests/retry.rs"]
mod retry_tests;
