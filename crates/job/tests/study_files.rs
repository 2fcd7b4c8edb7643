//! Study files: the shipped example parses, and every kind of mistake is
//! refused with the file, the line and what to do, before any rendering.

use std::path::{Path, PathBuf};

use glam::Vec3;
use vtfarm_job::study::{COCKPIT_INSTRUMENT_OBJECTS, load_study, parse_study};
use vtfarm_job::{GlassDesign, SceneSource};

fn repo(path: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(path)
}

/// A directory with a base job, for study texts to refer to.
fn dir_with_job() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("job.toml"),
        "[scene]\nbuiltin = \"cockpit\"\n",
    )
    .unwrap();
    dir
}

const HEADER: &str = "[study]\njob = \"job.toml\"\n";
const ONE_VARIANT: &str = "[[variants]]\nname = \"flat\"\nglass = \"flat\"\n";

fn refused(text: &str) -> String {
    let dir = dir_with_job();
    let file = dir.path().join("s.toml");
    let e = parse_study(text, &file).expect_err("the study must be refused");
    let message = e.to_string();
    assert!(
        message.starts_with(&file.display().to_string()),
        "names the file: {message}"
    );
    message
}

#[test]
fn the_example_study_parses_into_its_variants_and_eye_ellipse() {
    let study = load_study(&repo("configs/cockpit-study.toml")).unwrap();
    assert_eq!(study.eyes.len(), 7, "the centre plus 6 points");
    assert_eq!(study.eyes[0], Vec3::new(-0.55, 1.40, 0.10));
    let names: Vec<&str> = study.variants.iter().map(|v| v.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "current",
            "flat",
            "flat tilted 20",
            "cylindrical r0.5",
            "ellipsoidal"
        ]
    );
    assert!(matches!(
        study.variants[2].scene,
        SceneSource::Cockpit(c) if c.glass == GlassDesign::FlatTilted { degrees: 20.0 }
    ));
    assert_eq!((study.width, study.height), (Some(640), Some(360)));
    assert_eq!(study.metrics.instrument_objects, COCKPIT_INSTRUMENT_OBJECTS);
    let min_contrast = study.metrics.min_contrast.clone().unwrap();
    assert_eq!(min_contrast.value, 3.0);
    assert!(min_contrast.source.contains("ISO 15008"));
    // A value without its source is recorded as set in the study file.
    let veil = study.metrics.veiling_luminance_cd_m2.clone().unwrap();
    assert_eq!(veil.value, 500.0);
    assert!(
        veil.source.contains("cockpit-study.toml"),
        "{}",
        veil.source
    );
    assert_eq!(
        study.metrics.ambient_illuminance_lux.unwrap().value,
        45_000.0
    );
    // Every ellipse point lies on the ellipsoid (semi-axes 0.06, 0.04, 0.08,
    // tilted 12 degrees about x).
    let tilt = glam::Mat3::from_rotation_x(12f32.to_radians());
    for &eye in &study.eyes[1..] {
        let local = tilt.transpose() * (eye - study.eyes[0]);
        let r = (local / Vec3::new(0.06, 0.04, 0.08)).length();
        assert!((r - 1.0).abs() < 1e-4, "{eye}: {r}");
    }
}

#[test]
fn an_unknown_key_is_refused_with_its_line() {
    let m = refused(&format!(
        "{HEADER}[eyes]\npoints = [[0.0, 1.4, 0.1]]\n{ONE_VARIANT}glass_tint = 0.3\n"
    ));
    assert!(m.contains(":8:") && m.contains("glass_tint"), "{m}");
}

#[test]
fn an_empty_eye_ellipse_is_refused() {
    let m = refused(&format!(
        "{HEADER}[eyes.ellipse]\ncentre = [0.0, 1.4, 0.1]\nsemi_axes = [0.0, 0.0, 0.0]\n{ONE_VARIANT}"
    ));
    assert!(
        m.contains(":5:") && m.contains("eye ellipse is empty"),
        "{m}"
    );
    let m = refused(&format!(
        "{HEADER}[eyes.ellipse]\ncentre = [0.0, 1.4, 0.1]\nsemi_axes = [0.1, 0.1, 0.1]\npoints = 0\n{ONE_VARIANT}"
    ));
    assert!(m.contains("eyes.ellipse.points = 0"), "{m}");
    let m = refused(&format!("{HEADER}[eyes]\npoints = []\n{ONE_VARIANT}"));
    assert!(m.contains("eyes.points is empty"), "{m}");
    let m = refused(&format!("{HEADER}{ONE_VARIANT}"));
    assert!(m.contains("missing [eyes]"), "{m}");
}

#[test]
fn a_variant_file_that_does_not_exist_is_refused() {
    let m = refused(&format!(
        "{HEADER}[eyes]\npoints = [[0.0, 1.4, 0.1]]\n[[variants]]\nname = \"supplier\"\nobj = \"models/nowhere.obj\"\n"
    ));
    assert!(
        m.contains(":7:") && m.contains("variants[0].obj") && m.contains("nowhere.obj"),
        "{m}"
    );
}

#[test]
fn other_mistakes_name_what_to_fix() {
    let eyes = "[eyes]\npoints = [[0.0, 1.4, 0.1]]\n";
    let cases = [
        (
            format!("[study]\njob = \"missing.toml\"\n{eyes}{ONE_VARIANT}"),
            "study.job: no such file",
        ),
        (format!("{HEADER}{eyes}"), "at least one [[variants]]"),
        (
            format!("{HEADER}{eyes}{ONE_VARIANT}{ONE_VARIANT}"),
            "the name \"flat\" is used twice",
        ),
        (
            format!("{HEADER}{eyes}[[variants]]\nname = \"t\"\nglass = \"flat-tilted\"\n"),
            "needs variants[0].glass_tilt",
        ),
        (
            format!("{HEADER}{eyes}[[variants]]\nname = \"x\"\nglass = \"wavy\"\n"),
            "unknown variants[0].glass \"wavy\"",
        ),
        (
            format!("{HEADER}{eyes}[[variants]]\nname = \"x\"\n"),
            "needs glass = ",
        ),
        (
            format!("{HEADER}{eyes}{ONE_VARIANT}[metrics]\nmin_contrast = 0.5\n"),
            "metrics.min_contrast = 0.5: must be at least 1",
        ),
    ];
    for (text, expected) in cases {
        let m = refused(&text);
        assert!(m.contains(expected), "{expected:?} not in {m}");
    }
}

/// The unit-less metric keys of earlier study files are refused at their
/// line with the key that replaces them, never read in the wrong unit.
#[test]
fn unit_less_metric_keys_name_their_replacement() {
    let eyes = "[eyes]\npoints = [[0.0, 1.4, 0.1]]\n";
    for (key, replacement) in [
        ("veiling_luminance = 0.05", "veiling_luminance_cd_m2"),
        ("luminance_scale = 1.0", "cd/m²"),
        ("heat_scale = 0.2", "heat_max_cd_m2"),
    ] {
        let m = refused(&format!("{HEADER}{eyes}{ONE_VARIANT}[metrics]\n{key}\n"));
        let line = 3 + eyes.lines().count() + ONE_VARIANT.lines().count() + 1;
        assert!(
            m.contains(&format!(":{line}:")) && m.contains(replacement),
            "{key}: {m}"
        );
    }
    let m = refused(&format!(
        "{HEADER}{eyes}{ONE_VARIANT}[metrics]\nheat_min_cd_m2 = 10.0\nheat_max_cd_m2 = 5.0\n"
    ));
    assert!(m.contains("must be above heat_min_cd_m2"), "{m}");
}
