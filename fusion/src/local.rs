//! The local world model (LWM): one robot's pose and ball, from its own odometry and
//! sightings only, and the message it publishes as `*.var.world.local`.

use crate::ball::{
    field_observation_shared, BallEstimate, BallFilter, BallFilterConfig, BallSighting, BallUpdate,
    FieldObservation, Kick,
};
use crate::confidence::{pose_confidence, position_confidence};
use crate::kalman::UpdateError;
use crate::pose::{
    LandmarkSighting, Odometry, PoseEstimate, PoseFilter, PoseNoise, RangeBearingSighting,
    Relocalise,
};
use nalgebra::{Matrix2, Vector2};

/// What a robot publishes about itself: a snapshot of its LWM at `t_s`, plus the ball
/// information it gathered since its previous message (see the crate docs on fusion).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalWorldModel {
    /// When the snapshot holds. On the sender, its clock; after
    /// [`LocalWorldModel::from_bytes`], the receiver's (reception time minus age).
    pub t_s: f64,
    /// Message counter, +1 per publish (wrapping), so that a re-sent or duplicated message
    /// is not fused twice.
    pub seq: u16,
    /// The robot's pose and covariance.
    pub pose: PoseEstimate,
    /// The robot's own ball track at `t_s`, if it has one.
    pub ball: Option<BallEstimate>,
    /// Time since the robot last saw the ball (∞ if never).
    pub ball_seen_age_s: f64,
    /// Self-localisation confidence.
    pub slc: f64,
    /// Local ball confidence.
    pub lbc: f64,
    /// The robot's ball sightings since its previous message, combined into one field-frame
    /// position measurement (information-weighted), valid at `observation.t_s ≤ t_s`.
    pub observation: Option<FieldObservation>,
    /// The batches of the two previous messages (seq − 1, seq − 2) again, so that a lost
    /// message loses nothing if one of the next two arrives. A receiver takes each batch
    /// once, by sequence number.
    pub earlier: [Option<FieldObservation>; 2],
    /// The robot's latest kick, repeated in every message for [`KICK_REPORTED_FOR_S`]
    /// after it (so a lost message does not lose it).
    pub kick: Option<KickReport>,
}

/// How long after a kick a robot's messages carry it.
pub const KICK_REPORTED_FOR_S: f64 = 0.15;

/// A kick as an LWM carries it: the kick and its number, so that a receiver applies each
/// kick once however many messages repeat it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KickReport {
    /// The robot's kick counter, modulo 4 (kicks are seconds apart, a report lasts
    /// [`KICK_REPORTED_FOR_S`]: two bits tell consecutive kicks apart).
    pub number: u8,
    /// The kick, its time on the message's clock.
    pub kick: Kick,
}

/// What a receiver has taken from one robot's messages, so that each batch and each kick
/// in them is taken once however often messages repeat them (the GWM keeps one per
/// teammate; so does anything else that consumes LWMs, such as `huddle sim`'s reference).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Heard {
    /// Sequence number and time of the last message taken.
    last: Option<(u16, f64)>,
    /// Number and time of the last kick taken.
    kick: Option<(u8, f64)>,
}

/// Two reports of a kick with the same number this close in time (each placed by its own
/// message's age, so they differ by the network's jitter) are one kick: a report lasts
/// [`KICK_REPORTED_FOR_S`], and a robot's kicks with one number are four kicks apart.
const KICK_SAME_WITHIN_S: f64 = 0.3;

impl Heard {
    /// Takes `lwm` if it is news: `None` for a duplicate or an older message; otherwise the
    /// repeated batches of messages missed since the last one taken, oldest first (the
    /// message's own batch is [`LocalWorldModel::observation`]). A robot silent for
    /// `stale_after_s` may have restarted its counter: its next message is news, and its
    /// repeats are not relied on.
    pub fn take(
        &mut self,
        lwm: &LocalWorldModel,
        stale_after_s: f64,
    ) -> Option<[Option<FieldObservation>; 2]> {
        let last_seq = match self.last {
            Some((seq, t_s)) if lwm.t_s - t_s <= stale_after_s => {
                if (lwm.seq.wrapping_sub(seq) as i16) <= 0 {
                    return None;
                }
                Some(seq)
            }
            _ => None,
        };
        self.last = Some((lwm.seq, lwm.t_s));
        // Oldest first: earlier[1] is the batch of message seq − 2.
        Some(std::array::from_fn(|i| {
            let k = 1 - i;
            let batch_seq = lwm.seq.wrapping_sub(k as u16 + 1);
            let missed = last_seq.is_some_and(|last| (batch_seq.wrapping_sub(last) as i16) > 0);
            lwm.earlier[k].filter(|_| missed)
        }))
    }

    /// The kick `lwm` reports, if it was not taken before (it is taken now).
    pub fn kick(&mut self, lwm: &LocalWorldModel) -> Option<Kick> {
        let report = lwm.kick?;
        let seen = self.kick.is_some_and(|(number, t_s)| {
            number == report.number && (report.kick.t_s - t_s).abs() < KICK_SAME_WITHIN_S
        });
        if seen {
            return None;
        }
        self.take_kick(&report);
        Some(report.kick)
    }

    /// Marks a kick as taken without a message's say (a track started from the kicker's
    /// own ball, which already followed it).
    pub fn take_kick(&mut self, report: &KickReport) {
        self.kick = Some((report.number, report.kick.t_s));
    }
}

/// Settings of a [`LocalModel`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LocalConfig {
    /// Q and R of the pose EKF.
    pub pose_noise: PoseNoise,
    /// Gate on landmark sightings (χ², 2 dof); `None` for no gate.
    pub pose_gate_chi2: Option<f64>,
    /// How the gated pose filter finds itself again when lost (`None`: never).
    pub pose_relocalise: Option<Relocalise>,
    /// The ball filter.
    pub ball: BallFilterConfig,
}

/// Sums of the sightings since the last publish, in information form.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Accumulator {
    info: Matrix2<f64>,
    info_vec: Vector2<f64>,
    weight_time_s: f64,
    weight: f64,
}

impl Accumulator {
    const EMPTY: Accumulator = Accumulator {
        info: Matrix2::new(0.0, 0.0, 0.0, 0.0),
        info_vec: Vector2::new(0.0, 0.0),
        weight_time_s: 0.0,
        weight: 0.0,
    };

    fn add(&mut self, obs: &FieldObservation) {
        if let Some(inv) = obs.cov.try_inverse() {
            self.info += inv;
            self.info_vec += inv * obs.position;
            // The batch is stamped at the information-weighted mean time; over one publish
            // period a ball's path is close to straight, so this is where the combined
            // position belongs.
            let w = inv.trace();
            self.weight_time_s += w * obs.t_s;
            self.weight += w;
        }
    }

    fn take(&mut self) -> Option<FieldObservation> {
        let acc = std::mem::replace(self, Accumulator::EMPTY);
        if acc.weight <= 0.0 {
            return None;
        }
        let cov = acc.info.try_inverse()?;
        Some(FieldObservation {
            t_s: acc.weight_time_s / acc.weight,
            position: cov * acc.info_vec,
            cov: (cov + cov.transpose()) * 0.5,
        })
    }
}

/// One robot's running LWM: the pose EKF, the ball EKF, and the batch of ball information
/// waiting to be published. Feed it in time order.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalModel {
    pose: PoseFilter,
    ball: BallFilter,
    pending: Accumulator,
    /// The batches of the last two messages, newest first.
    sent: [Option<FieldObservation>; 2],
    seq: u16,
    last_seen_t_s: Option<f64>,
    kicks: u8,
    last_kick: Option<KickReport>,
}

impl LocalModel {
    /// An LWM starting at `initial_pose`, with no ball.
    pub fn new(config: LocalConfig, initial_pose: PoseEstimate) -> Self {
        LocalModel {
            pose: PoseFilter::new(initial_pose, config.pose_noise, config.pose_gate_chi2)
                .with_relocalise(config.pose_relocalise),
            ball: BallFilter::new(config.ball),
            pending: Accumulator::EMPTY,
            sent: [None; 2],
            seq: 0,
            last_seen_t_s: None,
            kicks: 0,
            last_kick: None,
        }
    }

    /// One odometry event.
    pub fn odometry(&mut self, odo: &Odometry) {
        self.pose.odometry(odo);
    }

    /// A landmark sighting in robot coordinates; its Mahalanobis² if applied.
    pub fn landmark(&mut self, sighting: &LandmarkSighting) -> Result<f64, UpdateError> {
        self.pose.landmark(sighting)
    }

    /// A range/bearing landmark sighting; its Mahalanobis² if applied.
    pub fn range_bearing(&mut self, sighting: &RangeBearingSighting) -> Result<f64, UpdateError> {
        self.pose.range_bearing(sighting)
    }

    /// A ball sighting in robot coordinates at `t_s`, made from the current pose estimate.
    pub fn ball_sighting(&mut self, t_s: f64, sighting: &BallSighting) -> BallUpdate {
        let obs = self.field_observation(t_s, sighting);
        let result = self.ball.observe(&obs);
        match result {
            BallUpdate::Initialised | BallUpdate::Updated(_) => self.pending.add(&obs),
            // The track restarted on a ball that moved: what was batched describes where
            // it no longer is.
            BallUpdate::Restarted => {
                self.pending = Accumulator::EMPTY;
                self.pending.add(&obs);
            }
            BallUpdate::Outlier(_) | BallUpdate::Rejected(_) => {}
        }
        if !matches!(result, BallUpdate::Rejected(_)) {
            self.last_seen_t_s = Some(t_s);
        }
        result
    }

    /// The robot kicked the ball: its own ball track follows the kick at once, and its next
    /// messages tell the team. `kick.direction_rad` is in the field frame, and its σ must
    /// cover everything the robot does not know about it: a robot whose foot kicks along
    /// its body adds its heading's variance (the pose's θθ entry); one that aims in the
    /// field frame, as `huddle sim`'s robots do, does not. An invalid kick (non-finite, σ
    /// not positive) is ignored.
    pub fn kick(&mut self, kick: &Kick) {
        if !kick.is_valid() {
            return;
        }
        self.ball.kick(kick);
        self.kicks = self.kicks.wrapping_add(1) % 4;
        self.last_kick = Some(KickReport {
            number: self.kicks,
            kick: *kick,
        });
    }

    /// A ball sighting at `t_s` as the field-frame observation this robot makes of it: from
    /// the current pose estimate, its uncertainty shared as the ball filter is set to.
    pub fn field_observation(&self, t_s: f64, sighting: &BallSighting) -> FieldObservation {
        field_observation_shared(
            t_s,
            &self.pose.estimate,
            sighting,
            self.ball.config.pose_error_sharing,
        )
    }

    /// The pose filter itself, e.g. to set Q for an odometry event of a known size or R
    /// for one sighting before applying it.
    pub fn pose_filter_mut(&mut self) -> &mut PoseFilter {
        &mut self.pose
    }

    /// Drops the ball track and whatever ball information waits to be published: the ball
    /// was put somewhere else by hand (a referee's kick-off, a ball out of play).
    pub fn forget_ball(&mut self) {
        self.ball = BallFilter::new(self.ball.config);
        self.pending = Accumulator::EMPTY;
        self.sent = [None; 2];
        self.last_seen_t_s = None;
        self.last_kick = None;
    }

    /// The current pose estimate.
    pub fn pose(&self) -> &PoseEstimate {
        &self.pose.estimate
    }

    /// Replaces the pose estimate (e.g. after a global relocalisation).
    pub fn set_pose(&mut self, pose: PoseEstimate) {
        self.pose.estimate = pose;
    }

    /// The robot's own ball predicted to `t_s`.
    pub fn ball_at(&self, t_s: f64) -> Option<BallEstimate> {
        self.ball.estimate_at(t_s)
    }

    /// The LWM at `t_s` without consuming the pending ball information.
    pub fn snapshot(&self, t_s: f64) -> LocalWorldModel {
        let ball = self.ball_at(t_s);
        LocalWorldModel {
            t_s,
            seq: self.seq,
            pose: self.pose.estimate,
            ball,
            ball_seen_age_s: self
                .last_seen_t_s
                .map_or(f64::INFINITY, |t| (t_s - t).max(0.0)),
            slc: pose_confidence(&self.pose.estimate.cov),
            lbc: ball.map_or(0.0, |b| position_confidence(&b.position_cov())),
            observation: None,
            earlier: [None; 2],
            kick: self
                .last_kick
                .filter(|k| (0.0..=KICK_REPORTED_FOR_S).contains(&(t_s - k.kick.t_s))),
        }
    }

    /// The message to publish at `t_s`: the snapshot plus every ball sighting batched since
    /// the previous publish, which this hands over (so it is published exactly once).
    pub fn publish(&mut self, t_s: f64) -> LocalWorldModel {
        self.seq = self.seq.wrapping_add(1);
        let mut lwm = self.snapshot(t_s);
        lwm.observation = self.pending.take();
        lwm.earlier = self.sent;
        self.sent = [lwm.observation, self.sent[0]];
        lwm
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn each_batch_and_kick_is_taken_once_however_often_repeated() {
        // A robot publishes four messages, each with a sighting; the receiver gets the
        // first and the fourth (two lost), then the fourth again (a duplicate).
        let start = PoseEstimate::new(0.0, -0.2, 0.0, Vector3::new(1e-4, 1e-4, 1e-5));
        let mut sender = LocalModel::new(LocalConfig::default(), start);
        let seen = BallSighting {
            local: Vector2::new(0.0, 0.2),
            cov: Matrix2::identity() * 1e-3,
        };
        let mut msgs = Vec::new();
        for k in 0..4 {
            let t_s = 0.04 * k as f64;
            sender.ball_sighting(t_s, &seen);
            if k == 2 {
                sender.kick(&Kick {
                    t_s,
                    speed_mps: 2.0,
                    direction_rad: 0.0,
                    speed_sigma_mps: 0.1,
                    direction_sigma_rad: 0.05,
                    contact_prob: 1.0,
                });
            }
            msgs.push(sender.publish(t_s + 0.01));
        }
        let mut heard = Heard::default();
        let first = heard
            .take(&msgs[0], 1.0)
            .expect("the first message is news");
        assert_eq!(first, [None, None], "nothing before the first to recover");
        assert_eq!(heard.kick(&msgs[0]), None);
        let fourth = heard.take(&msgs[3], 1.0).expect("news");
        assert_eq!(
            fourth,
            [msgs[1].observation, msgs[2].observation],
            "the two lost batches, oldest first"
        );
        assert!(heard.kick(&msgs[3]).is_some(), "the kick, first time");
        assert_eq!(heard.take(&msgs[3], 1.0), None, "a duplicate");
        assert_eq!(heard.take(&msgs[1], 1.0), None, "an older message");
        assert_eq!(heard.kick(&msgs[3]), None, "the same kick again");
        // After a long silence the counter may have restarted: news again, repeats unused.
        let mut restarted = msgs[1];
        restarted.t_s += 5.0;
        assert_eq!(heard.take(&restarted, 1.0), Some([None, None]));
    }
}
