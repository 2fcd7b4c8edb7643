//! Phong materials with the Whitted terms (mirror reflectance, transparency).

use glam::Vec3;

/// A surface material. Colours are linear RGB.
///
/// Mapping from MTL: `Ka`, `Kd`, `Ks`, `Ns`, `Ke` as named; `reflectance`
/// comes from `Ks` when `illum` is 3, 5 or 7 (or from the `Kr` extension);
/// `transmittance` is `1 - d` (or `Tr`); `ior` is `Ni`.
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
        }
    }

    /// Whether rays continue from this surface (mirror or transparent).
    pub fn is_specular(&self) -> bool {
        self.reflectance.max_element() > 0.0 || self.see_through()
    }

    /// Whether light passes through the surface (any transmittance): glass.
    /// The thin-glass model's layers and the tracer's reflected/transmitted
    /// split both go by it.
    pub fn see_through(&self) -> bool {
        self.transmittance.max_element() > 0.0
    }
}

impl Default for Material {
    fn default() -> Self {
        Material::diffuse("default", Vec3::splat(0.6))
    }
}
