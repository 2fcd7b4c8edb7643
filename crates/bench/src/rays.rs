//! `vtfarm bench rays`: closest-hit throughput on three fixed, reproducible
//! ray sets, so that the tracer can be compared with another one (Embree) on
//! exactly the same rays. docs/benchmarks.md ("Ray throughput") documents the sets.
//!
//! - primary: the camera's rays through the pixel centres (x + 0.5, y + 0.5),
//!   row 0 (top) first, x ascending within a row;
//! - incoherent: `--random-rays` rays from [`RayGenerator`]: origins uniform
//!   in the scene's bounding box, directions uniform on the unit sphere;
//! - reflection: for each primary ray (same order) whose closest hit lies on
//!   the reflector, the mirror ray about the shading normal (turned to face
//!   the eye), leaving the surface by [`SceneBvh::spawn_ray`].
//!
//! Only the queries are timed (ray generation and BVH build are not); each
//! set's figure is the best of [`ROUNDS`] passes.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use crate::support::{CpuClock, cpu_time};
use anyhow::{Context, Result, bail};
use glam::Vec3;
use rayon::prelude::*;
use serde::Serialize;
use vtfarm_cockpit::{COVER_GLASS, CockpitConfig, cockpit};
use vtfarm_scene::{Camera, Scene};
use vtfarm_trace::{BuildPreset, BvhLayout, BvhOptions, Ray, SceneBvh, reflect};

#[derive(clap::Args)]
pub struct RaysArgs {
    /// An OBJ file, or `cockpit` for the built-in cockpit (default detail).
    scene: String,
    /// Camera position (default for `cockpit`: the driver's eye).
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true)]
    eye: Option<Vec<f32>>,
    /// The point the camera looks at.
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true)]
    target: Option<Vec<f32>>,
    /// Camera up vector.
    #[arg(long, num_args = 3, value_names = ["X", "Y", "Z"], allow_negative_numbers = true)]
    up: Option<Vec<f32>>,
    /// Vertical field of view in degrees.
    #[arg(long)]
    fov: Option<f32>,
    #[arg(long, default_value_t = 1920)]
    width: u32,
    #[arg(long, default_value_t = 1080)]
    height: u32,
    /// Number of incoherent rays.
    #[arg(long, default_value_t = 2_000_000)]
    random_rays: usize,
    /// Seed of the incoherent-ray generator.
    #[arg(long, default_value_t = RayGenerator::DEFAULT_SEED)]
    seed: u64,
    /// The reflector object whose reflection rays are traced.
    #[arg(long, default_value = COVER_GLASS)]
    reflector: String,
    /// Worker threads (default: 1: rays per second on one thread, as docs/benchmarks.md compares them).
    #[arg(long, default_value_t = 1)]
    threads: usize,
    /// BVH build preset: fastest, very-fast, fast, medium, slow, very-slow
    /// (default: the tracer's default).
    #[arg(long, value_parser = parse_preset)]
    preset: Option<BuildPreset>,
    /// BVH layout: cw (8-wide), cw-octant (same tree, obvhs' traversal) or binary (default: the tracer's default).
    #[arg(long, value_parser = parse_layout)]
    layout: Option<BvhLayout>,
    /// Also measures this layout (same preset) in the same run, rounds
    /// interleaved, and prints the ratio: e.g. `cw-octant`, obvhs' own traversal.
    #[arg(long, value_parser = parse_layout)]
    baseline: Option<BvhLayout>,
    /// Also writes the figures as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Writes the scene's triangles and the three ray sets as float32 `.npy`
    /// files into this directory (`scripts/embree_rays.py` traces them).
    #[arg(long, value_name = "DIR")]
    dump_rays: Option<PathBuf>,
}

/// A `--preset` or `--layout` value that names none of the choices.
#[derive(Debug, thiserror::Error)]
#[error("unknown {what} '{given}' ({choices})")]
struct UnknownChoice {
    what: &'static str,
    given: String,
    choices: String,
}

fn parse_preset(s: &str) -> Result<BuildPreset, UnknownChoice> {
    BuildPreset::ALL
        .into_iter()
        .find(|p| p.name() == s)
        .ok_or_else(|| {
            let names: Vec<_> = BuildPreset::ALL.iter().map(|p| p.name()).collect();
            UnknownChoice {
                what: "preset",
                given: s.to_owned(),
                choices: names.join(", "),
            }
        })
}

fn parse_layout(s: &str) -> Result<BvhLayout, UnknownChoice> {
    match s {
        "cw" => Ok(BvhLayout::Cw),
        "cw-octant" => Ok(BvhLayout::CwOctant),
        "binary" => Ok(BvhLayout::Binary),
        _ => Err(UnknownChoice {
            what: "layout",
            given: s.to_owned(),
            choices: "cw, cw-octant, binary".to_owned(),
        }),
    }
}

#[derive(Serialize)]
struct RaysFigures {
    triangles: usize,
    threads: usize,
    bvh_build_seconds: f64,
    primary_rays: usize,
    primary_rays_per_second: f64,
    incoherent_rays: usize,
    incoherent_rays_per_second: f64,
    reflection_rays: usize,
    reflection_rays_per_second: f64,
    /// The coherent sets again through `closest_hits` (packets).
    primary_packet_rays_per_second: f64,
    reflection_packet_rays_per_second: f64,
    /// The same figures per second of this process's CPU time: on a busy
    /// machine these compare fairly with another tracer's (one thread).
    primary_rays_per_cpu_second: f64,
    incoherent_rays_per_cpu_second: f64,
    reflection_rays_per_cpu_second: f64,
    primary_packet_rays_per_cpu_second: f64,
    reflection_packet_rays_per_cpu_second: f64,
}

/// Passes over each ray set; the best counts.
const ROUNDS: usize = 3;

pub(crate) fn run(args: RaysArgs) -> Result<()> {
    crate::support::set_threads(Some(args.threads))?;
    let (scene, camera) = load(&args)?;
    let reflector = scene.object_id(&args.reflector).with_context(|| {
        format!(
            "{}: no object named '{}' (pick one with --reflector)",
            args.scene, args.reflector
        )
    })?;
    let default = BvhOptions::default();
    let options = BvhOptions {
        layout: args.layout.unwrap_or(default.layout),
        preset: args.preset.unwrap_or(default.preset),
    };
    let scene = Arc::new(scene);
    let start = Instant::now();
    let bvh = SceneBvh::with_options(scene.clone(), options);
    let bvh_build_seconds = start.elapsed().as_secs_f64();

    let baseline = args.baseline.map(|layout| {
        let start = Instant::now();
        let bvh = SceneBvh::with_options(scene.clone(), BvhOptions { layout, ..options });
        (bvh, start.elapsed().as_secs_f64())
    });
    let mut bvhs = vec![&bvh];
    bvhs.extend(baseline.as_ref().map(|(b, _)| b));

    let sets = RaySets::new(&bvh, &camera, args.random_rays, args.seed, Some(reflector));
    if let Some(dir) = &args.dump_rays {
        sets.dump(&bvh, dir)?;
    }
    let primary = rays_per_second(&bvhs, &sets.primary, Batch::Single);
    let incoherent = rays_per_second(&bvhs, &sets.incoherent, Batch::Single);
    let reflection = rays_per_second(&bvhs, &sets.reflection, Batch::Single);
    let primary_packets = rays_per_second(&bvhs, &sets.primary, Batch::Packets);
    let reflection_packets = rays_per_second(&bvhs, &sets.reflection, Batch::Packets);
    let figures = RaysFigures {
        triangles: scene.triangles.len(),
        threads: args.threads,
        bvh_build_seconds,
        primary_rays: sets.primary.len(),
        primary_rays_per_second: primary[0].wall,
        incoherent_rays: sets.incoherent.len(),
        incoherent_rays_per_second: incoherent[0].wall,
        reflection_rays: sets.reflection.len(),
        reflection_rays_per_second: reflection[0].wall,
        primary_packet_rays_per_second: primary_packets[0].wall,
        reflection_packet_rays_per_second: reflection_packets[0].wall,
        primary_rays_per_cpu_second: primary[0].cpu,
        incoherent_rays_per_cpu_second: incoherent[0].cpu,
        reflection_rays_per_cpu_second: reflection[0].cpu,
        primary_packet_rays_per_cpu_second: primary_packets[0].cpu,
        reflection_packet_rays_per_cpu_second: reflection_packets[0].cpu,
    };
    println!(
        "{} triangles, BVH {:?} (build {:.3} s), {} thread(s), best of {ROUNDS}",
        figures.triangles, options, figures.bvh_build_seconds, figures.threads
    );
    for (name, count, rate) in [
        ("primary", sets.primary.len(), primary[0]),
        ("incoherent", sets.incoherent.len(), incoherent[0]),
        ("reflection", sets.reflection.len(), reflection[0]),
        ("primary, packets", sets.primary.len(), primary_packets[0]),
        (
            "reflection, packets",
            sets.reflection.len(),
            reflection_packets[0],
        ),
    ] {
        println!(
            "{name:<20} {count:>9} rays  {:>7.2} M rays/s  {:>7.2} M rays/CPU-s",
            rate.wall / 1e6,
            rate.cpu / 1e6
        );
    }
    if let Some(((base, seconds), layout)) = baseline.as_ref().zip(args.baseline) {
        println!(
            "baseline {:?} (build {seconds:.3} s), same rounds interleaved:",
            base.options()
        );
        for (name, rates) in [
            ("primary", &primary),
            ("incoherent", &incoherent),
            ("reflection", &reflection),
            ("primary, packets", &primary_packets),
            ("reflection, packets", &reflection_packets),
        ] {
            println!(
                "{name:<20} {:>7.2} M rays/s  ({:?} is {:.2}x {layout:?})",
                rates[1].wall / 1e6,
                options.layout,
                rates[0].wall / rates[1].wall.max(1e-9)
            );
        }
    }
    if let Some(path) = &args.json {
        super::write_json(path, &figures)?;
    }
    Ok(())
}

/// The scene and the camera the arguments name.
fn load(args: &RaysArgs) -> Result<(Scene, Camera)> {
    let vec = |v: &Option<Vec<f32>>| v.as_ref().map(|v| Vec3::new(v[0], v[1], v[2]));
    let (scene, default_camera) = if args.scene == "cockpit" {
        let c = cockpit(&CockpitConfig::default());
        (c.scene, Some(c.camera))
    } else {
        let scene = vtfarm_scene::obj::load_obj(args.scene.as_ref(), &Default::default())?;
        (scene, None)
    };
    let required = |value: Option<Vec3>, from_default: Option<Vec3>, flag: &str| {
        value
            .or(from_default)
            .with_context(|| format!("{}: --{flag} is required for a scene file", args.scene))
    };
    let camera = Camera {
        eye: required(vec(&args.eye), default_camera.map(|c| c.eye), "eye")?,
        target: required(
            vec(&args.target),
            default_camera.map(|c| c.target),
            "target",
        )?,
        up: vec(&args.up)
            .or(default_camera.map(|c| c.up))
            .unwrap_or(Vec3::Y),
        fov_y_deg: match args.fov.or(default_camera.map(|c| c.fov_y_deg)) {
            Some(fov) => fov,
            None => bail!("{}: --fov is required for a scene file", args.scene),
        },
        width: args.width,
        height: args.height,
    };
    if !(camera.fov_y_deg > 0.0 && camera.fov_y_deg < 180.0)
        || camera.width == 0
        || camera.height == 0
    {
        bail!("the camera needs 0 < --fov < 180 and a non-empty image");
    }
    Ok((scene, camera))
}

/// The three ray sets of the module docs.
pub(super) struct RaySets {
    pub(super) primary: Vec<Ray>,
    pub(super) incoherent: Vec<Ray>,
    pub(super) reflection: Vec<Ray>,
}

impl RaySets {
    pub(super) fn new(
        bvh: &SceneBvh,
        camera: &Camera,
        random_rays: usize,
        seed: u64,
        reflector: Option<vtfarm_scene::ObjectId>,
    ) -> RaySets {
        let primary: Vec<Ray> = (0..camera.height)
            .flat_map(|y| (0..camera.width).map(move |x| (x, y)))
            .map(|(x, y)| Ray {
                origin: camera.eye,
                direction: camera.pixel_ray(x, y),
            })
            .collect();
        let (lo, hi) = bvh.scene().bounds();
        let mut generator = RayGenerator::new(seed);
        let incoherent = (0..random_rays).map(|_| generator.ray(lo, hi)).collect();
        let scene = bvh.scene();
        let reflection = primary
            .iter()
            .filter_map(|ray| {
                let hit = bvh.closest_hit(ray, f32::INFINITY)?;
                if Some(scene.triangles[hit.triangle.index()].object) != reflector {
                    return None;
                }
                let surface = bvh.surface_point(&hit);
                let facing = if surface.normal.dot(ray.direction) > 0.0 {
                    -surface.normal
                } else {
                    surface.normal
                };
                let direction = reflect(ray.direction, facing);
                Some(bvh.spawn_ray(surface.position, hit.triangle, direction))
            })
            .collect();
        RaySets {
            primary,
            incoherent,
            reflection,
        }
    }
}

impl RaySets {
    /// `triangles.npy` (triangles × 3 corners × xyz), then for each set
    /// `NAME_origins.npy` and `NAME_directions.npy` (rays × xyz, ray order)
    /// and `NAME_hits.npy` (rays: the closest hit's t, +inf for a miss), so
    /// that another tracer can check it found the same hits.
    fn dump(&self, bvh: &SceneBvh, dir: &std::path::Path) -> Result<()> {
        let scene = bvh.scene();
        std::fs::create_dir_all(dir).with_context(|| format!("{}", dir.display()))?;
        let corners: Vec<f32> = (scene.triangle_ids())
            .flat_map(|id| scene.triangle_positions(id))
            .flat_map(|p| p.to_array())
            .collect();
        let count = scene.triangles.len();
        vtfarm_imaging::write_npy_f32(&dir.join("triangles.npy"), &[count, 3, 3], &corners)?;
        for (name, rays) in self.named() {
            let xyz = |f: fn(&Ray) -> Vec3| -> Vec<f32> {
                rays.iter().flat_map(|r| f(r).to_array()).collect()
            };
            let shape = [rays.len(), 3];
            let path = |suffix: &str| dir.join(format!("{name}_{suffix}.npy"));
            vtfarm_imaging::write_npy_f32(&path("origins"), &shape, &xyz(|r| r.origin))?;
            vtfarm_imaging::write_npy_f32(&path("directions"), &shape, &xyz(|r| r.direction))?;
            let hits: Vec<f32> = rays
                .par_iter()
                .map(|r| {
                    bvh.closest_hit(r, f32::INFINITY)
                        .map_or(f32::INFINITY, |h| h.t)
                })
                .collect();
            vtfarm_imaging::write_npy_f32(&path("hits"), &[rays.len()], &hits)?;
        }
        println!("rays written to {}", dir.display());
        Ok(())
    }

    /// The sets with their names in file names and output.
    fn named(&self) -> [(&'static str, &[Ray]); 3] {
        [
            ("primary", &self.primary),
            ("incoherent", &self.incoherent),
            ("reflection", &self.reflection),
        ]
    }
}

/// The fixed generator of the incoherent rays (docs/benchmarks.md gives it
/// for other tracers): xorshift64* with state `seed` (0 becomes the default seed).
/// Each ray draws five numbers `u = (next() >> 40) / 2^24` in [0, 1), in this
/// order: origin x, y, z (`lo + (hi - lo) * u` per axis, in f32), then
/// `z = 1 - 2 u4` and `phi = 2 pi u5`; the direction is
/// `(sqrt(1 - z^2) cos phi, sqrt(1 - z^2) sin phi, z)`, computed in f64 and
/// rounded to f32.
pub(super) struct RayGenerator(u64);

impl RayGenerator {
    pub(super) const DEFAULT_SEED: u64 = 0x9E37_79B9_7F4A_7C15;

    pub(super) fn new(seed: u64) -> RayGenerator {
        RayGenerator(if seed == 0 { Self::DEFAULT_SEED } else { seed })
    }

    fn unit(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 40) as f32 / (1u64 << 24) as f32
    }

    pub(super) fn ray(&mut self, lo: Vec3, hi: Vec3) -> Ray {
        let origin = lo + (hi - lo) * Vec3::new(self.unit(), self.unit(), self.unit());
        let z = 1.0 - 2.0 * self.unit() as f64;
        let phi = std::f64::consts::TAU * self.unit() as f64;
        let r = (1.0 - z * z).max(0.0).sqrt();
        Ray {
            origin,
            direction: Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32),
        }
    }
}

/// Closest-hit queries per second of wall-clock and of CPU time.
#[derive(Clone, Copy)]
pub(super) struct Rate {
    pub(super) wall: f64,
    pub(super) cpu: f64,
}

/// Closest-hit queries per second over `rays` on rayon's pool for each BVH,
/// best of [`ROUNDS`] passes; the BVHs take turns within each round so that
/// load from other processes hits them alike.
pub(super) fn rays_per_second(bvhs: &[&SceneBvh], rays: &[Ray], batch: Batch) -> Vec<Rate> {
    let mut best = vec![(f64::INFINITY, f64::INFINITY); bvhs.len()];
    for _ in 0..ROUNDS {
        for (bvh, best) in bvhs.iter().zip(&mut best) {
            let (start, cpu_start) = (Instant::now(), cpu_seconds());
            let hits = rays
                .par_chunks(CHUNK)
                .map(|chunk| match batch {
                    Batch::Single => chunk
                        .iter()
                        .filter(|r| bvh.closest_hit(r, f32::INFINITY).is_some())
                        .count(),
                    Batch::Packets => bvh
                        .closest_hits(chunk, f32::INFINITY)
                        .iter()
                        .flatten()
                        .count(),
                })
                .sum::<usize>();
            std::hint::black_box(hits);
            best.0 = best.0.min(start.elapsed().as_secs_f64());
            best.1 = best.1.min(cpu_seconds() - cpu_start);
        }
    }
    let per_second = |seconds: f64| {
        if rays.is_empty() {
            0.0
        } else {
            rays.len() as f64 / seconds.max(1e-9)
        }
    };
    best.iter()
        .map(|&(wall, cpu)| Rate {
            wall: per_second(wall),
            cpu: per_second(cpu),
        })
        .collect()
}

/// CPU time of this process so far, all threads, in seconds; 0 where
/// there is no process clock, so CPU figures read as unmeasured.
fn cpu_seconds() -> f64 {
    cpu_time(CpuClock::Process).map_or(0.0, |t| t.as_secs_f64())
}

/// How the rays are handed to the tracer.
#[derive(Clone, Copy)]
pub(super) enum Batch {
    /// One `closest_hit` call per ray.
    Single,
    /// `closest_hits` on each chunk (packets of consecutive rays).
    Packets,
}

/// Rays per rayon task: large enough to amortise scheduling.
const CHUNK: usize = 4096;
