//! The report of `huddle sim --daemons` ([`super::daemons`]): its figures and how they
//! print. Moved out of `daemons.rs`, unchanged.

use serde::Serialize;

use super::daemons::{DaemonsOutage, InProcess, SPREAD_LATENCY_US};
use super::daemons_game::DaemonsGameReport;

/// The report of a `--daemons` match (the in-process report's names where the figure is
/// the same).
#[derive(Debug, Clone, Serialize)]
pub struct DaemonsReport {
    /// Always `"daemons"`.
    pub mode: &'static str,
    /// The league budget, if any.
    pub budget: Option<String>,
    /// Our robots.
    pub robots: usize,
    /// Played duration, s (wall clock).
    pub duration_s: f64,
    /// The network preset.
    pub preset: String,
    /// What each daemon's `--impair` was.
    pub impair: String,
    /// The match's seed.
    pub seed: u64,
    /// Ball-visible time, s.
    pub ball_visible_s: f64,
    /// Ball-visible time with exactly one goer, %.
    pub exactly_one_goer_pct: f64,
    /// … with two or more, %.
    pub conflict_pct: f64,
    /// … with none, %.
    pub no_goer_pct: f64,
    /// Longest conflict, ms.
    pub longest_conflict_ms: f64,
    /// Handovers of the ball between robots.
    pub handovers: u64,
    /// Goals for and against.
    pub goals_for: u32,
    /// Goals against.
    pub goals_against: u32,
    /// Kicks the robots swung.
    pub kick_attempts: u64,
    /// Frames the daemons sent (their `frames_out`).
    pub team_messages_sent: u64,
    /// Per robot.
    pub messages_per_robot: Vec<u64>,
    /// RMSE of the team ball the robots read from their daemons, ball visible, m.
    pub team_ball_rmse_m: f64,
    /// The central reference (the team's fusion hearing every robot's message at once,
    /// see the module's doc), m.
    pub centralized_rmse_m: f64,
    /// World-model messages the central reference took (and refused: undecodable).
    pub central_messages: u64,
    /// … refused.
    pub central_refused: u64,
    /// `team_ball_rmse_m / centralized_rmse_m`.
    pub rmse_ratio: f64,
    /// Samples of the team ball error.
    pub team_ball_samples: u64,
    /// Samples taken while the robot did not see the ball itself.
    pub blind_samples: u64,
    /// RMSE over those, m.
    pub blind_team_ball_rmse_m: f64,
    /// RMSE of the pose the daemons held against the truth, m.
    pub pose_rmse_m: f64,
    /// Relay writes the daemons refused (`ERR`): each is a bug in the robot program.
    pub relay_errors: u64,
    /// The first three refusals' texts (`robot N: ERR text`), so a refusal says what it was.
    pub relay_refusals: Vec<String>,
    /// Physics steps that started more than one step late (the machine was busy).
    pub late_steps: u64,
    /// Robot ticks that played on the layer's previous outputs (its tick on the new
    /// senses did not come within the wait).
    pub stale_views: u64,
    /// The other robot ticks: from writing the cycle's senses to playing on the layer's
    /// tick on them (relay in, layer tick, relay out), ms.
    pub view_lag_ms: Spread,
    /// How far behind the wall clock each physics step started, ms (the machine's
    /// load: the world the robots sense is this much older than their clocks say).
    pub behind_ms: Spread,
    /// Each daemon's clock: `[offset at start, s; drift, ppm]` (`--clock-offset`,
    /// `--clock-drift-ppm`), as the match drew the robot's clock in process; zeros
    /// outside the drawn world.
    pub clocks: Vec<[f64; 2]>,
    /// The same match in process (same seed and configuration), for the ratio.
    pub in_process: Option<InProcess>,
    /// Under `--game`: the referee's books ([`super::daemons_game`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub game: Option<DaemonsGameReport>,
    /// Under `--outage`: the arbitration while every daemon's radio was down, and with
    /// `--acoustic` the fallback's counters (`daemons_air`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outage: Option<DaemonsOutage>,
}

/// A distribution in brief, ms.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Spread {
    /// Median.
    pub p50: f64,
    /// 95th percentile.
    pub p95: f64,
    /// Largest.
    pub max: f64,
}

impl Spread {
    pub(super) fn of_us(mut us: Vec<u64>) -> Spread {
        if us.is_empty() {
            return Spread::default();
        }
        us.sort_unstable();
        let at = |q: f64| {
            let i = ((us.len() - 1) as f64 * q).round() as usize;
            us[i] as f64 / 1e3
        };
        Spread {
            p50: at(0.5),
            p95: at(0.95),
            max: at(1.0),
        }
    }
}

impl std::fmt::Display for Spread {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "p50 {:.2} / p95 {:.2} / max {:.1} ms",
            self.p50, self.p95, self.max
        )
    }
}

impl std::fmt::Display for DaemonsReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "huddle sim --daemons: {} robots in {} daemons, {:.0} s real time, {} ({}), seed {}",
            self.robots, self.robots, self.duration_s, self.preset, self.impair, self.seed
        )?;
        writeln!(
            f,
            "exactly one goer      {:.2}% of {:.1} s ball-visible (conflict {:.2}%, none {:.2}%, longest conflict {:.0} ms)",
            self.exactly_one_goer_pct,
            self.ball_visible_s,
            self.conflict_pct,
            self.no_goer_pct,
            self.longest_conflict_ms
        )?;
        writeln!(
            f,
            "team ball RMSE        {:.3} m ({} samples; blind {:.3} m over {}); central reference {:.3} m ({} messages, {} refused), ratio {:.3}",
            self.team_ball_rmse_m,
            self.team_ball_samples,
            self.blind_team_ball_rmse_m,
            self.blind_samples,
            self.centralized_rmse_m,
            self.central_messages,
            self.central_refused,
            self.rmse_ratio
        )?;
        if let Some(p) = &self.in_process {
            writeln!(
                f,
                "in process            team ball RMSE {:.3} m, one goer {:.2}%, pose RMSE {:.3} m: daemons / in-process RMSE {:.3}",
                p.team_ball_rmse_m, p.exactly_one_goer_pct, p.pose_rmse_m, p.rmse_vs_in_process
            )?;
            let runs: Vec<String> = p
                .spread
                .iter()
                .map(|s| format!("{:.3}", s.team_ball_rmse_m))
                .collect();
            writeln!(
                f,
                "in-process spread     team ball RMSE {} m (latency {:+?} µs): median {:.3} m, daemons / median {:.3}",
                runs.join(" "),
                SPREAD_LATENCY_US,
                p.team_ball_rmse_median_m,
                p.rmse_vs_in_process_median
            )?;
            if let Some(o) = &p.outage {
                writeln!(
                    f,
                    "in-process outage     exactly one goer {:.2} % of {:.1} s, near {:.2} %, {} handovers ({:.1} s from {:.1} s)",
                    o.outage_exactly_one_goer_pct,
                    o.outage_ball_visible_s,
                    o.outage_near_goer_pct,
                    o.outage_handovers,
                    o.outage_duration_s,
                    o.outage_start_s
                )?;
            }
        }
        writeln!(
            f,
            "messages              {} ({:?}); goals {}:{}; kicks {}; pose RMSE {:.3} m",
            self.team_messages_sent,
            self.messages_per_robot,
            self.goals_for,
            self.goals_against,
            self.kick_attempts,
            self.pose_rmse_m
        )?;
        // The first refusals' texts, if any, beside the count.
        let refusals = if self.relay_refusals.is_empty() {
            String::new()
        } else {
            format!(" ({})", self.relay_refusals.join("; "))
        };
        writeln!(
            f,
            "relay errors          {}{refusals}; late physics steps {}; stale views {}",
            self.relay_errors, self.late_steps, self.stale_views
        )?;
        writeln!(f, "view lag              {}", self.view_lag_ms)?;
        write!(f, "world behind clock    {}", self.behind_ms)?;
        if let Some(g) = &self.game {
            write!(f, "\n{g}")?;
        }
        if let Some(o) = &self.outage {
            write!(f, "\n{o}")?;
        }
        Ok(())
    }
}
