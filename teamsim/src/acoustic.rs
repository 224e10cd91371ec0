//! The simulator's side of the acoustic fallback: the outage on the network, the room
//! (`acoustic_channel`), and the outage's figures. The robots' side (slots, claim
//! encoding, the decision while the radio is silent) is the product's team layer:
//! [`team::acoustic`], re-exported here.

pub use team::acoustic::*;

use serde::Serialize;

pub use super::acoustic_channel::{AcousticChannel, AcousticError, AcousticStats, Heard};

/// The simulator's side: the outage on the network, the room, and the outage's figures.
impl super::Simulation {
    /// Schedule the outage and set up the room (called once from `Simulation::new`).
    pub(super) fn setup_fallback(&mut self) -> Result<(), super::SimError> {
        if let Some(o) = self.cfg.outage {
            if !(o.start_s.is_finite()
                && o.duration_s.is_finite()
                && o.start_s >= 0.0
                && o.duration_s >= 0.0)
            {
                return Err(super::SimError::Config(format!("bad outage {o:?}")));
            }
            let (from, to) = (
                netsim::Time::from_secs_f64(o.start_s),
                netsim::Time::from_secs_f64(o.start_s + o.duration_s),
            );
            for i in 0..self.robots.len() {
                let node = self.harness.node(i);
                let net = self.harness.net_mut();
                net.at(from, netsim::Action::Isolate(node))
                    .and_then(|()| net.at(to, netsim::Action::Rejoin(node)))
                    .map_err(|e| super::SimError::Config(format!("outage: {e}")))?;
            }
        }
        let cfg = self.cfg.acoustic;
        if !cfg.enabled {
            return Ok(());
        }
        let team = self.robots.len();
        let plan = SlotPlan::for_team(team, cfg.slot_s());
        for r in &mut self.robots {
            let params = *r.arbiter.params();
            r.sound = Some(SoundFallback::new(r.id, plan, &cfg, team, params));
        }
        self.acoustic = Some(
            AcousticChannel::new(&cfg, team, self.cfg.seed)
                .map_err(|e| super::SimError::Config(e.to_string()))?,
        );
        Ok(())
    }

    /// The room up to `t_s`: robots whose slot begins now sound their claims, and each
    /// robot hears what its decoder made of its microphone's signal so far.
    pub(super) fn acoustic_step(&mut self, t_s: f64) {
        let Some(channel) = &mut self.acoustic else {
            return;
        };
        for h in channel.advance_to(t_s) {
            let i = h.listener;
            let local = |s: f64| {
                super::robot::seconds(self.harness.local_at(i, netsim::Time::from_secs_f64(s)))
            };
            let start = local(h.detection.start_s);
            self.robots[i].hear_sound(&h.detection.message, start);
        }
        let dt = self.cfg.physics_dt_s;
        let positions = self.world.robot_positions();
        let mut team_times = Vec::with_capacity(self.robots.len());
        for i in 0..self.robots.len() {
            // Each robot's slots run on the team clock its own replica's estimates give,
            // as on a daemon (`team::acoustic::TeamClock`), never on the simulator's time.
            let now = self.harness.local_at(i, netsim::Time::from_secs_f64(t_s));
            let r = &mut self.robots[i];
            if let Some(replica) = self.harness.replica(i) {
                r.update_team_clock(now, replica.peers());
            }
            let local = super::robot::seconds(now);
            if let Some(team) = r.sound.as_ref().map(|s| s.clock()) {
                team_times.push(team.team_at_s(local));
            }
            let due = r
                .sound
                .as_ref()
                .is_some_and(|s| s.starts_in(r.id, local, dt));
            if !due {
                continue;
            }
            if let Some(message) = r.sound_claim(local) {
                channel.sound(i, &message, &positions);
            }
        }
        // How far apart the robots' team clocks read at this one instant (the truth, for
        // the figures only): slots start that far apart.
        if let (Some(o), Some(&first)) = (self.cfg.outage, team_times.first()) {
            if o.contains(t_s) {
                let read: Vec<f64> = team_times
                    .iter()
                    .map(|&t| TeamClock::near(t, first))
                    .collect();
                let spread = read.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                    - read.iter().copied().fold(f64::INFINITY, f64::min);
                let m = &mut self.outage_metrics;
                m.clock_spread_max_s = m.clock_spread_max_s.max(spread);
                m.clock_spread_sum_s += spread;
                m.clock_spread_samples += 1;
            }
        }
    }

    /// One metrics sample of the outage window, and of as long a window just before it
    /// (the radio deciding, for comparison).
    pub(super) fn sample_outage(&mut self, t_s: f64, visible: bool, goers: &[u8]) {
        let Some(o) = self.cfg.outage else {
            return;
        };
        let (world, robots) = (&self.world, &self.robots);
        let near = |g: u8| {
            // The truth, for the figures only: how far the lone goer is from the ball
            // beyond the field player nearest to it.
            let ball = world.ball.at;
            let distance = |i: usize| world.robots[i].pose.at.distance(ball);
            let nearest = (0..robots.len())
                .filter(|&i| robots[i].is_field_player() && robots[i].alive)
                .map(distance);
            is_near(robots.iter().position(|r| r.id == g).map(distance), nearest)
        };
        self.outage_metrics
            .sample(&o, t_s, self.cfg.physics_dt_s, visible, goers, near);
    }

    /// What the room carried so far (`None` without the fallback): how often robots
    /// sounded, and what their decoders made of it, outage or not.
    pub fn acoustic_stats(&self) -> Option<AcousticStats> {
        self.acoustic.as_ref().map(|c| c.stats)
    }

    /// The outage's figures for the report, when there was one.
    pub(super) fn outage_report(&self) -> Option<OutageReport> {
        let o = self.cfg.outage?;
        let s = self.acoustic.as_ref().map(|c| c.stats).unwrap_or_default();
        Some(OutageReport {
            windows: self.outage_metrics.windows(&o, self.cfg.acoustic.enabled),
            acoustic_tone_ms: round3(self.cfg.acoustic.tone_s * 1e3),
            acoustic_guard_ms: round3(self.cfg.acoustic.guard_s * 1e3),
            acoustic_sounded: s.sounded,
            acoustic_receptions: s.receptions,
            acoustic_decoded: s.decoded,
            acoustic_wrong: s.wrong,
            acoustic_collided: s.collided,
            acoustic_team_clock_spread_max_ms: round3(self.outage_metrics.clock_spread_max_s * 1e3),
            acoustic_team_clock_spread_mean_ms: round3(
                self.outage_metrics.clock_spread_sum_s * 1e3
                    / self.outage_metrics.clock_spread_samples.max(1) as f64,
            ),
        })
    }
}

/// A lone goer at most this much farther from the ball than the nearest field player is
/// "near" (the arbitration's hysteresis is 0.5 m, and costs lag the play).
pub const NEAR_GOER_M: f64 = 1.0;

/// The arbitration's figures in one window.
#[derive(Debug, Clone, Default)]
pub struct WindowFigures {
    /// Who went, as everywhere else.
    pub arbitration: super::metrics::Metrics,
    /// Ball-visible time with exactly one goer, s.
    pub lone_s: f64,
    /// Of that, time the goer was near (see [`NEAR_GOER_M`]), s.
    pub near_s: f64,
}

impl WindowFigures {
    /// Share of the lone-goer time the goer was near, percent.
    pub fn near_pct(&self) -> f64 {
        if self.lone_s > 0.0 {
            100.0 * self.near_s / self.lone_s
        } else {
            100.0
        }
    }
}

/// The outage window's figures, and those of as long a window just before it.
#[derive(Debug, Clone, Default)]
pub struct OutageFigures {
    /// Inside the outage.
    pub during: WindowFigures,
    /// Just before it, the radio deciding.
    pub before: WindowFigures,
    /// Inside the outage: the largest spread of the robots' team clocks at one instant, s.
    pub clock_spread_max_s: f64,
    /// Their sum over the samples, s, and the samples (for the mean).
    pub clock_spread_sum_s: f64,
    /// Samples of the spread.
    pub clock_spread_samples: u64,
}

impl OutageFigures {
    /// One sample at `t_s` (after a step of `dt`) of outage `o`'s window or of as long a
    /// window just before it; `near(goer)` says whether a lone goer is near the ball (see
    /// [`NEAR_GOER_M`]), asked only when there is one and the ball is visible.
    pub fn sample(
        &mut self,
        o: &OutageConfig,
        t_s: f64,
        dt: f64,
        visible: bool,
        goers: &[u8],
        near: impl FnOnce(u8) -> bool,
    ) {
        let before = OutageConfig {
            start_s: o.start_s - o.duration_s,
            ..*o
        };
        let window = if o.contains(t_s - dt) {
            &mut self.during
        } else if before.contains(t_s - dt) {
            &mut self.before
        } else {
            return;
        };
        window.arbitration.sample(t_s, dt, visible, goers);
        if let ([g], true) = (goers, visible) {
            window.lone_s += dt;
            if near(*g) {
                window.near_s += dt;
            }
        }
    }

    /// The two windows' figures for a report.
    pub fn windows(&self, o: &OutageConfig, acoustic: bool) -> OutageWindows {
        let (w, b) = (&self.during, &self.before);
        let m = &w.arbitration;
        OutageWindows {
            outage_start_s: round3(o.start_s),
            outage_duration_s: round3(o.duration_s),
            outage_acoustic: acoustic,
            outage_ball_visible_s: round3(m.visible_s),
            outage_exactly_one_goer_pct: round3(m.exactly_one_pct()),
            outage_conflict_pct: round3(m.conflict_pct()),
            outage_no_goer_pct: round3(m.no_goer_pct()),
            outage_handovers: m.handovers,
            outage_near_goer_pct: round3(w.near_pct()),
            before_outage_exactly_one_goer_pct: round3(b.arbitration.exactly_one_pct()),
            before_outage_handovers: b.arbitration.handovers,
            before_outage_near_goer_pct: round3(b.near_pct()),
        }
    }
}

/// Whether a lone goer `goer_m` from the ball is near it: within [`NEAR_GOER_M`] of the
/// nearest of the field players' distances `field_players_m` (`None`: not a field player
/// on the field, so not near).
pub fn is_near(goer_m: Option<f64>, field_players_m: impl Iterator<Item = f64>) -> bool {
    let nearest = field_players_m.fold(f64::INFINITY, f64::min);
    goer_m.is_some_and(|d| d <= nearest + NEAR_GOER_M)
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

/// The outage's arbitration figures: the window and as long a window just before it.
/// Percentages are of the ball-visible time inside the window.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutageWindows {
    /// When the outage started, s.
    pub outage_start_s: f64,
    /// How long it lasted, s.
    pub outage_duration_s: f64,
    /// Whether the acoustic fallback was on.
    pub outage_acoustic: bool,
    /// Ball-visible time inside the outage, s.
    pub outage_ball_visible_s: f64,
    /// Share of it with exactly one goer, percent.
    pub outage_exactly_one_goer_pct: f64,
    /// Share with two or more goers, percent.
    pub outage_conflict_pct: f64,
    /// Share with no goer, percent.
    pub outage_no_goer_pct: f64,
    /// Handovers of the lone goer inside the outage.
    pub outage_handovers: u64,
    /// Share of the lone-goer time the goer was within [`NEAR_GOER_M`] of the field
    /// player nearest to the ball (the truth), percent: a fallback that never handed the
    /// ball over would keep one goer and lose this.
    pub outage_near_goer_pct: f64,
    /// Exactly one goer in as long a window just before the outage (radio), percent.
    pub before_outage_exactly_one_goer_pct: f64,
    /// Handovers in that window.
    pub before_outage_handovers: u64,
    /// Near-goer share in that window, percent.
    pub before_outage_near_goer_pct: f64,
}

impl std::fmt::Display for OutageWindows {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "outage                {:>9.1} s from {:.1} s, all links down; acoustic fallback {}",
            self.outage_duration_s,
            self.outage_start_s,
            if self.outage_acoustic { "on" } else { "off" }
        )?;
        writeln!(
            f,
            "  exactly one goer    {:>9.2} %  of {:.1} s ball-visible outage time (two or more {:.2} %, none {:.2} %)",
            self.outage_exactly_one_goer_pct,
            self.outage_ball_visible_s,
            self.outage_conflict_pct,
            self.outage_no_goer_pct
        )?;
        write!(
            f,
            "  lone goer near ball {:>9.2} %  of lone-goer time, {} handovers (before the outage, radio: {:.2} % one goer, {:.2} % near, {} handovers)",
            self.outage_near_goer_pct,
            self.outage_handovers,
            self.before_outage_exactly_one_goer_pct,
            self.before_outage_near_goer_pct,
            self.before_outage_handovers
        )
    }
}

/// The outage's part of the report (flattened into it; absent without `--outage`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct OutageReport {
    /// The arbitration in the outage and before it.
    #[serde(flatten)]
    pub windows: OutageWindows,
    /// Tone length of the fallback's messages, ms.
    pub acoustic_tone_ms: f64,
    /// Silence after each tone, ms.
    pub acoustic_guard_ms: f64,
    /// Messages sounded (whole match).
    pub acoustic_sounded: u64,
    /// Receptions (messages × teammates listening).
    pub acoustic_receptions: u64,
    /// Receptions decoded right (value and slot).
    pub acoustic_decoded: u64,
    /// Detections that matched nothing sounded.
    pub acoustic_wrong: u64,
    /// Receptions overlapped by another message at the listener.
    pub acoustic_collided: u64,
    /// Inside the outage, the largest spread of the robots' team clocks
    /// ([`TeamClock`]) at one instant, ms: how far apart their slots start.
    pub acoustic_team_clock_spread_max_ms: f64,
    /// Its mean over the outage, ms.
    pub acoustic_team_clock_spread_mean_ms: f64,
}

impl std::fmt::Display for OutageReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "{}", self.windows)?;
        write!(
            f,
            "  acoustic            {:>9} sounded ({:.0} ms tones, {:.0} ms guard), {} of {} receptions decoded, {} wrong, {} collided",
            self.acoustic_sounded,
            self.acoustic_tone_ms,
            self.acoustic_guard_ms,
            self.acoustic_decoded,
            self.acoustic_receptions,
            self.acoustic_wrong,
            self.acoustic_collided
        )?;
        write!(
            f,
            "\n  team clock spread   {:>9.3} ms max, {:.3} ms mean (slots start that far apart)",
            self.acoustic_team_clock_spread_max_ms, self.acoustic_team_clock_spread_mean_ms
        )
    }
}
