//! The speaking thread: sounds queued messages one at a time through the output command.

use std::io::{self, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, SyncSender};
use std::sync::Arc;
use std::time::Duration;

use audio::{i16_to_s16le, Encoder, EncoderConfig, Message};
use comms::Instant;

use super::{Shared, BACKOFF_FIRST, BACKOFF_LAST};
use crate::state::Clock;

/// What the speaking thread needs.
pub(crate) struct SpeakConfig {
    pub(crate) command: String,
    pub(crate) encoder: EncoderConfig,
    pub(crate) gap: Duration,
    pub(crate) queue: usize,
}

/// Starts the thread; it ends (closing the command's input) once every sender is gone.
pub(crate) fn start(
    config: SpeakConfig,
    clock: Clock,
    shared: Arc<Shared>,
) -> io::Result<SyncSender<Message>> {
    let (tx, rx) = std::sync::mpsc::sync_channel(config.queue);
    std::thread::Builder::new()
        .name("audio-out".into())
        .spawn(move || run(&config, clock, &shared, &rx))?;
    Ok(tx)
}

/// The running output command.
struct Output {
    child: Child,
    stdin: ChildStdin,
    started: Instant,
}

fn run(config: &SpeakConfig, clock: Clock, shared: &Shared, queue: &Receiver<Message>) {
    let Ok(encoder) = Encoder::new(config.encoder.clone()) else {
        // Checked when audio started; cannot happen.
        return;
    };
    let rate = f64::from(config.encoder.sample_rate_hz);
    let gap = vec![0u8; 2 * (config.gap.as_secs_f64() * rate).round() as usize];
    let mut out: Option<Output> = None;
    let mut backoff = BACKOFF_FIRST;
    let mut no_start_before: Option<Instant> = None;
    for message in queue.iter() {
        if let Some(o) = &mut out {
            if let Ok(Some(status)) = o.child.try_wait() {
                tracing::warn!(command = %config.command, %status, "audio output command exited; restarting it");
                shared.count(|c| &c.out_failures);
                out = None;
            }
        }
        let written = match &mut out {
            Some(o) => Ok(o),
            None => {
                if let Some(at) = no_start_before {
                    wait_until(clock, at);
                }
                start_output(config, clock, shared, &gap).map(|o| out.insert(o))
            }
        }
        .and_then(|o| {
            let pcm = i16_to_s16le(&encoder.encode_i16(&message));
            o.stdin.write_all(&pcm)?;
            o.stdin.write_all(&gap)?;
            o.stdin.flush()
        });
        match written {
            Ok(()) => {
                tracing::debug!(%message, "audio said");
                shared.counters.said.fetch_add(1, Ordering::Relaxed);
            }
            Err(e) => {
                tracing::warn!(command = %config.command, error = %e, %message, "audio output failed; message lost");
                shared.counters.say_lost.fetch_add(1, Ordering::Relaxed);
                shared.counters.out_failures.fetch_add(1, Ordering::Relaxed);
                let now = clock.now();
                if let Some(mut o) = out.take() {
                    if now.saturating_duration_since(o.started) >= BACKOFF_LAST {
                        backoff = BACKOFF_FIRST;
                    }
                    let _ = o.child.kill();
                    let _ = o.child.wait();
                }
                no_start_before = Some(now + backoff);
                backoff = (backoff * 2).min(BACKOFF_LAST);
            }
        }
        shared.counters.say_pending.fetch_sub(1, Ordering::Relaxed);
        shared.changed.notify_one();
    }
    // Every sender is gone: end of input, the command plays what it has and exits.
    if let Some(Output {
        mut child, stdin, ..
    }) = out
    {
        drop(stdin);
        let _ = child.wait();
    }
}

/// Runs the output command and writes its lead-in silence.
fn start_output(
    config: &SpeakConfig,
    clock: Clock,
    shared: &Shared,
    gap: &[u8],
) -> io::Result<Output> {
    shared.count(|c| &c.out_starts);
    let mut child = Command::new("sh")
        .arg("-c")
        .arg(&config.command)
        .stdin(Stdio::piped())
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()?;
    let Some(mut stdin) = child.stdin.take() else {
        let _ = child.kill();
        let _ = child.wait();
        return Err(io::Error::other("no stdin pipe"));
    };
    if let Err(e) = stdin.write_all(gap) {
        let _ = child.kill();
        let _ = child.wait();
        return Err(e);
    }
    Ok(Output {
        child,
        stdin,
        started: clock.now(),
    })
}

/// Blocks this (non-runtime) thread until the driver's clock reaches `at`.
fn wait_until(clock: Clock, at: Instant) {
    loop {
        let now = clock.now();
        if now >= at {
            return;
        }
        std::thread::park_timeout(at.saturating_duration_since(now));
    }
}
