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
    let penalty = ScriptedPenalty {
        robot: 3,
        half: 1,
        after_play_s: 10.0,
    };
    // GameController3's late packets, as on a real field; the robot programs here hear no
    // whistle (they follow `local.var.gc.state`), so each layer goes by the GC's delayed
    // word.
    let (cfg, opts) = short_half(5, 60.0, vec![penalty], WhistleHearing::deaf());
    let r = daemons::run(&cfg, &opts, |_| {}).expect("the game is played with daemons");
    let g = r.game.as_ref().expect("a game report under --game");
    let shown = format!("{r}");
    eprintln!("{shown}");
    assert_eq!(r.relay_errors, 0, "every relay write is taken: {shown}");
    assert_eq!(
        g.books.game_illegal_messages, 0,
        "the team is never illegal: {shown}"
    );
    assert_eq!(
        g.books.game_messages_oversized, 0,
        "no frame over 128 B: {shown}"
    );
    // The GC's count against the daemons' own.
    let sent = r.team_messages_sent;
    let heard = g.books.game_messages_counted + g.books.game_messages_uncounted;
    assert!(
        g.books.game_messages_counted > 50,
        "the GC counted the team's play: {shown}"
    );
    assert!(
        sent.abs_diff(heard) <= r.robots as u64,
        "the GC counts what the daemons sent ({} counted = frames_out {sent} less {} heard in \
         uncounted states, but for ≤ {} in flight at the end): {shown}",
        g.books.game_messages_counted,
        g.books.game_messages_uncounted,
        r.robots
    );
    assert!(
        g.books.game_kick_offs >= 1,
        "at least the half's first kick-off: {shown}"
    );
    let far = g.kick_off_spot_error_m[0];
    assert!(
        far < 1.0,
        "the robots walked to their kick-off spots in Ready (farthest {far} m): {shown}"
    );
    assert_eq!(g.books.game_penalties, 1, "robot 3 was penalised: {shown}");
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

/// #34, twelfth session: the daemons' robot programs hear the referee's whistle and write
/// `local.var.robot.whistle` to their daemons. Under GameController3's delays (Set shown
/// for 15 s after play starts) a team whose programs hear none sits out every kick-off's
/// first 15 s: its daemons send at most the taker's Set claim a kick-off in the first
/// 10 s of play. Programs that hear every whistle (0.2–1.0 s late) start play at it, and
/// their daemons tell the team from the kick-off on. Seed 6, three robots, a 90 s half
/// with no penalty, the two games played at once (each its own daemons, group and
/// ports); only the whistle differs. (The daemons pace `--budget spl` for a 600 s half:
/// on this 90 s one they may spend freely, and the hearing team sends most of its frames
/// in the kick-offs' first 10 s, ~170 a kick-off; the figure says when the team speaks,
/// not how much a real game's pace lets it.)
#[test]
fn daemons_whose_programs_hear_the_whistle_play_from_the_kick_off() {
    let game = |whistle: WhistleHearing| {
        let (cfg, opts) = short_half(6, 90.0, Vec::new(), whistle);
        std::thread::spawn(move || daemons::run(&cfg, &opts, |_| {}))
    };
    let hearing = WhistleHearing {
        p_heard: 1.0,
        ..WhistleHearing::typical()
    };
    let (deaf, hearing) = (game(WhistleHearing::deaf()), game(hearing));
    type Played = std::thread::JoinHandle<Result<daemons::DaemonsReport, daemons::DaemonsError>>;
    let report = |h: Played| {
        let r: daemons::DaemonsReport = h
            .join()
            .expect("the game's thread")
            .expect("the game is played with daemons");
        (r.game.clone().expect("a game report under --game"), r)
    };
    let ((deaf, deaf_r), (hearing, hearing_r)) = (report(deaf), report(hearing));
    let shown = format!("deaf:\n{deaf_r}\nhearing:\n{hearing_r}");
    eprintln!("{shown}");
    assert_eq!(
        (
            deaf.books.game_whistles_heard,
            hearing.books.game_whistles_missed
        ),
        (0, 0),
        "deaf programs hear no whistle, the others every one: {shown}"
    );
    assert!(
        hearing.books.game_whistles_heard >= 3 * 2,
        "the half's Standby and first kick-off whistles, each robot: {shown}"
    );
    assert!(
        deaf.books.game_kick_offs >= 1 && hearing.books.game_kick_offs >= 1,
        "{shown}"
    );
    assert!(
        deaf.game_kick_off_messages <= u64::from(deaf.books.game_kick_offs),
        "without the whistle the daemons' layers think it is Set for the first 15 s of \
         play: at most the taker's claim a kick-off in its first 10 s ({} frames, {} \
         kick-offs): {shown}",
        deaf.game_kick_off_messages,
        deaf.books.game_kick_offs
    );
    assert!(
        hearing.game_kick_off_messages > u64::from(hearing.books.game_kick_offs)
            && hearing.game_kick_off_messages > deaf.game_kick_off_messages,
        "hearing the whistle the daemons tell the team from the kick-off on: {} frames in \
         {} kick-offs' first 10 s (deaf: {}): {shown}",
        hearing.game_kick_off_messages,
        hearing.books.game_kick_offs,
        deaf.game_kick_off_messages
    );
    for (g, r) in [(&deaf, &deaf_r), (&hearing, &hearing_r)] {
        assert_eq!(
            (g.books.game_illegal_messages, r.relay_errors),
            (0, 0),
            "never illegal, every relay write taken (the whistle's too): {shown}"
        );
    }
}

/// A one-half game of three robots under GameController3's delays, on real daemons with
/// `--budget spl` over loopback links that lose nothing (so the GC's count can be held to
/// the daemons' own).
fn short_half(
    seed: u64,
    half_s: f64,
    penalties: Vec<ScriptedPenalty>,
    whistle: WhistleHearing,
) -> (SimConfig, DaemonsOptions) {
    let script = GameScript {
        halves: 1,
        half_s,
        break_s: 0.0,
        initial_s: 3.0,
        standby_s: 3.0,
        ready_s: 10.0,
        set_s: 3.0,
        finished_s: 3.0,
        penalty_s: 20.0,
        messages_per_game: 1200,
        penalties,
        delays: GcDelays::gc3(),
        whistle,
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
    (cfg, opts)
}
