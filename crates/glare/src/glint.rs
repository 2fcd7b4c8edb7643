//! The glint: a source mirrored toward the eye (the sun's disc in the
//! cover glass, SAE J1757-1's direct-sunlight case), measured on a
//! luminance map (cd/m² per pixel, row-major, the camera's size; e.g.
//! [`crate::reflected_luminance`] of a frame).
//!
//! * **Peak luminance**: the brightest pixel's, in cd/m². A pixel the
//!   disc's image covers wholly has the disc's luminance times the glass's
//!   reflectance (the sun of E lux: `kr · E / Ω`, Ω its solid angle); a
//!   pixel it covers in part has its share.
//! * **Illuminance at the eye**: `E = Σ L · Ω_pixel` over the pixels at or
//!   above a luminance floor ([`vtfarm_scene::Camera::pixel_solid_angle`]),
//!   in lux on a plane facing the glint: the quantity the disability-glare
//!   formulas take. For the sun mirrored by a glass of reflectance kr it is
//!   `kr · E_sun`, whatever the resolution (the tracer gives a pixel its
//!   share of the disc).

use serde::Serialize;
use vtfarm_scene::Camera;

/// The glint figures of one luminance map (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Glint {
    pub peak_luminance_cd_m2: f32,
    pub eye_illuminance_lux: f64,
    /// Pixels at or above the floor.
    pub pixels: usize,
    /// Their solid angle in steradians.
    pub solid_angle_sr: f64,
}

/// The glint of `luminance_cd_m2` seen by `camera`, over the pixels at or
/// above `floor_cd_m2` (0 counts every pixel). Non-finite values count as 0.
///
/// # Panics
/// When the map is not the camera's size.
pub fn glint(luminance_cd_m2: &[f32], camera: &Camera, floor_cd_m2: f32) -> Glint {
    assert_eq!(
        luminance_cd_m2.len(),
        camera.width as usize * camera.height as usize,
        "a luminance map of the camera's size"
    );
    let mut g = Glint::default();
    for (i, &l) in luminance_cd_m2.iter().enumerate() {
        let l = if l.is_finite() { l } else { 0.0 };
        if l <= 0.0 || l < floor_cd_m2 {
            continue;
        }
        let (x, y) = (i as u32 % camera.width, i as u32 / camera.width);
        let omega = f64::from(camera.pixel_solid_angle(x, y));
        g.peak_luminance_cd_m2 = g.peak_luminance_cd_m2.max(l);
        g.eye_illuminance_lux += f64::from(l) * omega;
        g.pixels += 1;
        g.solid_angle_sr += omega;
    }
    g
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;

    #[test]
    fn a_uniform_map_gives_its_luminance_times_the_fields_solid_angle() {
        let camera = Camera {
            eye: Vec3::ZERO,
            target: -Vec3::Z,
            up: Vec3::Y,
            fov_y_deg: 30.0,
            width: 400,
            height: 300,
        };
        let g = glint(&vec![1000.0; 400 * 300], &camera, 0.0);
        // The field of a w × h rectangle at unit depth: 4·atan(w·h / (4·√(1 + w²/4 + h²/4))) for its half sides.
        let h = 2.0 * (15f64).to_radians().tan();
        let w = h * 400.0 / 300.0;
        let field = 4.0 * ((w * h / 4.0) / (1.0 + w * w / 4.0 + h * h / 4.0).sqrt()).atan();
        assert!(
            (g.solid_angle_sr / field - 1.0).abs() < 1e-3,
            "{} vs {field}",
            g.solid_angle_sr
        );
        assert!((g.eye_illuminance_lux / (1000.0 * field) - 1.0).abs() < 1e-3);
        assert_eq!(g.peak_luminance_cd_m2, 1000.0);
    }
}
