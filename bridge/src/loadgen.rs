//! Field traffic for the load bench, encoded ahead of time: `robots` real
//! `comms::Replica`s (the robots' own sans-IO code) set their share of `keys` at `rate`
//! Hz in virtual time, hear each other's frames (so they echo, and the bridge anchors
//! their clocks as on a field), and every datagram they would send is kept with its send
//! time. Replayed by one lightweight sender, the bridge gets the exact frames of a team
//! producing that load, without the daemons, their timers and their tokio runtimes
//! competing with the bridge for the machine. Sans-IO: no clock, no socket.

use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};
use std::time::Duration;

use comms::{Instant, Replica, ReplicaConfig, Value};

/// One datagram of the generated traffic.
#[derive(Clone, Debug)]
pub struct Frame {
    /// When to send it, from the start of the replay.
    pub at: Duration,
    /// The sending robot.
    pub robot: u8,
    /// The encoded frame.
    pub bytes: Vec<u8>,
}

/// What was generated.
#[derive(Clone, Debug)]
pub struct Traffic {
    /// Every datagram, by send time.
    pub frames: Vec<Frame>,
    /// Value changes made (sets), over all robots.
    pub updates: u64,
    /// Each robot's id and its keys' count (`*.var.load.k0` … `k<count-1>`).
    pub robots: Vec<(u8, usize)>,
    /// The value every key holds at the end (the last tick).
    pub final_value: i64,
}

/// Generates `seconds` of `keys` keys at `rate` Hz shared by `robots` robots of `team`.
/// Each tick every key gets the tick's number. Robots start 1 s before the first tick
/// (a team already up when the load begins), so the traffic is `seconds + 1` long.
pub fn generate(team: u8, robots: u8, keys: usize, rate: u32, seconds: u64) -> Traffic {
    let robots = robots.max(1);
    let per = keys.div_ceil(usize::from(robots));
    let mut replicas: Vec<Replica> = (1..=robots)
        .map(|id| {
            let cfg = ReplicaConfig::new(id, team);
            Replica::new(cfg, 0x1000 + u64::from(id), Instant::from_micros(0))
                .expect("the default config is valid")
        })
        .collect();
    let counts: Vec<(u8, usize)> = (0..robots)
        .map(|i| {
            let count = per.min(keys.saturating_sub(usize::from(i) * per));
            (i + 1, count)
        })
        .collect();
    let names: Vec<Vec<String>> = counts
        .iter()
        .map(|(_, n)| (0..*n).map(|j| format!("*.var.load.k{j}")).collect())
        .collect();
    let period = Duration::from_secs_f64(1.0 / f64::from(rate.max(1)));
    let warm_up = Duration::from_secs(1);
    let ticks = seconds * u64::from(rate);
    let end = warm_up + period * ticks as u32;
    let mut frames = Vec::new();
    let mut updates = 0;
    let mut now = Duration::ZERO;
    let mut tick = 0u64;
    let mut next_tick = warm_up;
    loop {
        let t = Instant::from_micros(now.as_micros() as u64);
        if now >= next_tick && tick < ticks {
            tick += 1;
            for (replica, keys) in replicas.iter_mut().zip(&names) {
                for key in keys {
                    if replica.set(t, key, Value::Int(tick as i64)).is_ok() {
                        updates += 1;
                    }
                }
            }
            next_tick = warm_up + period * tick as u32;
        }
        for replica in replicas.iter_mut() {
            if replica.poll_timeout().is_some_and(|d| d <= t) {
                replica.handle_timeout(t);
            }
        }
        // Every frame sent now is heard by the teammates now (one medium).
        let mut sent = Vec::new();
        for replica in replicas.iter_mut() {
            while let Some(tx) = replica.poll_transmit() {
                sent.push((replica.robot_id(), tx.payload));
            }
        }
        for (robot, bytes) in &sent {
            let from = SocketAddr::V4(SocketAddrV4::new(
                Ipv4Addr::LOCALHOST,
                10_000 + u16::from(*robot),
            ));
            for replica in replicas.iter_mut().filter(|r| r.robot_id() != *robot) {
                replica.handle_datagram(t, from, bytes);
                while replica.poll_event().is_some() {}
            }
        }
        for replica in replicas.iter_mut() {
            while replica.poll_event().is_some() {}
        }
        frames.extend(sent.into_iter().map(|(robot, bytes)| Frame {
            at: now,
            robot,
            bytes,
        }));
        if now >= end {
            break;
        }
        // The next instant anything happens: a tick or a replica's timer.
        let mut next = if tick < ticks { next_tick } else { end };
        for replica in &replicas {
            if let Some(d) = replica.poll_timeout() {
                next = next.min(Duration::from_micros(d.as_micros()));
            }
        }
        now = next.max(now + Duration::from_micros(1)).min(end);
    }
    Traffic {
        frames,
        updates,
        robots: counts,
        final_value: ticks as i64,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Story: 40 keys at 100 Hz from 2 robots for 0.5 s: every set is counted, frames
    /// are in time order and within the traffic's length, and a listening replica fed the
    /// frames ends with every key at the last tick.
    #[test]
    fn generated_frames_carry_every_final_value() {
        let traffic = generate(7, 2, 40, 100, 1);
        assert_eq!(traffic.updates, 40 * 100, "every key set every tick");
        assert!(traffic.frames.windows(2).all(|w| w[0].at <= w[1].at));
        assert!(traffic.frames.last().unwrap().at <= Duration::from_secs(2));
        let mut listener =
            Replica::new(ReplicaConfig::new(254, 7), 1, Instant::from_micros(0)).unwrap();
        for f in &traffic.frames {
            let t = Instant::from_micros(f.at.as_micros() as u64);
            let from = SocketAddr::V4(SocketAddrV4::new(Ipv4Addr::LOCALHOST, 9));
            listener.handle_datagram(t, from, &f.bytes);
            while listener.poll_event().is_some() {}
        }
        for (robot, count) in &traffic.robots {
            for j in 0..*count {
                let v = listener
                    .get(&format!("{robot}.var.load.k{j}"))
                    .unwrap()
                    .map(|e| e.value.clone());
                assert_eq!(
                    v,
                    Some(Value::Int(traffic.final_value)),
                    "robot {robot} key {j} ends at the last tick"
                );
            }
        }
    }
}
