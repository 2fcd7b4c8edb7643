//! Behaviour tests: vertices show exactly what the ray tracer sees (convex
//! and concave mirrors, a lens with and without dispersion, a mirror seen in
//! a mirror), determinism, and the cockpit against the reference.

mod scenes;

use std::sync::Arc;

use glam::Vec3;
use vtfarm_method::{MethodFrame, ReflectionMethod, VertexTracing};
use vtfarm_raster::IdBuffer;
use vtfarm_scene::{Camera, Lighting, Scene, TriangleId};
use vtfarm_trace::{SceneBvh, SurfacePoint, TraceSettings, Tracer};

use self::scenes::Builder;
use crate::level::{Context, Level};
use crate::warp::{Kind, Warp};
use crate::{Pvrr, PvrrConfig, Refraction};

/// A scene, its BVH and a frame set-up.
struct Setup {
    bvh: SceneBvh,
    camera: Camera,
    lighting: Lighting,
    ids: IdBuffer,
    reflector: Vec<TriangleId>,
}

impl Setup {
    fn new(scene: Scene, lighting: Lighting, camera: Camera, reflector: Vec<TriangleId>) -> Self {
        let ids = vtfarm_raster::id_buffer(&scene, &camera);
        Setup {
            bvh: SceneBvh::new(Arc::new(scene)),
            camera,
            lighting,
            ids,
            reflector,
        }
    }

    fn frame(&self) -> MethodFrame<'_> {
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

    /// Each reflector vertex facing the eye, as a surface point and the eye
    /// ray's direction.
    fn facing_vertices(&self) -> Vec<(SurfacePoint, Vec3)> {
        let scene = self.bvh.scene();
        let mut seen = std::collections::BTreeMap::new();
        for &t in &self.reflector {
            for v in scene.triangles[t as usize].vertices {
                seen.entry(v).or_insert(t);
            }
        }
        seen.into_iter()
            .map(|(v, triangle)| {
                let position = scene.positions[v as usize];
                let point = SurfacePoint {
                    position,
                    normal: scene.normals[v as usize],
                    triangle,
                };
                (point, (position - self.camera.eye).normalize())
            })
            .filter(|(p, incoming)| p.normal.dot(*incoming) < 0.0)
            .collect()
    }
}

/// How the warped map compares with the ray tracer at the vertices.
#[derive(Debug)]
struct VertexErrors {
    facing: usize,
    /// Vertices the map shows (the others are traced, so trivially exact).
    mapped: usize,
    /// Mean and maximum of the largest channel error over mapped vertices.
    mean: f32,
    worst: f32,
    /// Share of mapped vertices within `tolerance`.
    within: f32,
}

/// Compares `warp` at every facing vertex with `expected(point, incoming)`.
fn vertex_errors(
    setup: &Setup,
    warp: &Warp<'_>,
    tolerance: f32,
    expected: &dyn Fn(&SurfacePoint, Vec3) -> Vec3,
) -> VertexErrors {
    let vertices = setup.facing_vertices();
    let mut errors = Vec::new();
    for (point, incoming) in &vertices {
        let (got, _, traced) = warp.radiance_at(point, *incoming);
        if traced == 0 {
            errors.push((got - expected(point, *incoming)).abs().max_element());
        }
    }
    let n = errors.len().max(1) as f32;
    VertexErrors {
        facing: vertices.len(),
        mapped: errors.len(),
        mean: errors.iter().sum::<f32>() / n,
        worst: errors.iter().copied().fold(0.0, f32::max),
        within: errors.iter().filter(|&&e| e <= tolerance).count() as f32 / n,
    }
}

/// The radiance the ray tracer sees along the vertex's mirror ray.
fn traced_reflection<'a>(frame: &'a MethodFrame<'a>) -> impl Fn(&SurfacePoint, Vec3) -> Vec3 + 'a {
    move |point, incoming| {
        let ray = frame
            .tracer
            .surface_terms(point, incoming)
            .reflection
            .unwrap();
        frame.secondary_tracer().trace(&ray).color
    }
}

fn config(map_resolution: u32, refraction: Refraction) -> PvrrConfig {
    PvrrConfig {
        map_resolution,
        refraction,
    }
}

/// A mirror cap (convex or concave) in the middle of the lit room.
fn mirror_in_room(facing: f32, radius: f32) -> Setup {
    let mut b = Builder::default();
    let lighting = scenes::room(&mut b);
    let reflector = b.grid(
        "mirror",
        scenes::mirror(),
        16,
        0.6,
        &scenes::spherical(radius, facing),
    );
    let camera = scenes::camera(Vec3::new(0.4, 0.5, 2.6), Vec3::ZERO, 40.0, 64);
    Setup::new(b.build(), lighting, camera, reflector)
}

#[test]
fn convex_mirror_vertices_show_the_ray_traced_reflection() {
    let setup = mirror_in_room(1.0, 3.0);
    let frame = setup.frame();
    let config = config(512, Refraction::Traced);
    let context = Context::new(&config, &frame.tracer);
    let level = Level {
        context: &context,
        tracer: frame.tracer,
    };
    let warp = Warp::build(&level, setup.camera.eye, &setup.reflector, Kind::Reflection);
    let view = warp.map().view;
    eprintln!("{:?} {view:?}", warp.debug_counts());
    assert!(
        view.near > 0.5,
        "the virtual viewpoint lies behind the convex mirror"
    );
    let errors = vertex_errors(&setup, &warp, 0.02, &traced_reflection(&frame));
    assert!(
        errors.mapped as f32 >= 0.95 * errors.facing as f32,
        "{errors:?}"
    );
    assert!(errors.within >= 0.97, "{errors:?}");
    assert!(errors.mean < 0.01, "{errors:?}");

    // The same map looked up by direction alone (an environment map from the
    // virtual viewpoint) is far off in this small room: the warp matters.
    let map = warp.map();
    let unwarped: Vec<f32> = setup
        .facing_vertices()
        .iter()
        .filter_map(|(point, incoming)| {
            let ray = frame.tracer.surface_terms(point, *incoming).reflection?;
            let at = map
                .view
                .coords_of_direction(&map.projector, ray.direction)?;
            Some(
                (map.sample(at) - traced_reflection(&frame)(point, *incoming))
                    .abs()
                    .max_element(),
            )
        })
        .collect();
    let unwarped_mean = unwarped.iter().sum::<f32>() / unwarped.len() as f32;
    assert!(
        errors.mean * 5.0 < unwarped_mean,
        "{errors:?} vs {unwarped_mean}"
    );
}
