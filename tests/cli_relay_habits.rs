//! The command line as a ROS 2 or mosquitto user reaches for it (issue 31): bare words
//! as strings, the daemon's counters out of `keys` unless asked, a hint when a pattern
//! matches nothing, `owner` an integer in JSON, `set --every`, `huddle hz`, one man page
//! per subcommand. Daemons on loopback only.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::process::{Command, Output};
use std::time::{Duration, Instant};

use daemon_support::Daemon;

fn huddle(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_huddle"));
    c.args(args)
        .env_remove("HUDDLE_RELAY")
        .env_remove("RUST_LOG");
    c
}

fn run(args: &[&str]) -> Output {
    huddle(args).output().expect("run huddle")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn one_daemon(id: u8) -> (Daemon, tempfile::TempDir) {
    let dir = tempfile::tempdir().unwrap();
    let group = daemon_support::scratch_group().to_string();
    let port = daemon_support::free_tcp_port();
    let d = Daemon::start(id, &group, port, &["--refresh", "50ms"], dir.path());
    (d, dir)
}

#[test]
fn bare_words_are_strings_and_keys_shows_the_teams_keys_first() {
    let (d, _dir) = one_daemon(4);
    let relay = d.relay.to_string();
    // mosquitto_pub -m attack: a bare word is a string.
    let out = run(&["set", "*.var.mode", "attack", "--relay", &relay]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = run(&["get", "*.var.mode", "--json", "--relay", &relay]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (v["type"].as_str(), v["value"].as_str(), v["owner"].as_u64()),
        (Some("string"), Some("attack"), Some(4)),
        "{v}"
    );
    // A number stays a number; a malformed literal is an error, not a string.
    run(&["set", "local.var.n", "42", "--relay", &relay]);
    let out = run(&["get", "local.var.n", "--json", "--relay", &relay]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (v["value"].as_i64(), v["owner"].as_u64()),
        (Some(42), Some(4))
    );
    let out = run(&["set", "local.var.n", "[1,", "2", "--relay", &relay]);
    assert_eq!(out.status.code(), Some(1), "a broken list is refused");
    assert!(
        text(&out.stderr).contains("not a value"),
        "{}",
        text(&out.stderr)
    );

    // keys: the team's keys, not 40 counters; --all shows them.
    let out = run(&["keys", "--relay", &relay]);
    let listed = text(&out.stdout);
    assert!(listed.contains("4.var.mode\n"), "{listed}");
    assert!(!listed.contains("local.var.huddle."), "{listed}");
    let out = run(&["keys", "--all", "--relay", &relay]);
    assert!(text(&out.stdout).contains("local.var.huddle.stats.frames_out\n"));
    let out = run(&[
        "keys",
        "local.var.huddle.stats.frames_out",
        "--relay",
        &relay,
    ]);
    assert_eq!(
        text(&out.stdout),
        "local.var.huddle.stats.frames_out\n",
        "asked by name"
    );

    // A key given as a pattern matches nothing: say so, and suggest `.#`.
    run(&["set", "*.var.ball.x", "1.5", "--relay", &relay]);
    let out = run(&["keys", "4.var.ball", "--relay", &relay]);
    assert!(out.status.success());
    assert_eq!(text(&out.stdout), "");
    assert!(
        text(&out.stderr).contains("4.var.ball.#"),
        "{}",
        text(&out.stderr)
    );
}

#[test]
fn set_every_repeats_and_hz_measures_the_rate_of_changes() {
    let (d, _dir) = one_daemon(5);
    let relay = d.relay.to_string();
    // A changing value 25 times a second (each a change, as hz counts changes).
    let mut c = d.client();
    let writer = std::thread::spawn(move || {
        let start = Instant::now();
        for i in 0..75u32 {
            let due = start + Duration::from_millis(40) * i;
            std::thread::sleep(due.saturating_duration_since(Instant::now()));
            assert_eq!(c.ask(&format!("SETV *.var.tick {i}")), "OK");
        }
    });
    let out = run(&[
        "hz", "5.var.#", "--every", "2500ms", "--window", "2s", "-n", "1", "--json", "--relay",
        &relay,
    ]);
    writer.join().unwrap();
    assert!(out.status.success(), "{}", text(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let tick = v["keys"]
        .as_array()
        .unwrap()
        .iter()
        .find(|k| k["key"] == "5.var.tick")
        .unwrap_or_else(|| panic!("5.var.tick in {v}"))
        .clone();
    let hz = tick["rate_hz"].as_f64().expect("a rate");
    assert!((20.0..30.0).contains(&hz), "about 25 Hz: {tick}");
    assert!(tick["jitter_ms"].as_f64().unwrap() < 20.0, "{tick}");
    assert!(tick["age_ms"].as_u64().unwrap() < 1000, "{tick}");

    // set --every: sends again on a schedule, -n of them.
    let started = Instant::now();
    let out = run(&[
        "set",
        "local.var.beat",
        "1",
        "--every",
        "50ms",
        "-n",
        "5",
        "--relay",
        &relay,
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let took = started.elapsed();
    assert!(
        took >= Duration::from_millis(200),
        "5 sends 50 ms apart take 200 ms: {took:?}"
    );
    let got = run(&["get", "local.var.beat", "--json", "--relay", &relay]);
    let v: serde_json::Value = serde_json::from_slice(&got.stdout).unwrap();
    assert_eq!(v["value"], 1);
    let out = run(&["set", "local.var.beat", "1", "-n", "5", "--relay", &relay]);
    assert!(!out.status.success(), "-n needs --every");
}

#[test]
fn man_writes_one_page_per_subcommand() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(&["man", "--dir", dir.path().to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    for page in [
        "huddle.1",
        "huddle-set.1",
        "huddle-hz.1",
        "huddle-daemon.1",
        "huddle-keys.1",
    ] {
        let path = dir.path().join(page);
        let roff = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{page}: {e}"));
        assert!(roff.contains(".TH"), "{page} is a man page");
    }
    let set = std::fs::read_to_string(dir.path().join("huddle-set.1")).unwrap();
    assert!(set.contains("every"), "the page documents set's flags");
}

#[test]
fn watch_on_a_terminal_redraws_in_place_shows_six_digits_and_q_quits() {
    if Command::new("script").arg("--version").output().is_err() {
        eprintln!("SKIPPED: no `script` (util-linux) to give watch a terminal");
        return;
    }
    let (d, dir) = one_daemon(3);
    let relay = d.relay.to_string();
    run(&["set", "*.var.pi", "3.141592653589793", "--relay", &relay]);
    let typescript = dir.path().join("watch.typescript");
    let inner = format!(
        "COLUMNS=100 LINES=20 {} watch '3.var.#' --relay {relay}",
        env!("CARGO_BIN_EXE_huddle")
    );
    let mut child = Command::new("script")
        .args(["-qfec", &inner])
        .arg(&typescript)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .expect("spawn script");
    std::thread::sleep(Duration::from_millis(1500));
    let mut keys = child.stdin.take().unwrap();
    std::io::Write::write_all(&mut keys, b"q").unwrap();
    let deadline = Instant::now() + Duration::from_secs(8);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("q did not end huddle watch");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    drop(keys);
    assert!(status.success(), "{status}");
    let screen = std::fs::read(&typescript).unwrap();
    let has = |needle: &[u8]| screen.windows(needle.len()).any(|w| w == needle);
    assert!(!has(b"\x1b[2J"), "no whole-screen clear: it flickers");
    assert!(has(b"\x1b[H"), "redrawn from the top, in place");
    assert!(has(b"3.14159\x1b[K"), "6 significant digits");
    assert!(!has(b"3.141592653589793"), "not 17");
    assert!(has(b"\x1b[?1049l"), "the terminal is given back");
}
