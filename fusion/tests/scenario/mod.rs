//! A seeded multi-robot ball scenario for the fusion tests: a true ball that rolls (and is
//! kicked), five robots that walk small circles with noisy odometry, see landmarks and the
//! ball with noise, run their LWM and GWM, and broadcast over a link with loss and latency
//! drawn from one seeded RNG. A centralized filter sees every honest robot's raw sightings
//! at once: the ceiling the team ball is measured against.

#![allow(dead_code)]

use fusion::nalgebra::{Matrix2, Matrix3, Matrix4, Vector2, Vector3, Vector4};
use fusion::{
    field_to_robot, wrap_angle, BallEstimate, BallFilterConfig, BallModel, BallSighting,
    CentralizedBall, GlobalConfig, GlobalModel, LandmarkSighting, LocalConfig, LocalModel,
    Odometry, PoseEstimate, PoseNoise, TeamBall,
};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;

pub const TICK_S: f64 = 1.0 / 30.0;
const WALL_X_M: f64 = 5.2;
const WALL_Y_M: f64 = 3.7;
const LANDMARKS: [(f64, f64); 6] = [
    (0.0, 3.0),
    (4.5, 3.0),
    (-4.5, 3.0),
    (0.0, -3.0),
    (4.5, -3.0),
    (-4.5, -3.0),
];
const HOMES: [(f64, f64); 5] = [
    (-3.5, 0.0),
    (-1.5, 1.5),
    (-1.5, -1.5),
    (1.0, 1.0),
    (1.0, -1.0),
];

/// A robot that reports a ball `offset_m` away from the real one in a time window.
#[derive(Debug, Clone, Copy)]
pub struct Liar {
    pub robot: usize,
    pub from_s: f64,
    pub to_s: f64,
    pub offset_m: Vector2<f64>,
}

#[derive(Debug, Clone)]
pub struct Scenario {
    pub seed: u64,
    pub duration_s: f64,
    pub robots: usize,
    /// Every `publish_every` ticks each robot publishes its LWM (3 → 10 Hz).
    pub publish_every: u64,
    pub loss: f64,
    pub latency_s: f64,
    pub jitter_s: f64,
    /// Chance per camera frame that a robot within range sees the ball.
    pub sight_prob: f64,
    pub model: BallModel,
    pub liar: Option<Liar>,
    /// A second robot that lies at the same time (two phantoms that may agree).
    pub second_liar: Option<Liar>,
    /// (time, new velocity) of kicks.
    pub kicks: Vec<(f64, Vector2<f64>)>,
    /// From this time on no message reaches anyone.
    pub silent_from_s: Option<f64>,
    pub ball_start: Option<Vector4<f64>>,
    /// Records are taken every `record_every` ticks after `warmup_s`.
    pub record_every: u64,
    pub warmup_s: f64,
}

impl Scenario {
    pub fn new(seed: u64) -> Self {
        Scenario {
            seed,
            duration_s: 20.0,
            robots: 5,
            publish_every: 3,
            loss: 0.1,
            latency_s: 0.05,
            jitter_s: 0.01,
            sight_prob: 0.6,
            model: BallModel::Rolling {
                friction_per_s: 0.5,
                accel_noise_m2_per_s3: 0.02,
            },
            liar: None,
            second_liar: None,
            kicks: Vec::new(),
            silent_from_s: None,
            ball_start: None,
            record_every: 3,
            warmup_s: 2.0,
        }
    }
}

/// What the scenario saw at one instant.
#[derive(Debug, Clone)]
pub struct Record {
    pub t_s: f64,
    pub truth: Vector4<f64>,
    /// Per robot: its team ball.
    pub team: Vec<Option<TeamBall>>,
    /// Per robot: its own ball.
    pub own: Vec<Option<BallEstimate>>,
    pub central: Option<BallEstimate>,
    /// Per robot: (true pose, estimate).
    pub pose: Vec<(Vector3<f64>, PoseEstimate)>,
    /// Times the ball has bounced off the field's edge so far (the model does not know walls).
    pub bounces: u32,
}

fn pose_noise() -> PoseNoise {
    PoseNoise {
        q: Matrix3::from_diagonal(&Vector3::new(4e-6, 4e-6, 2.5e-5)),
        r_landmark: Matrix2::identity() * 0.0025,
        ..PoseNoise::default()
    }
}

fn normal(rng: &mut ChaCha8Rng) -> f64 {
    rng.sample(StandardNormal)
}

/// A draw from N(0, cov) (cov PSD).
fn draw4(rng: &mut ChaCha8Rng, cov: &Matrix4<f64>) -> Vector4<f64> {
    let l = (cov + Matrix4::identity() * 1e-15)
        .cholesky()
        .expect("PSD")
        .l();
    l * Vector4::from_fn(|_, _| normal(rng))
}

fn draw3(rng: &mut ChaCha8Rng, cov: &Matrix3<f64>) -> Vector3<f64> {
    let l = (cov + Matrix3::identity() * 1e-15)
        .cholesky()
        .expect("PSD")
        .l();
    l * Vector3::from_fn(|_, _| normal(rng))
}

struct Delivery {
    at_s: f64,
    sent_s: f64,
    to: usize,
    from: usize,
    bytes: [u8; fusion::LWM_WIRE_LEN],
}

/// Runs a pose filter alone on one robot walking a circle, starting `offset` wrong (or, with
/// `None`, wrong by a draw from P0 = diag(`p0`), which is what P0 claims), and returns
/// (time, true pose, estimate) every tick.
pub fn walk_pose(
    seed: u64,
    offset: Option<Vector3<f64>>,
    p0: Vector3<f64>,
    duration_s: f64,
) -> Vec<(f64, Vector3<f64>, PoseEstimate)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = pose_noise();
    let mut truth = Vector3::new(-1.0, -1.0, 0.3);
    let offset = offset.unwrap_or_else(|| draw3(&mut rng, &Matrix3::from_diagonal(&p0)));
    let start = truth + offset;
    let mut filter = fusion::PoseFilter::new(
        PoseEstimate::new(start.x, start.y, start.z, p0),
        noise,
        None,
    );
    let mut out = Vec::new();
    let ticks = (duration_s / TICK_S) as u64;
    for k in 1..=ticks {
        let t = k as f64 * TICK_S;
        walk_step(&mut rng, &mut truth, &noise, |odo| filter.odometry(odo));
        if rng.random_bool(5.0 / 30.0) {
            if let Some(s) = landmark(&mut rng, &truth, &noise) {
                let _ = filter.landmark(&s);
            }
        }
        out.push((t, truth, filter.estimate));
    }
    out
}

/// One odometry tick on a circle of about 1 m radius at 0.2 m/s.
fn walk_step(
    rng: &mut ChaCha8Rng,
    truth: &mut Vector3<f64>,
    noise: &PoseNoise,
    mut apply: impl FnMut(&Odometry),
) {
    let odo = Odometry {
        forward_m: 0.2 * TICK_S,
        left_m: 0.0,
        turn_rad: 0.2 * TICK_S,
    };
    // Eq. (7): the truth moves by the commanded odometry plus Rot(θ) w, w ~ N(0, Q).
    let w = draw3(rng, &noise.q);
    let (s, c) = truth.z.sin_cos();
    let (f, l) = (odo.forward_m, odo.left_m);
    *truth = Vector3::new(
        truth.x - f * s - l * c + c * w.x - s * w.y,
        truth.y + f * c - l * s + s * w.x + c * w.y,
        wrap_angle(truth.z + odo.turn_rad + w.z),
    );
    apply(&odo);
}

fn landmark(
    rng: &mut ChaCha8Rng,
    truth: &Vector3<f64>,
    noise: &PoseNoise,
) -> Option<LandmarkSighting> {
    let (bx, by) = LANDMARKS[rng.random_range(0..LANDMARKS.len())];
    let field = Vector2::new(bx, by);
    let exact = field_to_robot(truth, &field);
    if exact.norm() > 7.0 {
        return None;
    }
    let sd = noise.r_landmark[(0, 0)].sqrt();
    Some(LandmarkSighting {
        field,
        local: exact + Vector2::new(normal(rng) * sd, normal(rng) * sd),
    })
}

/// Ball sighting noise in robot coordinates at distance `d_m`: depth is worse than bearing.
fn sighting_cov(d_m: f64) -> Matrix2<f64> {
    let sx = 0.02 + 0.02 * d_m;
    let sy = 0.02 + 0.05 * d_m;
    Matrix2::new(sx * sx, 0.0, 0.0, sy * sy)
}

pub fn run(sc: &Scenario) -> Vec<Record> {
    let mut rng = ChaCha8Rng::seed_from_u64(sc.seed);
    let noise = pose_noise();
    let ball_cfg = BallFilterConfig {
        model: sc.model,
        ..BallFilterConfig::default()
    };
    let local_cfg = LocalConfig {
        pose_noise: noise,
        pose_gate_chi2: None,
        pose_relocalise: None,
        ball: ball_cfg,
    };
    let gcfg = GlobalConfig {
        ball: sc.model,
        ..GlobalConfig::default()
    };
    let p0 = Vector3::new(0.01, 0.01, 0.003);
    let mut truths: Vec<Vector3<f64>> = (0..sc.robots)
        .map(|i| {
            let (x, y) = HOMES[i % HOMES.len()];
            Vector3::new(x, y, rng.random_range(-3.0..3.0))
        })
        .collect();
    let mut lwms: Vec<LocalModel> = truths
        .iter()
        .map(|tr| {
            let e = draw3(&mut rng, &Matrix3::from_diagonal(&p0));
            LocalModel::new(
                local_cfg,
                PoseEstimate::new(tr.x + e.x, tr.y + e.y, tr.z + e.z, p0),
            )
        })
        .collect();
    let mut gwms: Vec<GlobalModel> = (0..sc.robots)
        .map(|i| GlobalModel::new(i as u8, gcfg))
        .collect();
    let mut central = CentralizedBall::new(ball_cfg);
    let mut ball = sc.ball_start.unwrap_or_else(|| {
        Vector4::new(
            rng.random_range(-1.5..1.5),
            rng.random_range(-1.0..1.0),
            0.5 * normal(&mut rng),
            0.5 * normal(&mut rng),
        )
    });
    let mut kicks = sc.kicks.clone();
    let mut in_flight: Vec<Delivery> = Vec::new();
    let mut records = Vec::new();
    let mut bounces = 0;
    let ticks = (sc.duration_s / TICK_S).round() as u64;
    let (f_ball, q_ball) = sc.model.transition(TICK_S);

    for k in 1..=ticks {
        let t = k as f64 * TICK_S;
        // The world moves.
        ball = f_ball * ball + draw4(&mut rng, &q_ball);
        if let Some(pos) = kicks.iter().position(|(kt, _)| *kt <= t) {
            let (_, v) = kicks.remove(pos);
            ball.z = v.x;
            ball.w = v.y;
        }
        // The ball bounces off the boards around the field (which the model does not know).
        if ball.x.abs() > WALL_X_M || ball.y.abs() > WALL_Y_M {
            bounces += 1;
        }
        if ball.x.abs() > WALL_X_M {
            ball.z = -ball.z;
            ball.x = ball.x.clamp(-WALL_X_M, WALL_X_M);
        }
        if ball.y.abs() > WALL_Y_M {
            ball.w = -ball.w;
            ball.y = ball.y.clamp(-WALL_Y_M, WALL_Y_M);
        }

        // Messages that have arrived.
        in_flight.sort_by(|a, b| a.at_s.total_cmp(&b.at_s));
        let n = in_flight.partition_point(|d| d.at_s <= t);
        for d in in_flight.drain(..n) {
            let age = d.at_s - d.sent_s;
            gwms[d.to]
                .receive(d.from as u8, &d.bytes, d.at_s, age)
                .expect("our own encoder's bytes decode");
        }

        for i in 0..sc.robots {
            let lwm = &mut lwms[i];
            walk_step(&mut rng, &mut truths[i], &noise, |odo| lwm.odometry(odo));
            if rng.random_bool(5.0 / 30.0) {
                if let Some(s) = landmark(&mut rng, &truths[i], &noise) {
                    let _ = lwm.landmark(&s);
                }
            }
            let lying = [sc.liar, sc.second_liar]
                .into_iter()
                .flatten()
                .find(|l| l.robot == i && (l.from_s..l.to_s).contains(&t));
            let seen_at =
                Vector2::new(ball.x, ball.y) + lying.map_or(Vector2::zeros(), |l| l.offset_m);
            let exact = field_to_robot(&truths[i], &seen_at);
            let d = exact.norm();
            if d < 5.0 && rng.random_bool(sc.sight_prob) {
                let cov = sighting_cov(d);
                let local = exact
                    + Vector2::new(
                        normal(&mut rng) * cov[(0, 0)].sqrt(),
                        normal(&mut rng) * cov[(1, 1)].sqrt(),
                    );
                let s = BallSighting { local, cov };
                lwm.ball_sighting(t, &s);
                if lying.is_none() {
                    central.sighting(t, lwm.pose(), &s);
                }
            }
            if (k + i as u64).is_multiple_of(sc.publish_every) {
                let msg = lwm.publish(t);
                gwms[i].ingest(i as u8, &msg, t);
                let bytes = msg.to_bytes().expect("LWM encodes");
                for j in 0..sc.robots {
                    if j == i || rng.random_bool(sc.loss) {
                        continue;
                    }
                    let at_s = t + sc.latency_s + sc.jitter_s * rng.random_range(0.0..1.0);
                    if sc.silent_from_s.is_some_and(|s| at_s >= s) {
                        continue;
                    }
                    in_flight.push(Delivery {
                        at_s,
                        sent_s: t,
                        to: j,
                        from: i,
                        bytes,
                    });
                }
            }
        }

        if t >= sc.warmup_s && k % sc.record_every == 0 {
            records.push(Record {
                t_s: t,
                truth: ball,
                team: gwms
                    .iter()
                    .zip(&lwms)
                    .map(|(g, l)| g.team_ball(t, l.ball_at(t).as_ref()))
                    .collect(),
                own: lwms.iter().map(|l| l.ball_at(t)).collect(),
                central: central.estimate_at(t),
                pose: truths
                    .iter()
                    .zip(&lwms)
                    .map(|(tr, l)| (*tr, *l.pose()))
                    .collect(),
                bounces,
            });
        }
    }
    records
}

/// Normalised estimation error squared of a 4-D ball estimate.
pub fn nees4(est: &BallEstimate, truth: &Vector4<f64>) -> f64 {
    let e = truth - est.mean;
    e.dot(&est.cov.cholesky().expect("PD covariance").solve(&e))
}

/// NEES of a pose (θ error wrapped).
pub fn nees3(est: &PoseEstimate, truth: &Vector3<f64>) -> f64 {
    let mut e = truth - est.mean;
    e.z = wrap_angle(e.z);
    e.dot(&est.cov.cholesky().expect("PD covariance").solve(&e))
}

pub fn position_error(est: &BallEstimate, truth: &Vector4<f64>) -> f64 {
    (est.position() - Vector2::new(truth.x, truth.y)).norm()
}

/// Two-sided 95 % bounds on the average NEES of `runs` independent runs of a `dof`-D state.
pub use fusion::consistency::nees_bounds;
