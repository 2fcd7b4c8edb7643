//! The master's logic without sockets or clock: connections and messages in,
//! messages and closes out, around the pure `Scheduler`. The server crate's
//! async driver (`vtfarm_master::driver`) feeds it; tests drive it directly.
//!
//! Per frame it sends `FrameStart` to every worker first. A split frame's
//! base frame and ID buffer it asks the driver to rasterize
//! ([`Output::RasterizeBase`]) while the workers set up and trace; results
//! that arrive before it are held until it is there (and reported to the
//! scheduler as arrived, so they are not taken for stragglers). A whole
//! frame (batch work, the scheduler's `whole_frames`) has no base frame
//! here: its one package's worker renders, composites and encodes it, and
//! the core checks the finished frame's sizes and format and forwards it. Frames are
//! pipelined: the scheduler starts frame N+1 as soon as frame N has nothing
//! left to hand out, so up to `vtfarm_proto::FRAMES_IN_FLIGHT` frames are
//! assembled at once (the [`FarmRules`]). It hands out the
//! scheduler's packages, composites each accepted result over the base frame
//! and sends the finished frame to the submitter. A result that writes a
//! pixel its package does not own in the frame's ID buffer (pixel ownership)
//! fails the package.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use glam::Vec3;
use tracing::{debug, info, warn};
use vtfarm_imaging::Image;
use vtfarm_method::{MethodKind, reflector_groups};
use vtfarm_proto::{
    FrameDone, FramePhase, FrameStart, JobAction, JobScene, JobSummary, KeptFrames, Message,
    Package, PackageResult, PhaseKind, QueueStatus, RunningJob, SceneData, SceneHash, StatusReply,
    WireBitmap, WireFrameAux, WireFrameSetup, WireImage, WireImageFormat, WireJob, WireJobKind,
    WirePackageStats, WorkerFrameStats, WorkerStatus, check_triangle_ids, encoded_len,
};
use vtfarm_raster::IdBuffer;
use vtfarm_render::{FrameSetup, components_bounds, morton_order, reflector_flags};
use vtfarm_scene::{Scene, TriangleId};
use vtfarm_scheduler::{
    Assignment, Event, FrameWork, JobId, PackageId, PackageMeasure, QueueOptions, Scheduler,
    WorkerId, WorkerState,
};
use vtfarm_vertex::{FrameImage, PackageStats, PixelRect, Quality, SparseBitmap};

use crate::ahead::{Bases, frames_held_at_most};
use crate::error::{JobRejected, ResultRejected};
use crate::finish::{
    EncodedFrame, FinishQueue, FinishedFrame, Finishing, FrameEncodeRequest, SrgbBytes,
};
use crate::jobs::{JobControlError, JobEntry, JobState, JobTable, Retention};
use crate::record::{DamagedJob, Record, StoredJob, Written};
use crate::rules::FarmRules;
use crate::stages::{StageProgress, StageWork};
use crate::telemetry::Telemetry;
use crate::view::{GlareRequest, ViewError, ViewFigures, ViewRequest, ViewSource, Views};

/// A connection, numbered by the driver.
pub type ConnId = u64;

/// Who is on a connection (from its handshake).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Peer {
    Worker {
        name: String,
        threads: u32,
        address: String,
    },
    Submitter {
        address: String,
    },
}

/// What the core asks the driver to do.
#[derive(Debug)]
pub enum Output {
    Send(ConnId, Box<Message>),
    /// Drop the connection, logging why.
    Close(ConnId, String),
    /// Keep this in the job journal (only when the core is persistent).
    Persist(Record),
    /// Send `conn` the journal's `FrameDone`s of `job`, frames `frames`, in
    /// order, before anything that follows; a frame the journal cannot give
    /// back goes to [`MasterCore::replay_failed`] (rendered again).
    Replay {
        conn: ConnId,
        job: u64,
        frames: std::ops::Range<u32>,
    },
    /// Rasterize a base frame (CPU work, off the driver's task) and hand it
    /// to [`MasterCore::base_frame_ready`].
    RasterizeBase(BaseFrameRequest),
    /// Compute the glare figures of the view's stage just put on view (CPU
    /// work, off the driver's task, after the stage is shown; a driver may
    /// drop a request a newer one replaced before it started) and hand them
    /// to [`MasterCore::view_figures_ready`].
    ViewGlare(GlareRequest),
    /// Encode a finished split frame for the wire (CPU work, off the
    /// driver's task: `finish.rs` says why) and hand it to
    /// [`MasterCore::frame_encoded`].
    EncodeFrame(FrameEncodeRequest),
}

/// A base frame to rasterize: what [`BaseFrameRequest::rasterize`] needs.
#[derive(Clone, Debug)]
pub struct BaseFrameRequest {
    pub job: u64,
    pub frame: u32,
    scene: Arc<Scene>,
    setup: FrameSetup,
    /// Also convert it to 8-bit sRGB: the job's frames go out so
    /// (`finish.rs`). A view's job does not: its frames go only to the
    /// dashboard's list, off the view's latency, which its base frame is on.
    srgb: bool,
    /// A finished frame's buffers to rasterize into.
    spare: Option<Box<BaseFrame>>,
}

impl BaseFrameRequest {
    /// The shaded base frame and its ID buffer (and its sRGB bytes where
    /// the job's frames go out in sRGB), in a finished frame's buffers
    /// where the master has some (`vtfarm_raster::rasterize_into`).
    pub fn rasterize(self) -> BaseFrame {
        let BaseFrame {
            mut image,
            mut ids,
            mut srgb,
        } = self.spare.map_or_else(BaseFrame::empty, |spare| *spare);
        let (camera, lighting) = (&self.setup.camera, &self.setup.lighting);
        vtfarm_raster::rasterize_into(&self.scene, camera, lighting, &mut image, &mut ids);
        if self.srgb {
            srgb.convert_base(&image);
        } else {
            // Not held unused with a base frame made ahead.
            srgb = SrgbBytes::default();
        }
        BaseFrame { image, ids, srgb }
    }

    /// Whether it rasterizes into a finished frame's buffers.
    pub fn reuses_buffers(&self) -> bool {
        self.spare.is_some()
    }

    /// Whether it also converts the base frame to sRGB (all of it).
    pub fn converts_to_srgb(&self) -> bool {
        self.srgb
    }
}

/// A split frame's base frame ([`BaseFrameRequest::rasterize`]): the shaded
/// image, its ID buffer and its sRGB bytes (converted where the job's
/// frames go out in sRGB). A finished frame's buffers are kept for a later
/// frame's base frame: rasterizing and converting into them spares the
/// page faults of fresh buffers (at 1080p as much CPU as the work itself).
#[derive(Clone)]
pub struct BaseFrame {
    pub(crate) image: Image,
    pub(crate) ids: IdBuffer,
    pub(crate) srgb: SrgbBytes,
}

impl BaseFrame {
    fn empty() -> BaseFrame {
        BaseFrame {
            image: Image::black(0, 0),
            ids: IdBuffer::new(0, 0),
            srgb: SrgbBytes::default(),
        }
    }
}

impl std::fmt::Debug for BaseFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (width, height) = (self.image.width, self.image.height);
        let srgb = self.srgb.of_base();
        write!(f, "BaseFrame({width}x{height}, sRGB converted: {srgb})")
    }
}

/// Spare base-frame buffers kept: two (a 1080p image, ID buffer and sRGB
/// bytes are about 56 MB); base frames beyond them rasterize into fresh
/// buffers.
const SPARE_BASES: usize = 2;

pub use vtfarm_proto::ATTACH_GRACE;

struct Job {
    name: String,
    /// The submitters following the job: each gets every frame. Empty
    /// while none is attached (lost, or not back after a restart): a
    /// persistent master renders it on, journaling its frames.
    submitters: BTreeSet<ConnId>,
    /// Frames before this one were finished before a restart: they are
    /// journaled, and the scheduler's empty stand-ins for them are skipped.
    resume_from: u32,
    /// Frames finished so far (resumed ones included).
    frames_done: u32,
    scene: Arc<Scene>,
    scene_hash: SceneHash,
    reflectors: Vec<u32>,
    frames: Vec<FrameSetup>,
    /// Send the per-pixel components with each frame.
    aux: bool,
    /// How finished frames travel (and are journaled).
    image: WireImageFormat,
    method: MethodKind,
    /// For per-reflector methods, the reflector groups the work items
    /// index; `None` when the items are the reflector triangles themselves.
    groups: Option<Vec<Vec<u32>>>,
    /// The frames being assembled, oldest first (two while pipelined).
    assembling: Vec<FrameAssembly>,
    /// A progressive job's stages (the interactive view's moves), in
    /// order; empty for one stage at each frame's quality.
    stages: Vec<Quality>,
    /// Finished frames on their way out, and the job's end after them.
    finishing: FinishQueue,
}

impl Job {
    /// The request for frame `job`/`frame`'s base frame (its set-up must
    /// exist), into `spare`'s buffers where given; converted to sRGB ahead
    /// when the job's frames go out so (`finish.rs`).
    fn base_request(&self, job: u64, frame: u32, spare: Option<BaseFrame>) -> BaseFrameRequest {
        BaseFrameRequest {
            job,
            frame,
            scene: self.scene.clone(),
            setup: self.frames[frame as usize].clone(),
            srgb: self.image == WireImageFormat::Srgb8,
            spare: spare.map(Box::new),
        }
    }

    /// The frame `frame` if it is being assembled.
    fn assembly(&self, frame: u32) -> Option<&FrameAssembly> {
        self.assembling.iter().find(|a| a.start.frame == frame)
    }

    fn assembly_mut(&mut self, frame: u32) -> Option<&mut FrameAssembly> {
        self.assembling.iter_mut().find(|a| a.start.frame == frame)
    }

    /// The reflector triangles that work `items` cover, sorted: the
    /// triangles whose pixels the package's result may write.
    fn triangles_in(&self, items: &[u32]) -> Vec<TriangleId> {
        let mut triangles: Vec<TriangleId> = match &self.groups {
            Some(groups) => (items.iter())
                .filter_map(|&g| groups.get(g as usize))
                .flatten()
                .copied()
                .collect(),
            None => items.to_vec(),
        };
        triangles.sort_unstable();
        triangles
    }
}

/// The frame being assembled (its index is `start.frame`).
struct FrameAssembly {
    start: FrameStart,
    /// A whole frame: its worker finishes it, the core forwards `finished`.
    whole: bool,
    /// A whole frame's image and components as its worker sent them.
    finished: Option<(WireImage, Option<WireFrameAux>)>,
    /// The frame's ID buffer: which reflector triangle owns each pixel;
    /// `None` until the base frame is rasterized.
    ids: Option<IdBuffer>,
    /// Empty until the base frame is rasterized.
    image: Assembled,
    /// Results that came before the ID buffer, to check once it is there:
    /// (connection, result, its wire size).
    held: Vec<(ConnId, PackageResult, u64)>,
    /// When the frame started (master time) and where its time went.
    started: Duration,
    phases: Vec<FramePhase>,
    totals: PackageStats,
    triangles_done: u64,
    /// A progressive frame's stages as they come in (`stages.rs`).
    progress: Option<StageProgress<ResultPixels>>,
}

/// A frame as results are composited over its base frame: its pixels, the
/// rectangle results wrote, and the base frame's sRGB bytes (the encoding
/// converts only that rectangle into them, `finish.rs`).
pub(crate) struct Assembled {
    pub(crate) pixels: AssembledPixels,
    /// The union of the composited results' rectangles: every pixel
    /// written over the base frame lies inside.
    pub(crate) written: PixelRect,
    pub(crate) srgb: SrgbBytes,
}

/// A frame's pixels: the colour only, or with the per-pixel components
/// when the job asks for them (a view's jobs always do). No output of a
/// colour-only job reads the components, so their planes are not made.
pub(crate) enum AssembledPixels {
    Color(Image),
    Components(FrameImage),
}

impl AssembledPixels {
    pub(crate) fn color(&self) -> &Image {
        match self {
            AssembledPixels::Color(color) => color,
            AssembledPixels::Components(image) => &image.color,
        }
    }

    /// The colour buffer alone.
    pub(crate) fn into_color(self) -> Image {
        match self {
            AssembledPixels::Color(color) => color,
            AssembledPixels::Components(image) => image.color,
        }
    }
}

impl Assembled {
    /// Starts from the base frame, with components over `components` (the
    /// reflectors' rectangle) when the job asks for them.
    fn new(base: BaseFrame, components: Option<PixelRect>) -> (Assembled, IdBuffer) {
        let BaseFrame { image, ids, srgb } = base;
        let pixels = match components {
            Some(bounds) => AssembledPixels::Components(FrameImage::new(image, bounds)),
            None => AssembledPixels::Color(image),
        };
        let assembled = Assembled {
            pixels,
            written: PixelRect::EMPTY,
            srgb,
        };
        (assembled, ids)
    }

    /// Nothing yet: the base frame is on its way.
    fn awaiting_base() -> Assembled {
        Assembled {
            pixels: AssembledPixels::Color(Image::black(0, 0)),
            written: PixelRect::EMPTY,
            srgb: SrgbBytes::default(),
        }
    }

    pub(crate) fn color(&self) -> &Image {
        self.pixels.color()
    }

    /// The frame with its components, when the job asks for them.
    fn components(&self) -> Option<&FrameImage> {
        match &self.pixels {
            AssembledPixels::Components(image) => Some(image),
            AssembledPixels::Color(_) => None,
        }
    }

    /// Decodes a result into what this frame composites (the colours
    /// straight from the wire when that is all it keeps) and checks pixel
    /// ownership: every pixel it writes must be one that `ids` gives to a
    /// triangle `owned` accepts.
    fn check(
        &self,
        bitmap: WireBitmap,
        ids: &IdBuffer,
        owned: impl Fn(TriangleId) -> bool,
    ) -> Result<ResultPixels, ResultRejected> {
        let (width, height) = (self.color().width, self.color().height);
        let foreign = |(x, y): (u32, u32)| ResultRejected::ForeignPixel { x, y };
        match self.pixels {
            AssembledPixels::Color(_) => {
                let colors = bitmap.colors_within(width, height)?;
                // Inside the frame: `colors_within` checked.
                let bounds = bitmap_rect(bitmap.x0, bitmap.y0, bitmap.width, bitmap.height);
                // The ID buffer is the frame's size: every index is in it.
                match colors.iter().find(|(i, _)| !owned(ids.triangle[*i])) {
                    Some(&(i, _)) => Err(foreign((i as u32 % width, i as u32 / width))),
                    None => Ok(ResultPixels::Colors { bounds, colors }),
                }
            }
            AssembledPixels::Components(_) => {
                let bitmap = bitmap.into_bitmap_within(width, height)?;
                match bitmap.foreign_pixel(ids, owned) {
                    Some(pixel) => Err(foreign(pixel)),
                    None => Ok(ResultPixels::Bitmap(bitmap)),
                }
            }
        }
    }

    /// Writes a checked result's pixels ([`FrameImage::composite`]),
    /// adding its rectangle to the written one.
    fn composite(&mut self, pixels: &ResultPixels) {
        self.written = self.written.union(pixels.bounds());
        match (&mut self.pixels, pixels) {
            (AssembledPixels::Color(color), ResultPixels::Colors { colors, .. }) => {
                for &(i, c) in colors {
                    color.pixels[i] = c;
                }
            }
            (AssembledPixels::Components(image), ResultPixels::Bitmap(bitmap)) => {
                image.composite(bitmap)
            }
            // `check` decodes for the kind of assembly it is called on, and
            // a frame's kind is set once, with its base frame.
            _ => unreachable!("a result decoded for another kind of frame"),
        }
    }
}

/// A checked result: pixels to composite, or a whole frame finished.
enum Accepted {
    Composite(ResultPixels),
    Finished(WireImage, Option<WireFrameAux>),
}

/// A checked result in the form its frame composites: frame indices and
/// colours (with the rectangle they lie in), or the whole bitmap with the
/// components.
enum ResultPixels {
    Colors {
        bounds: PixelRect,
        colors: Vec<(usize, Vec3)>,
    },
    Bitmap(SparseBitmap),
}

impl ResultPixels {
    /// The rectangle every pixel it writes lies in.
    fn bounds(&self) -> PixelRect {
        match self {
            ResultPixels::Colors { bounds, .. } => *bounds,
            ResultPixels::Bitmap(bitmap) => {
                bitmap_rect(bitmap.x0, bitmap.y0, bitmap.width, bitmap.height)
            }
        }
    }
}

/// The rectangle of a result's bitmap (its corner and sides, inside the
/// frame once checked).
fn bitmap_rect(x0: u32, y0: u32, width: u32, height: u32) -> PixelRect {
    PixelRect {
        x0,
        y0,
        x1: x0 + width,
        y1: y0 + height,
    }
}

/// A package on its way: what the results must be matched against.
struct InFlight {
    job: u64,
    /// The connection of the worker it went to.
    worker: ConnId,
    frame: u32,
    /// Its frame's every item, to come back finished.
    whole: bool,
    /// The reflector triangles its items cover, sorted: for progress and
    /// pixel ownership.
    triangles: Vec<TriangleId>,
    /// Size of the `Package` message, for the statistics.
    bytes_in: u64,
    /// When it was handed out, or when its last result (a progressive
    /// frame's stage) arrived: where the next result's phases start on
    /// the timeline.
    last_result_at: Duration,
}

/// What a persistent core keeps beside the journal, so that nothing the
/// journal fails to keep or give back is lost (see `journal.rs`).
#[derive(Default)]
struct Kept {
    /// Finished frames not (yet) known to be written: until the driver
    /// says a frame's write succeeded ([`MasterCore::journal_written`]) it
    /// is replayed from here, and a frame whose write failed stays here as
    /// long as its job is kept.
    unjournaled: BTreeMap<(u64, u32), FrameDone>,
    /// Each journaled job as queued (its scene by hash, or inline for a
    /// job restored complete), to render a frame again.
    definitions: BTreeMap<u64, WireJob>,
    /// Jobs rendering one frame again that the journal could not give
    /// back: repair job → (its job, the frame).
    repairs: BTreeMap<u64, (u64, u32)>,
    /// Jobs set aside as damaged, with why: an attach is told so.
    damaged: BTreeMap<u64, String>,
    /// Jobs a record of which could not be written, with the last error:
    /// a submitter attaching later is told too.
    failed_writes: BTreeMap<u64, String>,
    /// Frames of `unjournaled` whose write failed (not queued again yet):
    /// one is written again after each write that succeeds.
    to_rewrite: BTreeSet<(u64, u32)>,
    /// Restored jobs whose journal had a damaged frame, rendered again:
    /// the frame and why, told to attaching submitters.
    damaged_frames: BTreeMap<u64, (u32, String)>,
}

impl Kept {
    /// A job's records are gone (or set aside): so is what is kept of it.
    fn forget(&mut self, job: u64) {
        self.definitions.remove(&job);
        self.failed_writes.remove(&job);
        self.damaged_frames.remove(&job);
        self.unjournaled.retain(|&(j, _), _| j != job);
        self.to_rewrite.retain(|&(j, _)| j != job);
    }
}

/// The master's state.
pub struct MasterCore {
    scheduler: Scheduler,
    peers: BTreeMap<ConnId, Peer>,
    scenes: BTreeMap<SceneHash, (Arc<Scene>, Arc<SceneData>)>,
    jobs: BTreeMap<u64, Job>,
    /// Submissions whose scene the master still has to receive.
    awaiting_scene: BTreeMap<ConnId, WireJob>,
    packages: BTreeMap<u64, InFlight>,
    /// The frames each worker keeps, as it counts them from the messages
    /// it got (`KeptFrames`, fed by [`MasterCore::send`]): a split frame's
    /// `FrameStart` goes again only to a worker that let it go.
    worker_frames: BTreeMap<ConnId, KeptFrames>,
    next_job: u64,
    scene_bytes_sent: u64,
    outbox: VecDeque<Output>,
    telemetry: Telemetry,
    /// Whether jobs are journaled and outlive their submitter.
    persistent: bool,
    /// Every listed job: its state, priority, progress and times; finished
    /// ones stay as long as `retention` allows (and, on a persistent
    /// master, their journaled frames for re-attaching).
    table: JobTable,
    retention: Retention,
    /// The wall clock at `now` zero, in milliseconds since the Unix epoch
    /// (the driver's reading; 0 on a virtual clock): the jobs' times.
    wall_origin_ms: u64,
    /// Why a job is being cancelled (who asked), for its listing and its
    /// submitters, until the scheduler's `JobCancelled`.
    cancel_reasons: BTreeMap<u64, String>,
    /// The journal's side of the core (persistent cores only).
    kept: Kept,
    /// The time of the input being handled.
    now: Duration,
    /// Workers that left during the running frame, for its stats' names.
    departed: BTreeMap<ConnId, Peer>,
    /// The interactive view: pickable scenes and the move being rendered.
    views: Views,
    /// Finished frames' buffers for the next base frames (at most [`SPARE_BASES`]).
    spare_bases: Vec<BaseFrame>,
    /// Base frames in the making and made ahead of a batch job's tail
    /// (`ahead.rs`).
    bases: Bases,
    /// The last finished frame's uncompressed bytes, the next one's buffer
    /// (where its base frame's sRGB bytes were not converted ahead).
    frame_bytes: Vec<u8>,
}

impl MasterCore {
    pub fn new(rules: FarmRules) -> Self {
        MasterCore {
            scheduler: Scheduler::new(rules.scheduler_config()),
            peers: BTreeMap::new(),
            scenes: BTreeMap::new(),
            jobs: BTreeMap::new(),
            awaiting_scene: BTreeMap::new(),
            packages: BTreeMap::new(),
            worker_frames: BTreeMap::new(),
            next_job: 1,
            scene_bytes_sent: 0,
            outbox: VecDeque::new(),
            telemetry: Telemetry::default(),
            persistent: false,
            table: JobTable::default(),
            retention: rules.retention,
            wall_origin_ms: 0,
            cancel_reasons: BTreeMap::new(),
            kept: Kept::default(),
            now: Duration::ZERO,
            departed: BTreeMap::new(),
            views: Views::default(),
            spare_bases: Vec::new(),
            bases: Bases::default(),
            frame_bytes: Vec::new(),
        }
    }

    /// A core that journals its jobs (`Output::Persist`) and renders a job
    /// whose submitter went away to the end.
    pub fn persistent(rules: FarmRules) -> Self {
        MasterCore {
            persistent: true,
            ..MasterCore::new(rules)
        }
    }

    /// Sets what the wall clock read at `now` zero (milliseconds since the
    /// Unix epoch): the jobs' submitted, started and finished times. The
    /// driver reads the clock; the core only adds.
    pub fn set_wall_clock(&mut self, origin_ms: u64) {
        self.wall_origin_ms = origin_ms;
    }

    /// The wall clock at `now`, in milliseconds since the epoch.
    fn wall_ms(&self, now: Duration) -> u64 {
        self.wall_origin_ms.saturating_add(now.as_millis() as u64)
    }

    /// The jobs as `vtfarm jobs` lists them.
    pub fn jobs(&self) -> &JobTable {
        &self.table
    }

    /// Resumes a journaled job (at start, before any connection): it runs
    /// from its first unfinished frame, or waits complete for its submitter.
    pub fn restore(&mut self, now: Duration, stored: StoredJob) {
        self.now = now;
        self.next_job = self.next_job.max(stored.id + 1);
        if let Some(damaged) = stored.damaged_frame.clone() {
            self.kept.damaged_frames.insert(stored.id, damaged);
        }
        let mut entry = match stored.summary.clone() {
            Some(summary) => JobEntry::from_summary(summary),
            // Written before its state (a crash between the two): queued.
            None => self.new_entry(stored.id, &stored.job, "unknown".into(), now),
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
            (self.kept.definitions).insert(stored.id, stored.job);
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
        let job = &stored.job;
        let scene = match &job.scene {
            JobScene::Data(data) => JobScene::Hash(data.hash),
            JobScene::Hash(hash) => JobScene::Hash(*hash),
        };
        let definition = WireJob {
            name: job.name.clone(),
            scene,
            frames: job.frames.clone(),
            reflectors: job.reflectors.clone(),
            aux: job.aux,
            method: job.method,
            image: job.image,
            priority: job.priority,
            kind: job.kind,
        };
        (self.kept.definitions).insert(stored.id, definition);
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
            warn!(job = stored.id, "{reason}; setting it aside");
            self.kept.definitions.remove(&stored.id);
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
                job = stored.id,
                from_frame = stored.frames_done,
                "job resumed from the journal"
            );
        }
        self.pump();
    }

    /// The next thing to do, if any.
    pub fn poll_output(&mut self) -> Option<Output> {
        self.outbox.pop_front()
    }

    /// When [`MasterCore::handle_timeout`] should run next.
    pub fn poll_timeout(&self) -> Option<Duration> {
        // A finished job too old to keep goes at its expiry.
        let expiry = (self.table.next_expiry(self.retention))
            .map(|ms| Duration::from_millis(ms.saturating_sub(self.wall_origin_ms)));
        [self.scheduler.poll_timeout(), expiry]
            .into_iter()
            .flatten()
            .min()
    }

    pub fn handle_timeout(&mut self, now: Duration) {
        self.now = now;
        self.scheduler.handle_timeout(now);
        self.forget_expired();
        self.pump();
    }

    /// Lets go of the finished jobs beyond [`Retention`]: their listing,
    /// their definition and their journaled frames.
    fn forget_expired(&mut self) {
        let now_ms = self.wall_ms(self.now);
        for id in self.table.expired(self.retention, now_ms) {
            debug!(job = id, "finished job no longer kept");
            self.table.remove(id);
            self.persist(Record::JobForgotten { id });
        }
    }

    /// A connection passed its handshake.
    pub fn connected(&mut self, now: Duration, conn: ConnId, peer: Peer) {
        self.now = now;
        if let Peer::Worker {
            name,
            threads,
            address,
        } = &peer
        {
            info!(worker = %name, %address, threads, "worker joined");
            if let Err(e) = self.scheduler.worker_joined(now, WorkerId(conn), *threads) {
                self.close(conn, format!("cannot join: {e}"));
                return;
            }
            self.worker_frames.insert(conn, KeptFrames::default());
            // A running frame: bring the newcomer up to date.
            let catch_up: Vec<Message> = self
                .jobs
                .iter()
                .filter(|(_, job)| !job.assembling.is_empty())
                .flat_map(|(&id, job)| {
                    // A whole frame's set-up goes only with its package.
                    let split = job.assembling.iter().filter(|a| !a.whole);
                    let starts = split.map(|a| a.start.clone());
                    std::iter::once(Message::SceneOffer {
                        hash: job.scene_hash,
                        job: id,
                    })
                    .chain(starts.map(Message::FrameStart))
                })
                .collect();
            for message in catch_up {
                self.send(conn, message);
            }
        }
        self.peers.insert(conn, peer);
        self.pump();
    }

    /// A connection went away (closed, failed, or dropped by us).
    pub fn disconnected(&mut self, now: Duration, conn: ConnId) {
        self.now = now;
        match self.peers.remove(&conn) {
            Some(peer @ Peer::Worker { .. }) => {
                info!(worker = %peer_name(conn, Some(&peer)), "worker left");
                let _ = self.scheduler.worker_left(now, WorkerId(conn));
                self.worker_frames.remove(&conn);
                // Its packages of the running frame still count in the frame's stats.
                self.departed.insert(conn, peer);
            }
            Some(Peer::Submitter { .. }) => {
                self.awaiting_scene.remove(&conn);
                let orphaned: Vec<u64> = self
                    .jobs
                    .iter()
                    .filter(|(_, j)| j.submitters.contains(&conn))
                    .map(|(&id, _)| id)
                    .collect();
                for job in orphaned {
                    let j = self.jobs.get_mut(&job).expect("listed above");
                    j.submitters.remove(&conn);
                    if !j.submitters.is_empty() {
                        continue; // others still follow it
                    }
                    if self.persistent {
                        // Its frames are journaled: it may come back (or
                        // attach from elsewhere) and get them.
                        info!(job, "submitter left; the job renders on");
                    } else {
                        // Nobody is left to receive the images: stop its jobs.
                        info!(job, "submitter left, cancelling its job");
                        let reason = "its submitter left (the embedded master keeps no frames)";
                        self.cancel_reasons.insert(job, reason.into());
                        let _ = self.scheduler.cancel_job(now, JobId(job));
                    }
                }
            }
            None => {}
        }
        self.pump();
    }

    /// A message arrived on a connection.
    pub fn message(&mut self, now: Duration, conn: ConnId, message: Message) {
        self.now = now;
        match self.peers.get(&conn) {
            Some(Peer::Worker { .. }) => self.worker_message(now, conn, message),
            Some(Peer::Submitter { .. }) => self.submitter_message(now, conn, message),
            None => debug!(conn, "message from an unknown connection ignored"),
        }
        self.pump();
    }

    fn worker_message(&mut self, now: Duration, conn: ConnId, message: Message) {
        let worker = WorkerId(conn);
        // Anything from a worker shows it is alive.
        let _ = self.scheduler.heartbeat(now, worker);
        // Results are counted at their wire size for the statistics.
        let result_bytes = match &message {
            Message::PackageResult(_) => encoded_len(&message),
            _ => 0,
        };
        match message {
            Message::Heartbeat => {}
            Message::RequestWork { .. } => {
                // A worker has one request out at a time and sets a frame up
                // when its first package of it comes, so any job's work will
                // do, whichever frame it names: the newest it heard of may
                // be of a job that ended (a higher priority's that ran
                // after it, say), and dropping the request would idle it.
                let _ = self.scheduler.request_work(now, worker);
            }
            Message::SceneRequest { hash } => match self.scenes.get(&hash) {
                Some((_, data)) => {
                    self.scene_bytes_sent += data.bytes.len() as u64;
                    self.send(conn, Message::SceneData((**data).clone()));
                }
                None => self.close(conn, "asked for a scene the master does not have".into()),
            },
            Message::PackageResult(result) => {
                self.record_package(conn, &result);
                self.package_result(now, conn, result, result_bytes)
            }
            Message::PackageFailed(failed) => {
                warn!(worker = %self.name(conn), package = failed.id, "package failed: {}", failed.error);
                match (self.scheduler).package_failed(
                    now,
                    worker,
                    PackageId(failed.id),
                    failed.error,
                ) {
                    // It runs nowhere now (a retry is a new assignment).
                    Ok(()) => self.drop_in_flight(failed.id, conn),
                    Err(e) => debug!("failure report ignored: {e}"),
                }
            }
            other => self.close(conn, format!("unexpected {} from a worker", other.name())),
        }
    }

    fn package_result(
        &mut self,
        now: Duration,
        conn: ConnId,
        result: PackageResult,
        bytes_out: u64,
    ) {
        let worker = WorkerId(conn);
        let Some(in_flight) = self.packages.get(&result.id) else {
            debug!(package = result.id, "result for an unknown package ignored");
            return;
        };
        let Some(job) = self.jobs.get(&in_flight.job) else {
            return;
        };
        let Some(current) = job.assembly(in_flight.frame) else {
            debug!(package = result.id, "result for a finished frame ignored");
            return;
        };
        let ids = current.ids.as_ref();
        if !in_flight.whole && ids.is_none() {
            // The base frame is still being rasterized: check the result
            // then; till then it is no straggler.
            let (job_id, frame) = (in_flight.job, in_flight.frame);
            let package = PackageId(result.id);
            if let Err(e) = self.scheduler.package_arrived(now, worker, package) {
                debug!(package = result.id, "result ignored: {e}");
                return;
            }
            let current = (self.jobs.get_mut(&job_id))
                .and_then(|j| j.assembly_mut(frame))
                .expect("checked above");
            current.held.push((conn, result, bytes_out));
            return;
        }
        let PackageResult {
            id,
            pixels,
            stats,
            busy_micros,
            setup_micros: _,
            triangle_samples,
            stage,
            mesh,
        } = result;
        let owned = |t| in_flight.triangles.binary_search(&t).is_ok();
        // A progressive frame's result is the stage its package's copy
        // on this worker is due to send; any other frame's has none.
        let stage = match (&current.progress, stage) {
            (Some(progress), stage) => progress.check(id, conn, stage.map(Quality::from)).map(Some),
            (None, None) => Ok(None),
            (None, Some(found)) => Err(crate::StageRejected::OutOfOrder {
                found: Quality::from(found).name().to_owned(),
                expected: "none (a frame of one stage)".to_owned(),
            }),
        };
        let checked = stage.map_err(ResultRejected::from).and_then(|stage| {
            let accepted = match (pixels, in_flight.whole, ids) {
                (vtfarm_proto::ResultPixels::Bitmap(bitmap), false, Some(ids)) => current
                    .image
                    .check(bitmap, ids, owned)
                    .map(Accepted::Composite),
                (vtfarm_proto::ResultPixels::Frame { image, aux }, true, _) => {
                    check_finished(job, in_flight.frame, image, aux)
                        .map(|(image, aux)| Accepted::Finished(image, aux))
                }
                (vtfarm_proto::ResultPixels::Frame { .. }, false, _) => {
                    Err(ResultRejected::FinishedFrameForSplitPackage)
                }
                // A split package's result without its base frame is held above.
                (vtfarm_proto::ResultPixels::Bitmap(_), _, _) => {
                    Err(ResultRejected::PixelsForWholeFrame)
                }
            };
            accepted.map(|accepted| (stage, accepted))
        });
        let (job_id, frame) = (in_flight.job, in_flight.frame);
        let (stage, accepted) = match checked {
            Ok(checked) => checked,
            Err(error) => {
                warn!(worker = %self.name(conn), package = id, "{error}");
                let failed =
                    (self.scheduler).package_failed(now, worker, PackageId(id), error.to_string());
                if failed.is_ok() {
                    // It runs nowhere now (a retry is a new assignment).
                    self.drop_in_flight(id, conn);
                }
                let current = (self.jobs.get_mut(&job_id)).and_then(|j| j.assembly_mut(frame));
                if let Some(progress) = current.and_then(|c| c.progress.as_mut()) {
                    progress.forget_copy(id, conn);
                }
                return;
            }
        };
        let stats = PackageStats::from(stats);
        let work = StageWork {
            busy: Duration::from_micros(busy_micros),
            samples: &triangle_samples,
            rays: stats.samples(),
            bytes_out,
        };
        if let Some(stage) = stage {
            // Still its package's copy on this worker (not done elsewhere
            // or requeued meanwhile); a stage in shows it is no straggler.
            if let Err(e) = self.scheduler.package_arrived(now, worker, PackageId(id)) {
                debug!(package = id, "stage result ignored: {e}");
                return;
            }
            if let Some(mesh) = &mesh {
                let triangles = &in_flight.triangles;
                if let Err(e) = (self.views).mesh_arrived(job_id, stage, triangles, mesh) {
                    warn!(worker = %self.name(conn), package = id, "mesh left out: {e}");
                }
            }
            let current = (self.jobs.get_mut(&job_id))
                .and_then(|j| j.assembly_mut(frame))
                .expect("checked above");
            let progress = current.progress.as_mut().expect("a stage was checked");
            let last = progress.is_last(stage);
            let copy = progress.record(id, conn, work);
            let measure = last.then(|| PackageMeasure {
                busy: copy.busy,
                item_seconds: copy.samples.iter().map(|&s| s as f64 + 1.0).collect(),
                rays: copy.rays,
                bytes_in: self.packages[&id].bytes_in,
                bytes_out: copy.bytes_out,
            });
            current.totals.add(&stats);
            let Accepted::Composite(pixels) = accepted else {
                unreachable!("a progressive frame is split")
            };
            self.stage_arrived(job_id, frame, stage, id, pixels);
            if let Some(measure) = measure {
                self.package_finished(now, conn, id, measure);
            }
            return;
        }
        let measure = PackageMeasure {
            busy: work.busy,
            // Samples are what an item costs; +1 so hidden ones are not free.
            // The scheduler checks that there is one per item.
            item_seconds: (triangle_samples.iter())
                .map(|&s| f64::from(s) + 1.0)
                .collect(),
            rays: work.rays,
            bytes_in: in_flight.bytes_in,
            bytes_out,
        };
        if !self.package_finished(now, conn, id, measure) {
            return;
        }
        let current = (self.jobs.get_mut(&job_id))
            .and_then(|j| j.assembly_mut(frame))
            .expect("checked above");
        current.totals.add(&stats);
        match accepted {
            Accepted::Composite(pixels) => current.image.composite(&pixels),
            Accepted::Finished(image, aux) => current.finished = Some((image, aux)),
        }
    }

    /// Package `id`'s last result from `conn` is in and checked: the
    /// scheduler hears it done with `measure` (all its stages' work);
    /// `false` when it refuses it (a late straggler copy or a duplicate:
    /// the first result won).
    fn package_finished(
        &mut self,
        now: Duration,
        conn: ConnId,
        id: u64,
        measure: PackageMeasure,
    ) -> bool {
        let (rays, bytes_out) = (measure.rays, measure.bytes_out);
        let done = self
            .scheduler
            .package_done(now, WorkerId(conn), PackageId(id), measure);
        if let Err(e) = done {
            debug!(package = id, "result ignored: {e}");
            return false;
        }
        // Done: a late duplicate copy now finds nothing and is ignored.
        let Some(in_flight) = self.packages.remove(&id) else {
            return true;
        };
        let worker_name = self.worker_name(conn);
        (self.telemetry).package_done(&worker_name, rays, in_flight.bytes_in, bytes_out);
        let Some(job) = self.jobs.get_mut(&in_flight.job) else {
            return true;
        };
        let total = job.reflectors.len() as u32;
        let Some(current) = job.assembly_mut(in_flight.frame) else {
            return true;
        };
        current.triangles_done += in_flight.triangles.len() as u64;
        if let Some(progress) = current.progress.as_mut() {
            progress.forget(id);
        }
        let progress = Message::Progress {
            job: in_flight.job,
            frame: current.start.frame,
            done: current.triangles_done as u32,
            total,
        };
        let submitters = job.submitters.clone();
        self.send_to(&submitters, progress);
        true
    }

    /// A checked stage `stage` of package `id` of a progressive frame:
    /// composited in place or held (`stages.rs`); a stage complete now is
    /// the view's.
    fn stage_arrived(
        &mut self,
        job_id: u64,
        frame: u32,
        stage: usize,
        id: u64,
        pixels: ResultPixels,
    ) {
        let Some(job) = self.jobs.get_mut(&job_id) else {
            return;
        };
        let Some(triangles) = self.packages.get(&id).map(|p| &p.triangles) else {
            return;
        };
        let Some(current) = job.assembling.iter_mut().find(|a| a.start.frame == frame) else {
            return;
        };
        let FrameAssembly {
            image,
            progress,
            phases,
            started,
            ..
        } = current;
        let Some(progress) = progress.as_mut() else {
            return;
        };
        let (views, scene, now, t0) = (&mut self.views, &job.scene, self.now, *started);
        let show = |stage, image: &Assembled| {
            if let Some(image) = image.components() {
                views.stage_finished(job_id, stage, image, scene, now);
            }
            // On the timeline: from the stage before it to this one.
            let shown = |p: &&FramePhase| p.kind == PhaseKind::Shown;
            let since = (phases.iter().rfind(shown))
                .map_or(t0, |p| t0 + Duration::from_micros(p.end_micros));
            phases.push(phase(t0, "view".into(), PhaseKind::Shown, since, now));
        };
        progress.deliver(stage, triangles, pixels, image, Assembled::composite, show);
        self.ask_for_view_figures();
    }

    /// The view's stage just shown gets its glare figures computed (after
    /// the driver carried out what came before: the stage is on view).
    fn ask_for_view_figures(&mut self) {
        if let Some(request) = self.views.take_glare_request() {
            self.outbox.push_back(Output::ViewGlare(request));
        }
    }

    /// The driver computed the glare figures [`Output::ViewGlare`] asked for.
    pub fn view_figures_ready(
        &mut self,
        now: Duration,
        generation: u64,
        quality: Quality,
        figures: ViewFigures,
    ) {
        self.now = now;
        self.views.figures_ready(generation, quality, figures);
    }

    fn submitter_message(&mut self, now: Duration, conn: ConnId, message: Message) {
        match message {
            Message::Heartbeat => {}
            Message::StatusRequest => {
                let reply = self.status();
                self.send(conn, Message::StatusReply(reply));
            }
            Message::SubmitJob { job } => self.submit(now, conn, job),
            Message::AttachJob { job, from_frame } => self.attach(conn, job, from_frame),
            Message::ListJobs { all } => {
                let jobs = self.table.list(all).map(JobEntry::summary).collect();
                self.send(conn, Message::JobList { jobs });
            }
            Message::ControlJob { job, action } => {
                let who = self.name(conn);
                let outcome = (self.control_job(now, job, action, &who)).map_err(|e| e.to_string());
                self.send(conn, Message::JobControlled { job, outcome });
            }
            Message::SceneData(data) => match self.awaiting_scene.remove(&conn) {
                Some(mut job) if job.scene == JobScene::Hash(data.hash) => {
                    job.scene = JobScene::Data(data);
                    self.submit(now, conn, job);
                }
                _ => self.close(conn, "scene data nobody asked for".into()),
            },
            other => self.close(
                conn,
                format!("unexpected {} from a submitter", other.name()),
            ),
        }
    }

    /// Checks a submitted job and queues it (or asks for its scene first).
    fn submit(&mut self, now: Duration, conn: ConnId, mut job: WireJob) {
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
        // The journal keeps the job with its scene by hash (the bytes once per scene).
        let scene = std::mem::replace(&mut job.scene, JobScene::Hash(scene_hash));
        let journaled = self.persistent.then(|| job.clone());
        job.scene = scene;
        let id = self.next_job;
        let frames = job.frames.len() as u32;
        let host = match self.peers.get(&conn) {
            Some(Peer::Submitter { address }) => address.clone(),
            _ => "unknown".into(),
        };
        let entry = self.new_entry(id, &job, host, now);
        if let Err(e) = self.queue_job(now, id, job, BTreeSet::from([conn]), 0) {
            return self.refuse_job(conn, e.to_string());
        }
        self.next_job += 1;
        self.table.insert(entry);
        self.remember_for_view(id);
        self.send(conn, Message::JobAccepted { job: id, frames });
        self.telemetry.counters.jobs_submitted += 1;
        if let Some(job) = journaled {
            self.kept.definitions.insert(id, job.clone());
            let scene = self.scenes[&scene_hash].1.clone();
            self.persist(Record::JobQueued {
                id,
                job: Box::new(job),
                scene,
            });
            self.persist_state(id);
        }
    }

    /// A listing for a job just submitted.
    fn new_entry(&self, id: u64, job: &WireJob, host: String, now: Duration) -> JobEntry {
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
        }
    }

    /// Journals job `id`'s listing (its state, priority and times).
    fn persist_state(&mut self, id: u64) {
        if let Some(entry) = self.table.get(id) {
            let summary = entry.summary();
            self.persist(Record::JobState(Box::new(summary)));
        }
    }

    /// Moves a listed job to `to` and journals it; a job the table does
    /// not list (a frame rendered again) has no state to keep.
    fn set_job_state(&mut self, id: u64, to: JobState) {
        let at = self.wall_ms(self.now);
        match self.table.set_state(id, to, at) {
            Ok(Some(_)) => self.persist_state(id),
            Ok(None) => {}
            // The core asks only for what the table allows: a bug if not.
            Err(e) => warn!("{e}"),
        }
    }

    /// A user's request about a job (`vtfarm cancel` and the like, the
    /// dashboard's buttons, the HTTP API): the job as it is afterwards, or
    /// why not. `who` names the asker for the job's submitters and listing.
    pub fn control_job(
        &mut self,
        now: Duration,
        id: u64,
        action: JobAction,
        who: &str,
    ) -> Result<JobSummary, JobControlError> {
        self.now = now;
        let entry = self.table.get(id).ok_or(JobControlError::UnknownJob(id))?;
        let state = entry.state;
        if entry.kind == WireJobKind::View {
            return Err(JobControlError::ViewJob(id));
        }
        let not_now = |action, applies_to| JobControlError::NotNow {
            job: id,
            state,
            action,
            applies_to,
        };
        match action {
            JobAction::Cancel => {
                if state.is_finished() {
                    return Err(not_now("cancel", "queued, running or paused"));
                }
                info!(job = id, by = who, "cancelling the job");
                let reason = format!("job {id} was cancelled by {who}");
                self.cancel_reasons.insert(id, reason);
                let _ = self.scheduler.cancel_job(now, JobId(id));
            }
            JobAction::Pause => {
                if !matches!(state, JobState::Queued | JobState::Running) {
                    return Err(not_now("pause", "queued or running"));
                }
                info!(job = id, by = who, "pausing the job");
                let _ = self.scheduler.pause_job(now, JobId(id));
                self.set_job_state(id, JobState::Paused);
                self.tell_state(id, format!("paused by {who}"));
            }
            JobAction::Resume => {
                if state != JobState::Paused {
                    return Err(not_now("resume", "paused"));
                }
                info!(job = id, by = who, "resuming the job");
                let started = self.table.get(id).is_some_and(|e| e.started_ms.is_some());
                let to = if started {
                    JobState::Running
                } else {
                    JobState::Queued
                };
                self.set_job_state(id, to);
                let _ = self.scheduler.resume_job(now, JobId(id));
                self.tell_state(id, format!("resumed by {who}"));
            }
            JobAction::Requeue { failed_only } => {
                if !state.is_finished() {
                    return Err(not_now("requeue", "completed, failed or cancelled"));
                }
                self.requeue(now, id, failed_only)?;
                info!(job = id, by = who, failed_only, "job queued again");
            }
            JobAction::SetPriority(priority) => {
                let _ = self.scheduler.set_priority(now, JobId(id), priority);
                if let Some(entry) = self.table.get_mut(id) {
                    entry.priority = priority;
                }
                self.persist_state(id);
            }
        }
        self.pump();
        let entry = self.table.get(id).ok_or(JobControlError::UnknownJob(id))?;
        Ok(entry.summary())
    }

    /// Tells a job's submitters its new state and why.
    fn tell_state(&mut self, id: u64, reason: String) {
        let (Some(entry), Some(job)) = (self.table.get(id), self.jobs.get(&id)) else {
            return;
        };
        let message = Message::JobStateChanged {
            job: id,
            state: entry.state.into(),
            reason,
        };
        let submitters = job.submitters.clone();
        self.send_to(&submitters, message);
    }

    /// Queues a finished job again under its id: every frame, or with
    /// `failed_only` the frames it did not finish.
    fn requeue(
        &mut self,
        now: Duration,
        id: u64,
        failed_only: bool,
    ) -> Result<(), JobControlError> {
        let entry = self.table.get(id).ok_or(JobControlError::UnknownJob(id))?;
        let resume_from = if failed_only { entry.frames_done } else { 0 };
        if failed_only && resume_from >= entry.frames_total {
            return Err(JobControlError::NothingToRequeue(id));
        }
        let requeue_error = |reason: String| JobControlError::Requeue { job: id, reason };
        let definition = (self.kept.definitions.get(&id).cloned()).ok_or_else(|| {
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
            self.kept.definitions.insert(id, journaled.clone());
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

    /// Checks a job whose scene is in the cache (or in `job`) and queues it
    /// under `id`, frames before `resume_from` being finished already.
    fn queue_job(
        &mut self,
        now: Duration,
        id: u64,
        job: WireJob,
        submitters: BTreeSet<ConnId>,
        resume_from: u32,
    ) -> Result<(), JobRejected> {
        self.queue_job_with(now, id, job, submitters, resume_from, false)
    }

    /// [`MasterCore::queue_job`], the job queued `paused` or not.
    fn queue_job_with(
        &mut self,
        now: Duration,
        id: u64,
        mut job: WireJob,
        submitters: BTreeSet<ConnId>,
        resume_from: u32,
        paused: bool,
    ) -> Result<(), JobRejected> {
        let (priority, job_kind) = (job.priority, job.kind);
        let scene_hash = match &job.scene {
            JobScene::Data(d) => d.hash,
            JobScene::Hash(h) => *h,
        };
        if let JobScene::Data(data) = std::mem::replace(&mut job.scene, JobScene::Hash(scene_hash))
        {
            let scene = data.to_scene().map_err(JobRejected::BadScene)?;
            (self.scenes.entry(scene_hash)).or_insert_with(|| (Arc::new(scene), Arc::new(data)));
        }
        let scene = match self.scenes.get(&scene_hash) {
            Some((scene, _)) => scene.clone(),
            None => return Err(JobRejected::UnknownScene),
        };
        check_triangle_ids("reflectors", &job.reflectors, scene.triangles.len())
            .map_err(JobRejected::BadReflectors)?;
        if job.reflectors.is_empty() || job.frames.is_empty() {
            return Err(JobRejected::Empty);
        }
        if job.aux && job.image != WireImageFormat::LinearF32 {
            return Err(JobRejected::ComponentsNeedLinearFrames);
        }
        let frames: Result<Vec<FrameSetup>, _> =
            job.frames.into_iter().map(FrameSetup::try_from).collect();
        let frames = frames.map_err(JobRejected::BadFrame)?;
        let reflectors = morton_order(&scene, job.reflectors);
        let method = MethodKind::from(job.method);
        // Per-reflector methods take whole reflectors: their work items are
        // reflector groups, which the workers derive from the same list.
        let groups = (method.per_reflector()).then(|| reflector_groups(&scene, &reflectors));
        let items: Vec<u32> = match &groups {
            Some(groups) => (0..groups.len() as u32).collect(),
            None => reflectors.clone(),
        };
        // Finished frames get no work: the scheduler completes them at once.
        let work = (0..frames.len() as u32)
            .map(|f| FrameWork {
                items: if f < resume_from {
                    Vec::new()
                } else {
                    items.clone()
                },
            })
            .collect();
        info!(job = id, name = %job.name, frames = frames.len(), reflectors = reflectors.len(), method = method.name(), "job queued");
        self.jobs.insert(
            id,
            Job {
                name: job.name,
                submitters,
                resume_from,
                frames_done: resume_from,
                scene,
                scene_hash,
                reflectors,
                frames,
                aux: job.aux,
                image: job.image,
                method,
                groups,
                assembling: Vec::new(),
                stages: Vec::new(),
                finishing: FinishQueue::default(),
            },
        );
        // The view's stages are split over the workers: their latency counts.
        let interactive = job_kind == WireJobKind::View;
        let options = QueueOptions {
            priority,
            paused,
            interactive,
        };
        let submitted = self
            .scheduler
            .submit_job_with(now, JobId(id), work, options);
        submitted.map_err(|e| {
            self.jobs.remove(&id);
            JobRejected::from(e)
        })
    }

    /// A submitter asks for a job's frames from `from_frame` on.
    fn attach(&mut self, conn: ConnId, job: u64, from_frame: u32) {
        // A finished job within retention: its journaled frames, then how it ended.
        let finished = (self.table.get(job))
            .filter(|e| e.state.is_finished() && self.persistent)
            .map(|e| (e.frames_total, e.frames_done, e.state, e.reason.clone()));
        let (frames, done) = if let Some(j) = self.jobs.get_mut(&job) {
            if !j.submitters.is_empty() {
                info!(job, "another submitter attached; each gets every frame");
            }
            j.submitters.insert(conn);
            (j.frames.len() as u32, j.frames_done)
        } else if let Some((frames, done, _, _)) = &finished {
            (*frames, *done)
        } else {
            let error = match (self.kept.damaged.get(&job), self.table.get(job)) {
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
        info!(job, conn, from_frame, "submitter attached");
        self.send(conn, Message::JobAccepted { job, frames });
        if let Some(error) = self.kept.failed_writes.get(&job).cloned() {
            self.send(conn, Message::JournalFailed { job, error });
        }
        if let Some((frame, reason)) = self.kept.damaged_frames.get(&job).cloned() {
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
    fn replay(&mut self, conn: ConnId, job: u64, frames: std::ops::Range<u32>) {
        let mut from_journal = frames.start..frames.start;
        for frame in frames {
            if let Some(done) = self.kept.unjournaled.get(&(job, frame)).cloned() {
                if !from_journal.is_empty() {
                    let frames = std::mem::replace(&mut from_journal, frame + 1..frame + 1);
                    self.outbox.push_back(Output::Replay { conn, job, frames });
                }
                from_journal = frame + 1..frame + 1;
                self.send(conn, Message::FrameDone(done));
            } else {
                from_journal.end = frame + 1;
            }
        }
        if !from_journal.is_empty() {
            let frames = from_journal;
            self.outbox.push_back(Output::Replay { conn, job, frames });
        }
    }

    /// Drops a job that ended, with its packages still in flight.
    fn forget_job(&mut self, job: u64) -> Option<Job> {
        self.packages.retain(|_, p| p.job != job);
        self.bases.forget(job);
        self.jobs.remove(&job)
    }

    /// Package `id` no longer runs on `worker` (it failed there, or the
    /// worker was lost): it leaves the packages in flight unless another
    /// worker runs it now.
    fn drop_in_flight(&mut self, id: u64, worker: ConnId) {
        if self.packages.get(&id).is_some_and(|p| p.worker == worker) {
            self.packages.remove(&id);
        }
    }

    /// Sends `message` to `conn`; a frame it names to a worker is among the
    /// frames that worker keeps now.
    fn send(&mut self, conn: ConnId, message: Message) {
        if let Some(kept) = self.worker_frames.get_mut(&conn) {
            kept.saw(&message);
        }
        self.outbox.push_back(Output::Send(conn, Box::new(message)));
    }

    /// Whether worker `conn` keeps frame `frame` of `job` (announced or
    /// set up), by the rule both ends count ([`KeptFrames`]).
    fn worker_keeps(&self, conn: ConnId, job: u64, frame: u32) -> bool {
        (self.worker_frames.get(&conn)).is_some_and(|kept| kept.contains((job, frame)))
    }

    /// Sends to each of a job's submitters.
    fn send_to(&mut self, submitters: &BTreeSet<ConnId>, message: Message) {
        for &conn in submitters {
            self.send(conn, message.clone());
        }
    }

    fn persist(&mut self, record: Record) {
        if !self.journals(record.job()) {
            return;
        }
        match &record {
            // Until the driver says it is written, a frame stays here.
            Record::FrameDone(done) => {
                (self.kept.unjournaled).insert((done.job, done.frame), (**done).clone());
            }
            Record::JobForgotten { id } | Record::JobDamaged { id, .. } => self.kept.forget(*id),
            _ => {}
        }
        self.outbox.push_back(Output::Persist(record));
    }

    /// Whether `job`'s records are journaled.
    fn journals(&self, job: u64) -> bool {
        // A view's jobs live as long as the page looks at them, and a frame
        // rendered again is journaled under its own job.
        self.persistent && !self.views.owns(job) && !self.kept.repairs.contains_key(&job)
    }

    fn refuse_job(&mut self, conn: ConnId, error: String) {
        warn!(conn, "job refused: {error}");
        self.send(
            conn,
            Message::JobFailed {
                job: 0,
                errors: vec![error],
            },
        );
    }

    fn close(&mut self, conn: ConnId, reason: String) {
        warn!(peer = %self.name(conn), "closing: {reason}");
        self.outbox.push_back(Output::Close(conn, reason));
    }

    fn name(&self, conn: ConnId) -> String {
        peer_name(conn, self.peers.get(&conn).or(self.departed.get(&conn)))
    }

    fn workers(&self) -> impl Iterator<Item = ConnId> + '_ {
        self.peers
            .iter()
            .filter(|(_, p)| matches!(p, Peer::Worker { .. }))
            .map(|(&c, _)| c)
    }

    /// Turns the scheduler's events and assignments into messages.
    fn pump(&mut self) {
        while let Some(event) = self.scheduler.poll_event() {
            self.event(event);
        }
        while let Some(assignment) = self.scheduler.poll_assignment() {
            self.assign(assignment);
        }
    }

    fn event(&mut self, event: Event) {
        match event {
            Event::JobStarted { job, .. } => {
                info!(job = job.0, "job started");
                if self
                    .table
                    .get(job.0)
                    .is_some_and(|e| e.state == JobState::Queued)
                {
                    self.set_job_state(job.0, JobState::Running);
                }
                let Some(hash) = self.jobs.get(&job.0).map(|j| j.scene_hash) else {
                    return;
                };
                let workers: Vec<ConnId> = self.workers().collect();
                for conn in workers {
                    self.send(conn, Message::SceneOffer { hash, job: job.0 });
                }
            }
            Event::JobResumed { job } => {
                // The workers may have let the job's frames go meanwhile:
                // each gets the starts it lacks.
                let Some(j) = self.jobs.get(&job.0) else {
                    return;
                };
                let offer = Message::SceneOffer {
                    hash: j.scene_hash,
                    job: job.0,
                };
                let starts: Vec<FrameStart> = (j.assembling.iter())
                    .filter(|a| !a.whole)
                    .map(|a| a.start.clone())
                    .collect();
                let workers: Vec<ConnId> = self.workers().collect();
                for conn in workers {
                    self.send(conn, offer.clone());
                    for start in &starts {
                        if !self.worker_keeps(conn, start.job, start.frame) {
                            self.send(conn, Message::FrameStart(start.clone()));
                        }
                    }
                }
            }
            Event::FrameStarted {
                job, frame, whole, ..
            } => {
                let resumed = (self.jobs.get(&job.0)).is_some_and(|j| frame < j.resume_from);
                if !resumed {
                    self.start_frame(job.0, frame, whole);
                }
                if whole {
                    // The master has little else to do while whole frames run.
                    self.make_base_ahead(job.0);
                }
            }
            Event::FrameComplete { job, frame, stats } => {
                let Some(j) = self.jobs.get_mut(&job.0) else {
                    return;
                };
                let Some(index) = j.assembling.iter().position(|a| a.start.frame == frame) else {
                    return;
                };
                let mut done = j.assembling.remove(index);
                // A progressive frame's stages went to the view as they came.
                if let (Some(image), None) = (done.image.components(), &done.progress) {
                    let now = self.now;
                    (self.views).stage_finished(job.0, frame as usize, image, &j.scene, now);
                    self.ask_for_view_figures();
                }
                info!(job = job.0, frame, wall = ?stats.wall, imbalance = stats.imbalance(), "frame complete");
                let workers = stats
                    .workers
                    .iter()
                    .map(|w| WorkerFrameStats {
                        name: self.name(w.worker.0),
                        busy_micros: w.busy.as_micros() as u64,
                        packages: w.packages,
                        triangles: w.items,
                        rays: w.rays,
                        bytes_in: w.bytes_in,
                        bytes_out: w.bytes_out,
                    })
                    .collect();
                let frame_stats = vtfarm_proto::FrameStats {
                    wall_micros: stats.wall.as_micros() as u64,
                    packages: stats.packages,
                    duplicates: stats.duplicates,
                    failures: stats.failures,
                    requeued: stats.requeued,
                    imbalance: stats.imbalance(),
                    speedup: stats.speedup(),
                    totals: WirePackageStats::from(&done.totals),
                    workers,
                    phases: done.phases.clone(),
                };
                // Encoded (and compressed) once, off the driver or by a
                // whole frame's worker: the journal and the submitter get the
                // same bytes. A frame nobody receives or keeps (a view's: the
                // view holds its stages) goes only to the dashboard's list,
                // in 8 bits, without components: its encoding is no part of
                // the view's latency.
                let owner = (self.kept.repairs.get(&job.0)).map_or(job.0, |&(owner, _)| owner);
                let journaled = self.journals(owner);
                let j = self.jobs.get_mut(&job.0).expect("checked above");
                let delivered = !j.submitters.is_empty() || journaled;
                let format = if delivered {
                    j.image
                } else {
                    WireImageFormat::Srgb8
                };
                let encoded = done.finished.take();
                if encoded.is_none() {
                    let request = FrameEncodeRequest {
                        job: job.0,
                        frame,
                        image: done.image,
                        format,
                        delivered,
                        scratch: std::mem::take(&mut self.frame_bytes),
                    };
                    self.outbox.push_back(Output::EncodeFrame(request));
                }
                let finished = FinishedFrame {
                    frame,
                    stats: frame_stats,
                    ids: done.ids,
                    encoded,
                    buffers: None,
                };
                j.finishing.push(Finishing::Frame(Box::new(finished)));
                self.departed.clear();
                self.tell_finished(job.0);
            }
            Event::JobComplete { job } => match self.jobs.get_mut(&job.0) {
                // Its last frames are on their way out: it ends after them.
                Some(j) if !j.finishing.is_empty() => j.finishing.push(Finishing::Complete),
                _ => self.job_complete(job.0),
            },
            Event::JobFailed {
                job,
                reason,
                errors,
            } => {
                // The same error from several workers is told once, with their names.
                let mut grouped: Vec<(String, Vec<String>)> = Vec::new();
                for (worker, error) in &errors {
                    let name = self.name(worker.0);
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
                warn!(job = job.0, "{}", errors.join("; "));
                if self.counts_in_totals(job.0) {
                    self.telemetry.counters.jobs_failed += 1;
                }
                let repaired = self.kept.repairs.remove(&job.0);
                if repaired.is_none() {
                    if let Some(entry) = self.table.get_mut(job.0) {
                        entry.reason = errors.join("; ");
                    }
                    self.set_job_state(job.0, JobState::Failed);
                }
                if let Some(j) = self.forget_job(job.0) {
                    let message = match repaired {
                        // Rendering a lost frame again failed: its job's
                        // submitters learn which frame they will not get.
                        Some((owner, frame)) => Message::FrameMissing {
                            job: owner,
                            frame,
                            reason: errors.join("; "),
                            rendering_again: false,
                        },
                        None => Message::JobFailed { job: job.0, errors },
                    };
                    self.send_to(&j.submitters, message);
                }
                if repaired.is_none() {
                    self.forget_view_job(job.0);
                    self.forget_expired();
                }
            }
            Event::JobCancelled { job } => {
                if self.counts_in_totals(job.0) {
                    self.telemetry.counters.jobs_cancelled += 1;
                }
                let reason = (self.cancel_reasons.remove(&job.0))
                    .unwrap_or_else(|| format!("job {} was cancelled", job.0));
                if let Some(entry) = self.table.get_mut(job.0) {
                    entry.reason = reason.clone();
                }
                self.set_job_state(job.0, JobState::Cancelled);
                if let Some(j) = self.forget_job(job.0) {
                    let state = JobState::Cancelled.into();
                    let message = Message::JobStateChanged {
                        job: job.0,
                        state,
                        reason,
                    };
                    self.send_to(&j.submitters, message);
                }
                if self.kept.repairs.remove(&job.0).is_none() {
                    self.forget_view_job(job.0);
                    self.forget_expired();
                }
            }
            Event::WorkerBlocklisted { worker, job } => {
                warn!(worker = %self.name(worker.0), job = job.0, "worker failed 3 packages: no more work of this job");
                let name = self.worker_name(worker.0);
                self.telemetry.blocklisted(&name, job.0);
            }
            Event::WorkerLost {
                worker,
                cause,
                requeued,
            } => {
                for package in &requeued {
                    self.drop_in_flight(package.0, worker.0);
                }
                let name = self.name(worker.0);
                match cause {
                    // A clean leave (a drained worker finished its package
                    // first) is no fault: `disconnected` said it left.
                    vtfarm_scheduler::LossCause::Left if requeued.is_empty() => {}
                    vtfarm_scheduler::LossCause::Left => {
                        info!(worker = %name, requeued = requeued.len(), "its packages go to the other workers");
                    }
                    vtfarm_scheduler::LossCause::HeartbeatTimeout => {
                        warn!(worker = %name, requeued = requeued.len(), "worker lost: it missed its heartbeats");
                        self.close(worker.0, "missed its heartbeats".into());
                    }
                }
            }
            Event::PackageCancelled { worker, package } => {
                self.send(worker.0, Message::CancelPackage { id: package.0 });
            }
        }
    }

    /// The scheduler's `JobComplete`, once the job's last frame is out.
    fn job_complete(&mut self, job: u64) {
        info!(job, "job complete");
        // A cancel asked for while its last frame was encoding came too
        // late (the scheduler had finished the job): the job completes.
        self.cancel_reasons.remove(&job);
        if self.counts_in_totals(job) {
            self.telemetry.counters.jobs_completed += 1;
        }
        let repaired = self.kept.repairs.remove(&job);
        if self.forget_job(job).is_some() && repaired.is_none() {
            // Kept (as retention allows) for a submitter that lost
            // the connection or attaches later.
            self.persist(Record::JobComplete { id: job });
            self.set_job_state(job, JobState::Completed);
            self.forget_view_job(job);
            self.forget_expired();
        }
    }

    /// The driver encoded the frame [`Output::EncodeFrame`] asked for: it
    /// goes out once the job's frames before it have (a job that ended
    /// meanwhile, cancelled or failed, drops it).
    pub fn frame_encoded(&mut self, now: Duration, encoded: EncodedFrame) {
        self.now = now;
        let job = encoded.job;
        let (taken, scratch) = match self.jobs.get_mut(&job) {
            Some(j) => j.finishing.encoded(encoded),
            None => (false, encoded.scratch),
        };
        if self.frame_bytes.is_empty() {
            self.frame_bytes = scratch;
        }
        if taken {
            self.tell_finished(job);
        }
    }

    /// Sends `job`'s finished frames that are ready, in order, and its end
    /// once they are all out.
    fn tell_finished(&mut self, job: u64) {
        while let Some(next) = (self.jobs.get_mut(&job)).and_then(|j| j.finishing.pop_ready()) {
            match next {
                Finishing::Frame(frame) => self.deliver_frame(job, *frame),
                Finishing::Complete => self.job_complete(job),
            }
        }
    }

    /// A finished frame, encoded, to its submitters and the journal.
    fn deliver_frame(&mut self, job: u64, finished: FinishedFrame) {
        let FinishedFrame {
            frame,
            stats,
            ids,
            encoded,
            buffers,
        } = finished;
        let (image, aux) = encoded.expect("only encoded frames are delivered");
        let Some(j) = self.jobs.get_mut(&job) else {
            return;
        };
        j.frames_done = frame + 1;
        if let Some(entry) = self.table.get_mut(job) {
            entry.frames_done = frame + 1;
        }
        let submitters = j.submitters.clone();
        // A frame rendered again is its own job's frame.
        let (owner, owner_frame) =
            (self.kept.repairs.get(&job)).map_or((job, frame), |&(owner, frame)| (owner, frame));
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
            self.spare(BaseFrame { image, ids, srgb });
        }
    }

    /// Announces the frame to the workers and, for a split frame, asks for
    /// its base image.
    fn start_frame(&mut self, job: u64, frame: u32, whole: bool) {
        let Some(j) = self.jobs.get_mut(&job) else {
            return;
        };
        let Some(setup) = j.frames.get(frame as usize) else {
            return;
        };
        // Made ahead, or coming: no base frame asked for again.
        let key = (job, frame);
        let ahead = self.bases.take(key);
        let coming = self.bases.making_ahead(key);
        let base = (!whole && ahead.is_none() && !coming)
            .then(|| j.base_request(job, frame, self.spare_bases.pop()));
        let start = FrameStart {
            job,
            frame,
            scene: j.scene_hash,
            setup: WireFrameSetup::from(setup),
            reflectors: j.reflectors.clone(),
            method: j.method.into(),
            aux: j.aux,
            image: j.image,
            stages: j.stages.iter().map(|&q| q.into()).collect(),
        };
        let progress =
            (j.stages.len() > 1).then(|| StageProgress::new(j.stages.clone(), &j.reflectors));
        j.assembling.push(FrameAssembly {
            start: start.clone(),
            whole,
            finished: None,
            ids: None,
            // The base frame, when it comes; until then results are held.
            image: Assembled::awaiting_base(),
            held: Vec::new(),
            started: self.now,
            phases: Vec::new(),
            totals: PackageStats::default(),
            triangles_done: 0,
            progress,
        });
        let submitters = j.submitters.clone();
        let total = j.reflectors.len() as u32;
        // A whole frame's set-up goes only with its package (`assign`).
        let workers: Vec<ConnId> = if whole {
            Vec::new()
        } else {
            self.workers().collect()
        };
        for conn in workers {
            self.send(conn, Message::FrameStart(start.clone()));
        }
        self.send_to(
            &submitters,
            Message::Progress {
                job,
                frame,
                done: 0,
                total,
            },
        );
        if let Some(base) = base {
            self.bases.requested(key, self.now, false);
            self.outbox.push_back(Output::RasterizeBase(base));
        }
        match ahead {
            Some(base) if !whole => self.use_base(job, frame, base),
            Some(base) => self.spare(base),
            None => {}
        }
    }

    /// Asks the driver for the next base frame of `job`'s last frames
    /// ahead of their start (`ahead.rs`): one at a time, while its whole
    /// frames run, for as many of its last frames (no more than the
    /// workers) as the base frames held, with those of the split frames
    /// being assembled, stay within the budget (`ahead::frames_held_at_most`).
    fn make_base_ahead(&mut self, job: u64) {
        let Some(j) = (self.jobs.get(&job)).filter(|j| j.assembling.iter().any(|a| a.whole)) else {
            return;
        };
        let Some(camera) = j.frames.last().map(|setup| setup.camera) else {
            return;
        };
        let in_flight = self.scheduler.config().frames_in_flight as usize;
        let budget = frames_held_at_most(in_flight, camera.width, camera.height);
        let assembling = (self.jobs.values().flat_map(|j| &j.assembling))
            .filter(|a| !a.whole)
            .count();
        if self.bases.any_making_ahead() || self.bases.held() + assembling >= budget {
            return;
        }
        let tail = budget.min(self.workers().count()) as u32;
        let frames = j.frames.len() as u32;
        let first = next_to_start(j).max(frames.saturating_sub(tail));
        let Some(frame) = (first..frames).find(|&f| !self.bases.has((job, f))) else {
            return;
        };
        let request = j.base_request(job, frame, self.spare_bases.pop());
        self.bases.requested((job, frame), self.now, true);
        self.outbox.push_back(Output::RasterizeBase(request));
    }

    /// Keeps a base frame's buffers (or a finished frame's) for a later
    /// base frame.
    fn spare(&mut self, base: BaseFrame) {
        if self.spare_bases.len() < SPARE_BASES {
            self.spare_bases.push(base);
        }
    }

    /// The driver rasterized the base frame that [`Output::RasterizeBase`]
    /// asked for: the held results are checked and composited now.
    pub fn base_frame_ready(&mut self, now: Duration, job: u64, frame: u32, base: BaseFrame) {
        self.now = now;
        let key = (job, frame);
        if let Some(cost) = self.bases.arrived(key, now) {
            // Gone meanwhile: nothing to learn for it.
            let _ = self.scheduler.base_frame_cost(now, JobId(job), cost);
        }
        let Some(j) = self.jobs.get(&job) else {
            self.spare(base);
            return;
        };
        let waiting = (j.assembly(frame)).is_some_and(|c| c.ids.is_none() && !c.whole);
        if waiting {
            self.use_base(job, frame, base);
        } else if frame >= next_to_start(j) {
            // Made ahead: kept for the frame's start.
            self.bases.keep(key, base);
            let _ = self.scheduler.base_frame_ahead(now, JobId(job), frame);
        } else {
            self.spare(base);
        }
        self.make_base_ahead(job);
        self.pump();
    }

    /// A split frame's base frame is here: the results held for it are
    /// checked and composited now.
    fn use_base(&mut self, job: u64, frame: u32, base: BaseFrame) {
        let now = self.now;
        let Some(j) = self.jobs.get_mut(&job) else {
            return;
        };
        // The components' planes cover the reflectors' rectangle only.
        let components = match j.frames.get(frame as usize) {
            Some(setup) if j.aux => {
                let is_reflector = reflector_flags(&j.scene, &j.reflectors);
                Some(components_bounds(&j.scene, &setup.camera, &is_reflector))
            }
            _ => None,
        };
        let Some(current) = j
            .assembly_mut(frame)
            .filter(|c| c.ids.is_none() && !c.whole)
        else {
            return;
        };
        // Nothing is composited yet: the image starts as the base frame.
        let (image, ids) = Assembled::new(base, components);
        current.image = image;
        current.ids = Some(ids);
        let phase = phase(
            current.started,
            "master".into(),
            PhaseKind::Base,
            current.started,
            now,
        );
        current.phases.push(phase);
        for (conn, result, bytes) in std::mem::take(&mut current.held) {
            self.package_result(now, conn, result, bytes);
        }
    }

    /// A result arrived: its package was in flight, its frame set up first
    /// if it was the worker's first package of the frame (the set-up starts
    /// when the package arrives), then computed for its busy time.
    fn record_package(&mut self, conn: ConnId, result: &PackageResult) {
        let name = self.name(conn);
        let now = self.now;
        let Some(in_flight) = self.packages.get_mut(&result.id) else {
            return;
        };
        // A progressive frame's later stage: from the stage before.
        let (frame, assigned_at) = (in_flight.frame, in_flight.last_result_at);
        in_flight.last_result_at = now;
        let Some(current) = (self.jobs.get_mut(&in_flight.job)).and_then(|j| j.assembly_mut(frame))
        else {
            return;
        };
        // The set-up first (it starts when the package arrives), then the
        // computing; what the worker's times leave of the interval is the
        // way there and back.
        let set_up = (assigned_at + Duration::from_micros(result.setup_micros)).min(now);
        let computed = now
            .saturating_sub(Duration::from_micros(result.busy_micros))
            .max(set_up);
        let t0 = current.started;
        if set_up > assigned_at {
            (current.phases).push(phase(
                t0,
                name.clone(),
                PhaseKind::Setup,
                assigned_at,
                set_up,
            ));
        }
        current.phases.extend([
            phase(t0, name.clone(), PhaseKind::Sending, set_up, computed),
            phase(t0, name, PhaseKind::Package, computed, now),
        ]);
    }

    fn assign(&mut self, a: Assignment) {
        let job = self.jobs.get(&a.job.0);
        let triangles = job.map_or_else(Vec::new, |j| j.triangles_in(&a.items));
        let whole = (job.and_then(|j| j.assembly(a.frame)))
            .filter(|_| a.whole)
            .map(|assembly| Box::new(assembly.start.clone()));
        // A worker that let this split frame go (it keeps the frames named
        // to it last, of any job: several jobs run at once) gets its start
        // again first; one that keeps it does not.
        let kept = self.worker_keeps(a.worker.0, a.job.0, a.frame);
        let again = (job.and_then(|j| j.assembly(a.frame)))
            .filter(|_| !kept && !a.whole)
            .map(|assembly| Message::FrameStart(assembly.start.clone()));
        let message = Message::Package(Package {
            id: a.package.0,
            job: a.job.0,
            frame: a.frame,
            triangles: a.items,
            whole,
        });
        let in_flight = InFlight {
            job: a.job.0,
            worker: a.worker.0,
            frame: a.frame,
            whole: a.whole,
            triangles,
            bytes_in: encoded_len(&message),
            last_result_at: self.now,
        };
        self.packages.insert(a.package.0, in_flight);
        if let Some(start) = again {
            self.send(a.worker.0, start);
        }
        self.send(a.worker.0, message);
    }

    /// Moves the interactive view's eye: cancels the previous move's job and
    /// queues the new view at rising quality (see `view.rs`); returns the
    /// new job's id.
    pub fn steer_view(&mut self, now: Duration, request: ViewRequest) -> Result<u64, ViewError> {
        self.now = now;
        let planned = self.views.plan(&request)?;
        if let Some(outdated) = self.views.running_job() {
            if self.scheduler.cancel_job(now, JobId(outdated)).is_ok() {
                self.views.superseded();
            }
        }
        let id = self.next_job;
        let entry = self.new_entry(id, &planned.job, "dashboard".into(), now);
        let queued = self.queue_job(now, id, planned.job.clone(), BTreeSet::new(), 0);
        if let Err(e) = queued {
            self.pump();
            return Err(ViewError::Queue(e.to_string()));
        }
        // One progressive frame: its packages go through the stages (its
        // frame starts as the scheduler's events are pumped, below).
        if let Some(j) = self
            .jobs
            .get_mut(&id)
            .filter(|_| planned.stages().len() > 1)
        {
            j.stages = planned.stages().to_vec();
        }
        self.next_job += 1;
        self.table.insert(entry);
        self.telemetry.counters.jobs_submitted += 1;
        self.views.started(planned, id, now);
        self.pump();
        Ok(id)
    }

    /// Whether a job's end counts in the completed, failed and cancelled
    /// totals: the listed jobs (a frame rendered again is no job of its
    /// own), which `jobs_submitted` counts as they are queued, so the
    /// totals agree.
    fn counts_in_totals(&self, id: u64) -> bool {
        self.table.get(id).is_some()
    }

    /// A view's job is listed only while it runs: each move of the eye
    /// makes several.
    fn forget_view_job(&mut self, id: u64) {
        if self
            .table
            .get(id)
            .is_some_and(|e| e.kind == WireJobKind::View)
        {
            self.table.remove(id);
        }
    }

    /// The interactive view's state.
    pub fn views(&self) -> &Views {
        &self.views
    }

    /// Keeps a submitted job's scene and first frame pickable for the view.
    fn remember_for_view(&mut self, id: u64) {
        let Some(j) = self.jobs.get(&id) else {
            return;
        };
        let Some(setup) = j.frames.first() else {
            return;
        };
        let source = ViewSource {
            name: j.name.clone(),
            scene_hash: j.scene_hash,
            scene: j.scene.clone(),
            reflectors: j.reflectors.clone(),
            method: j.method,
            setup: setup.clone(),
        };
        self.views.remember(id, source);
    }

    /// The master's history: counters, per-worker totals, finished frames.
    /// A job the journal set aside as damaged (at start): a submitter
    /// attaching to it is told why.
    pub fn restore_damaged(&mut self, damaged: DamagedJob) {
        self.next_job = self.next_job.max(damaged.id + 1);
        self.kept.damaged.insert(damaged.id, damaged.reason);
    }

    /// The driver wrote a record (or failed to): a written frame leaves
    /// memory; a failure is counted, told to the job's submitters, and the
    /// frame stays in memory for re-attaching submitters.
    pub fn journal_written(&mut self, now: Duration, written: Written) {
        self.now = now;
        match written.outcome {
            Ok(()) => {
                if let Some(frame) = written.frame {
                    self.kept.unjournaled.remove(&(written.job, frame));
                }
                // The disk takes records again: write a frame that failed.
                if let Some(key) = self.kept.to_rewrite.pop_first() {
                    if let Some(done) = self.kept.unjournaled.get(&key).cloned() {
                        let record = Record::FrameDone(Box::new(done));
                        self.outbox.push_back(Output::Persist(record));
                    }
                }
            }
            Err(error) => {
                if let Some(frame) = written.frame {
                    self.kept.to_rewrite.insert((written.job, frame));
                }
                warn!(job = written.job, "{error}");
                let counters = &mut self.telemetry.counters;
                counters.journal_write_failures += 1;
                let kept = written.frame.map_or(String::new(), |f| {
                    format!("; frame {f} is kept in memory until it is written")
                });
                let error = format!("{error}{kept}");
                self.telemetry.last_journal_error = Some(error.clone());
                (self.kept.failed_writes).insert(written.job, error.clone());
                let submitters = (self.jobs.get(&written.job)).map(|j| j.submitters.clone());
                let message = Message::JournalFailed {
                    job: written.job,
                    error,
                };
                self.send_to(&submitters.unwrap_or_default(), message);
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
        job: u64,
        frame: u32,
        error: String,
    ) {
        self.now = now;
        warn!(job, frame, "a finished frame cannot be read back: {error}");
        if let Some(done) = self.kept.unjournaled.get(&(job, frame)).cloned() {
            self.send(conn, Message::FrameDone(done));
            return self.pump();
        }
        let running = (self.kept.repairs.iter()).find(|(_, owned)| **owned == (job, frame));
        if let Some((&repair, _)) = running {
            if let Some(j) = self.jobs.get_mut(&repair) {
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
    fn render_again(
        &mut self,
        now: Duration,
        conn: ConnId,
        job: u64,
        frame: u32,
    ) -> Result<(), String> {
        let mut definition = (self.kept.definitions.get(&job).cloned())
            .ok_or_else(|| format!("the master no longer keeps job {job}"))?;
        let setup = (definition.frames.get(frame as usize).cloned())
            .ok_or_else(|| format!("job {job} has no frame {frame}"))?;
        definition.frames = vec![setup];
        definition.name = format!("{} (frame {frame} again)", definition.name);
        let id = self.next_job;
        self.queue_job(now, id, definition, BTreeSet::from([conn]), 0)
            .map_err(|e| e.to_string())?;
        self.next_job += 1;
        self.kept.repairs.insert(id, (job, frame));
        info!(job, frame, repair = id, "rendering a finished frame again");
        Ok(())
    }

    pub fn telemetry(&self) -> &Telemetry {
        &self.telemetry
    }

    /// The packages each worker (by name) is working on now.
    pub fn packages_by_worker(&self) -> BTreeMap<String, Vec<u64>> {
        self.packages_by_worker_where(|_| true)
    }

    /// The packages of job `job` each worker (by name) is working on now
    /// (several jobs run at once).
    pub fn job_packages_by_worker(&self, job: u64) -> BTreeMap<String, Vec<u64>> {
        self.packages_by_worker_where(|p| p.job == job)
    }

    fn packages_by_worker_where(
        &self,
        keep: impl Fn(&InFlight) -> bool,
    ) -> BTreeMap<String, Vec<u64>> {
        let mut by_worker: BTreeMap<String, Vec<u64>> = BTreeMap::new();
        for (&id, p) in self.packages.iter().filter(|(_, p)| keep(p)) {
            by_worker
                .entry(self.worker_name(p.worker))
                .or_default()
                .push(id);
        }
        by_worker
    }

    /// The frame being assembled of the first running job (in the order
    /// jobs get workers) that assembles one: job, frame index, reflector
    /// triangles done, and its image so far (base frame with the results
    /// composited).
    pub fn live_frame(&self) -> Option<LiveFrame<'_>> {
        (self.scheduler.queue().running.iter()).find_map(|running| {
            let job = self.jobs.get(&running.job.0)?;
            // Nothing to show until the base frame is there.
            let current = job.assembly(running.frame).filter(|c| c.ids.is_some())?;
            Some(LiveFrame {
                job: running.job.0,
                frame: current.start.frame,
                triangles_done: current.triangles_done,
                triangles_total: job.reflectors.len() as u64,
                image: current.image.color(),
            })
        })
    }

    /// A worker's name (its connection number if it is gone).
    fn worker_name(&self, conn: ConnId) -> String {
        match self.peers.get(&conn) {
            Some(Peer::Worker { name, .. }) => name.clone(),
            _ => format!("connection {conn}"),
        }
    }

    /// The farm's state for `vtfarm status`.
    pub fn status(&self) -> StatusReply {
        let workers = self
            .scheduler
            .workers()
            .into_iter()
            .filter(|w| w.state != WorkerState::Gone)
            .filter_map(|w| {
                let Some(Peer::Worker { name, address, .. }) = self.peers.get(&w.worker.0) else {
                    return None;
                };
                Some(WorkerStatus {
                    name: name.clone(),
                    address: address.clone(),
                    threads: w.threads,
                    state: format!("{:?}", w.state).to_lowercase(),
                    throughput: w.rate.unwrap_or(0.0),
                    packages_running: w.running as u32,
                    packages_done: w.packages_done,
                    triangles_done: w.items_done,
                    failures: w.failures,
                    busy_micros: w.busy.as_micros() as u64,
                })
            })
            .collect();
        let queue = self.scheduler.queue();
        // Progress in reflector triangles, as `Message::Progress` counts it
        // (work items are reflector groups for per-reflector methods).
        let running = (queue.running.iter())
            .map(|p| {
                let job = self.jobs.get(&p.job.0);
                RunningJob {
                    job: p.job.0,
                    name: job.map(|j| j.name.clone()).unwrap_or_default(),
                    frame: p.frame,
                    frames: p.frames,
                    triangles_done: (job.and_then(|j| j.assembly(p.frame)))
                        .map_or(0, |c| c.triangles_done),
                    triangles_total: job.map_or(0, |j| j.reflectors.len() as u64),
                }
            })
            .collect();
        StatusReply {
            workers,
            queue: QueueStatus {
                waiting: queue.waiting.iter().map(|j| j.0).collect(),
                running,
            },
            scene_bytes_sent: self.scene_bytes_sent,
        }
    }
}

/// A timeline phase from `start` to `end`, in microseconds from `t0`.
/// Checks a whole frame's finished image (and components) against what
/// its job asks for: the frame's size, the job's format, components when
/// the job asks for them, linear and of the frame's size. The compressed
/// bytes themselves are the submitter's to decode: its decoder
/// decompresses into exactly the size the sides imply.
/// The index of the next frame of `j` to start: frames start and complete
/// in order.
fn next_to_start(j: &Job) -> u32 {
    let assembling = j.assembling.iter().map(|a| a.start.frame + 1).max();
    let finishing = j.finishing.last_frame().map(|f| f + 1);
    (assembling.max(finishing)).unwrap_or(j.frames_done)
}

fn check_finished(
    job: &Job,
    frame: u32,
    image: WireImage,
    aux: Option<WireFrameAux>,
) -> Result<(WireImage, Option<WireFrameAux>), ResultRejected> {
    let camera = job.frames.get(frame as usize).map(|setup| setup.camera);
    let expected = camera.map_or((0, 0), |c| (c.width, c.height));
    let mismatch = |what, found: String, expected: String| {
        Err(ResultRejected::FinishedFrameMismatch {
            what,
            found,
            expected,
        })
    };
    let size = |image: &WireImage| (image.width, image.height);
    let show = |(w, h): (u32, u32)| format!("{w}x{h}");
    if size(&image) != expected {
        return mismatch("size", show(size(&image)), show(expected));
    }
    if image.format != job.image {
        return mismatch(
            "format",
            format!("{:?}", image.format),
            format!("{:?}", job.image),
        );
    }
    match &aux {
        Some(_) if !job.aux => return mismatch("components", "sent".into(), "none".into()),
        None if job.aux => return mismatch("components", "none".into(), "asked for".into()),
        Some(aux) => {
            for component in [&aux.reflected, &aux.transmitted] {
                if size(component) != expected || component.format != WireImageFormat::LinearF32 {
                    let found = format!("{} {:?}", show(size(component)), component.format);
                    let wanted = format!("{} LinearF32", show(expected));
                    return mismatch("component image", found, wanted);
                }
            }
        }
        None => {}
    }
    Ok((image, aux))
}

fn phase(t0: Duration, who: String, kind: PhaseKind, start: Duration, end: Duration) -> FramePhase {
    let micros = |t: Duration| t.saturating_sub(t0).as_micros() as u64;
    FramePhase {
        who,
        kind,
        start_micros: micros(start),
        end_micros: micros(end),
    }
}

/// The frame being assembled, borrowed from the core.
pub struct LiveFrame<'a> {
    pub job: u64,
    pub frame: u32,
    pub triangles_done: u64,
    pub triangles_total: u64,
    pub image: &'a vtfarm_imaging::Image,
}

/// How logs and statistics name a peer.
fn peer_name(conn: ConnId, peer: Option<&Peer>) -> String {
    match peer {
        Some(Peer::Worker { name, address, .. }) => format!("{name} ({address})"),
        Some(Peer::Submitter { address }) => format!("submitter ({address})"),
        None => format!("connection {conn}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An image with a different colour in (nearly) every pixel, by `seed`.
    fn gradient(width: u32, height: u32, seed: f32) -> Image {
        let pixels = (0..width * height)
            .map(|i| {
                let (x, y) = ((i % width) as f32, (i / width) as f32);
                Vec3::new(x / width as f32, y / height as f32, seed) * (1.0 + seed)
            })
            .collect();
        Image {
            width,
            height,
            pixels,
        }
    }

    /// Pixels of `rect` a result writes: every other one, in `seed`'s colour.
    fn written_pixels(rect: PixelRect, seed: f32) -> Vec<(u32, u32, Vec3)> {
        (rect.pixels())
            .filter(|(x, y)| (x + y) % 2 == 0)
            .map(|(x, y)| (x, y, Vec3::new(seed, 1.0 - seed, 0.5 * seed)))
            .collect()
    }

    /// A result over `rect` in the form a frame of `components` composites.
    fn result(width: u32, rect: PixelRect, seed: f32, components: bool) -> ResultPixels {
        let written = written_pixels(rect, seed);
        if !components {
            let colors = (written.iter())
                .map(|&(x, y, c)| ((y * width + x) as usize, c))
                .collect();
            return ResultPixels::Colors {
                bounds: rect,
                colors,
            };
        }
        let mask = (rect.pixels()).map(|(x, y)| (x + y) % 2 == 0).collect();
        let n = written.len();
        ResultPixels::Bitmap(SparseBitmap {
            x0: rect.x0,
            y0: rect.y0,
            width: rect.x1 - rect.x0,
            height: rect.y1 - rect.y0,
            mask,
            color: written.iter().map(|&(_, _, c)| c).collect(),
            reflected: vec![Vec3::splat(0.1); n],
            transmitted: vec![Vec3::splat(0.2); n],
            reflected_object: vec![3; n],
        })
    }

    /// A frame whose base frame was converted to sRGB ahead, in a buffer
    /// that held another frame's bytes, encodes to exactly the bytes of
    /// its composited image converted whole: the written rectangle holds
    /// every composited pixel, and the base's conversion left nothing of
    /// the other frame. Colour-only frames and frames with components,
    /// results far apart and none.
    #[test]
    fn a_frame_converted_ahead_encodes_as_its_whole_conversion() {
        let (width, height) = (97, 61);
        let rect = |x0, y0, x1, y1| PixelRect { x0, y0, x1, y1 };
        let results = [
            rect(3, 4, 20, 9),
            rect(60, 40, 97, 61),
            rect(10, 50, 12, 52),
        ];
        for components in [false, true] {
            for count in 0..=results.len() {
                let mut srgb = SrgbBytes::default();
                // Another frame's bytes, larger: converted over.
                srgb.convert_base(&gradient(width + 5, height, 0.9));
                let image = gradient(width, height, 0.1);
                srgb.convert_base(&image);
                let ids = IdBuffer::new(width, height);
                let base = BaseFrame { image, ids, srgb };
                let bounds = components.then_some(rect(0, 0, width, height));
                let (mut assembled, _) = Assembled::new(base, bounds);
                for (k, &r) in results.iter().take(count).enumerate() {
                    assembled.composite(&result(width, r, 0.3 * k as f32, components));
                }
                let expected = WireImage::encode(assembled.color(), WireImageFormat::Srgb8);
                let request = FrameEncodeRequest {
                    job: 1,
                    frame: 0,
                    image: assembled,
                    format: WireImageFormat::Srgb8,
                    delivered: true,
                    scratch: Vec::new(),
                };
                assert!(request.converts_written_pixels_only());
                let encoded = request.encode();
                assert!(
                    encoded.image == expected,
                    "components {components}, {count} results: other bytes"
                );
            }
        }
    }

    /// A job whose frames do not go out in sRGB has no bytes converted
    /// ahead: its frames are encoded whole, as before, in its format.
    #[test]
    fn a_frame_not_converted_ahead_is_encoded_whole() {
        let (width, height) = (31, 17);
        let base = BaseFrame {
            image: gradient(width, height, 0.4),
            ids: IdBuffer::new(width, height),
            srgb: SrgbBytes::default(),
        };
        let (mut assembled, _) = Assembled::new(base, None);
        let written = PixelRect {
            x0: 2,
            y0: 3,
            x1: 9,
            y1: 8,
        };
        assembled.composite(&result(width, written, 0.7, false));
        for format in [WireImageFormat::Srgb8, WireImageFormat::LinearF32] {
            let pixels = AssembledPixels::Color(assembled.color().clone());
            let expected = WireImage::encode(pixels.color(), format);
            let request = FrameEncodeRequest {
                job: 1,
                frame: 0,
                image: Assembled {
                    pixels,
                    written,
                    srgb: SrgbBytes::default(),
                },
                format,
                delivered: true,
                scratch: vec![0xab; 7],
            };
            assert!(!request.converts_written_pixels_only());
            assert!(request.encode().image == expected, "{format:?}");
        }
    }
}
