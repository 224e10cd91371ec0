//! Spec strings: `"loss=20%,delay=50ms,jitter=20ms"` ⇄ [`LinkConfig`].
//!
//! Comma-separated `key=value` items, keys case-insensitive, spaces around items ignored.
//! `preset=NAME` may come first and is then refined by the other keys.
//!
//! | key | value | meaning |
//! |---|---|---|
//! | `preset` | `lan`, `wlan`, `competition`, `competition-ps` | start from [`Preset::standalone`] |
//! | `delay` (`latency`) | duration (`50ms`, `200us`, `1.5s`, `100ns`) | base delay |
//! | `jitter` | duration | delay spread |
//! | `dist` (`jitter-dist`) | `uniform`, `normal`, `pareto` | spread shape ([`JitterDist`]) |
//! | `loss` | probability (`20%` or `0.2`) | independent loss |
//! | `burst-good`, `burst-bad` | duration | Gilbert–Elliott mean gap and burst |
//! | `burst-loss`, `burst-good-loss` | probability | loss while bad / good |
//! | `dup` (`duplicate`) | probability | duplication |
//! | `reorder` | probability | skip the delay, overtaking earlier packets |
//! | `rate` | `6mbit`, `500kbit`, `1gbit`, `9600bit` | bandwidth |
//! | `queue` (`limit`) | packets | queue limit with a rate |
//! | `beacon` | duration or `off` | multicast hold to the next beacon |
//!
//! Any `burst-*` key switches bursts on, starting from the preset's bursts or from
//! [`GilbertElliott::default`].

use std::fmt;
use std::str::FromStr;
use std::time::Duration;

use crate::impairment::{ConfigError, GilbertElliott, JitterDist, LinkConfig};
use crate::preset::Preset;
use crate::time::duration_ns;

/// Why a spec string could not be parsed.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SpecError {
    /// An item is not of the form `key=value`.
    #[error("`{item}` is not key=value")]
    NotKeyValue {
        /// The offending item.
        item: String,
    },
    /// The key is not one of the known keys.
    #[error("unknown key `{key}` (known: preset, delay, jitter, dist, loss, burst-good, burst-bad, burst-loss, burst-good-loss, dup, reorder, rate, queue, beacon)")]
    UnknownKey {
        /// The offending key.
        key: String,
    },
    /// A key appears twice.
    #[error("key `{key}` given twice")]
    DuplicateKey {
        /// The repeated key.
        key: String,
    },
    /// `preset=` came after other keys (it would silently override them).
    #[error("preset= must be the first item")]
    PresetNotFirst,
    /// The preset name is unknown.
    #[error("unknown preset `{name}` (known: lan, wlan, competition, competition-ps)")]
    UnknownPreset {
        /// The offending name.
        name: String,
    },
    /// A duration is malformed (needs a unit: ns, us, µs, ms, s, min).
    #[error("{key}: `{value}` is not a duration like 50ms, 200us, 1.5s, 5min")]
    BadDuration {
        /// The key.
        key: String,
        /// The offending value.
        value: String,
    },
    /// A probability is malformed or outside [0, 1].
    #[error("{key}: `{value}` is not a probability like 20% or 0.2")]
    BadProbability {
        /// The key.
        key: String,
        /// The offending value.
        value: String,
    },
    /// A rate is malformed.
    #[error("rate: `{value}` is not a rate like 6mbit, 500kbit, 9600bit")]
    BadRate {
        /// The offending value.
        value: String,
    },
    /// A packet count is malformed.
    #[error("{key}: `{value}` is not a positive whole number")]
    BadCount {
        /// The key.
        key: String,
        /// The offending value.
        value: String,
    },
    /// The jitter distribution is unknown.
    #[error("unknown jitter distribution `{name}` (known: uniform, normal, pareto)")]
    UnknownDistribution {
        /// The offending name.
        name: String,
    },
    /// The values parse but do not make a valid link.
    #[error("invalid link: {0}")]
    Invalid(#[from] ConfigError),
}

fn canonical_key(key: &str) -> Option<&'static str> {
    Some(match key {
        "preset" => "preset",
        "delay" | "latency" => "delay",
        "jitter" => "jitter",
        "dist" | "jitter-dist" | "distribution" => "dist",
        "loss" => "loss",
        "burst-good" => "burst-good",
        "burst-bad" => "burst-bad",
        "burst-loss" => "burst-loss",
        "burst-good-loss" => "burst-good-loss",
        "dup" | "duplicate" => "dup",
        "reorder" => "reorder",
        "rate" => "rate",
        "queue" | "limit" => "queue",
        "beacon" => "beacon",
        _ => return None,
    })
}

impl FromStr for LinkConfig {
    type Err = SpecError;

    fn from_str(spec: &str) -> Result<LinkConfig, SpecError> {
        let mut config = LinkConfig::default();
        let mut seen: Vec<&'static str> = Vec::new();
        for item in spec.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (raw_key, value) = item.split_once('=').ok_or_else(|| SpecError::NotKeyValue {
                item: item.to_string(),
            })?;
            let lower = raw_key.trim().to_ascii_lowercase();
            let value = value.trim();
            let key = canonical_key(&lower).ok_or(SpecError::UnknownKey { key: lower.clone() })?;
            if seen.contains(&key) {
                return Err(SpecError::DuplicateKey {
                    key: key.to_string(),
                });
            }
            if key == "preset" && !seen.is_empty() {
                return Err(SpecError::PresetNotFirst);
            }
            seen.push(key);
            match key {
                "preset" => config = value.parse::<Preset>()?.standalone(),
                "delay" => config.latency = duration(key, value)?,
                "jitter" => config.jitter = duration(key, value)?,
                "dist" => config.jitter_dist = distribution(value)?,
                "loss" => config.loss = probability(key, value)?,
                "dup" => config.duplicate = probability(key, value)?,
                "reorder" => config.reorder = probability(key, value)?,
                "rate" => config.rate_bps = Some(rate(value)?),
                "queue" => config.queue_limit = count(key, value)?,
                "beacon" if value.eq_ignore_ascii_case("off") => config.beacon = None,
                "beacon" => config.beacon = Some(duration(key, value)?),
                burst_key => {
                    let burst = config.burst.get_or_insert_with(GilbertElliott::default);
                    match burst_key {
                        "burst-good" => burst.mean_good = duration(key, value)?,
                        "burst-bad" => burst.mean_bad = duration(key, value)?,
                        "burst-loss" => burst.loss_bad = probability(key, value)?,
                        _ => burst.loss_good = probability(key, value)?,
                    }
                }
            }
        }
        config.validate()?;
        Ok(config)
    }
}

fn split_unit(value: &str) -> (&str, &str) {
    let at = value
        .find(|c: char| c.is_alphabetic() || c == 'µ' || c == '%')
        .unwrap_or(value.len());
    (value[..at].trim(), value[at..].trim())
}

fn non_negative(number: &str) -> Option<f64> {
    number
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && *v >= 0.0)
}

/// A duration with its unit, as spec strings take it (`50ms`, `200us`, `1.5s`, `5min`; a
/// bare number is refused rather than guessed); `what` names the value in the error (a
/// key, a command-line flag).
pub fn parse_duration(what: &str, value: &str) -> Result<Duration, SpecError> {
    duration(what, value)
}

/// A probability as spec strings take it: `20%` or `0.2`, within 0..=1.
pub fn parse_probability(what: &str, value: &str) -> Result<f64, SpecError> {
    probability(what, value)
}

fn duration(key: &str, value: &str) -> Result<Duration, SpecError> {
    let bad = || SpecError::BadDuration {
        key: key.to_string(),
        value: value.to_string(),
    };
    let (number, unit) = split_unit(value);
    let ns_per_unit = match unit.to_ascii_lowercase().as_str() {
        "ns" => 1.0,
        "us" | "µs" => 1e3,
        "ms" => 1e6,
        "s" => 1e9,
        "min" => 60e9,
        _ => return Err(bad()),
    };
    let ns = (non_negative(number).ok_or_else(bad)? * ns_per_unit).round();
    if ns >= u64::MAX as f64 {
        return Err(bad());
    }
    Ok(Duration::from_nanos(ns as u64))
}

fn probability(key: &str, value: &str) -> Result<f64, SpecError> {
    let bad = || SpecError::BadProbability {
        key: key.to_string(),
        value: value.to_string(),
    };
    let (number, unit) = split_unit(value);
    let p = match unit {
        "%" => non_negative(number).ok_or_else(bad)? / 100.0,
        "" => non_negative(number).ok_or_else(bad)?,
        _ => return Err(bad()),
    };
    if p > 1.0 {
        return Err(bad());
    }
    Ok(p)
}

fn rate(value: &str) -> Result<u64, SpecError> {
    let bad = || SpecError::BadRate {
        value: value.to_string(),
    };
    let (number, unit) = split_unit(value);
    let bits_per_unit = match unit.to_ascii_lowercase().as_str() {
        "bit" => 1.0,
        "kbit" => 1e3,
        "mbit" => 1e6,
        "gbit" => 1e9,
        _ => return Err(bad()),
    };
    let bps = (non_negative(number).ok_or_else(bad)? * bits_per_unit).round();
    if bps < 1.0 || bps >= u64::MAX as f64 {
        return Err(bad());
    }
    Ok(bps as u64)
}

fn count(key: &str, value: &str) -> Result<usize, SpecError> {
    value
        .parse::<usize>()
        .ok()
        .filter(|&n| n > 0)
        .ok_or_else(|| SpecError::BadCount {
            key: key.to_string(),
            value: value.to_string(),
        })
}

fn distribution(value: &str) -> Result<JitterDist, SpecError> {
    [JitterDist::Uniform, JitterDist::Normal, JitterDist::Pareto]
        .into_iter()
        .find(|d| d.name().eq_ignore_ascii_case(value))
        .ok_or_else(|| SpecError::UnknownDistribution {
            name: value.to_string(),
        })
}

/// Writes a duration exactly, in the largest unit that divides it.
struct SpecDuration(Duration);

impl fmt::Display for SpecDuration {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ns = duration_ns(self.0);
        match ns {
            0 => write!(f, "0ms"),
            _ if ns.is_multiple_of(1_000_000_000) => write!(f, "{}s", ns / 1_000_000_000),
            _ if ns.is_multiple_of(1_000_000) => write!(f, "{}ms", ns / 1_000_000),
            _ if ns.is_multiple_of(1_000) => write!(f, "{}us", ns / 1_000),
            _ => write!(f, "{ns}ns"),
        }
    }
}

/// Writes a probability as a percentage when that parses back to the same number.
struct SpecProbability(f64);

impl fmt::Display for SpecProbability {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let percent = self.0 * 100.0;
        if percent / 100.0 == self.0 && format!("{percent}").parse::<f64>() == Ok(percent) {
            write!(f, "{percent}%")
        } else {
            write!(f, "{}", self.0)
        }
    }
}

impl fmt::Display for LinkConfig {
    /// The spec string of every non-default field (empty for a perfect link); it parses
    /// back to an equal config.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let default = LinkConfig::default();
        let mut items: Vec<String> = Vec::new();
        if self.latency != default.latency {
            items.push(format!("delay={}", SpecDuration(self.latency)));
        }
        if self.jitter != default.jitter {
            items.push(format!("jitter={}", SpecDuration(self.jitter)));
        }
        if self.jitter_dist != default.jitter_dist {
            items.push(format!("dist={}", self.jitter_dist.name()));
        }
        if self.loss != default.loss {
            items.push(format!("loss={}", SpecProbability(self.loss)));
        }
        if let Some(b) = &self.burst {
            items.push(format!("burst-good={}", SpecDuration(b.mean_good)));
            items.push(format!("burst-bad={}", SpecDuration(b.mean_bad)));
            items.push(format!("burst-loss={}", SpecProbability(b.loss_bad)));
            items.push(format!("burst-good-loss={}", SpecProbability(b.loss_good)));
        }
        if self.duplicate != default.duplicate {
            items.push(format!("dup={}", SpecProbability(self.duplicate)));
        }
        if self.reorder != default.reorder {
            items.push(format!("reorder={}", SpecProbability(self.reorder)));
        }
        if let Some(bps) = self.rate_bps {
            let rate = match bps {
                _ if bps % 1_000_000_000 == 0 => format!("{}gbit", bps / 1_000_000_000),
                _ if bps % 1_000_000 == 0 => format!("{}mbit", bps / 1_000_000),
                _ if bps % 1_000 == 0 => format!("{}kbit", bps / 1_000),
                _ => format!("{bps}bit"),
            };
            items.push(format!("rate={rate}"));
        }
        if self.queue_limit != default.queue_limit {
            items.push(format!("queue={}", self.queue_limit));
        }
        if let Some(beacon) = self.beacon {
            items.push(format!("beacon={}", SpecDuration(beacon)));
        }
        f.write_str(&items.join(","))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_issue_example_parses_to_what_it_says() {
        let c: LinkConfig = "loss=20%,delay=50ms,jitter=20ms".parse().unwrap();
        assert_eq!(c.loss, 0.2);
        assert_eq!(c.latency, Duration::from_millis(50));
        assert_eq!(c.jitter, Duration::from_millis(20));
        assert_eq!(c.jitter_dist, JitterDist::Uniform);
        assert_eq!(c.burst, None);
    }

    #[test]
    fn every_key_parses_and_the_config_prints_back_to_an_equal_one() {
        let spec = " preset=wlan , Latency=1.5ms,jitter=250us,dist=Normal,loss=0.125,\
                    burst-good=2s,burst-bad=40ms,burst-loss=80%,burst-good-loss=1%,\
                    dup=2%,reorder=5%,rate=6.5mbit,limit=32,beacon=102.4ms";
        let c: LinkConfig = spec.parse().unwrap();
        assert_eq!(c.latency, Duration::from_micros(1500));
        assert_eq!(c.jitter_dist, JitterDist::Normal);
        assert_eq!(c.rate_bps, Some(6_500_000));
        assert_eq!(c.queue_limit, 32);
        assert_eq!(c.beacon, Some(Duration::from_micros(102_400)));
        let burst = c.burst.unwrap();
        assert_eq!(
            (burst.mean_good, burst.loss_bad),
            (Duration::from_secs(2), 0.8)
        );
        let printed = c.to_string();
        assert_eq!(
            printed.parse::<LinkConfig>().unwrap(),
            c,
            "round trip of `{printed}`"
        );
        for p in Preset::ALL {
            let c = p.standalone();
            assert_eq!(
                c.to_string().parse::<LinkConfig>().unwrap(),
                c,
                "preset {p}"
            );
            assert_eq!(format!("preset={p}").parse::<LinkConfig>().unwrap(), c);
        }
        assert_eq!("".parse::<LinkConfig>().unwrap(), LinkConfig::default());
    }

    #[test]
    fn bad_specs_say_what_is_wrong() {
        let err = |s: &str| s.parse::<LinkConfig>().unwrap_err();
        assert!(matches!(err("loss"), SpecError::NotKeyValue { .. }));
        assert!(matches!(err("los=3%"), SpecError::UnknownKey { key } if key == "los"));
        assert!(matches!(err("loss=120%"), SpecError::BadProbability { .. }));
        assert!(matches!(err("loss=-1%"), SpecError::BadProbability { .. }));
        assert!(matches!(err("loss=NaN"), SpecError::BadProbability { .. }));
        assert!(
            matches!(err("delay=50"), SpecError::BadDuration { .. }),
            "unit required"
        );
        assert!(matches!(
            err("delay=50 parsecs"),
            SpecError::BadDuration { .. }
        ));
        assert!(matches!(err("rate=6mbps"), SpecError::BadRate { .. }));
        assert!(matches!(err("rate=0bit"), SpecError::BadRate { .. }));
        assert!(matches!(err("queue=0"), SpecError::BadCount { .. }));
        assert!(matches!(
            err("dist=cauchy"),
            SpecError::UnknownDistribution { .. }
        ));
        assert!(matches!(
            err("preset=moon"),
            SpecError::UnknownPreset { .. }
        ));
        assert!(matches!(
            err("loss=1%,preset=lan"),
            SpecError::PresetNotFirst
        ));
        assert!(matches!(
            err("loss=1%,loss=2%"),
            SpecError::DuplicateKey { .. }
        ));
        assert!(matches!(
            err("burst-bad=0ms"),
            SpecError::Invalid(ConfigError::ZeroBurstMean)
        ));
        assert!(matches!(
            err("beacon=0s"),
            SpecError::Invalid(ConfigError::ZeroBeacon)
        ));
        assert_eq!(
            err("delay=fast").to_string(),
            "delay: `fast` is not a duration like 50ms, 200us, 1.5s, 5min"
        );
    }

    proptest::proptest! {
        #[test]
        fn any_string_parses_or_fails_cleanly(spec in "[a-z=,%.0-9µ -]{0,60}") {
            let _ = spec.parse::<LinkConfig>();
        }

        #[test]
        fn any_valid_config_prints_and_parses_back(
            latency_us in 0u64..1_000_000,
            jitter_ns in 0u64..100_000_000,
            loss in 0.0f64..=1.0,
            dup in 0.0f64..=1.0,
            rate_bps in proptest::option::of(1u64..10_000_000_000),
            queue in 1usize..10_000,
        ) {
            let c = LinkConfig {
                latency: Duration::from_micros(latency_us),
                jitter: Duration::from_nanos(jitter_ns),
                loss,
                duplicate: dup,
                rate_bps,
                queue_limit: queue,
                ..LinkConfig::default()
            };
            proptest::prop_assert_eq!(c.to_string().parse::<LinkConfig>(), Ok(c));
        }
    }
}
