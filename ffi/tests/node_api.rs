//! The node's typed API, league transports and budget through the C ABI, on loopback:
//! what a C or C++ robot program calls, each call checked against what a teammate sees.
#![allow(clippy::disallowed_methods)] // real sockets in real time: the tests wait for frames

use std::ffi::{c_char, CStr, CString};
use std::net::SocketAddrV4;
use std::time::{Duration, Instant};

use huddle::*;

fn zeroed<T>() -> T {
    // SAFETY: used for the C structs only, where all-zero is valid (NULL strings).
    unsafe { std::mem::zeroed() }
}

fn text(chars: &[c_char]) -> String {
    // SAFETY: huddle NUL-terminates every string it writes.
    unsafe { CStr::from_ptr(chars.as_ptr()) }
        .to_string_lossy()
        .into_owned()
}

fn c(s: &str) -> CString {
    CString::new(s).unwrap()
}

struct Node(*mut huddle_node);

impl Drop for Node {
    fn drop(&mut self) {
        huddle_node_stop(self.0);
    }
}

/// Starts a node from `cfg` after `edit`; the strings live in `keep`.
fn start(robot: u8, edit: impl FnOnce(&mut huddle_node_config)) -> Result<Node, (i32, String)> {
    let mut cfg: huddle_node_config = zeroed();
    cfg.robot_id = robot;
    // Departed after 300 ms of silence: long enough for a loaded machine.
    cfg.refresh_ms = 100;
    edit(&mut cfg);
    let mut err: huddle_error = zeroed();
    // SAFETY: a valid config whose strings outlive the call; a writable error.
    let node = unsafe { huddle_node_start(&cfg, &mut err) };
    if node.is_null() {
        Err((err.code, text(&err.message)))
    } else {
        Ok(Node(node))
    }
}

fn multicast(robot: u8, group: SocketAddrV4) -> Node {
    let ip = c(&group.ip().to_string());
    start(robot, |cfg| {
        cfg.group_address = ip.as_ptr();
        cfg.group_port = group.port();
    })
    .unwrap_or_else(|e| panic!("start robot {robot}: {e:?}"))
}

/// Polls `f` every 10 ms for up to 5 s until it gives `Some`.
fn eventually<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(5) {
        if let Some(v) = f() {
            return v;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    panic!("{what}: not within 5 s");
}

fn get_float(node: &Node, key: &str) -> Option<f64> {
    let key = c(key);
    let mut v = 0.0;
    let mut err: huddle_error = zeroed();
    // SAFETY: a live node, a NUL-terminated key, writable outputs.
    let rc = unsafe { huddle_node_get_float(node.0, key.as_ptr(), &mut v, &mut err) };
    assert!(rc >= 0, "get_float {key:?}: {}", text(&err.message));
    (rc == 1).then_some(v)
}

fn set_float(node: &Node, key: &str, v: f64) {
    let key = c(key);
    let mut err: huddle_error = zeroed();
    // SAFETY: a live node, a NUL-terminated key, a writable error.
    let rc = unsafe { huddle_node_set_float(node.0, key.as_ptr(), v, &mut err) };
    assert_eq!(rc, 0, "set_float: {}", text(&err.message));
}

#[test]
fn typed_values_of_every_type_reach_a_teammate_and_long_ones_read_whole() {
    let group = driver::scratch_group().unwrap();
    let one = multicast(1, group);
    let two = multicast(2, group);
    let mut err: huddle_error = zeroed();
    // A literal of 3000 floats is far beyond the 1023 bytes of huddle_binding.value.
    let long: Vec<f64> = (0..3000)
        .map(|i| f64::from(i) * 0.001 + 0.123_456_789)
        .collect();
    let blob: Vec<u8> = (0..=255).collect();
    // SAFETY (all calls below): a live node, NUL-terminated strings, buffers of the
    // lengths given, writable outputs.
    unsafe {
        assert_eq!(
            huddle_node_set_int(one.0, c("*.var.i").as_ptr(), -7, &mut err),
            0
        );
        assert_eq!(
            huddle_node_set_bool(one.0, c("*.var.b").as_ptr(), 1, &mut err),
            0
        );
        assert_eq!(
            huddle_node_set_string(
                one.0,
                c("*.var.s").as_ptr(),
                c("say \"hi\"").as_ptr(),
                &mut err
            ),
            0
        );
        let few = [0.5, -2.25];
        assert_eq!(
            huddle_node_set_floats(one.0, c("*.var.f").as_ptr(), few.as_ptr(), 2, &mut err),
            0
        );
        assert_eq!(
            huddle_node_set_bytes(
                one.0,
                c("*.var.y").as_ptr(),
                blob.as_ptr(),
                blob.len(),
                &mut err
            ),
            0
        );
        // Too big for one frame on the wire: kept local, where it is read whole.
        assert_eq!(
            huddle_node_set_floats(
                one.0,
                c("local.var.long").as_ptr(),
                long.as_ptr(),
                long.len(),
                &mut err
            ),
            0,
            "{}",
            text(&err.message)
        );
    }
    set_float(&one, "*.var.x", 1.5);
    eventually("robot 2 reads robot 1's float", || {
        get_float(&two, "1.var.x")
    });
    assert_eq!(get_float(&two, "1.var.x"), Some(1.5));
    eventually("robot 2 reads robot 1's bytes", || {
        let mut len = 0;
        // SAFETY: as above; a length query.
        let rc = unsafe {
            huddle_node_get_bytes(
                two.0,
                c("1.var.y").as_ptr(),
                std::ptr::null_mut(),
                0,
                &mut len,
                &mut err,
            )
        };
        (rc == 1).then_some(len)
    });
    // SAFETY (all calls below): as above.
    unsafe {
        let mut i = 0i64;
        assert_eq!(
            huddle_node_get_int(two.0, c("1.var.i").as_ptr(), &mut i, &mut err),
            1
        );
        assert_eq!(i, -7);
        let mut b = 0;
        assert_eq!(
            huddle_node_get_bool(two.0, c("1.var.b").as_ptr(), &mut b, &mut err),
            1
        );
        assert_eq!(b, 1);
        // A float read of an int converts; an int read of a string is a type error.
        let mut f = 0.0;
        assert_eq!(
            huddle_node_get_float(two.0, c("1.var.i").as_ptr(), &mut f, &mut err),
            1
        );
        assert_eq!(f, -7.0);
        assert_eq!(
            huddle_node_get_int(two.0, c("1.var.s").as_ptr(), &mut i, &mut err),
            -1
        );
        assert_eq!(err.code, HUDDLE_E_TYPE, "{}", text(&err.message));
        assert_eq!(text(&err.message), "1.var.s holds a string, not an int");
        assert_eq!(i, -7, "a refused read leaves the output alone");

        let mut len = 0;
        let mut small = [0 as c_char; 4];
        assert_eq!(
            huddle_node_get_string(
                two.0,
                c("1.var.s").as_ptr(),
                small.as_mut_ptr(),
                small.len(),
                &mut len,
                &mut err
            ),
            -1
        );
        assert_eq!(
            (err.code, len),
            (HUDDLE_E_BUFFER, 8),
            "the length comes back"
        );
        let mut whole = vec![0 as c_char; len + 1];
        assert_eq!(
            huddle_node_get_string(
                two.0,
                c("1.var.s").as_ptr(),
                whole.as_mut_ptr(),
                whole.len(),
                &mut len,
                &mut err
            ),
            1
        );
        assert_eq!(text(&whole), "say \"hi\"");

        let mut floats = [0.0; 2];
        assert_eq!(
            huddle_node_get_floats(
                two.0,
                c("1.var.f").as_ptr(),
                floats.as_mut_ptr(),
                2,
                &mut len,
                &mut err
            ),
            1
        );
        assert_eq!((floats, len), ([0.5, -2.25], 2));
        let mut bytes = vec![0u8; 256];
        assert_eq!(
            huddle_node_get_bytes(
                two.0,
                c("1.var.y").as_ptr(),
                bytes.as_mut_ptr(),
                256,
                &mut len,
                &mut err
            ),
            1
        );
        assert_eq!(bytes, blob);

        // The long value: the binding is cut, the length query and the typed read are not.
        let mut binding: huddle_binding = zeroed();
        assert_eq!(
            huddle_node_get(one.0, c("local.var.long").as_ptr(), &mut binding, &mut err),
            1
        );
        assert!(binding.value_len > 1023, "{}", binding.value_len);
        let mut n = 0;
        assert_eq!(
            huddle_node_get_literal(
                one.0,
                c("local.var.long").as_ptr(),
                std::ptr::null_mut(),
                0,
                &mut n,
                &mut err
            ),
            1
        );
        assert_eq!(n, binding.value_len);
        let mut literal = vec![0 as c_char; n + 1];
        assert_eq!(
            huddle_node_get_literal(
                one.0,
                c("local.var.long").as_ptr(),
                literal.as_mut_ptr(),
                n + 1,
                &mut n,
                &mut err
            ),
            1
        );
        let parsed = comms::parse_literal(&text(&literal)).expect("the whole literal parses");
        assert_eq!(parsed, comms::Value::Floats(long.clone()));
        let mut all = vec![0.0; long.len()];
        assert_eq!(
            huddle_node_get_floats(
                one.0,
                c("local.var.long").as_ptr(),
                all.as_mut_ptr(),
                all.len(),
                &mut n,
                &mut err
            ),
            1
        );
        assert_eq!(all, long);
        // An unknown key is 0, not an error.
        assert_eq!(
            huddle_node_get_int(two.0, c("1.var.nothing").as_ptr(), &mut i, &mut err),
            0
        );
    }
}

#[test]
fn watched_changes_arrive_as_events_and_keys_and_stats_are_listed() {
    let group = driver::scratch_group().unwrap();
    let one = multicast(1, group);
    let two = multicast(2, group);
    let mut err: huddle_error = zeroed();
    // SAFETY (all calls below): live nodes, NUL-terminated strings, writable outputs.
    unsafe {
        assert_eq!(
            huddle_node_watch(two.0, c("+.var.ball.#").as_ptr(), &mut err),
            0
        );
        assert_eq!(
            huddle_node_watch(two.0, c("1.var.#.x").as_ptr(), &mut err),
            -1
        );
        assert_eq!(err.code, HUDDLE_E_KEY);
    }
    set_float(&one, "*.var.other", 9.0); // not watched
    set_float(&one, "*.var.ball.dist", 2.5);
    let mut event: huddle_event = zeroed();
    let changed = eventually("a value-changed event", || {
        // SAFETY: as above.
        let rc = unsafe { huddle_node_next_event(two.0, 50, &mut event, &mut err) };
        assert!(rc >= 0);
        (rc == 1 && event.kind == HUDDLE_EVENT_VALUE_CHANGED).then(|| text(&event.name))
    });
    assert_eq!(changed, "1.var.ball.dist", "only the watched key");
    assert_eq!((event.robot, text(&event.value)), (1, "2.5".to_owned()));

    // SAFETY: as above.
    unsafe {
        let mut len = 0;
        let n = huddle_node_keys(
            two.0,
            c("1.var.#").as_ptr(),
            std::ptr::null_mut(),
            0,
            &mut len,
            &mut err,
        );
        assert_eq!(n, 2, "{}", text(&err.message));
        let mut buf = vec![0 as c_char; len + 1];
        huddle_node_keys(
            two.0,
            c("1.var.#").as_ptr(),
            buf.as_mut_ptr(),
            buf.len(),
            &mut len,
            &mut err,
        );
        assert_eq!(text(&buf), "1.var.ball.dist\n1.var.other\n");

        let mut stats: huddle_stats = zeroed();
        assert_eq!(huddle_node_stats(two.0, &mut stats, &mut err), 0);
        assert!(
            stats.frames_in > 0 && stats.datagrams_received > 0,
            "frames in {}",
            stats.frames_in
        );
        assert_eq!(stats.peers_present, 1, "robot 1");
        assert_eq!(stats.id_conflicts, 0);

        // Every counter the replica mirrors is readable by name (the struct holds the
        // oldest ones only), and agrees with the struct where both have it.
        let mut len = 0;
        let stats_keys = c("local.var.huddle.stats.#");
        huddle_node_keys(
            two.0,
            stats_keys.as_ptr(),
            std::ptr::null_mut(),
            0,
            &mut len,
            &mut err,
        );
        let mut buf = vec![0 as c_char; len + 1];
        huddle_node_keys(
            two.0,
            stats_keys.as_ptr(),
            buf.as_mut_ptr(),
            buf.len(),
            &mut len,
            &mut err,
        );
        let names: Vec<String> = text(&buf)
            .lines()
            .map(|k| k.trim_start_matches("local.var.huddle.stats.").to_owned())
            .filter(|n| !n.starts_with("peer."))
            .collect();
        assert!(
            names.iter().any(|n| n == "talk_unknown_value"),
            "mirrored: {names:?}"
        );
        for name in &names {
            let mut v = u64::MAX;
            assert_eq!(
                huddle_node_stats_counter(two.0, c(name).as_ptr(), &mut v, &mut err),
                1,
                "huddle_node_stats_counter knows the mirrored counter {name}"
            );
            assert_ne!(v, u64::MAX, "{name} was written");
        }
        let mut v = 7;
        assert_eq!(
            huddle_node_stats_counter(two.0, c("no_such_counter").as_ptr(), &mut v, &mut err),
            0,
            "an unknown name is 0, not an error"
        );
        assert_eq!(v, 7, "out untouched");
        assert_eq!(
            huddle_node_stats_counter(two.0, std::ptr::null(), &mut v, &mut err),
            -1
        );
        assert_eq!(err.code, HUDDLE_E_NULL);
        let mut conflicts = u64::MAX;
        assert_eq!(
            huddle_node_stats_counter(two.0, c("id_conflicts").as_ptr(), &mut conflicts, &mut err),
            1
        );
        assert_eq!(
            conflicts, stats.id_conflicts,
            "the struct and the name agree"
        );
        assert_eq!(
            huddle_node_unwatch(two.0, c("+.var.ball.#").as_ptr(), &mut err),
            1
        );
    }
}

#[test]
fn an_spl_team_on_loopback_broadcast_hears_each_other() {
    let port = driver::scratch_group().unwrap().port();
    let node = |robot| {
        start(robot, |cfg| {
            cfg.transport = HUDDLE_TRANSPORT_BROADCAST;
            cfg.group_port = port;
        })
        .unwrap_or_else(|e| panic!("broadcast robot {robot}: {e:?}"))
    };
    let (one, two) = (node(1), node(2));
    set_float(&one, "*.var.x", 3.0);
    assert_eq!(
        eventually("robot 2 hears a broadcast", || get_float(&two, "1.var.x")),
        3.0
    );
    // A group address with the broadcast transport is a mistake, said clearly.
    let group = c("239.1.2.3");
    let refused = start(3, |cfg| {
        cfg.transport = HUDDLE_TRANSPORT_BROADCAST;
        cfg.group_address = group.as_ptr();
    })
    .err()
    .expect("refused");
    assert_eq!(refused.0, HUDDLE_E_CONFIG, "{}", refused.1);
}

#[test]
fn unicast_goes_to_listed_peers_only() {
    let (pa, pb, pc) = (
        driver::scratch_group().unwrap().port(),
        driver::scratch_group().unwrap().port(),
        driver::scratch_group().unwrap().port(),
    );
    let node = |robot, port: u16, peers: &[u16]| {
        let peers: Vec<CString> = peers.iter().map(|p| c(&format!("127.0.0.1:{p}"))).collect();
        let ptrs: Vec<*const c_char> = peers.iter().map(|p| p.as_ptr()).collect();
        start(robot, |cfg| {
            cfg.transport = HUDDLE_TRANSPORT_UNICAST;
            cfg.group_port = port;
            cfg.peers = ptrs.as_ptr();
            cfg.peer_count = ptrs.len();
        })
        .unwrap_or_else(|e| panic!("unicast robot {robot}: {e:?}"))
    };
    let one = node(1, pa, &[pb, pc]);
    let two = node(2, pb, &[pa]);
    // Robot 3 sends to robot 2, which does not list it: refused.
    let three = node(3, pc, &[pb, pa]);
    set_float(&one, "*.var.x", 4.0);
    set_float(&three, "*.var.x", 5.0);
    assert_eq!(
        eventually("robot 2 hears robot 1", || get_float(&two, "1.var.x")),
        4.0
    );
    assert_eq!(
        eventually("robot 3 hears robot 1", || get_float(&three, "1.var.x")),
        4.0
    );
    let refused = eventually("robot 2 refuses robot 3", || {
        let mut stats: huddle_stats = zeroed();
        // SAFETY: a live node, writable outputs.
        unsafe { huddle_node_stats(two.0, &mut stats, std::ptr::null_mut()) };
        (stats.unicast_refused > 0).then_some(stats.unicast_refused)
    });
    assert!(refused > 0);
    assert_eq!(get_float(&two, "3.var.x"), None, "not a listed peer");
    let none = start(4, |cfg| cfg.transport = HUDDLE_TRANSPORT_UNICAST)
        .err()
        .expect("no peers");
    assert_eq!(none.0, HUDDLE_E_CONFIG, "{}", none.1);
}

#[test]
fn under_a_budget_pacing_holds_values_and_the_priority_path_does_not() {
    let group = driver::scratch_group().unwrap();
    let ip = c(&group.ip().to_string());
    let spec = c("60/60s");
    let node = start(1, |cfg| {
        cfg.group_address = ip.as_ptr();
        cfg.group_port = group.port();
        cfg.budget = spec.as_ptr();
        cfg.team_size = 1;
    })
    .expect("a node with a budget");
    let mut err: huddle_error = zeroed();
    let mut budget: huddle_budget = zeroed();
    // SAFETY (all calls below): a live node, NUL-terminated strings, writable outputs.
    unsafe {
        assert_eq!(huddle_node_budget(node.0, &mut budget, &mut err), 1);
        assert_eq!(
            budget.sent + budget.left,
            60,
            "this robot's share of 60 messages, none pooled"
        );
        let key = c("*.var.x");
        let own = c("1.var.x");
        // 48 ordinary messages over 60 s: one per 1.25 s. The second of two quick sets waits.
        let mut held = false;
        for i in 0..5 {
            assert_eq!(
                huddle_node_set_float(node.0, key.as_ptr(), f64::from(i), &mut err),
                0
            );
            held |= huddle_node_is_pending(node.0, own.as_ptr(), &mut err) == 1;
        }
        assert!(held, "the pacing held no value back");
        assert_eq!(huddle_node_budget(node.0, &mut budget, &mut err), 1);
        assert!(budget.headroom <= 0, "headroom {}", budget.headroom);
        let sent_before = budget.sent;
        assert_eq!(
            huddle_node_set_priority(node.0, key.as_ptr(), c("99.0").as_ptr(), &mut err),
            0
        );
        assert_eq!(
            huddle_node_is_pending(node.0, own.as_ptr(), &mut err),
            0,
            "a priority item goes at once"
        );
        assert_eq!(huddle_node_budget(node.0, &mut budget, &mut err), 1);
        assert_eq!(budget.sent, sent_before + 1, "one message from the reserve");
        // The GameController says an hour is left: the same messages spread thinner.
        assert_eq!(huddle_node_set_game_clock(node.0, 3_600_000, &mut err), 0);
        // A bad budget is a clear refusal.
        let bad = c("lots");
        let refused = start(2, |cfg| cfg.budget = bad.as_ptr())
            .err()
            .expect("refused");
        assert_eq!(refused.0, HUDDLE_E_CONFIG);
        assert!(
            refused.1.contains("expected spl, humanoid or N/DURATION"),
            "{}",
            refused.1
        );
    }
    // Without a budget there is none to report.
    let free = multicast(3, driver::scratch_group().unwrap());
    // SAFETY: as above.
    assert_eq!(
        unsafe { huddle_node_budget(free.0, &mut budget, &mut err) },
        0
    );
}

#[test]
fn a_second_node_with_a_running_robots_id_is_refused() {
    let group = driver::scratch_group().unwrap();
    let _first = multicast(5, group);
    let ip = c(&group.ip().to_string());
    let twin = start(5, |cfg| {
        cfg.group_address = ip.as_ptr();
        cfg.group_port = group.port();
        cfg.id_check_ms = 500; // five refresh periods of the running node
    });
    let (code, message) = twin.err().expect("the twin must not start");
    assert_eq!(code, HUDDLE_E_ID_CONFLICT);
    assert!(message.contains("robot id 5"), "{message}");
    // Another id on the same group starts after the same check.
    let other = start(6, |cfg| {
        cfg.group_address = ip.as_ptr();
        cfg.group_port = group.port();
        cfg.id_check_ms = 300;
    });
    assert!(other.is_ok(), "{:?}", other.err());
}

#[test]
fn team_layer_inputs_are_checked_and_outputs_read_typed() {
    let group = driver::scratch_group().unwrap();
    // No layer: the outputs below are written by hand, and a layer's tick would overwrite
    // them. The typed calls check their inputs all the same.
    let ip = c(&group.ip().to_string());
    let node = start(1, |cfg| {
        cfg.group_address = ip.as_ptr();
        cfg.group_port = group.port();
        cfg.no_team_layer = 1;
    })
    .unwrap();
    let mut err: huddle_error = zeroed();
    // SAFETY (all calls below): a live node, arrays of the lengths given, writable outputs.
    unsafe {
        let cov = [0.04, 0.0, 0.0, 0.04, 0.0, 0.01];
        assert_eq!(
            huddle_node_set_robot_pose(node.0, 1.0, -0.5, 0.3, cov.as_ptr(), 0.05, &mut err),
            0
        );
        let mut n = 0;
        let mut pose = [0.0; 10];
        assert_eq!(
            huddle_node_get_floats(
                node.0,
                c("local.var.robot.pose").as_ptr(),
                pose.as_mut_ptr(),
                10,
                &mut n,
                &mut err
            ),
            1
        );
        assert_eq!(
            pose,
            [1.0, -0.5, 0.3, 0.04, 0.0, 0.0, 0.04, 0.0, 0.01, 0.05]
        );

        let not_pd = [0.04, 0.05, 0.04];
        assert_eq!(
            huddle_node_set_robot_ball(node.0, 1.0, 0.0, not_pd.as_ptr(), 0.0, &mut err),
            -1
        );
        assert_eq!(err.code, HUDDLE_E_VALUE);
        assert!(
            text(&err.message).contains("not positive definite"),
            "{}",
            text(&err.message)
        );
        let ok = [0.01, 0.0, 0.01];
        assert_eq!(
            huddle_node_set_robot_ball(node.0, f64::NAN, 0.0, ok.as_ptr(), 0.0, &mut err),
            -1
        );
        assert_eq!(
            huddle_node_set_robot_ball(node.0, 1.0, 0.0, ok.as_ptr(), 11.0, &mut err),
            -1
        );
        let mut len = 0;
        assert_eq!(
            huddle_node_get_floats(
                node.0,
                c("local.var.robot.ball").as_ptr(),
                std::ptr::null_mut(),
                0,
                &mut len,
                &mut err
            ),
            0,
            "refused sightings wrote nothing"
        );
        assert_eq!(
            huddle_node_set_robot_kick(node.0, 0.5, 3.0, 0.9, &mut err),
            0
        );

        // The outputs, in the layout the team layer writes them.
        let mut ball: huddle_team_ball = zeroed();
        assert_eq!(
            huddle_node_get_team_ball(node.0, &mut ball, &mut err),
            0,
            "no ball yet"
        );
        let tb = [1.0, 2.0, 0.1, 0.2, 0.03, 0.0, 0.03, 0.8, 0.4];
        huddle_node_set_floats(
            node.0,
            c("local.var.team.ball").as_ptr(),
            tb.as_ptr(),
            9,
            &mut err,
        );
        assert_eq!(huddle_node_get_team_ball(node.0, &mut ball, &mut err), 1);
        assert_eq!(
            (ball.x, ball.vy, ball.cov, ball.confidence, ball.age_s),
            (1.0, 0.2, [0.03, 0.0, 0.03], 0.8, 0.4)
        );
        let mates = [2.0, 1.0, 1.0, 0.0, 0.1, 3.0, -1.0, 2.0, 3.1, 4.0];
        huddle_node_set_floats(
            node.0,
            c("local.var.team.mates").as_ptr(),
            mates.as_ptr(),
            10,
            &mut err,
        );
        let mut out: [huddle_teammate; 1] = zeroed();
        let mut count = 0;
        assert_eq!(
            huddle_node_get_team_mates(node.0, out.as_mut_ptr(), 1, &mut count, &mut err),
            -1
        );
        assert_eq!((err.code, count), (HUDDLE_E_BUFFER, 2));
        let mut out: [huddle_teammate; 2] = zeroed();
        assert_eq!(
            huddle_node_get_team_mates(node.0, out.as_mut_ptr(), 2, &mut count, &mut err),
            1
        );
        assert_eq!((out[1].robot, out[1].silent_s), (3, 4.0));
    }
}

/// The node's layer guards its input keys whatever call writes them, as the daemon's
/// relay guards do; with `no_team_layer` they are plain keys.
#[test]
fn the_team_layer_refuses_a_bad_input_from_any_set_call_and_runs_on_a_pose() {
    let group = driver::scratch_group().unwrap();
    let ip = c(&group.ip().to_string());
    let with_layer = |off: u8| {
        start(1, |cfg| {
            cfg.group_address = ip.as_ptr();
            cfg.group_port = group.port();
            cfg.no_team_layer = off;
        })
        .unwrap()
    };
    let not_pd = [1.0, 0.0, 0.04, 0.05, 0.04];
    let key = c("local.var.robot.ball");
    let mut err: huddle_error = zeroed();
    let node = with_layer(0);
    // SAFETY (all calls below): a live node, NUL-terminated strings, arrays of the
    // lengths given, writable outputs.
    unsafe {
        let rc = huddle_node_set_floats(node.0, key.as_ptr(), not_pd.as_ptr(), 5, &mut err);
        assert_eq!(
            (rc, err.code),
            (-1, HUDDLE_E_VALUE),
            "a layer guards its inputs"
        );
        assert_eq!(
            text(&err.message),
            "local.var.robot.ball: the covariance is not positive definite; nothing written"
        );
        let rc = huddle_node_set(node.0, key.as_ptr(), c("true").as_ptr(), &mut err);
        assert_eq!(
            (rc, err.code),
            (-1, HUDDLE_E_VALUE),
            "{}",
            text(&err.message)
        );
        let mut goer = 9;
        let mut going = 9;
        assert_eq!(
            huddle_node_get_team_goer(node.0, &mut goer, &mut going, &mut err),
            0,
            "dormant until a pose or odometry"
        );
        let cov = [0.01, 0.0, 0.0, 0.01, 0.0, 0.001];
        let pose = c("local.var.robot.pose");
        let mut values = vec![0.5, -1.0, 0.0];
        values.extend(cov);
        assert_eq!(
            huddle_node_set_floats(node.0, pose.as_ptr(), values.as_ptr(), 9, &mut err),
            0
        );
        // The pose closed a cycle: the layer ticked before the call returned.
        assert_eq!(
            huddle_node_get_team_goer(node.0, &mut goer, &mut going, &mut err),
            1
        );
        assert_eq!((goer, going), (0, 0), "no ball seen: nobody goes");
        // The layer's outputs are its own, the counters the node's: a set call of one is
        // refused (the relay's `ERR 423`) and writes nothing.
        let out = c("local.var.team.goer");
        let rc = huddle_node_set(node.0, out.as_ptr(), c("2").as_ptr(), &mut err);
        assert_eq!((rc, err.code), (-1, HUDDLE_E_KEY), "{}", text(&err.message));
        assert!(
            text(&err.message).starts_with("local.var.team.goer is written by the team layer"),
            "{}",
            text(&err.message)
        );
        let counter = c("local.var.huddle.stats.frames_in");
        let rc = huddle_node_set_int(node.0, counter.as_ptr(), 0, &mut err);
        assert_eq!((rc, err.code), (-1, HUDDLE_E_KEY), "{}", text(&err.message));
        assert_eq!(
            huddle_node_get_team_goer(node.0, &mut goer, &mut going, &mut err),
            1
        );
        assert_eq!(goer, 0, "a refused set writes nothing");
        let mut held: huddle_pose = zeroed();
        assert_eq!(huddle_node_get_team_pose(node.0, &mut held, &mut err), 1);
        assert!(
            (held.x - 0.5).abs() < 1e-6 && (held.y + 1.0).abs() < 1e-6,
            "the layer holds the pose written: ({}, {})",
            held.x,
            held.y
        );
        drop(node);

        let plain = with_layer(1);
        let rc = huddle_node_set_floats(plain.0, key.as_ptr(), not_pd.as_ptr(), 5, &mut err);
        assert_eq!(rc, 0, "no layer: a plain key ({})", text(&err.message));
        let rc = huddle_node_set(plain.0, out.as_ptr(), c("2").as_ptr(), &mut err);
        assert_eq!(
            rc,
            0,
            "no layer: its outputs are plain keys ({})",
            text(&err.message)
        );
    }
}

#[test]
fn the_replica_has_the_same_typed_calls_in_virtual_time() {
    let mut err: huddle_error = zeroed();
    let replica = |robot| {
        let mut cfg: huddle_replica_config = zeroed();
        cfg.robot_id = robot;
        // SAFETY: a valid config, a writable error.
        let r = unsafe { huddle_replica_new(&cfg, u64::from(robot), 0, std::ptr::null_mut()) };
        assert!(!r.is_null());
        r
    };
    let (one, two) = (replica(1), replica(2));
    let pose = [0.5, -1.0, 0.25];
    let note = "x".repeat(700);
    // SAFETY (all calls below): live replicas, NUL-terminated strings, buffers of the
    // capacities given, writable outputs.
    unsafe {
        assert_eq!(
            huddle_replica_set_floats(
                one,
                1000,
                c("*.var.pose").as_ptr(),
                pose.as_ptr(),
                3,
                &mut err
            ),
            0
        );
        assert_eq!(
            huddle_replica_set_int(one, 1000, c("*.var.mode").as_ptr(), 4, &mut err),
            0
        );
        assert_eq!(
            huddle_replica_set_bool(one, 1000, c("*.var.ready").as_ptr(), 1, &mut err),
            0
        );
        assert_eq!(
            huddle_replica_set_float(one, 1000, c("*.var.cost").as_ptr(), 2.5, &mut err),
            0
        );
        assert_eq!(
            huddle_replica_set_string(
                one,
                1000,
                c("*.var.note").as_ptr(),
                c(&note).as_ptr(),
                &mut err
            ),
            0
        );
        assert_eq!(
            huddle_replica_set_bytes(
                one,
                1000,
                c("*.var.raw").as_ptr(),
                [9u8, 8].as_ptr(),
                2,
                &mut err
            ),
            0
        );
        let mut buf = [0u8; 2048];
        let mut len = 0;
        while huddle_replica_poll_transmit(one, buf.as_mut_ptr(), buf.len(), &mut len, &mut err)
            == 1
        {
            assert_eq!(
                huddle_replica_handle_datagram(two, 3000, buf.as_ptr(), len, &mut err),
                0
            );
        }
        let mut floats = [0.0; 3];
        assert_eq!(
            huddle_replica_get_floats(
                two,
                c("1.var.pose").as_ptr(),
                floats.as_mut_ptr(),
                3,
                &mut len,
                &mut err
            ),
            1
        );
        assert_eq!(floats, pose);
        let (mut i, mut f, mut b) = (0i64, 0.0, 0);
        assert_eq!(
            huddle_replica_get_int(two, c("1.var.mode").as_ptr(), &mut i, &mut err),
            1
        );
        assert_eq!(
            huddle_replica_get_float(two, c("1.var.cost").as_ptr(), &mut f, &mut err),
            1
        );
        assert_eq!(
            huddle_replica_get_bool(two, c("1.var.ready").as_ptr(), &mut b, &mut err),
            1
        );
        assert_eq!((i, f, b), (4, 2.5, 1));
        let mut raw = [0u8; 2];
        assert_eq!(
            huddle_replica_get_bytes(
                two,
                c("1.var.raw").as_ptr(),
                raw.as_mut_ptr(),
                2,
                &mut len,
                &mut err
            ),
            1
        );
        assert_eq!(raw, [9, 8]);
        assert_eq!(
            huddle_replica_get_string(
                two,
                c("1.var.note").as_ptr(),
                std::ptr::null_mut(),
                0,
                &mut len,
                &mut err
            ),
            1
        );
        assert_eq!(len, 700);
        let mut whole = vec![0 as c_char; len + 1];
        assert_eq!(
            huddle_replica_get_string(
                two,
                c("1.var.note").as_ptr(),
                whole.as_mut_ptr(),
                len + 1,
                &mut len,
                &mut err
            ),
            1
        );
        assert_eq!(text(&whole), note);
        assert_eq!(
            huddle_replica_get_literal(
                two,
                c("1.var.note").as_ptr(),
                std::ptr::null_mut(),
                0,
                &mut len,
                &mut err
            ),
            1
        );
        assert_eq!(
            len, 702,
            "the quoted literal, beyond huddle_binding's 1023 only when longer"
        );
        assert_eq!(
            huddle_replica_get_int(two, c("1.var.note").as_ptr(), &mut i, &mut err),
            -1
        );
        assert_eq!(err.code, HUDDLE_E_TYPE);
    }
    huddle_replica_free(one);
    huddle_replica_free(two);
}
