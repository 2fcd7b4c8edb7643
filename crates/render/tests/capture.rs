//! The sun as the source it is, and conservative capture: a glint the
//! vertex samples cannot see, a small bright source between them and a
//! reflector face with no visible corner are found at `full` as the
//! per-pixel reference finds them.

use std::sync::Arc;

use glam::Vec3;
use vtfarm_glare::{Glint, GlintThreshold, measure_glint};
use vtfarm_render::{FrameSetup, RenderOptions, Renderer};
use vtfarm_scene::photometry::{self, directional_intensity};
use vtfarm_scene::{Camera, Light, LightKind, Lighting, Material, Scene, TriangleId};
use vtfarm_vertex::{FrameImage, Quality};

const SUN_LUX: f32 = 100_000.0;
const KR: f32 = 0.1;

fn mirror(kr: f32) -> Material {
    Material {
        reflectance: Vec3::splat(kr),
        ..Material::diffuse("mirror", Vec3::ZERO)
    }
}

/// The triangles of the object `name`.
fn triangles_of(scene: &Scene, name: &str) -> Vec<TriangleId> {
    let object = scene.object_id(name).unwrap();
    scene.triangles_of(object).collect()
}

fn render(renderer: &Renderer, setup: &FrameSetup, quality: Quality) -> FrameImage {
    let mut setup = setup.clone();
    setup.vertex.quality = quality;
    renderer
        .render(&setup, &RenderOptions::default(), &mut |_, _| {})
        .image
}

/// The reflected luminance (cd/m²) of every pixel of a frame.
fn reflected_cd_m2(frame: &FrameImage) -> Vec<f32> {
    (frame.components().reflected.pixels.iter())
        .map(|&c| photometry::cd_m2(c))
        .collect()
}

fn eye(width: u32) -> Camera {
    Camera {
        eye: Vec3::new(0.0, 0.5, 2.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_deg: 40.0,
        width,
        height: width * 9 / 16,
    }
}

/// Where the eye sees the sun mirrored at the image centre: a mirror in
/// z = 0 reflects the ray to the origin toward +z.
fn toward_sun() -> Vec3 {
    Vec3::new(0.0, -0.5, 2.0).normalize()
}

fn sun() -> Light {
    Light {
        kind: LightKind::sun(-toward_sun()),
        color: Vec3::ONE,
        intensity: directional_intensity(Vec3::ONE, SUN_LUX).unwrap(),
    }
}

/// A two-triangle mirror of kr 0.1 whose corners the eye sees, the sun
/// mirrored in its middle (where no vertex sees it), and `between` (a
/// window or a roof) across the sun's way back when given.
fn glint_scene(width: u32, between: Option<Material>) -> (Renderer, FrameSetup) {
    let mut scene = Scene::default();
    // The glint at the origin: off the quad's diagonal and its samples.
    scene.append_quad(
        "mirror",
        mirror(KR),
        Vec3::new(-0.37, -0.41, 0.0),
        Vec3::X * 0.93,
        Vec3::Y * 0.87,
    );
    if let Some(material) = between {
        // At z = 1 the reflected rays of the glint pass y = -0.25; the eye's
        // rays to the glint pass y = 0.25.
        scene.append_quad(
            "between",
            material,
            Vec3::new(-1.0, -0.8, 1.0),
            Vec3::Y * 0.75,
            Vec3::X * 2.0,
        );
    }
    let reflectors = triangles_of(&scene, "mirror");
    let setup = FrameSetup {
        camera: eye(width),
        lighting: Lighting {
            lights: vec![sun()],
            ambient: Vec3::ZERO,
            background: Vec3::ZERO,
        },
        trace: Default::default(),
        vertex: Default::default(),
    };
    (Renderer::new(Arc::new(scene), reflectors), setup)
}

/// The glint of luminance map `l`: its pixels at or above `floor_cd_m2`.
fn glint(l: &[f32], camera: &Camera, floor_cd_m2: f32) -> Glint {
    let threshold = GlintThreshold {
        luminance_cd_m2: floor_cd_m2,
        source: "the test's floor".into(),
    };
    measure_glint(l, camera, &threshold, &[])
}

/// The glint of a frame's reflected light, and the angular diameter (°)
/// of its image: the disc whose second moment about its centre the
/// image's has, the pixel footprint's share taken out (the tracer gives a
/// pixel the overlap of its footprint, a disc of the pixel's area).
fn measure(frame: &FrameImage, camera: &Camera) -> (Glint, f64) {
    let l = reflected_cd_m2(frame);
    let g = glint(&l, camera, 0.0);
    let axis = toward_sun();
    let reflected_axis = vtfarm_trace::reflect(axis, Vec3::Z);
    let mut moment = 0.0f64;
    for (i, &l) in l.iter().enumerate().filter(|(_, l)| **l > 0.0) {
        let (x, y) = (i as u32 % camera.width, i as u32 / camera.width);
        // The pixel's direction mirrored back to the sky.
        let seen = camera.pixel_ray(x, y);
        let theta = f64::from(seen.dot(reflected_axis).clamp(-1.0, 1.0).acos());
        moment += f64::from(l) * f64::from(camera.pixel_solid_angle(x, y)) * theta * theta;
    }
    moment /= f64::from(g.eye_illuminance_lux);
    let footprint = f64::from(camera.pixel_size_at_unit_depth()) / std::f64::consts::PI.sqrt();
    // A uniform disc of radius r has E[θ²] = r²/2; the footprint's adds ρ²/2.
    let radius = (2.0 * moment - footprint * footprint).max(0.0).sqrt();
    (g, 2.0 * radius.to_degrees())
}

#[test]
fn the_suns_glint_in_a_flat_mirror_lights_the_eye_with_kr_times_e_at_every_resolution() {
    let expected = f64::from(KR * SUN_LUX);
    for width in [320, 1280, 1920] {
        let (renderer, setup) = glint_scene(width, None);
        for quality in [Quality::Full, Quality::Reference] {
            let frame = render(&renderer, &setup, quality);
            let (g, diameter) = measure(&frame, &setup.camera);
            eprintln!(
                "{width} px {}: {:.1} lx, peak {:.3e} cd/m², {} px, image {diameter:.3}°",
                quality.name(),
                g.eye_illuminance_lux,
                g.peak_luminance_cd_m2,
                g.pixels
            );
            assert!(
                (f64::from(g.eye_illuminance_lux) / expected - 1.0).abs() <= 0.02,
                "{width} px {}: {} lx, expected {expected}",
                quality.name(),
                g.eye_illuminance_lux
            );
            assert!(
                (diameter / 0.53 - 1.0).abs() <= 0.1,
                "{width} px {}: an image of {diameter}°",
                quality.name()
            );
        }
    }
    // Resolved, a pixel the disc covers shows kr · E / Ω.
    let (renderer, setup) = glint_scene(1920, None);
    let frame = render(&renderer, &setup, Quality::Full);
    let omega = vtfarm_scene::solid_angle_of_cone(0.265f32.to_radians());
    let peak = glint(&reflected_cd_m2(&frame), &setup.camera, 0.0).peak_luminance_cd_m2;
    assert!(
        (peak / (KR * SUN_LUX / omega) - 1.0).abs() <= 0.01,
        "peak {peak} cd/m²"
    );
}

#[test]
fn a_window_of_kt_0_8_on_the_suns_way_passes_0_8_of_the_glint() {
    let window = Material {
        transmittance: Vec3::splat(0.8),
        ..Material::diffuse("window", Vec3::ZERO)
    };
    let expected = f64::from(0.8 * KR * SUN_LUX);
    let (renderer, setup) = glint_scene(640, Some(window));
    for quality in [Quality::Full, Quality::Reference] {
        let frame = render(&renderer, &setup, quality);
        let g = glint(&reflected_cd_m2(&frame), &setup.camera, 0.0);
        assert!(
            (f64::from(g.eye_illuminance_lux) / expected - 1.0).abs() <= 0.02,
            "{}: {} lx, expected {expected}",
            quality.name(),
            g.eye_illuminance_lux
        );
    }
}

#[test]
fn a_sun_the_roof_hides_gives_no_glint() {
    let roof = Material::diffuse("roof", Vec3::splat(0.05));
    let (renderer, setup) = glint_scene(640, Some(roof));
    for quality in Quality::ALL {
        let frame = render(&renderer, &setup, quality);
        let g = glint(&reflected_cd_m2(&frame), &setup.camera, 10_000.0);
        assert_eq!(g.pixels, 0, "{}: {g:?}", quality.name());
    }
}

/// A lamp of 1,000,000 cd/m² (above the default capture threshold),
/// 4 cm across, where the eye sees it mirrored at `at` on the mirror
/// plane z = 0.
fn add_lamp(scene: &mut Scene, camera: &Camera, at: Vec3) {
    let glow = photometry::emission(Vec3::ONE, 1.0e6).unwrap();
    let mirrored = vtfarm_trace::reflect((at - camera.eye).normalize(), Vec3::Z);
    let centre = at + mirrored * 1.5;
    scene.append_quad(
        "lamp",
        Material {
            emission: glow,
            ..Material::diffuse("lamp", Vec3::ZERO)
        },
        centre - Vec3::new(0.02, 0.02, 0.0),
        Vec3::Y * 0.04,
        Vec3::X * 0.04,
    );
}

/// The reflected light (sum of cd/m² over pixels) of the reflector pixels
/// that mirror `object`.
fn reflected_energy_of(frame: &FrameImage, object: vtfarm_scene::ObjectId) -> f64 {
    frame
        .glass()
        .filter(|&i| frame.pixel(i).object == object.raw())
        .map(|i| f64::from(photometry::cd_m2(frame.pixel(i).reflected)))
        .sum()
}

#[test]
fn a_small_lamp_mirrored_between_the_vertices_of_a_coarse_mirror_is_found_at_full() {
    let mut scene = Scene::default();
    scene.append_quad(
        "mirror",
        mirror(0.9),
        Vec3::new(-0.5, -0.5, 0.0),
        Vec3::X,
        Vec3::Y,
    );
    let camera = eye(640);
    add_lamp(&mut scene, &camera, Vec3::new(0.07, 0.05, 0.0));
    let lamp = scene.object_id("lamp").unwrap();
    let reflectors = triangles_of(&scene, "mirror");
    let renderer = Renderer::new(Arc::new(scene), reflectors);
    let setup = FrameSetup {
        camera,
        lighting: Lighting {
            lights: Vec::new(),
            ambient: Vec3::ZERO,
            background: Vec3::ZERO,
        },
        trace: Default::default(),
        vertex: Default::default(),
    };
    let reference = reflected_energy_of(&render(&renderer, &setup, Quality::Reference), lamp);
    let full = reflected_energy_of(&render(&renderer, &setup, Quality::Full), lamp);
    eprintln!("lamp: full {full:.4e}, reference {reference:.4e}");
    assert!(reference > 0.0, "the reference mirrors the lamp");
    assert!(full >= 0.99 * reference, "full {full} of {reference}");
    assert!(full <= 1.01 * reference, "full {full} of {reference}");
}

/// The sum of the reflected luminance over a frame's reflector pixels.
fn reflected_sum(frame: &FrameImage) -> f64 {
    frame
        .glass()
        .map(|i| f64::from(photometry::cd_m2(frame.pixel(i).reflected)))
        .sum()
}

#[test]
fn a_mirror_whose_corners_are_off_screen_or_hidden_reflects_at_every_level() {
    for hidden in [false, true] {
        let mut scene = Scene::default();
        // Corners off screen: far wider than the view. Hidden: inside the
        // view, behind a frame of four bars.
        let half = if hidden { 0.5 } else { 3.0 };
        // At z = 0.3 the eye's ray to (x, y, 0) passes (0.85 x, 0.075 + 0.85 y).
        scene.append_quad(
            "mirror",
            mirror(0.9),
            Vec3::new(-half, -half, 0.0),
            Vec3::X * 2.0 * half,
            Vec3::Y * 2.0 * half,
        );
        if hidden {
            let bar = Material::diffuse("bar", Vec3::splat(0.2));
            let z = 0.3;
            for (corner, u, v) in [
                (Vec3::new(-0.7, 0.375, z), Vec3::X * 1.4, Vec3::Y * 0.4),
                (Vec3::new(-0.7, -0.625, z), Vec3::X * 1.4, Vec3::Y * 0.4),
                (Vec3::new(-0.7, -0.225, z), Vec3::X * 0.4, Vec3::Y * 0.6),
                (Vec3::new(0.3, -0.225, z), Vec3::X * 0.4, Vec3::Y * 0.6),
            ] {
                scene.append_quad("frame", bar.clone(), corner, u, v);
            }
        }
        let camera = eye(480);
        add_lamp(&mut scene, &camera, Vec3::new(0.02, 0.0, 0.0));
        let reflectors = triangles_of(&scene, "mirror");
        let renderer = Renderer::new(Arc::new(scene), reflectors);
        let setup = FrameSetup {
            camera,
            lighting: Lighting {
                lights: Vec::new(),
                ambient: Vec3::splat(0.05),
                background: photometry::grey(1000.0),
            },
            trace: Default::default(),
            vertex: vtfarm_vertex::VertexSettings {
                // No capture: the face is found because no corner is seen.
                capture_cd_m2: f32::MAX,
                ..Default::default()
            },
        };
        let reference = reflected_sum(&render(&renderer, &setup, Quality::Reference));
        assert!(reference > 0.0);
        for quality in [Quality::Preview, Quality::Refine, Quality::Full] {
            let level = reflected_sum(&render(&renderer, &setup, quality));
            eprintln!(
                "hidden {hidden} {}: {level:.4e} of {reference:.4e}",
                quality.name()
            );
            assert!(
                (level / reference - 1.0).abs() <= 0.01,
                "hidden {hidden} {}: {level} of {reference}",
                quality.name()
            );
        }
    }
}
