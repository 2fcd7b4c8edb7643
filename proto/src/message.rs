//! The messages: one [`Message`] enum for every connection, whose variants
//! are grouped by who talks to whom.
//!
//! Compatibility rules: bincode encodes a variant by its position, so new
//! variants go at the end and any change to an existing message bumps
//! [`crate::PROTOCOL_VERSION`]. `Message::Hello` stays variant 0 and `Hello`
//! keeps `magic` and `version` as its first fields in every version, so a
//! master can tell an old or new client's version even when the rest of its
//! `Hello` no longer decodes.
//!
//! Flows (the scheduler's and the job table's docs have the state machines):
//! - every connection: `Hello` → `Welcome` | `Refused` on the first stream
//!   (see [`crate::handshake`]);
//! - worker ↔ master: master `SceneOffer` → worker `SceneRequest` (when the
//!   hash is not cached) → master `SceneData`; master `FrameStart`; worker
//!   `RequestWork` → master `Package`; worker `PackageResult` (one per
//!   stage of a progressive frame, in the stages' order) |
//!   `PackageFailed`; master `CancelPackage`, `Shutdown`; both `Heartbeat`;
//! - submitter ↔ master: `SubmitJob` → `JobAccepted`, then `Progress` and
//!   `FrameDone` per frame, or `JobFailed`; `StatusRequest` → `StatusReply`;
//!   `AttachJob` → `JobAccepted` and the frames, each a `FrameDone` or a
//!   `FrameMissing`; `JournalFailed` when the master cannot keep a record;
//!   `ListJobs` → `JobRows`; `ControlJob` → `JobControlled` (and
//!   `JobStateChanged` to the job's submitters); `SubmitStudy` →
//!   `SceneRequest`s for the scenes the master lacks, then `StudyAccepted`
//!   and each variant's messages as a job's; `AttachJob` of a study →
//!   `StudyAccepted` (the submitter then attaches to its variants).

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use vtfarm_method::{FrameSetup, MethodKind};
use vtfarm_scene::{Scene, TriangleId};
use vtfarm_vertex::Quality;

use crate::wire::{
    WireBitmap, WireError, WireFrameSetup, WireImage, WireImageFormat, WireMesh, WireMethod,
    WirePackageStats, WireQuality, WireScene,
};

/// A scene's content hash: SHA-256 of its canonical encoding (see [`scene_hash`]).
pub type SceneHash = [u8; 32];
/// A job, numbered by the master: the scheduler's id, encoded as the bare number.
pub use vtfarm_scheduler::JobId;
/// A package, numbered by the master; unique for the master's lifetime.
pub type PackageId = u64;

/// Everything that travels on a vtfarm connection.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Message {
    // Handshake, on the first stream of every connection.
    /// Client → master: who I am. Must stay variant 0.
    Hello(Hello),
    /// Master → client: accepted.
    Welcome(Welcome),
    /// Master → client: not accepted; the master then closes the connection
    /// with the code's [`RefuseCode::close_code`].
    Refused(Refusal),

    // Worker ↔ master.
    /// Master → worker: job `job` runs now, on this scene: a worker asks
    /// for its work once it has the scene (a whole frame's set-up comes
    /// only with its package, so this is all a worker may hear of the job).
    SceneOffer { hash: SceneHash, job: JobId },
    /// Worker → master: send me this scene, I do not have it cached.
    SceneRequest { hash: SceneHash },
    /// Master → worker (and submitter → master inside a job): a scene.
    SceneData(SceneData),
    /// Master → worker: the set-up of a frame whose packages follow.
    FrameStart(FrameStart),
    /// Worker → master: I have a free slot and this frame set up, send a
    /// package of it. A request for any other frame is stale and dropped.
    RequestWork { job: JobId, frame: u32 },
    /// Master → worker: trace these reflector triangles.
    Package(Package),
    /// Worker → master: a package's pixels and counters.
    PackageResult(PackageResult),
    /// Worker → master: a package could not be traced; the master decides
    /// whether to retry it elsewhere.
    PackageFailed(PackageFailed),
    /// Master → worker: drop this package (its frame was cancelled or it was
    /// already done elsewhere); no result is expected.
    CancelPackage { id: PackageId },
    /// Either way: I am alive (sent when idle; any message counts too).
    Heartbeat,
    /// Master → worker: finish nothing more, disconnect.
    Shutdown,

    // Submitter ↔ master.
    /// Submitter → master: render this job.
    SubmitJob { job: WireJob },
    /// Master → submitter: the job is queued under this id.
    JobAccepted { job: JobId, frames: u32 },
    /// Master → submitter: `done` of the frame's `total` reflector triangles
    /// are in (per-reflector methods count each group's triangles).
    Progress {
        job: JobId,
        frame: u32,
        done: u32,
        total: u32,
    },
    /// Master → submitter: a finished frame.
    FrameDone(FrameDone),
    /// Master → submitter: the job was abandoned, with the reasons.
    JobFailed { job: JobId, errors: Vec<String> },
    /// Submitter → master: what is the farm doing?
    StatusRequest,
    /// Master → submitter: the answer.
    StatusReply(StatusReply),
    /// Submitter → master: send me job `job`'s frames from `from_frame` on
    /// (after a lost connection, or from another shell). The master answers
    /// `JobAccepted` and the frames, or `JobFailed` when it has no such job.
    AttachJob { job: JobId, from_frame: u32 },

    // Submitter ↔ master, since version 6: the journal's troubles.
    /// Master → submitter: a finished frame of the job cannot be given
    /// back (its journal record failed its check or is gone). With
    /// `rendering_again` it is being rendered again and follows as a
    /// `FrameDone`; without, the submitter will not get it.
    FrameMissing {
        job: JobId,
        frame: u32,
        reason: String,
        rendering_again: bool,
    },
    /// Master → submitter: a record of the job could not be journaled (a
    /// full disk, say): a restarted master would not have it. The job goes
    /// on; a frame that was not written stays in the master's memory.
    JournalFailed { job: JobId, error: String },

    // Submitter ↔ master, since version 7: managing jobs.
    /// Submitter → master: list the jobs (`all`: the finished ones kept
    /// too, not only queued, running and paused).
    ListJobs { all: bool },
    /// Listings (the master's journal keeps a job's as a `JobList` of
    /// one; `ListJobs` is answered with [`Message::JobRows`]).
    JobList { jobs: Vec<JobSummary> },
    /// Submitter → master: change a job (cancel, pause, resume, requeue,
    /// set its priority).
    ControlJob { job: JobId, action: JobAction },
    /// Master → submitter: how a `ControlJob` went: the job as it is now,
    /// or why the master refused.
    JobControlled {
        job: JobId,
        outcome: Result<JobSummary, String>,
    },
    /// Master → the job's submitters: the job changed state by a user's
    /// hand (paused, resumed, cancelled), with who asked.
    JobStateChanged {
        job: JobId,
        state: WireJobState,
        reason: String,
    },

    // Submitter ↔ master: studies.
    /// Submitter → master: run this study, its variants as one job (the
    /// master asks for each scene it does not have).
    SubmitStudy { study: WireStudy },
    /// Master → submitter: the study is queued (or attached to) under
    /// `study`; its variants, in order, are the jobs `variants` (each its
    /// id and frame count), whose messages follow as any job's.
    StudyAccepted {
        study: JobId,
        variants: Vec<(JobId, u32)>,
    },
    /// Master → submitter: the jobs (`ListJobs`), oldest first, a study
    /// with its variants.
    JobRows { rows: Vec<JobRow> },

    // Worker → master: the interactive view.
    /// Worker → master: a progressive frame whose first stage is `preview`
    /// (a move of the view's eye) and has at most
    /// [`MAX_CORNER_MESH_TRIANGLES`] reflector triangles sends, before its
    /// frame is set up, every reflector triangle's corners traced from the
    /// eye (`vtfarm_vertex::corner_meshes`): the view's first image, ahead
    /// of the packages' results.
    FrameMesh {
        job: JobId,
        frame: u32,
        mesh: WireMesh,
    },
}

/// The most reflector triangles a [`Message::FrameMesh`] holds (about
/// 180 bytes each on the wire, 12 MB at most): a larger reflector's preview
/// comes with its packages' results, in pieces of a package's size.
pub const MAX_CORNER_MESH_TRIANGLES: usize = 65_536;

impl Message {
    /// The variant's name, for logs and "unexpected message" errors.
    pub fn name(&self) -> &'static str {
        match self {
            Message::Hello(_) => "Hello",
            Message::Welcome(_) => "Welcome",
            Message::Refused(_) => "Refused",
            Message::SceneOffer { .. } => "SceneOffer",
            Message::SceneRequest { .. } => "SceneRequest",
            Message::SceneData(_) => "SceneData",
            Message::FrameStart(_) => "FrameStart",
            Message::RequestWork { .. } => "RequestWork",
            Message::Package(_) => "Package",
            Message::PackageResult(_) => "PackageResult",
            Message::PackageFailed(_) => "PackageFailed",
            Message::CancelPackage { .. } => "CancelPackage",
            Message::Heartbeat => "Heartbeat",
            Message::Shutdown => "Shutdown",
            Message::SubmitJob { .. } => "SubmitJob",
            Message::JobAccepted { .. } => "JobAccepted",
            Message::Progress { .. } => "Progress",
            Message::FrameDone(_) => "FrameDone",
            Message::JobFailed { .. } => "JobFailed",
            Message::StatusRequest => "StatusRequest",
            Message::StatusReply(_) => "StatusReply",
            Message::AttachJob { .. } => "AttachJob",
            Message::FrameMissing { .. } => "FrameMissing",
            Message::JournalFailed { .. } => "JournalFailed",
            Message::ListJobs { .. } => "ListJobs",
            Message::JobList { .. } => "JobList",
            Message::ControlJob { .. } => "ControlJob",
            Message::JobControlled { .. } => "JobControlled",
            Message::JobStateChanged { .. } => "JobStateChanged",
            Message::SubmitStudy { .. } => "SubmitStudy",
            Message::StudyAccepted { .. } => "StudyAccepted",
            Message::JobRows { .. } => "JobRows",
            Message::FrameMesh { .. } => "FrameMesh",
        }
    }
}

/// The first message of every connection.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Hello {
    /// Always [`crate::MAGIC`]. Frozen position: first field.
    pub magic: [u8; 8],
    /// The client's [`crate::PROTOCOL_VERSION`]. Frozen position: second field.
    pub version: u32,
    /// The cluster token from `cluster.toml`.
    pub token: String,
    pub role: Role,
}

impl Hello {
    /// A `Hello` of this build's protocol version.
    pub fn new(token: impl Into<String>, role: Role) -> Self {
        Hello {
            magic: crate::MAGIC,
            version: crate::PROTOCOL_VERSION,
            token: token.into(),
            role,
        }
    }
}

/// What a connecting client is.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Role {
    /// A render worker with this many tracing threads and a name for logs
    /// and status (the host name by default).
    Worker { threads: u32, name: String },
    /// A command-line client that submits jobs and asks for status.
    Submitter,
}

/// The master's answer to an accepted `Hello`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Welcome {
    /// The master's protocol version (equal to the client's).
    pub version: u32,
    /// The master's name for logs.
    pub master_name: String,
}

/// Why the master refused a connection. Each code has a QUIC application
/// error code ([`RefuseCode::close_code`]) with which the master closes the
/// connection after sending `Refused`, so a client that lost the message
/// still learns the reason; 0 (`vtfarm_transport::CLOSE_NORMAL`) is an orderly close.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum RefuseCode {
    /// Close code 1: the token does not match the cluster's.
    BadToken,
    /// Close code 2: the client speaks another protocol version.
    BadVersion,
    /// Close code 3: the first message is not a well-formed vtfarm `Hello`
    /// (garbage, wrong magic, another message, stream ended early).
    BadMessage,
    /// Close code 4: the first message is longer than
    /// [`crate::MAX_HANDSHAKE_BYTES`].
    TooLarge,
    /// Close code 5: no `Hello` within the handshake timeout, or a message
    /// on an accepted session that stalled ([`crate::MESSAGE_STALL`]).
    Timeout,
    /// Close code 6: the master is shutting down.
    ShuttingDown,
    /// Close code 7: the connection failed during the handshake; nothing
    /// could be sent back (the master closes with this code anyway).
    Disconnected,
}

impl RefuseCode {
    pub const ALL: [RefuseCode; 7] = [
        RefuseCode::BadToken,
        RefuseCode::BadVersion,
        RefuseCode::BadMessage,
        RefuseCode::TooLarge,
        RefuseCode::Timeout,
        RefuseCode::ShuttingDown,
        RefuseCode::Disconnected,
    ];

    /// The application error code the master closes the connection with
    /// (0 is an orderly close).
    pub fn close_code(self) -> u32 {
        match self {
            RefuseCode::BadToken => 1,
            RefuseCode::BadVersion => 2,
            RefuseCode::BadMessage => 3,
            RefuseCode::TooLarge => 4,
            RefuseCode::Timeout => 5,
            RefuseCode::ShuttingDown => 6,
            RefuseCode::Disconnected => 7,
        }
    }

    /// The refusal a connection's close code stands for, if any.
    pub fn from_close_code(code: u64) -> Option<RefuseCode> {
        RefuseCode::ALL
            .into_iter()
            .find(|c| u64::from(c.close_code()) == code)
    }
}

/// A refusal: the `Refused` message, and what `vtfarm_transport::server_handshake`
/// returns for a client it turned away.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize, thiserror::Error)]
#[error("refused ({code:?}): {message}")]
pub struct Refusal {
    pub code: RefuseCode,
    /// A human-readable reason (never echoes the token).
    pub message: String,
}

impl Refusal {
    pub fn new(code: RefuseCode, message: impl Into<String>) -> Self {
        Refusal {
            code,
            message: message.into(),
        }
    }
}

/// The SHA-256 of a scene's canonical encoding (bincode of its [`WireScene`]).
pub fn scene_hash(scene: &Scene) -> SceneHash {
    Sha256::digest(encode_scene(scene)).into()
}

fn encode_scene(scene: &Scene) -> Vec<u8> {
    crate::framing::encode_value(&WireScene::from(scene))
}

/// A scene by value: its canonical encoding and that encoding's hash, so the
/// receiver can check the content before decoding and cache it by hash.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SceneData {
    pub hash: SceneHash,
    /// bincode of a [`WireScene`] (standard configuration).
    #[serde(with = "bytes")]
    pub bytes: Vec<u8>,
}

impl SceneData {
    /// Encodes and hashes a scene.
    pub fn from_scene(scene: &Scene) -> Self {
        let bytes = encode_scene(scene);
        SceneData {
            hash: Sha256::digest(&bytes).into(),
            bytes,
        }
    }

    /// Checks the hash, decodes and validates the scene.
    pub fn to_scene(&self) -> Result<Scene, WireError> {
        let actual: SceneHash = Sha256::digest(&self.bytes).into();
        if actual != self.hash {
            return Err(WireError::HashMismatch {
                announced: hex::encode(self.hash),
                actual: hex::encode(actual),
            });
        }
        let wire: WireScene =
            crate::framing::decode_value(&self.bytes).map_err(|e| WireError::Decode {
                what: "scene data",
                message: e.to_string(),
            })?;
        Scene::try_from(wire)
    }
}

/// The set-up of one frame: workers rebuild the BVH (per scene) and ID
/// buffers (per frame) from it before tracing packages.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameStart {
    pub job: JobId,
    pub frame: u32,
    /// The scene, announced earlier with `SceneOffer`.
    pub scene: SceneHash,
    pub setup: WireFrameSetup,
    /// All reflector triangles of the frame (the behind-ID buffer needs
    /// them); check with [`crate::wire::check_triangle_ids`].
    pub reflectors: Vec<u32>,
    /// The reflection method. For per-reflector methods a package's items
    /// are indices of reflector groups (`vtfarm_method::reflector_groups`
    /// of `reflectors`), not triangle ids.
    pub method: WireMethod,
    /// Whether results carry the per-pixel components besides the colour
    /// (the job's `aux`): [`crate::WireBitmapParts::All`] or only `Color`;
    /// a whole frame's result its [`WireFrameAux`].
    pub aux: bool,
    /// How a whole frame's image travels (the job's [`WireJob::image`]).
    pub image: WireImageFormat,
    /// A progressive frame's stages (the interactive view: `preview`,
    /// `refine`, `full`): each package is set up once and advanced through
    /// them on the same vertices, one [`PackageResult`] per stage, the
    /// last completing the package. Each stage but the last carries its
    /// meshes and no pixels (an empty bitmap); the last carries every
    /// pixel the package owns. Empty: one stage, at the set-up's quality.
    /// Check with [`check_stages`].
    pub stages: Vec<WireQuality>,
}

/// The most stages a progressive frame has (every [`WireQuality`] once).
pub const MAX_STAGES: usize = 4;

/// Checks a progressive frame's stages: at most [`MAX_STAGES`], each later
/// than the one before (preview, refine, full, reference), and none for a
/// per-reflector method (it has no quality levels).
pub fn check_stages(stages: &[WireQuality], method: WireMethod) -> Result<(), WireError> {
    let bad = |reason: String| Err(WireError::BadStages(reason));
    if stages.len() > MAX_STAGES {
        return bad(format!("{} stages, at most {MAX_STAGES}", stages.len()));
    }
    let later = |a: WireQuality, b: WireQuality| Quality::from(b) > Quality::from(a);
    if let Some(pair) = stages.windows(2).find(|pair| !later(pair[0], pair[1])) {
        return bad(format!("{:?} before {:?}", pair[0], pair[1]));
    }
    if stages.len() > 1 && MethodKind::from(method).per_reflector() {
        return bad(format!(
            "{} stages for a per-reflector method",
            stages.len()
        ));
    }
    Ok(())
}

/// A package: reflector triangle ids of one frame, traced as a unit (or
/// reflector group indices, see [`FrameStart::method`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Package {
    pub id: PackageId,
    /// The frame (announced with `FrameStart`) the package belongs to.
    pub job: JobId,
    pub frame: u32,
    pub triangles: Vec<u32>,
    /// A whole frame (every item of it, batch work) comes with its
    /// frame's set-up, which no other worker hears of (a whole frame's
    /// `FrameStart` travels only with it): the worker also rasterizes the
    /// base frame, composites and encodes the finished frame as the master
    /// would, and answers with [`ResultPixels::Frame`].
    pub whole: Option<Box<FrameStart>>,
}

/// A traced package.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PackageResult {
    pub id: PackageId,
    pub pixels: ResultPixels,
    pub stats: WirePackageStats,
    /// Wall time the worker spent on the package, for load balancing.
    pub busy_micros: u64,
    /// Wall time the worker spent setting up the package's frame for it
    /// (its first package of the frame; 0 for the others): the set-up
    /// phase of the master's timeline.
    pub setup_micros: u64,
    /// Samples traced per triangle of the package, in package order: how the
    /// load balancer splits `busy_micros` over the triangles.
    pub triangle_samples: Vec<u32>,
    /// The stage of a progressive frame these pixels are ([`FrameStart::stages`],
    /// in order; the pixels that changed since the package's last stage,
    /// every owned pixel at the first; counters and times of this stage
    /// alone); `None` for a frame of one stage.
    pub stage: Option<WireQuality>,
    /// A progressive frame's `preview` and `refine` stages: the package's
    /// refinement meshes after the stage, which the dashboard's view draws
    /// as vertex colours; `None` otherwise.
    pub mesh: Option<WireMesh>,
}

/// What a result carries: a split package's pixels, for the master to
/// composite over its base frame, or a whole frame finished on the worker.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum ResultPixels {
    /// The package's pixels (a split frame's package).
    Bitmap(WireBitmap),
    /// The finished frame of a whole package: its image in the job's
    /// format and its components when the job asks for them, exactly what
    /// the master's [`FrameDone`] carries.
    Frame {
        image: WireImage,
        aux: Option<WireFrameAux>,
    },
}

/// A package the worker could not trace.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct PackageFailed {
    pub id: PackageId,
    pub error: String,
}

/// A job as a submitter sends it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireJob {
    /// A name for logs and status (the job file's name).
    pub name: String,
    pub scene: JobScene,
    /// One set-up per frame, rendered in order.
    pub frames: Vec<WireFrameSetup>,
    /// The reflector triangles (the same for every frame).
    pub reflectors: Vec<u32>,
    /// Also send each frame's per-pixel components (`FrameDone::aux`).
    pub aux: bool,
    /// The reflection method of every frame.
    pub method: WireMethod,
    /// How finished frames travel (`FrameDone::image`): linear unless the
    /// submitter writes only 8-bit outputs. The components (`aux`) are
    /// always linear.
    pub image: WireImageFormat,
    /// Higher runs first; equal priorities run in submission order.
    pub priority: i32,
    /// What the job is, for listings.
    pub kind: WireJobKind,
}

/// What a job is, for `vtfarm jobs`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WireJobKind {
    /// A job file's frames (`vtfarm submit`, `vtfarm render`).
    Render,
    /// A glare study: one job whose variants are jobs of their own.
    Study,
    /// A move of the dashboard's interactive view.
    View,
    /// A variant of a glare study (listed under its study).
    Variant,
}

impl WireJobKind {
    /// The lowercase name listings use: the one serde gives it in JSON.
    pub fn name(self) -> &'static str {
        match self {
            WireJobKind::Render => "render",
            WireJobKind::Study => "study",
            WireJobKind::View => "view",
            WireJobKind::Variant => "variant",
        }
    }
}

/// A glare study as a submitter sends it: its variants, each a job (a
/// variant is one scene), run and controlled as one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireStudy {
    /// Its name in listings.
    pub name: String,
    /// Every variant's priority (higher runs first).
    pub priority: i32,
    /// The variants in the study's order, each naming its scene by hash.
    pub variants: Vec<WireJob>,
}

/// One row of `vtfarm jobs`: a job, or a study with its variants.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct JobRow {
    /// The job, or the study: its state and frames are its variants'
    /// together.
    pub job: JobSummary,
    /// A study's variants, in order (none for other jobs).
    pub variants: Vec<JobSummary>,
}

/// A job's state on the wire (the master core's `JobState`, whose table
/// of transitions is the one rule). [`WireJobState::name`] is the one
/// table of the states' names: listings, metrics, logs and the serde
/// names (JSON) all read it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WireJobState {
    Queued,
    Running,
    Paused,
    Completed,
    Failed,
    Cancelled,
}

impl WireJobState {
    /// Every state, in the order listings count them (and the serde
    /// variant index: the order is part of the wire).
    pub const ALL: [WireJobState; 6] = [
        WireJobState::Queued,
        WireJobState::Running,
        WireJobState::Paused,
        WireJobState::Completed,
        WireJobState::Failed,
        WireJobState::Cancelled,
    ];

    /// The lowercase name listings, metrics and JSON use.
    pub fn name(self) -> &'static str {
        match self {
            WireJobState::Queued => "queued",
            WireJobState::Running => "running",
            WireJobState::Paused => "paused",
            WireJobState::Completed => "completed",
            WireJobState::Failed => "failed",
            WireJobState::Cancelled => "cancelled",
        }
    }

    /// The state with this name.
    fn from_name(name: &str) -> Option<WireJobState> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }
}

impl std::fmt::Display for WireJobState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// As a derived unit enum serializes: the variant's index (bincode) and its
/// name from [`WireJobState::name`] (JSON).
impl Serialize for WireJobState {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let index = Self::ALL.iter().position(|s| s == self).unwrap_or_default();
        serializer.serialize_unit_variant("WireJobState", index as u32, self.name())
    }
}

/// The names serde's errors and `deserialize_enum` want as a static list.
static STATE_NAMES: std::sync::LazyLock<[&'static str; 6]> =
    std::sync::LazyLock::new(|| WireJobState::ALL.map(WireJobState::name));

impl<'de> Deserialize<'de> for WireJobState {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        use serde::de::{EnumAccess, Error, VariantAccess, Visitor};

        /// A variant tag: an index (bincode) or a name (JSON).
        struct Tag(WireJobState);
        impl<'de> Deserialize<'de> for Tag {
            fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
                deserializer.deserialize_identifier(TagVisitor)
            }
        }
        struct TagVisitor;
        impl Visitor<'_> for TagVisitor {
            type Value = Tag;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a job state's name or index")
            }
            fn visit_u64<E: Error>(self, index: u64) -> Result<Tag, E> {
                (usize::try_from(index).ok())
                    .and_then(|i| WireJobState::ALL.get(i).copied())
                    .map(Tag)
                    .ok_or_else(|| E::custom(format_args!("no job state has index {index}")))
            }
            fn visit_str<E: Error>(self, name: &str) -> Result<Tag, E> {
                WireJobState::from_name(name)
                    .map(Tag)
                    .ok_or_else(|| E::unknown_variant(name, &*STATE_NAMES))
            }
        }
        struct StateVisitor;
        impl<'de> Visitor<'de> for StateVisitor {
            type Value = WireJobState;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a job state")
            }
            fn visit_enum<A: EnumAccess<'de>>(self, data: A) -> Result<WireJobState, A::Error> {
                let (Tag(state), variant) = data.variant::<Tag>()?;
                variant.unit_variant()?;
                Ok(state)
            }
        }
        deserializer.deserialize_enum("WireJobState", &*STATE_NAMES, StateVisitor)
    }
}

/// What a user asks of a job (`vtfarm cancel|pause|resume|requeue|priority`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum JobAction {
    Cancel,
    Pause,
    Resume,
    /// Render a finished job again: every frame, or with `failed_only`
    /// only the frames it did not finish.
    Requeue {
        failed_only: bool,
    },
    SetPriority(i32),
}

impl JobAction {
    /// The `vtfarm` command that asks for it.
    pub fn command(&self) -> &'static str {
        match self {
            JobAction::Cancel => "cancel",
            JobAction::Pause => "pause",
            JobAction::Resume => "resume",
            JobAction::Requeue { failed_only: false } => "requeue",
            JobAction::Requeue { failed_only: true } => "requeue --failed",
            JobAction::SetPriority(_) => "priority",
        }
    }
}

/// One job as `vtfarm jobs`, `GET /api/jobs` and the dashboard list it.
/// Times are milliseconds since the Unix epoch, as the master's clock
/// read them.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct JobSummary {
    pub id: JobId,
    pub name: String,
    pub kind: WireJobKind,
    pub state: WireJobState,
    pub priority: i32,
    pub frames_done: u32,
    /// Frames a failed job did not finish.
    pub frames_failed: u32,
    /// Frames a cancelled job did not finish.
    pub frames_cancelled: u32,
    pub frames_total: u32,
    pub submitted_ms: u64,
    pub started_ms: Option<u64>,
    pub finished_ms: Option<u64>,
    /// Where it was submitted from (the submitter's address; `master` for
    /// the interactive view's jobs).
    pub host: String,
    /// Why it failed or who cancelled it; empty otherwise.
    pub reason: String,
}

/// What a job asks the farm for, besides its scene and frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct JobOptions {
    /// The reflection method the workers run.
    pub method: MethodKind,
    /// Send the per-pixel components (mask, reflected, transmitted,
    /// reflected object) with each frame.
    pub aux: bool,
}

/// The job message for a scene (named by its hash) and its frames, its
/// finished frames sent linear.
pub fn wire_job(
    name: &str,
    scene: &SceneData,
    frames: &[FrameSetup],
    reflectors: &[TriangleId],
    options: JobOptions,
) -> WireJob {
    WireJob {
        name: name.to_owned(),
        scene: JobScene::Hash(scene.hash),
        frames: frames.iter().map(WireFrameSetup::from).collect(),
        reflectors: crate::wire_triangles(reflectors),
        aux: options.aux,
        method: options.method.into(),
        image: WireImageFormat::LinearF32,
        priority: 0,
        kind: WireJobKind::Render,
    }
}

/// Where a job's scene comes from.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum JobScene {
    /// The scene itself.
    Data(SceneData),
    /// A scene the master already has (from an earlier job); the master
    /// fails the job when it does not.
    Hash(SceneHash),
}

/// A finished frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FrameDone {
    pub job: JobId,
    pub frame: u32,
    /// The composited frame in the job's [`WireImageFormat`].
    pub image: WireImage,
    pub stats: FrameStats,
    /// The per-pixel components, when the job asked for them.
    pub aux: Option<WireFrameAux>,
}

/// A frame's per-pixel components besides the colour: what a glare study
/// measures, row-major from the top; compressed like the colour (the
/// conversions are [`WireFrameAux::encode`] and
/// [`WireFrameAux::into_components`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireFrameAux {
    /// The reflected component (linear RGB; black off the reflectors).
    pub reflected: WireImage,
    /// The transmitted component (linear RGB; black off the reflectors).
    pub transmitted: WireImage,
    /// The object each pixel mirrors (`vtfarm_scene::NONE` for none):
    /// little-endian byte planes, zstd-compressed.
    #[serde(with = "bytes")]
    pub reflected_object: Vec<u8>,
    /// 1 on reflector pixels, 0 elsewhere, a byte per pixel, zstd-compressed.
    #[serde(with = "bytes")]
    pub mask: Vec<u8>,
}

/// Counters of one farm frame (written by `vtfarm submit` as `stats.json`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameStats {
    /// Master wall time from the frame's first assignment to its last result.
    pub wall_micros: u64,
    /// Packages the frame was cut into (each counted once).
    pub packages: u32,
    /// Straggler copies handed out.
    pub duplicates: u32,
    /// Failed attempts that were retried elsewhere.
    pub failures: u32,
    /// Packages requeued from lost workers.
    pub requeued: u32,
    /// `(max busy - mean busy) / mean busy` over the workers that took part.
    pub imbalance: f64,
    /// Sum of busy time over wall time: how many workers were busy on
    /// average (not a speed-up over anything; the name stays for the status
    /// API's JSON).
    pub speedup: f64,
    /// Sum of the packages' counters.
    pub totals: WirePackageStats,
    /// Each worker's share, in the order the workers joined.
    pub workers: Vec<WorkerFrameStats>,
    /// Where the frame's time went, as the master saw it (for the timeline).
    pub phases: Vec<FramePhase>,
}

/// One stretch of a frame's timeline, in master time from the frame's start.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FramePhase {
    /// `master` or the worker's name.
    pub who: String,
    pub kind: PhaseKind,
    pub start_micros: u64,
    pub end_micros: u64,
}

/// What a [`FramePhase`] was spent on; the gaps between phases are idle.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PhaseKind {
    /// The master rasterizing the base frame and ID buffer.
    Base,
    /// A worker setting the frame up, until its first request for work arrives.
    Setup,
    /// A package in flight both ways: assignment to compute start (the
    /// master sees the package and the result transfer only together).
    Sending,
    /// A worker computing a package (its reported busy time, ending when
    /// the result arrived).
    Package,
    /// A progressive frame's stage on its way to the view (row `view`):
    /// from the stage before it went on view (or the frame's start) until
    /// this one did.
    Shown,
}

/// One worker's share of a frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WorkerFrameStats {
    pub name: String,
    pub busy_micros: u64,
    pub packages: u32,
    pub triangles: u32,
    pub rays: u64,
    pub bytes_in: u64,
    pub bytes_out: u64,
}

/// The farm's state, for `vtfarm status`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StatusReply {
    pub workers: Vec<WorkerStatus>,
    pub queue: QueueStatus,
    /// Scene bytes the master has sent to workers since it started (a worker
    /// that has a scene cached is sent nothing).
    pub scene_bytes_sent: u64,
}

/// One connected worker.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct WorkerStatus {
    pub name: String,
    /// The worker's remote address as the master sees it.
    pub address: String,
    pub threads: u32,
    /// Idle, waiting or busy.
    pub state: String,
    /// Measured throughput, assignment to result, in the load balancer's
    /// cost units (estimated triangle cost) per second; 0 before its first
    /// package.
    pub throughput: f64,
    pub packages_running: u32,
    pub packages_done: u64,
    pub triangles_done: u64,
    pub failures: u64,
    pub busy_micros: u64,
}

/// The master's queue.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct QueueStatus {
    /// Jobs waiting to start, in the order they will.
    pub waiting: Vec<JobId>,
    /// The running jobs (several run at once when workers would otherwise
    /// idle), in the order they get workers: each with its current frame
    /// and that frame's progress.
    pub running: Vec<RunningJob>,
}

/// Progress of a running job.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct RunningJob {
    pub job: JobId,
    pub name: String,
    pub frame: u32,
    pub frames: u32,
    /// Reflector triangles of the current frame that are in, and in all (as
    /// [`Message::Progress`] counts them).
    pub triangles_done: u64,
    pub triangles_total: u64,
    /// Paused: it keeps its place but gets no new work.
    pub paused: bool,
}

/// Serde helper for byte vectors: bincode then writes a length and the raw
/// bytes (and reads them in one copy) instead of one call per byte.
pub(crate) mod bytes {
    use serde::{Deserializer, Serializer};

    pub(crate) fn serialize<S: Serializer>(bytes: &[u8], s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(bytes)
    }

    pub(crate) fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<u8>, D::Error> {
        struct Visitor;
        impl<'de> serde::de::Visitor<'de> for Visitor {
            type Value = Vec<u8>;

            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("a byte array")
            }

            fn visit_bytes<E: serde::de::Error>(self, v: &[u8]) -> Result<Vec<u8>, E> {
                Ok(v.to_vec())
            }

            fn visit_byte_buf<E: serde::de::Error>(self, v: Vec<u8>) -> Result<Vec<u8>, E> {
                Ok(v)
            }

            // Self-describing formats may present bytes as a sequence.
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<Vec<u8>, A::Error> {
                let mut v = Vec::new();
                while let Some(b) = seq.next_element()? {
                    v.push(b);
                }
                Ok(v)
            }
        }
        d.deserialize_byte_buf(Visitor)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::tests::scene;

    #[test]
    fn a_job_id_encodes_as_the_bare_number_in_bincode_and_json() {
        let config = bincode::config::standard();
        for n in [0, 7, 300, u64::MAX] {
            let bytes = bincode::serde::encode_to_vec(JobId(n), config).unwrap();
            assert_eq!(bytes, bincode::serde::encode_to_vec(n, config).unwrap());
            let (back, _): (JobId, usize) =
                bincode::serde::decode_from_slice(&bytes, config).unwrap();
            assert_eq!(back, JobId(n));
            assert_eq!(serde_json::to_string(&JobId(n)).unwrap(), n.to_string());
            assert_eq!(JobId(n).to_string(), n.to_string());
            assert_eq!(n.to_string().parse::<JobId>(), Ok(JobId(n)));
        }
        assert_eq!(format!("{:012}", JobId(7)), "000000000007");
    }

    #[test]
    fn a_job_kinds_name_is_its_json_name() {
        use WireJobKind::*;
        for kind in [Render, Study, View, Variant] {
            let json = serde_json::to_string(&kind).unwrap();
            assert_eq!(json, format!("\"{}\"", kind.name()));
        }
    }

    /// The unit enum serde would derive: the encoding that the names of
    /// [`WireJobState::name`] must keep, on the wire and in JSON.
    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    #[serde(rename_all = "lowercase")]
    enum Derived {
        Queued,
        Running,
        Paused,
        Completed,
        Failed,
        Cancelled,
    }

    #[test]
    fn job_states_serialize_as_the_derived_enum_in_bincode_and_json() {
        let derived = [
            Derived::Queued,
            Derived::Running,
            Derived::Paused,
            Derived::Completed,
            Derived::Failed,
            Derived::Cancelled,
        ];
        let config = bincode::config::standard();
        for (state, derived) in WireJobState::ALL.into_iter().zip(derived) {
            let bytes = bincode::serde::encode_to_vec(state, config).unwrap();
            assert_eq!(
                bytes,
                bincode::serde::encode_to_vec(&derived, config).unwrap()
            );
            let (back, _): (WireJobState, _) =
                bincode::serde::decode_from_slice(&bytes, config).unwrap();
            assert_eq!(back, state);
            let json = serde_json::to_string(&state).unwrap();
            assert_eq!(json, serde_json::to_string(&derived).unwrap());
            assert_eq!(json, format!("\"{state}\""));
            assert_eq!(serde_json::from_str::<WireJobState>(&json).unwrap(), state);
        }
        let bad = serde_json::from_str::<WireJobState>("\"done\"").unwrap_err();
        assert!(bad.to_string().contains("unknown variant `done`"), "{bad}");
        let beyond = bincode::serde::encode_to_vec(6u32, config).unwrap();
        assert!(bincode::serde::decode_from_slice::<WireJobState, _>(&beyond, config).is_err());
    }

    #[test]
    fn scene_data_round_trips_and_hashes_the_canonical_encoding() {
        let s = scene();
        let data = SceneData::from_scene(&s);
        assert_eq!(data.hash, scene_hash(&s));
        assert_eq!(data.to_scene().expect("intact"), s);
        // Equal scenes hash equal; any change changes the hash.
        assert_eq!(scene_hash(&scene()), data.hash);
        let mut moved = scene();
        moved.positions[3].y += 1.0;
        assert_ne!(scene_hash(&moved), data.hash);
    }

    #[test]
    fn tampered_scene_data_is_rejected() {
        let mut data = SceneData::from_scene(&scene());
        let last = data.bytes.len() - 1;
        data.bytes[last] ^= 1;
        let error = data.to_scene().expect_err("hash no longer matches");
        assert!(matches!(error, WireError::HashMismatch { .. }), "{error}");
        // Consistent hash but content that does not decode.
        let junk = vec![0xff; 16];
        let data = SceneData {
            hash: Sha256::digest(&junk).into(),
            bytes: junk,
        };
        let error = data.to_scene().expect_err("not a scene");
        assert!(matches!(error, WireError::Decode { .. }), "{error}");
    }

    #[test]
    fn close_codes_are_distinct_and_invertible() {
        for code in RefuseCode::ALL {
            assert_ne!(code.close_code(), 0, "0 is an orderly close");
            let close = u64::from(code.close_code());
            assert_eq!(RefuseCode::from_close_code(close), Some(code));
        }
        assert_eq!(RefuseCode::from_close_code(0), None);
    }
}
