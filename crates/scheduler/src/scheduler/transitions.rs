//! The package and worker state changes (the crate documentation's tables):
//! assigning, completing, failing, losing and abandoning packages.

use std::ops::Range;
use std::time::Duration;

use super::{COMPUTE_SAMPLES, Pick, Scheduler, seconds};
use crate::frame::{Attempt, Frame, Package};
use crate::{
    Assignment, Event, JobFailure, JobId, LossCause, PackageId, PackageMeasure, PackageState,
    WorkerFrameStats, WorkerId,
};

impl Scheduler {
    /// Hands `pick` to `worker`: (new) → Assigned, Queued → Assigned, or
    /// Assigned → Duplicated; the worker goes Waiting → Busy.
    pub(super) fn assign(&mut self, j: usize, worker: WorkerId, pick: Pick) {
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
    pub(super) fn complete(&mut self, worker: WorkerId, id: PackageId, measure: &PackageMeasure) {
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
    pub(super) fn cancel_losing_copy(
        &mut self,
        j: usize,
        id: PackageId,
        cost: f64,
        loser: Attempt,
    ) {
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
    pub(super) fn fail_attempt(&mut self, worker: WorkerId, id: PackageId, error: String) {
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
    pub(super) fn lose(&mut self, worker: WorkerId, cause: LossCause) {
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
    pub(super) fn fail_job(
        &mut self,
        j: usize,
        reason: JobFailure,
        errors: Vec<(WorkerId, String)>,
    ) {
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
    pub(super) fn abandon_job(&mut self, j: usize) -> JobId {
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

/// How a package's busy time splits over its items: the worker's split when
/// it is usable, else the estimates.
pub(super) fn split_weights(
    measure: &PackageMeasure,
    frame: &Frame,
    range: Range<usize>,
) -> Vec<f64> {
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
pub(super) fn smooth(old: Option<f64>, observed: f64, weight: f64) -> Option<f64> {
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
pub(super) fn smooth_seconds(old: Option<f64>, observed: Duration, weight: f64) -> Option<f64> {
    smooth(old, observed.as_secs_f64(), weight)
}
