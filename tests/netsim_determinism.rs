//! The harness is deterministic: one seed gives one run. Five robots on the
//! `competition` network write at 25 Hz, post talk messages and lose robot 2 for half a
//! second; from the seed alone, two runs end with identical blackboards (every binding of
//! every replica: value, owner, version, incarnation and the receiver-side stamp, which
//! depends on each frame's arrival time), identical event histories and the same netsim
//! trace hash. Another seed changes the losses and delays, hence the trace and the
//! receive stamps.

use std::collections::BTreeMap;
use std::time::Duration;

use comms::{Key, Pattern, ReplicaConfig, Value};
use huddle::harness::Harness;
use netsim::{Action, Preset, Sim, Time};

const ROBOTS: usize = 5;
const TICK: Duration = Duration::from_millis(40);
const END: Duration = Duration::from_secs(3);

fn at(d: Duration) -> Time {
    Time::from_nanos(d.as_nanos() as u64)
}

/// Every binding of one replica, as text: key → (value, owner, version, incarnation,
/// stamp in µs on that robot's clock).
type Board = BTreeMap<String, (Value, u8, u64, u64, u64)>;

struct Run {
    boards: Vec<Board>,
    events: Vec<Vec<String>>,
    trace_hash: u64,
    trace_events: u64,
}

fn run(seed: u64) -> Run {
    let net = Sim::builder().preset(Preset::Competition);
    let mut h = Harness::new(ROBOTS, net, ReplicaConfig::new(1, 7), seed).expect("a valid team");
    // Robot 3's clock is 5 s ahead and 100 ppm fast: skew must not break determinism.
    h.set_clock(2, Duration::from_secs(5), 100.0)
        .expect("valid clock");
    let two = h.node(1);
    h.net_mut()
        .at(at(Duration::from_millis(1000)), Action::Isolate(two))
        .expect("future");
    h.net_mut()
        .at(at(Duration::from_millis(1500)), Action::Rejoin(two))
        .expect("future");
    let pose = Key::parse("*.var.pose").expect("valid key");
    let mut events = vec![Vec::new(); ROBOTS];
    let mut t = Duration::ZERO;
    let mut tick = 0u32;
    while t < END {
        t += TICK;
        tick += 1;
        h.run_until(at(t));
        for (i, log) in events.iter_mut().enumerate() {
            log.extend(h.drain_events(i).map(|e| format!("{e:?}")));
            let v = Value::Floats(vec![i as f64, tick as f64]);
            h.set(i, &pose, v).expect("own key");
            if tick % 10 == i as u32 {
                let now = h.local_now(i);
                h.replica_mut(i)
                    .expect("alive")
                    .post(now, "*.talk.plan", Value::Int(i64::from(tick)))
                    .expect("own queue");
            }
        }
    }
    h.run_until(at(END + Duration::from_millis(500)));
    let all = Pattern::parse("#").expect("valid pattern");
    let boards = (0..ROBOTS)
        .map(|i| {
            let r = h.replica(i).expect("alive");
            r.iter(&all)
                .map(|(k, e)| {
                    let v = (
                        e.value.clone(),
                        e.owner,
                        e.version,
                        e.incarnation,
                        e.stamp.as_micros(),
                    );
                    (k.to_string(), v)
                })
                .collect()
        })
        .collect();
    for (i, log) in events.iter_mut().enumerate() {
        log.extend(h.drain_events(i).map(|e| format!("{e:?}")));
    }
    Run {
        boards,
        events,
        trace_hash: h.net().trace().hash(),
        trace_events: h.net().trace().event_count(),
    }
}

#[test]
fn the_same_seed_gives_the_same_blackboards_events_and_trace() {
    let (a, b) = (run(11), run(11));
    assert!(
        a.trace_events > 1000,
        "a busy run: {} trace events",
        a.trace_events
    );
    assert!(
        a.boards.iter().all(|board| board.len() > 5),
        "every robot holds the team's values"
    );
    assert_eq!(
        a.trace_hash, b.trace_hash,
        "seed 11 twice: trace hashes differ"
    );
    for i in 0..ROBOTS {
        assert_eq!(
            a.boards[i],
            b.boards[i],
            "seed 11 twice: robot {}'s blackboard differs",
            i + 1
        );
        assert_eq!(
            a.events[i],
            b.events[i],
            "seed 11 twice: robot {}'s events differ",
            i + 1
        );
    }
}

#[test]
fn another_seed_gives_another_run() {
    let (a, c) = (run(11), run(12));
    assert_ne!(
        a.trace_hash, c.trace_hash,
        "seeds 11 and 12: same trace hash"
    );
    // Compare only what the network decides: when each copy arrived (stamps of
    // teammates' values), not the incarnations, which are also drawn from the seed.
    let stamps = |r: &Run| -> Vec<Vec<(String, u64)>> {
        r.boards
            .iter()
            .enumerate()
            .map(|(i, board)| {
                board
                    .iter()
                    .filter(|(k, v)| v.1 != i as u8 + 1 && !k.starts_with("local."))
                    .map(|(k, v)| (k.clone(), v.4))
                    .collect()
            })
            .collect()
    };
    assert_ne!(
        stamps(&a),
        stamps(&c),
        "seeds 11 and 12: every copy arrived at the same instant"
    );
}
