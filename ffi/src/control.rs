//! The node's budget and priority path, value-changed watches, key listing and stats.
//!
//! Under a league budget (`huddle_node_config.budget`) the replica paces frames over the
//! game clock; these calls reach what `huddle daemon` and the simulated robots use: a
//! priority set that may draw on the reserve at once, the GameController's remaining
//! time, the headroom left, and whether a value still waits for a frame.

use std::ffi::{c_char, c_int};
use std::time::Duration;

use comms::{Key, Pattern};

use crate::error::*;
use crate::node::{huddle_node, lookup, set_value};
use crate::text::{read_str, write_text};

/// A node's budget now (`huddle_node_budget`).
#[repr(C)]
#[allow(non_camel_case_types)]
pub struct huddle_budget {
    /// Ordinary frames the pacing would let go now before it holds one back (negative
    /// while it holds frames back; priority items may still go from the reserve).
    pub headroom: i64,
    /// Messages this robot sent so far.
    pub sent: u64,
    /// Messages left: this robot's own, or with a pooled budget the team's as far as this
    /// robot has heard.
    pub left: u64,
}

/// A node's counters (`huddle_node_stats`).
///
/// The struct's layout is fixed (programs built against an older `huddle.h` keep
/// working): counters added since are read by name with `huddle_node_stats_counter`,
/// which knows every counter, these included.
#[repr(C)]
#[allow(non_camel_case_types)]
pub struct huddle_stats {
    /// Frames accepted from teammates.
    pub frames_in: u64,
    /// Frames this robot sent (each one message of a budget).
    pub frames_out: u64,
    /// Bytes of those frames.
    pub bytes_in: u64,
    /// Bytes of frames sent.
    pub bytes_out: u64,
    /// Datagrams dropped for any reason (bad tag, other team, malformed, ...).
    pub frames_dropped: u64,
    /// Teammates' value updates applied.
    pub updates_applied: u64,
    /// Talk messages delivered to this robot.
    pub talk_delivered: u64,
    /// Talk messages given up.
    pub talk_given_up: u64,
    /// Times another robot was heard sending with this robot's id.
    pub id_conflicts: u64,
    /// Datagrams the sockets sent (a frame to the group and two peers is three).
    pub datagrams_sent: u64,
    /// Datagrams the sockets received.
    pub datagrams_received: u64,
    /// Sends the OS refused.
    pub send_errors: u64,
    /// Unicast datagrams from an address that is not a listed peer, dropped.
    pub unicast_refused: u64,
    /// Teammates heard and not departed.
    pub peers_present: u32,
    /// Teammates heard that are now departed.
    pub peers_departed: u32,
}

/// Sets `key` to the value `literal` spells on the **priority path**: under a budget the
/// next frame may draw on the reserve at once instead of waiting for the pacing (a goer
/// change, a kick, a referee event). Without a budget it is `huddle_node_set`. Returns 0,
/// or -1 with `err` set.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` and `literal` are NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_priority(
    node: *mut huddle_node,
    key: *const c_char,
    literal: *const c_char,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises NULL or NUL-terminated strings.
        let key = unsafe { read_str(key, "key") }?;
        // SAFETY: as above.
        let literal = unsafe { read_str(literal, "literal") }?;
        let value = comms::parse_literal(literal)
            .map_err(|e| Failure::new(HUDDLE_E_LITERAL, format!("value {literal:?}: {e}")))?;
        set_value(node, key, value, true)?;
        Ok(0)
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// `huddle_node_set_floats` on the priority path (see `huddle_node_set_priority`).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `values` is readable for `n` doubles (NULL when `n`
/// is 0); `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_priority_floats(
    node: *mut huddle_node,
    key: *const c_char,
    values: *const f64,
    n: usize,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        // SAFETY: the caller promises a NULL or NUL-terminated string.
        let key = unsafe { read_str(key, "key") }?;
        // SAFETY: the caller promises `n` readable doubles.
        let values = unsafe { crate::typed::read_array(values, n, "values") }?;
        set_value(node, key, comms::Value::Floats(values.to_vec()), true)?;
        Ok(0)
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Tells the budget that `remaining_ms` of play are left now (the GameController's
/// `secsRemaining`): it paces the rest of its messages over that. Without a budget it
/// does nothing. Returns 0, or -1 (`HUDDLE_E_CLOCK`: the node's GameController listener
/// has heard the GC, whose clock the budget follows; nothing changed).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_set_game_clock(
    node: *mut huddle_node,
    remaining_ms: u64,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let node = lookup(node)?;
        // The GC's figures bring their clock: a program's would move the pacing line
        // until the GC's next packet. The relay's rule decides (a client's `CLOK` is
        // refused with `ERR 424` in the same cases).
        let taken = node.with_state(|state, now| {
            comms::relay::Board::set_game_clock(
                &mut state.replica,
                now,
                Duration::from_millis(remaining_ms),
            )
            .is_ok()
        })?;
        if !taken {
            return Err(Failure::new(
                HUDDLE_E_CLOCK,
                "the game clock is the GameController's while its figures are in force",
            ));
        }
        Ok(0)
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Fills `out` with the budget now (headroom, messages sent and left). Returns 1, 0 when
/// the node has no budget (`out` untouched), -1 on error.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_budget(
    node: *mut huddle_node,
    out: *mut huddle_budget,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let node = lookup(node)?;
        // SAFETY: the caller promises `out` is NULL or valid for writes.
        let out = unsafe { out.as_mut() }.ok_or_else(|| Failure::null("out"))?;
        let status = node.with_state(|state, now| {
            // The headroom is the pacing's at the replica's last input: bring it to now.
            state.replica.handle_timeout(now);
            let r = &state.replica;
            r.budget_headroom().zip(r.budget_status())
        })?;
        Ok(match status {
            Some((headroom, (sent, left))) => {
                *out = huddle_budget {
                    headroom,
                    sent,
                    left,
                };
                1
            }
            None => 0,
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Whether this robot's value at `key` changed and still waits for a frame (a budget's
/// pacing holds it). Returns 1 pending, 0 not, -1 on error.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `key` is NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_is_pending(
    node: *mut huddle_node,
    key: *const c_char,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let node = lookup(node)?;
        // SAFETY: the caller promises a NULL or NUL-terminated string.
        let key = unsafe { read_str(key, "key") }?;
        let key = Key::parse(key).map_err(|e| Failure::new(HUDDLE_E_KEY, e.to_string()))?;
        Ok(c_int::from(
            node.with_state(|state, _| state.replica.is_pending(&key))?,
        ))
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Asks for `HUDDLE_EVENT_VALUE_CHANGED` events (from `huddle_node_next_event`) for every
/// binding matching `pattern` (`+.var.ball.#`, `2.var.#`, `local.var.team.#`): each
/// insert or change, this robot's and teammates', with the owner and the new value. A
/// pattern given twice counts once. Returns 0, or -1 (`HUDDLE_E_KEY`: not a pattern).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `pattern` is NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_watch(
    node: *mut huddle_node,
    pattern: *const c_char,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let node = lookup(node)?;
        // SAFETY: the caller promises a NULL or NUL-terminated string.
        let pattern = parse_pattern(unsafe { read_str(pattern, "pattern") }?)?;
        node.with_state(|state, _| {
            if !state.watches.contains(&pattern) {
                state.watches.push(pattern);
            }
        })?;
        Ok(0)
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Stops the events `huddle_node_watch(pattern)` asked for (events already queued stay).
/// Returns 1 when the pattern was watched, 0 when not, -1 on error.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `pattern` is NULL or NUL-terminated; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_unwatch(
    node: *mut huddle_node,
    pattern: *const c_char,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let node = lookup(node)?;
        // SAFETY: the caller promises a NULL or NUL-terminated string.
        let pattern = parse_pattern(unsafe { read_str(pattern, "pattern") }?)?;
        node.with_state(|state, _| {
            let before = state.watches.len();
            state.watches.retain(|p| *p != pattern);
            c_int::from(state.watches.len() != before)
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

fn parse_pattern(text: &str) -> Result<Pattern, Failure> {
    Pattern::parse(text).map_err(|e| Failure::new(HUDDLE_E_KEY, format!("pattern {text:?}: {e}")))
}

/// Lists the stored keys matching `pattern` (`#`: all; `+.var.#`: every robot's
/// variables; `local.#`), in key order, one per line (each ending in `\n`), into `buf`
/// (`cap` bytes, NUL-terminated); `len` gets the list's length without the NUL. `buf`
/// NULL and `cap` 0: only the length. Returns how many keys there are (0 or more), or
/// -1 on error (`HUDDLE_E_BUFFER` when `cap < len + 1`, nothing copied; call again with
/// `len + 1`).
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `pattern` is NULL or NUL-terminated; `buf` is NULL or writable for `cap` bytes; `len`
/// is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_keys(
    node: *mut huddle_node,
    pattern: *const c_char,
    buf: *mut c_char,
    cap: usize,
    len: *mut usize,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let node = lookup(node)?;
        // SAFETY: the caller promises a NULL or NUL-terminated string.
        let pattern = parse_pattern(unsafe { read_str(pattern, "pattern") }?)?;
        let (count, list) = node.with_state(|state, _| {
            let mut list = String::new();
            let mut count = 0usize;
            for (key, _) in state.replica.iter(&pattern) {
                list.push_str(&key.to_string());
                list.push('\n');
                count += 1;
            }
            (count, list)
        })?;
        // SAFETY: the caller promises `buf` is NULL or writable for `cap` bytes and `len`
        // NULL or writable.
        unsafe { write_all(&list, buf, cap, len) }?;
        Ok(c_int::try_from(count).unwrap_or(c_int::MAX))
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Copies all of `text` NUL-terminated into `buf`, or fails with `HUDDLE_E_BUFFER`;
/// `len` gets its length either way; `buf` NULL with `cap` 0 asks for the length only.
///
/// # Safety
///
/// `buf` is NULL or writable for `cap` bytes; `len` is NULL or writable.
unsafe fn write_all(
    text: &str,
    buf: *mut c_char,
    cap: usize,
    len: *mut usize,
) -> Result<(), Failure> {
    // SAFETY: the caller promises `len` is NULL or writable.
    let len = unsafe { len.as_mut() }.ok_or_else(|| Failure::null("len"))?;
    *len = text.len();
    if buf.is_null() {
        return if cap == 0 {
            Ok(())
        } else {
            Err(Failure::null("buf"))
        };
    }
    if text.len() + 1 > cap {
        return Err(Failure::new(
            HUDDLE_E_BUFFER,
            format!(
                "the list takes {} bytes with its NUL, the buffer holds {cap}",
                text.len() + 1
            ),
        ));
    }
    // SAFETY: non-NULL, and the caller promises `cap` writable bytes.
    let dst = unsafe { std::slice::from_raw_parts_mut(buf, cap) };
    write_text(dst, text);
    Ok(())
}

/// Fills `out` with the node's counters. Returns 0, or -1.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_stats(
    node: *mut huddle_node,
    out: *mut huddle_stats,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let node = lookup(node)?;
        // SAFETY: the caller promises `out` is NULL or valid for writes.
        let out = unsafe { out.as_mut() }.ok_or_else(|| Failure::null("out"))?;
        *out = node.with_state(|state, _| {
            let s = state.replica.stats();
            let (mut present, mut departed) = (0, 0);
            for peer in state.replica.peers() {
                if peer.present {
                    present += 1;
                } else {
                    departed += 1;
                }
            }
            huddle_stats {
                frames_in: s.frames_in,
                frames_out: s.frames_out,
                bytes_in: s.bytes_in,
                bytes_out: s.bytes_out,
                frames_dropped: s.drops_total(),
                updates_applied: s.updates_applied,
                talk_delivered: s.talk_delivered,
                talk_given_up: s.talk_given_up,
                id_conflicts: s.id_conflicts,
                datagrams_sent: state.io.datagrams_sent,
                datagrams_received: state.io.datagrams_received,
                send_errors: state.io.send_errors,
                unicast_refused: state.io.unicast_refused,
                peers_present: present,
                peers_departed: departed,
            }
        })?;
        Ok(0)
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// Reads the node's counter `name` into `out`: any counter the replica mirrors as
/// `local.var.huddle.stats.<name>` (`frames_in`, `talk_given_up`, `talk_unknown_value`,
/// `items_skipped`, `nacks_limited`, `clock_outliers`, ..., `drops.total`,
/// `drops.<reason>` such as `drops.bad_tag`), the node's sockets' (`datagrams_sent`,
/// `datagrams_received`, `send_errors`, `unicast_refused`) and `peers_present`,
/// `peers_departed`. `huddle stats --json` and `docs/` name them; `huddle_stats` holds
/// the oldest of them in a fixed layout, and counters added later are read here only, so
/// that the struct never changes size under a program built against an older header.
///
/// Returns 1 with `*out` set, 0 when this library has no counter by that name (a program
/// written for a newer library can tell; `out` untouched), -1 on error.
///
/// Thread safety: may be called from any thread, concurrently with any node function.
///
/// # Safety
///
/// `name` is NULL or NUL-terminated; `out` is NULL or writable; `err` is NULL or writable.
#[no_mangle]
pub unsafe extern "C" fn huddle_node_stats_counter(
    node: *mut huddle_node,
    name: *const c_char,
    out: *mut u64,
    err: *mut huddle_error,
) -> c_int {
    let body = || {
        let node = lookup(node)?;
        // SAFETY: the caller promises NULL or a NUL-terminated string.
        let name = unsafe { read_str(name, "name") }?;
        // SAFETY: the caller promises `out` is NULL or valid for writes.
        let out = unsafe { out.as_mut() }.ok_or_else(|| Failure::null("out"))?;
        let value = node.with_state(|state, _| {
            let io = &state.io;
            match name {
                "datagrams_sent" => Some(io.datagrams_sent),
                "datagrams_received" => Some(io.datagrams_received),
                "send_errors" => Some(io.send_errors),
                "unicast_refused" => Some(io.unicast_refused),
                "peers_present" | "peers_departed" => {
                    let present = name == "peers_present";
                    let n = state
                        .replica
                        .peers()
                        .filter(|p| p.present == present)
                        .count();
                    Some(n as u64)
                }
                _ => replica_counter(state.replica.stats(), name),
            }
        })?;
        Ok(match value {
            Some(v) => {
                *out = v;
                1
            }
            None => 0,
        })
    };
    // SAFETY: the caller promises `err` is NULL or writable.
    unsafe { guard(err, -1, body) }
}

/// The replica's counter `name`, by the name it has in `local.var.huddle.stats.*`
/// ([`comms::Stats::mirrored`]), and two the node reads that the mirror does not write.
fn replica_counter(s: &comms::Stats, name: &str) -> Option<u64> {
    match name {
        "own_frames" => Some(s.own_frames),
        "talk_queue_overflow" => Some(s.talk_queue_overflow),
        _ => s.mirrored(name),
    }
}
