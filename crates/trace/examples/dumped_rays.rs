//! Traces the rays `vtfarm bench rays --dump-rays DIR` wrote, on one thread,
//! single rays and packets (per second of this thread's CPU time), for every BVH preset named on the command line:
//! the quick loop for tracer work (it builds only this crate).
//!
//! Run: `cargo run --release -p vtfarm-trace --example dumped_rays -- DIR [PRESET...]`
//!
//! Also checks that packets return exactly the single-ray hits.

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use vtfarm_scene::{Material, MaterialId, Object, Scene, Triangle};
use vtfarm_trace::{BuildPreset, BvhLayout, BvhOptions, Ray, SceneBvh};

fn main() {
    let mut args = std::env::args().skip(1);
    let dir = std::path::PathBuf::from(args.next().expect("usage: dumped_rays DIR [PRESET...]"));
    let presets: Vec<BuildPreset> = args
        .map(|name| {
            *BuildPreset::ALL
                .iter()
                .find(|p| p.name() == name)
                .unwrap_or_else(|| panic!("unknown preset {name}"))
        })
        .collect();
    let presets = if presets.is_empty() {
        vec![BvhOptions::default().preset]
    } else {
        presets
    };
    let corners = read_npy(&dir.join("triangles.npy"));
    let mut scene = Scene {
        objects: vec![Object { name: "all".into() }],
        materials: vec![Material::default()],
        ..Scene::default()
    };
    for corner in corners.chunks_exact(9) {
        let base = scene.positions.len() as u32;
        for p in corner.chunks_exact(3) {
            scene.positions.push(Vec3::from_slice(p));
            scene.normals.push(Vec3::Y);
        }
        scene.triangles.push(Triangle {
            vertices: [base, base + 1, base + 2],
            object: vtfarm_scene::ObjectId(0),
            material: MaterialId(0),
        });
    }
    let scene = Arc::new(scene);
    let sets: Vec<(&str, Vec<Ray>)> = ["primary", "incoherent", "reflection"]
        .into_iter()
        .map(|name| {
            let o = read_npy(&dir.join(format!("{name}_origins.npy")));
            let d = read_npy(&dir.join(format!("{name}_directions.npy")));
            let rays = o
                .chunks_exact(3)
                .zip(d.chunks_exact(3))
                .map(|(o, d)| Ray {
                    origin: Vec3::from_slice(o),
                    direction: Vec3::from_slice(d),
                })
                .collect();
            (name, rays)
        })
        .collect();
    for preset in presets {
        let start = Instant::now();
        let bvh = SceneBvh::with_options(
            scene.clone(),
            BvhOptions {
                layout: BvhLayout::Cw,
                preset,
            },
        );
        println!(
            "{} build {:.3} s",
            preset.name(),
            start.elapsed().as_secs_f64()
        );
        for (name, rays) in &sets {
            let mut best = [f64::INFINITY; 2];
            let mut single = Vec::new();
            let mut packets = Vec::new();
            for _ in 0..3 {
                let start = thread_seconds();
                single = rays
                    .iter()
                    .map(|r| bvh.closest_hit(r, f32::INFINITY))
                    .collect();
                best[0] = best[0].min(thread_seconds() - start);
                let start = thread_seconds();
                packets = rays
                    .chunks(4096)
                    .flat_map(|c| bvh.closest_hits(c, f32::INFINITY))
                    .collect();
                best[1] = best[1].min(thread_seconds() - start);
            }
            assert!(single == packets, "{name}: packets differ from single rays");
            println!(
                "  {name:<11} single {:6.2} M rays/CPU-s  packets {:6.2} M rays/CPU-s",
                rays.len() as f64 / best[0] / 1e6,
                rays.len() as f64 / best[1] / 1e6
            );
        }
    }
}

/// CPU time of this thread (Linux), so that figures hold on a busy machine.
fn thread_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/thread-self/schedstat").expect("Linux schedstat");
    let nanos: u64 = stat
        .split_whitespace()
        .next()
        .and_then(|n| n.parse().ok())
        .expect("schedstat");
    nanos as f64 * 1e-9
}

/// The float32 data of a `.npy` file (version 1.0, as `vtfarm` writes it).
fn read_npy(path: &std::path::Path) -> Vec<f32> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let header = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    bytes[10 + header..]
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect()
}
