//! RGme (GameController → robots) on arbitrary bytes: the decoder and a tracker must
//! never panic; whatever decodes re-encodes to the very same bytes (nothing misread); a
//! packet the tracker refuses changes nothing it held.
#![no_main]

use std::net::SocketAddr;
use std::time::Duration;

use gamecontroller::{GameControlData, GameTracker};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(d) = GameControlData::decode(data) {
        assert_eq!(
            &d.encode()[..],
            data,
            "a decoded packet re-encodes to its bytes"
        );
    }
    // A tracker holding a valid packet of team 12's game, then the fuzzed one.
    let from = SocketAddr::from(([10, 0, 0, 1], 3838));
    let mut tracker = GameTracker::new(12, 3);
    let mut game = GameControlData::new([12, 34]);
    game.packet_number = 100;
    tracker
        .receive(Duration::from_secs(1), from, &game.encode())
        .expect("a valid packet");
    let before = *tracker.game().expect("held");
    let stats = tracker.stats();
    match tracker.receive(Duration::from_millis(1_500), from, data) {
        Ok(gamecontroller::Received::Accepted) => {
            let after = tracker.game().expect("held");
            assert_eq!(&after.encode()[..], data);
        }
        Ok(gamecontroller::Received::Stale) | Err(_) => {
            assert_eq!(
                tracker.game(),
                Some(&before),
                "a refused packet changes nothing"
            );
            assert_eq!(tracker.stats().accepted, stats.accepted);
        }
    }
    let _ = tracker.message_budget();
    let _ = tracker.penalized();
});
