//! Scene-level tests with analytic expectations: mirror sphere, slab
//! refraction, total internal reflection, shadows, BVH against brute force,
//! signatures, batches and determinism.

use std::sync::Arc;

use glam::Vec3;
use vtfarm_scene::{Light, LightKind, Lighting, Material, NONE, ObjectId, Scene, TriangleId};

use crate::testutil::{SceneBuilder, TestRng, emitter, glass, mirror};
use crate::whitted::{reflect, refract};
use crate::{
    BuildPreset, BvhLayout, BvhOptions, Hit, PixelCone, Ray, Rays, Sample, SceneBvh, SurfacePoint,
    TraceSettings, Tracer,
};

fn dark() -> Lighting {
    Lighting {
        lights: Vec::new(),
        ambient: Vec3::ZERO,
        background: Vec3::new(0.01, 0.02, 0.03),
    }
}

fn point_light(position: Vec3) -> Light {
    Light {
        kind: LightKind::Point { position },
        color: Vec3::ONE,
        intensity: 1.0,
    }
}

fn bvh(builder: SceneBuilder) -> SceneBvh {
    assert_eq!(builder.scene.validate(), Ok(()));
    SceneBvh::new(Arc::new(builder.scene))
}

fn tracer<'a>(bvh: &'a SceneBvh, lighting: &'a Lighting) -> Tracer<'a> {
    Tracer {
        bvh,
        lighting,
        settings: TraceSettings::default(),
        cone: PixelCone::FINEST,
    }
}

fn assert_close(actual: Vec3, expected: Vec3, tolerance: f32) {
    assert!(
        (actual - expected).abs().max_element() <= tolerance,
        "{actual} != {expected} (±{tolerance})"
    );
}

/// The surface point a ray hits, for tests that call `shade`.
fn point_on(bvh: &SceneBvh, origin: Vec3, target: Vec3) -> SurfacePoint {
    let ray = Ray {
        origin,
        direction: (target - origin).normalize(),
    };
    let hit = bvh
        .closest_hit(&ray, f32::INFINITY)
        .expect("the test aims the ray at a surface");
    bvh.surface_point(&hit)
}

#[test]
fn mirror_sphere_reflects_in_the_analytic_direction() {
    let eye = Vec3::new(0.0, 0.0, 6.0);
    let target_light = Vec3::new(1.0, 0.5, 0.25);
    for normal in [
        Vec3::new(0.3, 0.2, 1.0),
        Vec3::new(-0.5, 0.4, 0.8),
        Vec3::new(0.1, -0.7, 0.7),
    ] {
        // On the exact sphere the ray towards p = n reflects about n.
        let n = normal.normalize();
        let incoming = (n - eye).normalize();
        let r = incoming - 2.0 * incoming.dot(n) * n;
        let (side, _) = r.any_orthonormal_pair();

        let mut b = SceneBuilder::default();
        b.icosphere(mirror("chrome"), Vec3::ZERO, 1.0, 4);
        let target = b.square(emitter("target", target_light), n + r * 3.0, -r, 0.2);
        let decoy = b.square(
            emitter("decoy", Vec3::new(0.2, 0.9, 0.1)),
            n + r * 3.0 + side * 0.45,
            -r,
            0.2,
        );
        let bvh = bvh(b);
        let lighting = dark();
        let ray = Ray {
            origin: eye,
            direction: incoming,
        };
        let sample = tracer(&bvh, &lighting).trace(&ray);

        assert_eq!(sample.reflected_object, target.raw(), "decoy is {decoy}");
        // kr = 1 and nothing else lights the sphere: it shows the panel exactly.
        assert_eq!(sample.color, target_light);
        assert_eq!(sample.reflected, target_light);

        // The smooth-normal reflection is within a fraction of a degree of
        // the exact sphere's.
        let hit = bvh
            .closest_hit(&ray, f32::INFINITY)
            .expect("the ray aims at the sphere");
        let point = bvh.surface_point(&hit);
        assert!(point.position.distance(n) < 2e-3, "{}", point.position);
        let angle = reflect(incoming, point.normal)
            .angle_between(r)
            .to_degrees();
        assert!(angle < 0.5, "reflection off by {angle}°");
    }
}

/// A glass slab with faces y = 0 and y = -thickness; thin emissive strips
/// along z at y = -screen_depth, strip i covering x in [i w, (i + 1) w] and
/// emitting (i + 1, 0, 0).
fn slab_with_strips(thickness: f32, screen_depth: f32, strip_width: f32, strips: u32) -> SceneBvh {
    let mut b = SceneBuilder::default();
    b.quad(
        glass("top", 1.5),
        Vec3::new(-5.0, 0.0, -5.0),
        Vec3::Z * 10.0,
        Vec3::X * 10.0,
    );
    b.quad(
        glass("bottom", 1.5),
        Vec3::new(-5.0, -thickness, -5.0),
        Vec3::X * 10.0,
        Vec3::Z * 10.0,
    );
    for i in 0..strips {
        let corner = Vec3::new(i as f32 * strip_width, -screen_depth, -1.0);
        b.quad(
            emitter("strip", Vec3::new(i as f32 + 1.0, 0.0, 0.0)),
            corner,
            Vec3::Z * 2.0,
            Vec3::X * strip_width,
        );
    }
    bvh(b)
}

#[test]
fn slab_displaces_the_ray_laterally_and_keeps_its_direction() {
    let (thickness, width) = (0.5, 0.01);
    for screen_depth in [1.0f32, 2.0] {
        let bvh = slab_with_strips(thickness, screen_depth, width, 500);
        let lighting = dark();
        for theta_deg in [30.0f32, 45.0, 60.0] {
            let theta = theta_deg.to_radians();
            let direction = Vec3::new(theta.sin(), -theta.cos(), 0.0);
            let sample = tracer(&bvh, &lighting).trace(&Ray {
                origin: -direction * 2.0,
                direction,
            });

            // Without the slab the ray meets the screen at depth * tan θ; the
            // slab shifts it sideways by d = t sin(θ - θ') / cos θ', which is
            // d / cos θ along the horizontal screen.
            let theta_t = (theta.sin() / 1.5).asin();
            let shift = thickness * (theta - theta_t).sin() / theta_t.cos();
            let expected_x = screen_depth * theta.tan() - shift / theta.cos();
            let strip = sample.color.x - 1.0;
            assert_eq!(
                sample.color.x.fract(),
                0.0,
                "saw {} at {theta_deg}°",
                sample.color
            );
            let centre = (strip + 0.5) * width;
            assert!(
                (centre - expected_x).abs() <= 0.5 * width + 1e-4,
                "θ = {theta_deg}°, depth {screen_depth}: strip at x = {centre}, expected {expected_x}"
            );
        }
    }
}

#[test]
fn refraction_follows_snell_and_parallel_faces_restore_the_direction() {
    let up = Vec3::Y;
    for theta_deg in [0.0f32, 20.0, 45.0, 70.0] {
        let theta = theta_deg.to_radians();
        let incoming = Vec3::new(theta.sin(), -theta.cos(), 0.0);
        let inside =
            refract(incoming, up, 1.0 / 1.5).expect("entering glass never reflects totally");
        // Snell: sin θ' = sin θ / 1.5.
        assert!((inside.x - theta.sin() / 1.5).abs() < 1e-6, "{inside}");
        let out =
            refract(inside, up, 1.5).expect("leaving through a parallel face mirrors entering");
        assert!(out.distance(incoming) < 1e-6, "{out} vs {incoming}");
    }
    // Past the critical angle asin(1 / 1.5) = 41.8° light cannot leave.
    let steep = Vec3::new(45f32.to_radians().sin(), -45f32.to_radians().cos(), 0.0);
    assert_eq!(refract(steep, Vec3::Y, 1.5), None);
}

#[test]
fn total_internal_reflection_sends_the_transmitted_energy_into_the_mirror_ray() {
    let mut b = SceneBuilder::default();
    // A thick glass block (faces y = 0 and y = -2) with an emissive panel
    // inside it, and a sky panel above it.
    b.quad(
        glass("top", 1.5),
        Vec3::new(-5.0, 0.0, -5.0),
        Vec3::Z * 10.0,
        Vec3::X * 10.0,
    );
    b.quad(
        glass("bottom", 1.5),
        Vec3::new(-5.0, -2.0, -5.0),
        Vec3::X * 10.0,
        Vec3::Z * 10.0,
    );
    let inner_light = Vec3::new(0.0, 0.0, 3.0);
    let sky_light = Vec3::new(0.0, 5.0, 0.0);
    let inner = b.quad(
        emitter("inner", inner_light),
        Vec3::new(0.1, -0.5, -2.0),
        Vec3::Z * 6.0,
        Vec3::X * 3.0,
    );
    let sky = b.quad(
        emitter("sky", sky_light),
        Vec3::new(-1.0, 1.0, -2.0),
        Vec3::X * 11.0,
        Vec3::Z * 6.0,
    );
    let bvh = bvh(b);
    let lighting = dark();
    let tracer = tracer(&bvh, &lighting);
    // Triangle 0 of the top face covers z >= x; (0, 0, 1) lies inside it.
    let point = SurfacePoint {
        position: Vec3::new(0.0, 0.0, 1.0),
        normal: Vec3::Y,
        triangle: TriangleId(0),
    };

    // Below the critical angle the ray leaves the glass and sees the sky.
    let a = 35f32.to_radians();
    let below = tracer.shade(&point, Vec3::new(a.sin(), a.cos(), 0.0));
    assert_eq!(below.color, sky_light);
    assert_eq!(below.reflected_object, NONE); // kr = 0: no mirror ray at all
    assert_eq!(below.reflected, Vec3::ZERO);

    for degrees in [45.0f32, 60.0] {
        let a = degrees.to_radians();
        let totally_reflected = tracer.shade(&point, Vec3::new(a.sin(), a.cos(), 0.0));
        assert_eq!(totally_reflected.color, inner_light, "{degrees}°");
        assert_eq!(totally_reflected.reflected_object, inner.raw());
        assert_eq!(totally_reflected.reflected, inner_light);
        assert_ne!(totally_reflected.signature, below.signature);
    }
    assert_ne!(sky, inner);
}

#[test]
fn fresnel_moves_transmission_into_reflection_at_grazing_angles() {
    let mut b = SceneBuilder::default();
    b.quad(
        glass("top", 1.5),
        Vec3::new(-5.0, 0.0, -5.0),
        Vec3::Z * 10.0,
        Vec3::X * 10.0,
    );
    let sky_light = Vec3::new(0.0, 5.0, 0.0);
    let sky = b.quad(
        emitter("sky", sky_light),
        Vec3::new(-20.0, 1.0, -2.0),
        Vec3::X * 40.0,
        Vec3::Z * 4.0,
    );
    let bvh = bvh(b);
    let lighting = dark();
    let point = SurfacePoint {
        position: Vec3::new(0.0, 0.0, 1.0),
        normal: Vec3::Y,
        triangle: TriangleId(0),
    };
    let a = 80f32.to_radians();
    let incoming = Vec3::new(a.sin(), -a.cos(), 0.0);

    let plain = tracer(&bvh, &lighting).shade(&point, incoming);
    assert_eq!(plain.reflected_object, NONE);

    let fresnel = Tracer {
        bvh: &bvh,
        lighting: &lighting,
        settings: TraceSettings {
            fresnel: true,
            ..Default::default()
        },
        cone: PixelCone::FINEST,
    };
    let graze = fresnel.shade(&point, incoming);
    assert_eq!(graze.reflected_object, sky.raw());
    // The Fresnel equations at n = 1.5 (kr = 0, kt = 1 head-on): the share
    // (F(θ) − F0) / (1 − F0) of the transmittance moves to the mirror ray.
    let (cos_i, sin_t) = (a.cos(), a.sin() / 1.5);
    let cos_t = (1.0 - sin_t * sin_t).sqrt();
    let rs = (cos_i - 1.5 * cos_t) / (cos_i + 1.5 * cos_t);
    let rp = (1.5 * cos_i - cos_t) / (1.5 * cos_i + cos_t);
    let (f, f0) = (0.5 * (rs * rs + rp * rp), 0.04);
    assert_close(graze.reflected, sky_light * ((f - f0) / (1.0 - f0)), 1e-4);
    // Head-on, the factor is zero: nothing moves to the mirror ray.
    assert_eq!(fresnel.shade(&point, -Vec3::Y).reflected_object, NONE);
}

/// Floor (y = 0), a square occluder at y = 1 over the origin, and point
/// lights at (-2, 3, 0) and (2, 3, 0). The occluder shades x in [0.25, 1.75]
/// from the first light and x in [-1.75, -0.25] from the second (|z| < 0.75).
struct ShadowScene {
    bvh: SceneBvh,
    lighting: Lighting,
    floor: Material,
}

fn shadow_scene(occluder: Material, lights: &[Vec3]) -> ShadowScene {
    let floor = Material {
        ambient: Vec3::splat(0.5),
        ..Material::diffuse("floor", Vec3::splat(0.5))
    };
    let mut b = SceneBuilder::default();
    b.quad(
        floor.clone(),
        Vec3::new(-10.0, 0.0, -10.0),
        Vec3::Z * 20.0,
        Vec3::X * 20.0,
    );
    b.square(occluder, Vec3::Y, Vec3::Y, 0.5);
    let lighting = Lighting {
        lights: lights.iter().map(|&p| point_light(p)).collect(),
        ambient: Vec3::splat(0.2),
        background: Vec3::ZERO,
    };
    ShadowScene {
        bvh: bvh(b),
        lighting,
        floor,
    }
}

#[test]
fn a_point_behind_an_occluder_gets_only_ambient() {
    let occluders = [
        Material::diffuse("wall", Vec3::splat(0.3)),
        glass("glass", 1.5),
    ];
    for occluder in occluders {
        let s = shadow_scene(occluder, &[Vec3::new(0.0, 3.0, 0.0)]);
        let tracer = tracer(&s.bvh, &s.lighting);
        let ambient_only = s.floor.ambient * s.lighting.ambient;

        // Straight down from under the occluder (transparent ones count as
        // opaque for shadows).
        let under = tracer.trace(&Ray {
            origin: Vec3::new(0.05, 0.5, 0.03),
            direction: -Vec3::Y,
        });
        assert_eq!(under.color, ambient_only);

        // Far from it the light reaches the floor: ambient + Kd (n . l).
        let lit_point = Vec3::new(3.0, 0.0, 0.0);
        let lit = tracer.trace(&Ray {
            origin: lit_point + Vec3::Y,
            direction: -Vec3::Y,
        });
        let n_dot_l = Vec3::Y.dot((Vec3::new(0.0, 3.0, 0.0) - lit_point).normalize());
        assert_close(lit.color, ambient_only + s.floor.diffuse * n_dot_l, 1e-5);
    }

    // A directional light straight down is blocked the same way.
    let mut s = shadow_scene(Material::diffuse("wall", Vec3::splat(0.3)), &[]);
    s.lighting.lights.push(Light {
        kind: LightKind::Directional {
            direction: -Vec3::Y,
            angular_diameter_deg: 0.0,
        },
        color: Vec3::ONE,
        intensity: 2.0,
    });
    let tracer = tracer(&s.bvh, &s.lighting);
    let under = tracer.trace(&Ray {
        origin: Vec3::new(0.1, 0.5, 0.1),
        direction: -Vec3::Y,
    });
    assert_eq!(under.color, s.floor.ambient * s.lighting.ambient);
    let lit = tracer.trace(&Ray {
        origin: Vec3::new(2.0, 0.5, 0.1),
        direction: -Vec3::Y,
    });
    assert_close(
        lit.color,
        s.floor.ambient * s.lighting.ambient + s.floor.diffuse * 2.0,
        1e-5,
    );
}

#[test]
fn a_surface_that_only_emits_casts_no_shadow() {
    // A panel standing for the sky outside a window: the light passes it.
    let light = Vec3::new(0.0, 3.0, 0.0);
    let s = shadow_scene(emitter("sky panel", Vec3::ONE), &[light]);
    let tracer = tracer(&s.bvh, &s.lighting);
    let under_point = Vec3::new(0.05, 0.0, 0.03);
    let under = tracer.trace(&Ray {
        origin: under_point + Vec3::Y * 0.5,
        direction: -Vec3::Y,
    });
    let n_dot_l = Vec3::Y.dot((light - under_point).normalize());
    assert_close(
        under.color,
        s.floor.ambient * s.lighting.ambient + s.floor.diffuse * n_dot_l,
        1e-5,
    );
    // The same ray is still occluded for any-hit queries; only shadows pass.
    let up = Ray {
        origin: under_point,
        direction: Vec3::Y,
    };
    assert!(s.bvh.occluded(&up, f32::INFINITY));
    assert!(!s.bvh.shadowed(&up, f32::INFINITY));
}

#[test]
fn max_depth_one_shades_only_the_first_surface() {
    let mut b = SceneBuilder::default();
    let mut chrome = mirror("chrome");
    chrome.emission = Vec3::splat(0.25);
    b.square(chrome, Vec3::ZERO, Vec3::Z, 1.0);
    b.square(emitter("panel", Vec3::ONE), Vec3::Z * 3.0, -Vec3::Z, 1.0);
    let bvh = bvh(b);
    let lighting = dark();
    let ray = Ray {
        origin: Vec3::new(0.1, 0.1, 2.0),
        direction: -Vec3::Z,
    };
    let shallow = Tracer {
        bvh: &bvh,
        lighting: &lighting,
        settings: TraceSettings {
            max_depth: 1,
            fresnel: false,
            ..Default::default()
        },
        cone: PixelCone::FINEST,
    };
    let sample = shallow.trace(&ray);
    assert_eq!(sample.color, Vec3::splat(0.25));
    assert_eq!(sample.reflected, Vec3::ZERO);
    assert_eq!(sample.reflected_object, NONE);
    // One level more reaches the panel behind the eye.
    let deeper = Tracer {
        settings: TraceSettings {
            max_depth: 2,
            fresnel: false,
            ..Default::default()
        },
        ..shallow
    };
    assert_eq!(deeper.trace(&ray).color, Vec3::splat(1.25));
}

/// A random triangle soup with a shared-edge grid and degenerate triangles.
fn soup(seed: u64) -> Scene {
    let mut rng = TestRng::new(seed);
    let mut b = SceneBuilder::default();
    let random: Vec<[Vec3; 3]> = (0..1500)
        .map(|_| {
            let c = rng.vec3(-1.0, 1.0);
            [
                c + rng.vec3(-0.3, 0.3),
                c + rng.vec3(-0.3, 0.3),
                c + rng.vec3(-0.3, 0.3),
            ]
        })
        .collect();
    b.triangles(Material::default(), &random);
    let degenerate: Vec<[Vec3; 3]> = (0..120)
        .map(|i| {
            let (a, c) = (rng.vec3(-1.0, 1.0), rng.vec3(-1.0, 1.0));
            match i % 3 {
                0 => [a, a, c],
                1 => [a, a.lerp(c, 0.37), c],
                _ => [a, a, a],
            }
        })
        .collect();
    b.triangles(Material::default(), &degenerate);
    // A 12 x 12 grid of quads at z = 0.25: shared edges and vertices give
    // exact ties in t.
    let cell = 1.5 / 12.0;
    let grid: Vec<[Vec3; 3]> = (0..144)
        .flat_map(|i| {
            let p = Vec3::new(
                -0.75 + (i % 12) as f32 * cell,
                -0.75 + (i / 12) as f32 * cell,
                0.25,
            );
            let (x, y) = (Vec3::X * cell, Vec3::Y * cell);
            [[p, p + x, p + x + y], [p, p + x + y, p + y]]
        })
        .collect();
    b.triangles(Material::default(), &grid);
    b.scene
}

#[test]
fn bvh_closest_and_any_hit_equal_brute_force_for_every_layout() {
    let scene = Arc::new(soup(7));
    let degenerate = 1500..1620u32;
    let mut rng = TestRng::new(99);
    let mut rays: Vec<(Ray, f32)> = (0..3000)
        .map(|i| {
            let ray = Ray {
                origin: rng.vec3(-2.0, 2.0),
                direction: rng.direction(),
            };
            (
                ray,
                if i % 2 == 0 {
                    f32::INFINITY
                } else {
                    rng.range(0.05, 3.0)
                },
            )
        })
        .collect();
    // Axis-aligned rays: zero and negative-zero direction components.
    for _ in 0..300 {
        for direction in [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z] {
            rays.push((
                Ray {
                    origin: rng.vec3(-1.5, 1.5),
                    direction,
                },
                f32::INFINITY,
            ));
        }
    }
    // Rays straight through grid vertices and edge midpoints.
    for i in 0..13 * 13 {
        let cell = 1.5 / 12.0;
        let p = Vec3::new(
            -0.75 + (i % 13) as f32 * cell,
            -0.75 + (i / 13) as f32 * cell,
            0.25,
        );
        for offset in [Vec3::ZERO, Vec3::X * cell * 0.5] {
            let origin = Vec3::new(0.1, -0.2, 2.0);
            rays.push((
                Ray {
                    origin,
                    direction: (p + offset - origin).normalize(),
                },
                f32::INFINITY,
            ));
        }
    }

    let reference = SceneBvh::new(scene.clone());
    let expected: Vec<Option<Hit>> = rays
        .iter()
        .map(|(ray, t)| reference.closest_hit_brute_force(ray, *t))
        .collect();
    let hits = expected.iter().flatten().count();
    assert!(
        hits > rays.len() / 5,
        "only {hits} hits: the soup should be hit often"
    );
    assert!(
        expected
            .iter()
            .flatten()
            .all(|h| !degenerate.contains(&h.triangle.raw()))
    );

    for layout in BvhLayout::ALL {
        for preset in BuildPreset::ALL {
            let bvh = SceneBvh::with_options(scene.clone(), BvhOptions { layout, preset });
            // The AVX2 build where the CPU has it, then the portable one.
            for bvh in [&bvh, &bvh_clone(&bvh).portable()] {
                for ((ray, t_max), want) in rays.iter().zip(&expected) {
                    assert_eq!(
                        bvh.closest_hit(ray, *t_max),
                        *want,
                        "{layout:?} {preset:?} {ray:?} {t_max}"
                    );
                    assert_eq!(
                        bvh.occluded(ray, *t_max),
                        want.is_some(),
                        "{layout:?} {preset:?} {ray:?}"
                    );
                }
            }
        }
    }
}

/// A second BVH with the same options (`SceneBvh` is not `Clone`).
fn bvh_clone(bvh: &SceneBvh) -> SceneBvh {
    SceneBvh::with_options(Arc::new(bvh.scene().clone()), bvh.options())
}

#[test]
fn packets_return_the_single_ray_hits_bit_for_bit() {
    let bits =
        |h: &Option<Hit>| h.map(|h| (h.triangle, h.t.to_bits(), h.u.to_bits(), h.v.to_bits()));
    for seed in [3, 7] {
        let scene = Arc::new(soup(seed));
        let mut rng = TestRng::new(seed + 100);
        // Camera rays in row order (coherent), then random rays (incoherent),
        // then rays no query can hit with, mixed into the packets.
        let eye = Vec3::new(0.1, -0.2, 2.5);
        let mut rays: Vec<Ray> = (0..40 * 30)
            .map(|i| {
                let p = Vec3::new(
                    -1.2 + (i % 40) as f32 * 0.06,
                    0.9 - (i / 40) as f32 * 0.06,
                    0.0,
                );
                Ray {
                    origin: eye,
                    direction: (p - eye).normalize(),
                }
            })
            .collect();
        rays.extend((0..1500).map(|_| Ray {
            origin: rng.vec3(-2.0, 2.0),
            direction: rng.direction(),
        }));
        for i in [5, 13, 1300, 2001] {
            rays.insert(
                i,
                Ray {
                    origin: eye,
                    direction: Vec3::ZERO,
                },
            );
            rays.insert(
                i + 3,
                Ray {
                    origin: Vec3::NAN,
                    direction: Vec3::X,
                },
            );
        }
        for layout in BvhLayout::ALL {
            for preset in [BuildPreset::Fastest, BuildPreset::VerySlow] {
                let bvh = SceneBvh::with_options(scene.clone(), BvhOptions { layout, preset });
                let portable = bvh_clone(&bvh).portable();
                for t_max in [f32::INFINITY, 2.4] {
                    let single: Vec<Option<Hit>> =
                        rays.iter().map(|r| bvh.closest_hit(r, t_max)).collect();
                    let packets = bvh.closest_hits(&rays, t_max);
                    let portable_single: Vec<Option<Hit>> = rays
                        .iter()
                        .map(|r| portable.closest_hit(r, t_max))
                        .collect();
                    let portable_packets = portable.closest_hits(&rays, t_max);
                    assert!(single.iter().map(bits).eq(portable_single.iter().map(bits)));
                    assert!(
                        packets
                            .iter()
                            .map(bits)
                            .eq(portable_packets.iter().map(bits))
                    );
                    assert_eq!(packets.len(), rays.len());
                    assert!(single.iter().flatten().count() > rays.len() / 10);
                    for (i, (p, s)) in packets.iter().zip(&single).enumerate() {
                        assert_eq!(
                            bits(p),
                            bits(s),
                            "{layout:?} {preset:?} ray {i} {:?}",
                            rays[i]
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn closest_hit_reports_original_ids_and_barycentrics_from_both_sides() {
    let mut scene = soup(3);
    // A known triangle, shifted away from the soup, in the middle of the list.
    let mut b = SceneBuilder {
        scene: Scene::default(),
    };
    b.triangles(
        Material::default(),
        &[[
            Vec3::new(5.0, 0.0, 0.0),
            Vec3::new(6.0, 0.0, 0.0),
            Vec3::new(5.0, 1.0, 0.0),
        ]],
    );
    let known = TriangleId((scene.triangles.len() / 2) as u32);
    let mut tail = scene.triangles.split_off(known.index());
    scene.append(&b.scene);
    scene.triangles.append(&mut tail);
    assert_eq!(scene.validate(), Ok(()));
    let bvh = SceneBvh::new(Arc::new(scene));

    for (z, direction) in [(1.5, -Vec3::Z), (-1.5, Vec3::Z)] {
        let ray = Ray {
            origin: Vec3::new(5.2, 0.3, z),
            direction,
        };
        let hit = bvh
            .closest_hit(&ray, f32::INFINITY)
            .expect("the ray aims at the triangle");
        assert_eq!(hit.triangle, known);
        assert!(
            (hit.t - 1.5).abs() < 1e-6 && (hit.u - 0.2).abs() < 1e-6 && (hit.v - 0.3).abs() < 1e-6,
            "{hit:?}"
        );
        assert_eq!(bvh.closest_hit(&ray, 1.4), None);
        assert!(!bvh.occluded(&ray, 1.4));
        assert!(bvh.occluded(&ray, 1.6));
    }
}

#[test]
fn empty_and_single_triangle_scenes_work() {
    let lighting = dark();
    let empty = SceneBvh::new(Arc::new(Scene::default()));
    let ray = Ray {
        origin: Vec3::ZERO,
        direction: Vec3::X,
    };
    assert_eq!(empty.closest_hit(&ray, f32::INFINITY), None);
    assert!(!empty.occluded(&ray, f32::INFINITY));
    assert_eq!(
        tracer(&empty, &lighting).trace(&ray).color,
        lighting.background
    );

    let mut b = SceneBuilder::default();
    b.triangles(
        emitter("one", Vec3::ONE),
        &[[
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(1.0, 1.0, -1.0),
            Vec3::new(1.0, 0.0, 1.0),
        ]],
    );
    let one = bvh(b);
    assert_eq!(tracer(&one, &lighting).trace(&ray).color, Vec3::ONE);
}

/// The two-light shadow scene plus a vertical mirror at z = -5 and red and
/// blue panels it can show.
fn signature_scene() -> (ShadowScene, [ObjectId; 2]) {
    let mut s = shadow_scene(
        Material::diffuse("wall", Vec3::splat(0.3)),
        &[Vec3::new(-2.0, 3.0, 0.0), Vec3::new(2.0, 3.0, 0.0)],
    );
    let mut b = SceneBuilder {
        scene: s.bvh.scene().clone(),
    };
    b.square(mirror("mirror"), Vec3::new(0.0, 0.5, -5.0), Vec3::Z, 1.0);
    let red = b.square(
        emitter("red", Vec3::X),
        Vec3::new(-3.0, 0.5, -2.0),
        Vec3::new(1.0, 0.0, -1.0),
        0.5,
    );
    let blue = b.square(
        emitter("blue", Vec3::Z),
        Vec3::new(3.0, 0.5, -2.0),
        Vec3::new(-1.0, 0.0, -1.0),
        0.5,
    );
    s.bvh = bvh(b);
    (s, [red, blue])
}

#[test]
fn signatures_match_exactly_when_ray_trees_match() {
    let (s, [red, blue]) = signature_scene();
    let tracer = tracer(&s.bvh, &s.lighting);
    let down = |x: f32, z: f32| {
        tracer.trace(&Ray {
            origin: Vec3::new(x, 0.5, z),
            direction: -Vec3::Y,
        })
    };

    // Both lights reach x = 0, 5 and 6: same object, same shadow bits.
    let (both_a, both_b, both_c) = (down(5.0, 0.0), down(6.0, 0.3), down(0.0, 0.0));
    assert_ne!(both_a.color, both_b.color);
    assert_eq!(both_a.signature, both_b.signature);
    assert_eq!(both_a.signature, both_c.signature);
    // x = 1 is shadowed from light 0 only, x = -1 from light 1 only: one lit
    // light each, but not the same one.
    let (only_1, only_0) = (down(1.0, 0.0), down(-1.0, 0.0));
    assert_eq!(only_1.signature, down(1.2, 0.1).signature);
    assert_ne!(only_1.signature, both_a.signature);
    assert_ne!(only_1.signature, only_0.signature);
    assert_ne!(only_0.signature, both_a.signature);
    // A different object, and a miss.
    let occluder_top = tracer.trace(&Ray {
        origin: Vec3::new(0.1, 2.0, 0.0),
        direction: -Vec3::Y,
    });
    assert_ne!(occluder_top.signature, both_a.signature);
    let miss = tracer.trace(&Ray {
        origin: Vec3::new(5.0, 0.5, 0.0),
        direction: Vec3::Y,
    });
    assert_eq!(miss.reflected_object, NONE);
    assert_ne!(miss.signature, both_a.signature);
    assert_ne!(miss.signature, occluder_top.signature);

    // The mirror: same reflected panel → same signature, other panel → other.
    let on_mirror = |x: f32| point_on(&s.bvh, Vec3::new(x, 0.5, 0.0), Vec3::new(x, 0.5, -5.0));
    let towards = |d: Vec3| d.normalize();
    let red_a = tracer.shade(&on_mirror(0.0), towards(Vec3::new(-3.0, 0.0, -3.0)));
    let red_b = tracer.shade(&on_mirror(0.1), towards(Vec3::new(-3.1, 0.0, -3.0)));
    let blue_a = tracer.shade(&on_mirror(0.0), towards(Vec3::new(3.0, 0.0, -3.0)));
    assert_eq!(
        (
            red_a.reflected_object,
            red_b.reflected_object,
            blue_a.reflected_object
        ),
        (red.raw(), red.raw(), blue.raw())
    );
    assert_eq!(red_a.reflected, Vec3::X);
    assert_eq!(red_a.signature, red_b.signature);
    assert_ne!(red_a.signature, blue_a.signature);
}

#[test]
fn trace_and_shade_share_one_path() {
    let (s, _) = signature_scene();
    let tracer = tracer(&s.bvh, &s.lighting);
    let mut rng = TestRng::new(5);
    for _ in 0..200 {
        let ray = Ray {
            origin: Vec3::new(0.0, 2.5, 6.0),
            direction: (rng.vec3(-3.0, 3.0) - Vec3::new(0.0, 2.5, 6.0)).normalize(),
        };
        let Some(hit) = s.bvh.closest_hit(&ray, f32::INFINITY) else {
            continue;
        };
        let traced = tracer.trace(&ray);
        let shaded = tracer.shade(&s.bvh.surface_point(&hit), ray.direction);
        assert_eq!(bits(&traced), bits(&shaded));
    }
}

/// A sample as plain bits, for exact comparisons (-0.0 vs 0.0, NaN).
fn bits(s: &Sample) -> ([u32; 3], [u32; 3], [u32; 3], u32, u64) {
    (
        s.color.to_array().map(f32::to_bits),
        s.reflected.to_array().map(f32::to_bits),
        s.transmitted.to_array().map(f32::to_bits),
        s.reflected_object,
        s.signature,
    )
}

/// The signature scene plus a glass ball and a mirror ball, so that rays
/// branch; with its lighting.
fn branching_scene() -> (Arc<Scene>, Lighting) {
    let (s, _) = signature_scene();
    let mut b = SceneBuilder {
        scene: s.bvh.scene().clone(),
    };
    b.icosphere(glass("ball", 1.5), Vec3::new(-1.0, 1.5, 1.0), 0.6, 3);
    b.icosphere(mirror("ball"), Vec3::new(1.2, 0.7, 1.5), 0.5, 3);
    (Arc::new(b.scene), s.lighting)
}

#[test]
fn batches_equal_single_calls_bit_for_bit_on_any_thread_count() {
    let (scene, lighting) = branching_scene();
    let bvh = SceneBvh::new(scene.clone());
    let tracer = Tracer {
        settings: TraceSettings {
            max_depth: 6,
            fresnel: true,
            ..Default::default()
        },
        ..tracer(&bvh, &lighting)
    };

    let eye = Vec3::new(0.3, 2.0, 7.0);
    let mut rng = TestRng::new(11);
    let rays: Vec<Ray> = (0..600)
        .map(|_| Ray {
            origin: eye,
            direction: (rng.vec3(-2.0, 2.0) - eye).normalize(),
        })
        .collect();
    let single: Vec<_> = rays
        .iter()
        .map(|r| tracer.trace(r))
        .map(|s| bits(&s))
        .collect();
    for threads in [1, 2, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a thread pool");
        let batch: Vec<_> = pool
            .install(|| tracer.trace_batch(&rays))
            .iter()
            .map(bits)
            .collect();
        assert_eq!(batch, single, "{threads} threads");
        // A BVH built on a different number of threads answers identically.
        let rebuilt = pool.install(|| SceneBvh::new(scene.clone()));
        let again: Vec<_> = Tracer {
            bvh: &rebuilt,
            ..tracer
        }
        .trace_batch(&rays)
        .iter()
        .map(bits)
        .collect();
        assert_eq!(again, single, "BVH built on {threads} threads");
    }

    let points: Vec<(SurfacePoint, Vec3)> = rays
        .iter()
        .filter_map(|r| {
            bvh.closest_hit(r, f32::INFINITY)
                .map(|h| (bvh.surface_point(&h), r.direction))
        })
        .collect();
    assert!(points.len() > 300);
    let shaded: Vec<_> = tracer.shade_batch(&points).iter().map(bits).collect();
    let one_by_one: Vec<_> = points
        .iter()
        .map(|(p, d)| bits(&tracer.shade(p, *d)))
        .collect();
    assert_eq!(shaded, one_by_one);
    // Some rays really branched: the sample set is not trivially uniform.
    assert!(single.iter().any(|s| s.3 != NONE));
}

#[test]
fn shade_points_traces_the_first_reflections_in_packets_with_the_single_ray_samples() {
    let (scene, lighting) = branching_scene();
    let bvh = SceneBvh::new(scene);
    // Camera rays in row order onto both balls: coherent packets, as a
    // reflector's pixels are.
    let eye = Vec3::new(0.3, 2.0, 7.0);
    let points: Vec<(SurfacePoint, Vec3)> = (0..48 * 32)
        .filter_map(|i| {
            let target = Vec3::new(
                -2.0 + (i % 48) as f32 * 0.09,
                2.4 - (i / 48) as f32 * 0.07,
                1.2,
            );
            let ray = Ray {
                origin: eye,
                direction: (target - eye).normalize(),
            };
            let hit = bvh.closest_hit(&ray, f32::INFINITY)?;
            Some((bvh.surface_point(&hit), ray.direction))
        })
        .collect();
    for (max_depth, fresnel) in [(6, true), (2, false), (1, false)] {
        let tracer = Tracer {
            settings: TraceSettings {
                max_depth,
                fresnel,
                ..Default::default()
            },
            ..tracer(&bvh, &lighting)
        };
        let shade = |(p, d): &(SurfacePoint, Vec3)| bits(&tracer.shade(p, *d));
        let reflection = |(p, d): &(SurfacePoint, Vec3)| bits(&tracer.shade_reflection(p, *d));
        let single: Vec<_> = points.iter().map(shade).collect();
        let single_reflection: Vec<_> = points.iter().map(reflection).collect();
        // Batches of every size, so packets are full, partial and single.
        for batch in [1, 7, 64, points.len()] {
            let batched = |rays| -> Vec<_> {
                points
                    .chunks(batch)
                    .flat_map(|chunk| tracer.shade_points(chunk, rays))
                    .map(|s| bits(&s))
                    .collect()
            };
            assert_eq!(batched(Rays::Both), single, "{max_depth} {batch}");
            assert_eq!(
                batched(Rays::ReflectionOnly),
                single_reflection,
                "{max_depth} {batch}"
            );
        }
        if max_depth > 1 {
            // Both kinds of secondary ray really went through the packets.
            let mirrored = single.iter().filter(|s| s.3 != NONE).count();
            let refracting = points
                .iter()
                .filter(|(p, d)| tracer.surface_terms(p, *d).refraction.is_some())
                .count();
            assert!(
                mirrored > 100 && refracting > 100,
                "{mirrored} {refracting}"
            );
        }
    }
}

/// The pixel cone only picks textures' mip levels: untextured samples are
/// the same bits with or without it; with textures, shading on demand and
/// generation by generation carry the same path lengths (the same bits),
/// and the cone does change what minified textures give.
#[test]
fn the_pixel_cone_changes_only_textured_samples_the_same_way_in_both_walks() {
    let (scene, lighting) = branching_scene();
    let eye = Vec3::new(0.3, 2.0, 7.0);
    let cone = PixelCone { eye, spread: 0.05 };
    let rays: Vec<Ray> = (0..48 * 32)
        .map(|i| {
            let target = Vec3::new(
                -2.0 + (i % 48) as f32 * 0.09,
                2.4 - (i / 48) as f32 * 0.07,
                1.2,
            );
            Ray {
                origin: eye,
                direction: (target - eye).normalize(),
            }
        })
        .collect();
    let samples = |tracer: &Tracer| {
        let points: Vec<(SurfacePoint, Vec3)> = (rays.iter())
            .filter_map(|ray| {
                let hit = tracer.bvh.closest_hit(ray, f32::INFINITY)?;
                Some((tracer.bvh.surface_point(&hit), ray.direction))
            })
            .collect();
        let traced: Vec<_> = rays.iter().map(|r| bits(&tracer.trace(r))).collect();
        let shaded: Vec<_> = (points.iter())
            .map(|(p, d)| bits(&tracer.shade(p, *d)))
            .collect();
        let batched: Vec<_> = (tracer.shade_points(&points, Rays::Both).iter())
            .map(bits)
            .collect();
        (traced, shaded, batched)
    };
    let settings = TraceSettings {
        max_depth: 6,
        ..Default::default()
    };
    let bvh = SceneBvh::new(scene.clone());
    let finest = Tracer {
        settings,
        ..tracer(&bvh, &lighting)
    };
    assert_eq!(samples(&Tracer { cone, ..finest }), samples(&finest));

    // Every material textured with a checkerboard of one-texel squares.
    let mut textured = (*scene).clone();
    let rgba = (0..16 * 16)
        .flat_map(|i: u32| [if (i % 16 + i / 16) % 2 == 0 { 255 } else { 0 }; 4])
        .collect();
    textured.textures = vec![vtfarm_scene::Texture::from_rgba8("checker", 16, 16, rgba).unwrap()];
    for material in &mut textured.materials {
        material.diffuse_texture = Some(0);
    }
    textured.corner_uvs = textured
        .triangle_ids()
        .map(|t| {
            textured
                .triangle_positions(t)
                .map(|p| glam::Vec2::new(p.x + p.y, p.z) * 4.0)
        })
        .collect();
    let bvh = SceneBvh::new(Arc::new(textured));
    let finest = Tracer {
        settings,
        ..tracer(&bvh, &lighting)
    };
    let coned = samples(&Tracer { cone, ..finest });
    assert_eq!(coned.1, coned.2, "on demand and by generations");
    let changed = (coned.0.iter().zip(&samples(&finest).0))
        .filter(|(a, b)| a != b)
        .count();
    assert!(changed > 500, "{changed} samples changed by the cone");
}

#[test]
fn piles_of_identical_triangles_are_traversed_completely() {
    // Identical boxes give PLOC nothing to sort by: a worst case for tree
    // depth, deeper than obvhs' fixed-size CwBvh stack (`SceneBvh` then
    // falls back to the binary layout). Every triangle ties; id 0 must win.
    let corners = [
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
    ];
    let pile = vec![corners; 5000];
    let mut b = SceneBuilder::default();
    b.triangles(Material::default(), &pile);
    let scene = Arc::new(b.scene);
    let mut rng = TestRng::new(17);
    let rays: Vec<Ray> = (0..50)
        .map(|_| {
            let origin = Vec3::new(
                rng.range(-0.4, 0.4),
                rng.range(-0.8, 0.4),
                rng.range(-1.0, 1.0).signum(),
            );
            Ray {
                origin,
                direction: (rng.vec3(-0.3, 0.3).with_z(0.0) - origin).normalize(),
            }
        })
        .collect();
    for layout in BvhLayout::ALL {
        let bvh = SceneBvh::with_options(
            scene.clone(),
            BvhOptions {
                layout,
                preset: BuildPreset::Medium,
            },
        );
        for ray in &rays {
            let hit = bvh.closest_hit(ray, f32::INFINITY);
            assert_eq!(
                hit.map(|h| h.triangle),
                Some(TriangleId(0)),
                "{:?}",
                bvh.options()
            );
            assert_eq!(hit, bvh.closest_hit_brute_force(ray, f32::INFINITY));
        }
    }
}

#[test]
fn the_bvh_and_tracer_can_be_shared_across_threads() {
    fn shareable<T: Send + Sync>() {}
    shareable::<SceneBvh>();
    shareable::<Tracer<'static>>();
}

#[test]
fn surface_terms_recombine_to_the_shaded_sample() {
    // A glass pane over a lit floor with an emissive sky above: the pane has
    // local light, a reflection and a refraction, all three non-zero.
    let mut b = SceneBuilder::default();
    b.quad(
        Material {
            reflectance: Vec3::splat(0.2),
            transmittance: Vec3::splat(0.7),
            diffuse: Vec3::splat(0.1),
            ..glass("pane", 1.5)
        },
        Vec3::new(-5.0, 0.0, -5.0),
        Vec3::Z * 10.0,
        Vec3::X * 10.0,
    );
    b.quad(
        Material::diffuse("floor", Vec3::splat(0.6)),
        Vec3::new(-20.0, -1.0, -20.0),
        Vec3::Z * 40.0,
        Vec3::X * 40.0,
    );
    b.quad(
        emitter("sky", Vec3::new(0.0, 3.0, 1.0)),
        Vec3::new(-20.0, 2.0, -20.0),
        Vec3::X * 40.0,
        Vec3::Z * 40.0,
    );
    let bvh = bvh(b);
    let lighting = Lighting {
        lights: vec![point_light(Vec3::new(1.0, 1.5, 0.0))],
        ambient: Vec3::splat(0.1),
        background: Vec3::ZERO,
    };
    for fresnel in [false, true] {
        let settings = TraceSettings {
            fresnel,
            ..Default::default()
        };
        let full = Tracer {
            bvh: &bvh,
            lighting: &lighting,
            settings,
            cone: PixelCone::FINEST,
        };
        // The secondary rays start one level deeper inside `shade`.
        let deeper = Tracer {
            settings: TraceSettings {
                max_depth: settings.max_depth - 1,
                ..settings
            },
            ..full
        };
        let point = point_on(&bvh, Vec3::new(0.0, 1.0, 2.0), Vec3::new(0.0, 0.0, 0.5));
        let incoming = (point.position - Vec3::new(0.0, 1.0, 2.0)).normalize();
        let terms = full.surface_terms(&point, incoming);
        let reflected = terms.kr * deeper.trace(&terms.reflection.unwrap()).color;
        let transmitted = terms.kt * deeper.trace(&terms.refraction.unwrap()).color;
        let sample = full.shade(&point, incoming);
        assert!(terms.local.max_element() > 0.0 && reflected.max_element() > 0.0);
        assert!(transmitted.max_element() > 0.0);
        assert_close(sample.reflected, reflected, 1e-6);
        assert_close(sample.transmitted, transmitted, 1e-6);
        assert_close(sample.color, terms.local + reflected + transmitted, 1e-5);
    }
}

/// A scene with one vertex at `far` and two ordinary triangles.
fn scene_with_far_vertex(far: f32) -> Scene {
    let mut b = SceneBuilder::default();
    b.triangles(
        Material::default(),
        &[
            [Vec3::ZERO, Vec3::X, Vec3::Y],
            [Vec3::Z, Vec3::X, Vec3::new(far, 0.0, 0.0)],
        ],
    );
    b.scene
}

#[test]
fn absurd_coordinates_are_refused_instead_of_panicking_the_build() {
    // 1e22 overflows obvhs' SAH costs and panics bvh2_to_cwbvh.
    for far in [1e22, -3e30, f32::MAX] {
        for preset in BuildPreset::ALL {
            let options = BvhOptions {
                layout: BvhLayout::Cw,
                preset,
            };
            let error = SceneBvh::try_with_options(Arc::new(scene_with_far_vertex(far)), options)
                .expect_err("a vertex beyond the limit");
            assert!(
                error.to_string().contains("vertex 5"),
                "{far} {preset:?}: {error}"
            );
        }
    }
    // At the limit it builds and traces.
    let bvh = SceneBvh::try_new(Arc::new(scene_with_far_vertex(
        vtfarm_scene::MAX_COORDINATE,
    )))
    .expect("a vertex at the limit");
    let ray = Ray {
        origin: Vec3::new(0.2, 0.2, 1.0),
        direction: -Vec3::Z,
    };
    assert_eq!(
        bvh.closest_hit(&ray, f32::INFINITY).map(|h| h.triangle),
        Some(TriangleId(0))
    );
}
