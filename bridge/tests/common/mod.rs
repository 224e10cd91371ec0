//! What the bridge's end-to-end tests share: the bridge binary as a child process, a
//! recording Zenoh subscriber, a capture of every datagram on the team's group.
#![allow(dead_code, clippy::disallowed_methods)]

use std::net::SocketAddrV4;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use comms::Value;
use huddle_bridge::export::parse_attachment;
use huddle_bridge::harness::Daemon;
use zenoh::sample::SampleKind;
use zenoh::Wait;

/// The bridge binary, killed when dropped.
pub struct BridgeProcess(pub Child);

impl BridgeProcess {
    /// `huddle-bridge --group G --iface 127.0.0.1 --team N --venue V --connect tcp/…`
    /// plus `extra`.
    pub fn start(group: SocketAddrV4, team: u8, venue: &str, port: u16, extra: &[&str]) -> Self {
        let child = Command::new(env!("CARGO_BIN_EXE_huddle-bridge"))
            .args(["--group", &group.to_string(), "--iface", "127.0.0.1"])
            .args(["--team", &team.to_string(), "--venue", venue])
            .args(["--connect", &format!("tcp/127.0.0.1:{port}")])
            .args(extra)
            .env("RUST_LOG", "info,zenoh=warn")
            .stdout(Stdio::null())
            .spawn()
            .expect("the bridge starts");
        BridgeProcess(child)
    }

    /// As [`BridgeProcess::start`], its log (stderr) written to `log`.
    pub fn start_logged(
        group: SocketAddrV4,
        team: u8,
        venue: &str,
        port: u16,
        extra: &[&str],
        log: &std::path::Path,
    ) -> Self {
        let file = std::fs::File::create(log).expect("the bridge's log file");
        let child = Command::new(env!("CARGO_BIN_EXE_huddle-bridge"))
            .args(["--group", &group.to_string(), "--iface", "127.0.0.1"])
            .args(["--team", &team.to_string(), "--venue", venue])
            .args(["--connect", &format!("tcp/127.0.0.1:{port}")])
            .args(extra)
            .env("RUST_LOG", "info,zenoh=warn")
            .env("NO_COLOR", "1")
            .stdout(Stdio::null())
            .stderr(file)
            .spawn()
            .expect("the bridge starts");
        BridgeProcess(child)
    }

    /// Sends SIGTERM.
    pub fn terminate(&self) {
        let status = Command::new("kill")
            .args(["-TERM", &self.0.id().to_string()])
            .status()
            .expect("kill runs");
        assert!(status.success(), "kill -TERM");
    }

    /// Whether it is still running.
    pub fn running(&mut self) -> bool {
        matches!(self.0.try_wait(), Ok(None))
    }
}

impl Drop for BridgeProcess {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A sample as received.
#[derive(Clone, Debug)]
pub struct Got {
    pub key: String,
    pub payload: String,
    pub attachment: String,
    pub at: Instant,
    /// Zenoh's timestamp: when the bridge published it (wall clock, this machine's).
    pub published: Option<std::time::SystemTime>,
}

impl Got {
    /// `(incarnation, version, age)` from the attachment.
    pub fn meta(&self) -> (u64, u64, Duration) {
        parse_attachment(&self.attachment).expect("a well-formed attachment")
    }
}

/// Samples and liveliness changes of one subscriber.
#[derive(Default)]
pub struct Recorded {
    pub samples: Vec<Got>,
    pub alive: Vec<(SampleKind, String)>,
}

/// A subscriber on `keyexpr` and a liveliness subscriber on `alive_keyexpr`.
pub struct Recorder {
    pub data: Arc<Mutex<Recorded>>,
    _subs: (
        zenoh::pubsub::Subscriber<()>,
        Option<zenoh::pubsub::Subscriber<()>>,
    ),
}

impl Recorder {
    pub fn new(session: &zenoh::Session, keyexpr: &str, alive_keyexpr: Option<&str>) -> Self {
        let data: Arc<Mutex<Recorded>> = Arc::default();
        let d = data.clone();
        let sub = session
            .declare_subscriber(keyexpr.to_owned())
            .callback(move |s| {
                let got = Got {
                    key: s.key_expr().as_str().to_owned(),
                    payload: s.payload().try_to_string().unwrap_or_default().into_owned(),
                    attachment: s
                        .attachment()
                        .and_then(|a| a.try_to_string().ok().map(|c| c.into_owned()))
                        .unwrap_or_default(),
                    at: Instant::now(),
                    published: s.timestamp().map(|t| t.get_time().to_system_time()),
                };
                d.lock().unwrap().samples.push(got);
            })
            .wait()
            .expect("subscribe");
        let lsub = alive_keyexpr.map(|k| {
            let d = data.clone();
            session
                .liveliness()
                .declare_subscriber(k.to_owned())
                .history(true)
                .callback(move |s| {
                    d.lock()
                        .unwrap()
                        .alive
                        .push((s.kind(), s.key_expr().as_str().to_owned()));
                })
                .wait()
                .expect("liveliness subscribe")
        });
        Recorder {
            data,
            _subs: (sub, lsub),
        }
    }

    pub fn samples(&self) -> Vec<Got> {
        self.data.lock().unwrap().samples.clone()
    }

    pub fn alive(&self) -> Vec<(SampleKind, String)> {
        self.data.lock().unwrap().alive.clone()
    }

    pub fn of(&self, key: &str) -> Vec<Got> {
        self.samples()
            .into_iter()
            .filter(|s| s.key == key)
            .collect()
    }
}

/// Polls `cond` every 10 ms until it holds or `timeout` passes; returns whether it held.
pub fn wait_until(timeout: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let end = Instant::now() + timeout;
    loop {
        if cond() {
            return true;
        }
        if Instant::now() > end {
            return false;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Every datagram sent to the team's group, captured by a socket of our own.
pub struct Capture {
    pub datagrams: Arc<Mutex<Vec<Vec<u8>>>>,
    pub socket: std::net::UdpSocket,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Capture {
    pub fn start(group: SocketAddrV4) -> Capture {
        let cfg = driver::SocketConfig {
            group,
            ..driver::SocketConfig::default()
        };
        let socket = driver::open(&cfg).expect("capture socket").socket;
        socket.set_nonblocking(false).unwrap();
        socket
            .set_read_timeout(Some(Duration::from_millis(20)))
            .unwrap();
        let datagrams: Arc<Mutex<Vec<Vec<u8>>>> = Arc::default();
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let socket = socket.try_clone().unwrap();
            let datagrams = datagrams.clone();
            let stop = stop.clone();
            std::thread::spawn(move || {
                let mut buf = vec![0u8; 65_536];
                while !stop.load(Ordering::Relaxed) {
                    if let Ok((n, _)) = socket.recv_from(&mut buf) {
                        datagrams.lock().unwrap().push(buf[..n].to_vec());
                    }
                }
            })
        };
        Capture {
            datagrams,
            socket,
            stop,
            thread: Some(thread),
        }
    }

    /// `(sender, incarnation)` of every captured frame of `team`.
    pub fn origins(&self, team: u8) -> Vec<(u8, u64)> {
        self.datagrams
            .lock()
            .unwrap()
            .iter()
            .filter_map(|d| comms::wire::peek_origin(d, team))
            .collect()
    }

    /// The last captured frame of `sender` in life `incarnation`.
    pub fn last_of(&self, team: u8, sender: u8, incarnation: u64) -> Option<Vec<u8>> {
        self.datagrams
            .lock()
            .unwrap()
            .iter()
            .rev()
            .find(|d| comms::wire::peek_origin(d, team) == Some((sender, incarnation)))
            .cloned()
    }
}

impl Drop for Capture {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Whether `python3` can import `module`.
pub fn python_with(module: &str) -> bool {
    Command::new("python3")
        .args(["-c", &format!("import {module}")])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Every daemon sets its keys `k0 .. k{keys}` to `value`, in one batch (one datagram) each:
/// a round of a load test.
pub fn set_round(daemons: &[Daemon], keys: usize, value: i64) {
    for d in daemons {
        d.run(move |h| {
            h.batch(|b| {
                for k in 0..keys {
                    let _ = b.set(&format!("*.var.k{k}"), Value::Int(value));
                }
            });
            None
        });
    }
}
