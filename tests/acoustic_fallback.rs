//! The acoustic fallback (issue part 4): when every WLAN link is down, robots sound their
//! should-I-go claims as Cerberus tones, each in its own slot, and decide on what their
//! own microphone's decoder hears. Definitions in `huddle::sim::acoustic`.
//!
//! - The channel alone: a teammate 5 m away decodes a claim with its content and one
//!   flight time (5/343 s) late; two robots sounding together collide (whatever the
//!   decoder makes of the mix, it is not both messages); distance lowers the SNR.
//! - The team: a 30 s outage from 60 s, seeds 1–3 (the defaults were chosen on seeds
//!   101–105), in the dry room: the fallback at least doubles the share of ball-visible
//!   outage time with exactly one goer and keeps it ≥ 70%. The target (≥ 90%) is
//!   NOT met yet: 77–92% on seeds 101–105, and with a realistic reverberant field
//!   (critical distance 8 m, T60 1 s) the decoder loses most claims beyond ~4 m.

use comms::arbitration::Posted;
use huddle::sim::acoustic::{
    decode_claim, encode_claim, AcousticChannel, AcousticConfig, Heard, OutageConfig,
    SPEED_OF_SOUND_MPS,
};
use huddle::sim::{Report, SimConfig, Simulation};

fn claim(h: f64, going: bool) -> audio::Message {
    encode_claim(Posted { h, going }, 1000.0)
}

/// The default crowd (25 dB in-band SNR at 1 m) in a dry room: the reverberant field is
/// negligible (critical distance 1 km), so what is checked is flight, 1/r and the crowd.
fn dry_room() -> AcousticConfig {
    AcousticConfig {
        enabled: true,
        critical_distance_m: 1000.0,
        ..AcousticConfig::default()
    }
}

/// Sound `messages` (robot index, message) at 1.5 s and listen until 3 s. The decoders
/// hear the room's background for 1.5 s first: the decoder's noise floor (a trimmed mean
/// that follows speech) needs more than half a second of it before it trusts a tone.
fn sound_once(
    room: &AcousticConfig,
    positions: &[(f64, f64)],
    messages: &[(usize, audio::Message)],
) -> (Vec<Heard>, AcousticChannel) {
    let mut ch = AcousticChannel::new(room, positions.len(), 7).expect("a valid room");
    let mut heard = ch.advance_to(1.5);
    for (from, m) in messages {
        ch.sound(*from, m, positions);
    }
    let mut t = 1.5;
    while t < 3.0 {
        t += 0.01;
        heard.extend(ch.advance_to(t));
    }
    (heard, ch)
}

#[test]
fn a_teammate_5_m_away_decodes_the_claim_one_flight_time_late() {
    let m = claim(2.3, true);
    // Listeners at 5 m and at 34.3 m (a flight of 100 ms, long enough to see in the
    // decoder's start times whatever their resolution).
    let positions = [(0.0, 0.0), (5.0, 0.0), (0.0, 34.3)];
    // A quiet dry room: the 34.3 m listener must hear it too.
    let quiet = AcousticConfig {
        crowd_snr_db_at_1m: 60.0,
        ..dry_room()
    };
    let (heard, ch) = sound_once(&quiet, &positions, &[(0, m)]);
    let at = |j: usize| {
        heard
            .iter()
            .find(|h| h.listener == j)
            .unwrap_or_else(|| panic!("listener {j} decoded nothing: {heard:?}"))
            .detection
    };
    let near = at(1);
    assert_eq!(near.message, m, "the content survives 5 m");
    let back = decode_claim(&near.message, 1000.0).unwrap();
    assert!(back.going && (back.h - 2.3).abs() <= 0.15, "claim {back:?}");
    let flight = 5.0 / SPEED_OF_SOUND_MPS;
    assert!(
        (near.start_s - (1.5 + flight)).abs() < 0.02,
        "heard from {:.4} s, sounded at 1.5 s + {flight:.4} s flight",
        near.start_s
    );
    let far = at(2);
    let delta = far.start_s - near.start_s;
    let expect = (34.3 - 5.0) / SPEED_OF_SOUND_MPS;
    assert!(
        (delta - expect).abs() < 0.02,
        "34.3 m listener {delta:.4} s later than the 5 m one, expected {expect:.4} s"
    );
    assert_eq!(ch.stats.sounded, 1);
    assert_eq!(ch.stats.collided, 0);
    assert_eq!(
        ch.stats.decoded, 2,
        "both listeners decoded it: {:?}",
        ch.stats
    );
}

#[test]
fn two_robots_sounding_in_the_same_slot_collide() {
    let a = claim(1.0, true);
    let b = claim(4.0, false);
    // Robots 0 and 1 are 3 m from listener 2, on either side: equal levels at its
    // microphone, arriving together.
    let positions = [(-3.0, 0.0), (3.0, 0.0), (0.0, 0.0)];
    let (heard, ch) = sound_once(&dry_room(), &positions, &[(0, a), (1, b)]);
    let at2: Vec<_> = heard.iter().filter(|h| h.listener == 2).collect();
    assert!(
        !(at2.iter().any(|h| h.detection.message == a)
            && at2.iter().any(|h| h.detection.message == b)),
        "listener 2 decoded both colliding messages: {at2:?}"
    );
    assert!(
        at2.is_empty() || at2.len() == 1,
        "the mix is one transmission at most: {at2:?}"
    );
    assert!(
        ch.stats.collided >= 2,
        "the overlap is counted: {:?}",
        ch.stats
    );
    // Alone, the same message at the same spot is decoded: the collision did it.
    let (alone, _) = sound_once(&dry_room(), &positions, &[(0, a)]);
    assert!(
        alone
            .iter()
            .any(|h| h.listener == 2 && h.detection.message == a),
        "alone, listener 2 decodes robot 0: {alone:?}"
    );
}

#[test]
fn distance_lowers_the_snr() {
    let m = claim(0.7, false);
    let positions = [(0.0, 0.0), (1.5, 0.0), (9.0, 0.0)];
    // A quieter crowd (40 dB at 1 m) so that both decode and their SNRs can be compared.
    let room = AcousticConfig {
        crowd_snr_db_at_1m: 40.0,
        ..dry_room()
    };
    let (heard, _) = sound_once(&room, &positions, &[(0, m)]);
    let snr = |j: usize| {
        heard
            .iter()
            .find(|h| h.listener == j)
            .map(|h| h.detection.tone_snr_db)
            .unwrap_or_else(|| panic!("listener {j} decoded nothing: {heard:?}"))
    };
    let (near, far) = (snr(1), snr(2));
    assert!(
        near - far > 6.0,
        "1/r from 1.5 m to 9 m is 15.6 dB less direct sound; measured {near:.1} dB vs {far:.1} dB"
    );
}

/// 95 s of play with every link down from 60 s to 90 s.
fn outage(seed: u64, acoustic: bool) -> Report {
    let room = dry_room();
    let cfg = SimConfig {
        duration_s: 95.0,
        seed,
        snapshot_every_s: 0.0,
        outage: Some(OutageConfig {
            start_s: 60.0,
            duration_s: 30.0,
        }),
        acoustic: AcousticConfig {
            enabled: acoustic,
            ..room
        },
        ..SimConfig::default()
    };
    let mut sim = Simulation::new(cfg).expect("a valid configuration");
    sim.run(|_| {});
    sim.report(0.0)
}

#[test]
fn a_30_s_outage_keeps_one_goer_far_more_often_with_the_acoustic_fallback() {
    let mut rows = Vec::new();
    for seed in 1..=3 {
        let off = outage(seed, false).outage.expect("an outage report");
        let on = outage(seed, true).outage.expect("an outage report");
        rows.push(format!(
            "seed {seed}: without {:.1}% (conflict {:.1}%, none {:.1}%), with {:.1}% (conflict {:.1}%, none {:.1}%; {} sounded, {}/{} decoded, {} collided)",
            off.outage_exactly_one_goer_pct,
            off.outage_conflict_pct,
            off.outage_no_goer_pct,
            on.outage_exactly_one_goer_pct,
            on.outage_conflict_pct,
            on.outage_no_goer_pct,
            on.acoustic_sounded,
            on.acoustic_decoded,
            on.acoustic_receptions,
            on.acoustic_collided
        ));
        assert!(
            on.outage_ball_visible_s > 5.0,
            "seed {seed}: the ball was seen in the outage"
        );
        assert!(
            on.acoustic_sounded > 50,
            "seed {seed}: robots sounded their claims during the outage"
        );
        assert!(
            on.outage_exactly_one_goer_pct >= 70.0,
            "seed {seed}: exactly one goer {:.1}% < 70% with the fallback\n{}",
            on.outage_exactly_one_goer_pct,
            rows.join("\n")
        );
        assert!(
            on.outage_exactly_one_goer_pct >= 2.0 * off.outage_exactly_one_goer_pct,
            "seed {seed}: the fallback at least doubles it\n{}",
            rows.join("\n")
        );
        assert!(
            on.acoustic_decoded * 2 > on.acoustic_receptions,
            "seed {seed}: most receptions decode in the dry room\n{}",
            rows.join("\n")
        );
        assert_eq!(
            off.acoustic_sounded, 0,
            "without the fallback nobody sounds"
        );
    }
    eprintln!("{}", rows.join("\n"));
}
