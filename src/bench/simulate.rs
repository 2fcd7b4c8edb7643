//! `vtfarm bench simulate`: the pure scheduler (`vtfarm_scheduler::sim`) on
//! simulated farms, driven by costs recorded from a real frame.
//!
//! Recording: the cockpit frame is rasterized once, then every reflector
//! triangle (in the Morton order the master uses) is traced as a package of
//! its own with `trace_package` on a one-thread rayon pool, so its wall time
//! is its compute time on one thread (several such pools run side by side,
//! one per core; each triangle is traced `--repeats` times and the least time
//! kept, to shed noise). Timed is what a worker's `busy_micros` covers:
//! `trace_package` plus the conversion of the bitmap for the wire. Each
//! result is encoded as the `PackageResult` message a worker would send, and
//! its length is the triangle's result size.
//!
//! Model (see `vtfarm_scheduler::sim`): a worker of speed 1 is one thread of
//! this machine; every worker has its own link of the given bandwidth and
//! latency to an infinitely fast master; results cost the mean recorded bytes
//! per triangle (the simulator has one size per item). Every simulated frame
//! is the recorded frame again, so from the second frame on the scheduler's
//! cost estimates are measured ones. Not modelled: a worker's per-frame
//! set-up (its rasterizer pass), the master's own link and compositing.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use serde::Serialize;
use vtfarm_cockpit::CockpitConfig;
use vtfarm_proto::{Message, PackageResult, WireBitmap, WirePackageStats, encode_message};
use vtfarm_render::Renderer;
use vtfarm_scheduler::sim::{SimConfig, SimFrame, SimJob, SimWorker, Simulation};
use vtfarm_scheduler::{FrameStats, JobId};
use vtfarm_vertex::{PackageOptions, Quality, SparseBitmap, trace_package};

use super::{CockpitJob, write_json};

#[derive(clap::Args)]
pub(crate) struct SimulateArgs {
    /// Worker counts to simulate.
    #[arg(long, value_delimiter = ',', default_values_t = [1usize, 2, 4, 8, 16, 32, 64])]
    workers: Vec<usize>,
    /// Frames per simulated job (each the recorded frame).
    #[arg(long, default_value_t = 3)]
    frames: usize,
    /// Link bandwidths in Mbit/s (every worker has its own link).
    #[arg(long, value_delimiter = ',', default_values_t = [10.0f64, 100.0])]
    link_mbit: Vec<f64>,
    /// One-way link latency in milliseconds.
    #[arg(long, default_value_t = 0.5)]
    latency_ms: f64,
    /// Fixed time per package on a worker (set-up), in milliseconds.
    #[arg(long, default_value_t = 1.0)]
    package_overhead_ms: f64,
    /// Multiplies every recorded cost (e.g. to emulate slower machines).
    #[arg(long, default_value_t = 1.0)]
    cost_scale: f64,
    /// Width of the recorded frame.
    #[arg(long, default_value_t = 1920)]
    width: u32,
    /// Height of the recorded frame.
    #[arg(long, default_value_t = 1080)]
    height: u32,
    /// Quality level of the recorded frame.
    #[arg(long, value_parser = crate::shared::parse_quality, default_value = "full")]
    quality: Quality,
    /// Cockpit detail (1.0 ≈ 100k triangles).
    #[arg(long, default_value_t = CockpitConfig::DEFAULT_DETAIL)]
    detail: f32,
    /// Threads recording costs (each a one-thread pool; default: all cores).
    #[arg(long)]
    threads: Option<usize>,
    /// Times each triangle is traced while recording (the least time is kept).
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Also writes the figures as JSON here (an array of rows).
    #[arg(long)]
    json: Option<PathBuf>,
}

/// Per-triangle costs of one frame, in the master's (Morton) order.
#[derive(Clone, Debug)]
pub(super) struct Recording {
    /// Reflector triangle ids in Morton order.
    pub(super) triangles: Vec<u32>,
    /// Compute seconds on one thread, per triangle.
    pub(super) seconds: Vec<f64>,
    /// Bytes of the `PackageResult` message of a one-triangle package.
    pub(super) result_bytes: Vec<u64>,
    /// Traced samples per triangle.
    pub(super) samples: Vec<u64>,
    /// Reflector pixels per triangle.
    pub(super) pixels: Vec<u64>,
    /// Bytes of a `PackageResult` without pixels (a message's fixed part).
    pub(super) empty_result_bytes: u64,
    /// Rasterizer and behind-buffer pass.
    pub(super) base_frame_seconds: f64,
    /// Wall time of the per-triangle tracing, all passes.
    pub(super) tracing_wall_seconds: f64,
}

impl Recording {
    fn total_seconds(&self) -> f64 {
        self.seconds.iter().sum()
    }

    fn total_bytes(&self) -> u64 {
        self.result_bytes.iter().sum()
    }

    /// Mean result bytes per triangle beyond a message's fixed part.
    fn bytes_per_item(&self) -> u64 {
        let n = self.result_bytes.len().max(1) as u64;
        let pixel_bytes: u64 = self
            .result_bytes
            .iter()
            .map(|b| b.saturating_sub(self.empty_result_bytes))
            .sum();
        pixel_bytes.div_ceil(n)
    }
}

/// Encoded size of the result message a worker sends for this package.
fn result_message_bytes(
    bitmap: WireBitmap,
    stats: WirePackageStats,
    busy: Duration,
    triangle_samples: Vec<u32>,
) -> Result<u64> {
    let message = Message::PackageResult(PackageResult {
        id: 0,
        bitmap,
        stats,
        busy_micros: busy.as_micros() as u64,
        triangle_samples,
    });
    Ok(encode_message(&message)?.len() as u64)
}

/// One triangle's measurements: (index, seconds, bytes, samples, pixels).
type Measure = (usize, f64, u64, u64, u64);

/// Traces each reflector triangle of `job` as a package of its own on
/// `threads` one-thread pools, `repeats` times, and records its least time,
/// its result bytes, samples and pixels.
pub(super) fn record(job: &CockpitJob, threads: usize, repeats: usize) -> Result<Recording> {
    let renderer = Renderer::new(job.scene.clone(), job.reflectors.clone());
    let start = Instant::now();
    let (_, ids) = renderer.base_frame(&job.setup);
    let behind = renderer.behind(&job.setup);
    let base_frame_seconds = start.elapsed().as_secs_f64();
    let frame = renderer.frame(&job.setup, &ids, &behind);
    let triangles = renderer.reflectors().to_vec();
    let n = triangles.len();
    let runs = n * repeats.max(1);
    let next = AtomicUsize::new(0);
    let start = Instant::now();
    let per_thread: Vec<Vec<Measure>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads.max(1))
            .map(|_| {
                s.spawn(|| -> Result<Vec<Measure>> {
                    let pool = rayon::ThreadPoolBuilder::new()
                        .num_threads(1)
                        .build()
                        .context("building a one-thread pool")?;
                    pool.install(|| {
                        let mut out = Vec::new();
                        loop {
                            let run = next.fetch_add(1, Ordering::Relaxed);
                            if run >= runs {
                                break;
                            }
                            let i = run % n;
                            let t0 = Instant::now();
                            let result = trace_package(
                                &frame,
                                &triangles[i..=i],
                                &PackageOptions::default(),
                                &mut |_| {},
                            );
                            let bitmap = WireBitmap::from(&result.bitmap);
                            let busy = t0.elapsed();
                            let bytes = result_message_bytes(
                                bitmap,
                                WirePackageStats::from(&result.stats),
                                busy,
                                result.triangle_samples,
                            )?;
                            out.push((
                                i,
                                busy.as_secs_f64(),
                                bytes,
                                result.stats.samples(),
                                result.stats.pixels,
                            ));
                        }
                        Ok(out)
                    })
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("a recording thread panicked"))
            .collect::<Result<_>>()
    })?;
    let tracing_wall_seconds = start.elapsed().as_secs_f64();
    let mut seconds = vec![f64::INFINITY; n];
    let mut result_bytes = vec![0; n];
    let mut samples = vec![0; n];
    let mut pixels = vec![0; n];
    for (i, s, b, k, p) in per_thread.into_iter().flatten() {
        seconds[i] = seconds[i].min(s);
        // Pixels and samples are deterministic; the message differs only in
        // the varint of its busy time.
        result_bytes[i] = result_bytes[i].max(b);
        samples[i] = k;
        pixels[i] = p;
    }
    let empty_result_bytes = result_message_bytes(
        WireBitmap::from(&SparseBitmap::default()),
        WirePackageStats::default(),
        Duration::ZERO,
        vec![0],
    )?;
    Ok(Recording {
        triangles,
        seconds,
        result_bytes,
        samples,
        pixels,
        empty_result_bytes,
        base_frame_seconds,
        tracing_wall_seconds,
    })
}

/// One simulated farm: the figures of its frames.
#[derive(Serialize)]
struct Row {
    workers: usize,
    link_mbit: f64,
    /// Half the workers (rounded down) at half speed.
    heterogeneous: bool,
    /// Sum of the workers' speeds: the ideal speed-up over one worker.
    ideal: f64,
    /// Last frame: sum of busy times over wall time.
    speedup: f64,
    /// Last frame: one worker's wall time (same link) over this wall time.
    speedup_vs_one: f64,
    /// Last frame: (max busy − mean busy) / mean busy.
    imbalance: f64,
    /// Last frame's wall time (first assignment to last result).
    wall_seconds: f64,
    imbalance_per_frame: Vec<f64>,
    wall_seconds_per_frame: Vec<f64>,
    /// Packages of the last frame.
    packages: u32,
    /// Straggler copies handed out in the last frame.
    duplicates: u32,
}

/// Simulates `frames` copies of the recorded frame on `workers`.
fn simulate(
    recording: &Recording,
    config: &SimConfig,
    workers: Vec<SimWorker>,
    frames: usize,
    cost_scale: f64,
) -> Result<Vec<FrameStats>> {
    let frame = SimFrame {
        items: recording.triangles.clone(),
        costs: recording.seconds.iter().map(|s| s * cost_scale).collect(),
    };
    let mut sim = Simulation::new(config.clone(), workers);
    sim.submit(SimJob {
        id: JobId(1),
        submit_at: Duration::ZERO,
        frames: vec![frame; frames],
    });
    let report = sim.drive();
    if !report.finished || report.frames.len() != frames || !report.violations.is_empty() {
        bail!(
            "the simulation did not complete: {} of {frames} frames, violations {:?}, refusals {:?}",
            report.frames.len(),
            report.violations,
            report.refusals
        );
    }
    Ok(report.frames.iter().map(|f| f.stats.clone()).collect())
}

pub(crate) fn run(args: SimulateArgs) -> Result<()> {
    if args.frames == 0 || args.workers.contains(&0) {
        bail!("--frames and every --workers entry must be at least 1");
    }
    if args.link_mbit.iter().any(|&m| m.is_nan() || m <= 0.0) {
        bail!("every --link-mbit entry must be positive");
    }
    let threads = args
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let job = CockpitJob::new(args.detail, args.width, args.height, args.quality)?;
    eprintln!(
        "recording per-triangle costs ({} reflector triangles, {}x{} {}, {threads} one-thread pools) ...",
        job.reflectors.len(),
        args.width,
        args.height,
        args.quality.name()
    );
    let recording = record(&job, threads, args.repeats)?;
    let total = recording.total_seconds() * args.cost_scale;
    let samples: u64 = recording.samples.iter().sum();
    let config = SimConfig {
        result_bytes_per_item: recording.bytes_per_item(),
        rays_per_second: samples as f64 / total.max(1e-9),
        ..SimConfig::default()
    };
    let latency = Duration::from_secs_f64(args.latency_ms.max(0.0) / 1e3);
    let overhead = Duration::from_secs_f64(args.package_overhead_ms.max(0.0) / 1e3);
    let worker = |speed: f64, mbit: f64| SimWorker {
        link_bits_per_second: mbit * 1e6,
        latency,
        package_overhead: overhead,
        ..SimWorker::with_speed(speed)
    };
    let mut rows = Vec::new();
    for &mbit in &args.link_mbit {
        let one = simulate(
            &recording,
            &config,
            vec![worker(1.0, mbit)],
            args.frames,
            args.cost_scale,
        )?;
        for &n in &args.workers {
            for heterogeneous in [false, true] {
                if heterogeneous && n < 2 {
                    continue;
                }
                let slow = if heterogeneous { n / 2 } else { 0 };
                let speeds: Vec<f64> = (0..n)
                    .map(|k| if k >= n - slow { 0.5 } else { 1.0 })
                    .collect();
                let stats = simulate(
                    &recording,
                    &config,
                    speeds.iter().map(|&s| worker(s, mbit)).collect(),
                    args.frames,
                    args.cost_scale,
                )?;
                let last = stats.last().context("no frame simulated")?;
                let one_last = one.last().context("no frame simulated")?;
                let wall = last.wall.as_secs_f64();
                rows.push(Row {
                    workers: n,
                    link_mbit: mbit,
                    heterogeneous,
                    ideal: speeds.iter().sum(),
                    speedup: last.speedup(),
                    speedup_vs_one: one_last.wall.as_secs_f64() / wall.max(1e-12),
                    imbalance: last.imbalance(),
                    wall_seconds: wall,
                    imbalance_per_frame: stats.iter().map(FrameStats::imbalance).collect(),
                    wall_seconds_per_frame: stats.iter().map(|f| f.wall.as_secs_f64()).collect(),
                    packages: last.packages,
                    duplicates: last.duplicates,
                });
            }
        }
    }
    print_report(&args, &job, &recording, &config, &rows);
    if let Some(path) = &args.json {
        write_json(path, &rows)?;
    }
    Ok(())
}

fn print_report(
    args: &SimulateArgs,
    job: &CockpitJob,
    rec: &Recording,
    config: &SimConfig,
    rows: &[Row],
) {
    let n = rec.triangles.len();
    let owning = rec.pixels.iter().filter(|&&p| p > 0).count();
    let total = rec.total_seconds() * args.cost_scale;
    let max = rec.seconds.iter().copied().fold(0.0, f64::max) * args.cost_scale;
    let bytes = rec.total_bytes();
    println!(
        "bench simulate — costs recorded from the cockpit ({} triangles), {}x{} {}, cover glass {} triangles ({} own pixels)",
        job.scene.triangles.len(),
        args.width,
        args.height,
        args.quality.name(),
        n,
        owning
    );
    println!(
        "  one thread: {:.3} s per frame{} (mean {:.2} ms, max {:.2} ms per triangle); {} samples, {} pixels",
        total,
        if args.cost_scale == 1.0 {
            String::new()
        } else {
            format!(" (recorded costs x{})", args.cost_scale)
        },
        total / n.max(1) as f64 * 1e3,
        max * 1e3,
        rec.samples.iter().sum::<u64>(),
        rec.pixels.iter().sum::<u64>()
    );
    println!(
        "  results: {:.2} MB per frame as one-triangle messages, {} bytes per triangle modelled (+ {} per message)",
        bytes as f64 / 1e6,
        config.result_bytes_per_item,
        config.header_bytes
    );
    println!(
        "  recording: base frame {:.3} s, per-triangle tracing {:.3} s wall ({} passes, least time kept)",
        rec.base_frame_seconds, rec.tracing_wall_seconds, args.repeats
    );
    println!(
        "model: speed 1 = one thread of this machine; {} frame(s) of the recorded costs; own link per worker, {} ms latency, {} ms per package",
        args.frames, args.latency_ms, args.package_overhead_ms
    );
    println!(
        "columns: mixed = half the workers at half speed; ideal = sum of speeds; busy/wall and imbalance of the last frame (imb. f1: first frame, uniform estimates); vs 1 wkr = wall of one speed-1 worker on the same link / wall; effic. = vs 1 wkr / ideal (above 100% where the links, not the compute, bound the frame)"
    );
    println!(
        "{:>7} {:>6} {:>6} {:>6} {:>9} {:>9} {:>7} {:>8} {:>8} {:>9} {:>8}",
        "workers",
        "link",
        "set",
        "ideal",
        "busy/wall",
        "vs 1 wkr",
        "effic.",
        "imb. f1",
        "imb. last",
        "wall ms",
        "packages"
    );
    for r in rows {
        println!(
            "{:>7} {:>6} {:>6} {:>6.1} {:>9.2} {:>9.2} {:>6.0}% {:>7.1}% {:>8.1}% {:>9.1} {:>8}",
            r.workers,
            format!("{}M", r.link_mbit),
            if r.heterogeneous { "mixed" } else { "equal" },
            r.ideal,
            r.speedup,
            r.speedup_vs_one,
            r.speedup_vs_one / r.ideal * 100.0,
            r.imbalance_per_frame.first().copied().unwrap_or(0.0) * 100.0,
            r.imbalance * 100.0,
            r.wall_seconds * 1e3,
            r.packages
        );
    }
    for &mbit in &args.link_mbit {
        println!(
            "  note: through one shared master link of {mbit} Mbit/s the results alone would take {:.3} s per frame (the model gives each worker its own link)",
            bytes as f64 * 8.0 / (mbit * 1e6)
        );
    }
    // The comparison with the paper: the fastest link, equal workers.
    let best_link = args.link_mbit.iter().copied().fold(0.0, f64::max);
    let equal: Vec<&Row> = rows
        .iter()
        .filter(|r| !r.heterogeneous && r.link_mbit == best_link)
        .collect();
    let linear_to = equal
        .iter()
        .filter(|r| r.speedup_vs_one >= 0.8 * r.ideal)
        .map(|r| r.workers)
        .max()
        .unwrap_or(0);
    let at16 = equal.iter().min_by_key(|r| r.workers.abs_diff(16));
    println!(
        "paper (§4.1, Fig. 9, 210k-polygon truck, 13.2 s per frame on one processor): near-linear speed-up to about ten processors, imbalance < 10%; our aim: < 5% at 16 workers"
    );
    print!("here ({best_link} Mbit, equal workers): efficiency >= 80% up to {linear_to} workers");
    match at16 {
        Some(r) => println!(
            "; at {} workers speed-up {:.2} over one worker, imbalance {:.1}% in the last frame: aim {}",
            r.workers,
            r.speedup_vs_one,
            r.imbalance * 100.0,
            if r.imbalance < 0.05 { "met" } else { "missed" }
        ),
        None => println!(),
    }
    if args.cost_scale == 1.0 && total > 0.0 && total < 13.2 {
        println!(
            "  (this frame is {:.3} s on one thread; --cost-scale {:.0} gives the paper's work per frame)",
            total,
            13.2 / total
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The recording has one entry per reflector triangle, in the master's
    /// Morton order, and its one-triangle packages together cover exactly
    /// the reflector pixels of a whole-frame render (package independence:
    /// the per-triangle sizes and costs belong to the same work).
    #[test]
    fn recording_covers_every_reflector_triangle_in_morton_order() {
        let job = CockpitJob::new(0.3, 64, 36, Quality::Full).unwrap();
        let recording = record(&job, 2, 1).unwrap();
        let expected = vtfarm_render::morton_order(&job.scene, job.reflectors.clone());
        assert_eq!(recording.triangles, expected);
        let n = expected.len();
        assert_eq!(recording.seconds.len(), n);
        assert_eq!(recording.result_bytes.len(), n);
        assert!(recording.seconds.iter().all(|s| s.is_finite() && *s >= 0.0));
        assert!(
            recording
                .result_bytes
                .iter()
                .all(|&b| b >= recording.empty_result_bytes)
        );

        let renderer = Renderer::new(job.scene.clone(), job.reflectors.clone());
        let frame = renderer.render(
            &job.setup,
            &vtfarm_render::RenderOptions::default(),
            &mut |_, _| {},
        );
        assert!(frame.stats.pixels > 0, "the glass is in view");
        assert_eq!(recording.pixels.iter().sum::<u64>(), frame.stats.pixels);
        // Every covered pixel costs at least its two colours (24 bytes) and
        // an object id; a triangle without pixels sends about the fixed part.
        let empty = recording.empty_result_bytes;
        for (&p, &b) in recording.pixels.iter().zip(&recording.result_bytes) {
            if p > 0 {
                assert!(b >= empty + 25 * p, "pixels {p}, bytes {b}");
            } else {
                assert!(b < empty + 32, "no pixels, bytes {b}");
            }
        }
    }
}
