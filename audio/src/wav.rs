//! WAV files through `hound`: read any linear PCM or float WAV to mono f32, write 16-bit
//! PCM or 32-bit float. A file that is not linear PCM, is cut short, or has a rate the
//! decoder cannot use is a typed error, never a panic.

use std::io::{Read, Seek, Write};

/// A mono recording.
#[derive(Clone, Debug, PartialEq)]
pub struct Recording {
    /// Sample rate, Hz.
    pub sample_rate_hz: u32,
    /// Samples in [-1, 1]; several channels are averaged.
    pub samples: Vec<f32>,
}

/// Lowest rate the decoder accepts (the top tone, 4 kHz, is then at Nyquist).
pub const MIN_RATE_HZ: u32 = 8_000;
/// Highest rate the decoder accepts.
pub const MAX_RATE_HZ: u32 = 192_000;

/// Why a WAV file cannot be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadWavError {
    /// Not a RIFF/WAVE file, or a header hound cannot parse.
    #[error("not a readable WAV file: {0}")]
    Malformed(String),
    /// A WAV whose samples are not linear PCM or IEEE float (A-law, µ-law, ADPCM, …), or a
    /// sample width hound does not read.
    #[error("WAV format unsupported (only linear PCM and 32-bit float): {0}")]
    NotPcm(String),
    /// The data chunk ends before the header says it does.
    #[error("WAV truncated after {samples_read} samples")]
    Truncated {
        /// Samples read before the data ran out.
        samples_read: usize,
    },
    /// The sample rate is outside 8000 … 192000 Hz.
    #[error("WAV sample rate {0} Hz unsupported (8000..=192000)")]
    UnsupportedRate(u32),
    /// A WAV with zero channels.
    #[error("WAV has no channels")]
    NoChannels,
    /// Reading failed for another reason.
    #[error("I/O error reading WAV: {0}")]
    Io(#[from] std::io::Error),
}

/// Why a WAV file cannot be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteWavError {
    /// The rate is outside 8000 … 192000 Hz.
    #[error("sample rate {0} Hz unsupported (8000..=192000)")]
    UnsupportedRate(u32),
    /// hound refused or the writer failed.
    #[error("writing WAV failed: {0}")]
    Write(#[from] hound::Error),
}

/// Maps hound's error; `samples_read` is `Some` once the header is parsed.
fn classify(e: hound::Error, samples_read: Option<usize>) -> ReadWavError {
    match (e, samples_read) {
        // hound reports a short data chunk as an I/O error of its own kind.
        (hound::Error::IoError(_), Some(samples_read)) => ReadWavError::Truncated { samples_read },
        (hound::Error::IoError(io), None) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            ReadWavError::Truncated { samples_read: 0 }
        }
        (e, _) => classify_format(e),
    }
}

fn classify_format(e: hound::Error) -> ReadWavError {
    match e {
        hound::Error::IoError(io) => ReadWavError::Io(io),
        hound::Error::Unsupported => ReadWavError::NotPcm("unsupported format tag".into()),
        hound::Error::FormatError(m) => ReadWavError::Malformed(m.to_string()),
        other => ReadWavError::NotPcm(other.to_string()),
    }
}

/// Reads a WAV from `reader`.
pub fn read_wav<R: Read>(reader: R) -> Result<Recording, ReadWavError> {
    let mut wav = hound::WavReader::new(reader).map_err(|e| classify(e, None))?;
    let spec = wav.spec();
    if spec.channels == 0 {
        return Err(ReadWavError::NoChannels);
    }
    if !(MIN_RATE_HZ..=MAX_RATE_HZ).contains(&spec.sample_rate) {
        return Err(ReadWavError::UnsupportedRate(spec.sample_rate));
    }
    let channels = usize::from(spec.channels);
    let mut interleaved: Vec<f32> = Vec::new();
    match spec.sample_format {
        hound::SampleFormat::Float => {
            if spec.bits_per_sample != 32 {
                return Err(ReadWavError::NotPcm(format!(
                    "{}-bit float",
                    spec.bits_per_sample
                )));
            }
            for s in wav.samples::<f32>() {
                let n = interleaved.len();
                interleaved.push(s.map_err(|e| classify(e, Some(n / channels)))?);
            }
        }
        hound::SampleFormat::Int => {
            if !(1..=32).contains(&spec.bits_per_sample) {
                return Err(ReadWavError::NotPcm(format!(
                    "{}-bit",
                    spec.bits_per_sample
                )));
            }
            let scale = 1.0 / (1u64 << (spec.bits_per_sample - 1)) as f64;
            for s in wav.samples::<i32>() {
                let n = interleaved.len();
                let v = s.map_err(|e| classify(e, Some(n / channels)))?;
                interleaved.push((f64::from(v) * scale) as f32);
            }
        }
    }
    if !interleaved.len().is_multiple_of(channels) {
        return Err(ReadWavError::Truncated {
            samples_read: interleaved.len() / channels,
        });
    }
    let samples = interleaved
        .chunks_exact(channels)
        .map(|c| c.iter().sum::<f32>() / channels as f32)
        .collect();
    Ok(Recording {
        sample_rate_hz: spec.sample_rate,
        samples,
    })
}

fn check_rate(rate: u32) -> Result<(), WriteWavError> {
    if (MIN_RATE_HZ..=MAX_RATE_HZ).contains(&rate) {
        Ok(())
    } else {
        Err(WriteWavError::UnsupportedRate(rate))
    }
}

/// Writes mono 16-bit PCM.
pub fn write_wav_i16<W: Write + Seek>(
    writer: W,
    sample_rate_hz: u32,
    samples: &[i16],
) -> Result<(), WriteWavError> {
    check_rate(sample_rate_hz)?;
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: sample_rate_hz,
        bits_per_sample: 16,
        sample_format: hound::SampleFormat::Int,
    };
    let mut w = hound::WavWriter::new(writer, spec)?;
    for &s in samples {
        w.write_sample(s)?;
    }
    w.finalize()?;
    Ok(())
}

/// Writes mono 32-bit float.
pub fn write_wav_f32<W: Write + Seek>(
    writer: W,
    sample_rate_hz: u32,
    samples: &[f32],
) -> Result<(), WriteWavError> {
    check_rate(sample_rate_hz)?;
    let spec = hound::WavSpec {
        channels: 1,
        sample_rate: sample_rate_hz,
        bits_per_sample: 32,
        sample_format: hound::SampleFormat::Float,
    };
    let mut w = hound::WavWriter::new(writer, spec)?;
    for &s in samples {
        w.write_sample(s)?;
    }
    w.finalize()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    fn wav_bytes(rate: u32, samples: &[i16]) -> Vec<u8> {
        let mut c = Cursor::new(Vec::new());
        write_wav_i16(&mut c, rate, samples).unwrap();
        c.into_inner()
    }

    #[test]
    fn i16_and_f32_files_read_back() {
        let samples: Vec<i16> = (0..1000).map(|i| (i * 37 % 2000 - 1000) as i16).collect();
        let r = read_wav(Cursor::new(wav_bytes(16_000, &samples))).unwrap();
        assert_eq!(r.sample_rate_hz, 16_000);
        assert_eq!(r.samples.len(), 1000);
        assert!((r.samples[1] - 37.0 / 32768.0 + 1000.0 / 32768.0).abs() < 1e-6);
        let mut c = Cursor::new(Vec::new());
        write_wav_f32(&mut c, 48_000, &[0.25, -0.5]).unwrap();
        let r = read_wav(Cursor::new(c.into_inner())).unwrap();
        assert_eq!(r.samples, vec![0.25, -0.5]);
    }

    #[test]
    fn truncated_file_is_a_typed_error() {
        let bytes = wav_bytes(16_000, &[1000; 500]);
        // Cut in the middle of the data chunk (header is 44 bytes).
        let cut = &bytes[..44 + 301];
        match read_wav(Cursor::new(cut.to_vec())) {
            Err(ReadWavError::Truncated { samples_read }) => assert_eq!(samples_read, 150),
            other => panic!("expected Truncated, got {other:?}"),
        }
        // Cut inside the header.
        assert!(matches!(
            read_wav(Cursor::new(bytes[..20].to_vec())),
            Err(ReadWavError::Malformed(_) | ReadWavError::Truncated { .. } | ReadWavError::Io(_))
        ));
    }

    #[test]
    fn not_pcm_and_bad_rate_are_typed_errors() {
        let mut bytes = wav_bytes(16_000, &[0; 10]);
        // Format tag 7 = µ-law.
        bytes[20] = 7;
        assert!(
            matches!(
                read_wav(Cursor::new(bytes)),
                Err(ReadWavError::NotPcm(_) | ReadWavError::Malformed(_))
            ),
            "µ-law must be refused"
        );
        let bytes = {
            let mut c = Cursor::new(Vec::new());
            let spec = hound::WavSpec {
                channels: 1,
                sample_rate: 4_000,
                bits_per_sample: 16,
                sample_format: hound::SampleFormat::Int,
            };
            let mut w = hound::WavWriter::new(&mut c, spec).unwrap();
            w.write_sample(0i16).unwrap();
            w.finalize().unwrap();
            c.into_inner()
        };
        assert!(matches!(
            read_wav(Cursor::new(bytes)),
            Err(ReadWavError::UnsupportedRate(4_000))
        ));
        assert!(matches!(
            read_wav(Cursor::new(b"RIFF\0\0\0\0WAVEjunk".to_vec())),
            Err(ReadWavError::Malformed(_) | ReadWavError::Truncated { .. } | ReadWavError::Io(_))
        ));
    }
}
