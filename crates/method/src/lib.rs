//! One interface for every reflection method the product offers: a method
//! turns a frame set-up and a reflector into that reflector's pixels.
//!
//! - [`FrameSetup`]: one frame's camera, lighting and settings.
//! - [`ReflectionMethod`]: the interface; [`MethodFrame`] is its input (the
//!   tracer with the scene's BVH, lighting and settings; the camera; the
//!   frame's ID buffer; the reflector's triangles), [`MethodOutput`] its
//!   result (a [`SparseBitmap`] over the reflector's pixels and counters).
//! - [`VertexTracing`]: adaptive progressive vertex tracing at any quality,
//!   the reference (every pixel ray traced) included.
//! - [`shade_reflector`]: the finishing step shared by the methods that find
//!   the reflected radiance their own way (cube maps, PVRR, the environment
//!   map): `colour = local + kr * reflected + kt * transmitted` at exactly the
//!   surface points the ray tracer shades, so error figures measure the
//!   method and nothing else.
//!
//! Architecture invariant: every method writes only the pixels the frame's ID
//! buffer gives to the reflector's triangles (pixel ownership), so methods and
//! packages composite in any order.

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;
use vtfarm_raster::IdBuffer;
use vtfarm_scene::{Camera, Lighting, NONE, ObjectId, Scene, TriangleId};
use vtfarm_trace::{SceneBvh, SurfacePoint, TraceSettings, Tracer};
use vtfarm_vertex::{
    Behind, Frame, GlassPass, PackageOptions, PackageStats, PixelValue, ShadowCache, SparseBitmap,
    Stop, VertexOwners, VertexSettings, pixel_surface, trace_package,
};

/// Everything that can change from one frame to the next: what a job
/// gives each of its frames, and what the farm sends in `FrameStart`.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameSetup {
    pub camera: Camera,
    pub lighting: Lighting,
    pub trace: TraceSettings,
    pub vertex: VertexSettings,
}

/// A frame as every method sees it.
#[derive(Clone, Copy, Debug)]
pub struct MethodFrame<'a> {
    /// The scene's BVH (and through it the scene), lighting and settings.
    pub tracer: Tracer<'a>,
    pub camera: Camera,
    /// The frame's ID buffer over the whole scene: a pixel belongs to the
    /// reflector when its triangle is one of `reflector`.
    pub ids: &'a IdBuffer,
    /// The reflector's triangles (one connected surface for cube maps/PVRR).
    pub reflector: &'a [TriangleId],
    /// The package's cancel flag and sample budget; `None` runs to the end.
    /// A method charges the rays it counts ([`MethodFrame::charge`]; those
    /// of [`shade_reflector`] are charged there), checks
    /// [`MethodFrame::stopped`] between its phases and per pixel, and when
    /// stopped returns what it has (the worker discards it).
    pub stop: Option<&'a Stop>,
}

/// Everything a [`MethodFrame`] borrows, owned: one view of a scene ready
/// for any number of methods (`vtfarm compare`, tests).
pub struct OwnedFrame {
    pub bvh: SceneBvh,
    pub camera: Camera,
    pub lighting: Lighting,
    pub trace: TraceSettings,
    pub ids: IdBuffer,
    pub reflector: Vec<TriangleId>,
}

impl OwnedFrame {
    /// Builds the scene's BVH and rasterizes the frame's ID buffer.
    pub fn new(
        scene: Arc<Scene>,
        camera: Camera,
        lighting: Lighting,
        trace: TraceSettings,
        reflector: Vec<TriangleId>,
    ) -> Self {
        let ids = vtfarm_raster::id_buffer(&scene, &camera);
        OwnedFrame {
            bvh: SceneBvh::new(scene),
            camera,
            lighting,
            trace,
            ids,
            reflector,
        }
    }

    /// The rasterized base frame the reflector pixels go over (shaded from
    /// the ID buffer already at hand: the same image `rasterize` gives).
    pub fn base_frame(&self) -> vtfarm_imaging::Image {
        vtfarm_raster::shade_ids(self.bvh.scene(), &self.camera, &self.lighting, &self.ids)
    }

    /// The view every method takes.
    pub fn frame(&self) -> MethodFrame<'_> {
        MethodFrame {
            tracer: Tracer {
                bvh: &self.bvh,
                lighting: &self.lighting,
                settings: self.trace,
                cone: vtfarm_trace::PixelCone::of(&self.camera),
            },
            camera: self.camera,
            ids: &self.ids,
            reflector: &self.reflector,
            stop: None,
        }
    }
}

#[cfg(any(test, feature = "cockpit-fixture"))]
impl OwnedFrame {
    /// The built-in cockpit at `detail`, seen by its driver camera at
    /// `width` × `height`, with the cover glass as the reflector and default
    /// trace settings: the shared fixture of the methods' tests.
    pub fn cockpit(detail: f32, width: u32, height: u32) -> OwnedFrame {
        let c = vtfarm_cockpit::cockpit(&vtfarm_cockpit::CockpitConfig {
            detail,
            ..Default::default()
        });
        let camera = Camera {
            width,
            height,
            ..c.camera
        };
        let reflector = c.cover_glass_triangles();
        OwnedFrame::new(
            Arc::new(c.scene),
            camera,
            c.lighting,
            TraceSettings::default(),
            reflector,
        )
    }
}

/// The methods' shared test of [`MethodFrame::stop`]: `method` charges
/// exactly the rays it counts (a budget of that many changes nothing, one
/// fewer stops it over budget), a budget of a tenth of them stops it having
/// counted less than half, and cancelled before it starts it leaves every
/// pixel black.
#[cfg(any(test, feature = "cockpit-fixture"))]
pub fn check_honours_stop(method: &dyn ReflectionMethod, frame: &MethodFrame<'_>) {
    use vtfarm_vertex::Stopped;
    let name = method.name();
    let render = |stop: &Stop| {
        method.render(&MethodFrame {
            stop: Some(stop),
            ..*frame
        })
    };
    let free = method.render(&MethodFrame {
        stop: None,
        ..*frame
    });
    let rays = free.counters.rays;
    assert!(rays >= 100, "{name}: {rays} rays are too few to test with");
    assert!(free.bitmap.color.iter().any(|c| *c != Vec3::ZERO), "{name}");

    let enough = Stop::with_budget(rays);
    assert_eq!(render(&enough).bitmap, free.bitmap, "{name}");
    assert_eq!(
        enough.stopped(),
        None,
        "{name}: charged more rays than it counted"
    );

    let short = Stop::with_budget(rays - 1);
    render(&short);
    assert_eq!(
        short.stopped(),
        Some(Stopped::OverBudget { budget: rays - 1 }),
        "{name}: charged fewer rays than it counted"
    );

    let tenth = Stop::with_budget(rays / 10);
    let stopped = render(&tenth);
    assert_eq!(
        tenth.stopped(),
        Some(Stopped::OverBudget { budget: rays / 10 })
    );
    assert!(
        stopped.counters.rays < rays / 2,
        "{name}: went on to {} of {rays} rays after its budget of {}",
        stopped.counters.rays,
        rays / 10
    );

    let cancelled = Stop::with_budget(u64::MAX);
    cancelled.cancel();
    let output = render(&cancelled);
    assert!(
        output.bitmap.color.iter().all(|c| *c == Vec3::ZERO),
        "{name}: a cancelled method shaded pixels"
    );
    assert!(
        output.counters.rays < rays / 2,
        "{name}: a cancelled method counted {} of {rays} rays",
        output.counters.rays
    );
}

/// One reflector pixel: the surface point the eye ray through its centre
/// hits, and that ray's unit direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReflectorPixel {
    pub x: u32,
    pub y: u32,
    pub point: SurfacePoint,
    pub incoming: Vec3,
}

/// What a method did, for `vtfarm compare`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MethodCounters {
    /// Rays cast (eye, secondary, shadow rays are not counted separately:
    /// one sample or one traced secondary ray counts one).
    pub rays: u64,
    /// Reflection-point searches (cube maps) or per-vertex reflection rays (PVRR).
    pub searches: u64,
    /// Reflector pixels written.
    pub pixels: u64,
    /// Per-reflector pre-processing (cube maps, reflection maps).
    pub setup_time: Duration,
    /// Everything, pre-processing included.
    pub time: Duration,
}

/// A method's result for one reflector in one frame.
#[derive(Clone, Debug, Default)]
pub struct MethodOutput {
    pub bitmap: SparseBitmap,
    pub counters: MethodCounters,
}

/// A reflection method. Implementations are deterministic: the same frame
/// gives the same bitmap whatever the thread count.
pub trait ReflectionMethod: Send + Sync {
    /// A short name for tables and file names (`full`, `cubemap-grid`, ...).
    fn name(&self) -> String;
    /// Renders the reflector's pixels.
    fn render(&self, frame: &MethodFrame<'_>) -> MethodOutput;
}

/// The methods a job can choose (`[quality] method` in a job file).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum MethodKind {
    /// Adaptive progressive vertex tracing at the job's quality level.
    #[default]
    VertexTracing,
    /// Reflector cube maps with a reflection-point search per vertex.
    CubeMap,
    /// The same with the interpolation grid.
    CubeMapGrid,
    /// Per-vertex reflection and refraction.
    Pvrr,
    /// One environment map from the reflector's centre (the baseline).
    EnvironmentMap,
}

impl MethodKind {
    pub const ALL: [MethodKind; 5] = [
        MethodKind::VertexTracing,
        MethodKind::CubeMap,
        MethodKind::CubeMapGrid,
        MethodKind::Pvrr,
        MethodKind::EnvironmentMap,
    ];

    pub fn name(self) -> &'static str {
        match self {
            MethodKind::VertexTracing => "vertex",
            MethodKind::CubeMap => "cubemap",
            MethodKind::CubeMapGrid => "cubemap-grid",
            MethodKind::Pvrr => "pvrr",
            MethodKind::EnvironmentMap => "envmap",
        }
    }

    pub fn from_name(name: &str) -> Option<MethodKind> {
        MethodKind::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Whether the method needs a whole reflector at a time (it
    /// pre-processes per reflector), so that the farm packs reflectors,
    /// not triangles; vertex tracing works per triangle.
    pub fn per_reflector(self) -> bool {
        self != MethodKind::VertexTracing
    }
}

/// The reflectors as per-reflector methods take them: the triangles of each
/// object, objects in ascending id, triangles in the order given. The master
/// and the workers both derive them from a frame's reflector list, so a
/// group index means the same on both sides.
pub fn reflector_groups(
    scene: &vtfarm_scene::Scene,
    triangles: &[TriangleId],
) -> Vec<Vec<TriangleId>> {
    let mut groups: std::collections::BTreeMap<ObjectId, Vec<TriangleId>> = Default::default();
    for &t in triangles {
        groups
            .entry(scene.triangles[t.index()].object)
            .or_default()
            .push(t);
    }
    groups.into_values().collect()
}

/// Puts the pixels of bitmaps that own disjoint pixels into one bitmap.
pub fn merge_bitmaps(frame_width: u32, bitmaps: &[SparseBitmap]) -> SparseBitmap {
    let pixels = bitmaps
        .iter()
        .flat_map(|b| {
            b.covered().map(move |(x, y, k)| PixelValue {
                index: y * frame_width + x,
                color: b.color[k],
                reflected: b.reflected[k],
                transmitted: b.transmitted[k],
                object: b.reflected_object[k],
            })
        })
        .collect();
    SparseBitmap::from_pixels(frame_width, pixels)
}

impl MethodFrame<'_> {
    /// Whether the package must stop: cancelled, or over its sample budget.
    pub fn stopped(&self) -> bool {
        self.stop.is_some_and(|s| s.stopped().is_some())
    }

    /// Counts `rays` traced rays against the package's sample budget.
    pub fn charge(&self, rays: u64) {
        if let Some(stop) = self.stop {
            stop.charge(rays);
        }
    }

    /// Whether each scene triangle is part of the reflector.
    pub fn reflector_flags(&self) -> Vec<bool> {
        let mut flags = vec![false; self.tracer.bvh.scene().triangles.len()];
        for &t in self.reflector {
            flags[t.index()] = true;
        }
        flags
    }

    /// The reflector's pixels in row-major order.
    pub fn pixels(&self) -> Vec<ReflectorPixel> {
        let flags = self.reflector_flags();
        let scene = self.tracer.bvh.scene();
        let (w, h) = (self.ids.width, self.ids.height);
        (0..h)
            .into_par_iter()
            .flat_map_iter(|y| {
                let flags = &flags;
                (0..w).filter_map(move |x| {
                    let triangle = TriangleId(self.ids.triangle_at(x, y));
                    let owned = flags.get(triangle.index()).copied().unwrap_or(false);
                    owned.then(|| {
                        let (point, incoming) =
                            pixel_surface(scene, &self.camera, self.ids, triangle, x, y);
                        ReflectorPixel {
                            x,
                            y,
                            point,
                            incoming,
                        }
                    })
                })
            })
            .collect()
    }

    /// The tracer for rays that leave the reflector: one level less deep,
    /// so a secondary ray traced here sees what it sees inside `shade`.
    pub fn secondary_tracer(&self) -> Tracer<'_> {
        Tracer {
            settings: TraceSettings {
                max_depth: self.tracer.settings.max_depth.max(1) - 1,
                ..self.tracer.settings
            },
            ..self.tracer
        }
    }
}

/// The reflected radiance a method found for one pixel (unweighted: the
/// radiance arriving along the mirror direction) and the object it shows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reflection {
    pub radiance: Vec3,
    /// The object's number ([`ObjectId::raw`]), `NONE` for none.
    pub object: u32,
}

impl Reflection {
    pub const NONE: Reflection = Reflection {
        radiance: Vec3::ZERO,
        object: NONE,
    };
}

/// Finishes reflector pixels from a method's reflections:
/// `local + kr * reflection + kt * transmitted`, with local Phong (shadow rays
/// included) and kr/kt exactly as the ray tracer has them. `transmitted` is
/// the radiance arriving along the refraction ray per pixel; `None` traces
/// those rays (for methods that handle reflection only), and then a back
/// surface's ghost image counts as reflected, as the ray tracer counts it.
/// A given radiance carries no ghost: PVRR's mapped refraction keeps it in
/// the transmitted part (the colour is the same either way). Returns the bitmap
/// and the number of rays traced for the transmission (already charged to
/// the frame's stop). Once the frame is stopped, the pixels left are black.
pub fn shade_reflector(
    frame: &MethodFrame<'_>,
    pixels: &[ReflectorPixel],
    reflections: &[Reflection],
    transmitted: Option<&[Vec3]>,
) -> (SparseBitmap, u64) {
    assert_eq!(pixels.len(), reflections.len());
    let secondary = frame.secondary_tracer();
    let values: Vec<(PixelValue, u64)> = pixels
        .par_iter()
        .enumerate()
        .map(|(i, pixel)| {
            let index = pixel.y * frame.ids.width + pixel.x;
            if frame.stopped() {
                // Left black: a stopped package's result is discarded.
                let black = PixelValue {
                    index,
                    color: Vec3::ZERO,
                    reflected: Vec3::ZERO,
                    transmitted: Vec3::ZERO,
                    object: NONE,
                };
                return (black, 0);
            }
            let terms = frame.tracer.surface_terms(&pixel.point, pixel.incoming);
            let reflection = reflections[i];
            let reflected = if terms.reflection.is_some() {
                terms.kr * reflection.radiance
            } else {
                Vec3::ZERO
            };
            let (through, ghost, rays) = match (transmitted, terms.refraction) {
                (_, None) => (Vec3::ZERO, Vec3::ZERO, 0),
                (Some(given), Some(_)) => (given[i], Vec3::ZERO, 0),
                (None, Some(ray)) => {
                    frame.charge(1);
                    let seen = secondary.trace_transmission(&ray);
                    (seen.radiance, seen.ghost, 1)
                }
            };
            let (through, ghost) = (terms.kt * through, terms.kt * ghost);
            let value = PixelValue {
                index,
                color: terms.local + reflected + through,
                // The ghost is reflected light (`vtfarm_trace::Sample`).
                reflected: reflected + ghost,
                transmitted: through - ghost,
                object: if terms.reflection.is_some() {
                    reflection.object
                } else {
                    NONE
                },
            };
            (value, rays)
        })
        .collect();
    let rays = values.iter().map(|(_, r)| r).sum();
    let bitmap = SparseBitmap::from_pixels(
        frame.ids.width,
        values.into_iter().map(|(v, _)| v).collect(),
    );
    (bitmap, rays)
}

/// Adaptive progressive vertex tracing (`crates/vertex`) as a method; the
/// reference quality traces every pixel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VertexTracing {
    pub settings: VertexSettings,
}

impl VertexTracing {
    /// The per-pixel reference: every reflector pixel traced, with default
    /// thresholds (they do not matter to it).
    pub fn reference() -> Self {
        VertexTracing {
            settings: VertexSettings {
                quality: vtfarm_vertex::Quality::Reference,
                ..VertexSettings::default()
            },
        }
    }
}

impl ReflectionMethod for VertexTracing {
    fn name(&self) -> String {
        self.settings.quality.name().to_owned()
    }

    fn render(&self, frame: &MethodFrame<'_>) -> MethodOutput {
        let start = Instant::now();
        let scene = frame.tracer.bvh.scene();
        let behind = Behind::new(
            &frame.tracer,
            &frame.camera,
            frame.ids,
            &frame.reflector_flags(),
            self.settings.transmission,
            GlassPass::Upfront,
            &ShadowCache::default(),
        );
        let owners = VertexOwners::new(scene);
        let vertex_frame = Frame {
            tracer: frame.tracer,
            camera: frame.camera,
            ids: frame.ids,
            behind: &behind,
            owners: &owners,
            settings: self.settings,
            stop: frame.stop,
        };
        let setup_time = start.elapsed();
        let result = trace_package(
            &vertex_frame,
            frame.reflector,
            &PackageOptions::default(),
            &mut |_| {},
        );
        let stats: PackageStats = result.stats;
        MethodOutput {
            counters: MethodCounters {
                rays: stats.samples(),
                searches: 0,
                pixels: stats.pixels,
                setup_time,
                time: start.elapsed(),
            },
            bitmap: result.bitmap,
        }
    }
}

#[cfg(test)]
mod tests;
