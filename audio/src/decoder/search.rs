//! The search while nothing is tracked: after each window, the best frame of the sliding
//! sums at any scale must pass the frame-energy gate and the rules, twice in a row, to be
//! tracked. A frame that sounded too long is skipped until it stops.

use super::Decoder;
use crate::tones::{basic_tones, Frame, BASIC_COUNT, SENDER_COUNT, TONE_COUNT};

/// Per-tone false-alarm probability of "present" on one slot's integrated sum while
/// searching. It only triggers the slot decision (the frame-energy test at
/// [`P_FRAME_CONFIRM`](super::confirm::P_FRAME_CONFIRM) there carries the protection
/// against noise), so it is as lenient as
/// [`P_TONE_CONFIRM`](super::confirm::P_TONE_CONFIRM): a stricter one would, at
/// low SNR, now and then miss 2 of the 3 tones of a real frame's basic in every candidate
/// window, and the frame would never be tracked.
pub(super) const P_TONE: f64 = 1e-2;
/// Per-window false-alarm probability of the frame-energy detector (before the rules).
pub(super) const P_FRAME: f64 = 1e-6;

/// The same valid frame found in consecutive windows.
#[derive(Clone, Copy, Debug)]
pub(super) struct Run {
    frame: Frame,
    count: u32,
}

impl Decoder {
    /// Looks for a frame in the sliding sums; the second window in a row that finds the
    /// same one starts tracking it.
    pub(super) fn detect(&mut self) {
        let count = self.sliding_count;
        if count == 0 {
            self.run = None;
            return;
        }
        let scales = self.geometry.scale_count();
        let mut best = (f64::NEG_INFINITY, 0usize);
        for j in 0..scales {
            let s = &self.sliding[j * TONE_COUNT..(j + 1) * TONE_COUNT];
            let basic = |b: usize| -> f64 { basic_tones(b).iter().map(|&k| s[k]).sum() };
            let sender = (0..SENDER_COUNT)
                .map(basic)
                .fold(f64::NEG_INFINITY, f64::max);
            let data = (SENDER_COUNT..BASIC_COUNT)
                .map(basic)
                .fold(f64::NEG_INFINITY, f64::max);
            if sender + data > best.0 {
                best = (sender + data, j);
            }
        }
        let threshold = self.frame_threshold(count, P_FRAME);
        if best.0 < threshold {
            self.run = None;
            return;
        }
        let j = best.1;
        let (frame, _p) = Self::apply_rules(
            &self.sliding[j * TONE_COUNT..(j + 1) * TONE_COUNT],
            count,
            P_TONE,
            P_TONE,
        );
        super::trace!("detect w={} e={:.0} thr={:.0} frame {:?} present {:?}", self.windows_seen, best.0, threshold, frame, (0..TONE_COUNT).filter(|&k| _p[k]).collect::<Vec<_>>());
        let Some(frame) = frame else {
            self.run = None;
            return;
        };
        if matches!(self.blocked, Some(b) if b.frame == frame) {
            self.run = None;
            return;
        }
        let run = match self.run {
            Some(r) if r.frame == frame => Run {
                frame,
                count: r.count + 1,
            },
            _ => Run { frame, count: 1 },
        };
        self.run = Some(run);
        if run.count >= 2 {
            self.start_tracking(frame, j);
        }
    }

    /// Unblocks a blocked frame once its tones have fallen below its quiet level in two
    /// windows in a row, or at its deadline.
    pub(super) fn update_blocked(&mut self) {
        let Some(b) = self.blocked else {
            return;
        };
        let Some(rec) = self.history.back() else {
            return;
        };
        let x = Self::excess(rec, b.scale, &b.frame.tones());
        let quiet = if x < b.quiet_below { b.quiet + 1 } else { 0 };
        let expired = b.until.is_some_and(|u| rec.start >= u);
        self.blocked = if quiet >= 2 || expired {
            // The windows summed so far hold the frame's loud tail: integrate afresh from
            // here unless another frame is already being found.
            if self.run.is_none() && self.tracking.is_none() {
                let start = rec.start;
                self.reset_sliding(start);
            }
            None
        } else {
            Some(Blocked { quiet, ..b })
        };
    }
}

/// A frame the search skips (see [`Decoder::update_blocked`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct Blocked {
    pub(super) frame: Frame,
    pub(super) scale: usize,
    /// Six-tone excess per window below which a window counts as quiet.
    pub(super) quiet_below: f64,
    /// Quiet windows in a row so far.
    pub(super) quiet: u32,
    /// Window start (sample) from which the block lifts regardless.
    pub(super) until: Option<u64>,
}
