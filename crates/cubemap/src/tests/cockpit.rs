//! The methods on the cockpit's cover glass against the ray-traced
//! reference: both cube-map variants must be closer than the environment
//! map on the reflected component.

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_method::{MethodFrame, MethodOutput, ReflectionMethod, VertexTracing};
use vtfarm_raster::IdBuffer;
use vtfarm_scene::{Camera, Lighting};
use vtfarm_trace::{SceneBvh, TraceSettings, Tracer};
use vtfarm_vertex::{Quality, SparseBitmap, VertexSettings};

use crate::{CubeMapMethod, EnvironmentMap, ReflectorShape};

pub(super) struct Setup {
    pub(super) bvh: SceneBvh,
    camera: Camera,
    lighting: Lighting,
    ids: IdBuffer,
    pub(super) reflector: Vec<u32>,
}

pub(super) fn small_cockpit() -> Setup {
    let c = cockpit(&CockpitConfig {
        detail: 0.3,
        ..Default::default()
    });
    let camera = Camera {
        width: 320,
        height: 180,
        ..c.camera
    };
    let reflector = c.cover_glass_triangles();
    let ids = vtfarm_raster::id_buffer(&c.scene, &camera);
    Setup {
        bvh: SceneBvh::new(Arc::new(c.scene)),
        camera,
        lighting: c.lighting,
        ids,
        reflector,
    }
}

impl Setup {
    pub(super) fn frame(&self) -> MethodFrame<'_> {
        MethodFrame {
            tracer: Tracer {
                bvh: &self.bvh,
                lighting: &self.lighting,
                settings: TraceSettings::default(),
            },
            camera: self.camera,
            ids: &self.ids,
            reflector: &self.reflector,
        }
    }
}

/// Mean absolute error per channel over the reflector's pixels.
fn mean_absolute_error(a: &[Vec3], b: &[Vec3]) -> f32 {
    assert_eq!(a.len(), b.len());
    let sum: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| f64::from((*x - *y).abs().element_sum()) / 3.0)
        .sum();
    (sum / a.len() as f64) as f32
}

struct Errors {
    reflected: f32,
    color: f32,
}

fn errors(output: &SparseBitmap, reference: &SparseBitmap) -> Errors {
    assert_eq!(output.mask, reference.mask);
    Errors {
        reflected: mean_absolute_error(&output.reflected, &reference.reflected),
        color: mean_absolute_error(&output.color, &reference.color),
    }
}

fn timed(method: &dyn ReflectionMethod, frame: &MethodFrame<'_>) -> MethodOutput {
    let start = Instant::now();
    let out = method.render(frame);
    println!(
        "{:>13}: {:>7.1} ms (setup {:.1} ms), {} searches, {} rays",
        method.name(),
        start.elapsed().as_secs_f64() * 1e3,
        out.counters.setup_time.as_secs_f64() * 1e3,
        out.counters.searches,
        out.counters.rays
    );
    out
}

#[test]
fn cube_maps_are_closer_to_the_reference_than_the_environment_map() {
    let setup = small_cockpit();
    let frame = setup.frame();
    let reference = VertexTracing {
        settings: VertexSettings {
            quality: Quality::Reference,
            ..Default::default()
        },
    };
    let reference = timed(&reference, &frame).bitmap;
    let envmap = errors(
        &timed(&EnvironmentMap::default(), &frame).bitmap,
        &reference,
    );
    println!(
        "envmap: reflected MAE {:.5}, colour MAE {:.5}",
        envmap.reflected, envmap.color
    );
    for method in [CubeMapMethod::full(), CubeMapMethod::grid()] {
        let out = timed(&method, &frame);
        assert!(out.counters.searches > 0);
        assert_eq!(
            out.counters.pixels,
            reference.mask.iter().filter(|m| **m).count() as u64
        );
        let e = errors(&out.bitmap, &reference);
        println!(
            "{}: reflected MAE {:.5}, colour MAE {:.5}",
            method.name(),
            e.reflected,
            e.color
        );
        assert!(
            e.reflected < envmap.reflected,
            "{}: {} vs envmap {}",
            method.name(),
            e.reflected,
            envmap.reflected
        );
        assert!(
            e.color <= envmap.color,
            "{}: {} vs envmap {}",
            method.name(),
            e.color,
            envmap.color
        );
    }
}

#[test]
fn the_cover_glass_is_concave() {
    let setup = small_cockpit();
    let prepared = CubeMapMethod::full().prepare(&setup.frame());
    assert_eq!(prepared.shape, ReflectorShape::Concave);
}
