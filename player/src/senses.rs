//! What a robot's body gives its brain and takes from it: camera frames and odometry in,
//! motion commands out. The field simulator makes these from its truth; the brain sees
//! nothing else of the world.

use fusion::wrap_angle;
use serde::Serialize;
use team::Vec2;

/// One detection in the robot's frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Sighting {
    /// Distance, metres.
    pub range_m: f64,
    /// Bearing, radians, 0 = straight ahead, positive to the left.
    pub bearing_rad: f64,
}

impl Sighting {
    /// The sighting as a point in the robot's frame.
    pub fn local(&self) -> Vec2 {
        Vec2::from_angle(self.bearing_rad) * self.range_m
    }
}

/// Everything one camera frame saw.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct Frame {
    /// The ball, if detected.
    pub ball: Option<Sighting>,
    /// Whether the opponent goal's centre is in view (the seed's `front_found_other_goal()`).
    pub opponent_goal_in_view: bool,
    /// Fixed landmarks detected, by index into [`team::calibration::FieldGeometry::landmarks`].
    pub landmarks: Vec<(usize, Sighting)>,
    /// Opponent robots detected.
    pub opponents: Vec<Sighting>,
}

/// What a robot asks of its base: a velocity in the field frame and a heading.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotionCommand {
    /// Wanted velocity, field frame, m/s (capped at the top speed).
    pub velocity: Vec2,
    /// Wanted heading, radians.
    pub heading_rad: f64,
}

/// Motion measured by the wheels, in the robot's own frame at the start of the motion
/// (the Δf, Δl, Δθ of tsinghua-2005 §4).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct Odometry {
    /// Forward travel, metres.
    pub forward_m: f64,
    /// Leftward travel, metres.
    pub left_m: f64,
    /// Turn, radians (counter-clockwise positive).
    pub turn_rad: f64,
}

impl Odometry {
    /// This motion followed by `next` (composed in the frame of the first).
    pub fn then(self, next: Odometry) -> Odometry {
        let d = Vec2::new(next.forward_m, next.left_m).rotate(self.turn_rad);
        Odometry {
            forward_m: self.forward_m + d.x,
            left_m: self.left_m + d.y,
            turn_rad: wrap_angle(self.turn_rad + next.turn_rad),
        }
    }
}
