//! The interactive view through the sans-IO core (`Pair`: real worker
//! sessions, virtual clock): a move of the eye is one progressive frame,
//! set up once on the master and on each worker, its stages composited in
//! place, each byte for byte the single-process render at its quality, the
//! refinement continuing the preview's vertices; moving the eye cancels the
//! outdated move's remaining stages, and only the newest eye is rendered to
//! `full`.

#[path = "support/frame.rs"]
mod frame;

mod support;

use frame::small_frame;
use std::collections::BTreeSet;
use std::sync::Arc;
use std::time::Duration;
use vtfarm_proto::JobId;

use glam::Vec3;
use support::pair::Pair;
use vtfarm_cockpit::Cockpit;
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_master::stream::{self, StageMessage};
use vtfarm_master::view::{EYE_BOX, STAGES, ViewError, ViewOutcome, ViewRequest};
use vtfarm_master::{FarmRules, MasterCore};
use vtfarm_master::{JobOptions, wire_job};
use vtfarm_method::MethodKind;
use vtfarm_proto::{
    Message, PackageResult, PhaseKind, ResultPixels, SceneData, WireBitmap, WireQuality,
};
use vtfarm_render::{FrameSetup, RenderOptions, Renderer};
use vtfarm_scene::{Projector, ScreenPoint, TriangleId};
use vtfarm_vertex::{Quality, SparseBitmap};

/// Virtual time a scenario may take at most.
const BOUND: Duration = Duration::from_secs(600);

#[test]
fn three_quick_moves_leave_one_frame_rendered_to_full_and_the_others_cancelled() {
    let c = cockpit(&CockpitConfig {
        detail: 0.2,
        glass_segments: 24,
        ..CockpitConfig::default()
    });
    let reflectors = c.cover_glass_triangles();
    let setup = small_frame(&c, Vec3::ZERO);
    let data = SceneData::from_scene(&c.scene);
    let options = JobOptions {
        method: MethodKind::VertexTracing,
        aux: false,
    };
    let job = wire_job("source", &data, &[setup], &reflectors, options);
    let mut pair = Pair::new(FarmRules::default());
    pair.add_worker("w1", 1.0);
    pair.add_worker("w2", 1.0);
    pair.submit(job, data);
    pair.drive(BOUND, |p| p.frames_done().len() == 1);
    let source = pair.job_id().expect("the job was accepted");

    // Refused moves change nothing.
    let unknown = ViewRequest {
        job: JobId(99),
        offset: [0.0; 3],
        page_draws_scene: false,
        preview_only: false,
    };
    assert_eq!(
        pair.act(|m, now| m.steer_view(now, unknown)),
        Err(ViewError::UnknownSource(JobId(99)))
    );
    let bad = ViewRequest {
        job: source,
        offset: [f32::NAN, 0.0, 0.0],
        page_draws_scene: false,
        preview_only: false,
    };
    assert_eq!(
        pair.act(|m, now| m.steer_view(now, bad)),
        Err(ViewError::BadOffset)
    );

    // Three moves, each as soon as the previous one's packages are out at
    // the workers (the last one beyond the box, so it is clamped).
    let offsets = [[0.02, 0.0, 0.0], [0.04, 0.01, 0.0], [0.5, 0.0, 0.0]];
    let mut jobs = Vec::new();
    for (k, offset) in offsets.into_iter().enumerate() {
        let request = ViewRequest {
            job: source,
            offset,
            page_draws_scene: false,
            preview_only: false,
        };
        jobs.push(pair.act(|m, now| m.steer_view(now, request)).unwrap());
        if k + 1 < offsets.len() {
            pair.drive(BOUND, |p| {
                p.workers.iter().any(|w| w.is_running_a_package())
            });
        }
    }
    pair.drive(BOUND, |p| {
        let current = p.master.views().current().unwrap();
        current.stages_done == current.stages_total
            && p.workers.iter().all(|w| !w.is_running_a_package())
            && p.master
                .views()
                .latest()
                .is_some_and(|l| l.figures.is_some())
    });

    let outcomes: Vec<ViewOutcome> = pair.master.views().outcomes().copied().collect();
    let full: Vec<&ViewOutcome> = (outcomes.iter())
        .filter(|o| {
            matches!(
                o,
                ViewOutcome::Rendered {
                    quality: Quality::Full,
                    ..
                }
            )
        })
        .collect();
    assert_eq!(
        full,
        [&ViewOutcome::Rendered {
            generation: 3,
            job: jobs[2],
            quality: Quality::Full
        }],
        "{outcomes:?}"
    );
    for (generation, &job) in (1..).zip(&jobs[..2]) {
        assert!(
            outcomes.contains(&ViewOutcome::Cancelled { generation, job }),
            "move {generation} cancelled: {outcomes:?}"
        );
    }
    // The last move went through preview and refine to full, in order.
    let stages: Vec<Quality> = (outcomes.iter())
        .filter_map(|o| match *o {
            ViewOutcome::Rendered {
                generation: 3,
                quality,
                ..
            } => Some(quality),
            _ => None,
        })
        .collect();
    assert_eq!(stages, STAGES);
    let counters = &pair.master.telemetry().counters;
    assert_eq!(counters.jobs_cancelled, 2);
    // The source job and three moves: every one submitted has ended once.
    assert_eq!(counters.jobs_submitted, 4);
    let ended = counters.jobs_completed + counters.jobs_failed + counters.jobs_cancelled;
    assert_eq!(ended, counters.jobs_submitted);

    // The view shows the clamped eye, equal to the single-process render.
    let current = pair.master.views().current().unwrap();
    assert_eq!(current.offset, [EYE_BOX, 0.0, 0.0]);
    let latest = pair.master.views().latest().unwrap();
    assert_eq!((latest.generation, latest.quality), (3, Quality::Full));
    let moved = small_frame(&c, Vec3::new(EYE_BOX, 0.0, 0.0));
    let renderer = Renderer::new(Arc::new(c.scene.clone()), reflectors);
    let reference = renderer.render(&moved, &Default::default(), &mut |_, _| {});
    assert!(latest.image().pixels == reference.image.color.pixels);
    // Its glare figures (computed after it went on view) are those of the
    // composited components.
    let figures = latest
        .figures
        .as_ref()
        .expect("the figures of the stage on view");
    assert_eq!(figures.glare.glass_pixels, reference.image.glass().count());
    let map = &figures.object_map;
    assert_eq!(
        (map.width, map.height),
        (latest.image().width, latest.image().height)
    );
}

/// A farm of two workers that rendered a job of the small cockpit (the
/// view's source): the farm, the cockpit, its reflectors, the job's id.
fn farm_with_a_source() -> (Pair, Cockpit, Vec<TriangleId>, JobId) {
    let c = cockpit(&CockpitConfig {
        detail: 0.2,
        glass_segments: 24,
        ..CockpitConfig::default()
    });
    let reflectors = c.cover_glass_triangles();
    let data = SceneData::from_scene(&c.scene);
    let options = JobOptions {
        method: MethodKind::VertexTracing,
        aux: false,
    };
    let setup = small_frame(&c, Vec3::ZERO);
    let job = wire_job("source", &data, &[setup], &reflectors, options);
    let mut pair = Pair::new(FarmRules::default());
    pair.add_worker("w1", 1.0);
    pair.add_worker("w2", 1.0);
    pair.submit(job, data);
    pair.drive(BOUND, |p| p.frames_done().len() == 1);
    let source = pair.job_id().expect("the job was accepted");
    (pair, c, reflectors, source)
}

/// The small frame of `c` with the eye moved by `offset`, at `quality`.
fn moved(c: &Cockpit, offset: Vec3, quality: Quality) -> FrameSetup {
    let mut setup = small_frame(c, offset);
    setup.vertex.quality = quality;
    setup
}

/// The view's latest image is, byte for byte, the single-process render
/// at `full` of the source eye moved by `offset`.
fn assert_the_view_shows_the_full_render(
    pair: &Pair,
    c: &Cockpit,
    reflectors: Vec<TriangleId>,
    offset: Vec3,
) {
    let latest = pair.master.views().latest().unwrap();
    let renderer = Renderer::new(Arc::new(c.scene.clone()), reflectors);
    let reference = renderer.render(
        &moved(c, offset, Quality::Full),
        &Default::default(),
        &mut |_, _| {},
    );
    assert!(latest.image().pixels == reference.image.color.pixels);
}

/// Drives until stage `quality` of move `generation` is complete.
fn drive_to_stage(pair: &mut Pair, generation: u64, quality: Quality) {
    pair.drive(BOUND, |p| {
        p.master.views().outcomes().any(|o| match *o {
            ViewOutcome::Rendered {
                generation: g,
                quality: q,
                ..
            } => (g, q) == (generation, quality),
            ViewOutcome::Cancelled { .. } => false,
        })
    });
}

/// One move: the master rasterizes one base frame and each worker sets its
/// frame up once for the three stages; the stages before `full` carry
/// meshes and no pixels, so the view shows only the last, byte for byte
/// the single-process render at `full`; each package runs each stage
/// once, the stages together trace exactly the vertices the same packages
/// trace at `full` from scratch (refine and full continue the preview's
/// vertices and edges; none is traced twice), and exactly its pixels.
#[test]
fn a_move_is_one_progressive_frame_set_up_once_its_last_stage_the_single_process_render() {
    let (mut pair, c, reflectors, source) = farm_with_a_source();
    let set_ups_before: Vec<u64> = (pair.workers.iter())
        .map(|w| w.state.engine.set_ups())
        .collect();
    let runs_before: Vec<usize> = pair
        .workers
        .iter()
        .map(|w| w.state.stages_run.len())
        .collect();
    let offset = Vec3::new(0.03, 0.01, -0.02);
    let request = ViewRequest {
        job: source,
        offset: offset.to_array(),
        page_draws_scene: false,
        preview_only: false,
    };
    let job = pair.act(|m, now| m.steer_view(now, request)).unwrap();
    let renderer = Renderer::new(Arc::new(c.scene.clone()), reflectors);
    for quality in STAGES {
        drive_to_stage(&mut pair, 1, quality);
        let latest = pair.master.views().latest().filter(|l| l.generation == 1);
        if quality < Quality::Full {
            assert!(latest.is_none(), "{quality:?}: a mesh stage has no image");
            continue;
        }
        let reference = renderer.render(
            &moved(&c, offset, quality),
            &Default::default(),
            &mut |_, _| {},
        );
        assert!(
            latest.unwrap().image().pixels == reference.image.color.pixels,
            "{quality:?}: the single-process render's pixels"
        );
    }
    pair.drive(BOUND, |p| {
        p.master.telemetry().frames().any(|f| f.job == job)
    });

    // Set up once: one base frame on the master, one set-up per worker.
    let bases: Vec<_> = (pair.base_frames.iter())
        .filter(|(j, _)| *j == job)
        .collect();
    assert_eq!(bases, [&(job, 0)]);
    for (w, before) in pair.workers.iter().zip(set_ups_before) {
        assert_eq!(w.state.engine.set_ups() - before, 1, "{}", w.name);
    }
    // Each package ran its three stages once, in order, on one worker.
    let mut stages_of: std::collections::BTreeMap<u64, Vec<usize>> = Default::default();
    let mut packages = Vec::new();
    let mut traced = (0, 0);
    for (w, before) in pair.workers.iter().zip(runs_before) {
        for run in &w.state.stages_run[before..] {
            assert_eq!(run.job, job);
            stages_of.entry(run.package).or_default().push(run.stage);
            if run.stage == 0 {
                packages.push(run.triangles.iter().copied().map(TriangleId).collect());
            }
            traced.0 += run.stats.vertex_samples;
            traced.1 += run.stats.filled_pixels;
        }
    }
    assert!(packages.len() >= 2, "{packages:?}");
    assert!(stages_of.values().all(|s| s == &[0, 1, 2]), "{stages_of:?}");
    let scratch = |quality| {
        let setup = moved(&c, offset, quality);
        renderer
            .render_packages(&setup, &packages, &Default::default(), &mut |_, _| {})
            .stats
    };
    let full = scratch(Quality::Full);
    assert_eq!(traced.0, full.vertex_samples, "every vertex traced once");
    // Three renders from scratch trace the preview's vertices three times;
    // the progressive frame fills its pixels once, at `full`.
    let separate = STAGES.map(scratch);
    let separate_vertices: u64 = separate.iter().map(|s| s.vertex_samples).sum();
    assert!(traced.0 < separate_vertices, "{traced:?} {separate:?}");
    assert_eq!(traced.1, full.filled_pixels, "pixels traced at full only");
    // The frame's totals are its stages' work.
    let done = pair
        .master
        .telemetry()
        .frames()
        .find(|f| f.job == job)
        .unwrap();
    assert_eq!(done.stats.totals.vertex_samples, traced.0);
    // Its timeline has the master's base frame, the workers' stages (set-ups
    // take no time here), and the three stages going on view one after
    // another.
    let kinds: Vec<PhaseKind> = done.stats.phases.iter().map(|p| p.kind).collect();
    for kind in [PhaseKind::Base, PhaseKind::Package] {
        assert!(kinds.contains(&kind), "{kinds:?}");
    }
    let shown: Vec<(u64, u64)> = (done.stats.phases.iter())
        .filter(|p| p.kind == PhaseKind::Shown)
        .map(|p| (p.start_micros, p.end_micros))
        .collect();
    assert_eq!(shown.len(), 3, "{shown:?}");
    assert!(
        shown
            .windows(2)
            .all(|w| w[0].1 == w[1].0 && w[0].0 <= w[0].1),
        "{shown:?}"
    );
}

/// A move whose preview is on screen is cancelled by a newer move at
/// once: its refine and full are never shown, its packages' later stages
/// stop, and the newer move goes through its stages to the newest eye.
#[test]
fn a_newer_move_cancels_the_older_moves_remaining_stages() {
    let (mut pair, c, reflectors, source) = farm_with_a_source();
    let first = ViewRequest {
        job: source,
        offset: [0.02, 0.0, 0.0],
        page_draws_scene: false,
        preview_only: false,
    };
    let old = pair.act(|m, now| m.steer_view(now, first)).unwrap();
    drive_to_stage(&mut pair, 1, Quality::Preview);
    let runs_at_cancel: Vec<usize> = pair
        .workers
        .iter()
        .map(|w| w.state.stages_run.len())
        .collect();
    let second = ViewRequest {
        job: source,
        offset: [-0.03, 0.02, 0.0],
        page_draws_scene: false,
        preview_only: false,
    };
    let new = pair.act(|m, now| m.steer_view(now, second)).unwrap();
    assert!(pair.master.views().outcomes().any(|o| *o
        == ViewOutcome::Cancelled {
            generation: 1,
            job: old
        }));
    drive_to_stage(&mut pair, 2, Quality::Full);
    let shown: Vec<(u64, Quality)> = (pair.master.views().outcomes())
        .filter_map(|o| match *o {
            ViewOutcome::Rendered {
                generation,
                quality,
                ..
            } => Some((generation, quality)),
            ViewOutcome::Cancelled { .. } => None,
        })
        .collect();
    assert_eq!(
        shown,
        [
            (1, Quality::Preview),
            (2, Quality::Preview),
            (2, Quality::Refine),
            (2, Quality::Full)
        ]
    );
    // The cancel reaches each worker before the newer move's packages do
    // (in order on its link): no stage of the old move starts after the
    // worker's first stage of the new one.
    for (w, before) in pair.workers.iter().zip(runs_at_cancel) {
        let runs = &w.state.stages_run[before..];
        let first_new = runs.iter().position(|r| r.job == new);
        let first_new = first_new.unwrap_or_else(|| panic!("{} ran the new move", w.name));
        let late: Vec<_> = (runs[first_new..].iter())
            .filter(|r| r.job == old)
            .map(|r| (r.package, r.stage))
            .collect();
        assert_eq!(late, [], "{}", w.name);
    }
    // The old move's frame never completed.
    assert!(!pair.master.telemetry().frames().any(|f| f.job == old));
    assert_eq!(pair.master.telemetry().counters.jobs_cancelled, 1);
    assert_the_view_shows_the_full_render(&pair, &c, reflectors, Vec3::from(second.offset));
}

/// A worker's stage results are checked like any result, and refused
/// naming the peer when out of order (a refine before the package's
/// preview, a stage for a frame of one stage) or out of the frame: the
/// package fails and runs again, and the move still ends byte for byte
/// the single-process render.
#[test]
fn stage_results_out_of_order_or_out_of_the_frame_fail_their_package() {
    let (mut pair, c, reflectors, source) = farm_with_a_source();
    let request = ViewRequest {
        job: source,
        offset: [0.01, 0.01, 0.0],
        page_draws_scene: false,
        preview_only: false,
    };
    let job = pair.act(|m, now| m.steer_view(now, request)).unwrap();
    pair.drive(BOUND, |p| {
        p.workers.iter().any(|w| w.is_running_a_package())
            && !p.master.packages_by_worker().is_empty()
    });
    let (name, conn) = (pair.workers[0].name.clone(), pair.workers[0].conn());
    let result = |id, stage, pixels| PackageResult {
        id,
        pixels,
        stats: Default::default(),
        busy_micros: 1,
        setup_micros: 0,
        triangle_samples: vec![],
        stage,
        mesh: None,
    };
    let outside = ResultPixels::Bitmap(WireBitmap::from(&SparseBitmap {
        x0: 500,
        y0: 0,
        width: 1,
        height: 1,
        mask: vec![true],
        color: vec![Vec3::ONE],
        reflected: vec![Vec3::ZERO],
        transmitted: vec![Vec3::ZERO],
        reflected_object: vec![0],
    }));
    let empty = ResultPixels::Bitmap(Default::default());
    let tampered = [
        // A refine before the package's preview.
        result(0, Some(WireQuality::Refine), empty.clone()),
        // No stage on a progressive frame's result.
        result(0, None, empty),
        // A preview with pixels outside the frame.
        result(0, Some(WireQuality::Preview), outside),
    ];
    let mut failed = 0;
    for tampered in tampered {
        let mine = pair
            .master
            .packages_by_worker()
            .get(&name)
            .cloned()
            .unwrap_or_default();
        let Some(&id) = mine.first() else { continue };
        let failures = pair
            .master
            .status()
            .workers
            .iter()
            .find(|w| w.name == name)
            .map(|w| w.failures);
        pair.act(|m, now| {
            m.message(
                now,
                conn,
                Message::PackageResult(PackageResult { id, ..tampered }),
            )
        });
        let after = pair
            .master
            .status()
            .workers
            .iter()
            .find(|w| w.name == name)
            .map(|w| w.failures);
        assert_eq!(
            after,
            failures.map(|f| f + 1),
            "refused, counted against {name}"
        );
        let listed = (pair.master.packages_by_worker().get(&name).cloned()).unwrap_or_default();
        assert!(!listed.contains(&id), "{id} runs nowhere now: {listed:?}");
        failed += 1;
    }
    assert!(failed >= 1);
    drive_to_stage(&mut pair, 1, Quality::Full);
    pair.drive(BOUND, |p| {
        p.master.telemetry().frames().any(|f| f.job == job)
    });
    assert_the_view_shows_the_full_render(&pair, &c, reflectors, Vec3::from(request.offset));
}

/// The stage messages streamed so far: each decoded.
fn streamed(master: &MasterCore) -> (u64, Vec<StageMessage>) {
    let stream = master.views().stream();
    let decoded = (stream.messages.iter())
        .map(|m| stream::decode(&m.bytes).expect("a stage message decodes"))
        .collect();
    (stream.generation, decoded)
}

/// A face as the single-process render reports it: screen corners and
/// corner colours, as bits.
type FaceBits = [([u32; 3], [u32; 3]); 3];

fn face_bits(corners: [ScreenPoint; 3], colors: [Vec3; 3]) -> FaceBits {
    let bits = |v: Vec3| v.to_array().map(f32::to_bits);
    [0, 1, 2].map(|k| {
        let s = corners[k];
        (bits(Vec3::new(s.x, s.y, s.depth)), bits(colors[k]))
    })
}

/// Each stage goes out as its message once the stage is complete, while
/// the later stages are still being traced; decoded, a `preview` or
/// `refine` message is, face for face and bit for bit, the refined faces
/// the single-process render at that quality traces for the move's eye,
/// and the `full` overlay is that render's reflector pixels. The page draws
/// the scene itself: the master's image of the move is that render only
/// where the packages look, the background elsewhere.
#[test]
fn each_stage_is_streamed_as_it_completes_and_decodes_to_the_single_process_render() {
    let (mut pair, c, reflectors, source) = farm_with_a_source();
    let offset = Vec3::new(0.01, 0.0, 0.0);
    let request = ViewRequest {
        job: source,
        offset: offset.to_array(),
        page_draws_scene: true,
        preview_only: false,
    };
    pair.act(|m, now| m.steer_view(now, request)).unwrap();
    let renderer = Renderer::new(Arc::new(c.scene.clone()), reflectors);
    for (k, quality) in STAGES.into_iter().enumerate() {
        drive_to_stage(&mut pair, 1, quality);
        let (generation, messages) = streamed(&pair.master);
        assert_eq!(generation, 1);
        assert_eq!(messages.len(), k + 1, "one message per stage complete");
        let message = &messages[k];
        let header = message.header();
        assert_eq!((header.generation, header.quality), (1, quality));
        let setup = moved(&c, offset, quality);
        assert_eq!(header.eye, setup.camera.eye);
        let options = RenderOptions {
            collect_faces: true,
            ..Default::default()
        };
        let reference = renderer.render(&setup, &options, &mut |_, _| {});
        match message {
            StageMessage::Mesh { meshes, .. } => {
                let projector = Projector::new(&setup.camera);
                let faces_of = |m: &vtfarm_vertex::StageMesh| -> Vec<FaceBits> {
                    (m.faces.iter())
                        .map(|f| {
                            let corners = f.map(|v| {
                                let p = m.positions[v as usize];
                                projector.project(p).expect("a sent face is in front")
                            });
                            face_bits(corners, f.map(|v| m.samples[v as usize].color))
                        })
                        .collect()
                };
                let mut traced: Vec<FaceBits> = (reference.faces.iter())
                    .map(|f| face_bits(f.corners, f.colors))
                    .collect();
                traced.sort_unstable();
                let mut sent: Vec<FaceBits> = meshes.iter().flat_map(faces_of).collect();
                sent.sort_unstable();
                assert!(!sent.is_empty());
                if quality == Quality::Preview {
                    // The workers' corner mesh, sent before the frame's
                    // set-up: every reflector triangle, hidden or not. The
                    // render traces those that own pixels: their faces are
                    // here bit for bit, and each other face is of a
                    // triangle the frame does not show at all.
                    let reflectors = c.cover_glass_triangles();
                    let vertices: usize = meshes.iter().map(|m| m.positions.len()).sum();
                    assert_eq!(vertices, 3 * reflectors.len(), "each reflector's corners");
                    let corners_of = |t: TriangleId| {
                        let tri = c.scene.triangles[t.index()];
                        tri.vertices
                            .map(|v| c.scene.positions[v as usize].to_array().map(f32::to_bits))
                    };
                    let triangle_at: std::collections::BTreeMap<_, TriangleId> =
                        reflectors.iter().map(|&t| (corners_of(t), t)).collect();
                    let (ids, _) = renderer.id_buffers(&setup);
                    let shown: BTreeSet<u32> = (0..ids.height)
                        .flat_map(|y| (0..ids.width).map(move |x| (x, y)))
                        .map(|(x, y)| ids.triangle_at(x, y))
                        .collect();
                    let mut extra = 0;
                    for m in meshes {
                        for (face, bits) in m.faces.iter().zip(faces_of(m)) {
                            if traced.binary_search(&bits).is_ok() {
                                continue;
                            }
                            let corners =
                                face.map(|v| m.positions[v as usize].to_array().map(f32::to_bits));
                            let t = triangle_at[&corners];
                            assert!(!shown.contains(&t.raw()), "triangle {t} is shown");
                            extra += 1;
                        }
                    }
                    assert!(extra > 0, "the frame hides some of the glass");
                    assert_eq!(sent.len(), traced.len() + extra);
                    assert!(traced.iter().all(|f| sent.binary_search(f).is_ok()));
                } else {
                    assert!(sent == traced, "{quality:?}: the render's faces");
                }
            }
            StageMessage::Overlay { overlay, .. } => {
                assert_eq!(quality, Quality::Full);
                let width = reference.image.color.width;
                let sent: Vec<(usize, [u32; 3])> = (overlay.pixels())
                    .map(|(x, y, c)| ((y * width + x) as usize, c.to_array().map(f32::to_bits)))
                    .collect();
                let rendered: Vec<(usize, [u32; 3])> = (reference.image.glass())
                    .map(|i| {
                        (
                            i,
                            reference.image.color.pixels[i].to_array().map(f32::to_bits),
                        )
                    })
                    .collect();
                assert!(!sent.is_empty());
                assert!(sent == rendered, "the render's reflector pixels");
                let latest = pair.master.views().latest().unwrap();
                let is_reflector = vtfarm_render::reflector_flags(&c.scene, renderer.reflectors());
                let around = vtfarm_render::package_bounds(&c.scene, &setup, &is_reflector);
                let (mut inside, mut outside) = (0, 0);
                for (i, (&shown, &rendered)) in (latest.image().pixels.iter())
                    .zip(&reference.image.color.pixels)
                    .enumerate()
                {
                    let (x, y) = ((i % width as usize) as u32, (i / width as usize) as u32);
                    if around.contains(x, y) {
                        assert_eq!(shown, rendered, "({x}, {y})");
                        inside += 1;
                    } else {
                        assert_eq!(shown, setup.lighting.background, "({x}, {y})");
                        outside += 1;
                    }
                }
                assert!(
                    inside > 0 && outside > 0,
                    "{inside} inside, {outside} outside"
                );
            }
        }
    }
}

/// The preview goes out on a worker's corner mesh, traced before the
/// frame's set-up: before any stage of the move's packages is complete,
/// and once (the second worker's mesh is dropped); the stage's results
/// then make its image without a second message.
#[test]
fn the_preview_goes_out_on_the_corner_mesh_before_any_stage_is_complete() {
    let (mut pair, _, _, source) = farm_with_a_source();
    let request = ViewRequest {
        job: source,
        offset: [0.02, 0.0, 0.0],
        page_draws_scene: false,
        preview_only: false,
    };
    pair.act(|m, now| m.steer_view(now, request)).unwrap();
    pair.drive(BOUND, |p| !streamed(&p.master).1.is_empty());
    let (generation, messages) = streamed(&pair.master);
    assert_eq!(generation, 1);
    assert_eq!(messages.len(), 1);
    assert_eq!(messages[0].header().quality, Quality::Preview);
    let current = pair.master.views().current().expect("the move is on");
    assert_eq!(current.stages_done, 0, "no stage is complete yet");
    drive_to_stage(&mut pair, 1, Quality::Refine);
    let qualities: Vec<Quality> = (streamed(&pair.master).1.iter())
        .map(|m| m.header().quality)
        .collect();
    assert_eq!(qualities, [Quality::Preview, Quality::Refine]);
}

/// A move that asks for its preview only (a dragging hand's) ends there:
/// in the step its preview is streamed, the master cancels the move's job,
/// and nothing more of it is streamed.
#[test]
fn a_preview_only_move_ends_at_its_preview_and_nothing_more_is_streamed() {
    let (mut pair, _, _, source) = farm_with_a_source();
    let request = ViewRequest {
        job: source,
        offset: [0.02, 0.0, 0.0],
        page_draws_scene: true,
        preview_only: true,
    };
    let job = pair.act(|m, now| m.steer_view(now, request)).unwrap();
    pair.drive(BOUND, |p| !streamed(&p.master).1.is_empty());
    let cancelled = ViewOutcome::Cancelled { generation: 1, job };
    assert!(pair.master.views().outcomes().any(|o| *o == cancelled));
    // Whatever was on its way settles.
    pair.drive(BOUND, |p| {
        p.workers.iter().all(|w| !w.is_running_a_package())
    });
    let (generation, messages) = streamed(&pair.master);
    assert_eq!(generation, 1);
    let qualities: Vec<Quality> = messages.iter().map(|m| m.header().quality).collect();
    assert_eq!(qualities, [Quality::Preview]);
    let ended = (pair.master.views().outcomes()).filter(|o| **o == cancelled);
    assert_eq!(ended.count(), 1, "the move ended once");
}

/// A newer move empties the stream: at no step after it does a message of
/// the cancelled move go out, and the newer move's three stages follow in
/// order.
#[test]
fn a_newer_move_cancels_the_older_and_nothing_of_the_cancelled_move_is_streamed() {
    let (mut pair, _, _, source) = farm_with_a_source();
    let request = |x| ViewRequest {
        job: source,
        offset: [x, 0.0, 0.0],
        page_draws_scene: false,
        preview_only: false,
    };
    pair.act(|m, now| m.steer_view(now, request(0.01))).unwrap();
    drive_to_stage(&mut pair, 1, Quality::Preview);
    assert_eq!(
        streamed(&pair.master).1.len(),
        1,
        "the first move's preview"
    );
    pair.act(|m, now| m.steer_view(now, request(0.02))).unwrap();
    assert_eq!(streamed(&pair.master), (2, Vec::new()));
    let mut seen = Vec::new();
    pair.drive(BOUND, |p| {
        let (generation, messages) = streamed(&p.master);
        assert_eq!(generation, 2);
        for m in &messages {
            assert_eq!(m.header().generation, 2, "a message of the cancelled move");
        }
        seen.push(messages.len());
        messages.len() == STAGES.len()
    });
    assert!(seen.windows(2).all(|w| w[0] <= w[1]), "{seen:?}");
    let qualities: Vec<Quality> = streamed(&pair.master)
        .1
        .iter()
        .map(|m| m.header().quality)
        .collect();
    assert_eq!(qualities, STAGES);
}
