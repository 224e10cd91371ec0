//! The team layer on a real robot: [`team::TeamLayer`] fed from the `local.var.robot.*`
//! keys a robot program writes (through the relay, the C node or a handle), ticked on the
//! driver's thread, its decisions written to `local.var.team.*` and its messages to the
//! team through the replica, with priority where the layer asks for it. The contract is
//! `docs/team-layer.md` ([`team::contract`]).
//!
//! A malformed input is refused at the relay's `SETV` (a guard per input key), so the
//! layer only ever sees values it can take. The layer stays dormant, writing and sending
//! nothing, until the robot program has said where it is (a pose or an odometry reading):
//! a daemon without a robot program behind it is a plain blackboard.

use std::cell::RefCell;
use std::rc::Rc;
use std::time::Duration;

use comms::arbitration::{self, ArbitrationParams};
use comms::relay::{ErrCode, Rejected};
use comms::{Instant, Key, Replica, Value};
use team::contract::{self, BallInput, KickInput};
use team::{Calibration, Pose, Senses, TeamConfig, TeamLayer};

use crate::{Guard, Handle, Notice, Watch};

/// How the daemon runs its robot's team layer.
#[derive(Debug, Clone, Copy)]
pub struct TeamLayerConfig {
    /// Control period, sending policy, world models.
    pub team: TeamConfig,
    /// The arbitration's parameters.
    pub params: ArbitrationParams,
    /// What the robot knows of its body, ball and field.
    pub calibration: Calibration,
    /// Robots in the team (ids 1..=team_size are teammates).
    pub team_size: usize,
    /// Under a budget: the interval its pacing allows between this robot's messages
    /// (claims and world models are held that long, see [`team::adapt_to_budget`]).
    pub budget_interval: Option<Duration>,
}

impl TeamLayerConfig {
    /// The layer for a team of `team_size` robots: `voi` under a budget, `every` without.
    pub fn new(team_size: usize, budget_interval: Option<Duration>) -> Self {
        let mut team = TeamConfig {
            send_policy: team::SendPolicy::default_for(budget_interval.is_some()),
            ..TeamConfig::default()
        };
        let mut params = ArbitrationParams::default();
        if let Some(interval) = budget_interval {
            team::adapt_to_budget(&mut params, &mut team.world_model, interval);
        }
        TeamLayerConfig {
            team,
            params,
            calibration: Calibration::default(),
            team_size,
            budget_interval,
        }
    }
}

/// What the robot program wrote since the previous tick.
#[derive(Default)]
struct Inputs {
    pose: Option<(contract::PoseInput, Instant)>,
    odometry: Vec<fusion::Odometry>,
    landmarks: Vec<(fusion::RangeBearingSighting, fusion::nalgebra::Matrix2<f64>)>,
    balls: Vec<(BallInput, Instant)>,
    kicks: Vec<(KickInput, Instant)>,
    goal_in_view: bool,
    cost: Option<f64>,
    goalkeeper: Option<bool>,
    /// The referee put the ball back, when the robot program said so.
    ball_reset: Option<Instant>,
    /// The robot program has said where it is: the layer runs.
    fed: bool,
}

/// The team layer running on a driver; dropping it stops the layer (its guards, its
/// watches and its tick).
pub struct TeamRunner {
    _guards: Vec<Guard>,
    _watches: Vec<Watch>,
    task: tokio::task::JoinHandle<()>,
}

impl Drop for TeamRunner {
    fn drop(&mut self) {
        self.task.abort();
    }
}

/// The layer, shared by the tick and the reaction to teammates' claims.
struct Shared {
    layer: TeamLayer,
    cfg: TeamLayerConfig,
    /// Ticks so far (`local.var.team.tick`).
    ticks: i64,
    /// Which balls the layer has published and not yet withdrawn.
    balls_out: BallsOut,
}

/// Whether the layer's last word on each ball key was a ball (so losing it is said as
/// `[]`; a key the layer never wrote is left to whoever wrote it).
#[derive(Default)]
struct BallsOut {
    team: bool,
    own: bool,
}

/// Starts robot `handle`'s team layer: guards on the inputs, a watch that collects them,
/// a reaction to teammates' claims, and a tick every control period. Must run inside a
/// [`tokio::task::LocalSet`] (the driver's thread).
pub fn start(handle: &Handle, cfg: TeamLayerConfig) -> TeamRunner {
    let id = handle.robot_id();
    let core = Rc::new(RefCell::new(TeamCore::new(id, cfg)));
    // The robot program's cycle drives the layer: its odometry (or pose) closes a cycle's
    // inputs, and the layer ticks on it at once, so what it publishes holds that cycle.
    let cycle = Rc::new(tokio::sync::Notify::new());
    // Each client's SETV passes its key's guard exactly once, identical values included
    // (a robot walking steadily writes the same odometry every period): the guard both
    // refuses a bad value and takes a good one, stamped on the driver's clock.
    let clock = handle.clock();
    let guards = contract::INPUT_KEYS
        .iter()
        .map(|&key| {
            let core = Rc::clone(&core);
            let cycle = Rc::clone(&cycle);
            handle
                .guard(key, move |value| {
                    match core.borrow_mut().input(key, value, clock.now()) {
                        Err(e) => Err(Rejected {
                            code: ErrCode::BadValue,
                            text: e.to_string(),
                        }),
                        Ok(closes_cycle) => {
                            if closes_cycle {
                                cycle.notify_one();
                            }
                            Ok(())
                        }
                    }
                })
                .expect("the contract's keys are valid")
        })
        .collect();
    let claims = Rc::clone(&core);
    let react = handle
        .watch("+.var.machine.heuristic", move |h, notice| {
            let Notice::Changed { key, .. } = notice else {
                return;
            };
            if key.scope() == comms::Scope::Robot(id) {
                return;
            }
            // A teammate's claim as it arrives, not at the next tick.
            let mut core = claims.borrow_mut();
            h.with_replica(|replica, now| core.react(replica, now));
        })
        .expect("a valid pattern");
    let ticker = handle.clone();
    let period = core.borrow().period();
    let task = tokio::task::spawn_local(async move {
        let mut every = tokio::time::interval(period);
        every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        // A cycle closing sooner than half a period after the last tick waits for the
        // timer: a program writing odometry faster than the control period does not make
        // the layer tick (and send) faster.
        let mut last = tokio::time::Instant::now() - period;
        loop {
            tokio::select! {
                _ = every.tick() => {}
                () = cycle.notified() => {
                    if last.elapsed() < period / 2 {
                        continue;
                    }
                    // While the program drives, the timer only stands in for a missed
                    // cycle: it must not tick just before the next cycle closes.
                    every.reset_at(tokio::time::Instant::now() + period * 3 / 2);
                }
            }
            last = tokio::time::Instant::now();
            let mut core = core.borrow_mut();
            ticker.with_replica(|replica, now| core.tick(replica, now));
        }
    });
    TeamRunner {
        _guards: guards,
        _watches: vec![react],
        task,
    }
}

/// The team layer and what the robot program wrote, without a driver around them: what
/// [`start`] runs on the daemon's thread, and what a driver of its own (the C node's
/// engine) runs on its replica. The driver hands it every write of an input key
/// ([`TeamCore::input`]), ticks it every control period and when an input closes a cycle
/// ([`TeamCore::tick`]), and tells it when a teammate's claim changed
/// ([`TeamCore::react`]). Until a pose or odometry came, it writes and sends nothing.
pub struct TeamCore {
    inputs: Inputs,
    shared: Shared,
}

impl TeamCore {
    /// Robot `id`'s layer, dormant until fed.
    pub fn new(id: u8, cfg: TeamLayerConfig) -> TeamCore {
        let layer = TeamLayer::new(
            id,
            false,
            cfg.params,
            Pose::default(),
            &cfg.calibration,
            &cfg.team.world_model,
            cfg.team_size.max(usize::from(id)),
        );
        TeamCore {
            inputs: Inputs::default(),
            shared: Shared {
                layer,
                cfg,
                ticks: 0,
                balls_out: BallsOut::default(),
            },
        }
    }

    /// The control period: the longest between two ticks.
    pub fn period(&self) -> Duration {
        Duration::from_secs_f64(self.shared.cfg.team.control_period_s.max(0.005))
    }

    /// Whether the robot program has said where it is (the layer runs).
    pub fn fed(&self) -> bool {
        self.inputs.fed
    }

    /// One write of `key` by the robot program at `now`: checked by the contract and, if
    /// it is an input, taken for the next tick. `Err`: refused, nothing taken (the write
    /// must not happen either). `Ok(true)`: it closes the program's cycle (a pose or
    /// odometry), so the layer should tick now (at most twice a period). Keys that are
    /// not inputs are `Ok(false)`.
    pub fn input(
        &mut self,
        key: &str,
        value: &Value,
        now: Instant,
    ) -> Result<bool, contract::ContractError> {
        match contract::check(key, value) {
            None => Ok(false),
            Some(Err(e)) => Err(e),
            Some(Ok(())) => {
                take(&mut self.inputs, key, value, now);
                if let Some(at) = self.inputs.ball_reset.take() {
                    // At once, not at the next tick: a teammate's message that arrives in
                    // between must already meet a forgotten ball.
                    self.shared.layer.forget_ball(team::seconds(at));
                    tracing::info!("team layer: ball reset");
                }
                Ok(key == contract::ODOMETRY_KEY || key == contract::POSE_KEY)
            }
        }
    }

    /// One control tick on what came since the previous one; nothing while dormant.
    pub fn tick(&mut self, replica: &mut Replica, now: Instant) {
        if self.inputs.fed {
            tick(replica, now, &mut self.shared, &mut self.inputs);
        }
    }

    /// A teammate's claim changed: decide again at once; nothing while dormant.
    pub fn react(&mut self, replica: &mut Replica, now: Instant) {
        if !self.inputs.fed {
            return;
        }
        let s = &mut self.shared;
        let waiting = replica.is_pending(&team::world_local_key());
        let writes = s.layer.redecide(replica.blackboard(), now, waiting);
        apply(replica, now, writes, true);
        publish(replica, now, &s.layer, &mut s.balls_out);
    }
}

/// One write of the robot program, as the contract reads it (its guard refused it if it
/// does not parse).
fn take(inputs: &mut Inputs, key: &str, value: &Value, stamp: Instant) {
    match key {
        contract::POSE_KEY => {
            if let Ok(p) = contract::parse_pose(value) {
                inputs.pose = Some((p, stamp));
                inputs.fed = true;
            }
        }
        contract::ODOMETRY_KEY => {
            if let Ok(o) = contract::parse_odometry(value) {
                inputs.odometry.push(o);
                inputs.fed = true;
            }
        }
        contract::LANDMARKS_KEY => {
            if let Ok(l) = contract::parse_landmarks(value) {
                inputs.landmarks.extend(l);
            }
        }
        contract::BALL_KEY => {
            if let Ok(b) = contract::parse_ball(value) {
                inputs.balls.push((b, stamp));
            }
        }
        contract::KICK_KEY => {
            if let Ok(k) = contract::parse_kick(value) {
                inputs.kicks.push((k, stamp));
            }
        }
        contract::GOAL_IN_VIEW_KEY => {
            inputs.goal_in_view = contract::parse_bool(contract::GOAL_IN_VIEW_KEY, value)
                .unwrap_or(inputs.goal_in_view);
        }
        contract::COST_KEY => inputs.cost = contract::parse_cost(value).ok(),
        contract::GOALKEEPER_KEY => {
            inputs.goalkeeper = contract::parse_bool(contract::GOALKEEPER_KEY, value).ok();
        }
        contract::BALL_RESET_KEY => {
            if matches!(
                contract::parse_bool(contract::BALL_RESET_KEY, value),
                Ok(true)
            ) {
                inputs.ball_reset = Some(stamp);
                // Sightings from before the restart are of a ball that is gone.
                inputs.balls.clear();
            }
        }
        _ => {}
    }
}

/// The penalised player numbers `local.var.gc.penalized` holds (floats; anything else,
/// or a number out of 1–255, is nobody).
fn penalized(board: &comms::Blackboard) -> Vec<u8> {
    let key = Key::parse(PENALIZED_KEY).expect("a valid key");
    match board.get(&key).map(|e| &e.value) {
        Some(Value::Floats(v)) => v
            .iter()
            .filter(|x| x.is_finite() && **x >= 1.0 && **x <= 255.0)
            .map(|&x| x as u8)
            .collect(),
        _ => Vec::new(),
    }
}

/// Where the GameController listener writes the game's state.
pub const GC_STATE_KEY: &str = "local.var.gc.state";

/// Where the GameController listener writes this team's penalised player numbers.
pub const PENALIZED_KEY: &str = "local.var.gc.penalized";

/// Seconds from `earlier` to `now` on the driver's clock.
fn since(now: Instant, earlier: Instant) -> f64 {
    now.saturating_duration_since(earlier).as_secs_f64()
}

/// One control tick of the layer on what the robot program wrote since the previous one.
fn tick(replica: &mut Replica, now: Instant, s: &mut Shared, inputs: &mut Inputs) {
    let Shared {
        layer,
        cfg,
        ticks,
        balls_out,
    } = s;
    if let Some(gk) = inputs.goalkeeper.take() {
        layer.set_goalkeeper(gk);
    }
    if let Some(at) = inputs.ball_reset.take() {
        layer.forget_ball(team::seconds(at));
        tracing::info!("team layer: ball reset (at the tick)");
    }
    // The GameController listener's word on who is off the field (none without one).
    layer.set_penalties(&penalized(replica.blackboard()));
    // Out of play (the GC's state is not Playing) the layer tells the team nothing.
    // Set starts the kick-off hold (see `TeamLayer::set_kick_off_next`).
    let state = Key::parse(GC_STATE_KEY).expect("a valid key");
    let state = match replica.blackboard().get(&state).map(|e| &e.value) {
        Some(Value::String(s)) => Some(s.as_str()),
        _ => None,
    };
    layer.set_in_play(state.is_none_or(|s| s == "playing"));
    layer.set_kick_off_next(state == Some("set"));
    let balls: Vec<_> = inputs
        .balls
        .drain(..)
        .map(|(b, stamp)| {
            (
                team::frames::ball_sighting_from_rep103(b.local, b.cov),
                b.age_s + since(now, stamp),
            )
        })
        .collect();
    let odometry = std::mem::take(&mut inputs.odometry);
    let landmarks = std::mem::take(&mut inputs.landmarks);
    let senses = Senses {
        odometry: &odometry,
        landmarks: &landmarks,
        pose: inputs.pose.take().map(|(p, _)| (p.pose, p.cov)),
        ball: &balls,
        goal_in_view: inputs.goal_in_view,
        opponents: &[],
        cost: inputs.cost,
    };
    let claim_key = arbitration::heuristic_key();
    let lwm = layer.sense(
        &cfg.team,
        now,
        &senses,
        replica.blackboard(),
        replica.is_pending(&claim_key),
    );
    let (_, posted) = layer.decide(replica.blackboard(), now);
    let now_s = team::seconds(now);
    let kicked = !inputs.kicks.is_empty();
    for (k, stamp) in inputs.kicks.drain(..) {
        layer.report_kick(
            &cfg.team,
            now_s - since(now, stamp),
            k.direction_rad,
            k.speed_mps,
            k.contact_prob,
        );
    }
    let (writes, priority) = layer.finish(
        &cfg.team,
        now,
        lwm,
        posted,
        0,
        kicked,
        replica.is_pending(&team::world_local_key()),
        replica.is_pending(&claim_key),
        replica.budget_headroom(),
    );
    apply(replica, now, writes, priority);
    publish(replica, now, layer, balls_out);
    // Last, so a program that sees the tick change finds this tick's outputs in place.
    *ticks += 1;
    if let Err(e) = replica.set(now, contract::TICK_KEY, Value::Int(*ticks)) {
        tracing::warn!(error = %e, "team layer: the tick count was refused");
    }
}

/// The layer's messages to the team, through the replica.
fn apply(replica: &mut Replica, now: Instant, writes: Vec<(Key, Value)>, priority: bool) {
    for (key, value) in writes {
        let written = if priority {
            replica.set_priority(now, &key, value)
        } else {
            replica.set_key(now, &key, value)
        };
        if let Err(e) = written {
            // The layer writes its own keys of valid shape: a refusal is a bug worth a log.
            tracing::warn!(%key, error = %e, "team layer: a write was refused");
        }
    }
}

/// The layer's decisions on `local.var.team.*` for the robot program.
fn publish(replica: &mut Replica, now: Instant, layer: &TeamLayer, balls_out: &mut BallsOut) {
    let now_s = team::seconds(now);
    let mut out: Vec<(&str, Value)> = vec![
        (
            contract::GOER_KEY,
            Value::Int(layer.decision.goer.map_or(0, i64::from)),
        ),
        (contract::GOING_KEY, Value::Bool(layer.going())),
        (contract::COST_OUT_KEY, Value::Float(layer.h)),
        (
            contract::POSE_OUT_KEY,
            contract::pose_value(layer.pose_estimate()),
        ),
    ];
    // No ball is said as `[]`, not by leaving the key alone: after a kick-off's reset
    // the last published ball is where the ball was before the goal, and a robot program
    // reading it would walk there.
    if let Some(b) = layer.team_ball_held {
        let age_s = layer
            .gwm
            .teammates(now_s)
            .iter()
            .filter_map(|t| t.lwm.ball.map(|b| now_s - b.t_s))
            .chain(layer.ball_seen_at_s.map(|t| now_s - t))
            .fold(f64::INFINITY, f64::min);
        let age_s = if age_s.is_finite() {
            age_s
        } else {
            now_s - b.estimate.t_s
        };
        out.push((
            contract::TEAM_BALL_KEY,
            contract::ball_value(&b.estimate, Some(b.gbc), age_s),
        ));
    } else if balls_out.team {
        out.push((contract::TEAM_BALL_KEY, contract::no_ball_value()));
    }
    balls_out.team = layer.team_ball_held.is_some();
    let own = layer.own_ball(now_s);
    if let Some(b) = own {
        let age_s = layer.ball_seen_at_s.map_or(0.0, |t| now_s - t);
        out.push((
            contract::OWN_BALL_KEY,
            contract::ball_value(&b, None, age_s),
        ));
    } else if balls_out.own {
        out.push((contract::OWN_BALL_KEY, contract::no_ball_value()));
    }
    balls_out.own = own.is_some();
    let mates: Vec<f64> = layer
        .gwm
        .teammates(now_s)
        .iter()
        .filter(|t| t.id != layer.id)
        .flat_map(|t| {
            let p = team::frames::from_fusion_pose(&t.pose);
            [f64::from(t.id), p.at.x, p.at.y, p.theta_rad, t.silent_for_s]
        })
        .collect();
    out.push((contract::MATES_KEY, Value::Floats(mates)));
    if let Some(h) = replica.budget_headroom() {
        out.push((contract::BUDGET_KEY, Value::Int(h)));
    }
    for (key, value) in out {
        if let Err(e) = replica.set(now, key, value) {
            tracing::warn!(key, error = %e, "team layer: an output was refused");
        }
    }
}
