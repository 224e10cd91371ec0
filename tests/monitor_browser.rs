//! The team monitor as a person sees it: `huddle sim --monitor` on loopback, the page
//! opened in a real headless Chromium, and every robot and the team ball checked to be
//! drawn where `GET /state` says they are, through the page's field-to-screen transform;
//! a robot switched off is drawn as departed; a screenshot is kept as an artifact
//! (`target/tmp/monitor-sim.png`). Skipped, with a message, where Chromium is absent
//! (`scripts/install-chromium.sh` installs it).

#![allow(clippy::disallowed_methods)] // a real browser and server, real time

mod daemon_support;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn chromium() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    [
        "chromium",
        "chromium-browser",
        "google-chrome",
        "google-chrome-stable",
    ]
    .iter()
    .flat_map(|name| std::env::split_paths(&path).map(move |dir| dir.join(name)))
    .find(|p| p.is_file())
}

/// A plain HTTP/1.1 GET; the body.
fn get(addr: SocketAddr, path: &str) -> std::io::Result<String> {
    let mut s = TcpStream::connect(addr)?;
    s.set_read_timeout(Some(Duration::from_secs(5)))?;
    write!(
        s,
        "GET {path} HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\n\r\n"
    )?;
    let mut text = String::new();
    s.read_to_string(&mut text)?;
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    if !head.starts_with("HTTP/1.1 200") {
        return Err(std::io::Error::other(format!("{path}: {head}")));
    }
    Ok(body.to_owned())
}

struct Killed(Child);
impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn browser(chromium: &Path, profile: &Path, extra: &[&str], url: &str) -> std::process::Output {
    Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--virtual-time-budget=10000",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .args(extra)
        .arg(url)
        .stdin(Stdio::null())
        .output()
        .expect("run chromium")
}

/// `name="value"` of the first tag in `dom` that contains `marker`.
fn attr(dom: &str, marker: &str, name: &str) -> Option<String> {
    let at = dom.find(marker)?;
    let start = dom[..at].rfind('<')?;
    let end = at + dom[at..].find('>')?;
    let tag = &dom[start..end];
    let key = format!(" {name}=\"");
    let from = tag.find(&key)? + key.len();
    Some(tag[from..from + tag[from..].find('"')?].to_owned())
}

fn translate(t: &str) -> (f64, f64) {
    let inner = t.trim_start_matches("translate(").trim_end_matches(')');
    let (x, y) = inner.split_once(',').expect("translate(x,y)");
    (x.trim().parse().unwrap(), y.trim().parse().unwrap())
}

#[test]
fn the_monitor_page_draws_every_robot_and_the_team_ball_where_state_says() {
    let Some(chromium) = chromium() else {
        eprintln!(
            "SKIPPED: no chromium on PATH; scripts/install-chromium.sh installs it \
             (apt-get install -y chromium)"
        );
        return;
    };
    let addr: SocketAddr = format!("127.0.0.1:{}", daemon_support::free_tcp_port())
        .parse()
        .unwrap();
    // A short match, fast, robot 3 switched off at 1 s; the monitor keeps serving the
    // final picture after the match, so the page and /state can be compared exactly.
    let _sim = Killed(
        Command::new(env!("CARGO_BIN_EXE_huddle"))
            .args([
                "sim",
                "--robots",
                "5",
                "--duration",
                "3s",
                "--preset",
                "lan",
            ])
            .args([
                "--speed",
                "20",
                "--kill",
                "3@1s",
                "--monitor",
                &addr.to_string(),
            ])
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .spawn()
            .expect("spawn huddle sim --monitor"),
    );
    let deadline = Instant::now() + Duration::from_secs(60);
    let state: serde_json::Value = loop {
        if let Ok(body) = get(addr, "/state") {
            let state: serde_json::Value = serde_json::from_str(&body).expect("/state is JSON");
            if state["finished"] == true {
                break state;
            }
        }
        assert!(Instant::now() < deadline, "the simulated match never ended");
        std::thread::sleep(Duration::from_millis(50));
    };
    let robots = state["robots"].as_array().unwrap();
    assert_eq!(robots.len(), 5, "{state}");

    let profile = tempfile::tempdir().unwrap();
    let url = format!("http://{addr}/?updates=5");
    let out = browser(&chromium, profile.path(), &["--dump-dom"], &url);
    let dom = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && dom.contains("data-robot="),
        "chromium drew nothing: {}\n{dom}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Live updates arrived (server-sent events), not just the first fetch.
    let live: u32 = attr(&dom, "<body", "data-live").unwrap().parse().unwrap();
    assert!(live >= 5, "only {live} live updates");

    let num = |name| -> f64 { attr(&dom, "id=\"field\"", name).unwrap().parse().unwrap() };
    let (scale, ox, oy) = (num("data-scale"), num("data-ox"), num("data-oy"));
    let field = &state["field"];
    let border = field["border_m"].as_f64().unwrap();
    assert!((ox - (field["length_m"].as_f64().unwrap() / 2.0 + border) * scale).abs() < 1.0);
    assert!((oy - (field["width_m"].as_f64().unwrap() / 2.0 + border) * scale).abs() < 1.0);
    let screen = |p: &serde_json::Value| {
        (
            ox + p["x"].as_f64().unwrap() * scale,
            oy - p["y"].as_f64().unwrap() * scale,
        )
    };
    let close = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).hypot(a.1 - b.1) <= 2.0;

    for r in robots {
        let id = r["id"].as_u64().unwrap();
        let marker = format!("data-robot=\"{id}\"");
        let drawn = translate(&attr(&dom, &marker, "transform").expect("robot drawn"));
        let expected = screen(&r["pose"]);
        assert!(
            close(drawn, expected),
            "robot {id} drawn at {drawn:?}, state says {expected:?}"
        );
        let departed = attr(&dom, &marker, "data-departed").unwrap();
        let class = attr(&dom, &marker, "class").unwrap();
        assert_eq!(departed, r["departed"].to_string(), "robot {id}");
        assert_eq!(
            class.contains("departed"),
            r["departed"] == true,
            "robot {id}"
        );
        if !r["ball"].is_null() {
            let m = format!("data-robot-ball=\"{id}\"");
            let cx: f64 = attr(&dom, &m, "cx").unwrap().parse().unwrap();
            let cy: f64 = attr(&dom, &m, "cy").unwrap().parse().unwrap();
            assert!(close((cx, cy), screen(&r["ball"])), "robot {id}'s ball");
        }
    }
    let r3 = robots.iter().find(|r| r["id"] == 3).unwrap();
    assert_eq!(r3["departed"], true, "robot 3 was switched off: {r3}");
    let goers = robots.iter().filter(|r| r["goer"] == true).count();
    assert!(goers <= 1, "at most one goer ringed");

    let team = &state["team_ball"];
    assert!(!team.is_null(), "a team ball after 3 s of play");
    let cx: f64 = attr(&dom, "data-ball=\"team\"", "cx")
        .unwrap()
        .parse()
        .unwrap();
    let cy: f64 = attr(&dom, "data-ball=\"team\"", "cy")
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        close((cx, cy), screen(team)),
        "team ball drawn at ({cx}, {cy})"
    );

    // The screenshot, kept as an artifact.
    let shot = Path::new(env!("CARGO_TARGET_TMPDIR")).join("monitor-sim.png");
    let _ = std::fs::remove_file(&shot);
    let profile = tempfile::tempdir().unwrap();
    let out = browser(
        &chromium,
        profile.path(),
        &[
            "--window-size=1400,900",
            &format!("--screenshot={}", shot.display()),
        ],
        &url,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let png = std::fs::read(&shot).expect("a screenshot");
    assert!(png.starts_with(b"\x89PNG") && png.len() > 10_000);
    eprintln!("screenshot: {}", shot.display());
}
