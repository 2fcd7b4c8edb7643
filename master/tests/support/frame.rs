//! The small cockpit frame the master's tests render: 96×54 pixels at `full`.

use glam::Vec3;
use vtfarm_cockpit::Cockpit;
use vtfarm_render::FrameSetup;
use vtfarm_scene::Camera;
use vtfarm_trace::TraceSettings;
use vtfarm_vertex::{Quality, VertexSettings};

/// The driver's view of `cockpit`, its eye moved by `eye_offset`.
pub(crate) fn small_frame(cockpit: &Cockpit, eye_offset: Vec3) -> FrameSetup {
    FrameSetup {
        camera: Camera {
            eye: cockpit.camera.eye + eye_offset,
            width: 96,
            height: 54,
            ..cockpit.camera
        },
        lighting: cockpit.lighting.clone(),
        trace: TraceSettings::default(),
        vertex: VertexSettings {
            quality: Quality::Full,
            ..VertexSettings::default()
        },
    }
}
