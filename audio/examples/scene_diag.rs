//! One row of `huddle audio rooms`, listing what it missed and got wrong (for diagnosis):
//! `cargo run --release -p audio --example scene_diag -- DIR ROOM SNR|quiet TALKERS
//! LONG_SHARE MESSAGES SEED [two]`.
use audio::evaluation::{load_room_set, run_scene_trial, SceneTrial};

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    if a.len() < 7 {
        eprintln!("usage: scene_diag DIR ROOM SNR|quiet TALKERS LONG_SHARE MESSAGES SEED [two]");
        std::process::exit(2);
    }
    let set = load_room_set(std::path::Path::new(&a[0])).expect("room set");
    let room = set
        .rooms
        .iter()
        .find(|r| r.name == a[1])
        .expect("room in the set");
    let trial = SceneTrial {
        seed: a[6].parse().expect("seed"),
        snr_db: a[2].parse().ok(),
        talkers: a[3].parse().expect("talkers"),
        messages: a[5].parse().expect("messages"),
        long_share: a[4].parse().expect("long share"),
        two_senders: a.get(7).is_some_and(|s| s == "two"),
        max_clock_error: 0.005,
        team: audio::TeamPlan::Three,
    };
    let out = run_scene_trial(room, &set.babble, &trial).expect("trial");
    println!(
        "{}: {}/{} correct, long {}/{}, {} wrong, {} extra, overlapped {}/{}",
        room.name,
        out.correct,
        out.sent,
        out.long_correct,
        out.long_sent,
        out.wrong,
        out.spurious,
        out.overlapped_correct,
        out.overlapped_sent
    );
    for (m, t) in &out.missed {
        println!("  missed {m} at {t:.2} s");
    }
    for (d, around) in &out.wrong_reports {
        println!(
            "  wrong {} at {:.2} s over {around:?}",
            d.message, d.start_s
        );
    }
}
