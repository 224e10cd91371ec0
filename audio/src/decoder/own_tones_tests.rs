//! Tests of the first slot's rules on the tracked frame's own tones (`own_tones.rs`): a
//! frame the room spread over 25–30 dB is taken, and only that frame, only then.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::confirm::{P_TONE_CONFIRM, P_TONE_RIVAL};
use super::own_tones::own_tones_decision;
use super::Decoder;
use crate::tones::{Frame, Sender, TONE_COUNT};

/// Slot sums of `count` windows: noise of mean 1 per window (seeded) on every tone, plus
/// `excess` per window on the tones listed.
fn slot_sums(seed: u64, count: usize, excess: &[(usize, f64)]) -> [f64; TONE_COUNT] {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut sums = [0.0; TONE_COUNT];
    for s in sums.iter_mut() {
        for _ in 0..count {
            let u: f64 = rng.random_range(f64::EPSILON..1.0);
            *s -= u.ln();
        }
    }
    for &(k, e) in excess {
        sums[k] += e * count as f64;
    }
    sums
}

/// The traced first slot of tuning row 64015 at 1233.8 s (short, lab-1.2, 0 dB): sender
/// LeftAttacker (basic 1: k1, k25, k49), data 8 (basic 11: k11, k35, k59), per-window
/// excess as the trace read them.
const ROW_64015: [(usize, f64); 6] = [
    (1, 53.2),
    (25, 85.7),
    (49, 135.5),
    (11, 1066.7),
    (35, 34857.1),
    (59, 2641.5),
];

fn left_attacker(data: u8) -> Frame {
    Frame {
        sender: Sender::LeftAttacker,
        data,
    }
}

#[test]
fn a_frame_spread_over_the_rooms_range_is_taken_on_its_own_tones() {
    // The data's k35 sits on a peak of the room, the sender's k1 and k25 26–28 dB below
    // it though 17–19 dB above the noise: the rules drop them as too far below the
    // loudest tone and the sender's vote with them. Judged against the frame's own tones
    // (−30 dB), the frame is the tracked one, on six noise draws.
    for seed in 0..6 {
        let sums = slot_sums(seed, 14, &ROW_64015);
        let (plain, _) =
            Decoder::apply_rules(&sums, 14, P_TONE_CONFIRM, P_TONE_RIVAL, Some(1), |_, _| {
                true
            });
        assert_eq!(plain, None, "seed {seed}: the rules refuse it as before");
        let got = own_tones_decision(left_attacker(8), &sums, 14, P_TONE_CONFIRM, P_TONE_RIVAL);
        assert_eq!(
            got.map(|(f, _)| f),
            Some(left_attacker(8)),
            "seed {seed}: the frame's own tones give it"
        );
    }
}

#[test]
fn own_tones_further_than_30_db_below_the_loudest_still_do_not_count() {
    // The same slot with the sender's k1 and k25 at 32–34 dB below k35 (14 and 22 per
    // window): beyond the own range, no sender vote, no frame.
    let mut tones = ROW_64015;
    tones[0].1 = 14.0;
    tones[1].1 = 22.0;
    let sums = slot_sums(7, 14, &tones);
    let got = own_tones_decision(left_attacker(8), &sums, 14, P_TONE_CONFIRM, P_TONE_RIVAL);
    assert_eq!(got.map(|(f, _)| f), None, "{tones:?}");
}

#[test]
fn a_loudest_tone_not_the_frames_own_gives_nothing() {
    // A foreign loud tone (k40, no tone of the frame) above all of the frame's: the spread
    // is not the room's on this frame, and the rules' verdict stands.
    let mut tones = ROW_64015.to_vec();
    tones.push((40, 60_000.0));
    let sums = slot_sums(8, 14, &tones);
    let got = own_tones_decision(left_attacker(8), &sums, 14, P_TONE_CONFIRM, P_TONE_RIVAL);
    assert_eq!(got.map(|(f, _)| f), None, "foreign k40 loudest");
}

#[test]
fn only_the_tracked_frame_is_taken() {
    // Tracked as data 3 (basic 6: k6, k30, k54, silent here) while the slot sounds data 8:
    // the own rules make no vote for data 3, and data 8 is not the tracked frame.
    let sums = slot_sums(9, 14, &ROW_64015);
    let got = own_tones_decision(left_attacker(3), &sums, 14, P_TONE_CONFIRM, P_TONE_RIVAL);
    assert_eq!(
        got.map(|(f, _)| f),
        None,
        "tracked data 3, slot sounds data 8"
    );
}

#[test]
fn in_a_crowd_the_tracked_data_counts_within_the_senders_allowance() {
    // The traced first slot of tuning row 67009 at 1955.0 s (short, lab-0.5, 0 dB):
    // RightAttacker (k2, k26, k50 at 140, 1303, 169 per window), data 1 (k4 silent, k28 at
    // 355, k52 at 9.6), among twelve babble tones at 3–8 per window. In the crowd a tone
    // counts within 10 dB of the fourth loudest (169): k52 falls out and the data's vote
    // with it. Within the sender's 15 dB, as the tracked data's tone, it stays.
    let mut tones = vec![
        (2, 140.0),
        (26, 1302.7),
        (50, 168.8),
        (28, 355.1),
        (52, 9.6),
    ];
    for (i, k) in [8, 12, 16, 20, 32, 36, 40, 44, 56, 60, 64, 68]
        .into_iter()
        .enumerate()
    {
        tones.push((k, 3.0 + (i % 6) as f64));
    }
    let frame = Frame {
        sender: Sender::RightAttacker,
        data: 1,
    };
    for seed in 10..16 {
        let sums = slot_sums(seed, 14, &tones);
        let (plain, present) =
            Decoder::apply_rules(&sums, 14, P_TONE_CONFIRM, P_TONE_RIVAL, Some(2), |_, _| {
                true
            });
        assert!(
            plain.is_none() && !present[52],
            "seed {seed}: the crowd drops k52 ({plain:?})"
        );
        let got = own_tones_decision(frame, &sums, 14, P_TONE_CONFIRM, P_TONE_RIVAL);
        assert_eq!(got.map(|(f, _)| f), Some(frame), "seed {seed}");
    }
}
