//! Compares obvhs BVH layouts (CwBvh, Bvh2) and build presets on a procedural
//! interior scene: build time, closest-hit and any-hit cost per ray.
//!
//! Run: `cargo run --release -p vtfarm-trace --example bvh_layouts`
//!
//! Rays are traced on one thread so that the numbers compare layouts rather
//! than scheduling. "any-hit" uses `occluded` with t_max = 2 m.

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::Vec3;
use rand::{Rng as _, SeedableRng};
use rand_xoshiro::Xoshiro256PlusPlus;
use vtfarm_scene::{Material, MaterialId, Object, Scene, Triangle};
use vtfarm_trace::{BuildPreset, BvhLayout, BvhOptions, Ray, SceneBvh};

/// Seeded inputs from the workspace's one test generator (`rand_xoshiro`).
struct Rng(Xoshiro256PlusPlus);

impl Rng {
    fn new(seed: u64) -> Rng {
        Rng(Xoshiro256PlusPlus::seed_from_u64(seed))
    }

    fn unit(&mut self) -> f32 {
        self.0.random()
    }

    fn vec3(&mut self, lo: Vec3, hi: Vec3) -> Vec3 {
        lo + (hi - lo) * Vec3::new(self.unit(), self.unit(), self.unit())
    }

    fn direction(&mut self) -> Vec3 {
        loop {
            let v = self.vec3(Vec3::splat(-1.0), Vec3::ONE);
            if v.length_squared() > 1e-4 && v.length_squared() <= 1.0 {
                return v.normalize();
            }
        }
    }
}

fn push_triangle(scene: &mut Scene, corners: [Vec3; 3]) {
    let n = (corners[1] - corners[0])
        .cross(corners[2] - corners[0])
        .normalize_or(Vec3::Y);
    let base = scene.positions.len() as u32;
    scene.positions.extend(corners);
    scene.normals.extend([n; 3]);
    scene.triangles.push(Triangle {
        vertices: [base, base + 1, base + 2],
        object: vtfarm_scene::ObjectId(0),
        material: MaterialId(0),
    });
}

/// A UV sphere of `rings` x `segments` quads.
fn push_sphere(scene: &mut Scene, centre: Vec3, radius: f32, rings: u32, segments: u32) {
    let at = |ring: u32, segment: u32| {
        let (theta, phi) = (
            std::f32::consts::PI * ring as f32 / rings as f32,
            std::f32::consts::TAU * segment as f32 / segments as f32,
        );
        centre
            + radius
                * Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                )
    };
    for ring in 0..rings {
        for segment in 0..segments {
            let (a, b, c, d) = (
                at(ring, segment),
                at(ring + 1, segment),
                at(ring + 1, segment + 1),
                at(ring, segment + 1),
            );
            push_triangle(scene, [a, b, c]);
            push_triangle(scene, [a, c, d]);
        }
    }
}

/// A 20 x 6 x 20 m room (large wall triangles), a grid of spheres and clutter.
fn room() -> Scene {
    let mut scene = Scene {
        objects: vec![Object {
            name: "room".into(),
        }],
        materials: vec![Material::default()],
        ..Scene::default()
    };
    let (lo, hi) = (Vec3::new(-10.0, 0.0, -10.0), Vec3::new(10.0, 6.0, 10.0));
    let corner = |i: u32| {
        Vec3::new(
            [lo.x, hi.x][i as usize & 1],
            [lo.y, hi.y][(i as usize >> 1) & 1],
            [lo.z, hi.z][(i as usize >> 2) & 1],
        )
    };
    for [a, b, c, d] in [
        [0, 1, 3, 2],
        [4, 6, 7, 5],
        [0, 2, 6, 4],
        [1, 5, 7, 3],
        [0, 4, 5, 1],
        [2, 3, 7, 6],
    ] {
        push_triangle(&mut scene, [corner(a), corner(b), corner(c)]);
        push_triangle(&mut scene, [corner(a), corner(c), corner(d)]);
    }
    for i in 0..64 {
        let centre = Vec3::new(
            -8.0 + (i % 8) as f32 * 2.3,
            1.0 + (i % 3) as f32,
            -8.0 + (i / 8) as f32 * 2.3,
        );
        push_sphere(&mut scene, centre, 0.4 + 0.1 * (i % 5) as f32, 20, 32);
    }
    let mut rng = Rng::new(1);
    for _ in 0..20_000 {
        let c = rng.vec3(lo, hi);
        let s = Vec3::splat(0.15);
        push_triangle(
            &mut scene,
            [
                c + rng.vec3(-s, s),
                c + rng.vec3(-s, s),
                c + rng.vec3(-s, s),
            ],
        );
    }
    scene
}

/// Camera rays from a corner of the room plus random rays from random points
/// inside it (a stand-in for secondary and shadow rays).
fn rays() -> Vec<Ray> {
    let mut rng = Rng::new(12345);
    let eye = Vec3::new(-9.0, 3.0, 9.0);
    let forward = (Vec3::new(0.0, 1.5, 0.0) - eye).normalize();
    let right = forward.cross(Vec3::Y).normalize();
    let up = right.cross(forward);
    let mut rays = Vec::new();
    for y in 0..250 {
        for x in 0..400 {
            let (u, v) = ((x as f32 - 200.0) / 320.0, (125.0 - y as f32) / 320.0);
            rays.push(Ray {
                origin: eye,
                direction: (forward + right * u + up * v).normalize(),
            });
        }
    }
    for _ in 0..100_000 {
        rays.push(Ray {
            origin: rng.vec3(Vec3::new(-9.9, 0.1, -9.9), Vec3::new(9.9, 5.9, 9.9)),
            direction: rng.direction(),
        });
    }
    rays
}

fn main() {
    let scene = Arc::new(room());
    let rays = rays();
    let configs: Vec<BvhOptions> = BvhLayout::ALL
        .into_iter()
        .flat_map(|layout| BuildPreset::ALL.map(|preset| BvhOptions { layout, preset }))
        .collect();
    // Rounds interleave the configurations so that load from other processes
    // hits them all alike. Rays go in short chunks; a configuration's time is
    // the sum over chunks of each chunk's best round, which filters out
    // chunks that were preempted.
    let chunks: Vec<&[Ray]> = rays.chunks(CHUNK).collect();
    let mut build = vec![Duration::MAX; configs.len()];
    let mut closest = vec![vec![Duration::MAX; chunks.len()]; configs.len()];
    let mut any = vec![vec![Duration::MAX; chunks.len()]; configs.len()];
    let mut hits = vec![0; configs.len()];
    for _round in 0..ROUNDS {
        for (i, &options) in configs.iter().enumerate() {
            let start = Instant::now();
            let bvh = SceneBvh::with_options(scene.clone(), options);
            build[i] = build[i].min(start.elapsed());
            hits[i] = 0;
            for (c, chunk) in chunks.iter().enumerate() {
                let start = Instant::now();
                hits[i] += chunk
                    .iter()
                    .filter(|r| bvh.closest_hit(r, f32::INFINITY).is_some())
                    .count();
                closest[i][c] = closest[i][c].min(start.elapsed());
                let start = Instant::now();
                let blocked = chunk.iter().filter(|r| bvh.occluded(r, 2.0)).count();
                any[i][c] = any[i][c].min(start.elapsed());
                assert!(blocked <= chunk.len());
            }
        }
    }
    let closest: Vec<Duration> = closest.iter().map(|c| c.iter().sum()).collect();
    let any: Vec<Duration> = any.iter().map(|c| c.iter().sum()).collect();
    let per_ray = |d: Duration| d.as_nanos() as f64 / rays.len() as f64;
    println!(
        "{} triangles, {} rays, best of {ROUNDS} interleaved rounds per {CHUNK}-ray chunk",
        scene.triangles.len(),
        rays.len()
    );
    println!(
        "{:<8} {:<9} {:>9} {:>12} {:>12} {:>7}",
        "layout", "preset", "build ms", "closest ns", "any-hit ns", "hits"
    );
    for (i, options) in configs.iter().enumerate() {
        println!(
            "{:<8} {:<9} {:>9.1} {:>12.1} {:>12.1} {:>7}",
            format!("{:?}", options.layout),
            format!("{:?}", options.preset),
            build[i].as_secs_f64() * 1e3,
            per_ray(closest[i]),
            per_ray(any[i]),
            hits[i]
        );
    }
}

const ROUNDS: usize = 7;
const CHUNK: usize = 10_000;
