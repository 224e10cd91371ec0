//! `huddle sim --seed 1 --duration 60s --json`, the README's main job cut to one minute,
//! must print the figures pinned in `tests/data/sim_seed1_60s.json`: every key but the
//! wall-clock speed. The simulation is deterministic for a seed, so any difference is a
//! change of behaviour somewhere in the protocol, the filters, the network model or the
//! field. When a change is meant to move the figures, regenerate the file and say why
//! in the commit:
//!
//! ```sh
//! cargo run --release -- sim --seed 1 --duration 60s --json \
//!   | python3 -c 'import json,sys; d=json.load(sys.stdin); d.pop("sim_speed_x"); json.dump(d, open("tests/data/sim_seed1_60s.json","w"), indent=1, sort_keys=True)'
//! ```

use std::process::Command;

use serde_json::{Map, Value};

/// Keys that measure the machine, not the simulation.
const WALL_CLOCK_KEYS: [&str; 1] = ["sim_speed_x"];

fn figures(json: &str) -> Map<String, Value> {
    let Value::Object(mut map) = serde_json::from_str(json).expect("the report is JSON") else {
        panic!("the report is a JSON object: {json}");
    };
    for key in WALL_CLOCK_KEYS {
        map.remove(key);
    }
    map
}

#[test]
fn one_minute_of_the_default_match_gives_the_pinned_figures() {
    let out = Command::new(env!("CARGO_BIN_EXE_huddle"))
        .args(["sim", "--seed", "1", "--duration", "60s", "--json"])
        .output()
        .expect("huddle runs");
    assert!(
        out.status.success(),
        "huddle sim failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got = figures(&String::from_utf8_lossy(&out.stdout));
    let want = figures(include_str!("data/sim_seed1_60s.json"));

    let mut differences = Vec::new();
    for (key, expected) in &want {
        match got.get(key) {
            Some(value) if value == expected => {}
            Some(value) => differences.push(format!("{key}: pinned {expected}, now {value}")),
            None => differences.push(format!("{key}: pinned {expected}, now missing")),
        }
    }
    for key in got.keys().filter(|k| !want.contains_key(*k)) {
        differences.push(format!("{key}: new, not pinned"));
    }
    assert!(
        differences.is_empty(),
        "seed 1, 60 s: the figures moved (regenerate tests/data/sim_seed1_60s.json only if \
         that was meant):\n  {}",
        differences.join("\n  ")
    );
}
