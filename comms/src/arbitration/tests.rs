use super::*;

fn fresh(robot: u8, h: f64, going: bool) -> Candidate {
    Candidate {
        robot,
        posted: Posted { h, going },
        age: Duration::from_millis(20),
    }
}

#[test]
fn the_seeds_example_the_robot_facing_the_goal_goes() {
    // Robots 1 and 2 are both 2 m from the ball; only robot 2 faces the opponent goal.
    let p = ArbitrationParams::default();
    let h1 = heuristic(
        &p,
        Some(BallView {
            distance_m: 2.0,
            facing_opponent_goal: false,
        }),
    );
    let h2 = heuristic(
        &p,
        Some(BallView {
            distance_m: 2.0,
            facing_opponent_goal: true,
        }),
    );
    let d = decide(&p, &[fresh(1, h1, false), fresh(2, h2, false)]);
    assert!(d.should_go(2), "robot 2 faces the goal and must go: {d:?}");
    assert!(!d.should_go(1), "robot 1 must stand still: {d:?}");
}

#[test]
fn a_robot_that_does_not_see_the_ball_posts_the_seeds_1000() {
    assert_eq!(heuristic(&ArbitrationParams::default(), None), 1000.0);
}

#[test]
fn ties_go_to_the_lower_robot_id_whatever_the_order_heard() {
    let p = ArbitrationParams::default();
    let a = decide(&p, &[fresh(3, 1.0, false), fresh(2, 1.0, false)]);
    let b = decide(&p, &[fresh(2, 1.0, false), fresh(3, 1.0, false)]);
    assert_eq!(a.goer, Some(2));
    assert_eq!(b.goer, Some(2));
}

#[test]
fn stale_values_do_not_count() {
    let p = ArbitrationParams::default();
    let mut dead = fresh(1, 0.1, true);
    dead.age = p.stale_after + Duration::from_millis(1);
    let d = decide(&p, &[dead, fresh(2, 3.0, false)]);
    assert_eq!(d.goer, Some(2), "a silent robot's old cost must not win");
}

#[test]
fn the_current_goer_keeps_going_unless_beaten_by_more_than_the_margin() {
    let p = ArbitrationParams {
        hysteresis_m: 0.3,
        ..Default::default()
    };
    // Robot 2 is going at 2.0 m; robot 1 is 0.2 m closer: not enough to take over.
    let d = decide(&p, &[fresh(1, 1.8, false), fresh(2, 2.0, true)]);
    assert_eq!(d.goer, Some(2), "a 0.2 m edge is inside the 0.3 m margin");
    // 0.4 m closer: robot 1 takes over.
    let d = decide(&p, &[fresh(1, 1.6, false), fresh(2, 2.0, true)]);
    assert_eq!(d.goer, Some(1), "a 0.4 m edge beats the 0.3 m margin");
}

#[test]
fn malformed_posted_values_are_ignored() {
    assert_eq!(Posted::from_floats(&[1.0]), None);
    assert_eq!(Posted::from_floats(&[f64::NAN, 1.0]), None);
    let p = Posted {
        h: 2.5,
        going: true,
    };
    assert_eq!(Posted::from_floats(&p.to_floats()), Some(p));
}

#[test]
fn nobody_goes_when_nobody_sees_the_ball() {
    let p = ArbitrationParams::default();
    let d = decide(&p, &[fresh(1, 1000.0, true), fresh(2, 1000.0, false)]);
    assert_eq!(d.goer, None, "no robot sees the ball: {d:?}");
}

#[test]
fn a_restarted_robot_listens_before_it_claims_the_ball() {
    let p = ArbitrationParams::default();
    let mut a = Arbiter::new(3, false, p);
    // Robot 3 is the best placed, but it has just started and heard nobody yet.
    let (d, posted) = a.tick(Duration::from_millis(40), 0.5, &[]);
    assert!(d.should_go(3), "its view says it is best: {d:?}");
    assert!(
        !posted.going && !a.going(),
        "but it must not go while listening"
    );
    // After the listening time it hears robot 1 going at 2 m and takes over.
    let heard = [fresh(1, 2.0, true)];
    let (_, posted) = a.tick(Duration::from_millis(80), 0.5, &heard);
    assert!(
        posted.going,
        "listening is over and 0.5 m beats 2.0 m - margin"
    );
}

#[test]
fn a_goalkeeper_never_competes() {
    let p = ArbitrationParams::default();
    let mut gk = Arbiter::new(
        1,
        true,
        ArbitrationParams {
            listen_for: Duration::ZERO,
            ..p
        },
    );
    let (d, posted) = gk.tick(Duration::from_millis(40), 0.1, &[fresh(2, 3.0, false)]);
    assert_eq!(d.goer, Some(2), "the field player goes: {d:?}");
    assert!(!posted.going);
    assert_eq!(
        posted.h, p.no_ball_cost,
        "teammates must never count the keeper"
    );
}

#[test]
fn costs_are_read_from_the_blackboard_with_receiver_side_ages() {
    let mut board = Blackboard::new(2);
    let t0 = Instant::from_micros(1_000_000);
    board
        .set(
            t0,
            &heuristic_key(),
            Posted {
                h: 1.5,
                going: true,
            }
            .into(),
        )
        .unwrap();
    // A teammate's copy that claims to be a float, not [h, going]: ignored.
    board
        .set(
            t0,
            &Key::parse("*.var.machine.other").unwrap(),
            Value::Float(0.0),
        )
        .unwrap();
    let later = Instant::from_micros(1_250_000);
    let got = heard(&board, later);
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(got[0].robot, 2);
    assert_eq!(
        got[0].posted,
        Posted {
            h: 1.5,
            going: true
        }
    );
    assert_eq!(got[0].age, Duration::from_millis(250));
}

#[test]
fn parameters_come_from_the_configuration_keys_and_bad_ones_are_refused() {
    let mut board = Blackboard::new(1);
    let t = Instant::ZERO;
    let set = |b: &mut Blackboard, k: &str, v: Value| {
        b.set(t, &Key::parse(k).unwrap(), v).unwrap();
    };
    set(&mut board, config_keys::K1_M, Value::Float(-0.8));
    set(&mut board, config_keys::STALE_MS, Value::Int(450));
    set(
        &mut board,
        config_keys::ROLE,
        Value::String("goalkeeper".into()),
    );
    let p = ArbitrationParams::from_blackboard(&board, ArbitrationParams::default()).unwrap();
    assert_eq!(p.k1_m, -0.8);
    assert_eq!(p.stale_after, Duration::from_millis(450));
    assert_eq!(
        p.hysteresis_m,
        ArbitrationParams::default().hysteresis_m,
        "default kept"
    );
    assert!(is_goalkeeper(&board).unwrap());
    set(&mut board, config_keys::K1_M, Value::Float(0.5));
    let err = ArbitrationParams::from_blackboard(&board, ArbitrationParams::default());
    assert!(
        matches!(err, Err(ParamsError::OutOfRange { .. })),
        "k1 >= 0 breaks the seed: {err:?}"
    );
    set(&mut board, config_keys::K1_M, Value::String("far".into()));
    let err = ArbitrationParams::from_blackboard(&board, ArbitrationParams::default());
    assert!(
        matches!(err, Err(ParamsError::NotANumber { .. })),
        "{err:?}"
    );
}

#[test]
fn two_robots_claiming_at_once_from_equal_distances_agree_on_the_lower_id() {
    // Robots 1 and 2 race to the ball from 2 m; each hears the other 50 ms late, so
    // each sees itself 7.5 cm ahead (1.5 m/s · 50 ms).
    let p = ArbitrationParams::default();
    let view_of_1 = decide(&p, &[fresh(1, 1.925, true), fresh(2, 2.0, true)]);
    let view_of_2 = decide(&p, &[fresh(1, 2.0, true), fresh(2, 1.925, true)]);
    assert_eq!(view_of_1.goer, Some(1));
    assert_eq!(
        view_of_2.goer,
        Some(1),
        "robot 2 must yield, or both keep going"
    );
    // Without the tie band both would go.
    let no_band = ArbitrationParams { tie_m: 0.0, ..p };
    assert_eq!(
        decide(&no_band, &[fresh(1, 2.0, true), fresh(2, 1.925, true)]).goer,
        Some(2)
    );
    // A claim better by more than the band still wins.
    let d = decide(&p, &[fresh(1, 2.0, true), fresh(2, 1.7, true)]);
    assert_eq!(d.goer, Some(2));
}

#[test]
fn with_latency_compensation_both_ends_of_a_handover_switch_together() {
    // Robot 1 is going at 2.0 m; robot 2's cost drops to 1.0 m at once (it has just
    // seen the ball close by). Latency 50 ms, ticks of 10 ms.
    let p = ArbitrationParams {
        listen_for: Duration::ZERO,
        latency_compensation: Duration::from_millis(50),
        ..Default::default()
    };
    let tick = Duration::from_millis(10);
    let mut a1 = Arbiter::new(1, false, p);
    let mut a2 = Arbiter::new(2, false, p);
    // Both have been posting for a while: robot 1 going at 2.0, robot 2 at 3.0.
    let mut sent1 = Vec::new();
    let mut sent2 = Vec::new();
    let mut switched = (None, None);
    for k in 0..40usize {
        let h2 = if k < 20 { 3.0 } else { 1.0 };
        // Each hears the other's post from 5 ticks (50 ms) ago.
        let heard = |sent: &Vec<Posted>, robot| -> Vec<Candidate> {
            sent.len()
                .checked_sub(5)
                .map(|i| Candidate {
                    robot,
                    posted: sent[i],
                    age: Duration::ZERO,
                })
                .into_iter()
                .collect()
        };
        let h1_heard = heard(&sent2, 2);
        let h2_heard = heard(&sent1, 1);
        let (_, p1) = a1.tick(tick, 2.0, &h1_heard);
        let (_, p2) = a2.tick(tick, h2, &h2_heard);
        sent1.push(p1);
        sent2.push(p2);
        if k >= 20 && !p1.going && switched.0.is_none() {
            switched.0 = Some(k);
        }
        if k >= 20 && p2.going && switched.1.is_none() {
            switched.1 = Some(k);
        }
    }
    let (Some(stop), Some(start)) = switched else {
        panic!("the handover never happened: {switched:?}");
    };
    assert!(
        stop.abs_diff(start) <= 1,
        "robot 1 stopped at tick {stop}, robot 2 started at {start}"
    );
    assert!(
        start >= 24,
        "robot 2 claims one latency after its cost dropped, at {start}"
    );
}
