//! The error record every entry point fills, its codes, and the guard that keeps every
//! panic on the Rust side of the boundary.

use std::ffi::c_char;
use std::panic::{catch_unwind, AssertUnwindSafe};

/// No error.
pub const HUDDLE_OK: i32 = 0;
/// A required pointer argument was NULL.
pub const HUDDLE_E_NULL: i32 = 1;
/// A string argument was not valid UTF-8.
pub const HUDDLE_E_UTF8: i32 = 2;
/// A key that does not parse, or one this call may not use (another robot's key, a
/// talk queue given to set, a value key given to post, a key the node itself writes:
/// `local.var.team.*` while its team layer runs, `local.var.gc.*` while its
/// GameController listener runs, `local.var.huddle.*`).
pub const HUDDLE_E_KEY: i32 = 3;
/// A value literal that does not parse (see `comms::literal`: `42`, `1.5`, `true`,
/// `"text"`, `[1, 2.5]`, `0x0a0b`).
pub const HUDDLE_E_LITERAL: i32 = 4;
/// A configuration that cannot work (robot id, refresh period, MTU, config file line).
pub const HUDDLE_E_CONFIG: i32 = 5;
/// The network could not be set up (not a multicast group, no such interface, port).
pub const HUDDLE_E_NETWORK: i32 = 6;
/// The node or replica was stopped or freed (or the pointer never was one).
pub const HUDDLE_E_STOPPED: i32 = 7;
/// A caller's buffer is too small; nothing was lost, call again with a larger one.
pub const HUDDLE_E_BUFFER: i32 = 8;
/// A talk message was refused: too large for one frame, or too many queues.
pub const HUDDLE_E_POST: i32 = 9;
/// A file could not be read (key file, config directory).
pub const HUDDLE_E_IO: i32 = 10;
/// A bug inside huddle (a panic, caught at the boundary). Please report it.
pub const HUDDLE_E_INTERNAL: i32 = 11;
/// Another robot sends with this node's robot id (`huddle_node_config.id_check_ms`).
pub const HUDDLE_E_ID_CONFLICT: i32 = 12;
/// A typed read of a value of another type (`huddle_node_get_int` of a string), or a
/// team-layer output of the wrong shape.
pub const HUDDLE_E_TYPE: i32 = 13;
/// A value a typed call refuses: NaN or infinity, a covariance that is not positive
/// definite, an age outside 0..=10 s.
pub const HUDDLE_E_VALUE: i32 = 14;
/// `huddle_node_set_game_clock` while the node's GameController listener has heard the
/// GC: the GC's `secsRemaining` is the budget's clock (the relay's `ERR 424`).
pub const HUDDLE_E_CLOCK: i32 = 15;

/// What went wrong in a call: a `HUDDLE_E_*` code (0 when the call succeeded) and a
/// NUL-terminated UTF-8 message, cut to fit. Every function taking a `huddle_error *`
/// fills it when it is not NULL; pass NULL to ignore the details.
#[repr(C)]
#[allow(non_camel_case_types)]
pub struct huddle_error {
    /// `HUDDLE_OK` or a `HUDDLE_E_*` code.
    pub code: i32,
    /// Why, in English; empty on success.
    pub message: [c_char; 256],
}

/// A failure on its way to the caller.
#[derive(Debug)]
pub(crate) struct Failure {
    pub(crate) code: i32,
    pub(crate) message: String,
}

impl Failure {
    pub(crate) fn new(code: i32, message: impl Into<String>) -> Failure {
        Failure {
            code,
            message: message.into(),
        }
    }

    pub(crate) fn null(what: &str) -> Failure {
        Failure::new(HUDDLE_E_NULL, format!("{what} is NULL"))
    }

    pub(crate) fn stopped(what: &str) -> Failure {
        Failure::new(
            HUDDLE_E_STOPPED,
            format!("the {what} was stopped or freed (or never started)"),
        )
    }
}

/// Runs `body` for an entry point: its result goes back as the return value, a failure
/// (or a panic) as `on_error` with the reason written to `err`.
///
/// # Safety
///
/// `err` is NULL or points to a writable `huddle_error`.
pub(crate) unsafe fn guard<T>(
    err: *mut huddle_error,
    on_error: T,
    body: impl FnOnce() -> Result<T, Failure>,
) -> T {
    let outcome = catch_unwind(AssertUnwindSafe(body)).unwrap_or_else(|panic| {
        let what = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "unknown panic".into());
        Err(Failure::new(
            HUDDLE_E_INTERNAL,
            format!("internal error (please report): {what}"),
        ))
    });
    let (result, code, message) = match outcome {
        Ok(value) => (value, HUDDLE_OK, String::new()),
        Err(f) => (on_error, f.code, f.message),
    };
    // SAFETY: the caller promises `err` is NULL or valid for writes.
    if let Some(err) = unsafe { err.as_mut() } {
        err.code = code;
        crate::text::write_text(&mut err.message, &message);
    }
    result
}
