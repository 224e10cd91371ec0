//! `huddle watch`: the seed's Monitor. On a terminal, a live table of key, owner, age and
//! value that fits the window (long lines cut, rows that do not fit scroll by a page every
//! few seconds), the robots heard and the ones departed, and the talk queues' latest
//! messages and losses; on a pipe, one line per update. Either way it reconnects with
//! backoff when the daemon restarts.
//!
//! On a terminal it is calm: it draws on the alternate screen and overwrites the table in
//! place (cursor home, each line cleared to its end; never a whole-screen clear, which
//! flickers), numbers show 6 significant digits, and `q` (or Ctrl-C) quits and gives the
//! terminal back as it was.

use std::collections::{BTreeMap, VecDeque};
use std::io::{IsTerminal, Write};
use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use clap::Args;
use comms::relay::{Binding, MAX_REFRESH_MS};
use comms::{Key, Pattern};

use super::duration;
use super::feed::{Feed, FeedEvent};
use super::relay::{utc_now, RelayAddr};

/// The daemon's record of when each peer was last heard (its age is the silence).
const PEER_STATS: &str = "local.var.huddle.stats.peer.+.last_heard_us";

/// How long one page of rows stays up when they do not all fit.
const PAGE_TIME: Duration = Duration::from_secs(3);

/// `huddle watch PATTERN...`
#[derive(Args, Debug)]
pub struct WatchArgs {
    /// Patterns: `+` one level, `#` the rest (`+.var.machine.#`, `2.var.#`, `+.talk.plan`).
    #[arg(required = true)]
    pub patterns: Vec<String>,
    /// Refresh interval (`500ms`, `1s`; `0s` pushes each change as it happens).
    #[arg(long, default_value = "500ms", value_parser = duration::parse)]
    pub interval: Duration,
    /// A robot not heard for this long is marked departed (plus one `--interval`: the
    /// table learns when a robot was heard only once per interval).
    #[arg(long, default_value = "1s", value_parser = duration::parse_positive)]
    pub departed: Duration,
    /// Latest messages shown per talk queue.
    #[arg(long, default_value_t = 3, value_name = "N")]
    pub messages: usize,
    #[command(flatten)]
    pub relay: RelayAddr,
}

/// Everything the table shows.
struct View {
    patterns: Vec<Pattern>,
    robot: Option<u8>,
    values: BTreeMap<String, (Binding, Instant)>,
    /// Per talk queue (`3.talk.plan`): the latest messages, with the time they came.
    talk: BTreeMap<String, VecDeque<(String, String)>>,
    /// `LOST` lines, latest last, with the time they came.
    losses: VecDeque<(String, String)>,
    /// Peers, and when they were last heard (now − the stat's age).
    peers: BTreeMap<u8, Instant>,
    departed_after: Duration,
    departed: Vec<u8>,
    status: Option<String>,
    keep: usize,
}

impl View {
    fn shows(&self, key: &str) -> bool {
        Key::parse(key).is_ok_and(|k| self.patterns.iter().any(|p| p.matches(&k)))
    }

    /// Takes one pushed line; returns what a pipe prints for it, if anything.
    fn take(&mut self, line: &str) -> Option<String> {
        let now = Instant::now();
        if let Some(lost) = line.strip_prefix("LOST ") {
            self.losses
                .push_back((utc_now()[11..19].to_owned(), lost.to_owned()));
            while self.losses.len() > self.keep.max(1) {
                self.losses.pop_front();
            }
            return Some(format!("LOST {lost}"));
        }
        let Some(b) = Binding::parse(line) else {
            tracing::warn!("relay: {line}");
            return None;
        };
        if let Some(robot) = b
            .key
            .strip_prefix("local.var.huddle.stats.peer.")
            .and_then(|r| r.strip_suffix(".last_heard_us"))
            .and_then(|r| r.parse::<u8>().ok())
        {
            let heard = now
                .checked_sub(Duration::from_millis(b.age_ms))
                .unwrap_or(now);
            self.peers.insert(robot, heard);
        }
        if !self.shows(&b.key) {
            return None;
        }
        let piped = format!("{}\t{}\t{}\t{} ms", b.key, b.owner(), b.value, b.age_ms);
        if b.key.split('.').nth(1) == Some("talk") {
            let queue = self.talk.entry(b.key.clone()).or_default();
            queue.push_back((utc_now()[11..19].to_owned(), b.value.clone()));
            while queue.len() > self.keep.max(1) {
                queue.pop_front();
            }
        } else {
            self.values.insert(b.key.clone(), (b, now));
        }
        Some(piped)
    }

    /// Robots that just went silent for longer than `departed_after`.
    fn newly_departed(&mut self) -> Vec<(u8, Duration)> {
        let mut news = Vec::new();
        for (&robot, heard) in &self.peers {
            let silent = heard.elapsed();
            let gone = silent > self.departed_after;
            let known = self.departed.contains(&robot);
            if gone && !known {
                news.push((robot, silent));
            }
        }
        self.departed = self
            .peers
            .iter()
            .filter(|(_, h)| h.elapsed() > self.departed_after)
            .map(|(r, _)| *r)
            .collect();
        news
    }

    fn robots_line(&self) -> String {
        let mut parts = Vec::new();
        if let Some(me) = self.robot {
            parts.push(format!("{me} (this)"));
        }
        for (robot, heard) in &self.peers {
            let silent = heard.elapsed();
            if self.departed.contains(robot) {
                parts.push(format!("{robot} DEPARTED {:.1}s ago", silent.as_secs_f64()));
            } else {
                parts.push(format!("{robot} {}ms", silent.as_millis()));
            }
        }
        format!("robots: {}", parts.join(" · "))
    }

    /// The whole screen as lines, before fitting to the window.
    fn render(&self, title: &str, rows_fit: impl Fn(usize) -> usize, page: u64) -> Vec<String> {
        let mut head = vec![title.to_owned()];
        head.push(match &self.status {
            Some(s) => s.clone(),
            None => self.robots_line(),
        });
        head.push(format!("{:<40} {:>10} {:>9}  value", "key", "owner", "age"));
        let mut tail = Vec::new();
        if !self.talk.is_empty() || !self.losses.is_empty() {
            tail.push("talk (latest messages):".to_owned());
        }
        for (queue, msgs) in &self.talk {
            let shown: Vec<String> = msgs.iter().map(|(t, v)| format!("{t} {v}")).collect();
            tail.push(format!("  {queue:<24} {}", shown.join(" · ")));
        }
        for (t, lost) in &self.losses {
            tail.push(format!("  LOST {lost} (at {t})"));
        }
        let rows: Vec<String> = self
            .values
            .values()
            .map(|(b, seen)| {
                let age_ms = b.age_ms + seen.elapsed().as_millis() as u64;
                let owner = match b.owner().parse::<u8>() {
                    Ok(r) if self.departed.contains(&r) => format!("{r} gone"),
                    _ => b.owner().to_owned(),
                };
                format!(
                    "{:<40} {:>10} {:>6} ms  {}",
                    b.key,
                    owner,
                    age_ms,
                    short_value(&b.value)
                )
            })
            .collect();
        let fit = rows_fit(head.len() + tail.len()).max(1);
        let mut lines = head;
        if rows.len() <= fit {
            lines.extend(rows);
        } else {
            // Scroll: one page at a time, a footer line saying where we are.
            let per_page = fit.saturating_sub(1).max(1);
            let pages = rows.len().div_ceil(per_page);
            let first = (page as usize % pages) * per_page;
            let last = (first + per_page).min(rows.len());
            lines.extend(rows[first..last].iter().cloned());
            lines.push(format!(
                "rows {}–{} of {} (page {} of {}, next in {}s)",
                first + 1,
                last,
                rows.len(),
                first / per_page + 1,
                pages,
                PAGE_TIME.as_secs()
            ));
        }
        lines.extend(tail);
        lines
    }
}

/// A number with 6 significant digits, as `%g` writes it (`0.333333`, `1.23457e+06`).
fn significant(x: f64) -> String {
    if !x.is_finite() || x == 0.0 {
        return comms::Value::Float(x).to_string();
    }
    let exp = x.abs().log10().floor() as i32;
    if !(-4..6).contains(&exp) {
        let text = format!("{x:.5e}");
        let (mantissa, e) = text.split_once('e').unwrap_or((&text, "0"));
        let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
        let e: i32 = e.parse().unwrap_or(0);
        return format!("{mantissa}e{}{:02}", if e < 0 { '-' } else { '+' }, e.abs());
    }
    let decimals = (5 - exp).max(0) as usize;
    let text = format!("{x:.decimals$}");
    if text.contains('.') {
        text.trim_end_matches('0').trim_end_matches('.').to_owned()
    } else {
        text
    }
}

/// A value literal as the table shows it: floats (alone or in a list) to 6 significant
/// digits; anything else as it is.
fn short_value(literal: &str) -> String {
    match comms::parse_literal(literal) {
        Ok(comms::Value::Float(x)) => significant(x),
        Ok(comms::Value::Floats(v)) => {
            let items: Vec<String> = v.iter().map(|&x| significant(x)).collect();
            format!("[{}]", items.join(", "))
        }
        _ => literal.to_owned(),
    }
}

/// One redraw in place: cursor home, each line followed by clear-to-end-of-line, then
/// clear below. Nothing is cleared before it is overwritten, so nothing flickers.
fn frame(lines: &[String]) -> String {
    let mut out = String::from("\x1b[H");
    for line in lines {
        out.push_str(line);
        out.push_str("\x1b[K\r\n");
    }
    out.push_str("\x1b[J");
    out
}

/// Whether a key typed at the table ends it: `q`, `Q`, Ctrl-C (read as a byte, the
/// terminal's signals being off), Ctrl-D.
fn quits(byte: u8) -> bool {
    matches!(byte, b'q' | b'Q' | 0x03 | 0x04)
}

/// The terminal while the table is up: keys read one by one without echo (so `q` quits
/// at once), the alternate screen, no cursor. Dropping it restores all three.
struct Screen {
    saved_stty: Option<String>,
}

impl Screen {
    fn stty(args: &[&str]) -> Option<String> {
        let tty = std::fs::File::open("/dev/tty").ok()?;
        let out = std::process::Command::new("stty")
            .args(args)
            .stdin(tty)
            .stderr(std::process::Stdio::null())
            .output()
            .ok()?;
        out.status
            .success()
            .then(|| String::from_utf8_lossy(&out.stdout).trim().to_owned())
    }

    /// Takes the terminal over; `keys` then receives each byte typed.
    fn open(out: &mut impl Write) -> Result<(Screen, std::sync::mpsc::Receiver<u8>)> {
        let saved_stty = Screen::stty(&["-g"]);
        if saved_stty.is_some() {
            Screen::stty(&["-icanon", "-echo", "-isig", "min", "1"]);
        }
        let (tx, rx) = std::sync::mpsc::channel();
        if saved_stty.is_some() {
            std::thread::spawn(move || {
                use std::io::Read as _;
                let Ok(mut tty) = std::fs::File::open("/dev/tty") else {
                    return;
                };
                let mut byte = [0u8; 1];
                while let Ok(1) = tty.read(&mut byte) {
                    if tx.send(byte[0]).is_err() {
                        return;
                    }
                }
            });
        }
        // Alternate screen, cursor hidden.
        write!(out, "\x1b[?1049h\x1b[?25l")?;
        out.flush()?;
        Ok((Screen { saved_stty }, rx))
    }
}

impl Drop for Screen {
    fn drop(&mut self) {
        let mut out = std::io::stdout();
        let _ = write!(out, "\x1b[?25h\x1b[?1049l");
        let _ = out.flush();
        if let Some(saved) = &self.saved_stty {
            Screen::stty(&[saved.as_str()]);
        }
    }
}

/// Cuts a line to `width` columns (characters), marking the cut with `…`.
fn fit_width(line: &str, width: usize) -> String {
    if line.chars().count() <= width {
        return line.to_owned();
    }
    let mut s: String = line.chars().take(width.saturating_sub(1)).collect();
    s.push('…');
    s
}

/// The terminal's (columns, rows): `COLUMNS`/`LINES` if set, else `stty size` on the
/// controlling terminal, else 80×24.
fn terminal_size() -> (usize, usize) {
    let env = |name: &str| std::env::var(name).ok()?.trim().parse::<usize>().ok();
    if let (Some(c), Some(r)) = (env("COLUMNS"), env("LINES")) {
        return (c, r);
    }
    let stty = std::fs::File::open("/dev/tty").ok().and_then(|tty| {
        let out = std::process::Command::new("stty")
            .arg("size")
            .stdin(tty)
            .stderr(std::process::Stdio::null())
            .output()
            .ok()?;
        let text = String::from_utf8(out.stdout).ok()?;
        let mut it = text.split_whitespace().map(|n| n.parse::<usize>().ok());
        let (rows, cols) = (it.next()??, it.next()??);
        (rows > 0 && cols > 0).then_some((cols, rows))
    });
    stty.unwrap_or((80, 24))
}

/// `huddle watch`
pub fn watch(args: WatchArgs) -> Result<()> {
    let refresh_ms = args.interval.as_millis();
    if refresh_ms > u128::from(MAX_REFRESH_MS) {
        bail!("--interval is at most 1h (the relay's REFR limit)");
    }
    let patterns = args
        .patterns
        .iter()
        .map(|p| Pattern::parse(p).map_err(|e| anyhow::anyhow!("{p:?}: {e}")))
        .collect::<Result<Vec<_>>>()?;
    let mut subscribed = args.patterns.clone();
    subscribed.push(PEER_STATS.to_owned());
    let target = args.relay.relay.clone();
    let feed = Feed::start(target.clone(), subscribed, refresh_ms as u64)?;
    let robot_of = |greeting: &str| greeting.rsplit(' ').next().and_then(|r| r.parse().ok());
    let mut view = View {
        patterns,
        robot: robot_of(&feed.greeting),
        values: BTreeMap::new(),
        talk: BTreeMap::new(),
        losses: VecDeque::new(),
        peers: BTreeMap::new(),
        departed_after: args.departed + args.interval,
        departed: Vec::new(),
        status: None,
        keep: args.messages,
    };
    let tty = std::io::stdout().is_terminal();
    let redraw = args
        .interval
        .clamp(Duration::from_millis(100), Duration::from_secs(1));
    let started = Instant::now();
    let mut next_draw = Instant::now();
    let mut size = (terminal_size(), Instant::now());
    let mut out = std::io::stdout().lock();
    let (screen, keys) = if tty {
        let (screen, keys) = Screen::open(&mut out)?;
        (Some(screen), Some(keys))
    } else {
        (None, None)
    };
    loop {
        if let Some(keys) = &keys {
            if keys.try_iter().any(quits) {
                drop(screen);
                return Ok(());
            }
        }
        let wait = next_draw
            .saturating_duration_since(Instant::now())
            .min(Duration::from_millis(250));
        match feed.next_within(wait)? {
            Some(FeedEvent::Line(line)) => {
                if let Some(piped) = view.take(&line) {
                    if !tty {
                        writeln!(out, "{piped}")?;
                        out.flush()?;
                    }
                }
            }
            Some(FeedEvent::Connected(greeting)) => {
                tracing::info!(%greeting, "reconnected to the relay");
                view.robot = robot_of(&greeting);
                view.status = None;
                // A restarted daemon starts over: forget the old peers' clocks.
                view.peers.clear();
                view.departed.clear();
            }
            Some(FeedEvent::Down { reason, retry_in }) => {
                let status = format!(
                    "relay {target}: {reason}; reconnecting in {}",
                    duration::show(retry_in)
                );
                if !tty {
                    tracing::warn!("{status}");
                }
                view.status = Some(status);
            }
            None => {}
        }
        for (robot, silent) in view.newly_departed() {
            if !tty {
                tracing::warn!(
                    robot,
                    "departed: not heard for {:.1}s",
                    silent.as_secs_f64()
                );
            }
        }
        if tty && Instant::now() >= next_draw {
            if size.1.elapsed() > Duration::from_secs(1) {
                size = (terminal_size(), Instant::now());
            }
            let (cols, rows) = size.0;
            let title = fit_width(
                &format!(
                    "huddle watch {} — {} {}",
                    args.patterns.join(" "),
                    target,
                    &utc_now()[11..19]
                ),
                cols,
            );
            let page = started.elapsed().as_secs() / PAGE_TIME.as_secs();
            let lines = view.render(&title, |fixed| rows.saturating_sub(fixed + 1), page);
            let fitted: Vec<String> = lines.iter().map(|l| fit_width(l, cols)).collect();
            write!(out, "{}", frame(&fitted))?;
            out.flush()?;
            next_draw = Instant::now() + redraw;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(patterns: &[&str]) -> View {
        View {
            patterns: patterns
                .iter()
                .map(|p| Pattern::parse(p).unwrap())
                .collect(),
            robot: Some(2),
            values: BTreeMap::new(),
            talk: BTreeMap::new(),
            losses: VecDeque::new(),
            peers: BTreeMap::new(),
            departed_after: Duration::from_millis(50),
            departed: Vec::new(),
            status: None,
            keep: 2,
        }
    }

    #[test]
    fn numbers_show_six_significant_digits() {
        assert_eq!(short_value("0.30000000000000004"), "0.3");
        assert_eq!(short_value("3.141592653589793"), "3.14159");
        assert_eq!(short_value("1234567.89"), "1.23457e+06");
        assert_eq!(short_value("0.000012345678"), "1.23457e-05");
        assert_eq!(short_value("-2.0"), "-2");
        assert_eq!(short_value("[0.1, 2.718281828459045]"), "[0.1, 2.71828]");
        assert_eq!(short_value("42"), "42", "ints as they are");
        assert_eq!(short_value("\"text 0.123456789\""), "\"text 0.123456789\"");
    }

    #[test]
    fn a_redraw_overwrites_in_place_and_q_quits() {
        let f = frame(&["title".into(), "row".into()]);
        assert!(f.starts_with("\x1b[H"), "cursor home first: {f:?}");
        assert!(
            !f.contains("\x1b[2J"),
            "no whole-screen clear (it flickers): {f:?}"
        );
        assert_eq!(
            f.matches("\x1b[K").count(),
            2,
            "each line cleared to its end"
        );
        assert!(f.ends_with("\x1b[J"), "what is below the table is cleared");
        assert!(quits(b'q') && quits(b'Q') && quits(0x03));
        assert!(!quits(b'x') && !quits(b'\n'));
    }

    #[test]
    fn rows_that_do_not_fit_scroll_a_page_at_a_time() {
        let mut v = view(&["+.var.#"]);
        for i in 0..10 {
            v.take(&format!("UPD 3.var.k{i} int {i} 0"));
        }
        // 3 header lines; room for 5 more: 4 rows and the footer.
        let page0 = v.render("t", |fixed| 8 - fixed, 0);
        assert_eq!(page0.len(), 8, "{page0:#?}");
        assert!(page0[3].starts_with("3.var.k0"));
        assert!(page0[7].starts_with("rows 1–4 of 10"), "{page0:#?}");
        let page2 = v.render("t", |fixed| 8 - fixed, 2);
        assert!(page2[3].starts_with("3.var.k8"), "{page2:#?}");
        let page3 = v.render("t", |fixed| 8 - fixed, 3);
        assert_eq!(page3[3], page0[3], "pages wrap around");
        assert_eq!(fit_width("abcdef", 4), "abc…");
        assert_eq!(fit_width("abc", 4), "abc");
    }

    #[test]
    fn talk_messages_are_kept_per_queue_and_losses_shown() {
        let mut v = view(&["+.talk.plan"]);
        for m in ["\"a\"", "\"b\"", "\"c\""] {
            assert!(v.take(&format!("UPD 3.talk.plan string {m} 0")).is_some());
        }
        assert_eq!(
            v.take("LOST 3.talk.plan 4 6").as_deref(),
            Some("LOST 3.talk.plan 4 6")
        );
        let screen = v.render("t", |_| 20, 0).join("\n");
        assert!(
            screen.contains("\"b\" · ") && screen.contains("\"c\""),
            "{screen}"
        );
        assert!(!screen.contains("\"a\""), "only the latest two: {screen}");
        assert!(screen.contains("LOST 3.talk.plan 4 6"), "{screen}");
    }

    #[test]
    fn a_silent_robot_is_marked_departed() {
        let mut v = view(&["3.var.#"]);
        v.take("UPD local.var.huddle.stats.peer.3.last_heard_us int 5 0");
        v.take("UPD 3.var.x int 1 0");
        assert!(v.newly_departed().is_empty());
        std::thread::sleep(Duration::from_millis(80));
        assert_eq!(v.newly_departed().len(), 1);
        assert!(v.newly_departed().is_empty(), "reported once");
        let screen = v.render("t", |_| 20, 0).join("\n");
        assert!(screen.contains("3 DEPARTED"), "{screen}");
        assert!(screen.contains("3 gone"), "{screen}");
        assert!(
            !screen.contains("last_heard_us"),
            "the peer stat is not a row"
        );
    }
}
