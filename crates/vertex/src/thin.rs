//! The raster pass of the thin-glass model (`Transmission::Raster`): what
//! the reflectors show behind them, computed per pixel the way a rasterizer
//! blends a transparent surface over the scene, with no ray traced.
//!
//! A see-through reflector is a thin shell: its front surface, optionally a
//! back surface close behind (a slab, like the cover glass: a see-through
//! surface that is no reflector, or one of the reflector's own that faces
//! away from the eye), then the opaque scene. Per reflector pixel, from the
//! interpolated normals:
//! - the transmitted part is kt(front) · kt(back) times the opaque surface
//!   behind, seen along the eye ray shifted sideways by the slab (Snell
//!   through both surfaces, which leaves the direction unchanged), shaded
//!   with local Phong whose shadow test is a shadow map per light (Whitted's
//!   shadow rays treat the glass as opaque, and so does the map; surfaces
//!   that only emit cast no shadow in either, `vtfarm_trace::casts_shadow`);
//! - the back surface mirrors about what the front does: the reflected part
//!   is scaled by (kr(front) + kt(front)² · kr(back)) / kr(front), kr(back)
//!   taken along the refracted ray. This ghost counts as reflected light,
//!   as in traced shading (`vtfarm_trace::Sample::reflected`), so the
//!   reflected/transmitted split is the same at every quality level.
//!
//! Everything here is deterministic for any thread count, so workers rebuild
//! it like the ID buffers.

use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use glam::Vec3;
use rayon::prelude::*;
use vtfarm_raster::{IdBuffer, IdPass};
use vtfarm_scene::shading::phong;
use vtfarm_scene::{Camera, Light, LightKind, NONE, Projector, Scene, TriangleId};
use vtfarm_trace::{SurfacePoint, Tracer, refract};

use crate::{
    PixelRect, PixelValue, Transmission, barycentric_in_plane, pixel_surface_along,
    reflector_bounds,
};

/// What lies behind the reflectors: the ID buffer of the opaque scene
/// (neither reflectors nor see-through surfaces), and with
/// [`Transmission::Raster`] what the thin-glass terms of every see-through
/// reflector pixel need (see the module docs). Part of the frame's raster
/// pass, built over the reflectors' bounds only ([`crate::reflector_bounds`]):
/// the ID buffer is empty elsewhere.
#[derive(Debug)]
pub struct Behind {
    pub ids: IdBuffer,
    /// The pixels the thin-glass terms cover.
    bounds: PixelRect,
    glass: GlassTerms,
    /// How many glass pixels' terms were computed (see
    /// [`Behind::glass_computations`]).
    computed: AtomicU64,
}

/// When the thin-glass terms of the glass pixels are computed. Either way a
/// pixel gets the same terms, bit for bit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum GlassPass {
    /// All of them in [`Behind::new`], as a rasterizer blends the glass
    /// over the frame: a frame rendered on one machine.
    #[default]
    Upfront,
    /// Each as its pixel is finished: a farm worker, which finishes only
    /// the pixels of its packages, so the pass splits between workers
    /// instead of being repeated on each. A pixel's terms are computed the
    /// first time and kept: the later stages of a progressive frame, which
    /// finish the same pixels again, take them from the store.
    OnDemand,
}

/// The thin-glass terms, or what computing them needs.
#[derive(Debug)]
enum GlassTerms {
    /// Traced transmission, or no see-through reflector pixel.
    Nothing,
    /// Per pixel of `bounds`, row-major.
    Upfront(Vec<ThinGlass>),
    /// The see-through surfaces that are not reflectors (a slab's back),
    /// the shadow maps and the frame camera's view, and the terms computed
    /// so far: each pixel's once per frame, however many stages of a
    /// progressive frame finish it.
    OnDemand {
        layers: IdBuffer,
        shadows: Arc<ShadowMaps>,
        view: View,
        store: TermStore,
    },
}

/// The thin-glass terms computed so far, per pixel of [`Behind`]'s bounds.
/// A row's slots are allocated when a pixel of it is first finished, so a
/// worker pays only for the rows its packages reach.
#[derive(Debug)]
struct TermStore {
    width: u32,
    rows: Box<[OnceLock<Box<[TermSlot]>>]>,
}

/// One pixel's stored terms: their bits, and whether they are there yet.
/// Two threads that computed the same pixel's terms at once would store the
/// same bits (the terms are a function of the pixel), so no lock is needed.
#[derive(Debug, Default)]
struct TermSlot {
    bits: [AtomicU32; 4],
    stored: AtomicBool,
}

impl TermStore {
    fn new(bounds: PixelRect) -> TermStore {
        let rows = (bounds.y1 - bounds.y0) as usize;
        TermStore {
            width: bounds.x1 - bounds.x0,
            rows: std::iter::repeat_with(OnceLock::new).take(rows).collect(),
        }
    }

    /// The terms of the pixel in `column` of `row` (relative to the
    /// bounds), computed by `compute` unless they already were.
    fn get_or_compute(
        &self,
        column: u32,
        row: u32,
        compute: impl FnOnce() -> ThinGlass,
    ) -> ThinGlass {
        let slots = self.rows[row as usize].get_or_init(|| {
            std::iter::repeat_with(TermSlot::default)
                .take(self.width as usize)
                .collect()
        });
        let slot = &slots[column as usize];
        if slot.stored.load(Ordering::Acquire) {
            let [x, y, z, scale] = slot
                .bits
                .each_ref()
                .map(|b| f32::from_bits(b.load(Ordering::Relaxed)));
            return ThinGlass {
                transmitted: Vec3::new(x, y, z),
                reflection_scale: scale,
            };
        }
        let terms = compute();
        let t = terms.transmitted;
        for (b, v) in slot
            .bits
            .iter()
            .zip([t.x, t.y, t.z, terms.reflection_scale])
        {
            b.store(v.to_bits(), Ordering::Relaxed);
        }
        slot.stored.store(true, Ordering::Release);
        terms
    }
}

/// Pixels around the reflectors that [`Behind`] covers besides them: the
/// behind-glass hints read 4-neighbours, and the thin-glass model looks
/// beside a pixel by the slab's sideways shift (about a pixel for the
/// cockpit's 3-mm glass at 1920×1080).
const BEHIND_MARGIN: u32 = 16;

/// The thin-glass terms of one reflector pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
struct ThinGlass {
    /// kt(front) · kt(back) · the opaque scene behind.
    transmitted: Vec3,
    /// What the front surface's reflection is multiplied by to add the back
    /// surface's (1 for a single sheet or an opaque reflector).
    reflection_scale: f32,
}

impl Default for ThinGlass {
    /// Nothing transmitted, the reflection as it is (an opaque reflector).
    fn default() -> Self {
        ThinGlass {
            transmitted: Vec3::ZERO,
            reflection_scale: 1.0,
        }
    }
}

impl Behind {
    /// Rasterizes what lies behind the reflectors of a frame whose ID buffer
    /// is `ids` (`is_reflector` per scene triangle).
    pub fn new(
        tracer: &Tracer<'_>,
        camera: &Camera,
        ids: &IdBuffer,
        is_reflector: &[bool],
        transmission: Transmission,
        pass: GlassPass,
        cache: &ShadowCache,
    ) -> Behind {
        let scene = tracer.bvh.scene();
        let buffers = BehindBuffers::new(scene, camera, None, is_reflector, transmission);
        Behind::from_buffers(tracer, camera, ids, is_reflector, buffers, pass, cache)
    }

    /// A worker's frame set-up: the frame's ID buffer over `frame_within`
    /// and what lies behind its reflectors ([`Behind::new`]), the buffers
    /// rasterized together (the scene projected and set up once).
    #[allow(clippy::too_many_arguments)]
    pub fn with_frame_ids(
        tracer: &Tracer<'_>,
        camera: &Camera,
        frame_within: PixelRect,
        is_reflector: &[bool],
        transmission: Transmission,
        pass: GlassPass,
        cache: &ShadowCache,
        id_cache: &IdBufferCache,
    ) -> (IdBuffer, Behind) {
        let key = IdBufferKey {
            camera: *camera,
            frame_within,
            transmission,
        };
        let mut buffers = id_cache.get(key, || {
            BehindBuffers::new(
                tracer.bvh.scene(),
                camera,
                Some(frame_within),
                is_reflector,
                transmission,
            )
        });
        let ids = buffers.frame.take().expect("asked for the frame's buffer");
        let behind = Behind::from_buffers(tracer, camera, &ids, is_reflector, buffers, pass, cache);
        (ids, behind)
    }

    fn from_buffers(
        tracer: &Tracer<'_>,
        camera: &Camera,
        ids: &IdBuffer,
        is_reflector: &[bool],
        buffers: BehindBuffers,
        pass: GlassPass,
        cache: &ShadowCache,
    ) -> Behind {
        let BehindBuffers {
            bounds,
            behind,
            layers,
            ..
        } = buffers;
        let (glass, computed) = match layers {
            None => (GlassTerms::Nothing, 0),
            Some(layers) => GlassTerms::new(
                tracer,
                camera,
                ids,
                &behind,
                layers,
                is_reflector,
                bounds,
                pass,
                cache,
            ),
        };
        Behind {
            ids: behind,
            bounds,
            glass,
            computed: AtomicU64::new(computed),
        }
    }

    /// How many glass pixels' thin-glass terms were computed: every one in
    /// [`Behind::new`] with [`GlassPass::Upfront`]; with
    /// [`GlassPass::OnDemand`], each pixel the first time it is finished
    /// (later stages of a progressive frame take the stored terms).
    pub fn glass_computations(&self) -> u64 {
        self.computed.load(Ordering::Relaxed)
    }

    /// Finishes a reflector pixel whose value holds the local part and the
    /// front surface's reflection: adds the back surface's reflection and the
    /// transmitted part (nothing with traced transmission). `tracer`,
    /// `camera` and `ids` are the frame's, as given to [`Behind::new`];
    /// (`x`, `y`) is the value's pixel.
    pub fn finish(
        &self,
        tracer: &Tracer<'_>,
        camera: &Camera,
        ids: &IdBuffer,
        (x, y): (u32, u32),
        value: &mut PixelValue,
    ) {
        if !self.bounds.contains(x, y) {
            return;
        }
        let glass = match &self.glass {
            GlassTerms::Nothing => return,
            GlassTerms::Upfront(terms) => {
                let local =
                    (y - self.bounds.y0) * (self.bounds.x1 - self.bounds.x0) + (x - self.bounds.x0);
                terms[local as usize]
            }
            GlassTerms::OnDemand {
                layers,
                shadows,
                view,
                store,
            } => {
                let t = ids.triangle_at(x, y);
                if t == NONE || !see_through(tracer.bvh.scene(), TriangleId(t)) {
                    // What the up-front pass holds there, to the bit.
                    ThinGlass::default()
                } else {
                    let (column, row) = (x - self.bounds.x0, y - self.bounds.y0);
                    store.get_or_compute(column, row, || {
                        self.computed.fetch_add(1, Ordering::Relaxed);
                        glass_at(tracer, camera, view, ids, layers, &self.ids, shadows, x, y)
                    })
                }
            }
        };
        let ghost = value.reflected * (glass.reflection_scale - 1.0);
        value.reflected += ghost;
        value.transmitted += glass.transmitted;
        value.color += ghost + glass.transmitted;
    }
}

/// Whether `triangle` belongs in the ID buffer of what lies behind the
/// reflectors: neither a reflector nor see-through.
pub(crate) fn lies_behind(scene: &Scene, is_reflector: &[bool], triangle: TriangleId) -> bool {
    !is_reflector[triangle.index()] && !see_through(scene, triangle)
}

/// Whether `triangle`'s front (its winding's normal) faces away from `eye`:
/// the back surface of a closed pane, seen through its front.
fn faces_away(scene: &Scene, eye: Vec3, triangle: TriangleId) -> bool {
    let [a, ..] = scene.triangle_positions(triangle);
    (a - eye).dot(scene.geometric_normal(triangle)) > 0.0
}

/// Whether `triangle`'s material lets light through.
fn see_through(scene: &Scene, triangle: TriangleId) -> bool {
    scene.material_of(triangle).see_through()
}

/// The ID buffers a frame's [`Behind`] is made of, rasterized in one go.
#[derive(Clone, Debug)]
struct BehindBuffers {
    /// The pixels [`Behind`] covers.
    bounds: PixelRect,
    /// The frame's own buffer, when asked for.
    frame: Option<IdBuffer>,
    /// The opaque scene (neither reflectors nor see-through surfaces).
    behind: IdBuffer,
    /// The see-through surfaces that can lie behind a reflector's front (a
    /// slab's back): those that are not reflectors, and the reflectors'
    /// that face away from the eye (the back of a pane whose two faces are
    /// one reflector). Over the reflectors alone (only glass pixels read
    /// it): with the thin-glass model, when a reflector is see-through.
    layers: Option<IdBuffer>,
}

impl BehindBuffers {
    fn new(
        scene: &Scene,
        camera: &Camera,
        frame_within: Option<PixelRect>,
        is_reflector: &[bool],
        transmission: Transmission,
    ) -> BehindBuffers {
        let bounds = reflector_bounds(scene, camera, is_reflector, BEHIND_MARGIN);
        let any_glass = transmission == Transmission::Raster
            && (scene.triangle_ids().zip(is_reflector)).any(|(t, &r)| r && see_through(scene, t));
        let all = |_: TriangleId| true;
        let opaque = |t: TriangleId| lies_behind(scene, is_reflector, t);
        let not_opaque = |t: TriangleId| !opaque(t);
        let layer = |t: TriangleId| {
            see_through(scene, t) && (!is_reflector[t.index()] || faces_away(scene, camera.eye, t))
        };
        let mut passes = vec![IdPass {
            within: bounds,
            keep: &opaque,
        }];
        if any_glass {
            passes.push(IdPass {
                within: reflector_bounds(scene, camera, is_reflector, 0),
                keep: &layer,
            });
        }
        // The frame's buffer is the nearer of the opaque scene's and the
        // rest's where the first covers it (the usual case: the margins are
        // small): the rest is little to scan-convert, the opaque scene is
        // most of the set-up and is not scan-converted twice.
        let clamp = |r: PixelRect| r.clamped(camera.width, camera.height);
        let split = frame_within.filter(|&f| clamp(bounds).holds(clamp(f)));
        if let Some(within) = frame_within {
            let keep: &(dyn Fn(TriangleId) -> bool + Sync) =
                if split.is_some() { &not_opaque } else { &all };
            passes.push(IdPass { within, keep });
        }
        let mut buffers = vtfarm_raster::id_buffers_within(scene, camera, &passes).into_iter();
        let behind = buffers.next().expect("one buffer per pass");
        let layers = any_glass.then(|| buffers.next().expect("one buffer per pass"));
        let frame = match (buffers.next(), split) {
            (Some(rest), Some(within)) => Some(vtfarm_raster::nearer_of(&behind, &rest, within)),
            (frame, _) => frame,
        };
        BehindBuffers {
            bounds,
            frame,
            behind,
            layers,
        }
    }
}

impl GlassTerms {
    /// The thin-glass terms of every pixel of `bounds` whose reflector is
    /// see-through, or (`GlassPass::OnDemand`) what computing them needs;
    /// and how many were computed.
    #[allow(clippy::too_many_arguments)]
    fn new(
        tracer: &Tracer<'_>,
        camera: &Camera,
        ids: &IdBuffer,
        behind: &IdBuffer,
        layers: IdBuffer,
        is_reflector: &[bool],
        bounds: PixelRect,
        pass: GlassPass,
        cache: &ShadowCache,
    ) -> (GlassTerms, u64) {
        let scene = tracer.bvh.scene();
        let glass_triangle = |t: TriangleId| is_reflector[t.index()] && see_through(scene, t);
        let glass_pixel = |x: u32, y: u32| {
            let t = ids.triangle_at(x, y);
            t != NONE && glass_triangle(TriangleId(t))
        };
        if !bounds.pixels().any(|(x, y)| glass_pixel(x, y)) {
            return (GlassTerms::Nothing, 0);
        }
        let shadows =
            ShadowMaps::for_frame(tracer, camera, ids, behind, bounds, &glass_triangle, cache);
        let view = View {
            projector: Projector::new(camera),
            forward: camera.basis().0,
        };
        if pass == GlassPass::OnDemand {
            let store = TermStore::new(bounds);
            let terms = GlassTerms::OnDemand {
                layers,
                shadows,
                view,
                store,
            };
            return (terms, 0);
        }
        let width = (bounds.x1 - bounds.x0) as usize;
        let mut out = vec![ThinGlass::default(); width * (bounds.y1 - bounds.y0) as usize];
        let computed = out
            .par_chunks_mut(width)
            .enumerate()
            .map(|(row, slots)| {
                let y = bounds.y0 + row as u32;
                let mut computed = 0;
                for (column, slot) in slots.iter_mut().enumerate() {
                    let x = bounds.x0 + column as u32;
                    if glass_pixel(x, y) {
                        *slot =
                            glass_at(tracer, camera, &view, ids, &layers, behind, &shadows, x, y);
                        computed += 1;
                    }
                }
                computed
            })
            .sum();
        (GlassTerms::Upfront(out), computed)
    }
}

/// The frame camera's projector and forward axis (view depth runs along it).
#[derive(Clone, Copy, Debug)]
struct View {
    projector: Projector,
    forward: Vec3,
}

/// The thin-glass terms at one glass pixel (`view` is `camera`'s).
#[allow(clippy::too_many_arguments)]
fn glass_at(
    tracer: &Tracer<'_>,
    camera: &Camera,
    view: &View,
    ids: &IdBuffer,
    layers: &IdBuffer,
    behind: &IdBuffer,
    shadows: &ShadowMaps,
    x: u32,
    y: u32,
) -> ThinGlass {
    let scene = tracer.bvh.scene();
    let direction = view.projector.pixel_ray(x, y);
    let (front, direction) = pixel_surface_along(
        scene,
        camera,
        ids,
        TriangleId(ids.triangle_at(x, y)),
        (x, y),
        direction,
    );
    // A pane drawn as one surface facing away is in the layers too, as
    // its own nearest layer: it has no back surface.
    let back = TriangleId::from_raw(layers.triangle_at(x, y))
        .filter(|&back| back != front.triangle && layers.depth_at(x, y) < behind.depth_at(x, y))
        .map(|back| pixel_surface_along(scene, camera, layers, back, (x, y), direction).0);
    let slab = SlabWeights::of(tracer, &front, direction, back.as_ref());
    let shift = back
        .and_then(|back_point| {
            let inside = inside_direction(scene, &front, direction)?;
            Some(slab_shift(&front, &back_point, direction, inside))
        })
        .unwrap_or(Vec3::ZERO);
    let seen = opaque_radiance(
        tracer,
        camera,
        view,
        behind,
        shadows,
        (x, y, direction),
        front.position,
        shift,
    );
    ThinGlass {
        transmitted: slab.behind * seen,
        reflection_scale: slab.reflection_scale,
    }
}

/// What a see-through reflector lets through and adds to its reflection
/// at one point: the weight of the opaque scene behind it, kt(front) ·
/// kt(back), and the factor on the front surface's reflection that adds
/// the back surface's ghost (see the module docs). An opaque reflector's
/// are [`SlabWeights::OPAQUE`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlabWeights {
    pub behind: Vec3,
    pub reflection_scale: f32,
}

impl SlabWeights {
    /// Nothing let through, the reflection as it is.
    pub const OPAQUE: SlabWeights = SlabWeights {
        behind: Vec3::ZERO,
        reflection_scale: 1.0,
    };

    /// The weights at `front`, seen along `direction`, with the slab's
    /// `back` surface behind it (met along the refracted ray) or none.
    fn of(
        tracer: &Tracer<'_>,
        front: &SurfacePoint,
        direction: Vec3,
        back: Option<&SurfacePoint>,
    ) -> SlabWeights {
        let (kr, kt) = tracer.weights(front, direction);
        let Some(back) = back else {
            return SlabWeights {
                behind: kt,
                reflection_scale: 1.0,
            };
        };
        // The back surface is met from inside, along the refracted ray
        // (with Fresnel weights its angle matters; parallel surfaces give
        // it the front's kr again, as a traced ray finds).
        let scene = tracer.bvh.scene();
        let inside = inside_direction(scene, front, direction).unwrap_or(direction);
        let (kr_back, kt_back) = tracer.weights(back, inside);
        // The ghost: in through the front, reflected at the back, out
        // through the front again. Counted as reflected, as the tracer
        // counts it (`vtfarm_trace::Sample::reflected`).
        let kr_front = kr.max_element();
        let reflection_scale = if kr_front > 0.0 {
            1.0 + (kt * kt * kr_back).max_element() / kr_front
        } else {
            1.0
        };
        SlabWeights {
            behind: kt * kt_back,
            reflection_scale,
        }
    }

    /// The weights at a reflector's surface point seen from `eye`, for a
    /// view that draws the scene behind the glass itself and blends the
    /// traced reflection over it: what [`Behind`] applies per pixel, at
    /// the point. The back surface is the first see-through one along the
    /// refracted ray; nothing is let through with traced transmission (the
    /// traced sample holds it).
    pub fn at_point(
        tracer: &Tracer<'_>,
        eye: Vec3,
        point: &SurfacePoint,
        transmission: Transmission,
    ) -> SlabWeights {
        let scene = tracer.bvh.scene();
        if transmission != Transmission::Raster || !see_through(scene, point.triangle) {
            return SlabWeights::OPAQUE;
        }
        let direction = (point.position - eye).normalize_or(-point.normal);
        let inside = inside_direction(scene, point, direction).unwrap_or(direction);
        let ray = tracer.bvh.spawn_ray(point.position, point.triangle, inside);
        let back = (tracer.bvh.closest_hit(&ray, f32::INFINITY))
            .map(|hit| tracer.bvh.surface_point(&hit))
            .filter(|b| b.triangle != point.triangle && see_through(scene, b.triangle));
        SlabWeights::of(tracer, point, direction, back.as_ref())
    }
}

/// How far sideways a ray along `direction` leaves a slab whose front and
/// back surfaces it meets (straight) at `front` and `back`: inside, it runs
/// along the Snell direction `inside` ([`inside_direction`]) to the back
/// plane, and leaves parallel to `direction` again.
fn slab_shift(front: &SurfacePoint, back: &SurfacePoint, direction: Vec3, inside: Vec3) -> Vec3 {
    let normal = facing_normal(front, direction);
    let thickness = (back.position - front.position).dot(-normal);
    let along = inside.dot(-normal);
    if thickness <= 0.0 || along <= 1e-6 {
        return Vec3::ZERO;
    }
    let exit = inside * (thickness / along);
    // The exit point relative to where the straight ray would be.
    exit - direction * exit.dot(direction)
}

/// The front surface's normal on the side `direction` comes from.
fn facing_normal(front: &SurfacePoint, direction: Vec3) -> Vec3 {
    if front.normal.dot(direction) > 0.0 {
        -front.normal
    } else {
        front.normal
    }
}

/// The direction of a ray along `direction` inside a slab whose front
/// surface it enters at `front` (Snell); `None` on total internal reflection.
fn inside_direction(scene: &Scene, front: &SurfacePoint, direction: Vec3) -> Option<Vec3> {
    // A thin sheet's rays pass straight (`Material::bending_ior`).
    let eta = 1.0 / scene.material_of(front.triangle).bending_ior();
    refract(direction, facing_normal(front, direction), eta)
}

/// The rasterizer's colour of the opaque scene seen through glass pixel
/// (x, y) (front surface point `front`) along the eye ray shifted sideways
/// by `shift`: the triangle the behind buffer shows where the shifted ray's
/// hit projects, shaded with shadow-mapped local Phong.
#[allow(clippy::too_many_arguments)]
fn opaque_radiance(
    tracer: &Tracer<'_>,
    camera: &Camera,
    view: &View,
    behind: &IdBuffer,
    shadows: &ShadowMaps,
    (x, y, direction): (u32, u32, Vec3),
    front: Vec3,
    shift: Vec3,
) -> Vec3 {
    let scene = tracer.bvh.scene();
    if behind.triangle_at(x, y) == NONE {
        return tracer.lighting.background;
    }
    // The shifted ray is parallel to the eye ray: it meets the opaque scene
    // about the shift beside where the eye ray does.
    let straight = camera.eye + direction * (behind.depth_at(x, y) / direction.dot(view.forward));
    let Some(guess) = view.projector.project(straight + shift) else {
        return tracer.lighting.background;
    };
    let origin = front + shift;
    let (gx, gy) = (floor(guess.x), floor(guess.y));
    // The triangle the behind buffer shows at the guess or, when the
    // shifted ray misses it, at a neighbouring pixel: the first the ray
    // meets inside.
    let candidates = [
        (0, 0),
        (1, 0),
        (-1, 0),
        (0, 1),
        (0, -1),
        (1, 1),
        (-1, -1),
        (1, -1),
        (-1, 1),
    ];
    let mut first = None;
    let mut found = None;
    for (dx, dy) in candidates {
        let (px, py) = (gx + dx, gy + dy);
        if px < 0 || py < 0 || px >= behind.width as i64 || py >= behind.height as i64 {
            continue;
        }
        let Some(triangle) = TriangleId::from_raw(behind.triangle_at(px as u32, py as u32)) else {
            continue;
        };
        let Some((position, weights)) = ray_plane(scene, triangle, origin, direction) else {
            continue;
        };
        first.get_or_insert((triangle, position, weights));
        if weights.iter().all(|&w| w >= -1e-4) {
            found = Some((triangle, position, weights));
            break;
        }
    }
    let Some((triangle, position, [wa, wb, wc])) = found.or(first) else {
        return tracer.lighting.background;
    };
    let [na, nb, nc] = scene.triangle_normals(triangle);
    let normal = normalize_or_else(na * wa + nb * wb + nc * wc, || {
        scene.geometric_normal(triangle).normalize_or(Vec3::Y)
    });
    // A pixel's footprint there, for the texture's mip level (an
    // untextured material is borrowed whatever the footprint).
    let footprint = if scene.material_of(triangle).is_textured() {
        (position - camera.eye).length() * camera.pixel_size_at_unit_depth()
    } else {
        0.0
    };
    phong(
        &scene.textured_material(triangle, Vec3::new(wa, wb, wc), footprint),
        tracer.lighting,
        position,
        normal,
        -direction,
        |light, _, _| {
            let k = tracer
                .lighting
                .lights
                .iter()
                .position(|l| std::ptr::eq(l, light))
                .unwrap_or(usize::MAX);
            shadows.lit(k, position, triangle)
        },
    )
}

/// `v.normalize_or(fallback())` (the same operations), with the fallback
/// worked out only when needed.
pub(crate) fn normalize_or_else(v: Vec3, fallback: impl FnOnce() -> Vec3) -> Vec3 {
    let rcp = v.length_recip();
    if rcp.is_finite() && rcp > 0.0 {
        v * rcp
    } else {
        fallback()
    }
}

/// `v.floor() as i64`, without a call to the C library's `floorf` (the
/// portable x86-64 target has no rounding instruction): exact for every
/// `f32`, NaN giving 0 and the infinities saturating as `as` does.
fn floor(v: f32) -> i64 {
    let truncated = v as i64;
    // Only a negative non-integer truncates upwards; beyond 2^23 every
    // f32 is an integer and the conversion back is exact.
    if (truncated as f32) > v {
        truncated.saturating_sub(1)
    } else {
        truncated
    }
}

/// Where the ray from `origin` along `direction` meets the plane of
/// `triangle`, and the barycentric weights of that point.
fn ray_plane(
    scene: &Scene,
    triangle: TriangleId,
    origin: Vec3,
    direction: Vec3,
) -> Option<(Vec3, [f32; 3])> {
    let [a, b, c] = scene.triangle_positions(triangle);
    let plane = (b - a).cross(c - a);
    let denom = direction.dot(plane);
    if denom.abs() <= 1e-12 {
        return None;
    }
    let position = origin + direction * ((a - origin).dot(plane) / denom);
    Some((position, barycentric_in_plane([a, b, c], plane, position)))
}

/// The box the shadow maps of a frame cover: around the opaque points
/// behind the glass pixels of `bounds`, snapped outward to a grid (empty,
/// `lo` above `hi`, when there are none).
fn shadow_box(
    camera: &Camera,
    ids: &IdBuffer,
    behind: &IdBuffer,
    bounds: PixelRect,
    glass_triangle: &dyn Fn(TriangleId) -> bool,
) -> (Vec3, Vec3) {
    // The opaque points behind the glass, bounded by a box. A pass
    // over every pixel of the reflectors' bounds on every frame: each
    // triangle's test is made once per run of its pixels, and the
    // points need no unit rays.
    let projector = Projector::new(camera);
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    let mut last = (NONE, false);
    for (x, y) in bounds.pixels() {
        let t = ids.triangle_at(x, y);
        if t != last.0 {
            last = (t, t != NONE && glass_triangle(TriangleId(t)));
        }
        if last.1 && behind.triangle_at(x, y) != NONE {
            let p = camera.eye + projector.pixel_depth_step(x, y) * behind.depth_at(x, y);
            lo = lo.min(p);
            hi = hi.max(p);
        }
    }
    if lo.x <= hi.x {
        let extent = (hi - lo).max_element().max(1e-3);
        let grid = 2f32.powi((extent / 4.0).log2().ceil() as i32);
        lo = (lo / grid).floor() * grid;
        hi = (hi / grid).ceil() * grid;
    }
    (lo, hi)
}

/// Where the thin-glass pass's shadow maps look from: one camera per light
/// (`None` for a light that sits among the points it lights, which then
/// lights them all), each map [`SHADOW_MAP_SIZE`] texels square and
/// holding every triangle that casts a shadow
/// (`vtfarm_trace::casts_shadow`), and how much nearer than a point an
/// occluder must be to shadow it (unless the map shows the point's own
/// triangle there).
#[derive(Clone, Debug, PartialEq)]
pub struct ShadowViews {
    pub cameras: Vec<Option<Camera>>,
    /// Texels along each side of a map.
    pub size: u32,
    pub bias: f32,
}

impl ShadowViews {
    /// The views of `lights` over the snapped box `lo`..`hi` ([`shadow_box`]).
    fn of(lights: &[Light], lo: Vec3, hi: Vec3) -> ShadowViews {
        let radius = ((hi - lo) * 0.5).length().max(1e-3) * 1.05;
        let cameras = (lights.iter())
            .map(|light| {
                if lo.x > hi.x {
                    return None;
                }
                let centre = (lo + hi) * 0.5;
                let (eye, distance) = match light.kind {
                    LightKind::Point { position } => (position, (centre - position).length()),
                    LightKind::Directional { direction, .. } => {
                        let far = radius * 100.0;
                        (centre - direction.normalize_or(Vec3::NEG_Y) * far, far)
                    }
                };
                if distance <= radius * 1.05 {
                    // The light sits among the points: no frustum holds them.
                    return None;
                }
                let forward = (centre - eye).normalize();
                let up = if forward.y.abs() > 0.9 {
                    Vec3::X
                } else {
                    Vec3::Y
                };
                Some(Camera {
                    eye,
                    target: centre,
                    up,
                    fov_y_deg: 2.0 * (radius / distance).asin().to_degrees(),
                    width: SHADOW_MAP_SIZE,
                    height: SHADOW_MAP_SIZE,
                })
            })
            .collect();
        ShadowViews {
            cameras,
            size: SHADOW_MAP_SIZE,
            // 5 texels of a 1024 map across the box's bounding sphere.
            bias: radius * 5e-3 * (1024.0 / SHADOW_MAP_SIZE as f32),
        }
    }

    /// The views a frame from `camera` gets (the box of its opaque points
    /// behind the see-through reflectors): for a drawing of the scene that
    /// shadows what it shows through the glass as the thin-glass pass
    /// does. No camera at all without see-through reflector pixels.
    pub fn for_frame(
        scene: &Scene,
        camera: &Camera,
        lights: &[Light],
        is_reflector: &[bool],
    ) -> ShadowViews {
        // The frame's own buffer is read only over the reflectors' bounds.
        let within = reflector_bounds(scene, camera, is_reflector, BEHIND_MARGIN);
        let buffers = BehindBuffers::new(
            scene,
            camera,
            Some(within),
            is_reflector,
            Transmission::Raster,
        );
        let ids = buffers
            .frame
            .as_ref()
            .expect("asked for the frame's buffer");
        let glass_triangle = |t: TriangleId| is_reflector[t.index()] && see_through(scene, t);
        let (lo, hi) = shadow_box(
            camera,
            ids,
            &buffers.behind,
            buffers.bounds,
            &glass_triangle,
        );
        ShadowViews::of(lights, lo, hi)
    }
}

/// One shadow map per light: the scene's ID buffer seen from the light
/// through a frustum fitted to a box around the opaque points behind the
/// glass. The box is snapped outward to a grid (a power of two, a quarter
/// to a half of its size), so that the maps depend on the lights and the
/// snapped box alone: frames whose eyes differ a little share them
/// ([`ShadowCache`]), and every machine builds the same ones.
#[derive(Clone, Debug)]
struct ShadowMaps {
    maps: Vec<Option<ShadowMap>>,
    /// How much nearer than a point an occluder must be to shadow it: a
    /// few texels, so a surface does not shadow itself between texels.
    bias: f32,
}

/// One light's map: what its ID buffer holds per texel, triangle and depth
/// side by side (a look-up touches one cache line, not two).
#[derive(Clone, Debug)]
struct ShadowMap {
    projector: Projector,
    size: u32,
    texels: Vec<(u32, f32)>,
}

impl ShadowMap {
    fn new(projector: Projector, ids: &IdBuffer) -> ShadowMap {
        debug_assert_eq!(ids.width, ids.height);
        debug_assert_eq!(ids.window, PixelRect::full(ids.width, ids.height));
        ShadowMap {
            projector,
            size: ids.width,
            texels: ids
                .triangle
                .iter()
                .copied()
                .zip(ids.depth.iter().copied())
                .collect(),
        }
    }
}

/// Texels along each side of a shadow map: twice the 1024 that a box fitted
/// exactly needed, since snapping at most doubles the box.
const SHADOW_MAP_SIZE: u32 = 2048;

/// What a set of shadow maps is built from: the lights and the snapped box.
#[derive(Clone, Debug, PartialEq)]
struct ShadowKey {
    lights: Vec<Light>,
    lo: Vec3,
    hi: Vec3,
}

/// What a frame's ID buffers ([`BehindBuffers::new`]) depend on besides the
/// scene and its reflectors, which are the renderer's.
#[derive(Clone, Copy, Debug, PartialEq)]
struct IdBufferKey {
    camera: Camera,
    frame_within: PixelRect,
    transmission: Transmission,
}

/// The ID buffers of the last frame (the frame's own, the opaque scene
/// behind the reflectors, the slab backs), kept for the next: a renderer
/// holds one for its scene and reflectors. They are a function of the
/// camera, the rectangle and the transmission model alone — not of the
/// lights — so frames that differ only in the sun (a study's sweep)
/// rasterize them once, and whether they come from here or are made anew
/// never changes a pixel.
#[derive(Debug, Default)]
pub struct IdBufferCache {
    last: Mutex<Option<(IdBufferKey, BehindBuffers)>>,
    builds: AtomicU64,
}

impl IdBufferCache {
    /// How many sets of buffers were rasterized (a frame that reuses the
    /// last frame's rasterizes none).
    pub fn builds(&self) -> u64 {
        self.builds.load(Ordering::Relaxed)
    }

    /// Forgets the kept buffers (the next frame rasterizes its own).
    pub fn clear(&self) {
        *self.lock() = None;
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Option<(IdBufferKey, BehindBuffers)>> {
        (self.last.lock()).unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// The buffers for `key`, made with `build` unless the last frame's match.
    fn get(&self, key: IdBufferKey, build: impl FnOnce() -> BehindBuffers) -> BehindBuffers {
        if let Some((k, buffers)) = self.lock().as_ref()
            && *k == key
        {
            return buffers.clone();
        }
        self.builds.fetch_add(1, Ordering::Relaxed);
        let buffers = build();
        *self.lock() = Some((key, buffers.clone()));
        buffers
    }
}

/// The shadow maps of the last frame, kept for the next (a renderer holds
/// one per scene). The maps are a function of the key alone, so whether
/// they come from here or are built anew never changes a pixel.
#[derive(Debug, Default)]
pub struct ShadowCache {
    last: Mutex<Option<(ShadowKey, Arc<ShadowMaps>)>>,
    builds: AtomicU64,
}

impl ShadowCache {
    /// How many sets of maps were built (a frame that reuses the last
    /// frame's builds none).
    pub fn builds(&self) -> u64 {
        self.builds.load(Ordering::Relaxed)
    }

    /// The maps for `key`, built with `build` unless the last frame's match.
    fn get(&self, key: ShadowKey, build: impl FnOnce(&ShadowKey) -> ShadowMaps) -> Arc<ShadowMaps> {
        let mut last = self
            .last
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        if let Some((k, maps)) = last.as_ref()
            && *k == key
        {
            return maps.clone();
        }
        self.builds.fetch_add(1, Ordering::Relaxed);
        let maps = Arc::new(build(&key));
        *last = Some((key, maps.clone()));
        maps
    }
}

impl ShadowMaps {
    /// The maps for the opaque points behind the glass pixels of `bounds`,
    /// from `cache` when the last frame's fit.
    fn for_frame(
        tracer: &Tracer<'_>,
        camera: &Camera,
        ids: &IdBuffer,
        behind: &IdBuffer,
        bounds: PixelRect,
        glass_triangle: &dyn Fn(TriangleId) -> bool,
        cache: &ShadowCache,
    ) -> Arc<ShadowMaps> {
        let (lo, hi) = shadow_box(camera, ids, behind, bounds, glass_triangle);
        let key = ShadowKey {
            lights: tracer.lighting.lights.clone(),
            lo,
            hi,
        };
        cache.get(key, |key| ShadowMaps::new(tracer, key))
    }

    fn new(tracer: &Tracer<'_>, key: &ShadowKey) -> ShadowMaps {
        let scene = tracer.bvh.scene();
        let views = ShadowViews::of(&key.lights, key.lo, key.hi);
        let maps = (views.cameras.iter())
            .map(|view| {
                let view = view.as_ref()?;
                Some(ShadowMap::new(
                    Projector::new(view),
                    &vtfarm_raster::id_buffer_where(scene, view, &|t| tracer.bvh.casts_shadow(t)),
                ))
            })
            .collect();
        ShadowMaps {
            maps,
            bias: views.bias,
        }
    }

    /// Whether light `k` reaches `position` on `triangle`: the map shows
    /// that triangle there, or nothing clearly nearer than it. A light
    /// without a map lights every point (it sits among them).
    fn lit(&self, k: usize, position: Vec3, triangle: TriangleId) -> bool {
        let Some(Some(map)) = self.maps.get(k) else {
            return true;
        };
        let Some(s) = map.projector.project(position) else {
            return true;
        };
        let (x, y) = (floor(s.x), floor(s.y));
        let size = i64::from(map.size);
        if x < 0 || y < 0 || x >= size || y >= size {
            return true;
        }
        let (seen, depth) = map.texels[(y * size + x) as usize];
        seen == triangle.raw() || depth >= s.depth - self.bias
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_is_the_c_librarys_floor_for_every_kind_of_f32() {
        let mut values = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.5,
            -1.5,
            f32::EPSILON,
            -f32::EPSILON,
            f32::MIN_POSITIVE,
            -f32::MIN_POSITIVE,
            8_388_607.5,
            -8_388_607.5,
            16_777_217.0,
            9.3e18,
            -9.3e18,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        // And a sweep across pixel coordinates, around and past a shadow map.
        values.extend((-5000..5000).map(|i| i as f32 * 0.37));
        for v in values {
            assert_eq!(floor(v), v.floor() as i64, "{v}");
        }
    }

    #[test]
    fn normalize_or_else_is_normalize_or() {
        let fallback = Vec3::new(0.0, 0.0, 1.0);
        for v in [
            Vec3::new(3.0, -4.0, 12.0),
            Vec3::new(1e-30, 0.0, 0.0),
            Vec3::new(1e-20, 1e-20, 0.0),
            Vec3::ZERO,
            Vec3::new(f32::INFINITY, 0.0, 0.0),
            Vec3::new(f32::NAN, 1.0, 0.0),
            Vec3::new(0.1, 0.2, 0.3),
        ] {
            let (a, b) = (normalize_or_else(v, || fallback), v.normalize_or(fallback));
            assert_eq!(
                a.to_array().map(f32::to_bits),
                b.to_array().map(f32::to_bits),
                "{v}"
            );
        }
    }
}
