//! A mixed-version team's talk: a newer build posts a message whose value has a tag this
//! build does not know. The rule (`comms::wire`, "The compatibility promise"): this build
//! acknowledges the message (no NACK, the sender stops re-sending, the queue's order moves
//! on), counts it in `talk_unknown_value`, and hands it up as `TalkGivenUp` for that one
//! seq: never retried for ever, never delivered as another value. Before, the message was
//! skipped as an unknown item, NACKed 18 times, held the next one ~1 s and ended as a
//! `TalkGivenUp` after the give-up timer (docs/review-30-34.md, finding 5).

use std::net::SocketAddr;

use comms::{Event, Instant, Replica, ReplicaConfig, Value};

/// The same golden frame as `wire/tests.rs` `GOLDEN_FUTURE_TALK`: robot 3 of team 7,
/// queue `plan`, messages 1 (`Int(5)`), 2 (value tag 6) and 3 (`Int(7)`).
const GOLDEN_FUTURE_TALK: &str = include_str!("golden/future_talk.hex");

fn hex_bytes(hex: &str) -> Vec<u8> {
    (0..hex.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&hex[i..i + 2], 16).expect("hex"))
        .collect()
}

fn at_ms(ms: u64) -> Instant {
    Instant::from_micros(1_000_000 + ms * 1000)
}

#[test]
fn an_unknown_talk_value_is_acknowledged_counted_and_handed_up_as_skipped() {
    // Robot 2 of this build, seed 22; the frame comes from robot 3 of a newer build.
    let mut b = Replica::new(ReplicaConfig::new(2, 7), 22, at_ms(0)).expect("robot 2 starts");
    let from = SocketAddr::from(([127, 0, 0, 1], 2003));
    b.handle_datagram(at_ms(10), from, &hex_bytes(GOLDEN_FUTURE_TALK.trim()));
    let mut talk = Vec::new();
    let mut buf = Vec::new();
    // Three seconds of timers: a NACK or a give-up timer would show here.
    for ms in (10..3000).step_by(10) {
        b.handle_timeout(at_ms(ms));
        while b.poll_transmit_into(&mut buf).is_some() {}
        while let Some(e) = b.poll_event() {
            match e {
                Event::TalkDelivered {
                    queue,
                    from,
                    seq,
                    value,
                } => talk.push((queue, from, seq, Some(value))),
                Event::TalkGivenUp {
                    queue,
                    from,
                    first,
                    last,
                } => {
                    assert_eq!(first, last, "one message skipped, not a range");
                    talk.push((queue, from, first, None));
                }
                _ => {}
            }
        }
    }
    let plan = |seq, value| ("plan".to_string(), 3u8, seq, value);
    assert_eq!(
        talk,
        [
            plan(1, Some(Value::Int(5))),
            plan(2, None),
            plan(3, Some(Value::Int(7)))
        ],
        "in order: 1 delivered, 2 handed up as skipped, 3 delivered without a hold"
    );
    let s = b.stats();
    assert_eq!(s.talk_unknown_value, 1, "counted: {s:?}");
    assert_eq!(s.nacks_sent, 0, "acknowledged, so never NACKed: {s:?}");
    assert_eq!(s.talk_given_up, 0, "nothing was lost: {s:?}");
    assert_eq!(s.items_skipped, 0, "read, not skipped as unknown: {s:?}");
    assert_eq!(s.talk_delivered, 2, "{s:?}");
}
