//! Checks of the rasterizer against a brute-force ray caster and against its
//! own contracts: the top-left fill rule, near-plane clipping, shading with
//! the shared Phong model, and bit-identical results on any thread count.

use glam::{DVec3, Quat, Vec3};
use vtfarm_raster::{
    IdBuffer, IdPass, PixelRect, id_buffer, id_buffer_clipped, id_buffer_where, id_buffer_within,
    id_buffers_within, nearer_of, rasterize, rasterize_into, rasterize_within_into,
};
use vtfarm_scene::shading::phong;
use vtfarm_scene::{
    Camera, Light, LightKind, Lighting, Material, MaterialId, NEAR, NONE, Object, ObjectId, Scene,
    Triangle, TriangleId,
};

/// xorshift64*: a tiny seeded generator, so scenes are reproducible.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Self {
        Rng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in [lo, hi).
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    fn vec3(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }

    fn coin(&mut self) -> bool {
        self.next_u64() & 1 == 1
    }
}

/// Builds scenes one object at a time; every object gets its own material.
#[derive(Default)]
struct Builder {
    scene: Scene,
}

impl Builder {
    fn object(&mut self, name: &str, color: Vec3) -> ObjectId {
        self.scene.objects.push(Object {
            name: name.to_owned(),
        });
        self.scene.materials.push(Material::diffuse(name, color));
        ObjectId(self.scene.objects.len() as u32 - 1)
    }

    fn vertex(&mut self, p: Vec3, n: Vec3) -> u32 {
        self.scene.positions.push(p);
        self.scene.normals.push(n.normalize_or(Vec3::Y));
        self.scene.positions.len() as u32 - 1
    }

    fn triangle(&mut self, object: ObjectId, vertices: [u32; 3]) {
        self.scene.triangles.push(Triangle {
            vertices,
            object,
            material: MaterialId(object.raw()),
        });
    }

    /// A triangle with its own vertices and the geometric normal.
    fn flat(&mut self, object: ObjectId, [a, b, c]: [Vec3; 3]) {
        let n = (b - a).cross(c - a);
        let v = [a, b, c].map(|p| self.vertex(p, n));
        self.triangle(object, v);
    }

    /// A UV sphere with smooth normals.
    fn sphere(&mut self, object: ObjectId, center: Vec3, radius: f32, rings: u32, segments: u32) {
        let first = self.scene.positions.len() as u32;
        for r in 0..=rings {
            let theta = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..=segments {
                let phi = std::f32::consts::TAU * s as f32 / segments as f32;
                let n = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                );
                self.vertex(center + n * radius, n);
            }
        }
        let at = |r: u32, s: u32| first + r * (segments + 1) + s;
        for r in 0..rings {
            for s in 0..segments {
                if r > 0 {
                    self.triangle(object, [at(r, s), at(r, s + 1), at(r + 1, s)]);
                }
                if r + 1 < rings {
                    self.triangle(object, [at(r, s + 1), at(r + 1, s + 1), at(r + 1, s)]);
                }
            }
        }
    }

    /// A rotated box with flat faces.
    fn cuboid(&mut self, object: ObjectId, center: Vec3, half: Vec3, rotation: Quat) {
        for axis in 0..3 {
            for sign in [-1.0, 1.0] {
                let n = Vec3::AXES[axis] * sign;
                let u = Vec3::AXES[(axis + 1) % 3] * half[(axis + 1) % 3];
                let v = Vec3::AXES[(axis + 2) % 3] * half[(axis + 2) % 3];
                let c = n * half[axis];
                self.quad(
                    object,
                    [c - u - v, c + u - v, c + u + v, c - u + v].map(|p| center + rotation * p),
                );
            }
        }
    }

    /// Two triangles sharing the diagonal a-c.
    fn quad(&mut self, object: ObjectId, [a, b, c, d]: [Vec3; 4]) {
        let n = (b - a).cross(d - a);
        let v = [a, b, c, d].map(|p| self.vertex(p, n));
        self.triangle(object, [v[0], v[1], v[2]]);
        self.triangle(object, [v[0], v[2], v[3]]);
    }

    /// An `n` x `n` grid of cells over shared vertices `vertex_at(i, j)`, each
    /// cell split along a random diagonal, each triangle with a random winding.
    fn grid(
        &mut self,
        object: ObjectId,
        n: u32,
        rng: &mut Rng,
        vertex_at: impl Fn(u32, u32) -> Vec3,
    ) {
        let first = self.scene.positions.len() as u32;
        for j in 0..=n {
            for i in 0..=n {
                self.vertex(vertex_at(i, j), Vec3::Z);
            }
        }
        let at = |i: u32, j: u32| first + j * (n + 1) + i;
        for j in 0..n {
            for i in 0..n {
                let [a, b, c, d] = [at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)];
                let halves = if rng.coin() {
                    [[a, b, c], [a, c, d]]
                } else {
                    [[a, b, d], [b, c, d]]
                };
                for [p, q, r] in halves {
                    self.triangle(object, if rng.coin() { [p, q, r] } else { [p, r, q] });
                }
            }
        }
    }
}

/// Overlapping spheres, boxes and loose triangles at different depths, seen
/// from a random direction.
fn procedural_scene(seed: u64, width: u32, height: u32) -> (Scene, Camera) {
    let mut rng = Rng::new(seed);
    let mut b = Builder::default();
    for i in 0..4 {
        let o = b.object(&format!("sphere{i}"), rng.vec3(0.2, 1.0));
        let (center, radius) = (rng.vec3(-1.5, 1.5), rng.range(0.4, 1.2));
        b.sphere(o, center, radius, 10, 16);
    }
    for i in 0..3 {
        let o = b.object(&format!("box{i}"), rng.vec3(0.2, 1.0));
        let rotation = Quat::from_euler(
            glam::EulerRot::XYZ,
            rng.range(0.0, 3.0),
            rng.range(0.0, 3.0),
            0.0,
        );
        b.cuboid(o, rng.vec3(-2.0, 2.0), rng.vec3(0.2, 0.9), rotation);
    }
    let loose = b.object("loose", Vec3::splat(0.5));
    for _ in 0..40 {
        let c = rng.vec3(-2.5, 2.5);
        b.flat(
            loose,
            [
                c + rng.vec3(-0.8, 0.8),
                c + rng.vec3(-0.8, 0.8),
                c + rng.vec3(-0.8, 0.8),
            ],
        );
    }
    let ground = b.object("ground", Vec3::splat(0.7));
    b.grid(ground, 10, &mut rng, |i, j| {
        Vec3::new(i as f32 - 5.0, -2.0, j as f32 - 5.0)
    });
    let azimuth = rng.range(0.0, std::f32::consts::TAU);
    let camera = Camera {
        eye: Vec3::new(
            7.0 * azimuth.cos(),
            rng.range(0.5, 3.0),
            7.0 * azimuth.sin(),
        ),
        target: rng.vec3(-0.5, 0.5),
        up: Vec3::Y,
        fov_y_deg: rng.range(40.0, 70.0),
        width,
        height,
    };
    (b.scene, camera)
}

/// The first hit per pixel by brute-force Möller–Trumbore (in f64) over all
/// triangles along `Camera::pixel_ray`, ignoring hits nearer than the near
/// plane: (triangle, view depth, barycentric u and v).
fn ray_cast(scene: &Scene, camera: &Camera) -> Vec<Option<(TriangleId, f64, f64, f64)>> {
    ray_cast_beyond(scene, camera, NEAR)
}

/// [`ray_cast`] with the near plane at view depth `near`.
fn ray_cast_beyond(
    scene: &Scene,
    camera: &Camera,
    near: f32,
) -> Vec<Option<(TriangleId, f64, f64, f64)>> {
    let forward = camera.basis().0.as_dvec3();
    let eye = camera.eye.as_dvec3();
    let triangles: Vec<[DVec3; 3]> = scene
        .triangle_ids()
        .map(|t| scene.triangle_positions(t).map(|p| p.as_dvec3()))
        .collect();
    let mut hits = Vec::new();
    for y in 0..camera.height {
        for x in 0..camera.width {
            let dir = camera.pixel_ray(x, y).as_dvec3();
            let mut best: Option<(TriangleId, f64, f64, f64)> = None;
            for (id, [a, b, c]) in scene.triangle_ids().zip(&triangles) {
                let (e1, e2) = (*b - *a, *c - *a);
                let p = dir.cross(e2);
                let det = e1.dot(p);
                if det.abs() < 1e-15 {
                    continue;
                }
                let s = eye - *a;
                let u = s.dot(p) / det;
                let q = s.cross(e1);
                let v = dir.dot(q) / det;
                let depth = e2.dot(q) / det * dir.dot(forward);
                if u < 0.0 || v < 0.0 || u + v > 1.0 || depth < f64::from(near) {
                    continue;
                }
                if best.is_none_or(|(_, d, _, _)| depth < d) {
                    best = Some((id, depth, u, v));
                }
            }
            hits.push(best);
        }
    }
    hits
}

/// Asserts that `ids` sees the same triangle as the ray caster on at least
/// 99.5% of the pixels, at the same depth where it does; returns the share of
/// covered pixels.
fn assert_matches_ray_cast(scene: &Scene, camera: &Camera, ids: &IdBuffer) -> f64 {
    assert_matches_ray_cast_beyond(scene, camera, NEAR, ids)
}

/// [`assert_matches_ray_cast`] with the near plane at view depth `near`.
fn assert_matches_ray_cast_beyond(
    scene: &Scene,
    camera: &Camera,
    near: f32,
    ids: &IdBuffer,
) -> f64 {
    let hits = ray_cast_beyond(scene, camera, near);
    let mut agree = 0;
    for (i, hit) in hits.iter().enumerate() {
        let seen = TriangleId::from_raw(ids.triangle[i]);
        if seen != hit.map(|h| h.0) {
            continue;
        }
        agree += 1;
        if let Some((_, depth, _, _)) = hit {
            let relative = (f64::from(ids.depth[i]) - depth).abs() / depth;
            assert!(
                relative < 1e-3,
                "pixel {i}: depth {} vs ray cast {depth}",
                ids.depth[i]
            );
        } else {
            assert_eq!(ids.depth[i], f32::INFINITY);
        }
    }
    let share = agree as f64 / hits.len() as f64;
    assert!(
        share >= 0.995,
        "only {:.2}% of pixels agree with the ray cast",
        share * 100.0
    );
    hits.iter().filter(|h| h.is_some()).count() as f64 / hits.len() as f64
}

/// Asserts two ID buffers are equal bit for bit (depth included).
fn assert_same_ids(a: &IdBuffer, b: &IdBuffer) {
    assert_eq!((a.width, a.height, a.window), (b.width, b.height, b.window));
    assert_eq!(a.triangle, b.triangle);
    assert_eq!(a.object, b.object);
    assert!(
        a.depth
            .iter()
            .zip(&b.depth)
            .all(|(x, y)| x.to_bits() == y.to_bits())
    );
}

#[test]
fn id_buffer_matches_a_brute_force_ray_cast() {
    for seed in 1..=4 {
        let (scene, camera) = procedural_scene(seed, 128, 96);
        let ids = id_buffer(&scene, &camera);
        let covered = assert_matches_ray_cast(&scene, &camera, &ids);
        // Guard against a vacuous pass: the view must actually show things.
        assert!(covered > 0.2, "seed {seed}: only {covered} covered");
        let distinct: std::collections::HashSet<_> = ids.object.iter().collect();
        assert!(
            distinct.len() >= 4,
            "seed {seed}: {} objects seen",
            distinct.len()
        );
        for (i, &t) in ids.triangle.iter().enumerate() {
            let expected = if t == NONE {
                NONE
            } else {
                scene.triangles[t as usize].object.raw()
            };
            assert_eq!(ids.object[i], expected);
        }
    }
}

#[test]
fn a_buffer_within_a_rectangle_is_the_whole_buffer_there_and_empty_elsewhere() {
    let (scene, camera) = procedural_scene(3, 128, 96);
    let whole = id_buffer(&scene, &camera);
    let rects = [
        PixelRect::full(128, 96),
        // Band edges (16 rows) cut inside, odd columns.
        PixelRect {
            x0: 7,
            y0: 13,
            x1: 77,
            y1: 50,
        },
        PixelRect {
            x0: 0,
            y0: 95,
            x1: 1,
            y1: 96,
        },
        // Reaching past the image, and empty.
        PixelRect {
            x0: 100,
            y0: 80,
            x1: 500,
            y1: 500,
        },
        PixelRect {
            x0: 40,
            y0: 40,
            x1: 40,
            y1: 90,
        },
    ];
    for rect in rects {
        let part = id_buffer_within(&scene, &camera, rect, &|_| true);
        let inside = rect.clamped(128, 96);
        // The planes hold the rectangle only.
        assert_eq!(part.triangle.len(), inside.area());
        for (x, y) in PixelRect::full(128, 96).pixels() {
            let (triangle, object, depth) = if inside.contains(x, y) {
                (
                    whole.triangle_at(x, y),
                    whole.object_at(x, y),
                    whole.depth_at(x, y),
                )
            } else {
                (NONE, NONE, f32::INFINITY)
            };
            assert_eq!(part.triangle_at(x, y), triangle, "({x}, {y})");
            assert_eq!(part.object_at(x, y), object, "({x}, {y})");
            assert_eq!(part.depth_at(x, y).to_bits(), depth.to_bits(), "({x}, {y})");
        }
    }
    // Not vacuous: the middle rectangle shows several triangles.
    let middle = id_buffer_within(&scene, &camera, rects[1], &|_| true);
    let seen: std::collections::HashSet<_> = middle.triangle.iter().collect();
    assert!(seen.len() > 10, "{} triangles seen", seen.len());
}

#[test]
fn a_frame_rasterized_within_a_rectangle_is_the_whole_frame_there_and_background_elsewhere() {
    let (scene, camera) = procedural_scene(3, 128, 96);
    let lighting = Lighting {
        lights: vec![Light {
            kind: LightKind::Point {
                position: Vec3::new(0.0, 3.0, 2.0),
            },
            color: Vec3::ONE,
            intensity: 1.0,
        }],
        ambient: Vec3::splat(0.1),
        background: Vec3::new(0.2, 0.3, 0.4),
    };
    let (whole, whole_ids) = rasterize(&scene, &camera, &lighting);
    let rect = PixelRect {
        x0: 7,
        y0: 13,
        x1: 77,
        y1: 50,
    };
    // Into buffers of another frame, as a master reuses them.
    let other = Lighting {
        lights: Vec::new(),
        ..lighting.clone()
    };
    let (mut image, mut ids) = rasterize(&scene, &camera, &other);
    rasterize_within_into(&scene, &camera, &lighting, rect, &mut image, &mut ids);
    assert_eq!(ids.window, PixelRect::full(128, 96));
    let mut seen = std::collections::HashSet::new();
    for (x, y) in PixelRect::full(128, 96).pixels() {
        let i = ids.frame_index(x, y);
        if rect.contains(x, y) {
            assert_eq!(
                ids.triangle_at(x, y),
                whole_ids.triangle_at(x, y),
                "({x}, {y})"
            );
            assert_eq!(ids.object_at(x, y), whole_ids.object_at(x, y), "({x}, {y})");
            let depth = ids.depth_at(x, y).to_bits();
            assert_eq!(depth, whole_ids.depth_at(x, y).to_bits(), "({x}, {y})");
            assert_eq!(image.pixels[i], whole.pixels[i], "({x}, {y})");
            seen.insert(ids.triangle_at(x, y));
        } else {
            assert_eq!(ids.triangle_at(x, y), NONE, "({x}, {y})");
            assert_eq!(image.pixels[i], lighting.background, "({x}, {y})");
        }
    }
    assert!(seen.len() > 10, "{} triangles seen", seen.len());
}

#[test]
fn buffers_within_random_rectangles_match_the_whole_buffer_from_any_eye() {
    // Set-up drops the triangles wholly beside the rectangle first: on
    // random eyes (inside the scene too, where triangles cross the near
    // plane) and random rectangles (down to one pixel), the rectangle's
    // buffer is still the whole buffer there, bit for bit.
    let mut rng = Rng::new(41);
    let mut seen = 0;
    for seed in 1..=4 {
        let (scene, outside) = procedural_scene(seed, 96, 64);
        for eye in [outside.eye, rng.vec3(-1.5, 1.5), rng.vec3(-2.5, 2.5)] {
            let camera = Camera {
                eye,
                target: eye + rng.vec3(-1.0, 1.0),
                ..outside
            };
            let whole = id_buffer(&scene, &camera);
            for _ in 0..12 {
                let (x0, y0) = (rng.range(0.0, 96.0) as u32, rng.range(0.0, 64.0) as u32);
                let rect = PixelRect {
                    x0,
                    y0,
                    x1: x0 + 1 + rng.range(0.0, 40.0) as u32,
                    y1: y0 + 1 + rng.range(0.0, 30.0) as u32,
                };
                let part = id_buffer_within(&scene, &camera, rect, &|_| true);
                for (x, y) in rect.clamped(96, 64).pixels() {
                    assert_eq!(
                        part.triangle_at(x, y),
                        whole.triangle_at(x, y),
                        "{rect:?} ({x}, {y})"
                    );
                    let (a, b) = (part.depth_at(x, y), whole.depth_at(x, y));
                    assert_eq!(a.to_bits(), b.to_bits(), "{rect:?} ({x}, {y})");
                    seen += usize::from(a.is_finite());
                }
            }
        }
    }
    // Not vacuous: the rectangles saw surfaces.
    assert!(seen > 10_000, "{seen}");
}

#[test]
fn buffers_rasterized_together_are_each_the_buffer_rasterized_alone() {
    for seed in 1..=3 {
        let (scene, camera) = procedural_scene(seed, 128, 96);
        let all = |_: TriangleId| true;
        let even = |t: TriangleId| t.raw() % 2 == 0;
        let odd = |t: TriangleId| t.raw() % 2 == 1;
        let none = |_: TriangleId| false;
        let rect = |x0, y0, x1, y1| PixelRect { x0, y0, x1, y1 };
        // Nested, overlapping, disjoint, past the image and empty
        // rectangles, with filters that share triangles and that do not.
        let passes = [
            IdPass {
                within: rect(20, 10, 90, 70),
                keep: &all,
            },
            IdPass {
                within: rect(4, 2, 106, 78),
                keep: &even,
            },
            IdPass {
                within: rect(30, 20, 60, 40),
                keep: &odd,
            },
            IdPass {
                within: rect(100, 80, 500, 500),
                keep: &all,
            },
            IdPass {
                within: rect(0, 90, 10, 96),
                keep: &odd,
            },
            IdPass {
                within: rect(40, 40, 40, 90),
                keep: &all,
            },
            IdPass {
                within: rect(10, 10, 50, 50),
                keep: &none,
            },
        ];
        let together = id_buffers_within(&scene, &camera, &passes);
        assert_eq!(together.len(), passes.len());
        for (pass, buffer) in passes.iter().zip(&together) {
            let alone = id_buffer_within(&scene, &camera, pass.within, pass.keep);
            assert_same_ids(buffer, &alone);
        }
        // Not vacuous: the passes see triangles, and different ones.
        let seen = |b: &IdBuffer| b.triangle.iter().filter(|&&t| t != NONE).count();
        assert!(seen(&together[0]) > 1000 && seen(&together[1]) > 1000);
        assert_ne!(together[1].triangle, together[2].triangle);
        // No live pass at all: empty buffers.
        let empty = id_buffers_within(&scene, &camera, &passes[5..6]);
        assert!(empty[0].window.is_empty() && empty[0].triangle.is_empty());
        assert_eq!(empty[0].triangle_at(40, 40), NONE);
    }
}

#[test]
fn the_nearer_of_two_sets_buffers_is_the_buffer_of_both() {
    for seed in 1..=3 {
        let (scene, camera) = procedural_scene(seed, 128, 96);
        let all = |_: TriangleId| true;
        // Disjoint sets that interleave in depth, and one set empty.
        let thirds = |t: TriangleId| t.raw() % 3 == 0;
        let rest = |t: TriangleId| t.raw() % 3 != 0;
        let none = |_: TriangleId| false;
        let rect = |x0, y0, x1, y1| PixelRect { x0, y0, x1, y1 };
        let within = rect(10, 5, 100, 70);
        // `a` over a larger rectangle than `within`, `b` over exactly it.
        type Keep<'a> = &'a (dyn Fn(TriangleId) -> bool + Sync);
        let pairs: [(Keep, Keep); 3] = [(&thirds, &rest), (&rest, &thirds), (&all, &none)];
        for (keep_a, keep_b) in pairs {
            let a = id_buffer_within(&scene, &camera, rect(0, 0, 120, 90), keep_a);
            let b = id_buffer_within(&scene, &camera, within, keep_b);
            let both = id_buffer_within(&scene, &camera, within, &all);
            assert_same_ids(&nearer_of(&a, &b, within), &both);
            assert_same_ids(&nearer_of(&b, &a, within), &both);
        }
        // Not vacuous: each set shows pixels of the whole buffer.
        let both = id_buffer_within(&scene, &camera, within, &all);
        let shown = |keep: &dyn Fn(TriangleId) -> bool| {
            both.triangle
                .iter()
                .filter(|&&t| TriangleId::from_raw(t).is_some_and(keep))
                .count()
        };
        let (thirds, rest) = (shown(&thirds), shown(&rest));
        assert!(thirds > 300 && rest > 300, "{thirds} and {rest} pixels");
    }
}

/// How many of the grid's triangles, each rasterized alone, cover each pixel.
fn coverage_counts(scene: &Scene, camera: &Camera) -> Vec<u32> {
    let mut counts = vec![0; (camera.width * camera.height) as usize];
    for &t in &scene.triangles {
        let alone = Scene {
            triangles: vec![t],
            ..scene.clone()
        };
        let ids = id_buffer(&alone, camera);
        for (count, &id) in counts.iter_mut().zip(&ids.triangle) {
            *count += u32::from(id != NONE);
        }
    }
    counts
}

#[test]
fn a_tilted_mesh_covers_every_pixel_centre_inside_it_exactly_once() {
    let camera = Camera {
        eye: Vec3::new(0.0, 0.0, 3.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 55.0,
        width: 96,
        height: 72,
    };
    let mut rng = Rng::new(99);
    let mut b = Builder::default();
    let o = b.object("mesh", Vec3::ONE);
    let rotation = Quat::from_euler(glam::EulerRot::XYZ, 0.6, 0.35, 0.2);
    let n = 6;
    let (u, v) = (rotation * Vec3::X * 2.4, rotation * Vec3::Y * 2.4);
    let corner = -(u + v) * 0.5;
    // Interior vertices are jittered within the plane; the outline stays a parallelogram.
    let jitter: Vec<(f32, f32)> = (0..(n + 1) * (n + 1))
        .map(|_| (rng.range(-0.3, 0.3), rng.range(-0.3, 0.3)))
        .collect();
    b.grid(o, n, &mut rng, |i, j| {
        let (mut s, mut t) = (i as f32, j as f32);
        if i > 0 && i < n && j > 0 && j < n {
            let (ds, dt) = jitter[(j * (n + 1) + i) as usize];
            (s, t) = (s + ds, t + dt);
        }
        corner + u * s / n as f32 + v * t / n as f32
    });
    let scene = b.scene;
    let counts = coverage_counts(&scene, &camera);

    // Distance in pixels from a pixel centre to the projected outline, positive inside.
    let outline =
        [corner, corner + u, corner + u + v, corner + v].map(|p| camera.project(p).unwrap());
    let edge_distance = |k: usize, x: f32, y: f32| {
        let (a, b) = (outline[k], outline[(k + 1) % 4]);
        let (dx, dy) = (b.x - a.x, b.y - a.y);
        ((x - a.x) * dy - (y - a.y) * dx) / (dx * dx + dy * dy).sqrt()
    };
    let centre = camera.project(corner + (u + v) * 0.5).unwrap();
    let orientation = edge_distance(0, centre.x, centre.y).signum();
    let inside_distance = |x: f32, y: f32| {
        (0..4)
            .map(|k| orientation * edge_distance(k, x, y))
            .fold(f32::INFINITY, f32::min)
    };
    let mut inside = 0;
    for y in 0..camera.height {
        for x in 0..camera.width {
            let count = counts[(y * camera.width + x) as usize];
            let d = inside_distance(x as f32 + 0.5, y as f32 + 0.5);
            assert!(count <= 1, "pixel ({x}, {y}) covered {count} times");
            if d > 0.01 {
                assert_eq!(count, 1, "pixel ({x}, {y}) inside the mesh not covered");
                inside += 1;
            } else if d < -0.01 {
                assert_eq!(count, 0, "pixel ({x}, {y}) outside the mesh covered");
            }
        }
    }
    assert!(inside > 1000, "{inside}");
    // Drawing the whole mesh at once gives the union.
    let ids = id_buffer(&scene, &camera);
    assert!(
        ids.triangle
            .iter()
            .zip(&counts)
            .all(|(&t, &c)| (t != NONE) == (c == 1))
    );
}

/// A camera at the origin looking down -z, y up.
fn looking_down_z(fov_y_deg: f32, width: u32, height: u32) -> Camera {
    Camera {
        eye: Vec3::ZERO,
        target: -Vec3::Z,
        up: Vec3::Y,
        fov_y_deg,
        width,
        height,
    }
}

/// The world point on the plane at view depth `depth` seen through screen
/// point (`x`, `y`).
fn point_at(camera: &Camera, x: f32, y: f32, depth: f32) -> Vec3 {
    let dir = camera.ray_direction(x, y);
    camera.eye + dir * (depth / dir.dot(camera.basis().0))
}

#[test]
fn edges_through_pixel_centres_follow_the_top_left_rule() {
    // Every vertex sits on a pixel centre, so every edge (rows, columns and
    // diagonals) runs through pixel centres: all ties.
    let camera = looking_down_z(50.0, 64, 48);
    let mut rng = Rng::new(5);
    let mut b = Builder::default();
    let o = b.object("grid", Vec3::ONE);
    b.grid(o, 8, &mut rng, |i, j| {
        point_at(&camera, 10.5 + 4.0 * i as f32, 7.5 + 4.0 * j as f32, 2.0)
    });
    let counts = coverage_counts(&b.scene, &camera);
    for y in 0..camera.height {
        for x in 0..camera.width {
            // The outline's left and top edges are in, its right and bottom edges out.
            let expected = u32::from((10..42).contains(&x) && (7..39).contains(&y));
            assert_eq!(
                counts[(y * camera.width + x) as usize],
                expected,
                "pixel ({x}, {y})"
            );
        }
    }
}

/// A big floor at `y` reaching far behind the eye.
fn add_floor(b: &mut Builder, y: f32, half: f32) -> ObjectId {
    let o = b.object("floor", Vec3::splat(0.8));
    b.quad(
        o,
        [
            Vec3::new(-half, y, half),
            Vec3::new(half, y, half),
            Vec3::new(half, y, -half),
            Vec3::new(-half, y, -half),
        ],
    );
    o
}

#[test]
fn output_is_bit_identical_on_one_and_four_threads() {
    let (scene, camera) = procedural_scene(5, 160, 120);
    let mut b = Builder { scene };
    add_floor(&mut b, -2.5, 60.0);
    let lighting = Lighting {
        lights: vec![Light {
            kind: LightKind::Point {
                position: camera.eye,
            },
            color: Vec3::ONE,
            intensity: 1.0,
        }],
        ..Lighting::default()
    };
    let run = |threads| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| rasterize(&b.scene, &camera, &lighting))
    };
    let (image1, ids1) = run(1);
    let (image4, ids4) = run(4);
    assert_same_ids(&ids1, &ids4);
    let bits = |image: &vtfarm_imaging::Image| {
        image
            .pixels
            .iter()
            .flat_map(|c| c.to_array().map(f32::to_bits))
            .collect::<Vec<_>>()
    };
    assert_eq!(bits(&image1), bits(&image4));
}

#[test]
fn exact_depth_ties_go_to_the_lower_triangle_id() {
    let camera = looking_down_z(60.0, 64, 48);
    let mut b = Builder::default();
    let o = b.object("twice", Vec3::ONE);
    let corners = [
        Vec3::new(-1.0, -1.0, -2.0),
        Vec3::new(1.5, -0.5, -4.0),
        Vec3::new(0.0, 1.0, -3.0),
    ];
    let v = corners.map(|p| b.vertex(p, Vec3::Z));
    // The same triangle drawn first with the higher id: it must still lose.
    b.triangle(o, v);
    b.triangle(o, v);
    b.scene.triangles.swap(0, 1);
    let ids = id_buffer(&b.scene, &camera);
    assert!(ids.triangle.iter().all(|&t| t == 0 || t == NONE));
    assert!(ids.triangle.contains(&0));
}

#[test]
fn id_buffer_equals_the_one_from_rasterize() {
    let (scene, camera) = procedural_scene(3, 128, 96);
    let (_, from_rasterize) = rasterize(&scene, &camera, &Lighting::default());
    assert_same_ids(&id_buffer(&scene, &camera), &from_rasterize);
}

/// Buffers of earlier frames rasterized into again hold exactly the fresh
/// frame, nothing of what they held: frames of other scenes and views,
/// smaller, larger and of the same size (as a farm master reuses them).
#[test]
fn a_frame_rasterized_into_reused_buffers_is_the_fresh_frame() {
    let mut image = vtfarm_imaging::Image::new(50, 40, Vec3::NAN);
    let mut ids = IdBuffer::new(50, 40);
    ids.triangle.fill(0);
    for (seed, width, height) in [(7, 160, 120), (8, 96, 64), (9, 96, 64), (10, 200, 90)] {
        let (scene, camera) = procedural_scene(seed, width, height);
        let lighting = shading_lighting(camera.eye);
        rasterize_into(&scene, &camera, &lighting, &mut image, &mut ids);
        let (fresh_image, fresh_ids) = rasterize(&scene, &camera, &lighting);
        assert_same_ids(&ids, &fresh_ids);
        assert_eq!((image.width, image.height), (width, height));
        let bits = |image: &vtfarm_imaging::Image| {
            (image.pixels.iter())
                .flat_map(|c| c.to_array().map(f32::to_bits))
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&image), bits(&fresh_image), "seed {seed}");
        assert!(fresh_ids.triangle.contains(&NONE), "the background shows");
    }
}

#[test]
fn a_floor_reaching_behind_the_eye_is_clipped_not_dropped() {
    let camera = Camera {
        eye: Vec3::new(0.0, 1.5, 0.0),
        target: Vec3::new(0.0, 1.2, -4.0),
        up: Vec3::Y,
        fov_y_deg: 60.0,
        width: 96,
        height: 72,
    };
    let mut b = Builder::default();
    let floor = add_floor(&mut b, 0.0, 50.0);
    let ids = id_buffer(&b.scene, &camera);
    assert_matches_ray_cast(&b.scene, &camera, &ids);
    let ids = &ids;
    let row = |y: u32| (0..camera.width).map(move |x| ids.object_at(x, y));
    assert!(
        row(camera.height - 1).all(|o| o == floor.raw()),
        "the floor under the eye is missing"
    );
    assert!(row(0).all(|o| o == NONE), "the sky is not empty");
}

#[test]
fn walls_all_around_the_eye_fill_the_whole_view() {
    // The cockpit case: every wall passes beside or behind the eye.
    let camera = Camera {
        eye: Vec3::ZERO,
        target: Vec3::new(0.3, -0.2, -1.0),
        up: Vec3::Y,
        fov_y_deg: 90.0,
        width: 96,
        height: 72,
    };
    let mut b = Builder::default();
    let walls = b.object("walls", Vec3::splat(0.6));
    b.cuboid(
        walls,
        Vec3::new(0.4, 0.15, -0.85),
        Vec3::new(1.0, 0.65, 1.15),
        Quat::from_rotation_y(0.3),
    );
    let ids = id_buffer(&b.scene, &camera);
    assert!(
        ids.triangle.iter().all(|&t| t != NONE),
        "a hole in the walls"
    );
    assert_matches_ray_cast(&b.scene, &camera, &ids);
}

fn shading_lighting(eye: Vec3) -> Lighting {
    Lighting {
        lights: vec![
            Light {
                kind: LightKind::Point { position: eye },
                color: Vec3::ONE,
                intensity: 1.5,
            },
            Light {
                kind: LightKind::Directional {
                    direction: Vec3::new(0.3, -0.5, -1.0),
                    angular_diameter_deg: 0.0,
                },
                color: Vec3::new(1.0, 0.9, 0.7),
                intensity: 0.5,
            },
        ],
        ambient: Vec3::splat(0.1),
        background: Vec3::new(0.2, 0.3, 0.4),
    }
}

fn shiny(b: &mut Builder, name: &str) -> ObjectId {
    let o = b.object(name, Vec3::new(0.6, 0.5, 0.4));
    let m = &mut b.scene.materials[o.index()];
    (m.specular, m.shininess) = (Vec3::splat(0.3), 20.0);
    o
}

#[test]
fn a_quad_facing_a_head_on_light_is_shaded_by_phong() {
    let camera = looking_down_z(60.0, 64, 48);
    let mut b = Builder::default();
    let o = shiny(&mut b, "quad");
    b.quad(
        o,
        [
            Vec3::new(-1.0, -0.8, -3.0),
            Vec3::new(1.0, -0.8, -3.0),
            Vec3::new(1.0, 0.8, -3.0),
            Vec3::new(-1.0, 0.8, -3.0),
        ],
    );
    let lighting = shading_lighting(camera.eye);
    let (image, ids) = rasterize(&b.scene, &camera, &lighting);
    assert_ne!(ids.triangle_at(32, 24), NONE);
    let mut covered = 0;
    for y in 0..camera.height {
        for x in 0..camera.width {
            let color = image.get(x, y);
            if ids.triangle_at(x, y) == NONE {
                assert_eq!(color, lighting.background);
                continue;
            }
            covered += 1;
            let dir = camera.pixel_ray(x, y);
            let hit = camera.eye + dir * (-3.0 / dir.z);
            let expected = phong(
                &b.scene.materials[o.index()],
                &lighting,
                hit,
                Vec3::Z,
                -dir,
                |_, _, _| true,
            );
            assert!(
                (color - expected).abs().max_element() < 1e-4,
                "({x}, {y}): {color} vs {expected}"
            );
        }
    }
    assert!(covered > 300, "{covered}");
}

#[test]
fn normals_are_interpolated_perspective_correctly() {
    let camera = looking_down_z(60.0, 96, 72);
    let mut b = Builder::default();
    let o = shiny(&mut b, "slanted");
    // Corners at very different depths with very different normals, so affine
    // (screen-space) interpolation would be far off.
    let corners = [
        Vec3::new(-1.5, -1.0, -1.5),
        Vec3::new(3.0, -0.7, -6.0),
        Vec3::new(-0.4, 1.4, -2.0),
    ];
    let normals = [
        Vec3::new(0.6, 0.0, 0.8),
        Vec3::new(-0.5, 0.5, 0.7),
        Vec3::new(0.0, -0.6, 0.8),
    ]
    .map(Vec3::normalize);
    let v = [0, 1, 2].map(|i| b.vertex(corners[i], normals[i]));
    b.triangle(o, v);
    let lighting = shading_lighting(camera.eye);
    let (image, ids) = rasterize(&b.scene, &camera, &lighting);
    let hits = ray_cast(&b.scene, &camera);
    let mut checked = 0;
    for (i, hit) in hits.iter().enumerate() {
        let (Some((_, _, u, v)), false) = (hit, ids.triangle[i] == NONE) else {
            continue;
        };
        let (u, v) = (*u as f32, *v as f32);
        let (x, y) = (i as u32 % camera.width, i as u32 / camera.width);
        let position = corners[0] * (1.0 - u - v) + corners[1] * u + corners[2] * v;
        let normal = (normals[0] * (1.0 - u - v) + normals[1] * u + normals[2] * v).normalize();
        let to_eye = (camera.eye - position).normalize();
        let expected = phong(
            &b.scene.materials[o.index()],
            &lighting,
            position,
            normal,
            to_eye,
            |_, _, _| true,
        );
        assert!(
            (image.get(x, y) - expected).abs().max_element() < 1e-3,
            "({x}, {y}): {} vs {expected}",
            image.get(x, y)
        );
        checked += 1;
    }
    assert!(checked > 1000, "{checked}");
}

#[test]
fn the_default_near_plane_gives_the_id_buffer_bit_for_bit() {
    for seed in 1..=3 {
        let (scene, camera) = procedural_scene(seed, 96, 64);
        let keep = |t: TriangleId| t.raw() % 3 != 0;
        assert_same_ids(
            &id_buffer_clipped(&scene, &camera, NEAR, &keep),
            &id_buffer_where(&scene, &camera, &keep),
        );
        assert_same_ids(
            &id_buffer_clipped(&scene, &camera, NEAR, &|_| true),
            &id_buffer(&scene, &camera),
        );
    }
}

#[test]
fn a_custom_near_plane_clips_exactly_there() {
    // A quad filling the screen rectangle [4, 60] x [4, 44], its view depth
    // growing from 1 at the left edge to 4 at the right (1/z linear across).
    let camera = Camera {
        eye: Vec3::new(0.2, 0.3, 0.1),
        target: Vec3::new(0.2, 0.3, -1.0),
        up: Vec3::Y,
        fov_y_deg: 50.0,
        width: 64,
        height: 48,
    };
    let (left, right) = (1.0f64, 4.0f64);
    let mut b = Builder::default();
    let o = b.object("ramp", Vec3::ONE);
    b.quad(
        o,
        [
            point_at(&camera, 4.0, 4.0, left as f32),
            point_at(&camera, 60.0, 4.0, right as f32),
            point_at(&camera, 60.0, 44.0, right as f32),
            point_at(&camera, 4.0, 44.0, left as f32),
        ],
    );
    let expected_depth = |x: u32| {
        1.0 / (1.0 / left + (f64::from(x) + 0.5 - 4.0) / 56.0 * (1.0 / right - 1.0 / left))
    };
    let default = id_buffer(&b.scene, &camera);
    for near in [1.5f32, 2.0, 3.3] {
        let ids = id_buffer_clipped(&b.scene, &camera, near, &|_| true);
        let (mut empty, mut filled) = (0, 0);
        for y in 4..44 {
            for x in 4..60 {
                // Both buffers hold the whole frame.
                let i = ids.slot(x, y).unwrap();
                let expected = expected_depth(x);
                // Every pixel of the quad is there at the default near plane.
                assert_ne!(default.triangle[i], NONE, "({x}, {y})");
                let margin = (expected - f64::from(near)) / f64::from(near);
                if margin < -1e-3 {
                    assert_eq!(ids.triangle[i], NONE, "near {near}: ({x}, {y}) in front");
                    assert_eq!(ids.depth[i], f32::INFINITY);
                    empty += 1;
                } else if margin > 1e-3 {
                    assert_ne!(ids.triangle[i], NONE, "near {near}: ({x}, {y}) beyond");
                    assert_eq!(ids.object[i], o.raw());
                    let d = f64::from(ids.depth[i]);
                    assert!((d - expected).abs() < expected * 1e-4, "({x}, {y}): {d}");
                    assert!(ids.depth[i] >= near * (1.0 - 1e-6));
                    filled += 1;
                }
            }
        }
        assert!(empty >= 40 && filled >= 40, "near {near}: {empty} {filled}");
        // Outside the quad nothing.
        assert_eq!(ids.triangle_at(2, 2), NONE);
    }
}

#[test]
fn custom_near_planes_match_a_ray_cast_from_there() {
    for seed in 1..=3 {
        let (scene, camera) = procedural_scene(seed, 96, 64);
        // The camera is about 7 from the middle: planes through the scene,
        // and one nearer than the default.
        for near in [5.5f32, 7.0, NEAR * 0.1] {
            let ids = id_buffer_clipped(&scene, &camera, near, &|_| true);
            assert_matches_ray_cast_beyond(&scene, &camera, near, &ids);
        }
    }
}

#[test]
fn a_near_plane_closer_than_the_default_shows_what_lies_between() {
    let camera = looking_down_z(60.0, 32, 24);
    let mut b = Builder::default();
    let o = b.object("close", Vec3::ONE);
    let depth = NEAR * 0.5;
    b.quad(
        o,
        [
            point_at(&camera, 8.0, 6.0, depth),
            point_at(&camera, 24.0, 6.0, depth),
            point_at(&camera, 24.0, 18.0, depth),
            point_at(&camera, 8.0, 18.0, depth),
        ],
    );
    assert!(
        id_buffer(&b.scene, &camera)
            .triangle
            .iter()
            .all(|&t| t == NONE)
    );
    let ids = id_buffer_clipped(&b.scene, &camera, NEAR * 0.1, &|_| true);
    for y in 0..camera.height {
        for x in 0..camera.width {
            let inside = (8..24).contains(&x) && (6..18).contains(&y);
            assert_eq!(ids.triangle_at(x, y) != NONE, inside, "({x}, {y})");
        }
    }
}

/// A union holds both rectangles and no more; an empty one adds nothing.
#[test]
fn a_union_is_the_smallest_rectangle_holding_both() {
    let a = PixelRect {
        x0: 2,
        y0: 5,
        x1: 10,
        y1: 7,
    };
    let b = PixelRect {
        x0: 4,
        y0: 1,
        x1: 12,
        y1: 6,
    };
    let both = PixelRect {
        x0: 2,
        y0: 1,
        x1: 12,
        y1: 7,
    };
    assert_eq!(a.union(b), both);
    assert_eq!(b.union(a), both);
    let empty = PixelRect {
        x0: 50,
        y0: 50,
        x1: 50,
        y1: 60,
    };
    assert_eq!(a.union(empty), a);
    assert_eq!(empty.union(a), a);
    assert!(PixelRect::EMPTY.union(empty).is_empty());
}

/// A copy made in the planes of dropped buffers of other sizes (larger and
/// smaller, holding other values) is the buffer, to the bit.
#[test]
fn a_copy_in_dropped_buffers_planes_is_the_buffer() {
    let (scene, camera) = procedural_scene(7, 96, 64);
    let ids = id_buffer(&scene, &camera);
    let window = PixelRect {
        x0: 10,
        y0: 5,
        x1: 70,
        y1: 40,
    };
    let part = id_buffer_within(&scene, &camera, window, &|_| true);
    for other in [(160, 120), (40, 30)] {
        let (scene, camera) = procedural_scene(3, other.0, other.1);
        drop(id_buffer(&scene, &camera));
        assert_same_ids(&ids.clone(), &ids);
        drop(id_buffer(&scene, &camera));
        assert_same_ids(&part.clone(), &part);
    }
}
