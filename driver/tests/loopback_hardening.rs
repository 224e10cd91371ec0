//! The driver's sockets over loopback (issue #12): a member hears its own group only,
//! unicast only from its `--peer`s, and float vectors cross relay → wire → relay as f64.
//! Everything sends on 127.0.0.0/8 only, to a group and port of the test's own.

mod support;

use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::time::Duration;

use comms::{ReplicaConfig, Value};
use driver::{open_multicast, scratch_group, Driver, DriverConfig, SocketConfig};
use support::{frame_from, run_local, wait_for};
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};

fn config(id: u8, group: SocketAddrV4) -> DriverConfig {
    let mut cfg = DriverConfig::new(ReplicaConfig::new(id, 0));
    cfg.socket.group = group;
    cfg
}

/// A plain socket on a loopback address of its own choosing.
fn udp_on(ip: [u8; 4]) -> UdpSocket {
    UdpSocket::bind((Ipv4Addr::from(ip), 0)).expect("bind a loopback address")
}

// Loopback delivery happens inside `send_to`, in order, and the driver handles datagrams
// in the order it reads them: once a marker frame sent after a probe has been applied,
// the probe was either applied too or never delivered. No waiting for nothing to happen.

#[test]
fn a_member_without_peers_takes_no_unicast() {
    run_local(async {
        let group = scratch_group().unwrap();
        let member = Driver::bind(config(1, group)).unwrap();
        let handle = member.handle();
        let mut sub = handle.subscribe("+.var.x").unwrap();
        tokio::task::spawn_local(member.run(std::future::pending()));

        // Robot 8's frame by unicast to the member's port on its interface address.
        let stranger = udp_on([127, 0, 0, 1]);
        stranger
            .send_to(&frame_from(8), (Ipv4Addr::LOCALHOST, group.port()))
            .unwrap();
        // Robot 7's frame to the group: the marker.
        let cfg = SocketConfig {
            group,
            ..SocketConfig::default()
        };
        let team = open_multicast(&cfg).unwrap().socket;
        team.send_to(&frame_from(7), group).unwrap();

        wait_for(&mut sub, "7.var.x").await;
        assert_eq!(
            handle.get("8.var.x").unwrap(),
            None,
            "unicast reached a member that has no --peer"
        );
    });
}

#[test]
fn a_member_does_not_apply_frames_of_another_group_on_its_port() {
    run_local(async {
        let group = scratch_group().unwrap();
        let mut other = *scratch_group().unwrap().ip();
        if other == *group.ip() {
            other = Ipv4Addr::from(u32::from(other) ^ 1);
        }
        let other = SocketAddrV4::new(other, group.port());
        let member = Driver::bind(config(1, group)).unwrap();
        let handle = member.handle();
        let mut sub = handle.subscribe("+.var.x").unwrap();
        tokio::task::spawn_local(member.run(std::future::pending()));

        // Another team on this host, same port, other group.
        let neighbour = open_multicast(&SocketConfig {
            group: other,
            ..SocketConfig::default()
        })
        .unwrap()
        .socket;
        neighbour.send_to(&frame_from(8), other).unwrap();
        neighbour.send_to(&frame_from(7), group).unwrap();

        wait_for(&mut sub, "7.var.x").await;
        assert_eq!(
            handle.get("8.var.x").unwrap(),
            None,
            "a frame sent to {other} was applied by a member of {group}"
        );
    });
}

#[test]
fn unicast_is_taken_from_configured_peers_only_and_frames_to_peers_leave_from_the_iface() {
    run_local(async {
        let group = scratch_group().unwrap();
        // The teammate lives on 127.0.0.2, a stranger on 127.0.0.3: both loopback.
        let peer = udp_on([127, 0, 0, 2]);
        let peer_addr = peer.local_addr().unwrap();
        let stranger = udp_on([127, 0, 0, 3]);
        let mut cfg = config(1, group);
        cfg.peers = vec![peer_addr];
        let member = Driver::bind(cfg).unwrap();
        let handle = member.handle();
        let mut sub = handle.subscribe("+.var.x").unwrap();
        tokio::task::spawn_local(member.run(std::future::pending()));

        // The member's first frame reaches the peer by unicast, from <iface>:<port>.
        let peer_rx = peer.try_clone().unwrap();
        let from = tokio::task::spawn_blocking(move || {
            peer_rx
                .set_read_timeout(Some(Duration::from_secs(10)))
                .unwrap();
            let mut buf = [0u8; 2048];
            peer_rx.recv_from(&mut buf).expect("a frame for the peer").1
        })
        .await
        .unwrap();
        let member_addr = SocketAddr::from((Ipv4Addr::LOCALHOST, group.port()));
        assert_eq!(from, member_addr);

        let before = handle.stats().io;
        stranger.send_to(&frame_from(8), member_addr).unwrap();
        peer.send_to(&frame_from(9), member_addr).unwrap();
        wait_for(&mut sub, "9.var.x").await;
        assert_eq!(handle.get("8.var.x").unwrap(), None, "a stranger's unicast");
        let after = handle.stats().io;
        assert_eq!(after.unicast_refused - before.unicast_refused, 1);
    });
}

/// One relay line in, one line out.
async fn ask(
    reader: &mut BufReader<tokio::net::tcp::OwnedReadHalf>,
    writer: &mut tokio::net::tcp::OwnedWriteHalf,
    line: &str,
) -> String {
    writer
        .write_all(format!("{line}\n").as_bytes())
        .await
        .unwrap();
    let mut answer = String::new();
    reader.read_line(&mut answer).await.unwrap();
    answer.trim_end().to_owned()
}

async fn relay_for(handle: driver::Handle) -> tokio::net::TcpStream {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::task::spawn_local(driver::serve(listener, handle, std::future::pending()));
    tokio::net::TcpStream::connect(addr).await.unwrap()
}

#[test]
fn floats_that_do_not_fit_f32_cross_relay_wire_and_relay_exactly() {
    run_local(async {
        let group = scratch_group().unwrap();
        let one = Driver::bind(config(1, group)).unwrap();
        let two = Driver::bind(config(2, group)).unwrap();
        let (h1, h2) = (one.handle(), two.handle());
        let mut sub = h2.subscribe("1.var.f").unwrap();
        tokio::task::spawn_local(one.run(std::future::pending()));
        tokio::task::spawn_local(two.run(std::future::pending()));

        let (r1, mut w1) = relay_for(h1).await.into_split();
        let (r2, mut w2) = relay_for(h2.clone()).await.into_split();
        let (mut r1, mut r2) = (BufReader::new(r1), BufReader::new(r2));
        let mut greeting = String::new();
        r1.read_line(&mut greeting).await.unwrap();
        r2.read_line(&mut greeting).await.unwrap();

        let literal = "[123456789.123, 1e-50, -1e300, 0.1]";
        assert_eq!(
            ask(&mut r1, &mut w1, &format!("SETV *.var.f {literal}")).await,
            "OK"
        );
        wait_for(&mut sub, "1.var.f").await;
        let entry = h2.get("1.var.f").unwrap().expect("replicated");
        assert_eq!(
            entry.value,
            Value::Floats(vec![123_456_789.123, 1e-50, -1e300, 0.1]),
            "set on robot 1, read on robot 2 through the wire"
        );
        let answer = ask(&mut r2, &mut w2, "GETV 1.var.f").await;
        assert!(
            answer.starts_with(&format!("VAL 1.var.f floats {literal} ")),
            "{answer}"
        );
    });
}
