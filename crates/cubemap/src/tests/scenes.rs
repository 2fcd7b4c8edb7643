//! Small hand-built scenes: an icosphere mirror with coloured quads around
//! it, and a saddle.

use glam::Vec3;
use vtfarm_scene::{Material, MaterialId, Object, ObjectId, Scene, Triangle, TriangleId};

/// Adds an object with its own material; returns its (object, material) ids.
pub(crate) fn add_object(
    scene: &mut Scene,
    name: &str,
    material: Material,
) -> (ObjectId, MaterialId) {
    scene.objects.push(Object {
        name: name.to_owned(),
    });
    scene.materials.push(material);
    (
        ObjectId(scene.objects.len() as u32 - 1),
        MaterialId(scene.materials.len() as u32 - 1),
    )
}

/// Adds vertices and faces (indices into `positions`) to `object`.
pub(crate) fn push(
    scene: &mut Scene,
    object: (ObjectId, MaterialId),
    positions: &[Vec3],
    normals: &[Vec3],
    faces: &[[u32; 3]],
) {
    let base = scene.positions.len() as u32;
    scene.positions.extend_from_slice(positions);
    scene.normals.extend_from_slice(normals);
    scene.triangles.extend(faces.iter().map(|f| Triangle {
        vertices: f.map(|v| v + base),
        object: object.0,
        material: object.1,
    }));
}

pub(super) fn mirror() -> Material {
    Material {
        reflectance: Vec3::ONE,
        ..Material::diffuse("mirror", Vec3::ZERO)
    }
}

/// Adds a sphere; `inward` turns normals and winding inside (a concave
/// mirror seen from within). Returns its triangle ids.
pub(super) fn add_sphere(
    scene: &mut Scene,
    centre: Vec3,
    radius: f32,
    levels: u32,
    inward: bool,
) -> Vec<TriangleId> {
    let (points, mut faces) = vtfarm_scene::shapes::icosphere(levels);
    let sign = if inward { -1.0 } else { 1.0 };
    if inward {
        for f in &mut faces {
            f.swap(1, 2);
        }
    }
    let first = scene.triangles.len();
    let object = add_object(scene, "sphere", mirror());
    let positions: Vec<Vec3> = points.iter().map(|&u| centre + u * radius).collect();
    let normals: Vec<Vec3> = points.iter().map(|&u| u * sign).collect();
    push(scene, object, &positions, &normals, &faces);
    scene.triangle_ids().skip(first).collect()
}

/// Adds an `n` × `n` grid of quads (two triangles each) over the unit
/// square to `object`; `surface(s, t)` places each lattice point and gives
/// its normal. Returns the new triangle ids.
fn add_grid(
    scene: &mut Scene,
    object: (ObjectId, MaterialId),
    n: u32,
    surface: impl Fn(f32, f32) -> (Vec3, Vec3),
) -> Vec<TriangleId> {
    let (positions, normals): (Vec<Vec3>, Vec<Vec3>) = (0..=n)
        .flat_map(|j| (0..=n).map(move |i| (i, j)))
        .map(|(i, j)| surface(i as f32 / n as f32, j as f32 / n as f32))
        .unzip();
    let mut faces = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let k = j * (n + 1) + i;
            faces.push([k, k + 1, k + n + 2]);
            faces.push([k, k + n + 2, k + n + 1]);
        }
    }
    let first = scene.triangles.len();
    push(scene, object, &positions, &normals, &faces);
    scene.triangle_ids().skip(first).collect()
}

/// The mirror sphere of radius `radius` at the origin with four quads
/// around it; returns the scene and the sphere's triangles.
pub(super) fn sphere_scene(radius: f32) -> (Scene, Vec<TriangleId>) {
    let mut scene = Scene::default();
    let sphere = add_sphere(&mut scene, Vec3::ZERO, radius, 4, false);
    let low = Vec3::new(-3.0, -1.5, -3.0);
    // (name, colour, corner, u, v) in units of the radius.
    let quads = [
        (
            "floor",
            Vec3::new(0.8, 0.2, 0.2),
            low,
            Vec3::Z * 6.0,
            Vec3::X * 6.0,
        ),
        (
            "back",
            Vec3::new(0.2, 0.8, 0.2),
            low,
            Vec3::X * 6.0,
            Vec3::Y * 4.0,
        ),
        (
            "left",
            Vec3::new(0.2, 0.2, 0.8),
            Vec3::new(-3.0, -1.5, 3.0),
            Vec3::Z * -6.0,
            Vec3::Y * 4.0,
        ),
        (
            "right",
            Vec3::new(0.8, 0.8, 0.2),
            Vec3::new(3.0, -1.5, -3.0),
            Vec3::Z * 6.0,
            Vec3::Y * 4.0,
        ),
    ];
    for (name, color, corner, u, v) in quads {
        scene.append_quad(
            name,
            Material::diffuse(name, color),
            corner * radius,
            u * radius,
            v * radius,
        );
    }
    (scene, sphere)
}

/// A saddle z = (x² - y²) / 2 over [-1, 1]², normals up.
pub(super) fn saddle() -> (Scene, Vec<TriangleId>) {
    let mut scene = Scene::default();
    let object = add_object(&mut scene, "saddle", mirror());
    let triangles = add_grid(&mut scene, object, 8, |s, t| {
        let (x, y) = (s * 2.0 - 1.0, t * 2.0 - 1.0);
        (
            Vec3::new(x, y, (x * x - y * y) * 0.5),
            Vec3::new(-x, y, 1.0).normalize(),
        )
    });
    (scene, triangles)
}

/// A sheet `corner + s u + t v` split into `n` × `n` quads (one object).
pub(super) fn dense_sheet(
    scene: &mut Scene,
    corner: Vec3,
    u: Vec3,
    v: Vec3,
    n: u32,
) -> Vec<TriangleId> {
    let object = add_object(scene, "sheet", Material::diffuse("sheet", Vec3::splat(0.5)));
    let normal = u.cross(v).normalize();
    add_grid(scene, object, n, |s, t| (corner + u * s + v * t, normal))
}
