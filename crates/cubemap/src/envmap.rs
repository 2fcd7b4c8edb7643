//! The plain environment map (Blinn and Newell; the paper's baseline): one
//! colour cube map of the scene without the reflector, rendered from the
//! reflector's centroid by the base-frame rasterizer (local Phong, no
//! shadows), looked up by each pixel's mirror direction.

use std::time::Instant;

use glam::Vec3;
use vtfarm_imaging::Image;
use vtfarm_method::{
    MethodCounters, MethodFrame, MethodOutput, Reflection, ReflectionMethod, ReflectorPixel,
    shade_reflector,
};
use vtfarm_raster::{id_buffer_where, shade_ids};
use vtfarm_scene::{Lighting, Scene, TriangleId};

use crate::cube::CubeLayout;
use crate::reflected::reflected_triangle_flags;

/// The environment-map method (`envmap`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnvironmentMap {
    /// Texels per face side.
    pub resolution: u32,
}

impl Default for EnvironmentMap {
    fn default() -> Self {
        EnvironmentMap { resolution: 256 }
    }
}

/// A rendered colour cube map with the object seen in each texel.
#[derive(Clone, Debug)]
pub struct EnvironmentCube {
    pub layout: CubeLayout,
    pub color: Vec<Vec3>,
    pub object: Vec<u32>,
}

impl EnvironmentCube {
    /// Renders the scene triangles `keep` accepts from `layout.centre`;
    /// empty texels get the background (as `shade_ids` leaves them).
    pub fn render(scene: &Scene, lighting: &Lighting, layout: CubeLayout, keep: &[bool]) -> Self {
        let mut cube = EnvironmentCube {
            layout,
            color: Vec::with_capacity(layout.texel_count()),
            object: Vec::with_capacity(layout.texel_count()),
        };
        let keep = |t: TriangleId| keep.get(t.index()).copied().unwrap_or(false);
        for face_index in 0..6 {
            let camera = layout.camera(face_index);
            let ids = id_buffer_where(scene, &camera, &keep);
            let image: Image = shade_ids(scene, &camera, lighting, &ids);
            cube.color.extend(image.pixels);
            cube.object.extend_from_slice(&ids.object);
        }
        cube
    }

    /// Bilinear colour and nearest object in `direction`.
    pub fn lookup(&self, direction: Vec3) -> Reflection {
        let p = self.layout.locate(direction);
        let radiance = self
            .layout
            .bilinear(p)
            .iter()
            .map(|&(index, weight)| self.color[index] * weight)
            .sum();
        Reflection {
            radiance,
            object: self.object[self.layout.nearest(p)],
        }
    }
}

/// The unit mirror direction of a reflector pixel's eye ray about its
/// shading normal (as the ray tracer reflects).
pub(crate) fn mirror_direction(pixel: &ReflectorPixel) -> Vec3 {
    let normal = pixel.point.normal.normalize_or(Vec3::Y);
    let facing = if normal.dot(pixel.incoming) > 0.0 {
        -normal
    } else {
        normal
    };
    vtfarm_trace::reflect(pixel.incoming, facing)
}

/// The area-weighted centroid of the reflector's triangles.
pub(crate) fn reflector_centroid(scene: &Scene, triangles: &[TriangleId]) -> Vec3 {
    let (sum, area) = triangles.iter().fold((Vec3::ZERO, 0.0), |(sum, area), &t| {
        let [a, b, c] = scene.triangle_positions(t);
        let w = 0.5 * (b - a).cross(c - a).length();
        (sum + (a + b + c) * (w / 3.0), area + w)
    });
    if area > 0.0 { sum / area } else { Vec3::ZERO }
}

impl EnvironmentMap {
    /// The map of the frame's reflector, rendered from its centroid.
    pub fn cube(&self, frame: &MethodFrame<'_>) -> EnvironmentCube {
        let keep = reflected_triangle_flags(frame.tracer.bvh.scene(), frame.reflector);
        self.cube_of(frame, &keep)
    }

    /// [`EnvironmentMap::cube`] with the reflected triangles already known.
    pub(crate) fn cube_of(&self, frame: &MethodFrame<'_>, keep: &[bool]) -> EnvironmentCube {
        let scene = frame.tracer.bvh.scene();
        let layout = CubeLayout {
            centre: reflector_centroid(scene, frame.reflector),
            resolution: self.resolution.max(2),
        };
        EnvironmentCube::render(scene, frame.tracer.lighting, layout, keep)
    }
}

impl ReflectionMethod for EnvironmentMap {
    fn name(&self) -> String {
        "envmap".to_owned()
    }

    fn render(&self, frame: &MethodFrame<'_>) -> MethodOutput {
        let start = Instant::now();
        let cube = self.cube(frame);
        let setup_time = start.elapsed();
        if frame.stopped() {
            return MethodOutput::default();
        }
        let pixels = frame.pixels();
        let reflections: Vec<Reflection> = pixels
            .iter()
            .map(|p| cube.lookup(mirror_direction(p)))
            .collect();
        let (bitmap, rays) = shade_reflector(frame, &pixels, &reflections, None);
        MethodOutput {
            bitmap,
            counters: MethodCounters {
                rays,
                searches: 0,
                pixels: pixels.len() as u64,
                setup_time,
                time: start.elapsed(),
            },
        }
    }
}
