//! The daemon's tick on what its GameController listener wrote (`local.var.gc.state`, the
//! accepted counter) and a whistle the robot program heard: the team layer's reading of
//! the whistle (`TeamLayer::heard_whistle`) against the GC's last word.

use super::core_tests::{floats, robot_2_at_the_origin};
use super::{GC_ACCEPTED_KEY, GC_STATE_KEY};
use comms::{Instant, Replica, Value};
use std::time::Duration;
use team::{contract, Whistle};

/// The play whistle the tick published for the listener's pacing clock.
fn play_whistle(replica: &Replica) -> Option<Value> {
    published(replica, contract::PLAY_WHISTLE_KEY)
}

/// What the tick published at `key`.
fn published(replica: &Replica, key: &str) -> Option<Value> {
    replica
        .get(key)
        .expect("a valid key")
        .map(|e| e.value.clone())
}

#[test]
fn with_the_gamecontroller_silent_in_ready_the_program_s_whistle_starts_play() {
    // Scenario: robot 2's listener holds the GC's last word, Ready, and its accepted
    // counter moves every second until 3 s, when the WLAN dies. The program writes a
    // whistle at 2 s (another field's: the GC heard, nothing) and the kick-off's at 8 s
    // (the GC silent for 5 s: play started). The tick hands the layer the GC's Ready
    // and publishes the play whistle for the listener.
    let mut now = Instant::from_micros(1_000_000);
    let (mut core, mut replica) = robot_2_at_the_origin(now);
    replica
        .set(now, GC_STATE_KEY, Value::String("ready".into()))
        .expect("a local key");
    let mut packets = 0;
    let mut meant = Vec::new();
    while now <= Instant::from_micros(9_000_000) {
        let us = now.as_micros();
        if us <= 3_000_000 && us.is_multiple_of(500_000) {
            packets += 1;
            replica
                .set(now, GC_ACCEPTED_KEY, Value::Int(packets))
                .expect("a local key");
        }
        if us == 2_000_000 || us == 8_000_000 {
            core.input(contract::WHISTLE_KEY, &Value::Bool(true), now)
                .expect("a valid whistle");
        }
        core.input(contract::ODOMETRY_KEY, &floats(&[0.0, 0.0, 0.0]), now)
            .expect("valid odometry");
        core.tick(&mut replica, now);
        if us == 2_000_000 || us == 8_000_000 {
            meant.push(core.shared.layer.whistle());
        }
        now += Duration::from_millis(40);
    }
    assert_eq!(
        meant,
        [None, Some(Whistle::PlayStarted(8.0))],
        "at 2 s (the GC heard) nothing; at 8 s (silent since 3 s) the kick-off"
    );
    assert_eq!(
        play_whistle(&replica),
        Some(floats(&[8.0])),
        "the play whistle published"
    );
}

#[test]
fn the_tick_publishes_the_goal_s_whistle_and_the_kick_off_s_after_it_for_the_program() {
    // Scenario: robot 2's listener shows Playing (GameController3 shows it 15 s past a
    // goal) and its accepted counter moves every 0.5 s until 105 s, when the WLAN dies.
    // The program writes the goal's whistle at 100 s (the GC heard: a goal) and the
    // kick-off's at 120 s, 20 s later (the GC silent for 15 s: play started, by
    // `GOAL_TO_KICK_OFF_MIN_S..MAX_S`). A program reads the layer's reading from
    // `local.var.team.goal_whistle` and `local.var.team.play_whistle`, as `huddle sim
    // --daemons --game`'s programs do: its body walks to its kick-off spot, then plays.
    let mut now = Instant::from_micros(99_000_000);
    let (mut core, mut replica) = robot_2_at_the_origin(now);
    replica
        .set(now, GC_STATE_KEY, Value::String("playing".into()))
        .expect("a local key");
    let mut packets = 0;
    let mut shown = Vec::new();
    while now <= Instant::from_micros(121_000_000) {
        let us = now.as_micros();
        if us <= 105_000_000 && us.is_multiple_of(500_000) {
            packets += 1;
            replica
                .set(now, GC_ACCEPTED_KEY, Value::Int(packets))
                .expect("a local key");
        }
        let whistled = us == 100_000_000 || us == 120_000_000;
        if whistled {
            core.input(contract::WHISTLE_KEY, &Value::Bool(true), now)
                .expect("a valid whistle");
        }
        core.input(contract::ODOMETRY_KEY, &floats(&[0.0, 0.0, 0.0]), now)
            .expect("valid odometry");
        core.tick(&mut replica, now);
        if whistled {
            shown.push((
                published(&replica, contract::GOAL_WHISTLE_KEY),
                play_whistle(&replica),
            ));
        }
        now += Duration::from_millis(40);
    }
    assert_eq!(
        shown,
        [
            (Some(floats(&[100.0])), None),
            (Some(floats(&[])), Some(floats(&[120.0]))),
        ],
        "at 100 s the goal's whistle, no play whistle yet; at 120 s the goal's withdrawn \
         ([]) and the kick-off's published"
    );
    assert_eq!(
        core.shared.layer.whistle(),
        Some(Whistle::PlayStarted(120.0)),
        "the layer acts on the kick-off's whistle"
    );
}
