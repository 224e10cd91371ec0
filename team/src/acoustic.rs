//! The fallback over sound: when the WLAN fails, robots sound their should-I-go claims as
//! Cerberus tones and each hears what its own microphone's decoder makes of the room.
//!
//! **Slots.** The seed's plan has three sender basics; a team has four field players. So a
//! robot sounds only in its own slot of a repeating cycle on the team clock
//! ([`TeamClock`]: the lowest field player's clock as the replica estimates it from the
//! radio's echoes, kept through an outage): the slot a message started in says who sent
//! it, and the sender basic is free to carry data. The daemon (`huddle daemon --audio-fallback`)
//! and the simulator drive the same code: each updates the clock from its replica every
//! tick ([`SoundFallback::update_clock`]) and sounds the claim at each
//! [`SoundFallback::next_slot`]. A slot is one tone plus a guard ([`AcousticConfig::guard_s`]). Both are
//! set for a hall, not for a dry room: a 100 ms tone in a reverberant hall (critical
//! distance 8 m, T60 anywhere from 0.6 to 2 s) is almost never decoded, even alone with a
//! second of silence around it; the decoder needs about 300 ms there, and the previous
//! slot's tail and the end test (half a tone past the end) want the guard at about 300 ms.
//! The default 400 + 300 ms slot makes a 2.8 s cycle for four robots.
//!
//! **Decision.** While the radio is silent (dead by the GameController's heartbeat,
//! [`crate::heartbeat`]; without a GameController, no teammate's radio claim fresher than
//! the arbitration's staleness limit), in play, the fallback decides, on the claims this
//! robot holds:
//! each field player's newest, by radio (the last one heard before the outage) or by
//! sound, its own as the team holds it (what it posted when it last heard a teammate by
//! radio, then what it sounded, quantised), and judged by the same rules as its
//! teammates judge it: a robot holding the same claims as they do names the goer they
//! name (`acoustic_agreement_tests.rs` plays 200 such teams).
//! Every claim counts as fresh until `stale_cycles` cycles old: a missed message leaves
//! the teammate's previous claim standing rather than making room for a second goer, so
//! the goer the team agreed by radio keeps the ball until a claim sounded in the room
//! says otherwise. A claim heard by sound counts from the end of its slot, on everyone's
//! clock, its sender's too: robots that heard the same messages change their minds at the
//! same instant. The rule is the arbitration's (`comms::arbitration::decide`: lowest cost,
//! the goer's lowered by the hysteresis margin, ties to the lower id).
//! What is left is robots that missed different messages: they disagree until the next
//! cycle, and as the goer's "going" claim stands until it is heard to let go, this shows
//! as time with no goer far more than as two goers.
//!
//! **Claim.** A short message carries 3 × 21 = 63 values ([`encode_claim`]): 0 = "no ball,
//! no claim", 1–31 = "not going" with the cost h in one of 31 bins of
//! [`COST_BIN_M`] from −0.5 m, 32–62 = "going" with its bin. The robot's (h, going) is what
//! the radio posts, so the arbitration decides on the same kind of data either way.
//!
//! **Channel** (`teamsim`'s `AcousticChannel`, the simulator's side; robots never see it). Each robot
//! has a loudspeaker and a microphone at its true position. For every listener, every
//! sounding robot's PCM arrives delayed by distance / 343 m/s and attenuated as 1/r (from
//! 1 m); the room adds a diffuse reverberant field (a Schroeder reverberator, T60
//! configurable, its level equal to the direct sound's at the critical distance, so it does
//! not fall with distance) and the crowd adds speech babble (`audio::channel::Babble`) at
//! a level given as the in-band SNR of one robot's sound heard at 1 m. The mix goes into
//! the listener's own streaming `audio::Decoder`; two robots sounding together collide as
//! the decoder makes of the sum. A robot's own sound is mixed in too, and ignored by its
//! slot.

use audio::{Message, Sender};
use std::collections::VecDeque;
use std::time::Duration;

use comms::arbitration::{self, ArbitrationParams, Candidate, Decision, Posted};

pub use crate::heartbeat::{RadioHeartbeat, GC_SILENT_S};
pub use crate::team_clock::{TeamClock, WRAP_S};
use serde::Serialize;

/// Speed of sound, m/s.
pub const SPEED_OF_SOUND_MPS: f64 = 343.0;
/// Sample rate of the acoustic channel, Hz.
pub const SAMPLE_RATE_HZ: u32 = 16_000;
/// Width of one cost bin, m.
pub const COST_BIN_M: f64 = 0.3;
/// Cost at the bottom of bin 0, m (h can be as low as k1 = −0.5 m at the ball).
pub const COST_FLOOR_M: f64 = -0.5;
/// Cost bins per going state.
pub const COST_BINS: u16 = 31;
/// Values a short message carries when the slot names the sender (3 sender basics × 21).
pub const CLAIM_VALUES: u16 = 63;

/// How the fallback is set up.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AcousticConfig {
    /// Whether robots use the fallback (sound their claims when the radio is stale and
    /// decide on what they hear).
    pub enabled: bool,
    /// Tone (frame) duration, s.
    pub tone_s: f64,
    /// Silence after each tone before the next slot, s.
    pub guard_s: f64,
    /// In-band SNR of one robot's sound heard 1 m away, against the crowd's babble, dB.
    pub crowd_snr_db_at_1m: f64,
    /// The room's reverberation time, s.
    pub t60_s: f64,
    /// Distance at which the direct sound equals the reverberant field, m (default 8 m:
    /// r_c ≈ 0.057·√(Q·V/T60) for a 10,000 m³ hall, Q = 2, T60 = 1 s).
    pub critical_distance_m: f64,
    /// Claims older than this many cycles no longer count while the fallback decides.
    pub stale_cycles: f64,
    /// Hysteresis margin of the fallback's decision, m (`None`: the arbitration's).
    pub hysteresis_m: Option<f64>,
    /// Whether a claim to be going whose sender's last slot went by unheard loses the
    /// goer's hysteresis margin.
    pub doubt_going: bool,
}

impl Default for AcousticConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            // 400 ms: in a reverberant room (T60 0.6–2 s, critical distance 8 m) the
            // decoder decodes almost no 100 ms claims, even from a robot sounding alone
            // with a second of silence around it (0–3%), 20–30% of 150 ms ones and
            // ~95% of 300 ms ones; four robots taking turns: 300 ms 73–84%, 400 ms
            // 93–97% with this guard (`tests/acoustic_fallback.rs` shows the
            // difference).
            tone_s: 0.4,
            // The decoder's end test listens half a tone past the end, and in a hall the
            // previous slot's tail still sounds: with 400 ms tones at T60 1 s, guards of
            // 80/150/300/500 ms decoded 50/77/97/96% of the receptions.
            guard_s: 0.3,
            crowd_snr_db_at_1m: 25.0,
            t60_s: 1.0,
            critical_distance_m: 8.0,
            // A claim counts for three cycles (8.4 s): missing one message must not
            // drop a goer's claim, which would make a second goer.
            stale_cycles: 3.0,
            hysteresis_m: None,
            doubt_going: true,
        }
    }
}

impl AcousticConfig {
    /// One slot, s.
    pub fn slot_s(&self) -> f64 {
        self.tone_s + self.guard_s
    }
}

/// A WLAN outage: every link down from `start_s` for `duration_s`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct OutageConfig {
    /// When it starts, s of simulated time.
    pub start_s: f64,
    /// How long it lasts, s.
    pub duration_s: f64,
}

impl OutageConfig {
    /// Whether `t_s` falls inside it.
    pub fn contains(&self, t_s: f64) -> bool {
        t_s >= self.start_s && t_s < self.start_s + self.duration_s
    }
}

/// Who sounds when: a cycle of one slot per field player, on the team clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlotPlan {
    /// The first field player's id (slot 0).
    pub first_id: u8,
    /// Slots in a cycle (field players).
    pub slots: u8,
    /// One slot, s.
    pub slot_s: f64,
}

impl SlotPlan {
    /// The slots of a team of `team_size` robots (ids 1 ..= team_size): one per field
    /// player, robot 1 (the goalkeeper) left out in a team of three or more. The
    /// simulator and the daemon both take their plan from here.
    pub fn for_team(team_size: usize, slot_s: f64) -> SlotPlan {
        let with_keeper = team_size >= 3;
        SlotPlan {
            first_id: if with_keeper { 2 } else { 1 },
            slots: (team_size - usize::from(with_keeper)).clamp(1, 255) as u8,
            slot_s,
        }
    }

    /// The ids of the robots with a slot, in slot order.
    pub fn ids(&self) -> impl Iterator<Item = u8> {
        let first = self.first_id;
        (0..self.slots).map(move |k| first + k)
    }

    /// One cycle, s.
    pub fn cycle_s(&self) -> f64 {
        self.slot_s * f64::from(self.slots)
    }

    /// The slot robot `id` sounds in, if it has one.
    pub fn slot_of(&self, id: u8) -> Option<u8> {
        let k = id.checked_sub(self.first_id)?;
        (k < self.slots).then_some(k)
    }

    /// Whether robot `id`'s slot begins in `[t_s, t_s + dt_s)`.
    pub fn starts_in(&self, id: u8, t_s: f64, dt_s: f64) -> bool {
        let Some(k) = self.slot_of(id) else {
            return false;
        };
        let offset = f64::from(k) * self.slot_s;
        // The latest slot start before the end of the step, then whether the step holds it.
        let n = ((t_s + dt_s - 1e-9 - offset) / self.cycle_s()).floor();
        let start = offset + n * self.cycle_s();
        start >= t_s - 1e-9
    }

    /// The end of the slot a message heard to start at `start_s` was sounded in.
    pub fn slot_end(&self, start_s: f64) -> f64 {
        let k = ((start_s - 0.02) / self.slot_s).round().max(0.0);
        (k + 1.0) * self.slot_s
    }

    /// Who sent a message heard to start at `start_s` (the flight and the decoder's
    /// error make it a little late; the nearest slot start at or before it wins).
    pub fn sender_at(&self, start_s: f64) -> Option<u8> {
        // Up to 40 ms of flight and error are expected; anything within half a slot of a
        // slot start is attributed to it.
        let k = ((start_s - 0.02) / self.slot_s).round();
        if !k.is_finite() || k < 0.0 {
            return None;
        }
        let slot = (k as u64 % u64::from(self.slots)) as u8;
        Some(self.first_id + slot)
    }
}

/// A claim newer than one cycle and this is not in doubt (the decoder reports a claim
/// within its slot's guard; this allows for late reports), s.
const DOUBT_MARGIN_S: f64 = 0.2;

/// A claim as this robot holds it: what a teammate (or itself) last told the team, by
/// radio or by sound, and from when it counts (this robot's clock, s).
#[derive(Debug, Clone, Copy, PartialEq)]
struct Told {
    posted: Posted,
    at_s: f64,
}

/// A robot's side of the fallback: the slot plan it shares with its team, the claims its
/// own microphone's decoder gave it, and the decision it makes on them while the radio is
/// silent. Robot code holds this; it never sees the room.
#[derive(Debug, Clone)]
pub struct SoundFallback {
    plan: SlotPlan,
    /// Claims older than this no longer count, s.
    expire_s: f64,
    /// The rule the team decides by while the fallback is in control.
    params: ArbitrationParams,
    /// Whether a going claim whose last slot went by unheard loses the goer's margin.
    doubt_going: bool,
    /// Per robot (index = id − 1): its latest claim heard by sound (its own: sounded),
    /// in force from the end of its slot.
    sounded: Vec<Option<Told>>,
    /// Per robot: a claim heard before the end of its slot, waiting to come into force.
    pending: Vec<Option<Told>>,
    /// What this robot posted on the radio while the radio decided, newest last, over
    /// the last [`POSTS_KEPT_S`] (see [`SoundFallback::own_as_held`]).
    posts: VecDeque<Told>,
    /// Whether some teammate with a slot had no fresh radio claim at the last decision.
    radio_stale: bool,
    /// Whether no teammate with a slot had a fresh radio claim at the last decision: the
    /// radio is silent and the fallback decides.
    in_control: bool,
    /// The team clock the slots run on (this robot's own until
    /// [`SoundFallback::update_clock`] hears a lower id).
    clock: TeamClock,
    /// Per teammate: how often its replica has echoed this robot's frames. A teammate
    /// echoes a frame of ours only if it heard it.
    echoes: Vec<Echoes>,
    /// Whether this robot hears teammates but none has echoed its frames for
    /// [`UNHEARD_AFTER_S`]: its own sends are failing (see [`SoundFallback::claim`]).
    unheard: bool,
    /// Whether the radio was dead by the GameController's heartbeat: since when it was
    /// silent and, once it works again, since when it works (this robot's clock, s). The
    /// fallback hands back to the radio when every teammate's claim told since the silence
    /// began has come (see [`SoundFallback::radio`]).
    dead: Option<(f64, Option<f64>)>,
}

/// A teammate's echoes of this robot's frames, as its replica counts them.
#[derive(Debug, Clone, Copy)]
struct Echoes {
    robot: u8,
    /// Echo samples so far (`PeerInfo::clock_samples`).
    samples: u64,
    /// When `samples` last grew (this robot's clock), s.
    grew_at_s: f64,
}

/// A robot that hears its teammates but whose frames none of them has echoed for this
/// long takes itself to be unheard, s (a teammate echoes each other robot every few of its
/// frames: about every 0.1–0.2 s at 25 Hz in a team of five).
pub const UNHEARD_AFTER_S: f64 = 1.0;

/// How long a robot keeps its own radio posts: longer than the radio's staleness limit,
/// so that when the fallback takes control the post its teammates last heard is still
/// there, s.
const POSTS_KEPT_S: f64 = 2.0;

impl SoundFallback {
    /// Robot `me`'s fallback, in a team of `team` robots sounding on `plan`, deciding with
    /// the arbitration's `params` (hysteresis, tie band, no-ball cost). A team whose
    /// claims hold longer than [`UNHEARD_AFTER_S`] (`params.stale_after`, raised under a
    /// league's budget by `adapt_to_budget`) sends too rarely for echoes to say whether a
    /// robot is heard (under the SPL's budget an echo needs a teammate's frame within
    /// 655 ms of one of ours: a few a minute), so it never takes itself for unheard: in
    /// a 95 s match under the budget every robot did, and sounded a claim every cycle
    /// while the radio worked.
    pub fn new(
        me: u8,
        plan: SlotPlan,
        cfg: &AcousticConfig,
        team: usize,
        params: ArbitrationParams,
    ) -> Self {
        Self {
            plan,
            expire_s: cfg.stale_cycles * plan.cycle_s(),
            params: ArbitrationParams {
                hysteresis_m: cfg.hysteresis_m.unwrap_or(params.hysteresis_m),
                ..params
            },
            doubt_going: cfg.doubt_going,
            sounded: vec![None; team],
            pending: vec![None; team],
            posts: VecDeque::new(),
            radio_stale: false,
            in_control: false,
            clock: TeamClock::among(me, plan.first_id),
            echoes: Vec::new(),
            unheard: false,
            dead: None,
        }
    }

    /// This robot's replica's view of its teammates at `now` (`comms::Replica::peers`):
    /// the slots run on the team clock it gives ([`TeamClock`]). The daemon's team layer
    /// and the simulator's robots call it every tick; until a teammate with a lower id is
    /// heard, slots run on this robot's own clock.
    pub fn update_clock(
        &mut self,
        now: comms::Instant,
        peers: impl IntoIterator<Item = comms::PeerInfo>,
    ) {
        let now_s = now.as_micros() as f64 * 1e-6;
        let Self { clock, echoes, .. } = self;
        let mut hearing = false;
        clock.update(
            now,
            peers.into_iter().inspect(|p| {
                hearing |=
                    now.saturating_duration_since(p.last_heard).as_secs_f64() <= UNHEARD_AFTER_S;
                let grown = Echoes {
                    robot: p.robot,
                    samples: p.clock_samples,
                    grew_at_s: now_s,
                };
                match echoes.iter_mut().find(|e| e.robot == p.robot) {
                    Some(e) if e.samples != p.clock_samples => *e = grown,
                    Some(_) => {}
                    None => echoes.push(grown),
                }
            }),
        );
        // Unheard: teammates are heard, one has echoed before, and none has for a while.
        let echoed_once = self.echoes.iter().any(|e| e.samples > 0);
        let echoed_lately = self
            .echoes
            .iter()
            .any(|e| e.samples > 0 && now_s - e.grew_at_s <= UNHEARD_AFTER_S);
        self.unheard = self.detects_unheard() && hearing && echoed_once && !echoed_lately;
    }

    /// Whether echoes come often enough to tell an unheard robot: not when the team's
    /// claims hold longer than [`UNHEARD_AFTER_S`] (see [`SoundFallback::new`]).
    fn detects_unheard(&self) -> bool {
        self.params.stale_after.as_secs_f64() <= UNHEARD_AFTER_S
    }

    /// Whether this robot hears its teammates but none echoes its frames (see
    /// [`UNHEARD_AFTER_S`]), as of the last [`SoundFallback::update_clock`].
    pub fn unheard(&self) -> bool {
        self.unheard
    }

    /// The team clock the slots run on.
    pub fn clock(&self) -> &TeamClock {
        &self.clock
    }

    /// Team time at `local_s` (this robot's clock), s.
    fn team_s(&self, local_s: f64) -> f64 {
        self.clock.team_at_s(local_s)
    }

    /// A message that started at `local_s` (this robot's clock): the team time it started
    /// at, brought into the epoch of the slot it belongs to (see [`TeamClock::near`]).
    fn heard_team_s(&self, local_s: f64) -> f64 {
        let team = self.team_s(local_s);
        if team > WRAP_S - self.plan.slot_s / 2.0 {
            // Sounded at the start of the new epoch, heard a little early.
            team - WRAP_S
        } else {
            team
        }
    }

    /// The end of the slot a message that started at `local_s` was sounded in, on this
    /// robot's clock.
    fn slot_end_local(&self, local_s: f64) -> f64 {
        let team = self.heard_team_s(local_s);
        local_s + (self.plan.slot_end(team) - team)
    }

    /// When robot `me`'s next slot starts, at or after `local_s` (this robot's clock, s),
    /// on this robot's clock; `None` if it has no slot.
    pub fn next_slot(&self, me: u8, local_s: f64) -> Option<f64> {
        let k = self.plan.slot_of(me)?;
        let offset = f64::from(k) * self.plan.slot_s;
        let (cycle, slot) = (self.plan.cycle_s(), self.plan.slot_s);
        Some(self.clock.next_slot(local_s, offset, cycle, slot))
    }

    /// Whether robot `me`'s slot begins in `[local_s, local_s + dt_s)` (this robot's
    /// clock).
    pub fn starts_in(&self, me: u8, local_s: f64, dt_s: f64) -> bool {
        self.next_slot(me, local_s - 1e-9)
            .is_some_and(|start| start < local_s + dt_s - 1e-9)
    }

    /// The team's slot plan.
    pub fn plan(&self) -> &SlotPlan {
        &self.plan
    }

    /// Whether the fallback decided last time (the radio was silent).
    pub fn in_control(&self) -> bool {
        self.in_control
    }

    /// A message robot `me`'s decoder produced, started at `start_s` on `me`'s clock. The
    /// slot it started in names the sender; the claim counts from the end of that slot,
    /// when every teammate that decodes it has (so the team changes its mind at once).
    /// Its own slot and long messages are ignored.
    pub fn hear(&mut self, me: u8, message: &Message, start_s: f64) {
        let Some(from) = self.plan.sender_at(self.heard_team_s(start_s)) else {
            return;
        };
        let Some(posted) = decode_claim(message, self.params.no_ball_cost) else {
            return;
        };
        if from == me {
            return;
        }
        let at_s = self.slot_end_local(start_s);
        if let Some(slot) = self.pending.get_mut(usize::from(from) - 1) {
            *slot = Some(Told { posted, at_s });
        }
    }

    /// What robot `me` sounds in its slot starting at `start_s` (its clock): `posted`,
    /// while some teammate's radio claim is stale, or while this robot is unheard (it
    /// hears its teammates but none echoes its frames: its own sends are failing, and its
    /// teammates, taking it for gone by radio, count it by what it sounds, see
    /// [`SoundFallback::sounded_for_stale`]); nothing otherwise (or when it has no slot).
    /// What it sounds counts for itself, as its teammates will hear it (quantised), from
    /// the end of the slot.
    pub fn claim(&mut self, me: u8, posted: Posted, start_s: f64) -> Option<Message> {
        if !((self.radio_stale || self.unheard) && self.plan.slot_of(me).is_some()) {
            return None;
        }
        let message = encode_claim(posted, self.params.no_ball_cost);
        let at_s = self.slot_end_local(start_s);
        if let (Some(heard), Some(slot)) = (
            decode_claim(&message, self.params.no_ball_cost),
            self.pending.get_mut(usize::from(me) - 1),
        ) {
            *slot = Some(Told {
                posted: heard,
                at_s,
            });
        }
        Some(message)
    }

    /// Robot `me` in play at `now_s` with the radio claims `radio` it holds and the
    /// radio's heartbeat `beat`: whether the radio is silent, so that the fallback
    /// decides. Silent: dead by the GameController's heartbeat
    /// ([`RadioHeartbeat::dead`]), or, with no GameController heard lately and some
    /// teammate heard once, no teammate with a slot has a claim fresher than
    /// `stale_after`; and after a dead radio, until every teammate has told a claim since
    /// it came back. While the GameController is heard the radio works: claims are only
    /// old (under a budget a claim holds 15 s, out of play nobody tells one).
    pub fn radio(
        &mut self,
        me: u8,
        radio: &[Candidate],
        stale_after: Duration,
        beat: &RadioHeartbeat,
        now_s: f64,
    ) -> bool {
        let fresh = |id: u8| radio.iter().any(|c| c.robot == id && c.age <= stale_after);
        let mates: Vec<u8> = self.plan.ids().filter(|&id| id != me).collect();
        let dead = beat.dead(now_s);
        // Back from the dead: the radio works, but the teammates' claims are still those
        // from before the outage until each tells a new one. Handing back at once left
        // robots deciding on different mixes of old radio claims and sounded ones (no
        // goer for 6.5 s after a 30 s outage); the fallback keeps deciding on the newest
        // of each (radio or sound) until every teammate's new claim has come, for at most
        // `stale_after`.
        let back = match self.dead {
            _ if dead => {
                // Claims heard since the last thing the radio carried are new.
                let silent_from = beat.last_heard_s().unwrap_or(now_s);
                let since = self.dead.map_or(silent_from, |(s, _)| s.min(silent_from));
                self.dead = Some((since, None));
                None
            }
            Some((since, None)) => {
                self.dead = Some((since, Some(now_s)));
                Some((since, now_s))
            }
            Some((since, Some(back_s))) => Some((since, back_s)),
            None => None,
        };
        let handing_back = back.is_some_and(|(since, back_s)| {
            let told_since = |id: u8| {
                radio
                    .iter()
                    .any(|c| c.robot == id && now_s - c.age.as_secs_f64() > since)
            };
            now_s - back_s < stale_after.as_secs_f64() && mates.iter().any(|&id| !told_since(id))
        });
        if back.is_some() && !handing_back {
            self.dead = None;
        }
        let by_age = !beat.working(now_s) && beat.heard_a_teammate();
        let silent = dead || handing_back;
        self.radio_stale = silent || (by_age && mates.iter().any(|&id| !fresh(id)));
        self.in_control =
            !mates.is_empty() && (silent || (by_age && mates.iter().all(|&id| !fresh(id))));
        self.in_control
    }

    /// Robot out of play (the GameController says anything but Playing, or it is
    /// penalised): nobody plays the ball and nobody tells a claim, so the fallback neither
    /// decides nor sounds. Sounding in Set would also sound over the referee's whistle,
    /// which every team's robots are listening for.
    pub fn out_of_play(&mut self) {
        self.radio_stale = false;
        self.in_control = false;
        // A restart after an outage: every claim is told again at its kick-off, by radio
        // if it works.
        self.dead = None;
    }

    /// What this robot posted on the radio at `now_s` while the radio decided: its
    /// teammates hold the last of these they heard when the radio falls silent.
    pub fn posted(&mut self, now_s: f64, posted: Posted) {
        self.posts.push_back(Told {
            posted,
            at_s: now_s,
        });
        while self.posts.len() > 1 && self.posts[0].at_s < now_s - POSTS_KEPT_S {
            self.posts.pop_front();
        }
    }

    /// This robot's radio claim as its teammates hold it (`radio`: theirs, aged on this
    /// robot's clock): what it posted when it last heard one of them. Its posts after that
    /// went into a silent radio (the radio fails both ways at once, or the robot would
    /// still hear its teammates), so counting them would make it decide on a claim nobody
    /// else holds: a robot whose cost rose in the moment before the fallback took control
    /// would yield to a teammate that still held it for the goer (no goer), one whose
    /// cost fell would go beside the goer (two), until its own sound came into force.
    fn own_as_held(&self, me: u8, now_s: f64, radio: &[Candidate]) -> Option<Told> {
        let newest = self.posts.back().copied();
        let Some(last_heard) = radio
            .iter()
            .filter(|c| c.robot != me)
            .map(|c| now_s - c.age.as_secs_f64())
            .max_by(f64::total_cmp)
        else {
            return newest;
        };
        self.posts
            .iter()
            .rev()
            .find(|p| p.at_s <= last_heard + 1e-6)
            .or(self.posts.front())
            .copied()
    }

    /// The claims robot `me` decides on at `now_s` while the radio is silent: each
    /// field player's newest claim, by radio (`radio`, aged on this robot's clock) or by
    /// sound, unless older than `stale_cycles` cycles; every one counts as fresh (age
    /// zero), so a missed message leaves the teammate's previous claim standing instead
    /// of making room for a second goer.
    pub fn candidates(&mut self, me: u8, now_s: f64, radio: &[Candidate]) -> Vec<Candidate> {
        self.promote(now_s);
        let mut out = Vec::new();
        for id in self.plan.ids() {
            let by_radio = if id == me {
                self.own_as_held(me, now_s, radio)
            } else {
                radio.iter().find(|c| c.robot == id).map(|c| Told {
                    posted: c.posted,
                    at_s: now_s - c.age.as_secs_f64(),
                })
            };
            let by_sound = self.sounded.get(usize::from(id) - 1).copied().flatten();
            let newest = match (by_radio, by_sound) {
                (Some(r), Some(s)) => Some(if s.at_s >= r.at_s { s } else { r }),
                (r, s) => r.or(s),
            };
            if let Some(t) = newest.filter(|t| now_s - t.at_s <= self.expire_s) {
                out.push(self.candidate(id, t, now_s));
            }
        }
        out
    }

    /// While the radio still decides (some teammate's radio claims are fresh): the claims
    /// heard by sound of the teammates whose radio claims are stale (older than
    /// `stale_after`) and older than what they sounded since, as the fallback counts them
    /// (see [`SoundFallback::candidates`]), to stand in for their radio claims. A robot
    /// whose own sends fail while it still hears the team is taken for gone by its
    /// teammates' radio; its claims by sound keep it in their arbitration, so they and it
    /// decide on the same claims. A teammate that is gone sounds nothing and drops out by
    /// the radio's rule, as before.
    pub fn sounded_for_stale(
        &mut self,
        me: u8,
        now_s: f64,
        radio: &[Candidate],
        stale_after: Duration,
    ) -> Vec<Candidate> {
        self.promote(now_s);
        let mut out = Vec::new();
        for id in self.plan.ids().filter(|&id| id != me) {
            let by_radio = radio.iter().find(|c| c.robot == id);
            if by_radio.is_some_and(|c| c.age <= stale_after) {
                continue;
            }
            let radio_at = by_radio.map_or(f64::NEG_INFINITY, |c| now_s - c.age.as_secs_f64());
            if let Some(t) = self.sounded.get(usize::from(id) - 1).copied().flatten() {
                if t.at_s > radio_at && now_s - t.at_s <= self.expire_s {
                    out.push(self.candidate(id, t, now_s));
                }
            }
        }
        out
    }

    /// Claims heard whose slot has ended come into force.
    fn promote(&mut self, now_s: f64) {
        for (pending, sounded) in self.pending.iter_mut().zip(&mut self.sounded) {
            if let Some(p) = pending.filter(|p| p.at_s <= now_s) {
                if sounded.is_none_or(|s| s.at_s <= p.at_s) {
                    *sounded = Some(p);
                }
                *pending = None;
            }
        }
    }

    /// Robot `id`'s claim `t` as robot `me` counts it at `now_s`: fresh (age zero), a
    /// claim to be going in doubt once its sender's last slot went by unheard.
    fn candidate(&self, id: u8, t: Told, now_s: f64) -> Candidate {
        let mut posted = t.posted;
        if self.doubt_going && now_s - t.at_s > self.plan.cycle_s() + DOUBT_MARGIN_S {
            // Its last slot went by unheard: a claim to be going is in doubt (it may have
            // let go in the message this robot missed), so it keeps its cost but not the
            // goer's margin. A robot's own claim too: its teammates doubt it when its
            // radio claim has stood a cycle before its first slot came, and it must
            // decide as they do, or it goes on beside the robot they now name.
            posted.going = false;
        }
        Candidate {
            robot: id,
            posted,
            age: Duration::ZERO,
        }
    }

    /// The team's decision on `candidates` (see [`SoundFallback::candidates`]): the
    /// arbitration's rule (lowest cost, the goer's by the hysteresis margin, ties to the
    /// lower id), so robots that heard the same claims agree.
    pub fn decide(&self, candidates: &[Candidate]) -> Decision {
        arbitration::decide(&self.params, candidates)
    }
}

/// The message that carries a claim (see the module docs for the values).
pub fn encode_claim(posted: Posted, no_ball_cost: f64) -> Message {
    let value = if !(posted.h.is_finite() && posted.h < no_ball_cost) {
        0
    } else {
        let bin = ((posted.h - COST_FLOOR_M) / COST_BIN_M)
            .floor()
            .clamp(0.0, f64::from(COST_BINS - 1)) as u16;
        1 + bin + if posted.going { COST_BINS } else { 0 }
    };
    let sender = Sender::from_index((value / 21) as u8).expect("value < 63");
    Message::short(sender, (value % 21) as u8).expect("data < 21")
}

/// The claim a message carries (bin centres), or `None` for a long message.
pub fn decode_claim(message: &Message, no_ball_cost: f64) -> Option<Posted> {
    let Message::Short { sender, data } = *message else {
        return None;
    };
    let value = u16::from(sender.index()) * 21 + u16::from(data);
    if value == 0 || value >= CLAIM_VALUES {
        return Some(Posted {
            h: no_ball_cost,
            going: false,
        });
    }
    let going = value > COST_BINS;
    let bin = (value - 1) % COST_BINS;
    Some(Posted {
        h: COST_FLOOR_M + (f64::from(bin) + 0.5) * COST_BIN_M,
        going,
    })
}

#[cfg(test)]
#[path = "acoustic_agreement_tests.rs"]
mod agreement_tests;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_claim_survives_its_message_within_a_bin() {
        for going in [false, true] {
            for k in 0..40 {
                let h = -0.5 + 0.25 * f64::from(k);
                let p = Posted { h, going };
                let back = decode_claim(&encode_claim(p, 1000.0), 1000.0).unwrap();
                assert_eq!(back.going, going, "h {h}");
                if h < 8.5 {
                    assert!(
                        (back.h - h).abs() <= COST_BIN_M / 2.0 + 1e-9,
                        "h {h} → {}",
                        back.h
                    );
                }
            }
        }
        let none = decode_claim(
            &encode_claim(
                Posted {
                    h: 1000.0,
                    going: false,
                },
                1000.0,
            ),
            1000.0,
        )
        .unwrap();
        assert_eq!(none.h, 1000.0, "no ball stays no ball");
    }

    #[test]
    fn the_slot_names_the_sender() {
        let plan = SlotPlan {
            first_id: 2,
            slots: 4,
            slot_s: 0.21,
        };
        for id in 2..=5u8 {
            let k = f64::from(id - 2);
            assert!(plan.starts_in(id, 3.0 * plan.cycle_s() + k * 0.21, 0.01));
            assert_eq!(
                plan.sender_at(7.0 * plan.cycle_s() + k * 0.21 + 0.03),
                Some(id)
            );
        }
        assert!(!plan.starts_in(1, 0.0, 0.01), "the goalkeeper has no slot");
    }

    /// A robot in a lab: no GameController, teammates heard (claims' age decides).
    pub(super) fn lab() -> RadioHeartbeat {
        let mut beat = RadioHeartbeat::default();
        beat.heard_teammate(0.0);
        beat
    }

    fn radio_claim(robot: u8, h: f64, going: bool, age_s: f64) -> Candidate {
        Candidate {
            robot,
            posted: Posted { h, going },
            age: Duration::from_secs_f64(age_s),
        }
    }

    /// Four field players (ids 2–5) in the default slots, and the radio's staleness.
    fn four_slot_fallback() -> (SlotPlan, Duration, SoundFallback) {
        let cfg = AcousticConfig::default();
        let plan = SlotPlan {
            first_id: 2,
            slots: 4,
            slot_s: cfg.slot_s(),
        };
        let stale = ArbitrationParams::default().stale_after;
        let fb = SoundFallback::new(3, plan, &cfg, 5, ArbitrationParams::default());
        (plan, stale, fb)
    }

    #[test]
    fn the_radio_goer_keeps_the_ball_until_a_claim_heard_in_the_room_beats_it() {
        let (plan, stale, mut fb) = four_slot_fallback();
        // Robot 3 at 11.55 s: the radio still speaks; 2 goes, 4 is a little closer (within
        // the hysteresis margin).
        let at = |t: f64| {
            vec![
                radio_claim(2, 1.0, true, t - 11.5),
                radio_claim(4, 0.8, false, t - 11.5),
                radio_claim(5, 3.0, false, t - 11.5),
            ]
        };
        assert!(
            !fb.radio(3, &at(11.55), stale, &lab(), 11.55),
            "fresh radio: the arbiter decides"
        );
        fb.posted(
            11.55,
            Posted {
                h: 2.0,
                going: false,
            },
        );
        // At 12 s the radio is silent: the fallback keeps the agreed goer.
        assert!(
            fb.radio(3, &at(12.0), stale, &lab(), 12.0),
            "silent radio: the fallback decides"
        );
        let goer = |fb: &mut SoundFallback, t: f64| {
            let c = fb.candidates(3, t, &at(t));
            fb.decide(&c).goer
        };
        assert_eq!(
            goer(&mut fb, 12.0),
            Some(2),
            "the goer agreed by radio keeps the ball"
        );
        // Robot 4 sounds 0.2 m in its slot; heard 20 ms into it, it counts from its end.
        let start = (12.0 / plan.cycle_s()).floor() * plan.cycle_s() + 2.0 * plan.slot_s;
        assert_eq!(plan.sender_at(start + 0.02), Some(4));
        fb.hear(3, &claim_message(0.2, false), start + 0.02);
        let end = plan.slot_end(start + 0.02);
        assert!((end - (start + plan.slot_s)).abs() < 1e-9);
        assert_eq!(
            goer(&mut fb, end - 0.05),
            Some(2),
            "not before its slot ends"
        );
        assert_eq!(
            goer(&mut fb, end + 0.01),
            Some(4),
            "0.25 m beats 1.0 − 0.5 m"
        );
    }

    #[test]
    fn under_a_budget_the_gamecontrollers_packets_tell_a_dead_radio_from_a_quiet_one() {
        // The SPL's budget: claims hold 15 s. Robot 3's teammates last told theirs at 5 s;
        // the WLAN fails at 10 s and the GameController's packets stop with it.
        let (plan, _, mut fb) = four_slot_fallback();
        let stale = Duration::from_secs(15);
        let told = |t: f64| -> Vec<Candidate> {
            [2, 4, 5]
                .map(|id| radio_claim(id, f64::from(id), id == 2, t - 5.0))
                .to_vec()
        };
        let mut beat = RadioHeartbeat::default();
        let mut t = 0.0;
        while t <= 10.0 {
            beat.heard_gamecontroller(t);
            t += 0.5;
        }
        beat.heard_teammate(9.8);
        let start = |fb: &SoundFallback, t: f64| fb.next_slot(3, t).expect("robot 3 has a slot");
        let quiet = Posted {
            h: 3.0,
            going: false,
        };
        assert!(!fb.radio(3, &told(12.9), stale, &beat, 12.9));
        let s = start(&fb, 12.9);
        assert_eq!(
            fb.claim(3, quiet, s),
            None,
            "GC heard 2.9 s ago: nothing sounded"
        );
        assert!(
            fb.radio(3, &told(13.1), stale, &beat, 13.1),
            "neither the GC nor a teammate for 3.1 s: the fallback decides (its claims are \
             10 s from stale)"
        );
        let s = start(&fb, 13.1);
        assert!(
            fb.claim(3, quiet, s).is_some(),
            "and robot 3 sounds its claim"
        );
        // The GameController is heard again at 25 s: the radio is back, but the claims
        // are those from before the outage. The fallback keeps deciding until every
        // teammate has told one since.
        beat.heard_gamecontroller(25.0);
        assert!(fb.radio(3, &told(25.2), stale, &beat, 25.2), "handing back");
        let mut new = told(25.2);
        new[0].age = Duration::from_millis(100);
        new[1].age = Duration::from_millis(50);
        assert!(
            fb.radio(3, &new, stale, &beat, 25.2),
            "robot 5 has not told yet"
        );
        new[2].age = Duration::ZERO;
        assert!(
            !fb.radio(3, &new, stale, &beat, 25.2),
            "all told: the radio decides"
        );
        let s = start(&fb, 25.2);
        assert_eq!(fb.claim(3, quiet, s), None, "and nothing is sounded");
        // A team that never lost its radio: claims 20 s old with the GameController heard
        // are only old (out of play, or a budget's quiet spell).
        let (_, _, mut fresh) = four_slot_fallback();
        assert!(
            !fresh.radio(3, &told(25.2), stale, &beat, 25.2),
            "not the fallback's"
        );
        // In a lab (no GameController ever) the claims' age decides, as before.
        assert!(fresh.radio(3, &told(25.2), stale, &lab(), 25.2));
        assert!(plan.slot_of(3).is_some());
    }

    #[test]
    fn a_going_claim_whose_slot_went_by_unheard_loses_the_margin() {
        let (plan, stale, mut fb) = four_slot_fallback();
        let at = |t: f64| {
            vec![
                radio_claim(2, 1.0, true, t - 10.0),
                radio_claim(4, 0.7, false, t - 10.0),
                radio_claim(5, 3.0, false, t - 10.0),
            ]
        };
        fb.posted(
            10.0,
            Posted {
                h: 2.0,
                going: false,
            },
        );
        assert!(fb.radio(3, &at(10.5), stale, &lab(), 10.5));
        let goer = |fb: &mut SoundFallback, t: f64| {
            let c = fb.candidates(3, t, &at(t));
            fb.decide(&c).goer
        };
        assert_eq!(goer(&mut fb, 10.5), Some(2));
        // A cycle and more without a word from robot 2: its claim is in doubt.
        let later = 10.0 + plan.cycle_s() + DOUBT_MARGIN_S + 0.1;
        assert_eq!(
            goer(&mut fb, later),
            Some(4),
            "1.0 m without the margin loses to 0.7 m"
        );
        // Older than `stale_cycles` cycles: gone (robot 3's own claim is too).
        let expired = 10.0 + AcousticConfig::default().stale_cycles * plan.cycle_s() + 0.1;
        assert_eq!(fb.candidates(3, expired, &at(expired)), vec![]);
    }

    fn claim_message(h: f64, going: bool) -> Message {
        encode_claim(Posted { h, going }, 1000.0)
    }

    /// Robot `robot`'s view of robot 2, whose clock reads `offset_s` ahead of its own.
    fn peer_two(offset_s: f64, heard_s: f64) -> comms::PeerInfo {
        comms::PeerInfo {
            robot: 2,
            incarnation: 1,
            last_heard: comms::Instant::from_micros((heard_s * 1e6) as u64),
            present: true,
            frames: 100,
            conflicting: false,
            clock_offset_us: Some((offset_s * 1e6).round() as i64),
            clock_drift_ppm: Some(0.0),
            round_trip: Some(Duration::from_millis(3)),
            clock_samples: 20,
            clock_offset_one_way_us: None,
        }
    }

    #[test]
    fn robots_whose_clocks_are_seconds_apart_sound_and_attribute_on_the_team_clock() {
        // Robot 2's clock is the team's; robot 4's reads 7.3 s less, robot 5's 13.6 s
        // more. Each knows robot 2's offset from the replica's echoes.
        let (plan, _, _) = four_slot_fallback();
        let fallback = |me| {
            let cfg = AcousticConfig::default();
            SoundFallback::new(me, plan, &cfg, 5, ArbitrationParams::default())
        };
        let mut four = fallback(4);
        let mut five = fallback(5);
        four.update_clock(
            comms::Instant::from_micros(100_000_000),
            [peer_two(7.3, 99.9)],
        );
        five.update_clock(
            comms::Instant::from_micros(120_000_000),
            [peer_two(-13.6, 119.9)],
        );
        // Robot 4's next slot, on its own clock, is a slot start of robot 4 on the team
        // clock (slot 2 of each cycle).
        let next = four.next_slot(4, 100.0).expect("robot 4 has a slot");
        let team = next + 7.3;
        let k = (team / plan.slot_s).round();
        assert!(
            (team - k * plan.slot_s).abs() < 1e-6,
            "a slot boundary on the team clock"
        );
        assert_eq!(plan.sender_at(team + 0.02), Some(4), "and it is robot 4's");
        assert!(four.starts_in(4, next, 0.01) && !four.starts_in(4, next + 0.05, 0.01));
        // Robot 5 hears it 30 ms later on its own clock, 20.9 s apart from robot 4's:
        // the slot still names robot 4, and the claim counts from the slot's end.
        let heard_at_five = next + 7.3 - (-13.6) + 0.03;
        five.radio(5, &[], Duration::from_millis(1), &lab(), 0.0);
        five.hear(5, &claim_message(0.5, true), heard_at_five);
        let end_at_five = heard_at_five - 0.03 + plan.slot_s;
        let before = five.candidates(5, end_at_five - 0.05, &[]);
        assert!(
            before.iter().all(|c| c.robot != 4),
            "not before the slot ends: {before:?}"
        );
        let after = five.candidates(5, end_at_five + 0.01, &[]);
        let four_said = after.iter().find(|c| c.robot == 4).map(|c| c.posted);
        assert!(
            four_said.is_some_and(|p| p.going && (p.h - 0.5).abs() <= COST_BIN_M / 2.0 + 1e-9),
            "robot 5 holds robot 4's claim (going, h 0.5 m) from the end of its slot: {after:?}"
        );
        // On its own clock (no team clock) robot 5 would have put it down to another robot.
        let own = fallback(5);
        assert_ne!(
            own.plan().sender_at(heard_at_five),
            Some(4),
            "without the team clock the slot names someone else"
        );
    }

    /// Robot `robot` as a replica sees it at `heard_s`, its echoes of our frames counted
    /// `samples` times.
    fn peer(robot: u8, heard_s: f64, samples: u64) -> comms::PeerInfo {
        comms::PeerInfo {
            robot,
            clock_samples: samples,
            last_heard: comms::Instant::from_micros((heard_s * 1e6) as u64),
            ..peer_two(0.0, heard_s)
        }
    }

    #[test]
    fn a_robot_that_hears_its_teammates_but_is_not_echoed_sounds_its_claim() {
        // Robot 3 hears 2, 4 and 5 at 25 Hz; their echoes of its frames grow until 10 s,
        // then stop (its sends fail); the radio stays fresh at robot 3 all along.
        let (_, stale, mut fb) = four_slot_fallback();
        let fresh = || {
            vec![
                radio_claim(2, 1.0, true, 0.02),
                radio_claim(4, 2.0, false, 0.02),
                radio_claim(5, 3.0, false, 0.02),
            ]
        };
        let mut t: f64 = 5.0;
        let mut sounded_at = None;
        while t < 14.0 {
            let samples = (t.min(10.0) * 10.0) as u64;
            fb.update_clock(
                comms::Instant::from_micros((t * 1e6) as u64),
                [2, 4, 5].map(|id| peer(id, t - 0.01, samples)),
            );
            assert!(
                !fb.radio(3, &fresh(), stale, &lab(), t),
                "the radio decides"
            );
            if fb.unheard() && sounded_at.is_none() {
                sounded_at = Some(t);
                let m = fb.claim(
                    3,
                    Posted {
                        h: 1.5,
                        going: false,
                    },
                    t,
                );
                assert!(m.is_some(), "unheard, it sounds its claim at {t} s");
            }
            if t < 10.9 {
                assert!(!fb.unheard(), "echoed lately at {t} s");
                assert!(
                    fb.claim(
                        3,
                        Posted {
                            h: 1.5,
                            going: false
                        },
                        t
                    )
                    .is_none(),
                    "heard by radio, nothing to sound at {t} s"
                );
            }
            t += 0.04;
        }
        let at = sounded_at.expect("it took itself for unheard");
        assert!(
            (11.0..11.1).contains(&at),
            "unheard {UNHEARD_AFTER_S} s after the last echo (10 s): at {at} s"
        );
        // Hearing nobody (a full outage) is not being unheard: the radio is stale anyway.
        fb.update_clock(
            comms::Instant::from_micros(20_000_000),
            [2, 4, 5].map(|id| peer(id, 14.0, 100)),
        );
        assert!(!fb.unheard(), "nobody heard for 6 s");
    }

    #[test]
    fn a_teammate_stale_by_radio_counts_by_what_it_sounded_and_a_silent_one_drops_out() {
        // Robot 3's radio: 4 and 5 fresh, 2 stale (its sends failed at 10 s); 5's sound
        // is ignored.
        let (plan, stale, mut fb) = four_slot_fallback();
        let radio = |now: f64| {
            [
                radio_claim(2, 1.0, true, now - 10.0),
                radio_claim(4, 2.0, false, 0.02),
                radio_claim(5, 3.0, false, 0.02),
            ]
        };
        assert_eq!(
            fb.sounded_for_stale(3, 12.0, &radio(12.0), stale),
            vec![],
            "nothing heard by sound: robot 2 drops out by the radio's rule"
        );
        // Robot 2 sounds its claim in its slot (slot 0 of the cycle), robot 5 too.
        let slot2 = fb.next_slot(2, 12.0).expect("robot 2 has a slot");
        fb.hear(3, &claim_message(0.9, true), slot2 + 0.02);
        let slot5 = fb.next_slot(5, 12.0).expect("robot 5 has a slot");
        fb.hear(3, &claim_message(2.9, false), slot5 + 0.02);
        let after = slot2.max(slot5) + plan.slot_s + 0.01;
        let by_sound = fb.sounded_for_stale(3, after, &radio(after), stale);
        assert_eq!(by_sound.len(), 1, "only the stale robot: {by_sound:?}");
        assert_eq!(by_sound[0].robot, 2);
        assert!(
            by_sound[0].posted.going && (by_sound[0].posted.h - 0.9).abs() <= COST_BIN_M,
            "robot 2 counts going at about 0.9 m: {by_sound:?}"
        );
        // A cycle and more later without a word from robot 2: in doubt, not gone.
        let later = slot2 + plan.slot_s + plan.cycle_s() + DOUBT_MARGIN_S + 0.1;
        let doubted = fb.sounded_for_stale(3, later, &radio(later), stale);
        assert!(
            doubted.len() == 1 && !doubted[0].posted.going,
            "its going claim is in doubt: {doubted:?}"
        );
    }
}
