//! A long message's second slot decided by its data basics' median windows, once the
//! checks of a slot refused it: the sender and the timing are known, and what is left
//! is which of the plan's long-frame data basics sounds there.

use super::confirm::{SlotDecision, P_TONE_RIVAL};
use super::tracking::{Stage, Tracking};
use super::{median, Decoder};
use crate::significance::{gamma_upper_quantile, hann_share_inside};
use crate::tones::{basic_tones, Frame, DATA_VALUES, SENDER_COUNT};

/// Least factor by which the picked data basic's median window (the excess of its three
/// tones) must exceed every other candidate's.
const BY_SUMS_MARGIN: f64 = 4.0;
/// Least median window of the picked data basic (excess of its three tones per window,
/// noise 1 per tone): clear of the noise, whose three-tone median is about −0.3.
const BY_SUMS_FLOOR: f64 = 3.0;
/// The other candidates' median windows count as at least this much against the margin.
const BY_SUMS_RIVAL_FLOOR: f64 = 1.0;
/// Least share of its median window over the whole slot the picked basic must hold over
/// each half of it.
const BY_SUMS_HALF_SHARE: f64 = 0.3;

impl Decoder {
    /// The second slot `[a, b)` of the tracked long message `t`, refused by the checks of
    /// a slot, decided by its data basics' **median windows**: under a plan whose long
    /// frames say data of their own ([`crate::TeamPlan::Checked`]: 11 basics), the data
    /// basic whose three tones' per-window excess has the largest median, at least
    /// [`BY_SUMS_MARGIN`] times every other candidate's and [`BY_SUMS_FLOOR`] clear of
    /// the noise, holding in each half of the slot.
    ///
    /// Why: on the long lab T60 1.2 s 0 dB row (four talkers), tuning draws S = 94–97,
    /// 43 of the 57 lost long messages were lost on the second slot, the first passed:
    /// sender, scale and timing known, the second frame refused by a check that guards a
    /// first slot against what is not a frame at all (a stray tone, a vote not steady,
    /// no data basic with two votes when the data's tones sit in the room's notches).
    /// Told the timing, a reference decoder picks nearly every one of them by the median
    /// window (`evaluation::oracle`). The median lets a talker's passing harmonic go; a
    /// tone in a notch still adds its share.
    ///
    /// What it never takes: a slot where the sender does not keep its level through each
    /// half (the tail of a short message, a gap before the sender's next message);
    /// another sender basic sounding (two tones at the rival level) or beginning with
    /// the slot (another robot, see `Decoder::sender_began_with_slot`); data that began
    /// before the slot (another robot's frame, see `Decoder::second_data_began_before`);
    /// the first frame's data dying away (its tail), which is left out of the
    /// candidates, and that data again unless it keeps its level (a repeat).
    pub(super) fn second_slot_by_sums(&self, t: &Tracking, a: f64, b: f64) -> Option<SlotDecision> {
        if t.stage != Stage::Slot2 {
            return None;
        }
        let plan = self.config.team;
        let candidates: Vec<u8> = (0..DATA_VALUES)
            .filter(|&d| plan.frame_is_long_only(d))
            .collect();
        if candidates.len() < 2 {
            return None;
        }
        let mid = 0.5 * (a + b);
        if !self.sender_keeps_level(t, a, mid) || !self.sender_keeps_level(t, mid, b) {
            return None;
        }
        let slot = self.integrate_slot(t.scale, a, b)?;
        let n = slot.count.max(1) as f64;
        let rival = gamma_upper_quantile(n, P_TONE_RIVAL);
        let own = t.sender.index() as usize;
        let strong = |s: usize| {
            basic_tones(s)
                .iter()
                .filter(|&&k| slot.sums[k] >= rival)
                .count()
        };
        if (0..SENDER_COUNT).any(|s| s != own && strong(s) >= 2) {
            return None;
        }
        let window_len = self.geometry.window_len as f64;
        let median_window = |basic: usize, from: f64, to: f64| -> Option<f64> {
            let tones = basic_tones(basic);
            let values: Vec<f64> = self
                .history
                .iter()
                .filter(|w| hann_share_inside(w.start as f64, window_len, from, to) >= 0.9)
                .map(|w| Self::excess(w, t.scale, &tones))
                .collect();
            (values.len() >= 2).then(|| median(values))
        };
        let first = SENDER_COUNT + usize::from(t.data[0]);
        let first_is_tail = self.dies_away(t, first, a, b, &slot.level);
        let mut scored: Vec<(u8, f64)> = Vec::with_capacity(candidates.len());
        for &d in &candidates {
            let basic = SENDER_COUNT + usize::from(d);
            if basic == first && first_is_tail {
                continue;
            }
            scored.push((d, median_window(basic, a, b)?));
        }
        scored.sort_by(|x, y| y.1.total_cmp(&x.1));
        let (&(data, best), rest) = scored.split_first()?;
        let next = rest.first().map_or(0.0, |r| r.1).max(BY_SUMS_RIVAL_FLOOR);
        let basic = SENDER_COUNT + usize::from(data);
        let halves = (median_window(basic, a, mid)?, median_window(basic, mid, b)?);
        let holds_halves =
            halves.0 >= BY_SUMS_HALF_SHARE * best && halves.1 >= BY_SUMS_HALF_SHARE * best;
        let repeat_holds = basic != first || self.basic_keeps_level(t, basic, mid, b);
        let frame = Frame {
            sender: t.sender,
            data,
        };
        let mut present = [false; crate::tones::TONE_COUNT];
        let floor = gamma_upper_quantile(n, super::confirm::P_TONE_CONFIRM);
        for k in basic_tones(own).into_iter().chain(basic_tones(basic)) {
            present[k] = slot.sums[k] >= floor;
        }
        let verdict = if best < BY_SUMS_FLOOR {
            Some("too faint")
        } else if best < BY_SUMS_MARGIN * next {
            Some("no margin")
        } else if !holds_halves {
            Some("not in both halves")
        } else if !repeat_holds {
            Some("the first data, not holding its level")
        } else if self
            .sender_began_with_slot(t, frame, &slot.sums, slot.count, a, b)
            .is_some()
        {
            Some("another sender began with it")
        } else if basic != first
            && self
                .second_data_began_before(t, data, &present, a, b)
                .is_some()
        {
            Some("data began before the slot")
        } else {
            None
        };
        self.note(a, || {
            format!(
                "second slot by sums: data {data} median {best:.1} (halves {:.1} {:.1}), next {:.1}: {}",
                halves.0,
                halves.1,
                rest.first().map_or(0.0, |r| r.1),
                verdict.unwrap_or("decided")
            )
        });
        if verdict.is_some() {
            return None;
        }
        Some(SlotDecision {
            frame,
            present,
            level: slot.level,
            noise: slot.noise,
        })
    }
}
