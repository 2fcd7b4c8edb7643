//! The base-frame rasterizer (the paper's OpenGL pass): a multi-threaded
//! z-buffer rasterizer with the camera convention of `vtfarm_scene::Camera`,
//! producing the shaded base frame (per-pixel Phong, no ray tracing) and the
//! ID buffer (object id, triangle id, depth per pixel).
//!
//! Architecture invariant: deterministic; the same scene and camera give the
//! same ID buffer bit for bit on any machine and thread count (workers rebuild
//! it locally instead of receiving it).
//!
//! The pipeline has three stages:
//! 1. `setup`: project every vertex once, clip triangles that cross the near
//!    plane (or reach far outside the image) in view space, and snap corners to
//!    a fixed-point sub-pixel grid (`triangle`). The near plane lies at view
//!    depth `vtfarm_scene::NEAR` unless the caller of [`id_buffer_clipped`]
//!    places it elsewhere (a reflection map seen from behind its mirror).
//!    Only triangles that reach the rectangle being rasterized are kept;
//!    those wholly beside it are dropped first, by a byte per vertex.
//! 2. `bands`: bin triangles into horizontal bands and scan-convert each band
//!    on its own rayon task, nearest triangles first, with exact integer edge
//!    functions, the top-left fill rule and a (depth, triangle id) z-test.
//! 3. `shade`: deferred Phong shading, once per visible pixel, several pixels
//!    of a triangle at a time (`lanes`), bit-identical to the scalar model.
//!
//! The z-test's span loop and the shading lanes run in AVX2 registers where
//! the CPU has it (checked at run time): IEEE arithmetic is correctly
//! rounded in any register and nothing is fused, so every machine gets the
//! same bits. Dropped buffers leave their planes to the next (`spare`).

mod bands;
mod glass;
mod lanes;
mod setup;
mod shade;
mod spare;
mod triangle;

pub use glass::blend_see_through;

use rayon::prelude::*;
use vtfarm_imaging::Image;
use vtfarm_scene::{Camera, Lighting, NEAR, NONE, Scene, TriangleId};

/// Per-pixel visibility: which object and triangle is seen, and at what view
/// depth, over a `width` x `height` frame. The planes hold the pixels of
/// `window` only (row-major, `window`'s width per row): every pixel outside
/// it is empty (`NONE`, infinite depth). A buffer of the whole frame has the
/// whole frame as its window; a worker's covers the reflectors' bounds, so
/// that it costs their pixels, not the frame's. Read pixels with
/// [`IdBuffer::triangle_at`] and its siblings, or [`IdBuffer::slot`].
#[derive(Debug, PartialEq)]
pub struct IdBuffer {
    pub width: u32,
    pub height: u32,
    /// The pixels the planes hold, inside the frame.
    pub window: PixelRect,
    /// The object seen at each pixel ([`vtfarm_scene::ObjectId::raw`]), `NONE` where none is.
    pub object: Vec<u32>,
    /// The triangle seen at each pixel ([`TriangleId::raw`]), `NONE` where none is.
    pub triangle: Vec<u32>,
    /// View depth (distance along the camera's forward axis); infinity where empty.
    pub depth: Vec<f32>,
}

impl IdBuffer {
    /// An empty buffer of the whole frame.
    pub fn new(width: u32, height: u32) -> Self {
        IdBuffer::empty_within(width, height, PixelRect::full(width, height))
    }

    /// An empty buffer whose planes hold `window` (cut to the frame).
    pub fn empty_within(width: u32, height: u32, window: PixelRect) -> Self {
        let mut ids = IdBuffer::unshaped();
        ids.reshape_within(width, height, window);
        ids.object.fill(NONE);
        ids.triangle.fill(NONE);
        ids.depth.fill(f32::INFINITY);
        ids
    }

    /// A buffer of no pixels, no allocations yet.
    fn unshaped() -> Self {
        IdBuffer {
            width: 0,
            height: 0,
            window: EMPTY,
            object: Vec::new(),
            triangle: Vec::new(),
            depth: Vec::new(),
        }
    }

    /// Gives this buffer the frame size and `window` (cut to the frame) of
    /// [`IdBuffer::empty_within`], its planes that window's length with
    /// whatever values: in this buffer's allocations, or else in planes of
    /// dropped buffers (`spare`).
    fn reshape_within(&mut self, width: u32, height: u32, window: PixelRect) {
        let window = Some(window.clamped(width, height))
            .filter(|w| !w.is_empty())
            .unwrap_or(EMPTY);
        let n = window.area();
        (self.width, self.height, self.window) = (width, height, window);
        for plane in [&mut self.object, &mut self.triangle] {
            spare::reshape(plane, n, NONE);
        }
        spare::reshape(&mut self.depth, n, f32::INFINITY);
    }

    /// The frame's index of pixel (`x`, `y`): row-major over the whole
    /// frame, as images and bitmaps number pixels.
    pub fn frame_index(&self, x: u32, y: u32) -> usize {
        y as usize * self.width as usize + x as usize
    }

    /// Where pixel (`x`, `y`) lies in the planes, or `None` outside the
    /// window (an empty pixel, or one off the frame).
    #[inline]
    pub fn slot(&self, x: u32, y: u32) -> Option<usize> {
        let w = self.window;
        w.contains(x, y)
            .then(|| (y - w.y0) as usize * (w.x1 - w.x0) as usize + (x - w.x0) as usize)
    }

    /// The triangle seen at pixel (`x`, `y`), `NONE` where none is (or off the frame).
    #[inline]
    pub fn triangle_at(&self, x: u32, y: u32) -> u32 {
        self.slot(x, y).map_or(NONE, |i| self.triangle[i])
    }

    /// The object seen at pixel (`x`, `y`), `NONE` where none is (or off the frame).
    #[inline]
    pub fn object_at(&self, x: u32, y: u32) -> u32 {
        self.slot(x, y).map_or(NONE, |i| self.object[i])
    }

    /// The view depth at pixel (`x`, `y`), infinity where nothing is seen (or off the frame).
    #[inline]
    pub fn depth_at(&self, x: u32, y: u32) -> f32 {
        self.slot(x, y).map_or(f32::INFINITY, |i| self.depth[i])
    }
}

impl Clone for IdBuffer {
    /// In planes of dropped buffers where there are some (`spare`): a copy
    /// in fresh memory pays a page fault per 4 KiB (a worker copies its
    /// kept set-up buffers every frame).
    fn clone(&self) -> Self {
        IdBuffer {
            width: self.width,
            height: self.height,
            window: self.window,
            object: spare::copied(&self.object),
            triangle: spare::copied(&self.triangle),
            depth: spare::copied(&self.depth),
        }
    }
}

impl Drop for IdBuffer {
    /// Keeps the planes for the next buffer (`spare`).
    fn drop(&mut self) {
        spare::keep(std::mem::take(&mut self.object));
        spare::keep(std::mem::take(&mut self.triangle));
        spare::keep(std::mem::take(&mut self.depth));
    }
}

/// A rectangle of pixels: columns `x0..x1`, rows `y0..y1` (ends exclusive).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelRect {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

impl PixelRect {
    /// The whole `width` x `height` image.
    pub fn full(width: u32, height: u32) -> Self {
        PixelRect {
            x0: 0,
            y0: 0,
            x1: width,
            y1: height,
        }
    }

    /// This rectangle cut to a `width` x `height` image.
    pub fn clamped(self, width: u32, height: u32) -> Self {
        PixelRect {
            x0: self.x0.min(width),
            y0: self.y0.min(height),
            x1: self.x1.min(width),
            y1: self.y1.min(height),
        }
    }

    pub fn is_empty(self) -> bool {
        self.x0 >= self.x1 || self.y0 >= self.y1
    }

    /// The number of pixels inside.
    pub fn area(self) -> usize {
        if self.is_empty() {
            return 0;
        }
        (self.x1 - self.x0) as usize * (self.y1 - self.y0) as usize
    }

    /// No pixel.
    pub const EMPTY: PixelRect = EMPTY;

    /// The smallest rectangle holding every pixel of both (an empty one
    /// adds nothing).
    pub fn union(self, other: PixelRect) -> PixelRect {
        match (self.is_empty(), other.is_empty()) {
            (_, true) => self,
            (true, false) => other,
            (false, false) => PixelRect {
                x0: self.x0.min(other.x0),
                y0: self.y0.min(other.y0),
                x1: self.x1.max(other.x1),
                y1: self.y1.max(other.y1),
            },
        }
    }

    /// Whether every pixel of `other` lies inside (an empty `other` does).
    pub fn holds(self, other: PixelRect) -> bool {
        other.is_empty()
            || (self.x0 <= other.x0
                && self.y0 <= other.y0
                && other.x1 <= self.x1
                && other.y1 <= self.y1)
    }

    /// Whether pixel (`x`, `y`) lies inside.
    pub fn contains(self, x: u32, y: u32) -> bool {
        (self.x0..self.x1).contains(&x) && (self.y0..self.y1).contains(&y)
    }

    /// The pixels inside, row by row.
    pub fn pixels(self) -> impl Iterator<Item = (u32, u32)> {
        (self.y0..self.y1).flat_map(move |y| (self.x0..self.x1).map(move |x| (x, y)))
    }
}

/// No pixel: the window of a buffer with nothing rasterized.
const EMPTY: PixelRect = PixelRect {
    x0: 0,
    y0: 0,
    x1: 0,
    y1: 0,
};

/// The largest supported image width or height: keeps the fixed-point edge
/// functions exact in 64-bit integers.
const MAX_DIMENSION: u32 = 1 << 20;

/// Rasterizes the whole scene: the shaded base frame (linear RGB) and the ID buffer.
///
/// # Panics
/// If the camera's width or height exceeds 2^20 pixels, or the scene
/// indexes missing vertices, objects or materials.
pub fn rasterize(scene: &Scene, camera: &Camera, lighting: &Lighting) -> (Image, IdBuffer) {
    let mut image = Image::new(0, 0, lighting.background);
    let mut ids = IdBuffer::unshaped();
    rasterize_into(scene, camera, lighting, &mut image, &mut ids);
    (image, ids)
}

/// [`rasterize`] into the buffers of an earlier frame, whatever they hold:
/// they end up exactly as `rasterize` would make them, in their own
/// allocations (a frame rasterized in fresh buffers pays a page fault per
/// 4 KiB of them, at 1080p as much as the rasterizing itself).
///
/// # Panics
/// As [`rasterize`].
pub fn rasterize_into(
    scene: &Scene,
    camera: &Camera,
    lighting: &Lighting,
    image: &mut Image,
    ids: &mut IdBuffer,
) {
    let full = PixelRect::full(camera.width, camera.height);
    rasterize_ids_into(scene, camera, NEAR, full, &|_| true, ids);
    shade::shade_into(scene, camera, lighting, ids, image);
}

/// [`rasterize_into`] over the pixels of `within` only: they get exactly
/// what the whole frame has there, every other pixel is empty and the
/// background. For a caller that needs the frame at a known part alone (the
/// reflectors of a view whose page draws the scene itself), at the cost of
/// that part and of filling the buffers.
///
/// # Panics
/// As [`rasterize`].
pub fn rasterize_within_into(
    scene: &Scene,
    camera: &Camera,
    lighting: &Lighting,
    within: PixelRect,
    image: &mut Image,
    ids: &mut IdBuffer,
) {
    let part = rasterize_ids(scene, camera, NEAR, within, &|_| true);
    ids.reshape_within(
        camera.width,
        camera.height,
        PixelRect::full(camera.width, camera.height),
    );
    ids.object.fill(NONE);
    ids.triangle.fill(NONE);
    ids.depth.fill(f32::INFINITY);
    let w = part.window;
    let span = (w.x1 - w.x0) as usize;
    for (row, y) in (w.y0..w.y1).enumerate() {
        let from = row * span..(row + 1) * span;
        let to = ids.frame_index(w.x0, y);
        let to = to..to + span;
        ids.object[to.clone()].copy_from_slice(&part.object[from.clone()]);
        ids.triangle[to.clone()].copy_from_slice(&part.triangle[from.clone()]);
        ids.depth[to].copy_from_slice(&part.depth[from]);
    }
    shade::shade_into(scene, camera, lighting, ids, image);
}

/// Shades an ID buffer of the whole frame (local Phong, no shadows): with
/// [`id_buffer_where`] this rasterizes part of a scene, e.g. a cube-map face
/// without the reflector.
///
/// # Panics
/// If `ids` holds less than the whole frame (a buffer of
/// [`id_buffer_within`]).
pub fn shade_ids(scene: &Scene, camera: &Camera, lighting: &Lighting, ids: &IdBuffer) -> Image {
    shade::shade(scene, camera, lighting, ids)
}

/// Only the ID buffer (workers rebuild it locally; must equal the one from `rasterize` bit for bit).
///
/// # Panics
/// As [`rasterize`].
pub fn id_buffer(scene: &Scene, camera: &Camera) -> IdBuffer {
    id_buffer_where(scene, camera, &|_| true)
}

/// The ID buffer of only the triangles `keep` accepts, as if the others were
/// not there (the vertex tracer uses it to see what lies behind the glass).
pub fn id_buffer_where(
    scene: &Scene,
    camera: &Camera,
    keep: &(dyn Fn(TriangleId) -> bool + Sync),
) -> IdBuffer {
    id_buffer_clipped(scene, camera, NEAR, keep)
}

/// [`id_buffer_where`] over the pixels of `within` only: they get exactly
/// what the whole buffer has there, every other pixel stays empty. For a
/// caller that looks at a known part of the frame (a worker at the
/// reflectors), at the cost of that part.
///
/// # Panics
/// As [`rasterize`].
pub fn id_buffer_within(
    scene: &Scene,
    camera: &Camera,
    within: PixelRect,
    keep: &(dyn Fn(TriangleId) -> bool + Sync),
) -> IdBuffer {
    rasterize_ids(scene, camera, NEAR, within, keep)
}

/// One buffer of [`id_buffers_within`]: the pixels it covers and the
/// triangles it keeps.
#[derive(Clone, Copy)]
pub struct IdPass<'a> {
    pub within: PixelRect,
    pub keep: &'a (dyn Fn(TriangleId) -> bool + Sync),
}

/// [`id_buffer_within`] for several passes at once, each buffer bit for bit
/// what `id_buffer_within(scene, camera, pass.within, pass.keep)` gives: the
/// scene's vertices are projected and its triangles set up once for all (a
/// worker's frame buffer and the buffers behind its glass cover about the
/// same pixels, and projecting the scene is most of a small buffer's cost).
///
/// # Panics
/// As [`rasterize`].
pub fn id_buffers_within(scene: &Scene, camera: &Camera, passes: &[IdPass<'_>]) -> Vec<IdBuffer> {
    check_camera(camera);
    let clamp = |r: PixelRect| r.clamped(camera.width, camera.height);
    let live: Vec<PixelRect> = (passes.iter())
        .map(|p| clamp(p.within))
        .filter(|r| !r.is_empty())
        .collect();
    let Some(union) = live.iter().copied().reduce(PixelRect::union) else {
        return passes
            .iter()
            .map(|_| IdBuffer::empty_within(camera.width, camera.height, EMPTY))
            .collect();
    };
    let triangles = bands::nearest_first(&setup::setup(scene, camera, NEAR, union, &|t| {
        passes.iter().any(|p| (p.keep)(t))
    }));
    passes
        .iter()
        .map(|pass| {
            let within = clamp(pass.within);
            // A triangle's set-up does not depend on the rectangle beyond
            // which triangles are dropped, so the pass's own are these,
            // still nearest first.
            let kept: Vec<bool> = if within.is_empty() {
                Vec::new()
            } else {
                (triangles.par_iter())
                    .map(|t| t.reaches(within) && (pass.keep)(t.id))
                    .collect()
            };
            let mut ids = IdBuffer::unshaped();
            resolve_into(
                scene,
                camera,
                &triangles,
                bands::Kept::Flagged(&kept),
                within,
                &mut ids,
            );
            ids
        })
        .collect()
}

/// The ID buffer over `within` of two disjoint sets of triangles, from the
/// buffers `a` and `b` of each (their windows must hold `within`): per pixel
/// the nearer of the two, an exact depth tie going to the lower triangle id
/// as in the z-test, so bit for bit the buffer of both sets rasterized
/// together. It costs per pixel where scan conversion costs per triangle: a
/// worker's frame buffer is the one behind its glass and the glass's.
///
/// # Panics
/// If the buffers are of different frames or a window does not hold `within`.
pub fn nearer_of(a: &IdBuffer, b: &IdBuffer, within: PixelRect) -> IdBuffer {
    assert_eq!(
        (a.width, a.height),
        (b.width, b.height),
        "buffers of one frame"
    );
    let mut out = IdBuffer::empty_within(a.width, a.height, within);
    let w = out.window;
    assert!(
        a.window.holds(w) && b.window.holds(w),
        "the buffers {:?} and {:?} must hold {w:?}",
        a.window,
        b.window
    );
    let len = (w.x1 - w.x0) as usize;
    for (row, y) in (w.y0..w.y1).enumerate() {
        let row_of = |ids: &IdBuffer| ids.slot(w.x0, y).map_or(0..0, |i| i..i + len);
        let (ra, rb) = (row_of(a), row_of(b));
        let slots = row * len..(row + 1) * len;
        let pixels = (out.triangle[slots.clone()].iter_mut())
            .zip(&mut out.object[slots.clone()])
            .zip(&mut out.depth[slots]);
        let sources = (a.triangle[ra.clone()].iter())
            .zip(&a.object[ra.clone()])
            .zip(&a.depth[ra])
            .zip(
                b.triangle[rb.clone()]
                    .iter()
                    .zip(&b.object[rb.clone()])
                    .zip(&b.depth[rb]),
            );
        for (((t, o), d), (((&ta, &oa), &da), ((&tb, &ob), &db))) in pixels.zip(sources) {
            let b_wins = db < da || (db == da && tb < ta);
            (*t, *o, *d) = if b_wins { (tb, ob, db) } else { (ta, oa, da) };
        }
    }
    out
}

/// [`id_buffer_where`] with the near clipping plane at view depth `near`
/// instead of `vtfarm_scene::NEAR`: geometry nearer than `near` along the
/// camera's forward axis is clipped away exactly at the plane, so a pixel
/// shows the first kept surface beyond it. With `near == NEAR` the result is
/// [`id_buffer_where`]'s, bit for bit; like it, it is deterministic for any
/// thread count.
///
/// # Panics
/// As [`rasterize`], and if `near` is not positive and finite.
pub fn id_buffer_clipped(
    scene: &Scene,
    camera: &Camera,
    near: f32,
    keep: &(dyn Fn(TriangleId) -> bool + Sync),
) -> IdBuffer {
    let full = PixelRect::full(camera.width, camera.height);
    rasterize_ids(scene, camera, near, full, keep)
}

/// The one ID-buffer pass behind the public variants.
fn rasterize_ids(
    scene: &Scene,
    camera: &Camera,
    near: f32,
    within: PixelRect,
    keep: &(dyn Fn(TriangleId) -> bool + Sync),
) -> IdBuffer {
    let mut ids = IdBuffer::unshaped();
    rasterize_ids_into(scene, camera, near, within, keep, &mut ids);
    ids
}

/// [`rasterize_ids`] into `ids`, whatever it holds.
fn rasterize_ids_into(
    scene: &Scene,
    camera: &Camera,
    near: f32,
    within: PixelRect,
    keep: &(dyn Fn(TriangleId) -> bool + Sync),
    ids: &mut IdBuffer,
) {
    assert!(
        near > 0.0 && near.is_finite(),
        "the near plane must lie in front of the eye, not at depth {near}"
    );
    check_camera(camera);
    let within = within.clamped(camera.width, camera.height);
    if within.is_empty() {
        return ids.reshape_within(camera.width, camera.height, EMPTY);
    }
    // Only triangles that reach `within` are set up: a small rectangle costs
    // little more than projecting the scene's vertices.
    let triangles = setup::setup(scene, camera, near, within, keep);
    let triangles = bands::nearest_first(&triangles);
    resolve_into(scene, camera, &triangles, bands::Kept::All, within, ids);
}

/// Panics unless the camera's image fits the rasterizer.
fn check_camera(camera: &Camera) {
    assert!(
        camera.width <= MAX_DIMENSION && camera.height <= MAX_DIMENSION,
        "image {}x{} exceeds the rasterizer's limit of {MAX_DIMENSION} pixels per side",
        camera.width,
        camera.height
    );
}

/// Makes `ids` (whatever it holds) the ID buffer over `within` (inside the
/// image; its window) of the set-up `triangles` (nearest first,
/// `bands::nearest_first`) that are `kept`.
fn resolve_into(
    scene: &Scene,
    camera: &Camera,
    triangles: &[triangle::RasterTriangle],
    kept: bands::Kept<'_>,
    within: PixelRect,
    ids: &mut IdBuffer,
) {
    // The bands initialize the planes they fill.
    ids.reshape_within(camera.width, camera.height, within);
    bands::resolve_nearest_first(&scene.triangles, triangles, kept, ids);
}
