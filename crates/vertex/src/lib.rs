//! Adaptive progressive vertex tracing (Ullmann et al., section 3): traces
//! reflector vertices instead of pixels, refines edges where colours or ray
//! trees differ, and fills the last small triangles per pixel.
//!
//! Architecture invariant: the result for a reflector triangle depends only on
//! that triangle, the scene and the frame set-up, never on which other
//! triangles share its package. The farm splits work on this.

/// How far the vertex tracer goes, in the order a progressive frame goes
/// ([`ProgressivePackage`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
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
    /// At `full`, edges longer than this on screen (pixels) are split even
    /// when their end samples agree: a reflected object smaller than the gap
    /// between two samples would otherwise be missed (the sampling-density
    /// guarantee). `refine` is the paper's progressive level and trusts its
    /// corner samples, as the paper's refinement does.
    pub max_edge: f32,
    /// Where a see-through reflector's transmitted part comes from.
    pub transmission: Transmission,
    /// Conservative capture (`capture.rs`): emitters at least this bright
    /// (cd/m²) are looked for in every reflector face's cone of reflected
    /// directions, as a directional light's disc always is; a face that may
    /// mirror one is split and, at `full`, traced per pixel.
    pub capture_cd_m2: f32,
}

/// The default [`VertexSettings::capture_cd_m2`]: 50,000 cd/m², lamps,
/// LEDs and sunlit specular highlights rather than sky and windows (a
/// cover glass of kr 0.04 mirrors such a source at 2,000 cd/m² and more,
/// four times the 500 cd/m² glare threshold of `vtfarm-glare`). A
/// vtfarm engineering default; lower it to capture dimmer sources at the
/// cost of more traced pixels.
pub const DEFAULT_CAPTURE_CD_M2: f32 = 50_000.0;

/// Where the transmitted part of a see-through reflector comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Transmission {
    /// Thin shells (cover glass, windows, windshields): what the glass lets
    /// through is the rasterized opaque scene behind it, shaded per pixel and
    /// weighted per pixel by the glass's transmittance (for a shell that is
    /// a slab with a back surface, by both surfaces'); only the reflection is
    /// vertex traced, so refinement follows reflection edges alone.
    #[default]
    Raster,
    /// Thick or lens-like refractors: the refraction ray is traced with the
    /// rest of the Whitted tree, at vertices and filled pixels alike.
    Traced,
}

impl Transmission {
    pub const ALL: [Transmission; 2] = [Transmission::Raster, Transmission::Traced];

    pub fn name(self) -> &'static str {
        match self {
            Transmission::Raster => "raster",
            Transmission::Traced => "traced",
        }
    }

    pub fn from_name(name: &str) -> Option<Transmission> {
        Transmission::ALL.into_iter().find(|t| t.name() == name)
    }
}

/// The smallest accepted [`VertexSettings::pixel_floor`]: edges shorter than
/// half a pixel are never split, so a triangle covering P pixels gets at most
/// about 8P faces whatever `epsilon` and `flatness` say (a floor of 0 with
/// epsilon 0 refined hard edges down to float noise).
pub const MIN_PIXEL_FLOOR: f32 = 0.5;
/// The deepest accepted [`VertexSettings::max_depth`]: 32 halvings take a
/// 16384-pixel edge below the smallest pixel floor.
pub const MAX_REFINE_DEPTH: u32 = 32;
/// The widest accepted [`VertexSettings::visibility_radius`]: the test costs
/// `(2r + 1)^2` ID-buffer reads per vertex.
pub const MAX_VISIBILITY_RADIUS: u32 = 64;

impl VertexSettings {
    /// Checks every bound: `epsilon` and `depth_tolerance` finite and not
    /// negative, `pixel_floor` finite and at least [`MIN_PIXEL_FLOOR`],
    /// `flatness` 0 to 1, `max_depth` at most [`MAX_REFINE_DEPTH`],
    /// `visibility_radius` at most [`MAX_VISIBILITY_RADIUS`].
    pub fn validate(&self) -> Result<(), OutOfBounds> {
        non_negative("epsilon", self.epsilon)?;
        check(
            "pixel_floor",
            self.pixel_floor,
            format!("finite and at least {MIN_PIXEL_FLOOR} (pixels)"),
            |f| f.is_finite() && f >= MIN_PIXEL_FLOOR,
        )?;
        check("flatness", self.flatness, "between 0 and 1", |v| {
            (0.0..=1.0).contains(&v)
        })?;
        check(
            "max_depth",
            self.max_depth,
            format!("0 to {MAX_REFINE_DEPTH}"),
            |d| d <= MAX_REFINE_DEPTH,
        )?;
        check(
            "visibility_radius",
            self.visibility_radius,
            format!("0 to {MAX_VISIBILITY_RADIUS}"),
            |r| r <= MAX_VISIBILITY_RADIUS,
        )?;
        non_negative("depth_tolerance", self.depth_tolerance)?;
        non_negative("max_edge", self.max_edge)?;
        non_negative("capture_cd_m2", self.capture_cd_m2)?;
        Ok(())
    }
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
            max_edge: 24.0,
            transmission: Transmission::Raster,
            capture_cd_m2: DEFAULT_CAPTURE_CD_M2,
        }
    }
}

mod capture;
mod composite;
mod fill;
mod package;
mod refine;
mod stop;
mod thin;

pub use composite::{Components, FrameImage, draw_wireframe};
pub use package::{
    FinishedFace, PackageOptions, PackageResult, PackageStats, PhaseTimes, PixelBits, PixelValue,
    ProgressivePackage, SparseBitmap, StageError, StageMesh, TracedPackage, corner_meshes,
    trace_package, trace_package_into,
};
pub use stop::{Stop, Stopped};
pub use thin::{Behind, GlassPass, IdBufferCache, ShadowCache, ShadowViews, SlabWeights};
pub use vtfarm_raster::PixelRect;

use glam::Vec3;
use vtfarm_raster::IdBuffer;
use vtfarm_scene::bounds::{OutOfBounds, check, non_negative};
use vtfarm_scene::{Camera, Projector, ScreenPoint, TriangleId};
use vtfarm_trace::{Rays, Sample, SurfacePoint, Tracer};

/// For each scene vertex, the lowest triangle id that uses it. A corner shared
/// by several reflector triangles is traced once per package, as the surface
/// point of this owner, so its sample cannot depend on which of the triangles
/// happened to be in the package. Built once per scene.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VertexOwners(Vec<TriangleId>);

impl VertexOwners {
    pub fn new(scene: &vtfarm_scene::Scene) -> Self {
        // A vertex no triangle uses keeps an owner past every triangle.
        let mut owners = vec![TriangleId(vtfarm_scene::NONE); scene.positions.len()];
        for (t, tri) in scene.triangle_ids().zip(&scene.triangles) {
            for v in tri.vertices {
                owners[v as usize] = owners[v as usize].min(t);
            }
        }
        VertexOwners(owners)
    }

    /// The owner of vertex `v`.
    pub(crate) fn of(&self, v: u32) -> TriangleId {
        self.0[v as usize]
    }
}

/// A reflector vertex seen from `eye` as a surface point and the eye ray's
/// direction.
fn vertex_point(
    eye: Vec3,
    triangle: TriangleId,
    position: Vec3,
    normal: Vec3,
) -> (SurfacePoint, Vec3) {
    let incoming = (position - eye).normalize();
    let point = SurfacePoint {
        position,
        normal,
        triangle,
    };
    (point, incoming)
}

/// Which secondary rays a vertex-traced sample's first surface spawns.
fn vertex_rays(transmission: Transmission) -> Rays {
    match transmission {
        Transmission::Raster => Rays::ReflectionOnly,
        Transmission::Traced => Rays::Both,
    }
}

/// Everything a package needs about its frame: the tracer (scene, BVH,
/// lighting), the camera, the frame's ID buffer and the thresholds.
#[derive(Clone, Copy)]
pub struct Frame<'a> {
    pub tracer: Tracer<'a>,
    pub camera: Camera,
    pub ids: &'a IdBuffer,
    /// What the reflectors show behind them (see [`Behind`]).
    pub behind: &'a Behind,
    pub owners: &'a VertexOwners,
    pub settings: VertexSettings,
    /// Cancellation and the sample budget; `None` runs to the end.
    pub stop: Option<&'a Stop>,
}

impl Frame<'_> {
    /// Whether the package must stop (see [`Stop`]).
    fn stopped(&self) -> bool {
        self.stop.is_some_and(|s| s.stopped().is_some())
    }

    /// Every traced sample counts against the budget, here in one place.
    fn charge_sample(&self) {
        self.charge_samples(1);
    }

    fn charge_samples(&self, samples: u64) {
        if let Some(stop) = self.stop {
            stop.charge(samples);
        }
    }

    fn projector(&self) -> Projector {
        Projector::new(&self.camera)
    }

    /// Whether `triangle` is see-through, so [`Frame::behind`] hints at what it shows.
    fn see_through(&self, triangle: TriangleId) -> bool {
        self.tracer.bvh.scene().material_of(triangle).see_through()
    }

    /// Whether refinement and filling watch the opaque scene behind
    /// `triangle`: only when it is see-through and its transmission is
    /// traced (rasterized transmission is exact per pixel already).
    fn behind_hints(&self, triangle: TriangleId) -> bool {
        self.settings.transmission == Transmission::Traced && self.see_through(triangle)
    }

    /// The object behind the reflectors at pixel (x, y), or `NONE` off screen.
    fn behind_object(&self, x: i64, y: i64) -> u32 {
        let ids = &self.behind.ids;
        if x < 0 || y < 0 || x >= ids.width as i64 || y >= ids.height as i64 {
            return vtfarm_scene::NONE;
        }
        ids.object_at(x as u32, y as u32)
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
        self.ids.triangle_at(x, y) == triangle.raw()
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
        let full = PixelRect::full(self.ids.width, self.ids.height);
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
        let object = self.tracer.bvh.scene().triangles[triangle.index()]
            .object
            .raw();
        let r = self.settings.visibility_radius as i64;
        let (cx, cy) = (s.x.floor() as i64, s.y.floor() as i64);
        let tolerance = self.settings.depth_tolerance * s.depth;
        (cy - r..=cy + r).any(|y| {
            (cx - r..=cx + r).any(|x| {
                if x < 0 || y < 0 || x >= self.ids.width as i64 || y >= self.ids.height as i64 {
                    return false;
                }
                let (x, y) = (x as u32, y as u32);
                self.ids.object_at(x, y) == object
                    && (self.ids.depth_at(x, y) - s.depth).abs() <= tolerance
            })
        })
    }

    /// Traces a reflector vertex: the primary ray runs from the eye to the
    /// vertex, no intersection needed. With raster transmission only the
    /// local part and the reflection are traced (see [`Transmission`]).
    fn shade_vertex(&self, triangle: TriangleId, position: Vec3, normal: Vec3) -> Sample {
        self.charge_sample();
        let (point, incoming) = self.vertex_point(triangle, position, normal);
        match self.rays() {
            Rays::ReflectionOnly => self.tracer.shade_reflection(&point, incoming),
            Rays::Both => self.tracer.shade(&point, incoming),
        }
    }

    /// [`Frame::shade_vertex`] for a batch of (triangle, position, normal),
    /// the same samples: their first reflection rays share packets
    /// ([`Tracer::shade_points`]).
    fn shade_vertices(&self, vertices: &[(TriangleId, Vec3, Vec3)]) -> Vec<Sample> {
        self.charge_samples(vertices.len() as u64);
        let points: Vec<(SurfacePoint, Vec3)> = vertices
            .iter()
            .map(|&(triangle, position, normal)| self.vertex_point(triangle, position, normal))
            .collect();
        self.tracer.shade_points(&points, self.rays())
    }

    fn vertex_point(
        &self,
        triangle: TriangleId,
        position: Vec3,
        normal: Vec3,
    ) -> (SurfacePoint, Vec3) {
        vertex_point(self.camera.eye, triangle, position, normal)
    }

    fn rays(&self) -> Rays {
        vertex_rays(self.settings.transmission)
    }

    /// Traces `pixels`, each (triangle, x, y) on its triangle (see
    /// [`pixel_surface`]), in one batch through [`Tracer::shade_points`]:
    /// neighbouring pixels' reflection rays share packets (the same values as
    /// one pixel at a time). `reference`: full Whitted, the refraction ray
    /// traced whatever the transmission setting (the reference level);
    /// otherwise traced the way vertices are and finished (see
    /// [`Frame::finish_pixel`]): triangle filling and pixels no face reaches.
    fn trace_pixels(&self, pixels: &[(TriangleId, u32, u32)], reference: bool) -> Vec<PixelValue> {
        self.charge_samples(pixels.len() as u64);
        let scene = self.tracer.bvh.scene();
        let points: Vec<(SurfacePoint, Vec3)> = pixels
            .iter()
            .map(|&(t, x, y)| pixel_surface(scene, &self.camera, self.ids, t, x, y))
            .collect();
        let rays = if reference { Rays::Both } else { self.rays() };
        let samples = self.tracer.shade_points(&points, rays);
        pixels
            .iter()
            .zip(&samples)
            .map(|(&(_, x, y), sample)| {
                let mut value = PixelValue::from_sample(self.ids.frame_index(x, y) as u32, sample);
                if !reference {
                    self.finish_pixel((x, y), &mut value);
                }
                value
            })
            .collect()
    }

    /// Finishes a vertex-traced pixel value: adds the rasterized
    /// transmitted part (zero unless the transmission comes from the
    /// rasterizer and the reflector is see-through; see [`Behind::finish`]).
    /// (`x`, `y`) is the value's pixel.
    pub fn finish_pixel(&self, (x, y): (u32, u32), value: &mut PixelValue) {
        self.behind
            .finish(&self.tracer, &self.camera, self.ids, (x, y), value);
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
    pixel_surface_along(scene, camera, ids, triangle, (x, y), camera.pixel_ray(x, y))
}

/// [`pixel_surface`] with the pixel's ray `direction` at hand (from a
/// [`Projector`], bit-identical to the camera's).
pub(crate) fn pixel_surface_along(
    scene: &vtfarm_scene::Scene,
    camera: &Camera,
    ids: &IdBuffer,
    triangle: TriangleId,
    (x, y): (u32, u32),
    direction: Vec3,
) -> (SurfacePoint, Vec3) {
    let [a, b, c] = scene.triangle_positions(triangle);
    let [na, nb, nc] = scene.triangle_normals(triangle);
    let plane_normal = (b - a).cross(c - a);
    let denom = direction.dot(plane_normal);
    let t = if denom.abs() > 1e-12 {
        (a - camera.eye).dot(plane_normal) / denom
    } else {
        // Grazing: fall back on the rasterized depth.
        let forward = camera.basis().0;
        ids.depth_at(x, y) / direction.dot(forward)
    };
    let position = camera.eye + direction * t;
    let [wa, wb, wc] = barycentric_in_plane([a, b, c], plane_normal, position);
    let normal = thin::normalize_or_else(na * wa + nb * wb + nc * wc, || {
        plane_normal.normalize_or(Vec3::Y)
    });
    let point = SurfacePoint {
        position,
        normal,
        triangle,
    };
    (point, direction)
}

/// The part of the frame the vertex tracer looks at: the bounding rectangle
/// of the reflector triangles' projections (`is_reflector` per scene
/// triangle) widened by `margin` pixels, cut to the frame; the whole frame
/// when a reflector reaches behind the eye. Every reflector pixel lies
/// inside without margin; look-ups around them need one: the frame's ID
/// buffer [`VertexSettings::visibility_radius`] + 1 (the visibility test),
/// [`Behind`] its own. ID buffers built over it
/// ([`vtfarm_raster::id_buffer_within`]) then give the vertex tracer exactly
/// what whole-frame ones give, so workers build only this part.
pub fn reflector_bounds(
    scene: &vtfarm_scene::Scene,
    camera: &Camera,
    is_reflector: &[bool],
    margin: u32,
) -> PixelRect {
    let projector = Projector::new(camera);
    let full = PixelRect::full(camera.width, camera.height);
    let (mut lo, mut hi) = (
        glam::Vec2::splat(f32::INFINITY),
        glam::Vec2::splat(f32::NEG_INFINITY),
    );
    for (t, _) in scene.triangle_ids().zip(is_reflector).filter(|(_, r)| **r) {
        for p in scene.triangle_positions(t) {
            let Some(s) = projector.project(p) else {
                return full;
            };
            lo = lo.min(glam::Vec2::new(s.x, s.y));
            hi = hi.max(glam::Vec2::new(s.x, s.y));
        }
    }
    if lo.x > hi.x {
        return PixelRect {
            x0: 0,
            y0: 0,
            x1: 0,
            y1: 0,
        };
    }
    let margin = margin as f32;
    let clamp = |v: f32, size: u32| v.clamp(0.0, size as f32) as u32;
    PixelRect {
        x0: clamp(lo.x.floor() - margin, camera.width),
        y0: clamp(lo.y.floor() - margin, camera.height),
        x1: clamp(hi.x.ceil() + 1.0 + margin, camera.width),
        y1: clamp(hi.y.ceil() + 1.0 + margin, camera.height),
    }
}

/// The ID buffer of what lies behind the reflectors: every triangle that is
/// neither a reflector nor transparent. Deterministic like every ID buffer, so
/// workers rebuild it (over [`reflector_bounds`] only, see [`Behind`]).
pub fn behind_id_buffer(
    scene: &vtfarm_scene::Scene,
    camera: &Camera,
    is_reflector: &[bool],
) -> IdBuffer {
    let full = PixelRect::full(camera.width, camera.height);
    behind_id_buffer_within(scene, camera, is_reflector, full)
}

/// [`behind_id_buffer`] over the pixels of `within` only.
fn behind_id_buffer_within(
    scene: &vtfarm_scene::Scene,
    camera: &Camera,
    is_reflector: &[bool],
    within: PixelRect,
) -> IdBuffer {
    vtfarm_raster::id_buffer_within(scene, camera, within, &|t| {
        thin::lies_behind(scene, is_reflector, t)
    })
}

/// Barycentric weights of `p` (on the triangle's plane) in the triangle
/// `[a, b, c]`; a degenerate triangle gives equal weights.
pub fn barycentric([a, b, c]: [Vec3; 3], p: Vec3) -> [f32; 3] {
    barycentric_in_plane([a, b, c], (b - a).cross(c - a), p)
}

/// [`barycentric`] with the triangle's plane normal `n` at hand: exactly
/// `(b - a).cross(c - a)`, which callers that intersect the plane have
/// worked out already (the same weights, to the bit).
pub(crate) fn barycentric_in_plane([a, b, c]: [Vec3; 3], n: Vec3, p: Vec3) -> [f32; 3] {
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
