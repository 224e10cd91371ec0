//! Byte fixtures from the published header layout, round trips, property tests of the
//! decoders on arbitrary bytes, the tracker's ordering and the budget's figures.

use std::net::SocketAddr;
use std::time::Duration;

use proptest::prelude::*;

use crate::*;

fn gc() -> SocketAddr {
    "10.1.2.3:3838".parse().unwrap()
}

fn secs(s: u64) -> Duration {
    Duration::from_secs(s)
}

/// An RGme packet written field by field from `RoboCupGameControlData.h`, independently
/// of the encoder: team 12 (blue) against 34 (red), Playing in the second half after a
/// corner kick for 34, 1:40 left, player 3 of team 12 penalized (pushing, 27 s).
fn golden_control() -> Vec<u8> {
    let mut b = Vec::new();
    b.extend_from_slice(b"RGme");
    b.push(18); // version
    b.push(201); // packetNumber
    b.push(7); // playersPerTeam
    b.push(1); // competitionPhase: play-off
    b.push(0); // competitionType
    b.push(0); // gamePhase: normal
    b.push(3); // state: playing
    b.push(3); // setPlay: corner kick
    b.push(0); // firstHalf: no
    b.push(34); // kickingTeam
    b.extend_from_slice(&100i16.to_le_bytes()); // secsRemaining
    b.extend_from_slice(&(-5i16).to_le_bytes()); // secondaryTime
    for (team, colour, score, budget) in [(12u8, 0u8, 2u8, 431u16), (34, 1, 1, 1030)] {
        b.extend_from_slice(&[team, colour, colour, 1, score, 0]);
        b.extend_from_slice(&0x0102u16.to_le_bytes()); // singleShots
        b.extend_from_slice(&budget.to_le_bytes()); // messageBudget
        for p in 1..=20u8 {
            if team == 12 && p == 3 {
                b.extend_from_slice(&[2, 27]);
            } else if p > 7 {
                b.extend_from_slice(&[14, 0]);
            } else {
                b.extend_from_slice(&[0, 0]);
            }
        }
    }
    b
}

#[test]
fn rgme_golden_bytes_decode_to_the_fields_the_header_defines() {
    let bytes = golden_control();
    assert_eq!(bytes.len(), 118, "the C struct is 118 bytes");
    let d = GameControlData::decode(&bytes).expect("a valid packet");
    assert_eq!(d.packet_number, 201);
    assert_eq!(d.players_per_team, 7);
    assert_eq!(d.competition_phase, 1);
    assert_eq!(d.game_phase, GamePhase::Normal);
    assert_eq!(d.state, State::Playing);
    assert_eq!(d.set_play, SetPlay::CornerKick);
    assert!(!d.first_half);
    assert_eq!(d.kicking_team, 34);
    assert_eq!((d.secs_remaining, d.secondary_time), (100, -5));
    let us = d.team(12).expect("team 12 is in the packet");
    assert_eq!(
        (us.score, us.message_budget, us.single_shots),
        (2, 431, 0x0102)
    );
    assert_eq!(
        us.player(3),
        Some(&RobotInfo {
            penalty: 2,
            secs_till_unpenalised: 27
        })
    );
    assert_eq!(us.player(8).unwrap().penalty, PENALTY_SUBSTITUTE);
    assert_eq!(us.player(0), None, "players are numbered from 1");
    assert_eq!(us.player(21), None);
    assert_eq!(d.team(34).unwrap().message_budget, 1030);
    assert_eq!(
        d.encode().to_vec(),
        bytes,
        "the encoder writes the same bytes"
    );
}

/// An RGrt packet written from `RoboCupGameControlReturnData`: player 3 of team 12,
/// fallen, at (1500 mm, -200 mm, 0.5 rad), ball seen 1.25 s ago 800 mm ahead, 100 left.
#[test]
fn rgrt_golden_bytes_match_the_header_layout() {
    let mut b = Vec::new();
    b.extend_from_slice(b"RGrt");
    b.extend_from_slice(&[4, 3, 12, 1]);
    for f in [1500.0f32, -200.0, 0.5, 1.25, 800.0, 100.0] {
        b.extend_from_slice(&f.to_le_bytes());
    }
    assert_eq!(b.len(), 32, "the C struct is 32 bytes");
    let m = StatusMessage {
        player_num: 3,
        team_num: 12,
        fallen: true,
        pose: [1500.0, -200.0, 0.5],
        ball_age: 1.25,
        ball: [800.0, 100.0],
    };
    assert_eq!(m.encode().to_vec(), b);
    assert_eq!(StatusMessage::decode(&b), Ok(m));
}

#[test]
fn rgrt_never_carries_nan_and_the_ball_is_made_relative_to_the_robot() {
    let m = StatusMessage {
        pose: [f32::NAN, f32::INFINITY, 0.0],
        ball_age: f32::NAN,
        ..StatusMessage::new(2, 5)
    };
    let d = StatusMessage::decode(&m.encode()).expect("the GC's checks pass");
    assert_eq!(d.pose[0], 0.0);
    assert_eq!(d.pose[1], f32::MAX);
    assert_eq!(d.ball_age, -1.0, "a NaN age goes as unknown");

    // Robot at (1, 2) m facing +y; ball at (1, 3): one metre straight ahead.
    let inputs = StatusInputs {
        pose: Some([1.0, 2.0, std::f64::consts::FRAC_PI_2]),
        ball: Some(([1.0, 3.0], 0.4)),
        fallen: false,
    };
    let m = inputs.to_message(4, 12);
    assert_eq!(m.pose[..2], [1000.0, 2000.0]);
    assert!((m.ball[0] - 1000.0).abs() < 1e-3, "ahead: {:?}", m.ball);
    assert!(m.ball[1].abs() < 1e-3, "not to a side: {:?}", m.ball);
    assert!((m.ball_age - 0.4).abs() < 1e-6);

    // A ball without a pose cannot be made relative: unknown.
    let blind = StatusInputs {
        pose: None,
        ..inputs
    };
    assert_eq!(blind.to_message(4, 12).ball_age, -1.0);
    let nan_pose = StatusInputs {
        pose: Some([f64::NAN, 0.0, 0.0]),
        ..inputs
    };
    let m = nan_pose.to_message(4, 12);
    assert!(
        m.pose.iter().all(|v| v.is_finite()) && m.ball_age == -1.0,
        "{m:?}"
    );
}

#[test]
fn truncated_oversized_wrong_version_and_wrong_team_packets_are_errors() {
    let good = golden_control();
    assert!(matches!(
        GameControlData::decode(&good[..117]),
        Err(DecodeError::Length { len: 117, .. })
    ));
    let mut long = good.clone();
    long.push(0);
    assert!(matches!(
        GameControlData::decode(&long),
        Err(DecodeError::Length { len: 119, .. })
    ));
    let mut v17 = good.clone();
    v17[4] = 17;
    assert_eq!(
        GameControlData::decode(&v17),
        Err(DecodeError::WrongVersion(17))
    );
    let mut monitor = good.clone();
    monitor[0..4].copy_from_slice(b"RGTD");
    assert_eq!(
        GameControlData::decode(&monitor),
        Err(DecodeError::BadHeader)
    );
    let mut bad_state = good.clone();
    bad_state[10] = 6;
    assert!(matches!(
        GameControlData::decode(&bad_state),
        Err(DecodeError::BadField { field: "state", .. })
    ));
    assert_eq!(
        GameControlData::decode_for_team(&good, 99),
        Err(DecodeError::WrongTeam { teams: [12, 34] })
    );
    assert!(GameControlData::decode_for_team(&good, 34).is_ok());
}

#[test]
fn the_counting_rule_is_game_controller_3s() {
    let mut g = GameControlData::new([1, 2]);
    for (phase, state, counted) in [
        (GamePhase::Normal, State::Initial, false),
        (GamePhase::Normal, State::Standby, true),
        (GamePhase::Normal, State::Ready, true),
        (GamePhase::Normal, State::Set, true),
        (GamePhase::Normal, State::Playing, true),
        (GamePhase::Normal, State::Finished, false),
        (GamePhase::Timeout, State::Initial, false),
        (GamePhase::PenaltyShoot, State::Playing, false),
        (GamePhase::PenaltyShoot, State::Set, false),
    ] {
        g.game_phase = phase;
        g.state = state;
        assert_eq!(g.messages_counted(), counted, "{phase:?} {state:?}");
    }
}

#[test]
fn a_stale_or_reordered_packet_never_moves_the_game_backwards() {
    let mut t = GameTracker::new(12, 3);
    let mut g = GameControlData::new([12, 34]);
    let send = |t: &mut GameTracker, g: &GameControlData, at: Duration| {
        t.receive(at, gc(), &g.encode()).unwrap()
    };
    g.packet_number = 250;
    g.state = State::Set;
    assert_eq!(send(&mut t, &g, secs(10)), Received::Accepted);
    // Playing, numbered across the wrap.
    g.packet_number = 2;
    g.state = State::Playing;
    assert_eq!(
        send(&mut t, &g, secs(10) + Duration::from_millis(500)),
        Received::Accepted
    );
    // The Set packet arrives again, late: it is older.
    g.packet_number = 251;
    g.state = State::Set;
    assert_eq!(send(&mut t, &g, secs(11)), Received::Stale);
    assert_eq!(
        t.state(),
        Some(State::Playing),
        "the game did not go back to Set"
    );
    // A duplicate of the newest is stale too.
    g.packet_number = 2;
    assert_eq!(send(&mut t, &g, secs(11)), Received::Stale);
    assert_eq!(t.stats().stale, 2);
    // Reordered packet 0 just before 2 (2 behind): stale, not a GC restart.
    g.packet_number = 0;
    assert_eq!(send(&mut t, &g, secs(11)), Received::Stale);
    // After 2 s of silence the next packet is taken whatever its number.
    g.packet_number = 200;
    g.state = State::Ready;
    assert_eq!(send(&mut t, &g, secs(14)), Received::Accepted);
    assert_eq!(t.state(), Some(State::Ready));
    // A restarted GC numbers from 0: taken at once.
    g.packet_number = 0;
    g.state = State::Initial;
    assert_eq!(
        send(&mut t, &g, secs(14) + Duration::from_millis(500)),
        Received::Accepted
    );
    assert_eq!(t.state(), Some(State::Initial));
}

#[test]
fn bad_packets_are_counted_and_leave_the_game_as_it_was() {
    let mut t = GameTracker::new(12, 3);
    let good = golden_control();
    t.receive(secs(1), gc(), &good).unwrap();
    let before = *t.game().unwrap();
    let mut v19 = good.clone();
    v19[4] = 19;
    let mut other = GameControlData::new([5, 6]);
    other.packet_number = 202;
    let mut bad_phase = good.clone();
    bad_phase[5] = 202;
    bad_phase[9] = 9;
    let inputs: Vec<Vec<u8>> = vec![
        good[..60].to_vec(),
        [good.clone(), vec![0; 10]].concat(),
        v19,
        other.encode().to_vec(),
        bad_phase,
        b"RGTD".to_vec(),
        vec![],
    ];
    for bytes in &inputs {
        assert!(
            t.receive(secs(2), gc(), bytes).is_err(),
            "{} bytes",
            bytes.len()
        );
    }
    assert_eq!(t.game(), Some(&before), "nothing held changed");
    let s = t.stats();
    assert_eq!(
        (
            s.bad_length,
            s.wrong_version,
            s.wrong_team,
            s.bad_field,
            s.bad_header
        ),
        (3, 1, 1, 1, 1),
        "{s:?}"
    );
    assert_eq!(s.bad(), 7);
    assert_eq!(s.accepted, 1);
}

#[test]
fn the_tracker_shows_this_teams_and_this_robots_figures() {
    let mut t = GameTracker::new(12, 3);
    assert_eq!(t.state(), None, "nothing heard yet");
    t.receive(secs(1), gc(), &golden_control()).unwrap();
    assert_eq!(t.score(), Some(2));
    assert_eq!(t.message_budget(), Some(431));
    assert_eq!(t.own_penalty(), Some(2));
    assert_eq!(t.own_secs_till_unpenalised(), Some(27));
    assert_eq!(t.penalized(), Some(true));
    assert_eq!(t.we_kick(), Some(false));
    assert_eq!(t.set_play(), Some(SetPlay::CornerKick));
    assert_eq!(t.opponent().unwrap().team_number, 34);
    assert_eq!(t.messages_counted(), Some(true));
    assert_eq!(t.gc_address(), Some("10.1.2.3:3939".parse().unwrap()));
    assert!(t.is_live(secs(2), secs(2)) && !t.is_live(secs(4), secs(2)));
    let other = GameTracker::new(34, 3);
    assert_eq!(other.message_budget(), None);
}

fn playing(budget: u16, secs_remaining: i16, first_half: bool) -> GameControlData {
    let mut g = GameControlData::new([12, 34]);
    g.state = State::Playing;
    g.first_half = first_half;
    g.secs_remaining = secs_remaining;
    g.team_mut(12).unwrap().message_budget = budget;
    g
}

/// The figures the daemon's listener hands to `comms` (`driver::budget_figures`): the
/// GC's budget less the margin, counted or not, and the game time left over the halves.
#[test]
fn the_gcs_figures_give_the_team_its_budget_less_the_margin_and_the_games_time_left() {
    let b = GcBudget::spl(5);
    assert_eq!(b.margin, 14, "two frames per robot and four more");
    for (budget, left) in [(0u16, 0u32), (14, 0), (15, 1), (950, 936)] {
        let cap = b.cap(&playing(budget, 300, false), 12).unwrap();
        assert_eq!(cap.team_left, left, "{budget} left by the GC");
        assert_eq!(cap.message_budget, budget);
        assert!(cap.counted, "Playing is counted");
    }
    assert_eq!(
        b.cap(&playing(950, 300, false), 99),
        None,
        "not this team's game"
    );
    // First half, 300 s left: 900 s of game to go.
    let g = playing(920, 300, true);
    assert_eq!(b.game_remaining(&g), secs(900));
    // Over time: none left of this half, never a negative time.
    assert_eq!(b.game_remaining(&playing(920, -5, false)), secs(0));
    // The half-time break is not counted, and the clock stands at the second half.
    let mut brk = playing(400, 0, true);
    brk.state = State::Finished;
    let cap = b.cap(&brk, 12).unwrap();
    assert!(!cap.counted, "the break costs nothing");
    assert_eq!(cap.game_remaining, secs(600), "the second half's 600 s");
    // The penalty shoot-out is not counted and has no game time.
    let mut shoot = playing(3, 0, false);
    shoot.game_phase = GamePhase::PenaltyShoot;
    let cap = b.cap(&shoot, 12).unwrap();
    assert!(!cap.counted && cap.game_remaining == secs(0));
    // Two minutes of extra time: the GC's 120 messages and 120 s more reach the figures.
    let extra = b.cap(&playing(20 + 120, 120, false), 12).unwrap();
    assert_eq!(extra.team_left, 20 + 120 - 14);
    assert_eq!(extra.game_remaining, secs(120));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    /// Any bytes: the decoders return, never panic, and whatever they accept re-encodes
    /// to the same bytes (nothing was misread).
    #[test]
    fn decoders_take_any_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
        if let Ok(d) = GameControlData::decode(&bytes) {
            prop_assert_eq!(d.encode().to_vec(), bytes.clone());
        }
        if let Ok(m) = StatusMessage::decode(&bytes) {
            prop_assert_eq!(m.encode().to_vec(), bytes);
        }
    }

    /// A valid header on random bodies: decoded exactly or rejected for a named field.
    #[test]
    fn rgme_bodies_decode_exactly_or_name_their_bad_field(body in proptest::collection::vec(any::<u8>(), 113)) {
        let mut bytes = b"RGme\x12".to_vec();
        bytes.extend_from_slice(&body);
        match GameControlData::decode(&bytes) {
            Ok(d) => prop_assert_eq!(d.encode().to_vec(), bytes),
            Err(DecodeError::BadField { .. }) => {}
            Err(e) => prop_assert!(false, "unexpected {:?}", e),
        }
    }

    /// Truncating or extending a valid packet is always an error.
    #[test]
    fn any_other_length_is_an_error(len in 0usize..300) {
        prop_assume!(len != GAMECONTROLLER_STRUCT_SIZE);
        let mut bytes = golden_control();
        bytes.resize(len, 0);
        prop_assert!(GameControlData::decode(&bytes).is_err());
    }

    /// Whatever order packets arrive in, the tracker's packet number only moves forward
    /// (modulo 256, by at most 127) while the GC is heard, but for a GC restarted at 0.
    #[test]
    fn the_tracker_only_moves_forward(order in proptest::collection::vec(0u8..40, 1..60)) {
        let mut t = GameTracker::new(12, 3);
        let mut g = GameControlData::new([12, 34]);
        let mut last: Option<u8> = None;
        for (i, n) in order.iter().enumerate() {
            g.packet_number = n.wrapping_add(250);
            let at = Duration::from_millis(i as u64 * 10);
            t.receive(at, gc(), &g.encode()).unwrap();
            let now = t.game().unwrap().packet_number;
            if let Some(l) = last {
                let ahead = now.wrapping_sub(l);
                let restart = now == 0 && (128..=239).contains(&ahead);
                prop_assert!(ahead <= 127 || restart, "{} after {}", now, l);
            }
            last = Some(now);
        }
    }

    /// Encode then decode is the identity for every valid value.
    #[test]
    fn rgrt_round_trips(p in 1u8..=20, t in any::<u8>(), f in any::<bool>(),
                        x in -1e4f32..1e4, y in -1e4f32..1e4, a in -4f32..4.0, age in -1f32..100.0) {
        let m = StatusMessage { player_num: p, team_num: t, fallen: f, pose: [x, y, a], ball_age: age, ball: [y, x] };
        prop_assert_eq!(StatusMessage::decode(&m.encode()), Ok(m));
    }
}
