//! The largest scene the limits allow (`glass_segments = 1024`, about 2.2
//! million triangles) on a master and a local worker: decoding the scene
//! and building its BVH take the worker seconds, on blocking threads, and
//! its heartbeats go on meanwhile, so the master keeps it and requeues
//! nothing.

#[path = "support/frame.rs"]
mod frame;

use std::time::Duration;

use frame::small_frame;
use glam::Vec3;
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_embedded::local_worker;
use vtfarm_master::FarmRules;
use vtfarm_master::{Peer, spawn_master};
use vtfarm_method::MethodKind;
use vtfarm_proto::SceneData;
use vtfarm_render::FrameSetup;
use vtfarm_scene::Camera;
use vtfarm_submit::{JobOptions, run_job, wire_job};
use vtfarm_transport::Link;
use vtfarm_worker::WorkerConfig;

/// The whole run is bounded by this (the scene alone takes tens of
/// seconds on a busy machine).
const WAIT: Duration = Duration::from_secs(900);

#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn a_worker_building_the_largest_scene_keeps_its_heartbeat() {
    let c = cockpit(&CockpitConfig {
        glass_segments: CockpitConfig::MAX_GLASS_SEGMENTS,
        ..CockpitConfig::default()
    });
    assert!(
        c.scene.triangles.len() > 2_000_000,
        "{}",
        c.scene.triangles.len()
    );
    let base = small_frame(&c, Vec3::ZERO);
    let setup = FrameSetup {
        camera: Camera {
            width: 32,
            height: 18,
            ..base.camera
        },
        ..base
    };
    // A few reflector triangles: the BVH is the whole scene's all the same.
    let glass = c.cover_glass_triangles();
    let reflectors: Vec<_> = glass.iter().step_by(glass.len() / 64).copied().collect();
    let data = SceneData::from_scene(&c.scene);
    drop(c);
    let options = JobOptions {
        method: MethodKind::VertexTracing,
        aux: false,
    };
    let job = wire_job("largest", &data, &[setup], &reflectors, options);
    let (master, _task) = spawn_master(FarmRules::default());
    let worker = local_worker(&master, "w1".into(), 2, WorkerConfig::default());
    let (master_end, mut submitter) = Link::pair();
    let peer = Peer::Submitter {
        address: "test".into(),
    };
    master.attach(peer, master_end, None);
    let run = run_job(&mut submitter, job, &data, |_| {});
    let frames = tokio::time::timeout(WAIT, run)
        .await
        .expect("bounded")
        .expect("the frame");
    assert_eq!(frames.len(), 1);
    assert_eq!(frames[0].stats.requeued, 0, "no package was requeued");
    let status = master.inspect(|core| core.status()).await.unwrap();
    assert_eq!(status.workers.len(), 1, "the worker is still there");
    let counters = master
        .inspect(|core| core.telemetry().counters.clone())
        .await
        .unwrap();
    assert_eq!(counters.packages_requeued, 0);
    assert!(!worker.is_finished(), "the worker's session goes on");
    master.stop();
}
