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

use super::duration;

/// Arguments of `huddle sim`.
#[derive(Args, Debug, Clone)]
pub struct SimArgs {
    /// Robots on our team (robot 1 keeps goal when there are three or more).
    #[arg(long, default_value_t = 5)]
    pub robots: usize,
    /// Opponents on the field (obstacles that chase the ball).
    #[arg(long, default_value_t = 3)]
    pub opponents: usize,
    /// Simulated duration, with its unit: `300s`, `5min`.
    #[arg(long, default_value = "300s", value_parser = duration::parse)]
    pub duration: Duration,
    /// Network preset: lan, wlan, competition.
    #[arg(long, default_value = "competition")]
    pub preset: Preset,
    /// Independent loss per receiver, `20%` or `0.2` (replaces the preset's loss model).
    #[arg(long, value_parser = parse_fraction)]
    pub loss: Option<f64>,
    /// One-way latency, `50ms` (replaces the preset's).
    #[arg(long, value_parser = duration::parse)]
    pub latency: Option<Duration>,
    /// Latency jitter, `20ms` (replaces the preset's).
    #[arg(long, value_parser = duration::parse)]
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
    /// Write what a listener beside robot 1 hears to this pcapng file (as `huddle
    /// record` does), for `huddle replay`.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Pace the match at N times real time (`--speed 1`: real time); without it, as fast
    /// as it computes.
    #[arg(long)]
    pub speed: Option<f64>,
    /// Serve the live team monitor on this address (`127.0.0.1:8080`) while the match
    /// runs, and after it until Ctrl-C; paced at real time unless --speed says otherwise.
    #[arg(long, value_name = "ADDR")]
    pub monitor: Option<std::net::SocketAddr>,
    /// Switch robot ID off at simulated time T (it stops and falls silent): `3@20s`.
    #[arg(long, value_name = "ID@T", value_parser = super::monitor_sim::parse_kill)]
    pub kill: Vec<(u8, Duration)>,
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
            record: None,
            speed: None,
            monitor: None,
            kill: Vec::new(),
        }
    }
}

/// `20%` or `0.2`, within 0..=1.
fn parse_fraction(s: &str) -> Result<f64, String> {
    netsim::parse_probability("probability", s.trim()).map_err(|e| e.to_string())
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
    if super::monitor_sim::wanted(&args) {
        super::monitor_sim::run(&mut sim, &args, &bar)?;
    }
    sim.run(|t_s| bar.set_position((t_s * 1e3) as u64));
    let wall_s = started.elapsed().as_secs_f64();
    bar.finish_and_clear();
    let report = sim.report(wall_s);
    if let Some(path) = &args.svg {
        std::fs::write(path, huddle::sim::svg::render(&sim))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if args.json {
        outln!("{}", serde_json::to_string(&report)?);
    } else {
        outln!("{report}");
        if let Some(path) = &args.svg {
            outln!("picture               {}", path.display());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_and_fractions_parse_as_written_in_the_issue() {
        assert_eq!(duration::parse("300s"), Ok(Duration::from_secs(300)));
        assert_eq!(duration::parse("50ms"), Ok(Duration::from_millis(50)));
        assert_eq!(duration::parse("5min"), Ok(Duration::from_secs(300)));
        assert!(duration::parse("5 parsecs").is_err());
        assert_eq!(parse_fraction("20%"), Ok(0.2));
        assert_eq!(parse_fraction("0.3"), Ok(0.3));
        assert!(parse_fraction("120%").is_err());
    }

    #[test]
    fn a_duration_without_a_unit_is_refused_not_guessed() {
        // Read as seconds, `--latency 50` would be a typo that silently ruins a run.
        let err = duration::parse("50").expect_err("no unit");
        assert!(
            err.contains("50ms") && err.contains("50s"),
            "the error shows the form: {err}"
        );
    }
}
