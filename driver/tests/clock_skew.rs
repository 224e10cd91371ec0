//! A driver whose clock is skewed on purpose (`DriverConfig::clock_skew`, the daemon's
//! `--clock-offset` / `--clock-drift-ppm`): two robots on a scratch group on loopback,
//! robot 1's clock reading 20 s at its start and gaining 300 ppm (ten times the drawn
//! world's σ), robot 2's the machine's.
//! Values still replicate both ways, each robot ages its teammate's values on its own
//! clock as truly as it ages its own, and robot 2's estimate of robot 1's clock finds the
//! offset. (How the estimate fits a drift over its 64 s window is comms' own test.) This is what `huddle sim --daemons` relies on to give each daemon
//! the clock its robot draws in process.

#![allow(clippy::disallowed_methods)] // real drivers over loopback, real time

use std::time::Duration;

use comms::{Instant, ReplicaConfig};
use driver::{ClockSkew, Driver, DriverConfig, Handle};

mod support;
use support::{run_local, wait_for};

const OFFSET: Duration = Duration::from_secs(20);
const DRIFT_PPM: f64 = 300.0;

fn config(id: u8, group: std::net::SocketAddrV4, skew: ClockSkew) -> DriverConfig {
    let mut cfg = DriverConfig::new(ReplicaConfig::new(id, 0));
    cfg.socket.group = group;
    cfg.clock_skew = skew;
    cfg
}

/// The age `handle` gives `key` now, on its own clock.
fn age(handle: &Handle, key: &str) -> Duration {
    let entry = handle.get(key).unwrap().expect("replicated");
    entry.age(handle.now())
}

fn us(t: Instant) -> i64 {
    i64::try_from(t.as_micros()).unwrap()
}

#[test]
fn a_skewed_robot_replicates_and_its_teammates_age_its_values_right() {
    run_local(async {
        let group = driver::scratch_group().unwrap();
        let skewed =
            Driver::bind(config(1, group, ClockSkew::new(OFFSET, DRIFT_PPM).unwrap())).unwrap();
        let plain = Driver::bind(config(2, group, ClockSkew::NONE)).unwrap();
        let (one, two) = (skewed.handle(), plain.handle());
        assert!(
            one.now().as_micros() >= 20_000_000,
            "robot 1's clock reads its offset: {:?}",
            one.now()
        );
        let mut heard_by_two = two.subscribe("1.var.x").unwrap();
        let mut heard_by_one = one.subscribe("2.var.y").unwrap();
        tokio::task::spawn_local(skewed.run(std::future::pending()));
        tokio::task::spawn_local(plain.run(std::future::pending()));

        // Each robot writes once; the periodic refresh then re-sends the same old value.
        one.set("*.var.x", 1.5).unwrap();
        two.set("*.var.y", 2.5).unwrap();
        let written = std::time::Instant::now();
        wait_for(&mut heard_by_two, "1.var.x").await;
        wait_for(&mut heard_by_one, "2.var.y").await;
        // Long enough for refreshes and echoes to have gone both ways many times.
        tokio::time::sleep(Duration::from_millis(2500)).await;

        let real = written.elapsed();
        let on_two = age(&two, "1.var.x");
        let on_one = age(&one, "2.var.y");
        let tolerance = Duration::from_millis(40);
        assert!(
            on_two.abs_diff(real) < tolerance,
            "robot 2 ages robot 1's value {on_two:?}, written {real:?} ago: a skewed sender's \
             age must not carry its clock's offset"
        );
        // Robot 1's clock runs fast: 2.5 s is 2.50075 s on it.
        let real_on_one = real.mul_f64(1.0 + DRIFT_PPM * 1e-6);
        assert!(
            on_one.abs_diff(real_on_one) < tolerance,
            "robot 1 ages robot 2's value {on_one:?} on its own clock, expected {real_on_one:?}"
        );
        // Each ages its own value as its teammate does (within the tolerance): the two
        // timelines agree on when a write happened.
        let own_one = age(&one, "1.var.x");
        assert!(
            own_one.abs_diff(real_on_one) < tolerance,
            "robot 1 ages its own value {own_one:?}"
        );

        // Robot 2's estimate of robot 1's clock against the truth (both read back to back
        // on this one thread).
        let truth_us = us(one.now()) - us(two.now());
        let peer = two
            .stats()
            .peers
            .into_iter()
            .find(|p| p.robot == 1)
            .expect("robot 1 heard");
        let estimate = peer
            .clock_offset_us
            .expect("an offset estimated from echoes");
        // Echo samples come about once a second: from two or three the estimate cannot
        // follow the drift yet, which has added 300 µs a second since.
        let drifted_us = (real.as_secs_f64() * DRIFT_PPM) as i64;
        assert!(
            (estimate - truth_us).abs() < 5_000 + drifted_us,
            "robot 2 estimates robot 1's clock {estimate} µs ahead; it is {truth_us} µs \
             ({} samples)",
            peer.clock_samples
        );
    });
}
