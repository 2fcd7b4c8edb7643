//! The simulator and the real master core run the same scheduler with the
//! same configuration: every call the simulator makes into its scheduler is
//! replayed into a `MasterCore` as the messages a real farm would carry, and
//! both must hand out exactly the same packages (worker, id, triangles).

use std::time::Duration;

use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_master::FarmRules;
use vtfarm_master::{JobOptions, MasterCore, Output, Peer, wire_job};
use vtfarm_method::MethodKind;
use vtfarm_proto::{JobScene, Message, PackageFailed, PackageResult, SceneData, WireJob};
use vtfarm_render::{FrameSetup, morton_order};
use vtfarm_scene::Camera;
use vtfarm_scheduler::JobId;
use vtfarm_scheduler::sim::{SimConfig, SimFrame, SimInput, SimJob, SimWorker, Simulation};

const SUBMITTER: u64 = 100;

#[test]
fn the_simulator_and_the_master_core_assign_the_same_packages() {
    let c = cockpit(&CockpitConfig {
        detail: 0.2,
        ..CockpitConfig::default()
    });
    let setup = FrameSetup {
        camera: Camera {
            width: 64,
            height: 36,
            ..c.camera
        },
        lighting: c.lighting.clone(),
        trace: Default::default(),
        vertex: Default::default(),
    };
    // The master's order of the reflector triangles: its work items.
    let items = morton_order(&c.scene, c.cover_glass_triangles());
    // Whole seconds per item, so the core's "samples + 1" carries them exactly.
    let frame = SimFrame {
        costs: items.iter().map(|&t| f64::from(t % 4 + 1)).collect(),
        items: items.clone(),
    };
    let config = SimConfig {
        scheduler: FarmRules::default().scheduler_config(),
        ..SimConfig::default()
    };
    let workers = vec![
        SimWorker {
            frame_setup: Duration::from_millis(30),
            ..SimWorker::with_speed(1.0)
        },
        SimWorker {
            frame_setup: Duration::from_millis(70),
            join_at: Duration::from_secs(5),
            ..SimWorker::with_speed(1.0)
        },
        SimWorker {
            frame_setup: Duration::from_millis(50),
            ..SimWorker::with_speed(1.0)
        },
    ];
    let mut sim = Simulation::new(config, workers);
    sim.submit(SimJob {
        id: JobId(1),
        submit_at: Duration::from_millis(1),
        frames: vec![frame; 3],
    });
    let report = sim.drive().clone();
    assert!(report.finished && report.frames.len() == 3, "{report:?}");
    let simulated: Vec<(u64, u64, Vec<u32>)> = (report.assignments.iter())
        .map(|(_, a)| (a.worker.0, a.package.0, a.items.clone()))
        .collect();
    assert!(simulated.len() > 6, "{simulated:?}");

    // The same calls, as messages into the real master core.
    let data = SceneData::from_scene(&c.scene);
    let mut core = MasterCore::new(FarmRules::default());
    let mut assigned = Vec::new();
    let mut current_frame = 0;
    let mut frames_done = 0;
    for (now, input) in &report.inputs {
        let now = *now;
        match input {
            SimInput::Submit(job, _) => {
                assert_eq!(*job, JobId(1));
                let options = JobOptions {
                    method: MethodKind::VertexTracing,
                    aux: false,
                };
                let setups = vec![setup.clone(); 3];
                let job = WireJob {
                    scene: JobScene::Data(data.clone()),
                    ..wire_job("agree", &data, &setups, &items, options)
                };
                let submitter = Peer::Submitter {
                    address: "test".into(),
                };
                core.connected(now, SUBMITTER, submitter);
                core.message(now, SUBMITTER, Message::SubmitJob { job });
            }
            SimInput::Joined(worker, threads) => {
                let peer = Peer::Worker {
                    name: format!("w{}", worker.0),
                    threads: *threads,
                    address: "test".into(),
                };
                core.connected(now, worker.0, peer);
            }
            SimInput::Request(worker) => {
                let request = Message::RequestWork {
                    job: 1,
                    frame: current_frame,
                };
                core.message(now, worker.0, request);
            }
            SimInput::Heartbeat(worker) => core.message(now, worker.0, Message::Heartbeat),
            SimInput::Left(worker) => core.disconnected(now, worker.0),
            SimInput::Done(worker, package, measure) => {
                let result = PackageResult {
                    id: package.0,
                    bitmap: Default::default(),
                    stats: Default::default(),
                    busy_micros: measure.busy.as_micros() as u64,
                    setup_micros: 0,
                    triangle_samples: (measure.item_seconds.iter())
                        .map(|&s| s as u32 - 1)
                        .collect(),
                };
                core.message(now, worker.0, Message::PackageResult(result));
            }
            SimInput::Failed(worker, package, error) => {
                let failed = PackageFailed {
                    id: package.0,
                    error: error.clone(),
                };
                core.message(now, worker.0, Message::PackageFailed(failed));
            }
            SimInput::Timeout => core.handle_timeout(now),
            // The core holds results for the base frame by itself; here base
            // frames are ready at once, and so they are in the simulation.
            SimInput::Arrived(..) => panic!("no result waits for a base frame here"),
        }
        // Carry out the core's outputs; base frames are ready at once.
        while let Some(output) = core.poll_output() {
            match output {
                Output::Send(conn, message) => match *message {
                    Message::Package(p) => assigned.push((conn, p.id, p.triangles)),
                    Message::FrameStart(start) => current_frame = start.frame,
                    Message::FrameDone(_) => frames_done += 1,
                    _ => {}
                },
                Output::RasterizeBase(request) => {
                    let (job, frame) = (request.job, request.frame);
                    let base = request.rasterize();
                    core.base_frame_ready(now, job, frame, base);
                }
                Output::Close(conn, reason) => panic!("closed {conn}: {reason}"),
                Output::Persist(_) | Output::Replay { .. } => {}
            }
        }
    }
    assert_eq!(frames_done, 3);
    assert_eq!(assigned, simulated);
}
