//! Whitted recursion: local Phong with shadow rays at every surface, plus a
//! mirror ray weighted by kr and a Snell refraction ray weighted by kt, and
//! the ray-tree signature that tells vertex tracing when two samples saw the
//! same things.

use glam::Vec3;
use rayon::prelude::*;
use vtfarm_scene::shading::phong;
use vtfarm_scene::{Camera, Light, LightKind, Lighting, NONE};

use crate::bvh::spawn_offset;
use crate::{Hit, Ray, Sample, SceneBvh, SurfacePoint, TraceSettings, Transmission};

/// Whitted tracer for one frame's lighting.
///
/// Recursion: a surface at depth `d` (the first one has depth 1) spawns its
/// reflection and refraction rays only while `d < settings.max_depth`;
/// `max_depth` 0 behaves as 1.
///
/// Shadow rays treat every occluder as opaque, transparent ones included
/// (classic Whitted: no caustics or coloured shadows), pass surfaces that
/// only emit ([`crate::casts_shadow`]), and stop at a point
/// light's distance (minus the spawn epsilon, so geometry at the light does
/// not shadow it).
#[derive(Clone, Copy, Debug)]
pub struct Tracer<'a> {
    pub bvh: &'a SceneBvh,
    pub lighting: &'a Lighting,
    pub settings: TraceSettings,
    /// The pixel's cone, for the mip level of the textures rays meet.
    pub cone: PixelCone,
}

/// The cone of rays through one pixel, for the mip level of textures in
/// traced shading ([`vtfarm_scene::Scene::textured_material`]'s
/// footprint). The rule: a surface's footprint is `spread` times the length
/// of the ray path from the eye to it — the eye's distance for a point
/// shaded directly or the first hit of a ray from the eye, plus every
/// segment after it for reflected and refracted rays (the cone keeps its
/// angle at a surface, exact for flat mirrors and thin glass). The
/// rasterized base frame and the thin-glass pass use the same footprint
/// for what they see directly, so the three shading paths pick the same
/// level. A function of the ray tree alone: deterministic.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelCone {
    pub eye: Vec3,
    /// Metres of footprint per metre of path (a pixel's width at unit depth).
    pub spread: f32,
}

impl PixelCone {
    /// No cone: every texture sampled at its finest level.
    pub const FINEST: PixelCone = PixelCone {
        eye: Vec3::ZERO,
        spread: 0.0,
    };

    /// The cone of one pixel of `camera`.
    pub fn of(camera: &Camera) -> PixelCone {
        PixelCone {
            eye: camera.eye,
            spread: camera.pixel_size_at_unit_depth(),
        }
    }

    /// The path length from the eye to `point`, seen directly.
    fn distance(&self, point: Vec3) -> f32 {
        (point - self.eye).length()
    }
}

/// What shading one surface produced; `reflected`, `transmitted` and
/// `reflected_object` are only reported for the first surface.
///
/// The split, the one meaning of "reflected" at every quality level (the
/// thin-glass model of `vtfarm-vertex` computes the same): the light the
/// glass reflects toward the eye. That is the first surface's own
/// reflection plus the reflections of every see-through surface its
/// refraction ray passes before it meets an opaque one (a slab's back
/// surface: the ghost image), weighted by the transmittances on the way;
/// `transmitted` is the rest of what the refraction ray brings back.
#[derive(Clone, Copy, Debug)]
struct Shaded {
    color: Vec3,
    reflected: Vec3,
    transmitted: Vec3,
    reflected_object: u32,
    /// The light this surface and the see-through surfaces behind it
    /// reflect back along the ray (zero for an opaque surface or a miss):
    /// `kr · reflection + kt · ghost of the refraction's surface`.
    ghost: Vec3,
}

mod generations;

/// Which secondary rays the first surface of a sample spawns (deeper
/// surfaces spawn both).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rays {
    /// Reflection and refraction: [`Tracer::shade`].
    Both,
    /// The reflection alone: [`Tracer::shade_reflection`].
    ReflectionOnly,
}

/// Words fed to the signature besides object ids. Object ids are `u32`, so
/// anything at or above 2^32 cannot collide with one.
mod word {
    const MARK: u64 = 1 << 32;
    pub(super) const MISS: u64 = MARK | 1;
    pub(super) const REFLECT: u64 = MARK | 2;
    pub(super) const REFRACT: u64 = MARK | 3;
    pub(super) const LIGHTS_END: u64 = MARK | 4;
    /// Plus the light's index: the light lights the surface (facing it and
    /// unoccluded).
    pub(super) const LIT: u64 = 2 << 32;
    /// Plus the light's index: a ray that left the scene saw the light's
    /// disc (some of its footprint did).
    pub(super) const DISC: u64 = 3 << 32;
}

impl Shaded {
    /// A colour with no reflected or transmitted part.
    fn only(color: Vec3) -> Shaded {
        Shaded {
            color,
            reflected: Vec3::ZERO,
            transmitted: Vec3::ZERO,
            reflected_object: NONE,
            ghost: Vec3::ZERO,
        }
    }
}

/// The state of one sample's depth-first walk: its signature so far, and
/// scratch space for a surface's light words.
struct Walk {
    signature: Signature,
    lit: Vec<u64>,
}

/// Deterministic FxHash-style hash of the ray tree's event sequence.
#[derive(Clone, Copy, Debug)]
struct Signature(u64);

impl Signature {
    const SEED: u64 = 0x243f_6a88_85a3_08d3;
    const K: u64 = 0x517c_c1b7_2722_0a95;

    fn new() -> Self {
        Signature(Self::SEED)
    }

    fn add(&mut self, word: u64) {
        self.0 = (self.0.rotate_left(5) ^ word).wrapping_mul(Self::K);
    }

    /// The Fx state with a murmur3 finaliser, so that short sequences that
    /// differ in one word differ in about half the bits.
    fn finish(self) -> u64 {
        let mut h = self.0;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^ (h >> 33)
    }
}

/// Rays per rayon task of [`Tracer::trace_batch`]: whole packets, large
/// enough to amortise scheduling.
const PRIMARY_CHUNK: usize = 256;

/// Mirror direction of unit `incoming` about unit `normal`.
pub fn reflect(incoming: Vec3, normal: Vec3) -> Vec3 {
    (incoming - 2.0 * incoming.dot(normal) * normal).normalize_or(incoming)
}

/// Snell refraction of unit `incoming` through a surface with unit `normal`
/// facing the incoming side (`incoming . normal <= 0`), with `eta` = n1 / n2.
/// `None` on total internal reflection.
pub fn refract(incoming: Vec3, normal: Vec3, eta: f32) -> Option<Vec3> {
    Refraction::new(incoming, normal, eta).map(|r| r.direction())
}

/// [`refract`] in two steps: whether light gets through, then (only when
/// asked for: weights alone do not need it) the direction.
#[derive(Clone, Copy, Debug)]
struct Refraction {
    incoming: Vec3,
    normal: Vec3,
    eta: f32,
    cos_i: f32,
    k: f32,
}

impl Refraction {
    /// `None` on total internal reflection.
    fn new(incoming: Vec3, normal: Vec3, eta: f32) -> Option<Refraction> {
        let cos_i = -incoming.dot(normal);
        let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
        (k >= 0.0).then_some(Refraction {
            incoming,
            normal,
            eta,
            cos_i,
            k,
        })
    }

    fn direction(&self) -> Vec3 {
        let Refraction {
            incoming,
            normal,
            eta,
            cos_i,
            k,
        } = *self;
        (eta * incoming + (eta * cos_i - k.sqrt()) * normal).normalize_or(incoming)
    }
}

/// Schlick's angular factor `(1 - cos)^5`: 0 head-on, 1 at grazing. With
/// `F0` the head-on reflectance, Schlick's `F = F0 + (1 - F0) * factor`.
/// For opaque reflectors (whose index of refraction says nothing of them).
pub(crate) fn schlick_factor(cos: f32) -> f32 {
    (1.0 - cos.clamp(0.0, 1.0)).powi(5)
}

/// The unpolarised Fresnel reflectance of a dielectric interface (the mean
/// of the s- and p-polarised reflectances of the Fresnel equations), light
/// arriving at `cos_i` from the side of index n1 and leaving at `cos_t`
/// (Snell), `eta = n1 / n2`. Symmetric in the direction of travel: the same
/// from either side for the same pair of angles.
pub fn fresnel_reflectance(cos_i: f32, cos_t: f32, eta: f32) -> f32 {
    let s = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let p = (eta * cos_t - cos_i) / (eta * cos_t + cos_i);
    let r = 0.5 * (s * s + p * p);
    if r.is_finite() {
        r.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

/// The share of a see-through surface's transmittance that the Fresnel
/// equations move to its reflectance at this angle: 0 head-on (the
/// material's own kr and kt are its head-on values), 1 at grazing, and in
/// between `(F(θ) - F0) / (1 - F0)` with `F` [`fresnel_reflectance`] and
/// `F0` its head-on value. A material with `kr = F0` and `kt = 1 - F0` (a
/// clear dielectric) then reflects exactly `F(θ)`.
fn fresnel_factor(cos_i: f32, cos_t: f32, eta: f32) -> f32 {
    let head_on = fresnel_reflectance(1.0, 1.0, eta);
    let f = fresnel_reflectance(cos_i.clamp(0.0, 1.0), cos_t.clamp(0.0, 1.0), eta);
    if head_on >= 1.0 {
        return 1.0;
    }
    ((f - head_on) / (1.0 - head_on)).clamp(0.0, 1.0)
}

impl Tracer<'_> {
    /// Traces a primary ray from the camera (depth 0).
    pub fn trace(&self, ray: &Ray) -> Sample {
        let link = Link::Ray(*ray, self.cone.distance(ray.origin));
        self.sample_of(&mut OnDemand { tracer: self }, link, Rays::Both)
    }

    /// Shades a known surface point seen along `incoming` (unit direction of
    /// the ray arriving at the point, e.g. from the eye to a reflector
    /// vertex) without intersecting a primary ray: local Phong with shadow
    /// rays + kr * reflected ray + kt * refracted ray, recursively. This is
    /// what vertex tracing calls per vertex and per filled pixel.
    pub fn shade(&self, point: &SurfacePoint, incoming: Vec3) -> Sample {
        let link = Link::Point(*point, incoming);
        self.sample_of(&mut OnDemand { tracer: self }, link, Rays::Both)
    }

    /// What a refraction ray leaving a see-through surface brings back:
    /// its radiance, and the part of it that the see-through surfaces on
    /// its way reflect back (a slab's back surface: the ghost image, which
    /// [`Sample::reflected`] counts as reflected light). Weighted by the
    /// surface's `kt`, they are its transmitted and ghost terms.
    pub fn trace_transmission(&self, ray: &Ray) -> Transmission {
        let link = Link::Ray(*ray, self.cone.distance(ray.origin));
        let (shaded, _) = self.shade_root(&mut OnDemand { tracer: self }, link, Rays::Both);
        Transmission {
            radiance: shaded.color,
            ghost: shaded.ghost,
        }
    }

    /// [`Tracer::shade`] without the point's own refraction ray: local Phong
    /// with shadow rays plus kr times the reflected radiance (traced in full
    /// Whitted), `transmitted` zero, and a signature of the reflected subtree
    /// only. For a thin reflector whose transmitted part comes from elsewhere
    /// (the rasterizer): vertex tracing then refines at reflection edges; the
    /// point's own shadow-ray outcomes stay out of the signature (a shadow
    /// edge across the glass splits only where the colour shows it).
    pub fn shade_reflection(&self, point: &SurfacePoint, incoming: Vec3) -> Sample {
        let link = Link::Point(*point, incoming);
        self.sample_of(&mut OnDemand { tracer: self }, link, Rays::ReflectionOnly)
    }

    /// Batches over all cores with rayon (results in input order), the
    /// same samples as [`Tracer::trace`] per ray; the primary hits come from
    /// [`SceneBvh::closest_hits`] (packets: coherent batches such as camera
    /// rays in row order trace faster that way).
    pub fn trace_batch(&self, rays: &[Ray]) -> Vec<Sample> {
        rays.par_chunks(PRIMARY_CHUNK)
            .flat_map_iter(|chunk| {
                let hits = self.bvh.closest_hits(chunk, f32::INFINITY);
                chunk.iter().zip(hits).map(|(ray, hit)| {
                    let link = Link::Hit(*ray, hit, self.cone.distance(ray.origin));
                    self.sample_of(&mut OnDemand { tracer: self }, link, Rays::Both)
                })
            })
            .collect()
    }

    pub fn shade_batch(&self, points: &[(SurfacePoint, Vec3)]) -> Vec<Sample> {
        points
            .par_iter()
            .map(|(point, incoming)| self.shade(point, *incoming))
            .collect()
    }

    /// [`Tracer::shade`] (`Rays::Both`) or [`Tracer::shade_reflection`]
    /// (`Rays::ReflectionOnly`) of every point, on this thread, with the same
    /// samples bit for bit, generation by generation: all first surfaces
    /// are shaded, then all their reflection rays are traced together
    /// through [`SceneBvh::closest_hits`] (packets of consecutive rays), then
    /// all their refraction rays, then the surfaces those rays hit, and so on
    /// (module `generations`). Pays for coherent batches: neighbouring
    /// pixels or vertices of one reflector, in order.
    pub fn shade_points(&self, points: &[(SurfacePoint, Vec3)], rays: Rays) -> Vec<Sample> {
        generations::shade_points(self, points, rays)
    }

    /// The sample of the ray tree rooted at `root`, whose first surface
    /// spawns `rays`.
    fn sample_of<S: TreeSource>(&self, source: &mut S, root: S::Link, rays: Rays) -> Sample {
        let (shaded, signature) = self.shade_root(source, root, rays);
        sample(shaded, signature)
    }

    /// The ray tree rooted at `root` shaded, and its signature.
    fn shade_root<S: TreeSource>(
        &self,
        source: &mut S,
        root: S::Link,
        rays: Rays,
    ) -> (Shaded, Signature) {
        let mut walk = Walk {
            signature: Signature::new(),
            lit: Vec::new(),
        };
        let (shaded, _) = self.shade_tree(source, root, 1, 1.0, rays, &mut walk);
        (shaded, walk.signature)
    }

    /// The one shading path of every sample: the radiance arriving along
    /// `link`, whose surface gets depth `depth` and carries `weight` of the
    /// sample (the product of kr/kt above it), summed depth first with the
    /// signature's words in tree order; also returns the object hit (`NONE`
    /// on a miss).
    fn shade_tree<S: TreeSource>(
        &self,
        source: &mut S,
        link: S::Link,
        depth: u32,
        weight: f32,
        rays: Rays,
        walk: &mut Walk,
    ) -> (Shaded, u32) {
        // Branches too weak to change a pixel visibly stay out of the ray-tree
        // signature, so they do not drive the refinement.
        let tracked = weight >= self.settings.signature_min_weight;
        walk.lit.clear();
        let surface = match source.visit(link, depth, rays, &mut walk.lit) {
            Visited::Surface(surface) => surface,
            Visited::Miss(direction) => {
                if tracked {
                    walk.signature.add(word::MISS);
                }
                let mut sky = self.lighting.background;
                for (index, light) in self.lighting.lights.iter().enumerate() {
                    let seen = self.disc_seen(light, direction);
                    if seen != Vec3::ZERO {
                        sky += seen;
                        if tracked {
                            walk.signature.add(word::DISC + index as u64);
                        }
                    }
                }
                return (Shaded::only(sky), NONE);
            }
        };
        if tracked {
            walk.signature.add(u64::from(surface.object));
        }
        // `shade_reflection` watches the reflection alone (see there).
        if tracked && rays == Rays::Both {
            for &word in &walk.lit {
                walk.signature.add(word);
            }
            walk.signature.add(word::LIGHTS_END);
        }
        let mut shaded = Shaded::only(surface.local);
        let (reflection_weight, refraction_weight) = child_weights(weight, surface.kr, surface.kt);
        if let Some(child) = surface.reflection {
            if tracked {
                walk.signature.add(word::REFLECT);
            }
            let (seen, object) = self.shade_tree(
                source,
                child,
                depth + 1,
                reflection_weight,
                Rays::Both,
                walk,
            );
            if depth == 1 && reflection_weight < self.settings.signature_min_weight {
                // The sample reports the first reflection's object however
                // weak the reflection (glass reflects ~4 %): keep that object
                // in the signature, so refinement finds its edges.
                walk.signature.add(u64::from(object));
            }
            shaded.reflected = surface.kr * seen.color;
            shaded.reflected_object = object;
            shaded.color += shaded.reflected;
        }
        if let Some(child) = surface.refraction {
            if tracked {
                walk.signature.add(word::REFRACT);
            }
            let (seen, _) = self.shade_tree(
                source,
                child,
                depth + 1,
                refraction_weight,
                Rays::Both,
                walk,
            );
            let through = surface.kt * seen.color;
            shaded.color += through;
            // The see-through surfaces behind reflect too (see `Shaded`):
            // their reflections move from the transmitted part to the
            // reflected one; the colour is the same sum either way.
            let ghost = surface.kt * seen.ghost;
            shaded.transmitted = through - ghost;
            shaded.reflected += ghost;
        }
        if surface.see_through {
            shaded.ghost = shaded.reflected;
        }
        (shaded, surface.object)
    }

    /// The radiance of `light`'s disc ([`Light::disc`]) that a ray leaving
    /// the scene along unit `direction` brings back: the disc's radiance
    /// times the share of the ray's pixel footprint it covers
    /// ([`vtfarm_scene::SunDisc::coverage`]). The footprint is a disc of
    /// the pixel's area, `spread` wide, about the ray: the cone keeps its
    /// angle at every surface ([`PixelCone`]), exact for flat mirrors and
    /// thin glass. Without a cone ([`PixelCone::FINEST`]) the ray is one
    /// direction, inside the disc or not. Direct lighting stays the light's
    /// (local shading): a disc is only ever seen, never lights a surface.
    fn disc_seen(&self, light: &Light, direction: Vec3) -> Vec3 {
        let Some(disc) = light.disc() else {
            return Vec3::ZERO;
        };
        let footprint = self.cone.spread / std::f32::consts::PI.sqrt();
        let coverage = disc.coverage(direction.normalize_or_zero(), footprint);
        if coverage > 0.0 {
            disc.radiance * coverage
        } else {
            Vec3::ZERO
        }
    }

    /// A surface's terms with the `LIT` words of the lights that reach it
    /// pushed onto `lit` (when `rays` lets its lights into the signature)
    /// and its secondary rays, none at the deepest depth.
    fn surface_of(
        &self,
        point: &SurfacePoint,
        incoming: Vec3,
        path: f32,
        depth: u32,
        rays: Rays,
        lit: &mut Vec<u64>,
    ) -> (SurfaceTerms, Option<Ray>, Option<Ray>) {
        let terms = self.terms(point, incoming, path, &mut |light| {
            if rays == Rays::Both {
                lit.push(word::LIT + light_index(self.lighting, light));
            }
        });
        if depth >= self.settings.max_depth.max(1) {
            return (terms, None, None);
        }
        let refraction = terms.refraction.filter(|_| rays == Rays::Both);
        (terms, terms.reflection, refraction)
    }

    /// The parts of `shade` that need no secondary ray: local Phong with
    /// shadow rays, the weights kr and kt (Fresnel included when set) and the
    /// reflection and refraction rays themselves, untraced. Other reflection
    /// methods (cube maps, PVRR) find the reflected radiance their own way and
    /// combine it as `local + kr * reflected + kt * transmitted`.
    pub fn surface_terms(&self, point: &SurfacePoint, incoming: Vec3) -> SurfaceTerms {
        let path = self.cone.distance(point.position);
        self.terms(point, incoming, path, &mut |_| {})
    }

    /// Only kr and kt of [`Tracer::surface_terms`] (Fresnel included when
    /// set): no shadow or secondary ray, so cheap enough for every pixel.
    pub fn weights(&self, point: &SurfacePoint, incoming: Vec3) -> (Vec3, Vec3) {
        let (normal, geometric, incoming) = self.normals(point, incoming);
        let material = self.material_at(point, self.cone.distance(point.position));
        let s = secondary_rays(
            &material,
            normal,
            geometric,
            incoming,
            self.settings.fresnel,
        );
        (s.kr, s.kt)
    }

    /// The material at `point`, `path` metres along the rays from the eye,
    /// textured ([`vtfarm_scene::Scene::textured_material`], the footprint
    /// of [`PixelCone`] choosing the mip level).
    fn material_at(
        &self,
        point: &SurfacePoint,
        path: f32,
    ) -> std::borrow::Cow<'_, vtfarm_scene::Material> {
        let scene = self.bvh.scene();
        if !scene.material_of(point.triangle).is_textured() {
            return std::borrow::Cow::Borrowed(scene.material_of(point.triangle));
        }
        let weights = scene.barycentrics(point.triangle, point.position);
        scene.textured_material(point.triangle, weights, path * self.cone.spread)
    }

    /// The unit shading normal, geometric normal and incoming direction at
    /// `point`. Callers' normals come from interpolation: this guards against
    /// zero ones (and a degenerate triangle's zero geometric normal).
    fn normals(&self, point: &SurfacePoint, incoming: Vec3) -> (Vec3, Vec3, Vec3) {
        let geometric = self.bvh.geometric_normal(point.triangle);
        let normal = point.normal.normalize_or(geometric);
        let geometric = if geometric == Vec3::ZERO {
            normal
        } else {
            geometric
        };
        (normal, geometric, incoming.normalize_or(-normal))
    }

    /// [`Tracer::surface_terms`], telling `lit` each light that reaches the
    /// point (for the ray-tree signature).
    fn terms(
        &self,
        point: &SurfacePoint,
        incoming: Vec3,
        path: f32,
        lit: &mut dyn FnMut(&Light),
    ) -> SurfaceTerms {
        let material = self.material_at(point, path);
        let (normal, geometric, incoming) = self.normals(point, incoming);
        let local = phong(
            &material,
            self.lighting,
            point.position,
            normal,
            -incoming,
            |light, to_light, distance| {
                let visible = self.light_visible(point, light, to_light, distance);
                if visible {
                    lit(light);
                }
                visible
            },
        );
        let secondary = secondary_rays(
            &material,
            normal,
            geometric,
            incoming,
            self.settings.fresnel,
        );
        let spawn = |direction| {
            self.bvh
                .spawn_ray(point.position, point.triangle, direction)
        };
        SurfaceTerms {
            local,
            kr: secondary.kr,
            kt: secondary.kt,
            reflection: (secondary.kr.max_element() > 0.0)
                .then(|| spawn(reflect(incoming, secondary.facing))),
            refraction: secondary
                .refracted
                .filter(|_| secondary.kt.max_element() > 0.0)
                .map(|r| spawn(r.direction())),
        }
    }

    /// The shadow test for one light from a surface point. A point light's
    /// ray stops short of the light by the spawn offset of the light's own
    /// position, so geometry at the light does not shadow it.
    fn light_visible(
        &self,
        point: &SurfacePoint,
        light: &Light,
        to_light: Vec3,
        distance: f32,
    ) -> bool {
        let ray = self.bvh.spawn_ray(point.position, point.triangle, to_light);
        let t_max = match light.kind {
            LightKind::Point { position } => {
                let origin_moved = self.bvh.spawn_distance(point.position, point.triangle);
                distance - origin_moved - spawn_offset(position.abs().max_element())
            }
            LightKind::Directional { .. } => f32::INFINITY,
        };
        !self.bvh.shadowed(&ray, t_max)
    }
}

/// The local part of a surface and its secondary rays, untraced
/// (see [`Tracer::surface_terms`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceTerms {
    /// Local Phong with shadow rays.
    pub local: Vec3,
    /// Weight of the reflected radiance.
    pub kr: Vec3,
    /// Weight of the transmitted radiance.
    pub kt: Vec3,
    /// The mirror ray, when kr > 0.
    pub reflection: Option<Ray>,
    /// The Snell ray, when kt > 0 and there is no total internal reflection.
    pub refraction: Option<Ray>,
}

/// What [`Tracer::shade_tree`] needs of a surface: its object and terms,
/// and where its secondary rays lead.
struct VisitedSurface<L> {
    object: u32,
    /// The material lets light through (glass; see [`Shaded::ghost`]).
    see_through: bool,
    local: Vec3,
    kr: Vec3,
    kt: Vec3,
    reflection: Option<L>,
    refraction: Option<L>,
}

enum Visited<L> {
    /// The ray hit nothing; it left the scene along this direction.
    Miss(Vec3),
    Surface(VisitedSurface<L>),
}

/// Where [`Tracer::shade_tree`] gets the surfaces of a ray tree: traced on
/// demand ([`OnDemand`], one sample), or recorded by a generational batch
/// (module `generations`). Either way the figures come from
/// [`Tracer::surface_of`], so the samples agree bit for bit.
trait TreeSource {
    /// The way to a node of the tree.
    type Link: Copy;
    /// The node `link` leads to, at depth `depth`, whose surface spawns
    /// `rays`; pushes its light words onto `lit` (see [`Tracer::surface_of`]).
    fn visit(
        &mut self,
        link: Self::Link,
        depth: u32,
        rays: Rays,
        lit: &mut Vec<u64>,
    ) -> Visited<Self::Link>;
}

/// A node of a ray tree traced on demand.
#[derive(Clone, Copy)]
enum Link {
    /// A known surface point (seen from the eye) and the direction it is
    /// seen along.
    Point(SurfacePoint, Vec3),
    /// A ray still to trace, and the path length to its origin
    /// ([`PixelCone`]).
    Ray(Ray, f32),
    /// A ray, its closest hit and the path length to its origin.
    Hit(Ray, Option<Hit>, f32),
}

/// Traces each ray when the depth-first walk reaches it.
struct OnDemand<'a> {
    tracer: &'a Tracer<'a>,
}

impl TreeSource for OnDemand<'_> {
    type Link = Link;

    fn visit(&mut self, link: Link, depth: u32, rays: Rays, lit: &mut Vec<u64>) -> Visited<Link> {
        let tracer = self.tracer;
        let (point, incoming, path) = match link {
            Link::Point(point, incoming) => (point, incoming, tracer.cone.distance(point.position)),
            Link::Ray(ray, path) => {
                let hit = tracer.bvh.closest_hit(&ray, f32::INFINITY);
                return self.visit(Link::Hit(ray, hit, path), depth, rays, lit);
            }
            Link::Hit(ray, None, _) => return Visited::Miss(ray.direction),
            Link::Hit(ray, Some(hit), path) => {
                (tracer.bvh.surface_point(&hit), ray.direction, path + hit.t)
            }
        };
        let (terms, reflection, refraction) =
            tracer.surface_of(&point, incoming, path, depth, rays, lit);
        Visited::Surface(VisitedSurface {
            object: tracer.bvh.scene().triangles[point.triangle.index()]
                .object
                .raw(),
            see_through: tracer.bvh.see_through(point.triangle),
            local: terms.local,
            kr: terms.kr,
            kt: terms.kt,
            reflection: reflection.map(|ray| Link::Ray(ray, path)),
            refraction: refraction.map(|ray| Link::Ray(ray, path)),
        })
    }
}

/// The weights (shares of the sample) of a surface's reflected and
/// refracted subtrees, for a surface of weight `weight`.
fn child_weights(weight: f32, kr: Vec3, kt: Vec3) -> (f32, f32) {
    (weight * kr.max_element(), weight * kt.max_element())
}

/// kr, kt and the refraction of a surface hit along `incoming`.
struct Secondary {
    kr: Vec3,
    kt: Vec3,
    /// The shading normal on the incoming side.
    facing: Vec3,
    /// `None` on total internal reflection or for an opaque surface.
    refracted: Option<Refraction>,
}

fn secondary_rays(
    material: &vtfarm_scene::Material,
    normal: Vec3,
    geometric: Vec3,
    incoming: Vec3,
    fresnel: bool,
) -> Secondary {
    // The shading normal on the incoming side, for both secondary rays.
    let facing = if normal.dot(incoming) > 0.0 {
        -normal
    } else {
        normal
    };
    // Inside/outside is a property of the geometry, not of the smoothed
    // normal: the geometric normal points outside. A thin sheet has no
    // inside: light meets it from air on either side.
    let entering = geometric.dot(incoming) < 0.0 || material.thin;
    let ior = material.fresnel_ior();
    let eta = if entering { 1.0 / ior } else { ior };

    let mut kr = material.reflectance;
    let mut kt = material.transmittance;
    let refracted = if kt.max_element() > 0.0 {
        // A thin sheet's ray passes straight (eta 1).
        Refraction::new(incoming, facing, if material.thin { 1.0 } else { eta })
    } else {
        None
    };
    if kt.max_element() > 0.0 && refracted.is_none() {
        // Total internal reflection: the transmitted energy reflects.
        kr += kt;
        kt = Vec3::ZERO;
    }
    if fresnel || material.fresnel {
        let cos_i = -incoming.dot(facing);
        match refracted {
            Some(t) if kt.max_element() > 0.0 => {
                // The angle inside: the ray's own, or for a thin sheet the
                // one Snell gives at its ior (never total from air).
                let cos_t = if material.thin {
                    Refraction::new(incoming, facing, eta).map_or(0.0, |r| r.k.sqrt())
                } else {
                    -t.direction().dot(facing)
                };
                let moved = kt * fresnel_factor(cos_i, cos_t, eta);
                kr += moved;
                kt -= moved;
            }
            _ if kr.max_element() > 0.0 => kr += (Vec3::ONE - kr) * schlick_factor(cos_i),
            _ => {}
        }
    }
    Secondary {
        kr,
        kt,
        facing,
        refracted,
    }
}

/// The index of `light` in `lighting.lights` (`phong` hands out references
/// into that list), as a signature word offset.
fn light_index(lighting: &Lighting, light: &Light) -> u64 {
    // A reference not from the list (impossible with `phong`) hashes as an
    // index past the end rather than aborting a render.
    lighting
        .lights
        .iter()
        .position(|l| std::ptr::eq(l, light))
        .unwrap_or(lighting.lights.len()) as u64
}

fn sample(shaded: Shaded, signature: Signature) -> Sample {
    Sample {
        color: shaded.color,
        reflected: shaded.reflected,
        transmitted: shaded.transmitted,
        reflected_object: shaded.reflected_object,
        signature: signature.finish(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hash(words: &[u64]) -> u64 {
        let mut s = Signature::new();
        words.iter().for_each(|&w| s.add(w));
        s.finish()
    }

    #[test]
    fn signature_hash_is_stable_and_order_sensitive() {
        // Pinned: signatures travel between farm machines and must not
        // change with platform or build.
        assert_eq!(hash(&[]), 0x7acd_bb98_b134_4213);
        assert_eq!(
            hash(&[3, word::LIT, word::LIGHTS_END]),
            0xaca4_bb8b_dc1b_5240
        );
        assert_ne!(hash(&[1, 2]), hash(&[2, 1]));
        assert_ne!(hash(&[1]), hash(&[1, 0]));
        assert_ne!(hash(&[word::MISS]), hash(&[]));
    }

    #[test]
    fn reflection_mirrors_about_the_normal() {
        let incoming = Vec3::new(1.0, -1.0, 0.0).normalize();
        assert!(reflect(incoming, Vec3::Y).distance(Vec3::new(1.0, 1.0, 0.0).normalize()) < 1e-6);
    }

    #[test]
    fn schlick_factor_is_zero_head_on_and_one_at_grazing() {
        assert_eq!(schlick_factor(1.0), 0.0);
        assert_eq!(schlick_factor(0.0), 1.0);
        assert!((schlick_factor(0.5) - 0.03125).abs() < 1e-7);
    }
}
