//! vtfarm's photometric convention, written once: how lux and cd/m² become
//! the renderer's linear RGB and back.
//!
//! * **Luminance of a colour.** The photometric `Y` of a linear Rec.709/sRGB
//!   colour is `0.2126 R + 0.7152 G + 0.0722 B` ([`luminance`]).
//! * **The render unit.** A rendered radiance whose `Y` is 1 is a luminance
//!   of [`CD_M2_PER_UNIT`] = 10,000 cd/m². Luminance in cd/m² is therefore
//!   `CD_M2_PER_UNIT · Y(rgb)` ([`cd_m2`]). The renderer keeps this fixed
//!   scale instead of cd/m² themselves because its 8-bit images and the
//!   vertex tracer's refinement threshold (in sRGB steps) need values near 1:
//!   the scale is the exposure of every PNG by default (white = 10,000
//!   cd/m²; a job's `[output] white_cd_m2` sets another, [`exposure_scale`]),
//!   while the glare metrics, luminance NPYs and OpenEXR images are in
//!   cd/m² (the `.npy` of a rendered image keeps render units).
//! * **Reflected light** is the light the glass reflects toward the eye:
//!   its front surface's reflection and its back surface's (the ghost
//!   image), at every quality level (`vtfarm_trace::Sample::reflected`).
//!   For a pane of surface reflectance `R` and transmittance `T` that is
//!   `R + T²R / (1 − R²)` of what it mirrors (the tracer counts the inner
//!   bounces to its depth, the thin-glass model the first, `R + T²R`);
//!   with Fresnel weights `R` is the unpolarised Fresnel reflectance at the
//!   angle of incidence.
//! * **Emitters** (sky and window panels, backlit markings, lamps) are given
//!   a luminance `L` in cd/m² and a colour; their emission is the colour
//!   scaled to `Y = L / CD_M2_PER_UNIT` ([`emission`]).
//! * **A directional light** (the sun) of illuminance `E` lux, measured on a
//!   surface facing it, lights a Lambertian surface of reflectance `ρ` at
//!   incidence `θ` to a luminance `L = ρ · E · cos θ / π` cd/m². Local
//!   shading computes `Kd · cos θ · colour · intensity`, so the light's
//!   intensity is `E / (π · CD_M2_PER_UNIT · Y(colour))`
//!   ([`directional_intensity`]): the colour sets the hue, the lux the amount.
//!   Worked example: a white (ρ = 1) panel facing a 100,000 lx sun has
//!   `L = 100,000 / π ≈ 31,831 cd/m²`, a rendered `Y` of 3.18.
//! * **Ambient light** of illuminance `E` lux (diffuse, from every side) gives
//!   a surface of ambient reflectance `Ka` the luminance `Ka · E / π`
//!   ([`ambient`]).
//! * **Mirrors and glass** weight what they reflect by `kr` and what they
//!   transmit by `kt`, so a mirror of reflectance `kr` showing a panel of
//!   luminance `L` has the reflected luminance `kr · L`.
//!
//! Point lights keep unit-less intensities (they have no distance falloff,
//! so no candela value would mean anything).

use glam::Vec3;

/// cd/m² of a rendered radiance whose luminance `Y` is 1.
pub const CD_M2_PER_UNIT: f32 = 10_000.0;

/// Photometric luminance `Y` of a linear Rec.709/sRGB colour, in the
/// colour's own unit: `0.2126 R + 0.7152 G + 0.0722 B`.
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// The luminance in cd/m² of a rendered radiance.
pub fn cd_m2(radiance: Vec3) -> f32 {
    CD_M2_PER_UNIT * luminance(radiance)
}

/// The emission (render units) of a surface of `color`'s hue with the
/// luminance `cd_m2`; `None` for a colour without luminance (black), which
/// no amount of cd/m² can make bright.
pub fn emission(color: Vec3, cd_m2: f32) -> Option<Vec3> {
    let y = luminance(color);
    (y > 0.0).then(|| color * (cd_m2 / (CD_M2_PER_UNIT * y)))
}

/// The factor a PNG multiplies render units by so that a luminance of
/// `white_cd_m2` shows as white: 1 for [`CD_M2_PER_UNIT`], the exposure
/// of every PNG by default.
pub fn exposure_scale(white_cd_m2: f32) -> f32 {
    CD_M2_PER_UNIT / white_cd_m2
}

/// A grey of luminance `cd_m2`, in render units (backgrounds given in cd/m²).
pub fn grey(cd_m2: f32) -> Vec3 {
    Vec3::splat(cd_m2 / CD_M2_PER_UNIT)
}

/// The intensity of a directional light of `color` that delivers
/// `illuminance_lux` to a surface facing it; `None` for a black colour.
pub fn directional_intensity(color: Vec3, illuminance_lux: f32) -> Option<f32> {
    let y = luminance(color);
    (y > 0.0).then(|| illuminance_lux / (std::f32::consts::PI * CD_M2_PER_UNIT * y))
}

/// The ambient term (render units, grey) of a diffuse illuminance of
/// `illuminance_lux` from every side.
pub fn ambient(illuminance_lux: f32) -> Vec3 {
    Vec3::splat(illuminance_lux / (std::f32::consts::PI * CD_M2_PER_UNIT))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shading::phong;
    use crate::{Light, LightKind, Lighting, Material};

    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() <= 1e-5 * b.abs().max(1.0)
    }

    /// The README's worked example: a white Lambertian panel facing a
    /// 100,000 lx sun has a luminance of 100,000/π cd/m², whatever the sun's
    /// colour; at 60° incidence half of it.
    #[test]
    fn white_lambertian_panel_under_100000_lux_has_100000_over_pi_cd_m2() {
        for color in [Vec3::ONE, Vec3::new(1.0, 0.95, 0.85)] {
            let sun = Light {
                kind: LightKind::Directional {
                    direction: -Vec3::Z,
                    angular_diameter_deg: 0.0,
                },
                color,
                intensity: directional_intensity(color, 100_000.0).unwrap(),
            };
            let lighting = Lighting {
                lights: vec![sun],
                ambient: Vec3::ZERO,
                background: Vec3::ZERO,
            };
            let white = Material::diffuse("white", Vec3::ONE);
            let facing = phong(
                &white,
                &lighting,
                Vec3::ZERO,
                Vec3::Z,
                Vec3::Z,
                |_, _, _| true,
            );
            assert!(
                close(cd_m2(facing), 100_000.0 / std::f32::consts::PI),
                "{}",
                cd_m2(facing)
            );
            let tilted = Vec3::new(60f32.to_radians().sin(), 0.0, 60f32.to_radians().cos());
            let oblique = phong(&white, &lighting, Vec3::ZERO, tilted, tilted, |_, _, _| {
                true
            });
            assert!(close(cd_m2(oblique), 50_000.0 / std::f32::consts::PI));
        }
    }

    #[test]
    fn emitters_and_ambient_light_have_the_luminance_they_are_given() {
        let panel = Material {
            emission: emission(Vec3::new(0.3, 0.35, 0.45), 8_000.0).unwrap(),
            ..Material::diffuse("panel", Vec3::ZERO)
        };
        let lit = |m: &Material, ambient_lux: f32| {
            let lighting = Lighting {
                lights: Vec::new(),
                ambient: ambient(ambient_lux),
                background: Vec3::ZERO,
            };
            cd_m2(phong(
                m,
                &lighting,
                Vec3::ZERO,
                Vec3::Z,
                Vec3::Z,
                |_, _, _| true,
            ))
        };
        assert!(close(lit(&panel, 0.0), 8_000.0));
        let grey = Material::diffuse("grey", Vec3::splat(0.2));
        assert!(close(
            lit(&grey, 3_000.0),
            0.2 * 3_000.0 / std::f32::consts::PI
        ));
        assert_eq!(emission(Vec3::ZERO, 100.0), None);
        assert_eq!(directional_intensity(Vec3::ZERO, 100.0), None);
    }
}
