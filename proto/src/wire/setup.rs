//! A frame's settings on the wire ([`WireFrameSetup`]: camera, lighting,
//! trace and vertex settings, method) and a package's counters
//! ([`WirePackageStats`]).

use std::time::Duration;

use serde::{Deserialize, Serialize};
use vtfarm_method::{FrameSetup, MethodKind};
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{PackageStats, Quality, Transmission, VertexSettings};

use super::{WireCamera, WireError, WireLighting, bounds};

/// [`TraceSettings`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireTraceSettings {
    pub max_depth: u32,
    pub fresnel: bool,
    pub signature_min_weight: f32,
}

impl From<&TraceSettings> for WireTraceSettings {
    fn from(t: &TraceSettings) -> Self {
        WireTraceSettings {
            max_depth: t.max_depth,
            fresnel: t.fresnel,
            signature_min_weight: t.signature_min_weight,
        }
    }
}

impl TryFrom<WireTraceSettings> for TraceSettings {
    type Error = WireError;

    fn try_from(w: WireTraceSettings) -> Result<Self, WireError> {
        let trace = TraceSettings {
            max_depth: w.max_depth,
            fresnel: w.fresnel,
            signature_min_weight: w.signature_min_weight,
        };
        trace.validate().map_err(bounds("trace"))?;
        Ok(trace)
    }
}

/// [`Quality`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireQuality {
    Preview,
    Refine,
    Full,
    Reference,
}

impl From<Quality> for WireQuality {
    fn from(q: Quality) -> Self {
        match q {
            Quality::Preview => WireQuality::Preview,
            Quality::Refine => WireQuality::Refine,
            Quality::Full => WireQuality::Full,
            Quality::Reference => WireQuality::Reference,
        }
    }
}

impl From<WireQuality> for Quality {
    fn from(q: WireQuality) -> Self {
        match q {
            WireQuality::Preview => Quality::Preview,
            WireQuality::Refine => Quality::Refine,
            WireQuality::Full => Quality::Full,
            WireQuality::Reference => Quality::Reference,
        }
    }
}

/// [`Transmission`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireTransmission {
    Raster,
    Traced,
}

impl From<Transmission> for WireTransmission {
    fn from(t: Transmission) -> Self {
        match t {
            Transmission::Raster => WireTransmission::Raster,
            Transmission::Traced => WireTransmission::Traced,
        }
    }
}

impl From<WireTransmission> for Transmission {
    fn from(t: WireTransmission) -> Self {
        match t {
            WireTransmission::Raster => Transmission::Raster,
            WireTransmission::Traced => Transmission::Traced,
        }
    }
}

/// [`MethodKind`] on the wire.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum WireMethod {
    #[default]
    VertexTracing,
    CubeMap,
    CubeMapGrid,
    Pvrr,
    EnvironmentMap,
}

impl From<MethodKind> for WireMethod {
    fn from(m: MethodKind) -> Self {
        match m {
            MethodKind::VertexTracing => WireMethod::VertexTracing,
            MethodKind::CubeMap => WireMethod::CubeMap,
            MethodKind::CubeMapGrid => WireMethod::CubeMapGrid,
            MethodKind::Pvrr => WireMethod::Pvrr,
            MethodKind::EnvironmentMap => WireMethod::EnvironmentMap,
        }
    }
}

impl From<WireMethod> for MethodKind {
    fn from(m: WireMethod) -> Self {
        match m {
            WireMethod::VertexTracing => MethodKind::VertexTracing,
            WireMethod::CubeMap => MethodKind::CubeMap,
            WireMethod::CubeMapGrid => MethodKind::CubeMapGrid,
            WireMethod::Pvrr => MethodKind::Pvrr,
            WireMethod::EnvironmentMap => MethodKind::EnvironmentMap,
        }
    }
}

/// [`VertexSettings`] on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireVertexSettings {
    pub quality: WireQuality,
    pub epsilon: f32,
    pub pixel_floor: f32,
    pub flatness: f32,
    pub max_depth: u32,
    pub visibility_radius: u32,
    pub depth_tolerance: f32,
    pub max_edge: f32,
    pub transmission: WireTransmission,
    pub capture_cd_m2: f32,
}

impl From<&VertexSettings> for WireVertexSettings {
    fn from(v: &VertexSettings) -> Self {
        WireVertexSettings {
            quality: v.quality.into(),
            epsilon: v.epsilon,
            pixel_floor: v.pixel_floor,
            flatness: v.flatness,
            max_depth: v.max_depth,
            visibility_radius: v.visibility_radius,
            depth_tolerance: v.depth_tolerance,
            max_edge: v.max_edge,
            transmission: v.transmission.into(),
            capture_cd_m2: v.capture_cd_m2,
        }
    }
}

impl TryFrom<WireVertexSettings> for VertexSettings {
    type Error = WireError;

    fn try_from(w: WireVertexSettings) -> Result<Self, WireError> {
        let vertex = VertexSettings {
            quality: w.quality.into(),
            epsilon: w.epsilon,
            pixel_floor: w.pixel_floor,
            flatness: w.flatness,
            max_depth: w.max_depth,
            visibility_radius: w.visibility_radius,
            depth_tolerance: w.depth_tolerance,
            max_edge: w.max_edge,
            transmission: w.transmission.into(),
            capture_cd_m2: w.capture_cd_m2,
        };
        vertex.validate().map_err(bounds("vertex"))?;
        Ok(vertex)
    }
}

/// [`FrameSetup`] on the wire: everything that can change from one frame to
/// the next.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct WireFrameSetup {
    pub camera: WireCamera,
    pub lighting: WireLighting,
    pub trace: WireTraceSettings,
    pub vertex: WireVertexSettings,
}

impl From<&FrameSetup> for WireFrameSetup {
    fn from(f: &FrameSetup) -> Self {
        WireFrameSetup {
            camera: (&f.camera).into(),
            lighting: (&f.lighting).into(),
            trace: (&f.trace).into(),
            vertex: (&f.vertex).into(),
        }
    }
}

impl TryFrom<WireFrameSetup> for FrameSetup {
    type Error = WireError;

    fn try_from(w: WireFrameSetup) -> Result<Self, WireError> {
        Ok(FrameSetup {
            camera: w.camera.try_into()?,
            lighting: w.lighting.try_into()?,
            trace: w.trace.try_into()?,
            vertex: w.vertex.try_into()?,
        })
    }
}

/// [`PackageStats`] on the wire. Durations keep their full precision.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct WirePackageStats {
    pub triangles: u64,
    pub traced_triangles: u64,
    pub visible_vertices: u64,
    pub vertex_samples: u64,
    pub filled_pixels: u64,
    pub refined_edges: u64,
    pub faces: u64,
    pub pixels: u64,
    pub vertex_time: Duration,
    pub fill_time: Duration,
}

impl From<&PackageStats> for WirePackageStats {
    fn from(s: &PackageStats) -> Self {
        WirePackageStats {
            triangles: s.triangles,
            traced_triangles: s.traced_triangles,
            visible_vertices: s.visible_vertices,
            vertex_samples: s.vertex_samples,
            filled_pixels: s.filled_pixels,
            refined_edges: s.refined_edges,
            faces: s.faces,
            pixels: s.pixels,
            vertex_time: s.vertex_time,
            fill_time: s.fill_time,
        }
    }
}

// Counters cannot be invalid, and serde already rejects malformed durations.
impl From<WirePackageStats> for PackageStats {
    fn from(s: WirePackageStats) -> Self {
        PackageStats {
            triangles: s.triangles,
            traced_triangles: s.traced_triangles,
            visible_vertices: s.visible_vertices,
            vertex_samples: s.vertex_samples,
            filled_pixels: s.filled_pixels,
            refined_edges: s.refined_edges,
            faces: s.faces,
            pixels: s.pixels,
            vertex_time: s.vertex_time,
            fill_time: s.fill_time,
        }
    }
}

#[cfg(test)]
mod tests {
    use std::time::Duration;

    use vtfarm_method::{FrameSetup, MethodKind};
    use vtfarm_trace::TraceSettings;
    use vtfarm_vertex::{PackageStats, Quality, VertexSettings};

    use super::*;
    use crate::wire::tests::{camera, check_rejects, lighting, round_trip};

    #[test]
    fn settings_round_trip() {
        let trace = TraceSettings {
            max_depth: 7,
            fresnel: true,
            signature_min_weight: 0.125,
        };
        assert_eq!(
            round_trip::<TraceSettings, WireTraceSettings>(&trace),
            trace
        );
        for method in MethodKind::ALL {
            assert_eq!(MethodKind::from(WireMethod::from(method)), method);
        }
        for quality in Quality::ALL {
            assert_eq!(Quality::from(WireQuality::from(quality)), quality);
            let vertex = VertexSettings {
                quality,
                max_depth: 9,
                visibility_radius: 2,
                ..VertexSettings::default()
            };
            assert_eq!(
                round_trip::<VertexSettings, WireVertexSettings>(&vertex),
                vertex
            );
        }
        let setup = FrameSetup {
            camera: camera(),
            lighting: lighting(),
            trace,
            vertex: VertexSettings::default(),
        };
        assert_eq!(round_trip::<FrameSetup, WireFrameSetup>(&setup), setup);
    }

    #[test]
    fn hostile_settings_are_rejected() {
        let trace = WireTraceSettings::from(&TraceSettings::default());
        check_rejects::<_, TraceSettings>(&trace, |t| t.max_depth = 0, "trace max_depth = 0");
        check_rejects::<_, TraceSettings>(&trace, |t| t.max_depth = 65, "trace max_depth = 65");
        let vertex = WireVertexSettings::from(&VertexSettings::default());
        check_rejects::<_, VertexSettings>(&vertex, |v| v.epsilon = -1.0, "vertex epsilon = -1");
        check_rejects::<_, VertexSettings>(
            &vertex,
            |v| v.visibility_radius = 1000,
            "vertex visibility_radius = 1000",
        );
        // Values that would run away: the same `validate` as the job parser.
        check_rejects::<_, VertexSettings>(
            &vertex,
            |v| v.max_depth = u32::MAX,
            "vertex max_depth = 4294967295: must be 0 to 32",
        );
        check_rejects::<_, VertexSettings>(
            &vertex,
            |v| (v.pixel_floor, v.epsilon) = (0.0, 0.0),
            "vertex pixel_floor = 0: must be finite and at least 0.5",
        );
    }

    #[test]
    fn package_stats_round_trip() {
        let stats = PackageStats {
            triangles: 1,
            traced_triangles: 2,
            visible_vertices: 3,
            vertex_samples: 4,
            filled_pixels: 5,
            refined_edges: 6,
            faces: 7,
            pixels: 8,
            vertex_time: Duration::new(1, 234_567_891),
            fill_time: Duration::from_nanos(17),
        };
        assert_eq!(PackageStats::from(WirePackageStats::from(&stats)), stats);
    }
}
