//! The team layer on a real robot: [`team::TeamLayer`] fed from the `local.var.robot.*`
//! keys a robot program writes (through the relay, the C node or a handle), ticked on the
//! driver's thread, its decisions written to `local.var.team.*` and its messages to the
//! team through the replica, with priority where the layer asks for it. The contract is
//! `docs/team-layer.md` ([`team::contract`]).
//!
//! A malformed input is refused at the relay's `SETV` (a guard per input key), so the
//! layer only ever sees values it can take; its outputs (`local.var.team.*`) are its own
//! while it runs: a client's write of one is refused (`ERR 423`, [`Handle::reserve`]). The layer stays dormant, writing and sending
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
    /// The acoustic fallback, when the robot sounds its claims while the radio is silent
    /// ([`team::acoustic`]; `tone_s` must be the audio's tone duration). Only its slot
    /// and decision settings are read (the room's are the simulator's).
    pub acoustic: Option<team::acoustic::AcousticConfig>,
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
            acoustic: None,
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
    /// The robot program heard the referee's whistle, when.
    whistle: Option<Instant>,
    /// The program has written a whistle at least once; the log said once that it had
    /// not when the GC first said Playing.
    whistle_ever: bool,
    whistle_unheard_logged: bool,
    /// The robot program has said where it is: the layer runs.
    fed: bool,
}

/// The team layer running on a driver; dropping it stops the layer (its guards, its
/// watches and its tick).
pub struct TeamRunner {
    _guards: Vec<Guard>,
    _watches: Vec<Watch>,
    task: tokio::task::JoinHandle<()>,
    fallback: Option<tokio::task::JoinHandle<()>>,
}

impl Drop for TeamRunner {
    fn drop(&mut self) {
        self.task.abort();
        if let Some(f) = &self.fallback {
            f.abort();
        }
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
    start_with_fallback(handle, cfg, None)
}

/// As [`start`], with the acoustic fallback on the daemon's audio (`cfg.acoustic` set,
/// `audio` from [`crate::audio::Audio::fallback`]): heard messages go to the layer, and a
/// task wakes at the start of each of this robot's slots (on the team clock) to sound
/// its claim while the radio is stale.
pub fn start_with_fallback(
    handle: &Handle,
    cfg: TeamLayerConfig,
    audio: Option<crate::audio::FallbackAudio>,
) -> TeamRunner {
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
        .chain(std::iter::once(
            handle
                .reserve(crate::guard::TEAM_KEYS, crate::guard::TEAM_OWNER)
                .expect("a valid pattern"),
        ))
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
    let fallback = audio.map(|audio| {
        let core = Rc::clone(&core);
        tokio::task::spawn_local(run_fallback(core, handle.clock(), audio))
    });
    let ticker = handle.clone();
    let period = core.borrow().period();
    let task = tokio::task::spawn_local(async move {
        let mut every = tokio::time::interval(period);
        every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        let started = tokio::time::Instant::now();
        let mut pacer = Pacer::new(period);
        loop {
            tokio::select! {
                _ = every.tick() => pacer.timer(started.elapsed()),
                () = cycle.notified() => {
                    if !pacer.cycle(started.elapsed()) {
                        continue;
                    }
                    // While the program drives, the timer only stands in for a missed
                    // cycle: it must not tick just before the next cycle closes.
                    every.reset_at(tokio::time::Instant::now() + period * 3 / 2);
                }
            }
            let mut core = core.borrow_mut();
            ticker.with_replica(|replica, now| core.tick(replica, now));
        }
    });
    TeamRunner {
        _guards: guards,
        _watches: vec![react],
        task,
        fallback,
    }
}

/// The acoustic fallback on a daemon: hands heard messages to the layer, and sounds the
/// layer's claim at the start of each of this robot's slots.
async fn run_fallback(
    core: Rc<RefCell<TeamCore>>,
    clock: crate::state::Clock,
    audio: crate::audio::FallbackAudio,
) {
    let crate::audio::FallbackAudio { mut heard, speaker } = audio;
    let mut listening = true;
    // The slot last sounded (or passed): never the same slot twice.
    let mut after = clock.now();
    loop {
        let now = clock.now();
        let next = core
            .borrow()
            .next_sound_slot(after.max(now))
            .unwrap_or(now + Duration::from_secs(1));
        let wait = next.saturating_duration_since(now);
        tokio::select! {
            h = heard.recv(), if listening => match h {
                Some((message, start)) => core.borrow_mut().hear_sound(&message, start),
                None => listening = false,
            },
            () = tokio::time::sleep(wait) => {
                let now = clock.now();
                // The team clock may have moved while asleep (a new estimate, a new
                // reference): ask again which slot start is due, and sound only at one.
                let due = core
                    .borrow()
                    .next_sound_slot(now.saturating_sub(SLOT_LATE).max(after));
                let Some(due) = due.filter(|&d| d <= now + SLOT_EARLY) else {
                    continue;
                };
                after = due + SLOT_EARLY;
                let claim = core.borrow_mut().sound_claim(now);
                if let Some(message) = claim {
                    if speaker.sound_now(message) {
                        tracing::debug!(%message, "acoustic fallback: claim sounded");
                    }
                }
            }
        }
    }
}

/// A slot's start is taken as come this much before it (a timer's rounding).
const SLOT_EARLY: Duration = Duration::from_millis(2);
/// A claim later than this into its slot is not sounded: heard that late it could be
/// taken for the next robot's (the slot is attributed within half a slot, a guard of
/// 300 ms; the speaking command's own latency comes on top).
const SLOT_LATE: Duration = Duration::from_millis(50);

/// When the layer ticks: on each cycle the robot program closes, and on a timer standing
/// in for cycles that do not come. A cycle closing sooner than half a period after the
/// last cycle's tick waits for the timer, so a program writing odometry faster than the
/// control period does not make the layer tick (and send) faster. A cycle closing soon
/// after a *timer* tick ticks at once: that tick stood in for a late cycle, and making the
/// cycle wait for the next one would lock the timer just ahead of every later cycle (each
/// tick then a cycle old, the program's wait for it always in vain), as a late cycle on a
/// loaded machine did.
///
/// The daemon's loop and the C node's engine both pace their layer with it; times are
/// since any fixed start.
#[derive(Debug, Clone, Copy)]
pub struct Pacer {
    period: Duration,
    /// The last tick: when (time since the layer started), and whether the timer made it.
    last: Option<(Duration, bool)>,
}

impl Pacer {
    /// A pacer for a layer ticking every `period`.
    pub fn new(period: Duration) -> Pacer {
        Pacer { period, last: None }
    }

    /// A cycle closed at `now`: whether the layer ticks on it.
    pub fn cycle(&mut self, now: Duration) -> bool {
        let ticks = match self.last {
            Some((at, false)) => now.saturating_sub(at) >= self.period / 2,
            Some((_, true)) | None => true,
        };
        if ticks {
            self.last = Some((now, false));
        }
        ticks
    }

    /// The timer ticked the layer at `now`.
    pub fn timer(&mut self, now: Duration) {
        self.last = Some((now, true));
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
        let mut layer = TeamLayer::new(
            id,
            false,
            cfg.params,
            Pose::default(),
            &cfg.calibration,
            &cfg.team.world_model,
            cfg.team_size.max(usize::from(id)),
        );
        if let Some(ac) = cfg.acoustic.filter(|a| a.enabled) {
            layer.sound = Some(team::acoustic::SoundFallback::new(
                id,
                team::acoustic::SlotPlan::for_team(cfg.team_size, ac.slot_s()),
                &ac,
                cfg.team_size.max(usize::from(id)),
                cfg.params,
            ));
        }
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
        if self.shared.layer.sound.is_some() {
            // The fallback's slots run on the team clock the replica's estimates give.
            self.shared.layer.update_team_clock(now, replica.peers());
        }
        // Whether the radio works (with the GC's packets, `tick` below).
        self.shared.layer.heard_teammates(now, replica.peers());
        if self.inputs.fed {
            tick(replica, now, &mut self.shared, &mut self.inputs);
        }
    }

    /// When this robot's next acoustic slot starts, at or after `now` (the driver's
    /// clock); `None` without the fallback.
    pub fn next_sound_slot(&self, now: Instant) -> Option<Instant> {
        let at = self.shared.layer.next_sound_slot(team::seconds(now))?;
        Some(Instant::from_micros((at.max(0.0) * 1e6).round() as u64))
    }

    /// The claim to sound in this robot's slot, starting `now`: some while the radio is
    /// stale, none otherwise (and none while dormant).
    pub fn sound_claim(&mut self, now: Instant) -> Option<audio::Message> {
        if !self.inputs.fed {
            return None;
        }
        self.shared.layer.sound_claim(team::seconds(now))
    }

    /// A message this robot's microphone decoder heard, begun at `start`.
    pub fn hear_sound(&mut self, message: &audio::Message, start: Instant) {
        self.shared.layer.hear_sound(message, team::seconds(start));
    }

    /// A teammate's claim changed: decide again at once; nothing while dormant.
    pub fn react(&mut self, replica: &mut Replica, now: Instant) {
        if !self.inputs.fed {
            return;
        }
        let s = &mut self.shared;
        let waiting = replica.is_pending(&team::world_local_key());
        let writes = s.layer.redecide(replica.blackboard(), now, waiting);
        // Its latest tick's world model, if it rides along, is stamped at that tick, so
        // teammates place it where it holds (not at this later write).
        let built = s.layer.world_model_built();
        let world = team::world_local_key();
        let (ride, claims): (Vec<_>, Vec<_>) = writes.into_iter().partition(|(k, _)| *k == world);
        apply(replica, now, claims, true);
        for (key, value) in ride {
            if let Err(e) = replica.set_key_built(now, &key, value, built) {
                tracing::warn!(%key, error = %e, "team layer: a write was refused");
            }
        }
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
        contract::WHISTLE_KEY => {
            if matches!(contract::parse_bool(contract::WHISTLE_KEY, value), Ok(true)) {
                inputs.whistle = Some(stamp);
                inputs.whistle_ever = true;
            }
        }
        _ => {}
    }
}

/// The GameController listener's count of accepted packets, rewritten (and so stamped)
/// at each one.
pub const GC_ACCEPTED_KEY: &str = "local.var.huddle.stats.gc.accepted";

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

/// Where the GameController listener writes the set play (`penalty_kick`: the ball on a
/// penalty mark, not the centre spot).
pub const GC_SET_PLAY_KEY: &str = "local.var.gc.set_play";

/// Where the GameController listener writes this team's penalised player numbers.
pub const PENALIZED_KEY: &str = "local.var.gc.penalized";

/// Where the GameController listener writes this team's score and the other team's.
pub const GC_SCORE_KEY: &str = "local.var.gc.score";
/// See [`GC_SCORE_KEY`].
pub const GC_OPPONENT_SCORE_KEY: &str = "local.var.gc.opponent_score";

/// A score the GameController listener wrote under `key` (an int of 0-255), if any.
fn gc_score(board: &comms::Blackboard, key: &str) -> Option<u8> {
    let key = Key::parse(key).expect("a valid key");
    match board.get(&key).map(|e| &e.value) {
        Some(Value::Int(n)) => u8::try_from(*n).ok(),
        _ => None,
    }
}

/// Seconds from `earlier` to `now` on the driver's clock.
fn since(now: Instant, earlier: Instant) -> f64 {
    now.saturating_duration_since(earlier).as_secs_f64()
}

/// A text the GameController listener wrote under `key`, if any.
fn gc_text<'a>(board: &'a comms::Blackboard, key: &str) -> Option<&'a str> {
    let key = Key::parse(key).expect("a valid key");
    match board.get(&key).map(|e| &e.value) {
        Some(Value::String(s)) => Some(s.as_str()),
        _ => None,
    }
}

/// The whistle the layer acts on, one key per meaning, each `[t]` or `[]` and written
/// when it changes: the play whistle (`key` [`contract::PLAY_WHISTLE_KEY`]) for the
/// GameController listener, which paces the budget's clock from it at its next packet
/// (`driver::budget_figures`: GameController3 shows Set for 15 s after the whistle, and
/// each of its packets would otherwise set the clock back); both it and the goal's
/// ([`contract::GOAL_WHISTLE_KEY`]) for the robot program, whose body follows the layer's
/// reading of the whistle (it knows what a whistle means with the GC silent; a program's
/// own reading would not, and its body would stand while the layer plays).
fn publish_whistle(replica: &mut Replica, now: Instant, key: &'static str, at: Option<f64>) {
    let parsed = Key::parse(key).expect("a valid key");
    // Compared in place: the tick runs at 25 Hz and the value rarely changes.
    let unchanged = match replica.blackboard().get(&parsed).map(|e| &e.value) {
        Some(Value::Floats(shown)) => shown.as_slice() == at.as_slice(),
        None => at.is_none(),
        Some(_) => false,
    };
    if unchanged {
        return;
    }
    let value: Vec<f64> = at.into_iter().collect();
    if let Err(e) = replica.set(now, key, Value::Floats(value)) {
        tracing::warn!(key, error = %e, "team layer: cannot publish the whistle");
    }
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
    // Its last accepted packet: the radio's heartbeat for the acoustic fallback.
    let accepted = Key::parse(GC_ACCEPTED_KEY).expect("a valid key");
    if let Some(e) = replica.blackboard().get(&accepted) {
        layer.heard_gamecontroller(team::seconds(e.stamp));
    }
    // A goal the GameController announces (a score rose in its newest packet: the
    // listener keeps only the newest by `packetNumber`) puts the ball back, with no
    // robot program's ball reset (`TeamLayer::set_scores`).
    let scores = (
        gc_score(replica.blackboard(), GC_SCORE_KEY),
        gc_score(replica.blackboard(), GC_OPPONENT_SCORE_KEY),
    );
    if let (Some(own), Some(other)) = scores {
        if layer.set_scores(own, other, team::seconds(now)) {
            // Sightings from before the goal are of a ball that is gone.
            inputs.balls.clear();
            tracing::info!(own, other, "team layer: goal heard from the GameController");
        }
    }
    // Out of play (the GC's state is not Playing) the layer tells the team nothing but,
    // in Set, the kick-off taker's claim. Set starts the kick-off hold and puts the ball
    // on the centre spot (both in `TeamLayer::set_kick_off_next`'s doc); a penalty
    // kick's Set has the ball elsewhere.
    let board = replica.blackboard();
    let state = gc_text(board, GC_STATE_KEY);
    let gc_playing = state == Some("playing");
    // Ready: with the radio dead, the next whistle is the one that starts play.
    layer.set_gc_ready(state == Some("ready"));
    layer.set_in_play(state.is_none_or(|s| s == "playing"));
    let kick_off = state == Some("set") && gc_text(board, GC_SET_PLAY_KEY) != Some("penalty_kick");
    if layer.set_kick_off_next(kick_off) {
        // Every claim changes at the whistle: the team's priority frames get their room.
        replica.restart_priority_room(now);
    }
    // The referee's whistle, heard by the robot program: GameController3 shows play and
    // goals 15 s late (`TeamLayer::heard_whistle`).
    if let Some(at) = inputs.whistle.take() {
        match layer.heard_whistle(team::seconds(at)) {
            Some(team::Whistle::PlayStarted(_)) => {
                tracing::info!("team layer: whistle heard, play started");
            }
            Some(team::Whistle::Goal(_)) => {
                // Sightings from before the goal are of a ball that is gone.
                inputs.balls.clear();
                tracing::info!("team layer: whistle heard in play, a goal");
            }
            None => tracing::debug!("team layer: whistle heard, nothing to start"),
        }
    } else if gc_playing && !inputs.whistle_ever && !inputs.whistle_unheard_logged {
        inputs.whistle_unheard_logged = true;
        tracing::info!(
            "team layer: the robot program writes no whistle ({}): under GameController3 \
             the layer stays out of play for the GC's delay (15 s) after each kick-off's \
             whistle and learns each goal that late",
            contract::WHISTLE_KEY
        );
    }
    // Published before the tick's sense, which drops a whistle older than the trust
    // (`TeamLayer::whistle_timeout`): that shows a tick (40 ms) later; the GC's word and
    // the program's whistle, taken above, show at this tick.
    publish_whistle(
        replica,
        now,
        contract::PLAY_WHISTLE_KEY,
        layer.play_whistle_at(),
    );
    publish_whistle(
        replica,
        now,
        contract::GOAL_WHISTLE_KEY,
        layer.goal_whistle_at(),
    );
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
    // Kicks first: the program writes a kick after the tick it decided on, so each one
    // is older than this cycle's sightings. Taken after them (as before), the tick's
    // world model went out without the kick and the team ball held the ball before it
    // for one more tick (40 ms: 16 cm at a kick's 4 m/s), and the kick turned a track
    // that had already taken a later sighting. In process the kick is in the next tick's
    // world model; so it is here.
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
    let before = layer.decision.goer;
    let (_, posted) = layer.decide(replica.blackboard(), now);
    if layer.decision.goer != before {
        // For tracing a disagreement: what the fallback held when the goer changed.
        tracing::debug!(
            goer = ?layer.decision.goer,
            going = layer.going(),
            fallback = ?layer.sound,
            "team layer: the goer changed"
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
    // The tick's own message in full (`sense` made it; a reaction between ticks makes
    // none, so this is the tick's and not `publish`'s).
    if let Some(own) = layer.gwm.latest(layer.id) {
        if let Ok(bytes) = own.to_bytes() {
            let world = Value::Bytes(bytes.to_vec());
            if let Err(e) = replica.set(now, contract::WORLD_OUT_KEY, world) {
                tracing::warn!(error = %e, "team layer: its own message was refused");
            }
        }
    }
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

#[cfg(test)]
mod pacer_tests {
    use super::Pacer;
    use std::time::Duration;

    const PERIOD: Duration = Duration::from_millis(40);

    /// Drives a pacer as the daemon's loop does: a program closing a cycle every period
    /// at `cycles` (ms), the timer a period after its last tick and reset to 1.5 periods
    /// after each cycle tick. Returns, per cycle, whether it ticked at once.
    fn play(cycles: &[u64]) -> Vec<bool> {
        let mut pacer = Pacer::new(PERIOD);
        let mut timer = Duration::ZERO;
        let mut ticked = Vec::new();
        for &c in cycles {
            let c = Duration::from_millis(c);
            while timer <= c {
                pacer.timer(timer);
                timer += PERIOD;
            }
            let now = pacer.cycle(c);
            if now {
                timer = c + PERIOD * 3 / 2;
            }
            ticked.push(now);
        }
        ticked
    }

    #[test]
    fn a_late_cycle_does_not_lock_the_timer_ahead_of_the_cycles_that_follow() {
        // Cycles every 40 ms from 10 ms. The one due at 130 ms closes at 165 ms (the
        // machine was busy), so the timer stood in for it at 150 ms and goes on every
        // 40 ms from there; the next closes at 169 ms, and every later one 1 ms earlier
        // than its slot (the scheduling jitter of a loaded machine), 19 ms after a timer
        // tick. The one at 169 ms waits (4 ms after the late one); the later ones must
        // tick as they close, not wait for the timer a cycle later.
        let mut cycles: Vec<u64> = (0..30).map(|k| 10 + 40 * k).collect();
        cycles[3] = 165;
        for c in &mut cycles[4..] {
            *c -= 1;
        }
        let ticked = play(&cycles);
        assert!(ticked[3], "the late cycle ticks: {ticked:?}");
        assert!(!ticked[4], "a cycle 4 ms after a tick waits: {ticked:?}");
        let prompt = ticked[5..].iter().filter(|&&t| t).count();
        assert_eq!(
            prompt,
            ticked.len() - 5,
            "every later cycle ticks at once: {ticked:?}"
        );
    }

    #[test]
    fn a_program_writing_faster_than_the_period_does_not_tick_faster() {
        // Odometry every 10 ms for a second: at most one cycle tick per half period.
        let cycles: Vec<u64> = (1..=100).map(|k| 10 * k).collect();
        let ticks = play(&cycles).iter().filter(|&&t| t).count();
        assert!(
            (24..=51).contains(&ticks),
            "{ticks} cycle ticks in a second at a 40 ms period"
        );
    }
}

#[cfg(test)]
mod core_tests {
    use super::{TeamCore, TeamLayerConfig};
    use comms::{Instant, Replica, ReplicaConfig, Value};
    use std::time::Duration;
    use team::contract;

    pub(super) fn floats(v: &[f64]) -> Value {
        Value::Floats(v.to_vec())
    }

    fn team_ball(replica: &Replica) -> Option<Value> {
        replica
            .get(contract::TEAM_BALL_KEY)
            .expect("a valid key")
            .map(|e| e.value.clone())
    }

    /// Robot 2's layer and replica, the robot standing at the field's origin facing +x.
    pub(super) fn robot_2_at_the_origin(now: Instant) -> (TeamCore, Replica) {
        let mut core = TeamCore::new(2, TeamLayerConfig::new(3, None));
        let config = ReplicaConfig::new(2, 0).with_known_paths(team::known_paths());
        let replica = Replica::new(config, 7, now).expect("a valid replica");
        let pose = floats(&[0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.001]);
        core.input(contract::POSE_KEY, &pose, now)
            .expect("a valid pose");
        (core, replica)
    }

    /// One program cycle of a robot standing still: a ball sighting, odometry, a tick.
    fn cycle(core: &mut TeamCore, replica: &mut Replica, now: Instant, ball: &[f64]) {
        core.input(contract::BALL_KEY, &floats(ball), now)
            .expect("a valid sighting");
        core.input(contract::ODOMETRY_KEY, &floats(&[0.0, 0.0, 0.0]), now)
            .expect("valid odometry");
        core.tick(replica, now);
    }

    #[test]
    fn a_teammate_s_claim_after_a_ball_reset_does_not_bring_the_old_ball_back() {
        // Robot 2 sees the ball 1.5 m ahead for half a second; then the referee puts it
        // back (the program writes the reset) and, before the layer's next tick, a
        // teammate's claim changes (as every claim does at a kick-off), so the layer
        // decides and publishes again. It must not say the ball before the goal (`huddle
        // sim --daemons`: one robot in ten matches played on it 40 ms after a goal, 4.9 m
        // off), but the kick-off spot, the centre of the field, where the rules put it.
        let mut now = Instant::from_micros(1_000_000);
        let (mut core, mut replica) = robot_2_at_the_origin(now);
        for _ in 0..12 {
            cycle(&mut core, &mut replica, now, &[1.5, 0.0, 0.01, 0.0, 0.01]);
            now += Duration::from_millis(40);
        }
        let held = team_ball(&replica);
        assert!(
            matches!(&held, Some(Value::Floats(f)) if !f.is_empty()),
            "the layer holds the ball it saw: {held:?}"
        );
        core.input(contract::BALL_RESET_KEY, &Value::Bool(true), now)
            .expect("a valid reset");
        now += Duration::from_millis(5);
        core.react(&mut replica, now);
        let spot = team_ball(&replica);
        assert!(
            matches!(&spot, Some(Value::Floats(f)) if f.len() >= 2 && f[0].abs() < 1e-6 && f[1].abs() < 1e-6),
            "after the reset the layer's team ball is the centre spot: {spot:?}"
        );
    }

    #[test]
    fn while_the_gamecontroller_and_the_team_are_silent_the_layer_tells_nothing() {
        // Robot 2 hears the GameController (its listener's accepted counter, rewritten at
        // each packet) every 0.5 s until 3 s, and no teammate: at 6.1 s the radio is dead
        // by the heartbeat, and the layer holds its claim (a league would count frames
        // nobody hears) until the GC is heard again.
        let key = comms::arbitration::heuristic_key();
        let accepted = |r: &mut Replica, now, n: i64| {
            r.set(now, super::GC_ACCEPTED_KEY, Value::Int(n))
                .expect("a local key");
        };
        let version = |r: &Replica| r.blackboard().get(&key).map(|e| e.version);
        let mut now = Instant::from_micros(1_000_000);
        let (mut core, mut replica) = robot_2_at_the_origin(now);
        let mut packets = 0;
        let mut told_at_6 = None;
        while now < Instant::from_micros(7_000_000) {
            if now.as_micros() <= 3_000_000 && now.as_micros().is_multiple_of(500_000) {
                packets += 1;
                accepted(&mut replica, now, packets);
            }
            cycle(&mut core, &mut replica, now, &[1.5, 0.0, 0.01, 0.0, 0.01]);
            if now.as_micros() == 6_200_000 {
                told_at_6 = version(&replica);
            }
            now += Duration::from_millis(40);
        }
        assert!(
            core.shared.layer.radio_dead(7.0),
            "neither the GC nor a teammate since 3 s"
        );
        assert!(
            told_at_6.is_some(),
            "the claim was told while the GC was heard"
        );
        assert_eq!(
            version(&replica),
            told_at_6,
            "nothing told from 6.2 s to 7 s (the radio dead)"
        );
        accepted(&mut replica, now, packets + 1);
        cycle(&mut core, &mut replica, now, &[1.5, 0.0, 0.01, 0.0, 0.01]);
        assert!(!core.shared.layer.radio_dead(team::seconds(now)));
        assert!(
            version(&replica) > told_at_6,
            "the claim is told again at the GC's next packet"
        );
    }

    #[test]
    fn a_goal_the_gamecontroller_announces_puts_the_ball_back_with_no_program_reset() {
        // Robot 2 sees the ball 1.5 m ahead while the GC's packets say 0:0; then a packet
        // says 1:0 (a goal). With no ball reset from the robot program, the layer's team
        // ball must be the kick-off spot (the centre) at the next tick, not the old ball.
        let mut now = Instant::from_micros(1_000_000);
        let (mut core, mut replica) = robot_2_at_the_origin(now);
        let score = |r: &mut Replica, now, own: i64| {
            r.set(now, super::GC_SCORE_KEY, Value::Int(own))
                .expect("a local key");
            r.set(now, super::GC_OPPONENT_SCORE_KEY, Value::Int(0))
                .expect("a local key");
        };
        score(&mut replica, now, 0);
        for _ in 0..12 {
            cycle(&mut core, &mut replica, now, &[1.5, 0.0, 0.01, 0.0, 0.01]);
            now += Duration::from_millis(40);
        }
        let held = team_ball(&replica);
        assert!(
            matches!(&held, Some(Value::Floats(f)) if f.len() >= 2 && f[0] > 1.0),
            "at 0:0 the layer holds the ball it saw: {held:?}"
        );
        score(&mut replica, now, 1);
        core.input(contract::ODOMETRY_KEY, &floats(&[0.0, 0.0, 0.0]), now)
            .expect("valid odometry");
        core.tick(&mut replica, now);
        let spot = team_ball(&replica);
        assert!(
            matches!(&spot, Some(Value::Floats(f)) if f.len() >= 2 && f[0].abs() < 1e-6 && f[1].abs() < 1e-6),
            "after the GC's 1:0 the layer's team ball is the centre spot: {spot:?}"
        );
    }

    #[test]
    fn every_tick_writes_the_robots_own_message_in_full_even_under_a_budget() {
        // Robot 2 of an SPL-budgeted team (a message every 3 s at best: the team hears
        // the compact form, rarely) sees the ball 1.5 m ahead every cycle. A log, or the
        // central reference of `huddle sim --daemons`, wants every tick's message in full:
        // `local.var.team.world` holds it, 75 bytes, one new sequence number per tick,
        // with that tick's sighting batch.
        let mut now = Instant::from_micros(1_000_000);
        let mut core = TeamCore::new(2, TeamLayerConfig::new(3, Some(Duration::from_secs(3))));
        let config = ReplicaConfig::new(2, 0).with_known_paths(team::known_paths());
        let mut replica = Replica::new(config, 7, now).expect("a valid replica");
        let pose = floats(&[0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.01, 0.0, 0.001]);
        core.input(contract::POSE_KEY, &pose, now)
            .expect("a valid pose");
        let mut seqs = Vec::new();
        for tick in 0..10 {
            cycle(&mut core, &mut replica, now, &[1.5, 0.0, 0.01, 0.0, 0.01]);
            let Some(Value::Bytes(bytes)) = replica
                .get(contract::WORLD_OUT_KEY)
                .expect("a valid key")
                .map(|e| e.value.clone())
            else {
                panic!("tick {tick}: the layer writes its own message");
            };
            assert_eq!(bytes.len(), 75, "tick {tick}: the full form");
            let lwm = fusion::LocalWorldModel::from_bytes(&bytes, 0.0)
                .expect("the layer's own message decodes");
            if tick > 0 {
                assert!(
                    lwm.observation.is_some(),
                    "tick {tick}: the tick's sighting is in its batch"
                );
            }
            seqs.push(lwm.seq);
            now += Duration::from_millis(40);
        }
        assert!(
            seqs.windows(2).all(|w| w[1] == w[0].wrapping_add(1)),
            "one message per tick, none skipped: {seqs:?}"
        );
    }

    #[test]
    fn a_kick_is_in_the_team_ball_of_the_tick_after_it() {
        // Robot 2 stands still with the ball 0.3 m ahead for half a second. After a tick
        // it kicks the ball straight ahead at 4 m/s (the program writes the kick once it
        // has played on that tick's outputs, as every program does); its next cycle sees
        // the ball 16 cm on. The tick on that cycle must publish a team ball that moves
        // with the kick, as the in-process robot's does. Before, the kick was taken after
        // the tick had built its world model: the team ball stood still for one more
        // tick and the kick turned a track that had already taken the later sighting
        // (`huddle sim --daemons`: every kick 40 ms late, 16 cm at a kick's speed).
        let mut now = Instant::from_micros(1_000_000);
        let (mut core, mut replica) = robot_2_at_the_origin(now);
        let sighting = |x: f64| [x, 0.0, 0.0004, 0.0, 0.0004];
        for _ in 0..12 {
            cycle(&mut core, &mut replica, now, &sighting(0.3));
            now += Duration::from_millis(40);
        }
        let kick_at = Instant::from_micros(now.as_micros() - 39_000);
        core.input(contract::KICK_KEY, &floats(&[0.0, 4.0, 1.0]), kick_at)
            .expect("a valid kick");
        cycle(&mut core, &mut replica, now, &sighting(0.3 + 4.0 * 0.039));
        let Some(Value::Floats(ball)) = team_ball(&replica) else {
            panic!("the layer publishes a team ball");
        };
        let ball = contract::parse_ball_output(contract::TEAM_BALL_KEY, &Value::Floats(ball))
            .expect("the layer's own output parses")
            .expect("a ball, not `[]`");
        assert!(
            ball.velocity.x > 3.0 && ball.velocity.y.abs() < 0.5,
            "the team ball moves off with the kick at the tick after it: {ball:?}"
        );
        assert!(
            (ball.at.x - 0.456).abs() < 0.05,
            "the team ball is where the kicked ball is: {ball:?}"
        );
    }
}

#[cfg(test)]
#[path = "team_gc_tests.rs"]
mod gc_tests;

#[cfg(test)]
#[path = "team_input_tests.rs"]
mod input_tests;
