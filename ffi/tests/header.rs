//! The checked-in `include/huddle.h` is what cbindgen makes of the source today.

use std::path::Path;

#[test]
fn the_checked_in_header_is_up_to_date() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config = cbindgen::Config::from_file(dir.join("cbindgen.toml")).expect("cbindgen.toml");
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        .with_src(dir.join("src/lib.rs"))
        .generate()
        .expect("cbindgen reads the crate");
    let mut fresh = Vec::new();
    bindings.write(&mut fresh);
    let path = dir.join("include/huddle.h");
    if std::env::var_os("HUDDLE_BLESS").is_some() {
        std::fs::write(&path, &fresh).expect("write include/huddle.h");
        return;
    }
    let checked_in = std::fs::read(&path).unwrap_or_default();
    assert!(
        checked_in == fresh,
        "include/huddle.h is out of date with ffi/src; regenerate it with\n    \
         HUDDLE_BLESS=1 cargo test -p huddle-ffi --test header\nand commit it"
    );
}
