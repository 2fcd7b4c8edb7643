//! The async driver of a [`WorkerSession`] over any [`Link`]: it feeds the
//! session messages, finished work, deadlines and the drain signal, prepares
//! frames with the [`Engine`], runs packages on blocking threads, and sends
//! what the session says. No protocol decision is made here.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;
use std::time::Duration;

use tokio::sync::{oneshot, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tracing::{debug, warn};
use vtfarm_proto::{Message, PackageId, PackageResult, SceneData, SceneHash, WireMesh};
use vtfarm_scene::Scene;
use vtfarm_transport::Link;
use vtfarm_vertex::{ProgressivePackage, Stop};

use crate::engine::{ActiveFrame, Engine, FrameError, PackageError, PreparedFrames, SceneError};
use crate::session::{FrameKey, SceneStore, SessionEnd, Task, WorkerConfig, WorkerSession};

/// How long a drained worker waits for the master to close its side.
const GOODBYE_LIMIT: Duration = Duration::from_secs(5);

/// Tells sessions to drain (see [`crate::session`]); cheap to clone, and it
/// stays set across reconnects.
#[derive(Clone, Debug)]
pub struct DrainSignal(watch::Receiver<bool>);

impl DrainSignal {
    /// A signal and the sender that raises it (`send(true)`).
    pub fn new() -> (watch::Sender<bool>, DrainSignal) {
        let (tx, rx) = watch::channel(false);
        (tx, DrainSignal(rx))
    }

    /// A signal that is never raised.
    pub fn never() -> DrainSignal {
        DrainSignal::new().1
    }

    /// Whether draining was asked for.
    pub fn is_raised(&self) -> bool {
        *self.0.borrow()
    }

    /// Waits until draining is asked for (forever if the sender is gone unraised).
    pub async fn raised(&mut self) {
        if self.0.wait_for(|&d| d).await.is_err() {
            std::future::pending::<()>().await;
        }
    }
}

impl SceneStore for Engine {
    fn has_scene(&mut self, hash: &SceneHash) -> bool {
        Engine::has_scene(self, hash)
    }

    type Error = SceneError;

    fn add_scene(&mut self, data: SceneData) -> Result<(), SceneError> {
        Engine::add_scene(self, data)
    }
}

/// The engine as the session sees it from [`serve`]: the scene I/O is
/// done by then (on a blocking thread), so nothing here waits for the disk
/// or decodes.
struct Ready<'a> {
    engine: &'a mut Engine,
    /// How checking the `SceneData` being handled went.
    added: Option<Result<(), SceneError>>,
}

impl SceneStore for Ready<'_> {
    type Error = SceneError;

    fn has_scene(&mut self, hash: &SceneHash) -> bool {
        self.engine.has_scene_in_memory(hash)
    }

    fn add_scene(&mut self, data: SceneData) -> Result<(), SceneError> {
        match self.added.take() {
            Some(added) => added,
            // Not checked on a thread first (no such path): check it here.
            None => SceneStore::add_scene(self.engine, data),
        }
    }
}

/// A package stage's outcome, with the package's progress for its next stage.
type StageDone = (
    Result<PackageResult, PackageError>,
    Option<ProgressivePackage>,
);

/// The package stage being computed, and its stop (set when the master cancels it).
type Running = (PackageId, JoinHandle<StageDone>, Arc<Stop>);

/// A frame being set up on a blocking thread.
type Preparing = (FrameKey, JoinHandle<Result<ActiveFrame, FrameError>>);

/// A scene read from the cache (`None`: not there) or checked and cached,
/// on a blocking thread, with the message that waits for it.
type SceneWork = JoinHandle<(SceneHash, Message, Option<Result<Scene, SceneError>>)>;

/// Serves the master over `link` until it shuts the worker down, the link
/// drops, or `drain` is raised and the session drained.
///
/// Nothing slow runs on this task: scenes are read, checked and cached,
/// frames set up (a new scene's BVH included) and packages run on blocking
/// threads, so heartbeats go out on time whatever the scene's size.
/// Messages that arrive while a scene is being read or checked wait for
/// it, in order.
pub async fn serve(
    link: Link,
    engine: &mut Engine,
    config: WorkerConfig,
    mut drain: DrainSignal,
) -> SessionEnd {
    let Link { tx, mut rx, .. } = link;
    let start = Instant::now();
    let mut session = WorkerSession::new(Duration::ZERO);
    let mut frames = PreparedFrames::default();
    let mut preparing: Option<Preparing> = None;
    // The corner mesh of the frame being prepared, when it is a view's.
    let mut corner_mesh: Option<(FrameKey, oneshot::Receiver<WireMesh>)> = None;
    let mut running: Option<Running> = None;
    let mut scene_work: Option<SceneWork> = None;
    let mut waiting: VecDeque<Message> = VecDeque::new();
    // Progressive packages between their stages.
    let mut progress: BTreeMap<PackageId, ProgressivePackage> = BTreeMap::new();
    loop {
        // A cancelled package's progress goes with it, and the frames the
        // session let go with them.
        progress.retain(|&id, _| session.continues(id));
        frames.retain(|key| session.keeps_set_up(key));
        // Hand the session the messages that waited for a scene, until
        // one needs the disk or a check again.
        while scene_work.is_none() {
            let Some(message) = waiting.pop_front() else {
                break;
            };
            match scene_io(message, engine) {
                Ok(message) => {
                    let mut ready = Ready {
                        engine,
                        added: None,
                    };
                    session.handle_message(start.elapsed(), message, &mut ready);
                }
                Err(work) => scene_work = Some(work),
            }
        }
        // A cancelled package stops now, freeing its memory and the cores.
        if let Some((id, _, stop)) = &running {
            if session.is_cancelled(*id) {
                stop.cancel();
            }
        }
        while let Some(task) = session.poll_task() {
            match task {
                Task::PrepareFrame(frame_start) => {
                    let key = (frame_start.job, frame_start.frame);
                    match engine.frame_parts(frame_start) {
                        Ok(mut parts) => {
                            // The renderer (a new scene's BVH) and the ID
                            // buffers on a blocking thread, so that heartbeats
                            // and a finished package of an older frame go out
                            // meanwhile; a view's corner mesh first.
                            let (mesh_tx, mesh_rx) = oneshot::channel();
                            let task = tokio::task::spawn_blocking(move || {
                                if let Some(mesh) = parts.corner_mesh()? {
                                    let _ = mesh_tx.send(mesh);
                                }
                                parts.build()
                            });
                            // The session prepares one frame at a time.
                            preparing = Some((key, task));
                            corner_mesh = Some((key, mesh_rx));
                        }
                        Err(e) => session.frame_prepared(start.elapsed(), key, Err(e)),
                    }
                }
                Task::RunPackage { package, stage } => {
                    let id = package.id;
                    debug!(package = id, stage, "package started");
                    let active = frames.get(package.job, package.frame);
                    let budget =
                        active.as_ref().map_or(0, |a| a.pixels()) * config.samples_per_pixel_budget;
                    let stop = Arc::new(Stop::with_budget(budget));
                    let task_stop = stop.clone();
                    let mut staged = progress.remove(&id);
                    let task = tokio::task::spawn_blocking(move || {
                        let outcome = match active {
                            Some(a) if (a.job, a.frame) == (package.job, package.frame) => {
                                let mut run = || {
                                    let slowdown = config.slowdown;
                                    a.run_stage(&package, stage, &mut staged, slowdown, &task_stop)
                                };
                                // A progressive package's later stages yield
                                // the cores to what the view's first image
                                // waits for (`priority`).
                                if stage > 0 {
                                    crate::priority::later_stages().install(run)
                                } else {
                                    run()
                                }
                            }
                            _ => Err(PackageError::FrameNotPrepared),
                        };
                        (outcome, staged)
                    });
                    running = Some((id, task, stop));
                }
            }
        }
        while let Some(message) = session.poll_message() {
            if tx.send(message).is_err() {
                return SessionEnd::Disconnected;
            }
        }
        if let Some(end) = session.poll_end() {
            if end == SessionEnd::Drained {
                // Goodbye: close our side and let the master close its side
                // (it requeues what this worker held at once).
                drop(tx);
                let _ = tokio::time::timeout(GOODBYE_LIMIT, async {
                    while rx.recv().await.is_some() {}
                })
                .await;
            }
            return end;
        }
        let deadline = start + session.poll_timeout();
        tokio::select! {
            message = rx.recv() => {
                let Some(message) = message else { return SessionEnd::Disconnected };
                // In order behind any message still waiting for a scene.
                waiting.push_back(message);
            }
            done = async { (&mut scene_work.as_mut().expect("guarded by the select condition")).await }, if scene_work.is_some() => {
                scene_work = None;
                let (hash, message, outcome) = match done {
                    Ok(done) => done,
                    Err(join) => {
                        warn!("the scene task failed: {join}");
                        continue;
                    }
                };
                let added = outcome.map(|checked| {
                    checked.map(|scene| engine.insert_scene(hash, scene))
                });
                let mut ready = Ready { engine, added };
                session.handle_message(start.elapsed(), message, &mut ready);
            }
            outcome = async { (&mut running.as_mut().expect("guarded by the select condition").1).await }, if running.is_some() => {
                let (id, _, _) = running.take().expect("guarded by the select condition");
                let (outcome, staged) = match outcome {
                    Ok(done) => done,
                    Err(join) => (Err(PackageError::Task(join)), None),
                };
                session.package_finished(start.elapsed(), id, outcome);
                // Its next stage may be the session's next task already.
                if let Some(staged) = staged.filter(|_| session.continues(id)) {
                    progress.insert(id, staged);
                }
            }
            traced = async { (&mut corner_mesh.as_mut().expect("guarded by the select condition").1).await }, if corner_mesh.is_some() => {
                let (key, _) = corner_mesh.take().expect("guarded by the select condition");
                // No mesh (not a view's frame, or its set-up failed): nothing to send.
                if let Ok(mesh) = traced {
                    session.corner_mesh_traced(start.elapsed(), key, mesh);
                }
            }
            built = async { (&mut preparing.as_mut().expect("guarded by the select condition").1).await }, if preparing.is_some() => {
                let (key, _) = preparing.take().expect("guarded by the select condition");
                // A corner mesh not taken yet goes out before the frame is ready.
                if let Some((mesh_key, mut traced)) = corner_mesh.take() {
                    if let Ok(mesh) = traced.try_recv() {
                        session.corner_mesh_traced(start.elapsed(), mesh_key, mesh);
                    }
                }
                let outcome = match built {
                    Ok(Ok(active)) => {
                        engine.keep_renderer(&active);
                        frames.insert(active);
                        Ok(())
                    }
                    Ok(Err(e)) => Err(e),
                    Err(join) => Err(FrameError::Task(join)),
                };
                session.frame_prepared(start.elapsed(), key, outcome);
            }
            () = tokio::time::sleep_until(deadline) => session.handle_timeout(start.elapsed()),
            () = drain.raised(), if !session.is_draining() => {
                debug!("drain requested");
                session.drain(start.elapsed());
            }
        }
    }
}

/// `message` back when the session can take it now, or the blocking task
/// that reads or checks its scene first: a scene offered and not in
/// memory is looked for in the disk cache, a scene sent is checked and
/// cached.
fn scene_io(message: Message, engine: &Engine) -> Result<Message, SceneWork> {
    let cache = engine.cache().clone();
    match message {
        Message::SceneOffer { hash, job } if !engine.has_scene_in_memory(&hash) => {
            Err(tokio::task::spawn_blocking(move || {
                let loaded = cache.load(&hash).map(Ok);
                (hash, Message::SceneOffer { hash, job }, loaded)
            }))
        }
        Message::SceneData(data) => Err(tokio::task::spawn_blocking(move || {
            let checked = cache.store(&data);
            (data.hash, Message::SceneData(data), Some(checked))
        })),
        other => Ok(other),
    }
}
