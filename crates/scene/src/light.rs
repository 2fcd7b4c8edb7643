//! Lights (given by the job file, since OBJ has none) and global lighting terms.

use glam::Vec3;

use crate::bounds::{self, OutOfBounds};

/// Where a light is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    /// A point light at a position; no distance falloff (classic Whitted).
    Point { position: Vec3 },
    /// A directional light; `direction` points from the light into the scene.
    Directional { direction: Vec3 },
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
    /// direction (shading normalizes it); colour and intensity finite and not
    /// negative.
    pub fn validate(&self) -> Result<(), OutOfBounds> {
        match self.kind {
            LightKind::Point { position } => {
                bounds::point("position", position)?;
            }
            LightKind::Directional { direction } => {
                if !(direction.is_finite() && direction != Vec3::ZERO) {
                    return Err(OutOfBounds::new(
                        "direction",
                        direction,
                        "finite and not zero",
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
            LightKind::Directional { direction } => (-direction.normalize(), f32::INFINITY),
        }
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
                kind: LightKind::Directional {
                    direction: DAYLIGHT_SUN_DIRECTION.normalize(),
                },
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
