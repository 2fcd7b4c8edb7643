//! The small cockpit job the master's scenario tests run: frames from
//! slightly different eyes, and their single-process images to compare with.

use std::sync::Arc;

use glam::Vec3;
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_master::{JobOptions, wire_job};
use vtfarm_method::MethodKind;
use vtfarm_proto::{SceneData, WireJob};
use vtfarm_render::{FrameSetup, Renderer};
use vtfarm_scene::{Scene, TriangleId};

use crate::frame::small_frame;

/// A small cockpit job of `frames` frames from slightly different eyes.
pub(crate) struct Job {
    pub(crate) scene: Scene,
    pub(crate) reflectors: Vec<TriangleId>,
    pub(crate) frames: Vec<FrameSetup>,
}

impl Job {
    pub(crate) fn new(frames: usize) -> Job {
        let c = cockpit(&CockpitConfig {
            detail: 0.2,
            glass_segments: 24,
            ..CockpitConfig::default()
        });
        let reflectors = c.cover_glass_triangles();
        let frames = (0..frames)
            .map(|k| small_frame(&c, Vec3::new(0.01, 0.005, 0.0) * k as f32))
            .collect();
        Job {
            scene: c.scene,
            reflectors,
            frames,
        }
    }

    pub(crate) fn wire(&self) -> (WireJob, SceneData) {
        let data = SceneData::from_scene(&self.scene);
        (
            wire_job(
                "faults",
                &data,
                &self.frames,
                &self.reflectors,
                JobOptions {
                    method: MethodKind::VertexTracing,
                    aux: false,
                },
            ),
            data,
        )
    }

    /// The single-process images.
    pub(crate) fn reference(&self) -> Vec<Vec<Vec3>> {
        let renderer = Renderer::new(Arc::new(self.scene.clone()), self.reflectors.clone());
        (self.frames.iter())
            .map(|f| {
                let render = renderer.render(f, &Default::default(), &mut |_, _| {});
                render.image.color.pixels
            })
            .collect()
    }
}
