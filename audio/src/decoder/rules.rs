//! The seed's rules on integrated sums: which tones are present, which basics have 2 of
//! their 3 tones, and whether that leaves exactly one sender and one data basic; and the
//! six-tone energy test a frame must pass to stand out of noise at all.

use super::Decoder;
use crate::significance::gamma_upper_quantile;
use crate::tones::{basic_tones, Frame, Sender, BASIC_COUNT, SENDER_COUNT, TONE_COUNT};

/// A tone is leakage, not present, when its excess is below this share of an adjacent
/// tone's excess (−20 dB; Hann leakage at 3 bins is about −31 dB).
const NEIGHBOUR_LEAKAGE: f64 = 0.01;
/// A tone more than 25 dB below the loudest tone is not present: window sidelobes two or
/// more tones away, and a loudspeaker's harmonic and intermodulation products, sit lower
/// than that; a real tone that weak would be lost anyway (and the 2-of-3 vote covers one).
const DYNAMIC_RANGE: f64 = 0.003_162;

/// More tones present than this (a frame's six and a few of noise) is a crowd (see
/// [`Decoder::apply_rules`]).
const CROWD: usize = 10;
/// In a crowd, a tone counts as present only within this share of the fourth loudest
/// tone's excess (−10 dB).
const CROWD_RANGE: f64 = 0.1;
/// In a crowd, a tone of the tracked sender's basic counts within this share of the
/// fourth loudest tone's excess (−15 dB) when a slot is decided (see
/// [`Decoder::apply_rules`]).
const OWN_CROWD_RANGE: f64 = 0.0316;
/// A rival basic counts only with its vote at least this share of the top basic's (−6 dB).
const RIVAL_RANGE: f64 = 0.25;

/// The tracked frame's own basics, whose tones [`Decoder::apply_rules_with`] judges more
/// leniently (see `own_tones.rs`).
#[derive(Clone, Copy, Debug)]
pub(super) struct OwnTones {
    /// The tracked sender's basic.
    pub(super) sender: Option<usize>,
    /// The tracked data's basic.
    pub(super) data: Option<usize>,
    /// Least share of the loudest tone's excess an own tone keeps to be present.
    pub(super) dynamic_range: f64,
}

impl Default for OwnTones {
    fn default() -> Self {
        OwnTones {
            sender: None,
            data: None,
            dynamic_range: DYNAMIC_RANGE,
        }
    }
}

/// Whether tone `k` of the integrated sums `sums` (of `n` windows) is leakage of an
/// adjacent louder tone: its excess below [`NEIGHBOUR_LEAKAGE`] of a neighbour's.
pub(super) fn is_leakage(sums: &[f64], n: f64, k: usize) -> bool {
    let left = if k > 0 { sums[k - 1] - n } else { 0.0 };
    let right = if k + 1 < TONE_COUNT {
        sums[k + 1] - n
    } else {
        0.0
    };
    sums[k] - n < NEIGHBOUR_LEAKAGE * left.max(right)
}

impl Decoder {
    /// The rules on integrated sums `sums` (72 tones) of `count` windows: tones present
    /// at `p_tone`; when several sender (or data) basics have 2 of 3 tones present, the
    /// strongest stands and each other one counts only if it also has 2 of 3 at `p_rival`.
    ///
    /// `is_transmitter(frame, present)` is asked of each rival that passes those: a
    /// rival counts only if the frame it would make with the other group's strongest
    /// basic (a second data basic with the sender, a second sender with the data) sounds
    /// like a transmitter's tones, not babble's (the search passes `|_, _| true`).
    ///
    /// `own_sender` is the sender basic of the frame being tracked, when a slot of it is
    /// decided (the search passes `None`): in a crowd its tones count within
    /// [`OWN_CROWD_RANGE`] rather than [`CROWD_RANGE`]. The room spreads one frame's tones
    /// over 10–20 dB (a tone in a notch), and where the data basic is the loud one the
    /// fourth loudest tone is the sender's loudest: its other two, 10–15 dB down, fell out
    /// of the crowd and the sender's vote with them (lab T60 1.2 s at 0 dB, seed 801021:
    /// 9 of 38 lost long messages, e.g. at 88.88 s k1 and k25 at 44 and 47 per window
    /// against k49 at 512). A sender is the one basic the search has already named, and
    /// the slot's other checks (steady votes, both halves, neighbours, one scale) apply
    /// to those tones as to any.
    pub(super) fn apply_rules(
        sums: &[f64],
        count: usize,
        p_tone: f64,
        p_rival: f64,
        own_sender: Option<usize>,
        is_transmitter: impl Fn(Frame, &[bool; TONE_COUNT]) -> bool,
    ) -> (Option<Frame>, [bool; TONE_COUNT]) {
        let own = OwnTones {
            sender: own_sender,
            ..OwnTones::default()
        };
        Self::apply_rules_with(sums, count, p_tone, p_rival, own, is_transmitter)
    }

    /// [`Decoder::apply_rules`] with the tracked frame's own basics named in `own`: the
    /// tones of `own.sender` (and of `own.data`) count in a crowd within
    /// [`OWN_CROWD_RANGE`], and the tones of both within `own.dynamic_range` of the
    /// loudest tone rather than [`DYNAMIC_RANGE`] (see `own_tones.rs`).
    pub(super) fn apply_rules_with(
        sums: &[f64],
        count: usize,
        p_tone: f64,
        p_rival: f64,
        own: OwnTones,
        is_transmitter: impl Fn(Frame, &[bool; TONE_COUNT]) -> bool,
    ) -> (Option<Frame>, [bool; TONE_COUNT]) {
        let own_basic = |k: usize| {
            [own.sender, own.data]
                .into_iter()
                .flatten()
                .any(|b| basic_tones(b).contains(&k))
        };
        let n = count.max(1) as f64;
        let threshold = gamma_upper_quantile(n, p_tone);
        let rival_threshold = gamma_upper_quantile(n, p_rival);
        let mut present = [false; TONE_COUNT];
        let loudest = sums.iter().fold(0.0f64, |m, &s| m.max(s - n));
        for k in 0..TONE_COUNT {
            let range = if own_basic(k) {
                own.dynamic_range
            } else {
                DYNAMIC_RANGE
            };
            present[k] =
                sums[k] >= threshold && !is_leakage(sums, n, k) && sums[k] - n >= range * loudest;
        }
        // A crowd of present tones is not noise of the kind the thresholds assume: babble's
        // voiced harmonics and formants, or a hall's reverberant smear, lift many tones
        // above the Gamma quantile at once. Then only tones within CROWD_RANGE of the
        // frame's loudest four (the least a 2-of-3 vote on two basics rests on) count:
        // the message's own tones stand far above such a background.
        if present.iter().filter(|&&p| p).count() > CROWD {
            let mut excess: Vec<f64> = (0..TONE_COUNT).map(|k| sums[k] - n).collect();
            excess.sort_unstable_by(|a, b| b.total_cmp(a));
            let reference = excess[3].max(0.0);
            for k in 0..TONE_COUNT {
                let range = if own_basic(k) {
                    OWN_CROWD_RANGE
                } else {
                    CROWD_RANGE
                };
                if sums[k] - n < range * reference {
                    present[k] = false;
                }
            }
        }
        let mut senders = Vec::new();
        let mut data = Vec::new();
        for b in 0..BASIC_COUNT {
            let votes = basic_tones(b).iter().filter(|&&k| present[k]).count();
            if votes >= 2 {
                if b < SENDER_COUNT {
                    senders.push(b);
                } else {
                    data.push(b);
                }
            }
        }
        let basic_sum = |b: usize| -> f64 { basic_tones(b).iter().map(|&k| sums[k]).sum() };
        let strong_votes = |b: usize| {
            basic_tones(b)
                .iter()
                .filter(|&&k| present[k] && sums[k] >= rival_threshold)
                .count()
        };
        // The excess of the weaker of a basic's two loudest tones: what its vote rests on.
        let vote = |b: usize| {
            let mut e = basic_tones(b).map(|k| sums[k] - n);
            e.sort_unstable_by(|x, y| y.total_cmp(x));
            e[1]
        };
        let top = |group: &[usize]| {
            group
                .iter()
                .copied()
                .max_by(|&a, &b| basic_sum(a).total_cmp(&basic_sum(b)))
        };
        let (top_sender, top_data) = (top(&senders), top(&data));
        // The frame a rival basic would make with the other group's strongest basic.
        let with_rival = |b: usize| -> Option<Frame> {
            let (s, d) = if b < SENDER_COUNT {
                (b, top_data?)
            } else {
                (top_sender?, b)
            };
            Some(Frame {
                sender: Sender::from_index(s as u8)?,
                data: (d - SENDER_COUNT) as u8,
            })
        };
        for (group, top) in [(&mut senders, top_sender), (&mut data, top_data)] {
            if group.len() > 1 {
                let top = top.unwrap_or(0);
                // A rival also needs its 2-of-3 vote within RIVAL_RANGE of the top
                // basic's: under babble, harmonics give some basic two strong tones now
                // and then, far below a real second transmitter (which sounds at full
                // level, or is lost under the first anyway).
                let top_vote = vote(top);
                group.retain(|&b| {
                    b == top
                        || (strong_votes(b) >= 2
                            && vote(b) >= RIVAL_RANGE * top_vote
                            && with_rival(b).is_none_or(|f| is_transmitter(f, &present)))
                });
            }
        }
        let frame = match (senders.as_slice(), data.as_slice()) {
            (&[s], &[d]) => Sender::from_index(s as u8).map(|sender| Frame {
                sender,
                data: (d - SENDER_COUNT) as u8,
            }),
            _ => None,
        };
        (frame, present)
    }

    /// Least six-tone sum over `count` windows for a frame to stand out of noise: the
    /// Gamma(6·count) quantile at `p` union-bounded over the 63 frames and all scales.
    pub(super) fn frame_threshold(&self, count: usize, p: f64) -> f64 {
        let hypotheses =
            (SENDER_COUNT * (BASIC_COUNT - SENDER_COUNT) * self.geometry.scale_count()) as f64;
        gamma_upper_quantile(6.0 * count.max(1) as f64, p / hypotheses)
    }
}
