//! HDR output of `vtfarm render`: OpenEXR in cd/m² (RGB, luminance Y and,
//! with `--aux`, the reflected and transmitted layers) read back by two
//! decoders equals the linear `.npy` values exactly; the PNG's exposure;
//! unsupported extensions refused with the supported ones; a missing
//! output directory created; a write error's cause said once.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const CD_M2_PER_UNIT: f32 = 10_000.0;

fn vtfarm(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_vtfarm"))
        .args(args)
        .output()
        .expect("the vtfarm binary runs")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

fn stock_job() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/cockpit.toml");
    path.to_str().unwrap().to_owned()
}

/// Renders the stock job at 96 × 54 to `output` (with `extra` arguments).
fn render(output: &Path, extra: &[&str]) -> Output {
    let output = output.to_str().unwrap();
    let mut args = vec!["render", "--width", "96", "--height", "54", "-o", output];
    args.extend_from_slice(extra);
    let job = stock_job();
    args.insert(1, &job);
    vtfarm(&args)
}

/// A float32 `.npy` (version 1.0, little-endian) as its values.
fn read_npy(path: &Path) -> Vec<f32> {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    let header = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    bytes[10 + header..]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}

/// Every channel of an OpenEXR file as read by the `exr` crate.
fn read_exr(path: &Path) -> (usize, usize, BTreeMap<String, Vec<f32>>) {
    let image = exr::prelude::read_first_flat_layer_from_file(path).expect("a valid OpenEXR");
    let layer = &image.layer_data;
    let size = layer.size;
    let channels = (layer.channel_data.list.iter())
        .map(|c| {
            let values: Vec<f32> = c.sample_data.values_as_f32().collect();
            (c.name.to_string(), values)
        })
        .collect();
    (size.width(), size.height(), channels)
}

/// The channels an `.npy` image of shape (h, w, 3) in render units makes
/// in cd/m²: `prefix`R, G, B and Y, as `vtfarm_scene::photometry` states.
fn expected_channels(prefix: &str, npy: &[f32]) -> Vec<(String, Vec<f32>)> {
    let channel = |k: usize| npy.chunks_exact(3).map(|c| c[k] * CD_M2_PER_UNIT).collect();
    let y = (npy.chunks_exact(3))
        .map(|c| CD_M2_PER_UNIT * (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]))
        .collect();
    vec![
        (format!("{prefix}R"), channel(0)),
        (format!("{prefix}G"), channel(1)),
        (format!("{prefix}B"), channel(2)),
        (format!("{prefix}Y"), y),
    ]
}

/// Reads the EXR with Python's `OpenEXR` package and checks every channel
/// against the `.npy` files bit for bit. `false` when the package is
/// missing outside CI; under `CI=true` a missing package fails the test
/// (`.ci/run` installs it).
fn python_openexr_agrees(exr: &Path, npys: &[(&str, &Path)]) -> bool {
    let script = r#"
import sys
try:
    import numpy as np
    import OpenEXR
except ImportError as e:
    print("missing", e)
    sys.exit(3)
exr = sys.argv[1]
pairs = sys.argv[2:]
with OpenEXR.File(exr, separate_channels=True) as f:
    channels = f.channels()
    for k in range(0, len(pairs), 2):
        prefix, npy = pairs[k], pairs[k + 1]
        rgb = np.load(npy).astype(np.float32)
        s = np.float32(10000.0)
        expected = {
            "R": rgb[..., 0] * s, "G": rgb[..., 1] * s, "B": rgb[..., 2] * s,
            "Y": s * (np.float32(0.2126) * rgb[..., 0] + np.float32(0.7152) * rgb[..., 1]
                      + np.float32(0.0722) * rgb[..., 2]),
        }
        for name, values in expected.items():
            got = channels[prefix + name].pixels
            assert got.dtype == np.float32, (name, got.dtype)
            if not np.array_equal(got.view(np.uint32), values.view(np.uint32)):
                print("differs", prefix + name, np.abs(got - values).max())
                sys.exit(1)
print("ok")
"#;
    let mut command = Command::new("python3");
    command.arg("-c").arg(script).arg(exr);
    for (prefix, npy) in npys {
        command.arg(prefix).arg(npy);
    }
    let out = match command.output() {
        Ok(out) => out,
        Err(e) if std::env::var("CI").as_deref() != Ok("true") => {
            eprintln!("python3 not available ({e}): the OpenEXR cross-check is CI's");
            return false;
        }
        Err(e) => panic!("python3 is needed under CI: {e}"),
    };
    let said = format!("{}{}", text(&out.stdout), text(&out.stderr));
    if out.status.code() == Some(3) {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI must have Python's OpenEXR and numpy (.ci/run installs them): {said}"
        );
        eprintln!("Python's OpenEXR is not installed ({said}): the cross-check is CI's");
        return false;
    }
    assert!(out.status.success(), "Python's OpenEXR disagrees: {said}");
    true
}

#[test]
fn an_exr_from_render_holds_the_npy_values_in_cd_m2_for_both_decoders() {
    let dir = tempfile::tempdir().unwrap();
    let (exr, npy) = (dir.path().join("out.exr"), dir.path().join("out.npy"));
    let (aux_exr, aux_npy) = (dir.path().join("aux_exr"), dir.path().join("aux_npy"));
    for (output, aux) in [(&exr, &aux_exr), (&npy, &aux_npy)] {
        let out = render(output, &["--aux", aux.to_str().unwrap()]);
        assert!(out.status.success(), "{}", text(&out.stderr));
    }
    let (width, height, channels) = read_exr(&exr);
    assert_eq!((width, height), (96, 54));
    let color = read_npy(&npy);
    let mut expected = expected_channels("", &color);
    expected.extend(expected_channels(
        "reflected.",
        &read_npy(&aux_npy.join("reflected.npy")),
    ));
    expected.extend(expected_channels(
        "transmitted.",
        &read_npy(&aux_npy.join("transmitted.npy")),
    ));
    let names: Vec<&String> = channels.keys().collect();
    assert_eq!(names.len(), 12, "{names:?}");
    for (name, values) in &expected {
        let got = &channels[name];
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(got), bits(values), "channel {name}");
    }
    // Real content: the side window's reflection is far over 1 render unit
    // in the glass, which a PNG clips.
    assert!(channels["Y"].iter().any(|&y| y > 10_000.0));
    assert!(channels["reflected.Y"].iter().any(|&y| y > 1_000.0));
    // The second decoder.
    python_openexr_agrees(
        &exr,
        &[
            ("", &npy),
            ("reflected.", &aux_npy.join("reflected.npy")),
            ("transmitted.", &aux_npy.join("transmitted.npy")),
        ],
    );
}

#[test]
fn an_unsupported_extension_is_refused_naming_the_supported_ones() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["out.jpg", "out.EXRX", "out"] {
        let path = dir.path().join(name);
        let out = render(&path, &[]);
        assert!(!out.status.success(), "{name} accepted");
        let stderr = text(&out.stderr);
        for supported in [".png", ".exr", ".npy"] {
            assert!(stderr.contains(supported), "{name}: {stderr}");
        }
        assert!(!path.exists(), "{name}: nothing written under a wrong name");
        assert_eq!(stderr.lines().count(), 1, "one line: {stderr}");
    }
}

#[test]
fn a_missing_output_directory_is_created_and_a_write_error_says_its_cause_once() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("missing/dir/out.png");
    let out = render(&png, &[]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert!(png.is_file());
    // A directory where the file should go: the cause, once.
    let blocked: PathBuf = dir.path().join("blocked.png");
    std::fs::create_dir(&blocked).unwrap();
    let out = render(&blocked, &[]);
    assert!(!out.status.success());
    let stderr = text(&out.stderr);
    let line = stderr.lines().find(|l| l.starts_with("error:")).unwrap();
    assert!(line.contains("blocked.png"), "{line}");
    let cause = line.rsplit(": ").next().unwrap();
    assert_eq!(line.matches(cause).count(), 1, "the cause twice: {line}");
}

#[test]
fn the_png_exposure_and_tone_curve_come_from_the_job() {
    let dir = tempfile::tempdir().unwrap();
    // The stock job with its documented [output] keys changed.
    let job = std::fs::read_to_string(stock_job()).unwrap();
    assert!(job.contains("white_cd_m2 = 10000.0") && job.contains("tone = \"clip\""));
    let brighter_job = job.replace("white_cd_m2 = 10000.0", "white_cd_m2 = 2500.0");
    let brighter = dir.path().join("brighter.toml");
    std::fs::write(&brighter, &brighter_job).unwrap();
    let toned = dir.path().join("toned.toml");
    let toned_job = brighter_job.replace("tone = \"clip\"", "tone = \"reinhard\"");
    std::fs::write(&toned, toned_job).unwrap();
    let png = |job: &Path, name: &str| {
        let path = dir.path().join(name);
        let out = vtfarm(&[
            "render",
            job.to_str().unwrap(),
            "--width",
            "96",
            "--height",
            "54",
            "-o",
            path.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", text(&out.stderr));
        image::open(&path).unwrap().to_rgb8().into_raw()
    };
    let npy = dir.path().join("linear.npy");
    assert!(render(&npy, &[]).status.success());
    let linear = read_npy(&npy);
    let srgb = |v: f32| {
        let v = v.clamp(0.0, 1.0);
        let s = if v <= 0.003_130_8 {
            v * 12.92
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        };
        (s * 255.0 + 0.5) as u8
    };
    let stock = png(Path::new(&stock_job()), "stock.png");
    let bright = png(&brighter, "bright.png");
    let tone = png(&toned, "tone.png");
    for (k, &v) in linear.iter().enumerate() {
        // The default: 1 render unit (10,000 cd/m²) is white.
        assert_eq!(stock[k], srgb(v), "stock {k}");
        // White at 2,500 cd/m²: four times the linear value.
        assert!(bright[k].abs_diff(srgb(v * 4.0)) <= 1, "bright {k}");
        // Reinhard: x / (1 + x) of the scaled value, nothing clipped.
        let x = v * 4.0;
        assert!(tone[k].abs_diff(srgb(x / (1.0 + x))) <= 1, "tone {k}");
    }
    assert!(
        bright.iter().filter(|&&b| b == 255).count() > stock.iter().filter(|&&b| b == 255).count()
    );
    assert!(tone.iter().all(|&b| b < 255), "Reinhard clips nothing");
}
