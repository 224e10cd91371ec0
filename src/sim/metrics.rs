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
//!   while the ball is visible (as above), once that robot's GWM, the centralized filter
//!   and the robot's network-limited reference all have a ball: that robot's team ball
//!   predicted to the tick, the centralized estimate at the same instant, the reference's,
//!   and the true ball.
//! - **team-ball RMSE** / **centralized RMSE**: root mean square of the position error over
//!   all team-ball samples; **ratio** = team / centralized.
//! - **centralized with kicks**: the centralized filter also told every kick of ours as it
//!   happens (speed, direction and their σ, as the kicker reports it). The issue's
//!   centralized filter sees sightings only; a team that reports its kicks has more, so
//!   this is its ceiling.
//! - **network-limited reference**: at each robot, the centralized filter fed exactly the
//!   ball information that has reached that robot (its own sightings and kicks at once,
//!   teammates' batches and kick reports when their messages arrive;
//!   `fusion::NetworkLimitedBall`): what that filter makes of what the network delivered.
//!   Team / it measures the fusion, it / centralized with kicks measures the network.
//! - **blind**: the samples of robots that have not seen the ball themselves within their
//!   ball memory (`BrainConfig::ball_memory_s`), whose team ball is what the network
//!   brought.
//! - **team-ball NEES**: the position NEES eᵀ P⁻¹ e (2 degrees of freedom) averaged over all
//!   team-ball samples. Samples close in time (and different robots' team balls at one
//!   instant) are strongly correlated, so its χ² 95% bounds are computed for one
//!   independent sample per [`NEES_INDEPENDENT_EVERY_S`] of ball-visible time:
//!   N = visible time / that, bounds χ²₂ₙ(0.025, 0.975) / N.
//! - **pose**: every live robot's pose estimate against its true pose at each of its
//!   control ticks: position RMSE, heading RMSE, and the average NEES (3 dof).

use serde::Serialize;

/// A handover back to the previous goer within this many seconds is a flap.
pub const FLAP_WINDOW_S: f64 = 2.0;

/// Team-ball errors this far apart count as independent for the NEES bounds: several times
/// the time a ball error takes to be forgotten (the team filter's memory is a few
/// publish periods; a kick resets it).
pub const NEES_INDEPENDENT_EVERY_S: f64 = 1.0;

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
    /// The network-limited reference of this robot (`fusion::NetworkLimitedBall`), m².
    pub limited_sq_m2: f64,
    /// The robot has not seen the ball itself within its ball memory: what it knows came
    /// over the network.
    pub blind: bool,
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
    /// Σ network-limited reference, m².
    pub limited_sq_m2: f64,
}

impl ErrorSums {
    fn add(&mut self, s: &BallSample) {
        self.samples += 1;
        self.team_sq_m2 += s.team_sq_m2;
        self.central_sq_m2 += s.central_sq_m2;
        self.central_kicks_sq_m2 += s.central_kicks_sq_m2;
        self.limited_sq_m2 += s.limited_sq_m2;
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

    /// Network-limited reference RMSE, m.
    pub fn limited_rmse_m(&self) -> f64 {
        self.rmse(self.limited_sq_m2)
    }
}

/// Sums behind the world-model figures; see the module docs for the definitions.
#[derive(Debug, Clone, Default)]
pub struct FusionMetrics {
    /// Every team-ball sample.
    pub all: ErrorSums,
    /// The samples of robots that did not see the ball themselves.
    pub blind: ErrorSums,
    /// Σ position NEES of the team ball.
    pub team_nees: f64,
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
        self.team_nees += s.team_nees;
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
        self.team_nees / self.all.samples as f64
    }

    /// Average centralized NEES.
    pub fn central_nees(&self) -> f64 {
        self.central_nees / self.all.samples as f64
    }

    /// Independent samples the NEES bounds are computed for.
    pub fn nees_independent_samples(&self) -> u64 {
        (self.visible_s / NEES_INDEPENDENT_EVERY_S).floor().max(1.0) as u64
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
    fn the_team_ball_nees_bounds_are_for_one_sample_per_second_of_visible_time() {
        // 300 s of ball-visible time: 300 independent 2-dof samples. χ²₆₀₀(0.025) =
        // 534.02, χ²₆₀₀(0.975) = 669.77 (exact, by the incomplete gamma function).
        let f = FusionMetrics {
            visible_s: 300.5,
            ..FusionMetrics::default()
        };
        assert_eq!(f.nees_independent_samples(), 300);
        let (lo, hi) = f.nees_bounds();
        assert!((lo - 534.02 / 300.0).abs() < 0.001, "{lo}");
        assert!((hi - 669.77 / 300.0).abs() < 0.001, "{hi}");
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
