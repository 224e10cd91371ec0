//! A league's message budget in the simulated match: the SPL's 1,200 messages per team
//! per 20-minute game (about one a second for the whole team) and 128-byte frames, on the
//! `competition` network, the set-up: seeds 1–3, the first half (600 s).
//!
//! Claims:
//! - neither policy spends more than the game's budget allows by then (1,200 per 1,200 s:
//!   600 by 600 s), and both spend most of it; no frame is over 128 bytes;
//! - both policies agree on one goer at least 95% of the ball-visible time: priority
//!   frames (goer changes, kicks) share the team's room beyond its pacing, so a goer's
//!   stop is told at once (see `comms::TeamPool`); with a reserve per robot they were at
//!   about 92%;
//! - huddle's VOI policy gives the robots that do not see the ball a better team ball
//!   than B-Human's limiter at the same budget: at most 0.9× its RMSE on each seed and
//!   0.85× over the three; and its robots agree on one goer about as often: over the
//!   three seeds no more than a point less.
//!
//! The targets are 0.8× the baseline's blind RMSE and one goer at least the
//! baseline's. Seeds 1–3: blind ratio 0.77 / 0.82 / 0.79 (0.79 over the three); one goer
//! VOI 96.6 / 97.4 / 98.2% against 99.1 / 96.1 / 95.9% (97.4 against 97.0 over the three).
//! Per seed both figures move by more than the margins the targets leave: a change that
//! alters no decision (a world model no longer sent twice in one frame, so frames a few
//! dozen bytes shorter) took seed 2's ratio from 0.72 to 0.82 and seed 1's one goer from
//! 98.1 to 96.6%. Over seeds 4–27 (tuning) and 28–51 (not tuned on): blind 0.91 / 0.90 m
//! against 1.45 / 1.44 m, at most 0.8× on 46 of 48 seeds; one goer 98.4 / 98.1% against
//! 97.5 / 96.8%, at or above on 39 of 48. So this test asserts what holds with room:
//! the figures for the issue are in `huddle sim --budget spl --policy voi|baseline`.
use huddle::sim::policy::SendPolicy;
use huddle::sim::{Report, SimConfig, Simulation};

fn play(policy: SendPolicy, seed: u64) -> Report {
    let mut cfg = SimConfig {
        duration_s: 600.0,
        seed,
        budget: Some(comms::BudgetSpec::SPL),
        ..SimConfig::default()
    };
    cfg.network.preset = netsim::Preset::Competition;
    cfg.brain.team.send_policy = policy;
    let mut sim = Simulation::new(cfg).expect("a valid configuration");
    sim.run(|_| {});
    sim.report(0.0)
}

#[test]
fn under_the_spl_budget_voi_tells_blind_robots_better_than_b_humans_limiter() {
    let (mut blind, mut one_goer) = ([0.0; 2], [0.0; 2]);
    for seed in 1..=3 {
        let baseline = play(SendPolicy::Baseline, seed);
        let voi = play(SendPolicy::Voi, seed);
        for (k, (name, r)) in [("baseline", &baseline), ("voi", &voi)]
            .into_iter()
            .enumerate()
        {
            eprintln!(
                "seed {seed} {name}: {} messages {:?}, max {} B, blind team ball {:.3} m ({} samples), one goer {:.2}%",
                r.team_messages_sent,
                r.messages_per_robot,
                r.max_payload_bytes,
                r.blind_team_ball_rmse_m,
                r.blind_samples,
                r.exactly_one_goer_pct
            );
            assert!(
                r.team_messages_sent <= 600,
                "seed {seed} {name}: {} messages in 600 s of an SPL game (1,200 per 1,200 s)",
                r.team_messages_sent
            );
            assert!(
                r.team_messages_sent >= 500,
                "seed {seed} {name}: the budget is there to be spent: {} of 600",
                r.team_messages_sent
            );
            assert!(
                r.max_payload_bytes <= 128,
                "seed {seed} {name}: a {} B frame breaks the SPL's 128-byte limit",
                r.max_payload_bytes
            );
            assert!(
                r.blind_samples > 1000,
                "seed {seed} {name}: robots were blind at times"
            );
            blind[k] += r.blind_team_ball_rmse_m / 3.0;
            one_goer[k] += r.exactly_one_goer_pct / 3.0;
        }
        let ratio = voi.blind_team_ball_rmse_m / baseline.blind_team_ball_rmse_m;
        assert!(
            ratio <= 0.9,
            "seed {seed}: VOI's blind robots must know the ball better: {:.3} m vs the \
             baseline's {:.3} m ({ratio:.2}×, at most 0.9×)",
            voi.blind_team_ball_rmse_m,
            baseline.blind_team_ball_rmse_m
        );
    }
    for (k, name) in ["baseline", "voi"].iter().enumerate() {
        assert!(
            one_goer[k] >= 95.0,
            "{name}: the team agrees on one goer {:.2}% of the time, under 95%",
            one_goer[k]
        );
    }
    assert!(
        blind[1] <= 0.85 * blind[0],
        "VOI's blind robots over seeds 1-3: {:.3} m vs the baseline's {:.3} m (at most 0.85×)",
        blind[1],
        blind[0]
    );
    assert!(
        one_goer[1] >= one_goer[0] - 1.0,
        "VOI must not cost the team its agreement on one goer: {:.2}% vs {:.2}% over seeds 1-3",
        one_goer[1],
        one_goer[0]
    );
}
