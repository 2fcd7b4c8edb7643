//! `vtfarm bench raster`: the rasterizer's per-frame costs on the built-in
//! cockpit — the master's shaded base frame (`vtfarm_raster::rasterize`) and a
//! worker's ID buffer over the reflectors' screen bounds
//! (`vtfarm_raster::id_buffer_within`, as `Renderer::id_buffers` builds it) —
//! on one thread and on several, best of a few rounds — and the rest of a
//! farm worker's per-frame set-up (`Renderer::id_buffers`: the frame's ID
//! buffer and `Behind`, rasterized together, with on-demand thin-glass
//! terms) and those terms per glass pixel (`Frame::finish_pixel` over every
//! see-through reflector pixel, as a frame's packages finish them between
//! them). Last, whether the master should send its visibility (the ID
//! buffer over the reflectors' bounds) to a split frame's workers instead
//! of each rasterizing it: its bytes packed with zstd, the CPU to pack and
//! unpack them and their time on a 100 Mbit and a 1 Gbit link, against the
//! one-thread time to rasterize it.

use std::time::Instant;

use crate::support::{CpuClock, cpu_time};
use anyhow::{Context, Result};
use vtfarm_cockpit::CockpitConfig;
use vtfarm_raster::{IdPass, PixelRect};
use vtfarm_render::Renderer;
use vtfarm_vertex::{PixelValue, Quality, VertexSettings, reflector_bounds};

use super::CockpitJob;
use vtfarm_scene::TriangleId;

#[derive(clap::Args)]
pub struct RasterArgs {
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
            .for_each(|&t| is_reflector[t.index()] = true);
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
        let renderer = Renderer::new(job.scene.clone(), job.reflectors.clone());
        // Warms the renderer's shadow-map cache: a worker builds the maps on
        // its first frame and keeps them while the lights and the box stay.
        let (frame_ids, _) = renderer.id_buffers(&job.setup);
        let glass: Vec<(u32, u32)> = bounds
            .pixels()
            .filter(|&(x, y)| {
                TriangleId::from_raw(frame_ids.triangle_at(x, y)).is_some_and(|t| {
                    is_reflector[t.index()]
                        && scene.material_of(t).transmittance.max_element() > 0.0
                })
            })
            .collect();
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
            // A new view's set-up: the buffers kept from the last frame of
            // the same camera (`IdBufferCache`) are forgotten first.
            let fresh_setup = || {
                renderer.id_buffer_cache().clear();
                drop(renderer.id_buffers(&job.setup))
            };
            let setup = least(&fresh_setup);
            // The same in CPU time per set-up over a few rounds: what the
            // set-up costs a busy machine's cores, whatever else runs.
            let setup_cpu = cpu_time(CpuClock::Process)
                .map(|t| t.as_secs_f64())
                .map(|before| {
                    let rounds = args.rounds.max(1) * 2;
                    for _ in 0..rounds {
                        pool.install(fresh_setup);
                    }
                    cpu_time(CpuClock::Process)
                        .map(|t| t.as_secs_f64())
                        .map_or(f64::NAN, |after| (after - before) / f64::from(rounds))
                });
            // A worker's three buffers (frame, behind the glass, the slab's
            // back) rasterized one by one and together, rounds interleaved
            // so that both see the same machine.
            let all = |_: TriangleId| true;
            let passes = [0, 16, 0].map(|margin| IdPass {
                within: reflector_bounds(scene, camera, &is_reflector, margin),
                keep: &all,
            });
            let (mut apart, mut together) = (f64::INFINITY, f64::INFINITY);
            for _ in 0..args.rounds.max(1) {
                let start = Instant::now();
                pool.install(|| {
                    for pass in &passes {
                        drop(vtfarm_raster::id_buffer_within(
                            scene,
                            camera,
                            pass.within,
                            pass.keep,
                        ));
                    }
                });
                apart = apart.min(start.elapsed().as_secs_f64());
                let start = Instant::now();
                pool.install(|| drop(vtfarm_raster::id_buffers_within(scene, camera, &passes)));
                together = together.min(start.elapsed().as_secs_f64());
            }
            // The glass terms are computed pixel by pixel as packages finish
            // them: one thread, whatever the pool. Timed in runs of a few
            // hundred microseconds, the least of each kept, so that a
            // machine busy with other work still gives the quiet figure.
            // A frame computes a pixel's terms once and later stages take
            // them from its store: each round has a set-up of its own, and
            // each run is finished on every round's set-up in turn, then
            // again, from their stores.
            let set_ups: Vec<_> = (0..args.rounds.max(1))
                .map(|_| renderer.id_buffers(&job.setup))
                .collect();
            let frames: Vec<_> = (set_ups.iter())
                .map(|(ids, behind)| renderer.frame(&job.setup, ids, behind))
                .collect();
            let runs: Vec<&[(u32, u32)]> = glass.chunks(1024).collect();
            let finish_run = |frame: &vtfarm_vertex::Frame<'_>, run: &[(u32, u32)]| {
                let start = Instant::now();
                for &(x, y) in run {
                    let mut value = PixelValue {
                        index: frame_ids.frame_index(x, y) as u32,
                        color: glam::Vec3::ZERO,
                        reflected: glam::Vec3::ONE,
                        transmitted: glam::Vec3::ZERO,
                        object: 0,
                    };
                    frame.finish_pixel((x, y), &mut value);
                    std::hint::black_box(value);
                }
                start.elapsed().as_secs_f64()
            };
            let least_run = |run: &[(u32, u32)]| {
                (frames.iter())
                    .map(|frame| finish_run(frame, run))
                    .fold(f64::INFINITY, f64::min)
            };
            let computed: Vec<f64> = runs.iter().map(|run| least_run(run)).collect();
            let stored: Vec<f64> = runs.iter().map(|run| least_run(run)).collect();
            let (terms, stored): (f64, f64) = (computed.iter().sum(), stored.iter().sum());
            println!(
                "  {n} thread(s): base frame {base:.4} s (ID buffer {ids:.4} s, shading {:.4} s), within {within:.4} s",
                base - ids
            );
            println!(
                "    worker set-up {setup:.4} s ({} CPU; three buffers one by one {apart:.4} s, together {together:.4} s); thin-glass terms of {} glass px {terms:.4} s ({:.0} ns/px; again, from the frame's store, {:.0} ns/px)",
                setup_cpu.map_or("no".to_owned(), |c| format!("{c:.4} s")),
                glass.len(),
                terms * 1e9 / glass.len().max(1) as f64,
                stored * 1e9 / glass.len().max(1) as f64
            );
        }
        print_visibility_transfer(&job, bounds, args.rounds.max(1))?;
    }
    Ok(())
}

/// The links the visibility's transfer is priced on, in Mbit/s.
const VISIBILITY_LINKS_MBIT: [f64; 2] = [100.0, 1000.0];

/// Prints what sending the master's visibility (the frame's ID buffer over
/// the reflectors' bounds) would cost a split frame's worker against
/// rasterizing it itself, one thread each, least of `rounds`.
fn print_visibility_transfer(job: &CockpitJob, bounds: PixelRect, rounds: u32) -> Result<()> {
    let (scene, camera) = (&*job.scene, &job.setup.camera);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .context("building a one-thread pool")?;
    let least = |f: &mut dyn FnMut()| {
        (0..rounds)
            .map(|_| {
                let start = Instant::now();
                f();
                start.elapsed().as_secs_f64()
            })
            .fold(f64::INFINITY, f64::min)
    };
    let ids = vtfarm_raster::id_buffer_within(scene, camera, bounds, &|_| true);
    let rasterize = least(&mut || {
        pool.install(|| {
            drop(vtfarm_raster::id_buffer_within(
                scene,
                camera,
                bounds,
                &|_| true,
            ))
        })
    });
    // What a worker needs of it: object, triangle and depth per pixel.
    let raw: Vec<u8> = (ids.object.iter().flat_map(|o| o.to_le_bytes()))
        .chain(ids.triangle.iter().flat_map(|t| t.to_le_bytes()))
        .chain(ids.depth.iter().flat_map(|d| d.to_le_bytes()))
        .collect();
    let packed = zstd::bulk::compress(&raw, 1).context("packing the visibility")?;
    let pack = least(&mut || drop(zstd::bulk::compress(&raw, 1)));
    let unpack = least(&mut || drop(zstd::bulk::decompress(&packed, raw.len())));
    let links = VISIBILITY_LINKS_MBIT.map(|mbit| {
        let on_link = packed.len() as f64 * 8.0 / (mbit * 1e6);
        let sent = pack + on_link + unpack;
        format!(
            "{mbit:.0} Mbit {sent:.4} s ({:.1}× the raster)",
            sent / rasterize
        )
    });
    println!(
        "  sending the visibility instead of rasterizing it ({rasterize:.4} s, one thread): {:.2} MB, {:.2} MB with zstd -1 (pack {pack:.4} s, unpack {unpack:.4} s); packed, on the link and unpacked: {}",
        raw.len() as f64 / 1e6,
        packed.len() as f64 / 1e6,
        links.join(", ")
    );
    Ok(())
}

fn pixels(r: PixelRect) -> u64 {
    u64::from(r.x1 - r.x0) * u64::from(r.y1 - r.y0)
}
