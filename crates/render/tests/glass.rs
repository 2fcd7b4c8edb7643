//! Glass against closed forms and the per-pixel reference: thin glass and
//! glTF transmission glass under Fresnel at every quality level and through
//! the other methods' `shade_reflector`; a pane's back-surface ghost whether
//! its back is part of the reflector or a separate object.

use std::path::Path;
use std::sync::Arc;

use glam::Vec3;
use vtfarm_method::{MethodKind, OwnedFrame};
use vtfarm_render::{FrameSetup, RenderOptions, Renderer};
use vtfarm_scene::photometry;
use vtfarm_scene::{Camera, Lighting, Material, MaterialId, ObjectId, Scene, TriangleId};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{FrameImage, PixelRect, Quality, VertexSettings};

/// The emitter's luminance, cd/m².
const EMITTER_CD_M2: f32 = 20_000.0;

/// Unpolarised Fresnel reflectance at `cos_i` from air onto index `n`.
fn fresnel(cos_i: f64, n: f64) -> f64 {
    let sin_t = (1.0 - cos_i * cos_i).sqrt() / n;
    let cos_t = (1.0 - sin_t * sin_t).sqrt();
    let rs = (cos_i - n * cos_t) / (cos_i + n * cos_t);
    let rp = (n * cos_i - cos_t) / (n * cos_i + cos_t);
    0.5 * (rs * rs + rp * rp)
}

fn f0(n: f32) -> f32 {
    ((n - 1.0) / (n + 1.0)).powi(2)
}

fn dark() -> Lighting {
    Lighting {
        lights: Vec::new(),
        ambient: Vec3::ZERO,
        background: Vec3::ZERO,
    }
}

/// A camera `distance` from the origin at `theta_deg` from +Z (in the xz
/// plane), looking at the origin through a narrow field.
fn camera_at(theta_deg: f32, distance: f32) -> Camera {
    let a = theta_deg.to_radians();
    Camera {
        eye: Vec3::new(a.sin(), 0.0, a.cos()) * distance,
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 10.0,
        width: 48,
        height: 48,
    }
}

/// A uniform emitter of [`EMITTER_CD_M2`] filling every direction a
/// surface at the origin facing +Z mirrors the camera at `theta_deg` into.
fn mirrored_emitter(scene: &mut Scene, theta_deg: f32) {
    let a = theta_deg.to_radians();
    let r = Vec3::new(-a.sin(), 0.0, a.cos());
    let side = r.cross(Vec3::Y).normalize();
    let glow = photometry::emission(Vec3::ONE, EMITTER_CD_M2).unwrap();
    scene.append_quad(
        "emitter",
        Material {
            emission: glow,
            ..Material::diffuse("emitter", Vec3::ZERO)
        },
        r * 6.0 - side * 30.0 - Vec3::Y * 30.0,
        Vec3::Y * 60.0,
        side * 60.0,
    );
}

fn triangles_of(scene: &Scene, objects: &[ObjectId]) -> Vec<TriangleId> {
    scene
        .triangle_ids()
        .filter(|&t| objects.contains(&scene.triangles[t.index()].object))
        .collect()
}

fn setup(camera: Camera, lighting: Lighting, fresnel: bool, quality: Quality) -> FrameSetup {
    FrameSetup {
        camera,
        lighting,
        trace: TraceSettings {
            fresnel,
            ..TraceSettings::default()
        },
        vertex: VertexSettings {
            quality,
            ..VertexSettings::default()
        },
    }
}

fn render(renderer: &Renderer, setup: &FrameSetup) -> FrameImage {
    (renderer.render(setup, &RenderOptions::default(), &mut |_, _| {})).image
}

/// The worst relative error over the glass pixels of `frame` of the
/// reflected luminance against F(θ) · L, θ each pixel's own angle to +Z.
fn worst_fresnel_error(frame: &FrameImage, camera: &Camera, n: f32) -> (f64, usize) {
    let pixels: Vec<usize> = frame.glass().collect();
    let worst = (pixels.iter())
        .map(|&i| {
            let (x, y) = (i as u32 % camera.width, i as u32 / camera.width);
            let cos = f64::from(camera.pixel_ray(x, y).z.abs());
            let expected = fresnel(cos, f64::from(n)) * f64::from(EMITTER_CD_M2);
            let measured = f64::from(photometry::cd_m2(frame.pixel(i).reflected));
            (measured / expected - 1.0).abs()
        })
        .fold(0.0, f64::max);
    (worst, pixels.len())
}

/// Renders the sheet scene (`scene` holds the sheet as object 0, then
/// gets the emitter) at 0°, 45° and 70°, at every quality level and with
/// the cube-map method, and checks every glass pixel's reflected luminance
/// against F(θ) · L within 1 %.
fn check_sheet_under_fresnel(what: &str, sheet: Scene, n: f32) {
    for theta in [0.0f32, 45.0, 70.0] {
        let mut scene = sheet.clone();
        mirrored_emitter(&mut scene, theta);
        let scene = Arc::new(scene);
        let reflectors = triangles_of(&scene, &[ObjectId(0)]);
        let camera = camera_at(theta, 3.0);
        let renderer = Renderer::new(scene.clone(), reflectors.clone());
        for quality in Quality::ALL {
            let frame = render(&renderer, &setup(camera, dark(), true, quality));
            let (worst, pixels) = worst_fresnel_error(&frame, &camera, n);
            assert_eq!(pixels, 48 * 48, "{what}: the sheet fills the frame");
            assert!(
                worst <= 0.01,
                "{what} at {theta}°, {quality:?}: {:.3} % off F(θ) · L",
                worst * 100.0
            );
        }
        // The methods that finish through `shade_reflector`.
        let trace = TraceSettings {
            fresnel: true,
            ..TraceSettings::default()
        };
        let owned = OwnedFrame::new(scene.clone(), camera, dark(), trace, reflectors);
        let method = vtfarm_render::method(MethodKind::CubeMap, VertexSettings::default());
        let output = method.render(&owned.frame());
        let mut frame = FrameImage::new(owned.base_frame(), PixelRect::full(48, 48));
        frame.composite(&output.bitmap);
        let (worst, pixels) = worst_fresnel_error(&frame, &camera, n);
        assert_eq!(pixels, 48 * 48);
        assert!(
            worst <= 0.01,
            "{what} at {theta}°, cube map: {:.3} % off F(θ) · L",
            worst * 100.0
        );
    }
}

/// Cells along each side of [`grid`]: a few pixels each, so that
/// interpolating between vertices (preview, refinement) follows F(θ).
const CELLS: u32 = 80;

/// A 4 × 4 m square at the origin facing +Z, in [`CELLS`]² cells: its
/// positions and its triangles' corners.
fn grid() -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let step = 4.0 / CELLS as f32;
    let positions = (0..=CELLS)
        .flat_map(|j| (0..=CELLS).map(move |i| Vec3::new(i as f32, j as f32, 0.0) * step))
        .map(|p| p - Vec3::new(2.0, 2.0, 0.0))
        .collect();
    let at = |i: u32, j: u32| j * (CELLS + 1) + i;
    let triangles = (0..CELLS)
        .flat_map(|j| (0..CELLS).map(move |i| (i, j)))
        .flat_map(|(i, j)| {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            [[a, b, c], [a, c, d]]
        })
        .collect();
    (positions, triangles)
}

/// [`grid`] as the scene's object 0, "sheet".
fn sheet(material: Material) -> Scene {
    let (positions, triangles) = grid();
    Scene {
        normals: vec![Vec3::Z; positions.len()],
        positions,
        triangles: (triangles.into_iter())
            .map(|vertices| vtfarm_scene::Triangle {
                vertices,
                object: ObjectId(0),
                material: MaterialId(0),
            })
            .collect(),
        objects: vec![vtfarm_scene::Object {
            name: "sheet".into(),
        }],
        materials: vec![material],
        ..Scene::default()
    }
}

#[test]
fn thin_glass_under_fresnel_reflects_f_theta_of_its_ior_at_every_quality() {
    // A job's `thin = true` glass: kr F0, kt 1 - F0, rays straight.
    let n = 1.5;
    let glass = Material {
        reflectance: Vec3::splat(f0(n)),
        transmittance: Vec3::splat(1.0 - f0(n)),
        ior: n,
        thin: true,
        ..Material::diffuse("glass", Vec3::ZERO)
    };
    check_sheet_under_fresnel("thin glass", sheet(glass), n);
}

/// Writes a glTF file of [`grid`], its material `material` (JSON), the
/// buffer beside it.
fn write_sheet_gltf(dir: &Path, material: &str) -> std::path::PathBuf {
    let (positions, triangles) = grid();
    let mut bin = Vec::new();
    for v in positions.iter().flat_map(|p| p.to_array()) {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    for _ in &positions {
        for v in [0.0f32, 0.0, 1.0] {
            bin.extend_from_slice(&v.to_le_bytes());
        }
    }
    for i in triangles.iter().flatten() {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    std::fs::write(dir.join("sheet.bin"), &bin).unwrap();
    let (count, indices) = (positions.len(), triangles.len() * 3);
    let vectors = count * 12;
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "extensionsUsed": ["KHR_materials_ior", "KHR_materials_transmission"],
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"name": "sheet", "mesh": 0}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "NORMAL": 1}}, "indices": 2, "material": 0}}]}}],
  "materials": [{material}],
  "buffers": [{{"uri": "sheet.bin", "byteLength": {len}}}],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": {vectors}}},
    {{"buffer": 0, "byteOffset": {vectors}, "byteLength": {vectors}}},
    {{"buffer": 0, "byteOffset": {twice}, "byteLength": {index_bytes}}}
  ],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": {count}, "type": "VEC3", "min": [-2, -2, 0], "max": [2, 2, 0]}},
    {{"bufferView": 1, "componentType": 5126, "count": {count}, "type": "VEC3"}},
    {{"bufferView": 2, "componentType": 5125, "count": {indices}, "type": "SCALAR"}}
  ]
}}"#,
        len = bin.len(),
        twice = 2 * vectors,
        index_bytes = indices * 4,
    );
    let path = dir.join("sheet.gltf");
    std::fs::write(&path, json).unwrap();
    path
}

#[test]
fn gltf_transmission_glass_under_fresnel_reflects_f_theta_of_its_khr_ior() {
    // KHR_materials_transmission glass of KHR_materials_ior 1.6 (not the
    // default 1.5: the file's ior must reach the Fresnel weights).
    let n = 1.6;
    let dir = tempfile::tempdir().unwrap();
    let path = write_sheet_gltf(
        dir.path(),
        r#"{"name": "glass",
            "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0, "roughnessFactor": 0},
            "extensions": {"KHR_materials_ior": {"ior": 1.6},
                           "KHR_materials_transmission": {"transmissionFactor": 1}}}"#,
    );
    let imported = vtfarm_scene::gltf::import_gltf(&path, &Default::default()).unwrap();
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let glass = &imported.scene.materials[0];
    assert!(glass.thin, "transmission glass is thin");
    check_sheet_under_fresnel("glTF glass", imported.scene, n);
}

/// A 4-mm pane of kr 0.1, kt 0.85 and ior 1.5 at the origin (front facing
/// +Z, back at z = -0.004 facing -Z), its back in the front's object or
/// an object of its own; a dim board behind it and the emitter mirrored at
/// `theta_deg`. The reflectors: the pane's object (both faces when one).
fn slab(theta_deg: f32, one_object: bool) -> (Scene, Vec<TriangleId>) {
    let glass = Material {
        reflectance: Vec3::splat(0.1),
        transmittance: Vec3::splat(0.85),
        ior: 1.5,
        ..Material::diffuse("glass", Vec3::ZERO)
    };
    let mut scene = sheet(glass.clone());
    let back = scene.append_quad(
        "pane_back",
        glass,
        Vec3::new(-2.0, -2.0, -0.004),
        Vec3::Y * 4.0,
        Vec3::X * 4.0,
    );
    if one_object {
        for t in back {
            scene.triangles[t.index()].object = ObjectId(0);
        }
    }
    scene.append_quad(
        "board",
        Material::diffuse("board", Vec3::splat(0.3)),
        Vec3::new(-4.0, -4.0, -0.5),
        Vec3::X * 8.0,
        Vec3::Y * 8.0,
    );
    mirrored_emitter(&mut scene, theta_deg);
    let reflectors = triangles_of(&scene, &[ObjectId(0)]);
    (scene, reflectors)
}

fn median(mut values: Vec<f32>) -> f32 {
    values.sort_by(f32::total_cmp);
    values[values.len() / 2]
}

#[test]
fn a_panes_ghost_is_the_same_at_every_quality_whether_its_back_is_in_the_reflector_or_not() {
    // Both surfaces reflect toward the eye: 0.1 + 0.85² · 0.1 of the
    // emitter (no Fresnel: the head-on weights at every angle).
    let expected = (0.1 + 0.85 * 0.85 * 0.1) * EMITTER_CD_M2;
    for theta in [0.0f32, 45.0] {
        for one_object in [true, false] {
            let (scene, reflectors) = slab(theta, one_object);
            let renderer = Renderer::new(Arc::new(scene), reflectors);
            let lighting = Lighting {
                ambient: Vec3::splat(0.05),
                ..dark()
            };
            for quality in Quality::ALL {
                let frame = render(
                    &renderer,
                    &setup(camera_at(theta, 3.0), lighting.clone(), false, quality),
                );
                let reflected: Vec<f32> = (frame.glass())
                    .map(|i| photometry::cd_m2(frame.pixel(i).reflected))
                    .collect();
                assert_eq!(reflected.len(), 48 * 48);
                let lr = median(reflected);
                assert!(
                    (lr / expected - 1.0).abs() <= 0.01,
                    "{theta}°, back {}, {quality:?}: {lr} cd/m², expected {expected}",
                    if one_object {
                        "in the reflector"
                    } else {
                        "an object of its own"
                    }
                );
            }
        }
    }
}

/// The weights a view that draws the scene itself blends the glass with
/// (`StageMesh::slabs`) are the pane's closed form at every vertex: the
/// board behind weighted by kt(front) · kt(back), the reflection scaled by
/// 1 + kt² (the back's kr is the front's), with and without Fresnel, the
/// back in the reflector or not; a single sheet lets kt through and adds
/// no ghost.
#[test]
fn a_panes_vertices_carry_the_weights_of_its_closed_form() {
    let (kr0, kt0) = (0.1f64, 0.85f64);
    for theta in [0.0f32, 45.0] {
        for with_fresnel in [false, true] {
            for back in [Some(false), Some(true), None] {
                let (scene, reflectors) = match back {
                    Some(one_object) => slab(theta, one_object),
                    None => {
                        let glass = slab(theta, false).0.materials[0].clone();
                        let scene = sheet(glass);
                        let reflectors = triangles_of(&scene, &[ObjectId(0)]);
                        (scene, reflectors)
                    }
                };
                let renderer = Renderer::new(Arc::new(scene), reflectors);
                let setup = setup(
                    camera_at(theta, 3.0),
                    dark(),
                    with_fresnel,
                    Quality::Preview,
                );
                let mut checked = 0;
                for mesh in renderer.corner_meshes(&setup) {
                    for (p, slab) in mesh.positions.iter().zip(&mesh.slabs) {
                        // The front's inner vertices (a ray at an edge can
                        // miss the back).
                        if p.z < -0.001 || p.x.abs() > 1.9 || p.y.abs() > 1.9 {
                            continue;
                        }
                        let cos_i = f64::from((*p - setup.camera.eye).normalize().z.abs());
                        let f0 = f64::from(f0(1.5));
                        let moved = if with_fresnel {
                            (fresnel(cos_i, 1.5) - f0) / (1.0 - f0)
                        } else {
                            0.0
                        };
                        let (kr, kt) = (kr0 + kt0 * moved, kt0 * (1.0 - moved));
                        let (behind, scale) = match back {
                            Some(_) => (kt * kt, 1.0 + kt * kt * kr / kr),
                            None => (kt, 1.0),
                        };
                        let what =
                            format!("{theta}°, fresnel {with_fresnel}, back {back:?}, at {p}");
                        assert!(
                            (f64::from(slab.behind.x) - behind).abs() < 1e-4,
                            "{what}: behind {} against {behind}",
                            slab.behind
                        );
                        assert!(
                            (f64::from(slab.reflection_scale) - scale).abs() < 1e-4,
                            "{what}: scale {} against {scale}",
                            slab.reflection_scale
                        );
                        checked += 1;
                    }
                }
                assert!(checked > 100, "{checked} vertices");
            }
        }
    }
}

/// A UV sphere of radius `r` at the origin, outward normals, triangles
/// wound counter-clockwise seen from outside.
fn sphere(r: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let (rings, segments) = (16u32, 24u32);
    let mut positions = Vec::new();
    for i in 0..=rings {
        let polar = std::f32::consts::PI * i as f32 / rings as f32;
        for j in 0..=segments {
            let azimuth = std::f32::consts::TAU * j as f32 / segments as f32;
            positions.push(
                Vec3::new(
                    polar.sin() * azimuth.cos(),
                    polar.cos(),
                    -polar.sin() * azimuth.sin(),
                ) * r,
            );
        }
    }
    let at = |i: u32, j: u32| i * (segments + 1) + j;
    let mut triangles = Vec::new();
    for i in 0..rings {
        for j in 0..segments {
            let (a, b, c, d) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
            triangles.push([a, b, c]);
            triangles.push([a, c, d]);
        }
    }
    (positions, triangles)
}

/// A mesh of [`write_gltf`]: positions, normals, triangles and material.
type GltfMesh = (Vec<Vec3>, Vec<Vec3>, Vec<[u32; 3]>, usize);

/// Writes a glTF file of meshes and nodes (name, mesh, translation), the
/// buffer beside it.
fn write_gltf(
    dir: &Path,
    meshes: &[GltfMesh],
    nodes: &[(&str, usize, Vec3)],
    materials: &str,
) -> std::path::PathBuf {
    let mut bin: Vec<u8> = Vec::new();
    let (mut views, mut accessors, mut primitives) = (vec![], vec![], vec![]);
    for (positions, normals, triangles, material) in meshes {
        let first = accessors.len();
        for (vectors, bounds) in [(positions, true), (normals, false)] {
            let offset = bin.len();
            for v in vectors.iter().flat_map(|v| v.to_array()) {
                bin.extend_from_slice(&v.to_le_bytes());
            }
            views.push(format!(
                r#"{{"buffer": 0, "byteOffset": {offset}, "byteLength": {}}}"#,
                bin.len() - offset
            ));
            let (lo, hi) = (vectors.iter())
                .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
                    (lo.min(p), hi.max(p))
                });
            let range = if bounds {
                format!(
                    r#", "min": {:?}, "max": {:?}"#,
                    lo.to_array(),
                    hi.to_array()
                )
            } else {
                String::new()
            };
            accessors.push(format!(
                r#"{{"bufferView": {}, "componentType": 5126, "count": {}, "type": "VEC3"{range}}}"#,
                views.len() - 1,
                vectors.len()
            ));
        }
        let offset = bin.len();
        for i in triangles.iter().flatten() {
            bin.extend_from_slice(&i.to_le_bytes());
        }
        views.push(format!(
            r#"{{"buffer": 0, "byteOffset": {offset}, "byteLength": {}}}"#,
            bin.len() - offset
        ));
        accessors.push(format!(
            r#"{{"bufferView": {}, "componentType": 5125, "count": {}, "type": "SCALAR"}}"#,
            views.len() - 1,
            triangles.len() * 3
        ));
        primitives.push(format!(
            r#"{{"primitives": [{{"attributes": {{"POSITION": {first}, "NORMAL": {}}}, "indices": {}, "material": {material}}}]}}"#,
            first + 1,
            first + 2
        ));
    }
    std::fs::write(dir.join("scene.bin"), &bin).unwrap();
    let nodes: Vec<String> = (nodes.iter())
        .map(|(name, mesh, t)| {
            format!(
                r#"{{"name": "{name}", "mesh": {mesh}, "translation": {:?}}}"#,
                t.to_array()
            )
        })
        .collect();
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "extensionsUsed": ["KHR_materials_ior", "KHR_materials_transmission"],
  "scene": 0,
  "scenes": [{{"nodes": {:?}}}],
  "nodes": [{}],
  "meshes": [{}],
  "materials": {materials},
  "buffers": [{{"uri": "scene.bin", "byteLength": {}}}],
  "bufferViews": [{}],
  "accessors": [{}]
}}"#,
        (0..nodes.len()).collect::<Vec<_>>(),
        nodes.join(", "),
        primitives.join(", "),
        bin.len(),
        views.join(", "),
        accessors.join(", ")
    );
    let path = dir.join("scene.gltf");
    std::fs::write(&path, json).unwrap();
    path
}

#[test]
fn glass_spheres_that_are_no_reflector_show_what_lies_behind_them_with_one_warning() {
    // Three transmission-glass spheres of a glTF file before a grey
    // backdrop; the left one is the reflector. The other two are drawn
    // see-through: kt of their front and back surfaces (1 - F0 = 0.96
    // each) times the backdrop, not black.
    let dir = tempfile::tempdir().unwrap();
    let (ball, ball_triangles) = sphere(0.5);
    let ball_normals = ball.iter().map(|p| p.normalize()).collect();
    let backdrop = vec![
        Vec3::new(-5.0, -5.0, -2.0),
        Vec3::new(5.0, -5.0, -2.0),
        Vec3::new(5.0, 5.0, -2.0),
        Vec3::new(-5.0, 5.0, -2.0),
    ];
    let path = write_gltf(
        dir.path(),
        &[
            (ball, ball_normals, ball_triangles, 0),
            (backdrop, vec![Vec3::Z; 4], vec![[0, 1, 2], [0, 2, 3]], 1),
        ],
        &[
            ("sphere_a", 0, Vec3::new(-1.5, 0.0, 0.0)),
            ("sphere_b", 0, Vec3::ZERO),
            ("sphere_c", 0, Vec3::new(1.5, 0.0, 0.0)),
            ("backdrop", 1, Vec3::ZERO),
        ],
        r#"[{"name": "glass",
             "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0, "roughnessFactor": 0},
             "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1}}},
            {"name": "grey",
             "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1], "metallicFactor": 0, "roughnessFactor": 1}}]"#,
    );
    let imported = vtfarm_scene::gltf::import_gltf(&path, &Default::default()).unwrap();
    assert!(imported.warnings.is_empty(), "{:?}", imported.warnings);
    let scene = Arc::new(imported.scene);
    let object = |name| scene.object_id(name).unwrap();
    let reflectors = triangles_of(&scene, &[object("sphere_a")]);
    let renderer = Renderer::new(scene.clone(), reflectors);
    let lighting = Lighting {
        ambient: Vec3::splat(0.2),
        ..dark()
    };
    let camera = Camera {
        eye: Vec3::new(0.0, 0.0, 5.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 40.0,
        width: 96,
        height: 64,
    };
    let setup = setup(camera, lighting, false, Quality::Full);
    let (_, ids) = renderer.base_frame(&setup);
    let frame = render(&renderer, &setup);
    // The backdrop's ambient term, through two surfaces of kt 0.96.
    let backdrop = 0.5 * 0.2;
    let expected = 0.96 * 0.96 * backdrop;
    for name in ["sphere_b", "sphere_c"] {
        let id = object(name);
        let seen: Vec<f32> = (0..camera.width * camera.height)
            .filter(|&i| ids.object_at(i % camera.width, i / camera.width) == id.raw())
            .map(|i| frame.color.pixels[i as usize].x)
            .collect();
        assert!(seen.len() > 100, "{name}: {} px", seen.len());
        let lowest = seen.iter().copied().fold(f32::INFINITY, f32::min);
        let middle = median(seen);
        assert!(
            (middle / expected - 1.0).abs() <= 0.01,
            "{name}: {middle}, expected {expected}"
        );
        assert!(lowest >= 0.9 * expected, "{name}: a pixel of {lowest}");
    }
    // One warning names them (and not the reflector).
    let mut image = vtfarm_imaging::Image::new(0, 0, Vec3::ZERO);
    let mut ids = vtfarm_raster::IdBuffer::new(0, 0);
    let warned = std::sync::atomic::AtomicBool::new(false);
    let is_reflector = vtfarm_render::reflector_flags(&scene, renderer.reflectors());
    let glass = vtfarm_render::base_frame_into(
        &scene,
        &setup,
        &is_reflector,
        vtfarm_render::BaseExtent::Whole,
        (&mut image, &mut ids),
        &warned,
    );
    assert_eq!(glass, [object("sphere_b"), object("sphere_c")]);
    assert!(warned.load(std::sync::atomic::Ordering::Relaxed));
    let warning = vtfarm_render::see_through_warning(&scene, &glass);
    assert!(
        warning.contains("(sphere_b, sphere_c)") && !warning.contains("sphere_a"),
        "{warning}"
    );
}
