//! The listening thread: runs the input command, decodes its PCM, hands messages over.

use std::io::{self, Read};
use std::process::{Command, Stdio};
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, Sender, TryRecvError};
use std::sync::Arc;

use audio::{Decoder, DecoderConfig, S16leDecoder};

use super::{pause, ChildSlot, Heard, Restart, Shared, StreamClock, BACKOFF_FIRST, BACKOFF_LAST};
use crate::state::Clock;

/// What the listening thread needs.
pub(crate) struct ListenConfig {
    pub(crate) command: String,
    pub(crate) decoder: DecoderConfig,
    pub(crate) restart: Restart,
}

/// The running listener: stop it to kill its command and end its thread.
pub(crate) struct Listener {
    stop: Option<Sender<()>>,
    child: ChildSlot,
}

impl Listener {
    pub(crate) fn start(
        config: ListenConfig,
        clock: Clock,
        shared: Arc<Shared>,
        heard: tokio::sync::mpsc::Sender<Heard>,
    ) -> io::Result<Listener> {
        let (stop_tx, stop_rx) = std::sync::mpsc::channel();
        let child = ChildSlot::default();
        let slot = child.clone();
        std::thread::Builder::new()
            .name("audio-in".into())
            .spawn(move || {
                let thread = Thread {
                    config,
                    clock,
                    shared,
                    heard,
                    stop: stop_rx,
                    child: slot,
                };
                thread.run();
            })?;
        Ok(Listener {
            stop: Some(stop_tx),
            child,
        })
    }

    /// Ends the thread: a pause returns at once, a blocking read sees the end of input.
    pub(crate) fn stop(&mut self) {
        self.stop.take();
        if let Some(child) = lock(&self.child).as_mut() {
            let _ = child.kill();
        }
    }
}

fn lock(slot: &ChildSlot) -> std::sync::MutexGuard<'_, Option<std::process::Child>> {
    slot.lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// How one run of the command ended.
enum RunEnd {
    /// Stop asked, or nobody listens any more.
    Stopped,
    /// The command ended; `success`: status 0 and its output read to the end.
    Ended { success: bool },
}

struct Thread {
    config: ListenConfig,
    clock: Clock,
    shared: Arc<Shared>,
    heard: tokio::sync::mpsc::Sender<Heard>,
    stop: Receiver<()>,
    child: ChildSlot,
}

impl Thread {
    fn stopping(&self) -> bool {
        matches!(
            self.stop.try_recv(),
            Err(TryRecvError::Disconnected) | Ok(())
        )
    }

    fn run(self) {
        let mut backoff = BACKOFF_FIRST;
        loop {
            if self.stopping() {
                return;
            }
            self.shared.count(|c| &c.in_starts);
            let started = self.clock.now();
            let success = match self.one_run() {
                RunEnd::Stopped => return,
                RunEnd::Ended { success } => success,
            };
            if !success {
                self.shared.count(|c| &c.in_failures);
            }
            let again = match self.config.restart {
                Restart::OnFailure => !success,
                Restart::Always => true,
                Restart::Never => false,
            };
            if !again {
                tracing::info!(
                    command = %self.config.command,
                    success,
                    "audio input ended; not restarted (restart policy)"
                );
                return;
            }
            if self.clock.now().saturating_duration_since(started) >= BACKOFF_LAST {
                backoff = BACKOFF_FIRST;
            }
            tracing::warn!(
                command = %self.config.command,
                success,
                "audio input ended; restarting in {backoff:?}"
            );
            if pause(&self.stop, backoff) {
                return;
            }
            backoff = (backoff * 2).min(BACKOFF_LAST);
        }
    }

    /// Runs the command once, decoding its output to the end.
    fn one_run(&self) -> RunEnd {
        let spawned = Command::new("sh")
            .arg("-c")
            .arg(&self.config.command)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn();
        let mut child = match spawned {
            Ok(child) => child,
            Err(e) => {
                tracing::warn!(command = %self.config.command, error = %e, "cannot run the audio input command");
                return RunEnd::Ended { success: false };
            }
        };
        let Some(mut stdout) = child.stdout.take() else {
            let _ = child.kill();
            let _ = child.wait();
            return RunEnd::Ended { success: false };
        };
        *lock(&self.child) = Some(child);
        if self.stopping() {
            // `Listener::stop` may have looked before the child was in its slot.
            if let Some(mut child) = lock(&self.child).take() {
                let _ = child.kill();
                let _ = child.wait();
            }
            return RunEnd::Stopped;
        }
        let Ok(mut decoder) = Decoder::new(self.config.decoder.clone()) else {
            // Checked when audio started; cannot happen.
            return RunEnd::Stopped;
        };
        let rate = f64::from(self.config.decoder.sample_rate_hz);
        // The byte counter is mirrored about once a second of audio, not per read.
        let bytes_per_notice = 2 * u64::from(self.config.decoder.sample_rate_hz);
        let mut unnoticed = 0u64;
        let mut pcm = S16leDecoder::new();
        let mut bytes = vec![0u8; 4096];
        let mut samples = Vec::with_capacity(bytes.len() / 2 + 1);
        let mut stream_clock = StreamClock::default();
        let mut read_ok = true;
        let mut receiver_gone = false;
        loop {
            let n = match stdout.read(&mut bytes) {
                Ok(0) => break,
                Ok(n) => n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => {
                    tracing::warn!(error = %e, "reading the audio input failed");
                    read_ok = false;
                    break;
                }
            };
            let read_at = self.clock.now();
            self.shared
                .counters
                .in_bytes
                .fetch_add(n as u64, Ordering::Relaxed);
            unnoticed += n as u64;
            if unnoticed >= bytes_per_notice {
                unnoticed = 0;
                self.shared.changed.notify_one();
            }
            samples.clear();
            pcm.push(&bytes[..n], &mut samples);
            decoder.push_i16(&samples);
            stream_clock.read(read_at, decoder.samples_pushed() as f64 / rate);
            if !self.hand_over(&mut decoder, &stream_clock) {
                receiver_gone = true;
                break;
            }
        }
        drop(stdout);
        if !receiver_gone {
            // A stream that ends right after a message still reports it.
            decoder.finish();
            receiver_gone = !self.hand_over(&mut decoder, &stream_clock);
        }
        if pcm.has_pending_byte() {
            tracing::debug!("audio input ended in the middle of a sample (odd byte count)");
            self.shared.count(|c| &c.in_cut_samples);
        }
        self.shared.changed.notify_one();
        let status = lock(&self.child).take().map(|mut child| {
            if receiver_gone {
                let _ = child.kill();
            }
            child.wait()
        });
        if receiver_gone || self.stopping() {
            return RunEnd::Stopped;
        }
        let success = match status {
            Some(Ok(status)) if status.success() => read_ok,
            Some(Ok(status)) => {
                tracing::warn!(command = %self.config.command, %status, "audio input command failed");
                false
            }
            Some(Err(e)) => {
                tracing::warn!(error = %e, "cannot wait for the audio input command");
                false
            }
            None => false,
        };
        RunEnd::Ended { success }
    }

    /// Hands every decided message to the driver's thread; false if it is gone.
    fn hand_over(&self, decoder: &mut Decoder, clock: &StreamClock) -> bool {
        while let Some(refused) = decoder.poll_refused() {
            tracing::info!(
                message = %refused.message,
                plan = %self.config.decoder.team,
                "audio heard a message the team plan cannot have sent; dropped"
            );
            self.shared.count(|c| &c.refused);
        }
        while let Some(detection) = decoder.poll_message() {
            let heard = Heard {
                start: clock.at(detection.start_s),
                detection,
            };
            if self.heard.blocking_send(heard).is_err() {
                return false;
            }
        }
        true
    }
}
