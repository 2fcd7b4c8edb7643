//! Phong materials with the Whitted terms (mirror reflectance, transparency).

use glam::Vec3;

use crate::TextureId;

/// A surface material. Colours are linear RGB.
///
/// Mapping from MTL: `Ka`, `Kd`, `Ks`, `Ns`, `Ke` as named; `reflectance`
/// and `fresnel` by [`mtl_reflectance`]; `transmittance` is `1 - d` (or `Tr`);
/// `ior` is `Ni`.
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
    /// A thin sheet (a pane drawn as one surface): rays pass it straight,
    /// and `ior` serves only its Fresnel weights ([`Material::fresnel_ior`]).
    pub thin: bool,
    /// Reflects by the Fresnel equations whatever the job's `[quality]
    /// fresnel` says: MTL's `illum` 5 and 7 ("Fresnel on").
    pub fresnel: bool,
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
            thin: false,
            fresnel: false,
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

    /// The index of refraction of the Fresnel weights: `ior`, thin or not
    /// (1, no Fresnel rise, when it is not a positive number).
    pub fn fresnel_ior(&self) -> f32 {
        if self.ior.is_finite() && self.ior > 0.0 {
            self.ior
        } else {
            1.0
        }
    }

    /// The index of refraction rays bend by: [`Material::fresnel_ior`], or
    /// 1 for a thin sheet (rays pass it straight).
    pub fn bending_ior(&self) -> f32 {
        if self.thin { 1.0 } else { self.fresnel_ior() }
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

/// What of an MTL material decides its mirror reflectance and transmittance.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MtlOptics {
    /// `Kr` (a vtfarm extension).
    pub kr: Option<Vec3>,
    /// `illum`.
    pub illum: Option<u8>,
    /// `Ks`.
    pub ks: Option<Vec3>,
    /// `Ni`.
    pub ni: Option<f32>,
    /// What `d`, `Tr` and `Tf` let through (black for an opaque material).
    pub transmittance: Vec3,
}

/// An MTL material's Whitted terms ([`mtl_reflectance`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MtlTerms {
    /// The head-on mirror reflectance ([`Material::reflectance`]).
    pub kr: Vec3,
    /// The transmittance ([`Material::transmittance`]).
    pub kt: Vec3,
    /// Whether kr follows the Fresnel equations away from head-on
    /// ([`Material::fresnel`]).
    pub fresnel: bool,
}

/// The mirror reflectance of an MTL material, the one statement of the rule:
///
/// 1. `Kr` where given;
/// 2. otherwise `Ks` for `illum` 3 to 7, the MTL specification's "ray trace
///    on" models, whose reflection term is `Ks` times what the ray brings
///    (times the Fresnel term for 5 and 7, which is `Ks` head-on); 5 and 7
///    without `Ks` take the Fresnel reflectance at normal incidence of `Ni`
///    ([`fresnel_reflectance`]; [`GLASS_IOR`] without `Ni`);
/// 3. for any other `illum`, that Fresnel term when the material transmits
///    and has `Ni` (a dielectric), otherwise nothing.
///
/// `illum` 5 and 7 ("Fresnel on") also make the reflectance rise by the
/// Fresnel equations towards grazing angles, `Kr` or not, whatever the
/// job's `[quality] fresnel`. The refraction models 6 and 7 transmit what
/// they let through times `1 - kr` (the specification's `(1 - Ks) Tf`),
/// unless `Kr` is given (then as written, vtfarm's own export).
///
/// A job can still make a material with `Ni` > 1 and nothing else reflect
/// by Fresnel by naming it as a reflector (`vtfarm_job`).
pub fn mtl_reflectance(m: &MtlOptics) -> MtlTerms {
    let fresnel = matches!(m.illum, Some(5 | 7));
    let transmits = m.transmittance.max_element() > 0.0;
    let dielectric = |ior: f32| Vec3::splat(fresnel_reflectance(ior));
    let kr = match (m.kr, m.illum, m.ks) {
        (Some(kr), _, _) => kr,
        (None, Some(3..=7), Some(ks)) => ks,
        (None, Some(5 | 7), None) => dielectric(m.ni.unwrap_or(GLASS_IOR)),
        (None, Some(3 | 4 | 6), None) => Vec3::ZERO,
        (None, _, _) => match m.ni {
            Some(ior) if transmits => dielectric(ior),
            _ => Vec3::ZERO,
        },
    };
    let kt = match (m.kr, m.illum) {
        (None, Some(6 | 7)) => m.transmittance * (Vec3::ONE - kr).clamp(Vec3::ZERO, Vec3::ONE),
        _ => m.transmittance,
    };
    MtlTerms { kr, kt, fresnel }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rule for every `illum` model, with and without `Kr`, `Ks` and `Ni`.
    #[test]
    fn mtl_reflectance_follows_the_specification_per_illum_model() {
        let ks = Vec3::splat(0.5);
        let glass = 0.04;
        let water = (0.33f32 / 2.33).powi(2);
        let optics = |illum: Option<u8>, ks: Option<Vec3>, ni: Option<f32>, transmits: bool| {
            mtl_reflectance(&MtlOptics {
                kr: None,
                illum,
                ks,
                ni,
                transmittance: Vec3::splat(if transmits { 0.8 } else { 0.0 }),
            })
        };
        let reflectance = |illum, ni, transmits| optics(illum, Some(ks), ni, transmits).kr;
        for illum in [None, Some(0), Some(1), Some(2), Some(8), Some(9), Some(10)] {
            assert_eq!(reflectance(illum, None, false), Vec3::ZERO, "{illum:?}");
            assert_eq!(
                reflectance(illum, Some(1.5), false),
                Vec3::ZERO,
                "{illum:?}"
            );
            let dielectric = reflectance(illum, Some(1.5), true);
            assert!((dielectric - Vec3::splat(glass)).abs().max_element() < 1e-7);
            assert!(!optics(illum, Some(ks), Some(1.5), true).fresnel);
        }
        for illum in 3..=7 {
            // Ks, even at Ni 1.00 (a window written `illum 4`, `Ks 0.5`, `Ni 1.00`).
            assert_eq!(
                reflectance(Some(illum), Some(1.0), true),
                ks,
                "illum {illum}"
            );
            assert_eq!(reflectance(Some(illum), None, false), ks, "illum {illum}");
            let fresnel = optics(Some(illum), Some(ks), None, false).fresnel;
            assert_eq!(
                fresnel,
                illum == 5 || illum == 7,
                "illum {illum}: Fresnel on"
            );
        }
        for illum in [3, 4, 6] {
            assert_eq!(optics(Some(illum), None, Some(1.5), true).kr, Vec3::ZERO);
        }
        // The refraction models pass (1 - Ks) of what they let through.
        for (illum, kt) in [(3, 0.8), (4, 0.8), (5, 0.8), (6, 0.4), (7, 0.4)] {
            let terms = optics(Some(illum), Some(ks), Some(1.5), true);
            assert_eq!(terms.kt, Vec3::splat(kt), "illum {illum}");
        }
        for illum in [5, 7] {
            // Without Ks, the Fresnel term of Ni is the head-on value.
            let f = optics(Some(illum), None, Some(1.33), true).kr;
            assert!((f - Vec3::splat(water)).abs().max_element() < 1e-7, "{f}");
            let f = optics(Some(illum), None, None, false).kr;
            assert!((f - Vec3::splat(glass)).abs().max_element() < 1e-7, "{f}");
            assert_eq!(optics(Some(illum), None, Some(1.0), true).kr, Vec3::ZERO);
        }
        let kr = Vec3::new(0.1, 0.2, 0.3);
        for illum in [None, Some(2), Some(3), Some(7)] {
            let given = MtlOptics {
                kr: Some(kr),
                illum,
                ks: Some(ks),
                ni: Some(1.5),
                transmittance: Vec3::splat(0.8),
            };
            let reflection = mtl_reflectance(&given);
            assert_eq!(reflection.kr, kr, "Kr wins over illum {illum:?}");
            assert_eq!(reflection.fresnel, illum == Some(7), "illum {illum:?}");
            assert_eq!(reflection.kt, Vec3::splat(0.8), "as written, with Kr");
        }
    }
}
