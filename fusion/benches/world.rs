//! Hot paths: one pose predict + landmark update, and one GWM round (5 LWMs in, team ball out).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use fusion::nalgebra::{Matrix2, Matrix4, Vector2, Vector3, Vector4};
use fusion::{
    BallEstimate, FieldObservation, GlobalConfig, GlobalModel, LandmarkSighting, LocalWorldModel,
    Odometry, PoseEstimate, PoseFilter, PoseNoise,
};
use std::hint::black_box;
use std::time::{Duration, Instant};

fn pose(c: &mut Criterion) {
    let mut g = c.benchmark_group("pose");
    g.throughput(Throughput::Elements(1));
    let start = PoseEstimate::new(0.0, 0.0, 0.1, Vector3::new(0.01, 0.01, 0.003));
    let odo = Odometry {
        forward_m: 0.01,
        left_m: 0.001,
        turn_rad: 0.005,
    };
    let landmarks = [
        Vector2::new(0.0, 3.0),
        Vector2::new(4.5, 3.0),
        Vector2::new(-4.5, -3.0),
    ];
    g.bench_function("predict_plus_landmark_update", |b| {
        let mut f = PoseFilter::new(start, PoseNoise::default(), Some(13.8));
        let mut k = 0usize;
        b.iter(|| {
            f.odometry(black_box(&odo));
            let field = landmarks[k % 3];
            k += 1;
            let local =
                fusion::field_to_robot(&f.estimate.mean, &field) + Vector2::new(0.01, -0.01);
            let _ = f.landmark(black_box(&LandmarkSighting { field, local }));
        })
    });
    g.finish();
}

/// 5 robots' messages, 10 Hz, about a ball rolling slowly: `rounds` rounds of byte frames.
fn messages(rounds: usize) -> Vec<[[u8; fusion::LWM_WIRE_LEN]; 5]> {
    (0..rounds)
        .map(|r| {
            let t = r as f64 * 0.1;
            let ball = Vector2::new(-1.0 + 0.02 * (r % 100) as f64, 0.5);
            std::array::from_fn(|i| {
                let wobble = Vector2::new(
                    ((r * 7 + i * 3) % 11) as f64 * 0.004,
                    ((r * 5 + i) % 7) as f64 * -0.004,
                );
                let lwm = LocalWorldModel {
                    t_s: t,
                    seq: (r + 1) as u16,
                    pose: PoseEstimate::new(
                        i as f64 - 2.0,
                        1.0,
                        0.3,
                        Vector3::new(0.002, 0.002, 0.0005),
                    ),
                    ball: Some(BallEstimate {
                        t_s: t,
                        mean: Vector4::new(ball.x, ball.y, 0.2, 0.0),
                        cov: Matrix4::from_diagonal(&Vector4::new(0.004, 0.004, 0.02, 0.02)),
                    }),
                    ball_seen_age_s: 0.02,
                    slc: 0.8,
                    lbc: 0.8,
                    observation: Some(FieldObservation {
                        t_s: t - 0.03,
                        position: ball + wobble,
                        cov: Matrix2::identity() * 0.01,
                    }),
                    earlier: [None; 2],
                    kick: None,
                };
                lwm.to_bytes().expect("encodes")
            })
        })
        .collect()
}

fn gwm(c: &mut Criterion) {
    let mut g = c.benchmark_group("gwm");
    g.throughput(Throughput::Elements(1));
    let rounds = messages(20_000);
    g.bench_function("fuse_5_lwms_and_read_team_ball", |b| {
        b.iter_custom(|iters| {
            let mut total = Duration::ZERO;
            let mut done = 0u64;
            while done < iters {
                // A fresh GWM per pass over the recorded rounds, so sequence numbers move on.
                let mut gwm = GlobalModel::new(0, GlobalConfig::default());
                let n = ((iters - done) as usize).min(rounds.len());
                #[allow(clippy::disallowed_methods)] // iter_custom: the bench times its passes
                let started = Instant::now();
                for (r, round) in rounds[..n].iter().enumerate() {
                    let now = r as f64 * 0.1 + 0.05;
                    for (i, bytes) in round.iter().enumerate() {
                        let _ = gwm.receive(i as u8, black_box(bytes), now, 0.05);
                    }
                    black_box(gwm.team_ball(now, None));
                }
                total += started.elapsed();
                done += n as u64;
            }
            total
        })
    });
    g.finish();
}

criterion_group!(benches, pose, gwm);
criterion_main!(benches);
