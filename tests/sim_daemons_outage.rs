//! `huddle sim --daemons --outage … --acoustic`: a WLAN outage on real daemons, and the
//! acoustic fallback carrying the team through it. Four robots in the drawn world (their
//! clocks seconds apart and drifting), each team layer in a `huddle daemon` on loopback (a
//! scratch group, IP_MULTICAST_IF 127.0.0.1). Every daemon's radio goes down 8 s in, for
//! 20 s (`huddle daemon --outage`). With `--acoustic` each daemon also speaks and listens
//! (`--audio-fallback`, `--audio-out`/`--audio-in` on FIFOs) through the simulator's room:
//! the hall, the crowd, the robots' true positions, in real time. Nothing of the fallback
//! runs in the simulator; the daemons' team layers sound, hear and decide.
//!
//! Scenario: the same seed twice, the fallback off and on. Off, the field players cannot
//! hear each other's claims and the team holds no single goer; on, the daemons' claims
//! cross the room and the team keeps exactly one goer most of the outage. The bounds are
//! loose on purpose (real time on a shared machine, one short match); the seed table is in
//! docs/results/acoustic-fallback-daemon.md.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

use std::process::Command;

fn outage_match(acoustic: bool) -> serde_json::Value {
    let mut args = vec![
        "sim",
        "--daemons",
        "--robots",
        "4",
        "--duration",
        "30s",
        "--seed",
        "3",
        "--outage",
        "20s@8s",
        "--json",
    ];
    if acoustic {
        args.push("--acoustic");
    }
    let out = Command::new(env!("CARGO_BIN_EXE_huddle"))
        .args(&args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("run huddle sim --daemons");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "huddle sim {args:?} failed: {stderr}");
    serde_json::from_slice(&out.stdout).expect("one JSON report on stdout")
}

#[test]
fn in_an_outage_real_daemons_keep_one_goer_by_sound_and_not_without_it() {
    let off = outage_match(false);
    let on = outage_match(true);
    for r in [&off, &on] {
        assert_eq!(
            r["relay_errors"], 0,
            "every write is one the contract takes: {r}"
        );
        let dropped = r["outage"]["radio_dropped"].as_u64().expect("a count");
        assert!(
            dropped > 100,
            "the daemons' radios were down: {dropped} dropped: {r}"
        );
        let visible = r["outage"]["outage_ball_visible_s"]
            .as_f64()
            .expect("a figure");
        assert!(
            visible > 5.0,
            "the ball was seen in the outage ({visible} s): {r}"
        );
    }
    assert_eq!(
        off["outage"]["acoustic_sounded"], 0,
        "without --acoustic nothing is sounded: {off}"
    );
    let sounded = on["outage"]["acoustic_sounded"].as_u64().expect("a count");
    let heard = on["outage"]["acoustic_heard"].as_u64().expect("a count");
    // 20 s of outage, 3 slots of 0.7 s, 3 field players: about 28 claims sounded after
    // the staleness limit, each heard by up to 3 teammates.
    assert!(
        sounded >= 15 && heard >= sounded,
        "the daemons sounded claims and their teammates heard them: {sounded} sounded, {heard} heard: {on}"
    );
    let one_off = off["outage"]["outage_exactly_one_goer_pct"]
        .as_f64()
        .expect("a figure");
    let one_on = on["outage"]["outage_exactly_one_goer_pct"]
        .as_f64()
        .expect("a figure");
    assert!(
        one_on >= 80.0 && one_on >= one_off + 20.0,
        "with the fallback the daemons keep one goer in the outage: {one_on:.1}% (without: {one_off:.1}%)\non: {on}\noff: {off}"
    );
}
