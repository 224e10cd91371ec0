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
    let mut dead = fresh(1, 0.1, false);
    dead.age = p.stale_after + Duration::from_millis(1);
    let d = decide(&p, &[dead, fresh(2, 3.0, false)]);
    assert_eq!(d.goer, Some(2), "a silent robot's old cost must not win");
    let mut dead_goer = fresh(1, 0.1, true);
    dead_goer.age = p.silent_goer_after + Duration::from_millis(1);
    let d = decide(&p, &[dead_goer, fresh(2, 3.0, false)]);
    assert_eq!(d.goer, Some(2), "nor a goer silent past silent_goer_after");
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
    set(&mut board, config_keys::SILENT_GOER_MS, Value::Int(1500));
    set(&mut board, config_keys::ACK_MARGIN_MS, Value::Float(60.0));
    set(
        &mut board,
        config_keys::ROLE,
        Value::String("goalkeeper".into()),
    );
    let p = ArbitrationParams::from_blackboard(&board, ArbitrationParams::default()).unwrap();
    assert_eq!(p.k1_m, -0.8);
    assert_eq!(p.stale_after, Duration::from_millis(450));
    assert_eq!(p.silent_goer_after, Duration::from_millis(1500));
    assert_eq!(p.ack_margin, Duration::from_millis(60));
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

#[test]
fn a_silent_goer_keeps_the_ball_longer_than_a_silent_bystander() {
    // Robot 1's last post said it was going at 1.0 m; robot 2 is at 2.0 m.
    let p = ArbitrationParams::default();
    let claim = |age_ms: u64, going: bool| Candidate {
        robot: 1,
        posted: Posted { h: 1.0, going },
        age: Duration::from_millis(age_ms),
    };
    let me = fresh(2, 2.0, false);
    let d = decide(&p, &[claim(800, true), me]);
    assert_eq!(
        d.goer,
        Some(1),
        "silent for 0.8 s: still the goer, not gone"
    );
    let d = decide(&p, &[claim(1100, true), me]);
    assert_eq!(d.goer, Some(2), "silent past silent_goer_after: gone");
    let d = decide(&p, &[claim(400, false), me]);
    assert_eq!(
        d.goer,
        Some(2),
        "a bystander's claim is stale after stale_after"
    );
}

/// Two robots, each hearing the other's posts one `delay_ticks` late unless a lost tick
/// drops them; the receiver-side age grows while nothing arrives. Ticks of 10 ms.
struct Pair {
    arbiters: [Arbiter; 2],
    sent: [Vec<Posted>; 2],
    /// Per receiver: the latest post heard and the tick it arrived at.
    heard: [Option<(Posted, usize)>; 2],
    delay_ticks: usize,
}

const PAIR_TICK: Duration = Duration::from_millis(10);

impl Pair {
    fn new(p: ArbitrationParams, delay_ticks: usize) -> Pair {
        Pair {
            arbiters: [Arbiter::new(1, false, p), Arbiter::new(2, false, p)],
            sent: [Vec::new(), Vec::new()],
            heard: [None, None],
            delay_ticks,
        }
    }

    /// Tick `k` with costs `h`; `lost(from)` drops robot `from`'s post arriving now.
    /// Returns who is going.
    fn tick(&mut self, k: usize, h: [f64; 2], lost: impl Fn(usize) -> bool) -> [bool; 2] {
        for to in 0..2 {
            let from = 1 - to;
            if let Some(i) = self.sent[from].len().checked_sub(self.delay_ticks) {
                if !lost(from) {
                    self.heard[to] = Some((self.sent[from][i], k));
                }
            }
        }
        let mut going = [false; 2];
        for me in 0..2 {
            let heard: Vec<Candidate> = self.heard[me]
                .map(|(posted, at)| Candidate {
                    robot: (2 - me) as u8,
                    posted,
                    age: PAIR_TICK * (k - at) as u32,
                })
                .into_iter()
                .collect();
            let (_, posted) = self.arbiters[me].tick(PAIR_TICK, h[me], &heard);
            self.sent[me].push(posted);
            going[me] = posted.going;
        }
        going
    }
}

fn unacknowledged_claim(ack_margin: Duration) -> (usize, Option<usize>, bool) {
    // Robot 1 goes at 2.0 m. At tick 50 robot 2's cost drops to 1.0 m, but everything
    // robot 2 sends from tick 50 to 100 is lost (a 500 ms burst at its sender); robot 1's
    // posts get through. Latency 50 ms.
    let p = ArbitrationParams {
        listen_for: Duration::ZERO,
        latency_compensation: Duration::from_millis(50),
        ack_margin,
        ..Default::default()
    };
    let mut pair = Pair::new(p, 5);
    let (mut both, mut deferred_at, mut end) = (0, None, [false; 2]);
    for k in 0..200 {
        let h2 = if k < 50 { 3.0 } else { 1.0 };
        let going = pair.tick(k, [2.0, h2], |from| from == 1 && (55..105).contains(&k));
        if going == [true, true] {
            both += 1;
        }
        if deferred_at.is_none() && pair.arbiters[1].deferring_to() == Some(1) {
            deferred_at = Some(k);
        }
        end = going;
    }
    (both, deferred_at, end == [false, true])
}

#[test]
fn a_claim_the_goer_does_not_acknowledge_is_withdrawn_until_the_goer_lets_go() {
    let p = ArbitrationParams::default();
    let (both, deferred_at, handed_over) = unacknowledged_claim(p.ack_margin);
    // Robot 2 claims one latency after its drop (tick 55) and waits two latencies plus
    // the margin (180 ms) for robot 1's release: then it backs off.
    let limit = (2 * 50 + p.ack_margin.as_millis() as usize) / 10 + 2;
    assert!(
        both <= limit,
        "two goers for {both} ticks, limit {limit} (backed off at {deferred_at:?})"
    );
    assert!(deferred_at.is_some(), "robot 2 backs off");
    assert!(
        handed_over,
        "once robot 1 hears robot 2 again, robot 2 goes alone"
    );
    // Without the rule, both go for as long as robot 2's burst lasts.
    let (both_without, _, _) = unacknowledged_claim(Duration::from_secs(10));
    assert!(
        both_without >= 45,
        "without the acknowledgement rule two goers for {both_without} ticks"
    );
}

#[test]
fn a_goer_that_gives_up_frees_the_ball_at_once_and_a_silent_one_does_not() {
    // Robot 1 goes at 1.0 m, robot 2 waits at 2.0 m. From tick 50 robot 1's frames are
    // lost for 600 ms (it keeps going: silence); at tick 150 robot 1 loses the ball
    // and says so (the no-ball cost).
    let p = ArbitrationParams {
        listen_for: Duration::ZERO,
        ..Default::default()
    };
    let mut pair = Pair::new(p, 2);
    let mut first_go_2 = None;
    for k in 0..200 {
        let h1 = if k < 150 { 1.0 } else { p.no_ball_cost };
        let going = pair.tick(k, [h1, 2.0], |from| from == 0 && (50..110).contains(&k));
        if (20..150).contains(&k) {
            assert_eq!(going, [true, false], "tick {k}: robot 1 keeps the ball");
        } else if going[1] && first_go_2.is_none() {
            first_go_2 = Some(k);
        }
    }
    assert!(
        first_go_2.is_some_and(|k| k <= 150 + 2 + 1),
        "robot 2 takes over one latency after the give-up, at {first_go_2:?}"
    );
}

/// Under a league's budget a claim waits seconds for a frame. Robot 3 took the ball while
/// alone; its claim to be going has not gone out, so teammates hold its last message:
/// cost 1.0, not going. Robot 2 then tells cost 0.8. Teammates weigh 0.8 against 1.0 and
/// see robot 2 as the goer. Robot 3 must weigh the same: were its untold claim to count
/// with the hysteresis margin (1.0 − 0.5 beats 0.8), it would go on beside robot 2.
#[test]
fn a_claim_teammates_have_not_heard_earns_no_margin() {
    let p = ArbitrationParams {
        stale_after: Duration::from_secs(15),
        ..ArbitrationParams::default()
    };
    let tick = Duration::from_millis(40);
    let told_not_going = Posted {
        h: 1.0,
        going: false,
    };
    for (told, goes_on) in [
        // Deciding on its told cost only, with its own going (the old rule): both go.
        (None, true),
        // Deciding on the whole claim teammates hold: robot 2 alone goes.
        (Some(told_not_going), false),
    ] {
        let mut a = Arbiter::new(3, false, p);
        // Alone, past its listening time: it goes.
        for _ in 0..5 {
            a.tick(tick, 1.0, &[]);
        }
        assert!(a.going(), "alone, robot 3 goes");
        match told {
            None => a.set_told_cost(Some(1.0)),
            Some(t) => a.set_told(Some(t)),
        }
        let (decision, posted) = a.tick(tick, 1.0, &[fresh(2, 0.8, false)]);
        assert_eq!(
            posted.going,
            goes_on,
            "told {told:?}: robot 3 {} going",
            if goes_on { "keeps" } else { "stops" }
        );
        let teammates = decide(&p, &[fresh(2, 0.8, false), fresh(3, 1.0, false)]);
        assert_eq!(teammates.goer, Some(2), "teammates see robot 2 as the goer");
        if told.is_some() {
            assert_eq!(decision.goer, teammates.goer, "robot 3 agrees with them");
        }
    }
}

#[test]
fn claims_are_read_from_each_robots_scope_as_the_pattern_reads_them() {
    // `heard` looks the path up in each robot's scope instead of walking the pattern: it
    // must find what the pattern finds, and nothing in the local scope.
    use crate::{Pattern, Scope};
    assert_eq!(heuristic_key().path(), HEURISTIC_PATH);
    let mut board = Blackboard::new(3);
    let t0 = Instant::from_micros(2_000_000);
    let claim = Posted {
        h: 0.7,
        going: false,
    };
    board.set(t0, &heuristic_key(), claim.into()).unwrap();
    board
        .set(
            t0,
            &Key::parse("local.var.machine.heuristic").unwrap(),
            claim.into(),
        )
        .unwrap();
    let now = Instant::from_micros(2_100_000);
    let pattern = Pattern::parse(HEURISTIC_PATTERN).unwrap();
    let by_pattern: Vec<(u8, Duration)> = board
        .iter(&pattern)
        .filter_map(|(key, e)| match key.scope() {
            Scope::Robot(r) => Some((r, e.age(now))),
            _ => None,
        })
        .collect();
    let got: Vec<(u8, Duration)> = heard(&board, now)
        .iter()
        .map(|c| (c.robot, c.age))
        .collect();
    assert_eq!(got, by_pattern, "heard and the pattern disagree");
    assert_eq!(got, vec![(3, Duration::from_millis(100))]);
}
