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
//!
//! It owns its parts and routes each input to them, one method per input
//! (and per kind of scheduler event); the parts know nothing of it:
//! [`Peers`] (connections), [`Frames`] (frame assembly and compositing),
//! [`Recovery`] (the journal's side) and `status` (status and live frames).

mod control;
mod events;
mod journal;
mod study;

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use tracing::{debug, info, warn};
use vtfarm_proto::{
    JobScene, Message, PackageResult, SceneData, SceneHash, StatusReply, WireJob, WireJobKind,
    WireStudy, encoded_len,
};
use vtfarm_scene::Scene;
use vtfarm_scheduler::{
    Assignment, Event, JobId, PackageId, PackageMeasure, QueueOptions, Scheduler,
};
use vtfarm_vertex::{PackageStats, Quality};

use crate::error::JobRejected;
use crate::frames::assembly::Accepted;
use crate::frames::base::BaseFrame;
use crate::frames::finish::EncodedFrame;
use crate::frames::job::Job;
use crate::frames::{Arrival, BaseUse, Frames};
use crate::jobs::{JobTable, Retention};
use crate::output::Output;
use crate::peers::{ConnId, Peer, Peers};
use crate::record::Record;
use crate::recovery::Recovery;
use crate::rules::FarmRules;
use crate::stages::StageWork;
use crate::status::{self, LiveFrame};
use crate::telemetry::Telemetry;
use crate::view::{ViewError, ViewFigures, ViewRequest, ViewSource, Views};

pub use vtfarm_proto::ATTACH_GRACE;

/// The master's state.
pub struct MasterCore {
    scheduler: Scheduler,
    /// Who is on each connection.
    peers: Peers,
    /// The scenes jobs use, parsed and as the wire carries them.
    scenes: BTreeMap<SceneHash, (Arc<Scene>, Arc<SceneData>)>,
    /// The jobs being rendered: frames assembled, packages in flight.
    frames: Frames,
    /// Submissions whose scene the master still has to receive.
    awaiting_scene: BTreeMap<ConnId, WireJob>,
    /// Studies whose scenes (these hashes) the master still has to receive.
    awaiting_scenes: BTreeMap<ConnId, (WireStudy, BTreeSet<SceneHash>)>,
    next_job: JobId,
    scene_bytes_sent: u64,
    outbox: VecDeque<Output>,
    telemetry: Telemetry,
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
    cancel_reasons: BTreeMap<JobId, String>,
    /// The journal's side of the core (whether it journals at all too).
    recovery: Recovery,
    /// The time of the input being handled.
    now: Duration,
    /// The interactive view: pickable scenes and the move being rendered.
    views: Views,
}

impl MasterCore {
    pub fn new(rules: FarmRules) -> Self {
        MasterCore {
            scheduler: Scheduler::new(rules.scheduler_config()),
            peers: Peers::default(),
            scenes: BTreeMap::new(),
            frames: Frames::default(),
            awaiting_scene: BTreeMap::new(),
            awaiting_scenes: BTreeMap::new(),
            next_job: JobId(1),
            scene_bytes_sent: 0,
            outbox: VecDeque::new(),
            telemetry: Telemetry::default(),
            table: JobTable::default(),
            retention: rules.retention,
            wall_origin_ms: 0,
            cancel_reasons: BTreeMap::new(),
            recovery: Recovery::new(false),
            now: Duration::ZERO,
            views: Views::default(),
        }
    }

    /// A core that journals its jobs (`Output::Persist`) and renders a job
    /// whose submitter went away to the end.
    pub fn persistent(rules: FarmRules) -> Self {
        MasterCore {
            recovery: Recovery::new(true),
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

    /// The next thing to do, if any.
    pub fn poll_output(&mut self) -> Option<Output> {
        self.outbox.pop_front()
    }

    /// When [`MasterCore::handle_timeout`] should run next.
    pub fn poll_timeout(&self) -> Option<Duration> {
        // A finished job too old to keep goes at its expiry.
        let expiry = (self.table.next_expiry(self.retention))
            .map(|ms| Duration::from_millis(ms.saturating_sub(self.wall_origin_ms)));
        // A kept frame is written again even while nothing else is.
        [
            self.scheduler.poll_timeout(),
            expiry,
            self.recovery.retry_at(),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    pub fn handle_timeout(&mut self, now: Duration) {
        self.now = now;
        self.scheduler.handle_timeout(now);
        self.forget_expired();
        if let Some(record) = self.recovery.retry_due(now) {
            self.outbox.push_back(Output::Persist(record));
        }
        self.pump();
    }

    /// Lets go of the finished jobs beyond [`Retention`]: their listing,
    /// their definition and their journaled frames.
    fn forget_expired(&mut self) {
        let now_ms = self.wall_ms(self.now);
        for id in self.table.expired(self.retention, now_ms) {
            debug!(job = %id, "finished job no longer kept");
            let variants = self.table.remove(id).map(|e| e.variants);
            self.persist(Record::JobForgotten { id });
            for variant in variants.unwrap_or_default() {
                self.table.remove(variant);
                self.persist(Record::JobForgotten { id: variant });
            }
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
            if let Err(e) = self.scheduler.worker_joined(now, conn.worker(), *threads) {
                self.close(conn, format!("cannot join: {e}"));
                return;
            }
            self.peers.joined(conn, peer);
            // A running frame: bring the newcomer up to date.
            for message in self.frames.catch_up() {
                self.send(conn, message);
            }
        } else {
            self.peers.joined(conn, peer);
        }
        self.pump();
    }

    /// A connection went away (closed, failed, or dropped by us).
    pub fn disconnected(&mut self, now: Duration, conn: ConnId) {
        self.now = now;
        match self.peers.left(conn) {
            Some(Peer::Worker { .. }) => {
                info!(worker = %self.peers.name(conn), "worker left");
                let _ = self.scheduler.worker_left(now, conn.worker());
            }
            Some(Peer::Submitter { .. }) => self.submitter_left(now, conn),
            None => {}
        }
        self.pump();
    }

    /// A submitter went away: a job nobody follows now renders on when it
    /// is journaled, else it is cancelled.
    fn submitter_left(&mut self, now: Duration, conn: ConnId) {
        self.awaiting_scene.remove(&conn);
        self.awaiting_scenes.remove(&conn);
        for (&job, j) in self.frames.jobs.iter_mut() {
            if !j.submitters.remove(&conn) || !j.submitters.is_empty() {
                continue; // not its, or others still follow it
            }
            if self.recovery.persistent() {
                // Its frames are journaled: it may come back (or attach
                // from elsewhere) and get them.
                info!(%job, "submitter left; the job renders on");
            } else {
                // Nobody is left to receive the images: stop its jobs.
                info!(%job, "submitter left, cancelling its job");
                let reason = "its submitter left (the embedded master keeps no frames)";
                self.cancel_reasons.insert(job, reason.into());
                let _ = self.scheduler.cancel_job(now, job);
            }
        }
    }

    /// A message arrived on a connection.
    pub fn message(&mut self, now: Duration, conn: ConnId, message: Message) {
        self.now = now;
        match self.peers.get(conn) {
            Some(Peer::Worker { .. }) => self.worker_message(now, conn, message),
            Some(Peer::Submitter { .. }) => self.submitter_message(now, conn, message),
            None => debug!(%conn, "message from an unknown connection ignored"),
        }
        self.pump();
    }

    fn worker_message(&mut self, now: Duration, conn: ConnId, message: Message) {
        let worker = conn.worker();
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
            Message::FrameMesh { job, frame, mesh } => {
                if let Err(e) = self.views.corner_mesh_arrived(job, frame, &mesh, now) {
                    warn!(worker = %self.peers.name(conn), %job, "corner mesh left out: {e}");
                }
            }
            Message::PackageFailed(failed) => {
                warn!(worker = %self.peers.name(conn), package = failed.id, "package failed: {}", failed.error);
                match (self.scheduler).package_failed(
                    now,
                    worker,
                    PackageId(failed.id),
                    failed.error,
                ) {
                    // It runs nowhere now (a retry is a new assignment).
                    Ok(()) => self.frames.drop_in_flight(failed.id, conn),
                    Err(e) => debug!("failure report ignored: {e}"),
                }
            }
            other => self.close(conn, format!("unexpected {} from a worker", other.name())),
        }
        if let Some(job) = self.views.take_ended_at_preview() {
            let _ = self.scheduler.cancel_job(now, job);
        }
    }

    fn package_result(
        &mut self,
        now: Duration,
        conn: ConnId,
        result: PackageResult,
        bytes_out: u64,
    ) {
        let worker = conn.worker();
        match self.frames.arrival(result.id) {
            Arrival::UnknownPackage => {
                return debug!(package = result.id, "result for an unknown package ignored");
            }
            Arrival::FrameGone => {
                return debug!(package = result.id, "result for a finished frame ignored");
            }
            Arrival::AwaitingBase => {
                // The base frame is still being rasterized: check the
                // result then; till then it is no straggler.
                let package = PackageId(result.id);
                if let Err(e) = self.scheduler.package_arrived(now, worker, package) {
                    return debug!(package = result.id, "result ignored: {e}");
                }
                return self.frames.hold(conn, result, bytes_out);
            }
            Arrival::Ready => {}
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
        let Some(in_flight) = self.frames.packages.get(&id) else {
            return;
        };
        let (job_id, frame, bytes_in) = (in_flight.job, in_flight.frame, in_flight.bytes_in);
        let checked = (self.frames.check_result(conn, id, pixels, stage)).expect("ready above");
        let (stage, accepted) = match checked {
            Ok(checked) => checked,
            Err(error) => {
                warn!(worker = %self.peers.name(conn), package = id, "{error}");
                let failed =
                    (self.scheduler).package_failed(now, worker, PackageId(id), error.to_string());
                if failed.is_ok() {
                    // It runs nowhere now (a retry is a new assignment).
                    self.frames.drop_in_flight(id, conn);
                }
                return self.frames.refused(id, conn);
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
                return debug!(package = id, "stage result ignored: {e}");
            }
            if let Some(mesh) = &mesh {
                let triangles = (self.frames.packages.get(&id)).map_or(&[][..], |p| &p.triangles);
                if let Err(e) = (self.views).mesh_arrived(job_id, stage, triangles, mesh) {
                    let worker = self.peers.name(conn);
                    warn!(%worker, package = id, "mesh left out: {e}");
                }
            }
            let measure = self.frames.stage_in(id, conn, stage, work, &stats);
            let Accepted::Composite(pixels) = accepted else {
                unreachable!("a progressive frame is split")
            };
            let views = &mut self.views;
            (self.frames).stage_arrived((job_id, frame), stage, id, pixels, views, now);
            self.ask_for_view_figures();
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
            bytes_in,
            bytes_out,
        };
        if self.package_finished(now, conn, id, measure) {
            self.frames.accept(job_id, frame, &stats, accepted);
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
            .package_done(now, conn.worker(), PackageId(id), measure);
        if let Err(e) = done {
            debug!(package = id, "result ignored: {e}");
            return false;
        }
        // Done: a late duplicate copy now finds nothing and is ignored.
        let Some((in_flight, progress)) = self.frames.package_done(id) else {
            return true;
        };
        let worker_name = self.peers.worker_name(conn);
        (self.telemetry).package_done(&worker_name, rays, in_flight.bytes_in, bytes_out);
        if let Some(progress) = progress {
            self.send_to_job(in_flight.job, progress);
        }
        true
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
            Message::SubmitStudy { study } => self.submit_study(now, conn, study),
            Message::ListJobs { all } => {
                let rows = self.table.rows(all);
                self.send(conn, Message::JobRows { rows });
            }
            Message::ControlJob { job, action } => {
                let who = self.peers.controller(conn, &action);
                let outcome = (self.control_job(now, job, action, &who)).map_err(|e| e.to_string());
                self.send(conn, Message::JobControlled { job, outcome });
            }
            Message::SceneData(data) => match self.awaiting_scene.remove(&conn) {
                Some(mut job) if job.scene == JobScene::Hash(data.hash) => {
                    job.scene = JobScene::Data(data);
                    self.submit(now, conn, job);
                }
                None if self.awaiting_scenes.contains_key(&conn) => {
                    self.study_scene(now, conn, data)
                }
                _ => self.close(conn, "scene data nobody asked for".into()),
            },
            other => self.close(
                conn,
                format!("unexpected {} from a submitter", other.name()),
            ),
        }
    }

    /// Checks a job whose scene is in the cache (or in `job`) and queues it
    /// under `id`, frames before `resume_from` being finished already.
    fn queue_job(
        &mut self,
        now: Duration,
        id: JobId,
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
        id: JobId,
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
        let (name, frames) = (job.name.clone(), job.frames.len());
        let (job, work) = Job::checked(job, scene, scene_hash, submitters, resume_from)?;
        let (reflectors, method) = (job.reflectors.len(), job.method.name());
        info!(job = %id, %name, frames, reflectors, method, "job queued");
        self.frames.jobs.insert(id, job);
        // The view's stages are split over the workers: their latency counts.
        let interactive = job_kind == WireJobKind::View;
        let options = QueueOptions {
            priority,
            paused,
            interactive,
        };
        let submitted = self.scheduler.submit_job_with(now, id, work, options);
        submitted.map_err(|e| {
            self.frames.jobs.remove(&id);
            JobRejected::from(e)
        })
    }

    /// Sends `message` to `conn`; a frame it names to a worker is among the
    /// frames that worker keeps now.
    fn send(&mut self, conn: ConnId, message: Message) {
        self.peers.saw(conn, &message);
        self.outbox.push_back(Output::Send(conn, Box::new(message)));
    }

    /// Sends to each of a job's submitters.
    fn send_to(&mut self, submitters: &BTreeSet<ConnId>, message: Message) {
        for &conn in submitters {
            self.send(conn, message.clone());
        }
    }

    /// Sends to each of job `job`'s submitters (none when it is not rendered).
    fn send_to_job(&mut self, job: JobId, message: Message) {
        let submitters = (self.frames.jobs.get(&job)).map(|j| j.submitters.clone());
        self.send_to(&submitters.unwrap_or_default(), message);
    }

    fn persist(&mut self, record: Record) {
        if !self.journals(record.job()) {
            return;
        }
        self.recovery.persisting(&record);
        self.outbox.push_back(Output::Persist(record));
    }

    /// Whether `job`'s records are journaled.
    fn journals(&self, job: JobId) -> bool {
        self.recovery.journals(job, self.views.owns(job))
    }

    fn refuse_job(&mut self, conn: ConnId, error: String) {
        warn!(%conn, "job refused: {error}");
        self.send(
            conn,
            Message::JobFailed {
                job: JobId(0),
                errors: vec![error],
            },
        );
    }

    fn close(&mut self, conn: ConnId, reason: String) {
        warn!(peer = %self.peers.name(conn), "closing: {reason}");
        self.outbox.push_back(Output::Close(conn, reason));
    }

    /// Turns the scheduler's events and assignments into messages.
    fn pump(&mut self) {
        while let Some(event) = self.scheduler.poll_event() {
            match event {
                Event::JobStarted { job, .. } => self.job_started(job),
                Event::JobResumed { job } => self.job_resumed(job),
                Event::FrameStarted {
                    job, frame, whole, ..
                } => self.frame_started(job, frame, whole),
                Event::FrameComplete { job, frame, stats } => {
                    self.frame_complete(job, frame, &stats)
                }
                Event::JobComplete { job } => self.job_done(job),
                Event::JobFailed {
                    job,
                    reason,
                    errors,
                } => self.job_failed(job, &reason, &errors),
                Event::JobCancelled { job } => self.job_cancelled(job),
                Event::WorkerBlocklisted { worker, job } => {
                    self.worker_blocklisted(ConnId::of_worker(worker), job)
                }
                Event::WorkerLost {
                    worker,
                    cause,
                    requeued,
                } => self.worker_lost(ConnId::of_worker(worker), cause, &requeued),
                Event::PackageCancelled { worker, package } => {
                    self.send(
                        ConnId::of_worker(worker),
                        Message::CancelPackage { id: package.0 },
                    );
                }
            }
        }
        while let Some(assignment) = self.scheduler.poll_assignment() {
            self.assign(assignment);
        }
    }

    /// The driver encoded the frame [`Output::EncodeFrame`] asked for: it
    /// goes out once the job's frames before it have (a job that ended
    /// meanwhile, cancelled or failed, drops it).
    pub fn frame_encoded(&mut self, now: Duration, encoded: EncodedFrame) {
        self.now = now;
        let job = encoded.job;
        if self.frames.frame_encoded(encoded) {
            self.tell_finished(job);
        }
    }

    /// Asks the driver for the next base frame of `job`'s last frames
    /// ahead of their start, if one is to be made ([`Frames::base_ahead`]).
    fn make_base_ahead(&mut self, job: JobId) {
        let in_flight = self.scheduler.config().frames_in_flight as usize;
        let workers = self.peers.workers().len();
        if let Some(request) = self.frames.base_ahead(job, in_flight, workers, self.now) {
            self.outbox.push_back(Output::RasterizeBase(request));
        }
    }

    /// The driver rasterized the base frame that [`Output::RasterizeBase`]
    /// asked for: the held results are checked and composited now.
    pub fn base_frame_ready(&mut self, now: Duration, job: JobId, frame: u32, base: BaseFrame) {
        self.now = now;
        let (cost, used) = self.frames.base_ready(job, frame, base, now);
        if let Some(cost) = cost {
            // Gone meanwhile: nothing to learn for it.
            let _ = self.scheduler.base_frame_cost(now, job, cost);
        }
        match used {
            BaseUse::Waiting(base) => {
                for (conn, result, bytes) in self.frames.use_base(job, frame, base, now) {
                    self.package_result(now, conn, result, bytes);
                }
            }
            BaseUse::Ahead => {
                let _ = self.scheduler.base_frame_ahead(now, job, frame);
            }
            BaseUse::Spared => {}
            BaseUse::JobGone => return,
        }
        self.make_base_ahead(job);
        self.pump();
    }

    /// A result arrived: its package was in flight, its frame set up first
    /// if it was the worker's first package of the frame (the set-up starts
    /// when the package arrives), then computed for its busy time.
    fn record_package(&mut self, conn: ConnId, result: &PackageResult) {
        let name = self.peers.name(conn);
        self.frames.record_package(name, result, self.now);
    }

    fn assign(&mut self, a: Assignment) {
        // A worker that let this split frame go (it keeps the frames named
        // to it last, of any job: several jobs run at once) gets its start
        // again first; one that keeps it does not.
        let worker = ConnId::of_worker(a.worker);
        let kept = self.peers.keeps(worker, a.job, a.frame);
        let (again, package) = self.frames.assign(a, kept, self.now);
        if let Some(start) = again {
            self.send(worker, start);
        }
        self.send(worker, package);
    }

    /// Moves the interactive view's eye: cancels the previous move's job and
    /// queues the new view at rising quality (see `view.rs`); returns the
    /// new job's id.
    pub fn steer_view(&mut self, now: Duration, request: ViewRequest) -> Result<JobId, ViewError> {
        self.now = now;
        let planned = self.views.plan(&request)?;
        if let Some(outdated) = self.views.running_job() {
            if self.scheduler.cancel_job(now, outdated).is_ok() {
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
        if let Some(j) = self.frames.jobs.get_mut(&id) {
            if planned.stages().len() > 1 {
                j.stages = planned.stages().to_vec();
            }
            if request.page_draws_scene {
                j.base_extent = vtfarm_render::BaseExtent::Packages;
            }
        }
        self.next_job.0 += 1;
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
    fn counts_in_totals(&self, id: JobId) -> bool {
        self.table.get(id).is_some()
    }

    /// A view's job is listed only while it runs: each move of the eye
    /// makes several.
    fn forget_view_job(&mut self, id: JobId) {
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
    fn remember_for_view(&mut self, id: JobId) {
        let Some(j) = self.frames.jobs.get(&id) else {
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
    pub fn telemetry(&self) -> &Telemetry {
        &self.telemetry
    }

    /// The packages each worker (by name) is working on now.
    pub fn packages_by_worker(&self) -> BTreeMap<String, Vec<u64>> {
        (self.frames).packages_by_worker(|_| true, |conn| self.peers.worker_name(conn))
    }

    /// The packages of job `job` each worker (by name) is working on now
    /// (several jobs run at once).
    pub fn job_packages_by_worker(&self, job: JobId) -> BTreeMap<String, Vec<u64>> {
        (self.frames).packages_by_worker(|p| p.job == job, |conn| self.peers.worker_name(conn))
    }

    /// The frame being assembled of the first running job that assembles
    /// one ([`status::live_frame`]).
    pub fn live_frame(&self) -> Option<LiveFrame<'_>> {
        status::live_frame(&self.scheduler, &self.frames)
    }

    /// The farm's state for `vtfarm status`.
    pub fn status(&self) -> StatusReply {
        status::status(
            &self.scheduler,
            &self.peers,
            &self.frames,
            self.scene_bytes_sent,
        )
    }
}
