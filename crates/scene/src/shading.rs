//! Local Phong shading, shared by the rasterizer (base frame) and the ray
//! tracer (every Whitted hit) so both light a surface identically.

use glam::Vec3;

use crate::{Light, Lighting, Material};

/// Local Phong radiance at a surface point: emission + ambient + for each
/// light (diffuse + specular) times the light's radiance.
///
/// `normal` is the unit shading normal, `to_eye` the unit direction from the
/// point towards the viewer. `light_visible` answers the shadow test for a
/// light given the unit direction to it and its distance; the rasterizer
/// passes `|_, _, _| true` (no shadows).
pub fn phong(
    material: &Material,
    lighting: &Lighting,
    position: Vec3,
    normal: Vec3,
    to_eye: Vec3,
    mut light_visible: impl FnMut(&Light, Vec3, f32) -> bool,
) -> Vec3 {
    // Shade the side facing the viewer: sheets are two-sided.
    let n = if normal.dot(to_eye) < 0.0 {
        -normal
    } else {
        normal
    };
    let mut color = material.emission + material.ambient * lighting.ambient;
    for light in &lighting.lights {
        let (to_light, distance) = light.direction_from(position);
        let n_dot_l = n.dot(to_light);
        if n_dot_l <= 0.0 || !light_visible(light, to_light, distance) {
            continue;
        }
        let mut term = material.diffuse * n_dot_l;
        if material.specular.max_element() > 0.0 {
            let reflected = 2.0 * n_dot_l * n - to_light;
            let r_dot_v = reflected.dot(to_eye).max(0.0);
            term += material.specular * r_dot_v.powf(material.shininess.max(1.0));
        }
        color += term * light.radiance();
    }
    color
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::LightKind;

    #[test]
    fn head_on_light_gives_ambient_plus_diffuse_plus_full_highlight() {
        let mut m = Material::diffuse("m", Vec3::splat(0.5));
        m.specular = Vec3::splat(0.25);
        m.shininess = 10.0;
        let lighting = Lighting {
            lights: vec![Light {
                kind: LightKind::Point {
                    position: Vec3::Z * 2.0,
                },
                color: Vec3::ONE,
                intensity: 2.0,
            }],
            ambient: Vec3::splat(0.1),
            background: Vec3::ZERO,
        };
        let c = phong(&m, &lighting, Vec3::ZERO, Vec3::Z, Vec3::Z, |_, _, _| true);
        assert!(
            (c - Vec3::splat(0.05 + (0.5 + 0.25) * 2.0))
                .abs()
                .max_element()
                < 1e-5
        );
        let shadowed = phong(&m, &lighting, Vec3::ZERO, Vec3::Z, Vec3::Z, |_, _, _| false);
        assert!((shadowed - Vec3::splat(0.05)).abs().max_element() < 1e-6);
    }
}
