//! The master's core driven directly, without sockets or clock: connections,
//! messages and time go in, messages come out. Hostile or confused peers get
//! closed or ignored while the frame still completes correctly.

use std::sync::Arc;
use std::time::Duration;

use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_master::{BaseFrameRequest, MasterCore, Output, Peer, wire_job};
use vtfarm_proto::{JobScene, Message, PackageResult, SceneData, WireJob};
use vtfarm_render::{FrameSetup, Renderer};
use vtfarm_scene::Camera;
use vtfarm_scheduler::SchedulerConfig;
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{Quality, VertexSettings};
use vtfarm_worker::Engine;
use vtfarm_worker::engine::ActiveFrame;

const WORKER: u64 = 1;
const SUBMITTER: u64 = 2;
const INTRUDER: u64 = 3;

struct Harness {
    core: MasterCore,
    now: Duration,
    engine: Engine,
    frame: Option<ActiveFrame>,
    /// Base frames the core asked for, rasterized only when the test says.
    bases: Vec<BaseFrameRequest>,
}

impl Harness {
    fn tick(&mut self) -> Duration {
        self.now += Duration::from_millis(1);
        self.now
    }

    fn outputs(&mut self) -> Vec<Output> {
        let outputs: Vec<Output> = std::iter::from_fn(|| self.core.poll_output()).collect();
        for output in &outputs {
            if let Output::RasterizeBase(request) = output {
                self.bases.push(request.clone());
            }
        }
        outputs
    }

    /// Hands the core the base frames it asked for.
    fn rasterize_bases(&mut self) -> Vec<Output> {
        for request in std::mem::take(&mut self.bases) {
            let image = request.rasterize();
            self.core
                .base_frame_ready(request.job, request.frame, &image);
        }
        self.outputs()
    }

    /// Sends to the core and returns the messages for `conn` (and closes of anyone).
    fn send(&mut self, from: u64, message: Message) -> Vec<Output> {
        let now = self.tick();
        self.core.message(now, from, message);
        self.outputs()
    }
}

fn messages_to(outputs: &[Output], conn: u64) -> Vec<&Message> {
    outputs
        .iter()
        .filter_map(|o| match o {
            Output::Send(c, m) if *c == conn => Some(m.as_ref()),
            _ => None,
        })
        .collect()
}

#[test]
fn a_frame_completes_through_the_core_despite_bad_peer_messages() {
    let c = cockpit(&CockpitConfig {
        detail: 0.2,
        ..CockpitConfig::default()
    });
    let reflectors: Vec<u32> = c.cover_glass_triangles();
    let setup = FrameSetup {
        camera: Camera {
            width: 96,
            height: 54,
            ..c.camera
        },
        lighting: c.lighting.clone(),
        trace: TraceSettings::default(),
        vertex: VertexSettings {
            quality: Quality::Full,
            ..VertexSettings::default()
        },
    };
    let reference = Renderer::new(Arc::new(c.scene.clone()), reflectors.clone()).render(
        &setup,
        &Default::default(),
        &mut |_, _| {},
    );
    let data = SceneData::from_scene(&c.scene);

    let mut h = Harness {
        core: MasterCore::new(SchedulerConfig::default()),
        now: Duration::ZERO,
        engine: Engine::new(None),
        frame: None,
        bases: Vec::new(),
    };
    h.core.connected(
        h.now,
        WORKER,
        Peer::Worker {
            name: "w".into(),
            threads: 1,
            address: "test".into(),
        },
    );
    h.core.connected(
        h.now,
        SUBMITTER,
        Peer::Submitter {
            address: "test".into(),
        },
    );
    h.core.connected(
        h.now,
        INTRUDER,
        Peer::Worker {
            name: "intruder".into(),
            threads: 1,
            address: "test".into(),
        },
    );
    let job = WireJob {
        // The scene itself rather than its hash: no round trip for it.
        scene: JobScene::Data(data.clone()),
        ..wire_job("core", &data, std::slice::from_ref(&setup), &reflectors)
    };
    let out = h.send(SUBMITTER, Message::SubmitJob { job });
    assert!(matches!(
        messages_to(&out, SUBMITTER)[0],
        Message::JobAccepted { frames: 1, .. }
    ));
    // Every worker hears of the scene and the frame.
    let to_worker = messages_to(&out, WORKER);
    assert!(matches!(to_worker[0], Message::SceneOffer { .. }));
    let Message::FrameStart(start) = to_worker[1] else {
        panic!("{to_worker:?}")
    };
    h.engine.add_scene(data).unwrap();
    h.frame = Some(h.engine.start_frame(start.clone()).unwrap());
    let (job_id, frame_id) = (start.job, start.frame);

    // A worker may not submit jobs: the intruder is dropped, nobody else is.
    let out = h.send(INTRUDER, Message::StatusRequest);
    assert!(
        out.iter().any(|o| matches!(o, Output::Close(INTRUDER, _))),
        "{out:?}"
    );
    h.core.disconnected(h.now, INTRUDER);
    // A request for another frame is stale and gets nothing.
    let out = h.send(
        WORKER,
        Message::RequestWork {
            job: job_id,
            frame: frame_id + 1,
        },
    );
    assert!(messages_to(&out, WORKER).is_empty());
    // A result for a package nobody assigned is ignored.
    let out = h.send(
        WORKER,
        Message::PackageResult(PackageResult {
            id: 999,
            bitmap: Default::default(),
            stats: Default::default(),
            busy_micros: 1,
            triangle_samples: vec![],
        }),
    );
    assert!(messages_to(&out, WORKER).is_empty());

    let mut malformed_sent = false;
    let mut done = None;
    let mut out = h.send(
        WORKER,
        Message::RequestWork {
            job: job_id,
            frame: frame_id,
        },
    );
    for _ in 0..10_000 {
        if let Some(m) = messages_to(&out, SUBMITTER)
            .into_iter()
            .find(|m| matches!(m, Message::FrameDone(_)))
        {
            done = Some(m.clone());
            break;
        }
        let package = messages_to(&out, WORKER).into_iter().find_map(|m| match m {
            Message::Package(p) => Some(p.clone()),
            _ => None,
        });
        out = match package {
            // The first package comes back with a bitmap outside the frame: it fails and is retried.
            Some(p) if !malformed_sent => {
                malformed_sent = true;
                let mut result = h.frame.as_ref().unwrap().run(&p, 1.0).unwrap();
                result.bitmap.x0 = u32::MAX - 1;
                result.bitmap.width = 4;
                h.send(WORKER, Message::PackageResult(result))
            }
            Some(p) => {
                let result = h.frame.as_ref().unwrap().run(&p, 1.0).unwrap();
                h.send(WORKER, Message::PackageResult(result))
            }
            None => h.send(
                WORKER,
                Message::RequestWork {
                    job: job_id,
                    frame: frame_id,
                },
            ),
        };
        // The base frame comes late: the frame waits for it after its last result.
        if out.is_empty() {
            out = h.rasterize_bases();
        }
    }
    let Some(Message::FrameDone(done)) = done else {
        panic!("the frame did not complete")
    };
    assert!(h.bases.is_empty(), "the frame waited for its base frame");
    assert!(malformed_sent);
    assert_eq!(
        done.stats.failures, 1,
        "the malformed result counted as a failure: {:?}",
        done.stats
    );
    let (_, _, pixels) = done.image.into_pixels().unwrap();
    assert!(
        pixels == reference.image.color.pixels,
        "the image equals the single-process render"
    );
}
