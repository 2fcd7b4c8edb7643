//! `vtfarm bench`, which the command-line program calls: the paper's
//! Table 1 on the built-in cockpit and the tracer's ray throughput
//! (`table1`), the load balancer on simulated farms driven by costs
//! recorded from a real frame (`simulate`, see [`SimulateArgs`]), a real
//! QUIC farm on localhost (`cluster`, see [`ClusterArgs`]), and a
//! progressive frame against separate renders (`progressive`, see
//! [`ProgressiveArgs`]), and the interactive view's latency on a localhost
//! farm of processes (`view`, see [`ViewArgs`]). Speed targets live here,
//! not in tests.

mod cluster;
mod progressive;
mod raster;
mod rays;
mod simulate;
pub mod support;
mod view;

pub use cluster::ClusterArgs;
pub use progressive::ProgressiveArgs;
pub use raster::RasterArgs;
pub use rays::RaysArgs;
pub use simulate::SimulateArgs;
pub use view::ViewArgs;

use std::path::PathBuf;
use std::sync::Arc;

use anyhow::Result;
use serde::Serialize;
use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_render::{FrameSetup, RenderOptions, Renderer, compare};
use vtfarm_trace::{SceneBvh, TraceSettings};
use vtfarm_vertex::{Quality, VertexSettings};

#[derive(clap::Subcommand)]
pub enum BenchCommand {
    /// Reproduces the paper's Table 1: reference, preview, refine and full on the cockpit.
    Table1(Table1Args),
    /// The scheduler on simulated farms (1 to 64 workers, 10/100 Mbit links),
    /// driven by per-triangle costs recorded from a real cockpit frame.
    Simulate(simulate::SimulateArgs),
    /// One worker against two over real QUIC on 127.0.0.1, all in this process.
    Cluster(cluster::ClusterArgs),
    /// Closest-hit rays per second on fixed camera, random and reflection
    /// rays (compare with another tracer on the same rays; see docs/benchmarks.md).
    Rays(rays::RaysArgs),
    /// The rasterizer's per-frame costs: the master's base frame and a
    /// worker's ID buffer over the reflectors' bounds, on 1 and more threads.
    Raster(raster::RasterArgs),
    /// Preview, refine and full as three separate renders against one
    /// progressive frame (set up once, each stage continuing the last).
    Progressive(progressive::ProgressiveArgs),
    /// The interactive view's latency: a localhost farm of processes, eye
    /// moves through its HTTP API, each stage timed on the event stream.
    View(view::ViewArgs),
}

/// The cockpit frame a one-process benchmark renders and the threads it
/// renders on: what `table1`, `progressive` and `view` share.
#[derive(clap::Args)]
pub struct CockpitFrameArgs {
    #[arg(long, default_value_t = 1920)]
    width: u32,
    #[arg(long, default_value_t = 1080)]
    height: u32,
    /// Cockpit detail (1.0 ≈ 100k triangles).
    #[arg(long, default_value_t = CockpitConfig::DEFAULT_DETAIL)]
    detail: f32,
    /// Worker threads (default: all cores).
    #[arg(long)]
    threads: Option<usize>,
}

impl CockpitFrameArgs {
    /// Sizes the process's thread pool (`--threads`) and builds the
    /// cockpit job at `quality`.
    fn set_up(&self, quality: Quality) -> Result<CockpitJob> {
        crate::support::set_threads(self.threads)?;
        CockpitJob::new(self.detail, self.width, self.height, quality)
    }
}

#[derive(clap::Args)]
pub struct Table1Args {
    #[command(flatten)]
    frame: CockpitFrameArgs,
    /// Refinement threshold in 8-bit sRGB steps (default: the job default).
    #[arg(long)]
    epsilon: Option<f32>,
    /// Also writes the figures as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Writes each level's image into this directory.
    #[arg(long)]
    images: Option<PathBuf>,
}

#[derive(Serialize)]
struct LevelFigures {
    name: &'static str,
    seconds: f64,
    traced_samples: u64,
    /// Of `traced_samples`: at vertices (corners and refinement), and per
    /// pixel (triangle filling, rim pixels no face reaches, the reference).
    vertex_samples: u64,
    pixel_samples: u64,
    speedup: f64,
    sample_ratio: f64,
    share_off: f64,
    mean_abs: f64,
    /// Where `seconds` went (see [`vtfarm_render::FrameTimes`]): setting up
    /// the frame's planes, tracing and refining the vertices, tracing the
    /// pixels that get a sample of their own, and the interpolation pass
    /// that gives every other pixel its value and writes all of them.
    image_setup_seconds: f64,
    vertex_seconds: f64,
    pixel_trace_seconds: f64,
    interpolation_seconds: f64,
    /// The floors: the level's traced samples alone (vertices and traced
    /// pixels) and its per-pixel pass alone (set-up and interpolation).
    /// The factor cannot beat the reference's time over either.
    trace_seconds: f64,
    fill_seconds: f64,
}

/// The thin-glass model on its own: the reference with its traced
/// transmitted part replaced by the rasterized one (`transmission = "raster"`),
/// against the reference.
#[derive(Serialize)]
struct ModelFigures {
    share_off: f64,
    mean_abs: f64,
}

#[derive(Serialize)]
struct Table1 {
    width: u32,
    height: u32,
    scene_triangles: usize,
    reflector_triangles: usize,
    glass_pixels: u64,
    base_frame_seconds: f64,
    levels: Vec<LevelFigures>,
    model: ModelFigures,
    coherent_rays_per_second: f64,
    incoherent_rays_per_second: f64,
}

pub fn run(command: BenchCommand) -> Result<()> {
    match command {
        BenchCommand::Table1(args) => table1(args),
        BenchCommand::Simulate(args) => simulate::run(args),
        BenchCommand::Cluster(args) => cluster::run(args),
        BenchCommand::Rays(args) => rays::run(args),
        BenchCommand::Raster(args) => raster::run(args),
        BenchCommand::Progressive(args) => progressive::run(args),
        BenchCommand::View(args) => view::run(args),
    }
}

fn table1(args: Table1Args) -> Result<()> {
    let job = args.frame.set_up(Quality::Full)?;
    let scene = job.scene.clone();
    let renderer = Renderer::new(scene.clone(), job.reflectors.clone());
    let camera = job.setup.camera;
    let setup_for = |quality| FrameSetup {
        vertex: VertexSettings {
            quality,
            epsilon: args
                .epsilon
                .map_or(VertexSettings::default().epsilon, |e| e / 255.0),
            ..VertexSettings::default()
        },
        ..job.setup.clone()
    };
    // Reference first: the others are measured against it.
    let order = [
        Quality::Reference,
        Quality::Preview,
        Quality::Refine,
        Quality::Full,
    ];
    let mut frames = Vec::new();
    for q in order {
        eprintln!("rendering {} ...", q.name());
        // Best of several runs (frames are identical): the fast levels take
        // milliseconds, where one run's noise on a shared machine would move
        // the factor by half; the reference takes seconds.
        let runs = if q == Quality::Reference { 3 } else { 9 };
        let frame = (0..runs)
            .map(|_| renderer.render(&setup_for(q), &RenderOptions::default(), &mut |_, _| {}))
            .min_by_key(|f| f.total_time - f.raster_time)
            .expect("three runs");
        if let Some(dir) = &args.images {
            std::fs::create_dir_all(dir)?;
            frame
                .image
                .color
                .write_png(&dir.join(format!("{}.png", q.name())))?;
        }
        frames.push((q, frame));
    }
    let reference = &frames[0].1;
    // Everything after the raster pass: set-up, tracing, filling, compositing.
    let seconds = |f: &vtfarm_render::RenderedFrame| (f.total_time - f.raster_time).as_secs_f64();
    let ref_seconds = seconds(reference);
    let ref_samples = reference.stats.samples() as f64;
    let levels: Vec<LevelFigures> = frames
        .iter()
        .map(|(q, f)| {
            let seconds = seconds(f);
            let err = compare(&f.image, &reference.image);
            let t = &f.times;
            let trace = t.phases.vertices + t.phases.pixel_tracing;
            let fill = t.image_setup + t.phases.interpolation;
            LevelFigures {
                name: q.name(),
                seconds,
                traced_samples: f.stats.samples(),
                vertex_samples: f.stats.vertex_samples,
                pixel_samples: f.stats.filled_pixels,
                speedup: ref_seconds / seconds.max(1e-9),
                sample_ratio: ref_samples / (f.stats.samples() as f64).max(1.0),
                share_off: err.share_off,
                mean_abs: err.mean_abs,
                image_setup_seconds: t.image_setup.as_secs_f64(),
                vertex_seconds: t.phases.vertices.as_secs_f64(),
                pixel_trace_seconds: t.phases.pixel_tracing.as_secs_f64(),
                interpolation_seconds: t.phases.interpolation.as_secs_f64(),
                trace_seconds: trace.as_secs_f64(),
                fill_seconds: fill.as_secs_f64(),
            }
        })
        .collect();
    let model = {
        let setup = setup_for(Quality::Full);
        let ids = vtfarm_raster::id_buffer(&scene, &camera);
        let behind = renderer.behind(&setup, &ids);
        let modelled = vtfarm_render::thin_glass_model(
            &reference.image,
            &renderer.frame(&setup, &ids, &behind),
        );
        let err = compare(&modelled, &reference.image);
        ModelFigures {
            share_off: err.share_off,
            mean_abs: err.mean_abs,
        }
    };
    let (coherent, incoherent) = ray_throughput(renderer.bvh(), &camera);
    let table = Table1 {
        width: camera.width,
        height: camera.height,
        scene_triangles: scene.triangles.len(),
        reflector_triangles: renderer.reflectors().len(),
        glass_pixels: reference.stats.pixels,
        base_frame_seconds: reference.raster_time.as_secs_f64(),
        levels,
        model,
        coherent_rays_per_second: coherent,
        incoherent_rays_per_second: incoherent,
    };
    print_table1(&table);
    if let Some(path) = &args.json {
        write_json(path, &table)?;
    }
    Ok(())
}

fn print_table1(t: &Table1) {
    println!(
        "Table 1 — cockpit {} triangles, {}x{}, cover glass {} triangles / {} pixels",
        t.scene_triangles, t.width, t.height, t.reflector_triangles, t.glass_pixels
    );
    println!(
        "{:<10} {:>10} {:>12} {:>10} {:>12} {:>12} {:>10} {:>14}",
        "level",
        "time s",
        "samples",
        "factor",
        "sample fac.",
        "px off >8",
        "mean err",
        "paper fac/smp"
    );
    for l in &t.levels {
        let paper = match l.name {
            "preview" => "502 / 322",
            "refine" => "77 / 1,972",
            "full" => "18 / 6,790",
            _ => "",
        };
        println!(
            "{:<10} {:>10.3} {:>12} {:>10.1} {:>12.1} {:>11.3}% {:>10.3} {:>14}",
            l.name,
            l.seconds,
            l.traced_samples,
            l.speedup,
            l.sample_ratio,
            l.share_off * 100.0,
            l.mean_abs,
            paper
        );
    }
    println!(
        "where the time goes (ms): set-up = the frame's planes, vertices = tracing and refining them,\n\
         traced px = pixels traced one by one, interp. = every other pixel interpolated and all written;\n\
         floors: the factor if only the tracing (trace) or only the per-pixel pass (fill) took time"
    );
    println!(
        "{:<10} {:>8} {:>9} {:>10} {:>8} {:>8} {:>12} {:>11} {:>16}",
        "level",
        "set-up",
        "vertices",
        "traced px",
        "interp.",
        "other",
        "trace floor",
        "fill floor",
        "samples vtx/px"
    );
    let ref_seconds = t.levels.first().map_or(0.0, |l| l.seconds);
    for l in &t.levels {
        let other = l.seconds - l.trace_seconds - l.fill_seconds;
        println!(
            "{:<10} {:>8.2} {:>9.2} {:>10.2} {:>8.2} {:>8.2} {:>11.0}x {:>10.0}x {:>16}",
            l.name,
            l.image_setup_seconds * 1e3,
            l.vertex_seconds * 1e3,
            l.pixel_trace_seconds * 1e3,
            l.interpolation_seconds * 1e3,
            other * 1e3,
            ref_seconds / l.trace_seconds.max(1e-9),
            ref_seconds / l.fill_seconds.max(1e-9),
            format!("{} / {}", l.vertex_samples, l.pixel_samples),
        );
    }
    println!(
        "thin-glass model alone (reference with rasterized transmission): {:.3}% px off >8, mean err {:.3}",
        t.model.share_off * 100.0,
        t.model.mean_abs
    );
    println!(
        "base frame (rasterizer, image + ID buffers): {:.3} s",
        t.base_frame_seconds
    );
    println!(
        "tracer: {:.2} M coherent rays/s (camera rays), {:.2} M incoherent rays/s (random rays in the cab)",
        t.coherent_rays_per_second / 1e6,
        t.incoherent_rays_per_second / 1e6
    );
}

/// Closest-hit throughput for camera rays (coherent) and for as many random
/// rays in the scene bounds (incoherent): `bench rays`' first two sets.
fn ray_throughput(bvh: &SceneBvh, camera: &vtfarm_scene::Camera) -> (f64, f64) {
    let pixels = (camera.width * camera.height) as usize;
    let sets = rays::RaySets::new(bvh, camera, pixels, rays::RayGenerator::DEFAULT_SEED, None);
    (
        rays::rays_per_second(&[bvh], &sets.primary, rays::Batch::Single)[0].wall,
        rays::rays_per_second(&[bvh], &sets.incoherent, rays::Batch::Single)[0].wall,
    )
}

/// The built-in cockpit as the farm benchmarks render it: the cover glass as
/// reflector, the cockpit's camera at the requested size.
struct CockpitJob {
    scene: Arc<vtfarm_scene::Scene>,
    /// Reflector triangle ids, ascending (as a job file selects them).
    reflectors: Vec<vtfarm_scene::TriangleId>,
    setup: FrameSetup,
}

impl CockpitJob {
    fn new(detail: f32, width: u32, height: u32, quality: Quality) -> Result<CockpitJob> {
        let c = cockpit(&CockpitConfig {
            detail,
            ..CockpitConfig::default()
        });
        let reflectors = c.cover_glass_triangles();
        let setup = FrameSetup {
            camera: vtfarm_scene::Camera {
                width,
                height,
                ..c.camera
            },
            lighting: c.lighting,
            trace: TraceSettings::default(),
            vertex: VertexSettings {
                quality,
                ..VertexSettings::default()
            },
        };
        Ok(CockpitJob {
            scene: Arc::new(c.scene),
            reflectors,
            setup,
        })
    }
}

/// Writes a bench table as JSON and says so.
fn write_json(path: &std::path::Path, value: &impl Serialize) -> Result<()> {
    crate::support::write_json(path, value)?;
    println!("wrote {}", path.display());
    Ok(())
}
