//! The simulated farm behind `vtfarm bench simulate`: the master's own
//! sans-IO core ([`MasterCore`]) and the workers' own sessions
//! ([`WorkerSession`]) on a virtual clock, with the CPU work and the links
//! modelled. Every decision — which frame starts when, which requests count,
//! package sizes, held results, stragglers — is made by the same code as in
//! the real farm; only the work and the wires are replaced by their costs.
//!
//! Model:
//! - **CPU.** Each machine has cores shared fairly by its running jobs (a job
//!   runs on one core at most): a worker with one core that sets a frame up
//!   (its blocking thread) while it traces a package runs both at half speed,
//!   as the real worker does. The master has its own machine
//!   ([`FarmConfig::master_cores`]): its base frame is spread over those
//!   cores (the rasterizer is parallel), and its driver handles one input at
//!   a time, each costing CPU (a result: [`FarmCosts::result_per_item`] per
//!   item; a finished frame: [`FarmCosts::frame_out`]); inputs queue
//!   meanwhile. With [`FarmConfig::shared_cores`] everything runs on one
//!   machine (a localhost farm), so the master takes CPU from the workers,
//!   and [`FarmConfig::background_threads`] stand for other work on that
//!   machine (always runnable, each sharing the cores like a job of the
//!   farm's).
//! - **Work.** A package costs the recorded one-thread seconds of its items
//!   over the worker's speed, plus a fixed overhead; a frame's set-up
//!   [`FarmCosts::worker_setup`] over the speed. Results carry each item's
//!   recorded samples (what the master's cost estimates learn from) and an
//!   empty bitmap; their size on the wire is the recorded one.
//! - **Links.** Each worker's link and the master's one shared link, each a
//!   rate (a message occupies both for its size over the slower rate) plus a
//!   latency. The submitter sits on the master's machine: its messages cost
//!   nothing on the links, its handling of each finished frame
//!   ([`FarmCosts::submitter`]) CPU there.
//! - **Accounting.** Each process's CPU (master, workers, submitter) and the
//!   other work's are kept at every delivery ([`cpu_per_frame`],
//!   [`steady_background_cores`]), to set beside what a real run's
//!   processes used (`scripts/scaling.sh` reads /proc).
//!
//! The master core rasterizes for real, but at a tiny resolution (the base
//! frame's *time* is modelled): the images do not matter here.

use std::collections::{BTreeMap, HashMap};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Result, bail};
use vtfarm_master::FarmRules;
use vtfarm_master::{JobOptions, MasterCore, Output, Peer, wire_job};
use vtfarm_method::MethodKind;
use vtfarm_proto::{
    FrameStats, JobScene, Message, PackageResult, SceneData, SceneHash, WireBitmap,
    WireBitmapParts, WirePackageStats, encoded_len,
};
use vtfarm_render::FrameSetup;
use vtfarm_scene::Scene;
use vtfarm_vertex::SparseBitmap;
use vtfarm_worker::{SceneStore, Task, WorkerSession};

/// What the work costs: per item (reflector triangle, in the master's
/// Morton order) and per frame, in one-thread seconds of this machine.
#[derive(Clone, Debug)]
pub(crate) struct FarmCosts {
    /// The work items (reflector triangle ids) in the master's order.
    pub(crate) items: Vec<u32>,
    /// Tracing seconds per item.
    pub(crate) seconds: Vec<f64>,
    /// Traced samples per item (what a result reports).
    pub(crate) samples: Vec<u32>,
    /// Bytes per item of a result beyond a message's fixed part.
    pub(crate) result_bytes: Vec<u64>,
    /// A result message's fixed part.
    pub(crate) empty_result_bytes: u64,
    /// A worker's set-up of a frame.
    pub(crate) worker_setup: f64,
    /// The master's base frame on one thread.
    pub(crate) base_frame: f64,
    /// The master's driver per item of a result (decode, check, composite).
    pub(crate) result_per_item: f64,
    /// The master's driver per finished frame (the image for the wire).
    pub(crate) frame_out: f64,
    /// The master's journal thread per finished frame (compress, write):
    /// beside the driver, on the master's cores.
    pub(crate) journal: f64,
    /// The submitter per finished frame (decode, PNG, timeline), on the
    /// master's machine.
    pub(crate) submitter: f64,
}

/// One simulated worker.
#[derive(Clone, Debug)]
pub(crate) struct FarmWorker {
    /// Work per second of one thread (1: one thread of the recording machine).
    pub(crate) speed: f64,
    /// Cores of its machine: a package uses them all (the tracer is
    /// parallel), a frame's set-up one (so it overlaps a package on a
    /// spare core). Ignored on a shared machine (one core's worth each).
    pub(crate) cores: u32,
    pub(crate) link_bits_per_second: f64,
    pub(crate) latency: Duration,
    /// Fixed time per package.
    pub(crate) package_overhead: Duration,
}

/// The farm around the workers.
#[derive(Clone, Debug)]
pub(crate) struct FarmConfig {
    /// The master's shared link, bits per second each way.
    pub(crate) master_link_bits_per_second: f64,
    /// Cores of the master's machine.
    pub(crate) master_cores: u32,
    /// Everything on one machine of this many cores (a localhost farm):
    /// workers, master and its base frames share them.
    pub(crate) shared_cores: Option<u32>,
    /// Other work on the shared machine: this many threads that always want
    /// to run and share its cores fairly with the farm's jobs (a fraction
    /// runs part of the time). Ignored without [`FarmConfig::shared_cores`].
    pub(crate) background_threads: f64,
    /// Frames of the job.
    pub(crate) frames: u32,
    /// Gives up at this virtual time.
    pub(crate) time_limit: Duration,
}

/// A finished frame as the submitter got it.
#[derive(Clone, Debug)]
pub(crate) struct FarmFrame {
    /// When the master announced the frame (its first `FrameStart` sent):
    /// none of its work, set-ups included, can start earlier.
    pub(crate) started_at: Duration,
    /// When the master's driver sent it.
    pub(crate) done_at: Duration,
    /// Load imbalance over the frame's lifetime (`started_at` to
    /// `done_at`): `(max − mean) / mean` of every worker's time spent on
    /// packages in that window, whichever frame they belonged to (with
    /// pipelined frames a worker's share of one frame says nothing of its
    /// idle time). A worker idle throughout counts with 0; 0 when no
    /// worker traced.
    pub(crate) imbalance: f64,
    /// The share of the frame's traced work done after the first frame's
    /// delivery.
    pub(crate) share_after_first_delivery: f64,
    /// The frame's index in its job.
    pub(crate) index: u32,
    /// CPU seconds the other work ([`FarmConfig::background_threads`]) had
    /// got by the frame's delivery.
    pub(crate) background_cpu: f64,
    /// CPU seconds each process had used by the frame's delivery: the
    /// master (driver, base frames, journal), each worker, the submitter.
    pub(crate) cpu: Vec<f64>,
    pub(crate) stats: FrameStats,
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
pub(crate) fn steady_frame_seconds(frames: &[FarmFrame]) -> f64 {
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
pub(crate) fn steady_background_cores(frames: &[FarmFrame]) -> f64 {
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
pub(crate) fn cpu_per_frame(frames: &[FarmFrame]) -> Vec<f64> {
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
pub(crate) struct FarmJob {
    pub(crate) scene: Arc<Scene>,
    pub(crate) reflectors: Vec<u32>,
    pub(crate) setup: FrameSetup,
}

/// One package run on a worker.
#[derive(Clone, Debug)]
struct PackageRun {
    start: Duration,
    /// `None` while it runs.
    end: Option<Duration>,
    frame: u32,
    /// Its items' one-thread seconds.
    work: f64,
}

/// Connection of the submitter; workers get 1, 2, ...
const SUBMITTER: u64 = 1_000_000;

/// Simulates `job` on `workers` and returns its finished frames in order.
pub(crate) fn simulate_farm(
    job: &FarmJob,
    costs: &FarmCosts,
    config: &FarmConfig,
    workers: &[FarmWorker],
) -> Result<Vec<FarmFrame>> {
    let mut farm = Farm::new(job, costs, config, workers);
    farm.run()?;
    if farm.frames.len() != config.frames as usize {
        bail!(
            "the simulated farm finished {} of {} frames by {:?} of virtual time",
            farm.frames.len(),
            config.frames,
            farm.now
        );
    }
    let end = farm.now;
    let mut frames = farm.frames;
    let first_delivery = frames.first().map_or(end, |f| f.done_at);
    for frame in &mut frames {
        frame.imbalance = window_imbalance(&farm.busy, frame.started_at, frame.done_at, end);
        let index = frame.index;
        let runs = farm.busy.iter().flatten().filter(|r| r.frame == index);
        let (after, all) = runs.fold((0.0, 0.0), |(after, all), r| {
            let share = r.share_within(first_delivery, end, end);
            (after + r.work * share, all + r.work)
        });
        frame.share_after_first_delivery = if all > 0.0 { after / all } else { 0.0 };
    }
    Ok(frames)
}

impl PackageRun {
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

/// Who a CPU job belongs to; its completion is handled accordingly.
#[derive(Clone, Debug)]
enum Work {
    Setup {
        worker: usize,
        key: (u64, u32),
    },
    Package {
        worker: usize,
        result: Box<PackageResult>,
        started: Duration,
        bytes: u64,
    },
    /// One core's share of a base frame.
    Base {
        job: u64,
        frame: u32,
    },
    /// The driver's handling of an input: its outputs go out when done.
    Driver(Vec<Output>),
    /// Work that only takes CPU (the journal's).
    Background,
    /// The submitter's handling of a finished frame: only takes CPU.
    Submitter,
}

impl Work {
    /// Whose CPU it is, of a farm of `workers`: 0 the master's, `w + 1`
    /// worker `w`'s, `workers + 1` the submitter's.
    fn owner(&self, workers: usize) -> usize {
        match self {
            Work::Setup { worker, .. } | Work::Package { worker, .. } => worker + 1,
            Work::Base { .. } | Work::Driver(_) | Work::Background => 0,
            Work::Submitter => workers + 1,
        }
    }
}

struct CpuJob {
    machine: usize,
    /// Cores it can use at once.
    threads: u32,
    /// CPU seconds left.
    left: f64,
    work: Work,
}

/// A timed event.
enum Event {
    ToMaster(u64, Box<Message>),
    ToWorker(usize, Box<Message>),
}

/// An input waiting for the master's driver.
enum DriverInput {
    Message(u64, Box<Message>),
    Base(u64, u32),
}

struct SimStore {
    scenes: Vec<SceneHash>,
}

impl SceneStore for SimStore {
    fn has_scene(&mut self, hash: &SceneHash) -> bool {
        self.scenes.contains(hash)
    }

    type Error = std::convert::Infallible;

    fn add_scene(&mut self, data: SceneData) -> Result<(), Self::Error> {
        self.scenes.push(data.hash);
        Ok(())
    }
}

struct Worker {
    spec: FarmWorker,
    session: WorkerSession,
    store: SimStore,
    /// When its link is free, towards the master and from it.
    link_free: [Duration; 2],
}

struct Farm<'a> {
    costs: &'a FarmCosts,
    config: &'a FarmConfig,
    now: Duration,
    master: MasterCore,
    workers: Vec<Worker>,
    /// Cores per machine: the master's is 0, worker `w`'s is `w + 1`
    /// (all 0 on a shared machine).
    cores: Vec<u32>,
    cpu: Vec<CpuJob>,
    events: BTreeMap<(Duration, u64), Event>,
    sequence: u64,
    /// When the master's link is free, towards the workers and from them.
    master_link_free: [Duration; 2],
    driver_queue: std::collections::VecDeque<DriverInput>,
    driver_busy: bool,
    /// Base-frame shares still running, per frame.
    base_left: BTreeMap<(u64, u32), u32>,
    /// Items of results that arrived before their frame's base image.
    held_items: BTreeMap<(u64, u32), usize>,
    base_ready: Vec<(u64, u32)>,
    /// Base frames being "rasterized", to hand to the core when done.
    pending_base: BTreeMap<(u64, u32), vtfarm_master::BaseFrameRequest>,
    /// Each package's frame, for the held results.
    package_frames: BTreeMap<u64, (u64, u32)>,
    index_of: HashMap<u32, usize>,
    empty_bitmap: WireBitmap,
    scene: SceneData,
    scene_bytes: u64,
    frames: Vec<FarmFrame>,
    /// When each frame was first announced to a worker.
    frame_started: BTreeMap<u32, Duration>,
    /// Per worker, its packages on the virtual clock.
    busy: Vec<Vec<PackageRun>>,
    /// CPU seconds the other work on the shared machine has got so far.
    background_cpu: f64,
    /// CPU seconds used so far, by owner (see [`Work::owner`]).
    cpu_used: Vec<f64>,
}

impl<'a> Farm<'a> {
    fn new(
        job: &FarmJob,
        costs: &'a FarmCosts,
        config: &'a FarmConfig,
        specs: &[FarmWorker],
    ) -> Farm<'a> {
        let scene = SceneData::from_scene(&job.scene);
        let scene_bytes = encoded_len(&Message::SceneData(scene.clone()));
        let cores = match config.shared_cores {
            Some(c) => vec![c.max(1)],
            None => std::iter::once(config.master_cores.max(1))
                .chain(specs.iter().map(|w| w.cores.max(1)))
                .collect(),
        };
        let mut farm = Farm {
            costs,
            config,
            now: Duration::ZERO,
            master: MasterCore::new(FarmRules::default()),
            workers: Vec::new(),
            cores,
            cpu: Vec::new(),
            events: BTreeMap::new(),
            sequence: 0,
            master_link_free: [Duration::ZERO; 2],
            driver_queue: Default::default(),
            driver_busy: false,
            base_left: BTreeMap::new(),
            held_items: BTreeMap::new(),
            base_ready: Vec::new(),
            pending_base: BTreeMap::new(),
            package_frames: BTreeMap::new(),
            index_of: (costs.items.iter().enumerate())
                .map(|(i, &t)| (t, i))
                .collect(),
            empty_bitmap: WireBitmap::encode(&SparseBitmap::default(), WireBitmapParts::Color),
            scene,
            scene_bytes,
            frames: Vec::new(),
            frame_started: BTreeMap::new(),
            busy: vec![Vec::new(); specs.len()],
            background_cpu: 0.0,
            cpu_used: vec![0.0; specs.len() + 2],
        };
        let peer = Peer::Submitter {
            address: "simulated".into(),
        };
        farm.master.connected(farm.now, SUBMITTER, peer);
        for (w, spec) in specs.iter().enumerate() {
            farm.workers.push(Worker {
                spec: spec.clone(),
                session: WorkerSession::new(Duration::ZERO),
                store: SimStore { scenes: Vec::new() },
                link_free: [Duration::ZERO; 2],
            });
            let peer = Peer::Worker {
                name: format!("w{w}"),
                threads: 1,
                address: "simulated".into(),
            };
            farm.master.connected(farm.now, w as u64 + 1, peer);
        }
        let frames = vec![job.setup.clone(); config.frames as usize];
        let wire = wire_job(
            "simulated",
            &farm.scene,
            &frames,
            &job.reflectors,
            JobOptions {
                method: MethodKind::VertexTracing,
                aux: false,
            },
        );
        let wire = vtfarm_proto::WireJob {
            scene: JobScene::Data(farm.scene.clone()),
            ..wire
        };
        farm.master
            .message(farm.now, SUBMITTER, Message::SubmitJob { job: wire });
        farm.route_master_outputs();
        farm
    }

    fn machine_of_worker(&self, w: usize) -> usize {
        if self.config.shared_cores.is_some() {
            0
        } else {
            w + 1
        }
    }

    /// Other threads that always want to run on `machine`.
    fn background_threads(&self, machine: usize) -> f64 {
        match self.config.shared_cores {
            Some(_) if machine == 0 => self.config.background_threads.max(0.0),
            _ => 0.0,
        }
    }

    /// Each running job's speed on its machine (its threads, all slowed
    /// alike when the machine has fewer cores than threads want to run),
    /// and the other work's (cores it gets).
    fn rates(&self) -> (Vec<f64>, f64) {
        let mut wanted: Vec<f64> = (0..self.cores.len())
            .map(|m| self.background_threads(m))
            .collect();
        for job in &self.cpu {
            wanted[job.machine] += f64::from(job.threads);
        }
        let share = |m: usize| (f64::from(self.cores[m]) / wanted[m]).min(1.0);
        let jobs = (self.cpu.iter())
            .map(|j| f64::from(j.threads) * share(j.machine))
            .collect();
        let background = self.background_threads(0);
        (
            jobs,
            if background > 0.0 {
                background * share(0)
            } else {
                0.0
            },
        )
    }

    fn run(&mut self) -> Result<()> {
        let mut steps: u64 = 0;
        while self.frames.len() < self.config.frames as usize {
            steps += 1;
            if steps > 50_000_000 || self.now > self.config.time_limit {
                bail!(
                    "the simulated farm did not finish (virtual time {:?})",
                    self.now
                );
            }
            let (rates, background_rate) = self.rates();
            let cpu_next = (self.cpu.iter().zip(&rates))
                .enumerate()
                .map(|(i, (j, r))| (j.left.max(0.0) / r, i))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            let event_at = self.events.keys().next().map(|k| k.0);
            let master_at = self.master.poll_timeout();
            let session_at = (self.workers.iter().enumerate())
                .map(|(w, x)| (x.session.poll_timeout(), w))
                .min();
            let cpu_at = cpu_next.map(|(dt, _)| self.now + Duration::from_secs_f64(dt));
            let next = [event_at, master_at, session_at.map(|s| s.0), cpu_at]
                .into_iter()
                .flatten()
                .min();
            let Some(next) = next else {
                bail!("the simulated farm stalled at {:?}", self.now);
            };
            let next = next.max(self.now);
            let dt = (next - self.now).as_secs_f64();
            let workers = self.workers.len();
            for (job, rate) in self.cpu.iter_mut().zip(&rates) {
                job.left -= dt * rate;
                self.cpu_used[job.work.owner(workers)] += dt * rate;
            }
            self.background_cpu += dt * background_rate;
            self.now = next;
            if cpu_at == Some(next) {
                let (_, i) = cpu_next.expect("a CPU job is due");
                let job = self.cpu.swap_remove(i);
                self.finish(job.work);
            } else if event_at == Some(next) {
                let (_, event) = self.events.pop_first().expect("an event is due");
                match event {
                    Event::ToMaster(conn, message) => {
                        self.queue_for_driver(DriverInput::Message(conn, message))
                    }
                    Event::ToWorker(w, message) => {
                        let worker = &mut self.workers[w];
                        worker
                            .session
                            .handle_message(next, *message, &mut worker.store);
                        self.pump_worker(w);
                    }
                }
            } else if master_at == Some(next) {
                self.master.handle_timeout(next);
                self.route_master_outputs();
            } else if let Some((_, w)) = session_at {
                self.workers[w].session.handle_timeout(next);
                self.pump_worker(w);
            }
        }
        Ok(())
    }

    fn schedule(&mut self, at: Duration, event: Event) {
        self.events.insert((at, self.sequence), event);
        self.sequence += 1;
    }

    /// Starts `seconds` of one-thread work on `machine`, on one thread.
    fn start_cpu(&mut self, machine: usize, seconds: f64, work: Work) {
        self.start_threads(machine, 1, seconds, work);
    }

    fn start_threads(&mut self, machine: usize, threads: u32, seconds: f64, work: Work) {
        self.cpu.push(CpuJob {
            machine,
            threads: threads.max(1),
            left: seconds.max(0.0),
            work,
        });
    }

    /// A message of `bytes` over worker `w`'s link and the master's link,
    /// `to_master` or from it: when it arrives.
    fn transfer(&mut self, w: usize, bytes: u64, to_master: bool) -> Duration {
        let direction = usize::from(to_master);
        let worker = &mut self.workers[w];
        let rate = (worker.spec.link_bits_per_second).min(self.config.master_link_bits_per_second);
        let start = (self.now)
            .max(worker.link_free[direction])
            .max(self.master_link_free[direction]);
        let end = start + Duration::from_secs_f64(bytes as f64 * 8.0 / rate);
        worker.link_free[direction] = end;
        self.master_link_free[direction] = end;
        end + worker.spec.latency
    }

    fn finish(&mut self, work: Work) {
        match work {
            Work::Setup { worker, key } => {
                self.workers[worker]
                    .session
                    .frame_prepared(self.now, key, Ok(()));
                self.pump_worker(worker);
            }
            Work::Package {
                worker,
                mut result,
                started,
                bytes,
            } => {
                result.busy_micros = (self.now - started).as_micros() as u64;
                let open =
                    (self.busy[worker].iter_mut()).rfind(|r| r.start == started && r.end.is_none());
                if let Some(run) = open {
                    run.end = Some(self.now);
                }
                let id = result.id;
                let session = &mut self.workers[worker].session;
                session.package_finished(self.now, id, Ok(*result));
                self.pump_worker_sized(worker, Some(bytes));
            }
            Work::Base { job, frame } => {
                let left = self.base_left.entry((job, frame)).or_insert(1);
                *left -= 1;
                if *left == 0 {
                    self.base_left.remove(&(job, frame));
                    self.queue_for_driver(DriverInput::Base(job, frame));
                }
            }
            Work::Driver(outputs) => {
                self.driver_busy = false;
                for output in outputs {
                    self.release(output);
                }
                self.next_driver_input();
            }
            Work::Background | Work::Submitter => {}
        }
    }

    fn queue_for_driver(&mut self, input: DriverInput) {
        self.driver_queue.push_back(input);
        if !self.driver_busy {
            self.next_driver_input();
        }
    }

    /// Hands the driver's next input to the core; its outputs go out once
    /// the driver's CPU time for it has passed.
    fn next_driver_input(&mut self) {
        let Some(input) = self.driver_queue.pop_front() else {
            return;
        };
        let mut seconds = 0.0;
        match input {
            DriverInput::Message(conn, message) => {
                if let Message::PackageResult(result) = message.as_ref() {
                    let items = result.triangle_samples.len();
                    seconds += self.costs.result_per_item * items as f64;
                    if let Some(&key) = self.package_frames.get(&result.id) {
                        if !self.base_ready.contains(&key) {
                            *self.held_items.entry(key).or_default() += items;
                        }
                    }
                }
                self.master.message(self.now, conn, *message);
            }
            DriverInput::Base(job, frame) => {
                self.base_ready.push((job, frame));
                let held = self.held_items.remove(&(job, frame)).unwrap_or(0);
                seconds += self.costs.result_per_item * held as f64;
                // The tiny stand-in image: the time was modelled.
                let request = self.pending_base.remove(&(job, frame));
                if let Some(request) = request {
                    let base = request.rasterize();
                    self.master.base_frame_ready(self.now, job, frame, base);
                }
            }
        }
        let mut outputs = Vec::new();
        while let Some(output) = self.master.poll_output() {
            if let Output::Send(_, message) = &output {
                if matches!(message.as_ref(), Message::FrameDone(_)) {
                    seconds += self.costs.frame_out;
                }
            }
            outputs.push(output);
        }
        self.driver_busy = true;
        self.start_cpu(0, seconds, Work::Driver(outputs));
    }

    /// Outputs of a core call made outside the driver's queue (timeouts).
    fn route_master_outputs(&mut self) {
        while let Some(output) = self.master.poll_output() {
            self.release(output);
        }
    }

    fn release(&mut self, output: Output) {
        match output {
            Output::Send(SUBMITTER, message) => match *message {
                Message::FrameDone(done) => {
                    let started_at = self.frame_started.get(&done.frame).copied();
                    self.frames.push(FarmFrame {
                        started_at: started_at.unwrap_or(self.now),
                        done_at: self.now,
                        imbalance: 0.0,
                        share_after_first_delivery: 0.0,
                        index: done.frame,
                        background_cpu: self.background_cpu,
                        cpu: self.cpu_used.clone(),
                        stats: done.stats,
                    });
                    self.start_cpu(0, self.costs.journal, Work::Background);
                    self.start_cpu(0, self.costs.submitter, Work::Submitter);
                }
                Message::SceneRequest { .. } => {
                    let data = Message::SceneData(self.scene.clone());
                    self.schedule(self.now, Event::ToMaster(SUBMITTER, Box::new(data)));
                }
                _ => {}
            },
            Output::Send(conn, message) => {
                let w = (conn - 1) as usize;
                match message.as_ref() {
                    Message::Package(p) => {
                        self.package_frames.insert(p.id, (p.job, p.frame));
                    }
                    Message::FrameStart(start) => {
                        self.frame_started.entry(start.frame).or_insert(self.now);
                    }
                    _ => {}
                }
                let bytes = match message.as_ref() {
                    Message::SceneData(_) => self.scene_bytes,
                    m => encoded_len(m),
                };
                let at = self.transfer(w, bytes, false);
                self.schedule(at, Event::ToWorker(w, message));
            }
            Output::RasterizeBase(request) => {
                let key = (request.job, request.frame);
                let shares = self.cores[0];
                self.base_left.insert(key, shares);
                self.pending_base.insert(key, request);
                let seconds = self.costs.base_frame / f64::from(shares);
                for _ in 0..shares {
                    let work = Work::Base {
                        job: key.0,
                        frame: key.1,
                    };
                    self.start_cpu(0, seconds, work);
                }
            }
            Output::Close(..) | Output::Persist(_) | Output::Replay { .. } => {}
        }
    }

    fn pump_worker(&mut self, w: usize) {
        self.pump_worker_sized(w, None);
    }

    /// Starts worker `w`'s tasks and sends its messages (a result at
    /// `result_bytes`, its recorded size).
    fn pump_worker_sized(&mut self, w: usize, result_bytes: Option<u64>) {
        let machine = self.machine_of_worker(w);
        while let Some(task) = self.workers[w].session.poll_task() {
            let speed = self.workers[w].spec.speed;
            match task {
                Task::PrepareFrame(start) => {
                    let key = (start.job, start.frame);
                    let seconds = self.costs.worker_setup / speed;
                    self.start_cpu(machine, seconds, Work::Setup { worker: w, key });
                }
                Task::RunPackage(package) => {
                    let indices: Vec<usize> = (package.triangles.iter())
                        .filter_map(|t| self.index_of.get(t).copied())
                        .collect();
                    let work: f64 = indices.iter().map(|&i| self.costs.seconds[i]).sum();
                    let overhead = self.workers[w].spec.package_overhead.as_secs_f64();
                    let bytes = self.costs.empty_result_bytes
                        + (indices.iter())
                            .map(|&i| self.costs.result_bytes[i])
                            .sum::<u64>();
                    let result = PackageResult {
                        id: package.id,
                        bitmap: self.empty_bitmap.clone(),
                        stats: WirePackageStats::default(),
                        busy_micros: 0,
                        setup_micros: 0,
                        triangle_samples: indices.iter().map(|&i| self.costs.samples[i]).collect(),
                    };
                    let package_work = Work::Package {
                        worker: w,
                        result: Box::new(result),
                        started: self.now,
                        bytes,
                    };
                    let threads = match self.config.shared_cores {
                        Some(_) => 1,
                        None => self.workers[w].spec.cores.max(1),
                    };
                    let seconds = (work + overhead) / speed;
                    self.busy[w].push(PackageRun {
                        start: self.now,
                        end: None,
                        frame: package.frame,
                        work,
                    });
                    self.start_threads(machine, threads, seconds, package_work);
                }
            }
        }
        while let Some(message) = self.workers[w].session.poll_message() {
            let bytes = match (&message, result_bytes) {
                (Message::PackageResult(_), Some(bytes)) => bytes,
                _ => encoded_len(&message),
            };
            let at = self.transfer(w, bytes, true);
            self.schedule(at, Event::ToMaster(w as u64 + 1, Box::new(message)));
        }
    }
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
        let items = morton_order(&c.scene, reflectors.clone());
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
            worker_setup,
            base_frame,
            result_per_item: 0.0,
            frame_out: 0.0,
            journal: 0.0,
            submitter: 0.0,
        };
        (job, costs)
    }

    fn config(frames: u32) -> FarmConfig {
        FarmConfig {
            master_link_bits_per_second: 1e9,
            master_cores: 1,
            shared_cores: None,
            background_threads: 0.0,
            frames,
            time_limit: Duration::from_secs(3600),
        }
    }

    fn workers(n: usize) -> Vec<FarmWorker> {
        let worker = FarmWorker {
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
    /// frames' work is done) made the old measure, the mean interval
    /// between deliveries, near 0 s and the efficiency above 100%. Over
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
                    let farm: Vec<FarmWorker> = (workers(count).into_iter().zip(&speeds))
                        .map(|(w, &speed)| FarmWorker { speed, ..w })
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
        let shared = FarmConfig {
            shared_cores: Some(1),
            ..config(5)
        };
        let interval = |config: &FarmConfig, n| {
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
            let workers: Vec<FarmWorker> = (workers(1).into_iter())
                .map(|w| FarmWorker { cores, ..w })
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
        let shared = |background_threads| FarmConfig {
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
        let own = FarmConfig {
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
        let shared = FarmConfig {
            shared_cores: Some(2),
            ..config(6)
        };
        let farm = workers(2);
        let mut last = (0.0, 0.0);
        for cores in [0.3, 0.9, 1.5] {
            let threads =
                crate::simulate::background_threads_for(&job, &costs, &shared, &farm, cores)
                    .unwrap();
            let config = FarmConfig {
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
        let none = crate::simulate::background_threads_for(&job, &costs, &shared, &farm, 0.0);
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
        costs.result_per_item = 1e-4;
        costs.frame_out = 0.003;
        costs.journal = 0.002;
        costs.submitter = 0.004;
        let farm: Vec<FarmWorker> = (workers(2).into_iter())
            .map(|w| FarmWorker {
                package_overhead: Duration::ZERO,
                ..w
            })
            .collect();
        let frames = simulate_farm(&job, &costs, &config(8), &farm).unwrap();
        let cpu = &frames.last().unwrap().cpu;
        assert_eq!(cpu.len(), 4, "master, two workers, submitter");
        let (n, items) = (frames.len() as f64, costs.items.len() as f64);
        let master = n * (costs.base_frame + costs.result_per_item * items + costs.frame_out)
            + (n - 1.0) * costs.journal;
        let close = |a: f64, b: f64| (a - b).abs() < 1e-9 * b.max(1.0);
        assert!(
            close(cpu[0], master),
            "master {} s, costs {master} s",
            cpu[0]
        );
        assert!(
            close(cpu[3], (n - 1.0) * costs.submitter),
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

    /// A slow shared master link bounds the frame: results can come no
    /// faster than their bytes through it.
    #[test]
    fn a_slow_master_link_bounds_the_frame() {
        let (job, mut costs) = small_farm(0.0, 0.0);
        costs.result_bytes = vec![20_000; costs.items.len()];
        let slow = FarmConfig {
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
}
