//! The team ball on seeded five-robot scenarios: as good as a centralized filter, honest
//! about its uncertainty, deaf to one liar, quick to follow a kick, and on its own when
//! everyone else falls silent.

mod scenario;

use fusion::nalgebra::{Vector2, Vector4};
use fusion::TeamBallSource;
use scenario::{nees4, nees_bounds, position_error, run, Liar, Record, Scenario};

struct Summary {
    team_rmse_m: f64,
    central_rmse_m: f64,
    own_rmse_m: f64,
    team_anees: f64,
    own_anees: f64,
    central_anees: f64,
}

/// RMSE and average NEES over all records of all runs (every robot's team ball counts).
fn summarise(runs: &[Vec<Record>]) -> Summary {
    let (mut te, mut ce, mut oe, mut tn, mut on, mut cn) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut nt, mut nc, mut no) = (0usize, 0usize, 0usize);
    for rec in runs.iter().flatten() {
        for team in rec.team.iter().flatten() {
            te += position_error(&team.estimate, &rec.truth).powi(2);
            tn += nees4(&team.estimate, &rec.truth);
            nt += 1;
        }
        for own in rec.own.iter().flatten() {
            oe += position_error(own, &rec.truth).powi(2);
            on += nees4(own, &rec.truth);
            no += 1;
        }
        if let Some(c) = &rec.central {
            ce += position_error(c, &rec.truth).powi(2);
            cn += nees4(c, &rec.truth);
            nc += 1;
        }
    }
    Summary {
        team_rmse_m: (te / nt as f64).sqrt(),
        central_rmse_m: (ce / nc as f64).sqrt(),
        own_rmse_m: (oe / no as f64).sqrt(),
        team_anees: tn / nt as f64,
        own_anees: on / no as f64,
        central_anees: cn / nc as f64,
    }
}

fn report(label: &str, s: &Summary) {
    eprintln!(
        "{label}: team RMSE {:.4} m, centralized {:.4} m, ratio {:.3}; own-ball RMSE {:.4} m; ANEES team {:.3}, own {:.3}, centralized {:.3}",
        s.team_rmse_m,
        s.central_rmse_m,
        s.team_rmse_m / s.central_rmse_m,
        s.own_rmse_m,
        s.team_anees,
        s.own_anees,
        s.central_anees
    );
}

#[test]
fn team_ball_is_within_125_percent_of_centralized_and_honest_over_50_runs() {
    let runs: Vec<Vec<Record>> = (0..50).map(|seed| run(&Scenario::new(seed))).collect();
    let s = summarise(&runs);
    report("10% loss, 50 ms", &s);
    let (lo, hi) = nees_bounds(4, 50);
    let ratio = s.team_rmse_m / s.central_rmse_m;
    assert!(
        ratio <= 1.25,
        "team RMSE {:.4} m is {ratio:.3}× the centralized {:.4} m",
        s.team_rmse_m,
        s.central_rmse_m
    );
    assert!(
        (lo..=hi).contains(&s.team_anees),
        "team ANEES {:.3} outside [{lo:.3}, {hi:.3}]",
        s.team_anees
    );
    assert!(
        (lo..=hi).contains(&s.own_anees),
        "own-ball ANEES {:.3} outside [{lo:.3}, {hi:.3}]",
        s.own_anees
    );
    assert!(
        s.team_rmse_m < s.own_rmse_m,
        "fusing the team must beat one robot alone"
    );
}

#[test]
fn at_30_percent_loss_and_100_ms_the_team_ball_loses_a_little_accuracy_but_stays_honest() {
    let runs: Vec<Vec<Record>> = (0..20)
        .map(|seed| {
            let mut sc = Scenario::new(100 + seed);
            sc.loss = 0.3;
            sc.latency_s = 0.1;
            run(&sc)
        })
        .collect();
    let s = summarise(&runs);
    report("30% loss, 100 ms", &s);
    let (lo, hi) = nees_bounds(4, 20);
    // Each message repeats the two batches before it, so a batch is lost only when three
    // messages in a row are (2.7% at 30% independent loss); what remains is mostly the
    // 100 ms delay. Honesty must not suffer.
    assert!(
        s.team_rmse_m / s.central_rmse_m <= 1.3,
        "ratio {:.3}",
        s.team_rmse_m / s.central_rmse_m
    );
    assert!(
        (lo..=hi).contains(&s.team_anees),
        "team ANEES {:.3} outside [{lo:.3}, {hi:.3}]",
        s.team_anees
    );
}

/// Share of the honest robots' team-ball samples within `radius_m` of the truth in a window.
fn share_within(
    recs: &[Record],
    honest: &[usize],
    from_s: f64,
    to_s: f64,
    radius_m: f64,
) -> (f64, f64) {
    let (mut good, mut all, mut worst) = (0usize, 0usize, 0.0f64);
    for rec in recs.iter().filter(|r| (from_s..to_s).contains(&r.t_s)) {
        for &i in honest {
            let team = rec.team[i].expect("every robot has a team ball");
            let e = position_error(&team.estimate, &rec.truth);
            worst = worst.max(e);
            all += 1;
            good += usize::from(e <= radius_m);
        }
    }
    (good as f64 / all as f64, worst)
}

#[test]
fn a_phantom_ball_two_metres_away_for_five_seconds_cannot_drag_the_team_ball() {
    for (loss, latency_s) in [(0.1, 0.05), (0.3, 0.1)] {
        let mut shares = Vec::new();
        for seed in 0..10 {
            let mut sc = Scenario::new(200 + seed);
            sc.loss = loss;
            sc.latency_s = latency_s;
            sc.record_every = 1;
            // The ball rolls slowly through the middle, in sight of most robots.
            sc.ball_start = Some(Vector4::new(-0.8, 0.0, 0.2, 0.1));
            // Robot 3 sits near the ball and reports it 2 m off, 5 s long.
            sc.liar = Some(Liar {
                robot: 3,
                from_s: 6.0,
                to_s: 11.0,
                offset_m: Vector2::new(1.2, 1.6),
            });
            let recs = run(&sc);
            let (share, worst) = share_within(&recs, &[0, 1, 2, 4], 6.0, 11.0, 0.3);
            assert!(
                share >= 0.99,
                "seed {}, {:.0}% loss, {:.0} ms: team ball within 0.3 m only {:.1}% of the time (worst {worst:.2} m)",
                sc.seed,
                loss * 100.0,
                latency_s * 1000.0,
                share * 100.0
            );
            shares.push(share);
        }
        eprintln!(
            "phantom at {:.0}% loss, {:.0} ms: within 0.3 m {:?}",
            loss * 100.0,
            latency_s * 1000.0,
            shares
        );
    }
}

/// Two robots each hold a phantom ball, 1.5 m and 2.2 m off and wide enough to agree
/// with each other, while three teammates track the real one (seed 517 of the drawn
/// simulator: the goalkeeper's and a defender's false balls moved every robot's team
/// ball 7 m for a tick). Two dissenters must not outvote three supporters.
#[test]
fn two_agreeing_phantoms_cannot_outvote_three_robots_that_see_the_ball() {
    let mut moved = Vec::new();
    for seed in 0..10 {
        let mut sc = Scenario::new(700 + seed);
        sc.record_every = 1;
        sc.ball_start = Some(Vector4::new(-0.8, 0.0, 0.2, 0.1));
        sc.liar = Some(Liar {
            robot: 3,
            from_s: 6.0,
            to_s: 11.0,
            offset_m: Vector2::new(1.2, 0.9),
        });
        sc.second_liar = Some(Liar {
            robot: 4,
            from_s: 6.0,
            to_s: 11.0,
            offset_m: Vector2::new(1.8, 1.3),
        });
        let recs = run(&sc);
        let (share, worst) = share_within(&recs, &[0, 1, 2], 6.0, 11.0, 0.3);
        moved.push((sc.seed, share, worst));
    }
    eprintln!("two phantoms: (seed, share within 0.3 m, worst m) {moved:?}");
    // A tie may still restart by design: when only two of the three have seen the ball
    // within the dissent window, two phantoms equal them. So at most one seed of ten may
    // move at all (before the rule, all ten moved, by 1.4-2.9 m).
    let dragged: Vec<_> = moved.iter().filter(|(_, share, _)| *share < 0.99).collect();
    assert!(
        dragged.len() <= 1,
        "the phantoms dragged the team ball of the robots that see the ball on {} seeds: \
         {dragged:?}",
        dragged.len()
    );
}

#[test]
fn a_kicked_ball_is_followed_within_half_a_second() {
    for seed in 0..10 {
        let mut sc = Scenario::new(300 + seed);
        sc.record_every = 1;
        sc.ball_start = Some(Vector4::new(-1.5, 0.0, 0.0, 0.0));
        // Kicked at 8 s towards the far side at 3 m/s: it travels ~6 m.
        sc.kicks = vec![(
            8.0,
            Vector2::new(2.4, 1.8 * if seed % 2 == 0 { 1.0 } else { -1.0 }),
        )];
        sc.duration_s = 12.0;
        let recs = run(&sc);
        // Nobody near the ball's path may lag more than 0.3 m from 0.5 s after the kick on,
        // while the ball is still rolling fast and in sight of several robots.
        let (share, worst) = share_within(&recs, &[0, 1, 2, 3, 4], 8.5, 10.0, 0.3);
        assert!(
            share >= 0.99,
            "seed {}: after the kick only {:.1}% within 0.3 m (worst {worst:.2} m)",
            sc.seed,
            share * 100.0
        );
    }
}

#[test]
fn when_every_teammate_falls_silent_the_team_ball_is_the_robots_own() {
    let mut sc = Scenario::new(400);
    sc.silent_from_s = Some(10.0);
    let recs = run(&sc);
    let before = recs.iter().find(|r| r.t_s > 9.0).unwrap();
    assert!(before
        .team
        .iter()
        .all(|t| t.unwrap().source == TeamBallSource::Fused));
    for rec in recs.iter().filter(|r| r.t_s > 11.2) {
        for (team, own) in rec.team.iter().zip(&rec.own) {
            let (team, own) = (team.unwrap(), own.unwrap());
            assert_eq!(
                team.source,
                TeamBallSource::OwnFallback,
                "at {:.2} s",
                rec.t_s
            );
            assert!(
                (team.estimate.mean - own.mean).norm() < 1e-9,
                "fallback is exactly the own ball"
            );
        }
    }
}
