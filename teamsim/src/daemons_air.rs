//! `huddle sim --daemons --outage DURATION@START [--acoustic]`: the WLAN outage and the
//! acoustic fallback on real daemons. Each daemon gets the outage as a robot rehearses it
//! (`huddle daemon --outage`), and with `--acoustic` a loudspeaker and a microphone: its
//! `--audio-out` command writes into a FIFO the simulator reads, its `--audio-in` command
//! reads a FIFO the simulator writes, and between them runs the same room the in-process
//! match uses ([`Room`]: delay by distance, 1/r, the hall's reverberation, the crowd's
//! babble), at the robots' true positions, paced by the wall clock as a sound card is.
//! The daemons' team layers do the rest (`--audio-fallback`: slots on the team clock,
//! claims sounded and decoded): nothing of the fallback runs in the simulator.
//!
//! What the simulator cannot see here: which detections were right (the daemons decode),
//! so the acoustic line gives the daemons' own counters (claims sounded, heard, slots let
//! go), not the in-process channel's decoded and wrong counts; and the team clocks' spread
//! (the daemons do not publish their team clock).
//!
//! The WLAN fails for every robot at once: each daemon's `--outage` counts from its own
//! start, so each is told START plus the time from its start to an instant fixed before
//! the first was started ([`OUTAGE_LEAD`] ahead), and the match begins at that instant.
//! The figures are taken over the window in which every daemon is down, on the match's
//! clock (printed): a daemon's start (its driver's bind) comes up to [`START_LAG_S`]
//! after its process was started.

// A real-time loop over real processes and pipes: it reads the wall clock and sleeps.
#![allow(clippy::disallowed_methods)]

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use serde::Serialize;

use super::acoustic::{OutageConfig, OutageWindows, SAMPLE_RATE_HZ};
use super::acoustic_channel::Room;
use super::daemons::DaemonsError;
use super::SimConfig;

/// The room writes this many samples to each microphone at a time (20 ms, a sound
/// card's period).
const PERIOD: usize = 320;

/// How long after its process is started a daemon's driver binds, at most, s: its
/// `--outage` counts from then, so its window may begin this much later.
pub(super) const START_LAG_S: f64 = 0.2;

/// Under `--outage`, the match starts this long after the first daemon is started, so
/// that every daemon can be told when the outage begins on a common instant.
pub(super) const OUTAGE_LEAD: Duration = Duration::from_secs(3);

/// `O_NONBLOCK` on Linux (`libc` is not a dependency).
const O_NONBLOCK: i32 = 0o4000;

/// Whether the match's outage and acoustic settings are ones daemons take.
pub(super) fn check(cfg: &SimConfig) -> Result<(), DaemonsError> {
    let a = &cfg.acoustic;
    if !a.enabled {
        return Ok(());
    }
    let d = team::acoustic::AcousticConfig::default();
    if a.hysteresis_m != d.hysteresis_m
        || a.doubt_going != d.doubt_going
        || a.stale_cycles != d.stale_cycles
    {
        return Err(DaemonsError::Config(
            "--daemons runs the daemon's fallback, which takes only --acoustic-tone and \
             --acoustic-guard: drop --acoustic-hysteresis and --acoustic-no-doubt"
                .into(),
        ));
    }
    if cfg.robots > 16 {
        return Err(DaemonsError::Config(format!(
            "the acoustic room takes at most 16 robots, not {}",
            cfg.robots
        )));
    }
    Ok(())
}

/// A duration as the daemon's flags take it, in whole microseconds.
fn us(s: f64) -> String {
    format!("{}us", (s * 1e6).round() as u64)
}

/// Robot `id`'s daemon flags for the match's outage (the match starting `match_in` after
/// the daemon is started) and, with `--acoustic`, its loudspeaker and microphone (FIFOs in
/// `dir`, made by [`Air::start`]).
pub(super) fn daemon_args(cfg: &SimConfig, dir: &Path, id: u8, match_in: Duration) -> Vec<String> {
    let mut args = Vec::new();
    if let Some(o) = cfg.outage {
        args.push("--outage".into());
        let start_s = o.start_s + match_in.as_secs_f64();
        args.push(format!("{}@{}", us(o.duration_s), us(start_s)));
    }
    let a = &cfg.acoustic;
    if a.enabled {
        let (speaker, mic) = fifos(dir, id);
        args.extend([
            "--audio-in".into(),
            format!("cat '{}'", mic.display()),
            "--audio-out".into(),
            format!("cat > '{}'", speaker.display()),
            "--audio-tone".into(),
            us(a.tone_s),
            "--audio-fallback-guard".into(),
            us(a.guard_s),
            // Only the pause after a `say`: nothing says here but the fallback, whose
            // slots pace it; short, so the loudspeaker's first run starts nearly on time.
            "--audio-gap".into(),
            "20ms".into(),
            "--audio-heard".into(),
            "local.var.audio.heard".into(),
            "--audio-fallback".into(),
        ]);
    }
    args
}

fn fifos(dir: &Path, id: u8) -> (PathBuf, PathBuf) {
    (
        dir.join(format!("speaker-{id}")),
        dir.join(format!("microphone-{id}")),
    )
}

/// The window in which every daemon's radio is down, on the match's clock: the daemons
/// were told the outage starts `START` after `anchor`, and the match started at `started`
/// (at or after it).
pub(super) fn outage_window(
    cfg: &SimConfig,
    anchor: Instant,
    started: Instant,
) -> Option<OutageConfig> {
    let o = cfg.outage?;
    let late_s = started.saturating_duration_since(anchor).as_secs_f64();
    let start_s = o.start_s - late_s + START_LAG_S;
    Some(OutageConfig {
        start_s,
        duration_s: (o.duration_s - START_LAG_S).max(0.0),
    })
}

/// What the room counted.
#[derive(Debug, Clone, Default, Serialize)]
pub struct AirCounts {
    /// Seconds each robot's loudspeaker played sound (not silence).
    pub on_air_s: Vec<f64>,
    /// Periods the room wrote more than 100 ms behind the wall clock (the machine was
    /// busy; the microphones got them late, in a burst).
    pub late_periods: u64,
    /// Microphones whose daemon stopped reading.
    pub deaf: u64,
}

/// The room between the daemons: a thread streaming every loudspeaker into every
/// microphone.
pub(super) struct Air {
    positions: Arc<Mutex<Vec<(f64, f64)>>>,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<AirCounts>>,
    microphones: Vec<PathBuf>,
}

impl Air {
    /// Makes the FIFOs for robots `ids` in `dir` and starts the room (the match's
    /// acoustic settings, its crowd drawn from `seed`); robots stand at `positions`.
    pub(super) fn start(
        cfg: &SimConfig,
        dir: &Path,
        ids: &[u8],
        positions: Vec<(f64, f64)>,
    ) -> Result<Air, DaemonsError> {
        let room = Room::new(&cfg.acoustic, ids.len(), cfg.seed)
            .map_err(|e| DaemonsError::Config(e.to_string()))?;
        let (mut speakers, mut microphones) = (Vec::new(), Vec::new());
        for &id in ids {
            let (s, m) = fifos(dir, id);
            for p in [&s, &m] {
                let _ = std::fs::remove_file(p);
                let made =
                    Command::new("mkfifo")
                        .arg(p)
                        .status()
                        .map_err(|e| DaemonsError::Io {
                            what: "running mkfifo".into(),
                            source: e,
                        })?;
                if !made.success() {
                    return Err(DaemonsError::Config(format!(
                        "mkfifo {} failed ({made})",
                        p.display()
                    )));
                }
            }
            speakers.push(s);
            microphones.push(m);
        }
        let positions = Arc::new(Mutex::new(positions));
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let (positions, stop, mics) = (
                Arc::clone(&positions),
                Arc::clone(&stop),
                microphones.clone(),
            );
            std::thread::Builder::new()
                .name("acoustic-room".into())
                .spawn(move || play(room, &speakers, &mics, &positions, &stop))
                .map_err(|e| DaemonsError::Io {
                    what: "starting the acoustic room".into(),
                    source: e,
                })?
        };
        Ok(Air {
            positions,
            stop,
            thread: Some(thread),
            microphones,
        })
    }

    /// The robots' true positions now, m.
    pub(super) fn set_positions(&self, positions: Vec<(f64, f64)>) {
        *self.positions.lock().unwrap_or_else(|e| e.into_inner()) = positions;
    }

    /// Stops the room and returns its counts.
    pub(super) fn stop(mut self) -> AirCounts {
        self.halt().unwrap_or_default()
    }

    fn halt(&mut self) -> Option<AirCounts> {
        self.stop.store(true, Ordering::Relaxed);
        // The room may still wait to open a microphone whose daemon never read it: a
        // reader of our own lets that open return.
        let _readers: Vec<_> = self
            .microphones
            .iter()
            .filter_map(|m| {
                std::fs::OpenOptions::new()
                    .read(true)
                    .custom_flags(O_NONBLOCK)
                    .open(m)
                    .ok()
            })
            .collect();
        self.thread.take().and_then(|t| t.join().ok())
    }
}

impl Drop for Air {
    fn drop(&mut self) {
        let _ = self.halt();
    }
}

/// The room's loop: every period, what each loudspeaker wrote into the room at its
/// robot's position, and the room's signal at each robot out to its microphone.
fn play(
    mut room: Room,
    speakers: &[PathBuf],
    microphones: &[PathBuf],
    positions: &Mutex<Vec<(f64, f64)>>,
    stop: &AtomicBool,
) -> AirCounts {
    let n = speakers.len();
    let mut counts = AirCounts {
        on_air_s: vec![0.0; n],
        ..AirCounts::default()
    };
    // Non-blocking: a daemon starts its loudspeaker's command at its first claim.
    let mut outs: Vec<Option<std::fs::File>> = speakers
        .iter()
        .map(|p| {
            std::fs::OpenOptions::new()
                .read(true)
                .custom_flags(O_NONBLOCK)
                .open(p)
                .ok()
        })
        .collect();
    // Blocks until each daemon's input command has opened its microphone.
    let mut mics: Vec<Option<std::fs::File>> = Vec::with_capacity(n);
    for p in microphones {
        if stop.load(Ordering::Relaxed) {
            return counts;
        }
        mics.push(std::fs::OpenOptions::new().write(true).open(p).ok());
    }
    let mut queued: Vec<VecDeque<i16>> = vec![VecDeque::new(); n];
    let mut pcms: Vec<audio::S16leDecoder> = (0..n).map(|_| audio::S16leDecoder::new()).collect();
    let mut buf = vec![0u8; 1 << 16];
    let mut samples = Vec::new();
    let mut block = vec![0.0f32; PERIOD];
    let rate = f64::from(SAMPLE_RATE_HZ);
    let trace = super::daemons::trace();
    let mut was_sounding = vec![false; n];
    let mut held: Vec<Vec<(f64, f64)>> = vec![Vec::new(); n];
    let started = Instant::now();
    let mut written = 0u64;
    while !stop.load(Ordering::Relaxed) {
        for (i, out) in outs.iter_mut().enumerate() {
            let Some(f) = out else { continue };
            while let Ok(got) = f.read(&mut buf) {
                if got == 0 {
                    break;
                }
                samples.clear();
                pcms[i].push(&buf[..got], &mut samples);
                queued[i].extend(samples.iter().copied());
            }
        }
        let due = (started.elapsed().as_secs_f64() * rate) as u64;
        if due > written + (0.1 * rate) as u64 + PERIOD as u64 {
            counts.late_periods += 1;
        }
        while written + PERIOD as u64 <= due {
            let at: Vec<(f64, f64)> = positions.lock().unwrap_or_else(|e| e.into_inner()).clone();
            for (i, q) in queued.iter_mut().enumerate() {
                let mut sounding = false;
                for x in block.iter_mut() {
                    let s = q.pop_front().unwrap_or(0);
                    sounding |= s != 0;
                    *x = audio::i16_to_f32(s);
                }
                if sounding && !was_sounding[i] {
                    // Where everyone stands when a sound begins holds until it ends: a
                    // delay rounded anew each period would cut a click into the sound
                    // wherever it moved by a sample (robots move a few cm in a tone).
                    held[i].clone_from(&at);
                    if trace {
                        eprintln!("sounded speaker={} wall={:.3}", i + 1, wall_s());
                    }
                }
                was_sounding[i] = sounding;
                if sounding && held[i].len() == n {
                    room.sound(i, &block, &held[i]);
                    counts.on_air_s[i] += PERIOD as f64 / rate;
                }
            }
            room.play(PERIOD);
            for (j, mic) in mics.iter_mut().enumerate() {
                let Some(f) = mic else { continue };
                let bytes: Vec<u8> = room
                    .microphone(j)
                    .iter()
                    .flat_map(|&x| audio::f32_to_i16(x).to_le_bytes())
                    .collect();
                if f.write_all(&bytes).is_err() {
                    counts.deaf += 1;
                    *mic = None;
                }
            }
            written += PERIOD as u64;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    counts
}

/// The wall clock, s since the epoch, for lining up trace lines from several threads.
pub(super) fn wall_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// The outage's figures from real daemons: the arbitration over the window every
/// daemon's radio was down (and as long a window before it), and the daemons' own
/// counters of the fallback.
#[derive(Debug, Clone, Serialize)]
pub struct DaemonsOutage {
    /// The window and the arbitration in it.
    #[serde(flatten)]
    pub windows: OutageWindows,
    /// Claims the daemons sounded (`audio.fallback_sounded`, summed).
    pub acoustic_sounded: u64,
    /// Messages their decoders heard and handed to their layers (`audio.fallback_heard`,
    /// summed; each robot's microphone hears its own claims too).
    pub acoustic_heard: u64,
    /// Slots let go because a `say` was pending (`audio.fallback_busy`).
    pub acoustic_busy: u64,
    /// Messages their decoders heard in all (`audio.heard`).
    pub audio_heard: u64,
    /// Datagrams the outage dropped (`io.impair_dropped`, summed).
    pub radio_dropped: u64,
    /// The room's counts (absent without `--acoustic`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub air: Option<AirCounts>,
}

impl std::fmt::Display for DaemonsOutage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "{}", self.windows)?;
        write!(
            f,
            "  radio               {:>9} datagrams dropped by the daemons' --outage (the window is the one every daemon was down in)",
            self.radio_dropped
        )?;
        if let Some(air) = &self.air {
            let robots = air.on_air_s.len() as u64;
            let on_air: Vec<String> = air.on_air_s.iter().map(|s| format!("{s:.1}")).collect();
            write!(
                f,
                "\n  acoustic            {:>9} claims sounded, heard {} times of {} (each claim at every microphone, its sender's too), {} slots let go; on air [{}] s; room late {} periods, deaf microphones {}",
                self.acoustic_sounded,
                self.acoustic_heard,
                self.acoustic_sounded * robots,
                self.acoustic_busy,
                on_air.join(", "),
                air.late_periods,
                air.deaf
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_window_is_the_one_every_daemon_is_down_in_on_the_match_clock() {
        // Every daemon told `--outage 30s@60s` from the anchor; the match started 0.3 s
        // after the anchor (the daemons were slow to start).
        let cfg = SimConfig {
            outage: Some(OutageConfig {
                start_s: 60.0,
                duration_s: 30.0,
            }),
            ..SimConfig::default()
        };
        let anchor = Instant::now();
        let started = anchor + Duration::from_millis(300);
        let w = outage_window(&cfg, anchor, started).expect("an outage");
        assert!(
            (w.start_s - (59.7 + START_LAG_S)).abs() < 1e-9
                && (w.start_s + w.duration_s - 89.7).abs() < 1e-9,
            "window {w:?}"
        );
        let none = SimConfig {
            outage: None,
            ..cfg
        };
        assert!(outage_window(&none, anchor, started).is_none());
    }

    #[test]
    fn each_daemon_gets_the_outage_and_its_own_loudspeaker_and_microphone() {
        let mut cfg = SimConfig {
            outage: Some(OutageConfig {
                start_s: 60.0,
                duration_s: 30.0,
            }),
            ..SimConfig::default()
        };
        let dir = Path::new("/tmp/room");
        let lead = Duration::from_millis(2500);
        assert_eq!(
            daemon_args(&cfg, dir, 3, lead),
            vec!["--outage", "30000000us@62500000us"],
            "the outage from the daemon's start, the match 2.5 s later; no room without --acoustic"
        );
        cfg.acoustic.enabled = true;
        let args = daemon_args(&cfg, dir, 3, lead).join(" ");
        for want in [
            "--audio-in cat '/tmp/room/microphone-3'",
            "--audio-out cat > '/tmp/room/speaker-3'",
            "--audio-tone 400000us",
            "--audio-fallback-guard 300000us",
            "--audio-fallback",
        ] {
            assert!(args.contains(want), "{want:?} in {args}");
        }
        assert!(check(&cfg).is_ok());
        cfg.acoustic.hysteresis_m = Some(0.1);
        assert!(
            check(&cfg).is_err(),
            "a setting the daemon cannot take is refused"
        );
    }
}
