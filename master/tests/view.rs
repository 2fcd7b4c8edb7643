//! The interactive view through the sans-IO core (`Pair`: real worker
//! sessions, virtual clock): moving the eye cancels the outdated view's
//! job and only the newest eye is rendered to `full`, equal to the
//! single-process render of that eye.

#[path = "support/frame.rs"]
mod frame;

mod support;

use frame::small_frame;
use std::sync::Arc;
use std::time::Duration;

use glam::Vec3;
use support::pair::Pair;
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_master::FarmRules;
use vtfarm_master::view::{EYE_BOX, ViewError, ViewOutcome, ViewRequest};
use vtfarm_master::{JobOptions, wire_job};
use vtfarm_method::MethodKind;
use vtfarm_proto::SceneData;
use vtfarm_render::Renderer;
use vtfarm_vertex::Quality;

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
        job: 99,
        offset: [0.0; 3],
    };
    assert_eq!(
        pair.act(|m, now| m.steer_view(now, unknown)),
        Err(ViewError::UnknownSource(99))
    );
    let bad = ViewRequest {
        job: source,
        offset: [f32::NAN, 0.0, 0.0],
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
    assert_eq!(stages, [Quality::Preview, Quality::Refine, Quality::Full]);
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
    assert!(latest.image.pixels == reference.image.color.pixels);
    // Its glare figures are those of the composited components.
    assert_eq!(latest.glare.glass_pixels, reference.image.glass().count());
    assert!(latest.object_map.width >= latest.image.width);
}
