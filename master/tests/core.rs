//! The master's core driven directly, without sockets or clock: connections,
//! messages and time go in, messages come out. Hostile or confused peers get
//! closed or ignored while the frame still completes correctly.

#[path = "support/frame.rs"]
mod frame;

use frame::small_frame;
use std::sync::Arc;
use std::time::Duration;
use vtfarm_proto::JobId;

use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_master::{
    BaseFrameRequest, FrameEncodeRequest, JobOptions, MasterCore, Output, Peer, wire_job,
};
use vtfarm_master::{ConnId, FarmRules};
use vtfarm_master_core::JobState;
use vtfarm_method::MethodKind;
use vtfarm_proto::{
    FrameDone, JobScene, Message, Package, PackageResult, PhaseKind, ResultPixels, SceneData,
    WireBitmap, WireFrameAux, WireImage, WireImageFormat, WireJob,
};
use vtfarm_raster::IdBuffer;
use vtfarm_render::Renderer;
use vtfarm_vertex::{SparseBitmap, Stop};
use vtfarm_worker::Engine;
use vtfarm_worker::engine::ActiveFrame;

const WORKER: ConnId = ConnId(1);
const SUBMITTER: ConnId = ConnId(2);
const INTRUDER: ConnId = ConnId(3);

struct Harness {
    core: MasterCore,
    now: Duration,
    engine: Engine,
    frame: Option<ActiveFrame>,
    /// Base frames the core asked for, rasterized only when the test says.
    bases: Vec<BaseFrameRequest>,
    /// Finished frames to encode, held here when set (else encoded at once).
    held_encodings: Option<Vec<FrameEncodeRequest>>,
}

impl Harness {
    fn tick(&mut self) -> Duration {
        self.now += Duration::from_millis(1);
        self.now
    }

    /// The core's outputs; a finished frame's encoding is carried out at
    /// once (as a driver's thread would), so what follows it is here too.
    fn outputs(&mut self) -> Vec<Output> {
        let mut outputs = Vec::new();
        while let Some(output) = self.core.poll_output() {
            match output {
                Output::RasterizeBase(request) => {
                    self.bases.push(request.clone());
                    outputs.push(Output::RasterizeBase(request));
                }
                Output::EncodeFrame(request) => match self.held_encodings.as_mut() {
                    Some(held) => held.push(request),
                    None => {
                        let now = self.tick();
                        self.core.frame_encoded(now, request.encode());
                    }
                },
                output => outputs.push(output),
            }
        }
        outputs
    }

    /// Hands the core the base frames it asked for.
    fn rasterize_bases(&mut self) -> Vec<Output> {
        for request in std::mem::take(&mut self.bases) {
            let now = self.tick();
            let (job, frame) = (request.job, request.frame);
            let base = request.rasterize();
            self.core.base_frame_ready(now, job, frame, base);
        }
        self.outputs()
    }

    /// Sends to the core and returns the messages for `conn` (and closes of anyone).
    fn send(&mut self, from: ConnId, message: Message) -> Vec<Output> {
        let now = self.tick();
        self.core.message(now, from, message);
        self.outputs()
    }
}

fn messages_to(outputs: &[Output], conn: ConnId) -> Vec<&Message> {
    outputs
        .iter()
        .filter_map(|o| match o {
            Output::Send(c, m) if *c == conn => Some(m.as_ref()),
            _ => None,
        })
        .collect()
}

/// A master with one worker and one submitter, and the job's first frame
/// started on both sides.
struct StartedFrame {
    h: Harness,
    job: JobId,
    frame: u32,
    /// The master's ID buffer of the frame (every worker rebuilds the same).
    ids: IdBuffer,
    /// The single-process render of the frame.
    reference: Vec<[f32; 3]>,
}

fn start_frame() -> StartedFrame {
    start_job(1)
}

/// A master with one worker and one submitter and a job of `frames`
/// frames of the same view: with more than one frame, frame 0 is whole
/// (more frames than workers) and the worker sets it up from its package.
fn start_job(frames: usize) -> StartedFrame {
    let c = cockpit(&CockpitConfig {
        detail: 0.2,
        ..CockpitConfig::default()
    });
    let reflectors = c.cover_glass_triangles();
    let setup = small_frame(&c, glam::Vec3::ZERO);
    let reference = Renderer::new(Arc::new(c.scene.clone()), reflectors.clone()).render(
        &setup,
        &Default::default(),
        &mut |_, _| {},
    );
    let data = SceneData::from_scene(&c.scene);

    let mut h = Harness {
        core: MasterCore::new(FarmRules::default()),
        now: Duration::ZERO,
        engine: Engine::new(None),
        frame: None,
        bases: Vec::new(),
        held_encodings: None,
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
    let options = JobOptions {
        method: MethodKind::VertexTracing,
        aux: false,
    };
    let job = WireJob {
        // The scene itself rather than its hash: no round trip for it.
        scene: JobScene::Data(data.clone()),
        ..wire_job(
            "core",
            &data,
            &vec![setup.clone(); frames],
            &reflectors,
            options,
        )
    };
    let out = h.send(SUBMITTER, Message::SubmitJob { job });
    let Message::JobAccepted { job, .. } = messages_to(&out, SUBMITTER)[0] else {
        panic!("{out:?}")
    };
    let job = *job;
    // Every worker hears of the scene and, unless it is whole, the frame.
    let to_worker = messages_to(&out, WORKER);
    assert!(matches!(to_worker[0], Message::SceneOffer { .. }));
    h.engine.add_scene(data).unwrap();
    match to_worker.get(1) {
        Some(Message::FrameStart(start)) => {
            h.frame = Some(h.engine.start_frame(start.clone()).unwrap());
        }
        other => assert!(frames > 1 && other.is_none(), "{to_worker:?}"),
    }
    StartedFrame {
        h,
        job,
        frame: 0,
        ids: vtfarm_raster::id_buffer(&c.scene, &setup.camera),
        reference: reference
            .image
            .color
            .pixels
            .iter()
            .map(|p| p.to_array())
            .collect(),
    }
}

/// Runs the frame's packages on the worker until the frame is done; the
/// first package's result goes through `tamper` first. Returns the finished frame.
fn finish_frame(
    started: &mut StartedFrame,
    tamper: impl FnOnce(&Package, &mut PackageResult),
) -> FrameDone {
    let out = run_packages(started, tamper, |_, out| {
        messages_to(out, SUBMITTER)
            .iter()
            .any(|m| matches!(m, Message::FrameDone(_)))
    });
    let done = messages_to(&out, SUBMITTER)
        .into_iter()
        .find_map(|m| match m {
            Message::FrameDone(done) => Some(done.clone()),
            _ => None,
        });
    done.expect("run until a frame was done")
}

/// Runs the frame's packages on the worker until `stop` holds for the
/// harness and the last outputs (which it returns); the first package's
/// result goes through `tamper` first.
fn run_packages(
    started: &mut StartedFrame,
    tamper: impl FnOnce(&Package, &mut PackageResult),
    stop: impl Fn(&Harness, &[Output]) -> bool,
) -> Vec<Output> {
    let h = &mut started.h;
    let request = Message::RequestWork {
        job: started.job,
        frame: started.frame,
    };
    let mut tamper = Some(tamper);
    let mut out = h.send(WORKER, request.clone());
    for _ in 0..10_000 {
        if stop(h, &out) {
            return out;
        }
        let package = messages_to(&out, WORKER).into_iter().find_map(|m| match m {
            Message::Package(p) => Some(p.clone()),
            _ => None,
        });
        out = match package {
            Some(p) => {
                // A whole frame's set-up comes with its package.
                if let Some(start) = &p.whole {
                    h.frame = Some(h.engine.start_frame((**start).clone()).unwrap());
                }
                let unlimited = Stop::with_budget(u64::MAX);
                let mut result = h.frame.as_ref().unwrap().run(&p, 1.0, &unlimited).unwrap();
                let first = tamper.is_some();
                if first {
                    // The worker set the frame up for its first package.
                    result.setup_micros = 1;
                }
                if let Some(tamper) = tamper.take() {
                    tamper(&p, &mut result);
                }
                let mut out = h.send(WORKER, Message::PackageResult(result));
                if first && p.whole.is_none() {
                    // The base frame comes after the first result, which
                    // waits for its ID buffer to be checked.
                    assert!(messages_to(&out, SUBMITTER).is_empty(), "{out:?}");
                    out.extend(h.rasterize_bases());
                }
                out
            }
            None => h.send(WORKER, request.clone()),
        };
    }
    panic!("the frame did not get there")
}

/// The frame counted one failed package and still equals the single-process render.
fn assert_one_failure_and_the_reference(started: &StartedFrame, done: FrameDone) {
    // The timeline: the master's base frame (a split frame's), the worker's
    // set-up and packages.
    let whole = done.stats.phases.iter().all(|p| p.kind != PhaseKind::Base);
    let kinds: &[PhaseKind] = if whole {
        &[PhaseKind::Setup, PhaseKind::Package]
    } else {
        &[PhaseKind::Base, PhaseKind::Setup, PhaseKind::Package]
    };
    for &kind in kinds {
        let phase = (done.stats.phases.iter()).find(|p| p.kind == kind);
        assert!(
            phase.is_some_and(|p| p.start_micros <= p.end_micros),
            "{kind:?} in {:?}",
            done.stats.phases
        );
    }
    assert_eq!(
        done.stats.failures, 1,
        "the bad result counted as a failure: {:?}",
        done.stats
    );
    let (_, _, pixels) = done.image.into_pixels().unwrap();
    let pixels: Vec<[f32; 3]> = pixels.iter().map(|p| p.to_array()).collect();
    assert!(
        pixels == started.reference,
        "the image equals the single-process render"
    );
}

#[test]
fn a_frame_completes_through_the_core_despite_bad_peer_messages() {
    let mut started = start_frame();
    let h = &mut started.h;
    h.core.connected(
        h.now,
        INTRUDER,
        Peer::Worker {
            name: "intruder".into(),
            threads: 1,
            address: "test".into(),
        },
    );
    // A worker may not submit jobs: the intruder is dropped, nobody else is.
    let out = h.send(INTRUDER, Message::StatusRequest);
    assert!(
        out.iter().any(|o| matches!(o, Output::Close(INTRUDER, _))),
        "{out:?}"
    );
    h.core.disconnected(h.now, INTRUDER);
    // (A request naming another job is a request all the same: a worker's
    // newest frame may be of a job that ended. `tests/jobs.rs` runs jobs
    // out of id order, where that happens.)
    // A result for a package nobody assigned is ignored.
    let out = h.send(
        WORKER,
        Message::PackageResult(PackageResult {
            id: 999,
            pixels: ResultPixels::Bitmap(Default::default()),
            stats: Default::default(),
            busy_micros: 1,
            setup_micros: 0,
            triangle_samples: vec![],
            stage: None,
            mesh: None,
        }),
    );
    assert!(messages_to(&out, WORKER).is_empty());

    // The first package comes back with a bitmap outside the frame: it fails and is retried.
    let done = finish_frame(&mut started, |_, result| {
        let ResultPixels::Bitmap(bitmap) = &mut result.pixels else {
            panic!("a split frame's result is a bitmap");
        };
        bitmap.x0 = u32::MAX - 1;
        bitmap.width = 4;
    });
    assert_one_failure_and_the_reference(&started, done);
}

/// A split frame's image is encoded off the driver (`Output::EncodeFrame`):
/// the frame goes out only once encoded, still equal to the single-process
/// render, and its job is complete only after it.
#[test]
fn a_finished_frame_goes_out_once_encoded_and_its_job_ends_after_it() {
    let mut started = start_frame();
    started.h.held_encodings = Some(Vec::new());
    let out = run_packages(
        &mut started,
        |_, _| {},
        |h, _| h.held_encodings.as_ref().is_some_and(|e| !e.is_empty()),
    );
    let told = |out: &[Output]| -> Vec<&str> {
        messages_to(out, SUBMITTER)
            .iter()
            .map(|m| m.name())
            .filter(|&n| n != "Progress")
            .collect()
    };
    assert!(!told(&out).contains(&"FrameDone"), "{out:?}");
    let h = &mut started.h;
    let running = |h: &Harness| h.core.jobs().get(started.job).map(|e| e.state);
    assert_eq!(running(h), Some(JobState::Running));
    let mut held = h.held_encodings.take().unwrap();
    assert_eq!(held.len(), 1);
    let now = h.tick();
    h.core.frame_encoded(now, held.remove(0).encode());
    let out = h.outputs();
    assert_eq!(told(&out), vec!["FrameDone"], "{out:?}");
    assert_eq!(running(h), Some(JobState::Completed));
    let Message::FrameDone(done) = messages_to(&out, SUBMITTER)[0] else {
        unreachable!()
    };
    let (_, _, pixels) = done.image.clone().into_pixels().unwrap();
    let pixels: Vec<[f32; 3]> = pixels.iter().map(|p| p.to_array()).collect();
    assert!(pixels == started.reference);
}

#[test]
fn a_result_writing_pixels_its_package_does_not_own_fails_the_package() {
    let mut started = start_frame();
    let ids = started.ids.clone();
    // The first package's result also writes one pixel of the frame that
    // none of its triangles own (another package's, or the base frame's):
    // in bounds and well formed, so only the ownership check can catch it.
    let done = finish_frame(&mut started, |package, result| {
        let foreign = (ids.triangle.iter())
            .position(|t| !package.triangles.contains(t))
            .expect("the package does not own the whole frame") as u32;
        result.pixels = ResultPixels::Bitmap(WireBitmap::from(&SparseBitmap {
            x0: foreign % ids.width,
            y0: foreign / ids.width,
            width: 1,
            height: 1,
            mask: vec![true],
            color: vec![glam::Vec3::new(1.0, 0.0, 1.0)],
            reflected: vec![glam::Vec3::ZERO],
            transmitted: vec![glam::Vec3::ZERO],
            reflected_object: vec![0],
        }));
    });
    assert_one_failure_and_the_reference(&started, done);
}

/// A whole frame comes back finished from its worker; the master checks
/// it as it checks a split frame's pixels: a finished frame of another
/// size or format, or pixels to composite where a finished frame is due,
/// fail the package (retried, and the frame still equals the
/// single-process render); so does a finished frame for a split package.
#[test]
fn a_whole_frame_that_is_not_what_its_job_asks_for_fails_the_package() {
    type Tamper = fn(&mut PackageResult);
    let tampers: [(&str, Tamper); 4] = [
        ("wrong size", |result| {
            if let ResultPixels::Frame { image, .. } = &mut result.pixels {
                image.width += 1;
            }
        }),
        ("wrong format", |result| {
            if let ResultPixels::Frame { image, .. } = &mut result.pixels {
                image.format = WireImageFormat::Srgb8;
            }
        }),
        ("unasked components", |result| {
            if let ResultPixels::Frame { aux, .. } = &mut result.pixels {
                *aux = Some(WireFrameAux {
                    reflected: WireImage::default(),
                    transmitted: WireImage::default(),
                    reflected_object: Vec::new(),
                    mask: Vec::new(),
                });
            }
        }),
        ("pixels instead", |result| {
            result.pixels = ResultPixels::Bitmap(Default::default());
        }),
    ];
    for (what, tamper) in tampers {
        let mut started = start_job(3);
        let done = finish_frame(&mut started, |package, result| {
            assert!(
                package.whole.is_some(),
                "frame 0 of 3 on one worker is whole"
            );
            assert!(
                matches!(result.pixels, ResultPixels::Frame { .. }),
                "{what}"
            );
            tamper(result);
        });
        assert_eq!(done.frame, 0, "{what}");
        assert_one_failure_and_the_reference(&started, done);
    }
    // A finished frame where pixels are due (a split frame's package).
    let mut started = start_frame();
    let done = finish_frame(&mut started, |_, result| {
        result.pixels = ResultPixels::Frame {
            image: WireImage::from_pixels(1, 1, &[glam::Vec3::ONE]),
            aux: None,
        };
    });
    assert_one_failure_and_the_reference(&started, done);
}
