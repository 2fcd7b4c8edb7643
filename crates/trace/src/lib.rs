//! The base ray tracer: a BVH (obvhs) over all scene triangles, closest-hit
//! and any-hit queries, and Whitted recursion with local Phong shading,
//! shadow rays, mirror reflection and Snell refraction.
//!
//! Architecture invariant: the tracer knows nothing of pixels, packages or
//! networking; it answers "what colour does this ray / surface point see".
//!
//! - [`SceneBvh`] (module `bvh`): the BVH and the closest-hit / any-hit
//!   queries, independent of tree layout and thread count.
//! - [`Tracer`] (module `whitted`): Whitted shading of rays and of known
//!   surface points, single or batched with rayon.
//!
//! Everything is deterministic: the same scene, lighting and input give
//! bit-identical samples whatever the number of threads.

mod bvh;
mod leaf;
mod whitted;
mod wide;

#[cfg(test)]
mod closed_form;
#[cfg(test)]
mod precision;
#[cfg(test)]
mod scenarios;
#[cfg(test)]
mod testutil;

pub use bvh::{
    BuildPreset, BvhLayout, BvhOptions, Emitter, InvalidScene, SceneBvh, casts_shadow, spawn_offset,
};
pub use whitted::{PixelCone, Rays, SurfaceTerms, Tracer, fresnel_reflectance, reflect, refract};

use glam::Vec3;
use vtfarm_scene::TriangleId;
use vtfarm_scene::bounds::{OutOfBounds, check, non_negative};

/// A ray; `direction` is unit length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub origin: Vec3,
    pub direction: Vec3,
}

/// The closest intersection of a ray with the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub triangle: TriangleId,
    /// Distance along the ray.
    pub t: f32,
    /// Barycentric weights of the triangle's vertices 1 and 2 (vertex 0 has
    /// `1 - u - v`).
    pub u: f32,
    pub v: f32,
}

/// A point on a surface where shading starts without a primary intersection
/// (vertex tracing shades reflector vertices directly).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    pub position: Vec3,
    /// Unit shading normal (interpolated vertex normal).
    pub normal: Vec3,
    /// The triangle the point lies on (gives material, object and geometric normal).
    pub triangle: TriangleId,
}

/// Settings of the recursion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceSettings {
    /// Maximum recursion depth: 1 shades the first surface only.
    pub max_depth: u32,
    /// Weight kr and kt by angle: see-through surfaces with the
    /// unpolarised Fresnel equations at their index of refraction (kr and
    /// kt are the head-on values), opaque reflectors with Schlick's
    /// approximation. A material whose own `fresnel` is set is weighted
    /// so either way; a thin sheet's (`thin`) index serves these weights
    /// only, its rays passing straight.
    pub fresnel: bool,
    /// Ray-tree branches whose weight (the product of kr/kt above them) is
    /// below this are left out of the signature.
    pub signature_min_weight: f32,
}

/// The deepest Whitted recursion accepted: each level is a stack frame of
/// the recursion, and deeper trees only risk the stack.
pub const MAX_TRACE_DEPTH: u32 = 64;

impl TraceSettings {
    /// `max_depth` 1 to [`MAX_TRACE_DEPTH`]; `signature_min_weight` finite
    /// and not negative.
    pub fn validate(&self) -> Result<(), OutOfBounds> {
        check(
            "max_depth",
            self.max_depth,
            format!("1 to {MAX_TRACE_DEPTH}"),
            |d| (1..=MAX_TRACE_DEPTH).contains(&d),
        )?;
        non_negative("signature_min_weight", self.signature_min_weight)?;
        Ok(())
    }
}

impl Default for TraceSettings {
    fn default() -> Self {
        TraceSettings {
            max_depth: 5,
            fresnel: false,
            signature_min_weight: 0.05,
        }
    }
}

/// What a refraction ray brought back ([`Tracer::trace_transmission`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transmission {
    /// The radiance arriving along the ray.
    pub radiance: Vec3,
    /// The part of `radiance` that the see-through surfaces along the ray
    /// reflect back (the ghost image; reflected light, see
    /// [`Sample::reflected`]).
    pub ghost: Vec3,
}

/// What one traced sample saw.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Total linear RGB radiance.
    pub color: Vec3,
    /// The reflected component: the light the glass reflects toward the
    /// eye, what a glare study measures. kr times the radiance of the first
    /// reflection ray, plus the reflections of the see-through surfaces the
    /// first refraction ray passes before an opaque one (a slab's back
    /// surface, the ghost image), weighted by the transmittances on the way.
    /// The thin-glass model counts the same, so the split does not depend
    /// on the quality level.
    pub reflected: Vec3,
    /// The transmitted component: kt times the radiance of the first
    /// refraction ray less the ghost counted in `reflected` (what is seen
    /// through the glass).
    pub transmitted: Vec3,
    /// The object hit by the first reflection ray (its
    /// [`vtfarm_scene::ObjectId::raw`]), or `vtfarm_scene::NONE`.
    pub reflected_object: u32,
    /// A compact ray-tree signature: a hash of the objects hit along the tree
    /// (and of shadow-ray outcomes), equal for samples whose trees match.
    pub signature: u64,
}
