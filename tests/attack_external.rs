//! The independent attack suite (`scripts/attack/`, Python, standard library only) against
//! this build's `huddle daemon`s on loopback: crafted, mutated and keyed wire frames, the
//! GameController listener's packets, relay lines and connections, config files, and a
//! newer build's frames. Each attack checks afterwards that the daemon lives, answers a
//! fresh client, kept what it stored, counted what it dropped, and never moved the game
//! backwards. `docs/attack-suite.md` says what each one does.
//!
//! Short by default (well under a minute). For a manual run, `HUDDLE_ATTACK_LONG=1` runs
//! the `--long` mode, `HUDDLE_ATTACK_SEED=N` repeats a seed (otherwise the suite takes one
//! from the clock and prints it), and `HUDDLE_ATTACK_OLD=/a/huddle:/b/huddle` adds a
//! mixed team with each older binary:
//! `HUDDLE_ATTACK_LONG=1 cargo test --test attack_external -- --nocapture`.
//! Skipped, with a message saying so, where python3 is absent.

use std::path::Path;
use std::process::Command;

#[test]
fn the_independent_attack_suite_finds_nothing_against_this_build() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = std::env::var("PYTHON").unwrap_or_else(|_| "python3".into());
    let has_python = Command::new(&python)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_python {
        println!("SKIPPED: the attack suite needs {python} (not found)");
        eprintln!("SKIPPED: the attack suite needs {python} (not found)");
        return;
    }
    let mut cmd = Command::new(&python);
    cmd.arg(root.join("scripts/attack/run.py"))
        .args(["--huddle", env!("CARGO_BIN_EXE_huddle")])
        .env("PYTHONDONTWRITEBYTECODE", "1");
    if std::env::var_os("HUDDLE_ATTACK_LONG").is_some() {
        cmd.arg("--long");
    }
    if let Ok(seed) = std::env::var("HUDDLE_ATTACK_SEED") {
        cmd.args(["--seed", &seed]);
    }
    if let Some(old) = std::env::var_os("HUDDLE_ATTACK_OLD") {
        for path in std::env::split_paths(&old) {
            cmd.arg("--old").arg(path);
        }
    }
    let out = cmd.output().expect("run scripts/attack/run.py");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{stdout}");
    eprintln!("{stderr}");
    let summary = stdout
        .lines()
        .rev()
        .find(|l| l.starts_with("attack suite:"))
        .unwrap_or("no summary line");
    assert!(
        out.status.success(),
        "the attack suite failed ({}): {summary}\n{stdout}\n{stderr}",
        out.status
    );
    assert!(
        summary.contains(", 0 failed,"),
        "the suite ran no attack: {summary}"
    );
}
