//! Unit tests of a simulated robot: its senses reach its team layer, and its play follows
//! the layer's decision.

use super::*;
use crate::senses::Sighting;
use crate::tactics::Mode;

/// Robot 2 alone at (−1, 0) facing the opponent goal, in a team of five.
fn lone_robot() -> (Robot, BrainConfig) {
    let cfg = BrainConfig::default();
    let cal = Calibration::default();
    let start = Pose {
        at: Vec2::new(-1.0, 0.0),
        theta_rad: 0.0,
    };
    let r = Robot::new(
        2,
        Position::Field(1),
        ArbitrationParams::default(),
        start,
        &cal,
        &cfg.team.world_model,
        5,
    );
    (r, cfg)
}

#[test]
fn a_robot_that_sees_the_ball_ahead_claims_it_and_heads_for_it() {
    let (mut r, cfg) = lone_robot();
    let board = Blackboard::new(2);
    let homes = [
        Vec2::new(-3.0, 0.0),
        Vec2::new(-1.0, 0.0),
        Vec2::new(2.0, 1.0),
    ];
    let holders = [1, 2, 3];
    let mut out = None;
    for k in 1..=10u64 {
        let percepts = Percepts {
            frame: Frame {
                ball: Some(Sighting {
                    range_m: 1.5,
                    bearing_rad: 0.0,
                }),
                ..Frame::default()
            },
            odometry: Odometry::default(),
        };
        out = Some(r.tick(
            &cfg,
            TickInput {
                local_now: Instant::from_micros(k * 40_000),
                percepts,
                board: &board,
                world_model_waiting: false,
                claim_waiting: false,
                budget_headroom: None,
                homes: &homes,
                holders: &holders,
            },
        ));
    }
    let out = out.expect("ticked");
    assert!(
        r.going(),
        "alone with the ball 1.5 m ahead, it goes: {:?}",
        r.decision
    );
    assert_eq!(r.tactics.mode, Mode::Active, "the goer is active");
    let ball = r.ball.expect("its own ball").at;
    assert!(
        (ball.x - 0.5).abs() < 0.1 && ball.y.abs() < 0.1,
        "its ball is where the camera put it: {ball:?}"
    );
    assert!(
        out.writes
            .iter()
            .any(|(k, _)| *k == comms::arbitration::heuristic_key()),
        "its claim goes to the team"
    );
    let cmd = out.command.expect("a motion command");
    assert!(cmd.velocity.x > 0.0, "it heads for the ball: {cmd:?}");
}
