//! What a waiting worker gets and how much: picking a job's work under frame
//! affinity, guided self-scheduling of package sizes, workers' rates and
//! straggler deadlines.

use std::time::Duration;

use super::{MIN_CREW, Offer, Pick, RunningJob, SPARE_FRAMES, Scheduler, Worker, seconds};
use crate::frame::{Frame, Package};
use crate::{JobId, PackageId, PackageState, StragglerPolicy, WorkerId};

impl Scheduler {
    /// What running job `j` has for `worker`: a queued package it may take
    /// (split when much larger than its target), else the next unassigned
    /// items, else, once nothing is left to hand out, a straggler's second
    /// copy; or, under frame affinity, a frame to start for it. A paused
    /// job, or one that blocklisted the worker, has nothing.
    pub(super) fn pick(&self, j: usize, worker: WorkerId) -> Offer {
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
    pub(super) fn copy_of_a_late_oldest_frame(
        &self,
        job: &RunningJob,
        worker: WorkerId,
    ) -> Option<Pick> {
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
    pub(super) fn whole_copy_due(
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
    pub(super) fn whole_copy_late_at(
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
    pub(super) fn pick_with_affinity(&self, j: usize, worker: WorkerId) -> Offer {
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
    pub(super) fn crew_size(&self, job: &RunningJob) -> usize {
        let crews = (self.config.frames_in_flight.saturating_sub(SPARE_FRAMES)).max(1) as usize;
        self.eligible_workers(job)
            .count()
            .div_ceil(crews)
            .max(MIN_CREW)
    }

    /// Connected workers not blocklisted for `job`.
    pub(super) fn eligible_workers<'a>(
        &'a self,
        job: &'a RunningJob,
    ) -> impl Iterator<Item = &'a Worker> {
        self.eligible_ids(job).map(|(_, w)| w)
    }

    /// Connected workers not blocklisted for `job`, with their ids.
    pub(super) fn eligible_ids<'a>(
        &'a self,
        job: &'a RunningJob,
    ) -> impl Iterator<Item = (WorkerId, &'a Worker)> {
        (self.workers.iter())
            .filter(|(id, w)| w.connected && !job.blocklist.contains(id))
            .map(|(&id, w)| (id, w))
    }

    /// Connected workers whose crew is frame `index` of `job`.
    pub(super) fn crew_of(&self, job: JobId, index: u32) -> usize {
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
    pub(super) fn crew_target(&self, job: &RunningJob, worker: WorkerId, frame: &Frame) -> f64 {
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
    pub(super) fn pick_unassigned(
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
    pub(super) fn may_retry(&self, job: &RunningJob, package: &Package, worker: WorkerId) -> bool {
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
    pub(super) fn target_cost(&self, job: &RunningJob, worker: WorkerId) -> f64 {
        let prior = self.prior_rate_per_thread(job);
        let total_rate: f64 = (self.eligible_ids(job))
            .map(|(id, w)| rate_with_prior(job, id, w, prior))
            .sum();
        let unassigned: f64 = job.running_frames().map(Frame::unassigned_cost).sum();
        self.sized(unassigned, total_rate) * self.rate_of(job, worker)
    }

    /// A package's target duration in seconds: `unassigned` work over `k`
    /// times `rate`, clamped (see [`PackageSizing`](crate::PackageSizing)).
    pub(super) fn sized(&self, unassigned: f64, rate: f64) -> f64 {
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
    pub(super) fn rate_of(&self, job: &RunningJob, worker: WorkerId) -> f64 {
        let prior = self.prior_rate_per_thread(job);
        (self.workers.get(&worker)).map_or(0.0, |w| rate_with_prior(job, worker, w, prior))
    }

    /// The rate per thread assumed for a worker before its first result in
    /// `job`: the mean over the job's measured connected workers, else the
    /// configured one.
    pub(super) fn prior_rate_per_thread(&self, job: &RunningJob) -> f64 {
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
    pub(super) fn straggler_deadline(&self) -> Option<Duration> {
        (0..self.running.len())
            .filter_map(|j| self.straggler_deadline_of(j))
            .min()
    }

    /// The earliest moment a running package of running job `j` becomes a
    /// straggler that a waiting worker could take; `None` while work is
    /// left to hand out (but for a late whole oldest frame).
    pub(super) fn straggler_deadline_of(&self, j: usize) -> Option<Duration> {
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
}

/// A worker's measured rate in `job`, or before its first result there
/// `prior_per_thread` times its threads.
pub(super) fn rate_with_prior(
    job: &RunningJob,
    id: WorkerId,
    worker: &Worker,
    prior_per_thread: f64,
) -> f64 {
    (job.measures.get(&id).and_then(|m| m.rate))
        .unwrap_or(prior_per_thread * f64::from(worker.threads))
}

/// Whether `worker` may run a second copy of `package`.
pub(super) fn may_duplicate(package: &Package, worker: WorkerId) -> bool {
    package.state() == PackageState::Assigned
        && package.attempt_of(worker).is_none()
        && !package.failed_on(worker)
        // Its result is here, waiting for the driver's check.
        && package.attempts.iter().all(|a| a.arrived_at.is_none())
}

/// When the running copy of an assigned package becomes a straggler.
pub(super) fn straggler_deadline(package: &Package, policy: &StragglerPolicy) -> Duration {
    let Some(attempt) = package.attempts.first() else {
        return Duration::MAX;
    };
    let wait = seconds(attempt.expected.as_secs_f64() * policy.factor).max(policy.min_delay);
    attempt.assigned_at.saturating_add(wait)
}
