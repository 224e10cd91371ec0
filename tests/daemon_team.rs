//! Three daemons (robots 1, 2, 3) on loopback multicast, one test, the list:
//! values cross robots with a small age, talk arrives in order, a restarted robot is
//! re-accepted, garbage and wrongly keyed frames are dropped and counted.
//! Everything sends on loopback only (a group and port of the test's own, IP_MULTICAST_IF 127.0.0.1).

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::net::{Ipv4Addr, SocketAddrV4, UdpSocket};
use std::time::Duration;

use comms::relay::Binding;
use comms::wire::{encode_frame, Frame, Item, TeamKey};
use comms::Value;
use daemon_support::Daemon;
use driver::{open_multicast, SocketConfig};

fn start(id: u8, group: SocketAddrV4, dir: &std::path::Path) -> Daemon {
    let key = dir.join("team.key");
    let args = [
        "--refresh",
        "50ms",
        "--team",
        "7",
        "--key-file",
        key.to_str().unwrap(),
    ];
    let relay_port = daemon_support::free_tcp_port();
    Daemon::start(id, &group.to_string(), relay_port, &args, dir)
}

#[test]
fn three_daemons_share_values_talk_restarts_and_drop_bad_frames() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("team.key"), "robocup-2000-team-key\n").unwrap();
    std::fs::write(dir.path().join("config.dat"), "*.var.team = \"ISocRob\"\n").unwrap();
    std::fs::write(dir.path().join("config-2.dat"), "*.var.boot = 1\n").unwrap();
    let group = daemon_support::scratch_group();
    let d1 = start(1, group, dir.path());
    let mut d2 = start(2, group, dir.path());
    let d3 = start(3, group, dir.path());
    let (mut c1, mut c3) = (d1.client(), d3.client());
    assert_eq!(c1.greeting, "HUDDLE 2 robot 1");

    // 1. A value set through robot 1's relay is read through robot 3's, freshly.
    assert_eq!(c1.ask("SETV *.var.ball.dist 1.5"), "OK");
    let answer = c3.wait_for("1.var.ball.dist", Duration::from_secs(3), |a| {
        a.starts_with("VAL")
    });
    let b = Binding::parse(&answer).unwrap();
    let age_ms = b.age_ms;
    assert_eq!(
        (b.key.as_str(), b.ty.as_str(), b.value.as_str()),
        ("1.var.ball.dist", "float", "1.5")
    );
    assert!(age_ms < 200, "robot 3 sees robot 1's value {age_ms} ms old");
    c3.wait_for("2.var.team", Duration::from_secs(3), |a| {
        a.ends_with("\"ISocRob\" 0") || a.starts_with("VAL 2.var.team string")
    });

    // 2. Talk posted on robot 2 reaches 1 and 3 once each, in order.
    let mut listeners = [d1.client(), d3.client()];
    for l in &mut listeners {
        assert_eq!(l.ask("ADDW +.talk.plan"), "OK");
    }
    let mut c2 = d2.client();
    for i in 0..30 {
        assert_eq!(c2.ask(&format!("SETV *.talk.plan \"pass {i}\"")), "OK");
    }
    for (who, l) in [1, 3].iter().zip(&mut listeners) {
        for i in 0..30 {
            let line = l.line();
            assert_eq!(
                line,
                format!("UPD 2.talk.plan string \"pass {i}\" 0"),
                "robot {who}, message {i}"
            );
        }
    }

    // 3. Robot 2 crashes and restarts with a new boot value: re-accepted at once.
    assert_eq!(c2.ask("SETV *.var.role \"defender\""), "OK");
    c1.wait_for("2.var.role", Duration::from_secs(3), |a| {
        a.contains("\"defender\"")
    });
    drop(c2);
    d2.kill();
    std::fs::write(dir.path().join("config-2.dat"), "*.var.boot = 2\n").unwrap();
    let d2 = start(2, group, dir.path());
    let mut c2 = d2.client();
    assert_eq!(c2.ask("SETV *.var.role \"attacker\""), "OK");
    for c in [&mut c1, &mut c3] {
        c.wait_for("2.var.boot", Duration::from_secs(3), |a| {
            a.starts_with("VAL 2.var.boot int 2 ")
        });
        let role = c.wait_for("2.var.role", Duration::from_secs(3), |a| {
            a.contains("\"attacker\"")
        });
        let age_ms = Binding::parse(&role).unwrap().age_ms;
        assert!(age_ms < 500, "the restarted robot's value is fresh: {role}");
    }

    // 4. Garbage and a frame tagged with the wrong key, sent to the group: dropped,
    // counted, nothing else changes.
    let before: Vec<(i64, i64)> = [&mut c1, &mut c2, &mut c3]
        .into_iter()
        .map(|c| (c.stat("drops.bad_magic"), c.stat("drops.bad_tag")))
        .collect();
    // The driver's own socket set-up: IP_MULTICAST_IF 127.0.0.1, TTL 1.
    let cfg = SocketConfig {
        group,
        iface: Ipv4Addr::LOCALHOST,
        ..SocketConfig::default()
    };
    let tx: UdpSocket = open_multicast(&cfg).unwrap().socket;
    tx.send_to(&[0x5a; 40], group).unwrap();
    let forged = Frame {
        team: 7,
        sender: 9,
        incarnation: 1,
        seq: 1,
        clock: Default::default(),
        items: vec![Item::Update {
            path: "ball.dist".into(),
            value: Value::Float(99.0),
            version: 1,
            age_us: 0,
        }],
    };
    tx.send_to(
        &encode_frame(&forged, Some(&TeamKey::new(b"not-our-key"))),
        group,
    )
    .unwrap();
    for ((who, c), (magic0, tag0)) in [1, 2, 3]
        .iter()
        .zip([&mut c1, &mut c2, &mut c3])
        .zip(before)
    {
        let deadline = std::time::Instant::now() + Duration::from_secs(3);
        loop {
            let (magic, tag) = (c.stat("drops.bad_magic"), c.stat("drops.bad_tag"));
            if magic > magic0 && tag > tag0 {
                assert_eq!(
                    (magic, tag),
                    (magic0 + 1, tag0 + 1),
                    "robot {who}: one drop each"
                );
                break;
            }
            assert!(
                std::time::Instant::now() < deadline,
                "robot {who} did not count the drops"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        assert!(
            c.ask("GETV 9.var.ball.dist").starts_with("ERR 404 "),
            "robot {who} took the forged value"
        );
        let newest = c.ask("GETV *.var.ball.dist");
        assert!(
            newest.starts_with("VAL 1.var.ball.dist float 1.5 "),
            "robot {who}: {newest}"
        );
    }
}
