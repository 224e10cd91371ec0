//! One row of `huddle audio backgrounds` with the decoder's trace around each false
//! message (for diagnosis): `cargo run --release -p audio --example background_diag --
//! KIND T60 SECONDS SEED` (KIND: talkers, crowd, whistles, music, doors, everything; the
//! row seed of `huddle audio backgrounds --seed S` is `S · 1000 + 10 · kind + hall`).
use audio::evaluation::{run_background_false_alarm_trial_traced, Background};

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    if a.len() < 4 {
        eprintln!("usage: background_diag KIND T60 SECONDS SEED");
        std::process::exit(2);
    }
    let kind = Background::ALL
        .into_iter()
        .find(|k| k.name() == a[0])
        .expect("a background name");
    let t60: f64 = a[1].parse().expect("T60");
    let seconds: f64 = a[2].parse().expect("seconds");
    let seed: u64 = a[3].parse().expect("seed");
    // The checked plan (as the room rows use) unless a fifth argument names another.
    let team: audio::TeamPlan = a
        .get(4)
        .map_or(Ok(audio::TeamPlan::Checked), |s| s.parse())
        .expect("a team plan");
    let (out, trace) = run_background_false_alarm_trial_traced(kind, seconds, t60, seed, team);
    println!(
        "{} T60 {t60}: {} false in {:.2} h",
        kind.name(),
        out.false_messages,
        out.hours
    );
    let slots = trace.iter().filter(|e| e.what.starts_with("slot ")).count();
    let passed = trace.iter().filter(|e| e.what.ends_with("passes")).count();
    println!("  {slots} slots decided on their checks, {passed} passed them");
    for d in &out.detections {
        println!(
            "false {} at {:.2} s, tone SNR {:.1} dB, scale {:.4}",
            d.message, d.start_s, d.tone_snr_db, d.frequency_scale
        );
        for e in trace
            .iter()
            .filter(|e| e.at_s > d.start_s - 3.0 && e.at_s < d.end_s + 3.0)
        {
            println!("    {:9.2} {}", e.at_s, e.what);
        }
    }
}
