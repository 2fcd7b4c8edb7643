//! The journal under damage, through the real submitter: a persistent
//! master on 127.0.0.1 (QUIC), a local worker, and `run_remote_job` as
//! `vtfarm submit --attach` runs it. A flipped byte in each record kind, a
//! truncated, an emptied and a missing frame, a frame damaged while the
//! master runs, a full disk, and two submitters on one job: every frame a
//! submitter gets is byte-identical to a clean run's, or it fails with an
//! error naming the job or frame; no job directory is deleted; every wait
//! is bounded and ends on a protocol event.

#[path = "support/frame.rs"]
mod frame;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;
use vtfarm_proto::JobId;

use frame::small_frame;
use glam::Vec3;
use tokio::task::JoinHandle;
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_embedded::local_worker;
use vtfarm_master::journal::Storage;
use vtfarm_master::{ConnId, FarmRules};
use vtfarm_master::{Journal, MasterHandle, server, spawn_persistent_master};
use vtfarm_method::MethodKind;
use vtfarm_proto::{HandshakePolicy, Message, SceneData, WireJob};
use vtfarm_render::FrameSetup;
use vtfarm_submit::{
    FinishedFrame, JobError, JobEvent, JobOptions, RemoteJob, run_remote_job, wire_job,
};
use vtfarm_transport::ClusterConfig;
use vtfarm_transport::client::ClientOptions;
use vtfarm_worker::WorkerConfig;

/// Every wait on the network is bounded by this.
const WAIT: Duration = Duration::from_secs(120);

const FRAMES: usize = 4;

/// The job every test runs: four small cockpit frames.
fn job() -> (WireJob, SceneData) {
    let c = cockpit(&CockpitConfig {
        detail: 0.1,
        ..CockpitConfig::default()
    });
    let setups: Vec<FrameSetup> = (0..FRAMES)
        .map(|k| small_frame(&c, Vec3::new(0.01, 0.0, 0.0) * k as f32))
        .collect();
    let data = SceneData::from_scene(&c.scene);
    let options = JobOptions {
        method: MethodKind::VertexTracing,
        aux: false,
    };
    let job = wire_job(
        "journal",
        &data,
        &setups,
        &c.cover_glass_triangles(),
        options,
    );
    (job, data)
}

/// A store that fails frame writes with "No space left on device" while
/// `full` is set, as a full disk does (job and scene records still fit).
struct FullDisk {
    full: AtomicBool,
}

impl Storage for FullDisk {
    fn write_atomic(&self, path: &Path, bytes: &[u8]) -> std::io::Result<()> {
        let is_frame = (path.file_name().and_then(|n| n.to_str()))
            .is_some_and(|n| n.bytes().all(|b| b.is_ascii_digit()));
        if is_frame && self.full.load(Ordering::SeqCst) {
            return Err(std::io::Error::from_raw_os_error(libc::ENOSPC));
        }
        vtfarm_master::journal::Disk.write_atomic(path, bytes)
    }
}

/// A persistent master on `state` with one local worker.
struct Master {
    handle: MasterHandle,
    task: JoinHandle<()>,
    endpoint: quinn::Endpoint,
    options: ClientOptions,
}

impl Master {
    fn start(state: &Path, storage: Option<Arc<dyn Storage>>) -> Master {
        let identity = server::identity(state, &["127.0.0.1".into()]).unwrap();
        let endpoint = server::bind("127.0.0.1:0".parse().unwrap(), &identity).unwrap();
        let address = endpoint.local_addr().unwrap();
        let cluster = ClusterConfig::generate(&address.to_string(), &identity).unwrap();
        let journal = match storage {
            Some(storage) => Journal::open_with(state, storage).unwrap(),
            None => Journal::open(state).unwrap(),
        };
        let (handle, task) = spawn_persistent_master(FarmRules::default(), journal);
        let policy = HandshakePolicy::new(cluster.token.clone(), "test-master");
        tokio::spawn(server::serve(endpoint.clone(), policy, handle.clone()));
        let _worker = local_worker(&handle, "w1".into(), 2, WorkerConfig::default());
        let options = ClientOptions {
            master: cluster.master,
            token: cluster.token,
            fingerprint: cluster.fingerprint,
        };
        Master {
            handle,
            task,
            endpoint,
            options,
        }
    }

    /// Stops the master; its journal writer writes what is queued first.
    async fn stop(self) {
        self.endpoint.close(vtfarm_transport::CLOSE_NORMAL, b"stop");
        self.handle.stop();
        tokio::time::timeout(WAIT, self.task)
            .await
            .expect("the master stops")
            .unwrap();
    }

    /// Waits, woken by the core's changes and within [`WAIT`], until every
    /// frame's journal write has failed (`what` names it in the failure).
    async fn until_every_frame_write_failed(&self, what: &str) {
        let failures =
            |core: &vtfarm_master::MasterCore| core.telemetry().counters.journal_write_failures;
        let mut changes = self.handle.changes();
        tokio::time::timeout(WAIT, async {
            while self.handle.inspect(failures).await < Some(FRAMES as u64) {
                changes.changed().await.expect("the master runs");
            }
        })
        .await
        .expect(what);
    }

    /// Waits, as above, until `journal` holds every frame of job 1.
    async fn until_job_1_is_written(&self, journal: &Journal, what: &str) {
        let all_written = || (0..FRAMES as u32).all(|f| journal.frame(JobId(1), f).is_ok());
        let mut changes = self.handle.changes();
        tokio::time::timeout(WAIT, async {
            while !all_written() {
                changes.changed().await.expect("the master runs");
            }
        })
        .await
        .expect(what);
    }

    /// Runs a submitter from `start`, bounded; its warnings beside.
    async fn follow(
        &self,
        start: RemoteJob<'_>,
    ) -> (Result<Vec<FinishedFrame>, JobError>, Vec<String>) {
        let mut warnings = Vec::new();
        let run = run_remote_job(&self.options, start, |event| {
            if let JobEvent::Warning(w) = event {
                warnings.push(w);
            }
        });
        let outcome = tokio::time::timeout(WAIT, run)
            .await
            .expect("the submitter finished");
        (outcome, warnings)
    }
}

fn assert_identical(frames: &[FinishedFrame], reference: &[FinishedFrame], case: &str) {
    assert_eq!(frames.len(), reference.len(), "{case}: frame count");
    for (got, want) in frames.iter().zip(reference) {
        assert_eq!(got.frame, want.frame, "{case}");
        assert!(
            got.image == want.image,
            "{case}: frame {} differs",
            got.frame
        );
    }
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

fn flip_byte(path: &Path, at: usize) {
    let mut bytes = std::fs::read(path).unwrap();
    let at = at.min(bytes.len() - 1);
    bytes[at] ^= 0x5a;
    std::fs::write(path, bytes).unwrap();
}

fn job_dir(state: &Path) -> PathBuf {
    state.join("jobs/000000000001")
}

fn scene_file(state: &Path) -> PathBuf {
    let scenes = std::fs::read_dir(state.join("jobs/scenes")).unwrap();
    let scenes: Vec<PathBuf> = scenes.map(|e| e.unwrap().path()).collect();
    assert_eq!(scenes.len(), 1, "{scenes:?}");
    scenes[0].clone()
}

/// The damage done to a copy of the clean journal before a master starts on it.
#[derive(Clone, Copy, Debug)]
enum Damage {
    FlipFrame(u32, usize),
    TruncateFrame(u32),
    EmptyFrame(u32),
    MissingFrame(u32),
    FlipJob,
    FlipScene,
}

impl Damage {
    fn apply(self, state: &Path) {
        let frame = |f: u32| job_dir(state).join(format!("{f:06}"));
        match self {
            Damage::FlipFrame(f, at) => flip_byte(&frame(f), at),
            Damage::TruncateFrame(f) => {
                let bytes = std::fs::read(frame(f)).unwrap();
                std::fs::write(frame(f), &bytes[..bytes.len() / 2]).unwrap();
            }
            Damage::EmptyFrame(f) => std::fs::write(frame(f), b"").unwrap(),
            Damage::MissingFrame(f) => std::fs::remove_file(frame(f)).unwrap(),
            Damage::FlipJob => flip_byte(&job_dir(state).join("job"), 40),
            Damage::FlipScene => flip_byte(&scene_file(state), 1000),
        }
    }
}

/// Runs the job once on a clean master; returns its frames and the state
/// directory the master left (the job complete, every frame journaled).
async fn clean_run() -> (Vec<FinishedFrame>, tempfile::TempDir) {
    let state = tempfile::tempdir().unwrap();
    let master = Master::start(state.path(), None);
    let (job, scene) = job();
    let (frames, warnings) = master
        .follow(RemoteJob::Submit { job, scene: &scene })
        .await;
    let frames = frames.expect("the clean run completes");
    assert!(warnings.is_empty(), "{warnings:?}");
    master.stop().await;
    (frames, state)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn damaged_records_are_rendered_again_or_refused_by_name_and_never_deleted() {
    let (reference, clean) = clean_run().await;
    assert_eq!(reference.len(), FRAMES);
    let frame_cases = [
        Damage::FlipFrame(2, 0),
        Damage::FlipFrame(2, 7),
        Damage::FlipFrame(0, usize::MAX),
        Damage::TruncateFrame(1),
        Damage::EmptyFrame(3),
        Damage::MissingFrame(1),
    ];
    for damage in frame_cases {
        let state = tempfile::tempdir().unwrap();
        copy_dir(clean.path(), state.path());
        damage.apply(state.path());
        let master = Master::start(state.path(), None);
        let (frames, warnings) = master.follow(RemoteJob::Attach { job: JobId(1) }).await;
        let case = format!("{damage:?}");
        let frames = frames.unwrap_or_else(|e| panic!("{case}: {e}"));
        assert_identical(&frames, &reference, &case);
        // Told which frame is rendered again, and why.
        let (frame, why) = match damage {
            Damage::FlipFrame(f, _) | Damage::TruncateFrame(f) => (f, "checksum mismatch"),
            Damage::EmptyFrame(f) => (f, "too short"),
            Damage::MissingFrame(f) => (f, "missing"),
            Damage::FlipJob | Damage::FlipScene => unreachable!("frame cases only"),
        };
        let told = format!("frame {frame} of job 1 is rendered again");
        assert!(
            warnings
                .iter()
                .any(|w| w.contains(&told) && w.contains(why)),
            "{case}: {warnings:?}"
        );
        master.stop().await;
        assert!(
            job_dir(state.path()).join("job").exists(),
            "{case}: job kept"
        );
        if !matches!(damage, Damage::MissingFrame(_)) {
            let kept = std::fs::read_dir(job_dir(state.path())).unwrap();
            let kept = kept.filter(|e| {
                e.as_ref()
                    .unwrap()
                    .path()
                    .extension()
                    .is_some_and(|x| x == "damaged")
            });
            assert_eq!(kept.count(), 1, "{case}: the damaged frame is kept aside");
        }
    }
    for damage in [Damage::FlipJob, Damage::FlipScene] {
        let state = tempfile::tempdir().unwrap();
        copy_dir(clean.path(), state.path());
        damage.apply(state.path());
        let master = Master::start(state.path(), None);
        let (outcome, _) = master.follow(RemoteJob::Attach { job: JobId(1) }).await;
        let case = format!("{damage:?}");
        let error = outcome.expect_err(&case).to_string();
        let aside = state.path().join("jobs/damaged/000000000001");
        for needle in [
            "job 1 could not be read back",
            "checksum mismatch",
            &aside.display().to_string(),
        ] {
            assert!(error.contains(needle), "{case}: {error}");
        }
        assert!(aside.join("job").exists(), "{case}: the job is kept aside");
        assert!(
            std::fs::read_to_string(aside.join("why"))
                .unwrap()
                .contains("checksum")
        );
        master.stop().await;
        // A second start still knows why, and the files stay.
        let master = Master::start(state.path(), None);
        let (outcome, _) = master.follow(RemoteJob::Attach { job: JobId(1) }).await;
        assert!(
            outcome
                .expect_err(&case)
                .to_string()
                .contains("checksum mismatch")
        );
        master.stop().await;
        assert!(aside.join("job").exists(), "{case}: still kept");
    }
}

/// A frame damaged while the master runs (after it read the journal) is
/// found when a submitter attaches: rendered again, and the submitter,
/// told why, gets it.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_frame_damaged_after_start_is_rendered_again_for_the_submitter() {
    let (reference, clean) = clean_run().await;
    let master = Master::start(clean.path(), None);
    // The master has read the journal once it answers a status request.
    let status = master.handle.inspect(|core| core.status()).await.unwrap();
    assert!(
        status.queue.running.is_empty(),
        "the job was restored complete"
    );
    flip_byte(&job_dir(clean.path()).join("000001"), 100);
    std::fs::remove_file(job_dir(clean.path()).join("000003")).unwrap();
    let (frames, warnings) = master.follow(RemoteJob::Attach { job: JobId(1) }).await;
    assert_identical(
        &frames.expect("attached"),
        &reference,
        "damaged after start",
    );
    for frame in [
        "frame 1 of job 1 is rendered again",
        "frame 3 of job 1 is rendered again",
    ] {
        assert!(warnings.iter().any(|w| w.contains(frame)), "{warnings:?}");
    }
    let again = master
        .handle
        .inspect(|c| c.telemetry().counters.frames_rendered_again);
    assert_eq!(again.await, Some(2));
    master.stop().await;
    // Rendered again, the frames are journaled again.
    let journal = Journal::open(clean.path()).unwrap();
    assert_eq!(journal.frame(JobId(1), 1).unwrap().frame, 1);
    assert_eq!(journal.frame(JobId(1), 3).unwrap().frame, 3);
}

/// A full disk: every frame write fails. The submitter still gets every
/// frame and is told the master cannot journal them; `/metrics` counts the
/// failures; a second submitter attaching later gets them from memory.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_full_disk_reaches_the_submitter_and_metrics_and_frames_stay_in_memory() {
    let (reference, _clean) = clean_run().await;
    let state = tempfile::tempdir().unwrap();
    let disk = Arc::new(FullDisk {
        full: AtomicBool::new(true),
    });
    let master = Master::start(state.path(), Some(disk.clone()));
    let (job, scene) = job();
    let (frames, _) = master
        .follow(RemoteJob::Submit { job, scene: &scene })
        .await;
    assert_identical(&frames.expect("delivered"), &reference, "full disk");
    // Every frame's write has failed by now (woken by the core's changes;
    // a kept frame is tried again after each record that fits, and fails
    // again while the disk is full).
    master
        .until_every_frame_write_failed("every frame write failed")
        .await;
    let (again, warnings) = master.follow(RemoteJob::Attach { job: JobId(1) }).await;
    assert_identical(&again.expect("from memory"), &reference, "attached later");
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("No space left on device") && w.contains("kept in memory")),
        "{warnings:?}"
    );
    let app = vtfarm_master::http::router(
        master.handle.clone(),
        vtfarm_master::http::HttpAccess::new("t"),
    )
    .layer(axum::extract::connect_info::MockConnectInfo(
        "127.0.0.1:1".parse::<std::net::SocketAddr>().unwrap(),
    ));
    let request = axum::http::Request::get("/metrics").body(axum::body::Body::empty());
    let response = tower::ServiceExt::oneshot(app, request.unwrap())
        .await
        .unwrap();
    let body = axum::body::to_bytes(response.into_body(), 1 << 20)
        .await
        .unwrap();
    let text = String::from_utf8(body.to_vec()).unwrap();
    // Each frame's write failed, and a retry after a record that fitted.
    let counted = (text.lines())
        .find_map(|l| l.strip_prefix("vtfarm_journal_write_failures_total "))
        .and_then(|n| n.parse::<usize>().ok());
    assert!(counted.is_some_and(|n| n >= FRAMES), "{text}");
    // The disk has room again: the next job's writes succeed, and after
    // each the master writes one of the kept frames again.
    disk.full.store(false, Ordering::SeqCst);
    let (second, scene) = self::job();
    let submit = RemoteJob::Submit {
        job: second,
        scene: &scene,
    };
    let (frames, _) = master.follow(submit).await;
    assert_identical(&frames.expect("the second job"), &reference, "room again");
    let journal = Journal::open(state.path()).unwrap();
    master
        .until_job_1_is_written(
            &journal,
            "the kept frames were written once the disk had room",
        )
        .await;
    for f in 0..FRAMES as u32 {
        let done = journal.frame(JobId(1), f).unwrap();
        assert!(
            done.image == reference_wire(&reference, f),
            "frame {f} as sent"
        );
    }
    master.stop().await;
    assert!(job_dir(state.path()).join("job").exists());
}

/// The wire image a submitter's frame came from (frames are linear f32).
fn reference_wire(reference: &[FinishedFrame], frame: u32) -> vtfarm_proto::WireImage {
    let vtfarm_submit::FrameColor::Linear(image) = &reference[frame as usize].image else {
        panic!("linear frames");
    };
    vtfarm_proto::WireImage::from_pixels(image.width, image.height, &image.pixels)
}

/// Two submitters follow one job: the second attaches while the first
/// runs it, and both finish with every frame.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn two_submitters_on_one_job_both_get_every_frame() {
    let state = tempfile::tempdir().unwrap();
    let master = Arc::new(Master::start(state.path(), None));
    let (job, scene) = job();
    let (accepted, on_accepted) = tokio::sync::oneshot::channel();
    let second = {
        let master = master.clone();
        tokio::spawn(async move {
            let job: JobId = on_accepted.await.expect("the first submitter's job");
            master.follow(RemoteJob::Attach { job }).await
        })
    };
    let mut accepted = Some(accepted);
    let run = run_remote_job(
        &master.options,
        RemoteJob::Submit { job, scene: &scene },
        |event| {
            // The second attaches once the first frame is in: the job runs on.
            if let JobEvent::FrameDone(f) = event {
                if f.frame == 0 {
                    if let Some(accepted) = accepted.take() {
                        let _ = accepted.send(JobId(1));
                    }
                }
            }
        },
    );
    let first = tokio::time::timeout(WAIT, run)
        .await
        .expect("bounded")
        .expect("first");
    let (second, _) = tokio::time::timeout(WAIT, second)
        .await
        .expect("bounded")
        .unwrap();
    assert_eq!(first.len(), FRAMES);
    assert_identical(&second.expect("second"), &first, "second submitter");
    Arc::try_unwrap(master)
        .ok()
        .expect("one owner")
        .stop()
        .await;
}

/// When the master says a frame cannot be delivered, the submitter stops
/// with an error naming the frame and the job.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_frame_the_master_cannot_deliver_fails_the_submitter_naming_it() {
    let (job, scene) = job();
    let (mut submitter, mut master) = vtfarm_transport::Link::pair();
    let fake_master = tokio::spawn(async move {
        let submitted = tokio::time::timeout(WAIT, master.rx.recv()).await;
        assert!(matches!(submitted, Ok(Some(Message::SubmitJob { .. }))));
        for message in [
            Message::JobAccepted {
                job: JobId(7),
                frames: 3,
            },
            Message::FrameMissing {
                job: JobId(7),
                frame: 1,
                reason: "its record is gone and so is its job".into(),
                rendering_again: false,
            },
        ] {
            master.tx.send(message).unwrap();
        }
        master
    });
    let run = vtfarm_submit::run_job(&mut submitter, job, &scene, |_| {});
    let error = tokio::time::timeout(WAIT, run).await.expect("bounded");
    let error = error.expect_err("a frame was lost").to_string();
    assert_eq!(
        error,
        "frame 1 of job 7 cannot be delivered: its record is gone and so is its job"
    );
    drop(fake_master.await.unwrap());
}

/// A frame that cannot be read back and cannot be rendered again either
/// (its job's scene no longer decodes) is told to the submitter as lost,
/// naming the frame and both reasons.
#[test]
fn a_frame_that_cannot_be_rendered_again_is_told_lost() {
    let (mut job, scene) = job();
    let mut bytes = scene.bytes.clone();
    bytes[0] ^= 1;
    job.scene = vtfarm_proto::JobScene::Data(SceneData {
        hash: scene.hash,
        bytes,
    });
    let mut core = vtfarm_master::MasterCore::persistent(FarmRules::default());
    let now = Duration::ZERO;
    core.restore(
        now,
        vtfarm_master::StoredJob {
            id: JobId(3),
            job,
            frames_done: FRAMES as u32,
            complete: true,
            damaged_frame: None,
            summary: None,
        },
    );
    let submitter = vtfarm_master::Peer::Submitter {
        address: "test".into(),
    };
    let conn = ConnId(1);
    core.connected(now, conn, submitter);
    core.message(
        now,
        conn,
        Message::AttachJob {
            job: JobId(3),
            from_frame: 0,
        },
    );
    let mut replays = Vec::new();
    while let Some(output) = core.poll_output() {
        if let vtfarm_master::Output::Replay { frames, .. } = output {
            replays.push(frames);
        }
    }
    assert_eq!(replays.len(), 1);
    assert_eq!(replays[0], 0..FRAMES as u32);
    core.replay_failed(
        now,
        conn,
        JobId(3),
        2,
        "jobs/000000000003/000002: missing".into(),
    );
    let told: Vec<Message> = std::iter::from_fn(|| core.poll_output())
        .filter_map(|o| match o {
            vtfarm_master::Output::Send(c, message) if c == conn => Some(*message),
            _ => None,
        })
        .collect();
    let [
        Message::FrameMissing {
            job: JobId(3),
            frame: 2,
            reason,
            rendering_again: false,
        },
    ] = told.as_slice()
    else {
        panic!("{told:?}");
    };
    assert!(
        reason.starts_with(
            "jobs/000000000003/000002: missing; it cannot be rendered again: bad scene"
        ),
        "{reason}"
    );
}

/// A second spelling of a journaled job's directory (`jobs/1` beside
/// `jobs/000000000001`) is set aside with its reason, never read as a
/// second job 1: the restarted master delivers job 1 again and runs a new
/// job to the end.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_stray_job_directory_is_set_aside_and_the_restarted_master_runs_new_jobs() {
    let (reference, state) = clean_run().await;
    copy_dir(&job_dir(state.path()), &state.path().join("jobs/1"));
    let master = Master::start(state.path(), None);
    let (job, scene) = job();
    let (frames, warnings) = master
        .follow(RemoteJob::Submit { job, scene: &scene })
        .await;
    assert_identical(&frames.expect("a new job runs"), &reference, "new job");
    assert!(warnings.is_empty(), "{warnings:?}");
    let (again, _) = master.follow(RemoteJob::Attach { job: JobId(1) }).await;
    assert_identical(&again.expect("job 1 once"), &reference, "job 1");
    master.stop().await;
    let why = std::fs::read_to_string(state.path().join("jobs/damaged/stray-1/why")).unwrap();
    assert!(
        why.contains("jobs/1 is not how job 1's directory is spelled"),
        "{why}"
    );
    assert!(state.path().join("jobs/damaged/stray-1/job").exists());
}

/// A valid `job` record of job 2 copied into job 1's directory names job
/// 2: a submitter attaching to job 1 is refused with the file and the
/// mismatch, never given job 2's frames as job 1's.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_job_record_copied_into_another_jobs_directory_is_refused_on_attach() {
    let (_, state) = clean_run().await;
    let master = Master::start(state.path(), None);
    let (mut second, scene) = job();
    second.frames.truncate(1);
    let (frames, _) = master
        .follow(RemoteJob::Submit {
            job: second,
            scene: &scene,
        })
        .await;
    assert_eq!(frames.expect("job 2 runs").len(), 1);
    master.stop().await;
    let jobs = state.path().join("jobs");
    std::fs::copy(jobs.join("000000000002/job"), jobs.join("000000000001/job")).unwrap();

    let master = Master::start(state.path(), None);
    let (attached, _) = master.follow(RemoteJob::Attach { job: JobId(1) }).await;
    let error = attached.expect_err("job 1's record is job 2's").to_string();
    assert!(
        error.contains("000000000001/job") && error.contains("it holds a record of job 2"),
        "{error}"
    );
    let (again, _) = master.follow(RemoteJob::Attach { job: JobId(2) }).await;
    assert_eq!(again.expect("job 2 is untouched").len(), 1);
    master.stop().await;
}

/// A journaled job in `state` (cancelled or paused) whose listing is then
/// lost (`damage`): the restarted master holds it paused, says why in its
/// listing, and runs a new job to the end while it waits.
async fn a_lost_listing_holds_the_job(state: vtfarm_proto::WireJobState, damage: fn(&Path)) {
    let dir = tempfile::tempdir().unwrap();
    let journal = Journal::open(dir.path()).unwrap();
    let (job, scene) = job();
    let summary = vtfarm_proto::JobSummary {
        id: JobId(1),
        name: "held".into(),
        kind: job.kind,
        state,
        priority: 0,
        frames_done: 0,
        frames_failed: 0,
        frames_cancelled: 0,
        frames_total: FRAMES as u32,
        submitted_ms: 1,
        started_ms: None,
        finished_ms: None,
        host: "test".into(),
        reason: "asked by the test".into(),
    };
    let mut queued = job.clone();
    queued.scene = vtfarm_proto::JobScene::Hash(scene.hash);
    journal
        .write(vtfarm_master::Record::JobQueued {
            id: JobId(1),
            job: Box::new(queued),
            scene: Arc::new(scene.clone()),
        })
        .unwrap();
    journal
        .write(vtfarm_master::Record::JobState(Box::new(summary)))
        .unwrap();
    damage(&dir.path().join("jobs/000000000001/state"));

    let master = Master::start(dir.path(), None);
    let (frames, _) = master
        .follow(RemoteJob::Submit { job, scene: &scene })
        .await;
    assert_eq!(frames.expect("job 2 runs").len(), FRAMES);
    let listed = master
        .handle
        .inspect(|core| {
            let entry = core.jobs().get(JobId(1)).expect("job 1 listed");
            (entry.state, entry.frames_done, entry.reason.clone())
        })
        .await
        .expect("the master runs");
    assert_eq!(
        (listed.0, listed.1),
        (vtfarm_master_core::JobState::Paused, 0),
        "{state:?}: {}",
        listed.2
    );
    assert!(listed.2.contains("held paused"), "{}", listed.2);
    master.stop().await;
    assert!(
        !dir.path().join("jobs/000000000001/000000").exists(),
        "{state:?}: job 1 never ran"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_cancelled_job_whose_state_record_is_lost_never_runs_again_on_its_own() {
    a_lost_listing_holds_the_job(vtfarm_proto::WireJobState::Cancelled, |path| {
        std::fs::remove_file(path).unwrap()
    })
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_paused_job_whose_state_record_is_damaged_stays_paused() {
    a_lost_listing_holds_the_job(vtfarm_proto::WireJobState::Paused, |path| {
        flip_byte(path, 30)
    })
    .await;
}

/// Frames kept in memory while the disk was full are written once it has
/// room again, with nothing else happening on the master (no other record
/// to write after).
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn kept_frames_are_written_when_the_disk_frees_up_while_the_master_is_idle() {
    let state = tempfile::tempdir().unwrap();
    let disk = Arc::new(FullDisk {
        full: AtomicBool::new(true),
    });
    let master = Master::start(state.path(), Some(disk.clone()));
    let (job, scene) = job();
    let (frames, _) = master
        .follow(RemoteJob::Submit { job, scene: &scene })
        .await;
    let frames = frames.expect("delivered from memory");
    master
        .until_every_frame_write_failed("every frame write failed")
        .await;
    disk.full.store(false, Ordering::SeqCst);
    let journal = Journal::open(state.path()).unwrap();
    master
        .until_job_1_is_written(
            &journal,
            "the kept frames were written with nothing else to write",
        )
        .await;
    for f in 0..FRAMES as u32 {
        let done = journal.frame(JobId(1), f).unwrap();
        assert!(
            done.image == reference_wire(&frames, f),
            "frame {f} as sent"
        );
    }
    master.stop().await;
}
