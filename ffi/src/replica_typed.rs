//! Typed set and get on the sans-IO replica, as `typed` gives them to the node: one call
//! per value type, time an argument (`now_us`), variable-length reads through a length
//! query (`buf` NULL and `cap` 0: the length only; too small: `HUDDLE_E_BUFFER` with
//! `len` set). After a set, drain `huddle_replica_poll_transmit` as after any input.

use std::ffi::{c_char, c_int};

use comms::Value;

use crate::error::*;
use crate::replica::huddle_replica;
use crate::text::read_str;
use crate::typed::{copy_out, get_typed, put, read_array, set_typed, wrong_type, Target};

/// Sets `key` to the integer `value` at `now_us`. Returns 0, or -1 with `err` set.
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_set_int(
    replica: *mut huddle_replica,
    now_us: u64,
    key: *const c_char,
    value: i64,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        set_typed(Target::Replica(replica, now_us), key, err, || {
            Ok(Value::Int(value))
        })
    }
}

/// Sets `key` to the float `value` at `now_us`. Returns 0, or -1 with `err` set.
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_set_float(
    replica: *mut huddle_replica,
    now_us: u64,
    key: *const c_char,
    value: f64,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        set_typed(Target::Replica(replica, now_us), key, err, || {
            Ok(Value::Float(value))
        })
    }
}

/// Sets `key` to the bool `value` (non-zero: true) at `now_us`. Returns 0, or -1 with `err` set.
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_set_bool(
    replica: *mut huddle_replica,
    now_us: u64,
    key: *const c_char,
    value: c_int,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        set_typed(Target::Replica(replica, now_us), key, err, || {
            Ok(Value::Bool(value != 0))
        })
    }
}

/// Sets `key` to the NUL-terminated UTF-8 string `value` (no quotes or escapes) at `now_us`. Returns 0, or -1 with `err` set.
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `value` is NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_set_string(
    replica: *mut huddle_replica,
    now_us: u64,
    key: *const c_char,
    value: *const c_char,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        set_typed(Target::Replica(replica, now_us), key, err, || {
            Ok(Value::String(read_str(value, "value")?.to_owned()))
        })
    }
}

/// Sets `key` to the `n` doubles at `values` at `now_us`. Returns 0, or -1 with `err` set.
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `values` is readable for `n` doubles (NULL when `n` is 0); `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_set_floats(
    replica: *mut huddle_replica,
    now_us: u64,
    key: *const c_char,
    values: *const f64,
    n: usize,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        set_typed(Target::Replica(replica, now_us), key, err, || {
            Ok(Value::Floats(read_array(values, n, "values")?.to_vec()))
        })
    }
}

/// Sets `key` to the `n` bytes at `bytes` at `now_us`. Returns 0, or -1 with `err` set.
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `bytes` is readable for `n` bytes (NULL when `n` is 0); `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_set_bytes(
    replica: *mut huddle_replica,
    now_us: u64,
    key: *const c_char,
    bytes: *const u8,
    n: usize,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        set_typed(Target::Replica(replica, now_us), key, err, || {
            Ok(Value::Bytes(read_array(bytes, n, "bytes")?.to_vec()))
        })
    }
}

/// Reads an int at `key` into `out`. Returns 1, 0 when the key is unknown, -1 on error
/// (`HUDDLE_E_TYPE`: another type).
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_get_int(
    replica: *mut huddle_replica,
    key: *const c_char,
    out: *mut i64,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(
            Target::Replica(replica, 0),
            key,
            err,
            |key, value| match value {
                Value::Int(v) => put(out, v),
                other => Err(wrong_type(key, &other, "int")),
            },
        )
    }
}

/// Reads a float (an int is converted) at `key` into `out`. Returns 1, 0 when the key is unknown, -1 on error
/// (`HUDDLE_E_TYPE`: another type).
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_get_float(
    replica: *mut huddle_replica,
    key: *const c_char,
    out: *mut f64,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(
            Target::Replica(replica, 0),
            key,
            err,
            |key, value| match value {
                Value::Float(v) => put(out, v),
                Value::Int(v) => put(out, v as f64),
                other => Err(wrong_type(key, &other, "float")),
            },
        )
    }
}

/// Reads a bool (1 or 0) at `key` into `out`. Returns 1, 0 when the key is unknown, -1 on error
/// (`HUDDLE_E_TYPE`: another type).
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_get_bool(
    replica: *mut huddle_replica,
    key: *const c_char,
    out: *mut c_int,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(
            Target::Replica(replica, 0),
            key,
            err,
            |key, value| match value {
                Value::Bool(v) => put(out, c_int::from(v)),
                other => Err(wrong_type(key, &other, "bool")),
            },
        )
    }
}

/// Reads the string (NUL-terminated; `len` without the NUL) at `key` into `buf` (`cap` bytes); `len` gets its length. `buf` NULL and
/// `cap` 0: only the length. Returns 1, 0 when the key is unknown, -1 on error
/// (`HUDDLE_E_TYPE`; `HUDDLE_E_BUFFER` when it does not fit, nothing copied).
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `buf` is NULL or writable for `cap` bytes; `len` is
/// NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_get_string(
    replica: *mut huddle_replica,
    key: *const c_char,
    buf: *mut c_char,
    cap: usize,
    len: *mut usize,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(
            Target::Replica(replica, 0),
            key,
            err,
            |key, value| match value {
                Value::String(s) => copy_out(s.as_bytes(), 1, buf.cast::<u8>(), cap, len),
                other => Err(wrong_type(key, &other, "string")),
            },
        )
    }
}

/// Reads the `floats` value (`len` elements) at `key` into `buf` (`cap` doubles); `len` gets its length. `buf` NULL and
/// `cap` 0: only the length. Returns 1, 0 when the key is unknown, -1 on error
/// (`HUDDLE_E_TYPE`; `HUDDLE_E_BUFFER` when it does not fit, nothing copied).
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `buf` is NULL or writable for `cap` doubles; `len` is
/// NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_get_floats(
    replica: *mut huddle_replica,
    key: *const c_char,
    buf: *mut f64,
    cap: usize,
    len: *mut usize,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(
            Target::Replica(replica, 0),
            key,
            err,
            |key, value| match value {
                Value::Floats(v) => copy_out(&v, 0, buf, cap, len),
                other => Err(wrong_type(key, &other, "floats")),
            },
        )
    }
}

/// Reads the `bytes` value at `key` into `buf` (`cap` bytes); `len` gets its length. `buf` NULL and
/// `cap` 0: only the length. Returns 1, 0 when the key is unknown, -1 on error
/// (`HUDDLE_E_TYPE`; `HUDDLE_E_BUFFER` when it does not fit, nothing copied).
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `buf` is NULL or writable for `cap` bytes; `len` is
/// NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_get_bytes(
    replica: *mut huddle_replica,
    key: *const c_char,
    buf: *mut u8,
    cap: usize,
    len: *mut usize,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(
            Target::Replica(replica, 0),
            key,
            err,
            |key, value| match value {
                Value::Bytes(v) => copy_out(&v, 0, buf, cap, len),
                other => Err(wrong_type(key, &other, "bytes")),
            },
        )
    }
}

/// Reads the value of any type as its literal, however long (NUL-terminated; `len` without the NUL) at `key` into `buf` (`cap` bytes); `len` gets its length. `buf` NULL and
/// `cap` 0: only the length. Returns 1, 0 when the key is unknown, -1 on error
/// (`HUDDLE_E_TYPE`; `HUDDLE_E_BUFFER` when it does not fit, nothing copied).
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `buf` is NULL or writable for `cap` bytes; `len` is
/// NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_get_literal(
    replica: *mut huddle_replica,
    key: *const c_char,
    buf: *mut c_char,
    cap: usize,
    len: *mut usize,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(Target::Replica(replica, 0), key, err, |_, value| {
            copy_out(value.to_string().as_bytes(), 1, buf.cast::<u8>(), cap, len)
        })
    }
}
