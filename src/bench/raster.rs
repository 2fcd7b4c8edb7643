//! `vtfarm bench raster`: the rasterizer's per-frame costs on the built-in
//! cockpit — the master's shaded base frame (`vtfarm_raster::rasterize`) and a
//! worker's ID buffer over the reflectors' screen bounds
//! (`vtfarm_raster::id_buffer_within`, as `Renderer::id_buffers` builds it) —
//! on one thread and on several, best of a few rounds.

use std::time::Instant;

use anyhow::{Context, Result};
use vtfarm_cockpit::CockpitConfig;
use vtfarm_raster::PixelRect;
use vtfarm_vertex::{Quality, VertexSettings, reflector_bounds};

use super::CockpitJob;

#[derive(clap::Args)]
pub(crate) struct RasterArgs {
    #[arg(long, default_value_t = 1920)]
    width: u32,
    #[arg(long, default_value_t = 1080)]
    height: u32,
    /// Cockpit details to measure (default: the default and the farm's scaling job's).
    #[arg(long, num_args = 1.., default_values_t = [CockpitConfig::DEFAULT_DETAIL, CockpitConfig::LARGE_DETAIL])]
    detail: Vec<f32>,
    /// Thread counts to measure (default: 1 and all cores).
    #[arg(long, num_args = 1..)]
    threads: Vec<usize>,
    /// Rounds per figure; the least time is kept.
    #[arg(long, default_value_t = 5)]
    rounds: u32,
}

pub(crate) fn run(args: RasterArgs) -> Result<()> {
    let threads = if args.threads.is_empty() {
        vec![
            1,
            std::thread::available_parallelism().map_or(1, |n| n.get()),
        ]
    } else {
        args.threads.clone()
    };
    println!(
        "{}x{}, least wall time of {} rounds; `within`: the ID buffer over the reflectors' bounds",
        args.width, args.height, args.rounds
    );
    for &detail in &args.detail {
        let job = CockpitJob::new(detail, args.width, args.height, Quality::Full)?;
        let (scene, camera) = (&*job.scene, &job.setup.camera);
        let mut is_reflector = vec![false; scene.triangles.len()];
        job.reflectors
            .iter()
            .for_each(|&t| is_reflector[t as usize] = true);
        let margin = VertexSettings::default().visibility_radius + 1;
        let bounds = reflector_bounds(scene, camera, &is_reflector, margin);
        println!(
            "detail {detail}: {} triangles; reflectors' bounds {}x{} px ({:.1}% of the frame)",
            scene.triangles.len(),
            bounds.x1 - bounds.x0,
            bounds.y1 - bounds.y0,
            100.0 * pixels(bounds) as f64
                / pixels(PixelRect::full(camera.width, camera.height)) as f64
        );
        for &n in &threads {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .context("building the thread pool")?;
            let least = |f: &(dyn Fn() + Sync)| {
                (0..args.rounds.max(1))
                    .map(|_| {
                        let start = Instant::now();
                        pool.install(f);
                        start.elapsed().as_secs_f64()
                    })
                    .fold(f64::INFINITY, f64::min)
            };
            let base =
                least(&|| drop(vtfarm_raster::rasterize(scene, camera, &job.setup.lighting)));
            let ids = least(&|| drop(vtfarm_raster::id_buffer(scene, camera)));
            let within = least(&|| {
                drop(vtfarm_raster::id_buffer_within(
                    scene,
                    camera,
                    bounds,
                    &|_| true,
                ))
            });
            println!(
                "  {n} thread(s): base frame {base:.4} s (ID buffer {ids:.4} s, shading {:.4} s), within {within:.4} s",
                base - ids
            );
        }
    }
    Ok(())
}

fn pixels(r: PixelRect) -> u64 {
    u64::from(r.x1 - r.x0) * u64::from(r.y1 - r.y0)
}
