//! Tests of the check that a frame's two basics are one transmitter's (`coherence.rs`):
//! two robots sounding at once must never give a frame of one's sender and the other's
//! data.

use super::tests::decode_traced;
use crate::tones::{tone_frequency_hz, Frame, Message, Sender};

/// Tones `(frequency index, amplitude, from s, to s)` over `seconds` of white noise of
/// `sigma` (seed `seed`), each switched on with a 5 ms ramp and dying away after its end
/// as in a room of `t60` seconds (−60 dB in `t60`; 0: switched off with the ramp).
fn timed_tones(
    tones: &[(usize, f64, f64, f64)],
    seconds: f64,
    t60: f64,
    sigma: f64,
    seed: u64,
) -> Vec<f32> {
    let rate = 16_000.0;
    let ramp = 0.005;
    let mut x: Vec<f32> = (0..(seconds * rate) as usize)
        .map(|n| {
            let t = n as f64 / rate;
            tones
                .iter()
                .map(|&(k, amp, from, to)| {
                    let rise = ((t - from) / ramp).clamp(0.0, 1.0);
                    let fall = if t <= to {
                        1.0
                    } else if t60 > 0.0 {
                        (-6.91 * (t - to) / t60).exp()
                    } else {
                        ((to - t) / ramp + 1.0).clamp(0.0, 1.0)
                    };
                    let edge = rise * fall;
                    amp * edge * (2.0 * std::f64::consts::PI * tone_frequency_hz(k) * t).sin()
                })
                .sum::<f64>() as f32
        })
        .collect();
    let mut noise = crate::channel::WhiteNoise::new(seed, sigma);
    crate::channel::Source::add_to(&mut noise, &mut x);
    x
}

/// Two robots' short messages: `first` from 0.5 s, `second` from `0.5 + lag` s, each tone
/// at its own amplitude (`(tone of the frame, 0..6 in `Frame::tones` order) → amplitude`).
fn two_robots(
    first: (Frame, [f64; 6]),
    second: (Frame, [f64; 6]),
    lag: f64,
    t60: f64,
    seed: u64,
) -> Vec<f32> {
    let mut tones = Vec::new();
    for ((frame, amps), from) in [(first, 0.5), (second, 0.5 + lag)] {
        for (k, amp) in frame.tones().into_iter().zip(amps) {
            if amp > 0.0 {
                tones.push((k, amp, from, from + 1.0));
            }
        }
    }
    timed_tones(&tones, 4.0, t60, 0.002, seed)
}

#[test]
fn two_robots_half_a_tone_apart_give_no_frame_of_one_robots_sender_and_the_others_data() {
    // Lab T60 1.2 s, two robots at 10 dB (check row 990033, 296.92 s): sender 1 sent data
    // 7, its sender tones weak in that room (k25 only), its data tones loud; sender 0 sent
    // data 0 half a tone later, its sender tones loud and its data weak. The slot found
    // between them passed as sender 0 with data 7, a wrong message. Here the tones die
    // away as in a T60 1.2 s room (switched off dry, the slot does not sound through and
    // the old code refused it too; with the tail it reported sender 0 data 7 on every
    // seed). A frame's two basics begin and end together; here the data fades from the
    // slot's last quarter while the sender holds it. Whatever is decoded must be a
    // message one of them sent.
    let s1 = Frame {
        sender: Sender::LeftAttacker,
        data: 7,
    };
    let s0 = Frame {
        sender: Sender::Goalkeeper,
        data: 0,
    };
    // Frame::tones order: sender low, data low, sender mid, data mid, sender high, data high.
    let first = (s1, [0.0, 0.006, 0.004, 0.02, 0.0, 0.02]);
    let second = (s0, [0.003, 0.004, 0.008, 0.006, 0.0015, 0.002]);
    let sent = [
        Message::Short {
            sender: s1.sender,
            data: s1.data,
        },
        Message::Short {
            sender: s0.sender,
            data: s0.data,
        },
    ];
    for seed in [990_033u64, 1, 2, 3] {
        let x = two_robots(first, second, 0.5, 1.2, seed);
        let (got, _, shown) = decode_traced(&x);
        assert!(
            got.iter().all(|m| sent.contains(m)),
            "seed {seed}: decoded {got:?}, sent {sent:?}\n{}",
            shown.join("\n")
        );
    }
}

#[test]
fn two_robots_starting_together_with_one_sender_faint_give_no_mixed_frame() {
    // Hall T60 2 s, two robots at 10 dB (check row 990036, 1049.96 s): sender 1 sent data
    // 2, sender 0 data 9 0.07 s later. Sender 0's data tones hardly reached the
    // microphone, sender 1's sender tones came 7–8 dB under sender 0's: no rival within
    // the rules' 6 dB, and the frame passed as sender 0 with data 2. A second sender basic
    // that sounds like a transmitter (steady, through both halves) means a second robot,
    // and then the data may be either's.
    let s1 = Frame {
        sender: Sender::LeftAttacker,
        data: 2,
    };
    let s0 = Frame {
        sender: Sender::Goalkeeper,
        data: 9,
    };
    let first = (s1, [0.0035, 0.005, 0.004, 0.0055, 0.0, 0.0]);
    let second = (s0, [0.008, 0.0, 0.01, 0.0008, 0.0, 0.0]);
    let sent = [
        Message::Short {
            sender: s1.sender,
            data: s1.data,
        },
        Message::Short {
            sender: s0.sender,
            data: s0.data,
        },
    ];
    for seed in [990_036u64, 1, 2, 3] {
        let x = two_robots(first, second, 0.07, 2.0, seed);
        let (got, _, shown) = decode_traced(&x);
        assert!(
            got.iter().all(|m| sent.contains(m)),
            "seed {seed}: decoded {got:?}, sent {sent:?}\n{}",
            shown.join("\n")
        );
    }
}

#[test]
fn a_second_slot_whose_data_began_in_the_first_slot_is_another_robots_frame() {
    // Lab T60 0.5 s, two robots at 10 dB (tuning row 18031, 1530.56 s): sender 2 sent
    // long (13, 20), its second data (k23, k47, k71) in the room's notches; sender 1 began
    // long (11, 20) 0.19 s before sender 2's second slot, its data 11 loud (k38 3,311 per
    // window against sender 2's k26 1,645). The second slot passed as sender 2 with data
    // 11: long 284, a wrong message. A robot's second frame begins with its slot; data
    // that sounded through the end of the first slot at its level is another robot's.
    // Amplitudes from the row's per-window levels (amplitude ∝ √level, k26 = 0.02).
    let (s2, s1) = (Sender::RightAttacker, Sender::LeftAttacker);
    let tones = |frame: Frame, amps: [f64; 6], from: f64| -> Vec<(usize, f64, f64, f64)> {
        frame
            .tones()
            .into_iter()
            .zip(amps)
            .filter(|&(_, amp)| amp > 0.0)
            .map(|(k, amp)| (k, amp, from, from + 1.0))
            .collect()
    };
    // Frame::tones order: sender low, data low, sender mid, data mid, sender high, data high.
    // Sender 1 began 0.19 s before sender 2's second slot.
    let lead = 0.19;
    let mut all = Vec::new();
    for (frame, amps, from) in [
        (
            Frame {
                sender: s2,
                data: 13,
            },
            [0.0094, 0.0085, 0.02, 0.009, 0.001, 0.0019],
            0.5,
        ),
        (
            Frame {
                sender: s2,
                data: 20,
            },
            [0.0094, 0.001, 0.02, 0.001, 0.001, 0.0046],
            1.5,
        ),
        (
            Frame {
                sender: s1,
                data: 11,
            },
            [0.0, 0.0072, 0.0016, 0.0186, 0.0019, 0.0025],
            1.5 - lead,
        ),
        (
            Frame {
                sender: s1,
                data: 20,
            },
            [0.0, 0.0033, 0.0016, 0.0017, 0.0019, 0.0034],
            2.5 - lead,
        ),
    ] {
        all.extend(tones(frame, amps, from));
    }
    let sent = [
        Message::Long {
            sender: s2,
            value: 13 * 21 + 20,
        },
        Message::Long {
            sender: s1,
            value: 11 * 21 + 20,
        },
    ];
    for seed in [18_031u64, 1, 2, 3] {
        let x = timed_tones(&all, 5.0, 0.5, 0.002, seed);
        let (got, _, shown) = decode_traced(&x);
        assert!(
            got.iter().all(|m| sent.contains(m)),
            "seed {seed}: decoded {got:?}, sent {sent:?}\n{}",
            shown.join("\n")
        );
    }
}

#[test]
fn a_frame_refused_for_a_foreign_sound_stays_refused_when_found_again_a_few_windows_away() {
    // Hall T60 2 s, two robots at 10 dB (check row 990036): the slot of sender 0 with
    // sender 1's data 2 was refused off grid at 1049.96 s; the search found the frame
    // again at 1050.02 s, where the windows at the slot's edges differ, and it passed: a
    // wrong message. The refusal is remembered over the frame's span.
    use super::{Decoder, DecoderConfig};
    let d = Decoder::new(DecoderConfig::default()).unwrap();
    let rate = 16_000.0;
    let frame = Frame {
        sender: Sender::Goalkeeper,
        data: 2,
    };
    let a = 1049.96 * rate;
    d.remember_refusal(frame, a, a, 23, "off grid");
    let later = a + 0.06 * rate;
    assert!(
        d.recalled_refusal(frame, later, later, 23).is_some(),
        "the same frame found again 0.06 s later by another tracking must be refused"
    );
    assert!(
        d.recalled_refusal(frame, a - 0.064 * rate, a, 23).is_none(),
        "the refused tracking's own retries at earlier onsets are decided on their own"
    );
    let other = Frame { data: 9, ..frame };
    assert!(
        d.recalled_refusal(other, later, later, 23).is_none(),
        "another frame is not refused"
    );
    let far = a + 0.5 * d.geometry.slot_samples;
    assert!(
        d.recalled_refusal(frame, far, far, 23).is_none(),
        "the same frame half a slot away is another transmission"
    );
    assert!(
        d.recalled_refusal(frame, later, later, 22).is_none(),
        "an off-grid refusal is a verdict on the scale: the frame found a bin away is decided anew"
    );
    // A refusal for the onset or the level (not a foreign sound) is not remembered.
    let e = Decoder::new(DecoderConfig::default()).unwrap();
    e.remember_refusal(frame, a, a, 23, "does not sound through");
    assert!(e.recalled_refusal(frame, later, later, 23).is_none());
}

#[test]
fn a_second_slot_whose_data_began_a_window_before_it_is_another_robots_frame() {
    // Lab T60 0.5 s, two robots at 10 dB (tuning row 47031, 1066.52 s): sender 2 sent
    // long (18, 13), its second data (k16, k40, k64) in the room's notches; sender 1
    // began long (15, 19) about 0.15 s before sender 2's second slot, its data 15 loud
    // and its sender tones weak. Over the quarter before the slot data 15 held only 0.40
    // of its level (the quarter's first window was still silent), in the window just
    // before the slot 1.05; the slot passed as sender 2's long 393, a wrong message.
    // Amplitudes from the row's per-window levels (amplitude ∝ √level, k26 = 0.02 at 992).
    // Here sender 1 leads by 0.12 s: with the windows of this synthetic slot, at 0.15 s the
    // quarter test on the data refuses the slot already; at 0.12 s the decoder reported
    // long 393 on every seed, and a test on the one window before the slot (round 14,
    // reverted) cost right messages and missed leads of 0.10 s or less. What catches it
    // (round 19) is sender 1's *sender*: weak, but out of the noise, it began with the
    // slot (`Decoder::sender_began_with_slot`), so the slot's data may be sender 1's.
    // Leads from 0 (sender 1 begins exactly with the slot) to 0.12 s.
    for lead in [0.0, 0.04, 0.09, 0.12] {
        a_robot_beginning_near_a_second_slot(lead);
    }
}

fn a_robot_beginning_near_a_second_slot(lead: f64) {
    let (s2, s1) = (Sender::RightAttacker, Sender::LeftAttacker);
    let mut all = Vec::new();
    // Frame::tones order: sender low, data low, sender mid, data mid, sender high, data high.
    for (sender, data, amps, from) in [
        (s2, 18, [0.0082, 0.0055, 0.02, 0.0121, 0.0015, 0.0031], 0.5),
        (s2, 13, [0.0082, 0.0034, 0.02, 0.0022, 0.0015, 0.001], 1.5),
        (
            s1,
            15,
            [0.0014, 0.0066, 0.0014, 0.0068, 0.0042, 0.0],
            1.5 - lead,
        ),
        (
            s1,
            19,
            [0.0014, 0.002, 0.0014, 0.0026, 0.0042, 0.0027],
            2.5 - lead,
        ),
    ] {
        let frame = Frame { sender, data };
        for (k, amp) in frame.tones().into_iter().zip(amps) {
            if amp > 0.0 {
                all.push((k, amp, from, from + 1.0));
            }
        }
    }
    let sent = [
        Message::Long {
            sender: s2,
            value: 18 * 21 + 13,
        },
        Message::Long {
            sender: s1,
            value: 15 * 21 + 19,
        },
    ];
    for seed in [47_031u64, 1, 2, 3] {
        let x = timed_tones(&all, 5.0, 0.5, 0.002, seed);
        let (got, _, shown) = decode_traced(&x);
        assert!(
            got.iter().all(|m| sent.contains(m)),
            "seed {seed}, sender 1 {lead} s ahead of sender 2's second slot: decoded {got:?}, sent {sent:?}\n{}",
            shown.join("\n")
        );
    }
}
