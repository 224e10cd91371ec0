//! The export rules on real replicas joined by a loop, in virtual time.

use std::net::SocketAddr;
use std::time::Duration;

use comms::{Instant, Replica, ReplicaConfig, Value};

use super::*;

const TEAM: u8 = 7;

fn at(ms: u64) -> Instant {
    Instant::from_micros(ms * 1000)
}

/// A robot, the bridge's listening replica and its exporter.
struct Rig {
    robot: Replica,
    listener: Replica,
    exporter: Exporter,
    ops: Vec<Op>,
}

impl Rig {
    fn new(cfg: ExportConfig) -> Rig {
        let robot = Replica::new(ReplicaConfig::new(2, TEAM), 0x22, at(0)).unwrap();
        let listener = Replica::new(ReplicaConfig::new(254, TEAM), 1, at(0)).unwrap();
        let keys = TeamKeys::new("lab", TEAM, "huddle_ros").unwrap();
        Rig {
            robot,
            listener,
            exporter: Exporter::new(keys, cfg),
            ops: Vec::new(),
        }
    }

    /// Delivers the robot's pending frames at `now` (1 ms later) and runs both sides'
    /// timers to `now`.
    fn step(&mut self, now: Instant) {
        while let Some(deadline) = self.robot.poll_timeout() {
            if deadline > now {
                break;
            }
            self.robot.handle_timeout(deadline);
        }
        let from = SocketAddr::from(([127, 0, 0, 1], 2000));
        let arrive = now + Duration::from_millis(1);
        let frames: Vec<_> = std::iter::from_fn(|| self.robot.poll_transmit()).collect();
        for t in frames {
            self.listener.handle_datagram(arrive, from, &t.payload);
        }
        while let Some(deadline) = self.listener.poll_timeout() {
            if deadline > arrive {
                break;
            }
            self.listener.handle_timeout(deadline);
        }
        while self.listener.poll_transmit().is_some() {}
        while self.robot.poll_event().is_some() {}
        while let Some(e) = self.listener.poll_event() {
            self.exporter.handle_event(arrive, &self.listener, e);
        }
        self.exporter.handle_timeout(arrive, &self.listener);
        self.ops.extend(self.exporter.drain_ops());
    }

    fn puts(&self) -> Vec<(String, String, u64)> {
        self.ops
            .iter()
            .filter_map(|op| match op {
                Op::Put(s) => Some((
                    s.key.clone(),
                    s.payload.clone(),
                    parse_attachment(&s.attachment()).unwrap().1,
                )),
                _ => None,
            })
            .collect()
    }
}

#[test]
fn a_change_goes_out_once_and_refreshes_do_not() {
    let mut rig = Rig::new(ExportConfig::default());
    rig.robot
        .set(at(0), "*.var.ball.dist", Value::Float(2.5))
        .unwrap();
    rig.robot
        .set(at(0), "local.var.secret", Value::from("x"))
        .unwrap();
    rig.step(at(0));
    // Ten refresh periods of the same value.
    for ms in (10..=1000).step_by(10) {
        rig.step(at(ms));
    }
    assert_eq!(
        rig.puts(),
        vec![("huddle/@v1/lab/7/2/var/ball/dist".into(), "2.5".into(), 1)],
        "one sample for one change; local.* never left; refreshes were not forwarded"
    );
    assert!(rig.exporter.stats().values_out == 1);
    let alive: Vec<_> = rig
        .ops
        .iter()
        .filter(|op| matches!(op, Op::Alive { .. }))
        .collect();
    assert_eq!(
        alive,
        vec![&Op::Alive {
            robot: 2,
            incarnation: 0x22,
            key: "huddle/@v1/lab/7/2/@alive/0000000000000022".into()
        }]
    );
}

#[test]
fn the_attachment_carries_the_age_at_the_bridge() {
    let mut rig = Rig::new(ExportConfig::default());
    rig.robot.set(at(0), "*.var.x", Value::Int(1)).unwrap();
    rig.step(at(0));
    let Some(Op::Put(sample)) = rig.ops.iter().find(|op| matches!(op, Op::Put(_))) else {
        panic!("no sample: {:?}", rig.ops);
    };
    let (inc, ver, age) = parse_attachment(&sample.attachment()).unwrap();
    assert_eq!((inc, ver), (0x22, 1));
    assert_eq!(
        age,
        Duration::ZERO,
        "received and exported in the same instant"
    );
    let key = comms::Key::parse("2.var.x").unwrap();
    let entry = rig.listener.blackboard().get(&key).unwrap().clone();
    let later = rig.exporter.sample(at(251), &key, &entry).unwrap();
    assert_eq!(
        parse_attachment(&later.attachment()).unwrap().2,
        Duration::from_millis(250),
        "a reply later computes the age at its own time"
    );
}

#[test]
fn a_rate_cap_sends_the_newest_value_at_the_end_of_each_period() {
    let mut rig = Rig::new(ExportConfig {
        min_interval: Some(Duration::from_millis(100)),
        ros2: false,
    });
    for i in 0..=25u64 {
        rig.robot
            .set(at(i * 10), "*.var.t", Value::Int(i as i64))
            .unwrap();
        rig.step(at(i * 10));
    }
    rig.step(at(400));
    let values: Vec<String> = rig.puts().into_iter().map(|p| p.1).collect();
    // Published at 1 ms (0), then the newest at 101 ms (10), 201 ms (20), 301 ms (25).
    assert_eq!(
        values,
        ["0", "10", "20", "25"],
        "26 changes at 100 Hz, cap 10 Hz"
    );
    assert_eq!(rig.exporter.stats().rate_held, 3);
}

#[test]
fn a_restart_swaps_the_token_and_the_old_life_is_not_rolled_back_to() {
    let mut rig = Rig::new(ExportConfig::default());
    rig.robot.set(at(0), "*.var.x", Value::Int(5)).unwrap();
    rig.step(at(0));
    let old_frame = {
        rig.robot.set(at(50), "*.var.x", Value::Int(6)).unwrap();
        rig.robot.poll_transmit().unwrap().payload
    };
    // The robot restarts with a larger incarnation and sets x once (version 1).
    rig.robot = Replica::new(ReplicaConfig::new(2, TEAM), 0x33, at(60)).unwrap();
    rig.robot.set(at(60), "*.var.x", Value::Int(1)).unwrap();
    rig.step(at(60));
    // The old life's frame arrives late.
    let from = SocketAddr::from(([127, 0, 0, 1], 2000));
    rig.listener.handle_datagram(at(70), from, &old_frame);
    while let Some(e) = rig.listener.poll_event() {
        rig.exporter.handle_event(at(70), &rig.listener, e);
    }
    rig.ops.extend(rig.exporter.drain_ops());
    let tokens: Vec<_> = rig
        .ops
        .iter()
        .filter(|op| !matches!(op, Op::Put(_)))
        .cloned()
        .collect();
    assert_eq!(
        tokens,
        vec![
            Op::Alive {
                robot: 2,
                incarnation: 0x22,
                key: "huddle/@v1/lab/7/2/@alive/0000000000000022".into()
            },
            Op::Gone { robot: 2 },
            Op::Alive {
                robot: 2,
                incarnation: 0x33,
                key: "huddle/@v1/lab/7/2/@alive/0000000000000033".into()
            },
        ],
        "a restart is a DELETE then a PUT"
    );
    let values: Vec<String> = rig.puts().into_iter().map(|p| p.1).collect();
    assert_eq!(values, ["5", "1"], "the old life's 6 never went out");
}

#[test]
fn a_departure_withdraws_the_token() {
    let mut rig = Rig::new(ExportConfig::default());
    rig.robot.set(at(0), "*.var.x", Value::Int(5)).unwrap();
    rig.step(at(0));
    // The robot falls silent: only the listener's timers run.
    for ms in (10..1000).step_by(10) {
        let now = at(ms);
        while let Some(d) = rig.listener.poll_timeout() {
            if d > now {
                break;
            }
            rig.listener.handle_timeout(d);
        }
        while let Some(e) = rig.listener.poll_event() {
            rig.exporter.handle_event(now, &rig.listener, e);
        }
    }
    rig.ops.extend(rig.exporter.drain_ops());
    assert_eq!(rig.ops.last(), Some(&Op::Gone { robot: 2 }));
    assert!(rig.exporter.alive().is_empty());
}

#[test]
fn ros2_samples_carry_cdr_beside_the_text() {
    let mut rig = Rig::new(ExportConfig {
        min_interval: None,
        ros2: true,
    });
    rig.robot
        .set(at(0), "*.var.ball.dist", Value::Float(2.5))
        .unwrap();
    rig.robot
        .set(at(0), "*.var.near-ball", Value::Bool(true))
        .unwrap();
    rig.step(at(0));
    let ros: Vec<_> = rig
        .ops
        .iter()
        .filter_map(|op| match op {
            Op::Put(s) => Some((s.key.clone(), s.ros2.clone())),
            _ => None,
        })
        .collect();
    assert!(ros.contains(&(
        "huddle/@v1/lab/7/2/var/ball/dist".into(),
        Some((
            "huddle_ros/lab/team7/robot2/ball/dist".into(),
            cdr::encode(&Value::Float(2.5))
        ))
    )));
    assert!(
        ros.contains(&("huddle/@v1/lab/7/2/var/near-ball".into(), None)),
        "near-ball has no ROS 2 name but still goes out as huddle"
    );
    assert_eq!(rig.exporter.stats().ros2_unmappable, 1);
}

#[test]
fn attachments_parse_back_and_garbage_does_not() {
    let a = attachment(0xabc, 42, Duration::from_micros(1234));
    assert_eq!(a, "incarnation=0000000000000abc version=42 age_us=1234");
    assert_eq!(
        parse_attachment(&a),
        Some((0xabc, 42, Duration::from_micros(1234)))
    );
    assert_eq!(parse_attachment("version=1"), None);
    assert_eq!(parse_attachment("incarnation=zz version=1 age_us=2"), None);
}
