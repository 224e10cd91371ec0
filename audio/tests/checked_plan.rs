//! A long message whose second frame is lost is never a wrong message under the checked
//! plan (issue #33). A robot sounds a long message; its second frame reaches the
//! listener 20–40 dB down (a notch of the room, a door, a second robot over it) under
//! white noise at 10 dB in-band. Under the seed's plan the first frame alone is a valid
//! short message, and the decoder, hearing the sender stop, reports it: a wrong message.
//! Under the checked plan the same frame cannot be a short message and is dropped.
//! Seeds 9101… (never tuned on).

use audio::channel::{power, white_sigma_for_in_band_snr, Source, WhiteNoise};
use audio::{
    Decoder, DecoderConfig, Detection, Encoder, EncoderConfig, Message, TeamMessage, TeamPlan,
};
use rand::{RngExt, SeedableRng};

fn decode(plan: TeamPlan, x: &[f32]) -> Vec<Detection> {
    let mut d = Decoder::new(DecoderConfig {
        team: plan,
        ..DecoderConfig::default()
    })
    .unwrap();
    let mut out = Vec::new();
    for block in x.chunks(1000) {
        d.push_f32(block);
        out.extend(std::iter::from_fn(|| d.poll_message()));
    }
    d.finish();
    out.extend(std::iter::from_fn(|| d.poll_message()));
    out
}

/// A long message of `plan` with its second frame `drop_db` down, in noise.
fn cut_long(plan: TeamPlan, robot: u8, value: u16, drop_db: f32, seed: u64) -> (Message, Vec<f32>) {
    let enc = Encoder::new(EncoderConfig::default()).unwrap();
    let m = plan
        .encode(TeamMessage {
            robot,
            long: true,
            value,
        })
        .unwrap();
    let tone = enc.encode_f32(&m);
    let half = tone.len() / 2;
    let mut x = vec![0.0f32; 16_000];
    x.extend_from_slice(&tone[..half]);
    let g = 10f32.powf(-drop_db / 20.0);
    x.extend(tone[half..].iter().map(|v| v * g));
    x.extend(vec![0.0f32; 32_000]);
    let sigma = white_sigma_for_in_band_snr(power(&tone[..half]), 10.0, 16_000);
    WhiteNoise::new(seed, sigma).add_to(&mut x);
    (m, x)
}

#[test]
fn a_long_message_cut_to_its_first_frame_is_lost_not_wrong() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9101);
    let (mut wrong_three, mut wrong_checked, mut refused) = (Vec::new(), Vec::new(), 0);
    for k in 0..24u64 {
        let robot = rng.random_range(0..3u8);
        let drop_db = rng.random_range(20.0f32..40.0);
        let seed = 9101 + k;
        // The seed's plan: any value.
        let (m, x) = cut_long(
            TeamPlan::Three,
            robot,
            rng.random_range(0..441),
            drop_db,
            seed,
        );
        wrong_three.extend(
            decode(TeamPlan::Three, &x)
                .into_iter()
                .filter(|d| d.message != m),
        );
        // The checked plan, the same cut.
        let (m, x) = cut_long(
            TeamPlan::Checked,
            robot,
            rng.random_range(0..121),
            drop_db,
            seed,
        );
        let heard = decode(TeamPlan::Three, &x);
        refused += heard
            .iter()
            .filter(|d| TeamPlan::Checked.decode(&d.message).is_none())
            .count();
        wrong_checked.extend(
            decode(TeamPlan::Checked, &x)
                .into_iter()
                .filter(|d| d.message != m),
        );
    }
    // The premise: the cut does fool the end test under the seed's plan.
    assert!(
        wrong_three.len() >= 12,
        "the seed's plan turns most cut long messages into short ones: {wrong_three:?}"
    );
    assert!(
        wrong_checked.is_empty(),
        "the checked plan reported something else than the long message sent: {wrong_checked:?}"
    );
    assert!(
        refused >= 12,
        "and its decoder dropped the cut frames: {refused} of 24"
    );
}
