//! Luminance against physics: closed-form results, each within 1 %, in
//! cd/m² through `vtfarm_scene::photometry` (the one statement of the
//! units). A dielectric interface and a two-surface pane reflecting a
//! uniform emitter (the unpolarised Fresnel equations), a Lambertian panel
//! under a sun of known illuminance, an ideal mirror.

use std::sync::Arc;

use glam::Vec3;
use vtfarm_scene::photometry::{self, CD_M2_PER_UNIT};
use vtfarm_scene::{Light, LightKind, Lighting, Material, TriangleId};

use crate::testutil::{SceneBuilder, emitter, mirror};
use crate::{PixelCone, SceneBvh, SurfacePoint, TraceSettings, Tracer};

/// The emitter's luminance, cd/m².
const EMITTER_CD_M2: f32 = 20_000.0;

/// Unpolarised Fresnel reflectance of light arriving at `theta` (radians)
/// from air on a dielectric of index `n`, straight from the Fresnel
/// equations (in f64, independent of the tracer's own formula).
fn fresnel(theta: f64, n: f64) -> f64 {
    let (cos_i, sin_i) = (theta.cos(), theta.sin());
    let cos_t = (1.0 - (sin_i / n).powi(2)).sqrt();
    let rs = (cos_i - n * cos_t) / (cos_i + n * cos_t);
    let rp = (n * cos_i - cos_t) / (n * cos_i + cos_t);
    0.5 * (rs * rs + rp * rp)
}

/// A clear dielectric of index `n`: head-on kr = F0 and kt = 1 − F0, so
/// that with Fresnel weights it reflects exactly F(θ).
fn dielectric(name: &str, n: f32) -> Material {
    let f0 = ((n - 1.0) / (n + 1.0)).powi(2);
    Material {
        reflectance: Vec3::splat(f0),
        transmittance: Vec3::splat(1.0 - f0),
        ior: n,
        ..Material::diffuse(name, Vec3::ZERO)
    }
}

fn dark() -> Lighting {
    Lighting {
        lights: Vec::new(),
        ambient: Vec3::ZERO,
        background: Vec3::ZERO,
    }
}

fn within_one_percent(what: &str, actual: f64, expected: f64) {
    let error = (actual - expected).abs() / expected.abs();
    assert!(
        error <= 0.01,
        "{what}: {actual} cd/m², expected {expected} cd/m² ({:.3} % off)",
        error * 100.0
    );
}

/// A uniform emitter of [`EMITTER_CD_M2`] filling the sky over the plane
/// y = 0 (a panel at y = 1, far wider than any ray of the tests reaches).
fn sky(b: &mut SceneBuilder) {
    let glow = photometry::emission(Vec3::ONE, EMITTER_CD_M2).expect("white has luminance");
    b.quad(
        emitter("sky", glow),
        Vec3::new(-1e3, 1.0, -1e3),
        Vec3::X * 2e3,
        Vec3::Z * 2e3,
    );
}

/// The reflected luminance (cd/m²) of the glass at the origin seen at
/// `theta_deg` from its normal (+Y), with Fresnel weights.
fn reflected_at(bvh: &SceneBvh, theta_deg: f32, max_depth: u32) -> f64 {
    let lighting = dark();
    let tracer = Tracer {
        bvh,
        lighting: &lighting,
        settings: TraceSettings {
            fresnel: true,
            max_depth,
            ..TraceSettings::default()
        },
        cone: PixelCone::FINEST,
    };
    let a = theta_deg.to_radians();
    let point = SurfacePoint {
        position: Vec3::ZERO,
        normal: Vec3::Y,
        triangle: TriangleId(0),
    };
    let incoming = Vec3::new(a.sin(), -a.cos(), 0.0);
    f64::from(photometry::cd_m2(tracer.shade(&point, incoming).reflected))
}

#[test]
fn a_dielectric_surface_reflects_l_times_the_fresnel_reflectance() {
    let mut b = SceneBuilder::default();
    // One interface, n = 1.5, facing up (+Y); nothing below it.
    b.quad(
        dielectric("pane", 1.5),
        Vec3::new(-50.0, 0.0, -50.0),
        Vec3::Z * 100.0,
        Vec3::X * 100.0,
    );
    sky(&mut b);
    let bvh = SceneBvh::new(Arc::new(b.scene));
    for theta in [0.0f32, 45.0, 70.0] {
        let expected = f64::from(EMITTER_CD_M2) * fresnel(f64::from(theta).to_radians(), 1.5);
        within_one_percent(&format!("{theta}°"), reflected_at(&bvh, theta, 5), expected);
    }
    // The figures the check stands on: 4.0 %, 5.0 % and 17.1 %.
    assert!((fresnel(0.0, 1.5) - 0.04).abs() < 1e-12);
    assert!((fresnel(45f64.to_radians(), 1.5) - 0.0503).abs() < 1e-4);
    assert!((fresnel(70f64.to_radians(), 1.5) - 0.1711).abs() < 1e-4);
}

#[test]
fn a_thin_sheet_reflects_l_times_the_fresnel_reflectance_of_its_ior() {
    // One surface drawn as a thin sheet (a job's `thin = true`, a glTF
    // transmission material): rays pass it straight, its ior 1.6 gives the
    // Fresnel weights. Nothing lies below it.
    let n = 1.6;
    let mut b = SceneBuilder::default();
    b.quad(
        Material {
            thin: true,
            ..dielectric("sheet", n)
        },
        Vec3::new(-50.0, 0.0, -50.0),
        Vec3::Z * 100.0,
        Vec3::X * 100.0,
    );
    sky(&mut b);
    let bvh = SceneBvh::new(Arc::new(b.scene));
    for theta in [0.0f32, 45.0, 70.0] {
        let f = fresnel(f64::from(theta).to_radians(), f64::from(n));
        let expected = f64::from(EMITTER_CD_M2) * f;
        within_one_percent(&format!("{theta}°"), reflected_at(&bvh, theta, 5), expected);
        // The rest passes straight through: the ior bends no ray.
        let lighting = dark();
        let tracer = Tracer {
            bvh: &bvh,
            lighting: &lighting,
            settings: TraceSettings {
                fresnel: true,
                ..TraceSettings::default()
            },
            cone: PixelCone::FINEST,
        };
        let a = theta.to_radians();
        let incoming = Vec3::new(a.sin(), -a.cos(), 0.0);
        let point = SurfacePoint {
            position: Vec3::ZERO,
            normal: Vec3::Y,
            triangle: TriangleId(0),
        };
        let terms = tracer.surface_terms(&point, incoming);
        let through = terms.refraction.expect("a thin sheet transmits").direction;
        assert!(through.distance(incoming) < 1e-6, "{theta}°: {through}");
        let kt = f64::from(terms.kt.x);
        assert!((kt - (1.0 - f)).abs() < 1e-3, "{theta}°: kt {kt}");
    }
}

#[test]
fn a_pane_reflects_both_surfaces_as_reflected_light() {
    // A 1-cm pane of n = 1.5: the front faces up, the back (a separate
    // surface) faces down. Its reflectance with every inner bounce is
    // R + T²R / (1 − R²) = 2R / (1 + R) (T = 1 − R, the same R at both
    // surfaces by reciprocity); all of it counts as reflected.
    let mut b = SceneBuilder::default();
    b.quad(
        dielectric("front", 1.5),
        Vec3::new(-50.0, 0.0, -50.0),
        Vec3::Z * 100.0,
        Vec3::X * 100.0,
    );
    b.quad(
        dielectric("back", 1.5),
        Vec3::new(-50.0, -0.01, -50.0),
        Vec3::X * 100.0,
        Vec3::Z * 100.0,
    );
    sky(&mut b);
    let bvh = SceneBvh::new(Arc::new(b.scene));
    for theta in [0.0f32, 45.0, 70.0] {
        let r = fresnel(f64::from(theta).to_radians(), 1.5);
        let expected = f64::from(EMITTER_CD_M2) * 2.0 * r / (1.0 + r);
        within_one_percent(
            &format!("pane at {theta}°"),
            reflected_at(&bvh, theta, 12),
            expected,
        );
    }
}

#[test]
fn a_lambertian_panel_under_e_lux_has_rho_e_over_pi() {
    let (rho, lux) = (0.6f32, 80_000.0f32);
    let mut b = SceneBuilder::default();
    b.quad(
        Material::diffuse("panel", Vec3::splat(rho)),
        Vec3::new(-1.0, 0.0, -1.0),
        Vec3::Z * 2.0,
        Vec3::X * 2.0,
    );
    let bvh = SceneBvh::new(Arc::new(b.scene));
    let color = Vec3::new(1.0, 0.95, 0.85);
    for incidence_deg in [0.0f32, 40.0] {
        let a = incidence_deg.to_radians();
        let lighting = Lighting {
            lights: vec![Light {
                kind: LightKind::Directional {
                    direction: Vec3::new(a.sin(), -a.cos(), 0.0),
                    angular_diameter_deg: 0.0,
                },
                color,
                intensity: photometry::directional_intensity(color, lux).unwrap(),
            }],
            ambient: Vec3::ZERO,
            background: Vec3::ZERO,
        };
        let tracer = Tracer {
            bvh: &bvh,
            lighting: &lighting,
            settings: TraceSettings::default(),
            cone: PixelCone::FINEST,
        };
        let point = SurfacePoint {
            position: Vec3::ZERO,
            normal: Vec3::Y,
            triangle: TriangleId(0),
        };
        let seen = tracer.shade(&point, Vec3::new(0.0, -1.0, 0.3).normalize());
        let expected = f64::from(rho * lux * a.cos()) / std::f64::consts::PI;
        within_one_percent(
            &format!("panel at {incidence_deg}°"),
            f64::from(photometry::cd_m2(seen.color)),
            expected,
        );
    }
}

#[test]
fn an_ideal_mirror_reflects_l() {
    let mut b = SceneBuilder::default();
    b.quad(
        mirror("mirror"),
        Vec3::new(-50.0, 0.0, -50.0),
        Vec3::Z * 100.0,
        Vec3::X * 100.0,
    );
    sky(&mut b);
    let bvh = SceneBvh::new(Arc::new(b.scene));
    for theta in [0.0f32, 45.0, 70.0] {
        let lighting = dark();
        let tracer = Tracer {
            bvh: &bvh,
            lighting: &lighting,
            settings: TraceSettings::default(),
            cone: PixelCone::FINEST,
        };
        let a = theta.to_radians();
        let point = SurfacePoint {
            position: Vec3::ZERO,
            normal: Vec3::Y,
            triangle: TriangleId(0),
        };
        let sample = tracer.shade(&point, Vec3::new(a.sin(), -a.cos(), 0.0));
        within_one_percent(
            &format!("mirror at {theta}°"),
            f64::from(photometry::cd_m2(sample.reflected)),
            f64::from(EMITTER_CD_M2),
        );
        assert_eq!(sample.color, sample.reflected, "a mirror shows only L");
    }
    // The convention's scale, for the record: 1 render unit = 10,000 cd/m².
    assert_eq!(CD_M2_PER_UNIT, 10_000.0);
}
