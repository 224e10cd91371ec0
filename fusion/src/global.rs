//! The global world model (GWM): teammates from their LWMs and the team ball, fused from
//! every robot's published ball information (see the crate docs for why it is built this way).

use crate::ball::{initial_estimate, update, BallEstimate, BallModel, FieldObservation, Kick};
use crate::confidence::position_confidence;
use crate::kalman;
use crate::local::{Heard, LocalWorldModel};
use crate::pose::PoseEstimate;
use crate::wire::DecodeError;
use nalgebra::{Matrix2, Matrix4, SMatrix, Vector2, Vector4};
use std::cell::RefCell;
use std::collections::VecDeque;

mod checkpoints;
#[cfg(test)]
mod lazy_tests;
mod measured;
mod records;
mod search;
use checkpoints::{Base, Checkpoints};
use measured::Measured;
use records::Records;
use search::{partition_near_back, partition_near_front};

/// Settings of a [`GlobalModel`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GlobalConfig {
    /// The team ball's motion model (use the robots' own).
    pub ball: BallModel,
    /// Velocity variance of a track started from a bare observation (m²/s²).
    pub initial_velocity_var: f64,
    /// χ² (2 dof) gate of an observation against the team ball at the observation's time.
    pub gate_chi2: f64,
    /// Observations younger than this stay re-orderable, so late arrivals slot in by time.
    pub commit_lag_s: f64,
    /// A teammate not heard for this long is silent: it no longer counts as fresh, and when
    /// every teammate is silent the team ball is the robot's own.
    pub stale_after_s: f64,
    /// How fast a silent teammate's confidence falls (per second).
    pub confidence_decay_per_s: f64,
    /// A robot whose observations were rejected within this window, with none accepted
    /// since, dissents from the team ball.
    pub dissent_window_s: f64,
    /// With no accepted observation for this long, a single dissenter may restart the ball.
    pub support_timeout_s: f64,
    /// A one-way transit time (s) added to every received message's age, for ages that
    /// count from the moment the frame left the sender. comms' ages include each frame's
    /// own estimated transit (wire format 3), so with comms this is 0 (the default). See
    /// the crate docs, *Time*.
    pub transit_s: f64,
    /// The robot's own observations that must fail the gate in a row (agreeing with each
    /// other, unopposed) before its own camera restarts the team ball; 0 turns it off.
    pub own_restart_after: u32,
    /// The same for a teammate's observations (see `challenge`): one more than the own,
    /// since a teammate may be wrong about the ball where the own camera is what this
    /// robot sees; 0 turns it off.
    pub teammate_restart_after: u32,
    /// How far from a kicker's reported position the ball may be for its kick to be taken
    /// (m), before both positions' uncertainty is added: the robot's radius, the ball's,
    /// and the reach of a foot.
    pub kick_reach_m: f64,
    /// Sparse messages (a league's message budget): a teammate whose messages come more
    /// than this far apart (s) is taken by its ball *track*, not by the sighting batches
    /// its messages carry. Under a budget a message carries the batch of one control tick
    /// (what was batched between messages was never sent), while the track holds every
    /// sighting the teammate made. The track's new information since its previous message
    /// is fused (see `track_measurement`), so nothing is counted twice. `None`: batches
    /// only (the default; messages every control tick).
    pub track_after_s: Option<f64>,
    /// After [`GlobalModel::forget_ball`] at `t`, a teammate's ball information stamped
    /// before `t` + this is void too (s). Its stamp carries the shared clock's placement
    /// error (a few ms), so a message sent just before the ball was put back can land just
    /// after the forget and start the new team ball on the old one, far from the centre
    /// spot, until the cameras outvote it. The own robot's stamps are exact.
    pub forget_margin_s: f64,
}

impl Default for GlobalConfig {
    fn default() -> Self {
        GlobalConfig {
            ball: BallModel::default(),
            initial_velocity_var: 4.0,
            gate_chi2: 9.21,
            commit_lag_s: 0.5,
            stale_after_s: 1.0,
            confidence_decay_per_s: 0.5,
            dissent_window_s: 0.5,
            support_timeout_s: 0.5,
            transit_s: 0.0,
            own_restart_after: 2,
            teammate_restart_after: 3,
            kick_reach_m: 0.5,
            track_after_s: None,
            forget_margin_s: 0.03,
        }
    }
}

/// What [`GlobalModel::ingest`] did with one LWM.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Ingest {
    /// Same or older sequence number than one already taken: ignored (re-send, duplicate).
    Duplicate,
    /// Pose taken; the message carried no new ball information.
    NoObservation,
    /// There was no team ball: it starts from this robot's.
    Started,
    /// The ball observation passed the gate and is fused.
    Accepted(f64),
    /// The ball observation failed the gate (Mahalanobis² given) and is not fused.
    Rejected(f64),
    /// The ball observation is older than the committed team ball: too late to use.
    Late,
}

/// Counters, for reports and tests.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GlobalStats {
    /// Observations fused.
    pub accepted: u64,
    /// Observations gated out.
    pub rejected: u64,
    /// Observations too late to use (and kicks too late or gated out, see `kick_velocity`).
    pub late: u64,
    /// Messages ignored as duplicates or re-sends.
    pub duplicates: u64,
    /// Times the team ball restarted from a consensus of dissenting robots.
    pub restarts: u64,
    /// Batches taken from the repeats in a later message (their own message was lost).
    pub recovered: u64,
    /// Kicks applied to the team ball.
    pub kicks: u64,
    /// Kicks refused: the kicker was not within reach of the team ball.
    pub kicks_refused: u64,
    /// Teammates' tracks taken for their new information (sparse messages, see
    /// [`GlobalConfig::track_after_s`]).
    pub tracks: u64,
}

/// Where a [`TeamBall`] came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TeamBallSource {
    /// The fused team track.
    Fused,
    /// No fresh teammate: the robot's own ball.
    OwnFallback,
}

/// The team ball at a time, with its global ball confidence (GBC).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TeamBall {
    /// The estimate, predicted to the time asked for.
    pub estimate: BallEstimate,
    /// Global ball confidence in [0, 1].
    pub gbc: f64,
    /// Fused or fallback.
    pub source: TeamBallSource,
}

/// A teammate as the GWM sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Teammate {
    /// Robot id.
    pub id: u8,
    /// Its last reported pose (it stays put while the robot is silent).
    pub pose: PoseEstimate,
    /// Its SLC, minus the constant-rate decay since its last message.
    pub confidence: f64,
    /// Seconds since its last message's snapshot time.
    pub silent_for_s: f64,
    /// Its last LWM.
    pub lwm: LocalWorldModel,
}

#[derive(Debug, Clone, PartialEq)]
struct RobotRecord {
    lwm: LocalWorldModel,
    /// `lwm` is still the message exactly as [`GlobalModel::ingest`] took it (a
    /// [`GlobalModel::forget_ball`] since drops its ball): see [`GlobalModel::received`].
    as_taken: bool,
    received_t_s: f64,
    last_rejected_t_s: Option<f64>,
    last_accepted_t_s: Option<f64>,
    /// Its newest accepted observation (see `restart_on_consensus`).
    accepted_obs: Option<FieldObservation>,
    /// Its observations rejected in a row that agree with each other (see `challenge`).
    rejected_run: Vec<FieldObservation>,
    /// The track those observations make, filtered as each joined the run (`None` while
    /// the run is empty), so that a challenge does not filter the whole run again.
    run_track: Option<BallEstimate>,
    /// What has been taken from its messages (sequence numbers, kicks).
    heard: Heard,
}

impl RobotRecord {
    /// Ends its run of rejected observations.
    fn clear_run(&mut self) {
        self.rejected_run.clear();
        self.run_track = None;
    }
}

/// A robot's GWM. Feed it every LWM (teammates' through [`GlobalModel::receive`], its own
/// through [`GlobalModel::ingest`]) and ask for [`GlobalModel::team_ball`].
#[derive(Debug, Clone)]
pub struct GlobalModel {
    own_id: u8,
    config: GlobalConfig,
    robots: Records<RobotRecord>,
    committed: Option<BallEstimate>,
    /// Observations not yet committed, in time order, and the state after each
    /// (checkpoints, so that a late arrival replays only what follows it, and only when
    /// read: a read through `&self`, [`GlobalModel::team_ball`], brings them up to date,
    /// hence the cell). Queues: `commit` takes from the front at every message.
    /// The newest state (the head of the track) is the last checkpoint, or the committed
    /// ball when nothing is pending: not kept apart, so no insertion copies it.
    pending: VecDeque<Measured>,
    after: RefCell<Checkpoints>,
    last_support_t_s: f64,
    /// Ball information from before this time is void (see [`GlobalModel::forget_ball`]).
    forgotten_before_t_s: f64,
    /// The latest time of an observation that passed the gate.
    last_accepted_obs_t_s: f64,
    /// Every robot's rejected observations not yet older than the committed ball: after
    /// a restart, those that agree with the new track are fused at their own times.
    rejected: VecDeque<Measured>,
    /// The track as it was before the latest restart, so that a kick whose report arrives
    /// after the cameras already restarted the ball can rewind to it (see `kicked`).
    rewind: Option<Rewind>,
    /// The team ball is still the one [`GlobalModel::place_ball`] put down: no camera has
    /// restarted it and no kick has moved it since.
    placed: bool,
    stats: GlobalStats,
}

/// Two GWMs are equal when they hold the same state: stale checkpoints (see
/// `checkpoints`) are brought up to date before they are compared.
impl PartialEq for GlobalModel {
    fn eq(&self, other: &Self) -> bool {
        for gwm in [self, other] {
            let base = gwm.base();
            gwm.after.borrow_mut().settled(&base);
        }
        self.own_id == other.own_id
            && self.config == other.config
            && self.robots == other.robots
            && self.committed == other.committed
            && self.pending == other.pending
            && self.after.borrow().states() == other.after.borrow().states()
            && self.last_support_t_s == other.last_support_t_s
            && self.forgotten_before_t_s == other.forgotten_before_t_s
            && self.last_accepted_obs_t_s == other.last_accepted_obs_t_s
            && self.rejected == other.rejected
            && self.rewind == other.rewind
            && self.placed == other.placed
            && self.stats == other.stats
    }
}

/// A track set aside by a restart.
#[derive(Debug, Clone, PartialEq)]
struct Rewind {
    /// The restarted track begins here.
    restart_t_s: f64,
    committed: BallEstimate,
    pending: VecDeque<Measured>,
    after: VecDeque<BallEstimate>,
    rejected: VecDeque<Measured>,
}

impl GlobalModel {
    /// An empty GWM for robot `own_id`.
    pub fn new(own_id: u8, config: GlobalConfig) -> Self {
        GlobalModel {
            own_id,
            config,
            robots: Records::default(),
            committed: None,
            pending: VecDeque::new(),
            after: RefCell::default(),
            last_support_t_s: f64::NEG_INFINITY,
            forgotten_before_t_s: f64::NEG_INFINITY,
            last_accepted_obs_t_s: f64::NEG_INFINITY,
            rejected: VecDeque::new(),
            rewind: None,
            placed: false,
            stats: GlobalStats::default(),
        }
    }

    /// The settings.
    pub fn config(&self) -> &GlobalConfig {
        &self.config
    }

    /// Counters so far.
    pub fn stats(&self) -> GlobalStats {
        self.stats
    }

    /// A teammate's message as received at `now_s`, `age_s` old by the receiver's reckoning
    /// (its snapshot holds at `now_s − age_s − transit_s`, see [`GlobalConfig::transit_s`]).
    /// Bytes from the network: errors, never panics.
    pub fn receive(
        &mut self,
        robot: u8,
        bytes: &[u8],
        now_s: f64,
        age_s: f64,
    ) -> Result<Ingest, DecodeError> {
        let lwm = self.decode(bytes, now_s, age_s)?;
        Ok(self.ingest(robot, &lwm, now_s))
    }

    /// A teammate's message decoded and placed on this robot's clock as [`Self::receive`]
    /// places it, for a caller that also wants the LWM itself (then [`Self::ingest`] it).
    pub fn decode(
        &self,
        bytes: &[u8],
        now_s: f64,
        age_s: f64,
    ) -> Result<LocalWorldModel, DecodeError> {
        LocalWorldModel::from_bytes(bytes, now_s - age_s - self.config.transit_s)
    }

    /// One LWM (`lwm.t_s` on this robot's clock). Use this for the robot's own LWM each
    /// time it publishes, and [`GlobalModel::receive`] for teammates.
    pub fn ingest(&mut self, robot: u8, lwm: &LocalWorldModel, now_s: f64) -> Ingest {
        // `or_insert_with`: the record (an LWM, ~0.6 kB) is built only for a new robot.
        let rec = self.robots.get_or_insert_with(robot, || RobotRecord {
            lwm: *lwm,
            as_taken: true,
            received_t_s: now_s,
            last_rejected_t_s: None,
            last_accepted_t_s: None,
            accepted_obs: None,
            rejected_run: Vec::new(),
            run_track: None,
            heard: Heard::default(),
        });
        let first = rec.heard == Heard::default();
        let Some(missed) = rec.heard.take(lwm, self.config.stale_after_s) else {
            self.stats.duplicates += 1;
            return Ingest::Duplicate;
        };
        // Of the previous message only its time and (for a sparse one) its ball are used:
        // read them before it is overwritten rather than copying the whole LWM.
        let previous_t_s = rec.lwm.t_s;
        let sparse = robot != self.own_id
            && self
                .config
                .track_after_s
                .is_some_and(|gap| first || lwm.t_s - previous_t_s > gap);
        // What the teammate's track learnt since its previous message (its batches hold
        // one tick of it) starts from the previous message's ball.
        let before_ball = if sparse
            && !first
            && lwm.kick.is_none_or(|k| k.kick.t_s <= previous_t_s)
            && previous_t_s < lwm.t_s
        {
            rec.lwm.ball
        } else {
            None
        };
        rec.lwm = *lwm;
        rec.as_taken = true;
        rec.received_t_s = now_s;

        let result = if sparse {
            let model = self.config.ball;
            match track_measurement(&model, before_ball.as_ref(), lwm) {
                None => Ingest::NoObservation,
                Some(m) => {
                    self.stats.tracks += 1;
                    self.observe(robot, &m, lwm, now_s)
                }
            }
        } else {
            // Oldest first, so that the filter sees them in time order: the repeats of
            // messages lost in between, then the message's own batch.
            for obs in missed.into_iter().flatten() {
                self.stats.recovered += 1;
                self.observe(robot, &obs.into(), lwm, now_s);
            }
            match lwm.observation {
                None => Ingest::NoObservation,
                Some(obs) => self.observe(robot, &obs.into(), lwm, now_s),
            }
        };
        let rec = self.robots.get_mut(&robot).expect("record inserted above");
        if let Some(kick) = rec.heard.kick(lwm) {
            self.kicked(robot, &kick, &lwm.pose, now_s);
        }
        self.commit(now_s - self.config.commit_lag_s);
        self.restart_on_consensus(now_s);
        result
    }

    fn observe(
        &mut self,
        robot: u8,
        measured: &Measured,
        lwm: &LocalWorldModel,
        now_s: f64,
    ) -> Ingest {
        let model = self.config.ball;
        let obs = &measured.obs;
        if obs.t_s < self.forgotten_before(robot) {
            self.stats.late += 1;
            return Ingest::Late;
        }
        let Some(committed) = self.committed else {
            let start = lwm
                .ball
                .unwrap_or_else(|| initial_estimate(&model, obs, self.config.initial_velocity_var));
            self.committed = Some(start);
            self.clear_pending();
            self.last_support_t_s = now_s;
            self.last_accepted_obs_t_s = obs.t_s;
            if let Some(rec) = self.robots.get_mut(&robot) {
                rec.last_accepted_t_s = Some(now_s);
                rec.accepted_obs = Some(*obs);
                if lwm.ball.is_some() {
                    // The robot's own ball already turned with its kick: not twice.
                    if let Some(report) = lwm.kick {
                        rec.heard.take_kick(&report);
                    }
                }
            }
            return Ingest::Started;
        };
        if obs.t_s < committed.t_s {
            self.stats.late += 1;
            return Ingest::Late;
        }
        let Some(prior) = self.state_at(obs.t_s) else {
            return Ingest::Late;
        };
        let Some(d2) = prior.position_mahalanobis_sq(&model, obs) else {
            return Ingest::Late;
        };
        let rec = self.robots.get_mut(&robot).expect("record inserted above");
        if d2 > self.config.gate_chi2 {
            rec.last_rejected_t_s = Some(now_s);
            self.stats.rejected += 1;
            let at = partition_near_back(&self.rejected, |p| p.t_s <= obs.t_s);
            self.rejected.insert(at, *measured);
            self.challenge(robot, obs, now_s);
            return Ingest::Rejected(d2);
        }
        rec.last_accepted_t_s = Some(now_s);
        rec.accepted_obs = Some(*obs);
        rec.clear_run();
        self.last_support_t_s = now_s;
        self.last_accepted_obs_t_s = self.last_accepted_obs_t_s.max(obs.t_s);
        self.stats.accepted += 1;
        self.insert_pending(measured, &prior);
        Ingest::Accepted(d2)
    }

    /// Fuses `obs` (which passed the gate against `prior`, the state at its time) into the
    /// pending observations; the ones after it are carried forward when next read.
    fn insert_pending(&mut self, obs: &Measured, prior: &BallEstimate) {
        let model = self.config.ball;
        let at = partition_near_back(&self.pending, |p| p.t_s <= obs.t_s);
        // Up to date already: `prior` was read there.
        self.after.borrow_mut().settle(&self.base(), at);
        self.pending.insert(at, *obs);
        // `prior` is the state just before this observation: update it; the observations
        // after it (arrived earlier, made later) go on from there.
        let next = obs.apply(&model, prior).unwrap_or(*prior);
        let base = self.base();
        self.after.borrow_mut().insert(&base, at, next);
    }

    /// What the checkpoints are computed from.
    fn base(&self) -> Base<'_> {
        Base {
            model: &self.config.ball,
            committed: self.committed.as_ref(),
            pending: &self.pending,
        }
    }

    fn clear_pending(&mut self) {
        self.pending.clear();
        self.after.get_mut().clear();
    }

    /// The team track at `t_s`: the state after the committed ball and every pending
    /// observation up to `t_s`, predicted to `t_s` (see `checkpoints`).
    fn state_at(&self, t_s: f64) -> Option<BallEstimate> {
        self.after.borrow_mut().state_at(&self.base(), t_s)
    }

    fn commit(&mut self, before_t_s: f64) {
        let r = partition_near_front(&self.rejected, |p| p.t_s < before_t_s);
        self.rejected.drain(..r);
        let n = partition_near_front(&self.pending, |p| p.t_s < before_t_s);
        if n == 0 || self.committed.is_none() {
            return;
        }
        let base = self.base();
        let mut after = self.after.borrow_mut();
        let committed = *after.after(&base, n).expect("a committed ball");
        after.drain_front(n);
        drop(after);
        self.committed = Some(committed);
        self.pending.drain(..n);
    }

    /// A robot's observations disagree with the team ball: a kick, bounce or shove that
    /// it saw, or a false ball. Once enough of its observations in a row fail the gate
    /// (`own_restart_after` for the robot's own camera, `teammate_restart_after` for a
    /// teammate), agree with each other, and nobody's observation made *since the first of
    /// them* has supported the old ball, the team ball restarts from the first of them and
    /// every observation since (its own and everyone else's, accepted or rejected) that
    /// agrees with the new track is fused at its own time. Reports from before the kick,
    /// still arriving, do not hold it back (they describe the ball before it moved). A liar
    /// among robots that see the real ball cannot do it: their observations keep
    /// supporting the team ball after the liar's first false one.
    fn challenge(&mut self, robot: u8, obs: &FieldObservation, now_s: f64) {
        let needed = if robot == self.own_id {
            self.config.own_restart_after
        } else {
            self.config.teammate_restart_after
        };
        if needed == 0 {
            return;
        }
        let model = self.config.ball;
        let gate = self.config.gate_chi2;
        let velocity_var = self.config.initial_velocity_var;
        let Some(rec) = self.robots.get_mut(&robot) else {
            return;
        };
        if let (Some(last), Some(track)) = (rec.rejected_run.last(), rec.run_track) {
            let agrees = obs.t_s >= last.t_s
                && track
                    .position_mahalanobis_sq(&model, obs)
                    .is_some_and(|d2| d2 <= gate);
            if !agrees {
                rec.clear_run();
            }
        }
        rec.run_track = Some(match rec.run_track {
            None => initial_estimate(&model, obs, velocity_var),
            Some(est) => update(&model, &est, obs, None).map_or(est, |(e, _)| e),
        });
        rec.rejected_run.push(*obs);
        let run = &rec.rejected_run;
        if run.len() < needed as usize || run[0].t_s <= self.last_accepted_obs_t_s {
            return;
        }
        let first = run[0];
        rec.accepted_obs = run.last().copied();
        rec.clear_run();
        rec.last_rejected_t_s = None;
        rec.last_accepted_t_s = Some(now_s);
        self.restart_from(&first, now_s);
    }

    /// A teammate (or this robot) kicked the ball: the kick joins the pending observations
    /// at its own time, so the team ball as it was at the kick, with the kick's velocity,
    /// continues the track from then on, and every observation made since (pending or
    /// rejected) is gated against it and fused at its own time. Sightings after a kick no
    /// longer have to outvote the old track first: the team ball turns the moment the
    /// kick's report arrives. What was seen before the kick is kept, and a sighting made
    /// before it whose message comes after the report (a beacon hold delays teammates'
    /// messages by up to two beacons while the kicker's own report is at once) slots in
    /// before it: the kick is applied again on the better state. Dissent is cleared (it
    /// was about the kick).
    ///
    /// A kick is taken only from a kicker that was within reach of the team ball at the
    /// kick ([`GlobalConfig::kick_reach_m`] plus three σ of both positions): a robot that
    /// claims to kick a ball it is nowhere near cannot turn the team ball. When the
    /// cameras restarted the ball after the kick but before its report came, the track is
    /// rewound to the kick first; when the kick is older than the committed ball and there
    /// is nothing to rewind, its velocity is fused instead (see `kick_velocity`).
    fn kicked(&mut self, robot: u8, kick: &Kick, kicker: &PoseEstimate, now_s: f64) {
        if !kick.is_valid() || kick.t_s < self.forgotten_before(robot) {
            return;
        }
        let Some(committed) = self.committed else {
            return;
        };
        let model = self.config.ball;
        // The track at the kick: the one set aside by a restart since, if there is one and
        // nothing of the restarted track has been committed (true within the commit lag).
        let rewind = self.rewind.take().filter(|rw| {
            kick.t_s < rw.restart_t_s
                && kick.t_s >= rw.committed.t_s
                && now_s - kick.t_s <= self.config.commit_lag_s
                && committed.t_s <= rw.restart_t_s
        });
        let at_kick = match &rewind {
            Some(rw) => {
                let n = rw.pending.partition_point(|o| o.t_s <= kick.t_s);
                let state = if n == 0 {
                    rw.committed
                } else {
                    rw.after[n - 1]
                };
                Some(state.predict_to(&model, kick.t_s))
            }
            None if kick.t_s >= committed.t_s => self.state_at(kick.t_s),
            None => None,
        };
        let (ball, travelled_m) = match &at_kick {
            Some(b) => (*b, 0.0),
            // Older than the committed ball: since the kick it has rolled at most this far.
            None => (committed, kick.speed_mps * (committed.t_s - kick.t_s)),
        };
        if !self.within_reach(&ball, kicker, travelled_m) {
            self.stats.kicks_refused += 1;
            self.rewind = rewind;
            return;
        }
        let Some(before) = at_kick else {
            self.kick_velocity(kick, &committed);
            return;
        };
        // What was seen after the kick, by either track (the one set aside by a restart,
        // if there is one), fused or not: gated again against the kicked one. What was
        // seen before it stays, and a sighting from before it that arrives later still
        // slots in before it.
        let later: Vec<Measured> = match rewind {
            Some(mut rw) => {
                let keep = rw.pending.partition_point(|o| o.t_s <= kick.t_s);
                let later = self
                    .pending
                    .iter()
                    .chain(&self.rejected)
                    .chain(rw.pending.range(keep..))
                    .chain(&rw.rejected)
                    .filter(|o| o.t_s > kick.t_s)
                    .copied()
                    .collect();
                rw.pending.truncate(keep);
                rw.after.truncate(keep);
                self.committed = Some(rw.committed);
                self.pending = rw.pending;
                self.after.get_mut().restore(rw.after);
                later
            }
            None => {
                let keep = self.pending.partition_point(|o| o.t_s <= kick.t_s);
                // Up to date already: the state at the kick was read there.
                self.after.borrow_mut().settle(&self.base(), keep);
                self.after.get_mut().truncate(keep);
                self.pending
                    .drain(keep..)
                    .chain(self.rejected.iter().filter(|o| o.t_s > kick.t_s).copied())
                    .collect()
            }
        };
        self.rejected.clear();
        self.stats.kicks += 1;
        self.placed = false;
        for rec in self.robots.values_mut() {
            rec.last_rejected_t_s = None;
            rec.clear_run();
        }
        let kicked = Measured::kick(kick);
        let turned = kicked.apply(&model, &before).unwrap_or(before);
        self.pending.push_back(kicked);
        self.after.get_mut().push_back(turned);
        self.last_support_t_s = now_s;
        self.last_accepted_obs_t_s = kick.t_s;
        self.regate(later);
    }

    /// Whether a kicker at `kicker` could have reached `ball` (which may have rolled up to
    /// `travelled_m` since the kick).
    fn within_reach(&self, ball: &BallEstimate, kicker: &PoseEstimate, travelled_m: f64) -> bool {
        let kicker_at = Vector2::new(kicker.mean.x, kicker.mean.y);
        let cov = ball.position_cov() + kicker.cov.fixed_view::<2, 2>(0, 0);
        let sigma_m = cov.symmetric_eigenvalues().max().max(0.0).sqrt();
        let d = (ball.position() - kicker_at).norm();
        d.is_finite() && d <= self.config.kick_reach_m + travelled_m + 3.0 * sigma_m
    }

    /// A kick that is older than the committed ball: the track restarted since (a camera
    /// saw the ball go before the report arrived), so the kick can no longer place the
    /// turn, but it still tells the velocity. The kick's velocity, rolled forward by the
    /// model to the committed time, is fused into the committed ball as a velocity
    /// measurement (gated: a track restarted by something after the kick, a bounce or a
    /// shove, does not take it), and the pending observations are replayed on top.
    fn kick_velocity(&mut self, kick: &Kick, committed: &BallEstimate) {
        let model = self.config.ball;
        if committed.t_s - kick.t_s > self.config.commit_lag_s {
            self.stats.late += 1;
            return;
        }
        let (v, v_cov) = kick.velocity();
        let mut kicked = BallEstimate {
            t_s: kick.t_s,
            mean: Vector4::new(0.0, 0.0, v.x, v.y),
            cov: Matrix4::zeros(),
        };
        kicked.cov.fixed_view_mut::<2, 2>(2, 2).copy_from(&v_cov);
        let rolled = kicked.predict_to(&model, committed.t_s);
        let h = SMatrix::<f64, 2, 4>::new(0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0);
        let r: Matrix2<f64> = rolled.cov.fixed_view::<2, 2>(2, 2).into_owned();
        let innovation = rolled.velocity() - committed.velocity();
        let Ok(u) = kalman::update(
            &committed.mean,
            &committed.cov,
            &innovation,
            &h,
            &r,
            Some(self.config.gate_chi2),
        ) else {
            self.stats.late += 1;
            return;
        };
        self.stats.kicks += 1;
        self.placed = false;
        self.committed = Some(BallEstimate {
            t_s: committed.t_s,
            mean: u.mean,
            cov: u.cov,
        });
        let base = self.base();
        self.after.borrow_mut().stale_from(&base, 0);
    }

    /// The team ball restarts from `first`; every observation made after it (pending or
    /// rejected) is gated against the new track and fused at its own time.
    fn restart_from(&mut self, first: &FieldObservation, now_s: f64) {
        let model = self.config.ball;
        let fresh = initial_estimate(&model, first, self.config.initial_velocity_var);
        self.stats.restarts += 1;
        self.keep_for_rewind(fresh.t_s);
        self.restart_with(fresh, now_s);
    }

    /// Sets the current track aside before a restart at `restart_t_s`.
    fn keep_for_rewind(&mut self, restart_t_s: f64) {
        let base = self.base();
        let rewind = self.committed.map(|committed| Rewind {
            restart_t_s,
            committed,
            pending: self.pending.clone(),
            after: self.after.borrow_mut().settled(&base).clone(),
            rejected: self.rejected.clone(),
        });
        self.rewind = rewind;
    }

    /// The team ball restarts as `fresh`; every observation made after it (pending or
    /// rejected) is gated against the new track and fused at its own time.
    fn restart_with(&mut self, fresh: BallEstimate, now_s: f64) {
        let since: Vec<Measured> = self
            .pending
            .iter()
            .chain(self.rejected.iter())
            .filter(|o| o.t_s > fresh.t_s)
            .copied()
            .collect();
        self.committed = Some(fresh);
        self.placed = false;
        self.clear_pending();
        self.rejected.clear();
        self.last_support_t_s = now_s;
        self.last_accepted_obs_t_s = fresh.t_s;
        self.regate(since);
    }

    /// Fuses `since` (everything after the head, in any order) at their own times: each
    /// observation gated against the track at its time, each kick applied.
    fn regate(&mut self, mut since: Vec<Measured>) {
        let model = self.config.ball;
        // One observation may sit in both lists (or twice, after a rewind): fuse it once.
        // Sorting by time, then place, puts copies next to each other.
        since.sort_by(|a, b| {
            a.t_s
                .total_cmp(&b.t_s)
                .then(a.position.x.total_cmp(&b.position.x))
                .then(a.position.y.total_cmp(&b.position.y))
        });
        since.dedup();
        for o in &since {
            let Some(prior) = self.state_at(o.t_s) else {
                continue;
            };
            if o.kick.is_some() {
                self.insert_pending(o, &prior);
                continue;
            }
            match prior.position_mahalanobis_sq(&model, o) {
                Some(d2) if d2 <= self.config.gate_chi2 => {
                    self.last_accepted_obs_t_s = self.last_accepted_obs_t_s.max(o.t_s);
                    self.insert_pending(o, &prior);
                }
                _ => {
                    let at = partition_near_back(&self.rejected, |p| p.t_s <= o.t_s);
                    self.rejected.insert(at, *o);
                }
            }
        }
    }

    /// One liar cannot move the team ball: its observations fail the gate and it dissents
    /// alone. A real kick makes every robot that sees the ball dissent at once, and their
    /// own tracks agree with each other: then the team ball restarts from them.
    fn restart_on_consensus(&mut self, now_s: f64) {
        let model = self.config.ball;
        let window = self.config.dissent_window_s;
        let dissenting = |r: &RobotRecord| {
            r.lwm.ball.is_some()
                && r.last_rejected_t_s.is_some_and(|rej| {
                    rej >= now_s - window && r.last_accepted_t_s.is_none_or(|acc| acc < rej)
                })
        };
        let unsupported = now_s - self.last_support_t_s > self.config.support_timeout_s;
        // Counted before any ball is predicted: at every message, there is usually nobody
        // or one robot dissenting, and one cannot restart a supported ball on its own.
        match self.robots.values().filter(|r| dissenting(r)).count() {
            0 => return,
            1 if !unsupported => return,
            _ => {}
        }
        let dissenters: Vec<(u8, BallEstimate)> = self
            .robots
            .iter()
            .filter(|(_, r)| dissenting(r))
            .filter_map(|(&id, r)| r.lwm.ball.map(|b| (id, b.predict_to(&model, now_s))))
            .collect();
        let agree = |a: &BallEstimate, b: &BallEstimate| {
            kalman::mahalanobis_sq(
                &(a.position() - b.position()),
                &(a.position_cov() + b.position_cov()),
            )
            .is_some_and(|d2| d2 <= self.config.gate_chi2)
        };
        let mut best: Vec<usize> = Vec::new();
        for (i, (_, a)) in dissenters.iter().enumerate() {
            let group: Vec<usize> = dissenters
                .iter()
                .enumerate()
                .filter(|(j, (_, b))| *j == i || agree(a, b))
                .map(|(j, _)| j)
                .collect();
            if group.len() > best.len() {
                best = group;
            }
        }
        if best.len() < 2 && !unsupported {
            return;
        }
        let mut fused = dissenters[best[0]].1;
        for &j in &best[1..] {
            fused = fuse_independent(&fused, &dissenters[j].1);
        }
        // Nor can fewer robots than see the ball where the team has it: two robots that
        // each hold a false ball (wide enough to agree with each other) must not move a
        // ball three teammates are tracking (seed 517 of the drawn simulator). A robot
        // supports the team ball against the group if its last observation, accepted
        // within the dissent window and not dissented from since, fits the team ball
        // better than the group's (Mahalanobis). After a kick nobody reported, what the
        // old track still takes (far robots' wide sightings of the rolling ball) fits the
        // kicked ball as well, so it does not hold the kick back.
        if !unsupported {
            let supporting = |r: &RobotRecord| {
                r.last_accepted_t_s.is_some_and(|acc| {
                    acc >= now_s - window && r.last_rejected_t_s.is_none_or(|rej| rej < acc)
                }) && r.accepted_obs.is_some_and(|obs| {
                    let team = self
                        .state_at(obs.t_s)
                        .and_then(|b| b.position_mahalanobis_sq(&model, &obs));
                    let group = fused.position_mahalanobis_sq(&model, &obs);
                    match (team, group) {
                        (Some(team), Some(group)) => team < group,
                        _ => false,
                    }
                })
            };
            // Dissenters outside the group whose ball does not fit the group's oppose it too.
            let elsewhere = dissenters
                .iter()
                .enumerate()
                .filter(|(j, (_, b))| !best.contains(j) && !agree(&fused, b))
                .count();
            let supporters = self.robots.values().filter(|r| supporting(r)).count() + elsewhere;
            if best.len() < supporters {
                return;
            }
        }
        self.keep_for_rewind(fused.t_s);
        self.committed = Some(fused);
        self.placed = false;
        self.clear_pending();
        self.rejected.clear();
        self.last_support_t_s = now_s;
        self.stats.restarts += 1;
        for &j in &best {
            if let Some(rec) = self.robots.get_mut(&dissenters[j].0) {
                rec.last_rejected_t_s = None;
                rec.last_accepted_t_s = Some(now_s);
                rec.accepted_obs = rec.rejected_run.last().copied();
            }
        }
    }

    /// Drops the team ball and every robot's ball as last reported, and ignores ball
    /// information from before `t_s` still on its way: the ball was put somewhere else by
    /// hand at `t_s` (a referee's kick-off). Teammates' poses are kept.
    pub fn forget_ball(&mut self, t_s: f64) {
        self.rewind = None;
        self.committed = None;
        self.placed = false;
        self.clear_pending();
        self.forgotten_before_t_s = t_s;
        self.rejected.clear();
        for rec in self.robots.values_mut() {
            if rec.lwm.ball.take().is_some() {
                rec.as_taken = false;
            }
            rec.last_rejected_t_s = None;
            rec.accepted_obs = None;
            rec.clear_run();
        }
    }

    /// The ball was put down by hand at `placed.t_s` where `placed` says (a referee's
    /// kick-off: the centre spot, its covariance the placement's error): everything
    /// [`GlobalModel::forget_ball`] drops goes, and the team ball starts as `placed`
    /// instead of with the next sighting. Sightings after it are gated against it and
    /// fused as any; a wrong placement does not stick: the robot's own camera restarts it
    /// after [`GlobalConfig::own_restart_after`] agreeing sightings, a teammate's after
    /// [`GlobalConfig::teammate_restart_after`], and once nothing has supported it for
    /// [`GlobalConfig::support_timeout_s`] a single dissenting robot does. Until a
    /// teammate is heard the team ball is the placement (see [`GlobalModel::team_ball`]).
    pub fn place_ball(&mut self, placed: BallEstimate) {
        self.forget_ball(placed.t_s);
        self.committed = Some(placed);
        self.last_support_t_s = placed.t_s;
        self.last_accepted_obs_t_s = placed.t_s;
        self.placed = true;
    }

    /// Whether the team ball is still the one [`GlobalModel::place_ball`] put down (fused
    /// with sightings that agreed with it, but not restarted or kicked since).
    pub fn is_placed(&self) -> bool {
        self.placed
    }

    /// Ball information from `robot` stamped before this is void (see
    /// [`GlobalConfig::forget_margin_s`]).
    fn forgotten_before(&self, robot: u8) -> f64 {
        if robot == self.own_id {
            self.forgotten_before_t_s
        } else {
            self.forgotten_before_t_s + self.config.forget_margin_s
        }
    }

    fn any_fresh_teammate(&self, now_s: f64) -> bool {
        self.robots
            .iter()
            .any(|(&id, r)| id != self.own_id && now_s - r.lwm.t_s <= self.config.stale_after_s)
    }

    /// The team ball at `now_s`: the fused track, or the robot's own ball when every
    /// teammate is silent. `own_ball` is the robot's freshest own ball
    /// ([`crate::LocalModel::ball_at`]); without it the fallback uses the own LWM last
    /// ingested. `None` before anyone has seen a ball.
    pub fn team_ball(&self, now_s: f64, own_ball: Option<&BallEstimate>) -> Option<TeamBall> {
        let model = self.config.ball;
        let (estimate, source) = if self.any_fresh_teammate(now_s) {
            (self.state_at(now_s)?, TeamBallSource::Fused)
        } else {
            let own = match own_ball {
                Some(b) => Some(*b),
                None => self.robots.get(&self.own_id).and_then(|r| r.lwm.ball),
            };
            match own {
                Some(own) => (own.predict_to(&model, now_s), TeamBallSource::OwnFallback),
                // A ball put down by hand is known without anyone's sighting.
                None if self.placed => (self.state_at(now_s)?, TeamBallSource::Fused),
                None => return None,
            }
        };
        Some(TeamBall {
            gbc: position_confidence(&estimate.position_cov()),
            estimate,
            source,
        })
    }

    /// Every other robot heard from, with its decayed confidence.
    pub fn teammates(&self, now_s: f64) -> Vec<Teammate> {
        self.teammates_iter(now_s).collect()
    }

    /// [`GlobalModel::teammates`] one at a time, in the same order, for a caller that
    /// only passes over them (a robot does at every tick).
    pub fn teammates_iter(&self, now_s: f64) -> impl Iterator<Item = Teammate> + '_ {
        self.robots
            .iter()
            .filter(move |(&id, _)| id != self.own_id)
            .map(move |(&id, r)| {
                let silent_for_s = (now_s - r.lwm.t_s).max(0.0);
                Teammate {
                    id,
                    pose: r.lwm.pose,
                    confidence: (r.lwm.slc - self.config.confidence_decay_per_s * silent_for_s)
                        .max(0.0),
                    silent_for_s,
                    lwm: r.lwm,
                }
            })
    }

    /// The latest LWM taken from robot `id` (this robot's own included), on this robot's
    /// clock: for logs and references that want what the team's fusion holds.
    pub fn latest(&self, id: u8) -> Option<&LocalWorldModel> {
        self.robots.get(&id).map(|r| &r.lwm)
    }

    /// [`Self::latest`] only while it is still the LWM exactly as [`Self::ingest`] took it
    /// (its last call for `id` that was not a [`Ingest::Duplicate`]): `None` once a
    /// [`Self::forget_ball`] or [`Self::place_ball`] dropped its ball. A second reader of
    /// the same message (the simulator's delivery reference, through the team layer) takes
    /// it from here instead of a copy of its own.
    pub fn received(&self, id: u8) -> Option<&LocalWorldModel> {
        self.robots.get(&id).filter(|r| r.as_taken).map(|r| &r.lwm)
    }

    /// Where robot `id` last said the ball was, predicted to `now_s` (for displays).
    pub fn robot_ball(&self, id: u8, now_s: f64) -> Option<Vector2<f64>> {
        let b = self.robots.get(&id)?.lwm.ball?;
        Some(b.predict_to(&self.config.ball, now_s).position())
    }
}

/// What a teammate's compact message adds to a filter that took its previous one: the
/// information its track gained since, as a measurement of the whole state (x, y, vx, vy)
/// at the message's time (see [`track_gain`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackGain {
    /// When the state was measured (the message's snapshot time), s.
    pub t_s: f64,
    /// The measured state.
    pub mean: Vector4<f64>,
    /// Its covariance (directions the track learnt nothing in carry 10⁶).
    pub cov: Matrix4<f64>,
}

/// The measurement the GWM takes from a sparse teammate message (`GlobalConfig::
/// track_after_s`): `lwm`'s track's information minus what `previous` (the sender's
/// track in the message taken before, if it continues into this one), rolled forward,
/// already held. For a reference that should read the compact world model exactly as the
/// team does.
pub fn track_gain(
    model: &BallModel,
    previous: Option<&BallEstimate>,
    lwm: &LocalWorldModel,
) -> Option<TrackGain> {
    let m = track_measurement(model, previous, lwm)?;
    let (mean, cov) = m.state?;
    Some(TrackGain {
        t_s: m.obs.t_s,
        mean,
        cov,
    })
}

/// The information a teammate's track gained since its previous message, as a measurement
/// of the whole state at the new message's time: the new track's information minus what
/// the previous track, rolled forward, already held (the receiver took that one before).
/// Exact for a track that only filtered sightings in between; the process noise added
/// meanwhile makes it slightly generous. Directions where the track learnt nothing (a
/// teammate that did not see the ball, rounding on the wire) carry no information; `None`
/// when none is left. Without a previous track (the first message, a kick or a restart in
/// between) the new track is taken whole.
fn track_measurement(
    model: &BallModel,
    previous: Option<&BallEstimate>,
    lwm: &LocalWorldModel,
) -> Option<Measured> {
    /// Below this share of what the new track holds in a direction, a direction learnt
    /// nothing new (the wire rounds covariances to a few per cent).
    const NEW_SHARE: f64 = 0.05;
    /// Variance of a direction that carries no information, m² or m²/s².
    const NO_INFORMATION_VAR: f64 = 1e6;
    let track = lwm.ball?;
    if !track
        .mean
        .iter()
        .chain(track.cov.iter())
        .all(|v| v.is_finite())
    {
        return None;
    }
    let info_new = track.cov.try_inverse()?;
    let mut info = info_new;
    let mut info_vec = info_new * track.mean;
    if let Some(prev) = previous {
        let rolled = prev.predict_to(model, track.t_s);
        // A track that jumped away from where the previous one rolled to restarted on a
        // moved ball: nothing of the previous one is in it.
        let continues = kalman::mahalanobis_sq(
            &(track.position() - rolled.position()),
            &(rolled.position_cov() + track.position_cov()),
        )
        .is_some_and(|d2| d2 <= 13.82);
        if let (true, Some(info_old)) = (continues, rolled.cov.try_inverse()) {
            info -= info_old;
            info_vec -= info_old * rolled.mean;
        }
    }
    let info = (info + info.transpose()) * 0.5;
    let eig = info.symmetric_eigen();
    let mut cov = Matrix4::zeros();
    let mut mean = Vector4::zeros();
    let mut any = false;
    for k in 0..4 {
        let v = eig.eigenvectors.column(k).into_owned();
        let held = v.dot(&(info_new * v));
        let lambda = eig.eigenvalues[k];
        // Along v: the measured coordinate and its variance.
        let (coordinate, var) = if lambda.is_finite() && lambda > NEW_SHARE * held {
            any = true;
            (v.dot(&info_vec) / lambda, 1.0 / lambda)
        } else {
            (v.dot(&track.mean), NO_INFORMATION_VAR)
        };
        mean += v * coordinate;
        cov += v * v.transpose() * var;
    }
    if !any || !mean.iter().chain(cov.iter()).all(|v| v.is_finite()) {
        return None;
    }
    let cov = (cov + cov.transpose()) * 0.5;
    Some(Measured {
        obs: FieldObservation {
            t_s: track.t_s,
            position: Vector2::new(mean.x, mean.y),
            cov: cov.fixed_view::<2, 2>(0, 0).into_owned(),
        },
        state: Some((mean, cov)),
        kick: None,
    })
}

/// The product of two independent Gaussian estimates of the same state at the same time.
fn fuse_independent(a: &BallEstimate, b: &BallEstimate) -> BallEstimate {
    // A static model has zero velocity variance; a whisker keeps S invertible.
    let r = b.cov + Matrix4::identity() * 1e-12;
    match kalman::update(
        &a.mean,
        &a.cov,
        &(b.mean - a.mean),
        &Matrix4::identity(),
        &r,
        None,
    ) {
        Ok(u) => BallEstimate {
            t_s: a.t_s,
            mean: u.mean,
            cov: u.cov,
        },
        Err(_) => *a,
    }
}
