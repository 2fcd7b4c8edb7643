//! The frame pipeline on the built-in cockpit: the rasterizer's ID buffer
//! against the ray tracer's first hits, and progressive delivery of faces.

use std::sync::Arc;
use std::time::Duration;

use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_render::{FrameSetup, Renderer};
use vtfarm_scene::{Camera, NONE, TriangleId};
use vtfarm_trace::{Ray, TraceSettings};
use vtfarm_vertex::{PackageOptions, Quality, VertexSettings, trace_package};

fn small_cockpit() -> (Renderer, FrameSetup) {
    let c = cockpit(&CockpitConfig {
        detail: 0.3,
        ..CockpitConfig::default()
    });
    let reflectors: Vec<TriangleId> = c.cover_glass_triangles();
    let setup = FrameSetup {
        camera: Camera {
            width: 240,
            height: 135,
            ..c.camera
        },
        lighting: c.lighting,
        trace: TraceSettings::default(),
        vertex: VertexSettings {
            quality: Quality::Full,
            ..VertexSettings::default()
        },
    };
    (Renderer::new(Arc::new(c.scene), reflectors), setup)
}

#[test]
fn id_buffer_agrees_with_ray_cast_first_hits_on_the_cockpit() {
    let (renderer, setup) = small_cockpit();
    let (_, ids) = renderer.base_frame(&setup);
    let camera = setup.camera;
    let mut agree = 0;
    for y in 0..camera.height {
        for x in 0..camera.width {
            let ray = Ray {
                origin: camera.eye,
                direction: camera.pixel_ray(x, y),
            };
            let hit = renderer
                .bvh()
                .closest_hit(&ray, f32::INFINITY)
                .map_or(NONE, |h| h.triangle.raw());
            agree += (hit == ids.triangle_at(x, y)) as u32;
        }
    }
    let share = agree as f64 / (camera.width * camera.height) as f64;
    assert!(
        share >= 0.995,
        "ID buffer agrees with the ray cast on {:.3}% of pixels",
        share * 100.0
    );
}

#[test]
fn time_breaks_deliver_the_preview_then_every_refined_face() {
    let (renderer, setup) = small_cockpit();
    let (_, ids) = renderer.base_frame(&setup);
    let behind = renderer.behind(&setup, &ids);
    let frame = renderer.frame(&setup, &ids, &behind);
    let mut deliveries = Vec::new();
    let options = PackageOptions {
        collect_faces: true,
        time_break: Some(Duration::ZERO),
    };
    let result = trace_package(&frame, renderer.reflectors(), &options, &mut |faces| {
        deliveries.push(faces.to_vec())
    });
    assert!(
        deliveries.len() >= 2,
        "a preview and at least one refinement break: {}",
        deliveries.len()
    );
    // The first break shows the unrefined triangles (the preview) ...
    assert_eq!(deliveries[0].len() as u64, result.stats.traced_triangles);
    // ... and the later ones, together, every final face exactly once.
    let refined: Vec<_> = deliveries[1..].concat();
    assert_eq!(refined, result.faces);
    assert!(
        result.faces.len() as u64 > result.stats.traced_triangles,
        "the refinement split faces"
    );
}

#[test]
fn glass_pixels_split_into_reflected_and_transmitted_light() {
    let (renderer, setup) = small_cockpit();
    let frame = renderer.render(&setup, &Default::default(), &mut |_, _| {});
    let image = &frame.image;
    let glass: Vec<usize> = image.glass().collect();
    assert!(!glass.is_empty());
    let seen_through = glass
        .iter()
        .filter(|&&i| image.pixel(i).transmitted.max_element() > 0.0)
        .count();
    assert!(
        seen_through * 10 > glass.len() * 9,
        "the instruments are seen through the glass"
    );
    for &i in &glass {
        // Colour = local Phong (never negative) + reflected + transmitted.
        let p = image.pixel(i);
        let local = p.color - p.reflected - p.transmitted;
        assert!(local.min_element() > -1e-4, "pixel {i}: {local}");
    }
    // Outside the glass both components stay black.
    let outside = (0..image.color.pixels.len())
        .find(|&i| !image.is_glass(i))
        .unwrap();
    assert_eq!(image.pixel(outside).transmitted, glam::Vec3::ZERO);
    assert_eq!(image.pixel(outside).reflected, glam::Vec3::ZERO);
    assert_eq!(image.pixel(outside).object, NONE);
}

/// A whole frame ([`Renderer::finish_frame`]) in the buffers a frame of
/// another size and eye left behind is bit for bit the one a fresh renderer
/// finishes: the kept buffers carry nothing over.
#[test]
fn a_whole_frame_in_kept_buffers_is_the_one_in_fresh_buffers() {
    let (renderer, setup) = small_cockpit();
    let other = FrameSetup {
        camera: Camera {
            width: 320,
            height: 150,
            eye: setup.camera.eye + glam::Vec3::new(0.03, 0.0, 0.01),
            ..setup.camera
        },
        ..setup.clone()
    };
    let finish = |renderer: &Renderer, setup: &FrameSetup| {
        let (ids, behind) = renderer.id_buffers(setup);
        let frame = renderer.frame(setup, &ids, &behind);
        let options = PackageOptions::default();
        let traced = trace_package(&frame, renderer.reflectors(), &options, &mut |_| {});
        renderer.finish_frame(setup, &traced.bitmap, |image, _| {
            let bits: Vec<u32> = (image.color.pixels.iter())
                .flat_map(|p| p.to_array().map(f32::to_bits))
                .collect();
            (bits, image.components())
        })
    };
    let fresh = |setup: &FrameSetup| finish(&small_cockpit().0, setup);
    let (first, second, third) = (
        finish(&renderer, &other),
        finish(&renderer, &setup),
        finish(&renderer, &other),
    );
    assert!(first == fresh(&other), "the first frame");
    assert!(
        second == fresh(&setup),
        "a smaller frame in the larger one's buffers"
    );
    assert!(
        third == fresh(&other),
        "a larger frame in the smaller one's buffers"
    );
    assert_ne!(first.0, second.0, "the two frames differ");
}
