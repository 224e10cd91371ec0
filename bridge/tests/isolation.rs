//! Isolation test: two teams at one venue behind one router with user/password
//! authentication and the access control of docs/bridge.md (default deny; a team writes
//! only under its own prefix; the log server reads everything). Team 8's client gets 0
//! samples and 0 replies of team 7, and its put under team 7's prefix reaches nobody,
//! while the log server sees both teams. Each team may query its own `@bridge/flush` (the
//! bridge's flush barrier at shutdown), and team 7's barrier passes under the policy.

#![allow(clippy::disallowed_methods)] // real sockets, real time

mod common;

use std::time::Duration;

use common::{wait_until, BridgeProcess, Recorder};
use comms::Value;
use huddle_bridge::harness::{client, free_port, router, Daemon, DaemonSpec};
use zenoh::Wait;

const VENUE: &str = "venue";

fn acl() -> String {
    let team_rules = |n: u8| {
        format!(
            r#"{{ id: "team{n}_publish", permission: "allow", flows: ["ingress"],
                 messages: ["put", "delete", "declare_queryable", "reply", "liveliness_token"],
                 key_exprs: ["huddle/@v1/{VENUE}/{n}/**", "huddle/@v1/{VENUE}/{n}/@bridge/*",
                             "huddle/@v1/{VENUE}/{n}/*/@alive/*"] }},
               {{ id: "team{n}_flush", permission: "allow", flows: ["ingress"],
                 messages: ["query"], key_exprs: ["huddle/@v1/{VENUE}/{n}/@bridge/flush"] }},
               {{ id: "team{n}_serve", permission: "allow", flows: ["egress"],
                 messages: ["query"],
                 key_exprs: ["huddle/@v1/{VENUE}/{n}/**", "huddle/@v1/{VENUE}/{n}/@bridge/*"] }}"#
        )
    };
    format!(
        r#"{{
          enabled: true,
          default_permission: "deny",
          rules: [
            {}, {},
            {{ id: "read_all", permission: "allow", flows: ["ingress", "egress"],
               messages: ["declare_subscriber", "query", "declare_liveliness_subscriber",
                          "liveliness_query", "put", "delete", "reply", "liveliness_token"],
               key_exprs: ["huddle/@v1/{VENUE}/**", "huddle/@v1/{VENUE}/*/@bridge/*",
                           "huddle/@v1/{VENUE}/*/*/@alive/*"] }},
          ],
          subjects: [
            {{ id: "team7", usernames: ["team7"] }},
            {{ id: "team8", usernames: ["team8"] }},
            {{ id: "readers", usernames: ["logserver"] }},
          ],
          policies: [
            {{ rules: ["team7_publish", "team7_flush", "team7_serve"], subjects: ["team7"] }},
            {{ rules: ["team8_publish", "team8_flush", "team8_serve"], subjects: ["team8"] }},
            {{ rules: ["read_all"], subjects: ["readers"] }},
          ],
        }}"#,
        team_rules(7),
        team_rules(8)
    )
}

fn login(user: &str) -> Vec<(&'static str, String)> {
    vec![
        ("transport/auth/usrpwd/user", format!("\"{user}\"")),
        ("transport/auth/usrpwd/password", format!("\"pw-{user}\"")),
    ]
}

fn as_refs<'a>(v: &'a [(&'static str, String)]) -> Vec<(&'static str, &'a str)> {
    v.iter().map(|(k, s)| (*k, s.as_str())).collect()
}

#[test]
fn team_8_reads_nothing_of_team_7_and_cannot_write_there() {
    let dir = tempfile::tempdir().unwrap();
    let users = dir.path().join("users.txt");
    std::fs::write(
        &users,
        "team7:pw-team7\nteam8:pw-team8\nlogserver:pw-logserver\n",
    )
    .unwrap();
    let port = free_port().unwrap();
    let dict = format!("\"{}\"", users.display());
    let acl = acl();
    let _router = router(
        port,
        &[
            ("transport/auth/usrpwd/dictionary_file", dict.as_str()),
            ("access_control", acl.as_str()),
        ],
    )
    .expect("router with ACL");

    // Each team's bridge logs in as its team.
    let mut bridges = Vec::new();
    let mut daemons = Vec::new();
    for team in [7u8, 8] {
        let cfg = dir.path().join(format!("team{team}.json5"));
        std::fs::write(
            &cfg,
            format!(
                "{{ transport: {{ auth: {{ usrpwd: {{ user: \"team{team}\", password: \"pw-team{team}\" }} }} }} }}"
            ),
        )
        .unwrap();
        let group = driver::scratch_group().unwrap();
        let d = Daemon::start(DaemonSpec::new(1, team, group)).unwrap();
        d.set("*.var.ball.dist", Value::Float(f64::from(team)));
        daemons.push(d);
        bridges.push(BridgeProcess::start_logged(
            group,
            team,
            VENUE,
            port,
            &["--zenoh-config", cfg.to_str().unwrap()],
            &dir.path().join(format!("bridge{team}.log")),
        ));
    }

    let log = client(port, &as_refs(&login("logserver"))).expect("log server logs in");
    let log_rec = Recorder::new(&log, &format!("huddle/@v1/{VENUE}/**"), None);
    let team8 = client(port, &as_refs(&login("team8"))).expect("team 8 logs in");
    let spy = Recorder::new(&team8, &format!("huddle/@v1/{VENUE}/7/**"), None);
    // A second team 8 session writes: a session's own puts reach its own subscribers
    // without the router, which would hide what the router lets through.
    let team8_writer = client(port, &as_refs(&login("team8"))).expect("team 8 logs in");
    std::thread::sleep(Duration::from_millis(300));

    // Both teams change a value; team 8 tries to write under team 7.
    daemons[0].set("*.var.ball.dist", Value::Float(7.5));
    daemons[1].set("*.var.ball.dist", Value::Float(8.5));
    let forged = format!("huddle/@v1/{VENUE}/7/1/var/ball/dist");
    for _ in 0..5 {
        let _ = team8_writer.put(&forged, "666").wait();
        std::thread::sleep(Duration::from_millis(20));
    }
    let seven = format!("huddle/@v1/{VENUE}/7/1/var/ball/dist");
    let eight = format!("huddle/@v1/{VENUE}/8/1/var/ball/dist");
    assert!(
        wait_until(Duration::from_secs(5), || {
            let s = log_rec.samples();
            s.iter().any(|g| g.key == seven && g.payload == "7.5")
                && s.iter().any(|g| g.key == eight && g.payload == "8.5")
        }),
        "the log server reads both teams: {:?}",
        log_rec.samples()
    );
    let team7_replies = team8
        .get(format!("huddle/@v1/{VENUE}/7/**"))
        .timeout(Duration::from_secs(1))
        .wait()
        .unwrap()
        .iter()
        .filter(|r| r.result().is_ok())
        .count();
    std::thread::sleep(Duration::from_millis(300));
    assert_eq!(spy.samples().len(), 0, "team 8 got 0 samples of team 7");
    assert_eq!(team7_replies, 0, "team 8 got 0 replies about team 7");
    assert!(
        log_rec.samples().iter().all(|g| g.payload != "666"),
        "team 8's put under team 7 reached nobody"
    );
    for b in &mut bridges {
        assert!(b.running(), "both bridges run");
    }
    // Under this policy the bridge's flush barrier at shutdown (a query on its own
    // `@bridge/flush`, answered by the router) passes: it is not left to time out.
    bridges[0].terminate();
    assert!(
        wait_until(Duration::from_secs(30), || !bridges[0].running()),
        "team 7's bridge exits after SIGTERM"
    );
    let log = std::fs::read_to_string(dir.path().join("bridge7.log")).unwrap();
    assert!(
        log.contains("flush barrier: the router routed every put"),
        "the router answered team 7's flush barrier under the ACL; the bridge's log:\n{log}"
    );
}
