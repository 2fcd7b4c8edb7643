//! One level of the recursion (paper §4.4): a tracer whose depth says how many
//! bounces are left, the shading of surfaces seen in a map, and the counters
//! every level adds to.
//!
//! A map texel that shows a specular object is that object seen from the
//! virtual viewpoint, so it is finished like a reflector pixel: local Phong
//! plus kr times that object's own PVRR reflection (a nested map, one level
//! down) plus kt times its traced transmission. Recursion ends where the
//! Whitted tracer's does, at `max_depth`.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};

use glam::Vec3;
use rayon::prelude::*;
use vtfarm_method::MethodFrame;
use vtfarm_scene::{ObjectId, TriangleId};
use vtfarm_trace::{SurfacePoint, TraceSettings, Tracer};
use vtfarm_vertex::Stop;

use crate::PvrrConfig;
use crate::warp::{Kind, Warp};

/// What a frame's levels share.
pub(crate) struct Context<'a> {
    pub(crate) config: &'a PvrrConfig,
    /// The triangles of every specular object, for multiple reflection.
    specular: BTreeMap<ObjectId, Vec<TriangleId>>,
    /// The package's stop: every counted ray is charged to it.
    stop: Option<&'a Stop>,
    searches: AtomicU64,
    rays: AtomicU64,
    texels: AtomicU64,
    fallbacks: AtomicU64,
}

impl<'a> Context<'a> {
    pub(crate) fn new(config: &'a PvrrConfig, frame: &MethodFrame<'a>) -> Self {
        let scene = frame.tracer.bvh.scene();
        let mut specular: BTreeMap<ObjectId, Vec<TriangleId>> = BTreeMap::new();
        for (id, triangle) in scene.triangle_ids().zip(&scene.triangles) {
            if scene.materials[triangle.material.index()].is_specular() {
                specular.entry(triangle.object).or_default().push(id);
            }
        }
        Context {
            config,
            specular,
            stop: frame.stop,
            searches: AtomicU64::new(0),
            rays: AtomicU64::new(0),
            texels: AtomicU64::new(0),
            fallbacks: AtomicU64::new(0),
        }
    }

    /// The counts so far (sums, so independent of the thread count).
    pub(crate) fn counts(&self) -> Counts {
        Counts {
            searches: self.searches.load(Ordering::Relaxed),
            rays: self.rays.load(Ordering::Relaxed),
            texels: self.texels.load(Ordering::Relaxed),
            fallbacks: self.fallbacks.load(Ordering::Relaxed),
        }
    }
}

/// What a frame's levels did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Counts {
    /// Per-vertex exit-ray searches (rays too).
    pub(crate) searches: u64,
    /// All rays: searches, occlusion tests, fallbacks, transmission rays of
    /// specular surfaces seen in maps, the shared finishing step's rays.
    pub(crate) rays: u64,
    /// Map texels rasterized and shaded (not rays).
    pub(crate) texels: u64,
    /// Lookups traced because a corner had no texture coordinate.
    pub(crate) fallbacks: u64,
}

/// A surface seen along a ray (a map texel's visible point).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Seen {
    pub(crate) point: SurfacePoint,
    pub(crate) incoming: Vec3,
    pub(crate) object: ObjectId,
}

/// A recursion level: `tracer` shades its reflectors at depth 1.
#[derive(Clone, Copy)]
pub(crate) struct Level<'a> {
    pub(crate) context: &'a Context<'a>,
    pub(crate) tracer: Tracer<'a>,
}

impl<'a> Level<'a> {
    /// The level `bounces` surfaces further along a ray.
    pub(crate) fn deeper(&self, bounces: u32) -> Level<'a> {
        Level {
            context: self.context,
            tracer: Tracer {
                settings: TraceSettings {
                    max_depth: self.tracer.settings.max_depth.saturating_sub(bounces),
                    ..self.tracer.settings
                },
                ..self.tracer
            },
        }
    }

    /// Whether surfaces at this level still spawn secondary rays.
    pub(crate) fn recurses(&self) -> bool {
        self.tracer.settings.max_depth > 1
    }

    pub(crate) fn count_searches(&self, n: u64) {
        self.context.searches.fetch_add(n, Ordering::Relaxed);
        self.count_rays(n);
    }

    pub(crate) fn count_fallback(&self) {
        self.context.fallbacks.fetch_add(1, Ordering::Relaxed);
    }

    pub(crate) fn count_texels(&self, n: u64) {
        self.context.texels.fetch_add(n, Ordering::Relaxed);
    }

    pub(crate) fn count_rays(&self, n: u64) {
        self.count_charged_rays(n);
        if let Some(stop) = self.context.stop {
            stop.charge(n);
        }
    }

    /// Counts rays already charged to the stop (the shared finishing step's).
    pub(crate) fn count_charged_rays(&self, n: u64) {
        self.context.rays.fetch_add(n, Ordering::Relaxed);
    }

    /// Whether the package must stop (cancelled or over its budget): the
    /// loops then skip their work, and the result is discarded.
    pub(crate) fn stopped(&self) -> bool {
        self.context.stop.is_some_and(|s| s.stopped().is_some())
    }

    /// The radiance leaving each seen surface towards `eye` (the background
    /// where nothing is seen).
    pub(crate) fn shade_seen(&self, eye: Vec3, seen: &[Option<Seen>]) -> Vec<Vec3> {
        let background = self.tracer.lighting.background;
        let mut radiance: Vec<Vec3> = seen
            .par_iter()
            .map(|s| match s {
                _ if self.stopped() => Vec3::ZERO,
                Some(s) if !self.is_nested(s.object) => {
                    self.tracer.surface_terms(&s.point, s.incoming).local
                }
                Some(_) => Vec3::ZERO,
                None => background,
            })
            .collect();
        let mut nested: BTreeMap<ObjectId, Vec<usize>> = BTreeMap::new();
        for (i, s) in seen.iter().enumerate() {
            if let Some(s) = s.filter(|s| self.is_nested(s.object)) {
                nested.entry(s.object).or_default().push(i);
            }
        }
        for (object, indices) in nested {
            let points: Vec<Seen> = indices.iter().filter_map(|&i| seen[i]).collect();
            let colors = self.shade_specular(eye, &self.context.specular[&object], &points);
            for (i, c) in indices.into_iter().zip(colors) {
                radiance[i] = c;
            }
        }
        radiance
    }

    fn is_nested(&self, object: ObjectId) -> bool {
        self.recurses() && self.context.specular.contains_key(&object)
    }

    /// Specular surfaces of one object seen from `eye`: local + kr * their
    /// PVRR reflection + kt * their traced transmission.
    fn shade_specular(&self, eye: Vec3, triangles: &[TriangleId], points: &[Seen]) -> Vec<Vec3> {
        if self.stopped() {
            return vec![Vec3::ZERO; points.len()];
        }
        let warp = Warp::build(self, eye, triangles, Kind::Reflection);
        let secondary = self.deeper(1).tracer;
        points
            .par_iter()
            .map(|s| {
                let terms = self.tracer.surface_terms(&s.point, s.incoming);
                let mut color = terms.local;
                if terms.reflection.is_some() {
                    color += terms.kr * warp.radiance_at(&s.point, s.incoming).radiance;
                }
                if let Some(ray) = terms.refraction {
                    color += terms.kt * secondary.trace(&ray).color;
                    self.count_rays(1);
                }
                color
            })
            .collect()
    }
}
