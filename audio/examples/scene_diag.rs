//! One row of `huddle audio rooms`, listing what it missed and got wrong (for diagnosis):
//! `cargo run --release -p audio --example scene_diag -- DIR ROOM SNR|quiet TALKERS
//! LONG_SHARE MESSAGES SEED [two|one] [checked]`.
use audio::evaluation::{load_room_set, run_scene_trial_traced, SceneTrial};

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
    let team = match a.get(8).map(String::as_str) {
        Some("checked") => audio::TeamPlan::Checked,
        _ => audio::TeamPlan::Three,
    };
    let trial = SceneTrial {
        seed: a[6].parse().expect("seed"),
        snr_db: a[2].parse().ok(),
        talkers: a[3].parse().expect("talkers"),
        messages: a[5].parse().expect("messages"),
        long_share: a[4].parse().expect("long share"),
        two_senders: a.get(7).is_some_and(|s| s == "two"),
        max_clock_error: 0.005,
        team,
    };
    let (out, trace) = run_scene_trial_traced(room, &set.babble, &trial).expect("trial");
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
    if let Ok(path) = std::env::var("SCENE_DUMP_TRACE") {
        let text: String = trace
            .iter()
            .map(|e| format!("{:.2} {}\n", e.at_s, e.what))
            .collect();
        std::fs::write(path, text).expect("trace dump");
    }
    // What lost each missed message: the decoder's decisions from just before its start
    // to a little after its end (a long message is two tones).
    let mut causes = std::collections::BTreeMap::<String, usize>::new();
    for (m, t) in &out.missed {
        let len = if matches!(m, audio::Message::Long { .. }) {
            2.0
        } else {
            1.0
        };
        let near: Vec<_> = trace
            .iter()
            .filter(|e| e.at_s > t - 0.6 && e.at_s < t + len + 0.8)
            .collect();
        let cause = if !near.iter().any(|e| e.what.starts_with("found")) {
            // What the search said while the message sounded (nothing: it was idle, a
            // frame was being tracked).
            let mut kinds = std::collections::BTreeMap::<&str, usize>::new();
            for e in near
                .iter()
                .filter(|e| e.at_s >= *t && e.at_s < t + len + 0.3)
            {
                if let Some(w) = e.what.strip_prefix("search: ") {
                    *kinds.entry(w.split(' ').next().unwrap_or("")).or_default() += 1;
                }
            }
            match kinds.iter().max_by_key(|(_, &n)| n) {
                Some((k, _)) => format!("never found: search {k}"),
                None => "never found: search idle".to_string(),
            }
        } else {
            near.iter()
                .rev()
                .find(|e| {
                    !e.what.starts_with("found")
                        && !e.what.starts_with("timeline")
                        && !e.what.starts_with("search")
                })
                .map(|e| {
                    let w = &e.what;
                    let w = w.split(" level ").next().unwrap_or(w).to_string();
                    match e.what.find("dB: ") {
                        Some(i) => e.what[i + 4..].split(" [").next().unwrap_or("").to_string(),
                        None => w.split(": votes").next().unwrap_or("").to_string(),
                    }
                })
                .unwrap_or_else(|| "found, nothing decided".to_string())
        };
        println!("  missed {m} at {t:.2} s: {cause}");
        for e in &near {
            println!("      {:9.2} {}", e.at_s, e.what);
        }
        *causes.entry(cause).or_default() += 1;
    }
    for (c, n) in &causes {
        println!("cause {n:5} {c}");
    }
    for (d, around) in &out.wrong_reports {
        println!(
            "  wrong {} at {:.2} s over {around:?}",
            d.message, d.start_s
        );
    }
}
