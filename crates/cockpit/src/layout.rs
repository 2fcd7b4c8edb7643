//! Where things are: the cab's interior box, its openings, the driver's eye
//! and the cover glass frame, shared by the part builders so openings and
//! the panels behind them agree.
//!
//! Metres, +Y up, the driver looks along -Z; the cab floor is at y = 0 and
//! the road 1.3 m below it. Left-hand drive: the driver sits at x < 0.

use glam::{Quat, Vec2, Vec3};

use crate::mesh::Frame;

/// Interior box of the cab (walls, floor, roof lie on its faces).
pub(crate) const CAB_MIN: Vec3 = Vec3::new(-1.15, 0.0, -1.25);
pub(crate) const CAB_MAX: Vec3 = Vec3::new(1.15, 2.0, 0.95);

/// The windshield opening in the front wall: x range, y range.
pub(crate) const WINDSHIELD_X: Vec2 = Vec2::new(-1.05, 1.05);
pub(crate) const WINDSHIELD_Y: Vec2 = Vec2::new(1.12, 1.92);

/// The door window openings in both side walls: z range, y range.
pub(crate) const SIDE_WINDOW_Z: Vec2 = Vec2::new(-1.0, 0.25);
pub(crate) const SIDE_WINDOW_Y: Vec2 = Vec2::new(1.12, 1.85);

/// Height of the road (the ground panel) below the cab floor.
pub(crate) const GROUND_Y: f32 = -1.3;

/// The driver's centre line.
pub(crate) const DRIVER_X: f32 = -0.55;

/// The driver's eye: 0.7 m behind and 0.35 m above the cover glass centre.
pub(crate) const EYE: Vec3 = Vec3::new(DRIVER_X, 1.40, 0.10);

/// Centre of the cover glass's front surface.
pub(crate) const GLASS_CENTER: Vec3 = Vec3::new(DRIVER_X, 1.05, -0.60);

/// Inner focus of the ellipsoidal glass design (the outer one is the eye):
/// 0.2 m from the glass centre, up and a little towards the driver, above
/// the driver's sight lines to the glass. A focus only a few cm from the
/// glass would give an ellipsoid too slim for a 0.46 m wide glass (its
/// minor semi-axis is at most sqrt(r1 r2), about 0.18 m at r1 = 4 cm).
pub(crate) const ABSORBER: Vec3 = Vec3::new(DRIVER_X, 1.24, -0.55);

/// The glass is turned away from facing the eye, to the driver's left and
/// downwards, so the eye sees the left door (and its window) in it rather
/// than itself.
const GLASS_YAW_DEG: f32 = 18.0;
const GLASS_PITCH_DEG: f32 = -10.0;

/// The cluster frame: origin at the glass centre, z the glass normal there
/// (towards the driver), y up along the glass, x to the driver's right.
pub(crate) fn glass_frame() -> Frame {
    let to_eye = (EYE - GLASS_CENTER).normalize();
    let horizontal = Vec3::new(to_eye.x, 0.0, to_eye.z).normalize();
    let elevation = to_eye.y.asin() + GLASS_PITCH_DEG.to_radians();
    let (sin, cos) = elevation.sin_cos();
    let pitched = horizontal * cos + Vec3::Y * sin;
    // A negative turn about +Y swings a normal facing +Z towards -X (left).
    let normal = Quat::from_rotation_y(-GLASS_YAW_DEG.to_radians()) * pitched;
    Frame::facing(GLASS_CENTER, normal, Vec3::Y)
}
