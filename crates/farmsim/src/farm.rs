//! The driver: one event loop over the real [`MasterCore`] and
//! [`WorkerSession`]s on a virtual clock. It routes the core's `Output`s and
//! the sessions' tasks and messages exactly as the real drivers do, hands
//! the work to a [`CostModel`], holds each message on the links for its
//! modelled time (`Farm::transfer`) and shares each machine's cores among
//! its running CPU jobs. Fault knobs (kills, partitions, duplicated results,
//! draining, master restarts, submitter loss) act on the same loop.

use std::collections::{BTreeMap, BTreeSet, HashMap, VecDeque};
use std::time::Duration;
use vtfarm_proto::JobId;

use vtfarm_master_core::view::GlareRequest;
use vtfarm_master_core::{
    BaseFrameRequest, ConnId, DamagedJob, EncodedFrame, FarmRules, FrameEncodeRequest, MasterCore,
    Output, Peer, Record, StoredJob, Written,
};
use vtfarm_proto::{
    FrameDone, FrameKey, FrameStart, FrameStats, JobRow, JobScene, Message, Package, PackageResult,
    ResultPixels, SceneData, WireBitmap, WireImage, WireJob, WireMesh, WirePackageStats, WireStudy,
    encoded_len,
};
use vtfarm_worker::engine::{FrameError, PackageError};
use vtfarm_worker::{SceneStore, SessionEnd, Task, WorkerSession};

/// What the work of a farm costs and gives: the pluggable cost model.
/// Seconds are one-thread CPU seconds of a worker of speed 1.
pub trait CostModel {
    /// A worker's own state beside its session: its scene store, its
    /// prepared frames.
    type Worker: SceneStore;

    /// A new worker's state.
    fn new_worker(&mut self) -> Self::Worker;

    /// The worker's session starts anew: its prepared frames are gone (its
    /// scene cache stays).
    fn reconnected(&mut self, worker: &mut Self::Worker);

    /// Sets a frame up: the outcome the session hears and its CPU seconds.
    fn prepare_frame(
        &mut self,
        worker: &mut Self::Worker,
        start: FrameStart,
    ) -> (Result<(), FrameError>, f64);

    /// The corner mesh a worker sends ahead of setting up frame `start`
    /// (`FrameParts::corner_mesh`: a view's frame), if the model makes one.
    fn corner_mesh(&mut self, _worker: &mut Self::Worker, _start: &FrameStart) -> Option<WireMesh> {
        None
    }

    /// Runs stage `stage` of a package of a prepared frame (0 unless the
    /// frame is progressive; see `vtfarm_worker::Task::RunPackage`).
    fn run_package(
        &mut self,
        worker: &mut Self::Worker,
        package: &Package,
        stage: usize,
    ) -> PackageWork;

    /// What the master's machine spends.
    fn master_costs(&self) -> MasterCosts;

    /// Drops what the model records of the worker's work for the tests
    /// ([`Farm::forget_records`]).
    fn forget_records(&mut self, _worker: &mut Self::Worker) {}

    /// The worker's session keeps only the frames `keeps` accepts
    /// (`WorkerSession::keeps_set_up`): a model that holds prepared frames
    /// lets the others go, as the real driver does.
    fn retain_frames(&mut self, _worker: &mut Self::Worker, _keeps: &dyn Fn(FrameKey) -> bool) {}
}

/// A package's outcome under a [`CostModel`].
pub struct PackageWork {
    /// The result the session reports (the farm sets `busy_micros`).
    pub result: PackageResult,
    /// Its CPU seconds (before the worker's speed and overhead).
    pub seconds: f64,
    /// Its result's size on the wire (`None`: the encoded message's).
    pub wire_bytes: Option<u64>,
    /// The package fails after its seconds with this error instead of
    /// giving `result` (a worker's fault, for the tests of retries).
    pub failure: Option<PackageError>,
}

/// A modelled package's result: stand-in pixels (a black whole frame in
/// its job's image format, or `bitmap` for a split frame's package) and
/// `triangle_samples`, the cost the load balancer learns.
pub fn stand_in_result(
    package: &Package,
    bitmap: WireBitmap,
    triangle_samples: Vec<u32>,
) -> PackageResult {
    let pixels = match &package.whole {
        Some(start) => {
            let camera = &start.setup.camera;
            let black = vtfarm_imaging::Image::black(camera.width, camera.height);
            ResultPixels::Frame {
                image: WireImage::encode(&black, start.image),
                aux: None,
            }
        }
        None => ResultPixels::Bitmap(bitmap),
    };
    PackageResult {
        id: package.id,
        pixels,
        stats: WirePackageStats::default(),
        busy_micros: 0,
        setup_micros: 0,
        triangle_samples,
        stage: None,
        mesh: None,
    }
}

/// CPU seconds the master's machine spends, one thread each. A whole frame
/// (batch work) costs the master none of `base_frame`, `result_per_item`
/// and `frame_out`: its worker rasterizes, composites and encodes it (the
/// same functions, the whole frame converted once), and the driver only
/// forwards it. A split frame's `frame_out` runs beside the driver
/// (`Output::EncodeFrame`), as the real driver runs it on a blocking
/// thread. A job whose frames go out in sRGB has its base frames
/// converted with their rasterizing (`BaseFrameRequest::converts_to_srgb`:
/// `frame_out` there) and its finished split frames convert only the
/// pixels results wrote (`frame_out_written`).
#[derive(Clone, Copy, Debug, Default)]
pub struct MasterCosts {
    /// A split frame's base frame (spread over the master's cores: the
    /// rasterizer is parallel).
    pub base_frame: f64,
    /// The driver per item of a split frame's result (decode, check, composite).
    pub result_per_item: f64,
    /// A whole frame's sRGB conversion, spread over the master's cores
    /// (`Image::to_srgb8_into` converts on all): with the base frame when
    /// it converts it ahead, else per finished split frame, beside the
    /// driver, its image for the wire's parallel part...
    pub frame_out: f64,
    /// ... or that of the pixels results wrote (the reflectors' rectangle)
    /// when the base frame came converted...
    pub frame_out_written: f64,
    /// ... and then its part on one thread (zstd).
    pub frame_out_serial: f64,
    /// Per finished split frame, on the driver once it is encoded: the
    /// `FrameDone` for the submitter and the telemetry's copy (serial).
    pub frame_sent: f64,
    /// The journal thread per finished frame, beside the driver.
    pub journal: f64,
    /// The submitter per finished frame (decode, PNG, timeline), on the
    /// master's machine.
    pub submitter: f64,
}

impl MasterCosts {
    /// A finished split frame's sRGB conversion, the parallel part of its
    /// encoding: only the written pixels' where its base frame came
    /// converted.
    fn frame_conversion(&self, request: &FrameEncodeRequest) -> f64 {
        if request.converts_written_pixels_only() {
            self.frame_out_written
        } else {
            self.frame_out
        }
    }
}

/// A worker's machine and link.
#[derive(Clone, Debug)]
pub struct WorkerSpec {
    /// Work per second of one thread (1: one thread of the recording machine).
    pub speed: f64,
    /// Cores of its machine: a package uses them all (the tracer is
    /// parallel), a frame's set-up one (so it overlaps a package on a
    /// spare core). Ignored on a shared machine (one core's worth each).
    pub cores: u32,
    /// Its link's rate, bits per second each way (infinite: latency only).
    pub link_bits_per_second: f64,
    /// Its link's one-way latency.
    pub latency: Duration,
    /// Fixed CPU time per package.
    pub package_overhead: Duration,
}

/// The machines around the workers.
#[derive(Clone, Debug)]
pub struct FarmConfig {
    /// The master's shared link, bits per second each way.
    pub master_link_bits_per_second: f64,
    /// Cores of the master's machine.
    pub master_cores: u32,
    /// Everything on one machine of this many cores (a localhost farm):
    /// workers, master and its base frames share them.
    pub shared_cores: Option<u32>,
    /// Other work on the shared machine: this many threads that always want
    /// to run and share its cores fairly with the farm's jobs (a fraction
    /// runs part of the time). Ignored without [`FarmConfig::shared_cores`].
    pub background_threads: f64,
    /// Delay of the submitter's messages to the master (it sits on the
    /// master's machine, off the links).
    pub submitter_latency: Duration,
}

/// Where a finished frame's record keeping goes: the master's job journal.
pub trait JobJournal {
    /// Keeps `record`; `Err` with the error's text when the write failed.
    fn write(&self, record: Record) -> Result<(), String>;
    /// A kept finished frame; `Err` with the reason when it cannot be read.
    fn frame(&self, job: JobId, frame: u32) -> Result<FrameDone, String>;
    /// Every kept unfinished job, for a restarted master, and the jobs set
    /// aside as damaged.
    fn load(&self) -> (Vec<StoredJob>, Vec<DamagedJob>);
    /// Every kept study (restored after the jobs, its variants among them).
    fn load_studies(&self) -> Vec<JobRow> {
        Vec::new()
    }
}

/// A finished frame as the submitter got it.
#[derive(Clone, Debug)]
pub struct Delivery {
    /// The frame's index in its job.
    pub index: u32,
    /// When the master announced the frame (its first `FrameStart` sent).
    pub started_at: Duration,
    /// When the master's driver sent it.
    pub done_at: Duration,
    /// When its last result reached the master's driver (`done_at` when
    /// none came: a replayed frame): frames are sent in order, so one
    /// finished early may wait after this for those before it.
    pub completed_at: Duration,
    /// CPU seconds the other work had got by then.
    pub background_cpu: f64,
    /// CPU seconds each process had used by then: the master (driver, base
    /// frames, journal), each worker, the submitter.
    pub cpu: Vec<f64>,
    pub stats: FrameStats,
}

/// One package run on a worker, on the virtual clock.
#[derive(Clone, Debug)]
pub struct PackageRun {
    pub start: Duration,
    /// `None` while it runs.
    pub end: Option<Duration>,
    /// Its job.
    pub job: JobId,
    /// Its frame's index.
    pub frame: u32,
    /// Its CPU seconds as the model gave them.
    pub work: f64,
}

/// Per-frame work of one thread that takes frames one at a time (the
/// master's journal thread, the submitter): as one CPU job per frame, 256
/// frames finished together would share the master's cores 512 ways and
/// starve its driver, which the real one-thread consumers never do.
#[derive(Debug, Default)]
struct OneThread {
    /// Frames not started yet.
    waiting: usize,
    /// Whether a frame's work runs.
    running: bool,
}

impl OneThread {
    /// A frame came: whether its work starts now (nothing runs).
    fn add(&mut self) -> bool {
        if self.running {
            self.waiting += 1;
            false
        } else {
            self.running = true;
            true
        }
    }

    /// A frame's work ended: whether the next one's starts.
    fn next(&mut self) -> bool {
        self.running = self.waiting > 0;
        self.waiting = self.waiting.saturating_sub(1);
        self.running
    }
}

/// A simulated worker: its machine, its fault knobs, its session and the
/// cost model's state of it.
pub struct SimWorker<W> {
    pub name: String,
    pub spec: WorkerSpec,
    /// Every message either way is lost while set.
    pub partitioned: bool,
    /// Each result reaches the master twice.
    pub duplicate_results: bool,
    /// Results this worker's sessions sent.
    pub results_sent: u32,
    /// The frames of the `FrameStart`s the master sent it, in order.
    pub frame_starts_got: Vec<(JobId, u32)>,
    conn: ConnId,
    /// Bumped on every (re)connection and loss, so old events are dropped.
    epoch: u64,
    session: Option<WorkerSession>,
    pub state: W,
    /// When its link is free, towards the master and from it.
    link_free: [Duration; 2],
}

impl<W> SimWorker<W> {
    /// Whether the worker is connected and holds a running package.
    pub fn is_running_a_package(&self) -> bool {
        self.session.as_ref().is_some_and(|s| s.running().is_some())
    }

    /// Whether the worker's session is up.
    pub fn is_connected(&self) -> bool {
        self.session.is_some()
    }

    /// The master's connection of its current session (for inputs from
    /// outside the model, as a test's injected message).
    pub fn conn(&self) -> ConnId {
        self.conn
    }
}

/// A timed event.
#[derive(Debug)]
enum Event {
    ToMaster(ConnId, Box<Message>),
    ToWorker(usize, u64, Box<Message>),
    /// A link closed (the master hears of it at once).
    Closed(ConnId),
}

/// Who a CPU job belongs to; its completion is handled accordingly.
enum Work {
    Setup {
        worker: usize,
        epoch: u64,
        key: (JobId, u32),
        outcome: Result<(), FrameError>,
    },
    Package {
        worker: usize,
        epoch: u64,
        result: Box<PackageResult>,
        failure: Option<PackageError>,
        started: Duration,
        bytes: Option<u64>,
    },
    /// One core's share of a base frame.
    Base((JobId, u32)),
    /// A finished split frame's encoding, beside the driver: its part on
    /// every core, then (`Some`: seconds) its part on one thread.
    Encode(Box<FrameEncodeRequest>, Option<f64>),
    /// The driver's handling of an input: its outputs go out when done.
    Driver(Vec<Output>),
    /// Work that only takes CPU (the journal's).
    Journal,
    /// The submitter's handling of a finished frame: only takes CPU.
    Submitter,
}

impl Work {
    fn worker(&self) -> Option<usize> {
        match self {
            Work::Setup { worker, .. } | Work::Package { worker, .. } => Some(*worker),
            _ => None,
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

/// An input waiting for the master's driver, which handles one at a time.
enum DriverInput {
    Message(ConnId, Box<Message>),
    Base((JobId, u32)),
    /// A finished frame encoded (costing the driver nothing more).
    Encoded(Box<EncodedFrame>),
    Closed(ConnId),
    /// The view's glare figures (costing nothing), after the stage is shown.
    Glare(Box<GlareRequest>),
}

/// The master, its workers and one submitter on a virtual clock.
pub struct Farm<M: CostModel> {
    pub master: MasterCore,
    pub now: Duration,
    pub workers: Vec<SimWorker<M::Worker>>,
    /// Everything the master sent the submitter, in order.
    pub to_submitter: Vec<Message>,
    /// Every frame a `FrameStart` announced, in order (a whole frame's
    /// with each of its packages).
    pub frame_starts: Vec<(JobId, u32)>,
    /// Every base frame the master asked for (job, frame), in order.
    pub base_frames: Vec<(JobId, u32)>,
    /// Base frames rasterized into a finished frame's buffers.
    pub bases_in_reused_buffers: usize,
    /// Each finished frame the submitter got, with its times and CPU.
    pub deliveries: Vec<Delivery>,
    /// Per worker, its packages on the virtual clock.
    pub busy: Vec<Vec<PackageRun>>,
    /// Steps taken so far (a bound against livelock).
    pub steps: u64,
    model: M,
    config: FarmConfig,
    rules: FarmRules,
    journal: Option<Box<dyn JobJournal>>,
    scene: Option<SceneData>,
    /// The submitter's current connection (`None` while it is away).
    submitter: Option<ConnId>,
    next_conn: ConnId,
    events: BTreeMap<(Duration, u64), Event>,
    next_seq: u64,
    /// Cores per machine: the master's is 0, worker `w`'s is `w + 1`
    /// (only 0 on a shared machine).
    cores: Vec<u32>,
    cpu: Vec<CpuJob>,
    /// When the master's link is free, towards the workers and from them.
    master_link_free: [Duration; 2],
    driver_queue: VecDeque<DriverInput>,
    driver_busy: bool,
    /// Finished frames for the master's journal thread and for the
    /// submitter: each takes them one at a time on one thread.
    journal_frames: OneThread,
    submitter_frames: OneThread,
    /// Base-frame shares still running, per frame.
    base_left: BTreeMap<(JobId, u32), u32>,
    /// Base frames being "rasterized", to hand to the core when done.
    pending_base: BTreeMap<(JobId, u32), BaseFrameRequest>,
    /// Frames whose base image is asked for and not ready yet.
    base_pending: BTreeSet<(JobId, u32)>,
    /// Items of results that arrived before their frame's base image.
    held_items: BTreeMap<(JobId, u32), usize>,
    /// Each package's frame, for the held results (until its result comes).
    package_frames: HashMap<u64, (JobId, u32)>,
    /// When each frame was first announced (until its delivery).
    frame_started: BTreeMap<(JobId, u32), Duration>,
    /// When each frame's latest result reached the driver (until its delivery).
    frame_last_result: BTreeMap<(JobId, u32), Duration>,
    /// CPU seconds the other work on the shared machine has got so far.
    background_cpu: f64,
    /// CPU seconds used so far: the master's, the submitter's.
    master_cpu: f64,
    submitter_cpu: f64,
    worker_cpu: Vec<f64>,
}

impl<M: CostModel> Farm<M> {
    /// A farm whose master runs `rules` (journaling into `journal`, when
    /// given), with a submitter connected and no workers.
    pub fn with_model(
        model: M,
        config: FarmConfig,
        rules: FarmRules,
        journal: Option<Box<dyn JobJournal>>,
    ) -> Farm<M> {
        let master = match journal {
            Some(_) => MasterCore::persistent(rules.clone()),
            None => MasterCore::new(rules.clone()),
        };
        let mut farm = Farm {
            master,
            now: Duration::ZERO,
            workers: Vec::new(),
            to_submitter: Vec::new(),
            frame_starts: Vec::new(),
            base_frames: Vec::new(),
            bases_in_reused_buffers: 0,
            deliveries: Vec::new(),
            busy: Vec::new(),
            steps: 0,
            cores: vec![config.shared_cores.unwrap_or(config.master_cores).max(1)],
            model,
            config,
            rules,
            journal,
            scene: None,
            submitter: None,
            next_conn: ConnId(1),
            events: BTreeMap::new(),
            next_seq: 0,
            cpu: Vec::new(),
            master_link_free: [Duration::ZERO; 2],
            driver_queue: VecDeque::new(),
            driver_busy: false,
            journal_frames: OneThread::default(),
            submitter_frames: OneThread::default(),
            base_left: BTreeMap::new(),
            pending_base: BTreeMap::new(),
            base_pending: BTreeSet::new(),
            held_items: BTreeMap::new(),
            package_frames: HashMap::new(),
            frame_started: BTreeMap::new(),
            frame_last_result: BTreeMap::new(),
            background_cpu: 0.0,
            master_cpu: 0.0,
            submitter_cpu: 0.0,
            worker_cpu: Vec::new(),
        };
        farm.connect_submitter();
        farm
    }

    /// The cost model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The cost model, to change between steps (a test's new costs).
    pub fn model_mut(&mut self) -> &mut M {
        &mut self.model
    }

    fn connect_submitter(&mut self) {
        let conn = self.next_conn;
        self.next_conn.0 += 1;
        self.submitter = Some(conn);
        let peer = Peer::Submitter {
            address: "simulated".into(),
        };
        self.master.connected(self.now, conn, peer);
    }

    /// The submitter's connection drops (the master hears of it at once).
    pub fn drop_submitter(&mut self) {
        if let Some(conn) = self.submitter.take() {
            self.master.disconnected(self.now, conn);
            self.route_master_outputs();
        }
    }

    /// A submitter connects and attaches to `job` from the first frame it lacks.
    pub fn attach_submitter(&mut self, job: JobId) {
        self.connect_submitter();
        let from_frame = self.frames_done().len() as u32;
        let conn = self.submitter.expect("just connected");
        self.master
            .message(self.now, conn, Message::AttachJob { job, from_frame });
        self.route_master_outputs();
    }

    /// Kills the master and starts a new one on the same journal: every
    /// connection is lost, the workers reconnect at once, the submitter
    /// stays away until it attaches again.
    pub fn restart_master(&mut self) {
        let journal = self.journal.as_ref().expect("a persistent farm");
        let (stored, damaged) = journal.load();
        self.master = MasterCore::persistent(self.rules.clone());
        self.events.clear();
        self.driver_queue.clear();
        self.driver_busy = false;
        self.journal_frames = OneThread::default();
        self.submitter_frames = OneThread::default();
        self.cpu.retain(|job| job.work.worker().is_some());
        self.base_left.clear();
        self.pending_base.clear();
        self.base_pending.clear();
        self.held_items.clear();
        self.package_frames.clear();
        self.submitter = None;
        for job in damaged {
            self.master.restore_damaged(job);
        }
        let studies = journal.load_studies();
        for job in stored {
            self.master.restore(self.now, job);
        }
        for study in studies {
            self.master.restore_study(self.now, study);
        }
        for w in 0..self.workers.len() {
            if self.workers[w].session.is_some() {
                self.connect(w);
            }
        }
        self.route_master_outputs();
    }

    /// The job id the master gave the submitter.
    pub fn job_id(&self) -> Option<JobId> {
        self.to_submitter.iter().find_map(|m| match m {
            Message::JobAccepted { job, .. } => Some(*job),
            _ => None,
        })
    }

    /// Adds a worker of `spec` that connects now; returns its index.
    pub fn join(&mut self, name: &str, spec: WorkerSpec) -> usize {
        if self.config.shared_cores.is_none() {
            self.cores.push(spec.cores.max(1));
        }
        let state = self.model.new_worker();
        self.workers.push(SimWorker {
            name: name.to_owned(),
            spec,
            partitioned: false,
            duplicate_results: false,
            results_sent: 0,
            frame_starts_got: Vec::new(),
            conn: ConnId(0),
            epoch: 0,
            session: None,
            state,
            link_free: [Duration::ZERO; 2],
        });
        self.busy.push(Vec::new());
        self.worker_cpu.push(0.0);
        let w = self.workers.len() - 1;
        self.connect(w);
        w
    }

    /// (Re)connects worker `w` with a fresh session (its scene cache stays).
    pub fn connect(&mut self, w: usize) {
        self.stop_work_of(w);
        let conn = self.next_conn;
        self.next_conn.0 += 1;
        let worker = &mut self.workers[w];
        worker.conn = conn;
        worker.epoch += 1;
        worker.session = Some(WorkerSession::new(self.now));
        self.model.reconnected(&mut worker.state);
        let peer = Peer::Worker {
            name: worker.name.clone(),
            threads: 1,
            address: "simulated".into(),
        };
        self.master.connected(self.now, conn, peer);
        self.route_master_outputs();
        self.pump_worker(w);
    }

    /// Kills worker `w` silently (kill -9 without a FIN: the master must
    /// notice from the missing heartbeats).
    pub fn kill(&mut self, w: usize) {
        self.workers[w].session = None;
        self.workers[w].epoch += 1;
        self.stop_work_of(w);
    }

    /// Tells worker `w` to drain (SIGTERM).
    pub fn drain(&mut self, w: usize) {
        if let Some(session) = self.workers[w].session.as_mut() {
            session.drain(self.now);
        }
        self.pump_worker(w);
    }

    /// Calls the master's core now (an input from outside the farm, like
    /// the HTTP side's) and routes what follows.
    pub fn act<R>(&mut self, call: impl FnOnce(&mut MasterCore, Duration) -> R) -> R {
        let answer = call(&mut self.master, self.now);
        self.route_master_outputs();
        answer
    }

    /// Submits `job` with its scene by hash (the submitter answers the
    /// master's scene requests).
    pub fn submit(&mut self, job: WireJob, scene: SceneData) {
        let job = WireJob {
            scene: JobScene::Hash(scene.hash),
            ..job
        };
        self.scene = Some(scene);
        let conn = self.submitter.expect("the submitter is connected");
        self.master
            .message(self.now, conn, Message::SubmitJob { job });
        self.route_master_outputs();
    }

    /// Submits `study`, its variants' scene `scene` by hash (the
    /// submitter answers the master's scene requests).
    pub fn submit_study(&mut self, mut study: WireStudy, scene: SceneData) {
        for variant in &mut study.variants {
            variant.scene = JobScene::Hash(scene.hash);
        }
        self.scene = Some(scene);
        let conn = self.submitter.expect("the submitter is connected");
        self.master
            .message(self.now, conn, Message::SubmitStudy { study });
        self.route_master_outputs();
    }

    /// Forgets what the farm recorded for its user (what the submitter
    /// got, the frames announced, the base frames, the deliveries, package
    /// and stage runs), so that
    /// only the master's and the sessions' memory is left.
    pub fn forget_records(&mut self) {
        self.to_submitter = Vec::new();
        self.frame_starts = Vec::new();
        self.base_frames = Vec::new();
        self.deliveries = Vec::new();
        for runs in &mut self.busy {
            *runs = Vec::new();
        }
        for worker in &mut self.workers {
            self.model.forget_records(&mut worker.state);
        }
    }

    /// The finished frames the submitter kept, in order (like
    /// `run_remote_job`, it skips a frame it has already).
    pub fn frames_done(&self) -> Vec<&FrameDone> {
        let mut frames: Vec<&FrameDone> = Vec::new();
        for m in &self.to_submitter {
            match m {
                Message::FrameDone(done) if done.frame as usize == frames.len() => {
                    frames.push(done)
                }
                _ => {}
            }
        }
        frames
    }

    /// Whether the submitter was told its job failed.
    pub fn job_failed(&self) -> Option<&Vec<String>> {
        self.to_submitter.iter().find_map(|m| match m {
            Message::JobFailed { errors, .. } => Some(errors),
            _ => None,
        })
    }

    /// Runs until `done` holds; panics (with the state) after `max_virtual`
    /// of virtual time or a million steps.
    pub fn drive(&mut self, max_virtual: Duration, mut done: impl FnMut(&Farm<M>) -> bool) {
        assert!(
            self.drive_bounded(max_virtual, 1_000_000, &mut done),
            "not done after {:?} of virtual time ({} steps); the submitter got {:?}",
            self.now,
            self.steps,
            self.to_submitter
                .iter()
                .map(Message::name)
                .collect::<Vec<_>>()
        );
    }

    /// Runs until `done` holds (true), or a bound is hit or nothing is left
    /// to happen (false).
    pub fn drive_bounded(
        &mut self,
        max_virtual: Duration,
        max_steps: u64,
        done: &mut impl FnMut(&Farm<M>) -> bool,
    ) -> bool {
        let limit = self.now + max_virtual;
        for _ in 0..max_steps {
            if done(self) {
                return true;
            }
            if !self.step(limit) {
                return done(self);
            }
        }
        done(self)
    }

    /// Each running CPU job's speed on its machine (its threads, all slowed
    /// alike when the machine has fewer cores than threads want to run),
    /// and the other work's (cores it gets).
    fn rates(&self) -> (Vec<f64>, f64) {
        let background = match self.config.shared_cores {
            Some(_) => self.config.background_threads.max(0.0),
            None => 0.0,
        };
        let mut wanted = vec![0.0; self.cores.len()];
        wanted[0] = background;
        for job in &self.cpu {
            wanted[job.machine] += f64::from(job.threads);
        }
        let share = |m: usize| (f64::from(self.cores[m]) / wanted[m]).min(1.0);
        let jobs = (self.cpu.iter())
            .map(|j| f64::from(j.threads) * share(j.machine))
            .collect();
        let background = if background > 0.0 {
            background * share(0)
        } else {
            0.0
        };
        (jobs, background)
    }

    /// Advances to the next event, deadline or finished CPU job and handles
    /// it; false when nothing is due by `limit`.
    pub fn step(&mut self, limit: Duration) -> bool {
        self.steps += 1;
        let (rates, background_rate) = self.rates();
        let cpu_next = (self.cpu.iter().zip(&rates))
            .enumerate()
            .map(|(i, (j, r))| (j.left.max(0.0) / r, i))
            .min_by(|a, b| a.0.total_cmp(&b.0));
        let cpu_at = cpu_next.map(|(dt, _)| self.now + Duration::from_secs_f64(dt));
        let event_at = self.events.keys().next().map(|k| k.0);
        let master_at = self.master.poll_timeout();
        let worker_at = (self.workers.iter().enumerate())
            .filter_map(|(w, x)| x.session.as_ref().map(|s| (s.poll_timeout(), w)))
            .min();
        let next = [cpu_at, event_at, master_at, worker_at.map(|(t, _)| t)]
            .into_iter()
            .flatten()
            .min();
        let Some(next) = next.filter(|&t| t <= limit) else {
            return false;
        };
        let next = next.max(self.now);
        let dt = (next - self.now).as_secs_f64();
        for (job, rate) in self.cpu.iter_mut().zip(&rates) {
            job.left -= dt * rate;
            let used = match job.work.worker() {
                Some(w) => &mut self.worker_cpu[w],
                None if matches!(job.work, Work::Submitter) => &mut self.submitter_cpu,
                None => &mut self.master_cpu,
            };
            *used += dt * rate;
        }
        self.background_cpu += dt * background_rate;
        self.now = next;
        if cpu_at == Some(next) {
            let (_, i) = cpu_next.expect("a CPU job is due");
            let job = self.cpu.swap_remove(i);
            self.finish(job.work);
        } else if event_at == Some(next) {
            let (_, event) = self.events.pop_first().expect("an event is due");
            self.deliver(event);
        } else if master_at.is_some_and(|t| t <= next) {
            // A deadline that an input set in the past is due now.
            self.master.handle_timeout(next);
            self.route_master_outputs();
        } else if let Some((_, w)) = worker_at {
            let session = self.workers[w].session.as_mut().expect("chosen as live");
            session.handle_timeout(next);
            self.pump_worker(w);
        }
        true
    }

    fn schedule(&mut self, at: Duration, event: Event) {
        self.events.insert((at, self.next_seq), event);
        self.next_seq += 1;
    }

    fn machine_of_worker(&self, w: usize) -> usize {
        match self.config.shared_cores {
            Some(_) => 0,
            None => w + 1,
        }
    }

    /// Starts `seconds` of one-thread work on `machine`, on `threads` threads.
    fn start_cpu(&mut self, machine: usize, threads: u32, seconds: f64, work: Work) {
        self.cpu.push(CpuJob {
            machine,
            threads: threads.max(1),
            left: seconds.max(0.0),
            work,
        });
    }

    /// Drops worker `w`'s running CPU jobs (its session is gone).
    fn stop_work_of(&mut self, w: usize) {
        self.cpu.retain(|job| job.work.worker() != Some(w));
    }

    /// The link model: a message of `bytes` between worker `w` and the
    /// master (`to_master` or from it) holds the worker's link and the
    /// master's shared link together, for its size over the slower rate,
    /// each direction one message at a time; it arrives a latency after
    /// its last byte left. Returns when it arrives.
    fn transfer(
        &mut self,
        w: usize,
        message: &Message,
        bytes: Option<u64>,
        to_master: bool,
    ) -> Duration {
        let direction = usize::from(to_master);
        let worker = &self.workers[w];
        let rate = (worker.spec.link_bits_per_second).min(self.config.master_link_bits_per_second);
        if rate.is_infinite() {
            return self.now + worker.spec.latency;
        }
        let bytes = bytes.unwrap_or_else(|| encoded_len(message));
        // An unlimited master link is held by no message: each crosses its
        // worker's link alone.
        let shared = self.config.master_link_bits_per_second.is_finite();
        let mut start = (self.now).max(worker.link_free[direction]);
        if shared {
            start = start.max(self.master_link_free[direction]);
        }
        let end = start + Duration::from_secs_f64(bytes as f64 * 8.0 / rate);
        self.workers[w].link_free[direction] = end;
        if shared {
            self.master_link_free[direction] = end;
        }
        end + self.workers[w].spec.latency
    }

    fn deliver(&mut self, event: Event) {
        let now = self.now;
        match event {
            Event::ToMaster(conn, message) => {
                self.queue_for_driver(DriverInput::Message(conn, message))
            }
            Event::Closed(conn) => self.queue_for_driver(DriverInput::Closed(conn)),
            Event::ToWorker(w, epoch, message) => {
                let worker = &mut self.workers[w];
                match worker.session.as_mut() {
                    Some(session) if worker.epoch == epoch => {
                        session.handle_message(now, *message, &mut worker.state)
                    }
                    _ => return,
                }
                self.pump_worker(w);
            }
        }
    }

    fn finish(&mut self, work: Work) {
        match work {
            Work::Setup {
                worker,
                epoch,
                key,
                outcome,
            } => {
                let w = &mut self.workers[worker];
                if let Some(session) = w.session.as_mut().filter(|_| w.epoch == epoch) {
                    session.frame_prepared(self.now, key, outcome);
                    self.pump_worker(worker);
                }
            }
            Work::Package {
                worker,
                epoch,
                mut result,
                failure,
                started,
                bytes,
            } => {
                result.busy_micros = (self.now - started).as_micros() as u64;
                let open =
                    (self.busy[worker].iter_mut()).rfind(|r| r.start == started && r.end.is_none());
                if let Some(run) = open {
                    run.end = Some(self.now);
                }
                let w = &mut self.workers[worker];
                if let Some(session) = w.session.as_mut().filter(|_| w.epoch == epoch) {
                    let id = result.id;
                    let outcome = failure.map_or(Ok(*result), Err);
                    session.package_finished(self.now, id, outcome);
                    self.pump_worker_sized(worker, bytes);
                }
            }
            Work::Base(key) => {
                let left = self.base_left.entry(key).or_insert(1);
                *left -= 1;
                if *left == 0 {
                    self.base_left.remove(&key);
                    self.queue_for_driver(DriverInput::Base(key));
                }
            }
            Work::Encode(request, Some(serial)) => {
                self.start_cpu(0, 1, serial, Work::Encode(request, None));
            }
            Work::Encode(request, None) => {
                let encoded = request.encode();
                self.queue_for_driver(DriverInput::Encoded(Box::new(encoded)));
            }
            Work::Driver(outputs) => {
                self.driver_busy = false;
                for output in outputs {
                    self.route_master_output(output);
                }
                self.next_driver_input();
            }
            Work::Journal => {
                if self.journal_frames.next() {
                    let seconds = self.model.master_costs().journal;
                    self.start_cpu(0, 1, seconds, Work::Journal);
                }
            }
            Work::Submitter => {
                if self.submitter_frames.next() {
                    let seconds = self.model.master_costs().submitter;
                    self.start_cpu(0, 1, seconds, Work::Submitter);
                }
            }
        }
    }

    fn queue_for_driver(&mut self, input: DriverInput) {
        self.driver_queue.push_back(input);
        if !self.driver_busy {
            self.next_driver_input();
        }
    }

    /// Whether `conn` is a connection the farm still holds.
    fn is_current(&self, conn: ConnId) -> bool {
        self.submitter == Some(conn) || self.workers.iter().any(|w| w.conn == conn)
    }

    /// Hands the driver's next input to the core; its outputs go out once
    /// the driver's CPU time for it has passed.
    fn next_driver_input(&mut self) {
        let Some(input) = self.driver_queue.pop_front() else {
            return;
        };
        let costs = self.model.master_costs();
        let mut seconds = 0.0;
        match input {
            DriverInput::Message(conn, message) => {
                if !self.is_current(conn) {
                    return self.next_driver_input();
                }
                if let Message::PackageResult(result) = message.as_ref() {
                    // A whole frame comes finished: the driver only forwards it.
                    let items = match result.pixels {
                        ResultPixels::Bitmap(_) => result.triangle_samples.len(),
                        ResultPixels::Frame { .. } => 0,
                    };
                    seconds += costs.result_per_item * items as f64;
                    if let Some(key) = self.package_frames.remove(&result.id) {
                        // A straggler's copy after the frame went out is
                        // not kept (its entry would never be removed).
                        if self.frame_started.contains_key(&key) {
                            self.frame_last_result.insert(key, self.now);
                        }
                        if self.base_pending.contains(&key) {
                            *self.held_items.entry(key).or_default() += items;
                        }
                    }
                }
                self.master.message(self.now, conn, *message);
            }
            DriverInput::Closed(conn) => self.master.disconnected(self.now, conn),
            DriverInput::Glare(request) => {
                let figures = request.compute();
                let (generation, quality) = (request.generation, request.quality);
                (self.master).view_figures_ready(self.now, generation, quality, figures);
            }
            DriverInput::Encoded(encoded) => {
                seconds += costs.frame_sent;
                self.master.frame_encoded(self.now, *encoded)
            }
            DriverInput::Base(key) => {
                self.base_pending.remove(&key);
                let held = self.held_items.remove(&key).unwrap_or(0);
                seconds += costs.result_per_item * held as f64;
                if let Some(request) = self.pending_base.remove(&key) {
                    let base = request.rasterize();
                    self.master.base_frame_ready(self.now, key.0, key.1, base);
                }
            }
        }
        let mut outputs = Vec::new();
        while let Some(output) = self.master.poll_output() {
            match output {
                // The real driver encodes a view's frame for the dashboard
                // on its task (beside the figures, not before them).
                Output::EncodeFrame(request) if request.for_dashboard_only() => {
                    seconds += costs.frame_conversion(&request) + costs.frame_out_serial;
                    self.master.frame_encoded(self.now, request.encode());
                }
                output => outputs.push(output),
            }
        }
        self.driver_busy = true;
        self.start_cpu(0, 1, seconds, Work::Driver(outputs));
    }

    /// Outputs of a core call made outside the driver's queue (timeouts,
    /// connections, the tests' own calls).
    fn route_master_outputs(&mut self) {
        while let Some(output) = self.master.poll_output() {
            self.route_master_output(output);
        }
    }

    fn route_master_output(&mut self, output: Output) {
        match output {
            Output::Send(conn, message) if Some(conn) == self.submitter => {
                self.submitter_received(conn, *message)
            }
            Output::Send(conn, message) => {
                let Some(w) = self.workers.iter().position(|w| w.conn == conn) else {
                    return;
                };
                match message.as_ref() {
                    Message::Package(p) => {
                        let key = (p.job, p.frame);
                        self.package_frames.insert(p.id, key);
                        if p.whole.is_some() {
                            // A whole frame's set-up travels with it.
                            self.frame_starts.push(key);
                            self.frame_started.entry(key).or_insert(self.now);
                        }
                    }
                    Message::FrameStart(start) => {
                        let key = (start.job, start.frame);
                        self.frame_starts.push(key);
                        self.workers[w].frame_starts_got.push(key);
                        self.frame_started.entry(key).or_insert(self.now);
                    }
                    _ => {}
                }
                if self.workers[w].partitioned {
                    return;
                }
                let at = self.transfer(w, &message, None, false);
                let epoch = self.workers[w].epoch;
                self.schedule(at, Event::ToWorker(w, epoch, message));
            }
            Output::Close(conn, _) => {
                // The driver drops the connection: the worker's session ends.
                if let Some(w) = self.workers.iter().position(|w| w.conn == conn) {
                    self.kill(w);
                }
                self.master.disconnected(self.now, conn);
            }
            Output::ViewGlare(request) => {
                self.queue_for_driver(DriverInput::Glare(Box::new(request)))
            }
            Output::EncodeFrame(request) => {
                // One job on every core (the machine's other work, the
                // driver and base frames, shares them), then one thread.
                let costs = self.model.master_costs();
                let conversion = costs.frame_conversion(&request);
                let work = Work::Encode(Box::new(request), Some(costs.frame_out_serial));
                self.start_cpu(0, self.cores[0], conversion, work);
            }
            Output::RasterizeBase(request) => {
                let key = (request.job, request.frame);
                self.base_frames.push(key);
                self.bases_in_reused_buffers += usize::from(request.reuses_buffers());
                let shares = self.cores[0];
                self.base_left.insert(key, shares);
                self.base_pending.insert(key);
                let costs = self.model.master_costs();
                let srgb = if request.converts_to_srgb() {
                    costs.frame_out
                } else {
                    0.0
                };
                self.pending_base.insert(key, request);
                let seconds = (costs.base_frame + srgb) / f64::from(shares);
                for _ in 0..shares {
                    self.start_cpu(0, 1, seconds, Work::Base(key));
                }
            }
            Output::Persist(record) => {
                let journal = self.journal.as_ref();
                let (job, frame) = (record.job(), record.frame());
                let outcome = journal
                    .expect("only a persistent core persists")
                    .write(record);
                let written = Written {
                    job,
                    frame,
                    outcome,
                };
                self.master.journal_written(self.now, written);
            }
            Output::Replay { conn, job, frames } => {
                let journal = self
                    .journal
                    .as_ref()
                    .expect("only a persistent core replays");
                for frame in frames {
                    match journal.frame(job, frame) {
                        Ok(done) if Some(conn) == self.submitter => {
                            self.to_submitter.push(Message::FrameDone(done));
                        }
                        Ok(_) => {}
                        Err(e) => self.master.replay_failed(self.now, conn, job, frame, e),
                    }
                }
            }
        }
    }

    /// The submitter's side: answers scene requests, keeps the rest, and
    /// spends its CPU (and the journal's) on each finished frame.
    fn submitter_received(&mut self, conn: ConnId, message: Message) {
        match message {
            Message::SceneRequest { hash } => {
                let data = self.scene.clone().filter(|s| s.hash == hash);
                if let Some(data) = data {
                    let at = self.now + self.config.submitter_latency;
                    let reply = Message::SceneData(data);
                    self.schedule(at, Event::ToMaster(conn, Box::new(reply)));
                }
            }
            Message::FrameDone(done) => {
                let key = (done.job, done.frame);
                let started_at = self.frame_started.remove(&key);
                let completed_at = self.frame_last_result.remove(&key);
                let mut cpu = vec![self.master_cpu];
                cpu.extend(&self.worker_cpu);
                cpu.push(self.submitter_cpu);
                self.deliveries.push(Delivery {
                    index: done.frame,
                    started_at: started_at.unwrap_or(self.now),
                    done_at: self.now,
                    completed_at: completed_at.unwrap_or(self.now),
                    background_cpu: self.background_cpu,
                    cpu,
                    stats: done.stats.clone(),
                });
                let costs = self.model.master_costs();
                if self.journal_frames.add() {
                    self.start_cpu(0, 1, costs.journal, Work::Journal);
                }
                if self.submitter_frames.add() {
                    self.start_cpu(0, 1, costs.submitter, Work::Submitter);
                }
                self.to_submitter.push(Message::FrameDone(done));
            }
            message => self.to_submitter.push(message),
        }
    }

    fn pump_worker(&mut self, w: usize) {
        self.pump_worker_sized(w, None);
    }

    /// A package cancelled while it runs stops now, freeing the worker's
    /// cores, as the real worker's driver stops it.
    fn stop_cancelled_package(&mut self, w: usize) {
        let Some(session) = self.workers[w].session.as_mut() else {
            return;
        };
        let Some(id) = session.running().filter(|&id| session.is_cancelled(id)) else {
            return;
        };
        let epoch = self.workers[w].epoch;
        let job = (self.cpu.iter()).position(|job| {
            matches!(&job.work, Work::Package { worker, epoch: e, result, .. }
                if *worker == w && *e == epoch && result.id == id)
        });
        let Some(job) = job else {
            return;
        };
        if let Work::Package { started, .. } = self.cpu.swap_remove(job).work {
            let open = (self.busy[w].iter_mut()).rfind(|r| r.start == started && r.end.is_none());
            if let Some(run) = open {
                run.end = Some(self.now);
            }
        }
        let stopped = PackageError::Stopped {
            id,
            why: "cancelled".into(),
        };
        let session = self.workers[w].session.as_mut().expect("checked above");
        session.package_finished(self.now, id, Err(stopped));
    }

    /// Starts worker `w`'s tasks and sends its messages (a result at
    /// `result_bytes` on the wire, when the model says).
    fn pump_worker_sized(&mut self, w: usize, result_bytes: Option<u64>) {
        let machine = self.machine_of_worker(w);
        let shared = self.config.shared_cores.is_some();
        let worker = &mut self.workers[w];
        if let Some(session) = &worker.session {
            let keeps = |key| session.keeps_set_up(key);
            self.model.retain_frames(&mut worker.state, &keeps);
        }
        self.stop_cancelled_package(w);
        let Some(session) = self.workers[w].session.as_mut() else {
            return;
        };
        let mut tasks = Vec::new();
        while let Some(task) = session.poll_task() {
            tasks.push(task);
        }
        for task in tasks {
            let worker = &mut self.workers[w];
            let (speed, epoch) = (worker.spec.speed, worker.epoch);
            match task {
                Task::PrepareFrame(start) => {
                    let key = (start.job, start.frame);
                    // Traced before the set-up, it goes out with this pump's messages.
                    if let Some(mesh) = self.model.corner_mesh(&mut worker.state, &start) {
                        if let Some(session) = worker.session.as_mut() {
                            session.corner_mesh_traced(self.now, key, mesh);
                        }
                    }
                    let (outcome, seconds) = self.model.prepare_frame(&mut worker.state, start);
                    let work = Work::Setup {
                        worker: w,
                        epoch,
                        key,
                        outcome,
                    };
                    self.start_cpu(machine, 1, seconds / speed, work);
                }
                Task::RunPackage { package, stage } => {
                    let run = self.model.run_package(&mut worker.state, &package, stage);
                    let overhead = worker.spec.package_overhead.as_secs_f64();
                    let threads = if shared { 1 } else { worker.spec.cores };
                    self.busy[w].push(PackageRun {
                        start: self.now,
                        end: None,
                        job: package.job,
                        frame: package.frame,
                        work: run.seconds,
                    });
                    let work = Work::Package {
                        worker: w,
                        epoch,
                        result: Box::new(run.result),
                        failure: run.failure,
                        started: self.now,
                        bytes: run.wire_bytes,
                    };
                    self.start_cpu(machine, threads, (run.seconds + overhead) / speed, work);
                }
            }
        }
        let Some(session) = self.workers[w].session.as_mut() else {
            return;
        };
        let mut messages = Vec::new();
        while let Some(message) = session.poll_message() {
            messages.push(message);
        }
        let end = session.poll_end();
        for message in messages {
            let worker = &mut self.workers[w];
            if worker.partitioned {
                continue;
            }
            let conn = worker.conn;
            let bytes = match &message {
                Message::PackageResult(_) => {
                    worker.results_sent += 1;
                    result_bytes
                }
                _ => None,
            };
            let at = self.transfer(w, &message, bytes, true);
            if matches!(message, Message::PackageResult(_)) && self.workers[w].duplicate_results {
                self.schedule(at, Event::ToMaster(conn, Box::new(message.clone())));
            }
            self.schedule(at, Event::ToMaster(conn, Box::new(message)));
        }
        if let Some(end) = end {
            let worker = &mut self.workers[w];
            worker.session = None;
            worker.epoch += 1;
            let (conn, at) = (worker.conn, self.now + worker.spec.latency);
            self.stop_work_of(w);
            if end == SessionEnd::Drained {
                // Goodbye: the link closes and the master hears it at once.
                self.schedule(at, Event::Closed(conn));
            }
        }
    }
}
