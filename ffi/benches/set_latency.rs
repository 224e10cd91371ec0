//! `huddle_node_set` → teammate-visible latency against the Rust driver's
//! `Handle::set`, measured in one process run on one loopback group.
//!
//! The teammate is a `driver::Driver` on its own thread with a watch on both senders'
//! key: the moment its watch runs is "visible". Sender A is a Rust `Driver` whose own
//! task calls `Handle::set`; sender B is a huddle node driven through the C API from a
//! plain thread, as a C++ program would. Samples alternate, one at a time, and the
//! report gives the median and 90th percentile of each and the ratio of the medians.
//!
//! `cargo bench -p huddle-ffi --bench set_latency` (`-- 2000` for more samples).
#![allow(clippy::disallowed_methods)] // a real-time benchmark reads the clock

use std::ffi::CString;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use comms::{ReplicaConfig, Value};
use driver::{Driver, DriverConfig, Notice};
use huddle::*;

fn driver_config(id: u8, group: std::net::SocketAddrV4) -> DriverConfig {
    let mut cfg = DriverConfig::new(ReplicaConfig::new(id, 0));
    cfg.socket.group = group;
    cfg
}

/// Runs `f` on a new thread inside a current-thread runtime and LocalSet.
fn spawn_local_thread<F, Fut>(f: F) -> std::thread::JoinHandle<()>
where
    F: FnOnce() -> Fut + Send + 'static,
    Fut: std::future::Future<Output = ()> + 'static,
{
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .expect("runtime");
        tokio::task::LocalSet::new().block_on(&rt, f());
    })
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn main() {
    let samples: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(500);
    let group = driver::scratch_group().expect("scratch group");

    // The teammate (robot 2): reports (owner, value, when its watch ran).
    let (seen_tx, seen_rx) = mpsc::channel::<(u8, i64, Instant)>();
    let (stop_observer, observer_stop) = tokio::sync::oneshot::channel::<()>();
    let (observer_ready, ready) = mpsc::channel();
    let observer = spawn_local_thread(move || async move {
        let driver = Driver::bind(driver_config(2, group)).expect("bind robot 2");
        let _watch = driver
            .handle()
            .watch("+.var.bench.x", move |_, notice| {
                let at = Instant::now();
                if let Notice::Changed { entry, .. } = notice {
                    if let Value::Int(v) = entry.value {
                        let _ = seen_tx.send((entry.owner, v, at));
                    }
                }
            })
            .expect("pattern");
        observer_ready.send(()).expect("main waits");
        let _ = driver
            .run(async {
                let _ = observer_stop.await;
            })
            .await;
    });
    ready.recv().expect("observer up");

    // Sender A (robot 1): the Rust driver; on request i, its task sets the value and
    // says when the call started.
    let (go_tx, mut go_rx) = tokio::sync::mpsc::unbounded_channel::<i64>();
    let (started_tx, started_rx) = mpsc::channel::<Instant>();
    let rust_sender = spawn_local_thread(move || async move {
        let driver = Driver::bind(driver_config(1, group)).expect("bind robot 1");
        let handle = driver.handle();
        let run = tokio::task::spawn_local(driver.run(std::future::pending()));
        while let Some(i) = go_rx.recv().await {
            let t0 = Instant::now();
            handle.set("*.var.bench.x", i).expect("own key");
            started_tx.send(t0).expect("main waits");
        }
        run.abort();
    });

    // Sender B (robot 3): a huddle node through the C API.
    let group_ip = CString::new(group.ip().to_string()).expect("no NUL");
    let iface = CString::new("127.0.0.1").expect("no NUL");
    // SAFETY: all-zero is a valid huddle_node_config and huddle_error (NULL strings).
    let mut cfg: huddle_node_config = unsafe { std::mem::zeroed() };
    cfg.robot_id = 3;
    cfg.group_address = group_ip.as_ptr();
    cfg.group_port = group.port();
    cfg.interface_address = iface.as_ptr();
    // SAFETY: as above.
    let mut err: huddle_error = unsafe { std::mem::zeroed() };
    // SAFETY: a valid config whose strings outlive the call; a writable error.
    let node = unsafe { huddle_node_start(&cfg, &mut err) };
    assert!(!node.is_null(), "node start failed");
    let key = CString::new("*.var.bench.x").expect("no NUL");

    let wait_seen = |owner: u8, value: i64| -> Instant {
        loop {
            let (o, v, at) = seen_rx
                .recv_timeout(Duration::from_secs(2))
                .expect("the teammate sees every value");
            if (o, v) == (owner, value) {
                return at;
            }
        }
    };
    let mut rust_us = Vec::with_capacity(samples);
    let mut ffi_us = Vec::with_capacity(samples);
    let warmup = 50;
    for i in 0..(samples + warmup) as i64 {
        // Rust driver.
        go_tx.send(i).expect("sender A runs");
        let t0 = started_rx.recv().expect("sender A answers");
        let at = wait_seen(1, i);
        let rust = at.duration_since(t0).as_secs_f64() * 1e6;
        std::thread::sleep(Duration::from_millis(1));
        // C API.
        let literal = CString::new(i.to_string()).expect("no NUL");
        let t0 = Instant::now();
        // SAFETY: a live node, NUL-terminated strings, a writable error.
        let rc = unsafe { huddle_node_set(node, key.as_ptr(), literal.as_ptr(), &mut err) };
        assert_eq!(rc, 0, "set failed");
        let at = wait_seen(3, i);
        let ffi = at.duration_since(t0).as_secs_f64() * 1e6;
        std::thread::sleep(Duration::from_millis(1));
        if i >= warmup as i64 {
            rust_us.push(rust);
            ffi_us.push(ffi);
        }
    }
    huddle_node_stop(node);
    drop(go_tx);
    rust_sender.join().expect("sender A ends");
    let _ = stop_observer.send(());
    observer.join().expect("observer ends");

    rust_us.sort_by(f64::total_cmp);
    ffi_us.sort_by(f64::total_cmp);
    let (r50, f50) = (percentile(&rust_us, 0.5), percentile(&ffi_us, 0.5));
    println!("set -> teammate-visible latency, {samples} samples each, loopback multicast");
    println!(
        "  Rust driver (Handle::set on the driver task): median {r50:7.1} us  p90 {:7.1} us",
        percentile(&rust_us, 0.9)
    );
    println!(
        "  C API (huddle_node_set from another thread):  median {f50:7.1} us  p90 {:7.1} us",
        percentile(&ffi_us, 0.9)
    );
    println!("  ratio of medians (C API / Rust): {:.2}", f50 / r50);
}
