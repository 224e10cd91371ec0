use audio::evaluation::{run_room_trial, RoomNoise, RoomTrial};
fn main() {
    let a: Vec<String> = std::env::args().collect();
    let t60: f64 = a[1].parse().unwrap();
    let snr: f64 = a[2].parse().unwrap();
    let noise = if a[3] == "babble" { RoomNoise::Babble } else { RoomNoise::White };
    let n: usize = a[4].parse().unwrap();
    let seed: u64 = a.get(5).map(|s| s.parse().unwrap()).unwrap_or(7);
    audio::TRACE.store(std::env::var_os("TRACE").is_some(), std::sync::atomic::Ordering::Relaxed);
    let out = run_room_trial(&RoomTrial::new(seed, t60, snr, noise, n)).unwrap();
    println!("sent {} correct {} wrong {} extra {}", out.sent, out.correct, out.wrong, out.spurious);
}
