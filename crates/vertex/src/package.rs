//! A task package: a set of reflector triangles traced into a sparse bitmap.
//!
//! Phase 1 traces the package's distinct original vertices in one parallel
//! batch (the preview). Phase 2 refines each triangle on its own (in
//! parallel) and reports finished faces at time breaks. Phase 3 (module
//! `fill`) gives every pixel the ID buffer assigns to a triangle its colour:
//! Gouraud from the final face that contains the pixel centre, or a
//! per-pixel trace where the face's samples still disagree (triangle
//! filling) or no face reached it, written straight into planes: the
//! frame's ([`trace_package_into`]) or the package's bitmap.

use std::collections::HashMap;
use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;
use vtfarm_raster::{IdBuffer, PixelRect};
use vtfarm_scene::{Camera, NONE, Projector, ScreenPoint, TriangleId};
use vtfarm_trace::{Sample, Tracer};

use crate::fill::{Filled, Planes, TracedPixels, TrianglePlan, fill};
use crate::refine::{MeshVertex, TriangleMesh};
use crate::thin::SlabWeights;
use crate::{Frame, FrameImage, Quality, VertexOwners, VertexSettings, vertex_point, vertex_rays};

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
    /// The counters and times as (name, value) rows for a summary table.
    pub fn rows(&self) -> [(&'static str, String); 7] {
        let summed =
            |t: std::time::Duration| format!("{:.3} s (summed over packages)", t.as_secs_f64());
        [
            ("traced triangles", self.traced_triangles.to_string()),
            ("visible vertices", self.visible_vertices.to_string()),
            ("refined edges", self.refined_edges.to_string()),
            (
                "traced samples",
                format!(
                    "{} ({} vertices + {} filled pixels)",
                    self.samples(),
                    self.vertex_samples,
                    self.filled_pixels
                ),
            ),
            ("reflector pixels", self.pixels.to_string()),
            ("vertex tracing", summed(self.vertex_time)),
            ("triangle filling", summed(self.fill_time)),
        ]
    }

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

/// A covered pixel's colour, reflected and transmitted parts as float bits
/// and its reflected object: what byte-exact comparisons of bitmaps compare.
pub type PixelBits = ([u32; 3], [u32; 3], [u32; 3], u32);

impl SparseBitmap {
    /// Each covered pixel, (x, y), with its [`PixelBits`].
    pub fn pixel_bits(&self) -> impl Iterator<Item = ((u32, u32), PixelBits)> + '_ {
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        self.covered().map(move |(x, y, k)| {
            let value = (
                bits(self.color[k]),
                bits(self.reflected[k]),
                bits(self.transmitted[k]),
                self.reflected_object[k],
            );
            ((x, y), value)
        })
    }

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
            x >= ids.width
                || y >= ids.height
                || !TriangleId::from_raw(ids.triangle_at(x, y)).is_some_and(&owns)
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
    let mut dense = DensePlanes::default();
    let traced = run_package(frame, triangles, options, progress, &mut dense);
    traced.with(dense.bitmap(|_| true))
}

/// [`trace_package`] writing its pixels straight into a frame (one machine
/// rendering a whole frame; the farm's master composites the same values
/// from bitmaps).
pub fn trace_package_into(
    frame: &Frame<'_>,
    triangles: &[TriangleId],
    options: &PackageOptions,
    progress: &mut dyn FnMut(&[FinishedFace]),
    image: &mut FrameImage,
) -> TracedPackage {
    run_package(frame, triangles, options, progress, image)
}

/// What [`trace_package_into`] returns besides the pixels it wrote.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TracedPackage {
    pub stats: PackageStats,
    /// The final faces, when asked for.
    pub faces: Vec<FinishedFace>,
    /// As [`PackageResult::triangle_samples`].
    pub triangle_samples: Vec<u32>,
    pub times: PhaseTimes,
}

impl TracedPackage {
    /// The package's result with `bitmap` as its pixels.
    fn with(self, bitmap: SparseBitmap) -> PackageResult {
        PackageResult {
            bitmap,
            stats: self.stats,
            faces: self.faces,
            triangle_samples: self.triangle_samples,
        }
    }
}

/// Wall times of a package's phases on this machine: the breakdown of a
/// frame rendered in one process (`bench table1`). Not in [`PackageStats`],
/// which travels.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhaseTimes {
    /// Phases 1 and 2: tracing and refining the vertices (with the
    /// visibility tests and the mesh bookkeeping).
    pub vertices: Duration,
    /// Tracing the pixels that get a sample of their own (triangle filling,
    /// pixels no face reaches, every pixel at `reference`).
    pub pixel_tracing: Duration,
    /// Everything else of phase 3: which face covers each pixel, the
    /// interpolation and the writing of every value into the planes.
    pub interpolation: Duration,
}

impl PhaseTimes {
    pub fn add(&mut self, o: &PhaseTimes) {
        self.vertices += o.vertices;
        self.pixel_tracing += o.pixel_tracing;
        self.interpolation += o.interpolation;
    }
}

/// Where a package's pixels go: planes covering at least `rect`.
trait Target {
    fn planes(&mut self, rect: PixelRect) -> Planes<'_>;
}

impl Target for FrameImage {
    fn planes(&mut self, rect: PixelRect) -> Planes<'_> {
        self.row_planes(rect.y0, rect.y1)
    }
}

/// A package's own planes over its rectangle, packed into its bitmap at the end.
#[derive(Default)]
struct DensePlanes {
    rect: Option<PixelRect>,
    color: Vec<Vec3>,
    reflected: Vec<Vec3>,
    transmitted: Vec<Vec3>,
    object: Vec<u32>,
    mask: Vec<bool>,
}

impl Target for DensePlanes {
    fn planes(&mut self, rect: PixelRect) -> Planes<'_> {
        let n = ((rect.x1 - rect.x0) * (rect.y1 - rect.y0)) as usize;
        *self = DensePlanes {
            rect: Some(rect),
            color: vec![Vec3::ZERO; n],
            reflected: vec![Vec3::ZERO; n],
            transmitted: vec![Vec3::ZERO; n],
            object: vec![NONE; n],
            mask: vec![false; n],
        };
        let stride = (rect.x1 - rect.x0) as usize;
        Planes {
            x0: rect.x0,
            y0: rect.y0,
            stride,
            color_x0: rect.x0,
            color_stride: stride,
            color: &mut self.color,
            reflected: &mut self.reflected,
            transmitted: &mut self.transmitted,
            object: &mut self.object,
            mask: &mut self.mask,
        }
    }
}

impl DensePlanes {
    /// Whether pixel `i` was written here and differs from `last`'s (the
    /// same rectangle: a package's stages): written there, or not in
    /// every bit of colour, components and object.
    fn differs(&self, last: &DensePlanes, i: usize) -> bool {
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        last.rect != self.rect
            || !last.mask[i]
            || bits(last.color[i]) != bits(self.color[i])
            || bits(last.reflected[i]) != bits(self.reflected[i])
            || bits(last.transmitted[i]) != bits(self.transmitted[i])
            || last.object[i] != self.object[i]
    }

    /// The written pixels `keep` accepts (by index into the planes) as a
    /// bitmap over their bounding rectangle.
    fn bitmap(&self, keep: impl Fn(usize) -> bool) -> SparseBitmap {
        let Some(rect) = self.rect else {
            return SparseBitmap::default();
        };
        let mask: Vec<bool> = (0..self.mask.len())
            .map(|i| self.mask[i] && keep(i))
            .collect();
        let stride = (rect.x1 - rect.x0) as usize;
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for (i, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
            let (x, y) = (i % stride, i / stride);
            x0 = x0.min(x);
            y0 = y0.min(y);
            x1 = x1.max(x + 1);
            y1 = y1.max(y + 1);
        }
        if x0 > x1 {
            return SparseBitmap::default();
        }
        // Sized up front: planes grown by pushing copy themselves into
        // fresh pages at every doubling.
        let kept = mask.iter().filter(|&&m| m).count();
        let mut bitmap = SparseBitmap {
            x0: rect.x0 + x0 as u32,
            y0: rect.y0 + y0 as u32,
            width: (x1 - x0) as u32,
            height: (y1 - y0) as u32,
            mask: Vec::with_capacity((x1 - x0) * (y1 - y0)),
            color: Vec::with_capacity(kept),
            reflected: Vec::with_capacity(kept),
            transmitted: Vec::with_capacity(kept),
            reflected_object: Vec::with_capacity(kept),
        };
        for y in y0..y1 {
            let row = y * stride + x0..y * stride + x1;
            for (i, &kept) in row.clone().zip(&mask[row]) {
                bitmap.mask.push(kept);
                if kept {
                    bitmap.color.push(self.color[i]);
                    bitmap.reflected.push(self.reflected[i]);
                    bitmap.transmitted.push(self.transmitted[i]);
                    bitmap.reflected_object.push(self.object[i]);
                }
            }
        }
        bitmap
    }
}

/// A package traced stage by stage on the same vertices and edges, as the
/// paper's `Refine()` goes on after `TimeToBreak`: set up once
/// ([`ProgressivePackage::new`]: which triangles own pixels, and where),
/// then advanced `Preview` → `Refine` → `Full`, each stage continuing the
/// meshes the last one left (the corners are traced at the first stage,
/// each split's vertex once, in the pass that splits it; a pixel traced one
/// by one, once, whichever stages need it) and writing every pixel its
/// triangles own. A stage gives exactly the pixels of the
/// package traced from scratch at its quality, because that is this type
/// too, advanced once ([`trace_package`]); stages may be skipped
/// (`Preview` → `Full`), and `Reference` (every pixel traced) may follow any.
pub struct ProgressivePackage {
    triangles: Vec<TriangleId>,
    owned: Vec<(TriangleId, PixelRect)>,
    /// One per owned triangle once the corners are traced.
    meshes: Vec<TriangleMesh>,
    stage: Option<Quality>,
    /// The pixels the last stage left (bitmap stages only), so the next
    /// stage's bitmap holds only what changed.
    pixels: Option<DensePlanes>,
    /// The pixels earlier stages traced one by one, so none is traced
    /// twice; `None` for a package of one stage ([`trace_package`]).
    traced_pixels: Option<TracedPixels>,
    stopped: bool,
}

/// Why a [`ProgressivePackage`] cannot take a stage.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
pub enum StageError {
    #[error(
        "a package at {from:?} cannot go to {to:?}: stages go preview, refine, full, and reference after any"
    )]
    NotLater { from: Quality, to: Quality },
    #[error("the package was stopped in an earlier stage: its meshes are incomplete")]
    Stopped,
}

impl ProgressivePackage {
    /// The package's set-up: the triangles that own pixels (the others cost
    /// nothing at any stage) and the rectangles that hold their pixels.
    pub fn new(frame: &Frame<'_>, triangles: &[TriangleId]) -> Self {
        ProgressivePackage {
            triangles: triangles.to_vec(),
            owned: (triangles.iter())
                .filter_map(|&t| frame.owned_rect(t).map(|r| (t, r)))
                .collect(),
            meshes: Vec::new(),
            stage: None,
            pixels: None,
            traced_pixels: Some(TracedPixels::new()),
            stopped: false,
        }
    }

    /// The last stage run to its end (`None` before the first).
    pub fn stage(&self) -> Option<Quality> {
        self.stage
    }

    /// Runs stage `quality` (later than [`ProgressivePackage::stage`]) on
    /// `frame` (the one the package was set up on; its
    /// `settings.quality` is ignored) and returns the package's pixels that
    /// changed since the last stage, every owned pixel at the first, as a
    /// bitmap: composited in order over the base frame, the stages' bitmaps
    /// give each stage's image. The counters are this stage's work
    /// ([`TracedPackage::stats`]).
    pub fn advance(
        &mut self,
        frame: &Frame<'_>,
        quality: Quality,
        options: &PackageOptions,
        progress: &mut dyn FnMut(&[FinishedFace]),
    ) -> Result<PackageResult, StageError> {
        let mut planes = DensePlanes::default();
        let traced = self.run(frame, quality, options, progress, Some(&mut planes))?;
        let bitmap = match &self.pixels {
            Some(last) => planes.bitmap(|i| planes.differs(last, i)),
            None => planes.bitmap(|_| true),
        };
        self.pixels = Some(planes);
        Ok(traced.with(bitmap))
    }

    /// Runs stage `quality` as [`ProgressivePackage::advance`] does, on the
    /// vertices only: the meshes refined to `quality`
    /// ([`ProgressivePackage::meshes`]) and no pixel filled or written, so
    /// its bitmap is empty and the next stage's bitmap holds every owned
    /// pixel. What a view draws from the meshes needs no more.
    pub fn advance_meshes(
        &mut self,
        frame: &Frame<'_>,
        quality: Quality,
        options: &PackageOptions,
        progress: &mut dyn FnMut(&[FinishedFace]),
    ) -> Result<PackageResult, StageError> {
        let traced = self.run(frame, quality, options, progress, None)?;
        self.pixels = None;
        Ok(traced.with(SparseBitmap::default()))
    }

    /// [`ProgressivePackage::advance`] writing the stage's pixels straight
    /// into `image` (every owned pixel, over the last stage's).
    pub fn advance_into(
        &mut self,
        frame: &Frame<'_>,
        quality: Quality,
        options: &PackageOptions,
        progress: &mut dyn FnMut(&[FinishedFace]),
        image: &mut FrameImage,
    ) -> Result<TracedPackage, StageError> {
        self.run(frame, quality, options, progress, Some(image))
    }

    /// One stage's three phases, its pixels written into `target` (without
    /// one, the vertex phases only).
    fn run(
        &mut self,
        frame: &Frame<'_>,
        quality: Quality,
        options: &PackageOptions,
        progress: &mut dyn FnMut(&[FinishedFace]),
        target: Option<&mut dyn Target>,
    ) -> Result<TracedPackage, StageError> {
        if self.stopped {
            return Err(StageError::Stopped);
        }
        if let Some(from) = self.stage.filter(|&from| quality <= from) {
            return Err(StageError::NotLater { from, to: quality });
        }
        let frame = &Frame {
            settings: VertexSettings {
                quality,
                ..frame.settings
            },
            ..*frame
        };
        let owned = &self.owned;
        let mut stats = PackageStats {
            triangles: self.triangles.len() as u64,
            traced_triangles: owned.len() as u64,
            ..Default::default()
        };
        let mut times = PhaseTimes::default();

        // Per owned triangle, the vertex samples this stage traces.
        let mut new_samples = vec![0; owned.len()];
        let vertex_start = Instant::now();
        let refined = quality != Quality::Reference;
        if refined {
            if self.meshes.len() != owned.len() {
                self.meshes = trace_corners(frame, owned, &mut stats);
                new_samples.fill(3);
            }
            let before: Vec<u64> = self.meshes.iter().map(|m| m.refined_edges).collect();
            refine_all(frame, &mut self.meshes, quality, options, progress);
            for ((m, before), new) in self.meshes.iter().zip(before).zip(&mut new_samples) {
                stats.refined_edges += m.refined_edges - before;
                *new += m.refined_edges - before;
                stats.visible_vertices += m.vertices.iter().filter(|v| v.visible).count() as u64;
                stats.faces += m.faces().count() as u64;
            }
            stats.vertex_samples += stats.refined_edges;
        }
        stats.vertex_time = vertex_start.elapsed();
        times.vertices = stats.vertex_time;

        let fill_start = Instant::now();
        let meshes = &self.meshes;
        let rect = owned.iter().map(|&(_, r)| r).reduce(|a, b| PixelRect {
            x0: a.x0.min(b.x0),
            y0: a.y0.min(b.y0),
            x1: a.x1.max(b.x1),
            y1: a.y1.max(b.y1),
        });
        let (filled, planning) = match (target, rect) {
            (Some(target), Some(rect)) => {
                let plans: Vec<TrianglePlan> = owned
                    .par_iter()
                    .enumerate()
                    .map(|(k, &(t, rect))| {
                        TrianglePlan::new(frame, t, rect, meshes.get(k).filter(|_| refined))
                    })
                    .collect();
                let planning = fill_start.elapsed();
                let planes = &mut target.planes(rect);
                let filled = fill(frame, &plans, planes, self.traced_pixels.as_mut());
                (filled, planning)
            }
            _ => (Filled::default(), Duration::ZERO),
        };
        stats.fill_time = fill_start.elapsed();
        times.pixel_tracing = filled.tracing;
        times.interpolation = planning + filled.interpolation;
        stats.filled_pixels = filled.traced.iter().sum();
        stats.pixels = filled.written;
        let mut triangle_samples = vec![0; self.triangles.len()];
        let mut next_owned = 0;
        for (slot, &t) in triangle_samples.iter_mut().zip(&self.triangles) {
            if owned.get(next_owned).is_some_and(|&(o, _)| o == t) {
                let traced = filled.traced.get(next_owned).copied().unwrap_or(0);
                *slot = (new_samples[next_owned] + traced) as u32;
                next_owned += 1;
            }
        }

        let faces = if options.collect_faces && refined {
            meshes.iter().flat_map(finished_faces).collect()
        } else {
            Vec::new()
        };
        if frame.stopped() {
            self.stopped = true;
        } else {
            self.stage = Some(quality);
        }
        Ok(TracedPackage {
            stats,
            faces,
            triangle_samples,
            times,
        })
    }
}

impl ProgressivePackage {
    /// The refined meshes as the last stage left them, one per owned
    /// triangle in package order (empty before the first stage, and after
    /// a `Reference` stage only the meshes the stages before it made):
    /// what the dashboard's view draws Gouraud-shaded over the scene it
    /// draws itself, with each vertex's [`SlabWeights`] in `frame`. Faces
    /// with a corner behind the eye are left out, as in [`FinishedFace`]s.
    pub fn meshes(&self, frame: &Frame<'_>) -> Vec<StageMesh> {
        self.meshes
            .iter()
            .map(|m| StageMesh::of(frame, m))
            .collect()
    }
}

/// One reflector triangle's refinement mesh after a stage: its vertices
/// (world positions with their traced samples) and its live faces.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StageMesh {
    /// The original reflector triangle the mesh refines.
    pub triangle: TriangleId,
    pub positions: Vec<Vec3>,
    /// Per vertex, the traced sample as a pixel would hold it (`index` 0).
    pub samples: Vec<PixelValue>,
    /// Per vertex, what the glass lets through of the scene behind it and
    /// adds to its reflection, for a drawing that blends the samples over
    /// that scene as [`Behind`](crate::Behind) does per pixel.
    pub slabs: Vec<SlabWeights>,
    /// Indices into `positions`, winding as the original triangle's.
    pub faces: Vec<[u32; 3]>,
}

impl StageMesh {
    fn of(frame: &Frame<'_>, mesh: &TriangleMesh) -> StageMesh {
        let scene = frame.tracer.bvh.scene();
        let corners = scene.triangles[mesh.triangle.index()].vertices;
        let projected = |f: &&crate::refine::Face| {
            (f.vertices.iter()).all(|&v| mesh.vertices[v as usize].screen.is_some())
        };
        StageMesh {
            triangle: mesh.triangle,
            positions: mesh.vertices.iter().map(|v| v.position).collect(),
            samples: (mesh.vertices.iter())
                .map(|v| PixelValue::from_sample(0, &v.sample))
                .collect(),
            slabs: (mesh.vertices.iter().enumerate())
                .map(|(k, v)| {
                    // A corner is its owner's point, as it was traced.
                    let on = corners
                        .get(k)
                        .map_or(mesh.triangle, |&c| frame.owners.of(c));
                    slab_weights(frame, on, v.position, v.normal)
                })
                .collect(),
            faces: mesh.faces().filter(projected).map(|f| f.vertices).collect(),
        }
    }
}

/// The [`SlabWeights`] at a mesh vertex traced as a point of `triangle`.
fn slab_weights(
    frame: &Frame<'_>,
    triangle: TriangleId,
    position: Vec3,
    normal: Vec3,
) -> SlabWeights {
    let eye = frame.camera.eye;
    let (point, _) = vertex_point(eye, triangle, position, normal);
    SlabWeights::at_point(&frame.tracer, eye, &point, frame.settings.transmission)
}

/// The `preview` meshes of `triangles` before any frame is set up: each
/// triangle's corners traced from `camera`'s eye the way a package traces
/// them (a shared corner as its owner's point, the same rays), hidden or
/// not, with the triangle's face when every corner lies in front of the
/// eye. A package's `preview` stage keeps the meshes of the triangles that
/// own pixels: those are among these, bit for bit. Whoever draws them
/// hides the rest with a depth test. In `triangles`' order.
pub fn corner_meshes(
    tracer: Tracer<'_>,
    camera: &Camera,
    settings: &VertexSettings,
    owners: &VertexOwners,
    triangles: &[TriangleId],
) -> Vec<StageMesh> {
    let scene = tracer.bvh.scene();
    let mut corner_index = HashMap::new();
    let mut corners = Vec::new();
    let corner_slots: Vec<[usize; 3]> = (triangles.iter())
        .map(|&t| {
            scene.triangles[t.index()].vertices.map(|v| {
                *corner_index.entry(v).or_insert_with(|| {
                    corners.push((owners.of(v), v));
                    corners.len() - 1
                })
            })
        })
        .collect();
    let rays = vertex_rays(settings.transmission);
    let traced: Vec<(Sample, SlabWeights)> = corners
        .par_chunks(VERTEX_BATCH)
        .flat_map_iter(|chunk| {
            let points: Vec<_> = (chunk.iter())
                .map(|&(t, v)| {
                    let v = v as usize;
                    vertex_point(camera.eye, t, scene.positions[v], scene.normals[v])
                })
                .collect();
            let slabs: Vec<SlabWeights> = (points.iter())
                .map(|(point, _)| {
                    SlabWeights::at_point(&tracer, camera.eye, point, settings.transmission)
                })
                .collect();
            tracer.shade_points(&points, rays).into_iter().zip(slabs)
        })
        .collect();
    let projector = Projector::new(camera);
    (triangles.iter().zip(&corner_slots))
        .map(|(&t, slots)| {
            let positions: Vec<Vec3> = (scene.triangles[t.index()].vertices.iter())
                .map(|&v| scene.positions[v as usize])
                .collect();
            let in_front = positions.iter().all(|&p| projector.project(p).is_some());
            StageMesh {
                triangle: t,
                samples: slots
                    .map(|k| PixelValue::from_sample(0, &traced[k].0))
                    .to_vec(),
                slabs: slots.map(|k| traced[k].1).to_vec(),
                positions,
                faces: if in_front {
                    vec![[0, 1, 2]]
                } else {
                    Vec::new()
                },
            }
        })
        .collect()
}

/// A package from scratch: one stage of a [`ProgressivePackage`].
fn run_package(
    frame: &Frame<'_>,
    triangles: &[TriangleId],
    options: &PackageOptions,
    progress: &mut dyn FnMut(&[FinishedFace]),
    target: &mut dyn Target,
) -> TracedPackage {
    let mut package = ProgressivePackage {
        traced_pixels: None,
        ..ProgressivePackage::new(frame, triangles)
    };
    package
        .run(
            frame,
            frame.settings.quality,
            options,
            progress,
            Some(target),
        )
        .expect("a new package takes any stage")
}

/// Phase 1: traces the distinct original vertices of the owned triangles
/// once (neighbours share corners) and makes each triangle's unrefined mesh.
fn trace_corners(
    frame: &Frame<'_>,
    owned: &[(TriangleId, PixelRect)],
    stats: &mut PackageStats,
) -> Vec<TriangleMesh> {
    let scene = frame.tracer.bvh.scene();
    // Neighbouring triangles share corners: trace each once, on its owner.
    let mut corner_index = HashMap::new();
    let mut corners = Vec::new();
    let corner_slots: Vec<[usize; 3]> = owned
        .iter()
        .map(|&(t, _)| {
            scene.triangles[t.index()].vertices.map(|v| {
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
    owned
        .iter()
        .zip(&corner_slots)
        .map(|(&(t, _), slots)| {
            let tri = scene.triangles[t.index()];
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
        .collect()
}

/// Phase 2: refines each triangle's mesh on to `quality` (in parallel),
/// reporting finished faces at time breaks.
fn refine_all(
    frame: &Frame<'_>,
    meshes: &mut [TriangleMesh],
    quality: Quality,
    options: &PackageOptions,
    progress: &mut dyn FnMut(&[FinishedFace]),
) {
    let projector = frame.projector();
    if let Some(every) = options.time_break {
        progress(&meshes.iter().flat_map(finished_faces).collect::<Vec<_>>());
        let mut last_break = Instant::now();
        let mut pending = Vec::new();
        // Chunks keep the time breaks frequent while each chunk stays parallel.
        let chunk = (rayon::current_num_threads() * 8).max(1);
        for part in meshes.chunks_mut(chunk) {
            part.par_iter_mut()
                .for_each(|m| m.refine_to(frame, &projector, quality));
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
            .for_each(|m| m.refine_to(frame, &projector, quality));
    }
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
                let i = ids
                    .slot(x, y)
                    .expect("a whole-frame buffer holds every pixel");
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
        assert_eq!(
            left_column.foreign_pixel(&ids, |t| t == TriangleId(7)),
            None
        );
        assert_eq!(
            left_column.foreign_pixel(&ids, |t| t == TriangleId(8)),
            Some((0, 0))
        );
        // Uncovered pixels of the rectangle do not count; (1, 1) is 8's.
        let corner = bitmap(0, 0, 2, 2, &[true, false, true, true]);
        assert_eq!(
            corner.foreign_pixel(&ids, |t| t == TriangleId(7)),
            Some((1, 1))
        );
        assert_eq!(
            corner.foreign_pixel(&ids, |t| t == TriangleId(7) || t == TriangleId(8)),
            None
        );
        // A pixel outside the frame is never owned.
        let outside = bitmap(3, 0, 1, 1, &[true]);
        assert_eq!(outside.foreign_pixel(&ids, |_| true), Some((3, 0)));
    }
}
