//! Review evidence for #30 item 2 ("the transmit and receive paths without per-frame
//! allocation"): a counting global allocator (per thread) around each step of a replica
//! sending and receiving frames in steady state (every key already held, the scratch
//! buffers warmed up). Prints the allocations per frame of each step and asserts the
//! ones the code documents as allocation-free.

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

#[derive(Default, Debug)]
struct Tally {
    frames: u64,
    set: u64,
    transmit_into: u64,
    transmit_alloc: u64,
    receive: u64,
    events: u64,
}

/// Runs `steps` steps of robot 1 writing `values` and robot 2 receiving, counting the
/// allocations of each step after `warm` warm-up steps.
fn run(values: &dyn Fn(u64) -> Vec<(&'static str, Value)>, use_into: bool) -> Tally {
    let from = SocketAddr::from(([127, 0, 0, 1], 2000));
    let mut a = Replica::new(config(1), 11, at_ms(0)).unwrap();
    let mut b = Replica::new(config(2), 22, at_ms(0)).unwrap();
    let mut buf = Vec::with_capacity(2048);
    let mut t = Tally::default();
    let (warm, steps) = (200u64, 1200u64);
    for step in 0..steps {
        let now = at_ms(step * 5);
        let vals = values(step); // built outside the counted steps
        let counting = step >= warm;
        let c0 = allocs();
        for (k, v) in vals {
            a.set(now, k, v).unwrap();
        }
        a.handle_timeout(now);
        b.handle_timeout(now);
        let c1 = allocs();
        let mut frames: Vec<Vec<u8>> = Vec::new();
        let mut into_allocs = 0;
        let mut alloc_allocs = 0;
        loop {
            let before = allocs();
            if use_into {
                if a.poll_transmit_into(&mut buf).is_none() {
                    break;
                }
                into_allocs += allocs() - before;
                frames.push(buf.clone());
            } else {
                let Some(tx) = a.poll_transmit() else { break };
                alloc_allocs += allocs() - before;
                frames.push(tx.payload);
            }
        }
        while b.poll_transmit_into(&mut buf).is_some() {}
        let mut recv = 0;
        let mut ev = 0;
        for f in &frames {
            let before = allocs();
            b.handle_datagram(now, from, f);
            recv += allocs() - before;
            let before = allocs();
            while b.poll_event().is_some() {}
            ev += allocs() - before;
        }
        while a.poll_event().is_some() {}
        if counting {
            t.frames += frames.len() as u64;
            t.set += c1 - c0;
            t.transmit_into += into_allocs;
            t.transmit_alloc += alloc_allocs;
            t.receive += recv;
            t.events += ev;
        }
    }
    t
}

fn per_frame(n: u64, frames: u64) -> f64 {
    n as f64 / frames.max(1) as f64
}

#[test]
fn review_allocations_per_frame_in_steady_state() {
    let scalars = |step: u64| {
        vec![
            ("*.var.machine.heuristic", Value::Float(step as f64 * 0.5)),
            ("*.var.pose.x", Value::Int(step as i64)),
            ("*.var.ball.seen", Value::Bool(step % 2 == 0)),
        ]
    };
    let with_bytes = |step: u64| {
        let mut v = scalars(step);
        v.push(("*.var.world.local", Value::Bytes(vec![step as u8; 75])));
        v
    };
    for (name, f) in [
        (
            "scalars (float, int, bool; a known path)",
            &scalars as &dyn Fn(u64) -> _,
        ),
        ("scalars + a 75-byte world model (Bytes)", &with_bytes),
    ] {
        let into = run(f, true);
        let alloc = run(f, false);
        println!(
            "{name}: {} frames; per frame: set+timers {:.2}, poll_transmit_into {:.2}, \
             poll_transmit {:.2}, handle_datagram {:.2}, poll_event drain {:.2}",
            into.frames,
            per_frame(into.set, into.frames),
            per_frame(into.transmit_into, into.frames),
            per_frame(alloc.transmit_alloc, alloc.frames),
            per_frame(into.receive, into.frames),
            per_frame(into.events, into.frames),
        );
        assert!(
            into.frames > 500,
            "{name}: frames went out ({})",
            into.frames
        );
        assert_eq!(
            into.transmit_into, 0,
            "{name}: poll_transmit_into into a kept buffer allocates nothing per frame"
        );
    }
}
