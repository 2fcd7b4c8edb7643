//! Textures from OBJ/MTL end to end: a textured wall seen directly (the
//! rasterized base frame) and in a floor mirror (traced shading) shows the
//! texture's colours where ray geometry says it must, the scene travels to
//! the farm's workers textures included, and `vtfarm render` (the farm)
//! writes exactly the single-process image's bytes.

use std::path::Path;
use std::process::Command;
use std::sync::Arc;

use glam::Vec3;
use vtfarm_method::FrameSetup;
use vtfarm_proto::SceneData;
use vtfarm_render::Renderer;
use vtfarm_scene::obj::{ObjOptions, import_obj};
use vtfarm_scene::{Camera, Lighting, Projector, Scene, TriangleId};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{Quality, VertexSettings};

/// The texture's four quadrants (sRGB bytes): top left, top right, bottom
/// left, bottom right.
const QUADRANTS: [[u8; 3]; 4] = [[200, 30, 30], [30, 200, 30], [30, 30, 200], [220, 220, 40]];

/// An 8×8 PNG of four 4×4 quadrants.
fn write_texture(path: &Path) {
    let image = image::RgbImage::from_fn(8, 8, |x, y| {
        image::Rgb(QUADRANTS[(usize::from(y >= 4) * 2) + usize::from(x >= 4)])
    });
    image.save(path).unwrap();
}

const OBJ: &str = "mtllib scene.mtl
o wall
usemtl wall
v -4 0 -4
v 4 0 -4
v 4 4 -4
v -4 4 -4
vt 0 0
vt 1 0
vt 1 1
vt 0 1
f 1/1 2/2 3/3
f 1/1 3/3 4/4
o mirror
usemtl mirror
v -4 0 0.5
v 4 0 0.5
v 4 0 -4
v -4 0 -4
f 5 6 7
f 5 7 8
";

const MTL: &str = "newmtl wall
Ka 1 1 1
Kd 1 1 1
map_Kd wall.png
newmtl mirror
Ka 0 0 0
Kd 0 0 0
Kr 1 1 1
";

const JOB: &str = r#"
[scene]
obj = "scene.obj"
[camera]
eye = [0, 1, 0]
target = [0, 0.6, -4]
fov_y = 60
width = 64
height = 48
[lighting]
lights = []
ambient = [1, 1, 1]
background = [0, 0, 0]
[reflectors]
objects = ["mirror"]
[quality]
level = "full"
"#;

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

/// The texture coordinates where the ray from `origin` along `d` meets the
/// wall (z = -4, x and y within it), if it does.
fn wall_uv(origin: Vec3, d: Vec3) -> Option<(f32, f32)> {
    if d.z >= 0.0 {
        return None;
    }
    let p = origin + d * ((-4.0 - origin.z) / d.z);
    (p.x.abs() < 4.0 && (0.0..4.0).contains(&p.y)).then_some(((p.x + 4.0) / 8.0, p.y / 4.0))
}

/// The colour pixel (x, y) must have, seen directly or in the floor mirror
/// (an ideal mirror: the ambient-lit texel itself), where the texture is
/// flat around the point: `None` near a quadrant's edge or off the wall.
fn expected(x: u32, y: u32) -> Option<(Vec3, bool)> {
    let camera = camera();
    let d = Projector::new(&camera).pixel_ray(x, y);
    let floor = (d.y < 0.0).then(|| camera.eye + d * (-camera.eye.y / d.y));
    let (uv, mirrored) = match floor {
        Some(p) if p.x.abs() < 4.0 && (-4.0..0.5).contains(&p.z) => {
            (wall_uv(p, Vec3::new(d.x, -d.y, d.z))?, true)
        }
        _ => (wall_uv(camera.eye, d)?, false),
    };
    let (u, v) = uv;
    let margin = |t: f32| [0.0, 0.5, 1.0].iter().all(|edge| (t - edge).abs() > 0.1);
    if !(margin(u) && margin(v)) {
        return None;
    }
    let quadrant = QUADRANTS[usize::from(v < 0.5) * 2 + usize::from(u >= 0.5)];
    let linear = quadrant.map(|c| vtfarm_imaging::srgb_to_linear(f32::from(c) / 255.0));
    Some((Vec3::from_array(linear), mirrored))
}

fn setup() -> FrameSetup {
    FrameSetup {
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
    }
}

fn mirror_triangles(scene: &Scene) -> Vec<TriangleId> {
    let mirror = scene.object_id("mirror").unwrap();
    (0..scene.triangles.len() as TriangleId)
        .filter(|&t| scene.triangles[t as usize].object == mirror)
        .collect()
}

#[test]
fn a_textured_wall_shows_its_texels_directly_in_a_mirror_and_through_the_farm() {
    let dir = tempfile::tempdir().unwrap();
    write_texture(&dir.path().join("wall.png"));
    std::fs::write(dir.path().join("scene.obj"), OBJ).unwrap();
    std::fs::write(dir.path().join("scene.mtl"), MTL).unwrap();
    std::fs::write(dir.path().join("job.toml"), JOB).unwrap();
    let imported = import_obj(&dir.path().join("scene.obj"), &ObjOptions::default()).unwrap();
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let scene = imported.scene;
    assert_eq!(scene.textures.len(), 1);
    assert_eq!(scene.corner_uvs.len(), scene.triangles.len());

    let renderer = Renderer::new(Arc::new(scene.clone()), mirror_triangles(&scene));
    let image = renderer
        .render(&setup(), &Default::default(), &mut |_, _| {})
        .image
        .color;
    let (mut direct, mut mirrored) = (0, 0);
    for y in 0..48 {
        for x in 0..64 {
            let Some((colour, in_mirror)) = expected(x, y) else {
                continue;
            };
            let got = image.get(x, y);
            assert!(
                (got - colour).abs().max_element() < 1e-4,
                "pixel ({x}, {y}) {}: {got}, expected {colour}",
                if in_mirror { "in the mirror" } else { "direct" }
            );
            if in_mirror {
                mirrored += 1;
            } else {
                direct += 1;
            }
        }
    }
    assert!(
        direct > 200 && mirrored > 100,
        "{direct} direct, {mirrored} mirrored pixels checked"
    );

    // The workers get the scene textures included, as the submitter has it.
    let data = SceneData::from_scene(&scene);
    assert_eq!(data.to_scene().unwrap(), scene);

    // `vtfarm render` (the embedded farm) writes the single-process image.
    let png = dir.path().join("farm.png");
    let out = Command::new(env!("CARGO_BIN_EXE_vtfarm"))
        .args([
            "render",
            dir.path().join("job.toml").to_str().unwrap(),
            "-o",
        ])
        .arg(&png)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let farm = image::open(&png).unwrap().to_rgb8().into_raw();
    assert_eq!(farm, image.to_srgb8(), "the farm's image differs");
}

#[test]
fn a_missing_texture_is_a_warning_at_its_line_and_the_colour_stays_flat() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("scene.obj"), OBJ).unwrap();
    std::fs::write(dir.path().join("scene.mtl"), MTL).unwrap();
    let imported = import_obj(&dir.path().join("scene.obj"), &ObjOptions::default()).unwrap();
    let [warning] = &imported.warnings[..] else {
        panic!("{:?}", imported.warnings)
    };
    let message = warning.to_string();
    assert!(
        message.starts_with(&format!("{}:4:", dir.path().join("scene.mtl").display()))
            && message.contains("wall.png")
            && message.contains("flat colour"),
        "{message}"
    );
    let scene = imported.scene;
    let wall = &scene.materials[scene.material_id("wall").unwrap() as usize];
    assert_eq!((wall.diffuse, wall.diffuse_texture), (Vec3::ONE, None));
}
