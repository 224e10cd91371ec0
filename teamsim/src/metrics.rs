//! What `huddle sim` measures about arbitration, sampled on the physics clock.
//!
//! Definitions (they are the report's, word for word):
//! - **ball visible**: at least one field player (a robot that competes: not the
//!   goalkeeper) detected the ball in its most recent camera frame (one frame per control
//!   tick). Only this time is judged: when nobody sees the ball nobody should go.
//! - **goer**: a field player whose latest control tick decided to go (its `Arbiter` says
//!   `going`), i.e. a robot that is driving at the ball right now.
//! - **exactly one / conflict / none**: the share of ball-visible time with one goer, with
//!   two or more, with none.
//! - **conflict length**: a run of consecutive ball-visible samples with two or more goers.
//! - **handover**: the lone goer changes from one robot to another (through any gap).
//! - **flap**: a handover back to the robot that lost the ball within the previous
//!   [`FLAP_WINDOW_S`] (A → B → A).
//!
//! And about the world models ([`FusionMetrics`]):
//! - **team-ball sample**: at every control tick of every live robot (goalkeeper included)
//!   while the ball is visible (as above), once that robot's GWM, the centralized filters
//!   and the robot's delivery reference all have a ball: that robot's team ball as it
//!   holds it at the tick (the GWM's, widened while a body closes in on it: see
//!   `WorldModelConfig::contact_horizon_s`), the references' estimates at the same instant, and the true
//!   ball.
//! - **team-ball RMSE** / **centralized RMSE**: root mean square of the position error over
//!   all team-ball samples; **ratio** = team / centralized.
//! - **centralized**: the team's own fusion (`fusion::GlobalModel`, the team's settings
//!   and rules) fed every robot's LWM of every tick at once, on the global clock: no
//!   network (`super::references`).
//! - **centralized with kicks** (cK): the same, also told for sure every kick of ours
//!   that met the ball, and none of the swings that missed. The ceiling for a team that
//!   reports its kicks.
//! - **delivery reference**: at each robot, the team's own fusion fed exactly the
//!   messages that reached that robot (its own LWM at once, teammates' when their
//!   messages arrive), each placed at its true sender time (`super::references`). Team /
//!   it measures what the team's clock estimate and commit lag cost; it / cK measures
//!   the network.
//! - **delayed-centralized**: at each robot, the team's own fusion fed its own LWMs at
//!   once and every teammate's LWM of every tick, none lost, each exactly the run's
//!   measured median one-way delay late.
//! - Every reference places the ball on the centre spot at a kick-off, as the team does.
//! - **blind**: the samples of robots that have not seen the ball themselves within their
//!   ball memory (`BrainConfig::ball_memory_s`), whose team ball is what the network
//!   brought.
//! - **team-ball NEES**: the position NEES eᵀ P⁻¹ e (2 degrees of freedom) averaged over all
//!   team-ball samples, and per band of the true ball speed: **still** (below
//!   [`STILL_BELOW_MPS`]), **rolling**, **fast** (above [`FAST_ABOVE_MPS`]). Samples close in
//!   time (and different robots' team balls at one instant) are strongly correlated, so
//!   each χ² 95% bound is computed for the number of independent samples the series is
//!   worth by the method of batch means ([`NEES_BATCHES`] batches of consecutive samples,
//!   `fusion::consistency::batch_means_effective_samples`): bounds χ²₂ₙ(0.025, 0.975) / n.
//!   **Above 99.9%**: the share of samples whose NEES exceeds χ²₂'s 99.9% point (13.8),
//!   0.1% for an honest filter. **Median**: 1.386 for an honest filter (0.693 of the
//!   mean). **Above 99.9% at mean 2**: the same share had the group's covariances all
//!   been scaled by the one factor that puts its mean at 2; 0.1% for errors of a
//!   Gaussian's shape at any scale, so a figure above the tail target says that no
//!   single scale (of q, R or a widening) meets both targets.
//! - **NEES by cause**: each team-ball sample is put down to the latest event that changed
//!   the true ball's motion other than friction within [`CAUSE_WINDOW_S`] before it
//!   ([`BallEvent`]: a kick that met the ball, a bounce off the boards, a push by one of our
//!   robots or by an opponent; none within the window: **quiet**), so the samples above
//!   the 99.9% point can be counted per cause.
//! - **pose**: every live robot's pose estimate against its true pose at each of its
//!   control ticks: position RMSE, heading RMSE, and the average NEES (3 dof).

use serde::Serialize;

/// A handover back to the previous goer within this many seconds is a flap.
pub const FLAP_WINDOW_S: f64 = 2.0;

/// A ball slower than this is still, m/s.
pub const STILL_BELOW_MPS: f64 = 0.1;
/// A ball faster than this is fast, m/s (between: rolling).
pub const FAST_ABOVE_MPS: f64 = 1.5;
/// Batches the NEES series is cut into for its effective sample count.
pub const NEES_BATCHES: usize = 50;
/// A team-ball sample is put down to the latest ball event at most this long before it, s.
pub const CAUSE_WINDOW_S: f64 = 1.0;

/// What changed the true ball's motion other than friction (the simulator's truth, for
/// the NEES tail's causes; robots never see it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BallEvent {
    /// No event within [`CAUSE_WINDOW_S`].
    Quiet,
    /// One of our kicks met the ball.
    Kick,
    /// The ball bounced off the boards.
    Bounce,
    /// One of our robots pushed it (walked into it).
    OurPush,
    /// An opponent pushed it.
    OpponentPush,
}

impl BallEvent {
    /// Every cause, in the report's order.
    pub const ALL: [BallEvent; 5] = [
        BallEvent::Quiet,
        BallEvent::Kick,
        BallEvent::Bounce,
        BallEvent::OurPush,
        BallEvent::OpponentPush,
    ];

    fn index(self) -> usize {
        self as usize
    }
}

/// The team-ball NEES of the samples put down to one cause.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CauseSums {
    /// Samples.
    pub samples: u64,
    /// Σ NEES.
    pub nees_sum: f64,
    /// Samples above χ²₂'s 99.9% point.
    pub above_999: u64,
    /// … of those, how long after the event: within 0.1 s, 0.1–0.3 s, later.
    pub above_999_after: [u64; 3],
    /// … of those, at the robot whose kick or push it was.
    pub above_999_at_actor: u64,
}

/// One team-ball sample (see the module docs): squared position errors against the true
/// ball and position NEES.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BallSample {
    /// The robot's team ball, m².
    pub team_sq_m2: f64,
    /// Its NEES.
    pub team_nees: f64,
    /// The centralized filter (no network), m².
    pub central_sq_m2: f64,
    /// Its NEES.
    pub central_nees: f64,
    /// The centralized filter that is also told every kick as it happens, m².
    pub central_kicks_sq_m2: f64,
    /// The delivery reference of this robot, m².
    pub delivery_sq_m2: f64,
    /// The true ball's speed, m/s.
    pub speed_mps: f64,
    /// The robot has not seen the ball itself within its ball memory: what it knows came
    /// over the network.
    pub blind: bool,
    /// The latest ball event within [`CAUSE_WINDOW_S`].
    pub cause: BallEvent,
    /// How long before the sample it happened, s.
    pub cause_age_s: f64,
    /// The sample is at the robot whose kick or push it was.
    pub at_actor: bool,
}

/// Squared-error sums of one group of team-ball samples.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ErrorSums {
    /// Samples.
    pub samples: u64,
    /// Σ team ball, m².
    pub team_sq_m2: f64,
    /// Σ centralized, m².
    pub central_sq_m2: f64,
    /// Σ centralized with kicks, m².
    pub central_kicks_sq_m2: f64,
    /// Σ delivery reference, m².
    pub delivery_sq_m2: f64,
}

impl ErrorSums {
    fn add(&mut self, s: &BallSample) {
        self.samples += 1;
        self.team_sq_m2 += s.team_sq_m2;
        self.central_sq_m2 += s.central_sq_m2;
        self.central_kicks_sq_m2 += s.central_kicks_sq_m2;
        self.delivery_sq_m2 += s.delivery_sq_m2;
    }

    fn rmse(&self, sum_sq_m2: f64) -> f64 {
        (sum_sq_m2 / self.samples as f64).sqrt()
    }

    /// Team-ball RMSE, m (NaN without samples).
    pub fn team_rmse_m(&self) -> f64 {
        self.rmse(self.team_sq_m2)
    }

    /// Centralized RMSE, m.
    pub fn central_rmse_m(&self) -> f64 {
        self.rmse(self.central_sq_m2)
    }

    /// Centralized-with-kicks RMSE, m.
    pub fn central_kicks_rmse_m(&self) -> f64 {
        self.rmse(self.central_kicks_sq_m2)
    }

    /// Delivery reference RMSE, m.
    pub fn delivery_rmse_m(&self) -> f64 {
        self.rmse(self.delivery_sq_m2)
    }
}

/// The team-ball NEES of one group of samples, with the series for its effective count.
#[derive(Debug, Clone, Default)]
pub struct NeesSeries {
    /// The NEES of each sample, in time order.
    pub series: Vec<f64>,
    /// Samples above χ²₂'s 99.9% point.
    pub above_999: u64,
}

impl NeesSeries {
    fn add(&mut self, nees: f64) {
        if !nees.is_finite() {
            return;
        }
        self.series.push(nees);
        if nees > fusion::consistency::CHI2_2DOF_999 {
            self.above_999 += 1;
        }
    }

    /// Samples.
    pub fn samples(&self) -> usize {
        self.series.len()
    }

    /// Average NEES (NaN without samples).
    pub fn mean(&self) -> f64 {
        self.series.iter().sum::<f64>() / self.series.len() as f64
    }

    /// Share of samples above χ²₂'s 99.9% point, percent.
    pub fn above_999_pct(&self) -> f64 {
        100.0 * self.above_999 as f64 / self.series.len().max(1) as f64
    }

    /// Median NEES: 2 ln 2 ≈ 1.386 (0.693 of the mean) for an honest filter.
    pub fn median(&self) -> f64 {
        let mut sorted = self.series.clone();
        sorted.sort_by(f64::total_cmp);
        match sorted.len() {
            0 => f64::NAN,
            n if n % 2 == 1 => sorted[n / 2],
            n => 0.5 * (sorted[n / 2 - 1] + sorted[n / 2]),
        }
    }

    /// The share above χ²₂'s 99.9% point, percent, had every covariance of the series been
    /// scaled by the one factor that puts its mean NEES at 2 (NEES scales inversely with
    /// the covariance): 0.1 for errors of an honest filter's shape, whatever its scale.
    /// Above the tail target, no single rescaling (of q, R or a widening) can meet both
    /// the mean and the tail target: the errors are heavier-tailed than the Gaussian the
    /// covariance describes (mostly small, now and then a jump nobody has told of yet).
    pub fn above_999_pct_at_mean_2(&self) -> f64 {
        let mean = self.mean();
        if mean.is_nan() || mean <= 0.0 {
            return f64::NAN;
        }
        let threshold = fusion::consistency::CHI2_2DOF_999 * mean / 2.0;
        let above = self.series.iter().filter(|&&x| x > threshold).count();
        100.0 * above as f64 / self.series.len() as f64
    }

    /// Independent samples the series is worth (batch means over [`NEES_BATCHES`]
    /// batches); for a series too short to cut, `fallback_per_sample` of its length.
    pub fn effective_samples(&self, fallback_per_sample: f64) -> u64 {
        let batch = self.series.len() / NEES_BATCHES;
        fusion::consistency::batch_means_effective_samples(&self.series, batch)
            .unwrap_or(self.series.len() as f64 * fallback_per_sample)
            .floor()
            .max(1.0) as u64
    }
}

/// Sums behind the world-model figures; see the module docs for the definitions.
#[derive(Debug, Clone, Default)]
pub struct FusionMetrics {
    /// Every team-ball sample.
    pub all: ErrorSums,
    /// The samples of robots that did not see the ball themselves.
    pub blind: ErrorSums,
    /// The team ball's NEES, all samples.
    pub nees: NeesSeries,
    /// … per true ball speed: still, rolling, fast.
    pub nees_bands: [NeesSeries; 3],
    /// … per cause ([`BallEvent::ALL`]'s order).
    pub by_cause: [CauseSums; 5],
    /// The samples: the robot (index), the instant and the true ball there, global
    /// `(t, x, y)`, with the team ball's squared error: for the delayed-centralized
    /// reference.
    pub instants: Vec<(usize, (f64, f64, f64), f64)>,
    /// Σ position NEES of the centralized filter.
    pub central_nees: f64,
    /// Ball-visible seconds (for the NEES bounds).
    pub visible_s: f64,
    /// Pose samples.
    pub pose_samples: u64,
    /// Σ squared pose position error, m².
    pub pose_sq_m2: f64,
    /// Σ squared heading error, rad².
    pub heading_sq_rad2: f64,
    /// Σ pose NEES (3 dof).
    pub pose_nees: f64,
}

impl FusionMetrics {
    /// One team-ball sample.
    pub fn ball(&mut self, s: &BallSample) {
        self.all.add(s);
        if s.blind {
            self.blind.add(s);
        }
        self.nees.add(s.team_nees);
        let band = if s.speed_mps < STILL_BELOW_MPS {
            0
        } else if s.speed_mps <= FAST_ABOVE_MPS {
            1
        } else {
            2
        };
        self.nees_bands[band].add(s.team_nees);
        if s.team_nees.is_finite() {
            let c = &mut self.by_cause[s.cause.index()];
            c.samples += 1;
            c.nees_sum += s.team_nees;
            if s.team_nees > fusion::consistency::CHI2_2DOF_999 {
                c.above_999 += 1;
                let k = if s.cause_age_s < 0.1 {
                    0
                } else if s.cause_age_s < 0.3 {
                    1
                } else {
                    2
                };
                c.above_999_after[k] += 1;
                c.above_999_at_actor += u64::from(s.at_actor);
            }
        }
        self.central_nees += s.central_nees;
    }

    /// One pose sample.
    pub fn pose(&mut self, sq_m2: f64, heading_sq_rad2: f64, nees: f64) {
        self.pose_samples += 1;
        self.pose_sq_m2 += sq_m2;
        self.heading_sq_rad2 += heading_sq_rad2;
        self.pose_nees += nees;
    }

    /// Team-ball samples.
    pub fn samples(&self) -> u64 {
        self.all.samples
    }

    /// Average team-ball NEES.
    pub fn team_nees(&self) -> f64 {
        self.nees.mean()
    }

    /// Average centralized NEES.
    pub fn central_nees(&self) -> f64 {
        self.central_nees / self.all.samples as f64
    }

    /// Independent samples the whole NEES series is worth (batch means).
    pub fn nees_independent_samples(&self) -> u64 {
        self.nees.effective_samples(1.0)
    }

    /// Independent samples of a band: its own batch means, or for a band too short to
    /// cut, its share of the whole series' count.
    pub fn band_independent_samples(&self, band: usize) -> u64 {
        let per_sample = self.nees_independent_samples() as f64 / self.nees.samples().max(1) as f64;
        self.nees_bands[band].effective_samples(per_sample)
    }

    /// χ² 95% bounds of the average 2-dof NEES over [`Self::nees_independent_samples`]
    /// (`fusion::consistency::nees_bounds`, Wilson–Hilferty).
    pub fn nees_bounds(&self) -> (f64, f64) {
        fusion::consistency::nees_bounds(2, self.nees_independent_samples())
    }

    /// Pose position RMSE, m.
    pub fn pose_rmse_m(&self) -> f64 {
        (self.pose_sq_m2 / self.pose_samples as f64).sqrt()
    }

    /// Heading RMSE, rad.
    pub fn heading_rmse_rad(&self) -> f64 {
        (self.heading_sq_rad2 / self.pose_samples as f64).sqrt()
    }

    /// Average pose NEES (3 dof).
    pub fn pose_nees(&self) -> f64 {
        self.pose_nees / self.pose_samples as f64
    }
}

/// Accumulates samples; see the module docs for the definitions.
#[derive(Debug, Clone, Default)]
pub struct Metrics {
    /// Seconds of ball-visible time.
    pub visible_s: f64,
    /// Seconds of ball-visible time with exactly one goer.
    pub one_s: f64,
    /// Seconds of ball-visible time with two or more goers.
    pub conflict_s: f64,
    /// Seconds of ball-visible time with no goer.
    pub none_s: f64,
    /// Longest conflict, seconds.
    pub longest_conflict_s: f64,
    /// When the longest conflict started, seconds of simulated time.
    pub longest_conflict_at_s: f64,
    /// Number of handovers.
    pub handovers: u64,
    /// Number of flaps.
    pub flaps: u64,
    /// The oldest a live teammate's claim was when a live robot decided on it, seconds:
    /// the longest the network kept one robot's claims from another.
    pub longest_claim_gap_s: f64,
    conflict_run_s: f64,
    conflict_start_s: f64,
    lone_goer: Option<u8>,
    /// The goer before the last handover and when that handover happened.
    previous: Option<(u8, f64)>,
}

impl Metrics {
    /// Record `dt_s` seconds ending at `t_s` during which the ball was (not) visible and
    /// `goers` were going.
    pub fn sample(&mut self, t_s: f64, dt_s: f64, ball_visible: bool, goers: &[u8]) {
        if !ball_visible {
            self.end_conflict();
            return;
        }
        self.visible_s += dt_s;
        match goers.len() {
            0 => {
                self.none_s += dt_s;
                self.end_conflict();
            }
            1 => {
                self.one_s += dt_s;
                self.end_conflict();
                let g = goers[0];
                if let Some(old) = self.lone_goer.filter(|&old| old != g) {
                    self.handovers += 1;
                    if matches!(self.previous, Some((p, at)) if p == g && t_s - at <= FLAP_WINDOW_S)
                    {
                        self.flaps += 1;
                    }
                    self.previous = Some((old, t_s));
                }
                self.lone_goer = Some(g);
            }
            _ => {
                self.conflict_s += dt_s;
                if self.conflict_run_s == 0.0 {
                    self.conflict_start_s = t_s - dt_s;
                }
                self.conflict_run_s += dt_s;
                if self.conflict_run_s > self.longest_conflict_s {
                    self.longest_conflict_s = self.conflict_run_s;
                    self.longest_conflict_at_s = self.conflict_start_s;
                }
            }
        }
    }

    /// A live robot decided on a live teammate's claim `age_s` old.
    pub fn claim_age(&mut self, age_s: f64) {
        self.longest_claim_gap_s = self.longest_claim_gap_s.max(age_s);
    }

    fn end_conflict(&mut self) {
        self.conflict_run_s = 0.0;
    }

    /// Share of ball-visible time with exactly one goer, percent (100 with no visible time).
    pub fn exactly_one_pct(&self) -> f64 {
        pct(self.one_s, self.visible_s, 100.0)
    }

    /// Share of ball-visible time with two or more goers, percent.
    pub fn conflict_pct(&self) -> f64 {
        pct(self.conflict_s, self.visible_s, 0.0)
    }

    /// Share of ball-visible time with no goer, percent.
    pub fn no_goer_pct(&self) -> f64 {
        pct(self.none_s, self.visible_s, 0.0)
    }

    /// Handovers per minute of ball-visible time.
    pub fn handovers_per_min(&self) -> f64 {
        per_min(self.handovers, self.visible_s)
    }

    /// Flaps per minute of ball-visible time.
    pub fn flaps_per_min(&self) -> f64 {
        per_min(self.flaps, self.visible_s)
    }
}

fn pct(part: f64, whole: f64, empty: f64) -> f64 {
    if whole > 0.0 {
        100.0 * part / whole
    } else {
        empty
    }
}

fn per_min(n: u64, visible_s: f64) -> f64 {
    if visible_s > 0.0 {
        n as f64 * 60.0 / visible_s
    } else {
        0.0
    }
}

/// Which robots went when, for the SVG timeline: closed intervals of going per robot and
/// of ball visibility, seconds.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Timeline {
    /// Per robot (index = id − 1): intervals during which it was going.
    pub going: Vec<Vec<(f64, f64)>>,
    /// Intervals during which the ball was visible.
    pub visible: Vec<(f64, f64)>,
    open_going: Vec<Option<f64>>,
    open_visible: Option<f64>,
}

impl Timeline {
    /// An empty timeline for `robots` robots.
    pub fn new(robots: usize) -> Self {
        Self {
            going: vec![Vec::new(); robots],
            open_going: vec![None; robots],
            ..Default::default()
        }
    }

    /// Record the state at `t_s`.
    pub fn sample(&mut self, t_s: f64, ball_visible: bool, going: impl Iterator<Item = bool>) {
        for (i, g) in going.enumerate() {
            toggle(&mut self.open_going[i], &mut self.going[i], t_s, g);
        }
        toggle(&mut self.open_visible, &mut self.visible, t_s, ball_visible);
    }

    /// Close every open interval at `t_s`.
    pub fn finish(&mut self, t_s: f64) {
        for i in 0..self.going.len() {
            toggle(&mut self.open_going[i], &mut self.going[i], t_s, false);
        }
        toggle(&mut self.open_visible, &mut self.visible, t_s, false);
    }
}

fn toggle(open: &mut Option<f64>, done: &mut Vec<(f64, f64)>, t_s: f64, on: bool) {
    match (*open, on) {
        (None, true) => *open = Some(t_s),
        (Some(start), false) => {
            done.push((start, t_s));
            *open = None;
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shares_conflicts_handovers_and_flaps_follow_the_definitions() {
        let mut m = Metrics::default();
        let dt = 0.01;
        let mut t = 0.0;
        let mut run = |m: &mut Metrics, n: usize, visible: bool, goers: &[u8]| {
            for _ in 0..n {
                t += dt;
                m.sample(t, dt, visible, goers);
            }
        };
        run(&mut m, 100, true, &[1]); // 1 s robot 1
        run(&mut m, 5, true, &[1, 2]); // 50 ms conflict
        run(&mut m, 100, true, &[2]); // handover 1 → 2
        run(&mut m, 50, false, &[]); // not judged
        run(&mut m, 10, true, &[]); // 100 ms with nobody
        run(&mut m, 3, true, &[1, 2]); // 30 ms conflict
        run(&mut m, 82, true, &[1]); // back to 1 within 2 s: a flap
        assert!((m.visible_s - 3.0).abs() < 1e-9, "visible {}", m.visible_s);
        assert!((m.conflict_s - 0.08).abs() < 1e-9);
        assert!((m.none_s - 0.1).abs() < 1e-9);
        assert!((m.longest_conflict_s - 0.05).abs() < 1e-9);
        assert_eq!((m.handovers, m.flaps), (2, 1));
        assert!((m.exactly_one_pct() + m.conflict_pct() + m.no_goer_pct() - 100.0).abs() < 1e-9);
        assert!(
            (m.handovers_per_min() - 40.0).abs() < 1e-9,
            "2 handovers in 3 s"
        );
    }

    #[test]
    fn the_team_ball_nees_bounds_count_a_correlated_series_by_its_batch_means() {
        // 600 independent NEES values, each held for 25 robot ticks (a team ball that
        // changes slowly): 15,000 samples worth about 600, and the bounds are for those.
        let mut f = FusionMetrics::default();
        let mut state = 7u64;
        for _ in 0..600 {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1);
            let u = ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64;
            let nees = -2.0 * u.ln(); // χ²₂
            for _ in 0..25 {
                f.nees.add(nees);
            }
        }
        let n = f.nees_independent_samples();
        assert!(
            (300..=1200).contains(&n),
            "15,000 samples of 600 values: worth {n} independent ones"
        );
        assert_eq!(f.nees_bounds(), fusion::consistency::nees_bounds(2, n));
        assert!(
            f.nees.above_999_pct() < 1.0,
            "χ²₂ values rarely pass the 99.9% point: {}%",
            f.nees.above_999_pct()
        );
    }

    #[test]
    fn a_scale_mixture_cannot_be_rescaled_into_the_mean_and_the_tail_targets() {
        use rand::{RngExt, SeedableRng};
        // χ²₂ values, drawn as −2 ln u (u in (0, 1]).
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let mut chi2 = move || -2.0 * (1.0 - rng.random::<f64>()).ln();
        // An honest filter's errors under a covariance twice too wide: mean 1, nothing
        // in the tail, and scaled back to mean 2, the honest 0.1% above the 99.9% point.
        let mut wide = NeesSeries::default();
        for _ in 0..100_000 {
            wide.add(0.5 * chi2());
        }
        assert!((wide.mean() - 1.0).abs() < 0.02, "mean {}", wide.mean());
        assert!(
            (wide.median() / wide.mean() - std::f64::consts::LN_2).abs() < 0.02,
            "median {} of mean {}: a χ² shape",
            wide.median(),
            wide.mean()
        );
        let rescaled = wide.above_999_pct_at_mean_2();
        assert!(
            (0.06..=0.14).contains(&rescaled),
            "{rescaled}% above at mean 2"
        );
        // A team ball widened for a jump that mostly did not come: 95% of samples three
        // times too wide, 5% (a jump came) a little overconfident. Underconfident on
        // average, hardly any tail, yet scaled to mean 2 about 1% of samples pass the
        // 99.9% point: the shape, not the scale, is wrong.
        let mut mixture = NeesSeries::default();
        for k in 0..100_000 {
            let scale = if k % 20 == 0 { 1.5 } else { 0.3 };
            mixture.add(scale * chi2());
        }
        assert!(
            mixture.mean() < 0.8 && mixture.above_999_pct() < 0.3,
            "mean {}, {}% above",
            mixture.mean(),
            mixture.above_999_pct()
        );
        assert!(
            mixture.median() / mixture.mean() < 0.65,
            "median {} of mean {}: heavier-tailed than χ²",
            mixture.median(),
            mixture.mean()
        );
        let rescaled = mixture.above_999_pct_at_mean_2();
        assert!(
            rescaled > 0.5,
            "{rescaled}% above at mean 2: no single scale meets both targets"
        );
    }

    #[test]
    fn the_timeline_closes_intervals() {
        let mut tl = Timeline::new(2);
        tl.sample(0.0, true, [true, false].into_iter());
        tl.sample(1.0, true, [false, true].into_iter());
        tl.finish(2.0);
        assert_eq!(tl.going[0], vec![(0.0, 1.0)]);
        assert_eq!(tl.going[1], vec![(1.0, 2.0)]);
        assert_eq!(tl.visible, vec![(0.0, 2.0)]);
    }
}
