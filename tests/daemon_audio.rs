//! The daemon speaks and listens through raw s16le PCM pipes, on loopback only: messages
//! encoded here and played into `--audio-in` appear on the blackboard once each, in
//! order, with their sender and data; `say` through the relay writes PCM to `--audio-out`
//! that decodes to the messages said, in order; garbage, an odd byte count, commands
//! that fail or stop reading never stop the daemon serving its relay, and are counted.
//! No assertion depends on timing: every wait polls with a generous deadline.

#![allow(clippy::disallowed_methods)] // real daemons over loopback, real time

mod daemon_support;

use std::io::Write;
use std::path::Path;
use std::time::{Duration, Instant};

use audio::{
    i16_to_s16le, write_wav_i16, Decoder, DecoderConfig, Encoder, EncoderConfig, Message,
    S16leDecoder, Sender,
};
use daemon_support::{Client, Daemon};

const RATE: u32 = 16_000;
/// Long enough for any wait below on a loaded machine; never a pass/fail threshold.
const PATIENCE: Duration = Duration::from_secs(30);

fn encoder(tone_s: f64) -> Encoder {
    Encoder::new(EncoderConfig {
        sample_rate_hz: RATE,
        tone_duration_s: tone_s,
        fade_s: (tone_s / 20.0).min(0.01),
        ..EncoderConfig::default()
    })
    .expect("a valid encoder")
}

fn silence(seconds: f64) -> Vec<i16> {
    vec![0; (seconds * f64::from(RATE)) as usize]
}

fn start(id: u8, extra: &[&str], dir: &Path) -> Daemon {
    let group = daemon_support::scratch_group().to_string();
    let relay_port = daemon_support::free_tcp_port();
    Daemon::start(id, &group, relay_port, extra, dir)
}

/// The `name=value` words of a heard value (`VAL`/`UPD` line), by name.
fn heard_fields(line: &str) -> std::collections::BTreeMap<String, String> {
    let binding = comms::relay::Binding::parse(line)
        .unwrap_or_else(|| panic!("not a binding line: {line:?}"));
    assert_eq!(binding.ty, "string", "heard values are strings: {line:?}");
    binding
        .value
        .trim_matches('"')
        .split_whitespace()
        .filter_map(|w| w.split_once('='))
        .map(|(k, v)| (k.to_owned(), v.to_owned()))
        .collect()
}

/// The `kind`, `sender` and `data` words of a heard value line (empty when missing).
fn kind_sender_data(line: &str) -> [String; 3] {
    let fields = heard_fields(line);
    ["kind", "sender", "data"].map(|name| fields.get(name).cloned().unwrap_or_default())
}

/// Reads lines until one starts with `prefix` (other pushes are skipped), or panics.
fn next_line_starting(c: &mut Client, prefix: &str) -> String {
    let deadline = Instant::now() + PATIENCE;
    c.reader.get_ref().set_read_timeout(Some(PATIENCE)).unwrap();
    loop {
        let line = c.line();
        if line.starts_with(prefix) {
            return line;
        }
        assert!(Instant::now() < deadline, "no {prefix:?} line in time");
    }
}

/// Polls a counter until `ok`, or panics with its last value.
fn wait_stat(c: &mut Client, name: &str, ok: impl Fn(i64) -> bool) -> i64 {
    let deadline = Instant::now() + PATIENCE;
    loop {
        let v = c.stat(name);
        if ok(v) {
            return v;
        }
        assert!(Instant::now() < deadline, "audio counter {name} still {v}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Robot 3 listens on a FIFO the test writes into as a microphone would: a long
/// message, then a short one. A watching client gets each as one update, in order,
/// with the sender and data played and its start time; closing the FIFO ends
/// the stream (status 0), which is not restarted.
#[test]
fn messages_played_into_audio_in_appear_on_the_blackboard_once_each_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("mic.fifo");
    daemon_support::mkfifo(&fifo);
    let input = format!("cat '{}'", fifo.display());
    let daemon = start(3, &["--audio-in", &input], dir.path());
    let mut c = daemon.client();
    assert_eq!(c.ask("ADDW 3.var.audio.#"), "OK");
    assert_eq!(c.ask("REFR 0"), "OK");

    let enc = encoder(1.0);
    let first = Message::long(Sender::LeftAttacker, 300).unwrap();
    let second = Message::short(Sender::Goalkeeper, 4).unwrap();
    // Opening blocks until the daemon's `cat` opens its end.
    let mut mic = std::fs::OpenOptions::new()
        .write(true)
        .open(&fifo)
        .expect("open the FIFO for writing");
    let mut heard = Vec::new();
    let mut written = 0usize;
    for message in [first, second] {
        let mut pcm = silence(0.5);
        pcm.extend(enc.encode_i16(&message));
        pcm.extend(silence(1.5));
        mic.write_all(&i16_to_s16le(&pcm)).expect("write PCM");
        written += 2 * pcm.len();
        // Each message is decided from the audio after it, before the next is played.
        let line = next_line_starting(&mut c, "UPD 3.var.audio.heard ");
        heard.push(heard_fields(&line));
    }
    drop(mic);
    for (i, (fields, message)) in heard.iter().zip([first, second]).enumerate() {
        let want = [
            ("seq", (i + 1).to_string()),
            ("kind", message.kind().to_owned()),
            ("sender", message.sender().index().to_string()),
            ("data", message.value().to_string()),
        ];
        for (name, value) in want {
            assert_eq!(
                fields.get(name),
                Some(&value),
                "message {i} ({message}): {name} in {fields:?}"
            );
        }
    }
    for fields in &heard {
        let start: Result<u64, _> = fields["start_us"].parse();
        assert!(
            start.is_ok(),
            "start_us is µs on the daemon's clock: {fields:?}"
        );
    }

    let mut stats = daemon.client();
    wait_stat(&mut stats, "audio.heard", |n| n == 2);
    wait_stat(&mut stats, "audio.in_bytes", |n| n == written as i64);
    assert_eq!(
        stats.stat("audio.in_starts"),
        1,
        "status 0 is not restarted"
    );
    assert_eq!(stats.stat("audio.in_failures"), 0, "cat ended cleanly");
    assert_eq!(stats.stat("audio.in_cut_samples"), 0);
}

/// A WAV file (with its 44-byte header, which is only 22 samples of noise to the
/// decoder) played once with `cat`: the message is on the blackboard as the team sees
/// it (`*.var.audio.heard` resolves to robot 5's copy), the command is not restarted.
#[test]
fn a_wav_file_through_audio_in_is_heard() {
    let dir = tempfile::tempdir().unwrap();
    let wav = dir.path().join("msg.wav");
    let message = Message::short(Sender::RightAttacker, 17).unwrap();
    let mut pcm = silence(0.5);
    pcm.extend(encoder(1.0).encode_i16(&message));
    pcm.extend(silence(0.5));
    write_wav_i16(std::fs::File::create(&wav).unwrap(), RATE, &pcm).expect("write WAV");
    let input = format!("cat '{}'", wav.display());
    let daemon = start(5, &["--audio-in", &input], dir.path());
    let mut c = daemon.client();
    let line = c.wait_for("*.var.audio.heard", PATIENCE, |a| a.starts_with("VAL"));
    assert!(
        line.starts_with("VAL 5.var.audio.heard string "),
        "robot 5 owns it: {line}"
    );
    assert_eq!(kind_sender_data(&line), ["short", "2", "17"], "{line}");
    wait_stat(&mut c, "audio.heard", |n| n == 1);
    assert_eq!(c.stat("audio.in_starts"), 1);
}

/// Every sample of a file written by `cat`, once its size reaches `bytes`.
fn read_pcm(path: &Path, bytes: u64) -> Vec<i16> {
    let deadline = Instant::now() + PATIENCE;
    loop {
        let len = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
        if len >= bytes {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "{} has {len} of {bytes} bytes",
            path.display()
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let raw = std::fs::read(path).unwrap();
    assert_eq!(raw.len() as u64, bytes, "exactly the PCM said");
    let mut samples = Vec::new();
    S16leDecoder::new().push(&raw, &mut samples);
    samples
}

fn decode(samples: &[i16], tone_s: f64) -> Vec<Message> {
    let mut d = Decoder::new(DecoderConfig {
        sample_rate_hz: RATE,
        tone_duration_s: tone_s,
        ..DecoderConfig::default()
    })
    .unwrap();
    let mut heard = Vec::new();
    for block in samples.chunks(1000) {
        d.push_i16(block);
        heard.extend(std::iter::from_fn(|| d.poll_message()).map(|m| m.message));
    }
    d.finish();
    heard.extend(std::iter::from_fn(|| d.poll_message()).map(|m| m.message));
    heard
}

/// Robot 4 says two messages through `cat > said.raw`; invalid ones get `ERR 412` and
/// nothing is queued. The file holds lead-in gap, message, gap, message, gap, exactly,
/// and decodes to the two messages in the order said.
#[test]
fn say_writes_pcm_that_decodes_to_the_messages_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("said.raw");
    let output = format!("cat > '{}'", out.display());
    let daemon = start(4, &["--audio-out", &output], dir.path());
    let mut c = daemon.client();
    for bad in [
        "SETV local.var.audio.say \"short 1 21\"",
        "SETV local.var.audio.say \"long 1 441\"",
        "SETV local.var.audio.say \"short 3 1\"",
        "SETV local.var.audio.say \"hello\"",
        "SETV local.var.audio.say 7",
    ] {
        let answer = c.ask(bad);
        assert!(answer.starts_with("ERR 412 "), "{bad} -> {answer}");
    }
    assert!(
        c.ask("GETV local.var.audio.say").starts_with("ERR 404"),
        "a refused say is not written"
    );
    assert_eq!(c.ask("SETV local.var.audio.say \"long 2 300\""), "OK");
    // The heard form is accepted too, so a heard message can be said again.
    assert_eq!(
        c.ask("SETV local.var.audio.say \"seq=7 kind=short sender=0 data=4 start_us=1\""),
        "OK"
    );
    wait_stat(&mut c, "audio.said", |n| n == 2);
    assert_eq!(c.stat("audio.say_invalid"), 5);
    assert_eq!(c.stat("audio.say_accepted"), 2);
    wait_stat(&mut c, "audio.say_pending", |n| n == 0);

    // 1 s frames and gaps (the defaults) at 16 kHz: gap, long (2 frames), gap, short, gap.
    let seconds = 1 + 2 + 1 + 1 + 1;
    let samples = read_pcm(&out, seconds * u64::from(RATE) * 2);
    let said = decode(&samples, 1.0);
    assert_eq!(
        said,
        vec![
            Message::long(Sender::RightAttacker, 300).unwrap(),
            Message::short(Sender::Goalkeeper, 4).unwrap()
        ],
        "the PCM written decodes to the messages said, in order"
    );
}

/// An output command that never reads: the first message blocks in the pipe, two more
/// wait in the queue (`--audio-queue 2`), and the next say is refused with `ERR 430`;
/// the relay keeps answering. (The accepted count is 2 or 3: the speaking thread may
/// not have taken the first message off the queue yet.)
#[test]
fn a_full_say_queue_is_refused_and_the_relay_keeps_serving() {
    let dir = tempfile::tempdir().unwrap();
    let daemon = start(
        6,
        // `sleep` never reads its stdin; it is gone 20 s after the test.
        &["--audio-out", "sleep 20", "--audio-queue", "2"],
        dir.path(),
    );
    let mut c = daemon.client();
    let mut accepted = 0;
    let refused = loop {
        let answer = c.ask("SETV local.var.audio.say \"short 1 7\"");
        if answer != "OK" {
            break answer;
        }
        accepted += 1;
        assert!(accepted <= 3, "a queue of 2 took {accepted} messages");
    };
    assert!(refused.starts_with("ERR 430 "), "{refused}");
    assert!((2..=3).contains(&accepted), "accepted {accepted}");
    assert_eq!(c.ask("SETV *.var.still \"here\""), "OK");
    wait_stat(&mut c, "audio.say_full", |n| n == 1);
}

/// An output command that stops reading after 1000 bytes: the message being written is
/// lost and counted, and the command runs again (after its backoff) for the next one.
#[test]
fn a_broken_output_pipe_loses_one_message_and_the_command_restarts() {
    let dir = tempfile::tempdir().unwrap();
    let daemon = start(7, &["--audio-out", "head -c 1000 > /dev/null"], dir.path());
    let mut c = daemon.client();
    assert_eq!(c.ask("SETV local.var.audio.say \"short 1 7\""), "OK");
    wait_stat(&mut c, "audio.say_lost", |n| n == 1);
    assert_eq!(c.ask("SETV local.var.audio.say \"short 1 8\""), "OK");
    wait_stat(&mut c, "audio.out_starts", |n| n == 2);
    wait_stat(&mut c, "audio.say_lost", |n| n == 2);
    assert_eq!(c.stat("audio.said"), 0);
    assert!(c.stat("audio.out_failures") >= 2);
    assert!(c
        .ask("GETV local.var.huddle.stats.frames_out")
        .starts_with("VAL"));
}

/// Garbage in: seeded random bytes with an odd count (played once), then a command that
/// fails at once (restarted with backoff, each failure counted). Nothing is heard, the
/// cut sample is counted, and the daemon keeps serving its relay throughout.
#[test]
fn garbage_pcm_and_failing_commands_never_stop_the_daemon() {
    use rand::{RngExt as _, SeedableRng as _};
    let dir = tempfile::tempdir().unwrap();
    let noise = dir.path().join("noise.raw");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let bytes: Vec<u8> = (0..100_001).map(|_| rng.random()).collect();
    std::fs::write(&noise, &bytes).unwrap();
    let input = format!("cat '{}'", noise.display());
    let daemon = start(8, &["--audio-in", &input], dir.path());
    let mut c = daemon.client();
    wait_stat(&mut c, "audio.in_bytes", |n| n == 100_001);
    wait_stat(&mut c, "audio.in_cut_samples", |n| n == 1);
    assert_eq!(c.stat("audio.heard"), 0, "noise is no message");
    assert!(c.ask("GETV *.var.audio.heard").starts_with("ERR 404"));
    assert_eq!(c.ask("SETV *.var.still \"here\""), "OK");

    let failing = start(9, &["--audio-in", "exit 3"], dir.path());
    let mut c = failing.client();
    wait_stat(&mut c, "audio.in_starts", |n| n >= 2);
    wait_stat(&mut c, "audio.in_failures", |n| n >= 2);
    // No `--audio-out`: saying is refused plainly, not silently dropped.
    let answer = c.ask("SETV local.var.audio.say \"short 1 7\"");
    assert!(answer.starts_with("ERR 503 "), "{answer}");
    assert_eq!(c.ask("SETV *.var.still \"here\""), "OK");
}

/// A team on the checked plan (`--audio-team checked`). Robot 8 says `long 2 57` and
/// `short 1 9` in the plan's terms (a value the plan does not have is `ERR 412`, with
/// the plan's ranges); robot 9, listening to exactly the PCM robot 8 wrote, writes both
/// with the plan's robot and value. Then the long message is cut after its first frame,
/// as a hall's echo or a second robot sounding over it would: under the seed's plan
/// robot 10 hears that frame alone as the short message "sender 2 data 15", a message
/// nobody sent; under the checked plan robot 11 writes nothing and counts the drop.
#[test]
fn under_the_checked_plan_a_long_message_cut_to_one_frame_is_never_heard_as_a_short_one() {
    let dir = tempfile::tempdir().unwrap();
    let said_path = dir.path().join("said.raw");
    let output = format!("cat > '{}'", said_path.display());
    let speaker = start(
        8,
        &["--audio-out", &output, "--audio-team", "checked"],
        dir.path(),
    );
    let mut c = speaker.client();
    let refused = c.ask("SETV local.var.audio.say \"short 1 10\"");
    assert!(
        refused.starts_with("ERR 412 ") && refused.contains("0..=9"),
        "a checked short says 0 … 9: {refused}"
    );
    assert_eq!(c.ask("SETV local.var.audio.say \"long 2 57\""), "OK");
    assert_eq!(
        c.ask("SETV local.var.audio.say \"short left-attacker 9\""),
        "OK"
    );
    wait_stat(&mut c, "audio.said", |n| n == 2);
    // Gap, long (2 frames), gap, short, gap: 1 s each at the defaults.
    let said = read_pcm(&said_path, 6 * u64::from(RATE) * 2);
    drop(speaker);

    // Robot 9's microphone is a FIFO, written once it watches, so no update is missed.
    let fifo = dir.path().join("mic.fifo");
    daemon_support::mkfifo(&fifo);
    let input = format!("cat '{}'", fifo.display());
    let listener = start(
        9,
        &["--audio-in", &input, "--audio-team", "checked"],
        dir.path(),
    );
    let mut c = listener.client();
    assert_eq!(c.ask("ADDW 9.var.audio.#"), "OK");
    assert_eq!(c.ask("REFR 0"), "OK");
    let mut mic = std::fs::OpenOptions::new()
        .write(true)
        .open(&fifo)
        .expect("open the FIFO for writing");
    mic.write_all(&i16_to_s16le(&said)).expect("write PCM");
    drop(mic);
    for (robot, kind, value) in [("2", "long", "57"), ("1", "short", "9")] {
        let line = next_line_starting(&mut c, "UPD 9.var.audio.heard ");
        let fields = heard_fields(&line);
        let got = [
            fields.get("plan").map(String::as_str),
            fields.get("robot").map(String::as_str),
            fields.get("kind").map(String::as_str),
            fields.get("value").map(String::as_str),
        ];
        assert_eq!(
            got,
            [Some("checked"), Some(robot), Some(kind), Some(value)],
            "{line}"
        );
    }

    // The long message's first frame, and the silence a lost second frame leaves.
    let frame = RATE as usize; // 1 s frames
    let long_start = frame; // after the lead-in gap
    let mut cut = silence(0.5);
    cut.extend_from_slice(&said[long_start..long_start + frame]);
    cut.extend(silence(2.5));
    let cut_path = dir.path().join("cut.raw");
    std::fs::write(&cut_path, i16_to_s16le(&cut)).unwrap();
    let input = format!("cat '{}'", cut_path.display());

    let seed_plan = start(10, &["--audio-in", &input], dir.path());
    let mut c = seed_plan.client();
    let line = c.wait_for("10.var.audio.heard", PATIENCE, |a| a.starts_with("VAL"));
    assert_eq!(
        kind_sender_data(&line),
        ["short", "2", "15"],
        "under the seed's plan the first frame alone is a (wrong) short message: {line}"
    );

    let checked = start(
        11,
        &["--audio-in", &input, "--audio-team", "checked"],
        dir.path(),
    );
    let mut c = checked.client();
    wait_stat(&mut c, "audio.refused", |n| n == 1);
    assert_eq!(
        c.stat("audio.heard"),
        0,
        "nothing written under the checked plan"
    );
    assert!(
        c.ask("GETV 11.var.audio.heard").starts_with("ERR 404"),
        "no heard value at all"
    );
}
