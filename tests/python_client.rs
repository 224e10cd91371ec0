//! The Python client's tests (`clients/python/tests`, pytest) under `cargo test`: they
//! start real daemons on loopback from this build's binary (`HUDDLE_BIN`). Skipped,
//! with a message saying so, only where python3 or pytest is absent.

use std::path::Path;
use std::process::Command;

#[test]
fn python_client_tests_pass_against_real_daemons() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = std::env::var("PYTHON").unwrap_or_else(|_| "python3".into());
    let has = |args: &[&str]| {
        Command::new(&python)
            .args(args)
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if !has(&["--version"]) {
        println!("SKIPPED: the Python client's tests need {python} (not found)");
        eprintln!("SKIPPED: the Python client's tests need {python} (not found)");
        return;
    }
    if !has(&["-c", "import pytest"]) {
        println!("SKIPPED: the Python client's tests need pytest ({python} -m pip install pytest)");
        eprintln!(
            "SKIPPED: the Python client's tests need pytest ({python} -m pip install pytest)"
        );
        return;
    }
    let out = Command::new(&python)
        .args([
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "clients/python/tests",
        ])
        .current_dir(root)
        .env("HUDDLE_BIN", env!("CARGO_BIN_EXE_huddle"))
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .expect("run pytest");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{stdout}");
    eprintln!("{stderr}");
    assert!(
        out.status.success(),
        "pytest failed ({}):\n{stdout}\n{stderr}",
        out.status
    );
    assert!(stdout.contains(" passed"), "pytest ran no test:\n{stdout}");
}
