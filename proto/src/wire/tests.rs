//! Fixtures the wire's tests share (a small scene, camera, lighting and
//! bitmap; round trips and rejections), and the tests of the shared checks.

use glam::Vec3;
use proptest::prelude::*;
use vtfarm_scene::{
    Camera, Light, LightKind, Lighting, Material, MaterialId, Object, Scene, Triangle, TriangleId,
};
use vtfarm_vertex::SparseBitmap;

use super::{WireError, check_triangle_ids};

pub(crate) fn material(name: &str) -> Material {
    Material {
        name: name.to_owned(),
        ambient: Vec3::new(0.1, 0.2, 0.3),
        diffuse: Vec3::new(0.4, 0.5, 0.6),
        specular: Vec3::splat(0.25),
        shininess: 32.0,
        emission: Vec3::new(0.0, 0.5, 0.0),
        reflectance: Vec3::splat(0.9),
        transmittance: Vec3::splat(0.1),
        ior: 1.5,
        ..Default::default()
    }
}

/// Two triangles in two objects with two materials.
pub(crate) fn scene() -> Scene {
    Scene {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, -0.5)],
        normals: vec![Vec3::Z; 4],
        triangles: vec![
            Triangle {
                vertices: [0, 1, 2],
                object: vtfarm_scene::ObjectId(0),
                material: MaterialId(0),
            },
            Triangle {
                vertices: [1, 3, 2],
                object: vtfarm_scene::ObjectId(1),
                material: MaterialId(1),
            },
        ],
        objects: vec![
            Object {
                name: "glass".to_owned(),
            },
            Object {
                name: "dash".to_owned(),
            },
        ],
        materials: vec![material("mirror"), Material::default()],
        ..Default::default()
    }
}

pub(crate) fn camera() -> Camera {
    Camera {
        eye: Vec3::new(0.0, 1.0, 3.0),
        target: Vec3::new(0.2, 0.5, 0.0),
        up: Vec3::Y,
        fov_y_deg: 45.0,
        width: 64,
        height: 48,
    }
}

pub(crate) fn lighting() -> Lighting {
    Lighting {
        lights: vec![
            Light {
                kind: LightKind::Point {
                    position: Vec3::new(1.0, 2.0, 3.0),
                },
                color: Vec3::ONE,
                intensity: 0.8,
            },
            Light {
                kind: LightKind::Directional {
                    direction: Vec3::new(0.0, -1.0, -1.0),
                    angular_diameter_deg: vtfarm_scene::SUN_ANGULAR_DIAMETER_DEG,
                },
                color: Vec3::new(1.0, 0.9, 0.8),
                intensity: 0.5,
            },
        ],
        ambient: Vec3::splat(0.05),
        background: Vec3::new(0.2, 0.3, 0.9),
    }
}

/// A 5 × 3 rectangle (15 mask bits: not a multiple of 8) with 4 covered pixels.
pub(crate) fn bitmap() -> SparseBitmap {
    let mut mask = vec![false; 15];
    for i in [0, 6, 7, 14] {
        mask[i] = true;
    }
    SparseBitmap {
        x0: 3,
        y0: 2,
        width: 5,
        height: 3,
        mask,
        color: vec![Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE],
        reflected: vec![Vec3::ZERO, Vec3::splat(0.5), Vec3::ZERO, Vec3::splat(0.25)],
        transmitted: vec![Vec3::ONE, Vec3::splat(0.125), Vec3::X, Vec3::ZERO],
        reflected_object: vec![0, vtfarm_scene::NONE, 1, 0],
    }
}

pub(crate) fn round_trip<D, W>(value: &D) -> D
where
    for<'a> W: From<&'a D>,
    D: TryFrom<W, Error = WireError>,
{
    D::try_from(W::from(value)).expect("a domain value converts back")
}

/// Applies `damage` to a valid wire value and expects the conversion to
/// fail with a message containing `expected`.
pub(crate) fn check_rejects<W: Clone, D: TryFrom<W, Error = WireError> + std::fmt::Debug>(
    valid: &W,
    damage: impl FnOnce(&mut W),
    expected: &str,
) {
    let mut w = valid.clone();
    damage(&mut w);
    let message = D::try_from(w).expect_err(expected).to_string();
    assert!(message.contains(expected), "{message:?} lacks {expected:?}");
}

pub(crate) fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        Just(f32::NAN),
        Just(f32::INFINITY),
        Just(0.0f32),
        -2.0f32..2.0
    ]
}

#[test]
fn triangle_id_lists_are_checked_against_the_scene() {
    assert_eq!(
        check_triangle_ids("reflectors", &[2, 0, 1], 3).unwrap(),
        [2, 0, 1].map(TriangleId)
    );
    let error = check_triangle_ids("reflectors", &[0, 3], 3).expect_err("3 of 3");
    assert_eq!(
        error.to_string(),
        "reflectors[1] = 3 is out of range (there are 3)"
    );
    let error = check_triangle_ids("package", &[1, 1], 3).expect_err("duplicate");
    assert_eq!(error.to_string(), "package lists 1 twice");
}
