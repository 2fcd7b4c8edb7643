//! Phase 3 of a package: every pixel the ID buffer gives to one of its
//! triangles gets its value, straight into per-pixel planes (a frame's, or
//! a package's own rectangle that becomes its bitmap). One pass over the
//! pixels, split into bands of rows over the threads, interpolates where a
//! final face's samples agree; the pixels that need a sample of their own
//! (triangle filling, the rim no face reaches, every pixel at `reference`)
//! are collected and traced afterwards in batches, then written.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use vtfarm_raster::PixelRect;
use vtfarm_scene::{NONE, TriangleId};
use vtfarm_trace::Sample;

use crate::refine::{Face, TriangleMesh};
use crate::{Frame, PixelValue, Quality};

/// Per-pixel planes over a rectangle of the frame, row-major, `stride`
/// pixels a row, the first element pixel (`x0`, `y0`): where phase 3 writes.
/// The colour plane covers the same rows but may be wider (a frame's is
/// full width): `color_stride` pixels a row, the first column `color_x0`.
pub(crate) struct Planes<'a> {
    pub(crate) x0: u32,
    pub(crate) y0: u32,
    pub(crate) stride: usize,
    pub(crate) color_x0: u32,
    pub(crate) color_stride: usize,
    pub(crate) color: &'a mut [Vec3],
    pub(crate) reflected: &'a mut [Vec3],
    pub(crate) transmitted: &'a mut [Vec3],
    pub(crate) object: &'a mut [u32],
    pub(crate) mask: &'a mut [bool],
}

impl<'a> Planes<'a> {
    pub(crate) fn set(&mut self, x: u32, y: u32, value: &PixelValue) {
        let row = (y - self.y0) as usize;
        self.color[row * self.color_stride + (x - self.color_x0) as usize] = value.color;
        let i = row * self.stride + (x - self.x0) as usize;
        self.reflected[i] = value.reflected;
        self.transmitted[i] = value.transmitted;
        self.object[i] = value.object;
        self.mask[i] = true;
    }

    /// The planes cut into bands of `rows` rows (the last may be shorter).
    fn bands(&mut self, rows: u32) -> Vec<Planes<'_>> {
        let n = self.stride * rows as usize;
        if n == 0 {
            return Vec::new();
        }
        let (x0, y0, stride) = (self.x0, self.y0, self.stride);
        let (color_x0, color_stride) = (self.color_x0, self.color_stride);
        self.color
            .chunks_mut(color_stride * rows as usize)
            .zip(self.reflected.chunks_mut(n))
            .zip(self.transmitted.chunks_mut(n))
            .zip(self.object.chunks_mut(n))
            .zip(self.mask.chunks_mut(n))
            .enumerate()
            .map(
                |(k, ((((color, reflected), transmitted), object), mask))| Planes {
                    x0,
                    y0: y0 + k as u32 * rows,
                    stride,
                    color_x0,
                    color_stride,
                    color,
                    reflected,
                    transmitted,
                    object,
                    mask,
                },
            )
            .collect()
    }

    /// The rows `y0..y1` the planes cover.
    pub(crate) fn rows(&self) -> (u32, u32) {
        let rows = self.mask.len().checked_div(self.stride).unwrap_or(0);
        (self.y0, self.y0 + rows as u32)
    }
}

/// Rows per band of the interpolation pass: many more bands than threads
/// (the glass is uneven), few enough that each band's look at every
/// triangle of the package stays cheap.
const BAND_ROWS: u32 = 8;

/// Pixels per batch of [`Frame::trace_pixels`]: neighbours whose
/// reflection rays fill packets, few enough that a stop is noticed soon.
const PIXEL_BATCH: usize = 256;

/// What phase 3 knows about one triangle of the package before its pixels.
pub(crate) struct TrianglePlan<'m> {
    pub(crate) triangle: TriangleId,
    /// Every pixel the triangle owns lies inside.
    pub(crate) rect: PixelRect,
    /// The final faces on screen (none at `reference`: every pixel traced).
    faces: Vec<ScreenFace<'m>>,
    /// The best face per pixel of `rect` when there are several:
    /// (smallest barycentric, face index).
    best: Vec<(f32, u32)>,
    /// The pixels a lone face may reach (empty for several faces).
    lone_reach: PixelRect,
    /// Per face: its samples agree, so its pixels are interpolated.
    interpolated: Vec<bool>,
    /// Per face: with traced transmission at `full`, the object behind the
    /// glass its corners all see (`NONE`: they see different things), and
    /// a pixel is interpolated only where its surroundings show that too.
    behind_corner: Vec<Option<u32>>,
}

impl<'m> TrianglePlan<'m> {
    /// The plan of an owned triangle: its final faces on screen and, when it
    /// has several, which one each pixel centre falls in best (largest
    /// smallest barycentric), so the faces need no fill rule and leave no gaps.
    pub(crate) fn new(
        frame: &Frame<'_>,
        triangle: TriangleId,
        rect: PixelRect,
        mesh: Option<&'m TriangleMesh>,
    ) -> Self {
        // A triangle none of whose samples is visible (corners off screen
        // or hidden) has nothing to interpolate from: every pixel it owns
        // is traced, at every level.
        let mesh = mesh.filter(|m| m.vertices.iter().any(|v| v.visible));
        let faces: Vec<ScreenFace> = mesh.map_or_else(Vec::new, |mesh| {
            mesh.faces()
                .filter_map(|f| ScreenFace::new(mesh, f))
                .collect()
        });
        let width = rect.x1 - rect.x0;
        let mut best: Vec<(f32, u32)> = Vec::new();
        if faces.len() > 1 {
            best = vec![(f32::NEG_INFINITY, NO_FACE); (width * (rect.y1 - rect.y0)) as usize];
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
        let fill = frame.settings.quality == Quality::Full;
        // At `full`, faces whose samples disagree are filled, and so are
        // faces that may mirror a bright source (`capture.rs`).
        let interpolated = faces
            .iter()
            .map(|f| {
                !(fill
                    && (f.mesh.face_disagrees(f.face, frame.settings.epsilon)
                        || f.mesh.face_captures(frame, f.face)))
            })
            .collect();
        let behind_corner = faces
            .iter()
            .map(|f| {
                if !fill || !frame.behind_hints(triangle) {
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
        let lone_reach = match faces.as_slice() {
            [face] => face.reach(rect),
            _ => PixelRect {
                x0: 0,
                y0: 0,
                x1: 0,
                y1: 0,
            },
        };
        TrianglePlan {
            triangle,
            rect,
            lone_reach,
            faces,
            best,
            interpolated,
            behind_corner,
        }
    }

    /// The face whose interpolation gives owned pixel (x, y) and the
    /// pixel's weights in it, or `None` when the pixel is traced: no face
    /// reaches it, or its face's samples disagree at `full` (triangle
    /// filling), or a detail behind the glass may hide there.
    fn interpolating_face(&self, frame: &Frame<'_>, x: u32, y: u32) -> Option<(usize, [f32; 3])> {
        let (fi, w) = if self.faces.len() > 1 {
            let width = self.rect.x1 - self.rect.x0;
            let fi = self.best[((y - self.rect.y0) * width + (x - self.rect.x0)) as usize].1;
            let face = self.faces.get(fi as usize)?;
            (fi as usize, face.weights(x, y))
        } else {
            let face = self.faces.first()?;
            if !self.lone_reach.contains(x, y) {
                return None;
            }
            let w = face.weights(x, y);
            if face.score(w) < -1e-4 {
                return None;
            }
            (0, w)
        };
        if !self.interpolated[fi] {
            return None;
        }
        let hidden_detail = self.behind_corner[fi]
            .is_some_and(|o| o == NONE || frame.behind_around(x, y) != Some(o));
        (!hidden_detail).then_some((fi, w))
    }
}

/// What phase 3 did.
#[derive(Default)]
pub(crate) struct Filled {
    /// Samples traced per plan.
    pub(crate) traced: Vec<u64>,
    /// Pixels written.
    pub(crate) written: u64,
    /// Wall time of the interpolation pass and of writing the traced values.
    pub(crate) interpolation: Duration,
    /// Wall time of tracing the pixels that get a sample of their own.
    pub(crate) tracing: Duration,
}

/// The finished values of pixels traced one by one by earlier stages of a
/// progressive package, by frame index: a pixel's traced value is a
/// function of the pixel alone (its triangle, the frame), so a later stage
/// that traces the pixel again takes it from here, the same bits.
pub(crate) type TracedPixels = HashMap<u32, PixelValue>;

/// Phase 3: writes every pixel the plans' triangles own into `planes`
/// (which must cover their rectangles). A stopped package writes nothing,
/// or stops tracing within a batch and writes no traced value (its partial
/// result is dropped). Pixels to trace that `earlier` holds are taken from
/// it, the others traced and added to it (not at `reference`, whose
/// pixels are traced another way); without it, every one is traced.
pub(crate) fn fill(
    frame: &Frame<'_>,
    plans: &[TrianglePlan<'_>],
    planes: &mut Planes<'_>,
    mut earlier: Option<&mut TracedPixels>,
) -> Filled {
    let mut filled = Filled {
        traced: vec![0; plans.len()],
        written: 0,
        interpolation: Duration::ZERO,
        tracing: Duration::ZERO,
    };
    if frame.stopped() {
        return filled;
    }
    let start = Instant::now();
    // Interpolation, band by band; the pixels to trace are collected as
    // (plan, x, y), row-major within each plan and band.
    let bands: Vec<(Vec<ToTrace>, u64)> = planes
        .bands(BAND_ROWS)
        .into_par_iter()
        .map(|mut band| {
            let mut to_trace = Vec::new();
            let mut written = 0;
            let (y0, y1) = band.rows();
            for (pi, plan) in plans.iter().enumerate() {
                for y in plan.rect.y0.max(y0)..plan.rect.y1.min(y1) {
                    let row = frame.ids.frame_index(0, y);
                    for x in plan.rect.x0..plan.rect.x1 {
                        if frame.ids.triangle_at(x, y) != plan.triangle.raw() {
                            continue;
                        }
                        match plan.interpolating_face(frame, x, y) {
                            Some((fi, w)) => {
                                let index = (row + x as usize) as u32;
                                let mut value = plan.faces[fi].gouraud(index, w);
                                frame.finish_pixel((x, y), &mut value);
                                band.set(x, y, &value);
                                written += 1;
                            }
                            None => to_trace.push((pi as u32, x, y)),
                        }
                    }
                }
            }
            (to_trace, written)
        })
        .collect();
    filled.written = bands.iter().map(|(_, n)| n).sum();
    let mut to_trace: Vec<ToTrace> = bands.into_iter().flat_map(|(p, _)| p).collect();
    // Triangle by triangle, row-major: a batch then covers a compact patch
    // of the glass (its reflection rays stay coherent), not a strip of rows.
    to_trace.sort_by_key(|&(plan, _, _)| plan);
    let reference = frame.settings.quality == Quality::Reference;
    let index = |x: u32, y: u32| frame.ids.frame_index(x, y) as u32;
    if let Some(earlier) = earlier.as_deref().filter(|_| !reference) {
        to_trace.retain(|&(_, x, y)| match earlier.get(&index(x, y)) {
            Some(value) => {
                planes.set(x, y, value);
                filled.written += 1;
                false
            }
            None => true,
        });
    }
    filled.interpolation = start.elapsed();

    let start = Instant::now();
    let values: Vec<Vec<PixelValue>> = to_trace
        .par_chunks(PIXEL_BATCH)
        .map(|batch| {
            if frame.stopped() {
                return Vec::new();
            }
            let pixels: Vec<(TriangleId, u32, u32)> = batch
                .iter()
                .map(|&(pi, x, y)| (plans[pi as usize].triangle, x, y))
                .collect();
            frame.trace_pixels(&pixels, reference)
        })
        .collect();
    filled.tracing = start.elapsed();

    let start = Instant::now();
    let write = !frame.stopped();
    for (batch, values) in to_trace.chunks(PIXEL_BATCH).zip(&values) {
        for (&(pi, x, y), value) in batch.iter().zip(values) {
            filled.traced[pi as usize] += 1;
            if write {
                planes.set(x, y, value);
                filled.written += 1;
                if let Some(earlier) = earlier.as_deref_mut().filter(|_| !reference) {
                    earlier.insert(index(x, y), *value);
                }
            }
        }
    }
    filled.interpolation += start.elapsed();
    filled
}

/// A pixel to trace: (plan index, x, y).
type ToTrace = (u32, u32, u32);

/// No face reaches the pixel.
const NO_FACE: u32 = u32::MAX;

/// A final face with its corners on screen, ready for barycentric weights
/// and perspective-correct interpolation.
pub(crate) struct ScreenFace<'m> {
    mesh: &'m TriangleMesh,
    face: &'m Face,
    pub(crate) a: Vec2,
    pub(crate) b: Vec2,
    pub(crate) c: Vec2,
    /// One over twice the signed screen area.
    inv_denom: f32,
    /// One over each corner's view depth.
    inv_depth: [f32; 3],
}

impl<'m> ScreenFace<'m> {
    /// `None` when a corner is behind the eye or the face is degenerate on screen.
    fn new(mesh: &'m TriangleMesh, face: &'m Face) -> Option<Self> {
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
            mesh,
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
    fn gouraud(&self, index: u32, w: [f32; 3]) -> PixelValue {
        let v = self
            .face
            .vertices
            .map(|i| &self.mesh.vertices[i as usize].sample);
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
