//! OBJ/MTL import and export: fixtures under `tests/data`, error messages with
//! file and line, round trips, and robustness against garbled input.

use std::fs;
use std::path::{Path, PathBuf};

use glam::Vec3;
use proptest::prelude::*;
use tempfile::TempDir;
use vtfarm_scene::obj::{
    MAX_FACE_VERTICES, ObjError, ObjOptions, ObjWarning, import_obj, load_obj, write_obj,
};
use vtfarm_scene::shapes::disc_polygon_obj;
use vtfarm_scene::{Material, MaterialId, Object, ObjectId, Scene, Triangle, TriangleId};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn load(path: &Path) -> Result<Scene, ObjError> {
    load_obj(path, &ObjOptions::default())
}

/// Writes `files` (name, contents) into a fresh directory and loads the first.
fn load_files(files: &[(&str, &[u8])]) -> (TempDir, Result<Scene, ObjError>) {
    let dir = TempDir::new().unwrap();
    for (name, contents) in files {
        fs::write(dir.path().join(name), contents).unwrap();
    }
    let result = load(&dir.path().join(files[0].0));
    (dir, result)
}

fn approx(a: Vec3, b: Vec3) -> bool {
    (a - b).abs().max_element() < 1e-6
}

/// The triangles of a scene as (object name, material, corner positions,
/// corner normals), which is what survives any vertex renumbering.
fn triangle_list(scene: &Scene) -> Vec<(String, Material, [Vec3; 3], [Vec3; 3])> {
    scene
        .triangle_ids()
        .map(|i| {
            let t = scene.triangles[i.index()];
            (
                scene.objects[t.object.index()].name.clone(),
                scene.material_of(i).clone(),
                scene.triangle_positions(i),
                scene.triangle_normals(i),
            )
        })
        .collect()
}

#[test]
fn a_cube_without_normals_gets_24_vertices_with_face_normals() {
    let scene = load(&data("cube.obj")).unwrap();
    assert_eq!(scene.triangles.len(), 12);
    assert_eq!(
        scene.objects,
        [Object {
            name: "cube".into()
        }]
    );
    assert_eq!(
        scene
            .materials
            .iter()
            .map(|m| &m.name[..])
            .collect::<Vec<_>>(),
        ["red", "white"]
    );
    // Two runs of three faces, four corners per face.
    assert_eq!(scene.positions.len(), 24);
    for i in TriangleId::range(12) {
        let face = scene.geometric_normal(i);
        assert!(scene.triangle_normals(i).iter().all(|&n| approx(n, face)));
        // Faces are wound counter-clockwise seen from outside.
        let centre = scene.triangle_positions(i).iter().sum::<Vec3>() / 3.0;
        assert!(face.dot(centre - Vec3::splat(0.5)) > 0.0);
    }
    let white = &scene.materials[1];
    assert_eq!(
        (white.ambient, white.diffuse),
        (Vec3::splat(0.2), Vec3::splat(0.9))
    );
    // Ka defaults to Kd.
    assert_eq!(scene.materials[0].ambient, Vec3::new(0.8, 0.1, 0.1));
}

#[test]
fn a_room_maps_objects_materials_and_normals() {
    let scene = load(&data("room.obj")).unwrap();
    let names = |v: Vec<&str>| v.into_iter().map(String::from).collect::<Vec<_>>();
    assert_eq!(
        scene
            .objects
            .iter()
            .map(|o| o.name.clone())
            .collect::<Vec<_>>(),
        names(vec!["floor", "mirror", "lamp", "glass"])
    );
    assert_eq!(
        scene
            .materials
            .iter()
            .map(|m| m.name.clone())
            .collect::<Vec<_>>(),
        names(vec![
            "mirror", "tinted", "lamp", "glass", "frosted", "default"
        ])
    );
    // floor 2, mirror 2, lamp pentagon 3, glass 4 + 1, mirror again 1; the
    // point and the 3-vertex line add nothing.
    assert_eq!(scene.triangles.len(), 13);
    let per_object = |o| {
        scene
            .triangles
            .iter()
            .filter(|t| t.object == ObjectId(o))
            .count()
    };
    assert_eq!([0, 1, 2, 3].map(per_object), [2, 3, 3, 5]);

    let material = |name: &str| &scene.materials[scene.material_id(name).unwrap().index()];
    assert_eq!(material("default"), &Material::default());
    let mirror = material("mirror");
    assert_eq!(
        (mirror.reflectance, mirror.shininess),
        (Vec3::splat(0.9), 200.0)
    );
    assert_eq!(material("tinted").reflectance, Vec3::new(0.2, 0.4, 0.6));
    let lamp = material("lamp");
    assert_eq!(
        (lamp.emission, lamp.ambient, lamp.specular),
        (Vec3::new(5.0, 4.5, 4.0), Vec3::ZERO, Vec3::ZERO)
    );
    let glass = material("glass");
    assert_eq!(
        (
            glass.transmittance,
            glass.ior,
            glass.reflectance,
            glass.fresnel
        ),
        // illum 7 with Ks 1: a mirror of Ks, passing (1 - Ks) of d's 0.9.
        (Vec3::ZERO, 1.5, Vec3::ONE, true)
    );
    let frosted = material("frosted");
    assert_eq!(
        (frosted.transmittance, frosted.ior, frosted.reflectance),
        // A dielectric (Tr with Ni): Fresnel at normal incidence.
        (
            Vec3::splat(0.75),
            1.3,
            Vec3::splat(((1.3f32 - 1.0) / (1.3 + 1.0)).powi(2))
        )
    );
    assert!(!material("lamp").is_specular() && frosted.is_specular());

    for (i, t) in scene.triangle_ids().zip(&scene.triangles) {
        let name = &scene.objects[t.object.index()].name;
        let normals = scene.triangle_normals(i);
        let expected = match &name[..] {
            // From the file's `vn 0 2 0`, normalised.
            "floor" => Vec3::Y,
            "mirror" => Vec3::Z,
            "lamp" => -Vec3::Y,
            // The tetrahedron's edges are sharp: flat faces.
            _ => scene.geometric_normal(i),
        };
        assert!(
            normals.iter().all(|&n| approx(n, expected)),
            "{name}: {normals:?}"
        );
        if name != "floor" {
            assert!(approx(scene.geometric_normal(i), expected), "{name}");
        }
    }
    // floor 4, mirror 4 + 3, lamp 5, glass 4 faces x 3 + frosted 3.
    assert_eq!(scene.positions.len(), 4 + 4 + 3 + 5 + 12 + 3);
}

#[test]
fn the_crease_angle_option_controls_smoothing() {
    let smooth = load_obj(
        &data("cube.obj"),
        &ObjOptions {
            crease_angle_deg: 120.0,
            ..Default::default()
        },
    )
    .unwrap();
    // One vertex per corner in each of the two material runs.
    assert_eq!(smooth.positions.len(), 16);
    for (p, n) in smooth.positions.iter().zip(&smooth.normals) {
        assert!(approx(*n, (*p - Vec3::splat(0.5)).normalize()), "{p} {n}");
    }
}

#[test]
fn a_loaded_scene_survives_write_and_load_bit_for_bit() {
    let dir = TempDir::new().unwrap();
    for fixture in ["cube.obj", "room.obj"] {
        let scene = load(&data(fixture)).unwrap();
        write_obj(&scene, dir.path(), "copy").unwrap();
        let again = load(&dir.path().join("copy.obj")).unwrap();
        assert_eq!(again, scene, "{fixture}");
    }
}

/// A hand-built scene: three objects sharing a vertex array, a mirror, glass,
/// a lamp and the default material, with triangles of one object interleaved
/// with another's.
fn built_scene() -> Scene {
    let mut mirror = Material::diffuse("mirror", Vec3::splat(0.05));
    mirror.specular = Vec3::splat(0.8);
    mirror.shininess = 500.0;
    mirror.reflectance = Vec3::new(0.9, 0.85, 0.8);
    let mut glass = Material::diffuse("green glass", Vec3::ZERO);
    glass.transmittance = Vec3::splat(0.3);
    glass.reflectance = Vec3::splat(0.1);
    glass.ior = 1.52;
    // Written as illum 7 with Kr: its own Fresnel and kt as they are.
    glass.fresnel = true;
    let mut lamp = Material::diffuse("lamp", Vec3::ONE);
    lamp.emission = Vec3::new(10.0, 9.0, 1.0 / 3.0);
    let positions = vec![
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.1),
        // Large, but within vtfarm_scene::MAX_COORDINATE (1e6 m).
        Vec3::new(-1e-7, 2.5e5, std::f32::consts::PI),
    ];
    let normals = positions
        .iter()
        .map(|p| (*p + Vec3::new(0.1, 0.2, 1.0)).normalize())
        .collect();
    let t = |vertices, object, material| Triangle {
        vertices,
        object: ObjectId(object),
        material: MaterialId(material),
    };
    Scene {
        positions,
        normals,
        triangles: vec![
            t([0, 1, 2], 0, 0),
            t([1, 3, 2], 0, 1),
            t([2, 3, 4], 1, 2),
            t([0, 1, 2], 2, 3),
            t([1, 3, 2], 0, 1),
        ],
        objects: ["wall with mirror", "lamp", "shelf"]
            .map(|name| Object { name: name.into() })
            .into(),
        materials: vec![Material::default(), mirror, glass, lamp],
        ..Default::default()
    }
}

#[test]
fn a_built_scene_survives_write_and_load() {
    let dir = TempDir::new().unwrap();
    let scene = built_scene();
    write_obj(&scene, dir.path(), "built").unwrap();
    let again = load(&dir.path().join("built.obj")).unwrap();
    again.validate().unwrap();
    assert_eq!(again.objects, scene.objects);
    assert_eq!(again.materials.len(), scene.materials.len());
    for (a, b) in again.materials.iter().zip(&scene.materials) {
        // Transmittance goes through `d = 1 - t`, so it may round.
        assert!(approx(a.transmittance, b.transmittance), "{}", a.name);
        assert_eq!(
            &Material {
                transmittance: b.transmittance,
                ..a.clone()
            },
            b
        );
    }
    let (expected, found) = (triangle_list(&scene), triangle_list(&again));
    assert_eq!(found.len(), expected.len());
    for (f, e) in found.iter().zip(&expected) {
        assert_eq!((&f.0, &f.2, &f.3), (&e.0, &e.2, &e.3));
        assert_eq!(f.1.name, e.1.name);
    }
}

#[test]
fn written_files_follow_the_obj_conventions_other_loaders_expect() {
    let dir = TempDir::new().unwrap();
    let scene = built_scene();
    write_obj(&scene, dir.path(), "built").unwrap();
    let obj = fs::read_to_string(dir.path().join("built.obj")).unwrap();
    let mtl = fs::read_to_string(dir.path().join("built.mtl")).unwrap();

    let lines = |text: &str, key: &str| {
        text.lines()
            .filter_map(|l| {
                l.strip_prefix(key)
                    .and_then(|r| r.strip_prefix(' '))
                    .map(str::to_owned)
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(lines(&obj, "mtllib"), ["built.mtl"]);
    assert_eq!(lines(&obj, "v").len(), scene.positions.len());
    assert_eq!(lines(&obj, "vn").len(), scene.normals.len());
    let defined = lines(&mtl, "newmtl");
    assert!(lines(&obj, "usemtl").iter().all(|m| defined.contains(m)));
    assert_eq!(
        lines(&obj, "o"),
        ["wall with mirror", "lamp", "shelf", "wall with mirror"]
    );
    // `f v//vn` with 1-based indices, the same for position and normal.
    let faces = lines(&obj, "f");
    assert_eq!(faces.len(), scene.triangles.len());
    for (face, t) in faces.iter().zip(&scene.triangles) {
        let corners: Vec<u32> = face
            .split(' ')
            .map(|c| {
                let (v, vn) = c.split_once("//").unwrap();
                assert_eq!(v, vn);
                v.parse().unwrap()
            })
            .collect();
        assert_eq!(corners, t.vertices.map(|v| v + 1));
    }
    // Mirrors say `illum 3` (glass with its own Fresnel `illum 7`) and
    // carry Kr; the rest `illum 2`.
    assert_eq!(lines(&mtl, "illum"), ["2", "3", "7", "2"]);
    assert_eq!(
        lines(&mtl, "Kr"),
        ["0 0 0", "0.9 0.85 0.8", "0.1 0.1 0.1", "0 0 0"]
    );

    // tobj on its own, with separate position and normal indices, sees the
    // same geometry.
    let options = tobj::LoadOptions {
        triangulate: true,
        ..Default::default()
    };
    let (models, materials) = tobj::load_obj(dir.path().join("built.obj"), &options).unwrap();
    assert_eq!(materials.unwrap().len(), 4);
    let corners: Vec<[f32; 3]> = models
        .iter()
        .flat_map(|m| {
            m.mesh.indices.iter().map(|&i| {
                let p = &m.mesh.positions[3 * i as usize..][..3];
                [p[0], p[1], p[2]]
            })
        })
        .collect();
    let expected: Vec<[f32; 3]> = TriangleId::range(5)
        .flat_map(|i| scene.triangle_positions(i).map(|p| p.to_array()))
        .collect();
    assert_eq!(corners, expected);
}

#[test]
fn write_obj_rejects_scenes_it_cannot_round_trip() {
    let dir = TempDir::new().unwrap();
    let mut twins = built_scene();
    twins.materials[2].name = "mirror".into();
    let mut blank = built_scene();
    blank.objects[1].name = " lamp".into();
    let mut nan = built_scene();
    nan.positions[3].y = f32::NAN;
    let mut broken = built_scene();
    broken.triangles[0].material = MaterialId(9);
    for (scene, message) in [
        (twins, "two materials are named \"mirror\""),
        (blank, "object name \" lamp\" cannot be written"),
        (nan, "vertex 3: position = [1, NaN, 0.1]: must be finite"),
        (broken, "triangle 0 names missing material 9"),
    ] {
        let error = write_obj(&scene, dir.path(), "bad")
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("bad.obj: ") && error.contains(message),
            "{error}"
        );
    }
    assert!(!dir.path().join("bad.obj").exists());
}

const TRIANGLE: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
const GOOD_MTL: &str = "newmtl a\nKd 1 0 0\n";

/// Bad input: (OBJ text, MTL text for `lib.mtl`, file the error must name,
/// line, part of the message). One case per line, hence no rustfmt.
#[rustfmt::skip]
const BAD: &[(&str, &str, &str, usize, &str)] = &[
    ("v 1 2\n", "", "bad.obj", 1, "v: expected 3 to 6 numbers, found 2"),
    ("v 0 0 0\nv 1 2 abc\n", "", "bad.obj", 2, "\"abc\" is not a finite number"),
    ("v 1 2 3 4 5\n", "", "bad.obj", 1, "expected x y z, x y z w or x y z r g b"),
    ("v 1 2 3 0\n", "", "bad.obj", 1, "cannot divide by w = 0"),
    ("v 1 2 3 1 1 1\nv 0 0 0\n", "", "bad.obj", 2, "colours must be given for all"),
    ("v 0 0 0\nvn 0 0 nan\n", "", "bad.obj", 2, "vn: \"nan\" is not a finite number"),
    ("vt 0.5\n", "", "bad.obj", 1, "vt: expected 2 to 3 numbers, found 1"),
    ("# ok\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "", "bad.obj", 5, "vertex index 4 is out of range: 3"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "", "bad.obj", 4, "vertex index 0 (OBJ indices start at 1)"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n", "", "bad.obj", 4, "vertex index -4 is out of range"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/x 2 3\n", "", "bad.obj", 4, "texture index \"x\" is not an integer"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1//1 2//1 3//1\n", "", "bad.obj", 4, "normal index 1 is out of range: 0"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf /1 2 3\n", "", "bad.obj", 4, "vertex index \"\" is not an integer"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/// 2 3\n", "", "bad.obj", 4, "\"1///\" has more than v/vt/vn"),
    ("v 0 0 0\nv 1 0 0\nf 1 2\n", "", "bad.obj", 3, "a face needs at least 3 vertices, found 2"),
    ("v 0 0 0\nusemtl\n", "", "bad.obj", 2, "usemtl without a material name"),
    ("v 0 0 0\nusemtl red\n", "", "bad.obj", 2, "usemtl names material \"red\", which no mtllib"),
    ("mtllib lib.mtl\nusemtl b\n", GOOD_MTL, "bad.obj", 2, "usemtl names material \"b\""),
    ("mtllib\n", "", "bad.obj", 1, "mtllib without a file name"),
    ("v 0 0 0\nmtllib missing.mtl\n", "", "bad.obj", 2, "cannot read material library"),
    ("mtllib lib.mtl\n", "newmtl\n", "lib.mtl", 1, "newmtl: no material name"),
    // tobj itself would panic on this one.
    ("mtllib lib.mtl\n", "newmtl a\nKd 1 2\n", "lib.mtl", 2, "Kd: expected 3 numbers, found 2"),
    ("mtllib lib.mtl\n", "newmtl a\nKs 1 2 x\n", "lib.mtl", 2, "Ks: \"x\" is not a finite number"),
    ("mtllib lib.mtl\n", "newmtl a\n\nKe 1 1 1 1\n", "lib.mtl", 3, "Ke: expected 3 numbers, found 4"),
    ("mtllib lib.mtl\n", "newmtl a\nKr 1\n", "lib.mtl", 2, "Kr: expected 3 numbers, found 1"),
    ("mtllib lib.mtl\n", "newmtl a\nKa inf 0 0\n", "lib.mtl", 2, "Ka: \"inf\" is not a finite number"),
    ("mtllib lib.mtl\n", "newmtl a\nNs\n", "lib.mtl", 2, "Ns: expected a number, found 0"),
    ("mtllib lib.mtl\n", "newmtl a\nNi 1.5.2\n", "lib.mtl", 2, "Ni: \"1.5.2\" is not a finite number"),
    ("mtllib lib.mtl\n", "newmtl a\nd half\n", "lib.mtl", 2, "d: \"half\" is not a finite number"),
    ("mtllib lib.mtl\n", "newmtl a\nTr 0.1 0.2\n", "lib.mtl", 2, "Tr: expected a number, found 2"),
    ("mtllib lib.mtl\n", "newmtl a\nillum 300\n", "lib.mtl", 2, "illum: \"300\" is not a model number"),
    ("mtllib lib.mtl\n", "newmtl a\nmap_Kd\n", "lib.mtl", 2, "map_Kd: no texture file name"),
    ("mtllib lib.mtl\n", "newmtl a\nKd 1 1 # grey\n", "lib.mtl", 2, "Kd: expected 3 numbers, found 2"),
    ("mtllib lib.mtl\n", "newmtl a\nTf 1 1\n", "lib.mtl", 2, "Tf: expected r g b or one number"),
    ("v 0 0 1e22\n", "", "bad.obj", 1, "coordinate 10000000000000000000000 is beyond ±1e6"),
    ("v 0 0 0\nv -2e8 0 0\n", "", "bad.obj", 2, "coordinate 200000000 is beyond ±1e6"),
    ("v 0 0 0\nv 1 1 1 1e-30\n", "", "bad.obj", 2, "coordinate 1000000000000000000000000000000 is beyond"),
    ("v 0 0 1e39\n", "", "bad.obj", 1, "\"1e39\" is not a finite number"),
    ("v 0 0 -inf\n", "", "bad.obj", 1, "\"-inf\" is not a finite number"),
    ("v 0 0 0 # a comment\nv 1 0 0 # another\nv 0 1 0\nf 1 2 3 # 4\nf 1 2 x # y\n", "", "bad.obj", 5, "\"x\" is not an integer"),
];

#[test]
fn every_error_names_the_file_and_line() {
    for &(obj, mtl, file, line, message) in BAD {
        let (dir, result) = load_files(&[
            ("bad.obj", format!("{obj}{TRIANGLE}f -1 -2 -3\n").as_bytes()),
            ("lib.mtl", mtl.as_bytes()),
        ]);
        let error = result.expect_err(obj).to_string();
        let location = format!("{}:{line}: ", dir.path().join(file).display());
        assert!(error.starts_with(&location), "{obj:?} {mtl:?}: {error}");
        assert!(error.contains(message), "{obj:?} {mtl:?}: {error}");
    }
}

#[test]
fn missing_files_are_named_with_the_line_that_refers_to_them() {
    let (dir, result) = load_files(&[("a.obj", b"# lib\nmtllib nowhere.mtl\n")]);
    let error = result.unwrap_err();
    assert!(
        matches!(&error, ObjError::Reference { line: 2, what: "material library", file, .. }
        if *file == dir.path().join("nowhere.mtl")),
        "{error:?}"
    );
    assert!(error.to_string().contains("nowhere.mtl"));

    let missing = data("no such file.obj");
    let error = load(&missing).unwrap_err();
    assert!(
        matches!(&error, ObjError::Io { path, .. } if *path == missing),
        "{error:?}"
    );
    assert!(
        error
            .to_string()
            .starts_with(&missing.display().to_string())
    );
}

#[test]
fn files_without_triangles_are_errors() {
    for text in [
        "",
        "# nothing\n",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nl 1 2 3\np 1\n",
    ] {
        let (dir, result) = load_files(&[("empty.obj", text.as_bytes())]);
        let error = result.unwrap_err().to_string();
        assert_eq!(
            error,
            format!("{}: no triangles", dir.path().join("empty.obj").display())
        );
    }
}

#[test]
fn invalid_utf8_is_reported_at_its_line() {
    let (dir, result) = load_files(&[("bin.obj", b"v 0 0 0\nv 1 0 0\no caf\xe9\n")]);
    let error = result.unwrap_err().to_string();
    assert_eq!(
        error,
        format!(
            "{}:3: not valid UTF-8",
            dir.path().join("bin.obj").display()
        )
    );
}

#[test]
fn tolerant_of_common_variations() {
    // A byte-order mark, CRLF line ends, tabs, indentation, a `w` coordinate,
    // vertex colours, vt with three numbers, names with spaces, `g` groups and
    // an MTL "default" that faces without usemtl pick up.
    let obj = "\u{feff}mtllib\tmy lib.mtl\r\n  v 0 0 0 2\r\nv\t2 0 0 2\r\nv 0 2 0 2\r\n\
               vt 0 0 0\r\ng left wall\r\nf 1/1 2/1 3/1\r\nusemtl  dark red \r\nf 3 2 1\r\n";
    let mtl = "newmtl default\nKd 0.1 0.2 0.3\nnewmtl dark red\nKd 0.5 0 0\n";
    let (_dir, result) = load_files(&[("v.obj", obj.as_bytes()), ("my lib.mtl", mtl.as_bytes())]);
    let scene = result.unwrap();
    assert_eq!(
        scene.objects,
        [Object {
            name: "left wall".into()
        }]
    );
    assert_eq!(scene.materials.len(), 2);
    assert_eq!(
        scene.material_of(TriangleId(0)).diffuse,
        Vec3::new(0.1, 0.2, 0.3)
    );
    assert_eq!(scene.material_of(TriangleId(1)).name, "dark red");
    assert_eq!(
        scene.triangle_positions(TriangleId(0)),
        [Vec3::ZERO, Vec3::X, Vec3::Y]
    );

    let coloured = "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 1 2 3\n";
    let (_dir, result) = load_files(&[("c.obj", coloured.as_bytes())]);
    assert_eq!(result.unwrap().triangles.len(), 1);
}

/// Writes `files` into a fresh directory (creating subdirectories) and
/// imports the first, keeping the warnings.
fn import_files(files: &[(&str, &[u8])]) -> (TempDir, Result<(Scene, Vec<ObjWarning>), ObjError>) {
    let dir = TempDir::new().unwrap();
    for (name, contents) in files {
        let path = dir.path().join(name);
        fs::create_dir_all(path.parent().unwrap()).unwrap();
        fs::write(path, contents).unwrap();
    }
    let result = import_obj(&dir.path().join(files[0].0), &ObjOptions::default())
        .map(|imported| (imported.scene, imported.warnings));
    (dir, result)
}

const TRIANGLE_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";

#[test]
fn what_exporters_write_loads() {
    // Inline comments after numbers, CRLF, trailing spaces after names, a
    // name with `#` in it, a Windows texture path that exists and one that
    // does not.
    let obj = "mtllib scene.mtl \r\nv 0 0 0 # origin\r\nv 1 0 0\r\nv 0 1 0\t# up\r\n\
               o car # body\r\nusemtl Material #25  \r\nf 1 2 3 # one face\r\n";
    let mtl = "newmtl Material #25  \r\nKa 0.1 0.1 0.8 # Blue\r\nKd 0.5 0.5 0.5 #grey\r\n\
               Ns 10 # shiny\r\nillum 2 # highlight\r\nmap_Kd textures\\wood.ppm\r\n\
               map_Ks textures\\glass_baseColor.png\r\n";
    let (dir, result) = import_files(&[
        ("scene.obj", obj.as_bytes()),
        ("scene.mtl", mtl.as_bytes()),
        ("textures/wood.ppm", b"P3 1 1 1 1 1 1\n"),
    ]);
    let (scene, warnings) = result.unwrap();
    // `#` that starts a word ends an `o` line too? No: names keep it.
    assert_eq!(scene.objects[0].name, "car # body");
    assert_eq!(scene.materials[0].name, "Material #25");
    assert_eq!(
        scene.material_of(TriangleId(0)).ambient,
        Vec3::new(0.1, 0.1, 0.8)
    );
    assert_eq!(scene.material_of(TriangleId(0)).shininess, 10.0);
    assert_eq!(
        warnings,
        [ObjWarning {
            path: dir.path().join("scene.mtl"),
            line: 7,
            message: format!(
                "texture {} ignored (No such file or directory (os error 2)); \
                 vtfarm uses map_Kd and map_d only",
                dir.path().join("textures/glass_baseColor.png").display()
            ),
        }]
    );
    assert!(warnings[0].to_string().starts_with(&format!(
        "{}:7: texture",
        dir.path().join("scene.mtl").display()
    )));
}

#[test]
fn objects_without_groups_are_named_by_their_material() {
    let obj = format!(
        "mtllib m.mtl\n{TRIANGLE_OBJ}f 1 2 3\nusemtl glass\nf 1 2 3\nusemtl paint\nf 1 3 2\n\
         usemtl glass\nf 2 1 3\ng body\nusemtl paint\nf 3 2 1\n"
    );
    let mtl = "newmtl glass\nd 0.5\nnewmtl paint\nKd 1 0 0\n";
    let (_dir, result) = load_files(&[("m.obj", obj.as_bytes()), ("m.mtl", mtl.as_bytes())]);
    let scene = result.unwrap();
    let names: Vec<&str> = scene
        .triangles
        .iter()
        .map(|t| scene.objects[t.object.index()].name.as_str())
        .collect();
    assert_eq!(names, ["default", "glass", "paint", "glass", "body"]);
}

#[test]
fn errors_quote_huge_input_cut_short() {
    let huge = "9".repeat(10_000_000);
    for (obj, mtl) in [
        (format!("v 0 0 {huge}\n"), String::new()),
        (format!("v 0 0 0\nusemtl {huge}\n"), String::new()),
        (format!("{TRIANGLE_OBJ}f 1 2 {huge}\n"), String::new()),
        (
            "mtllib m.mtl\n".to_owned(),
            format!("newmtl a\nNs 1{huge}x\n"),
        ),
    ] {
        let (_dir, result) = load_files(&[("big.obj", obj.as_bytes()), ("m.mtl", mtl.as_bytes())]);
        let error = result.unwrap_err().to_string();
        assert!(
            error.len() < 300,
            "{} bytes: {}",
            error.len(),
            &error[..300]
        );
        assert!(error.contains("99999\"… (10000"), "{error}");
    }
}

#[test]
fn huge_polygons_load_and_oversized_ones_are_refused() {
    // 40,000 vertices loaded in 5.3 s before the normals were computed in
    // linear time (0.14 s after; see `examples/polygon_load.rs`).
    let (_dir, result) = load_files(&[("disc.obj", disc_polygon_obj(40_000).as_bytes())]);
    let scene = result.unwrap();
    assert_eq!(scene.triangles.len(), 39_998);
    assert!(
        scene.normals.iter().all(|n| n.y > 0.999),
        "the disc is flat"
    );

    let n = MAX_FACE_VERTICES + 1;
    let (dir, result) = load_files(&[("disc.obj", disc_polygon_obj(n).as_bytes())]);
    assert_eq!(
        result.unwrap_err().to_string(),
        format!(
            "{}:{}: f: a face with more than {MAX_FACE_VERTICES} vertices; \
             split it into smaller polygons",
            dir.path().join("disc.obj").display(),
            n + 1
        )
    );
}

/// The reflectance, transmittance and own Fresnel a one-material MTL gives.
fn optics(mtl: &str) -> (Vec3, Vec3, bool) {
    let obj = format!("mtllib m.mtl\n{TRIANGLE_OBJ}usemtl m\nf 1 2 3\n");
    let mtl = format!("newmtl m\n{mtl}");
    let (_dir, result) = load_files(&[("m.obj", obj.as_bytes()), ("m.mtl", mtl.as_bytes())]);
    let m = result.unwrap().material_of(TriangleId(0)).clone();
    (m.reflectance, m.transmittance, m.fresnel)
}

#[test]
fn illum_models_reflect_ks_as_the_specification_says_and_dielectrics_by_fresnel() {
    let glass = Vec3::splat(0.2f32 * 0.2); // ((1.5 - 1) / (1.5 + 1))²
    let water = Vec3::splat((0.33f32 / 2.33).powi(2));
    let ks = Vec3::splat(0.5);
    for (mtl, expected) in [
        // Ray-traced without Fresnel (illum 3, 4, 6): Ks, whatever Ni says.
        ("Ks 0.5 0.5 0.5\nillum 3\n", (ks, Vec3::ZERO, false)),
        (
            "Ks 0.5 0.5 0.5\nillum 4\nNi 1.5\nd 0.2\n",
            (ks, Vec3::splat(0.8), false),
        ),
        (
            "Ks 0.5 0.5 0.5\nillum 4\nNi 1.00\nd 0.2\n",
            (ks, Vec3::splat(0.8), false),
        ),
        // The refraction models pass (1 - Ks) Tf.
        (
            "Ks 0.5 0.5 0.5\nillum 6\nd 0.5\n",
            (ks, Vec3::splat(0.25), false),
        ),
        // Fresnel on (illum 5, 7): Ks head-on, rising with the angle; an
        // `illum 5` mirror of Ks 0.95 reflects 0.95 head-on.
        (
            "Ks 0.95 0.95 0.95\nillum 5\n",
            (Vec3::splat(0.95), Vec3::ZERO, true),
        ),
        (
            "Ks 0.5 0.5 0.5\nillum 7\nNi 1.33\nTf 0.6 0.7 0.9\n",
            (ks, Vec3::new(0.3, 0.35, 0.45), true),
        ),
        // Without Ks, the Fresnel models reflect the dielectric's F0.
        ("illum 5\n", (glass, Vec3::ZERO, true)),
        (
            "illum 7\nNi 1.33\nTf 1\nd 0.5\n",
            (water, Vec3::splat(0.5) * (1.0 - water), true),
        ),
        // A dielectric with any other illum: d < 1 (or Tr) and Ni.
        (
            "Ks 0.5 0.5 0.5\nillum 2\nNi 1.5\nd 0.3\n",
            (glass, Vec3::splat(0.7), false),
        ),
        ("Ni 1.5\nTr 0.6\n", (glass, Vec3::splat(0.6), false)),
        // Not dielectric: opaque (Tf alone is a filter), or no Ni.
        (
            "illum 2\nNi 1.5\nTf 1 1 1\n",
            (Vec3::ZERO, Vec3::ZERO, false),
        ),
        ("illum 2\nd 0.3\n", (Vec3::ZERO, Vec3::splat(0.7), false)),
        // Kr wins over everything, and keeps the transmittance as written.
        (
            "Ks 0.5 0.5 0.5\nillum 7\nNi 1.5\nd 0.2\nKr 0.1 0.2 0.3\n",
            (Vec3::new(0.1, 0.2, 0.3), Vec3::splat(0.8), true),
        ),
    ] {
        let (kr, kt, fresnel) = optics(mtl);
        assert!(
            (kr - expected.0).abs().max_element() < 1e-6
                && (kt - expected.1).abs().max_element() < 1e-6
                && fresnel == expected.2,
            "{mtl:?}: kr {kr}, kt {kt}, fresnel {fresnel}, expected {expected:?}"
        );
    }
}

#[test]
fn io_errors_are_printed_once() {
    // The I/O error is part of the message and not also a `source`, so
    // printing the error chain does not repeat it.
    let (_dir, result) = load_files(&[("a.obj", b"mtllib gone.mtl\n")]);
    let error = result.unwrap_err();
    assert!(std::error::Error::source(&error).is_none(), "{error:?}");
    assert_eq!(error.to_string().matches("No such file").count(), 1);
}

#[test]
fn zero_normals_in_the_file_fall_back_to_the_face_normal() {
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 0\nvn 0 0 3\nf 1//1 2//2 3//2\n";
    let (_dir, result) = load_files(&[("z.obj", obj.as_bytes())]);
    let scene = result.unwrap();
    assert_eq!(scene.triangle_normals(TriangleId(0)), [Vec3::Z; 3]);
}

/// Tokens likely to upset a parser: broken numbers, odd indices, huge values.
fn token() -> impl Strategy<Value = String> {
    prop_oneof![
        (-4i32..12).prop_map(|i| i.to_string()),
        (-2.0f32..2.0).prop_map(|x| x.to_string()),
        prop::sample::select(vec![
            "0",
            "-0",
            "nan",
            "inf",
            "-inf",
            "1e40",
            "1e-45",
            "",
            "/",
            "//",
            "1/",
            "/1",
            "1//",
            "1/1/1",
            "1//1",
            "-1/-1/-1",
            "2/0/1",
            "1/2/3/4",
            "99999999999999999999",
            "-9223372036854775808",
            "9223372036854775807/1",
            "x",
            "#",
            "é",
            "\t",
        ])
        .prop_map(String::from),
        "[ -~]{0,6}",
    ]
}

fn line_of(keywords: &'static [&'static str]) -> impl Strategy<Value = String> {
    (
        prop::sample::select(keywords),
        prop::collection::vec(token(), 0..7),
    )
        .prop_map(|(k, words)| format!("{k} {}", words.join(" ")))
}

const OBJ_KEYWORDS: &[&str] = &[
    "v", "v", "v", "vt", "vn", "f", "f", "f", "l", "p", "o", "g", "s", "usemtl", "mtllib", "#", "",
];
const MTL_KEYWORDS: &[&str] = &[
    "newmtl", "Ka", "Kd", "Ks", "Ke", "Kr", "Ns", "Ni", "d", "Tr", "illum", "map_Kd", "bump",
    "map_Bump", "map_d", "refl", "Tf", "",
];

/// A few real lines mixed in so that the garbage often reaches deep paths.
fn obj_text() -> impl Strategy<Value = String> {
    let good = prop::sample::select(vec![
        "v 0 0 0",
        "v 1 0 0",
        "v 0 1 0",
        "vn 0 0 1",
        "vt 0 0",
        "f 1 2 3",
        "f -1 -2 -3",
        "f 1//1 2//1 3//1",
        "mtllib lib.mtl",
        "usemtl a",
        "o thing",
        "f 1/1 2/1 3/1 1/1",
    ])
    .prop_map(String::from);
    prop::collection::vec(
        prop_oneof![3 => line_of(OBJ_KEYWORDS), 2 => good, 1 => "[^\n]{0,20}"],
        0..40,
    )
    .prop_map(|lines| lines.join("\n"))
}

fn mtl_text() -> impl Strategy<Value = String> {
    let good = prop::sample::select(vec!["newmtl a", "Kd 1 1 1", "illum 3", "map_Kd tex.png"])
        .prop_map(String::from);
    prop::collection::vec(prop_oneof![3 => line_of(MTL_KEYWORDS), 1 => good], 0..20)
        .prop_map(|lines| lines.join("\n"))
}

/// Mostly printable bytes: any byte >= 0x80 ends the load at the UTF-8 check.
fn byte() -> impl Strategy<Value = u8> {
    prop_oneof![8 => 0x20u8..0x7f, 1 => Just(b'\n'), 1 => any::<u8>()]
}

/// Loading must give Ok or Err, never panic; an Ok scene is valid.
fn check_no_panic(files: &[(&str, &[u8])]) {
    let (_dir, result) = load_files(&[files, &[("tex.png", b"png".as_slice())]].concat());
    if let Ok(scene) = result {
        scene.validate().unwrap();
        assert!(scene.normals.iter().all(|n| n.is_finite()));
    }
}

proptest! {
    #[test]
    fn garbled_obj_and_mtl_never_panic(obj in obj_text(), mtl in mtl_text()) {
        check_no_panic(&[("g.obj", obj.as_bytes()), ("lib.mtl", mtl.as_bytes())]);
    }

    #[test]
    fn truncated_fixtures_never_panic(cut in 0usize..2000, mtl_cut in 0usize..400) {
        let obj = fs::read(data("room.obj")).unwrap();
        let mtl = fs::read(data("room.mtl")).unwrap();
        let extra = fs::read(data("extra.mtl")).unwrap();
        let wood = fs::read(data("wood.ppm")).unwrap();
        check_no_panic(&[
            ("room.obj", &obj[..cut.min(obj.len())]),
            ("room.mtl", &mtl[..mtl_cut.min(mtl.len())]),
            ("extra.mtl", &extra),
            ("wood.ppm", &wood),
        ]);
    }

    #[test]
    fn mutated_bytes_never_panic(edits in prop::collection::vec((0usize..2000, byte()), 1..8)) {
        let mut obj = fs::read(data("room.obj")).unwrap();
        let n = obj.len();
        for (at, byte) in edits {
            obj[at % n] = byte;
        }
        let mtl = fs::read(data("room.mtl")).unwrap();
        let extra = fs::read(data("extra.mtl")).unwrap();
        let wood = fs::read(data("wood.ppm")).unwrap();
        check_no_panic(&[("room.obj", &obj), ("room.mtl", &mtl), ("extra.mtl", &extra), ("wood.ppm", &wood)]);
    }
}
