//! The acoustic fallback (issue part 4): when every WLAN link is down, robots sound their
//! should-I-go claims as Cerberus tones, each in its own slot, and decide on what their
//! own microphone's decoder hears. Definitions in `huddle::sim::acoustic`.
//!
//! - The channel alone: a teammate 5 m away decodes a claim with its content and one
//!   flight time (5/343 s) late; two robots sounding together collide (whatever the
//!   decoder makes of the mix, it is not both messages); distance lowers the SNR.
//! - The slot: four robots taking turns with the default slot (400 ms tone, 300 ms
//!   guard) are decoded in halls of T60 0.6, 1 and 2 s (critical distance 8 m). The
//!   earlier 100 ms tone + 80 ms guard was decoded about 1% of the time there (15% in the
//!   simulated match), which is what left two or more goers for most of an outage.
//! - The team: a 30 s outage from 60 s, seeds 1–3 (the defaults were chosen on seeds
//!   101–112), in the default reverberant room (T60 1 s, critical distance 8 m) and in a
//!   dry hall: the target, ≥ 90% of ball-visible outage time with exactly one
//!   goer, holds in both, and the fallback still hands the ball over (it is not a goer
//!   frozen at the outage's start).

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

/// The channel's 1/r, probed on what the microphones pick up (the decoder's tone SNR no
/// longer follows the level: its noise floor is held within 13 dB of the band's tone
/// power, #33). Listeners 1.5 m and 9 m from the sender, each with its own crowd at 40 dB
/// under the sender's level at 1 m, in a dry room: the message's in-band power over each
/// microphone's crowd is its received SNR, 15.6 dB lower at 9 m by 1/r, and both decode it.
#[test]
fn distance_lowers_the_snr() {
    use audio::channel::in_band_power;
    let m = claim(0.7, false);
    let positions = [(0.0, 0.0), (1.5, 0.0), (9.0, 0.0)];
    let room = AcousticConfig {
        crowd_snr_db_at_1m: 40.0,
        ..dry_room()
    };
    let fs = 16_000.0;
    let mut ch = AcousticChannel::new(&room, positions.len(), 7).expect("a valid room");
    // The crowd alone for 1.5 s, then the message and its flight, heard in one block.
    let mut heard = ch.advance_to(1.5);
    let crowd: Vec<Vec<f32>> = (0..3).map(|j| ch.microphone(j).to_vec()).collect();
    ch.sound(0, &m, &positions);
    let sounding = room.tone_s * m.frames().len() as f64;
    heard.extend(ch.advance_to(1.5 + sounding + 9.0 / SPEED_OF_SOUND_MPS));
    let received_snr_db = |j: usize| {
        let flight = (positions[j].0 / SPEED_OF_SOUND_MPS * fs) as usize;
        let mic = &ch.microphone(j)[flight..];
        let band = |x: &[f32]| in_band_power(x, fs, 500.0, 4000.0);
        // The crowd's own level from its last second (its first is the babble settling).
        let noise = band(&crowd[j][crowd[j].len() - 16_000..]);
        10.0 * ((band(mic) - noise) / noise).log10()
    };
    let (near, far) = (received_snr_db(1), received_snr_db(2));
    let by_distance = 20.0 * (9.0f64 / 1.5).log10();
    assert!(
        (near - far - by_distance).abs() < 3.0,
        "1/r from 1.5 m to 9 m is {by_distance:.1} dB less direct sound; received SNR \
         {near:.1} dB vs {far:.1} dB"
    );
    // Not asserted: the level itself. Measured 42.0 dB at 1.5 m where the configured
    // 40 dB at 1 m gives 36.5 dB, because the crowd is calibrated on its whole-band
    // power, and the synthetic babble has about 5 dB of its power outside 500–4000 Hz.
    // That is a calibration note for the channel (#33), not the 1/r this test probes.
    ch.advance_to(4.0).into_iter().for_each(|h| heard.push(h));
    for j in [1, 2] {
        assert!(
            heard
                .iter()
                .any(|h| h.listener == j && h.detection.message == m),
            "listener {j} decoded the claim: {heard:?}"
        );
    }
}

/// Four robots at typical spots of a 9 × 6 m field take turns in their slots (robot 0,
/// the goalkeeper, only listens) for `cycles` cycles, each sounding a random claim: the
/// share of receptions decoded right.
fn turns(room: &AcousticConfig, cycles: usize) -> (f64, AcousticChannel) {
    use rand::{RngExt, SeedableRng};
    let positions = [
        (-4.0, 0.0),
        (-2.0, 1.5),
        (0.0, -1.5),
        (2.0, 2.0),
        (3.0, -2.0),
    ];
    let mut ch = AcousticChannel::new(room, positions.len(), 7).expect("a valid room");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut t = 1.5;
    ch.advance_to(t);
    for _ in 0..cycles {
        for k in 1..positions.len() {
            let m = claim(rng.random_range(0.0..6.0), rng.random_bool(0.3));
            ch.sound(k, &m, &positions);
            let end = t + room.slot_s();
            while t < end - 1e-9 {
                t += 0.01;
                ch.advance_to(t);
            }
        }
    }
    ch.advance_to(t + 2.0);
    let s = ch.stats;
    (s.decoded as f64 / s.receptions as f64, ch)
}

#[test]
fn the_default_slot_is_heard_in_reverberant_halls() {
    let mut rows = Vec::new();
    let mut worst: f64 = 1.0;
    for t60_s in [0.6, 1.0, 2.0] {
        let room = AcousticConfig {
            enabled: true,
            t60_s,
            ..AcousticConfig::default()
        };
        let (share, ch) = turns(&room, 8);
        rows.push(format!(
            "T60 {t60_s} s: {:.1}% of {} receptions decoded, {} wrong",
            100.0 * share,
            ch.stats.receptions,
            ch.stats.wrong
        ));
        assert_eq!(ch.stats.wrong, 0, "T60 {t60_s} s: no wrong claims");
        worst = worst.min(share);
    }
    eprintln!("{}", rows.join("\n"));
    assert!(
        worst >= 0.85,
        "400 ms tones with 300 ms guards are decoded in every hall (≥ 85%; 92–97% measured)\n{}",
        rows.join("\n")
    );
}

/// 95 s of play with every link down from 60 s to 90 s, in `room` (fallback on or off).
fn outage(seed: u64, room: Option<AcousticConfig>) -> Report {
    let cfg = SimConfig {
        duration_s: 95.0,
        seed,
        snapshot_every_s: 0.0,
        outage: Some(OutageConfig {
            start_s: 60.0,
            duration_s: 30.0,
        }),
        acoustic: room.unwrap_or_default(),
        ..SimConfig::default()
    };
    let mut sim = Simulation::new(cfg).expect("a valid configuration");
    sim.run(|_| {});
    sim.report(0.0)
}

#[test]
fn a_30_s_outage_keeps_one_goer_with_the_acoustic_fallback_in_a_hall_and_a_dry_room() {
    let hall = AcousticConfig {
        enabled: true,
        ..AcousticConfig::default()
    };
    let mut rows = Vec::new();
    let mut handovers = 0;
    for seed in 1..=3 {
        let off = outage(seed, None).outage.expect("an outage report");
        assert_eq!(
            off.acoustic_sounded, 0,
            "seed {seed}: without the fallback nobody sounds"
        );
        for (name, room) in [("hall", hall), ("dry", dry_room())] {
            let on = outage(seed, Some(room)).outage.expect("an outage report");
            rows.push(format!(
                "seed {seed} {name}: without {:.1}% (conflict {:.1}%), with {:.1}% (conflict {:.1}%, none {:.1}%; {} handovers, goer near the ball {:.1}% of the time; {}/{} decoded, {} wrong)",
                off.windows.outage_exactly_one_goer_pct,
                off.windows.outage_conflict_pct,
                on.windows.outage_exactly_one_goer_pct,
                on.windows.outage_conflict_pct,
                on.windows.outage_no_goer_pct,
                on.windows.outage_handovers,
                on.windows.outage_near_goer_pct,
                on.acoustic_decoded,
                on.acoustic_receptions,
                on.acoustic_wrong,
            ));
            let table = rows.join("\n");
            assert!(
                on.windows.outage_ball_visible_s > 5.0,
                "seed {seed} {name}: the ball was seen in the outage"
            );
            assert!(
                on.acoustic_sounded >= 30,
                "seed {seed} {name}: robots sounded their claims during the outage (a 2.8 s cycle of four slots: ~40 in 30 s)"
            );
            assert!(
                on.windows.outage_exactly_one_goer_pct >= 90.0,
                "seed {seed} {name}: exactly one goer {:.1}% < 90% with the fallback\n{table}",
                on.windows.outage_exactly_one_goer_pct,
            );
            assert!(
                on.windows.outage_exactly_one_goer_pct
                    >= 2.0 * off.windows.outage_exactly_one_goer_pct,
                "seed {seed} {name}: the fallback at least doubles it\n{table}"
            );
            assert!(
                on.acoustic_decoded * 10 >= on.acoustic_receptions * 8,
                "seed {seed} {name}: ≥ 80% of receptions decode\n{table}"
            );
            assert!(
                on.windows.outage_near_goer_pct >= 60.0,
                "seed {seed} {name}: the lone goer is mostly one near the ball, not whoever went when the radio failed\n{table}"
            );
            handovers += on.windows.outage_handovers;
        }
    }
    eprintln!("{}", rows.join("\n"));
    assert!(
        handovers >= 3,
        "the fallback hands the ball over during outages ({handovers} handovers in 6 outages)\n{}",
        rows.join("\n")
    );
}

/// 95 s in the drawn world (every robot's clock its own), under `budget`, every link down
/// from 60 s to 90 s, the fallback on in the default hall.
fn drawn_outage(
    seed: u64,
    budget: Option<comms::BudgetSpec>,
) -> (huddle::sim::acoustic::OutageReport, f64) {
    let cfg = SimConfig {
        duration_s: 95.0,
        seed,
        snapshot_every_s: 0.0,
        drawn_world: true,
        budget,
        outage: Some(OutageConfig {
            start_s: 60.0,
            duration_s: 30.0,
        }),
        acoustic: AcousticConfig {
            enabled: true,
            ..AcousticConfig::default()
        },
        ..SimConfig::default()
    };
    let mut sim = Simulation::new(cfg).expect("a valid configuration");
    // Ball-visible samples of the outage once every robot's fallback is in control, and
    // those with exactly one goer.
    let mut controlled = (0u32, 0u32);
    while !sim.finished() {
        sim.step();
        let in_control = sim
            .robots
            .iter()
            .all(|r| r.sound.as_ref().is_some_and(|s| s.in_control()));
        let visible = sim
            .robots
            .iter()
            .any(|r| r.is_field_player() && r.sees_ball());
        if (60.0..90.0).contains(&sim.time_s()) && in_control && visible {
            let goers = sim
                .robots
                .iter()
                .filter(|r| r.is_field_player() && r.going())
                .count();
            controlled.0 += 1;
            controlled.1 += u32::from(goers == 1);
        }
    }
    let pct = 100.0 * f64::from(controlled.1) / f64::from(controlled.0.max(1));
    (sim.report(0.0).outage.expect("an outage report"), pct)
}

/// One seed's line of the team-clock tables.
fn clock_row(seed: u64, on: &huddle::sim::acoustic::OutageReport) -> String {
    format!(
        "seed {seed}: one goer {:.2}% (two+ {:.2}%, none {:.2}%), team clocks within {:.3} ms (mean {:.3} ms), {} collided",
        on.windows.outage_exactly_one_goer_pct,
        on.windows.outage_conflict_pct,
        on.windows.outage_no_goer_pct,
        on.acoustic_team_clock_spread_max_ms,
        on.acoustic_team_clock_spread_mean_ms,
        on.acoustic_collided,
    )
}

/// The drawn world gives every robot a clock of its own: up to 20 s apart, tens of ppm of
/// drift. The slots run on the team clock each robot's replica estimates
/// (`team::acoustic::TeamClock`), as on a daemon; on the robots' own clocks (before the
/// team clock) the slot a claim was heard in named the wrong robot and the team kept
/// exactly one goer 16–96% of the outage (seeds 1–8, 55% on average), none most of the
/// rest. Seeds 1–3, nothing tuned on them.
#[test]
fn robots_whose_clocks_are_seconds_apart_take_turns_on_the_team_clock() {
    let mut rows = Vec::new();
    for seed in 1..=3 {
        let (on, _) = drawn_outage(seed, None);
        rows.push(clock_row(seed, &on));
        let table = rows.join("\n");
        assert!(
            on.acoustic_team_clock_spread_max_ms > 0.0 && on.acoustic_team_clock_spread_max_ms < 30.0,
            "seed {seed}: the robots' team clocks agree to the echo estimate's error, far inside the 300 ms guard (6.4 ms measured on seeds 1–8)\n{table}"
        );
        assert!(
            on.windows.outage_exactly_one_goer_pct >= 90.0,
            "seed {seed}: exactly one goer ≥ 90% of the outage with clocks seconds apart\n{table}"
        );
    }
    eprintln!("{}", rows.join("\n"));
}

/// Under the SPL's budget (1,200 messages a game) frames are seconds apart and echoes,
/// which need a teammate's frame within 655 ms of one of ours, rarer still: in a 95 s
/// match each robot had an echo estimate of one or two teammates, read a different
/// reference, and the team clocks were seconds apart (here seed 4: 9.2 s, 230 collisions,
/// one goer 53% of the outage; `huddle sim --budget spl`, seeds 1–12: 0.45–15.8 s). The
/// team clock now also reads a teammate's clock from its send stamps, and keeps a
/// reference the replica still counts present.
///
/// With no GameController (this lab run) nothing tells a dead radio from a quiet one
/// under the budget: the fallback takes control only when the claims go stale (15 s), and
/// until then the team runs on the last claims each robot heard, which differ at 20%
/// loss. That part moves with any change to the match (seeds 1–12: 70–100% over the whole
/// outage before and after the heartbeat, which changed nothing here but the match's
/// first second), so one goer is asserted from the moment every robot is in control; in
/// a game the GameController's packets hand over within 3 s (`acoustic_fallback_game`).
/// Seeds 4, 6, 8 (check seeds: the causes were traced on 1, 4 and 6).
#[test]
fn under_the_spl_budget_the_team_clocks_still_agree_and_one_robot_goes() {
    let mut rows = Vec::new();
    for seed in [4, 6, 8] {
        let (on, controlled) = drawn_outage(seed, Some(comms::BudgetSpec::SPL));
        rows.push(format!(
            "{}, one goer {controlled:.2}% once all in control",
            clock_row(seed, &on)
        ));
        let table = rows.join("\n");
        assert!(
            on.acoustic_team_clock_spread_max_ms < 100.0,
            "seed {seed}: the team clocks agree within a transit or two, far inside the 300 ms guard (22–34 ms measured)\n{table}"
        );
        assert!(
            controlled >= 90.0,
            "seed {seed}: exactly one goer ≥ 90% of the outage once the fallback decides, under the budget\n{table}"
        );
    }
    eprintln!("{}", rows.join("\n"));
}
