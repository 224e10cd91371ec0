//! The command-line clients: `huddle get`, `set`, `keys`, `echo` and `stats` (`watch`,
//! the seed's Monitor, is in `watch.rs`). Each speaks the relay line protocol to a daemon
//! (`--relay`, default `HUDDLE_RELAY` or 127.0.0.1:2001).

use std::collections::BTreeMap;
use std::io::Write;
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use clap::Args;
use comms::relay::Binding;
use serde_json::json;

use super::duration;
use super::feed::{Feed, FeedEvent};
use super::relay::{
    binding_json, greeting_robot, owner_id, utc_now, RelayAddr, RelayClient, RelayTarget,
};

/// `huddle get KEY`
#[derive(Args, Debug)]
pub struct GetArgs {
    /// Key: `*.var.x` (newest copy of any robot), `3.var.x`, `local.var.x`.
    pub key: String,
    /// Print one JSON object: key, owner, type, value, age_ms.
    #[arg(long)]
    pub json: bool,
    /// Wait for the key to appear instead of failing at once.
    #[arg(long)]
    pub wait: bool,
    /// With `--wait`: give up after this long (`5s`; default: wait until it appears).
    #[arg(long, requires = "wait", value_parser = duration::parse)]
    pub timeout: Option<Duration>,
    /// Refuse a value older than this (`500ms`): an error naming its age, exit 1. Ages are
    /// on this robot's clock: since reception, plus the frame's estimated network transit
    /// and the age the sender reported.
    #[arg(long, value_parser = duration::parse)]
    pub max_age: Option<Duration>,
    #[command(flatten)]
    pub relay: RelayAddr,
}

/// `huddle set KEY VALUE`
#[derive(Args, Debug)]
pub struct SetArgs {
    /// Key: `*.var.x`, `local.var.x`; `*.talk.q` posts a message.
    pub key: String,
    /// Value: a literal (`42`, `4.2`, `true`, `'"text"'`, `'[1, 2]'`, `0x0a0b`), or bare
    /// words, sent as a string (`attack`, `kick off`). The rule: what reads as a literal
    /// is that literal; what does not, and does not start like one (a digit, sign, dot,
    /// `"` or `[`), is a string. So `42` and `true` are a number and a bool: write
    /// `'"42"'` for the text. Several words are joined by spaces.
    #[arg(required = true, num_args = 1.., allow_negative_numbers = true)]
    pub value: Vec<String>,
    /// Send it again every period (`100ms`), like `ros2 topic pub --rate`, until
    /// interrupted or `--count` sends. Each send restamps the value (its age starts
    /// again); `echo` and `hz` see changes only, so an unchanged value shows once there.
    #[arg(long, value_parser = duration::parse_positive, value_name = "PERIOD")]
    pub every: Option<Duration>,
    /// With `--every`: stop after this many sends.
    #[arg(long, short = 'n', value_name = "N", requires = "every")]
    pub count: Option<u64>,
    #[command(flatten)]
    pub relay: RelayAddr,
}

/// The literal `huddle set` sends for its VALUE words: a literal as typed, bare words as
/// a string (see `SetArgs::value`). A malformed literal (`[1, 2`, `1.2.3`, `"open`) is
/// an error saying what is wrong, not a string.
pub fn value_literal(words: &[String]) -> Result<String> {
    let text = words.join(" ");
    match comms::parse_literal(&text) {
        Ok(_) => Ok(text),
        Err(e) => {
            let starts_like_a_literal = text.trim_start().starts_with(|c: char| {
                c.is_ascii_digit() || matches!(c, '-' | '+' | '.' | '"' | '[')
            });
            if starts_like_a_literal || text.trim().is_empty() {
                bail!("{text:?} is not a value: {e} (bare words are sent as a string; quote a number to send it as text: '\"42\"')");
            }
            Ok(comms::Value::String(text).to_string())
        }
    }
}

/// `huddle keys [PATTERN]`
#[derive(Args, Debug)]
pub struct KeysArgs {
    /// Pattern: `+` one level, `#` the rest (default `#`: every key).
    #[arg(default_value = "#")]
    pub pattern: String,
    /// With each key its owner, type, value and age.
    #[arg(long, short)]
    pub long: bool,
    /// One JSON object per line (as `get --json`).
    #[arg(long)]
    pub json: bool,
    /// Also the daemon's own keys (`local.var.huddle.*`: its counters, see `huddle
    /// stats`), hidden otherwise unless PATTERN names them.
    #[arg(long, short = 'a')]
    pub all: bool,
    #[command(flatten)]
    pub relay: RelayAddr,
}

/// Keys of the daemon's own (its counters) and of client probes: listed by `keys` only
/// with `--all`, or when the pattern asks for them by name.
fn is_internal(key: &str) -> bool {
    key.starts_with("local.var.huddle.") || key.starts_with("local.var.huddle_client.")
}

/// What to say when a pattern matched nothing: most often a key was given where a
/// pattern of its children was meant (`1.var.ball` for `1.var.ball.#`).
pub fn no_match_hint(pattern: &str) -> String {
    if pattern.ends_with('#') {
        format!("no key matches {pattern}")
    } else {
        format!("no key matches {pattern} (patterns match whole keys: for the keys under it, try {pattern}.#)")
    }
}

/// `huddle echo PATTERN...`
#[derive(Args, Debug)]
pub struct EchoArgs {
    /// Patterns: `+` one level, `#` the rest (`+.var.ball.#`, `+.talk.plan`).
    #[arg(required = true)]
    pub patterns: Vec<String>,
    /// One JSON object per line: time, owner, key, type, value, age_ms.
    #[arg(long)]
    pub json: bool,
    /// Exit after this many updates.
    #[arg(long, short = 'n', value_name = "N")]
    pub count: Option<u64>,
    #[command(flatten)]
    pub relay: RelayAddr,
}

/// `huddle stats`
#[derive(Args, Debug)]
pub struct StatsArgs {
    /// Print one JSON object: every counter, drops by reason, peers' last-heard age.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub relay: RelayAddr,
}

fn print_binding(out: &mut impl Write, b: &Binding, json: bool, robot: Option<u8>) -> Result<()> {
    if json {
        writeln!(out, "{}", binding_json(b, robot))?;
    } else {
        let departed = if b.departed { ", owner departed" } else { "" };
        writeln!(
            out,
            "{} {} {} (age {} ms{departed})",
            b.key, b.ty, b.value, b.age_ms
        )?;
    }
    Ok(())
}

/// `huddle get`
pub fn get(args: GetArgs) -> Result<()> {
    let mut c = RelayClient::connect(&args.relay.relay)?;
    let started = Instant::now();
    let b = loop {
        match c.get(&args.key, args.max_age)? {
            Some(b) => break b,
            None if !args.wait => bail!("no value for {} (wait for it with --wait)", args.key),
            None => match args.timeout {
                Some(limit) if started.elapsed() >= limit => {
                    bail!("no value for {} after {}", args.key, duration::show(limit))
                }
                _ => std::thread::sleep(Duration::from_millis(20)),
            },
        }
    };
    print_binding(&mut std::io::stdout().lock(), &b, args.json, c.robot())?;
    let _ = c.send("QUIT");
    Ok(())
}

/// `huddle set`
pub fn set(args: SetArgs) -> Result<()> {
    let line = format!("SETV {} {}", args.key, value_literal(&args.value)?);
    let mut c = RelayClient::connect(&args.relay.relay)?;
    c.request(&line)?;
    if let Some(period) = args.every {
        // Paced on a schedule, not by sleeping a period after each send, so the rate
        // holds whatever a round trip takes.
        let start = Instant::now();
        let mut sent = 1u64;
        while args.count.is_none_or(|n| sent < n) {
            let next = start + period.mul_f64(sent as f64);
            if let Some(wait) = next.checked_duration_since(Instant::now()) {
                std::thread::sleep(wait);
            }
            c.request(&line)?;
            sent += 1;
        }
    }
    let _ = c.send("QUIT");
    Ok(())
}

/// `huddle keys`
pub fn keys(args: KeysArgs) -> Result<()> {
    let mut c = RelayClient::connect(&args.relay.relay)?;
    let robot = c.robot();
    let mut all = c.snapshot(&[args.pattern.as_str()])?;
    let asked_for_internal = is_internal(&args.pattern);
    let matched = all.len();
    if !(args.all || asked_for_internal) {
        all.retain(|b| !is_internal(&b.key));
    }
    if matched == 0 {
        eprintln!("{}", no_match_hint(&args.pattern));
    } else if all.is_empty() {
        eprintln!(
            "only the daemon's own keys match {} ({matched}; list them with --all)",
            args.pattern
        );
    }
    let mut out = std::io::stdout().lock();
    for b in &all {
        if args.json {
            writeln!(out, "{}", binding_json(b, robot))?;
        } else if args.long {
            writeln!(
                out,
                "{}\t{}\t{}\t{}\t{}ms",
                b.key,
                owner_id(b, robot).map_or_else(|| b.owner().to_owned(), |o| o.to_string()),
                b.ty,
                b.value,
                b.age_ms
            )?;
        } else {
            writeln!(out, "{}", b.key)?;
        }
    }
    Ok(())
}

/// One pushed line as `echo` prints it; `None` for lines that are not news.
fn echo_line(line: &str, json: bool, robot: Option<u8>) -> Option<String> {
    let time = utc_now();
    if let Some(b) = Binding::parse(line) {
        return Some(if json {
            let mut v = binding_json(&b, robot);
            v["time"] = json!(time);
            v.to_string()
        } else {
            format!(
                "{time}\t{}\t{}\t{}\t{}ms",
                owner_id(&b, robot).map_or_else(|| b.owner().to_owned(), |o| o.to_string()),
                b.key,
                b.value,
                b.age_ms
            )
        });
    }
    // Talk messages given up by the replica (`LOST …`): never dropped silently.
    let lost = line.strip_prefix("LOST ")?;
    Some(if json {
        json!({"time": time, "lost": lost}).to_string()
    } else {
        format!("{time}\tLOST\t{lost}")
    })
}

/// `huddle echo`: each change as it happens, one line each (like `mosquitto_sub -v` or
/// `ros2 topic echo`), reconnecting when the daemon restarts.
pub fn echo(args: EchoArgs) -> Result<()> {
    let feed = Feed::start(args.relay.relay.clone(), args.patterns.clone(), 0)?;
    let mut out = std::io::stdout().lock();
    let mut printed = 0u64;
    let mut robot = None;
    if args.count == Some(0) {
        return Ok(());
    }
    loop {
        match feed.next()? {
            FeedEvent::Line(line) => match echo_line(&line, args.json, robot) {
                Some(text) => {
                    writeln!(out, "{text}")?;
                    out.flush()?;
                    printed += 1;
                    if args.count.is_some_and(|n| printed >= n) {
                        return Ok(());
                    }
                }
                None => tracing::warn!("relay: {line}"),
            },
            FeedEvent::Connected(greeting) => {
                robot = greeting_robot(&greeting);
                tracing::info!(%greeting, "reconnected to the relay")
            }
            FeedEvent::Down { reason, retry_in } => tracing::warn!(
                "{reason}; reconnecting to {} in {}",
                args.relay.relay,
                duration::show(retry_in)
            ),
        }
    }
}

/// The daemon's counters, read from `local.var.huddle.stats.#`.
pub fn fetch_stats(relay: &RelayTarget) -> Result<Vec<Binding>> {
    RelayClient::connect(relay)?.snapshot(&["local.var.huddle.stats.#"])
}

fn stat_name(b: &Binding) -> &str {
    b.key.trim_start_matches("local.var.huddle.stats.")
}

/// `huddle stats --json`: counters by name, `drops` by reason, `peers` by robot.
fn stats_json(all: &[Binding]) -> serde_json::Value {
    let mut counters = serde_json::Map::new();
    let mut drops = BTreeMap::new();
    let mut peers = BTreeMap::new();
    for b in all {
        let n = stat_name(b);
        let v: i64 = b.value.parse().unwrap_or(0);
        if let Some(reason) = n.strip_prefix("drops.") {
            drops.insert(reason.to_owned(), v);
        } else if let Some(robot) = n
            .strip_prefix("peer.")
            .and_then(|r| r.strip_suffix(".last_heard_us"))
        {
            peers.insert(robot.to_owned(), json!({ "last_heard_ms": b.age_ms }));
        } else {
            counters.insert(n.to_owned(), json!(v));
        }
    }
    counters.insert("drops".into(), json!(drops));
    counters.insert("peers".into(), json!(peers));
    serde_json::Value::Object(counters)
}

/// `huddle stats`
pub fn stats(args: StatsArgs) -> Result<()> {
    let all = fetch_stats(&args.relay.relay)?;
    let mut out = std::io::stdout().lock();
    if args.json {
        writeln!(out, "{}", stats_json(&all))?;
    } else {
        write!(out, "{}", stats_text(&all))?;
    }
    Ok(())
}

/// The counters `huddle stats` names on its own lines (`stats_text`); every other
/// mirrored counter goes on its `also` line when it is not 0, so that a counter added to
/// the mirror is never invisible in the human form (`--json` has them all).
const STATS_NAMED: [&str; 12] = [
    "frames_in",
    "frames_out",
    "bytes_in",
    "bytes_out",
    "updates_applied",
    "updates_stale",
    "talk_delivered",
    "talk_given_up",
    "talk_unknown_value",
    "talk_resent",
    "nacks_sent",
    "drops.total",
];

/// Drops and refusals of the I/O layer, by the names the daemon mirrors them under
/// (`driver::IoStats::dropped`, one list; older daemons mirror fewer or none), and the
/// replica's NACKs held back, on their own line when not 0.
fn stats_io() -> impl Iterator<Item = &'static str> {
    driver::IoStats::default()
        .dropped()
        .into_iter()
        .map(|(name, _)| name)
        .chain(["nacks_limited"])
}

/// `huddle stats` without `--json`: a few lines for people.
fn stats_text(all: &[Binding]) -> String {
    use std::fmt::Write as _;
    let get = |n: &str| {
        all.iter()
            .find(|b| stat_name(b) == n)
            .map(|b| b.value.clone())
    };
    let or0 = |n: &str| get(n).unwrap_or_else(|| "0".into());
    let mut out = String::new();
    // Writing into a String cannot fail.
    let _ = writeln!(
        out,
        "frames in {}  out {}   bytes in {}  out {}",
        or0("frames_in"),
        or0("frames_out"),
        or0("bytes_in"),
        or0("bytes_out")
    );
    let _ = writeln!(
        out,
        "updates applied {}  stale {}   talk delivered {}  given up {}  unknown value {}  \
         resent {}  nacks {}",
        or0("updates_applied"),
        or0("updates_stale"),
        or0("talk_delivered"),
        or0("talk_given_up"),
        or0("talk_unknown_value"),
        or0("talk_resent"),
        or0("nacks_sent")
    );
    let drops: Vec<String> = all
        .iter()
        .filter_map(|b| {
            let reason = stat_name(b).strip_prefix("drops.")?;
            (reason != "total" && b.value != "0").then(|| format!("{reason} {}", b.value))
        })
        .collect();
    let _ = writeln!(
        out,
        "drops {}{}",
        or0("drops.total"),
        if drops.is_empty() {
            String::new()
        } else {
            format!(" ({})", drops.join(", "))
        }
    );
    let io: Vec<String> = stats_io()
        .filter_map(|n| get(n).filter(|v| v != "0").map(|v| format!("{n} {v}")))
        .collect();
    if !io.is_empty() {
        let _ = writeln!(out, "dropped or refused {}", io.join("  "));
    }
    // Only a daemon that speaks or listens (`--audio-in`, `--audio-out`) has these.
    let audio: Vec<String> = all
        .iter()
        .filter_map(|b| {
            Some(format!(
                "{} {}",
                stat_name(b).strip_prefix("audio.")?,
                b.value
            ))
        })
        .collect();
    if !audio.is_empty() {
        let _ = writeln!(out, "audio {}", audio.join("  "));
    }
    // Every other counter that is not 0 (the replica's refusals, clock estimates, the
    // GameController listener's counts, ...).
    let also: Vec<String> = all
        .iter()
        .filter(|b| {
            let n = stat_name(b);
            !STATS_NAMED.contains(&n)
                && !stats_io().any(|io| io == n)
                && !n.starts_with("drops.")
                && !n.starts_with("audio.")
                && !n.starts_with("peer.")
                && b.value != "0"
        })
        .map(|b| format!("{} {}", stat_name(b), b.value))
        .collect();
    if !also.is_empty() {
        let _ = writeln!(out, "also {}", also.join("  "));
    }
    for b in all {
        if let Some(robot) = stat_name(b)
            .strip_prefix("peer.")
            .and_then(|r| r.strip_suffix(".last_heard_us"))
        {
            // The counter is mirrored once per refresh period when it moves, so its age
            // is the time since the peer was last heard, to within one period.
            let _ = writeln!(out, "peer {robot}: last heard {} ms ago", b.age_ms);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn echo_prints_time_owner_key_value_age_and_never_drops_a_loss() {
        let line = echo_line("UPD 3.var.ball.dist float 1.5 12", false, Some(1)).unwrap();
        let fields: Vec<&str> = line.split('\t').collect();
        assert_eq!(&fields[1..], ["3", "3.var.ball.dist", "1.5", "12ms"]);
        let v: serde_json::Value =
            serde_json::from_str(&echo_line("UPD 3.var.n int 7 0", true, Some(1)).unwrap())
                .unwrap();
        assert_eq!(v["value"], json!(7));
        assert_eq!(v["owner"], json!(3), "an integer, as in /state and Python");
        assert!(v["time"].is_string());
        let local: serde_json::Value =
            serde_json::from_str(&echo_line("UPD local.var.n int 7 0", true, Some(4)).unwrap())
                .unwrap();
        assert_eq!(
            local["owner"],
            json!(4),
            "a local key is the relay's robot's"
        );
        let lost = echo_line("LOST 3.talk.plan 4 6", false, None).unwrap();
        assert!(lost.ends_with("\tLOST\t3.talk.plan 4 6"), "{lost}");
        assert_eq!(echo_line("OK", false, None), None);
    }

    #[test]
    fn bare_words_are_strings_and_literals_stay_literals() {
        let lit = |words: &[&str]| {
            value_literal(&words.iter().map(|w| w.to_string()).collect::<Vec<_>>())
                .map_err(|e| e.to_string())
        };
        assert_eq!(lit(&["attack"]).unwrap(), "\"attack\"");
        assert_eq!(lit(&["kick", "off"]).unwrap(), "\"kick off\"");
        assert_eq!(lit(&["42"]).unwrap(), "42");
        assert_eq!(lit(&["-1.5"]).unwrap(), "-1.5");
        assert_eq!(lit(&["true"]).unwrap(), "true");
        assert_eq!(lit(&["\"42\""]).unwrap(), "\"42\"");
        assert_eq!(lit(&["[1,", "2]"]).unwrap(), "[1, 2]");
        assert_eq!(lit(&["0x0a0b"]).unwrap(), "0x0a0b");
        assert_eq!(lit(&["say \"hi\""]).unwrap(), "\"say \\\"hi\\\"\"");
        for typo in [&["[1,", "2"][..], &["1.2.3"], &["\"open"]] {
            assert!(
                lit(typo).is_err(),
                "{typo:?} is a malformed literal, not a string"
            );
        }
    }

    #[test]
    fn an_empty_match_suggests_the_children_pattern() {
        assert!(no_match_hint("1.var.ball").contains("1.var.ball.#"));
        assert!(!no_match_hint("1.var.#").contains("try"));
        assert!(is_internal("local.var.huddle.stats.frames_in"));
        assert!(!is_internal("local.var.huddlex"));
    }

    #[test]
    fn stats_json_groups_drops_and_peers() {
        let b = |line: &str| Binding::parse(line).unwrap();
        let all = [
            b("UPD local.var.huddle.stats.frames_in int 10 0"),
            b("UPD local.var.huddle.stats.drops.total int 2 0"),
            b("UPD local.var.huddle.stats.drops.garbage int 2 0"),
            b("UPD local.var.huddle.stats.peer.3.last_heard_us int 99 40"),
        ];
        let v = stats_json(&all);
        assert_eq!(v["frames_in"], json!(10));
        assert_eq!(v["drops"]["garbage"], json!(2));
        assert_eq!(v["peers"]["3"]["last_heard_ms"], json!(40));
    }

    #[test]
    fn stats_text_names_every_counter_that_is_not_zero() {
        // A daemon whose replica acknowledged one talk message of a newer build's value
        // type, cut off two relay clients and saw a stale GameController packet.
        let b = |line: &str| Binding::parse(line).unwrap();
        let all = [
            b("UPD local.var.huddle.stats.frames_in int 10 0"),
            b("UPD local.var.huddle.stats.talk_given_up int 0 0"),
            b("UPD local.var.huddle.stats.talk_unknown_value int 1 0"),
            b("UPD local.var.huddle.stats.items_skipped int 0 0"),
            b("UPD local.var.huddle.stats.clock_outliers int 4 0"),
            b("UPD local.var.huddle.stats.gc.stale int 1 0"),
            b("UPD local.var.huddle.stats.relay_cutoffs int 2 0"),
            b("UPD local.var.huddle.stats.drops.total int 0 0"),
            b("UPD local.var.huddle.stats.peer.3.last_heard_us int 99 40"),
        ];
        let text = stats_text(&all);
        assert!(
            text.contains("given up 0  unknown value 1  resent 0"),
            "talk_unknown_value is on the talk line:\n{text}"
        );
        assert!(
            text.contains("dropped or refused relay_cutoffs 2\n"),
            "{text}"
        );
        assert!(
            text.contains("also clock_outliers 4  gc.stale 1\n"),
            "counters without a line of their own are listed when not 0:\n{text}"
        );
        assert!(!text.contains("items_skipped"), "zeros stay out:\n{text}");
        assert!(text.ends_with("peer 3: last heard 40 ms ago\n"), "{text}");
    }
}
