//! Rasterizes the virtual meshes into the reflector's pixels (the paper's
//! second rendering pass): only pixels the frame's ID buffer gives to the
//! reflector, only fragments behind the reflector's surface, nearest
//! virtual fragment wins (ties to the lower triangle id).
//!
//! Bands of rows run on rayon; each band visits its triangles in index
//! order with a strict (depth, triangle) comparison, so the result does not
//! depend on the thread count.

use rayon::prelude::*;
use vtfarm_method::ReflectorPixel;
use vtfarm_raster::IdBuffer;
use vtfarm_scene::{Camera, NONE, Projector, ScreenPoint};

use crate::mesh::ReflectedMesh;
use crate::search::{Region, VirtualVertex};

/// What a reflector pixel shows of the virtual meshes: a triangle of the
/// reflected mesh and perspective-correct barycentric weights of its corners.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct VirtualHit {
    pub(crate) triangle: u32,
    pub(crate) weights: [f32; 3],
}

/// A virtual triangle projected to the screen.
struct ScreenTriangle {
    triangle: u32,
    corners: [ScreenPoint; 3],
    /// Its pixels in the window (see [`PixelWindow::span`]).
    span: (u32, u32, u32, u32),
}

/// The reflector pixels' rectangle and a map from its pixels to their
/// index in the pixel list.
struct PixelWindow {
    x0: u32,
    y0: u32,
    width: u32,
    height: u32,
    slot: Vec<u32>,
}

const BAND_ROWS: u32 = 8;

/// One hit (or none) per entry of `pixels`. `virtuals` holds the virtual
/// vertex of every vertex of `mesh`.
pub(crate) fn rasterize_virtual_meshes(
    mesh: &ReflectedMesh,
    camera: &Camera,
    ids: &IdBuffer,
    pixels: &[ReflectorPixel],
    virtuals: &[VirtualVertex],
) -> Vec<Option<VirtualHit>> {
    let Some(window) = PixelWindow::new(pixels) else {
        return Vec::new();
    };
    let projector = Projector::new(camera);
    let screen: Vec<ScreenTriangle> = mesh
        .triangles
        .par_iter()
        .enumerate()
        .filter_map(|(t, triangle)| {
            let corners = triangle.corners.map(|v| virtuals[v as usize]);
            // Triangles wholly hidden or unreflected stay out (§6.1); a
            // failed corner would place the triangle anywhere.
            let usable = corners.iter().all(|c| c.region != Region::Failed)
                && corners.iter().any(|c| c.in_front);
            if !usable {
                return None;
            }
            let projected = corners.map(|c| projector.project(c.virtual_position));
            let [Some(a), Some(b), Some(c)] = projected else {
                return None;
            };
            let corners = [a, b, c];
            Some(ScreenTriangle {
                triangle: t as u32,
                corners,
                span: window.span(&corners)?,
            })
        })
        .collect();

    let bands = window.height.div_ceil(BAND_ROWS);
    let mut bins = vec![Vec::new(); bands as usize];
    for (k, t) in screen.iter().enumerate() {
        let (_, _, y_lo, y_hi) = t.span;
        for band in y_lo / BAND_ROWS..=y_hi / BAND_ROWS {
            bins[band as usize].push(k);
        }
    }
    let band_hits: Vec<Vec<(usize, VirtualHit)>> = bins
        .par_iter()
        .enumerate()
        .map(|(band, members)| {
            let rows = band as u32 * BAND_ROWS..((band as u32 + 1) * BAND_ROWS).min(window.height);
            window.rasterize_band(ids, rows, members.iter().map(|&k| &screen[k]))
        })
        .collect();
    let mut hits = vec![None; pixels.len()];
    for (slot, hit) in band_hits.into_iter().flatten() {
        hits[slot] = Some(hit);
    }
    hits
}

impl PixelWindow {
    fn new(pixels: &[ReflectorPixel]) -> Option<PixelWindow> {
        let x0 = pixels.iter().map(|p| p.x).min()?;
        let x1 = pixels.iter().map(|p| p.x).max()?;
        let y0 = pixels.iter().map(|p| p.y).min()?;
        let y1 = pixels.iter().map(|p| p.y).max()?;
        let (width, height) = (x1 - x0 + 1, y1 - y0 + 1);
        let mut slot = vec![NONE; (width * height) as usize];
        for (k, p) in pixels.iter().enumerate() {
            slot[((p.y - y0) * width + p.x - x0) as usize] = k as u32;
        }
        Some(PixelWindow {
            x0,
            y0,
            width,
            height,
            slot,
        })
    }

    /// The window-relative pixels whose centres lie in the bounding box of
    /// a screen triangle's corners, as inclusive (x_lo, x_hi, y_lo, y_hi);
    /// `None` if none.
    fn span(&self, corners: &[ScreenPoint; 3]) -> Option<(u32, u32, u32, u32)> {
        let range = |v: [f32; 3], origin: u32, limit: u32| {
            let v = v.map(|c| c - origin as f32 - 0.5);
            let lo = v[0].min(v[1]).min(v[2]).ceil().max(0.0);
            let hi = v[0].max(v[1]).max(v[2]).floor().min(limit as f32 - 1.0);
            (lo <= hi).then_some((lo as u32, hi as u32))
        };
        let (x_lo, x_hi) = range(corners.map(|c| c.x), self.x0, self.width)?;
        let (y_lo, y_hi) = range(corners.map(|c| c.y), self.y0, self.height)?;
        Some((x_lo, x_hi, y_lo, y_hi))
    }

    fn rasterize_band<'a>(
        &self,
        ids: &IdBuffer,
        rows: std::ops::Range<u32>,
        triangles: impl Iterator<Item = &'a ScreenTriangle>,
    ) -> Vec<(usize, VirtualHit)> {
        let band_pixels = ((rows.end - rows.start) * self.width) as usize;
        let mut best: Vec<Option<(f32, VirtualHit)>> = vec![None; band_pixels];
        for t in triangles {
            let [a, b, c] = t.corners;
            let area = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x);
            if area.abs() < 1e-12 {
                continue;
            }
            let (x_lo, x_hi, y_lo, y_hi) = t.span;
            for y in y_lo.max(rows.start)..=y_hi.min(rows.end - 1) {
                for x in x_lo..=x_hi {
                    let slot = self.slot[(y * self.width + x) as usize];
                    if slot == NONE {
                        continue;
                    }
                    let (px, py) = ((self.x0 + x) as f32 + 0.5, (self.y0 + y) as f32 + 0.5);
                    let edge = |p: ScreenPoint, q: ScreenPoint| {
                        ((p.x - px) * (q.y - py) - (p.y - py) * (q.x - px)) / area
                    };
                    let w = [edge(b, c), edge(c, a), edge(a, b)];
                    if w.iter().any(|&wi| wi < 0.0) {
                        continue;
                    }
                    let q = [w[0] / a.depth, w[1] / b.depth, w[2] / c.depth];
                    let sum = q[0] + q[1] + q[2];
                    let depth = 1.0 / sum;
                    let surface = ids.depth_at(self.x0 + x, self.y0 + y);
                    if depth < surface * (1.0 - 1e-4) {
                        continue;
                    }
                    let local = ((y - rows.start) * self.width + x) as usize;
                    let better =
                        best[local].is_none_or(|(d, hit)| (depth, t.triangle) < (d, hit.triangle));
                    if better {
                        best[local] = Some((
                            depth,
                            VirtualHit {
                                triangle: t.triangle,
                                weights: q.map(|qi| qi / sum),
                            },
                        ));
                    }
                }
            }
        }
        best.into_iter()
            .enumerate()
            .filter_map(|(local, hit)| {
                let (x, y) = (
                    local as u32 % self.width,
                    rows.start + local as u32 / self.width,
                );
                let slot = self.slot[(y * self.width + x) as usize];
                hit.map(|(_, h)| (slot as usize, h))
            })
            .collect()
    }
}
