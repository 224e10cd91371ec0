//! The C and C++ examples, compiled with the system `cc` and `c++` against the library
//! this build made (`libhuddle.a` for C, `libhuddle.so` for C++) and run on a loopback
//! group of their own. Skipped, with a message, where no compiler is installed.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Where this build left `libhuddle.a` and `libhuddle.so`: `target/<profile>/deps`, beside
/// this test binary, when `cargo test` built the library for the tests (a fresh checkout),
/// else `target/<profile>` (after `cargo build -p huddle-ffi`).
fn lib_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    // target/<profile>/deps/examples-<hash>
    let deps = exe.parent().expect("target/<profile>/deps");
    if deps.join("libhuddle.a").exists() {
        return deps.to_path_buf();
    }
    deps.parent().expect("target/<profile>").to_path_buf()
}

fn have(compiler: &str) -> bool {
    Command::new(compiler).arg("--version").output().is_ok()
}

fn run(compiler: &str, source: &str, link: &[String], name: &str) -> Option<String> {
    if !have(compiler) {
        eprintln!("SKIPPED: no `{compiler}` on this machine; cannot compile {source}");
        return None;
    }
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let std = if compiler == "cc" {
        "-std=c11"
    } else {
        "-std=c++17"
    };
    let compiled = Command::new(compiler)
        .args([std, "-Wall", "-Wextra", "-Werror", "-g", "-I"])
        .arg(dir.join("include"))
        .arg(dir.join("examples").join(source))
        .args(link)
        .arg("-o")
        .arg(&out)
        .output()
        .expect("run the compiler");
    assert!(
        compiled.status.success(),
        "{compiler} {source} failed:\n{}",
        String::from_utf8_lossy(&compiled.stderr)
    );
    let group = driver::scratch_group().expect("a scratch group");
    let ran = Command::new(&out)
        .arg(group.ip().to_string())
        .arg(group.port().to_string())
        .output()
        .expect("run the example");
    let stdout = String::from_utf8_lossy(&ran.stdout).into_owned();
    assert!(
        ran.status.success(),
        "{name} failed ({}):\n{stdout}\n{}",
        ran.status,
        String::from_utf8_lossy(&ran.stderr)
    );
    Some(stdout)
}

#[test]
fn the_c_example_links_the_static_library_and_its_robots_talk() {
    let lib = lib_dir().join("libhuddle.a");
    assert!(lib.exists(), "{} was not built", lib.display());
    let link = [
        lib.display().to_string(),
        "-lpthread".into(),
        "-ldl".into(),
        "-lm".into(),
    ];
    let Some(out) = run("cc", "two_robots.c", &link, "two_robots") else {
        return;
    };
    assert!(
        out.contains("robot 2 read 1.var.ball.dist = 1.5 (float, owner 1, age "),
        "{out}"
    );
    let after_ms: f64 = out
        .split(" ms after start")
        .next()
        .and_then(|s| s.rsplit(", ").next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no time in {out}"));
    // Measured, not asserted: the machines are shared and noisy.
    println!("robot 2 read robot 1's value {after_ms} ms after the start");
    assert!(out.contains("refused: 2.var.x belongs to robot 2"), "{out}");
    assert!(out.contains("refused: value \"not a literal\""), "{out}");
    assert!(
        out.contains("robot 2 got 100 talk messages from robot 1, in order"),
        "{out}"
    );
    assert!(out.contains("after stop: the node was stopped"), "{out}");
    assert!(out.ends_with("two_robots: OK\n"), "{out}");
}

#[test]
fn the_cpp_example_links_the_shared_library_through_the_raii_wrapper() {
    let dir = lib_dir();
    assert!(
        dir.join("libhuddle.so").exists(),
        "libhuddle.so was not built"
    );
    let link = [
        format!("-L{}", dir.display()),
        "-lhuddle".into(),
        format!("-Wl,-rpath,{}", dir.display()),
    ];
    let Some(out) = run("c++", "two_robots.cpp", &link, "two_robots_cpp") else {
        return;
    };
    assert!(
        out.contains("robot 2 read 1.var.ball.dist = 2.25 (float, age "),
        "{out}"
    );
    assert!(
        out.contains("refused: value \"\\\"unterminated\": unterminated string"),
        "{out}"
    );
    assert!(
        out.contains("robot 2 got 100 talk messages from robot 1, in order"),
        "{out}"
    );
    assert!(
        out.contains("replica 2 read 1.var.machine.heuristic = 2.5 age 0 ms"),
        "{out}"
    );
    assert!(out.ends_with("two_robots_cpp: OK\n"), "{out}");
}
