//! The submitter's side of the protocol, over any [`Link`]: `vtfarm submit`
//! runs it over QUIC, `vtfarm render` and `vtfarm study` against the
//! embedded master (`vtfarm-embedded`). A client of the farm: it knows the
//! wire and the transport, nothing of the master's or a worker's insides.
//!
//! The job names its scene by hash first; the master asks for the bytes only
//! when it does not have that scene yet. [`run_remote_job`] follows a job
//! across lost connections: it reconnects and re-attaches (`AttachJob`) to
//! receive the frames from the first one it lacks.
//!
//! The submitter tracks every frame it is owed: it takes the frames in any
//! order (a frame the journal could not give back comes later, rendered
//! again), skips those it has, asks again from the first one it lacks after
//! each reconnect, and fails naming the frame when the master says one
//! cannot be delivered. Several submitters may follow one job: each gets
//! every frame.
//!
//! [`run_remote_study`] runs a study as one job: its variants' frames on
//! one connection, re-attached the same way.
//!
//! [`list_jobs`] and [`control_job`] manage the master's jobs (`vtfarm
//! jobs`, `cancel`, `pause`, `resume`, `requeue`, `priority`); a job's
//! follower learns of a user's pause, resume or cancel
//! (`JobStateChanged`): a cancel ends it with [`JobError::Cancelled`].
//!
//! [`listing`] turns what the master answers into the text a submitter
//! prints: the tables of `vtfarm jobs` and `vtfarm status`, a frame's
//! statistics and the JSON lines of `vtfarm submit --json`.

pub mod listing;
pub mod progress;
mod study;

pub use study::{RemoteStudy, StudyEvent, run_remote_study};

use std::collections::BTreeMap;
use std::time::{Duration, Instant};
use vtfarm_proto::JobId;

use tracing::warn;
use vtfarm_imaging::Image;
use vtfarm_proto::{
    ATTACH_GRACE, FrameDone, FrameStats, JobAction, JobRow, JobSummary, Message, Role, SceneData,
    WireFrameAux, WireImage, WireImageFormat, WireJob, WireJobState,
};
use vtfarm_transport::Link;
use vtfarm_transport::client::{ClientOptions, ConnectError, connect};
use vtfarm_vertex::FrameImage;

/// The job message and its options: the wire's, here for the submitter's users.
pub use vtfarm_proto::{JobOptions, wire_job};

/// A finished frame as the submitter receives it.
#[derive(Clone, Debug)]
pub struct FinishedFrame {
    pub frame: u32,
    /// The colour, in the format the job asked for (`WireJob::image`).
    pub image: FrameColor,
    pub stats: FrameStats,
    /// The colour with the per-pixel components, when the job asked for them.
    pub components: Option<FrameImage>,
}

/// A finished frame's colour.
#[derive(Clone, Debug, PartialEq)]
pub enum FrameColor {
    Linear(Image),
    /// 8-bit sRGB, RGB interleaved ([`Image::to_srgb8`] of the linear frame).
    Srgb8 {
        width: u32,
        height: u32,
        pixels: Vec<u8>,
    },
}

impl FrameColor {
    /// The linear colours, unless the job asked for sRGB.
    pub fn linear(&self) -> Option<&Image> {
        match self {
            FrameColor::Linear(image) => Some(image),
            FrameColor::Srgb8 { .. } => None,
        }
    }

    /// The 8-bit sRGB pixels, RGB interleaved: the same bytes from either form.
    pub fn to_srgb8(&self) -> Vec<u8> {
        match self {
            FrameColor::Linear(image) => image.to_srgb8(),
            FrameColor::Srgb8 { pixels, .. } => pixels.clone(),
        }
    }

    /// Writes the frame as an 8-bit sRGB PNG: the same file from either form.
    pub fn write_png(&self, path: &std::path::Path) -> Result<(), vtfarm_imaging::ImageError> {
        match self {
            FrameColor::Linear(image) => image.write_png(path),
            FrameColor::Srgb8 {
                width,
                height,
                pixels,
            } => vtfarm_imaging::write_srgb8_png(path, *width, *height, pixels),
        }
    }
}

/// What happens while a job runs, for progress displays.
#[derive(Clone, Debug)]
pub enum JobEvent<'a> {
    Accepted {
        job: JobId,
        frames: u32,
    },
    Progress {
        frame: u32,
        done: u32,
        total: u32,
    },
    FrameDone(&'a FinishedFrame),
    /// Something the user should know that does not end the job (a frame
    /// being rendered again, a record the master could not journal).
    Warning(String),
    /// A user paused or resumed the job (`reason` says who).
    StateChanged {
        job: JobId,
        state: WireJobState,
        reason: String,
    },
}

/// Why a job did not complete.
#[derive(Debug, thiserror::Error)]
pub enum JobError {
    #[error("the master failed the job:\n  {}", .0.join("\n  "))]
    Failed(Vec<String>),
    #[error("the connection to the master closed{}", .0.as_ref().map(|e| format!(": {e}")).unwrap_or_default())]
    Disconnected(Option<String>),
    #[error("bad answer from the master: {0}")]
    Protocol(String),
    /// A user cancelled the job (`reason` says who).
    #[error("{reason}")]
    Cancelled { job: JobId, reason: String },
    /// The master refused a request about a job (`vtfarm cancel` and the like).
    #[error("{0}")]
    Refused(String),
    /// The follower's own handling of an event failed (it says why).
    #[error("{0}")]
    Stopped(String),
    #[error("frame {frame} of job {job} cannot be delivered: {reason}")]
    FrameLost {
        job: JobId,
        frame: u32,
        reason: String,
    },
    #[error(transparent)]
    Connect(#[from] ConnectError),
}

/// Submits `job` and waits for all its frames.
pub async fn run_job(
    link: &mut Link,
    job: WireJob,
    scene: &SceneData,
    mut on_event: impl FnMut(JobEvent<'_>),
) -> Result<Vec<FinishedFrame>, JobError> {
    send(link, Message::SubmitJob { job })?;
    let mut follower = JobFollower::default();
    follower.follow(link, Some(scene), &mut on_event).await?;
    Ok(follower.into_frames())
}

/// What a remote job run starts from.
pub enum RemoteJob<'a> {
    /// Submit this job (its scene is sent if the master asks).
    Submit { job: WireJob, scene: &'a SceneData },
    /// Re-attach to a job the master already has (`vtfarm submit --attach`).
    Attach { job: JobId },
}

/// Runs a job on the master at `options` and waits for all its frames. When
/// the connection drops after the master accepted the job, it reconnects
/// with backoff (for up to [`ATTACH_GRACE`]) and re-attaches, so a
/// restarted master goes on sending frames; connecting the first time fails
/// fast.
pub async fn run_remote_job(
    options: &ClientOptions,
    start: RemoteJob<'_>,
    mut on_event: impl FnMut(JobEvent<'_>),
) -> Result<Vec<FinishedFrame>, JobError> {
    let (mut submission, scene, mut follower) = match start {
        RemoteJob::Submit { job, scene } => (Some(job), Some(scene), JobFollower::default()),
        RemoteJob::Attach { job } => (None, None, JobFollower::attaching(job)),
    };
    let mut lost_at: Option<Instant> = None;
    loop {
        let conn = connect_following(options, lost_at).await?;
        let mut link = conn.link;
        let request = match (submission.take(), follower.job) {
            (Some(job), _) => Message::SubmitJob { job },
            (None, Some(job)) => Message::AttachJob {
                job,
                from_frame: follower.first_missing(),
            },
            (None, None) => return Err(JobError::Protocol("no job to attach to".into())),
        };
        let outcome = match send(&link, request) {
            Ok(()) => follower.follow(&mut link, scene, &mut on_event).await,
            Err(e) => Err(e),
        };
        conn.connection
            .close(vtfarm_transport::CLOSE_NORMAL, b"done");
        conn.endpoint.wait_idle().await;
        match outcome {
            Ok(()) => return Ok(follower.into_frames()),
            Err(JobError::Disconnected(why)) if follower.job.is_some() => {
                let why = why.map(|w| format!(": {w}")).unwrap_or_default();
                warn!("lost the master{why}; reconnecting to follow the job");
                lost_at = Some(Instant::now());
            }
            Err(e) => return Err(e),
        }
    }
}

/// Connects to the master; after a lost connection (at `lost_at`) it
/// retries a transient failure with backoff for up to [`ATTACH_GRACE`],
/// the first time it fails fast.
async fn connect_following(
    options: &ClientOptions,
    lost_at: Option<Instant>,
) -> Result<vtfarm_transport::client::Connection, JobError> {
    let mut backoff = Duration::from_millis(200);
    loop {
        match connect(options, Role::Submitter).await {
            Ok(conn) => return Ok(conn),
            Err(e) => {
                let retry = lost_at.is_some_and(|t| t.elapsed() < ATTACH_GRACE);
                if !(retry && e.is_transient()) {
                    return Err(JobError::Connect(e));
                }
                warn!("{e}; retrying in {backoff:?}");
                tokio::time::sleep(backoff).await;
                backoff = (backoff * 2).min(Duration::from_secs(5));
            }
        }
    }
}

/// The master's jobs (`all`: the finished ones it keeps too), oldest
/// first, each study with its variants.
pub async fn list_jobs(options: &ClientOptions, all: bool) -> Result<Vec<JobRow>, JobError> {
    let reply = request(options, Message::ListJobs { all }, |m| match m {
        Message::JobRows { rows } => Some(rows),
        _ => None,
    });
    reply.await
}

/// Asks the master to cancel, pause, resume, requeue or re-prioritise
/// `job`; the job as it is afterwards, or [`JobError::Refused`] with why.
pub async fn control_job(
    options: &ClientOptions,
    job: JobId,
    action: JobAction,
) -> Result<JobSummary, JobError> {
    let reply = request(options, Message::ControlJob { job, action }, |m| match m {
        Message::JobControlled { job: j, outcome } if j == job => Some(outcome),
        _ => None,
    });
    reply.await?.map_err(JobError::Refused)
}

/// Sends one request on a connection of its own and waits for the answer
/// `answer` picks out (skipping other messages).
async fn request<T>(
    options: &ClientOptions,
    message: Message,
    answer: impl Fn(Message) -> Option<T>,
) -> Result<T, JobError> {
    let conn = connect(options, Role::Submitter).await?;
    let mut link = conn.link;
    let reply = async {
        send(&link, message)?;
        loop {
            let Some(message) = link.rx.recv().await else {
                return Err(JobError::Disconnected(link.error()));
            };
            if let Some(reply) = answer(message) {
                return Ok(reply);
            }
        }
    };
    let reply = reply.await;
    conn.connection
        .close(vtfarm_transport::CLOSE_NORMAL, b"done");
    conn.endpoint.wait_idle().await;
    reply
}

fn send(link: &Link, message: Message) -> Result<(), JobError> {
    link.tx
        .send(message)
        .map_err(|_| JobError::Disconnected(link.error()))
}

/// A job's frames as they come in, over one connection or several.
#[derive(Default)]
struct JobFollower {
    /// The job's id, once accepted (or the one attached to).
    job: Option<JobId>,
    /// How many frames the job has, once accepted.
    total: Option<usize>,
    /// The frames received, by number: the others are still owed.
    frames: BTreeMap<u32, FinishedFrame>,
}

impl JobFollower {
    fn attaching(job: JobId) -> Self {
        JobFollower {
            job: Some(job),
            ..JobFollower::default()
        }
    }

    /// The first frame not received yet (where an attach asks from).
    fn first_missing(&self) -> u32 {
        (0..)
            .find(|f| !self.frames.contains_key(f))
            .expect("fewer than 2^32 frames")
    }

    /// The frames in order.
    fn into_frames(self) -> Vec<FinishedFrame> {
        self.frames.into_values().collect()
    }

    /// Receives until every frame is in (or the job fails, or the link drops).
    async fn follow(
        &mut self,
        link: &mut Link,
        scene: Option<&SceneData>,
        on_event: &mut impl FnMut(JobEvent<'_>),
    ) -> Result<(), JobError> {
        while self.total.is_none_or(|total| self.frames.len() < total) {
            let Some(message) = link.rx.recv().await else {
                return Err(JobError::Disconnected(link.error()));
            };
            match message {
                Message::SceneRequest { hash } => match scene.filter(|s| s.hash == hash) {
                    Some(scene) => send(link, Message::SceneData(scene.clone()))?,
                    None => return Err(JobError::Protocol("request for an unknown scene".into())),
                },
                Message::JobAccepted { job, frames } => {
                    self.job = Some(job);
                    self.total = Some(frames as usize);
                    on_event(JobEvent::Accepted { job, frames });
                }
                Message::Progress {
                    frame, done, total, ..
                } => on_event(JobEvent::Progress { frame, done, total }),
                // A frame the submitter has already (re-sent after
                // re-attaching) or of another job is skipped.
                Message::FrameDone(done)
                    if self.frames.contains_key(&done.frame)
                        || self.job.is_some_and(|job| job != done.job)
                        || self.total.is_some_and(|total| done.frame as usize >= total) => {}
                Message::FrameDone(done) => {
                    let finished = finished_frame(done)?;
                    on_event(JobEvent::FrameDone(&finished));
                    self.frames.insert(finished.frame, finished);
                }
                told @ (Message::FrameMissing { .. } | Message::JournalFailed { .. }) => {
                    if let Some(warning) = warning_of(told)? {
                        on_event(JobEvent::Warning(warning));
                    }
                }
                Message::JobFailed { errors, .. } => return Err(JobError::Failed(errors)),
                Message::JobStateChanged { job, state, reason } => {
                    if state == WireJobState::Cancelled {
                        return Err(JobError::Cancelled { job, reason });
                    }
                    on_event(JobEvent::StateChanged { job, state, reason });
                }
                // The answer to attaching to a study.
                Message::StudyAccepted { study, .. } => {
                    return Err(JobError::Refused(format!(
                        "job {study} is a study: follow it with its study file"
                    )));
                }
                Message::Heartbeat => {}
                other => return Err(JobError::Protocol(format!("unexpected {}", other.name()))),
            }
        }
        Ok(())
    }
}

/// What a follower makes of a frame the master is missing or a journal it
/// cannot write: a warning for the user, or the error that ends the
/// follow (a frame that will not come); `None` for any other message.
pub(crate) fn warning_of(message: Message) -> Result<Option<String>, JobError> {
    match message {
        Message::FrameMissing {
            job,
            frame,
            reason,
            rendering_again: true,
        } => Ok(Some(format!(
            "frame {frame} of job {job} is rendered again: {reason}"
        ))),
        Message::FrameMissing {
            job, frame, reason, ..
        } => Err(JobError::FrameLost { job, frame, reason }),
        Message::JournalFailed { job, error } => Ok(Some(format!(
            "the master cannot journal job {job}: {error}"
        ))),
        _ => Ok(None),
    }
}

/// A finished frame off the wire, its colour and components checked.
fn finished_frame(done: FrameDone) -> Result<FinishedFrame, JobError> {
    let frame = done.frame;
    let in_frame = |e: JobError| match e {
        JobError::Protocol(e) => JobError::Protocol(format!("frame {frame}: {e}")),
        other => other,
    };
    let image = frame_color(done.image).map_err(in_frame)?;
    let components = match (done.aux, &image) {
        (None, _) => None,
        (Some(aux), FrameColor::Linear(color)) => Some(components(color, aux).map_err(in_frame)?),
        (Some(_), FrameColor::Srgb8 { .. }) => {
            return Err(in_frame(JobError::Protocol(
                "components with an sRGB colour".into(),
            )));
        }
    };
    Ok(FinishedFrame {
        frame,
        image,
        stats: done.stats,
        components,
    })
}

fn frame_color(wire: WireImage) -> Result<FrameColor, JobError> {
    let protocol = |e: vtfarm_proto::WireError| JobError::Protocol(e.to_string());
    match wire.format {
        WireImageFormat::LinearF32 => image(wire).map(FrameColor::Linear),
        WireImageFormat::Srgb8 => {
            let (width, height, pixels) = wire.into_srgb8().map_err(protocol)?;
            Ok(FrameColor::Srgb8 {
                width,
                height,
                pixels,
            })
        }
    }
}

fn image(wire: WireImage) -> Result<Image, JobError> {
    let (width, height, pixels) = wire
        .into_pixels()
        .map_err(|e| JobError::Protocol(e.to_string()))?;
    Ok(Image {
        width,
        height,
        pixels,
    })
}

/// Rebuilds the frame's components from the wire, checking their sizes.
fn components(color: &Image, aux: WireFrameAux) -> Result<FrameImage, JobError> {
    (aux.into_components(color.clone()))
        .map_err(|e| JobError::Protocol(format!("frame components: {e}")))
}
