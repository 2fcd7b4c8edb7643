//! Vertex tracing against the per-pixel reference, and the package
//! independence the farm relies on.

use std::f32::consts::PI;
use std::sync::Arc;

use glam::Vec3;
use rand::{Rng as _, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use vtfarm_cockpit::{COVER_GLASS, CockpitConfig, cockpit};
use vtfarm_render::{ErrorFigures, FrameSetup, RenderOptions, Renderer, compare, split_packages};
use vtfarm_scene::{
    Camera, Light, LightKind, Lighting, Material, MaterialId, Object, Scene, Triangle, TriangleId,
};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{
    FrameImage, PackageOptions, Quality, VertexSettings, reflector_bounds, trace_package,
};

/// A UV sphere (smooth normals) appended to `scene` as object `name`.
fn add_sphere(
    scene: &mut Scene,
    name: &str,
    material: Material,
    centre: Vec3,
    radius: f32,
    rings: u32,
    segments: u32,
) {
    let mut part = Scene {
        objects: vec![Object { name: name.into() }],
        materials: vec![material],
        ..Scene::default()
    };
    for r in 0..=rings {
        let theta = PI * r as f32 / rings as f32;
        for s in 0..=segments {
            let phi = 2.0 * PI * s as f32 / segments as f32;
            let n = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            part.positions.push(centre + n * radius);
            part.normals.push(n);
        }
    }
    let row = segments + 1;
    for r in 0..rings {
        for s in 0..segments {
            let (a, b, c, d) = (
                r * row + s,
                r * row + s + 1,
                (r + 1) * row + s,
                (r + 1) * row + s + 1,
            );
            for vertices in [[a, c, b], [b, c, d]] {
                let [p, q, w] = vertices.map(|v| part.positions[v as usize]);
                if (q - p).cross(w - p).length() > 1e-9 {
                    part.triangles.push(Triangle {
                        vertices,
                        object: vtfarm_scene::ObjectId(0),
                        material: MaterialId(0),
                    });
                }
            }
        }
    }
    scene.append(&part);
}

fn emissive(name: &str, color: Vec3) -> Material {
    Material {
        emission: color,
        ..Material::diffuse(name, color * 0.2)
    }
}

/// A mirror sphere in a room of coloured, partly emissive walls: sharp
/// reflected edges everywhere on the sphere.
fn mirror_sphere_scene() -> (Scene, Camera, Lighting) {
    let mut scene = Scene::default();
    let mirror = Material {
        reflectance: Vec3::splat(0.9),
        specular: Vec3::splat(0.3),
        shininess: 40.0,
        ..Material::diffuse("mirror", Vec3::splat(0.05))
    };
    add_sphere(&mut scene, "sphere", mirror, Vec3::ZERO, 1.0, 24, 48);
    let s = 4.0;
    scene.append_quad(
        "floor",
        Material::diffuse("floor", Vec3::new(0.6, 0.5, 0.4)),
        Vec3::new(-s, -1.5, s),
        Vec3::X * 2.0 * s,
        Vec3::NEG_Z * 2.0 * s,
    );
    scene.append_quad(
        "back",
        emissive("back", Vec3::new(0.9, 0.2, 0.2)),
        Vec3::new(-s, -1.5, -s),
        Vec3::X * 2.0 * s,
        Vec3::Y * 6.0,
    );
    scene.append_quad(
        "left",
        emissive("left", Vec3::new(0.2, 0.9, 0.3)),
        Vec3::new(-s, -1.5, s),
        Vec3::NEG_Z * 2.0 * s,
        Vec3::Y * 6.0,
    );
    scene.append_quad(
        "window",
        emissive("window", Vec3::splat(3.0)),
        Vec3::new(s - 0.01, 0.0, 1.0),
        Vec3::NEG_Z * 2.0,
        Vec3::Y * 1.5,
    );
    scene.append_quad(
        "block",
        Material::diffuse("block", Vec3::new(0.2, 0.3, 0.8)),
        Vec3::new(-1.0, -1.5, 2.0),
        Vec3::X * 0.8,
        Vec3::Y * 1.2,
    );
    let camera = Camera {
        eye: Vec3::new(0.5, 0.8, 3.5),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 40.0,
        width: 160,
        height: 120,
    };
    let lighting = Lighting {
        lights: vec![Light {
            kind: LightKind::Point {
                position: Vec3::new(2.0, 3.0, 2.0),
            },
            color: Vec3::ONE,
            intensity: 0.8,
        }],
        ambient: Vec3::splat(0.1),
        background: Vec3::new(0.2, 0.3, 0.5),
    };
    (scene, camera, lighting)
}

fn object_triangles(scene: &Scene, name: &str) -> Vec<TriangleId> {
    let object = scene.object_id(name).expect("object exists");
    scene.triangles_of(object).collect()
}

fn setup(camera: Camera, lighting: &Lighting, quality: Quality) -> FrameSetup {
    FrameSetup {
        camera,
        lighting: lighting.clone(),
        trace: TraceSettings::default(),
        vertex: VertexSettings {
            quality,
            ..VertexSettings::default()
        },
    }
}

/// Renders every level and returns the error figures of each against the reference.
fn levels_against_reference(
    renderer: &Renderer,
    camera: Camera,
    lighting: &Lighting,
) -> Vec<(Quality, ErrorFigures, u64)> {
    let render = |q| {
        renderer.render(
            &setup(camera, lighting, q),
            &RenderOptions::default(),
            &mut |_, _| {},
        )
    };
    let reference = render(Quality::Reference);
    assert!(
        reference.stats.pixels > 1000,
        "the reflector must be on screen: {} pixels",
        reference.stats.pixels
    );
    [Quality::Preview, Quality::Refine, Quality::Full]
        .into_iter()
        .map(|q| {
            let frame = render(q);
            let objects = object_map_agreement(&frame.image, &reference.image);
            eprintln!(
                "{:<8} reflected-object map agrees on {:.3}%",
                q.name(),
                objects * 100.0
            );
            if q == Quality::Full {
                assert!(
                    objects >= 0.995,
                    "full: the reflected-object map agrees on {:.3}% of reflector pixels",
                    objects * 100.0
                );
            }
            assert_eq!(
                frame.image.glass().collect::<Vec<_>>(),
                reference.image.glass().collect::<Vec<_>>(),
                "{}: every level covers the same pixels",
                q.name()
            );
            let err = compare(&frame.image, &reference.image);
            eprintln!(
                "{:<8} {:>6} samples vs {:>6}: {:.3}% off by >8/255, mean {:.3}",
                q.name(),
                frame.stats.samples(),
                reference.stats.samples(),
                err.share_off * 100.0,
                err.mean_abs
            );
            (q, err, frame.stats.samples())
        })
        .collect()
}

/// The share of the reference's reflector pixels where `test` mirrors the
/// same object.
fn object_map_agreement(test: &FrameImage, reference: &FrameImage) -> f64 {
    let pixels: Vec<usize> = reference.glass().collect();
    let same = pixels
        .iter()
        .filter(|&&i| test.pixel(i).object == reference.pixel(i).object)
        .count();
    same as f64 / pixels.len().max(1) as f64
}

/// A large mirror made of two triangles (each about 10,000 pixels on
/// screen) facing a dim room with small bright lamps (about 19 pixels
/// across in the mirror) that reflect between its corners: no corner sample
/// sees them, so only the sampling-density guarantee (`max_edge`) finds them.
fn large_triangle_scene() -> (Scene, Camera, Lighting) {
    let mut scene = Scene::default();
    let mirror = Material {
        reflectance: Vec3::splat(0.8),
        ..Material::diffuse("mirror", Vec3::splat(0.05))
    };
    scene.append_quad(
        "mirror",
        mirror,
        Vec3::new(-2.0, -1.5, 0.0),
        Vec3::X * 4.0,
        Vec3::Y * 3.0,
    );
    // The wall behind the eye that the mirror shows, dim.
    scene.append_quad(
        "wall",
        Material::diffuse("wall", Vec3::splat(0.3)),
        Vec3::new(-20.0, -20.0, 12.0),
        Vec3::Y * 40.0,
        Vec3::X * 40.0,
    );
    // Small lamps on that wall, between where the corners' reflections land.
    let mut k = 0;
    for ix in -2..=2 {
        for iy in -1..=1 {
            let centre = Vec3::new(ix as f32 * 3.1 + 0.4, iy as f32 * 3.3 + 0.3, 11.9);
            scene.append_quad(
                &format!("lamp{k}"),
                emissive("lamp", Vec3::new(3.0, 2.5, 1.5)),
                centre - Vec3::new(0.7, 0.7, 0.0),
                Vec3::Y * 1.4,
                Vec3::X * 1.4,
            );
            k += 1;
        }
    }
    let camera = Camera {
        eye: Vec3::new(0.3, 0.2, 6.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 40.0,
        width: 240,
        height: 180,
    };
    let lighting = Lighting {
        lights: Vec::new(),
        ambient: Vec3::splat(0.2),
        background: Vec3::ZERO,
    };
    (scene, camera, lighting)
}

/// Renders every level of `scene` with object `reflector` as the
/// reflector, checks that `full` is within 8/255 of the reference on 99% of
/// the reflector's pixels (and its reflected-object map on 99.5%), and
/// returns the renderer and every level's figures.
fn full_against_reference(
    scene: Scene,
    reflector: &str,
    camera: Camera,
    lighting: &Lighting,
) -> (Renderer, Vec<(Quality, ErrorFigures, u64)>) {
    let reflectors = object_triangles(&scene, reflector);
    let renderer = Renderer::new(Arc::new(scene), reflectors);
    let figures = levels_against_reference(&renderer, camera, lighting);
    let (_, full, _) = figures[2];
    assert!(
        full.share_off <= 0.01,
        "full: {:.3}% of pixels off",
        full.share_off * 100.0
    );
    (renderer, figures)
}

#[test]
fn full_finds_small_reflected_objects_between_the_corners_of_large_triangles() {
    let (scene, camera, lighting) = large_triangle_scene();
    let (renderer, _) = full_against_reference(scene, "mirror", camera, &lighting);
    // Without the guarantee the same frame misses lamps.
    let reference = renderer.render(
        &setup(camera, &lighting, Quality::Reference),
        &RenderOptions::default(),
        &mut |_, _| {},
    );
    let mut unguarded = setup(camera, &lighting, Quality::Full);
    unguarded.vertex.max_edge = 1e6;
    let frame = renderer.render(&unguarded, &RenderOptions::default(), &mut |_, _| {});
    let objects = object_map_agreement(&frame.image, &reference.image);
    assert!(
        objects < 0.995,
        "without max_edge the map agrees on {:.3}%: the scene must reproduce the miss",
        objects * 100.0
    );
}

#[test]
fn full_matches_reference_on_a_mirror_sphere() {
    let (scene, camera, lighting) = mirror_sphere_scene();
    let (_, figures) = full_against_reference(scene, "sphere", camera, &lighting);
    // The levels trade accuracy for samples in order.
    assert!(figures[0].1.share_off >= figures[1].1.share_off);
    assert!(figures[1].1.share_off >= figures[2].1.share_off);
}

#[test]
fn full_matches_reference_on_the_cockpit() {
    let c = cockpit(&CockpitConfig {
        detail: 0.3,
        ..CockpitConfig::default()
    });
    let camera = Camera {
        width: 320,
        height: 180,
        ..c.camera
    };
    let (_, figures) = full_against_reference(c.scene, COVER_GLASS, camera, &c.lighting);
    assert!(figures[2].2 > 0);
}

/// Renders with the given packages and returns the composited frame.
fn render_with(
    renderer: &Renderer,
    setup: &FrameSetup,
    packages: &[Vec<TriangleId>],
) -> FrameImage {
    renderer
        .render_packages(setup, packages, &RenderOptions::default(), &mut |_, _| {})
        .image
}

/// The scenes the farm's invariants are checked on: a mirror sphere, and
/// the cockpit's cover glass (thin-glass model) `cockpit_width` pixels wide.
fn farm_scenes(cockpit_width: u32) -> [(Scene, &'static str, Camera, Lighting); 2] {
    let (sphere, sphere_camera, sphere_lighting) = mirror_sphere_scene();
    let c = cockpit(&CockpitConfig {
        detail: 0.3,
        ..CockpitConfig::default()
    });
    let cockpit_camera = Camera {
        width: cockpit_width,
        height: cockpit_width * 9 / 16,
        ..c.camera
    };
    [
        (sphere, "sphere", sphere_camera, sphere_lighting),
        (c.scene, COVER_GLASS, cockpit_camera, c.lighting),
    ]
}

#[test]
fn random_packages_give_byte_identical_images() {
    for (scene, reflector, camera, lighting) in farm_scenes(160) {
        check_random_packages(scene, reflector, camera, &lighting);
    }
}

/// Renders `scene` whole and in shuffled packages of several sizes at every
/// level and checks that every buffer is bit-identical.
fn check_random_packages(scene: Scene, reflector: &str, camera: Camera, lighting: &Lighting) {
    let reflectors = object_triangles(&scene, reflector);
    let renderer = Renderer::new(Arc::new(scene), reflectors.clone());
    for quality in [Quality::Preview, Quality::Refine, Quality::Full] {
        let s = setup(camera, lighting, quality);
        let whole = render_with(&renderer, &s, std::slice::from_ref(&reflectors));
        let mut shuffled = reflectors.clone();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        for i in (1..shuffled.len()).rev() {
            shuffled.swap(i, rng.random_range(0..=i));
        }
        for size in [1, 7, 100] {
            let split = render_with(&renderer, &s, &split_packages(&shuffled, size));
            let differing = (0..whole.color.pixels.len())
                .filter(|&i| {
                    split.color.pixels[i] != whole.color.pixels[i]
                        || split.pixel(i).object != whole.pixel(i).object
                })
                .count();
            assert_eq!(
                differing,
                0,
                "{} with packages of {size}: pixels differ",
                quality.name()
            );
            assert!(
                split == whole,
                "{} with packages of {size}: every buffer bit-identical",
                quality.name()
            );
        }
    }
}

#[test]
fn workers_id_buffers_over_the_reflector_bounds_give_the_same_frame() {
    // Also the farm tests' small cockpit frame with the eye moved sideways.
    let [_, (small, _, small_camera, small_lighting)] = farm_scenes(96);
    let moved = Camera {
        eye: small_camera.eye + Vec3::new(0.03, 0.0, 0.0),
        ..small_camera
    };
    let moved_eye = (small, COVER_GLASS, moved, small_lighting);
    for (scene, reflector, camera, lighting) in farm_scenes(320).into_iter().chain([moved_eye]) {
        let reflectors = object_triangles(&scene, reflector);
        let renderer = Renderer::new(Arc::new(scene), reflectors.clone());
        let mut is_reflector = vec![false; renderer.scene().triangles.len()];
        reflectors
            .iter()
            .for_each(|&t| is_reflector[t.index()] = true);
        let margin = VertexSettings::default().visibility_radius + 1;
        let bounds = reflector_bounds(renderer.scene(), &camera, &is_reflector, margin);
        let area = (bounds.x1 - bounds.x0) * (bounds.y1 - bounds.y0);
        if reflector == COVER_GLASS {
            assert!(
                area < camera.width * camera.height / 2,
                "the glass's bounds {bounds:?} must leave most of the frame out"
            );
        }
        for quality in [Quality::Preview, Quality::Refine, Quality::Full] {
            let s = setup(camera, &lighting, quality);
            // The master: whole-frame buffers.
            let master = render_with(&renderer, &s, std::slice::from_ref(&reflectors));
            // A worker: the bounded buffers and the thin-glass terms computed
            // per finished pixel, packages composited the same way.
            let (base, full_ids) = renderer.base_frame(&s);
            let (ids, behind) = renderer.id_buffers(&s);
            for (x, y) in bounds.pixels() {
                assert_eq!(
                    ids.triangle_at(x, y),
                    full_ids.triangle_at(x, y),
                    "({x}, {y})"
                );
            }
            let frame = renderer.frame(&s, &ids, &behind);
            let mut worker = renderer.frame_image(&s, base);
            for package in split_packages(&reflectors, 7) {
                let result =
                    trace_package(&frame, &package, &PackageOptions::default(), &mut |_| {});
                worker.composite(&result.bitmap);
            }
            assert!(
                worker == master,
                "{reflector} at {}: the worker's frame differs from the master's",
                quality.name()
            );
        }
    }
}

#[test]
fn thin_glass_model_agrees_with_traced_transmission_on_a_flat_pane() {
    // A 3-mm slab of glass (front surface the reflector, back surface 3 mm
    // behind) in front of a board of coloured stripes, a lamp behind the eye.
    let mut scene = Scene::default();
    let glass = Material {
        reflectance: Vec3::splat(0.1),
        transmittance: Vec3::splat(0.85),
        ior: 1.5,
        ..Material::diffuse("glass", Vec3::splat(0.01))
    };
    let (w, h) = (1.2, 0.9);
    scene.append_quad(
        "pane",
        glass.clone(),
        Vec3::new(-w, -h, 0.0),
        Vec3::X * 2.0 * w,
        Vec3::Y * 2.0 * h,
    );
    scene.append_quad(
        "pane_back",
        glass,
        Vec3::new(-w, -h, -0.003),
        Vec3::Y * 2.0 * h,
        Vec3::X * 2.0 * w,
    );
    for k in 0..12 {
        let x = -1.5 + k as f32 * 0.25;
        let color = if k % 2 == 0 {
            Vec3::new(0.8, 0.2, 0.1)
        } else {
            Vec3::new(0.1, 0.3, 0.8)
        };
        scene.append_quad(
            &format!("stripe{k}"),
            Material::diffuse("stripe", color),
            Vec3::new(x, -1.5, -0.4),
            Vec3::X * 0.25,
            Vec3::Y * 3.0,
        );
    }
    scene.append_quad(
        "lamp",
        emissive("lamp", Vec3::splat(2.0)),
        Vec3::new(-0.5, 0.2, 5.0),
        Vec3::Y * 0.6,
        Vec3::X * 1.0,
    );
    let camera = Camera {
        eye: Vec3::new(0.4, 0.3, 2.5),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 45.0,
        width: 240,
        height: 180,
    };
    let lighting = Lighting {
        lights: vec![Light {
            kind: LightKind::Point {
                position: Vec3::new(0.5, 1.0, -0.2),
            },
            color: Vec3::ONE,
            intensity: 0.6,
        }],
        ambient: Vec3::splat(0.3),
        background: Vec3::splat(0.1),
    };
    let reflectors = object_triangles(&scene, "pane");
    let renderer = Renderer::new(Arc::new(scene), reflectors);
    let s = setup(camera, &lighting, Quality::Reference);
    let reference = renderer
        .render(&s, &RenderOptions::default(), &mut |_, _| {})
        .image;
    // The reference with its traced transmitted part (through both surfaces,
    // the back one's reflection included) replaced by the raster model's.
    let (_, ids) = renderer.base_frame(&s);
    let behind = renderer.behind(&s, &ids);
    let modelled = vtfarm_render::thin_glass_model(&reference, &renderer.frame(&s, &ids, &behind));
    let err = compare(&modelled, &reference);
    assert!(err.pixels > 10_000, "the pane covers {} pixels", err.pixels);
    // The slab shifts the view by well under a pixel here: only stripe
    // edges may differ.
    assert!(
        err.share_off <= 0.01,
        "model vs traced: {:.3}% of pixels off, mean {:.3}",
        err.share_off * 100.0,
        err.mean_abs
    );
    // The stripes are seen at all: the transmitted part carries the image.
    let transmitted: f32 = reference
        .glass()
        .map(|i| reference.pixel(i).transmitted.max_element())
        .sum();
    assert!(transmitted > 0.1 * err.pixels as f32);
}

#[test]
fn shadow_maps_kept_from_a_nearby_frame_change_no_pixel() {
    // Two frames of the farm's small cockpit with eyes 1 mm apart: the
    // second reuses the first's shadow maps, and gives what a renderer that
    // never saw the first frame gives.
    let [_, (scene, reflector, camera, lighting)] = farm_scenes(96);
    let reflectors = object_triangles(&scene, reflector);
    let scene = Arc::new(scene);
    let moved = Camera {
        eye: camera.eye + Vec3::new(0.001, 0.0, 0.0),
        ..camera
    };
    let warm = Renderer::new(scene.clone(), reflectors.clone());
    let cold = Renderer::new(scene, reflectors.clone());
    for quality in [Quality::Preview, Quality::Full] {
        let render = |renderer: &Renderer, camera: Camera| {
            let s = setup(camera, &lighting, quality);
            render_with(renderer, &s, std::slice::from_ref(&reflectors))
        };
        render(&warm, camera);
        let before = warm.shadow_cache().builds();
        let reused = render(&warm, moved);
        assert_eq!(
            warm.shadow_cache().builds(),
            before,
            "the maps were rebuilt"
        );
        assert!(
            reused == render(&cold, moved),
            "{}: reused shadow maps changed the frame",
            quality.name()
        );
    }
    assert_eq!(cold.shadow_cache().builds(), 1);
}
