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

/// A newest window below this share of the summed windows' mean excess is a decaying
/// tail, not a sounding frame (see [`Decoder::decaying`]).
const DECAYING_SHARE: f64 = 0.8;
/// Least windows per tone for the decay check (about half a second of tone).
const DECAYING_MIN_WINDOWS: usize = 6;
/// Noise allowance of the decay check, standard deviations of six tones' excess.
const DECAYING_NOISE_Z: f64 = 2.0;

/// A frame just decided found again at less than this share of its level (−10 dB) is its
/// tail (see [`Decoder::decaying`]).
const RECENT_TAIL_SHARE: f64 = 0.1;

/// The frame of the last decided transmission, for [`Decoder::decaying`].
#[derive(Clone, Copy, Debug)]
pub(super) struct Recent {
    pub(super) frame: Frame,
    /// Its six tones' per-window excess when it was decided.
    pub(super) level: f64,
    /// Where its transmission ended (sample).
    pub(super) end: f64,
    /// Window start (sample) from which it is forgotten (a tail is gone by then).
    pub(super) until: u64,
}

/// Why a frame found is not tracked yet (see [`Decoder::decaying`]).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Decay {
    /// The tail of the transmission just decided.
    TailOfRecent,
    /// Its newest window falls below the windows summed.
    Falling,
}

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
            self.note_search(|| format!("gate {:.0} of {threshold:.0}", best.0));
            self.run = None;
            return;
        }
        let j = best.1;
        let sums = &self.sliding[j * TONE_COUNT..(j + 1) * TONE_COUNT];
        let (frame, present) = Self::apply_rules(sums, count, P_TONE, P_TONE, None, |_, _| true);
        let frame = frame.or_else(|| {
            let leader = clear_leader(sums, count, &present);
            if let Some(f) = leader {
                self.note_search(|| format!("leader {f:?}"));
            }
            leader
        });
        let frame = frame.or_else(|| {
            let found = sender_below_crowd(sums, count, &present);
            if let Some(f) = found {
                self.note_search(|| format!("sender below the crowd {f:?}"));
            }
            found
        });
        let Some(frame) = frame else {
            self.note_search(|| {
                let voted = |r: std::ops::Range<usize>| -> Vec<usize> {
                    r.filter(|&b| basic_tones(b).iter().filter(|&&k| present[k]).count() >= 2)
                        .collect()
                };
                // Each voted basic's tones: per-window excess (* present).
                let n = count.max(1) as f64;
                // The sender basics always (a sender with one tone in a notch of the
                // room has no vote), then every other basic with a vote.
                let shown: Vec<usize> = (0..SENDER_COUNT)
                    .chain(voted(SENDER_COUNT..BASIC_COUNT))
                    .collect();
                let detail: Vec<String> = shown
                    .iter()
                    .map(|&b| {
                        let t: Vec<String> = basic_tones(b)
                            .iter()
                            .map(|&k| {
                                format!(
                                    "{}{:.0}",
                                    if present[k] { "*" } else { "" },
                                    (sums[k] - n) / n
                                )
                            })
                            .collect();
                        format!("b{b}[{}]", t.join(" "))
                    })
                    .collect();
                format!(
                    "rules: senders {:?} data {:?} ({} tones present) {}",
                    voted(0..SENDER_COUNT),
                    voted(SENDER_COUNT..BASIC_COUNT)
                        .iter()
                        .map(|b| b - SENDER_COUNT)
                        .collect::<Vec<_>>(),
                    present.iter().filter(|&&p| p).count(),
                    detail.join(" ")
                )
            });
            self.run = None;
            return;
        };
        if matches!(self.blocked, Some(b) if b.frame == frame) {
            self.note_search(|| format!("blocked {frame:?}"));
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
            match self.decaying(frame, j, count) {
                None => self.start_tracking(frame, j),
                // The rules found it only once the whole tone was in the sums (talkers
                // kept a vote down, or a rival up, until then): its slot has been heard
                // whole, and is decided on the windows from its onset like any other.
                Some(Decay::Falling) if self.slot_heard(frame, j) => {
                    self.note_search(|| format!("found falling {frame:?}"));
                    self.start_tracking(frame, j);
                }
                Some(_) => self.note_search(|| format!("decaying {frame:?}")),
            }
        } else {
            self.note_search(|| format!("seen {frame:?}"));
        }
    }

    /// Records a search step at the window the search stands at (diagnosis only).
    fn note_search(&self, what: impl FnOnce() -> String) {
        if let Some(w) = self.search_newest() {
            let at = w.start as f64;
            self.note(at, || format!("search: {}", what()));
        }
    }

    /// Whether `frame`'s energy at `scale` is dying away rather than sounding: the newest
    /// window holds less than [`DECAYING_SHARE`] of the mean per-window excess of the
    /// `count` windows summed (beyond the noise's spread). A message's onset is rising or
    /// steady there; a reverberant tail (of a message already decided, or of one whose
    /// start was missed) decays. The search waits (a real frame passes a window later),
    /// unless the frame's whole slot has already been heard (see `detect`): under talkers
    /// the rules may find a frame only once its whole tone is in the sums, when its newest
    /// window is already past its end (lab T60 0.5 s at 0 dB, tuning row 801009: 20 of
    /// its 59 lost messages are decided once such a frame is tracked).
    fn decaying(&self, frame: Frame, scale: usize, count: usize) -> Option<Decay> {
        let newest = self.search_newest()?;
        let tones = frame.tones();
        let n = count.max(1) as f64;
        let mean = (tones
            .iter()
            .map(|&k| self.sliding[scale * TONE_COUNT + k])
            .sum::<f64>()
            - 6.0 * n)
            / n;
        let latest = Self::excess(newest, scale, &tones);
        // The frame just decided, far below the level it was decided at: its tail (the
        // same robot sending it again sounds at about the same level).
        let tail_of_recent = self.recent.is_some_and(|r| {
            r.frame == frame && newest.start < r.until && latest < RECENT_TAIL_SHARE * r.level
        });
        // Tones only a few windows long end within the search's two-window run, so
        // their newest window is past their peak as a matter of course: no decay test.
        let long_tone = self.geometry.slot_windows >= DECAYING_MIN_WINDOWS;
        if tail_of_recent {
            Some(Decay::TailOfRecent)
        } else if long_tone && latest < DECAYING_SHARE * mean - DECAYING_NOISE_Z * 6f64.sqrt() {
            Some(Decay::Falling)
        } else {
            None
        }
    }

    /// Whether the whole slot of `frame` at `scale`, from the onset it would be tracked
    /// at, lies in the windows the search has heard.
    fn slot_heard(&self, frame: Frame, scale: usize) -> bool {
        let (Some(onset), Some(newest)) = (self.estimate_onset(frame, scale), self.search_newest())
        else {
            return false;
        };
        onset + self.geometry.slot_samples
            <= (newest.start + self.geometry.window_len as u64) as f64
    }

    /// The window the search stands at: the newest heard, or the one a replay is at.
    pub(super) fn search_newest(&self) -> Option<&super::windows::WindowRecord> {
        match self.replaying {
            Some(index) => self.record(index),
            None => self.history.back(),
        }
    }

    /// Runs the search again over the windows heard since `floor`, as if nothing had been
    /// tracked meanwhile, until it starts tracking a frame; then goes on live.
    ///
    /// While a frame is tracked the search is idle. In a hall full of talkers the search
    /// now and then picks up a frame that babble (over a reverberant tail) assembled for a
    /// moment, and a message that begins while that frame's slot is heard out would be
    /// lost: by the time the slot fails, the message's onset lies behind the newest
    /// window, and a search resumed there sees only its decaying part. Replaying the
    /// windows finds the message at its onset, as a second search running alongside
    /// would have.
    pub(super) fn replay_search(&mut self, floor: u64) {
        self.floor = floor;
        self.sliding.iter_mut().for_each(|s| *s = 0.0);
        self.sliding_count = 0;
        self.run = None;
        for index in self.indices_from(floor) {
            self.add_to_sliding(index);
            self.replaying = Some(index);
            self.detect();
            self.replaying = None;
            // Something else took over the sums (a block lifted and integration restarted
            // at the newest window): the replay has nothing left to look at.
            let took_over = self.sliding_first + self.sliding_count as u64 != index + 1;
            if self.tracking.is_some() || self.pending_replay.is_some() || took_over {
                // The tracking takes the windows from here (its slot may already be
                // complete: `start_tracking` moved it on as far as the audio allows), or
                // what it tracked was decided and asked for a replay of its own.
                return;
            }
        }
    }

    /// Runs the replays decisions asked for, one after the other (a replay may find a frame
    /// whose decision asks for the next): never one inside another, whose sliding sums
    /// would be the other's. Each starts at least a hop after the last failed slot's
    /// floor, so they end.
    pub(super) fn run_pending_replays(&mut self) {
        while let Some(floor) = self.pending_replay.take() {
            self.replay_search(floor);
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
        let expired = b.until.filter(|&u| rec.start >= u);
        self.blocked = if quiet >= 2 || expired.is_some() {
            // The windows summed so far hold the frame's loud tail: integrate afresh from
            // here (from the deadline, where the same frame may start again) unless
            // another frame is already being found.
            if b.fresh_start && self.run.is_none() && self.tracking.is_none() {
                let start = expired.unwrap_or(rec.start);
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
    /// Integration restarts when the block lifts (the windows summed hold the frame's
    /// tail).
    pub(super) fresh_start: bool,
}

/// Least ratio of the strongest data basic's three-tone excess to the next one's for the
/// search's fallback (see [`clear_leader`]).
const LEADER_MARGIN: f64 = 1.5;

/// The frame the search tracks when its rules left several data basics with 2 of 3
/// tones `present` (sliding sums `sums` over `count` windows), or `None`.
///
/// Under talkers in a small reverberant room the talkers' harmonics keep two tones of
/// some other data basics alive while a message sounds (lab T60 0.5 s at 0 dB: "senders
/// [0] data [4, 5, 9, 19]"), the rules want exactly one, and the message was never
/// tracked. Taking the strongest of each group there (f7a1c27) found them, but handed the
/// slot decision a crowd's assembled frames too, and two became false messages in 10 h.
/// So only where the evidence is a transmitter's: exactly one sender basic, with all
/// three of its tones present (harmonics give a basic two of three now and then, a
/// sender sounds all three), and a data basic clearly ahead of the next
/// ([`LEADER_MARGIN`]). The two windows in a row and the slot's decision still follow.
fn clear_leader(sums: &[f64], count: usize, present: &[bool; TONE_COUNT]) -> Option<Frame> {
    let n = count.max(1) as f64;
    let tones = |b: usize| basic_tones(b).iter().filter(|&&k| present[k]).count();
    let excess = |b: usize| -> f64 { basic_tones(b).iter().map(|&k| sums[k] - n).sum() };
    let voted = |r: std::ops::Range<usize>| -> Vec<usize> {
        let mut v: Vec<usize> = r.filter(|&b| tones(b) >= 2).collect();
        v.sort_unstable_by(|&a, &b| excess(b).total_cmp(&excess(a)));
        v
    };
    let (senders, data) = (voted(0..SENDER_COUNT), voted(SENDER_COUNT..BASIC_COUNT));
    let (&[s], [d, rest @ ..]) = (senders.as_slice(), data.as_slice()) else {
        return None;
    };
    let clear = rest
        .first()
        .is_none_or(|&r| excess(*d) >= LEADER_MARGIN * excess(r));
    if tones(s) < 3 || !clear {
        return None;
    }
    Some(Frame {
        sender: crate::tones::Sender::from_index(s as u8)?,
        data: (d - SENDER_COUNT) as u8,
    })
}

/// The frame the search tracks when no sender basic kept a vote in a crowd of present
/// tones, but one would at the range the slot decision gives the tracked sender's tones
/// (`own_sender` of [`Decoder::apply_rules`], −15 dB of the fourth loudest tone rather
/// than −10 dB), or `None`.
///
/// The room puts one or two of a sender's tones in a notch (5–15 dB below its loudest)
/// while the data basic sounds at full level: its three tones and the sender's loudest
/// are the four loudest, and the crowd rule drops the sender's other two (lab T60 0.5 s at
/// 0 dB, tuning row 28009 at 1590.37 s: sender 1 at 8, 235 and 12 per window, data 8 at
/// 242, 296 and 246; the fourth loudest is 235, the crowd's range 23.5). The search
/// never tracked such a frame, so the slot decision, which would count those tones, never
/// saw it. Only where the evidence is a transmitter's: exactly one sender basic passes at
/// its own range, and the frame's data basic has all three tones present (babble's
/// harmonics give a basic two of three now and then). The two windows in a row and the
/// slot's decision still follow.
fn sender_below_crowd(sums: &[f64], count: usize, present: &[bool; TONE_COUNT]) -> Option<Frame> {
    let votes = |present: &[bool; TONE_COUNT], b: usize| {
        basic_tones(b).iter().filter(|&&k| present[k]).count()
    };
    if (0..SENDER_COUNT).any(|b| votes(present, b) >= 2) {
        return None;
    }
    let mut found = (0..SENDER_COUNT).filter_map(|s| {
        let (frame, own) = Decoder::apply_rules(sums, count, P_TONE, P_TONE, Some(s), |_, _| true);
        frame.filter(|f| {
            usize::from(f.sender.index()) == s
                && votes(&own, SENDER_COUNT + usize::from(f.data)) == 3
        })
    });
    match (found.next(), found.next()) {
        (Some(f), None) => Some(f),
        _ => None,
    }
}

#[cfg(test)]
#[path = "search_tests.rs"]
mod tests;
