//! What the core asks the journal to keep ([`Record`]) and what a restarted
//! master reads back from it ([`StoredJob`], [`DamagedJob`]); how a write
//! went ([`Written`]). Plain data: the server crate's
//! `journal` writes and reads the files.

use std::sync::Arc;
use std::time::Duration;
use vtfarm_proto::JobId;

use vtfarm_proto::{FrameDone, JobRow, JobSummary, SceneData, WireJob};

/// What the core asks to keep.
#[derive(Clone, Debug, PartialEq)]
pub enum Record {
    /// A job was queued (its scene by hash in `job`, the bytes in `scene`).
    JobQueued {
        id: JobId,
        job: Box<WireJob>,
        scene: Arc<SceneData>,
    },
    /// A frame finished.
    FrameDone(Box<FrameDone>),
    /// Every frame of the job is done (kept for re-attaching submitters).
    JobComplete { id: JobId },
    /// The job is gone: failed, cancelled, or delivered long enough ago.
    JobForgotten { id: JobId },
    /// The job cannot run from its record: set it aside in `jobs/damaged/`
    /// with `reason`, never delete it.
    JobDamaged { id: JobId, reason: String },
    /// The job's listing changed (state, priority, times): the newest
    /// replaces the one before.
    JobState(Box<JobSummary>),
    /// A study's listing and its variants (their ids; each variant's own
    /// records keep its state): the newest replaces the one before.
    StudyState(Box<JobRow>),
}

impl Record {
    /// The job the record is about.
    pub fn job(&self) -> JobId {
        match self {
            Record::JobQueued { id, .. }
            | Record::JobComplete { id }
            | Record::JobForgotten { id }
            | Record::JobDamaged { id, .. } => *id,
            Record::FrameDone(done) => done.job,
            Record::JobState(summary) => summary.id,
            Record::StudyState(row) => row.job.id,
        }
    }

    /// The frame the record is, if it is one.
    pub fn frame(&self) -> Option<u32> {
        match self {
            Record::FrameDone(done) => Some(done.frame),
            _ => None,
        }
    }
}

/// How long after a failed write (a full disk) a frame kept in memory is
/// written again when no other record is: the disk may have room by then.
pub const KEPT_FRAME_RETRY: Duration = Duration::from_secs(2);

/// How writing one record went, as the server's journal writer reports it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Written {
    pub job: JobId,
    /// The frame, when the record was a finished frame.
    pub frame: Option<u32>,
    /// `Err` with the error's text (which names the file) when it failed.
    pub outcome: Result<(), String>,
}

/// A job read back from the journal.
#[derive(Debug)]
pub struct StoredJob {
    pub id: JobId,
    /// The job with its scene's bytes (`JobScene::Data`).
    pub job: WireJob,
    /// How many frames are finished, counted from frame 0 without a gap.
    pub frames_done: u32,
    pub complete: bool,
    /// Its listing as last journaled (state, priority, times); `None` when
    /// it is missing or damaged: the job is then held paused (nothing says
    /// it was not cancelled or paused, and such a job must not run again on
    /// its own) unless its records say it is complete.
    pub summary: Option<JobSummary>,
    /// The frame that ended the count because its record failed its check
    /// (or is missing while later ones are there), and why: it is rendered
    /// again, and an attaching submitter is told.
    pub damaged_frame: Option<(u32, String)>,
}

/// A job set aside in `jobs/damaged/` (now or by an earlier start).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DamagedJob {
    pub id: JobId,
    /// What failed (the file and the check) and where the job now lies.
    pub reason: String,
}
