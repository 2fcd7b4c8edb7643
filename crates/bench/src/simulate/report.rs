//! The figures of the simulated farms: one row per farm, printed as a
//! table and written as JSON.

use anyhow::{Context, Result};
use serde::Serialize;

use vtfarm_farmsim::{FarmFrame, WorkerSpec, cpu_per_frame, steady_frame_seconds};

use super::SimulateArgs;
use super::record::Recording;
use crate::CockpitJob;

/// One simulated farm: the figures of its frames.
#[derive(Serialize)]
pub(super) struct Row {
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
    pub(super) frame_seconds_idle: f64,
    /// The modelled other work: always-runnable threads, and the cores
    /// they got over the steady window (`steady_background_cores`).
    pub(super) background_threads: f64,
    pub(super) background_cores: f64,
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
    pub(super) fn set_name(&self) -> &'static str {
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
    pub(super) fn new(
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

pub(super) fn print_report(
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
    // The farm's aims for equal workers, as speed-up over one worker
    // per worker (a whole frame's base frame and compositing are the
    // workers' work in whole frames, so `effic.`, tracing alone, cannot
    // reach 100%).
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
