//! One white-noise row of `huddle audio eval` (for diagnosis and quick checks of the dry
//! figures): `cargo run --release -p audio --example snr_diag -- SNR FREQUENCY_ERROR
//! MESSAGES SEED [LONG_SHARE]`. The eval's −13 dB row is seed `S + 4`, its +0.5% row
//! `S + 200` (S the eval's `--seed`).
use audio::evaluation::{run_snr_trial_team, SnrTrial};

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    if a.len() < 4 {
        eprintln!("usage: snr_diag SNR FREQUENCY_ERROR MESSAGES SEED [LONG_SHARE]");
        std::process::exit(2);
    }
    let trial = SnrTrial {
        seed: a[3].parse().expect("seed"),
        snr_db: a[0].parse().expect("SNR"),
        messages: a[2].parse().expect("messages"),
        tone_duration_s: 1.0,
        sample_rate_hz: 16_000,
        long_share: a.get(4).map_or(0.0, |s| s.parse().expect("long share")),
        frequency_error: a[1].parse().expect("frequency error"),
    };
    let out = run_snr_trial_team(&trial, audio::TeamPlan::Three).expect("trial");
    println!(
        "SNR {} dB, error {}: {}/{} correct, {} wrong, {} extra",
        trial.snr_db, trial.frequency_error, out.correct, out.sent, out.wrong, out.spurious
    );
    for (m, start, _) in &out.missed {
        println!("  missed {m} at {start:.2} s");
    }
}
