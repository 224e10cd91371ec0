//! Typed set and get on the node: one call per value type, no text in between.
//!
//! Sets take the C value (`int64_t`, `double`, a bool as `int`, a NUL-terminated string,
//! an array of doubles or bytes). Gets return 1 when found, 0 when the key is unknown
//! (the output untouched), -1 on error: `HUDDLE_E_TYPE` when the value has another type
//! (a float read accepts an int). Variable-length reads (string, floats, bytes, the
//! literal) take a buffer and its capacity and always write the full length to `len`:
//! a call with `buf` NULL and `cap` 0 asks only for the length; a buffer too small gives
//! `HUDDLE_E_BUFFER` with `len` set, so a second call with `len` (+1 for a string's NUL)
//! reads all of it, however long.

use std::ffi::{c_char, c_int};

use comms::Value;

use crate::error::*;
use crate::node::{get_value, huddle_node, set_value};
use crate::replica::huddle_replica;
use crate::text::read_str;

/// What a typed call works on: the node, or the replica at the caller's time (µs).
#[derive(Clone, Copy)]
pub(crate) enum Target {
    Node(*mut huddle_node),
    Replica(*mut huddle_replica, u64),
}

impl Target {
    fn set(self, key: &str, value: Value) -> Result<(), Failure> {
        match self {
            Target::Node(node) => set_value(node, key, value, false),
            Target::Replica(replica, now_us) => {
                crate::replica::set_value(replica, now_us, key, value)
            }
        }
    }

    fn get(self, key: &str) -> Result<Option<Value>, Failure> {
        match self {
            Target::Node(node) => get_value(node, key),
            Target::Replica(replica, _) => crate::replica::get_value(replica, key),
        }
    }
}

/// Sets `key` to a value of one type; shared by the typed setters.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `err` is NULL or writable.
pub(crate) unsafe fn set_typed(
    target: impl Into<Target>,
    key: *const c_char,
    err: *mut huddle_error,
    value: impl FnOnce() -> Result<Value, Failure>,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises a NULL or NUL-terminated string.
        let key = unsafe { read_str(key, "key") }?;
        target.into().set(key, value()?)?;
        Ok(0)
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

impl From<*mut huddle_node> for Target {
    fn from(node: *mut huddle_node) -> Target {
        Target::Node(node)
    }
}

/// Reads `key` and hands its value to `take` (which checks the type and copies out).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `err` is NULL or writable.
pub(crate) unsafe fn get_typed(
    target: impl Into<Target>,
    key: *const c_char,
    err: *mut huddle_error,
    take: impl FnOnce(&str, Value) -> Result<(), Failure>,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises a NULL or NUL-terminated string.
        let key = unsafe { read_str(key, "key") }?;
        match target.into().get(key)? {
            Some(value) => {
                take(key, value)?;
                Ok(1)
            }
            None => Ok(0),
        }
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

pub(crate) fn wrong_type(key: &str, value: &Value, wanted: &str) -> Failure {
    Failure::new(
        HUDDLE_E_TYPE,
        format!(
            "{key} holds a {}, not a{} {wanted}",
            value.value_type().name(),
            if wanted.starts_with(['a', 'e', 'i', 'o', 'u']) {
                "n"
            } else {
                ""
            }
        ),
    )
}

/// A writable out-pointer, or `HUDDLE_E_NULL`.
///
/// # Safety
///
/// `ptr` is NULL or valid for writes.
unsafe fn out<'a, T>(ptr: *mut T, what: &str) -> Result<&'a mut T, Failure> {
    // SAFETY: forwarded from the caller.
    unsafe { ptr.as_mut() }.ok_or_else(|| Failure::null(what))
}

/// Writes `value` to the caller's `ptr`.
///
/// # Safety
///
/// `ptr` is NULL or valid for writes.
pub(crate) unsafe fn put<T>(ptr: *mut T, value: T) -> Result<(), Failure> {
    // SAFETY: forwarded from the caller.
    *unsafe { out(ptr, "out") }? = value;
    Ok(())
}

/// Copies `items` into the caller's `buf` of `cap` items, `len` set to how many there
/// are; `extra`: room needed beyond them (a string's NUL). `buf` NULL with `cap` 0 is a
/// length query.
///
/// # Safety
///
/// `buf` is NULL or writable for `cap` items; `len` is NULL or writable.
pub(crate) unsafe fn copy_out<T: Copy + Default>(
    items: &[T],
    extra: usize,
    buf: *mut T,
    cap: usize,
    len: *mut usize,
) -> Result<(), Failure> {
    // SAFETY: forwarded from the caller.
    let len = unsafe { out(len, "len") }?;
    *len = items.len();
    if buf.is_null() {
        return if cap == 0 {
            Ok(())
        } else {
            Err(Failure::null("buf"))
        };
    }
    let need = items.len() + extra;
    if need > cap {
        return Err(Failure::new(
            HUDDLE_E_BUFFER,
            format!("the value takes {need} elements, the buffer holds {cap}: call again with a larger one"),
        ));
    }
    // SAFETY: non-NULL, and the caller promises `cap >= need` writable items.
    let dst = unsafe { std::slice::from_raw_parts_mut(buf, need) };
    dst[..items.len()].copy_from_slice(items);
    for slot in &mut dst[items.len()..] {
        *slot = T::default();
    }
    Ok(())
}

/// Sets `key` to the integer `value`. Returns 0, or -1 with `err` set.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_int(
    node: *mut huddle_node,
    key: *const c_char,
    value: i64,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe { set_typed(node, key, err, || Ok(Value::Int(value))) }
}

/// Sets `key` to the float `value` (NaN and infinities are values too). Returns 0, or -1.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_float(
    node: *mut huddle_node,
    key: *const c_char,
    value: f64,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe { set_typed(node, key, err, || Ok(Value::Float(value))) }
}

/// Sets `key` to the bool `value` (non-zero: true). Returns 0, or -1.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_bool(
    node: *mut huddle_node,
    key: *const c_char,
    value: c_int,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe { set_typed(node, key, err, || Ok(Value::Bool(value != 0))) }
}

/// Sets `key` to the string `value` (NUL-terminated UTF-8, taken as it is: no quotes or
/// escapes). Returns 0, or -1.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` and `value` are NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_string(
    node: *mut huddle_node,
    key: *const c_char,
    value: *const c_char,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        set_typed(node, key, err, || {
            Ok(Value::String(read_str(value, "value")?.to_owned()))
        })
    }
}

/// The caller's array of `n` items (`ptr` may be NULL when `n` is 0).
///
/// # Safety
///
/// `ptr` is NULL or readable for `n` items.
pub(crate) unsafe fn read_array<'a, T>(
    ptr: *const T,
    n: usize,
    what: &str,
) -> Result<&'a [T], Failure> {
    if n == 0 {
        return Ok(&[]);
    }
    if ptr.is_null() {
        return Err(Failure::null(what));
    }
    // SAFETY: non-NULL, and the caller promises `n` readable items.
    Ok(unsafe { std::slice::from_raw_parts(ptr, n) })
}

/// Sets `key` to the `n` doubles at `values` (a `floats` value). Returns 0, or -1.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `values` is readable for `n` doubles (NULL when `n`
/// is 0); `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_floats(
    node: *mut huddle_node,
    key: *const c_char,
    values: *const f64,
    n: usize,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        set_typed(node, key, err, || {
            Ok(Value::Floats(read_array(values, n, "values")?.to_vec()))
        })
    }
}

/// Sets `key` to the `n` bytes at `bytes` (a `bytes` value). Returns 0, or -1.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `bytes` is readable for `n` bytes (NULL when `n` is
/// 0); `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_bytes(
    node: *mut huddle_node,
    key: *const c_char,
    bytes: *const u8,
    n: usize,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        set_typed(node, key, err, || {
            Ok(Value::Bytes(read_array(bytes, n, "bytes")?.to_vec()))
        })
    }
}

/// Reads the integer at `key` into `out`. Returns 1, 0 when the key is unknown, -1 on
/// error (`HUDDLE_E_TYPE`: not an int).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_get_int(
    node: *mut huddle_node,
    key: *const c_char,
    out: *mut i64,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(node, key, err, |key, value| match value {
            Value::Int(v) => put(out, v),
            other => Err(wrong_type(key, &other, "int")),
        })
    }
}

/// Reads the float at `key` into `out` (an int is converted). Returns 1, 0 when the key
/// is unknown, -1 on error (`HUDDLE_E_TYPE`).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_get_float(
    node: *mut huddle_node,
    key: *const c_char,
    out: *mut f64,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(node, key, err, |key, value| match value {
            Value::Float(v) => put(out, v),
            Value::Int(v) => put(out, v as f64),
            other => Err(wrong_type(key, &other, "float")),
        })
    }
}

/// Reads the bool at `key` into `out` (1 or 0). Returns 1, 0 when the key is unknown, -1
/// on error (`HUDDLE_E_TYPE`).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_get_bool(
    node: *mut huddle_node,
    key: *const c_char,
    out: *mut c_int,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(node, key, err, |key, value| match value {
            Value::Bool(v) => put(out, c_int::from(v)),
            other => Err(wrong_type(key, &other, "bool")),
        })
    }
}

/// Reads the string at `key` into `buf` (`cap` bytes, NUL-terminated); `len` gets its
/// length in bytes without the NUL. `buf` NULL and `cap` 0: only the length. Returns 1,
/// 0 when the key is unknown, -1 on error (`HUDDLE_E_TYPE`; `HUDDLE_E_BUFFER` when
/// `cap < len + 1`, nothing copied).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `buf` is NULL or writable for `cap` bytes; `len` is
/// NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_get_string(
    node: *mut huddle_node,
    key: *const c_char,
    buf: *mut c_char,
    cap: usize,
    len: *mut usize,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(node, key, err, |key, value| match value {
            Value::String(s) => copy_out(s.as_bytes(), 1, buf.cast::<u8>(), cap, len),
            other => Err(wrong_type(key, &other, "string")),
        })
    }
}

/// Reads the `floats` value at `key` into `buf` (`cap` doubles); `len` gets how many it
/// holds. `buf` NULL and `cap` 0: only the length. Returns 1, 0 when the key is unknown,
/// -1 on error (`HUDDLE_E_TYPE`; `HUDDLE_E_BUFFER` when `cap < len`, nothing copied).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `buf` is NULL or writable for `cap` doubles; `len`
/// is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_get_floats(
    node: *mut huddle_node,
    key: *const c_char,
    buf: *mut f64,
    cap: usize,
    len: *mut usize,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(node, key, err, |key, value| match value {
            Value::Floats(v) => copy_out(&v, 0, buf, cap, len),
            other => Err(wrong_type(key, &other, "floats")),
        })
    }
}

/// Reads the `bytes` value at `key` into `buf` (`cap` bytes); `len` gets its length.
/// `buf` NULL and `cap` 0: only the length. Returns 1, 0 when the key is unknown, -1 on
/// error (`HUDDLE_E_TYPE`; `HUDDLE_E_BUFFER` when `cap < len`, nothing copied).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `buf` is NULL or writable for `cap` bytes; `len` is
/// NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_get_bytes(
    node: *mut huddle_node,
    key: *const c_char,
    buf: *mut u8,
    cap: usize,
    len: *mut usize,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(node, key, err, |key, value| match value {
            Value::Bytes(v) => copy_out(&v, 0, buf, cap, len),
            other => Err(wrong_type(key, &other, "bytes")),
        })
    }
}

/// Reads the value at `key`, of any type, as its literal (what `huddle_node_set` reads)
/// into `buf` (`cap` bytes, NUL-terminated), however long: `len` gets the literal's length
/// without the NUL (`huddle_binding.value` holds 1023 bytes at most). `buf` NULL and
/// `cap` 0: only the length. Returns 1, 0 when the key is unknown, -1 on error
/// (`HUDDLE_E_BUFFER` when `cap < len + 1`, nothing copied).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `buf` is NULL or writable for `cap` bytes; `len` is
/// NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_get_literal(
    node: *mut huddle_node,
    key: *const c_char,
    buf: *mut c_char,
    cap: usize,
    len: *mut usize,
    err: *mut huddle_error,
) -> c_int {
    // SAFETY: forwarded from the caller.
    unsafe {
        get_typed(node, key, err, |_, value| {
            copy_out(value.to_string().as_bytes(), 1, buf.cast::<u8>(), cap, len)
        })
    }
}
