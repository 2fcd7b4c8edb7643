//! The scene's bounding volume hierarchy (obvhs) and the two ray queries the
//! tracer needs: closest hit and any hit (shadow rays).
//!
//! Results never depend on the BVH's shape: ties in `t` go to the lowest
//! original triangle id, and leaf boxes are padded so that rounding in the box
//! test cannot cull a triangle that the triangle test would hit. That makes
//! [`SceneBvh::closest_hit`] equal to a brute-force loop over all triangles,
//! bit for bit, whatever layout, preset or thread count built the tree.

use std::fmt;
use std::sync::Arc;

use glam::{Vec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::aabb::Aabb;
use obvhs::bvh2::Bvh2;
use obvhs::bvh2::leaf_collapser::collapse;
use obvhs::bvh2::reinsertion::ReinsertionOptimizer;
use obvhs::cwbvh::CwBvh;
use obvhs::cwbvh::bvh2_to_cwbvh::bvh2_to_cwbvh;
use obvhs::ploc::PlocBuilder;
use obvhs::ray::{Ray as BvhRay, RayHit};
use obvhs::splits::split_aabbs_preset;
use obvhs::triangle::Triangle as BvhTriangle;
use vtfarm_scene::{MaterialId, ObjectId, Scene, TriangleId};

use crate::leaf::{LaneHits, Leaves, bits};
use crate::wide::{Isa, LeafTest};
use crate::{Hit, Ray, SurfacePoint};

/// Which obvhs tree layout a [`SceneBvh`] uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BvhLayout {
    /// Compressed 8-wide BVH (`obvhs::cwbvh`), closest hits traversed
    /// nearest child first (module `wide`). As fast as `CwOctant` within the
    /// noise of `bench rays` (0.93x to 1.12x, busy 2-core machine); kept as
    /// the default because it has no 1e-4 lower bound on box entry (obvhs'
    /// test culls a box that lies entirely closer than that).
    Cw,
    /// The same tree with obvhs' own (octant-ordered) closest-hit traversal:
    /// the baseline `bench rays --layout cw-octant` measures against.
    CwOctant,
    /// Binary BVH (`obvhs::bvh2`) with collapsed multi-triangle leaves.
    Binary,
}

impl BvhLayout {
    pub const ALL: [BvhLayout; 3] = [BvhLayout::Cw, BvhLayout::CwOctant, BvhLayout::Binary];
}

/// Which obvhs build preset (`BvhBuildParams::*_build`) a [`SceneBvh`] uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BuildPreset {
    Fastest,
    VeryFast,
    Fast,
    Medium,
    /// Adds spatial pre-splits of large triangles.
    Slow,
    /// Adds spatial pre-splits and heavy reinsertion.
    VerySlow,
}

impl BuildPreset {
    /// Every preset, fastest build first.
    pub const ALL: [BuildPreset; 6] = [
        BuildPreset::Fastest,
        BuildPreset::VeryFast,
        BuildPreset::Fast,
        BuildPreset::Medium,
        BuildPreset::Slow,
        BuildPreset::VerySlow,
    ];

    /// The preset's command-line name (`very-slow`).
    pub fn name(self) -> &'static str {
        match self {
            BuildPreset::Fastest => "fastest",
            BuildPreset::VeryFast => "very-fast",
            BuildPreset::Fast => "fast",
            BuildPreset::Medium => "medium",
            BuildPreset::Slow => "slow",
            BuildPreset::VerySlow => "very-slow",
        }
    }

    fn params(self) -> BvhBuildParams {
        match self {
            BuildPreset::Fastest => BvhBuildParams::fastest_build(),
            BuildPreset::VeryFast => BvhBuildParams::very_fast_build(),
            BuildPreset::Fast => BvhBuildParams::fast_build(),
            BuildPreset::Medium => BvhBuildParams::medium_build(),
            BuildPreset::Slow => BvhBuildParams::slow_build(),
            BuildPreset::VerySlow => BvhBuildParams::very_slow_build(),
        }
    }
}

/// How to build a [`SceneBvh`]. The default is the fastest combination for
/// closest-hit queries measured by `examples/bvh_layouts.rs`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BvhOptions {
    pub layout: BvhLayout,
    pub preset: BuildPreset,
}

impl Default for BvhOptions {
    /// CwBvh with the `very_slow_build` preset: the fastest closest hit.
    /// Measured by `examples/bvh_layouts.rs` (102k-triangle room, 200k camera
    /// and random rays, one thread, busy 2-core dev box, best of 7 rounds;
    /// closest-hit ns/ray, build ms):
    ///   Cw:     Fastest 844/54, VeryFast 741/48, Fast 788/58, Medium 840/80,
    ///           Slow 773/115, VerySlow 734/269 (any hit 308 ns, also best);
    ///   Binary: Fastest 1173/22, VeryFast 1146/46, Fast 1168/47,
    ///           Medium 1176/58, Slow 1113/121, VerySlow 1028/304.
    /// Cw wins by ~30 % throughout. The slow build costs ~0.3 s per 100k
    /// triangles once per scene, against millions of rays per frame.
    fn default() -> Self {
        BvhOptions {
            layout: BvhLayout::Cw,
            preset: BuildPreset::VerySlow,
        }
    }
}

/// Calls `$recv.$method::<KX, KY, KZ>(args)` with the constant axis order
/// equal to `$axes` (a permutation made by [`ShearedRay::new`]).
macro_rules! with_axes {
    ($axes:expr, $recv:ident . $method:ident ( $($arg:expr),* )) => {
        match $axes {
            [1, 2, 0] => $recv.$method::<1, 2, 0>($($arg),*),
            [2, 1, 0] => $recv.$method::<2, 1, 0>($($arg),*),
            [2, 0, 1] => $recv.$method::<2, 0, 1>($($arg),*),
            [0, 2, 1] => $recv.$method::<0, 2, 1>($($arg),*),
            [0, 1, 2] => $recv.$method::<0, 1, 2>($($arg),*),
            axes => {
                debug_assert_eq!(axes, [1, 0, 2]);
                $recv.$method::<1, 0, 2>($($arg),*)
            }
        }
    };
}

/// Triangle data in BVH leaf order, laid out for the intersection test.
#[derive(Clone, Copy, Debug)]
pub(crate) struct PrimTriangle {
    v0: Vec3A,
    v1: Vec3A,
    v2: Vec3A,
    /// Unnormalised plane normal `(v1 - v0) x (v2 - v0)`, zero for triangles
    /// too degenerate to hit reliably.
    n: Vec3A,
}

impl PrimTriangle {
    fn new([v0, v1, v2]: [Vec3; 3]) -> Self {
        let (v0, v1, v2) = (Vec3A::from(v0), Vec3A::from(v1), Vec3A::from(v2));
        let (e1, e2) = (v1 - v0, v2 - v0);
        let n = e1.cross(e2);
        // sin(angle between the edges) below ~1e-6 is rounding noise in f32:
        // the plane (and so t) of such a sliver is meaningless, treat it as a
        // line and never hit it.
        // (Written so that NaN input also counts as degenerate.)
        let solid = n.length_squared() > 1e-12 * e1.length_squared() * e2.length_squared();
        PrimTriangle {
            v0,
            v1,
            v2,
            n: if solid { n } else { Vec3A::ZERO },
        }
    }

    pub(crate) fn corners(&self) -> [Vec3A; 3] {
        [self.v0, self.v1, self.v2]
    }

    /// Whether the triangle can be hit at all (not too degenerate).
    pub(crate) fn is_solid(&self) -> bool {
        self.n != Vec3A::ZERO
    }

    /// Two-sided ray/triangle test; returns (t, u, v) with u, v the weights of
    /// vertices 1 and 2.
    ///
    /// The watertight test of Woop, Benthin and Wald (JCGT 2013): the
    /// vertices are moved into the ray's frame (origin at 0, direction along
    /// +z after a shear), where the barycentric numerators are 2D edge
    /// functions of those vertices. A vertex shared by several triangles has
    /// the same sheared coordinates in each, so the edge functions are exact
    /// orientation tests of the same points (recomputed in f64 when f32
    /// rounds one to zero): a ray through a shared edge or vertex is inside
    /// at least one of the triangles around it, and nothing leaks through.
    /// Edges are inclusive.
    ///
    /// [`PrimTriangle::intersect_in`] does the work; this picks its axis order.
    #[cfg(test)]
    fn intersect(&self, ray: &ShearedRay) -> Option<(f32, f32, f32)> {
        with_axes!(ray.axes, self.intersect_in(ray))
    }

    /// The test for a ray whose axis order ([`ShearedRay::axes`]) is
    /// `[KX, KY, KZ]`: with the axes constant, picking a vertex's coordinate
    /// is free (by a variable axis it goes through memory).
    #[inline(always)]
    fn intersect_in<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        ray: &ShearedRay,
    ) -> Option<(f32, f32, f32)> {
        if !self.is_solid() {
            return None; // too degenerate to hit reliably
        }
        let (kx, ky, kz) = (KX, KY, KZ);
        let a = self.v0 - ray.origin;
        let b = self.v1 - ray.origin;
        let c = self.v2 - ray.origin;
        let (ax, ay) = (a[kx] - ray.shear.x * a[kz], a[ky] - ray.shear.y * a[kz]);
        let (bx, by) = (b[kx] - ray.shear.x * b[kz], b[ky] - ray.shear.y * b[kz]);
        let (cx, cy) = (c[kx] - ray.shear.x * c[kz], c[ky] - ray.shear.y * c[kz]);
        let mut w0 = cx * by - cy * bx;
        let mut w1 = ax * cy - ay * cx;
        let mut w2 = bx * ay - by * ax;
        if w0 == 0.0 || w1 == 0.0 || w2 == 0.0 {
            // Products of two f32 are exact in f64, so the sign is exact.
            let cross = |x0: f32, y0: f32, x1: f32, y1: f32| {
                (f64::from(x0) * f64::from(y1) - f64::from(y0) * f64::from(x1)) as f32
            };
            w0 = cross(cx, cy, bx, by);
            w1 = cross(ax, ay, cx, cy);
            w2 = cross(bx, by, ax, ay);
        }
        let inside = (w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0) || (w0 <= 0.0 && w1 <= 0.0 && w2 <= 0.0);
        let det = w0 + w1 + w2;
        if !inside || det == 0.0 {
            return None;
        }
        let z = ray.shear.z;
        let t = (w0 * (z * a[kz]) + w1 * (z * b[kz]) + w2 * (z * c[kz])) / det;
        let inv_det = 1.0 / det;
        // `+ 0.0` turns a -0.0 weight (on an edge) into +0.0.
        Some((t, w1 * inv_det + 0.0, w2 * inv_det + 0.0))
    }
}

/// A ray prepared for [`PrimTriangle::intersect`]: the axis permutation that
/// makes the direction's largest component z (swapping x and y when it is
/// negative, which keeps the winding) and the shear that maps the direction
/// to +z.
pub(crate) struct ShearedRay {
    pub(crate) origin: Vec3A,
    axes: [usize; 3],
    /// (Sx, Sy, Sz) of the paper.
    pub(crate) shear: Vec3A,
}

impl ShearedRay {
    fn new(origin: Vec3A, direction: Vec3A) -> ShearedRay {
        let kz = direction.abs().max_position();
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if direction[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let dz = direction[kz];
        ShearedRay {
            origin,
            axes: [kx, ky, kz],
            shear: Vec3A::new(direction[kx] / dz, direction[ky] / dz, 1.0 / dz),
        }
    }
}

/// The tree itself; `Empty` for scenes without triangles (obvhs needs one).
enum Accel {
    Empty,
    Cw(CwBvh),
    Binary(Bvh2),
}

/// The scene plus its BVH; built once per scene, shared (Send + Sync) by all threads.
///
/// Ray-origin convention: queries accept hits with `t` in `(0, t_max)`; they
/// do not skip a neighbourhood of the origin. Rays leaving a surface must
/// start slightly off it: build them with [`SceneBvh::spawn_ray`], which
/// moves the origin [`SceneBvh::spawn_distance`] off the triangle's plane.
pub struct SceneBvh {
    scene: Arc<Scene>,
    options: BvhOptions,
    accel: Accel,
    /// Indexed by BVH primitive slot (leaf order; with pre-splits a triangle
    /// can fill several slots).
    prims: Vec<PrimTriangle>,
    /// The same triangles by leaf, for the 8-wide layout's walk (empty for
    /// the others).
    leaves: Leaves,
    /// Original scene triangle id of each slot.
    prim_ids: Vec<TriangleId>,
    /// Unit geometric normals by original triangle id (zero if degenerate).
    geometric_normals: Vec<Vec3>,
    /// Whether queries run their AVX2 build ([`has_avx2`]).
    avx2: bool,
    /// Whether each slot's triangle casts shadows ([`casts_shadow`]).
    slot_casts_shadow: Vec<bool>,
    /// The scene's emitters ([`Emitter`]), by object and material.
    emitters: Vec<Emitter>,
}

/// The emitting triangles of one object and material: how bright they are
/// and where, for the vertex tracer's capture test (what a reflector face
/// may mirror). Bounds by a sphere around their box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Emitter {
    pub object: ObjectId,
    /// The luminance of the material's emission in cd/m²
    /// ([`vtfarm_scene::photometry::cd_m2`]).
    pub luminance_cd_m2: f32,
    pub centre: Vec3,
    pub radius: f32,
}

/// The emitters of `scene` ([`Emitter`]), in (object, material) order.
fn emitters_of(scene: &Scene) -> Vec<Emitter> {
    let mut boxes: std::collections::BTreeMap<(ObjectId, MaterialId), (Vec3, Vec3)> =
        Default::default();
    for (id, t) in scene.triangle_ids().zip(&scene.triangles) {
        let material = &scene.materials[t.material.index()];
        if material.emission.max_element() <= 0.0 {
            continue;
        }
        let entry = boxes
            .entry((t.object, t.material))
            .or_insert((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)));
        for p in scene.triangle_positions(id) {
            entry.0 = entry.0.min(p);
            entry.1 = entry.1.max(p);
        }
    }
    boxes
        .into_iter()
        .map(|((object, material), (lo, hi))| Emitter {
            object,
            luminance_cd_m2: vtfarm_scene::photometry::cd_m2(
                scene.materials[material.index()].emission,
            ),
            centre: (lo + hi) * 0.5,
            radius: (hi - lo).length() * 0.5,
        })
        .collect()
}

/// Whether a surface of `material` blocks light: every surface except those
/// that only emit (the panels outside the windows that stand for sky, road
/// and landscape, and lamps). They stand for light, not for an occluder, so
/// a low sun shines into a cab past the panel outside its window.
pub fn casts_shadow(material: &vtfarm_scene::Material) -> bool {
    let responds = [
        material.ambient,
        material.diffuse,
        material.specular,
        material.reflectance,
        material.transmittance,
    ]
    .iter()
    .any(|&k| k != Vec3::ZERO);
    responds || material.emission == Vec3::ZERO
}

fn triangle_casts_shadow(scene: &Scene, id: TriangleId) -> bool {
    casts_shadow(scene.material_of(id))
}

impl fmt::Debug for SceneBvh {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SceneBvh")
            .field("options", &self.options)
            .field("triangles", &self.scene.triangles.len())
            .field("primitive_slots", &self.prims.len())
            .finish()
    }
}

/// The closest hit found so far, with ties broken towards the lowest id so
/// that the result does not depend on the order triangles are visited in.
struct ClosestSoFar {
    t_max: f32,
    hit: Option<Hit>,
}

impl ClosestSoFar {
    /// Offers a candidate; returns whether it became the closest.
    #[inline(always)]
    fn offer(&mut self, triangle: TriangleId, (t, u, v): (f32, f32, f32)) -> bool {
        let better = match self.hit {
            None => t < self.t_max,
            Some(best) => t < best.t || (t == best.t && triangle < best.triangle),
        };
        // `t > 0.0` is false for NaN too.
        if better && t > 0.0 {
            self.hit = Some(Hit { triangle, t, u, v });
        }
        better && t > 0.0
    }
}

/// The distance a ray origin keeps from a surface whose coordinates are at
/// most `magnitude` in absolute value: 64 units in the last place (2^-24
/// relative) of that magnitude. Putting a point on a plane and testing a ray
/// against the plane each err by a few units in the last place of the
/// coordinates involved (about 20 together, PBRT 3.9's bounds), so 64 keeps
/// the origin on its side of the plane as the triangle test computes it.
/// Secondary rays, shadow-ray ends and every method's ray origins use this
/// one rule. The floor keeps a surface at the origin representable.
pub fn spawn_offset(magnitude: f32) -> f32 {
    (magnitude * (64.0 * f32::EPSILON * 0.5)).max(f32::MIN_POSITIVE)
}

/// The next float above a positive `t`. Traversal culls boxes entered at
/// `t >= tmax`; keeping tmax one ulp above the best hit lets a triangle at
/// exactly the same `t` (shared edges, coplanar overlaps) still be offered, so
/// the lowest-id tie-break sees every candidate.
#[inline(always)]
fn next_up(t: f32) -> f32 {
    f32::from_bits(t.to_bits() + 1)
}

/// A scene the BVH cannot be built over: it breaks [`Scene::validate`]
/// (an index out of range, or a vertex beyond
/// [`vtfarm_scene::MAX_COORDINATE`], where obvhs' build overflows and panics).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InvalidScene(pub String);

impl fmt::Display for InvalidScene {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "cannot build the BVH: {}", self.0)
    }
}

impl std::error::Error for InvalidScene {}

impl SceneBvh {
    /// Builds the BVH with the default (fastest measured) [`BvhOptions`].
    /// For scenes from outside (files, the network) use [`SceneBvh::try_new`].
    ///
    /// # Panics
    /// On a scene that breaks [`Scene::validate`].
    pub fn new(scene: Arc<Scene>) -> SceneBvh {
        SceneBvh::with_options(scene, BvhOptions::default())
    }

    /// [`SceneBvh::new`], or the reason the scene cannot have a BVH.
    pub fn try_new(scene: Arc<Scene>) -> Result<SceneBvh, InvalidScene> {
        SceneBvh::try_with_options(scene, BvhOptions::default())
    }

    /// Builds the BVH with an explicit layout and build preset (benchmarks,
    /// or trading trace speed for build time). Query results are identical
    /// for every choice.
    ///
    /// # Panics
    /// On a scene that breaks [`Scene::validate`].
    pub fn with_options(scene: Arc<Scene>, options: BvhOptions) -> SceneBvh {
        match SceneBvh::try_with_options(scene, options) {
            Ok(bvh) => bvh,
            Err(e) => panic!("{e}"),
        }
    }

    /// [`SceneBvh::with_options`], or the reason the scene cannot have a BVH.
    pub fn try_with_options(
        scene: Arc<Scene>,
        options: BvhOptions,
    ) -> Result<SceneBvh, InvalidScene> {
        scene.validate().map_err(|e| InvalidScene(e.to_string()))?;
        let count = scene.triangles.len();
        let tri_positions: Vec<[Vec3; 3]> = scene
            .triangle_ids()
            .map(|id| scene.triangle_positions(id))
            .collect();
        let geometric_normals = scene
            .triangle_ids()
            .map(|id| scene.geometric_normal(id))
            .collect();

        let (lo, hi) = scene.bounds();
        let scale = if lo.is_finite() && hi.is_finite() {
            (hi - lo)
                .max_element()
                .max(lo.abs().max_element())
                .max(hi.abs().max_element())
        } else {
            0.0
        };
        let (accel, slots) = if count == 0 {
            (Accel::Empty, Vec::new())
        } else {
            build(&tri_positions, options, scale * 1e-6)
        };
        let prims: Vec<PrimTriangle> = slots
            .iter()
            .map(|&i| PrimTriangle::new(tri_positions[i.index()]))
            .collect();
        let leaves = match &accel {
            Accel::Cw(cw) if options.layout == BvhLayout::Cw => Leaves::new(cw, &prims, &slots),
            _ => Leaves::default(),
        };
        let slot_casts_shadow = slots
            .iter()
            .map(|&i| triangle_casts_shadow(&scene, i))
            .collect();
        // Report the layout actually used (see the depth fallback in `build`).
        let options = match accel {
            Accel::Binary(_) => BvhOptions {
                layout: BvhLayout::Binary,
                ..options
            },
            _ => options,
        };

        let emitters = emitters_of(&scene);
        Ok(SceneBvh {
            scene,
            options,
            accel,
            prims,
            leaves,
            prim_ids: slots,
            geometric_normals,
            avx2: has_avx2(),
            slot_casts_shadow,
            emitters,
        })
    }

    pub fn scene(&self) -> &Scene {
        &self.scene
    }

    /// The scene's emitters, by object and material ([`Emitter`]).
    pub fn emitters(&self) -> &[Emitter] {
        &self.emitters
    }

    /// The options the BVH was built with; the layout is `Binary` when a
    /// CwBvh would have been too deep for obvhs' fixed traversal stack.
    pub fn options(&self) -> BvhOptions {
        self.options
    }

    /// How far a ray leaving `position` on `triangle` starts off the
    /// triangle's plane: [`spawn_offset`] of the largest coordinate of the
    /// point and the triangle's corners. It depends only on the hit and its
    /// own triangle, never on the scene's extent, so 1-unit details in a
    /// 500-unit scene keep 1-unit precision.
    pub fn spawn_distance(&self, position: Vec3, triangle: TriangleId) -> f32 {
        let [a, b, c] = self.scene.triangle_positions(triangle);
        let magnitude = [position, a, b, c]
            .iter()
            .map(|p| p.abs().max_element())
            .fold(0.0, f32::max);
        spawn_offset(magnitude)
    }

    /// A ray leaving the surface point `position` on `triangle` in unit
    /// direction `direction`, safe from hitting that triangle again: the
    /// origin is put on the triangle's plane (however the point was computed
    /// — barycentric interpolation, a pixel ray meeting the plane) and then
    /// [`SceneBvh::spawn_distance`] along the geometric normal, on the side
    /// the ray travels into. Tangentially the origin stays where it was. A
    /// degenerate triangle has no plane: its ray starts that distance along
    /// `direction` instead.
    pub fn spawn_ray(&self, position: Vec3, triangle: TriangleId, direction: Vec3) -> Ray {
        let distance = self.spawn_distance(position, triangle);
        let normal = self.geometric_normal(triangle);
        if normal == Vec3::ZERO {
            return Ray {
                origin: position + direction * distance,
                direction,
            };
        }
        let corner = self.scene.triangle_positions(triangle)[0];
        let side = if direction.dot(normal) >= 0.0 {
            distance
        } else {
            -distance
        };
        let height = (position - corner).dot(normal);
        Ray {
            origin: position + normal * (side - height),
            direction,
        }
    }

    /// The unit geometric normal of a triangle (counter-clockwise winding),
    /// zero for a degenerate one.
    pub fn geometric_normal(&self, triangle: TriangleId) -> Vec3 {
        self.geometric_normals[triangle.index()]
    }

    /// The surface point of a hit: the barycentric interpolation of the
    /// triangle's positions and of its vertex normals (normalised; the
    /// geometric normal where the vertex normals cancel out).
    pub fn surface_point(&self, hit: &Hit) -> SurfacePoint {
        let [p0, p1, p2] = self.scene.triangle_positions(hit.triangle);
        let [n0, n1, n2] = self.scene.triangle_normals(hit.triangle);
        let w0 = 1.0 - hit.u - hit.v;
        let normal =
            (n0 * w0 + n1 * hit.u + n2 * hit.v).normalize_or(self.geometric_normal(hit.triangle));
        SurfacePoint {
            position: p0 * w0 + p1 * hit.u + p2 * hit.v,
            normal,
            triangle: hit.triangle,
        }
    }

    /// Closest hit with t in (0, `t_max`) (see the type's docs for why the
    /// lower bound is 0). Ties go to the lowest triangle id. Triangles are
    /// two-sided; degenerate ones are never hit.
    pub fn closest_hit(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is set only where the CPU has the features
            // (`has_avx2`, checked when the BVH was built).
            return unsafe { self.closest_hit_avx2(ray, t_max) };
        }
        self.closest_hit_with(Isa::Portable, ray, t_max)
    }

    /// [`SceneBvh::closest_hit`] compiled for AVX2: the same code, so the
    /// same results, with the 8-child box test in 256-bit registers.
    ///
    /// # Safety
    /// The CPU must have the enabled features ([`has_avx2`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt,bmi1,bmi2,lzcnt")]
    unsafe fn closest_hit_avx2(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        self.closest_hit_with(Isa::Avx2, ray, t_max)
    }

    #[inline(always)]
    fn closest_hit_with(&self, isa: Isa, ray: &Ray, t_max: f32) -> Option<Hit> {
        let (origin, direction) = (Vec3A::from(ray.origin), Vec3A::from(ray.direction));
        let bvh_ray = bvh_ray(origin, direction, t_max)?;
        let sheared = ShearedRay::new(origin, direction);
        with_axes!(
            sheared.axes,
            self.closest_hit_in(isa, &bvh_ray, &sheared, t_max)
        )
    }

    /// The closest hit for a ray with axis order `[KX, KY, KZ]`.
    #[inline(always)]
    fn closest_hit_in<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        isa: Isa,
        bvh_ray: &BvhRay,
        sheared: &ShearedRay,
        t_max: f32,
    ) -> Option<Hit> {
        let mut best = ClosestSoFar { t_max, hit: None };
        let test = |best: &mut ClosestSoFar, slot: usize| match self.prims[slot]
            .intersect_in::<KX, KY, KZ>(sheared)
        {
            Some(tuv) if best.offer(self.prim_ids[slot], tuv) => {
                best.hit.map_or(f32::INFINITY, |h| next_up(h.t))
            }
            _ => f32::INFINITY,
        };
        let mut unused = RayHit::none();
        match &self.accel {
            Accel::Empty => false,
            Accel::Cw(bvh) if self.options.layout == BvhLayout::Cw => {
                let mut leaf = ClosestInLeaves::<KX, KY, KZ> {
                    bvh: self,
                    ray: sheared,
                    best,
                };
                crate::wide::closest(isa, bvh, bvh_ray, &mut leaf);
                return leaf.best.hit;
            }
            Accel::Cw(bvh) => {
                bvh.ray_traverse(*bvh_ray, &mut unused, |_, slot| test(&mut best, slot))
            }
            Accel::Binary(bvh) => {
                bvh.ray_traverse(*bvh_ray, &mut unused, |_, slot| test(&mut best, slot))
            }
        };
        best.hit
    }

    /// [`SceneBvh::closest_hit`] for a batch of rays, same results bit for
    /// bit. With the `Cw` layout, packets of 8 consecutive rays share the tree
    /// walk: on coherent rays (camera rays in row order, a reflector's
    /// reflection rays) `bench rays` measured it at about 1.5x single rays;
    /// on incoherent rays it is slower than single rays.
    pub fn closest_hits(&self, rays: &[Ray], t_max: f32) -> Vec<Option<Hit>> {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: as in `closest_hit`.
            return unsafe { self.closest_hits_avx2(rays, t_max) };
        }
        self.closest_hits_with(Isa::Portable, rays, t_max)
    }

    /// [`SceneBvh::closest_hits`] compiled for AVX2.
    ///
    /// # Safety
    /// The CPU must have the enabled features ([`has_avx2`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt,bmi1,bmi2,lzcnt")]
    unsafe fn closest_hits_avx2(&self, rays: &[Ray], t_max: f32) -> Vec<Option<Hit>> {
        self.closest_hits_with(Isa::Avx2, rays, t_max)
    }

    #[inline(always)]
    fn closest_hits_with(&self, isa: Isa, rays: &[Ray], t_max: f32) -> Vec<Option<Hit>> {
        let Accel::Cw(bvh) = &self.accel else {
            return rays
                .iter()
                .map(|r| self.closest_hit_with(isa, r, t_max))
                .collect();
        };
        if self.options.layout != BvhLayout::Cw {
            return rays
                .iter()
                .map(|r| self.closest_hit_with(isa, r, t_max))
                .collect();
        }
        let mut hits = Vec::with_capacity(rays.len());
        for packet in rays.chunks(crate::wide::PACKET) {
            // Rays that can hit nothing sit out; `lane` maps packet slots back.
            let mut lane = [0usize; crate::wide::PACKET];
            let mut bvh_rays = Vec::with_capacity(packet.len());
            let mut sheared = Vec::with_capacity(packet.len());
            for (i, ray) in packet.iter().enumerate() {
                let (origin, direction) = (Vec3A::from(ray.origin), Vec3A::from(ray.direction));
                if let Some(r) = bvh_ray(origin, direction, t_max) {
                    lane[bvh_rays.len()] = i;
                    sheared.push(ShearedRay::new(origin, direction));
                    bvh_rays.push(r);
                }
            }
            let best: [ClosestSoFar; crate::wide::PACKET] =
                std::array::from_fn(|_| ClosestSoFar { t_max, hit: None });
            let mut leaf = PacketInLeaves {
                bvh: self,
                rays: &sheared,
                best,
            };
            crate::wide::closest_packet(isa, bvh, &bvh_rays, &mut leaf);
            let best = leaf.best;
            let start = hits.len();
            hits.resize(start + packet.len(), None);
            for (r, best) in best.iter().enumerate().take(bvh_rays.len()) {
                hits[start + lane[r]] = best.hit;
            }
        }
        hits
    }

    /// Any hit with t in (0, `t_max`); stops at the first hit found.
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        self.any_hit(ray, t_max, None)
    }

    /// Whether a shadow-casting triangle ([`casts_shadow`]) lies on the
    /// ray with t in (0, `t_max`): the shadow test.
    pub fn shadowed(&self, ray: &Ray, t_max: f32) -> bool {
        self.any_hit(ray, t_max, Some(&self.slot_casts_shadow))
    }

    /// Whether triangle `id`'s material lets light through (any
    /// transmittance): glass, whose reflections count as reflected light
    /// wherever a ray meets it behind a reflector.
    pub fn see_through(&self, id: TriangleId) -> bool {
        self.scene.material_of(id).see_through()
    }

    /// Whether triangle `id` casts shadows ([`casts_shadow`]).
    pub fn casts_shadow(&self, id: TriangleId) -> bool {
        triangle_casts_shadow(&self.scene, id)
    }

    /// Any hit among the slots `counts` marks (all for `None`).
    fn any_hit(&self, ray: &Ray, t_max: f32, counts: Option<&[bool]>) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: as in `closest_hit`.
            return unsafe { self.any_hit_avx2(ray, t_max, counts) };
        }
        self.any_hit_with(Isa::Portable, ray, t_max, counts)
    }

    /// [`SceneBvh::any_hit`] compiled for AVX2.
    ///
    /// # Safety
    /// The CPU must have the enabled features ([`has_avx2`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt,bmi1,bmi2,lzcnt")]
    unsafe fn any_hit_avx2(&self, ray: &Ray, t_max: f32, counts: Option<&[bool]>) -> bool {
        self.any_hit_with(Isa::Avx2, ray, t_max, counts)
    }

    #[inline(always)]
    fn any_hit_with(&self, isa: Isa, ray: &Ray, t_max: f32, counts: Option<&[bool]>) -> bool {
        let (origin, direction) = (Vec3A::from(ray.origin), Vec3A::from(ray.direction));
        let Some(bvh_ray) = bvh_ray(origin, direction, t_max) else {
            return false;
        };
        let sheared = ShearedRay::new(origin, direction);
        with_axes!(
            sheared.axes,
            self.any_hit_in(isa, &bvh_ray, &sheared, t_max, counts)
        )
    }

    /// Any hit for a ray with axis order `[KX, KY, KZ]`.
    #[inline(always)]
    fn any_hit_in<const KX: usize, const KY: usize, const KZ: usize>(
        &self,
        isa: Isa,
        bvh_ray: &BvhRay,
        sheared: &ShearedRay,
        t_max: f32,
        counts: Option<&[bool]>,
    ) -> bool {
        let test = |slot: usize| {
            if counts.is_some_and(|c| !c[slot]) {
                return f32::INFINITY;
            }
            match self.prims[slot].intersect_in::<KX, KY, KZ>(sheared) {
                Some((t, _, _)) if t > 0.0 && t < t_max => t,
                _ => f32::INFINITY,
            }
        };
        match &self.accel {
            Accel::Empty => false,
            Accel::Cw(bvh) if self.options.layout == BvhLayout::Cw => {
                let mut leaf = AnyInLeaves::<KX, KY, KZ> {
                    bvh: self,
                    ray: sheared,
                    t_max,
                    counts,
                };
                crate::wide::any(isa, bvh, bvh_ray, &mut leaf)
            }
            Accel::Cw(bvh) => !bvh.ray_traverse_miss(*bvh_ray, |_, slot| test(slot)),
            Accel::Binary(bvh) => !bvh.ray_traverse_miss(*bvh_ray, |_, slot| test(slot)),
        }
    }

    /// The same BVH with queries on the portable build even where the CPU
    /// has AVX2, so tests check both builds.
    #[cfg(test)]
    pub(crate) fn portable(mut self) -> SceneBvh {
        self.avx2 = false;
        self
    }

    /// Reference closest hit: every triangle, in id order, with the same
    /// triangle test and tie-break as [`SceneBvh::closest_hit`].
    #[cfg(test)]
    pub(crate) fn closest_hit_brute_force(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        let (origin, direction) = (Vec3A::from(ray.origin), Vec3A::from(ray.direction));
        let sheared = ShearedRay::new(origin, direction);
        let mut best = ClosestSoFar { t_max, hit: None };
        for id in self.scene.triangle_ids() {
            let tri = PrimTriangle::new(self.scene.triangle_positions(id));
            if let Some(tuv) = tri.intersect(&sheared) {
                best.offer(id, tuv);
            }
        }
        best.hit
    }
}

/// The closest-hit leaf test of one ray with axis order `[KX, KY, KZ]`.
struct ClosestInLeaves<'a, const KX: usize, const KY: usize, const KZ: usize> {
    bvh: &'a SceneBvh,
    ray: &'a ShearedRay,
    best: ClosestSoFar,
}

impl<const KX: usize, const KY: usize, const KZ: usize> LeafTest
    for ClosestInLeaves<'_, KX, KY, KZ>
{
    #[inline(always)]
    fn test(&mut self, _: usize, first: u32, _: u32) -> f32 {
        let hits = self.bvh.leaves.hits::<KX, KY, KZ>(first, self.ray);
        offer_leaf(&mut self.best, &hits)
    }
}

/// The closest-hit leaf test of a packet's rays (any axis orders).
struct PacketInLeaves<'a> {
    bvh: &'a SceneBvh,
    rays: &'a [ShearedRay],
    best: [ClosestSoFar; crate::wide::PACKET],
}

impl LeafTest for PacketInLeaves<'_> {
    #[inline(always)]
    fn test(&mut self, r: usize, first: u32, _: u32) -> f32 {
        let block = self.bvh.leaves.block(first);
        let ray = &self.rays[r];
        let hits = with_axes!(ray.axes, block.intersect_in(ray));
        offer_leaf(&mut self.best[r], &hits)
    }
}

/// The any-hit leaf test of one ray with axis order `[KX, KY, KZ]`: hits
/// in `(0, t_max)` on slots `counts` marks (all for `None`).
struct AnyInLeaves<'a, const KX: usize, const KY: usize, const KZ: usize> {
    bvh: &'a SceneBvh,
    ray: &'a ShearedRay,
    t_max: f32,
    counts: Option<&'a [bool]>,
}

impl<const KX: usize, const KY: usize, const KZ: usize> LeafTest for AnyInLeaves<'_, KX, KY, KZ> {
    #[inline(always)]
    fn test(&mut self, _: usize, first: u32, _: u32) -> f32 {
        let hits = self.bvh.leaves.hits::<KX, KY, KZ>(first, self.ray);
        for lane in bits(hits.hits) {
            let t = hits.t[lane];
            let slot = first as usize + lane;
            if t > 0.0 && t < self.t_max && self.counts.is_none_or(|c| c[slot]) {
                return t;
            }
        }
        f32::INFINITY
    }
}

/// Offers a leaf's hits to `best` in slot order; returns the new `tmax` for
/// the walk: just above the closest hit when one of them became it, else
/// `f32::INFINITY`.
#[inline(always)]
fn offer_leaf(best: &mut ClosestSoFar, hits: &LaneHits) -> f32 {
    let mut closer = false;
    for lane in bits(hits.hits) {
        let tuv = (hits.t[lane], hits.u[lane], hits.v[lane]);
        closer |= best.offer(hits.ids[lane], tuv);
    }
    match best.hit {
        Some(hit) if closer => next_up(hit.t),
        _ => f32::INFINITY,
    }
}

/// Whether this CPU runs the queries' AVX2 builds (the features their
/// `target_feature` attribute enables).
fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        is_x86_feature_detected!("avx2")
            && is_x86_feature_detected!("popcnt")
            && is_x86_feature_detected!("bmi1")
            && is_x86_feature_detected!("bmi2")
            && is_x86_feature_detected!("lzcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// The obvhs ray for a query, or `None` when nothing can be hit (non-finite
/// input, empty interval).
fn bvh_ray(origin: Vec3A, direction: Vec3A, t_max: f32) -> Option<BvhRay> {
    if !origin.is_finite()
        || !direction.is_finite()
        || direction == Vec3A::ZERO
        || t_max.is_nan()
        || t_max <= 0.0
    {
        return None;
    }
    // obvhs picks a CwBvh node's near planes by `direction < 0.0` but
    // inverts -0.0 to a large negative: a -0.0 component (as in `-Vec3::Y`)
    // would pair swapped planes and miss. Adding +0.0 turns -0.0 into +0.0.
    Some(BvhRay::new(origin, direction + Vec3A::ZERO, 0.0, t_max))
}

/// Builds the tree over padded triangle boxes; returns it with the original
/// triangle id of each primitive slot. Mirrors obvhs'
/// `build_{cwbvh,bvh2}_from_tris`, plus the padding.
fn build(tris: &[[Vec3; 3]], options: BvhOptions, pad: f32) -> (Accel, Vec<TriangleId>) {
    let params = options.preset.params();
    let obvhs_tris: Vec<BvhTriangle> = tris
        .iter()
        .map(|&[a, b, c]| BvhTriangle {
            v0: a.into(),
            v1: b.into(),
            v2: c.into(),
        })
        .collect();
    let mut aabbs: Vec<Aabb> = obvhs_tris.iter().map(|t| t.aabb()).collect();
    let mut indices: Vec<u32> = (0..tris.len() as u32).collect();
    if params.pre_split {
        let largest = aabbs.iter().map(Aabb::half_area).fold(0.0, f32::max);
        let average = aabbs.iter().map(Aabb::half_area).sum::<f32>() / aabbs.len() as f32;
        split_aabbs_preset(&mut aabbs, &mut indices, &obvhs_tris, average, largest);
    }
    // Padding (~16 ulps of the largest coordinate) makes every leaf box
    // strictly contain its triangle, so the slab test's rounding cannot cull
    // a hit the triangle test reports.
    let pad = Vec3A::splat(pad);
    for aabb in &mut aabbs {
        *aabb = Aabb::new(aabb.min - pad, aabb.max + pad);
    }

    let mut bvh2 = PlocBuilder::with_capacity(aabbs.len()).build(
        params.ploc_search_distance,
        &aabbs,
        indices,
        params.sort_precision,
        params.search_depth_threshold,
    );
    bvh2.uses_spatial_splits = params.pre_split;
    let mut reinsertion = ReinsertionOptimizer::default();
    reinsertion.run(&mut bvh2, params.reinsertion_batch_ratio, None);
    match options.layout {
        BvhLayout::Cw | BvhLayout::CwOctant => {
            let cw = bvh2_to_cwbvh(&bvh2, params.max_prims_per_leaf.clamp(1, 3), true, false);
            if cw_depth(&cw) < CW_STACK_LIMIT {
                let slots = triangle_ids(&cw.primitive_indices);
                return (Accel::Cw(cw), slots);
            }
            // obvhs traverses a CwBvh with a fixed 32-entry stack that
            // silently overwrites its top when full (missed hits). Only a
            // pathological scene gets this deep; the binary layout's stack
            // grows with the tree instead.
            binary(bvh2, params, &mut reinsertion)
        }
        BvhLayout::Binary => binary(bvh2, params, &mut reinsertion),
    }
}

/// Traversal holds at most one stack entry per level below the root.
pub(crate) const CW_STACK_LIMIT: usize = 31;

/// Finishes a binary BVH the way obvhs' `build_bvh2_from_tris` does.
fn binary(
    mut bvh2: Bvh2,
    params: BvhBuildParams,
    reinsertion: &mut ReinsertionOptimizer,
) -> (Accel, Vec<TriangleId>) {
    collapse(
        &mut bvh2,
        params.max_prims_per_leaf.clamp(1, 255),
        params.collapse_traversal_cost,
    );
    reinsertion.run(
        &mut bvh2,
        params.reinsertion_batch_ratio * params.post_collapse_reinsertion_batch_ratio_multiplier,
        None,
    );
    // Traversal sizes its stack by `max_depth`, recorded during the PLOC
    // build; make sure the collapse and reinsertion passes did not deepen it.
    bvh2.max_depth = bvh2.max_depth.max(bvh2_depth(&bvh2));
    let slots = triangle_ids(&bvh2.primitive_indices);
    (Accel::Binary(bvh2), slots)
}

/// The triangle of each primitive slot, from obvhs' primitive indices.
fn triangle_ids(primitive_indices: &[u32]) -> Vec<TriangleId> {
    primitive_indices.iter().copied().map(TriangleId).collect()
}

/// The number of node levels of a binary BVH.
fn bvh2_depth(bvh: &Bvh2) -> usize {
    let mut deepest = 0;
    let mut pending = vec![(0usize, 1usize)];
    while let Some((index, depth)) = pending.pop() {
        let Some(node) = bvh.nodes.get(index) else {
            continue;
        };
        deepest = deepest.max(depth);
        if !node.is_leaf() {
            let first = node.first_index as usize;
            pending.extend([(first, depth + 1), (first + 1, depth + 1)]);
        }
    }
    deepest
}

/// The number of inner-node levels of a CwBvh.
fn cw_depth(cw: &CwBvh) -> usize {
    let mut deepest = 0;
    let mut pending = vec![(0usize, 1usize)];
    while let Some((index, depth)) = pending.pop() {
        deepest = deepest.max(depth);
        let Some(node) = cw.nodes.get(index) else {
            continue;
        };
        for child in 0..8 {
            if !node.is_child_empty(child) && !node.is_leaf(child) {
                pending.push((node.child_node_index(child) as usize, depth + 1));
            }
        }
    }
    deepest
}
