//! `huddle hz PATTERN...`: how often each matching key changes, like `ros2 topic hz`:
//! per key, the rate over a sliding window, the shortest and longest interval between
//! updates, the jitter (standard deviation of the intervals) and the value's age now (on
//! the owner's clock, as the relay reports it, plus the time since it arrived). It counts
//! changes, as the relay pushes them: a value set again unchanged is not one.

use std::collections::{BTreeMap, VecDeque};
use std::io::Write;
use std::time::{Duration, Instant};

use anyhow::Result;
use clap::Args;
use comms::relay::Binding;
use serde_json::json;

use super::duration;
use super::feed::{Feed, FeedEvent};
use super::relay::{utc_now, RelayAddr};

/// `huddle hz PATTERN...`
#[derive(Args, Debug)]
pub struct HzArgs {
    /// Patterns: `+` one level, `#` the rest (`+.var.ball`, `2.var.#`, `+.talk.plan`).
    #[arg(required = true)]
    pub patterns: Vec<String>,
    /// Rates over the updates of the last this long.
    #[arg(long, default_value = "10s", value_parser = duration::parse_positive)]
    pub window: Duration,
    /// Print a report this often.
    #[arg(long, default_value = "1s", value_parser = duration::parse_positive)]
    pub every: Duration,
    /// Stop after this many reports.
    #[arg(long, short = 'n', value_name = "N")]
    pub count: Option<u64>,
    /// One JSON object per report: time, and per key rate_hz, min_ms, max_ms, jitter_ms,
    /// age_ms, updates.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub relay: RelayAddr,
}

/// One key's updates: when they came (on this machine's clock), within the window.
#[derive(Debug, Default)]
struct KeyTimes {
    times: VecDeque<Instant>,
    /// The latest update's age as the relay reported it, and when it arrived.
    last: Option<(u64, Instant, bool)>,
}

/// One key's figures for a report.
#[derive(Debug, Clone, PartialEq)]
pub struct KeyRate {
    /// The key as stored (`3.var.ball`).
    pub key: String,
    /// Updates per second over the window (`None`: fewer than two updates in it).
    pub rate_hz: Option<f64>,
    /// Shortest and longest interval between updates, in ms.
    pub min_ms: Option<f64>,
    /// See `min_ms`.
    pub max_ms: Option<f64>,
    /// Standard deviation of the intervals, in ms.
    pub jitter_ms: Option<f64>,
    /// The value's age now, in ms.
    pub age_ms: u64,
    /// Updates in the window.
    pub updates: usize,
    /// The owner has departed (the relay's flag).
    pub departed: bool,
}

/// Every key's updates; no I/O, time is an argument.
#[derive(Debug)]
pub struct Rates {
    window: Duration,
    keys: BTreeMap<String, KeyTimes>,
}

impl Rates {
    /// Rates over `window`.
    pub fn new(window: Duration) -> Rates {
        Rates {
            window,
            keys: BTreeMap::new(),
        }
    }

    /// An update of `b` that arrived at `now`. A key's first update is placed when it
    /// was set (`now - age`), not when it arrived: it is the snapshot a subscription
    /// starts with, whose arrival says nothing about the key's rate.
    pub fn record(&mut self, b: &Binding, now: Instant) {
        let entry = self.keys.entry(b.key.clone()).or_default();
        let at = if entry.last.is_none() {
            now.checked_sub(Duration::from_millis(b.age_ms))
                .unwrap_or(now)
        } else {
            now
        };
        entry.times.push_back(at);
        entry.last = Some((b.age_ms, now, b.departed));
        Self::trim(&mut entry.times, now, self.window);
    }

    fn trim(times: &mut VecDeque<Instant>, now: Instant, window: Duration) {
        while times
            .front()
            .is_some_and(|&t| now.saturating_duration_since(t) > window)
        {
            times.pop_front();
        }
    }

    /// Each key's figures at `now`, in key order.
    pub fn report(&mut self, now: Instant) -> Vec<KeyRate> {
        let window = self.window;
        self.keys
            .iter_mut()
            .map(|(key, k)| {
                Self::trim(&mut k.times, now, window);
                let intervals: Vec<f64> = k
                    .times
                    .iter()
                    .zip(k.times.iter().skip(1))
                    .map(|(a, b)| b.saturating_duration_since(*a).as_secs_f64() * 1000.0)
                    .collect();
                let (age_ms, departed) = match k.last {
                    Some((age, arrived, departed)) => (
                        age + now.saturating_duration_since(arrived).as_millis() as u64,
                        departed,
                    ),
                    None => (0, false),
                };
                let mut rate = KeyRate {
                    key: key.clone(),
                    rate_hz: None,
                    min_ms: None,
                    max_ms: None,
                    jitter_ms: None,
                    age_ms,
                    updates: k.times.len(),
                    departed,
                };
                if !intervals.is_empty() {
                    let n = intervals.len() as f64;
                    let mean = intervals.iter().sum::<f64>() / n;
                    let var = intervals.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
                    rate.rate_hz = (mean > 0.0).then(|| 1000.0 / mean);
                    rate.min_ms = intervals.iter().copied().reduce(f64::min);
                    rate.max_ms = intervals.iter().copied().reduce(f64::max);
                    rate.jitter_ms = Some(var.sqrt());
                }
                rate
            })
            .collect()
    }
}

fn cell(v: Option<f64>, decimals: usize) -> String {
    v.map_or_else(|| "—".to_owned(), |x| format!("{x:.decimals$}"))
}

/// A report as a table, one line per key.
pub fn table(rates: &[KeyRate]) -> Vec<String> {
    let mut lines = vec![format!(
        "{:<36} {:>9} {:>8} {:>8} {:>9} {:>9} {:>7}",
        "key", "rate Hz", "min ms", "max ms", "jitter ms", "age ms", "updates"
    )];
    for r in rates {
        lines.push(format!(
            "{:<36} {:>9} {:>8} {:>8} {:>9} {:>9} {:>7}{}",
            r.key,
            cell(r.rate_hz, 2),
            cell(r.min_ms, 1),
            cell(r.max_ms, 1),
            cell(r.jitter_ms, 1),
            r.age_ms,
            r.updates,
            if r.departed { "  (owner departed)" } else { "" }
        ));
    }
    lines
}

/// A report as one JSON object.
pub fn report_json(rates: &[KeyRate]) -> serde_json::Value {
    let keys: Vec<serde_json::Value> = rates
        .iter()
        .map(|r| {
            json!({
                "key": r.key,
                "rate_hz": r.rate_hz,
                "min_ms": r.min_ms,
                "max_ms": r.max_ms,
                "jitter_ms": r.jitter_ms,
                "age_ms": r.age_ms,
                "updates": r.updates,
                "departed": r.departed,
            })
        })
        .collect();
    json!({ "time": utc_now(), "keys": keys })
}

/// `huddle hz`
pub fn run(args: HzArgs) -> Result<()> {
    let feed = Feed::start(args.relay.relay.clone(), args.patterns.clone(), 0)?;
    let mut rates = Rates::new(args.window);
    let mut out = std::io::stdout().lock();
    let mut next_report = Instant::now() + args.every;
    let mut reports = 0u64;
    if args.count == Some(0) {
        return Ok(());
    }
    loop {
        let wait = next_report.saturating_duration_since(Instant::now());
        match feed.next_within(wait)? {
            Some(FeedEvent::Line(line)) => {
                if let Some(b) = Binding::parse(&line) {
                    rates.record(&b, Instant::now());
                }
            }
            Some(FeedEvent::Connected(greeting)) => {
                tracing::info!(%greeting, "reconnected to the relay")
            }
            Some(FeedEvent::Down { reason, retry_in }) => tracing::warn!(
                "{reason}; reconnecting to {} in {}",
                args.relay.relay,
                duration::show(retry_in)
            ),
            None => {}
        }
        let now = Instant::now();
        if now < next_report {
            continue;
        }
        next_report += args.every;
        let report = rates.report(now);
        if args.json {
            writeln!(out, "{}", report_json(&report))?;
        } else if report.is_empty() {
            writeln!(
                out,
                "no updates yet for {} (patterns match whole keys: `1.var.ball.#` for the keys under 1.var.ball)",
                args.patterns.join(" ")
            )?;
        } else {
            for line in table(&report) {
                writeln!(out, "{line}")?;
            }
            writeln!(out)?;
        }
        out.flush()?;
        reports += 1;
        if args.count.is_some_and(|n| reports >= n) {
            return Ok(());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn upd(key: &str, age_ms: u64) -> Binding {
        Binding::parse(&format!("UPD {key} float 1.0 {age_ms}")).expect("an UPD line")
    }

    #[test]
    fn a_steady_25_hz_key_reports_25_hz_without_jitter_and_a_jittery_one_its_spread() {
        let t0 = Instant::now();
        let ms = |n: u64| t0 + Duration::from_millis(n);
        let mut r = Rates::new(Duration::from_secs(10));
        // The subscription's snapshot: set 30 ms before it arrived.
        r.record(&upd("1.var.ball", 30), ms(30));
        for i in 1..=50 {
            r.record(&upd("1.var.ball", 0), ms(i * 40));
        }
        // Another key alternating 30 and 50 ms intervals.
        let mut t = 0;
        for i in 0..40 {
            t += if i % 2 == 0 { 30 } else { 50 };
            r.record(&upd("2.var.pose", 0), ms(t));
        }
        let report = r.report(ms(2010));
        let ball = &report[0];
        assert_eq!(ball.key, "1.var.ball");
        let hz = ball.rate_hz.expect("a rate");
        assert!((hz - 25.0).abs() < 0.01, "25 Hz, got {hz}");
        assert!(ball.jitter_ms.unwrap() < 0.01, "{ball:?}");
        assert_eq!(ball.updates, 51);
        assert_eq!(ball.age_ms, 10, "0 ms when it came, 10 ms ago");
        let pose = &report[1];
        assert!((pose.rate_hz.unwrap() - 25.0).abs() < 0.7, "{pose:?}");
        assert_eq!((pose.min_ms, pose.max_ms), (Some(30.0), Some(50.0)));
        assert!((pose.jitter_ms.unwrap() - 10.0).abs() < 0.3, "{pose:?}");
    }

    #[test]
    fn a_key_that_stops_loses_its_rate_after_the_window_and_keeps_ageing() {
        let t0 = Instant::now();
        let mut r = Rates::new(Duration::from_secs(1));
        for i in 0..10 {
            r.record(&upd("3.var.x", 5), t0 + Duration::from_millis(i * 100));
        }
        let later = r.report(t0 + Duration::from_millis(5000));
        assert_eq!(later[0].rate_hz, None, "{later:?}");
        assert_eq!(later[0].updates, 0);
        assert_eq!(later[0].age_ms, 5 + 4100);
        let lines = table(&later);
        assert!(lines[1].starts_with("3.var.x"), "{lines:?}");
        let j = report_json(&later);
        assert_eq!(j["keys"][0]["rate_hz"], serde_json::Value::Null);
        assert_eq!(j["keys"][0]["age_ms"], json!(4105));
    }
}
