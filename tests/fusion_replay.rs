//! `huddle fusion replay` against a stored golden output, and its handling of bad input.

use std::io::Write;
use std::process::{Command, Stdio};

const ARGS: [&str; 10] = [
    "--x0",
    "0.5,-0.3,0.1",
    "--p0",
    "0.25,0.25,0.1",
    "--q",
    "0.0001,0.0001,0.0002",
    "--r",
    "0.0025,0.0025",
    "--gate",
    "13.8",
];

fn data(name: &str) -> String {
    format!("{}/tests/data/fusion/{name}", env!("CARGO_MANIFEST_DIR"))
}

fn replay(args: &[&str], stdin: Option<&str>) -> std::process::Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_huddle"))
        .args(["fusion", "replay"])
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("huddle runs");
    let mut pipe = child.stdin.take().unwrap();
    pipe.write_all(stdin.unwrap_or("").as_bytes()).unwrap();
    drop(pipe);
    child.wait_with_output().unwrap()
}

fn numbers(line: &serde_json::Value) -> Vec<f64> {
    let mut v = vec![
        line["t"].as_f64().unwrap(),
        line["x"].as_f64().unwrap(),
        line["y"].as_f64().unwrap(),
    ];
    v.push(line["theta"].as_f64().unwrap());
    v.extend(
        line["P"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| p.as_f64().unwrap()),
    );
    v
}

#[test]
fn a_walk_with_a_misidentified_landmark_replays_to_the_stored_output() {
    // 60 odometry events and 20 landmark sightings (one of them 3 m wrong, gated out),
    // plus "ball" lines and a blank line that replay must skip.
    let mut args = ARGS.to_vec();
    let input = data("walk.jsonl");
    args.push(&input);
    let out = replay(&args, None);
    assert!(
        out.status.success(),
        "replay failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got: Vec<serde_json::Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).expect("output is JSON lines"))
        .collect();
    let expected: Vec<serde_json::Value> = std::fs::read_to_string(data("walk.expected.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(
        got.len(),
        80,
        "one output per odometry or landmark event, none for other types"
    );
    assert_eq!(got.len(), expected.len());
    for (k, (g, e)) in got.iter().zip(&expected).enumerate() {
        let (g, e) = (numbers(g), numbers(e));
        assert_eq!(g.len(), 13, "t, x, y, theta and 9 covariance entries");
        for (a, b) in g.iter().zip(&e) {
            assert!(
                (a - b).abs() <= 1e-9,
                "output line {} drifted: {a} vs stored {b}",
                k + 1
            );
        }
    }
    // The robot really walked to about (−2.97, −0.85) facing −π: the replay agrees.
    let last = numbers(got.last().unwrap());
    assert!(
        (last[1] + 2.969).abs() < 0.1 && (last[2] + 0.852).abs() < 0.1,
        "final pose {last:?}"
    );
}

#[test]
fn stdin_works_and_a_malformed_line_is_an_error_naming_its_number() {
    let input = concat!(
        "{\"t\":0.1,\"type\":\"odometry\",\"forward\":0.1,\"left\":0,\"turn\":0}\n",
        "{\"t\":0.2,\"type\":\"whistle\"}\n",
        "{\"t\":0.3,\"type\":\"landmark\",\"id\":3,\"field_x\":1.0,\"field_y\":2.0,\"local_x\":0.5}\n",
    );
    let out = replay(&["-"], Some(input));
    assert!(
        !out.status.success(),
        "a landmark without local_y must fail"
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("line 3"),
        "error should name line 3: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "no panic: {stderr}");
    // The line before the bad one was still processed and printed.
    assert_eq!(String::from_utf8_lossy(&out.stdout).lines().count(), 1);

    let out = replay(&["-"], Some("{\"t\":0.1,\"type\":\"odometry\"\n"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && stderr.contains("line 1"),
        "truncated JSON: {stderr}"
    );
}

#[test]
fn bad_options_are_refused() {
    let out = replay(&["--gate", "maybe", "-"], Some(""));
    assert!(!out.status.success());
    let out = replay(&["--r", "0.1", "-"], Some(""));
    assert!(!out.status.success(), "--r needs two variances");
}
