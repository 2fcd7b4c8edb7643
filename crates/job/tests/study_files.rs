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

#[test]
fn a_sun_sweep_is_a_grid_or_a_range_of_utc_times() {
    use vtfarm_job::study::{SunSweep, UtcTime};
    let dir = dir_with_job();
    let file = dir.path().join("s.toml");
    let grid = parse_study(
        &format!("{HEADER}[eyes]\npoints = [[0, 1.4, 0]]\n{ONE_VARIANT}[sun]\nazimuths = [0, 90]\nelevations = [10, 45, 90]\n"),
        &file,
    )
    .unwrap();
    assert_eq!(
        grid.sun,
        Some(SunSweep::Grid {
            azimuths_deg: vec![0.0, 90.0],
            elevations_deg: vec![10.0, 45.0, 90.0]
        })
    );
    // Local time at +02:00 is two hours ahead of UTC; the end is inclusive.
    let times = parse_study(
        &format!("{HEADER}[eyes]\npoints = [[0, 1.4, 0]]\n{ONE_VARIANT}[sun]\nstart = 2026-06-21T10:00:00+02:00\nend = 2026-06-21T09:00:00Z\nstep_minutes = 30\nlatitude = 48.1\nlongitude = 11.6\nheading = 90\n"),
        &file,
    )
    .unwrap();
    let Some(SunSweep::Times {
        times, heading_deg, ..
    }) = times.sun
    else {
        panic!("a time range: {:?}", times.sun);
    };
    let text: Vec<String> = times.iter().map(UtcTime::to_string).collect();
    assert_eq!(
        text,
        [
            "2026-06-21T08:00:00Z",
            "2026-06-21T08:30:00Z",
            "2026-06-21T09:00:00Z"
        ]
    );
    assert_eq!(heading_deg, 90.0);
    // Day numbers across leap years and before 1970 round-trip.
    for (y, mo, d) in [(1969, 12, 31), (2000, 2, 29), (2024, 3, 1), (2100, 12, 31)] {
        let t = UtcTime::from_civil(y, mo, d, 23, 59, 58, 0).unwrap();
        assert_eq!(t.civil(), (i64::from(y), mo, d, 23, 59, 58));
    }
    assert_eq!(UtcTime::from_civil(2023, 2, 29, 0, 0, 0, 0), None);
}

#[test]
fn sun_sweep_mistakes_name_the_line_and_the_fix() {
    let head = format!("{HEADER}[eyes]\npoints = [[0, 1.4, 0]]\n{ONE_VARIANT}[sun]\n");
    for (sun, line, expected) in [
        (
            "azimuths = [0]\nelevations = [0]\n",
            10,
            "over 0 and at most 90",
        ),
        ("azimuths = [0]\n", 8, "needs sun.elevations"),
        (
            "azimuths = [0]\nelevations = [30]\nlatitude = 48.0\n",
            8,
            "not both",
        ),
        (
            "start = 2026-06-21T08:00:00\nlatitude = 48.0\nlongitude = 11.0\nheading = 0\n",
            9,
            "UTC offset",
        ),
        (
            "start = 2026-06-21T08:00:00Z\nlatitude = 98.0\nlongitude = 11.0\nheading = 0\n",
            10,
            "-90 to 90",
        ),
        (
            "start = 2026-06-21T08:00:00Z\nlatitude = 48.0\nlongitude = 11.0\n",
            8,
            "needs sun.heading",
        ),
        (
            "start = 2026-06-21T08:00:00Z\nend = 2026-06-20T08:00:00Z\nstep_minutes = 10\nlatitude = 48.0\nlongitude = 11.0\nheading = 0\n",
            10,
            "before sun.start",
        ),
        (
            "start = 2026-06-21T08:00:00Z\nend = 2027-06-20T08:00:00Z\nstep_minutes = 1\nlatitude = 48.0\nlongitude = 11.0\nheading = 0\n",
            10,
            "at most 10000",
        ),
    ] {
        let message = refused(&format!("{head}{sun}"));
        assert!(
            message.contains(&format!("s.toml:{line}")) && message.contains(expected),
            "{sun}: {message}"
        );
    }
}

#[test]
fn the_example_sun_study_sweeps_sixteen_suns_over_seven_eyes_and_five_designs() {
    let study = load_study(&repo("configs/cockpit-sun-study.toml")).unwrap();
    assert_eq!(study.eyes.len(), 7);
    assert_eq!(study.variants.len(), 5);
    let Some(vtfarm_job::study::SunSweep::Grid {
        azimuths_deg,
        elevations_deg,
    }) = study.sun
    else {
        panic!("a grid sweep: {:?}", study.sun);
    };
    assert_eq!(azimuths_deg.len() * elevations_deg.len(), 16);
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
