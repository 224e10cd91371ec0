//! Determinism: one seed, one run, byte for byte; retuning one link leaves the others alone.

use std::time::Duration;

use netsim::{Action, Dest, LinkConfig, NodeId, Preset, Sim, Time, TraceKind};

/// Five robots on the competition WLAN, each multicasting 100 frames/s for 10 s, robot 4
/// partitioned from 2 s to 4 s; `tune` may change the network before the start.
fn match_run(seed: u64, tune: impl FnOnce(&mut Sim, &[NodeId])) -> Sim {
    let mut sim = Sim::builder()
        .seed(seed)
        .preset(Preset::Competition)
        .build()
        .unwrap();
    let robots = sim.add_nodes(5);
    let team = sim.add_group(&robots).unwrap();
    tune(&mut sim, &robots);
    sim.at(Time::from_secs(2), Action::Isolate(robots[3]))
        .unwrap();
    sim.at(Time::from_secs(4), Action::Rejoin(robots[3]))
        .unwrap();
    for frame in 0..1000u64 {
        for (k, &robot) in robots.iter().enumerate() {
            // Staggered by 1.3 ms per robot, payload numbered.
            let at = Time::from_micros(frame * 10_000 + k as u64 * 1_300);
            let payload = format!("robot {} frame {frame}", robot.0).into_bytes();
            sim.send_at(at, robot, Dest::Group(team), payload).unwrap();
        }
    }
    sim.run_until(Time::from_secs(11));
    sim
}

fn trace_text(sim: &Sim) -> String {
    let mut out = Vec::new();
    sim.write_trace(&mut out).unwrap();
    String::from_utf8(out).unwrap()
}

#[test]
fn the_same_seed_gives_the_same_trace_and_another_seed_a_different_one() {
    let a = match_run(2024, |_, _| {});
    let b = match_run(2024, |_, _| {});
    assert!(
        a.trace().event_count() > 20_000,
        "a real workload: {}",
        a.trace().event_count()
    );
    assert_eq!(a.trace().hash(), b.trace().hash(), "same seed, same hash");
    assert_eq!(trace_text(&a), trace_text(&b), "same seed, same trace text");
    let c = match_run(2025, |_, _| {});
    assert_ne!(
        a.trace().hash(),
        c.trace().hash(),
        "different seed, different hash"
    );
}

#[test]
fn the_hash_is_kept_without_recording_and_is_the_same() {
    let recorded = match_run(7, |_, _| {});
    let unrecorded = match_run(7, |sim, _| sim.set_trace_recording(false));
    assert!(unrecorded.trace().events().is_empty());
    assert_eq!(recorded.trace().hash(), unrecorded.trace().hash());
}

/// Every delivery and drop on the link `from → to`, as (seq, time, what).
fn link_events(sim: &Sim, from: NodeId, to: NodeId) -> Vec<(u64, Time, String)> {
    sim.trace()
        .events()
        .iter()
        .filter_map(|e| match &e.kind {
            TraceKind::Deliver {
                from: f,
                to: t,
                seq,
                ..
            } if (*f, *t) == (from, to) => Some((*seq, e.at, "deliver".to_string())),
            TraceKind::Drop {
                from: f,
                to: t,
                seq,
                reason,
                ..
            } if (*f, *t) == (from, to) => Some((*seq, e.at, reason.to_string())),
            _ => None,
        })
        .collect()
}

#[test]
fn retuning_one_link_does_not_change_what_happens_on_any_other() {
    let base = match_run(99, |_, _| {});
    let retuned = match_run(99, |sim, robots| {
        let awful: LinkConfig = "delay=300ms,jitter=100ms,loss=60%,dup=30%".parse().unwrap();
        sim.set_link(robots[0], robots[1], awful).unwrap();
    });
    let robots: Vec<NodeId> = base.nodes().collect();
    assert_ne!(
        link_events(&base, robots[0], robots[1]),
        link_events(&retuned, robots[0], robots[1]),
        "the retuned link itself changed"
    );
    for &from in &robots {
        for &to in &robots {
            if (from, to) != (robots[0], robots[1]) {
                assert_eq!(
                    link_events(&base, from, to),
                    link_events(&retuned, from, to),
                    "link {from}->{to} must not notice that {}->{} was retuned",
                    robots[0],
                    robots[1]
                );
            }
        }
    }
}

#[test]
fn a_scheduled_retune_takes_effect_at_its_time() {
    let mut sim = Sim::builder()
        .seed(1)
        .link("delay=10ms".parse().unwrap())
        .build()
        .unwrap();
    let [a, b] = sim.add_nodes(2)[..] else {
        unreachable!()
    };
    let slow: LinkConfig = "delay=40ms".parse().unwrap();
    sim.at(
        Time::from_secs(1),
        Action::SetLink {
            from: a,
            to: b,
            config: Box::new(slow),
        },
    )
    .unwrap();
    sim.send_at(Time::from_millis(500), a, Dest::Node(b), b"before".to_vec())
        .unwrap();
    sim.send_at(Time::from_millis(1500), a, Dest::Node(b), b"after".to_vec())
        .unwrap();
    sim.run_for(Duration::from_secs(2));
    let got: Vec<(Time, Vec<u8>)> = sim.drain(b).map(|d| (d.at, d.bytes.to_vec())).collect();
    assert_eq!(
        got,
        vec![
            (Time::from_millis(510), b"before".to_vec()),
            (Time::from_millis(1540), b"after".to_vec())
        ]
    );
}
