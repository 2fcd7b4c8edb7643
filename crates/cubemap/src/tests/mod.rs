//! Tests: the search against an analytic mirror sphere, the grid against
//! the full search, the shape classification, and the methods on the
//! cockpit against the ray-traced reference.

mod cockpit;
pub(crate) mod scenes;
mod sphere;
