//! `huddle sim`: a simulated match of a whole team over a simulated network, and the
//! arbitration report. Also what `huddle` runs with no subcommand.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use huddle::sim::{NetworkConfig, SimConfig, Simulation};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use netsim::Preset;

/// Arguments of `huddle sim`.
#[derive(Args, Debug, Clone)]
pub struct SimArgs {
    /// Robots on our team (robot 1 keeps goal when there are three or more).
    #[arg(long, default_value_t = 5)]
    pub robots: usize,
    /// Opponents on the field (obstacles that chase the ball).
    #[arg(long, default_value_t = 3)]
    pub opponents: usize,
    /// Simulated duration: `300s`, `5m`, `90` (seconds).
    #[arg(long, default_value = "300s", value_parser = parse_duration)]
    pub duration: Duration,
    /// Network preset: lan, wlan, competition.
    #[arg(long, default_value = "competition")]
    pub preset: Preset,
    /// Independent loss per receiver, `20%` or `0.2` (replaces the preset's loss model).
    #[arg(long, value_parser = parse_fraction)]
    pub loss: Option<f64>,
    /// One-way latency, `50ms` (replaces the preset's).
    #[arg(long, value_parser = parse_duration)]
    pub latency: Option<Duration>,
    /// Latency jitter, `20ms` (replaces the preset's).
    #[arg(long, value_parser = parse_duration)]
    pub jitter: Option<Duration>,
    /// Seed of everything random: the same seed gives the same match.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write a picture of the field and the goer timeline to this SVG file.
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Print the report as one JSON object.
    #[arg(long)]
    pub json: bool,
}

impl Default for SimArgs {
    fn default() -> Self {
        Self {
            robots: 5,
            opponents: 3,
            duration: Duration::from_secs(300),
            preset: Preset::Competition,
            loss: None,
            latency: None,
            jitter: None,
            seed: 1,
            svg: None,
            json: false,
        }
    }
}

/// `300s`, `1.5s`, `50ms`, `200us`, `5m`, `5min`, or a bare number of seconds.
pub fn parse_duration(s: &str) -> Result<Duration, String> {
    let s = s.trim();
    let split = s
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(s.len());
    let (num, unit) = s.split_at(split);
    let x: f64 = num
        .parse()
        .map_err(|_| format!("`{s}` is not a duration such as 300s or 50ms"))?;
    let secs = match unit.trim() {
        "" | "s" => x,
        "ms" => x / 1e3,
        "us" | "µs" => x / 1e6,
        "m" | "min" => x * 60.0,
        other => {
            return Err(format!(
                "unknown time unit `{other}` in `{s}` (use s, ms, us, m)"
            ))
        }
    };
    Duration::try_from_secs_f64(secs).map_err(|e| format!("`{s}`: {e}"))
}

/// `20%` or `0.2`, within 0..=1.
pub fn parse_fraction(s: &str) -> Result<f64, String> {
    let s = s.trim();
    let x = match s.strip_suffix('%') {
        Some(p) => p.trim().parse::<f64>().map(|v| v / 100.0),
        None => s.parse::<f64>(),
    }
    .map_err(|_| format!("`{s}` is not a probability such as 20% or 0.2"))?;
    if (0.0..=1.0).contains(&x) {
        Ok(x)
    } else {
        Err(format!("`{s}` is outside 0–100%"))
    }
}

/// Run `huddle sim`.
pub fn run(args: SimArgs) -> Result<()> {
    if args.robots == 0 {
        bail!("--robots must be at least 1");
    }
    let cfg = SimConfig {
        robots: args.robots,
        opponents: args.opponents,
        duration_s: args.duration.as_secs_f64(),
        network: NetworkConfig {
            preset: args.preset,
            loss: args.loss,
            latency: args.latency,
            jitter: args.jitter,
        },
        seed: args.seed,
        ..SimConfig::default()
    };
    let mut sim = Simulation::new(cfg).context("setting up the simulation")?;
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::with_draw_target(
            Some(args.duration.as_millis() as u64),
            ProgressDrawTarget::stderr(),
        )
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} simulating {bar:40} {pos}/{len} ms simulated ({eta})",
        )
        .expect("a valid template"),
    );
    let started = Instant::now();
    sim.run(|t_s| bar.set_position((t_s * 1e3) as u64));
    let wall_s = started.elapsed().as_secs_f64();
    bar.finish_and_clear();
    let report = sim.report(wall_s);
    if let Some(path) = &args.svg {
        std::fs::write(path, huddle::sim::svg::render(&sim))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!("{report}");
        if let Some(path) = &args.svg {
            println!("picture               {}", path.display());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_and_fractions_parse_as_written_in_the_issue() {
        assert_eq!(parse_duration("300s"), Ok(Duration::from_secs(300)));
        assert_eq!(parse_duration("50ms"), Ok(Duration::from_millis(50)));
        assert_eq!(parse_duration("5m"), Ok(Duration::from_secs(300)));
        assert_eq!(parse_duration("90"), Ok(Duration::from_secs(90)));
        assert!(parse_duration("5 parsecs").is_err());
        assert_eq!(parse_fraction("20%"), Ok(0.2));
        assert_eq!(parse_fraction("0.3"), Ok(0.3));
        assert!(parse_fraction("120%").is_err());
    }
}
