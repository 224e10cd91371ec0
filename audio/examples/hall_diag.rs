//! One row of `huddle audio eval --section rooms`, listing the messages it missed (for
//! diagnosis): `cargo run --release -p audio --example hall_diag -- SEED T60 white|babble
//! SNR [MESSAGES [LONG_SHARE]]`. The eval's row seed is `seed + 1000 + 100·i + 10·j + k`
//! (T60 index i, noise j, SNR index k).
use audio::evaluation::{run_room_trial, RoomNoise, RoomTrial};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    if a.len() < 5 {
        eprintln!("usage: hall_diag ROW_SEED T60 white|babble SNR [MESSAGES [LONG_SHARE]]");
        std::process::exit(2);
    }
    let seed: u64 = a[1].parse().unwrap();
    let t60: f64 = a[2].parse().unwrap();
    let noise = if a[3] == "white" {
        RoomNoise::White
    } else {
        RoomNoise::Babble
    };
    let snr: f64 = a[4].parse().unwrap();
    let n: usize = a.get(5).map(|x| x.parse().unwrap()).unwrap_or(1000);
    let mut trial = RoomTrial::new(seed, t60, snr, noise, n);
    trial.long_share = a.get(6).map(|x| x.parse().unwrap()).unwrap_or(0.0);
    let out = run_room_trial(&trial).unwrap();
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
