//! What `huddle sim` reports: the [`Report`] (also the `--json` object), its text form,
//! and a sweep's rows.

use serde::Serialize;

use std::time::Duration;

use super::{acoustic, game, policy, BallEvent, Transport};

/// What `huddle sim` reports (also its `--json` object). Percentages are of ball-visible
/// time; per-minute rates are per minute of ball-visible time. See [`metrics`](super::metrics) for the
/// definitions of *ball visible*, *goer*, *handover* and *flap*.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// The team's message budget (`None`: no limit).
    pub budget: Option<String>,
    /// The robots' sending policy.
    pub policy: policy::SendPolicy,
    /// The world: `ideal` (its physics are the robots' calibration, clocks ideal) or
    /// `drawn` (physics drawn per match around it, start errors, real clocks).
    pub world: &'static str,
    /// How frames travelled.
    pub transport: Transport,
    /// Frames (messages) the whole team sent.
    pub team_messages_sent: u64,
    /// … per robot.
    pub messages_per_robot: Vec<u64>,
    /// The largest frame any robot sent, bytes (header, items and tag).
    pub max_payload_bytes: usize,
    /// Messages the team had left of its budget at the end.
    pub budget_left: Option<u64>,
    /// Robots on our team.
    pub robots: usize,
    /// Simulated seconds.
    pub duration_s: f64,
    /// Network preset.
    pub preset: String,
    /// Mean loss per receiver, percent.
    pub loss_pct: f64,
    /// One-way latency, ms.
    pub latency_ms: f64,
    /// Jitter, ms.
    pub jitter_ms: f64,
    /// The seed.
    pub seed: u64,
    /// Seconds during which at least one field player saw the ball.
    pub ball_visible_s: f64,
    /// The same as a share of the match, percent.
    pub ball_visible_pct: f64,
    /// Share of ball-visible time with exactly one goer, percent.
    pub exactly_one_goer_pct: f64,
    /// Share with two or more goers, percent.
    pub conflict_pct: f64,
    /// Share with no goer, percent.
    pub no_goer_pct: f64,
    /// Longest stretch with two or more goers, ms.
    pub longest_conflict_ms: f64,
    /// When it started, seconds.
    pub longest_conflict_at_s: f64,
    /// The bound it stays under, ms. Under a budget it comes from the arbitration's
    /// parameters alone (`SimConfig::conflict_bound_budgeted`: 2 × latency compensation +
    /// ack margin + one keepalive + p99 delay + control period; a lost keepalive can take
    /// a conflict past it). Without one: the longest claim gap
    /// ([`Report::longest_claim_gap_ms`]) plus the measured one-way delay's 99th
    /// percentile (all delivered frames) plus one control period. Why it holds: a
    /// conflict starts when a robot B claims the ball while another, A, still goes. It ends when A hears a post B made after claiming and
    /// yields (within one gap + one delay of the claim, then A's next decision, at most
    /// a control period later), or earlier when B backs off (A still claims in a post
    /// made after B's claim should have reached it:
    /// `comms::arbitration::ArbitrationParams::ack_margin`). A goer that merely fell
    /// silent keeps the ball for `silent_goer_after` (1 s), so a burst shorter than that
    /// starts no conflict; a longer one can, and the gap term covers it. The bound
    /// assumes A and B agree once each has heard the other's posts of the same instant
    /// (what the latency compensation is for), and a delay within the p99.
    pub conflict_bound_ms: f64,
    /// The oldest a live teammate's claim was when a live robot decided on it, ms: the
    /// longest the network kept one robot's claims from another (bursts, beacon holds).
    pub longest_claim_gap_ms: f64,
    /// Median one-way delay of the frames delivered, ms.
    pub delay_p50_ms: f64,
    /// 99th percentile of it, ms.
    pub delay_p99_ms: f64,
    /// Handovers (the lone goer changed).
    pub handovers: u64,
    /// Handovers per minute of ball-visible time.
    pub handovers_per_min: f64,
    /// Flaps (A → B → A within two seconds).
    pub flaps: u64,
    /// Flaps per minute of ball-visible time.
    pub flaps_per_min: f64,
    /// Goals we scored.
    pub goals_for: u32,
    /// Goals against us.
    pub goals_against: u32,
    /// Shots that met the ball.
    pub shots: u32,
    /// Passes that met the ball.
    pub passes: u32,
    /// Kicks the robots swung (each reported to the team with its kicker's odds).
    pub kick_attempts: u64,
    /// The share of them that met the ball, percent.
    pub kick_contact_pct: f64,
    /// Frames sent into the network (one per multicast transmission per receiver).
    pub frames_sent: u64,
    /// Frames delivered.
    pub frames_delivered: u64,
    /// Frames lost.
    pub frames_lost: u64,
    /// Team-ball RMSE against the true ball, m: every live robot's GWM team ball at each of
    /// its control ticks while the ball is visible (see [`metrics`](super::metrics)).
    pub team_ball_rmse_m: f64,
    /// The same for the centralized reference (the team's fusion fed every robot's LWM at
    /// every tick at once: no network) at the same instants, m.
    pub centralized_rmse_m: f64,
    /// team_ball_rmse_m / centralized_rmse_m.
    pub rmse_ratio: f64,
    /// The centralized reference also told every kick that met the ball for sure, and no
    /// swing that missed (cK), m: the ceiling for a team that reports its kicks.
    pub centralized_kicks_rmse_m: f64,
    /// team_ball_rmse_m / centralized_kicks_rmse_m.
    pub rmse_ratio_kicks: f64,
    /// The delivery reference at the same instants, m: at each robot, the team's fusion
    /// fed exactly the messages that reached it, each at its true sender time (see
    /// [`metrics`](super::metrics)).
    pub delivery_rmse_m: f64,
    /// team_ball_rmse_m / delivery_rmse_m: what the team's clock estimate and commit lag
    /// cost.
    pub delivery_ratio: f64,
    /// delivery_rmse_m / centralized_kicks_rmse_m: what the network costs.
    pub network_ratio: f64,
    /// The delayed-centralized reference, m: at each robot, the team's fusion fed its own
    /// LWMs at once and every teammate's LWM of every tick, none lost, exactly the median
    /// delay (`delay_p50_ms`) late.
    pub delayed_centralized_rmse_m: f64,
    /// team_ball_rmse_m / delayed_centralized_rmse_m (over the samples where the reference
    /// has a ball).
    pub delayed_centralized_ratio: f64,
    /// Samples of robots that had not seen the ball themselves within their ball memory.
    pub blind_samples: u64,
    /// Team-ball RMSE over those samples, m.
    pub blind_team_ball_rmse_m: f64,
    /// Centralized RMSE over those samples, m.
    pub blind_centralized_rmse_m: f64,
    /// Delivery reference RMSE over those samples, m.
    pub blind_delivery_rmse_m: f64,
    /// Average position NEES (2 dof) of the team ball over the same samples.
    pub team_ball_nees: f64,
    /// Its χ² 95% bounds for `team_ball_nees_samples` independent samples.
    pub team_ball_nees_bounds: [f64; 2],
    /// Independent samples the bounds assume (batch means of the NEES series).
    pub team_ball_nees_samples: u64,
    /// Share of samples above χ²₂'s 99.9% point, percent (0.1 for an honest filter).
    pub team_ball_nees_above_999_pct: f64,
    /// The same had every covariance been scaled by the one factor that puts the mean
    /// NEES at 2, percent (0.1 for a Gaussian's shape at any scale; see [`NeesBand`]).
    pub team_ball_nees_above_999_pct_at_mean_2: f64,
    /// The team-ball NEES while the true ball is still.
    pub team_ball_nees_still: NeesBand,
    /// … rolling.
    pub team_ball_nees_rolling: NeesBand,
    /// … fast.
    pub team_ball_nees_fast: NeesBand,
    /// The team-ball NEES per cause: the latest event that changed the true ball's motion
    /// within a second before the sample ([`super::metrics::BallEvent`], `quiet`: none).
    pub team_ball_nees_by_cause: Vec<NeesCause>,
    /// Average position NEES of the centralized filter.
    pub centralized_nees: f64,
    /// Team-ball samples (robot ticks) behind the RMSEs.
    pub team_ball_samples: u64,
    /// Pose position RMSE of every robot's pose EKF at each of its ticks, m.
    pub pose_rmse_m: f64,
    /// Heading RMSE, rad.
    pub heading_rmse_rad: f64,
    /// Average pose NEES (3 dof).
    pub pose_nees: f64,
    /// The shared-time estimate's error: each robot's estimate of each teammate's clock
    /// offset (comms' echo fit, `PeerInfo::clock_offset_us`) against the true offset,
    /// sampled once a simulated second, root mean square, µs (0 with ideal clocks
    /// would still show the estimate's own error).
    pub clock_offset_error_rms_us: f64,
    /// … its 95th percentile, µs.
    pub clock_offset_error_p95_us: f64,
    /// … its largest, µs.
    pub clock_offset_error_max_us: f64,
    /// … the samples (robot, teammate, second) it is over.
    pub clock_offset_samples: u64,
    /// Simulated seconds per wall-clock second (the only field that varies between runs
    /// with the same seed).
    pub sim_speed_x: f64,
    /// The outage and the acoustic fallback (flattened; absent without an outage).
    #[serde(flatten)]
    pub outage: Option<acoustic::OutageReport>,
    /// The GameController's books (flattened; absent without `--game`).
    #[serde(flatten)]
    pub game: Option<super::GameReport>,
    /// Under a budget: blind robots' team-ball error by the age of the newest ball a
    /// teammate told them (absent without a budget, where news is never old).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub blind_by_told_age: Option<Vec<super::ToldAgeBin>>,
}

/// The team-ball NEES over one band of true ball speeds (see [`metrics`](super::metrics)).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NeesBand {
    /// Average position NEES (2 dof).
    pub nees: f64,
    /// Its χ² 95% bounds for `independent_samples`.
    pub bounds: [f64; 2],
    /// Samples in the band.
    pub samples: u64,
    /// Independent samples they are worth (batch means).
    pub independent_samples: u64,
    /// Share above χ²₂'s 99.9% point, percent.
    pub above_999_pct: f64,
    /// Median NEES (1.386 for an honest filter, 0.693 of its mean).
    pub median: f64,
    /// The share above the 99.9% point had the band's covariances been scaled by the one
    /// factor that puts its mean at 2, percent: 0.1 for a Gaussian's shape at any scale;
    /// above the tail target no single scale meets both targets.
    pub above_999_pct_at_mean_2: f64,
}

/// The team-ball NEES of the samples put down to one cause (see
/// [`metrics`](super::metrics)).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct NeesCause {
    /// The cause.
    pub cause: super::BallEvent,
    /// Samples.
    pub samples: u64,
    /// Their average position NEES (2 dof).
    pub nees: f64,
    /// Their samples above χ²₂'s 99.9% point, as a percentage of **all** team-ball samples
    /// (the causes' shares add up to `team_ball_nees_above_999_pct`).
    pub above_999_pct_of_all: f64,
    /// … of them, within 0.1 s of the event, 0.1–0.3 s, later (% of all samples).
    pub above_999_pct_after: [f64; 3],
    /// … of them, at the robot whose kick or push it was (% of all samples).
    pub above_999_pct_at_actor: f64,
}

/// One report as a row of `huddle sim --sweep` (the figures that move with the network).
pub struct SweepRow<'a>(pub &'a Report);

impl SweepRow<'_> {
    /// The column heads.
    pub fn header() -> &'static str {
        "delay ms  p50 ms  p99 ms  one goer %  conflict ms / bound  team ball m  ×central  ×central+kicks  NEES"
    }
}

impl std::fmt::Display for SweepRow<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let r = self.0;
        write!(
            f,
            "{:>8.0}  {:>6.0}  {:>6.0}  {:>10.2}  {:>8.0} / {:<6.0}  {:>11.4}  {:>8.3}  {:>14.3}  {:>5.2}",
            r.latency_ms,
            r.delay_p50_ms,
            r.delay_p99_ms,
            r.exactly_one_goer_pct,
            r.longest_conflict_ms,
            r.conflict_bound_ms,
            r.team_ball_rmse_m,
            r.rmse_ratio,
            r.rmse_ratio_kicks,
            r.team_ball_nees
        )
    }
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "huddle sim: {} robots, {:.0} s simulated, network {} (loss {:.1}%, latency {:.0} ms ± {:.0} ms), seed {}",
            self.robots, self.duration_s, self.preset, self.loss_pct, self.latency_ms, self.jitter_ms, self.seed
        )?;
        writeln!(
            f,
            "ball visible          {:>9.1} s  ({:.1}% of the match)",
            self.ball_visible_s, self.ball_visible_pct
        )?;
        writeln!(
            f,
            "exactly one goer      {:>9.2} %  of ball-visible time",
            self.exactly_one_goer_pct
        )?;
        writeln!(f, "two or more goers     {:>9.2} %", self.conflict_pct)?;
        writeln!(f, "no goer               {:>9.2} %", self.no_goer_pct)?;
        writeln!(
            f,
            "longest conflict      {:>9.0} ms (at {:.1} s; bound {:.0} ms = {} + p99 delay {:.0} ms + control period; longest claim gap {:.0} ms; median delay {:.0} ms)",
            self.longest_conflict_ms,
            self.longest_conflict_at_s,
            self.conflict_bound_ms,
            if self.budget.is_some() {
                "2 latency compensations + ack margin + keepalive"
            } else {
                "longest claim gap"
            },
            self.delay_p99_ms,
            self.longest_claim_gap_ms,
            self.delay_p50_ms
        )?;
        writeln!(
            f,
            "shared time           {:>9.0} µs rms error of the teammates' clock offsets (p95 {:.0} µs, max {:.0} µs, {} samples)",
            self.clock_offset_error_rms_us,
            self.clock_offset_error_p95_us,
            self.clock_offset_error_max_us,
            self.clock_offset_samples
        )?;
        writeln!(
            f,
            "handovers             {:>9.2} /min ({} in all)",
            self.handovers_per_min, self.handovers
        )?;
        writeln!(
            f,
            "flaps                 {:>9.2} /min ({} in all)",
            self.flaps_per_min, self.flaps
        )?;
        writeln!(
            f,
            "play                  {} shots, {} passes, goals {}–{}; {} kicks swung, {:.0}% met the ball",
            self.shots, self.passes, self.goals_for, self.goals_against, self.kick_attempts, self.kick_contact_pct
        )?;
        writeln!(
            f,
            "network               {} frames sent, {} delivered, {} lost",
            self.frames_sent, self.frames_delivered, self.frames_lost
        )?;
        writeln!(
            f,
            "messages              {} by the team ({:?} per robot), largest {} B; budget {}, {} left; policy {:?}",
            self.team_messages_sent,
            self.messages_per_robot,
            self.max_payload_bytes,
            self.budget.as_deref().unwrap_or("none"),
            self.budget_left.map_or("–".to_string(), |l| l.to_string()),
            self.policy
        )?;
        writeln!(
            f,
            "team ball RMSE        {:>9.4} m  (centralized {:.4} m, ratio {:.3}; {} robot ticks)",
            self.team_ball_rmse_m, self.centralized_rmse_m, self.rmse_ratio, self.team_ball_samples
        )?;
        writeln!(
            f,
            "  centralized + kicks {:>9.4} m  (also told every kick at once; ratio {:.3})",
            self.centralized_kicks_rmse_m, self.rmse_ratio_kicks
        )?;
        writeln!(
            f,
            "  delivery reference  {:>9.4} m  (centralized fed what reached each robot, at true times: fusion costs ×{:.3}, the network ×{:.3})",
            self.delivery_rmse_m, self.delivery_ratio, self.network_ratio
        )?;
        writeln!(
            f,
            "  delayed centralized {:>9.4} m  (every sighting {:.0} ms late, no loss: team ×{:.3})",
            self.delayed_centralized_rmse_m, self.delay_p50_ms, self.delayed_centralized_ratio
        )?;
        writeln!(
            f,
            "  robots blind to it  {:>9.4} m  (centralized {:.4} m, delivery {:.4} m; {} robot ticks)",
            self.blind_team_ball_rmse_m,
            self.blind_centralized_rmse_m,
            self.blind_delivery_rmse_m,
            self.blind_samples
        )?;
        writeln!(
            f,
            "team ball NEES        {:>9.3}    (χ² 95% bounds [{:.3}, {:.3}] for {} independent samples; centralized {:.3})",
            self.team_ball_nees,
            self.team_ball_nees_bounds[0],
            self.team_ball_nees_bounds[1],
            self.team_ball_nees_samples,
            self.centralized_nees
        )?;
        for (name, b) in [
            ("still", &self.team_ball_nees_still),
            ("rolling", &self.team_ball_nees_rolling),
            ("fast", &self.team_ball_nees_fast),
        ] {
            writeln!(
                f,
                "  {name:<8}            {:>9.3}    (bounds [{:.3}, {:.3}] for {} of {} samples; {:.2}% above the 99.9% point; median {:.3}; {:.2}% above if scaled to mean 2)",
                b.nees, b.bounds[0], b.bounds[1], b.independent_samples, b.samples, b.above_999_pct, b.median, b.above_999_pct_at_mean_2
            )?;
        }
        writeln!(
            f,
            "  above 99.9% point   {:>9.3} %  (0.1% for an honest filter; {:.3}% if scaled to mean 2)",
            self.team_ball_nees_above_999_pct, self.team_ball_nees_above_999_pct_at_mean_2
        )?;
        writeln!(
            f,
            "pose                  {:>9.4} m RMSE, heading {:.4} rad RMSE, NEES {:.3} (3 dof)",
            self.pose_rmse_m, self.heading_rmse_rad, self.pose_nees
        )?;
        if let Some(o) = &self.outage {
            writeln!(f, "{o}")?;
        }
        if let Some(g) = &self.game {
            writeln!(f, "{g}")?;
        }
        write!(
            f,
            "speed                 {:>9.0} × real time",
            self.sim_speed_x
        )
    }
}

impl super::Simulation {
    /// The report so far; `wall_s` is the wall time the run took (for `sim_speed_x`).
    pub fn report(&self, wall_s: f64) -> Report {
        let m = &self.metrics;
        let f = &self.fusion;
        let (nees_lo, nees_hi) = f.nees_bounds();
        let net = self.harness.net().network_stats();
        // The conflict bound uses the delay the network actually gave (a beacon hold and
        // queues included), not the nominal latency; before anything was delivered, the
        // configured expectation.
        let (delay_p50, delay_p99) = match net.delay_percentiles(&[0.5, 0.99])[..] {
            [p50, p99] => (p50, p99),
            _ => {
                let d = self.cfg.expected_delay();
                (d, d)
            }
        };
        let simulated_s = self.time_s();
        let delayed = self.delayed.squared_errors(
            delay_p50.as_secs_f64(),
            &self
                .fusion
                .instants
                .iter()
                .map(|&(i, at, _)| (i, at))
                .collect::<Vec<_>>(),
        );
        let (mut team_sq, mut delayed_sq, mut delayed_n) = (0.0, 0.0, 0u64);
        for (&(_, _, te), d) in self.fusion.instants.iter().zip(&delayed) {
            if let Some(d) = d {
                team_sq += te;
                delayed_sq += d;
                delayed_n += 1;
            }
        }
        let delayed_rmse = (delayed_sq / delayed_n as f64).sqrt();
        let team_rmse_on_delayed = (team_sq / delayed_n as f64).sqrt();
        let band = |k: usize| {
            let n = f.band_independent_samples(k);
            let (lo, hi) = fusion::consistency::nees_bounds(2, n);
            NeesBand {
                nees: round3(f.nees_bands[k].mean()),
                bounds: [round3(lo), round3(hi)],
                samples: f.nees_bands[k].samples() as u64,
                independent_samples: n,
                above_999_pct: round3(f.nees_bands[k].above_999_pct()),
                median: round3(f.nees_bands[k].median()),
                above_999_pct_at_mean_2: round3(f.nees_bands[k].above_999_pct_at_mean_2()),
            }
        };
        let all_samples = f.nees.samples().max(1) as f64;
        let by_cause = BallEvent::ALL
            .iter()
            .zip(&f.by_cause)
            .map(|(&cause, c)| NeesCause {
                cause,
                samples: c.samples,
                nees: round3(c.nees_sum / c.samples.max(1) as f64),
                above_999_pct_of_all: round3(100.0 * c.above_999 as f64 / all_samples),
                above_999_pct_after: c
                    .above_999_after
                    .map(|n| round3(100.0 * n as f64 / all_samples)),
                above_999_pct_at_actor: round3(100.0 * c.above_999_at_actor as f64 / all_samples),
            })
            .collect();
        let per_robot: Vec<u64> = (0..self.robots.len())
            .map(|i| self.harness.replica(i).map_or(0, |r| r.stats().frames_out))
            .collect();
        // The league counts the team's frames: what is left of the team's messages.
        let team_sent: u64 = per_robot.iter().sum();
        let budget_left = self
            .cfg
            .budget
            .map(|spec| spec.team_messages.saturating_sub(team_sent));
        Report {
            budget: self.cfg.budget.map(|b| b.to_string()),
            policy: self.cfg.brain.team.send_policy,
            world: if self.cfg.drawn_world {
                "drawn"
            } else {
                "ideal"
            },
            transport: self.cfg.transport,
            team_messages_sent: per_robot.iter().sum(),
            messages_per_robot: per_robot,
            max_payload_bytes: self.harness.max_payload(),
            budget_left,
            robots: self.cfg.robots,
            duration_s: simulated_s,
            preset: self.cfg.network.preset.name().to_string(),
            loss_pct: round3(100.0 * self.cfg.network.mean_loss()),
            latency_ms: self.cfg.network.latency().as_secs_f64() * 1e3,
            jitter_ms: self.cfg.network.links().0.jitter.as_secs_f64() * 1e3,
            seed: self.cfg.seed,
            ball_visible_s: round3(m.visible_s),
            ball_visible_pct: round3(100.0 * m.visible_s / simulated_s.max(1e-9)),
            exactly_one_goer_pct: round3(m.exactly_one_pct()),
            conflict_pct: round3(m.conflict_pct()),
            no_goer_pct: round3(m.no_goer_pct()),
            longest_conflict_ms: round3(m.longest_conflict_s * 1e3),
            longest_conflict_at_s: round3(m.longest_conflict_at_s),
            conflict_bound_ms: round3(
                match self.cfg.budget {
                    Some(_) => self
                        .cfg
                        .conflict_bound_budgeted(&self.arbitration_run, delay_p99),
                    None => self
                        .cfg
                        .conflict_bound(Duration::from_secs_f64(m.longest_claim_gap_s), delay_p99),
                }
                .as_secs_f64()
                    * 1e3,
            ),
            longest_claim_gap_ms: round3(m.longest_claim_gap_s * 1e3),
            delay_p50_ms: round3(delay_p50.as_secs_f64() * 1e3),
            delay_p99_ms: round3(delay_p99.as_secs_f64() * 1e3),
            handovers: m.handovers,
            handovers_per_min: round3(m.handovers_per_min()),
            flaps: m.flaps,
            flaps_per_min: round3(m.flaps_per_min()),
            goals_for: self.world.goals_for,
            goals_against: self.world.goals_against,
            shots: self.contacts.shots,
            passes: self.contacts.passes,
            kick_attempts: self.kick_attempts,
            kick_contact_pct: round3(
                100.0 * self.kick_contacts as f64 / self.kick_attempts.max(1) as f64,
            ),
            frames_sent: net.sent,
            frames_delivered: net.delivered,
            frames_lost: net.lost_total(),
            team_ball_rmse_m: round4(f.all.team_rmse_m()),
            centralized_rmse_m: round4(f.all.central_rmse_m()),
            rmse_ratio: round3(f.all.team_rmse_m() / f.all.central_rmse_m()),
            delivery_rmse_m: round4(f.all.delivery_rmse_m()),
            delivery_ratio: round3(f.all.team_rmse_m() / f.all.delivery_rmse_m()),
            network_ratio: round3(f.all.delivery_rmse_m() / f.all.central_kicks_rmse_m()),
            delayed_centralized_rmse_m: round4(delayed_rmse),
            delayed_centralized_ratio: round3(team_rmse_on_delayed / delayed_rmse),
            centralized_kicks_rmse_m: round4(f.all.central_kicks_rmse_m()),
            rmse_ratio_kicks: round3(f.all.team_rmse_m() / f.all.central_kicks_rmse_m()),
            blind_samples: f.blind.samples,
            blind_team_ball_rmse_m: round4(f.blind.team_rmse_m()),
            blind_centralized_rmse_m: round4(f.blind.central_rmse_m()),
            blind_delivery_rmse_m: round4(f.blind.delivery_rmse_m()),
            team_ball_nees: round3(f.team_nees()),
            team_ball_nees_bounds: [round3(nees_lo), round3(nees_hi)],
            team_ball_nees_samples: f.nees_independent_samples(),
            team_ball_nees_above_999_pct: round3(f.nees.above_999_pct()),
            team_ball_nees_above_999_pct_at_mean_2: round3(f.nees.above_999_pct_at_mean_2()),
            team_ball_nees_still: band(0),
            team_ball_nees_rolling: band(1),
            team_ball_nees_fast: band(2),
            team_ball_nees_by_cause: by_cause,
            centralized_nees: round3(f.central_nees()),
            team_ball_samples: f.samples(),
            pose_rmse_m: round4(f.pose_rmse_m()),
            heading_rmse_rad: round4(f.heading_rmse_rad()),
            pose_nees: round3(f.pose_nees()),
            clock_offset_error_rms_us: round3(
                (self.clock_errors_us.iter().map(|e| e * e).sum::<f64>()
                    / self.clock_errors_us.len().max(1) as f64)
                    .sqrt(),
            ),
            clock_offset_error_p95_us: {
                let mut e = self.clock_errors_us.clone();
                e.sort_by(f64::total_cmp);
                e.get((e.len() * 95 / 100).min(e.len().saturating_sub(1)))
                    .copied()
                    .unwrap_or(0.0)
            },
            clock_offset_error_max_us: self.clock_errors_us.iter().copied().fold(0.0, f64::max),
            clock_offset_samples: self.clock_errors_us.len() as u64,
            sim_speed_x: if wall_s > 0.0 {
                round3(simulated_s / wall_s)
            } else {
                0.0
            },
            outage: self.outage_report(),
            game: self.game.as_ref().map(game::Game::report),
            blind_by_told_age: self
                .cfg
                .budget
                .is_some()
                .then(|| self.blind_by_told_age.report()),
        }
    }
}

fn round3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

fn round4(x: f64) -> f64 {
    (x * 10_000.0).round() / 10_000.0
}
