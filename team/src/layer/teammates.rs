//! What a robot hears of its teammates: their world models from the replica's blackboard
//! into its GWM, and their motion from those messages' poses. Part of [`TeamLayer`]; a
//! room of its own so that the layer's file keeps to its tick.

use comms::{Blackboard, Instant, Value};
use fusion::nalgebra::Vector2;

use super::{robot_id, seconds, TeamLayer, TeammateMotion, TEAMMATE_VELOCITY_BASELINE_S};

impl TeamLayer {
    /// Teammates' new LWMs from `board` into the GWM, at `local_now` (step 1 of a tick,
    /// see [`TeamLayer::sense`]).
    pub(super) fn hear_teammates(&mut self, board: &Blackboard, local_now: Instant) {
        let now_s = seconds(local_now);
        for j in 0..self.heard.len() {
            let id = robot_id(j);
            if id == self.id {
                continue;
            }
            let Some(e) = board.get(&self.keys.world_local_of[j]) else {
                continue;
            };
            let at = (e.incarnation, e.version);
            if self.heard[j] == Some(at) {
                continue;
            }
            self.heard[j] = Some(at);
            self.decoded[j] = None;
            if let Value::Bytes(bytes) = &e.value {
                let age_s = e.age(local_now).as_secs_f64();
                // A malformed message is the sender's bug; the GWM just does not take it.
                if let Ok(lwm) = self.gwm.decode(bytes, now_s, age_s) {
                    // A duplicate leaves the record on the message it took before.
                    if self.gwm.ingest(id, &lwm, now_s) != fusion::Ingest::Duplicate {
                        self.decoded[j] = Some(at);
                    }
                }
            }
        }
    }

    /// Each teammate's velocity from its messages' poses at least
    /// [`TEAMMATE_VELOCITY_BASELINE_S`] apart (over one message interval a pose's noise
    /// would swamp it; what the GWM keeps is the latest pose only).
    pub(super) fn track_teammates(&mut self, now_s: f64) {
        for t in self.gwm.teammates_iter(now_s) {
            let Some(slot) = usize::from(t.id)
                .checked_sub(1)
                .and_then(|k| self.teammate_motion.get_mut(k))
            else {
                continue;
            };
            let (t_s, at) = (t.lwm.t_s, Vector2::new(t.pose.mean.x, t.pose.mean.y));
            *slot = Some(match *slot {
                Some(m) if t_s >= m.anchor.0 && t_s - m.anchor.0 < TEAMMATE_VELOCITY_BASELINE_S => {
                    TeammateMotion { at, ..m }
                }
                Some(m)
                    if t_s > m.anchor.0
                        && t_s - m.anchor.0 < 4.0 * TEAMMATE_VELOCITY_BASELINE_S =>
                {
                    TeammateMotion {
                        anchor: (t_s, at),
                        velocity: (at - m.anchor.1) / (t_s - m.anchor.0),
                        at,
                    }
                }
                _ => TeammateMotion {
                    anchor: (t_s, at),
                    velocity: Vector2::zeros(),
                    at,
                },
            });
        }
    }
}
