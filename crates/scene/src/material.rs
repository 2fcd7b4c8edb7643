//! Phong materials with the Whitted terms (mirror reflectance, transparency).

use glam::Vec3;

use crate::TextureId;

/// A surface material. Colours are linear RGB.
///
/// Mapping from MTL: `Ka`, `Kd`, `Ks`, `Ns`, `Ke` as named; `reflectance`
/// by [`mtl_reflectance`]; `transmittance` is `1 - d` (or `Tr`); `ior` is `Ni`.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    /// Ambient reflectance (Ka).
    pub ambient: Vec3,
    /// Diffuse reflectance (Kd).
    pub diffuse: Vec3,
    /// Specular reflectance of the Phong highlight (Ks).
    pub specular: Vec3,
    /// Phong exponent (Ns).
    pub shininess: f32,
    /// Emitted radiance (Ke): windows, sky panels, lamps.
    pub emission: Vec3,
    /// Mirror reflectance kr (weight of the reflected ray).
    pub reflectance: Vec3,
    /// Transmittance kt (weight of the refracted ray).
    pub transmittance: Vec3,
    /// Index of refraction (Ni).
    pub ior: f32,
    /// A base-colour texture (`map_Kd`): its colour multiplies `diffuse`
    /// and `ambient`.
    pub diffuse_texture: Option<TextureId>,
    /// An alpha texture (`map_d`): it multiplies the opacity `1 -
    /// transmittance`.
    pub alpha_texture: Option<TextureId>,
}

impl Material {
    /// A plain diffuse material.
    pub fn diffuse(name: &str, color: Vec3) -> Self {
        Material {
            name: name.to_owned(),
            ambient: color,
            diffuse: color,
            specular: Vec3::ZERO,
            shininess: 1.0,
            emission: Vec3::ZERO,
            reflectance: Vec3::ZERO,
            transmittance: Vec3::ZERO,
            ior: 1.0,
            diffuse_texture: None,
            alpha_texture: None,
        }
    }

    /// Whether rays continue from this surface (mirror or transparent).
    pub fn is_specular(&self) -> bool {
        self.reflectance.max_element() > 0.0 || self.see_through()
    }

    /// Whether any point of the surface lets light through (a
    /// transmittance, or an alpha texture that can make it see-through):
    /// glass. The thin-glass model's layers and the tracer's
    /// reflected/transmitted split both go by it.
    pub fn see_through(&self) -> bool {
        self.transmittance.max_element() > 0.0 || self.alpha_texture.is_some()
    }

    /// Whether a texture changes this material from point to point.
    pub fn is_textured(&self) -> bool {
        self.diffuse_texture.is_some() || self.alpha_texture.is_some()
    }
}

impl Default for Material {
    fn default() -> Self {
        Material::diffuse("default", Vec3::splat(0.6))
    }
}

/// The index of refraction assumed for a glass `illum` model (5, 7) without `Ni`.
pub const GLASS_IOR: f32 = 1.5;

/// The Fresnel reflectance at normal incidence of a dielectric with index of
/// refraction `ior` in air: `((ior - 1) / (ior + 1))²` (0.04 for glass, 0
/// at `ior` 1).
pub fn fresnel_reflectance(ior: f32) -> f32 {
    if ior.is_finite() && ior > 0.0 {
        ((ior - 1.0) / (ior + 1.0)).powi(2)
    } else {
        0.0
    }
}

/// What of an MTL material decides its mirror reflectance.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MtlOptics {
    /// `Kr` (a vtfarm extension).
    pub kr: Option<Vec3>,
    /// `illum`.
    pub illum: Option<u8>,
    /// `Ks`, black when not given.
    pub ks: Vec3,
    /// `Ni`.
    pub ni: Option<f32>,
    /// Whether the material lets light through (`d` < 1, `Tr` or `Tf`).
    pub transmits: bool,
}

/// The mirror reflectance of an MTL material, the one statement of the rule:
///
/// 1. `Kr` where given;
/// 2. otherwise `Ks` for `illum` 3, 4 and 6 (the MTL specification's
///    "ray trace on" models without Fresnel);
/// 3. Fresnel at normal incidence from `Ni` ([`fresnel_reflectance`];
///    [`GLASS_IOR`] without `Ni`) for `illum` 5 and 7 ("Fresnel on");
/// 4. for any other `illum`, that Fresnel term when the material transmits
///    and has `Ni` (a dielectric), otherwise nothing.
///
/// A job can still make a material with `Ni` > 1 and nothing else reflect
/// by Fresnel by naming it as a reflector (`vtfarm_job`).
pub fn mtl_reflectance(m: &MtlOptics) -> Vec3 {
    match (m.kr, m.illum) {
        (Some(kr), _) => kr,
        (None, Some(3 | 4 | 6)) => m.ks,
        (None, Some(5 | 7)) => Vec3::splat(fresnel_reflectance(m.ni.unwrap_or(GLASS_IOR))),
        (None, _) => match m.ni {
            Some(ior) if m.transmits => Vec3::splat(fresnel_reflectance(ior)),
            _ => Vec3::ZERO,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rule for every `illum` model, with and without `Kr` and `Ni`.
    #[test]
    fn mtl_reflectance_follows_the_specification_per_illum_model() {
        let ks = Vec3::splat(0.5);
        let glass = 0.04;
        let water = (0.33f32 / 2.33).powi(2);
        let reflectance = |illum: Option<u8>, ni: Option<f32>, transmits: bool| {
            mtl_reflectance(&MtlOptics {
                kr: None,
                illum,
                ks,
                ni,
                transmits,
            })
        };
        for illum in [None, Some(0), Some(1), Some(2), Some(8), Some(9), Some(10)] {
            assert_eq!(reflectance(illum, None, false), Vec3::ZERO, "{illum:?}");
            assert_eq!(
                reflectance(illum, Some(1.5), false),
                Vec3::ZERO,
                "{illum:?}"
            );
            let dielectric = reflectance(illum, Some(1.5), true);
            assert!((dielectric - Vec3::splat(glass)).abs().max_element() < 1e-7);
        }
        for illum in [3, 4, 6] {
            // Ks, even at Ni 1.00 (a window written `illum 4`, `Ks 0.5`, `Ni 1.00`).
            assert_eq!(
                reflectance(Some(illum), Some(1.0), true),
                ks,
                "illum {illum}"
            );
            assert_eq!(reflectance(Some(illum), None, false), ks, "illum {illum}");
        }
        for illum in [5, 7] {
            let f = reflectance(Some(illum), Some(1.33), true);
            assert!((f - Vec3::splat(water)).abs().max_element() < 1e-7, "{f}");
            let f = reflectance(Some(illum), None, false);
            assert!((f - Vec3::splat(glass)).abs().max_element() < 1e-7, "{f}");
            assert_eq!(reflectance(Some(illum), Some(1.0), true), Vec3::ZERO);
        }
        let kr = Vec3::new(0.1, 0.2, 0.3);
        for illum in [None, Some(2), Some(3), Some(7)] {
            let given = MtlOptics {
                kr: Some(kr),
                illum,
                ks,
                ni: Some(1.5),
                transmits: true,
            };
            assert_eq!(mtl_reflectance(&given), kr, "Kr wins over illum {illum:?}");
        }
    }
}
