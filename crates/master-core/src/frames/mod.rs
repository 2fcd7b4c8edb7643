//! Frame assembly and compositing: the jobs being rendered, their frames
//! as results are checked and composited, the packages in flight, the base
//! frames (made ahead, and the spare buffers they rasterize into) and the
//! finished frames on their way out, encoded off the driver's task. It
//! sends nothing: its methods return what the master tells the workers,
//! the submitters and the driver.
//!
//! - `job`: a job as rendered, checked once as it is queued.
//! - `assembly`: a frame's pixels, ownership check and timeline.
//! - `base`: base frames to rasterize, their sRGB bytes and spare buffers.
//! - `ahead`: base frames made ahead of a batch job's tail.
//! - `finish`: finished frames encoded and delivered in order.

pub(crate) mod ahead;
pub(crate) mod assembly;
pub(crate) mod base;
pub(crate) mod finish;
pub(crate) mod job;

use std::collections::BTreeMap;
use std::time::Duration;
use vtfarm_proto::JobId;

use vtfarm_proto::{
    FramePhase, FrameStart, FrameStats, Message, Package, PackageResult, PhaseKind, ResultPixels,
    WireImageFormat, WirePackageStats, WireQuality, WorkerFrameStats, encoded_len,
};
use vtfarm_render::components_bounds;
use vtfarm_scene::TriangleId;
use vtfarm_scheduler::{Assignment, PackageMeasure};
use vtfarm_vertex::{PackageStats, Quality};

use crate::error::ResultRejected;
use crate::peers::ConnId;
use crate::stages::{StageProgress, StageRejected, StageWork};
use crate::view::Views;
use ahead::{Bases, frames_held_at_most};
use assembly::{Accepted, Assembled, FrameAssembly, phase};
use base::{BaseFrame, BaseFrameRequest, Spares};
use finish::{EncodedFrame, FinishedFrame, Finishing, FrameEncodeRequest};
use job::Job;

/// A package on its way: what the results must be matched against.
pub(crate) struct InFlight {
    pub(crate) job: JobId,
    /// The connection of the worker it went to.
    pub(crate) worker: ConnId,
    pub(crate) frame: u32,
    /// Its frame's every item, to come back finished.
    pub(crate) whole: bool,
    /// The reflector triangles its items cover, sorted: for progress and
    /// pixel ownership.
    pub(crate) triangles: Vec<TriangleId>,
    /// Size of the `Package` message, for the statistics.
    pub(crate) bytes_in: u64,
    /// When it was handed out, or when its last result (a progressive
    /// frame's stage) arrived: where the next result's phases start on
    /// the timeline.
    pub(crate) last_result_at: Duration,
}

/// A frame just started ([`Frames::start_frame`]): what goes out.
pub(crate) struct StartedFrame {
    /// Its start, for the workers (none for a whole frame: its set-up goes
    /// with its package).
    pub(crate) start: Option<FrameStart>,
    /// Its job's submitters' first progress report.
    pub(crate) progress: Message,
    /// The base frame to ask the driver for (a split frame's, unless made
    /// ahead or coming).
    pub(crate) rasterize: Option<BaseFrameRequest>,
}

/// Where a base frame the driver handed back goes ([`Frames::base_ready`]).
#[derive(Debug)]
pub(crate) enum BaseUse {
    /// Its frame waits for it: the caller hands it to [`Frames::use_base`].
    Waiting(BaseFrame),
    /// Made ahead: kept for its frame's start.
    Ahead,
    /// Nobody needs it: its buffers are kept for a later one.
    Spared,
    /// Its job ended meanwhile: its buffers are kept for a later one.
    JobGone,
}

/// The frames being rendered: see the module's documentation.
#[derive(Default)]
pub(crate) struct Frames {
    pub(crate) jobs: BTreeMap<JobId, Job>,
    pub(crate) packages: BTreeMap<u64, InFlight>,
    /// Finished frames' buffers for the next base frames.
    spares: Spares,
    /// Base frames in the making and made ahead of a batch job's tail.
    bases: Bases,
    /// The last finished frame's uncompressed bytes, the next one's buffer
    /// (where its base frame's sRGB bytes were not converted ahead).
    frame_bytes: Vec<u8>,
}

impl Frames {
    /// Drops a job that ended, with its packages still in flight and its
    /// base frames made ahead.
    pub(crate) fn forget_job(&mut self, job: JobId) -> Option<Job> {
        self.packages.retain(|_, p| p.job != job);
        self.bases.forget(job);
        self.jobs.remove(&job)
    }

    /// Package `id` no longer runs on `worker` (it failed there, or the
    /// worker was lost): it leaves the packages in flight unless another
    /// worker runs it now.
    pub(crate) fn drop_in_flight(&mut self, id: u64, worker: ConnId) {
        if self.packages.get(&id).is_some_and(|p| p.worker == worker) {
            self.packages.remove(&id);
        }
    }

    /// Keeps a base frame's buffers (or a finished frame's) for a later
    /// base frame.
    pub(crate) fn spare(&mut self, base: BaseFrame) {
        self.spares.keep(base);
    }

    /// Starts assembling frame `frame` of `job` at `now`: what goes out, or
    /// `None` for a job or frame it does not have. A base frame made
    /// ahead is used at once (through [`Frames::use_base`]: the caller gets
    /// no held results from a frame just started).
    pub(crate) fn start_frame(
        &mut self,
        job: JobId,
        frame: u32,
        whole: bool,
        now: Duration,
    ) -> Option<StartedFrame> {
        let j = self.jobs.get_mut(&job)?;
        j.frames.get(frame as usize)?;
        // Made ahead, or coming: no base frame asked for again.
        let key = (job, frame);
        let ahead = self.bases.take(key);
        let coming = self.bases.making_ahead(key);
        let rasterize = (!whole && ahead.is_none() && !coming)
            .then(|| j.base_request(job, frame, self.spares.take()));
        let start = j.frame_start(job, frame);
        let progress =
            (j.stages.len() > 1).then(|| StageProgress::new(j.stages.clone(), &j.reflectors));
        j.assembling
            .push(FrameAssembly::new(start.clone(), whole, now, progress));
        let progress = Message::Progress {
            job,
            frame,
            done: 0,
            total: j.reflectors.len() as u32,
        };
        if rasterize.is_some() {
            self.bases.requested(key, now, false);
        }
        match ahead {
            Some(base) if !whole => {
                let held = self.use_base(job, frame, base, now);
                debug_assert!(held.is_empty(), "a frame just started holds no results");
            }
            Some(base) => self.spare(base),
            None => {}
        }
        Some(StartedFrame {
            start: (!whole).then_some(start),
            progress,
            rasterize,
        })
    }

    /// The next base frame of `job`'s last frames to make ahead of their
    /// start (`ahead.rs`): one at a time, while its whole frames run, for
    /// as many of its last frames (no more than `workers`) as the base
    /// frames held, with those of the split frames being assembled, stay
    /// within the budget ([`frames_held_at_most`] with `frames_in_flight`).
    pub(crate) fn base_ahead(
        &mut self,
        job: JobId,
        frames_in_flight: usize,
        workers: usize,
        now: Duration,
    ) -> Option<BaseFrameRequest> {
        let j = (self.jobs.get(&job)).filter(|j| j.assembling.iter().any(|a| a.whole))?;
        let camera = j.frames.last().map(|setup| setup.camera)?;
        let budget = frames_held_at_most(frames_in_flight, camera.width, camera.height);
        let assembling = (self.jobs.values().flat_map(|j| &j.assembling))
            .filter(|a| !a.whole)
            .count();
        if self.bases.any_making_ahead() || self.bases.held() + assembling >= budget {
            return None;
        }
        let tail = budget.min(workers) as u32;
        let frames = j.frames.len() as u32;
        let first = j.next_to_start().max(frames.saturating_sub(tail));
        let frame = (first..frames).find(|&f| !self.bases.has((job, f)))?;
        let request = j.base_request(job, frame, self.spares.take());
        self.bases.requested((job, frame), now, true);
        Some(request)
    }

    /// The driver handed back the base frame of `job`'s frame `frame` at
    /// `now`: how long it took when it was made alone (the master's time
    /// per base frame), and where it goes.
    pub(crate) fn base_ready(
        &mut self,
        job: JobId,
        frame: u32,
        base: BaseFrame,
        now: Duration,
    ) -> (Option<Duration>, BaseUse) {
        let key = (job, frame);
        let cost = self.bases.arrived(key, now);
        let Some(j) = self.jobs.get(&job) else {
            self.spare(base);
            return (cost, BaseUse::JobGone);
        };
        let waiting = (j.assembly(frame)).is_some_and(|c| c.ids.is_none() && !c.whole);
        let used = if waiting {
            BaseUse::Waiting(base)
        } else if frame >= j.next_to_start() {
            self.bases.keep(key, base);
            BaseUse::Ahead
        } else {
            self.spare(base);
            BaseUse::Spared
        };
        (cost, used)
    }

    /// A split frame's base frame is here at `now`: the frame starts from
    /// it, and the results held for it are returned to be checked now.
    pub(crate) fn use_base(
        &mut self,
        job: JobId,
        frame: u32,
        base: BaseFrame,
        now: Duration,
    ) -> Vec<(ConnId, PackageResult, u64)> {
        let Some(j) = self.jobs.get_mut(&job) else {
            return Vec::new();
        };
        // The components' planes cover the reflectors' rectangle only.
        let components = match j.frames.get(frame as usize) {
            Some(setup) if j.aux => {
                Some(components_bounds(&j.scene, &setup.camera, &j.is_reflector))
            }
            _ => None,
        };
        let Some(current) = j
            .assembly_mut(frame)
            .filter(|c| c.ids.is_none() && !c.whole)
        else {
            return Vec::new();
        };
        // Nothing is composited yet: the image starts as the base frame.
        let (image, ids) = Assembled::new(base, components);
        current.based(image, ids, now);
        std::mem::take(&mut current.held)
    }

    /// A result arrived at `now` from the worker named `name`: its
    /// package's frame gets the result's phases on its timeline.
    pub(crate) fn record_package(&mut self, name: String, result: &PackageResult, now: Duration) {
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
        current.record_package(name, assigned_at, now, result);
    }

    /// Turns the scheduler's assignment into the `Package` for its worker,
    /// kept in flight from `now`; first the frame's start again when the
    /// worker does not keep a split frame (`kept`).
    pub(crate) fn assign(
        &mut self,
        a: Assignment,
        kept: bool,
        now: Duration,
    ) -> (Option<Message>, Message) {
        let job = self.jobs.get(&a.job);
        let triangles = job.map_or_else(Vec::new, |j| j.triangles_in(&a.items));
        let whole = (job.and_then(|j| j.assembly(a.frame)))
            .filter(|_| a.whole)
            .map(|assembly| Box::new(assembly.start.clone()));
        let again = (job.and_then(|j| j.assembly(a.frame)))
            .filter(|_| !kept && !a.whole)
            .map(|assembly| Message::FrameStart(assembly.start.clone()));
        let message = Message::Package(Package {
            id: a.package.0,
            job: a.job,
            frame: a.frame,
            triangles: a.items,
            whole,
        });
        let in_flight = InFlight {
            job: a.job,
            worker: ConnId::of_worker(a.worker),
            frame: a.frame,
            whole: a.whole,
            triangles,
            bytes_in: encoded_len(&message),
            last_result_at: now,
        };
        self.packages.insert(a.package.0, in_flight);
        (again, message)
    }

    /// Records an encoded frame with its job's finished frames: whether a
    /// frame waited for it (none does when its job ended meanwhile).
    pub(crate) fn frame_encoded(&mut self, encoded: EncodedFrame) -> bool {
        let (taken, scratch) = match self.jobs.get_mut(&encoded.job) {
            Some(j) => j.finishing.encoded(encoded),
            None => (false, encoded.scratch),
        };
        if self.frame_bytes.is_empty() {
            self.frame_bytes = scratch;
        }
        taken
    }

    /// The split frames' starts of every job assembling one, with each
    /// job's scene: what a worker joining now needs.
    pub(crate) fn catch_up(&self) -> Vec<Message> {
        (self.jobs.iter())
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
            .collect()
    }

    /// The packages in flight that `keep` keeps, by worker (named by
    /// `name`).
    pub(crate) fn packages_by_worker(
        &self,
        keep: impl Fn(&InFlight) -> bool,
        name: impl Fn(ConnId) -> String,
    ) -> BTreeMap<String, Vec<u64>> {
        let mut by_worker: BTreeMap<String, Vec<u64>> = BTreeMap::new();
        for (&id, p) in self.packages.iter().filter(|(_, p)| keep(p)) {
            by_worker.entry(name(p.worker)).or_default().push(id);
        }
        by_worker
    }

    /// Where package `id`'s result stands.
    pub(crate) fn arrival(&self, id: u64) -> Arrival {
        let Some(in_flight) = self.packages.get(&id) else {
            return Arrival::UnknownPackage;
        };
        let job = self.jobs.get(&in_flight.job);
        match job.and_then(|j| j.assembly(in_flight.frame)) {
            None => Arrival::FrameGone,
            Some(current) if !in_flight.whole && current.ids.is_none() => Arrival::AwaitingBase,
            Some(_) => Arrival::Ready,
        }
    }

    /// Holds a result from `conn` (of `bytes` on the wire) until its
    /// frame's base frame is here ([`Arrival::AwaitingBase`]).
    pub(crate) fn hold(&mut self, conn: ConnId, result: PackageResult, bytes: u64) {
        let Some(in_flight) = self.packages.get(&result.id) else {
            return;
        };
        let frame = in_flight.frame;
        if let Some(current) =
            (self.jobs.get_mut(&in_flight.job)).and_then(|j| j.assembly_mut(frame))
        {
            current.held.push((conn, result, bytes));
        }
    }

    /// Checks package `id`'s result from `conn` ([`Arrival::Ready`]): its
    /// stage (a progressive frame's, the one its copy on `conn` is due to
    /// send; none for any other frame) and its pixels (pixel ownership
    /// for a split frame, the finished image for a whole one).
    pub(crate) fn check_result(
        &self,
        conn: ConnId,
        id: u64,
        pixels: ResultPixels,
        stage: Option<WireQuality>,
    ) -> Option<Result<(Option<usize>, Accepted), ResultRejected>> {
        let in_flight = self.packages.get(&id)?;
        let job = self.jobs.get(&in_flight.job)?;
        let current = job.assembly(in_flight.frame)?;
        let owned = |t| in_flight.triangles.binary_search(&t).is_ok();
        let stage = match (&current.progress, stage) {
            (Some(progress), stage) => progress.check(id, conn, stage.map(Quality::from)).map(Some),
            (None, None) => Ok(None),
            (None, Some(found)) => Err(StageRejected::OutOfOrder {
                found: Quality::from(found).name().to_owned(),
                expected: "none (a frame of one stage)".to_owned(),
            }),
        };
        let checked = stage.map_err(ResultRejected::from).and_then(|stage| {
            let accepted = match (pixels, in_flight.whole, current.ids.as_ref()) {
                (ResultPixels::Bitmap(bitmap), false, Some(ids)) => current
                    .image
                    .check(bitmap, ids, owned)
                    .map(Accepted::Composite),
                (ResultPixels::Frame { image, aux }, true, _) => job
                    .check_finished(in_flight.frame, image, aux)
                    .map(|(image, aux)| Accepted::Finished(image, aux)),
                (ResultPixels::Frame { .. }, false, _) => {
                    Err(ResultRejected::FinishedFrameForSplitPackage)
                }
                // A split package's result without its base frame is held.
                (ResultPixels::Bitmap(_), _, _) => Err(ResultRejected::PixelsForWholeFrame),
            };
            accepted.map(|accepted| (stage, accepted))
        });
        Some(checked)
    }

    /// Package `id`'s result from `conn` was refused: a progressive frame
    /// forgets the copy's stages.
    pub(crate) fn refused(&mut self, id: u64, conn: ConnId) {
        if let Some(progress) = self.assembly_of(id).and_then(|c| c.progress.as_mut()) {
            progress.forget_copy(id, conn);
        }
    }

    /// A progressive frame's checked stage `stage` of package `id` from
    /// `conn`, with its `work` and `stats`: the package's measure when it
    /// was its last stage.
    pub(crate) fn stage_in(
        &mut self,
        id: u64,
        conn: ConnId,
        stage: usize,
        work: StageWork<'_>,
        stats: &PackageStats,
    ) -> Option<PackageMeasure> {
        let bytes_in = self.packages.get(&id)?.bytes_in;
        let current = self.assembly_of(id)?;
        let progress = current.progress.as_mut()?;
        let last = progress.is_last(stage);
        let copy = progress.record(id, conn, work);
        let measure = last.then(|| PackageMeasure {
            busy: copy.busy,
            item_seconds: copy.samples.iter().map(|&s| s as f64 + 1.0).collect(),
            rays: copy.rays,
            bytes_in,
            bytes_out: copy.bytes_out,
        });
        current.totals.add(stats);
        measure
    }

    /// Package `id`'s result was accepted (the scheduler took it done):
    /// its stats count in its frame and its pixels are composited (or its
    /// whole frame's image kept).
    pub(crate) fn accept(
        &mut self,
        job: JobId,
        frame: u32,
        stats: &PackageStats,
        accepted: Accepted,
    ) {
        let Some(current) = self.jobs.get_mut(&job).and_then(|j| j.assembly_mut(frame)) else {
            return;
        };
        current.totals.add(stats);
        match accepted {
            Accepted::Composite(pixels) => current.image.composite(&pixels),
            Accepted::Finished(image, aux) => current.finished = Some((image, aux)),
        }
    }

    /// Package `id` is done: it leaves the packages in flight and its
    /// triangles count in its frame's progress. The package, and the
    /// progress report for its job's submitters (when its frame is still
    /// assembled).
    pub(crate) fn package_done(&mut self, id: u64) -> Option<(InFlight, Option<Message>)> {
        let in_flight = self.packages.remove(&id)?;
        let Some(job) = self.jobs.get_mut(&in_flight.job) else {
            return Some((in_flight, None));
        };
        let total = job.reflectors.len() as u32;
        let Some(current) = job.assembly_mut(in_flight.frame) else {
            return Some((in_flight, None));
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
        Some((in_flight, Some(progress)))
    }

    /// A checked stage `stage` of package `id` of a progressive frame (its
    /// job and index), at `now`: composited in place or held (`stages.rs`);
    /// a stage complete now goes on view in `views`, and on the frame's
    /// timeline.
    pub(crate) fn stage_arrived(
        &mut self,
        (job_id, frame): (JobId, u32),
        stage: usize,
        id: u64,
        pixels: assembly::ResultPixels,
        views: &mut Views,
        now: Duration,
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
        let (scene, t0) = (&job.scene, *started);
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
    }

    /// The scheduler completed frame `(job, frame)` (with `stats`, its
    /// workers named by `name`): it leaves assembly for its job's finished
    /// frames, to be encoded (the request returned, for a split frame) and
    /// told in order. A frame of one stage with components goes on view
    /// (a progressive frame's stages went as they came). `journaled`: the
    /// journal keeps it. `None` when it is not assembled.
    pub(crate) fn complete_frame(
        &mut self,
        (job, frame): (JobId, u32),
        stats: &vtfarm_scheduler::FrameStats,
        name: impl Fn(ConnId) -> String,
        journaled: bool,
        views: &mut Views,
        now: Duration,
    ) -> Option<Option<FrameEncodeRequest>> {
        let j = self.jobs.get_mut(&job)?;
        let index = j.assembling.iter().position(|a| a.start.frame == frame)?;
        let mut done = j.assembling.remove(index);
        if let (Some(image), None) = (done.image.components(), &done.progress) {
            views.stage_finished(job, frame as usize, image, &j.scene, now);
        }
        let workers = (stats.workers.iter())
            .map(|w| WorkerFrameStats {
                name: name(ConnId::of_worker(w.worker)),
                busy_micros: w.busy.as_micros() as u64,
                packages: w.packages,
                triangles: w.items,
                rays: w.rays,
                bytes_in: w.bytes_in,
                bytes_out: w.bytes_out,
            })
            .collect();
        let frame_stats = FrameStats {
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
        // Encoded (and compressed) once, off the driver or by a whole
        // frame's worker: the journal and the submitter get the same
        // bytes. A frame nobody receives or keeps (a view's: the view
        // holds its stages) goes only to the dashboard's list, in 8 bits,
        // without components: its encoding is no part of the view's latency.
        let delivered = !j.submitters.is_empty() || journaled;
        let format = if delivered {
            j.image
        } else {
            WireImageFormat::Srgb8
        };
        let encoded = done.finished.take();
        let request = encoded.is_none().then(|| FrameEncodeRequest {
            job,
            frame,
            image: done.image,
            format,
            delivered,
            scratch: std::mem::take(&mut self.frame_bytes),
        });
        let finished = FinishedFrame {
            frame,
            stats: frame_stats,
            ids: done.ids,
            encoded,
            buffers: None,
        };
        j.finishing.push(Finishing::Frame(Box::new(finished)));
        Some(request)
    }

    /// The frame package `id` belongs to, while it is assembled.
    fn assembly_of(&mut self, id: u64) -> Option<&mut FrameAssembly> {
        let in_flight = self.packages.get(&id)?;
        let frame = in_flight.frame;
        self.jobs.get_mut(&in_flight.job)?.assembly_mut(frame)
    }
}

/// Where a package's result stands ([`Frames::arrival`]).
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum Arrival {
    /// No such package in flight (done, failed or its job gone).
    UnknownPackage,
    /// Its frame is no longer assembled.
    FrameGone,
    /// Its split frame's base frame is being rasterized: held until then.
    AwaitingBase,
    /// To check now.
    Ready,
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeSet;

    use vtfarm_scheduler::{JobId, PackageId};

    use super::*;
    use crate::testkit;

    const MS: Duration = Duration::from_millis(1);

    /// Frames holding job 1 of `frames` frames of the test square.
    fn frames_with_job(frames: usize) -> Frames {
        let (job, scene, hash) = testkit::job(frames);
        let (job, _) = Job::checked(job, scene, hash, BTreeSet::from([ConnId(9)]), 0).unwrap();
        let mut all = Frames::default();
        all.jobs.insert(JobId(1), job);
        all
    }

    fn assignment(package: u64, worker: u64, frame: u32, whole: bool) -> Assignment {
        Assignment {
            worker: ConnId(worker).worker(),
            package: PackageId(package),
            job: JobId(1),
            frame,
            items: vec![0, 1],
            estimated_cost: 1.0,
            expected: MS,
            duplicate: false,
            whole,
        }
    }

    fn result(id: u64) -> PackageResult {
        PackageResult {
            id,
            pixels: ResultPixels::Bitmap(Default::default()),
            stats: Default::default(),
            busy_micros: 0,
            setup_micros: 0,
            triangle_samples: vec![1, 1],
            stage: None,
            mesh: None,
        }
    }

    /// A split frame asks the driver for its base frame and the workers
    /// hear of it; a whole frame does neither (its set-up goes with its
    /// package).
    #[test]
    fn a_split_frame_asks_for_its_base_frame_and_a_whole_one_does_not() {
        let mut frames = frames_with_job(2);
        let split = frames.start_frame(JobId(1), 0, false, MS).unwrap();
        assert!(split.start.is_some());
        assert!(
            split
                .rasterize
                .is_some_and(|r| (r.job, r.frame) == (JobId(1), 0))
        );
        let whole = frames.start_frame(JobId(1), 1, true, MS).unwrap();
        assert!(whole.start.is_none() && whole.rasterize.is_none());
        assert!(
            frames.start_frame(JobId(1), 2, false, MS).is_none(),
            "no frame 2"
        );
        assert!(
            frames.start_frame(JobId(2), 0, false, MS).is_none(),
            "no job 2"
        );
        let (again, package) = frames.assign(assignment(5, 3, 1, true), false, MS);
        assert!(again.is_none(), "a whole frame's start goes in its package");
        assert!(matches!(package, Message::Package(p) if p.whole.is_some()));
    }

    /// Results that come before their frame's base frame are held and
    /// handed back, in order, when it is here.
    #[test]
    fn results_before_the_base_frame_are_held_until_it_is_here() {
        let mut frames = frames_with_job(1);
        let request = frames
            .start_frame(JobId(1), 0, false, MS)
            .unwrap()
            .rasterize
            .unwrap();
        let (again, _) = frames.assign(assignment(5, 3, 0, false), false, MS);
        assert!(again.is_some(), "a worker that does not keep the frame");
        frames.assign(assignment(6, 4, 0, false), true, MS);
        assert_eq!(frames.arrival(5), Arrival::AwaitingBase);
        frames.hold(ConnId(3), result(5), 10);
        frames.hold(ConnId(4), result(6), 20);
        let (cost, used) = frames.base_ready(JobId(1), 0, request.rasterize(), 5 * MS);
        assert_eq!(cost, Some(4 * MS), "made alone: the master's time");
        let BaseUse::Waiting(base) = used else {
            panic!("the frame waits for its base frame");
        };
        let held = frames.use_base(JobId(1), 0, base, 5 * MS);
        let held: Vec<_> = held
            .iter()
            .map(|(conn, r, bytes)| (conn.0, r.id, *bytes))
            .collect();
        assert_eq!(held, [(3, 5, 10), (4, 6, 20)]);
        assert_eq!(frames.arrival(5), Arrival::Ready);
        assert_eq!(frames.arrival(8), Arrival::UnknownPackage);
    }

    /// A package leaves the packages in flight when the worker it runs on
    /// drops it (not when another worker's copy fails), when done, and
    /// with its job.
    #[test]
    fn a_package_in_flight_goes_with_its_worker_its_result_or_its_job() {
        let mut frames = frames_with_job(1);
        frames.start_frame(JobId(1), 0, false, MS);
        for (package, worker) in [(5, 3), (6, 4), (7, 4)] {
            frames.assign(assignment(package, worker, 0, false), true, MS);
        }
        frames.drop_in_flight(5, ConnId(4));
        assert!(frames.packages.contains_key(&5), "it runs on worker 3");
        frames.drop_in_flight(5, ConnId(3));
        assert!(!frames.packages.contains_key(&5));
        let (done, progress) = frames.package_done(6).unwrap();
        assert_eq!(done.triangles, [0, 1].map(TriangleId));
        assert!(matches!(
            progress,
            Some(Message::Progress {
                done: 2,
                total: 2,
                ..
            })
        ));
        let by_worker = frames.packages_by_worker(|_| true, |conn| format!("w{conn}"));
        assert_eq!(by_worker, BTreeMap::from([("w4".to_owned(), vec![7])]));
        assert!(frames.forget_job(JobId(1)).is_some());
        assert!(frames.packages.is_empty());
        assert_eq!(frames.arrival(7), Arrival::UnknownPackage);
    }

    /// A base frame whose job ended, or whose frame is past, only lends
    /// its buffers to the next one.
    #[test]
    fn a_base_frame_nobody_waits_for_is_kept_as_spare_buffers() {
        let mut frames = frames_with_job(1);
        let request = frames
            .start_frame(JobId(1), 0, false, MS)
            .unwrap()
            .rasterize
            .unwrap();
        let base = request.clone().rasterize();
        frames.forget_job(JobId(1));
        let (_, used) = frames.base_ready(JobId(1), 0, base, 2 * MS);
        assert!(matches!(used, BaseUse::JobGone));
        let mut frames = frames_with_job(1);
        let again = frames
            .start_frame(JobId(1), 0, false, MS)
            .unwrap()
            .rasterize
            .unwrap();
        assert!(!again.reuses_buffers());
        assert!(
            frames
                .complete_frame(
                    (JobId(1), 0),
                    &Default::default(),
                    |_| String::new(),
                    false,
                    &mut Views::default(),
                    MS,
                )
                .is_some()
        );
        let (_, used) = frames.base_ready(JobId(1), 0, request.rasterize(), 2 * MS);
        assert!(matches!(used, BaseUse::Spared), "its frame is past");
    }
}
