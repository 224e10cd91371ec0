//! End-to-end codec stories: round trips at every rate and format, a recording made by
//! other code, corrupt files, noise, a whistle, and arbitrary input.

use std::io::Cursor;

use audio::channel::{power, white_sigma_for_in_band_snr, Source, Whistle, WhiteNoise};
use audio::evaluation::{run_snr_trial, run_whistle_over_messages, SnrTrial};
use audio::{
    read_wav, tone_frequency_hz, write_wav_i16, Decoder, DecoderConfig, Detection, Encoder,
    EncoderConfig, Frame, Message, ReadWavError, Sender,
};
use proptest::prelude::*;

fn decode(config: DecoderConfig, samples: &[f32], block: usize) -> Vec<Detection> {
    let mut d = Decoder::new(config).unwrap();
    let mut out = Vec::new();
    for chunk in samples.chunks(block.max(1)) {
        d.push_f32(chunk);
        out.extend(std::iter::from_fn(|| d.poll_message()));
    }
    d.finish();
    out.extend(std::iter::from_fn(|| d.poll_message()));
    out
}

fn decode_i16(config: DecoderConfig, samples: &[i16], block: usize) -> Vec<Detection> {
    let mut d = Decoder::new(config).unwrap();
    let mut out = Vec::new();
    for chunk in samples.chunks(block.max(1)) {
        d.push_i16(chunk);
        out.extend(std::iter::from_fn(|| d.poll_message()));
    }
    d.finish();
    out.extend(std::iter::from_fn(|| d.poll_message()));
    out
}

#[test]
fn round_trip_at_every_rate_in_both_formats() {
    let messages = [
        Message::short(Sender::Goalkeeper, 0).unwrap(),
        Message::long(Sender::RightAttacker, 21 * 13 + 2).unwrap(),
    ];
    for rate in [8_000u32, 16_000, 44_100, 48_000] {
        let enc = Encoder::new(EncoderConfig {
            sample_rate_hz: rate,
            ..Default::default()
        })
        .unwrap();
        let config = DecoderConfig {
            sample_rate_hz: rate,
            ..Default::default()
        };
        let pad = rate as usize / 2;
        for m in messages {
            let mut x = vec![0.0f32; pad];
            x.extend(enc.encode_f32(&m));
            x.extend(vec![0.0f32; 2 * pad]);
            let got = decode(config.clone(), &x, 777);
            assert_eq!(
                got.iter().map(|d| d.message).collect::<Vec<_>>(),
                vec![m],
                "f32 at {rate} Hz"
            );
            assert!(
                (got[0].start_s - 0.5).abs() < 0.05,
                "start {} at {rate} Hz",
                got[0].start_s
            );

            let mut y = vec![0i16; pad];
            y.extend(enc.encode_i16(&m));
            y.extend(vec![0i16; 2 * pad]);
            let got = decode_i16(config.clone(), &y, 4096);
            assert_eq!(
                got.iter().map(|d| d.message).collect::<Vec<_>>(),
                vec![m],
                "i16 at {rate} Hz"
            );
        }
    }
}

#[test]
fn short_tones_round_trip() {
    // A tenth of the seed's tone length.
    let enc = Encoder::new(EncoderConfig {
        tone_duration_s: 0.1,
        fade_s: 0.005,
        ..Default::default()
    })
    .unwrap();
    let config = DecoderConfig {
        tone_duration_s: 0.1,
        ..Default::default()
    };
    let mut x = vec![0.0f32; 4_000];
    let sent = [
        Message::short(Sender::LeftAttacker, 9).unwrap(),
        Message::long(Sender::Goalkeeper, 400).unwrap(),
        Message::short(Sender::RightAttacker, 20).unwrap(),
    ];
    for m in sent {
        x.extend(enc.encode_f32(&m));
        x.extend(vec![0.0f32; 4_000]);
    }
    let got: Vec<Message> = decode(config, &x, 160).iter().map(|d| d.message).collect();
    assert_eq!(got, sent);
}

/// Six tones written by plain sine code (not the encoder): another program's recording,
/// 0.5% sharp, 30 dB quieter than the encoder's level, on a DC offset, with noise and
/// 16-bit quantisation, through a WAV file.
fn foreign_recording(frame: Frame, scale: f64, seconds: f64) -> Vec<i16> {
    let rate = 16_000.0;
    let n = (seconds * rate) as usize;
    let start = (0.7 * rate) as usize;
    let mut noise = WhiteNoise::new(99, 0.002);
    let mut x = vec![0.0f32; n + 3 * rate as usize];
    noise.add_to(&mut x);
    for (i, v) in x.iter_mut().enumerate() {
        *v += 0.2; // DC offset
        if i >= start && i < start + n {
            let t = (i - start) as f64 / rate;
            let s: f64 = frame
                .tones()
                .iter()
                .map(|&k| {
                    (2.0 * std::f64::consts::PI * tone_frequency_hz(k) * scale * t + k as f64).sin()
                })
                .sum();
            *v += (0.004 * s) as f32;
        }
    }
    x.iter().map(|&v| (v * 32767.0).round() as i16).collect()
}

#[test]
fn decodes_a_recording_made_by_other_code_with_level_frequency_and_dc_errors() {
    for scale in [0.995, 1.005] {
        let frame = Frame {
            sender: Sender::RightAttacker,
            data: 11,
        };
        let samples = foreign_recording(frame, scale, 1.0);
        let mut file = Cursor::new(Vec::new());
        write_wav_i16(&mut file, 16_000, &samples).unwrap();
        let rec = read_wav(Cursor::new(file.into_inner())).unwrap();
        let got = decode(DecoderConfig::default(), &rec.samples, 1000);
        assert_eq!(got.len(), 1, "scale {scale}: {got:?}");
        assert_eq!(
            got[0].message,
            Message::short(frame.sender, frame.data).unwrap()
        );
        assert!(
            (got[0].frequency_scale - scale).abs() < 0.002,
            "scale estimate {} for {scale}",
            got[0].frequency_scale
        );
        assert!(
            (got[0].start_s - 0.7).abs() < 0.06,
            "start {}",
            got[0].start_s
        );
    }
}

#[test]
fn corrupt_and_truncated_wavs_are_typed_errors() {
    let mut file = Cursor::new(Vec::new());
    write_wav_i16(&mut file, 16_000, &[100; 1000]).unwrap();
    let bytes = file.into_inner();
    for cut in [0, 4, 12, 30, 43, 44 + 501] {
        let r = read_wav(Cursor::new(bytes[..cut].to_vec()));
        assert!(r.is_err(), "cut at {cut} must fail");
    }
    assert!(matches!(
        read_wav(Cursor::new(bytes[..44 + 500].to_vec())),
        Err(ReadWavError::Truncated { .. })
    ));
}

#[test]
fn loud_long_messages_start_where_they_start() {
    // 300 long messages at 0 dB (seed 103 of the eval's long row). A first slot that
    // starts late catches the second frame's data as a rival basic and the message is
    // lost; the onset is a least-squares fit over the windows around the edge, so one
    // plateau window reading low cannot pass for the edge.
    let out = run_snr_trial(&SnrTrial {
        seed: 103,
        snr_db: 0.0,
        messages: 300,
        tone_duration_s: 1.0,
        sample_rate_hz: 16_000,
        long_share: 1.0,
        frequency_error: 0.0,
    })
    .unwrap();
    assert_eq!(
        (out.correct, out.wrong, out.spurious),
        (300, 0, 0),
        "correct, wrong, extra of 300 long messages at 0 dB"
    );
    let mut errors = out.start_errors_s.clone();
    errors.sort_by(|a, b| a.total_cmp(b));
    let p95 = errors[errors.len() * 95 / 100];
    assert!(p95 < 0.03, "start error p95 {p95} s");
}

#[test]
fn noisy_messages_at_minus_6_db_decode() {
    // 200 messages (a quarter long) at −6 dB in-band SNR: seven dB above the target
    // operating point, so every one should come through, none wrong.
    let trial = SnrTrial {
        seed: 2026,
        snr_db: -6.0,
        messages: 200,
        tone_duration_s: 1.0,
        sample_rate_hz: 16_000,
        long_share: 0.25,
        frequency_error: 0.0,
    };
    let out = run_snr_trial(&trial).unwrap();
    assert_eq!(
        (out.correct, out.wrong, out.spurious),
        (200, 0, 0),
        "{out:?}"
    );
    // The same from a sender 0.3% sharp (resampled): the scale search finds it; a few
    // messages may be lost there (a known weakness), none may be wrong.
    let out = run_snr_trial(&SnrTrial {
        frequency_error: 0.003,
        messages: 150,
        ..trial
    })
    .unwrap();
    assert_eq!((out.wrong, out.spurious), (0, 0), "{out:?}");
    assert!(
        out.correct >= 147,
        "decoded {} of {}",
        out.correct,
        out.sent
    );
}

#[test]
fn a_whistle_over_messages_is_never_a_wrong_message() {
    let out = run_whistle_over_messages(40, 7);
    assert_eq!(out.wrong, 0, "{out:?}");
    assert_eq!(out.spurious, 0, "{out:?}");
    // A whistle up to 20 dB louder than the message, sweeping through a third of the
    // tones, adds extra basics to most frames, which the rules then refuse: a miss is
    // acceptable, a wrong message is not. Some must still get through.
    assert!(out.correct >= 4, "{out:?}");
}

#[test]
fn a_whistle_alone_is_not_a_message() {
    let mut x = vec![0.0f32; 16_000 * 30];
    WhiteNoise::new(1, 0.01).add_to(&mut x);
    Whistle::new(2, 16_000, 0.2).add_to(&mut x);
    assert!(power(&x) > 0.0);
    let got = decode(DecoderConfig::default(), &x, 4000);
    assert!(got.is_empty(), "{got:?}");
}

#[test]
fn quiet_message_in_noise_has_a_plausible_snr_estimate() {
    let enc = Encoder::new(EncoderConfig::default()).unwrap();
    let m = Message::short(Sender::Goalkeeper, 5).unwrap();
    let x = enc.encode_f32(&m);
    let sigma = white_sigma_for_in_band_snr(power(&x), 0.0, 16_000);
    let mut y = vec![0.0f32; 8_000];
    y.extend(x);
    y.extend(vec![0.0f32; 16_000]);
    WhiteNoise::new(5, sigma).add_to(&mut y);
    let got = decode(DecoderConfig::default(), &y, 512);
    assert_eq!(got.len(), 1);
    // 0 dB in-band, six tones: each tone is 1/6 of the power against 1/71 of the noise
    // band per ~49 Hz; in one 128 ms window that is about +17 dB.
    assert!(
        got[0].tone_snr_db > 10.0 && got[0].tone_snr_db < 25.0,
        "{}",
        got[0].tone_snr_db
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn arbitrary_sample_streams_never_panic(
        samples in proptest::collection::vec(prop_oneof![
            -2.0f32..2.0,
            Just(f32::NAN),
            Just(f32::INFINITY),
            Just(0.0f32),
            Just(1e30f32),
        ], 0..20_000),
        block in 1usize..3000,
        rate in prop_oneof![Just(8_000u32), Just(16_000), Just(44_100)],
        tone in audio::MIN_TONE_DURATION_S..1.5,
    ) {
        let config = DecoderConfig { sample_rate_hz: rate, tone_duration_s: tone, ..Default::default() };
        let _ = decode(config, &samples, block);
    }

    #[test]
    fn arbitrary_bytes_as_wav_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut b = b"RIFF\x24\x08\0\0WAVEfmt ".to_vec();
        b.extend(bytes.iter().copied());
        let _ = read_wav(Cursor::new(b));
        let _ = read_wav(Cursor::new(bytes));
    }
}
