//! Real scenes: a corpus of small generated OBJ/MTL files, each with one quirk
//! exporters produce, loads (or is refused with file and line) and renders;
//! and the reflected-object maps of `reference` and `full` agree with a
//! brute-force f64 reflection check (no BVH) on generated scenes, including
//! a 500-unit scene with 1-unit details and glass.

use std::fmt::Write as _;
use std::path::Path;
use std::sync::Arc;

use glam::{DVec3, Vec3};
use vtfarm_raster::IdBuffer;
use vtfarm_render::{FrameSetup, RenderOptions, Renderer};
use vtfarm_scene::obj::{ObjOptions, import_obj};
use vtfarm_scene::{Camera, Light, LightKind, Lighting, NONE, Scene, TriangleId};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{Quality, VertexSettings};

/// An OBJ file being written: vertices are numbered as they are added.
#[derive(Default)]
struct Obj {
    text: String,
    vertices: usize,
}

impl Obj {
    fn line(&mut self, line: &str) -> &mut Self {
        self.text.push_str(line);
        self.text.push('\n');
        self
    }

    /// A `nu` × `nv` grid of quads spanning `u` and `v` from `corner`.
    fn grid(&mut self, corner: Vec3, u: Vec3, v: Vec3, nu: usize, nv: usize) -> &mut Self {
        let first = self.vertices + 1;
        for j in 0..=nv {
            for i in 0..=nu {
                let p = corner + u * (i as f32 / nu as f32) + v * (j as f32 / nv as f32);
                let _ = writeln!(self.text, "v {} {} {}", p.x, p.y, p.z);
            }
        }
        self.vertices += (nu + 1) * (nv + 1);
        let at = |i: usize, j: usize| first + j * (nu + 1) + i;
        for j in 0..nv {
            for i in 0..nu {
                let _ = writeln!(
                    self.text,
                    "f {} {} {} {}",
                    at(i, j),
                    at(i + 1, j),
                    at(i + 1, j + 1),
                    at(i, j + 1)
                );
            }
        }
        self
    }

    /// An axis-aligned box.
    fn cuboid(&mut self, lo: Vec3, hi: Vec3) -> &mut Self {
        let d = hi - lo;
        let (x, y, z) = (Vec3::X * d.x, Vec3::Y * d.y, Vec3::Z * d.z);
        self.grid(lo, y, x, 1, 1)
            .grid(lo + z, x, y, 1, 1)
            .grid(lo, z, y, 1, 1)
            .grid(lo + x, y, z, 1, 1)
            .grid(lo, x, z, 1, 1)
            .grid(lo + y, z, x, 1, 1)
    }

    /// A UV sphere (quads and pole triangles).
    fn sphere(&mut self, centre: Vec3, radius: f32, rings: usize, segments: usize) -> &mut Self {
        let first = self.vertices + 1;
        for r in 0..=rings {
            let theta = std::f32::consts::PI * r as f32 / rings as f32;
            for s in 0..segments {
                let phi = std::f32::consts::TAU * s as f32 / segments as f32;
                let p = centre
                    + radius
                        * Vec3::new(
                            theta.sin() * phi.cos(),
                            theta.cos(),
                            -theta.sin() * phi.sin(),
                        );
                let _ = writeln!(self.text, "v {} {} {}", p.x, p.y, p.z);
            }
        }
        self.vertices += (rings + 1) * segments;
        let at = |r: usize, s: usize| first + r * segments + s % segments;
        for r in 0..rings {
            for s in 0..segments {
                let (a, b, c, d) = (at(r, s), at(r + 1, s), at(r + 1, s + 1), at(r, s + 1));
                match r {
                    0 => writeln!(self.text, "f {a} {b} {c}"),
                    _ if r == rings - 1 => writeln!(self.text, "f {a} {b} {d}"),
                    _ => writeln!(self.text, "f {a} {b} {c} {d}"),
                }
                .unwrap();
            }
        }
        self
    }
}

const MTL: &str = "\
newmtl tunnel
Kd 0.5 0.5 0.45
newmtl red
Kd 0.8 0.1 0.1
newmtl green
Kd 0.1 0.8 0.1
newmtl blue
Kd 0.1 0.1 0.8
newmtl lamp
Kd 1 1 1
Ke 4 4 4
newmtl glass
Kd 0.02 0.02 0.02
Ks 0.5 0.5 0.5
Ni 1.5
d 0.2
illum 4
newmtl mirror
Kd 0.05 0.05 0.05
Ks 0.9 0.9 0.9
illum 3
";

/// The quirk-free core every scene shares: a windshield (`glass`, tilted
/// towards the camera) and 1-unit details above and behind the camera that
/// it mirrors, all at the origin, grouped with `o` or named by `usemtl`.
fn details(obj: &mut Obj, groups: bool) {
    let object = |obj: &mut Obj, name: &str, material: &str| {
        if groups {
            obj.line(&format!("o {name}"));
        }
        obj.line(&format!("usemtl {material}"));
    };
    object(obj, "windshield", "glass");
    let n = Vec3::new(0.0, 0.5, -1.0).normalize();
    let u = Vec3::X * 1.2;
    let v = n.cross(Vec3::X) * 0.8;
    obj.grid(-u * 0.5 - v * 0.5, u, v, 6, 4);
    // Boxes 2 cm apart, thin poles: sharp reflected edges everywhere.
    for (i, material) in ["red", "green", "blue", "red", "green"].iter().enumerate() {
        object(obj, &format!("box{i}"), material);
        let x = -0.6 + 0.24 * i as f32;
        obj.cuboid(Vec3::new(x, 0.9, -1.4), Vec3::new(x + 0.22, 1.2, -1.1));
    }
    object(obj, "poles", "blue");
    for i in 0..6 {
        let x = -0.5 + 0.2 * i as f32;
        obj.cuboid(Vec3::new(x, 1.2, -1.6), Vec3::new(x + 0.02, 1.7, -1.58));
    }
}

/// The 500-unit tunnel around the details: huge floor, wall and ceiling
/// triangles, and lamps along it.
fn tunnel(obj: &mut Obj, groups: bool) {
    if groups {
        obj.line("o tunnel");
    }
    obj.line("usemtl tunnel");
    let (w, h, l) = (6.0, 6.0, 240.0);
    obj.grid(
        Vec3::new(-w, -0.6, -l),
        Vec3::X * 2.0 * w,
        Vec3::Z * 2.0 * l,
        2,
        4,
    )
    .grid(
        Vec3::new(-w, -0.6, -l),
        Vec3::Z * 2.0 * l,
        Vec3::Y * h,
        4,
        1,
    )
    .grid(Vec3::new(w, -0.6, -l), Vec3::Y * h, Vec3::Z * 2.0 * l, 1, 4)
    .grid(
        Vec3::new(-w, h - 0.6, -l),
        Vec3::Z * 2.0 * l,
        Vec3::X * 2.0 * w,
        4,
        2,
    );
    if groups {
        obj.line("o lamps");
    }
    obj.line("usemtl lamp");
    for i in 0..8 {
        let z = -200.0 + 50.0 * i as f32;
        obj.cuboid(
            Vec3::new(-1.0, h - 0.8, z),
            Vec3::new(1.0, h - 0.6, z + 4.0),
        );
    }
}

fn camera(width: u32, height: u32) -> Camera {
    Camera {
        eye: Vec3::new(0.0, 0.6, -2.2),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 30.0,
        width,
        height,
    }
}

fn lighting() -> Lighting {
    Lighting {
        lights: vec![Light {
            kind: LightKind::Point {
                position: Vec3::new(1.0, 3.0, -3.0),
            },
            color: Vec3::ONE,
            intensity: 1.0,
        }],
        ..Lighting::default()
    }
}

fn setup(camera: Camera, quality: Quality) -> FrameSetup {
    FrameSetup {
        camera,
        lighting: lighting(),
        trace: TraceSettings::default(),
        vertex: VertexSettings {
            quality,
            ..VertexSettings::default()
        },
    }
}

/// Writes `obj` and `mtl` as `name.obj`/`scene.mtl` (plus `files`) into `dir`.
fn write(dir: &Path, name: &str, obj: &str, mtl: &str, files: &[&str]) -> std::path::PathBuf {
    for file in files {
        let path = dir.join(file);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(path, b"P3 1 1 1 1 1 1\n").unwrap();
    }
    std::fs::write(dir.join("scene.mtl"), mtl).unwrap();
    let path = dir.join(format!("{name}.obj"));
    std::fs::write(&path, obj).unwrap();
    path
}

/// The triangles of objects whose material reflects.
fn reflectors(scene: &Scene) -> Vec<TriangleId> {
    scene
        .triangle_ids()
        .filter(|&t| scene.material_of(t).reflectance.max_element() > 0.0)
        .collect()
}

/// What each corpus file does to the shared scene.
enum Quirk {
    /// Text transformed after generation.
    Text(fn(String) -> String),
    /// MTL text transformed.
    Mtl(fn(String) -> String),
    /// Refused at this line, with this message.
    Refused(&'static str),
}

#[test]
fn a_corpus_of_exporter_quirks_loads_and_renders() {
    let crlf: fn(String) -> String = |t| t.replace('\n', "\r\n");
    let corpus: Vec<(&str, bool, Quirk)> = vec![
        ("crlf", true, Quirk::Text(crlf)),
        ("crlf-mtl", true, Quirk::Mtl(crlf)),
        (
            "trailing-spaces",
            true,
            Quirk::Text(|t| t.replace("usemtl glass", "usemtl glass  \t")),
        ),
        (
            "trailing-spaces-mtl",
            true,
            Quirk::Mtl(|t| t.replace("newmtl glass", "newmtl glass   ")),
        ),
        (
            "textures",
            true,
            Quirk::Mtl(|t| {
                t.replace(
                    "newmtl glass\n",
                    "newmtl glass\nmap_Kd textures\\glass_baseColor.png\nmap_Ks tex\\there.ppm\n",
                )
            }),
        ),
        (
            "inline-comments",
            true,
            Quirk::Mtl(|t| {
                t.replace("Ni 1.5", "Ni 1.5 # glass")
                    .replace("Kd 0.1 0.1 0.8", "Kd 0.1 0.1 0.8 # Blue")
            }),
        ),
        ("no-groups", false, Quirk::Text(|t| t)),
        (
            "zero-area",
            true,
            Quirk::Text(|t| {
                t + "o sliver\nusemtl red\nv 0 2 -1\nv 1 2 -1\nv 2 2 -1\nf -1 -2 -3\nf -1 -1 -2\n"
            }),
        ),
        (
            "illum-7",
            true,
            Quirk::Mtl(|t| {
                t.replace("illum 4", "illum 7")
                    .replace("d 0.2", "Tf 0.8 0.9 0.8")
            }),
        ),
        (
            "huge-polygon",
            true,
            Quirk::Text(|mut t| {
                t.push_str("o disc\nusemtl green\n");
                for i in 0..20_000 {
                    let a = std::f32::consts::TAU * i as f32 / 20_000.0;
                    let _ = writeln!(t, "v {} 2.5 {}", a.cos(), a.sin() - 1.5);
                }
                t.push('f');
                for i in 1..=20_000 {
                    let _ = write!(t, " -{i}");
                }
                t + "\n"
            }),
        ),
        ("non-finite", true, Quirk::Refused("v 0 nan 0")),
        ("absurd", true, Quirk::Refused("v 0 1e22 0")),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (name, groups, quirk) in corpus {
        let mut obj = Obj::default();
        obj.line("mtllib scene.mtl");
        details(&mut obj, groups);
        tunnel(&mut obj, groups);
        let (mut text, mut mtl) = (obj.text, MTL.to_owned());
        let mut refused = None;
        match quirk {
            Quirk::Text(f) => text = f(text),
            Quirk::Mtl(f) => mtl = f(mtl),
            Quirk::Refused(line) => {
                refused = Some(text.lines().count() + 1);
                text = format!("{text}{line}\n");
            }
        }
        let path = write(dir.path(), name, &text, &mtl, &["tex/there.ppm"]);
        let imported = import_obj(&path, &ObjOptions::default());
        if let Some(line) = refused {
            let error = imported.unwrap_err().to_string();
            let location = format!("{}:{line}: ", path.display());
            assert!(error.starts_with(&location), "{name}: {error}");
            continue;
        }
        let imported = imported.unwrap_or_else(|e| panic!("{name}: {e}"));
        let scene = imported.scene;
        let windshield = if groups { "windshield" } else { "glass" };
        assert!(
            scene.object_id(windshield).is_some(),
            "{name}: objects named"
        );
        let warnings = imported.warnings.len();
        assert_eq!(warnings, usize::from(name == "textures"), "{name}");
        let glass = scene.material_id("glass").expect("glass keeps its name");
        assert!(
            scene.materials[glass.index()].reflectance.min_element() > 0.03,
            "{name}: glass reflects by Fresnel"
        );

        let reflectors = reflectors(&scene);
        let renderer = Renderer::new(Arc::new(scene), reflectors);
        let frame = renderer.render(
            &setup(camera(64, 48), Quality::Full),
            &RenderOptions::default(),
            &mut |_, _| {},
        );
        let image = frame.image.components();
        let color = frame.image.color;
        let covered = image.mask.iter().filter(|&&m| m).count();
        let mirrored = image
            .reflected_object
            .iter()
            .filter(|&&o| o != NONE)
            .count();
        assert!(covered > 300, "{name}: {covered} reflector pixels");
        assert!(
            mirrored * 2 > covered,
            "{name}: {mirrored} of {covered} mirror something"
        );
        assert!(color.pixels.iter().all(|p| p.is_finite()), "{name}");
    }
}

/// A triangle in f64.
type Triangle64 = [DVec3; 3];

/// Two-sided Möller–Trumbore in f64; edges inclusive.
fn intersect64([a, b, c]: &Triangle64, origin: DVec3, direction: DVec3) -> Option<f64> {
    let (e1, e2) = (*b - *a, *c - *a);
    let p = direction.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-300 {
        return None;
    }
    let s = origin - *a;
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = direction.dot(q) / det;
    if u < 0.0 || v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some(e2.dot(q) / det)
}

/// The object each reflector pixel mirrors, by brute force in f64: the
/// pixel's eye ray meets its triangle's plane, reflects about the
/// barycentric normal (on the incoming side), and the closest of all other
/// triangles along the mirror ray is the answer. `None` off the reflectors.
fn reference_map(
    scene: &Scene,
    camera: &Camera,
    ids: &IdBuffer,
    is_reflector: &[bool],
) -> Vec<Option<u32>> {
    let triangles: Vec<Triangle64> = (scene.triangle_ids())
        .map(|t| scene.triangle_positions(t).map(|p| p.as_dvec3()))
        .collect();
    let eye = camera.eye.as_dvec3();
    (0..ids.triangle.len())
        .map(|i| {
            let own = TriangleId::from_raw(ids.triangle[i])?;
            if !is_reflector[own.index()] {
                return None;
            }
            let (x, y) = (i as u32 % ids.width, i as u32 / ids.width);
            let direction = camera.pixel_ray(x, y).as_dvec3();
            let [a, b, c] = triangles[own.index()];
            let n = (b - a).cross(c - a);
            let point = eye + direction * ((a - eye).dot(n) / direction.dot(n));
            let area = n.length_squared();
            let wa = (c - b).cross(point - b).dot(n) / area;
            let wb = (a - c).cross(point - c).dot(n) / area;
            let [na, nb, nc] = scene.triangle_normals(own).map(|n| n.as_dvec3());
            let normal = (na * wa + nb * wb + nc * (1.0 - wa - wb)).normalize();
            let facing = if normal.dot(direction) > 0.0 {
                -normal
            } else {
                normal
            };
            let mirror = (direction - 2.0 * direction.dot(facing) * facing).normalize();
            let floor = 1e-9 * (1.0 + point.abs().max_element());
            let closest = (0..triangles.len())
                .filter(|&t| t != own.index())
                .filter_map(|t| intersect64(&triangles[t], point, mirror).map(|d| (d, t)))
                .filter(|&(d, _)| d > floor)
                .min_by(|p, q| p.0.total_cmp(&q.0));
            Some(closest.map_or(NONE, |(_, t)| scene.triangles[t].object.raw()))
        })
        .collect()
}

/// The share of reflector pixels whose reflected object at `quality`
/// matches the f64 reference, with the pixel count.
fn agreement(scene: &Arc<Scene>, camera: Camera, quality: Quality) -> (f64, usize) {
    let reflectors = reflectors(scene);
    let renderer = Renderer::new(scene.clone(), reflectors.clone());
    let frame = renderer.render(
        &setup(camera, quality),
        &RenderOptions::default(),
        &mut |_, _| {},
    );
    let mut is_reflector = vec![false; scene.triangles.len()];
    for t in reflectors {
        is_reflector[t.index()] = true;
    }
    let ids = vtfarm_raster::id_buffer(scene, &camera);
    let expected = reference_map(scene, &camera, &ids, &is_reflector);
    let (mut pixels, mut agree) = (0, 0);
    for (i, expected) in expected.iter().enumerate() {
        if let Some(object) = expected {
            pixels += 1;
            agree += usize::from(frame.image.pixel(i).object == *object);
        }
    }
    (agree as f64 / pixels as f64, pixels)
}

/// The generated scenes of the reflection check.
fn check_scenes(dir: &Path) -> Vec<(&'static str, Arc<Scene>)> {
    let mut large = Obj::default();
    large.line("mtllib scene.mtl");
    details(&mut large, true);
    tunnel(&mut large, true);

    // Glass (illum 7 with Ni) and a mirror sphere among the details.
    let mut glass = Obj::default();
    glass.line("mtllib scene.mtl");
    details(&mut glass, true);
    glass.line("o ball\nusemtl mirror");
    glass.sphere(Vec3::new(0.45, 0.15, -0.3), 0.2, 12, 24);
    glass.line("o room\nusemtl tunnel");
    glass.cuboid(Vec3::new(-3.0, -0.6, -4.0), Vec3::new(3.0, 3.0, 3.0));
    let glass_mtl = MTL.replace("illum 4", "illum 7");

    [
        ("large", large.text, MTL.to_owned()),
        ("glass", glass.text, glass_mtl),
    ]
    .into_iter()
    .map(|(name, obj, mtl)| {
        let path = write(dir, name, &obj, &mtl, &[]);
        let scene = import_obj(&path, &ObjOptions::default()).unwrap().scene;
        (name, Arc::new(scene))
    })
    .collect()
}

#[test]
fn reflected_objects_agree_with_a_brute_force_f64_check() {
    let dir = tempfile::tempdir().unwrap();
    let mut figures = Vec::new();
    for (name, scene) in check_scenes(dir.path()) {
        let camera = camera(320, 240);
        let (reference, pixels) = agreement(&scene, camera, Quality::Reference);
        let (full, _) = agreement(&scene, camera, Quality::Full);
        println!("{name}: {pixels} reflector pixels, reference {reference:.5}, full {full:.5}");
        figures.push((name, pixels, reference, full));
    }
    for (name, pixels, reference, full) in figures {
        assert!(pixels > 10_000, "{name}: {pixels}");
        assert!(
            reference >= 0.999,
            "{name}: reference agrees on {reference}"
        );
        assert!(full >= 0.995, "{name}: full agrees on {full}");
    }
}
