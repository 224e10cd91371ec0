//! Loopback rigs for the tests and `huddle-bridge bench`: in-process daemons (the same
//! `driver::Driver` `huddle daemon` runs, one thread and one current-thread runtime
//! each) and an in-process Zenoh router. Everything binds 127.0.0.1 and uses scratch
//! multicast groups: nothing leaves the machine.

use std::net::SocketAddrV4;
use std::sync::mpsc as std_mpsc;
use std::thread::JoinHandle;

use comms::ReplicaConfig;
use driver::{Driver, DriverConfig, Handle, Impairment, SocketConfig, Watch};
use tokio::sync::{mpsc, oneshot};
use zenoh::Wait;

/// Work for a daemon's thread: runs on its driver's task with its handle; a returned
/// watch stays registered until the daemon stops.
pub type Command = Box<dyn FnOnce(&Handle) -> Option<Watch> + Send>;

/// Builds a daemon's impairment on its own thread (the driver is not `Send`).
pub type ImpairmentFactory = Box<dyn FnOnce() -> Box<dyn Impairment> + Send>;

/// A daemon running on a thread of this process.
pub struct Daemon {
    commands: mpsc::UnboundedSender<Command>,
    stop: Option<oneshot::Sender<()>>,
    thread: Option<JoinHandle<()>>,
    /// Its robot id.
    pub id: u8,
}

/// How a test daemon is set up.
pub struct DaemonSpec {
    /// Robot id.
    pub id: u8,
    /// Team id.
    pub team: u8,
    /// The team's scratch group.
    pub group: SocketAddrV4,
    /// The team key.
    pub key: Option<Vec<u8>>,
    /// An impairment of every outgoing datagram.
    pub impairment: Option<ImpairmentFactory>,
    /// The incarnation (`None`: a fresh random one).
    pub incarnation: Option<u64>,
}

impl DaemonSpec {
    /// Robot `id` of `team` on `group`, no key, no impairment.
    pub fn new(id: u8, team: u8, group: SocketAddrV4) -> DaemonSpec {
        DaemonSpec {
            id,
            team,
            group,
            key: None,
            impairment: None,
            incarnation: None,
        }
    }
}

impl Daemon {
    /// Starts a daemon; returns once its socket is open.
    pub fn start(spec: DaemonSpec) -> std::io::Result<Daemon> {
        let (tx, mut rx) = mpsc::unbounded_channel::<Command>();
        let (stop_tx, stop_rx) = oneshot::channel::<()>();
        let (ready_tx, ready_rx) = std_mpsc::channel::<Result<(), String>>();
        let id = spec.id;
        let thread = std::thread::Builder::new()
            .name(format!("daemon-{id}"))
            .spawn(move || {
                let rt = match tokio::runtime::Builder::new_current_thread()
                    .enable_all()
                    .build()
                {
                    Ok(rt) => rt,
                    Err(e) => {
                        let _ = ready_tx.send(Err(e.to_string()));
                        return;
                    }
                };
                let local = tokio::task::LocalSet::new();
                local.block_on(&rt, async move {
                    let mut rcfg = ReplicaConfig::new(spec.id, spec.team);
                    if let Some(key) = spec.key {
                        rcfg = rcfg.with_team_key(key);
                    }
                    let mut cfg = DriverConfig::new(rcfg);
                    cfg.socket = SocketConfig {
                        group: spec.group,
                        ..SocketConfig::default()
                    };
                    cfg.incarnation = spec.incarnation;
                    let driver = match Driver::bind(cfg) {
                        Ok(d) => d,
                        Err(e) => {
                            let _ = ready_tx.send(Err(e.to_string()));
                            return;
                        }
                    };
                    if let Some(make) = spec.impairment {
                        driver.set_impairment(Some(make()));
                    }
                    let handle = driver.handle();
                    let run = tokio::task::spawn_local(driver.run(async {
                        let _ = stop_rx.await;
                    }));
                    let _ = ready_tx.send(Ok(()));
                    let mut watches = Vec::new();
                    loop {
                        tokio::select! {
                            cmd = rx.recv() => match cmd {
                                Some(cmd) => watches.extend(cmd(&handle)),
                                None => break,
                            },
                            _ = tokio::time::sleep(std::time::Duration::from_millis(20)) => {
                                if run.is_finished() {
                                    break;
                                }
                            }
                        }
                    }
                    drop(watches);
                    let _ = run.await;
                });
            })?;
        match ready_rx.recv() {
            Ok(Ok(())) => Ok(Daemon {
                commands: tx,
                stop: Some(stop_tx),
                thread: Some(thread),
                id,
            }),
            Ok(Err(e)) => Err(std::io::Error::other(e)),
            Err(_) => Err(std::io::Error::other("the daemon thread ended")),
        }
    }

    /// Runs `f` on the daemon's task.
    pub fn run(&self, f: impl FnOnce(&Handle) -> Option<Watch> + Send + 'static) {
        let _ = self.commands.send(Box::new(f));
    }

    /// Sets `key` to the literal `value` (`2.5`, `"x"`), logging a refusal.
    pub fn set(&self, key: &str, value: comms::Value) {
        let key = key.to_owned();
        self.run(move |h| {
            if let Err(e) = h.set(&key, value) {
                tracing::warn!("set {key}: {e}");
            }
            None
        });
    }

    /// Stops the daemon without a word to its team (like `kill -9`: huddle sends no
    /// goodbye, a robot that stops is one that falls silent).
    pub fn kill(mut self) {
        self.stop_now();
    }

    fn stop_now(&mut self) {
        if let Some(stop) = self.stop.take() {
            let _ = stop.send(());
        }
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        self.stop_now();
    }
}

/// A free TCP port on 127.0.0.1 (the kernel's choice, released at once).
pub fn free_port() -> std::io::Result<u16> {
    Ok(std::net::TcpListener::bind("127.0.0.1:0")?
        .local_addr()?
        .port())
}

/// A Zenoh router listening on `tcp/127.0.0.1:<port>`, scouting off; `extra`: further
/// `(key, json5 value)` settings (access control, authentication).
pub fn router(port: u16, extra: &[(&str, &str)]) -> zenoh::Result<zenoh::Session> {
    let mut cfg = zenoh::Config::default();
    cfg.insert_json5("mode", "\"router\"")?;
    cfg.insert_json5("listen/endpoints", &format!("[\"tcp/127.0.0.1:{port}\"]"))?;
    cfg.insert_json5("scouting/multicast/enabled", "false")?;
    for (k, v) in extra {
        cfg.insert_json5(k, v)?;
    }
    zenoh::open(cfg).wait()
}

/// A client session connected to the router on `port`; `extra` as for [`router`].
pub fn client(port: u16, extra: &[(&str, &str)]) -> zenoh::Result<zenoh::Session> {
    let mut cfg = zenoh::Config::default();
    cfg.insert_json5("mode", "\"client\"")?;
    cfg.insert_json5("connect/endpoints", &format!("[\"tcp/127.0.0.1:{port}\"]"))?;
    cfg.insert_json5("scouting/multicast/enabled", "false")?;
    for (k, v) in extra {
        cfg.insert_json5(k, v)?;
    }
    zenoh::open(cfg).wait()
}
