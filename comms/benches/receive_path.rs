//! The per-update cost of the sustained A → B run of `huddle bench comms`, without
//! sockets: robot A writes 1,000 global keys per batch and packs them into MTU frames;
//! every frame is fed back to A (multicast loop: its own frame, to be ignored) and to B
//! (decode, apply, change event); both drain their events as the driver does.
//!
//! A plain `main` with a fixed amount of work, so that `valgrind --tool=callgrind` gives
//! repeatable instruction counts on a noisy shared machine:
//!
//! ```text
//! cargo bench -p comms --bench receive_path                      # wall time per update
//! valgrind --tool=callgrind target/release/deps/receive_path-* --rounds 20
//! ```
//!
//! Reports nanoseconds per update for each of the three parts (send on A, own loopback on
//! A, receive on B) and the updates/s one core would sustain for B alone.

use std::hint::black_box;
use std::net::SocketAddr;
use std::time::Duration;

use comms::{Event, Instant, Replica, ReplicaConfig, Value};

const KEYS: usize = 1000;

struct Parts {
    send: Duration,
    own: Duration,
    receive: Duration,
    updates: u64,
}

#[allow(clippy::disallowed_methods)] // a bench measures time; the library never does
fn clock() -> std::time::Instant {
    std::time::Instant::now()
}

fn drain(r: &mut Replica) {
    while let Some(e) = r.poll_event() {
        // The driver reads the changed binding to hand it to subscribers.
        if let Event::ValueChanged { key } = &e {
            black_box(r.blackboard().get(key));
        }
        black_box(e);
    }
}

fn run(rounds: u64, keyed: bool) -> Parts {
    let from = SocketAddr::from(([127, 0, 0, 1], 2000));
    let cfg = |id| {
        let c = ReplicaConfig::new(id, 0).with_refresh_period(Duration::from_secs(5));
        if keyed {
            c.with_team_key(*b"team key for the bench, 32 bytes")
        } else {
            c
        }
    };
    let mut a = Replica::new(cfg(1), 0xA, Instant::ZERO).expect("valid config");
    let mut b = Replica::new(cfg(2), 0xB, Instant::ZERO).expect("valid config");
    let keys: Vec<String> = (0..KEYS).map(|k| format!("*.var.bench.k{k}")).collect();
    let (mut send, mut own, mut receive) = (Duration::ZERO, Duration::ZERO, Duration::ZERO);
    let mut frames = Vec::new();
    let mut updates = 0u64;
    for round in 0..rounds {
        let now = Instant::from_micros(1000 + round * 2000);
        let t0 = clock();
        for key in &keys {
            a.set(now, key, Value::Int(updates as i64))
                .expect("a valid global key");
            updates += 1;
        }
        frames.clear();
        while let Some(t) = a.poll_transmit() {
            frames.push(t.payload);
        }
        drain(&mut a);
        let t1 = clock();
        for f in &frames {
            a.handle_datagram(now, from, f);
        }
        drain(&mut a);
        let t2 = clock();
        for f in &frames {
            b.handle_datagram(now, from, f);
        }
        drain(&mut b);
        let t3 = clock();
        send += t1 - t0;
        own += t2 - t1;
        receive += t3 - t2;
    }
    let s = b.stats();
    assert_eq!(s.drops_total(), 0, "the bench must apply, not drop");
    assert_eq!(s.updates_applied, updates, "B applies every update");
    assert_eq!(a.stats().own_frames, a.stats().frames_out);
    Parts {
        send,
        own,
        receive,
        updates,
    }
}

fn main() {
    let mut rounds = 400u64;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        if arg == "--rounds" {
            rounds = args
                .next()
                .and_then(|v| v.parse().ok())
                .expect("--rounds N");
        }
        // cargo bench passes `--bench`; anything else is ignored.
    }
    for keyed in [false, true] {
        let p = run(rounds, keyed);
        let per = |d: Duration| d.as_nanos() as f64 / p.updates as f64;
        println!(
            "{:<9} {} updates: send on A {:6.1} ns/update, own loopback on A {:6.1} ns/update, receive on B {:6.1} ns/update ({:.0} updates/s on one core)",
            if keyed { "hmac" } else { "no key" },
            p.updates,
            per(p.send),
            per(p.own),
            per(p.receive),
            1e9 / per(p.receive),
        );
    }
}
