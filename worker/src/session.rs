//! The worker's side of a session with the master as a sans-IO state
//! machine (quinn-proto style): messages, finished work and time go in
//! (`handle_message`, `frame_prepared`, `package_finished`, `handle_timeout`,
//! `drain`), messages, work to do and the next deadline come out
//! (`poll_message`, `poll_task`, `poll_timeout`, `poll_end`). It owns no
//! socket, no clock and no thread; `serve.rs` drives it over a `Link`, and
//! the master's fault harness drives it on a virtual clock.
//!
//! Pull-based: the worker asks for work (`RequestWork`, naming the newest
//! frame it heard of) whenever it has no package waiting, so one package is
//! asked for ahead while another runs; it runs one package at a time (the
//! package itself uses every core), and sends the result or the error. The
//! master pipelines frames and gives each frame's work to a crew of workers
//! (frame affinity), so a frame is prepared only when a package of it comes:
//! a worker sets up the frames of its crew, not every frame announced.
//! Prepared frames stay usable: the session keeps the frames the master
//! named last ([`KeptFrames`], the rule the master counts on, so it sends a
//! frame's `FrameStart` again only to a worker that let it go) and those of
//! the packages in hand.
//! A whole frame's package brings its frame's set-up itself (no other
//! worker hears of that frame); its result is the finished frame.
//! Frames are prepared one at a time, for the first waiting package. Scenes
//! are fetched only when the store lacks them. Heartbeats go out every
//! [`HEARTBEAT_INTERVAL`].
//!
//! A progressive frame (the interactive view, `FrameStart::stages`) runs
//! each package stage by stage, one result per stage: the lowest stage
//! waiting goes first, a package not started before every later stage, so
//! the whole frame's preview is out before any refinement; a package is
//! done (and leaves the session) with its last stage.
//!
//! Draining (SIGTERM): no more requests; the package in hand (the running
//! one, or else the first received, whose frame may still be set up)
//! finishes (or the [`DRAIN_LIMIT`] passes), then the session ends with
//! [`SessionEnd::Drained`] and the driver says goodbye by closing the link,
//! which makes the master requeue everything else at once.

use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::time::Duration;

use tracing::{info, warn};
use vtfarm_proto::{
    FrameStart, JobId, KeptFrames, Message, Package, PackageFailed, PackageId, PackageResult,
    SceneData, SceneHash, WireMesh,
};

use crate::engine::{FrameError, PackageError};

/// How long a worker waits between heartbeats.
pub const HEARTBEAT_INTERVAL: Duration = Duration::from_secs(1);

/// How long a draining worker lets its running package go on before it
/// hands it back anyway.
pub const DRAIN_LIMIT: Duration = Duration::from_secs(30);

/// How a worker behaves.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorkerConfig {
    /// Makes every package take this many times its compute time (≥ 1): a
    /// documented way to emulate a slower machine.
    pub slowdown: f64,
    /// Traced samples a package may use per pixel of its frame before it
    /// fails as a runaway (see [`crate::engine::SAMPLES_PER_PIXEL_BUDGET`]).
    pub samples_per_pixel_budget: u64,
}

impl Default for WorkerConfig {
    fn default() -> Self {
        WorkerConfig {
            slowdown: 1.0,
            samples_per_pixel_budget: crate::engine::SAMPLES_PER_PIXEL_BUDGET,
        }
    }
}

/// Why a session ended.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SessionEnd {
    /// The master said `Shutdown`.
    Shutdown,
    /// The link went down.
    Disconnected,
    /// The worker was told to stop (SIGTERM) and drained.
    Drained,
}

/// Scenes the worker has, by content hash (the engine's cache, or a test's).
pub trait SceneStore {
    /// Whether the scene is at hand.
    fn has_scene(&mut self, hash: &SceneHash) -> bool;
    /// Why a scene was refused.
    type Error: std::fmt::Display;
    /// Checks a scene from the master and keeps it.
    fn add_scene(&mut self, data: SceneData) -> Result<(), Self::Error>;
}

/// A frame by job and index.
pub use vtfarm_proto::FrameKey;

/// A job the master offered and whether its scene is at hand.
#[derive(Clone, Copy, Debug)]
struct JobOffer {
    job: JobId,
    hash: SceneHash,
    ready: bool,
}

/// Work the driver carries out and answers.
#[derive(Clone, Debug, PartialEq)]
pub enum Task {
    /// Build the frame's ID buffers (and renderer); answer with
    /// [`WorkerSession::frame_prepared`], after
    /// [`WorkerSession::corner_mesh_traced`] for a view's frame.
    PrepareFrame(FrameStart),
    /// Run stage `stage` of the package (0 for a frame of one stage; the
    /// driver keeps a progressive package's progress between its stages
    /// while [`WorkerSession::continues`] says so) on its frame, which is
    /// among the prepared ones; answer
    /// with [`WorkerSession::package_finished`].
    RunPackage { package: Package, stage: usize },
}

/// A package stage the driver runs.
#[derive(Clone, Debug)]
struct RunningStage {
    package: Package,
    stage: usize,
}

/// The worker's session state.
#[derive(Debug)]
pub struct WorkerSession {
    /// The frames the master named last: the session keeps these (and
    /// those of packages in hand) announced or prepared, and lets the
    /// others go.
    kept: KeptFrames,
    /// The frames prepared: their packages can run.
    prepared: BTreeSet<FrameKey>,
    /// A frame handed to the driver for preparation (one at a time), and
    /// since when.
    preparing: Option<FrameKey>,
    preparing_since: Duration,
    /// How long frames took to set up, told with the first result of each
    /// (at most `FRAMES_IN_FLIGHT`, the oldest dropped).
    setup_to_tell: BTreeMap<FrameKey, Duration>,
    /// The latest time any entry point was told.
    now: Duration,
    /// Frames announced and not prepared yet, oldest first: one is prepared
    /// when a package of it comes.
    announced: VecDeque<FrameStart>,
    /// A frame whose scene is still on its way.
    awaiting_scene: VecDeque<FrameStart>,
    /// The job last offered (`SceneOffer`): work of it may be asked for
    /// once its scene is here.
    offered: Option<JobOffer>,
    /// A frame that could not be prepared, with why: its packages fail so.
    unusable: Option<(FrameKey, FrameError)>,
    queue: VecDeque<Package>,
    running: Option<RunningStage>,
    /// Packages of progressive frames between their stages, with the
    /// next stage each runs, in the order they got there.
    continuing: VecDeque<(Package, usize)>,
    /// Stages per frame (more than one for a progressive frame), of the
    /// frames announced lately.
    stage_counts: VecDeque<(FrameKey, usize)>,
    /// Packages the master took back while they ran: their results are dropped.
    cancelled: BTreeSet<PackageId>,
    /// Whether a `RequestWork` is outstanding.
    requested: bool,
    next_heartbeat: Duration,
    /// When draining gives up on the running package.
    drain_deadline: Option<Duration>,
    /// The package in hand when draining began, if none was running: the
    /// first one received (its frame may still be being set up). It is
    /// finished like a running one.
    held_at_drain: Option<PackageId>,
    end: Option<SessionEnd>,
    outbox: VecDeque<Message>,
    tasks: VecDeque<Task>,
}

impl WorkerSession {
    /// A session that starts at `now`.
    pub fn new(now: Duration) -> Self {
        WorkerSession {
            kept: KeptFrames::default(),
            prepared: BTreeSet::new(),
            preparing: None,
            preparing_since: now,
            setup_to_tell: BTreeMap::new(),
            now,
            announced: VecDeque::new(),
            awaiting_scene: VecDeque::new(),
            offered: None,
            unusable: None,
            queue: VecDeque::new(),
            running: None,
            continuing: VecDeque::new(),
            stage_counts: VecDeque::new(),
            cancelled: BTreeSet::new(),
            requested: false,
            next_heartbeat: now + HEARTBEAT_INTERVAL,
            drain_deadline: None,
            held_at_drain: None,
            end: None,
            outbox: VecDeque::new(),
            tasks: VecDeque::new(),
        }
    }

    /// The next message for the master.
    pub fn poll_message(&mut self) -> Option<Message> {
        self.outbox.pop_front()
    }

    /// The next work for the driver.
    pub fn poll_task(&mut self) -> Option<Task> {
        self.tasks.pop_front()
    }

    /// When [`WorkerSession::handle_timeout`] should run next.
    pub fn poll_timeout(&self) -> Duration {
        self.drain_deadline
            .map_or(self.next_heartbeat, |d| d.min(self.next_heartbeat))
    }

    /// Why the session ended, once it has; the driver then stops.
    pub fn poll_end(&self) -> Option<SessionEnd> {
        self.end.clone()
    }

    /// Whether the session is draining (or has drained).
    pub fn is_draining(&self) -> bool {
        self.drain_deadline.is_some()
    }

    /// The package running now, if any.
    pub fn running(&self) -> Option<PackageId> {
        self.running.as_ref().map(|r| r.package.id)
    }

    /// Whether package `id`'s progress between stages is still wanted: a
    /// later stage of it waits, or runs (the driver keeps the progress
    /// while so, and hands it to that stage's task).
    pub fn continues(&self, id: PackageId) -> bool {
        let running_later =
            (self.running.as_ref()).is_some_and(|r| r.package.id == id && r.stage > 0);
        running_later || self.continuing.iter().any(|(p, _)| p.id == id)
    }

    /// Whether the master cancelled the running package `id`: the driver
    /// stops it (its result would be dropped anyway).
    pub fn is_cancelled(&self, id: PackageId) -> bool {
        self.cancelled.contains(&id)
    }

    /// Time passed: heartbeats, and the end of a drain that took too long.
    pub fn handle_timeout(&mut self, now: Duration) {
        self.now = now;
        if now >= self.next_heartbeat {
            self.outbox.push_back(Message::Heartbeat);
            self.next_heartbeat = now + HEARTBEAT_INTERVAL;
        }
        if self.drain_deadline.is_some_and(|d| now >= d) && self.end.is_none() {
            warn!(
                package = self.running(),
                "drain limit reached, handing the running package back"
            );
            self.end = Some(SessionEnd::Drained);
        }
    }

    /// Stop taking work: finish the running package, then end.
    pub fn drain(&mut self, now: Duration) {
        self.now = now;
        if self.drain_deadline.is_none() {
            info!("draining: finishing the running package, handing back the rest");
            self.drain_deadline = Some(now + DRAIN_LIMIT);
            // Its later stages, if it has any, finish too.
            self.held_at_drain = self.running().or(self.queue.front().map(|p| p.id));
        }
        self.advance();
    }

    /// A message from the master.
    pub fn handle_message(
        &mut self,
        now: Duration,
        message: Message,
        scenes: &mut impl SceneStore,
    ) {
        self.now = now;
        // What the master counts on this worker keeping (the frames of
        // packages in hand stay too; see `forget_unkept`).
        self.kept.saw(&message);
        // A package answers the request. A frame start renews it: the
        // master drops a request naming a job that is no longer running
        // (asking twice changes nothing at the master).
        self.requested &= !matches!(
            message,
            Message::Package(_) | Message::FrameStart(_) | Message::SceneOffer { .. }
        );
        match message {
            Message::Shutdown => self.end = Some(SessionEnd::Shutdown),
            Message::SceneOffer { hash, job } => {
                let ready = scenes.has_scene(&hash);
                if !ready {
                    self.outbox.push_back(Message::SceneRequest { hash })
                }
                self.offered = Some(JobOffer { job, hash, ready });
            }
            Message::Heartbeat => {}
            Message::SceneData(data) => {
                let hash = data.hash;
                match scenes.add_scene(data) {
                    Err(e) => warn!("{e}"),
                    Ok(()) => {
                        if let Some(offer) = self.offered.as_mut().filter(|o| o.hash == hash) {
                            offer.ready = true;
                        }
                    }
                }
                for start in std::mem::take(&mut self.awaiting_scene) {
                    self.start_frame(start, scenes);
                }
            }
            Message::FrameStart(start) => self.start_frame(start, scenes),
            Message::Package(package) => {
                // A whole frame's set-up comes with it alone.
                if let Some(start) = &package.whole {
                    self.start_frame((**start).clone(), scenes);
                }
                self.queue.push_back(package);
            }
            Message::CancelPackage { id } => {
                self.queue.retain(|p| p.id != id);
                self.continuing.retain(|(p, _)| p.id != id);
                if self.running() == Some(id) {
                    self.cancelled.insert(id);
                }
            }
            other => warn!(
                message = other.name(),
                "unexpected message from the master, ignored"
            ),
        }
        self.advance();
    }

    /// The driver prepared (or failed to prepare) a frame.
    pub fn frame_prepared(
        &mut self,
        now: Duration,
        key: FrameKey,
        outcome: Result<(), FrameError>,
    ) {
        self.now = now;
        if self.preparing != Some(key) {
            return;
        }
        self.preparing = None;
        (self.setup_to_tell).insert(key, now.saturating_sub(self.preparing_since));
        while self.setup_to_tell.len() > vtfarm_proto::FRAMES_IN_FLIGHT {
            self.setup_to_tell.pop_first();
        }
        match outcome {
            Ok(()) => {
                info!(job = %key.0, frame = key.1, "frame ready");
                self.prepared.insert(key);
            }
            Err(error) => {
                warn!(job = %key.0, frame = key.1, "cannot start frame: {error}");
                self.unusable = Some((key, error));
            }
        }
        self.prepare_next();
        self.advance();
    }

    /// The driver traced the corner mesh of the frame it is preparing
    /// (`FrameParts::corner_mesh`): it goes to the master at once, ahead of
    /// the set-up, unless the frame was let go meanwhile.
    pub fn corner_mesh_traced(&mut self, now: Duration, key: FrameKey, mesh: WireMesh) {
        self.now = now;
        if self.preparing == Some(key) {
            let (job, frame) = key;
            (self.outbox).push_back(Message::FrameMesh { job, frame, mesh });
        }
    }

    /// Lets go of the frames (announced, waiting for their scene or
    /// prepared) that are neither kept ([`KeptFrames`]) nor the frame of a
    /// package in hand: at most `FRAMES_IN_FLIGHT` and those stay.
    fn forget_unkept(&mut self) {
        let in_hand = (self.queue.iter())
            .chain(self.continuing.iter().map(|(p, _)| p))
            .chain(self.running.iter().map(|r| &r.package));
        let in_hand: BTreeSet<FrameKey> = in_hand.map(|p| (p.job, p.frame)).collect();
        let keep = |key: FrameKey| self.kept.contains(key) || in_hand.contains(&key);
        self.announced.retain(|f| keep((f.job, f.frame)));
        self.awaiting_scene.retain(|f| keep((f.job, f.frame)));
        self.prepared.retain(|&key| keep(key));
    }

    /// Whether the driver keeps frame `key` set up: it is prepared, or
    /// being prepared (the driver lets the others go).
    pub fn keeps_set_up(&self, key: FrameKey) -> bool {
        self.is_prepared(key) || self.preparing == Some(key)
    }

    /// Hands the driver the next frame to prepare, if none is being
    /// prepared: the frame of the first waiting package if it is only
    /// announced. A draining session prepares only the frame of the
    /// package in hand.
    fn prepare_next(&mut self) {
        if self.preparing.is_some() {
            return;
        }
        let draining = self.is_draining();
        let wanted = (self.queue.front())
            .filter(|p| !draining || Some(p.id) == self.held_at_drain)
            .map(|p| (p.job, p.frame));
        let position = (self.announced.iter()).position(|f| Some((f.job, f.frame)) == wanted);
        if let Some(start) = position.and_then(|i| self.announced.remove(i)) {
            self.preparing = Some((start.job, start.frame));
            self.preparing_since = self.now;
            self.tasks.push_back(Task::PrepareFrame(start));
        }
    }

    /// The running package finished.
    pub fn package_finished(
        &mut self,
        now: Duration,
        id: PackageId,
        outcome: Result<PackageResult, PackageError>,
    ) {
        self.now = now;
        if self.running() != Some(id) {
            return;
        }
        let RunningStage { package, stage } = self.running.take().expect("checked above");
        let frame = (package.job, package.frame);
        if !self.cancelled.remove(&id) {
            self.outbox.push_back(match outcome {
                Ok(mut result) => {
                    if let Some(setup) = self.setup_to_tell.remove(&frame) {
                        result.setup_micros = setup.as_micros() as u64;
                    }
                    if stage + 1 < self.stage_count(frame) {
                        self.continuing.push_back((package, stage + 1));
                    }
                    Message::PackageResult(result)
                }
                // The wire carries the reason as text.
                Err(error) => Message::PackageFailed(PackageFailed {
                    id,
                    error: error.to_string(),
                }),
            });
        }
        self.advance();
    }

    /// How many stages each package of frame `key` runs.
    fn stage_count(&self, key: FrameKey) -> usize {
        (self.stage_counts.iter())
            .rfind(|(k, _)| *k == key)
            .map_or(1, |&(_, count)| count)
    }

    fn start_frame(&mut self, start: FrameStart, scenes: &mut impl SceneStore) {
        // Announced again (as a whole frame's package brings it again): a
        // frame still kept, being set up or waiting to be is not set up
        // twice.
        let key = (start.job, start.frame);
        let known = |f: &FrameStart| (f.job, f.frame) == key;
        if self.is_prepared(key)
            || self.preparing == Some(key)
            || self.announced.iter().any(known)
            || self.awaiting_scene.iter().any(known)
        {
            return;
        }
        self.unusable = None;
        // As many as the frames announced, set up and kept can be.
        if self.stage_counts.len() == 3 * vtfarm_proto::FRAMES_IN_FLIGHT {
            self.stage_counts.pop_front();
        }
        let key = (start.job, start.frame);
        (self.stage_counts).push_back((key, start.stages.len().max(1)));
        // Both lists are kept to the frames kept (`forget_unkept`).
        if scenes.has_scene(&start.scene) {
            self.announced.push_back(start);
            self.prepare_next();
        } else {
            // The scene was offered and requested; the frame waits for it
            // (so do whole frames' set-ups that came with their packages).
            self.awaiting_scene.push_back(start);
        }
    }

    /// Starts the next package, ends a finished drain, asks for work.
    fn advance(&mut self) {
        if self.end.is_some() {
            return;
        }
        self.forget_unkept();
        // The frame of a package that came while another runs is set up
        // beside it.
        self.prepare_next();
        while self.running.is_none() {
            // A package not started yet first (its preview before any
            // package's later stages); while it waits for its frame, a
            // later stage of another.
            if !self.start_queued() && !self.start_continuing() {
                break;
            }
        }
        if self.is_draining() {
            let held = |id: PackageId| Some(id) == self.held_at_drain;
            let held_waits = (self.queue.front()).is_some_and(|p| held(p.id))
                || self.continuing.iter().any(|(p, _)| held(p.id));
            if self.running.is_none() && !held_waits {
                // Queued packages go back to the queue when the link closes.
                self.end = Some(SessionEnd::Drained);
            }
            return;
        }
        // One package ahead: the next one is asked for while one runs, so
        // the master's answer (its driver may be busy finishing a frame)
        // overlaps the tracing.
        let nothing_queued = self.queue.is_empty();
        // The newest frame heard of names the job the worker asks work of;
        // a job offered whose scene is here will do (its whole frames'
        // set-ups come with their packages).
        let offered = (self.offered.as_ref())
            .filter(|o| o.ready)
            .map(|o| (o.job, 0));
        let newest = (self.announced.iter().map(|f| (f.job, f.frame)))
            .chain(self.prepared.last().copied())
            .chain(offered)
            .max();
        let asks = nothing_queued && self.awaiting_scene.is_empty() && !self.requested;
        if let Some((job, frame)) = newest.filter(|_| asks) {
            self.outbox.push_back(Message::RequestWork { job, frame });
            self.requested = true;
        }
    }

    /// Starts the first queued package, or fails it when its frame cannot
    /// be had; `false` when there is none or it waits (for its frame, or
    /// for the drain: only the package in hand runs then).
    fn start_queued(&mut self) -> bool {
        let Some(package) = self.queue.front() else {
            return false;
        };
        if self.is_draining() && Some(package.id) != self.held_at_drain {
            return false;
        }
        let key = (package.job, package.frame);
        let waiting = self.preparing == Some(key)
            || (self.awaiting_scene.iter()).any(|f| (f.job, f.frame) == key);
        if waiting {
            return false;
        }
        if !self.is_prepared(key) {
            let mut announced = self.announced.iter().any(|f| (f.job, f.frame) == key);
            // A whole frame's package carries its set-up: announced
            // again if others pushed it out meanwhile.
            if let Some(start) = package.whole.as_ref().filter(|_| !announced) {
                self.announced.push_back((**start).clone());
                announced = true;
            }
            if announced {
                // Its first package: prepare the frame now.
                self.prepare_next();
                return false;
            }
        }
        let package = self.queue.pop_front().expect("front exists");
        self.run(package, 0);
        true
    }

    /// Starts the lowest later stage waiting (the earliest to get there
    /// among equals); `false` when none may run.
    fn start_continuing(&mut self) -> bool {
        let draining = self.is_draining();
        let next = (self.continuing.iter().enumerate())
            .filter(|(_, (p, _))| !draining || Some(p.id) == self.held_at_drain)
            .min_by_key(|(i, (_, stage))| (*stage, *i))
            .map(|(i, _)| i);
        let Some((package, stage)) = next.and_then(|i| self.continuing.remove(i)) else {
            return false;
        };
        self.run(package, stage);
        true
    }

    /// Whether frame `key` is prepared.
    fn is_prepared(&self, key: FrameKey) -> bool {
        self.prepared.contains(&key)
    }

    /// Hands the driver stage `stage` of `package`, or fails the package
    /// when its frame is not prepared (the master retries it elsewhere).
    fn run(&mut self, package: Package, stage: usize) {
        let key = (package.job, package.frame);
        if self.is_prepared(key) {
            let task = Task::RunPackage {
                package: package.clone(),
                stage,
            };
            self.running = Some(RunningStage { package, stage });
            self.tasks.push_back(task);
            return;
        }
        let error = match &self.unusable {
            Some((k, why)) if *k == key => format!("cannot start frame: {why}"),
            _ if stage > 0 => format!(
                "frame {} of job {} is no longer prepared for the package's later stages",
                key.1, key.0
            ),
            _ => format!(
                "package of job {} frame {} arrived without its frame",
                key.0, key.1
            ),
        };
        self.outbox.push_back(Message::PackageFailed(PackageFailed {
            id: package.id,
            error,
        }));
    }
}

#[cfg(test)]
mod tests;
