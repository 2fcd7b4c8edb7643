//! Adaptive progressive vertex tracing (Ullmann et al., section 3): traces
//! reflector vertices instead of pixels, refines edges where colours or ray
//! trees differ, and fills the last small triangles per pixel.
//!
//! Architecture invariant: the result for a reflector triangle depends only on
//! that triangle, the scene and the frame set-up, never on which other
//! triangles share its package. The farm splits work on this.

/// How far the vertex tracer goes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Quality {
    /// Trace the mesh vertices only, Gouraud-interpolate between them.
    Preview,
    /// Adaptive edge refinement without triangle filling.
    Refine,
    /// Refinement plus per-pixel triangle filling.
    Full,
    /// Every reflector pixel ray traced: the ground truth.
    Reference,
}

impl Quality {
    pub const ALL: [Quality; 4] = [Quality::Preview, Quality::Refine, Quality::Full, Quality::Reference];

    pub fn name(self) -> &'static str {
        match self {
            Quality::Preview => "preview",
            Quality::Refine => "refine",
            Quality::Full => "full",
            Quality::Reference => "reference",
        }
    }

    pub fn from_name(name: &str) -> Option<Quality> {
        Quality::ALL.into_iter().find(|q| q.name() == name)
    }
}

/// The vertex tracer's thresholds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VertexSettings {
    pub quality: Quality,
    /// Colour difference (per channel, in 8-bit sRGB units / 255) above which an
    /// edge is refined.
    pub epsilon: f32,
    /// Edges shorter than this on screen (pixels) are not refined: the paper's
    /// 2-pixel floor.
    pub pixel_floor: f32,
    /// The flatness factor v: a face with h / c < v has its long edge c split.
    pub flatness: f32,
    /// Maximum refinement depth (splits along one lineage).
    pub max_depth: u32,
    /// Half-size of the ID-buffer neighbourhood checked for vertex visibility.
    pub visibility_radius: u32,
    /// Relative depth tolerance of the visibility test.
    pub depth_tolerance: f32,
}

impl Default for VertexSettings {
    fn default() -> Self {
        VertexSettings {
            quality: Quality::Full,
            epsilon: 2.0 / 255.0,
            pixel_floor: 2.0,
            flatness: 0.2,
            max_depth: 16,
            visibility_radius: 1,
            depth_tolerance: 0.01,
        }
    }
}
