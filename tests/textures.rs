//! Textures from OBJ/MTL end to end: a textured wall seen directly (the
//! rasterized base frame), in a floor mirror (traced shading) and through a
//! pane of thin glass (the rasterized transmission) shows the texture's
//! colours where ray geometry says it must, the scene travels to
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
o pane
usemtl glass
v -1.5 1.1 -2
v -0.2 1.1 -2
v -0.2 2 -2
v -1.5 2 -2
f 9 10 11
f 9 11 12
";

const MTL: &str = "newmtl wall
Ka 1 1 1
Kd 1 1 1
map_Kd wall.png
newmtl mirror
Ka 0 0 0
Kd 0 0 0
Kr 1 1 1
newmtl glass
Ka 0 0 0
Kd 0 0 0
Kr 0 0 0
d 0.5
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
objects = ["mirror", "pane"]
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

/// How a pixel sees the wall.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Seen {
    Directly,
    InTheMirror,
    ThroughGlass,
}

/// The colour pixel (x, y) must have, seen directly, in the floor mirror
/// (an ideal mirror: the ambient-lit texel itself) or through the pane
/// (transmittance 0.5, no refraction: it has no `Ni`), where the texture is
/// flat around the point: `None` near a quadrant's or the pane's edge, or
/// off the wall.
fn expected(x: u32, y: u32) -> Option<(Vec3, Seen)> {
    let camera = camera();
    let d = Projector::new(&camera).pixel_ray(x, y);
    let floor = (d.y < 0.0).then(|| camera.eye + d * (-camera.eye.y / d.y));
    let pane = camera.eye + d * ((-2.0 - camera.eye.z) / d.z);
    let inside = |v: f32, lo: f32, hi: f32| v > lo + 0.05 && v < hi - 0.05;
    let near = |v: f32, lo: f32, hi: f32| v > lo - 0.05 && v < hi + 0.05;
    let on_pane = inside(pane.x, -1.5, -0.2) && inside(pane.y, 1.1, 2.0);
    if near(pane.x, -1.5, -0.2) && near(pane.y, 1.1, 2.0) && !on_pane {
        return None;
    }
    let (uv, seen) = match floor {
        Some(p) if p.x.abs() < 4.0 && (-4.0..0.5).contains(&p.z) => {
            let up = Vec3::new(d.x, -d.y, d.z);
            // The reflected ray must not pass the pane.
            let q = p + up * ((-2.0 - p.z) / up.z);
            if p.z > -2.0 && near(q.x, -1.5, -0.2) && near(q.y, 1.1, 2.0) {
                return None;
            }
            (wall_uv(p, up)?, Seen::InTheMirror)
        }
        _ if on_pane => (wall_uv(camera.eye, d)?, Seen::ThroughGlass),
        _ => (wall_uv(camera.eye, d)?, Seen::Directly),
    };
    let (u, v) = uv;
    let margin = |t: f32| [0.0, 0.5, 1.0].iter().all(|edge| (t - edge).abs() > 0.1);
    if !(margin(u) && margin(v)) {
        return None;
    }
    let quadrant = QUADRANTS[usize::from(v < 0.5) * 2 + usize::from(u >= 0.5)];
    let linear = quadrant.map(|c| vtfarm_imaging::srgb_to_linear(f32::from(c) / 255.0));
    let weight = if seen == Seen::ThroughGlass { 0.5 } else { 1.0 };
    Some((Vec3::from_array(linear) * weight, seen))
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

fn reflector_triangles(scene: &Scene) -> Vec<TriangleId> {
    let chosen = [scene.object_id("mirror"), scene.object_id("pane")].map(Option::unwrap);
    scene
        .triangle_ids()
        .filter(|&t| chosen.contains(&scene.triangles[t.index()].object))
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

    let renderer = Renderer::new(Arc::new(scene.clone()), reflector_triangles(&scene));
    let image = renderer
        .render(&setup(), &Default::default(), &mut |_, _| {})
        .image
        .color;
    let mut checked = std::collections::BTreeMap::new();
    for y in 0..48 {
        for x in 0..64 {
            let Some((colour, seen)) = expected(x, y) else {
                continue;
            };
            let got = image.get(x, y);
            assert!(
                (got - colour).abs().max_element() < 1e-4,
                "pixel ({x}, {y}) {seen:?}: {got}, expected {colour}"
            );
            *checked.entry(format!("{seen:?}")).or_insert(0) += 1;
        }
    }
    let count = |seen: Seen| checked.get(&format!("{seen:?}")).copied().unwrap_or(0);
    assert!(
        count(Seen::Directly) > 200
            && count(Seen::InTheMirror) > 100
            && count(Seen::ThroughGlass) > 20,
        "pixels checked: {checked:?}"
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
    let wall = &scene.materials[scene.material_id("wall").unwrap().index()];
    assert_eq!((wall.diffuse, wall.diffuse_texture), (Vec3::ONE, None));
}
