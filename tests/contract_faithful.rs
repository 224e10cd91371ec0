//! The relay path gives a daemon's team layer exactly what the in-process robot gives its
//! own: a robot program's writes (`player::remote::contract_inputs`, through the
//! contract's guards into `driver::team::TeamCore`) and the in-process robot's
//! `team::Senses` (built as `player::Robot::tick` builds them) must hold the same pose,
//! tick for tick, through what makes the drawn world's poses hard.
//!
//! Scenario: robot 2 walks a circle of 1.5 m at 0.8 m/s for 30 s, sampled every 40 ms.
//! Its odometry reads 4% long with noise; from 8 to 9 s its body is held (a teammate in
//! the way) while the wheels report the walk, so it is kidnapped by 0.8 m; one landmark
//! sighting in 25 is named as its twin through the centre spot (the χ² gate refuses it);
//! it sees the ball at (1.0, 0.5) whenever it faces it. Both layers must publish the same
//! pose to 1 µm at every tick, and the same own ball. `huddle sim --daemons` showed the
//! drawn world's poses worse through the daemons than in process (0.05–0.13 m against
//! 0.05–0.07 m); a shadow layer fed as here matched the daemons' exactly, and the gap
//! was the in-process run being a low draw (docs/results/sim-daemons.md). This test
//! keeps the path faithful.

use comms::{Instant, Replica, ReplicaConfig, Value};
use driver::team::{TeamCore, TeamLayerConfig};
use player::perception;
use player::remote::{contract_inputs, start_pose_value};
use player::senses::{Frame, Odometry, Sighting};
use player::Percepts;
use team::contract;
use team::{Calibration, Pose, TeamLayer, Vec2};

/// A small deterministic noise source (xorshift), uniform in [−1, 1].
struct Noise(u64);

impl Noise {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// What the camera sees from `truth`: landmarks within 5 m and 60° of the heading (one in
/// 25 named as its twin), the ball if in view.
fn look(cal: &Calibration, truth: &Pose, ball: Vec2, noise: &mut Noise, k: &mut u32) -> Frame {
    let marks = cal.field.landmarks();
    let seen = |at: Vec2, noise: &mut Noise| {
        let rel = truth.to_local(at);
        let (range, bearing) = (rel.x.hypot(rel.y), rel.y.atan2(rel.x));
        (range < 5.0 && bearing.abs() < 1.05).then(|| Sighting {
            range_m: range * (1.0 + 0.03 * noise.next()),
            bearing_rad: bearing + 0.02 * noise.next(),
        })
    };
    let mut landmarks = Vec::new();
    for (i, &m) in marks.iter().enumerate() {
        if let Some(s) = seen(m, noise) {
            *k += 1;
            let name = if (*k).is_multiple_of(25) {
                // Its twin through the centre spot.
                let twin = Vec2::new(-m.x, -m.y);
                (0..marks.len())
                    .min_by(|&a, &b| marks[a].distance(twin).total_cmp(&marks[b].distance(twin)))
                    .unwrap_or(i)
            } else {
                i
            };
            landmarks.push((name, s));
        }
    }
    Frame {
        ball: seen(ball, noise),
        opponent_goal_in_view: false,
        landmarks,
        opponents: Vec::new(),
    }
}

fn floats(v: &Value) -> Vec<f64> {
    match v {
        Value::Floats(f) => f.clone(),
        other => panic!("expected floats, got {other:?}"),
    }
}

#[test]
fn a_daemon_s_layer_holds_the_pose_the_in_process_layer_holds() {
    let cal = Calibration::default();
    let team_cfg = team::TeamConfig::default();
    let wm = team_cfg.world_model;
    let (radius, speed, dt) = (1.5, 0.8, 0.04);
    let ball = Vec2::new(1.0, 0.5);
    let start = Pose {
        at: Vec2::new(radius, 0.0),
        theta_rad: std::f64::consts::FRAC_PI_2,
    };

    // In process: the layer the simulated robot runs, fed `team::Senses`.
    let mut layer = TeamLayer::new(
        2,
        false,
        comms::arbitration::ArbitrationParams::default(),
        start,
        &cal,
        &wm,
        3,
    );
    let board = comms::Blackboard::new(2);

    // Through the relay's contract: the daemon's layer, told its start pose first.
    let mut core = TeamCore::new(2, TeamLayerConfig::new(3, None));
    let mut now = Instant::from_micros(5_000_000);
    let config = ReplicaConfig::new(2, 0).with_known_paths(team::known_paths());
    let mut replica = Replica::new(config, 11, now).expect("a valid replica");
    core.input(
        contract::POSE_KEY,
        &start_pose_value(&start, wm.start_sigma_m, wm.start_sigma_rad),
        now,
    )
    .expect("the start pose is taken");
    core.tick(&mut replica, now);

    let mut noise = Noise(0x9e37_79b9_7f4a_7c15);
    let mut named = 0;
    let mut truth = start;
    let (mut worst_gap, mut worst_error, mut ticks) = (0.0f64, 0.0f64, 0);
    for step in 1..=750 {
        now = Instant::from_micros(now.as_micros() + 40_000);
        let t = f64::from(step) * dt;
        // The walk along the circle (a turn of speed/radius per second).
        let turn = speed / radius * dt;
        let walked = Odometry {
            forward_m: speed * dt,
            left_m: 0.0,
            turn_rad: turn,
        };
        let held = (8.0..9.0).contains(&t);
        if !held {
            let d = Vec2::new(walked.forward_m, 0.0).rotate(truth.theta_rad);
            truth = Pose {
                at: truth.at + d,
                theta_rad: fusion::wrap_angle(truth.theta_rad + turn),
            };
        }
        let odometry = Odometry {
            forward_m: walked.forward_m * 1.04 * (1.0 + 0.05 * noise.next()),
            left_m: 0.002 * noise.next(),
            turn_rad: walked.turn_rad * 1.04 + 0.003 * noise.next(),
        };
        let frame = look(&cal, &truth, ball, &mut noise, &mut named);

        // In process, as `player::Robot::tick` builds its senses.
        let marks = cal.field.landmarks();
        let landmarks: Vec<_> = frame
            .landmarks
            .iter()
            .map(|(k, s)| perception::landmark_sighting(&cal.sensors, marks[*k], s))
            .collect();
        let odo = [perception::to_fusion_odometry(&odometry)];
        let balls: Vec<_> = frame
            .ball
            .iter()
            .map(|s| (perception::ball_sighting(&cal.sensors, s), 0.0))
            .collect();
        let senses = team::Senses {
            odometry: &odo,
            landmarks: &landmarks,
            pose: None,
            ball: &balls,
            goal_in_view: false,
            opponents: &[],
            cost: None,
        };
        layer.sense(&team_cfg, now, &senses, &board, false);

        // Through the contract, as `huddle sim --daemons`' robot programs write it.
        let percepts = Percepts { frame, odometry };
        for (key, value) in contract_inputs(&cal, &percepts) {
            core.input(key, &value, now)
                .unwrap_or_else(|e| panic!("{key} = {value} refused: {e}"));
        }
        core.tick(&mut replica, now);

        let published = replica
            .get(contract::POSE_OUT_KEY)
            .expect("a valid key")
            .map(|e| e.value.clone())
            .expect("the daemon's layer publishes its pose");
        let p = contract::parse_pose_output(&published).expect("its own output parses");
        let mine = layer.pose_belief;
        let gap = p
            .pose
            .at
            .distance(mine.at)
            .max(fusion::wrap_angle(p.pose.theta_rad - mine.theta_rad).abs());
        worst_gap = worst_gap.max(gap);
        worst_error = worst_error.max(truth.at.distance(mine.at));
        if let (Some(own), Some(e)) = (
            layer.own_ball(team::seconds(now)),
            replica.get(contract::OWN_BALL_KEY).expect("a valid key"),
        ) {
            let f = floats(&e.value);
            let gap = (f[0] - own.position().x).hypot(f[1] - own.position().y);
            assert!(
                gap < 1e-6,
                "tick {step}: own ball {f:?} through the contract, {own:?} in process"
            );
        }
        ticks += 1;
    }
    assert!(
        worst_gap < 1e-6,
        "the two layers' poses parted by {worst_gap} (m or rad) over {ticks} ticks"
    );
    assert!(
        worst_error > 0.3,
        "the held body kidnapped the robot (worst pose error {worst_error} m): the test \
         must exercise the gate and the relocalisation"
    );
}
