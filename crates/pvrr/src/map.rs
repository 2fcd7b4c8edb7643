//! The first pass (paper §3.1 step 2): the reflection map, the scene without
//! the reflector rasterized from the virtual viewpoint through the §3.3
//! frustum, and its bilinear lookup.
//!
//! The frustum's near plane lies just in front of the reflector (the virtual
//! viewpoint of a convex mirror lies behind the mirror, inside whatever is
//! there), so the map is an ID buffer with that near plane
//! (`vtfarm_raster::id_buffer_clipped`) over every triangle but the excluded
//! objects': per texel the triangle seen at the texel centre. The texel's
//! surface point is where the ray through the texel centre meets that
//! triangle's plane, with the barycentric normal, as
//! `vtfarm_vertex::pixel_surface` reconstructs a pixel's; it is then shaded
//! as a ray-traced hit seen from the virtual viewpoint.
//!
//! The occlusion test of §6 ([`ReflectionMap::shows`]) still casts one ray
//! per vertex: it asks whether the virtual viewpoint sees a given point, at
//! full precision rather than at the nearest texel centre.

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use vtfarm_raster::IdBuffer;
use vtfarm_scene::{Camera, NONE, ObjectId, Projector, Scene, TriangleId};
use vtfarm_trace::Ray;

use crate::level::{Level, Seen};
use crate::viewpoint::MapView;

/// Surfaces of excluded objects passed on one occlusion ray at most; more means
/// a degenerate stack of coincident sheets.
const MAX_SKIPS: usize = 16;

/// How close, relative to its distance, a visible point must be to P to be P.
const SAME_POINT: f32 = 1e-3;

/// The first surface beyond the near plane, in `direction` from the virtual
/// viewpoint, that is not one of `excluded` (sorted): by one ray from the
/// near plane, what the map's z-buffer shows in that exact direction.
fn first_visible(
    level: &Level<'_>,
    view: &MapView,
    excluded: &[ObjectId],
    direction: Vec3,
) -> Option<Seen> {
    let bvh = level.tracer.bvh;
    let scene = bvh.scene();
    let forward = view.camera.basis().0;
    let start = view.near / direction.dot(forward).max(1e-6);
    let mut ray = Ray {
        origin: view.camera.eye + direction * start,
        direction,
    };
    for _ in 0..MAX_SKIPS {
        let hit = bvh.closest_hit(&ray, f32::INFINITY)?;
        let object = scene.triangles[hit.triangle.index()].object;
        let point = bvh.surface_point(&hit);
        if excluded.binary_search(&object).is_err() {
            return Some(Seen {
                point,
                incoming: direction,
                object,
            });
        }
        ray = bvh.spawn_ray(point.position, point.triangle, direction);
    }
    None
}

/// The surface seen at the centre of texel (`x`, `y`) of the map's ID buffer:
/// where the ray through the texel centre meets the plane of the triangle
/// seen there (its view depth where the ray grazes the plane), with the
/// barycentric vertex normal.
fn texel_surface(scene: &Scene, camera: &Camera, ids: &IdBuffer, x: u32, y: u32) -> Option<Seen> {
    let triangle = TriangleId::from_raw(ids.triangle_at(x, y))?;
    let (point, direction) = vtfarm_vertex::pixel_surface(scene, camera, ids, triangle, x, y);
    Some(Seen {
        point,
        incoming: direction,
        object: ObjectId(ids.object_at(x, y)),
    })
}

/// A rendered reflection (or refraction) map.
pub(crate) struct ReflectionMap {
    pub(crate) view: MapView,
    pub(crate) projector: Projector,
    radiance: Vec<Vec3>,
    object: Vec<u32>,
    /// The objects left out (the reflector itself), sorted.
    excluded: Vec<ObjectId>,
}

impl ReflectionMap {
    /// Renders the map: rasterizes the scene without `excluded` (sorted)
    /// from the virtual viewpoint with the view's near plane, and shades each
    /// texel's visible surface point by `level` as seen from there (multiple
    /// reflection recurses there).
    pub(crate) fn render(level: &Level<'_>, view: MapView, excluded: &[ObjectId]) -> Self {
        let camera = view.camera;
        let scene = level.tracer.bvh.scene();
        let keep = |t: TriangleId| {
            excluded
                .binary_search(&scene.triangles[t.index()].object)
                .is_err()
        };
        let ids = vtfarm_raster::id_buffer_clipped(scene, &camera, view.near, &keep);
        let texels = (camera.width * camera.height) as usize;
        let seen: Vec<Option<Seen>> = (0..texels)
            .into_par_iter()
            .map(|i| {
                let (x, y) = (i as u32 % camera.width, i as u32 / camera.width);
                texel_surface(scene, &camera, &ids, x, y)
            })
            .collect();
        level.count_texels(texels as u64);
        let radiance = level.shade_seen(camera.eye, &seen);
        ReflectionMap {
            projector: Projector::new(&camera),
            view,
            radiance,
            object: seen
                .iter()
                .map(|s| s.map_or(NONE, |s| s.object.raw()))
                .collect(),
            excluded: excluded.to_vec(),
        }
    }

    /// Whether the map shows the scene point `p` (a hit P) or, for `None`,
    /// the empty background in `direction` from the virtual viewpoint: the
    /// occlusion test of §6, one ray.
    pub(crate) fn shows(&self, level: &Level<'_>, p: Option<Vec3>, direction: Vec3) -> bool {
        let eye = self.view.camera.eye;
        level.count_rays(1);
        let Some(p) = p else {
            return first_visible(level, &self.view, &self.excluded, direction).is_none();
        };
        let distance = p.distance(eye);
        let towards = (p - eye) / distance;
        first_visible(level, &self.view, &self.excluded, towards)
            .is_some_and(|s| s.point.position.distance(p) <= distance * SAME_POINT)
    }

    /// Bilinear lookup at continuous map coordinates (texel centres at +0.5),
    /// clamped at the border.
    pub(crate) fn sample(&self, at: Vec2) -> Vec3 {
        let (w, h) = (self.view.camera.width, self.view.camera.height);
        let fx = (at.x - 0.5).clamp(0.0, (w - 1) as f32);
        let fy = (at.y - 0.5).clamp(0.0, (h - 1) as f32);
        let (x0, y0) = (fx.floor() as u32, fy.floor() as u32);
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (tx, ty) = (fx - x0 as f32, fy - y0 as f32);
        let texel = |x: u32, y: u32| self.radiance[(y * w + x) as usize];
        let top = texel(x0, y0).lerp(texel(x1, y0), tx);
        let bottom = texel(x0, y1).lerp(texel(x1, y1), tx);
        top.lerp(bottom, ty)
    }

    /// The object of the texel containing `at`.
    pub(crate) fn object_at(&self, at: Vec2) -> u32 {
        let (w, h) = (self.view.camera.width, self.view.camera.height);
        let x = (at.x.max(0.0) as u32).min(w - 1);
        let y = (at.y.max(0.0) as u32).min(h - 1);
        self.object[(y * w + x) as usize]
    }
}
