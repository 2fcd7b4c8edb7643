//! Deferred shading of the base frame: visibility is resolved first, then
//! each pixel is lit once with the shared local Phong model (no shadows, no
//! ray tracing).

use glam::Vec3;
use rayon::prelude::*;
use vtfarm_imaging::Image;
use vtfarm_scene::shading::phong;
use vtfarm_scene::{Camera, Lighting, NONE, Projector, Scene, TriangleId};

use crate::IdBuffer;

/// Shades every pixel of `ids`; empty pixels get the background.
pub(crate) fn shade(scene: &Scene, camera: &Camera, lighting: &Lighting, ids: &IdBuffer) -> Image {
    let mut image = Image::new(ids.width, ids.height, lighting.background);
    let width = ids.width as usize;
    if width == 0 {
        return image;
    }
    let rays = Projector::new(camera);
    image
        .pixels
        .par_chunks_mut(width)
        .zip(ids.triangle.par_chunks(width))
        .enumerate()
        .for_each(|(y, (colors, triangles))| {
            for (x, (color, &t)) in colors.iter_mut().zip(triangles).enumerate() {
                if t != NONE {
                    let dir = rays.pixel_ray(x as u32, y as u32);
                    *color = shade_pixel(scene, camera.eye, lighting, t, dir);
                }
            }
        });
    image
}

/// Phong at the point of triangle `id` seen from `eye` along the pixel ray `dir`.
fn shade_pixel(scene: &Scene, eye: Vec3, lighting: &Lighting, id: TriangleId, dir: Vec3) -> Vec3 {
    let corners = scene.triangle_positions(id).map(|p| p - eye);
    let w = perspective_barycentrics(corners, dir);
    let [n0, n1, n2] = scene.triangle_normals(id);
    let normal = (n0 * w.x + n1 * w.y + n2 * w.z)
        .try_normalize()
        .unwrap_or_else(|| scene.geometric_normal(id));
    let offset = corners[0] * w.x + corners[1] * w.y + corners[2] * w.z;
    let to_eye = (-offset).normalize_or(-dir);
    phong(
        scene.material_of(id),
        lighting,
        eye + offset,
        normal,
        to_eye,
        |_, _, _| true,
    )
}

/// The barycentric coordinates of the point where the ray from the eye along
/// `dir` meets the plane of a triangle whose `corners` are given relative to
/// the eye. Each weight is the volume of the tetrahedron spanned by the ray and
/// the opposite edge: this equals screen-space barycentrics weighted by 1/z
/// (perspective-correct interpolation) but needs no projected corners, so it
/// also holds for triangles clipped at the near plane.
fn perspective_barycentrics([a, b, c]: [Vec3; 3], dir: Vec3) -> Vec3 {
    let raw = Vec3::new(
        dir.dot(b.cross(c)),
        dir.dot(c.cross(a)),
        dir.dot(a.cross(b)),
    );
    let w = raw / raw.element_sum();
    if !w.is_finite() {
        // The ray grazes the plane: any point of the triangle will do.
        return Vec3::splat(1.0 / 3.0);
    }
    // Pixel centres lie inside the triangle up to snapping; clamp the rest.
    let w = w.max(Vec3::ZERO);
    w / w.element_sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn barycentrics_follow_the_ray_not_the_screen() {
        let corners = [
            Vec3::new(-1.0, -1.0, -1.0),
            Vec3::new(3.0, -1.0, -3.0),
            Vec3::new(-1.0, 1.0, -1.0),
        ];
        let point = corners[0] * 0.2 + corners[1] * 0.5 + corners[2] * 0.3;
        let w = perspective_barycentrics(corners, point.normalize());
        assert!(
            (w - Vec3::new(0.2, 0.5, 0.3)).abs().max_element() < 1e-5,
            "{w}"
        );
        // Independent of the corners' orientation.
        let w = perspective_barycentrics([corners[0], corners[2], corners[1]], point.normalize());
        assert!(
            (w - Vec3::new(0.2, 0.3, 0.5)).abs().max_element() < 1e-5,
            "{w}"
        );
    }
}
