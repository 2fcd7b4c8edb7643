//! The session state machine on a virtual clock, message by message.

use std::collections::BTreeSet;
use std::time::Duration;

use glam::Vec3;
use vtfarm_method::FrameSetup;
use vtfarm_proto::{
    FrameStart, Message, Package, PackageFailed, PackageResult, SceneData, SceneHash,
    WireFrameSetup, WireMethod,
};
use vtfarm_scene::{Camera, Lighting};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::VertexSettings;

use super::{DRAIN_LIMIT, HEARTBEAT_INTERVAL, SceneStore, SessionEnd, Task, WorkerSession};

const SCENE: SceneHash = [7; 32];

/// Scenes by hash only.
#[derive(Default)]
struct Scenes(BTreeSet<SceneHash>);

impl SceneStore for Scenes {
    fn has_scene(&mut self, hash: &SceneHash) -> bool {
        self.0.contains(hash)
    }

    fn add_scene(&mut self, data: SceneData) -> Result<(), String> {
        self.0.insert(data.hash);
        Ok(())
    }
}

fn frame_start(job: u64, frame: u32) -> FrameStart {
    let camera = Camera {
        eye: Vec3::ZERO,
        target: Vec3::Z,
        up: Vec3::Y,
        fov_y_deg: 60.0,
        width: 8,
        height: 8,
    };
    FrameStart {
        job,
        frame,
        scene: SCENE,
        setup: WireFrameSetup::from(&FrameSetup {
            camera,
            lighting: Lighting::default(),
            trace: TraceSettings::default(),
            vertex: VertexSettings::default(),
        }),
        reflectors: vec![0],
        method: WireMethod::VertexTracing,
        aux: false,
    }
}

fn package(id: u64, job: u64, frame: u32) -> Message {
    Message::Package(Package {
        id,
        job,
        frame,
        triangles: vec![0],
    })
}

fn result(id: u64) -> PackageResult {
    PackageResult {
        id,
        bitmap: Default::default(),
        stats: Default::default(),
        busy_micros: 1,
        triangle_samples: vec![1],
    }
}

fn messages(s: &mut WorkerSession) -> Vec<Message> {
    std::iter::from_fn(|| s.poll_message()).collect()
}

fn tasks(s: &mut WorkerSession) -> Vec<Task> {
    std::iter::from_fn(|| s.poll_task()).collect()
}

/// A session with the scene at hand that was told to prepare frame (1, 0).
fn preparing_session() -> (WorkerSession, Scenes) {
    let mut scenes = Scenes::default();
    scenes.0.insert(SCENE);
    let mut s = WorkerSession::new(Duration::ZERO);
    let start = Message::FrameStart(frame_start(1, 0));
    s.handle_message(Duration::ZERO, start, &mut scenes);
    assert_eq!(tasks(&mut s), vec![Task::PrepareFrame(frame_start(1, 0))]);
    assert_eq!(
        messages(&mut s),
        vec![],
        "no request before the frame is ready"
    );
    (s, scenes)
}

/// A session with frame (1, 0) prepared and work requested.
fn ready_session() -> (WorkerSession, Scenes) {
    let (mut s, scenes) = preparing_session();
    s.frame_prepared(Duration::ZERO, (1, 0), Ok(()));
    assert_eq!(
        messages(&mut s),
        vec![Message::RequestWork { job: 1, frame: 0 }]
    );
    (s, scenes)
}

#[test]
fn work_is_asked_for_once_the_frame_is_ready_and_again_after_each_result() {
    let (mut s, mut scenes) = ready_session();
    let now = Duration::from_millis(5);
    s.handle_message(now, package(10, 1, 0), &mut scenes);
    assert!(matches!(&tasks(&mut s)[..], [Task::RunPackage(p)] if p.id == 10));
    assert_eq!(messages(&mut s), vec![], "no second request while busy");
    s.package_finished(now, 10, Ok(result(10)));
    assert_eq!(
        messages(&mut s),
        vec![
            Message::PackageResult(result(10)),
            Message::RequestWork { job: 1, frame: 0 }
        ]
    );
}

#[test]
fn a_frame_waits_for_its_scene_and_so_do_its_packages() {
    let mut scenes = Scenes::default();
    let mut s = WorkerSession::new(Duration::ZERO);
    s.handle_message(
        Duration::ZERO,
        Message::SceneOffer { hash: SCENE },
        &mut scenes,
    );
    assert_eq!(
        messages(&mut s),
        vec![Message::SceneRequest { hash: SCENE }]
    );
    s.handle_message(
        Duration::ZERO,
        Message::FrameStart(frame_start(1, 0)),
        &mut scenes,
    );
    s.handle_message(Duration::ZERO, package(10, 1, 0), &mut scenes);
    assert_eq!(tasks(&mut s), vec![], "nothing runs without the scene");
    assert_eq!(messages(&mut s), vec![]);
    let data = SceneData {
        hash: SCENE,
        bytes: vec![],
    };
    s.handle_message(Duration::ZERO, Message::SceneData(data), &mut scenes);
    assert_eq!(tasks(&mut s), vec![Task::PrepareFrame(frame_start(1, 0))]);
    s.frame_prepared(Duration::ZERO, (1, 0), Ok(()));
    assert!(matches!(&tasks(&mut s)[..], [Task::RunPackage(p)] if p.id == 10));
}

#[test]
fn packages_of_a_frame_that_failed_to_prepare_fail_with_its_reason() {
    let (mut s, mut scenes) = preparing_session();
    s.handle_message(Duration::ZERO, package(10, 1, 0), &mut scenes);
    s.frame_prepared(Duration::ZERO, (1, 0), Err("BVH build panicked".into()));
    s.handle_message(Duration::ZERO, package(11, 2, 5), &mut scenes);
    let failed: Vec<(u64, String)> = messages(&mut s)
        .into_iter()
        .map(|m| match m {
            Message::PackageFailed(PackageFailed { id, error }) => (id, error),
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(failed.len(), 2, "{failed:?}");
    assert!(failed[0].1.contains("BVH build panicked"), "{failed:?}");
    assert!(failed[1].1.contains("without its frame"), "{failed:?}");
    assert_eq!(tasks(&mut s), vec![]);
}

#[test]
fn a_cancelled_running_package_sends_no_result() {
    let (mut s, mut scenes) = ready_session();
    s.handle_message(Duration::ZERO, package(10, 1, 0), &mut scenes);
    s.handle_message(Duration::ZERO, package(11, 1, 0), &mut scenes);
    s.handle_message(
        Duration::ZERO,
        Message::CancelPackage { id: 10 },
        &mut scenes,
    );
    s.handle_message(
        Duration::ZERO,
        Message::CancelPackage { id: 11 },
        &mut scenes,
    );
    s.package_finished(Duration::ZERO, 10, Ok(result(10)));
    let ran: Vec<u64> = (tasks(&mut s).into_iter())
        .map(|t| match t {
            Task::RunPackage(p) => p.id,
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(ran, vec![10], "the queued one was dropped");
    assert_eq!(
        messages(&mut s),
        vec![Message::RequestWork { job: 1, frame: 0 }]
    );
}

#[test]
fn heartbeats_follow_the_virtual_clock() {
    let mut s = WorkerSession::new(Duration::ZERO);
    assert_eq!(s.poll_timeout(), HEARTBEAT_INTERVAL);
    s.handle_timeout(HEARTBEAT_INTERVAL / 2);
    assert_eq!(messages(&mut s), vec![]);
    s.handle_timeout(HEARTBEAT_INTERVAL);
    assert_eq!(messages(&mut s), vec![Message::Heartbeat]);
    assert_eq!(s.poll_timeout(), 2 * HEARTBEAT_INTERVAL);
}

#[test]
fn draining_finishes_the_running_package_then_ends_without_asking_for_more() {
    let (mut s, mut scenes) = ready_session();
    s.handle_message(Duration::ZERO, package(10, 1, 0), &mut scenes);
    s.handle_message(Duration::ZERO, package(11, 1, 0), &mut scenes);
    tasks(&mut s);
    s.drain(Duration::ZERO);
    assert_eq!(s.poll_end(), None, "the running package finishes first");
    s.package_finished(Duration::ZERO, 10, Ok(result(10)));
    assert_eq!(messages(&mut s), vec![Message::PackageResult(result(10))]);
    assert_eq!(tasks(&mut s), vec![], "the queued package is handed back");
    assert_eq!(s.poll_end(), Some(SessionEnd::Drained));
}

#[test]
fn draining_finishes_a_package_whose_frame_is_still_being_set_up() {
    let (mut s, mut scenes) = preparing_session();
    s.handle_message(Duration::ZERO, package(10, 1, 0), &mut scenes);
    s.handle_message(Duration::ZERO, package(11, 1, 0), &mut scenes);
    assert_eq!(tasks(&mut s), vec![], "both wait for the frame");
    s.drain(Duration::ZERO);
    assert_eq!(
        s.poll_end(),
        None,
        "the package in hand waits for its frame"
    );
    let next = Message::FrameStart(frame_start(1, 1));
    s.handle_message(Duration::ZERO, next, &mut scenes);
    s.frame_prepared(Duration::ZERO, (1, 0), Ok(()));
    // Only the package runs: frame (1, 1), announced while draining, is not set up.
    assert!(matches!(&tasks(&mut s)[..], [Task::RunPackage(p)] if p.id == 10));
    assert_eq!(messages(&mut s), vec![], "no request while draining");
    s.package_finished(Duration::ZERO, 10, Ok(result(10)));
    assert_eq!(messages(&mut s), vec![Message::PackageResult(result(10))]);
    assert_eq!(tasks(&mut s), vec![], "the second package is handed back");
    assert_eq!(s.poll_end(), Some(SessionEnd::Drained));
}

#[test]
fn a_drain_that_outlasts_its_limit_hands_the_running_package_back() {
    let (mut s, mut scenes) = ready_session();
    s.handle_message(Duration::ZERO, package(10, 1, 0), &mut scenes);
    s.drain(Duration::ZERO);
    assert_eq!(s.poll_timeout(), HEARTBEAT_INTERVAL);
    s.handle_timeout(DRAIN_LIMIT - Duration::from_millis(1));
    assert_eq!(s.poll_end(), None);
    s.handle_timeout(DRAIN_LIMIT);
    assert_eq!(s.poll_end(), Some(SessionEnd::Drained));
}

#[test]
fn an_idle_worker_drains_at_once_and_shutdown_ends_the_session() {
    let (mut s, mut scenes) = ready_session();
    s.drain(Duration::ZERO);
    assert_eq!(s.poll_end(), Some(SessionEnd::Drained));
    let (mut s, _) = ready_session();
    s.handle_message(Duration::ZERO, Message::Shutdown, &mut scenes);
    assert_eq!(s.poll_end(), Some(SessionEnd::Shutdown));
}

#[test]
fn a_frame_announced_while_a_package_runs_is_prepared_and_older_frames_stay_usable() {
    let (mut s, mut scenes) = ready_session();
    let now = Duration::from_millis(5);
    s.handle_message(now, package(10, 1, 0), &mut scenes);
    assert!(matches!(&tasks(&mut s)[..], [Task::RunPackage(p)] if p.id == 10));
    // Frame 1 is announced while frame 0's package runs: it is prepared
    // beside it, and work is asked for frame 1 once both are done.
    s.handle_message(now, Message::FrameStart(frame_start(1, 1)), &mut scenes);
    assert_eq!(tasks(&mut s), vec![Task::PrepareFrame(frame_start(1, 1))]);
    s.frame_prepared(now, (1, 1), Ok(()));
    assert_eq!(messages(&mut s), vec![], "busy: no request yet");
    s.package_finished(now, 10, Ok(result(10)));
    assert_eq!(
        messages(&mut s),
        vec![
            Message::PackageResult(result(10)),
            Message::RequestWork { job: 1, frame: 1 }
        ]
    );
    // A requeued package of frame 0 still runs here.
    s.handle_message(now, package(11, 1, 0), &mut scenes);
    assert!(matches!(&tasks(&mut s)[..], [Task::RunPackage(p)] if p.id == 11));
    s.package_finished(now, 11, Ok(result(11)));
    let _ = messages(&mut s);
    // A frame more than FRAMES_IN_FLIGHT back is too old: the master
    // retries its package elsewhere.
    for frame in 2..=vtfarm_proto::FRAMES_IN_FLIGHT as u32 {
        s.handle_message(now, Message::FrameStart(frame_start(1, frame)), &mut scenes);
        s.frame_prepared(now, (1, frame), Ok(()));
    }
    let _ = (tasks(&mut s), messages(&mut s));
    s.handle_message(now, package(12, 1, 0), &mut scenes);
    assert!(matches!(&messages(&mut s)[..], [Message::PackageFailed(f), ..] if f.id == 12));
}

/// Frames announced faster than the worker sets them up: one is prepared at
/// a time, the newest next, and a skipped frame only when a package of it
/// comes (the package waits for it instead of failing).
#[test]
fn frames_are_prepared_one_at_a_time_and_a_skipped_one_when_a_package_needs_it() {
    let (mut s, mut scenes) = ready_session();
    let now = Duration::from_millis(5);
    s.handle_message(now, Message::FrameStart(frame_start(1, 1)), &mut scenes);
    assert_eq!(tasks(&mut s), vec![Task::PrepareFrame(frame_start(1, 1))]);
    for frame in [2, 3] {
        s.handle_message(now, Message::FrameStart(frame_start(1, frame)), &mut scenes);
    }
    assert_eq!(tasks(&mut s), vec![], "one frame at a time");
    s.frame_prepared(now, (1, 1), Ok(()));
    assert_eq!(
        tasks(&mut s),
        vec![Task::PrepareFrame(frame_start(1, 3))],
        "the newest next; frame 2 is skipped"
    );
    assert_eq!(
        messages(&mut s),
        vec![],
        "no request before the newest is ready"
    );
    // A requeued package of the skipped frame waits for its set-up.
    s.handle_message(now, package(20, 1, 2), &mut scenes);
    assert_eq!((tasks(&mut s), messages(&mut s)), (vec![], vec![]));
    s.frame_prepared(now, (1, 3), Ok(()));
    assert_eq!(tasks(&mut s), vec![Task::PrepareFrame(frame_start(1, 2))]);
    s.frame_prepared(now, (1, 2), Ok(()));
    assert!(matches!(&tasks(&mut s)[..], [Task::RunPackage(p)] if p.id == 20));
    s.package_finished(now, 20, Ok(result(20)));
    assert_eq!(
        messages(&mut s),
        vec![
            Message::PackageResult(result(20)),
            Message::RequestWork { job: 1, frame: 3 }
        ],
        "work is asked for the newest frame again"
    );
    // Frames 0 to 3 are all kept for their packages.
    for (id, frame) in [(21, 0), (22, 1)] {
        s.handle_message(now, package(id, 1, frame), &mut scenes);
        assert!(matches!(&tasks(&mut s)[..], [Task::RunPackage(p)] if p.id == id));
        s.package_finished(now, id, Ok(result(id)));
    }
}
