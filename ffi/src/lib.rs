//! huddle for C and C++: the library a robot program links (`libhuddle.a` or
//! `libhuddle.so`) with the header `include/huddle.h`, which cbindgen generates from this
//! crate (a test fails when the checked-in header is out of date).
//!
//! **What it is.** Two levels behind one C API:
//!
//! - **the node** (`huddle_node_*`): `comms::Replica` on the `driver` crate's sockets,
//!   as `huddle daemon` runs it without the relay: multicast, SPL broadcast (10000 +
//!   team) or unicast to listed peers, under a league budget if asked (`spl`,
//!   `humanoid`, `N/DURATION`) with the priority path, the game clock and the headroom.
//!   The program sets, reads and posts in-process, on its own thread (a set is on the
//!   wire when it returns), typed (`huddle_node_set_float`, `huddle_node_get_floats`, ...,
//!   long values read whole through a length query) or as literals, with no daemon and
//!   no socket round trip per update; a thread of the node's own receives and runs the
//!   timers; talk messages, peer changes, id conflicts and watched value changes arrive
//!   as events (`huddle_node_next_event`); `huddle_node_keys` and `huddle_node_stats`
//!   list what it holds. It runs the team layer as `huddle daemon` does (the daemon's
//!   own `driver::team::TeamCore`, `docs/team-layer.md`): typed calls write its inputs
//!   (any write of an input key is checked by the contract) and read its outputs, the
//!   team ball, the goer and whether this robot goes; and, on the `spl` budget or when
//!   asked, the daemon's GameController listener (`driver::GcListener`);
//! - **the replica** (`huddle_replica_*`): `comms::Replica`, the sans-IO state machine,
//!   for programs that own their socket and their clock.
//!
//! `include/huddle.hpp` wraps both in C++17 RAII classes (header-only); `examples/` holds
//! `two_robots.c` and `two_robots.cpp`, which `tests/examples.rs` compiles with the
//! system `cc`/`c++` and runs on loopback.
//!
//! **What it is not.** No protocol logic: every frame is decided by `comms`, every socket
//! is opened by the `driver` (`driver::open`, `driver::open_unicast`); the node only moves
//! datagrams between them; no team logic of its own either: the team layer and the
//! GameController listener are the driver's, run on the node's lock and threads.
//!
//! **Linking.** `cargo build --profile ffi -p huddle-ffi` makes `target/ffi/libhuddle.a`
//! without huddle's debug info; `ffi/install.sh PREFIX` installs it stripped with the headers,
//! pkg-config files (`huddle`, `huddle-static`) and a CMake package (`huddle::huddle`).
//!
//! # Rules at the boundary
//!
//! - No panic crosses it: every entry point catches one and returns an error
//!   (`HUDDLE_E_INTERNAL`), with the reason in the caller's `huddle_error`.
//! - Every pointer argument is checked for NULL (`HUDDLE_E_NULL`); `err` may be NULL.
//! - Strings are NUL-terminated UTF-8, validated (`HUDDLE_E_UTF8`).
//! - The caller owns what it allocated (configs, bindings, events, buffers: huddle only
//!   copies into them); what huddle allocated it releases with the matching function:
//!   `huddle_node_stop`, `huddle_replica_free`.
//! - A `huddle_node *` or `huddle_replica *` is a handle looked up on every call
//!   (`handles`): after stop or free it gives `HUDDLE_E_STOPPED`, never a crash.
//! - Node functions may be called from any thread at once; replica functions too (each
//!   locks its replica). Each function's doc says so.
//!
//! # Regenerating the header
//!
//! `HUDDLE_BLESS=1 cargo test -p huddle-ffi --test header` rewrites `include/huddle.h`
//! from this source (with `cbindgen.toml`).
//!
//! # Example (the node, from Rust through the C API)
//!
//! ```no_run
//! use std::ffi::CString;
//! use huddle::*;
//!
//! let group = CString::new("239.255.42.1").unwrap();
//! let mut cfg: huddle_node_config = unsafe { std::mem::zeroed() };
//! cfg.robot_id = 1;
//! cfg.group_address = group.as_ptr();
//! let mut err: huddle_error = unsafe { std::mem::zeroed() };
//! // SAFETY: valid config, strings and error record.
//! let node = unsafe { huddle_node_start(&cfg, &mut err) };
//! assert!(!node.is_null());
//! let (key, value) = (CString::new("*.var.ball.dist").unwrap(), CString::new("1.5").unwrap());
//! // SAFETY: NUL-terminated strings.
//! assert_eq!(unsafe { huddle_node_set(node, key.as_ptr(), value.as_ptr(), &mut err) }, 0);
//! huddle_node_stop(node);
//! ```

#![deny(unsafe_op_in_unsafe_fn)]
#![warn(missing_docs)]

mod binding;
mod control;
mod engine;
mod error;
mod event;
mod gc;
mod handles;
mod node;
mod replica;
mod replica_typed;
mod team;
mod text;
mod typed;

pub use binding::huddle_binding;
pub use control::*;
pub use error::*;
pub use event::*;
pub use node::*;
pub use replica::*;
pub use replica_typed::*;
pub use team::*;
pub use typed::*;

/// The library's version, e.g. `"0.1.0"` (a static string: do not free it).
///
/// Thread safety: may be called from any thread.
#[no_mangle]
pub extern "C" fn huddle_version() -> *const std::ffi::c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}
