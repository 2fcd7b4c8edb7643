//! The master's job journal: its queue and each job's finished frames, kept
//! in the state directory so that a restarted master resumes its jobs from
//! the last finished frame and a submitter can re-attach.
//!
//! Layout (every file one protocol message, written to a temporary name and
//! renamed, so a crash leaves either the old or the new file):
//!
//! ```text
//! STATE/jobs/format                the journal's format, [`JOURNAL_FORMAT`]
//! STATE/jobs/scenes/HASH.scene     the scene bytes of queued jobs
//! STATE/jobs/NNNNNNNNNNNN/job      SubmitJob { job } (scene by hash)
//! STATE/jobs/NNNNNNNNNNNN/FFFFFF   FrameDone of frame F
//! STATE/jobs/NNNNNNNNNNNN/complete present once every frame is done
//! ```
//!
//! Frames are the bulk; a `FrameDone` already carries its image compressed
//! in the job's format (`WireImage`), so the file holds the very message the
//! submitter got, and a re-attached submitter gets the same bytes. A
//! delivered job's frames go [`ATTACH_GRACE`](vtfarm_master_core::ATTACH_GRACE)
//! after it completes. A journal of another format (an older master's) is
//! refused at start with an error that says what to do.
//!
//! The core never touches it: it emits [`Record`]s, the driver writes them
//! and feeds [`StoredJob`]s back at start. A damaged entry is skipped with a
//! warning naming its file; the master never fails to start over it.

use std::io::Read;
use std::path::{Path, PathBuf};

use tracing::warn;
use vtfarm_master_core::{Record, StoredJob};
use vtfarm_proto::{
    FrameDone, JobScene, MAX_MESSAGE_BYTES, Message, SceneData, SceneHash, decode_message,
    encode_message,
};

/// Writes a [`Journal`]'s records on a thread of its own, in order, so that
/// the master's driver does not wait for a finished frame's compression and
/// disk (a 1080p frame is 25 MB before compression). [`JournalWriter::flush`]
/// waits until everything sent before it is written (before the journal is
/// read back, as for a replay). Dropping the writer writes what is queued
/// and ends the thread. At most [`JournalWriter::QUEUED`] records wait: when
/// the disk falls behind, the driver waits for it instead of holding an
/// unbounded backlog of frames in memory.
pub struct JournalWriter {
    queue: Option<std::sync::mpsc::SyncSender<WriterInput>>,
    thread: Option<std::thread::JoinHandle<()>>,
}

enum WriterInput {
    Write(Box<Record>),
    Flush(std::sync::mpsc::Sender<()>),
}

impl JournalWriter {
    /// Records queued before [`JournalWriter::write`] waits for the disk.
    pub const QUEUED: usize = 4;

    pub fn new(journal: Journal) -> JournalWriter {
        let (queue, inputs) = std::sync::mpsc::sync_channel(Self::QUEUED);
        let thread = std::thread::Builder::new()
            .name("journal".into())
            .spawn(move || {
                for input in inputs {
                    match input {
                        WriterInput::Write(record) => journal.write(*record),
                        WriterInput::Flush(done) => {
                            let _ = done.send(());
                        }
                    }
                }
            });
        match thread {
            Ok(thread) => JournalWriter {
                queue: Some(queue),
                thread: Some(thread),
            },
            Err(e) => {
                warn!("cannot start the journal thread ({e}): records are not kept");
                JournalWriter {
                    queue: None,
                    thread: None,
                }
            }
        }
    }

    /// Queues a record (waits while [`JournalWriter::QUEUED`] are queued).
    pub fn write(&self, record: Record) {
        if let Some(queue) = &self.queue {
            let _ = queue.send(WriterInput::Write(Box::new(record)));
        }
    }

    /// Waits until every record queued so far is written.
    pub fn flush(&self) {
        let (done, written) = std::sync::mpsc::channel();
        if let Some(queue) = &self.queue {
            if queue.send(WriterInput::Flush(done)).is_ok() {
                let _ = written.recv();
            }
        }
    }
}

impl Drop for JournalWriter {
    fn drop(&mut self) {
        drop(self.queue.take());
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The journal's format: 2 since finished frames are kept as sent
/// (compressed inside the message), 1 (no `format` file) before.
pub const JOURNAL_FORMAT: u32 = 2;

/// Why the journal cannot be used.
#[derive(Debug, thiserror::Error)]
#[error("job journal {path}: {source}")]
pub struct JournalError {
    path: PathBuf,
    source: std::io::Error,
}

impl JournalError {
    fn other(path: PathBuf, message: String) -> JournalError {
        JournalError {
            path,
            source: std::io::Error::other(message),
        }
    }
}

/// The journal in a directory.
#[derive(Clone, Debug)]
pub struct Journal {
    dir: PathBuf,
}

impl Journal {
    /// Opens (creating) the journal under `state_dir/jobs`; refuses one of
    /// another [`JOURNAL_FORMAT`].
    pub fn open(state_dir: &Path) -> Result<Journal, JournalError> {
        let dir = state_dir.join("jobs");
        std::fs::create_dir_all(dir.join("scenes")).map_err(|source| JournalError {
            path: dir.clone(),
            source,
        })?;
        let journal = Journal { dir };
        let path = journal.dir.join("format");
        let format = match std::fs::read_to_string(&path) {
            Ok(text) => text.trim().parse::<u32>().ok(),
            // No file: format 1, unless the journal is empty.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                (!journal.job_ids().is_empty()).then_some(1)
            }
            Err(source) => return Err(JournalError { path, source }),
        };
        match format {
            Some(JOURNAL_FORMAT) => Ok(journal),
            None if !path.exists() => {
                write_atomic(&path, format!("{JOURNAL_FORMAT}\n").as_bytes())
                    .map_err(|source| JournalError { path, source })?;
                Ok(journal)
            }
            other => {
                let found =
                    other.map_or("an unreadable format".to_owned(), |f| format!("format {f}"));
                Err(JournalError::other(
                    journal.dir.clone(),
                    format!(
                        "{found}, but this master reads format {JOURNAL_FORMAT}: finish its jobs with the master that wrote it, or remove the directory to start afresh"
                    ),
                ))
            }
        }
    }

    fn job_dir(&self, id: u64) -> PathBuf {
        self.dir.join(format!("{id:012}"))
    }

    fn scene_path(&self, hash: &SceneHash) -> PathBuf {
        self.dir
            .join("scenes")
            .join(format!("{}.scene", hex::encode(hash)))
    }

    fn frame_path(&self, id: u64, frame: u32) -> PathBuf {
        self.job_dir(id).join(format!("{frame:06}"))
    }

    /// Writes a record; a failure is logged (the farm goes on, unjournaled).
    /// Taken by value: a finished frame is written without a copy.
    pub fn write(&self, record: Record) {
        let what = record_name(&record);
        let written = match record {
            Record::JobQueued { id, job, scene } => {
                let scene_path = self.scene_path(&scene.hash);
                let scene_written = if scene_path.exists() {
                    Ok(())
                } else {
                    write_atomic(&scene_path, &scene.bytes)
                };
                scene_written.and_then(|()| {
                    std::fs::create_dir_all(self.job_dir(id))?;
                    let message = Message::SubmitJob { job: *job };
                    write_message(&self.job_dir(id).join("job"), &message)
                })
            }
            Record::FrameDone(done) => write_message(
                &self.frame_path(done.job, done.frame),
                &Message::FrameDone(*done),
            ),
            Record::JobComplete { id } => write_atomic(&self.job_dir(id).join("complete"), b""),
            Record::JobForgotten { id } => {
                let removed = std::fs::remove_dir_all(self.job_dir(id));
                let removed = removed.or_else(|e| match e.kind() {
                    std::io::ErrorKind::NotFound => Ok(()),
                    _ => Err(e),
                });
                removed.and_then(|()| self.remove_unused_scenes())
            }
        };
        if let Err(e) = written {
            warn!(dir = %self.dir.display(), "cannot journal {what}: {e}");
        }
    }

    /// Removes the scenes no journaled job names any more.
    fn remove_unused_scenes(&self) -> std::io::Result<()> {
        let used: Vec<String> = (self.job_ids().into_iter())
            .filter_map(|id| match read_message(&self.job_dir(id).join("job"))? {
                Message::SubmitJob { job } => match job.scene {
                    JobScene::Hash(hash) => Some(format!("{}.scene", hex::encode(hash))),
                    JobScene::Data(_) => None,
                },
                _ => None,
            })
            .collect();
        for entry in std::fs::read_dir(self.dir.join("scenes"))? {
            let entry = entry?;
            if !used.iter().any(|u| entry.file_name() == u.as_str()) {
                std::fs::remove_file(entry.path())?;
            }
        }
        Ok(())
    }

    /// The ids of the journaled jobs, in order.
    fn job_ids(&self) -> Vec<u64> {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return Vec::new();
        };
        let mut ids: Vec<u64> = entries
            .filter_map(|e| e.ok()?.file_name().to_str()?.parse().ok())
            .collect();
        ids.sort_unstable();
        ids
    }

    /// A finished frame, if the journal has it.
    pub fn frame(&self, id: u64, frame: u32) -> Option<FrameDone> {
        match read_message(&self.frame_path(id, frame))? {
            Message::FrameDone(done) if done.job == id && done.frame == frame => Some(done),
            _ => None,
        }
    }

    /// Every job in the journal, in id order; damaged ones are skipped with a warning.
    pub fn load(&self) -> Vec<StoredJob> {
        (self.job_ids().into_iter())
            .filter_map(|id| self.load_job(id))
            .collect()
    }

    fn load_job(&self, id: u64) -> Option<StoredJob> {
        let path = self.job_dir(id).join("job");
        let Some(Message::SubmitJob { mut job }) = read_message(&path) else {
            warn!(path = %path.display(), "skipping a damaged journal entry");
            return None;
        };
        let JobScene::Hash(hash) = job.scene else {
            warn!(path = %path.display(), "skipping a journal entry with an inline scene");
            return None;
        };
        let scene_path = self.scene_path(&hash);
        let Ok(bytes) = std::fs::read(&scene_path) else {
            warn!(path = %scene_path.display(), "skipping a job whose scene is missing");
            return None;
        };
        job.scene = JobScene::Data(SceneData { hash, bytes });
        let frames = job.frames.len() as u32;
        let frames_done = (0..frames)
            .take_while(|&f| self.frame_path(id, f).exists())
            .count() as u32;
        let complete = self.job_dir(id).join("complete").exists() && frames_done == frames;
        Some(StoredJob {
            id,
            job,
            frames_done,
            complete,
        })
    }
}

fn record_name(record: &Record) -> String {
    match record {
        Record::JobQueued { id, .. } => format!("job {id}"),
        Record::FrameDone(done) => format!("job {} frame {}", done.job, done.frame),
        Record::JobComplete { id } => format!("the completion of job {id}"),
        Record::JobForgotten { id } => format!("the removal of job {id}"),
    }
}

fn write_message(path: &Path, message: &Message) -> std::io::Result<()> {
    let frame = encode_message(message).map_err(std::io::Error::other)?;
    write_atomic(path, &frame[4..])
}

/// Reads a message, no more than a message may hold (a damaged file
/// cannot make the master allocate more).
fn read_message(path: &Path) -> Option<Message> {
    let mut bytes = Vec::new();
    (std::fs::File::open(path).ok()?)
        .take(u64::from(MAX_MESSAGE_BYTES) + 1)
        .read_to_end(&mut bytes)
        .ok()?;
    if bytes.len() > MAX_MESSAGE_BYTES as usize {
        return None;
    }
    decode_message(&bytes).ok()
}

/// Writes `bytes` to a temporary file beside `path` and renames it over `path`.
fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let temporary = path.with_extension("partial");
    std::fs::write(&temporary, bytes)?;
    std::fs::rename(&temporary, path)
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::Vec3;
    use vtfarm_proto::{FrameStats, WireImage};
    use vtfarm_render::FrameSetup;
    use vtfarm_scene::{Camera, Scene};

    use super::*;

    fn frame_done(job: u64, frame: u32) -> Record {
        Record::FrameDone(Box::new(FrameDone {
            job,
            frame,
            image: WireImage::from_pixels(1, 1, &[Vec3::splat(frame as f32)]),
            stats: FrameStats::default(),
            aux: None,
        }))
    }

    #[test]
    fn a_job_reads_back_up_to_its_first_missing_frame_and_goes_with_its_scene() {
        let dir = tempfile::tempdir().unwrap();
        let journal = Journal::open(dir.path()).unwrap();
        let scene = Arc::new(SceneData::from_scene(&Scene::default()));
        let setup = FrameSetup {
            camera: Camera {
                eye: Vec3::ZERO,
                target: Vec3::Z,
                up: Vec3::Y,
                fov_y_deg: 60.0,
                width: 1,
                height: 1,
            },
            lighting: Default::default(),
            trace: Default::default(),
            vertex: Default::default(),
        };
        let options = crate::JobOptions {
            method: vtfarm_method::MethodKind::VertexTracing,
            aux: false,
        };
        let frames = [setup.clone(), setup.clone(), setup];
        let job = crate::wire_job("j", &scene, &frames, &[0], options);
        journal.write(Record::JobQueued {
            id: 4,
            job: Box::new(job.clone()),
            scene: scene.clone(),
        });
        journal.write(frame_done(4, 0));
        journal.write(frame_done(4, 2));
        let stored = journal.load();
        assert_eq!(stored.len(), 1);
        assert_eq!(
            (stored[0].id, stored[0].frames_done, stored[0].complete),
            (4, 1, false)
        );
        assert_eq!(stored[0].job.scene, JobScene::Data((*scene).clone()));
        assert_eq!(stored[0].job.frames, job.frames);
        assert_eq!(journal.frame(4, 2).unwrap().frame, 2);

        journal.write(Record::JobForgotten { id: 4 });
        assert!(journal.load().is_empty());
        assert!(journal.frame(4, 0).is_none());
        let scenes = std::fs::read_dir(dir.path().join("jobs/scenes")).unwrap();
        assert_eq!(scenes.count(), 0, "the scene went with its last job");
    }

    /// The writer thread keeps the records' order (a job's directory
    /// before its frames, its removal after them), and a flush makes
    /// everything sent before it readable.
    #[test]
    fn the_writer_thread_keeps_the_order_and_a_flush_makes_records_readable() {
        let dir = tempfile::tempdir().unwrap();
        let journal = Journal::open(dir.path()).unwrap();
        let writer = JournalWriter::new(journal.clone());
        // No JobQueued: the frames need the job's directory, made here.
        std::fs::create_dir_all(journal.job_dir(3)).unwrap();
        for frame in 0..20 {
            writer.write(frame_done(3, frame));
        }
        writer.flush();
        for frame in 0..20 {
            assert_eq!(journal.frame(3, frame).map(|d| d.frame), Some(frame));
        }
        writer.write(frame_done(3, 20));
        writer.write(Record::JobForgotten { id: 3 });
        writer.write(frame_done(3, 21));
        drop(writer);
        // Removed after frame 20; frame 21 then finds no directory.
        assert!(journal.frame(3, 20).is_none());
        assert!(journal.frame(3, 21).is_none());
    }

    #[test]
    fn a_frame_is_kept_compressed_and_reads_back_bit_for_bit() {
        let c = vtfarm_cockpit::cockpit(&vtfarm_cockpit::CockpitConfig {
            detail: 0.3,
            ..Default::default()
        });
        let camera = Camera {
            width: 160,
            height: 90,
            ..c.camera
        };
        let (image, _) = vtfarm_raster::rasterize(&c.scene, &camera, &c.lighting);
        let done = FrameDone {
            job: 7,
            frame: 3,
            image: WireImage::from_pixels(160, 90, &image.pixels),
            stats: FrameStats::default(),
            aux: None,
        };
        let dir = tempfile::tempdir().unwrap();
        let journal = Journal::open(dir.path()).unwrap();
        std::fs::create_dir_all(journal.job_dir(7)).unwrap();
        journal.write(Record::FrameDone(Box::new(done.clone())));
        assert_eq!(journal.frame(7, 3), Some(done));
        let raw = 160 * 90 * 12;
        let kept = std::fs::metadata(journal.frame_path(7, 3)).unwrap().len();
        assert!(kept * 3 < raw, "{kept} bytes for a {raw}-byte frame");
    }

    /// A journal an older master wrote (format 1: no `format` file, frames
    /// compressed whole) or one of an unknown format is refused with an
    /// error that names it; an empty or current one opens.
    #[test]
    fn a_journal_of_another_format_is_refused_with_a_clear_error() {
        let dir = tempfile::tempdir().unwrap();
        Journal::open(dir.path()).unwrap();
        assert_eq!(
            std::fs::read_to_string(dir.path().join("jobs/format")).unwrap(),
            "2\n"
        );
        Journal::open(dir.path()).expect("the current format opens again");

        let old = tempfile::tempdir().unwrap();
        std::fs::create_dir_all(old.path().join("jobs/000000000001")).unwrap();
        let error = Journal::open(old.path()).expect_err("format 1").to_string();
        assert!(
            error.contains("format 1, but this master reads format 2"),
            "{error}"
        );
        assert!(
            error.contains(&old.path().join("jobs").display().to_string()),
            "{error}"
        );

        std::fs::write(old.path().join("jobs/format"), "7\n").unwrap();
        let error = Journal::open(old.path()).expect_err("format 7").to_string();
        assert!(error.contains("format 7"), "{error}");
    }

    #[test]
    fn a_damaged_entry_is_skipped() {
        let dir = tempfile::tempdir().unwrap();
        let journal = Journal::open(dir.path()).unwrap();
        std::fs::create_dir_all(journal.job_dir(1)).unwrap();
        std::fs::write(journal.job_dir(1).join("job"), b"\xff\xfe not a message").unwrap();
        assert!(journal.load().is_empty());
        assert!(journal.frame(1, 0).is_none());
        // A frame file that is not zstd, or that decompresses to garbage.
        std::fs::write(journal.frame_path(1, 0), b"\x28\xb5\x2f\xfd garbage").unwrap();
        assert!(journal.frame(1, 0).is_none());
        let not_a_message = zstd::bulk::compress(&[0xff; 64], 3).unwrap();
        std::fs::write(journal.frame_path(1, 0), not_a_message).unwrap();
        assert!(journal.frame(1, 0).is_none());
    }
}
