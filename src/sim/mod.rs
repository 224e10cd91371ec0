//! `huddle sim`: a whole team on one field, talking only through comms replicas over
//! netsim, and a report on how well should-I-go arbitration held up.
//!
//! The loop runs on a fixed physics step (10 ms). Before each step the network and the
//! replicas are brought up to the step's instant ([`Harness::run_until`]); every robot
//! whose control tick is due then senses, decides and acts ([`Robot::tick`]), its
//! blackboard writes go into its replica (and out at once), the world moves one step,
//! and the arbitration [`Metrics`] take a sample. Robots' control ticks are spread over
//! the control period (robot k starts k/N of a period late), as unsynchronised robots are.
//!
//! To add per-robot processing (a world model), extend [`Robot`] and
//! [`Robot::tick`]: each tick has the robot's camera [`Frame`](crate::field::camera::Frame),
//! its [`Odometry`](crate::field::body::Odometry) and its replica's blackboard.

pub mod metrics;
pub mod perception;
pub mod robot;
pub mod svg;

use std::time::Duration;

use comms::arbitration::ArbitrationParams;
use comms::ReplicaConfig;
use fusion::CentralizedBall;
use netsim::{LinkConfig, Preset, Sim as Net, Time, UplinkConfig};
use serde::Serialize;

use crate::field::behaviour::{formation_homes, Position};
use crate::field::geometry::{Pose, Vec2};
use crate::field::{FieldConfig, World};
use crate::harness::{Harness, HarnessError};
pub use metrics::{BallSample, FusionMetrics, Metrics, Timeline, FLAP_WINDOW_S};
pub use robot::{BrainConfig, Robot, TickInput, WorldModelConfig};

/// The network the team plays on: a netsim preset with optional overrides.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NetworkConfig {
    /// The preset everything not overridden comes from.
    #[serde(serialize_with = "preset_name")]
    pub preset: Preset,
    /// Loss per receiver, as a fraction (overrides the preset's loss, bursts included).
    pub loss: Option<f64>,
    /// One-way latency (overrides the preset's).
    pub latency: Option<Duration>,
    /// Jitter (overrides the preset's).
    pub jitter: Option<Duration>,
}

fn preset_name<S: serde::Serializer>(p: &Preset, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(p.name())
}

impl Default for NetworkConfig {
    fn default() -> Self {
        Self {
            preset: Preset::Competition,
            loss: None,
            latency: None,
            jitter: None,
        }
    }
}

impl NetworkConfig {
    /// Independent loss with a fixed latency and jitter on an otherwise ideal link (the
    /// test grid's conditions).
    pub fn simple(loss: f64, latency: Duration, jitter: Duration) -> Self {
        Self {
            preset: Preset::Lan,
            loss: Some(loss),
            latency: Some(latency),
            jitter: Some(jitter),
        }
    }

    /// The link and uplink this describes. An explicit loss replaces the preset's whole
    /// loss model (independent loss per receiver, no bursts), so `--loss 20%` means 20%.
    pub fn links(&self) -> (LinkConfig, UplinkConfig) {
        let mut link = self.preset.link();
        let mut uplink = self.preset.uplink();
        if let Some(loss) = self.loss {
            link.loss = loss;
            link.burst = None;
            uplink = UplinkConfig::default();
        }
        if let Some(l) = self.latency {
            link.latency = l;
        }
        if let Some(j) = self.jitter {
            link.jitter = j;
        }
        (link, uplink)
    }

    /// The mean loss one receiver sees (uplink bursts and per-receiver loss together).
    pub fn mean_loss(&self) -> f64 {
        let (link, uplink) = self.links();
        1.0 - (1.0 - link.mean_loss()) * (1.0 - uplink.mean_loss())
    }

    /// The mean one-way delay a frame takes: the latency plus, with a beacon hold, half a
    /// beacon interval on average.
    pub fn expected_delay(&self) -> Duration {
        let link = self.links().0;
        link.latency + link.beacon.map_or(Duration::ZERO, |b| b / 2)
    }

    /// The mean one-way latency, for the conflict bound.
    pub fn latency(&self) -> Duration {
        self.links().0.latency
    }
}

/// Everything a simulated match depends on.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SimConfig {
    /// Our robots (robot 1 keeps goal when there are three or more).
    pub robots: usize,
    /// Opponents on the field.
    pub opponents: usize,
    /// Simulated duration, seconds.
    pub duration_s: f64,
    /// The network.
    pub network: NetworkConfig,
    /// The seed of everything random (noise, network, incarnations).
    pub seed: u64,
    /// The field and its physics.
    pub field: FieldConfig,
    /// How robots sense and play.
    pub brain: BrainConfig,
    /// Arbitration parameters.
    #[serde(skip)]
    pub arbitration: ArbitrationParams,
    /// Set the arbitration's latency compensation to the network's expected delay (as a
    /// team would configure `latency_ms` for its WLAN), unless it is set already.
    pub compensate_latency: bool,
    /// The replicas' refresh period.
    #[serde(skip)]
    pub refresh_period: Duration,
    /// Physics step, seconds.
    pub physics_dt_s: f64,
    /// Keep a snapshot of the field every this many seconds for the SVG (0: none).
    pub snapshot_every_s: f64,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            robots: 5,
            opponents: 3,
            duration_s: 300.0,
            network: NetworkConfig::default(),
            seed: 1,
            field: FieldConfig::default(),
            brain: BrainConfig::default(),
            arbitration: ArbitrationParams::default(),
            compensate_latency: true,
            refresh_period: Duration::from_millis(100),
            physics_dt_s: 0.01,
            snapshot_every_s: 0.25,
        }
    }
}

impl SimConfig {
    /// The *nominal* longest conflict (the report's bound uses the measured delay instead,
    /// see [`Report::conflict_bound_ms`]): one latency (the network's expected
    /// one-way delay, a beacon hold included; the old goer has not
    /// heard the new one yet) plus two refresh periods (a lost update is repeated at the
    /// next refresh at the latest, and the old goer acts at its next control tick).
    pub fn conflict_bound(&self) -> Duration {
        self.network.expected_delay() + self.refresh_period * 2
    }
}

/// Why a simulation could not start.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The team or the network could not be built (shown as the harness's message, with
    /// the harness error as its source).
    #[error("{0}")]
    Harness(#[from] HarnessError),
    /// A parameter is out of range.
    #[error("{0}")]
    Config(String),
}

/// Where everything was at one instant (for the SVG).
#[derive(Debug, Clone, Serialize)]
pub struct Snapshot {
    /// Simulated time, seconds.
    pub t_s: f64,
    /// Our robots' true poses.
    pub robots: Vec<Pose>,
    /// Which of them were going.
    pub going: Vec<bool>,
    /// Opponents' positions.
    pub opponents: Vec<Vec2>,
    /// The true ball.
    pub ball: Vec2,
}

/// A match in progress.
pub struct Simulation {
    cfg: SimConfig,
    /// The true world.
    pub world: World,
    /// Our robots' minds.
    pub robots: Vec<Robot>,
    /// Their replicas over the simulated network.
    pub harness: Harness,
    /// Arbitration figures so far.
    pub metrics: Metrics,
    /// World-model figures so far.
    pub fusion: FusionMetrics,
    /// The reference: one ball filter fed every robot's sightings at once, no network.
    pub central: CentralizedBall,
    /// The same fed every kick as well, as it happens: the ceiling for a team that reports
    /// its kicks (as huddle's robots do).
    pub central_kicks: CentralizedBall,
    /// Who went when.
    pub timeline: Timeline,
    /// Field snapshots for the picture.
    pub snapshots: Vec<Snapshot>,
    homes: Vec<Vec2>,
    holders: Vec<u8>,
    next_tick_s: Vec<f64>,
    step: u64,
    next_snapshot_s: f64,
}

impl Simulation {
    /// Set up the match: robots at their formation spots, the ball on the centre spot.
    pub fn new(cfg: SimConfig) -> Result<Self, SimError> {
        if !(1..=254).contains(&cfg.robots) {
            return Err(SimError::Config(format!(
                "robots must be 1..=254, not {}",
                cfg.robots
            )));
        }
        if !(cfg.duration_s.is_finite() && cfg.duration_s >= 0.0) {
            return Err(SimError::Config(format!(
                "bad duration {} s",
                cfg.duration_s
            )));
        }
        if !(cfg.physics_dt_s > 0.0 && cfg.brain.control_period_s >= cfg.physics_dt_s) {
            return Err(SimError::Config(
                "the control period must be at least one physics step".into(),
            ));
        }
        let n = cfg.robots;
        let with_keeper = n >= 3;
        let field_players = n - usize::from(with_keeper);
        let homes = formation_homes(&cfg.field, field_players);
        let mut positions = Vec::with_capacity(n);
        if with_keeper {
            positions.push(Position::Goalkeeper);
        }
        positions.extend((0..field_players).map(Position::Field));
        let holders: Vec<u8> = (0..field_players)
            .map(|k| crate::harness::robot_id(k + usize::from(with_keeper)))
            .collect();
        let starts: Vec<Pose> = positions
            .iter()
            .map(|p| match p {
                Position::Goalkeeper => Pose {
                    at: Vec2::new(-cfg.field.length_m / 2.0 + 0.3, 0.0),
                    theta_rad: 0.0,
                },
                Position::Field(k) => {
                    let at = homes[*k];
                    Pose {
                        at,
                        theta_rad: (Vec2::default() - at).angle(),
                    }
                }
            })
            .collect();
        let world = World::new(cfg.field, &starts, cfg.opponents, cfg.seed);
        let mut params = cfg.arbitration;
        if cfg.compensate_latency && params.latency_compensation.is_zero() {
            params.latency_compensation = cfg.network.expected_delay();
        }
        // No transit for the GWM to subtract: comms' ages include each frame's own
        // transit, estimated from the traffic (wire format 3), so `transit_s` stays 0.
        let world_model = cfg.brain.world_model;
        let robots = positions
            .iter()
            .zip(&starts)
            .enumerate()
            .map(|(i, (&p, &pose))| {
                Robot::new(
                    crate::harness::robot_id(i),
                    p,
                    params,
                    pose,
                    &world_model,
                    n,
                )
            })
            .collect();
        let central = CentralizedBall::new(world_model.local.ball);
        let central_kicks = central.clone();
        let (link, uplink) = cfg.network.links();
        let net = Net::builder().link(link).uplink(uplink);
        let replica = ReplicaConfig::new(1, 1).with_refresh_period(cfg.refresh_period);
        let mut harness = Harness::new(n, net, replica, cfg.seed)?;
        harness.keep_events(false);
        let period = cfg.brain.control_period_s;
        let next_tick_s = (0..n).map(|i| period * i as f64 / n as f64).collect();
        Ok(Self {
            timeline: Timeline::new(n),
            cfg,
            world,
            robots,
            harness,
            metrics: Metrics::default(),
            fusion: FusionMetrics::default(),
            central,
            central_kicks,
            snapshots: Vec::new(),
            homes,
            holders,
            next_tick_s,
            step: 0,
            next_snapshot_s: 0.0,
        })
    }

    /// The configuration.
    pub fn config(&self) -> &SimConfig {
        &self.cfg
    }

    /// Simulated time, seconds.
    pub fn time_s(&self) -> f64 {
        self.step as f64 * self.cfg.physics_dt_s
    }

    /// Whether the configured duration has been simulated.
    pub fn finished(&self) -> bool {
        self.time_s() >= self.cfg.duration_s - 1e-9
    }

    /// One physics step: network up to now, due control ticks, physics, a metrics sample.
    pub fn step(&mut self) {
        let dt = self.cfg.physics_dt_s;
        let t = self.time_s();
        self.harness.run_until(Time::from_secs_f64(t));
        let mut ticked = Vec::new();
        for i in 0..self.robots.len() {
            if self.next_tick_s[i] > t + 1e-9 {
                let Some(replica) = self.harness.replica(i) else {
                    continue;
                };
                let now = self.harness.local_now(i);
                if let Some((key, value)) = self.robots[i].redecide(t, replica.blackboard(), now) {
                    self.harness
                        .set(i, &key, value)
                        .expect("robots only write their own valid keys");
                }
                continue;
            }
            self.next_tick_s[i] += self.cfg.brain.control_period_s;
            if !self.robots[i].alive {
                continue;
            }
            let Some(replica) = self.harness.replica(i) else {
                continue;
            };
            let input = TickInput {
                t_s: t,
                local_now: self.harness.local_now(i),
                board: replica.blackboard(),
                homes: &self.homes,
                holders: &self.holders,
            };
            let writes = self.robots[i].tick(&mut self.world, &self.cfg.brain, input);
            for (key, value) in writes {
                // Our own keys of valid shape: a refusal would be a bug worth seeing.
                self.harness
                    .set(i, &key, value)
                    .expect("robots only write their own valid keys");
            }
            let r = &self.robots[i];
            if let Some(s) = &r.ball_sighting {
                self.central.sighting(t, r.lwm.pose(), s);
                self.central_kicks.sighting(t, r.lwm.pose(), s);
            }
            if let Some(kick) = &r.kicked {
                // A kick is a control input the team knows, like the sightings: this
                // reference has it as it happens, with no network in between.
                self.central_kicks.kick(&fusion::Kick { t_s: t, ..*kick });
            }
            ticked.push(i);
        }
        self.harness.flush();
        self.sample_world_models(t, &ticked);
        if self.world.step(dt).is_some() {
            // The referee puts the ball back on the centre spot and the game controller
            // tells every robot: the ball they tracked is gone.
            // It happened during this step, after every sighting made at its start.
            for i in 0..self.robots.len() {
                let now_s = self.harness.local_now(i).as_micros() as f64 * 1e-6 + dt;
                self.robots[i].forget_ball(now_s);
            }
            self.central.forget();
            self.central_kicks.forget();
        }
        self.step += 1;
        let t_end = self.time_s();
        let visible = self
            .robots
            .iter()
            .any(|r| r.is_field_player() && r.sees_ball());
        let goers: Vec<u8> = self
            .robots
            .iter()
            .filter(|r| r.is_field_player() && r.going())
            .map(|r| r.id)
            .collect();
        self.metrics.sample(t_end, dt, visible, &goers);
        self.timeline
            .sample(t_end, visible, self.robots.iter().map(Robot::going));
        if self.cfg.snapshot_every_s > 0.0 && t_end >= self.next_snapshot_s {
            self.next_snapshot_s += self.cfg.snapshot_every_s;
            self.snapshots.push(Snapshot {
                t_s: t_end,
                robots: self.world.robots.iter().map(|b| b.pose).collect(),
                going: self.robots.iter().map(Robot::going).collect(),
                opponents: self.world.opponents.iter().map(|b| b.pose.at).collect(),
                ball: self.world.ball.at,
            });
        }
    }

    /// The world-model figures at `t_s` for the robots that ticked then (see
    /// [`metrics`] for the definitions).
    fn sample_world_models(&mut self, t_s: f64, ticked: &[usize]) {
        let visible = self
            .robots
            .iter()
            .any(|r| r.is_field_player() && r.sees_ball());
        if visible {
            self.fusion.visible_s += self.cfg.physics_dt_s;
        }
        let truth = perception::to_fusion_point(self.world.ball.at);
        let central = self.central.estimate_at(t_s);
        let central_kicks = self.central_kicks.estimate_at(t_s);
        for &i in ticked {
            let r = &self.robots[i];
            let true_pose =
                perception::to_fusion_pose(&self.world.robots[i].pose, Default::default());
            let est = r.lwm.pose();
            let mut e = true_pose.mean - est.mean;
            e.z = fusion::wrap_angle(e.z);
            let nees = est.cov.cholesky().map_or(f64::NAN, |c| e.dot(&c.solve(&e)));
            self.fusion.pose(e.x * e.x + e.y * e.y, e.z * e.z, nees);
            if !visible {
                continue;
            }
            let now_s = self.harness.local_now(i).as_micros() as f64 * 1e-6;
            let own = r.lwm.ball_at(now_s);
            let (Some(team), Some(c), Some(ck), Some(limited)) = (
                r.gwm.team_ball(now_s, own.as_ref()),
                central,
                central_kicks,
                r.reference.estimate_at(now_s),
            ) else {
                continue;
            };
            let pos_nees = |b: &fusion::BallEstimate| {
                let e = truth - b.position();
                b.position_cov()
                    .cholesky()
                    .map_or(f64::NAN, |ch| e.dot(&ch.solve(&e)))
            };
            let te = (team.estimate.position() - truth).norm_squared();
            let ce = (c.position() - truth).norm_squared();
            self.fusion.ball(&BallSample {
                team_sq_m2: te,
                team_nees: pos_nees(&team.estimate),
                central_sq_m2: ce,
                central_nees: pos_nees(&c),
                central_kicks_sq_m2: (ck.position() - truth).norm_squared(),
                limited_sq_m2: (limited.position() - truth).norm_squared(),
                blind: r.ball.is_none(),
            });
        }
    }

    /// Run to the end, calling `progress(simulated seconds)` about ten times a second of
    /// simulated time.
    pub fn run(&mut self, mut progress: impl FnMut(f64)) {
        while !self.finished() {
            self.step();
            if self.step.is_multiple_of(10) {
                progress(self.time_s());
            }
        }
        self.timeline.finish(self.time_s());
    }

    /// Switch robot `i` off (it stops and falls silent).
    pub fn kill(&mut self, i: usize) {
        self.robots[i].kill(&mut self.world);
        self.harness.kill(i);
    }

    /// The report so far; `wall_s` is the wall time the run took (for `sim_speed_x`).
    pub fn report(&self, wall_s: f64) -> Report {
        let m = &self.metrics;
        let f = &self.fusion;
        let (nees_lo, nees_hi) = f.nees_bounds();
        let net = self.harness.net().network_stats();
        // The conflict bound uses the delay the network actually gave (a beacon hold and
        // queues included), not the nominal latency; before anything was delivered, the
        // configured expectation.
        let (delay_p50, delay_p99) = match net.delay_percentiles(&[0.5, 0.99])[..] {
            [p50, p99] => (p50, p99),
            _ => {
                let d = self.cfg.network.expected_delay();
                (d, d)
            }
        };
        let simulated_s = self.time_s();
        Report {
            robots: self.cfg.robots,
            duration_s: simulated_s,
            preset: self.cfg.network.preset.name().to_string(),
            loss_pct: round3(100.0 * self.cfg.network.mean_loss()),
            latency_ms: self.cfg.network.latency().as_secs_f64() * 1e3,
            jitter_ms: self.cfg.network.links().0.jitter.as_secs_f64() * 1e3,
            seed: self.cfg.seed,
            ball_visible_s: round3(m.visible_s),
            ball_visible_pct: round3(100.0 * m.visible_s / simulated_s.max(1e-9)),
            exactly_one_goer_pct: round3(m.exactly_one_pct()),
            conflict_pct: round3(m.conflict_pct()),
            no_goer_pct: round3(m.no_goer_pct()),
            longest_conflict_ms: round3(m.longest_conflict_s * 1e3),
            longest_conflict_at_s: round3(m.longest_conflict_at_s),
            conflict_bound_ms: round3(
                (delay_p99 + self.cfg.refresh_period * 2).as_secs_f64() * 1e3,
            ),
            delay_p50_ms: round3(delay_p50.as_secs_f64() * 1e3),
            delay_p99_ms: round3(delay_p99.as_secs_f64() * 1e3),
            handovers: m.handovers,
            handovers_per_min: round3(m.handovers_per_min()),
            flaps: m.flaps,
            flaps_per_min: round3(m.flaps_per_min()),
            goals_for: self.world.goals_for,
            goals_against: self.world.goals_against,
            shots: self.robots.iter().map(|r| r.counts.shots).sum(),
            passes: self.robots.iter().map(|r| r.counts.passes).sum(),
            frames_sent: net.sent,
            frames_delivered: net.delivered,
            frames_lost: net.lost_total(),
            team_ball_rmse_m: round4(f.all.team_rmse_m()),
            centralized_rmse_m: round4(f.all.central_rmse_m()),
            rmse_ratio: round3(f.all.team_rmse_m() / f.all.central_rmse_m()),
            network_limited_rmse_m: round4(f.all.limited_rmse_m()),
            fusion_ratio: round3(f.all.team_rmse_m() / f.all.limited_rmse_m()),
            network_ratio: round3(f.all.limited_rmse_m() / f.all.central_kicks_rmse_m()),
            centralized_kicks_rmse_m: round4(f.all.central_kicks_rmse_m()),
            rmse_ratio_kicks: round3(f.all.team_rmse_m() / f.all.central_kicks_rmse_m()),
            blind_samples: f.blind.samples,
            blind_team_ball_rmse_m: round4(f.blind.team_rmse_m()),
            blind_centralized_rmse_m: round4(f.blind.central_rmse_m()),
            blind_network_limited_rmse_m: round4(f.blind.limited_rmse_m()),
            team_ball_nees: round3(f.team_nees()),
            team_ball_nees_bounds: [round3(nees_lo), round3(nees_hi)],
            team_ball_nees_samples: f.nees_independent_samples(),
            centralized_nees: round3(f.central_nees()),
            team_ball_samples: f.samples(),
            pose_rmse_m: round4(f.pose_rmse_m()),
            heading_rmse_rad: round4(f.heading_rmse_rad()),
            pose_nees: round3(f.pose_nees()),
            sim_speed_x: if wall_s > 0.0 {
                round3(simulated_s / wall_s)
            } else {
                0.0
            },
        }
    }
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

fn round4(x: f64) -> f64 {
    (x * 10_000.0).round() / 10_000.0
}

/// What `huddle sim` reports (also its `--json` object). Percentages are of ball-visible
/// time; per-minute rates are per minute of ball-visible time. See [`metrics`] for the
/// definitions of *ball visible*, *goer*, *handover* and *flap*.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// Robots on our team.
    pub robots: usize,
    /// Simulated seconds.
    pub duration_s: f64,
    /// Network preset.
    pub preset: String,
    /// Mean loss per receiver, percent.
    pub loss_pct: f64,
    /// One-way latency, ms.
    pub latency_ms: f64,
    /// Jitter, ms.
    pub jitter_ms: f64,
    /// The seed.
    pub seed: u64,
    /// Seconds during which at least one field player saw the ball.
    pub ball_visible_s: f64,
    /// The same as a share of the match, percent.
    pub ball_visible_pct: f64,
    /// Share of ball-visible time with exactly one goer, percent.
    pub exactly_one_goer_pct: f64,
    /// Share with two or more goers, percent.
    pub conflict_pct: f64,
    /// Share with no goer, percent.
    pub no_goer_pct: f64,
    /// Longest stretch with two or more goers, ms.
    pub longest_conflict_ms: f64,
    /// When it started, seconds.
    pub longest_conflict_at_s: f64,
    /// The bound it should stay under: the measured one-way delay's 99th percentile (all
    /// delivered frames) + two refresh periods, ms.
    pub conflict_bound_ms: f64,
    /// Median one-way delay of the frames delivered, ms.
    pub delay_p50_ms: f64,
    /// 99th percentile of it, ms.
    pub delay_p99_ms: f64,
    /// Handovers (the lone goer changed).
    pub handovers: u64,
    /// Handovers per minute of ball-visible time.
    pub handovers_per_min: f64,
    /// Flaps (A → B → A within two seconds).
    pub flaps: u64,
    /// Flaps per minute of ball-visible time.
    pub flaps_per_min: f64,
    /// Goals we scored.
    pub goals_for: u32,
    /// Goals against us.
    pub goals_against: u32,
    /// Shots kicked.
    pub shots: u32,
    /// Passes kicked.
    pub passes: u32,
    /// Frames sent into the network (one per multicast transmission per receiver).
    pub frames_sent: u64,
    /// Frames delivered.
    pub frames_delivered: u64,
    /// Frames lost.
    pub frames_lost: u64,
    /// Team-ball RMSE against the true ball, m: every live robot's GWM team ball at each of
    /// its control ticks while the ball is visible (see [`metrics`]).
    pub team_ball_rmse_m: f64,
    /// The same for the centralized filter (every robot's sightings, no network) at the
    /// same instants, m.
    pub centralized_rmse_m: f64,
    /// team_ball_rmse_m / centralized_rmse_m.
    pub rmse_ratio: f64,
    /// The centralized filter that also knows every kick as it happens, m: the ceiling for
    /// a team that reports its kicks, as huddle's robots do (the centralized filter
    /// sees sightings only).
    pub centralized_kicks_rmse_m: f64,
    /// team_ball_rmse_m / centralized_kicks_rmse_m.
    pub rmse_ratio_kicks: f64,
    /// The network-limited reference at the same instants, m: at each robot, the
    /// centralized filter fed exactly the ball information that had reached it (see
    /// [`metrics`]); what the centralized filter makes of what this network delivered.
    pub network_limited_rmse_m: f64,
    /// team_ball_rmse_m / network_limited_rmse_m: what the fusion itself costs.
    pub fusion_ratio: f64,
    /// network_limited_rmse_m / centralized_kicks_rmse_m: what the network costs (both know
    /// the kicks; the reference only once their reports arrive).
    pub network_ratio: f64,
    /// Samples of robots that had not seen the ball themselves within their ball memory.
    pub blind_samples: u64,
    /// Team-ball RMSE over those samples, m.
    pub blind_team_ball_rmse_m: f64,
    /// Centralized RMSE over those samples, m.
    pub blind_centralized_rmse_m: f64,
    /// Network-limited reference RMSE over those samples, m.
    pub blind_network_limited_rmse_m: f64,
    /// Average position NEES (2 dof) of the team ball over the same samples.
    pub team_ball_nees: f64,
    /// Its χ² 95% bounds for `team_ball_nees_samples` independent samples.
    pub team_ball_nees_bounds: [f64; 2],
    /// Independent samples the bounds assume (one per second of ball-visible time).
    pub team_ball_nees_samples: u64,
    /// Average position NEES of the centralized filter.
    pub centralized_nees: f64,
    /// Team-ball samples (robot ticks) behind the RMSEs.
    pub team_ball_samples: u64,
    /// Pose position RMSE of every robot's pose EKF at each of its ticks, m.
    pub pose_rmse_m: f64,
    /// Heading RMSE, rad.
    pub heading_rmse_rad: f64,
    /// Average pose NEES (3 dof).
    pub pose_nees: f64,
    /// Simulated seconds per wall-clock second (the only field that varies between runs
    /// with the same seed).
    pub sim_speed_x: f64,
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "huddle sim: {} robots, {:.0} s simulated, network {} (loss {:.1}%, latency {:.0} ms ± {:.0} ms), seed {}",
            self.robots, self.duration_s, self.preset, self.loss_pct, self.latency_ms, self.jitter_ms, self.seed
        )?;
        writeln!(
            f,
            "ball visible          {:>9.1} s  ({:.1}% of the match)",
            self.ball_visible_s, self.ball_visible_pct
        )?;
        writeln!(
            f,
            "exactly one goer      {:>9.2} %  of ball-visible time",
            self.exactly_one_goer_pct
        )?;
        writeln!(f, "two or more goers     {:>9.2} %", self.conflict_pct)?;
        writeln!(f, "no goer               {:>9.2} %", self.no_goer_pct)?;
        writeln!(
            f,
            "longest conflict      {:>9.0} ms (at {:.1} s; bound = measured p99 delay {:.0} ms + 2 refresh = {:.0} ms; median delay {:.0} ms)",
            self.longest_conflict_ms, self.longest_conflict_at_s, self.delay_p99_ms, self.conflict_bound_ms, self.delay_p50_ms
        )?;
        writeln!(
            f,
            "handovers             {:>9.2} /min ({} in all)",
            self.handovers_per_min, self.handovers
        )?;
        writeln!(
            f,
            "flaps                 {:>9.2} /min ({} in all)",
            self.flaps_per_min, self.flaps
        )?;
        writeln!(
            f,
            "play                  {} shots, {} passes, goals {}–{}",
            self.shots, self.passes, self.goals_for, self.goals_against
        )?;
        writeln!(
            f,
            "network               {} frames sent, {} delivered, {} lost",
            self.frames_sent, self.frames_delivered, self.frames_lost
        )?;
        writeln!(
            f,
            "team ball RMSE        {:>9.4} m  (centralized {:.4} m, ratio {:.3}; {} robot ticks)",
            self.team_ball_rmse_m, self.centralized_rmse_m, self.rmse_ratio, self.team_ball_samples
        )?;
        writeln!(
            f,
            "  centralized + kicks {:>9.4} m  (also told every kick at once; ratio {:.3})",
            self.centralized_kicks_rmse_m, self.rmse_ratio_kicks
        )?;
        writeln!(
            f,
            "  network-limited     {:>9.4} m  (centralized fed what reached each robot: fusion costs ×{:.3}, the network ×{:.3})",
            self.network_limited_rmse_m, self.fusion_ratio, self.network_ratio
        )?;
        writeln!(
            f,
            "  robots blind to it  {:>9.4} m  (centralized {:.4} m, network-limited {:.4} m; {} robot ticks)",
            self.blind_team_ball_rmse_m,
            self.blind_centralized_rmse_m,
            self.blind_network_limited_rmse_m,
            self.blind_samples
        )?;
        writeln!(
            f,
            "team ball NEES        {:>9.3}    (χ² 95% bounds [{:.3}, {:.3}] for {} independent samples; centralized {:.3})",
            self.team_ball_nees,
            self.team_ball_nees_bounds[0],
            self.team_ball_nees_bounds[1],
            self.team_ball_nees_samples,
            self.centralized_nees
        )?;
        writeln!(
            f,
            "pose                  {:>9.4} m RMSE, heading {:.4} rad RMSE, NEES {:.3} (3 dof)",
            self.pose_rmse_m, self.heading_rmse_rad, self.pose_nees
        )?;
        write!(
            f,
            "speed                 {:>9.0} × real time",
            self.sim_speed_x
        )
    }
}
