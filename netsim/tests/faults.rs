//! Fault verbs, clocks, bandwidth, reordering and duplication, seen through the simulator.

use std::time::Duration;

use netsim::{Action, Dest, DropReason, LinkConfig, NodeClock, NodeId, Sim, Time, TraceKind};
use proptest::prelude::*;

fn sim_with(spec: &str, nodes: usize) -> (Sim, Vec<NodeId>) {
    let mut sim = Sim::builder()
        .seed(3)
        .link(spec.parse().unwrap())
        .build()
        .unwrap();
    let ids = sim.add_nodes(nodes);
    (sim, ids)
}

fn arrivals(sim: &mut Sim, node: NodeId) -> Vec<(Time, NodeId)> {
    sim.drain(node).map(|d| (d.at, d.from)).collect()
}

#[test]
fn a_partition_drops_both_ways_including_packets_in_flight_and_a_repair_restores() {
    let (mut sim, n) = sim_with("delay=10ms", 3);
    sim.at(Time::from_secs(1), Action::Partition(n[0], n[1]))
        .unwrap();
    sim.at(Time::from_secs(3), Action::Repair(n[0], n[1]))
        .unwrap();
    // Everyone unicasts to everyone every 100 ms, at 50 ms past.
    for tick in 0..40u64 {
        for &from in &n {
            for &to in &n {
                if from != to {
                    let at = Time::from_millis(100 * tick + 50);
                    sim.send_at(at, from, Dest::Node(to), vec![0u8; 8]).unwrap();
                }
            }
        }
    }
    // One packet is in the air when the cut comes: sent at 995 ms, due at 1005 ms.
    sim.send_at(Time::from_millis(995), n[0], Dest::Node(n[1]), vec![1u8; 8])
        .unwrap();
    sim.run_until(Time::from_secs(5));

    let at_1 = arrivals(&mut sim, n[1]);
    let from_0: Vec<Time> = at_1
        .iter()
        .filter(|(_, f)| *f == n[0])
        .map(|(t, _)| *t)
        .collect();
    assert!(
        from_0
            .iter()
            .all(|&t| t < Time::from_secs(1) || t > Time::from_secs(3)),
        "nothing from n1 reaches n2 while they are partitioned: {from_0:?}"
    );
    assert_eq!(from_0.len(), 40 - 20, "20 sends fall inside [1 s, 3 s)");
    assert_eq!(
        from_0.last(),
        Some(&Time::from_millis(3960)),
        "traffic resumes after repair"
    );
    let s01 = sim.link_stats(n[0], n[1]).unwrap();
    assert_eq!(
        s01.lost(DropReason::Partition),
        21,
        "20 cut at send, 1 in flight"
    );
    assert_eq!(
        sim.link_stats(n[1], n[0])
            .unwrap()
            .lost(DropReason::Partition),
        20
    );
    assert_eq!(
        sim.link_stats(n[0], n[2]).unwrap().delivered,
        40,
        "the third robot is not affected"
    );
    assert_eq!(
        s01.sent,
        s01.delivered + s01.lost_total(),
        "every packet accounted for"
    );
}

#[test]
fn an_isolated_node_hears_only_itself_until_it_rejoins() {
    let (mut sim, n) = sim_with("delay=1ms", 3);
    let team = sim.add_group(&n).unwrap();
    sim.isolate(n[2]).unwrap();
    sim.send(n[2], Dest::Group(team), b"anyone?".to_vec())
        .unwrap();
    sim.send(n[0], Dest::Group(team), b"hello team".to_vec())
        .unwrap();
    sim.run_for(Duration::from_millis(10));
    assert_eq!(
        arrivals(&mut sim, n[2]),
        vec![(Time::ZERO, n[2])],
        "only its own loopback"
    );
    assert_eq!(
        arrivals(&mut sim, n[1]),
        vec![(Time::from_millis(1), n[0])],
        "n2 hears n1 but not the isolated n3"
    );
    sim.heal();
    sim.send(n[2], Dest::Group(team), b"back".to_vec()).unwrap();
    sim.run_for(Duration::from_millis(10));
    assert_eq!(
        arrivals(&mut sim, n[1]),
        vec![(Time::from_millis(11), n[2])]
    );
    assert!(!sim.is_cut(n[2], n[0]));
}

#[test]
fn bad_ids_and_past_times_are_errors_not_panics() {
    let (mut sim, n) = sim_with("", 2);
    assert!(sim.send(NodeId(9), Dest::Node(n[0]), vec![]).is_err());
    assert!(sim
        .send(n[0], Dest::Group(netsim::GroupId(1)), vec![])
        .is_err());
    assert!(sim.partition(n[0], NodeId(0)).is_err());
    assert!(sim
        .set_link(
            n[0],
            n[1],
            LinkConfig {
                loss: 2.0,
                ..LinkConfig::default()
            }
        )
        .is_err());
    sim.run_until(Time::from_secs(1));
    assert!(sim
        .send_at(Time::from_millis(1), n[0], Dest::Node(n[1]), vec![])
        .is_err());
    assert!(sim.at(Time::from_millis(1), Action::Heal).is_err());
    assert!(sim.recv(NodeId(77)).is_none());
}

#[test]
fn receive_timestamps_are_on_the_receivers_skewed_clock() {
    let (mut sim, n) = sim_with("delay=20ms", 2);
    // n2's clock reads 1000 s at the start and runs 50 ppm fast.
    let clock = NodeClock::new(Duration::from_secs(1000), 50.0).unwrap();
    sim.set_clock(n[1], clock).unwrap();
    for s in 0..100u64 {
        sim.send_at(Time::from_secs(10 * s), n[0], Dest::Node(n[1]), vec![])
            .unwrap();
    }
    sim.run_until(Time::from_secs(1000));
    let got: Vec<_> = sim.drain(n[1]).collect();
    assert_eq!(got.len(), 100);
    for d in &got {
        assert_eq!(d.local_at, clock.to_local(d.at));
        assert_eq!(
            clock.to_global(d.local_at),
            d.at,
            "positive drift: exact round trip"
        );
    }
    // Intervals between arrivals, on n2's clock, are 10 s · (1 + 50 ppm).
    let local_gap = got[99].local_at - got[0].local_at;
    assert_eq!(
        local_gap,
        Duration::from_nanos(990_000_000_000 + 49_500_000)
    );
}

proptest! {
    #[test]
    fn clock_conversion_round_trips_and_never_fires_early(
        offset_ns in 0u64..1_000_000_000_000,
        drift_ppm in -100_000.0f64..100_000.0,
        global_ns in 0u64..1_000_000_000_000_000,
        local_ns in 0u64..1_000_000_000_000_000,
    ) {
        let clock = NodeClock::new(Duration::from_nanos(offset_ns), drift_ppm).unwrap();
        let g = Time::from_nanos(global_ns);
        let back = clock.to_global(clock.to_local(g));
        prop_assert!(back <= g);
        prop_assert_eq!(clock.to_local(back), clock.to_local(g));
        if clock.drift_ppm() >= 0.0 {
            prop_assert_eq!(back, g);
        }
        // A local deadline converted to global: the clock has reached it, and not a
        // nanosecond earlier.
        let l = Time::from_nanos(local_ns);
        let wake = clock.to_global(l);
        prop_assert!(clock.to_local(wake) >= l);
        if wake > Time::ZERO {
            prop_assert!(clock.to_local(Time::from_nanos(wake.as_nanos() - 1)) < l);
        }
    }
}

#[test]
fn bandwidth_serialises_and_tail_drops_in_the_simulator() {
    // 1 Mbit/s, 3 packets of queue, 1 ms latency; five 1250-byte packets at once.
    let (mut sim, n) = sim_with("delay=1ms,rate=1mbit,queue=3", 2);
    for _ in 0..5 {
        sim.send(n[0], Dest::Node(n[1]), vec![0u8; 1250]).unwrap();
    }
    sim.run_for(Duration::from_secs(1));
    let times: Vec<Time> = arrivals(&mut sim, n[1])
        .into_iter()
        .map(|(t, _)| t)
        .collect();
    assert_eq!(
        times,
        [11, 21, 31].map(Time::from_millis),
        "10 ms on the wire each + 1 ms"
    );
    let stats = sim.link_stats(n[0], n[1]).unwrap();
    assert_eq!(stats.lost(DropReason::QueueFull), 2);
    let p = stats.delay_percentiles(&[0.0, 0.5, 1.0]);
    assert_eq!(p, [11, 21, 31].map(Duration::from_millis));
}

/// Counts arrivals whose link sequence number is below one already seen, from the trace.
fn reordered_in_trace(sim: &Sim, from: NodeId, to: NodeId) -> u64 {
    let mut max_seq = None;
    let mut count = 0;
    for e in sim.trace().events() {
        if let TraceKind::Deliver {
            from: f,
            to: t,
            seq,
            ..
        } = e.kind
        {
            if (f, t) == (from, to) {
                match max_seq {
                    Some(m) if seq < m => count += 1,
                    _ => max_seq = Some(max_seq.map_or(seq, |m: u64| m.max(seq))),
                }
            }
        }
    }
    count
}

#[test]
fn reordering_and_duplication_are_counted_as_they_happen() {
    let n_packets = 100_000u64;
    let (mut sim, n) = sim_with("delay=10ms,reorder=5%,dup=10%", 2);
    for i in 0..n_packets {
        sim.send_at(Time::from_millis(i), n[0], Dest::Node(n[1]), vec![0u8; 4])
            .unwrap();
    }
    sim.run_until(Time::from_secs(n_packets / 1000 + 1));
    let stats = sim.link_stats(n[0], n[1]).unwrap().clone();
    let dups = sim.drain(n[1]).filter(|d| d.duplicate).count() as u64;
    assert_eq!(
        stats.duplicated, dups,
        "every duplicate counted arrives flagged"
    );
    let bound = 3.29 * (n_packets as f64 * 0.1 * 0.9).sqrt();
    assert!(
        (stats.duplicated as f64 - 0.1 * n_packets as f64).abs() < bound,
        "duplicated {} of {n_packets}",
        stats.duplicated
    );
    assert!(
        stats.reordered > 1000,
        "5% of packets overtake ~10 others each"
    );
    assert_eq!(stats.reordered, reordered_in_trace(&sim, n[0], n[1]));
    assert_eq!(
        stats.sent + stats.duplicated,
        stats.delivered + stats.lost_total()
    );

    // The same link without reordering and jitter keeps order.
    let (mut calm, m) = sim_with("delay=10ms,dup=10%", 2);
    for i in 0..10_000u64 {
        calm.send_at(Time::from_millis(i), m[0], Dest::Node(m[1]), vec![0u8; 4])
            .unwrap();
    }
    calm.run_until(Time::from_secs(11));
    assert_eq!(calm.link_stats(m[0], m[1]).unwrap().reordered, 0);
}
