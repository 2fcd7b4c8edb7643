//! The journal's inputs: jobs restored at start (resumed or set aside as
//! damaged), writes that succeeded or failed, and frames it could not
//! give back (rendered again).

use std::collections::BTreeSet;
use std::time::Duration;
use vtfarm_proto::JobId;

use tracing::{info, warn};
use vtfarm_proto::Message;

use crate::jobs::{JobEntry, JobState};
use crate::output::Output;
use crate::peers::ConnId;
use crate::record::{DamagedJob, Record, StoredJob, Written};
use crate::recovery::{AfterWrite, by_hash};

use super::MasterCore;

/// The reason listed for a restored job whose journaled listing is lost.
const LISTING_LOST: &str =
    "its state could not be read back from the journal: held paused (resume or cancel it)";

impl MasterCore {
    /// Resumes a journaled job (at start, before any connection): it runs
    /// from its first unfinished frame, or waits complete for its submitter.
    pub fn restore(&mut self, now: Duration, stored: StoredJob) {
        self.now = now;
        self.next_job = self.next_job.max(JobId(stored.id.0 + 1));
        if let Some(damaged) = stored.damaged_frame.clone() {
            self.recovery.frame_damaged(stored.id, damaged);
        }
        let mut entry = match stored.summary.clone() {
            Some(summary) => JobEntry::from_summary(summary),
            None => {
                // Its listing is lost (the journal warned, naming the file):
                // nothing says it was not cancelled or paused, so it is held.
                let mut entry = self.new_entry(stored.id, &stored.job, "unknown".into(), now);
                entry.state = JobState::Paused;
                entry.reason = LISTING_LOST.to_owned();
                entry
            }
        };
        entry.frames_done = stored.frames_done;
        entry.frames_total = stored.job.frames.len() as u32;
        // The frames decide whether it is complete: one whose journal lost
        // a frame renders from there again.
        match (stored.complete, entry.state) {
            (true, _) => entry.state = JobState::Completed,
            (false, JobState::Completed) => {
                entry.state = JobState::Queued;
                entry.finished_ms = None;
            }
            _ => {}
        }
        let state = entry.state;
        if state.is_finished() {
            // Kept (with its scene's bytes) to render a frame again that
            // the journal cannot give back, or to queue it again.
            self.recovery.keep_definition(stored.id, stored.job);
            self.table.insert(entry);
            return;
        }
        // It runs again from where it was: queued, or held while paused.
        if state == JobState::Running {
            entry.state = JobState::Queued;
        }
        let priority = entry.priority;
        self.table.insert(entry);
        // Once queued the scene is in the cache: the definition names it by hash.
        (self.recovery).keep_definition(stored.id, by_hash(&stored.job));
        let mut job = stored.job;
        job.priority = priority;
        let paused = state == JobState::Paused;
        let queued = self.queue_job_with(
            now,
            stored.id,
            job,
            BTreeSet::new(),
            stored.frames_done,
            paused,
        );
        if let Err(e) = queued {
            self.table.remove(stored.id);
            let reason = format!("cannot resume job {}: {e}", stored.id);
            warn!(job = %stored.id, "{reason}; setting it aside");
            self.recovery.forget_definition(stored.id);
            self.restore_damaged(DamagedJob {
                id: stored.id,
                reason: format!("{reason} (kept in jobs/damaged/)"),
            });
            self.persist(Record::JobDamaged {
                id: stored.id,
                reason,
            });
        } else {
            // Queued by this master: its end counts like a submitted job's.
            self.telemetry.counters.jobs_submitted += 1;
            info!(
                job = %stored.id,
                from_frame = stored.frames_done,
                "job resumed from the journal"
            );
        }
        self.pump();
    }

    /// A job the journal set aside as damaged (at start): a submitter
    /// attaching to it is told why.
    pub fn restore_damaged(&mut self, damaged: DamagedJob) {
        self.next_job = self.next_job.max(JobId(damaged.id.0 + 1));
        self.recovery.job_damaged(damaged.id, damaged.reason);
    }

    /// The driver wrote a record (or failed to): a written frame leaves
    /// memory; a failure is counted, told to the job's submitters, and the
    /// frame stays in memory for re-attaching submitters.
    pub fn journal_written(&mut self, now: Duration, written: Written) {
        self.now = now;
        let job = written.job;
        match self.recovery.written(now, written) {
            AfterWrite::Rewrite(record) => {
                // Written again as is: it is kept in memory already.
                if let Some(record) = record {
                    self.outbox.push_back(Output::Persist(record));
                }
            }
            AfterWrite::Failed(error) => {
                warn!(%job, "{error}");
                self.telemetry.counters.journal_write_failures += 1;
                self.telemetry.last_journal_error = Some(error.clone());
                self.send_to_job(job, Message::JournalFailed { job, error });
            }
        }
        self.pump();
    }

    /// The driver could not read frame `frame` of `job` back from the
    /// journal for `conn` (`error` says why): the frame is rendered again
    /// and `conn` gets it then, or `conn` is told it cannot have it.
    pub fn replay_failed(
        &mut self,
        now: Duration,
        conn: ConnId,
        job: JobId,
        frame: u32,
        error: String,
    ) {
        self.now = now;
        warn!(%job, frame, "a finished frame cannot be read back: {error}");
        if let Some(done) = self.recovery.unjournaled(job, frame).cloned() {
            self.send(conn, Message::FrameDone(done));
            return self.pump();
        }
        if let Some(repair) = self.recovery.repair_of(job, frame) {
            if let Some(j) = self.frames.jobs.get_mut(&repair) {
                j.submitters.insert(conn);
            }
        } else if let Err(e) = self.render_again(now, conn, job, frame) {
            let reason = format!("{error}; it cannot be rendered again: {e}");
            let lost = Message::FrameMissing {
                job,
                frame,
                reason,
                rendering_again: false,
            };
            self.send(conn, lost);
            return self.pump();
        }
        self.telemetry.counters.frames_rendered_again += 1;
        let again = Message::FrameMissing {
            job,
            frame,
            reason: error,
            rendering_again: true,
        };
        self.send(conn, again);
        self.pump();
    }

    /// Queues a job of the one frame `frame` of `job`, for `conn`.
    pub(super) fn render_again(
        &mut self,
        now: Duration,
        conn: ConnId,
        job: JobId,
        frame: u32,
    ) -> Result<(), String> {
        let definition = self.recovery.again(job, frame)?;
        let id = self.next_job;
        self.queue_job(now, id, definition, BTreeSet::from([conn]), 0)
            .map_err(|e| e.to_string())?;
        self.next_job.0 += 1;
        self.recovery.repairing(id, job, frame);
        info!(%job, frame, repair = %id, "rendering a finished frame again");
        Ok(())
    }
}
