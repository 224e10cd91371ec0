//! The acoustic fallback on real daemons: four `huddle daemon`s on loopback, their clocks
//! set seconds apart (`--clock-offset`, `--clock-drift-ppm`), each speaking into and
//! listening from a room this test mixes (FIFOs: every robot's loudspeaker summed, with
//! a little noise, into every robot's microphone, paced in real time as a sound card
//! would). The radio works for 5 s, then fails for everyone (`--outage 30s@5s`).
//!
//! Scenario: robot 1 is the goalkeeper; field players 2, 3 and 4 post costs 1, 2 and 3,
//! so the radio agrees robot 2 goes. In the outage the team layer sounds each field
//! player's claim in its own slot of the team clock (robot 1's clock, read through the
//! replica's echo estimates: on the robots' own clocks the slots would be seconds apart).
//! Then robot 2 walks away (cost 6): nobody can tell the others by radio, and the team must
//! hand the ball to robot 3 on what it hears, every robot agreeing, exactly one going.
//! Everything sends on loopback only (a scratch group, IP_MULTICAST_IF 127.0.0.1).

#![allow(clippy::disallowed_methods)] // real daemons, real time

mod daemon_support;

use std::io::{Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use daemon_support::{free_tcp_port, mkfifo, scratch_group, Client, Daemon};

const RATE: usize = 16_000;
/// The mixer writes this much audio at a time, as a sound card's period.
const PERIOD: usize = 320;

/// The room: every robot's loudspeaker FIFO summed into every robot's microphone FIFO,
/// at the pace of real time, until `stop`.
fn room(speakers: Vec<PathBuf>, microphones: Vec<PathBuf>, stop: Arc<AtomicBool>) {
    let mut outs: Vec<std::fs::File> = speakers
        .iter()
        .map(|p| {
            // Non-blocking: the daemon starts its speaking command at its first claim.
            std::fs::OpenOptions::new()
                .read(true)
                .custom_flags(libc_o_nonblock())
                .open(p)
                .expect("open a loudspeaker FIFO")
        })
        .collect();
    // Blocks until each daemon's `cat` has opened its microphone.
    let mut mics: Vec<std::fs::File> = microphones
        .iter()
        .map(|p| {
            std::fs::OpenOptions::new()
                .write(true)
                .open(p)
                .expect("open a microphone FIFO")
        })
        .collect();
    let mut queued: Vec<std::collections::VecDeque<i16>> = vec![Default::default(); outs.len()];
    let mut pending_byte: Vec<Option<u8>> = vec![None; outs.len()];
    let started = Instant::now();
    let mut written = 0usize;
    let mut noise = 0x2545_f491_4f6c_dd1du64;
    let mut buf = vec![0u8; 1 << 16];
    while !stop.load(Ordering::Relaxed) {
        for (i, out) in outs.iter_mut().enumerate() {
            while let Ok(n) = out.read(&mut buf) {
                if n == 0 {
                    break;
                }
                let mut bytes: Vec<u8> = pending_byte[i].take().into_iter().collect();
                bytes.extend_from_slice(&buf[..n]);
                let pairs = bytes.chunks_exact(2);
                pending_byte[i] = pairs.remainder().first().copied();
                queued[i].extend(pairs.map(|b| i16::from_le_bytes([b[0], b[1]])));
            }
        }
        let due = (started.elapsed().as_secs_f64() * RATE as f64) as usize;
        while written + PERIOD <= due {
            let mut mix = vec![0i32; PERIOD];
            for q in &mut queued {
                for m in mix.iter_mut() {
                    *m += i32::from(q.pop_front().unwrap_or(0));
                }
            }
            for mic in &mut mics {
                let mut pcm = Vec::with_capacity(2 * PERIOD);
                for m in &mix {
                    // xorshift noise, ±150: the room is never digitally silent.
                    noise ^= noise << 13;
                    noise ^= noise >> 7;
                    noise ^= noise << 17;
                    let n = (noise % 301) as i32 - 150;
                    let s = (*m + n).clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16;
                    pcm.extend_from_slice(&s.to_le_bytes());
                }
                if mic.write_all(&pcm).is_err() {
                    return;
                }
            }
            written += PERIOD;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// `O_NONBLOCK` on Linux (the test runs there only; `libc` is not a dependency).
fn libc_o_nonblock() -> i32 {
    0o4000
}

fn start(id: u8, group: &str, dir: &Path, clock: (&str, &str), outage: &str) -> Daemon {
    let speaker = dir.join(format!("speaker{id}"));
    let microphone = dir.join(format!("mic{id}"));
    let input = format!("cat '{}'", microphone.display());
    let output = format!("cat > '{}'", speaker.display());
    let config = dir.join(format!("config{id}"));
    std::fs::create_dir_all(&config).unwrap();
    Daemon::start(
        id,
        group,
        free_tcp_port(),
        &[
            "--team-size",
            "4",
            "--no-gamecontroller",
            "--outage",
            outage,
            "--audio-in",
            &input,
            "--audio-out",
            &output,
            "--audio-tone",
            "400ms",
            "--audio-gap",
            "300ms",
            "--audio-heard",
            "local.var.audio.heard",
            "--audio-fallback",
            "--clock-offset",
            clock.0,
            "--clock-drift-ppm",
            clock.1,
        ],
        &config,
    )
}

fn goer(c: &mut Client) -> String {
    let answer = c.ask("GETV local.var.team.goer");
    comms::relay::Binding::parse(&answer).map_or(answer.clone(), |b| b.value)
}

fn going(c: &mut Client) -> bool {
    let answer = c.ask("GETV local.var.team.going");
    comms::relay::Binding::parse(&answer).is_some_and(|b| b.value == "true")
}

/// Waits until every robot names `want` as the goer and only `want` is going.
fn wait_for_goer(clients: &mut [Client], want: u8, within: Duration, what: &str) {
    let deadline = Instant::now() + within;
    loop {
        let goers: Vec<String> = clients.iter_mut().map(goer).collect();
        let goings: Vec<bool> = clients.iter_mut().map(going).collect();
        let agreed = goers.iter().all(|g| *g == want.to_string());
        let one = goings
            .iter()
            .enumerate()
            .all(|(i, g)| *g == (i + 1 == usize::from(want)));
        if agreed && one {
            return;
        }
        assert!(
            Instant::now() < deadline,
            "{what}: after {within:?} the goers robots 1-4 name are {goers:?} and going is {goings:?}; want robot {want}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Four daemons with clocks seconds apart and drifting (as robots switched on at
/// different times), robot `id` rehearsing `--outage outage(id)`, in one mixed room; robot
/// 1 the goalkeeper, field players 2, 3 and 4 posting costs 1, 2 and 3. Dropped, it stops
/// the daemons and the room.
struct Team {
    clients: Vec<Client>,
    /// When the daemons had started.
    started: Instant,
    daemons: Vec<Daemon>,
    stop: Arc<AtomicBool>,
    mixer: Option<std::thread::JoinHandle<()>>,
    _dir: tempfile::TempDir,
}

impl Team {
    fn start(outage: impl Fn(u8) -> &'static str) -> Team {
        let dir = tempfile::tempdir().unwrap();
        let group = scratch_group().to_string();
        let ids = [1u8, 2, 3, 4];
        let (mut speakers, mut mics) = (Vec::new(), Vec::new());
        for id in ids {
            let s = dir.path().join(format!("speaker{id}"));
            let m = dir.path().join(format!("mic{id}"));
            mkfifo(&s);
            mkfifo(&m);
            speakers.push(s);
            mics.push(m);
        }
        let stop = Arc::new(AtomicBool::new(false));
        let mixer = {
            let stop = stop.clone();
            std::thread::spawn(move || room(speakers, mics, stop))
        };
        let clocks = [
            ("0s", "0"),
            ("7.3s", "25"),
            ("13.6s", "-30"),
            ("3.1s", "12"),
        ];
        let daemons: Vec<Daemon> = ids
            .iter()
            .zip(clocks)
            .map(|(&id, clock)| start(id, &group, dir.path(), clock, outage(id)))
            .collect();
        let started = Instant::now();
        let mut clients: Vec<Client> = daemons.iter().map(Daemon::client).collect();
        for (i, c) in clients.iter_mut().enumerate() {
            let id = i + 1;
            let x = -1.0 - i as f64;
            assert_eq!(
                c.ask(&format!("SETV local.var.robot.goalkeeper {}", id == 1)),
                "OK"
            );
            let cost = if id == 1 { 1000.0 } else { (id - 1) as f64 };
            assert_eq!(c.ask(&format!("SETV local.var.robot.cost {cost:.1}")), "OK");
            assert_eq!(
                c.ask(&format!(
                    "SETV local.var.robot.pose [{x:.1}, 0.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.01]"
                )),
                "OK"
            );
        }
        Team {
            clients,
            started,
            daemons,
            stop,
            mixer: Some(mixer),
            _dir: dir,
        }
    }
}

impl Drop for Team {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        self.clients.clear();
        self.daemons.clear();
        if let Some(m) = self.mixer.take() {
            let _ = m.join();
        }
    }
}

#[test]
fn in_a_radio_outage_the_team_hands_the_ball_over_by_sound_on_the_team_clock() {
    let mut team = Team::start(|_| "30s@5s");
    let (started, clients) = (team.started, &mut team.clients);
    wait_for_goer(
        clients,
        2,
        Duration::from_secs(4),
        "by radio, robot 2 (cost 1) goes",
    );
    // The outage starts 5 s after each daemon's start; give the layer's staleness limit
    // and a cycle of slots (3 x 0.7 s) to take over.
    std::thread::sleep(Duration::from_secs(9).saturating_sub(started.elapsed()));
    wait_for_goer(
        clients,
        2,
        Duration::from_secs(1),
        "in the outage, the goer the radio agreed keeps the ball",
    );
    let sounded: Vec<i64> = clients
        .iter_mut()
        .map(|c| c.stat("audio.fallback_sounded"))
        .collect();
    assert!(
        sounded[0] == 0 && sounded[1..].iter().all(|&n| n >= 1),
        "the field players sound claims in the outage, the goalkeeper none: {sounded:?}"
    );
    // Robot 2 walks away from the ball: only sound can tell the team.
    assert_eq!(clients[1].ask("SETV local.var.robot.cost 6.0"), "OK");
    wait_for_goer(
        clients,
        3,
        Duration::from_secs(9),
        "in the outage, robot 2 let go by sound and robot 3 (cost 2) takes the ball",
    );
    assert!(
        started.elapsed() < Duration::from_secs(34),
        "the hand-over happened inside the outage ({:?} after the start)",
        started.elapsed()
    );
    // It holds: two more cycles, exactly one goer, everyone agreeing.
    for _ in 0..10 {
        wait_for_goer(
            clients,
            3,
            Duration::from_millis(500),
            "the hand-over holds",
        );
        std::thread::sleep(Duration::from_millis(400));
    }
    for (i, c) in clients.iter_mut().enumerate() {
        let heard = c.stat("audio.fallback_heard");
        let busy = c.stat("audio.fallback_busy");
        assert!(heard >= 3, "robot {} heard {heard} claims", i + 1);
        assert_eq!(busy, 0, "robot {}: no slot was let go", i + 1);
    }
}

/// Scenario 2: only robot 2's sends fail (from 5 s after its start, for 30 s); it still
/// hears its teammates, and they are on the radio with each other. Its teammates take it
/// for gone after the staleness limit and their radio would hand the ball to robot 3,
/// while robot 2, hearing nothing against it, goes on: two goers for as long as it lasts
/// (measured before the change: 0 of 94 samples with one goer). Robot 2 sees that no
/// teammate echoes its frames any more and sounds its claim; its teammates count what it
/// sounds in place of its stale radio claim; all agree robot 2 goes.
#[test]
fn a_robot_whose_own_sends_fail_is_heard_by_sound_and_the_team_keeps_one_goer() {
    // Only robot 2's radio fails; the others' outage never comes.
    let mut team = Team::start(|id| if id == 2 { "30s@5s" } else { "1s@1000s" });
    let (started, clients) = (team.started, &mut team.clients);
    wait_for_goer(
        clients,
        2,
        Duration::from_secs(4),
        "by radio, robot 2 (cost 1) goes",
    );
    // Robot 2's sends fail at 5 s: the staleness limit, UNHEARD_AFTER_S (1 s) and a
    // cycle of slots (2.1 s) later, robot 2's claim has been sounded and heard.
    std::thread::sleep(Duration::from_secs(10).saturating_sub(started.elapsed()));
    let (mut one, mut samples) = (0, 0);
    let mut seen = Vec::new();
    while started.elapsed() < Duration::from_secs(25) {
        let goers: Vec<String> = clients.iter_mut().map(goer).collect();
        let goings: Vec<bool> = clients.iter_mut().map(going).collect();
        samples += 1;
        if goings == [false, true, false, false] && goers.iter().all(|g| g == "2") {
            one += 1;
        } else if seen.len() < 5 {
            seen.push(format!(
                "{:.1} s: goers {goers:?}, going {goings:?}",
                started.elapsed().as_secs_f64()
            ));
        }
        std::thread::sleep(Duration::from_millis(200));
    }
    let sounded: Vec<i64> = clients
        .iter_mut()
        .map(|c| c.stat("audio.fallback_sounded"))
        .collect();
    assert!(
        sounded[1] >= 3,
        "robot 2, unheard by radio, sounds its claim: sounded {sounded:?}"
    );
    assert!(
        one * 10 >= samples * 9,
        "all agree robot 2 goes, and only it, in {one} of {samples} samples from 10 to 25 s; \
         sounded {sounded:?}; first others: {seen:?}"
    );
}
