//! Shared by the daemon and relay tests: spawn the built `huddle daemon` on loopback
//! multicast (or another transport, still on loopback), talk raw relay bytes to it, and
//! (`netns`) build a pair of network namespaces for tests that need two hosts.
#![allow(dead_code)] // each test file uses a different part

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, SocketAddrV4, TcpListener, TcpStream};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

pub mod netns;

/// Makes a FIFO at `path` (a test's microphone or a config file that never ends).
pub fn mkfifo(path: &Path) {
    let status = Command::new("mkfifo").arg(path).status().unwrap();
    assert!(status.success(), "mkfifo {}", path.display());
}

/// Waits until the daemon `child` (robot `id`) serves its relay at `relay`: its greeting
/// names the robot. A bound port alone is not enough (it accepts connections into its
/// backlog a moment before the daemon serves, and logs that it runs); another robot's
/// greeting means the port is some other daemon's, and this one will fail to bind and
/// exit. Panics if the daemon exits or is not up within 10 s.
pub fn await_relay(child: &mut Child, relay: SocketAddr, id: u8) {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("daemon {id} exited at start: {status}");
        }
        if let Ok(stream) = TcpStream::connect(relay) {
            let _ = stream.set_read_timeout(Some(Duration::from_secs(2)));
            let mut greeting = String::new();
            let _ = BufReader::new(stream).read_line(&mut greeting);
            if greeting.trim_end().ends_with(&format!("robot {id}")) {
                return;
            }
        }
        assert!(
            Instant::now() < deadline,
            "daemon {id}'s relay never came up"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A multicast group and port of this test's own, so that two runs of the suite on one
/// host never hear each other (see `driver::scratch_group`).
pub fn scratch_group() -> SocketAddrV4 {
    driver::scratch_group().expect("a free UDP port on loopback")
}

/// A TCP port on 127.0.0.1 that nothing listens on right now (the kernel's pick), for a
/// daemon's relay, and never the same twice in one test binary: the tests of a binary run
/// at once, and a port dropped by one probe could otherwise be handed to a second test
/// before the first test's daemon binds it (the second daemon then fails to bind, and its
/// test talks to the first test's daemon until that one stops).
pub fn free_tcp_port() -> u16 {
    static HANDED_OUT: PortsHandedOut = Mutex::new(BTreeSet::new());
    unused_port(&HANDED_OUT, || {
        TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("a free TCP port on loopback")
            .port()
    })
}

/// A UDP port on 127.0.0.1 that nothing uses right now (the kernel's pick), for a
/// daemon's team port or a GameController socket, and never the same twice in one test
/// binary (for the reason [`free_tcp_port`] gives).
pub fn free_udp_port() -> u16 {
    static HANDED_OUT: PortsHandedOut = Mutex::new(BTreeSet::new());
    unused_port(&HANDED_OUT, || {
        std::net::UdpSocket::bind("127.0.0.1:0")
            .and_then(|s| s.local_addr())
            .expect("a free UDP port on loopback")
            .port()
    })
}

/// The ports of one kind this test binary has handed out.
type PortsHandedOut = Mutex<BTreeSet<u16>>;

/// The kernel's picks (`pick`) until one not in `handed_out`, which then holds it too.
fn unused_port(handed_out: &PortsHandedOut, pick: impl Fn() -> u16) -> u16 {
    loop {
        let port = pick();
        if handed_out
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(port)
        {
            return port;
        }
    }
}

/// A running daemon, killed when dropped.
pub struct Daemon {
    pub child: Child,
    pub relay: SocketAddr,
}

impl Daemon {
    /// Starts robot `id` on `group` (always on the loopback interface) with its relay on
    /// `relay_port`, and waits until the relay answers.
    pub fn start(
        id: u8,
        group: &str,
        relay_port: u16,
        extra: &[&str],
        config_dir: &Path,
    ) -> Daemon {
        let net = ["--group", group, "--iface", "127.0.0.1"];
        Daemon::start_on(id, &net, relay_port, extra, config_dir)
    }

    /// Starts robot `id` with the network arguments `net` (`--transport`, `--iface`,
    /// `--port`, `--group`...: the test's own, always loopback) and its relay on
    /// `relay_port`, and waits until the relay answers.
    pub fn start_on(
        id: u8,
        net: &[&str],
        relay_port: u16,
        extra: &[&str],
        config_dir: &Path,
    ) -> Daemon {
        let relay: SocketAddr = format!("127.0.0.1:{relay_port}").parse().unwrap();
        let child = Command::new(env!("CARGO_BIN_EXE_huddle"))
            .args(["daemon", "--id", &id.to_string()])
            .args(net)
            .args(["--relay", &relay.to_string()])
            .arg("--config-dir")
            .arg(config_dir)
            .args(extra)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("spawn huddle daemon");
        let mut d = Daemon { child, relay };
        await_relay(&mut d.child, relay, id);
        d
    }

    pub fn client(&self) -> Client {
        Client::connect(self.relay)
    }

    /// SIGKILL, as a crash.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        self.kill();
    }
}

/// A raw relay connection: bytes out, lines in.
pub struct Client {
    pub reader: BufReader<TcpStream>,
    pub writer: TcpStream,
    pub greeting: String,
}

impl Client {
    pub fn connect(addr: SocketAddr) -> Client {
        let stream = TcpStream::connect(addr).expect("connect to relay");
        stream
            .set_read_timeout(Some(Duration::from_secs(5)))
            .unwrap();
        let writer = stream.try_clone().unwrap();
        let mut c = Client {
            reader: BufReader::new(stream),
            writer,
            greeting: String::new(),
        };
        c.greeting = c.line();
        c
    }

    pub fn send_raw(&mut self, bytes: &[u8]) {
        self.writer.write_all(bytes).expect("write to relay");
    }

    /// One line, terminator stripped; panics on timeout or EOF.
    pub fn line(&mut self) -> String {
        let mut s = String::new();
        let n = self.reader.read_line(&mut s).expect("read from relay");
        assert!(n > 0, "relay closed the connection");
        s.trim_end_matches(['\r', '\n']).to_owned()
    }

    /// A daemon counter, `local.var.huddle.stats.<name>`: 0 while it is not mirrored yet
    /// (counters appear at the first refresh).
    pub fn stat(&mut self, name: &str) -> i64 {
        let answer = self.ask(&format!("GETV local.var.huddle.stats.{name}"));
        comms::relay::Binding::parse(&answer).map_or(0, |b| {
            b.value
                .parse()
                .unwrap_or_else(|_| panic!("{name}: {answer:?}"))
        })
    }

    /// Sends `line` and returns the one-line answer.
    pub fn ask(&mut self, line: &str) -> String {
        self.send_raw(format!("{line}\n").as_bytes());
        self.line()
    }

    /// `GETV` until the answer satisfies `ok`, or panic after `within`.
    pub fn wait_for(&mut self, key: &str, within: Duration, ok: impl Fn(&str) -> bool) -> String {
        let deadline = Instant::now() + within;
        loop {
            let answer = self.ask(&format!("GETV {key}"));
            if ok(&answer) {
                return answer;
            }
            assert!(
                Instant::now() < deadline,
                "{key}: still {answer:?} after {within:?}"
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Everything until EOF or reset, with a bound on how long to read.
    pub fn drain_to_end(&mut self, within: Duration) -> (usize, bool) {
        let deadline = Instant::now() + within;
        let mut total = 0;
        let mut buf = vec![0u8; 64 * 1024];
        self.reader
            .get_ref()
            .set_read_timeout(Some(Duration::from_millis(200)))
            .unwrap();
        while Instant::now() < deadline {
            match self.reader.read(&mut buf) {
                Ok(0) => return (total, true),
                Ok(n) => total += n,
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
                Err(_) => return (total, true),
            }
        }
        (total, false)
    }
}

/// `huddle replay FILE --json`: what a recording holds, one binding per line. Panics
/// (with replay's own error) if replay fails.
pub fn replay_json(file: &Path) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_huddle"))
        .env("RUST_LOG", "warn")
        .arg("replay")
        .arg(file)
        .arg("--json")
        .output()
        .expect("run huddle replay");
    assert!(
        out.status.success(),
        "replay failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("replay prints UTF-8")
}
