//! A seeded stream of calls with bad arguments through the C API: NULL pointers, bad
//! keys, bad literals, non-UTF-8, small buffers, garbage datagrams, use after stop and
//! free. Each must return its error code, never crash. `check-memory.sh` runs this
//! binary under valgrind too.

use std::ffi::{c_char, CStr, CString};
use std::ptr::{null, null_mut};

use huddle::*;

fn zeroed<T>() -> T {
    // SAFETY: only used for the C API's plain structs, for which all-zero is valid.
    unsafe { std::mem::zeroed() }
}

fn message(err: &huddle_error) -> String {
    // SAFETY: huddle always NUL-terminates the message inside the array.
    unsafe { CStr::from_ptr(err.message.as_ptr()) }
        .to_string_lossy()
        .into_owned()
}

/// A small deterministic generator (xorshift), so a failure names its step.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    fn pick<T: Copy>(&mut self, items: &[T]) -> T {
        items[(self.next() % items.len() as u64) as usize]
    }
}

const KEYS: &[&[u8]] = &[
    b"*.var.x\0",
    b"local.var.y\0",
    b"2.var.not.mine\0",
    b"*.talk.plan\0",
    b"nonsense\0",
    b"*.var.\0",
    b"\0",
    b"*.var.\xff\xfe\0",
    b"*.var..x\0",
    b"local.var.robot.pose\0",
    b"local.var.robot.ball\0",
];
const LITERALS: &[&[u8]] = &[
    b"1\0",
    b"1.5\0",
    b"\"text\"\0",
    b"[1, 2]\0",
    b"0x0a\0",
    b"true\0",
    b"not a literal\0",
    b"\"unterminated\0",
    b"99999999999999999999\0",
    b"\xc3\x28\0",
    b"\0",
];

fn cstr(bytes: &[u8]) -> *const c_char {
    bytes.as_ptr().cast()
}

#[test]
fn bad_arguments_to_the_node_are_errors_and_use_after_stop_is_refused() {
    let group = driver::scratch_group().expect("scratch group");
    let ip = CString::new(group.ip().to_string()).unwrap();
    let lo = CString::new("127.0.0.1").unwrap();
    let mut err: huddle_error = zeroed();

    // Starts that must fail cleanly.
    // SAFETY (every call below): pointers are NULL or valid, strings NUL-terminated.
    assert!(unsafe { huddle_node_start(null(), &mut err) }.is_null());
    assert_eq!(err.code, HUDDLE_E_NULL);
    let mut cfg: huddle_node_config = zeroed();
    cfg.group_address = ip.as_ptr();
    cfg.group_port = group.port();
    cfg.interface_address = lo.as_ptr();
    cfg.robot_id = 255;
    assert!(unsafe { huddle_node_start(&cfg, &mut err) }.is_null());
    assert_eq!(err.code, HUDDLE_E_CONFIG, "{}", message(&err));
    cfg.robot_id = 1;
    let unicast = CString::new("127.0.0.1").unwrap();
    cfg.group_address = unicast.as_ptr();
    assert!(unsafe { huddle_node_start(&cfg, &mut err) }.is_null());
    assert_eq!(err.code, HUDDLE_E_NETWORK, "{}", message(&err));
    cfg.group_address = ip.as_ptr();
    let no_iface = CString::new("no-such-if0").unwrap();
    cfg.interface_address = no_iface.as_ptr();
    assert!(unsafe { huddle_node_start(&cfg, &mut err) }.is_null());
    assert_eq!(err.code, HUDDLE_E_NETWORK, "{}", message(&err));
    cfg.interface_address = lo.as_ptr();
    let missing = CString::new("/nonexistent/huddle/team.key").unwrap();
    cfg.key_file = missing.as_ptr();
    assert!(unsafe { huddle_node_start(&cfg, &mut err) }.is_null());
    assert_eq!(err.code, HUDDLE_E_IO, "{}", message(&err));
    cfg.key_file = null();
    cfg.config_dir = missing.as_ptr();
    assert!(unsafe { huddle_node_start(&cfg, &mut err) }.is_null());
    assert_eq!(err.code, HUDDLE_E_IO, "{}", message(&err));
    cfg.config_dir = null();

    let node = unsafe { huddle_node_start(&cfg, null_mut()) };
    assert!(!node.is_null());
    let mut binding: huddle_binding = zeroed();
    let mut event: huddle_event = zeroed();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    for step in 0..2000 {
        let key = cstr(rng.pick(KEYS));
        let literal = cstr(rng.pick(LITERALS));
        let key = if rng.next().is_multiple_of(10) {
            null()
        } else {
            key
        };
        let literal = if rng.next().is_multiple_of(10) {
            null()
        } else {
            literal
        };
        let err_ptr = if rng.next().is_multiple_of(4) {
            null_mut()
        } else {
            &mut err as *mut _
        };
        let rc = match rng.next() % 4 {
            0 => unsafe { huddle_node_set(node, key, literal, err_ptr) },
            1 => {
                let out = if rng.next().is_multiple_of(5) {
                    null_mut()
                } else {
                    &mut binding as *mut _
                };
                unsafe { huddle_node_get(node, key, out, err_ptr) }
            }
            2 => unsafe { huddle_node_post(node, key, literal, null_mut(), err_ptr) },
            _ => unsafe { huddle_node_next_event(node, 0, &mut event, err_ptr) },
        };
        assert!((-1..=1).contains(&rc), "step {step}: rc {rc}");
        if rc == -1 && !err_ptr.is_null() {
            // HUDDLE_E_VALUE: the team layer's contract refused a write to its input key.
            assert!(
                (HUDDLE_E_NULL..=HUDDLE_E_POST).contains(&err.code) || err.code == HUDDLE_E_VALUE,
                "step {step}: code {} {}",
                err.code,
                message(&err)
            );
            assert!(!message(&err).is_empty(), "step {step}: an error says why");
        }
    }
    let key = CString::new("*.var.x").unwrap();
    let one = CString::new("1").unwrap();
    assert_eq!(
        unsafe { huddle_node_set(null_mut(), key.as_ptr(), one.as_ptr(), &mut err) },
        -1
    );
    assert_eq!(err.code, HUDDLE_E_NULL);
    assert_eq!(
        unsafe { huddle_node_set(node, key.as_ptr(), one.as_ptr(), &mut err) },
        0
    );
    assert_eq!(err.code, HUDDLE_OK);

    huddle_node_stop(node);
    huddle_node_stop(node); // a second stop does nothing
    huddle_node_stop(null_mut());
    for rc in [
        unsafe { huddle_node_set(node, key.as_ptr(), one.as_ptr(), &mut err) },
        unsafe { huddle_node_get(node, key.as_ptr(), &mut binding, &mut err) },
        unsafe { huddle_node_post(node, key.as_ptr(), one.as_ptr(), null_mut(), &mut err) },
        unsafe { huddle_node_next_event(node, 0, &mut event, &mut err) },
    ] {
        assert_eq!(rc, -1);
        assert_eq!(err.code, HUDDLE_E_STOPPED, "{}", message(&err));
    }
    // A pointer huddle never handed out is refused the same way.
    let forged = 0xdead_bee0usize as *mut huddle_node;
    assert_eq!(
        unsafe { huddle_node_get(forged, key.as_ptr(), &mut binding, &mut err) },
        -1
    );
    assert_eq!(err.code, HUDDLE_E_STOPPED);
}

#[test]
fn bad_arguments_and_garbage_datagrams_to_the_replica_are_errors() {
    let mut err: huddle_error = zeroed();
    let mut cfg: huddle_replica_config = zeroed();
    // SAFETY (every call below): pointers are NULL or valid, strings NUL-terminated,
    // buffers as long as the lengths given.
    assert!(
        unsafe { huddle_replica_new(&cfg, 1, 0, &mut err) }.is_null(),
        "robot 0"
    );
    assert_eq!(err.code, HUDDLE_E_CONFIG);
    cfg.robot_id = 1;
    cfg.mtu = 10;
    assert!(
        unsafe { huddle_replica_new(&cfg, 1, 0, &mut err) }.is_null(),
        "tiny MTU"
    );
    cfg.mtu = 0;
    let a = unsafe { huddle_replica_new(&cfg, 1, 0, &mut err) };
    cfg.robot_id = 2;
    let b = unsafe { huddle_replica_new(&cfg, 2, 0, &mut err) };
    assert!(!a.is_null() && !b.is_null());

    let mut rng = Rng(42);
    let mut buf = [0u8; 2048];
    let mut len = 0usize;
    let mut event: huddle_event = zeroed();
    let mut binding: huddle_binding = zeroed();
    let mut at = 0u64;
    for step in 0..3000u64 {
        let now = step * 1000;
        let key = cstr(rng.pick(KEYS));
        let literal = cstr(rng.pick(LITERALS));
        let rc = match rng.next() % 8 {
            0 => unsafe { huddle_replica_set(a, now, key, literal, &mut err) },
            1 => unsafe { huddle_replica_post(a, now, key, literal, null_mut(), &mut err) },
            2 => unsafe { huddle_replica_get(b, now, key, &mut binding, &mut err) },
            3 => {
                // Garbage, or a real frame with bytes flipped.
                let n = (rng.next() % 300) as usize;
                for byte in &mut buf[..n] {
                    *byte = rng.next() as u8;
                }
                unsafe { huddle_replica_handle_datagram(b, now, buf.as_ptr(), n, &mut err) }
            }
            4 => {
                let cap = (rng.next() % 64) as usize * 32;
                let rc = unsafe {
                    huddle_replica_poll_transmit(a, buf.as_mut_ptr(), cap, &mut len, &mut err)
                };
                if rc == 1 {
                    if rng.next().is_multiple_of(2) {
                        let i = (rng.next() as usize) % len;
                        buf[i] ^= 0x5a;
                    }
                    unsafe { huddle_replica_handle_datagram(b, now, buf.as_ptr(), len, &mut err) };
                } else if rc == -1 {
                    assert_eq!(err.code, HUDDLE_E_BUFFER, "step {step}");
                    assert!(len > cap, "step {step}: the needed size is told");
                }
                rc
            }
            5 => unsafe { huddle_replica_handle_timeout(a, now, &mut err) },
            6 => unsafe { huddle_replica_poll_event(b, &mut event, &mut err) },
            _ => unsafe { huddle_replica_poll_timeout(a, &mut at, &mut err) },
        };
        assert!((-1..=1).contains(&rc), "step {step}: rc {rc}");
    }
    // NULLs.
    assert_eq!(
        unsafe { huddle_replica_handle_datagram(b, 0, null(), 5, &mut err) },
        -1
    );
    assert_eq!(err.code, HUDDLE_E_NULL);
    assert_eq!(
        unsafe { huddle_replica_handle_datagram(b, 0, null(), 0, &mut err) },
        0
    );
    assert_eq!(
        unsafe { huddle_replica_poll_transmit(a, null_mut(), 0, &mut len, &mut err) },
        -1
    );
    assert_eq!(
        unsafe { huddle_replica_poll_timeout(a, null_mut(), &mut err) },
        -1
    );
    assert_eq!(
        unsafe { huddle_replica_poll_event(a, null_mut(), &mut err) },
        -1
    );
    assert_eq!(err.code, HUDDLE_E_NULL);

    huddle_replica_free(a);
    huddle_replica_free(a);
    huddle_replica_free(null_mut());
    assert_eq!(unsafe { huddle_replica_handle_timeout(a, 0, &mut err) }, -1);
    assert_eq!(err.code, HUDDLE_E_STOPPED);
    huddle_replica_free(b);
}

#[test]
fn bad_arguments_to_the_typed_budget_and_team_calls_are_errors() {
    let group = driver::scratch_group().expect("scratch group");
    let ip = CString::new(group.ip().to_string()).unwrap();
    let mut err: huddle_error = zeroed();
    let mut cfg: huddle_node_config = zeroed();
    cfg.robot_id = 1;
    cfg.group_address = ip.as_ptr();
    cfg.group_port = group.port();

    // Configurations that must fail cleanly, each with its code.
    let bad_peer = CString::new("not an address").unwrap();
    let peers = [bad_peer.as_ptr()];
    let bcast = CString::new("10.0.255.255").unwrap();
    let budget = CString::new("1200 per game").unwrap();
    let policy = CString::new("fastest").unwrap();
    let gc_listen = CString::new("3838").unwrap();
    type Edit = Box<dyn Fn(&mut huddle_node_config)>;
    let cases: Vec<(&str, Edit, i32)> = vec![
        (
            "transport 7",
            Box::new(|c| c.transport = 7),
            HUDDLE_E_CONFIG,
        ),
        (
            "peers NULL with a count",
            Box::new(|c| c.peer_count = 2),
            HUDDLE_E_NULL,
        ),
        (
            "a peer that is no address",
            Box::new(move |c| {
                c.peers = peers.as_ptr();
                c.peer_count = 1;
            }),
            HUDDLE_E_NETWORK,
        ),
        (
            "a broadcast address for multicast",
            Box::new(move |c| c.broadcast_address = bcast.as_ptr()),
            HUDDLE_E_CONFIG,
        ),
        (
            "a budget that does not parse",
            Box::new(move |c| c.budget = budget.as_ptr()),
            HUDDLE_E_CONFIG,
        ),
        (
            "gamecontroller 7",
            Box::new(|c| c.gamecontroller = 7),
            HUDDLE_E_CONFIG,
        ),
        (
            "a team policy that is none",
            Box::new(move |c| c.team_policy = policy.as_ptr()),
            HUDDLE_E_CONFIG,
        ),
        (
            "a GameController address that is none",
            Box::new(move |c| {
                c.gamecontroller = HUDDLE_GC_ON;
                c.gc_listen = gc_listen.as_ptr();
            }),
            HUDDLE_E_NETWORK,
        ),
    ];
    for (what, edit, code) in &cases {
        let mut bad: huddle_node_config = zeroed();
        bad.robot_id = cfg.robot_id;
        bad.group_address = cfg.group_address;
        bad.group_port = cfg.group_port;
        edit(&mut bad);
        // SAFETY: a config whose pointers are NULL or valid; a writable error.
        assert!(
            unsafe { huddle_node_start(&bad, &mut err) }.is_null(),
            "{what}"
        );
        assert_eq!(err.code, *code, "{what}: {}", message(&err));
    }

    // SAFETY (every call below): pointers are NULL or valid, strings NUL-terminated,
    // buffers as long as the capacities given.
    let node = unsafe { huddle_node_start(&cfg, null_mut()) };
    assert!(!node.is_null());
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    let (mut i, mut f, mut b) = (0i64, 0f64, 0i32);
    let mut text = [0 as c_char; 8];
    let mut floats = [0f64; 4];
    let mut bytes = [0u8; 4];
    let mut len = 0usize;
    let mut stats: huddle_stats = zeroed();
    let mut budget: huddle_budget = zeroed();
    let mut ball: huddle_team_ball = zeroed();
    let (mut goer, mut going) = (0u8, 0);
    let cov = [0.01, 0.0, 0.01, 0.01, 0.0, 0.01];
    for step in 0..3000 {
        let key = if rng.next().is_multiple_of(10) {
            null()
        } else {
            cstr(rng.pick(KEYS))
        };
        let err_ptr = if rng.next().is_multiple_of(4) {
            null_mut()
        } else {
            &mut err as *mut _
        };
        let null_out = rng.next().is_multiple_of(6);
        let cap = (rng.next() % 5) as usize;
        let rc = unsafe {
            match rng.next() % 16 {
                0 => huddle_node_set_int(node, key, 7, err_ptr),
                1 => huddle_node_set_string(node, key, cstr(rng.pick(LITERALS)), err_ptr),
                2 => huddle_node_set_floats(
                    node,
                    key,
                    if null_out { null() } else { floats.as_ptr() },
                    cap,
                    err_ptr,
                ),
                3 => huddle_node_set_bytes(
                    node,
                    key,
                    if null_out { null() } else { bytes.as_ptr() },
                    cap,
                    err_ptr,
                ),
                4 => huddle_node_get_int(
                    node,
                    key,
                    if null_out { null_mut() } else { &mut i },
                    err_ptr,
                ),
                5 => huddle_node_get_float(
                    node,
                    key,
                    if null_out { null_mut() } else { &mut f },
                    err_ptr,
                ),
                6 => huddle_node_get_bool(
                    node,
                    key,
                    if null_out { null_mut() } else { &mut b },
                    err_ptr,
                ),
                7 => huddle_node_get_string(
                    node,
                    key,
                    if null_out {
                        null_mut()
                    } else {
                        text.as_mut_ptr()
                    },
                    cap,
                    &mut len,
                    err_ptr,
                ),
                8 => huddle_node_get_floats(
                    node,
                    key,
                    if null_out {
                        null_mut()
                    } else {
                        floats.as_mut_ptr()
                    },
                    cap,
                    &mut len,
                    err_ptr,
                ),
                9 => huddle_node_get_bytes(
                    node,
                    key,
                    bytes.as_mut_ptr(),
                    cap,
                    if null_out { null_mut() } else { &mut len },
                    err_ptr,
                ),
                10 => huddle_node_get_literal(node, key, text.as_mut_ptr(), cap, &mut len, err_ptr),
                11 => huddle_node_set_priority(node, key, cstr(rng.pick(LITERALS)), err_ptr),
                12 => huddle_node_is_pending(node, key, err_ptr),
                13 => huddle_node_watch(node, key, err_ptr),
                14 => huddle_node_set_robot_pose(
                    node,
                    1.0,
                    f64::NAN,
                    0.0,
                    if null_out { null() } else { cov.as_ptr() },
                    0.0,
                    err_ptr,
                ),
                _ => match rng.next() % 5 {
                    0 => huddle_node_stats(
                        node,
                        if null_out { null_mut() } else { &mut stats },
                        err_ptr,
                    ),
                    1 => huddle_node_budget(
                        node,
                        if null_out { null_mut() } else { &mut budget },
                        err_ptr,
                    ),
                    2 => huddle_node_get_team_ball(
                        node,
                        if null_out { null_mut() } else { &mut ball },
                        err_ptr,
                    ),
                    3 => huddle_node_get_team_goer(
                        node,
                        if null_out { null_mut() } else { &mut goer },
                        &mut going,
                        err_ptr,
                    ),
                    _ => huddle_node_keys(node, key, text.as_mut_ptr(), cap, &mut len, err_ptr)
                        .min(1),
                },
            }
        };
        assert!((-1..=1).contains(&rc), "step {step}: rc {rc}");
        if rc == -1 && !err_ptr.is_null() {
            assert!(
                (HUDDLE_E_NULL..=HUDDLE_E_VALUE).contains(&err.code)
                    && err.code != HUDDLE_E_INTERNAL,
                "step {step}: code {} {}",
                err.code,
                message(&err)
            );
            assert!(!message(&err).is_empty(), "step {step}: an error says why");
        }
    }
    huddle_node_stop(node);
    let key = CString::new("*.var.x").unwrap();
    for rc in unsafe {
        [
            huddle_node_set_float(node, key.as_ptr(), 1.0, &mut err),
            huddle_node_get_float(node, key.as_ptr(), &mut f, &mut err),
            huddle_node_stats(node, &mut stats, &mut err),
            huddle_node_budget(node, &mut budget, &mut err),
            huddle_node_set_game_clock(node, 1000, &mut err),
            huddle_node_watch(node, key.as_ptr(), &mut err),
        ]
    } {
        assert_eq!(rc, -1);
        assert_eq!(err.code, HUDDLE_E_STOPPED, "{}", message(&err));
    }
}
