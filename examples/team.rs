//! Two robots on loopback, from a multi-threaded runtime: set, get, a Stream, peer events.
use std::time::Duration;

use huddle::{Config, Notice, PeerEvent, StreamExt};

#[tokio::main]
pub async fn main() -> Result<(), Box<dyn std::error::Error>> {
    let wait = Duration::from_secs(5); // a teammate heard within 5 s, or an error
    let group = huddle::scratch_group()?; // a free group (real teams: Config::group)
    let one = huddle::open(Config::new(1, 0).group(group)).await?;
    let (mut peers, mut balls) = (one.peer_events(), one.subscribe("+.var.ball.#")?);
    let two = huddle::open(Config::new(2, 0).group(group)).await?;

    let writer = two.clone(); // Send + Clone: any task, any worker thread
    tokio::spawn(async move { writer.set("*.var.ball.dist", 1.5) }).await??;

    while let Some(Notice::Changed { key, entry }) =
        tokio::time::timeout(wait, balls.next()).await?
    {
        println!("robot 1 heard {key} = {}", entry.value);
        if key.to_string() == "2.var.ball.dist" {
            break;
        }
    }
    let dist: Option<f64> = one.get_as("2.var.ball.dist")?;
    println!("robot 2's ball is {dist:?} m away");
    assert_eq!(dist, Some(1.5), "robot 1 reads robot 2's value");

    drop(two); // robot 2 switches off: robot 1 sees it leave
    loop {
        let event = tokio::time::timeout(wait, peers.next()).await?;
        println!("peer event: {event:?}");
        match event {
            Some(PeerEvent::Departed { robot: 2 }) => return Ok(()),
            None => return Err("the session closed".into()),
            _ => {}
        }
    }
}
