//! A kick reported by the kicker: the team ball turns when the report arrives, not several
//! sightings later; and when the report comes after the cameras already restarted the
//! ball, the team ball rewinds to the kick instead of keeping the restart's guesswork.
//!
//! One sender (robot 1, standing 0.2 m behind the ball, facing it) publishes its LWM
//! at 25 Hz with a sighting per message; robot 2's GWM receives every message at once
//! (age 0). The ball rests at the origin until robot 1 kicks it along +x at 4 m/s at
//! t = 1 s. No friction, so the truth is x = 4 (t − 1).

mod kick_scenario;

use fusion::nalgebra::{Matrix2, Vector2, Vector3};
use fusion::{
    BallSighting, GlobalConfig, GlobalModel, LocalConfig, LocalModel, LocalWorldModel, PoseEstimate,
};
use kick_scenario::{kick, local_model, model, sighting, truth_x, KICK_T_S, PERIOD_S};

/// Robot 1's messages up to and including `until_s`, as robot 2 receives them; the kick
/// is left out of the messages sent before `kick_reported_from_s`.
fn messages(until_s: f64, kick_reported_from_s: f64) -> Vec<(f64, Vec<u8>)> {
    let mut sender = local_model(0.2);
    let mut out = Vec::new();
    let mut k = 0;
    loop {
        let t_s = k as f64 * PERIOD_S;
        if t_s > until_s + 1e-9 {
            return out;
        }
        // Robot frame: +x right (field +x), +y forward (field +y); the ball is 0.2 m ahead.
        sender.ball_sighting(t_s, &sighting(truth_x(t_s), 0.2));
        let mut msg: LocalWorldModel = sender.publish(t_s);
        if t_s < kick_reported_from_s - 1e-9 {
            msg.kick = None;
        }
        out.push((t_s, msg.to_bytes().expect("encodes").to_vec()));
        if (t_s - KICK_T_S).abs() < 1e-9 {
            // The foot meets the ball right after this tick's message.
            sender.kick(&kick());
        }
        k += 1;
    }
}

fn team_ball_error_m(gwm: &GlobalModel, t_s: f64) -> f64 {
    let team = gwm.team_ball(t_s, None).expect("a team ball");
    (team.estimate.position() - Vector2::new(truth_x(t_s), 0.0)).norm()
}

fn gwm() -> GlobalModel {
    GlobalModel::new(
        2,
        GlobalConfig {
            ball: model(),
            ..GlobalConfig::default()
        },
    )
}

#[test]
fn a_reported_kick_turns_the_team_ball_with_the_first_message_after_it() {
    let mut with_report = gwm();
    let mut without = gwm();
    for (t_s, bytes) in messages(KICK_T_S + PERIOD_S, 0.0) {
        with_report.receive(1, &bytes, t_s, 0.0).expect("valid");
        let mut lwm = LocalWorldModel::from_bytes(&bytes, t_s).expect("valid");
        lwm.kick = None;
        without.ingest(1, &lwm, t_s);
    }
    // 160 ms after the kick, one message (one sighting) after it has arrived.
    let at_s = KICK_T_S + 0.16;
    let (e_with, e_without) = (
        team_ball_error_m(&with_report, at_s),
        team_ball_error_m(&without, at_s),
    );
    assert_eq!(with_report.stats().kicks, 1, "the kick is applied once");
    assert!(
        e_with < 0.05,
        "with the kick report the team ball is {e_with:.3} m off 160 ms after the kick"
    );
    assert!(
        e_without > 0.3,
        "without it a single sighting cannot turn the ball yet ({e_without:.3} m off): \
         this test would not show what the report buys"
    );
}

#[test]
fn a_kick_reported_after_the_cameras_restarted_the_ball_rewinds_to_the_kick() {
    // The kick reaches robot 2 only with the third message after it (the first two lost
    // it): that message's sighting is the third off the old track, which restarts the team
    // ball from the first of them with no idea of its velocity, just before the kick is read.
    let report_s = KICK_T_S + 3.0 * PERIOD_S;
    let mut late = gwm();
    let mut never = gwm();
    for (t_s, bytes) in messages(report_s, report_s) {
        late.receive(1, &bytes, t_s, 0.0).expect("valid");
        let mut lwm = LocalWorldModel::from_bytes(&bytes, t_s).expect("valid");
        lwm.kick = None;
        never.ingest(1, &lwm, t_s);
    }
    assert!(
        never.stats().restarts >= 1,
        "the sightings alone restart the ball (stats {:?})",
        never.stats()
    );
    assert_eq!(late.stats().kicks, 1);
    let at_s = report_s + 0.2;
    let (e_late, e_never) = (
        team_ball_error_m(&late, at_s),
        team_ball_error_m(&never, at_s),
    );
    // The sightings are noise-free, so the rewound track is the truth itself; fusing the
    // kick's velocity into the restarted track instead (what happens when there is no
    // track to rewind to) leaves it ~1 cm off.
    assert!(
        e_late < 0.002,
        "the late report places the kick at its time: {e_late:.4} m off"
    );
    assert!(
        e_late < 0.5 * e_never,
        "the rewind must beat the restart's own track ({e_late:.3} m vs {e_never:.3} m)"
    );
}

#[test]
fn a_kick_repeated_in_later_messages_is_applied_once() {
    // The report rides in every message for 150 ms: four messages here.
    let mut gwm = gwm();
    let mut carried = 0;
    for (t_s, bytes) in messages(KICK_T_S + 0.3, 0.0) {
        let lwm = LocalWorldModel::from_bytes(&bytes, t_s).expect("valid");
        carried += usize::from(lwm.kick.is_some());
        gwm.receive(1, &bytes, t_s, 0.0).expect("valid");
    }
    assert!(carried >= 3, "the report is repeated ({carried} messages)");
    assert_eq!(gwm.stats().kicks, 1, "one kick, however often reported");
    let e = team_ball_error_m(&gwm, KICK_T_S + 0.4);
    assert!(
        e < 0.05,
        "the team ball follows the kicked ball: {e:.3} m off"
    );
}

#[test]
fn a_kick_claimed_far_from_the_ball_is_refused() {
    // Robot 3 stands 4 m from the ball and claims to have kicked it: robot 1, which sees
    // the ball, keeps reporting it at rest, and the team ball must stay put.
    let mut gwm = gwm();
    let liar_pose = PoseEstimate::new(-4.0, 0.0, 0.0, Vector3::new(1e-3, 1e-3, 1e-4));
    let mut liar = LocalModel::new(LocalConfig::default(), liar_pose);
    let mut still = messages(2.0, 0.0);
    // Robot 1's ball never moves in this test: its sightings after the kick time are
    // replaced by sightings of the ball at rest.
    let rest = PoseEstimate::new(0.0, -2.0, 0.0, Vector3::new(1e-4, 1e-4, 1e-5));
    let mut sender = LocalModel::new(LocalConfig::default(), rest);
    still.clear();
    for k in 0..=50 {
        let t_s = k as f64 * PERIOD_S;
        sender.ball_sighting(
            t_s,
            &BallSighting {
                local: Vector2::new(0.0, 2.0),
                cov: Matrix2::identity() * 4e-4,
            },
        );
        still.push((t_s, sender.publish(t_s).to_bytes().unwrap().to_vec()));
    }
    for (t_s, bytes) in still {
        gwm.receive(1, &bytes, t_s, 0.0).expect("valid");
        if (t_s - KICK_T_S).abs() < 1e-9 {
            liar.kick(&kick());
        }
        if t_s >= KICK_T_S - 1e-9 {
            let lie = liar.publish(t_s);
            gwm.receive(3, &lie.to_bytes().unwrap(), t_s, 0.0)
                .expect("valid");
        }
    }
    assert_eq!(gwm.stats().kicks, 0, "no kick taken: {:?}", gwm.stats());
    assert!(gwm.stats().kicks_refused >= 1, "{:?}", gwm.stats());
    let team = gwm.team_ball(2.0, None).expect("a team ball");
    assert!(
        team.estimate.position().norm() < 0.05 && team.estimate.velocity().norm() < 0.2,
        "the team ball stays at rest: {}",
        team.estimate.mean
    );
}
