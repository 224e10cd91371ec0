//! `huddle sim` with `--record`, `--speed`, `--monitor` or `--kill`: the match stepped
//! here rather than run in one call, so that it can be paced against the wall clock (the
//! simulation itself never reads a clock), its traffic recorded and its robots switched
//! off on cue.

use std::io::BufWriter;
use std::net::SocketAddr;
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use huddle::sim::Simulation;
use indicatif::ProgressBar;

use super::duration;
use super::sim_tap::SimTap;
use monitor::model::{Field, Model, Truth};
use monitor::pcapng::Writer;
use monitor::server;

/// `ID@T`: a robot id and a simulated time (`3@20s`).
pub fn parse_kill(s: &str) -> Result<(u8, Duration), String> {
    let (id, t) = s
        .split_once('@')
        .ok_or_else(|| format!("`{s}`: write ID@TIME, e.g. 3@20s"))?;
    let id: u8 = id
        .trim()
        .parse()
        .map_err(|_| format!("`{id}` is not a robot id (1..=254)"))?;
    if id == 0 {
        return Err("robot ids start at 1".into());
    }
    Ok((id, duration::parse(t)?))
}

/// What `huddle sim` asks of a match stepped here (its flags `--record`, `--speed`,
/// `--monitor`, `--kill`, and how many robots there are).
pub struct Stepping<'a> {
    /// Where to record the traffic (pcapng).
    pub record: Option<&'a Path>,
    /// Simulated seconds per wall-clock second.
    pub speed: Option<f64>,
    /// Where to serve the monitor.
    pub monitor: Option<SocketAddr>,
    /// Robots to switch off, and when (simulated time).
    pub kill: &'a [(u8, Duration)],
    /// The team's size.
    pub robots: usize,
}

impl Stepping<'_> {
    /// Whether the match needs stepping here (any of the flags that watch or pace it).
    pub fn wanted(&self) -> bool {
        self.record.is_some()
            || self.speed.is_some()
            || self.monitor.is_some()
            || !self.kill.is_empty()
    }
}

/// Steps `sim` to its end: paced, recorded, robots switched off as asked.
pub fn run(sim: &mut Simulation, args: &Stepping<'_>, bar: &ProgressBar) -> Result<()> {
    let speed = match (args.speed, args.monitor) {
        (Some(s), _) if !(s.is_finite() && s > 0.0) => {
            bail!("--speed must be a positive number, not {s}")
        }
        (Some(s), _) => Some(s),
        (None, Some(_)) => Some(1.0),
        (None, None) => None,
    };
    for &(id, _) in args.kill {
        if usize::from(id) > args.robots {
            bail!("--kill {id}@…: there are only {} robots", args.robots);
        }
    }
    let mut recorder = match args.record {
        Some(path) => {
            let file = std::fs::File::create(path)
                .with_context(|| format!("creating {}", path.display()))?;
            Some(Writer::new(BufWriter::new(file))?)
        }
        None => None,
    };
    let monitor = match args.monitor {
        Some(addr) => {
            let mut model = Model::new(1, None, monitor::listen::LISTENER_ID, 0, "sim", None)?;
            let f = &sim.config().field;
            model.set_field(Field {
                length_m: f.length_m,
                width_m: f.width_m,
                goal_width_m: f.goal_width_m,
                border_m: f.border_m,
            });
            model.set_truth(truth(sim));
            let shared = std::sync::Arc::new(std::sync::Mutex::new(model));
            server::spawn(addr, shared.clone())?;
            Some(shared)
        }
        None => None,
    };
    let mut tap = SimTap::new();
    let mut killed = vec![false; args.kill.len()];
    let started = Instant::now();
    let mut steps = 0u64;
    while !sim.finished() {
        let t_s = sim.time_s();
        for (k, &(id, at)) in args.kill.iter().enumerate() {
            if !killed[k] && t_s >= at.as_secs_f64() {
                killed[k] = true;
                sim.kill(usize::from(id) - 1);
            }
        }
        sim.step();
        steps += 1;
        if recorder.is_some() || monitor.is_some() {
            let mut failed = None;
            let mut model = monitor
                .as_ref()
                .map(|m| m.lock().unwrap_or_else(|p| p.into_inner()));
            tap.drain(sim, |p| {
                if let Some(model) = model.as_mut() {
                    model.datagram(p.t_ns, std::net::SocketAddr::V4(p.from), &p.payload);
                }
                if let (Some(w), None) = (recorder.as_mut(), &failed) {
                    failed = w.write(&p).err();
                }
            });
            if let Some(model) = model.as_mut() {
                model.advance(sim.harness.now().as_nanos());
                model.set_truth(truth(sim));
            }
            if let Some(e) = failed {
                return Err(e).context("writing the recording");
            }
        }
        if steps.is_multiple_of(10) {
            bar.set_position((sim.time_s() * 1e3) as u64);
            if let Some(speed) = speed {
                let due = Duration::from_secs_f64(sim.time_s() / speed);
                if let Some(wait) = due.checked_sub(started.elapsed()) {
                    std::thread::sleep(wait);
                }
            }
        }
    }
    if let Some(mut w) = recorder {
        w.flush().context("writing the recording")?;
    }
    if let Some(model) = monitor {
        model.lock().unwrap_or_else(|p| p.into_inner()).finish();
        if let Some(addr) = args.monitor {
            tracing::info!("the match is over; the monitor stays on http://{addr}/ until Ctrl-C");
        }
        wait_for_ctrl_c()?;
    }
    Ok(())
}

/// Blocks until Ctrl-C (the monitor keeps serving the last picture meanwhile).
pub fn wait_for_ctrl_c() -> Result<()> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?
        .block_on(tokio::signal::ctrl_c())?;
    Ok(())
}

/// Where everything really is, for the monitor.
fn truth(sim: &Simulation) -> Truth {
    use huddle::field::tactics::Mode;
    let robots = sim
        .robots
        .iter()
        .zip(&sim.world.robots)
        .map(|(r, body)| {
            let role = match r.tactics.mode {
                Mode::Active => "active",
                Mode::Auxiliary => "auxiliary",
                Mode::Inactive => "inactive",
                Mode::Goaltend => "goalkeeper",
            };
            let p = body.pose;
            (r.id, p.at.x, p.at.y, p.theta_rad, role.to_owned())
        })
        .collect();
    Truth {
        robots,
        ball: (sim.world.ball.at.x, sim.world.ball.at.y),
        opponents: sim
            .world
            .opponents
            .iter()
            .map(|o| (o.pose.at.x, o.pose.at.y))
            .collect(),
    }
}
