//! What the core asks the journal to keep ([`Record`]) and what a restarted
//! master reads back from it ([`StoredJob`]). Plain data: the server crate's
//! `journal` writes and reads the files.

use std::sync::Arc;

use vtfarm_proto::{FrameDone, SceneData, WireJob};

/// What the core asks to keep.
#[derive(Clone, Debug, PartialEq)]
pub enum Record {
    /// A job was queued (its scene by hash in `job`, the bytes in `scene`).
    JobQueued {
        id: u64,
        job: Box<WireJob>,
        scene: Arc<SceneData>,
    },
    /// A frame finished.
    FrameDone(Box<FrameDone>),
    /// Every frame of the job is done (kept for re-attaching submitters).
    JobComplete { id: u64 },
    /// The job is gone: failed, cancelled, or delivered long enough ago.
    JobForgotten { id: u64 },
}

impl Record {
    /// The job the record is about.
    pub fn job(&self) -> u64 {
        match self {
            Record::JobQueued { id, .. }
            | Record::JobComplete { id }
            | Record::JobForgotten { id } => *id,
            Record::FrameDone(done) => done.job,
        }
    }
}

/// A job read back from the journal.
#[derive(Debug)]
pub struct StoredJob {
    pub id: u64,
    /// The job with its scene's bytes (`JobScene::Data`).
    pub job: WireJob,
    /// How many frames are finished, counted from frame 0 without a gap.
    pub frames_done: u32,
    pub complete: bool,
}
