//! The `Send + Clone` session from a multi-threaded runtime: two robots on a scratch
//! group on loopback, writes from tasks on other threads, changes and peer events as
//! streams, and a departure when one robot closes.

use std::time::Duration;

use comms::{ReplicaConfig, Value};
use driver::{DriverConfig, Notice, PeerEvent, Session};
use futures_util::StreamExt;

fn config(id: u8, group: std::net::SocketAddrV4) -> DriverConfig {
    let mut cfg = DriverConfig::new(ReplicaConfig::new(id, 0));
    cfg.socket.group = group;
    cfg
}

/// The next item of `stream` that `pick` accepts, within 5 s.
async fn next_such<S, T, R>(stream: &mut S, what: &str, mut pick: impl FnMut(T) -> Option<R>) -> R
where
    S: futures_util::Stream<Item = T> + Unpin,
{
    let wait = tokio::time::timeout(Duration::from_secs(5), async {
        while let Some(item) = stream.next().await {
            if let Some(r) = pick(item) {
                return Some(r);
            }
        }
        None
    });
    match wait.await {
        Ok(Some(r)) => r,
        Ok(None) => panic!("the stream ended before {what}"),
        Err(_) => panic!("no {what} within 5 s"),
    }
}

fn assert_send_sync_clone<T: Send + Sync + Clone + 'static>() {}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_sessions_replicate_across_threads_and_report_peers() {
    assert_send_sync_clone::<Session>();
    let group = driver::scratch_group().expect("a scratch group");
    let one = Session::open(config(1, group))
        .await
        .expect("robot 1 opens");
    let mut joined = one.peer_events();
    let mut balls = one.subscribe("2.var.ball.#").expect("valid pattern");
    let two = Session::open(config(2, group))
        .await
        .expect("robot 2 opens");

    let robot = next_such(&mut joined, "robot 2 joining", |e| match e {
        PeerEvent::Joined { robot, .. } => Some(robot),
        _ => None,
    })
    .await;
    assert_eq!(robot, 2, "robot 1 hears robot 2 join");

    // Robot 2 writes from a task that may run on either worker thread.
    let writer = two.clone();
    tokio::spawn(async move { writer.set("*.var.ball.dist", 1.5) })
        .await
        .expect("the task ran")
        .expect("robot 2 sets its own key");
    let (key, value) = next_such(&mut balls, "robot 2's ball", |n| match n {
        Notice::Changed { key, entry } => Some((key.to_string(), entry.value)),
        _ => None,
    })
    .await;
    assert_eq!(
        (key.as_str(), value),
        ("2.var.ball.dist", Value::Float(1.5)),
        "robot 1's stream carries robot 2's write"
    );
    assert_eq!(
        one.get_as::<f64>("2.var.ball.dist").expect("valid key"),
        Some(1.5),
        "a typed read of the replicated value"
    );
    assert_eq!(
        one.get_as::<String>("2.var.ball.dist").expect("valid key"),
        None,
        "a read of another type is None, not a panic"
    );

    // Dropping every clone of robot 2 closes it: robot 1 reports it departed.
    drop(two);
    let robot = next_such(&mut joined, "robot 2 departing", |e| match e {
        PeerEvent::Departed { robot } => Some(robot),
        _ => None,
    })
    .await;
    assert_eq!(robot, 2, "robot 1 hears robot 2 fall silent");

    one.close();
    assert!(
        tokio::time::timeout(Duration::from_secs(1), balls.next())
            .await
            .expect("a closed session ends its streams at once")
            .is_none(),
        "the stream ends when the session closes"
    );
}
