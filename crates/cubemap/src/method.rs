//! The cube-map method behind [`ReflectionMethod`]: pre-process, search,
//! rasterize the virtual meshes, shade what they show.

use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;
use vtfarm_method::{
    MethodCounters, MethodFrame, MethodOutput, Reflection, ReflectionMethod, shade_reflector,
};
use vtfarm_trace::{Hit, SceneBvh, SurfacePoint};

use crate::envmap::{EnvironmentCube, EnvironmentMap, mirror_direction};
use crate::maps::ReflectorMaps;
use crate::mesh::ReflectedMesh;
use crate::raster::{VirtualHit, rasterize_virtual_meshes};
use crate::reflected::reflected_triangle_flags;
use crate::search::SearchSettings;
use crate::vertices::{GridSettings, virtual_vertices};

/// Settings of the cube-map method.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CubeMapConfig {
    /// Texels per side of each reflector map face.
    pub resolution: u32,
    /// Times each reflector triangle is split in four before rasterizing
    /// the maps (Phong tessellation; 0 keeps the mesh the tracer sees).
    pub subdivisions: u32,
    pub search: SearchSettings,
    /// The interpolation grid of §5; `None` searches every mesh vertex.
    pub grid: Option<GridSettings>,
    /// Texels per face side of the environment map for uncovered pixels.
    pub fallback_resolution: u32,
    /// Reflected triangles with a longer edge are split (see `mesh`), as a
    /// fraction of the reflector's radius around its centroid.
    pub max_edge_ratio: f32,
}

impl Default for CubeMapConfig {
    fn default() -> Self {
        CubeMapConfig {
            resolution: 256,
            subdivisions: 0,
            search: SearchSettings::default(),
            grid: None,
            fallback_resolution: 128,
            max_edge_ratio: 0.5,
        }
    }
}

/// Reflector cube maps with reflection-point search (`cubemap`, or
/// `cubemap-grid` with the interpolation grid).
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct CubeMapMethod {
    pub config: CubeMapConfig,
}

/// A reflector's view-independent pre-processing.
#[derive(Clone, Debug)]
pub struct PreparedReflector {
    /// The maps; `maps.shape` tells whether the search supports this
    /// reflector (print [`ReflectorShape::warning`](crate::ReflectorShape::warning)).
    pub maps: ReflectorMaps,
    /// Shows in pixels no virtual triangle covers.
    pub fallback: EnvironmentCube,
    /// The reflected meshes, split as `max_edge_ratio` asks.
    pub(crate) mesh: ReflectedMesh,
}

impl CubeMapMethod {
    /// Searches every mesh vertex.
    pub fn full() -> Self {
        CubeMapMethod::default()
    }

    /// Searches the corners of the §5 grid with the default fraction.
    pub fn grid() -> Self {
        CubeMapMethod {
            config: CubeMapConfig {
                grid: Some(GridSettings::default()),
                ..CubeMapConfig::default()
            },
        }
    }

    /// The pre-processing of the frame's reflector: its maps, the fallback
    /// environment map and the reflected meshes (none depends on the view).
    pub fn prepare(&self, frame: &MethodFrame<'_>) -> PreparedReflector {
        let scene = frame.tracer.bvh.scene();
        let maps = ReflectorMaps::build(
            scene,
            frame.reflector,
            self.config.resolution,
            self.config.subdivisions,
        );
        if let Some(warning) = maps.shape.warning() {
            tracing::warn!("{warning}");
        }
        let keep = reflected_triangle_flags(scene, frame.reflector);
        let fallback = EnvironmentMap {
            resolution: self.config.fallback_resolution,
        }
        .cube_of(frame, &keep);
        let mesh = ReflectedMesh::build(scene, &keep, self.config.max_edge_ratio * maps.radius);
        PreparedReflector {
            maps,
            fallback,
            mesh,
        }
    }

    /// Renders with an existing pre-processing.
    pub fn render_prepared(
        &self,
        frame: &MethodFrame<'_>,
        prepared: &PreparedReflector,
    ) -> MethodOutput {
        if frame.stopped() {
            return MethodOutput::default();
        }
        let scene = frame.tracer.bvh.scene();
        let mesh = &prepared.mesh;
        let (virtuals, searches) = virtual_vertices(
            mesh,
            &prepared.maps,
            frame.camera.eye,
            &self.config.search,
            self.config.grid.as_ref(),
            &|| frame.stopped(),
        );
        if frame.stopped() {
            return MethodOutput::default();
        }
        let pixels = frame.pixels();
        let hits = rasterize_virtual_meshes(mesh, &frame.camera, frame.ids, &pixels, &virtuals);
        let secondary = frame.secondary_tracer();
        // Each reflection with whether it shaded a hit (one ray's work).
        let (reflections, shaded): (Vec<Reflection>, Vec<bool>) = pixels
            .par_iter()
            .zip(&hits)
            .map(|(pixel, hit)| match hit {
                // Not shaded: a stopped package's result is discarded.
                Some(_) if frame.stopped() => (Reflection::NONE, false),
                Some(hit) => {
                    frame.charge(1);
                    let point = surface_point(frame.tracer.bvh, mesh, hit);
                    let incoming = (point.position - pixel.point.position).normalize_or_zero();
                    let reflection = Reflection {
                        radiance: secondary.shade(&point, incoming).color,
                        object: scene.triangles[point.triangle.index()].object.raw(),
                    };
                    (reflection, true)
                }
                None => (prepared.fallback.lookup(mirror_direction(pixel)), false),
            })
            .unzip();
        let shaded = shaded.iter().filter(|&&s| s).count() as u64;
        let (bitmap, rays) = shade_reflector(frame, &pixels, &reflections, None);
        MethodOutput {
            bitmap,
            counters: MethodCounters {
                rays: rays + shaded,
                searches,
                pixels: pixels.len() as u64,
                ..MethodCounters::default()
            },
        }
    }
}

impl ReflectionMethod for CubeMapMethod {
    fn name(&self) -> String {
        match self.config.grid {
            Some(_) => "cubemap-grid".to_owned(),
            None => "cubemap".to_owned(),
        }
    }

    fn render(&self, frame: &MethodFrame<'_>) -> MethodOutput {
        let start = Instant::now();
        let prepared = self.prepare(frame);
        let setup_time = start.elapsed();
        let mut output = self.render_prepared(frame, &prepared);
        output.counters.setup_time = setup_time;
        output.counters.time = start.elapsed();
        output
    }
}

/// The original surface point under a virtual fragment: the fragment's
/// weights mapped to barycentrics of the original triangle, interpolated as
/// the tracer interpolates a hit.
fn surface_point(bvh: &SceneBvh, mesh: &ReflectedMesh, hit: &VirtualHit) -> SurfacePoint {
    let triangle = &mesh.triangles[hit.triangle as usize];
    let w: Vec3 = (0..3)
        .map(|k| triangle.barycentric[k] * hit.weights[k])
        .sum();
    bvh.surface_point(&Hit {
        triangle: triangle.original,
        // Not a ray hit: surface_point reads only the barycentrics.
        t: 0.0,
        u: w.y,
        v: w.z,
    })
}
