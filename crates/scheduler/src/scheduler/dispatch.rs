//! Bookkeeping and dispatch: starting queued jobs and frames in rank order,
//! completing frames in order, and handing work to the waiting workers.

use std::cmp::Reverse;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::Duration;

use super::{
    Choice, Offer, QueuedJob, RunningJob, Scheduler, TailCosts, WHOLE_FRAMES_PER_WORKER, Wanted,
    Worker, rank,
};
use crate::costs::CostModel;
use crate::frame::Frame;
use crate::{
    Event, JobFailure, JobId, PackageId, ReportError, SchedulerConfig, WorkerError, WorkerId,
};

impl Scheduler {
    pub(super) fn advance(&mut self, now: Duration) -> Duration {
        self.now = self.now.max(now);
        self.now
    }

    pub(super) fn connected(&self, worker: WorkerId) -> Result<(), WorkerError> {
        match self.workers.get(&worker) {
            Some(w) if w.connected => Ok(()),
            _ => Err(WorkerError::NotConnected(worker)),
        }
    }

    pub(super) fn touch(&mut self, worker: WorkerId) {
        if let Some(w) = self.workers.get_mut(&worker) {
            w.last_seen = self.now;
        }
    }

    /// Accepts a result only for a package the worker runs now, counting why
    /// it refused otherwise. Accepted or not, a result from a connected
    /// worker is a heartbeat.
    pub(super) fn check_report(
        &mut self,
        worker: WorkerId,
        package: PackageId,
    ) -> Result<(), ReportError> {
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
    pub(super) fn dispatch(&mut self) {
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
    pub(super) fn start_jobs_and_frames(&mut self) {
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
    pub(super) fn hand_out(&mut self) -> Option<Wanted> {
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
    pub(super) fn choose(&self, worker: WorkerId) -> Choice {
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
    pub(super) fn may_start_ahead(&self, j: usize) -> bool {
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
    pub(super) fn room_for_a_frame(&self, j: usize) -> bool {
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
    pub(super) fn advance_jobs(&mut self) {
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
    pub(super) fn finish_oldest_frame(&mut self, j: usize) {
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
    pub(super) fn end_job(&mut self, j: usize) -> RunningJob {
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
    pub(super) fn start_ahead(&mut self, j: usize) {
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
    pub(super) fn lapse_requests(&mut self) {
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
    pub(super) fn start_queued(&mut self, id: JobId) {
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
    pub(super) fn no_eligible_worker(&self, j: usize) -> bool {
        let job = &self.running[j];
        let mut connected = self.workers.iter().filter(|(_, w)| w.connected).peekable();
        job.running_frames().any(Frame::has_unassigned)
            && connected.peek().is_some()
            && connected.all(|(id, _)| job.blocklist.contains(id))
    }
}

/// Whether the next frame of `job` to start is whole
/// ([`SchedulerConfig::whole_frames`]): more of its frames are not started
/// (the next included) than its tail ([`tail_frames`]) splits.
pub(super) fn starts_whole(
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
pub(super) fn starts_whole_with(
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
pub(super) fn tail_frames(
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
