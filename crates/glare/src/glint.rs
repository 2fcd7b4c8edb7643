//! Sun glare: the sun's image mirrored in the glass (the glint) as the
//! driver's eye receives it, from a frame's reflected luminance and its
//! camera (SAE J1757-1's direct-sunlight case).
//!
//! - The glint is the glass pixels whose reflected luminance `L_r` reaches
//!   [`GlintThreshold`]; its illuminance at the eye is `E = Σ L_r·Ω` over
//!   them, `Ω` each pixel's solid angle
//!   ([`vtfarm_scene::Camera::pixel_solid_angle`]). For the sun mirrored by
//!   a glass of reflectance kr it is `kr · E_sun` whatever the resolution:
//!   the tracer gives a pixel its share of the disc.
//! - The veiling luminance it casts on an instrument follows the CIE
//!   disability-glare formula `L_v = 10·E/θ²` ([`cie_veiling_luminance`]),
//!   `θ` in degrees between the glint and the instrument as seen from the
//!   eye; it holds for roughly 1° < θ < 30° ([`CIE_VALIDITY_DEG`]), and a
//!   `θ` outside is flagged, never silently used.
//! - The marking contrast with `L_v` added to both luminances
//!   ([`contrast_with_veil`]) is the contrast in the direct-sun case.

use glam::Vec3;
use serde::Serialize;
use vtfarm_scene::Camera;

/// Glass pixels at or above this reflected luminance form the glint.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct GlintThreshold {
    pub luminance_cd_m2: f32,
    pub source: String,
}

/// Default [`GlintThreshold`]: above any daylit sky or surface seen in the
/// glass, below the sun's image in a plain glass.
pub const DEFAULT_GLINT_LUMINANCE_CD_M2: f32 = 100_000.0;
pub const DEFAULT_GLINT_SOURCE: &str = "vtfarm engineering default: above a bright sky or sunlit surface (at most about 10^4 cd/m2), below the sun's image in a 4% glass (about 6*10^7 cd/m2); the engineer's to set";

impl Default for GlintThreshold {
    fn default() -> Self {
        GlintThreshold {
            luminance_cd_m2: DEFAULT_GLINT_LUMINANCE_CD_M2,
            source: DEFAULT_GLINT_SOURCE.to_owned(),
        }
    }
}

/// The glare angles (degrees) within which the CIE disability-glare formula
/// `L_v = 10·E/θ²` holds (CIE 146:2002 gives its simple form for about
/// 1° to 30°).
pub const CIE_VALIDITY_DEG: (f32, f32) = (1.0, 30.0);
pub const CIE_SOURCE: &str = "CIE 146:2002 disability glare, L_v = 10 E / theta^2 (theta in degrees, valid about 1 to 30 deg)";

/// The CIE veiling luminance at the eye (cd/m²) of a glare source giving
/// `illuminance_lux` at the eye at `theta_deg` from the line of sight.
pub fn cie_veiling_luminance(illuminance_lux: f32, theta_deg: f32) -> f32 {
    10.0 * illuminance_lux / (theta_deg * theta_deg)
}

/// Whether `theta_deg` lies where the CIE formula holds.
pub fn cie_valid(theta_deg: f32) -> bool {
    (CIE_VALIDITY_DEG.0..=CIE_VALIDITY_DEG.1).contains(&theta_deg)
}

/// `CR = (L_m + L_veil) / (L_b + L_veil)`: a marking's contrast with a veil
/// (reflection, ambient and glare luminances summed) over both.
pub fn contrast_with_veil(marking_cd_m2: f32, background_cd_m2: f32, veil_cd_m2: f32) -> f32 {
    (marking_cd_m2 + veil_cd_m2) / (background_cd_m2 + veil_cd_m2)
}

/// An instrument the glint may veil: its name and where it is in the image
/// (pixel coordinates of its visible area's centre).
#[derive(Clone, Debug, PartialEq)]
pub struct Instrument {
    pub name: String,
    pub pixel: [f32; 2],
}

/// The glint's veil on one instrument.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct InstrumentVeil {
    pub name: String,
    /// Angle between the glint and the instrument seen from the eye.
    pub angle_deg: f32,
    /// `L_v = 10·E/θ²` (cd/m²).
    pub veiling_luminance_cd_m2: f32,
    /// Whether `angle_deg` lies in [`CIE_VALIDITY_DEG`]; outside it the
    /// figure is an extrapolation.
    pub within_validity: bool,
}

/// The sun glare of one frame.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Glint {
    /// Glass pixels at or above the glint threshold (0: no glint).
    pub pixels: usize,
    pub peak_luminance_cd_m2: f32,
    /// `Σ L·Ω` over the glint's pixels (lux at the eye, on the plane facing
    /// the glint).
    pub eye_illuminance_lux: f32,
    /// The `L·Ω`-weighted mean direction of the glint (world, unit).
    pub direction: Option<[f32; 3]>,
    pub instruments: Vec<InstrumentVeil>,
}

impl Glint {
    /// Whether the sun's image reaches the eye in this frame.
    pub fn reaches_eye(&self) -> bool {
        self.pixels > 0
    }

    /// The instrument veiled most.
    pub fn worst_instrument(&self) -> Option<&InstrumentVeil> {
        (self.instruments.iter()).max_by(|a, b| {
            a.veiling_luminance_cd_m2
                .total_cmp(&b.veiling_luminance_cd_m2)
        })
    }
}

/// Measures the glint of a frame seen by `camera` whose glass pixels have
/// reflected luminance `reflected_cd_m2` (row-major, 0 off the glass).
pub fn measure_glint(
    reflected_cd_m2: &[f32],
    camera: &Camera,
    threshold: &GlintThreshold,
    instruments: &[Instrument],
) -> Glint {
    let width = camera.width as usize;
    let mut glint = Glint::default();
    let mut sum = Vec3::ZERO;
    // Summed in f64: a glint of a few bright pixels beside millions of
    // dim ones loses no digits.
    let mut illuminance = 0.0f64;
    for (i, &l) in reflected_cd_m2.iter().enumerate() {
        if !l.is_finite() || l <= 0.0 || l < threshold.luminance_cd_m2 {
            continue;
        }
        let (x, y) = ((i % width) as u32, (i / width) as u32);
        let e = l * camera.pixel_solid_angle(x, y);
        glint.pixels += 1;
        glint.peak_luminance_cd_m2 = glint.peak_luminance_cd_m2.max(l);
        illuminance += f64::from(e);
        sum += camera.pixel_ray(x, y) * e;
    }
    glint.eye_illuminance_lux = illuminance as f32;
    let Some(direction) = sum.try_normalize() else {
        return glint;
    };
    glint.direction = Some(direction.to_array());
    glint.instruments = (instruments.iter())
        .map(|instrument| {
            let [px, py] = instrument.pixel;
            let to = camera.ray_direction(px, py);
            let angle_deg = direction.dot(to).clamp(-1.0, 1.0).acos().to_degrees();
            InstrumentVeil {
                name: instrument.name.clone(),
                angle_deg,
                veiling_luminance_cd_m2: cie_veiling_luminance(
                    glint.eye_illuminance_lux,
                    angle_deg,
                ),
                within_validity: cie_valid(angle_deg),
            }
        })
        .collect();
    glint
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera(width: u32, height: u32, fov_y_deg: f32) -> Camera {
        Camera {
            eye: Vec3::ZERO,
            target: Vec3::NEG_Z,
            up: Vec3::Y,
            fov_y_deg,
            width,
            height,
        }
    }

    #[test]
    fn the_pixels_solid_angles_sum_to_the_images_solid_angle() {
        // A rectangular pyramid of half-angles a, b subtends
        // 4·asin(sin a · sin b).
        let c = camera(64, 48, 40.0);
        let tb = c.tan_half_fov();
        let ta = tb * 64.0 / 48.0;
        let closed = 4.0 * (ta.atan().sin() * tb.atan().sin()).asin();
        let sum: f64 = (0..48)
            .flat_map(|y| (0..64).map(move |x| (x, y)))
            .map(|(x, y)| f64::from(c.pixel_solid_angle(x, y)))
            .sum();
        assert!(
            (sum as f32 / closed - 1.0).abs() < 1e-3,
            "{sum} vs {closed}"
        );
    }

    /// A synthetic glint: a disc of the sun's angular diameter (0.53°) and
    /// luminance `l` at the image centre.
    fn sun_disc(c: &Camera, l: f32) -> Vec<f32> {
        let radius = (0.53f32 / 2.0).to_radians();
        (0..c.height)
            .flat_map(|y| (0..c.width).map(move |x| (x, y)))
            .map(|(x, y)| {
                let angle = c.pixel_ray(x, y).angle_between(Vec3::NEG_Z);
                if angle <= radius { l } else { 0.0 }
            })
            .collect()
    }

    #[test]
    fn a_synthetic_sun_glint_gives_its_closed_form_illuminance_and_veil() {
        // A 0.53° disc of L = 1.5e8 cd/m² (a Kr 0.1 mirror of a 100,000 lx
        // sun) gives E = L·Ω_disc = Kr·E_sun = 10,000 lx at the eye.
        let c = camera(1000, 1000, 4.0);
        let l = 1.5e8;
        let omega = std::f32::consts::PI * (0.53f32 / 2.0).to_radians().powi(2);
        let instruments = [
            Instrument {
                name: "dial 1.5°".into(),
                pixel: [
                    500.0 + 1.5f32.to_radians().tan() / c.pixel_size_at_unit_depth(),
                    500.0,
                ],
            },
            Instrument {
                name: "dial at the glint".into(),
                pixel: [500.0, 500.0],
            },
        ];
        let g = measure_glint(
            &sun_disc(&c, l),
            &c,
            &GlintThreshold::default(),
            &instruments,
        );
        assert!(g.reaches_eye());
        assert_eq!(g.peak_luminance_cd_m2, l);
        let closed = l * omega;
        assert!(
            (g.eye_illuminance_lux / closed - 1.0).abs() < 0.01,
            "{} vs {closed}",
            g.eye_illuminance_lux
        );
        let near = &g.instruments[0];
        assert!((near.angle_deg - 1.5).abs() < 0.01, "{}", near.angle_deg);
        assert!(near.within_validity);
        let lv = 10.0 * g.eye_illuminance_lux / (near.angle_deg * near.angle_deg);
        assert!((near.veiling_luminance_cd_m2 / lv - 1.0).abs() < 1e-5);
        // At the glint itself θ ≈ 0: outside the formula's range, flagged.
        assert!(!g.instruments[1].within_validity);
    }

    #[test]
    fn a_frame_below_the_threshold_has_no_glint() {
        let c = camera(50, 50, 30.0);
        let g = measure_glint(&vec![50_000.0; 2500], &c, &GlintThreshold::default(), &[]);
        assert_eq!(g, Glint::default());
        assert!(!g.reaches_eye());
    }

    #[test]
    fn the_veil_lowers_the_contrast_towards_one() {
        assert_eq!(contrast_with_veil(300.0, 100.0, 0.0), 3.0);
        assert!((contrast_with_veil(300.0, 100.0, 100.0) - 2.0).abs() < 1e-6);
        assert!(cie_valid(1.0) && cie_valid(30.0) && !cie_valid(0.5) && !cie_valid(31.0));
        assert_eq!(cie_veiling_luminance(1000.0, 10.0), 100.0);
    }
}
