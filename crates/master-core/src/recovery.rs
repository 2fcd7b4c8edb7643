//! Journal recovery: what a persistent master keeps beside the journal so
//! that nothing the journal fails to keep or give back is lost (see the
//! server's `journal.rs`). Finished frames stay in memory until their write
//! succeeds (and are written again after a failure); each journaled job's
//! definition is kept to render a frame again that the journal cannot give
//! back ("repairs"); damaged jobs and frames are remembered to tell a
//! submitter that attaches. It sends nothing: its methods say what the
//! master tells whom.

use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;
use std::time::Duration;
use vtfarm_proto::JobId;

use vtfarm_proto::{FrameDone, JobScene, WireJob};

use crate::record::{KEPT_FRAME_RETRY, Record, Written};

/// One step of sending a submitter a job's finished frames in order
/// ([`Recovery::replay`]).
#[derive(Debug, PartialEq)]
pub(crate) enum Replayed {
    /// A frame held in memory (its write pending or failed).
    Frame(Box<FrameDone>),
    /// Frames the driver reads back from the journal.
    Journal(Range<u32>),
}

/// What a journal write's outcome asks of the master ([`Recovery::written`]).
#[derive(Debug, PartialEq)]
pub(crate) enum AfterWrite {
    /// A record to write again now (a frame whose write failed before).
    Rewrite(Option<Record>),
    /// The write failed: the error to count and tell the job's submitters.
    Failed(String),
}

/// The journal's side of the master: see the module's documentation.
#[derive(Default)]
pub(crate) struct Recovery {
    /// Whether jobs are journaled and outlive their submitter.
    persistent: bool,
    /// Finished frames not (yet) known to be written: until the driver
    /// says a frame's write succeeded ([`Recovery::written`]) it is
    /// replayed from here, and a frame whose write failed stays here as
    /// long as its job is kept.
    unjournaled: BTreeMap<(JobId, u32), FrameDone>,
    /// Each journaled job as queued (its scene by hash, or inline for a
    /// job restored complete), to render a frame again.
    definitions: BTreeMap<JobId, WireJob>,
    /// Jobs rendering one frame again that the journal could not give
    /// back: repair job → (its job, the frame).
    repairs: BTreeMap<JobId, (JobId, u32)>,
    /// Jobs set aside as damaged, with why: an attach is told so.
    damaged: BTreeMap<JobId, String>,
    /// Jobs a record of which could not be written, with the last error:
    /// a submitter attaching later is told too.
    failed_writes: BTreeMap<JobId, String>,
    /// Frames of `unjournaled` whose write failed (not queued again yet):
    /// one is written again after each write that succeeds, and at
    /// `retry_at` when no other record is written.
    to_rewrite: BTreeSet<(JobId, u32)>,
    /// When to write a frame of `to_rewrite` again ([`KEPT_FRAME_RETRY`]
    /// after the last failure).
    retry_at: Option<Duration>,
    /// Restored jobs whose journal had a damaged frame, rendered again:
    /// the frame and why, told to attaching submitters.
    damaged_frames: BTreeMap<JobId, (u32, String)>,
}

impl Recovery {
    /// A master that journals its jobs (`persistent`) or keeps nothing.
    pub(crate) fn new(persistent: bool) -> Recovery {
        Recovery {
            persistent,
            ..Recovery::default()
        }
    }

    /// Whether jobs are journaled and outlive their submitter.
    pub(crate) fn persistent(&self) -> bool {
        self.persistent
    }

    /// Whether `job`'s records are journaled: on a persistent master,
    /// unless it is a view's job (`view_owned`: it lives as long as the
    /// page looks at it) or a frame rendered again (journaled under its
    /// own job).
    pub(crate) fn journals(&self, job: JobId, view_owned: bool) -> bool {
        self.persistent && !view_owned && !self.repairs.contains_key(&job)
    }

    /// `record` goes to the journal: a frame stays here until it is
    /// written; a job forgotten or set aside takes what is kept of it.
    pub(crate) fn persisting(&mut self, record: &Record) {
        match record {
            Record::FrameDone(done) => {
                (self.unjournaled).insert((done.job, done.frame), (**done).clone());
            }
            Record::JobForgotten { id } | Record::JobDamaged { id, .. } => self.forget(*id),
            _ => {}
        }
    }

    /// A job's records are gone (or set aside): so is what is kept of it.
    fn forget(&mut self, job: JobId) {
        self.definitions.remove(&job);
        self.failed_writes.remove(&job);
        self.damaged_frames.remove(&job);
        self.unjournaled.retain(|&(j, _), _| j != job);
        self.to_rewrite.retain(|&(j, _)| j != job);
    }

    /// Keeps job `id`'s definition (its scene named by hash) to queue it
    /// again or render a frame of it again.
    pub(crate) fn keep_definition(&mut self, id: JobId, job: WireJob) {
        self.definitions.insert(id, job);
    }

    pub(crate) fn forget_definition(&mut self, id: JobId) {
        self.definitions.remove(&id);
    }

    /// Job `id`'s definition as kept.
    pub(crate) fn definition(&self, id: JobId) -> Option<&WireJob> {
        self.definitions.get(&id)
    }

    /// A restored job's frame was damaged in the journal and is rendered
    /// again: attaching submitters are told.
    pub(crate) fn frame_damaged(&mut self, job: JobId, damaged: (u32, String)) {
        self.damaged_frames.insert(job, damaged);
    }

    /// A job the journal set aside as damaged, and why.
    pub(crate) fn job_damaged(&mut self, job: JobId, reason: String) {
        self.damaged.insert(job, reason);
    }

    /// Why job `job` could not be read back, if it could not.
    pub(crate) fn damaged(&self, job: JobId) -> Option<&str> {
        self.damaged.get(&job).map(String::as_str)
    }

    /// The last failed write of `job`, if any.
    pub(crate) fn failed_write(&self, job: JobId) -> Option<&str> {
        self.failed_writes.get(&job).map(String::as_str)
    }

    /// `job`'s frame that was damaged in the journal, and why, if any.
    pub(crate) fn damaged_frame(&self, job: JobId) -> Option<&(u32, String)> {
        self.damaged_frames.get(&job)
    }

    /// Frame `frame` of `job`, held in memory (its write pending or failed).
    pub(crate) fn unjournaled(&self, job: JobId, frame: u32) -> Option<&FrameDone> {
        self.unjournaled.get(&(job, frame))
    }

    /// The finished frames `frames` of `job`, in order: those whose
    /// journal write is pending or failed from memory, the runs between
    /// them read back from the journal by the driver.
    pub(crate) fn replay(&self, job: JobId, frames: Range<u32>) -> Vec<Replayed> {
        let mut steps = Vec::new();
        let mut from_journal = frames.start..frames.start;
        for frame in frames {
            if let Some(done) = self.unjournaled.get(&(job, frame)) {
                if !from_journal.is_empty() {
                    steps.push(Replayed::Journal(from_journal));
                }
                from_journal = frame + 1..frame + 1;
                steps.push(Replayed::Frame(Box::new(done.clone())));
            } else {
                from_journal.end = frame + 1;
            }
        }
        if !from_journal.is_empty() {
            steps.push(Replayed::Journal(from_journal));
        }
        steps
    }

    /// The driver wrote a record (or failed to): a written frame leaves
    /// memory and a frame whose write failed is written again; a failure
    /// is kept for attaching submitters and its frame stays in memory.
    pub(crate) fn written(&mut self, now: Duration, written: Written) -> AfterWrite {
        match written.outcome {
            Ok(()) => {
                if let Some(frame) = written.frame {
                    self.unjournaled.remove(&(written.job, frame));
                }
                // The disk takes records again: write a frame that failed.
                AfterWrite::Rewrite(self.kept_frame_to_rewrite())
            }
            Err(error) => {
                if let Some(frame) = written.frame {
                    self.to_rewrite.insert((written.job, frame));
                }
                self.retry_at = Some(now + KEPT_FRAME_RETRY);
                let kept = written.frame.map_or(String::new(), |f| {
                    format!("; frame {f} is kept in memory until it is written")
                });
                let error = format!("{error}{kept}");
                (self.failed_writes).insert(written.job, error.clone());
                AfterWrite::Failed(error)
            }
        }
    }

    /// A frame whose write failed, to write again, if any.
    fn kept_frame_to_rewrite(&mut self) -> Option<Record> {
        (self.to_rewrite.pop_first())
            .and_then(|key| self.unjournaled.get(&key).cloned())
            .map(|done| Record::FrameDone(Box::new(done)))
    }

    /// When a kept frame is to be written again even while nothing else
    /// is written (the disk may have freed up).
    pub(crate) fn retry_at(&self) -> Option<Duration> {
        self.retry_at.filter(|_| !self.to_rewrite.is_empty())
    }

    /// At `now`: a kept frame to write again, if its retry is due.
    pub(crate) fn retry_due(&mut self, now: Duration) -> Option<Record> {
        if self.retry_at.is_none_or(|at| at > now) {
            return None;
        }
        self.retry_at = None;
        self.kept_frame_to_rewrite()
    }

    /// The job of frame `frame` of `job`, and the frame there: a frame
    /// rendered again is its own job's frame.
    pub(crate) fn owner(&self, job: JobId, frame: u32) -> (JobId, u32) {
        self.repairs.get(&job).copied().unwrap_or((job, frame))
    }

    /// The repair job rendering frame `frame` of `job` again, if one runs.
    pub(crate) fn repair_of(&self, job: JobId, frame: u32) -> Option<JobId> {
        (self.repairs.iter())
            .find_map(|(&repair, &owned)| (owned == (job, frame)).then_some(repair))
    }

    /// A repair job ended: the frame it rendered again, if it was one.
    pub(crate) fn repair_ended(&mut self, job: JobId) -> Option<(JobId, u32)> {
        self.repairs.remove(&job)
    }

    /// A job of the one frame `frame` of `job`, to render it again (its
    /// definition kept), or why not.
    pub(crate) fn again(&self, job: JobId, frame: u32) -> Result<WireJob, String> {
        let mut definition = (self.definitions.get(&job).cloned())
            .ok_or_else(|| format!("the master no longer keeps job {job}"))?;
        let setup = (definition.frames.get(frame as usize).cloned())
            .ok_or_else(|| format!("job {job} has no frame {frame}"))?;
        definition.frames = vec![setup];
        definition.name = format!("{} (frame {frame} again)", definition.name);
        Ok(definition)
    }

    /// Job `repair` renders frame `frame` of `job` again.
    pub(crate) fn repairing(&mut self, repair: JobId, job: JobId, frame: u32) {
        self.repairs.insert(repair, (job, frame));
    }
}

/// `job` with its scene named by hash (as the journal keeps it once queued).
pub(crate) fn by_hash(job: &WireJob) -> WireJob {
    let scene = match &job.scene {
        JobScene::Data(data) => JobScene::Hash(data.hash),
        JobScene::Hash(hash) => JobScene::Hash(*hash),
    };
    WireJob {
        name: job.name.clone(),
        scene,
        frames: job.frames.clone(),
        reflectors: job.reflectors.clone(),
        aux: job.aux,
        method: job.method,
        image: job.image,
        priority: job.priority,
        kind: job.kind,
    }
}

#[cfg(test)]
mod tests {
    use vtfarm_imaging::Image;
    use vtfarm_proto::{FrameStats, WireImage, WireImageFormat};

    use super::*;
    use crate::testkit;

    fn done(job: JobId, frame: u32) -> Record {
        Record::FrameDone(Box::new(FrameDone {
            job,
            frame,
            image: WireImage::encode(&Image::black(1, 1), WireImageFormat::Srgb8),
            stats: FrameStats::default(),
            aux: None,
        }))
    }

    fn written(job: JobId, frame: u32, outcome: Result<(), String>) -> Written {
        Written {
            job,
            frame: Some(frame),
            outcome,
        }
    }

    /// A replay sends the frames still in memory itself and asks the
    /// journal for the runs between them, in order.
    #[test]
    fn a_replay_takes_unwritten_frames_from_memory_and_the_rest_from_the_journal() {
        let mut recovery = Recovery::new(true);
        for frame in [2, 3, 6] {
            recovery.persisting(&done(JobId(1), frame));
        }
        let steps: Vec<String> = (recovery.replay(JobId(1), 0..8).iter())
            .map(|step| match step {
                Replayed::Frame(done) => format!("memory {}", done.frame),
                Replayed::Journal(frames) => format!("journal {frames:?}"),
            })
            .collect();
        let expected = [
            "journal 0..2",
            "memory 2",
            "memory 3",
            "journal 4..6",
            "memory 6",
            "journal 7..8",
        ];
        assert_eq!(steps, expected);
        assert_eq!(recovery.replay(JobId(2), 0..2), [Replayed::Journal(0..2)]);
    }

    /// A frame whose write failed stays in memory and is written again
    /// after the next write that succeeds; the failure is kept for
    /// submitters that attach later.
    #[test]
    fn a_frame_whose_write_failed_is_written_again_after_the_next_success() {
        let mut recovery = Recovery::new(true);
        recovery.persisting(&done(JobId(1), 0));
        recovery.persisting(&done(JobId(1), 1));
        let failed = recovery.written(
            Duration::ZERO,
            written(JobId(1), 0, Err("disk full".into())),
        );
        let error = "disk full; frame 0 is kept in memory until it is written";
        assert_eq!(failed, AfterWrite::Failed(error.into()));
        assert_eq!(recovery.failed_write(JobId(1)), Some(error));
        assert!(recovery.unjournaled(JobId(1), 0).is_some());
        let again = recovery.written(Duration::ZERO, written(JobId(1), 1, Ok(())));
        assert_eq!(again, AfterWrite::Rewrite(Some(done(JobId(1), 0))));
        assert!(recovery.unjournaled(JobId(1), 1).is_none(), "written");
        assert_eq!(
            recovery.written(Duration::ZERO, written(JobId(1), 0, Ok(()))),
            AfterWrite::Rewrite(None)
        );
        assert!(recovery.unjournaled(JobId(1), 0).is_none());
    }

    /// A frame whose write failed is written again when its retry is due,
    /// even if no other record is written meanwhile (the disk freed up
    /// while the master was idle).
    #[test]
    fn a_frame_whose_write_failed_is_written_again_when_its_retry_is_due() {
        let mut recovery = Recovery::new(true);
        recovery.persisting(&done(JobId(1), 0));
        let at = Duration::from_secs(7);
        recovery.written(at, written(JobId(1), 0, Err("disk full".into())));
        assert_eq!(recovery.retry_at(), Some(at + KEPT_FRAME_RETRY));
        assert_eq!(recovery.retry_due(at), None, "not due yet");
        assert_eq!(
            recovery.retry_due(at + KEPT_FRAME_RETRY),
            Some(done(JobId(1), 0))
        );
        assert_eq!(recovery.retry_at(), None, "nothing left to retry");
    }

    /// A forgotten job takes what is kept of it; a repair renders its
    /// job's frame and is journaled under that job, never its own.
    #[test]
    fn a_repair_renders_a_kept_jobs_frame_and_is_not_journaled_itself() {
        let mut recovery = Recovery::new(true);
        let (job, _, _) = testkit::job(3);
        recovery.keep_definition(JobId(1), job);
        let again = recovery.again(JobId(1), 2).unwrap();
        assert_eq!(
            (again.frames.len(), again.name.as_str()),
            (1, "square (frame 2 again)")
        );
        assert!(recovery.again(JobId(1), 3).is_err(), "no frame 3");
        recovery.repairing(JobId(5), JobId(1), 2);
        assert_eq!(recovery.owner(JobId(5), 0), (JobId(1), 2));
        assert_eq!(recovery.repair_of(JobId(1), 2), Some(JobId(5)));
        assert!(recovery.journals(JobId(1), false));
        assert!(!recovery.journals(JobId(5), false), "a repair");
        assert!(!recovery.journals(JobId(1), true), "a view's job");
        assert!(
            !Recovery::new(false).journals(JobId(1), false),
            "not persistent"
        );
        recovery.persisting(&Record::JobForgotten { id: JobId(1) });
        assert!(recovery.again(JobId(1), 2).is_err(), "forgotten");
        assert_eq!(recovery.repair_ended(JobId(5)), Some((JobId(1), 2)));
    }
}
