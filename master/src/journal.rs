//! The master's job journal: its queue and each job's finished frames, kept
//! in the state directory so that a restarted master resumes its jobs from
//! the last finished frame and a submitter can re-attach.
//!
//! Layout (every file one record, see below):
//!
//! ```text
//! STATE/jobs/format                the journal's format, [`JOURNAL_FORMAT`]
//! STATE/jobs/scenes/HASH.scene     the scene bytes of queued jobs
//! STATE/jobs/NNNNNNNNNNNN/job      SubmitJob { job } (scene by hash)
//! STATE/jobs/NNNNNNNNNNNN/FFFFFF   FrameDone of frame F
//! STATE/jobs/NNNNNNNNNNNN/complete present once every frame is done
//! STATE/jobs/NNNNNNNNNNNN/state    JobList { jobs: [its listing] }: state,
//!                                  priority, times (the newest replaces it)
//! STATE/jobs/NNNNNNNNNNNN/study    a study's directory holds this alone:
//!                                  JobRows { rows: [its row] }, its listing
//!                                  and its variants (jobs of their own)
//! STATE/jobs/damaged/NNNNNNNNNNNN  a job set aside, with `why` beside its files
//! STATE/jobs/damaged/stray-NAME    an entry that is no job's (a second
//!                                  spelling of an id, a stray file), with `why`
//! ```
//!
//! A job's directory is named by its id in exactly one spelling (twelve
//! digits); any other entry in `jobs/` is set aside at start with its
//! reason and never read as a job, so no job is read twice.
//!
//! A record proves itself: its bytes follow their CRC32C ([`RECORD_HEADER`]),
//! and every read checks it, so a flipped byte, a truncated or an emptied
//! file is an error naming the file and the check, never a wrong frame.
//! Inside the checksum every job record starts with its envelope
//! ([`RecordKind`]): the journal's format, the record's kind and its job's
//! id, so a record in another job's directory (or in another file's place)
//! is an error naming the file, never that job's. A record is written to a
//! temporary file, fsynced and renamed (and the directory fsynced), so a
//! crash leaves the old record or the new one. Records are read only from
//! regular files and within [`MAX_MESSAGE_BYTES`]: a FIFO or a device in
//! the journal is an error, never a read that blocks or does not end.
//!
//! A job whose `state` is missing or damaged is held paused with a warning
//! naming the file (nothing else says whether it was cancelled or paused,
//! and such a job must not run again on its own); one whose `complete`
//! stands with every frame is complete.
//!
//! Frames are the bulk; a `FrameDone` already carries its image compressed
//! in the job's format (`WireImage`), so the file holds the very message the
//! submitter got, and a re-attached submitter gets the same bytes. A
//! finished job (completed, failed or cancelled) and its frames go when the
//! master's retention lets it go (`vtfarm master --keep-jobs`,
//! `--keep-jobs-hours`). A journal of format 4 (records without their
//! envelope) is upgraded at start: each record of each job's directory is
//! written again inside its envelope, naming the job its directory names,
//! and the format becomes [`JOURNAL_FORMAT`]; an interrupted upgrade
//! continues at the next start. A journal of any other format is refused at
//! start with an error that says what to do.
//!
//! The core never touches it: it emits [`Record`]s, the driver writes them
//! (and tells the core how each frame's write went) and feeds [`StoredJob`]s
//! back at start. At start a job whose own record (or scene) fails its check
//! is moved to `jobs/damaged/` with a warning naming the file and the check,
//! never deleted; a frame that fails its check is renamed `FFFFFF.damaged`
//! and the job resumes from it (it is rendered again).

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use vtfarm_proto::JobId;

use tracing::warn;
use vtfarm_master_core::{DamagedJob, Record, StoredJob, Written};
use vtfarm_proto::{
    FrameDone, JobRow, JobScene, JobSummary, MAX_MESSAGE_BYTES, Message, SceneData, SceneHash,
    decode_message, encode_message,
};
use vtfarm_scene::file::{read_regular, read_regular_text};

/// Writes a [`Journal`]'s records on a thread of its own, in order, so that
/// the master's driver does not wait for a finished frame's compression and
/// disk (a 1080p frame is 25 MB before compression). [`JournalWriter::flush`]
/// waits until everything sent before it is written (before the journal is
/// read back, as for a replay). Dropping the writer writes what is queued
/// and ends the thread. At most [`JournalWriter::QUEUED`] records wait: when
/// the disk falls behind, the driver waits for it instead of holding an
/// unbounded backlog of frames in memory. Each record's outcome goes to the
/// `report` callback given at start (the driver hands it to the core).
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

    /// A writer of `journal` that tells `report` how each record went.
    pub fn new(journal: Journal, report: impl Fn(Written) + Send + 'static) -> JournalWriter {
        let (queue, inputs) = std::sync::mpsc::sync_channel(Self::QUEUED);
        let thread = std::thread::Builder::new()
            .name("journal".into())
            .spawn(move || {
                for input in inputs {
                    match input {
                        WriterInput::Write(record) => {
                            let (job, frame) = (record.job(), record.frame());
                            let outcome = journal.write(*record).map_err(|e| e.to_string());
                            report(Written {
                                job,
                                frame,
                                outcome,
                            });
                        }
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

/// What [`Journal::load`] found.
#[derive(Debug, Default)]
pub struct Loaded {
    /// The jobs to resume, in id order.
    pub jobs: Vec<StoredJob>,
    /// The jobs set aside, in id order.
    pub damaged: Vec<DamagedJob>,
    /// The studies (each a listing over its variants, which are `jobs`),
    /// in id order: restored after the jobs.
    pub studies: Vec<JobRow>,
}

/// The journal's format: 5 since every record names its job, kind and
/// format ([`RecordKind`]), 4 when jobs first carried their priority and
/// kind and kept their listing (`state`), 3 when every record first carried
/// its checksum, 2 when finished frames were kept as sent without one, 1
/// (no `format` file) before.
pub const JOURNAL_FORMAT: u32 = 5;

/// The older format this master upgrades at start (see the module's doc).
pub const UPGRADED_FORMAT: u32 = 4;

/// The most bytes of the `format` file and of a `why` file.
const MAX_NOTE_BYTES: u64 = 64 << 10;

/// What a job's record holds; its envelope's kind byte. A new kind of
/// record takes the next free code, and a master that does not know a code
/// refuses the record naming it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordKind {
    /// `job`: the job as submitted (`SubmitJob`).
    Job,
    /// `FFFFFF`: a finished frame (`FrameDone`).
    Frame,
    /// `state`: the job's listing (`JobList` of one).
    State,
    /// `complete`: every frame is done (no body).
    Complete,
    /// `study`: a study's row (`JobRows` of one), alone in its directory.
    Study,
}

/// The start of every job record's payload.
const ENVELOPE_MAGIC: [u8; 4] = *b"vtjr";
/// Magic, format (u32), kind (u8), job id (u64), little-endian.
const ENVELOPE_BYTES: usize = 4 + 4 + 1 + 8;

impl RecordKind {
    const ALL: [RecordKind; 5] = [
        RecordKind::Job,
        RecordKind::Frame,
        RecordKind::State,
        RecordKind::Complete,
        RecordKind::Study,
    ];

    fn code(self) -> u8 {
        match self {
            RecordKind::Job => 1,
            RecordKind::Frame => 2,
            RecordKind::State => 3,
            RecordKind::Complete => 4,
            RecordKind::Study => 5,
        }
    }

    /// What a record of this kind is, for errors.
    fn record(self) -> &'static str {
        match self {
            RecordKind::Job => "a job record",
            RecordKind::Frame => "a frame record",
            RecordKind::State => "a state record",
            RecordKind::Complete => "a complete record",
            RecordKind::Study => "a study record",
        }
    }

    /// The kind a file of this name in a job's directory holds.
    fn of_file(name: &str) -> Option<RecordKind> {
        match name {
            "job" => Some(RecordKind::Job),
            "state" => Some(RecordKind::State),
            "complete" => Some(RecordKind::Complete),
            "study" => Some(RecordKind::Study),
            _ if name.len() == 6 && name.bytes().all(|b| b.is_ascii_digit()) => {
                Some(RecordKind::Frame)
            }
            _ => None,
        }
    }
}

/// A job record's payload: its envelope, then `body`.
fn envelope(kind: RecordKind, job: JobId, body: &[u8]) -> Vec<u8> {
    let mut payload = Vec::with_capacity(ENVELOPE_BYTES + body.len());
    payload.extend_from_slice(&ENVELOPE_MAGIC);
    payload.extend_from_slice(&JOURNAL_FORMAT.to_le_bytes());
    payload.push(kind.code());
    payload.extend_from_slice(&job.0.to_le_bytes());
    payload.extend_from_slice(body);
    payload
}

/// What an envelope names.
struct Envelope {
    format: u32,
    kind: Result<RecordKind, u8>,
    job: JobId,
}

/// The envelope at the start of `payload` and the body after it; `None`
/// without one (a record of format 4).
fn split_envelope(payload: &[u8]) -> Option<(Envelope, &[u8])> {
    if payload.len() < ENVELOPE_BYTES || payload[..4] != ENVELOPE_MAGIC {
        return None;
    }
    let format = u32::from_le_bytes(payload[4..8].try_into().expect("4 bytes"));
    let code = payload[8];
    let kind = (RecordKind::ALL.into_iter())
        .find(|k| k.code() == code)
        .ok_or(code);
    let job = JobId(u64::from_le_bytes(
        payload[9..17].try_into().expect("8 bytes"),
    ));
    Some((Envelope { format, kind, job }, &payload[ENVELOPE_BYTES..]))
}

/// The body of the record at `path`, which must be a `kind` record of job
/// `job` in this format.
fn open_envelope(
    path: &Path,
    payload: &[u8],
    kind: RecordKind,
    job: JobId,
) -> Result<Vec<u8>, RecordError> {
    let content = |error: String| RecordError::Content {
        path: path.to_owned(),
        expected: kind.record(),
        error,
    };
    let Some((envelope, body)) = split_envelope(payload) else {
        return Err(content(
            "no envelope naming its job, kind and format".to_owned(),
        ));
    };
    if envelope.format != JOURNAL_FORMAT {
        return Err(content(format!(
            "a record of format {}, this master reads format {JOURNAL_FORMAT}",
            envelope.format
        )));
    }
    match envelope.kind {
        Ok(found) if found == kind => {}
        Ok(found) => return Err(content(format!("it holds {}", found.record()))),
        Err(code) => {
            return Err(content(format!(
                "it holds a record of kind {code}, which this master does not know"
            )));
        }
    }
    if envelope.job != job {
        return Err(content(format!(
            "it holds a record of job {}, not of job {job} whose directory it is in",
            envelope.job
        )));
    }
    Ok(body.to_vec())
}

/// Every record file starts with the CRC32C of the bytes after it, 4 bytes
/// little-endian.
pub const RECORD_HEADER: usize = 4;

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

/// Why a record could not be read back: each names the file.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    #[error("{}: missing", .path.display())]
    Missing { path: PathBuf },
    #[error("{}: cannot read: {source}", .path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {len} bytes, too short to hold a record's checksum", .path.display())]
    Truncated { path: PathBuf, len: usize },
    #[error("{}: more than a record may hold ({MAX_MESSAGE_BYTES} bytes)", .path.display())]
    TooLarge { path: PathBuf },
    #[error("{}: checksum mismatch (CRC32C {stored:08x} stored, {computed:08x} computed)", .path.display())]
    Checksum {
        path: PathBuf,
        stored: u32,
        computed: u32,
    },
    #[error("{}: not a directory (a job's records are a directory)", .path.display())]
    NotADirectory { path: PathBuf },
    #[error("{}: checksum good but not {expected}: {error}", .path.display())]
    Content {
        path: PathBuf,
        expected: &'static str,
        error: String,
    },
}

/// Why a record could not be written.
#[derive(Debug, thiserror::Error)]
#[error("cannot journal {what} ({}): {source}", .path.display())]
pub struct WriteError {
    what: String,
    path: PathBuf,
    source: std::io::Error,
}

/// Where the journal's bytes go: the disk, or (in tests) a store that
/// fails on demand, as a full disk does.
pub trait Storage: Send + Sync {
    /// Writes `bytes` to `path` so that a crash leaves the old file or the
    /// new one, never half of one.
    fn write_atomic(&self, path: &Path, bytes: &[u8]) -> std::io::Result<()>;
}

/// The journal's storage on the file system: temporary file, fsync, rename,
/// fsync of the directory.
#[derive(Clone, Copy, Debug, Default)]
pub struct Disk;

impl Storage for Disk {
    fn write_atomic(&self, path: &Path, bytes: &[u8]) -> std::io::Result<()> {
        let temporary = path.with_extension("partial");
        let written = (|| {
            let mut file = std::fs::File::create(&temporary)?;
            file.write_all(bytes)?;
            file.sync_all()
        })();
        if let Err(e) = written {
            // A full disk must not keep the half-written file.
            let _ = std::fs::remove_file(&temporary);
            return Err(e);
        }
        std::fs::rename(&temporary, path)?;
        match path.parent() {
            Some(dir) => std::fs::File::open(dir)?.sync_all(),
            None => Ok(()),
        }
    }
}

/// The journal in a directory.
#[derive(Clone)]
pub struct Journal {
    dir: PathBuf,
    storage: Arc<dyn Storage>,
}

impl std::fmt::Debug for Journal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Journal").field("dir", &self.dir).finish()
    }
}

/// A record's file bytes: the checksum, then the payload.
fn record_bytes(payload: &[u8]) -> Vec<u8> {
    let mut bytes = Vec::with_capacity(RECORD_HEADER + payload.len());
    bytes.extend_from_slice(&crc32c::crc32c(payload).to_le_bytes());
    bytes.extend_from_slice(payload);
    bytes
}

/// Reads a record and checks its checksum, no more than a message may hold
/// (a damaged file cannot make the master allocate more).
fn read_record(path: &Path) -> Result<Vec<u8>, RecordError> {
    let path_buf = || path.to_owned();
    let limit = u64::from(MAX_MESSAGE_BYTES) + RECORD_HEADER as u64;
    // Only a regular file: a FIFO or a device in the journal is an error,
    // never a read that blocks the master or does not end.
    let mut bytes = read_regular(path, limit).map_err(|source| match source.kind() {
        std::io::ErrorKind::NotFound => RecordError::Missing { path: path_buf() },
        std::io::ErrorKind::FileTooLarge => RecordError::TooLarge { path: path_buf() },
        _ => RecordError::Read {
            path: path_buf(),
            source,
        },
    })?;
    if bytes.len() < RECORD_HEADER {
        return Err(RecordError::Truncated {
            path: path_buf(),
            len: bytes.len(),
        });
    }
    let stored = u32::from_le_bytes(bytes[..RECORD_HEADER].try_into().expect("4 bytes"));
    let computed = crc32c::crc32c(&bytes[RECORD_HEADER..]);
    if stored != computed {
        return Err(RecordError::Checksum {
            path: path_buf(),
            stored,
            computed,
        });
    }
    bytes.drain(..RECORD_HEADER);
    Ok(bytes)
}

/// Reads job `job`'s `kind` record holding one protocol message.
fn read_message(
    path: &Path,
    kind: RecordKind,
    job: JobId,
    expected: &'static str,
) -> Result<Message, RecordError> {
    let bytes = open_envelope(path, &read_record(path)?, kind, job)?;
    decode_message(&bytes).map_err(|e| RecordError::Content {
        path: path.to_owned(),
        expected,
        error: e.to_string(),
    })
}

impl Journal {
    /// Opens (creating) the journal under `state_dir/jobs`; refuses one of
    /// another [`JOURNAL_FORMAT`].
    pub fn open(state_dir: &Path) -> Result<Journal, JournalError> {
        Journal::open_with(state_dir, Arc::new(Disk))
    }

    /// [`Journal::open`] writing through `storage`.
    pub fn open_with(state_dir: &Path, storage: Arc<dyn Storage>) -> Result<Journal, JournalError> {
        let dir = state_dir.join("jobs");
        std::fs::create_dir_all(dir.join("scenes")).map_err(|source| JournalError {
            path: dir.clone(),
            source,
        })?;
        let journal = Journal { dir, storage };
        let path = journal.dir.join("format");
        let format = match read_regular_text(&path, MAX_NOTE_BYTES) {
            Ok(text) => text.trim().parse::<u32>().ok(),
            // No file: format 1, unless the journal is empty.
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                (!journal.job_ids().is_empty()).then_some(1)
            }
            Err(source) => return Err(JournalError { path, source }),
        };
        match format {
            Some(JOURNAL_FORMAT) => Ok(journal),
            Some(UPGRADED_FORMAT) => {
                journal.upgrade();
                (journal.storage)
                    .write_atomic(&path, format!("{JOURNAL_FORMAT}\n").as_bytes())
                    .map_err(|source| JournalError { path, source })?;
                Ok(journal)
            }
            None if !path.exists() => {
                (journal.storage)
                    .write_atomic(&path, format!("{JOURNAL_FORMAT}\n").as_bytes())
                    .map_err(|source| JournalError { path, source })?;
                Ok(journal)
            }
            other => {
                let found =
                    other.map_or("an unreadable format".to_owned(), |f| format!("format {f}"));
                Err(JournalError::other(
                    journal.dir.clone(),
                    format!(
                        "{found}, but this master reads format {JOURNAL_FORMAT} (and upgrades format {UPGRADED_FORMAT}): finish its jobs with the master that wrote it, or remove the directory to start afresh"
                    ),
                ))
            }
        }
    }

    fn job_dir(&self, id: JobId) -> PathBuf {
        self.dir.join(job_dir_name(id))
    }

    /// The completion marker of job `id`.
    fn complete_path(&self, id: JobId) -> PathBuf {
        self.job_dir(id).join("complete")
    }

    fn damaged_dir(&self) -> PathBuf {
        self.dir.join("damaged")
    }

    /// The scene file of `hash`.
    pub fn scene_path(&self, hash: &SceneHash) -> PathBuf {
        self.dir
            .join("scenes")
            .join(format!("{}.scene", hex::encode(hash)))
    }

    /// The file of frame `frame` of job `id`.
    pub fn frame_path(&self, id: JobId, frame: u32) -> PathBuf {
        self.job_dir(id).join(format!("{frame:06}"))
    }

    /// The record file of job `id`.
    pub fn job_path(&self, id: JobId) -> PathBuf {
        self.job_dir(id).join("job")
    }

    /// The record of study `id` (its listing and its variants).
    pub fn study_path(&self, id: JobId) -> PathBuf {
        self.job_dir(id).join("study")
    }

    /// The listing file of job `id` (its state, priority and times).
    pub fn state_path(&self, id: JobId) -> PathBuf {
        self.job_dir(id).join("state")
    }

    /// Job `id`'s listing as last written; `None` (with a warning naming
    /// the file) when there is none or it fails its check (the file is then
    /// kept as `state.damaged`): the job is held paused.
    fn load_state(&self, id: JobId) -> Option<JobSummary> {
        let path = self.state_path(id);
        let error = match read_message(&path, RecordKind::State, id, "a job's listing") {
            Ok(Message::JobList { mut jobs }) if jobs.len() == 1 && jobs[0].id == id => {
                return jobs.pop();
            }
            Ok(other) => RecordError::Content {
                path: path.clone(),
                expected: "this job's listing",
                error: format!("it holds a {}", other.name()),
            },
            Err(e @ RecordError::Missing { .. }) => {
                warn!(
                    job = %id,
                    "{e}: the job's state is lost; it is held paused (resume or cancel it)"
                );
                return None;
            }
            Err(e) => e,
        };
        let aside = path.with_extension("damaged");
        warn!(
            job = %id,
            "{error}: the job's state is lost; it is held paused (resume or cancel it; the file is kept as {})",
            aside.display()
        );
        if let Err(e) = std::fs::rename(&path, &aside) {
            warn!(path = %path.display(), "cannot rename the damaged listing: {e}");
        }
        None
    }

    fn write_record(&self, what: &str, path: &Path, payload: &[u8]) -> Result<(), WriteError> {
        (self.storage)
            .write_atomic(path, &record_bytes(payload))
            .map_err(|source| WriteError {
                what: what.to_owned(),
                path: path.to_owned(),
                source,
            })
    }

    fn write_message(
        &self,
        what: &str,
        path: &Path,
        (kind, job): (RecordKind, JobId),
        message: &Message,
    ) -> Result<(), WriteError> {
        let frame = encode_message(message).map_err(|e| WriteError {
            what: what.to_owned(),
            path: path.to_owned(),
            source: std::io::Error::other(e),
        })?;
        self.write_record(what, path, &envelope(kind, job, &frame[4..]))
    }

    /// Writes a record. Taken by value: a finished frame is written without
    /// a copy.
    pub fn write(&self, record: Record) -> Result<(), WriteError> {
        let what = record_name(&record);
        let io = |path: &Path| {
            let path = path.to_owned();
            let what = what.clone();
            move |source| WriteError { what, path, source }
        };
        match record {
            Record::JobQueued { id, job, scene } => {
                let scene_path = self.scene_path(&scene.hash);
                if read_record(&scene_path).is_err() {
                    self.write_record(&what, &scene_path, &scene.bytes)?;
                }
                let dir = self.job_dir(id);
                std::fs::create_dir_all(&dir).map_err(io(&dir))?;
                let message = Message::SubmitJob { job: *job };
                self.write_message(&what, &self.job_path(id), (RecordKind::Job, id), &message)
            }
            Record::FrameDone(done) => {
                let path = self.frame_path(done.job, done.frame);
                let kind = (RecordKind::Frame, done.job);
                self.write_message(&what, &path, kind, &Message::FrameDone(*done))
            }
            Record::JobComplete { id } => {
                let payload = envelope(RecordKind::Complete, id, b"");
                self.write_record(&what, &self.complete_path(id), &payload)
            }
            Record::JobState(summary) => {
                let (path, id) = (self.state_path(summary.id), summary.id);
                let message = Message::JobList {
                    jobs: vec![*summary],
                };
                self.write_message(&what, &path, (RecordKind::State, id), &message)
            }
            Record::StudyState(row) => {
                let id = row.job.id;
                let dir = self.job_dir(id);
                std::fs::create_dir_all(&dir).map_err(io(&dir))?;
                let message = Message::JobRows { rows: vec![*row] };
                let kind = (RecordKind::Study, id);
                self.write_message(&what, &self.study_path(id), kind, &message)
            }
            Record::JobForgotten { id } => {
                let dir = self.job_dir(id);
                let removed = std::fs::remove_dir_all(&dir).or_else(|e| match e.kind() {
                    std::io::ErrorKind::NotFound => Ok(()),
                    _ => Err(e),
                });
                removed.map_err(io(&dir))?;
                self.remove_unused_scenes().map_err(io(&self.dir))
            }
            Record::JobDamaged { id, reason } => {
                let dir = self.job_dir(id);
                self.set_aside(id, &reason).map(|_| ()).map_err(io(&dir))
            }
        }
    }

    /// Moves job `id`'s directory to `jobs/damaged/` with a `why` file
    /// holding `reason`; returns where it went. Nothing is deleted.
    fn set_aside(&self, id: JobId, reason: &str) -> std::io::Result<PathBuf> {
        self.set_aside_entry(&self.job_dir(id), &job_dir_name(id), reason)
    }

    /// Moves `source` (a directory, a file, or nothing) to
    /// `jobs/damaged/NAME` (`NAME.1`, … when taken), a directory with a
    /// `why` file holding `reason` (a file is moved inside it); returns
    /// where it went. Nothing is deleted.
    fn set_aside_entry(&self, source: &Path, name: &str, reason: &str) -> std::io::Result<PathBuf> {
        let damaged = self.damaged_dir();
        std::fs::create_dir_all(&damaged)?;
        // An entry of this name set aside before keeps its place.
        let target = (0..)
            .map(|k| match k {
                0 => damaged.join(name),
                k => damaged.join(format!("{name}.{k}")),
            })
            .find(|p| std::fs::symlink_metadata(p).is_err())
            .expect("an unused name");
        match std::fs::symlink_metadata(source) {
            Ok(meta) if meta.is_dir() => std::fs::rename(source, &target)?,
            Ok(_) => {
                std::fs::create_dir_all(&target)?;
                let file_name = source.file_name().unwrap_or(name.as_ref());
                std::fs::rename(source, target.join(file_name))?;
            }
            Err(_) => std::fs::create_dir_all(&target)?,
        }
        std::fs::write(target.join("why"), format!("{reason}\n"))?;
        warn!(path = %target.display(), "journal entry {name} set aside: {reason}");
        Ok(target)
    }

    /// Upgrades a format-4 journal's records: each record of each job's
    /// directory without its envelope is written again inside one naming
    /// the job of its directory. A record that fails its check is left as
    /// it is (the load sets it aside, naming it).
    fn upgrade(&self) {
        for id in self.job_ids() {
            let Ok(entries) = std::fs::read_dir(self.job_dir(id)) else {
                continue;
            };
            for entry in entries.flatten() {
                let name = entry.file_name();
                let Some(kind) = name.to_str().and_then(RecordKind::of_file) else {
                    continue;
                };
                let path = entry.path();
                let Ok(payload) = read_record(&path) else {
                    continue;
                };
                if split_envelope(&payload).is_some() {
                    continue;
                }
                let what = format!("the upgrade of {}", path.display());
                if let Err(e) = self.write_record(&what, &path, &envelope(kind, id, &payload)) {
                    warn!("{e}");
                }
            }
        }
    }

    /// Removes the scenes no journaled job names any more (jobs set aside
    /// keep theirs).
    fn remove_unused_scenes(&self) -> std::io::Result<()> {
        let damaged: Vec<PathBuf> = match std::fs::read_dir(self.damaged_dir()) {
            Ok(entries) => entries.filter_map(|e| Some(e.ok()?.path())).collect(),
            Err(_) => Vec::new(),
        };
        let records = (self.job_ids().into_iter().map(|id| self.job_path(id)))
            .chain(damaged.into_iter().map(|dir| dir.join("job")));
        let used: Vec<String> = records
            .filter_map(|path| match scene_record(&path)? {
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

    /// The ids of the journaled jobs (the directories named by an id in
    /// its one spelling), in order.
    fn job_ids(&self) -> Vec<JobId> {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return Vec::new();
        };
        let mut ids: Vec<JobId> = entries
            .filter_map(|e| parse_job_dir_name(e.ok()?.file_name().to_str()?))
            .collect();
        ids.sort_unstable();
        ids
    }

    /// The entries of `jobs/` that are neither a job's directory nor the
    /// journal's own, each with why it is not read.
    fn strays(&self) -> Vec<(PathBuf, String)> {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return Vec::new();
        };
        let mut strays: Vec<(PathBuf, String)> = entries
            .filter_map(|e| {
                let entry = e.ok()?;
                let name = entry.file_name().to_string_lossy().into_owned();
                if ["format", "scenes", "damaged"].contains(&name.as_str())
                    || parse_job_dir_name(&name).is_some()
                {
                    return None;
                }
                let reason = match name.parse::<JobId>() {
                    Ok(id) => format!(
                        "jobs/{name} is not how job {id}'s directory is spelled (jobs/{}); it is not read as a second copy of the job",
                        job_dir_name(id)
                    ),
                    Err(_) => format!(
                        "jobs/{name} is no job's directory (a job's is named by its id in twelve digits, as jobs/{})",
                        job_dir_name(JobId(1))
                    ),
                };
                Some((entry.path(), reason))
            })
            .collect();
        strays.sort();
        strays
    }

    /// A finished frame, checked against its checksum.
    pub fn frame(&self, id: JobId, frame: u32) -> Result<FrameDone, RecordError> {
        let path = self.frame_path(id, frame);
        match read_message(&path, RecordKind::Frame, id, "a finished frame")? {
            Message::FrameDone(done) if done.job == id && done.frame == frame => Ok(done),
            other => Err(RecordError::Content {
                path,
                expected: "this frame",
                error: match other {
                    Message::FrameDone(done) => {
                        format!("it holds frame {} of job {}", done.frame, done.job)
                    }
                    other => format!("it holds a {}", other.name()),
                },
            }),
        }
    }

    /// Every job in the journal, in id order. A job that cannot be read
    /// back is set aside (see the module's doc) and listed as damaged,
    /// with the jobs set aside by earlier starts.
    pub fn load(&self) -> Loaded {
        let mut loaded = Loaded::default();
        for (path, reason) in self.strays() {
            let name = path
                .file_name()
                .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
            if let Err(e) = self.set_aside_entry(&path, &format!("stray-{name}"), &reason) {
                warn!(path = %path.display(), "{reason}; and it cannot be set aside: {e}");
            }
        }
        for id in self.job_ids() {
            if self.study_path(id).exists() && !self.job_path(id).exists() {
                match self.load_study(id) {
                    Ok(row) => loaded.studies.push(row),
                    Err(e) => {
                        // Its variants run on as jobs of their own.
                        warn!(
                            study = %id,
                            "{e}: the study's variants are listed on their own"
                        );
                        if let Err(move_error) = self.set_aside(id, &e.to_string()) {
                            warn!(
                                study = %id,
                                "cannot set the damaged study aside: {move_error}"
                            );
                        }
                    }
                }
                continue;
            }
            match self.load_job(id) {
                Ok(job) => loaded.jobs.push(job),
                Err(e) => {
                    if let Err(move_error) = self.set_aside(id, &e.to_string()) {
                        warn!(job = %id, "cannot set the damaged job aside: {move_error}");
                        let reason = format!("{e} (and it could not be set aside: {move_error})");
                        loaded.damaged.push(DamagedJob { id, reason });
                    }
                }
            }
        }
        loaded.damaged.extend(self.set_aside_jobs());
        // One per id: the reason found now before the one set aside with.
        loaded.damaged.sort_by_key(|d| d.id);
        loaded.damaged.dedup_by_key(|d| d.id);
        loaded
    }

    /// The jobs in `jobs/damaged/`, one per id, with why and where.
    fn set_aside_jobs(&self) -> Vec<DamagedJob> {
        let Ok(entries) = std::fs::read_dir(self.damaged_dir()) else {
            return Vec::new();
        };
        let mut found: Vec<(JobId, PathBuf)> = entries
            .filter_map(|e| {
                let path = e.ok()?.path();
                let id: JobId = path
                    .file_name()?
                    .to_str()?
                    .split('.')
                    .next()?
                    .parse()
                    .ok()?;
                Some((id, path))
            })
            .collect();
        found.sort();
        found.dedup_by_key(|(id, _)| *id);
        (found.into_iter())
            .map(|(id, path)| {
                let why_path = path.join("why");
                let why = match read_regular_text(&why_path, MAX_NOTE_BYTES) {
                    Ok(why) if !why.trim().is_empty() => why.trim().to_owned(),
                    Ok(_) => format!("{}: empty, the reason is lost", why_path.display()),
                    Err(e) => format!("{}: {e}, the reason is lost", why_path.display()),
                };
                let reason = format!("{why}; the job is kept in {}", path.display());
                DamagedJob { id, reason }
            })
            .collect()
    }

    /// Study `id`'s row as last written.
    fn load_study(&self, id: JobId) -> Result<JobRow, RecordError> {
        let path = self.study_path(id);
        match read_message(&path, RecordKind::Study, id, "a study's row")? {
            Message::JobRows { mut rows } if rows.len() == 1 && rows[0].job.id == id => {
                Ok(rows.pop().expect("one row"))
            }
            other => Err(RecordError::Content {
                path,
                expected: "this study's row",
                error: format!("it holds a {}", other.name()),
            }),
        }
    }

    fn load_job(&self, id: JobId) -> Result<StoredJob, RecordError> {
        let dir = self.job_dir(id);
        if !std::fs::symlink_metadata(&dir).is_ok_and(|m| m.is_dir()) {
            return Err(RecordError::NotADirectory { path: dir });
        }
        let path = self.job_path(id);
        let Message::SubmitJob { mut job } = read_message(&path, RecordKind::Job, id, "a job")?
        else {
            return Err(RecordError::Content {
                path,
                expected: "a job",
                error: "another message".into(),
            });
        };
        let JobScene::Hash(hash) = job.scene else {
            return Err(RecordError::Content {
                path,
                expected: "a job with its scene by hash",
                error: "the scene is inline".into(),
            });
        };
        let scene_path = self.scene_path(&hash);
        let bytes = read_record(&scene_path)?;
        job.scene = JobScene::Data(SceneData { hash, bytes });
        let frames = job.frames.len() as u32;
        let mut frames_done = 0;
        let mut damaged_frame = None;
        while frames_done < frames {
            match self.frame(id, frames_done) {
                Ok(_) => frames_done += 1,
                Err(e @ RecordError::Missing { .. }) => {
                    // A gap: later frames are there, this one is lost.
                    let later = (frames_done + 1..frames).any(|f| self.frame_path(id, f).exists());
                    if later {
                        warn!(
                            job = %id,
                            frame = frames_done,
                            "{e}: the frame is rendered again"
                        );
                        damaged_frame = Some((frames_done, e.to_string()));
                    }
                    break;
                }
                Err(e) => {
                    let path = self.frame_path(id, frames_done);
                    let aside = path.with_extension("damaged");
                    let reason = format!("{e} (the file is kept as {})", aside.display());
                    warn!(
                        job = %id,
                        frame = frames_done,
                        "{reason}: the frame is rendered again"
                    );
                    if let Err(move_error) = std::fs::rename(&path, &aside) {
                        warn!(path = %path.display(), "cannot rename the damaged frame: {move_error}");
                    }
                    damaged_frame = Some((frames_done, reason));
                    break;
                }
            }
        }
        let complete = self.is_complete(id) && frames_done == frames;
        Ok(StoredJob {
            id,
            job,
            frames_done,
            complete,
            damaged_frame,
            summary: self.load_state(id),
        })
    }
}

impl Journal {
    /// Whether job `id`'s completion marker stands (one that fails its
    /// check does not, with a warning naming it: its frames are counted).
    fn is_complete(&self, id: JobId) -> bool {
        let path = self.complete_path(id);
        let checked = read_record(&path)
            .and_then(|payload| open_envelope(&path, &payload, RecordKind::Complete, id));
        match checked {
            Ok(_) => true,
            Err(RecordError::Missing { .. }) => false,
            Err(e) => {
                warn!(
                    job = %id,
                    "{e}: the job is complete only if every frame is there"
                );
                false
            }
        }
    }
}

/// A job's directory name: its id in twelve digits, its one spelling.
fn job_dir_name(id: JobId) -> String {
    format!("{:012}", id.0)
}

/// The job id a directory name spells, if it is that id's one spelling.
fn parse_job_dir_name(name: &str) -> Option<JobId> {
    let id = name.parse().ok()?;
    (job_dir_name(id) == name).then_some(id)
}

/// The message of a job record of this format or the one before, of any
/// job (to find the scenes still in use, set-aside jobs' included).
fn scene_record(path: &Path) -> Option<Message> {
    let payload = read_record(path).ok()?;
    let body = split_envelope(&payload).map_or(&payload[..], |(_, body)| body);
    decode_message(body).ok()
}

fn record_name(record: &Record) -> String {
    match record {
        Record::JobQueued { id, .. } => format!("job {id}"),
        Record::FrameDone(done) => format!("job {} frame {}", done.job, done.frame),
        Record::JobComplete { id } => format!("the completion of job {id}"),
        Record::JobForgotten { id } => format!("the removal of job {id}"),
        Record::JobDamaged { id, .. } => format!("setting job {id} aside"),
        Record::JobState(summary) => format!("the state of job {}", summary.id),
        Record::StudyState(row) => format!("the state of study {}", row.job.id),
    }
}

#[cfg(test)]
mod tests;
