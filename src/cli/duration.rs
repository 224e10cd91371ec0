//! The one duration syntax of every command-line flag: a number and its unit (`100ms`,
//! `1s`, `1.5s`, `5min`, `200us`), netsim's spec syntax. A bare number is refused with the
//! fix in the message, never read as some default unit.

use std::time::Duration;

/// Parses a flag's duration (clap `value_parser`).
pub fn parse(s: &str) -> Result<Duration, String> {
    let s = s.trim();
    if !s.is_empty() && s.parse::<f64>().is_ok() {
        return Err(format!(
            "`{s}` has no unit: write {s}ms (or {s}s, {s}min, {s}us)"
        ));
    }
    netsim::parse_duration("duration", s).map_err(|e| e.to_string())
}

/// Like [`parse`], but zero is refused (periods, timeouts that must elapse).
pub fn parse_positive(s: &str) -> Result<Duration, String> {
    let d = parse(s)?;
    if d.is_zero() {
        return Err(format!(
            "{s:?} is zero: give a positive duration such as 100ms"
        ));
    }
    Ok(d)
}

/// Writes a duration back in the flag syntax, shortest exact unit first (`1500ms`, `5min`).
pub fn show(d: Duration) -> String {
    let ns = d.as_nanos();
    if ns == 0 {
        "0s".into()
    } else if ns.is_multiple_of(60_000_000_000) {
        format!("{}min", ns / 60_000_000_000)
    } else if ns.is_multiple_of(1_000_000_000) {
        format!("{}s", ns / 1_000_000_000)
    } else if ns.is_multiple_of(1_000_000) {
        format!("{}ms", ns / 1_000_000)
    } else if ns.is_multiple_of(1_000) {
        format!("{}us", ns / 1_000)
    } else {
        format!("{ns}ns")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_issue_s_examples_parse_and_a_bare_number_shows_the_fix() {
        assert_eq!(parse("100ms"), Ok(Duration::from_millis(100)));
        assert_eq!(parse("1s"), Ok(Duration::from_secs(1)));
        assert_eq!(parse("5min"), Ok(Duration::from_secs(300)));
        assert_eq!(parse("1.5s"), Ok(Duration::from_millis(1500)));
        let err = parse("500").expect_err("no unit");
        assert!(err.contains("500ms"), "the error shows the form: {err}");
        assert!(parse_positive("0ms").is_err());
        assert!(parse("-1s").is_err());
    }

    #[test]
    fn show_writes_what_parse_reads() {
        for d in ["0s", "100ms", "1s", "5min", "1500ms", "250us", "90s"] {
            assert_eq!(show(parse(d).unwrap()), d);
        }
    }
}
