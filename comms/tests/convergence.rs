//! N replicas on a netsim network that loses, duplicates and reorders frames must end
//! with the same blackboard, and every talk message must reach every teammate exactly once,
//! in order. The network and the script of writes are seeded, so a failing case is replayed
//! exactly from the seed proptest prints.

use std::collections::BTreeMap;
use std::time::Duration;

use comms::{Event, Key, Pattern, Replica, ReplicaConfig, Value};
use comms_netsim::{robot_id, Harness};
use netsim::{JitterDist, LinkConfig, LinkStats, Sim, SimBuilder, Time};
use proptest::prelude::*;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Every link: a delay uniform in 0..=30 ms per copy (so frames overtake each other), the
/// given loss, and one frame in ten duplicated. Multicast loop is on: a sender hears itself.
fn network(loss: f64) -> SimBuilder {
    let link = LinkConfig {
        latency: Duration::from_millis(15),
        jitter: Duration::from_millis(15),
        jitter_dist: JitterDist::Uniform,
        loss,
        duplicate: 0.1,
        ..LinkConfig::default()
    };
    Sim::builder().link(link).record_trace(false)
}

struct Outcome {
    /// (receiver, sender, queue) -> delivered messages, in delivery order.
    delivered: BTreeMap<(usize, u8, String), Vec<i64>>,
    /// (sender, queue) -> posted messages (sequence number, value), in post order.
    posted: BTreeMap<(u8, String), Vec<(u64, i64)>>,
    /// (receiver, sender, queue) -> sequence numbers reported given up.
    given_up: BTreeMap<(usize, u8, String), Vec<u64>>,
    /// The robots and their network, as the run left them.
    team: Harness,
    /// What the network did, all links together.
    network: LinkStats,
}

impl Outcome {
    fn replicas(&self) -> impl Iterator<Item = &Replica> + '_ {
        (0..self.team.len()).map(|i| self.team.replica(i).expect("nobody was switched off"))
    }
}

fn run(seed: u64, n: usize, loss: f64, keyed: bool) -> Outcome {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut cfg = ReplicaConfig::new(1, 7);
    if keyed {
        cfg = cfg.with_team_key(b"team secret".to_vec());
    }
    let mut team = Harness::new(n, network(loss), cfg, seed ^ 0x9e37_79b9).expect("a valid team");
    let mut delivered: BTreeMap<(usize, u8, String), Vec<i64>> = BTreeMap::new();
    let mut posted: BTreeMap<(u8, String), Vec<(u64, i64)>> = BTreeMap::new();
    let mut given_up: BTreeMap<(usize, u8, String), Vec<u64>> = BTreeMap::new();
    let mut counter = 0i64;
    // Every 5 ms for 2 s each robot may write and post; then 3 s for repairs under the
    // same impairments.
    for step in 0..400u64 {
        team.run_until(Time::from_millis(5 * step));
        for i in 0..n {
            if rng.random_bool(0.2) {
                let key = Key::parse(&format!("*.var.k{}", rng.random_range(0..6))).unwrap();
                team.set(i, &key, Value::Int(rng.random_range(0..1000)))
                    .unwrap();
            }
            if rng.random_bool(0.1) {
                let queue = format!("q{}", rng.random_range(0..2));
                counter += 1;
                let seq = team
                    .post(i, &format!("*.talk.{queue}"), Value::Int(counter))
                    .unwrap()
                    .expect("nobody is switched off");
                posted
                    .entry((robot_id(i), queue))
                    .or_default()
                    .push((seq, counter));
            }
        }
    }
    team.run_until(Time::from_secs(5));
    for i in 0..n {
        for e in team.drain_events(i) {
            match e {
                Event::TalkDelivered {
                    queue,
                    from,
                    value: Value::Int(v),
                    ..
                } => delivered.entry((i, from, queue)).or_default().push(v),
                Event::TalkGivenUp {
                    queue,
                    from,
                    first,
                    last,
                } => given_up
                    .entry((i, from, queue))
                    .or_default()
                    .extend(first..=last),
                _ => {}
            }
        }
    }
    Outcome {
        delivered,
        posted,
        given_up,
        network: team.net().network_stats(),
        team,
    }
}

/// `allow_give_ups`: a message may be given up (on a harsh network), but only as
/// reported: every other message still arrives exactly once, in order.
fn check(
    seed: u64,
    n: usize,
    loss: f64,
    keyed: bool,
    allow_give_ups: bool,
) -> Result<(), TestCaseError> {
    let out = run(seed, n, loss, keyed);
    let all = Pattern::parse("+.var.#").unwrap();
    for owner in out.replicas() {
        let own = Pattern::parse(&format!("{}.var.#", owner.robot_id())).unwrap();
        let truth: Vec<(String, Value, u64)> = owner
            .iter(&own)
            .map(|(k, e)| (k.to_string(), e.value.clone(), e.version))
            .collect();
        for r in out.replicas() {
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
    let given_up: usize = out.given_up.values().map(Vec::len).sum();
    if !allow_give_ups {
        prop_assert_eq!(given_up, 0, "nothing should be given up at this loss rate");
    }
    for ((sender, queue), posted) in &out.posted {
        for receiver in 0..n {
            if receiver + 1 == *sender as usize {
                continue;
            }
            let lost = out
                .given_up
                .get(&(receiver, *sender, queue.clone()))
                .cloned()
                .unwrap_or_default();
            let posted: Vec<i64> = posted
                .iter()
                .filter(|(seq, _)| !lost.contains(seq))
                .map(|&(_, v)| v)
                .collect();
            let got = out
                .delivered
                .get(&(receiver, *sender, queue.clone()))
                .cloned()
                .unwrap_or_default();
            prop_assert_eq!(
                &got,
                &posted,
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
        check(seed, n, loss, keyed, false)?;
    }
}

#[test]
fn a_harsh_network_still_converges() {
    // 40% loss with duplication and 30 ms reordering, five robots, fixed seed. Values
    // converge; a talk message may be given up after 1 s known missing (3 of seeds
    // 2000..2030 lose one, delivered event by event as the driver does; the 1 ms tick
    // loop this test had before lost none), but only as reported.
    check(2026, 5, 0.4, true, true).unwrap();
}

#[test]
fn the_checker_notices_a_team_that_never_hears_each_other() {
    // Guards against a vacuous check: with every frame lost nothing may "converge".
    assert!(check(7, 3, 1.0, false, true).is_err());
    let out = run(7, 3, 0.2, false);
    let posted: usize = out.posted.values().map(Vec::len).sum();
    assert!(
        check(7, 3, 0.2, false, false).is_ok(),
        "the same script on a kinder network passes"
    );
    let resent: u64 = out.replicas().map(|r| r.stats().talk_resent).sum();
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
