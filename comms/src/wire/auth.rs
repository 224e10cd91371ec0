//! The team key: a truncated HMAC-SHA256 tag over everything before it, so teammates
//! drop frames from outside the team, altered frames and (with the replica's replay
//! window) replayed ones.

use hmac::{Hmac, KeyInit, Mac};
use sha2::Sha256;

use super::TAG_LEN;

/// A team key, ready to tag and check frames.
#[derive(Clone)]
pub struct TeamKey(Hmac<Sha256>);

impl TeamKey {
    /// Prepares HMAC-SHA256 with `key` (any length; 32 random bytes recommended).
    pub fn new(key: &[u8]) -> TeamKey {
        // HMAC accepts keys of every length (long ones are hashed), so this cannot fail.
        TeamKey(Hmac::<Sha256>::new_from_slice(key).expect("HMAC takes keys of any length"))
    }

    /// The frame tag over `data` (everything before the tag): for tools and tests that
    /// build frames by hand.
    pub fn tag(&self, data: &[u8]) -> [u8; TAG_LEN] {
        let mut mac = self.0.clone();
        mac.update(data);
        let full = mac.finalize().into_bytes();
        let mut tag = [0u8; TAG_LEN];
        tag.copy_from_slice(&full[..TAG_LEN]);
        tag
    }

    pub(super) fn verify(&self, data: &[u8], tag: &[u8]) -> bool {
        let mut mac = self.0.clone();
        mac.update(data);
        // Constant-time comparison of the leftmost TAG_LEN bytes.
        mac.verify_truncated_left(tag).is_ok()
    }
}

impl std::fmt::Debug for TeamKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("TeamKey(..)")
    }
}
