//! The replica: `comms::Replica`, the sans-IO protocol machine, for programs that own
//! their socket and their clock. Time is always an argument (`now_us`: microseconds on
//! the caller's monotonic clock); datagrams go in and out as bytes.
//!
//! The run loop, as for the Rust type: after **every** input (`set`, `post`,
//! `handle_datagram`, `handle_timeout`) drain `huddle_replica_poll_transmit` (send each
//! datagram to the team's group) and `huddle_replica_poll_event` until both return 0,
//! then wait for a datagram or until `huddle_replica_poll_timeout`, whichever is first.

use std::ffi::{c_char, c_int};
use std::net::{Ipv4Addr, SocketAddr};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use comms::{Instant, Key, Replica, ReplicaConfig, Transmit};

use crate::binding::{fill_binding, huddle_binding};
use crate::error::*;
use crate::event::{fill_replica_event, huddle_event};
use crate::handles::Handles;
use crate::node::{post_failure, set_failure};
use crate::text::read_str;

/// A sans-IO replica. Opaque: create it with `huddle_replica_new`, release it with
/// `huddle_replica_free`.
#[allow(non_camel_case_types)]
pub struct huddle_replica {
    _opaque: [u8; 0],
}

/// A replica's settings. Zero every field first: a zero or NULL field means its default.
/// Every robot of a team uses the same `team_id`, `refresh_ms`, `mtu` and team key.
#[repr(C)]
#[allow(non_camel_case_types)]
pub struct huddle_replica_config {
    /// This robot's id, 1..=254 (required).
    pub robot_id: u8,
    /// The team's id.
    pub team_id: u8,
    /// Refresh period of every global value (ms); 0: 100.
    pub refresh_ms: u32,
    /// Largest frame sent and accepted (bytes, 64..=65507); 0: 1200.
    pub mtu: u32,
    /// The team key's bytes (frames carry an HMAC tag); NULL: no key.
    pub team_key: *const u8,
    /// The team key's length in bytes.
    pub team_key_len: usize,
}

/// The replica and the datagram a too-small buffer could not take.
struct State {
    replica: Replica,
    pending: Option<Transmit>,
}

static REPLICAS: Handles<Mutex<State>> = Handles::new();

/// Runs `f` on the live replica behind `replica`.
fn with<T>(
    replica: *const huddle_replica,
    f: impl FnOnce(&mut State) -> Result<T, Failure>,
) -> Result<T, Failure> {
    if replica.is_null() {
        return Err(Failure::null("replica"));
    }
    let state = REPLICAS
        .get(replica)
        .ok_or_else(|| Failure::stopped("replica"))?;
    let mut state = state.lock().unwrap_or_else(|e| e.into_inner());
    f(&mut state)
}

/// Sets `key` to `value` at `now_us` (the typed calls).
pub(crate) fn set_value(
    replica: *mut huddle_replica,
    now_us: u64,
    key: &str,
    value: comms::Value,
) -> Result<(), Failure> {
    with(replica, |s| {
        s.replica
            .set(Instant::from_micros(now_us), key, value)
            .map_err(set_failure)
    })
}

/// The value at `key`, if there is one (the typed calls).
pub(crate) fn get_value(
    replica: *mut huddle_replica,
    key: &str,
) -> Result<Option<comms::Value>, Failure> {
    with(replica, |s| {
        s.replica
            .get(key)
            .map(|e| e.map(|e| e.value.clone()))
            .map_err(|e| Failure::new(HUDDLE_E_KEY, e.to_string()))
    })
}

/// The value `ptr` spells.
///
/// # Safety
///
/// `ptr` is NULL or a NUL-terminated string.
unsafe fn literal(ptr: *const c_char) -> Result<comms::Value, Failure> {
    // SAFETY: forwarded from the caller: NULL or NUL-terminated.
    let text = unsafe { read_str(ptr, "literal") }?;
    comms::parse_literal(text)
        .map_err(|e| Failure::new(HUDDLE_E_LITERAL, format!("value {text:?}: {e}")))
}

/// Creates a replica for robot `cfg->robot_id`. `incarnation` must differ between two
/// starts of one robot (use a random number); `now_us` is the caller's clock now.
/// Returns NULL on failure with the reason in `err`.
///
/// Thread safety: may be called from any thread. Each replica function locks its
/// replica, so calls on one replica from several threads are safe but serialised.
///
/// # Safety
///
/// `cfg` is NULL or points to a valid config whose `team_key` is NULL or readable for
/// `team_key_len` bytes; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_new(
    cfg: *const huddle_replica_config,
    incarnation: u64,
    now_us: u64,
    err: *mut huddle_error,
) -> *mut huddle_replica {
    let body = || {
        // SAFETY: the caller promises `cfg` is NULL or valid for reads.
        let cfg = unsafe { cfg.as_ref() }.ok_or_else(|| Failure::null("cfg"))?;
        let refresh = if cfg.refresh_ms == 0 {
            100
        } else {
            cfg.refresh_ms
        };
        let mut config = ReplicaConfig::new(cfg.robot_id, cfg.team_id)
            .with_refresh_period(Duration::from_millis(refresh.into()))
            .with_known_paths(team::known_paths());
        if cfg.mtu != 0 {
            config.mtu = cfg.mtu as usize;
        }
        if !cfg.team_key.is_null() {
            if cfg.team_key_len == 0 {
                return Err(Failure::new(HUDDLE_E_CONFIG, "team_key is empty"));
            }
            // SAFETY: non-NULL, and the caller promises `team_key_len` readable bytes.
            let key = unsafe { std::slice::from_raw_parts(cfg.team_key, cfg.team_key_len) };
            config = config.with_team_key(key.to_vec());
        }
        let replica = Replica::new(config, incarnation, Instant::from_micros(now_us))
            .map_err(|e| Failure::new(HUDDLE_E_CONFIG, e.to_string()))?;
        Ok(REPLICAS.insert(Arc::new(Mutex::new(State {
            replica,
            pending: None,
        }))))
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, std::ptr::null_mut(), body) }
}

/// Releases a replica. The pointer is dead afterwards: any call with it returns -1 with
/// `HUDDLE_E_STOPPED`, a second free does nothing. NULL does nothing.
///
/// Thread safety: may be called from any thread.
#[no_mangle]
pub extern "C" fn huddle_replica_free(replica: *mut huddle_replica) {
    let _ = std::panic::catch_unwind(|| REPLICAS.remove(replica));
}

/// Sets `key` to the value `literal` spells, at `now_us`. Returns 0, or -1 with `err`.
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` and `literal` are NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_set(
    replica: *mut huddle_replica,
    now_us: u64,
    key: *const c_char,
    literal: *const c_char,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises NULL or a NUL-terminated string.
        let key = unsafe { read_str(key, "key") }?;
        // SAFETY: the caller promises NULL or a NUL-terminated string.
        let value = unsafe { self::literal(literal) }?;
        with(replica, |s| {
            s.replica
                .set(Instant::from_micros(now_us), key, value)
                .map_err(set_failure)?;
            Ok(0)
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Posts the value `literal` spells to this robot's talk queue `key` (`*.talk.q`) at
/// `now_us`; writes its sequence number to `seq` when not NULL. Returns 0, or -1.
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` and `literal` are NULL or NUL-terminated; `seq` is NULL or writable; `err` is
/// NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_post(
    replica: *mut huddle_replica,
    now_us: u64,
    key: *const c_char,
    literal: *const c_char,
    seq: *mut u64,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises NULL or a NUL-terminated string.
        let key = unsafe { read_str(key, "key") }?;
        // SAFETY: the caller promises NULL or a NUL-terminated string.
        let value = unsafe { self::literal(literal) }?;
        let n = with(replica, |s| {
            s.replica
                .post(Instant::from_micros(now_us), key, value)
                .map_err(post_failure)
        })?;
        // SAFETY: the caller promises `seq` is NULL or valid for writes.
        if let Some(seq) = unsafe { seq.as_mut() } {
            *seq = n;
        }
        Ok(0)
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Reads `key` into `out`, its age measured to `now_us`. Returns 1 when found, 0 when
/// unknown, -1 on error.
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_get(
    replica: *mut huddle_replica,
    now_us: u64,
    key: *const c_char,
    out: *mut huddle_binding,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises NULL or a NUL-terminated string.
        let key = unsafe { read_str(key, "key") }?;
        // SAFETY: the caller promises `out` is NULL or valid for writes.
        let out = unsafe { out.as_mut() }.ok_or_else(|| Failure::null("out"))?;
        let bad_key = |e: comms::KeyError| Failure::new(HUDDLE_E_KEY, e.to_string());
        let asked = Key::parse(key).map_err(bad_key)?;
        with(replica, |s| {
            let Some(entry) = s.replica.get(key).map_err(bad_key)? else {
                return Ok(0);
            };
            let stored = match asked.scope() {
                comms::Scope::Global => asked.with_scope(comms::Scope::Robot(entry.owner)),
                _ => asked.clone(),
            };
            fill_binding(out, &stored, entry, entry.age(Instant::from_micros(now_us)));
            Ok(1)
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Feeds a datagram received from the team's group at `now_us`. Malformed, foreign or
/// badly tagged datagrams are dropped and counted (`HUDDLE_EVENT_FRAME_DROPPED`), never
/// an error. Returns 0, or -1 with `err` (NULL pointers, dead replica).
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `bytes` is NULL (only with `len` 0) or readable for `len` bytes; `err` is NULL or
/// writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_handle_datagram(
    replica: *mut huddle_replica,
    now_us: u64,
    bytes: *const u8,
    len: usize,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let bytes = if len == 0 {
            &[][..]
        } else if bytes.is_null() {
            return Err(Failure::null("bytes"));
        } else {
            // SAFETY: non-NULL, and the caller promises `len` readable bytes.
            unsafe { std::slice::from_raw_parts(bytes, len) }
        };
        // The source address only labels drop events; the caller does not give it.
        let from = SocketAddr::from((Ipv4Addr::UNSPECIFIED, 0));
        with(replica, |s| {
            s.replica
                .handle_datagram(Instant::from_micros(now_us), from, bytes);
            Ok(0)
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Runs the timers due at `now_us` (refresh, departures, talk repair). Returns 0, or -1.
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_handle_timeout(
    replica: *mut huddle_replica,
    now_us: u64,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        with(replica, |s| {
            s.replica.handle_timeout(Instant::from_micros(now_us));
            Ok(0)
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Takes the next datagram to send to the team's group into `buf` (`cap` bytes) and its
/// length into `len`. Returns 1 with a datagram, 0 when there is none, -1 on error; when
/// `buf` is too small the error is `HUDDLE_E_BUFFER`, `len` says how much is needed and
/// the datagram stays for the next call (a buffer of the MTU, 1200 by default, always
/// suffices).
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `buf` is NULL or writable for `cap` bytes; `len` is NULL or writable; `err` is NULL
/// or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_poll_transmit(
    replica: *mut huddle_replica,
    buf: *mut u8,
    cap: usize,
    len: *mut usize,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises `len` is NULL or valid for writes.
        let len = unsafe { len.as_mut() }.ok_or_else(|| Failure::null("len"))?;
        if buf.is_null() {
            return Err(Failure::null("buf"));
        }
        with(replica, |s| {
            let Some(transmit) = s.pending.take().or_else(|| s.replica.poll_transmit()) else {
                *len = 0;
                return Ok(0);
            };
            let n = transmit.payload.len();
            *len = n;
            if n > cap {
                s.pending = Some(transmit);
                return Err(Failure::new(
                    HUDDLE_E_BUFFER,
                    format!("the datagram takes {n} bytes, the buffer holds {cap}"),
                ));
            }
            // SAFETY: non-NULL, and the caller promises `cap >= n` writable bytes.
            let out = unsafe { std::slice::from_raw_parts_mut(buf, n) };
            out.copy_from_slice(&transmit.payload);
            Ok(1)
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Writes the next deadline (microseconds, the caller's clock) to `at_us`. Returns 1
/// with a deadline, 0 when there is none, -1 on error.
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `at_us` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_poll_timeout(
    replica: *mut huddle_replica,
    at_us: *mut u64,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises `at_us` is NULL or valid for writes.
        let at_us = unsafe { at_us.as_mut() }.ok_or_else(|| Failure::null("at_us"))?;
        with(replica, |s| {
            Ok(match s.replica.poll_timeout() {
                Some(at) => {
                    *at_us = at.as_micros();
                    1
                }
                None => 0,
            })
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Takes the next event into `out` (value changed, talk delivered or given up, peer
/// joined, departed or restarted, frame dropped). Returns 1 with an event, 0 when there
/// is none, -1 on error.
///
/// Thread safety: may be called from any thread (it locks the replica).
///
/// # Safety
///
/// `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_replica_poll_event(
    replica: *mut huddle_replica,
    out: *mut huddle_event,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises `out` is NULL or valid for writes.
        let out = unsafe { out.as_mut() }.ok_or_else(|| Failure::null("out"))?;
        with(replica, |s| {
            Ok(match s.replica.poll_event() {
                Some(event) => {
                    fill_replica_event(out, &event);
                    1
                }
                None => 0,
            })
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}
