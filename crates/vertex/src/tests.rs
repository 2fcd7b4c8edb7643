//! The vertex tracer on tiny hand-made frames whose splits can be worked out
//! on paper.
//!
//! The frame: a 64 × 64 camera at (0, 0, 10) looking down -z at a mirror
//! square spanning ±2 in x and y at z = 0, so one world unit on the mirror is
//! 8 pixels and the square covers pixels 16..48. The mirror is two triangles:
//! A = (-2,-2) (2,-2) (2,2) (on screen (16,48) (48,48) (48,16)) and
//! B = (-2,-2) (2,2) (-2,2). Behind the eye a red emitting wall at z = 20
//! fills the mirror's view; a blue emitting patch at z = 19.9 covers wall
//! x > 3, y < -3. A mirror point (x, y, 0) sees the patch plane at
//! (2.99 x, 2.99 y), so only mirror points with x > 1.003 and y < -1.003 see
//! blue (pixels 40..48 in x and y): of the corners, only A's (2, -2).
//!
//! Refining triangle A with a 20-pixel floor, by hand: the hypotenuse
//! (45 px) has red at both ends and stays; the bottom leg (32 px, red–blue)
//! splits at (0, -2), which sees red; its halves (16 px) are under the floor,
//! the new edge to (2, 2) (36 px) is red–red, and the face (0,-2) (2,-2) (2,2)
//! has h / c = 14.3 / 35.8 = 0.4, not flat. The right leg (32 px, blue–red)
//! splits at (2, 0), red; again the halves are short, the edge to (0, -2)
//! (22.6 px) is red–red, and the one disagreeing face left, (0,-2) (2,-2)
//! (2,0), is a right isosceles triangle (h / c = 0.5). So: 2 splits, 5
//! samples, 3 faces, and at `full` that last face (16 px legs, screen
//! (32,48) (48,48) (48,32)) is filled per pixel: the 120 pixel centres inside
//! it and the 16 on its hypotenuse, where it ties with its neighbour and
//! wins as the earlier face.

use std::sync::Arc;

use glam::Vec3;
use vtfarm_raster::IdBuffer;
use vtfarm_scene::{Camera, Lighting, Material, Scene, TriangleId};
use vtfarm_trace::{SceneBvh, TraceSettings, Tracer};

use crate::{
    Behind, Frame, GlassPass, PackageOptions, PackageResult, ProgressivePackage, Quality,
    ShadowCache, SparseBitmap, StageError, Stop, Stopped, Transmission, VertexOwners,
    VertexSettings, trace_package,
};

/// The default thresholds without the maximum edge length, so that only
/// the criteria under test split edges (the hand-worked splits assume it).
fn unguarded() -> VertexSettings {
    VertexSettings {
        max_edge: f32::MAX,
        ..VertexSettings::default()
    }
}

/// Mirror triangle A (the one with the blue corner) and B.
const A: TriangleId = TriangleId(0);
const B: TriangleId = TriangleId(1);

/// What a test frame holds besides the mirror.
#[derive(Clone, Copy, Default)]
struct Extras {
    /// An opaque grey strip in front of the mirror hiding its bottom edge
    /// (mirror y in about [-2.5, -1.5]) from the eye.
    bottom_occluder: bool,
}

struct TestFrame {
    bvh: SceneBvh,
    lighting: Lighting,
    camera: Camera,
    ids: IdBuffer,
    behind: Behind,
    owners: VertexOwners,
}

fn emitter(name: &str, color: Vec3) -> Material {
    Material {
        emission: color,
        ..Material::diffuse(name, Vec3::ZERO)
    }
}

/// Appends a quad `corner + s * u + t * v` as one object named after its material.
fn quad(scene: &mut Scene, material: Material, corner: Vec3, u: Vec3, v: Vec3) {
    let name = material.name.clone();
    scene.append_quad(&name, material, corner, u, v);
}

impl TestFrame {
    fn new(extras: Extras) -> TestFrame {
        let mut scene = Scene::default();
        let mirror = Material {
            reflectance: Vec3::ONE,
            ..Material::diffuse("mirror", Vec3::ZERO)
        };
        // Triangles 0 and 1: A = (-2,-2) (2,-2) (2,2), B = (-2,-2) (2,2) (-2,2).
        quad(
            &mut scene,
            mirror,
            Vec3::new(-2.0, -2.0, 0.0),
            Vec3::X * 4.0,
            Vec3::Y * 4.0,
        );
        // Walls behind the eye, facing the mirror (-z).
        quad(
            &mut scene,
            emitter("red", Vec3::new(1.0, 0.0, 0.0)),
            Vec3::new(-20.0, -20.0, 20.0),
            Vec3::Y * 40.0,
            Vec3::X * 40.0,
        );
        quad(
            &mut scene,
            emitter("blue", Vec3::new(0.0, 0.0, 1.0)),
            Vec3::new(3.0, -11.0, 19.9),
            Vec3::Y * 8.0,
            Vec3::X * 8.0,
        );
        if extras.bottom_occluder {
            // At depth 1 (z = 9) a tenth of the mirror's size covers the same pixels.
            quad(
                &mut scene,
                Material::diffuse("grey", Vec3::splat(0.5)),
                Vec3::new(-0.25, -0.25, 9.0),
                Vec3::X * 0.5,
                Vec3::Y * 0.1,
            );
        }
        let camera = Camera {
            eye: Vec3::new(0.0, 0.0, 10.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            // tan(fov / 2) = 0.4: the half height at depth 10 is 4 units = 32 px.
            fov_y_deg: 2.0 * 0.4f32.atan().to_degrees(),
            width: 64,
            height: 64,
        };
        let ids = vtfarm_raster::id_buffer(&scene, &camera);
        let mut is_reflector = vec![false; scene.triangles.len()];
        is_reflector[A.index()] = true;
        is_reflector[B.index()] = true;
        let owners = VertexOwners::new(&scene);
        let bvh = SceneBvh::new(Arc::new(scene));
        let lighting = Lighting {
            lights: Vec::new(),
            ambient: Vec3::ZERO,
            background: Vec3::ZERO,
        };
        let tracer = Tracer {
            bvh: &bvh,
            lighting: &lighting,
            settings: TraceSettings::default(),
            cone: vtfarm_trace::PixelCone::FINEST,
        };
        let behind = Behind::new(
            &tracer,
            &camera,
            &ids,
            &is_reflector,
            Transmission::Raster,
            GlassPass::Upfront,
            &ShadowCache::default(),
        );
        TestFrame {
            bvh,
            lighting,
            camera,
            ids,
            behind,
            owners,
        }
    }

    fn frame(&self, settings: VertexSettings) -> Frame<'_> {
        Frame {
            tracer: Tracer {
                bvh: &self.bvh,
                lighting: &self.lighting,
                settings: TraceSettings::default(),
                cone: vtfarm_trace::PixelCone::FINEST,
            },
            camera: self.camera,
            ids: &self.ids,
            behind: &self.behind,
            owners: &self.owners,
            settings,
            stop: None,
        }
    }

    fn trace(&self, settings: VertexSettings, triangles: &[TriangleId]) -> PackageResult {
        trace_package(
            &self.frame(settings),
            triangles,
            &PackageOptions::default(),
            &mut |_| {},
        )
    }

    /// The pixels the ID buffer gives to `triangle`.
    fn owned_pixels(&self, triangle: TriangleId) -> u64 {
        self.ids
            .triangle
            .iter()
            .filter(|&&t| t == triangle.raw())
            .count() as u64
    }
}

/// One refinement case: the frame, the thresholds that differ from the
/// defaults, and the package.
#[derive(Clone, Copy)]
struct Case {
    extras: Extras,
    quality: Quality,
    pixel_floor: f32,
    triangles: &'static [TriangleId],
}

impl Default for Case {
    fn default() -> Self {
        Case {
            extras: Extras::default(),
            quality: Quality::Full,
            pixel_floor: 20.0,
            triangles: &[A],
        }
    }
}

/// Traces the case and compares its counters, written as
/// `samples=.. splits=.. faces=.. filled=..`, with `expect` (`filled=A`
/// stands for all of triangle A's pixels).
fn check(case: Case, expect: &str) {
    let frame = TestFrame::new(case.extras);
    let settings = VertexSettings {
        quality: case.quality,
        pixel_floor: case.pixel_floor,
        ..unguarded()
    };
    let s = frame.trace(settings, case.triangles).stats;
    let filled = if s.filled_pixels == frame.owned_pixels(A) {
        "A".to_owned()
    } else {
        s.filled_pixels.to_string()
    };
    let got = format!(
        "samples={} splits={} faces={} filled={filled}",
        s.vertex_samples, s.refined_edges, s.faces
    );
    assert_eq!(got, expect);
}

#[test]
fn refinement_splits_only_edges_whose_ends_see_different_objects() {
    // Worked out in the module docs: both legs at the blue corner split once.
    check(Case::default(), "samples=5 splits=2 faces=3 filled=136");
    // B's corners all see red: nothing to refine, nothing to fill.
    check(
        Case {
            triangles: &[B],
            ..Case::default()
        },
        "samples=3 splits=0 faces=1 filled=0",
    );
    // Both together share the corners (-2,-2) and (2,2): traced once.
    check(
        Case {
            triangles: &[A, B],
            ..Case::default()
        },
        "samples=6 splits=2 faces=4 filled=136",
    );
}

#[test]
fn the_pixel_floor_stops_refinement() {
    // Legs of 32 px under a 33-px floor: no split, and the one face still
    // disagrees, so `full` fills all of A.
    check(
        Case {
            pixel_floor: 33.0,
            ..Case::default()
        },
        "samples=3 splits=0 faces=1 filled=A",
    );
    // With a 2-px floor the split goes on along the colour boundary.
    let frame = TestFrame::new(Extras::default());
    let settings = VertexSettings {
        pixel_floor: 2.0,
        ..unguarded()
    };
    let fine = frame.trace(settings, &[A]).stats;
    assert!(fine.refined_edges > 2, "{fine:?}");
    assert!(fine.filled_pixels < 136, "{fine:?}");
}

#[test]
fn preview_and_refine_fill_no_pixel() {
    check(
        Case {
            quality: Quality::Preview,
            ..Case::default()
        },
        "samples=3 splits=0 faces=1 filled=0",
    );
    check(
        Case {
            quality: Quality::Refine,
            ..Case::default()
        },
        "samples=5 splits=2 faces=3 filled=0",
    );
}

#[test]
fn an_edge_with_both_ends_hidden_is_not_refined() {
    // The strip hides (-2,-2) and (2,-2): the bottom leg stays whole; the
    // right leg (one end visible) still splits at (2,0), after which the
    // disagreeing face (-2,-2) (2,-2) (2,0) has h / c = 14.3 / 35.8 = 0.4.
    check(
        Case {
            extras: Extras {
                bottom_occluder: true,
            },
            quality: Quality::Refine,
            ..Case::default()
        },
        "samples=4 splits=1 faces=2 filled=0",
    );
}

#[test]
fn vertex_visibility_follows_the_id_buffer() {
    let plain = TestFrame::new(Extras::default());
    let hidden = TestFrame::new(Extras {
        bottom_occluder: true,
    });
    let projector = plain.frame(unguarded()).projector();
    let at = |x: f32, y: f32, z: f32| {
        projector
            .project(Vec3::new(x, y, z))
            .expect("in front of the eye")
    };
    let cases = [
        // (point, visible in the plain frame, visible with the strip)
        ((2.0, -2.0, 0.0), true, false),
        ((-2.0, -2.0, 0.0), true, false),
        ((2.0, 2.0, 0.0), true, true),
        ((0.0, 0.0, 0.0), true, true),
        // Same pixel, but 1 unit behind the mirror: depth off by 10%.
        ((0.0, 0.0, -1.0), false, false),
        // Off the mirror's pixels (the neighbourhood is 1 pixel).
        ((2.5, 0.0, 0.0), false, false),
    ];
    for ((x, y, z), plain_visible, hidden_visible) in cases {
        let s = at(x, y, z);
        let got = (
            plain.frame(unguarded()).vertex_visible(A, s),
            hidden.frame(unguarded()).vertex_visible(A, s),
        );
        assert_eq!(got, (plain_visible, hidden_visible), "at ({x}, {y}, {z})");
    }
}

#[test]
fn triangle_filling_gives_reference_pixels_where_interpolation_would_blur() {
    let frame = TestFrame::new(Extras::default());
    let run = |quality| {
        frame
            .trace(
                VertexSettings {
                    quality,
                    pixel_floor: 20.0,
                    ..unguarded()
                },
                &[A],
            )
            .bitmap
    };
    let reference = run(Quality::Reference);
    assert_eq!(reference.color.len() as u64, frame.owned_pixels(A));
    let off = |image: &crate::SparseBitmap| {
        assert_eq!(image.mask, reference.mask);
        image
            .color
            .iter()
            .zip(&reference.color)
            .filter(|(a, b)| (**a - **b).abs().max_element() > 1e-5)
            .count()
    };
    // The blue patch (pixels 40..48 in x and y) lies inside the filled face,
    // and every other face has three red corners: `full` is the reference.
    assert_eq!(off(&run(Quality::Full)), 0);
    // Without filling, the blue corner's colour smears over its face.
    assert!(off(&run(Quality::Refine)) > 40);
}

#[test]
fn the_flatness_guard_splits_a_flat_face_across_its_agreeing_long_edge() {
    // With a 14-px floor, the first split (bottom leg at (0,-2)) leaves the
    // disagreeing face (0,-2) (2,-2) (2,2): h = 14.3 px over its long edge
    // c = 35.8 px from (0,-2) to (2,2), whose ends both see red. Edge
    // refinement never splits that edge; the guard does when h / c = 0.4 is
    // under v, inserting (1, 0), on screen (40, 32).
    let frame = TestFrame::new(Extras::default());
    let has_guard_vertex = |flatness| {
        let settings = VertexSettings {
            pixel_floor: 14.0,
            flatness,
            ..unguarded()
        };
        let result = trace_package(
            &frame.frame(settings),
            &[A],
            &PackageOptions {
                collect_faces: true,
                time_break: None,
            },
            &mut |_| {},
        );
        result.faces.iter().any(|f| {
            f.corners
                .iter()
                .any(|c| (c.x - 40.0).abs() < 1e-3 && (c.y - 32.0).abs() < 1e-3)
        })
    };
    assert!(has_guard_vertex(0.45));
    assert!(!has_guard_vertex(0.2));
}

/// Traces triangle A at `full` (2 splits, 136 filled pixels) under `stop`.
fn trace_with_stop(frame: &TestFrame, stop: &Stop) -> PackageResult {
    let settings = VertexSettings {
        pixel_floor: 20.0,
        ..unguarded()
    };
    let frame = Frame {
        stop: Some(stop),
        ..frame.frame(settings)
    };
    trace_package(&frame, &[A], &PackageOptions::default(), &mut |_| {})
}

#[test]
fn a_cancelled_package_stops_before_refining_or_filling() {
    let frame = TestFrame::new(Extras::default());
    let stop = Stop::with_budget(u64::MAX);
    stop.cancel();
    let result = trace_with_stop(&frame, &stop);
    assert_eq!(stop.stopped(), Some(Stopped::Cancelled));
    // Only the corners were traced: no split, no filled pixel.
    let s = result.stats;
    assert_eq!(
        (s.vertex_samples, s.refined_edges, s.filled_pixels),
        (3, 0, 0)
    );
    assert!(result.bitmap.color.is_empty());
}

#[test]
fn a_sample_budget_stops_a_package_that_needs_more() {
    let frame = TestFrame::new(Extras::default());
    let unlimited = trace_with_stop(&frame, &Stop::with_budget(u64::MAX));
    let needed = unlimited.stats.samples();
    assert_eq!(needed, 5 + 136, "the hand-worked case");

    // Exactly enough: the same result, not stopped.
    let enough = Stop::with_budget(needed);
    let result = trace_with_stop(&frame, &enough);
    assert_eq!(enough.stopped(), None);
    assert_eq!(result.bitmap, unlimited.bitmap);

    // One short: stopped, within a sample of the budget.
    let short = Stop::with_budget(needed - 1);
    let result = trace_with_stop(&frame, &short);
    assert_eq!(
        short.stopped(),
        Some(Stopped::OverBudget { budget: needed - 1 })
    );
    assert!(result.stats.samples() <= needed);
    // Four samples: the corners and one split, then the second split is over.
    let tiny = Stop::with_budget(4);
    let result = trace_with_stop(&frame, &tiny);
    assert_eq!(tiny.stopped(), Some(Stopped::OverBudget { budget: 4 }));
    assert_eq!(result.stats.filled_pixels, 0);
}

#[test]
fn batched_pixels_and_vertices_equal_one_at_a_time() {
    let frame = TestFrame::new(Extras::default());
    for transmission in Transmission::ALL {
        let f = frame.frame(VertexSettings {
            transmission,
            ..unguarded()
        });
        // Both triangles' pixels in one batch, traced as the reference
        // does and as triangle filling does.
        let pixels: Vec<(TriangleId, u32, u32)> = (0..f.ids.height)
            .flat_map(|y| (0..f.ids.width).map(move |x| (x, y)))
            .filter_map(|(x, y)| {
                [A, B]
                    .into_iter()
                    .find(|&t| f.owns(t, x, y))
                    .map(|t| (t, x, y))
            })
            .collect();
        assert_eq!(
            pixels.len() as u64,
            frame.owned_pixels(A) + frame.owned_pixels(B)
        );
        for reference in [true, false] {
            let one_by_one: Vec<_> = pixels
                .iter()
                .map(|&p| f.trace_pixels(&[p], reference)[0])
                .collect();
            assert_eq!(f.trace_pixels(&pixels, reference), one_by_one);
        }

        let scene = frame.bvh.scene();
        let vertices: Vec<(TriangleId, Vec3, Vec3)> = [A, B]
            .iter()
            .flat_map(|&t| {
                scene.triangles[t.index()]
                    .vertices
                    .map(|v| (t, scene.positions[v as usize], scene.normals[v as usize]))
            })
            .collect();
        let single: Vec<_> = vertices
            .iter()
            .map(|&(t, p, n)| f.shade_vertex(t, p, n))
            .collect();
        assert_eq!(f.shade_vertices(&vertices), single, "{transmission:?}");
    }
}

/// The pixels of a bitmap as (x, y) → their bits, for byte-exact
/// comparison of composited stages.
type PixelBits = std::collections::BTreeMap<(u32, u32), crate::PixelBits>;

fn composite(pixels: &mut PixelBits, bitmap: &SparseBitmap) {
    pixels.extend(bitmap.pixel_bits());
}

/// Preview, refine and full on one package's vertices and edges give, stage
/// by stage, the pixels of the package traced from scratch at each quality,
/// each stage's bitmap holding only what changed; no vertex is traced
/// twice: each stage traces the samples its quality adds (counted by the
/// stop's meter too), and the package is set up once.
#[test]
fn progressive_stages_equal_packages_traced_from_scratch_and_trace_each_vertex_once() {
    let frame = TestFrame::new(Extras::default());
    let stages = [Quality::Preview, Quality::Refine, Quality::Full];
    // The hand-worked thresholds, the defaults (the maximum edge splits at
    // `full`) and a fine floor.
    let settings = [
        VertexSettings {
            pixel_floor: 20.0,
            ..unguarded()
        },
        VertexSettings::default(),
        VertexSettings {
            pixel_floor: 2.0,
            max_edge: 8.0,
            ..VertexSettings::default()
        },
    ];
    for settings in settings {
        let meter = Stop::with_budget(u64::MAX);
        let f = Frame {
            stop: Some(&meter),
            ..frame.frame(settings)
        };
        let mut package = ProgressivePackage::new(&f, &[A, B]);
        let mut progressive = PixelBits::new();
        let mut scratch_before = None;
        let mut changed = Vec::new();
        for quality in stages {
            let charged = meter.charged();
            let stage = package
                .advance(&f, quality, &PackageOptions::default(), &mut |_| {})
                .unwrap();
            assert_eq!(package.stage(), Some(quality));
            assert_eq!(meter.charged() - charged, stage.stats.samples());
            composite(&mut progressive, &stage.bitmap);
            changed.push(stage.bitmap.color.len());

            let scratch = frame.trace(
                VertexSettings {
                    quality,
                    ..settings
                },
                &[A, B],
            );
            let mut expected = PixelBits::new();
            composite(&mut expected, &scratch.bitmap);
            assert_eq!(progressive, expected, "{quality:?} {settings:?}");
            // The vertices this stage traced are those its quality adds.
            let before = scratch_before.map_or(0, |s: crate::PackageStats| s.vertex_samples);
            assert_eq!(
                stage.stats.vertex_samples,
                scratch.stats.vertex_samples - before,
                "{quality:?} {settings:?}"
            );
            assert_eq!(
                (stage.stats.faces, stage.stats.pixels),
                (scratch.stats.faces, scratch.stats.pixels)
            );
            scratch_before = Some(scratch.stats);
        }
        // Every owned pixel at the first stage; later, only what changed
        // (with the hand-worked thresholds, B's pixels never do).
        let owned = (frame.owned_pixels(A) + frame.owned_pixels(B)) as usize;
        assert_eq!(changed[0], owned);
        if settings.max_edge == f32::MAX {
            let a = frame.owned_pixels(A) as usize;
            assert!(changed[1..].iter().all(|&n| n <= a), "{changed:?}");
        }
        // Stages go forward only.
        assert_eq!(
            package
                .advance(&f, Quality::Refine, &PackageOptions::default(), &mut |_| {})
                .map(|_| ()),
            Err(StageError::NotLater {
                from: Quality::Full,
                to: Quality::Refine
            })
        );
    }
    // The hand-worked case: 3 corners at preview, 2 splits at refine, none
    // more at full, where A's disagreeing face is filled.
    let settings = VertexSettings {
        pixel_floor: 20.0,
        ..unguarded()
    };
    let f = frame.frame(settings);
    let mut package = ProgressivePackage::new(&f, &[A]);
    let counts: Vec<(u64, u64, u64)> = stages
        .iter()
        .map(|&q| {
            let s = package
                .advance(&f, q, &PackageOptions::default(), &mut |_| {})
                .unwrap()
                .stats;
            (s.vertex_samples, s.refined_edges, s.filled_pixels)
        })
        .collect();
    assert_eq!(counts, [(3, 0, 0), (2, 2, 0), (0, 0, 136)]);
}

/// Stages advanced on their meshes only write no pixel and trace each
/// vertex once as the full stages do; the next stage with pixels then
/// holds every owned pixel, the package traced from scratch at its quality
/// bit for bit, and the meshes are those of the full stages.
#[test]
fn mesh_only_stages_leave_the_next_stage_every_pixel_of_its_scratch_trace() {
    let frame = TestFrame::new(Extras::default());
    let settings = VertexSettings {
        pixel_floor: 2.0,
        max_edge: 8.0,
        ..VertexSettings::default()
    };
    let f = frame.frame(settings);
    let options = PackageOptions::default();
    let mut meshes_only = ProgressivePackage::new(&f, &[A, B]);
    let mut with_pixels = ProgressivePackage::new(&f, &[A, B]);
    let mut vertex_samples = 0;
    for quality in [Quality::Preview, Quality::Refine] {
        let stage = (meshes_only.advance_meshes(&f, quality, &options, &mut |_| {})).unwrap();
        let full = (with_pixels.advance(&f, quality, &options, &mut |_| {})).unwrap();
        assert_eq!(meshes_only.stage(), Some(quality));
        assert!(stage.bitmap.color.is_empty(), "{quality:?} wrote pixels");
        assert_eq!(stage.stats.pixels, 0);
        assert_eq!(stage.stats.vertex_samples, full.stats.vertex_samples);
        assert_eq!(
            meshes_only.meshes(&f),
            with_pixels.meshes(&f),
            "{quality:?}"
        );
        vertex_samples += stage.stats.vertex_samples;
    }
    let stage = (meshes_only.advance(&f, Quality::Full, &options, &mut |_| {})).unwrap();
    let scratch = frame.trace(
        VertexSettings {
            quality: Quality::Full,
            ..settings
        },
        &[A, B],
    );
    let (mut got, mut expected) = (PixelBits::new(), PixelBits::new());
    composite(&mut got, &stage.bitmap);
    composite(&mut expected, &scratch.bitmap);
    let owned = (frame.owned_pixels(A) + frame.owned_pixels(B)) as usize;
    assert_eq!(got.len(), owned, "every owned pixel");
    assert_eq!(got, expected);
    vertex_samples += stage.stats.vertex_samples;
    assert_eq!(vertex_samples, scratch.stats.vertex_samples);
}
