//! Adaptive progressive vertex tracing (Ullmann et al., section 3): traces
//! reflector vertices instead of pixels, refines edges where colours or ray
//! trees differ, and fills the last small triangles per pixel.
//!
//! Architecture invariant: the result for a reflector triangle depends only on
//! that triangle, the scene and the frame set-up, never on which other
//! triangles share its package. The farm splits work on this.

/// How far the vertex tracer goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Quality {
    /// Trace the mesh vertices only, Gouraud-interpolate between them.
    Preview,
    /// Adaptive edge refinement without triangle filling.
    Refine,
    /// Refinement plus per-pixel triangle filling.
    Full,
    /// Every reflector pixel ray traced: the ground truth.
    Reference,
}

impl Quality {
    pub const ALL: [Quality; 4] = [
        Quality::Preview,
        Quality::Refine,
        Quality::Full,
        Quality::Reference,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Quality::Preview => "preview",
            Quality::Refine => "refine",
            Quality::Full => "full",
            Quality::Reference => "reference",
        }
    }

    pub fn from_name(name: &str) -> Option<Quality> {
        Quality::ALL.into_iter().find(|q| q.name() == name)
    }
}

/// The vertex tracer's thresholds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VertexSettings {
    pub quality: Quality,
    /// Colour difference (per channel, in 8-bit sRGB units / 255) above which an
    /// edge is refined.
    pub epsilon: f32,
    /// Edges shorter than this on screen (pixels) are not refined: the paper's
    /// 2-pixel floor.
    pub pixel_floor: f32,
    /// The flatness factor v: a face with h / c < v has its long edge c split.
    pub flatness: f32,
    /// Maximum refinement depth (splits along one lineage).
    pub max_depth: u32,
    /// Half-size of the ID-buffer neighbourhood checked for vertex visibility.
    pub visibility_radius: u32,
    /// Relative depth tolerance of the visibility test.
    pub depth_tolerance: f32,
}

impl Default for VertexSettings {
    fn default() -> Self {
        VertexSettings {
            quality: Quality::Full,
            epsilon: 2.0 / 255.0,
            pixel_floor: 2.0,
            flatness: 0.2,
            max_depth: 16,
            visibility_radius: 1,
            depth_tolerance: 0.01,
        }
    }
}

mod composite;
mod package;
mod refine;

pub use composite::{FrameImage, draw_wireframe};
pub use package::{
    FinishedFace, PackageOptions, PackageResult, PackageStats, PixelValue, SparseBitmap,
    trace_package,
};

use glam::Vec3;
use package::PixelRect;
use vtfarm_raster::IdBuffer;
use vtfarm_scene::{Camera, Projector, ScreenPoint, TriangleId};
use vtfarm_trace::{Sample, SurfacePoint, Tracer};

/// For each scene vertex, the lowest triangle id that uses it. A corner shared
/// by several reflector triangles is traced once per package, as the surface
/// point of this owner, so its sample cannot depend on which of the triangles
/// happened to be in the package. Built once per scene.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VertexOwners(Vec<TriangleId>);

impl VertexOwners {
    pub fn new(scene: &vtfarm_scene::Scene) -> Self {
        let mut owners = vec![vtfarm_scene::NONE; scene.positions.len()];
        for (t, tri) in scene.triangles.iter().enumerate() {
            for v in tri.vertices {
                owners[v as usize] = owners[v as usize].min(t as TriangleId);
            }
        }
        VertexOwners(owners)
    }

    /// The owner of vertex `v`.
    pub(crate) fn of(&self, v: u32) -> TriangleId {
        self.0[v as usize]
    }
}

/// Everything a package needs about its frame: the tracer (scene, BVH,
/// lighting), the camera, the frame's ID buffer and the thresholds.
#[derive(Clone, Copy)]
pub struct Frame<'a> {
    pub tracer: Tracer<'a>,
    pub camera: Camera,
    pub ids: &'a IdBuffer,
    /// The ID buffer of the opaque scene without the reflectors: what a
    /// transparent reflector shows behind it (see [`behind_id_buffer`]).
    pub behind: &'a IdBuffer,
    pub owners: &'a VertexOwners,
    pub settings: VertexSettings,
}

impl Frame<'_> {
    fn projector(&self) -> Projector {
        Projector::new(&self.camera)
    }

    /// Whether `triangle` is see-through, so [`Frame::behind`] hints at what it shows.
    fn see_through(&self, triangle: TriangleId) -> bool {
        self.tracer
            .bvh
            .scene()
            .material_of(triangle)
            .transmittance
            .max_element()
            > 0.0
    }

    /// The object behind the reflectors at pixel (x, y), or `NONE` off screen.
    fn behind_object(&self, x: i64, y: i64) -> u32 {
        if x < 0 || y < 0 || x >= self.behind.width as i64 || y >= self.behind.height as i64 {
            return vtfarm_scene::NONE;
        }
        self.behind.object[self.behind.index(x as u32, y as u32)]
    }

    /// Whether the object behind the reflectors changes along the screen
    /// segment from `a` to `b` (sampled every pixel).
    fn behind_changes_along(&self, a: ScreenPoint, b: ScreenPoint) -> bool {
        let steps = (b.x - a.x).abs().max((b.y - a.y).abs()).ceil().max(1.0) as u32;
        let at = |i: u32| {
            let t = i as f32 / steps as f32;
            self.behind_object(
                (a.x + (b.x - a.x) * t).floor() as i64,
                (a.y + (b.y - a.y) * t).floor() as i64,
            )
        };
        let first = at(0);
        (1..=steps).any(|i| at(i) != first)
    }

    /// The object behind the reflectors at pixel (x, y) when its 4-neighbours
    /// show the same (refraction shifts the view by about a pixel), else `None`.
    fn behind_around(&self, x: u32, y: u32) -> Option<u32> {
        let (x, y) = (x as i64, y as i64);
        let o = self.behind_object(x, y);
        [(1, 0), (-1, 0), (0, 1), (0, -1)]
            .iter()
            .all(|(dx, dy)| self.behind_object(x + dx, y + dy) == o)
            .then_some(o)
    }

    /// Whether the ID buffer assigns pixel (x, y) to `triangle`.
    fn owns(&self, triangle: TriangleId, x: u32, y: u32) -> bool {
        self.ids.triangle[self.ids.index(x, y)] == triangle
    }

    /// The rectangle that holds every pixel `triangle` owns, or `None` when it
    /// owns none (hidden or off screen: it costs nothing then).
    fn owned_rect(&self, triangle: TriangleId) -> Option<PixelRect> {
        let projector = self.projector();
        let corners = self
            .tracer
            .bvh
            .scene()
            .triangle_positions(triangle)
            .map(|p| projector.project(p));
        let full = PixelRect {
            x0: 0,
            y0: 0,
            x1: self.ids.width,
            y1: self.ids.height,
        };
        let rect = match corners {
            [Some(a), Some(b), Some(c)] => {
                let clamp = |v: f32, hi: u32| v.clamp(0.0, hi as f32) as u32;
                PixelRect {
                    x0: clamp(a.x.min(b.x).min(c.x).floor() - 1.0, self.ids.width),
                    y0: clamp(a.y.min(b.y).min(c.y).floor() - 1.0, self.ids.height),
                    x1: clamp(a.x.max(b.x).max(c.x).ceil() + 1.0, self.ids.width),
                    y1: clamp(a.y.max(b.y).max(c.y).ceil() + 1.0, self.ids.height),
                }
            }
            // A corner behind the eye: the projection is unbounded, search all.
            _ => full,
        };
        let owns_any =
            (rect.y0..rect.y1).any(|y| (rect.x0..rect.x1).any(|x| self.owns(triangle, x, y)));
        owns_any.then_some(rect)
    }

    /// The visibility test of section 3: a vertex is visible when a pixel in
    /// a small neighbourhood of its projection shows the same reflector object
    /// at about the vertex's depth (vertices lie on edges, so their own pixel
    /// may belong to a neighbour).
    fn vertex_visible(&self, triangle: TriangleId, s: ScreenPoint) -> bool {
        let object = self.tracer.bvh.scene().triangles[triangle as usize].object;
        let r = self.settings.visibility_radius as i64;
        let (cx, cy) = (s.x.floor() as i64, s.y.floor() as i64);
        let tolerance = self.settings.depth_tolerance * s.depth;
        (cy - r..=cy + r).any(|y| {
            (cx - r..=cx + r).any(|x| {
                if x < 0 || y < 0 || x >= self.ids.width as i64 || y >= self.ids.height as i64 {
                    return false;
                }
                let i = self.ids.index(x as u32, y as u32);
                self.ids.object[i] == object && (self.ids.depth[i] - s.depth).abs() <= tolerance
            })
        })
    }

    /// Traces a reflector vertex: the primary ray runs from the eye to the
    /// vertex, no intersection needed.
    fn shade_vertex(&self, triangle: TriangleId, position: Vec3, normal: Vec3) -> Sample {
        let incoming = (position - self.camera.eye).normalize();
        self.tracer.shade(
            &SurfacePoint {
                position,
                normal,
                triangle,
            },
            incoming,
        )
    }

    /// Traces pixel (x, y) on `triangle` (see [`pixel_surface`]). The
    /// reference and triangle filling both use this, so filled pixels are
    /// exactly the reference.
    fn trace_pixel(&self, triangle: TriangleId, x: u32, y: u32) -> Sample {
        let scene = self.tracer.bvh.scene();
        let (point, direction) = pixel_surface(scene, &self.camera, self.ids, triangle, x, y);
        self.tracer.shade(&point, direction)
    }
}

/// The surface point of `triangle` seen through pixel (x, y) and the unit
/// direction of that pixel's eye ray: the ray through the pixel centre hits
/// the triangle's plane (every sub-triangle lies in it) and the normal is
/// interpolated barycentrically. Every method that shades reflector pixels
/// uses this, so they all shade the same points.
pub fn pixel_surface(
    scene: &vtfarm_scene::Scene,
    camera: &Camera,
    ids: &IdBuffer,
    triangle: TriangleId,
    x: u32,
    y: u32,
) -> (SurfacePoint, Vec3) {
    let [a, b, c] = scene.triangle_positions(triangle);
    let [na, nb, nc] = scene.triangle_normals(triangle);
    let direction = camera.pixel_ray(x, y);
    let plane_normal = (b - a).cross(c - a);
    let denom = direction.dot(plane_normal);
    let t = if denom.abs() > 1e-12 {
        (a - camera.eye).dot(plane_normal) / denom
    } else {
        // Grazing: fall back on the rasterized depth.
        let forward = camera.basis().0;
        ids.depth[ids.index(x, y)] / direction.dot(forward)
    };
    let position = camera.eye + direction * t;
    let [wa, wb, wc] = barycentric([a, b, c], position);
    let normal = (na * wa + nb * wb + nc * wc).normalize_or(plane_normal.normalize_or(Vec3::Y));
    let point = SurfacePoint {
        position,
        normal,
        triangle,
    };
    (point, direction)
}

/// The ID buffer of what lies behind the reflectors: every triangle that is
/// neither a reflector nor transparent. Deterministic like every ID buffer, so
/// workers rebuild it.
pub fn behind_id_buffer(
    scene: &vtfarm_scene::Scene,
    camera: &Camera,
    is_reflector: &[bool],
) -> IdBuffer {
    vtfarm_raster::id_buffer_where(scene, camera, &|t| {
        !is_reflector[t as usize] && scene.material_of(t).transmittance.max_element() <= 0.0
    })
}

/// Barycentric weights of `p` (on the triangle's plane) in the triangle
/// `[a, b, c]`; a degenerate triangle gives equal weights.
pub fn barycentric([a, b, c]: [Vec3; 3], p: Vec3) -> [f32; 3] {
    let n = (b - a).cross(c - a);
    let area = n.length_squared();
    if area <= 0.0 {
        return [1.0 / 3.0; 3];
    }
    let wa = (c - b).cross(p - b).dot(n) / area;
    let wb = (a - c).cross(p - c).dot(n) / area;
    [wa, wb, 1.0 - wa - wb]
}

#[cfg(test)]
mod tests;
