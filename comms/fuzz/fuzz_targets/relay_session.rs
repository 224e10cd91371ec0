//! A relay session fed arbitrary client bytes, in arbitrary pieces, against a replica:
//! must never panic, never hold more unsent output than its limit plus one reply, and the
//! replica must keep working after whatever the client wrote through it.
#![no_main]

use comms::relay::{Session, SessionLimits};
use comms::{Instant, Replica, ReplicaConfig};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&piece, rest)) = data.split_first() else {
        return;
    };
    let limits = SessionLimits {
        max_line_bytes: 256,
        max_output_bytes: 4096,
        ..SessionLimits::default()
    };
    let mut replica =
        Replica::new(ReplicaConfig::new(1, 7), 1, Instant::ZERO).expect("valid config");
    let mut session = Session::new(1, limits);
    let piece = usize::from(piece).max(1);
    let mut now = Instant::from_micros(1_000);
    for chunk in rest.chunks(piece) {
        session.handle_input(now, chunk, &mut replica);
        // A client that reads now and then: every other chunk.
        if now.as_micros() % 2_000 == 0 {
            let n = session.pending_output().len();
            session.consume_output(n);
        }
        now = Instant::from_micros(now.as_micros() + 1_000);
        session.handle_timeout(now, &replica);
        replica.handle_timeout(now);
        while replica.poll_transmit().is_some() {}
        while replica.poll_event().is_some() {}
        if session.is_finished() {
            break;
        }
    }
});
