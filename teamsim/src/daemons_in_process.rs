//! The in-process match `huddle sim --daemons` is judged against (see
//! [`super::daemons`]): the same seed played in this process, and again with the link's
//! latency moved by each of [`SPREAD_LATENCY_US`], since one seed's match swings by chance
//! as much as the daemons' match does. Moved out of `daemons.rs`, unchanged.

use serde::Serialize;

use super::daemons::{gaps, DaemonsError};
use super::SimConfig;
use super::Simulation;

/// The in-process figures `--daemons` is judged against.
#[derive(Debug, Clone, Serialize)]
pub struct InProcess {
    /// Its team-ball RMSE, m.
    pub team_ball_rmse_m: f64,
    /// Its pose RMSE, m.
    pub pose_rmse_m: f64,
    /// Its exactly-one-goer, %.
    pub exactly_one_goer_pct: f64,
    /// Daemons' team-ball RMSE over it.
    pub rmse_vs_in_process: f64,
    /// The same match in process with the link's latency moved by each of
    /// [`SPREAD_LATENCY_US`] (nothing else changed): how far one seed's match swings by
    /// chance alone. The daemons' match diverges from the in-process one within seconds
    /// (real time, real scheduling), so it is one more draw from this spread, not a
    /// replay of the in-process run.
    pub spread: Vec<SpreadRun>,
    /// The median team-ball RMSE of the in-process run and the spread's runs, m.
    pub team_ball_rmse_median_m: f64,
    /// Daemons' team-ball RMSE over that median.
    pub rmse_vs_in_process_median: f64,
    /// Under `--outage`: the in-process match's outage figures (its window is the
    /// configured one, the daemons' is every daemon's, a little shorter).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outage: Option<super::acoustic::OutageWindows>,
}

/// One in-process run of the spread.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct SpreadRun {
    /// The link latency it ran with, ms.
    pub latency_ms: f64,
    /// Its team-ball RMSE, m.
    pub team_ball_rmse_m: f64,
    /// Its pose RMSE, m.
    pub pose_rmse_m: f64,
}

/// How the spread's in-process runs move the link's one-way latency, µs (the competition
/// preset's is 20 ms with 10 ms of jitter: these stay well inside it).
pub const SPREAD_LATENCY_US: [i64; 6] = [-2000, -1000, -500, 500, 1000, 2000];

/// The in-process match `cfg` and its spread (see [`InProcess::spread`]), judged against
/// the daemons' team-ball RMSE `daemons_rmse_m`.
pub fn in_process(cfg: &SimConfig, daemons_rmse_m: f64) -> Result<InProcess, DaemonsError> {
    let mut sim = Simulation::new(cfg.clone())?;
    run_in_process(&mut sim);
    let own = sim.report(0.0);
    let base_us = cfg
        .network
        .latency
        .unwrap_or_else(|| cfg.network.preset.link().latency)
        .as_micros() as i64;
    let mut spread = Vec::with_capacity(SPREAD_LATENCY_US.len());
    for d in SPREAD_LATENCY_US {
        let mut c = cfg.clone();
        let us = u64::try_from((base_us + d).max(0)).unwrap_or(0);
        c.network.latency = Some(std::time::Duration::from_micros(us));
        let mut sim = Simulation::new(c)?;
        sim.run(|_| {});
        let r = sim.report(0.0);
        spread.push(SpreadRun {
            latency_ms: us as f64 / 1e3,
            team_ball_rmse_m: r.team_ball_rmse_m,
            pose_rmse_m: r.pose_rmse_m,
        });
    }
    let mut all: Vec<f64> = spread
        .iter()
        .map(|s| s.team_ball_rmse_m)
        .chain([own.team_ball_rmse_m])
        .collect();
    all.sort_by(f64::total_cmp);
    let median = all[all.len() / 2];
    let r3 = |x: f64| (x * 1000.0).round() / 1000.0;
    Ok(InProcess {
        team_ball_rmse_m: own.team_ball_rmse_m,
        pose_rmse_m: own.pose_rmse_m,
        exactly_one_goer_pct: own.exactly_one_goer_pct,
        rmse_vs_in_process: r3(daemons_rmse_m / own.team_ball_rmse_m),
        spread,
        team_ball_rmse_median_m: median,
        rmse_vs_in_process_median: r3(daemons_rmse_m / median),
        outage: own.outage.map(|o| o.windows),
    })
}

/// Plays `sim` (the in-process match `--daemons` is judged against) to its end; with
/// `HUDDLE_DAEMONS_TRACE=1`, prints each robot's pose error every physics step
/// (`inproc pose t=… robot=… err=… heading=…`), for comparing the two matches robot by
/// robot (`scripts/daemons-trace.py --pose`).
pub fn run_in_process(sim: &mut Simulation) {
    let trace = super::daemons::trace();
    while !sim.finished() {
        let t = sim.time_s();
        sim.step();
        if !trace {
            continue;
        }
        for (i, (r, body)) in sim.robots.iter().zip(&sim.world.robots).enumerate() {
            let est = r.lwm.pose().mean;
            let err = (body.pose.at.x - est.x).hypot(body.pose.at.y - est.y);
            let heading = fusion::wrap_angle(body.pose.theta_rad - est.z);
            eprintln!(
                "inproc pose t={t:.2} robot={} err={err:.4} heading={heading:.4} marks={} at={:.2},{:.2} gaps={:.2?}",
                r.id,
                r.frame.landmarks.len(),
                body.pose.at.x,
                body.pose.at.y,
                gaps(&sim.world, i)
            );
        }
    }
    let end = sim.time_s();
    sim.timeline.finish(end);
}
