//! The built-in truck cockpit: a procedural scene generated in code (no file
//! needed) with a concave curved instrument cover glass, the paper's test case.
//!
//! Layout (metres, +Y up, the driver looks along -Z, cab floor at y = 0): a
//! left-hand-drive cab 2.3 m wide with the driver at x = -0.55. The driver's
//! eye looks down at the instrument cluster over the steering wheel; the
//! cover glass in front of the dials is an ellipsoid patch, concave towards
//! the driver and turned a little to the driver's left, so its lower part
//! mirrors the bright left door window (as in the paper's figures). The
//! windows are openings with emissive panels outside them.
//!
//! Generation is plain arithmetic in a fixed order, so equal configurations
//! give bit-identical scenes.

mod builder;
mod cab;
mod cluster;
mod interior;
mod layout;
mod mesh;

use glam::Vec3;
use vtfarm_scene::{Camera, Light, LightKind, Lighting, Scene, photometry};

/// Settings of the generator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CockpitConfig {
    /// Scales the tessellation of every part: 1.0 gives about 100,000
    /// triangles, [`CockpitConfig::LARGE_DETAIL`] about 210,000.
    pub detail: f32,
    /// Subdivisions of the cover glass across it, half as many up it (its
    /// tessellation is set separately since it is the reflector).
    pub glass_segments: u32,
    /// The cover glass's shape; the default is today's curved glass.
    pub glass: GlassDesign,
}

/// Shapes of the cover glass for glare studies. All have the same outline
/// (0.46 m by 0.21 m, measured in the glass's tangent plane at its centre),
/// the same centre point and the same tessellation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum GlassDesign {
    /// The ellipsoid patch turned 18° to the driver's left and 10° down,
    /// concave towards the driver (mirrors the left door window).
    #[default]
    Current,
    /// A plane facing the nominal eye.
    Flat,
    /// [`GlassDesign::Flat`] rotated about its horizontal axis by `degrees`
    /// (positive: the top edge away from the driver; clamped to ±60°).
    FlatTilted { degrees: f32 },
    /// A cylinder section facing the eye, axis horizontal, concave towards
    /// the driver; `radius` is clamped to at least 0.15 m (at most 1000 m).
    Cylindrical { radius: f32 },
    /// An ellipsoid (of revolution) section with one focus at the eye and
    /// the other at a small black absorber above the glass (object
    /// [`GLARE_ABSORBER`]), so the eye sees almost only the absorber in it.
    Ellipsoidal,
}

impl GlassDesign {
    /// A short name for file names and tables, e.g. "flat-tilted-15".
    pub fn name(&self) -> String {
        match *self {
            GlassDesign::Current => "current".to_owned(),
            GlassDesign::Flat => "flat".to_owned(),
            GlassDesign::FlatTilted { degrees } => format!("flat-tilted-{degrees}"),
            GlassDesign::Cylindrical { radius } => format!("cylindrical-r{radius}"),
            GlassDesign::Ellipsoidal => "ellipsoidal".to_owned(),
        }
    }
}

impl CockpitConfig {
    pub const DEFAULT_DETAIL: f32 = 1.0;
    pub const LARGE_DETAIL: f32 = 2.1;
    /// The accepted `detail` range: 0.01 (about 1,000 triangles) to 10
    /// (about a million triangles, some 300 MB with the BVH).
    pub const DETAIL_RANGE: std::ops::RangeInclusive<f32> = 0.01..=10.0;
    /// The most glass segments: the glass has about segments² triangles, so
    /// 1024 gives a million reflector triangles.
    pub const MAX_GLASS_SEGMENTS: u32 = 1024;

    /// Checks `detail` and `glass_segments` against their bounds (the
    /// generator would otherwise clamp, or run out of memory).
    pub fn validate(&self) -> Result<(), vtfarm_scene::OutOfBounds> {
        use vtfarm_scene::bounds::check;
        let (lo, hi) = Self::DETAIL_RANGE.into_inner();
        check("detail", self.detail, format!("{lo} to {hi}"), |d| {
            Self::DETAIL_RANGE.contains(&d)
        })?;
        check(
            "glass_segments",
            self.glass_segments,
            format!("1 to {}", Self::MAX_GLASS_SEGMENTS),
            |n| (1..=Self::MAX_GLASS_SEGMENTS).contains(&n),
        )?;
        Ok(())
    }
}

impl Default for CockpitConfig {
    fn default() -> Self {
        CockpitConfig {
            detail: Self::DEFAULT_DETAIL,
            glass_segments: 24,
            glass: GlassDesign::Current,
        }
    }
}

/// The generated scene plus its suggested view and lights.
#[derive(Clone, Debug)]
pub struct Cockpit {
    pub scene: Scene,
    /// The default driver eye point looking at the instrument cluster.
    pub camera: Camera,
    /// Suggested lighting (a sun through the side window and the cab's
    /// diffuse daylight), in physical units.
    pub lighting: Lighting,
}

impl Cockpit {
    /// The triangles of the cover glass's front surface ([`COVER_GLASS`]):
    /// the default reflectors.
    pub fn cover_glass_triangles(&self) -> Vec<vtfarm_scene::TriangleId> {
        let glass = self
            .scene
            .object_id(COVER_GLASS)
            .expect("the generator always makes the cover glass");
        self.scene.triangles_of(glass).collect()
    }
}

/// Name of the cover-glass object facing the driver (the default reflector).
pub const COVER_GLASS: &str = "cover_glass";
/// Name of the cover glass's back surface (seen only through the glass).
pub const COVER_GLASS_BACK: &str = "cover_glass_back";
/// Name of the black absorber at the ellipsoidal glass's inner focus (only
/// in scenes with [`GlassDesign::Ellipsoidal`]).
pub const GLARE_ABSORBER: &str = "glare_absorber";
/// Material name of the cover glass.
pub const GLASS_MATERIAL: &str = "glass";

/// A point on the cockpit's default eye position, re-exported for tests.
pub fn default_eye() -> Vec3 {
    layout::EYE
}

/// The ellipsoidal glass's inner focus, the centre of [`GLARE_ABSORBER`]
/// (the outer focus is [`default_eye`]).
pub fn glare_absorber_focus() -> Vec3 {
    layout::ABSORBER
}

/// Generates the cockpit.
pub fn cockpit(config: &CockpitConfig) -> Cockpit {
    let detail = Detail::new(config.detail);
    let mut builder = builder::SceneBuilder::default();
    cab::build(&mut builder, detail);
    interior::build(&mut builder, detail);
    cluster::build(&mut builder, detail, config.glass_segments, config.glass);
    Cockpit {
        scene: builder.finish(),
        camera: camera(),
        lighting: lighting(),
    }
}

/// The driver's view of the cover glass.
fn camera() -> Camera {
    Camera {
        eye: default_eye(),
        target: layout::GLASS_CENTER,
        up: Vec3::Y,
        fov_y_deg: 50.0,
        width: 640,
        height: 360,
    }
}

/// Direction the sunlight travels: from high up on the driver's left,
/// slightly behind, in through the left door window. It is steep enough to
/// pass over the window's emissive panel (shadow rays treat every surface as
/// opaque) and comes from behind so none enters through the windshield.
const SUN_DIRECTION: Vec3 = Vec3::new(0.45, -0.85, -0.15);

/// Illuminance of the sun on a surface facing it: a clear summer noon.
pub const SUN_ILLUMINANCE_LUX: f32 = 100_000.0;
/// Diffuse daylight inside the cab (sky light through the windows, from
/// every side): the ambient term.
pub const CAB_AMBIENT_LUX: f32 = 2_500.0;
/// Luminance of rays that leave the scene (sky seen past the panels).
pub const BACKGROUND_CD_M2: f32 = 3_500.0;
/// The sky panel seen through the windshield: a bright sky near the horizon.
pub const SKY_CD_M2: f32 = 10_000.0;
/// The sunlit view through the left door window (sunlit clouds and white
/// surfaces reach 20,000 to 30,000 cd/m²): the stock glass's glare source.
pub const SUNLIT_WINDOW_CD_M2: f32 = 25_000.0;
/// The view through the right door window, on the shaded side.
pub const SHADED_WINDOW_CD_M2: f32 = 10_000.0;
/// Road and fields below the horizon: ground of reflectance 0.1 under the sun.
pub const GROUND_CD_M2: f32 = 3_000.0;
/// Backlit instrument markings in day mode.
pub const MARKING_CD_M2: f32 = 500.0;
/// Backlight of the black dial faces (their print also reflects the cab's
/// light).
pub const DIAL_FACE_CD_M2: f32 = 10.0;
/// Backlit red needles.
pub const NEEDLE_CD_M2: f32 = 300.0;
/// Lit warning lamps (tell-tales) in day mode.
pub const WARNING_LAMP_CD_M2: f32 = 1_500.0;

/// The sun through the left door window and the cab's diffuse daylight, in
/// the units of [`vtfarm_scene::photometry`].
fn lighting() -> Lighting {
    let color = Vec3::new(1.0, 0.95, 0.85);
    let sun = Light {
        kind: LightKind::sun(SUN_DIRECTION.normalize()),
        color,
        intensity: photometry::directional_intensity(color, SUN_ILLUMINANCE_LUX)
            .expect("the sun's colour has luminance"),
    };
    Lighting {
        lights: vec![sun],
        ambient: photometry::ambient(CAB_AMBIENT_LUX),
        background: photometry::emission(Vec3::new(0.3, 0.35, 0.45), BACKGROUND_CD_M2)
            .expect("the sky's colour has luminance"),
    }
}

/// How finely the parts (all but the glass) are tessellated: segment counts
/// per direction scale with the square root of the detail, so triangle
/// counts grow about linearly with it.
#[derive(Clone, Copy, Debug)]
struct Detail {
    scale: f32,
}

impl Detail {
    fn new(detail: f32) -> Self {
        let detail = if detail.is_finite() {
            detail.clamp(0.01, 100.0)
        } else {
            CockpitConfig::DEFAULT_DETAIL
        };
        Detail {
            scale: detail.sqrt(),
        }
    }

    /// The segment count for a direction with `base` segments at detail 1,
    /// never below `min`.
    fn segments(self, base: u32, min: u32) -> u32 {
        ((base as f32 * self.scale).round() as u32).max(min)
    }

    /// The cell size for a surface with cells of `base` metres at detail 1.
    fn cell(self, base: f32) -> f32 {
        base / self.scale
    }
}
