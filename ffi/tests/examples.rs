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
        out.contains(
            "typed: pose[2] 0.25, a string of 900 bytes, 6 keys of robot 1 (first \
             1.var.ball.dist), 1 peer present, budget none"
        ),
        "{out}"
    );
    assert!(
        out.contains("replica 2 read 1.var.machine.heuristic = 2.5 age 0 ms"),
        "{out}"
    );
    assert!(out.ends_with("two_robots_cpp: OK\n"), "{out}");
}

/// Compiles `source` (a path from the crate root) with `compiler` and `args`, runs it with
/// `run_args`, and returns its stdout; `None` (skipped, said) without the compiler.
fn build_and_run(
    compiler: &str,
    source: &Path,
    args: &[String],
    name: &str,
    run_args: &[String],
) -> Option<String> {
    if !have(compiler) {
        eprintln!(
            "SKIPPED: no `{compiler}` on this machine; cannot compile {}",
            source.display()
        );
        return None;
    }
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let compiled = Command::new(compiler)
        .arg(source)
        .args(args)
        .arg("-o")
        .arg(&out)
        .output()
        .expect("run the compiler");
    assert!(
        compiled.status.success(),
        "{compiler} {} failed:\n{}",
        source.display(),
        String::from_utf8_lossy(&compiled.stderr)
    );
    let ran = Command::new(&out)
        .args(run_args)
        .output()
        .expect("run the program");
    let stdout = String::from_utf8_lossy(&ran.stdout).into_owned();
    assert!(
        ran.status.success(),
        "{name} failed ({}):\n{stdout}\n{}",
        ran.status,
        String::from_utf8_lossy(&ran.stderr)
    );
    Some(stdout)
}

fn crate_dir() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn scratch_args() -> Vec<String> {
    let group = driver::scratch_group().expect("a scratch group");
    vec![group.ip().to_string(), group.port().to_string()]
}

#[test]
fn a_c_program_uses_the_typed_calls_events_keys_and_stats() {
    let lib = lib_dir().join("libhuddle.a");
    let args = [
        "-std=c11".into(),
        "-Wall".into(),
        "-Wextra".into(),
        "-Werror".into(),
        "-I".into(),
        crate_dir().join("include").display().to_string(),
        lib.display().to_string(),
        "-lpthread".into(),
        "-ldl".into(),
        "-lm".into(),
    ];
    let source = crate_dir().join("examples/typed_node.c");
    let Some(out) = build_and_run("cc", &source, &args, "typed_node", &scratch_args()) else {
        return;
    };
    assert!(
        out.contains("changed: 1.var.ball.pos = [0.33, -2.25, 0.1] (robot 1)"),
        "{out}"
    );
    assert!(
        out.contains("robot 2 reads ball (0.33, -2.25, 0.1), mode 3"),
        "{out}"
    );
    assert!(out.contains("role: striker (7 bytes)"), "{out}");
    assert!(
        out.contains("refused: 1.var.role holds a string, not an int"),
        "{out}"
    );
    assert!(
        out.contains(" bytes, ends  499.75]"),
        "the whole literal: {out}"
    );
    assert!(
        out.contains("3 keys of robot 1:\n1.var.ball.pos\n1.var.mode\n1.var.role\n"),
        "{out}"
    );
    assert!(out.contains("robot 2: 1 peer(s) present"), "{out}");
    assert!(
        out.contains("robot 2: talk_unknown_value 0, drops ")
            && out.contains(", no_such_counter found 0\n"),
        "a counter by name from C, and 0 for a name this library does not know: {out}"
    );
    assert!(out.ends_with("typed_node: OK\n"), "{out}");
}

/// Three robots' team layers in one C program, no daemon: robots 1 and 2 see the ball,
/// robot 3 is blind. Each node's layer fuses the teammates' world models into one team
/// ball, all three name robot 1 (nearest the ball) the goer and only it goes; bad inputs
/// get the contract's reason.
#[test]
fn three_c_nodes_run_the_team_layer_one_goer_one_team_ball() {
    let lib = lib_dir().join("libhuddle.a");
    let args = [
        "-std=c11".into(),
        "-Wall".into(),
        "-Wextra".into(),
        "-Werror".into(),
        "-I".into(),
        crate_dir().join("include").display().to_string(),
        lib.display().to_string(),
        "-lpthread".into(),
        "-ldl".into(),
        "-lm".into(),
    ];
    let source = crate_dir().join("examples/team_node.c");
    let Some(out) = build_and_run("cc", &source, &args, "team_node", &scratch_args()) else {
        return;
    };
    for robot in ["robot 1:", "robot 2:", "robot 3 (blind):"] {
        let line = out
            .lines()
            .find(|l| l.starts_with(robot))
            .unwrap_or_else(|| panic!("no line for {robot}: {out}"));
        let going = if robot == "robot 1:" { 1 } else { 0 };
        assert!(
            line.ends_with(&format!("goer 1, going {going}")),
            "robot 1 is nearest the ball and the only one going: {line}"
        );
    }
    assert!(
        out.contains("0 changes of mind in 25 more"),
        "the goer holds while nothing changes: {out}"
    );
    assert!(out.contains("robot 3 knows 2 teammates"), "{out}");
    for reason in [
        "refused (1): local.var.robot.pose: element 0 is not finite (NaN)",
        "refused (1): local.var.robot.ball: the covariance is not positive definite",
        "refused (1): local.var.robot.pose takes 9 or 10",
        "refused (1): local.var.robot.ball: age_s 7200 is not within [0, 10] s",
    ] {
        assert!(out.contains(reason), "missing {reason:?} in {out}");
    }
    assert!(out.ends_with("team_node: OK\n"), "{out}");
}

#[test]
fn the_cpp_wrapper_polls_datagrams_without_a_64_kib_buffer_each() {
    let dir = lib_dir();
    let args = [
        "-std=c++17".into(),
        "-Wall".into(),
        "-Wextra".into(),
        "-Werror".into(),
        "-I".into(),
        crate_dir().join("include").display().to_string(),
        format!("-L{}", dir.display()),
        "-lhuddle".into(),
        format!("-Wl,-rpath,{}", dir.display()),
    ];
    let source = crate_dir().join("tests/programs/poll_transmit_alloc.cpp");
    let Some(out) = build_and_run("c++", &source, &args, "poll_transmit_alloc", &[]) else {
        return;
    };
    let largest: usize = out
        .strip_prefix("largest allocation ")
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("no figure in {out}"));
    println!("{out}");
    // The first call sizes the kept buffer (2 KiB, above the 1200-byte MTU); each
    // datagram after costs its own string only.
    assert!(
        largest <= 2048,
        "poll_transmit allocated {largest} bytes at once: {out}"
    );
}

/// The README's C compile line, as written, run from the repository root with the
/// library this build made in place of `target/ffi/`.
#[test]
fn the_readme_compile_line_works_from_the_repository_root() {
    let root = crate_dir().parent().expect("the repository root");
    let readme = std::fs::read_to_string(root.join("README.md")).expect("README.md");
    let line = readme
        .lines()
        .map(str::trim)
        .find(|l| l.starts_with("cc ") && l.contains("two_robots.c"))
        .expect("a `cc ... two_robots.c` line in README.md");
    let words: Vec<&str> = line.split_whitespace().collect();
    assert_eq!(words[0], "cc");
    let lib = lib_dir();
    let mut args = Vec::new();
    let mut out = None;
    let mut words = words[1..].iter();
    while let Some(&w) = words.next() {
        if w == "-o" {
            out = words.next();
            continue;
        }
        let w = match w.strip_prefix("target/ffi/") {
            Some(file) => lib.join(file).display().to_string(),
            None => {
                if !w.starts_with('-') {
                    assert!(
                        root.join(w).exists(),
                        "README's `{w}` does not exist from the repository root"
                    );
                }
                w.to_owned()
            }
        };
        args.push(w);
    }
    assert!(out.is_some(), "the README line names its output: {line}");
    if !have("cc") {
        eprintln!("SKIPPED: no `cc`");
        return;
    }
    let exe = Path::new(env!("CARGO_TARGET_TMPDIR")).join("readme_two_robots");
    let compiled = Command::new("cc")
        .current_dir(root)
        .args(&args)
        .arg("-o")
        .arg(&exe)
        .output()
        .expect("run cc");
    assert!(
        compiled.status.success(),
        "{line}\n{}",
        String::from_utf8_lossy(&compiled.stderr)
    );
    let ran = Command::new(&exe)
        .args(scratch_args())
        .output()
        .expect("run it");
    assert!(
        ran.status.success(),
        "{}",
        String::from_utf8_lossy(&ran.stderr)
    );
}

/// `ffi/install.sh` into a scratch prefix: stripped libraries, and a program built with
/// nothing but `pkg-config` (and CMake's `find_package`, where CMake is installed).
#[test]
fn installed_libraries_are_stripped_and_found_by_pkg_config_and_cmake() {
    let prefix = Path::new(env!("CARGO_TARGET_TMPDIR")).join("install-prefix");
    let _ = std::fs::remove_dir_all(&prefix);
    let lib = lib_dir();
    let installed = Command::new(crate_dir().join("install.sh"))
        .arg(&prefix)
        .env("HUDDLE_LIB_DIR", &lib)
        .output()
        .expect("run install.sh");
    assert!(
        installed.status.success(),
        "{}",
        String::from_utf8_lossy(&installed.stderr)
    );
    let built = std::fs::metadata(lib.join("libhuddle.a")).unwrap().len();
    let archive = std::fs::read(prefix.join("lib/libhuddle.a")).unwrap();
    println!(
        "libhuddle.a: {:.1} MB as built, {:.1} MB installed",
        built as f64 / 1e6,
        archive.len() as f64 / 1e6
    );
    // Section headers, not bytes: the standard library's symboliser names .debug_info
    // in its own code.
    if have("readelf") {
        let sections = Command::new("readelf")
            .args(["-S", "-W"])
            .arg(prefix.join("lib/libhuddle.a"))
            .output()
            .expect("run readelf");
        let sections = String::from_utf8_lossy(&sections.stdout);
        assert!(sections.contains(".text"), "readelf listed no sections");
        assert!(
            !sections.contains(" .debug_info "),
            "the installed libhuddle.a still has .debug_info sections"
        );
    } else {
        eprintln!("SKIPPED: no `readelf`; the debug sections are not looked for");
    }
    for file in [
        "include/huddle.h",
        "include/huddle.hpp",
        "lib/libhuddle.so",
        "lib/cmake/huddle/huddleConfig.cmake",
        "lib/cmake/huddle/huddleConfigVersion.cmake",
    ] {
        assert!(prefix.join(file).exists(), "{file} not installed");
    }

    if !have("pkg-config") {
        eprintln!("SKIPPED: no `pkg-config`; the installed .pc files are not tried");
    } else {
        let flags = Command::new("pkg-config")
            .args(["--cflags", "--libs", "huddle-static"])
            .env("PKG_CONFIG_PATH", prefix.join("lib/pkgconfig"))
            .output()
            .expect("run pkg-config");
        assert!(
            flags.status.success(),
            "{}",
            String::from_utf8_lossy(&flags.stderr)
        );
        let flags: Vec<String> = String::from_utf8_lossy(&flags.stdout)
            .split_whitespace()
            .map(str::to_owned)
            .collect();
        let source = crate_dir().join("examples/two_robots.c");
        if let Some(out) = build_and_run(
            "cc",
            &source,
            &flags,
            "pkg_config_two_robots",
            &scratch_args(),
        ) {
            assert!(out.ends_with("two_robots: OK\n"), "{out}");
            let exe = Path::new(env!("CARGO_TARGET_TMPDIR")).join("pkg_config_two_robots");
            let size = std::fs::metadata(exe).unwrap().len();
            println!(
                "two_robots linked from the installed libhuddle.a: {:.1} MB",
                size as f64 / 1e6
            );
        }
    }

    if !have("cmake") {
        eprintln!("SKIPPED: no `cmake`; find_package(huddle) is not tried");
        return;
    }
    let project = Path::new(env!("CARGO_TARGET_TMPDIR")).join("cmake-project");
    let _ = std::fs::remove_dir_all(&project);
    std::fs::create_dir_all(&project).unwrap();
    std::fs::write(
        project.join("CMakeLists.txt"),
        format!(
            "cmake_minimum_required(VERSION 3.16)\nproject(uses_huddle C)\n\
             find_package(huddle 0.1 REQUIRED)\n\
             add_executable(two_robots {})\n\
             target_link_libraries(two_robots huddle::huddle_static)\n",
            crate_dir().join("examples/two_robots.c").display()
        ),
    )
    .unwrap();
    let build = project.join("build");
    let configured = Command::new("cmake")
        .arg("-S")
        .arg(&project)
        .arg("-B")
        .arg(&build)
        .arg(format!("-DCMAKE_PREFIX_PATH={}", prefix.display()))
        .output()
        .expect("run cmake");
    assert!(
        configured.status.success(),
        "{}",
        String::from_utf8_lossy(&configured.stderr)
    );
    let built = Command::new("cmake")
        .arg("--build")
        .arg(&build)
        .output()
        .expect("cmake --build");
    assert!(
        built.status.success(),
        "{}",
        String::from_utf8_lossy(&built.stdout)
    );
    let ran = Command::new(build.join("two_robots"))
        .args(scratch_args())
        .output()
        .unwrap();
    assert!(
        ran.status.success(),
        "{}",
        String::from_utf8_lossy(&ran.stderr)
    );
}
