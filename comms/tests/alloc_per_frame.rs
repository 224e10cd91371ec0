//! The transmit and receive paths allocate nothing per frame in steady state (#30 item 2).
//!
//! Its own test binary: a counting `#[global_allocator]` (per thread) around each step of
//! robot 1 writing values and robot 2 receiving them, after a warm-up (every key already
//! held, the scratch buffers grown). What it pins:
//!
//! - `poll_transmit_into` into a kept buffer: 0 allocations per frame (the path the
//!   daemon's `Driver`, the Rust `Session`, the C node and the netsim harness use);
//! - `handle_datagram` and draining `poll_event` for scalar values (float, int, bool): 0;
//! - receiving a `Bytes` value: at most 1 per frame (the received bytes are stored as a
//!   fresh `Vec`: documented, not a regression);
//! - `poll_transmit` (the allocating convenience kept for the C replica API): exactly 1
//!   per frame, its payload `Vec`. The test checks the counter sees that one, so a
//!   counter that counts nothing cannot pass the zero assertions.
//!
//! Reproduced by the review's probe `docs/review-30-34/alloc_per_frame.rs`.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::net::SocketAddr;

use comms::wire::KnownPaths;
use comms::{Instant, Replica, ReplicaConfig, Value};

struct Counting;

thread_local! {
    static ALLOCS: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: every call is forwarded to `System` unchanged; the counter is a thread-local
// `Cell` with a const initialiser (no allocation, no destructor).
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded as is.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded as is.
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded as is.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocs() -> u64 {
    ALLOCS.with(|c| c.get())
}

fn at_ms(ms: u64) -> Instant {
    Instant::from_micros(1_000_000 + ms * 1000)
}

fn config(id: u8) -> ReplicaConfig {
    let known = KnownPaths::new(["machine.heuristic", "world.local"]).expect("valid");
    ReplicaConfig::new(id, 7).with_known_paths(known)
}

/// Which transmit call the sender drains with.
#[derive(Clone, Copy, PartialEq)]
enum Drain {
    /// `poll_transmit_into` into one kept buffer.
    Into,
    /// `poll_transmit`, a fresh `Vec` per frame.
    Alloc,
}

/// Allocations counted after the warm-up, per step kind.
#[derive(Default, Debug)]
struct Tally {
    frames: u64,
    transmit: u64,
    receive: u64,
    events: u64,
}

type Values = dyn Fn(u64) -> Vec<(&'static str, Value)>;

/// Robot 1 (seed 11) writes `values(step)` every 5 ms for 1200 steps and robot 2
/// (seed 22) receives every frame; allocations are counted from step 200 on.
fn run(values: &Values, drain: Drain) -> Tally {
    let from = SocketAddr::from(([127, 0, 0, 1], 2000));
    let mut a = Replica::new(config(1), 11, at_ms(0)).expect("robot 1 starts");
    let mut b = Replica::new(config(2), 22, at_ms(0)).expect("robot 2 starts");
    let mut buf = Vec::with_capacity(2048);
    let mut other = Vec::with_capacity(2048);
    let mut frames: Vec<Vec<u8>> = Vec::with_capacity(16);
    let mut t = Tally::default();
    let (warm, steps) = (200u64, 1200u64);
    for step in 0..steps {
        let now = at_ms(step * 5);
        for (k, v) in values(step) {
            a.set(now, k, v).expect("a valid write");
        }
        a.handle_timeout(now);
        b.handle_timeout(now);
        frames.clear();
        let mut transmit = 0;
        loop {
            let before = allocs();
            let got = match drain {
                Drain::Into => a.poll_transmit_into(&mut buf).map(|_| None),
                Drain::Alloc => a.poll_transmit().map(|tx| Some(tx.payload)),
            };
            transmit += allocs() - before;
            match got {
                None => break,
                Some(None) => frames.push(buf.clone()),
                Some(Some(payload)) => frames.push(payload),
            }
        }
        while b.poll_transmit_into(&mut other).is_some() {}
        let (mut receive, mut events) = (0, 0);
        for f in &frames {
            let before = allocs();
            b.handle_datagram(now, from, f);
            receive += allocs() - before;
            let before = allocs();
            while b.poll_event().is_some() {}
            events += allocs() - before;
        }
        while a.poll_event().is_some() {}
        if step >= warm {
            t.frames += frames.len() as u64;
            t.transmit += transmit;
            t.receive += receive;
            t.events += events;
        }
    }
    t
}

fn scalars(step: u64) -> Vec<(&'static str, Value)> {
    vec![
        ("*.var.machine.heuristic", Value::Float(step as f64 * 0.5)),
        ("*.var.pose.x", Value::Int(step as i64)),
        ("*.var.ball.seen", Value::Bool(step.is_multiple_of(2))),
    ]
}

fn scalars_and_bytes(step: u64) -> Vec<(&'static str, Value)> {
    let mut v = scalars(step);
    v.push(("*.var.world.local", Value::Bytes(vec![step as u8; 75])));
    v
}

#[test]
fn sending_and_receiving_scalars_allocates_nothing_per_frame() {
    let t = run(&scalars, Drain::Into);
    assert!(t.frames > 500, "frames went out: {t:?}");
    assert_eq!(
        t.transmit, 0,
        "poll_transmit_into into a kept buffer allocates nothing per frame: {t:?}"
    );
    assert_eq!(
        t.receive, 0,
        "handle_datagram of float/int/bool values allocates nothing per frame: {t:?}"
    );
    assert_eq!(
        t.events, 0,
        "draining poll_event after a scalar frame allocates nothing: {t:?}"
    );
}

#[test]
fn a_bytes_value_costs_at_most_one_allocation_on_receipt_and_none_on_transmit() {
    let t = run(&scalars_and_bytes, Drain::Into);
    assert!(t.frames > 500, "frames went out: {t:?}");
    assert_eq!(
        t.transmit, 0,
        "poll_transmit_into allocates nothing per frame, Bytes or not: {t:?}"
    );
    assert!(
        t.receive + t.events <= t.frames,
        "a received Bytes value is stored as one fresh Vec, nothing more: {t:?}"
    );
}

#[test]
fn the_counter_sees_the_allocating_convenience() {
    // Guards the zero assertions above: the counter does count, and `poll_transmit`
    // (kept for the C replica API) is the one-`Vec`-per-frame path drivers must not use.
    let t = run(&scalars, Drain::Alloc);
    assert!(t.frames > 500, "frames went out: {t:?}");
    assert_eq!(
        t.transmit, t.frames,
        "poll_transmit allocates exactly its payload Vec per frame: {t:?}"
    );
}
