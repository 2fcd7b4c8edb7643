//! A simulated farm: the [`Scheduler`] with N simulated workers, in-memory
//! message delivery and a virtual clock that jumps to the next event (a
//! message arriving, a package finishing, a heartbeat, a scheduler deadline).
//! Like quinn's test `Pair`, it runs fault scenarios in milliseconds without
//! sockets or sleeps. It is the scheduler's own test model: the farm itself
//! (the real master core and worker sessions) is simulated by
//! `vtfarm-farmsim`, whose link model this one follows.
//!
//! Model: every item has a true cost in seconds on a worker of speed 1. A
//! worker computes one package at a time, taking its fixed overhead plus the
//! items' true cost divided by its speed (a slowdown divides the speed from a
//! given time on, also mid-package). Links as in `vtfarm-farmsim`: a message holds the
//! worker's link and (with [`SimConfig::master_link_bits_per_second`]) the
//! master's shared one together, for its size over the slower rate, one
//! message at a time per direction, then the latency; assignments carry a
//! few bytes per item, results [`SimConfig::result_bytes_per_item`] per item. A worker asks for work when it joins and, piggybacked on
//! each result, whenever it runs out. With the master's rules
//! ([`SchedulerConfig::pipelined`]: frame affinity, frames pipelined) every
//! worker hears of each new frame (`FrameStart` over its
//! link), sets it up ([`SimWorker::frame_setup`]; a worker that is computing
//! a package of the older frame shares its core between the two, so both
//! take longer) and then asks for work of that frame; like the master core,
//! the simulated master takes only requests for the newest frame. The
//! master rasterizes each split frame's base image ([`SimConfig::master_frame_cost`],
//! from the frame start on, one at a time, beside the tracing; a whole
//! frame's worker makes its own); results that
//! arrive before it are held ([`Scheduler::package_arrived`]) and accepted
//! when it is ready, as the master core does. Like the master core, it
//! reports each base frame's time ([`Scheduler::base_frame_cost`]: one at a
//! time, each takes the cost) and, with [`SimConfig::bases_ahead`], makes
//! the base frames of a batch job's last frames ahead once its first whole
//! frame starts ([`Scheduler::base_frame_ahead`]). The master handles messages
//! one at a time, and checking and compositing a result costs
//! [`SimConfig::master_result_cost_per_item`] per item.
//! [`SimReport::inputs`] logs every call into the scheduler.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::Duration;

use vtfarm_scheduler::{
    Assignment, Counters, Event, FrameStats, FrameWork, JobId, LossCause, PackageId,
    PackageMeasure, Scheduler, SchedulerConfig, WorkerId,
};

/// Settings of a simulation.
#[derive(Clone, Debug)]
pub(crate) struct SimConfig {
    pub scheduler: SchedulerConfig,
    /// How often a live worker sends a heartbeat. Default 1 s.
    pub heartbeat_interval: Duration,
    /// Bytes of every message besides its items. Default 64.
    pub header_bytes: u64,
    /// Assignment bytes per item (a triangle id). Default 4.
    pub assignment_bytes_per_item: u64,
    /// Result bytes per item (a triangle's pixels). Default 2048.
    pub result_bytes_per_item: u64,
    /// Rays per second of work at speed 1, for the statistics. Default 10⁶.
    pub rays_per_second: f64,
    /// [`Simulation::drive`] gives up at this virtual time. Default 1 hour.
    pub time_limit: Duration,
    /// Check the scheduler's invariants after every step and record
    /// violations in [`SimReport::violations`]. Default off (it costs time
    /// linear in the frame per step).
    pub validate: bool,
    /// The master's own link, shared by every worker's messages, in bits per
    /// second each way; `None`: unlimited. Default `None`.
    pub master_link_bits_per_second: Option<f64>,
    /// The master's per-frame work that overlaps the tracing (the base
    /// frame). Default zero.
    pub master_frame_cost: Duration,
    /// The master's time to check and composite a result, per item; its
    /// messages wait meanwhile. Default zero.
    pub master_result_cost_per_item: Duration,
    /// How many of a batch job's last frames the master makes the base
    /// frames of ahead, one at a time from its first whole frame's start
    /// on (at most one per worker), as the master core does. Default 0.
    pub bases_ahead: usize,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            scheduler: SchedulerConfig::default(),
            heartbeat_interval: Duration::from_secs(1),
            header_bytes: 64,
            assignment_bytes_per_item: 4,
            result_bytes_per_item: 2048,
            rays_per_second: 1e6,
            time_limit: Duration::from_secs(3600),
            validate: false,
            master_link_bits_per_second: None,
            master_frame_cost: Duration::ZERO,
            master_result_cost_per_item: Duration::ZERO,
            bases_ahead: 0,
        }
    }
}

/// One simulated worker; worker `i` of [`Simulation::new`] is `WorkerId(i)`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SimWorker {
    /// Reported to the scheduler (its guess before the first result); the
    /// speed alone decides how fast the worker computes.
    pub threads: u32,
    /// Work per second: an item of true cost `c` takes `c / speed` seconds.
    pub speed: f64,
    /// Link bandwidth in bits per second, both ways.
    pub link_bits_per_second: f64,
    /// Link latency, both ways.
    pub latency: Duration,
    /// Fixed time per package (set-up), counted as busy.
    pub package_overhead: Duration,
    /// When it joins.
    pub join_at: Duration,
    pub crash: Option<SimCrash>,
    pub slowdown: Option<SimSlowdown>,
    pub failures: SimFailures,
    /// Whether it stops a package when told to; one that does not sends a
    /// result the master must ignore.
    pub honours_cancel: bool,
    /// Time to set a frame up (ID buffers) before asking for its work, when
    /// requests lapse at a frame start. Default zero.
    pub frame_setup: Duration,
}

impl SimWorker {
    /// A single-threaded worker of the given speed on a 100 Mbit/s link with
    /// 0.2 ms latency and 1 ms overhead per package, joining at time 0.
    pub(crate) fn with_speed(speed: f64) -> SimWorker {
        SimWorker {
            threads: 1,
            speed,
            link_bits_per_second: 100e6,
            latency: Duration::from_micros(200),
            package_overhead: Duration::from_millis(1),
            join_at: Duration::ZERO,
            crash: None,
            slowdown: None,
            failures: SimFailures::Never,
            honours_cancel: true,
            frame_setup: Duration::ZERO,
        }
    }
}

/// A worker crash: it stops computing and sending at `at`.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SimCrash {
    pub at: Duration,
    /// Whether the master's driver notices the dropped connection (then the
    /// scheduler hears `worker_left` one latency later); otherwise only the
    /// heartbeat timeout finds out.
    pub noticed: bool,
}

/// From `at` on, the worker computes `factor` times slower.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SimSlowdown {
    pub at: Duration,
    pub factor: f64,
}

/// Which packages a worker fails (after its package overhead).
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum SimFailures {
    Never,
    Always,
    /// Its first `n` packages.
    FirstPackages(u32),
    /// Every package that contains one of these items.
    Items(Vec<u32>),
}

/// A job to simulate: its frames with the true cost of every item.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SimJob {
    pub id: JobId,
    pub submit_at: Duration,
    pub frames: Vec<SimFrame>,
}

/// One frame: items in Morton order and their true costs (seconds at speed 1).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SimFrame {
    pub items: Vec<u32>,
    pub costs: Vec<f64>,
}

/// What a simulation produced.
#[derive(Clone, Debug, Default)]
pub(crate) struct SimReport {
    /// Every scheduler event with the virtual time it came out.
    pub events: Vec<(Duration, Event)>,
    /// Every completed frame, in order.
    pub frames: Vec<SimFrameReport>,
    /// Every package handed out, with the virtual time.
    pub assignments: Vec<(Duration, Assignment)>,
    /// Whether every submitted job ended (complete, failed or cancelled).
    pub finished: bool,
    /// Virtual time when the simulation stopped.
    pub end: Duration,
    /// The scheduler's counters of ignored results at the end.
    pub counters: Counters,
    /// Inputs the scheduler refused, with the time (late results included).
    pub refusals: Vec<(Duration, String)>,
    /// Broken scheduler invariants (with [`SimConfig::validate`]); a
    /// non-empty list is a bug.
    pub violations: Vec<String>,
    /// Every call into the scheduler, in order, with its virtual time.
    pub inputs: Vec<(Duration, SimInput)>,
}

/// A call into the scheduler, as [`SimReport::inputs`] logs it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum SimInput {
    Submit(JobId, Vec<FrameWork>),
    Joined(WorkerId, u32),
    Request(WorkerId),
    Heartbeat(WorkerId),
    /// A result held until its frame's base image is ready.
    Arrived(WorkerId, PackageId),
    /// The master's time for a base frame of the job.
    BaseFrameCost(JobId, Duration),
    /// The master holds the base frame of a frame not started.
    BaseFrameAhead(JobId, u32),
    Left(WorkerId),
    Done(WorkerId, PackageId, PackageMeasure),
    Failed(WorkerId, PackageId, String),
    Timeout,
}

/// A completed frame as the simulation saw it.
#[derive(Clone, Debug)]
pub(crate) struct SimFrameReport {
    pub job: JobId,
    pub frame: u32,
    /// When it completed.
    pub at: Duration,
    /// When the master could send it: completed, and its base frame ready.
    pub done_at: Duration,
    pub stats: FrameStats,
    /// True cost of the items each worker's accepted results covered.
    pub true_cost: BTreeMap<WorkerId, f64>,
    /// How many accepted results covered each item (1 for each, if correct).
    pub completions: BTreeMap<u32, u32>,
}

/// The simulation: scheduler, workers, clock and messages in flight.
#[derive(Debug)]
pub(crate) struct Simulation {
    config: SimConfig,
    scheduler: Scheduler,
    now: Duration,
    workers: Vec<WorkerSim>,
    /// True costs of each frame of each submitted job.
    costs: BTreeMap<JobId, Vec<BTreeMap<u32, f64>>>,
    /// Jobs submitted to the simulation that have not ended.
    open_jobs: BTreeSet<JobId>,
    /// Pending events by time, then by the order they were scheduled.
    pending: BTreeMap<(Duration, u64), SimEvent>,
    sequence: u64,
    /// Accepted results of frames not complete yet.
    tallies: BTreeMap<(JobId, u32), Tally>,
    /// When each running frame's base frame is ready.
    frame_starts: BTreeMap<(JobId, u32), Duration>,
    /// When the shared master link is next free: towards the workers, from them.
    master_link_free: [Duration; 2],
    /// When the master's last base frame is done (it rasterizes one at a time).
    master_free: Duration,
    /// When the master's driver is done with the messages so far.
    master_busy_until: Duration,
    /// The newest frame started: the only one requests are taken for.
    newest: Option<FrameKey>,
    /// Results held until their frame's base image is ready.
    held: BTreeMap<FrameKey, Vec<HeldResult>>,
    /// Base frames made ahead ([`SimConfig::bases_ahead`]), ready then.
    bases_ahead: BTreeMap<FrameKey, Duration>,
    report: SimReport,
}

/// Which way a message crosses the master's link.
#[derive(Clone, Copy)]
enum Direction {
    ToWorker = 0,
    ToMaster = 1,
}

/// A frame by job and index.
type FrameKey = (JobId, u32);

/// A result the master holds for its frame's base image.
#[derive(Debug)]
struct HeldResult {
    worker: WorkerId,
    assignment: Assignment,
    measure: PackageMeasure,
    true_cost: f64,
}

#[derive(Debug)]
struct WorkerSim {
    id: WorkerId,
    spec: SimWorker,
    alive: bool,
    /// The newest frame it heard of, and when its set-up is done.
    frame: Option<FrameKey>,
    ready_at: Duration,
    /// Whether a request is outstanding (a package or a new frame voids it).
    requested: bool,
    inbox: VecDeque<Assignment>,
    current: Option<Computing>,
    /// Tells a finish event of the current package from a stale one.
    token: u64,
    started: u32,
    /// When its link is free, indexed by [`Direction`].
    link_free: [Duration; 2],
}

#[derive(Debug)]
struct Computing {
    assignment: Assignment,
    token: u64,
    started_at: Duration,
    /// When it ends, unless a frame set-up shares the core meanwhile.
    ends_at: Duration,
    /// The true cost of each item, in item order; their sum is the work.
    item_costs: Vec<f64>,
    fails: bool,
}

#[derive(Debug, Default)]
struct Tally {
    true_cost: BTreeMap<WorkerId, f64>,
    completions: BTreeMap<u32, u32>,
}

#[derive(Debug)]
enum SimEvent {
    Submit(SimJob),
    Join(usize),
    Crash(usize),
    HeartbeatTick(usize),
    ComputeEnd {
        worker: usize,
        token: u64,
    },
    /// `FrameStart` reaches a worker.
    FrameStart(usize, FrameKey),
    /// A worker's frame set-up is done.
    FrameReady(usize, FrameKey),
    /// The master's base image of a frame is ready.
    BaseReady(FrameKey),
    /// A base frame made ahead is ready (its frame has not started).
    BaseAhead(FrameKey),
    /// A frame's base frame, made ahead or none (whole), is there: the
    /// held results are accepted (nothing to measure).
    HeldReady(FrameKey),
    ToWorker(usize, ToWorker),
    ToMaster(usize, ToMaster),
}

#[derive(Debug)]
enum ToWorker {
    Assign(Assignment),
    Cancel(PackageId),
}

#[derive(Debug)]
enum ToMaster {
    /// A request for work of a frame (`None`: any, when requests do not lapse).
    Request(Option<FrameKey>),
    Heartbeat,
    Left,
    Done {
        assignment: Assignment,
        measure: PackageMeasure,
        true_cost: f64,
    },
    Failed {
        package: PackageId,
        error: String,
    },
}

/// Consecutive steps without the clock moving after which the simulation
/// reports a livelock instead of spinning.
const MAX_STEPS_AT_ONE_TIME: u32 = 1_000_000;

impl Simulation {
    pub(crate) fn new(config: SimConfig, workers: Vec<SimWorker>) -> Simulation {
        let scheduler = Scheduler::new(config.scheduler.clone());
        let mut simulation = Simulation {
            config,
            scheduler,
            now: Duration::ZERO,
            workers: Vec::with_capacity(workers.len()),
            costs: BTreeMap::new(),
            open_jobs: BTreeSet::new(),
            pending: BTreeMap::new(),
            sequence: 0,
            tallies: BTreeMap::new(),
            frame_starts: BTreeMap::new(),
            master_link_free: [Duration::ZERO; 2],
            master_free: Duration::ZERO,
            master_busy_until: Duration::ZERO,
            newest: None,
            held: BTreeMap::new(),
            bases_ahead: BTreeMap::new(),
            report: SimReport::default(),
        };
        for (index, spec) in workers.into_iter().enumerate() {
            simulation.schedule(spec.join_at, SimEvent::Join(index));
            if let Some(crash) = &spec.crash {
                simulation.schedule(crash.at, SimEvent::Crash(index));
            }
            simulation.workers.push(WorkerSim {
                id: WorkerId(index as u64),
                spec,
                alive: true,
                frame: None,
                ready_at: Duration::ZERO,
                requested: false,
                inbox: VecDeque::new(),
                current: None,
                token: 0,
                started: 0,
                link_free: [Duration::ZERO; 2],
            });
        }
        simulation
    }

    /// Submits a job at its `submit_at` time.
    pub(crate) fn submit(&mut self, job: SimJob) {
        self.open_jobs.insert(job.id);
        self.schedule(job.submit_at, SimEvent::Submit(job));
    }

    /// Runs until every submitted job ended and no result is in flight any
    /// more, nothing can happen any more, or [`SimConfig::time_limit`].
    pub(crate) fn drive(&mut self) -> &SimReport {
        self.drive_bounded(self.config.time_limit)
    }

    /// Runs until every submitted job ended and no result is in flight any
    /// more, nothing can happen any more, or the next event lies after
    /// `limit`.
    pub(crate) fn drive_bounded(&mut self, limit: Duration) -> &SimReport {
        let mut steps_at_this_time = 0;
        loop {
            if self.open_jobs.is_empty() {
                self.report.finished = true;
                // Let results still in flight arrive (and be refused).
                if self.quiescent() {
                    break;
                }
            }
            let Some(next) = self.next_time() else {
                break;
            };
            if next > limit {
                break;
            }
            let before = self.now;
            self.step();
            steps_at_this_time = if self.now == before {
                steps_at_this_time + 1
            } else {
                0
            };
            if steps_at_this_time > MAX_STEPS_AT_ONE_TIME {
                self.report
                    .violations
                    .push(format!("no progress at {:?}", self.now));
                break;
            }
        }
        self.report.end = self.now;
        self.report.counters = self.scheduler.counters();
        &self.report
    }

    /// Whether no package is computed, queued at a worker, or in flight.
    fn quiescent(&self) -> bool {
        let workers_idle = self
            .workers
            .iter()
            .all(|w| w.current.is_none() && w.inbox.is_empty());
        let in_flight = self.pending.values().any(|event| {
            matches!(
                event,
                SimEvent::ToWorker(_, ToWorker::Assign(_))
                    | SimEvent::ToMaster(_, ToMaster::Done { .. } | ToMaster::Failed { .. })
            )
        });
        workers_idle && !in_flight
    }

    pub(crate) fn now(&self) -> Duration {
        self.now
    }

    pub(crate) fn scheduler(&self) -> &Scheduler {
        &self.scheduler
    }

    pub(crate) fn report(&self) -> &SimReport {
        &self.report
    }

    pub(crate) fn into_report(self) -> SimReport {
        self.report
    }

    // ----- The event loop -----

    fn schedule(&mut self, at: Duration, event: SimEvent) {
        self.pending.insert((at, self.sequence), event);
        self.sequence += 1;
    }

    fn next_time(&self) -> Option<Duration> {
        let message = self.pending.first_key_value().map(|(&(at, _), _)| at);
        let timeout = self.scheduler.poll_timeout();
        message.into_iter().chain(timeout).min()
    }

    /// Advances to the next event (a scheduler deadline goes first on a tie)
    /// and handles it.
    fn step(&mut self) {
        let message = self.pending.first_key_value().map(|(&(at, _), _)| at);
        let timeout = self.scheduler.poll_timeout();
        let timeout_first = match (message, timeout) {
            (Some(m), Some(t)) => t <= m,
            (None, Some(_)) => true,
            (_, None) => false,
        };
        if let (true, Some(t)) = (timeout_first, timeout) {
            self.timeout(t);
        } else if let Some(((at, _), event)) = self.pending.pop_first() {
            self.now = self.now.max(at);
            self.handle(event);
        } else {
            return;
        }
        self.drain_outputs();
        if self.config.validate {
            if let Err(error) = self.scheduler.validate() {
                self.report
                    .violations
                    .push(format!("{:?}: {error}", self.now));
            }
        }
    }

    fn timeout(&mut self, at: Duration) {
        self.now = self.now.max(at);
        self.report.inputs.push((self.now, SimInput::Timeout));
        self.scheduler.handle_timeout(self.now);
    }

    fn handle(&mut self, event: SimEvent) {
        let now = self.now;
        match event {
            SimEvent::Submit(job) => {
                self.costs.insert(
                    job.id,
                    job.frames
                        .iter()
                        .map(|f| {
                            f.items
                                .iter()
                                .copied()
                                .zip(f.costs.iter().copied())
                                .collect()
                        })
                        .collect(),
                );
                let frames: Vec<FrameWork> = job
                    .frames
                    .into_iter()
                    .map(|f| FrameWork { items: f.items })
                    .collect();
                self.log(SimInput::Submit(job.id, frames.clone()));
                if let Err(error) = self.scheduler.submit_job(now, job.id, frames) {
                    self.refused(error.to_string());
                    self.open_jobs.remove(&job.id);
                }
            }
            SimEvent::Join(index) => {
                let Some(worker) = self.workers.get(index) else {
                    return;
                };
                if !worker.alive {
                    return;
                }
                let (id, threads) = (worker.id, worker.spec.threads);
                self.log(SimInput::Joined(id, threads));
                if let Err(error) = self.scheduler.worker_joined(now, id, threads) {
                    self.refused(error.to_string());
                }
                if !self.hears_frames() {
                    self.log(SimInput::Request(id));
                    if let Err(error) = self.scheduler.request_work(now, id) {
                        self.refused(error.to_string());
                    }
                } else if let Some(key) = self.newest {
                    // Like a real worker: it hears of the running frame
                    // (sets it up when requests lapse) and then asks.
                    let arrival =
                        self.arrival(index, self.config.header_bytes, Direction::ToWorker);
                    self.schedule(arrival, SimEvent::FrameStart(index, key));
                }
                let interval = self.config.heartbeat_interval;
                self.schedule(now + interval, SimEvent::HeartbeatTick(index));
            }
            SimEvent::Crash(index) => {
                let Some(worker) = self.workers.get_mut(index) else {
                    return;
                };
                let noticed = worker.spec.crash.as_ref().is_some_and(|c| c.noticed);
                let latency = worker.spec.latency;
                worker.alive = false;
                worker.current = None;
                worker.inbox.clear();
                if noticed {
                    self.schedule(now + latency, SimEvent::ToMaster(index, ToMaster::Left));
                }
            }
            SimEvent::HeartbeatTick(index) => {
                let Some(worker) = self.workers.get(index) else {
                    return;
                };
                if worker.alive {
                    let latency = worker.spec.latency;
                    self.schedule(
                        now + latency,
                        SimEvent::ToMaster(index, ToMaster::Heartbeat),
                    );
                    let interval = self.config.heartbeat_interval;
                    self.schedule(now + interval, SimEvent::HeartbeatTick(index));
                }
            }
            SimEvent::ComputeEnd { worker, token } => self.compute_end(worker, token),
            SimEvent::FrameStart(index, key) => {
                if self.config.scheduler.requests_lapse_at_frame_start {
                    self.frame_start(index, key)
                } else {
                    // Frame affinity: a frame is set up with its first
                    // package (not modelled); hearing of one, an idle
                    // worker asks.
                    self.ask_when_idle(index)
                }
            }
            SimEvent::FrameReady(index, key) => {
                let ready = self
                    .workers
                    .get(index)
                    .is_some_and(|w| w.alive && w.frame == Some(key) && now >= w.ready_at);
                if ready {
                    self.ask_when_idle(index);
                }
            }
            SimEvent::BaseReady(key) => self.base_ready(key),
            SimEvent::HeldReady(key) => self.accept_held(key),
            SimEvent::BaseAhead((job, frame)) => {
                let cost = self.config.master_frame_cost;
                self.log(SimInput::BaseFrameCost(job, cost));
                let _ = self.scheduler.base_frame_cost(now, job, cost);
                self.log(SimInput::BaseFrameAhead(job, frame));
                let _ = self.scheduler.base_frame_ahead(now, job, frame);
            }
            SimEvent::ToWorker(index, message) => self.deliver_to_worker(index, message),
            SimEvent::ToMaster(index, message) => {
                // The master's driver handles one message at a time.
                if now < self.master_busy_until {
                    let at = self.master_busy_until;
                    self.schedule(at, SimEvent::ToMaster(index, message));
                } else {
                    self.deliver_to_master(index, message);
                }
            }
        }
    }

    fn deliver_to_master(&mut self, index: usize, message: ToMaster) {
        let now = self.now;
        let id = WorkerId(index as u64);
        let refusal = match message {
            ToMaster::Request(frame) => {
                // Like the master core: only a worker set up for the newest
                // frame may get work (it keeps the frame before too).
                let lapse = self.config.scheduler.requests_lapse_at_frame_start;
                if lapse && frame != self.newest {
                    return;
                }
                self.log(SimInput::Request(id));
                (self.scheduler.request_work(now, id).err()).map(|e| e.to_string())
            }
            ToMaster::Heartbeat => {
                self.log(SimInput::Heartbeat(id));
                (self.scheduler.heartbeat(now, id).err()).map(|e| e.to_string())
            }
            ToMaster::Left => {
                self.log(SimInput::Left(id));
                (self.scheduler.worker_left(now, id).err()).map(|e| e.to_string())
            }
            ToMaster::Failed { package, error } => {
                self.log(SimInput::Failed(id, package, error.clone()));
                (self.scheduler.package_failed(now, id, package, error).err())
                    .map(|e| e.to_string())
            }
            ToMaster::Done {
                assignment,
                measure,
                true_cost,
            } => {
                let key = (assignment.job, assignment.frame);
                let base_ready = self.frame_starts.get(&key).is_none_or(|&at| at <= now);
                if base_ready {
                    self.accept(id, assignment, measure, true_cost)
                } else {
                    // Held for the base image, like the master core does.
                    self.log(SimInput::Arrived(id, assignment.package));
                    let arrived = self.scheduler.package_arrived(now, id, assignment.package);
                    match arrived {
                        Ok(()) => {
                            let held = HeldResult {
                                worker: id,
                                assignment,
                                measure,
                                true_cost,
                            };
                            self.held.entry(key).or_default().push(held);
                            None
                        }
                        Err(e) => Some(e.to_string()),
                    }
                }
            }
        };
        if let Some(refusal) = refusal {
            self.refused(refusal);
        }
    }

    /// The master checks and composites a result (its driver is busy
    /// meanwhile) and hands it to the scheduler.
    fn accept(
        &mut self,
        id: WorkerId,
        assignment: Assignment,
        measure: PackageMeasure,
        true_cost: f64,
    ) -> Option<String> {
        let now = self.now;
        let items = assignment.items.len() as u32;
        self.master_busy_until = now + self.config.master_result_cost_per_item * items;
        self.log(SimInput::Done(id, assignment.package, measure.clone()));
        let done = self
            .scheduler
            .package_done(now, id, assignment.package, measure);
        self.done_outcome(id, assignment, true_cost, done)
    }

    /// A frame's base image is ready: the held results are accepted.
    fn base_ready(&mut self, key: FrameKey) {
        let cost = self.config.master_frame_cost;
        if self.open_jobs.contains(&key.0) && !cost.is_zero() {
            self.log(SimInput::BaseFrameCost(key.0, cost));
            let _ = self.scheduler.base_frame_cost(self.now, key.0, cost);
        }
        self.accept_held(key);
    }

    /// The master accepts the results it held for the frame's base frame.
    fn accept_held(&mut self, key: FrameKey) {
        for held in self.held.remove(&key).unwrap_or_default() {
            let refusal = self.accept(held.worker, held.assignment, held.measure, held.true_cost);
            if let Some(refusal) = refusal {
                self.refused(refusal);
            }
        }
    }

    /// `FrameStart` reaches a worker: it sets the frame up, sharing its core
    /// with the package it computes (if any), which so ends later too.
    fn frame_start(&mut self, index: usize, key: FrameKey) {
        let now = self.now;
        let Some(worker) = self.workers.get_mut(index) else {
            return;
        };
        if !worker.alive {
            return;
        }
        let setup = worker.spec.frame_setup;
        // Processor sharing: both run at half speed while both run.
        let shared = (worker.current.as_ref())
            .map_or(Duration::ZERO, |c| c.ends_at.saturating_sub(now).min(setup));
        worker.frame = Some(key);
        worker.requested = false;
        worker.ready_at = worker.ready_at.max(now) + setup + shared;
        let ready_at = worker.ready_at;
        if let Some(current) = worker.current.as_mut().filter(|_| !shared.is_zero()) {
            worker.token += 1;
            current.token = worker.token;
            current.ends_at += shared;
            let (end, token) = (current.ends_at, current.token);
            self.schedule(
                end,
                SimEvent::ComputeEnd {
                    worker: index,
                    token,
                },
            );
        }
        self.schedule(ready_at, SimEvent::FrameReady(index, key));
    }

    /// A worker with nothing to do asks for work of its newest frame once it
    /// is set up (of any frame when requests do not lapse).
    fn ask_when_idle(&mut self, index: usize) {
        let now = self.now;
        let lapse = self.config.scheduler.requests_lapse_at_frame_start;
        let Some(worker) = self.workers.get_mut(index) else {
            return;
        };
        let idle = worker.alive && worker.current.is_none() && worker.inbox.is_empty();
        let ready = !lapse || (worker.frame.is_some() && now >= worker.ready_at);
        if !idle || !ready || worker.requested {
            return;
        }
        worker.requested = true;
        let frame = if lapse { worker.frame } else { None };
        let latency = worker.spec.latency;
        self.schedule(
            now + latency,
            SimEvent::ToMaster(index, ToMaster::Request(frame)),
        );
    }

    /// Tallies an accepted result; a refused one is returned for the report.
    fn done_outcome(
        &mut self,
        id: WorkerId,
        assignment: Assignment,
        true_cost: f64,
        done: Result<(), vtfarm_scheduler::ReportError>,
    ) -> Option<String> {
        match done {
            Ok(()) => {
                let tally = self
                    .tallies
                    .entry((assignment.job, assignment.frame))
                    .or_default();
                *tally.true_cost.entry(id).or_insert(0.0) += true_cost;
                for item in assignment.items {
                    *tally.completions.entry(item).or_insert(0) += 1;
                }
                None
            }
            Err(error) => Some(error.to_string()),
        }
    }

    fn deliver_to_worker(&mut self, index: usize, message: ToWorker) {
        let Some(worker) = self.workers.get_mut(index) else {
            return;
        };
        if !worker.alive {
            return;
        }
        match message {
            ToWorker::Assign(assignment) => {
                worker.requested = false;
                worker.inbox.push_back(assignment);
                if worker.current.is_none() {
                    self.start_next(index);
                }
            }
            ToWorker::Cancel(package) => {
                worker.inbox.retain(|a| a.package != package);
                let running = worker
                    .current
                    .as_ref()
                    .is_some_and(|c| c.assignment.package == package);
                if running && worker.spec.honours_cancel {
                    worker.current = None;
                    if worker.inbox.is_empty() {
                        self.ask_when_idle(index);
                    } else {
                        self.start_next(index);
                    }
                }
            }
        }
    }

    /// Starts the next package in the worker's inbox, if any.
    fn start_next(&mut self, index: usize) {
        let now = self.now;
        let Some(worker) = self.workers.get_mut(index) else {
            return;
        };
        let Some(assignment) = worker.inbox.pop_front() else {
            return;
        };
        let costs = self
            .costs
            .get(&assignment.job)
            .and_then(|frames| frames.get(assignment.frame as usize));
        // True seconds at speed 1 per item: the work, and how a worker splits its busy time.
        let item_costs: Vec<f64> = assignment
            .items
            .iter()
            .map(|item| costs.and_then(|c| c.get(item)).copied().unwrap_or(0.0))
            .collect();
        let work: f64 = item_costs.iter().sum();
        let fails = match &worker.spec.failures {
            SimFailures::Never => false,
            SimFailures::Always => true,
            SimFailures::FirstPackages(n) => worker.started < *n,
            SimFailures::Items(items) => assignment.items.iter().any(|i| items.contains(i)),
        };
        worker.started += 1;
        worker.token += 1;
        let token = worker.token;
        let compute_from = now + worker.spec.package_overhead;
        let end = if fails {
            compute_from
        } else {
            finish_time(
                compute_from,
                work,
                worker.spec.speed,
                worker.spec.slowdown.as_ref(),
            )
        };
        worker.current = Some(Computing {
            assignment,
            token,
            started_at: now,
            ends_at: end,
            item_costs,
            fails,
        });
        self.schedule(
            end,
            SimEvent::ComputeEnd {
                worker: index,
                token,
            },
        );
    }

    /// A package finished on a worker: it sends the result (and, when it has
    /// nothing else, a request for more) and starts its next package.
    fn compute_end(&mut self, index: usize, token: u64) {
        let now = self.now;
        let config = &self.config;
        let Some(worker) = self.workers.get_mut(index) else {
            return;
        };
        let current = worker.current.take_if(|c| c.token == token);
        let Some(computing) = current.filter(|_| worker.alive) else {
            return;
        };
        let items = computing.assignment.items.len() as u64;
        let bytes_in = config.header_bytes + config.assignment_bytes_per_item * items;
        let bytes_out = config.header_bytes + config.result_bytes_per_item * items;
        let message = if computing.fails {
            ToMaster::Failed {
                package: computing.assignment.package,
                error: format!("simulated failure on {}", worker.id),
            }
        } else {
            let work: f64 = computing.item_costs.iter().sum();
            ToMaster::Done {
                measure: PackageMeasure {
                    busy: now.saturating_sub(computing.started_at),
                    item_seconds: computing.item_costs,
                    rays: (work * config.rays_per_second) as u64,
                    bytes_in,
                    bytes_out,
                },
                true_cost: work,
                assignment: computing.assignment,
            }
        };
        let idle = worker.inbox.is_empty();
        let arrival = self.arrival(index, bytes_out, Direction::ToMaster);
        self.schedule(arrival, SimEvent::ToMaster(index, message));
        if idle {
            // Piggybacked on the result, when the frame is set up.
            let lapse = self.config.scheduler.requests_lapse_at_frame_start;
            let worker = &mut self.workers[index];
            let ready = !lapse || (worker.frame.is_some() && now >= worker.ready_at);
            if ready && !worker.requested {
                worker.requested = true;
                let frame = if lapse { worker.frame } else { None };
                self.schedule(arrival, SimEvent::ToMaster(index, ToMaster::Request(frame)));
            }
        } else {
            self.start_next(index);
        }
    }

    /// Sends the scheduler's assignments and acts on its events as a driver
    /// would: cancellations go to the worker, a worker lost to a heartbeat
    /// timeout is disconnected, completed frames are reported.
    fn drain_outputs(&mut self) {
        let now = self.now;
        while let Some(assignment) = self.scheduler.poll_assignment() {
            let index = assignment.worker.0 as usize;
            if index >= self.workers.len() {
                continue;
            }
            let bytes = self.config.header_bytes
                + self.config.assignment_bytes_per_item * assignment.items.len() as u64;
            let arrival = self.arrival(index, bytes, Direction::ToWorker);
            self.report.assignments.push((now, assignment.clone()));
            self.schedule(
                arrival,
                SimEvent::ToWorker(index, ToWorker::Assign(assignment)),
            );
        }
        while let Some(event) = self.scheduler.poll_event() {
            match &event {
                Event::PackageCancelled { worker, package } => {
                    let index = worker.0 as usize;
                    if let Some(w) = self.workers.get(index) {
                        let arrival = now + w.spec.latency;
                        self.schedule(
                            arrival,
                            SimEvent::ToWorker(index, ToWorker::Cancel(*package)),
                        );
                    }
                }
                Event::WorkerLost {
                    worker,
                    cause: LossCause::HeartbeatTimeout,
                    ..
                } => {
                    // The driver drops the connection; the worker is done.
                    if let Some(w) = self.workers.get_mut(worker.0 as usize) {
                        w.alive = false;
                        w.current = None;
                        w.inbox.clear();
                    }
                }
                Event::FrameStarted {
                    job, frame, whole, ..
                } => {
                    let key = (*job, *frame);
                    // A whole frame's worker renders its base image itself.
                    let ahead = self.bases_ahead.remove(&key);
                    if *whole && *frame == 0 {
                        self.make_bases_ahead(*job);
                    }
                    let base_ready = if *whole {
                        now
                    } else if let Some(at) = ahead {
                        now.max(at)
                    } else {
                        self.master_free =
                            now.max(self.master_free) + self.config.master_frame_cost;
                        self.schedule(self.master_free, SimEvent::BaseReady(key));
                        self.master_free
                    };
                    self.frame_starts.insert(key, base_ready);
                    if ahead.is_some() || *whole {
                        self.schedule(base_ready, SimEvent::HeldReady(key));
                    }
                    self.newest = Some(key);
                    if self.hears_frames() {
                        self.announce_frame(key);
                    }
                }
                Event::FrameComplete { job, frame, stats } => {
                    let tally = self.tallies.remove(&(*job, *frame)).unwrap_or_default();
                    let base_ready = self.frame_starts.remove(&(*job, *frame)).unwrap_or(now);
                    self.report.frames.push(SimFrameReport {
                        job: *job,
                        frame: *frame,
                        at: now,
                        done_at: now.max(base_ready),
                        stats: stats.clone(),
                        true_cost: tally.true_cost,
                        completions: tally.completions,
                    });
                }
                Event::JobComplete { job }
                | Event::JobFailed { job, .. }
                | Event::JobCancelled { job } => {
                    self.open_jobs.remove(job);
                    self.tallies.retain(|(j, _), _| j != job);
                }
                _ => {}
            }
            self.report.events.push((now, event));
        }
    }

    /// The master makes the base frames of `job`'s last frames ahead, one
    /// at a time after the base frames it is making
    /// ([`SimConfig::bases_ahead`]).
    fn make_bases_ahead(&mut self, job: JobId) {
        let frames = self.costs.get(&job).map_or(0, Vec::len) as u32;
        let count = (self.config.bases_ahead)
            .min(self.workers.len())
            .min(frames as usize) as u32;
        for frame in frames - count..frames {
            self.master_free = self.now.max(self.master_free) + self.config.master_frame_cost;
            self.bases_ahead.insert((job, frame), self.master_free);
            self.schedule(self.master_free, SimEvent::BaseAhead((job, frame)));
        }
    }

    /// Whether workers ask for work only once they heard of a frame, as
    /// vtfarm's do (under requests that lapse or frame affinity); else they
    /// ask as soon as they join.
    fn hears_frames(&self) -> bool {
        let rules = &self.config.scheduler;
        rules.requests_lapse_at_frame_start || rules.frame_affinity
    }

    fn refused(&mut self, refusal: String) {
        self.report.refusals.push((self.now, refusal));
    }

    fn log(&mut self, input: SimInput) {
        self.report.inputs.push((self.now, input));
    }

    /// A frame started: every live worker hears of it.
    fn announce_frame(&mut self, key: FrameKey) {
        let start_bytes = self.config.header_bytes;
        for index in 0..self.workers.len() {
            if !self.workers[index].alive {
                continue;
            }
            let arrival = self.arrival(index, start_bytes, Direction::ToWorker);
            self.schedule(arrival, SimEvent::FrameStart(index, key));
        }
    }

    /// When a message of `bytes` sent now by or to worker `index` arrives:
    /// it holds the worker's link and the master's shared one (if there is
    /// one) together, for its size over the slower rate, then the latency.
    fn arrival(&mut self, index: usize, bytes: u64, direction: Direction) -> Duration {
        let Some(worker) = self.workers.get_mut(index) else {
            return self.now;
        };
        let d = direction as usize;
        let master = self.config.master_link_bits_per_second;
        let rate = master.map_or(worker.spec.link_bits_per_second, |m| {
            m.min(worker.spec.link_bits_per_second)
        });
        let mut start = self.now.max(worker.link_free[d]);
        if master.is_some() {
            start = start.max(self.master_link_free[d]);
            self.master_link_free[d] = start + seconds(bytes as f64 * 8.0 / rate);
        }
        let end = start + seconds(bytes as f64 * 8.0 / rate);
        worker.link_free[d] = end;
        end + worker.spec.latency
    }
}

/// When `work` (seconds at speed 1) started at `start` ends on a worker of
/// `speed` that may slow down on the way.
fn finish_time(start: Duration, work: f64, speed: f64, slowdown: Option<&SimSlowdown>) -> Duration {
    let speed = if speed > 0.0 { speed } else { 1e-9 };
    let plain = work / speed;
    let Some(slowdown) = slowdown.filter(|s| s.factor > 0.0) else {
        return start + seconds(plain);
    };
    let (t0, at) = (start.as_secs_f64(), slowdown.at.as_secs_f64());
    let end = if t0 >= at {
        t0 + plain * slowdown.factor
    } else if t0 + plain <= at {
        t0 + plain
    } else {
        at + (work - (at - t0) * speed) / speed * slowdown.factor
    };
    seconds(end)
}

/// `x` seconds, 0 for NaN or negatives, capped at 10⁹ s.
fn seconds(x: f64) -> Duration {
    if x.is_nan() || x <= 0.0 {
        Duration::ZERO
    } else {
        Duration::from_secs_f64(x.min(1e9))
    }
}
