//! The scheduler state machine: inputs (`worker_*`, `request_work`,
//! `package_*`, `submit_job`, `cancel_job`, `pause_job`, `resume_job`,
//! `set_priority`, `handle_timeout`) change the
//! state and queue outputs, which the driver takes with `poll_assignment`,
//! `poll_event` and `poll_timeout`.
//!
//! Every input that can create, free or end work ends in `dispatch`, which
//! starts queued jobs and frames, fails a job nobody may work on, and hands
//! work to the waiting workers.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::ops::Range;
use std::time::Duration;

use crate::costs::CostModel;
use crate::frame::{Attempt, Frame, Package};
use crate::{
    Assignment, CancelError, Counters, Event, FrameWork, InvariantError, JobFailure, JobId,
    JobProgress, JoinError, LossCause, PackageId, PackageMeasure, PackageState, QueueOptions,
    QueueStatus, ReportError, SchedulerConfig, StragglerPolicy, SubmitError, WorkerError,
    WorkerFrameStats, WorkerId, WorkerState, WorkerStatus,
};

/// The master's scheduler and load balancer. See the crate documentation for
/// the policy and the state tables.
#[derive(Debug)]
pub struct Scheduler {
    config: SchedulerConfig,
    /// The latest `now` seen; inputs with an earlier one are read as this.
    now: Duration,
    workers: BTreeMap<WorkerId, Worker>,
    /// Workers that asked for work and got none yet, in the order they asked.
    waiting: VecDeque<WorkerId>,
    queued_jobs: VecDeque<QueuedJob>,
    /// The jobs that started and are not over, by rank ([`rank`]: the
    /// view's first, then priority, then id).
    running: Vec<RunningJob>,
    next_package: u64,
    assignments: VecDeque<Assignment>,
    events: VecDeque<Event>,
    counters: Counters,
}

#[derive(Debug)]
struct Worker {
    threads: u32,
    connected: bool,
    last_seen: Duration,
    wants_work: bool,
    /// Packages it runs, of any running job.
    running: BTreeSet<PackageId>,
    /// The job of its latest package: `status` shows its rates there.
    latest_job: Option<JobId>,
    /// Its measures in that job once the job ended (for `status`).
    ended_measures: Option<Measures>,
    packages_done: u64,
    items_done: u64,
    busy: Duration,
    failures: u64,
    /// Running frames (job, index) it got packages of (so has set up),
    /// for [`SchedulerConfig::frame_affinity`].
    frames: BTreeSet<(JobId, u32)>,
    /// The frame it took its last own (not duplicate) package of: its crew.
    crew: Option<(JobId, u32)>,
}

/// What a worker measured in one job: rates are in the job's cost unit
/// (its first frame's items cost [`CostEstimation::initial_item_cost`](crate::CostEstimation::initial_item_cost)
/// each), so each running job keeps its own.
#[derive(Debug, Default)]
struct Measures {
    /// Smoothed cost units per second from assignment to result.
    rate: Option<f64>,
    /// Cost units per busy second of its last packages, newest last.
    compute_samples: VecDeque<f64>,
}

#[derive(Debug)]
struct QueuedJob {
    id: JobId,
    frames: Vec<FrameWork>,
    /// Higher starts first; equal priorities start in id order.
    priority: i32,
    /// A paused job does not start.
    paused: bool,
    interactive: bool,
}

#[derive(Debug)]
struct RunningJob {
    id: JobId,
    priority: i32,
    /// A paused job hands out nothing new; its running packages finish.
    paused: bool,
    /// Frames not started yet.
    frames: VecDeque<FrameWork>,
    /// Every frame split, none whole ([`Scheduler::submit_interactive_job`]).
    interactive: bool,
    frame_count: u32,
    costs: CostModel,
    failures_by_worker: BTreeMap<WorkerId, u32>,
    blocklist: BTreeSet<WorkerId>,
    /// Every failure reported in the job, in order.
    errors: Vec<(WorkerId, String)>,
    /// The oldest running frame: frames complete in order.
    frame: Frame,
    /// The frames after it, started early, oldest first
    /// ([`SchedulerConfig::frames_in_flight`]).
    ahead: VecDeque<Frame>,
    /// Estimated cost of the next frames not started yet (`frames`), kept
    /// by [`RunningJob::estimate_unstarted`].
    unstarted_cost: f64,
    /// Each worker's rates in this job's cost unit.
    measures: BTreeMap<WorkerId, Measures>,
    /// What its tail's split frames cost, as measured ([`TailCosts`]).
    tail: TailCosts,
}

/// What a batch job's tail rule ([`tail_frames`]) reads: a whole frame's
/// time on a worker and the master's time per base frame, both measured,
/// and the frames whose base frames the master made ahead.
#[derive(Debug, Default)]
struct TailCosts {
    /// Smoothed busy seconds of the job's whole frames on their workers.
    whole_frame_seconds: Option<f64>,
    /// The least seconds of the master's base frames made alone
    /// ([`Scheduler::base_frame_cost`]).
    base_frame_seconds: Option<f64>,
    /// Frames not started whose base frames the master holds ready
    /// ([`Scheduler::base_frame_ahead`]).
    bases_ahead: BTreeSet<u32>,
}

impl TailCosts {
    /// Whether both times the tail rule reads are measured.
    fn is_measured(&self) -> bool {
        self.whole_frame_seconds.is_some() && self.base_frame_seconds.is_some()
    }
}

impl RunningJob {
    /// The frames not started yet that count towards whole frames (none
    /// for an interactive job).
    fn batch_frames_left(&self) -> usize {
        if self.interactive {
            0
        } else {
            self.frames.len()
        }
    }

    /// Estimates the next `lookahead` frames not started yet anew: after a
    /// frame started or the cost estimates learned from a complete one.
    /// With [`SchedulerConfig::frames_in_flight`] frames the whole-job bound
    /// on package sizes no longer binds (a crew's share of one frame is
    /// smaller), and summing every frame of a long job at every frame start
    /// would cost its frames squared.
    fn estimate_unstarted(&mut self, lookahead: usize) {
        let costs = &self.costs;
        self.unstarted_cost = (self.frames.iter().take(lookahead))
            .flat_map(|f| &f.items)
            .map(|&item| costs.estimate(item))
            .sum();
    }

    /// Estimated cost of the job's work that no worker runs yet: the running
    /// frames' unassigned work and the frames not started.
    fn remaining_cost(&self) -> f64 {
        let running: f64 = self.running_frames().map(Frame::unassigned_cost).sum();
        running + self.unstarted_cost
    }

    /// The running frames, oldest first.
    fn running_frames(&self) -> impl Iterator<Item = &Frame> {
        std::iter::once(&self.frame).chain(&self.ahead)
    }

    fn running_frames_mut(&mut self) -> impl Iterator<Item = &mut Frame> {
        std::iter::once(&mut self.frame).chain(self.ahead.iter_mut())
    }

    /// The running frame a package belongs to.
    fn frame_of(&self, package: PackageId) -> Option<&Frame> {
        (self.running_frames()).find(|f| f.packages.contains_key(&package))
    }

    fn frame_of_mut(&mut self, package: PackageId) -> Option<&mut Frame> {
        (self.running_frames_mut()).find(|f| f.packages.contains_key(&package))
    }

    /// The running frame with this index.
    fn frame_mut(&mut self, index: u32) -> Option<&mut Frame> {
        (self.running_frames_mut()).find(|f| f.index == index)
    }

    /// Its running frames that are split (each holds a base frame of the
    /// master's).
    fn split_frames(&self) -> usize {
        self.running_frames().filter(|f| !f.whole).count()
    }

    /// The packages of its frames that run now (one or two copies).
    fn running_packages(&self) -> impl Iterator<Item = (&PackageId, &Package)> {
        (self.running_frames())
            .flat_map(|f| &f.packages)
            .filter(|(_, p)| !p.attempts.is_empty())
    }

    /// Where it stands among the jobs ([`rank`]).
    fn rank(&self) -> (Reverse<i32>, JobId) {
        rank(self.priority, self.id)
    }
}

/// The order jobs run in: the highest priority first (the view's jobs
/// carry the highest), the lowest id (the earliest submitted) among
/// equals. A waiting worker takes work of the first job in this order that
/// has work it may take.
fn rank(priority: i32, id: JobId) -> (Reverse<i32>, JobId) {
    (Reverse(priority), id)
}

/// The smallest crew under frame affinity: a small farm keeps every
/// worker on every frame (a frame's latency stays short and one slow
/// worker never holds a frame alone); set-ups only matter once a worker's
/// share of a frame is small.
const MIN_CREW: usize = 4;

/// Frames in flight that no crew is sized for under frame affinity. Frames
/// complete in order, so besides the crews' frames a slot is held by the
/// oldest frame while its last packages run and by frames done but waiting
/// for it; with one more free, a crew whose frame has nothing left to hand
/// out starts the next frame instead of finding no room and spreading over
/// the other crews' frames, each worker paying a set-up for a small share
/// (at 64 simulated workers such helping doubled the set-ups per frame).
const SPARE_FRAMES: u32 = 3;

/// Whole frames in flight per worker (see [`SchedulerConfig::whole_frames`]):
/// each worker runs one and holds the next, asked for one package ahead.
/// Beyond them [`SchedulerConfig::frames_in_flight`] more may be in flight,
/// done and waiting for an older one (frames complete in order; a slower
/// worker's frame holds them). The crate documentation gives the reason.
pub const WHOLE_FRAMES_PER_WORKER: usize = 2;

/// How many recent packages a worker's compute rate is the median of.
const COMPUTE_SAMPLES: usize = 16;

/// What a waiting worker gets.
#[derive(Clone, Copy, Debug)]
enum Pick {
    /// The next unassigned items of frame `frame`, up to position `end`.
    Fresh { frame: u32, end: usize },
    /// The queued package at `index` of frame `frame`'s queue, or its part
    /// before `split`.
    Queued {
        frame: u32,
        index: usize,
        split: usize,
    },
    /// A second copy of a straggler.
    Duplicate(PackageId),
}

/// What one running job has for a waiting worker.
#[derive(Clone, Copy, Debug)]
enum Offer {
    Take(Pick),
    /// Nothing yet, but a frame of its own may start for it (frame affinity).
    NewFrame,
    Nothing,
}

/// What a waiting worker gets, from all the jobs.
#[derive(Clone, Copy, Debug)]
enum Choice {
    /// Work of running job `j`.
    Take(usize, Pick),
    /// It waits for a job (ranked so) to start a frame, or to start.
    Wait((Reverse<i32>, JobId), Wanted),
    Nothing,
}

/// What a waiting worker waits for.
#[derive(Clone, Copy, Debug)]
enum Wanted {
    /// A frame of this running job to start for it.
    Frame(JobId),
    /// This queued job to start.
    Job(JobId),
}

impl Scheduler {
    pub fn new(config: SchedulerConfig) -> Scheduler {
        Scheduler {
            config,
            now: Duration::ZERO,
            workers: BTreeMap::new(),
            waiting: VecDeque::new(),
            queued_jobs: VecDeque::new(),
            running: Vec::new(),
            next_package: 0,
            assignments: VecDeque::new(),
            events: VecDeque::new(),
            counters: Counters::default(),
        }
    }

    pub fn config(&self) -> &SchedulerConfig {
        &self.config
    }

    // ----- Inputs -----

    /// A worker connected with `threads` threads (0 is read as 1). A worker
    /// that was gone may join again under its old id and keeps its rate.
    pub fn worker_joined(
        &mut self,
        now: Duration,
        worker: WorkerId,
        threads: u32,
    ) -> Result<(), JoinError> {
        let now = self.advance(now);
        let threads = threads.max(1);
        match self.workers.get_mut(&worker) {
            Some(w) if w.connected => return Err(JoinError::AlreadyConnected(worker)),
            // Gone → Idle.
            Some(w) => {
                w.connected = true;
                w.threads = threads;
                w.last_seen = now;
            }
            // (new) → Idle.
            None => {
                self.workers.insert(
                    worker,
                    Worker {
                        threads,
                        connected: true,
                        last_seen: now,
                        wants_work: false,
                        running: BTreeSet::new(),
                        latest_job: None,
                        ended_measures: None,
                        packages_done: 0,
                        items_done: 0,
                        busy: Duration::ZERO,
                        failures: 0,
                        frames: BTreeSet::new(),
                        crew: None,
                    },
                );
            }
        }
        Ok(())
    }

    /// The worker disconnected: its packages go back to the queue.
    pub fn worker_left(&mut self, now: Duration, worker: WorkerId) -> Result<(), WorkerError> {
        self.advance(now);
        self.connected(worker)?;
        self.lose(worker, LossCause::Left);
        self.dispatch();
        Ok(())
    }

    /// The worker is alive. Every other input from a worker counts as a
    /// heartbeat too.
    pub fn heartbeat(&mut self, now: Duration, worker: WorkerId) -> Result<(), WorkerError> {
        self.advance(now);
        self.connected(worker)?;
        self.touch(worker);
        Ok(())
    }

    /// The worker asks for a package (Idle or Busy → Waiting). The package, now
    /// or once there is work, comes out of [`Scheduler::poll_assignment`]. Asking
    /// again before getting one changes nothing; asking while running a
    /// package lets the driver keep a worker's pipeline full.
    pub fn request_work(&mut self, now: Duration, worker: WorkerId) -> Result<(), WorkerError> {
        self.advance(now);
        self.connected(worker)?;
        self.touch(worker);
        if let Some(w) = self.workers.get_mut(&worker) {
            if !w.wants_work {
                w.wants_work = true;
                self.waiting.push_back(worker);
            }
        }
        self.dispatch();
        Ok(())
    }

    /// Queues a job: jobs run by rank (priority, then id; several at once
    /// when workers would otherwise idle, see the crate documentation), the
    /// frames of a job one after another. A job without frames completes at
    /// once; a frame without items completes at once.
    pub fn submit_job(
        &mut self,
        now: Duration,
        job: JobId,
        frames: Vec<FrameWork>,
    ) -> Result<(), SubmitError> {
        self.submit_job_with(now, job, frames, QueueOptions::default())
    }

    /// Queues a job whose frames' latency is what counts (the interactive
    /// view's stages): every frame is split over the workers, none is whole
    /// ([`SchedulerConfig::whole_frames`]). Otherwise as [`Scheduler::submit_job`].
    pub fn submit_interactive_job(
        &mut self,
        now: Duration,
        job: JobId,
        frames: Vec<FrameWork>,
    ) -> Result<(), SubmitError> {
        let options = QueueOptions {
            interactive: true,
            ..QueueOptions::default()
        };
        self.submit_job_with(now, job, frames, options)
    }

    /// [`Scheduler::submit_job`] at a priority, perhaps paused (a job
    /// restored paused) or interactive: a queued job of a higher priority
    /// starts first, equal priorities in id order.
    pub fn submit_job_with(
        &mut self,
        now: Duration,
        job: JobId,
        frames: Vec<FrameWork>,
        options: QueueOptions,
    ) -> Result<(), SubmitError> {
        self.advance(now);
        let started = self.running.iter().any(|r| r.id == job);
        if started || self.queued_jobs.iter().any(|q| q.id == job) {
            return Err(SubmitError::DuplicateJob(job));
        }
        self.queued_jobs.push_back(QueuedJob {
            id: job,
            frames,
            priority: options.priority,
            paused: options.paused,
            interactive: options.interactive,
        });
        self.dispatch();
        Ok(())
    }

    /// Pauses a queued or running job: it starts no frame and hands out no
    /// package until [`Scheduler::resume_job`]; its running packages finish
    /// and their results count.
    pub fn pause_job(&mut self, now: Duration, job: JobId) -> Result<(), CancelError> {
        self.set_paused(now, job, true)
    }

    /// Lets a paused job go on.
    pub fn resume_job(&mut self, now: Duration, job: JobId) -> Result<(), CancelError> {
        self.set_paused(now, job, false)
    }

    fn set_paused(&mut self, now: Duration, job: JobId, paused: bool) -> Result<(), CancelError> {
        self.advance(now);
        if let Some(queued) = self.queued_jobs.iter_mut().find(|q| q.id == job) {
            queued.paused = paused;
        } else if let Some(running) = self.running.iter_mut().find(|r| r.id == job) {
            if running.paused && !paused {
                self.events.push_back(Event::JobResumed { job });
            }
            running.paused = paused;
        } else {
            return Err(CancelError::UnknownJob(job));
        }
        self.dispatch();
        Ok(())
    }

    /// Changes a queued or running job's priority.
    pub fn set_priority(
        &mut self,
        now: Duration,
        job: JobId,
        priority: i32,
    ) -> Result<(), CancelError> {
        self.advance(now);
        if let Some(queued) = self.queued_jobs.iter_mut().find(|q| q.id == job) {
            queued.priority = priority;
        } else if let Some(running) = self.running.iter_mut().find(|r| r.id == job) {
            running.priority = priority;
            self.running.sort_by_key(RunningJob::rank);
        } else {
            return Err(CancelError::UnknownJob(job));
        }
        self.dispatch();
        Ok(())
    }

    /// The master made one of `job`'s base frames in `cost`, with no other
    /// base frame in the making meanwhile: its measured time per split
    /// frame's base frame, the least reported (a report also holds the
    /// master's waits for other work, which only add to it: a job's start
    /// keeps the master busy). With the job's measured whole-frame time it
    /// bounds how many of the job's last frames are split (see the crate
    /// documentation's Whole frames). A zero cost is ignored.
    pub fn base_frame_cost(
        &mut self,
        now: Duration,
        job: JobId,
        cost: Duration,
    ) -> Result<(), CancelError> {
        self.advance(now);
        let j = self.job_index(job).ok_or(CancelError::UnknownJob(job))?;
        let tail = &mut self.running[j].tail;
        let seconds = cost.as_secs_f64();
        if seconds > 0.0 {
            let least = tail.base_frame_seconds.map_or(seconds, |s| s.min(seconds));
            tail.base_frame_seconds = Some(least);
        }
        self.dispatch();
        Ok(())
    }

    /// The master holds the base frame of `job`'s frame `frame` ready, made
    /// ahead while the job's whole frames ran: splitting that frame costs
    /// the master no base frame at the tail. A frame that started already
    /// is ignored.
    pub fn base_frame_ahead(
        &mut self,
        now: Duration,
        job: JobId,
        frame: u32,
    ) -> Result<(), CancelError> {
        self.advance(now);
        let j = self.job_index(job).ok_or(CancelError::UnknownJob(job))?;
        let job = &mut self.running[j];
        let next = (job.frame_count).saturating_sub(job.frames.len() as u32);
        if frame >= next {
            job.tail.bases_ahead.insert(frame);
        }
        self.dispatch();
        Ok(())
    }

    /// The running job with this id.
    fn job_index(&self, job: JobId) -> Option<usize> {
        self.running.iter().position(|r| r.id == job)
    }

    /// The running job a package of a running frame belongs to.
    fn job_of(&self, package: PackageId) -> Option<usize> {
        (self.running.iter()).position(|job| job.frame_of(package).is_some())
    }

    /// A package of a running frame, wherever it runs.
    fn package(&self, package: PackageId) -> Option<&Package> {
        let job = &self.running[self.job_of(package)?];
        job.frame_of(package)?.packages.get(&package)
    }

    /// Cancels a queued or running job. The packages of a running job are
    /// cancelled ([`Event::PackageCancelled`] for each copy), then
    /// [`Event::JobCancelled`].
    pub fn cancel_job(&mut self, now: Duration, job: JobId) -> Result<(), CancelError> {
        self.advance(now);
        if let Some(index) = self.queued_jobs.iter().position(|q| q.id == job) {
            self.queued_jobs.remove(index);
        } else if let Some(index) = self.job_index(job) {
            self.abandon_job(index);
        } else {
            return Err(CancelError::UnknownJob(job));
        }
        self.events.push_back(Event::JobCancelled { job });
        self.dispatch();
        Ok(())
    }

    /// The worker finished the package. The first result of a package wins;
    /// the other copy of a straggler is cancelled. A late, duplicate or
    /// unknown result is ignored, counted, and explained by the error.
    pub fn package_done(
        &mut self,
        now: Duration,
        worker: WorkerId,
        package: PackageId,
        measure: PackageMeasure,
    ) -> Result<(), ReportError> {
        self.advance(now);
        self.check_report(worker, package)?;
        self.complete(worker, package, &measure);
        self.dispatch();
        Ok(())
    }

    /// The worker's result for the package arrived, but the driver accepts
    /// it only later (it checks results against the frame's base image,
    /// which may still be in the making): the package no longer runs late,
    /// so it is not duplicated, and the worker's rate is measured up to now.
    /// [`Scheduler::package_done`] or [`Scheduler::package_failed`] follows.
    pub fn package_arrived(
        &mut self,
        now: Duration,
        worker: WorkerId,
        package: PackageId,
    ) -> Result<(), ReportError> {
        let now = self.advance(now);
        self.check_report(worker, package)?;
        let attempt = (self.job_of(package))
            .and_then(|j| self.running[j].frame_of_mut(package))
            .and_then(|frame| frame.packages.get_mut(&package))
            .and_then(|p| {
                let index = p.attempt_of(worker)?;
                p.attempts.get_mut(index)
            });
        if let Some(attempt) = attempt {
            attempt.arrived_at.get_or_insert(now);
        }
        Ok(())
    }

    /// The worker could not compute the package. It is retried on another
    /// worker; see [`RetryPolicy`](crate::RetryPolicy) for when the worker is
    /// blocklisted and when the job fails.
    pub fn package_failed(
        &mut self,
        now: Duration,
        worker: WorkerId,
        package: PackageId,
        error: String,
    ) -> Result<(), ReportError> {
        self.advance(now);
        self.check_report(worker, package)?;
        self.fail_attempt(worker, package, error);
        self.dispatch();
        Ok(())
    }

    /// Acts on the deadlines due at `now`: workers whose heartbeat expired are
    /// lost, stragglers are duplicated to waiting workers.
    pub fn handle_timeout(&mut self, now: Duration) {
        let now = self.advance(now);
        let timeout = self.config.heartbeat_timeout;
        let expired: Vec<WorkerId> = self
            .workers
            .iter()
            .filter(|(_, w)| w.connected && w.last_seen.saturating_add(timeout) <= now)
            .map(|(&id, _)| id)
            .collect();
        for worker in expired {
            self.lose(worker, LossCause::HeartbeatTimeout);
        }
        self.dispatch();
    }

    // ----- Outputs -----

    /// The next package to send, in the order they were handed out.
    pub fn poll_assignment(&mut self) -> Option<Assignment> {
        self.assignments.pop_front()
    }

    /// The next event, in the order they happened.
    pub fn poll_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    /// When [`Scheduler::handle_timeout`] should be called next: the earliest
    /// heartbeat expiry, or the moment a running package becomes a straggler
    /// that a waiting worker could take.
    pub fn poll_timeout(&self) -> Option<Duration> {
        let timeout = self.config.heartbeat_timeout;
        let heartbeat = self
            .workers
            .values()
            .filter(|w| w.connected)
            .map(|w| w.last_seen.saturating_add(timeout))
            .min();
        let straggler = self.straggler_deadline();
        heartbeat.into_iter().chain(straggler).min()
    }

    // ----- Views -----

    /// Whether a job is queued or running.
    pub fn has_jobs(&self) -> bool {
        !self.running.is_empty() || !self.queued_jobs.is_empty()
    }

    /// Every worker ever joined, by id, for a `status` listing; its rates
    /// are those in the job of its latest package while that job runs.
    pub fn workers(&self) -> Vec<WorkerStatus> {
        self.workers
            .iter()
            .map(|(&id, w)| {
                let running = (w.latest_job.and_then(|job| self.job_index(job)))
                    .map(|j| self.running[j].measures.get(&id));
                let measures = running.unwrap_or(w.ended_measures.as_ref());
                (id, w, measures)
            })
            .map(|(id, w, measures)| WorkerStatus {
                worker: id,
                state: w.state(),
                threads: w.threads,
                rate: measures.and_then(|m| m.rate),
                compute_rate: measures.and_then(Measures::compute_rate),
                running: w.running.len(),
                packages_done: w.packages_done,
                items_done: w.items_done,
                busy: w.busy,
                failures: w.failures,
            })
            .collect()
    }

    pub fn worker_state(&self, worker: WorkerId) -> Option<WorkerState> {
        self.workers.get(&worker).map(Worker::state)
    }

    /// The state of a package of a running frame; `None` for packages of
    /// finished frames and jobs.
    pub fn package_state(&self, package: PackageId) -> Option<PackageState> {
        self.package(package).map(Package::state)
    }

    /// The job queue and the running jobs' progress, each in rank order.
    pub fn queue(&self) -> QueueStatus {
        let mut waiting: Vec<&QueuedJob> = self.queued_jobs.iter().collect();
        waiting.sort_by_key(|q| rank(q.priority, q.id));
        QueueStatus {
            waiting: waiting.into_iter().map(|q| q.id).collect(),
            running: (self.running.iter())
                .map(|job| JobProgress {
                    job: job.id,
                    frame: job.frame.index,
                    frames: job.frame_count,
                    items_done: job.frame.done_count,
                    items_total: job.frame.items.len(),
                    packages_running: job.running_packages().count(),
                    paused: job.paused,
                    blocklisted: job.blocklist.iter().copied().collect(),
                })
                .collect(),
        }
    }

    /// Ignored inputs so far.
    pub fn counters(&self) -> Counters {
        self.counters
    }

    /// Checks every internal invariant (for tests and fuzzing): each item of
    /// the running frame is in exactly one place (unassigned, one queued or
    /// running package, or one done package), package states match their
    /// copies and the queue, and workers' packages match the packages' copies.
    pub fn validate(&self) -> Result<(), InvariantError> {
        let fail = |message: String| Err(InvariantError(message));
        for (&id, w) in &self.workers {
            let listed = self.waiting.iter().filter(|&&x| x == id).count();
            if listed != usize::from(w.wants_work) {
                return fail(format!("{id} listed {listed} times as waiting"));
            }
            if !w.connected && (w.wants_work || !w.running.is_empty()) {
                return fail(format!("{id} is gone but waits or runs packages"));
            }
            for package in &w.running {
                let runs = self.package(*package).and_then(|p| p.attempt_of(id));
                if runs.is_none() {
                    return fail(format!("{id} lists {package} but does not run it"));
                }
            }
            let has_frame = |&(job, index): &(JobId, u32)| {
                (self.job_index(job))
                    .is_some_and(|j| (self.running[j].running_frames()).any(|f| f.index == index))
            };
            if let Some(stale) = (w.frames.iter().chain(&w.crew)).find(|f| !has_frame(f)) {
                return fail(format!("{id} keeps {stale:?}, no running frame"));
            }
        }
        if self.waiting.iter().any(|w| !self.workers.contains_key(w)) {
            return fail("an unknown worker waits".to_string());
        }
        let ranks: Vec<_> = self.running.iter().map(RunningJob::rank).collect();
        if ranks.windows(2).any(|w| w[0] >= w[1]) {
            return fail(format!("running jobs {ranks:?} are not in rank order"));
        }
        if let Some(q) = (self.queued_jobs.iter()).find(|q| self.job_index(q.id).is_some()) {
            return fail(format!("{} is queued and running", q.id));
        }
        for job in &self.running {
            let indices: Vec<u32> = job.running_frames().map(|f| f.index).collect();
            if indices.windows(2).any(|w| w[1] != w[0] + 1) {
                return fail(format!(
                    "{}: running frames {indices:?} are not consecutive",
                    job.id
                ));
            }
            if job.split_frames() > self.config.frames_in_flight.max(1) as usize {
                return fail(format!("{}: {} split frames", job.id, job.split_frames()));
            }
            for frame in job.running_frames() {
                self.validate_frame(frame)?;
            }
        }
        Ok(())
    }

    /// Checks one running frame's items and packages (see `validate`).
    fn validate_frame(&self, frame: &Frame) -> Result<(), InvariantError> {
        let fail = |message: String| Err(InvariantError(message));
        let n = frame.items.len();
        let mut owners = vec![0u32; n];
        for owner in &mut owners[frame.next_fresh..] {
            *owner += 1;
        }
        let mut done = vec![false; n];
        for (&id, p) in &frame.packages {
            let copies = p.attempts.len();
            let queued = frame.queue.iter().filter(|&&q| q == id).count();
            let expected = match p.state() {
                PackageState::Queued => (0, 1),
                PackageState::Assigned => (1, 0),
                PackageState::Duplicated => (2, 0),
                PackageState::Done => (0, 0),
                PackageState::Failed | PackageState::Cancelled => {
                    return fail(format!("{id} is {:?} in a running frame", p.state()));
                }
            };
            if (copies, queued) != expected {
                return fail(format!(
                    "{id} is {:?} with {copies} copies, queued {queued} times",
                    p.state()
                ));
            }
            if p.range.is_empty() || p.range.end > frame.next_fresh {
                return fail(format!("{id} covers {:?}", p.range));
            }
            if frame.whole && p.range != (0..n) {
                return fail(format!("{id} covers {:?} of a whole frame", p.range));
            }
            if copies == 2 && p.attempts[0].worker == p.attempts[1].worker {
                return fail(format!("{id} runs twice on one worker"));
            }
            for a in &p.attempts {
                let listed = self
                    .workers
                    .get(&a.worker)
                    .is_some_and(|w| w.connected && w.running.contains(&id));
                if !listed {
                    return fail(format!("{} does not list {id}", a.worker));
                }
            }
            for position in p.range.clone() {
                owners[position] += 1;
                done[position] = p.state() == PackageState::Done;
            }
        }
        if let Some(position) = owners.iter().position(|&o| o != 1) {
            return fail(format!(
                "position {position} is in {} places",
                owners[position]
            ));
        }
        if done != frame.done || frame.done.iter().filter(|&&d| d).count() != frame.done_count {
            return fail("done items do not match done packages".to_string());
        }
        Ok(())
    }

    // ----- Bookkeeping -----

    fn advance(&mut self, now: Duration) -> Duration {
        self.now = self.now.max(now);
        self.now
    }

    fn connected(&self, worker: WorkerId) -> Result<(), WorkerError> {
        match self.workers.get(&worker) {
            Some(w) if w.connected => Ok(()),
            _ => Err(WorkerError::NotConnected(worker)),
        }
    }

    fn touch(&mut self, worker: WorkerId) {
        if let Some(w) = self.workers.get_mut(&worker) {
            w.last_seen = self.now;
        }
    }

    /// Accepts a result only for a package the worker runs now, counting why
    /// it refused otherwise. Accepted or not, a result from a connected
    /// worker is a heartbeat.
    fn check_report(&mut self, worker: WorkerId, package: PackageId) -> Result<(), ReportError> {
        if self.connected(worker).is_err() {
            self.counters.results_not_connected += 1;
            return Err(ReportError::NotConnected(worker));
        }
        self.touch(worker);
        let current = self.package(package);
        let refusal = match current {
            Some(p) if p.state().is_final() => Some(ReportError::Finished(package)),
            Some(p) if p.attempt_of(worker).is_none() => {
                Some(ReportError::NotAssigned { package, worker })
            }
            Some(_) => None,
            // Ids are handed out in order, so a lower one belonged to a frame
            // or job that is over.
            None if package.0 < self.next_package => Some(ReportError::Finished(package)),
            None => Some(ReportError::UnknownPackage(package)),
        };
        let Some(refusal) = refusal else {
            return Ok(());
        };
        let counter = match refusal {
            ReportError::NotConnected(_) => &mut self.counters.results_not_connected,
            ReportError::UnknownPackage(_) => &mut self.counters.results_unknown_package,
            ReportError::Finished(_) => &mut self.counters.results_finished,
            ReportError::NotAssigned { .. } => &mut self.counters.results_not_assigned,
        };
        *counter += 1;
        Err(refusal)
    }

    /// Starts queued jobs and frames, fails a job nobody may work on, then
    /// hands work to the waiting workers in the order they asked, each from
    /// the first job in rank order that has work it may take.
    fn dispatch(&mut self) {
        loop {
            self.start_jobs_and_frames();
            // A worker waits for a frame of its own to start (frame
            // affinity) or for a queued job: the first such in rank order
            // starts, and hand-out runs again. Handing out a frame's last
            // work may start the next frame too.
            match self.hand_out() {
                Some(Wanted::Frame(job)) => {
                    if let Some(j) = self.job_index(job) {
                        self.start_ahead(j);
                    }
                }
                Some(Wanted::Job(job)) => self.start_queued(job),
                None if (0..self.running.len()).any(|j| self.may_start_ahead(j)) => {}
                None => break,
            }
        }
    }

    /// Completes finished frames and jobs, starts frames, and fails a job
    /// nobody may work on.
    fn start_jobs_and_frames(&mut self) {
        loop {
            self.advance_jobs();
            let Some(j) = (0..self.running.len()).find(|&j| self.no_eligible_worker(j)) else {
                break;
            };
            let errors = self.running[j].errors.clone();
            self.fail_job(j, JobFailure::NoEligibleWorker, errors);
        }
    }

    /// Hands work to the waiting workers in the order they asked, each from
    /// the first job in rank order with work it may take. Returns what the
    /// first in rank order of the workers left waiting waits for.
    fn hand_out(&mut self) -> Option<Wanted> {
        let mut wanted: Option<((Reverse<i32>, JobId), Wanted)> = None;
        let mut index = 0;
        while index < self.waiting.len() {
            let worker = self.waiting[index];
            match self.choose(worker) {
                Choice::Take(j, pick) => {
                    self.waiting.remove(index);
                    self.assign(j, worker, pick);
                }
                Choice::Wait(at, what) => {
                    if wanted.as_ref().is_none_or(|(best, _)| at < *best) {
                        wanted = Some((at, what));
                    }
                    index += 1;
                }
                Choice::Nothing => index += 1,
            }
        }
        wanted.map(|(_, what)| what)
    }

    /// What `worker` gets: walking the running and the queued jobs (not
    /// paused) in rank order, the first that has work it may take gives it,
    /// or starts a frame for it (frame affinity), or, queued, starts.
    fn choose(&self, worker: WorkerId) -> Choice {
        let mut queued: Vec<&QueuedJob> = (self.queued_jobs.iter()).filter(|q| !q.paused).collect();
        queued.sort_by_key(|q| rank(q.priority, q.id));
        let mut queued = queued.into_iter().peekable();
        // The first queued job ranked before `before` (or any, for `None`).
        let mut start = |before: Option<(Reverse<i32>, JobId)>| {
            let q = queued.next_if(|q| before.is_none_or(|b| rank(q.priority, q.id) < b))?;
            Some(Choice::Wait(rank(q.priority, q.id), Wanted::Job(q.id)))
        };
        for (j, job) in self.running.iter().enumerate() {
            if let Some(choice) = start(Some(job.rank())) {
                return choice;
            }
            match self.pick(j, worker) {
                Offer::Take(pick) => return Choice::Take(j, pick),
                Offer::NewFrame => return Choice::Wait(job.rank(), Wanted::Frame(job.id)),
                Offer::Nothing => {}
            }
        }
        start(None).unwrap_or(Choice::Nothing)
    }

    /// Whether the next frame of running job `j` starts early
    /// ([`SchedulerConfig::frames_in_flight`]): its newest running frame
    /// has nothing left to hand out, and it has room for a frame.
    fn may_start_ahead(&self, j: usize) -> bool {
        let job = &self.running[j];
        let newest = job.ahead.back().unwrap_or(&job.frame);
        !newest.has_unassigned() && self.room_for_a_frame(j)
    }

    /// Whether another frame of running job `j` may start now (beside the
    /// one it runs): split frames while the split frames of `j` and of the
    /// jobs ranked before it are fewer than
    /// [`SchedulerConfig::frames_in_flight`] (each holds a base frame of
    /// the master's, made one at a time, so a lower job never holds the
    /// slots a higher one needs), whole ones up to
    /// [`WHOLE_FRAMES_PER_WORKER`] per eligible worker beyond that (beyond
    /// nothing while the job's tail is unmeasured).
    fn room_for_a_frame(&self, j: usize) -> bool {
        let job = &self.running[j];
        if job.paused || job.frames.is_empty() || job.frame.is_complete() {
            return false;
        }
        let frames_in_flight = self.config.frames_in_flight as usize;
        if starts_whole(&self.config, &self.workers, job) {
            let workers = self.eligible_workers(job).count().max(1);
            // Until the tail is measured no frames beyond the workers' own
            // two: such a frame waits for a worker's third round, and the
            // tail's split frames, though done, wait for it (frames
            // complete in order) while the other workers idle.
            let beyond = if job.tail.is_measured() {
                frames_in_flight
            } else {
                0
            };
            job.ahead.len() + 1 < beyond + WHOLE_FRAMES_PER_WORKER * workers
        } else {
            let split: usize = self.running[..=j]
                .iter()
                .map(RunningJob::split_frames)
                .sum();
            split < frames_in_flight
        }
    }

    /// Completes finished frames and jobs and starts their next frames, and
    /// frames early where they may; starts the first queued job when none
    /// runs (a worker asks for work once it knows of a job).
    fn advance_jobs(&mut self) {
        let mut j = 0;
        loop {
            if j == self.running.len() {
                let first = (self.queued_jobs.iter())
                    .filter(|q| !q.paused)
                    .min_by_key(|q| rank(q.priority, q.id))
                    .map(|q| q.id);
                match first.filter(|_| self.running.is_empty()) {
                    Some(id) => {
                        self.start_queued(id);
                        j = 0;
                        continue;
                    }
                    None => return,
                }
            }
            if self.running[j].frame.is_complete() {
                // The job's next frame, or the next job, is at `j` now.
                self.finish_oldest_frame(j);
                continue;
            }
            if self.may_start_ahead(j) {
                self.start_ahead(j);
            }
            j += 1;
        }
    }

    /// Completes running job `j`'s oldest frame, which is complete: the
    /// next frame takes its place (started already, or now), or the job is
    /// complete and leaves.
    fn finish_oldest_frame(&mut self, j: usize) {
        let lookahead = self.config.frames_in_flight as usize;
        let job = &mut self.running[j];
        let speeds: BTreeMap<WorkerId, f64> = (job.measures.iter())
            .filter_map(|(&id, m)| Some((id, m.compute_rate()?)))
            .collect();
        job.costs.learn(&job.frame, &speeds);
        job.estimate_unstarted(lookahead);
        let finished = (job.id, job.frame.index);
        for w in self.workers.values_mut() {
            w.frames.remove(&finished);
            w.crew = w.crew.filter(|&c| c != finished);
        }
        let stats = job.frame.finish_stats(self.now);
        self.events.push_back(Event::FrameComplete {
            job: job.id,
            frame: job.frame.index,
            stats,
        });
        if let Some(next) = job.ahead.pop_front() {
            // Started already; the estimates now learn from this frame too.
            job.frame = next;
            job.frame.reestimate(&job.costs);
            for frame in &mut job.ahead {
                frame.reestimate(&job.costs);
            }
            return;
        }
        let whole = starts_whole(&self.config, &self.workers, job);
        match job.frames.pop_front() {
            Some(next) => {
                let index = job.frame.index + 1;
                job.tail.bases_ahead.remove(&index);
                job.frame = Frame::new(index, next.items, whole, &job.costs);
                job.estimate_unstarted(lookahead);
                self.events.push_back(Event::FrameStarted {
                    job: job.id,
                    frame: index,
                    items: job.frame.items.len(),
                    whole,
                });
                self.lapse_requests();
            }
            None => {
                self.events.push_back(Event::JobComplete { job: job.id });
                self.end_job(j);
            }
        }
    }

    /// Removes running job `j` (complete, failed or cancelled): the workers
    /// forget its frames, its measures go with it.
    fn end_job(&mut self, j: usize) -> RunningJob {
        let mut job = self.running.remove(j);
        for (id, w) in &mut self.workers {
            w.frames.retain(|&(id, _)| id != job.id);
            w.crew = w.crew.filter(|&(id, _)| id != job.id);
            if w.latest_job == Some(job.id) {
                w.ended_measures = job.measures.remove(id);
            }
        }
        job
    }

    /// Starts running job `j`'s next frame while its running frame finishes.
    fn start_ahead(&mut self, j: usize) {
        let lookahead = self.config.frames_in_flight as usize;
        let job = &mut self.running[j];
        let whole = starts_whole(&self.config, &self.workers, job);
        let Some(next) = job.frames.pop_front() else {
            return;
        };
        let index = job.ahead.back().unwrap_or(&job.frame).index + 1;
        job.tail.bases_ahead.remove(&index);
        let ahead = Frame::new(index, next.items, whole, &job.costs);
        job.estimate_unstarted(lookahead);
        self.events.push_back(Event::FrameStarted {
            job: job.id,
            frame: index,
            items: ahead.items.len(),
            whole,
        });
        job.ahead.push_back(ahead);
        self.lapse_requests();
    }

    /// At a frame's start, forgets who asked for work, when so configured.
    fn lapse_requests(&mut self) {
        if !self.config.requests_lapse_at_frame_start {
            return;
        }
        for &id in &self.waiting {
            if let Some(w) = self.workers.get_mut(&id) {
                w.wants_work = false;
            }
        }
        self.waiting.clear();
    }

    /// Starts the queued job `id`: it joins the running jobs at its rank,
    /// with rates of its own (they are in its cost unit).
    fn start_queued(&mut self, id: JobId) {
        let Some(index) = self.queued_jobs.iter().position(|q| q.id == id) else {
            return;
        };
        let next = self.queued_jobs.remove(index).expect("found above");
        let frame_count = u32::try_from(next.frames.len()).unwrap_or(u32::MAX);
        self.events.push_back(Event::JobStarted {
            job: next.id,
            frames: frame_count,
        });
        let mut frames = VecDeque::from(next.frames);
        let Some(first) = frames.pop_front() else {
            self.events.push_back(Event::JobComplete { job: next.id });
            return;
        };
        let costs = CostModel::new(self.config.estimation.initial_item_cost);
        let unstarted = if next.interactive {
            0
        } else {
            frames.len() + 1
        };
        let whole = starts_whole_with(
            &self.config,
            &self.workers,
            &BTreeSet::new(),
            unstarted,
            frame_count,
            &TailCosts::default(),
        );
        let frame = Frame::new(0, first.items, whole, &costs);
        self.events.push_back(Event::FrameStarted {
            job: next.id,
            frame: 0,
            items: frame.items.len(),
            whole,
        });
        self.lapse_requests();
        let mut job = RunningJob {
            id: next.id,
            priority: next.priority,
            paused: false,
            frames,
            interactive: next.interactive,
            frame_count,
            costs,
            failures_by_worker: BTreeMap::new(),
            blocklist: BTreeSet::new(),
            errors: Vec::new(),
            frame,
            ahead: VecDeque::new(),
            unstarted_cost: 0.0,
            measures: BTreeMap::new(),
            tail: TailCosts::default(),
        };
        job.estimate_unstarted(self.config.frames_in_flight as usize);
        let at = (self.running).partition_point(|r| r.rank() < job.rank());
        self.running.insert(at, job);
    }

    /// Whether running job `j` has work left that no connected worker may
    /// take, because every one is blocklisted (with no worker connected,
    /// the job waits for one).
    fn no_eligible_worker(&self, j: usize) -> bool {
        let job = &self.running[j];
        let mut connected = self.workers.iter().filter(|(_, w)| w.connected).peekable();
        job.running_frames().any(Frame::has_unassigned)
            && connected.peek().is_some()
            && connected.all(|(id, _)| job.blocklist.contains(id))
    }

    // ----- Package sizing -----

    /// What running job `j` has for `worker`: a queued package it may take
    /// (split when much larger than its target), else the next unassigned
    /// items, else, once nothing is left to hand out, a straggler's second
    /// copy; or, under frame affinity, a frame to start for it. A paused
    /// job, or one that blocklisted the worker, has nothing.
    fn pick(&self, j: usize, worker: WorkerId) -> Offer {
        let job = &self.running[j];
        if job.blocklist.contains(&worker) || job.paused {
            return Offer::Nothing;
        }
        if self.config.frame_affinity {
            if let Some(pick) = self.copy_of_a_late_oldest_frame(job, worker) {
                return Offer::Take(pick);
            }
            match self.pick_with_affinity(j, worker) {
                Offer::Nothing => {}
                offer => return offer,
            }
            if job.running_frames().any(Frame::has_unassigned) {
                return Offer::Nothing;
            }
        } else {
            let target = self.target_cost(job, worker);
            // Unassigned work of the older frame first; stragglers only once
            // both frames have nothing left to hand out.
            for frame in job.running_frames() {
                if let Some(pick) = self.pick_unassigned(job, frame, worker, target) {
                    return Offer::Take(pick);
                }
            }
            if job.running_frames().any(|f| !f.queue.is_empty()) {
                return Offer::Nothing;
            }
        }
        let Some(policy) = self.config.straggler.as_ref() else {
            return Offer::Nothing;
        };
        let no_room = !self.room_for_a_frame(j);
        (job.running_packages())
            .filter(|(_, p)| may_duplicate(p, worker))
            .filter(|(id, p)| {
                straggler_deadline(p, policy) <= self.now
                    || (no_room && self.whole_copy_due(job, **id, p, worker, policy))
            })
            .min_by_key(|&(&id, p)| (straggler_deadline(p, policy), id))
            .map_or(Offer::Nothing, |(&id, _)| Offer::Take(Pick::Duplicate(id)))
    }

    /// A copy of the oldest running frame when it is whole and its holder is
    /// late ([`Scheduler::whole_copy_late_at`]): frames complete in order,
    /// so every frame after it waits for it, and a copy comes before new
    /// work.
    fn copy_of_a_late_oldest_frame(&self, job: &RunningJob, worker: WorkerId) -> Option<Pick> {
        let policy = self.config.straggler.as_ref()?;
        let frame = Some(&job.frame).filter(|f| f.whole)?;
        let (&id, package) = (frame.packages.iter()).find(|(_, p)| may_duplicate(p, worker))?;
        let late_at = self.whole_copy_late_at(job, frame, package, policy)?;
        (late_at <= self.now).then_some(Pick::Duplicate(id))
    }

    /// Whether a waiting worker that may start no frame takes a copy of
    /// package `id` because it is a whole frame's: its holder is late by
    /// its rate as now measured ([`Scheduler::whole_copy_late_at`]), or
    /// `worker` would finish a copy in less than `1 / factor` of the time
    /// the holder is still expected to need. So a slow worker never holds
    /// the frame that the others wait for (frames complete in order) or
    /// the job's last frames alone, though it was given its frame before
    /// its speed was known.
    fn whole_copy_due(
        &self,
        job: &RunningJob,
        id: PackageId,
        package: &Package,
        worker: WorkerId,
        policy: &StragglerPolicy,
    ) -> bool {
        let Some(frame) = job.frame_of(id).filter(|f| f.whole) else {
            return false;
        };
        let (Some(attempt), Some(late_at)) = (
            package.attempts.first(),
            self.whole_copy_late_at(job, frame, package, policy),
        ) else {
            return false;
        };
        let cost = frame.cost(package.range.clone());
        let expected_end = attempt.assigned_at + seconds(cost / self.rate_of(job, attempt.worker));
        let left = expected_end.saturating_sub(self.now);
        let copy = seconds(policy.factor * cost / self.rate_of(job, worker));
        late_at <= self.now || copy < left
    }

    /// When the running copy of a whole frame's package counts as late:
    /// `max(factor · expected, min_delay)` after it was handed out, with
    /// the expectation from its worker's rate as now measured (not as
    /// guessed when the frame was handed out, before its first result).
    /// `None` for a package of a split frame.
    fn whole_copy_late_at(
        &self,
        job: &RunningJob,
        frame: &Frame,
        package: &Package,
        policy: &StragglerPolicy,
    ) -> Option<Duration> {
        let attempt = package.attempts.first().filter(|_| frame.whole)?;
        let expected = frame.cost(package.range.clone()) / self.rate_of(job, attempt.worker);
        let wait = seconds(expected * policy.factor).max(policy.min_delay);
        Some(attempt.assigned_at.saturating_add(wait))
    }

    /// Unassigned work of running job `j` for `worker` under frame
    /// affinity: of a frame it has (oldest first), else requeued work of
    /// any frame (frames complete in order), else of a frame whose crew is
    /// short; else a new frame while one may start (the dispatcher starts
    /// it for this worker), and once none may, of the oldest frame with
    /// work left.
    fn pick_with_affinity(&self, j: usize, worker: WorkerId) -> Offer {
        let job = &self.running[j];
        let Some(w) = self.workers.get(&worker) else {
            return Offer::Nothing;
        };
        let pick = |frame: &Frame| {
            let target = self.crew_target(job, worker, frame);
            self.pick_unassigned(job, frame, worker, target)
        };
        let own = (job.running_frames()).filter(|f| w.frames.contains(&(job.id, f.index)));
        if let Some(pick) = own.filter_map(pick).next() {
            return Offer::Take(pick);
        }
        let requeued = (job.running_frames())
            .filter(|f| !f.queue.is_empty())
            .filter_map(pick)
            .find(|p| matches!(p, Pick::Queued { .. }));
        if let Some(pick) = requeued {
            return Offer::Take(pick);
        }
        let size = self.crew_size(job);
        let short = (job.running_frames())
            .filter(|f| f.next_fresh < f.items.len())
            .find(|f| self.crew_of(job.id, f.index) < size);
        if let Some(frame) = short {
            return pick(frame).map_or(Offer::Nothing, Offer::Take);
        }
        if self.room_for_a_frame(j) {
            return Offer::NewFrame;
        }
        (job.running_frames().filter_map(pick).next()).map_or(Offer::Nothing, Offer::Take)
    }

    /// Workers per frame under frame affinity: the eligible workers spread
    /// over the frames in flight but [`SPARE_FRAMES`] (at least one crew),
    /// but at least [`MIN_CREW`].
    fn crew_size(&self, job: &RunningJob) -> usize {
        let crews = (self.config.frames_in_flight.saturating_sub(SPARE_FRAMES)).max(1) as usize;
        self.eligible_workers(job)
            .count()
            .div_ceil(crews)
            .max(MIN_CREW)
    }

    /// Connected workers not blocklisted for `job`.
    fn eligible_workers<'a>(&'a self, job: &'a RunningJob) -> impl Iterator<Item = &'a Worker> {
        self.eligible_ids(job).map(|(_, w)| w)
    }

    /// Connected workers not blocklisted for `job`, with their ids.
    fn eligible_ids<'a>(
        &'a self,
        job: &'a RunningJob,
    ) -> impl Iterator<Item = (WorkerId, &'a Worker)> {
        (self.workers.iter())
            .filter(|(id, w)| w.connected && !job.blocklist.contains(id))
            .map(|(&id, w)| (id, w))
    }

    /// Connected workers whose crew is frame `index` of `job`.
    fn crew_of(&self, job: JobId, index: u32) -> usize {
        (self.workers.values())
            .filter(|w| w.connected && w.crew == Some((job, index)))
            .count()
    }

    /// The cost of `worker`'s next package of `frame` under frame affinity:
    /// guided self-scheduling within the frame's crew (the frame's
    /// unassigned work over `k` times a full crew's rate), and no more than
    /// guided self-scheduling over the whole job (its remaining work over
    /// `k` times every worker's rate) gives: near the job's end, or in a
    /// job shorter than the farm is wide, every worker shares the last
    /// frames, so their packages shrink for all of them, not for one crew.
    fn crew_target(&self, job: &RunningJob, worker: WorkerId, frame: &Frame) -> f64 {
        let prior = self.prior_rate_per_thread(job);
        let (sum, count) = (self.eligible_ids(job)).fold((0.0, 0usize), |(sum, n), (id, w)| {
            (sum + rate_with_prior(job, id, w, prior), n + 1)
        });
        let crew_rate = sum / count.max(1) as f64 * self.crew_size(job) as f64;
        let crew = self.sized(frame.unassigned_cost(), crew_rate);
        let whole_job = self.sized(job.remaining_cost(), sum);
        crew.min(whole_job) * self.rate_of(job, worker)
    }

    /// A queued package of `frame` that `worker` may take (split when much
    /// larger than `target`), else the frame's next unassigned items.
    fn pick_unassigned(
        &self,
        job: &RunningJob,
        frame: &Frame,
        worker: WorkerId,
        target: f64,
    ) -> Option<Pick> {
        let split_factor = self.config.sizing.split_factor;
        for (index, id) in frame.queue.iter().enumerate() {
            let Some(package) = frame.packages.get(id) else {
                continue;
            };
            if !self.may_retry(job, package, worker) {
                continue;
            }
            let split = if !frame.whole && frame.cost(package.range.clone()) > split_factor * target
            {
                frame.cut(package.range.clone(), target)
            } else {
                package.range.end
            };
            let frame = frame.index;
            return Some(Pick::Queued {
                frame,
                index,
                split,
            });
        }
        (frame.next_fresh < frame.items.len()).then(|| Pick::Fresh {
            frame: frame.index,
            end: if frame.whole {
                frame.items.len()
            } else {
                frame.cut(frame.next_fresh..frame.items.len(), target)
            },
        })
    }

    /// A worker retries a package it failed only when every worker that may
    /// work on the job failed it too.
    fn may_retry(&self, job: &RunningJob, package: &Package, worker: WorkerId) -> bool {
        if !package.failed_on(worker) {
            return true;
        }
        self.workers
            .iter()
            .filter(|(id, w)| w.connected && !job.blocklist.contains(id))
            .all(|(&id, _)| package.failed_on(id))
    }

    /// The cost of the next package for `worker` (see
    /// [`PackageSizing`](crate::PackageSizing)).
    fn target_cost(&self, job: &RunningJob, worker: WorkerId) -> f64 {
        let prior = self.prior_rate_per_thread(job);
        let total_rate: f64 = (self.eligible_ids(job))
            .map(|(id, w)| rate_with_prior(job, id, w, prior))
            .sum();
        let unassigned: f64 = job.running_frames().map(Frame::unassigned_cost).sum();
        self.sized(unassigned, total_rate) * self.rate_of(job, worker)
    }

    /// A package's target duration in seconds: `unassigned` work over `k`
    /// times `rate`, clamped (see [`PackageSizing`](crate::PackageSizing)).
    fn sized(&self, unassigned: f64, rate: f64) -> f64 {
        let sizing = &self.config.sizing;
        let k = if sizing.guided_factor >= 1.0 {
            sizing.guided_factor
        } else {
            1.0
        };
        let seconds = unassigned / (k * rate);
        let min = sizing.min_duration.as_secs_f64();
        let max = sizing.max_duration.as_secs_f64().max(min);
        if seconds.is_nan() {
            max
        } else {
            seconds.clamp(min, max)
        }
    }

    /// The worker's rate in `job` (see [`rate_with_prior`]).
    fn rate_of(&self, job: &RunningJob, worker: WorkerId) -> f64 {
        let prior = self.prior_rate_per_thread(job);
        (self.workers.get(&worker)).map_or(0.0, |w| rate_with_prior(job, worker, w, prior))
    }

    /// The rate per thread assumed for a worker before its first result in
    /// `job`: the mean over the job's measured connected workers, else the
    /// configured one.
    fn prior_rate_per_thread(&self, job: &RunningJob) -> f64 {
        let (sum, count) = (job.measures.iter())
            .filter_map(|(id, m)| Some((self.workers.get(id)?, m.rate?)))
            .filter(|(w, _)| w.connected)
            .map(|(w, rate)| rate / f64::from(w.threads))
            .fold((0.0, 0), |(sum, count), r| (sum + r, count + 1));
        let initial = self.config.estimation.initial_rate_per_thread;
        if count > 0 {
            sum / f64::from(count)
        } else if initial.is_finite() && initial > 0.0 {
            initial
        } else {
            1.0
        }
    }

    /// The earliest moment a running package of any running job becomes
    /// a straggler that a waiting worker could take.
    fn straggler_deadline(&self) -> Option<Duration> {
        (0..self.running.len())
            .filter_map(|j| self.straggler_deadline_of(j))
            .min()
    }

    /// The earliest moment a running package of running job `j` becomes a
    /// straggler that a waiting worker could take; `None` while work is
    /// left to hand out (but for a late whole oldest frame).
    fn straggler_deadline_of(&self, j: usize) -> Option<Duration> {
        let policy = self.config.straggler.as_ref()?;
        let job = &self.running[j];
        if job.paused {
            return None;
        }
        let oldest_late = (job.frame.packages.values())
            .filter(|p| {
                (self.waiting.iter()).any(|&w| !job.blocklist.contains(&w) && may_duplicate(p, w))
            })
            .filter_map(|p| self.whole_copy_late_at(job, &job.frame, p, policy))
            .min();
        if job.running_frames().any(Frame::has_unassigned) {
            return oldest_late;
        }
        let takers: Vec<WorkerId> = self
            .waiting
            .iter()
            .copied()
            .filter(|w| !job.blocklist.contains(w))
            .collect();
        let no_room = !self.room_for_a_frame(j);
        (job.running_packages())
            .filter(|(_, p)| takers.iter().any(|&w| may_duplicate(p, w)))
            .map(|(id, p)| {
                let late = (job.frame_of(*id).filter(|_| no_room))
                    .and_then(|frame| self.whole_copy_late_at(job, frame, p, policy));
                straggler_deadline(p, policy).min(late.unwrap_or(Duration::MAX))
            })
            .chain(oldest_late)
            .min()
    }

    // ----- Transitions -----

    /// Hands `pick` to `worker`: (new) → Assigned, Queued → Assigned, or
    /// Assigned → Duplicated; the worker goes Waiting → Busy.
    fn assign(&mut self, j: usize, worker: WorkerId, pick: Pick) {
        let now = self.now;
        let rate = self.rate_of(&self.running[j], worker);
        let job = &mut self.running[j];
        let job_id = job.id;
        let frame = match pick {
            Pick::Fresh { frame, .. } | Pick::Queued { frame, .. } => job.frame_mut(frame),
            Pick::Duplicate(id) => job.frame_of_mut(id),
        };
        let Some(frame) = frame else {
            return;
        };
        let attempt_for = |cost: f64| Attempt {
            worker,
            assigned_at: now,
            expected: seconds(cost / rate),
            arrived_at: None,
        };
        let (id, range, cost, duplicate) = match pick {
            Pick::Fresh { end, .. } => {
                let id = PackageId(self.next_package);
                self.next_package += 1;
                let range = frame.next_fresh..end;
                let cost = frame.cost(range.clone());
                frame.next_fresh = end;
                let package = Package::assigned(range.clone(), attempt_for(cost), Vec::new());
                frame.packages.insert(id, package);
                (id, range, cost, false)
            }
            Pick::Queued { index, split, .. } => {
                let Some(&queued) = frame.queue.get(index) else {
                    return;
                };
                let Some(package) = frame.packages.get_mut(&queued) else {
                    return;
                };
                if split < package.range.end {
                    // The first part becomes a new package; the rest stays
                    // queued under its id, both keep the failure history.
                    let id = PackageId(self.next_package);
                    self.next_package += 1;
                    let head = package.range.start..split;
                    package.range.start = split;
                    let failures = package.failures.clone();
                    let cost = frame.cost(head.clone());
                    let package = Package::assigned(head.clone(), attempt_for(cost), failures);
                    frame.packages.insert(id, package);
                    (id, head, cost, false)
                } else {
                    let range = package.range.clone();
                    let cost = frame.cost(range.clone());
                    frame.queue.remove(index);
                    let Some(package) = frame.packages.get_mut(&queued) else {
                        return;
                    };
                    package.set_state(PackageState::Assigned);
                    package.attempts.push(attempt_for(cost));
                    (queued, range, cost, false)
                }
            }
            Pick::Duplicate(id) => {
                let Some(range) = frame.packages.get(&id).map(|p| p.range.clone()) else {
                    return;
                };
                let cost = frame.cost(range.clone());
                let Some(package) = frame.packages.get_mut(&id) else {
                    return;
                };
                package.set_state(PackageState::Duplicated);
                package.attempts.push(attempt_for(cost));
                frame.stats.duplicates += 1;
                (id, range, cost, true)
            }
        };
        frame.started.get_or_insert(now);
        if let Some(w) = self.workers.get_mut(&worker) {
            w.running.insert(id);
            w.wants_work = false;
            w.latest_job = Some(job_id);
            w.frames.insert((job_id, frame.index));
            if !duplicate {
                w.crew = Some((job_id, frame.index));
            }
        }
        self.assignments.push_back(Assignment {
            worker,
            package: id,
            job: job_id,
            frame: frame.index,
            items: frame.items[range].to_vec(),
            estimated_cost: cost,
            expected: seconds(cost / rate),
            duplicate,
            whole: frame.whole,
        });
    }

    /// Accepts a result: Assigned or Duplicated → Done, the other copy (if
    /// any) is cancelled; the worker goes Busy → Idle when it runs nothing
    /// else. Completes the frame when it was the last package.
    fn complete(&mut self, worker: WorkerId, id: PackageId, measure: &PackageMeasure) {
        let now = self.now;
        let smoothing = self.config.estimation.rate_smoothing;
        let Some(j) = self.job_of(id) else {
            return;
        };
        let job = &mut self.running[j];
        let measures = job.measures.entry(worker).or_default();
        let frames = std::iter::once(&mut job.frame).chain(job.ahead.iter_mut());
        let Some(frame) = frames.into_iter().find(|f| f.packages.contains_key(&id)) else {
            return;
        };
        let Some(package) = frame.packages.get_mut(&id) else {
            return;
        };
        let Some(index) = package.attempt_of(worker) else {
            return;
        };
        let attempt = package.attempts.remove(index);
        let losers = std::mem::take(&mut package.attempts);
        package.set_state(PackageState::Done);
        package.completed_by = Some(worker);
        let range = package.range.clone();
        let cost = frame.cost(range.clone());
        let whole = frame.whole;

        let busy = measure.busy.as_secs_f64();
        let weights = split_weights(measure, frame, range.clone());
        let weight_sum: f64 = weights.iter().sum();
        for (position, weight) in range.clone().zip(weights) {
            debug_assert!(!frame.done[position], "position {position} done twice");
            frame.done[position] = true;
            frame.measured[position] = busy * weight / weight_sum;
        }
        frame.done_count += range.len();
        frame.stats.packages += 1;
        let stats = frame
            .worker_stats
            .entry(worker)
            .or_insert_with(|| WorkerFrameStats {
                worker,
                busy: Duration::ZERO,
                packages: 0,
                items: 0,
                estimated_cost: 0.0,
                rays: 0,
                bytes_in: 0,
                bytes_out: 0,
            });
        stats.busy += measure.busy;
        stats.packages += 1;
        stats.items += u32::try_from(range.len()).unwrap_or(u32::MAX);
        stats.estimated_cost += cost;
        stats.rays += measure.rays;
        stats.bytes_in += measure.bytes_in;
        stats.bytes_out += measure.bytes_out;

        // Up to its arrival: a result held by the driver is not slow.
        let arrived = attempt.arrived_at.unwrap_or(now);
        let elapsed = arrived.saturating_sub(attempt.assigned_at).as_secs_f64();
        measures.rate = smooth(measures.rate, cost / elapsed, smoothing);
        let compute_rate = cost / busy;
        if compute_rate.is_finite() && compute_rate > 0.0 {
            if measures.compute_samples.len() == COMPUTE_SAMPLES {
                measures.compute_samples.pop_front();
            }
            measures.compute_samples.push_back(compute_rate);
        }
        if whole {
            let seconds = &mut job.tail.whole_frame_seconds;
            *seconds = smooth_seconds(*seconds, measure.busy, smoothing);
        }
        if let Some(w) = self.workers.get_mut(&worker) {
            w.running.remove(&id);
            w.packages_done += 1;
            w.items_done += range.len() as u64;
            w.busy += measure.busy;
        }
        for loser in losers {
            self.cancel_losing_copy(j, id, cost, loser);
        }
    }

    /// The other copy of a package that just completed is cancelled. That it
    /// had not finished is news about its worker: its rate is at most
    /// `cost / elapsed`.
    fn cancel_losing_copy(&mut self, j: usize, id: PackageId, cost: f64, loser: Attempt) {
        let bound = cost / self.now.saturating_sub(loser.assigned_at).as_secs_f64();
        let rate = self.rate_of(&self.running[j], loser.worker);
        if let Some(w) = self.workers.get_mut(&loser.worker) {
            w.running.remove(&id);
        }
        let job = &mut self.running[j];
        if bound.is_finite() && bound > 0.0 && bound < rate {
            job.measures.entry(loser.worker).or_default().rate = Some(bound);
        }
        if let Some(frame) = job.frame_of_mut(id) {
            frame.stats.cancelled_copies += 1;
        }
        self.events.push_back(Event::PackageCancelled {
            worker: loser.worker,
            package: id,
        });
    }

    /// A copy failed: Assigned → Queued (retry, at the front), Duplicated →
    /// Assigned (the other copy runs on), or Assigned → Failed when the
    /// package failed on enough different workers, which fails the job. The
    /// worker is blocklisted for the job after enough failures.
    fn fail_attempt(&mut self, worker: WorkerId, id: PackageId, error: String) {
        let retry = self.config.retry.clone();
        let Some(j) = self.job_of(id) else {
            return;
        };
        let job = &mut self.running[j];
        let Some(frame) = job.frame_of_mut(id) else {
            return;
        };
        let Some(package) = frame.packages.get_mut(&id) else {
            return;
        };
        let Some(index) = package.attempt_of(worker) else {
            return;
        };
        package.attempts.remove(index);
        package.failures.push((worker, error.clone()));
        frame.stats.failures += 1;
        let job_fails = if !package.attempts.is_empty() {
            package.set_state(PackageState::Assigned);
            None
        } else if package.failed_workers() >= retry.package_failures as usize {
            package.set_state(PackageState::Failed);
            Some(package.failures.clone())
        } else {
            package.set_state(PackageState::Queued);
            frame.queue.push_front(id);
            None
        };
        job.errors.push((worker, error));
        if let Some(w) = self.workers.get_mut(&worker) {
            w.running.remove(&id);
            w.failures += 1;
        }
        let count = job.failures_by_worker.entry(worker).or_insert(0);
        *count += 1;
        if *count >= retry.worker_failures_per_job && job.blocklist.insert(worker) {
            self.events.push_back(Event::WorkerBlocklisted {
                worker,
                job: job.id,
            });
        }
        if let Some(errors) = job_fails {
            self.fail_job(j, JobFailure::PackageFailed(id), errors);
        }
    }

    /// The worker left or timed out: Idle, Waiting or Busy → Gone. Each
    /// package it ran goes Assigned → Queued (to the front of the queue, in
    /// item order) or Duplicated → Assigned.
    fn lose(&mut self, worker: WorkerId, cause: LossCause) {
        let Some(w) = self.workers.get_mut(&worker) else {
            return;
        };
        w.connected = false;
        w.wants_work = false;
        let running = std::mem::take(&mut w.running);
        self.waiting.retain(|&x| x != worker);
        let mut all_requeued: Vec<PackageId> = Vec::new();
        for job in &mut self.running {
            for frame in job.running_frames_mut() {
                let mut requeued: Vec<(usize, PackageId)> = Vec::new();
                for &id in &running {
                    let Some(package) = frame.packages.get_mut(&id) else {
                        continue;
                    };
                    if let Some(index) = package.attempt_of(worker) {
                        package.attempts.remove(index);
                    }
                    if package.attempts.is_empty() {
                        package.set_state(PackageState::Queued);
                        requeued.push((package.range.start, id));
                    } else {
                        package.set_state(PackageState::Assigned);
                    }
                }
                requeued.sort_unstable();
                for &(_, id) in requeued.iter().rev() {
                    frame.queue.push_front(id);
                }
                frame.stats.requeued += u32::try_from(requeued.len()).unwrap_or(u32::MAX);
                all_requeued.extend(requeued.into_iter().map(|(_, id)| id));
            }
        }
        self.events.push_back(Event::WorkerLost {
            worker,
            cause,
            requeued: all_requeued,
        });
    }

    /// Fails running job `j`: its packages are cancelled, then
    /// [`Event::JobFailed`].
    fn fail_job(&mut self, j: usize, reason: JobFailure, errors: Vec<(WorkerId, String)>) {
        let job = self.abandon_job(j);
        self.events.push_back(Event::JobFailed {
            job,
            reason,
            errors,
        });
    }

    /// Ends running job `j`: every package not final goes → Cancelled,
    /// with [`Event::PackageCancelled`] for each copy that runs (only the
    /// job's holders are told).
    fn abandon_job(&mut self, j: usize) -> JobId {
        let mut job = self.end_job(j);
        for frame in job.running_frames_mut() {
            for (&id, package) in &mut frame.packages {
                if package.state().is_final() {
                    continue;
                }
                for attempt in std::mem::take(&mut package.attempts) {
                    if let Some(w) = self.workers.get_mut(&attempt.worker) {
                        w.running.remove(&id);
                    }
                    self.events.push_back(Event::PackageCancelled {
                        worker: attempt.worker,
                        package: id,
                    });
                }
                package.set_state(PackageState::Cancelled);
            }
        }
        job.id
    }
}

/// A worker's measured rate in `job`, or before its first result there
/// `prior_per_thread` times its threads.
fn rate_with_prior(job: &RunningJob, id: WorkerId, worker: &Worker, prior_per_thread: f64) -> f64 {
    (job.measures.get(&id).and_then(|m| m.rate))
        .unwrap_or(prior_per_thread * f64::from(worker.threads))
}

impl Measures {
    /// The median of its recent per-package compute rates. A package whose
    /// cost was misestimated (a hot spot in the first frame) gives an outlier
    /// that the median ignores, so that the worker's speed is not confused
    /// with the cost of the items it happened to get.
    fn compute_rate(&self) -> Option<f64> {
        let mut samples: Vec<f64> = self.compute_samples.iter().copied().collect();
        if samples.is_empty() {
            return None;
        }
        samples.sort_by(f64::total_cmp);
        let middle = samples.len() / 2;
        Some(if samples.len() % 2 == 0 {
            (samples[middle - 1] + samples[middle]) / 2.0
        } else {
            samples[middle]
        })
    }
}

impl Worker {
    fn state(&self) -> WorkerState {
        if !self.connected {
            WorkerState::Gone
        } else if self.wants_work {
            WorkerState::Waiting
        } else if !self.running.is_empty() {
            WorkerState::Busy
        } else {
            WorkerState::Idle
        }
    }
}

/// Whether `worker` may run a second copy of `package`.
fn may_duplicate(package: &Package, worker: WorkerId) -> bool {
    package.state() == PackageState::Assigned
        && package.attempt_of(worker).is_none()
        && !package.failed_on(worker)
        // Its result is here, waiting for the driver's check.
        && package.attempts.iter().all(|a| a.arrived_at.is_none())
}

/// Whether the next frame of `job` to start is whole
/// ([`SchedulerConfig::whole_frames`]): more of its frames are not started
/// (the next included) than its tail ([`tail_frames`]) splits.
fn starts_whole(
    config: &SchedulerConfig,
    workers: &BTreeMap<WorkerId, Worker>,
    job: &RunningJob,
) -> bool {
    let unstarted = job.batch_frames_left();
    starts_whole_with(
        config,
        workers,
        &job.blocklist,
        unstarted,
        job.frame_count,
        &job.tail,
    )
}

/// [`starts_whole`] for a job's next frame with `unstarted` frames not
/// started (it included) of `frame_count`.
fn starts_whole_with(
    config: &SchedulerConfig,
    workers: &BTreeMap<WorkerId, Worker>,
    blocklist: &BTreeSet<WorkerId>,
    unstarted: usize,
    frame_count: u32,
    tail: &TailCosts,
) -> bool {
    let eligible = (workers.iter())
        .filter(|(id, w)| w.connected && !blocklist.contains(id))
        .count();
    config.whole_frames
        && config.frame_affinity
        && unstarted > tail_frames(config, eligible, frame_count, tail)
}

/// How many of a batch job's last frames are split (its tail; see the
/// crate documentation's Whole frames): no more than the `eligible`
/// workers, and, once a whole frame's time on a worker and the master's
/// time per base frame are measured, only as many as the master makes the
/// base frames of within one whole frame (one at a time), those it made
/// ahead costing nothing. Until then no more than
/// [`SchedulerConfig::frames_in_flight`]. At least one: a job's last frame
/// is always split.
fn tail_frames(
    config: &SchedulerConfig,
    eligible: usize,
    frame_count: u32,
    tail: &TailCosts,
) -> usize {
    let widest = eligible.max(1);
    let (Some(whole), Some(base)) = (tail.whole_frame_seconds, tail.base_frame_seconds) else {
        return widest.min(config.frames_in_flight as usize).max(1);
    };
    let affordable = if base > 0.0 {
        (whole / base).floor()
    } else {
        f64::INFINITY
    };
    let mut to_make = 0.0;
    let mut split = 0;
    for index in (0..frame_count).rev().take(widest) {
        if !tail.bases_ahead.contains(&index) {
            if to_make + 1.0 > affordable {
                break;
            }
            to_make += 1.0;
        }
        split += 1;
    }
    split.max(1)
}

/// When the running copy of an assigned package becomes a straggler.
fn straggler_deadline(package: &Package, policy: &StragglerPolicy) -> Duration {
    let Some(attempt) = package.attempts.first() else {
        return Duration::MAX;
    };
    let wait = seconds(attempt.expected.as_secs_f64() * policy.factor).max(policy.min_delay);
    attempt.assigned_at.saturating_add(wait)
}

/// How a package's busy time splits over its items: the worker's split when
/// it is usable, else the estimates.
fn split_weights(measure: &PackageMeasure, frame: &Frame, range: Range<usize>) -> Vec<f64> {
    let reported = &measure.item_seconds;
    let usable = reported.len() == range.len()
        && reported.iter().all(|s| s.is_finite() && *s >= 0.0)
        && reported.iter().sum::<f64>() > 0.0;
    if usable {
        reported.clone()
    } else {
        range.map(|position| frame.estimate(position)).collect()
    }
}

/// Exponential smoothing; the first observation is taken as it is, and
/// observations that are not a positive number are ignored.
fn smooth(old: Option<f64>, observed: f64, weight: f64) -> Option<f64> {
    if !(observed.is_finite() && observed > 0.0) {
        return old;
    }
    let weight = if weight.is_nan() {
        0.3
    } else {
        weight.clamp(0.0, 1.0)
    };
    Some(old.map_or(observed, |old| old + weight * (observed - old)))
}

/// [`smooth`] of a measured time in seconds.
fn smooth_seconds(old: Option<f64>, observed: Duration, weight: f64) -> Option<f64> {
    smooth(old, observed.as_secs_f64(), weight)
}

/// A duration from seconds, 0 for what is not a positive number, capped so
/// that adding it to a time cannot overflow.
pub(crate) fn seconds(x: f64) -> Duration {
    if x.is_nan() || x <= 0.0 {
        Duration::ZERO
    } else {
        Duration::from_secs_f64(x.min(1e9))
    }
}
