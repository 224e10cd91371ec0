//! The decoder's unit tests: clean messages, the end test's timing, the Goertzel powers,
//! and sounds that must not be taken for a message.

use super::end_test::tone_powers;
use super::*;
use crate::encoder::{Encoder, EncoderConfig};
use crate::tones::{basic_tones, tone_frequency_hz, Frame, SENDER_COUNT};

mod room;
mod second_slot;
mod sender_vote;

fn decode_all(config: DecoderConfig, samples: &[f32], block: usize) -> Vec<Detection> {
    let mut d = Decoder::new(config).unwrap();
    decode_with(&mut d, samples, block)
}

/// Pushes `samples` through `d` in blocks of `block`, finishes, and returns every
/// message it reported.
fn decode_with(d: &mut Decoder, samples: &[f32], block: usize) -> Vec<Detection> {
    let mut out = Vec::new();
    for chunk in samples.chunks(block.max(1)) {
        d.push_f32(chunk);
        while let Some(m) = d.poll_message() {
            out.push(m);
        }
    }
    d.finish();
    while let Some(m) = d.poll_message() {
        out.push(m);
    }
    out
}

/// The default decoder, tracing, over `samples` in blocks of 1,000: the messages, and
/// its trace outside the search (for an assertion's message).
pub(super) fn decode_traced(samples: &[f32]) -> (Vec<Message>, Vec<TraceEvent>, Vec<String>) {
    decode_traced_with(DecoderConfig::default(), samples)
}

/// [`decode_traced`] with the decoder set to `config`.
pub(super) fn decode_traced_with(
    config: DecoderConfig,
    samples: &[f32],
) -> (Vec<Message>, Vec<TraceEvent>, Vec<String>) {
    let mut d = Decoder::new(config).unwrap();
    d.enable_trace();
    let got = decode_with(&mut d, samples, 1000)
        .into_iter()
        .map(|m| m.message)
        .collect();
    let trace = d.take_trace();
    let shown = trace
        .iter()
        .filter(|e| !e.what.starts_with("search"))
        .map(|e| format!("{:.2} {}", e.at_s, e.what))
        .collect();
    (got, trace, shown)
}

#[test]
fn clean_short_message_decodes_once_with_its_start_time() {
    let enc = Encoder::new(EncoderConfig::default()).unwrap();
    let msg = Message::short(Sender::LeftAttacker, 17).unwrap();
    let mut x = vec![0.0f32; 8_000];
    x.extend(enc.encode_f32(&msg));
    x.extend(vec![0.0f32; 16_000]);
    let got = decode_all(DecoderConfig::default(), &x, 333);
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(got[0].message, msg);
    assert!(
        (got[0].start_s - 0.5).abs() < 0.03,
        "start {}",
        got[0].start_s
    );
    // Loud and clean: the end test decides on its first short window (64 ms from
    // the end), not a whole analysis window later.
    assert!(
        got[0].decided_at_s - 1.5 < 0.1,
        "decided at {}",
        got[0].decided_at_s
    );
}

#[test]
fn goertzel_powers_match_the_direct_sum_off_the_bins() {
    // A tone 1.3 Hz off one of ours plus a step, through a 1024-sample Hann window:
    // the recursion must give the same |Σ y e^{−iωn}|² as the sum it replaces.
    let rate = 16_000.0;
    let y: Vec<f64> = (0..1024)
        .map(|n| {
            let hann = 0.5 - 0.5 * (2.0 * std::f64::consts::PI * n as f64 / 1024.0).cos();
            let t = n as f64 / rate;
            let x = (2.0 * std::f64::consts::PI * (tone_frequency_hz(30) + 1.3) * t).sin()
                + if n > 300 { 0.2 } else { -0.1 };
            x * hann
        })
        .collect();
    let omega: [f64; TONE_COUNT] =
        std::array::from_fn(|k| 2.0 * std::f64::consts::PI * tone_frequency_hz(k) / rate);
    let coefs: [f64; TONE_COUNT] = std::array::from_fn(|k| 2.0 * omega[k].cos());
    let got = tone_powers(&y, &coefs);
    for k in [0, 29, 30, 31, 71] {
        let (re, im) = y.iter().enumerate().fold((0.0, 0.0), |(re, im), (n, &v)| {
            let p = omega[k] * n as f64;
            (re + v * p.cos(), im - v * p.sin())
        });
        let direct = re * re + im * im;
        assert!(
            (got[k] - direct).abs() <= 1e-9 * direct.max(1.0),
            "tone {k}: Goertzel {} vs direct {direct}",
            got[k]
        );
    }
}

#[test]
fn messages_at_minus_6_db_are_reported_about_100_ms_after_their_end() {
    // 40 short messages in white noise at −6 dB in-band SNR (seed 11): the sender's
    // tones are ~8 dB above the noise in a 64 ms window after the end, so the short
    // windows reach the "stopped" bound within a few 16 ms hops, well before the
    // 128 ms analysis windows would.
    let out = crate::evaluation::run_snr_trial(&crate::evaluation::SnrTrial {
        seed: 11,
        snr_db: -6.0,
        messages: 40,
        tone_duration_s: 1.0,
        sample_rate_hz: 16_000,
        long_share: 0.0,
        frequency_error: 0.0,
    })
    .unwrap();
    assert_eq!((out.correct, out.wrong), (40, 0), "{out:?}");
    let mut delays_ms: Vec<f64> = out.delays_s.iter().map(|d| d * 1000.0).collect();
    delays_ms.sort_by(|a, b| a.total_cmp(b));
    let median = delays_ms[delays_ms.len() / 2];
    let last = delays_ms[delays_ms.len() - 1];
    assert!(
        median <= 120.0 && last <= 200.0,
        "median delay {median:.0} ms, longest {last:.0} ms: {delays_ms:.0?}"
    );
}

#[test]
fn clean_long_message_decodes_as_one_long() {
    let enc = Encoder::new(EncoderConfig::default()).unwrap();
    for value in [0u16, 21 * 4 + 4, 440, 123] {
        let msg = Message::long(Sender::Goalkeeper, value).unwrap();
        let mut x = vec![0.0f32; 4_000];
        x.extend(enc.encode_f32(&msg));
        x.extend(vec![0.0f32; 16_000]);
        let got = decode_all(DecoderConfig::default(), &x, 1024);
        assert_eq!(
            got.iter().map(|d| d.message).collect::<Vec<_>>(),
            vec![msg],
            "value {value}"
        );
    }
}

/// Six plain sines at `frame`'s tones, tone `i` moved by `offsets_hz[i]`, 1 s long.
fn sines(frame: Frame, offsets_hz: [f64; 6], rate: f64) -> Vec<f32> {
    let tones = frame.tones();
    (0..rate as usize)
        .map(|n| {
            let t = n as f64 / rate;
            tones
                .iter()
                .zip(offsets_hz)
                .map(|(&k, d)| {
                    (2.0 * std::f64::consts::PI * (crate::tones::tone_frequency_hz(k) + d) * t)
                        .sin()
                })
                .sum::<f64>() as f32
                * 0.05
        })
        .collect()
}

#[test]
fn tones_off_our_grid_by_their_own_amounts_are_not_a_message() {
    // Another codec's six tones, each near one of ours but off by its own amount (as a
    // 50 Hz grid passes ours): loud and clean, every tone inside the ±0.6% tolerance,
    // yet no one frequency scale explains them all. The same tones moved by
    // one common factor (a sender's clock 0.4% fast) are our message.
    let frame = Frame {
        sender: Sender::RightAttacker,
        data: 7,
    };
    let mut noise = crate::channel::WhiteNoise::new(6, 0.002);
    let lead = vec![0.0f32; 8_000];
    let tail = vec![0.0f32; 16_000];
    let scaled: [f64; 6] = {
        let tones = frame.tones();
        std::array::from_fn(|i| 0.004 * crate::tones::tone_frequency_hz(tones[i]))
    };
    for (offsets, expected) in [
        ([7.0, -6.0, 9.0, -5.0, 8.0, -7.0], 0),
        // Only 2 Hz off each way: every tone keeps most of its power at a middle
        // scale, but their peaks disagree by 4 Hz, where ours agree to a small fraction
        // of a hertz.
        ([2.0, -2.0, 2.0, -2.0, 2.0, -2.0], 0),
        (scaled, 1),
    ] {
        let mut x = lead.clone();
        x.extend(sines(frame, offsets, 16_000.0));
        x.extend(&tail);
        crate::channel::Source::add_to(&mut noise, &mut x);
        let got = decode_all(DecoderConfig::default(), &x, 1000);
        assert_eq!(got.len(), expected, "offsets {offsets:?}: {got:?}");
    }
}

#[test]
fn tones_shorter_than_the_shortest_window_are_refused_up_front() {
    // Tones much shorter than the 64 ms shortest window are decoded wrongly too
    // often; the decoder says so at configuration instead of guessing.
    for (tone_s, ok) in [(0.04, false), (0.059, false), (0.06, true), (1.0, true)] {
        let got = Decoder::new(DecoderConfig {
            tone_duration_s: tone_s,
            ..DecoderConfig::default()
        });
        assert_eq!(got.is_ok(), ok, "{tone_s} s tones");
    }
}

#[test]
fn a_file_holding_just_the_message_decodes() {
    // `huddle audio encode` writes the tones and nothing else: no noise, no silence
    // before or after. The noise level then drifts down by orders of magnitude over
    // the first windows (digital silence between the tones); an onset found on each
    // window's own level lands windows late, and the message is dropped as the second
    // half of a long one.
    let enc = Encoder::new(EncoderConfig::default()).unwrap();
    for msg in [
        Message::short(Sender::RightAttacker, 7).unwrap(),
        Message::long(Sender::LeftAttacker, 300).unwrap(),
    ] {
        let got = decode_all(DecoderConfig::default(), &enc.encode_f32(&msg), 4096);
        assert_eq!(got.iter().map(|d| d.message).collect::<Vec<_>>(), vec![msg]);
        assert!(got[0].start_s.abs() < 0.02, "start {}", got[0].start_s);
    }
}

#[test]
fn a_burst_whose_low_tones_lie_beyond_the_tolerance_is_not_a_message() {
    // A foreign burst: four loud tones, two of each
    // of two of our basics' three; three are 0.55% sharp, one is 0.74% sharp, beyond
    // the ±0.6% comb, where the comb's last bin still reads it strongly. The bin just
    // beyond the comb shows its peak is out there. The same four tones all 0.55%
    // sharp are our frame (2 of 3 tones of each basic).
    let rate = 16_000.0;
    let play = |tones: &[(usize, f64)]| -> Vec<f32> {
        let mut x = vec![0.0f32; 8_000];
        x.extend((0..16_000).map(|n| {
            let t = n as f64 / rate;
            tones
                .iter()
                .map(|&(k, e)| {
                    (2.0 * std::f64::consts::PI
                        * crate::tones::tone_frequency_hz(k)
                        * (1.0 + e)
                        * t)
                        .sin()
                })
                .sum::<f64>() as f32
                * 0.05
        }));
        x.extend(vec![0.0f32; 16_000]);
        crate::channel::Source::add_to(&mut crate::channel::WhiteNoise::new(9, 0.002), &mut x);
        x
    };
    let foreign = play(&[(2, 0.0055), (11, 0.0074), (26, 0.0055), (35, 0.0055)]);
    let got = decode_all(DecoderConfig::default(), &foreign, 1000);
    assert!(got.is_empty(), "foreign burst decoded: {got:?}");
    let ours = play(&[(2, 0.0055), (11, 0.0055), (26, 0.0055), (35, 0.0055)]);
    let got = decode_all(DecoderConfig::default(), &ours, 1000);
    assert_eq!(
        got.iter().map(|d| d.message).collect::<Vec<_>>(),
        vec![Message::short(Sender::RightAttacker, 8).unwrap()]
    );
}

#[test]
fn two_senders_at_once_is_not_a_message() {
    let enc = Encoder::new(EncoderConfig::default()).unwrap();
    let a = enc.encode_f32(&Message::short(Sender::Goalkeeper, 3).unwrap());
    let b = enc.encode_f32(&Message::short(Sender::RightAttacker, 3).unwrap());
    let mut x = vec![0.0f32; 4_000];
    x.extend(a.iter().zip(&b).map(|(p, q)| p + q));
    x.extend(vec![0.0f32; 16_000]);
    let got = decode_all(DecoderConfig::default(), &x, 500);
    assert!(
        got.is_empty(),
        "two sender basics must be rejected: {got:?}"
    );
}

/// A long message of sender 2, data 19 then 8, 1 s after the start, whose second frame's
/// data tones arrive `faint` of the amplitude of every other tone (in a hall each tone
/// reaches the microphone at its own level), over white noise at 10 dB in-band (seed 15).
fn long_message_with_a_faint_second_data(faint: f64) -> Vec<f32> {
    let rate = 16_000.0;
    let first = Frame {
        sender: Sender::RightAttacker,
        data: 19,
    };
    let second = Frame {
        sender: Sender::RightAttacker,
        data: 8,
    };
    let tone = |k: usize, n: usize, gain: f64| {
        gain * (2.0 * std::f64::consts::PI * tone_frequency_hz(k) * n as f64 / rate).sin()
    };
    let mut x = vec![0.0f32; 16_000];
    for n in 0..32_000usize {
        let frame = if n < 16_000 { first } else { second };
        let s: f64 = frame
            .tones()
            .iter()
            .map(|&k| {
                // Sender basics are 0–2, data basics 3–23, in each third of the tones.
                let data = k % 24 >= 3;
                tone(
                    k,
                    n,
                    if data && n >= 16_000 {
                        0.05 * faint
                    } else {
                        0.05
                    },
                )
            })
            .sum();
        x.push(s as f32);
    }
    x.extend(vec![0.0f32; 24_000]);
    let sigma = crate::channel::white_sigma_for_in_band_snr(0.0075, 10.0, 16_000);
    crate::channel::Source::add_to(&mut crate::channel::WhiteNoise::new(15, sigma), &mut x);
    x
}

#[test]
fn a_long_message_whose_second_data_is_faint_is_never_cut_to_a_short() {
    // Here the second frame's data tones arrive 16 dB below everything else, the sender's
    // tones go on at full level. The end test after the first frame must not call that
    // "stopped" (a short would be a wrong message): the long message, or nothing.
    let x = long_message_with_a_faint_second_data(0.158);
    let got = decode_all(DecoderConfig::default(), &x, 1000);
    assert!(
        got.iter()
            .all(|d| matches!(d.message, Message::Long { .. })),
        "a short reported for a long message: {got:?}"
    );
}

#[test]
fn a_long_message_whose_second_data_is_faint_is_decided_on_its_second_slot() {
    // Lab T60 2.0 s at 0 dB (tuning rows 11027, 14027, 15027): 25 of 105 lost long
    // messages ended with the end test after the first slot "unclear", the sender going
    // on but no data basic at the first frame's level (a second frame's data in a notch
    // of the room, 10-20 dB below the first's), and were dropped without a look at the
    // second slot. The second slot is now decided on its own evidence: data tones 16 and
    // 20 dB below the rest are the long message (old code: nothing).
    let long = Message::long(Sender::RightAttacker, 21 * 19 + 8).unwrap();
    for (faint, db) in [(0.158, 16), (0.1, 20)] {
        let (got, _, shown) = decode_traced(&long_message_with_a_faint_second_data(faint));
        assert_eq!(
            got,
            vec![long],
            "second data {db} dB below the rest: {shown:#?}"
        );
    }
}

/// A long message of sender 1 (its tones k1 silent, k25 sounding, k49 12 dB below k25: a
/// room's notches), data 16 then `second` (`None`: no second data at all), 1 s after the
/// start, in a T60 2.0 s room's way: every tone rings on after it stops, falling 30 dB per
/// second. The second frame's middle data tone sounds 14 dB above the rest, so k49 is
/// 26 dB below it. White noise at 0 dB in-band to the first frame (seed 33).
fn long_message_with_a_weak_sender_tone(second: Option<u8>) -> Vec<f32> {
    let rate = 16_000.0;
    let a = 0.05;
    // (tone, amplitude, from, to) in samples.
    let mut tones: Vec<(usize, f64, usize, usize)> =
        vec![(25, a, 16_000, 48_000), (49, 0.25 * a, 16_000, 48_000)];
    for k in basic_tones(SENDER_COUNT + 16) {
        tones.push((k, a, 16_000, 32_000));
    }
    if let Some(d) = second {
        let [low, middle, high] = basic_tones(SENDER_COUNT + usize::from(d));
        tones.extend([
            (low, a, 32_000, 48_000),
            (middle, 5.0 * a, 32_000, 48_000),
            (high, a, 32_000, 48_000),
        ]);
    }
    let mut x = vec![0.0f32; 88_000];
    for (k, amp, from, to) in tones {
        let w = 2.0 * std::f64::consts::PI * tone_frequency_hz(k) / rate;
        for (n, v) in x.iter_mut().enumerate().skip(from) {
            // 30 dB per second after the tone stops: amplitude × 10^(−1.5 t).
            let ring = if n < to {
                1.0
            } else {
                10f64.powf(-1.5 * (n - to) as f64 / rate)
            };
            *v += (amp * ring * (w * n as f64).sin()) as f32;
        }
    }
    let sigma = crate::channel::white_sigma_for_in_band_snr(4.0 * a * a / 2.0, 0.0, 16_000);
    crate::channel::Source::add_to(&mut crate::channel::WhiteNoise::new(33, sigma), &mut x);
    x
}

#[test]
fn a_second_frame_louder_than_the_first_keeps_the_senders_weak_tone() {
    // Lab T60 2.0 s at 0 dB (tuning rows 11027, 14027, 15027): 16 of 25 second slots
    // refused by the rules had the sender's weak tone at its first-slot level, but 25 dB
    // below the second frame's loudest data tone, where the rules stop counting tones
    // (e.g. k49 at 14 per window in both slots, k41 at 8,060), while the first frame's
    // data rang on into the slot. The sender is the first slot's, and its tone kept its
    // level: the long message (old code: nothing).
    let long = Message::long(Sender::LeftAttacker, 21 * 16 + 5).unwrap();
    let (got, _, shown) = decode_traced(&long_message_with_a_weak_sender_tone(Some(5)));
    assert_eq!(
        got,
        vec![long],
        "a data tone 26 dB above the sender's weak one: {shown:#?}"
    );
    // With no second data at all, the first frame's data ringing on into the second slot
    // is no second frame: never the first data twice, nor a short.
    let (got, _, shown) = decode_traced(&long_message_with_a_weak_sender_tone(None));
    assert!(
        got.is_empty(),
        "the first frame's data ringing on is not a second frame: {got:?} {shown:#?}"
    );
}

#[test]
fn dropout_statistics_match_their_distributions() {
    use super::confirm::{binomial_upper_tail, probability_below};
    let probability_below_noise_mean = |lambda: f64| probability_below(1.0, lambda);
    // No tone: the power is Exp(1), P(r < 1) = 1 − 1/e.
    let p0 = probability_below_noise_mean(0.0);
    assert!((p0 - (1.0 - (-1.0f64).exp())).abs() < 1e-4, "{p0}");
    // A loud tone almost never reads below the noise mean; the probability falls with λ.
    let p = [1.0, 4.0, 9.0, 16.0].map(probability_below_noise_mean);
    assert!(p.windows(2).all(|w| w[1] < w[0]), "{p:?}");
    assert!(p[3] < 1e-4, "{p:?}");
    // Binomial tails: P(X ≥ 0) = 1, P(X ≥ n + 1) = 0, P(X ≥ 2) for Bin(3, 0.5) = 1/2.
    assert_eq!(binomial_upper_tail(12, 0, 0.3), 1.0);
    assert_eq!(binomial_upper_tail(3, 4, 0.3), 0.0);
    assert!((binomial_upper_tail(3, 2, 0.5) - 0.5).abs() < 1e-12);
    // Bin(12, 0.01) ≥ 3: 2.0562e-4.
    let t = binomial_upper_tail(12, 3, 0.01);
    assert!((t / 2.0562e-4 - 1.0).abs() < 0.01, "{t}");
}

/// Digital silence, then a message: the noise floor sat at its quantisation minimum, and
/// the level smoothed up from there over many windows, so the first windows of the
/// message read tens of times louder than the last and a short tone failed the slot's
/// both-halves check (a 250 ms tone after 0.3 s of silence decoded nothing). Every tone
/// duration after any lead-in of silence, and a second message after silence that
/// follows the first, must decode with its start.
#[test]
fn a_message_after_digital_silence_decodes_at_any_tone_duration() {
    for tone_s in [0.1f64, 0.25, 0.5, 1.0] {
        let enc = Encoder::new(EncoderConfig {
            tone_duration_s: tone_s,
            fade_s: (tone_s / 20.0).min(0.01),
            ..EncoderConfig::default()
        })
        .unwrap();
        let config = DecoderConfig {
            tone_duration_s: tone_s,
            ..DecoderConfig::default()
        };
        let first = Message::short(Sender::Goalkeeper, 4).unwrap();
        let second = Message::short(Sender::RightAttacker, 11).unwrap();
        for lead_s in [0.1f64, 0.3, 0.6, 2.0] {
            let mut x = vec![0.0f32; (lead_s * 16_000.0) as usize];
            x.extend(enc.encode_f32(&first));
            let gap = x.len();
            x.extend(vec![0.0f32; 24_000]);
            let second_at = x.len() as f64 / 16_000.0;
            x.extend(enc.encode_f32(&second));
            x.extend(vec![0.0f32; 16_000]);
            let got = decode_all(config.clone(), &x, 512);
            let heard: Vec<Message> = got.iter().map(|d| d.message).collect();
            assert_eq!(
                heard,
                vec![first, second],
                "{tone_s} s tones after {lead_s} s of silence (and 1.5 s of it after {gap} samples)"
            );
            for (d, at) in got.iter().zip([lead_s, second_at]) {
                assert!(
                    (d.start_s - at).abs() < 0.03,
                    "{tone_s} s tones after {lead_s} s of silence: start {} for {at}",
                    d.start_s
                );
            }
        }
    }
}

#[test]
fn a_vote_tone_made_of_two_bursts_is_not_a_message() {
    // The false message of the 10 h backgrounds run (seed 303, `everything` in the T60
    // 1.2 s hall, 550.5 s): three tones held through a slot and a fourth, the one the
    // data basic's vote rested on, sounding only in two short bursts whose slot sum
    // passed for a tone (its median window at the floor, its mean at 9 dB). Each half
    // of the slot holds a burst, and the frame's energy is spread, so only the tone's
    // own windows tell. The same four tones held steadily are a message.
    let frame = Frame {
        sender: Sender::Goalkeeper,
        data: 7,
    };
    let rate = 16_000.0;
    let tones = frame.tones(); // 0, 10, 24, 34, 48, 58
    let (steady, bursty) = ([tones[0], tones[1], tones[2]], tones[3]);
    let tone = |k: usize, n: usize| {
        (2.0 * std::f64::consts::PI * tone_frequency_hz(k) * n as f64 / rate).sin()
    };
    for (bursts, expected) in [(true, 0), (false, 1)] {
        let mut x = vec![0.0f32; 8_000];
        x.extend((0..rate as usize).map(|n| {
            let t = n as f64 / rate;
            let held: f64 = steady.iter().map(|&k| 0.01 * tone(k, n)).sum();
            let in_burst = (0.25..0.38).contains(&t) || (0.62..0.75).contains(&t);
            let fourth = match (bursts, in_burst) {
                (true, true) => 0.025 * tone(bursty, n),
                (true, false) => 0.0,
                (false, _) => 0.01 * tone(bursty, n),
            };
            (held + fourth) as f32
        }));
        x.extend(vec![0.0f32; 16_000]);
        let mut noise = crate::channel::WhiteNoise::new(303, 0.03);
        crate::channel::Source::add_to(&mut noise, &mut x);
        let got = decode_all(DecoderConfig::default(), &x, 1000);
        assert_eq!(
            got.len(),
            expected,
            "fourth tone in bursts: {bursts}; decoded {got:?}"
        );
    }
}

#[test]
fn a_long_message_whose_tones_ring_on_briefly_is_still_a_long_message() {
    // In a hall the second frame's tones ring on after the message (a tone in a notch of
    // the room reverberates louder than it sounded, and babble lands on some data basic),
    // and the end test after the second slot took that for a third frame: the message
    // was lost as "too long" (T60 1.2 s, 0 dB in-band: about one long message in 40).
    // Here the sender's tones and one data basic go on at full level for 0.4 s after a
    // long message and stop: half a slot later the sender is plainly silent, and the
    // message is the long one sent. The same tones going on through the whole next slot
    // (a third frame, which no message has) are not a message.
    let enc = Encoder::new(EncoderConfig::default()).unwrap();
    let msg = Message::long(Sender::RightAttacker, 21 * 4 + 17).unwrap();
    let sent = enc.encode_f32(&msg);
    let rms = (sent
        .iter()
        .map(|&v| f64::from(v) * f64::from(v))
        .sum::<f64>()
        / sent.len() as f64)
        .sqrt();
    let amplitude = rms / 3f64.sqrt(); // six tones of equal amplitude
    let rate = 16_000.0;
    let ringing = Frame {
        sender: Sender::RightAttacker,
        data: 9,
    }
    .tones();
    for (ring_s, expected) in [(0.4, 1), (1.3, 0)] {
        let mut x = vec![0.0f32; 8_000];
        let at = x.len() + sent.len();
        x.extend(&sent);
        x.extend(vec![0.0f32; 40_000]);
        for n in 0..(ring_s * rate) as usize {
            let t = (at + n) as f64 / rate;
            let ring: f64 = ringing
                .iter()
                .map(|&k| (2.0 * std::f64::consts::PI * tone_frequency_hz(k) * t).sin())
                .sum();
            x[at + n] += (amplitude * ring) as f32;
        }
        let mut noise = crate::channel::WhiteNoise::new(33, 0.002);
        crate::channel::Source::add_to(&mut noise, &mut x);
        let got = decode_all(DecoderConfig::default(), &x, 1000);
        let messages: Vec<Message> = got.iter().map(|d| d.message).collect();
        assert_eq!(
            messages.len(),
            expected,
            "tones ring on for {ring_s} s: decoded {messages:?}"
        );
        if expected == 1 {
            assert_eq!(messages[0], msg, "the long message as sent");
        }
    }
}

/// `frame`'s tones 0.5 s after the start for 1 s at `amplitude` each (those in `skip`
/// left out), `error` sharp, then 2 s more, over white noise of `noise` rms and with
/// "harmonic" tones `(k, amplitude, from_s, to_s)`.
fn faint_scene(
    frame: Frame,
    skip: &[usize],
    amplitude: f64,
    error: f64,
    harmonics: &[(usize, f64, f64, f64)],
    noise: (u64, f64),
) -> Vec<f32> {
    let rate = 16_000.0;
    let tone = |k: usize, e: f64, n: usize| {
        (2.0 * std::f64::consts::PI * tone_frequency_hz(k) * (1.0 + e) * n as f64 / rate).sin()
    };
    let mut x: Vec<f32> = (0..(3.5 * rate) as usize)
        .map(|n| {
            let t = n as f64 / rate;
            let message: f64 = if (0.5..1.5).contains(&t) {
                frame
                    .tones()
                    .iter()
                    .filter(|k| !skip.contains(k))
                    .map(|&k| amplitude * tone(k, error, n))
                    .sum()
            } else {
                0.0
            };
            let harmonic: f64 = harmonics
                .iter()
                .filter(|h| (h.2..h.3).contains(&t))
                .map(|&(k, a, _, _)| a * tone(k, 0.0, n))
                .sum();
            (message + harmonic) as f32
        })
        .collect();
    let mut w = crate::channel::WhiteNoise::new(noise.0, noise.1);
    crate::channel::Source::add_to(&mut w, &mut x);
    x
}

#[test]
fn a_message_under_a_talkers_second_data_basic_is_still_found() {
    // Lab T60 0.5 s with four talkers at 0 dB (tuning row 801009): while a message
    // sounded, the talkers' harmonics gave other data basics two tones each ("senders
    // [0] data [4, 5, 9, 19]"), the search's rules wanted exactly one, and the message
    // was never tracked (by the time the harmonics left the search's sums, the message
    // had ended). Here held "harmonic" pairs on data 5's and data 6's tones (8 and 32,
    // 9 and 33) start before the message and stop 0.7 s into it, 1 dB below the
    // message's tones: the sender basic sounds all three tones and data 9 leads the
    // pairs clearly, so the search tracks it, and the slot decides the frame on its own
    // (the pairs do not sound steadily through the slot). Old code: nothing decoded.
    let frame = Frame {
        sender: Sender::Goalkeeper,
        data: 9,
    };
    let pairs: Vec<(usize, f64, f64, f64)> = [8, 32, 9, 33]
        .into_iter()
        .map(|k| (k, 0.009, 0.2, 1.2))
        .collect();
    let x = faint_scene(frame, &[], 0.01, 0.0, &pairs, (801, 0.02));
    let got = decode_all(DecoderConfig::default(), &x, 1000);
    assert_eq!(
        got.iter().map(|d| d.message).collect::<Vec<_>>(),
        vec![Message::short(Sender::Goalkeeper, 9).unwrap()],
        "a message under a second data basic's harmonics"
    );
}

#[test]
fn harmonics_on_two_tones_of_each_basic_do_not_lead_the_search() {
    // What babble assembles: two tones of one sender basic, and pairs on three data
    // basics, one a little louder than the others. None of it sounds like a
    // transmitter (no basic has all three tones), so the search's fallback for a message
    // under harmonics must not take the loudest pair: in a crowd it made false messages
    // (seed 919, crowd in the T60 1.2 s hall: short 2/19 at 2890.4 s). Whatever the
    // slot decision would say, the search does not start on it.
    let frame = Frame {
        sender: Sender::RightAttacker,
        data: 19,
    };
    let mut harmonics = Vec::new();
    for (k, a) in [(10, 0.007), (34, 0.007), (12, 0.006), (36, 0.006)] {
        harmonics.push((k, a, 0.3, 1.6));
    }
    // Sender 2 on tones 2 and 26 only, data 19 (basic 22) on 22 and 46 only.
    let x = faint_scene(frame, &[50, 70], 0.01, 0.0, &harmonics, (919, 0.02));
    let mut d = Decoder::new(DecoderConfig::default()).unwrap();
    d.enable_trace();
    d.push_f32(&x);
    d.finish();
    let trace = d.take_trace();
    assert!(
        !trace.iter().any(|e| e.what.starts_with("search: leader")),
        "the fallback took a frame of two-of-three basics: {:?}",
        trace
            .iter()
            .filter(|e| e.what.contains("leader"))
            .collect::<Vec<_>>()
    );
}

#[test]
fn a_faint_frame_of_four_tones_at_the_combs_edge_is_not_a_message() {
    // Seed 919, `everything` in the T60 1.2 s hall, 1698.93 s: a frame of four tones (2
    // of 3 of each basic) at 4.3 dB, found at the comb's outermost scale (+0.6%) and
    // reading as strongly there as one step in, passed every check and became a false
    // message. Whether such a frame peaks inside the comb or beyond it the noise cannot
    // tell, so it is refused. Here four faint tones 0.65% sharp (12 dB, below the 15 dB
    // of a frame that stands clear): refused (old code: a message). The same four loud at
    // +0.58%, and six faint tones at +0.5%, are messages.
    let frame = Frame {
        sender: Sender::RightAttacker,
        data: 2,
    };
    let decoded = |skip: &[usize], amplitude: f64, error: f64| {
        let x = faint_scene(frame, skip, amplitude, error, &[], (5, 0.02));
        decode_all(DecoderConfig::default(), &x, 1000)
            .iter()
            .map(|d| d.message)
            .collect::<Vec<_>>()
    };
    let message = vec![Message::short(Sender::RightAttacker, 2).unwrap()];
    assert_eq!(
        decoded(&[29, 50], 0.0045, 0.0065),
        vec![],
        "four faint tones at the edge"
    );
    assert_eq!(
        decoded(&[], 0.0045, 0.005),
        message,
        "six faint tones at +0.5%"
    );
    assert_eq!(
        decoded(&[29, 50], 0.03, 0.0058),
        message,
        "four loud tones at the edge"
    );
}

#[test]
fn a_long_messages_second_frame_with_one_tone_pulled_a_hertz_is_still_long() {
    // Lab T60 1.2 s with four talkers at 0 dB (tuning row 801021): a long message's
    // second slot was refused as off grid, one low tone 0.6–1.4 Hz off the common scale
    // (a talker's harmonic beside it) while its other loud tones agreed within 0.3 Hz.
    // Here the second frame's lowest data tone sits 1.1 Hz off: a long message (old
    // code: nothing). Since round 10 one tone 2.2 Hz off is let go too (its basic keeps
    // its vote on the other two, see `a_frame_with_one_tone_pulled_off_by_a_talker_...`);
    // two of its tones off by their own hertz are still refused.
    let first = Frame {
        sender: Sender::LeftAttacker,
        data: 11,
    };
    let second = Frame {
        sender: Sender::LeftAttacker,
        data: 4,
    };
    let play = |offsets: [f64; 6]| -> Vec<Message> {
        let mut x = vec![0.0f32; 8_000];
        x.extend(sines(first, [0.0; 6], 16_000.0));
        x.extend(sines(second, offsets, 16_000.0));
        x.extend(vec![0.0f32; 24_000]);
        let mut noise = crate::channel::WhiteNoise::new(21, 0.002);
        crate::channel::Source::add_to(&mut noise, &mut x);
        decode_all(DecoderConfig::default(), &x, 1000)
            .iter()
            .map(|d| d.message)
            .collect()
    };
    // `sines` moves tone i of `Frame::tones` (lowest first).
    let data_low = second
        .tones()
        .iter()
        .position(|&k| k == 7)
        .expect("data 4's lowest tone is k7");
    let mut one = [0.0; 6];
    one[data_low] = 1.1;
    let long = Message::long(Sender::LeftAttacker, 21 * 11 + 4).unwrap();
    assert_eq!(play(one), vec![long], "one tone 1.1 Hz off");
    let mut far = [0.0; 6];
    far[data_low] = 2.2;
    assert_eq!(play(far), vec![long], "one tone 2.2 Hz off");
    let mut two = [0.0; 6];
    two[data_low] = 1.1;
    two[(data_low + 1) % 6] = -1.1;
    assert!(
        !play(two).contains(&long),
        "two tones off by their own hertz"
    );
}

/// A long message of sender 2, data 14 then 12 (value 306), 0.5 s after the start, over
/// white noise (seed `seed`): the first frame's data tone k17 sounds only for its first
/// 0.4 s (a notch of the room) and k65 not at all, and a talker's harmonics hold data
/// 12's k15 and k63 6 dB below the message's tones through the first frame.
fn long_message_with_a_failing_first_slot(seed: u64) -> Vec<f32> {
    let rate = 16_000.0;
    let a = 0.01;
    let tone = |k: usize, n: usize| {
        (2.0 * std::f64::consts::PI * tone_frequency_hz(k) * n as f64 / rate).sin()
    };
    let mut x: Vec<f32> = (0..(4.5 * rate) as usize)
        .map(|n| {
            let t = n as f64 / rate;
            let mut tones: Vec<(usize, f64)> = Vec::new();
            if (0.5..2.5).contains(&t) {
                tones.extend([(2, a), (26, a), (50, a)]);
            }
            if (0.5..1.5).contains(&t) {
                tones.extend([(41, a), (15, 0.5 * a), (63, 0.5 * a)]);
                if t < 0.9 {
                    tones.push((17, a));
                }
            }
            if (1.5..2.5).contains(&t) {
                tones.extend([(15, a), (39, a), (63, a)]);
            }
            tones.iter().map(|&(k, amp)| amp * tone(k, n)).sum::<f64>() as f32
        })
        .collect();
    let mut w = crate::channel::WhiteNoise::new(seed, 0.02);
    crate::channel::Source::add_to(&mut w, &mut x);
    x
}

#[test]
fn a_slot_inside_its_senders_failed_slot_must_decide_data_that_began_with_it() {
    // Lab T60 2 s, 0 dB (row 959027, 960.76 s, with the search's clear-leader fallback):
    // a long message's first slot (data 14, one tone in a notch) was refused ("a vote
    // misses a half"), and the replay after it found the second frame (data 12) with its
    // onset on the six tones, inside the first frame: the sender's tones had sounded
    // since the first frame's onset. With a talker's harmonics on data 12's tones that
    // slot passed, the next one too, and long 264 (12, 12) came out over the 306 sent.
    // Here the same shape: the first slot fails, and whatever is decoded must be the
    // message sent (in practice nothing: a slot inside the failed one deciding data 12,
    // which began a slot later, is refused, and the second frame at its own onset
    // follows its sender's sounding and is dropped). Old code: long 264.
    let sent = Message::long(Sender::RightAttacker, 21 * 14 + 12).unwrap();
    for seed in [5, 6, 7] {
        let x = long_message_with_a_failing_first_slot(seed);
        let (got, trace, shown) = decode_traced(&x);
        assert!(
            got.iter().all(|&m| m == sent),
            "seed {seed}: decoded {got:?} over {sent}; trace: {shown:?}"
        );
        // The scene does exercise the replay: the first slot fails and a frame is
        // found again inside it.
        assert!(
            trace
                .iter()
                .any(|e| e.what.contains("a vote misses a half")
                    || e.what.starts_with("slot refused")),
            "seed {seed}: the first slot did not fail"
        );
    }
}

/// A short message (left attacker, data 13) through a room that spreads its tones: the
/// data tones k16, k40, k64 loud, the sender's k49 6 dB under them and its k1 and k25
/// 11.5 dB under k49 (notches); from half-way through the slot eight steady single tones
/// of other basics (a crowd, none a basic's 2 of 3) 14 dB under the data tones; white
/// noise (seed `seed`).
fn message_with_its_sender_in_notches_under_a_crowd(seed: u64) -> Vec<f32> {
    let rate = 16_000.0;
    let a = 0.02;
    let tone = |k: usize, n: usize| {
        (2.0 * std::f64::consts::PI * tone_frequency_hz(k) * n as f64 / rate).sin()
    };
    let notch = 0.5 * 10f64.powf(-11.5 / 20.0);
    let mut x: Vec<f32> = (0..(3.0 * rate) as usize)
        .map(|n| {
            let t = n as f64 / rate;
            let mut tones: Vec<(usize, f64)> = Vec::new();
            if (0.5..1.5).contains(&t) {
                tones.extend([(16, a), (40, a), (64, a), (49, 0.5 * a)]);
                tones.extend([(1, notch * a), (25, notch * a)]);
            }
            if (1.0..1.5).contains(&t) {
                for k in [3, 28, 53, 6, 31, 56, 9, 34] {
                    tones.push((k, 0.2 * a));
                }
            }
            tones.iter().map(|&(k, amp)| amp * tone(k, n)).sum::<f64>() as f32
        })
        .collect();
    let mut w = crate::channel::WhiteNoise::new(seed, 0.002);
    crate::channel::Source::add_to(&mut w, &mut x);
    x
}

#[test]
fn a_sender_whose_tones_a_room_spreads_keeps_its_vote_in_a_crowd() {
    // Lab T60 1.2 s, 0 dB (row 801021, 88.88 s; 9 of the row's 38 lost long messages):
    // the data basic loud, the sender's loudest tone the fourth loudest of the slot, and
    // its other two 10–15 dB under it. With more than ten tones present (talkers) the
    // crowd rule kept only tones within 10 dB of the fourth loudest: the sender kept one
    // vote and the slot was "refused by the rules". The tracked sender's tones now count
    // within 15 dB. Old code: nothing decoded.
    let sent = Message::short(Sender::LeftAttacker, 13).unwrap();
    for seed in [1, 2, 3] {
        let x = message_with_its_sender_in_notches_under_a_crowd(seed);
        let (got, _, shown) = decode_traced(&x);
        assert_eq!(got, vec![sent], "seed {seed}: trace: {shown:?}");
    }
}

#[test]
fn a_message_the_search_finds_only_at_its_end_is_still_decided() {
    // Lab T60 0.5 s with four talkers at 0 dB (tuning row 801009): a talker's harmonics
    // give a second data basic two tones at the message's level for most of the message,
    // so the search's rules find the frame only once the harmonics have left its sums,
    // when the newest window is already past the message's end. The decay gate took that
    // for a tail and the message was never tracked. Here a held pair on data 5's tones
    // (8 and 32) at the message's level from before it to 0.8 s into it: no basic leads
    // clearly while the pair is in the sums, and by the time it is not, the message has
    // ended. Its whole slot has been heard, so it is tracked from its onset and decided
    // there (the pair does not sound through the slot). Old code: nothing decoded.
    let frame = Frame {
        sender: Sender::LeftAttacker,
        data: 9,
    };
    let pair: Vec<(usize, f64, f64, f64)> =
        [8, 32].into_iter().map(|k| (k, 0.01, 0.2, 1.3)).collect();
    for seed in [1, 2, 3] {
        let x = faint_scene(frame, &[], 0.01, 0.0, &pair, (seed, 0.02));
        let (got, trace, shown) = decode_traced(&x);
        assert_eq!(
            got,
            vec![Message::short(Sender::LeftAttacker, 9).unwrap()],
            "seed {seed}: a message found only at its end; trace: {shown:?}, search: {:?}",
            trace
                .iter()
                .filter(|e| e.what.starts_with("search") && e.at_s > 0.4)
                .map(|e| format!("{:.2} {}", e.at_s, e.what))
                .collect::<Vec<_>>()
        );
    }
}

#[test]
fn a_frame_with_one_tone_pulled_off_by_a_talker_is_still_a_message() {
    // Hall T60 1.2 s with four talkers at 0 dB (tuning row 11024): 34 of 44 lost long
    // messages were refused as off grid, nearly all on k1 (549 Hz, in the talkers'
    // loudest band) pulled 1.5-2.7 Hz off, or past the comb, by a harmonic beside it
    // while the other loud tones agreed within 0.25 Hz. Here sender 1's k1 sits 2.5 Hz
    // off (0.46% at 549 Hz) and the rest on the grid: a message (old code: nothing).
    // The same tone off while its basic's vote rests on it (k25 silent) is refused: the
    // frame is then not two basics each voting on tones that agree, and a frame mixed
    // from two robots' tones would pass.
    let frame = Frame {
        sender: Sender::LeftAttacker,
        data: 7,
    };
    let tones = frame.tones();
    let play = |offsets: [f64; 6], silent: Option<usize>| -> Vec<Message> {
        let rate = 16_000.0;
        let mut x = vec![0.0f32; 8_000];
        x.extend((0..16_000).map(|n| {
            let t = n as f64 / rate;
            tones
                .iter()
                .zip(offsets)
                .filter(|(&k, _)| Some(k) != silent)
                .map(|(&k, d)| (2.0 * std::f64::consts::PI * (tone_frequency_hz(k) + d) * t).sin())
                .sum::<f64>() as f32
                * 0.05
        }));
        x.extend(vec![0.0f32; 16_000]);
        let mut noise = crate::channel::WhiteNoise::new(33, 0.002);
        crate::channel::Source::add_to(&mut noise, &mut x);
        decode_all(DecoderConfig::default(), &x, 1000)
            .iter()
            .map(|d| d.message)
            .collect()
    };
    let short = Message::short(Sender::LeftAttacker, 7).unwrap();
    let k1 = tones
        .iter()
        .position(|&k| k == 1)
        .expect("sender 1's lowest tone is k1");
    let mut pulled = [0.0; 6];
    pulled[k1] = 2.5;
    assert_eq!(play([0.0; 6], None), vec![short], "on the grid");
    assert_eq!(
        play(pulled, None),
        vec![short],
        "k1 2.5 Hz off, the rest on the grid"
    );
    assert!(
        play(pulled, Some(25)).is_empty(),
        "k1 2.5 Hz off with k25 silent: sender 1's vote rests on the tone off the grid"
    );
    let mut two = pulled;
    two[(k1 + 3) % 6] = -2.5;
    assert!(
        play(two, None).is_empty(),
        "two tones off by their own hertz"
    );
}

/// A frame of `tones` (frequency index, amplitude envelope over the slot's seconds) after
/// half a second of quiet and before a second, over white noise of `sigma` (seed `seed`).
fn shaped_frame(tones: &[(usize, &dyn Fn(f64) -> f64)], sigma: f64, seed: u64) -> Vec<f32> {
    let rate = 16_000.0;
    let mut x = vec![0.0f32; 8_000];
    x.extend((0..16_000).map(|n| {
        let t = n as f64 / rate;
        tones
            .iter()
            .map(|(k, amp)| amp(t) * (2.0 * std::f64::consts::PI * tone_frequency_hz(*k) * t).sin())
            .sum::<f64>() as f32
    }));
    x.extend(vec![0.0f32; 16_000]);
    let mut noise = crate::channel::WhiteNoise::new(seed, sigma);
    crate::channel::Source::add_to(&mut noise, &mut x);
    x
}

#[test]
fn a_note_with_tremolo_on_the_data_tones_is_not_a_message() {
    // Everything dry, backgrounds seed 13050 (10 h run of seed 13): two false messages,
    // e.g. at 1153.8 s, whose loud tones pulsed: the data tone read 374, 39, 235, 232,
    // 75, 379, 25, 497, 28 … in successive windows. Far above the noise, it never fell
    // to the noise mean, so no window counted as a dropout. Here the data's tones pulse
    // at 2.6 Hz, 15 dB down between their beats (old code: a message); held steadily,
    // the same frame is a message.
    let frame = Frame {
        sender: Sender::Goalkeeper,
        data: 7,
    };
    let tones = frame.tones(); // 0, 10, 24, 34, 48, 58
    let steady = |_: f64| 0.01;
    let pulsed = |t: f64| {
        if ((t / 0.192) as usize).is_multiple_of(2) {
            0.02
        } else {
            0.0036
        }
    };
    for (tremolo, expected) in [(false, 1), (true, 0)] {
        let data: &dyn Fn(f64) -> f64 = if tremolo { &pulsed } else { &steady };
        let shaped: Vec<(usize, &dyn Fn(f64) -> f64)> = tones
            .iter()
            .map(|&k| {
                let amp: &dyn Fn(f64) -> f64 = if frame.sender.index() as usize == k % 24 {
                    &steady
                } else {
                    data
                };
                (k, amp)
            })
            .collect();
        let x = shaped_frame(&shaped, 0.002, 13050);
        let (got, _, shown) = decode_traced(&x);
        assert_eq!(
            got.len(),
            expected,
            "data tones pulsed: {tremolo}; decoded {got:?}\n{}",
            shown.join("\n")
        );
    }
}

#[test]
fn a_frame_ringing_under_the_hall_level_is_not_refused_by_a_rival_of_babble() {
    // Hall T60 1.2 s with four talkers at 0 dB (tuning row 11018): 23 of 55 lost short
    // messages were refused by a rival basic that a talker's harmonics gave two tones for
    // part of the slot. Their typical tone (10–14 dB) was under the 15 dB at which a
    // rival must sound like a transmitter to count, though each basic had a tone far
    // above that (the room puts the others in notches). Here sender 0 and data 7 each
    // have one loud tone, one at about 12 dB and one weak; sender 1's k1 and k25 sound
    // for a fifth of the slot (old code: nothing). The same rival held through the slot
    // is a second transmitter: nothing.
    let frame = Frame {
        sender: Sender::Goalkeeper,
        data: 7,
    };
    let [k0, k10, k24, k34, k48, k58] = frame.tones();
    let loud = |_: f64| 0.02;
    let middle = |_: f64| 0.0035;
    let weak = |_: f64| 0.002;
    let burst = |t: f64| if (0.3..0.5).contains(&t) { 0.009 } else { 0.0 };
    let held = |_: f64| 0.0045;
    for (rival_held, expected) in [(false, 1), (true, 0)] {
        let rival: &dyn Fn(f64) -> f64 = if rival_held { &held } else { &burst };
        let x = shaped_frame(
            &[
                (k0, &loud),
                (k24, &middle),
                (k48, &weak),
                (k10, &loud),
                (k34, &middle),
                (k58, &weak),
                (1, rival),
                (25, rival),
            ],
            0.01,
            11018,
        );
        let (got, _, shown) = decode_traced(&x);
        assert_eq!(
            got.len(),
            expected,
            "rival held: {rival_held}; decoded {got:?}\n{}",
            shown.join("\n")
        );
    }
}
