//! Tests of the check that a first frame is not one the background assembled
//! (`bursts.rs`): it must not cost the weak messages of white noise, where a frame's tones
//! are as weak as a crowd's but the band around them is empty and they hold steadily.

use super::tests::decode_traced;
use crate::channel::{power, white_sigma_for_in_band_snr, Source, WhiteNoise};
use crate::encoder::{Encoder, EncoderConfig};
use crate::tones::{Message, Sender};

#[test]
fn weak_messages_in_white_noise_are_not_taken_for_the_background() {
    // Twelve short messages at −11 dB in-band in white noise (seed 14): their typical tone
    // sits well under 10 dB per window and under the 15 dB of a frame clear of the floor,
    // so both of the check's rules are asked about each. The band around them holds no
    // crowd of tones, and steady tones dip no more than the noise lets them: every
    // message is reported, none refused as the background's.
    let enc = Encoder::new(EncoderConfig::default()).unwrap();
    let senders = [
        Sender::Goalkeeper,
        Sender::LeftAttacker,
        Sender::RightAttacker,
    ];
    let sent: Vec<Message> = (0..12u8)
        .map(|i| Message::short(senders[usize::from(i) % 3], (5 * i) % 21).unwrap())
        .collect();
    let tone = enc.encode_f32(&sent[0]);
    let gap = vec![0.0f32; 16_000];
    let mut x = gap.clone();
    for m in &sent {
        x.extend(enc.encode_f32(m));
        x.extend(&gap);
    }
    let sigma = white_sigma_for_in_band_snr(power(&tone), -11.0, 16_000);
    WhiteNoise::new(14, sigma).add_to(&mut x);
    let (got, trace, shown) = decode_traced(&x);
    let refused: Vec<&String> = shown
        .iter()
        .filter(|e| e.contains("assembled by the background"))
        .collect();
    assert!(
        refused.is_empty(),
        "weak messages in white noise refused as the background's: {refused:#?}"
    );
    assert_eq!(got, sent, "every message at −11 dB; trace: {shown:#?}");
    // The frames were weak enough to be asked: their typical tone under 10 dB.
    let weak = trace
        .iter()
        .filter_map(|e| e.what.split(" level ").nth(1))
        .filter_map(|l| l.split(" dB: passes").next()?.parse::<f64>().ok())
        .filter(|&db| db < 10.0)
        .count();
    assert!(
        weak >= 6,
        "{weak} of the passing slots under 10 dB: the test asks too little; {shown:#?}"
    );
}

#[test]
fn vote_tones_that_sound_in_turn_are_not_together() {
    // Four vote tones over ten windows (noise mean 1, per-window noise from a fixed
    // pseudo-random sequence, seed 24). A transmitter's tones at 10 dB each read near
    // their median in every window: all four sound together throughout. The same four
    // tones at the same mean level, each in its own bursts (as babble's harmonics and a
    // talker's syllables put them, tuning row 24001 at 347.51 s: k1 29, 121, 50, 268 …
    // while k49 read 1–8), leave one of them silent in most windows.
    use super::bursts::{together_share, TOGETHER_SHARE};
    let mut state = 24u64;
    let mut noise = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        // Exponential (noise mean 1) from the top 53 bits.
        let u = ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
        -(u.ln()) as f32
    };
    let votes = [1usize, 4, 25, 28];
    let steady: Vec<Vec<f32>> = (0..10)
        .map(|_| {
            (0..72)
                .map(|k| noise() + if votes.contains(&k) { 10.0 } else { 0.0 })
                .collect()
        })
        .collect();
    let rows: Vec<&[f32]> = steady.iter().map(Vec::as_slice).collect();
    let share = together_share(&rows, &votes).expect("ten windows");
    assert!(
        share >= 0.9,
        "a steady frame at 10 dB: all four vote tones together in {share:.2} of the windows"
    );
    // Each tone on in its own three or four windows at 30 (the same mean of about 10).
    let bursts: Vec<Vec<f32>> = (0..10)
        .map(|w| {
            (0..72)
                .map(|k| {
                    let on = votes
                        .iter()
                        .position(|&v| v == k)
                        .is_some_and(|i| (w + i) % 3 == 0);
                    noise() + if on { 30.0 } else { 0.0 }
                })
                .collect()
        })
        .collect();
    let rows: Vec<&[f32]> = bursts.iter().map(Vec::as_slice).collect();
    let share = together_share(&rows, &votes).expect("ten windows");
    assert!(
        share < TOGETHER_SHARE,
        "four tones in turns: together in {share:.2} of the windows, not under {TOGETHER_SHARE}"
    );
    assert_eq!(
        together_share(&rows[..3], &votes),
        None,
        "three windows tell nothing"
    );
}
