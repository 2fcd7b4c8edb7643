//! The heat-map colour ramp: matplotlib's *inferno* (CC0, by Nathaniel J.
//! Smith and Stéfan van der Walt), sampled at 16 evenly spaced control points
//! and interpolated linearly in sRGB. Its lightness rises monotonically from
//! black to pale yellow, so brighter glare reads as brighter colour also in
//! grayscale prints.

use glam::Vec3;
use vtfarm_imaging::srgb_to_linear;

/// The 16 control points (sRGB, 0..1) at `t = i / 15`: entries
/// 0, 17, 34, …, 255 of the 256-entry inferno table.
pub const INFERNO_SRGB: [[f32; 3]; 16] = [
    [0.001462, 0.000466, 0.013866],
    [0.046915, 0.030324, 0.150164],
    [0.142378, 0.046242, 0.308553],
    [0.258234, 0.038571, 0.406485],
    [0.366529, 0.071579, 0.431994],
    [0.472328, 0.110547, 0.428334],
    [0.578304, 0.148039, 0.404411],
    [0.682656, 0.189501, 0.360757],
    [0.780517, 0.243327, 0.299523],
    [0.865006, 0.316822, 0.226055],
    [0.929644, 0.411479, 0.145367],
    [0.970919, 0.522853, 0.058367],
    [0.987622, 0.645320, 0.039886],
    [0.978806, 0.774545, 0.176037],
    [0.950018, 0.903409, 0.380271],
    [0.988362, 0.998364, 0.644924],
];

/// The colour of a value above its scale's top (cyan, outside the ramp), so
/// that a clipped value is never read as the top of the scale.
pub const BEYOND_SCALE_SRGB: [u8; 3] = [0, 230, 255];

/// [`BEYOND_SCALE_SRGB`] as a linear RGB colour.
pub fn beyond_scale_color() -> Vec3 {
    let [r, g, b] = BEYOND_SCALE_SRGB.map(|c| srgb_to_linear(f32::from(c) / 255.0));
    Vec3::new(r, g, b)
}

/// The ramp colour at `t` (clamped to [0, 1]; NaN counts as 0), as a
/// **linear** RGB colour ready for [`vtfarm_imaging::Image`].
pub fn ramp_color(t: f32) -> Vec3 {
    let t = if t.is_nan() { 0.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (INFERNO_SRGB.len() - 1) as f32;
    let i = (x.floor() as usize).min(INFERNO_SRGB.len() - 2);
    let f = x - i as f32;
    let a = Vec3::from_array(INFERNO_SRGB[i]);
    let b = Vec3::from_array(INFERNO_SRGB[i + 1]);
    let s = a + (b - a) * f;
    Vec3::new(
        srgb_to_linear(s.x),
        srgb_to_linear(s.y),
        srgb_to_linear(s.z),
    )
}
