//! Job files through the public API: every key, the defaults, every rejected
//! input (each error must name the file and the offending line), relative OBJ
//! paths and reflector selection.

use std::path::{Path, PathBuf};

use glam::Vec3;
use vtfarm_job::{
    CameraSpec, CockpitConfig, GlassDesign, Job, JobError, LightingSpec, ObjectAliases,
    OutputSettings, ReflectorSelector, SceneSource, ToneCurve, load_job, parse_job,
};
use vtfarm_method::MethodKind;
use vtfarm_scene::{
    Camera, Light, LightKind, Lighting, Material, MaterialId, Object, ObjectId, Scene, Triangle,
    TriangleId,
};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{Quality, Transmission, VertexSettings};

const JOB: &str = "jobs/test.toml";

fn parse(text: &str) -> Job {
    parse_job(text, Path::new(JOB)).unwrap_or_else(|e| panic!("{e}"))
}

fn error(text: &str, origin: &Path) -> String {
    match parse_job(text, origin) {
        Ok(job) => panic!("accepted:\n{text}\n{job:?}"),
        Err(e) => e.to_string(),
    }
}

/// Asserts that `text` is rejected with a message that starts with the job
/// file's `path:line:` and contains every one of `needles`.
fn assert_rejected(text: &str, line: usize, needles: &[&str]) {
    let message = error(text, Path::new(JOB));
    assert!(
        message.starts_with(&format!("{JOB}:{line}:")),
        "wrong place: {message}"
    );
    for needle in needles {
        assert!(
            message.contains(needle),
            "{needle:?} missing from: {message}"
        );
    }
}

const COCKPIT: &str = "[scene]\nbuiltin = \"cockpit\"\n";

/// A directory holding `models/cab.obj` (one triangle) and the path a job
/// file in its `jobs/` subdirectory would have.
fn obj_fixture() -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("models")).unwrap();
    std::fs::create_dir_all(dir.path().join("jobs")).unwrap();
    std::fs::write(
        dir.path().join("models/cab.obj"),
        "o glass\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    let job = dir.path().join("jobs/cab.toml");
    (dir, job)
}

const OBJ_JOB: &str = r#"
[scene]
obj = "../models/cab.obj"
[camera]
eye = [0, 0, 2]
target = [0, 0, 0]
fov_y = 40
width = 64
height = 48
[reflectors]
objects = ["glass"]
"#;

#[test]
fn every_key_is_read() {
    let job = parse(
        r#"
[scene]
builtin = "cockpit"
detail = 2.1
glass_segments = 7

[camera]
eye = [1, 2, 3]
target = [0.5, 1.5, -1]
up = [0, 0, 1]
fov_y = 35.5
width = 320
height = 200

[lighting]
ambient = [0.08, 0.09, 0.1]
background = [0.3, 0.35, 0.45]
[[lighting.lights]]
kind = "point"
position = [0, 2, 0]
color = [1, 0.5, 0.25]
intensity = 3.0
[[lighting.lights]]
kind = "directional"
direction = [0, -1, -1]

[reflectors]
objects = ["cover_glass", "mirror"]
materials = ["glass"]

[quality]
level = "reference"
epsilon = 5.1
pixel_floor = 1.5
flatness = 0.3
max_refine_depth = 9
max_trace_depth = 3
fresnel = true
method = "cubemap-grid"
max_edge = 12.5
transmission = "traced"

[frames]
eyes = [[1, 2, 4], [2, 2, 3]]
"#,
    );
    let expected = Job {
        file: PathBuf::from(JOB),
        scene: SceneSource::Cockpit(CockpitConfig {
            detail: 2.1,
            glass_segments: 7,
            ..CockpitConfig::default()
        }),
        camera: CameraSpec {
            eye: Some(Vec3::new(1.0, 2.0, 3.0)),
            target: Some(Vec3::new(0.5, 1.5, -1.0)),
            up: Some(Vec3::Z),
            fov_y_deg: Some(35.5),
            width: Some(320),
            height: Some(200),
        },
        lighting: LightingSpec {
            lights: Some(vec![
                Light {
                    kind: LightKind::Point {
                        position: Vec3::new(0.0, 2.0, 0.0),
                    },
                    color: Vec3::new(1.0, 0.5, 0.25),
                    intensity: 3.0,
                },
                Light {
                    kind: LightKind::Directional {
                        direction: Vec3::new(0.0, -1.0, -1.0),
                        angular_diameter_deg: 0.0,
                    },
                    color: Vec3::ONE,
                    intensity: 1.0,
                },
            ]),
            ambient: Some(Vec3::new(0.08, 0.09, 0.1)),
            background: Some(Vec3::new(0.3, 0.35, 0.45)),
        },
        reflectors: vec![
            ReflectorSelector::Object("cover_glass".into()),
            ReflectorSelector::Object("mirror".into()),
            ReflectorSelector::Material("glass".into()),
        ],
        trace: TraceSettings {
            max_depth: 3,
            fresnel: true,
            ..Default::default()
        },
        vertex: VertexSettings {
            quality: Quality::Reference,
            epsilon: 5.1 / 255.0,
            pixel_floor: 1.5,
            flatness: 0.3,
            max_depth: 9,
            max_edge: 12.5,
            transmission: Transmission::Traced,
            ..VertexSettings::default()
        },
        method: MethodKind::CubeMapGrid,
        eyes: vec![Vec3::new(1.0, 2.0, 4.0), Vec3::new(2.0, 2.0, 3.0)],
        output: OutputSettings::default(),
        locations: job.locations.clone(),
        materials: Vec::new(),
        camera_name: None,
    };
    assert_eq!(job, expected);
    // The keys checked against the scene later keep their lines.
    let line = |key: &str| job.locations[key].line;
    assert_eq!(line("camera.eye"), 8);
    assert_eq!(line("camera.height"), 13);
    assert_eq!(line("reflectors object \"mirror\""), 28);
    assert_eq!(line("reflectors material \"glass\""), 29);
    assert_eq!(line("frames.eyes[1]"), 44);
}

#[test]
fn a_bare_cockpit_job_takes_every_default() {
    let job = parse(COCKPIT);
    assert_eq!(job.scene, SceneSource::Cockpit(CockpitConfig::default()));
    assert_eq!(job.camera, CameraSpec::default());
    assert_eq!(job.lighting, LightingSpec::default());
    assert_eq!(
        job.reflectors,
        [ReflectorSelector::Object(
            vtfarm_cockpit::COVER_GLASS.into()
        )]
    );
    assert_eq!(job.trace, TraceSettings::default());
    assert_eq!(job.vertex, VertexSettings::default());
    assert!(job.eyes.is_empty());
}

#[test]
fn the_shipped_cockpit_job_parses() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/cockpit.toml");
    let job = load_job(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(job.scene, SceneSource::Cockpit(CockpitConfig::default()));
    // The cockpit's own view, at 720p.
    assert_eq!(
        job.camera,
        CameraSpec {
            width: Some(1280),
            height: Some(720),
            ..CameraSpec::default()
        }
    );
    assert_eq!(job.lighting, LightingSpec::default());
    assert_eq!(
        job.reflectors,
        [ReflectorSelector::Object(
            vtfarm_cockpit::COVER_GLASS.into()
        )]
    );
    assert_eq!(
        job.vertex,
        VertexSettings {
            quality: Quality::Full,
            ..VertexSettings::default()
        }
    );
    assert_eq!(job.trace, TraceSettings::default());
    assert!(job.eyes.is_empty());
}

#[test]
fn an_obj_path_is_relative_to_the_job_file() {
    let (dir, job_path) = obj_fixture();
    std::fs::write(&job_path, OBJ_JOB).unwrap();
    let job = load_job(&job_path).unwrap_or_else(|e| panic!("{e}"));
    let SceneSource::Obj(obj) = &job.scene else {
        panic!("{:?}", job.scene)
    };
    assert_eq!(
        obj.canonicalize().unwrap(),
        dir.path().join("models/cab.obj").canonicalize().unwrap()
    );
    // OBJ files carry no camera: up defaults to +Y, the rest was required.
    assert_eq!(job.camera.up, Some(Vec3::Y));
}

#[test]
fn an_obj_job_loads_with_its_camera_frames_and_default_lighting() {
    let (_dir, job_path) = obj_fixture();
    let text = format!("{OBJ_JOB}[frames]\neyes = [[1, 0, 2]]\n");
    std::fs::write(&job_path, text).unwrap();
    let job = load_job(&job_path).unwrap();
    let loaded = job.load_scene().unwrap_or_else(|e| panic!("{e}"));
    let camera = Camera {
        eye: Vec3::new(0.0, 0.0, 2.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 40.0,
        width: 64,
        height: 48,
    };
    assert_eq!(loaded.camera, camera);
    assert_eq!(
        loaded.frames,
        [
            camera,
            Camera {
                eye: Vec3::new(1.0, 0.0, 2.0),
                ..camera
            }
        ]
    );
    // No light in the file, none in the job: the default daylight, said once.
    assert_eq!(loaded.lighting, Lighting::daylight());
    assert_eq!(loaded.notes.len(), 1, "{:?}", loaded.notes);
    assert!(
        loaded.notes[0].contains("default daylight")
            && loaded.notes[0].contains("[[lighting.lights]]"),
        "{}",
        loaded.notes[0]
    );
    assert_eq!(
        job.reflector_triangles(&loaded.scene, &loaded.object_aliases)
            .unwrap(),
        [TriangleId(0)]
    );
}

#[test]
fn lights_the_job_sets_replace_the_default_daylight() {
    let (_dir, job_path) = obj_fixture();
    for (lighting, lights) in [
        ("[lighting]\nlights = []\n", vec![]),
        (
            "[[lighting.lights]]\nkind = \"point\"\nposition = [0, 1, 0]\n",
            vec![Light {
                kind: LightKind::Point { position: Vec3::Y },
                color: Vec3::ONE,
                intensity: 1.0,
            }],
        ),
    ] {
        std::fs::write(&job_path, format!("{OBJ_JOB}{lighting}")).unwrap();
        let loaded = load_job(&job_path).unwrap().load_scene().unwrap();
        assert_eq!(loaded.lighting.lights, lights);
        assert_eq!(loaded.lighting.ambient, Lighting::default().ambient);
        assert!(loaded.notes.is_empty(), "{:?}", loaded.notes);
    }
    // The daylight's sun and sky are the documented photometric values.
    let daylight = Lighting::daylight();
    let sun = daylight.lights[0];
    let facing = vtfarm_scene::shading::phong(
        &Material::diffuse("white", Vec3::ONE),
        &Lighting {
            ambient: Vec3::ZERO,
            ..daylight.clone()
        },
        Vec3::ZERO,
        -sun.direction_from(Vec3::ZERO).0 * -1.0,
        Vec3::Y,
        |_, _, _| true,
    );
    let expected = vtfarm_scene::DAYLIGHT_SUN_LUX / std::f32::consts::PI;
    let cd_m2 = vtfarm_scene::photometry::cd_m2(facing);
    assert!(
        (cd_m2 / expected - 1.0).abs() < 1e-5,
        "{cd_m2} vs {expected}"
    );
    assert!(
        (vtfarm_scene::photometry::cd_m2(daylight.background) / vtfarm_scene::DAYLIGHT_SKY_CD_M2
            - 1.0)
            .abs()
            < 1e-5
    );
}

/// A directory with `models/car.obj` (objects `body` and `windshield`,
/// materials `paint` and Blender's usual glass export) and `jobs/car.toml`.
fn car_fixture(materials: &str) -> (tempfile::TempDir, PathBuf) {
    let (dir, job) = obj_fixture();
    std::fs::write(
        dir.path().join("models/car.obj"),
        "mtllib car.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\n\
         o body\nusemtl paint\nf 1 2 3\no windshield\nusemtl glass\nf 1 3 2\n",
    )
    .unwrap();
    std::fs::write(
        dir.path().join("models/car.mtl"),
        "newmtl paint\nKd 0.5 0.5 0.5\nKs 0.5 0.5 0.5\nNs 100\nillum 2\n\
         newmtl glass\nKd 0.8 0.8 0.8\nNi 1.45\nd 1.0\nillum 2\n",
    )
    .unwrap();
    let text = OBJ_JOB
        .replace("cab.obj", "car.obj")
        .replace("objects = [\"glass\"]", "objects = [\"windshield\"]");
    std::fs::write(&job, format!("{text}{materials}")).unwrap();
    (dir, job)
}

#[test]
fn a_reflector_with_only_ni_reflects_by_fresnel_with_a_note() {
    let (_dir, job_path) = car_fixture("");
    let loaded = load_job(&job_path).unwrap().load_scene().unwrap();
    let glass = &loaded.scene.materials[loaded.scene.material_id("glass").unwrap().index()];
    let fresnel = (0.45f32 / 2.45).powi(2);
    assert!(
        (glass.reflectance - Vec3::splat(fresnel))
            .abs()
            .max_element()
            < 1e-7
    );
    // The note, and the default light's.
    assert_eq!(loaded.notes.len(), 2, "{:?}", loaded.notes);
    assert!(
        loaded.notes[0].contains("\"glass\"") && loaded.notes[0].contains("Fresnel"),
        "{}",
        loaded.notes[0]
    );
    // Not a reflector: untouched.
    let paint = &loaded.scene.materials[loaded.scene.material_id("paint").unwrap().index()];
    assert_eq!(paint.reflectance, Vec3::ZERO);
}

#[test]
fn material_overrides_replace_the_given_keys() {
    let (_dir, job_path) = car_fixture(
        r#"
[materials."paint"]
kd = [0.1, 0.2, 0.3]
ks = [0, 0, 0]
shininess = 5
emission_cd_m2 = 500
emission_color = [1, 0.5, 0]

[materials."glass"]
kr = [0.08, 0.08, 0.08]
thin = true
"#,
    );
    let job = load_job(&job_path).unwrap();
    let loaded = job.load_scene().unwrap();
    let material = |name| &loaded.scene.materials[loaded.scene.material_id(name).unwrap().index()];
    let paint = material("paint");
    assert_eq!(
        (
            paint.diffuse,
            paint.ambient,
            paint.specular,
            paint.shininess
        ),
        (
            Vec3::new(0.1, 0.2, 0.3),
            Vec3::new(0.1, 0.2, 0.3),
            Vec3::ZERO,
            5.0
        )
    );
    let emitted = vtfarm_scene::photometry::cd_m2(paint.emission);
    assert!((emitted - 500.0).abs() < 1e-2, "{emitted}");
    assert_eq!(paint.emission.y / paint.emission.x, 0.5);
    let glass = material("glass");
    // kr as given (no Fresnel note), thin: transmits the rest, straight.
    assert_eq!(glass.reflectance, Vec3::splat(0.08));
    assert_eq!(glass.transmittance, Vec3::splat(0.92));
    // Its Ni stays for the Fresnel weights; rays do not bend.
    assert!(glass.thin);
    assert_eq!((glass.ior, glass.bending_ior()), (1.45, 1.0));
    assert_eq!(
        loaded.notes.len(),
        1,
        "only the light's: {:?}",
        loaded.notes
    );
    // The cockpit's materials can be changed too.
    let cockpit = parse(&format!(
        "{COCKPIT}[materials.\"{}\"]\nkr = [0.5, 0.5, 0.5]\n",
        vtfarm_cockpit::GLASS_MATERIAL
    ))
    .load_scene()
    .unwrap();
    let id = cockpit
        .scene
        .material_id(vtfarm_cockpit::GLASS_MATERIAL)
        .unwrap();
    assert_eq!(
        cockpit.scene.materials[id.index()].reflectance,
        Vec3::splat(0.5)
    );
}

#[test]
fn unknown_materials_and_keys_are_errors_at_their_line() {
    let (_dir, job_path) = car_fixture("\n[materials.\"windshield\"]\nkr = [0.1, 0.1, 0.1]\n");
    let message = load_job(&job_path)
        .unwrap()
        .load_scene()
        .unwrap_err()
        .to_string();
    assert!(
        message.starts_with(&format!("{}:13:", job_path.display()))
            && message.contains("no material \"windshield\"")
            && message.contains("materials: glass, paint"),
        "{message}"
    );
    let (_dir, job_path) = car_fixture("\n[materials.\"glass\"]\nreflectance = 0.1\n");
    let message = load_job(&job_path).unwrap_err().to_string();
    assert!(
        message.starts_with(&format!("{}:14:", job_path.display()))
            && message.contains("unknown field `reflectance`"),
        "{message}"
    );
    for (table, line, needle) in [
        (
            "kd = [2, 0, 0]",
            14,
            "materials.\"glass\".kd = [2, 0, 0]: must be between 0 and 1",
        ),
        (
            "ior = 0.5",
            14,
            "materials.\"glass\".ior = 0.5: must be finite, 1 to 4",
        ),
        ("emission_color = [1, 1, 1]", 14, "give emission_cd_m2 too"),
        (
            "emission_cd_m2 = 10\nemission_color = [0, 0, 0]",
            15,
            "colour with luminance",
        ),
        ("texture = \"gone.png\"", 14, "no such file"),
    ] {
        let (_dir, job_path) = car_fixture(&format!("\n[materials.\"glass\"]\n{table}\n"));
        let message = load_job(&job_path).unwrap_err().to_string();
        assert!(
            message.starts_with(&format!("{}:{line}:", job_path.display()))
                && message.contains(needle),
            "{needle:?}: {message}"
        );
    }
}

#[test]
fn a_missing_obj_file_names_the_resolved_path_and_the_job_file() {
    let (dir, job_path) = obj_fixture();
    let message = error(&OBJ_JOB.replace("cab.obj", "cabin.obj"), &job_path);
    assert!(
        message.starts_with(&format!("{}:3:", job_path.display())),
        "{message}"
    );
    let resolved = dir.path().join("jobs").join("../models/cabin.obj");
    assert!(
        message.contains(&resolved.display().to_string()),
        "{message}"
    );
}

#[test]
fn a_missing_job_file_is_named() {
    let message = load_job(Path::new("no/such/job.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        message.starts_with("no/such/job.toml: cannot read job file"),
        "{message}"
    );
}

#[test]
fn malformed_toml_is_located() {
    assert_rejected("[scene\nbuiltin = \"cockpit\"\n", 1, &[]);
    assert_rejected("[scene]\nbuiltin = \"cockpit\"\ndetail = = 2\n", 3, &[]);
}

#[test]
fn unknown_keys_and_sections_are_named() {
    assert_rejected(
        &format!("{COCKPIT}[camera]\nwidht = 640\n"),
        4,
        &["widht", "width"],
    );
    assert_rejected(
        &format!("{COCKPIT}[qualty]\nlevel = \"full\"\n"),
        3,
        &["qualty"],
    );
    assert_rejected(
        &format!(
            "{COCKPIT}[[lighting.lights]]\nkind = \"point\"\nposition = [0, 1, 0]\nradius = 1\n"
        ),
        6,
        &["radius"],
    );
}

#[test]
fn the_output_section_sets_the_png_exposure() {
    let job = parse(COCKPIT);
    assert_eq!(job.output, OutputSettings::default());
    // The default is the PNGs vtfarm always wrote: white at 10,000 cd/m².
    assert!(job.output.exposure().is_identity());
    let job = parse(&format!(
        "{COCKPIT}[output]\nwhite_cd_m2 = 40000.0\ntone = \"reinhard\"\n"
    ));
    assert_eq!(job.output.white_cd_m2, 40_000.0);
    assert_eq!(job.output.tone, ToneCurve::Reinhard);
    assert_eq!(job.output.exposure().scale, 0.25);
    assert_rejected(
        &format!("{COCKPIT}[output]\nwhite_cd_m2 = 0.0\n"),
        4,
        &["white_cd_m2", "positive"],
    );
    assert_rejected(
        &format!("{COCKPIT}[output]\ntone = \"filmic\"\n"),
        4,
        &["filmic", "clip", "reinhard"],
    );
    assert_rejected(
        &format!("{COCKPIT}[output]\nexposure = 1.0\n"),
        4,
        &["exposure"],
    );
}

#[test]
fn wrong_types_are_located() {
    assert_rejected(
        &format!("{COCKPIT}[camera]\nwidth = \"640\"\n"),
        4,
        &["string"],
    );
    assert_rejected(&format!("{COCKPIT}[camera]\neye = [0, 1]\n"), 4, &["3"]);
    assert_rejected(&format!("{COCKPIT}[quality]\nfresnel = 1\n"), 4, &["bool"]);
    assert_rejected(
        &format!("{COCKPIT}[quality]\ntransmission = \"glass\"\n"),
        4,
        &["transmission", "raster", "traced"],
    );
    assert_rejected(
        &format!("{COCKPIT}[quality]\nmax_edge = -3\n"),
        4,
        &["max_edge"],
    );
    assert_rejected(&format!("{COCKPIT}[camera]\nheight = -1\n"), 4, &["-1"]);
}

#[test]
fn camera_values_out_of_range_are_located() {
    for (key, value, needle) in [
        ("width", "0", "camera.width = 0"),
        ("height", "16385", "camera.height = 16385"),
        ("fov_y", "0", "camera.fov_y = 0"),
        ("fov_y", "180", "camera.fov_y = 180"),
        ("eye", "[0, nan, 0]", "camera.eye"),
    ] {
        assert_rejected(
            &format!("{COCKPIT}[camera]\nup = [0, 1, 0]\n{key} = {value}\n"),
            5,
            &[needle],
        );
    }
}

#[test]
fn degenerate_views_are_located() {
    assert_rejected(
        &format!("{COCKPIT}[camera]\ntarget = [1, 1, 1]\neye = [1, 1, 1]\nup = [0, 1, 0]\n"),
        5,
        &["camera.eye = [1, 1, 1]: must be away from the target"],
    );
    assert_rejected(
        &format!("{COCKPIT}[camera]\neye = [0, 0, 0]\ntarget = [0, 2, 0]\nup = [0, 1, 0]\n"),
        6,
        &["parallel"],
    );
    assert_rejected(
        &format!(
            "{COCKPIT}[camera]\neye = [0, 0, 1]\ntarget = [0, 0, 0]\nup = [0, 1, 0]\n[frames]\neyes = [\n  [1, 0, 0],\n  [0, 0, 0],\n]\n"
        ),
        10,
        &["frames.eyes[1] = [0, 0, 0]: must be away from the target"],
    );
}

#[test]
fn the_scene_needs_exactly_one_known_source() {
    assert_rejected(
        "[scene]\nbuiltin = \"cockpit\"\nobj = \"cab.obj\"\n",
        3,
        &["not both"],
    );
    assert_rejected(
        "[camera]\nwidth = 8\n[scene]\ndetail = 2.0\n",
        3,
        &["builtin", "obj"],
    );
    assert_rejected(
        "[scene]\nbuiltin = \"truck\"\n",
        2,
        &["\"truck\"", "valid: cockpit"],
    );
    assert_rejected(&format!("{COCKPIT}detail = 0\n"), 3, &["scene.detail = 0"]);
    assert_rejected(
        &format!("{COCKPIT}glass_segments = 0\n"),
        3,
        &["scene.glass_segments = 0"],
    );
    let message = error("[camera]\nwidth = 8\n", Path::new(JOB));
    assert!(
        message.starts_with(&format!("{JOB}: missing [scene]")),
        "{message}"
    );
}

#[test]
fn cockpit_only_keys_are_rejected_for_obj_scenes() {
    let (_dir, job_path) = obj_fixture();
    let message = error(
        &OBJ_JOB.replace("[camera]", "detail = 2.0\n[camera]"),
        &job_path,
    );
    assert!(
        message.starts_with(&format!("{}:4:", job_path.display())),
        "{message}"
    );
    assert!(message.contains("scene.detail"), "{message}");
}

#[test]
fn obj_scenes_need_a_camera_and_reflectors() {
    let (_dir, job_path) = obj_fixture();
    let message = error(
        &OBJ_JOB
            .replace("fov_y = 40\n", "")
            .replace("height = 48\n", ""),
        &job_path,
    );
    assert!(
        message.starts_with(&format!(
            "{}: [camera] needs fov_y, height",
            job_path.display()
        )),
        "{message}"
    );
    let message = error(
        &OBJ_JOB.replace("[reflectors]\nobjects = [\"glass\"]\n", ""),
        &job_path,
    );
    assert!(
        message.starts_with(&format!(
            "{}: an OBJ scene needs [reflectors]",
            job_path.display()
        )),
        "{message}"
    );
}

#[test]
fn lighting_values_are_checked() {
    let light = |body: &str| format!("{COCKPIT}[[lighting.lights]]\n{body}");
    assert_rejected(
        &light("kind = \"point\"\nposition = [0, 1, 0]\nintensity = -1\n"),
        6,
        &["intensity = -1"],
    );
    assert_rejected(
        &light("kind = \"spot\"\n"),
        4,
        &["spot", "point", "directional"],
    );
    assert_rejected(&light("kind = \"point\"\n"), 4, &["needs position"]);
    assert_rejected(
        &light("kind = \"point\"\nposition = [0, 1, 0]\ndirection = [0, -1, 0]\n"),
        6,
        &["not a direction"],
    );
    assert_rejected(
        &light("kind = \"directional\"\ndirection = [0, 0, 0]\n"),
        5,
        &["not zero"],
    );
    assert_rejected(
        &light("kind = \"point\"\nposition = [0, 1, 0]\ncolor = [1, -0.5, 1]\n"),
        6,
        &["color"],
    );
    assert_rejected(
        &format!("{COCKPIT}[lighting]\nambient = [-0.1, 0, 0]\n"),
        4,
        &["lighting.ambient"],
    );
    // Each light costs shadow rays and a shadow map: the one past the bound
    // is named.
    let one_point_light = "[[lighting.lights]]\nkind = \"point\"\nposition = [0, 1, 0]\n";
    let many = |n: usize| format!("{COCKPIT}{}", one_point_light.repeat(n));
    parse(&many(64));
    assert_rejected(&many(65), 4 + 3 * 64, &["lighting.lights", "at most 64"]);
}

/// Lights in lux and cd/m² become render units by the one convention of
/// `vtfarm_scene::photometry`; unit-less keys keep loading as render units.
#[test]
fn photometric_lighting_keys_convert_by_the_convention() {
    use vtfarm_scene::photometry::{self, CD_M2_PER_UNIT};
    let job = parse(&format!(
        "{COCKPIT}[lighting]\nambient_illuminance_lux = 3000\nbackground_luminance_cd_m2 = 5000\n\
         [[lighting.lights]]\nkind = \"directional\"\ndirection = [0, -1, 0]\ncolor = [1, 0.9, 0.8]\nilluminance_lux = 100000\n\
         [[lighting.lights]]\nkind = \"point\"\nposition = [0, 1, 0]\nintensity = 0.5\n"
    ));
    let lights = job.lighting.lights.unwrap();
    let sun = lights[0];
    let facing_white = photometry::cd_m2(sun.radiance());
    assert!(
        (facing_white - 100_000.0 / std::f32::consts::PI).abs() < 0.5,
        "{facing_white}"
    );
    assert_eq!(sun.color, Vec3::new(1.0, 0.9, 0.8));
    assert!(matches!(
        sun.kind,
        LightKind::Directional { angular_diameter_deg, .. }
            if angular_diameter_deg == vtfarm_scene::SUN_ANGULAR_DIAMETER_DEG
    ));
    assert_eq!(lights[1].intensity, 0.5);
    assert_eq!(job.lighting.ambient, Some(photometry::ambient(3000.0)));
    assert_eq!(
        job.lighting.background,
        Some(Vec3::splat(5000.0 / CD_M2_PER_UNIT))
    );
}

#[test]
fn photometric_lighting_keys_are_checked() {
    let light = |body: &str| format!("{COCKPIT}[[lighting.lights]]\n{body}");
    assert_rejected(
        &light(
            "kind = \"directional\"\ndirection = [0, -1, 0]\nilluminance_lux = 1000\nintensity = 2\n",
        ),
        7,
        &["illuminance_lux or intensity", "not both"],
    );
    assert_rejected(
        &light("kind = \"point\"\nposition = [0, 1, 0]\nilluminance_lux = 1000\n"),
        6,
        &["illuminance_lux", "point lights"],
    );
    assert_rejected(
        &light("kind = \"point\"\nposition = [0, 1, 0]\nangular_diameter_deg = 0.5\n"),
        6,
        &["angular_diameter_deg", "directional"],
    );
    assert_rejected(
        &light(
            "kind = \"directional\"\ndirection = [0, -1, 0]\nilluminance_lux = 1000\nangular_diameter_deg = -1\n",
        ),
        7,
        &["angular_diameter_deg = -1", "between 0 and 10"],
    );
    assert_rejected(
        &light("kind = \"directional\"\ndirection = [0, -1, 0]\nilluminance_lux = -5\n"),
        6,
        &["illuminance_lux = -5", "not negative"],
    );
    assert_rejected(
        &light(
            "kind = \"directional\"\ndirection = [0, -1, 0]\ncolor = [0, 0, 0]\nilluminance_lux = 5\n",
        ),
        6,
        &["color", "luminance"],
    );
    assert_rejected(
        &format!(
            "{COCKPIT}[lighting]\nbackground = [0.1, 0.1, 0.1]\nbackground_luminance_cd_m2 = 300\n"
        ),
        5,
        &["background_luminance_cd_m2", "not both"],
    );
    assert_rejected(
        &format!("{COCKPIT}[lighting]\nambient_illuminance_lux = inf\n"),
        4,
        &["ambient_illuminance_lux", "finite"],
    );
}

#[test]
fn quality_values_are_checked() {
    assert_rejected(
        &format!("{COCKPIT}[quality]\nlevel = \"ultra\"\n"),
        4,
        &["\"ultra\"", "preview, refine, full, reference"],
    );
    assert_rejected(
        &format!("{COCKPIT}[quality]\nepsilon = -2\n"),
        4,
        &["quality.epsilon = -2"],
    );
    assert_rejected(
        &format!("{COCKPIT}[quality]\nflatness = 1.5\n"),
        4,
        &["quality.flatness"],
    );
    assert_rejected(
        &format!("{COCKPIT}[quality]\nmax_trace_depth = 0\n"),
        4,
        &["quality.max_trace_depth = 0"],
    );
    assert_rejected(
        &format!("{COCKPIT}[quality]\nmethod = \"raytrace\"\n"),
        4,
        &[
            "\"raytrace\"",
            "vertex, cubemap, cubemap-grid, pvrr, envmap",
        ],
    );
}

#[test]
fn an_empty_reflector_list_is_rejected() {
    assert_rejected(
        &format!("{COCKPIT}[reflectors]\nobjects = []\n"),
        3,
        &["selects nothing"],
    );
}

/// Four triangles over two objects and two materials:
/// 0 glass/paint, 1 dash/mirror, 2 glass/mirror, 3 dash/paint.
fn two_by_two_scene() -> Scene {
    let corners = [Vec3::ZERO, Vec3::X, Vec3::Y];
    let triangle = |i: u32, object, material| Triangle {
        vertices: [3 * i, 3 * i + 1, 3 * i + 2],
        object: ObjectId(object),
        material: MaterialId(material),
    };
    Scene {
        positions: (0..4).flat_map(|_| corners).collect(),
        normals: vec![Vec3::Z; 12],
        triangles: vec![
            triangle(0, 0, 1),
            triangle(1, 1, 0),
            triangle(2, 0, 0),
            triangle(3, 1, 1),
        ],
        objects: vec![
            Object {
                name: "glass".into(),
            },
            Object {
                name: "dash".into(),
            },
        ],
        materials: vec![
            Material::diffuse("mirror", Vec3::ONE),
            Material::diffuse("paint", Vec3::ONE),
        ],
        ..Default::default()
    }
}

fn with_reflectors(reflectors: Vec<ReflectorSelector>) -> Job {
    Job {
        reflectors,
        ..parse(COCKPIT)
    }
}

#[test]
fn reflectors_select_by_object_and_by_material() {
    use ReflectorSelector::{Material, Object};
    let scene = two_by_two_scene();
    scene.validate().unwrap();
    let select = |selectors| {
        let triangles = with_reflectors(selectors)
            .reflector_triangles(&scene, &ObjectAliases::new())
            .unwrap();
        triangles
            .into_iter()
            .map(TriangleId::raw)
            .collect::<Vec<_>>()
    };
    assert_eq!(select(vec![Object("glass".into())]), [0, 2]);
    assert_eq!(select(vec![Material("mirror".into())]), [1, 2]);
    // Sorted and without repeats however the selectors overlap.
    assert_eq!(
        select(vec![Material("mirror".into()), Object("glass".into())]),
        [0, 1, 2]
    );
}

#[test]
fn a_reflector_matching_nothing_lists_the_names() {
    let scene = two_by_two_scene();
    let job = with_reflectors(vec![ReflectorSelector::Object("cover_glass".into())]);
    let err = job
        .reflector_triangles(&scene, &ObjectAliases::new())
        .unwrap_err();
    assert!(matches!(err, JobError::NoReflector { .. }));
    assert_eq!(
        err.to_string(),
        format!(
            "{JOB}: reflector object \"cover_glass\" matches no triangle \
             (objects: dash, glass; materials: mirror, paint)"
        )
    );
}

#[test]
fn frames_put_the_camera_first_and_check_each_eye() {
    let camera = Camera {
        eye: Vec3::new(0.0, 1.0, 1.0),
        target: Vec3::new(0.0, 1.0, 0.0),
        up: Vec3::Y,
        fov_y_deg: 50.0,
        width: 16,
        height: 9,
    };
    // The eyes can only be checked at load time when the target is the cockpit's.
    let job = Job {
        eyes: vec![Vec3::new(1.0, 1.0, 1.0), camera.target],
        ..parse(COCKPIT)
    };
    let message = job.frames(&camera).unwrap_err().to_string();
    assert!(
        message.starts_with(&format!("{JOB}: frames.eyes[1]")),
        "{message}"
    );
    let job = Job {
        eyes: vec![Vec3::new(1.0, 1.0, 1.0)],
        ..job
    };
    let frames = job.frames(&camera).unwrap();
    assert_eq!(
        frames,
        [
            camera,
            Camera {
                eye: Vec3::new(1.0, 1.0, 1.0),
                ..camera
            }
        ]
    );
}

#[test]
fn specs_override_only_the_given_keys() {
    let base = Camera {
        eye: Vec3::ONE,
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 50.0,
        width: 8,
        height: 6,
    };
    let spec = CameraSpec {
        fov_y_deg: Some(30.0),
        width: Some(640),
        ..CameraSpec::default()
    };
    assert_eq!(
        spec.over(&base),
        Camera {
            fov_y_deg: 30.0,
            width: 640,
            ..base
        }
    );
    assert_eq!(spec.complete(), Err(vec!["eye", "target", "up", "height"]));
    let lighting = Lighting {
        lights: Vec::new(),
        ambient: Vec3::splat(0.2),
        background: Vec3::X,
    };
    let spec = LightingSpec {
        background: Some(Vec3::Z),
        ..LightingSpec::default()
    };
    assert_eq!(
        spec.over(lighting.clone()),
        Lighting {
            background: Vec3::Z,
            ..lighting
        }
    );
}

#[test]
fn a_broken_obj_file_is_reported_with_the_job_file() {
    let (dir, job_path) = obj_fixture();
    std::fs::write(&job_path, OBJ_JOB).unwrap();
    let job = load_job(&job_path).unwrap();
    std::fs::write(dir.path().join("models/cab.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();
    let error = job.load_scene().unwrap_err();
    let message = error.to_string();
    assert!(
        message.starts_with(&format!(
            "{}: cannot load the OBJ scene: ",
            job_path.display()
        )),
        "{message}"
    );
    assert!(message.contains("cab.obj"), "{message}");
    // The OBJ message is part of this one, not also a source that printing
    // the chain would repeat.
    assert!(std::error::Error::source(&error).is_none());
}

#[test]
fn cover_glass_designs_are_chosen_by_name() {
    let design = |extra: &str| match parse(&format!("{COCKPIT}{extra}")).scene {
        SceneSource::Cockpit(c) => c.glass,
        other => panic!("{other:?}"),
    };
    assert_eq!(design(""), GlassDesign::Current);
    assert_eq!(design("glass = \"flat\"\n"), GlassDesign::Flat);
    assert_eq!(
        design("glass = \"ellipsoidal\"\n"),
        GlassDesign::Ellipsoidal
    );
    assert_eq!(
        design("glass = \"flat-tilted\"\nglass_tilt = 15.0\n"),
        GlassDesign::FlatTilted { degrees: 15.0 }
    );
    assert_eq!(
        design("glass = \"cylindrical\"\nglass_radius = 0.5\n"),
        GlassDesign::Cylindrical { radius: 0.5 }
    );
    assert_rejected(
        &format!("{COCKPIT}glass = \"round\"\n"),
        3,
        &["scene.glass", "round", "ellipsoidal"],
    );
    assert_rejected(
        &format!("{COCKPIT}glass = \"flat-tilted\"\n"),
        3,
        &["needs scene.glass_tilt"],
    );
    assert_rejected(
        &format!("{COCKPIT}glass = \"flat-tilted\"\nglass_tilt = 90.0\n"),
        4,
        &["scene.glass_tilt", "-60 and 60"],
    );
    assert_rejected(
        &format!("{COCKPIT}glass = \"cylindrical\"\nglass_radius = 0.01\n"),
        4,
        &["scene.glass_radius"],
    );
}

#[test]
fn reflectors_without_reflectance_are_named_with_their_fix() {
    use vtfarm_job::{DullReflector, dull_reflectors};
    let mirror = Material {
        reflectance: Vec3::splat(0.5),
        ..Material::diffuse("mirror", Vec3::ONE)
    };
    let triangle = |object, material| Triangle {
        vertices: [0, 1, 2],
        object: ObjectId(object),
        material: MaterialId(material),
    };
    let scene = Scene {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        normals: vec![Vec3::Z; 3],
        triangles: vec![
            triangle(0, 0),
            triangle(0, 1),
            triangle(1, 1),
            triangle(0, 0),
        ],
        objects: vec![Object { name: "car".into() }, Object { name: "bus".into() }],
        materials: vec![Material::diffuse("glass", Vec3::ONE), mirror],
        ..Default::default()
    };
    let dull = dull_reflectors(&scene, &[0, 1, 2, 3].map(TriangleId));
    assert_eq!(
        dull,
        [DullReflector {
            object: "car".into(),
            material: "glass".into(),
            specular: 0.0,
            ior: 1.0,
        }]
    );
    let message = dull[0].to_string();
    // It names what is missing and the job's fix.
    for needle in [
        "\"car\"",
        "\"glass\"",
        "no Kr",
        "no illum 3, 4 or 6 with Ks",
        "Ni 1 is not above 1",
        "[materials.\"glass\"] kr = [r, g, b] or ior = 1.5",
    ] {
        assert!(message.contains(needle), "{needle:?} missing: {message}");
    }
    // A highlight is not a reflection: said so.
    let mut glossy = scene.clone();
    glossy.materials[0].specular = Vec3::splat(0.5);
    let message = dull_reflectors(&glossy, &[TriangleId(0)])[0].to_string();
    assert!(
        message.contains("its Ks 0.5 is only a highlight"),
        "{message}"
    );
    assert!(dull_reflectors(&scene, &[1, 2].map(TriangleId)).is_empty());
}

/// Values that would run away: each is refused at its line by the
/// settings' own bounds (the wire conversion calls the same `validate`).
#[test]
fn values_that_would_run_away_are_refused_at_their_line() {
    let check = |section: &str, key: &str, needle: &str| {
        assert_rejected(&format!("{COCKPIT}{section}\n{key}\n"), 4, &[needle]);
    };
    check(
        "[quality]",
        "max_refine_depth = 4294967295",
        "quality.max_refine_depth = 4294967295: must be 0 to 32",
    );
    check(
        "[quality]",
        "pixel_floor = 0",
        "quality.pixel_floor = 0: must be finite and at least 0.5",
    );
    check(
        "[quality]",
        "epsilon = -1",
        "quality.epsilon = -1: must be finite",
    );
    check(
        "[quality]",
        "flatness = 1.5",
        "quality.flatness = 1.5: must be between 0 and 1",
    );
    check(
        "[quality]",
        "max_trace_depth = 65",
        "quality.max_trace_depth = 65: must be 1 to 64",
    );
    check(
        "[camera]",
        "eye = [1e22, 0, 0]",
        "camera.eye = [10000000000000000000000, 0, 0]: must be finite and within ±1e6 m",
    );
    // `COCKPIT` ends in [scene]: these keys belong to it.
    assert_rejected(
        &format!("{COCKPIT}detail = 1e6\n"),
        3,
        &["scene.detail = 1000000: must be 0.01 to 10"],
    );
    assert_rejected(
        &format!("{COCKPIT}glass_segments = 1000000\n"),
        3,
        &["scene.glass_segments = 1000000: must be 1 to 1024"],
    );
    assert_rejected(
        &format!("{COCKPIT}[camera]\nwidth = 16384\nheight = 16384\n"),
        5,
        &["camera.width × camera.height = 16384 × 16384: must be at most 16777216 pixels"],
    );
    // A floor of 0.5 with epsilon 0 is bounded, so accepted.
    let job = parse(&format!(
        "{COCKPIT}[quality]\npixel_floor = 0.5\nepsilon = 0\n"
    ));
    assert_eq!((job.vertex.pixel_floor, job.vertex.epsilon), (0.5, 0.0));
}

/// Camera and reflector errors found against the scene name their line.
#[test]
fn errors_found_against_the_scene_name_the_line() {
    // An extra eye at the cockpit's default target: parsing cannot tell
    // (the target comes from the scene), resolving the frames can.
    let text = format!(
        "{COCKPIT}[camera]\nwidth = 64\nheight = 48\n[frames]\neyes = [[0, 0, 0], [-0.55, 1.05, -0.6]]\n[reflectors]\nobjects = [\"cover_glass\", \"nothing_here\"]\n"
    );
    let job = parse(&text);
    let message = job.load_scene().expect_err("eye at the target").to_string();
    assert!(
        message.starts_with(&format!("{JOB}:7:")) && message.contains("frames.eyes[1]"),
        "{message}"
    );
    let scene = job.scene_only().expect("the cockpit").scene;
    let message = job
        .reflector_triangles(&scene, &ObjectAliases::new())
        .expect_err("no such object")
        .to_string();
    assert!(
        message.starts_with(&format!("{JOB}:9:")) && message.contains("\"nothing_here\""),
        "{message}"
    );
    // A size given on the command line is checked against the memory bound too.
    let camera = vtfarm_scene::Camera {
        width: 16384,
        height: 16384,
        ..vtfarm_cockpit::cockpit(&CockpitConfig::default()).camera
    };
    let message = job
        .frames(&camera)
        .expect_err("too many pixels")
        .to_string();
    assert!(message.contains("at most 16777216 pixels"), "{message}");
}

#[test]
fn a_gltf_scene_takes_its_camera_by_name_and_reflectors_by_node() {
    let fixture =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../scene/tests/data/gltf/instanced.glb");
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(&fixture, dir.path().join("car.glb")).unwrap();
    let job_path = dir.path().join("job.toml");
    let write = |camera: &str| {
        std::fs::write(
            &job_path,
            format!(
                "[scene]\ngltf = \"car.glb\"\n[camera]\n{camera}width = 64\nheight = 48\n\
                 [reflectors]\nobjects = [\"right\"]\n"
            ),
        )
        .unwrap();
        load_job(&job_path)
    };
    let job = write("camera = \"driver\"\nfov_y = 30\n").unwrap_or_else(|e| panic!("{e}"));
    let loaded = job.load_scene().unwrap_or_else(|e| panic!("{e}"));
    // The file's camera under the job's keys.
    assert_eq!(loaded.camera.eye, Vec3::new(0.0, 1.0, 2.0));
    assert_eq!((loaded.camera.fov_y_deg, loaded.camera.width), (30.0, 64));
    let right = loaded.scene.object_id("right").unwrap();
    let chosen = job
        .reflector_triangles(&loaded.scene, &loaded.object_aliases)
        .unwrap();
    assert_eq!(chosen.len(), 2);
    assert!(
        chosen
            .iter()
            .all(|&t| loaded.scene.triangles[t.index()].object == right)
    );
    // A named reflector with glTF's default ior 1.5 reflects by Fresnel.
    let paint = &loaded.scene.materials[loaded.scene.material_id("paint").unwrap().index()];
    assert!((paint.reflectance - Vec3::splat(0.04)).abs().max_element() < 1e-6);
    // An unknown camera names the file's cameras, at its line.
    let message = write("camera = \"rear\"\n")
        .unwrap()
        .load_scene()
        .unwrap_err()
        .to_string();
    assert!(
        message.starts_with(&format!("{}:4:", job_path.display()))
            && message.contains("cameras: driver"),
        "{message}"
    );
    // Without a camera name the view keys are needed, as for OBJ.
    let message = write("").unwrap_err().to_string();
    assert!(
        message.contains("[camera] needs eye, target, fov_y"),
        "{message}"
    );
}

/// glTF reflectors by node, by the mesh a named node hides, or by material:
/// `instanced.glb` has nodes "left" and "right", both instancing mesh
/// "panel" (two triangles each) in material "paint".
#[test]
fn gltf_reflectors_are_picked_by_node_mesh_or_material_name() {
    let fixture =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../scene/tests/data/gltf/instanced.glb");
    let dir = tempfile::tempdir().unwrap();
    std::fs::copy(&fixture, dir.path().join("car.glb")).unwrap();
    let job_path = dir.path().join("job.toml");
    let chosen = |reflectors: &str| {
        std::fs::write(
            &job_path,
            format!(
                "[scene]\ngltf = \"car.glb\"\n[camera]\ncamera = \"driver\"\nwidth = 64\n\
                 height = 48\n[reflectors]\n{reflectors}\n"
            ),
        )
        .unwrap();
        let job = load_job(&job_path).unwrap_or_else(|e| panic!("{e}"));
        let loaded = job.load_scene().unwrap_or_else(|e| panic!("{e}"));
        let objects = |triangles: &[TriangleId]| -> Vec<String> {
            let mut names: Vec<String> = (triangles.iter())
                .map(|&t| loaded.scene.triangles[t.index()].object)
                .map(|o| loaded.scene.objects[o.index()].name.clone())
                .collect();
            names.dedup();
            names
        };
        let triangles = job.reflector_triangles(&loaded.scene, &loaded.object_aliases);
        triangles.map(|t| (t.len(), objects(&t)))
    };
    let both = (4, vec!["left".to_owned(), "right".to_owned()]);
    assert_eq!(
        chosen("objects = [\"right\"]").unwrap(),
        (2, vec!["right".to_owned()])
    );
    assert_eq!(chosen("objects = [\"panel\"]").unwrap(), both);
    assert_eq!(chosen("materials = [\"paint\"]").unwrap(), both);
    // A misspelt name lists the nodes' and the meshes' names.
    let message = chosen("objects = [\"pannel\"]").unwrap_err().to_string();
    assert!(
        message.starts_with(&format!("{}:8:", job_path.display()))
            && message.contains("objects: left, panel, right"),
        "{message}"
    );
    // The study's path (the scene without camera) knows the second names too.
    let job = load_job(&job_path).unwrap();
    let scene = job.scene_only().unwrap();
    assert_eq!(scene.object_aliases["panel"].len(), 2);
}

/// A job or study file that is `/dev/zero` or a FIFO without a writer is
/// refused at once (not read without end, not waited on), naming the file
/// and what it is.
#[test]
fn a_job_file_that_is_a_device_or_a_fifo_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("job.toml");
    let made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap();
    assert!(made.success());
    for (path, kind) in [
        (PathBuf::from("/dev/zero"), "a character device"),
        (fifo, "a FIFO"),
    ] {
        let (done, result) = std::sync::mpsc::channel();
        let file = path.clone();
        std::thread::spawn(move || {
            let job = load_job(&file).map(|_| ()).map_err(|e| e.to_string());
            let study = vtfarm_job::study::load_study(&file)
                .map(|_| ())
                .map_err(|e| e.to_string());
            let _ = done.send([job, study]);
        });
        let outcomes = result
            .recv_timeout(std::time::Duration::from_secs(30))
            .expect("refused without blocking");
        for outcome in outcomes {
            let error = outcome.unwrap_err();
            assert!(
                error.contains(&path.display().to_string())
                    && error.contains(&format!("{kind}, not a regular file")),
                "{error}"
            );
        }
    }
}
