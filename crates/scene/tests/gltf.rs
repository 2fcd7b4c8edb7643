//! glTF import against files written by an independent writer (pygltflib;
//! `tests/data/gltf/make_fixtures.py` made them): node transforms and
//! instancing, a camera, a textured mesh, thin glass from
//! `KHR_materials_ior`/`_transmission`, and a refused extension; and the
//! GLB export read back.

use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use vtfarm_scene::gltf::{
    GltfError, MAX_IMPORTED_VERTICES, MAX_NODE_DEPTH, MAX_NODE_VISITS, import_gltf, write_glb,
};
use vtfarm_scene::obj::ObjOptions;
use vtfarm_scene::{Material, ObjectId, Scene, TriangleId};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/gltf")
        .join(name)
}

fn material<'a>(scene: &'a Scene, name: &str) -> &'a Material {
    &scene.materials[scene.material_id(name).unwrap().index()]
}

/// The corner positions of the object's triangles, in order.
fn corners(scene: &Scene, object: &str) -> Vec<[Vec3; 3]> {
    let id = scene.object_id(object).unwrap();
    scene
        .triangles_of(id)
        .map(|t| scene.triangle_positions(t))
        .collect()
}

fn close(a: Vec3, b: Vec3) -> bool {
    (a - b).abs().max_element() < 1e-5
}

#[test]
fn nodes_place_each_instance_of_a_mesh_and_cameras_come_with_their_node() {
    let imported = import_gltf(&fixture("instanced.glb"), &ObjOptions::default()).unwrap();
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let scene = &imported.scene;
    // One object per node, named after it; the parent moves both.
    let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
    assert_eq!(names, ["left", "right"]);
    // The mesh both nodes instance stays a second name of both.
    assert_eq!(
        imported.mesh_objects.into_iter().collect::<Vec<_>>(),
        [("panel".to_owned(), vec![ObjectId(0), ObjectId(1)])]
    );
    let left = corners(scene, "left");
    assert_eq!(left.len(), 2);
    let offset = Vec3::new(10.0, 2.0, 0.0);
    assert!(
        close(left[0][0], offset) && close(left[0][1], offset + Vec3::X),
        "{left:?}"
    );
    assert!(
        close(left[0][2], offset + Vec3::new(1.0, 1.0, 0.0)),
        "{left:?}"
    );
    // A quarter turn about +Y and twice the size: x goes to -z.
    let right = corners(scene, "right");
    let origin = Vec3::new(10.0, 0.0, 0.0);
    assert!(
        close(right[0][1], origin + Vec3::new(0.0, 0.0, -2.0)),
        "{right:?}"
    );
    assert!(
        close(right[0][2], origin + Vec3::new(0.0, 2.0, -2.0)),
        "{right:?}"
    );
    // Normals turn with the node: the turned quad faces +X.
    let normal = scene.triangle_normals(TriangleId(2))[0];
    assert!(close(normal, Vec3::X) || close(normal, Vec3::Z), "{normal}");
    let t = scene.object_id("right").unwrap();
    let turned = scene.triangles_of(t).next().unwrap();
    assert!(close(scene.triangle_normals(turned)[0], Vec3::X));
    // The PBR base colour is the diffuse colour; glTF's default ior 1.5.
    let paint = material(scene, "paint");
    assert_eq!(
        (paint.diffuse, paint.ambient),
        (Vec3::new(0.8, 0.2, 0.1), Vec3::new(0.8, 0.2, 0.1))
    );
    assert_eq!((paint.reflectance, paint.ior), (Vec3::ZERO, 1.5));
    assert!((paint.specular - Vec3::splat(0.04)).abs().max_element() < 1e-6);
    // roughness 0.5: shininess 2 / 0.5⁴ - 2.
    assert_eq!(paint.shininess, 30.0);
    let [camera] = &imported.cameras[..] else {
        panic!("{:?}", imported.cameras)
    };
    assert_eq!(camera.name, "driver");
    assert!(close(camera.eye, Vec3::new(0.0, 1.0, 2.0)));
    assert!(close(camera.target, Vec3::new(0.0, 1.0, 1.0)));
    assert!(close(camera.up, Vec3::Y));
    assert!((camera.fov_y_deg - 0.8f32.to_degrees()).abs() < 1e-4);
}

#[test]
fn a_base_colour_texture_is_read_with_its_coordinates() {
    let imported = import_gltf(&fixture("textured.glb"), &ObjOptions::default()).unwrap();
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let scene = &imported.scene;
    let decal = material(scene, "decal");
    let texture = &scene.textures[decal.diffuse_texture.unwrap() as usize];
    assert_eq!((texture.width(), texture.height()), (4, 4));
    // v flipped to the scene's convention (up): corner (0, 0, 0) is the
    // image's bottom left.
    assert_eq!(scene.corner_uvs.len(), 2);
    assert_eq!(scene.corner_uvs[0][0], Vec2::new(0.0, 0.0));
    assert_eq!(scene.corner_uvs[0][2], Vec2::new(1.0, 1.0));
    // The texel colours at the quad's quarters: top left red, bottom right yellow.
    let at = |x: f32, y: f32| {
        let point = Vec3::new(x, y, 0.0);
        let t = TriangleId(if y <= x { 0 } else { 1 });
        let weights = scene.barycentrics(t, point);
        scene.textured_material(t, weights, 0.0).diffuse
    };
    let srgb = |c: [u8; 3]| {
        Vec3::from_array(c.map(|c| vtfarm_imaging::srgb_to_linear(f32::from(c) / 255.0)))
    };
    assert!(close(at(0.2, 0.8), srgb([200, 30, 30])), "{}", at(0.2, 0.8));
    assert!(
        close(at(0.8, 0.2), srgb([220, 220, 40])),
        "{}",
        at(0.8, 0.2)
    );
    assert!(close(at(0.2, 0.2), srgb([30, 30, 200])), "{}", at(0.2, 0.2));
}

#[test]
fn transmission_and_ior_make_thin_glass() {
    let imported = import_gltf(&fixture("glass.gltf"), &ObjOptions::default()).unwrap();
    let scene = &imported.scene;
    // An unnamed node takes its mesh's name.
    assert_eq!(scene.objects[0].name, "pane");
    let glass = material(scene, "windshield");
    let f0 = 0.04;
    assert!((glass.reflectance - Vec3::splat(f0)).abs().max_element() < 1e-6);
    let expected = Vec3::new(0.9, 1.0, 0.9) * (1.0 - f0);
    assert!(
        (glass.transmittance - expected).abs().max_element() < 1e-6,
        "{}",
        glass.transmittance
    );
    // Thin-walled: rays pass straight, the ior is the Fresnel weights';
    // nothing diffuse.
    assert!(glass.thin && !glass.fresnel);
    assert_eq!((glass.ior, glass.bending_ior()), (1.5, 1.0));
    assert_eq!(glass.diffuse, Vec3::ZERO);
    // No normals in the file: computed, facing +Z.
    assert!(close(scene.triangle_normals(TriangleId(0))[0], Vec3::Z));
}

#[test]
fn compressed_meshes_are_refused_naming_the_extension() {
    let error = import_gltf(&fixture("draco.gltf"), &ObjOptions::default()).unwrap_err();
    assert!(
        matches!(error, GltfError::UnsupportedExtension { .. }),
        "{error:?}"
    );
    let message = error.to_string();
    assert!(
        message.contains("draco.gltf") && message.contains("KHR_draco_mesh_compression"),
        "{message}"
    );
}

#[test]
fn the_glb_export_reads_back_as_the_same_scene() {
    let imported = import_gltf(&fixture("instanced.glb"), &ObjOptions::default()).unwrap();
    let mut scene = imported.scene;
    // Every material term exactly, including those PBR cannot say.
    let paint = &mut scene.materials[0];
    paint.ambient = Vec3::new(0.01, 0.02, 0.03);
    paint.reflectance = Vec3::new(0.3, 0.2, 0.1);
    paint.emission = Vec3::splat(2.5);
    paint.ior = 1.6;
    paint.thin = true;
    paint.fresnel = true;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("back.glb");
    write_glb(&scene, &path).unwrap();
    let back = import_gltf(&path, &ObjOptions::default()).unwrap();
    assert!(back.warnings.is_empty(), "{:?}", back.warnings);
    assert_eq!(back.scene, scene);
}

/// Files whose node trees instance without end (nodes sharing their
/// children, level after level; a node inside itself) are refused by the
/// count taken before any mesh is read, naming the file and the bound, so
/// a few kilobytes cannot make the import take unbounded time or memory.
#[test]
fn node_trees_that_instance_beyond_the_bounds_are_refused_before_reading() {
    let cases = [
        // 2^21 instances of a quad.
        (
            "instances_beyond_bound.gltf",
            format!("more than {MAX_NODE_VISITS} nodes"),
        ),
        // 2^9 instances of 2^16 vertices.
        (
            "vertices_beyond_bound.gltf",
            format!("more than {MAX_IMPORTED_VERTICES} vertices"),
        ),
        (
            "node_cycle.gltf",
            format!("deeper than {MAX_NODE_DEPTH} levels"),
        ),
    ];
    for (name, bound) in cases {
        let path = fixture(name);
        assert!(
            std::fs::metadata(&path).unwrap().len() < 10_000,
            "{name} is small"
        );
        let error = import_gltf(&path, &ObjOptions::default()).unwrap_err();
        assert!(
            matches!(error, GltfError::Invalid { .. }),
            "{name}: {error:?}"
        );
        let message = error.to_string();
        assert!(
            message.starts_with(&path.display().to_string()) && message.contains(&bound),
            "{name}: {message}"
        );
    }
}
