//! The ball EKF: position and velocity in the field frame with rolling friction
//! (tsinghua-2005 §4.3; cmunited-97-perception §2.3 for prediction ahead in time).
//!
//! One idea per file:
//! - `motion`: how the ball moves between sightings ([`BallModel`]);
//! - `field`: the ball on a real field, inside its boards, with speed-dependent noise
//!   ([`FieldBall`], [`Boards`]);
//! - `estimate`: a ball estimate at a time, predicted to any other ([`BallEstimate`]);
//! - `kick`: a kick as the kicker commanded it, and the estimate it leaves ([`Kick`]);
//! - `observation`: a sighting in robot coordinates as a field-frame measurement whose
//!   noise carries the pose uncertainty ([`BallSighting`], [`FieldObservation`]);
//! - `filter`: the update step and the running filter ([`update`], [`BallFilter`]);
//! - `reference`: what a team's fusion is measured against ([`CentralizedBall`],
//!   [`NetworkLimitedBall`]).

mod estimate;
mod field;
mod filter;
mod kick;
mod motion;
mod observation;
mod reference;

pub use estimate::BallEstimate;
pub use field::{Boards, FieldBall};
pub use filter::{initial_estimate, update, BallFilter, BallFilterConfig, BallUpdate};
pub use kick::Kick;
pub use motion::BallModel;
pub use observation::{
    field_observation, field_observation_shared, BallSighting, FieldObservation,
};
pub use reference::{CentralizedBall, NetworkLimitedBall};

#[cfg(test)]
mod tests;
