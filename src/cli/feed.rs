//! A relay subscription that outlives the daemon: `ADDW` each pattern, `REFR`, then read
//! pushes on a thread of its own, reconnecting with backoff (100 ms doubling to 5 s) when
//! the connection drops, e.g. while the daemon restarts. Used by `echo` and `watch`.

use std::sync::mpsc;
use std::time::Duration;

use anyhow::{bail, Result};

use super::relay::{RelayClient, RelayTarget};

/// First and longest wait between reconnection attempts.
const BACKOFF: (Duration, Duration) = (Duration::from_millis(100), Duration::from_secs(5));

/// What the feed's thread reports.
#[derive(Debug)]
pub enum FeedEvent {
    /// (Re)connected and subscribed; the relay's greeting.
    Connected(String),
    /// A pushed line (`UPD …`, `LOST …`, anything else the relay says).
    Line(String),
    /// The connection is down: why, and when the next attempt is made.
    Down {
        /// What went wrong.
        reason: String,
        /// Wait before the next attempt.
        retry_in: Duration,
    },
}

/// A subscription: see the module docs.
pub struct Feed {
    rx: mpsc::Receiver<FeedEvent>,
    /// The first connection's greeting.
    pub greeting: String,
}

fn subscribe(target: &RelayTarget, patterns: &[String], refresh_ms: u64) -> Result<RelayClient> {
    let mut c = RelayClient::connect(target)?;
    for p in patterns {
        c.request(&format!("ADDW {p}"))?;
    }
    c.request(&format!("REFR {refresh_ms}"))?;
    Ok(c)
}

impl Feed {
    /// Subscribes now (an error if the relay is not there or refuses a pattern), then
    /// reads and reconnects on a thread.
    pub fn start(target: RelayTarget, patterns: Vec<String>, refresh_ms: u64) -> Result<Feed> {
        let first = subscribe(&target, &patterns, refresh_ms)?;
        let greeting = first.greeting.clone();
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut client = Some(first);
            let mut backoff = BACKOFF.0;
            loop {
                let reason = match client.take() {
                    Some(c) => {
                        backoff = BACKOFF.0;
                        match pump(c, &tx) {
                            Some(reason) => reason,
                            None => return, // nobody listens any more
                        }
                    }
                    None => match subscribe(&target, &patterns, refresh_ms) {
                        Ok(c) => {
                            if tx.send(FeedEvent::Connected(c.greeting.clone())).is_err() {
                                return;
                            }
                            client = Some(c);
                            continue;
                        }
                        Err(e) => format!("{e:#}"),
                    },
                };
                let event = FeedEvent::Down {
                    reason,
                    retry_in: backoff,
                };
                if tx.send(event).is_err() {
                    return;
                }
                std::thread::sleep(backoff);
                backoff = (backoff * 2).min(BACKOFF.1);
            }
        });
        Ok(Feed { rx, greeting })
    }

    /// The next event, waiting at most `timeout`; `None` if nothing came.
    pub fn next_within(&self, timeout: Duration) -> Result<Option<FeedEvent>> {
        match self.rx.recv_timeout(timeout) {
            Ok(e) => Ok(Some(e)),
            Err(mpsc::RecvTimeoutError::Timeout) => Ok(None),
            Err(mpsc::RecvTimeoutError::Disconnected) => bail!("the relay feed stopped"),
        }
    }

    /// The next event.
    pub fn next(&self) -> Result<FeedEvent> {
        match self.rx.recv() {
            Ok(e) => Ok(e),
            Err(_) => bail!("the relay feed stopped"),
        }
    }
}

/// Forwards lines until the connection ends: `Some(why)`, or `None` if the receiver is gone.
fn pump(c: RelayClient, tx: &mpsc::Sender<FeedEvent>) -> Option<String> {
    use std::io::BufRead;
    let mut reader = c.into_reader();
    let mut s = String::new();
    loop {
        s.clear();
        match reader.read_line(&mut s) {
            Ok(0) => return Some("the relay closed the connection".into()),
            Ok(_) => {
                let line = s.trim_end_matches(['\r', '\n']).to_owned();
                tx.send(FeedEvent::Line(line)).ok()?;
            }
            Err(e) => return Some(format!("reading from the relay: {e}")),
        }
    }
}
