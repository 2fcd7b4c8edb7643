//! The worker's side of a session with the master, over any [`Link`].
//!
//! Pull-based: the worker asks for work (`RequestWork`) whenever it is idle,
//! runs one package at a time (the package itself uses every core), and
//! sends the result or the error. Scenes are fetched only when the disk cache
//! lacks them. Heartbeats go out every second, busy or not.

use std::collections::{BTreeSet, VecDeque};
use std::sync::Arc;

use tokio::task::JoinHandle;
use tracing::{info, warn};
use vtfarm_proto::{
    FrameStart, JobId, Link, Message, Package, PackageFailed, PackageId, PackageResult,
};
use vtfarm_vertex::Stop;

use crate::engine::{ActiveFrame, Engine, HEARTBEAT_INTERVAL};

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
}

/// The package being computed, and its stop (cancelled when the master cancels it).
type Running = (
    PackageId,
    JoinHandle<Result<PackageResult, String>>,
    Arc<Stop>,
);

/// Serves the master over `link` until it shuts the worker down or the link drops.
pub async fn serve(mut link: Link, engine: &mut Engine, config: WorkerConfig) -> SessionEnd {
    let mut session = Session {
        engine,
        config,
        frame: None,
        pending_frame: None,
        queue: VecDeque::new(),
        cancelled: BTreeSet::new(),
        frame_error: None,
    };
    let mut running: Option<Running> = None;
    // Whether a RequestWork is outstanding: work is asked for only once the
    // frame is ready, so the load balancer never counts set-up as tracing.
    let mut requested = false;
    let mut heartbeat = tokio::time::interval(HEARTBEAT_INTERVAL);
    let send = |link: &Link, m: Message| link.tx.send(m).is_ok();
    loop {
        tokio::select! {
            message = link.rx.recv() => {
                let Some(message) = message else { return SessionEnd::Disconnected };
                match message {
                    Message::Shutdown => return SessionEnd::Shutdown,
                    other => {
                        // A package answers the request; a new frame voids it
                        // (the master drops requests for other frames).
                        requested &= !matches!(other, Message::Package(_) | Message::FrameStart(_));
                        for reply in session.handle(other) {
                            send(&link, reply);
                        }
                        // Stop a cancelled package now: it frees its memory and the cores.
                        if let Some((id, _, stop)) = &running {
                            if session.cancelled.contains(id) {
                                stop.cancel();
                            }
                        }
                    }
                }
            }
            outcome = async { (&mut running.as_mut().expect("guarded by the select condition").1).await }, if running.is_some() => {
                let (id, _, _) = running.take().expect("guarded by the select condition");
                let reply = match outcome {
                    Ok(Ok(result)) => Message::PackageResult(result),
                    Ok(Err(error)) => Message::PackageFailed(PackageFailed { id, error }),
                    Err(join) => Message::PackageFailed(PackageFailed { id, error: format!("package task failed: {join}") }),
                };
                if !session.cancelled.remove(&id) && !send(&link, reply) {
                    return SessionEnd::Disconnected;
                }
            }
            _ = heartbeat.tick() => {
                if !send(&link, Message::Heartbeat) {
                    return SessionEnd::Disconnected;
                }
            }
        }
        if running.is_none() {
            let (started, failures) = session.next_package();
            for failure in failures {
                send(&link, failure);
            }
            running = started;
        }
        let idle = running.is_none() && session.queue.is_empty();
        let ready = session
            .frame
            .as_ref()
            .filter(|_| session.pending_frame.is_none());
        if let Some(frame) = ready.filter(|_| idle && !requested) {
            if !send(
                &link,
                Message::RequestWork {
                    job: frame.job,
                    frame: frame.frame,
                },
            ) {
                return SessionEnd::Disconnected;
            }
            requested = true;
        }
    }
}

struct Session<'a> {
    engine: &'a mut Engine,
    config: WorkerConfig,
    frame: Option<Arc<ActiveFrame>>,
    /// A frame whose scene is still on its way.
    pending_frame: Option<FrameStart>,
    queue: VecDeque<Package>,
    cancelled: BTreeSet<PackageId>,
    /// The last frame that could not start, with why: its packages fail with that.
    frame_error: Option<((JobId, u32), String)>,
}

impl Session<'_> {
    /// Handles one message from the master; returns the replies.
    fn handle(&mut self, message: Message) -> Vec<Message> {
        match message {
            Message::SceneOffer { hash } if !self.engine.has_scene(&hash) => {
                vec![Message::SceneRequest { hash }]
            }
            Message::SceneOffer { .. } | Message::Heartbeat => Vec::new(),
            Message::SceneData(data) => {
                if let Err(e) = self.engine.add_scene(data) {
                    warn!("{e}");
                    if let Some(start) = self.pending_frame.take() {
                        self.frame_error = Some(((start.job, start.frame), e));
                    }
                }
                match self.pending_frame.take() {
                    Some(start) => self.start_frame(start),
                    None => Vec::new(),
                }
            }
            Message::FrameStart(start) => self.start_frame(start),
            Message::Package(package) => {
                self.queue.push_back(package);
                Vec::new()
            }
            Message::CancelPackage { id } => {
                let before = self.queue.len();
                self.queue.retain(|p| p.id != id);
                if self.queue.len() == before {
                    // Running now (or already sent): drop its result.
                    self.cancelled.insert(id);
                }
                Vec::new()
            }
            other => {
                warn!(
                    message = other.name(),
                    "unexpected message from the master, ignored"
                );
                Vec::new()
            }
        }
    }

    fn start_frame(&mut self, start: FrameStart) -> Vec<Message> {
        if !self.engine.has_scene(&start.scene) {
            // The scene was offered and requested; the frame waits for it.
            self.pending_frame = Some(start);
            return Vec::new();
        }
        let (job, frame) = (start.job, start.frame);
        // Building the BVH and ID buffers is CPU work: keep it off the I/O threads' hot path.
        match tokio::task::block_in_place(|| self.engine.start_frame(start)) {
            Ok(active) => {
                info!(job, frame, "frame ready");
                self.frame = Some(Arc::new(active));
                Vec::new()
            }
            Err(error) => {
                warn!(job, frame, "cannot start frame: {error}");
                self.frame = None;
                self.frame_error = Some(((job, frame), error));
                // Its packages fail with this error as they arrive.
                self.pending_frame = None;
                Vec::new()
            }
        }
    }

    /// Starts the next queued package of the active frame; packages of any
    /// other frame fail at once (the master retries them elsewhere).
    fn next_package(&mut self) -> (Option<Running>, Vec<Message>) {
        let mut failures = Vec::new();
        while let Some(package) = self.queue.front() {
            let waiting_for_scene = self
                .pending_frame
                .as_ref()
                .is_some_and(|f| (f.job, f.frame) == (package.job, package.frame));
            if waiting_for_scene {
                break;
            }
            let package = self.queue.pop_front().expect("front exists");
            match &self.frame {
                Some(active) if (active.job, active.frame) == (package.job, package.frame) => {
                    let (active, slowdown, id) = (active.clone(), self.config.slowdown, package.id);
                    let budget = active.pixels() * self.config.samples_per_pixel_budget;
                    let stop = Arc::new(Stop::with_budget(budget));
                    let task_stop = stop.clone();
                    let task = tokio::task::spawn_blocking(move || {
                        active.run(&package, slowdown, &task_stop)
                    });
                    return (Some((id, task, stop)), failures);
                }
                _ => failures.push(Message::PackageFailed(PackageFailed {
                    id: package.id,
                    error: match &self.frame_error {
                        Some((frame, error)) if *frame == (package.job, package.frame) => {
                            format!(
                                "frame {} of job {} cannot start: {error}",
                                package.frame, package.job
                            )
                        }
                        _ => format!(
                            "package of job {} frame {} arrived without its frame",
                            package.job, package.frame
                        ),
                    },
                })),
            }
        }
        (None, failures)
    }
}
