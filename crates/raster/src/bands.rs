//! Visibility. Triangles are binned by the horizontal bands of rows their
//! bounding boxes overlap; each band is one rayon task that scan-converts its
//! triangles into its own slice of the z-buffer. The z-test is a total order
//! on (depth, triangle id), so a pixel's result does not depend on the order
//! in which triangles reach it: the output is the same for any thread count
//! and any scheduling.
//!
//! Most triangles of a detailed scene are hidden. Bands take their triangles
//! nearest first, and a row of a triangle whose nearest depth lies beyond
//! every depth already stored along it is skipped without interpolating its
//! depths: it could not win a single pixel there. The scan that tells stops
//! at the first stored depth at or beyond it.

use rayon::prelude::*;

use vtfarm_scene::{NONE, Triangle};

use crate::triangle::RasterTriangle;
use crate::{IdBuffer, PixelRect};

/// Rows per band: small enough for load balancing and a cache-resident
/// z-buffer slice, large enough that big triangles are not set up too often.
const BAND_ROWS: u32 = 16;

/// Fills `ids`' planes (whatever they held, of the window's size) with the
/// nearest triangle per pixel of the buffer's window, its depth and its
/// object (`NONE` and infinity where none is). A pixel's result does not
/// depend on the window, as long as it lies inside. Each band initializes
/// its own slices first, while they are in its cache.
/// `triangles` come in [`nearest_first`] order; the buffer is made of those
/// `kept` (a subsequence of such a list keeps it, so several buffers made
/// from one set-up sort it once).
pub(crate) fn resolve_nearest_first(
    scene_triangles: &[Triangle],
    triangles: &[RasterTriangle],
    kept: Kept<'_>,
    ids: &mut IdBuffer,
) {
    let window = ids.window;
    if window.is_empty() {
        return;
    }
    let stride = (window.x1 - window.x0) as usize;
    let bins = Bins::new(triangles, kept, window);
    let band_len = stride * BAND_ROWS as usize;
    let depth = ids.depth.par_chunks_mut(band_len);
    let triangle = ids.triangle.par_chunks_mut(band_len);
    let object = ids.object.par_chunks_mut(band_len);
    #[cfg(target_arch = "x86_64")]
    let avx2 = std::arch::is_x86_feature_detected!("avx2");
    depth
        .zip(triangle)
        .zip(object)
        .enumerate()
        .for_each(|(band, ((depth, triangle), object))| {
            depth.fill(f32::INFINITY);
            triangle.fill(NONE);
            let band = Band {
                window,
                first_row: window.y0 + band as u32 * BAND_ROWS,
                triangles: bins.band(band).iter().map(|&t| &triangles[t as usize]),
            };
            #[cfg(target_arch = "x86_64")]
            if avx2 {
                // SAFETY: the CPU supports AVX2, checked above.
                unsafe { band.resolve_avx2(depth, triangle) };
            } else {
                band.resolve(depth, triangle);
            }
            #[cfg(not(target_arch = "x86_64"))]
            band.resolve(depth, triangle);
            for (o, &t) in object.iter_mut().zip(&*triangle) {
                *o = if t == NONE {
                    NONE
                } else {
                    scene_triangles[t as usize].object.raw()
                };
            }
        });
}

/// One band's share of [`resolve_nearest_first`].
struct Band<I> {
    window: PixelRect,
    /// The band's first row in the frame.
    first_row: u32,
    /// Its triangles, nearest first.
    triangles: I,
}

impl<'a, I: Iterator<Item = &'a RasterTriangle>> Band<I> {
    /// [`Self::resolve`] compiled for AVX2: the same bits (the z-test's
    /// arithmetic is IEEE's in any register), in wider ones.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn resolve_avx2(self, depth: &mut [f32], triangle: &mut [u32]) {
        self.resolve(depth, triangle);
    }

    /// Scan-converts the band's triangles into its rows of the planes
    /// `depth` and `triangle`.
    #[inline(always)]
    fn resolve(self, depth: &mut [f32], triangle: &mut [u32]) {
        let Band {
            window,
            first_row,
            triangles,
        } = self;
        let stride = (window.x1 - window.x0) as usize;
        let last_row = first_row + (depth.len() / stride) as u32 - 1;
        // The planes' index of pixel (x, y) of this band.
        let slot = |x: u32, y: u32| (y - first_row) as usize * stride + (x - window.x0) as usize;
        for t in triangles {
            let nearest = t.nearest_depth();
            let hidden = |row: &[f32]| !reaches_beyond(row, nearest);
            for y in t.rows.0.max(first_row)..=t.rows.1.min(last_row) {
                let (c0, c1) = (t.columns.0.max(window.x0), t.columns.1.min(window.x1 - 1));
                if c0 > c1 || hidden(&depth[slot(c0, y)..=slot(c1, y)]) {
                    continue;
                }
                let Some((x0, x1)) = t.span(y) else { continue };
                let (x0, x1) = (x0.max(window.x0), x1.min(window.x1 - 1));
                if x0 > x1 || hidden(&depth[slot(x0, y)..=slot(x1, y)]) {
                    continue;
                }
                let span = slot(x0, y)..slot(x1, y) + 1;
                t.z_test_span(y, x0, &mut depth[span.clone()], &mut triangle[span]);
            }
        }
    }
}

/// Whether any of `depths` (never NaN) lies at or beyond `nearest`: where
/// none does, a triangle no nearer than `nearest` wins none of them. Scanned
/// a few registers at a time, stopping at the first that does.
fn reaches_beyond(depths: &[f32], nearest: f32) -> bool {
    const BLOCK: usize = 32;
    let beyond = |block: &[f32]| block.iter().fold(false, |any, &d| any | (d >= nearest));
    let blocks = depths.chunks_exact(BLOCK);
    let rest = blocks.remainder();
    blocks.into_iter().any(beyond) || beyond(rest)
}

/// The runs of set-up triangles `runs` as one list, nearest first (ties in
/// their order), copied so that bands read them in memory order.
pub(crate) fn nearest_first(runs: &[Vec<RasterTriangle>]) -> Vec<RasterTriangle> {
    let all: Vec<&RasterTriangle> = runs.iter().flatten().collect();
    // Positive depths order like their bits: sort (depth bits, index) keys.
    let mut keys: Vec<u64> = all
        .par_iter()
        .enumerate()
        .map(|(i, t)| u64::from(t.nearest_depth().to_bits()) << 32 | i as u64)
        .collect();
    keys.par_sort_unstable();
    keys.par_iter().map(|&k| *all[k as u32 as usize]).collect()
}

/// Which of the triangles a buffer is made of: all, or those whose flag is
/// set (several buffers made from one set-up take their share of it
/// without copying it).
#[derive(Clone, Copy)]
pub(crate) enum Kept<'a> {
    All,
    Flagged(&'a [bool]),
}

impl Kept<'_> {
    fn keeps(self, i: usize) -> bool {
        match self {
            Kept::All => true,
            Kept::Flagged(flags) => flags[i],
        }
    }
}

/// Triangle indices per band, in triangle order (a counting sort).
struct Bins {
    /// Band `b` owns `entries[offsets[b]..offsets[b + 1]]`.
    offsets: Vec<usize>,
    entries: Vec<u32>,
}

impl Bins {
    /// Bins the `kept` triangles by the bands of `window`'s rows, the first
    /// starting at its top.
    fn new(triangles: &[RasterTriangle], kept: Kept<'_>, window: PixelRect) -> Self {
        let bands = (window.y1 - window.y0).div_ceil(BAND_ROWS) as usize;
        let band_of =
            |y: u32| ((y.clamp(window.y0, window.y1 - 1) - window.y0) / BAND_ROWS) as usize;
        let overlapped = |t: &RasterTriangle| band_of(t.rows.0)..=band_of(t.rows.1);
        let kept = || (triangles.iter().enumerate()).filter(|&(i, _)| kept.keeps(i));
        let mut offsets = vec![0; bands + 1];
        for (_, t) in kept() {
            overlapped(t).for_each(|b| offsets[b + 1] += 1);
        }
        for b in 0..bands {
            offsets[b + 1] += offsets[b];
        }
        let mut next = offsets.clone();
        let mut entries = vec![0; offsets[bands]];
        for (i, t) in kept() {
            for b in overlapped(t) {
                entries[next[b]] = i as u32;
                next[b] += 1;
            }
        }
        Bins { offsets, entries }
    }

    fn band(&self, band: usize) -> &[u32] {
        &self.entries[self.offsets[band]..self.offsets[band + 1]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::triangle::ScreenVertex;
    use rand::{Rng as _, SeedableRng};
    use rand_xoshiro::Xoshiro256PlusPlus;
    use vtfarm_scene::TriangleId;

    #[test]
    fn the_portable_and_the_avx2_band_give_the_same_bits() {
        // Overlapping triangles at random depths (ties included: every
        // fourth shares its depths with the one before), whole bands of a
        // window that does not start at the frame's corner.
        let window = PixelRect {
            x0: 3,
            y0: 5,
            x1: 70,
            y1: 53,
        };
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(2);
        let mut next = |lo: f64, hi: f64| lo + (hi - lo) * rng.random::<f64>();
        let mut depths = [1.0; 3];
        let triangles: Vec<RasterTriangle> = TriangleId::range(300)
            .filter_map(|id| {
                if id.raw() % 4 != 1 {
                    depths = [next(0.05, 1.0), next(0.05, 1.0), next(0.05, 1.0)];
                }
                let corners = depths.map(|inv_depth| ScreenVertex {
                    x: next(-10.0, 80.0),
                    y: next(-10.0, 60.0),
                    inv_depth,
                });
                RasterTriangle::new(id, corners, window)
            })
            .collect();
        let triangles = nearest_first(&[triangles]);
        let bins = Bins::new(&triangles, Kept::All, window);
        let stride = (window.x1 - window.x0) as usize;
        let mut covered = 0;
        for band in 0..(window.y1 - window.y0).div_ceil(BAND_ROWS) as usize {
            let first_row = window.y0 + band as u32 * BAND_ROWS;
            let rows = (window.y1 - first_row).min(BAND_ROWS) as usize;
            let make = || Band {
                window,
                first_row,
                triangles: bins.band(band).iter().map(|&t| &triangles[t as usize]),
            };
            let mut portable = (
                vec![f32::INFINITY; stride * rows],
                vec![NONE; stride * rows],
            );
            make().resolve(&mut portable.0, &mut portable.1);
            covered += portable.1.iter().filter(|&&t| t != NONE).count();
            #[cfg(target_arch = "x86_64")]
            if std::arch::is_x86_feature_detected!("avx2") {
                let mut avx2 = (
                    vec![f32::INFINITY; stride * rows],
                    vec![NONE; stride * rows],
                );
                // SAFETY: the CPU supports AVX2, checked just above.
                unsafe { make().resolve_avx2(&mut avx2.0, &mut avx2.1) };
                assert_eq!(avx2.1, portable.1, "band {band}");
                let bits = |d: &[f32]| d.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&avx2.0), bits(&portable.0), "band {band}");
            }
        }
        // Not vacuous: most of the window is covered.
        assert!(covered > stride * 30, "{covered}");
    }
}
