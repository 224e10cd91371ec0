//! A fresh incarnation number for each start of a replica. Incarnations are ordered: a
//! later start of a robot has a larger one, so a teammate tells a restart from a replayed
//! or stray frame of an earlier life without having heard every life in between.

/// The start time in milliseconds since the Unix epoch in the high 48 bits and 16 random
/// bits below (two starts in one millisecond still differ). A robot's clock must not go
/// back between two of its starts: without a team key, a robot whose clock did (no RTC,
/// no NTP yet) is heard again once its previous life has been silent for the departure
/// limit; with a key, teammates that heard its previous life refuse the "older" one, as
/// they would a replay. Set the time before the daemon starts.
pub fn new_incarnation() -> u64 {
    let random = getrandom::u64().unwrap_or_else(|_| u64::from(std::process::id()));
    comms::ordered_incarnation(unix_millis(), random)
}

#[allow(clippy::disallowed_methods)] // the I/O shell: the start time comes from the world
fn unix_millis() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as u64)
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_later_start_has_a_larger_incarnation_whatever_the_random_bits() {
        let at = comms::ordered_incarnation;
        assert!(at(1_000_001, 0) > at(1_000_000, u64::MAX));
        assert_ne!(new_incarnation(), 0);
        let (a, b) = (new_incarnation(), new_incarnation());
        assert_ne!(a, b, "two starts differ");
    }
}
