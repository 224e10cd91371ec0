//! [`GcListener`] without sockets: datagrams in, the board's keys and the budget's figures
//! out. A bad or stale datagram is counted and leaves both exactly as they were.

use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::time::Duration;

use comms::{ExternalCap, Value};
use gamecontroller::{GameControlData, GcBudget, State};

use super::{GameControllerConfig, GcBoard, GcListener};

/// A blackboard of the listener's keys on a clock the test moves.
#[derive(Default)]
struct Board {
    now_ms: u64,
    keys: BTreeMap<&'static str, Value>,
    /// Every figure the listener fed the budget, in order.
    budget: Vec<(Option<Duration>, Option<ExternalCap>)>,
}

impl GcBoard for Board {
    fn now(&self) -> comms::Instant {
        comms::Instant::from_micros(self.now_ms * 1000)
    }
    fn set(&mut self, key: &'static str, value: Value) {
        self.keys.insert(key, value);
    }
    fn get(&self, _key: &str) -> Option<comms::Entry> {
        None
    }
    fn set_external_budget(&mut self, game_remaining: Option<Duration>, cap: Option<ExternalCap>) {
        self.budget.push((game_remaining, cap));
    }
}

impl Board {
    fn text(&self, key: &str) -> Option<&str> {
        match self.keys.get(key) {
            Some(Value::String(s)) => Some(s),
            _ => None,
        }
    }
    fn int(&self, key: &str) -> Option<i64> {
        match self.keys.get(key) {
            Some(Value::Int(n)) => Some(*n),
            _ => None,
        }
    }
    /// The game's keys (stats aside): what a bad or stale packet must not touch.
    fn game_keys(&self) -> Vec<(&'static str, Value)> {
        self.keys
            .iter()
            .filter(|(k, _)| !k.starts_with("local.var.huddle.stats"))
            .map(|(k, v)| (*k, v.clone()))
            .collect()
    }
}

fn gc() -> SocketAddr {
    "10.0.0.1:3838".parse().expect("an address")
}

/// Team 12, player 3, under the SPL budget for five robots; Playing, 900 messages left.
fn playing(number: u8) -> GameControlData {
    let mut g = GameControlData::new([12, 34]);
    g.packet_number = number;
    g.state = State::Playing;
    g.secs_remaining = 300;
    if let Some(t) = g.team_mut(12) {
        t.message_budget = 900;
    }
    g
}

fn listener() -> GcListener {
    let mut cfg = GameControllerConfig::new(12, 3);
    cfg.budget = Some(GcBudget::spl(5));
    GcListener::new(cfg)
}

#[test]
fn bad_datagrams_are_counted_by_kind_and_change_neither_the_keys_nor_the_budget() {
    // Scenario: a game in Playing is heard; then one datagram of each bad kind arrives,
    // each of which, misread, would say Finished with a full budget.
    let (mut l, mut b) = (listener(), Board::default());
    l.receive(&mut b, gc(), &playing(7).encode());
    assert_eq!(b.text("local.var.gc.state"), Some("playing"));
    let (keys, fed) = (b.game_keys(), b.budget.len());
    let mut lie = playing(8);
    lie.state = State::Finished;
    lie.team_mut(12).expect("our team").message_budget = 1200;
    let good = lie.encode();
    let mut header = good;
    header[..4].copy_from_slice(b"RGmX");
    let mut version = good;
    version[4] = 17;
    let mut field = good;
    field[10] = 99; // `state`: no such state
    let mut other = lie;
    other.teams[0].team_number = 5;
    let bad: [(&str, Vec<u8>); 7] = [
        ("empty", Vec::new()),
        ("truncated", good[..117].to_vec()),
        ("oversized", [&good[..], &[0u8]].concat()),
        ("header", header.to_vec()),
        ("version", version.to_vec()),
        ("field", field.to_vec()),
        ("team", other.encode().to_vec()),
    ];
    for (what, bytes) in &bad {
        b.now_ms += 100;
        l.receive(&mut b, gc(), bytes);
        assert_eq!(
            b.game_keys(),
            keys,
            "a {what} datagram changed the game's keys"
        );
        assert_eq!(b.budget.len(), fed, "a {what} datagram fed the budget");
    }
    let stat = |k: &str| b.int(&format!("local.var.huddle.stats.gc.{k}"));
    assert_eq!(
        [
            stat("bad_length"),
            stat("bad_header"),
            stat("wrong_version"),
            stat("bad_field"),
            stat("wrong_team"),
            stat("accepted"),
        ],
        [Some(3), Some(1), Some(1), Some(1), Some(1), Some(1)],
        "each counted under its kind, none accepted"
    );
}

#[test]
fn a_stale_packet_number_never_moves_the_game_or_the_budget_back_across_the_wrap() {
    // Scenario: packets 254, 255, 0, 1 arrive (the u8 wraps); then 255 again, late, with
    // an older game (Set, 950 left). It is stale: the state stays Playing and the budget
    // is not fed the older, larger figure.
    let (mut l, mut b) = (listener(), Board::default());
    for (k, n) in [254u8, 255, 0, 1].into_iter().enumerate() {
        let mut g = playing(n);
        g.team_mut(12).expect("our team").message_budget = 900 - k as u16;
        b.now_ms += 500;
        l.receive(&mut b, gc(), &g.encode());
    }
    assert_eq!(
        b.int("local.var.gc.budget"),
        Some(897),
        "1 follows 0 follows 255"
    );
    let (keys, fed) = (b.game_keys(), b.budget.len());
    let mut late = playing(255);
    late.state = State::Set;
    late.team_mut(12).expect("our team").message_budget = 950;
    b.now_ms += 100;
    l.receive(&mut b, gc(), &late.encode());
    assert_eq!(
        b.game_keys(),
        keys,
        "a stale packet changed the game's keys"
    );
    assert_eq!(b.budget.len(), fed, "a stale packet fed the budget");
    assert_eq!(b.int("local.var.huddle.stats.gc.stale"), Some(1));
    let (_, cap) = b.budget.last().copied().expect("the budget was fed");
    assert!(
        cap.is_some_and(|c| c.team_left < 897),
        "the cap is the newest figure less the margin: {cap:?}"
    );
    // The next packet in order is taken.
    b.now_ms += 400;
    l.receive(&mut b, gc(), &playing(2).encode());
    assert_eq!(b.int("local.var.huddle.stats.gc.accepted"), Some(5));
}
