//! Decoder throughput in samples per second on 16 kHz audio (1 s tones): white noise at
//! −6 dB in-band SNR with a message every couple of seconds, pushed in 512-sample blocks
//! as a sound card would deliver them. Real time at 16 kHz is 16 000 samples/s, so
//! throughput / 16 000 is the "× real time" figure.

use audio::channel::{power, white_sigma_for_in_band_snr, Source, WhiteNoise};
use audio::{Decoder, DecoderConfig, Encoder, EncoderConfig, Message, Sender};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};

fn stream(seconds: usize) -> Vec<f32> {
    let enc = Encoder::new(EncoderConfig::default()).unwrap();
    let mut x = Vec::with_capacity(seconds * 16_000);
    let mut i = 0u8;
    while x.len() < seconds * 16_000 {
        x.extend(vec![0.0f32; 16_000]);
        x.extend(enc.encode_f32(&Message::short(Sender::ALL[(i % 3) as usize], i % 21).unwrap()));
        i = i.wrapping_add(1);
    }
    x.truncate(seconds * 16_000);
    let sigma = white_sigma_for_in_band_snr(power(&x) * 2.0, -6.0, 16_000);
    WhiteNoise::new(1, sigma).add_to(&mut x);
    x
}

fn bench(c: &mut Criterion) {
    let x = stream(60);
    let mut group = c.benchmark_group("decoder");
    group.throughput(Throughput::Elements(x.len() as u64));
    group.sample_size(10);
    group.bench_function("16kHz_1s_tones_60s_stream", |b| {
        b.iter(|| {
            let mut d = Decoder::new(DecoderConfig::default()).unwrap();
            let mut n = 0;
            for block in x.chunks(512) {
                d.push_f32(block);
                while d.poll_message().is_some() {
                    n += 1;
                }
            }
            n
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
