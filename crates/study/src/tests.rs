//! Glare studies against physics: the ellipsoidal glass with the eye at its
//! focus, and a flat glass against a plane mirror computed analytically.

use std::path::Path;
use std::sync::Arc;

use glam::Vec3;
use vtfarm_job::study::parse_study;
use vtfarm_render::{RenderOptions, Renderer};
use vtfarm_scene::{NONE, Scene, TriangleId};

use super::*;

/// A study of `variants` (TOML tables) at 192x108 from `eyes`, with its base
/// job written next to it.
fn study_plan(dir: &Path, eyes: &[Vec3], variants: &str) -> StudyPlan {
    std::fs::write(
        dir.join("job.toml"),
        "[scene]\nbuiltin = \"cockpit\"\ndetail = 0.3\n",
    )
    .unwrap();
    let points: Vec<String> = eyes
        .iter()
        .map(|e| format!("[{}, {}, {}]", e.x, e.y, e.z))
        .collect();
    let text = format!(
        "[study]\njob = \"job.toml\"\nwidth = 192\nheight = 108\n[eyes]\npoints = [{}]\n{variants}",
        points.join(", ")
    );
    let file = dir.join("study.toml");
    std::fs::write(&file, &text).unwrap();
    let study = parse_study(&text, &file).unwrap();
    plan(&study, None).unwrap()
}

/// Renders every frame in this process and runs them through the writer.
fn run(plan: &StudyPlan, dir: &Path) -> (StudyReport, Vec<Vec<FrameImage>>) {
    let mut writer = StudyWriter::new(plan, dir).unwrap();
    let mut images = Vec::new();
    for (v, variant) in plan.variants.iter().enumerate() {
        let renderer = Renderer::new(Arc::new(variant.scene.clone()), variant.reflectors.clone());
        let mut frames = Vec::new();
        for (e, setup) in variant.setups.iter().enumerate() {
            let frame = renderer.render(setup, &RenderOptions::default(), &mut |_, _| {});
            writer.frame(v, e, &frame.image).unwrap();
            frames.push(frame.image);
        }
        images.push(frames);
    }
    (writer.finish(&test_run()).unwrap(), images)
}

/// A run as a caller would describe it.
fn test_run() -> RunInfo {
    RunInfo {
        version: "0.1.0 (commit 0123456789ab)".into(),
        date: "2026-12-07T05:00:00Z".into(),
        workers: "local, 1 worker(s) sharing 2 threads".into(),
        command: command_line(["vtfarm", "study", "study file.toml"].map(String::from)),
    }
}

fn mean_lr(report: &StudyReport, variant: &str, eye: usize) -> f32 {
    report
        .frames
        .iter()
        .find(|f| f.variant == variant && f.eye_index == eye)
        .unwrap()
        .summary
        .mean_reflected_luminance_cd_m2
}

#[test]
fn the_ellipsoidal_glass_mirrors_only_its_absorber_from_the_focus() {
    let dir = tempfile::tempdir().unwrap();
    let focus = vtfarm_cockpit::default_eye();
    let eyes = [
        focus,
        focus + Vec3::new(0.04, 0.0, 0.0),
        focus + Vec3::new(0.08, 0.0, 0.0),
        focus + Vec3::new(0.0, 0.04, 0.0),
        focus + Vec3::new(0.0, 0.08, 0.0),
        focus + Vec3::new(0.0, 0.0, 0.04),
        focus + Vec3::new(0.0, 0.0, 0.08),
    ];
    let plan = study_plan(
        dir.path(),
        &eyes,
        "[[variants]]\nname = \"flat\"\nglass = \"flat\"\n[[variants]]\nname = \"ellipsoidal\"\nglass = \"ellipsoidal\"\n",
    );
    let (report, _) = run(&plan, dir.path());
    let flat = mean_lr(&report, "flat", 0);
    let ellipsoidal: Vec<f32> = (0..eyes.len())
        .map(|e| mean_lr(&report, "ellipsoidal", e))
        .collect();
    assert!(
        ellipsoidal[0] * 10.0 <= flat,
        "ellipsoidal {} vs flat {flat}",
        ellipsoidal[0]
    );
    // From the focus the glass shows the absorber, nothing else.
    let nominal = &report.frames[plan.eyes.len()].summary;
    assert_eq!(nominal.objects[0].name, vtfarm_cockpit::GLARE_ABSORBER);
    assert!(
        nominal.objects[0].coverage_share > 0.95,
        "{:?}",
        nominal.objects
    );
    // Away from the focus other things appear in the glass: along each axis
    // (lateral, vertical, fore-aft) 8 cm off is at least ten times brighter
    // than the focus, and 4 cm off is no brighter than 8 cm off.
    for axis in 0..3 {
        let (near, far) = (ellipsoidal[1 + 2 * axis], ellipsoidal[2 + 2 * axis]);
        assert!(
            far >= 10.0 * ellipsoidal[0],
            "axis {axis}: {far} vs {}",
            ellipsoidal[0]
        );
        assert!(near <= far, "axis {axis}: 4 cm {near}, 8 cm {far}");
    }
    // The report ranks the designs and names both.
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(html.contains("<svg") && html.contains("ellipsoidal"));
    let csv = std::fs::read_to_string(dir.path().join("summary.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 2 * eyes.len());
}

/// Mirrors a point or a direction through the plane (o, unit n).
fn mirror(p: Vec3, o: Vec3, n: Vec3) -> Vec3 {
    p - 2.0 * (p - o).dot(n) * n
}

#[test]
fn a_flat_glass_reflects_the_analytic_mirror_image_of_the_scene() {
    let dir = tempfile::tempdir().unwrap();
    let eye = vtfarm_cockpit::default_eye() + Vec3::new(0.02, -0.01, 0.0);
    let plan = study_plan(
        dir.path(),
        &[eye],
        "[[variants]]\nname = \"flat\"\nglass = \"flat\"\n",
    );
    let (report, images) = run(&plan, dir.path());
    let variant = &plan.variants[0];
    let frame = &images[0][0];
    let camera = variant.setups[0].camera;
    let scene = &variant.scene;

    // The glass plane from its triangles (all coplanar for the flat design).
    let glass = variant.reflectors[0];
    let [a, _, _] = scene.triangle_positions(glass);
    let n = scene.geometric_normal(glass).normalize();
    for &t in &variant.reflectors {
        for p in scene.triangle_positions(t) {
            assert!((p - a).dot(n).abs() < 1e-5, "the flat glass is flat");
        }
    }
    // The mirror image: the scene reflected through the plane and seen
    // through the glass by the same camera. Only what lies on the eye's side
    // of the plane can appear in it.
    let eye_side = (camera.eye - a).dot(n).signum();
    let back = scene.object_id(vtfarm_cockpit::COVER_GLASS_BACK);
    let mut mirrored = Scene {
        positions: scene.positions.iter().map(|&p| mirror(p, a, n)).collect(),
        normals: scene
            .normals
            .iter()
            .map(|&d| d - 2.0 * d.dot(n) * n)
            .collect(),
        ..scene.clone()
    };
    let is_glass: Vec<bool> = scene
        .triangle_ids()
        .map(|t| variant.reflectors.contains(&t) || Some(scene.triangles[t.index()].object) == back)
        .collect();
    mirrored
        .triangles
        .iter_mut()
        .for_each(|t| t.vertices.swap(1, 2));
    let keep = |t: TriangleId| {
        let [p, q, r] = scene.triangle_positions(t);
        !is_glass[t.index()] && ((p + q + r) / 3.0 - a).dot(n) * eye_side > 0.0
    };
    let ids = vtfarm_raster::id_buffer_where(&mirrored, &camera, &keep);

    let (w, h) = (camera.width, camera.height);
    let (mut glass_pixels, mut agree) = (0usize, 0usize);
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            if !frame.is_glass(i) {
                continue;
            }
            glass_pixels += 1;
            let expected = ids.object_at(x, y);
            agree += (frame.pixel(i).object == expected) as usize;
        }
    }
    assert!(glass_pixels > 1000, "{glass_pixels} glass pixels");
    let share = agree as f64 / glass_pixels as f64;
    assert!(
        share >= 0.99,
        "{share:.4} of {glass_pixels} glass pixels agree"
    );
    // The map really shows things (not all NONE on both sides).
    assert!(
        frame
            .components()
            .reflected_object
            .iter()
            .filter(|&&o| o != NONE)
            .count()
            > glass_pixels / 2
    );
    assert_eq!(report.frames.len(), 1);
}

#[test]
fn an_obj_variant_measures_like_the_built_in_design_it_was_exported_from() {
    let dir = tempfile::tempdir().unwrap();
    let flat = vtfarm_cockpit::cockpit(&vtfarm_cockpit::CockpitConfig {
        detail: 0.3,
        glass: vtfarm_cockpit::GlassDesign::Flat,
        ..Default::default()
    });
    vtfarm_scene::obj::write_obj(&flat.scene, dir.path(), "flat-cab").unwrap();
    let plan = study_plan(
        dir.path(),
        &[vtfarm_cockpit::default_eye()],
        "[[variants]]\nname = \"built-in\"\nglass = \"flat\"\n\
         [[variants]]\nname = \"from OBJ\"\nobj = \"flat-cab.obj\"\n",
    );
    assert_eq!(
        plan.variants[1].reflectors.len(),
        plan.variants[0].reflectors.len()
    );
    let (report, images) = run(&plan, dir.path());
    let [built_in, from_obj] = [0, 1].map(|v| &report.frames[v].summary);
    assert_eq!(built_in.glass_pixels, from_obj.glass_pixels);
    assert_eq!(built_in.objects[0].name, from_obj.objects[0].name);
    let (a, b) = (
        built_in.mean_reflected_luminance_cd_m2,
        from_obj.mean_reflected_luminance_cd_m2,
    );
    assert!(a > 0.0 && (a - b).abs() <= 0.02 * a, "{a} vs {b}");
    assert!(dir.path().join("from-obj/eye_00/heat.png").is_file());

    // The per-pixel array agrees with the summary.
    let lr = read_npy_f32(&dir.path().join("from-obj/eye_00/reflected_luminance.npy"));
    let glass = &images[1][0].components().mask;
    assert_eq!(lr.len(), glass.len());
    let mean = lr
        .iter()
        .zip(glass)
        .filter(|(_, g)| **g)
        .map(|(l, _)| f64::from(*l))
        .sum::<f64>()
        / from_obj.glass_pixels as f64;
    assert!((mean as f32 - b).abs() <= 1e-5 * b, "{mean} vs {b}");
    assert!(lr.iter().zip(glass).all(|(l, g)| *g || *l == 0.0));
}

/// The data of a little-endian float32 `.npy` file (format 1.0).
fn read_npy_f32(path: &Path) -> Vec<f32> {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..6], b"\x93NUMPY");
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + header_len]).unwrap();
    assert!(header.contains("'descr': '<f4'"), "{header}");
    bytes[10 + header_len..]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

#[test]
fn an_eye_on_the_point_it_looks_at_is_refused_while_planning() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("job.toml"),
        "[scene]\nbuiltin = \"cockpit\"\ndetail = 0.3\n",
    )
    .unwrap();
    let text = "[study]\njob = \"job.toml\"\nlook_at = [0.0, 1.0, 0.0]\n[eyes]\npoints = [[-0.55, 1.4, 0.1], [0.0, 1.0, 0.0]]\n[[variants]]\nname = \"flat\"\nglass = \"flat\"\n";
    let study = parse_study(text, &dir.path().join("study.toml")).unwrap();
    let e = plan(&study, None).expect_err("eye 1 sits on the target");
    let message = e.to_string();
    assert!(
        message.contains("eye 1") && message.contains("must be away from the target"),
        "{message}"
    );
}

#[test]
fn a_low_sun_through_the_side_window_mirrors_brighter_than_a_sun_behind_the_roof() {
    let dir = tempfile::tempdir().unwrap();
    // The current glass mirrors the left side of the cab; a low sun from the
    // right shines through the right door window onto it, a sun from behind
    // stays behind the cab's back wall and roof.
    let plan = study_plan(
        dir.path(),
        &[vtfarm_cockpit::default_eye()],
        "[[variants]]\nname = \"current\"\nglass = \"current\"\n\
         [sun]\nazimuths = [90, 180]\nelevations = [10, 40]\n",
    );
    assert_eq!(plan.suns.len(), 4);
    assert_eq!(plan.frames(), 4);
    let (report, _) = run(&plan, dir.path());
    let lr = |azimuth: f32, elevation: f32| {
        let row = report
            .frames
            .iter()
            .find(|f| f.sun_azimuth_deg == Some(azimuth) && f.sun_elevation_deg == Some(elevation))
            .unwrap();
        row.summary.mean_reflected_luminance_cd_m2
    };
    let (side, roof) = (lr(90.0, 10.0), lr(180.0, 40.0));
    assert!(
        side > 1.05 * roof,
        "side window {side}, behind the roof {roof}"
    );

    // The report lists the side-window sun as the worst case, with what the
    // glass mirrors there.
    let worst = &report.ranking[0].worst_cases[0];
    assert_eq!(
        (worst.sun_azimuth_deg, worst.sun_elevation_deg),
        (Some(90.0), Some(10.0))
    );
    let covering = worst.most_covering_object.as_ref().map(|c| c.name.as_str());
    assert_eq!(covering, Some("cab_walls"));
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    let first_case = html
        .find("<tr><td>1<br>sun azimuth ")
        .expect("a worst-case table");
    assert!(
        html[first_case..].starts_with("<tr><td>1<br>sun azimuth 90.0&deg;, elevation 10.0&deg;"),
        "{}",
        &html[first_case..first_case + 120]
    );
    assert!(
        html.contains("over the sun positions</text>"),
        "the polar plots"
    );
    assert!(dir.path().join("current/sun_000/eye_00/heat.png").is_file());
    let csv = std::fs::read_to_string(dir.path().join("summary.csv")).unwrap();
    assert!(
        csv.lines()
            .next()
            .unwrap()
            .contains("sun_azimuth_deg,sun_elevation_deg")
    );
}

#[test]
fn a_date_range_skips_the_night_and_turns_the_sun_with_the_heading() {
    let dir = tempfile::tempdir().unwrap();
    // Munich on the June solstice, every three hours of the UTC day, driving
    // east: the sun is up from about 03:12 to 19:17 UTC.
    let plan = study_plan(
        dir.path(),
        &[vtfarm_cockpit::default_eye()],
        "[[variants]]\nname = \"flat\"\nglass = \"flat\"\n\
         [sun]\nstart = 2026-06-21T00:00:00Z\nend = 2026-06-21T21:00:00Z\nstep_minutes = 180\n\
         latitude = 48.14\nlongitude = 11.58\nheading = 90\n",
    );
    let below: Vec<String> = plan
        .suns_below_horizon
        .iter()
        .map(|t| t.to_string())
        .collect();
    assert_eq!(
        below,
        [
            "2026-06-21T00:00:00Z",
            "2026-06-21T03:00:00Z",
            "2026-06-21T21:00:00Z"
        ]
    );
    assert_eq!(plan.suns.len(), 5);
    assert_eq!(plan.variants[0].setups.len(), 5);
    assert!(plan.suns.iter().all(|s| s.elevation_deg > 0.0));
    // Near solar noon (11:27 UTC) the sun stands in the south, on the
    // right of a vehicle driving east, about 65° high (90° - 48.1° + 23.4°).
    let noon = plan.suns[2];
    assert_eq!(noon.time.unwrap().to_string(), "2026-06-21T12:00:00Z");
    assert!((noon.azimuth_deg - 90.0).abs() < 25.0, "{noon:?}");
    assert!((noon.elevation_deg - 64.5).abs() < 1.5, "{noon:?}");
    // The frame's sun light comes from there.
    let lighting = &plan.variants[0].setups[2].lighting;
    let vtfarm_scene::LightKind::Directional { direction, .. } = lighting.lights[0].kind else {
        panic!("the cockpit's sun is its first light");
    };
    let (azimuth, elevation) = sun::vehicle_angles(-direction);
    assert!(
        (azimuth - noon.azimuth_deg).abs() < 1e-3 && (elevation - noon.elevation_deg).abs() < 1e-3
    );
}

#[test]
fn the_stock_glass_names_the_side_window_as_culprit_and_its_fixed_sun_once() {
    // The stock cover glass from the nominal eye: the cab walls cover most
    // of the glass, dim; the left side window makes the glare.
    let dir = tempfile::tempdir().unwrap();
    let plan = study_plan(
        dir.path(),
        &[vtfarm_cockpit::default_eye()],
        "[[variants]]\nname = \"current\"\nglass = \"current\"\n",
    );
    let (report, _) = run(&plan, dir.path());
    let score = &report.ranking[0];
    let culprit = score
        .glare_culprits
        .first()
        .expect("the stock glass glares");
    assert_eq!(
        culprit.name, "side_window_left",
        "{:?}",
        score.glare_culprits
    );
    assert!(culprit.glare_share > 0.5, "{culprit:?}");
    assert!(score.glare_culprits.len() <= CULPRITS);
    let covering = score.most_covering_object.as_ref().unwrap();
    assert_eq!(covering.name, "cab_walls");
    let worst = &score.worst_cases[0];
    assert_eq!(worst.glare_culprits[0].name, "side_window_left");

    // summary.csv: the culprits, each with its share, and coverage apart.
    let csv = std::fs::read_to_string(dir.path().join("summary.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let row: Vec<&str> = lines.next().unwrap().split(',').collect();
    let column = |name: &str| {
        let k = header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("{name}"));
        row[k]
    };
    assert_eq!(column("culprit_1"), "side_window_left");
    assert!(column("culprit_1_glare_share").parse::<f32>().unwrap() > 0.5);
    assert_eq!(column("most_covering_object"), "cab_walls");
    // A fixed sun is the study's, not each row's.
    assert_eq!(column("sun_azimuth_deg"), "");

    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("summary.json")).unwrap())
            .unwrap();
    assert_eq!(json["sun"]["setting"], "fixed_from_job");
    let ranking = &json["ranking"][0];
    assert_eq!(ranking["glare_culprits"][0]["name"], "side_window_left");
    assert_eq!(ranking["most_covering_object"]["name"], "cab_walls");

    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(html.contains("Sun: fixed, the base job's directional light"));
    assert!(
        !html.contains("<th>sun</th>"),
        "no sun column without a sweep"
    );
    assert!(
        html.contains("side_window_left "),
        "the culprit in the tables"
    );
    assert!(html.contains("<th>x (m)</th>"), "units on the eye table");
    assert!(html.contains("glare threshold"), "threshold lines");
}

#[test]
fn the_report_says_how_it_was_made_and_warns_below_full() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("job.toml"),
        "[scene]\nbuiltin = \"cockpit\"\ndetail = 0.3\n",
    )
    .unwrap();
    let file = dir.path().join("study.toml");
    let text = "[study]\njob = \"job.toml\"\nwidth = 96\nheight = 54\n[eyes]\npoints = [[-0.55, 1.4, 0.1]]\n[[variants]]\nname = \"flat\"\nglass = \"flat\"\n";
    std::fs::write(&file, text).unwrap();
    let plan = plan_file(&file, Some(Quality::Preview)).unwrap();
    let (report, _) = run(&plan, dir.path());
    assert!(report.missing_frames.is_empty());
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("summary.json")).unwrap())
            .unwrap();
    let p = &json["provenance"];
    assert_eq!(p["quality"], "preview");
    assert!(
        p["quality_warning"]
            .as_str()
            .unwrap()
            .contains("below \"full\"")
    );
    assert_eq!(p["vtfarm_version"], "0.1.0 (commit 0123456789ab)");
    assert_eq!(
        (p["width"].as_u64(), p["height"].as_u64()),
        (Some(96), Some(54))
    );
    assert_eq!(p["method"], plan.method.name());
    assert_eq!(p["hash"], "SHA-256");
    assert_eq!(p["command"], "vtfarm study 'study file.toml'");
    // The study file's hash is SHA-256 of its bytes (a known digest).
    use sha2::Digest;
    let digest = hex::encode(sha2::Sha256::digest(text.as_bytes()));
    assert_eq!(p["inputs"][0]["role"], "study file");
    assert_eq!(p["inputs"][0]["sha256"], digest.as_str());
    assert_eq!(p["inputs"][1]["role"], "job file");
    assert_eq!(json["complete"], true);
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(
        html.contains("<p class=\"warning\">Warning: quality &quot;preview&quot; is below"),
        "{}",
        &html[..3000]
    );
    assert!(html.contains(&digest) && html.contains("local, 1 worker(s) sharing 2 threads"));
    // At `full` no warning.
    let full = plan_file(&file, Some(Quality::Full)).unwrap();
    let provenance = Provenance::new(&full, &test_run());
    assert_eq!(provenance.quality_warning, None);
}

/// A plan of a sun grid and eye points, without variants (the order
/// depends on the sweep only).
fn sweep_plan(azimuths: usize, elevations: usize, eyes: usize) -> StudyPlan {
    let suns = (0..elevations)
        .flat_map(|e| {
            (0..azimuths).map(move |a| SunPosition {
                azimuth_deg: a as f32 * 360.0 / azimuths as f32,
                elevation_deg: 5.0 + 80.0 * e as f32 / elevations as f32,
                time: None,
            })
        })
        .collect();
    StudyPlan {
        name: "sweep".into(),
        file: "study.toml".into(),
        eyes: vec![Vec3::ZERO; eyes],
        suns,
        suns_below_horizon: Vec::new(),
        sun_grid: Some((azimuths, elevations)),
        base_sun: None,
        variants: Vec::new(),
        params: Params::default(),
        glint: vtfarm_glare::GlintThreshold::default(),
        heat_range: LogRange {
            min_cd_m2: 1.0,
            max_cd_m2: 10.0,
        },
        method: vtfarm_method::MethodKind::VertexTracing,
        quality: Quality::Full,
        width: 1,
        height: 1,
        inputs: Vec::new(),
        exposure: vtfarm_imaging::Exposure::default(),
    }
}

#[test]
fn after_a_tenth_of_a_sweeps_frames_every_region_of_the_sun_polar_plot_has_a_frame() {
    // The polar plot's regions: four azimuth quadrants (ahead, right,
    // behind, left) by the lower and upper half of the swept elevations.
    for (azimuths, elevations, eyes) in [(8, 2, 7), (24, 4, 7), (16, 3, 3), (36, 6, 9)] {
        let plan = sweep_plan(azimuths, elevations, eyes);
        let order = plan.frame_order();
        let mut sorted = order.clone();
        sorted.sort();
        assert_eq!(sorted, (0..plan.frames_per_variant()).collect::<Vec<_>>());
        let tenth = plan.frames_per_variant().div_ceil(10);
        let mut regions = std::collections::BTreeSet::new();
        for &frame in &order[..tenth] {
            let sun = plan.suns[plan.frame_at(frame).0.unwrap()];
            let quadrant = ((sun.azimuth_deg + 45.0).rem_euclid(360.0) / 90.0) as usize;
            let upper = sun.elevation_deg >= 45.0;
            regions.insert((quadrant, upper));
        }
        assert_eq!(
            regions.len(),
            8,
            "{azimuths}x{elevations}x{eyes}: {regions:?}"
        );
        // The nominal eye and the first sun come first.
        assert_eq!(order[0], 0);
    }
}

#[test]
fn the_order_takes_every_other_index_before_those_between() {
    assert_eq!(
        (0..8).map(|i| order::level(i, 8)).collect::<Vec<_>>(),
        [0, 3, 2, 3, 1, 3, 2, 3]
    );
    assert_eq!(order::level(0, 1), 0);
    let plan = sweep_plan(1, 1, 5);
    assert_eq!(plan.frame_order(), [0, 4, 2, 1, 3]);
}

#[test]
fn no_polar_plot_value_lies_beyond_its_scale_unmarked_and_a_partial_report_lists_its_gaps() {
    let dir = tempfile::tempdir().unwrap();
    // The current glass mirrors far more than the flat one: one shared
    // scale must cover both.
    let plan = study_plan(
        dir.path(),
        &[vtfarm_cockpit::default_eye()],
        "[[variants]]\nname = \"current\"\nglass = \"current\"\n\
         [[variants]]\nname = \"flat\"\nglass = \"flat\"\n\
         [sun]\nazimuths = [90, 180]\nelevations = [10]\n",
    );
    let (report, _) = run(&plan, dir.path());
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    let attr = |disc: &str, name: &str| -> String {
        let start = disc.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
        disc[start..].split('"').next().unwrap().to_owned()
    };
    let discs: Vec<&str> = html
        .split("<circle")
        .filter(|c| c.contains("data-value"))
        .collect();
    assert_eq!(
        discs.len(),
        2 * 2 * 2,
        "two plots per variant, a disc per sun"
    );
    let mut tops = std::collections::BTreeSet::new();
    for disc in &discs {
        let value: f32 = attr(disc, "data-value").parse().unwrap();
        let top: f32 = attr(disc, "data-top").parse().unwrap();
        let beyond = attr(disc, "data-beyond") == "true";
        assert!(value <= top || beyond, "{value} beyond {top} unmarked");
        tops.insert(top.to_bits());
    }
    // The mean-luminance scale ends at the largest value of any variant.
    let largest = (report.frames.iter())
        .map(|f| f.summary.mean_reflected_luminance_cd_m2)
        .fold(0.0f32, f32::max);
    assert!(
        tops.contains(&largest.to_bits()),
        "{largest} not a scale's top"
    );
    assert!(html.contains("scale shared by all variants"));

    // A partial report of the frames so far names the ones it lacks.
    let partial = dir.path().join("partial");
    let mut writer = StudyWriter::new(&plan, &partial).unwrap();
    let variant = &plan.variants[1];
    let renderer = Renderer::new(Arc::new(variant.scene.clone()), variant.reflectors.clone());
    let frame = renderer.render(
        &variant.setups[1],
        &RenderOptions::default(),
        &mut |_, _| {},
    );
    writer.frame(1, 1, &frame.image).unwrap();
    assert!(matches!(
        StudyWriter::new(&plan, &partial)
            .unwrap()
            .finish(&test_run()),
        Err(StudyError::Frame { .. })
    ));
    let report = writer.finish_partial(&test_run()).unwrap();
    assert_eq!(report.frames.len(), 1);
    let missing: Vec<(&str, Option<usize>)> = (report.missing_frames.iter())
        .map(|m| (m.variant.as_str(), m.sun_index))
        .collect();
    assert_eq!(
        missing,
        [
            ("current", Some(0)),
            ("current", Some(1)),
            ("flat", Some(0))
        ]
    );
    let html = std::fs::read_to_string(partial.join("report.html")).unwrap();
    assert!(
        html.contains("Partial report: 1 of 4 frames rendered"),
        "{}",
        &html[..2000]
    );
    assert!(
        html.contains("Missing (3): current sun 0 eye 0, current sun 1 eye 0, flat sun 0 eye 0")
    );
    assert!(html.contains("not rendered</title>"));
    let json = std::fs::read_to_string(partial.join("summary.json")).unwrap();
    assert!(json.contains("\"complete\": false"));
}

#[test]
fn a_sun_sweep_finds_the_suns_glint_in_the_cover_glass_and_reports_its_veil() {
    let dir = tempfile::tempdir().unwrap();
    // The stock cab stands emissive panels outside its windows for the
    // sky and the view, and nothing is seen through a panel, the sun
    // included. Without those panels its windows open onto the sky.
    let mut cab = vtfarm_cockpit::cockpit(&vtfarm_cockpit::CockpitConfig {
        detail: 0.3,
        ..Default::default()
    })
    .scene;
    let panels: Vec<vtfarm_scene::ObjectId> =
        ["windshield_sky", "side_window_left", "side_window_right"]
            .iter()
            .map(|name| cab.object_id(name).expect("a stock panel"))
            .collect();
    cab.triangles.retain(|t| !panels.contains(&t.object));
    vtfarm_scene::obj::write_obj(&cab, dir.path(), "open-cab").unwrap();
    let variant = "[[variants]]\nname = \"open cab\"\nobj = \"open-cab.obj\"\n";

    // Where the glass mirrors the sky seen from the eye, a sun would glint:
    // the mirror direction at the middle one of those glass pixels.
    let probe = study_plan(dir.path(), &[vtfarm_cockpit::default_eye()], variant);
    let v = &probe.variants[0];
    let setup = &v.setups[0];
    let renderer = Renderer::new(Arc::new(v.scene.clone()), v.reflectors.clone());
    let frame = (renderer.render(setup, &RenderOptions::default(), &mut |_, _| {})).image;
    let (ids, _) = renderer.id_buffers(setup);
    let camera = &setup.camera;
    let mirrored: Vec<Vec3> = (frame.glass())
        .filter(|&i| frame.pixel(i).object == NONE)
        .map(|i| {
            let (x, y) = (i as u32 % camera.width, i as u32 / camera.width);
            let triangle = TriangleId(ids.triangle_at(x, y));
            let (surface, ray) =
                vtfarm_vertex::pixel_surface(&v.scene, camera, &ids, triangle, x, y);
            vtfarm_trace::reflect(ray, surface.normal)
        })
        .collect();
    assert!(
        mirrored.len() >= 10,
        "the glass mirrors the sky on {} pixels",
        mirrored.len()
    );
    let (azimuth, elevation) = crate::sun::vehicle_angles(mirrored[mirrored.len() / 2]);
    assert!(elevation > 1.0, "a sun above the horizon: {elevation}°");

    // The sweep: that sun, and one a quarter turn away.
    let away = (azimuth + 90.0) % 360.0;
    let plan = study_plan(
        dir.path(),
        &[vtfarm_cockpit::default_eye()],
        &format!("{variant}[sun]\nazimuths = [{azimuth}, {away}]\nelevations = [{elevation}]\n"),
    );
    let (report, _) = run(&plan, dir.path());
    let at = |a: f32| {
        let row = (report.frames.iter())
            .find(|f| f.sun_azimuth_deg == Some(a))
            .expect("a frame per sun");
        &row.glint
    };
    let glint = at(azimuth);
    assert!(glint.reaches_eye(), "the mirrored sun glints: {glint:?}");
    assert!(glint.peak_luminance_cd_m2 >= plan.glint.luminance_cd_m2);
    assert!(glint.eye_illuminance_lux > 0.0);
    let worst = glint.worst_instrument().expect("a veil on an instrument");
    let closed = 10.0 * glint.eye_illuminance_lux / (worst.angle_deg * worst.angle_deg);
    assert!(
        (worst.veiling_luminance_cd_m2 / closed - 1.0).abs() < 1e-5,
        "{worst:?}"
    );
    assert!(!at(away).reaches_eye(), "{:?}", at(away));

    // The report marks that sun on the polar plots and in the table, and
    // summary.json carries the figures.
    let html = std::fs::read_to_string(dir.path().join("report.html")).unwrap();
    assert!(
        html.contains("sun glint at the eye</b>"),
        "the frame's figures"
    );
    assert!(
        html.contains(r##"r="11" fill="none" stroke="#d00""##),
        "the polar mark"
    );
    let json = std::fs::read_to_string(dir.path().join("summary.json")).unwrap();
    for key in [
        "\"eye_illuminance_lux\"",
        "\"angle_deg\"",
        "\"within_validity\"",
    ] {
        assert!(json.contains(key), "summary.json lacks {key}");
    }
}
