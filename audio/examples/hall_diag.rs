//! One row of `huddle audio eval --section rooms`, listing the messages it missed (for
//! diagnosis): `cargo run --release -p audio --example hall_diag -- SEED T60 white|babble
//! SNR [MESSAGES [LONG_SHARE]]`. The eval's row seed is `seed + 1000 + 100·i + 10·j + k`
//! (T60 index i, noise j, SNR index k).
use audio::evaluation::{run_room_trial, RoomNoise, RoomTrial};
const USAGE: &str = "usage: hall_diag ROW_SEED T60 white|babble SNR [MESSAGES [LONG_SHARE]]";

/// The argument at `i` as a `T`, or the usage and exit status 2.
fn arg<T: std::str::FromStr>(a: &[String], i: usize, default: Option<T>) -> T {
    match (a.get(i).map(|s| s.parse::<T>()), default) {
        (Some(Ok(v)), _) => v,
        (None, Some(d)) => d,
        _ => {
            eprintln!("{USAGE}");
            std::process::exit(2);
        }
    }
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let seed: u64 = arg(&a, 1, None);
    let t60: f64 = arg(&a, 2, None);
    let noise = match a.get(3).map(String::as_str) {
        Some("white") => RoomNoise::White,
        Some("babble") => RoomNoise::Babble,
        _ => {
            eprintln!("{USAGE}");
            std::process::exit(2);
        }
    };
    let snr: f64 = arg(&a, 4, None);
    let n: usize = arg(&a, 5, Some(1000));
    let mut trial = RoomTrial::new(seed, t60, snr, noise, n);
    trial.long_share = arg(&a, 6, Some(0.0));
    let out = match run_room_trial(&trial) {
        Ok(out) => out,
        Err(e) => {
            eprintln!("hall_diag: {e}");
            std::process::exit(1);
        }
    };
    let mut e = out.start_errors_s.clone();
    e.sort_by(|a, b| a.total_cmp(b));
    println!(
        "seed {seed} T60 {t60} {} {snr} dB: {}/{} correct, {} wrong, {} extra; t0err p50 {:.0} p95 {:.0} ms",
        a[3], out.correct, out.sent, out.wrong, out.spurious,
        1000.0 * e.get(e.len() / 2).copied().unwrap_or(0.0),
        1000.0 * e.get(e.len() * 95 / 100).copied().unwrap_or(0.0)
    );
    for (m, s, t) in &out.missed {
        println!("MISSED {m:?} {s:.3}-{t:.3}");
    }
}
