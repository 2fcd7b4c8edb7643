//! A quinn-style `Pair` harness for the farm: the master's sans-IO core and
//! N worker sessions joined by in-memory queues, on a virtual clock that
//! jumps to the next deadline. Workers render for real (so images can be
//! compared with the single-process render), but a package *takes* virtual
//! time from a deterministic cost model (its samples times the worker's
//! slowdown), so schedules, faults and load balance replay exactly, in
//! milliseconds, without sockets or sleeps.
//!
//! Knobs: per-message latency, per-worker slowdown, silent kills (the master
//! hears nothing), link closes, partitions (every message either way is
//! lost), duplicated results, draining. [`Pair::drive`] runs until a
//! predicate holds and fails the test, never hangs, when a bound is hit.

use std::collections::BTreeMap;
use std::time::Duration;

use vtfarm_master::FarmRules;
use vtfarm_master::{ConnId, Journal, MasterCore, Output, Peer};
use vtfarm_proto::{FrameDone, JobScene, Message, PackageResult, SceneData, WireJob};
use vtfarm_worker::engine::PreparedFrames;
use vtfarm_worker::{Engine, SessionEnd, Task, WorkerSession};

/// Virtual time one traced sample costs a worker of slowdown 1.
const SAMPLE_COST: Duration = Duration::from_micros(20);

/// Where a message goes.
#[derive(Debug)]
enum Event {
    ToMaster(ConnId, Box<Message>),
    ToWorker(usize, u64, Box<Message>),
    /// A worker's package finished (for the session of that epoch).
    PackageDone(usize, u64, Box<PackageResult>),
    /// A worker's link closed (the master notices at once).
    Closed(ConnId),
}

/// A simulated worker.
pub(crate) struct SimWorker {
    pub(crate) name: String,
    /// Package time multiplier (≥ 1).
    pub(crate) slowdown: f64,
    /// Every message either way is lost while set.
    pub(crate) partitioned: bool,
    /// Each result reaches the master twice.
    pub(crate) duplicate_results: bool,
    conn: ConnId,
    /// Bumped on every (re)connection, so that old events are dropped.
    epoch: u64,
    session: Option<WorkerSession>,
    engine: Engine,
    frames: PreparedFrames,
    /// Results this worker's sessions sent.
    pub(crate) results_sent: u32,
}

impl SimWorker {
    /// Whether the worker is connected and holds a running package.
    pub(crate) fn is_running_a_package(&self) -> bool {
        self.session.as_ref().is_some_and(|s| s.running().is_some())
    }

    /// Whether the worker's session is up.
    pub(crate) fn is_connected(&self) -> bool {
        self.session.is_some()
    }
}

/// The master, its workers and one submitter on a virtual clock.
pub(crate) struct Pair {
    pub(crate) master: MasterCore,
    pub(crate) now: Duration,
    /// Delay of every message.
    pub(crate) latency: Duration,
    pub(crate) workers: Vec<SimWorker>,
    /// Everything the master sent the submitter, in order.
    pub(crate) to_submitter: Vec<Message>,
    scene: Option<SceneData>,
    events: BTreeMap<(Duration, u64), Event>,
    next_seq: u64,
    next_conn: ConnId,
    /// Steps taken so far (a bound against livelock).
    pub(crate) steps: u64,
    /// The submitter's current connection (`None` while it is away).
    submitter: Option<ConnId>,
    /// Every frame a `FrameStart` announced, in order.
    pub(crate) frame_starts: Vec<(u64, u32)>,
    /// Base frames rasterized into a finished frame's buffers.
    pub(crate) bases_in_reused_buffers: usize,
    rules: FarmRules,
    /// The job journal of a persistent master, in a temporary state directory.
    journal: Option<(Journal, tempfile::TempDir)>,
}

impl Pair {
    /// A pair whose master keeps its jobs in memory.
    pub(crate) fn new(rules: FarmRules) -> Pair {
        Pair::with_master(MasterCore::new(rules.clone()), rules, None)
    }

    /// A pair whose master journals its jobs in a temporary state directory.
    pub(crate) fn persistent(rules: FarmRules) -> Pair {
        let dir = tempfile::tempdir().unwrap();
        let journal = Journal::open(dir.path()).unwrap();
        let master = MasterCore::persistent(rules.clone());
        Pair::with_master(master, rules, Some((journal, dir)))
    }

    fn with_master(
        master: MasterCore,
        rules: FarmRules,
        journal: Option<(Journal, tempfile::TempDir)>,
    ) -> Pair {
        let mut pair = Pair {
            master,
            now: Duration::ZERO,
            latency: Duration::from_millis(1),
            workers: Vec::new(),
            to_submitter: Vec::new(),
            scene: None,
            events: BTreeMap::new(),
            next_seq: 0,
            next_conn: 1,
            steps: 0,
            submitter: None,
            frame_starts: Vec::new(),
            bases_in_reused_buffers: 0,
            rules,
            journal,
        };
        pair.connect_submitter();
        pair
    }

    fn connect_submitter(&mut self) {
        let conn = self.next_conn;
        self.next_conn += 1;
        self.submitter = Some(conn);
        let peer = Peer::Submitter {
            address: "pair".into(),
        };
        self.master.connected(self.now, conn, peer);
    }

    /// The submitter's connection drops (the master hears of it at once).
    pub(crate) fn drop_submitter(&mut self) {
        if let Some(conn) = self.submitter.take() {
            self.master.disconnected(self.now, conn);
            self.flush();
        }
    }

    /// A submitter connects and attaches to `job` from the first frame it lacks.
    pub(crate) fn attach_submitter(&mut self, job: u64) {
        self.connect_submitter();
        let from_frame = self.frames_done().len() as u32;
        let conn = self.submitter.expect("just connected");
        self.master
            .message(self.now, conn, Message::AttachJob { job, from_frame });
        self.flush();
    }

    /// Kills the master and starts a new one on the same journal: every
    /// connection is lost, the workers reconnect at once, the submitter
    /// stays away until it attaches again.
    pub(crate) fn restart_master(&mut self) {
        let (journal, _) = self.journal.as_ref().expect("a persistent pair");
        let journal = journal.clone();
        self.master = MasterCore::persistent(self.rules.clone());
        self.events.clear();
        self.submitter = None;
        let loaded = journal.load();
        for damaged in loaded.damaged {
            self.master.restore_damaged(damaged);
        }
        for stored in loaded.jobs {
            self.master.restore(self.now, stored);
        }
        for w in 0..self.workers.len() {
            if self.workers[w].session.is_some() {
                self.connect(w);
            }
        }
        self.flush();
    }

    /// The job id the master gave the submitter.
    pub(crate) fn job_id(&self) -> Option<u64> {
        self.to_submitter.iter().find_map(|m| match m {
            Message::JobAccepted { job, .. } => Some(*job),
            _ => None,
        })
    }

    /// Adds a worker that connects now; returns its index.
    pub(crate) fn add_worker(&mut self, name: &str, slowdown: f64) -> usize {
        self.workers.push(SimWorker {
            name: name.to_owned(),
            slowdown,
            partitioned: false,
            duplicate_results: false,
            conn: 0,
            epoch: 0,
            session: None,
            engine: Engine::new(None),
            frames: PreparedFrames::default(),
            results_sent: 0,
        });
        let w = self.workers.len() - 1;
        self.connect(w);
        w
    }

    /// (Re)connects worker `w` with a fresh session (its scene cache stays).
    pub(crate) fn connect(&mut self, w: usize) {
        let conn = self.next_conn;
        self.next_conn += 1;
        let worker = &mut self.workers[w];
        worker.conn = conn;
        worker.epoch += 1;
        worker.session = Some(WorkerSession::new(self.now));
        worker.frames = PreparedFrames::default();
        let peer = Peer::Worker {
            name: worker.name.clone(),
            threads: 1,
            address: "pair".into(),
        };
        self.master.connected(self.now, conn, peer);
        self.flush();
    }

    /// Kills worker `w` silently (kill -9 without a FIN: the master must
    /// notice from the missing heartbeats).
    pub(crate) fn kill(&mut self, w: usize) {
        self.workers[w].session = None;
        self.workers[w].epoch += 1;
    }

    /// Tells worker `w` to drain (SIGTERM).
    pub(crate) fn drain(&mut self, w: usize) {
        if let Some(session) = self.workers[w].session.as_mut() {
            session.drain(self.now);
        }
        self.flush();
    }

    /// Calls the master's core now (an input from outside the farm, like
    /// the HTTP side's) and routes what follows.
    pub(crate) fn act<R>(&mut self, call: impl FnOnce(&mut MasterCore, Duration) -> R) -> R {
        let answer = call(&mut self.master, self.now);
        self.flush();
        answer
    }

    /// Submits `job` with its scene (the submitter answers scene requests).
    pub(crate) fn submit(&mut self, job: WireJob, scene: SceneData) {
        let job = WireJob {
            scene: JobScene::Hash(scene.hash),
            ..job
        };
        self.scene = Some(scene);
        let conn = self.submitter.expect("the submitter is connected");
        self.master
            .message(self.now, conn, Message::SubmitJob { job });
        self.flush();
    }

    /// The finished frames the submitter kept, in order (like
    /// `run_remote_job`, it skips a frame it has already).
    pub(crate) fn frames_done(&self) -> Vec<&FrameDone> {
        let mut frames: Vec<&FrameDone> = Vec::new();
        for m in &self.to_submitter {
            match m {
                Message::FrameDone(done) if done.frame as usize == frames.len() => {
                    frames.push(done)
                }
                _ => {}
            }
        }
        frames
    }

    /// Whether the submitter was told its job failed.
    pub(crate) fn job_failed(&self) -> Option<&Vec<String>> {
        self.to_submitter.iter().find_map(|m| match m {
            Message::JobFailed { errors, .. } => Some(errors),
            _ => None,
        })
    }

    /// Runs until `done` holds; panics (with the state) after `max_virtual`
    /// of virtual time or a million steps.
    pub(crate) fn drive(&mut self, max_virtual: Duration, mut done: impl FnMut(&Pair) -> bool) {
        assert!(
            self.drive_bounded(max_virtual, 1_000_000, &mut done),
            "not done after {:?} of virtual time ({} steps); the submitter got {:?}",
            self.now,
            self.steps,
            self.to_submitter
                .iter()
                .map(Message::name)
                .collect::<Vec<_>>()
        );
    }

    /// Runs until `done` holds (true), or a bound is hit (false).
    pub(crate) fn drive_bounded(
        &mut self,
        max_virtual: Duration,
        max_steps: u64,
        done: &mut impl FnMut(&Pair) -> bool,
    ) -> bool {
        let limit = self.now + max_virtual;
        for _ in 0..max_steps {
            if done(self) {
                return true;
            }
            if !self.step(limit) {
                return done(self);
            }
        }
        done(self)
    }

    /// Advances to the next event or deadline and handles it; false when
    /// nothing is due before `limit`.
    pub(crate) fn step(&mut self, limit: Duration) -> bool {
        self.steps += 1;
        let event_at = self.events.keys().next().map(|k| k.0);
        let master_at = self.master.poll_timeout();
        let worker_at = (self.workers.iter().enumerate())
            .filter_map(|(w, x)| x.session.as_ref().map(|s| (s.poll_timeout(), w)))
            .min();
        let next = [event_at, master_at, worker_at.map(|(t, _)| t)]
            .into_iter()
            .flatten()
            .min();
        let Some(next) = next.filter(|&t| t <= limit) else {
            return false;
        };
        self.now = self.now.max(next);
        if event_at == Some(next) {
            let (_, event) = self.events.pop_first().expect("an event is due");
            self.deliver(event);
        } else if master_at == Some(next) {
            self.master.handle_timeout(self.now);
        } else if let Some((_, w)) = worker_at {
            let session = self.workers[w].session.as_mut().expect("chosen as live");
            session.handle_timeout(self.now);
        }
        self.flush();
        true
    }

    fn schedule(&mut self, at: Duration, event: Event) {
        self.events.insert((at, self.next_seq), event);
        self.next_seq += 1;
    }

    fn deliver(&mut self, event: Event) {
        let now = self.now;
        match event {
            Event::ToMaster(conn, message) => {
                if self.submitter == Some(conn) || self.workers.iter().any(|w| w.conn == conn) {
                    self.master.message(now, conn, *message);
                }
            }
            Event::ToWorker(w, epoch, message) => {
                let worker = &mut self.workers[w];
                match worker.session.as_mut() {
                    Some(session) if worker.epoch == epoch => {
                        session.handle_message(now, *message, &mut worker.engine)
                    }
                    _ => {}
                }
            }
            Event::PackageDone(w, epoch, result) => {
                let worker = &mut self.workers[w];
                match worker.session.as_mut() {
                    Some(session) if worker.epoch == epoch => {
                        session.package_finished(now, result.id, Ok(*result))
                    }
                    _ => {}
                }
            }
            Event::Closed(conn) => self.master.disconnected(now, conn),
        }
    }

    /// Routes everything the master and the sessions want done, until quiet.
    fn flush(&mut self) {
        loop {
            let mut quiet = true;
            while let Some(output) = self.master.poll_output() {
                quiet = false;
                self.route_master_output(output);
            }
            for w in 0..self.workers.len() {
                quiet &= !self.run_worker_outputs(w);
            }
            if quiet {
                return;
            }
        }
    }

    fn route_master_output(&mut self, output: Output) {
        let at = self.now + self.latency;
        match output {
            Output::Send(conn, message) if Some(conn) == self.submitter => {
                if let Message::SceneRequest { hash } = *message {
                    let data = self.scene.clone().filter(|s| s.hash == hash);
                    if let Some(data) = data {
                        let reply = Message::SceneData(data);
                        self.schedule(at, Event::ToMaster(conn, Box::new(reply)));
                    }
                } else {
                    self.to_submitter.push(*message);
                }
            }
            Output::Send(conn, message) => {
                if let Message::FrameStart(start) = message.as_ref() {
                    self.frame_starts.push((start.job, start.frame));
                }
                let reachable = (self.workers.iter())
                    .position(|w| w.conn == conn)
                    .filter(|&w| !self.workers[w].partitioned);
                if let Some(w) = reachable {
                    let epoch = self.workers[w].epoch;
                    self.schedule(at, Event::ToWorker(w, epoch, message));
                }
            }
            Output::Close(conn, _) => {
                // The driver drops the connection: the worker's session ends.
                if let Some(w) = self.workers.iter().position(|w| w.conn == conn) {
                    self.kill(w);
                }
                self.master.disconnected(self.now, conn);
            }
            Output::RasterizeBase(request) => {
                // The base frame takes no virtual time here.
                let (job, frame) = (request.job, request.frame);
                self.bases_in_reused_buffers += usize::from(request.reuses_buffers());
                let base = request.rasterize();
                (self.master).base_frame_ready(self.now, job, frame, base);
            }
            Output::Persist(record) => {
                let (journal, _) = self
                    .journal
                    .as_ref()
                    .expect("only a persistent core persists");
                let (job, frame) = (record.job(), record.frame());
                let outcome = journal.write(record).map_err(|e| e.to_string());
                let written = vtfarm_master_core::Written {
                    job,
                    frame,
                    outcome,
                };
                self.master.journal_written(self.now, written);
            }
            Output::Replay { conn, job, frames } => {
                let (journal, _) = self
                    .journal
                    .as_ref()
                    .expect("only a persistent core replays");
                let journal = journal.clone();
                for frame in frames {
                    match journal.frame(job, frame) {
                        Ok(done) if Some(conn) == self.submitter => {
                            self.to_submitter.push(Message::FrameDone(done));
                        }
                        Ok(_) => {}
                        Err(e) => {
                            (self.master).replay_failed(self.now, conn, job, frame, e.to_string())
                        }
                    }
                }
            }
        }
    }

    /// Carries out worker `w`'s tasks and sends its messages; true if it did anything.
    fn run_worker_outputs(&mut self, w: usize) -> bool {
        let at = self.now + self.latency;
        let worker = &mut self.workers[w];
        let Some(session) = worker.session.as_mut() else {
            return false;
        };
        let mut busy = false;
        let mut events = Vec::new();
        while let Some(task) = session.poll_task() {
            busy = true;
            match task {
                Task::PrepareFrame(start) => {
                    let key = (start.job, start.frame);
                    let outcome = worker.engine.start_frame(start);
                    let outcome = outcome.map(|frame| worker.frames.insert(frame));
                    session.frame_prepared(self.now, key, outcome);
                }
                Task::RunPackage(package) => {
                    let frame = (worker.frames.get(package.job, package.frame))
                        .expect("the session runs packages of prepared frames only");
                    let unlimited = vtfarm_vertex::Stop::with_budget(u64::MAX);
                    let mut result =
                        (frame.run(&package, 1.0, &unlimited)).expect("packages render");
                    let samples: u64 = (result.triangle_samples.iter())
                        .map(|&s| u64::from(s) + 1)
                        .sum();
                    let cost = SAMPLE_COST.mul_f64(samples as f64 * worker.slowdown);
                    result.busy_micros = cost.as_micros() as u64;
                    let epoch = worker.epoch;
                    events.push((
                        self.now + cost,
                        Event::PackageDone(w, epoch, Box::new(result)),
                    ));
                }
            }
        }
        while let Some(message) = session.poll_message() {
            busy = true;
            if worker.partitioned {
                continue;
            }
            if matches!(message, Message::PackageResult(_)) {
                worker.results_sent += 1;
                if worker.duplicate_results {
                    events.push((at, Event::ToMaster(worker.conn, Box::new(message.clone()))));
                }
            }
            events.push((at, Event::ToMaster(worker.conn, Box::new(message))));
        }
        if let Some(end) = session.poll_end() {
            busy = true;
            worker.session = None;
            worker.epoch += 1;
            if end == SessionEnd::Drained {
                // Goodbye: the link closes and the master hears it at once.
                events.push((at, Event::Closed(worker.conn)));
            }
        }
        for (at, event) in events {
            self.schedule(at, event);
        }
        busy
    }
}
