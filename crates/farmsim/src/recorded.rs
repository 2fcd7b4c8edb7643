//! `vtfarm bench simulate`'s model: the farm with costs recorded from a real
//! frame. A package costs the recorded one-thread seconds of its items over
//! the worker's speed, plus a fixed overhead; a frame's set-up
//! [`FarmCosts::worker_setup`] over the speed. Results carry each item's
//! recorded samples (what the master's cost estimates learn from) and an
//! empty bitmap; their size on the wire is the recorded one. A whole frame
//! costs its worker also what the master spends on a split one (base
//! frame, compositing, encoding: the same functions), and its result is a
//! stand-in image of the job's size, [`FarmCosts::frame_bytes`] on the wire. The master
//! core rasterizes for real, but at the job's tiny resolution (the base
//! frame's *time* is [`MasterCosts::base_frame`]): the images do not matter
//! here. [`simulate_farm`] runs a job to its end and measures each frame.

use std::collections::HashMap;
use std::sync::Arc;
use std::time::Duration;

use vtfarm_master_core::FarmRules;
use vtfarm_method::MethodKind;
use vtfarm_proto::{
    FrameStart, FrameStats, JobScene, Package, SceneData, SceneHash, WireBitmap, WireBitmapParts,
    WireFrameSetup, WireImageFormat, WireJob, wire_triangles,
};
use vtfarm_render::FrameSetup;
use vtfarm_scene::{Scene, TriangleId};
use vtfarm_vertex::SparseBitmap;
use vtfarm_worker::SceneStore;
use vtfarm_worker::engine::FrameError;

use crate::SimulationError;
use crate::farm::{
    CostModel, Farm, FarmConfig, MasterCosts, PackageRun, PackageWork, WorkerSpec, stand_in_result,
};

/// What the work costs: per item (reflector triangle, in the master's
/// Morton order) and per frame, in one-thread seconds of this machine.
#[derive(Clone, Debug)]
pub struct FarmCosts {
    /// The work items (reflector triangle ids) in the master's order.
    pub items: Vec<u32>,
    /// Tracing seconds per item.
    pub seconds: Vec<f64>,
    /// Traced samples per item (what a result reports).
    pub samples: Vec<u32>,
    /// Bytes per item of a result beyond a message's fixed part.
    pub result_bytes: Vec<u64>,
    /// A result message's fixed part.
    pub empty_result_bytes: u64,
    /// A finished frame's image on the wire (a whole frame's result).
    pub frame_bytes: u64,
    /// A worker's set-up of a frame.
    pub worker_setup: f64,
    /// A worker's first frame of the scene, beside its set-up: the scene
    /// decoded and checked, its renderer (the BVH) built
    /// (`vtfarm_worker::engine::FrameParts::build`); none for a worker that
    /// holds it ([`SimulationConfig::workers_hold_scene`]).
    pub scene_prepare: f64,
    /// The master's machine's.
    pub master: MasterCosts,
}

/// A simulated run: the machines around the workers and the job's length.
#[derive(Clone, Debug)]
pub struct SimulationConfig {
    /// The master's shared link, bits per second each way.
    pub master_link_bits_per_second: f64,
    /// Cores of the master's machine.
    pub master_cores: u32,
    /// Everything on one machine of this many cores (a localhost farm):
    /// workers, master and its base frames share them.
    pub shared_cores: Option<u32>,
    /// Other work on the shared machine: this many threads that always want
    /// to run and share its cores fairly with the farm's jobs (a fraction
    /// runs part of the time). Ignored without [`SimulationConfig::shared_cores`].
    pub background_threads: f64,
    /// Frames of the job.
    pub frames: u32,
    /// The master's rules (`FarmRules::default()` is what a master runs:
    /// whole frames for batch work).
    pub rules: FarmRules,
    /// Gives up at this virtual time.
    pub time_limit: Duration,
    /// Every worker holds the job's scene with its renderer from an earlier
    /// job of it (a shared cluster's common case): the master's offer needs
    /// no transfer and the first frame no [`FarmCosts::scene_prepare`]. Off,
    /// each worker gets the scene over the links and prepares it first.
    pub workers_hold_scene: bool,
}

/// A finished frame as the submitter got it.
#[derive(Clone, Debug)]
pub struct FarmFrame {
    /// When the master announced the frame (its first `FrameStart` sent):
    /// none of its work, set-ups included, can start earlier.
    pub started_at: Duration,
    /// When the master's driver sent it.
    pub done_at: Duration,
    /// When its last result reached the master ([`Delivery::completed_at`]):
    /// unlike `done_at`, never held back by the frames before it.
    ///
    /// [`Delivery::completed_at`]: crate::farm::Delivery::completed_at
    pub completed_at: Duration,
    /// Load imbalance over the frame's lifetime (`started_at` to
    /// `done_at`): `(max − mean) / mean` of every worker's time spent on
    /// packages in that window, whichever frame they belonged to (with
    /// pipelined frames a worker's share of one frame says nothing of its
    /// idle time). A worker idle throughout counts with 0; 0 when no
    /// worker traced.
    pub imbalance: f64,
    /// The share of the frame's traced work done after the first frame's
    /// delivery.
    pub share_after_first_delivery: f64,
    /// The frame's index in its job.
    pub index: u32,
    /// CPU seconds the other work ([`SimulationConfig::background_threads`]) had
    /// got by the frame's delivery.
    pub background_cpu: f64,
    /// CPU seconds each process had used by the frame's delivery: the
    /// master (driver, base frames, journal), each worker, the submitter.
    pub cpu: Vec<f64>,
    pub stats: FrameStats,
}

/// Steady-state seconds per frame: the window from the first frame's
/// delivery to the last frame's over the frames traced in it, each counted
/// with the share of its work done in the window (one frame: its own
/// lifetime). The start-up (the scene's way to every worker, uniform cost
/// estimates) is left out, whichever frames were announced meanwhile. When
/// less than a frame's work is left after the first delivery (a short job
/// whose frames all ran at once), the window is the whole job instead. The
/// window holds that much work, so it is never shorter than that work over
/// the workers' summed speed: an efficiency from it cannot exceed 100%,
/// however pipelined frames bunch.
pub fn steady_frame_seconds(frames: &[FarmFrame]) -> f64 {
    let (Some(first), Some(last)) = (frames.first(), frames.last()) else {
        return 0.0;
    };
    let traced: f64 = frames.iter().map(|f| f.share_after_first_delivery).sum();
    let (from, traced) = if traced >= 1.0 {
        (first.done_at, traced)
    } else {
        (first.started_at, frames.len() as f64)
    };
    last.done_at.saturating_sub(from).as_secs_f64() / traced
}

/// The cores the other work on a shared machine used on average over the
/// window of [`steady_frame_seconds`] (from the first frame's delivery to
/// the last's): what `scripts/scaling.sh` measures of a real run.
pub fn steady_background_cores(frames: &[FarmFrame]) -> f64 {
    let (Some(first), Some(last)) = (frames.first(), frames.last()) else {
        return 0.0;
    };
    let window = last.done_at.saturating_sub(first.done_at).as_secs_f64();
    if window > 0.0 {
        (last.background_cpu - first.background_cpu) / window
    } else {
        0.0
    }
}

/// CPU seconds per frame of each process (the master, each worker, the
/// submitter)
/// from the first frame's delivery to the last's, over the frames delivered
/// in between: what `scripts/scaling.sh` reads from /proc for a real run.
pub fn cpu_per_frame(frames: &[FarmFrame]) -> Vec<f64> {
    let (Some(first), Some(last)) = (frames.first(), frames.last()) else {
        return Vec::new();
    };
    let delivered = (frames.len() - 1).max(1) as f64;
    (first.cpu.iter().zip(&last.cpu))
        .map(|(a, b)| (b - a) / delivered)
        .collect()
}

/// The job the simulated master runs: the real scene and reflectors, one
/// frame set-up repeated.
pub struct FarmJob {
    pub scene: Arc<Scene>,
    pub reflectors: Vec<TriangleId>,
    pub setup: FrameSetup,
}

/// [`FarmCosts`] as the farm's cost model.
struct Recorded<'a> {
    costs: &'a FarmCosts,
    index_of: HashMap<u32, usize>,
    empty_bitmap: WireBitmap,
    /// The scene every new worker holds prepared
    /// ([`SimulationConfig::workers_hold_scene`]).
    held: Option<SceneHash>,
}

/// A recorded worker's scene store: the hashes it holds, and those it has
/// prepared (decoded, its renderer built: the engine keeps them).
#[derive(Default)]
pub struct SceneHashes {
    held: Vec<SceneHash>,
    prepared: Vec<SceneHash>,
}

impl SceneStore for SceneHashes {
    fn has_scene(&mut self, hash: &SceneHash) -> bool {
        self.held.contains(hash)
    }

    type Error = std::convert::Infallible;

    fn add_scene(&mut self, data: SceneData) -> Result<(), Self::Error> {
        self.held.push(data.hash);
        Ok(())
    }
}

impl CostModel for Recorded<'_> {
    type Worker = SceneHashes;

    fn new_worker(&mut self) -> SceneHashes {
        let held = Vec::from_iter(self.held);
        SceneHashes {
            prepared: held.clone(),
            held,
        }
    }

    fn reconnected(&mut self, _: &mut SceneHashes) {}

    fn prepare_frame(
        &mut self,
        worker: &mut SceneHashes,
        start: FrameStart,
    ) -> (Result<(), FrameError>, f64) {
        let mut seconds = self.costs.worker_setup;
        if !worker.prepared.contains(&start.scene) {
            worker.prepared.push(start.scene);
            seconds += self.costs.scene_prepare;
        }
        (Ok(()), seconds)
    }

    /// A recorded frame has one stage: `_stage` is 0.
    fn run_package(
        &mut self,
        _: &mut SceneHashes,
        package: &Package,
        _stage: usize,
    ) -> PackageWork {
        let indices: Vec<usize> = (package.triangles.iter())
            .filter_map(|t| self.index_of.get(t).copied())
            .collect();
        let costs = self.costs;
        let traced: f64 = indices.iter().map(|&i| costs.seconds[i]).sum();
        let (seconds, bytes) = match &package.whole {
            // Finished here: the master's work on a split frame, on the
            // worker, which converts the whole frame once, after its
            // tracing (`vtfarm_render::Renderer::finish_frame`: its base
            // frame is made then, so there is nothing to convert ahead).
            Some(_) => {
                let master = &costs.master;
                let finish = master.base_frame
                    + master.result_per_item * indices.len() as f64
                    + master.frame_out
                    + master.frame_out_serial
                    + master.frame_sent;
                (
                    traced + finish,
                    costs.empty_result_bytes + costs.frame_bytes,
                )
            }
            None => {
                let bytes = costs.empty_result_bytes
                    + indices.iter().map(|&i| costs.result_bytes[i]).sum::<u64>();
                (traced, bytes)
            }
        };
        let samples = indices.iter().map(|&i| costs.samples[i]).collect();
        PackageWork {
            result: stand_in_result(package, self.empty_bitmap.clone(), samples),
            seconds,
            wire_bytes: Some(bytes),
            failure: None,
        }
    }

    fn master_costs(&self) -> MasterCosts {
        self.costs.master
    }
}

/// Steps before a run counts as livelocked.
const MAX_STEPS: u64 = 50_000_000;

/// A run to its end: the frames delivered, each worker's package runs,
/// and the virtual time it ended.
struct FinishedRun {
    frames: Vec<FarmFrame>,
    busy: Vec<Vec<PackageRun>>,
    end: Duration,
}

/// Runs `job` on a farm of `workers` until every frame is delivered.
fn run_farm(
    job: &FarmJob,
    costs: &FarmCosts,
    config: &SimulationConfig,
    workers: &[WorkerSpec],
) -> Result<FinishedRun, SimulationError> {
    let scene = SceneData::from_scene(&job.scene);
    let model = Recorded {
        costs,
        index_of: (costs.items.iter().enumerate())
            .map(|(i, &t)| (t, i))
            .collect(),
        empty_bitmap: WireBitmap::encode(&SparseBitmap::default(), WireBitmapParts::Color),
        held: config.workers_hold_scene.then_some(scene.hash),
    };
    let machines = FarmConfig {
        master_link_bits_per_second: config.master_link_bits_per_second,
        master_cores: config.master_cores,
        shared_cores: config.shared_cores,
        background_threads: config.background_threads,
        submitter_latency: Duration::ZERO,
    };
    let mut farm = Farm::with_model(model, machines, config.rules.clone(), None);
    for (w, spec) in workers.iter().enumerate() {
        farm.join(&format!("w{w}"), spec.clone());
    }
    let frames = config.frames as usize;
    let wire = WireJob {
        name: "simulated".into(),
        scene: JobScene::Hash(scene.hash),
        frames: vec![WireFrameSetup::from(&job.setup); frames],
        reflectors: wire_triangles(&job.reflectors),
        aux: false,
        method: MethodKind::VertexTracing.into(),
        // As `vtfarm submit` asks (it writes only PNGs): what the
        // recorded encoding costs are of.
        image: WireImageFormat::Srgb8,
        priority: 0,
        kind: vtfarm_proto::WireJobKind::Render,
    };
    farm.submit(wire, scene);
    let mut delivered = |f: &Farm<Recorded>| f.deliveries.len() >= frames;
    let finished = farm.drive_bounded(config.time_limit, MAX_STEPS, &mut delivered);
    if !finished {
        return Err(SimulationError::Unfinished {
            delivered: farm.deliveries.len(),
            frames,
            at: farm.now,
        });
    }
    let frames = (farm.deliveries.iter())
        .map(|d| FarmFrame {
            started_at: d.started_at,
            done_at: d.done_at,
            completed_at: d.completed_at,
            imbalance: 0.0,
            share_after_first_delivery: 0.0,
            index: d.index,
            background_cpu: d.background_cpu,
            cpu: d.cpu.clone(),
            stats: d.stats.clone(),
        })
        .collect();
    Ok(FinishedRun {
        frames,
        busy: farm.busy,
        end: farm.now,
    })
}

/// Simulates `job` on `workers` and returns its finished frames in order.
pub fn simulate_farm(
    job: &FarmJob,
    costs: &FarmCosts,
    config: &SimulationConfig,
    workers: &[WorkerSpec],
) -> Result<Vec<FarmFrame>, SimulationError> {
    let FinishedRun {
        mut frames,
        busy,
        end,
    } = run_farm(job, costs, config, workers)?;
    let first_delivery = frames.first().map_or(end, |f| f.done_at);
    for frame in &mut frames {
        frame.imbalance = window_imbalance(&busy, frame.started_at, frame.done_at, end);
        let index = frame.index;
        let runs = busy.iter().flatten().filter(|r| r.frame == index);
        let (after, all) = runs.fold((0.0, 0.0), |(after, all), r| {
            let share = r.share_within(first_delivery, end, end);
            (after + r.work * share, all + r.work)
        });
        frame.share_after_first_delivery = if all > 0.0 { after / all } else { 0.0 };
    }
    Ok(frames)
}

/// A package run's time within a window.
trait Within {
    fn within(&self, from: Duration, to: Duration, end: Duration) -> f64;
    fn share_within(&self, from: Duration, to: Duration, end: Duration) -> f64;
}

impl Within for PackageRun {
    /// Seconds of it within `[from, to]` (running until `end` if it still runs).
    fn within(&self, from: Duration, to: Duration, end: Duration) -> f64 {
        let (start, stop) = (self.start.max(from), self.end.unwrap_or(end).min(to));
        stop.saturating_sub(start).as_secs_f64()
    }

    /// The share of it within `[from, to]`.
    fn share_within(&self, from: Duration, to: Duration, end: Duration) -> f64 {
        let length = self
            .end
            .unwrap_or(end)
            .saturating_sub(self.start)
            .as_secs_f64();
        if length > 0.0 {
            self.within(from, to, end) / length
        } else {
            f64::from(u8::from(self.start >= from))
        }
    }
}

/// `(max − mean) / mean` of each worker's package time within
/// `[from, to]` (packages still running at `end` run until then); 0 when
/// nobody traced.
fn window_imbalance(busy: &[Vec<PackageRun>], from: Duration, to: Duration, end: Duration) -> f64 {
    let within: Vec<f64> = (busy.iter())
        .map(|runs| runs.iter().map(|r| r.within(from, to, end)).sum())
        .collect();
    let mean = within.iter().sum::<f64>() / within.len().max(1) as f64;
    let max = within.iter().copied().fold(0.0, f64::max);
    if mean > 0.0 { (max - mean) / mean } else { 0.0 }
}

/// The other work on a shared machine that uses `cores` cores on average
/// beside the farm of `workers` (over the window `steady_background_cores`
/// measures): the number of always-runnable threads, found by bisection
/// (more threads get more of the machine). 0 for 0 cores.
pub fn background_threads_for(
    job: &FarmJob,
    costs: &FarmCosts,
    config: &SimulationConfig,
    workers: &[WorkerSpec],
    cores: f64,
) -> Result<f64, SimulationError> {
    if cores <= 0.0 {
        return Ok(0.0);
    }
    let used = |threads: f64| -> Result<f64, SimulationError> {
        let config = SimulationConfig {
            background_threads: threads,
            ..config.clone()
        };
        Ok(steady_background_cores(&simulate_farm(
            job, costs, &config, workers,
        )?))
    };
    let (mut low, mut high) = (0.0, 1.0);
    while used(high)? < cores {
        (low, high) = (high, high * 2.0);
        if high > 1024.0 {
            return Err(SimulationError::NoBackground { cores });
        }
    }
    // To 1/1000 of a thread or better.
    while high - low > 1e-3 * high.max(1.0) {
        let middle = (low + high) / 2.0;
        if used(middle)? < cores {
            low = middle;
        } else {
            high = middle;
        }
    }
    Ok((low + high) / 2.0)
}

#[cfg(test)]
mod tests {
    use vtfarm_cockpit::{CockpitConfig, cockpit};
    use vtfarm_render::morton_order;

    use super::*;

    /// A small cockpit job and costs: every item 10 ms, 2 samples, 100 bytes.
    fn small_farm(worker_setup: f64, base_frame: f64) -> (FarmJob, FarmCosts) {
        let c = cockpit(&CockpitConfig {
            detail: 0.2,
            ..CockpitConfig::default()
        });
        let reflectors = c.cover_glass_triangles();
        let items = wire_triangles(&morton_order(&c.scene, reflectors.clone()));
        let n = items.len();
        let job = FarmJob {
            scene: Arc::new(c.scene),
            reflectors,
            setup: FrameSetup {
                camera: vtfarm_scene::Camera {
                    width: 32,
                    height: 18,
                    ..c.camera
                },
                lighting: c.lighting,
                trace: Default::default(),
                vertex: Default::default(),
            },
        };
        let costs = FarmCosts {
            items,
            seconds: vec![0.01; n],
            samples: vec![2; n],
            result_bytes: vec![100; n],
            empty_result_bytes: 30,
            frame_bytes: 1000,
            worker_setup,
            scene_prepare: 0.0,
            master: MasterCosts {
                base_frame,
                ..MasterCosts::default()
            },
        };
        (job, costs)
    }

    fn config(frames: u32) -> SimulationConfig {
        SimulationConfig {
            master_link_bits_per_second: 1e9,
            master_cores: 1,
            shared_cores: None,
            background_threads: 0.0,
            frames,
            time_limit: Duration::from_secs(3600),
            workers_hold_scene: false,
            // The tests of the split frames' cost model; whole frames have
            // theirs.
            rules: FarmRules {
                whole_frames: false,
                ..FarmRules::default()
            },
        }
    }

    fn workers(n: usize) -> Vec<WorkerSpec> {
        let worker = WorkerSpec {
            speed: 1.0,
            link_bits_per_second: 1e9,
            latency: Duration::from_micros(100),
            package_overhead: Duration::from_millis(1),
            cores: 1,
        };
        vec![worker; n]
    }

    fn frame_times(frames: &[FarmFrame]) -> Vec<Duration> {
        frames.iter().map(|f| f.done_at).collect()
    }

    /// The steady frame time can never beat the work: pipelined frames
    /// that finish in a bunch (a straggler holds frame 0 while the next
    /// frames' work is done) would make the mean interval between
    /// deliveries near 0 s and the efficiency above 100%. Over
    /// farms of 1 to 24 workers, equal and mixed speeds, 2 to 5 frames:
    /// frame time × summed speed ≥ one thread's work per frame, and every
    /// frame's imbalance is finite and not negative.
    #[test]
    fn the_steady_frame_time_never_beats_the_work() {
        let (job, mut costs) = small_farm(0.02, 0.01);
        // Uneven items, one of them a tenth of the frame: bunching needs
        // a long last package.
        let n = costs.items.len();
        costs.seconds = (0..n).map(|i| 0.002 + 0.004 * (i % 5) as f64).collect();
        costs.seconds[n / 2] = costs.seconds.iter().sum::<f64>() / 10.0;
        let work: f64 = costs.seconds.iter().sum();
        let mut old_measure_beat_the_work = false;
        for count in [1usize, 2, 5, 8, 24] {
            for mixed in [false, true] {
                for frames in 2..=5 {
                    let speeds: Vec<f64> = (0..count)
                        .map(|k| if mixed && k % 2 == 1 { 0.5 } else { 1.0 })
                        .collect();
                    let farm: Vec<WorkerSpec> = (workers(count).into_iter().zip(&speeds))
                        .map(|(w, &speed)| WorkerSpec { speed, ..w })
                        .collect();
                    let run = simulate_farm(&job, &costs, &config(frames), &farm).unwrap();
                    let ideal: f64 = speeds.iter().sum();
                    let steady = steady_frame_seconds(&run);
                    assert!(
                        steady * ideal >= work,
                        "{count} workers (mixed {mixed}), {frames} frames: {steady} s per frame, work {work} s over {ideal}"
                    );
                    let first = run[0].done_at.as_secs_f64();
                    let last = run[run.len() - 1].done_at.as_secs_f64();
                    let old = (last - first) / (run.len() - 1) as f64;
                    old_measure_beat_the_work |= old * ideal < work;
                    for frame in &run {
                        assert!(frame.imbalance.is_finite() && frame.imbalance >= 0.0);
                        assert!(frame.started_at <= frame.done_at);
                    }
                }
            }
        }
        assert!(
            old_measure_beat_the_work,
            "the sweep no longer shows the bunching"
        );
    }

    /// A finished split frame is encoded beside the master's driver, as
    /// the real driver does it on a blocking thread: while frame N's image
    /// is encoded, the driver goes on handing out and taking in frame
    /// N+1's packages, so an encoding as long as half a frame's tracing on
    /// the farm costs the split frames little (on the driver it added
    /// itself to every frame; what is left is the last frame's, after the
    /// tracing), and the master's CPU still counts it.
    #[test]
    fn a_frames_encoding_does_not_hold_the_next_split_frame() {
        let (job, mut costs) = small_farm(0.0, 0.0);
        let farm = workers(4);
        let traced = costs.seconds.iter().sum::<f64>() / farm.len() as f64;
        let without =
            steady_frame_seconds(&simulate_farm(&job, &costs, &config(16), &farm).unwrap());
        // The finished frame's part (the job is in sRGB: the whole
        // frame's conversion went with its base frame).
        costs.master.frame_out_written = traced / 2.0;
        let frames = simulate_farm(&job, &costs, &config(16), &farm).unwrap();
        let with = steady_frame_seconds(&frames);
        assert!(
            with < without + 0.2 * costs.master.frame_out_written,
            "{with} s per frame with {} s of encoding, {without} s without",
            costs.master.frame_out_written
        );
        let master = frames.last().unwrap().cpu[0];
        let encoding = frames.len() as f64 * costs.master.frame_out_written;
        assert!(
            (master - encoding).abs() < 1e-9,
            "master {master} s, encoding {encoding} s"
        );
    }

    /// A worker's first frame of the scene costs it the scene's
    /// preparation beside the set-up, after the scene came over the link;
    /// workers that hold the scene prepared get no transfer and no
    /// preparation: their frame is delivered sooner by at least the
    /// preparation, and the master sends no scene.
    #[test]
    fn workers_holding_the_scene_skip_its_transfer_and_preparation() {
        let (job, mut costs) = small_farm(0.01, 0.0);
        costs.scene_prepare = 0.3;
        let run = |hold: bool| {
            let config = SimulationConfig {
                workers_hold_scene: hold,
                // Slow enough that the scene's transfer shows.
                master_link_bits_per_second: 1e7,
                ..config(1)
            };
            let mut spec = workers(4);
            for w in &mut spec {
                w.link_bits_per_second = 1e7;
            }
            let frames = simulate_farm(&job, &costs, &config, &spec).unwrap();
            let cpu: f64 = frames[0].cpu[1..5].iter().sum();
            (frames[0].done_at.as_secs_f64(), cpu)
        };
        let ((cold, cold_cpu), (held, held_cpu)) = (run(false), run(true));
        let items: f64 = costs.seconds.iter().sum();
        let setups = 4.0 * costs.worker_setup;
        let overheads = |cpu: f64| cpu - items - setups;
        // Package overheads aside, the cold workers spent one preparation each more.
        assert!(
            (overheads(cold_cpu) - overheads(held_cpu) - 4.0 * costs.scene_prepare).abs() < 0.05,
            "cold {cold_cpu} s of CPU, held {held_cpu} s"
        );
        let scene = SceneData::from_scene(&job.scene).bytes.len() as f64 * 8.0 / 1e7;
        assert!(
            cold > held + costs.scene_prepare + scene,
            "cold {cold} s, held {held} s, the scene {scene} s on the link"
        );
    }

    /// A single frame's encoding, the master's serial work after its last
    /// result, runs its parallel part (the sRGB conversion of the pixels
    /// results wrote) on every core of the master: on two cores the frame
    /// is delivered half that part sooner than on one, and its serial part
    /// takes as long on both.
    #[test]
    fn a_single_frames_encoding_spreads_over_the_masters_cores() {
        let (job, mut costs) = small_farm(0.0, 0.0);
        costs.master.frame_out_serial = 0.05;
        let latency = |parallel: f64, cores: u32| {
            let mut costs = costs.clone();
            costs.master.frame_out_written = parallel;
            let config = SimulationConfig {
                master_cores: cores,
                ..config(1)
            };
            let frames = simulate_farm(&job, &costs, &config, &workers(4)).unwrap();
            frames[0].done_at.as_secs_f64()
        };
        let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
        for cores in [1, 2] {
            let none = latency(0.0, cores);
            let with = latency(0.2, cores);
            let expected = none + 0.2 / f64::from(cores);
            assert!(
                close(with, expected),
                "{cores} cores: {with} s, not {expected} s"
            );
        }
    }

    /// A job whose frames go out in sRGB has its base frame converted with
    /// its rasterizing, while the workers trace: the whole frame's
    /// conversion still costs the master's CPU but does not stand
    /// between the frame's last result and its delivery, where only the
    /// conversion of the pixels results wrote is left.
    #[test]
    fn a_split_frame_converts_only_its_written_pixels_after_the_last_result() {
        let (job, costs) = small_farm(0.0, 0.0);
        let cores = 2;
        let farm = workers(4);
        let run = |whole: f64, written: f64| {
            let mut costs = costs.clone();
            costs.master.frame_out = whole;
            costs.master.frame_out_written = written;
            let config = SimulationConfig {
                master_cores: cores,
                ..config(1)
            };
            let frames = simulate_farm(&job, &costs, &config, &farm).unwrap();
            (frames[0].done_at.as_secs_f64(), frames[0].cpu[0])
        };
        let (whole, written) = (0.2, 0.02);
        // The base frame and its conversion are over before the tracing.
        let traced = costs.seconds.iter().sum::<f64>() / farm.len() as f64;
        assert!(whole / f64::from(cores) < traced / 2.0, "{traced} s traced");
        let (none, none_cpu) = run(0.0, 0.0);
        let (ahead, ahead_cpu) = run(whole, 0.0);
        let (delivered, cpu) = run(whole, written);
        let close = |a: f64, b: f64| (a - b).abs() < 1e-6;
        assert!(close(ahead, none), "{ahead} s, {none} s with no conversion");
        let expected = none + written / f64::from(cores);
        assert!(
            close(delivered, expected),
            "{delivered} s, not {expected} s"
        );
        // The whole conversion after the last result would come later.
        assert!(delivered < none + whole / f64::from(cores) - 0.05);
        assert!(close(ahead_cpu - none_cpu, whole), "{ahead_cpu} s of CPU");
        assert!(close(cpu - none_cpu, whole + written), "{cpu} s of CPU");
    }

    /// Same inputs, same frames at the same virtual times; every frame is
    /// delivered with every item traced once.
    #[test]
    fn the_farm_is_deterministic_and_delivers_every_frame() {
        let (job, costs) = small_farm(0.05, 0.05);
        let run = || simulate_farm(&job, &costs, &config(4), &workers(3)).unwrap();
        let (a, b) = (run(), run());
        assert_eq!(a.len(), 4);
        assert_eq!(frame_times(&a), frame_times(&b));
        for frame in &a {
            let items: u32 = frame.stats.workers.iter().map(|w| w.triangles).sum();
            assert_eq!(items as usize, costs.items.len());
        }
    }

    /// The load balancer spreads the work: with no fixed costs, four workers
    /// make the frames nearly four times as fast as one.
    #[test]
    fn four_workers_without_fixed_costs_are_nearly_four_times_as_fast() {
        let (job, costs) = small_farm(0.0, 0.0);
        let interval = |n| {
            steady_frame_seconds(&simulate_farm(&job, &costs, &config(6), &workers(n)).unwrap())
        };
        let (one, four) = (interval(1), interval(4));
        let work: f64 = costs.seconds.iter().sum();
        assert!(one >= work, "one worker: {one} s for {work} s of work");
        assert!(one / four > 3.2, "one {one} s, four {four} s");
    }

    /// On one shared core, a second worker only shares it: no faster; and
    /// the master's base frame takes from the workers too.
    #[test]
    fn workers_on_one_shared_core_are_no_faster() {
        let (job, costs) = small_farm(0.02, 0.0);
        let shared = SimulationConfig {
            shared_cores: Some(1),
            ..config(5)
        };
        let interval = |config: &SimulationConfig, n| {
            steady_frame_seconds(&simulate_farm(&job, &costs, config, &workers(n)).unwrap())
        };
        let (one, two) = (interval(&shared, 1), interval(&shared, 2));
        assert!(two > one * 0.95, "one {one} s, two {two} s");
        let (job_base, costs_base) = small_farm(0.02, 0.5);
        let with_base = steady_frame_seconds(
            &simulate_farm(&job_base, &costs_base, &shared, &workers(1)).unwrap(),
        );
        assert!(
            with_base > one + 0.4,
            "without base {one} s, with {with_base} s"
        );
    }

    /// A worker with two cores traces its packages on both; its set-up of
    /// frame N+1 overlaps only the last package of frame N (the master
    /// announces N+1 once N has nothing left to hand out, and late packages
    /// are small), so the frame takes about set-up + work / 2.
    #[test]
    fn a_second_core_halves_the_tracing_but_not_the_set_up() {
        let (job, costs) = small_farm(0.3, 0.0);
        let work: f64 = costs.seconds.iter().sum();
        let interval = |cores| {
            let workers: Vec<WorkerSpec> = (workers(1).into_iter())
                .map(|w| WorkerSpec { cores, ..w })
                .collect();
            steady_frame_seconds(&simulate_farm(&job, &costs, &config(8), &workers).unwrap())
        };
        let (one, two) = (interval(1), interval(2));
        assert!(one >= work + 0.3 * 0.99, "one core: {one} s");
        let serial = 0.3 + work / 2.0;
        assert!(
            two > serial * 0.97 && two < serial * 1.03,
            "two cores: {two} s, {serial} s serial"
        );
    }

    /// Other work on a shared core takes its share: one always-runnable
    /// thread beside a lone worker (nothing else costs CPU) halves the
    /// worker's speed while it traces, so the frame takes about twice its
    /// work, and that thread gets about half the core (all of it in the
    /// gaps while messages travel).
    #[test]
    fn other_work_on_a_shared_core_takes_its_share() {
        let (job, costs) = small_farm(0.0, 0.0);
        let work: f64 = costs.seconds.iter().sum();
        let shared = |background_threads| SimulationConfig {
            shared_cores: Some(1),
            background_threads,
            ..config(6)
        };
        let idle = simulate_farm(&job, &costs, &shared(0.0), &workers(1)).unwrap();
        let busy = simulate_farm(&job, &costs, &shared(1.0), &workers(1)).unwrap();
        assert_eq!(steady_background_cores(&idle), 0.0);
        let (idle_s, busy_s) = (steady_frame_seconds(&idle), steady_frame_seconds(&busy));
        assert!(idle_s < work * 1.1, "idle {idle_s} s for {work} s of work");
        assert!(
            busy_s > 1.9 * work && busy_s < 2.2 * work,
            "with other work {busy_s} s for {work} s of work"
        );
        let other = steady_background_cores(&busy);
        assert!(other > 0.5 && other < 0.55, "other work got {other} cores");
        // Without a shared machine there is nothing to share.
        let own = SimulationConfig {
            background_threads: 1.0,
            ..config(6)
        };
        let frames = simulate_farm(&job, &costs, &own, &workers(1)).unwrap();
        assert_eq!(steady_background_cores(&frames), 0.0);
    }

    /// The other work that a real run measured (cores) is found as the
    /// threads that use as much beside the simulated farm; more measured
    /// cores, more threads, and a slower frame.
    #[test]
    fn the_measured_other_work_is_matched_by_threads() {
        let (job, costs) = small_farm(0.02, 0.05);
        let shared = SimulationConfig {
            shared_cores: Some(2),
            ..config(6)
        };
        let farm = workers(2);
        let mut last = (0.0, 0.0);
        for cores in [0.3, 0.9, 1.5] {
            let threads = background_threads_for(&job, &costs, &shared, &farm, cores).unwrap();
            let config = SimulationConfig {
                background_threads: threads,
                ..shared.clone()
            };
            let frames = simulate_farm(&job, &costs, &config, &farm).unwrap();
            let used = steady_background_cores(&frames);
            assert!(
                (used - cores).abs() < 0.01 * cores,
                "{threads} threads used {used} of {cores} cores"
            );
            let seconds = steady_frame_seconds(&frames);
            assert!(
                threads > last.0 && seconds > last.1,
                "{cores} cores: {threads} threads, {seconds} s"
            );
            last = (threads, seconds);
        }
        let none = background_threads_for(&job, &costs, &shared, &farm, 0.0);
        assert_eq!(none.unwrap(), 0.0);
    }

    /// The CPU each simulated process has used by the last delivery is the
    /// costs it was given: the master its base frame, compositing and
    /// finished frame for every frame and the journal for all but the last
    /// (it starts at the delivery); the submitter its part likewise; the
    /// workers all the items and one set-up per frame each worker traced
    /// in. Its own machines, so nothing is shared.
    #[test]
    fn each_process_uses_the_cpu_of_its_costs() {
        let (job, mut costs) = small_farm(0.02, 0.05);
        costs.master = MasterCosts {
            result_per_item: 1e-4,
            frame_out: 0.003,
            frame_out_written: 0.0007,
            frame_out_serial: 0.0005,
            frame_sent: 0.001,
            journal: 0.002,
            ..costs.master
        };
        costs.master.submitter = 0.004;
        let farm: Vec<WorkerSpec> = (workers(2).into_iter())
            .map(|w| WorkerSpec {
                package_overhead: Duration::ZERO,
                ..w
            })
            .collect();
        let frames = simulate_farm(&job, &costs, &config(8), &farm).unwrap();
        let cpu = &frames.last().unwrap().cpu;
        assert_eq!(cpu.len(), 4, "master, two workers, submitter");
        let (n, items) = (frames.len() as f64, costs.items.len() as f64);
        let m = &costs.master;
        // The whole frame's sRGB conversion with the base frame, the
        // written pixels' with the finished frame.
        let per_frame = m.base_frame
            + m.result_per_item * items
            + m.frame_out
            + m.frame_out_written
            + m.frame_out_serial
            + m.frame_sent;
        let master = n * per_frame + (n - 1.0) * m.journal;
        let close = |a: f64, b: f64| (a - b).abs() < 1e-9 * b.max(1.0);
        assert!(
            close(cpu[0], master),
            "master {} s, costs {master} s",
            cpu[0]
        );
        assert!(
            close(cpu[3], (n - 1.0) * costs.master.submitter),
            "submitter {} s",
            cpu[3]
        );
        let work = n * costs.seconds.iter().sum::<f64>();
        let setups = (cpu[1] + cpu[2] - work) / costs.worker_setup;
        assert!(
            (setups - setups.round()).abs() < 1e-6 && (n..=2.0 * n).contains(&setups.round()),
            "workers {} s: {setups} set-ups",
            cpu[1] + cpu[2]
        );
        // Per frame over the steady window: about the same.
        let per_frame = cpu_per_frame(&frames);
        assert!((per_frame[0] - master / n).abs() < 0.1 * master / n);
    }

    /// The submitter takes finished frames one at a time, as the real one
    /// does: when a round of whole frames finishes together it falls
    /// behind on one core instead of taking every core of the master's
    /// machine (which starved the driver of a 256-worker farm). Between any
    /// two deliveries its CPU grows by at most the time between them.
    #[test]
    fn the_submitter_takes_finished_frames_one_at_a_time() {
        let (job, mut costs) = small_farm(0.0, 0.0);
        let whole_frame: f64 = costs.seconds.iter().sum();
        // Eight frames finishing together bring two frames' worth of work.
        costs.master.submitter = whole_frame / 4.0;
        let batch = SimulationConfig {
            master_cores: 2,
            rules: FarmRules::default(),
            ..config(24)
        };
        assert!(batch.rules.whole_frames);
        let frames = simulate_farm(&job, &costs, &batch, &workers(8)).unwrap();
        let submitter = |f: &FarmFrame| *f.cpu.last().unwrap();
        let (first, last) = (&frames[0], frames.last().unwrap());
        let (cpu, wall) = (
            submitter(last) - submitter(first),
            (last.done_at - first.done_at).as_secs_f64(),
        );
        assert!(cpu <= wall + 1e-9, "{cpu} s of CPU in {wall} s");
        // It stayed busy: one core's worth, not less.
        assert!(cpu > 0.9 * wall, "{cpu} s of CPU in {wall} s");
    }

    /// A slow shared master link bounds the frame: results can come no
    /// faster than their bytes through it.
    #[test]
    fn a_slow_master_link_bounds_the_frame() {
        let (job, mut costs) = small_farm(0.0, 0.0);
        costs.result_bytes = vec![20_000; costs.items.len()];
        let slow = SimulationConfig {
            master_link_bits_per_second: 10e6,
            ..config(4)
        };
        let frames = simulate_farm(&job, &costs, &slow, &workers(8)).unwrap();
        let bytes: u64 = costs.result_bytes.iter().sum();
        let link = bytes as f64 * 8.0 / 10e6;
        let interval = steady_frame_seconds(&frames);
        assert!(
            interval >= link,
            "{interval} s per frame, the link needs {link} s"
        );
        assert!(
            interval < link * 1.5,
            "{interval} s per frame, the link needs {link} s"
        );
    }

    /// The one link model: a result crosses the worker's link and the
    /// master's together, at the slower rate, not one after the other.
    /// Two equal 10 Mbit/s links, one worker, nothing else costing time:
    /// the frame takes the results' bytes over 10 Mbit/s once (sending
    /// over one link and then forwarding over the other would take twice
    /// that); a slower worker link is the one that counts.
    /// Whole frames (the master's rules): the master's CPU per frame is
    /// only the journal's (no base frame, compositing or encoding: the
    /// worker does them, the same costs on its clock), and a frame's
    /// result on the wire is the finished frame.
    #[test]
    fn a_whole_frame_costs_the_master_only_its_forwarding() {
        let (job, mut costs) = small_farm(0.02, 0.05);
        costs.master = MasterCosts {
            result_per_item: 1e-4,
            frame_out: 0.003,
            journal: 0.002,
            ..costs.master
        };
        let whole = SimulationConfig {
            rules: FarmRules::default(),
            ..config(8)
        };
        let frames = simulate_farm(&job, &costs, &whole, &workers(1)).unwrap();
        let n = frames.len() as f64;
        let cpu = &frames.last().unwrap().cpu;
        let m = &costs.master;
        // Frame 7 (the last) starts with one frame left on one worker: split.
        let split = m.base_frame + m.result_per_item * costs.items.len() as f64 + m.frame_out;
        let master = split + (n - 1.0) * m.journal;
        assert!(
            (cpu[0] - master).abs() < 1e-9,
            "master {} s, {master} s expected",
            cpu[0]
        );
        // The worker paid the whole frames' finishing: 7 of them.
        let work: f64 = costs.seconds.iter().sum();
        assert!(
            cpu[1] > n * (work + costs.worker_setup) + 7.0 * split * 0.99,
            "{cpu:?}"
        );
    }

    /// Frames go out in order, so on a farm of a fast and a slow worker
    /// the fast one's whole frames wait for the slow one's and leave in a
    /// bunch; `completed_at` is when each one's work was done: never after
    /// its delivery, and for the held frames well before it (what a steady
    /// rate is measured over: scripts/lab.sh).
    #[test]
    fn a_held_frame_completes_before_its_delivery() {
        let (job, costs) = small_farm(0.02, 0.05);
        let whole = SimulationConfig {
            rules: FarmRules::default(),
            ..config(12)
        };
        let mut farm = workers(2);
        farm[1].speed = 0.2;
        let frames = simulate_farm(&job, &costs, &whole, &farm).unwrap();
        let work: f64 = costs.seconds.iter().sum();
        assert!(frames.iter().all(|f| f.completed_at <= f.done_at));
        let held = (frames.iter())
            .filter(|f| (f.done_at - f.completed_at).as_secs_f64() > work)
            .count();
        assert!(held >= 2, "{held} frames held for a slower one");
        let mut completed: Vec<Duration> = frames.iter().map(|f| f.completed_at).collect();
        completed.sort();
        assert_ne!(completed, frame_times(&frames), "no frame was held");
    }

    #[test]
    fn a_message_holds_both_links_at_the_slower_rate() {
        let (job, mut costs) = small_farm(0.0, 0.0);
        costs.seconds = vec![0.0; costs.items.len()];
        costs.result_bytes = vec![20_000; costs.items.len()];
        let bytes: u64 = costs.result_bytes.iter().sum();
        let frame_seconds = |worker_rate: f64| {
            let config = SimulationConfig {
                master_link_bits_per_second: 10e6,
                ..config(4)
            };
            let farm: Vec<WorkerSpec> = (workers(1).into_iter())
                .map(|w| WorkerSpec {
                    link_bits_per_second: worker_rate,
                    package_overhead: Duration::ZERO,
                    ..w
                })
                .collect();
            steady_frame_seconds(&simulate_farm(&job, &costs, &config, &farm).unwrap())
        };
        let once = bytes as f64 * 8.0 / 10e6;
        let equal = frame_seconds(10e6);
        assert!(
            equal >= once && equal < 1.2 * once,
            "{equal} s per frame, the bytes need {once} s on one link"
        );
        let slow_worker = frame_seconds(5e6);
        assert!(
            slow_worker >= 2.0 * once && slow_worker < 2.4 * once,
            "{slow_worker} s per frame at 5 Mbit/s, the bytes need {} s",
            2.0 * once
        );
    }
}
