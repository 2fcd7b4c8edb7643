//! A profiling harness, not a benchmark of record (that is `vtfarm bench
//! raster`): runs one phase of the rasterizer on the stock cockpit at 1080p
//! in a loop, for `perf record`, and prints the least wall time and the mean
//! CPU time per round. `base` is the master's base frame into reused
//! buffers, `ids` the whole ID buffer, `within` the buffer over the
//! reflectors' bounds (a fixed 715x424 rectangle there), `passes` three
//! buffers of about those bounds rasterized together; `hash` prints a hash
//! of the images and buffers of six eyes, to compare two builds bit for bit.
//!
//! `cargo run --release -p vtfarm-raster --example profile -- PHASE [ROUNDS [THREADS]]`

use std::time::Instant;

use vtfarm_cockpit::{CockpitConfig, cockpit};
use vtfarm_raster::{IdPass, PixelRect};
use vtfarm_scene::TriangleId;

fn main() {
    let mut args = std::env::args().skip(1);
    let phase = args.next().unwrap_or_else(|| "base".into());
    let rounds: u32 = args.next().map_or(20, |r| r.parse().expect("rounds"));
    let threads: usize = args.next().map_or(1, |r| r.parse().expect("threads"));
    let c = cockpit(&CockpitConfig::default());
    let camera = vtfarm_scene::Camera {
        width: 1920,
        height: 1080,
        ..c.camera
    };
    let scene = &c.scene;
    let bounds = PixelRect {
        x0: 600,
        y0: 500,
        x1: 1315,
        y1: 924,
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    let mut image = vtfarm_imaging::Image::new(0, 0, glam::Vec3::ZERO);
    let mut ids = vtfarm_raster::IdBuffer::new(0, 0);
    let mut least = f64::INFINITY;
    let cpu_before = process_cpu_seconds();
    for _ in 0..rounds {
        let start = Instant::now();
        pool.install(|| match phase.as_str() {
            "base" => {
                vtfarm_raster::rasterize_into(scene, &camera, &c.lighting, &mut image, &mut ids)
            }
            "ids" => drop(vtfarm_raster::id_buffer(scene, &camera)),
            "within" => drop(vtfarm_raster::id_buffer_within(
                scene,
                &camera,
                bounds,
                &|_| true,
            )),
            "passes" => {
                let all = |_: TriangleId| true;
                let passes = [0, 16, 0].map(|m| IdPass {
                    within: PixelRect {
                        x0: bounds.x0 - m,
                        y0: bounds.y0 - m,
                        x1: bounds.x1 + m,
                        y1: bounds.y1 + m,
                    },
                    keep: &all,
                });
                drop(vtfarm_raster::id_buffers_within(scene, &camera, &passes))
            }
            "hash" => {
                let mut h = 0xcbf2_9ce4_8422_2325u64;
                let mut eat = |bits: u32| h = (h ^ u64::from(bits)).wrapping_mul(0x100_0000_01b3);
                for k in 0..6 {
                    let cam = vtfarm_scene::Camera {
                        eye: camera.eye + glam::Vec3::new(0.13, -0.07, 0.21) * k as f32,
                        target: camera.target + glam::Vec3::new(-0.3, 0.1, 0.05) * k as f32,
                        ..camera
                    };
                    let (image, ids) = vtfarm_raster::rasterize(scene, &cam, &c.lighting);
                    image
                        .pixels
                        .iter()
                        .for_each(|p| p.to_array().iter().for_each(|v| eat(v.to_bits())));
                    let within =
                        vtfarm_raster::id_buffer_within(scene, &cam, bounds, &|t| t.raw() % 3 != 0);
                    let (odd, third) = (
                        |t: TriangleId| t.raw() % 2 == 1,
                        |t: TriangleId| t.raw() % 3 != 0,
                    );
                    let passes = [
                        IdPass {
                            within: bounds,
                            keep: &odd,
                        },
                        IdPass {
                            within: PixelRect {
                                x0: 100,
                                y0: 40,
                                x1: 900,
                                y1: 700,
                            },
                            keep: &third,
                        },
                        IdPass {
                            within: PixelRect {
                                x0: 0,
                                y0: 0,
                                x1: 1920,
                                y1: 1080,
                            },
                            keep: &odd,
                        },
                    ];
                    let together = vtfarm_raster::id_buffers_within(scene, &cam, &passes);
                    for b in [&ids, &within].into_iter().chain(&together) {
                        b.triangle.iter().chain(&b.object).for_each(|&t| eat(t));
                        b.depth.iter().for_each(|d| eat(d.to_bits()));
                    }
                }
                println!("hash {h:016x}");
            }
            other => panic!("unknown phase {other}"),
        });
        least = least.min(start.elapsed().as_secs_f64());
    }
    let cpu = (process_cpu_seconds() - cpu_before) / f64::from(rounds);
    println!("{phase}: least {least:.4} s of {rounds}, mean CPU {cpu:.4} s");
}

/// User plus system time of this process (`/proc/self/stat`, clock ticks of 10 ms).
fn process_cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").expect("/proc/self/stat");
    let fields: Vec<&str> = stat
        .rsplit_once(')')
        .expect("stat")
        .1
        .split_whitespace()
        .collect();
    let ticks: f64 = fields[11].parse::<f64>().unwrap() + fields[12].parse::<f64>().unwrap();
    ticks / 100.0
}
