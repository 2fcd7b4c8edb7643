//! Precision at any scale: spawned rays never re-hit their own surface, the
//! offset follows the hit rather than the scene's extent, and the triangle
//! test leaves no crack at the shared edges and vertices of a fan.

use std::sync::Arc;

use glam::Vec3;
use vtfarm_scene::{Material, MaterialId, Object, Scene, Triangle, TriangleId};

use crate::testutil::{SceneBuilder, TestRng};
use crate::{Ray, SceneBvh, spawn_offset};

/// One object made of `corners` (one triangle each), with face normals.
fn scene_of(corners: &[[Vec3; 3]]) -> Scene {
    let mut builder = SceneBuilder::default();
    builder.triangles(Material::default(), corners);
    builder.scene
}

/// A closed fan of `n` triangles around `centre` in the plane spanned by
/// `u` and `v`, with rim radius `radius` (the rim vertices jittered), as
/// shared indexed vertices.
fn fan(rng: &mut TestRng, centre: Vec3, u: Vec3, v: Vec3, radius: f32, n: u32) -> Scene {
    let mut positions = vec![centre];
    for i in 0..n {
        let a = std::f32::consts::TAU * (i as f32 + rng.range(-0.3, 0.3)) / n as f32;
        let r = radius * rng.range(0.5, 1.0);
        positions.push(centre + (u * a.cos() + v * a.sin()) * r);
    }
    let normal = u.cross(v).normalize();
    Scene {
        normals: vec![normal; positions.len()],
        positions,
        triangles: (0..n)
            .map(|i| Triangle {
                vertices: [0, 1 + i, 1 + (i + 1) % n],
                object: vtfarm_scene::ObjectId(0),
                material: MaterialId(0),
            })
            .collect(),
        objects: vec![Object { name: "fan".into() }],
        materials: vec![Material::default()],
        ..Default::default()
    }
}

#[test]
fn rays_through_shared_vertices_and_edges_of_a_fan_never_miss() {
    let mut rng = TestRng::new(14);
    let mut rays = 0;
    for case in 0..60 {
        let u = rng.direction();
        let v = u.cross(rng.direction()).normalize();
        let scale = [1e-3, 1.0, 500.0, 1e5][case % 4];
        let centre = rng.vec3(-1.0, 1.0) * scale;
        let n = 3 + (rng.next_u64() % 40) as u32;
        let scene = Arc::new(fan(&mut rng, centre, u, v, scale * 0.1, n));
        let bvh = SceneBvh::new(scene.clone());
        for _ in 0..200 {
            // Aim at the centre vertex or at a point of a shared edge.
            let target = if rng.unit() < 0.5 {
                centre
            } else {
                let rim = scene.positions[1 + (rng.next_u64() % n as u64) as usize];
                centre + (rim - centre) * rng.range(0.0, 0.9)
            };
            let origin = target + rng.direction() * scale * rng.range(0.1, 10.0);
            let ray = Ray {
                origin,
                direction: (target - origin).normalize(),
            };
            if ray.direction.dot(u.cross(v)).abs() < 0.05 {
                continue; // grazing: the ray may pass beside the fan's rim
            }
            rays += 1;
            let (tree, brute) = (
                bvh.closest_hit(&ray, f32::INFINITY),
                bvh.closest_hit_brute_force(&ray, f32::INFINITY),
            );
            assert!(
                tree.is_some() && brute.is_some(),
                "case {case}: {ray:?} slipped through the fan ({tree:?}, {brute:?}), aimed at the {}",
                if target == centre { "centre" } else { "edge" }
            );
        }
    }
    assert!(rays > 8000, "{rays}");
}

#[test]
fn spawned_rays_never_hit_their_own_triangle_at_any_scale() {
    let mut rng = TestRng::new(7);
    for case in 0..400 {
        // 1e-3 … 1e4, placed up to 50 sizes off the origin: within MAX_COORDINATE.
        let scale = 10f32.powi((case % 8) as i32 - 3);
        let offset = rng.vec3(-1.0, 1.0) * scale * [0.0, 1.0, 50.0][case % 3];
        let corners = [0; 3].map(|_| offset + rng.vec3(-1.0, 1.0) * scale);
        let bvh = SceneBvh::new(Arc::new(scene_of(&[corners])));
        let normal = bvh.geometric_normal(TriangleId(0));
        if normal == Vec3::ZERO {
            continue;
        }
        for _ in 0..50 {
            let (b1, b2) = (rng.unit(), rng.unit());
            let (b1, b2) = if b1 + b2 > 1.0 {
                (1.0 - b1, 1.0 - b2)
            } else {
                (b1, b2)
            };
            let [a, b, c] = corners;
            // Both ways a caller computes a point: interpolation, and an eye
            // ray from far away meeting the plane.
            let interpolated = a * (1.0 - b1 - b2) + b * b1 + c * b2;
            let eye = interpolated + rng.direction() * scale * 300.0;
            let to = (interpolated - eye).normalize();
            let t = (a - eye).dot(normal) / to.dot(normal);
            for position in [interpolated, eye + to * t] {
                let direction = rng.direction();
                let ray = bvh.spawn_ray(position, TriangleId(0), direction);
                assert_eq!(
                    bvh.closest_hit_brute_force(&ray, f32::INFINITY),
                    None,
                    "case {case}: {position} leaving along {direction}"
                );
            }
        }
    }
}

#[test]
fn the_spawn_offset_follows_the_hit_not_the_scene() {
    // A 1-unit detail at the origin of a 500-unit scene.
    let detail = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let far = [
        Vec3::splat(-250.0),
        Vec3::new(250.0, -250.0, -250.0),
        Vec3::splat(250.0),
    ];
    let bvh = SceneBvh::new(Arc::new(scene_of(&[detail, far])));
    let near = bvh.spawn_distance(Vec3::new(0.25, 0.25, 0.0), TriangleId(0));
    assert_eq!(near, spawn_offset(1.0));
    assert!(near < 1e-5, "{near}");
    assert_eq!(
        bvh.spawn_distance(Vec3::ZERO, TriangleId(1)),
        spawn_offset(250.0)
    );
    // The origin leaves the plane by exactly that distance, tangentially in place.
    let ray = bvh.spawn_ray(
        Vec3::new(0.25, 0.25, 0.0),
        TriangleId(0),
        Vec3::new(0.0, 0.6, 0.8),
    );
    assert_eq!(ray.origin, Vec3::new(0.25, 0.25, near));
    let ray = bvh.spawn_ray(
        Vec3::new(0.25, 0.25, 0.0),
        TriangleId(0),
        Vec3::new(0.0, 0.6, -0.8),
    );
    assert_eq!(ray.origin, Vec3::new(0.25, 0.25, -near));
}
