//! The cost of one `REFR` push of a narrow watch on a full blackboard: a relay client
//! watches `2.var.ball.#` (3 bindings) with `REFR 1` while the blackboard holds 65,536
//! bindings of other robots (the default limit of all teammates' bindings together, as a
//! flood of spoofed keys would leave it; the 3 watched ones were there first). The lookup goes by scope and literal path
//! prefix, so a push costs what it pushes, not the blackboard's size; `+.var.#` (every
//! binding) is measured beside it for scale. Prints the bindings each pattern visits.
//!
//! Run: `cargo bench -p comms --bench watch_snapshot -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;
use std::time::Duration;

use comms::relay::{Session, SessionLimits};
use comms::{Blackboard, Instant, Pattern, Value};
use criterion::{criterion_group, criterion_main, Criterion};

const OTHER_KEYS: usize = 65_536;

fn board() -> Blackboard {
    let mut bb = Blackboard::new(1);
    let t = Instant::ZERO;
    for path in ["ball", "ball.x", "ball.y"] {
        bb.apply_remote(2, 5, path.into(), Value::Float(1.0), 1, t);
    }
    for i in 0..OTHER_KEYS {
        // 16 robots × 4096 keys: the per-robot limit, and the total one (3 short).
        let owner = 3 + (i / 4096) as u8;
        bb.apply_remote(owner, 5, format!("spoof.k{i:06}"), Value::Int(0), 1, t);
    }
    assert_eq!(bb.len(), OTHER_KEYS, "the limit of all teammates' bindings");
    while bb.poll_change().is_some() {}
    bb
}

fn snapshot(c: &mut Criterion) {
    let mut bb = board();
    for p in ["2.var.ball.#", "+.var.ball.#", "+.var.#"] {
        let pattern = Pattern::parse(p).unwrap();
        println!(
            "{p}: {} bindings visited of {}",
            bb.visited(&pattern),
            bb.len()
        );
    }
    let mut group = c.benchmark_group("watch_snapshot");
    for p in ["2.var.ball.#", "+.var.#"] {
        let limits = SessionLimits {
            // Room for a snapshot of everything (`+.var.#`), read after each push.
            max_output_bytes: 64 << 20,
            ..SessionLimits::default()
        };
        let mut s = Session::new(1, limits);
        let cmd = format!("ADDW {p}\nREFR 1\n");
        s.handle_input(Instant::ZERO, cmd.as_bytes(), &mut bb);
        let mut now = Instant::ZERO;
        group.bench_function(p, |b| {
            b.iter(|| {
                now += Duration::from_millis(1);
                s.handle_timeout(now, &bb);
                let n = s.pending_output().len();
                black_box(n);
                s.consume_output(n);
            })
        });
    }
    group.finish();
}

criterion_group!(benches, snapshot);
criterion_main!(benches);
