//! The test harness: the farm with the zero-cost model and its fault knobs.
//! Workers render every package for real (so images can be compared with
//! the single-process render), but only the traced samples take virtual
//! time (each [`SAMPLE_COST`] over the worker's speed); set-ups, base
//! frames, the master's driver and the submitter cost nothing, and links
//! have a latency only. Schedules, faults and load balance replay exactly,
//! in milliseconds, without sockets or sleeps.

use std::collections::BTreeMap;
use std::time::Duration;
use vtfarm_proto::JobId;

use vtfarm_master_core::FarmRules;
use vtfarm_proto::{
    FrameKey, FrameStart, Package, PackageId, SceneData, SceneHash, WireMesh, WirePackageStats,
};
use vtfarm_vertex::{ProgressivePackage, Stop};
use vtfarm_worker::Engine;
use vtfarm_worker::SceneStore;
use vtfarm_worker::engine::{FrameError, PreparedFrames};

use crate::farm::{CostModel, Farm, FarmConfig, JobJournal, MasterCosts, PackageWork, WorkerSpec};

/// Virtual time one traced sample costs a worker of speed 1.
pub const SAMPLE_COST: Duration = Duration::from_micros(20);

/// Delay of every message in the test harness.
pub const TEST_LATENCY: Duration = Duration::from_millis(1);

/// The zero-cost model: real rendering, only the samples take time.
#[derive(Debug, Default)]
pub struct Rendered;

/// A rendering worker's engine (scene cache), prepared frames and the
/// progressive packages between their stages (as `serve` keeps them; a
/// cancelled one's stays until the worker reconnects: test farms are short).
pub struct RenderingWorker {
    pub engine: Engine,
    frames: PreparedFrames,
    progress: BTreeMap<PackageId, ProgressivePackage>,
    /// Every package stage it ran, in order, for tests to count.
    pub stages_run: Vec<StageRun>,
}

/// A package stage a rendering worker ran.
#[derive(Clone, Debug)]
pub struct StageRun {
    pub job: JobId,
    pub package: PackageId,
    /// Its index among its frame's stages (0 for a frame of one stage).
    pub stage: usize,
    pub triangles: Vec<u32>,
    pub stats: WirePackageStats,
}

impl SceneStore for RenderingWorker {
    fn has_scene(&mut self, hash: &SceneHash) -> bool {
        self.engine.has_scene(hash)
    }

    type Error = vtfarm_worker::engine::SceneError;

    fn add_scene(&mut self, data: SceneData) -> Result<(), Self::Error> {
        self.engine.add_scene(data)
    }
}

impl CostModel for Rendered {
    type Worker = RenderingWorker;

    fn new_worker(&mut self) -> RenderingWorker {
        RenderingWorker {
            engine: Engine::new(None),
            frames: PreparedFrames::default(),
            progress: BTreeMap::new(),
            stages_run: Vec::new(),
        }
    }

    fn reconnected(&mut self, worker: &mut RenderingWorker) {
        worker.frames = PreparedFrames::default();
        worker.progress.clear();
    }

    fn prepare_frame(
        &mut self,
        worker: &mut RenderingWorker,
        start: FrameStart,
    ) -> (Result<(), FrameError>, f64) {
        let outcome = worker.engine.start_frame(start);
        (outcome.map(|frame| worker.frames.insert(frame)), 0.0)
    }

    fn corner_mesh(
        &mut self,
        worker: &mut RenderingWorker,
        start: &FrameStart,
    ) -> Option<WireMesh> {
        let mut parts = worker.engine.frame_parts(start.clone()).ok()?;
        // A frame that cannot be set up fails in `prepare_frame`.
        parts.corner_mesh().ok().flatten()
    }

    fn retain_frames(&mut self, worker: &mut RenderingWorker, keeps: &dyn Fn(FrameKey) -> bool) {
        worker.frames.retain(keeps);
    }

    fn run_package(
        &mut self,
        worker: &mut RenderingWorker,
        package: &Package,
        stage: usize,
    ) -> PackageWork {
        let frame = (worker.frames.get(package.job, package.frame))
            .expect("the session runs packages of prepared frames only");
        let unlimited = Stop::with_budget(u64::MAX);
        let mut progress = worker.progress.remove(&package.id);
        let result = frame.run_stage(package, stage, &mut progress, 1.0, &unlimited);
        let result = result.expect("packages render");
        if let Some(progress) = progress.filter(|_| stage + 1 < frame.stages()) {
            worker.progress.insert(package.id, progress);
        }
        worker.stages_run.push(StageRun {
            job: package.job,
            package: package.id,
            stage,
            triangles: package.triangles.clone(),
            stats: result.stats,
        });
        let samples: u64 = (result.triangle_samples.iter())
            .map(|&s| u64::from(s) + 1)
            .sum();
        PackageWork {
            result,
            seconds: SAMPLE_COST.as_secs_f64() * samples as f64,
            wire_bytes: None,
            failure: None,
        }
    }

    fn master_costs(&self) -> MasterCosts {
        MasterCosts::default()
    }

    fn forget_records(&mut self, worker: &mut RenderingWorker) {
        worker.stages_run = Vec::new();
    }
}

/// The test harness: the real master core and N rendering workers, one
/// submitter, [`TEST_LATENCY`] on every message.
pub type TestFarm = Farm<Rendered>;

fn test_config() -> FarmConfig {
    FarmConfig {
        master_link_bits_per_second: f64::INFINITY,
        master_cores: 1,
        shared_cores: None,
        background_threads: 0.0,
        submitter_latency: TEST_LATENCY,
    }
}

impl Farm<Rendered> {
    /// A harness whose master keeps its jobs in memory.
    pub fn new(rules: FarmRules) -> TestFarm {
        Farm::with_model(Rendered, test_config(), rules, None)
    }

    /// A harness whose master journals its jobs into `journal`.
    pub fn persistent(rules: FarmRules, journal: impl JobJournal + 'static) -> TestFarm {
        Farm::with_model(Rendered, test_config(), rules, Some(Box::new(journal)))
    }

    /// Adds a worker that connects now, its packages taking `slowdown`
    /// (≥ 1) times the samples' time; returns its index.
    pub fn add_worker(&mut self, name: &str, slowdown: f64) -> usize {
        let spec = WorkerSpec {
            speed: 1.0 / slowdown,
            cores: 1,
            link_bits_per_second: f64::INFINITY,
            latency: TEST_LATENCY,
            package_overhead: Duration::ZERO,
        };
        self.join(name, spec)
    }
}
