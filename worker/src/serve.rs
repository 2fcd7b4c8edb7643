//! The async driver of a [`WorkerSession`] over any [`Link`]: it feeds the
//! session messages, finished work, deadlines and the drain signal, prepares
//! frames with the [`Engine`], runs packages on blocking threads, and sends
//! what the session says. No protocol decision is made here.

use std::sync::Arc;
use std::time::Duration;

use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tracing::debug;
use vtfarm_proto::{PackageId, PackageResult, SceneData, SceneHash};
use vtfarm_transport::Link;
use vtfarm_vertex::Stop;

use crate::engine::{ActiveFrame, Engine, PreparedFrames};
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

    fn add_scene(&mut self, data: SceneData) -> Result<(), String> {
        Engine::add_scene(self, data)
    }
}

/// The package being computed, and its stop (set when the master cancels it).
type Running = (
    PackageId,
    JoinHandle<Result<PackageResult, String>>,
    Arc<Stop>,
);

/// A frame being set up on a blocking thread.
type Preparing = (FrameKey, JoinHandle<Result<ActiveFrame, String>>);

/// Serves the master over `link` until it shuts the worker down, the link
/// drops, or `drain` is raised and the session drained.
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
    let mut running: Option<Running> = None;
    loop {
        while let Some(task) = session.poll_task() {
            match task {
                Task::PrepareFrame(frame_start) => {
                    let key = (frame_start.job, frame_start.frame);
                    // A new scene's BVH is built here (once per scene); the
                    // ID buffers on a blocking thread, so that a package of
                    // an older frame that finishes meanwhile is sent at once.
                    let parts = tokio::task::block_in_place(|| engine.frame_parts(frame_start));
                    match parts {
                        Ok(parts) => {
                            let task = tokio::task::spawn_blocking(move || parts.build());
                            // The session prepares one frame at a time.
                            preparing = Some((key, task));
                        }
                        Err(e) => session.frame_prepared(start.elapsed(), key, Err(e)),
                    }
                }
                Task::RunPackage(package) => {
                    let id = package.id;
                    debug!(package = id, "package started");
                    let active = frames.get(package.job, package.frame);
                    let budget =
                        active.as_ref().map_or(0, |a| a.pixels()) * config.samples_per_pixel_budget;
                    let stop = Arc::new(Stop::with_budget(budget));
                    let task_stop = stop.clone();
                    let task = tokio::task::spawn_blocking(move || match active {
                        Some(a) if (a.job, a.frame) == (package.job, package.frame) => {
                            a.run(&package, config.slowdown, &task_stop)
                        }
                        _ => Err("the package's frame is not prepared".to_owned()),
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
                session.handle_message(start.elapsed(), message, engine);
                // A cancelled package stops now, freeing its memory and the cores.
                if let Some((id, _, stop)) = &running {
                    if session.is_cancelled(*id) {
                        stop.cancel();
                    }
                }
            }
            outcome = async { (&mut running.as_mut().expect("guarded by the select condition").1).await }, if running.is_some() => {
                let (id, _, _) = running.take().expect("guarded by the select condition");
                let outcome = outcome.unwrap_or_else(|join| Err(format!("package task failed: {join}")));
                session.package_finished(start.elapsed(), id, outcome);
            }
            built = async { (&mut preparing.as_mut().expect("guarded by the select condition").1).await }, if preparing.is_some() => {
                let (key, _) = preparing.take().expect("guarded by the select condition");
                let outcome = built
                    .unwrap_or_else(|join| Err(format!("frame set-up failed: {join}")))
                    .map(|active| frames.insert(active));
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
