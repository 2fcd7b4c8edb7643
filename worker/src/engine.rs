//! The worker's computing side, without I/O on the network: the scene cache
//! (in memory and on disk, by content hash), the renderer of the current
//! scene, the current frame's ID buffers, and running packages.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use tracing::{debug, info, warn};
use vtfarm_method::{MethodFrame, MethodKind, ReflectionMethod, merge_bitmaps, reflector_groups};
use vtfarm_proto::{
    FrameStart, JobId, Package, PackageResult, SceneData, SceneHash, WireBitmap, WireBitmapParts,
    WirePackageStats, check_triangle_ids,
};
use vtfarm_raster::IdBuffer;
use vtfarm_render::{FrameSetup, Renderer};
use vtfarm_scene::Scene;
use vtfarm_vertex::{
    Behind, Frame, PackageOptions, PackageStats, SparseBitmap, Stop, trace_package,
};

/// The frames a worker keeps prepared: the newest and the ones before it
/// whose packages the master may still hand out while frames are pipelined
/// ([`vtfarm_proto::FRAMES_IN_FLIGHT`], see `session`).
#[derive(Default)]
pub struct PreparedFrames(Vec<Arc<ActiveFrame>>);

impl PreparedFrames {
    /// Keeps `frame`, dropping the oldest (by job and frame) beyond
    /// [`vtfarm_proto::FRAMES_IN_FLIGHT`]: a skipped frame may be prepared
    /// after newer ones.
    pub fn insert(&mut self, frame: ActiveFrame) {
        self.0.push(Arc::new(frame));
        self.0.sort_by_key(|a| (a.job, a.frame));
        if self.0.len() > vtfarm_proto::FRAMES_IN_FLIGHT {
            self.0.remove(0);
        }
    }

    /// The prepared frame `frame` of `job`, if kept.
    pub fn get(&self, job: JobId, frame: u32) -> Option<Arc<ActiveFrame>> {
        (self.0.iter())
            .find(|a| (a.job, a.frame) == (job, frame))
            .cloned()
    }
}

/// A frame ready for packages: its renderer, set-up and ID buffers.
pub struct ActiveFrame {
    pub job: JobId,
    pub frame: u32,
    renderer: Arc<Renderer>,
    setup: FrameSetup,
    ids: IdBuffer,
    behind: Behind,
    /// The frame's method when it is not vertex tracing.
    per_reflector: Option<PerReflector>,
    /// What the results carry (the components only when the job wants them).
    parts: WireBitmapParts,
}

/// A per-reflector method with the reflector groups its package items index.
struct PerReflector {
    method: Box<dyn ReflectionMethod>,
    groups: Vec<Vec<u32>>,
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
    ) -> Result<PackageResult, String> {
        let start = Instant::now();
        let frame = Frame {
            stop: Some(stop),
            ..self.renderer.frame(&self.setup, &self.ids, &self.behind)
        };
        let (bitmap, stats, samples) = contain_panic(|| match &self.per_reflector {
            None => trace(&frame, &package.triangles),
            Some(per_reflector) => per_reflector.render(&frame, &package.triangles),
        })??;
        if let Some(why) = stop.stopped() {
            return Err(format!("package {} {why}", package.id));
        }
        let compute = start.elapsed();
        if slowdown > 1.0 {
            std::thread::sleep(compute.mul_f64(slowdown - 1.0));
        }
        Ok(PackageResult {
            id: package.id,
            bitmap: WireBitmap::encode(&bitmap, self.parts),
            stats: WirePackageStats::from(&stats),
            busy_micros: start.elapsed().as_micros() as u64,
            setup_micros: 0,
            triangle_samples: samples,
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
pub fn contain_panic<T>(f: impl FnOnce() -> T) -> Result<T, String> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).map_err(|payload| {
        let message = (payload.downcast_ref::<&str>().map(|s| s.to_string()))
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "no message".to_owned());
        format!("panicked: {message}")
    })
}

/// Vertex traces reflector triangles.
fn trace(
    frame: &Frame<'_>,
    triangles: &[u32],
) -> Result<(SparseBitmap, PackageStats, Vec<u32>), String> {
    let triangle_count = frame.tracer.bvh.scene().triangles.len();
    check_triangle_ids("package triangles", triangles, triangle_count)
        .map_err(|e| e.to_string())?;
    let result = trace_package(frame, triangles, &PackageOptions::default(), &mut |_| {});
    Ok((result.bitmap, result.stats, result.triangle_samples))
}

impl PerReflector {
    /// Renders whole reflectors (`items` index the groups); a group's cost
    /// for load balancing is its rays.
    fn render(
        &self,
        frame: &Frame<'_>,
        items: &[u32],
    ) -> Result<(SparseBitmap, PackageStats, Vec<u32>), String> {
        let mut bitmaps = Vec::with_capacity(items.len());
        let mut stats = PackageStats::default();
        let mut samples = Vec::with_capacity(items.len());
        for &item in items {
            let group = self.groups.get(item as usize).ok_or_else(|| {
                format!(
                    "package item {item} names no reflector (the frame has {})",
                    self.groups.len()
                )
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

/// Scenes by hash and the current frame.
pub struct Engine {
    cache_dir: Option<PathBuf>,
    scenes: BTreeMap<SceneHash, Arc<Scene>>,
    /// The renderer of the last (scene, reflectors): building a BVH is the
    /// expensive part of a new frame, so consecutive frames share it.
    renderer: Option<(SceneHash, Vec<u32>, Arc<Renderer>)>,
}

impl Engine {
    /// An engine caching scenes in `cache_dir` (created on demand), or only
    /// in memory.
    pub fn new(cache_dir: Option<PathBuf>) -> Self {
        Engine {
            cache_dir,
            scenes: BTreeMap::new(),
            renderer: None,
        }
    }

    fn cache_path(&self, hash: &SceneHash) -> Option<PathBuf> {
        Some(
            self.cache_dir
                .as_ref()?
                .join(format!("{}.scene", hex::encode(hash))),
        )
    }

    /// Whether the scene is at hand (memory, or the disk cache, which loads it).
    pub fn has_scene(&mut self, hash: &SceneHash) -> bool {
        if self.scenes.contains_key(hash) {
            return true;
        }
        let Some(path) = self.cache_path(hash) else {
            return false;
        };
        let Ok(bytes) = std::fs::read(&path) else {
            return false;
        };
        match (SceneData { hash: *hash, bytes }).to_scene() {
            Ok(scene) => {
                debug!(path = %path.display(), "scene loaded from the cache");
                self.scenes.insert(*hash, Arc::new(scene));
                true
            }
            Err(e) => {
                warn!(path = %path.display(), "dropping a bad cached scene: {e}");
                let _ = std::fs::remove_file(&path);
                false
            }
        }
    }

    /// Takes a scene from the master: checks it and keeps it (on disk too).
    pub fn add_scene(&mut self, data: SceneData) -> Result<(), String> {
        let scene = data
            .to_scene()
            .map_err(|e| format!("bad scene from the master: {e}"))?;
        if let Some(path) = self.cache_path(&data.hash) {
            let stored = path
                .parent()
                .map_or(Ok(()), std::fs::create_dir_all)
                .and_then(|()| std::fs::write(&path, &data.bytes));
            if let Err(e) = stored {
                warn!(path = %path.display(), "cannot cache the scene: {e}");
            }
        }
        info!(triangles = scene.triangles.len(), "scene received");
        self.scenes.insert(data.hash, Arc::new(scene));
        Ok(())
    }

    /// Prepares a frame: the renderer (reused when scene and reflectors are
    /// the same) and the ID buffers, rebuilt locally (they are deterministic).
    pub fn start_frame(&mut self, start: FrameStart) -> Result<ActiveFrame, String> {
        self.frame_parts(start)?.build()
    }

    /// The quick part of preparing a frame (checks, the renderer, cached per
    /// scene and reflectors); [`FrameParts::build`] does the rest (the ID
    /// buffers) and needs no engine, so a driver can run it on another thread.
    pub fn frame_parts(&mut self, start: FrameStart) -> Result<FrameParts, String> {
        let scene = self
            .scenes
            .get(&start.scene)
            .cloned()
            .ok_or("frame for a scene this worker does not have")?;
        check_triangle_ids("frame reflectors", &start.reflectors, scene.triangles.len())
            .map_err(|e| e.to_string())?;
        let setup = FrameSetup::try_from(start.setup).map_err(|e| e.to_string())?;
        // Items index the groups of the frame's reflector list as sent (the master's order).
        let method = MethodKind::from(start.method);
        let per_reflector = method.per_reflector().then(|| PerReflector {
            method: vtfarm_render::method(method, setup.vertex),
            groups: reflector_groups(&scene, &start.reflectors),
        });
        let renderer = match &self.renderer {
            Some((hash, reflectors, r))
                if *hash == start.scene && *reflectors == start.reflectors =>
            {
                r.clone()
            }
            _ => {
                let reflectors = start.reflectors.clone();
                let r = contain_panic(|| Renderer::try_new(scene, reflectors))?
                    .map_err(|e| e.to_string())?;
                let r = Arc::new(r);
                self.renderer = Some((start.scene, start.reflectors, r.clone()));
                r
            }
        };
        Ok(FrameParts {
            job: start.job,
            frame: start.frame,
            aux: start.aux,
            renderer,
            setup,
            per_reflector,
        })
    }
}

/// A frame checked and with its renderer, before its ID buffers are built.
pub struct FrameParts {
    job: JobId,
    frame: u32,
    aux: bool,
    renderer: Arc<Renderer>,
    setup: FrameSetup,
    per_reflector: Option<PerReflector>,
}

impl FrameParts {
    /// Builds the frame's ID buffers: the CPU work of a frame's set-up.
    pub fn build(self) -> Result<ActiveFrame, String> {
        let FrameParts {
            job,
            frame,
            aux,
            renderer,
            setup,
            per_reflector,
        } = self;
        let (ids, behind) = contain_panic(|| renderer.id_buffers(&setup))?;
        Ok(ActiveFrame {
            job,
            frame,
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
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use vtfarm_cockpit::Cockpit;
    use vtfarm_proto::{SceneData, WireFrameSetup};
    use vtfarm_scene::{Camera, Light, LightKind};

    /// A small cockpit and an engine that holds it.
    fn cockpit_engine() -> (Cockpit, SceneHash, Engine) {
        let cockpit = vtfarm_cockpit::cockpit(&vtfarm_cockpit::CockpitConfig {
            detail: 0.1,
            ..Default::default()
        });
        let data = SceneData::from_scene(&cockpit.scene);
        let hash = data.hash;
        let mut engine = Engine::new(None);
        engine.add_scene(data).unwrap();
        (cockpit, hash, engine)
    }

    /// Frame `frame` of the cockpit seen by `camera`, the sun along `sun`.
    fn cockpit_frame(
        (cockpit, hash): (&Cockpit, SceneHash),
        frame: u32,
        camera: Camera,
        sun: Vec3,
        reflectors: &[u32],
    ) -> FrameStart {
        let mut lighting = cockpit.lighting.clone();
        lighting.lights[0] = Light {
            kind: LightKind::Directional { direction: sun },
            ..lighting.lights[0]
        };
        let setup = FrameSetup {
            camera,
            lighting,
            trace: Default::default(),
            vertex: Default::default(),
        };
        FrameStart {
            job: 1,
            frame,
            scene: hash,
            setup: WireFrameSetup::from(&setup),
            reflectors: reflectors.to_vec(),
            method: MethodKind::VertexTracing.into(),
            aux: true,
        }
    }

    /// A study's sun sweep sends frames that differ only in the lighting:
    /// the worker keeps the scene's renderer (its BVH) for all of them.
    #[test]
    fn frames_that_differ_only_in_the_sun_share_the_renderer() {
        let (cockpit, hash, mut engine) = cockpit_engine();
        let reflectors = cockpit.cover_glass_triangles();
        let camera = Camera {
            width: 32,
            height: 18,
            ..cockpit.camera
        };
        let start = |frame: u32, sun: Vec3, reflectors: &[u32]| {
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
        // Other reflectors make another renderer.
        let c = engine
            .start_frame(start(2, Vec3::new(-0.9, -0.3, 0.1), &reflectors[1..]))
            .unwrap();
        assert!(!Arc::ptr_eq(&a.renderer, &c.renderer));
    }

    /// A frame's packages give the same bytes whether the engine set up
    /// other frames before (whose buffers covered other pixels, and whose
    /// shadow maps it keeps) or set up this frame alone: nothing of an
    /// earlier frame's set-up leaks into a later one.
    #[test]
    fn a_frame_traces_the_same_after_other_frames_as_alone() {
        let (cockpit, hash, mut engine) = cockpit_engine();
        let reflectors = cockpit.cover_glass_triangles();
        let camera = Camera {
            width: 96,
            height: 54,
            ..cockpit.camera
        };
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
                job: 1,
                frame,
                triangles: triangles.to_vec(),
            })
        };
        let trace = |active: &ActiveFrame| {
            packages(active.frame).map(|package| {
                let result = active
                    .run(&package, 1.0, &Stop::with_budget(u64::MAX))
                    .unwrap();
                (result.bitmap, result.triangle_samples)
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
        for (bitmap, _) in alone.iter().flatten() {
            let covered = SparseBitmap::try_from(bitmap.clone())
                .unwrap()
                .covered()
                .count();
            assert!(covered > 50, "{covered} pixels covered");
        }
    }
}
