//! End-to-end tests of the `vtfarm` command: a render of the default job to
//! PNG with every auxiliary output, the OBJ export read back as a job, and
//! bad inputs refused with a located message.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn vtfarm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vtfarm"))
        .args(args)
        .output()
        .expect("the vtfarm binary runs")
}

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(path)
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn render_writes_the_image_and_documented_aux_files() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("cockpit.png");
    let aux = dir.path().join("aux");
    let out = vtfarm(&[
        "render",
        repo("configs/cockpit.toml").to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
        "--width",
        "192",
        "--height",
        "108",
        "--aux",
        aux.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    for row in ["visible vertices", "traced samples", "triangle filling"] {
        assert!(stdout.contains(row), "closing table lacks {row}: {stdout}");
    }
    let image = image::open(&png).unwrap().to_rgb8();
    assert_eq!(image.dimensions(), (192, 108));

    let mask = image::open(aux.join("mask.png")).unwrap().to_luma8();
    let glass_pixels = mask.pixels().filter(|p| p.0[0] == 255).count();
    assert!(
        glass_pixels > 500,
        "the cover glass is on screen: {glass_pixels} pixels"
    );
    assert!(mask.pixels().all(|p| p.0[0] == 0 || p.0[0] == 255));

    let objects = image::open(aux.join("reflected_objects.png")).unwrap();
    let objects = objects.as_luma16().expect("a 16-bit grayscale PNG");
    let names: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(aux.join("objects.json")).unwrap()).unwrap();
    let name_of = |value: u16| {
        names
            .iter()
            .find(|e| e["value"] == value as u64)
            .and_then(|e| e["name"].as_str())
            .map(str::to_owned)
    };
    let mut seen = std::collections::BTreeSet::new();
    for (p, m) in objects.pixels().zip(mask.pixels()) {
        if m.0[0] == 0 {
            assert_eq!(p.0[0], 0, "only reflector pixels mirror something");
        } else if p.0[0] != 0 {
            seen.insert(name_of(p.0[0]).expect("every value is named in objects.json"));
        }
    }
    assert!(
        seen.contains("side_window_left"),
        "the glass mirrors the left side window: {seen:?}"
    );
    assert_colored_object_map(&aux, objects, &mask);
    for file in [
        "reflected.png",
        "reflected.npy",
        "transmitted.png",
        "transmitted.npy",
        "wireframe.png",
    ] {
        assert!(aux.join(file).is_file(), "{file} written");
    }
}

/// `reflected_objects_map.png`, the coloured map beside the 16-bit one:
/// the frame at the same pixels (a legend to its right), black off the
/// glass, and one visible colour per mirrored object, a different one for
/// each of the most common (the palette has ten).
fn assert_colored_object_map(
    aux: &Path,
    objects: &image::ImageBuffer<image::Luma<u16>, Vec<u16>>,
    mask: &image::GrayImage,
) {
    let map = image::open(aux.join("reflected_objects_map.png"))
        .unwrap()
        .to_rgb8();
    let (w, h) = objects.dimensions();
    assert!(
        map.width() > w && map.height() >= h,
        "a legend beside the frame"
    );
    let mut color_of = std::collections::BTreeMap::new();
    for y in 0..h {
        for x in 0..w {
            let color = map.get_pixel(x, y).0;
            let value = objects.get_pixel(x, y).0[0];
            if mask.get_pixel(x, y).0[0] == 0 {
                assert_eq!(color, [0, 0, 0], "black off the glass at ({x}, {y})");
            } else if value != 0 {
                assert!(
                    color.iter().any(|&c| c > 40),
                    "visible at ({x}, {y}): {color:?}"
                );
                let first = *color_of.entry(value).or_insert(color);
                assert_eq!(color, first, "object {value} has one colour");
            }
        }
    }
    let colors: std::collections::BTreeSet<[u8; 3]> = color_of.values().copied().collect();
    assert_eq!(
        colors.len(),
        color_of.len().min(10),
        "a colour per object: {color_of:?}"
    );
}

#[test]
fn exported_cockpit_renders_as_an_obj_job() {
    let dir = tempfile::tempdir().unwrap();
    let out = vtfarm(&[
        "scene",
        "export",
        "cockpit",
        "-o",
        dir.path().to_str().unwrap(),
        "--detail",
        "0.2",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let job = dir.path().join("job.toml");
    std::fs::write(
        &job,
        r#"
[scene]
obj = "cockpit.obj"
[camera]
eye = [-0.55, 1.4, 0.1]
target = [-0.55, 1.05, -0.6]
fov_y = 50.0
width = 96
height = 54
[reflectors]
materials = ["glass"]
[quality]
level = "preview"
"#,
    )
    .unwrap();
    let png = dir.path().join("obj.png");
    let out = vtfarm(&["render", job.to_str().unwrap(), "-o", png.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(image::open(&png).unwrap().to_rgb8().dimensions(), (96, 54));
}

#[test]
fn the_cockpit_exported_to_glb_renders_byte_identical_to_its_obj_export() {
    let dir = tempfile::tempdir().unwrap();
    for format in ["obj", "glb"] {
        let out = vtfarm(&[
            "scene",
            "export",
            "cockpit",
            "-o",
            dir.path().to_str().unwrap(),
            "--detail",
            "0.2",
            "--format",
            format,
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
    }
    // The same job on either file, with the cockpit's own kind of light.
    let job = |scene: &str| {
        format!(
            r#"
[scene]
{scene}
[camera]
eye = [-0.55, 1.4, 0.1]
target = [-0.55, 1.05, -0.6]
fov_y = 50.0
width = 96
height = 54
[[lighting.lights]]
kind = "directional"
direction = [0.45, -0.85, -0.15]
illuminance_lux = 100000
[reflectors]
materials = ["glass"]
[quality]
level = "full"
"#
        )
    };
    let mut images = Vec::new();
    for (name, scene) in [
        ("obj", "obj = \"cockpit.obj\""),
        ("glb", "gltf = \"cockpit.glb\""),
    ] {
        let file = dir.path().join(format!("{name}.toml"));
        std::fs::write(&file, job(scene)).unwrap();
        let png = dir.path().join(format!("{name}.png"));
        let out = vtfarm(&[
            "render",
            file.to_str().unwrap(),
            "-o",
            png.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        assert!(!text(&out.stderr).contains("warn"), "{}", text(&out.stderr));
        images.push(image::open(&png).unwrap().to_rgb8());
    }
    assert_eq!(images[0].dimensions(), (96, 54));
    assert!(images[0] == images[1], "the GLB export renders differently");
}

/// A lit quad `[materials."paint"]` can recolour, in front of the camera.
const PAINTED_OBJ: &str = "mtllib p.mtl\no quad\nusemtl paint\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\nf 1//1 3//1 4//1\n";

fn painted_job(extra: &str) -> String {
    format!(
        "[scene]\nobj = \"p.obj\"\n[camera]\neye = [0, 0, 2]\ntarget = [0, 0, 0]\nfov_y = 40\n\
         width = 32\nheight = 24\n[reflectors]\nobjects = [\"quad\"]\n{extra}"
    )
}

/// Renders the painted quad with `job` and returns the centre pixel and stderr.
fn render_painted(dir: &Path, job: &str) -> ([u8; 3], String) {
    std::fs::write(dir.join("p.obj"), PAINTED_OBJ).unwrap();
    std::fs::write(dir.join("p.mtl"), "newmtl paint\nKd 0.5 0.5 0.5\n").unwrap();
    std::fs::write(dir.join("p.toml"), job).unwrap();
    let png = dir.join("p.png");
    let out = vtfarm(&[
        "render",
        dir.join("p.toml").to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let image = image::open(&png).unwrap().to_rgb8();
    (image.get_pixel(16, 12).0, text(&out.stderr))
}

#[test]
fn a_scene_without_light_gets_the_default_daylight_and_one_warning() {
    let dir = tempfile::tempdir().unwrap();
    let (pixel, stderr) = render_painted(dir.path(), &painted_job(""));
    let warnings: Vec<&str> = stderr.lines().filter(|l| l.contains("WARN")).collect();
    assert_eq!(warnings.len(), 2, "{stderr}");
    let light: Vec<&&str> = warnings
        .iter()
        .filter(|l| l.contains("default daylight"))
        .collect();
    assert_eq!(light.len(), 1, "{stderr}");
    assert!(light[0].contains("[[lighting.lights]]"), "{}", light[0]);
    // The other is the quad's reflectance, which the job did not give.
    assert!(stderr.contains("reflects nothing"), "{stderr}");
    // Lit as stated: Kd 0.5 under the sun (at its angle to the quad's
    // normal, +Z) plus the sky's ambient term.
    let sun = vtfarm_scene::DAYLIGHT_SUN_DIRECTION.normalize();
    let lux = vtfarm_scene::DAYLIGHT_SUN_LUX * (-sun.z);
    let cd_m2 = 0.5 * lux / std::f32::consts::PI + 0.5 * vtfarm_scene::DAYLIGHT_SKY_CD_M2;
    let expected = vtfarm_imaging::encode_srgb8(glam::Vec3::splat(cd_m2 / 10_000.0));
    assert!(
        pixel.iter().zip(expected).all(|(&a, b)| a.abs_diff(b) <= 1),
        "{pixel:?} vs {expected:?}"
    );
}

#[test]
fn a_material_override_changes_the_image_as_stated() {
    let dir = tempfile::tempdir().unwrap();
    let lit = "[lighting]\nlights = []\nambient = [1, 1, 1]\n";
    let (before, _) = render_painted(dir.path(), &painted_job(lit));
    let (after, _) = render_painted(
        dir.path(),
        &painted_job(&format!(
            "{lit}[materials.\"paint\"]\nkd = [0.2, 0.4, 0.8]\n"
        )),
    );
    // Ambient light 1 shows the ambient reflectance, which kd also sets.
    assert_eq!(before, vtfarm_imaging::encode_srgb8(glam::Vec3::splat(0.5)));
    assert_eq!(
        after,
        vtfarm_imaging::encode_srgb8(glam::Vec3::new(0.2, 0.4, 0.8))
    );
}

/// Runs `vtfarm SUBCOMMAND DIR/FILE -o DIR/OUTPUT` on `contents` written
/// into `file` and returns stderr, asserting that it failed cleanly and
/// wrote nothing at `output`.
fn refused(dir: &Path, subcommand: &str, file: &str, contents: &str, output: &str) -> String {
    let path = dir.join(file);
    std::fs::write(&path, contents).unwrap();
    let output = dir.join(output);
    let out = vtfarm(&[
        subcommand,
        path.to_str().unwrap(),
        "-o",
        output.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(!output.exists(), "nothing written");
    let err = text(&out.stderr);
    assert!(!err.contains("panicked"), "{err}");
    err
}

/// Renders `job` (written into `dir` as bad.toml) and returns stderr,
/// asserting that the render failed cleanly and wrote no image.
fn refused_render(dir: &Path, job: &str) -> String {
    refused(dir, "render", "bad.toml", job, "x.png")
}

#[test]
fn bad_job_and_obj_files_are_refused_with_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let err = refused_render(
        dir.path(),
        "[scene]\nbuiltin = \"cockpit\"\n[camera]\nwidht = 5\n",
    );
    assert!(err.contains("bad.toml:4"), "names file and line: {err}");

    // Each message names the OBJ file and line, and each cause appears
    // once: no `file:line: msg: file:line: msg` chain.
    for (obj, location, cause) in [
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 zero\nf 1 2 3\n",
            "broken.obj:3",
            "zero",
        ),
        (
            "mtllib gone.mtl\n",
            "broken.obj:1: cannot read material library",
            "No such file",
        ),
    ] {
        std::fs::write(dir.path().join("broken.obj"), obj).unwrap();
        let err = refused_render(
            dir.path(),
            "[scene]\nobj = \"broken.obj\"\n[camera]\neye = [0, 0, 2]\ntarget = [0, 0, 0]\nfov_y = 40\nwidth = 8\nheight = 8\n[reflectors]\nobjects = [\"a\"]\n",
        );
        assert_eq!(err.matches(location).count(), 1, "{err}");
        assert_eq!(err.matches(cause).count(), 1, "{err}");
    }
}

/// Runs `vtfarm study` on `study` (written into `dir` next to a base job)
/// and returns stderr, asserting that it failed before any output.
fn refused_study(dir: &Path, study: &str) -> String {
    std::fs::write(
        dir.join("job.toml"),
        "[scene]\nbuiltin = \"cockpit\"\ndetail = 0.3\n",
    )
    .unwrap();
    refused(dir, "study", "bad-study.toml", study, "out")
}

#[test]
fn bad_study_files_are_refused_before_rendering() {
    let dir = tempfile::tempdir().unwrap();
    let head = "[study]\njob = \"job.toml\"\n";
    let flat = "[[variants]]\nname = \"flat\"\nglass = \"flat\"\n";
    let err = refused_study(
        dir.path(),
        &format!("{head}[eyes]\npoints = [[-0.55, 1.4, 0.1]]\nresolution = 3\n{flat}"),
    );
    assert!(
        err.contains("bad-study.toml:5") && err.contains("resolution"),
        "{err}"
    );
    let err = refused_study(
        dir.path(),
        &format!("{head}[eyes.ellipse]\ncentre = [-0.55, 1.4, 0.1]\nsemi_axes = [0, 0, 0]\n{flat}"),
    );
    assert!(
        err.contains("bad-study.toml:5") && err.contains("eye ellipse is empty"),
        "{err}"
    );
    let err = refused_study(
        dir.path(),
        &format!(
            "{head}[eyes]\npoints = [[-0.55, 1.4, 0.1]]\n[[variants]]\nname = \"b\"\nobj = \"b.obj\"\n"
        ),
    );
    assert!(
        err.contains("bad-study.toml:7") && err.contains("no such file") && err.contains("b.obj"),
        "{err}"
    );
    // A metrics object the variant's scene lacks is caught while planning.
    let err = refused_study(
        dir.path(),
        &format!(
            "{head}[eyes]\npoints = [[-0.55, 1.4, 0.1]]\n{flat}[metrics]\nmarking_objects = [\"ticks\"]\n"
        ),
    );
    assert!(
        err.contains("marking_objects") && err.contains("\"ticks\"") && err.contains("needles"),
        "{err}"
    );
}

#[test]
fn compare_measures_every_method_against_the_reference() {
    let dir = tempfile::tempdir().unwrap();
    let out = vtfarm(&[
        "compare",
        repo("configs/cockpit.toml").to_str().unwrap(),
        "-o",
        dir.path().to_str().unwrap(),
        "--width",
        "192",
        "--height",
        "108",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    let methods = [
        "reference",
        "preview",
        "refine",
        "full",
        "cubemap",
        "cubemap-grid",
        "pvrr",
        "envmap",
    ];
    for method in methods {
        assert!(
            stdout.lines().any(|l| l.starts_with(method)),
            "{method} in {stdout}"
        );
        let png = image::open(dir.path().join(format!("{method}.png"))).unwrap();
        assert_eq!((png.width(), png.height()), (192, 108));
    }
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("compare.json")).unwrap()).unwrap();
    let rows = json.as_array().unwrap();
    assert_eq!(rows.len(), methods.len());
    assert_eq!(rows[0]["mean_abs"], 0.0, "the reference against itself");
    assert!(
        rows[4]["searches"].as_u64().unwrap() > 0,
        "cube maps search"
    );
    let sheet = image::open(dir.path().join("sheet.png")).unwrap();
    assert!(sheet.width() > 8 * 40);
}

#[test]
fn render_runs_the_method_the_job_names_through_the_farm() {
    let dir = tempfile::tempdir().unwrap();
    let job = dir.path().join("pvrr.toml");
    std::fs::write(
        &job,
        "[scene]\nbuiltin = \"cockpit\"\ndetail = 0.3\n[camera]\nwidth = 160\nheight = 90\n[quality]\nmethod = \"pvrr\"\n",
    )
    .unwrap();
    let png = dir.path().join("pvrr.png");
    let aux = dir.path().join("aux");
    let out = vtfarm(&[
        "render",
        job.to_str().unwrap(),
        "-o",
        png.to_str().unwrap(),
        "--aux",
        aux.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(
        stdout.lines().any(|l| l.trim() == "method  pvrr"),
        "{stdout}"
    );
    assert!(image::open(&png).is_ok());
    for file in [
        "mask.png",
        "reflected.npy",
        "reflected_objects.png",
        "objects.json",
    ] {
        assert!(aux.join(file).is_file(), "{file}");
    }
    assert!(
        !aux.join("wireframe.png").exists(),
        "no refined faces without vertex tracing"
    );
}

/// A saddle z = x² − y² over [-1, 1]² as OBJ (with its normals), for the
/// cube-map method's shape warning.
fn saddle_obj() -> String {
    let n = 8;
    let mut obj = String::from("o saddle\n");
    for j in 0..=n {
        for i in 0..=n {
            let (x, y) = (
                2.0 * i as f32 / n as f32 - 1.0,
                2.0 * j as f32 / n as f32 - 1.0,
            );
            obj += &format!("v {x} {y} {}\n", 0.3 * (x * x - y * y));
            let normal = [-0.6 * x, 0.6 * y, 1.0];
            obj += &format!("vn {} {} {}\n", normal[0], normal[1], normal[2]);
        }
    }
    for j in 0..n {
        for i in 0..n {
            let v = |i: usize, j: usize| j * (n + 1) + i + 1;
            let (a, b, c, d) = (v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1));
            obj += &format!("f {a}//{a} {b}//{b} {c}//{c}\nf {a}//{a} {c}//{c} {d}//{d}\n");
        }
    }
    obj
}

#[test]
fn cube_maps_warn_about_a_reflector_that_is_neither_convex_nor_concave() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("saddle.obj"), saddle_obj()).unwrap();
    let job = dir.path().join("saddle.toml");
    std::fs::write(
        &job,
        "[scene]\nobj = \"saddle.obj\"\n[camera]\neye = [0, -2, 3]\ntarget = [0, 0, 0]\nfov_y = 40\nwidth = 64\nheight = 48\n[reflectors]\nobjects = [\"saddle\"]\n[quality]\nmethod = \"cubemap\"\n",
    )
    .unwrap();
    let png = dir.path().join("saddle.png");
    let out = vtfarm(&["render", job.to_str().unwrap(), "-o", png.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let err = text(&out.stderr);
    assert!(
        err.contains("reflector \"saddle\"") && err.contains("neither convex nor concave"),
        "{err}"
    );
    // The cockpit's concave glass gets no warning.
    let out = vtfarm(&[
        "compare",
        repo("configs/cockpit.toml").to_str().unwrap(),
        "-o",
        dir.path().join("cmp").to_str().unwrap(),
        "--width",
        "64",
        "--height",
        "36",
    ]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(
        !text(&out.stderr).contains("warning"),
        "{}",
        text(&out.stderr)
    );
}

/// A scene whose BVH cannot be built (a vertex at 1e22 overflowed obvhs and
/// hung `render` behind panicking workers): `render` exits non-zero with the
/// reason, within a bounded wait.
#[test]
fn render_of_a_poison_scene_exits_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("far.obj"),
        "o a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1e22 1 0\nf 1 2 3\nf 2 4 3\n",
    )
    .unwrap();
    let job = dir.path().join("far.toml");
    std::fs::write(
        &job,
        "[scene]\nobj = \"far.obj\"\n[camera]\neye = [0, 0, 2]\ntarget = [0, 0, 0]\nfov_y = 40\nwidth = 8\nheight = 8\n[reflectors]\nobjects = [\"a\"]\n",
    )
    .unwrap();
    let png = dir.path().join("far.png");
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_vtfarm"))
        .args(["render", job.to_str().unwrap(), "-o", png.to_str().unwrap()])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if std::time::Instant::now() > deadline {
            let _ = child.kill();
            panic!("render hung on a poison scene");
        }
        std::thread::sleep(std::time::Duration::from_millis(50));
    };
    let mut err = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err).unwrap();
    assert!(!status.success());
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains("far.obj:5"), "names the file and line: {err}");
    assert!(err.contains("±1e6"), "says why: {err}");
    assert!(!png.exists());
}

/// Absurd simulator settings are refused at once, before any cost is
/// recorded (an infinite latency would panic in `Duration`).
#[test]
fn bench_simulate_refuses_absurd_settings() {
    for (args, needle) in [
        (&["--latency-ms", "inf"][..], "--latency-ms"),
        (&["--cost-scale", "0"], "--cost-scale"),
        (&["--link-mbit", "nan"], "--link-mbit"),
        (&["--workers", "5000"], "at most 4096 workers"),
    ] {
        let out = vtfarm(&[&["bench", "simulate"][..], args].concat());
        assert!(!out.status.success(), "{args:?} was accepted");
        let stderr = text(&out.stderr);
        assert!(
            stderr.contains(needle) && !stderr.contains("panicked"),
            "{args:?}: {stderr}"
        );
    }
}

/// A master told to keep absurdly many finished jobs, or for absurdly
/// long, is refused before it binds anything (each kept job costs memory
/// and a line in every `jobs` reply).
#[test]
fn master_refuses_absurd_retention() {
    for (args, needle) in [
        (&["--keep-jobs", "99999999"][..], "--keep-jobs"),
        (&["--keep-jobs-hours", "99999999"], "--keep-jobs-hours"),
    ] {
        let out = vtfarm(&[&["master"][..], args].concat());
        assert!(!out.status.success(), "{args:?} was accepted");
        let stderr = text(&out.stderr);
        assert!(
            stderr.contains(needle) && stderr.contains("is not in 0..="),
            "{args:?}: {stderr}"
        );
    }
}

/// A small cockpit job (detail 0.3, 160x90, preview) written into `dir`.
fn small_job(dir: &Path) -> PathBuf {
    let job = dir.join("small.toml");
    std::fs::write(
        &job,
        "[scene]\nbuiltin = \"cockpit\"\ndetail = 0.3\n[camera]\nwidth = 160\nheight = 90\n[quality]\nlevel = \"preview\"\n",
    )
    .unwrap();
    job
}

/// `--width` or `--height` alone scales the job's size, keeping its aspect
/// ratio (16:9 here); both together are taken as they are.
#[test]
fn render_given_one_side_keeps_the_jobs_aspect_ratio() {
    let dir = tempfile::tempdir().unwrap();
    let job = small_job(dir.path());
    for (size, expected) in [
        (&["--width", "64"][..], (64, 36)),
        (&["--height", "45"], (80, 45)),
        (&["--width", "50", "--height", "50"], (50, 50)),
        (&["--width", "1"], (1, 1)),
    ] {
        let png = dir.path().join("out.png");
        let args = [
            &["render", job.to_str().unwrap(), "-o", png.to_str().unwrap()][..],
            size,
        ]
        .concat();
        let out = vtfarm(&args);
        assert!(out.status.success(), "{size:?}: {}", text(&out.stderr));
        let dimensions = image::open(&png).unwrap().to_rgb8().dimensions();
        assert_eq!(dimensions, expected, "{size:?}");
    }
}

/// The closing table's farm figure says what it is: the workers' summed
/// busy time over the frame's wall time (no "speed-up" that reads as a
/// slow-down when it is below 1).
#[test]
fn render_names_what_its_frame_figures_measure() {
    let dir = tempfile::tempdir().unwrap();
    let job = small_job(dir.path());
    let png = dir.path().join("out.png");
    let out = vtfarm(&["render", job.to_str().unwrap(), "-o", png.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let stdout = text(&out.stdout);
    assert!(stdout.contains("workers busy on average"), "{stdout}");
    assert!(!stdout.contains("speed-up"), "{stdout}");
}

/// The subcommands as `vtfarm --help` lists them.
fn listed_commands(help: &str) -> Vec<String> {
    help.lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_owned))
        .collect()
}

#[test]
fn help_lists_the_users_commands_first_and_bench_last() {
    let out = vtfarm(&["--help"]);
    assert!(out.status.success());
    let commands = listed_commands(&text(&out.stdout));
    assert_eq!(
        commands,
        [
            "render", "study", "compare", "cluster", "master", "worker", "submit", "status",
            "jobs", "cancel", "pause", "resume", "requeue", "priority", "scene", "bench", "help"
        ],
        "{commands:?}"
    );
}

/// What a newcomer reads in `--help`: every option described, the quality
/// levels listed, studies and their sun sweeps named where they are taken.
#[test]
fn help_describes_every_option_and_lists_the_quality_levels() {
    let help = |command: &str| {
        let out = vtfarm(&[command, "--help"]);
        assert!(out.status.success(), "{command} --help");
        text(&out.stdout)
    };
    for command in ["render", "compare", "submit"] {
        let help = help(command);
        for described in [
            "Image width in pixels",
            "Image height in pixels",
            "aspect ratio",
        ] {
            assert!(help.contains(described), "{command} --help: {help}");
        }
    }
    for command in ["render", "study", "submit"] {
        let help = help(command);
        for level in ["preview", "refine", "full", "reference"] {
            assert!(
                help.contains(level),
                "{command} --help lists {level}: {help}"
            );
        }
    }
    assert!(help("submit").contains("study file"));
    assert!(help("study").contains("sun positions"));

    let out = vtfarm(&["render", "configs/cockpit.toml", "--quality", "best"]);
    assert!(!out.status.success());
    let stderr = text(&out.stderr);
    assert!(
        stderr.contains("preview") && stderr.contains("reference"),
        "{stderr}"
    );
}

/// Each cause of a failure is printed once, and a value that came from the
/// command line is blamed on the command line.
#[test]
fn errors_name_their_cause_once_and_at_the_right_place() {
    let missing = vtfarm(&["render", "no/such/job.toml", "-o", "x.png"]);
    assert!(!missing.status.success());
    let err = text(&missing.stderr);
    assert_eq!(err.matches("os error 2").count(), 1, "{err}");
    assert!(err.contains("no/such/job.toml"), "{err}");

    let job = repo("configs/cockpit.toml");
    let zero = vtfarm(&[
        "render",
        job.to_str().unwrap(),
        "--width",
        "0",
        "-o",
        "x.png",
    ]);
    assert!(!zero.status.success());
    let err = text(&zero.stderr);
    assert!(err.contains("--width"), "{err}");
    assert!(
        !err.contains("cockpit.toml"),
        "the job file is not to blame: {err}"
    );

    let study = repo("configs/cockpit-sun-study.toml");
    let wrong = vtfarm(&["render", study.to_str().unwrap(), "-o", "x.png"]);
    assert!(!wrong.status.success());
    let err = text(&wrong.stderr);
    assert!(err.contains("vtfarm study"), "{err}");
    assert!(err.contains("cockpit-sun-study.toml:14:1"), "{err}");
    assert!(!err.contains("unknown field"), "{err}");
}

/// The top-level help names every output format of `render` and `scene export`.
#[test]
fn the_help_lists_every_output_format() {
    let help = text(&vtfarm(&["--help"]).stdout);
    for format in [".png", ".exr", ".npy", "OBJ", "GLB"] {
        assert!(help.contains(format), "{format} missing from:\n{help}");
    }
}
