//! The retried first slot's guard against another robot (`Decoder::rival_senders_beginning`,
//! report row 1012031 at 862.52 s; see `docs/results/acoustic-round23-report.md`).

use super::{Stage, Tracking};
use crate::decoder::{Decoder, DecoderConfig};
use crate::tones::{tone_frequency_hz, Sender, TONE_COUNT};

/// Tones `(index, from s, to s)` at one amplitude over faint white noise, 3 s.
fn scene(tones: &[(usize, f64, f64)]) -> Vec<f32> {
    let rate = 16_000.0;
    let mut x: Vec<f32> = (0..(3.0 * rate) as usize)
        .map(|n| {
            let t = n as f64 / rate;
            tones
                .iter()
                .filter(|&&(_, from, to)| (from..to).contains(&t))
                .map(|&(k, _, _)| {
                    0.01 * (2.0 * std::f64::consts::PI * tone_frequency_hz(k) * t).sin()
                })
                .sum::<f64>() as f32
        })
        .collect();
    let mut noise = crate::channel::WhiteNoise::new(1012, 0.002);
    crate::channel::Source::add_to(&mut noise, &mut x);
    x
}

#[test]
fn a_retried_slot_where_another_robot_began_with_the_frames_data_is_caught() {
    // Two robots half a tone apart: LeftAttacker's sender (k1, k25, k49) and data 13 (k16,
    // k40, k64) from 0.5 s, Goalkeeper's sender (k0, k24, k48) and data 8 (k11, k35, k59)
    // from 1.0 s. A first slot retried at 0.85 s holds Goalkeeper's frame from its fifth
    // on. Taken as LeftAttacker with data 8, the data began inside the slot with
    // Goalkeeper's sender while LeftAttacker's sounded before: Goalkeeper is the robot
    // that began there, the data its own. Taken as LeftAttacker with its own data 13
    // (sounding from 0.5 s), or as Goalkeeper's frame, nothing is caught.
    let x = scene(&[
        (1, 0.5, 2.5),
        (25, 0.5, 2.5),
        (49, 0.5, 2.5),
        (16, 0.5, 2.5),
        (40, 0.5, 2.5),
        (64, 0.5, 2.5),
        (0, 1.0, 2.0),
        (24, 1.0, 2.0),
        (48, 1.0, 2.0),
        (11, 1.0, 2.0),
        (35, 1.0, 2.0),
        (59, 1.0, 2.0),
    ]);
    let mut d = Decoder::new(DecoderConfig::default()).unwrap();
    d.push_f32(&x);
    let rate = 16_000.0;
    let (a, b) = (0.85 * rate, 1.85 * rate);
    let tracking = |sender: Sender, data: u8| Tracking {
        sender,
        data: [data, data],
        scale: d.geometry.nominal_scale(),
        onset: a,
        onset_refined: true,
        found_onset: a,
        stage: Stage::Slot1,
        level: [0.0; TONE_COUNT],
        present: [false; TONE_COUNT],
        noise: 1.0,
    };
    let goalkeeper = Sender::Goalkeeper.index() as usize;
    let left = Sender::LeftAttacker.index() as usize;
    let t = tracking(Sender::LeftAttacker, 8);
    assert_eq!(
        d.rival_senders(&t, a, b),
        vec![goalkeeper],
        "Goalkeeper's sender sounds over the slot"
    );
    assert_eq!(
        d.rival_senders_beginning(&t, &[goalkeeper], a, b),
        vec![goalkeeper],
        "LeftAttacker with data 8: Goalkeeper began inside the slot with that data"
    );
    let t = tracking(Sender::LeftAttacker, 13);
    assert!(
        d.rival_senders_beginning(&t, &[goalkeeper], a, b)
            .is_empty(),
        "LeftAttacker with its own data 13, sounding before the slot: not caught"
    );
    let t = tracking(Sender::Goalkeeper, 8);
    assert!(
        d.rival_senders_beginning(&t, &[left], a, b).is_empty(),
        "Goalkeeper's own frame, its sender began with its data: not caught"
    );
}
