//! One meaning of reflected light at every quality level: the light the
//! glass reflects toward the eye, its back surface's ghost included, at
//! `full` (the thin-glass model) as at `reference` (traced shading); and
//! the reflected luminance of the stock cockpit against physics.

use std::path::Path;
use std::sync::Arc;

use glam::Vec3;
use vtfarm_render::{FrameSetup, RenderOptions, Renderer};
use vtfarm_scene::photometry::{self, CD_M2_PER_UNIT};
use vtfarm_scene::{Camera, Lighting, Material, ObjectId, Scene, TriangleId};
use vtfarm_trace::{Ray, SceneBvh};
use vtfarm_vertex::{FrameImage, Quality};

/// The stock job, `configs/cockpit.toml` (the cover glass the reflector),
/// at `width` × `height` and `quality`; with `fresnel` overridden when
/// given.
fn stock_job(
    width: u32,
    height: u32,
    quality: Quality,
    fresnel: Option<bool>,
) -> (Renderer, FrameSetup) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../configs/cockpit.toml");
    let mut job = vtfarm_job::load_job(&path).expect("the stock job loads");
    job.vertex.quality = quality;
    if let Some(fresnel) = fresnel {
        job.trace.fresnel = fresnel;
    }
    let loaded = job.load_scene().expect("the cockpit builds");
    let reflectors = job
        .reflector_triangles(&loaded.scene, &loaded.object_aliases)
        .unwrap();
    let camera = Camera {
        width,
        height,
        ..loaded.camera
    };
    let setup = FrameSetup {
        camera,
        lighting: loaded.lighting,
        trace: job.trace,
        vertex: job.vertex,
    };
    (Renderer::new(Arc::new(loaded.scene), reflectors), setup)
}

fn render(renderer: &Renderer, setup: &FrameSetup, quality: Quality) -> FrameImage {
    let mut setup = setup.clone();
    setup.vertex.quality = quality;
    renderer
        .render(&setup, &RenderOptions::default(), &mut |_, _| {})
        .image
}

fn median(mut values: Vec<f32>) -> f32 {
    values.sort_by(f32::total_cmp);
    values[values.len() / 2]
}

/// The median over the glass pixels where both frames mirror `object` of
/// full's reflected luminance over the reference's.
fn median_ratio(full: &FrameImage, reference: &FrameImage, object: ObjectId) -> (f32, usize) {
    let object = object.raw();
    let ratios: Vec<f32> = reference
        .glass()
        .filter(|&i| full.pixel(i).object == object && reference.pixel(i).object == object)
        .map(|i| {
            photometry::cd_m2(full.pixel(i).reflected)
                / photometry::cd_m2(reference.pixel(i).reflected)
        })
        .collect();
    let n = ratios.len();
    (median(ratios), n)
}

/// The share of glass pixels whose reflected component differs between
/// the frames by more than 8/255 in some 8-bit sRGB channel: the `full`
/// tolerance of the colour (`accuracy.rs`), applied to the component.
fn reflected_share_off(full: &FrameImage, reference: &FrameImage) -> f64 {
    let glass: Vec<usize> = reference.glass().collect();
    let off = (glass.iter())
        .filter(|&&i| {
            let a = vtfarm_imaging::encode_srgb8(full.pixel(i).reflected);
            let b = vtfarm_imaging::encode_srgb8(reference.pixel(i).reflected);
            (0..3).any(|k| a[k].abs_diff(b[k]) > 8)
        })
        .count();
    off as f64 / glass.len() as f64
}

#[test]
fn full_and_reference_agree_on_the_reflected_light_of_the_stock_job() {
    let (renderer, setup) = stock_job(640, 360, Quality::Full, None);
    let full = render(&renderer, &setup, Quality::Full);
    let reference = render(&renderer, &setup, Quality::Reference);
    let window = renderer.scene().object_id("side_window_left").unwrap();
    let (ratio, pixels) = median_ratio(&full, &reference, window);
    eprintln!("side window: {pixels} pixels, full / reference {ratio}");
    assert!(pixels > 1000, "the glass mirrors the side window");
    assert!(
        (ratio - 1.0).abs() <= 0.02,
        "full / reference of the side window's reflection: {ratio}"
    );
    let off = reflected_share_off(&full, &reference);
    eprintln!(
        "reflected component: {:.3} % of glass pixels off",
        off * 100.0
    );
    assert!(off <= 0.01, "{:.3} % off", off * 100.0);
    // The glass's back surface is there: what it reflects is counted in
    // both as reflected (1.72 times the front's 0.12 · 25,000 cd/m²).
    let lr = median(
        reference
            .glass()
            .filter(|&i| reference.pixel(i).object == window.raw())
            .map(|i| photometry::cd_m2(reference.pixel(i).reflected))
            .collect(),
    );
    let front = 0.12 * vtfarm_cockpit::SUNLIT_WINDOW_CD_M2;
    assert!(lr > 1.7 * front && lr < 1.75 * front, "{lr} cd/m²");
}

#[test]
fn full_and_reference_agree_on_a_pane_whose_back_surface_is_no_reflector() {
    // A 4-mm pane: its front the reflector, its back a separate surface
    // (not a reflector) behind; a bright panel mirrored in it, a dim board
    // behind it.
    let glass = Material {
        reflectance: Vec3::splat(0.1),
        transmittance: Vec3::splat(0.85),
        ior: 1.5,
        ..Material::diffuse("glass", Vec3::ZERO)
    };
    let mut scene = Scene::default();
    let (w, h) = (1.0, 0.8);
    scene.append_quad(
        "pane",
        glass.clone(),
        Vec3::new(-w, -h, 0.0),
        Vec3::X * 2.0 * w,
        Vec3::Y * 2.0 * h,
    );
    scene.append_quad(
        "pane_back",
        glass,
        Vec3::new(-w, -h, -0.004),
        Vec3::Y * 2.0 * h,
        Vec3::X * 2.0 * w,
    );
    scene.append_quad(
        "board",
        Material::diffuse("board", Vec3::splat(0.3)),
        Vec3::new(-2.0, -2.0, -0.5),
        Vec3::X * 4.0,
        Vec3::Y * 4.0,
    );
    let glow = photometry::emission(Vec3::ONE, 20_000.0).unwrap();
    scene.append_quad(
        "panel",
        Material {
            emission: glow,
            ..Material::diffuse("panel", Vec3::ZERO)
        },
        Vec3::new(-3.0, -3.0, 4.0),
        Vec3::Y * 6.0,
        Vec3::X * 6.0,
    );
    let pane = scene.object_id("pane").unwrap();
    let reflectors: Vec<TriangleId> = scene.triangles_of(pane).collect();
    let panel = scene.object_id("panel").unwrap();
    let renderer = Renderer::new(Arc::new(scene), reflectors);
    let setup = FrameSetup {
        camera: Camera {
            eye: Vec3::new(0.3, 0.2, 2.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_deg: 50.0,
            width: 200,
            height: 150,
        },
        lighting: Lighting {
            lights: Vec::new(),
            ambient: Vec3::splat(0.05),
            background: Vec3::ZERO,
        },
        trace: Default::default(),
        vertex: Default::default(),
    };
    let full = render(&renderer, &setup, Quality::Full);
    let reference = render(&renderer, &setup, Quality::Reference);
    let (ratio, pixels) = median_ratio(&full, &reference, panel);
    assert!(pixels > 5000, "{pixels} pixels mirror the panel");
    assert!((ratio - 1.0).abs() <= 0.02, "full / reference {ratio}");
    assert!(reflected_share_off(&full, &reference) <= 0.01);
    // Both count the back surface: 0.1 + 0.85² · 0.1 of the panel.
    let lr = median(
        (reference.glass())
            .filter(|&i| reference.pixel(i).object == panel.raw())
            .map(|i| photometry::cd_m2(reference.pixel(i).reflected))
            .collect(),
    );
    let expected = (0.1 + 0.85 * 0.85 * 0.1) * 20_000.0;
    assert!(
        (lr / expected - 1.0).abs() <= 0.01,
        "{lr} vs {expected} cd/m²"
    );
}

/// Unpolarised Fresnel reflectance at `cos_i` from air onto index `n`.
fn fresnel(cos_i: f64, n: f64) -> f64 {
    let sin_t = (1.0 - cos_i * cos_i).sqrt() / n;
    let cos_t = (1.0 - sin_t * sin_t).sqrt();
    let rs = (cos_i - n * cos_t) / (cos_i + n * cos_t);
    let rp = (n * cos_i - cos_t) / (n * cos_i + cos_t);
    0.5 * (rs * rs + rp * rp)
}

#[test]
fn a_probe_pixel_of_the_stock_cockpit_reflects_r_theta_times_the_side_window() {
    // The stock job with Fresnel weights, so that R depends on θ.
    let (renderer, mut setup) = stock_job(320, 180, Quality::Reference, Some(true));
    setup.trace.max_depth = 8;
    let frame = render(&renderer, &setup, Quality::Reference);
    let scene = renderer.scene();
    let window = scene.object_id("side_window_left").unwrap();
    // A probe in the middle of the pixels that mirror the window.
    let probes: Vec<usize> = frame
        .glass()
        .filter(|&i| frame.pixel(i).object == window.raw())
        .collect();
    assert!(
        probes.len() > 100,
        "{} pixels mirror the window",
        probes.len()
    );
    let probe = probes[probes.len() / 2];
    let width = setup.camera.width;
    let (x, y) = (probe as u32 % width, probe as u32 / width);
    // θ from the traced geometry: the eye ray through the probe and the
    // glass's normal where it hits.
    let bvh = SceneBvh::new(Arc::new(scene.clone()));
    let direction = setup.camera.pixel_ray(x, y);
    let hit = (bvh.closest_hit(
        &Ray {
            origin: setup.camera.eye,
            direction,
        },
        f32::INFINITY,
    ))
    .expect("the probe's ray hits the glass");
    let point = bvh.surface_point(&hit);
    let cos = f64::from(direction.dot(point.normal.normalize()).abs());
    let theta = cos.acos().to_degrees();
    // The glass: kr 0.12 and kt 0.85 head-on, n = 1.5; with Fresnel the
    // share (F(θ) − F0) / (1 − F0) of kt moves to kr, at both surfaces
    // alike (the back is met at the refracted angle, where F is the same).
    let material = scene.material_of(point.triangle);
    let (kr0, kt0, n) = (
        f64::from(material.reflectance.x),
        f64::from(material.transmittance.x),
        f64::from(material.ior),
    );
    let f0 = fresnel(1.0, n);
    let moved = kt0 * (fresnel(cos, n) - f0) / (1.0 - f0);
    let (kr, kt) = (kr0 + moved, kt0 - moved);
    // The pane's reflectance, every inner bounce: R = kr + kt² kr / (1 − kr²).
    let pane = kr + kt * kt * kr / (1.0 - kr * kr);
    let window_cd_m2 = f64::from(vtfarm_cockpit::SUNLIT_WINDOW_CD_M2);
    let expected = pane * window_cd_m2;
    let measured = f64::from(photometry::cd_m2(frame.pixel(probe).reflected));
    eprintln!(
        "probe ({x}, {y}): θ = {theta:.1}°, R(θ) = {pane:.4}, {measured} cd/m² vs {expected}"
    );
    assert!(
        (measured / expected - 1.0).abs() <= 0.01,
        "probe at θ = {theta:.1}°: {measured} cd/m², expected R(θ) · L = {pane:.4} · {window_cd_m2}"
    );
    assert_eq!(CD_M2_PER_UNIT, 10_000.0);
}
