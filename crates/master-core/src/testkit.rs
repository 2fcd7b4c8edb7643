//! A tiny job for the parts' unit tests: a square of two reflector
//! triangles filling a 4 × 4 frame.

use std::sync::Arc;

use glam::Vec3;
use vtfarm_method::MethodKind;
use vtfarm_proto::{JobOptions, SceneData, SceneHash, WireJob, wire_job};
use vtfarm_render::FrameSetup;
use vtfarm_scene::{Camera, Material, MaterialId, Object, Scene, Triangle, TriangleId};

/// Pixels on a side of the test frames.
pub(crate) const SIDE: u32 = 4;

/// A unit square at z = 1 facing the eye at the origin: two triangles.
pub(crate) fn scene() -> Scene {
    let positions = vec![
        Vec3::new(-1.0, -1.0, 1.0),
        Vec3::new(1.0, -1.0, 1.0),
        Vec3::new(1.0, 1.0, 1.0),
        Vec3::new(-1.0, 1.0, 1.0),
    ];
    let triangle = |vertices| Triangle {
        vertices,
        object: vtfarm_scene::ObjectId(0),
        material: MaterialId(0),
    };
    Scene {
        normals: vec![Vec3::NEG_Z; positions.len()],
        positions,
        triangles: vec![triangle([0, 1, 2]), triangle([0, 2, 3])],
        objects: vec![Object {
            name: "glass".into(),
        }],
        materials: vec![Material::default()],
        ..Scene::default()
    }
}

/// A frame looking at the square, `SIDE` pixels on a side.
pub(crate) fn frame() -> FrameSetup {
    FrameSetup {
        camera: Camera {
            eye: Vec3::ZERO,
            target: Vec3::Z,
            up: Vec3::Y,
            fov_y_deg: 90.0,
            width: SIDE,
            height: SIDE,
        },
        lighting: Default::default(),
        trace: Default::default(),
        vertex: Default::default(),
    }
}

/// A job of `frames` frames of the square, both triangles reflectors; its
/// scene parsed and its hash.
pub(crate) fn job(frames: usize) -> (WireJob, Arc<Scene>, SceneHash) {
    let scene = scene();
    let data = SceneData::from_scene(&scene);
    let options = JobOptions {
        method: MethodKind::VertexTracing,
        aux: false,
    };
    let job = wire_job(
        "square",
        &data,
        &vec![frame(); frames],
        &[0, 1].map(TriangleId),
        options,
    );
    (job, Arc::new(scene), data.hash)
}
