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
use std::time::Duration;

use crate::costs::CostModel;
use crate::frame::{Frame, Package};
use crate::{
    Assignment, CancelError, Counters, Event, FrameWork, JobId, JoinError, LossCause, PackageId,
    PackageMeasure, QueueOptions, ReportError, SchedulerConfig, SubmitError, WorkerError, WorkerId,
    WorkerState,
};

mod dispatch;
mod sizing;
mod transitions;
mod views;

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

/// A duration from seconds, 0 for what is not a positive number, capped so
/// that adding it to a time cannot overflow.
pub(crate) fn seconds(x: f64) -> Duration {
    if x.is_nan() || x <= 0.0 {
        Duration::ZERO
    } else {
        Duration::from_secs_f64(x.min(1e9))
    }
}
