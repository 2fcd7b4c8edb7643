//! Recording a real frame's costs: every reflector triangle traced as a
//! package of its own, and the per-frame fixed costs of the master, the
//! workers and the submitter, each in the CPU time of the thread that ran it.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use vtfarm_proto::{
    FrameDone, Message, PackageResult, ResultPixels, SceneData, WireBitmap, WireBitmapParts,
    WireImage, WireImageFormat, WirePackageStats, decode_message, encode_message,
};
use vtfarm_render::Renderer;
use vtfarm_scene::TriangleId;

use crate::support::{CpuClock, cpu_time};
use vtfarm_vertex::{Frame, PackageOptions, PixelRect, SparseBitmap, trace_package};

use crate::CockpitJob;

/// Per-triangle costs of one frame, in the master's (Morton) order.
#[derive(Clone, Debug)]
pub(super) struct Recording {
    /// Reflector triangle ids in Morton order.
    pub(super) triangles: Vec<TriangleId>,
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
    pub(super) fn total_seconds(&self) -> f64 {
        self.seconds.iter().sum()
    }

    pub(super) fn total_bytes(&self) -> u64 {
        self.result_bytes.iter().sum()
    }

    /// Mean result bytes per triangle beyond a message's fixed part.
    pub(super) fn bytes_per_item(&self) -> u64 {
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
pub(super) struct CpuStopwatch {
    cpu: Option<Duration>,
    wall: Instant,
}

impl CpuStopwatch {
    pub(super) fn start() -> CpuStopwatch {
        CpuStopwatch {
            cpu: cpu_time(CpuClock::Thread),
            wall: Instant::now(),
        }
    }

    /// CPU time of this thread since `start` (which must have run on it).
    pub(super) fn elapsed(&self) -> Duration {
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
pub(super) fn least_cpu_seconds<T: Send>(
    pool: &rayon::ThreadPool,
    f: impl Fn() -> T + Sync,
) -> f64 {
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
pub(super) fn result_message_bytes(
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
pub(super) const FIXED_COST_RUNS: usize = 3;

/// One triangle's measurements: (index, seconds, bytes, samples, pixels,
/// and from its first pass the result's bitmap as sent).
pub(super) type Measure = (usize, f64, u64, u64, u64, Option<WireBitmap>);

/// A package's own cost beside its triangles', from the least times of
/// one-triangle packages (`single`, each paying it once) and of all of them
/// as one package (`whole`, paying it once): a package sets up and encodes
/// more than an empty one does (`empty`, the floor), so n one-triangle
/// packages cost more than one of n triangles, by n − 1 overheads.
pub(super) fn package_overhead(single: &[f64], whole: f64, empty: f64) -> f64 {
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
pub(super) fn trace_pass(
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
pub(super) struct FrameOut {
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
pub(super) fn frame_out_time(
    renderer: &Renderer,
    job: &CockpitJob,
    written: PixelRect,
) -> Result<FrameOut> {
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
            job: vtfarm_proto::JobId(1),
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
pub(super) fn composite_time(
    renderer: &Renderer,
    job: &CockpitJob,
    triangles: &[TriangleId],
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
                .find(|(p, _)| ids.triangle[*p] != triangles[*i].raw())
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

#[cfg(test)]
mod tests {
    use super::*;
    use vtfarm_vertex::Quality;

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
