//! `huddle sim --daemons --game`: three robot programs play a short half (60 s of play,
//! seed 5, the ideal world) with each team layer in a real `huddle daemon --budget spl`
//! whose GameController listener hears the simulated referee's RGme packets over UDP on
//! loopback. Robot 3 is penalised 10 s into the half, for 20 s.
//!
//! The referee counts the frames the daemons actually put on the group, as the GC does:
//! the team is never illegal; its count (counted in Standby/Ready/Set/Playing, plus the
//! frames heard in the other states) is what the daemons say they sent (`frames_out`,
//! read through each relay's `local.var.huddle.stats.*`), but for the few frames in
//! flight when the counters were read at the end (at most one per robot: the game is in
//! Finished then and the layers send little); the game has at least its first kick-off,
//! and the robots stood near their kick-off spots at it (they walked there in Ready on
//! the state their daemon's `local.var.gc.state` said); after the penalty's first 2 s no
//! teammate's layer names robot 3 the goer; and every robot's RGrt status reached the
//! referee's return port with no gap of 2 s or more (the GC shows a robot connected if
//! heard within 2 s). The links lose nothing here (`loss=0`): a frame lost by a daemon's
//! impairment never reaches a GC, so under loss the GC's count is below `frames_out` by
//! design.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

use huddle::sim::daemons::{self, DaemonsOptions};
use huddle::sim::referee::{GameScript, GcDelays, ScriptedPenalty, WhistleHearing};
use huddle::sim::SimConfig;

#[test]
fn three_daemons_play_a_short_half_under_a_gamecontroller_on_loopback() {
    let seed = 5;
    let script = GameScript {
        halves: 1,
        half_s: 60.0,
        break_s: 0.0,
        initial_s: 3.0,
        standby_s: 3.0,
        ready_s: 10.0,
        set_s: 3.0,
        finished_s: 3.0,
        penalty_s: 20.0,
        messages_per_game: 1200,
        penalties: vec![ScriptedPenalty {
            robot: 3,
            half: 1,
            after_play_s: 10.0,
        }],
        // GameController3's late packets, as on a real field; the daemons' robot
        // programs here write no whistle (they follow `local.var.gc.state`), so each
        // layer goes by the GC's delayed word.
        delays: GcDelays::gc3(),
        whistle: WhistleHearing::deaf(),
    };
    let mut cfg = SimConfig {
        robots: 3,
        seed,
        budget: Some(comms::BudgetSpec::SPL),
        duration_s: script.length_s() + 600.0,
        game: Some(script),
        ..SimConfig::default()
    };
    cfg.network.loss = Some(0.0);
    let opts = DaemonsOptions {
        exe: env!("CARGO_BIN_EXE_huddle").into(),
        impair: Some("loss=0".into()),
        log_dir: None,
    };
    let r = daemons::run(&cfg, &opts, |_| {}).expect("the game is played with daemons");
    let g = r.game.as_ref().expect("a game report under --game");
    let shown = format!("{r}");
    eprintln!("{shown}");
    assert_eq!(r.relay_errors, 0, "every relay write is taken: {shown}");
    assert_eq!(
        g.game_illegal_messages, 0,
        "the team is never illegal: {shown}"
    );
    assert_eq!(g.game_messages_oversized, 0, "no frame over 128 B: {shown}");
    // The GC's count against the daemons' own.
    let sent = r.team_messages_sent;
    let heard = g.game_messages_counted + g.game_messages_uncounted;
    assert!(
        g.game_messages_counted > 50,
        "the GC counted the team's play: {shown}"
    );
    assert!(
        sent.abs_diff(heard) <= r.robots as u64,
        "the GC counts what the daemons sent ({} counted = frames_out {sent} less {} heard in \
         uncounted states, but for ≤ {} in flight at the end): {shown}",
        g.game_messages_counted,
        g.game_messages_uncounted,
        r.robots
    );
    assert!(
        g.game_kick_offs >= 1,
        "at least the half's first kick-off: {shown}"
    );
    let far = g.kick_off_spot_error_m[0];
    assert!(
        far < 1.0,
        "the robots walked to their kick-off spots in Ready (farthest {far} m): {shown}"
    );
    assert_eq!(g.game_penalties, 1, "robot 3 was penalised: {shown}");
    assert!(
        g.penalised_claims_checked > 100,
        "the teammates were judged during the penalty: {shown}"
    );
    assert_eq!(
        g.penalised_claims_held, 0,
        "no teammate's layer counts the penalised robot's claim: {shown}"
    );
    assert_eq!(g.status.len(), 3, "{shown}");
    for s in &g.status {
        assert!(
            s.packets > 20 && s.longest_gap_s < 2.0,
            "robot {} is shown connected throughout ({} status packets, longest gap {} s): {shown}",
            s.robot,
            s.packets,
            s.longest_gap_s
        );
    }
}
