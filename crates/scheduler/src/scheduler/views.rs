//! What the scheduler shows: worker, package and queue status, counters,
//! and the invariant check its tests run after every input.

use super::{Measures, QueuedJob, RunningJob, Scheduler, Worker, rank};
use crate::frame::{Frame, Package};
use crate::{
    Counters, InvariantError, JobId, JobProgress, PackageId, PackageState, QueueStatus, WorkerId,
    WorkerState, WorkerStatus,
};

impl Scheduler {
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
                return fail(format!(
                    "job {}: {} split frames",
                    job.id,
                    job.split_frames()
                ));
            }
            for frame in job.running_frames() {
                self.validate_frame(frame)?;
            }
        }
        Ok(())
    }

    /// Checks one running frame's items and packages (see `validate`).
    pub(super) fn validate_frame(&self, frame: &Frame) -> Result<(), InvariantError> {
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
}
