//! One frame end to end on one machine: the base frame and ID buffer from the
//! rasterizer, the reflector triangles cut into packages and vertex traced,
//! the bitmaps composited over the base frame; plus the error figures against
//! a reference and the auxiliary output files; and the catalogue of
//! reflection methods ([`method`]).
//!
//! Architecture invariant: no networking and no scheduling policy here; the
//! farm's master drives the same pieces (`Renderer::frame`, `trace_package`,
//! `FrameImage::composite`) package by package.

pub mod output;

pub use vtfarm_method::FrameSetup;

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use glam::Vec3;
use vtfarm_imaging::{Image, encode_srgb8};
use vtfarm_method::{MethodKind, ReflectionMethod, VertexTracing};
use vtfarm_raster::IdBuffer;
use vtfarm_scene::{Camera, ObjectId, Scene, TriangleId};
use vtfarm_trace::{InvalidScene, SceneBvh, Tracer};
use vtfarm_vertex::{
    Behind, FinishedFace, Frame, FrameImage, GlassPass, IdBufferCache, PackageOptions,
    PackageStats, PhaseTimes, PixelRect, PixelValue, ProgressivePackage, Quality, ShadowCache,
    SparseBitmap, StageError, StageMesh, VertexOwners, VertexSettings, reflector_bounds,
    trace_package_into,
};

/// How to cut and run the reflector work.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RenderOptions {
    /// Reflector triangles per package.
    pub package_size: usize,
    /// Keep the final refined faces (for the wireframe overlay).
    pub collect_faces: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            package_size: 256,
            collect_faces: false,
        }
    }
}

/// A rendered frame with its counters.
#[derive(Clone, Debug)]
pub struct RenderedFrame {
    pub image: FrameImage,
    pub stats: PackageStats,
    /// Wall time of the rasterizer pass.
    pub raster_time: Duration,
    /// Wall time of the whole frame.
    pub total_time: Duration,
    /// Where the time after the raster pass went.
    pub times: FrameTimes,
    pub faces: Vec<FinishedFace>,
}

/// The wall times of a frame after its raster pass (the packages run one
/// after the other, so their phase times add up to wall time).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameTimes {
    /// Setting up the frame's planes over the base frame ([`FrameImage::new`]).
    pub image_setup: Duration,
    /// The packages' phases.
    pub phases: PhaseTimes,
}

/// The rectangle a frame's component planes cover: the reflectors' screen
/// bounds, no margin (the master's and a worker's finished frames alike).
pub fn components_bounds(scene: &Scene, camera: &Camera, is_reflector: &[bool]) -> PixelRect {
    reflector_bounds(scene, camera, is_reflector, 0)
}

/// For each scene triangle, whether it is one of `reflectors` (ids past the
/// scene's triangles are left out).
pub fn reflector_flags(scene: &Scene, reflectors: &[TriangleId]) -> Vec<bool> {
    let mut is_reflector = vec![false; scene.triangles.len()];
    for &t in reflectors {
        if let Some(flag) = is_reflector.get_mut(t.index()) {
            *flag = true;
        }
    }
    is_reflector
}

/// The base frame of `setup` into `image` and `ids`, whatever they hold
/// (`vtfarm_raster::rasterize_into`), with the see-through surfaces that are
/// no reflector blended over the opaque scene behind them
/// (`vtfarm_raster::blend_see_through`): every machine's base frame, so
/// that a frame is the same wherever it is made. Returns the objects of
/// that glass; `warned` is set the first time there are some, when the one
/// warning naming them ([`see_through_warning`]) is logged.
pub fn base_frame_into(
    scene: &Scene,
    setup: &FrameSetup,
    is_reflector: &[bool],
    extent: BaseExtent,
    (image, ids): (&mut Image, &mut IdBuffer),
    warned: &AtomicBool,
) -> Vec<ObjectId> {
    let (camera, lighting) = (&setup.camera, &setup.lighting);
    match extent {
        BaseExtent::Whole => vtfarm_raster::rasterize_into(scene, camera, lighting, image, ids),
        BaseExtent::Packages => {
            let within = package_bounds(scene, setup, is_reflector);
            vtfarm_raster::rasterize_within_into(scene, camera, lighting, within, image, ids);
        }
    }
    let glass = vtfarm_raster::blend_see_through(scene, camera, lighting, ids, image, is_reflector);
    if !glass.is_empty() && !warned.swap(true, Ordering::Relaxed) {
        tracing::warn!("{}", see_through_warning(scene, &glass));
    }
    glass
}

/// How much of a frame a base frame covers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BaseExtent {
    /// Every pixel.
    #[default]
    Whole,
    /// The pixels the packages look at ([`package_bounds`]), each exactly
    /// as in the whole frame; the rest empty and the background. For a
    /// frame whose viewer draws the scene itself and takes only the
    /// reflectors' pixels from the farm.
    Packages,
}

/// The pixels a frame's packages look at: the reflectors' bounds with the
/// vertex tracer's visibility margin (`vtfarm_vertex::reflector_bounds`).
pub fn package_bounds(scene: &Scene, setup: &FrameSetup, is_reflector: &[bool]) -> PixelRect {
    let margin = setup.vertex.visibility_radius + 1;
    reflector_bounds(scene, &setup.camera, is_reflector, margin)
}

/// The warning for see-through glass that is no reflector (`objects`): it
/// is drawn see-through, and shows no reflection.
pub fn see_through_warning(scene: &Scene, objects: &[ObjectId]) -> String {
    let names: Vec<&str> = (objects.iter())
        .map(|&o| scene.objects[o.index()].name.as_str())
        .collect();
    format!(
        "see-through glass that is no reflector ({}) is drawn see-through, without its \
         reflection: list it under [reflectors] to trace it",
        names.join(", ")
    )
}

/// A scene ready to render: its BVH and the reflector triangles.
pub struct Renderer {
    bvh: SceneBvh,
    owners: VertexOwners,
    reflectors: Vec<TriangleId>,
    is_reflector: Vec<bool>,
    /// The last frame's shadow maps of the thin-glass pass.
    shadows: ShadowCache,
    /// A worker's frame set-up's ID buffers, kept for the next frame of the
    /// same camera (they do not depend on the lights).
    id_buffers: IdBufferCache,
    /// Frames set up so far ([`Renderer::set_ups`]).
    set_ups: AtomicU64,
    /// Whole frames' buffers, kept for the next ([`Renderer::finish_frame`]).
    whole_frames: Mutex<Vec<WholeFrameBuffers>>,
    /// Whether glass that is no reflector was warned about ([`base_frame_into`]).
    warned_glass: AtomicBool,
}

/// A whole frame's large buffers, kept from frame to frame: buffers in
/// fresh memory pay a page fault per 4 KiB on their first write, 33 MB of
/// them at 1080p (the base image, its ID buffer, the encoded bytes), which
/// cost a one-thread worker up to a tenth of its frame, and more where
/// other processes share its core (docs/benchmarks.md, page faults).
struct WholeFrameBuffers {
    image: Image,
    ids: IdBuffer,
    scratch: Vec<u8>,
}

/// The most whole frames' buffers kept: a worker finishes at most two whole
/// frames at once (the scheduler's `WHOLE_FRAMES_PER_WORKER`).
const KEPT_WHOLE_FRAMES: usize = 2;

impl Renderer {
    /// Prepares a scene; the reflectors are kept in spatial (Morton) order so
    /// that consecutive runs make compact packages with short boundaries.
    ///
    /// # Panics
    /// On a scene that breaks [`Scene::validate`]; scenes from outside go
    /// through [`Renderer::try_new`].
    pub fn new(scene: Arc<Scene>, reflectors: Vec<TriangleId>) -> Self {
        Renderer::try_new(scene, reflectors).unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`Renderer::new`], or why the scene cannot be rendered (it breaks
    /// [`Scene::validate`], or a reflector id names no triangle).
    pub fn try_new(scene: Arc<Scene>, reflectors: Vec<TriangleId>) -> Result<Self, InvalidScene> {
        if let Some(&t) = reflectors
            .iter()
            .find(|&&t| t.index() >= scene.triangles.len())
        {
            return Err(InvalidScene(format!(
                "reflector {t} names no triangle (the scene has {})",
                scene.triangles.len()
            )));
        }
        let bvh = SceneBvh::try_new(scene)?;
        let scene = bvh.scene();
        let reflectors = morton_order(scene, reflectors);
        let owners = VertexOwners::new(scene);
        let is_reflector = reflector_flags(scene, &reflectors);
        Ok(Renderer {
            bvh,
            owners,
            reflectors,
            is_reflector,
            shadows: ShadowCache::default(),
            id_buffers: IdBufferCache::default(),
            set_ups: AtomicU64::new(0),
            whole_frames: Mutex::new(Vec::new()),
            warned_glass: AtomicBool::new(false),
        })
    }

    /// How many frames this renderer has set up: a whole frame's raster
    /// pass (base frame, ID buffer, the thin-glass pass) for
    /// [`Renderer::render`] or [`Renderer::progressive`], or a worker's
    /// ([`Renderer::id_buffers`]). A progressive frame counts one for all
    /// its stages.
    pub fn set_ups(&self) -> u64 {
        self.set_ups.load(Ordering::Relaxed)
    }

    /// A whole frame's raster pass: the base frame, its ID buffer and what
    /// lies behind the reflectors, with the thin-glass terms up front.
    fn set_up(&self, setup: &FrameSetup) -> (Image, IdBuffer, Behind) {
        self.set_ups.fetch_add(1, Ordering::Relaxed);
        let (base, ids) = self.base_frame(setup);
        let behind = self.behind(setup, &ids);
        (base, ids, behind)
    }

    pub fn scene(&self) -> &Scene {
        self.bvh.scene()
    }

    pub fn bvh(&self) -> &SceneBvh {
        &self.bvh
    }

    pub fn reflectors(&self) -> &[TriangleId] {
        &self.reflectors
    }

    /// The thin-glass pass's shadow maps, kept from frame to frame.
    pub fn shadow_cache(&self) -> &ShadowCache {
        &self.shadows
    }

    /// A worker's ID buffers ([`Renderer::id_buffers`]), kept from frame to
    /// frame: frames of one camera rasterize them once.
    pub fn id_buffer_cache(&self) -> &IdBufferCache {
        &self.id_buffers
    }

    /// The rasterized base frame and ID buffer, glass that is no reflector
    /// blended over what lies behind it ([`base_frame_into`]).
    pub fn base_frame(&self, setup: &FrameSetup) -> (Image, IdBuffer) {
        let mut image = Image::new(0, 0, setup.lighting.background);
        let mut ids = IdBuffer::new(0, 0);
        self.base_frame_in(setup, (&mut image, &mut ids));
        (image, ids)
    }

    /// [`base_frame_into`] this renderer's scene and reflectors.
    fn base_frame_in(&self, setup: &FrameSetup, buffers: (&mut Image, &mut IdBuffer)) {
        let warned = &self.warned_glass;
        let extent = BaseExtent::Whole;
        base_frame_into(
            self.scene(),
            setup,
            &self.is_reflector,
            extent,
            buffers,
            warned,
        );
    }

    /// A frame to composite into over `base`, its component planes over the
    /// reflectors' bounds ([`FrameImage::new`]).
    pub fn frame_image(&self, setup: &FrameSetup, base: Image) -> FrameImage {
        let bounds = components_bounds(self.scene(), &setup.camera, &self.is_reflector);
        FrameImage::new(base, bounds)
    }

    /// A whole frame finished where it was traced (a farm worker's whole
    /// frame): the base frame, and the frame's `bitmap` (all its reflector
    /// pixels) composited over it ([`FrameImage::composite`]) — what the
    /// master makes of a split frame's results, bit for bit — handed to
    /// `encode` with a scratch buffer for its bytes. The buffers are kept
    /// for the next whole frame.
    pub fn finish_frame<R>(
        &self,
        setup: &FrameSetup,
        bitmap: &SparseBitmap,
        encode: impl FnOnce(&FrameImage, &mut Vec<u8>) -> R,
    ) -> R {
        let kept = self.lock_whole_frames().pop();
        let WholeFrameBuffers {
            mut image,
            mut ids,
            mut scratch,
        } = kept.unwrap_or_else(|| WholeFrameBuffers {
            image: Image::new(0, 0, Vec3::ZERO),
            ids: IdBuffer::new(0, 0),
            scratch: Vec::new(),
        });
        self.base_frame_in(setup, (&mut image, &mut ids));
        let mut frame = self.frame_image(setup, image);
        frame.composite(bitmap);
        let encoded = encode(&frame, &mut scratch);
        let buffers = WholeFrameBuffers {
            image: frame.color,
            ids,
            scratch,
        };
        let mut kept = self.lock_whole_frames();
        if kept.len() < KEPT_WHOLE_FRAMES {
            kept.push(buffers);
        }
        encoded
    }

    fn lock_whole_frames(&self) -> MutexGuard<'_, Vec<WholeFrameBuffers>> {
        (self.whole_frames.lock()).unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Only the raster results a worker needs (no base frame): the frame's
    /// ID buffer and what lies behind the reflectors, both over the
    /// reflectors' bounds only (`vtfarm_vertex::reflector_bounds`; empty
    /// elsewhere, where no package looks), rasterized together. The thin-glass terms are left to
    /// the pixels the worker's packages finish (`GlassPass::OnDemand`), so
    /// two workers split that pass instead of each doing all of it.
    pub fn id_buffers(&self, setup: &FrameSetup) -> (IdBuffer, Behind) {
        self.set_ups.fetch_add(1, Ordering::Relaxed);
        let bounds = package_bounds(self.scene(), setup, &self.is_reflector);
        Behind::with_frame_ids(
            &self.tracer(setup),
            &setup.camera,
            bounds,
            &self.is_reflector,
            setup.vertex.transmission,
            GlassPass::OnDemand,
            &self.shadows,
            &self.id_buffers,
        )
    }

    /// What lies behind the reflectors of a frame whose ID buffer is `ids`
    /// (see `vtfarm_vertex::Behind`), with the thin-glass terms of every
    /// glass pixel: the raster pass of a whole frame.
    pub fn behind(&self, setup: &FrameSetup, ids: &IdBuffer) -> Behind {
        Behind::new(
            &self.tracer(setup),
            &setup.camera,
            ids,
            &self.is_reflector,
            setup.vertex.transmission,
            GlassPass::Upfront,
            &self.shadows,
        )
    }

    /// Every reflector triangle's `preview` mesh for `setup`'s eye, with
    /// no set-up of the frame ([`vtfarm_vertex::corner_meshes`]): what the
    /// interactive view draws first, while the frame is being set up.
    pub fn corner_meshes(&self, setup: &FrameSetup) -> Vec<StageMesh> {
        let tracer = self.tracer(setup);
        vtfarm_vertex::corner_meshes(
            tracer,
            &setup.camera,
            &setup.vertex,
            &self.owners,
            &self.reflectors,
        )
    }

    fn tracer<'a>(&'a self, setup: &'a FrameSetup) -> Tracer<'a> {
        Tracer {
            bvh: &self.bvh,
            lighting: &setup.lighting,
            settings: setup.trace,
            cone: vtfarm_trace::PixelCone::of(&setup.camera),
        }
    }

    /// The vertex tracer's view of a frame.
    pub fn frame<'a>(
        &'a self,
        setup: &'a FrameSetup,
        ids: &'a IdBuffer,
        behind: &'a Behind,
    ) -> Frame<'a> {
        Frame {
            tracer: self.tracer(setup),
            camera: setup.camera,
            ids,
            behind,
            owners: &self.owners,
            settings: setup.vertex,
            stop: None,
        }
    }

    /// Renders a frame with the given packages (each a set of reflector
    /// triangles); `progress` hears (triangles done, triangles in all).
    pub fn render_packages(
        &self,
        setup: &FrameSetup,
        packages: &[Vec<TriangleId>],
        options: &RenderOptions,
        progress: &mut dyn FnMut(u64, u64),
    ) -> RenderedFrame {
        let start = Instant::now();
        let (base, ids, behind) = self.set_up(setup);
        let raster_time = start.elapsed();
        let frame = self.frame(setup, &ids, &behind);
        let setup_start = Instant::now();
        let mut image = self.frame_image(setup, base);
        let mut times = FrameTimes {
            image_setup: setup_start.elapsed(),
            ..FrameTimes::default()
        };
        let mut stats = PackageStats::default();
        let mut faces = Vec::new();
        let total: u64 = packages.iter().map(|p| p.len() as u64).sum();
        let mut done = 0;
        let package_options = PackageOptions {
            collect_faces: options.collect_faces,
            time_break: None,
        };
        for package in packages {
            let traced =
                trace_package_into(&frame, package, &package_options, &mut |_| {}, &mut image);
            stats.add(&traced.stats);
            times.phases.add(&traced.times);
            faces.extend(traced.faces);
            done += package.len() as u64;
            progress(done, total);
        }
        RenderedFrame {
            image,
            stats,
            raster_time,
            total_time: start.elapsed(),
            times,
            faces,
        }
    }

    /// Renders a frame with the reflectors cut into packages of
    /// `options.package_size` triangles.
    pub fn render(
        &self,
        setup: &FrameSetup,
        options: &RenderOptions,
        progress: &mut dyn FnMut(u64, u64),
    ) -> RenderedFrame {
        let packages = split_packages(&self.reflectors, options.package_size);
        self.render_packages(setup, &packages, options, progress)
    }

    /// Sets a frame up once (the raster pass, the frame's planes, the
    /// packages' set-ups) for [`ProgressiveFrame::advance`] to take it
    /// through the stages on the same vertices (`setup.vertex.quality` is
    /// not used).
    pub fn progressive(&self, setup: &FrameSetup, options: &RenderOptions) -> ProgressiveFrame<'_> {
        let start = Instant::now();
        let (base, ids, behind) = self.set_up(setup);
        let image = self.frame_image(setup, base);
        let packages = {
            let frame = self.frame(setup, &ids, &behind);
            split_packages(&self.reflectors, options.package_size)
                .iter()
                .map(|package| ProgressivePackage::new(&frame, package))
                .collect()
        };
        ProgressiveFrame {
            renderer: self,
            setup: setup.clone(),
            ids,
            behind,
            image,
            packages,
            collect_faces: options.collect_faces,
            set_up_time: start.elapsed(),
        }
    }
}

/// A frame rendered stage by stage on one set-up ([`Renderer::progressive`]):
/// each [`ProgressiveFrame::advance`] continues every package's vertices
/// and edges (no vertex traced twice) and rewrites the reflector pixels, so
/// after each stage [`ProgressiveFrame::image`] is exactly the frame
/// [`Renderer::render`] gives at that quality.
pub struct ProgressiveFrame<'r> {
    renderer: &'r Renderer,
    setup: FrameSetup,
    ids: IdBuffer,
    behind: Behind,
    image: FrameImage,
    packages: Vec<ProgressivePackage>,
    collect_faces: bool,
    set_up_time: Duration,
}

/// What one stage of a [`ProgressiveFrame`] did.
#[derive(Clone, Debug)]
pub struct RenderedStage {
    pub quality: Quality,
    /// This stage's work (samples traced in it, splits made in it).
    pub stats: PackageStats,
    pub times: PhaseTimes,
    /// Wall time of the stage.
    pub time: Duration,
    /// The final faces after the stage, when the options asked for them.
    pub faces: Vec<FinishedFace>,
}

impl ProgressiveFrame<'_> {
    /// Runs stage `quality` (later than the last; see
    /// `vtfarm_vertex::ProgressivePackage`) over every package, into the
    /// frame's image.
    pub fn advance(&mut self, quality: Quality) -> Result<RenderedStage, StageError> {
        let start = Instant::now();
        let frame = self.renderer.frame(&self.setup, &self.ids, &self.behind);
        let options = PackageOptions {
            collect_faces: self.collect_faces,
            time_break: None,
        };
        let mut stats = PackageStats::default();
        let mut times = PhaseTimes::default();
        let mut faces = Vec::new();
        for package in &mut self.packages {
            let traced =
                package.advance_into(&frame, quality, &options, &mut |_| {}, &mut self.image)?;
            stats.add(&traced.stats);
            times.add(&traced.times);
            faces.extend(traced.faces);
        }
        Ok(RenderedStage {
            quality,
            stats,
            times,
            time: start.elapsed(),
            faces,
        })
    }

    /// The frame as the last stage left it (the base frame before the first).
    pub fn image(&self) -> &FrameImage {
        &self.image
    }

    /// Wall time of the set-up (raster pass, planes, packages).
    pub fn set_up_time(&self) -> Duration {
        self.set_up_time
    }
}

/// Sorts triangles by the Morton code of their centroids (ties by id), so
/// that triangles close in the list are close in space.
pub fn morton_order(scene: &Scene, mut triangles: Vec<TriangleId>) -> Vec<TriangleId> {
    let centroid = |t: TriangleId| {
        let [a, b, c] = scene.triangle_positions(t);
        (a + b + c) / 3.0
    };
    let (lo, hi) = triangles.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &t| (lo.min(centroid(t)), hi.max(centroid(t))),
    );
    let scale = (hi - lo).max(Vec3::splat(f32::MIN_POSITIVE));
    let code = |t: TriangleId| {
        let q = ((centroid(t) - lo) / scale * 1023.0).clamp(Vec3::ZERO, Vec3::splat(1023.0));
        spread_bits(q.x as u32) | (spread_bits(q.y as u32) << 1) | (spread_bits(q.z as u32) << 2)
    };
    triangles.sort_by_key(|&t| (code(t), t));
    triangles
}

/// Spreads the low 10 bits of `v` so that two zero bits follow each one.
fn spread_bits(v: u32) -> u32 {
    let mut x = v & 0x3ff;
    x = (x | (x << 16)) & 0x0300_00ff;
    x = (x | (x << 8)) & 0x0300_f00f;
    x = (x | (x << 4)) & 0x030c_30c3;
    (x | (x << 2)) & 0x0924_9249
}

/// Cuts triangles into consecutive packages of at most `size`.
pub fn split_packages(triangles: &[TriangleId], size: usize) -> Vec<Vec<TriangleId>> {
    triangles
        .chunks(size.max(1))
        .map(<[TriangleId]>::to_vec)
        .collect()
}

/// The per-pixel reference with its traced transmitted part replaced by the
/// thin-glass model's (rasterized transmission, the back surface's
/// reflection added to the front's): what `transmission = "raster"` would
/// give with every reflector pixel traced, i.e. the model's own error.
/// `frame` is the reference's frame with raster transmission. Each glass
/// pixel is traced again without its refraction ray
/// ([`Tracer::shade_reflection`]: local plus the front's reflection, which
/// the reference's own reflected part no longer tells apart from the back
/// surface's) and finished by the model.
pub fn thin_glass_model(reference: &FrameImage, frame: &Frame<'_>) -> FrameImage {
    use rayon::prelude::*;
    let mut modelled = reference.clone();
    let width = modelled.color.width as usize;
    let scene = frame.tracer.bvh.scene();
    let glass: Vec<usize> = reference.glass().collect();
    let values: Vec<PixelValue> = glass
        .par_iter()
        .map(|&i| {
            let (x, y) = ((i % width) as u32, (i / width) as u32);
            let triangle = TriangleId(frame.ids.triangle_at(x, y));
            let (point, direction) =
                vtfarm_vertex::pixel_surface(scene, &frame.camera, frame.ids, triangle, x, y);
            let sample = frame.tracer.shade_reflection(&point, direction);
            let mut value = PixelValue::from_sample(i as u32, &sample);
            frame.finish_pixel((x, y), &mut value);
            value
        })
        .collect();
    for value in &values {
        modelled.set_pixel(value);
    }
    modelled
}

/// How far an image is from a reference over the reference's reflector
/// pixels, in 8-bit sRGB steps.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ErrorFigures {
    /// Reflector pixels compared.
    pub pixels: u64,
    /// Mean absolute difference per channel (0..255).
    pub mean_abs: f64,
    /// Share of pixels with some channel off by more than 8/255.
    pub share_off: f64,
    /// Largest channel difference seen (0..255).
    pub max_abs: u8,
}

/// Compares `test` with `reference` on the reference's reflector pixels.
pub fn compare(test: &FrameImage, reference: &FrameImage) -> ErrorFigures {
    let mut pixels = 0u64;
    let mut sum = 0u64;
    let mut off = 0u64;
    let mut max_abs = 0u8;
    for i in reference.glass() {
        let a = encode_srgb8(test.color.pixels[i]);
        let b = encode_srgb8(reference.color.pixels[i]);
        let d = [0, 1, 2].map(|k| a[k].abs_diff(b[k]));
        pixels += 1;
        sum += d.iter().map(|&x| x as u64).sum::<u64>();
        let worst = d.into_iter().max().unwrap_or(0);
        max_abs = max_abs.max(worst);
        off += (worst > 8) as u64;
    }
    let n = pixels.max(1) as f64;
    ErrorFigures {
        pixels,
        mean_abs: sum as f64 / (3.0 * n),
        share_off: off as f64 / n,
        max_abs,
    }
}

/// The method catalogue: the method a job chose, with the job's vertex
/// settings (used by vertex tracing) and each other method's defaults. The
/// farm's workers and `vtfarm compare` build their methods here.
pub fn method(kind: MethodKind, vertex: VertexSettings) -> Box<dyn ReflectionMethod> {
    match kind {
        MethodKind::VertexTracing => Box::new(VertexTracing { settings: vertex }),
        MethodKind::CubeMap => Box::new(vtfarm_cubemap::CubeMapMethod::full()),
        MethodKind::CubeMapGrid => Box::new(vtfarm_cubemap::CubeMapMethod::grid()),
        MethodKind::Pvrr => Box::new(vtfarm_pvrr::Pvrr::default()),
        MethodKind::EnvironmentMap => Box::new(vtfarm_cubemap::EnvironmentMap::default()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use vtfarm_scene::MaterialId;

    #[test]
    fn spread_bits_interleaves() {
        assert_eq!(spread_bits(0b1), 0b1);
        assert_eq!(spread_bits(0b11), 0b1001);
        assert_eq!(spread_bits(0x3ff), 0x0924_9249);
    }

    #[test]
    fn morton_order_keeps_neighbours_together() {
        // Four far-apart clusters of two triangles each, listed interleaved.
        let mut scene = Scene::default();
        scene
            .objects
            .push(vtfarm_scene::Object { name: "o".into() });
        scene.materials.push(vtfarm_scene::Material::default());
        let corners = [
            Vec3::ZERO,
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(0.0, 10.0, 0.0),
            Vec3::new(10.0, 10.0, 10.0),
        ];
        for k in 0..8 {
            let base = corners[k % 4] + Vec3::splat(0.01 * (k / 4) as f32);
            let i = scene.positions.len() as u32;
            scene
                .positions
                .extend([base, base + Vec3::X * 0.1, base + Vec3::Y * 0.1]);
            scene.normals.extend([Vec3::Z; 3]);
            scene.triangles.push(vtfarm_scene::Triangle {
                vertices: [i, i + 1, i + 2],
                object: vtfarm_scene::ObjectId(0),
                material: MaterialId(0),
            });
        }
        let order = morton_order(&scene, TriangleId::range(8).collect());
        for pair in order.chunks(2) {
            assert_eq!(pair[0].raw() % 4, pair[1].raw() % 4, "{order:?}");
        }
    }
}
