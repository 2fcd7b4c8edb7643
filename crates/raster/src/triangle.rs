//! A triangle ready for scan conversion. Corners are snapped to a fixed-point
//! grid of 1/256 pixel so that edge functions are exact integers: the top-left
//! fill rule is then exact (triangles sharing an edge never both cover, nor
//! both miss, a pixel centre on it) and the result cannot depend on the order
//! or place in which pixels are evaluated.

use vtfarm_scene::TriangleId;

use crate::PixelRect;

/// Sub-pixel units per pixel.
const SUBPIXEL: i64 = 256;
/// A pixel centre's offset from its corner, in sub-pixel units.
const HALF_PIXEL: i64 = SUBPIXEL / 2;

/// A projected corner: continuous pixel coordinates and inverse view depth.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ScreenVertex {
    pub(crate) x: f64,
    pub(crate) y: f64,
    pub(crate) inv_depth: f64,
}

#[derive(Clone, Copy, Debug)]
pub(crate) struct RasterTriangle {
    pub(crate) id: TriangleId,
    /// Corners in sub-pixel units, ordered so that the signed area is
    /// positive (clockwise on the y-down screen): two-sided, no culling.
    corners: [[i64; 2]; 3],
    /// Inverse view depth, linear in screen space: its value at corner 0 and
    /// its derivatives along x and y (per pixel).
    inv_depth: [f64; 3],
    /// Smallest and largest corner inverse depth: interpolation inside the
    /// triangle stays in this range, rounding must not leave it.
    inv_depth_range: [f64; 2],
    /// Inclusive range of rows whose pixel centres the bounding box covers,
    /// clipped to the rectangle being rasterized.
    pub(crate) rows: (u32, u32),
    /// The same for columns.
    pub(crate) columns: (u32, u32),
}

/// Snaps a pixel coordinate to the sub-pixel grid. Callers keep coordinates
/// within the guard band, far from `i64` overflow.
fn snap(v: f64) -> i64 {
    (v * SUBPIXEL as f64).round() as i64
}

/// The pixels whose centres lie in the sub-pixel range [`lo`, `hi`],
/// intersected with `start..end`.
fn pixel_range(lo: i64, hi: i64, start: u32, end: u32) -> Option<(u32, u32)> {
    // First centre at or after lo: ceil((lo - HALF) / SUBPIXEL).
    let first = (-(HALF_PIXEL - lo).div_euclid(SUBPIXEL)).max(i64::from(start));
    let last = (hi - HALF_PIXEL)
        .div_euclid(SUBPIXEL)
        .min(i64::from(end) - 1);
    (first <= last).then_some((first as u32, last as u32))
}

impl RasterTriangle {
    /// Sets up a triangle for rasterizing the pixels of `within` (inside the
    /// image); `None` when it covers none of their centres for sure (zero
    /// area after snapping, or outside the rectangle).
    pub(crate) fn new(
        id: TriangleId,
        vertices: [ScreenVertex; 3],
        within: PixelRect,
    ) -> Option<Self> {
        let mut corners = vertices.map(|v| [snap(v.x), snap(v.y)]);
        let mut inv = vertices.map(|v| v.inv_depth);
        let [[x0, y0], [x1, y1], [x2, y2]] = corners;
        let area = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0);
        if area == 0 {
            return None;
        }
        if area < 0 {
            corners.swap(1, 2);
            inv.swap(1, 2);
        }
        let columns = pixel_range(x0.min(x1).min(x2), x0.max(x1).max(x2), within.x0, within.x1)?;
        let rows = pixel_range(y0.min(y1).min(y2), y0.max(y1).max(y2), within.y0, within.y1)?;

        // The plane of 1/z over the snapped corners (pixel units).
        let p = corners.map(|[x, y]| [x as f64 / SUBPIXEL as f64, y as f64 / SUBPIXEL as f64]);
        let (ex1, ey1) = (p[1][0] - p[0][0], p[1][1] - p[0][1]);
        let (ex2, ey2) = (p[2][0] - p[0][0], p[2][1] - p[0][1]);
        let (d1, d2) = (inv[1] - inv[0], inv[2] - inv[0]);
        let det = ex1 * ey2 - ey1 * ex2;
        let ddx = (d1 * ey2 - d2 * ey1) / det;
        let ddy = (d2 * ex1 - d1 * ex2) / det;
        let inv_depth_range = [
            inv[0].min(inv[1]).min(inv[2]),
            inv[0].max(inv[1]).max(inv[2]),
        ];
        Some(RasterTriangle {
            id,
            corners,
            inv_depth: [inv[0], ddx, ddy],
            inv_depth_range,
            rows,
            columns,
        })
    }

    /// Whether its bounding box reaches a pixel of `within`: a triangle set
    /// up for a larger rectangle covers no pixel of `within` otherwise.
    pub(crate) fn reaches(&self, within: PixelRect) -> bool {
        self.columns.0 < within.x1
            && self.columns.1 >= within.x0
            && self.rows.0 < within.y1
            && self.rows.1 >= within.y0
    }

    /// The inclusive range of columns of row `y` whose pixel centres the
    /// triangle covers under the top-left rule, or `None`.
    pub(crate) fn span(&self, y: u32) -> Option<(u32, u32)> {
        let py = i64::from(y) * SUBPIXEL + HALF_PIXEL;
        let (mut first, mut last) = (i64::from(self.columns.0), i64::from(self.columns.1));
        for i in 0..3 {
            let [ax, ay] = self.corners[i];
            let [bx, by] = self.corners[(i + 1) % 3];
            let (dx, dy) = (bx - ax, by - ay);
            // With positive area the inside is where every edge function is
            // >= 0. Centres exactly on an edge belong to it only if it is a
            // left edge (going up) or a top edge (horizontal, going right);
            // a shared edge is left/top for exactly one of its two triangles.
            let top_left = dy < 0 || (dy == 0 && dx > 0);
            // Edge function at column x: dx*(py - ay) - dy*(x*SUBPIXEL + HALF_PIXEL - ax)
            // = m - k*x; the pixel is inside this edge when m - k*x >= 0.
            let m = dx * (py - ay) - dy * (HALF_PIXEL - ax) - i64::from(!top_left);
            let k = dy * SUBPIXEL;
            match k.cmp(&0) {
                std::cmp::Ordering::Equal if m < 0 => return None,
                std::cmp::Ordering::Equal => {}
                std::cmp::Ordering::Greater => last = last.min(m.div_euclid(k)),
                std::cmp::Ordering::Less => first = first.max(-m.div_euclid(-k)),
            }
        }
        (first <= last).then_some((first as u32, last as u32))
    }

    /// A lower bound of [`Self::depth_at`] over the whole triangle: its
    /// nearest corner's depth (the interpolated 1/z is clamped to the
    /// corners' range, and division and rounding to `f32` are monotonic).
    pub(crate) fn nearest_depth(&self) -> f32 {
        (1.0 / self.inv_depth_range[1]) as f32
    }

    /// The view depth at the centre of pixel (`x`, `y`): 1/z is interpolated
    /// linearly in screen space (perspective-correct). Evaluated from scratch
    /// per pixel, never incrementally, so it does not depend on where a band
    /// or span starts.
    #[cfg(test)]
    pub(crate) fn depth_at(&self, x: u32, y: u32) -> f32 {
        self.depth_in_row(self.row_term(y), f64::from(x))
    }

    /// The part of 1/z that depends on the row alone.
    #[inline(always)]
    fn row_term(&self, y: u32) -> f64 {
        let y0 = self.corners[0][1] as f64 / SUBPIXEL as f64;
        self.inv_depth[2] * (f64::from(y) + 0.5 - y0)
    }

    /// [`Self::depth_at`] of column `x` in the row of `row_term`.
    #[inline(always)]
    fn depth_in_row(&self, row_term: f64, x: f64) -> f32 {
        let [inv0, ddx, _] = self.inv_depth;
        let x0 = self.corners[0][0] as f64 / SUBPIXEL as f64;
        let inv = inv0 + ddx * (x + 0.5 - x0) + row_term;
        // `f64::clamp` without its check of the bounds, which would keep
        // the loop of `z_test_span` from vectorizing (the range is ordered).
        let [lo, hi] = self.inv_depth_range;
        let inv = if inv < lo { lo } else { inv };
        let inv = if inv > hi { hi } else { inv };
        (1.0 / inv) as f32
    }

    /// Z-tests the pixels of row `y` from column `x0` on, one per slot of
    /// `depth` and `seen` (the row's stored depths and triangles there):
    /// where this triangle is nearer ([`Self::depth_at`]), or as near with
    /// a lower id, it takes the pixel.
    #[inline(always)]
    pub(crate) fn z_test_span(&self, y: u32, x0: u32, depth: &mut [f32], seen: &mut [u32]) {
        let row_term = self.row_term(y);
        let own = self.id.raw();
        let n = depth.len().min(seen.len());
        let (depth, seen) = (&mut depth[..n], &mut seen[..n]);
        for i in 0..n {
            // Columns are below 2^20: exact as `i32`, whose conversion
            // vectorizes.
            let x = f64::from((x0 + i as u32) as i32);
            let d = self.depth_in_row(row_term, x);
            // Nearer wins; an exact tie goes to the lower triangle id.
            // Unconditional stores and no short-circuit let the loop
            // vectorize.
            let (stored, id) = (depth[i], seen[i]);
            let wins = (d < stored) | ((d == stored) & (own < id));
            depth[i] = if wins { d } else { stored };
            seen[i] = if wins { own } else { id };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn vertex(x: f64, y: f64) -> ScreenVertex {
        ScreenVertex {
            x,
            y,
            inv_depth: 1.0,
        }
    }

    fn covered(t: &RasterTriangle, x: u32, y: u32) -> bool {
        t.span(y).is_some_and(|(a, b)| (a..=b).contains(&x))
    }

    #[test]
    fn centres_on_a_shared_diagonal_go_to_exactly_one_triangle() {
        // A 4x4-pixel square through pixel centres, split along its diagonal,
        // with both windings: every centre inside or on the diagonal is hit once.
        let [a, b, c, d] = [
            vertex(1.5, 1.5),
            vertex(5.5, 1.5),
            vertex(5.5, 5.5),
            vertex(1.5, 5.5),
        ];
        let upper = RasterTriangle::new(TriangleId(0), [a, b, c], PixelRect::full(8, 8)).unwrap();
        let lower = RasterTriangle::new(TriangleId(1), [a, d, c], PixelRect::full(8, 8)).unwrap();
        for y in 2..5 {
            for x in 2..5 {
                assert_eq!(
                    covered(&upper, x, y) as u32 + covered(&lower, x, y) as u32,
                    1,
                    "({x}, {y})"
                );
            }
        }
        // Left and top edges are in, right and bottom edges out.
        assert!(covered(&upper, 1, 1) && covered(&lower, 1, 4));
        assert!(!covered(&upper, 5, 3) && !covered(&lower, 3, 5));
    }

    #[test]
    fn depth_is_perspective_correct() {
        let t = RasterTriangle::new(
            TriangleId(0),
            [
                ScreenVertex {
                    x: 0.5,
                    y: 0.5,
                    inv_depth: 1.0,
                },
                ScreenVertex {
                    x: 8.5,
                    y: 0.5,
                    inv_depth: 0.25,
                },
                ScreenVertex {
                    x: 0.5,
                    y: 8.5,
                    inv_depth: 1.0,
                },
            ],
            PixelRect::full(16, 16),
        )
        .unwrap();
        // Halfway across on screen, 1/z is halfway: z = 1 / 0.625.
        assert!((t.depth_at(4, 0) - 1.6).abs() < 1e-6);
    }
}
