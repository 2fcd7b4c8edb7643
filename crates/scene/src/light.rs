//! Lights (given by the job file, since OBJ has none) and global lighting terms.

use glam::Vec3;

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

impl Default for Lighting {
    fn default() -> Self {
        Lighting {
            lights: Vec::new(),
            ambient: Vec3::splat(0.1),
            background: Vec3::ZERO,
        }
    }
}
