//! Plane geometry: the team layer's ([`team::geometry`]), which robots and the field share.

pub use team::geometry::*;
