//! The built-in truck cockpit: a procedural scene generated in code (no file
//! needed) with a concave curved instrument cover glass, the paper's test case.

use glam::Vec3;
use vtfarm_scene::{Camera, Lighting, Scene};

/// Settings of the generator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CockpitConfig {
    /// Scales the tessellation of every part: 1.0 gives about 100,000
    /// triangles, [`CockpitConfig::LARGE_DETAIL`] about 210,000.
    pub detail: f32,
    /// Subdivisions of the cover glass along each of its two directions
    /// (its tessellation is set separately since it is the reflector).
    pub glass_segments: u32,
}

impl CockpitConfig {
    pub const DEFAULT_DETAIL: f32 = 1.0;
    pub const LARGE_DETAIL: f32 = 2.1;
}

impl Default for CockpitConfig {
    fn default() -> Self {
        CockpitConfig { detail: Self::DEFAULT_DETAIL, glass_segments: 24 }
    }
}

/// The generated scene plus its suggested view and lights.
#[derive(Clone, Debug)]
pub struct Cockpit {
    pub scene: Scene,
    /// The default driver eye point looking at the instrument cluster.
    pub camera: Camera,
    /// Suggested lights (a sun through the side window, a cabin lamp).
    pub lighting: Lighting,
}

/// Name of the cover-glass object facing the driver (the default reflector).
pub const COVER_GLASS: &str = "cover_glass";
/// Name of the cover glass's back surface (seen only through the glass).
pub const COVER_GLASS_BACK: &str = "cover_glass_back";
/// Material name of the cover glass.
pub const GLASS_MATERIAL: &str = "glass";

/// A point on the cockpit's default eye position, re-exported for tests.
pub fn default_eye() -> Vec3 {
    todo!("cockpit generator")
}

/// Generates the cockpit.
pub fn cockpit(config: &CockpitConfig) -> Cockpit {
    let _ = config;
    todo!("cockpit generator")
}
