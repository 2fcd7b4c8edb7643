//! Per-vertex reflection and refraction, PVRR (Kakimoto, Tatsukawa, Chun,
//! Nishita: "Real-time reflection and refraction on a per-vertex basis").
//!
//! Like a dynamic environment map, PVRR renders the scene once into a map and
//! textures the reflector with it; unlike one, it warps the map so that every
//! reflector vertex shows exactly the point its ray-traced reflection ray
//! hits. Per frame and reflector ([`Pvrr`]):
//!
//! 1. Per reflector vertex, the exact exit ray (the tracer's mirror ray, or
//!    the eye ray refracted at the front and again at the back face) and
//!    its closest scene hit P through the BVH (§3.1 steps 1 and 3.1).
//! 2. The virtual viewpoint: the least-squares point closest to all the
//!    extended exit rays (§3.2), and the frustum of §3.3: viewing direction
//!    the mean exit direction, near plane just in front of the reflector,
//!    sides containing every exit ray up to the far end of the scene. For a
//!    concave mirror or a convex lens the rays cross near the viewpoint and
//!    the map looks into the reversed region beyond the crossing (§4.2,
//!    figure 8); the map is the same kind of image, only the near plane moves.
//! 3. The map: the scene without the reflector (and without the lens's own
//!    back face) rasterized from the virtual viewpoint, `map_resolution`
//!    texels on its longer side: a z-buffer (`vtfarm_raster::id_buffer_clipped`)
//!    whose near plane is the frustum's, so nothing between the virtual
//!    viewpoint and the reflector (for a convex mirror, whatever lies behind
//!    the mirror) enters the map. Each texel's surface point is rebuilt from
//!    the triangle the z-buffer shows there (the texel-centre ray on the
//!    triangle's plane, barycentric normal) and shaded like a ray-traced hit.
//! 4. Texture coordinates: the projection of each vertex's P into the map
//!    (§3.4), so the warped map shows P exactly at the vertex.
//! 5. Per reflector pixel: the texture coordinates interpolated with the
//!    barycentric weights of the pixel's exact surface point, and a bilinear
//!    lookup. `vtfarm_method::shade_reflector` then finishes the pixel as
//!    `local + kr * reflected + kt * transmitted`, exactly as the ray tracer.
//!
//! Extensions of §4: refraction ([`Refraction::Mapped`]) maps what is seen
//! through both faces the same way, with one index of refraction per colour
//! channel for chromatic aberration (three sets of texture coordinates over
//! one map, as in figure 15); multiple reflection (§4.4) recurses: a map texel
//! that shows another specular object is finished with that object's own
//! PVRR map from the virtual viewpoint, down to the tracer's `max_depth`.
//!
//! Refraction of the cockpit's cover glass: the default
//! ([`Refraction::Traced`]) leaves transmission to the shared finishing
//! step, which traces the refraction ray of every pixel. The glare study's
//! transmitted component must be exact, and a refraction map does poorly
//! there: the instruments sit a few centimetres behind a glass that is
//! concave towards the driver, so the near plane (one plane past the whole
//! glass, §3.3) clips the P of nearly half the vertices, and the pixels
//! around them fall back on tracing anyway (on the test cockpit, 160×90 at
//! detail 0.3: two thirds of the pixels, with a transmitted error of 7 % of
//! the mean). [`Refraction::Mapped`] is
//! for lenses: there the back face's own shading and kt are interpolated
//! from the vertices and the map supplies what lies beyond.
//!
//! # Deviation from the paper: vertices the map cannot show
//!
//! The paper guarantees that every vertex shows its P. That holds only when
//! the virtual viewpoint sees P: another object may hide P from it (§6,
//! figure 16), P may lie in the zooming region of a concave mirror or convex
//! lens (§4.2) or outside the widest frustum (80° half-angle), and a face
//! may reflect totally. Each vertex's P is therefore checked with one ray
//! from the virtual viewpoint; a vertex that fails has no texture
//! coordinate, and the pixels of the triangles around it are traced exactly
//! instead (the paper shows whatever the map holds there). On the cockpit's
//! concave glass the left door window is partly hidden from the virtual
//! viewpoint by the cab: about a quarter of the glass's pixels are traced,
//! and the reflected error against the reference drops from 0.021 (a quarter
//! of the mean reflected radiance) to 1e-5.
//!
//! # Limitations
//!
//! - Occlusion between vertices (§6): the checks above are per vertex; inside
//!   a triangle whose three vertices pass, the map shows what the virtual
//!   viewpoint sees, which differs from the ray tracer where an occluder's
//!   silhouette crosses the triangle. Only a planar mirror is free of this.
//! - Sparse vertices (§6): accuracy between vertices depends on the
//!   tessellation; a large quadrilateral mirror is only exact at its corners.
//! - One map per reflector: no subdivision of strongly curved surfaces into
//!   patches (§4.1) and no alignment of the map's up vector with a principal
//!   direction (§4.3).
//! - Map texels are shaded like ray-traced hits (Phong with shadow rays) but
//!   from the virtual viewpoint: view-dependent highlights on the reflected
//!   surfaces differ slightly from the ray tracer's. Specular objects seen in
//!   a map reflect through their own map (§4.4) but transmit by tracing.
//!
//! # Counters
//!
//! `searches` counts per-vertex exit rays (one per vertex for reflection, up
//! to two per vertex and distinct index for refraction); `rays` adds one
//! occlusion test per vertex, the traced fallbacks (one ray each: the
//! object seen, shaded in place), the transmission rays of specular surfaces
//! seen in maps and the rays of the shared finishing step. Map texels are
//! rasterized, not cast, and are not rays; shadow rays are not counted, as
//! in vertex tracing. `setup_time` covers the exit rays, viewpoints and maps.

mod level;
mod map;
mod paths;
mod viewpoint;
mod warp;

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;
use vtfarm_method::{
    MethodCounters, MethodFrame, MethodOutput, Reflection, ReflectionMethod, shade_reflector,
};

use crate::level::{Context, Counts, Level};
use crate::warp::{Kind, Warp};

/// PVRR as a [`ReflectionMethod`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pvrr {
    pub config: PvrrConfig,
}

/// Settings of [`Pvrr`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PvrrConfig {
    /// Texels on the longer side of each reflection or refraction map.
    pub map_resolution: u32,
    pub refraction: Refraction,
}

impl Default for PvrrConfig {
    fn default() -> Self {
        PvrrConfig {
            map_resolution: 256,
            refraction: Refraction::Traced,
        }
    }
}

/// How the light transmitted through the reflector is found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Refraction {
    /// Traced per pixel by `vtfarm_method::shade_reflector`.
    Traced,
    /// A refraction map through front and back faces (§4.5); `iors` gives
    /// one index of refraction per colour channel (R, G, B) for chromatic
    /// aberration (the paper's 1.60 / 1.61 / 1.62), `None` the material's.
    Mapped { iors: Option<[f32; 3]> },
}

impl Pvrr {
    pub fn new(config: PvrrConfig) -> Self {
        Pvrr { config }
    }
}

impl ReflectionMethod for Pvrr {
    fn name(&self) -> String {
        match self.config.refraction {
            Refraction::Traced => "pvrr".to_owned(),
            Refraction::Mapped { .. } => "pvrr-refraction".to_owned(),
        }
    }

    fn render(&self, frame: &MethodFrame<'_>) -> MethodOutput {
        self.render_counted(frame).0
    }
}

impl Pvrr {
    /// [`ReflectionMethod::render`] plus what the levels counted.
    fn render_counted(&self, frame: &MethodFrame<'_>) -> (MethodOutput, Counts) {
        let start = Instant::now();
        let context = Context::new(&self.config, frame);
        let level = Level {
            context: &context,
            tracer: frame.tracer,
        };
        let eye = frame.camera.eye;
        let pixels = frame.pixels();
        let build = |kind| Warp::build(&level, eye, frame.reflector, kind);
        let reflection = reflects(frame).then(|| build(Kind::Reflection));
        let refraction = self.refraction_kind(frame).map(build);
        let setup_time = start.elapsed();

        let (reflections, transmitted): (Vec<Reflection>, Vec<Vec3>) = pixels
            .par_iter()
            .map(|p| {
                if level.stopped() {
                    return (Reflection::NONE, Vec3::ZERO);
                }
                let at = |w: &Warp<'_>| w.radiance_at(&p.point, p.incoming);
                let reflected = reflection.as_ref().map(at);
                let through = refraction.as_ref().map_or(Vec3::ZERO, |w| at(w).radiance);
                let reflection = reflected.map_or(Reflection::NONE, |r| Reflection {
                    radiance: r.radiance,
                    object: r.object,
                });
                (reflection, through)
            })
            .unzip();
        let (bitmap, finish_rays) = shade_reflector(
            frame,
            &pixels,
            &reflections,
            refraction.as_ref().map(|_| transmitted.as_slice()),
        );
        level.count_charged_rays(finish_rays);
        let counts = context.counts();
        tracing::debug!(?counts, "pvrr rendered {} pixels", pixels.len());
        let output = MethodOutput {
            bitmap,
            counters: MethodCounters {
                rays: counts.rays,
                searches: counts.searches,
                pixels: pixels.len() as u64,
                setup_time,
                time: start.elapsed(),
            },
        };
        (output, counts)
    }
}

/// Whether the reflector mirrors at all (the shared finishing step skips
/// the reflection of a reflector that does not).
fn reflects(frame: &MethodFrame<'_>) -> bool {
    let scene = frame.tracer.bvh.scene();
    frame
        .reflector
        .first()
        .is_some_and(|&t| scene.material_of(t).reflectance.max_element() > 0.0)
}

impl Pvrr {
    /// The refraction map to build, if any: only for a transmitting reflector.
    fn refraction_kind(&self, frame: &MethodFrame<'_>) -> Option<Kind> {
        let Refraction::Mapped { iors } = self.config.refraction else {
            return None;
        };
        let scene = frame.tracer.bvh.scene();
        let first = *frame.reflector.first()?;
        let material = scene.material_of(first);
        (material.transmittance.max_element() > 0.0).then(|| Kind::Refraction {
            iors: iors.unwrap_or([material.bending_ior(); 3]),
        })
    }
}

#[cfg(test)]
mod tests;
