//! The worker's computing side, without I/O on the network: the scene cache
//! (in memory and on disk, by content hash), the renderer of the current
//! scene, the current frame's ID buffers, and running packages.
//!
//! What takes long (decoding a scene, reading and writing the disk cache,
//! building a renderer's BVH, the ID buffers) needs no `&mut Engine`:
//! [`SceneCache`], [`FrameParts::build`], so the driver runs it on blocking
//! threads and its heartbeats never wait behind it. The disk cache writes
//! through no symlink: a scene goes to a fresh temporary file (`O_EXCL`,
//! `O_NOFOLLOW`) renamed over the name, and reads refuse a symlink.

use std::collections::BTreeMap;
use std::io::Write;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use tracing::{debug, info, warn};
use vtfarm_method::{MethodFrame, MethodKind, ReflectionMethod, merge_bitmaps, reflector_groups};
use vtfarm_proto::{
    FrameKey, FrameStart, JobId, MAX_CORNER_MESH_TRIANGLES, Package, PackageResult, ResultPixels,
    SceneData, SceneHash, WireBitmap, WireBitmapParts, WireError, WireFrameAux, WireImage,
    WireImageFormat, WireMesh, WirePackageStats, check_stages, check_triangle_ids,
};
use vtfarm_raster::IdBuffer;
use vtfarm_render::{FrameSetup, Renderer};
use vtfarm_scene::{Scene, TriangleId};
use vtfarm_vertex::{
    Behind, Frame, PackageOptions, PackageStats, ProgressivePackage, Quality, SparseBitmap,
    StageError, Stop, trace_package,
};

/// The frames a worker keeps prepared: the newest and the ones before it
/// whose packages the master may still hand out while frames are pipelined
/// ([`vtfarm_proto::FRAMES_IN_FLIGHT`], see `session`).
#[derive(Default)]
pub struct PreparedFrames(Vec<Arc<ActiveFrame>>);

impl PreparedFrames {
    /// Keeps `frame` (until [`PreparedFrames::retain`] lets it go).
    pub fn insert(&mut self, frame: ActiveFrame) {
        self.0.push(Arc::new(frame));
    }

    /// Lets go of the frames `keep` refuses: the driver passes the
    /// session's [`crate::WorkerSession::keeps_set_up`], so the frames kept
    /// are the session's, bounded as it bounds them.
    pub fn retain(&mut self, keep: impl Fn(FrameKey) -> bool) {
        self.0.retain(|a| keep((a.job, a.frame)));
    }

    /// The prepared frame `frame` of `job`, if kept.
    pub fn get(&self, job: JobId, frame: u32) -> Option<Arc<ActiveFrame>> {
        (self.0.iter())
            .find(|a| (a.job, a.frame) == (job, frame))
            .cloned()
    }
}

/// A panic inside a scene's or a package's work, with its message.
#[derive(Debug, thiserror::Error)]
#[error("panicked: {0}")]
pub struct Panicked(pub String);

/// Why a frame could not be set up (the session fails its packages so).
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error("frame for a scene this worker does not have")]
    UnknownScene,
    #[error("frame reflectors: {0}")]
    Reflectors(WireError),
    #[error("frame set-up: {0}")]
    Setup(WireError),
    #[error("{0}")]
    Stages(WireError),
    #[error("the scene cannot be traced: {0}")]
    Renderer(String),
    #[error(transparent)]
    Panicked(#[from] Panicked),
    /// The blocking task that set the frame up did not finish.
    #[error("frame set-up failed: {0}")]
    Task(#[source] tokio::task::JoinError),
}

/// Why a package failed (its text goes to the master in `PackageFailed`).
#[derive(Debug, thiserror::Error)]
pub enum PackageError {
    #[error("package triangles: {0}")]
    Triangles(WireError),
    #[error("package item {item} names no reflector (the frame has {groups})")]
    NoSuchGroup { item: u32, groups: usize },
    #[error("package {id} {why}")]
    Stopped { id: u64, why: String },
    #[error("the package's frame is not prepared")]
    FrameNotPrepared,
    #[error("stage {stage} of a frame of {stages} stages")]
    NoSuchStage { stage: usize, stages: usize },
    /// A later stage of a progressive package whose earlier stages did not
    /// run here (the driver keeps a package's progress between stages).
    #[error("stage {stage} of package {id} without its earlier stages")]
    StageWithoutProgress { id: u64, stage: usize },
    #[error("a whole frame of {0} stages (a progressive frame is split)")]
    WholeProgressiveFrame(usize),
    #[error("package stage: {0}")]
    Stage(StageError),
    #[error(transparent)]
    Panicked(#[from] Panicked),
    /// The blocking task that ran the package did not finish.
    #[error("package task failed: {0}")]
    Task(#[source] tokio::task::JoinError),
}

/// Why a scene from the master was refused.
#[derive(Debug, thiserror::Error)]
#[error("bad scene from the master: {0}")]
pub struct SceneError(pub WireError);

/// A frame ready for packages: its renderer, set-up and ID buffers.
pub struct ActiveFrame {
    pub job: JobId,
    pub frame: u32,
    /// The scene and reflectors the renderer was built for (its cache key).
    renderer_key: (SceneHash, Vec<TriangleId>),
    renderer: Arc<Renderer>,
    setup: FrameSetup,
    ids: IdBuffer,
    behind: Behind,
    /// The frame's method when it is not vertex tracing.
    per_reflector: Option<PerReflector>,
    /// What the results carry (the components only when the job wants them).
    parts: WireBitmapParts,
    /// How a whole frame's finished image travels.
    image: WireImageFormat,
    /// A progressive frame's stages, in order (empty: one stage, at the
    /// set-up's quality).
    stages: Vec<Quality>,
}

/// A per-reflector method with the reflector groups its package items index.
struct PerReflector {
    method: Box<dyn ReflectionMethod>,
    groups: Vec<Vec<TriangleId>>,
}

impl ActiveFrame {
    /// Traces a package of this frame. `slowdown` > 1 stretches the time the
    /// package takes (sleeping `slowdown - 1` times the compute time), to
    /// emulate a slower machine in tests and benchmarks.
    ///
    /// `stop` cancels the package from another thread, and fails it when it
    /// traces more samples than its budget. A panic inside the package
    /// becomes its error: it never takes the worker down.
    pub fn run(
        &self,
        package: &Package,
        slowdown: f64,
        stop: &Stop,
    ) -> Result<PackageResult, PackageError> {
        self.run_stage(package, 0, &mut None, slowdown, stop)
    }

    /// How many stages each package of this frame runs (1 unless the frame
    /// is progressive).
    pub fn stages(&self) -> usize {
        self.stages.len().max(1)
    }

    /// Runs stage `stage` (an index into the frame's stages; 0 for a frame
    /// of one stage) of `package`, as [`ActiveFrame::run`] does a whole
    /// package. `progress` is the package's state between stages: `None`
    /// before its first, where it is set up (once) and kept for the next;
    /// each later stage continues its vertices and edges, and its result
    /// holds the pixels that changed.
    pub fn run_stage(
        &self,
        package: &Package,
        stage: usize,
        progress: &mut Option<ProgressivePackage>,
        slowdown: f64,
        stop: &Stop,
    ) -> Result<PackageResult, PackageError> {
        let start = Instant::now();
        let frame = Frame {
            stop: Some(stop),
            ..self.renderer.frame(&self.setup, &self.ids, &self.behind)
        };
        let stages = self.stages();
        if stage >= stages {
            return Err(PackageError::NoSuchStage { stage, stages });
        }
        if package.whole.is_some() && stages > 1 {
            return Err(PackageError::WholeProgressiveFrame(stages));
        }
        let quality = self.stages.get(stage).copied();
        let mut mesh = None;
        let (bitmap, stats, samples) = contain_panic(|| match (&self.per_reflector, quality) {
            (Some(per_reflector), _) => per_reflector.render(&frame, &package.triangles),
            (None, None) => trace(&frame, &package.triangles),
            (None, Some(quality)) => {
                // Every stage but the last is drawn from its meshes alone.
                let meshes_only = stage + 1 < stages;
                let traced = advance(&frame, package, stage, quality, meshes_only, progress);
                if meshes_only {
                    mesh = progress
                        .as_ref()
                        .map(|p| WireMesh::from(&p.meshes(&frame)[..]));
                }
                traced
            }
        })??;
        if let Some(why) = stop.stopped() {
            let (id, why) = (package.id, why.to_string());
            return Err(PackageError::Stopped { id, why });
        }
        let pixels = if package.whole.is_some() {
            contain_panic(|| self.finish(&bitmap))?
        } else {
            ResultPixels::Bitmap(WireBitmap::encode(&bitmap, self.parts))
        };
        let compute = start.elapsed();
        if slowdown > 1.0 {
            std::thread::sleep(compute.mul_f64(slowdown - 1.0));
        }
        Ok(PackageResult {
            id: package.id,
            pixels,
            stats: WirePackageStats::from(&stats),
            busy_micros: start.elapsed().as_micros() as u64,
            setup_micros: 0,
            triangle_samples: samples,
            stage: quality.map(Into::into),
            mesh,
        })
    }

    /// A whole frame finished here as the master finishes a split one: the
    /// base frame with every reflector pixel of `bitmap` composited over it
    /// ([`Renderer::finish_frame`]), encoded in the job's format with the
    /// components when the job asks for them (the `FrameDone` codecs).
    fn finish(&self, bitmap: &SparseBitmap) -> ResultPixels {
        let all_parts = matches!(self.parts, WireBitmapParts::All);
        (self.renderer).finish_frame(&self.setup, bitmap, |image, scratch| ResultPixels::Frame {
            image: WireImage::encode_reusing(&image.color, self.image, scratch),
            aux: all_parts.then(|| WireFrameAux::encode(image)),
        })
    }

    /// The frame's pixel count: a package's sample budget is a multiple of it
    /// (no package owns more than the frame's pixels).
    pub fn pixels(&self) -> u64 {
        u64::from(self.setup.camera.width) * u64::from(self.setup.camera.height)
    }
}

/// The default budget of traced samples per frame pixel for one package.
/// Vertex tracing needs about 5 per pixel it owns at most (vertices at the
/// half-pixel floor plus filling), so only a runaway reaches this.
pub const SAMPLES_PER_PIXEL_BUDGET: u64 = 64;

/// Runs `f`, turning a panic into an error with its message, so that neither
/// a scene nor a package can take the worker down.
pub fn contain_panic<T>(f: impl FnOnce() -> T) -> Result<T, Panicked> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|payload| {
        let message = (payload.downcast_ref::<&str>().map(|s| s.to_string()))
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "no message".to_owned());
        Panicked(message)
    })
}

/// Vertex traces reflector triangles.
fn trace(
    frame: &Frame<'_>,
    triangles: &[u32],
) -> Result<(SparseBitmap, PackageStats, Vec<u32>), PackageError> {
    let triangle_count = frame.tracer.bvh.scene().triangles.len();
    let triangles = check_triangle_ids("package triangles", triangles, triangle_count)
        .map_err(PackageError::Triangles)?;
    let result = trace_package(frame, &triangles, &PackageOptions::default(), &mut |_| {});
    Ok((result.bitmap, result.stats, result.triangle_samples))
}

/// Runs stage `stage` at `quality` of a progressive package (on its
/// meshes only, no pixels, with `meshes_only`): sets the package up at its
/// first stage, continues it at the others.
fn advance(
    frame: &Frame<'_>,
    package: &Package,
    stage: usize,
    quality: Quality,
    meshes_only: bool,
    progress: &mut Option<ProgressivePackage>,
) -> Result<(SparseBitmap, PackageStats, Vec<u32>), PackageError> {
    let staged = match progress {
        Some(staged) => staged,
        None if stage == 0 => {
            let triangle_count = frame.tracer.bvh.scene().triangles.len();
            let triangles =
                check_triangle_ids("package triangles", &package.triangles, triangle_count)
                    .map_err(PackageError::Triangles)?;
            progress.insert(ProgressivePackage::new(frame, &triangles))
        }
        None => {
            let id = package.id;
            return Err(PackageError::StageWithoutProgress { id, stage });
        }
    };
    let options = PackageOptions::default();
    let result = if meshes_only {
        staged.advance_meshes(frame, quality, &options, &mut |_| {})
    } else {
        staged.advance(frame, quality, &options, &mut |_| {})
    };
    let result = result.map_err(PackageError::Stage)?;
    Ok((result.bitmap, result.stats, result.triangle_samples))
}

impl PerReflector {
    /// Renders whole reflectors (`items` index the groups); a group's cost
    /// for load balancing is its rays.
    fn render(
        &self,
        frame: &Frame<'_>,
        items: &[u32],
    ) -> Result<(SparseBitmap, PackageStats, Vec<u32>), PackageError> {
        let mut bitmaps = Vec::with_capacity(items.len());
        let mut stats = PackageStats::default();
        let mut samples = Vec::with_capacity(items.len());
        for &item in items {
            let group = (self.groups.get(item as usize)).ok_or(PackageError::NoSuchGroup {
                item,
                groups: self.groups.len(),
            })?;
            let output = self.method.render(&MethodFrame {
                tracer: frame.tracer,
                camera: frame.camera,
                ids: frame.ids,
                reflector: group,
                stop: frame.stop,
            });
            let c = output.counters;
            stats.add(&PackageStats {
                triangles: group.len() as u64,
                traced_triangles: group.len() as u64,
                vertex_samples: c.rays,
                pixels: c.pixels,
                vertex_time: c.time,
                ..PackageStats::default()
            });
            samples.push(u32::try_from(c.rays).unwrap_or(u32::MAX));
            bitmaps.push(output.bitmap);
        }
        Ok((merge_bitmaps(frame.ids.width, &bitmaps), stats, samples))
    }
}

/// The worker's disk cache of scenes, by content hash: blocking I/O (and
/// decoding), run off the session's task.
#[derive(Clone, Debug)]
pub struct SceneCache {
    dir: Option<PathBuf>,
}

impl SceneCache {
    fn path(&self, hash: &SceneHash) -> Option<PathBuf> {
        let name = format!("{}.scene", hex::encode(hash));
        Some(self.dir.as_ref()?.join(name))
    }

    /// The cached scene `hash`, checked against its hash, if the disk has
    /// it. A bad file is removed; a symlink is not followed (a miss).
    pub fn load(&self, hash: &SceneHash) -> Option<Scene> {
        let path = self.path(hash)?;
        let bytes = read_no_follow(&path).ok()?;
        match (SceneData { hash: *hash, bytes }).to_scene() {
            Ok(scene) => {
                debug!(path = %path.display(), "scene loaded from the cache");
                Some(scene)
            }
            Err(e) => {
                warn!(path = %path.display(), "dropping a bad cached scene: {e}");
                let _ = std::fs::remove_file(&path);
                None
            }
        }
    }

    /// Checks a scene from the master and keeps it on disk (a failure to
    /// cache is logged: the scene is still used).
    pub fn store(&self, data: &SceneData) -> Result<Scene, SceneError> {
        let scene = data.to_scene().map_err(SceneError)?;
        if let Some(path) = self.path(&data.hash) {
            if let Err(e) = write_no_follow(&path, &data.bytes) {
                warn!(path = %path.display(), "cannot cache the scene: {e}");
            }
        }
        info!(triangles = scene.triangles.len(), "scene received");
        Ok(scene)
    }
}

/// Reads a file, refusing a symlink in its last component (`O_NOFOLLOW`).
fn read_no_follow(path: &Path) -> std::io::Result<Vec<u8>> {
    let mut file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW)
        .open(path)?;
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut file, &mut bytes)?;
    Ok(bytes)
}

/// Writes `bytes` to a fresh temporary file beside `path` (created, never
/// opened through a link: `O_EXCL` and `O_NOFOLLOW`) and renames it over
/// `path`, which replaces a symlink there instead of writing through it.
fn write_no_follow(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let temporary = path.with_extension(format!("partial-{}", std::process::id()));
    let _ = std::fs::remove_file(&temporary);
    let written = (|| {
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .custom_flags(libc::O_NOFOLLOW)
            .open(&temporary)?;
        file.write_all(bytes)?;
        file.sync_all()
    })();
    match written.and_then(|()| std::fs::rename(&temporary, path)) {
        Ok(()) => Ok(()),
        Err(e) => {
            let _ = std::fs::remove_file(&temporary);
            Err(e)
        }
    }
}

/// Scenes by hash and the current frame.
pub struct Engine {
    cache: SceneCache,
    scenes: BTreeMap<SceneHash, Arc<Scene>>,
    /// The renderer of the last (scene, reflectors): building a BVH is the
    /// expensive part of a new frame, so consecutive frames share it.
    renderer: Option<(SceneHash, Vec<TriangleId>, Arc<Renderer>)>,
}

impl Engine {
    /// An engine caching scenes in `cache_dir` (created on demand), or only
    /// in memory.
    pub fn new(cache_dir: Option<PathBuf>) -> Self {
        Engine {
            cache: SceneCache { dir: cache_dir },
            scenes: BTreeMap::new(),
            renderer: None,
        }
    }

    /// The disk cache, for the driver's blocking threads.
    pub fn cache(&self) -> &SceneCache {
        &self.cache
    }

    /// Whether the scene is in memory.
    pub fn has_scene_in_memory(&self, hash: &SceneHash) -> bool {
        self.scenes.contains_key(hash)
    }

    /// Keeps a scene the driver loaded or checked.
    pub fn insert_scene(&mut self, hash: SceneHash, scene: Scene) {
        self.scenes.insert(hash, Arc::new(scene));
    }

    /// Whether the scene is at hand (memory, or the disk cache, which loads
    /// it here: the driver does that on a blocking thread first).
    pub fn has_scene(&mut self, hash: &SceneHash) -> bool {
        if self.scenes.contains_key(hash) {
            return true;
        }
        match self.cache.load(hash) {
            Some(scene) => {
                self.insert_scene(*hash, scene);
                true
            }
            None => false,
        }
    }

    /// Takes a scene from the master: checks it and keeps it (on disk too).
    pub fn add_scene(&mut self, data: SceneData) -> Result<(), SceneError> {
        let scene = self.cache.store(&data)?;
        self.insert_scene(data.hash, scene);
        Ok(())
    }

    /// Prepares a frame: the renderer (reused when scene and reflectors are
    /// the same) and the ID buffers, rebuilt locally (they are deterministic).
    pub fn start_frame(&mut self, start: FrameStart) -> Result<ActiveFrame, FrameError> {
        let frame = self.frame_parts(start)?.build()?;
        self.keep_renderer(&frame);
        Ok(frame)
    }

    /// The quick part of preparing a frame (checks, the renderer if cached
    /// for this scene and reflectors); [`FrameParts::build`] does the rest
    /// (a new renderer's BVH, the ID buffers) and needs no engine, so a
    /// driver runs it on another thread and then hands the frame to
    /// [`Engine::keep_renderer`].
    pub fn frame_parts(&mut self, start: FrameStart) -> Result<FrameParts, FrameError> {
        let scene = (self.scenes.get(&start.scene).cloned()).ok_or(FrameError::UnknownScene)?;
        let reflectors =
            check_triangle_ids("frame reflectors", &start.reflectors, scene.triangles.len())
                .map_err(FrameError::Reflectors)?;
        let setup = FrameSetup::try_from(start.setup).map_err(FrameError::Setup)?;
        check_stages(&start.stages, start.method).map_err(FrameError::Stages)?;
        let stages = start.stages.iter().map(|&q| Quality::from(q)).collect();
        // Items index the groups of the frame's reflector list as sent (the master's order).
        let method = MethodKind::from(start.method);
        let per_reflector = method.per_reflector().then(|| PerReflector {
            method: vtfarm_render::method(method, setup.vertex),
            groups: reflector_groups(&scene, &reflectors),
        });
        let renderer = match &self.renderer {
            Some((hash, cached, r)) if *hash == start.scene && *cached == reflectors => {
                Some(r.clone())
            }
            _ => None,
        };
        Ok(FrameParts {
            job: start.job,
            frame: start.frame,
            aux: start.aux,
            image: start.image,
            renderer_key: (start.scene, reflectors),
            scene,
            renderer,
            setup,
            per_reflector,
            stages,
        })
    }

    /// Frames the kept renderer has set up ([`Renderer::set_ups`]; a
    /// progressive frame counts one for all its stages).
    pub fn set_ups(&self) -> u64 {
        self.renderer.as_ref().map_or(0, |(_, _, r)| r.set_ups())
    }

    /// Keeps a prepared frame's renderer for the next frames of its scene
    /// and reflectors.
    pub fn keep_renderer(&mut self, frame: &ActiveFrame) {
        let (hash, reflectors) = frame.renderer_key.clone();
        self.renderer = Some((hash, reflectors, frame.renderer.clone()));
    }
}

/// A frame checked, before its renderer (unless cached) and ID buffers are built.
pub struct FrameParts {
    job: JobId,
    frame: u32,
    aux: bool,
    image: WireImageFormat,
    renderer_key: (SceneHash, Vec<TriangleId>),
    scene: Arc<Scene>,
    renderer: Option<Arc<Renderer>>,
    setup: FrameSetup,
    per_reflector: Option<PerReflector>,
    stages: Vec<Quality>,
}

impl FrameParts {
    /// The renderer: the cached one, or a new one (the BVH, seconds for the
    /// largest scenes), kept for [`FrameParts::build`].
    fn renderer(&mut self) -> Result<Arc<Renderer>, FrameError> {
        if let Some(renderer) = &self.renderer {
            return Ok(renderer.clone());
        }
        let (scene, reflectors) = (self.scene.clone(), self.renderer_key.1.clone());
        let built = contain_panic(|| Renderer::try_new(scene, reflectors))?;
        let renderer = Arc::new(built.map_err(|e| FrameError::Renderer(e.to_string()))?);
        self.renderer = Some(renderer.clone());
        Ok(renderer)
    }

    /// For a frame whose first stage is `preview` (a move of the view's
    /// eye), every reflector triangle's corners traced from the eye
    /// ([`Renderer::corner_meshes`]), which need no set-up: sent ahead of
    /// it, they are the view's first image. `None` for any other frame,
    /// and for more than [`MAX_CORNER_MESH_TRIANGLES`] reflector triangles.
    pub fn corner_mesh(&mut self) -> Result<Option<WireMesh>, FrameError> {
        let vertex_traced = self.per_reflector.is_none();
        let fits = self.renderer_key.1.len() <= MAX_CORNER_MESH_TRIANGLES;
        if !(vertex_traced && fits && self.stages.first() == Some(&Quality::Preview)) {
            return Ok(None);
        }
        let renderer = self.renderer()?;
        let meshes = contain_panic(|| renderer.corner_meshes(&self.setup))?;
        Ok(Some(WireMesh::from(&meshes[..])))
    }

    /// Builds the frame's renderer (unless [`FrameParts::corner_mesh`] or
    /// the cache has it) and ID buffers: the CPU work of a frame's set-up.
    pub fn build(mut self) -> Result<ActiveFrame, FrameError> {
        let renderer = self.renderer()?;
        let FrameParts {
            job,
            frame,
            aux,
            image,
            renderer_key,
            scene: _,
            renderer: _,
            setup,
            per_reflector,
            stages,
        } = self;
        let (ids, behind) = contain_panic(|| renderer.id_buffers(&setup))?;
        Ok(ActiveFrame {
            job,
            frame,
            renderer_key,
            renderer,
            setup,
            ids,
            behind,
            per_reflector,
            parts: if aux {
                WireBitmapParts::All
            } else {
                WireBitmapParts::Color
            },
            image,
            stages,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use vtfarm_cockpit::Cockpit;
    use vtfarm_proto::{SceneData, WireFrameSetup, wire_triangles};
    use vtfarm_scene::{Camera, Light, LightKind};

    /// A small cockpit and an engine that holds it.
    fn cockpit_engine() -> (Cockpit, SceneHash, Engine) {
        cockpit_engine_at(0.1)
    }

    /// The cockpit at `detail` and an engine that holds it.
    fn cockpit_engine_at(detail: f32) -> (Cockpit, SceneHash, Engine) {
        let cockpit = vtfarm_cockpit::cockpit(&vtfarm_cockpit::CockpitConfig {
            detail,
            ..Default::default()
        });
        let data = SceneData::from_scene(&cockpit.scene);
        let hash = data.hash;
        let mut engine = Engine::new(None);
        engine.add_scene(data).unwrap();
        (cockpit, hash, engine)
    }

    /// The cockpit's own camera, `width` × `height` pixels.
    fn sized(cockpit: &Cockpit, width: u32, height: u32) -> Camera {
        Camera {
            width,
            height,
            ..cockpit.camera
        }
    }

    /// Frame `frame` of the cockpit seen by `camera`, the sun along `sun`.
    fn cockpit_frame(
        (cockpit, hash): (&Cockpit, SceneHash),
        frame: u32,
        camera: Camera,
        sun: Vec3,
        reflectors: &[TriangleId],
    ) -> FrameStart {
        let mut lighting = cockpit.lighting.clone();
        lighting.lights[0] = Light {
            kind: LightKind::sun(sun),
            ..lighting.lights[0]
        };
        let setup = FrameSetup {
            camera,
            lighting,
            trace: Default::default(),
            vertex: Default::default(),
        };
        FrameStart {
            job: JobId(1),
            frame,
            scene: hash,
            setup: WireFrameSetup::from(&setup),
            reflectors: wire_triangles(reflectors),
            method: MethodKind::VertexTracing.into(),
            aux: true,
            image: WireImageFormat::LinearF32,
            stages: Vec::new(),
        }
    }

    /// A study's sun sweep sends frames that differ only in the lighting:
    /// the worker keeps the scene's renderer (its BVH) for all of them.
    #[test]
    fn frames_that_differ_only_in_the_sun_share_the_renderer() {
        let (cockpit, hash, mut engine) = cockpit_engine();
        let reflectors = cockpit.cover_glass_triangles();
        let camera = sized(&cockpit, 32, 18);
        let start = |frame: u32, sun: Vec3, reflectors: &[TriangleId]| {
            cockpit_frame((&cockpit, hash), frame, camera, sun, reflectors)
        };
        let a = engine
            .start_frame(start(0, Vec3::new(0.45, -0.85, -0.15), &reflectors))
            .unwrap();
        let b = engine
            .start_frame(start(1, Vec3::new(-0.9, -0.3, 0.1), &reflectors))
            .unwrap();
        assert!(Arc::ptr_eq(&a.renderer, &b.renderer));
        assert_ne!(a.setup.lighting, b.setup.lighting);
        // The ID buffers do not depend on the sun: rasterized once.
        assert_eq!(a.renderer.id_buffer_cache().builds(), 1);
        assert_eq!((&a.ids, &a.behind.ids), (&b.ids, &b.behind.ids));
        // Other reflectors make another renderer.
        let c = engine
            .start_frame(start(2, Vec3::new(-0.9, -0.3, 0.1), &reflectors[1..]))
            .unwrap();
        assert!(!Arc::ptr_eq(&a.renderer, &c.renderer));
    }

    /// A frame that differs from the one before only in the sun reuses its
    /// ID buffers and traces exactly as when set up alone.
    #[test]
    fn a_sun_only_frame_reuses_the_id_buffers_and_traces_as_alone() {
        let (cockpit, hash, mut engine) = cockpit_engine();
        let reflectors = cockpit.cover_glass_triangles();
        let camera = sized(&cockpit, 96, 54);
        let start = |frame: u32, sun: Vec3| {
            cockpit_frame((&cockpit, hash), frame, camera, sun, &reflectors)
        };
        let second = start(1, Vec3::new(-0.9, -0.3, 0.1));
        let package = Package {
            id: 1,
            job: JobId(1),
            frame: 1,
            triangles: wire_triangles(&reflectors),
            whole: Some(Box::new(second.clone())),
        };
        let run = |frame: &ActiveFrame| {
            let result = frame.run(&package, 1.0, &Stop::with_budget(u64::MAX));
            let result = result.unwrap();
            (result.pixels, result.triangle_samples)
        };
        let alone = run(&cockpit_engine().2.start_frame(second.clone()).unwrap());
        let first = engine
            .start_frame(start(0, Vec3::new(0.45, -0.85, -0.15)))
            .unwrap();
        let reused = engine.start_frame(second).unwrap();
        assert_eq!(
            first.renderer.id_buffer_cache().builds(),
            1,
            "rasterized once"
        );
        assert_eq!(run(&reused), alone);
        assert_ne!(run(&first), alone, "not vacuous: the sun changes the frame");
    }

    /// A frame's packages give the same bytes whether the engine set up
    /// other frames before (whose buffers covered other pixels, and whose
    /// shadow maps it keeps) or set up this frame alone: nothing of an
    /// earlier frame's set-up leaks into a later one.
    #[test]
    fn a_frame_traces_the_same_after_other_frames_as_alone() {
        let (cockpit, hash, mut engine) = cockpit_engine();
        let reflectors = cockpit.cover_glass_triangles();
        let camera = sized(&cockpit, 96, 54);
        // The eye moved sideways and up, the sun turned: other reflector
        // bounds, other ID buffers, other shadows.
        let moved = Camera {
            eye: camera.eye + Vec3::new(0.08, 0.05, 0.0),
            ..camera
        };
        let frames = [
            cockpit_frame(
                (&cockpit, hash),
                0,
                camera,
                Vec3::new(0.45, -0.85, -0.15),
                &reflectors,
            ),
            cockpit_frame(
                (&cockpit, hash),
                1,
                moved,
                Vec3::new(-0.9, -0.3, 0.1),
                &reflectors,
            ),
        ];
        // Two packages, each half of the reflector triangles.
        let packages = |frame: u32| {
            let half = reflectors.len() / 2;
            [&reflectors[..half], &reflectors[half..]].map(|triangles| Package {
                id: u64::from(frame),
                job: JobId(1),
                frame,
                triangles: wire_triangles(triangles),
                whole: None,
            })
        };
        let trace = |active: &ActiveFrame| {
            packages(active.frame).map(|package| {
                let result = active
                    .run(&package, 1.0, &Stop::with_budget(u64::MAX))
                    .unwrap();
                (result.pixels, result.triangle_samples)
            })
        };
        let alone: Vec<_> = frames
            .iter()
            .map(|start| {
                let (_, _, mut engine) = cockpit_engine();
                trace(&engine.start_frame(start.clone()).unwrap())
            })
            .collect();
        // One engine: both frames prepared, then the first traced after the
        // second, then the first prepared again after the second.
        let first = engine.start_frame(frames[0].clone()).unwrap();
        let second = engine.start_frame(frames[1].clone()).unwrap();
        assert_eq!(trace(&second), alone[1]);
        assert_eq!(trace(&first), alone[0]);
        drop((first, second));
        let again = engine.start_frame(frames[0].clone()).unwrap();
        assert_eq!(trace(&again), alone[0]);
        // Not vacuous: the frames differ, and the packages cover pixels.
        assert_ne!(alone[0], alone[1]);
        for (pixels, _) in alone.iter().flatten() {
            let ResultPixels::Bitmap(bitmap) = pixels else {
                panic!("a split package's result is a bitmap");
            };
            let covered = SparseBitmap::try_from(bitmap.clone())
                .unwrap()
                .covered()
                .count();
            assert!(covered > 50, "{covered} pixels covered");
        }
    }

    /// A progressive frame's package set up once and advanced preview →
    /// refine → full: the stages before the last send their meshes and no
    /// pixel, the last every pixel the package owns, the package traced
    /// from scratch at `full`, and the stages trace together exactly the
    /// vertices the package traces at `full` from scratch (none twice).
    /// Stages go in order, each after the one before.
    #[test]
    fn a_progressive_package_runs_its_stages_on_one_set_up() {
        let (cockpit, hash, mut engine) = cockpit_engine();
        let reflectors = cockpit.cover_glass_triangles();
        let camera = sized(&cockpit, 96, 54);
        let sun = Vec3::new(0.45, -0.85, -0.15);
        let stages = [Quality::Preview, Quality::Refine, Quality::Full];
        let start = |quality: Quality, staged: bool| {
            let mut start = cockpit_frame((&cockpit, hash), 0, camera, sun, &reflectors);
            let mut setup = FrameSetup::try_from(start.setup).unwrap();
            setup.vertex.quality = quality;
            start.setup = WireFrameSetup::from(&setup);
            if staged {
                start.stages = stages.iter().map(|&q| q.into()).collect();
            }
            start
        };
        let progressive = engine.start_frame(start(Quality::Full, true)).unwrap();
        assert_eq!(progressive.stages(), 3);
        let package = Package {
            id: 4,
            job: JobId(1),
            frame: 0,
            triangles: wire_triangles(&reflectors[reflectors.len() / 3..]),
            whole: None,
        };
        let unlimited = || Stop::with_budget(u64::MAX);
        let bitmap = |result: &PackageResult| match &result.pixels {
            ResultPixels::Bitmap(b) => SparseBitmap::try_from(b.clone()).unwrap(),
            ResultPixels::Frame { .. } => panic!("a split package's result is a bitmap"),
        };
        // A later stage needs the earlier ones' progress.
        assert!(matches!(
            progressive.run_stage(&package, 1, &mut None, 1.0, &unlimited()),
            Err(PackageError::StageWithoutProgress { id: 4, stage: 1 })
        ));
        assert!(matches!(
            progressive.run_stage(&package, 3, &mut None, 1.0, &unlimited()),
            Err(PackageError::NoSuchStage {
                stage: 3,
                stages: 3
            })
        ));
        // Each pixel's colour and components, bit for bit.
        type Pixels = BTreeMap<(u32, u32), vtfarm_vertex::PixelBits>;
        let composite = |pixels: &mut Pixels, result: &PackageResult| {
            pixels.extend(bitmap(result).pixel_bits());
        };
        let mut progress = None;
        let mut pixels = Pixels::new();
        let mut vertex_samples = 0;
        for (k, &quality) in stages.iter().enumerate() {
            let result = progressive
                .run_stage(&package, k, &mut progress, 1.0, &unlimited())
                .unwrap();
            assert_eq!(result.stage, Some(quality.into()));
            vertex_samples += result.stats.vertex_samples;
            if quality < Quality::Full {
                assert!(bitmap(&result).color.is_empty(), "{quality:?} sent pixels");
                assert!(result.mesh.is_some(), "{quality:?} sent no meshes");
                continue;
            }
            composite(&mut pixels, &result);
            let alone = cockpit_engine()
                .2
                .start_frame(start(quality, false))
                .unwrap();
            let scratch = alone.run(&package, 1.0, &unlimited()).unwrap();
            assert_eq!(scratch.stage, None);
            let mut expected = Pixels::new();
            composite(&mut expected, &scratch);
            assert!(
                expected.len() > 50,
                "{quality:?}: {} pixels",
                expected.len()
            );
            assert!(pixels == expected, "{quality:?}");
            assert_eq!(vertex_samples, scratch.stats.vertex_samples);
        }
        // The package's frame was set up once for its three stages.
        assert_eq!(engine.set_ups(), 1);
    }

    /// A view's frame (first stage `preview`) has a corner mesh before any
    /// set-up: one part per reflector triangle, and each part a package's
    /// preview stage sends for the same triangle is the same, bit for bit.
    /// A frame of one stage has none.
    #[test]
    fn a_views_corner_mesh_needs_no_set_up_and_holds_the_preview_stages_meshes() {
        let (cockpit, hash, mut engine) = cockpit_engine();
        let reflectors = cockpit.cover_glass_triangles();
        let camera = sized(&cockpit, 96, 54);
        let sun = Vec3::new(0.45, -0.85, -0.15);
        let single = cockpit_frame((&cockpit, hash), 0, camera, sun, &reflectors);
        let mut view = single.clone();
        view.stages = [Quality::Preview, Quality::Refine, Quality::Full]
            .iter()
            .map(|&q| q.into())
            .collect();
        assert_eq!(
            engine.frame_parts(single).unwrap().corner_mesh().unwrap(),
            None
        );
        let mesh = (engine.frame_parts(view.clone()).unwrap().corner_mesh())
            .unwrap()
            .expect("a view's frame has a corner mesh");
        assert_eq!(engine.set_ups(), 0, "no frame was set up for it");
        let corners = mesh.decode().unwrap();
        let mut parts: Vec<TriangleId> = corners.iter().map(|m| m.triangle).collect();
        parts.sort_unstable();
        let mut all = reflectors.clone();
        all.sort_unstable();
        assert_eq!(parts, all);

        let frame = engine.start_frame(view).unwrap();
        let package = Package {
            id: 1,
            job: JobId(1),
            frame: 0,
            triangles: wire_triangles(&reflectors),
            whole: None,
        };
        let stop = Stop::with_budget(u64::MAX);
        let preview = frame.run_stage(&package, 0, &mut None, 1.0, &stop).unwrap();
        let sent = preview
            .mesh
            .expect("a preview result has its meshes")
            .decode()
            .unwrap();
        assert!(sent.len() > 10, "{} triangles own pixels", sent.len());
        for part in &sent {
            let corner = corners
                .iter()
                .find(|m| m.triangle == part.triangle)
                .unwrap();
            assert_eq!(corner, part, "triangle {}", part.triangle);
        }
    }

    /// A view's frame with more reflector triangles than a corner mesh
    /// holds sends none: its preview comes with its packages' results.
    #[test]
    fn a_reflector_too_large_for_a_corner_mesh_has_none() {
        let (cockpit, hash, mut engine) = cockpit_engine_at(1.0);
        let every_triangle: Vec<TriangleId> = cockpit.scene.triangle_ids().collect();
        assert!(every_triangle.len() > MAX_CORNER_MESH_TRIANGLES);
        let camera = sized(&cockpit, 96, 54);
        let sun = Vec3::new(0.45, -0.85, -0.15);
        let mut view = cockpit_frame((&cockpit, hash), 0, camera, sun, &every_triangle);
        view.stages = [Quality::Preview, Quality::Refine, Quality::Full]
            .iter()
            .map(|&q| q.into())
            .collect();
        assert_eq!(
            engine.frame_parts(view).unwrap().corner_mesh().unwrap(),
            None
        );
    }
}
