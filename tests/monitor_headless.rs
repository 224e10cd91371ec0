//! The team monitor's page as a robotics person meets it (issue 31): opened by headless
//! Chromium without any query, `--dump-dom` finishes (the page ends its live stream by
//! itself when headless); at 1280×720 the field, legend and robot table fit without
//! scrolling; world models show decoded, not as hex; robot numbers are readable on their
//! colours; a monitor that does not answer is shown as disconnected. Screenshots are
//! kept (`target/tmp/monitor-1280x720.png`, `monitor-disconnected.png`). Skipped, with a
//! message, where Chromium is absent (`scripts/install-chromium.sh` installs it).

#![allow(clippy::disallowed_methods)] // a real browser and server, real time

mod daemon_support;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

fn chromium() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    ["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .flat_map(|name| std::env::split_paths(&path).map(move |dir| dir.join(name)))
        .find(|p| p.is_file())
}

struct Killed(Child);
impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Runs headless Chromium on `url`; fails the test if it does not finish within 90 s
/// (the bug: an endless event stream kept `--dump-dom` waiting forever).
fn browser(chromium: &Path, extra: &[&str], url: &str) -> (bool, String, String) {
    let profile = tempfile::tempdir().unwrap();
    let mut child = Command::new(chromium)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--hide-scrollbars",
            "--virtual-time-budget=10000",
        ])
        .arg(format!("--user-data-dir={}", profile.path().display()))
        .args(extra)
        .arg(url)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run chromium");
    let mut stdout = child.stdout.take().unwrap();
    let mut stderr = child.stderr.take().unwrap();
    let out = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stdout.read_to_string(&mut s);
        s
    });
    let err = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let deadline = Instant::now() + Duration::from_secs(90);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("headless chromium never finished loading {url}");
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    (status.success(), out.join().unwrap(), err.join().unwrap())
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

fn shot_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(name)
}

#[test]
fn headless_the_page_finishes_fits_1280x720_and_decodes_world_models() {
    let Some(chromium) = chromium() else {
        eprintln!("SKIPPED: no chromium on PATH; scripts/install-chromium.sh installs it");
        return;
    };
    let addr: SocketAddr = format!("127.0.0.1:{}", daemon_support::free_tcp_port())
        .parse()
        .unwrap();
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
            .args(["--speed", "20", "--monitor", &addr.to_string()])
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
    // /state: one JSON type per field, numbers as numbers, world models decoded.
    let board = state["board"].as_array().unwrap();
    let world = board
        .iter()
        .find(|b| {
            b["key"]
                .as_str()
                .is_some_and(|k| k.ends_with(".var.world.local"))
        })
        .unwrap_or_else(|| panic!("a world model on the board: {board:?}"));
    assert!(world["decoded"]["pose"]["x"].is_f64(), "{world}");
    assert!(
        board.iter().all(|b| b["owner"].is_u64()),
        "owners are integers"
    );
    let heuristic = board
        .iter()
        .find(|b| {
            b["key"]
                .as_str()
                .is_some_and(|k| k.ends_with(".var.machine.heuristic"))
        })
        .expect("a claim on the board");
    assert!(
        heuristic["value"].is_array(),
        "floats as a JSON array: {heuristic}"
    );

    // No query: the headless page ends its stream by itself and --dump-dom finishes.
    let url = format!("http://{addr}/");
    let (ok, dom, err) = browser(&chromium, &["--window-size=1280,720", "--dump-dom"], &url);
    assert!(
        ok && dom.contains("data-robot="),
        "chromium drew nothing: {err}\n{dom}"
    );
    assert_eq!(
        attr(&dom, "<body", "data-connection").as_deref(),
        Some("ended"),
        "the headless page stopped its live updates"
    );
    assert_eq!(
        attr(&dom, "<body", "data-fits").as_deref(),
        Some("true"),
        "field, legend and robot table fit 1280×720 without scrolling"
    );
    assert!(dom.contains("pose ("), "world models decoded on the board");
    assert!(
        !dom.contains(">0x"),
        "no hex on the board for a world model"
    );
    assert!(dom.contains("opponent"), "opponents in the legend");
    assert!(
        !dom.contains("<th>h</th>") && !dom.contains("GBC"),
        "no unexplained jargon"
    );
    // Robot 5 is yellow: its number is black, with a white outline.
    let ink = dom.find("data-robot=\"5\"").and_then(|at| {
        let from = at + dom[at..].find("<text fill=\"")? + "<text fill=\"".len();
        Some(dom[from..from + dom[from..].find('"')?].to_owned())
    });
    assert_eq!(
        ink.as_deref(),
        Some("#000"),
        "a dark number on the yellow robot"
    );

    let shot = shot_path("monitor-1280x720.png");
    let _ = std::fs::remove_file(&shot);
    let (ok, _, err) = browser(
        &chromium,
        &[
            "--window-size=1280,720",
            &format!("--screenshot={}", shot.display()),
        ],
        &format!("http://{addr}/?updates=5"),
    );
    assert!(ok, "{err}");
    let png = std::fs::read(&shot).expect("a screenshot");
    assert!(png.starts_with(b"\x89PNG") && png.len() > 10_000);
    eprintln!("screenshot: {}", shot.display());
}

/// Serves the page, and nothing else (`/state` and `/events` answer 503): a monitor
/// that went away after the page loaded.
fn page_only_server() -> SocketAddr {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    std::thread::spawn(move || {
        for stream in listener.incoming() {
            let Ok(mut s) = stream else { continue };
            let mut buf = [0u8; 4096];
            let n = s.read(&mut buf).unwrap_or(0);
            let request = String::from_utf8_lossy(&buf[..n]).into_owned();
            let path = request.split_whitespace().nth(1).unwrap_or("/").to_owned();
            let page = include_str!("../monitor/src/web/index.html");
            let reply = if path == "/" || path.starts_with("/?") {
                format!(
                    "HTTP/1.1 200 OK\r\nContent-Type: text/html; charset=utf-8\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{page}",
                    page.len()
                )
            } else {
                "HTTP/1.1 503 Service Unavailable\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
                    .to_owned()
            };
            let _ = s.write_all(reply.as_bytes());
        }
    });
    addr
}

#[test]
fn a_monitor_that_does_not_answer_is_shown_as_disconnected() {
    let Some(chromium) = chromium() else {
        eprintln!("SKIPPED: no chromium on PATH; scripts/install-chromium.sh installs it");
        return;
    };
    let addr = page_only_server();
    let (ok, dom, err) = browser(&chromium, &["--dump-dom"], &format!("http://{addr}/"));
    assert!(ok, "{err}");
    assert_eq!(
        attr(&dom, "<body", "data-connection").as_deref(),
        Some("disconnected"),
        "{dom}"
    );
    assert!(dom.contains("disconnected: "), "said in words too");
    let shot = shot_path("monitor-disconnected.png");
    let (ok, _, err) = browser(
        &chromium,
        &[
            "--window-size=1280,720",
            &format!("--screenshot={}", shot.display()),
        ],
        &format!("http://{addr}/"),
    );
    assert!(ok, "{err}");
}
