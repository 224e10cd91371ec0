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
}

/// Starts robot `handle`'s team layer: guards on the inputs, a watch that collects them,
/// a reaction to teammates' claims, and a tick every control period. Must run inside a
/// [`tokio::task::LocalSet`] (the driver's thread).
pub fn start(handle: &Handle, cfg: TeamLayerConfig) -> TeamRunner {
    let id = handle.robot_id();
    let layer = TeamLayer::new(
        id,
        false,
        cfg.params,
        Pose::default(),
        &cfg.calibration,
        &cfg.team.world_model,
        cfg.team_size.max(usize::from(id)),
    );
    let inputs = Rc::new(RefCell::new(Inputs::default()));
    let shared = Rc::new(RefCell::new(Shared { layer, cfg }));
    // Each client's SETV passes its key's guard exactly once, identical values included
    // (a robot walking steadily writes the same odometry every period): the guard both
    // refuses a bad value and takes a good one, stamped on the driver's clock.
    let clock = handle.clock();
    let guards = contract::INPUT_KEYS
        .iter()
        .map(|&key| {
            let inputs = Rc::clone(&inputs);
            handle
                .guard(key, move |value| match contract::check(key, value) {
                    Some(Err(e)) => Err(Rejected {
                        code: ErrCode::BadValue,
                        text: e.to_string(),
                    }),
                    _ => {
                        take(&mut inputs.borrow_mut(), key, value, clock.now());
                        Ok(())
                    }
                })
                .expect("the contract's keys are valid")
        })
        .collect();
    let claims = Rc::clone(&shared);
    let fed = Rc::clone(&inputs);
    let react = handle
        .watch("+.var.machine.heuristic", move |h, notice| {
            let Notice::Changed { key, .. } = notice else {
                return;
            };
            if key.scope() == comms::Scope::Robot(id) {
                return;
            }
            // A teammate's claim as it arrives, not at the next tick.
            if !fed.borrow().fed {
                return;
            }
            let mut s = claims.borrow_mut();
            h.with_replica(|replica, now| {
                let waiting = replica.is_pending(&team::world_local_key());
                let writes = s.layer.redecide(replica.blackboard(), now, waiting);
                apply(replica, now, writes, true);
                publish(replica, now, &s.layer, &s.cfg);
            });
        })
        .expect("a valid pattern");
    let ticker = handle.clone();
    let period = Duration::from_secs_f64(cfg.team.control_period_s.max(0.005));
    let task = tokio::task::spawn_local(async move {
        let mut every = tokio::time::interval(period);
        every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            every.tick().await;
            let mut inputs = inputs.borrow_mut();
            if !inputs.fed {
                continue;
            }
            let mut s = shared.borrow_mut();
            let s = &mut *s;
            ticker.with_replica(|replica, now| tick(replica, now, s, &mut inputs));
        }
    });
    TeamRunner {
        _guards: guards,
        _watches: vec![react],
        task,
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
    let Shared { layer, cfg } = s;
    if let Some(gk) = inputs.goalkeeper.take() {
        layer.set_goalkeeper(gk);
    }
    // The GameController listener's word on who is off the field (none without one).
    layer.set_penalties(&penalized(replica.blackboard()));
    // Out of play (the GC's state is not Playing) the layer tells the team nothing.
    let state = Key::parse(GC_STATE_KEY).expect("a valid key");
    layer.set_in_play(match replica.blackboard().get(&state).map(|e| &e.value) {
        Some(Value::String(s)) => s == "playing",
        _ => true,
    });
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
    publish(replica, now, layer, cfg);
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
fn publish(replica: &mut Replica, now: Instant, layer: &TeamLayer, cfg: &TeamLayerConfig) {
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
    }
    if let Some(b) = layer.own_ball(now_s) {
        let age_s = layer.ball_seen_at_s.map_or(0.0, |t| now_s - t);
        out.push((
            contract::OWN_BALL_KEY,
            contract::ball_value(&b, None, age_s),
        ));
    }
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
    let _ = cfg;
    for (key, value) in out {
        if let Err(e) = replica.set(now, key, value) {
            tracing::warn!(key, error = %e, "team layer: an output was refused");
        }
    }
}
