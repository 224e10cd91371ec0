//! Frame decoding and the replica's datagram path on arbitrary bytes: must never panic,
//! and whatever decodes must re-encode to canonical bytes that decode and re-encode to
//! the same bytes (compared as bytes, so NaN payloads compare equal to themselves).
#![no_main]

use std::net::SocketAddr;

use comms::wire::{
    decode_frame, decode_frame_into, decode_frame_with, encode_frame, KnownPaths, TeamKey,
};
use comms::{Instant, Replica, ReplicaConfig};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let team = data.get(4).copied().unwrap_or(7);
    if let Ok(frame) = decode_frame(data, team, None) {
        let canonical = encode_frame(&frame, None);
        let again = decode_frame(&canonical, team, None).expect("canonical bytes decode");
        assert_eq!(encode_frame(&again, None), canonical, "encoding is stable");
    }
    // With a table of known paths (format 3 and 4 item 4): the borrowed view, walked
    // twice (validation, then the items) must agree with itself and with the one-pass
    // read the replica uses.
    let known = KnownPaths::new(["machine.heuristic", "world.local"]).expect("valid");
    let mut items = Vec::new();
    let one_pass = decode_frame_into(data, team, None, &known, &mut items);
    match decode_frame_with(data, team, None, &known) {
        Ok(frame) => {
            let owned = frame.to_frame();
            assert_eq!(owned.items.len(), frame.items().count(), "items are stable");
            assert!(one_pass.is_ok(), "one pass accepts what two passes accept");
            assert!(frame.items().eq(items.iter().copied()), "the same items");
        }
        Err(e) => {
            assert_eq!(one_pass.err(), Some(e), "the same error");
            assert!(items.is_empty(), "nothing handed out of a malformed frame");
        }
    }
    let key = TeamKey::new(b"fuzz");
    let _ = decode_frame(data, team, Some(&key));

    let mut replica =
        Replica::new(ReplicaConfig::new(1, team), 1, Instant::ZERO).expect("valid config");
    let from = SocketAddr::from(([127, 0, 0, 1], 2000));
    replica.handle_datagram(Instant::from_micros(1_000), from, data);
    replica.handle_timeout(Instant::from_micros(2_000_000));
    while replica.poll_transmit().is_some() {}
    while replica.poll_event().is_some() {}
});
