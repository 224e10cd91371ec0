//! Parity: the same three-robot script through netsim (the harness, `lan` preset: no
//! loss, ~100 µs) and through three real comms drivers on loopback multicast (a group and
//! port of the test's own, IP_MULTICAST_IF 127.0.0.1, loop on; one process, one thread) ends with
//! the same blackboards and the same talk deliveries.
//!
//! The script sets global values and posts talk messages at fixed times over 0.6 s;
//! both runs then go on to 1.2 s. Compared, per robot: every global binding `n.var.x`
//! (owner, path) → (value, version) — versions count the owner's writes, so they are
//! deterministic and compared too; stamps (clocks) and incarnations (random per start)
//! are not — and every talk message delivered, in order: (sender, queue, seq, value).

#![allow(clippy::disallowed_methods)] // real sockets, real time

use std::collections::BTreeMap;
use std::net::SocketAddrV4;
use std::time::Duration;

use comms::{Event, Key, Pattern, ReplicaConfig, Scope, Value};
use driver::{Driver, DriverConfig, Handle, Notice, SocketConfig};
use huddle::harness::Harness;
use netsim::{Preset, Sim, Time};

const ROBOTS: usize = 3;
const TEAM: u8 = 7;
const END: Duration = Duration::from_millis(1200);

#[derive(Clone, Debug)]
enum Act {
    Set(&'static str, Value),
    Post(&'static str, Value),
}

/// (time, robot index, action).
fn script() -> Vec<(Duration, usize, Act)> {
    let ms = Duration::from_millis;
    vec![
        (
            ms(50),
            0,
            Act::Set("*.var.ball", Value::Floats(vec![1.0, 2.0])),
        ),
        (ms(50), 1, Act::Set("*.var.role", Value::from("keeper"))),
        (ms(120), 2, Act::Set("*.var.h", Value::Float(2.5))),
        (
            ms(120),
            0,
            Act::Post("*.talk.plan", Value::from("pass to 2")),
        ),
        (ms(200), 1, Act::Set("*.var.role", Value::from("defender"))),
        (ms(200), 1, Act::Post("*.talk.plan", Value::from("ready"))),
        (
            ms(260),
            0,
            Act::Set("*.var.ball", Value::Floats(vec![1.5, 2.5])),
        ),
        (ms(260), 2, Act::Post("*.talk.plan", Value::from("mine"))),
        (ms(300), 2, Act::Set("*.var.h", Value::Float(1.25))),
        (ms(300), 0, Act::Post("*.talk.plan", Value::from("shoot"))),
        (ms(400), 1, Act::Set("*.var.seen", Value::Bool(true))),
        (ms(450), 0, Act::Set("*.var.count", Value::Int(3))),
        (ms(450), 0, Act::Set("*.var.count", Value::Int(4))),
        (ms(500), 2, Act::Post("*.talk.plan", Value::Int(42))),
        (ms(600), 1, Act::Set("*.var.role", Value::from("striker"))),
    ]
}

/// Global bindings: (owner, path) → (value, version).
type Board = BTreeMap<(u8, String), (Value, u64)>;
/// Talk deliveries in order: (sender, queue, seq, value).
type Talk = Vec<(u8, String, u64, Value)>;

fn board<'a>(entries: impl Iterator<Item = (Key, &'a comms::Entry)>) -> Board {
    entries
        .filter_map(|(key, e)| match key.scope() {
            Scope::Robot(owner) => {
                Some(((owner, key.path().to_owned()), (e.value.clone(), e.version)))
            }
            _ => None,
        })
        .collect()
}

fn through_netsim() -> (Vec<Board>, Vec<Talk>) {
    let net = Sim::builder().preset(Preset::Lan);
    let mut h = Harness::new(ROBOTS, net, ReplicaConfig::new(1, TEAM), 1).expect("a team");
    let mut talk = vec![Talk::new(); ROBOTS];
    let collect = |h: &mut Harness, talk: &mut [Talk]| {
        for (i, t) in talk.iter_mut().enumerate() {
            for e in h.drain_events(i) {
                if let Event::TalkDelivered {
                    queue,
                    from,
                    seq,
                    value,
                } = e
                {
                    t.push((from, queue, seq, value));
                }
            }
        }
    };
    for (at, i, act) in script() {
        h.run_until(Time::from_nanos(at.as_nanos() as u64));
        collect(&mut h, &mut talk);
        match act {
            Act::Set(key, value) => h
                .set(i, &Key::parse(key).expect("valid key"), value)
                .expect("own key"),
            Act::Post(key, value) => {
                let now = h.local_now(i);
                let r = h.replica_mut(i).expect("alive");
                r.post(now, key, value).expect("own queue");
            }
        }
    }
    h.run_until(Time::from_nanos(END.as_nanos() as u64));
    collect(&mut h, &mut talk);
    let all = Pattern::parse("+.var.#").expect("valid pattern");
    let boards = (0..ROBOTS)
        .map(|i| board(h.replica(i).expect("alive").iter(&all)))
        .collect();
    (boards, talk)
}

fn through_real_drivers() -> (Vec<Board>, Vec<Talk>) {
    let group: SocketAddrV4 = driver::scratch_group().expect("a free port on loopback");
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    let local = tokio::task::LocalSet::new();
    local.block_on(&runtime, async {
        let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
        let mut handles: Vec<Handle> = Vec::new();
        let mut tasks = Vec::new();
        for i in 0..ROBOTS {
            let mut config = DriverConfig::new(ReplicaConfig::new(i as u8 + 1, TEAM));
            config.socket = SocketConfig {
                group,
                ..SocketConfig::default()
            };
            assert!(config.socket.iface.is_loopback(), "loopback only");
            config.incarnation = Some(1000 + i as u64);
            let driver = Driver::bind(config).expect("driver on loopback");
            handles.push(driver.handle());
            let mut stop = stop_rx.clone();
            tasks.push(tokio::task::spawn_local(driver.run(async move {
                let _ = stop.wait_for(|s| *s).await;
            })));
        }
        let mut subs: Vec<_> = handles
            .iter()
            .map(|h| h.subscribe("+.talk.#").expect("valid pattern"))
            .collect();
        let start = tokio::time::Instant::now();
        for (at, i, act) in script() {
            tokio::time::sleep_until(start + at).await;
            match act {
                Act::Set(key, value) => handles[i].set(key, value).expect("own key"),
                Act::Post(key, value) => {
                    handles[i].post(key, value).expect("own queue");
                }
            }
        }
        tokio::time::sleep_until(start + END).await;
        let boards = handles
            .iter()
            .map(|h| {
                let entries = h.snapshot("+.var.#").expect("valid pattern");
                board(entries.iter().map(|(k, e)| (k.clone(), e)))
            })
            .collect();
        let talk = subs
            .iter_mut()
            .map(|s| {
                std::iter::from_fn(|| s.try_next())
                    .map(|n| match n {
                        Notice::Talk {
                            from,
                            queue,
                            seq,
                            value,
                        } => (from, queue, seq, value),
                        other => panic!("unexpected notice on a talk subscription: {other:?}"),
                    })
                    .collect()
            })
            .collect();
        let _ = stop_tx.send(true);
        for t in tasks {
            t.await.expect("driver task").expect("driver ran");
        }
        (boards, talk)
    })
}

#[test]
fn the_same_script_through_netsim_and_real_sockets_ends_the_same() {
    let (sim_boards, sim_talk) = through_netsim();
    let (real_boards, real_talk) = through_real_drivers();
    // The script is not trivial: every robot holds every robot's keys, and hears the
    // other robots' messages.
    for (i, b) in sim_boards.iter().enumerate() {
        assert_eq!(
            b.len(),
            5,
            "netsim: robot {} holds 1.ball, 1.count, 2.role, 2.seen, 3.h: {b:?}",
            i + 1
        );
        assert_eq!(
            b.get(&(1, "count".to_owned())),
            Some(&(Value::Int(4), 2)),
            "netsim: robot {} has robot 1's second write",
            i + 1
        );
    }
    for i in 0..ROBOTS {
        assert_eq!(
            sim_boards[i],
            real_boards[i],
            "robot {}: netsim and real sockets end with different blackboards",
            i + 1
        );
        assert!(!sim_talk[i].is_empty(), "robot {} heard talk", i + 1);
        assert_eq!(
            sim_talk[i],
            real_talk[i],
            "robot {}: netsim and real sockets delivered different talk",
            i + 1
        );
    }
}
