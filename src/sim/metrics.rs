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

use serde::Serialize;

/// A handover back to the previous goer within this many seconds is a flap.
pub const FLAP_WINDOW_S: f64 = 2.0;

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
