//! A fresh incarnation number for each start of a replica, from the OS's random source.

/// A random 64-bit incarnation. The OS's generator is the source; should it fail (it does
/// not on Linux after early boot), the wall clock and process id still make two starts
/// of one robot differ, which is all an incarnation has to do.
pub(crate) fn random_incarnation() -> u64 {
    getrandom::u64().unwrap_or_else(|_| fallback())
}

#[allow(clippy::disallowed_methods)] // the I/O shell: a seed from the outside world
fn fallback() -> u64 {
    let wall = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or_default();
    wall ^ (u64::from(std::process::id()) << 32)
}

#[cfg(test)]
mod tests {
    #[test]
    fn two_starts_get_different_incarnations() {
        assert_ne!(super::random_incarnation(), super::random_incarnation());
    }
}
