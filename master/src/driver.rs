//! The async driver around [`MasterCore`]: one task owns the core, feeds it
//! connections, messages and deadlines, and carries out its outputs. Links
//! come from the QUIC server or, for the embedded master, from in-process
//! pairs; the core cannot tell them apart.

use std::collections::BTreeMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;
use vtfarm_proto::JobId;

use tokio::sync::mpsc::{UnboundedReceiver, UnboundedSender, unbounded_channel};
use tokio::sync::{oneshot, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tracing::debug;
use vtfarm_master_core::view::{GlareRequest, ViewError, ViewFigures, ViewRequest};
use vtfarm_master_core::{ConnId, FarmRules, JobControlError, MasterCore, Output, Peer};
use vtfarm_proto::{JobAction, JobSummary, Message, StatusReply};
use vtfarm_transport::Link;

use crate::journal::{Journal, JournalWriter};
use vtfarm_master_core::{EncodedFrame, Written};

/// Called when the core drops a connection (closes the QUIC connection).
pub type Closer = Box<dyn FnOnce(&str) + Send>;

enum Input {
    Connected {
        conn: ConnId,
        peer: Peer,
        tx: UnboundedSender<Message>,
        closer: Option<Closer>,
    },
    Message {
        conn: ConnId,
        message: Box<Message>,
    },
    Disconnected {
        conn: ConnId,
    },
    /// A base frame and ID buffer rasterized on the blocking pool.
    BaseFrame {
        job: JobId,
        frame: u32,
        base: vtfarm_master_core::BaseFrame,
    },
    /// A finished frame encoded on the blocking pool.
    FrameEncoded(Box<EncodedFrame>),
    /// How writing a journal record went (from the journal's thread).
    Journaled(Written),
    /// The glare figures of a view's stage, computed on their thread.
    ViewFigures {
        generation: u64,
        quality: vtfarm_vertex::Quality,
        figures: ViewFigures,
    },
    /// A user's request about a job (from the HTTP API and dashboard).
    Control {
        job: JobId,
        action: JobAction,
        who: String,
        reply: oneshot::Sender<Result<JobSummary, JobControlError>>,
    },
    /// Move the interactive view's eye (from the HTTP view).
    Steer {
        request: ViewRequest,
        reply: oneshot::Sender<Result<JobId, ViewError>>,
    },
    /// Read the core's state (for the HTTP view); changes nothing.
    Inspect(Box<dyn FnOnce(&MasterCore) + Send>),
    /// End the master task (dropping every connection).
    Stop,
}

/// A running master: attach links to it.
#[derive(Clone)]
pub struct MasterHandle {
    inputs: UnboundedSender<Input>,
    next_conn: Arc<AtomicU64>,
    changes: watch::Receiver<u64>,
}

impl MasterHandle {
    /// Hands a connection that passed its handshake to the master.
    pub fn attach(&self, peer: Peer, link: Link, closer: Option<Closer>) -> ConnId {
        let conn = ConnId(self.next_conn.fetch_add(1, Ordering::Relaxed));
        let Link { tx, mut rx, .. } = link;
        let _ = self.inputs.send(Input::Connected {
            conn,
            peer,
            tx,
            closer,
        });
        let inputs = self.inputs.clone();
        tokio::spawn(async move {
            while let Some(message) = rx.recv().await {
                if inputs
                    .send(Input::Message {
                        conn,
                        message: Box::new(message),
                    })
                    .is_err()
                {
                    return;
                }
            }
            let _ = inputs.send(Input::Disconnected { conn });
        });
        conn
    }

    /// Runs `read` on the core between two inputs and returns its answer;
    /// `None` once the master has stopped.
    pub async fn inspect<R: Send + 'static>(
        &self,
        read: impl FnOnce(&MasterCore) -> R + Send + 'static,
    ) -> Option<R> {
        let (tx, rx) = oneshot::channel();
        let read = Box::new(move |core: &MasterCore| {
            let _ = tx.send(read(core));
        });
        self.inputs.send(Input::Inspect(read)).ok()?;
        rx.await.ok()
    }

    /// Cancels, pauses, resumes, requeues or re-prioritises a job
    /// ([`MasterCore::control_job`]) on behalf of `who`; `None` once the
    /// master has stopped.
    pub async fn control_job(
        &self,
        job: JobId,
        action: JobAction,
        who: String,
    ) -> Option<Result<JobSummary, JobControlError>> {
        let (reply, answer) = oneshot::channel();
        let control = Input::Control {
            job,
            action,
            who,
            reply,
        };
        self.inputs.send(control).ok()?;
        answer.await.ok()
    }

    /// Moves the interactive view's eye ([`MasterCore::steer_view`]); `None`
    /// once the master has stopped.
    pub async fn steer_view(&self, request: ViewRequest) -> Option<Result<JobId, ViewError>> {
        let (reply, answer) = oneshot::channel();
        self.inputs.send(Input::Steer { request, reply }).ok()?;
        answer.await.ok()
    }

    /// Ticks after every input the core handled (a connection, a message,
    /// a deadline): watchers re-read the state when it moves.
    pub fn changes(&self) -> watch::Receiver<u64> {
        self.changes.clone()
    }

    /// Waits until the master's status satisfies `done`, re-reading it after
    /// every input the core handles (woken by [`MasterHandle::changes`], no
    /// polling); `None` once the master has stopped. Callers bound the wait.
    pub async fn wait_for_status(
        &self,
        done: impl Fn(&StatusReply) -> bool,
    ) -> Option<StatusReply> {
        let mut changes = self.changes();
        loop {
            changes.mark_unchanged();
            let status = self.inspect(|core| core.status()).await?;
            if done(&status) {
                return Some(status);
            }
            changes.changed().await.ok()?;
        }
    }

    /// Ends the master task: its connections close and the workers' sessions end.
    pub fn stop(&self) {
        let _ = self.inputs.send(Input::Stop);
    }
}

/// Starts a master task that keeps its jobs in memory only.
pub fn spawn_master(rules: FarmRules) -> (MasterHandle, JoinHandle<()>) {
    spawn(MasterCore::new(rules), None)
}

/// Starts a master task that journals its jobs and resumes those it finds.
pub fn spawn_persistent_master(
    rules: FarmRules,
    journal: Journal,
) -> (MasterHandle, JoinHandle<()>) {
    spawn(MasterCore::persistent(rules), Some(journal))
}

fn spawn(core: MasterCore, journal: Option<Journal>) -> (MasterHandle, JoinHandle<()>) {
    let (inputs, rx) = unbounded_channel();
    let (changed, changes) = watch::channel(0);
    let handle = MasterHandle {
        inputs,
        next_conn: Arc::new(AtomicU64::new(1)),
        changes,
    };
    let task = tokio::spawn(run(core, handle.inputs.clone(), rx, journal, changed));
    (handle, task)
}

struct Connection {
    tx: UnboundedSender<Message>,
    closer: Option<Closer>,
}

async fn run(
    mut core: MasterCore,
    feedback: UnboundedSender<Input>,
    mut inputs: UnboundedReceiver<Input>,
    journal: Option<Journal>,
    changed: watch::Sender<u64>,
) {
    let start = Instant::now();
    // The jobs' times: the core adds its `now` to this reading.
    let wall = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH);
    core.set_wall_clock(wall.map_or(0, |t| t.as_millis() as u64));
    let mut conns: BTreeMap<ConnId, Connection> = BTreeMap::new();
    // The view's glare figures: one computation at a time; a stage shown
    // meanwhile replaces the one waiting (only the stage on view gets them).
    let mut glare_running = false;
    let mut glare_next: Option<GlareRequest> = None;
    let glare = GlareThread::start(feedback.clone());
    if let Some(journal) = &journal {
        let loaded = tokio::task::block_in_place(|| journal.load());
        for damaged in loaded.damaged {
            core.restore_damaged(damaged);
        }
        for stored in loaded.jobs {
            core.restore(start.elapsed(), stored);
        }
        for study in loaded.studies {
            core.restore_study(start.elapsed(), study);
        }
    }
    // Records are written off this task (a finished frame is compressed and
    // written while the next results come in); replays wait for them. How
    // each went comes back as an input.
    let writer = journal.clone().map(|journal| {
        let feedback = feedback.clone();
        JournalWriter::new(journal, move |written| {
            let _ = feedback.send(Input::Journaled(written));
        })
    });
    loop {
        // The scheduler's next deadline, or idle for a while.
        let deadline = start
            + core
                .poll_timeout()
                .unwrap_or(start.elapsed() + Duration::from_secs(3600));
        tokio::select! {
            input = inputs.recv() => {
                let Some(input) = input else { return };
                if matches!(input, Input::Stop) {
                    return;
                }
                if let Input::Inspect(read) = input {
                    // A read: nothing moved, so no tick for the watchers.
                    read(&core);
                    continue;
                }
                let now = start.elapsed();
                // Inside a block so the whole frame's CPU work (rasterizing,
                // compositing) does not starve the I/O tasks.
                tokio::task::block_in_place(|| match input {
                    Input::Connected { conn, peer, tx, closer } => {
                        conns.insert(conn, Connection { tx, closer });
                        core.connected(now, conn, peer);
                    }
                    Input::Message { conn, message } => {
                        if conns.contains_key(&conn) {
                            core.message(now, conn, *message);
                        }
                    }
                    Input::Disconnected { conn } => {
                        if conns.remove(&conn).is_some() {
                            core.disconnected(now, conn);
                        }
                    }
                    Input::BaseFrame { job, frame, base } => {
                        core.base_frame_ready(now, job, frame, base);
                    }
                    Input::FrameEncoded(encoded) => core.frame_encoded(now, *encoded),
                    Input::Journaled(written) => core.journal_written(now, written),
                    Input::ViewFigures { generation, quality, figures } => {
                        core.view_figures_ready(now, generation, quality, figures);
                        glare_running = false;
                        if let Some(request) = glare_next.take() {
                            glare_running = true;
                            glare.compute(request);
                        }
                    }
                    Input::Control { job, action, who, reply } => {
                        let _ = reply.send(core.control_job(now, job, action, &who));
                    }
                    Input::Steer { request, reply } => {
                        let _ = reply.send(core.steer_view(now, request));
                    }
                    Input::Inspect(read) => read(&core),
                    Input::Stop => {} // returned above
                });
            }
            _ = tokio::time::sleep_until(deadline) => core.handle_timeout(start.elapsed()),
        }
        while let Some(output) = core.poll_output() {
            match output {
                Output::Send(conn, message) => {
                    if let Some(c) = conns.get(&conn) {
                        let _ = c.tx.send(*message);
                    }
                }
                Output::Close(conn, reason) => {
                    if let Some(c) = conns.remove(&conn) {
                        debug!(%conn, "closing: {reason}");
                        if let Some(close) = c.closer {
                            close(&reason);
                        }
                        core.disconnected(start.elapsed(), conn);
                    }
                }
                Output::RasterizeBase(request) => {
                    // Off the driver's task: results keep flowing meanwhile.
                    let feedback = feedback.clone();
                    tokio::task::spawn_blocking(move || {
                        let (job, frame) = (request.job, request.frame);
                        let base = request.rasterize();
                        let _ = feedback.send(Input::BaseFrame { job, frame, base });
                    });
                }
                Output::EncodeFrame(request) if request.for_dashboard_only() => {
                    // A view's frame for the dashboard's list, here as
                    // before: on a thread it would compete with the figures
                    // of the stage on view, asked for just before it.
                    let encoded = tokio::task::block_in_place(|| request.encode());
                    core.frame_encoded(start.elapsed(), encoded);
                }
                Output::EncodeFrame(request) => {
                    // Off the driver's task too: the next frames' results
                    // and packages do not wait for a finished frame's bytes.
                    let feedback = feedback.clone();
                    tokio::task::spawn_blocking(move || {
                        let encoded = Box::new(request.encode());
                        let _ = feedback.send(Input::FrameEncoded(encoded));
                    });
                }
                Output::ViewGlare(request) => {
                    if glare_running {
                        glare_next = Some(request);
                    } else {
                        glare_running = true;
                        glare.compute(request);
                    }
                }
                Output::Persist(record) => {
                    if let Some(writer) = &writer {
                        // Waits only when the disk is behind by a few frames.
                        tokio::task::block_in_place(|| writer.write(record));
                    }
                }
                Output::Replay { conn, job, frames } => {
                    let (Some(journal), Some(writer), Some(c)) =
                        (&journal, &writer, conns.get(&conn))
                    else {
                        continue;
                    };
                    tokio::task::block_in_place(|| writer.flush());
                    for frame in frames {
                        match tokio::task::block_in_place(|| journal.frame(job, frame)) {
                            Ok(done) => {
                                let _ = c.tx.send(Message::FrameDone(done));
                            }
                            // Rendered again, or the submitter is told it is lost.
                            Err(e) => {
                                core.replay_failed(start.elapsed(), conn, job, frame, e.to_string())
                            }
                        }
                    }
                }
            }
        }
        changed.send_modify(|tick| *tick += 1);
    }
}

/// How much lower than the master's other work the view's glare figures
/// run (a `nice` increment): below the workers' later stages
/// (`vtfarm_worker`'s 10) too, so on a machine the master shares with its
/// workers the figures of a stage on view take only the cores that
/// rendering the next stage leaves, and never delay it.
const VIEW_FIGURES_NICENESS: i32 = 15;

/// The thread that computes the view's glare figures, one request at a
/// time, at [`VIEW_FIGURES_NICENESS`]; it ends with the driver.
struct GlareThread {
    requests: std::sync::mpsc::Sender<GlareRequest>,
}

impl GlareThread {
    fn start(feedback: UnboundedSender<Input>) -> GlareThread {
        let (requests, incoming) = std::sync::mpsc::channel::<GlareRequest>();
        let spawned = std::thread::Builder::new()
            .name("view-figures".into())
            .spawn(move || {
                vtfarm_transport::lower_this_thread(VIEW_FIGURES_NICENESS);
                for request in incoming {
                    let figures = request.compute();
                    let (generation, quality) = (request.generation, request.quality);
                    let figures = Input::ViewFigures {
                        generation,
                        quality,
                        figures,
                    };
                    if feedback.send(figures).is_err() {
                        return;
                    }
                }
            });
        if let Err(e) = spawned {
            tracing::warn!("cannot start the view's figures thread: {e}");
        }
        GlareThread { requests }
    }

    /// Computes `request`'s figures and hands them back as an input.
    fn compute(&self, request: GlareRequest) {
        let _ = self.requests.send(request);
    }
}
