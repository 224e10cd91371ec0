//! A WAV file from anywhere, into `read_wav` and, if it reads, through the streaming
//! decoder in uneven blocks: must never panic, and every sample read is finite and within
//! [-1, 1]. The same bytes as raw s16le PCM go through the stdin path's decoder too.
#![no_main]

use audio::{read_wav, Decoder, DecoderConfig, S16leDecoder};
use libfuzzer_sys::fuzz_target;

/// Keep one run short: two seconds at the highest rate.
const MAX_SAMPLES: usize = 2 * 192_000;

fuzz_target!(|data: &[u8]| {
    if let Ok(rec) = read_wav(data) {
        assert!(
            rec.samples.iter().all(|s| s.is_finite() && s.abs() <= 1.0),
            "samples in [-1, 1]"
        );
        if let Ok(mut d) = Decoder::new(DecoderConfig {
            sample_rate_hz: rec.sample_rate_hz,
            ..DecoderConfig::default()
        }) {
            let samples = &rec.samples[..rec.samples.len().min(MAX_SAMPLES)];
            let mut at = 0;
            let mut block = 1;
            while at < samples.len() {
                let end = (at + block).min(samples.len());
                d.push_f32(&samples[at..end]);
                while d.poll_message().is_some() {}
                at = end;
                block = block * 3 % 4099 + 1;
            }
            d.finish();
            while d.poll_message().is_some() {}
        }
    }
    let mut pcm = S16leDecoder::new();
    let mut d = Decoder::new(DecoderConfig::default()).expect("default config");
    let mut samples = Vec::new();
    for chunk in data.chunks(7) {
        samples.clear();
        pcm.push(chunk, &mut samples);
        d.push_i16(&samples);
        while d.poll_message().is_some() {}
    }
    d.finish();
    while d.poll_message().is_some() {}
});
