//! The whistle a robot program hears ([`TeamLayer::heard_whistle`]) against
//! GameController3's delayed word: a scenario each.

use comms::Blackboard;
use comms::Instant;
use std::time::Duration;

use super::{
    paced_game_remaining, Whistle, GOAL_TO_KICK_OFF_MIN_S, KICK_OFF_HOLD_S, WHISTLE_TRUST_S,
};
use crate::layer::{Senses, TeamConfig, TeamLayer};
use crate::Pose;

/// Robot 2 of 5 at the origin; its cost is `h` (about metres to the ball).
fn robot(h: f64) -> (TeamLayer, TeamConfig) {
    let (mut r, _cal, cfg) = crate::layer::tests::robot_2_of_5(Pose::default());
    r.h = h;
    (r, cfg)
}

fn at(s: f64) -> Instant {
    Instant::from_micros((s * 1e6).round() as u64)
}

/// What the daemon's tick does with the GC's word: `state` as the listener keeps it.
fn gc_says(r: &mut TeamLayer, state: &str) -> bool {
    r.set_gc_ready(state == "ready");
    r.set_in_play(state == "playing");
    r.set_kick_off_next(state == "set")
}

/// The daemon's ticks every 0.5 s from `from_s` to `to_s` on the GC's last word `state`,
/// the GC heard (a packet each tick) until `gc_until_s`: the heartbeat, the GC's word,
/// the layer's sense and decide, the robot's cost 0.5 (the ball 0.5 m away, no
/// teammate's claim heard). Returns whether a kick-off began at one of them.
fn ticks(
    r: &mut TeamLayer,
    cfg: &TeamConfig,
    state: &str,
    (from_s, to_s): (f64, f64),
    gc_until_s: f64,
) -> bool {
    let board = Blackboard::new(2);
    let senses = Senses {
        cost: Some(0.5),
        ..Senses::default()
    };
    let mut began = false;
    let mut t = from_s;
    while t <= to_s + 1e-9 {
        if t <= gc_until_s + 1e-9 {
            r.heard_gamecontroller(t);
        }
        began |= gc_says(r, state);
        r.sense(cfg, at(t), &senses, &board, false);
        r.decide(&board, at(t));
        t += 0.5;
    }
    began
}

#[test]
fn a_whistle_in_set_starts_play_and_the_kick_off_hold_while_the_gc_still_says_set() {
    // Scenario: a kick-off under GameController3. Robot 2 stands 2 m from the ball, the
    // GC says Set; the referee whistles at 20 s and the GC says Set until 35 s. The
    // program hears the whistle at 20.5 s: the layer is in play then, robot 2 holds back
    // for the hold's 3 s and goes after it, at 23.6 s, with the GC still saying Set. The
    // GC's Set after the whistle begins no second kick-off; its Playing changes nothing.
    let (mut r, _) = robot(2.0);
    let board = Blackboard::new(2);
    assert!(gc_says(&mut r, "set"), "Set: a kick-off begins");
    r.decide(&board, at(15.0));
    assert!(!r.going(), "in Set robot 2 leaves the ball to the taker");
    assert_eq!(
        r.heard_whistle(20.5),
        Some(Whistle::PlayStarted(20.5)),
        "a whistle in Set: play started"
    );
    assert!(r.in_play, "in play at the whistle");
    for s in [20.6, 20.5 + KICK_OFF_HOLD_S - 0.1] {
        assert!(
            !gc_says(&mut r, "set"),
            "{s} s: the GC's late Set begins nothing"
        );
        r.decide(&board, at(s));
        assert!(r.in_play && !r.going(), "{s} s: in play, in the hold");
    }
    assert!(!gc_says(&mut r, "set"));
    r.decide(&board, at(20.5 + KICK_OFF_HOLD_S + 0.1));
    assert!(
        r.going(),
        "after the hold robot 2 goes, 11 s before the GC says Playing"
    );
    assert!(!gc_says(&mut r, "playing"));
    assert!(r.in_play && r.whistle().is_none(), "the GC caught up");
}

#[test]
fn a_whistle_in_play_is_a_goal_the_ball_is_forgotten_and_play_left_until_ready() {
    // Scenario: robot 2 in play; a goal at 100 s, the program hears the whistle at
    // 100.4 s; GameController3 says Playing (the old score) until 115 s, then Ready with
    // the new score. From the whistle the layer is out of play (it tells nothing, goes
    // for no ball) and its team ball is the kick-off spot; at Ready the whistle is done.
    let (mut r, cfg) = robot(0.5);
    let board = Blackboard::new(2);
    gc_says(&mut r, "playing");
    r.set_scores(0, 0, 90.0);
    r.decide(&board, at(99.0));
    assert!(r.going(), "before the goal it plays the ball");
    assert_eq!(r.heard_whistle(100.4), Some(Whistle::Goal(100.4)));
    assert!(!r.in_play, "a goal: out of play at the whistle");
    let spot = r.team_ball_held.expect("the ball put back").estimate;
    assert!(
        spot.position().norm() < 1e-6,
        "the ball forgotten, put on the centre spot: {:?}",
        spot.position()
    );
    for s in [101.0, 114.9] {
        gc_says(&mut r, "playing");
        r.sense(&cfg, at(s), &Senses::default(), &board, false);
        assert!(
            !r.in_play,
            "{s} s: the GC's late Playing does not put it back in play"
        );
    }
    assert_eq!(
        r.heard_whistle(105.0),
        None,
        "a second whistle before the GC caught up means nothing more"
    );
    r.set_scores(1, 0, 115.0);
    gc_says(&mut r, "ready");
    assert!(
        r.whistle().is_none() && !r.in_play,
        "Ready: the GC caught up"
    );
}

#[test]
fn a_whistle_the_gc_never_follows_stands_twenty_seconds_at_most() {
    // Scenario: a whistle from the next field while in play at 50 s: GameController3 says
    // Playing on. The layer takes it for a goal, then after WHISTLE_TRUST_S (15 s of
    // GC3's delay and 5 s of margin) goes by the GC's Playing again. In Ready (or
    // Standby, Initial, Finished) a whistle changes nothing in the layer.
    let (mut r, cfg) = robot(0.5);
    let board = Blackboard::new(2);
    gc_says(&mut r, "playing");
    assert_eq!(r.heard_whistle(50.0), Some(Whistle::Goal(50.0)));
    gc_says(&mut r, "playing");
    r.sense(
        &cfg,
        at(50.0 + WHISTLE_TRUST_S - 0.1),
        &Senses::default(),
        &board,
        false,
    );
    assert!(!r.in_play, "within the trust: out of play");
    gc_says(&mut r, "playing");
    r.sense(
        &cfg,
        at(50.0 + WHISTLE_TRUST_S + 0.1),
        &Senses::default(),
        &board,
        false,
    );
    assert!(
        r.in_play && r.whistle().is_none(),
        "the GC never followed: in play again"
    );
    // A play whistle in Set that the GC never follows: Set again, a kick-off begins anew.
    assert!(gc_says(&mut r, "set"));
    assert!(r.heard_whistle(200.0).is_some());
    gc_says(&mut r, "set");
    r.sense(
        &cfg,
        at(200.0 + WHISTLE_TRUST_S + 0.1),
        &Senses::default(),
        &board,
        false,
    );
    assert!(!r.in_play, "the GC still says Set: out of play");
    assert!(gc_says(&mut r, "set"), "… and a kick-off begins again");
    // Ready: nothing.
    gc_says(&mut r, "ready");
    assert_eq!(
        r.heard_whistle(300.0),
        None,
        "a whistle in Ready means nothing here"
    );
    assert!(!r.in_play);
}

#[test]
fn the_pacing_clock_runs_from_a_play_whistle_while_the_gc_s_delayed_set_stands() {
    // Scenario: a kick-off under GameController3 with 300 s of the game left. The
    // referee whistles at 20 s; the program hears it at 20.5 s; the GC's packets say Set
    // with its figure standing at 300 s until 35 s, then Playing with the true figure.
    // The clock the budget paces by runs from the whistle (296 s at 24.5 s, 286 s at
    // 34.5 s), not the GC's standing 300 s; once the GC says Playing its figure rules.
    let (mut r, _) = robot(2.0);
    let standing = Duration::from_secs(300);
    assert!(gc_says(&mut r, "set"), "Set: a kick-off begins");
    assert_eq!(
        paced_game_remaining(r.play_whistle_at(), standing, true, 15.0),
        standing,
        "in Set before the whistle the GC's standing figure is the clock"
    );
    assert_eq!(r.heard_whistle(20.5), Some(Whistle::PlayStarted(20.5)));
    for (s, left) in [(24.5, 296.0), (34.5, 286.0)] {
        gc_says(&mut r, "set");
        let paced = paced_game_remaining(r.play_whistle_at(), standing, true, s).as_secs_f64();
        assert!(
            (paced - left).abs() < 1e-6,
            "{s} s: the GC's late Set stands at 300 s, the pacing clock runs from the \
             whistle: {paced} s left, expected {left}"
        );
    }
    // The GC caught up: Playing, its own (true) figure.
    let true_left = Duration::from_secs_f64(285.4);
    gc_says(&mut r, "playing");
    assert_eq!(
        paced_game_remaining(r.play_whistle_at(), true_left, false, 35.1),
        true_left,
        "the GC says Playing: its figure rules again"
    );
}

#[test]
fn a_goal_whistle_keeps_the_gc_s_figure_for_the_pacing_clock() {
    // Scenario: the GC says Playing; a goal's whistle at 100 s. The GC's clock runs on
    // (its delayed copy) and the pacing clock follows it: the rule moves only play's
    // whistle (see `paced_game_remaining`).
    let (mut r, _) = robot(2.0);
    gc_says(&mut r, "playing");
    assert_eq!(r.heard_whistle(100.0), Some(Whistle::Goal(100.0)));
    let gc = Duration::from_secs(200);
    assert_eq!(
        paced_game_remaining(r.play_whistle_at(), gc, false, 105.0),
        gc,
        "a goal's whistle: the GC's figure"
    );
}

#[test]
fn a_kick_off_whistle_stands_while_the_gamecontroller_is_silent() {
    // Scenario: GameController3 says Set until 15 s after the kick-off's whistle; the
    // program hears it at 190 s, and the WLAN dies at 200 s with the GC's last word Set.
    // The whistle stands through the silence (the GC says nothing, not Set), and is
    // dropped once the GC is heard saying Set past the trust.
    let (mut r, cfg) = robot(0.5);
    let board = Blackboard::new(2);
    let mut t = 180.0;
    while t <= 200.0 {
        r.heard_gamecontroller(t);
        gc_says(&mut r, "set");
        if (t - 190.0).abs() < 1e-9 {
            assert_eq!(r.heard_whistle(190.0), Some(Whistle::PlayStarted(190.0)));
        }
        t += 0.5;
    }
    for t in [211.0, 225.0] {
        r.sense(&cfg, at(t), &Senses::default(), &board, false);
        assert!(
            r.in_play,
            "the GC silent since 200 s: still in play at {t} s"
        );
    }
    r.heard_gamecontroller(226.0);
    gc_says(&mut r, "set");
    r.sense(&cfg, at(226.0), &Senses::default(), &board, false);
    assert!(
        !r.in_play,
        "the GC heard saying Set past the trust: out of play"
    );
}

#[test]
fn with_the_radio_dead_a_whistle_in_ready_is_the_kick_off() {
    // Scenario: a goal's Ready; the GC's packets say Ready until the WLAN dies at 200 s.
    // The robots walk to their places, the referee ends Ready at 210 s (Set, which no
    // robot hears) and whistles the kick-off at 215 s; the program hears it at 215.4 s.
    // Under the rules only the kick-off's whistle follows Ready: the layer is in play
    // and robot 2 (0.5 m from the ball, no teammate heard) goes, in no kick-off hold
    // (it heard no Set to begin one), and stays in play on the GC's last word (Ready)
    // through the outage.
    let (mut r, cfg) = robot(0.5);
    ticks(&mut r, &cfg, "ready", (180.0, 215.0), 200.0);
    assert!(!r.in_play, "Ready: out of play");
    assert!(r.radio_dead(215.4));
    assert_eq!(
        r.heard_whistle(215.4),
        Some(Whistle::PlayStarted(215.4)),
        "the GC silent since 200 s, its last word Ready: the kick-off"
    );
    assert!(r.in_play);
    ticks(&mut r, &cfg, "ready", (215.5, 215.5), 200.0);
    assert_eq!(
        r.kick_off_placement(),
        Some(super::KickOffPlacement::PlayHeard),
        "the tick hears play"
    );
    assert!(
        r.going() && r.kick_off_hold_until_s.is_none(),
        "robot 2 goes, no kick-off hold"
    );
    ticks(&mut r, &cfg, "ready", (216.0, 229.5), 200.0);
    assert!(
        r.in_play && r.going(),
        "the GC's last Ready does not take it out of play again"
    );
}

#[test]
fn a_whistle_in_ready_means_nothing_while_the_gc_is_heard_and_the_kick_off_once_it_is_silent() {
    // Scenario: Ready, the GC heard every 0.5 s until 130 s. A whistle from the next
    // field at 120 s means nothing: the GC would have said Set before a kick-off. The
    // WLAN dies at 130 s; the kick-off's whistle at 140 s is play.
    let (mut r, cfg) = robot(0.5);
    ticks(&mut r, &cfg, "ready", (100.0, 120.0), 130.0);
    assert_eq!(r.heard_whistle(120.0), None, "the GC heard: nothing");
    ticks(&mut r, &cfg, "ready", (120.5, 140.0), 130.0);
    assert!(!r.in_play, "out of play through the start of the outage");
    assert_eq!(
        r.heard_whistle(140.0),
        Some(Whistle::PlayStarted(140.0)),
        "the GC silent: the kick-off"
    );
    assert!(r.in_play);
}

#[test]
fn with_the_radio_dead_a_whistle_in_initial_standby_or_finished_means_nothing() {
    // Scenario: the GC heard until 100 s saying Initial, Standby or Finished, then
    // silent; a whistle at 110 s. In Standby it is the half's Ready (the program's walk),
    // in Finished or Initial nobody's kick-off: the layer stays out of play. Only Ready
    // is followed by the kick-off's whistle.
    for state in ["initial", "standby", "finished", "ready"] {
        let (mut r, cfg) = robot(0.5);
        ticks(&mut r, &cfg, state, (90.0, 110.0), 100.0);
        let meant = r.heard_whistle(110.0);
        ticks(&mut r, &cfg, state, (110.5, 112.0), 100.0);
        if state == "ready" {
            assert_eq!(meant, Some(Whistle::PlayStarted(110.0)), "{state}");
            assert!(r.in_play, "{state}: in play");
        } else {
            assert_eq!(meant, None, "{state}: nothing");
            assert!(!r.in_play, "{state}: out of play");
        }
    }
}

#[test]
fn with_the_radio_dead_the_whistle_after_a_goal_s_is_the_kick_off() {
    // Scenario: in play, the GC heard saying Playing until the WLAN dies at 100 s. A goal
    // at 105 s: the program hears its whistle (a goal), and the referee's second blow
    // 2 s later means nothing. Ready and Set take 35 s (the goal's whistle expires at
    // 125 s into the GC's last Playing); the kick-off's whistle at 140 s is play, not
    // another goal: the ball is not forgotten again. The next whistle, at 170 s, is a
    // goal. A robot that hears the kick-off 15 s after the goal (its whistle still
    // pending) is in play too; with the GC heard, such a whistle means nothing.
    let (mut r, cfg) = robot(0.5);
    ticks(&mut r, &cfg, "playing", (90.0, 105.0), 100.0);
    assert_eq!(r.heard_whistle(105.0), Some(Whistle::Goal(105.0)));
    assert_eq!(r.heard_whistle(107.0), None, "the second blow: nothing");
    ticks(&mut r, &cfg, "playing", (105.5, 139.5), 100.0);
    assert_eq!(
        r.heard_whistle(140.0),
        Some(Whistle::PlayStarted(140.0)),
        "35 s after the goal's whistle: the kick-off"
    );
    ticks(&mut r, &cfg, "playing", (140.0, 169.5), 100.0);
    assert!(r.in_play && r.going(), "in play after the kick-off");
    assert_eq!(
        r.heard_whistle(170.0),
        Some(Whistle::Goal(170.0)),
        "the next whistle: a goal"
    );

    let kick_off_s = 105.0 + GOAL_TO_KICK_OFF_MIN_S + 5.0;
    let (mut pending, cfg) = robot(0.5);
    ticks(&mut pending, &cfg, "playing", (90.0, 105.0), 100.0);
    assert_eq!(pending.heard_whistle(105.0), Some(Whistle::Goal(105.0)));
    ticks(&mut pending, &cfg, "playing", (105.5, kick_off_s), 100.0);
    assert!(!pending.in_play, "the goal's whistle pending: out of play");
    assert_eq!(
        pending.heard_whistle(kick_off_s),
        Some(Whistle::PlayStarted(kick_off_s)),
        "the goal's whistle pending, the radio dead: the kick-off"
    );
    ticks(
        &mut pending,
        &cfg,
        "playing",
        (kick_off_s + 0.5, 125.0),
        100.0,
    );
    assert!(pending.in_play && pending.going());

    let (mut heard, cfg) = robot(0.5);
    ticks(&mut heard, &cfg, "playing", (90.0, 105.0), 130.0);
    assert_eq!(heard.heard_whistle(105.0), Some(Whistle::Goal(105.0)));
    ticks(&mut heard, &cfg, "playing", (105.5, kick_off_s), 130.0);
    assert_eq!(
        heard.heard_whistle(kick_off_s),
        None,
        "the GC heard: nothing while the goal's whistle is pending, as before"
    );
    assert!(!heard.in_play);

    // The bounds: a robot that missed the kick-off's whistle takes one 70 s after the
    // goal's for the next goal; so does one whose GC said Playing past the goal whistle's
    // trust (the goal was not given) before the WLAN died at 130 s.
    for (gc_until_s, next_s) in [(100.0, 175.0), (130.0, 140.0)] {
        let (mut r, cfg) = robot(0.5);
        ticks(&mut r, &cfg, "playing", (90.0, 105.0), gc_until_s);
        assert_eq!(r.heard_whistle(105.0), Some(Whistle::Goal(105.0)));
        ticks(&mut r, &cfg, "playing", (105.5, next_s), gc_until_s);
        assert_eq!(
            r.heard_whistle(next_s),
            Some(Whistle::Goal(next_s)),
            "the GC heard until {gc_until_s} s, a whistle at {next_s} s: a goal"
        );
    }
}

#[test]
fn the_gc_heard_again_corrects_a_kick_off_taken_from_a_dead_radio() {
    // Scenario: the WLAN dies at 200 s in Ready; the program hears the kick-off's
    // whistle at 215 s and the layer is in play. (a) The WLAN is back at 229.5 s:
    // GameController3 says Set until 230 s (15 s after the whistle): its delayed word
    // of the kick-off that started, which begins no kick-off and no hold; then Playing,
    // and the GC has caught up. (b) The GC comes back at 222 s still saying Ready: the
    // whistle was not the kick-off, and the layer leaves play. (c) A goal in the outage
    // (the WLAN dead from 100 s, the GC's last word Playing): the kick-off's whistle at
    // 140 s, and at 150 s the GC is back with its delayed Set (until 155 s): no kick-off
    // begins, the layer stays in play through it and the GC's Playing.
    let (mut r, cfg) = robot(0.5);
    ticks(&mut r, &cfg, "ready", (190.0, 214.5), 200.0);
    assert_eq!(r.heard_whistle(215.0), Some(Whistle::PlayStarted(215.0)));
    ticks(&mut r, &cfg, "ready", (215.0, 229.0), 200.0);
    assert!(
        !ticks(&mut r, &cfg, "set", (229.5, 230.0), 230.0),
        "the GC's late Set begins no kick-off"
    );
    assert!(
        r.in_play && r.going() && r.kick_off_hold_until_s.is_none(),
        "in play, no hold"
    );
    ticks(&mut r, &cfg, "playing", (230.5, 231.0), 231.0);
    assert!(r.in_play && r.going() && r.whistle().is_none(), "caught up");

    let (mut r, cfg) = robot(0.5);
    ticks(&mut r, &cfg, "ready", (190.0, 214.5), 200.0);
    assert_eq!(r.heard_whistle(215.0), Some(Whistle::PlayStarted(215.0)));
    ticks(&mut r, &cfg, "ready", (215.0, 221.5), 200.0);
    assert!(r.in_play);
    ticks(&mut r, &cfg, "ready", (222.0, 222.0), 222.0);
    assert!(
        !r.in_play && r.whistle().is_none(),
        "the GC heard saying Ready: out of play"
    );

    let (mut r, cfg) = robot(0.5);
    ticks(&mut r, &cfg, "playing", (90.0, 105.0), 100.0);
    assert_eq!(r.heard_whistle(105.0), Some(Whistle::Goal(105.0)));
    ticks(&mut r, &cfg, "playing", (105.5, 139.5), 100.0);
    assert_eq!(r.heard_whistle(140.0), Some(Whistle::PlayStarted(140.0)));
    ticks(&mut r, &cfg, "playing", (140.0, 149.5), 100.0);
    assert!(
        !ticks(&mut r, &cfg, "set", (150.0, 155.0), 155.0),
        "the GC's late Set begins no kick-off"
    );
    assert!(
        r.in_play && r.going() && r.kick_off_hold_until_s.is_none(),
        "in play through the GC's late Set, no hold"
    );
    ticks(&mut r, &cfg, "playing", (155.5, 156.0), 156.0);
    assert!(r.in_play && r.whistle().is_none(), "caught up");
}
