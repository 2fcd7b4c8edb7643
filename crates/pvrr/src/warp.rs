//! The warped map of one reflector (paper §3.1 steps 2–4, §3.4, §4.5): per
//! vertex the exit ray and its hit P, the virtual viewpoint and frustum, the
//! map, texture coordinates that put each P exactly at its vertex, and the
//! per-point lookup (barycentric interpolation of the texture coordinates at
//! the exact surface point, then a bilinear map lookup).
//!
//! Texture coordinates are kept per colour channel: refraction with three
//! indices (§4.5, chromatic aberration) gives three sets over one shared map.
//! A vertex whose P is not in the map (the zooming region of §4.2, a path
//! that reflects totally, a point past the widest frustum, or a P hidden
//! from the virtual viewpoint by another object, §6) has no coordinate;
//! points on its triangles are traced exactly instead.

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use vtfarm_scene::{NONE, ObjectId, Scene, TriangleId};
use vtfarm_trace::SurfacePoint;
use vtfarm_vertex::barycentric;

use crate::level::Level;
use crate::map::ReflectionMap;
use crate::paths::{self, VertexPath};
use crate::viewpoint::{FrustumInput, fit_frustum, virtual_viewpoint};

/// What leaves the reflector towards the map.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Kind {
    Reflection,
    /// Refraction through front and back faces with one index of
    /// refraction per colour channel (R, G, B).
    Refraction {
        iors: [f32; 3],
    },
}

/// One vertex's data per colour channel.
#[derive(Clone, Copy, Debug, Default)]
struct VertexCoords {
    coords: [Option<Vec2>; 3],
    offset: Vec3,
    weight: Vec3,
}

/// What a lookup found.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Lookup {
    pub(crate) radiance: Vec3,
    pub(crate) object: u32,
}

/// A reflector's map and texture coordinates, ready for lookups.
pub(crate) struct Warp<'a> {
    level: Level<'a>,
    kind: Kind,
    map: ReflectionMap,
    /// The reflector's scene vertices, sorted; `vertices[i]` has `coords[i]`.
    vertices: Vec<u32>,
    coords: Vec<VertexCoords>,
}

impl<'a> Warp<'a> {
    /// Builds the map for `triangles` seen from `eye` at `level`.
    pub(crate) fn build(
        level: &Level<'a>,
        eye: Vec3,
        triangles: &[TriangleId],
        kind: Kind,
    ) -> Warp<'a> {
        let bvh = level.tracer.bvh;
        let scene = bvh.scene();
        let (vertices, points) = reflector_vertices(scene, triangles);
        let paths = vertex_paths(level, eye, &points, kind);
        let distinct: Vec<VertexPath> = paths
            .iter()
            .flat_map(|p| (0..3).filter(|&c| kind.own_path(c)).filter_map(|c| p[c]))
            .collect();
        let lines: Vec<_> = distinct.iter().map(|p| p.exit).collect();
        let hits: Vec<_> = distinct.iter().map(|p| p.hit).collect();
        let view = fit_frustum(&FrustumInput {
            eye: virtual_viewpoint(&lines),
            lines: &lines,
            hits: &hits,
            bounds: scene.bounds(),
            resolution: level.context.config.map_resolution,
        });
        let texel_level = level.deeper(kind.bounces());
        let excluded = excluded_objects(scene, triangles, &distinct);
        let map = ReflectionMap::render(&texel_level, view, &excluded);
        let coords = paths
            .par_iter()
            .map(|p| vertex_coords(&map, &texel_level, kind, p))
            .collect();
        Warp {
            level: *level,
            kind,
            map,
            vertices,
            coords,
        }
    }

    /// The radiance the reflector passes on at a point of one of its
    /// triangles seen along `incoming` (reflected, or transmitted through
    /// both faces) and the object shown there; traced (and counted) where a
    /// corner has no texture coordinate.
    pub(crate) fn radiance_at(&self, point: &SurfacePoint, incoming: Vec3) -> Lookup {
        let scene = self.level.tracer.bvh.scene();
        let corners = scene.triangles[point.triangle.index()].vertices.map(|v| {
            let i = self.vertices.binary_search(&v);
            // Invariant: points lie on the triangles the warp was built for.
            &self.coords[i.expect("a point on the warp's own reflector")]
        });
        let w = barycentric(scene.triangle_positions(point.triangle), point.position);
        let mut radiance = Vec3::ZERO;
        let mut object = NONE;
        let blend = |f: fn(&VertexCoords) -> Vec3| {
            f(corners[0]) * w[0] + f(corners[1]) * w[1] + f(corners[2]) * w[2]
        };
        let (offset, weight) = (blend(|v| v.offset), blend(|v| v.weight));
        for c in 0..3 {
            let [a, b, d] = corners.map(|v| v.coords[c]);
            let (Some(a), Some(b), Some(d)) = (a, b, d) else {
                return self.traced(point, incoming);
            };
            let at = a * w[0] + b * w[1] + d * w[2];
            radiance[c] = offset[c] + weight[c] * self.map.sample(at)[c];
            if c == 1 {
                object = self.map.object_at(at);
            }
        }
        Lookup { radiance, object }
    }

    /// The exact radiance at a point the map cannot show, by tracing.
    fn traced(&self, point: &SurfacePoint, incoming: Vec3) -> Lookup {
        self.level.count_fallback();
        let terms = self.level.tracer.surface_terms(point, incoming);
        let ray = match self.kind {
            Kind::Reflection => terms.reflection,
            Kind::Refraction { .. } => terms.refraction,
        };
        let Some(ray) = ray else {
            return Lookup {
                radiance: Vec3::ZERO,
                object: NONE,
            };
        };
        // One ray for both the object seen and its radiance: shading the hit
        // is what `Tracer::trace` does after the same intersection.
        self.level.count_rays(1);
        let bvh = self.level.tracer.bvh;
        let tracer = self.level.deeper(1).tracer;
        let Some(hit) = bvh.closest_hit(&ray, f32::INFINITY) else {
            return Lookup {
                radiance: tracer.lighting.background,
                object: NONE,
            };
        };
        Lookup {
            radiance: tracer.shade(&bvh.surface_point(&hit), ray.direction).color,
            object: bvh.scene().triangles[hit.triangle.index()].object.raw(),
        }
    }

    #[cfg(test)]
    pub(crate) fn map(&self) -> &ReflectionMap {
        &self.map
    }

    /// A lookup that the map answers, or `None` where it falls back on
    /// tracing.
    #[cfg(test)]
    pub(crate) fn mapped_at(&self, point: &SurfacePoint, incoming: Vec3) -> Option<Lookup> {
        let before = self.level.context.counts().fallbacks;
        let lookup = self.radiance_at(point, incoming);
        (self.level.context.counts().fallbacks == before).then_some(lookup)
    }
}

impl Kind {
    /// The earlier channel whose path channel `c` shares (equal indices of
    /// refraction), if any.
    fn shared_path(self, c: usize) -> Option<usize> {
        match self {
            Kind::Reflection => (c > 0).then_some(0),
            Kind::Refraction { iors } => (0..c).find(|&e| iors[e] == iors[c]),
        }
    }

    fn own_path(self, c: usize) -> bool {
        self.shared_path(c).is_none()
    }

    /// Surfaces between the eye and the map's scene: the reflector, or the
    /// lens's front and back faces.
    fn bounces(self) -> u32 {
        match self {
            Kind::Reflection => 1,
            Kind::Refraction { .. } => 2,
        }
    }
}

/// Per vertex and channel, the exit path (`None` for a vertex facing away
/// from the eye: it is never seen and its ray would only widen the frustum).
fn vertex_paths(
    level: &Level<'_>,
    eye: Vec3,
    points: &[SurfacePoint],
    kind: Kind,
) -> Vec<[Option<VertexPath>; 3]> {
    points
        .par_iter()
        .map(|point| {
            let incoming = (point.position - eye).normalize_or(Vec3::NEG_Z);
            let mut traced: [Option<VertexPath>; 3] = [None; 3];
            // A stopped package's paths stay untraced (its result is discarded).
            if point.normal.dot(incoming) >= 0.0 || level.stopped() {
                return traced;
            }
            for c in 0..3 {
                traced[c] = match (kind, kind.shared_path(c)) {
                    (_, Some(earlier)) => traced[earlier],
                    (Kind::Reflection, None) => paths::reflection(level, point, incoming),
                    (Kind::Refraction { iors }, None) => {
                        paths::refraction(level, point, incoming, iors[c])
                    }
                };
            }
            traced
        })
        .collect()
}

/// The objects the map leaves out, sorted: the reflector's and those its
/// paths pass through (a lens's back face).
fn excluded_objects(
    scene: &Scene,
    triangles: &[TriangleId],
    paths: &[VertexPath],
) -> Vec<ObjectId> {
    let mut excluded: Vec<ObjectId> = triangles
        .iter()
        .map(|&t| scene.triangles[t.index()].object)
        .chain(
            paths
                .iter()
                .map(|p| p.inner)
                .filter(|&o| o != NONE)
                .map(ObjectId),
        )
        .collect();
    excluded.sort_unstable();
    excluded.dedup();
    excluded
}

/// A vertex's texture coordinates (where the map shows its P) and its
/// back-face terms, per channel.
fn vertex_coords(
    map: &ReflectionMap,
    texel_level: &Level<'_>,
    kind: Kind,
    paths: &[Option<VertexPath>; 3],
) -> VertexCoords {
    let mut v = VertexCoords::default();
    if texel_level.stopped() {
        return v;
    }
    for (c, path) in paths.iter().enumerate() {
        let Some(path) = path else { continue };
        v.offset[c] = path.offset[c];
        v.weight[c] = path.weight[c];
        if let Some(earlier) = kind.shared_path(c) {
            v.coords[c] = v.coords[earlier];
            continue;
        }
        let coords = match path.hit {
            Some(hit) => map.view.coords_of_point(&map.projector, hit),
            None => map
                .view
                .coords_of_direction(&map.projector, path.exit.direction),
        };
        v.coords[c] = coords.filter(|_| map.shows(texel_level, path.hit, path.exit.direction));
    }
    v
}

/// The sorted distinct vertices of `triangles` and, per vertex, its surface
/// point (the vertex normal, on the lowest-numbered triangle that uses it).
pub(crate) fn reflector_vertices(
    scene: &Scene,
    triangles: &[TriangleId],
) -> (Vec<u32>, Vec<SurfacePoint>) {
    let mut owned: Vec<(u32, TriangleId)> = triangles
        .iter()
        .flat_map(|&t| scene.triangles[t.index()].vertices.map(|v| (v, t)))
        .collect();
    owned.sort_unstable();
    owned.dedup_by_key(|(v, _)| *v);
    let points = owned
        .iter()
        .map(|&(v, triangle)| SurfacePoint {
            position: scene.positions[v as usize],
            normal: scene.normals[v as usize],
            triangle,
        })
        .collect();
    (owned.into_iter().map(|(v, _)| v).collect(), points)
}
