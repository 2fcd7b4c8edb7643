//! One progressive frame (`Renderer::progressive`): set up once, taken
//! through preview, refine and full on the same vertices, each stage's
//! image byte for byte the frame rendered from scratch at that quality (what
//! `vtfarm render --quality` writes: the farm composites the same packages),
//! each stage tracing only the vertices its quality adds and no pixel an
//! earlier stage traced. A farm worker's progressive frame (its packages
//! advanced on one `Renderer::id_buffers` set-up) gives the same images and
//! computes each glass pixel's thin-glass terms once for all stages.

use std::sync::Arc;

use glam::Vec3;
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_render::{FrameSetup, RenderOptions, RenderedFrame, Renderer, split_packages};
use vtfarm_scene::{Camera, Lighting, Material, MaterialId, Object, Scene, Triangle, TriangleId};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{PackageOptions, ProgressivePackage, Quality, Transmission, VertexSettings};

fn small_cockpit() -> (Renderer, FrameSetup) {
    let c = cockpit(&CockpitConfig {
        detail: 0.3,
        ..CockpitConfig::default()
    });
    let reflectors = c.cover_glass_triangles();
    let setup = FrameSetup {
        camera: Camera {
            width: 240,
            height: 135,
            ..c.camera
        },
        lighting: c.lighting,
        trace: TraceSettings::default(),
        vertex: VertexSettings::default(),
    };
    (Renderer::new(Arc::new(c.scene), reflectors), setup)
}

/// A floor mirror and a pane of glass (kr 0.1, kt 0.6) in front of three
/// coloured walls, each quad two triangles; the mirror and the pane reflect.
fn quads(transmission: Transmission) -> (Renderer, FrameSetup) {
    let mut scene = Scene::default();
    let quads = [
        (
            Material {
                reflectance: Vec3::splat(0.9),
                ..Material::diffuse("mirror", Vec3::splat(0.05))
            },
            [
                (-4.0, 0.0, 1.0),
                (4.0, 0.0, 1.0),
                (4.0, 0.0, -5.0),
                (-4.0, 0.0, -5.0),
            ],
        ),
        (
            Material {
                reflectance: Vec3::splat(0.1),
                transmittance: Vec3::splat(0.6),
                ..Material::diffuse("pane", Vec3::ZERO)
            },
            [
                (-1.5, 0.4, -2.0),
                (0.5, 0.4, -2.0),
                (0.5, 1.8, -2.0),
                (-1.5, 1.8, -2.0),
            ],
        ),
        (
            Material::diffuse("red", Vec3::new(0.8, 0.1, 0.1)),
            [
                (-4.0, 0.0, -5.0),
                (0.0, 0.0, -5.0),
                (0.0, 3.0, -5.0),
                (-4.0, 3.0, -5.0),
            ],
        ),
        (
            Material::diffuse("green", Vec3::new(0.1, 0.7, 0.2)),
            [
                (0.0, 0.0, -5.0),
                (4.0, 0.0, -5.0),
                (4.0, 3.0, -5.0),
                (0.0, 3.0, -5.0),
            ],
        ),
        (
            Material::diffuse("blue", Vec3::new(0.1, 0.2, 0.9)),
            [
                (-0.6, 0.0, -3.5),
                (0.2, 0.0, -3.5),
                (0.2, 0.9, -3.5),
                (-0.6, 0.9, -3.5),
            ],
        ),
    ];
    for (id, (material, corners)) in quads.into_iter().enumerate() {
        let corners = corners.map(|(x, y, z)| Vec3::new(x, y, z));
        let base = scene.positions.len() as u32;
        let normal = (corners[1] - corners[0])
            .cross(corners[3] - corners[0])
            .normalize();
        scene.positions.extend(corners);
        scene.normals.extend([normal; 4]);
        scene.objects.push(Object {
            name: material.name.clone(),
        });
        scene.materials.push(material);
        for vertices in [[0, 1, 2], [0, 2, 3]] {
            scene.triangles.push(Triangle {
                vertices: vertices.map(|v| base + v),
                object: vtfarm_scene::ObjectId(id as u32),
                material: MaterialId(id as u32),
            });
        }
    }
    let setup = FrameSetup {
        camera: Camera {
            eye: Vec3::new(0.3, 1.2, 0.5),
            target: Vec3::new(0.0, 0.7, -4.0),
            up: Vec3::Y,
            fov_y_deg: 60.0,
            width: 160,
            height: 120,
        },
        lighting: Lighting {
            lights: vec![vtfarm_scene::Light {
                kind: vtfarm_scene::LightKind::Directional {
                    direction: Vec3::new(0.3, -1.0, -0.4).normalize(),
                    angular_diameter_deg: 0.0,
                },
                color: Vec3::ONE,
                intensity: 0.8,
            }],
            ambient: Vec3::splat(0.2),
            background: Vec3::splat(0.05),
        },
        trace: TraceSettings::default(),
        vertex: VertexSettings {
            transmission,
            ..VertexSettings::default()
        },
    };
    let reflectors: Vec<TriangleId> = TriangleId::range(4).collect();
    (Renderer::new(Arc::new(scene), reflectors), setup)
}

/// The stages of one progressive frame against three renders from scratch.
fn check(renderer: &Renderer, setup: &FrameSetup, name: &str) {
    let options = RenderOptions {
        package_size: 16,
        ..RenderOptions::default()
    };
    let set_ups = renderer.set_ups();
    let mut progressive = renderer.progressive(setup, &options);
    let mut scratch_samples = 0;
    let (mut traced_pixels, mut scratch_pixels) = (0, 0);
    for quality in [Quality::Preview, Quality::Refine, Quality::Full] {
        let stage = progressive.advance(quality).unwrap();
        let scratch = render_at(renderer, setup, quality, &options);
        let image = progressive.image();
        assert_eq!(
            image.color.to_srgb8(),
            scratch.image.color.to_srgb8(),
            "{name} {quality:?}: the bytes"
        );
        assert!(*image == scratch.image, "{name} {quality:?}: the values");
        assert!(scratch.stats.pixels > 100, "{name}: {:?}", scratch.stats);
        // Refine's new samples are refine's total less preview's, and so on.
        assert_eq!(
            stage.stats.vertex_samples,
            scratch.stats.vertex_samples - scratch_samples,
            "{name} {quality:?}"
        );
        scratch_samples = scratch.stats.vertex_samples;
        // Pixels traced one by one: only those no earlier stage traced.
        assert!(stage.stats.filled_pixels <= scratch.stats.filled_pixels);
        traced_pixels += stage.stats.filled_pixels;
        scratch_pixels += scratch.stats.filled_pixels;
        // Each stage has vertices of its own to add here (at this size the
        // cockpit's glass has no edge longer than the default maximum).
        if quality != Quality::Full || setup.vertex.max_edge < 24.0 {
            assert!(stage.stats.vertex_samples > 0, "{name} {quality:?}");
        }
    }
    // Rim pixels no face reaches are traced at every level from scratch,
    // once in a progressive frame.
    assert!(
        traced_pixels < scratch_pixels,
        "{name}: {traced_pixels} {scratch_pixels}"
    );
    // One set-up for the three stages, one per render from scratch.
    assert_eq!(renderer.set_ups() - set_ups, 1 + 3, "{name}");
}

#[test]
fn progressive_stages_equal_renders_from_scratch_on_the_cockpit() {
    let (renderer, setup) = small_cockpit();
    check(&renderer, &setup, "cockpit");
    // A shorter maximum edge, so that `full` splits agreeing edges too.
    let short_edges = FrameSetup {
        vertex: VertexSettings {
            max_edge: 2.5,
            ..setup.vertex
        },
        ..setup
    };
    check(&renderer, &short_edges, "cockpit, 2.5-px edges");
}

#[test]
fn progressive_stages_equal_renders_from_scratch_on_a_mirror_and_a_pane() {
    for transmission in Transmission::ALL {
        let (renderer, setup) = quads(transmission);
        check(&renderer, &setup, transmission.name());
    }
}

#[test]
fn a_progressive_frame_may_skip_a_stage_but_not_go_back() {
    let (renderer, setup) = quads(Transmission::Raster);
    let options = RenderOptions::default();
    let mut progressive = renderer.progressive(&setup, &options);
    progressive.advance(Quality::Preview).unwrap();
    progressive.advance(Quality::Full).unwrap();
    let full = renderer.render(&setup, &options, &mut |_, _| {});
    assert!(*progressive.image() == full.image);
    assert!(progressive.advance(Quality::Refine).is_err());
}

/// A worker's progressive frame: the thin-glass terms computed as its
/// packages finish pixels, each glass pixel's once for the three stages
/// (counted, against the up-front pass of a whole frame), and each stage's
/// image, composited from the packages' bitmaps, the frame rendered from
/// scratch at that quality.
#[test]
fn a_workers_progressive_frame_computes_each_glass_pixels_terms_once() {
    let (cockpit, cockpit_setup) = small_cockpit();
    let (pane, pane_setup) = quads(Transmission::Raster);
    for (renderer, setup, name) in [
        (cockpit, cockpit_setup, "cockpit"),
        (pane, pane_setup, "pane"),
    ] {
        let (base, full_ids) = renderer.base_frame(&setup);
        let upfront = renderer.behind(&setup, &full_ids).glass_computations();
        let scene = renderer.scene();
        let glass_pixels = (full_ids.triangle.iter())
            .filter_map(|&t| TriangleId::from_raw(t))
            .filter(|t| renderer.reflectors().contains(t) && scene.material_of(*t).see_through())
            .count() as u64;
        assert!(glass_pixels > 100, "{name}: {glass_pixels} glass pixels");
        assert_eq!(upfront, glass_pixels, "{name}: the up-front pass");

        let (ids, behind) = renderer.id_buffers(&setup);
        assert_eq!(
            behind.glass_computations(),
            0,
            "{name}: none before a package"
        );
        let frame = renderer.frame(&setup, &ids, &behind);
        let mut packages: Vec<ProgressivePackage> = split_packages(renderer.reflectors(), 16)
            .iter()
            .map(|package| ProgressivePackage::new(&frame, package))
            .collect();
        let mut image = renderer.frame_image(&setup, base.clone());
        for quality in [Quality::Preview, Quality::Refine, Quality::Full] {
            for package in &mut packages {
                let stage =
                    (package.advance(&frame, quality, &PackageOptions::default(), &mut |_| {}))
                        .unwrap();
                image.composite(&stage.bitmap);
            }
            let scratch = render_at(&renderer, &setup, quality, &RenderOptions::default());
            assert!(image == scratch.image, "{name} {quality:?}: the values");
            // Every glass pixel is finished at each stage, its terms
            // computed at the first alone.
            assert_eq!(
                behind.glass_computations(),
                glass_pixels,
                "{name} {quality:?}: terms computed"
            );
        }
    }
}

/// `setup` rendered from scratch at `quality`.
fn render_at(
    renderer: &Renderer,
    setup: &FrameSetup,
    quality: Quality,
    options: &RenderOptions,
) -> RenderedFrame {
    let setup = FrameSetup {
        vertex: VertexSettings {
            quality,
            ..setup.vertex
        },
        ..setup.clone()
    };
    renderer.render(&setup, options, &mut |_, _| {})
}
