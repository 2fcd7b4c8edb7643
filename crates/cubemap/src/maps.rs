//! The reflector cube maps (paper §4.1): per texel the position and normal
//! of the reflector surface seen from the map's centre, rasterized from a
//! (possibly finer) tessellation of the reflector.
//!
//! Each texel stores an exact sample of the (subdivided) triangles: the ray
//! from the centre through the texel centre is intersected with them and the
//! hit's barycentrics interpolate position and normal, so the maps are
//! perspective-correct (a GPU interpolating colours would be too).
//!
//! An open reflector leaves texels empty; the paper then asks for a closed
//! companion object (§6.2). Instead empty texels show the reflector's
//! quadric continuation ([`QuadricPatch`]), marked
//! [`TexelKind::Extension`], so searches for vertices reflected beyond the
//! rim still converge (those vertices belong to triangles that straddle
//! the rim).

use glam::Vec3;
use rayon::prelude::*;
use vtfarm_scene::{Scene, TriangleId};

use crate::cube::{CubeLayout, TexelPoint, face};
use crate::extension::QuadricPatch;
use crate::shape::{ReflectorShape, classify, facing};

/// What a texel holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TexelKind {
    /// No surface in this direction (not even the extension).
    Empty,
    /// The reflector itself.
    Surface,
    /// The quadric continuation of an open reflector beyond its rim.
    Extension,
}

/// A reflector's position and normal cube maps.
#[derive(Clone, Debug)]
pub struct ReflectorMaps {
    pub layout: CubeLayout,
    pub position: Vec<Vec3>,
    /// Unit normals as the reflector's vertex normals orient them.
    pub normal: Vec<Vec3>,
    pub kind: Vec<TexelKind>,
    /// Area-weighted centroid of the reflector.
    pub centroid: Vec3,
    /// The largest distance of the (tessellated) reflector from `centroid`.
    pub radius: f32,
    pub shape: ReflectorShape,
}

/// A bilinear sample of the maps.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceSample {
    pub position: Vec3,
    /// Unit normal.
    pub normal: Vec3,
    /// Whether the sample lies on the reflector rather than its extension.
    pub on_reflector: bool,
}

/// One triangle of the tessellation the maps are rasterized from.
#[derive(Clone, Copy, Debug)]
struct MapTriangle {
    positions: [Vec3; 3],
    normals: [Vec3; 3],
}

impl ReflectorMaps {
    /// Builds the maps of the reflector `triangles` of `scene` at
    /// `resolution` texels per face side, from the triangles subdivided
    /// `subdivisions` times (each split in four by Phong tessellation).
    pub fn build(
        scene: &Scene,
        triangles: &[TriangleId],
        resolution: u32,
        subdivisions: u32,
    ) -> ReflectorMaps {
        let mut mesh: Vec<MapTriangle> = triangles
            .iter()
            .map(|&t| MapTriangle {
                positions: scene.triangle_positions(t),
                normals: scene.triangle_normals(t),
            })
            .collect();
        for _ in 0..subdivisions {
            mesh = mesh.iter().flat_map(subdivide).collect();
        }
        let shape = classify(scene, triangles);
        let placement = Placement::new(&mesh, shape);
        let layout = CubeLayout {
            centre: placement.centre,
            resolution: resolution.max(2),
        };
        let (position, normal, kind) = rasterize(&layout, &mesh);
        let mut maps = ReflectorMaps {
            layout,
            position,
            normal,
            kind,
            centroid: placement.centroid,
            radius: placement.radius,
            shape,
        };
        let corners: Vec<Vec3> = mesh.iter().flat_map(|t| t.positions).collect();
        if let Some(patch) = QuadricPatch::fit(&corners, placement.centroid, placement.mean_normal)
        {
            maps.extend_beyond_rim(&patch);
        }
        maps
    }

    /// The bilinear sample at a direction from the centre; `None` where
    /// every tap is empty.
    pub fn sample(&self, direction: Vec3) -> Option<SurfaceSample> {
        self.sample_at(self.layout.locate(direction))
    }

    pub(crate) fn sample_at(&self, p: TexelPoint) -> Option<SurfaceSample> {
        let mut position = Vec3::ZERO;
        let mut normal = Vec3::ZERO;
        let (mut total, mut surface) = (0.0, 0.0);
        for (index, weight) in self.layout.bilinear(p) {
            match self.kind[index] {
                TexelKind::Empty => continue,
                TexelKind::Surface => surface += weight,
                TexelKind::Extension => {}
            }
            position += self.position[index] * weight;
            normal += self.normal[index] * weight;
            total += weight;
        }
        (total > 1e-6).then(|| SurfaceSample {
            position: position / total,
            normal: normal.normalize_or_zero(),
            on_reflector: surface >= 0.5 * total,
        })
    }

    /// Fills empty texels from the quadric continuation.
    fn extend_beyond_rim(&mut self, patch: &QuadricPatch) {
        let centre = self.layout.centre;
        for index in 0..self.kind.len() {
            if self.kind[index] != TexelKind::Empty {
                continue;
            }
            let direction = self.layout.texel_direction(index);
            if let Some((position, normal)) = patch.intersect(centre, direction) {
                self.position[index] = position;
                self.normal[index] = normal;
                self.kind[index] = TexelKind::Extension;
            }
        }
    }
}

/// Splits a triangle into four at its edge midpoints. New vertices are
/// placed by Phong tessellation (Boubekeur and Alexa 2008: the midpoint
/// moved halfway towards its projections on the corners' tangent planes),
/// so finer maps follow the smooth surface the vertex normals describe;
/// normals are interpolated.
fn subdivide(t: &MapTriangle) -> [MapTriangle; 4] {
    let [a, b, c] = t.positions;
    let [na, nb, nc] = t.normals;
    let mid = |p: Vec3, q: Vec3, np: Vec3, nq: Vec3| {
        let m = (p + q) * 0.5;
        let on_p = m - (m - p).dot(np) * np;
        let on_q = m - (m - q).dot(nq) * nq;
        let curved = (on_p + on_q) * 0.5;
        (m * 0.25 + curved * 0.75, (np + nq).normalize_or(np))
    };
    let (ab, nab) = mid(a, b, na, nb);
    let (bc, nbc) = mid(b, c, nb, nc);
    let (ca, nca) = mid(c, a, nc, na);
    let tri = |positions, normals| MapTriangle { positions, normals };
    [
        tri([a, ab, ca], [na, nab, nca]),
        tri([ab, b, bc], [nab, nb, nbc]),
        tri([ca, bc, c], [nca, nbc, nc]),
        tri([ab, bc, ca], [nab, nbc, nca]),
    ]
}

/// Where the maps sit. A closed reflector's area-weighted normals cancel
/// and the centre is its centroid (the paper's choice). An open patch seen
/// from its centroid would project edge-on, so the centre moves off it by
/// the patch's radius times its openness (|Σ area·normal| / Σ area: 0
/// closed, 1 flat), to the side of its centres of curvature: in front of a
/// concave patch (inside the bowl, which every texel ray then meets once,
/// its quadric continuation included), behind a convex or flat one.
struct Placement {
    centre: Vec3,
    centroid: Vec3,
    /// The largest distance of a corner from `centroid`.
    radius: f32,
    /// Σ area·normal / Σ area.
    mean_normal: Vec3,
}

impl Placement {
    fn new(mesh: &[MapTriangle], shape: ReflectorShape) -> Placement {
        let mut area_sum = 0.0f64;
        let mut weighted = glam::DVec3::ZERO;
        let mut normal_sum = glam::DVec3::ZERO;
        for t in mesh {
            let [a, b, c] = t.positions;
            let cross = (b - a).cross(c - a);
            let area = 0.5 * f64::from(cross.length());
            let oriented = facing(cross, t.normals);
            area_sum += area;
            weighted += ((a + b + c) / 3.0).as_dvec3() * area;
            normal_sum += oriented.normalize_or_zero().as_dvec3() * area;
        }
        if area_sum <= 0.0 {
            let p = mesh.first().map_or(Vec3::ZERO, |t| t.positions[0]);
            return Placement {
                centre: p,
                centroid: p,
                radius: 0.0,
                mean_normal: Vec3::ZERO,
            };
        }
        let centroid = (weighted / area_sum).as_vec3();
        let mean_normal = (normal_sum / area_sum).as_vec3();
        let radius = mesh
            .iter()
            .flat_map(|t| t.positions)
            .map(|p| (p - centroid).length())
            .fold(0.0, f32::max);
        let side = if shape == ReflectorShape::Concave {
            1.0
        } else {
            -1.0
        };
        Placement {
            centre: centroid + mean_normal * (side * radius),
            centroid,
            radius,
            mean_normal,
        }
    }
}

/// Rasterizes the tessellation into all six faces (one rayon task per
/// face; within a face triangles go in order and the hit nearest the
/// centre wins, ties to the earlier triangle): position, normal and kind
/// per texel.
fn rasterize(layout: &CubeLayout, mesh: &[MapTriangle]) -> (Vec<Vec3>, Vec<Vec3>, Vec<TexelKind>) {
    let res = layout.resolution as usize;
    let faces: Vec<Vec<(f32, Vec3, Vec3)>> = (0..6)
        .into_par_iter()
        .map(|face_index| {
            let mut texels = vec![(f32::INFINITY, Vec3::ZERO, Vec3::ZERO); res * res];
            for t in mesh {
                rasterize_on_face(layout, face_index, t, &mut texels);
            }
            texels
        })
        .collect();
    let texels = faces.concat();
    let kind = texels
        .iter()
        .map(|&(depth, _, _)| {
            if depth.is_finite() {
                TexelKind::Surface
            } else {
                TexelKind::Empty
            }
        })
        .collect();
    (
        texels.iter().map(|t| t.1).collect(),
        texels.iter().map(|t| t.2).collect(),
        kind,
    )
}

fn rasterize_on_face(
    layout: &CubeLayout,
    face_index: usize,
    t: &MapTriangle,
    texels: &mut [(f32, Vec3, Vec3)],
) {
    let f = face(face_index);
    let res = layout.resolution;
    let local = t.positions.map(|p| {
        let d = p - layout.centre;
        Vec3::new(d.dot(f.right), d.dot(f.up), d.dot(f.forward))
    });
    if local.iter().all(|p| p.z <= 0.0) {
        return;
    }
    let half = res as f32 * 0.5;
    let (i_range, j_range) = if local.iter().all(|p| p.z > 0.0) {
        let s = local.map(|p| (p.x / p.z + 1.0) * half);
        let tt = local.map(|p| (1.0 - p.y / p.z) * half);
        let lo = |v: [f32; 3]| v[0].min(v[1]).min(v[2]).floor().max(0.0) as u32;
        let hi = |v: [f32; 3]| v[0].max(v[1]).max(v[2]).ceil().min(res as f32) as u32;
        (lo(s)..hi(s), lo(tt)..hi(tt))
    } else {
        // Crossing the face's plane through the centre: only a triangle
        // close to the centre can reach into the face; test all texels.
        let longest = (0..3)
            .map(|k| (local[k] - local[(k + 1) % 3]).length())
            .fold(0.0, f32::max);
        let nearest = local
            .iter()
            .map(|p| p.length())
            .fold(f32::INFINITY, f32::min);
        if nearest > 2.0 * longest {
            return;
        }
        (0..res, 0..res)
    };
    for j in j_range {
        for i in i_range.clone() {
            let direction = layout.direction(face_index, i as f32 + 0.5, j as f32 + 0.5);
            let Some((distance, w)) = intersect(layout.centre, direction, &t.positions) else {
                continue;
            };
            let texel = &mut texels[(j * res + i) as usize];
            if distance < texel.0 {
                let [a, b, c] = t.positions;
                let [na, nb, nc] = t.normals;
                *texel = (
                    distance,
                    a * w[0] + b * w[1] + c * w[2],
                    (na * w[0] + nb * w[1] + nc * w[2]).normalize_or(na),
                );
            }
        }
    }
}

/// Möller–Trumbore: distance along `direction` (in its units) and the
/// barycentric weights, with a small tolerance so texels on shared edges
/// are never lost.
fn intersect(origin: Vec3, direction: Vec3, [a, b, c]: &[Vec3; 3]) -> Option<(f32, [f32; 3])> {
    const TOLERANCE: f32 = 1e-5;
    let (e1, e2) = (*b - *a, *c - *a);
    let p = direction.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-20 {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - *a;
    let u = s.dot(p) * inv;
    let q = s.cross(e1);
    let v = direction.dot(q) * inv;
    let distance = e2.dot(q) * inv;
    let inside = u >= -TOLERANCE && v >= -TOLERANCE && u + v <= 1.0 + TOLERANCE;
    (inside && distance > 0.0).then(|| {
        let (u, v) = (u.clamp(0.0, 1.0), v.clamp(0.0, 1.0));
        (distance, [1.0 - u - v, u, v])
    })
}
