//! The session state machine on a virtual clock, message by message.

use std::collections::BTreeSet;
use std::time::Duration;

use glam::Vec3;
use vtfarm_method::FrameSetup;
use vtfarm_proto::{
    FrameStart, JobId, Message, Package, PackageFailed, PackageResult, SceneData, SceneHash,
    WireFrameSetup, WireMethod,
};
use vtfarm_scene::{Camera, Lighting};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::VertexSettings;

use super::{DRAIN_LIMIT, HEARTBEAT_INTERVAL, SceneStore, SessionEnd, Task, WorkerSession};
use crate::engine::{FrameError, Panicked};

const SCENE: SceneHash = [7; 32];

/// Scenes by hash only.
#[derive(Default)]
struct Scenes(BTreeSet<SceneHash>);

impl SceneStore for Scenes {
    fn has_scene(&mut self, hash: &SceneHash) -> bool {
        self.0.contains(hash)
    }

    type Error = std::convert::Infallible;

    fn add_scene(&mut self, data: SceneData) -> Result<(), Self::Error> {
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
        job: JobId(job),
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
        image: vtfarm_proto::WireImageFormat::LinearF32,
        stages: Vec::new(),
    }
}

fn package(id: u64, job: u64, frame: u32) -> Message {
    Message::Package(Package {
        id,
        job: JobId(job),
        frame,
        triangles: vec![0],
        whole: None,
    })
}

fn result(id: u64) -> PackageResult {
    PackageResult {
        id,
        pixels: vtfarm_proto::ResultPixels::Bitmap(Default::default()),
        stats: Default::default(),
        busy_micros: 1,
        setup_micros: 0,
        triangle_samples: vec![1],
        stage: None,
        mesh: None,
    }
}

fn messages(s: &mut WorkerSession) -> Vec<Message> {
    std::iter::from_fn(|| s.poll_message()).collect()
}

fn tasks(s: &mut WorkerSession) -> Vec<Task> {
    std::iter::from_fn(|| s.poll_task()).collect()
}

/// A session with the scene at hand that heard of frame (1, 0): it sets
/// nothing up yet and asks for work at once.
fn announced_session() -> (WorkerSession, Scenes) {
    let mut scenes = Scenes::default();
    scenes.0.insert(SCENE);
    let mut s = WorkerSession::new(Duration::ZERO);
    let start = Message::FrameStart(frame_start(1, 0));
    s.handle_message(Duration::ZERO, start, &mut scenes);
    assert_eq!(
        tasks(&mut s),
        vec![],
        "a frame is set up for its first package"
    );
    assert_eq!(
        messages(&mut s),
        vec![Message::RequestWork {
            job: JobId(1),
            frame: 0
        }]
    );
    (s, scenes)
}

/// An announced session whose first package (9) of frame (1, 0) made it
/// prepare that frame.
fn preparing_session() -> (WorkerSession, Scenes) {
    let (mut s, mut scenes) = announced_session();
    s.handle_message(Duration::ZERO, package(9, 1, 0), &mut scenes);
    assert_eq!(tasks(&mut s), vec![Task::PrepareFrame(frame_start(1, 0))]);
    assert_eq!(messages(&mut s), vec![], "a package waits: no request");
    (s, scenes)
}

/// A session with frame (1, 0) prepared, its first package done and work
/// asked for.
fn ready_session() -> (WorkerSession, Scenes) {
    let (mut s, scenes) = preparing_session();
    s.frame_prepared(Duration::ZERO, (JobId(1), 0), Ok(()));
    assert!(matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, stage: 0 }] if p.id == 9));
    assert_eq!(
        messages(&mut s),
        vec![Message::RequestWork {
            job: JobId(1),
            frame: 0
        }],
        "the next package is asked for while one runs"
    );
    s.package_finished(Duration::ZERO, 9, Ok(result(9)));
    assert_eq!(messages(&mut s), vec![Message::PackageResult(result(9))]);
    (s, scenes)
}

#[test]
fn work_is_asked_for_at_once_and_one_package_ahead() {
    let (mut s, mut scenes) = ready_session();
    let now = Duration::from_millis(5);
    s.handle_message(now, package(10, 1, 0), &mut scenes);
    assert!(
        matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, stage: 0 }] if p.id == 10)
    );
    assert_eq!(
        messages(&mut s),
        vec![Message::RequestWork {
            job: JobId(1),
            frame: 0
        }],
        "one ahead"
    );
    s.handle_message(now, package(11, 1, 0), &mut scenes);
    assert_eq!(messages(&mut s), vec![], "no second request ahead");
    s.package_finished(now, 10, Ok(result(10)));
    assert!(
        matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, stage: 0 }] if p.id == 11)
    );
    assert_eq!(
        messages(&mut s),
        vec![
            Message::PackageResult(result(10)),
            Message::RequestWork {
                job: JobId(1),
                frame: 0
            }
        ]
    );
}

#[test]
fn a_frame_waits_for_its_scene_and_so_do_its_packages() {
    let mut scenes = Scenes::default();
    let mut s = WorkerSession::new(Duration::ZERO);
    s.handle_message(
        Duration::ZERO,
        Message::SceneOffer {
            hash: SCENE,
            job: JobId(1),
        },
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
    s.frame_prepared(Duration::ZERO, (JobId(1), 0), Ok(()));
    assert!(
        matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, stage: 0 }] if p.id == 10)
    );
}

#[test]
fn packages_of_a_frame_that_failed_to_prepare_fail_with_its_reason() {
    let (mut s, mut scenes) = preparing_session();
    let panicked = Panicked("BVH build panicked".into());
    s.frame_prepared(
        Duration::ZERO,
        (JobId(1), 0),
        Err(FrameError::Panicked(panicked)),
    );
    s.handle_message(Duration::ZERO, package(11, 2, 5), &mut scenes);
    let failed: Vec<(u64, String)> = messages(&mut s)
        .into_iter()
        .filter_map(|m| match m {
            Message::PackageFailed(PackageFailed { id, error }) => Some((id, error)),
            Message::RequestWork { .. } => None,
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(failed.len(), 2, "{failed:?}");
    assert_eq!(
        failed[0].1, "cannot start frame: panicked: BVH build panicked",
        "the frame's error, as the wire's reason"
    );
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
            Task::RunPackage {
                package: p,
                stage: 0,
            } => p.id,
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(ran, vec![10], "the queued one was dropped");
    // Asked ahead once package 10 ran, and again when 11 was dropped; no
    // result of 10.
    assert_eq!(
        messages(&mut s),
        vec![
            Message::RequestWork {
                job: JobId(1),
                frame: 0
            };
            2
        ]
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
    let _ = messages(&mut s);
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
    s.frame_prepared(Duration::ZERO, (JobId(1), 0), Ok(()));
    // Only the package runs: frame (1, 1), announced while draining, is not set up.
    assert!(matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, stage: 0 }] if p.id == 9));
    assert_eq!(messages(&mut s), vec![], "no request while draining");
    s.package_finished(Duration::ZERO, 9, Ok(result(9)));
    assert_eq!(messages(&mut s), vec![Message::PackageResult(result(9))]);
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

/// Frames announced while a package runs are not set up; a package of one
/// is (the newest it asked for, or an older one: a requeued package),
/// prepared frames stay usable, and a frame more than FRAMES_IN_FLIGHT
/// back is too old.
#[test]
fn a_frame_is_set_up_for_its_first_package_and_prepared_frames_stay_usable() {
    let (mut s, mut scenes) = ready_session();
    let now = Duration::from_millis(5);
    s.handle_message(now, package(10, 1, 0), &mut scenes);
    assert!(
        matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, stage: 0 }] if p.id == 10)
    );
    let _ = messages(&mut s);
    for frame in [1, 2] {
        s.handle_message(now, Message::FrameStart(frame_start(1, frame)), &mut scenes);
    }
    assert_eq!(tasks(&mut s), vec![], "announced, not set up");
    assert_eq!(
        messages(&mut s),
        vec![
            Message::RequestWork {
                job: JobId(1),
                frame: 1
            },
            Message::RequestWork {
                job: JobId(1),
                frame: 2
            }
        ],
        "each frame start renews the request"
    );
    // A package of frame 2 comes (the one ahead): frame 2 is prepared
    // beside the running package; frame 1 is skipped.
    s.handle_message(now, package(11, 1, 2), &mut scenes);
    assert_eq!(tasks(&mut s), vec![Task::PrepareFrame(frame_start(1, 2))]);
    s.frame_prepared(now, (JobId(1), 2), Ok(()));
    s.package_finished(now, 10, Ok(result(10)));
    assert!(
        matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, stage: 0 }] if p.id == 11)
    );
    assert_eq!(
        messages(&mut s),
        vec![
            Message::PackageResult(result(10)),
            Message::RequestWork {
                job: JobId(1),
                frame: 2
            }
        ]
    );
    s.package_finished(now, 11, Ok(result(11)));
    let _ = messages(&mut s);
    // A requeued package of the skipped frame 1 waits for its set-up;
    // one of frame 0 runs on the frame kept.
    s.handle_message(now, package(12, 1, 1), &mut scenes);
    assert_eq!(tasks(&mut s), vec![Task::PrepareFrame(frame_start(1, 1))]);
    s.frame_prepared(now, (JobId(1), 1), Ok(()));
    assert!(
        matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, stage: 0 }] if p.id == 12)
    );
    s.package_finished(now, 12, Ok(result(12)));
    s.handle_message(now, package(13, 1, 0), &mut scenes);
    assert!(
        matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, stage: 0 }] if p.id == 13)
    );
    s.package_finished(now, 13, Ok(result(13)));
    let _ = messages(&mut s);
    // Prepare frames up to FRAMES_IN_FLIGHT + 2: frame 0 falls out, and
    // its package fails so the master retries it elsewhere.
    for frame in 3..=vtfarm_proto::FRAMES_IN_FLIGHT as u32 + 2 {
        let id = 100 + u64::from(frame);
        s.handle_message(now, Message::FrameStart(frame_start(1, frame)), &mut scenes);
        s.handle_message(now, package(id, 1, frame), &mut scenes);
        s.frame_prepared(now, (JobId(1), frame), Ok(()));
        s.package_finished(now, id, Ok(result(id)));
    }
    let _ = (tasks(&mut s), messages(&mut s));
    s.handle_message(now, package(14, 1, 0), &mut scenes);
    assert!(matches!(&messages(&mut s)[..], [Message::PackageFailed(f), ..] if f.id == 14));
}

#[test]
fn the_first_result_of_a_frame_tells_how_long_its_set_up_took() {
    let (mut s, mut scenes) = preparing_session();
    // Frame (1, 0) was handed over for set-up at 0; ready at 40 ms.
    let ms = Duration::from_millis;
    s.frame_prepared(ms(40), (JobId(1), 0), Ok(()));
    assert!(matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, stage: 0 }] if p.id == 9));
    s.handle_message(ms(41), package(10, 1, 0), &mut scenes);
    s.package_finished(ms(50), 9, Ok(result(9)));
    let told = PackageResult {
        setup_micros: 40_000,
        ..result(9)
    };
    assert!(messages(&mut s).contains(&Message::PackageResult(told)));
    // The frame's next package had no set-up of its own.
    assert!(
        matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, stage: 0 }] if p.id == 10)
    );
    s.package_finished(ms(60), 10, Ok(result(10)));
    assert!(messages(&mut s).contains(&Message::PackageResult(result(10))));
}

/// A progressive frame's packages run stage by stage, one result each, the
/// lowest stage first (every package's preview before any refinement, a
/// package that came later before the others' later stages); a package
/// keeps its progress until its last stage, and a cancelled one loses its
/// remaining stages at once.
#[test]
fn a_progressive_frames_packages_run_the_lowest_stage_first() {
    let mut scenes = Scenes::default();
    scenes.0.insert(SCENE);
    let mut s = WorkerSession::new(Duration::ZERO);
    let start = FrameStart {
        stages: vec![
            vtfarm_proto::WireQuality::Preview,
            vtfarm_proto::WireQuality::Refine,
            vtfarm_proto::WireQuality::Full,
        ],
        ..frame_start(1, 0)
    };
    s.handle_message(
        Duration::ZERO,
        Message::FrameStart(start.clone()),
        &mut scenes,
    );
    s.handle_message(Duration::ZERO, package(9, 1, 0), &mut scenes);
    assert_eq!(tasks(&mut s), vec![Task::PrepareFrame(start)]);
    s.frame_prepared(Duration::ZERO, (JobId(1), 0), Ok(()));
    s.handle_message(Duration::ZERO, package(10, 1, 0), &mut scenes);
    let mut ran = Vec::new();
    let mut results = 0;
    let ms = Duration::from_millis;
    for step in 1..=8 {
        let task = tasks(&mut s);
        let [Task::RunPackage { package: p, stage }] = &task[..] else {
            break;
        };
        ran.push((p.id, *stage));
        if (p.id, *stage) == (10, 0) {
            // A third package comes while the others wait for refinement.
            s.handle_message(ms(step), package(11, 1, 0), &mut scenes);
        }
        let id = p.id;
        s.package_finished(ms(step), id, Ok(result(id)));
        results += (messages(&mut s).iter())
            .filter(|m| matches!(m, Message::PackageResult(_)))
            .count();
        if (id, *stage) == (9, 1) {
            assert!(s.continues(9), "9's full is next: its progress is kept");
            // The master cancels package 11 between its stages.
            s.handle_message(ms(step), Message::CancelPackage { id: 11 }, &mut scenes);
            assert!(!s.continues(11));
        }
    }
    assert_eq!(
        ran,
        [(9, 0), (10, 0), (11, 0), (9, 1), (10, 1), (9, 2), (10, 2)]
    );
    assert_eq!(results, ran.len(), "one result per stage");
    assert!(
        !s.continues(9) && !s.continues(10),
        "done with their last stage"
    );
}

/// A view frame's corner mesh, traced while the frame is set up, goes to
/// the master at once as `FrameMesh`; one that comes after the frame is
/// ready, or for a frame not being prepared, is dropped.
#[test]
fn a_corner_mesh_traced_during_the_set_up_goes_out_at_once() {
    let (mut s, _) = preparing_session();
    let mesh = vtfarm_proto::WireMesh::default();
    s.corner_mesh_traced(Duration::ZERO, (JobId(2), 0), mesh.clone());
    assert_eq!(messages(&mut s), Vec::new(), "not a frame being prepared");
    s.corner_mesh_traced(Duration::ZERO, (JobId(1), 0), mesh.clone());
    let sent = Message::FrameMesh {
        job: JobId(1),
        frame: 0,
        mesh: mesh.clone(),
    };
    assert_eq!(messages(&mut s), vec![sent]);
    s.frame_prepared(Duration::ZERO, (JobId(1), 0), Ok(()));
    s.corner_mesh_traced(Duration::ZERO, (JobId(1), 0), mesh);
    let late = messages(&mut s);
    assert!(
        !late.iter().any(|m| matches!(m, Message::FrameMesh { .. })),
        "{late:?}"
    );
}

/// Runs one package `id` of frame `key` from its `FrameStart` to its
/// result (the frame prepared on the way).
fn run_frame(s: &mut WorkerSession, scenes: &mut Scenes, id: u64, (job, frame): (u64, u32)) {
    let now = Duration::ZERO;
    s.handle_message(now, Message::FrameStart(frame_start(job, frame)), scenes);
    s.handle_message(now, package(id, job, frame), scenes);
    assert_eq!(tasks(s), vec![Task::PrepareFrame(frame_start(job, frame))]);
    s.frame_prepared(now, (JobId(job), frame), Ok(()));
    assert!(matches!(&tasks(s)[..], [Task::RunPackage { package: p, .. }] if p.id == id));
    s.package_finished(now, id, Ok(result(id)));
    let _ = messages(s);
}

/// The frames the master named last stay usable whatever their jobs' ids
/// (a lower job's frame after many of a higher job's), a frame not named
/// for longer falls out, and a package's frame stays while it is in hand.
#[test]
fn the_frames_named_last_stay_prepared_and_a_package_keeps_its_frame() {
    let (mut s, mut scenes) = ready_session();
    let kept = vtfarm_proto::FRAMES_IN_FLIGHT as u32;
    let now = Duration::ZERO;
    for frame in 0..kept {
        run_frame(&mut s, &mut scenes, 100 + u64::from(frame), (2, frame));
    }
    // Job 1's frame after job 2's: prepared and kept (the newest named).
    run_frame(&mut s, &mut scenes, 20, (1, 5));
    for key in [(JobId(1), 5), (JobId(2), 1), (JobId(2), kept - 1)] {
        assert!(s.keeps_set_up(key), "{key:?}");
    }
    // Job 2's frame 0 was named longest ago: let go.
    assert!(!s.keeps_set_up((JobId(2), 0)));
    // Packages in hand keep their frames however many frames are named
    // meanwhile; each frame goes once its package is done.
    s.handle_message(now, package(22, 2, 6), &mut scenes);
    s.handle_message(now, package(23, 2, 7), &mut scenes);
    assert!(matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, .. }] if p.id == 22));
    for frame in 0..kept {
        s.handle_message(now, Message::FrameStart(frame_start(3, frame)), &mut scenes);
    }
    assert!(s.keeps_set_up((JobId(2), 6)) && s.keeps_set_up((JobId(2), 7)));
    assert!(!s.keeps_set_up((JobId(1), 5)));
    s.package_finished(now, 22, Ok(result(22)));
    assert!(matches!(&tasks(&mut s)[..], [Task::RunPackage { package: p, .. }] if p.id == 23));
    assert!(!s.keeps_set_up((JobId(2), 6)));
    s.package_finished(now, 23, Ok(result(23)));
    assert!(!s.keeps_set_up((JobId(2), 7)));
    // A package of a frame let go fails: the master, counting the same,
    // sends the frame's start again first.
    let _ = messages(&mut s);
    s.handle_message(now, package(24, 1, 5), &mut scenes);
    assert!(matches!(&messages(&mut s)[..], [Message::PackageFailed(f), ..] if f.id == 24));
}
