//! fusion: the world models of a robot-soccer team — pose EKF, ball EKF, each robot's local
//! world model (LWM) and the global world model (GWM) it builds from its teammates' LWMs
//! (tsinghua-2005 §4, eqs. (2)–(16); cmunited-97-perception §2.3).
//!
//! It is pure computation: no I/O, no clock, no randomness. Every time is an `f64` argument
//! in seconds (`t_s`, `dt_s`) on the caller's clock; every filter step is a function of its
//! inputs. It is *not* a localisation system (no particle filter, no landmark recognition,
//! no data association beyond gating) and it does not send anything: the LWM encodes to
//! bytes that the caller publishes (as `*.var.world.local`) and decodes what it receives.
//!
//! # Letters
//! The textbook letters, used in code and docs alike:
//!
//! | letter | meaning |
//! |---|---|
//! | x, P | state mean and covariance |
//! | F (the seed's A) | state transition Jacobian ∂f/∂x |
//! | W | noise Jacobian ∂f/∂w (seed eq. (11)): rotates robot-frame odometry noise into the field frame |
//! | Q | process noise covariance (per odometry event for the pose; integrated over `dt_s` for the ball) |
//! | H | measurement Jacobian ∂h/∂x |
//! | R | measurement noise covariance |
//! | ν, S, K | innovation z − h(x), its covariance H P Hᵀ + R, the gain P Hᵀ S⁻¹ |
//!
//! Every update uses the Joseph form P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ, which stays
//! symmetric and positive semi-definite where the seed's eq. (15) can drift.
//!
//! # Frames and the pose EKF
//! Field frame fixed to the pitch; robot frame with +y forward and +x right (seed Fig. 6),
//! θ counter-clockwise with θ = 0 facing field +y. Odometry (forward f, left l, turn Δθ)
//! moves the pose by eq. (6): x' = x − f sin θ − l cos θ, y' = y + f cos θ − l sin θ,
//! θ' = θ + Δθ; F is eq. (10); Q = diag(q_right, q_forward, q_θ) in the robot frame enters
//! as W Q Wᵀ (eq. (12)). A landmark b seen at l in robot coordinates has
//! h = Rot(θ)ᵀ (b − p) (eq. (8)); the innovation is exactly the bracket of eq. (14).
//! Where the seed is ambiguous this crate decides, and says so:
//! - eq. (6) applies the translation in the heading *before* the turn; we do the same;
//! - the seed never writes H; ours is ∂(8)/∂(x, y, θ), see [`field_to_robot_pose_jacobian`];
//! - eq. (13) carries a V R Vᵀ that it then sets to R; we use R (the sighting is already in
//!   robot coordinates);
//! - eq. (7) adds the noise as `Rot(θ)·(w_x, w_y, w_θ)`, so w_x is along the robot's +x
//!   (right) and w_y along +y (forward): Q's first entry is *rightward* noise, not leftward;
//! - eq. (15) is the short covariance form; we use Joseph (above);
//! - θ is wrapped to (−π, π] after every step (the seed does not say).
//!
//! Range/bearing sightings are a second measurement model: bearing counter-clockwise from
//! forward, `atan2(−l_x, l_y)`, innovation wrapped.
//!
//! # Ball EKF
//! State (x, y, vx, vy) in the field frame, velocity decaying at `friction_per_s` with
//! white acceleration noise; the exact discretisation is in [`BallModel`]'s docs
//! (see [`BallModel::transition`]). [`BallEstimate::predict_to`] predicts to any future time
//! (the goalie's interception query). The seed's static model is [`BallModel::Static`].
//! [`BallModel::Field`] ([`FieldBall`]) is the ball a team calibrates on its own carpet:
//! drag plus a constant rolling deceleration (nonlinear mean, Jacobian at the mean), the
//! boards it bounces off ([`Boards`]: the mean reflected at the instant it meets a board,
//! P through the bounce's saltation matrix, the restitution's σ added), and acceleration
//! noise that grows with the speed, so a ball at rest is not predicted as loosely as one
//! that was just kicked.
//! A sighting in robot coordinates becomes a field-frame position with
//! R = Rot R_l Rotᵀ + J P_pose Jᵀ, J the Jacobian of the robot→field transform with respect
//! to the pose ([`field_observation`]), so a poorly localised robot reports a wide ball.
//!
//! # Team ball: why it is built this way
//! A teammate's ball *estimate* is not a measurement: it already contains everything that
//! robot saw before, the process noise it shares with every other track of the same ball,
//! and — if its GWM fed back — other robots' information. Fusing such estimates as if
//! independent, message after message, counts the same sightings again and again and is
//! overconfident; covariance intersection avoids that by assuming the worst correlation and
//! pays for it in accuracy.
//!
//! huddle sends the *new information* instead. Each LWM message carries, besides the
//! snapshot, one field-frame position measurement: the information-weighted combination
//! Λ = Σ R_i⁻¹, z = Λ⁻¹ Σ R_i⁻¹ z_i of exactly the sightings the robot made since its previous
//! message, stamped at their weighted mean time (see [`LocalModel::publish`]). Every sighting
//! is therefore published once; a sequence number makes a re-sent or duplicated message a
//! no-op ([`Ingest::Duplicate`]); the robot's own GWM takes its own messages the same way.
//! The GWM runs one ball filter, the same model as the robots', over these measurements,
//! each placed at its own time (reception time − receiver-side age − its offset in the
//! message), kept re-orderable for `commit_lag_s` so late arrivals slot in by time. That
//! is the centralized filter, minus lost messages and the batching within one publish
//! period, so nothing is counted twice and the covariance stays honest.
//!
//! Gating: each measurement must pass a χ² gate against the team ball at its time. A robot
//! whose measurements fail and none pass since *dissents*. One liar dissents alone and
//! never moves the team ball. A real kick makes every robot that sees the ball dissent at
//! once; when two or more dissenters' own ball tracks agree with each other, the team ball
//! restarts from their fusion (their own tracks are built from their own sightings only, so
//! this one-off product is not double counting), unless more robots oppose them: robots
//! whose last sighting, accepted within the window, fits the team ball better than the
//! group's, and dissenters elsewhere. Two robots holding false balls that happen to agree
//! do not move a ball three teammates see; a kick's far, wide sightings oppose nothing. A lone robot restarts it when enough of its
//! observations in a row (`own_restart_after` of the own camera's, `teammate_restart_after`
//! of a teammate's) fail the gate, agree with each other, and no observation made since
//! the first of them supported the old ball; every observation since, rejected or not, is
//! then re-gated against the new track and fused at its own time. A liar among robots that
//! see the real ball never gets there. Failing all that, a lone dissenter may restart the
//! ball when no one has supported the team ball for `support_timeout_s`. When every teammate is
//! silent, the team ball is the robot's own ([`TeamBallSource::OwnFallback`]).
//!
//! # Time
//! A teammate's message is placed at *reception − receiver-side age − transit*. Since wire
//! format 3, comms' receiver-side age already includes each frame's own transit: every
//! frame carries its send stamp and echoes a teammate's last frame with its hold time, so
//! each replica estimates every teammate's clock offset and drift (NTP-style, from traffic
//! already sent) and stamps a value at reception − that frame's transit − the sender's
//! age. Measured on a competition WLAN (20 ± 10 ms, bursty loss, clocks seconds apart and
//! drifting up to 200 ppm): placement error mean 0.0–0.1 ms, σ 2.3–2.8 ms; with a DTIM hold
//! of 204.8 ms, mean 2.4–3.3 ms, σ 7 ms, against +62 ms and σ 36 ms when only a mean transit
//! was subtracted (`tests/shared_time.rs`). So [`GlobalConfig::transit_s`] is 0 for ages
//! from comms; it remains for ages from elsewhere that leave the transit out.
//!
//! # Redundancy
//! Each message repeats the batches of the two messages before it. A receiver's blackboard
//! keeps only the newest copy of `*.var.world.local`, and a beacon hold delivers two or
//! three of a teammate's 25 Hz messages at once, so without the repeats most batches would
//! be overwritten before the GWM reads them; with them, a batch is lost only when three
//! messages in a row are. The GWM takes each batch once, by sequence number.
//!
//! # Kick-offs
//! When the ball is put back by hand the robots are told (the game controller):
//! [`LocalModel::forget_ball`], [`GlobalModel::forget_ball`] drop every ball belief and
//! every observation from before that moment still on its way; a teammate's for
//! [`GlobalConfig::forget_margin_s`] after it too, since the shared clock can place a
//! message sent just before the reset a few ms after it.
//!
//! # Kicks
//! A robot knows its own kicks before anyone sees them. [`LocalModel::kick`] turns its own
//! ball at once and puts the kick (time, speed, direction and their σ, as a [`Kick`]) in
//! its messages for [`KICK_REPORTED_FOR_S`]; a receiver takes each kick once, by its
//! number ([`KickReport`]). The GWM then puts the kick among its pending observations at
//! the kick time: the team ball continues from its own state there with the kick's
//! velocity and every observation made since is re-gated, so the team ball turns the
//! moment the report arrives instead of after several sightings have outvoted the old
//! track. What was seen before the kick stays, and a teammate's sighting from before it
//! whose message comes after the report (a beacon hold delays it; the kicker's own report
//! reaches its own GWM at once) slots in before the kick, which is applied again on top. When the cameras already restarted the ball before the report
//! came, the GWM rewinds to the track as it was before that restart; failing that, it fuses
//! the kick's velocity, rolled forward by the model, into the current track (gated).
//!
//! # What limits the team ball
//! `huddle sim` measures the team ball against references that run this crate's own
//! [`GlobalModel`] with the team's settings (its figures are in `huddle sim --json`): one
//! fed every robot's LWM at once with no network (central; and told every kick that met
//! the ball, cK); at every robot, a *delivery reference* fed exactly the messages that
//! reached that robot, each at its true sender time; and a *delayed-centralized
//! reference* (each teammate's LWM the median delay late, none lost). The team ball over
//! the delivery reference measures the clock estimate and commit lag; the delivery
//! reference over cK measures the network. [`CentralizedBall`] and [`NetworkLimitedBall`]
//! are the plain filters without the GWM's rules (`huddle sim --daemons` keeps the first).
//! [`consistency::nees_bounds`] gives the χ² bounds that NEES is held to. What sets the gap:
//! - *bias from delay*: placing teammates' messages at reception − age (without transit)
//!   lags a rolling ball, and a kick-off that teleports the ball leaves every filter on the
//!   old one; ages that include each frame's transit (comms' wire format 3) and
//!   `forget_ball` remove both;
//! - *the centralized filter is not delayed*: nearly all of the gap is the short time after
//!   each kick, bounce or shove, when a robot that does not see the ball itself has only
//!   its teammates' sightings, a network delay old, to go by, while the centralized filter
//!   has already followed. The own camera restarts the team ball at once
//!   (`own_restart_after`) and kick reports turn it when they arrive; no design can give a
//!   robot a teammate's sighting before it arrives, so against an undelayed reference the
//!   ratio is set by the network's delay, and where the network is quick the kick reports
//!   can take the team ball past a centralized filter that sees only sightings;
//! - *lost messages*: the repeats (see Redundancy) recover the batches a beacon hold and
//!   the blackboard's newest-copy rule would otherwise lose;
//! - *the ball model*: [`BallModel::Field`] models the field's own drag plus rolling
//!   friction exactly (nonlinear mean, Jacobian linearised at √(s² + tr P_vv) so a ball at
//!   rest keeps a fresh track's velocity variance) and its boards; every reference gets the
//!   same model (each with its own noise), so it moves the RMSEs, not the ratios much.
//!   Its speed-dependent acceleration noise is what trades accuracy against an honest
//!   NEES, and kick (and push) reports are what let a smaller one stay honest;
//! - *overconfidence from correlated pose errors*: `pose_error_sharing` (see
//!   [`field_observation_shared`]) keeps the centralized filter's and the team's NEES near
//!   their degrees of freedom.
//!
//! # The wire
//! An LWM is [`LWM_WIRE_LEN`] = 75 bytes (mm, mrad-scale fixed point, σ on a log scale and
//! correlations as i8). A comms frame carrying it alone fits an SPL message's 128 bytes
//! without a team key; the key's 16-byte HMAC tag takes it past 128 once the frame's
//! counters grow (the root `tests/frame_sizes.rs` pins the sizes). Quantising never
//! shrinks a covariance: see [`LocalWorldModel::to_bytes`]. Decoding takes untrusted bytes
//! and returns a [`DecodeError`], never panics.
//!
//! # Example
//! One robot sees the ball, publishes; a teammate fuses it.
//! ```
//! use fusion::nalgebra::{Matrix2, Vector2, Vector3};
//! use fusion::{BallSighting, GlobalConfig, GlobalModel, LocalConfig, LocalModel, Odometry, PoseEstimate};
//!
//! let start = PoseEstimate::new(0.0, -1.0, 0.0, Vector3::new(0.01, 0.01, 0.001));
//! let mut lwm = LocalModel::new(LocalConfig::default(), start);
//! lwm.odometry(&Odometry { forward_m: 0.1, left_m: 0.0, turn_rad: 0.0 });
//! let seen = BallSighting { local: Vector2::new(0.0, 2.0), cov: Matrix2::identity() * 0.01 };
//! lwm.ball_sighting(0.05, &seen);
//! let bytes = lwm.publish(0.1).to_bytes().unwrap();
//! assert_eq!(bytes.len(), fusion::LWM_WIRE_LEN); // 75
//!
//! let mut gwm = GlobalModel::new(2, GlobalConfig::default());
//! gwm.receive(1, &bytes, 0.15, 0.05).unwrap(); // robot 1's message, 50 ms old on arrival
//! let team = gwm.team_ball(0.2, None).unwrap();
//! assert!((team.estimate.position() - Vector2::new(0.0, 1.1)).norm() < 0.01);
//! ```

#![forbid(unsafe_code)]

mod ball;
mod confidence;
pub mod consistency;
mod geometry;
mod global;
mod kalman;
mod local;
mod pose;
mod wire;

pub use ball::{
    field_observation, field_observation_shared, initial_estimate, update as ball_update,
    BallEstimate, BallFilter, BallFilterConfig, BallModel, BallSighting, BallUpdate, Boards,
    CentralizedBall, FieldBall, FieldObservation, Kick, NetworkLimitedBall,
};
pub use confidence::{pose_confidence, position_confidence, REFERENCE_RADIUS_M};
pub use geometry::{
    field_to_robot, field_to_robot_pose_jacobian, robot_to_field, robot_to_field_pose_jacobian,
    rotation, wrap_angle,
};
pub use global::{
    track_gain, GlobalConfig, GlobalModel, GlobalStats, Ingest, TeamBall, TeamBallSource, Teammate,
    TrackGain,
};
pub use kalman::UpdateError;
pub use local::{Heard, KickReport, LocalConfig, LocalModel, LocalWorldModel, KICK_REPORTED_FOR_S};
pub use nalgebra;
pub use pose::{
    predict as pose_predict, update_landmark, update_range_bearing, LandmarkSighting, Odometry,
    PoseEstimate, PoseFilter, PoseNoise, RangeBearingSighting, Relocalise,
};
pub use wire::{DecodeError, EncodeError, LWM_COMPACT_LEN, LWM_WIRE_LEN};
