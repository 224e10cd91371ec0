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
        let (frame, _) = Self::apply_rules(
            &self.sliding[j * TONE_COUNT..(j + 1) * TONE_COUNT],
            count,
            P_TONE,
            P_TONE,
        );
        let Some(frame) = frame else {
            self.run = None;
            return;
        };
        if matches!(self.blocked, Some((b, ..)) if b == frame) {
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

    /// Unblocks a frame that sounded too long once its tones have fallen quiet in two
    /// windows in a row.
    pub(super) fn update_blocked(&mut self) {
        let Some((frame, scale, level, quiet)) = self.blocked else {
            return;
        };
        let Some(rec) = self.history.back() else {
            return;
        };
        let x = Self::excess(rec, scale, &frame.tones());
        let quiet = if x < 0.25 * level { quiet + 1 } else { 0 };
        self.blocked = if quiet >= 2 {
            None
        } else {
            Some((frame, scale, level, quiet))
        };
    }
}
