//! `huddle fusion`: world-model tools. `replay` runs the pose EKF offline over a robot's log.

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use fusion::nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use fusion::{LandmarkSighting, Odometry, PoseEstimate, PoseFilter, PoseNoise, UpdateError};
use serde::Deserialize;
use std::io::{BufRead, BufWriter, Write};

#[derive(Args, Debug)]
pub struct FusionArgs {
    #[command(subcommand)]
    command: FusionCommand,
}

#[derive(Subcommand, Debug)]
enum FusionCommand {
    /// Offline pose EKF over a JSON-lines log of odometry and landmark events.
    ///
    /// Input lines: {"t":s,"type":"odometry","forward":m,"left":m,"turn":rad} and
    /// {"t":s,"type":"landmark","id":..,"field_x":m,"field_y":m,"local_x":m,"local_y":m};
    /// other types are ignored. Output after every processed event:
    /// {"t":s,"x":..,"y":..,"theta":..,"P":[9 numbers, row-major]}.
    Replay(ReplayArgs),
}

#[derive(Args, Debug)]
struct ReplayArgs {
    /// Initial pose x,y,θ (m, m, rad).
    #[arg(long, value_parser = triple, default_value = "0,0,0", allow_hyphen_values = true)]
    x0: [f64; 3],
    /// Initial variances of x, y, θ (m², m², rad²).
    #[arg(long, value_parser = triple, default_value = "1,1,1")]
    p0: [f64; 3],
    /// Odometry noise variances per odometry event, robot frame: right, forward, θ.
    #[arg(long, value_parser = triple, default_value = "0.0001,0.0001,0.0001")]
    q: [f64; 3],
    /// Landmark sighting variances in robot coordinates: x (right), y (forward).
    #[arg(long, value_parser = pair, default_value = "0.01,0.01")]
    r: [f64; 2],
    /// Mahalanobis gate on landmark sightings: a χ² threshold (2 dof), or `off`.
    #[arg(long, value_parser = gate, default_value = "off")]
    gate: Gate,
    /// The log, or `-` for standard input.
    file: String,
}

#[derive(Clone, Copy, Debug)]
struct Gate(Option<f64>);

fn numbers<const N: usize>(s: &str, what: &str) -> Result<[f64; N], String> {
    let parts: Vec<&str> = s.split(',').collect();
    if parts.len() != N {
        return Err(format!("expected {N} comma-separated {what}, got {:?}", s));
    }
    let mut out = [0.0; N];
    for (o, p) in out.iter_mut().zip(parts) {
        *o = p.trim().parse::<f64>().map_err(|e| format!("{p:?}: {e}"))?;
        if !o.is_finite() {
            return Err(format!("{p:?} is not finite"));
        }
    }
    Ok(out)
}

fn triple(s: &str) -> Result<[f64; 3], String> {
    numbers::<3>(s, "numbers")
}

fn pair(s: &str) -> Result<[f64; 2], String> {
    let v = numbers::<2>(s, "variances")?;
    if v.iter().any(|x| *x <= 0.0) {
        return Err("variances must be positive".into());
    }
    Ok(v)
}

fn gate(s: &str) -> Result<Gate, String> {
    if s.eq_ignore_ascii_case("off") {
        return Ok(Gate(None));
    }
    match s.parse::<f64>() {
        Ok(g) if g > 0.0 && g.is_finite() => Ok(Gate(Some(g))),
        _ => Err(format!("{s:?}: expected a positive χ² threshold or `off`")),
    }
}

pub fn run(args: FusionArgs) -> Result<()> {
    match args.command {
        FusionCommand::Replay(a) => replay(a),
    }
}

#[derive(Deserialize)]
struct Head {
    t: f64,
    #[serde(rename = "type")]
    kind: String,
}

#[derive(Deserialize)]
struct OdometryLine {
    forward: f64,
    left: f64,
    turn: f64,
}

#[derive(Deserialize)]
struct LandmarkLine {
    field_x: f64,
    field_y: f64,
    local_x: f64,
    local_y: f64,
}

#[derive(serde::Serialize)]
struct OutLine {
    t: f64,
    x: f64,
    y: f64,
    theta: f64,
    #[serde(rename = "P")]
    p: [f64; 9],
}

fn replay(a: ReplayArgs) -> Result<()> {
    if a.p0.iter().any(|v| *v < 0.0) || a.q.iter().any(|v| *v < 0.0) {
        bail!("--p0 and --q are variances: they cannot be negative");
    }
    let reader: Box<dyn BufRead> = if a.file == "-" {
        Box::new(std::io::stdin().lock())
    } else {
        let f = std::fs::File::open(&a.file).with_context(|| format!("opening {}", a.file))?;
        Box::new(std::io::BufReader::new(f))
    };
    let noise = PoseNoise {
        q: Matrix3::from_diagonal(&Vector3::from(a.q)),
        r_landmark: Matrix2::from_diagonal(&Vector2::from(a.r)),
        ..PoseNoise::default()
    };
    let start = PoseEstimate::new(a.x0[0], a.x0[1], a.x0[2], Vector3::from(a.p0));
    let mut filter = PoseFilter::new(start, noise, a.gate.0);
    let stdout = std::io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    let mut last_t = f64::NEG_INFINITY;
    for (index, line) in reader.lines().enumerate() {
        let n = index + 1;
        let line = line.with_context(|| format!("{}: line {n}: read failed", a.file))?;
        if line.trim().is_empty() {
            continue;
        }
        let head: Head = serde_json::from_str(&line).with_context(|| {
            format!(
                "{}: line {n}: not an event with numeric \"t\" and string \"type\"",
                a.file
            )
        })?;
        let processed = match head.kind.as_str() {
            "odometry" => {
                let o: OdometryLine = serde_json::from_str(&line)
                    .with_context(|| format!("{}: line {n}: malformed odometry event", a.file))?;
                filter.odometry(&Odometry {
                    forward_m: o.forward,
                    left_m: o.left,
                    turn_rad: o.turn,
                });
                true
            }
            "landmark" => {
                let l: LandmarkLine = serde_json::from_str(&line)
                    .with_context(|| format!("{}: line {n}: malformed landmark event", a.file))?;
                match filter.landmark(&LandmarkSighting {
                    field: Vector2::new(l.field_x, l.field_y),
                    local: Vector2::new(l.local_x, l.local_y),
                }) {
                    // A gated sighting is still a processed event: the estimate is reported
                    // unchanged.
                    Ok(_) | Err(UpdateError::Gated { .. }) => {}
                    Err(e) => bail!("{}: line {n}: landmark update failed: {e}", a.file),
                }
                true
            }
            _ => false,
        };
        if !processed {
            continue;
        }
        if head.t < last_t {
            bail!(
                "{}: line {n}: time {} is before the previous event's {}",
                a.file,
                head.t,
                last_t
            );
        }
        last_t = head.t;
        let e = &filter.estimate;
        let p: [f64; 9] = std::array::from_fn(|k| e.cov[(k / 3, k % 3)]);
        serde_json::to_writer(
            &mut out,
            &OutLine {
                t: head.t,
                x: e.mean.x,
                y: e.mean.y,
                theta: e.mean.z,
                p,
            },
        )?;
        out.write_all(b"\n")?;
    }
    out.flush()?;
    Ok(())
}
