//! What the monitor shows, built from the team's frames alone: a listen-only replica
//! ([`Listener`]) for the blackboard, peers and talk; each robot's published local world
//! model (`n.var.world.local`: pose, covariance, ball) decoded; a global world model of
//! the monitor's own fed every LWM (the team ball, as a teammate would fuse it); the
//! should-I-go claims (`n.var.machine.heuristic`: cost and whether it goes); frame
//! counters per robot (rate, loss from sequence gaps, frames sent against a budget).
//! A simulated match adds the truth ([`Truth`]), which no robot has.
//!
//! [`Model::state`] is the picture as JSON, the same for `GET /state`, the page's live
//! updates and scripts.

use std::collections::{BTreeMap, VecDeque};
use std::net::SocketAddr;

use anyhow::Result;
use comms::arbitration::Posted;
use comms::wire::TeamKey;
use comms::{Pattern, Value};
use fusion::{GlobalConfig, GlobalModel, LocalWorldModel};
use serde_json::{json, Value as Json};

use crate::listen::{Heard, Listener};

/// The field drawn: sizes in metres (the simulator's field by default).
#[derive(Clone, Copy, Debug)]
pub struct Field {
    /// Between the goal lines.
    pub length_m: f64,
    /// Between the touch lines.
    pub width_m: f64,
    /// Goal mouth.
    pub goal_width_m: f64,
    /// Carpet beyond the lines.
    pub border_m: f64,
}

impl Default for Field {
    fn default() -> Self {
        // The field a team's robots believe they play on, until told otherwise.
        let f = team::Calibration::default().field;
        Self {
            length_m: f.length_m,
            width_m: f.width_m,
            goal_width_m: f.goal_width_m,
            border_m: f.border_m,
        }
    }
}

/// Where everything really is (a simulated match only).
#[derive(Clone, Debug, Default)]
pub struct Truth {
    /// Each robot: id, x, y (m), heading (rad), role.
    pub robots: Vec<(u8, f64, f64, f64, String)>,
    /// The ball: x, y (m).
    pub ball: (f64, f64),
    /// Opponents: x, y (m).
    pub opponents: Vec<(f64, f64)>,
}

/// Window over which a robot's message rate is measured, seconds.
const RATE_WINDOW_S: f64 = 2.0;
/// Bindings of the board the picture shows at most, in key order (`board_total` in the
/// picture says how many there are): a spoofer that fills the board to its limit does
/// not make every picture megabytes long.
pub const BOARD_SHOWN: usize = 500;
/// Frames one step forward in a robot's frame numbers counts for at most: a spoofed
/// frame numbered 10^9 (no key) shows as that many lost, not as 100% loss and a spent
/// budget. A real outage longer than this shows as a departure.
const MAX_SEQ_STEP: u64 = 64;
/// Talk messages kept for the log.
const TALK_KEPT: usize = 200;

#[derive(Default)]
struct RobotView {
    lwm: Option<LocalWorldModel>,
    posted: Option<Posted>,
    pass_to: Option<i64>,
    incarnation: u64,
    /// Highest frame number heard from the current life (`None`: none yet).
    last_seq: Option<u64>,
    /// Frames it sent, as far as the frame numbers say: each step forward counts, up to
    /// [`MAX_SEQ_STEP`] (a frame numbered far ahead, forged or not, moves it that much).
    sent: u64,
    received: u64,
    arrivals: VecDeque<f64>,
}

/// The monitor's picture of the team.
pub struct Model {
    listener: Listener,
    team: u8,
    key: Option<TeamKey>,
    gwm: GlobalModel,
    robots: BTreeMap<u8, RobotView>,
    talk: VecDeque<Json>,
    truth: Option<Truth>,
    field: Field,
    source: String,
    budget: Option<u64>,
    now_ns: u64,
    finished: bool,
}

impl Model {
    /// A model for team `team` (with its key, if frames are tagged), its clock starting at
    /// `start_ns`. `source` names where the frames come from (`sim`, `live`, `replay`),
    /// `budget` is the frames each robot may send (a league's message limit), if any.
    pub fn new(
        team: u8,
        key: Option<Vec<u8>>,
        listener_id: u8,
        start_ns: u64,
        source: &str,
        budget: Option<u64>,
    ) -> Result<Self> {
        let team_key = key.as_deref().map(TeamKey::new);
        Ok(Self {
            listener: Listener::new(team, key, listener_id, start_ns)?,
            team,
            key: team_key,
            gwm: GlobalModel::new(listener_id, GlobalConfig::default()),
            robots: BTreeMap::new(),
            talk: VecDeque::new(),
            truth: None,
            field: Field::default(),
            source: source.to_owned(),
            budget,
            now_ns: start_ns,
            finished: false,
        })
    }

    /// Sets the field drawn.
    pub fn set_field(&mut self, field: Field) {
        self.field = field;
    }

    /// Sets the truth (a simulated match).
    pub fn set_truth(&mut self, truth: Truth) {
        self.truth = Some(truth);
    }

    /// Marks the source as ended (a match or recording over): the picture stays.
    pub fn finish(&mut self) {
        self.finished = true;
    }

    /// Runs the clock to `t_ns` (departures).
    pub fn advance(&mut self, t_ns: u64) {
        let mut heard = Vec::new();
        self.advance_heard(t_ns, &mut heard);
    }

    /// Runs the clock to `t_ns`, adding what changed to `heard`.
    pub fn advance_heard(&mut self, t_ns: u64, heard: &mut Vec<Heard>) {
        self.now_ns = self.now_ns.max(t_ns);
        let from = heard.len();
        self.listener.advance(t_ns, heard);
        self.take(&heard[from..]);
    }

    /// Seconds since the model's start at `t_ns`.
    pub fn seconds_at(&self, t_ns: u64) -> f64 {
        self.listener.seconds(t_ns)
    }

    /// One datagram received at `t_ns` from `from`; returns what it changed.
    ///
    /// Only frames the listening replica took count in the frame counters (rate, loss,
    /// budget): with a team key a forged or replayed frame (another life's, or a copy)
    /// changes none of them. Without a key any frame can be forged, counters included.
    pub fn datagram(&mut self, t_ns: u64, from: SocketAddr, bytes: &[u8]) -> Vec<Heard> {
        self.now_ns = self.now_ns.max(t_ns);
        let t_s = self.listener.seconds(t_ns);
        let taken = |r: &comms::Replica| (r.stats().drops_total(), r.stats().own_frames);
        let before = taken(self.listener.replica());
        let mut heard = Vec::new();
        self.listener.datagram(t_ns, from, bytes, &mut heard);
        let admitted = taken(self.listener.replica()) == before;
        let frame = admitted
            .then(|| comms::wire::decode_frame(bytes, self.team, self.key.as_ref()).ok())
            .flatten();
        if let Some(frame) = frame {
            let v = self.robots.entry(frame.sender).or_default();
            if v.incarnation != frame.incarnation {
                v.incarnation = frame.incarnation;
                v.last_seq = None;
                v.sent = 0;
                v.received = 0;
            }
            match v.last_seq {
                None => v.sent = 1,
                Some(last) if frame.seq > last => {
                    v.sent += (frame.seq - last).min(MAX_SEQ_STEP);
                }
                Some(_) => {}
            }
            v.last_seq = v.last_seq.max(Some(frame.seq));
            v.received += 1;
            v.arrivals.push_back(t_s);
            while v.arrivals.front().is_some_and(|&a| a < t_s - RATE_WINDOW_S) {
                v.arrivals.pop_front();
            }
        }
        self.take(&heard);
        heard
    }

    fn take(&mut self, heard: &[Heard]) {
        let now = self.listener.instant(self.now_ns);
        let now_s = self.listener.seconds(self.now_ns);
        for h in heard {
            let Heard::Update {
                t_s,
                owner,
                key,
                value,
            } = h
            else {
                continue;
            };
            let path = key.split_once(".var.").map(|(_, p)| p);
            match (path, value) {
                (Some("world.local"), Value::Bytes(bytes)) => {
                    let age_s = self
                        .listener
                        .replica()
                        .get(key)
                        .ok()
                        .flatten()
                        .map_or(0.0, |e| e.age(now).as_secs_f64());
                    let v = self.robots.entry(*owner).or_default();
                    if let Ok(lwm) = LocalWorldModel::from_bytes(bytes, now_s - age_s) {
                        v.lwm = Some(lwm);
                    }
                    // A malformed LWM is the sender's bug: the team ball just goes without it.
                    let _ = self.gwm.receive(*owner, bytes, now_s, age_s);
                }
                (Some("machine.heuristic"), Value::Floats(f)) => {
                    self.robots.entry(*owner).or_default().posted = Posted::from_floats(f);
                }
                (Some("machine.pass_to"), Value::Int(n)) => {
                    self.robots.entry(*owner).or_default().pass_to = Some(*n);
                }
                _ => {}
            }
            if key.contains(".talk.") {
                self.talk.push_back(json!({
                    "t": t_s, "owner": owner, "key": key,
                    "value": crate::value_json(&value.to_string()),
                }));
                while self.talk.len() > TALK_KEPT {
                    self.talk.pop_front();
                }
            }
        }
    }

    /// Seconds since the model's start.
    pub fn t_s(&self) -> f64 {
        self.listener.seconds(self.now_ns)
    }

    /// The team ball as the monitor's GWM fuses it now: x, y (m) and its confidence.
    pub fn team_ball(&self) -> Option<(f64, f64, f64)> {
        let b = self.gwm.team_ball(self.t_s(), None)?;
        let p = b.estimate.position();
        Some((p.x, p.y, b.gbc))
    }

    /// The listening replica (frames, drops).
    pub fn replica(&self) -> &comms::Replica {
        self.listener.replica()
    }

    /// The picture as JSON: robots (id, pose, covariance, ball, role, goer, last heard,
    /// departed, conflicting, rate, loss, budget), the team ball, the truth if known,
    /// the blackboard and the talk log.
    pub fn state(&self) -> Json {
        let now = self.listener.instant(self.now_ns);
        let now_s = self.listener.seconds(self.now_ns);
        let replica = self.listener.replica();
        let peers: BTreeMap<u8, comms::PeerInfo> = replica.peers().map(|p| (p.robot, p)).collect();
        let goer = self
            .robots
            .iter()
            .filter(|(id, v)| {
                v.posted.is_some_and(|p| p.going) && peers.get(id).is_some_and(|p| p.present)
            })
            .map(|(id, _)| *id)
            .min();
        let receivers: Vec<i64> = self
            .robots
            .iter()
            .filter(|(id, v)| Some(**id) == goer && v.pass_to.is_some_and(|n| n > 0))
            .filter_map(|(_, v)| v.pass_to)
            .collect();
        let truth_role = |id: u8| {
            self.truth
                .as_ref()
                .and_then(|t| t.robots.iter().find(|r| r.0 == id).map(|r| r.4.clone()))
        };
        let robots: Vec<Json> = self
            .robots
            .iter()
            .map(|(&id, v)| {
                let peer = peers.get(&id);
                let pose = v.lwm.as_ref().map(|l| {
                    let m = &l.pose.mean;
                    let c = &l.pose.cov;
                    json!({
                        "pose": {"x": m.x, "y": m.y, "theta": m.z},
                        "cov": [[c[(0, 0)], c[(0, 1)], c[(0, 2)]],
                                [c[(1, 0)], c[(1, 1)], c[(1, 2)]],
                                [c[(2, 0)], c[(2, 1)], c[(2, 2)]]],
                        "ball": l.ball.as_ref().map(|b| {
                            let p = b.position();
                            let pc = b.position_cov();
                            json!({"x": p.x, "y": p.y,
                                   "cov": [[pc[(0, 0)], pc[(0, 1)]], [pc[(1, 0)], pc[(1, 1)]]]})
                        }),
                        "slc": l.slc, "lbc": l.lbc,
                    })
                });
                let going = goer == Some(id);
                let departed = peer.is_some_and(|p| !p.present);
                let role = if departed {
                    "departed".to_owned()
                } else if going {
                    "active".to_owned()
                } else if receivers.contains(&i64::from(id)) {
                    "auxiliary".to_owned()
                } else if let Some(r) = truth_role(id) {
                    r
                } else {
                    "inactive".to_owned()
                };
                let sent = v.sent;
                let loss = if sent > 0 {
                    1.0 - (v.received.min(sent) as f64 / sent as f64)
                } else {
                    0.0
                };
                let recent = v.arrivals.iter().filter(|&&a| a >= now_s - RATE_WINDOW_S).count();
                let rate = recent as f64 / RATE_WINDOW_S.min(now_s).max(0.1);
                let mut r = json!({
                    "id": id,
                    "pose": Json::Null, "cov": Json::Null, "ball": Json::Null,
                    "role": role,
                    "goer": going,
                    "h": v.posted.map(|p| p.h),
                    "claims": v.posted.is_some_and(|p| p.going),
                    "last_heard_s": peer.map(|p| now.saturating_duration_since(p.last_heard).as_secs_f64()),
                    "departed": departed,
                    "conflicting": peer.is_some_and(|p| p.conflicting),
                    "rate_hz": rate,
                    "loss": loss,
                    "frames_sent": sent,
                    "frames_received": v.received,
                    "budget_used": self.budget.map(|b| sent as f64 / b.max(1) as f64),
                });
                if let (Some(p), Some(obj)) = (pose, r.as_object_mut()) {
                    for k in ["pose", "cov", "ball", "slc", "lbc"] {
                        obj.insert(k.into(), p[k].clone());
                    }
                }
                r
            })
            .collect();
        let team_ball = self.gwm.team_ball(now_s, None).map(|b| {
            let p = b.estimate.position();
            json!({"x": p.x, "y": p.y, "gbc": b.gbc})
        });
        let truth = self.truth.as_ref().map(|t| {
            json!({
                "robots": t.robots.iter().map(|r| json!({"id": r.0, "x": r.1, "y": r.2, "theta": r.3, "role": r.4})).collect::<Vec<_>>(),
                "ball": {"x": t.ball.0, "y": t.ball.1},
                "opponents": t.opponents.iter().map(|o| json!({"x": o.0, "y": o.1})).collect::<Vec<_>>(),
            })
        });
        let all = Pattern::parse("#").ok();
        let robot_keys = || {
            all.iter()
                .flat_map(|p| replica.iter(p))
                .filter(|(k, _)| matches!(k.scope(), comms::Scope::Robot(_)))
        };
        let board_total = robot_keys().count();
        let board: Vec<Json> = robot_keys()
            .take(BOARD_SHOWN)
            .map(|(k, e)| {
                let mut b = json!({
                    "key": k.to_string(),
                    "owner": e.owner,
                    "type": e.value.value_type().name(),
                    "value": crate::value_json(&e.value.to_string()),
                    "age_ms": e.age(now).as_secs_f64() * 1e3,
                    "departed": replica.is_departed(e.owner),
                });
                if let (true, Value::Bytes(bytes)) = (k.path() == "world.local", &e.value) {
                    b["decoded"] = decode_world(bytes, now_s - e.age(now).as_secs_f64());
                }
                b
            })
            .collect();
        json!({
            "t": now_s,
            "source": self.source,
            "finished": self.finished,
            "field": {
                "length_m": self.field.length_m, "width_m": self.field.width_m,
                "goal_width_m": self.field.goal_width_m, "border_m": self.field.border_m,
            },
            "goer": goer,
            "robots": robots,
            "team_ball": team_ball,
            "truth": truth,
            "board": board,
            "board_total": board_total,
            "talk": self.talk.iter().collect::<Vec<_>>(),
        })
    }
}

/// A robot's world model (`n.var.world.local`, bytes on the wire) as the board shows
/// it: pose, its standard deviations, the ball it sees and its confidences; `null` when
/// it does not decode.
fn decode_world(bytes: &[u8], t_s: f64) -> Json {
    let Ok(l) = LocalWorldModel::from_bytes(bytes, t_s) else {
        return Json::Null;
    };
    let m = &l.pose.mean;
    let c = &l.pose.cov;
    json!({
        "pose": {"x": m.x, "y": m.y, "theta": m.z},
        "pose_sd": {"x": c[(0, 0)].max(0.0).sqrt(), "y": c[(1, 1)].max(0.0).sqrt(),
                    "theta": c[(2, 2)].max(0.0).sqrt()},
        "ball": l.ball.as_ref().map(|b| {
            let p = b.position();
            json!({"x": p.x, "y": p.y})
        }),
        "slc": l.slc,
        "lbc": l.lbc,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use comms::{Instant, Replica, ReplicaConfig};

    fn frames_of_robot_2() -> Vec<Vec<u8>> {
        let t0 = Instant::from_micros(0);
        let mut r = Replica::new(ReplicaConfig::new(2, 0), 7, t0).unwrap();
        r.set(t0, "*.var.machine.heuristic", Value::Floats(vec![1.5, 1.0]))
            .unwrap();
        r.set(t0, "*.var.machine.pass_to", Value::Int(3)).unwrap();
        // Not an LWM: the model must skip it, not fail.
        r.set(t0, "*.var.world.local", Value::Bytes(vec![0x33; 75]))
            .unwrap();
        r.post(t0, "*.talk.plan", Value::from("go")).unwrap();
        std::iter::from_fn(|| r.poll_transmit().map(|t| t.payload)).collect()
    }

    #[test]
    fn a_robot_s_claims_and_talk_show_in_the_state() {
        let mut m = Model::new(0, None, 254, 0, "test", Some(100)).unwrap();
        let from: SocketAddr = "127.0.0.1:2000".parse().unwrap();
        for f in frames_of_robot_2() {
            m.datagram(1_000_000, from, &f);
        }
        let s = m.state();
        assert_eq!(s["goer"], 2);
        let r = &s["robots"][0];
        assert_eq!(
            (r["id"].as_u64(), r["role"].as_str()),
            (Some(2), Some("active"))
        );
        assert_eq!(r["h"], 1.5);
        assert!(r["budget_used"].as_f64().unwrap() > 0.0);
        assert_eq!(s["talk"][0]["value"], "go");
        m.advance(2_000_000_000);
        assert_eq!(m.state()["robots"][0]["departed"], true);
        assert_eq!(m.state()["goer"], serde_json::Value::Null);
    }

    #[test]
    fn the_board_has_typed_values_and_ages_on_the_owners_clock() {
        // Robot 2 set its values 4 minutes before the monitor started listening: the
        // monitor hears them in a refresh frame and must show them 4 minutes old, not
        // as old as the monitor.
        let t0 = Instant::from_micros(0);
        let mut r = Replica::new(ReplicaConfig::new(2, 0), 7, t0).unwrap();
        r.set(t0, "*.var.machine.heuristic", Value::Floats(vec![1.5, 1.0]))
            .unwrap();
        r.set(t0, "*.var.machine.pass_to", Value::Int(3)).unwrap();
        while r.poll_transmit().is_some() {}
        let later = Instant::from_micros(240_000_000);
        let mut frames = Vec::new();
        while let Some(deadline) = r.poll_timeout() {
            if deadline > later {
                break;
            }
            r.handle_timeout(deadline);
            frames = std::iter::from_fn(|| r.poll_transmit().map(|t| t.payload)).collect();
        }
        assert!(!frames.is_empty(), "robot 2 refreshes its values");
        let mut m = Model::new(0, None, 254, 0, "test", None).unwrap();
        let from: SocketAddr = "127.0.0.1:2000".parse().unwrap();
        for f in &frames {
            m.datagram(1_000_000_000, from, f);
        }
        let s = m.state();
        let board = s["board"].as_array().expect("a board");
        let entry = |key: &str| {
            board
                .iter()
                .find(|b| b["key"] == key)
                .unwrap_or_else(|| panic!("{key} on the board: {board:?}"))
        };
        let h = entry("2.var.machine.heuristic");
        assert_eq!(h["value"], json!([1.5, 1.0]), "numbers as numbers");
        assert_eq!(h["owner"], json!(2));
        assert_eq!(entry("2.var.machine.pass_to")["value"], json!(3));
        let age_ms = h["age_ms"].as_f64().unwrap();
        assert!(
            age_ms > 200_000.0,
            "set 240 s before it was heard, shown {age_ms} ms old"
        );
    }

    #[test]
    fn garbage_and_flipped_frames_never_panic() {
        let mut m = Model::new(0, None, 254, 0, "test", None).unwrap();
        let from: SocketAddr = "127.0.0.1:2000".parse().unwrap();
        let frames = frames_of_robot_2();
        let mut x: u64 = 0x2545_f491_4f6c_dd1d;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            x
        };
        for i in 0..3000u64 {
            let mut f = frames[(i as usize) % frames.len()].clone();
            if i % 3 == 0 {
                f = (0..next() % 200).map(|_| next() as u8).collect();
            } else {
                for _ in 0..1 + next() % 4 {
                    let at = (next() as usize) % f.len().max(1);
                    if let Some(b) = f.get_mut(at) {
                        *b ^= next() as u8 | 1;
                    }
                }
            }
            m.datagram(i * 1_000_000, from, &f);
            if i % 100 == 0 {
                let _ = m.state().to_string();
            }
        }
    }
}
