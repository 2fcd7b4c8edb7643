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
use std::time::Duration;

use anyhow::{Context, Result, bail};
use vtfarm_cockpit::CockpitConfig;
use vtfarm_proto::PhaseKind;
use vtfarm_render::FrameSetup;

use vtfarm_farmsim::{
    FarmCosts, FarmFrame, FarmJob, MasterCosts, SimulationConfig, WorkerSpec,
    background_threads_for, simulate_farm, steady_background_cores, steady_frame_seconds,
};
use vtfarm_vertex::Quality;

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

mod record;
mod report;

use record::record;
use report::{Row, print_report};

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
        items: vtfarm_proto::wire_triangles(&recording.triangles),
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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

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
}
