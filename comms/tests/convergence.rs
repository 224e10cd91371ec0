//! N replicas on a netsim network that loses, duplicates and reorders frames must end
//! with the same blackboard, and every talk message must reach every teammate exactly once,
//! in order. The network and the script of writes are seeded, so a failing case is replayed
//! exactly from the seed proptest prints.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::time::Duration;

use comms::{Event, Instant, Pattern, Replica, ReplicaConfig, Value};
use netsim::{Dest, JitterDist, LinkConfig, LinkStats, Sim, Time};
use proptest::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Every link: a delay uniform in 0..=30 ms per copy (so frames overtake each other), the
/// given loss, and one frame in ten duplicated. Multicast loop is on: a sender hears itself.
fn network(seed: u64, loss: f64) -> Sim {
    let link = LinkConfig {
        latency: Duration::from_millis(15),
        jitter: Duration::from_millis(15),
        jitter_dist: JitterDist::Uniform,
        loss,
        duplicate: 0.1,
        ..LinkConfig::default()
    };
    Sim::builder()
        .seed(seed ^ 0x9e37_79b9)
        .link(link)
        .record_trace(false)
        .build()
        .expect("a valid link")
}

struct Outcome {
    /// (receiver, sender, queue) -> delivered messages, in delivery order.
    delivered: BTreeMap<(usize, u8, String), Vec<i64>>,
    /// (sender, queue) -> posted messages, in post order.
    posted: BTreeMap<(u8, String), Vec<i64>>,
    given_up: usize,
    replicas: Vec<Replica>,
    /// What the network did, all links together.
    network: LinkStats,
}

fn run(seed: u64, n: usize, loss: f64, keyed: bool) -> Outcome {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut net = network(seed, loss);
    let nodes = net.add_nodes(n);
    let team = net.add_group(&nodes).expect("fresh nodes form a group");
    let start = Instant::from_micros(1_000_000);
    let mut replicas: Vec<Replica> = (0..n)
        .map(|i| {
            let mut cfg = ReplicaConfig::new(i as u8 + 1, 7);
            if keyed {
                cfg = cfg.with_team_key(b"team secret".to_vec());
            }
            Replica::new(cfg, rng.random(), start).unwrap()
        })
        .collect();
    let addr = SocketAddr::from(([127, 0, 0, 1], 2000));
    let mut out = Outcome {
        delivered: BTreeMap::new(),
        posted: BTreeMap::new(),
        given_up: 0,
        replicas: Vec::new(),
        network: LinkStats::default(),
    };
    let mut counter = 0i64;
    // 2 s of traffic, then 3 s for repairs under the same impairments.
    for tick_ms in 0..5_000u64 {
        let now = start + Duration::from_millis(tick_ms);
        net.run_until(Time::from_millis(tick_ms));
        for (r, &node) in replicas.iter_mut().zip(&nodes) {
            while let Some(d) = net.recv(node) {
                r.handle_datagram(now, addr, &d.bytes);
            }
        }
        for (i, r) in replicas.iter_mut().enumerate() {
            if tick_ms < 2_000 && tick_ms % 5 == 0 {
                if rng.random_bool(0.2) {
                    let key = format!("*.var.k{}", rng.random_range(0..6));
                    r.set(now, &key, Value::Int(rng.random_range(0..1000)))
                        .unwrap();
                }
                if rng.random_bool(0.1) {
                    let queue = format!("q{}", rng.random_range(0..2));
                    counter += 1;
                    r.post(now, &format!("*.talk.{queue}"), Value::Int(counter))
                        .unwrap();
                    out.posted
                        .entry((r.robot_id(), queue))
                        .or_default()
                        .push(counter);
                }
            }
            if r.poll_timeout().is_some_and(|t| t <= now) {
                r.handle_timeout(now);
            }
            while let Some(t) = r.poll_transmit() {
                net.send(nodes[i], Dest::Group(team), t.payload)
                    .expect("a member sends to its group");
            }
            while let Some(e) = r.poll_event() {
                match e {
                    Event::TalkDelivered {
                        queue,
                        from,
                        value: Value::Int(v),
                        ..
                    } => out.delivered.entry((i, from, queue)).or_default().push(v),
                    Event::TalkGivenUp { .. } => out.given_up += 1,
                    _ => {}
                }
            }
        }
    }
    out.replicas = replicas;
    out.network = net.network_stats();
    out
}

fn check(seed: u64, n: usize, loss: f64, keyed: bool) -> Result<(), TestCaseError> {
    let out = run(seed, n, loss, keyed);
    let all = Pattern::parse("+.var.#").unwrap();
    for owner in &out.replicas {
        let own = Pattern::parse(&format!("{}.var.#", owner.robot_id())).unwrap();
        let truth: Vec<(String, Value, u64)> = owner
            .iter(&own)
            .map(|(k, e)| (k.to_string(), e.value.clone(), e.version))
            .collect();
        for r in &out.replicas {
            let copy: Vec<(String, Value, u64)> = r
                .iter(&own)
                .map(|(k, e)| (k.to_string(), e.value.clone(), e.version))
                .collect();
            prop_assert_eq!(
                &copy,
                &truth,
                "robot {}'s copy of robot {}'s values differs (seed {}, loss {})",
                r.robot_id(),
                owner.robot_id(),
                seed,
                loss
            );
        }
        prop_assert!(owner.iter(&all).count() > 0);
    }
    prop_assert_eq!(
        out.given_up,
        0,
        "nothing should be given up at this loss rate"
    );
    for ((sender, queue), posted) in &out.posted {
        for receiver in 0..n {
            if receiver + 1 == *sender as usize {
                continue;
            }
            let got = out
                .delivered
                .get(&(receiver, *sender, queue.clone()))
                .cloned()
                .unwrap_or_default();
            prop_assert_eq!(
                &got,
                posted,
                "robot {} got robot {}'s queue {} wrong (seed {})",
                receiver + 1,
                sender,
                queue,
                seed
            );
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, ..ProptestConfig::default() })]

    #[test]
    fn replicas_converge_and_talk_is_exactly_once_in_order(
        seed in any::<u64>(),
        n in 2usize..=4,
        loss in 0.0f64..0.3,
        keyed in any::<bool>(),
    ) {
        check(seed, n, loss, keyed)?;
    }
}

#[test]
fn a_harsh_network_still_converges() {
    // 40% loss with duplication and 30 ms reordering, five robots, fixed seed.
    check(2026, 5, 0.4, true).unwrap();
}

#[test]
fn the_checker_notices_a_team_that_never_hears_each_other() {
    // Guards against a vacuous check: with every frame lost nothing may "converge".
    assert!(check(7, 3, 1.0, false).is_err());
    let out = run(7, 3, 0.2, false);
    let posted: usize = out.posted.values().map(Vec::len).sum();
    let resent: u64 = out.replicas.iter().map(|r| r.stats().talk_resent).sum();
    assert!(
        posted > 50,
        "the script posts enough talk to matter ({posted})"
    );
    assert!(resent > 0, "at 20% loss some talk needs NACK repair");
    let net = &out.network;
    assert!(
        net.lost_total() > 0 && net.duplicated > 0 && net.reordered > 0,
        "the network loses ({}), duplicates ({}) and reorders ({})",
        net.lost_total(),
        net.duplicated,
        net.reordered
    );
}
