//! The search on an analytic mirror sphere, hidden vertices, the grid, and
//! the shape classification.

use glam::Vec3;
use vtfarm_scene::{Scene, TriangleId};

use super::scenes::{add_sphere, saddle, sphere_scene};
use crate::mesh::ReflectedMesh;
use crate::{
    GridSettings, ReflectorMaps, ReflectorShape, Region, SearchSettings, classify, search,
};

const RADIUS: f32 = 0.5;
const EYE: Vec3 = Vec3::new(0.3, 0.4, 2.0);

fn sphere_maps() -> (Scene, Vec<TriangleId>, ReflectorMaps) {
    let (scene, sphere) = sphere_scene(RADIUS);
    let maps = ReflectorMaps::build(&scene, &sphere, 256, 1);
    (scene, sphere, maps)
}

/// The analytic reflection point of `v` seen from `eye` on the sphere of
/// `radius` at the origin: bisection on the great circle through the
/// directions of the eye and of v, where the angles of eye and v with the
/// normal are equal.
fn analytic_reflection(eye: Vec3, v: Vec3, radius: f32) -> Vec3 {
    let u = eye.normalize();
    let w = (v - u * v.dot(u)).normalize();
    let phi_v = v.dot(w).atan2(v.dot(u));
    let point = |phi: f64| {
        let (s, c) = phi.sin_cos();
        (u.as_dvec3() * c + w.as_dvec3() * s) * f64::from(radius)
    };
    let imbalance = |phi: f64| {
        let r = point(phi);
        let n = r.normalize();
        n.dot((eye.as_dvec3() - r).normalize()) - n.dot((v.as_dvec3() - r).normalize())
    };
    let (mut lo, mut hi) = (0.0, f64::from(phi_v));
    for _ in 0..100 {
        let mid = 0.5 * (lo + hi);
        if imbalance(mid) > 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    point(0.5 * (lo + hi)).as_vec3()
}

/// Points around the sphere on the eye's side (the reflected region).
fn reflected_points() -> Vec<Vec3> {
    let mut points = Vec::new();
    for k in 0..40 {
        let a = k as f32 * 2.399; // golden angle
        let h = -0.8 + 1.6 * (k as f32 + 0.5) / 40.0;
        let ring = (1.0 - h * h).sqrt();
        let d = Vec3::new(ring * a.cos(), h, ring * a.sin());
        let p = d * RADIUS * (1.5 + (k % 5) as f32 * 0.6);
        // Keep points the sphere reflects: in front of the tangent plane
        // of the analytic reflection point and not behind the sphere.
        if p.dot(EYE.normalize()) > -0.3 * RADIUS {
            points.push(p);
        }
    }
    points
}

#[test]
fn search_finds_the_analytic_reflection_points_of_a_mirror_sphere() {
    let (_, _, maps) = sphere_maps();
    let points = reflected_points();
    assert!(points.len() > 20);
    let mut worst = 0.0f32;
    for &v in &points {
        let found = search(&maps, EYE, v, &SearchSettings::default());
        let expected = analytic_reflection(EYE, v, RADIUS);
        assert_eq!(found.region, Region::Reflected, "{v}: {found:?}");
        let error = (found.reflection_point - expected).length();
        worst = worst.max(error);
        assert!(
            error < 1e-3 * RADIUS,
            "{v}: found {} expected {expected}, error {error}",
            found.reflection_point
        );
        // V' lies on the eye ray through R at |V - R| behind it.
        let behind = (found.virtual_position - found.reflection_point).length();
        assert!((behind - (v - found.reflection_point).length()).abs() < 1e-4);
    }
    println!(
        "worst reflection-point error {:.2e} r over {} points",
        worst / RADIUS,
        points.len()
    );
}

#[test]
fn hidden_vertices_are_flagged_and_meet_the_eye_ray() {
    let (_, _, maps) = sphere_maps();
    let away = -EYE.normalize();
    let (side, up) = away.any_orthonormal_pair();
    for offset in [
        Vec3::ZERO,
        side * 0.2 * RADIUS,
        up * 0.3 * RADIUS,
        (side - up) * 0.2 * RADIUS,
    ] {
        let v = away * 2.5 * RADIUS + offset;
        let found = search(&maps, EYE, v, &SearchSettings::default());
        assert_eq!(found.region, Region::Hidden, "{v}: {found:?}");
        assert!(!found.in_front);
        let r = found.reflection_point;
        assert!(
            (r.length() - RADIUS).abs() < 2e-3 * RADIUS,
            "{r} is not on the sphere"
        );
        // R is where the eye ray towards V crosses the sphere.
        let ray = (v - EYE).normalize();
        let off_ray = (r - EYE).reject_from_normalized(ray).length();
        assert!(off_ray < 2e-3 * RADIUS, "{r} is {off_ray} off the eye ray");
    }
}

#[test]
fn the_grid_agrees_with_the_full_search() {
    let (_, _, maps) = sphere_maps();
    // The scene's quads are too coarse for a grid: a dense sheet between
    // the eye and the sphere instead.
    let mut sheet = Scene::default();
    let sheet_triangles = super::scenes::dense_sheet(
        &mut sheet,
        Vec3::new(-1.5, -0.75, 1.0),
        Vec3::X * 3.0,
        Vec3::Y * 1.5,
        40,
    );
    let settings = SearchSettings::default();
    let mut keep = vec![false; sheet.triangles.len()];
    for &t in &sheet_triangles {
        keep[t.index()] = true;
    }
    let mesh = ReflectedMesh::build(&sheet, &keep, 0.0);
    let full = crate::vertices::virtual_vertices(&mesh, &maps, EYE, &settings, None, &|| false);
    let grid = crate::vertices::virtual_vertices(
        &mesh,
        &maps,
        EYE,
        &settings,
        Some(&GridSettings { fraction: 0.1 }),
        &|| false,
    );
    assert!(
        grid.1 * 4 < full.1,
        "grid searches {} vs full {}",
        grid.1,
        full.1
    );
    let mut worst = 0.0f32;
    let mut compared = 0;
    for (a, b) in full.0.iter().zip(&grid.0) {
        if a.region != Region::Reflected || b.region != Region::Reflected {
            continue;
        }
        compared += 1;
        worst = worst.max((a.reflection_point - b.reflection_point).length());
    }
    assert!(compared > 500, "{compared} vertices compared");
    assert!(
        worst < 0.02 * RADIUS,
        "grid reflection points differ by up to {worst}"
    );
    println!(
        "grid vs full: worst {:.2e} r over {compared} vertices, {} vs {} searches",
        worst / RADIUS,
        grid.1,
        full.1
    );
}

#[test]
fn a_sphere_is_convex_outside_concave_inside_and_a_saddle_is_neither() {
    let (scene, sphere) = sphere_scene(RADIUS);
    assert_eq!(classify(&scene, &sphere), ReflectorShape::Convex);
    let mut inside = Scene::default();
    let inner = add_sphere(&mut inside, Vec3::ZERO, 1.0, 3, true);
    assert_eq!(classify(&inside, &inner), ReflectorShape::Concave);
    let (saddle_scene, saddle_triangles) = saddle();
    let shape = classify(&saddle_scene, &saddle_triangles);
    assert_eq!(shape, ReflectorShape::Neither);
    assert!(shape.warning().is_some());
    assert!(ReflectorShape::Convex.warning().is_none());
}
