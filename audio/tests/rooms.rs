//! Reverberant-hall stories: the room model has the reverberation it claims, messages
//! played into halls with babble decode (and long ones are not cut short by their own
//! tail), hours of reverberant babble say nothing, a hall built by another tool (sox's
//! `reverb`) decodes too, and the six-robot team plan works end to end.

use std::process::Command;

use audio::channel::{in_band_power, power, Convolver, RoomSpec, Source, WhiteNoise};
use audio::evaluation::{
    run_false_alarm_trial, run_room_false_alarm_trial, run_room_trial, Interference, RoomNoise,
    RoomTrial,
};
use audio::{
    read_wav, write_wav_f32, Decoder, DecoderConfig, Detection, Encoder, EncoderConfig, Message,
    Sender, TeamMessage, TeamPlan,
};
use proptest::prelude::*;

fn decode(config: DecoderConfig, samples: &[f32]) -> Vec<Detection> {
    let mut d = Decoder::new(config).unwrap();
    let mut out = Vec::new();
    for chunk in samples.chunks(1000) {
        d.push_f32(chunk);
        out.extend(std::iter::from_fn(|| d.poll_message()));
    }
    d.finish();
    out.extend(std::iter::from_fn(|| d.poll_message()));
    out
}

/// T60 from the impulse response's Schroeder decay curve: the −5 … −25 dB slope, × 3.
fn measured_t60(h: &[f32], rate: f64) -> f64 {
    let mut tail = vec![0.0f64; h.len() + 1];
    for i in (0..h.len()).rev() {
        tail[i] = tail[i + 1] + f64::from(h[i]) * f64::from(h[i]);
    }
    let db = |i: usize| 10.0 * (tail[i] / tail[0]).log10();
    let t5 = (0..h.len()).find(|&i| db(i) <= -5.0).unwrap();
    let t25 = (0..h.len()).find(|&i| db(i) <= -25.0).unwrap();
    3.0 * (t25 - t5) as f64 / rate
}

#[test]
fn the_room_model_has_the_reverberation_and_band_it_claims() {
    for (seed, t60) in [(3u64, 0.6), (4, 1.2), (5, 2.0)] {
        let spec = RoomSpec::hall(seed, t60, 16_000);
        let h = spec.impulse_response();
        assert_eq!(h, spec.impulse_response(), "seed {seed}: deterministic");
        let energy: f64 = h.iter().map(|&v| f64::from(v) * f64::from(v)).sum();
        assert!(
            (energy - 1.0).abs() < 1e-3,
            "seed {seed}: unit energy, got {energy}"
        );
        let got = measured_t60(&h, 16_000.0);
        assert!(
            (got / t60 - 1.0).abs() < 0.3,
            "seed {seed}: T60 {t60} s asked, {got:.2} s measured"
        );
        // White noise through the room: little left below 150 Hz (the band limit).
        let mut x = vec![0.0f32; 64_000];
        WhiteNoise::new(seed, 0.1).add_to(&mut x);
        let mut room = Convolver::new(&h);
        room.process(&mut x);
        let low = in_band_power(&x[16_000..], 16_000.0, 0.0, 150.0);
        let mid = in_band_power(&x[16_000..], 16_000.0, 1000.0, 1150.0);
        assert!(
            low < 0.1 * mid,
            "seed {seed}: band limit, {low:e} vs {mid:e}"
        );
    }
}

#[test]
fn the_convolver_matches_direct_convolution() {
    let h: Vec<f32> = (0..9000)
        .map(|i| ((i * 7919) % 13) as f32 / 13.0 - 0.5)
        .collect();
    let mut x = vec![0.0f32; 20_000];
    WhiteNoise::new(9, 1.0).add_to(&mut x);
    let mut y = x.clone();
    let mut c = Convolver::new(&h);
    for chunk in y.chunks_mut(777) {
        c.process(chunk);
    }
    let lat = c.latency();
    for i in [lat, lat + 1, lat + 5000, 19_999] {
        let n = i - lat;
        let direct: f64 = (0..=n.min(h.len() - 1))
            .map(|j| f64::from(h[j]) * f64::from(x[n - j]))
            .sum();
        assert!(
            (f64::from(y[i]) - direct).abs() < 1e-2 * (1.0 + direct.abs()),
            "sample {i}: {} vs {direct}",
            y[i]
        );
    }
}

#[test]
fn short_messages_decode_in_a_reverberant_hall_full_of_talkers() {
    // Seeds 71… are not among those `huddle audio eval` reports.
    for (seed, t60) in [(71u64, 1.2), (72, 2.0)] {
        let out = run_room_trial(&RoomTrial::new(seed, t60, 0.0, RoomNoise::Babble, 30)).unwrap();
        assert!(
            out.correct >= 27,
            "T60 {t60} s, babble 0 dB, seed {seed}: {} of 30 decoded",
            out.correct
        );
        assert_eq!(out.wrong, 0, "T60 {t60} s, seed {seed}: wrong messages");
        assert_eq!(out.spurious, 0, "T60 {t60} s, seed {seed}: extra messages");
    }
}

/// Two messages a babble hall used to cost (T60 1.2 s, six talkers at 0 dB in-band, 30
/// short messages per recording), each refused by a check that took what the hall does to
/// a real frame for a foreign sound. Before, each recording decoded 29 of 30, the one
/// below lost and nothing wrong:
/// - seed 3026, the goalkeeper's data 12 at 9.5 s: one tone's power peaked a comb step
///   off the scale the search had found the frame at (its sums still held the previous
///   message's tail), and the off-grid check, judging every tone at that scale, took it
///   for another codec's tone. At the slot's own common scale all six agree.
/// - seed 3005, the right attacker's data 20 at 59.6 s: talkers put two tones of another
///   data basic within 6 dB of a vote tone that sits in a notch of the room, a rival
///   basic, so no frame. Those tones come and go like speech; a second transmitter's
///   would sound through the slot.
#[test]
fn hall_colouring_no_longer_refuses_a_message() {
    for seed in [3026u64, 3005] {
        let out = run_room_trial(&RoomTrial::new(seed, 1.2, 0.0, RoomNoise::Babble, 30)).unwrap();
        assert!(out.missed.is_empty(), "seed {seed}: lost {:?}", out.missed);
        assert_eq!(
            out.correct, 30,
            "seed {seed}: {} of 30 decoded",
            out.correct
        );
        assert_eq!(out.wrong, 0, "seed {seed}: wrong messages");
        assert_eq!(out.spurious, 0, "seed {seed}: extra messages");
    }
}

/// Long messages in a hall: the second frame's data tones may reach the microphone far
/// below the first frame's (each tone has its own room response), which once made the end
/// test stop on a sender that plainly went on, reporting a wrong short. A long message may
/// be lost when the end cannot be told, never cut short.
#[test]
fn a_long_message_is_not_cut_short_by_its_own_tail() {
    for seed in [73u64, 80] {
        let mut trial = RoomTrial::new(seed, 1.2, 10.0, RoomNoise::White, 24);
        trial.long_share = 1.0;
        let out = run_room_trial(&trial).unwrap();
        assert_eq!(
            out.wrong, 0,
            "seed {seed}: a long message reported as a short (or garbled)"
        );
        assert!(
            out.correct >= 20,
            "seed {seed}: {} of 24 long messages decoded",
            out.correct
        );
    }
}

/// Long messages in halls full of talkers: a second frame's data tones may reach the
/// microphone 10 dB below the first frame's while its sender plainly goes on, and babble
/// puts power on any data basic; the end test once stopped on the first frame within a
/// few windows, reporting a wrong short (seed 87 lost one that way at T60 1.2 s and one
/// at 2.5 s). A long message may be lost, never cut short. Seeds 86 and 87 are not among
/// those `huddle audio eval` reports.
#[test]
fn long_messages_in_babble_halls_are_lost_rather_than_cut_short() {
    for seed in [86u64, 87] {
        for t60 in [1.2, 2.5] {
            let mut trial = RoomTrial::new(seed, t60, 0.0, RoomNoise::Babble, 30);
            trial.long_share = 1.0;
            let out = run_room_trial(&trial).unwrap();
            assert_eq!(
                out.wrong, 0,
                "seed {seed}, T60 {t60} s: a long message reported as a short (or garbled)"
            );
            assert!(
                out.correct >= 15,
                "seed {seed}, T60 {t60} s: {} of 30 long messages decoded",
                out.correct
            );
        }
    }
}

/// The longest hall the issue names (T60 2.5 s) at babble 0 dB: a short message's tail
/// with the same data once passed for a second frame (a wrong long), or for a
/// continuation that lost the message; the second slot must now keep the sender's level,
/// and a sender plainly silent half a slot later makes it a short.
#[test]
fn short_messages_decode_in_the_longest_hall() {
    for seed in [88u64, 89] {
        let out = run_room_trial(&RoomTrial::new(seed, 2.5, 0.0, RoomNoise::Babble, 40)).unwrap();
        assert!(
            out.correct >= 37,
            "T60 2.5 s, babble 0 dB, seed {seed}: {} of 40 decoded",
            out.correct
        );
        assert_eq!(out.wrong, 0, "T60 2.5 s, seed {seed}: wrong messages");
        assert_eq!(out.spurious, 0, "T60 2.5 s, seed {seed}: extra messages");
    }
}

#[test]
fn minutes_of_reverberant_babble_say_nothing() {
    let out = run_room_false_alarm_trial(1.5, 0.05, 74);
    assert_eq!(
        out.false_messages, 0,
        "false messages in 3 min of reverberant babble: {:?}",
        out.detections
    );
}

/// Twenty minutes of six talkers, in a T60 1.2 s hall and dry, at the level of a message:
/// nothing may be reported. Babble is the structured sound the Gaussian false-alarm
/// argument does not cover (see the decoder docs); seeds 81 and 82 are not among those
/// `huddle audio eval` reports.
#[test]
fn twenty_minutes_of_babble_in_a_hall_and_dry_say_nothing() {
    let hall = run_room_false_alarm_trial(1.2, 1.0 / 3.0, 81);
    assert_eq!(
        hall.false_messages, 0,
        "false messages in 20 min of reverberant babble: {:?}",
        hall.detections
    );
    let dry = run_false_alarm_trial(Interference::Babble, 1.0 / 3.0, 82);
    assert_eq!(
        dry.false_messages, 0,
        "false messages in 20 min of dry babble: {:?}",
        dry.detections
    );
}

/// The false-message row at full length: ten hours each of reverberant (T60 1.2 s
/// and 2.0 s) and dry babble, no message may be reported. Takes about ten minutes in
/// release: `cargo test --release -p audio --test rooms -- --ignored ten_hours`.
///
/// Measured at this commit: 0 false in 10 h in each of the T60 1.2 s hall (seed 83), the
/// T60 2.0 s hall (seed 84) and dry (seed 85); 390 s in release. (An intermediate
/// version that let an end test "unclear" be decided half a slot later for any frame
/// reported one frame of tones 2.4 dB above the floor in the T60 2.0 s hall: such late
/// decisions now need the frame's tones 6 dB up.) `huddle audio eval` shows the reported
/// seeds' figures.
///
/// With the hall allowances (a rival or stray of babble beside a frame, a failed slot of
/// babble before it, the slot's own common scale): 0 false in each row again, 289 s in
/// release. Made for every frame they let 1, 3 and 1 false messages through (T60 1.2 s,
/// 2.0 s, dry); for frames 6 dB up, 0, 2 and 1 (the dry one a frame of 11 dB whose
/// babble rival no longer counted): hence 15 dB.
#[test]
#[ignore = "ten hours of audio per row (minutes in release); run with --ignored"]
fn ten_hours_of_babble_in_halls_and_dry_say_nothing() {
    let mut heard = Vec::new();
    for (t60, seed) in [(1.2, 83u64), (2.0, 84)] {
        let out = run_room_false_alarm_trial(t60, 10.0, seed);
        heard.push((format!("T60 {t60} s hall, seed {seed}"), out.detections));
    }
    let dry = run_false_alarm_trial(Interference::Babble, 10.0, 85);
    heard.push(("dry, seed 85".to_string(), dry.detections));
    for (row, detections) in &heard {
        eprintln!("{row}: {} false in 10 h", detections.len());
    }
    assert!(
        heard.iter().all(|(_, d)| d.is_empty()),
        "false messages in 10 h of babble: {heard:?}"
    );
}

#[test]
fn six_robots_are_told_apart_in_a_hall() {
    let plan = TeamPlan::Six;
    let enc = Encoder::new(EncoderConfig::default()).unwrap();
    let h = RoomSpec::hall(75, 1.0, 16_000).impulse_response();
    let mut room = Convolver::new(&h);
    let sent: Vec<TeamMessage> = (0..6u8)
        .map(|robot| TeamMessage {
            robot,
            long: false,
            value: u16::from(robot) + 2,
        })
        .collect();
    let mut x = vec![0.0f32; 16_000];
    for m in &sent {
        x.extend(enc.encode_f32(&plan.encode(*m).unwrap()));
        x.extend(vec![0.0f32; 20_000]);
    }
    x.extend(vec![0.0f32; 32_000]);
    room.process(&mut x);
    let sigma = audio::channel::white_sigma_for_in_band_snr(power(&x), 0.0, 16_000);
    WhiteNoise::new(76, sigma).add_to(&mut x);
    let config = DecoderConfig {
        team: plan,
        ..DecoderConfig::default()
    };
    let got: Vec<TeamMessage> = decode(config, &x)
        .iter()
        .map(|d| {
            d.team_message(plan)
                .expect("the decoder keeps only the plan's")
        })
        .collect();
    assert_eq!(
        got, sent,
        "six robots, one message each, in a T60 1 s hall at 0 dB"
    );
}

#[test]
fn a_six_robot_decoder_drops_what_the_plan_cannot_send() {
    let enc = Encoder::new(EncoderConfig::default()).unwrap();
    // Data 20 and a long message across banks: valid in the seed's plan only.
    let foreign = [
        Message::short(Sender::RightAttacker, 20).unwrap(),
        Message::long(Sender::Goalkeeper, 21 * 2 + 15).unwrap(),
    ];
    let mut x = vec![0.0f32; 8_000];
    for m in foreign {
        x.extend(enc.encode_f32(&m));
        x.extend(vec![0.0f32; 16_000]);
    }
    let three = decode(DecoderConfig::default(), &x);
    assert_eq!(three.len(), 2, "the seed's plan hears both");
    let six = decode(
        DecoderConfig {
            team: TeamPlan::Six,
            ..DecoderConfig::default()
        },
        &x,
    );
    assert!(six.is_empty(), "the six-robot plan reports none: {six:?}");
}

/// A hall built by another tool: sox's `reverb` (a Freeverb-style network, not image
/// sources), a 300–6000 Hz band and pink noise, decoded through the WAV path.
#[test]
fn a_hall_built_by_sox_decodes() {
    if Command::new("sox").arg("--version").output().is_err() {
        eprintln!("SKIPPED: sox is not installed (scripts/install-sox.sh installs it)");
        return;
    }
    let dir = std::env::temp_dir().join(format!("audio-sox-room-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let enc = Encoder::new(EncoderConfig::default()).unwrap();
    let sent = [
        Message::short(Sender::Goalkeeper, 4).unwrap(),
        Message::short(Sender::RightAttacker, 17).unwrap(),
        Message::long(Sender::LeftAttacker, 21 * 9 + 12).unwrap(),
        Message::short(Sender::LeftAttacker, 0).unwrap(),
    ];
    let mut x = vec![0.0f32; 16_000];
    for m in &sent {
        x.extend(enc.encode_f32(m));
        x.extend(vec![0.0f32; 24_000]);
    }
    let dry = dir.join("dry.wav");
    let wet = dir.join("wet.wav");
    write_wav_f32(std::fs::File::create(&dry).unwrap(), 16_000, &x).unwrap();
    for (reverberance, room_scale) in [("60", "80"), ("90", "100")] {
        let status = Command::new("sox")
            .arg(&dry)
            .args(["-b", "16"])
            .arg(&wet)
            .args([
                "reverb",
                "-w",
                reverberance,
                "50",
                room_scale,
                "100",
                "20",
                "0",
            ])
            .args(["sinc", "300-6000", "gain", "-n", "-6"])
            .status()
            .unwrap();
        assert!(status.success(), "sox failed");
        let rec = read_wav(std::fs::File::open(&wet).unwrap()).unwrap();
        let mut y = rec.samples.clone();
        let sigma = audio::channel::white_sigma_for_in_band_snr(power(&y) * 1.5, 3.0, 16_000);
        WhiteNoise::new(77, sigma).add_to(&mut y);
        let got: Vec<Message> = decode(DecoderConfig::default(), &y)
            .iter()
            .map(|d| d.message)
            .collect();
        assert_eq!(
            got, sent,
            "sox reverb {reverberance}% room scale {room_scale}%"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Arbitrary audio into a six-robot decoder: no panic, and whatever it reports is a
    /// message of its plan.
    #[test]
    fn a_six_robot_decoder_reports_only_its_plan(
        samples in proptest::collection::vec(-2.0f32..2.0, 0..20_000),
        block in 1usize..3000,
    ) {
        let plan = TeamPlan::Six;
        let mut d = Decoder::new(DecoderConfig { team: plan, ..DecoderConfig::default() }).unwrap();
        for chunk in samples.chunks(block) {
            d.push_f32(chunk);
            while let Some(det) = d.poll_message() {
                prop_assert!(det.team_message(plan).is_some());
            }
        }
        d.finish();
        while let Some(det) = d.poll_message() {
            prop_assert!(det.team_message(plan).is_some());
        }
    }
}

/// A decoder must not stall for good. In this T60 2.0 s hall with babble 10 dB down
/// (`huddle audio eval --section rooms --seed 2`, row seed 1312), a replay of the search
/// once re-added windows to the sliding sums that were already in them. The sums then
/// ran ahead of the audio, the oldest window could no longer be taken off, and from
/// 902 s on every message was lost: 426 of 1,000 were decoded, against 943 with the sums
/// kept to consecutive windows, each counted once.
#[test]
fn a_long_hall_recording_never_stalls_the_decoder() {
    let out = run_room_trial(&RoomTrial::new(1312, 2.0, 10.0, RoomNoise::Babble, 1000)).unwrap();
    let lost_late = out
        .missed
        .iter()
        .filter(|(_, start, _)| *start > out.samples as f64 / 16_000.0 * 0.8)
        .count();
    assert!(
        lost_late < 30,
        "{lost_late} messages lost in the last fifth of the recording ({} of {} decoded): the \
         decoder stalled",
        out.correct,
        out.sent
    );
    assert!(
        out.correct * 100 >= out.sent * 88,
        "{} of {} decoded in a T60 2.0 s hall, babble 10 dB down",
        out.correct,
        out.sent
    );
}
