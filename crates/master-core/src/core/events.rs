//! The scheduler's events, one method each: jobs started, resumed,
//! completed, failed and cancelled; frames started and completed; workers
//! blocklisted and lost. Finished frames go out from here, in order.

use tracing::{info, warn};
use vtfarm_proto::JobId;
use vtfarm_proto::{FrameDone, FrameStart, Message};
use vtfarm_scheduler::{FrameStats, LossCause, PackageId, WorkerId};

use crate::frames::base::BaseFrame;
use crate::frames::finish::{FinishedFrame, Finishing};
use crate::jobs::JobState;
use crate::output::Output;
use crate::peers::ConnId;
use crate::record::Record;

use super::MasterCore;

impl MasterCore {
    /// The scheduler started `job`: listed as running, its scene offered
    /// to the workers.
    pub(super) fn job_started(&mut self, job: JobId) {
        info!(%job, "job started");
        if (self.table.get(job)).is_some_and(|e| e.state == JobState::Queued) {
            self.set_job_state(job, JobState::Running);
        }
        let Some(hash) = self.frames.jobs.get(&job).map(|j| j.scene_hash) else {
            return;
        };
        for conn in self.peers.workers() {
            self.send(conn, Message::SceneOffer { hash, job });
        }
    }

    /// The scheduler resumed `job`: the workers may have let its frames go
    /// meanwhile, so each gets the starts it lacks.
    pub(super) fn job_resumed(&mut self, job: JobId) {
        let Some(j) = self.frames.jobs.get(&job) else {
            return;
        };
        let offer = Message::SceneOffer {
            hash: j.scene_hash,
            job,
        };
        let starts: Vec<FrameStart> = (j.assembling.iter())
            .filter(|a| !a.whole)
            .map(|a| a.start.clone())
            .collect();
        for conn in self.peers.workers() {
            self.send(conn, offer.clone());
            for start in &starts {
                if !self.peers.keeps(conn, start.job, start.frame) {
                    self.send(conn, Message::FrameStart(start.clone()));
                }
            }
        }
    }

    /// The scheduler started frame `frame` of `job` (finished before a
    /// restart: nothing to assemble). The workers hear of a split frame
    /// and the driver is asked for its base frame; while whole frames run,
    /// base frames of the job's tail are made ahead.
    pub(super) fn frame_started(&mut self, job: JobId, frame: u32, whole: bool) {
        let resumed = (self.frames.jobs.get(&job)).is_some_and(|j| frame < j.resume_from);
        if !resumed {
            if let Some(started) = self.frames.start_frame(job, frame, whole, self.now) {
                if let Some(start) = started.start {
                    for conn in self.peers.workers() {
                        self.send(conn, Message::FrameStart(start.clone()));
                    }
                }
                self.send_to_job(job, started.progress);
                if let Some(request) = started.rasterize {
                    self.outbox.push_back(Output::RasterizeBase(request));
                }
            }
        }
        if whole {
            // The master has little else to do while whole frames run.
            self.make_base_ahead(job);
        }
    }

    /// The scheduler completed frame `frame` of `job`: it goes to be
    /// encoded, and out in order.
    pub(super) fn frame_complete(&mut self, job: JobId, frame: u32, stats: &FrameStats) {
        // A frame rendered again is journaled under its own job.
        let journaled = self.journals(self.recovery.owner(job, frame).0);
        let peers = &self.peers;
        let name = |conn| peers.name(conn);
        let (views, now) = (&mut self.views, self.now);
        let completed =
            (self.frames).complete_frame((job, frame), stats, name, journaled, views, now);
        let Some(request) = completed else {
            return;
        };
        self.ask_for_view_figures();
        info!(%job, frame, wall = ?stats.wall, imbalance = stats.imbalance(), "frame complete");
        if let Some(request) = request {
            self.outbox.push_back(Output::EncodeFrame(request));
        }
        self.peers.frame_complete();
        self.tell_finished(job);
    }

    /// The scheduler's `JobComplete`: the job ends once its last frames
    /// are out.
    pub(super) fn job_done(&mut self, job: JobId) {
        match self.frames.jobs.get_mut(&job) {
            Some(j) if !j.finishing.is_empty() => j.finishing.push(Finishing::Complete),
            _ => self.job_complete(job),
        }
    }

    /// The scheduler failed `job` (`reason`, and the workers' `errors`).
    pub(super) fn job_failed(
        &mut self,
        job: JobId,
        reason: &vtfarm_scheduler::JobFailure,
        errors: &[(WorkerId, String)],
    ) {
        // The same error from several workers is told once, with their names.
        let mut grouped: Vec<(String, Vec<String>)> = Vec::new();
        for (worker, error) in errors {
            let name = self.peers.name(ConnId::of_worker(*worker));
            match grouped.iter_mut().find(|(e, _)| e == error) {
                Some((_, names)) => names.push(name),
                None => grouped.push((error.clone(), vec![name])),
            }
        }
        let errors: Vec<String> = std::iter::once(format!("job failed: {reason:?}"))
            .chain(
                (grouped.into_iter())
                    .map(|(error, names)| format!("{}: {error}", names.join(", "))),
            )
            .collect();
        warn!(%job, "{}", errors.join("; "));
        if self.counts_in_totals(job) {
            self.telemetry.counters.jobs_failed += 1;
        }
        let repaired = self.recovery.repair_ended(job);
        if repaired.is_none() {
            if let Some(entry) = self.table.get_mut(job) {
                entry.reason = errors.join("; ");
            }
            self.set_job_state(job, JobState::Failed);
        }
        if let Some(j) = self.frames.forget_job(job) {
            let message = match repaired {
                // Rendering a lost frame again failed: its job's
                // submitters learn which frame they will not get.
                Some((owner, frame)) => Message::FrameMissing {
                    job: owner,
                    frame,
                    reason: errors.join("; "),
                    rendering_again: false,
                },
                None => Message::JobFailed { job, errors },
            };
            self.send_to(&j.submitters, message);
        }
        if repaired.is_none() {
            self.forget_view_job(job);
            self.forget_expired();
        }
    }

    /// The scheduler cancelled `job` (a user asked, or its submitter left).
    pub(super) fn job_cancelled(&mut self, job: JobId) {
        if self.counts_in_totals(job) {
            self.telemetry.counters.jobs_cancelled += 1;
        }
        let reason = (self.cancel_reasons.remove(&job))
            .unwrap_or_else(|| format!("job {job} was cancelled"));
        if let Some(entry) = self.table.get_mut(job) {
            entry.reason = reason.clone();
        }
        self.set_job_state(job, JobState::Cancelled);
        if let Some(j) = self.frames.forget_job(job) {
            let state = JobState::Cancelled.into();
            let message = Message::JobStateChanged { job, state, reason };
            self.send_to(&j.submitters, message);
        }
        if self.recovery.repair_ended(job).is_none() {
            self.forget_view_job(job);
            self.forget_expired();
        }
    }

    /// The scheduler gives `worker` no more work of `job`.
    pub(super) fn worker_blocklisted(&mut self, worker: ConnId, job: JobId) {
        let failures = self.scheduler.config().retry.worker_failures_per_job;
        warn!(worker = %self.peers.name(worker), %job, "worker failed {failures} packages: no more work of this job");
        let name = self.peers.worker_name(worker);
        self.telemetry.blocklisted(&name, job);
    }

    /// The scheduler lost `worker` (`cause`): its packages `requeued` go to
    /// the others.
    pub(super) fn worker_lost(&mut self, worker: ConnId, cause: LossCause, requeued: &[PackageId]) {
        for package in requeued {
            self.frames.drop_in_flight(package.0, worker);
        }
        let name = self.peers.name(worker);
        match cause {
            // A clean leave (a drained worker finished its package first)
            // is no fault: `disconnected` said it left.
            LossCause::Left if requeued.is_empty() => {}
            LossCause::Left => {
                info!(worker = %name, requeued = requeued.len(), "its packages go to the other workers");
            }
            LossCause::HeartbeatTimeout => {
                warn!(worker = %name, requeued = requeued.len(), "worker lost: it missed its heartbeats");
                self.close(worker, "missed its heartbeats".into());
            }
        }
    }

    /// The scheduler's `JobComplete`, once the job's last frame is out.
    pub(super) fn job_complete(&mut self, job: JobId) {
        info!(%job, "job complete");
        // A cancel asked for while its last frame was encoding came too
        // late (the scheduler had finished the job): the job completes.
        self.cancel_reasons.remove(&job);
        if self.counts_in_totals(job) {
            self.telemetry.counters.jobs_completed += 1;
        }
        let repaired = self.recovery.repair_ended(job);
        if self.frames.forget_job(job).is_some() && repaired.is_none() {
            // Kept (as retention allows) for a submitter that lost
            // the connection or attaches later.
            self.persist(Record::JobComplete { id: job });
            self.set_job_state(job, JobState::Completed);
            self.forget_view_job(job);
            self.forget_expired();
        }
    }

    /// Sends `job`'s finished frames that are ready, in order, and its end
    /// once they are all out.
    pub(super) fn tell_finished(&mut self, job: JobId) {
        while let Some(next) =
            (self.frames.jobs.get_mut(&job)).and_then(|j| j.finishing.pop_ready())
        {
            match next {
                Finishing::Frame(frame) => self.deliver_frame(job, *frame),
                Finishing::Complete => self.job_complete(job),
            }
        }
    }

    /// A finished frame, encoded, to its submitters and the journal.
    pub(super) fn deliver_frame(&mut self, job: JobId, finished: FinishedFrame) {
        let FinishedFrame {
            frame,
            stats,
            ids,
            encoded,
            buffers,
        } = finished;
        let (image, aux) = encoded.expect("only encoded frames are delivered");
        let Some(j) = self.frames.jobs.get_mut(&job) else {
            return;
        };
        j.frames_done = frame + 1;
        let submitters = j.submitters.clone();
        if let Some(entry) = self.table.get_mut(job) {
            entry.frames_done = frame + 1;
        }
        self.refresh_study_of(job);
        // A frame rendered again is its own job's frame.
        let (owner, owner_frame) = self.recovery.owner(job, frame);
        let message = FrameDone {
            job: owner,
            frame: owner_frame,
            image,
            stats: stats.clone(),
            aux,
        };
        if self.journals(owner) {
            self.persist(Record::FrameDone(Box::new(message.clone())));
        }
        let image = message.image.clone();
        (self.telemetry).frame_finished(owner, owner_frame, stats, image);
        self.send_to(&submitters, Message::FrameDone(message));
        if let (Some(ids), Some((image, srgb))) = (ids, buffers) {
            self.frames.spare(BaseFrame { image, ids, srgb });
        }
    }
}
