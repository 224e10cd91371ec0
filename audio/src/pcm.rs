//! Raw 16-bit little-endian PCM (`s16le`, what `arecord -f S16_LE` writes and
//! `aplay -f S16_LE` reads) and sample-format conversion.

/// f32 in [-1, 1] to i16, clamped, rounded.
pub fn f32_to_i16(x: f32) -> i16 {
    (x * 32767.0).round().clamp(-32768.0, 32767.0) as i16
}

/// i16 to f32 in [-1, 1).
pub fn i16_to_f32(x: i16) -> f32 {
    f32::from(x) / 32768.0
}

/// i16 samples as s16le bytes.
pub fn i16_to_s16le(samples: &[i16]) -> Vec<u8> {
    samples.iter().flat_map(|s| s.to_le_bytes()).collect()
}

/// Turns a byte stream cut anywhere (odd lengths included) into i16 samples.
#[derive(Debug, Default, Clone)]
pub struct S16leDecoder {
    pending: Option<u8>,
}

impl S16leDecoder {
    /// A decoder with nothing pending.
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends the samples completed by `bytes` to `out`; an odd byte waits for the next call.
    pub fn push(&mut self, mut bytes: &[u8], out: &mut Vec<i16>) {
        if let Some(lo) = self.pending.take() {
            match bytes.split_first() {
                Some((&hi, rest)) => {
                    out.push(i16::from_le_bytes([lo, hi]));
                    bytes = rest;
                }
                None => {
                    self.pending = Some(lo);
                    return;
                }
            }
        }
        let mut chunks = bytes.chunks_exact(2);
        out.extend(chunks.by_ref().map(|c| i16::from_le_bytes([c[0], c[1]])));
        self.pending = chunks.remainder().first().copied();
    }

    /// Whether an odd byte is waiting (a stream ending here was cut mid-sample).
    pub fn has_pending_byte(&self) -> bool {
        self.pending.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_split_anywhere_give_the_same_samples() {
        let samples = [0i16, -1, 32767, -32768, 1234];
        let bytes = i16_to_s16le(&samples);
        for cut in 0..=bytes.len() {
            let mut d = S16leDecoder::new();
            let mut out = Vec::new();
            d.push(&bytes[..cut], &mut out);
            d.push(&bytes[cut..], &mut out);
            assert_eq!(out, samples, "cut at byte {cut}");
            assert!(!d.has_pending_byte());
        }
    }

    #[test]
    fn conversion_round_trips_within_one_step() {
        for x in [-1.0f32, -0.5, 0.0, 0.25, 0.999] {
            let back = i16_to_f32(f32_to_i16(x));
            assert!((back - x).abs() < 1.0 / 16384.0, "{x} -> {back}");
        }
        assert_eq!(f32_to_i16(3.0), 32767, "out-of-range input clamps");
    }
}
