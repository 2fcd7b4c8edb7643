//! Checks of the generated cockpit: structure, triangle budget, the cover
//! glass's shape and visibility, and (by brute-force ray casting) that the
//! glass mirrors the left door window into the driver's eye.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use glam::Vec3;
use vtfarm_cockpit::{
    BACKGROUND_CD_M2, CAB_AMBIENT_LUX, COVER_GLASS, COVER_GLASS_BACK, Cockpit, CockpitConfig,
    DIAL_FACE_CD_M2, GLASS_MATERIAL, MARKING_CD_M2, SKY_CD_M2, SUN_ILLUMINANCE_LUX,
    SUNLIT_WINDOW_CD_M2, cockpit, default_eye,
};
use vtfarm_scene::{Camera, LightKind, MaterialId, ObjectId, Scene};

fn default_cockpit() -> &'static Cockpit {
    static COCKPIT: OnceLock<Cockpit> = OnceLock::new();
    COCKPIT.get_or_init(|| cockpit(&CockpitConfig::default()))
}

fn large_cockpit() -> &'static Cockpit {
    static COCKPIT: OnceLock<Cockpit> = OnceLock::new();
    COCKPIT.get_or_init(|| {
        cockpit(&CockpitConfig {
            detail: CockpitConfig::LARGE_DETAIL,
            ..CockpitConfig::default()
        })
    })
}

fn object(scene: &Scene, name: &str) -> ObjectId {
    scene
        .object_id(name)
        .unwrap_or_else(|| panic!("no object {name}"))
}

/// The contiguous vertex range of an object (the generator adds each
/// object's vertices in one block).
fn vertex_range(scene: &Scene, id: ObjectId) -> std::ops::RangeInclusive<usize> {
    let vertices = scene
        .triangles
        .iter()
        .filter(|t| t.object == id)
        .flat_map(|t| t.vertices);
    let (lo, hi) = vertices.fold((u32::MAX, 0), |(lo, hi), v| (lo.min(v), hi.max(v)));
    lo as usize..=hi as usize
}

/// The bounding box of an object's vertices.
fn object_bounds(scene: &Scene, id: ObjectId) -> (Vec3, Vec3) {
    vertex_range(scene, id)
        .map(|v| scene.positions[v])
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p), hi.max(p))
        })
}

/// Brute-force closest-hit ray casting over all triangles.
struct Caster<'a> {
    scene: &'a Scene,
    triangles: Vec<[Vec3; 3]>,
}

impl<'a> Caster<'a> {
    fn new(scene: &'a Scene) -> Self {
        let triangles = scene
            .triangle_ids()
            .map(|t| scene.triangle_positions(t))
            .collect();
        Caster { scene, triangles }
    }

    /// The closest triangle hit by the ray (two-sided) and its distance.
    fn cast(&self, origin: Vec3, dir: Vec3) -> Option<(usize, f32)> {
        let mut best: Option<(usize, f32)> = None;
        for (i, [a, b, c]) in self.triangles.iter().enumerate() {
            let (e1, e2) = (*b - *a, *c - *a);
            let p = dir.cross(e2);
            let det = e1.dot(p);
            if det.abs() < 1e-12 {
                continue;
            }
            let inv = 1.0 / det;
            let s = origin - *a;
            let u = s.dot(p) * inv;
            if !(0.0..=1.0).contains(&u) {
                continue;
            }
            let q = s.cross(e1);
            let v = dir.dot(q) * inv;
            if v < 0.0 || u + v > 1.0 {
                continue;
            }
            let t = e2.dot(q) * inv;
            if t > 1e-6 && best.is_none_or(|(_, bt)| t < bt) {
                best = Some((i, t));
            }
        }
        best
    }

    /// Name of the object the ray hits first, or "none".
    fn object_hit(&self, origin: Vec3, dir: Vec3) -> &str {
        match self.cast(origin, dir) {
            Some((t, _)) => &self.scene.objects[self.scene.triangles[t].object.index()].name,
            None => "none",
        }
    }
}

#[test]
fn default_detail_validates_with_about_100k_triangles() {
    let scene = &default_cockpit().scene;
    scene.validate().unwrap();
    let n = scene.triangles.len();
    assert!((90_000..=110_000).contains(&n), "{n} triangles");
}

#[test]
fn large_detail_validates_with_about_210k_triangles() {
    let scene = &large_cockpit().scene;
    scene.validate().unwrap();
    let n = scene.triangles.len();
    assert!((189_000..=231_000).contains(&n), "{n} triangles");
}

#[test]
fn generation_is_deterministic() {
    let (a, b) = (cockpit(&CockpitConfig::default()), default_cockpit());
    let bits = |s: &Scene| -> Vec<u32> {
        s.positions
            .iter()
            .chain(&s.normals)
            .flat_map(|v| v.to_array())
            .map(f32::to_bits)
            .collect()
    };
    assert_eq!(bits(&a.scene), bits(&b.scene));
    assert_eq!(a.scene, b.scene);
    assert_eq!(a.camera, b.camera);
    assert_eq!(a.lighting, b.lighting);
}

#[test]
fn no_triangle_is_degenerate() {
    for scene in [&default_cockpit().scene, &large_cockpit().scene] {
        for t in scene.triangle_ids() {
            let [a, b, c] = scene.triangle_positions(t);
            let area = (b - a).cross(c - a).length() * 0.5;
            assert!(
                area > 1e-10,
                "triangle {t} of {} has area {area}",
                scene.triangles.len()
            );
        }
    }
}

#[test]
fn windings_agree_with_vertex_normals() {
    let scene = &default_cockpit().scene;
    for t in scene.triangle_ids() {
        let mean: Vec3 = scene.triangle_normals(t).iter().sum();
        let object = &scene.objects[scene.triangles[t.index()].object.index()].name;
        assert!(
            scene.geometric_normal(t).dot(mean) > 0.0,
            "triangle {t} of {object} is wound clockwise"
        );
    }
}

#[test]
fn objects_are_the_documented_ones_each_with_its_own_material() {
    let scene = &default_cockpit().scene;
    let expected = [
        "cab_walls",
        "floor",
        "roof",
        "dashboard",
        "a_pillar_left",
        "a_pillar_right",
        "steering_wheel",
        "seat",
        "center_console",
        "windshield_sky",
        "side_window_left",
        "side_window_right",
        "ground",
        "instrument_panel",
        "dial_faces",
        "dial_markings",
        "needles",
        "warning_lamps",
        COVER_GLASS,
        COVER_GLASS_BACK,
        "cluster_hood",
    ];
    let names: Vec<&str> = scene.objects.iter().map(|o| o.name.as_str()).collect();
    let mut sorted = names.clone();
    sorted.sort_unstable();
    sorted.dedup();
    assert_eq!(
        sorted.len(),
        names.len(),
        "duplicate object names in {names:?}"
    );
    for name in expected {
        assert!(names.contains(&name), "missing {name}");
    }
    for name in &names {
        assert!(
            name.chars()
                .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'),
            "{name}"
        );
    }
    // Material -> objects using it: only the two glass surfaces share one.
    let mut users: BTreeMap<MaterialId, Vec<ObjectId>> = BTreeMap::new();
    for t in &scene.triangles {
        let objects = users.entry(t.material).or_default();
        if !objects.contains(&t.object) {
            objects.push(t.object);
        }
    }
    for (material, objects) in users {
        let name = &scene.materials[material.index()].name;
        if name == GLASS_MATERIAL {
            assert_eq!(
                objects,
                [object(scene, COVER_GLASS), object(scene, COVER_GLASS_BACK)]
            );
        } else {
            assert_eq!(objects.len(), 1, "material {name} is shared");
        }
    }
    for id in 0..scene.objects.len() as u32 {
        assert!(
            scene.triangles.iter().any(|t| t.object == ObjectId(id)),
            "{} is empty",
            names[id as usize]
        );
    }
}

#[test]
fn windows_are_bright_panels_and_the_glass_is_a_weak_mirror() {
    let scene = &default_cockpit().scene;
    let emission = |name: &str| {
        let id = object(scene, name);
        scene
            .material_of(scene.triangles_of(id).next().unwrap())
            .emission
    };
    // Emitters have the luminance in cd/m² the cockpit documents.
    let cd_m2 = |name: &str| vtfarm_scene::photometry::cd_m2(emission(name));
    let close = |a: f32, b: f32| (a - b).abs() <= 1e-4 * b;
    assert!(close(cd_m2("side_window_left"), SUNLIT_WINDOW_CD_M2));
    assert!(close(cd_m2("windshield_sky"), SKY_CD_M2));
    assert!(close(cd_m2("dial_markings"), MARKING_CD_M2));
    assert!(close(cd_m2("dial_faces"), DIAL_FACE_CD_M2));
    assert!(cd_m2("ground") < cd_m2("windshield_sky"));
    // The sun delivers its documented illuminance: a white Lambertian
    // surface facing it would have E/π cd/m².
    let sun = default_cockpit().lighting.lights[0];
    assert!(close(
        vtfarm_scene::photometry::cd_m2(sun.radiance()),
        SUN_ILLUMINANCE_LUX / std::f32::consts::PI
    ));
    let glass = &scene.materials[scene.material_id(GLASS_MATERIAL).unwrap().index()];
    assert_eq!(glass.reflectance, Vec3::splat(0.12));
    assert_eq!(glass.transmittance, Vec3::splat(0.85));
    assert_eq!(glass.ior, 1.5);
    assert!(glass.diffuse.max_element() <= 0.01 && glass.ambient.max_element() <= 0.01);
}

#[test]
fn glass_is_a_concave_thin_shell_facing_the_driver() {
    let scene = &default_cockpit().scene;
    let eye = default_eye();
    let (front, back) = (object(scene, COVER_GLASS), object(scene, COVER_GLASS_BACK));
    for id in [front, back] {
        assert_eq!(scene.triangles_of(id).count(), 24 * 12 * 2);
    }
    let (fr, br) = (vertex_range(scene, front), vertex_range(scene, back));
    assert_eq!(fr.clone().count(), br.clone().count());
    for (f, b) in fr.clone().zip(br) {
        let (p, n) = (scene.positions[f], scene.normals[f]);
        assert!(
            n.dot(eye - p) > 0.0,
            "front normal {n} at {p} faces away from the eye"
        );
        // The back surface lies 3 mm behind along the same normal, facing away.
        assert!((scene.positions[b] - (p - n * 0.003)).length() < 1e-5);
        assert!((scene.normals[b] + n).length() < 1e-5);
    }
    // Concave towards the driver: all of it lies on the driver's side of
    // every tangent plane, and the corners noticeably so.
    let points: Vec<(Vec3, Vec3)> = fr.map(|v| (scene.positions[v], scene.normals[v])).collect();
    for &(p, n) in &points {
        for &(q, _) in &points {
            assert!((q - p).dot(n) > -1e-6, "not concave at {p}");
        }
    }
    let centre = default_cockpit().camera.target;
    let (_, centre_normal) = points
        .iter()
        .min_by(|a, b| a.0.distance(centre).total_cmp(&b.0.distance(centre)))
        .unwrap();
    let bulge = points
        .iter()
        .map(|(q, _)| (*q - centre).dot(*centre_normal))
        .fold(0.0, f32::max);
    assert!(
        bulge > 0.02,
        "corners are only {bulge} m in front of the centre"
    );
    // Smooth normals: each triangle's vertex normals stay close to its plane's.
    for t in scene.triangles_of(front) {
        let g = scene.geometric_normal(t);
        assert!(
            scene.triangle_normals(t).iter().all(|n| n.dot(g) > 0.999),
            "triangle {t}"
        );
    }
    // About 0.45 m by 0.2 m, measured across and up the glass.
    let right = Vec3::Y.cross(*centre_normal).normalize();
    let up = centre_normal.cross(right);
    let extent = |axis: Vec3| {
        let d: Vec<f32> = points.iter().map(|(p, _)| p.dot(axis)).collect();
        d.iter().fold(f32::MIN, |a, &b| a.max(b)) - d.iter().fold(f32::MAX, |a, &b| a.min(b))
    };
    let (width, height) = (extent(right), extent(up));
    assert!((0.4..0.5).contains(&width), "width {width}");
    assert!((0.15..0.25).contains(&height), "height {height}");
}

#[test]
fn glass_tessellation_follows_the_config() {
    let scene = cockpit(&CockpitConfig {
        detail: 0.2,
        glass_segments: 16,
        ..CockpitConfig::default()
    })
    .scene;
    scene.validate().unwrap();
    let id = object(&scene, COVER_GLASS);
    assert_eq!(scene.triangles_of(id).count(), 16 * 8 * 2);
}

#[test]
fn camera_looks_from_the_driver_eye_at_the_glass_centre() {
    let c = default_cockpit();
    let camera = c.camera;
    assert_eq!(camera.eye, default_eye());
    assert_eq!(
        (camera.up, camera.fov_y_deg, camera.width, camera.height),
        (Vec3::Y, 50.0, 640, 360)
    );
    let glass = vertex_range(&c.scene, object(&c.scene, COVER_GLASS));
    let nearest = glass
        .map(|v| c.scene.positions[v].distance(camera.target))
        .fold(f32::MAX, f32::min);
    assert!(nearest < 0.01, "target is {nearest} m from the glass");
    let offset = camera.eye - camera.target;
    assert!(
        (0.6..0.8).contains(&offset.z) && (0.3..0.4).contains(&offset.y),
        "{offset}"
    );
}

/// Daylight in physical units: one sun in lux, the cab's diffuse daylight
/// as the ambient term in lux, no unit-less lamps.
#[test]
fn lighting_is_the_sun_and_the_cabs_daylight_in_physical_units() {
    use vtfarm_scene::photometry::{self, CD_M2_PER_UNIT};
    let lighting = &default_cockpit().lighting;
    let pi = std::f32::consts::PI;
    assert!((lighting.ambient.x * pi * CD_M2_PER_UNIT - CAB_AMBIENT_LUX).abs() < 0.1);
    assert!((photometry::cd_m2(lighting.background) - BACKGROUND_CD_M2).abs() < 0.5);
    assert_eq!(lighting.lights.len(), 1);
    assert!(matches!(
        lighting.lights[0].kind,
        LightKind::Directional { .. }
    ));
}

#[test]
fn cover_glass_covers_at_least_160k_pixels_at_1080p() {
    let c = default_cockpit();
    let camera = Camera {
        width: 1920,
        height: 1080,
        ..c.camera
    };
    let id = object(&c.scene, COVER_GLASS);
    let mut area = 0.0;
    for t in c.scene.triangles_of(id) {
        let [a, b, c] = c
            .scene
            .triangle_positions(t)
            .map(|p| camera.project(p).unwrap());
        for s in [a, b, c] {
            assert!(
                (0.0..=1920.0).contains(&s.x) && (0.0..=1080.0).contains(&s.y),
                "glass leaves the image"
            );
        }
        area += ((b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y)).abs() * 0.5;
    }
    println!("cover glass: {area:.0} pixels at 1920x1080");
    assert!(area >= 160_000.0, "{area} pixels");
}

#[test]
fn cover_glass_is_not_hidden_from_the_eye() {
    let c = default_cockpit();
    let caster = Caster::new(&c.scene);
    let eye = default_eye();
    let id = object(&c.scene, COVER_GLASS);
    let (mut seen, mut total) = (0, 0);
    for t in c.scene.triangles_of(id) {
        let centroid = c.scene.triangle_positions(t).iter().sum::<Vec3>() / 3.0;
        total += 1;
        if caster.object_hit(eye, (centroid - eye).normalize()) == COVER_GLASS {
            seen += 1;
        }
    }
    assert!(
        seen * 100 >= total * 98,
        "only {seen} of {total} glass triangles are visible"
    );
}

/// Reflects the eye's view of every front-glass vertex and names what the
/// mirrored ray hits; prints a map of the glass as the eye sees it.
fn reflection_map(c: &Cockpit) -> Vec<(Vec3, f32, String)> {
    let caster = Caster::new(&c.scene);
    let eye = default_eye();
    let camera = c.camera;
    let centre_y = camera.project(camera.target).unwrap().y;
    let mut hits = Vec::new();
    for v in vertex_range(&c.scene, object(&c.scene, COVER_GLASS)) {
        let (p, n) = (c.scene.positions[v], c.scene.normals[v]);
        let d = (p - eye).normalize();
        let r = d - 2.0 * d.dot(n) * n;
        let name = caster.object_hit(p + r * 1e-4, r).to_owned();
        hits.push((p, camera.project(p).unwrap().y - centre_y, name));
    }
    // The map: what each vertex mirrors, binned by where the eye sees it.
    let (cols, rows) = (36, 14);
    let screen: Vec<_> = hits
        .iter()
        .map(|(p, _, _)| camera.project(*p).unwrap())
        .collect();
    let (lo, hi) = screen.iter().fold(
        ((f32::MAX, f32::MAX), (f32::MIN, f32::MIN)),
        |(lo, hi), s| {
            (
                (lo.0.min(s.x), lo.1.min(s.y)),
                (hi.0.max(s.x), hi.1.max(s.y)),
            )
        },
    );
    let mut map = vec![vec![' '; cols]; rows];
    for (s, (_, _, name)) in screen.iter().zip(&hits) {
        let col = ((s.x - lo.0) / (hi.0 - lo.0) * (cols - 1) as f32).round() as usize;
        let row = ((s.y - lo.1) / (hi.1 - lo.1) * (rows - 1) as f32).round() as usize;
        map[row][col] = name.chars().next().unwrap_or('?');
    }
    for row in map {
        println!("{}", row.into_iter().collect::<String>());
    }
    hits
}

#[test]
fn glass_mirrors_the_left_door_window_in_its_lower_part() {
    let c = default_cockpit();
    let hits = reflection_map(c);
    let emissive = |name: &str| {
        let id = object(&c.scene, name);
        c.scene
            .triangles
            .iter()
            .find(|t| t.object == id)
            .map(|t| c.scene.materials[t.material.index()].emission)
    };
    let window: Vec<_> = hits.iter().filter(|h| h.2 == "side_window_left").collect();
    let dark = hits
        .iter()
        .filter(|h| {
            h.2 != "none"
                && emissive(&h.2).is_some_and(|e| e == Vec3::ZERO)
                && !h.2.starts_with("cover_glass")
        })
        .count();
    let n = hits.len();
    println!(
        "{} of {n} reflections reach the left window, {dark} dark interior",
        window.len()
    );
    assert!(
        window.len() * 10 >= n,
        "only {} of {n} reflections reach the left window",
        window.len()
    );
    assert!(
        dark * 10 >= n,
        "only {dark} of {n} reflections show dark interior"
    );
    let lower = window.iter().filter(|h| h.1 > 0.0).count();
    assert!(
        lower * 4 >= window.len() * 3,
        "{lower} of {} window reflections are low",
        window.len()
    );
}

#[test]
fn sun_shines_in_through_the_left_door_window() {
    let c = default_cockpit();
    let caster = Caster::new(&c.scene);
    let LightKind::Directional { direction, .. } = c.lighting.lights[0].kind else {
        panic!("no sun first")
    };
    let to_sun = -direction.normalize();
    let walls = object_bounds(&c.scene, object(&c.scene, "cab_walls"));
    let mut lit = BTreeMap::<&str, usize>::new();
    for name in [
        "seat",
        "floor",
        "dashboard",
        "steering_wheel",
        "center_console",
    ] {
        let range = vertex_range(&c.scene, object(&c.scene, name));
        for v in range.step_by(7) {
            let (p, n) = (c.scene.positions[v], c.scene.normals[v]);
            // Skip points on the walls' planes (the floor's edges): their
            // rays would leave through a wall's very edge.
            let inside = (p.x - walls.0.x)
                .min(walls.1.x - p.x)
                .min(p.z - walls.0.z)
                .min(walls.1.z - p.z)
                > 0.01;
            if n.dot(to_sun) <= 0.0 || !inside {
                continue;
            }
            if caster.cast(p + n * 1e-4, to_sun).is_none() {
                *lit.entry(name).or_default() += 1;
                // It leaves the cab through the left wall (whose only opening is the window).
                let t = (walls.0.x - p.x) / to_sun.x;
                let exit = p + to_sun * t;
                let through_left = exit.y > walls.0.y
                    && exit.y < walls.1.y
                    && exit.z > walls.0.z
                    && exit.z < walls.1.z;
                assert!(t > 0.0 && through_left, "{p} exits at {exit}");
            }
        }
    }
    println!("sunlit sample vertices: {lit:?}");
    assert!(lit.values().sum::<usize>() >= 50, "{lit:?}");
}

#[test]
fn odd_configurations_still_give_valid_scenes() {
    for (detail, glass_segments) in [(0.0, 0), (f32::NAN, 1), (0.05, 3), (-1.0, 7)] {
        let scene = cockpit(&CockpitConfig {
            detail,
            glass_segments,
            ..CockpitConfig::default()
        })
        .scene;
        scene.validate().unwrap();
        assert!(scene.object_id(COVER_GLASS).is_some());
    }
}

#[test]
fn triangle_count_grows_about_linearly_with_detail() {
    let count = |detail| {
        cockpit(&CockpitConfig {
            detail,
            ..CockpitConfig::default()
        })
        .scene
        .triangles
        .len() as f32
    };
    let (half, one, four) = (count(0.5), count(1.0), count(4.0));
    assert!((half / one - 0.5).abs() < 0.06, "{half} vs {one}");
    assert!((four / one - 4.0).abs() < 0.3, "{four} vs {one}");
}

// ---- Cover-glass design variants ----

use vtfarm_cockpit::{GLARE_ABSORBER, GlassDesign, glare_absorber_focus};

fn design_cockpit(glass: GlassDesign) -> Cockpit {
    cockpit(&CockpitConfig {
        detail: 0.2,
        glass_segments: 16,
        glass,
    })
}

/// Front-glass vertices with their normals.
fn front_glass(c: &Cockpit) -> Vec<(Vec3, Vec3)> {
    vertex_range(&c.scene, object(&c.scene, COVER_GLASS))
        .map(|v| (c.scene.positions[v], c.scene.normals[v]))
        .collect()
}

const DESIGNS: [GlassDesign; 6] = [
    GlassDesign::Current,
    GlassDesign::Flat,
    GlassDesign::FlatTilted { degrees: 15.0 },
    GlassDesign::FlatTilted { degrees: -10.0 },
    GlassDesign::Cylindrical { radius: 0.5 },
    GlassDesign::Ellipsoidal,
];

#[test]
fn every_design_validates_and_keeps_the_glass_visible_as_a_thin_shell() {
    let eye = default_eye();
    for design in DESIGNS {
        let c = design_cockpit(design);
        c.scene.validate().unwrap();
        let (front, back) = (
            object(&c.scene, COVER_GLASS),
            object(&c.scene, COVER_GLASS_BACK),
        );
        assert_eq!(c.scene.triangles_of(front).count(), 16 * 8 * 2);
        for (f, b) in vertex_range(&c.scene, front).zip(vertex_range(&c.scene, back)) {
            let (p, n) = (c.scene.positions[f], c.scene.normals[f]);
            assert!(n.dot(eye - p) > 0.0, "{}: normal faces away", design.name());
            assert!((c.scene.positions[b] - (p - n * 0.003)).length() < 1e-5);
        }
        let caster = Caster::new(&c.scene);
        let (mut seen, mut total) = (0, 0);
        for t in c.scene.triangles_of(front) {
            let centroid = c.scene.triangle_positions(t).iter().sum::<Vec3>() / 3.0;
            total += 1;
            if caster.object_hit(eye, (centroid - eye).normalize()) == COVER_GLASS {
                seen += 1;
            }
        }
        assert!(
            seen * 100 >= total * 98,
            "{}: only {seen} of {total} glass triangles are visible",
            design.name()
        );
        let has_absorber = c.scene.object_id(GLARE_ABSORBER).is_some();
        assert_eq!(has_absorber, design == GlassDesign::Ellipsoidal);
    }
}

#[test]
fn design_names() {
    let names: Vec<String> = DESIGNS.iter().map(GlassDesign::name).collect();
    assert_eq!(
        names,
        [
            "current",
            "flat",
            "flat-tilted-15",
            "flat-tilted--10",
            "cylindrical-r0.5",
            "ellipsoidal"
        ]
    );
}

#[test]
fn default_design_is_todays_glass_bit_for_bit() {
    let a = &default_cockpit().scene;
    let b = cockpit(&CockpitConfig {
        glass: GlassDesign::Current,
        ..CockpitConfig::default()
    })
    .scene;
    assert_eq!(CockpitConfig::default().glass, GlassDesign::Current);
    assert_eq!(a.triangles.len(), b.triangles.len());
    assert_eq!(a.positions, b.positions);
    assert_eq!(a.normals, b.normals);
    assert_eq!(a.objects.len(), b.objects.len());
}

/// The least-squares plane normal of points (smallest-eigenvalue direction
/// of the covariance, by inverse iteration).
fn plane_fit(points: &[Vec3]) -> (Vec3, Vec3) {
    let centroid = points.iter().sum::<Vec3>() / points.len() as f32;
    let mut m = glam::Mat3::ZERO;
    for p in points {
        let d = *p - centroid;
        m += glam::Mat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    let inv = (m + glam::Mat3::IDENTITY * 1e-9).inverse();
    let mut n = Vec3::new(0.3, 0.5, 0.7);
    for _ in 0..50 {
        n = (inv * n).normalize();
    }
    (centroid, n)
}

#[test]
fn flat_glass_is_planar_and_faces_the_eye() {
    let eye = default_eye();
    let flat = front_glass(&design_cockpit(GlassDesign::Flat));
    let points: Vec<Vec3> = flat.iter().map(|v| v.0).collect();
    let (centroid, n) = plane_fit(&points);
    let off = points
        .iter()
        .map(|p| (*p - centroid).dot(n).abs())
        .fold(0.0, f32::max);
    assert!(off < 1e-5, "{off} m off the plane");
    let to_eye = (eye - centroid).normalize();
    assert!(n.dot(to_eye).abs() > 0.9999, "plane normal {n}");
    for (_, vn) in &flat {
        assert!(vn.dot(to_eye) > 0.9999);
    }
}

#[test]
fn tilted_glass_turns_by_the_angle_top_edge_away() {
    let normal = |c: &Cockpit| {
        let points: Vec<Vec3> = front_glass(c).iter().map(|v| v.0).collect();
        let (_, n) = plane_fit(&points);
        let vn = front_glass(c)[0].1;
        if n.dot(vn) < 0.0 { -n } else { n }
    };
    let flat = normal(&design_cockpit(GlassDesign::Flat));
    for degrees in [15.0_f32, -10.0, 30.0] {
        let tilted = normal(&design_cockpit(GlassDesign::FlatTilted { degrees }));
        let angle = flat.dot(tilted).clamp(-1.0, 1.0).acos().to_degrees();
        assert!((angle - degrees.abs()).abs() < 0.05, "{degrees}: {angle}");
        // Top edge away from the driver: the normal turns upwards.
        assert_eq!(tilted.y > flat.y, degrees > 0.0);
    }
}

#[test]
fn cylindrical_glass_lies_at_the_radius_from_its_horizontal_axis() {
    let c = design_cockpit(GlassDesign::Cylindrical { radius: 0.5 });
    let (eye, centre) = (default_eye(), c.camera.target);
    let to_eye = (eye - centre).normalize();
    let axis_dir = Vec3::Y.cross(to_eye).normalize();
    let axis_point = centre + to_eye * 0.5;
    for (p, n) in front_glass(&c) {
        let d = p - axis_point;
        let radial = d - axis_dir * d.dot(axis_dir);
        let r = radial.length();
        assert!((r - 0.5).abs() < 1e-5, "{p} at {r} m from the axis");
        // Concave towards the driver: normals point at the axis.
        assert!(n.dot(-radial.normalize()) > 0.9999);
    }
}

#[test]
fn ellipsoidal_glass_mirrors_the_eye_onto_the_absorber() {
    let c = design_cockpit(GlassDesign::Ellipsoidal);
    let eye = default_eye();
    let f1 = glare_absorber_focus();
    let (lo, hi) = object_bounds(&c.scene, object(&c.scene, GLARE_ABSORBER));
    assert!(((lo + hi) * 0.5 - f1).length() < 1e-5);
    let mut worst = 0.0_f32;
    for (p, n) in front_glass(&c) {
        let d = (p - eye).normalize();
        let r = d - n * (2.0 * d.dot(n));
        let to_f1 = f1 - p;
        assert!(to_f1.dot(r) > 0.0);
        let miss = (to_f1 - r * to_f1.dot(r)).length();
        worst = worst.max(miss);
    }
    assert!(worst < 0.005, "reflected rays miss F1 by up to {worst} m");
    // Exact focusing also for the default tessellation.
    let fine = cockpit(&CockpitConfig {
        detail: 0.2,
        glass: GlassDesign::Ellipsoidal,
        ..CockpitConfig::default()
    });
    fine.scene.validate().unwrap();
}
