//! Mip levels in every shading path: a checkerboard of one-texel squares,
//! several texels to a pixel, averages to its mean colour seen directly
//! (the rasterized base frame), in a floor mirror (traced shading, the
//! footprint of `vtfarm_trace::PixelCone`) and through a pane of thin
//! glass (the rasterized transmission), instead of aliasing to whatever
//! texel a pixel centre meets.

use std::sync::Arc;

use glam::{Vec2, Vec3};
use vtfarm_render::{FrameSetup, Renderer};
use vtfarm_scene::texture::Texture;
use vtfarm_scene::{Camera, Lighting, Material, Object, Projector, Scene, Triangle, TriangleId};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{Quality, VertexSettings};

/// Texels of the checkerboard per side, and how often it repeats on the
/// wall: 64 texels to the metre.
const TEXELS: u32 = 64;
const REPEATS: f32 = 80.0;
const WALL: f32 = 40.0;

fn checkerboard() -> Texture {
    let rgba: Vec<u8> = (0..TEXELS * TEXELS)
        .flat_map(|i| {
            let white = (i % TEXELS + i / TEXELS) % 2 == 0;
            let c = if white { 255 } else { 0 };
            [c, c, c, 255]
        })
        .collect();
    Texture::from_rgba8("checker", TEXELS, TEXELS, rgba).unwrap()
}

/// The checkerboard's mean in linear light, as its mip levels hold it
/// (8-bit sRGB): every level from 1 on is uniformly this grey.
fn mean() -> f32 {
    let grey = vtfarm_imaging::encode_srgb8(Vec3::splat(0.5))[0];
    vtfarm_imaging::srgb_to_linear(f32::from(grey) / 255.0)
}

/// A wall at z = -4 (textured, lit by the ambient light alone), a floor
/// mirror in front of it and a pane of thin glass (transmittance 0.5) in
/// between.
fn scene() -> Scene {
    let mut scene = Scene {
        textures: vec![checkerboard()],
        ..Scene::default()
    };
    let wall = Material {
        ambient: Vec3::ONE,
        diffuse: Vec3::ONE,
        diffuse_texture: Some(0),
        ..Material::diffuse("wall", Vec3::ONE)
    };
    let mirror = Material {
        reflectance: Vec3::ONE,
        ..Material::diffuse("mirror", Vec3::ZERO)
    };
    let glass = Material {
        transmittance: Vec3::splat(0.5),
        ..Material::diffuse("glass", Vec3::ZERO)
    };
    let quads = [
        (
            "wall",
            wall,
            [
                Vec3::new(-WALL, 0.0, -4.0),
                Vec3::new(WALL, 0.0, -4.0),
                Vec3::new(WALL, WALL, -4.0),
                Vec3::new(-WALL, WALL, -4.0),
            ],
        ),
        (
            "mirror",
            mirror,
            [
                Vec3::new(-WALL, 0.0, 0.5),
                Vec3::new(WALL, 0.0, 0.5),
                Vec3::new(WALL, 0.0, -4.0),
                Vec3::new(-WALL, 0.0, -4.0),
            ],
        ),
        (
            "pane",
            glass,
            [
                Vec3::new(-1.5, 1.1, -2.0),
                Vec3::new(-0.2, 1.1, -2.0),
                Vec3::new(-0.2, 2.0, -2.0),
                Vec3::new(-1.5, 2.0, -2.0),
            ],
        ),
    ];
    let uvs = [Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y].map(|uv| uv * REPEATS);
    for (id, (name, material, corners)) in quads.into_iter().enumerate() {
        let id = id as u32;
        let base = scene.positions.len() as u32;
        let normal = (corners[1] - corners[0])
            .cross(corners[3] - corners[0])
            .normalize();
        scene.positions.extend(corners);
        scene.normals.extend([normal; 4]);
        scene.objects.push(Object { name: name.into() });
        scene.materials.push(material);
        for [a, b, c] in [[0, 1, 2], [0, 2, 3]] {
            scene.triangles.push(Triangle {
                vertices: [a, b, c].map(|v| base + v),
                object: vtfarm_scene::ObjectId(id),
                material: vtfarm_scene::MaterialId(id),
            });
            scene
                .corner_uvs
                .push([uvs[a as usize], uvs[b as usize], uvs[c as usize]]);
        }
    }
    scene.validate().unwrap();
    scene
}

fn camera() -> Camera {
    Camera {
        eye: Vec3::new(0.0, 1.0, 0.0),
        target: Vec3::new(0.0, 0.6, -4.0),
        up: Vec3::Y,
        fov_y_deg: 60.0,
        width: 64,
        height: 48,
    }
}

/// How a pixel sees the wall, and the share of its colour that arrives;
/// `None` near the pane's edges (directly or in the mirror), where a pixel
/// may take either side.
fn seen(x: u32, y: u32) -> Option<(&'static str, f32)> {
    let camera = camera();
    let d = Projector::new(&camera).pixel_ray(x, y);
    let on_pane = |origin: Vec3, d: Vec3, margin: f32| {
        let p = origin + d * ((-2.0 - origin.z) / d.z);
        p.x > -1.5 - margin && p.x < -0.2 + margin && p.y > 1.1 - margin && p.y < 2.0 + margin
    };
    let (origin, d, kind) = if d.y < 0.0 && (camera.eye + d * (-1.0 / d.y)).z > -4.0 {
        let floor = camera.eye + d * (-1.0 / d.y);
        (floor, Vec3::new(d.x, -d.y, d.z), "in the mirror")
    } else {
        (camera.eye, d, "directly")
    };
    // The pane lies between the eye (or the floor behind it) and the wall.
    let crosses = origin.z > -2.0;
    match (
        crosses && on_pane(origin, d, 0.05),
        crosses && on_pane(origin, d, -0.05),
    ) {
        (true, false) => None,
        (_, true) => Some((
            if kind == "directly" {
                "through the glass"
            } else {
                kind
            },
            0.5,
        )),
        _ => Some((kind, 1.0)),
    }
}

#[test]
fn a_minified_checkerboard_averages_to_its_mean_in_every_shading_path() {
    let scene = scene();
    let reflectors: Vec<TriangleId> = (2..6).map(TriangleId).collect();
    let renderer = Renderer::new(Arc::new(scene), reflectors);
    let setup = FrameSetup {
        camera: camera(),
        lighting: Lighting {
            lights: vec![],
            ambient: Vec3::ONE,
            background: Vec3::ZERO,
        },
        trace: TraceSettings::default(),
        vertex: VertexSettings {
            quality: Quality::Full,
            ..VertexSettings::default()
        },
    };
    let image = renderer
        .render(&setup, &Default::default(), &mut |_, _| {})
        .image
        .color;
    let mut checked = std::collections::BTreeMap::new();
    for y in 0..48 {
        for x in 0..64 {
            let Some((kind, share)) = seen(x, y) else {
                continue;
            };
            let expected = Vec3::splat(mean() * share);
            let got = image.get(x, y);
            assert!(
                (got - expected).abs().max_element() < 2e-3,
                "pixel ({x}, {y}) {kind}: {got}, the mean is {expected}"
            );
            *checked.entry(kind).or_insert(0) += 1;
        }
    }
    let count = |kind| checked.get(kind).copied().unwrap_or(0);
    assert!(
        count("directly") > 500 && count("in the mirror") > 500 && count("through the glass") > 30,
        "pixels checked: {checked:?}"
    );
}
