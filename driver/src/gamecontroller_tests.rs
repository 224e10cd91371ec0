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
    /// The keys the listener reads (the team layer's and the program's), as entries.
    inputs: BTreeMap<&'static str, comms::Entry>,
}

impl GcBoard for Board {
    fn now(&self) -> comms::Instant {
        comms::Instant::from_micros(self.now_ms * 1000)
    }
    fn set(&mut self, key: &'static str, value: Value) {
        self.keys.insert(key, value);
    }
    fn get(&self, key: &str) -> Option<comms::Entry> {
        self.inputs.get(key).cloned()
    }
    fn set_external_budget(&mut self, game_remaining: Option<Duration>, cap: Option<ExternalCap>) {
        self.budget.push((game_remaining, cap));
    }
}

impl Board {
    /// `key` written now with `value` (as the team layer or the program would).
    fn write(&mut self, key: &'static str, value: Value) {
        let version = self.inputs.get(key).map_or(1, |e| e.version + 1);
        let stamp = self.now();
        self.inputs.insert(
            key,
            comms::Entry {
                value,
                owner: 3,
                version,
                incarnation: 1,
                stamp,
            },
        );
    }
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

#[test]
fn the_status_packets_ball_age_is_the_sightings_age_not_the_rewritten_entrys() {
    // Scenario: player 3 at (1, 0) hears a GC every 500 ms; the team layer rewrites
    // `local.var.team.ball` every 100 ms (as `driver/src/team.rs` does), first absent, then
    // from a single sighting at 1.0 s on, with its own `age_s` (9th float) growing. The
    // status packets (every 700 ms here) must say -1 before the sighting, then an age that grows
    // with the layer's `age_s` and is never below it: the entry's own age is always ~0.
    let (mut l, mut b) = (listener(), Board::default());
    b.write("local.var.robot.pose", Value::Floats(vec![1.0, 0.0, 0.0]));
    let mut sent: Vec<(u64, f64, f32)> = Vec::new();
    let mut packet = 0u8;
    let mut layer_age = None;
    for tick in 0..=80u64 {
        b.now_ms = tick * 100;
        if b.now_ms % 500 == 0 {
            packet = packet.wrapping_add(1);
            l.receive(&mut b, gc(), &playing(packet).encode());
        }
        if b.now_ms >= 1000 {
            let age_s = (b.now_ms - 1000) as f64 / 1000.0;
            layer_age = Some(age_s);
            b.write(
                "local.var.team.ball",
                Value::Floats(vec![2.0, 0.0, 0.0, 0.0, 0.1, 0.0, 0.1, 0.9, age_s]),
            );
        }
        if b.now_ms % 700 == 0 {
            let (now_ms, layer) = (b.now_ms, layer_age.unwrap_or(-1.0));
            l.status(&mut b, |bytes, _| {
                let m = gamecontroller::StatusMessage::decode(bytes).expect("an RGrt packet");
                sent.push((now_ms, layer, m.ball_age));
                Ok(bytes.len())
            });
        }
    }
    assert!(sent.len() >= 10, "status packets were sent: {sent:?}");
    let before: Vec<_> = sent.iter().filter(|(t, _, _)| *t < 1000).collect();
    assert!(
        !before.is_empty() && before.iter().all(|(_, _, age)| *age == -1.0),
        "no ball seen yet: ballAge -1 (RGrt's unknown): {sent:?}"
    );
    let after: Vec<_> = sent.iter().filter(|(t, _, _)| *t >= 1000).collect();
    for w in after.windows(2) {
        assert!(
            w[1].2 > w[0].2,
            "ballAge grows with the sighting's age between packets: {sent:?}"
        );
    }
    for (t, layer, age) in &after {
        assert!(
            f64::from(*age) >= layer - 1e-3,
            "at {t} ms ballAge {age} is below the layer's own age_s {layer}: {sent:?}"
        );
    }
    let (_, layer, age) = after.last().expect("packets after the sighting");
    assert!(
        f64::from(*age) >= *layer - 1e-3 && *layer > 6.0,
        "the last packet carries the sighting's age ({layer} s), not the entry's: {age}"
    );
}

#[test]
fn a_silent_gc_leaves_its_last_figure_in_force() {
    // Scenario: a GC says Playing with 16 messages left, then falls silent for 30 s (its
    // packets lost, the team's still reaching it and counted). The listener must not give
    // the budget back to the replica's own accounting: no `None` cap is fed, so the
    // replica keeps the last figure less the frames it and its teammates sent since.
    let (mut l, mut b) = (listener(), Board::default());
    let mut g = playing(1);
    g.team_mut(12).expect("our team").message_budget = 16;
    l.receive(&mut b, gc(), &g.encode());
    let fed = b.budget.clone();
    let (_, cap) = fed.last().copied().expect("the budget was fed");
    assert!(
        cap.is_some_and(|c| c.counted && c.team_left == 2 && c.margin == 14),
        "16 left less the margin of 14: {cap:?}"
    );
    for s in 1..=30 {
        b.now_ms = s * 1000;
        l.check(&mut b);
    }
    assert_eq!(
        b.budget, fed,
        "30 s of GC silence changed the budget's figures (a None cap unlocks the own \
         accounting from the daemon's start)"
    );
    // Heard again: its new figure is the authority.
    let mut g = playing(2);
    g.team_mut(12).expect("our team").message_budget = 15;
    b.now_ms += 500;
    l.receive(&mut b, gc(), &g.encode());
    let (_, cap) = b.budget.last().copied().expect("fed again");
    assert_eq!(cap.map(|c| c.team_left), Some(1), "the GC's new figure");
}
