//! A task package: a set of reflector triangles traced into a sparse bitmap.
//!
//! Phase 1 traces the package's distinct original vertices in one parallel
//! batch (the preview). Phase 2 refines each triangle on its own (in
//! parallel) and reports finished faces at time breaks. Phase 3 gives every
//! pixel the ID buffer assigns to a triangle its colour: Gouraud from the
//! final face that contains the pixel centre, or a per-pixel trace where the
//! face's samples still disagree (triangle filling) or no face reached it.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use vtfarm_raster::{IdBuffer, PixelRect};
use vtfarm_scene::{NONE, ScreenPoint, TriangleId};
use vtfarm_trace::Sample;

use crate::refine::{Face, MeshVertex, TriangleMesh};
use crate::{Frame, Quality};

/// What the caller wants besides pixels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PackageOptions {
    /// Return the final refined faces in screen space (the wireframe overlay).
    pub collect_faces: bool,
    /// Call the progress callback at most this often.
    pub time_break: Option<Duration>,
}

/// A refined face as the progress callback and the wireframe overlay see it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FinishedFace {
    /// Screen positions (pixels) and view depths of the corners.
    pub corners: [ScreenPoint; 3],
    /// Linear colours of the corners.
    pub colors: [Vec3; 3],
}

/// Counters of one package.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PackageStats {
    /// Triangles in the package.
    pub triangles: u64,
    /// Triangles that own at least one pixel (the others cost nothing).
    pub traced_triangles: u64,
    /// Original and inserted vertices that passed the visibility test.
    pub visible_vertices: u64,
    /// Samples traced at vertices (original and inserted).
    pub vertex_samples: u64,
    /// Samples traced per pixel (triangle filling, or every pixel in `reference`).
    pub filled_pixels: u64,
    /// Edges split by the refinement.
    pub refined_edges: u64,
    /// Final faces after refinement.
    pub faces: u64,
    /// Pixels written.
    pub pixels: u64,
    /// Wall time of tracing and refining vertices.
    pub vertex_time: Duration,
    /// Wall time of assigning pixels and triangle filling.
    pub fill_time: Duration,
}

impl PackageStats {
    /// All traced samples (the paper's "pixel" column of Table 1).
    pub fn samples(&self) -> u64 {
        self.vertex_samples + self.filled_pixels
    }

    /// Adds another package's counters.
    pub fn add(&mut self, o: &PackageStats) {
        self.triangles += o.triangles;
        self.traced_triangles += o.traced_triangles;
        self.visible_vertices += o.visible_vertices;
        self.vertex_samples += o.vertex_samples;
        self.filled_pixels += o.filled_pixels;
        self.refined_edges += o.refined_edges;
        self.faces += o.faces;
        self.pixels += o.pixels;
        self.vertex_time += o.vertex_time;
        self.fill_time += o.fill_time;
    }
}

/// The reflector pixels of a package: a bounding rectangle with a coverage
/// mask, and for each covered pixel (row-major within the rectangle) its
/// colour, reflected and transmitted components and reflected object.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SparseBitmap {
    pub x0: u32,
    pub y0: u32,
    pub width: u32,
    pub height: u32,
    pub mask: Vec<bool>,
    pub color: Vec<Vec3>,
    pub reflected: Vec<Vec3>,
    pub transmitted: Vec<Vec3>,
    pub reflected_object: Vec<u32>,
}

impl SparseBitmap {
    /// The covered pixels as (x, y, index into the per-pixel arrays).
    pub fn covered(&self) -> impl Iterator<Item = (u32, u32, usize)> + '_ {
        self.mask
            .iter()
            .enumerate()
            .filter(|(_, m)| **m)
            .enumerate()
            .map(|(k, (i, _))| {
                (
                    self.x0 + i as u32 % self.width,
                    self.y0 + i as u32 / self.width,
                    k,
                )
            })
    }

    /// Pixel ownership: the first covered pixel that the ID buffer `ids`
    /// does not give to a triangle `owns` accepts (or that lies outside
    /// `ids`), or `None` when the package owns every pixel it writes. The
    /// master checks each result with it before compositing, so one package
    /// cannot overwrite another's pixels or the base frame.
    pub fn foreign_pixel(
        &self,
        ids: &IdBuffer,
        owns: impl Fn(TriangleId) -> bool,
    ) -> Option<(u32, u32)> {
        self.covered().map(|(x, y, _)| (x, y)).find(|&(x, y)| {
            x >= ids.width || y >= ids.height || !owns(ids.triangle[ids.index(x, y)])
        })
    }
}

/// The result of one package.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PackageResult {
    pub bitmap: SparseBitmap,
    pub stats: PackageStats,
    /// The final faces, when asked for.
    pub faces: Vec<FinishedFace>,
    /// Samples traced for each triangle of the package, in input order
    /// (corners counted for every triangle that uses them): the cost the
    /// farm's load balancer learns from.
    pub triangle_samples: Vec<u32>,
}

/// One pixel's value; `index` is `y * frame width + x`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelValue {
    pub index: u32,
    pub color: Vec3,
    pub reflected: Vec3,
    pub transmitted: Vec3,
    pub object: u32,
}

impl PixelValue {
    pub fn from_sample(index: u32, s: &Sample) -> Self {
        PixelValue {
            index,
            color: s.color,
            reflected: s.reflected,
            transmitted: s.transmitted,
            object: s.reflected_object,
        }
    }
}

/// Traces a package of reflector triangles. `progress` is called on this
/// thread at time breaks with the faces finished since the last call.
pub fn trace_package(
    frame: &Frame<'_>,
    triangles: &[TriangleId],
    options: &PackageOptions,
    progress: &mut dyn FnMut(&[FinishedFace]),
) -> PackageResult {
    let traced = trace_package_pixels(frame, triangles, options, progress);
    PackageResult {
        bitmap: SparseBitmap::from_parts(frame.ids.width, &traced.pixels),
        stats: traced.stats,
        faces: traced.faces,
        triangle_samples: traced.triangle_samples,
    }
}

/// A package traced with its pixels not packed into a bitmap: what a frame
/// rendered on one machine writes straight into its image
/// ([`crate::FrameImage::write`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TracedPixels {
    /// The pixels of each triangle that owns some, in package order.
    pub pixels: Vec<Vec<PixelValue>>,
    pub stats: PackageStats,
    /// The final faces, when asked for.
    pub faces: Vec<FinishedFace>,
    /// As [`PackageResult::triangle_samples`].
    pub triangle_samples: Vec<u32>,
}

/// [`trace_package`] without the packing into a bitmap.
pub fn trace_package_pixels(
    frame: &Frame<'_>,
    triangles: &[TriangleId],
    options: &PackageOptions,
    progress: &mut dyn FnMut(&[FinishedFace]),
) -> TracedPixels {
    let mut stats = PackageStats {
        triangles: triangles.len() as u64,
        ..Default::default()
    };
    let owned: Vec<(TriangleId, PixelRect)> = triangles
        .iter()
        .filter_map(|&t| frame.owned_rect(t).map(|r| (t, r)))
        .collect();
    stats.traced_triangles = owned.len() as u64;

    let vertex_start = Instant::now();
    let meshes = if frame.settings.quality == Quality::Reference {
        Vec::new()
    } else {
        let meshes = refine_all(frame, &owned, options, progress, &mut stats);
        for m in &meshes {
            stats.refined_edges += m.refined_edges;
            stats.visible_vertices += m.vertices.iter().filter(|v| v.visible).count() as u64;
            stats.faces += m.faces().count() as u64;
        }
        meshes
    };
    stats.vertex_time = vertex_start.elapsed();

    let fill_start = Instant::now();
    let per_triangle: Vec<(Vec<PixelValue>, u64)> = if meshes.is_empty() {
        owned
            .par_iter()
            .map(|&(t, rect)| trace_all_pixels(frame, t, rect))
            .collect()
    } else {
        meshes
            .par_iter()
            .zip(&owned)
            .map(|(mesh, &(_, rect))| shade_pixels(frame, mesh, rect))
            .collect()
    };
    stats.fill_time = fill_start.elapsed();
    stats.filled_pixels = per_triangle.iter().map(|(_, n)| n).sum();
    let mut triangle_samples = vec![0; triangles.len()];
    let mut next_owned = 0;
    for (slot, &t) in triangle_samples.iter_mut().zip(triangles) {
        if owned.get(next_owned).is_some_and(|&(o, _)| o == t) {
            let refined = meshes.get(next_owned).map_or(0, |m| m.refined_edges + 3);
            *slot = (refined + per_triangle[next_owned].1) as u32;
            next_owned += 1;
        }
    }

    let faces = if options.collect_faces {
        meshes.iter().flat_map(finished_faces).collect()
    } else {
        Vec::new()
    };
    let pixels: Vec<Vec<PixelValue>> = per_triangle.into_iter().map(|(p, _)| p).collect();
    stats.pixels = pixels.iter().map(|p| p.len() as u64).sum();
    TracedPixels {
        pixels,
        stats,
        faces,
        triangle_samples,
    }
}

/// Phases 1 and 2: traces the distinct original vertices once, then refines
/// each triangle, reporting finished faces at time breaks.
fn refine_all(
    frame: &Frame<'_>,
    owned: &[(TriangleId, PixelRect)],
    options: &PackageOptions,
    progress: &mut dyn FnMut(&[FinishedFace]),
    stats: &mut PackageStats,
) -> Vec<TriangleMesh> {
    let scene = frame.tracer.bvh.scene();
    // Neighbouring triangles share corners: trace each once, on its owner.
    let mut corner_index = HashMap::new();
    let mut corners = Vec::new();
    let corner_slots: Vec<[usize; 3]> = owned
        .iter()
        .map(|&(t, _)| {
            scene.triangles[t as usize].vertices.map(|v| {
                *corner_index.entry(v).or_insert_with(|| {
                    corners.push((frame.owners.of(v), v));
                    corners.len() - 1
                })
            })
        })
        .collect();
    let samples: Vec<Sample> = corners
        .par_chunks(VERTEX_BATCH)
        .flat_map_iter(|chunk| {
            let vertices: Vec<_> = chunk
                .iter()
                .map(|&(t, v)| (t, scene.positions[v as usize], scene.normals[v as usize]))
                .collect();
            frame.shade_vertices(&vertices)
        })
        .collect();
    stats.vertex_samples += samples.len() as u64;

    let projector = frame.projector();
    let mut meshes: Vec<TriangleMesh> = owned
        .iter()
        .zip(&corner_slots)
        .map(|(&(t, _), slots)| {
            let tri = scene.triangles[t as usize];
            let corner = |k: usize| {
                let v = tri.vertices[k] as usize;
                MeshVertex::new(
                    frame,
                    &projector,
                    t,
                    scene.positions[v],
                    scene.normals[v],
                    samples[slots[k]],
                )
            };
            TriangleMesh::new(t, [corner(0), corner(1), corner(2)])
        })
        .collect();
    if let Some(every) = options.time_break {
        progress(&meshes.iter().flat_map(finished_faces).collect::<Vec<_>>());
        let mut last_break = Instant::now();
        let mut pending = Vec::new();
        // Chunks keep the time breaks frequent while each chunk stays parallel.
        let chunk = (rayon::current_num_threads() * 8).max(1);
        for part in meshes.chunks_mut(chunk) {
            part.par_iter_mut()
                .for_each(|m| m.refine(frame, &projector));
            pending.extend(part.iter().flat_map(finished_faces));
            if last_break.elapsed() >= every {
                progress(&pending);
                pending.clear();
                last_break = Instant::now();
            }
        }
        if !pending.is_empty() {
            progress(&pending);
        }
    } else {
        meshes
            .par_iter_mut()
            .for_each(|m| m.refine(frame, &projector));
    }
    stats.vertex_samples += meshes.iter().map(|m| m.refined_edges).sum::<u64>();
    meshes
}

/// The screen-space faces of a mesh with their corner colours.
fn finished_faces(mesh: &TriangleMesh) -> impl Iterator<Item = FinishedFace> + '_ {
    mesh.faces().filter_map(|f| {
        let v = f.vertices.map(|i| mesh.vertices[i as usize]);
        let [Some(a), Some(b), Some(c)] = v.map(|v| v.screen) else {
            return None;
        };
        Some(FinishedFace {
            corners: [a, b, c],
            colors: v.map(|v| v.sample.color),
        })
    })
}

/// Corners per [`Frame::shade_vertices`] call: neighbours in mesh order,
/// whose reflection rays fill packets; small enough to share out to threads.
const VERTEX_BATCH: usize = 64;

/// Pixels per [`Frame::reference_pixels`] call: rows of neighbours whose
/// reflection rays fill packets, few enough that a stop is noticed soon.
const REFERENCE_BATCH: usize = 256;

/// Reference level: every owned pixel traced.
fn trace_all_pixels(
    frame: &Frame<'_>,
    triangle: TriangleId,
    rect: PixelRect,
) -> (Vec<PixelValue>, u64) {
    let owned: Vec<(u32, u32)> = rect
        .pixels()
        .filter(|&(x, y)| frame.owns(triangle, x, y))
        .collect();
    let mut pixels = Vec::with_capacity(owned.len());
    for batch in owned.chunks(REFERENCE_BATCH) {
        if frame.stopped() {
            break;
        }
        pixels.extend(frame.reference_pixels(triangle, batch));
    }
    let n = pixels.len() as u64;
    (pixels, n)
}

/// Phase 3 for one refined triangle: each owned pixel takes the final face
/// whose screen triangle contains its centre best (largest smallest
/// barycentric), so the faces need no fill rule and leave no gaps; pixels no
/// face reaches (float round-off at the rim) are traced.
fn shade_pixels(frame: &Frame<'_>, mesh: &TriangleMesh, rect: PixelRect) -> (Vec<PixelValue>, u64) {
    let width = rect.x1 - rect.x0;
    let area = (width * (rect.y1 - rect.y0)) as usize;
    let faces: Vec<ScreenFace> = mesh
        .faces()
        .filter_map(|f| ScreenFace::new(mesh, f))
        .collect();
    // The best face per pixel: (smallest barycentric, face index). A lone
    // face (every unrefined triangle) needs no table: it is tested per pixel.
    let mut best: Vec<(f32, u32)> = Vec::new();
    if faces.len() > 1 {
        best = vec![(f32::NEG_INFINITY, NO_FACE); area];
        for (fi, face) in faces.iter().enumerate() {
            let reach = face.reach(rect);
            for y in reach.y0..reach.y1 {
                let row = ((y - rect.y0) * width) as usize;
                for x in reach.x0..reach.x1 {
                    let score = face.score(face.weights(x, y));
                    let slot = &mut best[row + (x - rect.x0) as usize];
                    if score >= -1e-4 && score > slot.0 {
                        *slot = (score, fi as u32);
                    }
                }
            }
        }
    }
    let lone_reach = faces.first().map(|f| f.reach(rect));
    let face_at = |x: u32, y: u32| -> usize {
        if faces.len() > 1 {
            return best[((y - rect.y0) * width + (x - rect.x0)) as usize].1 as usize;
        }
        match (faces.first(), lone_reach) {
            (Some(face), Some(reach))
                if reach.contains(x, y) && face.score(face.weights(x, y)) >= -1e-4 =>
            {
                0
            }
            _ => NO_FACE as usize,
        }
    };
    let fill = frame.settings.quality == Quality::Full;
    let disagrees: Vec<bool> = faces
        .iter()
        .map(|f| fill && mesh.face_disagrees(f.face, frame.settings.epsilon))
        .collect();
    // A face whose samples agree may still hide a detail behind the glass that
    // no sample hit: its pixels near a change of the opaque scene behind are
    // filled too. `None`: no such check (opaque reflector, or not `full`).
    let behind_corner: Vec<Option<u32>> = faces
        .iter()
        .map(|f| {
            if !fill || !frame.behind_hints(mesh.triangle) {
                return None;
            }
            let objects = [f.a, f.b, f.c]
                .map(|s| frame.behind_object(s.x.floor() as i64, s.y.floor() as i64));
            // Corners that see different things behind: fill the whole face.
            Some(if objects[0] == objects[1] && objects[1] == objects[2] {
                objects[0]
            } else {
                NONE
            })
        })
        .collect();
    let mut traced = 0;
    let mut pixels = Vec::with_capacity(area / 2);
    for y in rect.y0..rect.y1 {
        if frame.stopped() {
            break;
        }
        for x in rect.x0..rect.x1 {
            if !frame.owns(mesh.triangle, x, y) {
                continue;
            }
            let index = frame.ids.index(x, y) as u32;
            let fi = face_at(x, y);
            let value = match faces.get(fi) {
                Some(face)
                    if !disagrees[fi]
                        && behind_corner[fi]
                            .is_none_or(|o| o != NONE && frame.behind_around(x, y) == Some(o)) =>
                {
                    let mut value = face.gouraud(index, mesh, face.weights(x, y));
                    frame.finish_pixel((x, y), &mut value);
                    value
                }
                _ => {
                    traced += 1;
                    frame.trace_pixel(mesh.triangle, x, y)
                }
            };
            pixels.push(value);
        }
    }
    (pixels, traced)
}

/// No face reaches the pixel.
const NO_FACE: u32 = u32::MAX;

/// A final face with its corners on screen, ready for barycentric weights
/// and perspective-correct interpolation.
struct ScreenFace<'m> {
    face: &'m Face,
    a: Vec2,
    b: Vec2,
    c: Vec2,
    /// One over twice the signed screen area.
    inv_denom: f32,
    /// One over each corner's view depth.
    inv_depth: [f32; 3],
}

impl<'m> ScreenFace<'m> {
    /// `None` when a corner is behind the eye or the face is degenerate on screen.
    fn new(mesh: &TriangleMesh, face: &'m Face) -> Option<Self> {
        let [Some(a), Some(b), Some(c)] = face.vertices.map(|i| mesh.vertices[i as usize].screen)
        else {
            return None;
        };
        let inv_depth = [a.depth, b.depth, c.depth].map(|d| 1.0 / d);
        let (a, b, c) = (
            Vec2::new(a.x, a.y),
            Vec2::new(b.x, b.y),
            Vec2::new(c.x, c.y),
        );
        let denom = (b - a).perp_dot(c - a);
        (denom.abs() >= 1e-12).then_some(ScreenFace {
            face,
            a,
            b,
            c,
            inv_denom: 1.0 / denom,
            inv_depth,
        })
    }

    /// The pixels of `rect` whose centres the face may contain: its screen
    /// bounding box, a pixel wider to the right and below.
    fn reach(&self, rect: PixelRect) -> PixelRect {
        let lo = self.a.min(self.b).min(self.c);
        let hi = self.a.max(self.b).max(self.c);
        PixelRect {
            x0: (lo.x.floor().max(rect.x0 as f32)) as u32,
            y0: (lo.y.floor().max(rect.y0 as f32)) as u32,
            x1: ((hi.x.ceil() + 1.0).min(rect.x1 as f32)) as u32,
            y1: ((hi.y.ceil() + 1.0).min(rect.y1 as f32)) as u32,
        }
    }

    /// How well the face contains a pixel centre of weights `w`: the
    /// smallest weight (negative outside).
    fn score(&self, w: [f32; 3]) -> f32 {
        w[0].min(w[1]).min(w[2])
    }

    /// The barycentric weights of pixel (x, y)'s centre.
    fn weights(&self, x: u32, y: u32) -> [f32; 3] {
        let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
        let wb = (p - self.a).perp_dot(self.c - self.a) * self.inv_denom;
        let wc = (self.b - self.a).perp_dot(p - self.a) * self.inv_denom;
        [1.0 - wb - wc, wb, wc]
    }

    /// Perspective-correct interpolation of the corner samples at screen
    /// weights `w` (divided by depth, as a GPU interpolates); the reflected
    /// object is the nearest corner's (the last of equals).
    fn gouraud(&self, index: u32, mesh: &TriangleMesh, w: [f32; 3]) -> PixelValue {
        let v = self
            .face
            .vertices
            .map(|i| &mesh.vertices[i as usize].sample);
        let pw: [f32; 3] = std::array::from_fn(|k| w[k].max(0.0) * self.inv_depth[k]);
        let scale = 1.0 / (pw[0] + pw[1] + pw[2]);
        let pw = pw.map(|x| x * scale);
        let blend = |f: fn(&Sample) -> Vec3| f(v[0]) * pw[0] + f(v[1]) * pw[1] + f(v[2]) * pw[2];
        let nearest = if pw[2] >= pw[1] && pw[2] >= pw[0] {
            2
        } else if pw[1] >= pw[0] {
            1
        } else {
            0
        };
        PixelValue {
            index,
            color: blend(|s| s.color),
            reflected: blend(|s| s.reflected),
            transmitted: blend(|s| s.transmitted),
            object: v[nearest].reflected_object,
        }
    }
}

impl SparseBitmap {
    /// Packs pixel values (each pixel at most once, any order) of a frame
    /// `frame_width` pixels wide into a bitmap: one pass over the bounding
    /// rectangle ranks the covered pixels row-major, and each value goes
    /// straight to its rank (no sort).
    pub fn from_pixels(frame_width: u32, pixels: Vec<PixelValue>) -> SparseBitmap {
        SparseBitmap::from_parts(frame_width, std::slice::from_ref(&pixels))
    }

    /// [`SparseBitmap::from_pixels`] of the pixel values of all `parts`.
    pub fn from_parts(frame_width: u32, parts: &[Vec<PixelValue>]) -> SparseBitmap {
        let pixels = || parts.iter().flatten();
        let n = parts.iter().map(Vec::len).sum();
        if n == 0 {
            return SparseBitmap::default();
        }
        let w = frame_width;
        let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0, 0);
        for p in pixels() {
            let (x, y) = (p.index % w, p.index / w);
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x + 1);
            y1 = y1.max(y + 1);
        }
        let width = x1 - x0;
        let local = |p: &PixelValue| ((p.index / w - y0) * width + (p.index % w - x0)) as usize;
        let mut mask = vec![false; (width * (y1 - y0)) as usize];
        for p in pixels() {
            mask[local(p)] = true;
        }
        // The rank of each covered pixel among the covered pixels, row-major
        // within the rectangle: the order of the per-pixel arrays.
        let mut rank = vec![0u32; mask.len()];
        let mut next = 0;
        for (r, &covered) in rank.iter_mut().zip(&mask) {
            *r = next;
            next += covered as u32;
        }
        let mut bitmap = SparseBitmap {
            x0,
            y0,
            width,
            height: y1 - y0,
            color: vec![Vec3::ZERO; n],
            reflected: vec![Vec3::ZERO; n],
            transmitted: vec![Vec3::ZERO; n],
            reflected_object: vec![NONE; n],
            mask,
        };
        for p in pixels() {
            let k = rank[local(p)] as usize;
            bitmap.color[k] = p.color;
            bitmap.reflected[k] = p.reflected;
            bitmap.transmitted[k] = p.transmitted;
            bitmap.reflected_object[k] = p.object;
        }
        bitmap
    }
}

#[cfg(test)]
mod ownership_tests {
    use super::*;

    /// A 3x2 frame: triangle 7 owns the left column, 8 the rest.
    fn ids() -> IdBuffer {
        let mut ids = IdBuffer::new(3, 2);
        for y in 0..2 {
            for x in 0..3 {
                let i = ids.index(x, y);
                ids.triangle[i] = if x == 0 { 7 } else { 8 };
            }
        }
        ids
    }

    /// A bitmap covering the given pixels of a `width` x `height` rectangle at (`x0`, `y0`).
    fn bitmap(x0: u32, y0: u32, width: u32, height: u32, mask: &[bool]) -> SparseBitmap {
        let n = mask.iter().filter(|&&m| m).count();
        SparseBitmap {
            x0,
            y0,
            width,
            height,
            mask: mask.to_vec(),
            color: vec![Vec3::ONE; n],
            reflected: vec![Vec3::ZERO; n],
            transmitted: vec![Vec3::ZERO; n],
            reflected_object: vec![NONE; n],
        }
    }

    #[test]
    fn pixel_values_pack_row_major_whatever_their_order() {
        // A frame 10 px wide; pixels (2, 1), (5, 1), (3, 2) in scrambled order.
        let value = |x: u32, y: u32| PixelValue {
            index: y * 10 + x,
            color: Vec3::splat(x as f32),
            reflected: Vec3::splat(y as f32),
            transmitted: Vec3::ONE,
            object: x * 100 + y,
        };
        let scrambled = vec![value(3, 2), value(2, 1), value(5, 1)];
        let b = SparseBitmap::from_pixels(10, scrambled);
        assert_eq!((b.x0, b.y0, b.width, b.height), (2, 1, 4, 2));
        let covered: Vec<_> = b.covered().collect();
        assert_eq!(covered, [(2, 1, 0), (5, 1, 1), (3, 2, 2)]);
        assert_eq!(b.color, [2.0, 5.0, 3.0].map(Vec3::splat));
        assert_eq!(b.reflected, [1.0, 1.0, 2.0].map(Vec3::splat));
        assert_eq!(b.reflected_object, [201, 501, 302]);
        assert_eq!(
            SparseBitmap::from_pixels(10, Vec::new()),
            SparseBitmap::default()
        );
    }

    #[test]
    fn a_bitmap_owns_only_its_triangles_pixels() {
        let ids = ids();
        let left_column = bitmap(0, 0, 1, 2, &[true, true]);
        assert_eq!(left_column.foreign_pixel(&ids, |t| t == 7), None);
        assert_eq!(left_column.foreign_pixel(&ids, |t| t == 8), Some((0, 0)));
        // Uncovered pixels of the rectangle do not count; (1, 1) is 8's.
        let corner = bitmap(0, 0, 2, 2, &[true, false, true, true]);
        assert_eq!(corner.foreign_pixel(&ids, |t| t == 7), Some((1, 1)));
        assert_eq!(corner.foreign_pixel(&ids, |t| t == 7 || t == 8), None);
        // A pixel outside the frame is never owned.
        let outside = bitmap(3, 0, 1, 1, &[true]);
        assert_eq!(outside.foreign_pixel(&ids, |_| true), Some((3, 0)));
    }
}
