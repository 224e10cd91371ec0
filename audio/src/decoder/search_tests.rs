//! Tests of the search's fallback for a sender whose tones sit in a notch of the room
//! under a crowd of present tones (`sender_below_crowd` in `search.rs`).

use super::{sender_below_crowd, Decoder, P_TONE};
use crate::tones::{Frame, Sender, TONE_COUNT};

/// Windows in the sliding sums (a one-second tone at the nominal hop).
const COUNT: usize = 16;

/// Sliding sums of `COUNT` windows of unit noise with the given per-window excess on
/// some tones.
fn sums_with(excess: &[(usize, f64)]) -> [f64; TONE_COUNT] {
    let n = COUNT as f64;
    let mut sums = [n; TONE_COUNT];
    for &(k, e) in excess {
        sums[k] = n * (1.0 + e);
    }
    sums
}

/// Tuning row 28009 at 1590.37 s in numbers: data 8 (tones 11, 35, 59) at full level,
/// sender 1 (tones 1, 25, 49) with its outer tones 15 dB and more below its middle one,
/// and six single tones of babble that make the present tones a crowd.
fn notch_case(data_low: f64) -> Vec<(usize, f64)> {
    vec![
        (11, 242.0),
        (35, 296.0),
        (59, data_low),
        (1, 8.0),
        (25, 235.0),
        (49, 12.0),
        (5, 3.0),
        (30, 3.0),
        (40, 3.0),
        (60, 3.0),
        (66, 250.0),
        (70, 3.0),
    ]
}

fn search_rules(sums: &[f64; TONE_COUNT]) -> (Option<Frame>, [bool; TONE_COUNT]) {
    Decoder::apply_rules(sums, COUNT, P_TONE, P_TONE, None, |_, _| true)
}

#[test]
fn a_sender_in_a_notch_under_a_crowd_is_found_at_its_own_range() {
    // The crowd's range (−10 dB of the fourth loudest, 235) drops the sender's outer
    // tones, so the search's rules see no sender; at the slot decision's range for the
    // tracked sender (−15 dB) they count, and only sender 1's do.
    let sums = sums_with(&notch_case(246.0));
    let (frame, present) = search_rules(&sums);
    assert_eq!(frame, None, "the crowd rule leaves no sender vote here");
    assert_eq!(
        sender_below_crowd(&sums, COUNT, &present),
        Some(Frame {
            sender: Sender::LeftAttacker,
            data: 8
        }),
        "the one sender that passes at its own range, with a full data basic"
    );
}

#[test]
fn a_data_basic_with_two_tones_is_not_taken_on_a_sender_below_the_crowd() {
    // The same scene with the data basic's third tone also below the crowd: two of three
    // is what babble's harmonics make now and then, so the fallback wants all three.
    let sums = sums_with(&notch_case(10.0));
    let (frame, present) = search_rules(&sums);
    assert_eq!(frame, None, "no sender vote at the crowd's range");
    assert_eq!(
        sender_below_crowd(&sums, COUNT, &present),
        None,
        "a two-tone data basic under a crowd is no transmitter's evidence"
    );
}

#[test]
fn two_senders_below_the_crowd_are_not_chosen_between() {
    // Sender 0 (tones 0, 24, 48) also passes at its own range: the search does not pick
    // one of two senders on this evidence.
    let mut case = notch_case(246.0);
    case.extend([(0, 9.0), (24, 200.0), (48, 10.0)]);
    let sums = sums_with(&case);
    let (frame, present) = search_rules(&sums);
    assert_eq!(frame, None, "no sender vote at the crowd's range");
    assert_eq!(
        sender_below_crowd(&sums, COUNT, &present),
        None,
        "two senders pass at their own range: neither is taken"
    );
}
