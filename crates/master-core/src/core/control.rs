//! A submitter's and a user's inputs about jobs: submitting, attaching
//! (with the journal's frames replayed), and the controls (cancel, pause,
//! resume, requeue, priority) with the job table's states.

use std::collections::BTreeSet;
use std::time::Duration;

use tracing::{info, warn};
use vtfarm_proto::{JobAction, JobScene, JobSummary, Message, WireJob, WireJobKind};
use vtfarm_scheduler::JobId;

use crate::error::JobRejected;
use crate::jobs::{JobControlError, JobEntry, JobState};
use crate::output::Output;
use crate::peers::ConnId;
use crate::record::Record;
use crate::recovery::Replayed;

use super::MasterCore;

impl MasterCore {
    /// Checks a submitted job and queues it (or asks for its scene first).
    pub(super) fn submit(&mut self, now: Duration, conn: ConnId, job: WireJob) {
        let scene_hash = match &job.scene {
            JobScene::Data(d) => d.hash,
            JobScene::Hash(h) => *h,
        };
        if job.scene == JobScene::Hash(scene_hash) && !self.scenes.contains_key(&scene_hash) {
            // Not cached here: ask the submitter for it.
            self.awaiting_scene.insert(conn, job);
            self.send(conn, Message::SceneRequest { hash: scene_hash });
            return;
        }
        let frames = job.frames.len() as u32;
        let host = self.peers.submitter_host(conn);
        match self.accept_job(now, BTreeSet::from([conn]), host, job) {
            Ok(id) => self.send(conn, Message::JobAccepted { job: id, frames }),
            Err(e) => self.refuse_job(conn, e.to_string()),
        }
    }

    /// Queues a job whose scene the master has (or `job` carries) for
    /// `submitters`, lists it and journals it; its id.
    pub(super) fn accept_job(
        &mut self,
        now: Duration,
        submitters: BTreeSet<ConnId>,
        host: String,
        mut job: WireJob,
    ) -> Result<JobId, JobRejected> {
        let scene_hash = match &job.scene {
            JobScene::Data(d) => d.hash,
            JobScene::Hash(h) => *h,
        };
        // The journal keeps the job with its scene by hash (the bytes once per scene).
        let scene = std::mem::replace(&mut job.scene, JobScene::Hash(scene_hash));
        let journaled = self.recovery.persistent().then(|| job.clone());
        job.scene = scene;
        let id = self.next_job;
        let entry = self.new_entry(id, &job, host, now);
        self.queue_job(now, id, job, submitters, 0)?;
        self.next_job.0 += 1;
        self.table.insert(entry);
        self.remember_for_view(id);
        self.telemetry.counters.jobs_submitted += 1;
        if let Some(job) = journaled {
            self.recovery.keep_definition(id, job.clone());
            let scene = self.scenes[&scene_hash].1.clone();
            self.persist(Record::JobQueued {
                id,
                job: Box::new(job),
                scene,
            });
            self.persist_state(id);
        }
        Ok(id)
    }

    /// A listing for a job just submitted.
    pub(super) fn new_entry(
        &self,
        id: JobId,
        job: &WireJob,
        host: String,
        now: Duration,
    ) -> JobEntry {
        JobEntry {
            id,
            name: crate::jobs::listed_name(&job.name),
            kind: job.kind,
            state: JobState::Queued,
            priority: job.priority,
            frames_done: 0,
            frames_total: job.frames.len() as u32,
            submitted_ms: self.wall_ms(now),
            started_ms: None,
            finished_ms: None,
            host,
            reason: String::new(),
            study: None,
            variants: Vec::new(),
        }
    }

    /// Journals job `id`'s listing (its state, priority and times).
    pub(super) fn persist_state(&mut self, id: JobId) {
        if let Some(entry) = self.table.get(id) {
            let summary = entry.summary();
            self.persist(Record::JobState(Box::new(summary)));
        }
    }

    /// Moves a listed job to `to` and journals it (and its study's state
    /// that follows); a job the table does not list (a frame rendered
    /// again) has no state to keep.
    pub(super) fn set_job_state(&mut self, id: JobId, to: JobState) {
        let at = self.wall_ms(self.now);
        match self.table.set_state(id, to, at) {
            Ok(Some(_)) => {
                self.persist_state(id);
                self.refresh_study_of(id);
            }
            Ok(None) => {}
            // The core asks only for what the table allows: a bug if not.
            Err(e) => warn!("{e}"),
        }
    }

    /// Brings the study job `id` is a variant of in line with its
    /// variants, journaling its state when that changed.
    pub(super) fn refresh_study_of(&mut self, id: JobId) {
        let Some(study) = self.table.get(id).and_then(|e| e.study) else {
            return;
        };
        if self.table.refresh_study(study, self.wall_ms(self.now)) {
            self.persist_study(study);
        }
    }

    /// Journals study `id`'s listing with its variants.
    pub(super) fn persist_study(&mut self, id: JobId) {
        if let Some(entry) = self.table.get(id).filter(|e| e.is_study()) {
            let row = self.table.row(entry);
            self.persist(Record::StudyState(Box::new(row)));
        }
    }

    /// A user's request about a job (`vtfarm cancel` and the like, the
    /// dashboard's buttons, the HTTP API): the job as it is afterwards, or
    /// why not. `who` names the asker for the job's submitters and listing.
    /// A study's request acts on each of its variants it applies to.
    pub fn control_job(
        &mut self,
        now: Duration,
        id: JobId,
        action: JobAction,
        who: &str,
    ) -> Result<JobSummary, JobControlError> {
        self.now = now;
        let entry = self.table.get(id).ok_or(JobControlError::UnknownJob(id))?;
        if entry.kind == WireJobKind::View {
            return Err(JobControlError::ViewJob(id));
        }
        if let Some(study) = entry.study {
            return Err(JobControlError::InStudy { job: id, study });
        }
        if entry.is_study() {
            self.control_study(now, id, action, who)?;
        } else {
            self.control_one(now, id, action, who)?;
        }
        self.pump();
        let entry = self.table.get(id).ok_or(JobControlError::UnknownJob(id))?;
        Ok(entry.summary())
    }

    /// Whether `action` applies to a job in `state`: why not, if not.
    pub(super) fn applies(
        id: JobId,
        state: JobState,
        action: &JobAction,
    ) -> Result<(), JobControlError> {
        let (applies, name, applies_to) = match action {
            JobAction::Cancel => (!state.is_finished(), "cancel", "queued, running or paused"),
            JobAction::Pause => (
                matches!(state, JobState::Queued | JobState::Running),
                "pause",
                "queued or running",
            ),
            JobAction::Resume => (state == JobState::Paused, "resume", "paused"),
            JobAction::Requeue { .. } => (
                state.is_finished(),
                "requeue",
                "completed, failed or cancelled",
            ),
            JobAction::SetPriority(_) => (
                !state.is_finished(),
                "priority",
                "queued, running or paused",
            ),
        };
        match applies {
            true => Ok(()),
            false => Err(JobControlError::NotNow {
                job: id,
                state,
                action: name,
                applies_to,
            }),
        }
    }

    /// [`MasterCore::control_job`] of one job (not a study's).
    pub(super) fn control_one(
        &mut self,
        now: Duration,
        id: JobId,
        action: JobAction,
        who: &str,
    ) -> Result<(), JobControlError> {
        let entry = self.table.get(id).ok_or(JobControlError::UnknownJob(id))?;
        Self::applies(id, entry.state, &action)?;
        match action {
            JobAction::Cancel => {
                info!(job = %id, by = who, "cancelling the job");
                let reason = format!("job {id} was cancelled by {who}");
                self.cancel_reasons.entry(id).or_insert(reason);
                let _ = self.scheduler.cancel_job(now, id);
            }
            JobAction::Pause => {
                info!(job = %id, by = who, "pausing the job");
                let _ = self.scheduler.pause_job(now, id);
                self.set_job_state(id, JobState::Paused);
                self.tell_state(id, format!("paused by {who}"));
            }
            JobAction::Resume => {
                info!(job = %id, by = who, "resuming the job");
                let started = self.table.get(id).is_some_and(|e| e.started_ms.is_some());
                let to = if started {
                    JobState::Running
                } else {
                    JobState::Queued
                };
                self.set_job_state(id, to);
                let _ = self.scheduler.resume_job(now, id);
                self.tell_state(id, format!("resumed by {who}"));
            }
            JobAction::Requeue { failed_only } => {
                self.requeue(now, id, failed_only)?;
                info!(job = %id, by = who, failed_only, "job queued again");
            }
            JobAction::SetPriority(priority) => {
                let _ = self.scheduler.set_priority(now, id, priority);
                if let Some(entry) = self.table.get_mut(id) {
                    entry.priority = priority;
                }
                self.persist_state(id);
            }
        }
        Ok(())
    }

    /// Tells a job's submitters its new state and why.
    pub(super) fn tell_state(&mut self, id: JobId, reason: String) {
        let Some(entry) = self.table.get(id) else {
            return;
        };
        let message = Message::JobStateChanged {
            job: id,
            state: entry.state.into(),
            reason,
        };
        self.send_to_job(id, message);
    }

    /// Queues a finished job again under its id: every frame, or with
    /// `failed_only` the frames it did not finish.
    pub(super) fn requeue(
        &mut self,
        now: Duration,
        id: JobId,
        failed_only: bool,
    ) -> Result<(), JobControlError> {
        let entry = self.table.get(id).ok_or(JobControlError::UnknownJob(id))?;
        let resume_from = if failed_only { entry.frames_done } else { 0 };
        if failed_only && resume_from >= entry.frames_total {
            return Err(JobControlError::NothingToRequeue(id));
        }
        let requeue_error = |reason: String| JobControlError::Requeue { job: id, reason };
        let definition = (self.recovery.definition(id).cloned()).ok_or_else(|| {
            requeue_error("this master keeps no job definitions (it journals nothing)".into())
        })?;
        let mut job = definition.clone();
        job.priority = entry.priority;
        // The definition names its scene by hash once queued.
        let scene_hash = match &job.scene {
            JobScene::Data(d) => d.hash,
            JobScene::Hash(h) => *h,
        };
        self.queue_job(now, id, job, BTreeSet::new(), resume_from)
            .map_err(|e| requeue_error(e.to_string()))?;
        if let Some(entry) = self.table.get_mut(id) {
            entry.frames_done = resume_from;
            entry.started_ms = None;
        }
        if self.journals(id) && !failed_only {
            // Its old frames go: a restart must not take them for new ones.
            self.persist(Record::JobForgotten { id });
            let mut journaled = definition;
            journaled.scene = JobScene::Hash(scene_hash);
            self.recovery.keep_definition(id, journaled.clone());
            if let Some((_, data)) = self.scenes.get(&scene_hash) {
                let scene = data.clone();
                self.persist(Record::JobQueued {
                    id,
                    job: Box::new(journaled),
                    scene,
                });
            }
        }
        self.set_job_state(id, JobState::Queued);
        self.telemetry.counters.jobs_submitted += 1;
        Ok(())
    }

    /// A submitter asks for a job's frames from `from_frame` on.
    pub(super) fn attach(&mut self, conn: ConnId, job: JobId, from_frame: u32) {
        // A study: the submitter attaches to each of its variants.
        if let Some(variants) = self.study_variants(job) {
            info!(study = %job, %conn, "submitter attached to the study");
            let study = job;
            return self.send(conn, Message::StudyAccepted { study, variants });
        }
        // A finished job within retention: its journaled frames, then how it ended.
        let finished = (self.table.get(job))
            .filter(|e| e.state.is_finished() && self.recovery.persistent())
            .map(|e| (e.frames_total, e.frames_done, e.state, e.reason.clone()));
        let (frames, done) = if let Some(j) = self.frames.jobs.get_mut(&job) {
            if !j.submitters.is_empty() {
                info!(%job, "another submitter attached; each gets every frame");
            }
            j.submitters.insert(conn);
            (j.frames.len() as u32, j.frames_done)
        } else if let Some((frames, done, _, _)) = &finished {
            (*frames, *done)
        } else {
            let error = match (self.recovery.damaged(job), self.table.get(job)) {
                (Some(reason), _) => {
                    format!("job {job} could not be read back from the journal: {reason}")
                }
                (None, Some(entry)) => format!(
                    "job {job} is {} and this master keeps no frames (it journals nothing)",
                    entry.state
                ),
                (None, None) => format!(
                    "the master has no job {job} (finished longer ago than it keeps jobs, or never submitted)"
                ),
            };
            let errors = vec![error];
            self.send(conn, Message::JobFailed { job, errors });
            return;
        };
        info!(%job, %conn, from_frame, "submitter attached");
        self.send(conn, Message::JobAccepted { job, frames });
        if let Some(error) = self.recovery.failed_write(job).map(str::to_owned) {
            self.send(conn, Message::JournalFailed { job, error });
        }
        if let Some((frame, reason)) = self.recovery.damaged_frame(job).cloned() {
            if frame >= from_frame {
                let again = Message::FrameMissing {
                    job,
                    frame,
                    reason,
                    rendering_again: true,
                };
                self.send(conn, again);
            }
        }
        self.replay(conn, job, from_frame..done);
        match finished {
            Some((_, _, JobState::Failed, reason)) => {
                self.send(
                    conn,
                    Message::JobFailed {
                        job,
                        errors: vec![reason],
                    },
                );
            }
            Some((_, _, JobState::Cancelled, reason)) => {
                let state = JobState::Cancelled.into();
                self.send(conn, Message::JobStateChanged { job, state, reason });
            }
            _ => {}
        }
    }

    /// Sends `conn` the finished frames `frames` of `job`, in order: those
    /// whose journal write is pending or failed from memory, the rest read
    /// back from the journal by the driver.
    pub(super) fn replay(&mut self, conn: ConnId, job: JobId, frames: std::ops::Range<u32>) {
        for step in self.recovery.replay(job, frames) {
            match step {
                Replayed::Frame(done) => self.send(conn, Message::FrameDone(*done)),
                Replayed::Journal(frames) => {
                    self.outbox.push_back(Output::Replay { conn, job, frames });
                }
            }
        }
    }
}
