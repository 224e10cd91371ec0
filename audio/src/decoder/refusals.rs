//! A first slot refused for a foreign sound under it is remembered over its span: the
//! same frame found again a few windows later, over nearly the same audio, is refused
//! too. Two robots sounding a few hundredths of a second apart give a slot of one robot's
//! sender and the other's data; a check that sees the second transmitter at one onset
//! (tones off the frame's common scale, a basic that began apart, a second sender basic)
//! can miss it at an onset one window later, where the windows at the slot's edges
//! differ. Which data is whose is no clearer there than it was.

use super::Decoder;
use crate::tones::Frame;

/// How many refusals are remembered (the latest ones).
const REMEMBERED: usize = 4;

/// How far (share of a slot) the onset of the same frame found again may lie from the
/// refused one's to be refused too: a quarter, the coherence checks' own resolution
/// (`coherence.rs`), fixed before any row was run. On check row 990036 the refused slot
/// came back 0.06 s later and passed as a wrong message.
const RECALL_SHARE: f64 = 0.25;

/// Refusal reasons of `Decoder::confirm_slot` that say a foreign sound is under the frame
/// (rather than that the onset or the level was wrong).
pub(super) const FOREIGN_REASONS: [&str; 3] =
    ["basics not together", "a second transmitter", "off grid"];

/// A first slot refused for a foreign sound.
#[derive(Clone, Copy, Debug)]
pub(super) struct Refusal {
    /// The frame the rules decided there.
    frame: Frame,
    /// The slot's first sample.
    a: f64,
    /// The frequency scale the frame was found at.
    scale: usize,
    /// The onset of the tracking that decided it (its retries share it).
    tracking_onset: f64,
    /// Why it was refused.
    why: &'static str,
}

/// The latest refusals, newest last.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Refusals([Option<Refusal>; REMEMBERED]);

impl Decoder {
    /// Remembers that the first slot at `a` of the tracking from `tracking_onset` (found
    /// at `scale`) decided `frame` and was refused for `why`, when that is a foreign sound.
    pub(super) fn remember_refusal(
        &self,
        frame: Frame,
        a: f64,
        tracking_onset: f64,
        scale: usize,
        why: &'static str,
    ) {
        if !FOREIGN_REASONS.contains(&why) {
            return;
        }
        let mut list = self.refusals.get();
        list.0.rotate_left(1);
        list.0[REMEMBERED - 1] = Some(Refusal {
            frame,
            a,
            scale,
            tracking_onset,
            why,
        });
        self.refusals.set(list);
    }

    /// A remembered refusal of `frame` by another tracking (found earlier, then dropped)
    /// at an onset within the recall distance of `a`: the reason, and how far it was. An
    /// `off grid` refusal is a verdict on the scale the frame was found at, so it is
    /// recalled only by a tracking found at the same `scale`: one robot's frame found a
    /// bin off its own scale is refused off grid and passes when found on it (tuning rows
    /// 11015 at 1757.80 s, scale 19 then 20, and 20021 at 1316.49 s, 19 then 18, lost
    /// with every refusal recalled), while the two robots' frame of check row 990036 came
    /// back at its scale (23).
    pub(super) fn recalled_refusal(
        &self,
        frame: Frame,
        a: f64,
        tracking_onset: f64,
        scale: usize,
    ) -> Option<(&'static str, f64)> {
        let recall = RECALL_SHARE * self.geometry.slot_samples;
        self.refusals
            .get()
            .0
            .iter()
            .flatten()
            .filter(|r| r.frame == frame && r.tracking_onset != tracking_onset)
            .filter(|r| r.why != "off grid" || r.scale == scale)
            .find(|r| (r.a - a).abs() <= recall)
            .map(|r| (r.why, (a - r.a) / self.rate()))
    }
}
