//! The team layer's own cost per robot tick, against a NAO's budget (about 1% of one core
//! at 30 Hz, i.e. 333 µs a tick) and against the filters alone measured in the same run.
//!
//! Five robots, each a `comms::Replica` and a `team::TeamLayer`, exchange frames in
//! memory at 25 Hz; every robot sees the ball and three landmarks each tick, so robot 2's
//! tick ingests four teammates' new LWMs, runs both EKFs, the GWM, the arbitration and
//! the VOI policy. Only robot 2's `sense` + `decide` + `finish` is timed; the baseline
//! is the same robot's pose and ball EKF updates, its LWM publish, and a second GWM's
//! decoding and ingest of the very LWMs robot 2's replica holds, and its team ball:
//! the filters without the team layer around them.
//!
//! `cargo bench -p team --bench tick`

// A benchmark measures wall time: the one place a clock may be read.
#![allow(clippy::disallowed_methods)]

use std::hint::black_box;
use std::time::{Duration, Instant as Wall};

use comms::arbitration::ArbitrationParams;
use comms::{Instant, Replica, ReplicaConfig};
use fusion::nalgebra::{Matrix2, Vector2};
use fusion::RangeBearingSighting;
use team::{frames, Calibration, Pose, SendPolicy, Senses, TeamConfig, TeamLayer, Vec2};

const ROBOTS: usize = 5;
const TICKS: u64 = 3_000;

struct Team {
    replicas: Vec<Replica>,
    layers: Vec<TeamLayer>,
    cfg: TeamConfig,
}

fn team() -> Team {
    let cfg = TeamConfig {
        send_policy: SendPolicy::Voi,
        ..TeamConfig::default()
    };
    let cal = Calibration::default();
    let replicas = (1..=ROBOTS as u8)
        .map(|id| {
            Replica::new(
                ReplicaConfig::new(id, 7),
                u64::from(id),
                Instant::from_micros(0),
            )
            .expect("a valid config")
        })
        .collect();
    let layers = (1..=ROBOTS as u8)
        .map(|id| {
            let start = Pose {
                at: Vec2::new(-3.0 + f64::from(id), 0.5 * f64::from(id) - 1.5),
                theta_rad: 0.0,
            };
            TeamLayer::new(
                id,
                false,
                ArbitrationParams::default(),
                start,
                &cal,
                &cfg.world_model,
                ROBOTS,
            )
        })
        .collect();
    Team {
        replicas,
        layers,
        cfg,
    }
}

/// Landmark sightings with their R.
type Landmarks = Vec<(RangeBearingSighting, Matrix2<f64>)>;

/// What robot `k` senses at tick `n`: a little forward motion, the ball ahead, landmarks.
fn senses_of(k: usize, n: u64) -> (fusion::Odometry, Landmarks, (fusion::BallSighting, f64)) {
    let odo = fusion::Odometry {
        forward_m: 0.01,
        left_m: 0.0,
        turn_rad: 0.001,
    };
    let marks = Calibration::default().field.landmarks();
    let landmarks = (0..3)
        .map(|j| {
            let m = marks[(n as usize + j + k) % marks.len()];
            (
                RangeBearingSighting {
                    field: Vector2::new(m.x, m.y),
                    range_m: 4.0,
                    bearing_rad: 0.1 * j as f64,
                },
                Matrix2::new(0.04, 0.0, 0.0, 0.0004),
            )
        })
        .collect();
    let wobble = 0.01 * ((n % 7) as f64 - 3.0);
    let ball = frames::ball_sighting_from_rep103(
        Vector2::new(2.0 + wobble, 0.3),
        Matrix2::identity() * 0.01,
    );
    (odo, landmarks, (ball, 0.0))
}

/// One tick of every robot; returns the wall time robot 2's team layer took.
fn tick(t: &mut Team, n: u64) -> Duration {
    let now = Instant::from_micros(n * 40_000);
    let mut timed = Duration::ZERO;
    for k in 0..ROBOTS {
        let (odo, landmarks, ball) = senses_of(k, n);
        let odometry = [odo];
        let balls = [ball];
        let senses = Senses {
            odometry: &odometry,
            landmarks: &landmarks,
            ball: &balls,
            ..Senses::default()
        };
        let replica = &mut t.replicas[k];
        let layer = &mut t.layers[k];
        let start = Wall::now();
        let lwm = layer.sense(&t.cfg, now, &senses, replica.blackboard(), false);
        let (_, posted) = layer.decide(replica.blackboard(), now);
        let (writes, _) = layer.finish(&t.cfg, now, lwm, posted, 0, false, false, false, None);
        if k == 1 {
            timed = start.elapsed();
        }
        for (key, value) in writes {
            replica.set_key(now, &key, value).expect("own keys");
        }
    }
    // Every frame to every other robot.
    let from = "127.0.0.1:2000".parse().expect("an address");
    let mut frames = Vec::new();
    for (k, r) in t.replicas.iter_mut().enumerate() {
        r.handle_timeout(now);
        while let Some(tx) = r.poll_transmit() {
            frames.push((k, tx.payload.to_vec()));
        }
    }
    for (k, bytes) in &frames {
        for (j, r) in t.replicas.iter_mut().enumerate() {
            if j != *k {
                r.handle_datagram(now, from, bytes);
            }
        }
    }
    timed
}

/// Robot 2's filters alone on the same inputs: pose EKF, ball EKF, GWM ingest.
fn filters_only(t: &Team, n: u64, layer: &mut TeamLayer) -> Duration {
    let now_s = n as f64 * 0.04;
    let (odo, landmarks, (ball, _)) = senses_of(1, n);
    let start = Wall::now();
    let pf = layer.lwm.pose_filter_mut();
    pf.odometry(&odo);
    for (s, r) in &landmarks {
        pf.noise.r_range_bearing = *r;
        let _ = pf.range_bearing(s);
    }
    layer.lwm.ball_sighting(now_s, &ball);
    let msg = layer.lwm.publish(now_s);
    layer.gwm.ingest(2, &msg, now_s);
    // The same teammates' LWMs robot 2's replica holds (new ones every tick).
    let board = t.replicas[1].blackboard();
    for id in (1..=ROBOTS as u8).filter(|&id| id != 2) {
        if let Some(comms::Value::Bytes(bytes)) =
            board.get(&team::world_local_of(id)).map(|e| &e.value)
        {
            if let Ok(m) = layer.gwm.decode(bytes, now_s, 0.0) {
                layer.gwm.ingest(id, &m, now_s);
            }
        }
    }
    black_box(layer.gwm.team_ball(now_s, None));
    start.elapsed()
}

fn main() {
    let mut t = team();
    // Warm up: every robot's LWM reaches its teammates.
    for n in 0..50 {
        tick(&mut t, n);
    }
    let mut layer_us = Vec::new();
    let mut base_us = Vec::new();
    let mut baseline = t.layers[1].clone();
    for round in 0..5u64 {
        let (mut a, mut b) = (Duration::ZERO, Duration::ZERO);
        for i in 0..TICKS {
            let n = 50 + round * TICKS + i;
            a += tick(&mut t, n);
            b += filters_only(&t, n, &mut baseline);
        }
        layer_us.push(a.as_secs_f64() * 1e6 / TICKS as f64);
        base_us.push(b.as_secs_f64() * 1e6 / TICKS as f64);
    }
    layer_us.sort_by(f64::total_cmp);
    base_us.sort_by(f64::total_cmp);
    let (layer, base) = (layer_us[2], base_us[2]);
    println!("team layer tick (robot 2 of 5, VOI, ball + 3 landmarks, 4 teammates' LWMs):");
    println!(
        "  median of 5 rounds of {TICKS} ticks: {layer:.1} µs per tick (rounds {:.1}–{:.1})",
        layer_us[0], layer_us[4]
    );
    println!(
        "  at 30 Hz: {:.3}% of one core (a NAO's budget: 1%, i.e. 333 µs a tick)",
        layer * 30.0 / 1e4
    );
    println!(
        "  the filters alone, same inputs, same run: {base:.1} µs; team layer / filters = {:.2}",
        layer / base
    );
}
