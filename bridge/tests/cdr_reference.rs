//! The `--ros2` CDR bytes against pycdr2, a reference CDR encoder from PyPI
//! (`scripts/install-zenoh-python.sh` installs it; skipped with a message without it).

use std::io::Write;
use std::process::{Command, Stdio};

use comms::Value;
use huddle_bridge::cdr;

fn python_with(module: &str) -> bool {
    Command::new("python3")
        .args(["-c", &format!("import {module}")])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn json(value: &Value) -> String {
    let (kind, v) = match value {
        Value::Int(i) => ("int", serde_json::json!(i.to_string())),
        Value::Float(f) => ("float", serde_json::json!(format!("{f:?}"))),
        Value::Bool(b) => ("bool", serde_json::json!(b)),
        Value::String(s) => ("string", serde_json::json!(s)),
        Value::Floats(v) => (
            "floats",
            serde_json::json!(v.iter().map(|f| format!("{f:?}")).collect::<Vec<_>>()),
        ),
        Value::Bytes(b) => ("bytes", serde_json::json!(b)),
    };
    serde_json::json!({"type": kind, "value": v}).to_string()
}

#[test]
fn every_type_encodes_as_pycdr2_does() {
    if !python_with("pycdr2") {
        eprintln!(
            "SKIPPED: python3 with pycdr2 is not available (pip install pycdr2; \
             scripts/install-zenoh-python.sh does it in CI)"
        );
        return;
    }
    let values = vec![
        Value::Int(0),
        Value::Int(-1),
        Value::Int(i64::MIN),
        Value::Int(i64::MAX),
        Value::Float(2.5),
        Value::Float(-0.0),
        Value::Float(1e-300),
        Value::Float(f64::INFINITY),
        Value::Bool(true),
        Value::Bool(false),
        Value::from(""),
        Value::from("x"),
        Value::from("héllo \"team\""),
        Value::from("abcd"),
        Value::Floats(vec![]),
        Value::Floats(vec![1.5]),
        Value::Floats(vec![1.0, -2.0, 3e10]),
        Value::Bytes(vec![]),
        Value::Bytes(vec![0]),
        Value::Bytes(vec![1, 2, 3, 255, 7]),
    ];
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/py/cdr_reference.py");
    let mut child = Command::new("python3")
        .arg(script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .expect("python3 runs");
    {
        let mut stdin = child.stdin.take().unwrap();
        for v in &values {
            writeln!(stdin, "{}", json(v)).unwrap();
        }
    }
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "the reference encoder failed");
    let lines: Vec<String> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(str::to_owned)
        .collect();
    assert_eq!(lines.len(), values.len());
    for (v, reference) in values.iter().zip(lines) {
        let ours: String = cdr::encode(v).iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(
            ours,
            reference,
            "{v:?} as {}: ours vs pycdr2's",
            cdr::ros2_type(v)
        );
    }
}
