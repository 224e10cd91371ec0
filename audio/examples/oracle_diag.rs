//! One row of `huddle audio rooms` decoded twice: by the decoder and by the oracle-timing
//! reference (told each message's start, length and clock error; see
//! `audio::evaluation::OracleVerdict`), with the split of the decoder's losses:
//! `cargo run --release -p audio --example oracle_diag -- DIR ROOM SNR|quiet TALKERS
//! LONG_SHARE MESSAGES SEED [one|two] [checked] [TONE_S]`. `TONE_S` (default 1) sends the
//! format with longer or shorter tones, decoder and oracle alike.
//! Each sent message gets a line `msg START SENT decoder=ok|lost oracle=ok|lost
//! mean=ok|lost margin=DB`; `python3 audio/rooms/oracle_split.py` joins them with
//! `scene_diag`'s causes.
use audio::evaluation::{load_room_set, run_scene_trial_with_oracle, SceneTrial};

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    if a.len() < 7 {
        eprintln!(
            "usage: oracle_diag DIR ROOM SNR|quiet TALKERS LONG_SHARE MESSAGES SEED [one|two] [checked] [TONE_S]"
        );
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
    let tone_s: f64 = a.get(9).map_or(1.0, |s| s.parse().expect("tone duration"));
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
    let (out, _trace, verdicts) =
        run_scene_trial_with_oracle(room, &set.babble, &trial, tone_s).expect("trial");
    let missed: Vec<(audio::Message, f64)> = out.missed.clone();
    let is_missed = |v: &audio::evaluation::OracleVerdict| {
        missed
            .iter()
            .any(|(m, t)| *m == v.sent && (t - v.start_s).abs() < 1e-6)
    };
    let mut split = [[0usize; 2]; 2];
    let mut mean_right = 0;
    for v in &verdicts {
        let lost = is_missed(v);
        split[usize::from(lost)][usize::from(!v.median_right())] += 1;
        mean_right += usize::from(v.mean_right());
        println!(
            "msg {:.2} {} decoder={} oracle={} mean={} margin={:.1}",
            v.start_s,
            v.sent,
            if lost { "lost" } else { "ok" },
            if v.median_right() { "ok" } else { "lost" },
            if v.mean_right() { "ok" } else { "lost" },
            v.median_margin_db
        );
    }
    let oracle_right = split[0][0] + split[1][0];
    println!(
        "{} tone {tone_s} s: decoder {}/{} (wrong {}, extra {}), oracle median {}/{}, oracle mean {}/{}",
        room.name,
        out.correct,
        out.sent,
        out.wrong,
        out.spurious,
        oracle_right,
        verdicts.len(),
        mean_right,
        verdicts.len()
    );
    println!(
        "split: decoder lost & oracle right {} (the decoder's to win), decoder lost & oracle lost {} (not in the signal for the oracle), decoder right & oracle lost {}",
        split[1][0], split[1][1], split[0][1]
    );
}
