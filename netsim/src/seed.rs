//! Random streams: one master seed, one independent ChaCha stream per link.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// What a stream randomises; part of the stream number, so streams never collide.
#[derive(Clone, Copy, Debug)]
#[repr(u8)]
pub(crate) enum Domain {
    /// A standalone [`crate::LinkModel`] built from a bare seed.
    Standalone = 1,
    /// The one-way link `a → b`.
    Link = 2,
    /// The shared uplink of sender `a`.
    Uplink = 3,
}

/// The ChaCha8 generator for `(seed, domain, a, b)`.
///
/// The key comes from the master seed alone and the stream number from what the stream
/// is for, so each link draws from its own stream: how many numbers one link consumes
/// (or how it is retuned) never shifts what another link sees.
pub(crate) fn stream(seed: u64, domain: Domain, a: u16, b: u16) -> ChaCha8Rng {
    let mut key = [0u8; 32];
    let mut state = seed;
    for chunk in key.chunks_exact_mut(8) {
        chunk.copy_from_slice(&splitmix64(&mut state).to_le_bytes());
    }
    let mut rng = ChaCha8Rng::from_seed(key);
    rng.set_stream((domain as u64) << 32 | u64::from(a) << 16 | u64::from(b));
    rng
}

/// SplitMix64 (Steele, Lea, Flood 2014): spreads a small seed over a full key.
fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn streams_differ_by_link_and_seed_and_repeat_for_the_same_inputs() {
        let first = |seed, d, a, b| stream(seed, d, a, b).next_u64();
        assert_eq!(first(7, Domain::Link, 1, 2), first(7, Domain::Link, 1, 2));
        assert_ne!(first(7, Domain::Link, 1, 2), first(7, Domain::Link, 2, 1));
        assert_ne!(first(7, Domain::Link, 1, 2), first(8, Domain::Link, 1, 2));
        assert_ne!(first(7, Domain::Link, 1, 2), first(7, Domain::Uplink, 1, 2));
    }
}
