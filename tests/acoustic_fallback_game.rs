//! The acoustic fallback in a game under the simulated GameController and the SPL's
//! budget, as a real team runs it (`huddle sim --game … --acoustic --budget spl`).
//!
//! Under the budget a claim holds 15 s and out of play nobody tells one, so a claim's age
//! does not say whether the radio works. Before this, robots took old claims for a silent
//! radio: in a 10-minute half with the radio working they sounded 852 claims (Ready and
//! Set included, over the referee's whistle) and decided on them, and the team had one
//! goer 96.0% of play against 99.2% without the fallback (seed 1). The GameController's
//! packets (2 Hz, on the same WLAN) are now the radio's heartbeat
//! (`team::acoustic::GC_SILENT_S`):
//!
//! - with the radio working the fallback never decides and never sounds, so the team
//!   plays exactly as without it;
//! - when the WLAN fails in play (the GC's packets with it), every robot takes control
//!   within a few seconds (it was 15 s: the claims' staleness), sounds only while the
//!   radio is out, and the team keeps one goer.
//!
//! A short game (one 90 s half, Ready/Set restarts after goals, robot 3 penalised for
//! 15 s), seeds 1–3, nothing tuned on them.

use huddle::sim::acoustic::{AcousticConfig, OutageConfig, GC_SILENT_S};
use huddle::sim::referee::{GameScript, GcDelays, ScriptedPenalty, WhistleHearing};
use huddle::sim::{Report, SimConfig, Simulation};

/// The longest a robot keeps deciding by sound after the radio is back: a claim's
/// staleness under the SPL's budget (15 s), plus the GC's next packet and a tick.
const HAND_BACK_S: f64 = 16.0;

fn short_game() -> GameScript {
    GameScript {
        halves: 1,
        half_s: 90.0,
        break_s: 0.0,
        initial_s: 3.0,
        standby_s: 3.0,
        ready_s: 10.0,
        set_s: 3.0,
        finished_s: 2.0,
        penalty_s: 15.0,
        // The league's rate: one message a second of play.
        messages_per_game: 90,
        penalties: vec![ScriptedPenalty {
            robot: 3,
            half: 1,
            after_play_s: 50.0,
        }],
        delays: GcDelays::none(),
        whistle: WhistleHearing::deaf(),
    }
}

/// What a game showed, sampled every 10 ms step.
#[derive(Default)]
struct Seen {
    /// When each sound was made (simulation time, s).
    sounds_at: Vec<f64>,
    /// When each robot (index) first took control in the outage, s.
    control_from: Vec<Option<f64>>,
    /// Whether any robot was in control outside the outage.
    control_outside: bool,
    /// Samples in play in the 20 s after the outage, and those with exactly one goer.
    after: (u32, u32),
    /// Samples in play in the outage once every robot is in control, and those with
    /// exactly one goer.
    controlled: (u32, u32),
    /// Play time after the outage until every robot held a claim told since from every
    /// teammate, s.
    told_again_at: Option<f64>,
    /// Play time since the outage's end, s.
    play_since_s: f64,
    /// Whether the referee said Playing when the outage ended (a goal in the outage ends
    /// it in Ready: the restart, not the fallback, hands back to the radio).
    ended_in_play: bool,
}

fn play(seed: u64, fallback: bool, outage: Option<OutageConfig>) -> (Report, Seen) {
    let script = short_game();
    let cfg = SimConfig {
        duration_s: script.length_s() + 600.0,
        seed,
        budget: Some(comms::BudgetSpec::SPL),
        game: Some(script),
        outage,
        acoustic: AcousticConfig {
            enabled: fallback,
            ..AcousticConfig::default()
        },
        ..SimConfig::default()
    };
    let mut sim = Simulation::new(cfg).expect("a valid configuration");
    let mut seen = Seen {
        control_from: vec![None; sim.robots.len()],
        ..Seen::default()
    };
    let mut sounded = 0;
    while !sim.finished() {
        sim.step();
        let t_s = sim.time_s();
        let now = sim.acoustic_stats().map_or(0, |s| s.sounded);
        seen.sounds_at.extend((sounded..now).map(|_| t_s));
        sounded = now;
        // The radio comes back with the GC's next packet (0.5 s); each robot hands back
        // when it holds a claim told since from every teammate, at most a claim's
        // staleness (15 s under the budget) later.
        let inside = outage
            .is_some_and(|o| (o.start_s..o.start_s + o.duration_s + HAND_BACK_S).contains(&t_s));
        let after = outage.is_some_and(|o| {
            let end_s = o.start_s + o.duration_s;
            (end_s..end_s + 20.0).contains(&t_s)
        });
        let playing = sim.referee().is_some_and(|r| r.playing());
        if outage.is_some_and(|o| (t_s - (o.start_s + o.duration_s)).abs() < 0.005) {
            seen.ended_in_play = playing;
        }
        if let Some(o) = outage.filter(|_| seen.told_again_at.is_none()) {
            // Play time since the outage (out of play nobody tells a claim).
            if t_s >= o.start_s + o.duration_s && playing {
                seen.play_since_s += 0.01;
            }
            let since_s = t_s - (o.start_s + o.duration_s);
            let told_again = since_s >= 0.0
                && (0..sim.robots.len()).all(|i| {
                    let Some(replica) = sim.harness.replica(i) else {
                        return false;
                    };
                    let now = sim.harness.local_now(i);
                    let heard = comms::arbitration::heard(replica.blackboard(), now);
                    sim.robots.iter().all(|mate| {
                        mate.id == sim.robots[i].id
                            || heard
                                .iter()
                                .any(|c| c.robot == mate.id && c.age.as_secs_f64() <= since_s)
                    })
                });
            if told_again {
                seen.told_again_at = Some(seen.play_since_s);
            }
        }
        let goers = sim
            .robots
            .iter()
            .filter(|r| r.is_field_player() && r.going())
            .count();
        let all_in_control = seen.control_from.iter().all(Option::is_some);
        if playing && all_in_control && outage.is_some_and(|o| o.contains(t_s)) {
            seen.controlled.0 += 1;
            seen.controlled.1 += u32::from(goers == 1);
        }
        if after && playing {
            seen.after.0 += 1;
            seen.after.1 += u32::from(goers == 1);
        }
        for (i, r) in sim.robots.iter().enumerate() {
            if r.sound.as_ref().is_some_and(|s| s.in_control()) {
                if inside {
                    seen.control_from[i].get_or_insert(t_s);
                } else {
                    seen.control_outside = true;
                }
            }
        }
    }
    (sim.report(0.0), seen)
}

#[test]
fn with_the_radio_working_the_fallback_stays_silent_and_the_team_plays_as_without_it() {
    for seed in 1..=3 {
        let (with, seen) = play(seed, true, None);
        let (without, _) = play(seed, false, None);
        assert!(
            seen.sounds_at.is_empty(),
            "seed {seed}: {} claims sounded with the radio working, the first at {:?} s",
            seen.sounds_at.len(),
            seen.sounds_at.first()
        );
        assert!(
            !seen.control_outside,
            "seed {seed}: the fallback decided with the radio working"
        );
        assert_eq!(
            with.exactly_one_goer_pct, without.exactly_one_goer_pct,
            "seed {seed}: the team plays as without the fallback"
        );
    }
}

#[test]
fn when_the_wlan_fails_in_play_the_gamecontroller_s_silence_hands_over_within_seconds() {
    // Play starts at 19 s; the WLAN (the GC's packets with it) is down 30–60 s.
    let outage = OutageConfig {
        start_s: 30.0,
        duration_s: 30.0,
    };
    for seed in 1..=3 {
        let (report, seen) = play(seed, true, Some(outage));
        let end_s = outage.start_s + outage.duration_s;
        for (i, from) in seen.control_from.iter().enumerate() {
            // The last packet came at most 0.5 s before the outage, one lost before it
            // at most another 0.5 s: control by GC_SILENT_S + 1 s (a tick's slack).
            let by = outage.start_s + GC_SILENT_S + 1.0;
            assert!(
                from.is_some_and(|t| t <= by),
                "seed {seed}: robot {} in control at {from:?} s, not by {by} s (a claim's \
                 staleness under the budget is 15 s)",
                i + 1
            );
        }
        assert!(
            !seen.control_outside,
            "seed {seed}: the fallback decided outside the outage"
        );
        let slot_s = AcousticConfig::default().slot_s();
        let stray: Vec<f64> = seen
            .sounds_at
            .iter()
            .copied()
            .filter(|&t| t < outage.start_s || t > end_s + HAND_BACK_S + slot_s)
            .collect();
        assert!(
            stray.is_empty(),
            "seed {seed}: sounded outside the outage at {stray:?}"
        );
        assert!(
            seen.sounds_at.len() >= 8,
            "seed {seed}: the robots sounded their claims in the outage ({} sounds)",
            seen.sounds_at.len()
        );
        // Until the fallback takes control (3-3.5 s) the team runs on what the radio
        // left it, under the budget sometimes a conflict (seed 1: robots 2 and 3 both
        // going from 5 s before the outage); from then on the fallback's own share.
        let whole = report.outage.expect("an outage report");
        let whole = whole.windows.outage_exactly_one_goer_pct;
        let (n, one) = seen.controlled;
        let pct = 100.0 * f64::from(one) / f64::from(n.max(1));
        assert!(
            n > 0 && pct >= 90.0,
            "seed {seed}: one goer {pct:.1}% of the outage's play once every robot is in \
             control ({n} samples; {whole:.1}% of the whole outage), under 90%"
        );
    }
}

#[test]
fn after_an_outage_the_team_tells_its_claims_at_once_with_or_without_the_fallback() {
    // Frames sent into a dead radio are counted by the budget: before the heartbeat the
    // team spent 106 frames in a 30 s outage and was paced into silence for a minute
    // after it, every robot going on teammates' claims gone stale (0-50% one goer in the
    // 30 s after, seeds 5 and 6 of `huddle sim --game restarts`). It now holds them while
    // the radio is dead and tells what changed when the GameController is heard again.
    let outage = OutageConfig {
        start_s: 30.0,
        duration_s: 30.0,
    };
    let mut handed_back = 0;
    for seed in 1..=3 {
        for fallback in [false, true] {
            let (_, seen) = play(seed, fallback, Some(outage));
            let after_s = seen.told_again_at;
            // Play time (out of play nobody tells a claim): at 20% loss every one of the
            // 20 robot-to-teammate links needs one of the budget's sparse frames (6-48 s
            // here). Without the hold seed 1 never did (0 of 2,000 samples after the
            // outage with one goer).
            assert!(
                after_s.is_some_and(|s| s <= 50.0),
                "seed {seed}, fallback {fallback}: every robot held every teammate's new \
                 claim {after_s:?} s of play after the outage, not within 50 s"
            );
            let (n, one) = seen.after;
            let pct = 100.0 * f64::from(one) / f64::from(n.max(1));
            // With the fallback the team decides by sound until every teammate's new
            // claim has come (99.8-100% here; it was 75% on seed 1 handing back at once),
            // when the radio comes back in play (after a goal in the outage the restart
            // tells every claim again).
            // Without it, robots whose teammates' new claims are lost go alone meanwhile
            // (55-99.5% here): the budget's staleness rule, not the outage.
            if fallback && seen.ended_in_play {
                handed_back += 1;
                assert!(
                    n > 0 && pct >= 90.0,
                    "seed {seed}: one goer {pct:.1}% of the play in the 20 s after the \
                     outage ({n} samples)"
                );
            }
        }
    }
    assert!(
        handed_back > 0,
        "some seed's outage ends in play, so that the hand-back is checked"
    );
}
