//! The driver's three transports over loopback, in one process: two replicas broadcast
//! to 127.255.255.255 and hear each other (and their own echo, which is no error); two
//! unicast replicas on 127.0.0.2 and 127.0.0.3 replicate to each other only, refuse a
//! stranger, and keep going when the OS refuses a send. Everything stays on
//! 127.0.0.0/8, on a port of the test's own.

mod support;

use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::time::Duration;

use comms::{ReplicaConfig, Value};
use driver::{scratch_group, Driver, DriverConfig, DriverError, Handle, Notice, Transport};
use support::{frame_from, run_local};

fn config(id: u8, transport: Transport, port: u16, iface: [u8; 4]) -> DriverConfig {
    let mut cfg = DriverConfig::new(ReplicaConfig::new(id, 0));
    cfg.socket.transport = transport;
    cfg.socket.group = SocketAddrV4::new(Ipv4Addr::UNSPECIFIED, port);
    cfg.socket.iface = Ipv4Addr::from(iface);
    cfg
}

/// A port no other test uses (the kernel's pick).
fn free_port() -> u16 {
    scratch_group().expect("a free UDP port").port()
}

/// Waits (with a generous cap) until `key` holds `value` on the subscription.
async fn wait_for(sub: &mut driver::Subscription, key: &str, value: &Value) {
    let wait = tokio::time::timeout(Duration::from_secs(10), async {
        loop {
            match sub.next().await {
                Some(Notice::Changed { key: k, entry }) if k.to_string() == key => {
                    if &entry.value == value {
                        return;
                    }
                }
                Some(_) => {}
                None => panic!("the driver stopped"),
            }
        }
    });
    wait.await
        .unwrap_or_else(|_| panic!("{key} = {value:?} never arrived"));
}

/// Starts a driver; its handle and a subscription to every robot's `var.#`.
fn start(cfg: DriverConfig) -> (Handle, driver::Subscription) {
    let driver = Driver::bind(cfg).expect("the driver starts");
    let handle = driver.handle();
    let sub = handle.subscribe("+.var.#").unwrap();
    tokio::task::spawn_local(driver.run(std::future::pending()));
    (handle, sub)
}

#[test]
fn two_broadcast_replicas_on_loopback_replicate_both_ways_and_skip_their_own_echo() {
    run_local(async {
        let port = free_port();
        let (h1, mut s1) = start(config(1, Transport::Broadcast, port, [127, 0, 0, 1]));
        let (h2, mut s2) = start(config(2, Transport::Broadcast, port, [127, 0, 0, 1]));

        h1.set("*.var.ball.dist", 1.5).unwrap();
        wait_for(&mut s2, "1.var.ball.dist", &Value::Float(1.5)).await;
        h2.set("*.var.role", "keeper").unwrap();
        wait_for(&mut s1, "2.var.role", &Value::String("keeper".into())).await;

        // A unicast to the port on 127.0.0.1 is not the team's broadcast: robot 8's
        // frame is never applied. Robot 7's broadcast after it is the marker (loopback
        // delivers in order inside send_to).
        let tx = UdpSocket::bind((Ipv4Addr::LOCALHOST, 0)).unwrap();
        tx.set_broadcast(true).unwrap();
        tx.send_to(&frame_from(8), (Ipv4Addr::LOCALHOST, port))
            .unwrap();
        tx.send_to(&frame_from(7), (Ipv4Addr::new(127, 255, 255, 255), port))
            .unwrap();
        wait_for(&mut s1, "7.var.x", &Value::Int(7)).await;
        assert_eq!(
            h1.get("8.var.x").unwrap(),
            None,
            "unicast reached a broadcast member"
        );

        for (who, h) in [(1, &h1), (2, &h2)] {
            let stats = h.stats();
            assert!(
                stats.replica.own_frames > 0,
                "robot {who} hears its own broadcasts back: {:?}",
                stats.replica
            );
            assert_eq!(
                stats.replica.drops_total(),
                0,
                "robot {who}: its own echo is no error"
            );
            assert_eq!(stats.io.send_errors, 0, "robot {who}: {:?}", stats.io);
        }
    });
}

#[test]
fn two_unicast_replicas_replicate_to_each_other_only_and_refuse_a_stranger() {
    run_local(async {
        // Robots on 127.0.0.2 and 127.0.0.3, one port, as two hosts would be.
        let port = free_port();
        let at = |last: u8| SocketAddr::from((Ipv4Addr::new(127, 0, 0, last), port));
        let mut c1 = config(1, Transport::Unicast, port, [127, 0, 0, 2]);
        c1.peers = vec![at(3)];
        let mut c2 = config(2, Transport::Unicast, port, [127, 0, 0, 3]);
        c2.peers = vec![at(2)];
        let (h1, mut s1) = start(c1);
        let (h2, mut s2) = start(c2);

        h1.set("*.var.ball.dist", 2.5).unwrap();
        wait_for(&mut s2, "1.var.ball.dist", &Value::Float(2.5)).await;
        h2.set("*.var.role", "striker").unwrap();
        wait_for(&mut s1, "2.var.role", &Value::String("striker".into())).await;

        // A stranger on 127.0.0.4 is refused; the peer's own marker frame after it is
        // applied (from its address and port: the peer's replica socket sends it).
        let stranger = UdpSocket::bind((Ipv4Addr::new(127, 0, 0, 4), 0)).unwrap();
        let before = h1.stats().io.unicast_refused;
        stranger.send_to(&frame_from(8), at(2)).unwrap();
        h2.set("*.var.marker", 1_i64).unwrap();
        wait_for(&mut s1, "2.var.marker", &Value::Int(1)).await;
        assert_eq!(h1.get("8.var.x").unwrap(), None, "a stranger's unicast");
        assert_eq!(h1.stats().io.unicast_refused - before, 1);

        for (who, h) in [(1, &h1), (2, &h2)] {
            let stats = h.stats();
            assert_eq!(
                stats.replica.own_frames, 0,
                "robot {who}: unicast never comes back to its sender"
            );
            assert_eq!(stats.replica.drops_total(), 0, "robot {who}");
            assert_eq!(stats.io.send_errors, 0, "robot {who}: {:?}", stats.io);
        }
    });
}

#[test]
fn unicast_without_peers_refuses_to_start_and_a_refused_send_is_counted_not_fatal() {
    run_local(async {
        let port = free_port();
        let cfg = config(1, Transport::Unicast, port, [127, 0, 0, 1]);
        assert!(matches!(Driver::bind(cfg), Err(DriverError::NoPeers)));

        // One peer is a broadcast address: without SO_BROADCAST the kernel refuses each
        // send to it (EACCES). The other peer still gets every frame.
        let good = UdpSocket::bind((Ipv4Addr::new(127, 0, 0, 5), 0)).unwrap();
        let mut cfg = config(1, Transport::Unicast, port, [127, 0, 0, 1]);
        cfg.peers = vec![
            SocketAddr::from((Ipv4Addr::new(127, 255, 255, 255), port)),
            good.local_addr().unwrap(),
        ];
        let (h1, _s1) = start(cfg);
        h1.set("*.var.ball.dist", 3.5).unwrap();
        let rx = good.try_clone().unwrap();
        let got = tokio::task::spawn_blocking(move || {
            rx.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
            let mut buf = [0u8; 2048];
            rx.recv_from(&mut buf)
        })
        .await
        .unwrap();
        let (n, from) = got.expect("the good peer gets a frame");
        assert!(n > 0);
        assert_eq!(from, SocketAddr::from((Ipv4Addr::LOCALHOST, port)));
        let io = h1.stats().io;
        assert!(io.send_errors >= 1, "the refused sends are counted: {io:?}");
        assert!(io.datagrams_sent >= 1, "{io:?}");
        h1.set("*.var.ball.dist", 4.5).unwrap();
        assert!(h1.stats().io.send_errors > io.send_errors, "and it goes on");
    });
}
