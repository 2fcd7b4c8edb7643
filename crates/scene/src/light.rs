//! Lights (given by the job file, since OBJ has none) and global lighting terms.

use glam::Vec3;

use crate::bounds::{self, OutOfBounds};

/// Where a light is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    /// A point light at a position; no distance falloff (classic Whitted).
    Point { position: Vec3 },
    /// A directional light; `direction` points from the light into the scene.
    /// `angular_diameter_deg` > 0 gives it a disc that rays leaving the
    /// scene see ([`Light::disc`]); 0 is a point at infinity (lights
    /// surfaces only).
    Directional {
        direction: Vec3,
        angular_diameter_deg: f32,
    },
}

impl LightKind {
    /// A directional light with the sun's disc ([`SUN_ANGULAR_DIAMETER_DEG`]).
    pub fn sun(direction: Vec3) -> LightKind {
        LightKind::Directional {
            direction,
            angular_diameter_deg: SUN_ANGULAR_DIAMETER_DEG,
        }
    }
}

/// The sun's angular diameter seen from the earth (0.53°, its mean), the
/// default disc of a directional light given in lux.
pub const SUN_ANGULAR_DIAMETER_DEG: f32 = 0.53;

/// The largest disc a directional light may have: its footprint model
/// ([`SunDisc::coverage`]) treats the disc as small.
pub const MAX_ANGULAR_DIAMETER_DEG: f32 = 10.0;

/// The disc of a directional light as rays leaving the scene see it: a
/// uniform disc (no limb darkening) of angular radius `radius` around
/// `toward`, whose radiance times its solid angle is the illuminance the
/// light gives a surface facing it. In the units of [`crate::photometry`]:
/// a light of `E` lux has the disc luminance `E / Ω` cd/m², Ω = 2π(1 − cos r).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SunDisc {
    /// Unit direction from the scene toward the disc's centre.
    pub toward: Vec3,
    /// Angular radius in radians.
    pub radius: f32,
    /// Radiance of the disc (render units).
    pub radiance: Vec3,
}

impl SunDisc {
    /// The disc's solid angle in steradians.
    pub fn solid_angle(&self) -> f32 {
        solid_angle_of_cone(self.radius)
    }

    /// The share of a ray's footprint that the disc covers: the ray along
    /// unit `direction` stands for a disc of directions of angular radius
    /// `footprint` (a pixel's cone; 0 for a ray that is a single
    /// direction). Both discs are small, so their overlap is that of two
    /// discs in the plane. A pixel whose footprint is a disc of its own
    /// area then carries its share of the disc's light, and the sum of
    /// radiance × solid angle over the pixels is the disc's whole
    /// illuminance at any resolution.
    pub fn coverage(&self, direction: Vec3, footprint: f32) -> f32 {
        let cos = direction.dot(self.toward).clamp(-1.0, 1.0);
        if cos <= 0.0 {
            return 0.0;
        }
        let distance = cos.acos();
        if footprint <= 0.0 {
            return if distance <= self.radius { 1.0 } else { 0.0 };
        }
        disc_overlap(distance, self.radius, footprint)
            / (std::f32::consts::PI * footprint * footprint)
    }
}

/// The solid angle of a cone of half-angle `radius` radians.
pub fn solid_angle_of_cone(radius: f32) -> f32 {
    // 2π(1 − cos r) written without cancellation for small r.
    let s = (0.5 * radius).sin();
    4.0 * std::f32::consts::PI * s * s
}

/// The area common to two discs of radii `a` and `b` whose centres are `d`
/// apart, in the plane.
fn disc_overlap(d: f32, a: f32, b: f32) -> f32 {
    use std::f32::consts::PI;
    if d >= a + b {
        return 0.0;
    }
    let (small, large) = if a < b { (a, b) } else { (b, a) };
    if d <= large - small {
        return PI * small * small;
    }
    let (d, a, b) = (d as f64, a as f64, b as f64);
    let alpha = ((d * d + a * a - b * b) / (2.0 * d * a))
        .clamp(-1.0, 1.0)
        .acos();
    let beta = ((d * d + b * b - a * a) / (2.0 * d * b))
        .clamp(-1.0, 1.0)
        .acos();
    let kite = 0.5
        * ((-d + a + b) * (d + a - b) * (d - a + b) * (d + a + b))
            .max(0.0)
            .sqrt();
    (a * a * alpha + b * b * beta - kite) as f32
}

/// One light: its kind, linear RGB colour and scalar intensity.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Light {
    pub kind: LightKind,
    pub color: Vec3,
    pub intensity: f32,
}

impl Light {
    /// A position within [`bounds::MAX_COORDINATE`] or a finite, non-zero
    /// direction (shading normalizes it) with a disc of 0 to
    /// [`MAX_ANGULAR_DIAMETER_DEG`] degrees; colour and intensity finite and not
    /// negative.
    pub fn validate(&self) -> Result<(), OutOfBounds> {
        match self.kind {
            LightKind::Point { position } => {
                bounds::point("position", position)?;
            }
            LightKind::Directional {
                direction,
                angular_diameter_deg,
            } => {
                if !(direction.is_finite() && direction != Vec3::ZERO) {
                    return Err(OutOfBounds::new(
                        "direction",
                        direction,
                        "finite and not zero",
                    ));
                }
                if !((0.0..=MAX_ANGULAR_DIAMETER_DEG).contains(&angular_diameter_deg)) {
                    return Err(OutOfBounds::new(
                        "angular_diameter_deg",
                        angular_diameter_deg,
                        format!("between 0 and {MAX_ANGULAR_DIAMETER_DEG} degrees"),
                    ));
                }
            }
        }
        bounds::non_negative3("color", self.color)?;
        bounds::non_negative("intensity", self.intensity)?;
        Ok(())
    }

    /// The radiance scale of this light (colour times intensity).
    pub fn radiance(&self) -> Vec3 {
        self.color * self.intensity
    }

    /// Unit direction from `point` towards the light and the distance to it
    /// (infinite for directional lights).
    pub fn direction_from(&self, point: Vec3) -> (Vec3, f32) {
        match self.kind {
            LightKind::Point { position } => {
                let d = position - point;
                let len = d.length();
                (d / len.max(f32::MIN_POSITIVE), len)
            }
            LightKind::Directional { direction, .. } => (-direction.normalize(), f32::INFINITY),
        }
    }

    /// The disc a ray leaving the scene sees, for a directional light with
    /// an angular diameter: its radiance is the light's radiance times
    /// π/Ω, so that the disc gives a surface facing it the illuminance the
    /// light gives (local shading's `Kd · cos θ · radiance` is the
    /// Lambertian `ρ · E · cos θ / π`). `None` for point lights and discs of
    /// no size.
    pub fn disc(&self) -> Option<SunDisc> {
        let LightKind::Directional {
            direction,
            angular_diameter_deg,
        } = self.kind
        else {
            return None;
        };
        if angular_diameter_deg <= 0.0 {
            return None;
        }
        let radius = 0.5 * angular_diameter_deg.to_radians();
        let omega = solid_angle_of_cone(radius);
        Some(SunDisc {
            toward: -direction.normalize(),
            radius,
            radiance: self.radiance() * (std::f32::consts::PI / omega),
        })
    }
}

/// Everything about light that is not geometry: the lights, the ambient term
/// and the colour seen by rays that leave the scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Lighting {
    pub lights: Vec<Light>,
    /// Ambient light colour, multiplied by each material's Ka.
    pub ambient: Vec3,
    /// Radiance of rays that hit nothing.
    pub background: Vec3,
}

impl Lighting {
    /// The most lights a frame may have: each costs a shadow ray per shaded
    /// point and, behind thin glass, a 2048² shadow map (48 MB).
    pub const MAX_LIGHTS: usize = 64;

    /// At most [`Lighting::MAX_LIGHTS`] lights.
    pub fn validate_count(count: usize) -> Result<(), OutOfBounds> {
        if count > Self::MAX_LIGHTS {
            return Err(OutOfBounds::new(
                "lights",
                count,
                format!("at most {} lights", Self::MAX_LIGHTS),
            ));
        }
        Ok(())
    }

    /// At most [`Lighting::MAX_LIGHTS`] lights, every light valid (the error
    /// names the light's index), ambient and background finite and not
    /// negative.
    pub fn validate(&self) -> Result<(), (Option<usize>, OutOfBounds)> {
        Self::validate_count(self.lights.len()).map_err(|e| (None, e))?;
        for (i, light) in self.lights.iter().enumerate() {
            light.validate().map_err(|e| (Some(i), e))?;
        }
        bounds::non_negative3("ambient", self.ambient).map_err(|e| (None, e))?;
        bounds::non_negative3("background", self.background).map_err(|e| (None, e))?;
        Ok(())
    }
}

/// Luminance of the default sky ([`Lighting::daylight`]): a hazy day's
/// sky away from the sun.
pub const DAYLIGHT_SKY_CD_M2: f32 = 2_000.0;
/// Illuminance of the default sun on a surface facing it: a hazy sun.
pub const DAYLIGHT_SUN_LUX: f32 = 30_000.0;
/// Direction the default sunlight travels: for a viewer looking along −Z
/// with +Y up, it comes from behind their left shoulder, 53° above the
/// horizon, so what faces the viewer is lit.
pub const DAYLIGHT_SUN_DIRECTION: Vec3 = Vec3::new(0.4, -0.8, -0.45);

impl Lighting {
    /// The light of a scene that has none: a white sun of
    /// [`DAYLIGHT_SUN_LUX`] along [`DAYLIGHT_SUN_DIRECTION`], and a uniform
    /// sky of [`DAYLIGHT_SKY_CD_M2`] as the background and as ambient light
    /// (a uniform sky of luminance L gives the illuminance π·L), in the
    /// units of [`crate::photometry`].
    pub fn daylight() -> Lighting {
        let color = Vec3::ONE;
        Lighting {
            lights: vec![Light {
                kind: LightKind::sun(DAYLIGHT_SUN_DIRECTION.normalize()),
                color,
                intensity: crate::photometry::directional_intensity(color, DAYLIGHT_SUN_LUX)
                    .expect("white has luminance"),
            }],
            ambient: crate::photometry::ambient(std::f32::consts::PI * DAYLIGHT_SKY_CD_M2),
            background: crate::photometry::grey(DAYLIGHT_SKY_CD_M2),
        }
    }
}

impl Default for Lighting {
    fn default() -> Self {
        Lighting {
            lights: Vec::new(),
            ambient: Vec3::splat(0.1),
            background: Vec3::ZERO,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photometry;

    fn sun(lux: f32, diameter_deg: f32) -> Light {
        Light {
            kind: LightKind::Directional {
                direction: Vec3::new(0.0, -1.0, -1.0),
                angular_diameter_deg: diameter_deg,
            },
            color: Vec3::ONE,
            intensity: photometry::directional_intensity(Vec3::ONE, lux).unwrap(),
        }
    }

    #[test]
    fn the_suns_disc_has_the_luminance_e_over_omega() {
        let disc = sun(100_000.0, 0.53).disc().unwrap();
        let omega = disc.solid_angle();
        let expected = 100_000.0 / omega;
        let l = photometry::cd_m2(disc.radiance);
        assert!((l / expected - 1.0).abs() < 1e-4, "{l} vs {expected}");
        assert!((l / 1.5e9 - 1.0).abs() < 0.02, "about 1.5·10⁹ cd/m²: {l}");
        assert_eq!(sun(100_000.0, 0.0).disc(), None);
    }

    #[test]
    fn pixel_footprints_on_a_grid_share_the_disc_without_loss() {
        let disc = sun(1.0, 0.53).disc().unwrap();
        let (right, up) = disc.toward.any_orthonormal_pair();
        for pixel_deg in [0.03f32, 0.1, 0.25, 0.6] {
            let s = pixel_deg.to_radians();
            let footprint = s / std::f32::consts::PI.sqrt();
            let mut sum = 0.0f64;
            for i in -60..60 {
                for j in -60..60 {
                    let (a, b) = ((i as f32 + 0.31) * s, (j as f32 + 0.17) * s);
                    let d = (disc.toward + right * a + up * b).normalize();
                    sum += f64::from(disc.coverage(d, footprint)) * f64::from(s * s);
                }
            }
            let omega = f64::from(disc.solid_angle());
            assert!(
                (sum / omega - 1.0).abs() < 0.02,
                "{pixel_deg}°: {sum} vs {omega}"
            );
        }
    }

    #[test]
    fn a_disc_wider_than_the_bound_or_negative_is_refused() {
        assert!(sun(1.0, -0.1).validate().is_err());
        assert!(sun(1.0, f32::NAN).validate().is_err());
        assert!(sun(1.0, MAX_ANGULAR_DIAMETER_DEG + 1.0).validate().is_err());
        assert!(sun(1.0, 0.53).validate().is_ok());
    }
}
