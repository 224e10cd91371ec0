//! What a relay client may not do to the daemon's own keys, and what operators see of it,
//! over TCP on loopback (the relay server the daemon runs, on a driver of the test's own).
//!
//! The attack suite (`scripts/attack/`) found that a client could write the team layer's
//! outputs (`local.var.team.*`) and the GameController listener's game state
//! (`local.var.gc.*`): every other program on the robot then read a decision the layer
//! never took or a game state the GC never sent (the listener writes a key only when the
//! GC's packet changes it, so a client's value stood until then). It also found two
//! counted drops nobody could see: relay clients cut off for not reading, and frames
//! dropped from a full send backlog were in `IoStats` but not in
//! `local.var.huddle.stats.*`, where `huddle stats` and every client look.

mod support;

use std::net::{Ipv4Addr, SocketAddr, UdpSocket};
use std::time::Duration;

use comms::{ReplicaConfig, Value};
use driver::team::TeamLayerConfig;
use driver::{scratch_group, Driver, DriverConfig, GameController, GameControllerConfig, Handle};
use gamecontroller::{GameControlData, State};
use support::run_local;
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};
use tokio::net::tcp::{OwnedReadHalf, OwnedWriteHalf};

/// Robot 1 of team 12 on a scratch group; `max_output_bytes` before a client is cut off.
fn robot_1(max_output_bytes: usize) -> Driver {
    let mut cfg = DriverConfig::new(ReplicaConfig::new(1, 12));
    cfg.socket.group = scratch_group().expect("a scratch group");
    cfg.session_limits.max_output_bytes = max_output_bytes;
    Driver::bind(cfg).expect("robot 1 binds")
}

/// The relay server on a loopback port of its own, for `handle`; its address.
async fn serve(handle: &Handle) -> SocketAddr {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    tokio::task::spawn_local(driver::serve(
        listener,
        handle.clone(),
        std::future::pending(),
    ));
    addr
}

/// A relay client that reads every answer.
struct Client {
    reader: BufReader<OwnedReadHalf>,
    writer: OwnedWriteHalf,
}

impl Client {
    async fn connect(addr: SocketAddr) -> Client {
        let (r, writer) = tokio::net::TcpStream::connect(addr)
            .await
            .unwrap()
            .into_split();
        let mut c = Client {
            reader: BufReader::new(r),
            writer,
        };
        let greeting = c.line().await;
        assert!(greeting.starts_with("HUDDLE "), "{greeting}");
        c
    }

    async fn line(&mut self) -> String {
        let mut line = String::new();
        let read = tokio::time::timeout(Duration::from_secs(10), self.reader.read_line(&mut line));
        read.await.expect("an answer within 10 s").unwrap();
        line.trim_end().to_owned()
    }

    async fn ask(&mut self, line: &str) -> String {
        self.writer
            .write_all(format!("{line}\n").as_bytes())
            .await
            .unwrap();
        self.line().await
    }
}

/// Waits (at most 10 s) until `key` holds a value `ok` takes; that value.
async fn wait_until(h: &Handle, key: &str, ok: impl Fn(&Value) -> bool) -> Value {
    for _ in 0..1000 {
        if let Some(e) = h.get(key).unwrap().filter(|e| ok(&e.value)) {
            return e.value;
        }
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let now = h.get(key).unwrap().map(|e| e.value);
    panic!("{key} never held the value waited for: it holds {now:?}");
}

/// Waits (at most 10 s) until `key` holds `want`.
async fn wait_for_value(h: &Handle, key: &str, want: Value) {
    wait_until(h, key, |v| *v == want).await;
}

fn free_udp_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

#[test]
fn a_relay_client_cannot_write_the_daemons_own_keys_while_their_writer_runs() {
    run_local(async {
        let driver = robot_1(1 << 20);
        let h = driver.handle();
        tokio::task::spawn_local(driver.run(std::future::pending()));
        let mut c = Client::connect(serve(&h).await).await;

        // Neither the team layer nor a GameController listener runs: their families are
        // ordinary local keys (a program running its own team code may use them).
        assert_eq!(c.ask("SETV local.var.team.goer 3").await, "OK");
        assert_eq!(c.ask("SETV local.var.gc.state \"set\"").await, "OK");
        // The counters are the daemon's always; the Python client's own keys are not
        // among them.
        let a = c.ask("SETV local.var.huddle.stats.frames_in 0").await;
        assert!(
            a.starts_with("ERR 423 local.var.huddle.stats.frames_in is written by the daemon"),
            "a client cannot reset a counter: {a}"
        );
        assert_eq!(
            c.ask("SETV local.var.huddle_client.float_probe [0.1]")
                .await,
            "OK"
        );

        let team = driver::team::start(&h, TeamLayerConfig::new(3, None));
        let gc_port = free_udp_port();
        let mut gc_cfg = GameControllerConfig::new(12, 1);
        gc_cfg.listen = SocketAddr::from((Ipv4Addr::LOCALHOST, gc_port));
        gc_cfg.status_period = None;
        let gc = GameController::start(&h, gc_cfg).expect("the listener binds");

        for line in [
            "SETV local.var.team.goer 2",
            "SETP local.var.team.going true",
            "SETV local.var.team.ball [2.0, 2.0]",
            "SETV local.var.gc.state \"playing\"",
            "SETP local.var.gc.penalized [1]",
        ] {
            let a = c.ask(line).await;
            assert!(a.starts_with("ERR 423 "), "{line}: {a}");
        }
        let a = c.ask("SETV local.var.team.ball [2.0, 2.0]").await;
        assert!(
            a.contains("is written by the team layer"),
            "the refusal says who writes the key: {a}"
        );
        let a = c.ask("SETV local.var.gc.state \"playing\"").await;
        assert!(a.contains("GameController"), "{a}");
        assert!(
            c.ask("GETV local.var.team.goer")
                .await
                .starts_with("VAL local.var.team.goer int 3 "),
            "a refused write writes nothing"
        );
        assert_eq!(
            c.ask("GETV local.var.team.ball").await.get(..7),
            Some("ERR 404")
        );

        // The parts' own writes go on: the layer takes the program's pose and ticks...
        let pose = "[0.5, -1.0, 0.25, 0.01, 0, 0, 0.01, 0, 0.003]";
        assert_eq!(
            c.ask(&format!("SETV local.var.robot.pose {pose}")).await,
            "OK"
        );
        wait_until(&h, "local.var.team.tick", |_| true).await;
        let goer = wait_until(&h, "local.var.team.goer", |_| true).await;
        assert_ne!(goer, Value::Int(3), "the layer writes its own decision");
        // ... and the listener writes what the GC says.
        let mut game = GameControlData::new([12, 34]);
        game.state = State::Playing;
        game.packet_number = 1;
        let gc_socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        gc_socket
            .send_to(&game.encode(), (Ipv4Addr::LOCALHOST, gc_port))
            .unwrap();
        wait_for_value(&h, "local.var.gc.state", Value::String("playing".into())).await;

        // Every refusal is counted, and shown where operators look.
        assert_eq!(h.stats().io.relay_read_only_refused, 8);
        wait_for_value(
            &h,
            "local.var.huddle.stats.relay_read_only_refused",
            Value::Int(8),
        )
        .await;

        // Once they stop, the families are ordinary keys again.
        drop(team);
        drop(gc);
        assert_eq!(c.ask("SETV local.var.team.goer 4").await, "OK");
        assert_eq!(c.ask("SETV local.var.gc.state \"finished\"").await, "OK");
    });
}

#[test]
fn a_client_cut_off_for_not_reading_moves_its_counter_key() {
    // Robot 1 cuts off a client with more than 64 KiB of unread output. The client asks
    // for a 3 KB value 2,000 times over and reads nothing: it is cut off, and
    // `local.var.huddle.stats.relay_cutoffs` says so; a reading client is served
    // throughout.
    run_local(async {
        let driver = robot_1(64 << 10);
        let h = driver.handle();
        tokio::task::spawn_local(driver.run(std::future::pending()));
        let addr = serve(&h).await;
        let mut reader = Client::connect(addr).await;
        let blob = "b".repeat(3000);
        assert_eq!(
            reader.ask(&format!("SETV local.var.blob \"{blob}\"")).await,
            "OK"
        );
        wait_for_value(&h, "local.var.huddle.stats.relay_cutoffs", Value::Int(0)).await;

        let socket = tokio::net::TcpSocket::new_v4().unwrap();
        socket.set_recv_buffer_size(4096).unwrap();
        let mut hog = socket.connect(addr).await.unwrap();
        let requests = "GETV local.var.blob\n".repeat(2000);
        // The daemon may close the connection before it has read all of them.
        let _ = hog.write_all(requests.as_bytes()).await;
        for _ in 0..1000 {
            if h.stats().io.relay_cutoffs > 0 {
                break;
            }
            assert!(
                reader
                    .ask("GETV local.var.blob")
                    .await
                    .starts_with("VAL local.var.blob string"),
                "a reading client is answered while another does not read"
            );
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        assert_eq!(
            h.stats().io.relay_cutoffs,
            1,
            "the client that does not read is cut off"
        );
        wait_for_value(&h, "local.var.huddle.stats.relay_cutoffs", Value::Int(1)).await;
        drop(hog);
    });
}
