//! Per-vertex exit rays (paper §3.1 steps 1 and 3.1, §4.5): the exact ray
//! that leaves the reflector at a vertex, and the scene point P it hits.
//!
//! Reflection is the tracer's own mirror ray. Refraction bends the eye ray at
//! the front face, follows it to the next surface (the back face) and bends
//! it again there, both times with the given index of refraction, so one
//! material can be traced with three indices for chromatic aberration.

use glam::Vec3;
use vtfarm_scene::NONE;
use vtfarm_trace::{Ray, SurfacePoint, refract};

use crate::level::Level;

/// A vertex's exit ray and what the ray tracer would add on the way.
#[derive(Clone, Copy, Debug)]
pub(crate) struct VertexPath {
    pub(crate) exit: Ray,
    /// P, where the exit ray meets the scene.
    pub(crate) hit: Option<Vec3>,
    /// The object the path passed through (a lens's back face), or `NONE`.
    pub(crate) inner: u32,
    /// Radiance along the front ray = `offset + weight * radiance(exit)`:
    /// what the back face adds itself (its local Phong and internal
    /// reflection) and its kt. Reflection: zero and one.
    pub(crate) offset: Vec3,
    pub(crate) weight: Vec3,
}

/// The mirror ray at a reflector vertex seen along `incoming`.
pub(crate) fn reflection(
    level: &Level<'_>,
    point: &SurfacePoint,
    incoming: Vec3,
) -> Option<VertexPath> {
    let exit = level.tracer.surface_terms(point, incoming).reflection?;
    Some(VertexPath {
        hit: closest_point(level, &exit),
        exit,
        inner: NONE,
        offset: Vec3::ZERO,
        weight: Vec3::ONE,
    })
}

/// The doubly refracted ray at a lens vertex seen along `incoming`, with
/// index of refraction `ior` at both faces. `None` where the front or back
/// does not transmit, the front ray leaves the scene, or a face reflects
/// totally.
pub(crate) fn refraction(
    level: &Level<'_>,
    point: &SurfacePoint,
    incoming: Vec3,
    ior: f32,
) -> Option<VertexPath> {
    let bvh = level.tracer.bvh;
    let inside = bend(level, point, incoming, ior)?;
    level.count_searches(1);
    let back_hit = bvh.closest_hit(&inside, f32::INFINITY)?;
    let back = bvh.surface_point(&back_hit);
    let exit = bend(level, &back, inside.direction, ior)?;
    // The back face is the second surface along the ray: its own terms come
    // from the tracer one level down, its internal reflection two levels down.
    let at_back = level.deeper(1);
    let terms = at_back.tracer.surface_terms(&back, inside.direction);
    let (mut offset, mut weight) = (terms.local, Vec3::ZERO);
    if at_back.recurses() {
        weight = terms.kt;
        if let Some(ray) = terms.reflection {
            offset += terms.kr * at_back.deeper(1).tracer.trace(&ray).color;
            level.count_rays(1);
        }
    }
    Some(VertexPath {
        hit: closest_point(level, &exit),
        exit,
        inner: bvh.scene().triangles[back.triangle.index()].object.raw(),
        offset,
        weight,
    })
}

/// Snell at a surface point with index `ior` (entering or leaving as the
/// geometric normal says, like the tracer), as a ray leaving the surface.
fn bend(level: &Level<'_>, point: &SurfacePoint, incoming: Vec3, ior: f32) -> Option<Ray> {
    let bvh = level.tracer.bvh;
    let material = bvh.scene().material_of(point.triangle);
    if material.transmittance.max_element() <= 0.0 {
        return None;
    }
    let geometric = bvh.geometric_normal(point.triangle);
    let normal = point.normal.normalize_or(geometric);
    let facing = if normal.dot(incoming) > 0.0 {
        -normal
    } else {
        normal
    };
    let eta = if geometric.dot(incoming) < 0.0 {
        1.0 / ior
    } else {
        ior
    };
    let direction = refract(incoming, facing, eta)?;
    Some(bvh.spawn_ray(point.position, point.triangle, direction))
}

fn closest_point(level: &Level<'_>, ray: &Ray) -> Option<Vec3> {
    level.count_searches(1);
    level
        .tracer
        .bvh
        .closest_hit(ray, f32::INFINITY)
        .map(|h| ray.origin + ray.direction * h.t)
}
