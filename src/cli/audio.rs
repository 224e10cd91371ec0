//! `huddle audio`: encode messages to WAV or raw PCM, decode WAV files, listen on stdin,
//! and measure the codec's robustness (`eval`).
//!
//! Raw PCM is 16-bit little-endian mono (`aplay -f S16_LE -r 16000`,
//! `arecord -f S16_LE -r 16000 -c 1`).

use std::fs::File;
use std::io::{BufWriter, Read, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use audio::channel::{power, white_sigma_for_in_band_snr, Source, WhiteNoise};
use audio::evaluation::{
    es_n0_db, run_background_false_alarm_trial, run_false_alarm_trial, run_room_false_alarm_trial,
    run_room_trial, run_snr_trial_team, run_whistle_over_messages, Background, Interference,
    RoomNoise, RoomTrial, SnrOutcome, SnrTrial,
};
use audio::evaluation::{
    load_room_set, run_scene_false_alarm_trial, run_scene_trial, ExternalRoom, SceneOutcome,
    SceneTrial,
};
use audio::{
    i16_to_s16le, read_wav, write_wav_f32, write_wav_i16, Decoder, DecoderConfig, Detection,
    Encoder, EncoderConfig, Message, S16leDecoder, Sender, TeamMessage, TeamPlan,
};
use clap::{Args, Subcommand, ValueEnum};

use super::duration;

/// Acoustic messaging: the 72-tone codec.
#[derive(Args, Debug)]
pub struct AudioArgs {
    #[command(subcommand)]
    command: AudioCommand,
}

#[derive(Subcommand, Debug)]
enum AudioCommand {
    /// Write a message as a WAV file (or raw s16le PCM to stdout when OUT is `-`).
    Encode {
        #[command(flatten)]
        message: MessageArgs,
        /// Output WAV file, or `-` for raw s16le on stdout.
        out: PathBuf,
        /// WAV sample format.
        #[arg(long, value_enum, default_value_t = SampleFormat::I16)]
        format: SampleFormat,
    },
    /// Write a message as raw s16le PCM to stdout (`… | aplay -f S16_LE -r 16000`).
    Send {
        #[command(flatten)]
        message: MessageArgs,
    },
    /// Decode a WAV file: one line per message.
    Decode {
        /// Input WAV (PCM or 32-bit float, any channel count, 8–192 kHz).
        input: PathBuf,
        /// One JSON object per line: {"t", "kind", "sender", "data"}.
        #[arg(long)]
        json: bool,
        /// Tone duration the senders use (`1s`, `250ms`).
        #[arg(long, default_value = "1s", value_parser = duration::parse_positive)]
        duration: Duration,
        /// Team plan the senders use (`three`: the seed's, `six`: up to six robots).
        #[arg(long, default_value_t = TeamPlan::Three)]
        team: TeamPlan,
    },
    /// Decode raw s16le mono PCM from stdin as it arrives (`arecord … | huddle audio listen`).
    Listen {
        /// Sample rate of the input, Hz.
        #[arg(long, default_value_t = 16_000)]
        rate: u32,
        /// Tone duration the senders use (`1s`, `250ms`).
        #[arg(long, default_value = "1s", value_parser = duration::parse_positive)]
        duration: Duration,
        /// One JSON object per line.
        #[arg(long)]
        json: bool,
        /// Team plan the senders use (`three`: the seed's, `six`: up to six robots).
        #[arg(long, default_value_t = TeamPlan::Three)]
        team: TeamPlan,
    },
    /// Robustness report: decode rates vs SNR, false messages per hour, whistle, speed,
    /// delay, shortest tone. Seeded and reproducible.
    Eval {
        /// How long each interference plays for the false-message rows (`6min`, `1s`).
        #[arg(long, default_value = "6min", value_parser = duration::parse_positive)]
        noise_time: Duration,
        /// Seed of every trial.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Messages per SNR row.
        #[arg(long, default_value_t = 1000)]
        messages: usize,
        /// Which tables to run.
        #[arg(long, value_enum, default_value_t = EvalSection::All)]
        section: EvalSection,
        /// Team plan of the messages sent and decoded (`three` or `six`).
        #[arg(long, default_value_t = TeamPlan::Three)]
        team: TeamPlan,
    },
    /// Room tests on a room set built by another tool (`audio/rooms/make_rooms.py`:
    /// pyroomacoustics image-source rooms, espeak-ng babble with its pauses): short
    /// messages over babble, long messages in halls, two robots overlapping, false
    /// messages in crowds. Wrong messages are counted on their own.
    Rooms {
        /// The room set's directory (holds `manifest.txt`).
        dir: PathBuf,
        /// Seed of messages, clocks, talkers (report seeds: 101 and up; see
        /// audio/rooms/README.md).
        #[arg(long, default_value_t = 101)]
        seed: u64,
        /// Messages per row.
        #[arg(long, default_value_t = 1000)]
        messages: usize,
        /// Crowd with no message, per room, for the false-message count (`10min`, `1h`).
        #[arg(long, default_value = "10min", value_parser = duration::parse_positive)]
        noise_time: Duration,
        /// Team plan the messages are drawn from (`checked`: long frames never read as a
        /// short; reports the plan cannot have sent are counted as refused, not wrong).
        #[arg(long, default_value_t = TeamPlan::Three)]
        team: TeamPlan,
        /// Rows run at once, each on its own thread (the table prints in row order; the
        /// figures do not depend on it, the `x real` column does).
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=64))]
        jobs: u16,
    },
    /// False messages in backgrounds that stop and start (nothing is sent): talkers who
    /// pause, a crowd that comes and goes, whistles, music-like tones, doors, and all of
    /// them at once, each falling to digital silence between spells, dry and in a hall.
    Backgrounds {
        /// Audio in all, split evenly over the 6 backgrounds × dry and hall (`600min`, `20min`).
        #[arg(long, default_value = "600min", value_parser = duration::parse_positive)]
        time: Duration,
        /// Seed of every background (report seeds: 101 and up).
        #[arg(long, default_value_t = 101)]
        seed: u64,
        /// Reverberation time of the hall rows, s.
        #[arg(long, default_value_t = 1.2)]
        t60: f64,
        /// Team plan the decoder is set to (`checked`: a first frame only a long message
        /// carries is decided on the sender's louder tone, and reported only with a second).
        #[arg(long, default_value_t = TeamPlan::Three)]
        team: TeamPlan,
        /// Rows run at once, each on its own thread.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u16).range(1..=64))]
        jobs: u16,
    },
}

#[derive(Args, Debug)]
struct MessageArgs {
    /// Sender: 0 goalkeeper, 1 left attacker, 2 right attacker (`--team six`: robot 0–5).
    #[arg(long)]
    sender: u8,
    /// Data value of a short message, 0–20 (`--team six`: 0–9).
    #[arg(long, conflicts_with = "long")]
    data: Option<u16>,
    /// Value of a long message, 0–440 (two frames: 21·first + second; `--team six`:
    /// 0–99, 10·first + second).
    #[arg(long)]
    long: Option<u16>,
    /// Team plan (`three`: the seed's 3 senders; `six`: up to 6 robots, fewer values).
    #[arg(long, default_value_t = TeamPlan::Three)]
    team: TeamPlan,
    /// Sample rate, Hz.
    #[arg(long, default_value_t = 16_000)]
    rate: u32,
    /// Tone duration (`1s`, `250ms`).
    #[arg(long, default_value = "1s", value_parser = duration::parse_positive)]
    duration: Duration,
}

/// Which part of `huddle audio eval` to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum EvalSection {
    /// Every table.
    All,
    /// The dry tables (white noise, long messages, short tones, false messages, speed).
    Dry,
    /// The reverberant-hall tables.
    Rooms,
    /// The decoder's speed against the length of the audio (1 min, 10 min, 100 min).
    Speed,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum SampleFormat {
    I16,
    F32,
}

impl MessageArgs {
    fn message(&self) -> Result<Message> {
        let (long, value) = match (self.data, self.long) {
            (Some(d), None) => (false, d),
            (None, Some(v)) => (true, v),
            _ => bail!("give either --data D (short) or --long VALUE (long)"),
        };
        Ok(self.team.encode(TeamMessage {
            robot: self.sender,
            long,
            value,
        })?)
    }

    fn encoder(&self) -> Result<Encoder> {
        Ok(Encoder::new(EncoderConfig {
            sample_rate_hz: self.rate,
            tone_duration_s: self.duration.as_secs_f64(),
            fade_s: (self.duration.as_secs_f64() / 20.0).min(0.01),
            ..EncoderConfig::default()
        })?)
    }
}

/// Runs `huddle audio …`.
pub fn run(args: AudioArgs) -> Result<()> {
    match args.command {
        AudioCommand::Encode {
            message,
            out,
            format,
        } => {
            let m = message.message()?;
            let enc = message.encoder()?;
            if out.as_os_str() == "-" {
                return send_raw(&enc, &m);
            }
            let file = BufWriter::new(
                File::create(&out).with_context(|| format!("creating {}", out.display()))?,
            );
            match format {
                SampleFormat::I16 => write_wav_i16(file, message.rate, &enc.encode_i16(&m))?,
                SampleFormat::F32 => write_wav_f32(file, message.rate, &enc.encode_f32(&m))?,
            }
            eprintln!("wrote {m} to {}", out.display());
            Ok(())
        }
        AudioCommand::Send { message } => send_raw(&message.encoder()?, &message.message()?),
        AudioCommand::Decode {
            input,
            json,
            duration,
            team,
        } => {
            let file =
                File::open(&input).with_context(|| format!("opening {}", input.display()))?;
            let rec = read_wav(std::io::BufReader::new(file))
                .with_context(|| format!("reading {}", input.display()))?;
            let mut d = Decoder::new(DecoderConfig {
                sample_rate_hz: rec.sample_rate_hz,
                tone_duration_s: duration.as_secs_f64(),
                team,
                ..DecoderConfig::default()
            })?;
            let mut out = std::io::stdout().lock();
            for block in rec.samples.chunks(4096) {
                d.push_f32(block);
                while let Some(m) = d.poll_message() {
                    print_detection(&mut out, &m, json, team)?;
                }
            }
            d.finish();
            while let Some(m) = d.poll_message() {
                print_detection(&mut out, &m, json, team)?;
            }
            Ok(())
        }
        AudioCommand::Listen {
            rate,
            duration,
            json,
            team,
        } => listen(rate, duration.as_secs_f64(), json, team),
        AudioCommand::Eval {
            noise_time,
            seed,
            messages,
            section,
            team,
        } => eval(
            noise_time.as_secs_f64() / 3600.0,
            seed,
            messages,
            section,
            team,
        ),
        AudioCommand::Rooms {
            dir,
            seed,
            messages,
            noise_time,
            team,
            jobs,
        } => rooms(
            &dir,
            seed,
            messages,
            noise_time.as_secs_f64(),
            team,
            usize::from(jobs),
        ),
        AudioCommand::Backgrounds {
            time,
            seed,
            t60,
            team,
            jobs,
        } => backgrounds(time.as_secs_f64(), seed, t60, team, usize::from(jobs)),
    }
}

fn send_raw(enc: &Encoder, m: &Message) -> Result<()> {
    let mut out = std::io::stdout().lock();
    out.write_all(&i16_to_s16le(&enc.encode_i16(m)))?;
    out.flush()?;
    Ok(())
}

/// One detection as a line. Under the seed's plan `sender` is the sender basic and `data`
/// the value; under `--team six` they are the robot (0–5) and its value, and the JSON
/// also carries `"team": "six"`.
fn print_detection(out: &mut impl Write, d: &Detection, json: bool, team: TeamPlan) -> Result<()> {
    // The decoder drops what its plan cannot have sent, so this always reads.
    let Some(tm) = d.team_message(team) else {
        return Ok(());
    };
    if json {
        let mut v = serde_json::json!({
            "t": (d.start_s * 1000.0).round() / 1000.0,
            "kind": d.message.kind(),
            "sender": tm.robot,
            "data": tm.value,
        });
        if team != TeamPlan::Three {
            v["team"] = serde_json::Value::from(team.name());
        }
        writeln!(out, "{v}")?;
    } else if team == TeamPlan::Three {
        writeln!(
            out,
            "{:9.3}s  {:5}  sender {} ({})  data {:3}",
            d.start_s,
            d.message.kind(),
            d.message.sender().index(),
            d.message.sender(),
            d.message.value()
        )?;
    } else {
        writeln!(
            out,
            "{:9.3}s  {:5}  robot {}  data {:3}",
            d.start_s,
            d.message.kind(),
            tm.robot,
            tm.value
        )?;
    }
    out.flush()?;
    Ok(())
}

fn listen(rate: u32, duration: f64, json: bool, team: TeamPlan) -> Result<()> {
    let mut d = Decoder::new(DecoderConfig {
        sample_rate_hz: rate,
        tone_duration_s: duration,
        team,
        ..DecoderConfig::default()
    })?;
    let mut stdin = std::io::stdin().lock();
    let mut out = std::io::stdout().lock();
    let mut pcm = S16leDecoder::new();
    let mut bytes = vec![0u8; 4096];
    let mut samples = Vec::with_capacity(2048);
    loop {
        let n = match stdin.read(&mut bytes) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e).context("reading stdin"),
        };
        samples.clear();
        pcm.push(&bytes[..n], &mut samples);
        d.push_i16(&samples);
        while let Some(m) = d.poll_message() {
            print_detection(&mut out, &m, json, team)?;
        }
    }
    d.finish();
    while let Some(m) = d.poll_message() {
        print_detection(&mut out, &m, json, team)?;
    }
    if pcm.has_pending_byte() {
        eprintln!("note: input ended in the middle of a sample (odd byte count)");
    }
    Ok(())
}

/// The `p` quantile of unsorted figures ([`huddle::summary::percentile`]), NaN for none.
fn percentile(v: &[f64], p: f64) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    huddle::summary::percentile(&s, p).unwrap_or(f64::NAN)
}

fn snr_row(label: &str, snr_db: f64, tone_s: f64, out: &SnrOutcome) -> Result<()> {
    outln!(
        "{label:>6} {snr_db:>6.1} {:>8.1} {:>6} {:>8.2}% {:>6.2}% {:>5} {:>7.0} {:>7.0} {:>7.0}",
        es_n0_db(snr_db, tone_s),
        out.sent,
        100.0 * out.correct_share(),
        100.0 * out.wrong_share(),
        out.spurious,
        1000.0 * percentile(&out.delays_s, 0.5),
        1000.0 * percentile(&out.delays_s, 0.95),
        1000.0 * percentile(&out.start_errors_s, 0.95),
    );
    Ok(())
}

fn eval(
    hours: f64,
    seed: u64,
    messages: usize,
    section: EvalSection,
    team: TeamPlan,
) -> Result<()> {
    let started = Instant::now();
    outln!(
        "huddle audio eval — seed {seed}, {messages} messages per row, 16 kHz, team plan {team}"
    );
    if section == EvalSection::Speed {
        outln!("Decoder speed against audio length (1 s tones, a short message every 2 s, white −6 dB):");
        outln!(
            "{:>10} {:>12} {:>12} {:>12} {:>14}",
            "audio",
            "decode s",
            "x realtime",
            "on-CPU s",
            "x real on CPU"
        );
        for minutes in [1.0, 10.0, 100.0] {
            let speed = decode_speed(seed, 60.0 * minutes)?;
            let (wall, cpu) = speed.realtime();
            outln!(
                "{:>7.0} min {:>12.2} {wall:>12.0} {:>12} {:>14}",
                speed.samples as f64 / 16_000.0 / 60.0,
                speed.wall_s,
                speed
                    .cpu_s
                    .map_or_else(|| "-".to_string(), |c| format!("{c:.2}")),
                cpu.map_or_else(|| "-".to_string(), |c| format!("{c:.0}")),
            );
        }
        return Ok(());
    }
    if section != EvalSection::Dry {
        eval_rooms(hours, seed, messages, team)?;
    }
    if section == EvalSection::Rooms {
        outln!("(eval took {:.1} s)", started.elapsed().as_secs_f64());
        return Ok(());
    }
    outln!("in-band SNR = message power / noise power inside 500–4000 Hz (white noise);");
    outln!("Es/N0 = energy of one short message (six tones × tone duration) / noise PSD.");
    outln!();
    outln!("1 s tones, short messages, white noise:");
    outln!(
        "{:>6} {:>6} {:>8} {:>6} {:>9} {:>7} {:>5} {:>7} {:>7} {:>7}",
        "",
        "SNR dB",
        "Es/N0 dB",
        "sent",
        "correct",
        "wrong",
        "extra",
        "delay50",
        "delay95",
        "t0err95"
    );
    outln!("{:>70}", "(ms)     (ms)    (ms)");
    let trial = |snr_db: f64, tone_s: f64, n: usize, long_share: f64, s: u64| {
        run_snr_trial_team(
            &SnrTrial {
                seed: s,
                snr_db,
                messages: n,
                tone_duration_s: tone_s,
                sample_rate_hz: 16_000,
                long_share,
                frequency_error: 0.0,
            },
            team,
        )
    };
    // Figures the closing summary compares with the targets.
    let mut worst_wrong = 0.0f64;
    let mut short_13 = None;
    let mut delays = Vec::new();
    for (i, snr) in [
        -20.0, -17.0, -15.0, -14.0, -13.0, -12.0, -10.0, -6.0, 0.0, 10.0,
    ]
    .into_iter()
    .enumerate()
    {
        let out = trial(snr, 1.0, messages, 0.0, seed.wrapping_add(i as u64))?;
        snr_row("short", snr, 1.0, &out)?;
        worst_wrong = worst_wrong.max(out.wrong_share());
        if snr == -13.0 {
            short_13 = Some(out.correct_share());
        }
        if [-13.0, -6.0, 0.0, 10.0].contains(&snr) {
            delays.push((
                snr,
                percentile(&out.delays_s, 0.5),
                percentile(&out.delays_s, 0.95),
            ));
        }
    }
    outln!();
    outln!("1 s tones, long messages (two frames), white noise:");
    for (i, snr) in [-13.0, -10.0, 0.0].into_iter().enumerate() {
        let out = trial(
            snr,
            1.0,
            messages / 2,
            1.0,
            seed.wrapping_add(100 + i as u64),
        )?;
        snr_row("long", snr, 1.0, &out)?;
        worst_wrong = worst_wrong.max(out.wrong_share());
    }
    outln!();
    outln!("1 s tones, short, sender 0.5% sharp:");
    let out = run_snr_trial_team(
        &SnrTrial {
            seed: seed.wrapping_add(200),
            snr_db: -13.0,
            messages: messages / 2,
            tone_duration_s: 1.0,
            sample_rate_hz: 16_000,
            long_share: 0.0,
            frequency_error: 0.005,
        },
        team,
    )?;
    snr_row("+0.5%", -13.0, 1.0, &out)?;
    worst_wrong = worst_wrong.max(out.wrong_share());

    outln!();
    outln!("Shortest tone that still decodes ≥ 99% at 0 dB (short messages):");
    let mut shortest = None;
    let mut tones_100 = None;
    for (i, tone_s) in [0.2, 0.15, 0.1, 0.08, 0.06, 0.05, 0.04]
        .into_iter()
        .enumerate()
    {
        if tone_s < audio::MIN_TONE_DURATION_S {
            outln!(
                "  {:>4.0} ms tones: refused by the decoder (shortest {:.0} ms)",
                tone_s * 1000.0,
                audio::MIN_TONE_DURATION_S * 1000.0
            );
            continue;
        }
        let out = trial(
            0.0,
            tone_s,
            messages / 2,
            0.0,
            seed.wrapping_add(300 + i as u64),
        )?;
        outln!(
            "  {:>4.0} ms tones: {:>6.2}% correct, {:.2}% wrong, {} extra ({} sent)",
            tone_s * 1000.0,
            100.0 * out.correct_share(),
            100.0 * out.wrong_share(),
            out.spurious,
            out.sent
        );
        worst_wrong = worst_wrong.max(out.wrong_share());
        if tone_s == 0.1 {
            tones_100 = Some(out.correct_share());
        }
        if out.correct_share() >= 0.99 {
            shortest = Some(tone_s);
        }
    }
    match shortest {
        Some(t) => outln!("  shortest ≥ 99%: {:.0} ms", t * 1000.0),
        None => outln!("  none of these reached 99%"),
    }

    outln!();
    outln!("False messages, nothing sent ({hours} h of each):");
    let mut false_total = 0;
    for (i, kind) in Interference::ALL.into_iter().enumerate() {
        let out = run_false_alarm_trial(kind, hours, seed.wrapping_add(400 + i as u64));
        false_total += out.false_messages;
        outln!(
            "  {:<16} {:>4} false in {:.2} h  ({:.2} per hour)",
            kind.name(),
            out.false_messages,
            out.hours,
            out.false_messages as f64 / out.hours.max(1e-9)
        );
    }

    outln!();
    let n = (messages / 4).max(20);
    let out = run_whistle_over_messages(n, seed.wrapping_add(500));
    outln!(
        "Whistle sweep over a message (10 dB SNR, whistle −10…+20 dB): {} sent, {} correct, {} wrong, {} extra",
        out.sent, out.correct, out.wrong, out.spurious
    );

    outln!();
    let speed = decode_speed(seed, 120.0)?;
    let (wall, cpu) = speed.realtime();
    outln!(
        "Decode speed: {:.2e} samples/s on one core = {wall:.0}× real time at 16 kHz \
         (on the CPU: {})",
        wall * 16_000.0,
        cpu.map_or_else(|| "not measured".to_string(), |c| format!("{c:.0}×"))
    );

    outln!();
    outln!("Against the issue's targets (seed {seed}):");
    let verdict = |ok: bool| if ok { "met" } else { "MISSED" };
    if let Some(c) = short_13 {
        outln!(
            "  short at -13 dB, 1 s tones     {:>7.2}%   target >= 99%      {}",
            100.0 * c,
            verdict(c >= 0.99)
        );
    }
    outln!(
        "  worst wrong share, any row     {:>7.2}%   target <= 0.1%     {}",
        100.0 * worst_wrong,
        verdict(worst_wrong <= 0.001)
    );
    outln!(
        "  false messages, all noises     {:>8}   target 0 in {hours} h each {}",
        false_total,
        verdict(false_total == 0)
    );
    // On the CPU where the system tells: the wall clock of a shared machine counts the
    // time the decoder waited for a core.
    let speed_x = cpu.unwrap_or(wall);
    outln!(
        "  decode speed                   {:>7.0}×   target >= 1000×    {}",
        speed_x,
        verdict(speed_x >= 1000.0)
    );
    for (snr, d50, d95) in &delays {
        outln!(
            "  report delay at {:>5.1} dB       {:>4.0} ms median, {:>4.0} ms p95   target <= 100 ms  {}",
            snr,
            1000.0 * d50,
            1000.0 * d95,
            verdict(*d50 <= 0.1)
        );
    }
    if let Some(c) = tones_100 {
        outln!(
            "  100 ms tones at 0 dB           {:>7.2}%   target >= 99%      {}",
            100.0 * c,
            verdict(c >= 0.99)
        );
    }
    outln!("(eval took {:.1} s)", started.elapsed().as_secs_f64());
    Ok(())
}

/// The reverberant-hall table: T60 × in-band SNR × white or babble, short messages,
/// senders' clocks off by up to ±0.5%, and false messages in reverberant babble.
fn eval_rooms(hours: f64, seed: u64, messages: usize, team: TeamPlan) -> Result<()> {
    outln!();
    outln!("Reverberant hall (image sources + diffuse tail, 300–6000 Hz, clocks ±0.5%), 1 s tones, short:");
    outln!(
        "{:>6} {:>7} {:>6} {:>6} {:>9} {:>7} {:>5} {:>7} {:>7} {:>7}",
        "T60 s",
        "noise",
        "SNR dB",
        "sent",
        "correct",
        "wrong",
        "extra",
        "delay50",
        "delay95",
        "t0err95"
    );
    let mut worst_wrong = 0.0f64;
    let mut targets = Vec::new();
    for (i, t60) in [0.3, 0.6, 1.2, 2.0].into_iter().enumerate() {
        for (j, noise) in [RoomNoise::White, RoomNoise::Babble]
            .into_iter()
            .enumerate()
        {
            for (k, snr) in [10.0, 0.0, -6.0].into_iter().enumerate() {
                let row_seed = seed.wrapping_add(1000 + 100 * i as u64 + 10 * j as u64 + k as u64);
                let mut trial = RoomTrial::new(row_seed, t60, snr, noise, messages);
                trial.decoder.team = team;
                let out = run_room_trial(&trial)?;
                outln!(
                    "{t60:>6.1} {:>7} {snr:>6.1} {:>6} {:>8.2}% {:>6.2}% {:>5} {:>7.0} {:>7.0} {:>7.0}",
                    noise.name(),
                    out.sent,
                    100.0 * out.correct_share(),
                    100.0 * out.wrong_share(),
                    out.spurious,
                    1000.0 * percentile(&out.delays_s, 0.5),
                    1000.0 * percentile(&out.delays_s, 0.95),
                    1000.0 * percentile(&out.start_errors_s, 0.95),
                );
                worst_wrong = worst_wrong.max(out.wrong_share());
                if noise == RoomNoise::Babble && snr == 0.0 && (t60 == 1.2 || t60 == 2.0) {
                    targets.push((t60, out.correct_share()));
                }
            }
        }
    }
    let fa = run_room_false_alarm_trial(1.2, hours, seed.wrapping_add(1900));
    outln!(
        "  reverberant babble (T60 1.2 s): {} false in {:.2} h",
        fa.false_messages,
        fa.hours
    );
    let verdict = |ok: bool| if ok { "met" } else { "MISSED" };
    for (t60, c) in targets {
        let goal = if t60 < 1.5 { 0.99 } else { 0.95 };
        outln!(
            "  T60 {t60:.1} s, babble 0 dB       {:>7.2}%   target >= {:.0}%      {}",
            100.0 * c,
            100.0 * goal,
            verdict(c >= goal)
        );
    }
    outln!(
        "  worst wrong share, room rows   {:>7.2}%   target <= 0.1%     {}",
        100.0 * worst_wrong,
        verdict(worst_wrong <= 0.001)
    );
    outln!(
        "  false messages, room babble    {:>8}   target 0           {}",
        fa.false_messages,
        verdict(fa.false_messages == 0)
    );
    Ok(())
}

/// Runs `work` on each of `items` on up to `jobs` threads and hands each result, in the
/// items' order, to `each` as soon as it and all before it are done (so a long table
/// prints as it goes, in the same order whatever `jobs` is).
fn in_order<T: Sync, R: Send>(
    items: &[T],
    jobs: usize,
    work: impl Fn(&T) -> R + Sync,
    mut each: impl FnMut(usize, R) -> Result<()>,
) -> Result<()> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let (tx, rx) = std::sync::mpsc::channel::<(usize, R)>();
    std::thread::scope(|scope| {
        for _ in 0..jobs.clamp(1, items.len().max(1)) {
            let tx = tx.clone();
            let (next, work) = (&next, &work);
            scope.spawn(move || loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some(item) = items.get(i) else { break };
                if tx.send((i, work(item))).is_err() {
                    break;
                }
            });
        }
        drop(tx);
        let mut done: std::collections::BTreeMap<usize, R> = std::collections::BTreeMap::new();
        let mut printed = 0;
        for (i, r) in rx {
            done.insert(i, r);
            while let Some(r) = done.remove(&printed) {
                each(printed, r)?;
                printed += 1;
            }
        }
        Ok(())
    })
}

/// One row of `huddle audio rooms`: what to run.
struct RoomsRow<'a> {
    label: &'static str,
    room: &'a ExternalRoom,
    trial: SceneTrial,
}

/// Prints one row of `huddle audio rooms` (`realtime`: audio seconds per second taken).
fn print_rooms_row(row: &RoomsRow, out: &SceneOutcome, realtime: f64) -> Result<()> {
    let (label, room, trial) = (row.label, row.room, &row.trial);
    let snr = trial
        .snr_db
        .map_or_else(|| "quiet".to_string(), |s| format!("{s:.0} dB"));
    let overlapped = if trial.two_senders {
        format!("{:>5}/{:<5}", out.overlapped_correct, out.overlapped_sent)
    } else {
        "-".to_string()
    };
    outln!(
        "{label:<8} {:<9} {:>5.2} {:>7} {:>3} {:>5} {:>8.2}% {:>11} {:>5} {:>7} {:>5} {:>11} {realtime:>6.0}",
        room.name,
        room.t60_measured_s,
        snr,
        trial.talkers,
        out.sent,
        100.0 * out.correct_share(),
        format!("{}/{}", out.long_correct, out.long_sent),
        out.wrong,
        out.refused,
        out.spurious,
        overlapped,
    );
    for (d, around) in &out.wrong_reports {
        let around: Vec<String> = around.iter().map(|m| m.to_string()).collect();
        outln!(
            "    wrong: {} at {:.2} s over [{}]",
            d.message,
            d.start_s,
            around.join(", ")
        );
    }
    for (d, around) in &out.refused_reports {
        let around: Vec<String> = around.iter().map(|m| m.to_string()).collect();
        outln!(
            "    refused: {} at {:.2} s over [{}]",
            d.message,
            d.start_s,
            around.join(", ")
        );
    }
    Ok(())
}

/// `huddle audio rooms`: the room set's tables and the targets they check.
fn rooms(
    dir: &std::path::Path,
    seed: u64,
    messages: usize,
    noise_s: f64,
    team: TeamPlan,
    jobs: usize,
) -> Result<()> {
    let started = Instant::now();
    let set = load_room_set(dir).with_context(|| format!("reading room set {}", dir.display()))?;
    outln!(
        "Room set {}: {} rooms, {} babble recordings; seed {seed}, {messages} messages per row, \
         team plan {team}",
        dir.display(),
        set.rooms.len(),
        set.babble.len()
    );
    outln!(
        "{:<8} {:<9} {:>5} {:>7} {:>3} {:>5} {:>9} {:>11} {:>5} {:>7} {:>5} {:>11} {:>6}",
        "row",
        "room",
        "T60 s",
        "SNR",
        "tlk",
        "sent",
        "correct",
        "long ok",
        "wrong",
        "refused",
        "extra",
        "overlap ok",
        "x real"
    );
    // Rows are seeded by their place in the table (`seed · 1000 + row`), as before `--jobs`.
    let mut rows: Vec<RoomsRow> = Vec::new();
    let mut push = |label, room, snr_db: Option<f64>, talkers, long_share, two| {
        let row = rows.len() as u64 + 1;
        rows.push(RoomsRow {
            label,
            room,
            trial: SceneTrial {
                seed: seed.wrapping_mul(1000).wrapping_add(row),
                snr_db,
                talkers,
                messages,
                long_share,
                two_senders: two,
                max_clock_error: 0.005,
                team,
            },
        });
    };
    for room in set.rooms.iter().filter(|r| r.t60_nominal_s <= 1.2) {
        for (k, snr) in [20.0, 10.0, 0.0].into_iter().enumerate() {
            push("short", room, Some(snr), 2 + k, 0.0, false);
        }
    }
    for room in set.rooms.iter().filter(|r| r.t60_nominal_s >= 1.2) {
        for (k, snr) in [None, Some(20.0), Some(0.0)].into_iter().enumerate() {
            push("long", room, snr, 2 + k, 1.0, false);
        }
    }
    for room in set.rooms.iter().filter(|r| r.t60_nominal_s >= 0.5) {
        push("two", room, Some(10.0), 3, 0.5, true);
    }
    let (mut short_worst, mut wrong, mut long_12, mut long_20) = (1.0f64, 0usize, 1.0f64, 1.0f64);
    let (mut refused, mut sent, mut audio_s) = (0usize, 0usize, 0.0f64);
    in_order(
        &rows,
        jobs,
        |row| {
            let t = Instant::now();
            let out = run_scene_trial(row.room, &set.babble, &row.trial);
            (out, t.elapsed().as_secs_f64().max(1e-9))
        },
        |i, (out, secs)| {
            let row = &rows[i];
            let out = out?;
            print_rooms_row(row, &out, out.seconds / secs)?;
            match row.label {
                "short" => short_worst = short_worst.min(out.correct_share()),
                "long" => {
                    let share = out.long_correct as f64 / out.long_sent.max(1) as f64;
                    if row.room.t60_nominal_s < 1.5 {
                        long_12 = long_12.min(share);
                    } else {
                        long_20 = long_20.min(share);
                    }
                }
                _ => {}
            }
            wrong += out.wrong;
            refused += out.refused;
            sent += out.sent;
            audio_s += out.seconds;
            Ok(())
        },
    )?;
    let mut false_messages = 0;
    let mut false_s = 0.0;
    let rooms: Vec<(usize, &ExternalRoom)> = set.rooms.iter().enumerate().collect();
    in_order(
        &rooms,
        jobs,
        |&(i, room)| {
            run_scene_false_alarm_trial(
                room,
                &set.babble,
                8,
                noise_s,
                seed.wrapping_mul(1000).wrapping_add(900 + i as u64),
                team,
            )
        },
        |i, heard| {
            for d in &heard {
                outln!(
                    "    false: {} at {:.1} s in {}",
                    d.message,
                    d.start_s,
                    rooms[i].1.name
                );
            }
            false_messages += heard.len();
            false_s += noise_s;
            Ok(())
        },
    )?;
    let verdict = |ok: bool| if ok { "met" } else { "MISSED" };
    outln!("Targets:");
    outln!(
        "  short over babble, 20…0 dB, T60 <= 1.2 s, worst row {:>7.2}%  target >= 99%  {}",
        100.0 * short_worst,
        verdict(short_worst >= 0.99)
    );
    outln!(
        "  long, T60 1.2 s, worst row                        {:>7.2}%  target >= 98%  {}",
        100.0 * long_12,
        verdict(long_12 >= 0.98)
    );
    outln!(
        "  long, T60 2.0 s, worst row                        {:>7.2}%  target >= 95%  {}",
        100.0 * long_20,
        verdict(long_20 >= 0.95)
    );
    outln!(
        "  wrong messages, all rows                          {:>8}  target 0       {}",
        wrong,
        verdict(wrong == 0)
    );
    outln!(
        "  refused (the plan cannot have sent them; lost, not wrong) {refused:>4} of {sent} sent"
    );
    outln!(
        "  false messages, crowd of 8, {:.2} h                {:>8}  target 0       {}",
        false_s / 3600.0,
        false_messages,
        verdict(false_messages == 0)
    );
    outln!(
        "(rooms took {:.1} s on {jobs} thread(s): {:.0} s of message audio, mixing included)",
        started.elapsed().as_secs_f64(),
        audio_s,
    );
    Ok(())
}

/// `huddle audio backgrounds`: false messages per background, dry and in a hall.
fn backgrounds(total_s: f64, seed: u64, t60: f64, team: TeamPlan, jobs: usize) -> Result<()> {
    anyhow::ensure!(
        (0.0..=5.0).contains(&t60),
        "--t60 {t60} s: a hall of 0 to 5 s"
    );
    let started = Instant::now();
    let per_row = total_s / (2 * Background::ALL.len()) as f64;
    outln!(
        "False messages in backgrounds that stop and start; seed {seed}, {:.2} h per row, team plan {team}",
        per_row / 3600.0
    );
    outln!(
        "{:<11} {:>6} {:>8} {:>6} {:>10}",
        "background",
        "T60 s",
        "hours",
        "false",
        "x realtime"
    );
    let mut rows = Vec::new();
    for (i, kind) in Background::ALL.into_iter().enumerate() {
        for (j, room_t60) in [0.0, t60].into_iter().enumerate() {
            let row_seed = seed
                .wrapping_mul(1000)
                .wrapping_add(10 * i as u64 + j as u64);
            rows.push((kind, room_t60, row_seed));
        }
    }
    let (mut false_messages, mut hours) = (0usize, 0.0f64);
    in_order(
        &rows,
        jobs,
        |&(kind, room_t60, row_seed)| {
            let t = Instant::now();
            let out = run_background_false_alarm_trial(kind, per_row, room_t60, row_seed, team);
            (out, t.elapsed().as_secs_f64().max(1e-9))
        },
        |i, (out, secs)| {
            let (kind, room_t60, _) = rows[i];
            outln!(
                "{:<11} {room_t60:>6.1} {:>8.2} {:>6} {:>10.0}",
                kind.name(),
                out.hours,
                out.false_messages,
                per_row / secs
            );
            for d in &out.detections {
                outln!("    false: {} at {:.1} s", d.message, d.start_s);
            }
            false_messages += out.false_messages;
            hours += out.hours;
            Ok(())
        },
    )?;
    outln!(
        "  false messages, {hours:.2} h of backgrounds   {false_messages:>6}   target 0   {}",
        if false_messages == 0 { "met" } else { "MISSED" }
    );
    outln!(
        "(backgrounds took {:.1} s on {jobs} thread(s), synthesis and room included)",
        started.elapsed().as_secs_f64(),
    );
    Ok(())
}

/// Times the decoder alone on `seconds` of noisy 16 kHz audio with messages (a short
/// message every two seconds, white noise at −6 dB in-band), generated a second at a
/// time so any length fits in memory; only the decoder's pushes are timed.
fn decode_speed(seed: u64, seconds: f64) -> Result<Speed> {
    let enc = Encoder::new(EncoderConfig::default())?;
    let tone = enc.encode_f32(&Message::short(Sender::Goalkeeper, 0)?);
    let sigma = white_sigma_for_in_band_snr(power(&tone) * 2.0, -6.0, 16_000);
    let mut noise = WhiteNoise::new(seed, sigma);
    let mut d = Decoder::new(DecoderConfig::default())?;
    let mut busy = Duration::ZERO;
    let mut on_cpu = Some(0.0f64);
    let (mut heard, mut done, mut i) = (0usize, 0u64, 0u8);
    let total = (seconds * 16_000.0) as u64;
    while done < total {
        let mut x = vec![0.0f32; 16_000];
        x.extend(enc.encode_f32(&Message::short(Sender::ALL[(i % 3) as usize], i % 21)?));
        i = i.wrapping_add(1);
        noise.add_to(&mut x);
        let t = Instant::now();
        let cpu = thread_cpu_s();
        for block in x.chunks(512) {
            d.push_f32(block);
            while d.poll_message().is_some() {
                heard += 1;
            }
        }
        busy += t.elapsed();
        on_cpu = match (on_cpu, cpu, thread_cpu_s()) {
            (Some(sum), Some(a), Some(b)) => Some(sum + (b - a)),
            _ => None,
        };
        done += x.len() as u64;
    }
    anyhow::ensure!(heard > 0, "speed run decoded nothing");
    Ok(Speed {
        samples: done,
        wall_s: busy.as_secs_f64(),
        cpu_s: on_cpu,
    })
}

/// What [`decode_speed`] measured.
struct Speed {
    samples: u64,
    /// Wall-clock seconds spent in the decoder's pushes.
    wall_s: f64,
    /// Seconds this thread ran on a CPU meanwhile (Linux), the figure a loaded machine
    /// does not inflate: with other builds sharing the cores, the wall clock counts the
    /// time the thread waited for one.
    cpu_s: Option<f64>,
}

impl Speed {
    /// × real time at 16 kHz, by the wall clock and (if known) on the CPU.
    fn realtime(&self) -> (f64, Option<f64>) {
        let audio = self.samples as f64 / 16_000.0;
        (
            audio / self.wall_s.max(1e-9),
            self.cpu_s.map(|c| audio / c.max(1e-9)),
        )
    }
}

/// This thread's time on a CPU so far, s (`/proc/thread-self/schedstat`; `None` elsewhere).
fn thread_cpu_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = text.split_whitespace().next()?.parse().ok()?;
    Some(ns / 1e9)
}
