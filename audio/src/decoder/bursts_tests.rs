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
