//! The budget through a whole replica: what its frames carry and when they go.

use std::time::Duration;

use crate::{Budget, Instant, Key, Replica, ReplicaConfig, Value};

fn at(ms: u64) -> Instant {
    Instant::from_micros(ms * 1000)
}

/// Robot 1 (its own share) hears that the GameController leaves the team 5 frames;
/// teammate 2 then sends 3 frames it hears. Robot 1, which always has news, sends the 2
/// left and no more until the GC's next figure: the teammates' frames since the figure
/// use it up too.
#[test]
fn teammates_frames_heard_since_the_gcs_figure_count_against_it() {
    let budget = crate::BudgetSpec::SPL.share(5).split();
    let cfg = ReplicaConfig {
        budget: Some(budget),
        mtu: 128,
        ..ReplicaConfig::new(1, 1)
    };
    let mut r1 = Replica::new(cfg, 1, at(0)).unwrap();
    let mut r2 = Replica::new(ReplicaConfig::new(2, 1), 2, at(0)).unwrap();
    let from: std::net::SocketAddr = "127.0.0.1:2000".parse().unwrap();
    r1.set_game_clock(at(0), Duration::ZERO);
    r1.set_external_budget(Some(crate::ExternalCap {
        counted: true,
        team_left: 5,
        rate_per_s: 1.0,
        margin: 0,
    }));
    let x = Key::parse("*.var.x").unwrap();
    let mut sent = 0;
    for ms in (0..3000).step_by(10) {
        if ms < 30 {
            r2.set_key(at(ms), &x, Value::Int(ms as i64)).unwrap();
            r2.handle_timeout(at(ms));
            while let Some(t) = r2.poll_transmit() {
                r1.handle_datagram(at(ms), from, &t.payload);
            }
        }
        r1.handle_timeout(at(ms));
        r1.set_priority(at(ms), &x, Value::Int(ms as i64)).unwrap();
        while r1.poll_transmit().is_some() {
            sent += 1;
        }
    }
    let heard = r1.peers().map(|p| p.frames).sum::<u64>();
    assert!(heard >= 3, "robot 2's frames were heard: {heard}");
    assert!(
        sent <= 5u64.saturating_sub(heard),
        "{sent} sent with {heard} of the team's 5 heard"
    );
}

/// Drives a replica for `until_ms`, writing `*.var.x` every 10 ms and the priority key
/// `*.var.goer` at each of `priority_at`; returns when each frame went.
fn run(budget: Budget, until_ms: u64, priority_at: &[u64]) -> (Vec<u64>, Replica) {
    let cfg = ReplicaConfig {
        budget: Some(budget),
        mtu: 128,
        ..ReplicaConfig::new(3, 1)
    };
    let mut r = Replica::new(cfg, 1, at(0)).unwrap();
    let x = Key::parse("*.var.x").unwrap();
    let goer = Key::parse("*.var.goer").unwrap();
    let mut frames = Vec::new();
    for ms in (0..until_ms).step_by(10) {
        r.handle_timeout(at(ms));
        r.set_key(at(ms), &x, Value::Int(ms as i64)).unwrap();
        if priority_at.contains(&ms) {
            r.set_priority(at(ms), &goer, Value::Int(ms as i64))
                .unwrap();
        }
        while let Some(t) = r.poll_transmit() {
            assert!(t.payload.len() <= 128, "{} bytes", t.payload.len());
            frames.push(ms);
        }
    }
    (frames, r)
}

#[test]
fn a_budgeted_replica_sends_no_more_frames_than_its_share_and_paces_them() {
    // An SPL-like share: 24 messages over 24 s, 4 of them reserved.
    let budget = Budget {
        messages: 24,
        game: Duration::from_secs(24),
        reserve: 4,
        team: None,
    };
    let (frames, r) = run(budget, 30_000, &[]);
    assert_eq!(
        frames.len(),
        20,
        "20 ordinary frames, the reserve kept: {frames:?}"
    );
    assert!(
        frames.windows(2).all(|w| w[1] - w[0] >= 900),
        "about one a second, not a burst: {frames:?}"
    );
    assert_eq!(r.budget_status(), Some((20, 4)));
}

#[test]
fn a_priority_item_goes_at_once_from_the_reserve_and_the_budget_still_holds() {
    let budget = Budget {
        messages: 10,
        game: Duration::from_secs(10),
        reserve: 2,
        team: None,
    };
    let (frames, r) = run(budget, 12_000, &[500, 600, 5_500]);
    assert!(
        frames.contains(&500),
        "the first goer change goes at once: {frames:?}"
    );
    assert!(
        !frames.contains(&600),
        "the second waits: the reserve is paced over the game: {frames:?}"
    );
    assert!(
        frames.contains(&5_500),
        "half a game later the reserve has opened again: {frames:?}"
    );
    assert_eq!(frames.len(), 10, "never beyond the budget: {frames:?}");
    assert_eq!(r.budget_status(), Some((10, 0)));
}

#[test]
fn half_a_game_of_an_spl_robot_that_always_has_news_spends_half_its_share() {
    // An SPL robot of five: 240 messages per 1200 s, 48 reserved; a goer change every
    // second asks for the reserve far more often than it lasts.
    let budget = crate::BudgetSpec::SPL.share(5).split();
    let priority: Vec<u64> = (0..600_000).step_by(1000).collect();
    let (frames, r) = run(budget, 600_000, &priority);
    let (messages, reserve) = (240, 48);
    assert_eq!((budget.messages, budget.reserve), (messages, reserve));
    let ordinary_half = (messages - reserve) / 2;
    assert_eq!(
        frames.len() as u64,
        ordinary_half + reserve / 2,
        "half of the ordinary share and half of the reserve (it is paced too)"
    );
    assert_eq!(r.budget_status(), Some((120, 120)));
}

/// Under a budget the refresh rides along in the room a frame has left; a value that
/// is in the frame as news already is not sent a second time by it (it was: 26 of a
/// league's 128 bytes on a claim repeated).
#[test]
fn a_frame_carries_a_value_once_even_when_its_refresh_is_due() {
    let budget = crate::BudgetSpec::SPL.share(5);
    let cfg = ReplicaConfig::new(3, 1).with_budget(&crate::BudgetSpec::SPL, 5);
    assert_eq!(cfg.budget, Some(budget));
    let mut r = Replica::new(cfg, 1, at(0)).unwrap();
    let claim = crate::arbitration::heuristic_key();
    let other = Key::parse("*.var.other").unwrap();
    r.set_key(at(0), &other, Value::Int(1)).unwrap();
    let mut frames = Vec::new();
    for s in 1..=30u64 {
        let now = at(s * 1000);
        r.handle_timeout(now);
        let posted = crate::arbitration::Posted {
            h: s as f64,
            going: s % 2 == 0,
        };
        r.set_priority(now, &claim, Value::from(posted)).unwrap();
        while let Some(t) = r.poll_transmit() {
            frames.push(crate::wire::decode_frame(&t.payload, 1, None).unwrap());
        }
    }
    assert!(frames.len() >= 5, "{} frames", frames.len());
    let mut refreshed = 0;
    for f in &frames {
        let paths: Vec<&str> = f
            .items
            .iter()
            .filter_map(|i| match i {
                crate::wire::Item::Update { path, .. } => Some(path.as_str()),
                _ => None,
            })
            .collect();
        let claims = paths.iter().filter(|&&p| p == "machine.heuristic").count();
        assert_eq!(claims, 1, "frame {}: {paths:?}", f.seq);
        refreshed += paths.contains(&"other") as usize;
    }
    assert!(refreshed > 0, "the refresh still rides along");
}

/// Under a budget a frame leaves out its echo (5 bytes of clock estimate, which any
/// later frame can carry) rather than a changed value that fits without it: with a
/// team key a league frame is 16 bytes tighter.
#[test]
fn an_echo_gives_way_to_news_that_fits_without_it() {
    let key = [7u8; 32];
    let claim = crate::arbitration::heuristic_key();
    let blob = Key::parse("*.var.blob").unwrap();
    let from = std::net::SocketAddr::from(([127, 0, 0, 1], 2000));
    let posted = crate::arbitration::Posted {
        h: 1.0,
        going: true,
    };
    let mut crowded = 0;
    let known = crate::wire::KnownPaths::new(["machine.heuristic", "world.local"]).unwrap();
    for len in 20..=90 {
        let cfg = ReplicaConfig::new(3, 1)
            .with_budget(&crate::BudgetSpec::SPL, 5)
            .with_team_key(key)
            .with_known_paths(known.clone());
        let mut r3 = Replica::new(cfg, 3, at(0)).unwrap();
        let mut r1 = Replica::new(ReplicaConfig::new(1, 1).with_team_key(key), 1, at(0)).unwrap();
        r1.handle_timeout(at(0));
        r3.handle_timeout(at(0));
        while let Some(t) = r1.poll_transmit() {
            r3.handle_datagram(at(5), from, &t.payload);
        }
        let value = Value::Bytes(vec![0xab; len]);
        if r3.set_key(at(10), &blob, value.clone()).is_err() {
            // Too large for a league frame on its own: refused, nothing to weigh.
            continue;
        }
        r3.set_priority(at(10), &claim, Value::from(posted))
            .unwrap();
        r3.handle_timeout(at(10));
        let frame = r3.poll_transmit().expect("the claim goes").payload;
        assert!(frame.len() <= 128, "len {len}: {} bytes", frame.len());
        let decoded = crate::wire::decode_frame_with(
            &frame,
            1,
            Some(&crate::wire::TeamKey::new(&key)),
            &known,
        )
        .unwrap()
        .to_frame();
        // Both values, written as the replica does, in a frame without an echo.
        let tk = crate::wire::TeamKey::new(&key);
        let mut w =
            crate::wire::FrameWriter::new(1, 3, 3, 1, 128, Some(&tk)).with_known_paths(&known);
        let both = [(&claim, Value::from(posted)), (&blob, value)]
            .iter()
            .all(|(k, v)| {
                w.push(crate::wire::ItemRef::Update {
                    path: k.path(),
                    value: v,
                    version: 1,
                    age_us: 0,
                })
            });
        if both {
            assert_eq!(
                decoded.items.len(),
                2,
                "len {len}: both fit without an echo"
            );
        }
        if decoded.clock.echo.is_none() {
            assert!(both, "len {len}: the echo went for nothing");
            crowded += 1;
        } else {
            assert!(frame.len() <= 128);
        }
    }
    assert!(crowded > 0, "some length fits only without the echo");
}

/// A path the application registered goes as one byte, with or without a budget; one it
/// did not register goes as text.
#[test]
fn registered_paths_go_as_one_byte() {
    let claim = crate::arbitration::heuristic_key();
    let frame_len = |cfg: ReplicaConfig| {
        let mut r = Replica::new(cfg, 1, at(0)).unwrap();
        r.handle_timeout(at(0));
        while r.poll_transmit().is_some() {}
        let posted = crate::arbitration::Posted {
            h: 1.0,
            going: true,
        };
        r.set_priority(at(10), &claim, Value::from(posted)).unwrap();
        r.handle_timeout(at(10));
        r.poll_transmit().expect("the claim goes").payload.len()
    };
    let table = crate::wire::KnownPaths::new(["world.local", "machine.heuristic"]).unwrap();
    let text = frame_len(ReplicaConfig::new(3, 1));
    let known = frame_len(ReplicaConfig::new(3, 1).with_known_paths(table.clone()));
    let league = frame_len(
        ReplicaConfig::new(3, 1)
            .with_budget(&crate::BudgetSpec::SPL, 5)
            .with_known_paths(table),
    );
    assert_eq!(known, league, "a budget does not change the path's coding");
    let (free, league) = (text, known);
    assert_eq!(
        free - league,
        "machine.heuristic".len(),
        "{free} vs {league} bytes"
    );
}

#[test]
fn a_value_that_cannot_fit_the_leagues_payload_is_refused_when_set() {
    let cfg = ReplicaConfig {
        budget: Some(Budget {
            messages: 10,
            game: Duration::from_secs(10),
            reserve: 1,
            team: None,
        }),
        mtu: 128,
        ..ReplicaConfig::new(3, 1)
    };
    let mut r = Replica::new(cfg, 1, at(0)).unwrap();
    let err = r
        .set(at(0), "*.var.image", Value::Bytes(vec![0; 120]))
        .expect_err("120 bytes of value cannot fit a 128-byte frame");
    assert!(err.to_string().contains("128"), "{err}");
}

/// Five replicas of one team on a lossless network (every frame reaches every other
/// replica at once) for `until_ms`; robot `i` has news every 10 ms when
/// `chatty(i, ms)`. Returns the frames each sent.
fn team(budget: Budget, until_ms: u64, chatty: impl Fn(usize, u64) -> bool) -> Vec<u64> {
    let mut sent = vec![0u64; 5];
    for (i, _) in team_frames(budget, until_ms, chatty, |_, _| false) {
        sent[i] += 1;
    }
    sent
}

/// [`team`], where robot `i` also has a priority item at `ms` when `priority(i, ms)`.
/// Returns every frame as (robot, ms), in the order sent.
fn team_frames(
    budget: Budget,
    until_ms: u64,
    chatty: impl Fn(usize, u64) -> bool,
    priority: impl Fn(usize, u64) -> bool,
) -> Vec<(usize, u64)> {
    let mut team: Vec<Replica> = (0..5)
        .map(|i| {
            let cfg = ReplicaConfig {
                budget: Some(budget),
                mtu: 128,
                ..ReplicaConfig::new(i as u8 + 1, 1)
            };
            Replica::new(cfg, 100 + i as u64, at(0)).unwrap()
        })
        .collect();
    let x = Key::parse("*.var.x").unwrap();
    let goer = Key::parse("*.var.goer").unwrap();
    let mut frames = Vec::new();
    let from: std::net::SocketAddr = "127.0.0.1:2000".parse().unwrap();
    for ms in (0..until_ms).step_by(10) {
        for i in 0..5 {
            team[i].handle_timeout(at(ms));
            if chatty(i, ms) {
                team[i].set_key(at(ms), &x, Value::Int(ms as i64)).unwrap();
            }
            if priority(i, ms) {
                team[i]
                    .set_priority(at(ms), &goer, Value::Int(ms as i64))
                    .unwrap();
            }
            while let Some(t) = team[i].poll_transmit() {
                frames.push((i, ms));
                for (j, other) in team.iter_mut().enumerate() {
                    if j != i {
                        other.handle_datagram(at(ms), from, &t.payload);
                    }
                }
            }
        }
    }
    frames
}

#[test]
fn a_pooled_team_lends_the_silent_robots_share_to_the_one_with_news() {
    // SPL rules over 100 s: 100 messages for the team. Robot 1 always has news; the
    // others only every 20 s.
    let spec = crate::BudgetSpec {
        team_messages: 100,
        game: Duration::from_secs(100),
        payload_limit: Some(128),
    };
    let sent = team(spec.share(5), 100_000, |i, ms| i == 0 || ms % 20_000 == 0);
    let total: u64 = sent.iter().sum();
    assert!(total <= 100, "never beyond the team's budget: {sent:?}");
    assert!(
        sent[0] >= 50,
        "robot 1 spends what the quiet ones leave, far beyond its 20: {sent:?}"
    );
    // The same robots, each kept to its own share.
    let split = team(spec.share(5).split(), 100_000, |i, ms| {
        i == 0 || ms % 20_000 == 0
    });
    assert!(split[0] <= 20, "alone, robot 1 has its share: {split:?}");
}

#[test]
fn a_pooled_team_where_everyone_has_news_shares_the_budget_about_equally() {
    let spec = crate::BudgetSpec {
        team_messages: 200,
        game: Duration::from_secs(100),
        payload_limit: Some(128),
    };
    let sent = team(spec.share(5), 100_000, |_, _| true);
    let total: u64 = sent.iter().sum();
    assert!(total <= 200, "never beyond the team's budget: {sent:?}");
    assert!(total >= 150, "and most of it spent: {sent:?}");
    let (lo, hi) = (sent.iter().min().unwrap(), sent.iter().max().unwrap());
    assert!(
        hi - lo <= 8,
        "no robot starves the others (robots under their share go first): {sent:?}"
    );
}

/// Every robot of a pooled team always has news, so ordinary frames keep the team on
/// its line. Robot 2 then has a goer change to tell every second for ten seconds,
/// more than its own fifth of a share would have paid for by then (5): each goes at
/// once, paid by the team's room beyond the line, and the team stays within its
/// budget pro rata.
#[test]
fn a_pooled_teams_priority_frames_go_at_once_while_everyone_else_fills_the_line() {
    let spec = crate::BudgetSpec {
        team_messages: 200,
        game: Duration::from_secs(100),
        payload_limit: Some(128),
    };
    let changes: Vec<u64> = (50_000..60_000).step_by(1000).collect();
    let frames = team_frames(
        spec.share(5),
        61_000,
        |_, _| true,
        |i, ms| i == 1 && changes.contains(&ms),
    );
    for (n, (_, ms)) in frames.iter().enumerate() {
        assert!(
            n as u64 <= 2 * ms / 1000,
            "{} frames by {ms} ms: beyond the budget pro rata (2 per second)",
            n + 1
        );
    }
    let told: Vec<u64> = frames
        .iter()
        .filter(|&&(i, ms)| i == 1 && changes.contains(&ms))
        .map(|&(_, ms)| ms)
        .collect();
    assert_eq!(
        told, changes,
        "each goer change went at once although the line was full"
    );
}

#[test]
fn a_forged_frame_counter_cannot_use_up_a_pooled_budget() {
    let spec = crate::BudgetSpec {
        team_messages: 100,
        game: Duration::from_secs(100),
        payload_limit: Some(128),
    };
    let cfg = ReplicaConfig {
        budget: Some(spec.share(5)),
        mtu: 128,
        ..ReplicaConfig::new(1, 1)
    };
    let mut r = Replica::new(cfg, 1, at(0)).unwrap();
    // A frame from "robot 7" numbered 1,000,000.
    let mut w = crate::wire::FrameWriter::new(1, 7, 9, 1_000_000, 128, None);
    w.push(crate::wire::ItemRef::Update {
        path: "7.var.x",
        value: &Value::Int(1),
        version: 1,
        age_us: 0,
    });
    let forged = w.finish();
    let from: std::net::SocketAddr = "127.0.0.1:2000".parse().unwrap();
    r.handle_datagram(at(0), from, &forged);
    let (_, left) = r.budget_status().unwrap();
    assert!(
        left >= 100 - 15 - 6,
        "one frame heard counts for at most 6, whatever its counter says: {left} left"
    );
}

#[test]
fn a_pooled_budget_smaller_than_its_margin_sends_nothing_and_does_not_panic() {
    // 5 messages for 5 robots: the margin (15) is larger than the budget.
    let spec = crate::BudgetSpec {
        team_messages: 5,
        game: Duration::from_secs(10),
        payload_limit: Some(128),
    };
    let sent = team(spec.share(5), 10_000, |_, _| true);
    assert!(
        sent.iter().sum::<u64>() <= 5,
        "never beyond the team's budget: {sent:?}"
    );
}

/// Scenario: under the SPL budget robot 1 builds its world model at 1.000 s (a control
/// tick that sent nothing), writes it at 1.030 s riding along a claim decided between
/// ticks (with priority), and the frame leaves at 1.040 s; robot 2 hears it at 1.045 s (the
/// two clocks agree). Written with `set_key_built`, robot 2 stamps it at its build time:
/// the age on the wire counts from the build, not from the late write (before, the
/// teammate placed the snapshot 30 ms after the instant it holds).
#[test]
fn a_value_written_late_is_stamped_at_its_build_time_by_a_teammate() {
    let cfg = ReplicaConfig {
        budget: Some(crate::BudgetSpec::SPL.share(5)),
        mtu: 128,
        ..ReplicaConfig::new(1, 1)
    };
    let mut r1 = Replica::new(cfg.clone(), 1, at(0)).unwrap();
    let mut r2 = Replica::new(ReplicaConfig::new(2, 1), 2, at(0)).unwrap();
    let from: std::net::SocketAddr = "127.0.0.1:2000".parse().unwrap();
    let world = Key::parse("*.var.world").unwrap();
    let claim = Key::parse("*.var.goer").unwrap();
    let mut stamps = Vec::new();
    for built in [false, true] {
        let value = Value::Bytes(vec![u8::from(built); 43]);
        r1.handle_timeout(at(1030));
        // The claim that takes it along, with priority.
        r1.set_priority(at(1030), &claim, Value::Int(1)).unwrap();
        if built {
            r1.set_key_built(at(1030), &world, value, at(1000)).unwrap();
        } else {
            r1.set_key(at(1030), &world, value).unwrap();
        }
        r1.handle_timeout(at(1040));
        let frame = r1
            .poll_transmit()
            .expect("the claim's priority lets a frame go at 1.04 s");
        r2.handle_datagram(at(1045), from, &frame.payload);
        let e = r2
            .blackboard()
            .get(&Key::parse("1.var.world").unwrap())
            .expect("robot 2 holds robot 1's world model")
            .clone();
        assert_eq!(e.value, Value::Bytes(vec![u8::from(built); 43]));
        stamps.push(e.stamp.as_micros());
        // The next round's frame may go at once (the test is about the stamp).
        r1 = Replica::new(cfg.clone(), 1, at(0)).unwrap();
        r2 = Replica::new(ReplicaConfig::new(2, 1), 2, at(0)).unwrap();
    }
    let [late, built] = stamps[..] else {
        unreachable!()
    };
    let ms = |us: u64| us as f64 / 1000.0;
    assert!(
        (ms(built) - 1000.0).abs() <= 5.0,
        "stamped at {} ms, built at 1000 ms",
        ms(built)
    );
    assert!(
        ms(late) >= 1025.0,
        "a plain late write is stamped at the write ({} ms): the case the build stamp fixes",
        ms(late)
    );
}
