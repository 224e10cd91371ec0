//! The team simulator behind `huddle sim`: a whole team on one field, talking only
//! through comms replicas over netsim, and a report on how well the team layer's world
//! model, sending policy and should-I-go arbitration held up against references given
//! the same information.
//!
//! **What it is not.** No robot runs this crate. The field's truth ([`field`]: the ball,
//! the bodies, the cameras, the goals) lives here and only here; the robots' brains are
//! the `player` crate (perception, tactics, motion) around the product's `team` layer,
//! and neither of those depends on this crate, so a brain cannot read the truth or the
//! world's constants: the crate boundary enforces it. `huddle sim --daemons`
//! ([`daemons`]) runs the same robots against real `huddle daemon`s instead.
//!
//! The loop runs on a fixed physics step (10 ms). Before each step the network and the
//! replicas are brought up to the step's instant ([`Harness::run_until`]); every robot
//! whose control tick is due then senses, decides and acts ([`Robot::tick`]), its
//! blackboard writes go into its replica (and out at once), the world moves one step,
//! and the arbitration [`Metrics`] take a sample. Robots' control ticks are spread over
//! the control period (robot k starts k/N of a period late), as unsynchronised robots are.
//! Each tick a robot gets its camera [`Frame`](crate::field::camera::Frame), its
//! [`Odometry`](crate::field::body::Odometry) and its replica's blackboard.
//!
//! Two seconds of the default match (five robots, the `competition` network):
//!
//! ```
//! use teamsim::{SimConfig, Simulation};
//!
//! let cfg = SimConfig { duration_s: 2.0, seed: 7, ..SimConfig::default() };
//! let mut sim = Simulation::new(cfg).expect("the defaults are valid");
//! sim.run(|_t_s| {});
//! let report = sim.report(0.0);
//! assert!(report.frames_sent > 0, "the robots talked");
//! ```

#![forbid(unsafe_code)]

pub mod acoustic;
mod acoustic_channel;
pub mod daemons;
mod daemons_air;
pub mod daemons_game;
mod daemons_in_process;
mod daemons_report;
pub mod field;
mod game;
pub mod metrics;
/// What a simulated robot's senses mean to its team layer ([`player::perception`]).
pub use player::perception;
/// The sending policies: the team layer's ([`team::policy`]).
pub use team::policy;
pub mod referee;
pub mod references;
mod report;
/// One of our robots: the simulated player ([`player::robot`]).
pub use player::robot;
pub mod svg;

use std::time::Duration;

use comms::arbitration::ArbitrationParams;
use comms::ReplicaConfig;
use netsim::{LinkConfig, Preset, Sim as Net, Time, UplinkConfig};
use serde::Serialize;

use crate::field::behaviour::{formation_homes, Position};
use crate::field::geometry::{Pose, Vec2};
use crate::field::{FieldConfig, World};
use comms_netsim::{Harness, HarnessError};
pub use game::{
    GameReport, GoalHeard, GoalNews, PlayBreakdown, ToldAgeBin, WithPenalised,
    SINCE_KICK_OFF_BINS_S, TOLD_AGE_BINS_S,
};
pub use metrics::{BallEvent, BallSample, FusionMetrics, Metrics, Timeline, FLAP_WINDOW_S};
pub use references::{
    CentralFusion, DelayedCentral, DeliveryReference, KickTruth, Publications, ReferenceConfig,
};
pub use report::{NeesBand, NeesCause, Report, SweepRow};
pub use robot::{BrainConfig, Percepts, Robot, TickInput, TickOutput, WorldModelConfig};

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
    /// DTIM period in beacons (overrides the preset's; with `competition`, which has no
    /// power-save hold, it adds one).
    pub dtim_period: Option<u32>,
}

fn budget_name<S: serde::Serializer>(
    b: &Option<comms::BudgetSpec>,
    s: S,
) -> Result<S::Ok, S::Error> {
    match b {
        Some(b) => s.serialize_str(&b.to_string()),
        None => s.serialize_none(),
    }
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
            dtim_period: None,
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
            dtim_period: None,
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
        if let Some(period) = self.dtim_period {
            link.beacon = Some(netsim::dtim_interval(period));
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

/// How frames travel (`huddle daemon --transport`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Transport {
    /// To the team's multicast group (held to the DTIM beacon under power save).
    #[default]
    Multicast,
    /// UDP broadcast (the SPL's rule): group-addressed for the air and the access point,
    /// so in netsim the same as multicast.
    Broadcast,
    /// One unicast copy to each teammate: not held to the beacon; each copy is a frame
    /// on the air (and would be a message against a league's count).
    Unicast,
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
    /// The network's own seed (its loss and latency draws, incarnations), if not `seed`:
    /// the same world with other network luck.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub network_seed: Option<u64>,
    /// The field and its physics.
    pub field: FieldConfig,
    /// How robots sense and play.
    pub brain: BrainConfig,
    /// The references' filters (each tuned for its own RMSE).
    #[serde(skip)]
    pub references: ReferenceConfig,
    /// Arbitration parameters.
    #[serde(skip)]
    pub arbitration: ArbitrationParams,
    /// How frames travel.
    pub transport: Transport,
    /// A league's message budget for the team, pooled by its robots (every robot runs
    /// huddle: `comms::BudgetSpec::share`), or none.
    #[serde(serialize_with = "budget_name")]
    pub budget: Option<comms::BudgetSpec>,
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
    // --- WLAN outage and the acoustic fallback (see `acoustic`) ---
    /// A WLAN outage (all links down), if any.
    pub outage: Option<acoustic::OutageConfig>,
    /// The acoustic fallback and its room.
    pub acoustic: acoustic::AcousticConfig,
    /// What the robots' brains know of their bodies, ball and field (`None`: the field's
    /// own constants, [`FieldConfig::exact_calibration`]).
    #[serde(skip)]
    pub calibration: Option<team::Calibration>,
    /// Draw the match's physics around `field` ([`crate::field::drawn_field`]), start
    /// each robot believing a pose off by its start σ, and give each robot a clock with
    /// an offset and a drift; the robots' calibration stays `field`'s nominal figures.
    pub drawn_world: bool,
    /// Play a whole game under a simulated GameController ([`referee`]): it ends when
    /// the referee says so (`duration_s` is then only a cap). `None`: a plain match.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub game: Option<referee::GameScript>,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            robots: 5,
            opponents: 3,
            duration_s: 300.0,
            network: NetworkConfig::default(),
            seed: 1,
            network_seed: None,
            field: FieldConfig::default(),
            brain: BrainConfig::default(),
            references: ReferenceConfig::default(),
            budget: None,
            transport: Transport::Multicast,
            arbitration: ArbitrationParams::default(),
            compensate_latency: true,
            refresh_period: Duration::from_millis(100),
            physics_dt_s: 0.01,
            snapshot_every_s: 0.25,
            outage: None,
            acoustic: acoustic::AcousticConfig::default(),
            calibration: None,
            drawn_world: false,
            game: None,
        }
    }
}

impl SimConfig {
    /// Under a budget, the longest two robots can both go by the arbitration's own
    /// parameters (`params` as the team runs them, budget and latency compensation
    /// applied), not by the run's gaps: a new claimant B backs off once it hears the old
    /// goer A still claiming in a post made `2 × latency_compensation + ack_margin` after
    /// B's claim; A posts at least every keepalive (`stale_after / 2` under a budget), that
    /// post takes at most `delay` (the measured p99) and B decides within a control
    /// period. It assumes the keepalive that matters is not lost: each lost one adds a
    /// keepalive period, and the report counts the matches where the longest conflict
    /// went past it.
    pub fn conflict_bound_budgeted(&self, params: &ArbitrationParams, delay: Duration) -> Duration {
        params.latency_compensation * 2
            + params.ack_margin
            + params.stale_after / 2
            + delay
            + Duration::from_secs_f64(self.brain.team.control_period_s)
    }

    /// The longest two robots can both go, given the longest time the network kept one
    /// robot's claims from another (`claim_gap`, measured: bursts and beacon holds
    /// included) and the one-way delay (`delay`, the measured 99th percentile): see
    /// [`Report::conflict_bound_ms`] for why.
    pub fn conflict_bound(&self, claim_gap: Duration, delay: Duration) -> Duration {
        claim_gap + delay + Duration::from_secs_f64(self.brain.team.control_period_s)
    }

    /// The mean one-way delay frames take with this transport: unicast is not held to
    /// the beacon.
    pub fn expected_delay(&self) -> Duration {
        match self.transport {
            Transport::Unicast => self.network.latency(),
            Transport::Multicast | Transport::Broadcast => self.network.expected_delay(),
        }
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
    /// The reference: the team's fusion fed every robot's LWM at every tick at once, no
    /// network (see [`references`]).
    pub central: CentralFusion,
    /// The same told every kick that met the ball for sure, and no swing that missed
    /// (cK): the ceiling for a team that reports its kicks.
    pub central_kicks: CentralFusion,
    /// Which kick attempts met the ball, for cK.
    pub kick_truth: KickTruth,
    /// Per robot: its fusion fed what that robot received, at true times.
    pub delivery: Vec<DeliveryReference>,
    /// The delayed-centralized reference's record.
    pub delayed: DelayedCentral,
    /// When each robot published each LWM version (global seconds).
    pub publications: Publications,
    /// Kick attempts the robots swung, and how many met the ball.
    pub kick_attempts: u64,
    /// Kicks that met the ball.
    pub kick_contacts: u64,
    /// Shots and passes that met the ball.
    pub contacts: robot::PlayCounts,
    /// Who went when.
    pub timeline: Timeline,
    /// Field snapshots for the picture.
    pub snapshots: Vec<Snapshot>,
    homes: Vec<Vec2>,
    holders: Vec<u8>,
    next_tick_s: Vec<f64>,
    /// When each robot last ticked (global s): its latest world model's publication time.
    ticked_at_s: Vec<f64>,
    step: u64,
    next_snapshot_s: f64,
    /// The latest event that changed the true ball's motion (global s), for the NEES
    /// tail's causes.
    ball_event: (f64, BallEvent),
    /// Whose kick or push it was (robot index).
    ball_event_by: Option<usize>,
    /// A kick met the ball during this step (robot index).
    kick_met: Option<usize>,
    // --- WLAN outage and the acoustic fallback (see `acoustic`) ---
    /// The room, when the fallback is on.
    acoustic: Option<acoustic::AcousticChannel>,
    /// Arbitration figures inside the outage window (and just before it).
    outage_metrics: acoustic::OutageFigures,
    /// The arbitration's parameters as the robots run them (budget and latency
    /// compensation applied), for the budgeted conflict bound.
    arbitration_run: ArbitrationParams,
    /// |estimated − true| teammate clock offsets, µs, sampled once a simulated second.
    clock_errors_us: Vec<f64>,
    /// The GameController and what each robot heard of it (`--game`).
    game: Option<game::Game>,
    /// Blind robots' team-ball error by the age of the newest ball told them.
    blind_by_told_age: game::BlindByToldAge,
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
        if !(cfg.physics_dt_s > 0.0 && cfg.brain.team.control_period_s >= cfg.physics_dt_s) {
            return Err(SimError::Config(
                "the control period must be at least one physics step".into(),
            ));
        }
        let n = cfg.robots;
        let with_keeper = n >= 3;
        let field_players = n - usize::from(with_keeper);
        let calibration = cfg
            .calibration
            .unwrap_or_else(|| cfg.field.exact_calibration());
        // The formation is the team's: drawn on the field's lines as the robots know them.
        let homes = formation_homes(&calibration.field, field_players);
        let mut positions = Vec::with_capacity(n);
        if with_keeper {
            positions.push(Position::Goalkeeper);
        }
        positions.extend((0..field_players).map(Position::Field));
        let holders: Vec<u8> = (0..field_players)
            .map(|k| comms_netsim::robot_id(k + usize::from(with_keeper)))
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
        // A drawn world's own stream, apart from the match's noise.
        let mut draw = <rand_chacha::ChaCha8Rng as rand::SeedableRng>::seed_from_u64(
            cfg.seed ^ 0x000d_0a11_c10c_0000,
        );
        let world_field = if cfg.drawn_world {
            crate::field::drawn_field(&cfg.field, cfg.seed)
        } else {
            cfg.field
        };
        let world = World::new(world_field, &starts, cfg.opponents, cfg.seed);
        let mut params = cfg.arbitration;
        let mut world_model = cfg.brain.team.world_model;
        let budget = cfg.budget.map(|b| b.share(n));
        if let Some(b) = budget {
            // The daemon sets a budgeted team up the same way.
            team::adapt_to_budget(&mut params, &mut world_model, b.interval());
        }
        if cfg.compensate_latency && params.latency_compensation.is_zero() {
            params.latency_compensation = cfg.expected_delay();
        }
        // No transit for the GWM to subtract: comms' ages include each frame's own
        // transit, estimated from the traffic (wire format 3), so `transit_s` stays 0.
        let robots = positions
            .iter()
            .zip(&starts)
            .enumerate()
            .map(|(i, (&p, &truth))| {
                // Put on its spot by hand: it believes the spot, off by its start σ.
                let pose = if cfg.drawn_world {
                    let wm = &world_model;
                    let mut n = || crate::field::camera::standard_normal(&mut draw);
                    Pose {
                        at: truth.at + Vec2::new(wm.start_sigma_m * n(), wm.start_sigma_m * n()),
                        theta_rad: fusion::wrap_angle(truth.theta_rad + wm.start_sigma_rad * n()),
                    }
                } else {
                    truth
                };
                Robot::new(
                    comms_netsim::robot_id(i),
                    p,
                    params,
                    pose,
                    &calibration,
                    &world_model,
                    n,
                )
            })
            .collect();
        // The references know the ball as the team does (its calibration), not the world.
        let references = cfg.references.on_team(fusion::BallFilterConfig {
            model: world_model.global.ball,
            ..world_model.local.ball
        });
        // Each reference runs the team's own fusion (its GWM and its settings).
        let central_config = references.central_fusion(world_model.global);
        let central = CentralFusion::new(central_config);
        let central_kicks = CentralFusion::new(central_config);
        let delayed = DelayedCentral::new(references.delayed_fusion(world_model.global), n);
        let delivery_config = references.delivery_fusion(world_model.global);
        let delivery = (0..n)
            .map(|i| DeliveryReference::new(comms_netsim::robot_id(i), delivery_config, n))
            .collect();
        let cfg = SimConfig { references, ..cfg };
        let arbitration_run = params;
        let (link, uplink) = cfg.network.links();
        let net = Net::builder().link(link).uplink(uplink);
        let mut replica = ReplicaConfig::new(1, 1)
            .with_refresh_period(cfg.refresh_period)
            .with_known_paths(team::known_paths());
        if let Some(spec) = &cfg.budget {
            replica = replica.with_budget(spec, n);
        }
        let mut harness = Harness::new(n, net, replica, cfg.network_seed.unwrap_or(cfg.seed))?;
        harness.set_unicast(cfg.transport == Transport::Unicast);
        if cfg.drawn_world {
            for i in 0..n {
                let offset = Duration::from_secs_f64(20.0 * rand::RngExt::random::<f64>(&mut draw));
                let drift_ppm = 30.0 * crate::field::camera::standard_normal(&mut draw);
                harness.set_clock(i, offset, drift_ppm)?;
            }
        }
        harness.keep_events(false);
        let game = cfg.game.clone().map(|script| {
            harness.log_sent(true);
            // Under a budget the replicas follow the GC's figures, as a daemon's do.
            let budget = cfg.budget.map(|_| gamecontroller::GcBudget {
                half: Duration::from_secs_f64(script.half_s),
                messages_per_game: u32::from(script.messages_per_game),
                ..gamecontroller::GcBudget::spl(u8::try_from(n).unwrap_or(u8::MAX))
            });
            let spots = world.opponents.iter().map(|b| b.pose).collect();
            let loss = cfg.network.mean_loss();
            game::Game::new(script, n, budget, loss, spots, cfg.seed)
        });
        let period = cfg.brain.team.control_period_s;
        let next_tick_s = (0..n).map(|i| period * i as f64 / n as f64).collect();
        let mut sim = Self {
            timeline: Timeline::new(n),
            cfg,
            world,
            robots,
            harness,
            metrics: Metrics::default(),
            fusion: FusionMetrics::default(),
            central,
            central_kicks,
            kick_truth: KickTruth::new(n),
            delivery,
            delayed,
            publications: Publications::new(n),
            kick_attempts: 0,
            kick_contacts: 0,
            contacts: robot::PlayCounts::default(),
            snapshots: Vec::new(),
            homes,
            holders,
            next_tick_s,
            ticked_at_s: vec![0.0; n],
            step: 0,
            next_snapshot_s: 0.0,
            ball_event: (f64::NEG_INFINITY, BallEvent::Quiet),
            ball_event_by: None,
            kick_met: None,
            acoustic: None,
            outage_metrics: acoustic::OutageFigures::default(),
            arbitration_run,
            clock_errors_us: Vec::new(),
            game,
            blind_by_told_age: Default::default(),
        };
        sim.setup_fallback()?;
        Ok(sim)
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
        self.game.as_ref().is_some_and(|g| g.referee.over())
            || self.time_s() >= self.cfg.duration_s - 1e-9
    }

    /// One physics step: network up to now, due control ticks, physics, a metrics sample.
    pub fn step(&mut self) {
        let dt = self.cfg.physics_dt_s;
        let t = self.time_s();
        self.harness.run_until(Time::from_secs_f64(t));
        self.referee_count(t);
        self.referee_step(t);
        // Whether the radio works (with the GC's packets in `referee_step`), as a
        // daemon's layer learns it from its replica every tick.
        for i in 0..self.robots.len() {
            if let Some(replica) = self.harness.replica(i) {
                let now = self.harness.local_now(i);
                self.robots[i].heard_teammates(now, replica.peers());
            }
        }
        self.acoustic_step(t);
        let mut ticked = Vec::new();
        // Built once a step, not per robot and write (each build parses and allocates).
        let lwm_key = robot::world_local_key();
        let claim_key = comms::arbitration::heuristic_key();
        for i in 0..self.robots.len() {
            if self.next_tick_s[i] > t + 1e-9 {
                let Some(replica) = self.harness.replica(i) else {
                    continue;
                };
                let now = self.harness.local_now(i);
                let waiting = replica.is_pending(&lwm_key);
                let writes = self.robots[i].redecide(replica.blackboard(), now, waiting);
                for (key, value) in writes {
                    let lwm = key == lwm_key;
                    if lwm {
                        // Its latest tick's world model, riding along: stamped at its
                        // tick, so teammates place it where it holds.
                        let (now, built) = (now, self.robots[i].world_model_built());
                        match self.harness.replica_mut(i) {
                            Some(r) => r.set_key_built(now, &key, value, built),
                            None => Ok(()),
                        }
                    } else {
                        // A goer change: priority under a budget.
                        self.harness.set_priority(i, &key, value)
                    }
                    .expect("robots only write their own valid keys");
                    if lwm {
                        self.record_publication(i, self.ticked_at_s[i]);
                    }
                }
                continue;
            }
            self.next_tick_s[i] += self.cfg.brain.team.control_period_s;
            if !self.robots[i].alive {
                continue;
            }
            self.ticked_at_s[i] = t;
            let Some(replica) = self.harness.replica(i) else {
                continue;
            };
            // The robot's senses: all it gets of the world. Its previous frame (replaced
            // first thing in its tick) lends its vectors.
            let spare = std::mem::take(&mut self.robots[i].frame);
            let percepts = Percepts {
                frame: self.world.look_reusing(i, spare),
                odometry: self.world.read_odometry(i),
            };
            let local_now = self.harness.local_now(i);
            let input = TickInput {
                local_now,
                percepts,
                board: replica.blackboard(),
                world_model_waiting: replica.is_pending(&lwm_key),
                claim_waiting: replica.is_pending(&claim_key),
                budget_headroom: replica.budget_headroom(),
                homes: &self.homes,
                holders: &self.holders,
            };
            let out = self.robots[i].tick(&self.cfg.brain, input);
            if let Some(cmd) = out.command {
                self.world.command_believed(i, cmd, &out.believed);
            }
            for (key, value) in out.writes {
                let lwm = key == lwm_key;
                // Our own keys of valid shape: a refusal would be a bug worth seeing.
                if out.priority {
                    self.harness.set_priority(i, &key, value)
                } else {
                    self.harness.set(i, &key, value)
                }
                .expect("robots only write their own valid keys");
                if lwm {
                    self.record_publication(i, t);
                }
            }
            self.judge_kick(i, out.kick.as_ref());
            self.feed_references(i, t);
            ticked.push(i);
        }
        self.harness.flush();
        self.referee_count(t);
        let in_play = self.in_play();
        if in_play {
            self.sample_claim_ages();
            self.sample_world_models(t, &ticked);
        }
        let ball_before = self.world.ball;
        let goal = self.world.step(dt);
        if let Some(g) = goal {
            self.referee_goal(t + dt, g == crate::field::Goal::For);
        }
        self.referee_hold();
        self.note_ball_event(t + dt, &ball_before);
        if goal.is_some() && self.game.is_none() {
            // No GameController (plain `huddle sim`): the ball is put back near the centre
            // spot and play goes on at once, with no Ready or Set. Every robot's team
            // layer is told at the goal's instant, as the robot program's ball reset
            // (`player::remote::RemoteRobot::ball_reset`, the contract's `BALL_RESET_KEY`,
            // which `huddle sim --daemons` writes to each daemon at this same instant)
            // tells it: this stands in for a GameController with no delay and no lost
            // packet, the best case of how a team learns a goal. Under `--game` each
            // robot learns it from the simulated GC's packets it receives
            // (`TeamLayer::set_scores` in `game.rs`, or at Set), as the daemon does.
            // It happened during this step, after every sighting made at its start.
            // Every reference puts it there too, as the team layer does.
            for i in 0..self.robots.len() {
                let now_s = self.harness.local_now(i).as_micros() as f64 * 1e-6 + dt;
                self.robots[i].forget_ball(now_s);
            }
            let everyone: Vec<usize> = (0..self.robots.len()).collect();
            self.place_references(&everyone, dt);
        }
        self.step += 1;
        if self.step.is_multiple_of(CLOCK_SAMPLE_STEPS) {
            self.sample_clocks();
        }
        let t_end = self.time_s();
        let visible = self
            .robots
            .iter()
            .any(|r| r.is_field_player() && r.sees_ball() && !r.penalized());
        let goers: Vec<u8> = self
            .robots
            .iter()
            .filter(|r| r.is_field_player() && r.going())
            .map(|r| r.id)
            .collect();
        if let Some(game) = &mut self.game {
            game.sample_play(t_end, dt, visible, goers.len());
        }
        if in_play {
            self.metrics.sample(t_end, dt, visible, &goers);
            self.sample_outage(t_end, visible, &goers);
        }
        self.timeline
            .sample(t_end, visible, self.robots.iter().map(|r| r.going()));
        if self.cfg.snapshot_every_s > 0.0 && t_end >= self.next_snapshot_s {
            self.next_snapshot_s += self.cfg.snapshot_every_s;
            self.snapshots.push(Snapshot {
                t_s: t_end,
                robots: self.world.robots.iter().map(|b| b.pose).collect(),
                going: self.robots.iter().map(|r| r.going()).collect(),
                opponents: self.world.opponents.iter().map(|b| b.pose.at).collect(),
                ball: self.world.ball.at,
            });
        }
    }

    /// What changed the ball's motion during the step that ended at `t_s`, other than
    /// friction (the truth, for the metrics only): a kick that met it, the boards, or the
    /// body it now touches.
    fn note_ball_event(&mut self, t_s: f64, before: &crate::field::ball::Ball) {
        let kicked = self.kick_met.take();
        let cfg = *self.world.config();
        let dt = self.cfg.physics_dt_s;
        let speed = before.velocity.norm();
        let slowed =
            (speed * (1.0 - cfg.ball.drag_per_s * dt) - cfg.ball.rolling_decel_mps2 * dt).max(0.0);
        let rolled = if speed > 0.0 {
            before.velocity * (slowed / speed)
        } else {
            before.velocity
        };
        let ball = self.world.ball;
        let mut by = kicked;
        let event = if kicked.is_some() {
            BallEvent::Kick
        } else if (ball.velocity - rolled).norm() < 1e-3 {
            return;
        } else {
            let (hx, hy) = (
                cfg.length_m / 2.0 + cfg.border_m - cfg.ball.radius_m,
                cfg.width_m / 2.0 + cfg.border_m - cfg.ball.radius_m,
            );
            let touches = |at: Vec2, r: f64| at.distance(ball.at) <= r + cfg.ball.radius_m + 1e-6;
            // A body pressing the ball into the boards is a push, not a bounce.
            by = self
                .world
                .robots
                .iter()
                .position(|b| touches(b.pose.at, cfg.kinematics.radius_m));
            if by.is_some() {
                BallEvent::OurPush
            } else if self
                .world
                .opponents
                .iter()
                .any(|b| touches(b.pose.at, cfg.opponent_kinematics.radius_m))
            {
                BallEvent::OpponentPush
            } else if ball.at.x.abs() >= hx - 1e-9 || ball.at.y.abs() >= hy - 1e-9 {
                BallEvent::Bounce
            } else {
                // The kick-off put it back: no team ball survives that.
                return;
            }
        };
        self.ball_event = (t_s, event);
        self.ball_event_by = by;
    }

    /// Robot `i` published its LWM at global `t_s`: remember which version that was, for
    /// the delivery references' true times.
    fn record_publication(&mut self, i: usize, t_s: f64) {
        let id = self.robots[i].id;
        if let Some(e) = self
            .harness
            .replica(i)
            .and_then(|r| r.blackboard().get(&robot::world_local_of(id)))
        {
            self.publications.record(i, e.version, t_s);
        }
    }

    /// The world carries out robot `i`'s kick attempt, turned by the robot's heading error
    /// as its motion is; the references that are told kicks hear of it.
    fn judge_kick(&mut self, i: usize, attempt: Option<&robot::KickAttempt>) {
        let Some(a) = attempt else {
            return;
        };
        self.kick_attempts += 1;
        let truth = self.world.robots[i].pose.theta_rad;
        let off = fusion::wrap_angle(truth - self.robots[i].pose_belief.theta_rad);
        let met = self.world.kick(i, a.direction_rad + off);
        // The team knows the attempt (the kicker's report, its contact odds included); cK
        // is told whether it met the ball.
        self.kick_truth.record(i, a.report.t_s, met);
        if met {
            self.kick_met = Some(i);
            self.kick_contacts += 1;
            if a.receiver != 0 {
                self.contacts.passes += 1;
            } else {
                self.contacts.shots += 1;
            }
        }
    }

    /// Robot `i`'s LWM of its tick at global `t_s` into the references, and what its
    /// replica received into its delivery reference.
    fn feed_references(&mut self, i: usize, t_s: f64) {
        let now_s = robot::seconds(self.harness.local_now(i));
        // The kick-off placements the tick made, by every reference at the same instant
        // and in the same order as by the team layer: Set's before it heard its
        // teammates; play heard's after, before its own message.
        let placement = self.robots[i].kick_off_placement();
        if placement == Some(team::KickOffPlacement::Set) {
            self.delivery[i].place(self.robots[i].kick_off_ball(now_s));
        }
        if placement == Some(team::KickOffPlacement::PlayHeard) {
            self.place_whole_team_references(t_s, true);
        }
        let r = &self.robots[i];
        // The sightings the robot's own ball filter took: what its batches tell the team
        // (a false ball its track gated out never reaches a teammate).
        let taken = r.ball_sighting.as_ref().filter(|_| r.ball_sighting_taken);
        let lwm = references::tick_lwm(&r.lwm, now_s, taken);
        let id = r.id;
        let global = references::shifted(&lwm, t_s - now_s);
        self.central.lwm(id, &global, t_s);
        let told = references::shifted(&self.kick_truth.told(i, &lwm), t_s - now_s);
        self.central_kicks.lwm(id, &told, t_s);
        self.delayed.lwm(t_s, i, &global);
        if let Some(replica) = self.harness.replica(i) {
            let harness = &self.harness;
            let publications = &self.publications;
            let layer = &self.robots[i];
            let shift_s = self.cfg.references.delivery_shift_s;
            let as_team = self.cfg.references.delivery_as_team;
            let (jitter_s, salt) = self.cfg.references.delivery_jitter_s;
            self.delivery[i].receive(
                i,
                replica.blackboard(),
                now_s,
                |j, version| {
                    if as_team.0 {
                        return layer
                            .gwm
                            .latest(comms_netsim::robot_id(j))
                            .map(|l| l.t_s);
                    }
                    let sent = publications.sent_at(j, version)?;
                    Some(
                        robot::seconds(harness.local_at(i, Time::from_secs_f64(sent)))
                            + shift_s
                            + jitter_s * unit_hash(salt, j as u64, version),
                    )
                },
                |j, incarnation, version| {
                    let lwm = layer.decoded_lwm(comms_netsim::robot_id(j), incarnation, version);
                    if trace_on() {
                        let placed = publications.sent_at(j, version).map(|sent| {
                            robot::seconds(harness.local_at(i, Time::from_secs_f64(sent)))
                        });
                        if let Some(l) = lwm {
                            let b = l.ball.map(|b| b.position());
                            let o = l.observation.map(|o| (o.t_s, o.position));
                            eprintln!(
                                "M {t_s:.3} r{} from r{} v{version} team_t {:.4} ref_t {:.4} ball {:?} obs {:?} kick {}",
                                i + 1,
                                j + 1,
                                l.t_s,
                                placed.unwrap_or(f64::NAN),
                                b.map(|p| (p.x, p.y)),
                                o,
                                l.kick.is_some()
                            );
                        }
                    }
                    lwm
                },
            );
        }
        if placement == Some(team::KickOffPlacement::PlayHeard) {
            self.delivery[i].place_again(self.robots[i].kick_off_ball(now_s));
        }
        // Its own after its teammates', as its team layer takes them.
        let as_published = match self.cfg.references.delivery_as_team.1 {
            true => self.robots[i].gwm.latest(id).copied(),
            false => None,
        };
        self.delivery[i].own(id, as_published.as_ref().unwrap_or(&lwm), now_s);
        if trace_on() {
            let gwm_line = |g: &fusion::GlobalModel| {
                let st = g.stats();
                let own = g
                    .latest(id)
                    .and_then(|l| l.observation)
                    .map(|o| (o.t_s, o.position.x, o.position.y));
                let b = g.team_ball(now_s, None).map(|b| b.estimate.mean);
                format!(
                    "acc {} rej {} late {} rs {} k {} kr {} tr {} own {:?} ball {:?}",
                    st.accepted,
                    st.rejected,
                    st.late,
                    st.restarts,
                    st.kicks,
                    st.kicks_refused,
                    st.tracks,
                    own,
                    b.map(|m| (m[0], m[1], m[2], m[3]))
                )
            };
            eprintln!(
                "G {t_s:.2} r{} TEAM {} | REF {}",
                i + 1,
                gwm_line(&self.robots[i].gwm),
                gwm_line(self.delivery[i].gwm())
            );
        }
    }

    /// Each live robot's estimate of each teammate's clock offset against the truth.
    fn sample_clocks(&mut self) {
        for i in 0..self.robots.len() {
            let Some(replica) = self.harness.replica(i) else {
                continue;
            };
            let mine = self.harness.local_now(i).as_micros() as i64;
            for p in replica.peers() {
                let (Some(est), Some(j)) = (p.clock_offset_us, usize::from(p.robot).checked_sub(1))
                else {
                    continue;
                };
                if j >= self.robots.len() || self.harness.replica(j).is_none() {
                    continue;
                }
                let truth = self.harness.local_now(j).as_micros() as i64 - mine;
                self.clock_errors_us
                    .push((est - truth).unsigned_abs() as f64);
            }
        }
    }

    /// How old the live teammates' claims were that each live robot decided on.
    fn sample_claim_ages(&mut self) {
        for r in self.robots.iter().filter(|r| r.alive) {
            for &(id, age) in &r.claim_ages {
                let teammate = usize::from(id)
                    .checked_sub(1)
                    .and_then(|k| self.robots.get(k));
                if teammate.is_some_and(|o| o.alive) {
                    self.metrics.claim_age(age.as_secs_f64());
                }
            }
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
            // A penalised robot carried off the field is not playing: its samples count
            // only in the game's figures with the penalised (see `game`).
            let off = self.world.off_field(i);
            if let Some(game) = &mut self.game {
                game.sample_pose(e.x * e.x + e.y * e.y, off);
            }
            if !off {
                self.fusion.pose(e.x * e.x + e.y * e.y, e.z * e.z, nees);
            }
            if !visible {
                continue;
            }
            let now_s = self.harness.local_now(i).as_micros() as f64 * 1e-6;
            let (Some(team), Some(c), Some(ck), Some(delivery)) = (
                r.team_ball_held,
                central,
                central_kicks,
                self.delivery[i].estimate_at(now_s),
            ) else {
                continue;
            };
            let pos_nees = |b: &fusion::BallEstimate| {
                let e = truth - b.position();
                b.position_cov()
                    .cholesky()
                    .map_or(f64::NAN, |ch| e.dot(&ch.solve(&e)))
            };
            // The team ball the robot holds from its tick (the same instant: ticks and
            // samples share the step).
            let mut team = team;
            team.estimate = team
                .estimate
                .predict_to(&self.cfg.brain.team.world_model.global.ball, now_s);
            let te = (team.estimate.position() - truth).norm_squared();
            if let Some(game) = &mut self.game {
                game.sample_team_ball(te, r.ball.is_none(), off);
                if r.ball.is_none() && !off {
                    game.sample_blind(t_s, te);
                }
            }
            if off {
                continue;
            }
            if r.ball.is_none() {
                let told = r
                    .gwm
                    .teammates_iter(now_s)
                    .filter_map(|m| m.lwm.ball)
                    .map(|b| b.t_s)
                    .max_by(f64::total_cmp);
                self.blind_by_told_age.add(told.map(|t| now_s - t), te);
            }
            let ce = (c.position() - truth).norm_squared();
            self.fusion.ball(&BallSample {
                team_sq_m2: te,
                team_nees: pos_nees(&team.estimate),
                central_sq_m2: ce,
                central_nees: pos_nees(&c),
                central_kicks_sq_m2: (ck.position() - truth).norm_squared(),
                delivery_sq_m2: (delivery.position() - truth).norm_squared(),
                speed_mps: self.world.ball.velocity.norm(),
                blind: r.ball.is_none(),
                cause: if t_s - self.ball_event.0 <= metrics::CAUSE_WINDOW_S {
                    self.ball_event.1
                } else {
                    BallEvent::Quiet
                },
                cause_age_s: t_s - self.ball_event.0,
                at_actor: self.ball_event_by == Some(i),
            });
            if trace_on() {
                eprintln!(
                    "S {t_s:.2} r{} blind {} te {:.3} de {:.3} truth ({:.2},{:.2}) team ({:.2},{:.2}) ref ({:.2},{:.2})",
                    i + 1,
                    r.ball.is_none(),
                    te.sqrt(),
                    (delivery.position() - truth).norm(),
                    truth.x,
                    truth.y,
                    team.estimate.position().x,
                    team.estimate.position().y,
                    delivery.position().x,
                    delivery.position().y
                );
            }
            self.fusion.instants.push((i, (t_s, truth.x, truth.y), te));
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

    /// The formation's home spots of the field positions (as the robots know the field).
    pub fn homes(&self) -> &[Vec2] {
        &self.homes
    }

    /// The robot id holding each field position.
    pub fn holders(&self) -> &[u8] {
        &self.holders
    }

    /// Switch robot `i` off (it stops and falls silent).
    pub fn kill(&mut self, i: usize) {
        let stop = self.robots[i].kill();
        let believed = self.robots[i].pose_belief;
        self.world.command_believed(i, stop, &believed);
        self.harness.kill(i);
    }
}

/// Teammates' clock offsets are sampled every this many physics steps (1 s at 10 ms).
const CLOCK_SAMPLE_STEPS: u64 = 100;

/// `HUDDLE_SIM_TRACE=1`: print every team-ball sample (team and delivery reference error)
/// and every teammate message as the team and its delivery reference placed it, to
/// stderr (#29's traces; read once per process).
fn trace_on() -> bool {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ON.get_or_init(|| std::env::var_os("HUDDLE_SIM_TRACE").is_some())
}

/// A number in [−1, 1) fixed by (`salt`, `a`, `b`): splitmix64's finaliser, for the
/// delivery reference's diagnostic jitter (no RNG state, the same for the same message).
fn unit_hash(salt: u64, a: u64, b: u64) -> f64 {
    let mut z =
        salt ^ a.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ b.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}
