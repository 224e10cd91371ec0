//! A listen-only member of a team's group: the same `comms::Replica` every robot runs,
//! fed every datagram heard (live or from a recording) and never allowed to send: what
//! it would transmit (its heartbeat, NACKs) is drained and discarded after every input.
//!
//! The listener needs a robot id of its own; frames *from* that id are taken for an id
//! conflict and dropped, so it uses one no robot of the team has (254 by default).

use std::net::SocketAddr;
use std::time::Duration;

use anyhow::{Context, Result};
use comms::{Event, Instant, Replica, ReplicaConfig, Scope, Value};
use serde_json::json;

/// The robot id a listener takes unless told otherwise: one no team uses.
pub const LISTENER_ID: u8 = 254;

/// Something the listener learned, in the order it learned it.
#[derive(Clone, Debug, PartialEq)]
pub enum Heard {
    /// A robot's value changed (`n.var.path`) or a talk message arrived (`n.talk.q`).
    Update {
        /// Seconds since the listener started.
        t_s: f64,
        /// The robot that wrote it.
        owner: u8,
        /// The key as stored (`2.var.ball.dist`).
        key: String,
        /// The value.
        value: Value,
    },
    /// A robot was heard for the first time or again.
    Joined {
        /// Seconds since the listener started.
        t_s: f64,
        /// Its id.
        robot: u8,
    },
    /// A robot fell silent.
    Departed {
        /// Seconds since the listener started.
        t_s: f64,
        /// Its id.
        robot: u8,
    },
    /// Two robots send with one id.
    Conflict {
        /// Seconds since the listener started.
        t_s: f64,
        /// The id.
        robot: u8,
    },
}

impl Heard {
    /// The update as the JSON line `huddle replay --json` prints:
    /// `{"t", "owner", "key", "type", "value"}`; `None` for peer changes.
    pub fn update_json(&self) -> Option<serde_json::Value> {
        let Heard::Update {
            t_s,
            owner,
            key,
            value,
        } = self
        else {
            return None;
        };
        Some(serde_json::json!({
            "t": (t_s * 1e6).round() / 1e6,
            "owner": owner,
            "key": key,
            "type": value.value_type().name(),
            "value": value_json(&value.to_string()),
        }))
    }
}

/// Timer deadlines [`Listener::advance`] runs one by one before it jumps to the end of a
/// gap: 1,000 refresh periods (100 s at the default 100 ms), more than any departure or
/// give-up takes, so a real recording's events keep their times.
pub const MAX_TIMER_STEPS: usize = 1000;

/// A replica that hears and never speaks.
pub struct Listener {
    replica: Replica,
    start_ns: u64,
}

/// Where the listener's clock starts: a day in, not at zero. A value heard for the first
/// time is stamped `arrival - the age its owner reported`; from a clock at zero that
/// would saturate at the listener's start, and a value 4 minutes old would show as old
/// as the monitor. Values up to a day old keep their true age.
const ORIGIN_US: u64 = 24 * 3600 * 1_000_000;

impl Listener {
    /// A listener for team `team` (with its key, if frames are tagged), whose clock
    /// starts at `start_ns` (nanoseconds on the clock the datagrams will be stamped with).
    pub fn new(team: u8, key: Option<Vec<u8>>, listener_id: u8, start_ns: u64) -> Result<Self> {
        // The daemons send the team layer's keys by index: read them by the same table.
        let mut cfg = ReplicaConfig::new(listener_id, team).with_known_paths(team::known_paths());
        if let Some(key) = key {
            cfg = cfg.with_team_key(key);
        }
        let replica = Replica::new(cfg, 1, Instant::from_micros(ORIGIN_US))
            .context("setting up the listening replica")?;
        let mut l = Self { replica, start_ns };
        l.discard_transmits();
        Ok(l)
    }

    /// The replica (its blackboard, peers and stats).
    pub fn replica(&self) -> &Replica {
        &self.replica
    }

    /// The listener's clock at `t_ns` (earlier times count as its start).
    pub fn instant(&self, t_ns: u64) -> Instant {
        Instant::from_micros(ORIGIN_US + t_ns.saturating_sub(self.start_ns) / 1000)
    }

    /// Seconds since the start at `t_ns`.
    pub fn seconds(&self, t_ns: u64) -> f64 {
        t_ns.saturating_sub(self.start_ns) as f64 / 1e9
    }

    /// Runs the replica's timers up to `t_ns` (departures are noticed here): each
    /// deadline in turn, up to [`MAX_TIMER_STEPS`]; the rest of a longer gap at once (a
    /// recording's clock may jump by years: a replay costs O(frames), not O(gap)).
    pub fn advance(&mut self, t_ns: u64, out: &mut Vec<Heard>) {
        let now = self.instant(t_ns);
        let mut steps = 0;
        while let Some(deadline) = self.replica.poll_timeout() {
            if deadline > now {
                break;
            }
            steps += 1;
            let at = if steps > MAX_TIMER_STEPS {
                now
            } else {
                deadline
            };
            self.replica.handle_timeout(at);
            self.discard_transmits();
            self.drain_events(at, out);
            if at == now {
                break;
            }
        }
    }

    /// Feeds one datagram received at `t_ns` from `from`.
    pub fn datagram(&mut self, t_ns: u64, from: SocketAddr, bytes: &[u8], out: &mut Vec<Heard>) {
        self.advance(t_ns, out);
        let now = self.instant(t_ns);
        self.replica.handle_datagram(now, from, bytes);
        self.discard_transmits();
        self.drain_events(now, out);
    }

    fn discard_transmits(&mut self) {
        while self.replica.poll_transmit().is_some() {}
    }

    fn drain_events(&mut self, now: Instant, out: &mut Vec<Heard>) {
        let t_s = now
            .saturating_duration_since(Instant::from_micros(ORIGIN_US))
            .as_secs_f64();
        while let Some(event) = self.replica.poll_event() {
            match event {
                Event::ValueChanged { key } => {
                    let Scope::Robot(owner) = key.scope() else {
                        continue; // the listener's own local values (its stats)
                    };
                    let Ok(Some(entry)) = self.replica.get(&key.to_string()) else {
                        continue;
                    };
                    out.push(Heard::Update {
                        t_s,
                        owner,
                        key: key.to_string(),
                        value: entry.value.clone(),
                    });
                }
                Event::TalkDelivered {
                    queue, from, value, ..
                } => out.push(Heard::Update {
                    t_s,
                    owner: from,
                    key: format!("{from}.talk.{queue}"),
                    value,
                }),
                Event::PeerJoined { robot, .. } => out.push(Heard::Joined { t_s, robot }),
                Event::PeerRestarted { robot, .. } => out.push(Heard::Joined { t_s, robot }),
                Event::PeerDeparted { robot } => out.push(Heard::Departed { t_s, robot }),
                Event::IncarnationConflict { robot, .. } => {
                    out.push(Heard::Conflict { t_s, robot })
                }
                Event::TalkGivenUp { .. } | Event::FrameDropped { .. } => {}
            }
        }
    }
}

/// How long after the last datagram a recording's replay still runs timers, so that
/// robots that fell silent at the end are reported departed.
pub const REPLAY_TAIL: Duration = Duration::from_secs(1);

/// A value literal as JSON: numbers, booleans, strings, arrays of numbers; bytes as a
/// `0x…` hex string; a float that JSON cannot hold (NaN, ±inf) as its literal string.
pub fn value_json(literal: &str) -> serde_json::Value {
    match comms::parse_literal(literal) {
        Ok(Value::Int(v)) => json!(v),
        Ok(Value::Float(v)) if v.is_finite() => json!(v),
        Ok(Value::Bool(v)) => json!(v),
        Ok(Value::String(s)) => json!(s),
        Ok(Value::Floats(v)) if v.iter().all(|x| x.is_finite()) => {
            json!(v)
        }
        // Bytes, non-finite floats, or a type this build does not know: the literal.
        _ => json!(literal),
    }
}
