//! The shared finishing step, reflector pixels and groups, and vertex
//! tracing behind the method interface, on a small cockpit frame.

use vtfarm_vertex::Quality;

use super::*;

fn small_cockpit() -> OwnedFrame {
    OwnedFrame::cockpit(0.3, 160, 90)
}

#[test]
fn exact_reflections_through_the_shared_finish_equal_the_reference() {
    let setup = small_cockpit();
    let frame = setup.frame();
    let pixels = frame.pixels();
    assert!(
        pixels.len() > 500,
        "the glass covers {} pixels",
        pixels.len()
    );
    let secondary = frame.secondary_tracer();
    let reflections: Vec<Reflection> = pixels
        .iter()
        .map(|p| {
            let terms = frame.tracer.surface_terms(&p.point, p.incoming);
            match terms.reflection {
                Some(ray) => {
                    let s = secondary.trace(&ray);
                    let hit = setup.bvh.closest_hit(&ray, f32::INFINITY);
                    Reflection {
                        radiance: s.color,
                        object: hit.map_or(NONE, |h| {
                            setup.bvh.scene().triangles[h.triangle.index()].object.raw()
                        }),
                    }
                }
                None => Reflection::NONE,
            }
        })
        .collect();
    let (bitmap, rays) = shade_reflector(&frame, &pixels, &reflections, None);
    assert!(rays > 0, "the cover glass transmits");
    let reference = VertexTracing::reference().render(&frame).bitmap;
    assert_eq!(bitmap.mask, reference.mask);
    assert_eq!((bitmap.x0, bitmap.y0), (reference.x0, reference.y0));
    assert_eq!(bitmap.reflected_object, reference.reflected_object);
    for (a, b) in bitmap.color.iter().zip(&reference.color) {
        assert!((*a - *b).abs().max_element() < 1e-5, "{a} vs {b}");
    }
    // The components split as the reference splits them: a back surface's
    // ghost image is reflected light.
    for (ours, theirs) in [
        (&bitmap.reflected, &reference.reflected),
        (&bitmap.transmitted, &reference.transmitted),
    ] {
        for (a, b) in ours.iter().zip(theirs) {
            assert!((*a - *b).abs().max_element() < 1e-5, "{a} vs {b}");
        }
    }
}

#[test]
fn reflector_pixels_are_exactly_the_id_buffer_pixels_of_the_reflector() {
    let setup = small_cockpit();
    let frame = setup.frame();
    let flags = frame.reflector_flags();
    let expected = setup
        .ids
        .triangle
        .iter()
        .filter(|&&t| flags.get(t as usize).copied().unwrap_or(false))
        .count();
    let pixels = frame.pixels();
    assert_eq!(pixels.len(), expected);
    assert!(
        pixels
            .windows(2)
            .all(|w| (w[0].y, w[0].x) < (w[1].y, w[1].x))
    );
}

#[test]
fn preview_counts_fewer_samples_than_the_reference() {
    let setup = small_cockpit();
    let frame = setup.frame();
    let preview = VertexTracing {
        settings: VertexSettings {
            quality: Quality::Preview,
            ..Default::default()
        },
    }
    .render(&frame);
    let reference = VertexTracing::reference().render(&frame);
    assert_eq!(preview.bitmap.mask, reference.bitmap.mask);
    assert_eq!(preview.counters.pixels, reference.counters.pixels);
    assert!(preview.counters.rays < reference.counters.rays);
    assert_eq!(preview.counters.searches, 0);
}

#[test]
fn method_names_round_trip_and_only_vertex_tracing_splits_reflectors() {
    for kind in MethodKind::ALL {
        assert_eq!(MethodKind::from_name(kind.name()), Some(kind));
        assert_eq!(kind.per_reflector(), kind != MethodKind::VertexTracing);
    }
    assert_eq!(MethodKind::from_name("raytrace"), None);
}

#[test]
fn reflector_groups_are_objects_and_merged_groups_equal_one_render() {
    let setup = small_cockpit();
    let scene = setup.bvh.scene();
    let back = scene
        .object_id(vtfarm_cockpit::COVER_GLASS_BACK)
        .expect("the cockpit has a glass back");
    // Two objects: the glass front and its back.
    let mut both = setup.reflector.clone();
    both.extend(scene.triangles_of(back));
    let groups = reflector_groups(scene, &both);
    assert_eq!(groups.len(), 2);
    assert_eq!(groups[0].len() + groups[1].len(), both.len());
    assert_eq!(
        groups[0], setup.reflector,
        "the front has the lower object id"
    );
    // Rendering each group and merging equals rendering the front alone
    // (the back shows no pixels of its own in front of the front).
    let frame = setup.frame();
    let whole = VertexTracing::reference().render(&frame).bitmap;
    let parts: Vec<SparseBitmap> = groups
        .iter()
        .map(|g| {
            VertexTracing::reference()
                .render(&MethodFrame {
                    reflector: g,
                    ..frame
                })
                .bitmap
        })
        .collect();
    assert_eq!(merge_bitmaps(setup.ids.width, &parts), whole);
}

#[test]
fn the_base_frame_is_the_rasterizers_image() {
    let setup = small_cockpit();
    let (image, ids) = vtfarm_raster::rasterize(setup.bvh.scene(), &setup.camera, &setup.lighting);
    assert_eq!(ids, setup.ids);
    assert_eq!(setup.base_frame(), image);
}

#[test]
fn vertex_tracing_honours_the_packages_stop() {
    let setup = small_cockpit();
    for settings in [
        VertexSettings::default(),
        VertexTracing::reference().settings,
    ] {
        check_honours_stop(&VertexTracing { settings }, &setup.frame());
    }
}
