//! The farm of the scenario tests: the real master core and worker sessions
//! ([`Farm`]) under a cost model of items with known true costs, so that
//! shares, speed-ups and fault runs can be checked against the work.
//!
//! Model: every item (a triangle of the cockpit scene) has a true cost in
//! seconds on a worker of speed 1; a package costs its items' sum (over the
//! worker's speed, plus its overhead) and reports one traced sample per
//! microsecond of it, which is what the master's cost estimates learn
//! from. A whole frame's result is a black image of the job's size. A
//! worker can be set to fail packages ([`Failures`]).

// Each test binary uses only some of the helpers.
#![allow(dead_code)]

use std::collections::HashMap;
use std::sync::{Arc, OnceLock};
use std::time::Duration;
use vtfarm_proto::JobId;

use rand::{Rng as _, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_farmsim::{
    CostModel, Farm, FarmConfig, MasterCosts, PackageRun, PackageWork, WorkerSpec, stand_in_result,
};
use vtfarm_master_core::FarmRules;
use vtfarm_method::MethodKind;
use vtfarm_proto::{
    FrameDone, FrameStart, FrameStats, JobScene, Message, Package, SceneData, SceneHash,
    WireBitmap, WireBitmapParts, WireFrameSetup, WireImageFormat, WireJob, WireJobKind,
};
use vtfarm_render::{FrameSetup, morton_order};
use vtfarm_scene::{Scene, TriangleId};
use vtfarm_vertex::SparseBitmap;
use vtfarm_worker::SceneStore;
use vtfarm_worker::engine::{FrameError, PackageError};

/// Traced samples a result reports per second of its true cost.
const SAMPLES_PER_SECOND: f64 = 1e6;

/// The scene every job renders (items are its triangles) and its set-up at
/// a tiny resolution: the master's base frames are real but the images do
/// not matter here.
pub(crate) struct World {
    pub(crate) scene: Arc<Scene>,
    pub(crate) data: SceneData,
    pub(crate) setup: FrameSetup,
}

/// Built once per test binary.
pub(crate) fn world() -> &'static World {
    static WORLD: OnceLock<World> = OnceLock::new();
    WORLD.get_or_init(|| {
        let c = cockpit(&CockpitConfig {
            detail: 0.2,
            ..CockpitConfig::default()
        });
        let setup = FrameSetup {
            camera: vtfarm_scene::Camera {
                width: 32,
                height: 18,
                ..c.camera
            },
            lighting: c.lighting,
            trace: Default::default(),
            vertex: Default::default(),
        };
        World {
            data: SceneData::from_scene(&c.scene),
            scene: Arc::new(c.scene),
            setup,
        }
    })
}

/// A frame's items in the master's (Morton) order and their true costs
/// (seconds at speed 1), in the same order.
#[derive(Clone, Debug)]
pub(crate) struct Items {
    pub(crate) items: Vec<u32>,
    pub(crate) costs: Vec<f64>,
}

impl Items {
    /// The frame's true cost on one worker of speed 1.
    pub(crate) fn work(&self) -> f64 {
        self.costs.iter().sum()
    }
}

/// A frame of the `n` triangles from `first` on, whose true costs vary
/// between `base` and `3·base`, plus a hot spot: the items at the
/// positions `hot` (in the master's order) cost `hot_factor` times more.
pub(crate) fn uneven_items(
    n: usize,
    first: u32,
    seed: u64,
    base: f64,
    hot: std::ops::Range<usize>,
    hot_factor: f64,
) -> Items {
    let ids = (first..first + n as u32).map(TriangleId).collect();
    let items = morton_order(&world().scene, ids)
        .into_iter()
        .map(TriangleId::raw)
        .collect();
    // The workspace's one seeded test generator.
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let costs = (0..n)
        .map(|i| {
            let c = base * (1.0 + 2.0 * rng.random::<f64>());
            if hot.contains(&i) { c * hot_factor } else { c }
        })
        .collect();
    Items { items, costs }
}

/// Which packages a worker fails.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) enum Failures {
    #[default]
    Never,
    Always,
    /// Its first `n` packages.
    FirstPackages(u32),
    /// Every package that holds one of these items.
    Items(Vec<u32>),
}

/// A package a worker ran (in the order of [`Farm::busy`]'s runs).
#[derive(Clone, Debug)]
pub(crate) struct Ran {
    pub(crate) job: JobId,
    pub(crate) frame: u32,
    pub(crate) whole: bool,
    pub(crate) items: usize,
    pub(crate) failed: bool,
}

/// A worker's state beside its session.
#[derive(Debug, Default)]
pub(crate) struct ItemWorker {
    scenes: Vec<SceneHash>,
    /// Set after it joined.
    pub(crate) failures: Failures,
    /// Its name, for its failures' text.
    pub(crate) name: String,
    pub(crate) ran: Vec<Ran>,
}

impl SceneStore for ItemWorker {
    fn has_scene(&mut self, hash: &SceneHash) -> bool {
        self.scenes.contains(hash)
    }

    type Error = std::convert::Infallible;

    fn add_scene(&mut self, data: SceneData) -> Result<(), Self::Error> {
        self.scenes.push(data.hash);
        Ok(())
    }
}

/// The cost model: true costs per item, the same in every frame and job.
#[derive(Debug, Default)]
pub(crate) struct ItemCosts {
    /// True cost of each item, by triangle id ([`submit`] adds a job's).
    pub(crate) costs: HashMap<u32, f64>,
    /// A worker's set-up of a frame, seconds at speed 1.
    pub(crate) frame_setup: f64,
    /// Result bytes on the wire per item, beside 64 bytes of header.
    pub(crate) result_bytes_per_item: u64,
    pub(crate) master: MasterCosts,
}

impl ItemCosts {
    pub(crate) fn add(&mut self, items: &Items) {
        let pairs = items.items.iter().copied().zip(items.costs.iter().copied());
        self.costs.extend(pairs);
    }
}

impl CostModel for ItemCosts {
    type Worker = ItemWorker;

    fn new_worker(&mut self) -> ItemWorker {
        ItemWorker::default()
    }

    fn reconnected(&mut self, _: &mut ItemWorker) {}

    fn prepare_frame(
        &mut self,
        _: &mut ItemWorker,
        _: FrameStart,
    ) -> (Result<(), FrameError>, f64) {
        (Ok(()), self.frame_setup)
    }

    fn run_package(
        &mut self,
        worker: &mut ItemWorker,
        package: &Package,
        _stage: usize,
    ) -> PackageWork {
        let costs: Vec<f64> = (package.triangles.iter())
            .map(|t| self.costs.get(t).copied().unwrap_or(0.0))
            .collect();
        let fails = match &worker.failures {
            Failures::Never => false,
            Failures::Always => true,
            Failures::FirstPackages(n) => worker.ran.len() < *n as usize,
            Failures::Items(items) => package.triangles.iter().any(|t| items.contains(t)),
        };
        worker.ran.push(Ran {
            job: package.job,
            frame: package.frame,
            whole: package.whole.is_some(),
            items: package.triangles.len(),
            failed: fails,
        });
        let bytes = 64 + self.result_bytes_per_item * costs.len() as u64;
        let bitmap = WireBitmap::encode(&SparseBitmap::default(), WireBitmapParts::Color);
        let samples = (costs.iter())
            .map(|c| (c * SAMPLES_PER_SECOND) as u32)
            .collect();
        PackageWork {
            result: stand_in_result(package, bitmap, samples),
            seconds: if fails { 0.0 } else { costs.iter().sum() },
            wire_bytes: Some(bytes),
            failure: fails.then(|| PackageError::Stopped {
                id: package.id,
                why: format!("failed on {}", worker.name),
            }),
        }
    }

    fn master_costs(&self) -> MasterCosts {
        self.master
    }
}

/// The scenario farm.
pub(crate) type ItemFarm = Farm<ItemCosts>;

/// A worker of speed `speed` with one core on a 100 Mbit/s link of 0.2 ms
/// latency, 1 ms of overhead per package.
pub(crate) fn worker(speed: f64) -> WorkerSpec {
    WorkerSpec {
        speed,
        cores: 1,
        link_bits_per_second: 100e6,
        latency: Duration::from_micros(200),
        package_overhead: Duration::from_millis(1),
    }
}

/// A farm under `rules` with an unlimited master link and the given costs.
pub(crate) fn farm(rules: FarmRules, model: ItemCosts) -> ItemFarm {
    farm_with_link(rules, model, f64::INFINITY)
}

/// A farm whose master's link runs at `master_link` bits per second.
pub(crate) fn farm_with_link(rules: FarmRules, model: ItemCosts, master_link: f64) -> ItemFarm {
    let config = FarmConfig {
        master_link_bits_per_second: master_link,
        master_cores: 1,
        shared_cores: None,
        background_threads: 0.0,
        submitter_latency: Duration::ZERO,
    };
    Farm::with_model(model, config, rules, None)
}

/// The master's rules with every frame split (no whole frames).
pub(crate) fn split_rules() -> FarmRules {
    FarmRules {
        whole_frames: false,
        ..FarmRules::default()
    }
}

/// The master's rules without straggler copies.
pub(crate) fn no_stragglers(rules: FarmRules) -> FarmRules {
    FarmRules {
        straggler: None,
        ..rules
    }
}

/// Adds `specs` as workers `w0`, `w1`, …
pub(crate) fn join_all(farm: &mut ItemFarm, specs: &[WorkerSpec]) {
    for spec in specs {
        let w = farm.workers.len();
        let name = format!("w{w}");
        farm.join(&name, spec.clone());
        farm.workers[w].state.name = name;
    }
}

/// Submits a job of `frames` copies of `items`' frame (its costs join the
/// model's).
pub(crate) fn submit(farm: &mut ItemFarm, items: &Items, frames: usize) {
    let world = world();
    let job = WireJob {
        name: "scenario".into(),
        scene: JobScene::Hash(world.data.hash),
        frames: vec![WireFrameSetup::from(&world.setup); frames],
        reflectors: items.items.clone(),
        aux: false,
        method: MethodKind::VertexTracing.into(),
        image: WireImageFormat::Srgb8,
        priority: 0,
        kind: WireJobKind::Render,
    };
    farm.model_mut().add(items);
    let before = accepted_jobs(farm).len();
    farm.submit(job, world.data.clone());
    // The master asks for the scene once: the next job by its hash waits
    // until it has it.
    farm.drive(Duration::from_secs(60), |f| accepted_jobs(f).len() > before);
}

/// Runs the farm until `at` (or until nothing is left to happen before).
pub(crate) fn run_until(farm: &mut ItemFarm, at: Duration) {
    let left = at.saturating_sub(farm.now);
    farm.drive_bounded(left, 10_000_000, &mut |_| false);
}

/// Runs until every one of the `jobs` submitted jobs has delivered its
/// frames or failed, with a bound of an hour of virtual time.
pub(crate) fn run_to_end(farm: &mut ItemFarm, frames_per_job: &[usize]) {
    let expected = frames_per_job.to_vec();
    farm.drive(Duration::from_secs(3600), |f| ended(f, &expected));
}

/// Whether each job ended: all its frames delivered, or failed.
fn ended(farm: &ItemFarm, frames_per_job: &[usize]) -> bool {
    let accepted = accepted_jobs(farm);
    accepted.len() == frames_per_job.len()
        && accepted.iter().zip(frames_per_job).all(|(job, &frames)| {
            let done = (farm.to_submitter.iter())
                .filter(|m| matches!(m, Message::FrameDone(d) if d.job == *job))
                .count();
            done == frames || failure(farm, *job).is_some()
        })
}

/// The jobs the master accepted, in submission order.
pub(crate) fn accepted_jobs(farm: &ItemFarm) -> Vec<JobId> {
    (farm.to_submitter.iter())
        .filter_map(|m| match m {
            Message::JobAccepted { job, .. } => Some(*job),
            _ => None,
        })
        .collect()
}

/// The errors a job failed with, if it failed.
pub(crate) fn failure(farm: &ItemFarm, job: JobId) -> Option<&Vec<String>> {
    farm.to_submitter.iter().find_map(|m| match m {
        Message::JobFailed { job: j, errors } if *j == job => Some(errors),
        _ => None,
    })
}

/// A delivered frame with its times.
#[derive(Clone, Debug)]
pub(crate) struct Delivered {
    pub(crate) job: JobId,
    pub(crate) frame: u32,
    /// When the master sent it.
    pub(crate) done_at: Duration,
    /// When its last result reached the master.
    pub(crate) completed_at: Duration,
    pub(crate) stats: FrameStats,
}

/// Every frame the submitter got, in order.
pub(crate) fn delivered(farm: &ItemFarm) -> Vec<Delivered> {
    let done: Vec<&FrameDone> = (farm.to_submitter.iter())
        .filter_map(|m| match m {
            Message::FrameDone(d) => Some(d),
            _ => None,
        })
        .collect();
    assert_eq!(done.len(), farm.deliveries.len(), "no replayed frames here");
    (done.iter().zip(&farm.deliveries))
        .map(|(d, t)| Delivered {
            job: d.job,
            frame: d.frame,
            done_at: t.done_at,
            completed_at: t.completed_at,
            stats: d.stats.clone(),
        })
        .collect()
}

/// Each delivered frame traced each of its `items` exactly once: its
/// workers' accepted items add up to the frame.
pub(crate) fn assert_each_item_once(frames: &[Delivered], items: usize) {
    for f in frames {
        let traced: u32 = f.stats.workers.iter().map(|w| w.triangles).sum();
        assert_eq!(traced as usize, items, "job {} frame {}", f.job, f.frame);
    }
}

/// The packages worker `w` ran: each run on the clock with what it was.
pub(crate) fn runs(farm: &ItemFarm, w: usize) -> Vec<(PackageRun, Ran)> {
    let ran = &farm.workers[w].state.ran;
    assert_eq!(ran.len(), farm.busy[w].len());
    (farm.busy[w].iter().cloned())
        .zip(ran.iter().cloned())
        .collect()
}

/// Each worker's share of the true cost of its packages of `frame` of
/// `job` that did not fail (a straggler's both copies count).
pub(crate) fn cost_shares(farm: &ItemFarm, job: JobId, frame: u32) -> Vec<f64> {
    let work: Vec<f64> = (0..farm.workers.len())
        .map(|w| {
            (runs(farm, w).iter())
                .filter(|(_, r)| r.job == job && r.frame == frame && !r.failed)
                .map(|(run, _)| run.work)
                .sum()
        })
        .collect();
    let total: f64 = work.iter().sum();
    work.iter().map(|w| w / total).collect()
}

/// The index of a worker from its name in the frame statistics
/// (`w3 (simulated)`: [`join_all`]'s name and its address).
pub(crate) fn worker_index(name: &str) -> usize {
    let index = name.strip_prefix('w').and_then(|n| n.split(' ').next());
    index
        .and_then(|n| n.parse().ok())
        .expect("a worker of join_all")
}

/// Kills worker `w` now; `noticed`: its connection drops (the master hears
/// at once), else only its missing heartbeats tell.
pub(crate) fn crash(farm: &mut ItemFarm, w: usize, noticed: bool) {
    let conn = farm.workers[w].conn();
    farm.kill(w);
    if noticed {
        farm.act(|master, now| master.disconnected(now, conn));
    }
}

/// The workers the master holds connected (by index), from its status.
pub(crate) fn connected_workers(farm: &ItemFarm) -> Vec<usize> {
    let status = farm.master.status();
    status
        .workers
        .iter()
        .map(|w| worker_index(&w.name))
        .collect()
}
