//! The daemon speaks and listens: the 72-tone codec (`audio`) on raw s16le PCM pipes.
//!
//! **Listening** (`--audio-in CMD`): `sh -c CMD` runs with its stdout read as mono s16le
//! PCM at the configured rate (`arecord -t raw -f S16_LE -r 16000 -c 1`, `cat file.raw`,
//! `sox file.wav -t raw -r 16000 -e signed -b 16 -c 1 -`). A dedicated thread reads and
//! decodes it (the decoder is CPU work, kept off the driver's thread) and hands each
//! decoded message to the driver's thread, which writes it to the blackboard (see
//! [`heard_value`]). When the command ends, what it sent is decided to its end
//! ([`audio::Decoder::finish`]); then the [`Restart`] policy applies: by default a
//! command that exits with status 0 has finished its stream (a file played once), and one
//! that fails, is killed or cannot start is restarted after a backoff doubling from 1 s to
//! 30 s (back to 1 s once a run lasted 30 s). Each run is a new stream with a new decoder.
//!
//! **Speaking** (`--audio-out CMD`): a client's `SETV local.var.audio.say "short 1 7"`
//! is checked at once ([`parse_say`]: an invalid message is the client's `ERR 412`,
//! nothing queued) and queued (a full queue is `ERR 430`). One thread sounds the messages
//! one at a time in order: it writes each message's PCM followed by [`AudioConfig::gap`]
//! of silence to the stdin of `sh -c CMD` (`aplay -t raw -f S16_LE -r 16000 -c 1`, or
//! `cat > file.raw`), which runs once and is kept; a player paces the writes, so the
//! rate is one message per `frames × tone duration + gap` of audio (2 s for a short, 3 s
//! for a long message at the defaults). A fresh command first gets one gap of silence.
//! If the command exits or a write fails, the message being written is lost (counted)
//! and the command restarts for the next one, after the same backoff.
//!
//! **Team plan** ([`AudioConfig::team`], `--audio-team`): the robots of a team agree on
//! how messages map to robots and values ([`audio::TeamPlan`]). The listener's decoder is
//! set to it, so a message the plan cannot have sent (under `checked`: a long message cut
//! to one frame, two short messages run together) is dropped and counted, never written;
//! heard values name the plan's robot and value ([`heard_team_value`]) and `say` takes
//! them ([`parse_team_say`]).
//!
//! Nothing the pipes carry stops the daemon: garbage PCM is only noise to the decoder,
//! an odd byte count is a cut sample, a command that exits is restarted or reported.
//! The counters are mirrored to `local.var.huddle.stats.audio.*` (see [`Counters`]).

mod listen;
mod speak;

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use audio::{DecoderConfig, Detection, EncoderConfig, Message, Sender, TeamMessage, TeamPlan};
use comms::relay::{ErrCode, Rejected};
use comms::{Instant, Key, Value};
use thiserror::Error;

use crate::guard::Guard;
use crate::handle::Handle;

/// When the listening command is run again after it ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Restart {
    /// Only after a failure (non-zero status, a signal, no start): a command exiting
    /// with status 0 has finished its stream (`cat file.raw`).
    #[default]
    OnFailure,
    /// After every end (a microphone that must never go quiet).
    Always,
    /// Never: one run.
    Never,
}

/// How the daemon speaks and listens.
#[derive(Clone, Debug)]
pub struct AudioConfig {
    /// Shell command whose stdout is the microphone (mono s16le); `None`: deaf.
    pub input: Option<String>,
    /// Shell command whose stdin is the loudspeaker (mono s16le); `None`: mute.
    pub output: Option<String>,
    /// Sample rate of both pipes, Hz.
    pub sample_rate_hz: u32,
    /// Tone duration (one frame), as every robot of the team uses it.
    pub tone_duration: Duration,
    /// Silence after each message spoken.
    pub gap: Duration,
    /// Messages waiting to be spoken, besides the one sounding; beyond: `ERR 430`.
    pub queue: usize,
    /// Where heard messages are written: `*.var.x` (the team sees them) or `local.var.x`.
    pub heard_key: String,
    /// The key a relay client writes to speak.
    pub say_key: String,
    /// When the listening command runs again.
    pub restart: Restart,
    /// The team plan every robot of the team speaks (`audio::TeamPlan`): heard messages it
    /// cannot have sent are dropped and counted (`audio.refused`), heard values carry the
    /// plan's robot and value, and `say` takes them. `Checked` is the plan under which a
    /// long message cut to one frame, or two short messages run together, is never a
    /// wrong message (two robots sounding at once can still, rarely, cross into a valid
    /// one: one robot's sender with the other's data).
    pub team: TeamPlan,
}

impl Default for AudioConfig {
    fn default() -> AudioConfig {
        AudioConfig {
            input: None,
            output: None,
            sample_rate_hz: 16_000,
            tone_duration: Duration::from_secs(1),
            gap: Duration::from_secs(1),
            queue: 8,
            heard_key: "*.var.audio.heard".into(),
            say_key: "local.var.audio.say".into(),
            restart: Restart::OnFailure,
            team: TeamPlan::Three,
        }
    }
}

/// Why audio could not start.
#[derive(Debug, Error)]
pub enum AudioError {
    /// The rate or tone duration does not suit the decoder.
    #[error("audio decoder: {0}")]
    Decoder(#[from] audio::DecoderConfigError),
    /// The rate or tone duration does not suit the encoder.
    #[error("audio encoder: {0}")]
    Encoder(#[from] audio::EncoderConfigError),
    /// The heard key is not a `var` key this robot may write.
    #[error("heard key {key:?}: {why}")]
    HeardKey {
        /// The key.
        key: String,
        /// Why.
        why: String,
    },
    /// The say key is not a `local.var` key.
    #[error("say key {key:?}: {why}")]
    SayKey {
        /// The key.
        key: String,
        /// Why.
        why: String,
    },
    /// The speaking queue must hold at least one message.
    #[error("the say queue must hold at least one message")]
    Queue,
    /// A thread could not be started.
    #[error("cannot start the audio thread: {0}")]
    Thread(std::io::Error),
}

/// Backoff before a failed command runs again: doubling from the first to the last.
pub(crate) const BACKOFF_FIRST: Duration = Duration::from_secs(1);
pub(crate) const BACKOFF_LAST: Duration = Duration::from_secs(30);

/// The audio counters, shared by the threads and mirrored by the driver's thread to
/// `local.var.huddle.stats.audio.<name>` (names in [`Counters::snapshot`]).
#[derive(Debug, Default)]
pub struct Counters {
    /// Messages decoded and written to the blackboard.
    pub heard: AtomicU64,
    /// Messages decoded that the team plan cannot have sent (a long message cut to one
    /// frame, frames of two robots run together): dropped, never written.
    pub refused: AtomicU64,
    /// PCM bytes read from the listening command.
    pub in_bytes: AtomicU64,
    /// Runs of the listening command started.
    pub in_starts: AtomicU64,
    /// Runs that failed (could not start, non-zero status, signal, read error).
    pub in_failures: AtomicU64,
    /// Runs that ended in the middle of a sample (an odd byte count).
    pub in_cut_samples: AtomicU64,
    /// Messages accepted by `say`.
    pub say_accepted: AtomicU64,
    /// `say` values refused: not a message.
    pub say_invalid: AtomicU64,
    /// `say` values refused: the queue was full.
    pub say_full: AtomicU64,
    /// Messages waiting or sounding now.
    pub say_pending: AtomicU64,
    /// Messages written whole to the speaking command.
    pub said: AtomicU64,
    /// Messages lost because the speaking command failed while they were written.
    pub say_lost: AtomicU64,
    /// Runs of the speaking command started.
    pub out_starts: AtomicU64,
    /// Runs that failed (could not start, exited, broken pipe).
    pub out_failures: AtomicU64,
    /// Heard messages handed to the team layer's acoustic fallback (`--audio-fallback`).
    pub fallback_heard: AtomicU64,
    /// Claims the fallback sounded in this robot's slot.
    pub fallback_sounded: AtomicU64,
    /// Slots the fallback let go by because a `say` message still waited or sounded (a
    /// claim sounded late would be taken for the next robot's).
    pub fallback_busy: AtomicU64,
}

impl Counters {
    /// How many counters [`Counters::snapshot`] gives.
    pub const COUNT: usize = 17;

    /// Every counter with its name under `local.var.huddle.stats.`.
    pub fn snapshot(&self) -> [(&'static str, u64); Counters::COUNT] {
        let g = |c: &AtomicU64| c.load(Ordering::Relaxed);
        [
            ("audio.heard", g(&self.heard)),
            ("audio.refused", g(&self.refused)),
            ("audio.in_bytes", g(&self.in_bytes)),
            ("audio.in_starts", g(&self.in_starts)),
            ("audio.in_failures", g(&self.in_failures)),
            ("audio.in_cut_samples", g(&self.in_cut_samples)),
            ("audio.say_accepted", g(&self.say_accepted)),
            ("audio.say_invalid", g(&self.say_invalid)),
            ("audio.say_full", g(&self.say_full)),
            ("audio.say_pending", g(&self.say_pending)),
            ("audio.said", g(&self.said)),
            ("audio.say_lost", g(&self.say_lost)),
            ("audio.out_starts", g(&self.out_starts)),
            ("audio.out_failures", g(&self.out_failures)),
            ("audio.fallback_heard", g(&self.fallback_heard)),
            ("audio.fallback_sounded", g(&self.fallback_sounded)),
            ("audio.fallback_busy", g(&self.fallback_busy)),
        ]
    }
}

pub(crate) fn bump(c: &AtomicU64) {
    c.fetch_add(1, Ordering::Relaxed);
}

/// What the threads tell the driver's thread.
pub(crate) struct Shared {
    pub(crate) counters: Counters,
    /// Wakes the task that mirrors the counters.
    pub(crate) changed: tokio::sync::Notify,
}

impl Shared {
    pub(crate) fn count(&self, c: impl Fn(&Counters) -> &AtomicU64) {
        bump(c(&self.counters));
        self.changed.notify_one();
    }
}

/// A decoded message and when it began on the driver's clock.
#[derive(Debug)]
pub(crate) struct Heard {
    pub(crate) detection: Detection,
    pub(crate) start: Instant,
}

/// Places a stream's samples on the driver's clock: `t0 + sample time`, with `t0` the
/// lower envelope of `read time - audio read so far` over the reads. A sample is never
/// read before it was captured, so each read bounds `t0` from above and the least
/// delayed read is the best bound; the envelope may rise by [`StreamClock::DRIFT`] of
/// the time elapsed, so a sound card slower than the driver's clock is followed. For a
/// live capture this is the capture time within the smallest buffering delay seen; for
/// input faster than real time (a file) it is as if that input had been captured in
/// real time up to the latest read (floored at the clock's start).
#[derive(Debug, Default)]
pub(crate) struct StreamClock {
    /// `t0` in µs on the driver's clock (may be negative), and the last read's time.
    anchor: Option<(i64, i64)>,
}

impl StreamClock {
    /// Largest drift followed, relative: 200 ppm (sound cards are within ±100 ppm).
    pub(crate) const DRIFT: f64 = 200e-6;

    /// A read returned at `read_at`, when `pushed_s` of audio had been read in all.
    pub(crate) fn read(&mut self, read_at: Instant, pushed_s: f64) {
        let at = i64::try_from(read_at.as_micros()).unwrap_or(i64::MAX);
        let bound = at.saturating_sub((pushed_s * 1e6) as i64);
        let t0 = match self.anchor {
            None => bound,
            Some((t0, last)) => {
                let rise = (at.saturating_sub(last) as f64 * Self::DRIFT) as i64;
                bound.min(t0.saturating_add(rise))
            }
        };
        self.anchor = Some((t0, at));
    }

    /// The driver-clock time of stream time `t_s` (0 before any read).
    pub(crate) fn at(&self, t_s: f64) -> Instant {
        let t0 = self.anchor.map_or(0, |(t0, _)| t0);
        let us = t0.saturating_add((t_s * 1e6) as i64).max(0);
        Instant::from_micros(us as u64)
    }
}

/// The blackboard value of a heard message: a string of `name=value` words, always in
/// this order: `seq` (1, 2, … per daemon run: tells a repeated message from the old
/// one), `kind` (`short`/`long`), `sender` (0 goalkeeper, 1 left attacker, 2 right
/// attacker), `data` (0 … 20 short, 0 … 440 long), `start_us` (when it began on this
/// robot's clock: µs since the daemon started, the clock of the stats'
/// `last_heard_us`), `snr_db` (per-tone SNR estimate).
///
/// ```
/// let m = audio::Message::short(audio::Sender::LeftAttacker, 7).unwrap();
/// assert_eq!(
///     driver::audio::heard_value(3, &m, comms::Instant::from_micros(1_500_000), 21.04),
///     "seq=3 kind=short sender=1 data=7 start_us=1500000 snr_db=21.0"
/// );
/// ```
pub fn heard_value(seq: u64, message: &Message, start: Instant, snr_db: f64) -> String {
    format!(
        "seq={seq} kind={} sender={} data={} start_us={} snr_db={snr_db:.1}",
        message.kind(),
        message.sender().index(),
        message.value(),
        start.as_micros(),
    )
}

/// The blackboard value of a message heard under team plan `plan`: [`heard_value`]'s
/// words, and under any plan but the seed's (`three`, where robot and value are the
/// sender and data) three more at the end: `plan` (its name), `robot` (0 … robots − 1)
/// and `value` (what the robot said, in the plan's range). A message the plan cannot
/// have sent gets none of them (the daemon drops those before this).
///
/// ```
/// use audio::{TeamMessage, TeamPlan};
/// let plan = TeamPlan::Checked;
/// let m = plan.encode(TeamMessage { robot: 2, long: true, value: 57 }).unwrap();
/// assert_eq!(
///     driver::audio::heard_team_value(plan, 4, &m, comms::Instant::from_micros(9), 12.0),
///     "seq=4 kind=long sender=2 data=327 start_us=9 snr_db=12.0 plan=checked robot=2 value=57"
/// );
/// ```
pub fn heard_team_value(
    plan: TeamPlan,
    seq: u64,
    message: &Message,
    start: Instant,
    snr_db: f64,
) -> String {
    let mut value = heard_value(seq, message, start, snr_db);
    if plan != TeamPlan::Three {
        if let Some(tm) = plan.decode(message) {
            value.push_str(&format!(
                " plan={} robot={} value={}",
                plan.name(),
                tm.robot,
                tm.value
            ));
        }
    }
    value
}

/// Why a `say` value is not a message.
#[derive(Clone, Debug, PartialEq, Eq, Error)]
pub enum SayError {
    /// Not a string value.
    #[error("expected a string such as \"short 1 7\" or \"long 2 300\", got a {0}")]
    NotText(&'static str),
    /// The words do not make a message.
    #[error(
        "{0}: expected \"[short|long] SENDER DATA\" (SENDER 0-2 or goalkeeper, \
         left-attacker, right-attacker; DATA 0-20 short, 0-440 long) or the \
         heard form \"kind=short sender=1 data=7\""
    )]
    Syntax(String),
    /// Out of range.
    #[error("{0}")]
    Range(#[from] audio::MessageError),
    /// The words do not make a message of the team plan.
    #[error(
        "{text}: expected \"[short|long] ROBOT VALUE\" under the {plan} plan (ROBOT \
         0-{}, VALUE 0-{} short, 0-{} long) or the heard form \"kind=short robot=1 value=7\"",
        .plan.robots() - 1,
        .plan.short_values() - 1,
        .plan.long_values() - 1
    )]
    PlanSyntax {
        /// What was given.
        text: String,
        /// The plan.
        plan: TeamPlan,
    },
    /// A robot or value the plan does not have.
    #[error("{0}")]
    Team(#[from] audio::TeamError),
    /// A message on the air (the heard form's `sender=`/`data=`) the plan cannot send.
    #[error("{message} is not a message of the {plan} plan")]
    NotInPlan {
        /// The message.
        message: Message,
        /// The plan.
        plan: TeamPlan,
    },
}

/// Reads a `say` value: a string `"[short|long] SENDER DATA"` (without a kind: short)
/// or the [`heard_value`] form (`kind=`, `sender=`, `data=` words; others ignored), so a
/// heard message can be said again as it is.
///
/// ```
/// use audio::{Message, Sender};
/// use comms::Value;
/// let say = |s: &str| driver::audio::parse_say(&Value::String(s.into()));
/// assert_eq!(say("long 2 300"), Ok(Message::long(Sender::RightAttacker, 300).unwrap()));
/// assert_eq!(say("goalkeeper 4"), Ok(Message::short(Sender::Goalkeeper, 4).unwrap()));
/// assert_eq!(say("seq=9 kind=short sender=1 data=7 start_us=5"), say("1 7"));
/// assert!(say("short 1 21").is_err());
/// ```
pub fn parse_say(value: &Value) -> Result<Message, SayError> {
    let Value::String(text) = value else {
        return Err(SayError::NotText(value.value_type().name()));
    };
    let syntax = || SayError::Syntax(format!("{text:?}"));
    let words: Vec<&str> = text.split_whitespace().collect();
    let (kind, sender, data) = if words.iter().any(|w| w.contains('=')) {
        let field = |name: &str| heard_field(&words, name);
        (
            field("kind").unwrap_or("short"),
            field("sender").ok_or_else(syntax)?,
            field("data").ok_or_else(syntax)?,
        )
    } else {
        positional(&words).ok_or_else(syntax)?
    };
    let sender = robot_word(sender)
        .and_then(Sender::from_index)
        .ok_or_else(syntax)?;
    let data: u16 = data.parse().map_err(|_| syntax())?;
    match kind {
        "short" => match u8::try_from(data) {
            Ok(data) => Ok(Message::short(sender, data)?),
            Err(_) => Err(audio::MessageError::DataOutOfRange(data).into()),
        },
        "long" => Ok(Message::long(sender, data)?),
        _ => Err(syntax()),
    }
}

/// The value of the `name=value` word called `name` among `words` (the heard form).
fn heard_field<'a>(words: &[&'a str], name: &str) -> Option<&'a str> {
    words
        .iter()
        .filter_map(|w| w.split_once('='))
        .find(|(n, _)| *n == name)
        .map(|(_, v)| v)
}

/// `[KIND] WHO WHAT` as `(kind, who, what)`, the kind `short` when left out.
fn positional<'a>(words: &[&'a str]) -> Option<(&'a str, &'a str, &'a str)> {
    match *words {
        [kind, who, what] => Some((kind, who, what)),
        [who, what] => Some(("short", who, what)),
        _ => None,
    }
}

/// A robot (sender basic) by number, or by the name its basic has for robots 0–2
/// (`Sender`'s display: goalkeeper, left-attacker, right-attacker).
fn robot_word(word: &str) -> Option<u8> {
    Sender::ALL
        .iter()
        .find(|s| s.to_string() == word)
        .map(|s| s.index())
        .or_else(|| word.parse().ok())
}

/// Reads a `say` value under team plan `plan`: `"[short|long] ROBOT VALUE"` (without a
/// kind: short; ROBOT 0 … robots − 1, or goalkeeper / left-attacker / right-attacker for
/// robots 0–2; VALUE in the plan's range), or the [`heard_team_value`] form (`kind=`,
/// `robot=`, `value=` words; a heard form with only `sender=` and `data=` is the message
/// on the air, taken if the plan can send it). Under the seed's plan (`three`) this is
/// [`parse_say`].
///
/// ```
/// use audio::{Message, Sender, TeamPlan};
/// use comms::Value;
/// let say = |s: &str| driver::audio::parse_team_say(&Value::String(s.into()), TeamPlan::Checked);
/// // A checked long message: both frames on data 10 … 20 (57 = 11 · 5 + 2).
/// assert_eq!(say("long 2 57"), Ok(Message::long(Sender::RightAttacker, 21 * 15 + 12).unwrap()));
/// assert_eq!(say("1 7"), Ok(Message::short(Sender::LeftAttacker, 7).unwrap()));
/// assert!(say("short 1 12").is_err(), "a checked short says 0 … 9");
/// assert!(say("kind=short sender=1 data=15").is_err(), "data 15 is a long message's frame");
/// ```
pub fn parse_team_say(value: &Value, plan: TeamPlan) -> Result<Message, SayError> {
    if plan == TeamPlan::Three {
        return parse_say(value);
    }
    let Value::String(text) = value else {
        return Err(SayError::NotText(value.value_type().name()));
    };
    let syntax = || SayError::PlanSyntax {
        text: format!("{text:?}"),
        plan,
    };
    let words: Vec<&str> = text.split_whitespace().collect();
    let (kind, robot, said) = if words.iter().any(|w| w.contains('=')) {
        let field = |name: &str| heard_field(&words, name);
        match (field("robot"), field("value")) {
            (Some(robot), Some(said)) => (field("kind").unwrap_or("short"), robot, said),
            (None, None) => {
                // The seed's heard form: the message on the air, if this plan sends it.
                let message = parse_say(value).map_err(|_| syntax())?;
                return match plan.decode(&message) {
                    Some(_) => Ok(message),
                    None => Err(SayError::NotInPlan { message, plan }),
                };
            }
            _ => return Err(syntax()),
        }
    } else {
        positional(&words).ok_or_else(syntax)?
    };
    let robot = robot_word(robot).ok_or_else(syntax)?;
    let said: u16 = said.parse().map_err(|_| syntax())?;
    let long = match kind {
        "short" => false,
        "long" => true,
        _ => return Err(syntax()),
    };
    Ok(plan.encode(TeamMessage {
        robot,
        long,
        value: said,
    })?)
}

/// The audio of a running driver; dropping it stops listening and speaking (the
/// listening command is killed, the speaking one gets end of input).
pub struct Audio {
    shared: Arc<Shared>,
    _guard: Option<Guard>,
    listener: Option<listen::Listener>,
    speaker: Option<SyncSender<Message>>,
    /// Where the mirror also hands each heard message, once [`Audio::fallback`] asked.
    tap: HeardTap,
    mirror: tokio::task::JoinHandle<()>,
}

/// The team layer's acoustic fallback's side of the audio (see [`Audio::fallback`]).
type HeardTap =
    std::rc::Rc<std::cell::RefCell<Option<tokio::sync::mpsc::UnboundedSender<(Message, Instant)>>>>;

/// What the team layer's acoustic fallback (`--audio-fallback`) takes from the daemon's
/// audio: every message the listener decodes, with its start on the driver's clock, and
/// a speaker that sounds a claim at once.
pub struct FallbackAudio {
    /// Heard messages and when each began (the driver's clock).
    pub heard: tokio::sync::mpsc::UnboundedReceiver<(Message, Instant)>,
    /// Sounds a claim now.
    pub speaker: Speaker,
}

/// The speaking thread, for the fallback's claims: one sounds only when nothing else
/// waits or sounds, so that it goes out in its slot.
#[derive(Clone)]
pub struct Speaker {
    tx: SyncSender<Message>,
    shared: Arc<Shared>,
}

impl Speaker {
    /// Hands `message` to the speaking command now; `false` (counted as
    /// `audio.fallback_busy`) if a `say` message still waits or is being written, so it
    /// would go out late, in another robot's slot.
    pub fn sound_now(&self, message: Message) -> bool {
        let counters = &self.shared.counters;
        if counters.say_pending.load(Ordering::Relaxed) > 0 {
            self.shared.count(|c| &c.fallback_busy);
            return false;
        }
        bump(&counters.say_pending);
        match self.tx.try_send(message) {
            Ok(()) => {
                self.shared.count(|c| &c.fallback_sounded);
                true
            }
            Err(_) => {
                counters.say_pending.fetch_sub(1, Ordering::Relaxed);
                self.shared.count(|c| &c.fallback_busy);
                false
            }
        }
    }
}

impl Audio {
    /// Starts listening and speaking as `config` asks, on the driver of `handle`. Call it
    /// on the driver's thread inside its [`tokio::task::LocalSet`]: a local task writes
    /// what is heard and mirrors the counters.
    pub fn start(handle: &Handle, config: AudioConfig) -> Result<Audio, AudioError> {
        let decoder = DecoderConfig {
            sample_rate_hz: config.sample_rate_hz,
            tone_duration_s: config.tone_duration.as_secs_f64(),
            team: config.team,
            ..DecoderConfig::default()
        };
        let tone_s = config.tone_duration.as_secs_f64();
        let encoder = EncoderConfig {
            sample_rate_hz: config.sample_rate_hz,
            tone_duration_s: tone_s,
            // As `huddle audio encode`: short fades, never more than a twentieth.
            fade_s: (tone_s / 20.0).min(0.01),
            ..EncoderConfig::default()
        };
        // Refuse a bad rate or tone duration now, not in a thread later.
        audio::Decoder::new(decoder.clone())?;
        audio::Encoder::new(encoder.clone())?;
        check_heard_key(handle, &config.heard_key)?;
        let say_key = Key::parse(&config.say_key).map_err(|e| AudioError::SayKey {
            key: config.say_key.clone(),
            why: e.to_string(),
        })?;
        if say_key.scope() != comms::Scope::Local || say_key.kind() != comms::Kind::Var {
            return Err(AudioError::SayKey {
                key: config.say_key.clone(),
                why: "must be a local.var key (a command to this robot only)".into(),
            });
        }
        if config.queue == 0 {
            return Err(AudioError::Queue);
        }

        let shared = Arc::new(Shared {
            counters: Counters::default(),
            changed: tokio::sync::Notify::new(),
        });
        let (heard_tx, heard_rx) = tokio::sync::mpsc::channel(64);
        let listener = match &config.input {
            Some(command) => Some(
                listen::Listener::start(
                    listen::ListenConfig {
                        command: command.clone(),
                        decoder,
                        restart: config.restart,
                    },
                    handle.clock(),
                    shared.clone(),
                    heard_tx,
                )
                .map_err(AudioError::Thread)?,
            ),
            None => None,
        };
        let speaker = match &config.output {
            Some(command) => Some(
                speak::start(
                    speak::SpeakConfig {
                        command: command.clone(),
                        encoder,
                        gap: config.gap,
                        queue: config.queue,
                    },
                    handle.clock(),
                    shared.clone(),
                )
                .map_err(AudioError::Thread)?,
            ),
            None => None,
        };
        let guard = if config.input.is_some() || config.output.is_some() {
            let check = say_check(&config, speaker.clone(), shared.clone());
            let guard = handle
                .guard(&config.say_key, check)
                .map_err(|e| AudioError::SayKey {
                    key: config.say_key.clone(),
                    why: e.to_string(),
                })?;
            Some(guard)
        } else {
            None
        };
        let tap = HeardTap::default();
        let mirror = tokio::task::spawn_local(mirror(
            handle.clone(),
            config.heard_key.clone(),
            config.team,
            shared.clone(),
            heard_rx,
            tap.clone(),
        ));
        Ok(Audio {
            shared,
            _guard: guard,
            listener,
            speaker,
            tap,
            mirror,
        })
    }

    /// The heard messages and the speaker for the team layer's acoustic fallback, if
    /// this daemon both listens and speaks (`None` otherwise). Heard messages go on being
    /// written to the blackboard as well.
    pub fn fallback(&self) -> Option<FallbackAudio> {
        let speaker = self.speaker.clone()?;
        self.listener.as_ref()?;
        let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
        *self.tap.borrow_mut() = Some(tx);
        Some(FallbackAudio {
            heard: rx,
            speaker: Speaker {
                tx: speaker,
                shared: self.shared.clone(),
            },
        })
    }

    /// The counters now.
    pub fn counters(&self) -> &Counters {
        &self.shared.counters
    }
}

impl Drop for Audio {
    fn drop(&mut self) {
        if let Some(listener) = &mut self.listener {
            listener.stop();
        }
        self.mirror.abort();
    }
}

fn check_heard_key(handle: &Handle, key: &str) -> Result<(), AudioError> {
    let bad = |why: String| AudioError::HeardKey {
        key: key.into(),
        why,
    };
    let parsed = Key::parse(key).map_err(|e| bad(e.to_string()))?;
    let own = match parsed.scope() {
        comms::Scope::Local | comms::Scope::Global => true,
        comms::Scope::Robot(id) => id == handle.robot_id(),
    };
    if parsed.kind() != comms::Kind::Var || !own {
        return Err(bad(
            "must be local.var.x, *.var.x or this robot's n.var.x".into()
        ));
    }
    Ok(())
}

/// The check in front of `SETV <say key>`: a message, and room in the queue.
fn say_check(
    config: &AudioConfig,
    speaker: Option<SyncSender<Message>>,
    shared: Arc<Shared>,
) -> impl FnMut(&Value) -> Result<(), Rejected> + 'static {
    let queue = config.queue;
    let plan = config.team;
    let per_message = config.tone_duration;
    let gap = config.gap;
    let check = move |value: &Value| {
        let counters = &shared.counters;
        let Some(speaker) = &speaker else {
            return Err(Rejected {
                code: ErrCode::Unavailable,
                text: "this daemon does not speak (no --audio-out)".into(),
            });
        };
        let message = parse_team_say(value, plan).map_err(|e| {
            shared.count(|c| &c.say_invalid);
            Rejected {
                code: ErrCode::BadValue,
                text: format!("not a message: {e}"),
            }
        })?;
        match speaker.try_send(message) {
            Ok(()) => {
                bump(&counters.say_pending);
                shared.count(|c| &c.say_accepted);
                Ok(())
            }
            Err(TrySendError::Full(_)) => {
                shared.count(|c| &c.say_full);
                Err(Rejected {
                    code: ErrCode::QueueFull,
                    text: format!(
                        "{queue} messages already wait to be said (one sounds per \
                         frames x {per_message:?} + {gap:?}); retry later"
                    ),
                })
            }
            Err(TrySendError::Disconnected(_)) => Err(Rejected {
                code: ErrCode::Unavailable,
                text: "the audio output has stopped".into(),
            }),
        }
    };
    check
}

/// On the driver's thread: writes each heard message, and mirrors the counters whenever
/// a thread changed one.
async fn mirror(
    handle: Handle,
    heard_key: String,
    plan: TeamPlan,
    shared: Arc<Shared>,
    mut heard: tokio::sync::mpsc::Receiver<Heard>,
    tap: HeardTap,
) {
    let mut last = [u64::MAX; Counters::COUNT];
    let mut seq = 0u64;
    let mut listening = true;
    loop {
        tokio::select! {
            h = heard.recv(), if listening => match h {
                Some(h) => {
                    seq += 1;
                    let d = &h.detection;
                    let value = heard_team_value(plan, seq, &d.message, h.start, d.tone_snr_db);
                    tracing::info!(message = %d.message, key = %heard_key, "audio heard");
                    if let Err(e) = handle.set(&heard_key, value) {
                        tracing::warn!(error = %e, key = %heard_key, "cannot write a heard message");
                    }
                    bump(&shared.counters.heard);
                    if let Some(tx) = tap.borrow().as_ref() {
                        if tx.send((d.message, h.start)).is_ok() {
                            bump(&shared.counters.fallback_heard);
                        }
                    }
                }
                // The listener has stopped for good; counters may still change.
                None => listening = false,
            },
            () = shared.changed.notified() => {}
        }
        for (i, (name, count)) in shared.counters.snapshot().into_iter().enumerate() {
            if last[i] != count {
                last[i] = count;
                let key = format!("local.var.huddle.stats.{name}");
                let _ = handle.set(&key, i64::try_from(count).unwrap_or(i64::MAX));
            }
        }
    }
}

/// Sleeps up to `d` on this (non-runtime) thread, or less when `stop` fires; returns
/// whether to stop.
pub(crate) fn pause(stop: &std::sync::mpsc::Receiver<()>, d: Duration) -> bool {
    !matches!(
        stop.recv_timeout(d),
        Err(std::sync::mpsc::RecvTimeoutError::Timeout)
    )
}

/// A child process shared with [`Audio`]'s drop, which kills it.
pub(crate) type ChildSlot = Arc<Mutex<Option<std::process::Child>>>;

#[cfg(test)]
mod tests {
    use super::*;

    fn at(us: u64) -> Instant {
        Instant::from_micros(us)
    }

    /// A live capture read in 128 ms blocks, each read late by 5–40 ms of buffering: the
    /// stream clock puts sample time 0 at the capture start plus the smallest delay.
    #[test]
    fn a_live_stream_is_placed_by_its_least_delayed_read() {
        let mut clock = StreamClock::default();
        let start_us = 2_000_000;
        let delays_us = [40_000, 5_000, 22_000, 31_000, 9_000, 17_000];
        for (i, delay) in delays_us.iter().enumerate() {
            let pushed_s = 0.128 * (i + 1) as f64;
            clock.read(at(start_us + (pushed_s * 1e6) as u64 + delay), pushed_s);
        }
        let t = clock.at(0.5).as_micros();
        let want = start_us + 500_000 + 5_000;
        assert!(
            t.abs_diff(want) <= 200,
            "sample time 0.5 s at {t} µs, want {want} ± drift"
        );
    }

    /// A sound card 100 ppm slow (fewer samples per driver second): the envelope rises
    /// with it, so an hour in, a message is placed within a few ms, not 360 ms early.
    #[test]
    fn a_slow_sound_card_is_followed() {
        let mut clock = StreamClock::default();
        let (mut t_us, mut pushed_s) = (0u64, 0.0);
        for _ in 0..(3600 * 8) {
            pushed_s += 0.125;
            t_us += (0.125 * (1.0 + 100e-6) * 1e6) as u64;
            clock.read(at(t_us + 1_000), pushed_s);
        }
        let placed = clock.at(pushed_s).as_micros();
        assert!(
            placed.abs_diff(t_us + 1_000) < 5_000,
            "end of stream placed at {placed} µs, captured at {t_us} µs"
        );
    }

    /// A file read at once is placed as if captured in real time up to the read, floored
    /// at the clock's start; before any read, stream time is driver time 0.
    #[test]
    fn a_burst_is_placed_as_if_real_time_and_floored_at_zero() {
        let mut clock = StreamClock::default();
        assert_eq!(clock.at(3.0), at(3_000_000));
        clock.read(at(1_000_000), 4.0);
        assert_eq!(clock.at(0.5), at(0), "t0 = 1 s - 4 s, floored");
        assert_eq!(clock.at(3.5), at(500_000));
    }

    #[test]
    fn say_values_are_checked_with_reasons() {
        let say = |s: &str| parse_say(&Value::String(s.into()));
        assert_eq!(
            say("short right-attacker 20"),
            Ok(Message::short(Sender::RightAttacker, 20).unwrap())
        );
        assert_eq!(
            say("  long 0 0 "),
            Ok(Message::long(Sender::Goalkeeper, 0).unwrap())
        );
        assert_eq!(
            say("short 1 300"),
            Err(SayError::Range(audio::MessageError::DataOutOfRange(300))),
            "a short's data beyond a byte is out of range as it was given"
        );
        for bad in [
            "",
            "1",
            "medium 1 2",
            "short 3 1",
            "short -1 2",
            "1 2 3 4",
            "kind=long",
        ] {
            assert!(
                matches!(say(bad), Err(SayError::Syntax(_))),
                "{bad:?}: {:?}",
                say(bad)
            );
        }
        assert_eq!(
            parse_say(&Value::Int(7)),
            Err(SayError::NotText("int")),
            "only strings say something"
        );
    }

    /// Under the checked plan a robot says `[short|long] ROBOT VALUE` in the plan's ranges;
    /// what the plan cannot send is refused with the plan's ranges in the reason, never
    /// turned into another message.
    #[test]
    fn say_values_under_a_team_plan_are_the_plans_robots_and_values() {
        let plan = TeamPlan::Checked;
        let say = |s: &str| parse_team_say(&Value::String(s.into()), plan);
        let encode = |robot, long, value| plan.encode(TeamMessage { robot, long, value }).unwrap();
        assert_eq!(say("short 2 9"), Ok(encode(2, false, 9)));
        assert_eq!(say("goalkeeper 3"), Ok(encode(0, false, 3)));
        assert_eq!(say("long right-attacker 120"), Ok(encode(2, true, 120)));
        let err = say("short 1 10").unwrap_err();
        assert!(
            matches!(err, SayError::Team(audio::TeamError::Value { .. })),
            "a checked short says 0 … 9: {err:?}"
        );
        assert!(matches!(say("long 1 121"), Err(SayError::Team(_))));
        assert!(
            matches!(say("short 3 1"), Err(SayError::Team(_))),
            "three robots"
        );
        for bad in [
            "",
            "7",
            "medium 1 2",
            "short x 2",
            "1 2 3 4",
            "robot=1",
            "short 1 -2",
        ] {
            let err = say(bad).unwrap_err();
            assert!(
                matches!(err, SayError::PlanSyntax { .. }),
                "{bad:?}: {err:?}"
            );
            assert!(
                err.to_string()
                    .contains("ROBOT 0-2, VALUE 0-9 short, 0-120 long"),
                "the reason names the plan's ranges: {err}"
            );
        }
        // The seed's heard form is the message on the air: taken if the plan sends it.
        assert_eq!(say("kind=short sender=1 data=7"), Ok(encode(1, false, 7)));
        let err = say("kind=short sender=1 data=17").unwrap_err();
        assert!(
            matches!(err, SayError::NotInPlan { .. }),
            "data 17 alone is half a checked long message: {err:?}"
        );
        // Six robots: robot 4 is the left attacker's basic in the second bank.
        let six = parse_team_say(&Value::String("short 4 7".into()), TeamPlan::Six);
        assert_eq!(six, Ok(Message::short(Sender::LeftAttacker, 17).unwrap()));
        // The seed's plan is `parse_say`, its errors included.
        assert_eq!(
            parse_team_say(&Value::String("short 1 300".into()), TeamPlan::Three),
            Err(SayError::Range(audio::MessageError::DataOutOfRange(300)))
        );
    }

    /// A heard value under any plan says again as the same message; under the seed's plan
    /// it has no plan words, under the others it names the robot and value.
    #[test]
    fn heard_team_values_say_again_as_the_same_message() {
        for plan in TeamPlan::ALL {
            for robot in 0..plan.robots() {
                for (long, value) in [
                    (false, plan.short_values() - 1),
                    (true, plan.long_values() - 1),
                    (true, 0),
                ] {
                    let m = plan.encode(TeamMessage { robot, long, value }).unwrap();
                    let v = heard_team_value(plan, 1, &m, at(5), 3.0);
                    assert_eq!(
                        parse_team_say(&Value::String(v.clone()), plan),
                        Ok(m),
                        "{plan}: {v}"
                    );
                    let words = format!("robot={robot} value={value}");
                    assert_eq!(v.ends_with(&words), plan != TeamPlan::Three, "{plan}: {v}");
                }
            }
        }
    }

    #[test]
    fn heard_values_say_again_as_the_same_message() {
        let m = Message::long(Sender::LeftAttacker, 440).unwrap();
        let v = heard_value(12, &m, at(7), -3.0);
        assert_eq!(parse_say(&Value::String(v)), Ok(m));
    }
}
