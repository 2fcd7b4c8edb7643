//! `vtfarm bench simulate`: the master's core and the workers' sessions on
//! simulated farms ([`vtfarm_farmsim`]), driven by costs recorded from a real
//! frame.
//!
//! Recording: the cockpit frame is rasterized once, then every reflector
//! triangle (in the Morton order the master uses) is traced as a package of
//! its own with `trace_package` on one-thread rayon pools (several side by
//! side, `--threads`; each triangle `--repeats` times, the least time kept).
//! Every cost is the **CPU time** of the thread that ran it, not wall time:
//! on a machine busy with other work the wall time grew with that load, and
//! the model then shared the cores out once more. Timed per triangle is what
//! a worker's `busy_micros` covers (`trace_package` and the result's
//! encoding) less a package's own cost (tracing no triangle, encoding the
//! empty result), which the model charges once per package. Each result is
//! encoded as the `PackageResult` message a worker would send; its length
//! is the triangle's result size.
//!
//! Per-frame fixed costs, each the least CPU time of three runs on one
//! thread with every run's output kept (the real processes keep several
//! frames in flight, so each frame writes fresh memory): a worker's set-up
//! (its ID buffers), the master's base frame, its checking and compositing
//! of the results, the finished frame for the wire and the journal, and the
//! submitter's decoding and PNG. The model ([`vtfarm_farmsim`]) runs the real
//! `MasterCore` and `WorkerSession`s with these costs; with
//! `--shared-cores` everything shares one machine, optionally with the
//! other work a real run met there (`--background-cores`). Every simulated
//! frame is the recorded frame again, so from the second frame on the
//! scheduler's cost estimates are measured ones. Not modelled: the
//! transport's own CPU (QUIC, the runtimes).
//!
//! `--worker-speed` and `--worker-mbit` give each worker its own speed and
//! link: the lab's CPU quotas and rate-limited links (`scripts/lab.sh`,
//! docs/lab.md), which slow the workers and leave the master as it is.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use serde::Serialize;
use vtfarm_cockpit::CockpitConfig;
use vtfarm_proto::PhaseKind;
use vtfarm_proto::{
    FrameDone, Message, PackageResult, ResultPixels, SceneData, WireBitmap, WireBitmapParts,
    WireImage, WireImageFormat, WirePackageStats, decode_message, encode_message,
};
use vtfarm_render::FrameSetup;
use vtfarm_render::Renderer;
use vtfarm_scene::TriangleId;

use crate::support::{CpuClock, cpu_time};
use vtfarm_farmsim::{
    FarmCosts, FarmFrame, FarmJob, MasterCosts, SimulationConfig, WorkerSpec,
    background_threads_for, cpu_per_frame, simulate_farm, steady_background_cores,
    steady_frame_seconds,
};
use vtfarm_vertex::{Frame, PackageOptions, PixelRect, Quality, SparseBitmap, trace_package};

use super::{CockpitJob, write_json};

#[derive(clap::Args)]
pub struct SimulateArgs {
    /// Worker counts to simulate.
    #[arg(long, value_delimiter = ',', default_values_t = [1usize, 2, 4, 8, 16, 32, 64])]
    workers: Vec<usize>,
    /// Frames per simulated job (each the recorded frame).
    /// The frame time is taken from the first's delivery to the last's, so
    /// more frames blur the pipeline's ramp up and down less.
    #[arg(long, default_value_t = 32)]
    frames: usize,
    /// Link bandwidths in Mbit/s, one simulation each: every worker's own
    /// link (unless --worker-mbit) and the master's one shared link.
    #[arg(long, value_delimiter = ',', default_values_t = [1000.0f64, 100.0])]
    link_mbit: Vec<f64>,
    /// One-way link latency in milliseconds.
    #[arg(long, default_value_t = 0.5)]
    latency_ms: f64,
    /// Fixed CPU time per package on a worker beside its triangles', in
    /// milliseconds (default: measured, tracing no triangle and encoding
    /// the empty result).
    #[arg(long)]
    package_overhead_ms: Option<f64>,
    /// Leaves out the per-frame fixed costs (worker set-up, master base
    /// frame): the load balancer alone, as in the paper's figures.
    #[arg(long)]
    no_fixed_costs: bool,
    /// Every worker already holds the scene with its renderer (BVH), from
    /// an earlier job of it: a shared cluster's common case. Without it
    /// each worker gets the scene over the links and, on its first frame,
    /// decodes it and builds the renderer (measured here, one thread).
    #[arg(long)]
    workers_hold_scene: bool,
    /// Multiplies every recorded tracing cost (36: the paper's work per
    /// frame).
    #[arg(long, default_value_t = 1.0)]
    cost_scale: f64,
    /// Multiplies the per-frame fixed costs (the master's base frame, the
    /// workers' set-up). Default 1: rasterizing does not grow with the
    /// traced work per frame (the paper's came from graphics hardware);
    /// set it like --cost-scale to emulate machines that are slower at
    /// everything.
    #[arg(long, default_value_t = 1.0)]
    fixed_cost_scale: f64,
    /// Cores of the master's own machine (default: this machine's): its
    /// base frame is rasterized in parallel (the rasterizer is bit-identical
    /// for any thread count), so it takes the recorded one-thread time
    /// divided by this. Its driver handles one input at a time.
    #[arg(long)]
    master_threads: Option<u32>,
    /// Each worker's speed (1: one thread of this machine; 0.45: a worker
    /// held to 45% of a core by a CPU quota, as `scripts/lab.sh
    /// --cpu-percent 45` runs it): one value for every worker, or one per
    /// worker with a single --workers count (`--workers 2 --worker-speed
    /// 0.45,0.15`). Only the workers slow down: the master and the
    /// submitter keep their machine's cores (--master-threads). Given, the
    /// rows with half the workers at half speed are left out, and each
    /// farm's "vs 1" is over its first worker alone. (With --shared-cores
    /// a slower worker needs more of the shared cores, unlike a quota.)
    #[arg(long, value_delimiter = ',', value_name = "SPEED")]
    worker_speed: Vec<f64>,
    /// Each worker's own link in Mbit/s, with the same rule as
    /// --worker-speed (`--workers 2 --worker-mbit 100,10`: the paper's
    /// mixture of 10 and 100 Mbit connections); --link-mbit stays the
    /// master's one shared link. Default: each --link-mbit value, for
    /// every worker's link too.
    #[arg(long, value_delimiter = ',', value_name = "MBIT")]
    worker_mbit: Vec<f64>,
    /// Cores of each worker's machine: a package uses them all (speed 1 is
    /// one thread each; the tracing is taken as parallel without loss), a
    /// frame's set-up one, so it overlaps a package on a spare core.
    #[arg(long, default_value_t = 1)]
    worker_threads: u32,
    /// Everything on one machine of this many cores (a localhost farm, as
    /// `scripts/scaling.sh` runs it): workers, master and submitter share them.
    #[arg(long)]
    shared_cores: Option<u32>,
    /// With --shared-cores: the cores other work used on that machine while
    /// the real run was measured (`scripts/scaling.sh` reads them from
    /// /proc/stat), one value for every --workers entry or one each. The
    /// other work is modelled as threads that always want to run, as many
    /// as make it use that much beside the simulated farm; the frame time
    /// on the idle machine is reported too.
    #[arg(long, value_delimiter = ',')]
    background_cores: Vec<f64>,
    /// Takes the per-frame fixed costs (the master's base frame, a worker's
    /// set-up) from the phases in a real run's `stats.json` (medians over
    /// the frames after the first) instead of timing them here.
    #[arg(long, value_name = "STATS_JSON")]
    fixed_costs: Option<PathBuf>,
    /// Width of the recorded frame.
    #[arg(long, default_value_t = 1920)]
    width: u32,
    /// Height of the recorded frame.
    #[arg(long, default_value_t = 1080)]
    height: u32,
    /// Quality level of the recorded frame.
    #[arg(long, value_parser = crate::support::parse_quality, default_value = "full")]
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
    /// The master's base frame (shaded, with its ID buffer), one thread.
    pub(super) base_frame_seconds: f64,
    /// A worker's frame set-up (ID and behind buffers), one thread.
    pub(super) worker_setup_seconds: f64,
    /// A worker's first frame of the scene beside its set-up: the scene
    /// decoded and checked, the renderer (BVH) built, one thread.
    pub(super) scene_prepare_seconds: f64,
    /// The set-up of a frame that differs from the worker's last only in
    /// the sun (its ID buffers kept), one thread.
    pub(super) sun_only_setup_seconds: f64,
    /// The master's checking and compositing of a frame's results, one thread.
    pub(super) composite_seconds: f64,
    /// The master per frame: the image for the wire (`WireImage::encode`),
    /// one thread's CPU: its sRGB conversion, all of it (on every core in
    /// the master, with the base frame of a split frame)...
    pub(super) frame_out_seconds: f64,
    /// ... that of the rectangle a split frame's results write
    /// ([`Recording::written`]), per finished split frame (on every core)...
    pub(super) frame_out_written_seconds: f64,
    /// ... and its compression (one thread).
    pub(super) frame_out_serial_seconds: f64,
    /// The rectangle a split frame's results write, as the master tracks
    /// it: the union of the recorded results' rectangles.
    pub(super) written: PixelRect,
    /// The master's driver per finished frame once encoded: the
    /// `FrameDone`'s bytes and the telemetry's copy.
    pub(super) frame_sent_seconds: f64,
    /// A finished frame's image on the wire (`FrameDone::image`, sRGB as
    /// `vtfarm submit` asks): what a whole frame's result carries.
    pub(super) frame_bytes: u64,
    /// The master's journal thread per finished frame: compress and write.
    pub(super) journal_seconds: f64,
    /// The submitter per finished frame: decode, PNG and timeline written.
    pub(super) submitter_seconds: f64,
    /// A package's own cost beside its triangles' (`seconds` leave it out).
    pub(super) package_seconds: f64,
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

/// Times work by the CPU time of the thread that runs it: a cost recorded
/// on a machine busy with other work is the CPU the work needs, not the
/// wall time it happened to get (timed by the wall clock, the costs grew
/// with the machine's load, and the simulator then counted that load once
/// more when it shared the cores). The wall clock where no thread clock is.
struct CpuStopwatch {
    cpu: Option<Duration>,
    wall: Instant,
}

impl CpuStopwatch {
    fn start() -> CpuStopwatch {
        CpuStopwatch {
            cpu: cpu_time(CpuClock::Thread),
            wall: Instant::now(),
        }
    }

    /// CPU time of this thread since `start` (which must have run on it).
    fn elapsed(&self) -> Duration {
        match (self.cpu, cpu_time(CpuClock::Thread)) {
            (Some(from), Some(to)) => to.saturating_sub(from),
            _ => self.wall.elapsed(),
        }
    }
}

/// The least CPU time `f` takes on `pool` in [`FIXED_COST_RUNS`] runs. Each
/// run's output is kept until all have run: the real master and workers
/// keep several frames' buffers at once (frames in flight), so each frame
/// writes fresh memory and pays for its page faults (timed with each
/// output dropped before the next run, the set-up read 0.048 s against the
/// workers' 0.060 s of CPU per frame beside their tracing).
fn least_cpu_seconds<T: Send>(pool: &rayon::ThreadPool, f: impl Fn() -> T + Sync) -> f64 {
    let mut kept = Vec::with_capacity(FIXED_COST_RUNS);
    let mut least = f64::INFINITY;
    for _ in 0..FIXED_COST_RUNS {
        let (seconds, output) = pool.install(|| {
            let clock = CpuStopwatch::start();
            let output = f();
            (clock.elapsed().as_secs_f64(), output)
        });
        least = least.min(seconds);
        kept.push(output);
    }
    least
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
        pixels: ResultPixels::Bitmap(bitmap),
        stats,
        busy_micros: busy.as_micros() as u64,
        setup_micros: 0,
        triangle_samples,
        stage: None,
        mesh: None,
    });
    Ok(encode_message(&message)?.len() as u64)
}

/// Runs of each per-frame fixed cost when recording (the least CPU time is
/// kept, whatever `--repeats` says: they are cheap beside the tracing).
const FIXED_COST_RUNS: usize = 3;

/// One triangle's measurements: (index, seconds, bytes, samples, pixels,
/// and from its first pass the result's bitmap as sent).
type Measure = (usize, f64, u64, u64, u64, Option<WireBitmap>);

/// A package's own cost beside its triangles', from the least times of
/// one-triangle packages (`single`, each paying it once) and of all of them
/// as one package (`whole`, paying it once): a package sets up and encodes
/// more than an empty one does (`empty`, the floor), so n one-triangle
/// packages cost more than one of n triangles, by n − 1 overheads.
fn package_overhead(single: &[f64], whole: f64, empty: f64) -> f64 {
    let n = single.len();
    if n < 2 || !whole.is_finite() {
        return empty;
    }
    let sum: f64 = single.iter().sum();
    ((sum - whole) / (n - 1) as f64).max(empty)
}

/// One pass of [`record`]: every triangle of `triangles` traced as a
/// package of its own on `threads` one-thread pools sharing `frame`; the
/// result bitmaps kept where `keep`.
fn trace_pass(
    frame: &Frame<'_>,
    triangles: &[TriangleId],
    threads: usize,
    keep: bool,
) -> Result<Vec<Vec<Measure>>> {
    let next = AtomicUsize::new(0);
    std::thread::scope(|s| {
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
                            let i = next.fetch_add(1, Ordering::Relaxed);
                            if i >= triangles.len() {
                                break;
                            }
                            let clock = CpuStopwatch::start();
                            let result = trace_package(
                                frame,
                                &triangles[i..=i],
                                &PackageOptions::default(),
                                &mut |_| {},
                            );
                            let bitmap = WireBitmap::encode(&result.bitmap, WireBitmapParts::Color);
                            let busy = clock.elapsed();
                            let kept = keep.then(|| bitmap.clone());
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
                                kept,
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
    })
}

/// Traces each reflector triangle of `job` as a package of its own on
/// `threads` one-thread pools, `repeats` times, and records its least time,
/// its result bytes, samples and pixels.
pub(super) fn record(job: &CockpitJob, threads: usize, repeats: usize) -> Result<Recording> {
    let renderer = Renderer::new(job.scene.clone(), job.reflectors.clone());
    // The fixed costs on one thread, like a `--threads 1` worker's.
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .context("building a one-thread pool")?;
    // Once untimed first: a worker builds its shadow maps on its first
    // frame and keeps them (`ShadowCache`), so a frame's set-up is timed
    // with them built (with `--repeats 1` the first build was counted).
    let (ids, behind) = renderer.id_buffers(&job.setup);
    let base_frame_seconds = least_cpu_seconds(&one_thread, || renderer.base_frame(&job.setup));
    // A frame of a new view rasterizes its ID buffers; one that differs
    // from the worker's last only in the sun reuses them (`IdBufferCache`).
    let worker_setup_seconds = least_cpu_seconds(&one_thread, || {
        renderer.id_buffer_cache().clear();
        renderer.id_buffers(&job.setup)
    });
    let sun_only_setup_seconds = least_cpu_seconds(&one_thread, || renderer.id_buffers(&job.setup));
    // A worker's first frame of the scene: `SceneCache::store`'s check and
    // decode, then `FrameParts::build`'s new renderer.
    let scene_data = SceneData::from_scene(&job.scene);
    let scene_prepare_seconds = least_cpu_seconds(&one_thread, || {
        let scene = scene_data
            .to_scene()
            .expect("the scene's own encoding decodes");
        Renderer::new(Arc::new(scene), job.reflectors.clone())
    });
    let frame = renderer.frame(&job.setup, &ids, &behind);
    // A package's own cost beside its triangles', at least: tracing none
    // and encoding the empty result.
    let empty_package_seconds = least_cpu_seconds(&one_thread, || {
        let result = trace_package(&frame, &[], &PackageOptions::default(), &mut |_| {});
        WireBitmap::encode(&result.bitmap, WireBitmapParts::Color)
    });
    let triangles = renderer.reflectors().to_vec();
    let n = triangles.len();
    // All triangles as one package (a whole frame's), each time on a frame
    // set up afresh (see below).
    let whole_package_seconds = least_cpu_seconds(&one_thread, || {
        let (ids, behind) = renderer.id_buffers(&job.setup);
        let frame = renderer.frame(&job.setup, &ids, &behind);
        let result = trace_package(&frame, &triangles, &PackageOptions::default(), &mut |_| {});
        WireBitmap::encode(&result.bitmap, WireBitmapParts::Color)
    });
    let start = Instant::now();
    // Each pass on a frame set up afresh: a worker computes a glass pixel's
    // thin-glass terms once per frame and keeps them (`Behind`), so a pass
    // over a frame already traced would time its packages without them.
    let mut per_thread: Vec<Vec<Measure>> = Vec::new();
    for pass in 0..repeats.max(1) {
        let (ids, behind) = renderer.id_buffers(&job.setup);
        let frame = renderer.frame(&job.setup, &ids, &behind);
        per_thread.extend(trace_pass(&frame, &triangles, threads, pass == 0)?);
    }
    let tracing_wall_seconds = start.elapsed().as_secs_f64();
    let mut seconds = vec![f64::INFINITY; n];
    let mut result_bytes = vec![0; n];
    let mut samples = vec![0; n];
    let mut pixels = vec![0; n];
    let mut bitmaps = Vec::with_capacity(n);
    let per_thread: Vec<Measure> = per_thread.into_iter().flatten().collect();
    for &(i, s, ..) in &per_thread {
        seconds[i] = seconds[i].min(s);
    }
    let package_seconds = package_overhead(&seconds, whole_package_seconds, empty_package_seconds);
    seconds
        .iter_mut()
        .for_each(|s| *s = (*s - package_seconds).max(0.0));
    for (i, _, b, k, p, bitmap) in per_thread {
        bitmaps.extend(bitmap.map(|bitmap| (i, bitmap)));
        // Pixels and samples are deterministic; the message differs only in
        // the varint of its busy time.
        result_bytes[i] = result_bytes[i].max(b);
        samples[i] = k;
        pixels[i] = p;
    }
    let written = (bitmaps.iter()).fold(PixelRect::EMPTY, |written, (_, b)| {
        written.union(PixelRect {
            x0: b.x0,
            y0: b.y0,
            x1: b.x0 + b.width,
            y1: b.y0 + b.height,
        })
    });
    let composite_seconds = composite_time(&renderer, job, &triangles, bitmaps)?;
    let FrameOut {
        convert_seconds: frame_out_seconds,
        convert_written_seconds: frame_out_written_seconds,
        compress_seconds: frame_out_serial_seconds,
        sent_seconds: frame_sent_seconds,
        journal_seconds,
        submitter_seconds,
        frame_bytes,
    } = frame_out_time(&renderer, job, written)?;
    let empty_result_bytes = result_message_bytes(
        WireBitmap::encode(&SparseBitmap::default(), WireBitmapParts::Color),
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
        worker_setup_seconds,
        scene_prepare_seconds,
        sun_only_setup_seconds,
        composite_seconds,
        frame_out_seconds,
        frame_out_written_seconds,
        frame_out_serial_seconds,
        written,
        frame_sent_seconds,
        frame_bytes,
        journal_seconds,
        submitter_seconds,
        package_seconds,
        tracing_wall_seconds,
    })
}

/// The master's work on a finished frame, as `MasterCore` and its driver do
/// it, each part's CPU on one thread (see [`FrameOut`]).
struct FrameOut {
    /// The frame's image for the wire, on one thread: the sRGB
    /// conversion...
    convert_seconds: f64,
    /// ... that of the written rectangle only, into the base frame's
    /// bytes converted ahead (`vtfarm_master_core`'s split frames)...
    convert_written_seconds: f64,
    /// ... and the rest of `WireImage::encode` (zstd).
    compress_seconds: f64,
    /// The `FrameDone` encoded for the submitter and the telemetry's copy.
    sent_seconds: f64,
    /// The journal's thread: its copy compressed and written.
    journal_seconds: f64,
    /// The submitter: decoded, the PNG and the timeline written, as
    /// `vtfarm submit` does.
    submitter_seconds: f64,
    /// The image's bytes on the wire.
    frame_bytes: u64,
}

/// [`FrameOut`] of the job's frame, its results written within `written`.
fn frame_out_time(renderer: &Renderer, job: &CockpitJob, written: PixelRect) -> Result<FrameOut> {
    // The encoding's tasks on this thread, the timed one: a pool of its
    // own thread would spin beside the parts timed after it (the
    // submitter's read 0.005 s for 0.003 s on this 2-thread machine).
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .use_current_thread()
        .build()
        .context("building a pool of this thread")?;
    let (base, _) = renderer.base_frame(&job.setup);
    let dir = tempfile::tempdir()?;
    let journal = vtfarm_master::Journal::open(dir.path())?;
    // The job's directory, which its queued record would have made.
    std::fs::create_dir_all(dir.path().join("jobs").join(format!("{:012}", 1)))?;
    let [
        mut converted,
        mut converted_written,
        mut encoded,
        mut sent,
        mut journaled,
        mut submitted,
    ] = [f64::INFINITY; 6];
    let mut srgb = Vec::new();
    let mut frame_bytes = 0;
    let mut kept = Vec::with_capacity(FIXED_COST_RUNS);
    // As `vtfarm submit` asks for it (it writes only PNGs).
    let format = WireImageFormat::Srgb8;
    let (columns, rows) = (written.x0..written.x1, written.y0..written.y1);
    for _ in 0..FIXED_COST_RUNS {
        let (convert, convert_written, encode, image) = pool.install(|| {
            let clock = CpuStopwatch::start();
            base.to_srgb8_into(&mut srgb);
            let convert = clock.elapsed().as_secs_f64();
            let clock = CpuStopwatch::start();
            base.to_srgb8_region_into(&mut srgb, columns.clone(), rows.clone());
            let convert_written = clock.elapsed().as_secs_f64();
            let clock = CpuStopwatch::start();
            let image = WireImage::encode(&base, format);
            (
                convert,
                convert_written,
                clock.elapsed().as_secs_f64(),
                image,
            )
        });
        converted = converted.min(convert);
        converted_written = converted_written.min(convert_written);
        encoded = encoded.min(encode);
        let clock = CpuStopwatch::start();
        let done = FrameDone {
            job: 1,
            frame: 0,
            image,
            stats: Default::default(),
            aux: None,
        };
        let record = vtfarm_master::Record::FrameDone(Box::new(done.clone()));
        // The master's telemetry keeps a copy of the image as sent.
        let kept_image = done.image.clone();
        frame_bytes = done.image.pixels.len() as u64;
        let message = encode_message(&Message::FrameDone(done))?;
        sent = sent.min(clock.elapsed().as_secs_f64());
        let clock = CpuStopwatch::start();
        journal.write(record)?;
        journaled = journaled.min(clock.elapsed().as_secs_f64());
        let clock = CpuStopwatch::start();
        let Message::FrameDone(done) = decode_message(&message[4..])? else {
            bail!("a FrameDone decoded as another message");
        };
        let (width, height, pixels) = done.image.into_srgb8()?;
        vtfarm_imaging::write_srgb8_png(&dir.path().join("frame.png"), width, height, &pixels)?;
        let timeline = vtfarm_master::timeline::timeline_svg(&done.stats);
        std::fs::write(dir.path().join("timeline.svg"), timeline)?;
        submitted = submitted.min(clock.elapsed().as_secs_f64());
        kept.push((kept_image, pixels));
    }
    Ok(FrameOut {
        convert_seconds: converted.min(encoded),
        convert_written_seconds: converted_written.min(converted),
        compress_seconds: (encoded - converted).max(0.0),
        sent_seconds: sent,
        journal_seconds: journaled,
        submitter_seconds: submitted,
        frame_bytes,
    })
}

/// The master's work on the results of a frame, on one thread: each
/// one-triangle result decoded, checked for pixel ownership and composited,
/// as `MasterCore` does.
fn composite_time(
    renderer: &Renderer,
    job: &CockpitJob,
    triangles: &[u32],
    bitmaps: Vec<(usize, WireBitmap)>,
) -> Result<f64> {
    let (base, ids) = renderer.base_frame(&job.setup);
    let (width, height) = (base.width, base.height);
    // A colour-only job: the colours straight from the wire.
    let mut image = base;
    let mut least = f64::INFINITY;
    for _ in 0..FIXED_COST_RUNS {
        let clock = CpuStopwatch::start();
        for (i, bitmap) in &bitmaps {
            let colors = bitmap.colors_within(width, height)?;
            if let Some((p, _)) = colors
                .iter()
                .find(|(p, _)| ids.triangle[*p] != triangles[*i])
            {
                bail!(
                    "triangle {}'s result writes the foreign pixel {p}",
                    triangles[*i]
                );
            }
            for (p, c) in colors {
                image.pixels[p] = c;
            }
        }
        least = least.min(clock.elapsed().as_secs_f64());
    }
    Ok(least)
}

/// One simulated farm: the figures of its frames.
#[derive(Serialize)]
struct Row {
    workers: usize,
    /// The master's shared link.
    link_mbit: f64,
    /// Half the workers (rounded down) at half speed.
    heterogeneous: bool,
    /// Each worker's speed (1: one thread of this machine).
    worker_speeds: Vec<f64>,
    /// Each worker's own link, Mbit/s.
    worker_mbit: Vec<f64>,
    /// Sum of the workers' speeds: the ideal speed-up over one worker.
    ideal: f64,
    /// Last frame: sum of busy times over its wall time (the scheduler's
    /// figure; with pipelined frames, others' work shares that wall time).
    speedup: f64,
    /// One worker's `frame_seconds` (same link; the first worker's speed
    /// and link with --worker-speed or --worker-mbit, else speed 1) over
    /// this one's.
    speedup_vs_one: f64,
    /// Per frame: the lifetime window's imbalance (see `FarmFrame::imbalance`).
    imbalance_per_frame: Vec<f64>,
    /// Per frame: announcement to delivery.
    latency_seconds_per_frame: Vec<f64>,
    /// Per frame: its delivery, seconds from the job's start (a script sets
    /// any window of frames beside a real run's arrivals: `scripts/lab.sh`
    /// takes the second half).
    done_seconds_per_frame: Vec<f64>,
    /// Per frame: when its last result reached the master, seconds from the
    /// job's start (`FarmFrame::completed_at`: frames leave in order, so on
    /// a farm of unequal workers deliveries bunch; these do not, and
    /// `scripts/lab.sh` measures its rates over them, as the master's
    /// "frame complete" log lines of a real run).
    completed_seconds_per_frame: Vec<f64>,
    /// Per frame: the CPU seconds each process had used by its delivery
    /// (the master, each worker, the submitter; see `FarmFrame::cpu`). A
    /// worker's CPU is on its own machine: at speed 0.45, 1 / 0.45 of the
    /// CPU the same work takes here.
    cpu_at_delivery: Vec<Vec<f64>>,
    /// Packages of the last frame.
    packages: u32,
    /// Straggler copies handed out in the last frame.
    duplicates: u32,
    /// Steady-state seconds per frame (`steady_frame_seconds`).
    frame_seconds: f64,
    /// The same farm without the other work on its shared machine
    /// (`--background-cores`); `frame_seconds` when there is none.
    frame_seconds_idle: f64,
    /// The modelled other work: always-runnable threads, and the cores
    /// they got over the steady window (`steady_background_cores`).
    background_threads: f64,
    background_cores: f64,
    /// CPU seconds per frame of the master and each worker
    /// (`cpu_per_frame`), to set beside the real processes'.
    cpu_per_frame: Vec<f64>,
    /// One thread's tracing per frame over (`frame_seconds` × `ideal`):
    /// at most 1 (see `steady_frame_seconds`).
    efficiency: f64,
    /// Largest imbalance of the frames after the first that were delivered
    /// before the last frame was announced (then the job drains: workers
    /// idle when no frame is left to start); of all after the first when
    /// none was.
    imbalance_after_first: f64,
}

impl Row {
    /// The table's "set": mixed (half the workers at half speed), equal
    /// (one speed and link), or given (workers that differ, as given).
    fn set_name(&self) -> &'static str {
        let same = |v: &[f64]| v.windows(2).all(|w| w[0] == w[1]);
        if self.heterogeneous {
            "mixed"
        } else if same(&self.worker_speeds) && same(&self.worker_mbit) {
            "equal"
        } else {
            "given"
        }
    }

    /// The figures of `frames` simulated on `workers`, against `one`, the
    /// same job on one worker, and `work`, one thread's tracing per frame.
    fn new(
        frames: &[FarmFrame],
        one: &[FarmFrame],
        work: f64,
        workers: &[WorkerSpec],
        link_mbit: f64,
        heterogeneous: bool,
    ) -> Result<Row> {
        let last = &frames.last().context("no frame simulated")?.stats;
        let worker_speeds: Vec<f64> = workers.iter().map(|w| w.speed).collect();
        let ideal: f64 = worker_speeds.iter().sum();
        let frame_seconds = steady_frame_seconds(frames);
        // The steady frames: after the first (the start-up) and delivered
        // before the last frame was announced (from then on the job
        // drains: a worker that runs out of work finds no frame to start).
        let last_announced = frames.last().context("no frame simulated")?.started_at;
        let after_first = frames.get(1..).filter(|f| !f.is_empty()).unwrap_or(frames);
        let undrained: Vec<&FarmFrame> = (after_first.iter())
            .filter(|f| f.done_at <= last_announced)
            .collect();
        let steady: Vec<&FarmFrame> = if undrained.is_empty() {
            after_first.iter().collect()
        } else {
            undrained
        };
        Ok(Row {
            workers: workers.len(),
            link_mbit,
            heterogeneous,
            worker_speeds,
            worker_mbit: (workers.iter())
                .map(|w| w.link_bits_per_second / 1e6)
                .collect(),
            ideal,
            speedup: last.speedup,
            speedup_vs_one: steady_frame_seconds(one) / frame_seconds.max(1e-12),
            imbalance_per_frame: frames.iter().map(|f| f.imbalance).collect(),
            latency_seconds_per_frame: (frames.iter())
                .map(|f| f.done_at.saturating_sub(f.started_at).as_secs_f64())
                .collect(),
            done_seconds_per_frame: frames.iter().map(|f| f.done_at.as_secs_f64()).collect(),
            completed_seconds_per_frame: (frames.iter())
                .map(|f| f.completed_at.as_secs_f64())
                .collect(),
            cpu_at_delivery: frames.iter().map(|f| f.cpu.clone()).collect(),
            packages: last.packages,
            duplicates: last.duplicates,
            frame_seconds,
            frame_seconds_idle: frame_seconds,
            background_threads: 0.0,
            background_cores: 0.0,
            cpu_per_frame: cpu_per_frame(frames),
            efficiency: work / (frame_seconds * ideal).max(1e-12),
            imbalance_after_first: (steady.iter()).map(|f| f.imbalance).fold(0.0, f64::max),
        })
    }
}

/// A per-worker option (`--worker-speed`, `--worker-mbit`): not given, one
/// value for every worker, or one value per worker of the one simulated
/// count.
#[derive(Clone, Debug, PartialEq)]
enum PerWorker {
    Default,
    Every(f64),
    Each(Vec<f64>),
}

impl PerWorker {
    /// `values` of `option` for the farms of `workers`: each positive and
    /// finite; more than one only as many as the one --workers count.
    fn parse(option: &str, values: &[f64], workers: &[usize]) -> Result<PerWorker> {
        if let Some(bad) = values.iter().find(|v| !(v.is_finite() && **v > 0.0)) {
            bail!("every {option} entry must be positive and finite, not {bad}");
        }
        Ok(match (values, workers) {
            ([], _) => PerWorker::Default,
            ([one], _) => PerWorker::Every(*one),
            (each, [n]) if each.len() == *n => PerWorker::Each(each.to_vec()),
            (each, _) => bail!(
                "{option} gives {} values but --workers is {}: give one value for every \
                 worker, or one per worker with a single --workers count",
                each.len(),
                workers
                    .iter()
                    .map(usize::to_string)
                    .collect::<Vec<_>>()
                    .join(",")
            ),
        })
    }

    /// Worker `k`'s value (`default` when the option was not given).
    fn value(&self, k: usize, default: f64) -> f64 {
        match self {
            PerWorker::Default => default,
            PerWorker::Every(v) => *v,
            PerWorker::Each(each) => each[k],
        }
    }
}

/// The `n` workers of a simulated farm: `base` with each one's speed and
/// own link from `speeds` and `links` (by default `base`'s), the last
/// `slow` of them at half that speed.
fn farm_workers(
    speeds: &PerWorker,
    links: &PerWorker,
    n: usize,
    slow: usize,
    base: &WorkerSpec,
) -> Vec<WorkerSpec> {
    (0..n)
        .map(|k| {
            let half = if k + slow >= n { 0.5 } else { 1.0 };
            WorkerSpec {
                speed: speeds.value(k, base.speed) * half,
                link_bits_per_second: links.value(k, base.link_bits_per_second / 1e6) * 1e6,
                ..base.clone()
            }
        })
        .collect()
}

/// Simulates `frames` copies of the recorded frame on `workers`.
fn simulate(
    job: &FarmJob,
    costs: &FarmCosts,
    config: &SimulationConfig,
    workers: Vec<WorkerSpec>,
) -> Result<Vec<FarmFrame>> {
    Ok(simulate_farm(job, costs, config, &workers)?)
}

/// Per-frame fixed costs measured in a real run: the medians, over the
/// frames after the first, of the master's base-frame phase and of the
/// workers' set-up phases in its `stats.json` (`vtfarm submit`).
#[derive(Debug, PartialEq)]
pub(super) struct MeasuredFixedCosts {
    pub(super) base_frame_seconds: f64,
    pub(super) worker_setup_seconds: f64,
}

pub(super) fn fixed_costs_from_stats(path: &std::path::Path) -> Result<MeasuredFixedCosts> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let frames: Vec<vtfarm_proto::FrameStats> = serde_json::from_str::<Vec<StatsFrame>>(&text)
        .with_context(|| format!("{}: not a stats.json of vtfarm submit", path.display()))?
        .into_iter()
        .map(|f| f.stats)
        .collect();
    let median = |kind: PhaseKind| -> Option<f64> {
        let mut d: Vec<f64> = (frames.iter().skip(1).flat_map(|f| &f.phases))
            .filter(|p| p.kind == kind)
            .map(|p| p.end_micros.saturating_sub(p.start_micros) as f64 / 1e6)
            .collect();
        d.sort_by(f64::total_cmp);
        d.get(d.len() / 2).copied()
    };
    match (median(PhaseKind::Base), median(PhaseKind::Setup)) {
        (Some(base_frame_seconds), Some(worker_setup_seconds)) => Ok(MeasuredFixedCosts {
            base_frame_seconds,
            worker_setup_seconds,
        }),
        _ => bail!(
            "{}: needs base and set-up phases of at least two frames",
            path.display()
        ),
    }
}

/// One frame of `stats.json`: its statistics (and fields this reader ignores).
#[derive(serde::Deserialize)]
struct StatsFrame {
    #[serde(flatten)]
    stats: vtfarm_proto::FrameStats,
}

pub(crate) fn run(args: SimulateArgs) -> Result<()> {
    if args.frames == 0 || args.workers.contains(&0) || args.master_threads == Some(0) {
        bail!("--frames, --master-threads and every --workers entry must be at least 1");
    }
    if args.link_mbit.iter().any(|&m| !(m.is_finite() && m > 0.0)) {
        bail!("every --link-mbit entry must be positive and finite");
    }
    let speeds = PerWorker::parse("--worker-speed", &args.worker_speed, &args.workers)?;
    let links = PerWorker::parse("--worker-mbit", &args.worker_mbit, &args.workers)?;
    // Workers as given: no made-up half-speed farms beside them.
    let given = speeds != PerWorker::Default || links != PerWorker::Default;
    // Durations and scales: finite, so the virtual clock stays meaningful.
    let times = [args.latency_ms, args.package_overhead_ms.unwrap_or(0.0)];
    let scales = [args.cost_scale, args.fixed_cost_scale];
    if !times.iter().all(|t| t.is_finite() && *t >= 0.0)
        || !scales.iter().all(|s| s.is_finite() && *s > 0.0)
    {
        bail!(
            "--latency-ms and --package-overhead-ms must be finite and not negative, \
             --cost-scale and --fixed-cost-scale finite and positive"
        );
    }
    let background_ok = match args.background_cores.len() {
        0 | 1 => true,
        n => n == args.workers.len(),
    };
    let cores_ok = |b: &f64| {
        b.is_finite() && *b >= 0.0 && args.shared_cores.is_some_and(|c| *b < f64::from(c))
    };
    if !background_ok || !args.background_cores.iter().all(cores_ok) {
        bail!(
            "--background-cores needs --shared-cores, one value or one per --workers entry, \
             each at least 0 and below the shared cores"
        );
    }
    // The simulated farm holds every worker's state and every frame's
    // stats: bound them.
    if args.workers.iter().any(|&w| w > 4096) || args.frames > 10_000 {
        bail!("at most 4096 workers and 10000 frames per simulation");
    }
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let threads = args.threads.unwrap_or(cores);
    let master_cores = args.master_threads.unwrap_or(cores as u32);
    let job = CockpitJob::new(args.detail, args.width, args.height, args.quality)?;
    eprintln!(
        "recording per-triangle costs ({} reflector triangles, {}x{} {}, {threads} one-thread pools) ...",
        job.reflectors.len(),
        args.width,
        args.height,
        args.quality.name()
    );
    let mut recording = record(&job, threads, args.repeats)?;
    if let Some(path) = &args.fixed_costs {
        let measured = fixed_costs_from_stats(path)?;
        // The phases are wall times of that run: the base frame already on
        // its machine's cores.
        recording.base_frame_seconds = measured.base_frame_seconds * f64::from(master_cores);
        recording.worker_setup_seconds = measured.worker_setup_seconds;
    }
    if args.no_fixed_costs {
        recording.base_frame_seconds = 0.0;
        recording.worker_setup_seconds = 0.0;
        recording.scene_prepare_seconds = 0.0;
        recording.composite_seconds = 0.0;
        recording.frame_out_seconds = 0.0;
        recording.frame_out_written_seconds = 0.0;
        recording.frame_out_serial_seconds = 0.0;
        recording.frame_sent_seconds = 0.0;
        recording.journal_seconds = 0.0;
        recording.submitter_seconds = 0.0;
    }
    let total = recording.total_seconds() * args.cost_scale;
    let n = recording.triangles.len().max(1) as f64;
    let costs = FarmCosts {
        items: recording.triangles.clone(),
        seconds: recording
            .seconds
            .iter()
            .map(|s| s * args.cost_scale)
            .collect(),
        samples: (recording.samples.iter())
            .map(|&s| u32::try_from(s).unwrap_or(u32::MAX))
            .collect(),
        result_bytes: (recording.result_bytes.iter())
            .map(|b| b.saturating_sub(recording.empty_result_bytes))
            .collect(),
        empty_result_bytes: recording.empty_result_bytes,
        frame_bytes: recording.frame_bytes,
        worker_setup: recording.worker_setup_seconds * args.fixed_cost_scale,
        scene_prepare: recording.scene_prepare_seconds * args.fixed_cost_scale,
        master: MasterCosts {
            base_frame: recording.base_frame_seconds * args.fixed_cost_scale,
            // Compositing does not grow with the work per pixel: not scaled.
            result_per_item: recording.composite_seconds / n,
            frame_out: recording.frame_out_seconds,
            frame_out_written: recording.frame_out_written_seconds,
            frame_out_serial: recording.frame_out_serial_seconds,
            frame_sent: recording.frame_sent_seconds,
            journal: recording.journal_seconds,
            submitter: recording.submitter_seconds,
        },
    };
    // The master core rasterizes a stand-in base frame: tiny, the time is modelled.
    let farm_job = FarmJob {
        scene: job.scene.clone(),
        reflectors: job.reflectors.clone(),
        setup: FrameSetup {
            camera: vtfarm_scene::Camera {
                width: 32,
                height: 18,
                ..job.setup.camera
            },
            ..job.setup.clone()
        },
    };
    let config = |mbit: f64| SimulationConfig {
        master_link_bits_per_second: mbit * 1e6,
        master_cores,
        shared_cores: args.shared_cores,
        background_threads: 0.0,
        frames: args.frames as u32,
        time_limit: Duration::from_secs(24 * 3600),
        rules: vtfarm_master::FarmRules::default(),
        workers_hold_scene: args.workers_hold_scene,
    };
    let latency = Duration::from_secs_f64(args.latency_ms / 1e3);
    let overhead = Duration::from_secs_f64(
        (args.package_overhead_ms).map_or(recording.package_seconds, |ms| ms / 1e3),
    );
    let worker = |speed: f64, mbit: f64| WorkerSpec {
        speed,
        link_bits_per_second: mbit * 1e6,
        latency,
        package_overhead: overhead,
        cores: args.worker_threads.max(1),
    };
    let farm = |n: usize, mbit: f64, slow: usize| {
        farm_workers(&speeds, &links, n, slow, &worker(1.0, mbit))
    };
    let mut rows = Vec::new();
    for &mbit in &args.link_mbit {
        let config = &config(mbit);
        let one = simulate(&farm_job, &costs, config, farm(1, mbit, 0))?;
        for (k, &n) in args.workers.iter().enumerate() {
            let background = match args.background_cores.as_slice() {
                [] => 0.0,
                [all] => *all,
                each => each[k],
            };
            let equal = farm(n, mbit, 0);
            let config = &SimulationConfig {
                background_threads: background_threads_for(
                    &farm_job, &costs, config, &equal, background,
                )?,
                ..config.clone()
            };
            for heterogeneous in [false, true] {
                if heterogeneous && (n < 2 || given) {
                    continue;
                }
                let slow = if heterogeneous { n / 2 } else { 0 };
                let workers = farm(n, mbit, slow);
                let frames = simulate(&farm_job, &costs, config, workers.clone())?;
                let mut row = Row::new(&frames, &one, total, &workers, mbit, heterogeneous)?;
                if config.background_threads > 0.0 {
                    let idle = SimulationConfig {
                        background_threads: 0.0,
                        ..config.clone()
                    };
                    let idle = simulate(&farm_job, &costs, &idle, workers)?;
                    row.frame_seconds_idle = steady_frame_seconds(&idle);
                }
                row.background_threads = config.background_threads;
                row.background_cores = steady_background_cores(&frames);
                rows.push(row);
            }
        }
    }
    print_report(&args, &job, &recording, &rows, master_cores);
    if let Some(path) = &args.json {
        write_json(path, &rows)?;
    }
    Ok(())
}

fn print_report(
    args: &SimulateArgs,
    job: &CockpitJob,
    rec: &Recording,
    rows: &[Row],
    master_cores: u32,
) {
    let config_bytes_per_item = rec.bytes_per_item();
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
        "  results: {:.2} MB per frame as one-triangle messages (compact: zstd, colour only), {} bytes per triangle modelled (+ {} per message)",
        bytes as f64 / 1e6,
        config_bytes_per_item,
        rec.empty_result_bytes
    );
    println!(
        "  fixed costs per frame (one thread, x{}{}): master base frame {:.3} s + its sRGB {:.3} s on every core (not scaled; overlap the tracing), worker set-up {:.3} s ({:.3} s for a frame that differs from the last only in the sun; a worker's first frame of the scene {:.3} s more{}); master compositing {:.3} s, finished frame out {:.3} s (sRGB of the {}x{} pixels results write, on every core) + {:.3} s (zstd) + {:.3} s sent and journal {:.3} s, submitter {:.3} s (not scaled); per package beside its triangles {:.2} ms; per-triangle tracing {:.3} s wall ({} passes, least CPU time kept); all CPU time",
        args.fixed_cost_scale,
        match &args.fixed_costs {
            Some(path) => format!(", base and set-up from {}", path.display()),
            None => String::new(),
        },
        rec.base_frame_seconds * args.fixed_cost_scale,
        rec.frame_out_seconds,
        rec.worker_setup_seconds * args.fixed_cost_scale,
        rec.sun_only_setup_seconds * args.fixed_cost_scale,
        rec.scene_prepare_seconds * args.fixed_cost_scale,
        if args.workers_hold_scene {
            ": every worker holds it prepared"
        } else {
            ""
        },
        rec.composite_seconds,
        rec.frame_out_written_seconds,
        rec.written.x1.saturating_sub(rec.written.x0),
        rec.written.y1.saturating_sub(rec.written.y0),
        rec.frame_out_serial_seconds,
        rec.frame_sent_seconds,
        rec.journal_seconds,
        rec.submitter_seconds,
        rec.package_seconds * 1e3,
        rec.tracing_wall_seconds,
        args.repeats
    );
    println!(
        "model: the master's own core and the workers' own sessions on a virtual clock; speed 1 = one thread of this machine; {} frame(s) of the recorded costs; each worker's own link and the master's one shared link at the given rate, {} ms latency, {:.2} ms per package; {}",
        args.frames,
        args.latency_ms,
        args.package_overhead_ms
            .unwrap_or(rec.package_seconds * 1e3),
        match args.shared_cores {
            Some(c) => format!("everything shares one machine of {c} cores"),
            None => format!(
                "the master on its own machine of {master_cores} cores, each worker on its own core"
            ),
        }
    );
    println!(
        "columns: mixed = half the workers at half speed; given = workers of differing --worker-speed or --worker-mbit; ideal = sum of speeds; frame s = steady-state time per frame: from the first frame's delivery to the last's, over the frames' work traced in between (set-ups, base frame, links included); effic. = one thread's tracing per frame / (frame s x ideal), at most 100%; vs 1 = one worker's frame s / frame s; imb. = worst frame after the first and delivered before the last frame's announcement (the job's drain) of (max - mean) / mean of the workers' package time within the frame's lifetime (announcement to delivery); latency = the last frame's lifetime"
    );
    println!(
        "{:>7} {:>6} {:>6} {:>6} {:>9} {:>7} {:>7} {:>7} {:>8} {:>8}",
        "workers",
        "link",
        "set",
        "ideal",
        "frame s",
        "effic.",
        "vs 1",
        "imb.",
        "latency",
        "packages"
    );
    for r in rows {
        println!(
            "{:>7} {:>6} {:>6} {:>6.1} {:>9.3} {:>6.0}% {:>7.2} {:>6.1}% {:>8.3} {:>8}",
            r.workers,
            format!("{}M", r.link_mbit),
            r.set_name(),
            r.ideal,
            r.frame_seconds,
            r.efficiency * 100.0,
            r.speedup_vs_one,
            r.imbalance_after_first * 100.0,
            r.latency_seconds_per_frame.last().copied().unwrap_or(0.0),
            r.packages
        );
        if !(args.worker_speed.is_empty() && args.worker_mbit.is_empty()) {
            let list = |v: &[f64]| v.iter().map(f64::to_string).collect::<Vec<_>>().join(",");
            println!(
                "{:>7} worker speeds {}, their own links {} Mbit/s",
                "",
                list(&r.worker_speeds),
                list(&r.worker_mbit)
            );
        }
        if r.background_threads > 0.0 {
            println!(
                "{:>7} other work on the machine: {:.2} always-runnable threads got {:.2} cores; {:.3} s per frame without it",
                "", r.background_threads, r.background_cores, r.frame_seconds_idle
            );
        }
    }
    for &mbit in &args.link_mbit {
        // Batch work runs in whole frames: each comes to the master finished.
        let whole_seconds = (rec.frame_bytes + rec.empty_result_bytes) as f64 * 8.0 / (mbit * 1e6);
        println!(
            "  {mbit} Mbit/s master link, whole frames: a finished frame ({:.2} MB) takes {whole_seconds:.4} s through it: the farm's bound is {:.0} frames per second",
            rec.frame_bytes as f64 / 1e6,
            1.0 / whole_seconds
        );
        let link_seconds = bytes as f64 * 8.0 / (mbit * 1e6);
        let fastest = (rows.iter())
            .filter(|r| r.link_mbit == mbit)
            .map(|r| r.frame_seconds)
            .fold(f64::INFINITY, f64::min);
        println!(
            "  {mbit} Mbit/s master link, split frames (the tail, single frames, the view): the results take {link_seconds:.3} s per frame through it, {:.0}% of the fastest simulated frame ({fastest:.3} s)",
            link_seconds / fastest * 100.0
        );
    }
    // The master's own work per frame: a whole frame costs its driver only
    // the forwarding and its journal thread the record; a split frame also
    // costs the base frame (with its sRGB conversion), the compositing of
    // every result and the image for the wire (the written pixels' sRGB).
    let base = (rec.base_frame_seconds * args.fixed_cost_scale + rec.frame_out_seconds)
        / f64::from(master_cores.max(1));
    let out = rec.frame_out_written_seconds / f64::from(master_cores.max(1))
        + rec.frame_out_serial_seconds
        + rec.frame_sent_seconds;
    let split = base.max(rec.composite_seconds + out);
    println!(
        "  the master's own work: per whole frame its journal {:.4} s (its own thread: at most {:.0} frames per second); per split frame {split:.3} s (base frame {base:.3} s on {master_cores} core(s), compositing {:.3} s, the image out {out:.3} s)",
        rec.journal_seconds,
        1.0 / rec.journal_seconds.max(1e-9),
        rec.composite_seconds,
    );
    // The aims of issue 26 for equal workers, as speed-up over one worker
    // per worker (a whole frame's base frame and compositing are the
    // workers' work now, so `effic.`, tracing alone, cannot reach 100%).
    for &mbit in &args.link_mbit {
        let equal = |n: usize| {
            (rows.iter()).find(|r| !r.heterogeneous && r.link_mbit == mbit && r.workers == n)
        };
        for (n, aim) in [(16, 0.9), (64, 0.85), (256, 0.9)] {
            if let Some(r) = equal(n) {
                let per_worker = r.speedup_vs_one / r.ideal;
                println!(
                    "  aim at {mbit} Mbit, {n} equal workers: speed-up per worker >= {:.0}%: {:.1}% ({:.2}x): {}",
                    aim * 100.0,
                    per_worker * 100.0,
                    r.speedup_vs_one,
                    if per_worker >= aim { "met" } else { "missed" }
                );
            }
        }
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
    use clap::Parser;

    /// n one-triangle packages pay the overhead n times, one package of all
    /// n once: the difference over n − 1; never below an empty package's.
    #[test]
    fn a_packages_overhead_is_what_one_package_of_all_saves_per_package() {
        // Triangles of 1, 2 and 3 ms plus 0.5 ms each as its own package;
        // all three as one package: 6.5 ms.
        let single = [0.0015, 0.0025, 0.0035];
        let overhead = package_overhead(&single, 0.0065, 0.0001);
        assert!((overhead - 0.0005).abs() < 1e-12, "{overhead}");
        assert_eq!(
            package_overhead(&single, 0.0075, 0.0001),
            0.0001,
            "the floor"
        );
        assert_eq!(
            package_overhead(&[0.002], 0.002, 0.0001),
            0.0001,
            "one triangle"
        );
    }

    /// `vtfarm bench simulate`'s arguments alone.
    #[derive(clap::Parser)]
    struct Cli {
        #[command(flatten)]
        args: SimulateArgs,
    }

    fn parse(args: &[&str]) -> SimulateArgs {
        Cli::try_parse_from(["simulate"].iter().chain(args))
            .expect("arguments parse")
            .args
    }

    fn per_worker(args: &SimulateArgs) -> Result<(PerWorker, PerWorker)> {
        Ok((
            PerWorker::parse("--worker-speed", &args.worker_speed, &args.workers)?,
            PerWorker::parse("--worker-mbit", &args.worker_mbit, &args.workers)?,
        ))
    }

    #[test]
    fn per_worker_speeds_and_links_parse_one_each_or_one_for_every_worker() {
        let args = parse(&[
            "--workers",
            "2",
            "--worker-speed",
            "0.45,0.15",
            "--worker-mbit",
            "100,10",
        ]);
        assert_eq!(
            per_worker(&args).unwrap(),
            (
                PerWorker::Each(vec![0.45, 0.15]),
                PerWorker::Each(vec![100.0, 10.0])
            )
        );
        let args = parse(&["--workers", "1,2,4", "--worker-speed", "0.22"]);
        assert_eq!(
            per_worker(&args).unwrap(),
            (PerWorker::Every(0.22), PerWorker::Default)
        );
        let args = parse(&[]);
        assert_eq!(
            per_worker(&args).unwrap(),
            (PerWorker::Default, PerWorker::Default)
        );
    }

    #[test]
    fn a_per_worker_list_that_does_not_match_the_workers_is_a_clear_error() {
        for (args, message) in [
            (
                &["--workers", "3", "--worker-speed", "0.45,0.15"][..],
                "--worker-speed gives 2 values but --workers is 3",
            ),
            (
                &["--workers", "1,2", "--worker-mbit", "100,10"][..],
                "--worker-mbit gives 2 values but --workers is 1,2",
            ),
            (
                &["--workers", "2", "--worker-speed", "0.45,0"][..],
                "every --worker-speed entry must be positive and finite, not 0",
            ),
            (
                &["--workers", "2", "--worker-mbit", "100,-10"][..],
                "every --worker-mbit entry must be positive and finite, not -10",
            ),
            (
                &["--workers", "1", "--worker-speed", "NaN"][..],
                "every --worker-speed entry must be positive and finite, not NaN",
            ),
        ] {
            let args = parse(args);
            let error = per_worker(&args).unwrap_err().to_string();
            assert!(error.starts_with(message), "{error}");
            // `run` refuses them before it records anything.
            let error = run(args).unwrap_err().to_string();
            assert!(error.starts_with(message), "{error}");
        }
    }

    #[test]
    fn farm_workers_take_each_speed_and_link_and_keep_the_rest() {
        let base = WorkerSpec {
            speed: 1.0,
            link_bits_per_second: 1e9,
            latency: Duration::from_micros(50),
            package_overhead: Duration::from_micros(20),
            cores: 1,
        };
        let each = farm_workers(
            &PerWorker::Each(vec![0.45, 0.15]),
            &PerWorker::Each(vec![100.0, 10.0]),
            2,
            0,
            &base,
        );
        let figures: Vec<(f64, f64)> = (each.iter())
            .map(|w| (w.speed, w.link_bits_per_second))
            .collect();
        assert_eq!(figures, [(0.45, 100e6), (0.15, 10e6)]);
        assert!(each.iter().all(|w| w.latency == base.latency
            && w.package_overhead == base.package_overhead
            && w.cores == 1));
        // The default farms: the base link, and the last `slow` at half speed.
        let mixed = farm_workers(&PerWorker::Default, &PerWorker::Default, 3, 1, &base);
        let figures: Vec<(f64, f64)> = (mixed.iter())
            .map(|w| (w.speed, w.link_bits_per_second))
            .collect();
        assert_eq!(figures, [(1.0, 1e9), (1.0, 1e9), (0.5, 1e9)]);
    }

    /// A whole run with workers as given: one farm of exactly those workers
    /// (no half-speed farm beside it), the master's link as --link-mbit,
    /// and per frame its delivery and every process's CPU in the JSON.
    #[test]
    fn given_workers_are_simulated_as_given_and_reported_per_frame() {
        let dir = tempfile::tempdir().unwrap();
        let json = dir.path().join("sim.json");
        let args = parse(&[
            "--workers",
            "2",
            "--worker-speed",
            "0.45,0.15",
            "--worker-mbit",
            "100,10",
            "--link-mbit",
            "1000",
            "--frames",
            "4",
            "--width",
            "64",
            "--height",
            "36",
            "--detail",
            "0.3",
            "--repeats",
            "1",
            "--threads",
            "1",
            "--master-threads",
            "1",
            "--json",
            json.to_str().unwrap(),
        ]);
        run(args).unwrap();
        let rows: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let rows = rows.as_array().unwrap();
        assert_eq!(rows.len(), 1, "one farm, no mixed one: {rows:?}");
        let row = &rows[0];
        assert_eq!(row["workers"], 2);
        assert_eq!(row["heterogeneous"], false);
        assert_eq!(row["link_mbit"], 1000.0);
        assert_eq!(row["worker_speeds"], serde_json::json!([0.45, 0.15]));
        assert_eq!(row["worker_mbit"], serde_json::json!([100.0, 10.0]));
        assert!((row["ideal"].as_f64().unwrap() - 0.6).abs() < 1e-12);
        let done = row["done_seconds_per_frame"].as_array().unwrap();
        assert_eq!(done.len(), 4);
        let done: Vec<f64> = done.iter().map(|d| d.as_f64().unwrap()).collect();
        assert!(done.windows(2).all(|w| w[0] <= w[1]), "{done:?}");
        let completed = row["completed_seconds_per_frame"].as_array().unwrap();
        assert_eq!(completed.len(), 4);
        assert!(
            (completed.iter().zip(&done)).all(|(c, d)| c.as_f64().unwrap() <= *d),
            "{completed:?} {done:?}"
        );
        let cpu = row["cpu_at_delivery"].as_array().unwrap();
        assert_eq!(cpu.len(), 4);
        // The master, two workers, the submitter.
        assert!(cpu.iter().all(|c| c.as_array().unwrap().len() == 4));
    }

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
        // Covered pixels cost bytes beyond the fixed part (compressed, so
        // no fixed amount per pixel); a triangle without pixels sends about
        // the fixed part.
        let empty = recording.empty_result_bytes;
        for (&p, &b) in recording.pixels.iter().zip(&recording.result_bytes) {
            if p > 0 {
                assert!(b > empty, "pixels {p}, bytes {b}");
            } else {
                assert!(b < empty + 32, "no pixels, bytes {b}");
            }
        }
    }
}
