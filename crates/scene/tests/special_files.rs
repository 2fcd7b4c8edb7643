//! Every file a scene names is read only when it is a regular file within
//! its bound: `/dev/zero` (endless) and a FIFO without a writer (a read that
//! would block for ever) as the OBJ, its `mtllib`, its `map_Kd`, the glTF
//! file, its buffer and its image are refused at once, naming the file;
//! and a glTF whose accessors disagree with their views or their
//! primitive is an error naming the accessor.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::Duration;

use vtfarm_scene::gltf::{GltfError, ImportedGltf, import_gltf};
use vtfarm_scene::obj::{ImportedObj, ObjError, ObjOptions, import_obj};

/// A wait that ends: a special file read by mistake would hang the test.
const BOUND: Duration = Duration::from_secs(30);

fn within_bound<T: Send + 'static>(work: impl FnOnce() -> T + Send + 'static) -> T {
    let (done, result) = mpsc::channel();
    std::thread::spawn(move || {
        let _ = done.send(work());
    });
    result
        .recv_timeout(BOUND)
        .expect("the import returned within the bound (it did not block on the file)")
}

fn mkfifo(path: &Path) {
    let made = std::process::Command::new("mkfifo")
        .arg(path)
        .status()
        .unwrap();
    assert!(made.success(), "mkfifo {}", path.display());
}

/// `name` in `dir` as each special file: a link to `/dev/zero`, a FIFO.
fn specials(dir: &Path, name: &str) -> [(&'static str, PathBuf); 2] {
    let zero = dir.join("zero");
    let fifo = dir.join("fifo");
    std::fs::create_dir_all(&zero).unwrap();
    std::fs::create_dir_all(&fifo).unwrap();
    std::os::unix::fs::symlink("/dev/zero", zero.join(name)).unwrap();
    mkfifo(&fifo.join(name));
    [
        ("a character device", zero.join(name)),
        ("a FIFO", fifo.join(name)),
    ]
}

const QUAD_OBJ: &str = "mtllib quad.mtl\nusemtl paint\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n";

fn obj(path: PathBuf) -> Result<ImportedObj, ObjError> {
    within_bound(move || import_obj(&path, &ObjOptions::default()))
}

fn gltf(path: PathBuf) -> Result<ImportedGltf, GltfError> {
    within_bound(move || import_gltf(&path, &ObjOptions::default()))
}

#[test]
fn an_obj_or_mtl_that_is_a_device_or_a_fifo_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    for (kind, path) in specials(dir.path(), "quad.obj") {
        let error = obj(path.clone()).unwrap_err().to_string();
        assert!(
            error.contains(&path.display().to_string())
                && error.contains(&format!("{kind}, not a regular file")),
            "{error}"
        );
    }
    for (kind, mtl) in specials(dir.path(), "quad.mtl") {
        let path = mtl.with_file_name("scene.obj");
        std::fs::write(&path, QUAD_OBJ).unwrap();
        let error = obj(path).unwrap_err().to_string();
        assert!(
            error.contains(&mtl.display().to_string())
                && error.contains(&format!("{kind}, not a regular file")),
            "{error}"
        );
    }
}

#[test]
fn a_texture_that_is_a_device_or_a_fifo_is_not_read_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    for (kind, texture) in specials(dir.path(), "wood.png") {
        let folder = texture.parent().unwrap();
        std::fs::write(
            folder.join("quad.mtl"),
            "newmtl paint\nKd 1 1 1\nmap_Kd wood.png\n",
        )
        .unwrap();
        std::fs::write(folder.join("quad.obj"), QUAD_OBJ).unwrap();
        let imported = obj(folder.join("quad.obj")).expect("the scene loads");
        assert!(imported.scene.textures.is_empty());
        let warnings: Vec<String> = imported.warnings.iter().map(|w| w.to_string()).collect();
        assert!(
            warnings
                .iter()
                .any(|w| w.contains(&texture.display().to_string())
                    && w.contains(&format!("{kind}, not a regular file"))),
            "{warnings:?}"
        );
    }
}

/// A one-quad glTF: positions (4 × 12 bytes) then `u16` indices (6 × 2
/// bytes) in one buffer of 60 bytes named `buffer_uri`, `image_uri` the
/// base colour texture's; `patch` edits the JSON before it is written.
fn quad_gltf(
    dir: &Path,
    buffer_uri: &str,
    image_uri: Option<&str>,
    patch: impl FnOnce(&mut serde_json::Value),
) -> PathBuf {
    let mut bin = Vec::new();
    for p in [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]] {
        for c in p {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0, 2, 3] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    if !buffer_uri.contains('/') {
        let path = dir.join(buffer_uri);
        if !path.exists() {
            std::fs::write(path, &bin).unwrap();
        }
    }
    let mut json = serde_json::json!({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "quad"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}],
        "materials": [{"name": "paint"}],
        "buffers": [{"uri": buffer_uri, "byteLength": 60}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 48},
            {"buffer": 0, "byteOffset": 48, "byteLength": 12}
        ],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3",
             "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}
        ]
    });
    if let Some(uri) = image_uri {
        json["images"] = serde_json::json!([{"uri": uri}]);
        json["textures"] = serde_json::json!([{"source": 0}]);
        json["materials"][0]["pbrMetallicRoughness"] =
            serde_json::json!({"baseColorTexture": {"index": 0}});
    }
    patch(&mut json);
    let path = dir.join("quad.gltf");
    std::fs::write(&path, serde_json::to_vec(&json).unwrap()).unwrap();
    path
}

#[test]
fn a_gltf_file_or_buffer_that_is_a_device_or_a_fifo_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    for (kind, path) in specials(dir.path(), "quad.glb") {
        let error = gltf(path.clone()).unwrap_err().to_string();
        assert!(
            error.contains(&path.display().to_string())
                && error.contains(&format!("{kind}, not a regular file")),
            "{error}"
        );
    }
    for (kind, buffer) in specials(dir.path(), "quad.bin") {
        let path = quad_gltf(buffer.parent().unwrap(), "quad.bin", None, |_| {});
        let error = gltf(path).unwrap_err().to_string();
        assert!(
            error.contains(&buffer.display().to_string())
                && error.contains(&format!("{kind}, not a regular file")),
            "{error}"
        );
    }
    // A file URI straight to the device.
    let path = quad_gltf(dir.path(), "file:///dev/zero", None, |_| {});
    let error = gltf(path).unwrap_err().to_string();
    assert!(
        error.contains("/dev/zero: a character device, not a regular file"),
        "{error}"
    );
}

#[test]
fn a_gltf_image_that_is_a_device_or_a_fifo_is_not_read_and_says_why() {
    let dir = tempfile::tempdir().unwrap();
    let mut cases: Vec<(&str, PathBuf, String)> = specials(dir.path(), "wood.png")
        .into_iter()
        .map(|(kind, image)| (kind, image, "wood.png".to_owned()))
        .collect();
    let zero = dir.path().join("direct");
    std::fs::create_dir_all(&zero).unwrap();
    cases.push((
        "a character device",
        zero.join("x"),
        "file:///dev/zero".to_owned(),
    ));
    for (kind, image, uri) in cases {
        let folder = image.parent().unwrap();
        let path = quad_gltf(folder, "quad.bin", Some(&uri), |_| {});
        let imported = gltf(path).expect("the scene loads");
        assert!(imported.scene.textures.is_empty());
        let warnings: Vec<String> = imported.warnings.iter().map(|w| w.to_string()).collect();
        let named = if uri.starts_with("file:") {
            "/dev/zero".to_owned()
        } else {
            image.display().to_string()
        };
        assert!(
            warnings
                .iter()
                .any(|w| w.contains(&named) && w.contains(&format!("{kind}, not a regular file"))),
            "{warnings:?}"
        );
    }
}

/// The index accessor claims 9 indices where its view holds 6: the
/// `gltf` crate's reader reads it as absent, which drew the quad's four
/// vertices unindexed.
#[test]
fn an_index_accessor_that_overruns_its_view_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let good = quad_gltf(dir.path(), "quad.bin", None, |_| {});
    let scene = gltf(good).expect("the consistent quad loads").scene;
    assert_eq!(scene.triangles.len(), 2);
    let path = quad_gltf(dir.path(), "quad.bin", None, |json| {
        json["accessors"][1]["count"] = serde_json::json!(9);
    });
    let error = gltf(path.clone()).unwrap_err();
    assert!(matches!(error, GltfError::Invalid { .. }), "{error:?}");
    let message = error.to_string();
    assert!(
        message.starts_with(&path.display().to_string())
            && message.contains("mesh 0 primitive 0: accessor 1 (9 elements of 2 bytes")
            && message.contains("needs 18 bytes of buffer view 1, which holds 12"),
        "{message}"
    );
    // A view beyond its buffer.
    let path = quad_gltf(dir.path(), "quad.bin", None, |json| {
        json["bufferViews"][1]["byteLength"] = serde_json::json!(40);
        json["buffers"][0]["byteLength"] = serde_json::json!(60);
    });
    let message = gltf(path).unwrap_err().to_string();
    assert!(
        message.contains("accessor 1: its buffer view 1 ends at byte 88 of buffer 0"),
        "{message}"
    );
}

#[test]
fn accessors_whose_counts_disagree_with_the_primitive_are_errors_naming_them() {
    let dir = tempfile::tempdir().unwrap();
    // Normals for three of the four vertices.
    let path = quad_gltf(dir.path(), "quad.bin", None, |json| {
        let normals = serde_json::json!(
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"});
        json["accessors"].as_array_mut().unwrap().push(normals);
        json["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = serde_json::json!(2);
    });
    let message = gltf(path).unwrap_err().to_string();
    assert!(
        message.contains("accessor 2 (Normals) has 3 elements, the POSITION accessor 0 has 4"),
        "{message}"
    );
    // Four indices: not a whole number of triangles.
    let path = quad_gltf(dir.path(), "quad.bin", None, |json| {
        json["accessors"][1]["count"] = serde_json::json!(4);
    });
    let message = gltf(path).unwrap_err().to_string();
    assert!(
        message.contains("accessor 1 (indices) has 4 elements, not a whole number of triangles"),
        "{message}"
    );
    // An index past the last vertex.
    let path = quad_gltf(dir.path(), "quad.bin", None, |json| {
        json["accessors"][0]["count"] = serde_json::json!(3);
        json["accessors"][0]["max"] = serde_json::json!([1, 1, 0]);
    });
    let message = gltf(path).unwrap_err().to_string();
    assert!(
        message.contains("accessor 1 (indices) names vertex 3, the POSITION accessor 0 has 3"),
        "{message}"
    );
}
